//! The substructure FMU's model: `numerics::substructure` stepped by `fmi2DoStep`, in the role
//! its `role` parameter chooses.

use fmi2::{CoSimModel, InstantiateContext, ModelError, ModelInfo};
use numerics::substructure::{Frame, Imposed, Numerical, Physical, Split};
use serde::{Deserialize, Serialize};

use crate::variables::{self as vars, *};

/// Relative tolerance on the physical role's communication step against `control_step`.
pub const STEP_TOLERANCE: f64 = 1e-9;

/// Everything the host sets before initialization.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Parameters {
    pub role: i32,
    pub frame: Frame,
    pub substeps: i32,
    pub control_step: f64,
}

impl Default for Parameters {
    fn default() -> Self {
        Parameters {
            role: ROLE_NUMERICAL,
            frame: Frame {
                mass: vec![DEFAULT_MASS; STOREYS],
                damping: vec![DEFAULT_DAMPING; STOREYS],
                stiffness: vec![DEFAULT_STIFFNESS; STOREYS],
                floor: SPLIT_FLOOR,
                gap: DEFAULT_GAP,
                contact_stiffness: DEFAULT_CONTACT_STIFFNESS,
            },
            substeps: DEFAULT_SUBSTEPS,
            control_step: DEFAULT_CONTROL_STEP,
        }
    }
}

fn invalid(name: &str, reason: String) -> ModelError {
    ModelError::InvalidValue {
        name: name.into(),
        reason,
    }
}

fn role_reason(value: i32) -> String {
    format!(
        "{value}: 0 (numerical substructure), 1 (physical, specimen floor 3) or 2 (physical, \
         specimen floors 2-3)"
    )
}

impl Parameters {
    /// Every parameter, whichever the role uses: the first bad one, by its name.
    pub fn check(&self) -> Result<(), ModelError> {
        if !(ROLE_NUMERICAL..=ROLE_PHYSICAL_FLOORS_2_3).contains(&self.role) {
            return Err(invalid("role", role_reason(self.role)));
        }
        let f = &self.frame;
        for (i, &m) in f.mass.iter().enumerate() {
            if !(m.is_finite() && m > 0.0) {
                return Err(invalid(
                    &format!("m{}", i + 1),
                    format!("{m}: a mass must be positive and finite"),
                ));
            }
        }
        for (prefix, values) in [("c", &f.damping), ("k", &f.stiffness)] {
            for (i, x) in values.iter().enumerate() {
                if !(x.is_finite() && *x >= 0.0) {
                    return Err(invalid(
                        &format!("{prefix}{}", i + 1),
                        format!("{x}: must be non-negative and finite"),
                    ));
                }
            }
        }
        if !(f.gap.is_finite() && f.gap >= 0.0) {
            return Err(invalid(
                "gap",
                format!(
                    "{}: the bumper's gap must be non-negative and finite",
                    f.gap
                ),
            ));
        }
        if !(f.contact_stiffness.is_finite() && f.contact_stiffness >= 0.0) {
            return Err(invalid(
                "contact_stiffness",
                format!("{}: must be non-negative and finite", f.contact_stiffness),
            ));
        }
        if self.substeps < 1 {
            return Err(invalid(
                "substeps",
                format!("{}: at least 1 RK4 step", self.substeps),
            ));
        }
        if !(self.control_step.is_finite() && self.control_step > 0.0) {
            return Err(invalid(
                "control_step",
                format!("{}: must be positive and finite", self.control_step),
            ));
        }
        Ok(())
    }

    fn substeps(&self) -> u32 {
        u32::try_from(self.substeps.max(1)).unwrap_or(1)
    }
}

/// An input held as `value + slope·(t − t_set)` inside a step (first-order interpolation).
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct RampInput {
    pub value: f64,
    pub slope: f64,
}

/// The FMU instance: parameters, inputs and both roles' states (the other role's stays at 0).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SubstructureModel {
    pub params: Parameters,
    pub force: RampInput,
    pub interface_force: f64,
    pub interface_force_rate: f64,
    /// y2_start, v2_start, y2_end, v2_end.
    pub motion: [f64; 4],
    pub numerical: Numerical,
    pub physical: Physical,
    /// The physical specimen at the end of the current motion (cached until an input or a
    /// parameter changes, or a step is taken).
    #[serde(skip)]
    preview: Option<Physical>,
}

fn unknown(vr: u32, kind: &'static str) -> ModelError {
    ModelError::UnknownVariable { vr, kind }
}

impl SubstructureModel {
    fn physical_role(&self) -> bool {
        self.params.role != ROLE_NUMERICAL
    }

    /// What the physical role's specimen holds.
    fn split(&self) -> Split {
        if self.params.role == ROLE_PHYSICAL_FLOORS_2_3 {
            Split::FloorPhysical
        } else {
            Split::FloorNumerical
        }
    }

    fn imposed(&self) -> Imposed {
        let [y0, v0, y1, v1] = self.motion;
        Imposed {
            y0,
            v0,
            y1,
            v1,
            h: self.params.control_step,
        }
    }

    /// The specimen at the end of the imposed motion.
    fn end_of_motion(&mut self) -> Physical {
        if let Some(p) = &self.preview {
            return p.clone();
        }
        let mut p = self.physical.clone();
        let h = self.params.control_step;
        if h.is_finite() && h > 0.0 {
            p.follow(&self.params.frame, &self.imposed(), self.params.substeps());
        }
        self.preview = Some(p.clone());
        p
    }

    fn real_slot(&mut self, vr: u32) -> Option<&mut f64> {
        let p = &mut self.params;
        let i = |base: u32| (vr - base) as usize;
        Some(match vr {
            MASS..=12 => &mut p.frame.mass[i(MASS)],
            DAMPING..=15 => &mut p.frame.damping[i(DAMPING)],
            STIFFNESS..=18 => &mut p.frame.stiffness[i(STIFFNESS)],
            GAP => &mut p.frame.gap,
            CONTACT_STIFFNESS => &mut p.frame.contact_stiffness,
            CONTROL_STEP => &mut p.control_step,
            vars::FORCE => &mut self.force.value,
            INTERFACE_FORCE => &mut self.interface_force,
            INTERFACE_FORCE_RATE => &mut self.interface_force_rate,
            Y2_START..=V2_END => &mut self.motion[i(Y2_START)],
            _ => return None,
        })
    }

    fn output(&mut self, vr: u32) -> Option<f64> {
        let numerical = !self.physical_role();
        let n = &self.numerical;
        let j = self.params.frame.floor - 1;
        Some(match vr {
            Y1 => n.y[0],
            V1 => n.v[0],
            Y2 => n.y[j],
            V2 => n.v[j],
            MEASURED_FORCE | Y3 | V3 | RELATIVE | A2 if numerical => 0.0,
            MEASURED_FORCE => {
                let p = self.end_of_motion();
                let a2 = self.imposed().acceleration_at_end();
                self.params.frame.interface_force(
                    self.split(),
                    self.motion[2],
                    self.motion[3],
                    a2,
                    &p,
                )
            }
            A2 => self.imposed().acceleration_at_end(),
            Y3 => self.end_of_motion().y[0],
            V3 => self.end_of_motion().v[0],
            RELATIVE => self.motion[2] - self.end_of_motion().y[0],
            _ => return None,
        })
    }
}

impl CoSimModel for SubstructureModel {
    fn info() -> &'static ModelInfo {
        vars::info()
    }

    fn instantiate(_context: &InstantiateContext) -> Result<Self, ModelError> {
        let params = Parameters::default();
        Ok(SubstructureModel {
            numerical: Numerical::at_rest(&params.frame),
            physical: Physical::at_rest(&params.frame),
            params,
            force: RampInput::default(),
            interface_force: 0.0,
            interface_force_rate: 0.0,
            motion: [0.0; 4],
            preview: None,
        })
    }

    fn get_real(&mut self, vr: u32) -> Result<f64, ModelError> {
        if let Some(x) = self.output(vr) {
            return Ok(x);
        }
        self.real_slot(vr).map(|x| *x).ok_or(unknown(vr, "Real"))
    }

    fn set_real(&mut self, vr: u32, value: f64) -> Result<(), ModelError> {
        let slot = self.real_slot(vr).ok_or(unknown(vr, "Real"))?;
        *slot = value;
        self.preview = None;
        Ok(())
    }

    fn get_integer(&mut self, vr: u32) -> Result<i32, ModelError> {
        match vr {
            ROLE => Ok(self.params.role),
            SUBSTEPS => Ok(self.params.substeps),
            _ => Err(unknown(vr, "Integer")),
        }
    }

    fn set_integer(&mut self, vr: u32, value: i32) -> Result<(), ModelError> {
        match vr {
            ROLE => {
                if !(ROLE_NUMERICAL..=ROLE_PHYSICAL_FLOORS_2_3).contains(&value) {
                    return Err(invalid("role", role_reason(value)));
                }
                self.params.role = value;
            }
            SUBSTEPS => self.params.substeps = value,
            _ => return Err(unknown(vr, "Integer")),
        }
        self.preview = None;
        Ok(())
    }

    /// `force` is interpolated; the other inputs are held over a step (the interface force's
    /// slope is the input `interface_force_rate`), so only a zero slope is accepted for them.
    fn set_real_input_derivative(&mut self, vr: u32, derivative: f64) -> Result<(), ModelError> {
        match vr {
            vars::FORCE => {
                self.force.slope = derivative;
                Ok(())
            }
            INTERFACE_FORCE | INTERFACE_FORCE_RATE | Y2_START..=V2_END => {
                if derivative == 0.0 {
                    Ok(())
                } else {
                    Err(ModelError::InvalidValue {
                        name: format!("the derivative of input vr {vr}"),
                        reason: format!(
                            "{derivative}: only `force` is interpolated; the interface force's \
                             slope is the input interface_force_rate, and the imposed motion is \
                             the Hermite through y2_start, v2_start, y2_end, v2_end"
                        ),
                    })
                }
            }
            _ => Err(unknown(vr, "Real input")),
        }
    }

    fn exit_initialization(&mut self) -> Result<(), ModelError> {
        self.params.check()?;
        self.preview = None;
        Ok(())
    }

    fn do_step(&mut self, time: f64, step_size: f64) -> Result<(), ModelError> {
        let f = self.params.frame.clone();
        let n = self.params.substeps();
        if self.physical_role() {
            let dt = self.params.control_step;
            if (step_size - dt).abs() > STEP_TOLERANCE * dt {
                return Err(ModelError::InvalidValue {
                    name: "communicationStepSize".into(),
                    reason: format!(
                        "{step_size} s at t = {time} s, but the imposed motion lasts \
                         control_step = {dt} s: step by exactly that"
                    ),
                });
            }
            let end = self.end_of_motion();
            if !end.y.iter().chain(&end.v).all(|x| x.is_finite()) {
                return Err(ModelError::Diverged {
                    time: time + step_size,
                    what: format!(
                        "floors {}-{}'s state is {:?}, {:?}",
                        f.floor + 1,
                        f.storeys(),
                        end.y,
                        end.v
                    ),
                });
            }
            self.physical = end;
        } else {
            let hs = step_size / f64::from(n);
            let (u, du) = (self.force.value, self.force.slope);
            let (fm, rate) = (self.interface_force, self.interface_force_rate);
            let mut next = self.numerical.clone();
            for j in 0..n {
                let tau0 = f64::from(j) * hs;
                next.step(&f, hs, (u + du * tau0, du), (fm + rate * tau0, rate));
            }
            if !next.y.iter().chain(&next.v).all(|x| x.is_finite()) {
                return Err(ModelError::Diverged {
                    time: time + step_size,
                    what: format!(
                        "floors 1-{}'s displacements {:?} and velocities {:?}",
                        f.floor, next.y, next.v
                    ),
                });
            }
            self.numerical = next;
            // The input at the step's end, and held from there unless a new slope comes.
            self.force = RampInput {
                value: u + du * step_size,
                slope: 0.0,
            };
        }
        self.preview = None;
        Ok(())
    }
}
