//! The three-storey shear model of eq. (1) with a control force and the effect library.

use crate::integrate;
use fmi2::{CoSimModel, InstantiateContext, ModelError, ModelInfo, VarType};
use serde::{Deserialize, Serialize};

use crate::effects::{Effects, Floors};
use crate::variables::*;

/// RK4 sub-steps per communication step: the fewest that keep the integration error (worst-floor
/// NMSE of the accelerations against 1024 sub-steps, 20 s at 51.2 Hz, 1–3 N random force, the
/// paper's prior parameters) under 1e-4 %, far below the sensor noise, for the linear model
/// (8 would do: 5.9e-5 %) and with the 0.5 mm bumper between floors 2 and 3 closing in half the
/// samples (32 give 2.4e-4 %, 64 give 7.1e-7 %). The figures: `tests/convergence.rs`, run with
/// `--nocapture`. The linear model's cost per step does not depend on it (`integrate`).
pub const DEFAULT_SUBSTEPS: u32 = 64;

/// The linear structure: masses of floors 1..3, damping and stiffness of storeys 1..3.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct ShearParameters {
    pub mass: [f64; 3],
    pub damping: [f64; 3],
    pub stiffness: [f64; 3],
    pub substeps: u32,
}

impl Default for ShearParameters {
    /// The reference paper's prior means (Table 1).
    fn default() -> Self {
        ShearParameters {
            mass: [5.2; 3],
            damping: [(-4.605f64).exp(); 3],
            stiffness: [4021.0; 3],
            substeps: DEFAULT_SUBSTEPS,
        }
    }
}

/// How a step with effects is integrated (the linear model always uses its step map).
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize, PartialEq, Eq)]
pub enum Integrator {
    /// Contacts alone: the exact flow of each contact region, the step split at the kinks
    /// (`piecewise`); any other effect: error-controlled Dormand–Prince 5(4) to
    /// [`ADAPTIVE_TOLERANCE`], split at the kinks.
    #[default]
    Exact,
    /// RK4 with `substeps` fixed sub-steps, split at the kinks (the integrator before the exact
    /// and error-controlled paths, kept for comparison).
    FixedSubsteps,
    /// Contacts alone as [`Integrator::Exact`]; any other effect RK4 with `substeps` fixed
    /// sub-steps, split at the kinks: the cheap setting for the many simulations of a fit, whose
    /// result is then scored with [`Integrator::Exact`].
    ExactContactsElseFixed,
}

/// The relative local error per step of the error-controlled path (per displacement and
/// velocity, against the largest of each over the step). Chosen so that its error against a
/// fine reference is below that of 64 fixed RK4 sub-steps (`tests/effects_accuracy.rs`).
pub const ADAPTIVE_TOLERANCE: f64 = 1e-10;

/// An input held as `value + slope·(t − t_set)` inside a step (first-order interpolation).
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct RampInput {
    pub value: f64,
    pub slope: f64,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ShearModel {
    pub params: ShearParameters,
    pub effects: Effects,
    /// Displacements and velocities of floors 1..3 (relative to the ground).
    pub displacement: Floors,
    pub velocity: Floors,
    pub force: RampInput,
    pub control_force: RampInput,
    /// The linear model's step as an affine map, cached for the current parameters and step.
    #[serde(skip)]
    pub step_map: Option<Box<integrate::LinearStepMap>>,
    /// How steps with effects are integrated.
    #[serde(default)]
    pub integrator: Integrator,
    /// The contact regions' flows, cached for the current parameters and step.
    #[serde(skip)]
    pub contact_maps: Option<Box<crate::piecewise::ContactMaps>>,
    /// The error-controlled path's next trial step, carried between communication steps (part
    /// of the state, so that a restored state steps on exactly).
    #[serde(default)]
    pub adaptive_step: f64,
    /// The forward sensitivities of the linear model, when switched on (`sensitivity`).
    #[serde(default)]
    pub sensitivities: crate::sensitivity::Sensitivities,
}

impl ShearModel {
    pub fn new(params: ShearParameters, effects: Effects) -> Self {
        ShearModel {
            params,
            effects,
            displacement: [0.0; 3],
            velocity: [0.0; 3],
            force: RampInput::default(),
            control_force: RampInput::default(),
            step_map: None,
            integrator: Integrator::default(),
            contact_maps: None,
            adaptive_step: 0.0,
            sensitivities: Default::default(),
        }
    }

    /// Floor accelerations for a state and a net input force on floor 1: eq. (1) solved for ÿ.
    #[inline]
    pub fn acceleration(&self, y: &Floors, v: &Floors, input: f64) -> Floors {
        let ShearParameters {
            mass: m,
            damping: c,
            stiffness: k,
            ..
        } = &self.params;
        // Storey forces (positive = resisting a positive drift) of the linear springs and dampers.
        let d = [y[0], y[1] - y[0], y[2] - y[1]];
        let dv = [v[0], v[1] - v[0], v[2] - v[1]];
        let s = [
            k[0] * d[0] + c[0] * dv[0],
            k[1] * d[1] + c[1] * dv[1],
            k[2] * d[2] + c[2] * dv[2],
        ];
        let mut rhs = [input - s[0] + s[1], s[2] - s[1], -s[2]];
        if self.effects.any_enabled() {
            let g = self.effects.force(y, v);
            for i in 0..3 {
                rhs[i] -= g[i];
            }
        }
        [rhs[0] / m[0], rhs[1] / m[1], rhs[2] / m[2]]
    }

    /// Advance the state from `t` to `t + h` with the inputs as ramps (see `integrate`).
    pub fn advance(&mut self, h: f64) {
        let (f0, fs) = (
            self.force.value - self.control_force.value,
            self.force.slope - self.control_force.slope,
        );
        let y = &self.displacement;
        let v = &self.velocity;
        let x0 = [y[0], y[1], y[2], v[0], v[1], v[2]];
        let x = if self.effects.any_enabled() {
            self.advance_with_effects(&x0, f0, fs, h)
        } else {
            if !self
                .step_map
                .as_ref()
                .is_some_and(|m| m.fits(&self.params, h))
            {
                self.step_map = Some(Box::new(integrate::LinearStepMap::new(self, h)));
            }
            match &self.step_map {
                Some(map) => {
                    if self.sensitivities.on {
                        self.sensitivities
                            .advance(&self.params, map, &x0, f0, fs, h);
                    }
                    map.apply(&x0, f0, fs)
                }
                None => x0,
            }
        };
        self.displacement = [x[0], x[1], x[2]];
        self.velocity = [x[3], x[4], x[5]];
        // The input ends the step at its ramp's end value; the slope was for this step only
        // (a master that interpolates sets it again for the next one), so a host that goes on
        // setting values alone gets those values, not an old ramp extrapolated.
        for input in [&mut self.force, &mut self.control_force] {
            input.value += input.slope * h;
            input.slope = 0.0;
        }
    }

    fn advance_with_effects(
        &mut self,
        x0: &integrate::State,
        u0: f64,
        slope: f64,
        h: f64,
    ) -> integrate::State {
        use crate::piecewise::ContactMaps;
        if self.integrator == Integrator::FixedSubsteps {
            return integrate::rk4_with_events(self, x0, u0, slope, h, self.params.substeps);
        }
        let contacts_alone = ContactMaps::applies(self);
        if !contacts_alone && self.integrator == Integrator::ExactContactsElseFixed {
            return integrate::rk4_with_events(self, x0, u0, slope, h, self.params.substeps);
        }
        if contacts_alone {
            if !self.contact_maps.as_ref().is_some_and(|m| m.fits(self, h)) {
                self.contact_maps = Some(Box::new(ContactMaps::new(self, h)));
            }
            if let Some(maps) = self.contact_maps.as_mut() {
                if let Ok(x) = maps.advance(x0, u0, slope) {
                    return x;
                }
            }
            // Not finite: the error-controlled path steps it and the host is told of the
            // divergence.
        }
        let mut step = self.adaptive_step;
        let x = integrate::dopri5_with_events(self, x0, u0, slope, h, &mut step);
        self.adaptive_step = step;
        x
    }

    /// Sensitivity output `k` (NaN unless they are on).
    fn sensitivity_output(&mut self, k: usize) -> f64 {
        if !self.sensitivities.on {
            return f64::NAN;
        }
        let (y, v) = (&self.displacement, &self.velocity);
        let x = [y[0], y[1], y[2], v[0], v[1], v[2]];
        let u = self.net_input();
        self.sensitivities
            .output(&self.params, &self.effects, &x, u, k)
    }

    fn net_input(&self) -> f64 {
        self.force.value - self.control_force.value
    }

    fn floor_index(vr: u32, first: u32) -> Option<usize> {
        vr.checked_sub(first).map(|i| i as usize).filter(|&i| i < 3)
    }
}

fn positive(name: &str, value: f64, strictly: bool) -> Result<f64, ModelError> {
    let ok = if strictly { value > 0.0 } else { value >= 0.0 };
    if ok {
        Ok(value)
    } else {
        Err(ModelError::InvalidValue {
            name: name.to_owned(),
            reason: format!("{value} must be {} 0", if strictly { ">" } else { "≥" }),
        })
    }
}

impl CoSimModel for ShearModel {
    fn info() -> &'static ModelInfo {
        info()
    }

    fn instantiate(_context: &InstantiateContext) -> Result<Self, ModelError> {
        Ok(ShearModel::new(
            ShearParameters::default(),
            Effects::default(),
        ))
    }

    fn get_real(&mut self, vr: u32) -> Result<f64, ModelError> {
        // The sensitivities first: a calibration reads 27 of them per step.
        if let Some(k) = vr.checked_sub(SENSITIVITY).filter(|&k| k < 27) {
            return Ok(self.sensitivity_output(k as usize));
        }
        let (y, v) = (self.displacement, self.velocity);
        let value = match vr {
            FORCE => self.force.value,
            CONTROL_FORCE => self.control_force.value,
            _ => {
                if let Some(i) = Self::floor_index(vr, ACC) {
                    self.acceleration(&y, &v, self.net_input())[i]
                } else if let Some(i) = Self::floor_index(vr, DISP) {
                    y[i]
                } else if let Some(i) = Self::floor_index(vr, VEL) {
                    v[i]
                } else if let Some(i) = Self::floor_index(vr, DRIFT) {
                    crate::effects::drift(&y, i)
                } else if let Some(i) = Self::floor_index(vr, MASS) {
                    self.params.mass[i]
                } else if let Some(i) = Self::floor_index(vr, DAMPING) {
                    self.params.damping[i]
                } else if let Some(i) = Self::floor_index(vr, STIFFNESS) {
                    self.params.stiffness[i]
                } else {
                    return self
                        .effects
                        .get_real(vr)
                        .ok_or(ModelError::UnknownVariable { vr, kind: "Real" });
                }
            }
        };
        Ok(value)
    }

    fn set_real(&mut self, vr: u32, value: f64) -> Result<(), ModelError> {
        let name = || {
            info()
                .find(VarType::Real, vr)
                .map(|v| v.name.clone())
                .unwrap_or_default()
        };
        match vr {
            FORCE => self.force.value = value,
            CONTROL_FORCE => self.control_force.value = value,
            _ => {
                if let Some(i) = Self::floor_index(vr, MASS) {
                    self.params.mass[i] = positive(&name(), value, true)?;
                } else if let Some(i) = Self::floor_index(vr, DAMPING) {
                    self.params.damping[i] = positive(&name(), value, false)?;
                } else if let Some(i) = Self::floor_index(vr, STIFFNESS) {
                    self.params.stiffness[i] = positive(&name(), value, false)?;
                } else {
                    return self
                        .effects
                        .set_real(vr, value)
                        .unwrap_or(Err(ModelError::UnknownVariable { vr, kind: "Real" }));
                }
            }
        }
        Ok(())
    }

    fn get_integer(&mut self, vr: u32) -> Result<i32, ModelError> {
        if vr == SUBSTEPS {
            return Ok(self.params.substeps as i32);
        }
        if vr == INTEGRATOR {
            return Ok(match self.integrator {
                Integrator::Exact => 0,
                Integrator::FixedSubsteps => 1,
                Integrator::ExactContactsElseFixed => 2,
            });
        }
        self.effects
            .get_integer(vr)
            .ok_or(ModelError::UnknownVariable {
                vr,
                kind: "Integer",
            })
    }

    fn set_integer(&mut self, vr: u32, value: i32) -> Result<(), ModelError> {
        if vr == SUBSTEPS {
            if !(1..=10000).contains(&value) {
                return Err(ModelError::InvalidValue {
                    name: "substeps".into(),
                    reason: format!("{value} is outside [1, 10000]"),
                });
            }
            self.params.substeps = value as u32;
            return Ok(());
        }
        if vr == INTEGRATOR {
            self.integrator = match value {
                0 => Integrator::Exact,
                1 => Integrator::FixedSubsteps,
                2 => Integrator::ExactContactsElseFixed,
                _ => {
                    return Err(ModelError::InvalidValue {
                        name: "integrator".into(),
                        reason: format!(
                            "{value} is none of 0 (exact), 1 (fixed sub-steps), 2 (exact for \
                             contacts alone, fixed sub-steps otherwise)"
                        ),
                    })
                }
            };
            return Ok(());
        }
        self.effects
            .set_integer(vr, value)
            .unwrap_or(Err(ModelError::UnknownVariable {
                vr,
                kind: "Integer",
            }))
    }

    fn get_boolean(&mut self, vr: u32) -> Result<bool, ModelError> {
        if vr == SENSITIVITIES {
            return Ok(self.sensitivities.on);
        }
        self.effects
            .get_boolean(vr)
            .ok_or(ModelError::UnknownVariable {
                vr,
                kind: "Boolean",
            })
    }

    fn set_boolean(&mut self, vr: u32, value: bool) -> Result<(), ModelError> {
        if vr == SENSITIVITIES {
            self.sensitivities.on = value;
            return Ok(());
        }
        self.effects
            .set_boolean(vr, value)
            .ok_or(ModelError::UnknownVariable {
                vr,
                kind: "Boolean",
            })
    }

    fn set_real_input_derivative(&mut self, vr: u32, derivative: f64) -> Result<(), ModelError> {
        match vr {
            FORCE => self.force.slope = derivative,
            CONTROL_FORCE => self.control_force.slope = derivative,
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
        self.advance(step_size);
        // Accelerations overflow a step before the state does; check what the host will read.
        let acc = self.acceleration(&self.displacement, &self.velocity, self.net_input());
        let finite = self
            .displacement
            .iter()
            .chain(&self.velocity)
            .chain(&acc)
            .all(|x| x.is_finite());
        if finite {
            Ok(())
        } else {
            Err(ModelError::Diverged {
                time: time + step_size,
                what: format!(
                    "non-finite displacement {:?}, velocity {:?} or acceleration {:?}; check the parameters and the substeps",
                    self.displacement, self.velocity, acc
                ),
            })
        }
    }
}
