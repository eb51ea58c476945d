//! `ProbeModel`: a small co-simulation model with one variable of every kind the layer treats
//! differently, for driving the C exports as a host would. It diverges on demand.
//!
//! `x` integrates `multiplier · u` (with `u` ramping at its input derivative inside a step);
//! the output `y = x + gain · u + offset` depends directly on the input `u`.

use std::sync::OnceLock;

use fmi2::{CoSimModel, InstantiateContext, ModelError, ModelInfo, Unit, Variable};
use serde::{Deserialize, Serialize};

pub const U: u32 = 1;
pub const Y: u32 = 2;
pub const X: u32 = 3;
/// Fixed real parameter, must be > 0 (the model's own check).
pub const GAIN: u32 = 4;
/// Tunable real parameter: settable after initialization too.
pub const OFFSET: u32 = 5;
/// Fixed Integer parameter in 1..=10 (the model's own check).
pub const MULTIPLIER: u32 = 6;
/// Boolean input: the next step diverges.
pub const DIVERGE: u32 = 7;
/// Fixed Boolean parameter.
pub const FLAG: u32 = 8;
/// Fixed String parameter.
pub const LABEL: u32 = 9;

pub const GAIN_START: f64 = 2.0;
pub const LABEL_START: &str = "probe";

pub fn info() -> &'static ModelInfo {
    static INFO: OnceLock<ModelInfo> = OnceLock::new();
    INFO.get_or_init(|| {
        ModelInfo::new(
            "Probe",
            "probe",
            "test model for the FMI 2.0 export layer",
            "1",
            vec![
                Variable::real_input("u", U, "m", 0.0),
                Variable::real_output("y", Y, "m").depends_on(&[U]),
                Variable::real_output("x", X, "m"),
                Variable::real_parameter("gain", GAIN, "1", GAIN_START),
                Variable::real_parameter("offset", OFFSET, "m", 0.0).tunable(),
                Variable::integer_parameter("multiplier", MULTIPLIER, 1),
                Variable::boolean_input("diverge", DIVERGE, false),
                Variable::boolean_parameter("flag", FLAG, false),
                Variable::string_parameter("label", LABEL, LABEL_START),
            ],
            vec![
                Unit {
                    name: "m",
                    kg: 0,
                    m: 1,
                    s: 0,
                },
                Unit {
                    name: "1",
                    kg: 0,
                    m: 0,
                    s: 0,
                },
            ],
            true,
            None,
        )
        .expect("the probe's variable table is consistent")
    })
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ProbeModel {
    pub u: f64,
    pub du: f64,
    pub x: f64,
    pub gain: f64,
    pub offset: f64,
    pub multiplier: i32,
    pub diverge: bool,
    pub flag: bool,
    pub label: String,
}

impl CoSimModel for ProbeModel {
    fn info() -> &'static ModelInfo {
        info()
    }

    fn instantiate(_context: &InstantiateContext) -> Result<Self, ModelError> {
        Ok(ProbeModel {
            u: 0.0,
            du: 0.0,
            x: 0.0,
            gain: GAIN_START,
            offset: 0.0,
            multiplier: 1,
            diverge: false,
            flag: false,
            label: LABEL_START.to_owned(),
        })
    }

    fn get_real(&mut self, vr: u32) -> Result<f64, ModelError> {
        match vr {
            U => Ok(self.u),
            Y => Ok(self.x + self.gain * self.u + self.offset),
            X => Ok(self.x),
            GAIN => Ok(self.gain),
            OFFSET => Ok(self.offset),
            _ => Err(ModelError::UnknownVariable { vr, kind: "Real" }),
        }
    }

    fn set_real(&mut self, vr: u32, value: f64) -> Result<(), ModelError> {
        match vr {
            U => self.u = value,
            GAIN if value > 0.0 => self.gain = value,
            GAIN => {
                return Err(ModelError::InvalidValue {
                    name: "gain".into(),
                    reason: format!("{value} must be > 0"),
                })
            }
            OFFSET => self.offset = value,
            _ => return Err(ModelError::UnknownVariable { vr, kind: "Real" }),
        }
        Ok(())
    }

    fn get_integer(&mut self, vr: u32) -> Result<i32, ModelError> {
        match vr {
            MULTIPLIER => Ok(self.multiplier),
            _ => Err(ModelError::UnknownVariable {
                vr,
                kind: "Integer",
            }),
        }
    }

    fn set_integer(&mut self, vr: u32, value: i32) -> Result<(), ModelError> {
        match vr {
            MULTIPLIER if (1..=10).contains(&value) => self.multiplier = value,
            MULTIPLIER => {
                return Err(ModelError::InvalidValue {
                    name: "multiplier".into(),
                    reason: format!("{value} is outside [1, 10]"),
                })
            }
            _ => {
                return Err(ModelError::UnknownVariable {
                    vr,
                    kind: "Integer",
                })
            }
        }
        Ok(())
    }

    fn get_boolean(&mut self, vr: u32) -> Result<bool, ModelError> {
        match vr {
            DIVERGE => Ok(self.diverge),
            FLAG => Ok(self.flag),
            _ => Err(ModelError::UnknownVariable {
                vr,
                kind: "Boolean",
            }),
        }
    }

    fn set_boolean(&mut self, vr: u32, value: bool) -> Result<(), ModelError> {
        match vr {
            DIVERGE => self.diverge = value,
            FLAG => self.flag = value,
            _ => {
                return Err(ModelError::UnknownVariable {
                    vr,
                    kind: "Boolean",
                })
            }
        }
        Ok(())
    }

    fn get_string(&mut self, vr: u32) -> Result<String, ModelError> {
        match vr {
            LABEL => Ok(self.label.clone()),
            _ => Err(ModelError::UnknownVariable { vr, kind: "String" }),
        }
    }

    fn set_string(&mut self, vr: u32, value: &str) -> Result<(), ModelError> {
        match vr {
            LABEL => self.label = value.to_owned(),
            _ => return Err(ModelError::UnknownVariable { vr, kind: "String" }),
        }
        Ok(())
    }

    fn set_real_input_derivative(&mut self, vr: u32, derivative: f64) -> Result<(), ModelError> {
        match vr {
            U => self.du = derivative,
            _ => {
                return Err(ModelError::UnknownVariable {
                    vr,
                    kind: "Real input",
                })
            }
        }
        Ok(())
    }

    fn do_step(&mut self, time: f64, step_size: f64) -> Result<(), ModelError> {
        if self.diverge {
            // Like a real integrator, the state is already ruined when the failure is noticed.
            self.x = f64::NAN;
            return Err(ModelError::Diverged {
                time: time + step_size,
                what: "the diverge input is set".into(),
            });
        }
        let h = step_size;
        self.x += f64::from(self.multiplier) * (self.u * h + 0.5 * self.du * h * h);
        self.u += self.du * h;
        Ok(())
    }
}
