//! The hybrid test on the master algorithm: the two substructures as two instances of the
//! `fmu_substructure` FMU (role 0 numerical; role 2 physical with the specimen floors 2 and 3,
//! the paper's split, or role 1 with the specimen floor 3), the actuator and the interface
//! bookkeeping as blocks ([`super::blocks`]), one communication step per control step
//! `h = dt / substeps`. The same computation as [`super::run`]:
//!
//! at each communication point `t_k`, in zero time and in node order (Gauss–Seidel),
//! the numerical FMU's floor 2 (its state at `t_k`) → the actuator block (the achieved
//! displacement and the Hermite motion over the last control step) → the physical FMU (the
//! specimen at the end of that motion: its outputs are a direct feedthrough of the motion) →
//! the interface block (floor 2's load from the measured force and its extrapolation slope,
//! the energy monitor, the log) → the numerical FMU's `interface_force` and `interface_force_rate`; then both FMUs step
//! to `t_{k+1}` (the numerical one with the excitation interpolated linearly over the step, the
//! physical one keeping the end of the motion).

use std::cell::RefCell;
use std::path::Path;
use std::rc::Rc;

use super::blocks::{ActuatorBlock, InterfaceBlock, InterfaceLog};
use super::{Frame, HybridError, HybridRun, Result, Split};
use crate::cosim::import::{Fmu, Instance};
use crate::cosim::master::{Clock, MasterError, NodeId, Port, System};

/// The FMU's file name (found by [`crate::twin::find_fmu`]).
pub const SUBSTRUCTURE_FMU: &str = "fmu_substructure.fmu";

const NUMERICAL_INPUTS: [&str; 3] = ["force", "interface_force", "interface_force_rate"];
const NUMERICAL_OUTPUTS: [&str; 4] = ["y1", "v1", "y2", "v2"];
const PHYSICAL_INPUTS: [&str; 4] = ["y2_start", "v2_start", "y2_end", "v2_end"];
const PHYSICAL_OUTPUTS: [&str; 5] = ["measured_force", "y3", "v3", "relative", "a2"];

/// Whether the substructure FMU's variables fit `s`: the paper's rig, three storeys cut at
/// its [`::structure::paper::SPLIT_FLOOR`] (its `m1..m3`, `y2`, `y3`, ...).
pub fn serves(s: &Frame) -> bool {
    ::structure::paper::is_paper_rig(&::structure::paper::HybridCut {
        storeys: s.storeys(),
        floor: s.floor,
    })
}

/// The FMU's role for the physical substructure of `split`.
fn physical_role(split: Split) -> i32 {
    match split {
        Split::FloorNumerical => 1,
        Split::FloorPhysical => 2,
    }
}

/// [`super::run`] on the master with the `fmu_substructure` FMU found like the other FMUs
/// (`TWIN_FMU_DIR`, else the one built into the binary).
pub fn run_on_master(
    s: &Frame,
    split: Split,
    excitation: &[f64],
    dt: f64,
    substeps: u32,
    actuator: impl FnMut(f64) -> f64 + 'static,
    energy_factor: f64,
) -> Result<HybridRun> {
    let path =
        crate::twin::find_fmu(SUBSTRUCTURE_FMU).map_err(|e| HybridError::Setup(e.to_string()))?;
    run_with_fmu(
        &path,
        s,
        split,
        excitation,
        dt,
        substeps,
        actuator,
        energy_factor,
    )
}

fn setup(e: impl std::fmt::Display) -> HybridError {
    HybridError::Setup(e.to_string())
}

/// An instance of the substructure FMU in `role`, initialised with `s`'s parameters.
fn substructure(fmu: &Fmu, role: i32, s: &Frame, h: f64) -> Result<Instance> {
    let name = if role == 0 { "numerical" } else { "physical" };
    let mut instance = fmu.instantiate(name).map_err(setup)?;
    let vr = |name: &str| fmu.value_reference(name).map_err(setup);
    instance.setup_experiment(0.0, None).map_err(setup)?;
    instance.enter_initialization_mode().map_err(setup)?;
    instance
        .set_integer(&[vr("role")?, vr("substeps")?], &[role, 1])
        .map_err(setup)?;
    let mut vrs = Vec::new();
    let mut values = Vec::new();
    for i in 0..s.storeys() {
        for (prefix, value) in [("m", s.mass[i]), ("c", s.damping[i]), ("k", s.stiffness[i])] {
            vrs.push(vr(&format!("{prefix}{}", i + 1))?);
            values.push(value);
        }
    }
    for (name, value) in [
        ("gap", s.gap),
        ("contact_stiffness", s.contact_stiffness),
        ("control_step", h),
    ] {
        vrs.push(vr(name)?);
        values.push(value);
    }
    instance.set_real(&vrs, &values).map_err(setup)?;
    instance.exit_initialization_mode().map_err(setup)?;
    Ok(instance)
}

/// [`run_on_master`] with the FMU at `fmu_path`.
#[allow(clippy::too_many_arguments)]
pub fn run_with_fmu(
    fmu_path: &Path,
    s: &Frame,
    split: Split,
    excitation: &[f64],
    dt: f64,
    substeps: u32,
    actuator: impl FnMut(f64) -> f64 + 'static,
    energy_factor: f64,
) -> Result<HybridRun> {
    let h = super::check_inputs(s, excitation, dt, substeps)?;
    if !serves(s) {
        return Err(HybridError::Setup(format!(
            "the substructure FMU's variables are the paper's rig's, three storeys cut at floor \
             2; this test is {} storeys cut at floor {} (run it on the Rust loop, \
             workflows::hybrid::run)",
            s.storeys(),
            s.floor
        )));
    }
    let log = Rc::new(RefCell::new(InterfaceLog::default()));
    let interface = InterfaceBlock::new(
        log.clone(),
        split,
        s.clone(),
        excitation.to_vec(),
        dt,
        substeps,
        energy_factor,
    )?;
    if excitation.is_empty() {
        return Ok(log.take().run);
    }
    let fmu = Fmu::open(fmu_path).map_err(setup)?;
    let vrs = |names: &[&str]| -> Result<Vec<u32>> {
        names
            .iter()
            .map(|n| fmu.value_reference(n).map_err(setup))
            .collect()
    };
    let mut system = System::new();
    let numerical = system.add_slave(
        "numerical",
        Box::new(substructure(&fmu, 0, s, h)?),
        vrs(&NUMERICAL_INPUTS)?,
        vrs(&NUMERICAL_OUTPUTS)?,
    );
    let actuator = system.add_block(
        "actuator",
        Box::new(ActuatorBlock::new(Box::new(actuator), h)),
        ActuatorBlock::INPUTS,
        ActuatorBlock::OUTPUTS,
    );
    let physical = system.add_slave(
        "physical",
        Box::new(substructure(&fmu, physical_role(split), s, h)?),
        vrs(&PHYSICAL_INPUTS)?,
        vrs(&PHYSICAL_OUTPUTS)?,
    );
    let bookkeeping = system.add_block(
        "interface",
        Box::new(interface),
        InterfaceBlock::INPUTS,
        InterfaceBlock::OUTPUTS,
    );
    let force = control_rate_force(excitation, dt, substeps, h);
    let steps = (force.len() - 1) as u64;
    let nodes = LoopNodes {
        numerical,
        actuator,
        physical,
        bookkeeping,
    };
    wire(&mut system, &nodes, force).map_err(setup)?;
    let result = system.run(Clock::new(0.0, h, steps), &mut [], |_, _| {});
    drop(system);
    let mut log = log.take();
    if let Some(stopped) = log.stopped.take() {
        return Err(stopped);
    }
    result.map_err(setup)?;
    Ok(log.run)
}

/// The excitation at the control rate, linear between the record's samples (as `run`
/// evaluates it); the master sends each segment's slope to the numerical FMU.
fn control_rate_force(excitation: &[f64], dt: f64, substeps: u32, h: f64) -> Vec<f64> {
    let mut force = Vec::with_capacity((excitation.len() - 1) * substeps as usize + 1);
    for w in excitation.windows(2) {
        let slope = (w[1] - w[0]) / dt;
        for j in 0..substeps {
            force.push(w[0] + slope * (f64::from(j) * h));
        }
    }
    force.push(excitation[excitation.len() - 1]);
    force
}

/// The loop's four nodes in the master's system.
struct LoopNodes {
    numerical: NodeId,
    actuator: NodeId,
    physical: NodeId,
    bookkeeping: NodeId,
}

/// The loop's wiring: the force into the numerical FMU with floor 2's load from the
/// bookkeeping, its floor 2 to the actuator, the actuator's motion to the physical FMU, and
/// both sides' outputs to the bookkeeping.
fn wire(
    system: &mut System,
    n: &LoopNodes,
    force: Vec<f64>,
) -> std::result::Result<(), MasterError> {
    let (numerical, actuator, physical, bookkeeping) =
        (n.numerical, n.actuator, n.physical, n.bookkeeping);
    let signal = system.add_signal("force", force);
    system.connect(signal, numerical, 0)?;
    system.connect(Port::Output(bookkeeping, 0), numerical, 1)?;
    system.connect(Port::Output(bookkeeping, 1), numerical, 2)?;
    system.connect(Port::Output(numerical, 2), actuator, 0)?;
    for p in 0..4 {
        system.connect(Port::Output(actuator, p), physical, p)?;
    }
    system.connect(Port::Output(numerical, 0), bookkeeping, 0)?;
    system.connect(Port::Output(numerical, 2), bookkeeping, 1)?;
    system.connect(Port::Output(actuator, 2), bookkeeping, 2)?;
    for (port, input) in [(0, 3), (1, 4), (3, 5), (4, 6)] {
        system.connect(Port::Output(physical, port), bookkeeping, input)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use std::collections::VecDeque;
    use std::path::PathBuf;

    use super::*;
    use crate::workflows::hybrid::{run, unit_peak};

    /// Where `scripts/build-fmus.sh` put the FMU; fails the test when it is not there.
    fn fmu_path() -> PathBuf {
        let target = std::env::var_os("CARGO_TARGET_DIR")
            .map(PathBuf::from)
            .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../target"));
        let path = target.join("fmu").join(SUBSTRUCTURE_FMU);
        assert!(
            path.is_file(),
            "{} is missing: run scripts/build-fmus.sh",
            path.display()
        );
        path
    }

    use crate::workflows::hybrid::tests::{excitation, structure};

    /// An amplitude error and a pure delay of `delay` control steps.
    fn actuator(a_err: f64, delay: usize) -> impl FnMut(f64) -> f64 + 'static {
        let mut queue: VecDeque<f64> = vec![0.0; delay].into();
        move |y| {
            queue.push_back((1.0 + a_err) * y);
            queue.pop_front().unwrap_or(0.0)
        }
    }

    /// The largest difference over the series' peak.
    fn relative(a: &[f64], b: &[f64]) -> f64 {
        assert_eq!(a.len(), b.len());
        let peak = b.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        a.iter()
            .zip(b)
            .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
            / peak
    }

    /// The master with the two FMU instances and the blocks is the Rust loop's computation,
    /// cut either way: on a record where the bumper closes, with a 3 % amplitude error (and a
    /// delay of 3 control steps with floor 2 numerical; the paper's cut refuses a delay), every
    /// signal agrees to 1e-12 of its peak and the contacts are the same.
    #[test]
    fn the_master_reproduces_the_rust_loop() {
        // Storey 3 damped enough to absorb the delay's negative damping (about k3 times the
        // delay): the run stays stable and the monitor quiet.
        let s = Frame {
            damping: vec![8.0, 3.5, 40.0],
            ..structure()
        };
        let (dt, substeps) = (1.0 / 51.2, 8);
        let unit = unit_peak(&excitation(400)).expect("unit");
        for split in Split::ALL {
            let delay = if split.floor_physical() { 0 } else { 3 };
            // 1.6 times the peak at which the bumper first closes, from the linear assembly.
            let open = Frame {
                gap: 1.0,
                ..s.clone()
            };
            let linear = run(
                &open,
                split,
                &unit,
                dt,
                substeps,
                actuator(0.03, delay),
                10.0,
            )
            .expect("linear");
            let force: Vec<f64> = unit
                .iter()
                .map(|f| 1.6 * s.gap / linear.max_relative * f)
                .collect();
            let reference =
                run(&s, split, &force, dt, substeps, actuator(0.03, delay), 10.0).expect("run");
            let master = run_with_fmu(
                &fmu_path(),
                &s,
                split,
                &force,
                dt,
                substeps,
                actuator(0.03, delay),
                10.0,
            )
            .expect("master");
            assert!(
                reference.contact_times.len() >= 2,
                "{:?}",
                reference.contact_times
            );
            assert_eq!(master.time, reference.time);
            let mut worst = 0.0f64;
            for (name, a, b) in [
                ("y1", &master.y1, &reference.y1),
                ("yjn", &master.yjn, &reference.yjn),
                ("yjp", &master.yjp, &reference.yjp),
                ("y3", &master.y_above, &reference.y_above),
                ("force", &master.force, &reference.force),
                (
                    "interface yjn",
                    &master.interface.yjn,
                    &reference.interface.yjn,
                ),
                (
                    "interface yjp",
                    &master.interface.yjp,
                    &reference.interface.yjp,
                ),
                (
                    "interface y3",
                    &master.interface.y_above,
                    &reference.interface.y_above,
                ),
                (
                    "interface force",
                    &master.interface.force,
                    &reference.interface.force,
                ),
                (
                    "interface ajp",
                    &master.interface.ajp,
                    &reference.interface.ajp,
                ),
            ] {
                let e = relative(a, b);
                assert!(e <= 1e-12, "{split:?}, {name}: {e:.2e}");
                worst = worst.max(e);
            }
            eprintln!(
                "{split:?}: master against the Rust loop: worst relative difference {worst:.2e}, {} contacts, \
                 peak y_r {:.3e} m",
                reference.contact_times.len(),
                reference.max_relative
            );
            assert_eq!(master.contact_times.len(), reference.contact_times.len());
            for (a, b) in master.contact_times.iter().zip(&reference.contact_times) {
                assert!((a - b).abs() <= 1e-12 * b, "{a} {b}");
            }
            assert!(
                (master.max_relative - reference.max_relative).abs()
                    <= 1e-12 * reference.max_relative
            );
            assert_eq!(master.interface.step, reference.interface.step);
            assert_eq!(master.excitation, reference.excitation);
        }
    }

    /// A delay the energy monitor stops: the master stops at the same control step with the
    /// same error.
    #[test]
    fn the_master_stops_where_the_rust_loop_does() {
        let s = Frame {
            gap: 1.0,
            ..structure()
        };
        let (dt, substeps) = (1.0 / 51.2, 4);
        let force = excitation(600);
        let stop = |r: Result<HybridRun>| match r {
            Err(HybridError::Unstable { time, .. }) => time,
            other => panic!("expected an unstable run, got {other:?}"),
        };
        let split = Split::FloorNumerical;
        let reference = stop(run(&s, split, &force, dt, substeps, actuator(0.0, 12), 1.5));
        let master = stop(run_with_fmu(
            &fmu_path(),
            &s,
            split,
            &force,
            dt,
            substeps,
            actuator(0.0, 12),
            1.5,
        ));
        assert_eq!(master, reference);
    }

    /// The FMU refuses bad parameters through the importer, naming the variable.
    #[test]
    fn the_fmu_refuses_bad_parameters_by_name() {
        let fmu = Fmu::open(&fmu_path()).expect("open");
        let mut bad = structure();
        bad.mass[1] = -1.0;
        let e = substructure(&fmu, 0, &bad, 1e-3)
            .err()
            .expect("refused")
            .to_string();
        assert!(e.contains("m2"), "{e}");
        let mut bad = structure();
        bad.gap = -1e-3;
        let e = substructure(&fmu, 1, &bad, 1e-3)
            .err()
            .expect("refused")
            .to_string();
        assert!(e.contains("gap"), "{e}");
        let e = substructure(&fmu, 3, &structure(), 1e-3)
            .err()
            .expect("refused")
            .to_string();
        assert!(e.contains("role"), "{e}");
    }
}
