//! The structure in the loop: the twin's physics FMU (with whatever effects it has) driven by a
//! record's force, with or without the LQR block, through the master at the controller's rate.
//! An observer keeps the accelerations at the record's rate, the control effort, the gain
//! schedule's switches and the contact initiations (the drift of a storey with a contact crossing
//! its gap, open → closed), all online.

use numerics::lqr::{Controller, Estimator, Scheduler, StateSpace};
use structure::channel::{Channel, Quantity};
use structure::effects::{Kind, Law, Side};

use super::ControlError;
use crate::blocks::lqr::{trigger_code, LqrBlock, Scheduled, SensorNoise};
use crate::cosim::master::{Clock, NodeId, Observer, Port, Recording};
use crate::twin::data::Measurement;
use crate::twin::system::{SystemBuilder, SystemError, TwinSystem};
use crate::twin::{ParameterValue, Twin, TwinError, PHYSICS};
use crate::workflows::train::CORRECTOR;

/// A gap watched for contact: the storey (1-based: storey 3 joins floors 2 and 3) and its law.
#[derive(Clone, Debug)]
pub struct Gap {
    pub storey: usize,
    pub law: Law,
}

impl Gap {
    pub fn gap(&self) -> f64 {
        match &self.law {
            Law::Contact(c) => c.gap,
            _ => f64::NAN,
        }
    }

    pub fn side(&self) -> i32 {
        match &self.law {
            Law::Contact(c) => c.side,
            _ => 0,
        }
    }

    /// "2-3" for storey 3.
    pub fn label(&self) -> String {
        format!("{}-{}", self.storey - 1, self.storey)
    }
}

/// The contacts the twin's physics has switched on.
pub fn twin_gaps(twin: &Twin) -> Vec<Gap> {
    let Some(physics) = twin.component(PHYSICS) else {
        return Vec::new();
    };
    // A twin whose structure does not read has no gaps here; run_control reports why.
    let floors = super::design::structure_of(twin).map_or(0, |s| s.storeys());
    let kind = Kind::Contact;
    let mut gaps = Vec::new();
    for location in 0..kind.sites(floors) {
        let prefix = kind.prefix(location);
        let on = matches!(
            physics.parameters.get(&format!("{prefix}_enabled")),
            Some(ParameterValue::Boolean(true))
        );
        if !on {
            continue;
        }
        let reals: Vec<f64> = kind
            .real_params()
            .iter()
            .map(
                |p| match physics.parameters.get(&format!("{prefix}_{}", p.suffix)) {
                    Some(ParameterValue::Real(x)) => *x,
                    _ => p.start,
                },
            )
            .collect();
        let side = match physics.parameters.get(&format!("{prefix}_side")) {
            Some(ParameterValue::Integer(i)) => Side::from_code(*i).unwrap_or(Side::Both),
            _ => Side::Both,
        };
        if let Some(law) = Law::new(kind, &reals, side) {
            gaps.push(Gap {
                storey: location + 1,
                law,
            });
        }
    }
    gaps
}

/// Which gain the loop uses.
#[derive(Clone, Debug)]
pub enum Gains {
    Fixed(Vec<f64>),
    Scheduled {
        low: Vec<f64>,
        high: Vec<f64>,
        schedule: numerics::lqr::Schedule,
    },
}

/// How the controller knows the state.
#[derive(Clone, Debug)]
pub enum StateSource {
    /// From the measured accelerations (with sensor noise when given).
    Estimated(Estimator),
    /// The structure's true displacements and velocities: the design's own optimum, the
    /// reference an estimator's cost is measured against.
    Exact,
}

/// The controller in the loop.
#[derive(Clone, Debug)]
pub struct LoopLaw {
    pub gains: Gains,
    pub state: StateSource,
}

/// The loop's fixed settings.
#[derive(Clone, Debug)]
pub struct LoopSetup {
    pub plant: StateSpace,
    /// The channels the controller reads (the plant's measurements, in its order).
    pub measured: Vec<Channel>,
    /// Controller samples per record sample.
    pub substeps: usize,
    pub noise: Option<SensorNoise>,
    pub gaps: Vec<Gap>,
    /// A control force beyond this (N) stops the run as unstable.
    pub force_limit: f64,
    /// Run the twin's GP corrector beside the physics (at the record's rate) and hand its
    /// latent variances to the schedule.
    pub corrector: bool,
}

/// A contact initiation.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ContactEvent {
    pub time: f64,
    /// "2-3": the storey whose gap closed.
    pub storey: String,
}

/// What one run of the loop gives.
#[derive(Clone, Debug, Default)]
pub struct Response {
    /// At the record's rate.
    pub time: Vec<f64>,
    /// Per floor.
    pub acc: Vec<Vec<f64>>,
    pub control: Vec<f64>,
    pub control_rms: f64,
    pub control_peak: f64,
    pub contacts: Vec<ContactEvent>,
    /// (time, high gain on) at each switch of the schedule.
    pub switches: Vec<(f64, bool)>,
    /// Fraction of the time on the high gain.
    pub high_fraction: f64,
    /// Fractions of the time the schedule's drift and latent-variance triggers held.
    pub drift_trigger_fraction: f64,
    pub variance_trigger_fraction: f64,
}

/// The law on the structure's exact state: inputs as [`LqrBlock`]'s, then the displacements and
/// velocities (m, m/s).
struct ExactStateBlock {
    floors: usize,
    /// Where the latent variances start among the inputs.
    latent_at: usize,
    /// Where the state starts among the inputs.
    state_at: usize,
    latent: bool,
    gains: Gains,
    scheduler: Option<Scheduler>,
    scale: f64,
    force_limit: f64,
    /// The command computed at the last point (applied one sample late, as the estimated law).
    pending: f64,
    last_time: f64,
    acting: f64,
}

impl crate::cosim::master::Block for ExactStateBlock {
    fn evaluate(
        &mut self,
        time: f64,
        inputs: &[f64],
        outputs: &mut [f64],
    ) -> Result<(), crate::cosim::master::MasterError> {
        let w = &inputs[self.state_at..self.state_at + 2 * self.floors];
        let at = self.latent_at;
        let latent = self.latent.then(|| &inputs[at..at + self.floors]);
        let mut triggers = 0.0;
        let (gain, high) = match (&self.gains, &mut self.scheduler) {
            (Gains::Fixed(g), _) => (g, false),
            (Gains::Scheduled { low, high, .. }, Some(s)) => {
                let on = s.decide(time, w, latent);
                triggers = trigger_code(s.triggers());
                (if on { high } else { low }, on)
            }
            (Gains::Scheduled { low, .. }, None) => (low, false),
        };
        let u: f64 = gain
            .iter()
            .zip(w.iter())
            .map(|(g, x)| g * x / self.scale)
            .sum();
        if !u.is_finite() || u.abs() > self.force_limit {
            return Err(crate::cosim::master::MasterError::Config(format!(
                "closed loop unstable: the control force reached {u:.3e} N at t = {time} s"
            )));
        }
        if time != self.last_time {
            self.acting = self.pending;
            self.last_time = time;
        }
        self.pending = u;
        outputs[0] = self.acting;
        outputs[1] = f64::from(u8::from(high));
        outputs[2] = triggers;
        Ok(())
    }
}

struct LoopObserver {
    floors: usize,
    ports: Vec<Port>,
    substeps: usize,
    gaps: Vec<Gap>,
    closed: Vec<bool>,
    k: usize,
    response: Response,
    sum_sq: f64,
    points: usize,
    high_points: usize,
    drift_points: usize,
    variance_points: usize,
    high: bool,
}

impl Observer for LoopObserver {
    fn record(&mut self, time: f64, values: &[f64]) {
        // values: acc1..N, control force, high flag, triggers, then one drift per gap.
        let n = self.floors;
        let r = &mut self.response;
        if self.k.is_multiple_of(self.substeps) {
            r.time.push(time);
            for f in 0..n {
                r.acc[f].push(values[f]);
            }
            r.control.push(values[n]);
        }
        self.k += 1;
        let u = values[n];
        self.sum_sq += u * u;
        r.control_peak = r.control_peak.max(u.abs());
        self.points += 1;
        let high = values[n + 1] != 0.0;
        if high != self.high {
            r.switches.push((time, high));
            self.high = high;
        }
        self.high_points += usize::from(high);
        let triggers = values[n + 2] as u8;
        self.drift_points += usize::from(triggers & 1 != 0);
        self.variance_points += usize::from(triggers & 2 != 0);
        for (i, gap) in self.gaps.iter().enumerate() {
            let closed = gap.law.force_at(values[n + 3 + i]) != 0.0;
            if closed && !self.closed[i] {
                r.contacts.push(ContactEvent {
                    time,
                    storey: gap.label(),
                });
            }
            self.closed[i] = closed;
        }
    }

    fn ports(&self) -> &[Port] {
        &self.ports
    }

    fn will_record(&mut self, points: usize) {
        let n = points / self.substeps + 1;
        self.response.time.reserve(n);
        for a in &mut self.response.acc {
            a.reserve(n);
        }
        self.response.control.reserve(n);
    }
}

/// The record's force at the controller's rate: linear between the record's samples.
fn upsample(force: &[f64], substeps: usize) -> Vec<f64> {
    let mut out = Vec::with_capacity((force.len() - 1) * substeps + 1);
    for w in force.windows(2) {
        for j in 0..substeps {
            out.push(w[0] + (w[1] - w[0]) * j as f64 / substeps as f64);
        }
    }
    out.push(*force.last().expect("a record has samples"));
    out
}

/// The physics FMU's output (its index among `acc1..N, disp1..N, vel1..N`) a measured channel
/// reads.
fn output_of(channel: &Channel, floors: usize) -> Result<usize, ControlError> {
    match channel {
        Channel::Response { quantity, floor } if (1..=floors).contains(floor) => {
            let block = match quantity {
                Quantity::Acceleration => 0,
                Quantity::Displacement => 1,
                Quantity::Velocity => 2,
                _ => {
                    return Err(ControlError::Options(format!(
                        "the controller cannot read '{}'",
                        channel.name()
                    )))
                }
            };
            Ok(block * floors + floor - 1)
        }
        _ => Err(ControlError::Options(format!(
            "the controller cannot read '{}': the structure has floors 1 to {floors}",
            channel.name()
        ))),
    }
}

/// Run the twin's physics on `data`'s excitation, passive (`law` None) or under `law`.
pub fn simulate(
    twin: &Twin,
    data: &Measurement,
    setup: &LoopSetup,
    law: Option<&LoopLaw>,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<Response, ControlError> {
    let grid = LoopGrid::of(data, setup)?;
    let builder = SystemBuilder::open(twin)?;
    if builder.fmu(PHYSICS).is_none() {
        return Err(ControlError::Twin(format!(
            "{} has no '{PHYSICS}' component",
            twin.describe()
        )));
    }
    let mut running = builder.empty();
    let physics = add_physics(&builder, &mut running, data, setup, &grid)?;
    let latent = add_corrector(&builder, &mut running, twin, setup, physics, &grid)?;
    let controller = match law {
        None => None,
        Some(law) => Some(add_controller(
            &mut running,
            setup,
            law,
            physics,
            latent,
            &grid,
        )?),
    };
    let mut observer = LoopObserver::new(&mut running, data, setup, physics, controller, &grid);
    run_loop(running, &mut observer, data, &grid, progress)?;
    Ok(observer.finish())
}

/// The loop's sizes and times: controller samples per record sample, the controller's step,
/// the record's first time, the floors and the channels the controller reads.
struct LoopGrid {
    substeps: usize,
    dt: f64,
    start: f64,
    floors: usize,
    measured: usize,
}

impl LoopGrid {
    /// The grid of `setup` on `data`; refused when the controller reads other channels than
    /// its model measures.
    fn of(data: &Measurement, setup: &LoopSetup) -> Result<LoopGrid, ControlError> {
        let substeps = setup.substeps.max(1);
        let floors = setup.plant.floors();
        let measured = setup.measured.len();
        if measured != setup.plant.c.nrows() {
            return Err(ControlError::Options(format!(
                "the controller reads {} channels but its model measures {}",
                measured,
                setup.plant.c.nrows()
            )));
        }
        Ok(LoopGrid {
            substeps,
            dt: data.dt / substeps as f64,
            start: data.time[0],
            floors,
            measured,
        })
    }
}

/// The physics in the system: its node (outputs `acc1..N, disp1..N, vel1..N`, then one drift
/// per gap; inputs the excitation and the control force) and the excitation's signal.
#[derive(Clone, Copy)]
struct PhysicsNode {
    node: NodeId,
    force: Port,
}

/// Add the physics FMU, driven by the record's excitation at the controller's rate (linear
/// between the record's samples), and set the system to record as the sensors read.
fn add_physics(
    builder: &SystemBuilder,
    running: &mut TwinSystem,
    data: &Measurement,
    setup: &LoopSetup,
    grid: &LoopGrid,
) -> Result<PhysicsNode, ControlError> {
    let floors = grid.floors;
    // Observed as the sensors read the structure: at each point before the controller's new
    // force acts (floor 1's acceleration jumps with it), which is what a record holds.
    running.system.recording = Recording::BeforeInputs;
    let mut outputs = Vec::new();
    for prefix in ["acc", "disp", "vel"] {
        for f in 1..=floors {
            outputs.push(format!("{prefix}{f}"));
        }
    }
    for gap in &setup.gaps {
        outputs.push(format!("drift{}", gap.storey));
    }
    let excitation = data.excitation.channel.name();
    let plant = builder
        .add_component(
            running,
            PHYSICS,
            grid.start,
            vec![excitation.clone(), "control_force".into()],
            outputs,
            None,
        )
        .map_err(system_error)?;
    let force = running.system.add_signal(
        &excitation,
        upsample(&data.excitation.values, grid.substeps),
    );
    running.system.connect(force, plant, 0)?;
    Ok(PhysicsNode { node: plant, force })
}

/// With `setup.corrector`, add the twin's GP corrector beside the physics, reading the physics'
/// accelerations and the force; refused when the twin has none. Returns its node.
fn add_corrector(
    builder: &SystemBuilder,
    running: &mut TwinSystem,
    twin: &Twin,
    setup: &LoopSetup,
    physics: PhysicsNode,
    grid: &LoopGrid,
) -> Result<Option<NodeId>, ControlError> {
    let floors = grid.floors;
    // The corrector keeps the record's rate (its lags are the record's samples).
    Ok(match builder.fmu(CORRECTOR) {
        Some(_) if setup.corrector => {
            let mut inputs: Vec<String> = (1..=floors).map(|f| format!("physics_acc{f}")).collect();
            inputs.push("force".into());
            let outputs = (1..=floors).map(|f| format!("latent_var{f}")).collect();
            let node = builder
                .add_component(
                    running,
                    CORRECTOR,
                    grid.start,
                    inputs,
                    outputs,
                    Some(grid.substeps),
                )
                .map_err(system_error)?;
            for f in 0..floors {
                running
                    .system
                    .connect(Port::Output(physics.node, f), node, f)?;
            }
            running.system.connect(physics.force, node, floors)?;
            Some(node)
        }
        None if setup.corrector => {
            return Err(ControlError::Options(format!(
                "{} has no corrector: the schedule cannot use a latent variance (train one with \
                 `twin train`, or leave the variance threshold out)",
                twin.describe()
            )))
        }
        _ => None,
    })
}

/// Add the controller's block: its inputs are the measured channels (sampled), the force, the
/// corrector's latent variances (when it runs) and, on the exact state, the structure's
/// displacements and velocities; its force drives the physics. Returns its node.
fn add_controller(
    running: &mut TwinSystem,
    setup: &LoopSetup,
    law: &LoopLaw,
    physics: PhysicsNode,
    latent: Option<NodeId>,
    grid: &LoopGrid,
) -> Result<NodeId, ControlError> {
    let (floors, measured) = (grid.floors, grid.measured);
    let (plant, force) = (physics.node, physics.force);
    let block = controller_block(setup, law, latent.is_some(), grid)?;
    let exact = matches!(law.state, StateSource::Exact);
    let latent_inputs = if latent.is_some() { floors } else { 0 };
    let state_at = LqrBlock::inputs(measured) + latent_inputs;
    let n_inputs = state_at + if exact { 2 * floors } else { 0 };
    let node = running
        .system
        .add_block("lqr", block, n_inputs, LqrBlock::OUTPUTS);
    for (i, channel) in setup.measured.iter().enumerate() {
        running.system.connect_sampled(
            Port::Output(plant, output_of(channel, floors)?),
            node,
            i,
        )?;
    }
    running.system.connect(force, node, measured)?;
    if let Some(c) = latent {
        for f in 0..floors {
            running.system.connect_sampled(
                Port::Output(c, f),
                node,
                LqrBlock::inputs(measured) + f,
            )?;
        }
    }
    if exact {
        for s in 0..2 * floors {
            running
                .system
                .connect_sampled(Port::Output(plant, floors + s), node, state_at + s)?;
        }
    }
    running.system.connect(Port::Output(node, 0), plant, 1)?;
    Ok(node)
}

/// The block that computes the control force: the LQR block on the estimated state, or the
/// law on the structure's exact state; `latent` when the corrector's variances are among its
/// inputs.
fn controller_block(
    setup: &LoopSetup,
    law: &LoopLaw,
    latent: bool,
    grid: &LoopGrid,
) -> Result<Box<dyn crate::cosim::master::Block>, ControlError> {
    let (floors, measured) = (grid.floors, grid.measured);
    Ok(match &law.state {
        StateSource::Estimated(estimator) => {
            let (first, scheduled) = match &law.gains {
                Gains::Fixed(g) => (g, None),
                Gains::Scheduled {
                    low,
                    high,
                    schedule,
                } => (
                    low,
                    Some(Scheduled {
                        scheduler: Scheduler::new(schedule.clone(), floors)?,
                        low: low.clone(),
                        high: high.clone(),
                    }),
                ),
            };
            let controller = Controller::new(&setup.plant, first, estimator, grid.dt)?;
            Box::new(LqrBlock::new(
                controller,
                scheduled,
                setup.noise.clone(),
                setup.force_limit,
                latent.then_some(floors),
            ))
        }
        StateSource::Exact => {
            let scheduler = match &law.gains {
                Gains::Scheduled { schedule, .. } => {
                    Some(Scheduler::new(schedule.clone(), floors)?)
                }
                Gains::Fixed(_) => None,
            };
            Box::new(ExactStateBlock {
                floors,
                latent_at: LqrBlock::inputs(measured),
                state_at: LqrBlock::inputs(measured) + if latent { floors } else { 0 },
                latent,
                gains: law.gains.clone(),
                scheduler,
                scale: setup.plant.state_scale,
                force_limit: setup.force_limit,
                pending: 0.0,
                last_time: f64::NAN,
                acting: 0.0,
            })
        }
    })
}

impl LoopObserver {
    /// The observer of a run: the physics' accelerations, the controller's force, gain flag and
    /// triggers (passive: a signal of zeros, added here) and each gap's drift.
    fn new(
        running: &mut TwinSystem,
        data: &Measurement,
        setup: &LoopSetup,
        physics: PhysicsNode,
        controller: Option<NodeId>,
        grid: &LoopGrid,
    ) -> LoopObserver {
        let (floors, substeps, plant) = (grid.floors, grid.substeps, physics.node);
        // Passive: the control force stays at the FMU's own 0, and the observer reads zeros.
        let zero = running
            .system
            .add_signal("zero", vec![0.0; (data.len() - 1) * substeps + 1]);
        let mut ports: Vec<Port> = (0..floors).map(|f| Port::Output(plant, f)).collect();
        match controller {
            Some(node) => ports.extend([
                Port::Output(node, 0),
                Port::Output(node, 1),
                Port::Output(node, 2),
            ]),
            None => ports.extend([zero, zero, zero]),
        }
        for (i, _) in setup.gaps.iter().enumerate() {
            ports.push(Port::Output(plant, 3 * floors + i));
        }
        LoopObserver {
            floors,
            ports,
            substeps,
            gaps: setup.gaps.clone(),
            closed: vec![false; setup.gaps.len()],
            k: 0,
            response: Response {
                acc: vec![Vec::new(); floors],
                ..Response::default()
            },
            sum_sq: 0.0,
            points: 0,
            high_points: 0,
            drift_points: 0,
            variance_points: 0,
            high: false,
        }
    }

    /// The run's response, with the control force's RMS and the fractions of the time on the
    /// high gain and under each trigger.
    fn finish(self) -> Response {
        let mut response = self.response;
        let points = self.points.max(1) as f64;
        response.control_rms = (self.sum_sq / points).sqrt();
        response.high_fraction = self.high_points as f64 / points;
        response.drift_trigger_fraction = self.drift_points as f64 / points;
        response.variance_trigger_fraction = self.variance_points as f64 / points;
        response
    }
}

/// Run the system over the record at the controller's step, `observer` watching; a run the
/// control force stopped is unstable. The system is dropped at the end.
fn run_loop(
    mut running: TwinSystem,
    observer: &mut LoopObserver,
    data: &Measurement,
    grid: &LoopGrid,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<(), ControlError> {
    let steps = ((data.len() - 1) * grid.substeps) as u64;
    let clock = Clock::new(grid.start, grid.dt, steps);
    running
        .system
        .run(clock, &mut [observer], progress)
        .map_err(|e| {
            let text = e.to_string();
            if text.contains("closed loop unstable") {
                ControlError::Unstable(text)
            } else {
                ControlError::Master(e)
            }
        })?;
    Ok(())
}

/// A variable the FMU lacks is the twin's fault (as before the builder); an FMU that cannot be
/// opened or initialised is the twin file's.
fn system_error(e: SystemError) -> ControlError {
    match e {
        SystemError::Twin(TwinError::Import(e)) => ControlError::Twin(e.to_string()),
        SystemError::Twin(e) => ControlError::TwinFile(e),
        SystemError::Master(e) => ControlError::Master(e),
        SystemError::Wiring(message) => ControlError::Twin(message),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn upsampling_is_linear_and_keeps_the_samples() {
        let f = upsample(&[0.0, 4.0, 0.0], 4);
        assert_eq!(f, vec![0.0, 1.0, 2.0, 3.0, 4.0, 3.0, 2.0, 1.0, 0.0]);
    }
}
