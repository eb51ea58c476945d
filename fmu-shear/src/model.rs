//! The N-storey shear model of eq. (1) with a control force and the effect library.

use crate::integrate;
use fmi2::{CoSimModel, InstantiateContext, ModelError, ModelInfo, VarType};
use serde::{Deserialize, Serialize};
use smallvec::SmallVec;
use structure::{Excitation, Structure};

use crate::effects::Effects;
use crate::linear::{LinearStepMap, StepInputs};
use crate::variables::*;

/// RK4 sub-steps per communication step: the fewest that keep the integration error (worst-floor
/// NMSE of the accelerations against 1024 sub-steps, 20 s at 51.2 Hz, 1–3 N random force, the
/// paper's prior parameters) under 1e-4 %, far below the sensor noise, for the linear model
/// (8 would do: 5.9e-5 %) and with the 0.5 mm bumper between floors 2 and 3 closing in half the
/// samples (32 give 2.4e-4 %, 64 give 7.1e-7 %). The figures: `tests/convergence.rs`, run with
/// `--nocapture`. The linear model's cost per step does not depend on it (`integrate`).
pub const DEFAULT_SUBSTEPS: u32 = 64;

/// The linear structure: masses of floors 1..N, damping and stiffness of storeys 1..N, what
/// excites it and where the control force acts.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct ShearParameters {
    pub mass: Vec<f64>,
    pub damping: Vec<f64>,
    pub stiffness: Vec<f64>,
    pub substeps: u32,
    /// A force at a floor (the input `force`, N) or ground acceleration (`ground_acc`, m/s²).
    #[serde(default, with = "excitation_code")]
    pub excitation: Excitation,
    /// The floor (1-based) the control force `control_force` acts on, against the excitation.
    #[serde(default = "first_floor")]
    pub control_floor: usize,
}

fn first_floor() -> usize {
    1
}

/// The excitation in the FMU state as a number (0 ground acceleration, K a force at floor K):
/// the serialized state is postcard, which cannot read [`Excitation`]'s tagged form.
mod excitation_code {
    use serde::{Deserialize, Deserializer, Serializer};
    use structure::Excitation;

    pub fn serialize<S: Serializer>(e: &Excitation, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_u64(match e {
            Excitation::Force { floor } => *floor as u64,
            Excitation::Base => 0,
        })
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Excitation, D::Error> {
        Ok(match u64::deserialize(d)? {
            0 => Excitation::Base,
            floor => Excitation::Force {
                floor: floor as usize,
            },
        })
    }
}

impl Default for ShearParameters {
    /// The reference paper's rig at its prior means (Table 1): [`Structure::default`].
    fn default() -> Self {
        ShearParameters::from_structure(&Structure::default())
    }
}

impl ShearParameters {
    /// The structure's values, the default sub-steps, the control force on floor 1.
    pub fn from_structure(structure: &Structure) -> Self {
        ShearParameters {
            mass: structure.mass.clone(),
            damping: structure.damping.clone(),
            stiffness: structure.stiffness.clone(),
            substeps: DEFAULT_SUBSTEPS,
            excitation: structure.excitation,
            control_floor: 1,
        }
    }

    pub fn storeys(&self) -> usize {
        self.mass.len()
    }

    /// How the model is laid out: its storeys, excitation and control floor.
    pub fn layout(&self) -> structure::paper::Layout {
        structure::paper::Layout {
            storeys: self.storeys(),
            excitation: self.excitation,
            control_floor: self.control_floor,
        }
    }

    /// The structure these parameters describe.
    pub fn structure(&self) -> Structure {
        Structure {
            mass: self.mass.clone(),
            damping: self.damping.clone(),
            stiffness: self.stiffness.clone(),
            excitation: self.excitation,
        }
    }
}

/// How a step with effects is integrated (the linear model always uses its step map).
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize, PartialEq, Eq)]
pub enum Integrator {
    /// Contacts alone: the exact flow of each contact region, the step split at the kinks
    /// (`piecewise_any`); any other effect: error-controlled Dormand–Prince 5(4) to
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
    /// Displacements and velocities of floors 1..N (relative to the ground).
    pub displacement: Vec<f64>,
    pub velocity: Vec<f64>,
    /// The excitation input: `force` (N) at the excited floor, or `ground_acc` (m/s²).
    pub force: RampInput,
    pub control_force: RampInput,
    /// The linear model's step as an affine map, cached for the current parameters and step.
    #[serde(skip)]
    pub step_map: Option<Box<LinearStepMap>>,
    /// How steps with effects are integrated.
    #[serde(default)]
    pub integrator: Integrator,
    /// The contact regions' flows (`piecewise_any`), cached for the current parameters and
    /// step.
    #[serde(skip)]
    pub contact_maps: Option<Box<crate::piecewise_any::AnyContactMaps>>,
    /// The error-controlled path's next trial step, carried between communication steps (part
    /// of the state, so that a restored state steps on exactly).
    #[serde(default)]
    pub adaptive_step: f64,
    /// The forward sensitivities of the linear model, when switched on (`sensitivity`).
    #[serde(default)]
    pub sensitivities: crate::sensitivity::Sensitivities,
    /// The parameters the instance started from (its structure and start values): they name
    /// its variable table, which a restored state must share.
    #[serde(default)]
    origin: Option<ShearParameters>,
    /// That table (built at `instantiate`).
    #[serde(skip)]
    table: Option<&'static ModelInfo>,
    /// The start values `disp{i}_start`, then `vel{i}_start`, as set (empty: every one 0).
    #[serde(default)]
    start: Vec<f64>,
    /// The accelerations a host reads, computed once for a state and its inputs (see
    /// [`ReadAccelerations`]).
    #[serde(skip)]
    read: ReadAccelerations,
}

/// What the accelerometers read at the state and inputs they were computed for. A master reads
/// them after a step and again after it sets the next inputs, and the step checks them: one
/// evaluation of the equations of motion serves every read until the state, an input or a
/// parameter changes (on the rig's contact records the reads were a fifth of a run).
#[derive(Clone, Debug, Default)]
struct ReadAccelerations {
    /// The displacements, velocities, force and control force they were computed at.
    at: Vec<f64>,
    values: Vec<f64>,
    /// False once a parameter or an effect may have changed.
    valid: bool,
}

impl ReadAccelerations {
    fn holds(&self, model: &ShearModel) -> bool {
        let n = model.storeys();
        self.valid
            && self.at.len() == 2 * n + 2
            && self.at[..n] == model.displacement[..]
            && self.at[n..2 * n] == model.velocity[..]
            && self.at[2 * n].to_bits() == model.force.value.to_bits()
            && self.at[2 * n + 1].to_bits() == model.control_force.value.to_bits()
    }
}

/// Storeys up to which a step's state vectors live on the stack.
const STATES_ON_STACK: usize = 20;

impl ShearModel {
    /// A model of the structure `params` with the effects `effects`, the library laid out for
    /// its storeys (sites the structure lacks dropped, new ones off).
    pub fn new(params: ShearParameters, mut effects: Effects) -> Self {
        let n = params.storeys();
        effects.fit(n);
        ShearModel {
            params,
            effects,
            displacement: vec![0.0; n],
            velocity: vec![0.0; n],
            force: RampInput::default(),
            control_force: RampInput::default(),
            step_map: None,
            integrator: Integrator::default(),
            contact_maps: None,
            adaptive_step: 0.0,
            sensitivities: Default::default(),
            origin: None,
            table: None,
            read: ReadAccelerations::default(),
            start: Vec::new(),
        }
    }

    pub fn storeys(&self) -> usize {
        self.params.storeys()
    }

    /// `out` minus the effects' forces at `y`, `v` (`g`: `n` zeros to hold them).
    #[inline]
    fn subtract_effects(&self, y: &[f64], v: &[f64], g: &mut [f64], out: &mut [f64]) {
        let n = g.len();
        self.effects.add_forces(&y[..n], &v[..n], g);
        for (o, g) in out.iter_mut().zip(g.iter()) {
            *o -= g;
        }
    }

    /// The relative floor accelerations `ÿ` for a state, an excitation input and a control
    /// force, written to `out`: eq. (1) solved for ÿ. Under ground acceleration an
    /// accelerometer reads `ÿ + a_g` ([`ShearModel::absolute_acceleration`]).
    #[inline]
    pub fn accelerations_into(
        &self,
        y: &[f64],
        v: &[f64],
        excitation: f64,
        control: f64,
        out: &mut [f64],
    ) {
        let n = self.storeys();
        let p = &self.params;
        // Storey forces (positive = resisting a positive drift) of the linear springs and
        // dampers; floor i gets the load, minus its storey's force, plus the one above.
        let storey = |s: usize| {
            let (d, dv) = if s == 0 {
                (y[0], v[0])
            } else {
                (y[s] - y[s - 1], v[s] - v[s - 1])
            };
            p.stiffness[s] * d + p.damping[s] * dv
        };
        let mut below = storey(0);
        for i in 0..n {
            let load = match p.excitation {
                Excitation::Force { floor } if floor == i + 1 => excitation,
                _ => 0.0,
            };
            let load = if p.control_floor == i + 1 {
                load - control
            } else {
                load
            };
            let mut rhs = load - below;
            if i + 1 < n {
                let above = storey(i + 1);
                rhs += above;
                below = above;
            }
            out[i] = rhs;
        }
        if self.effects.any_enabled() {
            // The effects' forces in a buffer on the stack for the usual buildings (zeroing
            // one of MAX_STOREYS for three floors was a tenth of a nonlinear step's cost; a
            // buffer on the heap for twenty storeys, a tenth of a fit's time in malloc/free).
            const SMALL: usize = 16;
            const LARGE: usize = 64;
            if n <= SMALL {
                self.subtract_effects(y, v, &mut [0.0; SMALL][..n], out);
            } else if n <= LARGE {
                self.subtract_effects(y, v, &mut [0.0; LARGE][..n], out);
            } else {
                self.subtract_effects(y, v, &mut vec![0.0; n], out);
            }
        }
        for i in 0..n {
            out[i] /= p.mass[i];
        }
        if p.excitation == Excitation::Base {
            for a in out.iter_mut() {
                *a -= excitation;
            }
        }
    }

    /// Floor accelerations for a state and an excitation input, with no control force: eq. (1)
    /// solved for ÿ (relative to the ground). In the paper's layout the input is the net force
    /// on floor 1, `force − control_force`.
    pub fn acceleration(&self, y: &[f64], v: &[f64], input: f64) -> Vec<f64> {
        let mut out = vec![0.0; self.storeys()];
        self.accelerations_into(y, v, input, 0.0, &mut out);
        out
    }

    /// What accelerometers read at the current state and inputs: `ÿ`, plus the ground
    /// acceleration under base excitation.
    pub fn absolute_acceleration(&self) -> Vec<f64> {
        let mut out = vec![0.0; self.storeys()];
        self.absolute_acceleration_into(&mut out);
        out
    }

    fn absolute_acceleration_into(&self, out: &mut [f64]) {
        self.accelerations_into(
            &self.displacement,
            &self.velocity,
            self.force.value,
            self.control_force.value,
            out,
        );
        if self.params.excitation == Excitation::Base {
            for a in out.iter_mut() {
                *a += self.force.value;
            }
        }
    }

    /// [`ShearModel::absolute_acceleration`], computed once for a state and its inputs (see
    /// [`ReadAccelerations`]).
    fn read_accelerations(&mut self) -> &[f64] {
        if !self.read.holds(self) {
            let mut read = std::mem::take(&mut self.read);
            read.values.resize(self.storeys(), 0.0);
            self.absolute_acceleration_into(&mut read.values);
            read.at.clear();
            read.at.extend_from_slice(&self.displacement);
            read.at.extend_from_slice(&self.velocity);
            read.at.push(self.force.value);
            read.at.push(self.control_force.value);
            read.valid = true;
            self.read = read;
        }
        &self.read.values
    }

    fn step_inputs(&self) -> StepInputs {
        StepInputs {
            excitation: self.force.value,
            excitation_slope: self.force.slope,
            control: self.control_force.value,
            control_slope: self.control_force.slope,
        }
    }

    /// Advance the state from `t` to `t + h` with the inputs as ramps (see `integrate`).
    pub fn advance(&mut self, h: f64) {
        let n = self.storeys();
        // On the stack for the usual buildings: a step of the linear model allocates nothing.
        let mut x0: SmallVec<[f64; 2 * STATES_ON_STACK]> = SmallVec::with_capacity(2 * n);
        x0.extend_from_slice(&self.displacement);
        x0.extend_from_slice(&self.velocity);
        let p = &self.params;
        let rig = structure::paper::is_paper_rig(&p.layout());
        if self.effects.any_enabled() && rig {
            // The paper's layout: the net input on floor 1 and the state a fixed array, as its
            // effect paths always stepped it (their results to the bit); every other layout
            // steps small vectors and its two inputs apart.
            let (f0, fs) = (
                self.force.value - self.control_force.value,
                self.force.slope - self.control_force.slope,
            );
            let inputs = StepInputs {
                excitation: f0,
                excitation_slope: fs,
                control: 0.0,
                control_slope: 0.0,
            };
            let state: integrate::State = std::array::from_fn(|i| x0[i]);
            let x = self.advance_with_effects(&state, &inputs, h);
            self.displacement.copy_from_slice(&x[..3]);
            self.velocity.copy_from_slice(&x[3..]);
        } else if self.effects.any_enabled() {
            // Any other structure: the excitation and the control force each as its ramp.
            let inputs = self.step_inputs();
            let x = self.advance_with_effects(&x0, &inputs, h);
            self.displacement.copy_from_slice(&x[..n]);
            self.velocity.copy_from_slice(&x[n..]);
        } else {
            if !self
                .step_map
                .as_ref()
                .is_some_and(|m| m.fits(&self.params, h))
            {
                self.step_map = Some(Box::new(LinearStepMap::new(&self.params, h)));
            }
            let inputs = self.step_inputs();
            if let Some(map) = &self.step_map {
                if self.sensitivities.on {
                    self.sensitivities
                        .advance(&self.params, map, &x0, &inputs, h);
                }
                let mut x: SmallVec<[f64; 2 * STATES_ON_STACK]> = smallvec::smallvec![0.0; 2 * n];
                map.apply_into(&x0, &inputs, &mut x);
                self.displacement.copy_from_slice(&x[..n]);
                self.velocity.copy_from_slice(&x[n..]);
            }
        }
        // The input ends the step at its ramp's end value; the slope was for this step only
        // (a master that interpolates sets it again for the next one), so a host that goes on
        // setting values alone gets those values, not an old ramp extrapolated.
        for input in [&mut self.force, &mut self.control_force] {
            input.value += input.slope * h;
            input.slope = 0.0;
        }
    }

    /// A step with effects from `x0` (`[y, ẏ]`, a fixed array on the paper's rig, a vector
    /// otherwise). Contacts alone step exactly by `piecewise_any` (up to
    /// `piecewise_any::MAX_EXACT_CONTACTS` contacts); other effects,
    /// and more contacts, by the error-controlled path, split at their kinks.
    fn advance_with_effects<S: crate::piecewise_any::Buffer>(
        &mut self,
        x0: &S,
        inputs: &StepInputs,
        h: f64,
    ) -> S {
        use crate::piecewise_any::AnyContactMaps;
        if self.integrator == Integrator::FixedSubsteps {
            return integrate::rk4_with_events(self, x0, inputs, h, self.params.substeps);
        }
        let contacts_alone = AnyContactMaps::applies(self);
        if !contacts_alone && self.integrator == Integrator::ExactContactsElseFixed {
            return integrate::rk4_with_events(self, x0, inputs, h, self.params.substeps);
        }
        if contacts_alone {
            // Up to `piecewise_any`'s number of contacts.
            if let Some(x) = integrate::exact_contacts(self, x0, inputs, h) {
                return x;
            }
            // Not finite: the error-controlled path steps it and the host is told of the
            // divergence.
        }
        let mut step = self.adaptive_step;
        let x = integrate::dopri5_with_events(self, x0, inputs, h, &mut step);
        self.adaptive_step = step;
        x
    }

    /// Sensitivity output `d_acc{floor}_d_{parameter}` (NaN unless they are on).
    fn sensitivity_output(&mut self, floor: usize, parameter: usize) -> f64 {
        if !self.sensitivities.on {
            return f64::NAN;
        }
        let inputs = self.step_inputs();
        // A host reads the N × 3N outputs one by one: all are computed at the first read after a
        // step or an input change, the rest come from there.
        if let Some(value) = self
            .sensitivities
            .cached(&self.params, &inputs, floor, parameter)
        {
            return value;
        }
        let n = self.storeys();
        let mut x = Vec::with_capacity(2 * n);
        x.extend_from_slice(&self.displacement);
        x.extend_from_slice(&self.velocity);
        self.sensitivities
            .output(&self.params, &self.effects, &x, &inputs, floor, parameter)
    }

    /// The index (0-based) of a floor or storey in the block of value references from `first`.
    /// `disp{i}_start` (slots 0..N) and `vel{i}_start` (N..2N).
    /// Whether a run starts at rest (every `disp{i}_start`, `vel{i}_start` 0).
    pub fn starts_at_rest(&self) -> bool {
        self.start.iter().all(|&x| x == 0.0)
    }

    fn start_slot(&self, vr: u32) -> Option<usize> {
        let n = self.storeys();
        self.index_in(vr, DISP_START)
            .or_else(|| self.index_in(vr, VEL_START).map(|i| n + i))
    }

    /// A start value: the state the run starts from (set before it starts, as the model's
    /// parameters are).
    fn set_start(&mut self, slot: usize, name: &str, value: f64) -> Result<(), ModelError> {
        if !value.is_finite() {
            return Err(ModelError::InvalidValue {
                name: name.into(),
                reason: format!("{value} is not a finite number"),
            });
        }
        let n = self.storeys();
        self.start.resize(2 * n, 0.0);
        self.start[slot] = value;
        if slot < n {
            self.displacement[slot] = value;
        } else {
            self.velocity[slot - n] = value;
        }
        Ok(())
    }

    /// The floor whose acceleration `get_real(vr)` reads, exactly where it reads one.
    fn acceleration_slot(&self, vr: u32) -> Option<usize> {
        let other = sensitivity_index(vr, self.storeys()).is_some()
            || matches!(vr, FORCE | GROUND_ACC | CONTROL_FORCE);
        if other {
            return None;
        }
        self.index_in(vr, ACC)
    }

    fn index_in(&self, vr: u32, first: u32) -> Option<usize> {
        vr.checked_sub(first)
            .map(|i| i as usize)
            .filter(|&i| i < self.storeys())
    }

    /// An instance for the structure in `resources/structure.json` under the FMU's resources,
    /// or the paper's rig without one.
    pub fn from_resources(resource_dir: Option<&std::path::Path>) -> Result<Self, ModelError> {
        let params = match resource_dir.map(|d| d.join(STRUCTURE_RESOURCE)) {
            Some(path) if path.exists() => read_structure_resource(&path)?,
            _ => ShearParameters::default(),
        };
        Ok(ShearModel::for_parameters(params))
    }

    /// An instance for `params` with every effect off, its variable table that of `params`'
    /// structure: what `fmi2Instantiate` makes of the structure's resource.
    pub fn for_parameters(params: ShearParameters) -> Self {
        let storeys = params.storeys();
        let mut model = ShearModel::new(params, Effects::new(storeys));
        model.table = Some(crate::variables::table(&model.params));
        model.origin = Some(model.params.clone());
        model
    }
}

/// The resource that says which structure an FMU models, under its `resources/`.
pub const STRUCTURE_RESOURCE: &str = "structure.json";

/// What `resources/structure.json` holds: a [`Structure`] (`mass`, `damping`, `stiffness`,
/// `excitation`) and, optionally, the control force's floor (1 when absent).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct StructureResource {
    #[serde(flatten)]
    pub structure: Structure,
    #[serde(default = "first_floor")]
    pub control_floor: usize,
}

impl StructureResource {
    /// The parameters, checked: a valid structure and a control floor it has.
    pub fn parameters(&self) -> Result<ShearParameters, String> {
        self.structure.validate().map_err(|e| e.to_string())?;
        let n = self.structure.storeys();
        if self.control_floor == 0 || self.control_floor > n {
            return Err(format!(
                "control_floor = {}: the structure has floors 1 to {n}",
                self.control_floor
            ));
        }
        let mut p = ShearParameters::from_structure(&self.structure);
        p.control_floor = self.control_floor;
        Ok(p)
    }
}

fn read_structure_resource(path: &std::path::Path) -> Result<ShearParameters, ModelError> {
    let fail = |why: String| ModelError::Other(format!("{}: {why}", path.display()));
    let text = std::fs::read_to_string(path).map_err(|e| fail(e.to_string()))?;
    let resource: StructureResource =
        serde_json::from_str(&text).map_err(|e| fail(e.to_string()))?;
    resource.parameters().map_err(fail)
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

    fn table(&self) -> &'static ModelInfo {
        self.table.unwrap_or_else(|| {
            crate::variables::table(self.origin.as_ref().unwrap_or(&self.params))
        })
    }

    fn instantiate(context: &InstantiateContext) -> Result<Self, ModelError> {
        ShearModel::from_resources(context.resource_dir.as_deref())
    }

    /// The structure read at `instantiate` (its parameters, as `origin` keeps them) without
    /// reading `resources/structure.json` again; every effect off, the state at rest.
    fn reset(&mut self, context: &InstantiateContext) -> Result<(), ModelError> {
        let Some(origin) = self.origin.take() else {
            *self = Self::instantiate(context)?;
            return Ok(());
        };
        let storeys = origin.storeys();
        let mut model = ShearModel::new(origin.clone(), Effects::new(storeys));
        model.table = self
            .table
            .or_else(|| Some(crate::variables::table(&origin)));
        model.origin = Some(origin);
        // The maps built so far go on: each is checked against the parameters before it is used
        // (`fits`), and a contact's regions whose system is unchanged keep their flows
        // (`adapt`). A calibration resets between simulations of one structure.
        model.step_map = self.step_map.take();
        model.contact_maps = self.contact_maps.take();
        *self = model;
        Ok(())
    }

    fn get_real(&mut self, vr: u32) -> Result<f64, ModelError> {
        // The sensitivities first: a calibration reads N × 3N of them per step.
        if let Some((floor, parameter)) = sensitivity_index(vr, self.storeys()) {
            return Ok(self.sensitivity_output(floor, parameter));
        }
        let value = match vr {
            FORCE if self.params.excitation != Excitation::Base => self.force.value,
            GROUND_ACC if self.params.excitation == Excitation::Base => self.force.value,
            CONTROL_FORCE => self.control_force.value,
            _ => {
                if let Some(i) = self.index_in(vr, ACC) {
                    self.read_accelerations()[i]
                } else if let Some(i) = self.index_in(vr, DISP) {
                    self.displacement[i]
                } else if let Some(i) = self.index_in(vr, VEL) {
                    self.velocity[i]
                } else if let Some(i) = self.index_in(vr, DRIFT) {
                    let y = &self.displacement;
                    if i == 0 {
                        y[0]
                    } else {
                        y[i] - y[i - 1]
                    }
                } else if let Some(i) = self.index_in(vr, MASS) {
                    self.params.mass[i]
                } else if let Some(i) = self.index_in(vr, DAMPING) {
                    self.params.damping[i]
                } else if let Some(i) = self.index_in(vr, STIFFNESS) {
                    self.params.stiffness[i]
                } else if let Some(i) = self.start_slot(vr) {
                    self.start.get(i).copied().unwrap_or(0.0)
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

    /// Every floor's acceleration comes from one evaluation of the equations of motion (the
    /// effects' forces included): computed, or checked against the state and inputs, once for
    /// the call, not once per floor (the check compares 2N + 2 values: reading 20 floors one
    /// by one cost 7.3M instructions in a 1,024-sample 20-storey run, the steps themselves 10M).
    fn get_reals(&mut self, vrs: &[u32], out: &mut [f64]) -> Result<(), ModelError> {
        let mut checked = false;
        for (slot, &vr) in out.iter_mut().zip(vrs) {
            *slot = match self.acceleration_slot(vr) {
                Some(i) => {
                    if !checked {
                        self.read_accelerations();
                        checked = true;
                    }
                    self.read.values[i]
                }
                None => self.get_real(vr)?,
            };
        }
        Ok(())
    }

    fn set_real(&mut self, vr: u32, value: f64) -> Result<(), ModelError> {
        // A parameter or an effect may change the accelerations at the same state and inputs
        // (the inputs themselves are part of what the reads are checked against).
        if !matches!(vr, FORCE | GROUND_ACC | CONTROL_FORCE) {
            self.read.valid = false;
        }
        let table = self.table();
        let name = || {
            table
                .find(VarType::Real, vr)
                .map(|v| v.name.clone())
                .unwrap_or_default()
        };
        match vr {
            FORCE if self.params.excitation != Excitation::Base => self.force.value = value,
            GROUND_ACC if self.params.excitation == Excitation::Base => self.force.value = value,
            CONTROL_FORCE => self.control_force.value = value,
            _ => {
                if let Some(i) = self.index_in(vr, MASS) {
                    self.params.mass[i] = positive(&name(), value, true)?;
                } else if let Some(i) = self.index_in(vr, DAMPING) {
                    self.params.damping[i] = positive(&name(), value, false)?;
                } else if let Some(i) = self.index_in(vr, STIFFNESS) {
                    self.params.stiffness[i] = positive(&name(), value, false)?;
                } else if let Some(i) = self.start_slot(vr) {
                    self.set_start(i, &name(), value)?;
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
        self.read.valid = false;
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
        self.read.valid = false;
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
            FORCE if self.params.excitation != Excitation::Base => self.force.slope = derivative,
            GROUND_ACC if self.params.excitation == Excitation::Base => {
                self.force.slope = derivative
            }
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
        let finite = self.read_accelerations().iter().all(|x| x.is_finite())
            && self
                .displacement
                .iter()
                .chain(&self.velocity)
                .all(|x| x.is_finite());
        if finite {
            Ok(())
        } else {
            Err(ModelError::Diverged {
                time: time + step_size,
                what: format!(
                    "non-finite displacement {:?}, velocity {:?} or acceleration {:?}; check the parameters and the substeps",
                    self.displacement, self.velocity, self.read.values
                ),
            })
        }
    }
}
