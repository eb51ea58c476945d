//! The simulated real-time hybrid test's interface as zero-time blocks of the master, between
//! the two `fmu_substructure` instances (see `workflows::hybrid::fmus`):
//!
//! * [`ActuatorBlock`]: floor 2's new displacement on the numerical side → the actuator → the
//!   motion imposed on the physical side over the control step (the cubic Hermite from the last
//!   achieved position and rate to the new ones, the new rate from the last three positions:
//!   only displacements cross the interface);
//! * [`InterfaceBlock`]: the measured force → floor 2's load on the numerical side
//!   (`numerics::substructure::interface_load`: the force, less the numerical floor 2's inertia
//!   when the specimen holds floor 2) as its `interface_force`, and its linear extrapolation
//!   slope, with the test's bookkeeping: the energy monitor, the bumper's
//!   contact times and the interface log (a [`HybridRun`] filled as the run goes).
//!
//! Each is stateful, one call per communication point; a second call at the same point with the
//! same inputs returns the same outputs, with other inputs it is a wiring error. The arithmetic
//! is `workflows::hybrid::run`'s, in the same order.

use std::cell::RefCell;
use std::rc::Rc;

use numerics::actuator::EnergyMonitor;
use numerics::substructure::{interface_load, Frame, SampledMotion, Split};

use super::{HybridError, HybridRun};
use crate::cosim::master::{Block, MasterError};

fn same_point<const N: usize>(
    last: &Option<(f64, Vec<f64>, [f64; N])>,
    time: f64,
    inputs: &[f64],
    outputs: &mut [f64],
    block: &str,
) -> Result<bool, MasterError> {
    if let Some((t, seen, out)) = last {
        if *t == time {
            if seen
                .iter()
                .zip(inputs)
                .all(|(a, b)| a.to_bits() == b.to_bits())
            {
                outputs.copy_from_slice(out);
                return Ok(true);
            }
            return Err(MasterError::Config(format!(
                "the {block} block's inputs changed inside a communication point: it takes one \
                 sample per point"
            )));
        }
    }
    Ok(false)
}

/// Input: floor 2's displacement on the numerical side. Outputs: `y2_start`, `v2_start`,
/// `y2_end`, `v2_end` for the physical substructure (at the first point: no motion, and the
/// actuator is not called).
pub struct ActuatorBlock {
    actuator: Box<dyn FnMut(f64) -> f64>,
    h: f64,
    achieved: SampledMotion,
    last: Option<(f64, Vec<f64>, [f64; 4])>,
}

impl ActuatorBlock {
    pub const INPUTS: usize = 1;
    pub const OUTPUTS: usize = 4;

    /// `actuator` turns each new target into the achieved displacement (called once per
    /// control step of `h` s, in order).
    pub fn new(actuator: Box<dyn FnMut(f64) -> f64>, h: f64) -> Self {
        ActuatorBlock {
            actuator,
            h,
            achieved: SampledMotion::default(),
            last: None,
        }
    }
}

impl Block for ActuatorBlock {
    fn evaluate(
        &mut self,
        time: f64,
        inputs: &[f64],
        outputs: &mut [f64],
    ) -> Result<(), MasterError> {
        if same_point(&self.last, time, inputs, outputs, "actuator")? {
            return Ok(());
        }
        let out = if self.last.is_none() {
            let (y, v) = (self.achieved.y, self.achieved.v);
            [y, v, y, v]
        } else {
            let achieved = (self.actuator)(inputs[0]);
            let m = self.achieved.advance(achieved, self.h);
            [m.y0, m.v0, m.y1, m.v1]
        };
        outputs.copy_from_slice(&out);
        self.last = Some((time, inputs.to_vec(), out));
        Ok(())
    }
}

/// What the interface block leaves behind: the run so far, and why it stopped it (if it did).
#[derive(Debug, Default)]
pub struct InterfaceLog {
    pub run: HybridRun,
    pub stopped: Option<HybridError>,
}

/// Inputs: `y1`, `y2` (numerical side), `yjp` (the achieved displacement, the actuator
/// block's `y2_end`), the measured force, `y3`, `relative`, `a2` (physical side).
/// Outputs: `interface_force` and `interface_force_rate` for the numerical side (floor 2's
/// load, extrapolated linearly from the last two).
pub struct InterfaceBlock {
    log: Rc<RefCell<InterfaceLog>>,
    split: Split,
    frame: Frame,
    excitation: Vec<f64>,
    dt: f64,
    substeps: u32,
    h: f64,
    gap: f64,
    monitor: EnergyMonitor,
    /// Floor 2's motion on the numerical side, for its acceleration.
    numerical_motion: SampledMotion,
    /// The last load.
    load: f64,
    y1_before: f64,
    closed: bool,
    points: u64,
    last: Option<(f64, Vec<f64>, [f64; 2])>,
}

impl InterfaceBlock {
    pub const INPUTS: usize = 7;
    pub const OUTPUTS: usize = 2;

    /// The test cut at `split` of the structure `frame` (the bumper's gap for the contact
    /// times, floor 2's mass for the load); `excitation` at `dt`, `substeps`
    /// control steps a sample; the energy monitor's `energy_factor`.
    pub fn new(
        log: Rc<RefCell<InterfaceLog>>,
        split: Split,
        frame: Frame,
        excitation: Vec<f64>,
        dt: f64,
        substeps: u32,
        energy_factor: f64,
    ) -> Result<Self, HybridError> {
        let monitor = EnergyMonitor::new(energy_factor, f64::INFINITY)
            .map_err(|e| HybridError::Setup(e.to_string()))?;
        {
            let mut l = log.borrow_mut();
            l.run.excitation = excitation.clone();
            l.run.max_relative = f64::NEG_INFINITY;
            l.run.split = split;
            l.run.interface.step = dt / f64::from(substeps);
        }
        let gap = frame.gap;
        Ok(InterfaceBlock {
            log,
            split,
            frame,
            excitation,
            dt,
            substeps,
            h: dt / f64::from(substeps),
            gap,
            monitor,
            numerical_motion: SampledMotion::default(),
            load: 0.0,
            y1_before: 0.0,
            closed: false,
            points: 0,
            last: None,
        })
    }

    /// Stop the run with `error`, kept in the log for the caller.
    fn stop(&self, error: HybridError) -> MasterError {
        let message = error.to_string();
        self.log.borrow_mut().stopped = Some(error);
        MasterError::Config(message)
    }
}

impl Block for InterfaceBlock {
    fn evaluate(
        &mut self,
        time: f64,
        inputs: &[f64],
        outputs: &mut [f64],
    ) -> Result<(), MasterError> {
        if same_point(&self.last, time, inputs, outputs, "interface")? {
            return Ok(());
        }
        let [y1, yjn, yjp, fm, y3, yr, ajp] = std::array::from_fn(|i| inputs[i]);
        let k = self.points;
        self.points += 1;
        let h = self.h;
        let substeps = u64::from(self.substeps);
        if k > 0 {
            // The control step that ended here: `j` of sample `ks`.
            let i = k - 1;
            let (ks, j) = ((i / substeps) as usize, (i % substeps) as u32);
            let t = ks as f64 * self.dt;
            let tau0 = f64::from(j) * h;
            let slope = (self.excitation[ks + 1] - self.excitation[ks]) / self.dt;
            let fe = (self.excitation[ks] + slope * tau0, slope);
            // The excitation's work on floor 1 over the step (force at mid-step).
            let input_work = (fe.0 + 0.5 * fe.1 * h) * (y1 - self.y1_before);
            self.monitor.observe(fm, yjn, input_work);
            {
                let mut log = self.log.borrow_mut();
                let run = &mut log.run;
                run.interface.yjn.push(yjn);
                run.interface.yjp.push(yjp);
                run.interface.y_above.push(y3);
                run.interface.force.push(fm);
                run.interface.ajp.push(ajp);
                run.max_relative = run.max_relative.max(yr);
                let now = yr > self.gap;
                if now && !self.closed {
                    run.contact_times.push(t + tau0 + h);
                }
                self.closed = now;
            }
            if !(fm.is_finite() && yjn.is_finite()) {
                return Err(self.stop(HybridError::Setup(format!(
                    "non-finite state at t = {:.4} s",
                    t + tau0 + h
                ))));
            }
            if self.monitor.unstable() {
                return Err(self.stop(HybridError::Unstable {
                    time: t + tau0 + h,
                    interface_work: self.monitor.interface_energy(),
                    excitation_work: self.monitor.input_energy(),
                }));
            }
        }
        let within = k % substeps;
        if within == 0 {
            let mut log = self.log.borrow_mut();
            let run = &mut log.run;
            run.time.push((k / substeps) as f64 * self.dt);
            run.y1.push(y1);
            run.yjn.push(yjn);
            run.yjp.push(yjp);
            run.y_above.push(y3);
            run.force.push(fm);
        }
        // The numerical floor 2's acceleration, estimated as the achieved motion's is.
        let ajn = if k > 0 {
            self.numerical_motion.advance(yjn, h).acceleration_at_end()
        } else {
            0.0
        };
        let load = interface_load(self.split, &self.frame, fm, ajn);
        let out = [load, (load - self.load) / h];
        self.load = load;
        self.y1_before = y1;
        outputs.copy_from_slice(&out);
        self.last = Some((time, inputs.to_vec(), out));
        Ok(())
    }
}
