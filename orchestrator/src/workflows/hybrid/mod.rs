//! The simulated real-time hybrid test (the reference paper's section 5): the structure split
//! into a numerical substructure, the twin's validated linear parts, and a physical one with
//! the contact, joined by an actuator that imposes the numerical interface displacement on the
//! physical side, and the measured interface force fed back.
//!
//! # Where the structure is cut
//!
//! By default as the paper's eqs (13)–(14) cut it ([`Split::FloorPhysical`]): the physical
//! substructure (the specimen) is floors 2 and 3 with storey 3 and the bumper between them;
//! the actuator drives the specimen's floor 2 to the numerical side's floor-2 displacement
//! (`y₂ₚ = (1 + a_err) y₂ₙ` with the amplitude error, and the actuator's delay and lag), and
//! the measured force carries floor 2's inertia,
//! `F_m = m₂ ÿ₂ₚ + c₃ (ẏ₂ₚ − ẏ₃) + k₃ (y₂ₚ − y₃) + F_nl(y_r)`, `y_r = y₂ₚ − y₃`. The numerical
//! substructure is floor 1 with storey 1, and storey 2 whose force on floor 2 the measured
//! force must equal (eq 14): `F_m = c₂ (ẏ₁ − ẏ₂ₙ) + k₂ (y₁ − y₂ₙ)`. So the amplitude error
//! scales floor 2's inertia as well as storey 3's drift.
//!
//! Eq (14) is massless: stepped with a force measured a step late it would be an advanced
//! equation (the force carries `ÿ₂` of the past, the equation gives `ẏ₂` now). The numerical
//! side therefore keeps the twin's `m₂` on floor 2 as a predictor and takes that inertia back
//! out of the load, `F_m − m₂ ÿ₂ₙ` (`numerics::substructure::interface_load`, the added-mass
//! correction of partitioned coupling), `ÿ₂ₙ` estimated from floor 2's numerical
//! displacements exactly as the specimen's achieved motion is built from its displacements:
//! the load is then storey 3's force plus the inertia of the actuator's error,
//! `m₂ (ÿ₂ₚ − ÿ₂ₙ)`. As the control step shrinks the loop is eqs (13)–(14), its error first
//! order in the step (the accelerations estimated from displacements); with perfect control the
//! correction vanishes and the loop is the whole structure.
//!
//! [`Split::FloorNumerical`] keeps floor 2 on the numerical side: the specimen is storey 3,
//! the bumper and floor 3, moved at floor 2, and `F_m = c₃ (ẏ₂ₚ − ẏ₃) + k₃ (y₂ₚ − y₃) +
//! F_nl(y_r)` carries no acceleration. Both are the whole structure under perfect control;
//! under an amplitude error they differ by floor 2's inertia error `a_err m₂ ÿ₂ₙ`, which the
//! paper's split has and this one does not. It stays because it needs no acceleration in the
//! measured force: with a pure delay in the loop the paper's split is a neutral delay
//! equation whose high frequencies a stepped test cannot hold, this one only loses damping.
//!
//! # Any building
//!
//! The paper's rig is three storeys cut at floor 2; a building of N storeys is cut at any floor
//! j with 1 ≤ j < N ([`Frame`]'s `floor`, `--split J`): the numerical substructure is floors
//! 1..j under the excitation at floor 1, the specimen floors j+1..N with storeys j+1..N and
//! the bumper in storey j+1, and floor j's mass in the specimen in the paper's cut — what is
//! said above of floors 2 and 3 is said of floors j and j+1. The substructure FMU's variables
//! are the paper rig's, so the master runs the FMUs for that cut ([`fmus::serves`]) and the
//! stepped test of another cut runs on the Rust loop, the same `numerics::substructure`.
//!
//! # Stepping
//!
//! Both substructures step at the control rate `h` (the record's step over `substeps`), as a
//! real-time controller does: the numerical substructure over `[t, t + h]` with the excitation
//! linear in time and floor 2's load of the last step extrapolated linearly (the usual
//! predictor of staggered coupling), the actuator turns its new displacement into the physical
//! one, and the physical substructure follows that displacement (a cubic Hermite over the step,
//! its rates from the last three positions: only displacements cross the interface; floor 2's
//! acceleration is the Hermite's at the step's end) and returns the force. RK4 for both.
//!
//! The substructures' equations and RK4 are `numerics::substructure`, shared with the
//! `fmu_substructure` FMU; [`fmus::run_on_master`] runs the same test with the substructures as
//! two instances of that FMU on the master algorithm.

use numerics::actuator::EnergyMonitor;
use numerics::substructure::{interface_load, Numerical, Physical, SampledMotion};
pub use numerics::substructure::{Cut, Frame, Split};
use serde::Serialize;

pub mod blocks;
pub mod experiment;
pub mod fmus;
pub mod identify;
pub mod monolithic;
pub mod options;
pub mod spectrum;

/// What can stop a hybrid test.
#[derive(Debug, thiserror::Error)]
pub enum HybridError {
    #[error("hybrid test: {0}")]
    Setup(String),
    #[error(
        "hybrid test unstable at t = {time:.3} s: the interface has put {interface_work:.3e} J into \
         the numerical substructure against {excitation_work:.3e} J from the excitation (the \
         actuator's delay acts as negative damping); stopped"
    )]
    Unstable {
        time: f64,
        interface_work: f64,
        excitation_work: f64,
    },
}

pub type Result<T, E = HybridError> = std::result::Result<T, E>;

/// `building` cut at `floor` with the bumper's `gap` and `contact_stiffness` (not checked:
/// [`Frame::check`]).
pub fn cut(
    building: &structure::Structure,
    floor: usize,
    gap: f64,
    contact_stiffness: f64,
) -> Frame {
    Frame {
        mass: building.mass.clone(),
        damping: building.damping.clone(),
        stiffness: building.stiffness.clone(),
        floor,
        gap,
        contact_stiffness,
    }
}

/// Time histories of a hybrid test at the record's sample times.
#[derive(Clone, Debug, Default, Serialize)]
pub struct HybridRun {
    pub time: Vec<f64>,
    pub excitation: Vec<f64>,
    /// Floor 1's displacement (the excitation's floor).
    pub y1: Vec<f64>,
    /// Floor j's displacement on the numerical side (the actuator's target).
    pub yjn: Vec<f64>,
    /// Floor j's displacement the actuator achieved on the physical side.
    pub yjp: Vec<f64>,
    /// Floor j + 1's displacement (the specimen's, above the bumper).
    pub y_above: Vec<f64>,
    /// The measured interface force.
    pub force: Vec<f64>,
    /// Where the structure was cut.
    pub split: Split,
    /// Times (s) at which the bumper closed (y_r crossing d upwards, at control steps).
    pub contact_times: Vec<f64>,
    /// The largest `y_r = y_jp − y_{j+1}`.
    pub max_relative: f64,
    /// The interface at every control step (what a hybrid test's controller logs).
    #[serde(skip)]
    pub interface: Interface,
}

/// The interface signals at the control rate.
#[derive(Clone, Debug, Default)]
pub struct Interface {
    pub step: f64,
    pub yjn: Vec<f64>,
    pub yjp: Vec<f64>,
    pub y_above: Vec<f64>,
    pub force: Vec<f64>,
    /// Floor j's acceleration on the physical side (the specimen's accelerometer; it is in the
    /// measured force when the specimen holds floor j).
    pub ajp: Vec<f64>,
}

/// Check a test's inputs — the structure, a positive step, at least one control step a
/// sample, a finite excitation — and give the control step `dt / substeps`.
pub(crate) fn check_inputs(s: &Frame, excitation: &[f64], dt: f64, substeps: u32) -> Result<f64> {
    s.check().map_err(HybridError::Setup)?;
    if !(dt.is_finite() && dt > 0.0) || substeps == 0 {
        return Err(HybridError::Setup(format!(
            "the step ({dt} s) must be positive and the control steps per sample ({substeps}) at \
             least 1"
        )));
    }
    if let Some(k) = excitation.iter().position(|f| !f.is_finite()) {
        return Err(HybridError::Setup(format!(
            "the excitation's sample {k} is not a finite number"
        )));
    }
    Ok(dt / f64::from(substeps))
}

/// Run the hybrid test cut at `split`: `excitation` (N on floor 1) at step `dt`, `substeps`
/// control steps per sample, `actuator` turning each new target displacement into the achieved
/// one (called once per control step, in order). `energy_factor`: stop with [`HybridError::Unstable`] when the
/// energy the interface has put into the numerical substructure exceeds this factor times the
/// excitation's ([`numerics::actuator::EnergyMonitor`]: a delay acts as negative damping).
pub fn run(
    s: &Frame,
    split: Split,
    excitation: &[f64],
    dt: f64,
    substeps: u32,
    mut actuator: impl FnMut(f64) -> f64,
    energy_factor: f64,
) -> Result<HybridRun> {
    let h = check_inputs(s, excitation, dt, substeps)?;
    let n = excitation.len();
    let frame = s;
    let jf = s.floor - 1;
    let mut out = HybridRun {
        excitation: excitation.to_vec(),
        max_relative: f64::NEG_INFINITY,
        split,
        ..HybridRun::default()
    };
    out.interface.step = h;
    let mut num = Numerical::at_rest(frame);
    let mut phys = Physical::at_rest(frame);
    // Floor j's motion as the actuator achieved it, and as the numerical side computed it.
    let mut achieved_motion = SampledMotion::default();
    let mut numerical_motion = SampledMotion::default();
    let mut fm = 0.0;
    // Floor j's load on the numerical side (the measured force, less the numerical floor j's
    // inertia when the specimen holds floor j), its last two values.
    let (mut load, mut load_previous) = (0.0, 0.0);
    let mut monitor = EnergyMonitor::new(energy_factor, f64::INFINITY)
        .map_err(|e| HybridError::Setup(e.to_string()))?;
    let mut closed = false;
    let record = |out: &mut HybridRun, t: f64, num: &Numerical, yjp: f64, phys: &Physical, fm| {
        out.time.push(t);
        out.y1.push(num.y[0]);
        out.yjn.push(num.y[jf]);
        out.yjp.push(yjp);
        out.y_above.push(phys.y[0]);
        out.force.push(fm);
    };
    for k in 0..n {
        let t = k as f64 * dt;
        record(&mut out, t, &num, achieved_motion.y, &phys, fm);
        if k + 1 == n {
            break;
        }
        let slope = (excitation[k + 1] - excitation[k]) / dt;
        for j in 0..substeps {
            let tau0 = f64::from(j) * h;
            let fe = (excitation[k] + slope * tau0, slope);
            // Floor j's load, extrapolated linearly from the last two.
            let load_slope = (load - load_previous) / h;
            let y1_before = num.y[0];
            num.step(frame, h, fe, (load, load_slope));
            let target = num.y[jf];
            // The achieved motion over the step: a cubic Hermite, its end rate from the last
            // three positions (only displacements cross the interface).
            let imposed = achieved_motion.advance(actuator(target), h);
            phys.step(frame, h, &imposed, 0.0);
            let ajp = imposed.acceleration_at_end();
            fm = frame.interface_force(split, imposed.y1, imposed.v1, ajp, &phys);
            let ajn = numerical_motion.advance(target, h).acceleration_at_end();
            load_previous = load;
            load = interface_load(split, frame, fm, ajn);
            // The excitation's work on floor 1 over the step (force at mid-step).
            let input_work = (fe.0 + 0.5 * fe.1 * h) * (num.y[0] - y1_before);
            monitor.observe(fm, num.y[jf], input_work);
            let yjp = imposed.y1;
            let yr = yjp - phys.y[0];
            out.interface.yjn.push(num.y[jf]);
            out.interface.yjp.push(yjp);
            out.interface.y_above.push(phys.y[0]);
            out.interface.force.push(fm);
            out.interface.ajp.push(ajp);
            out.max_relative = out.max_relative.max(yr);
            let now = yr > s.gap;
            if now && !closed {
                out.contact_times.push(t + tau0 + h);
            }
            closed = now;
            if !(fm.is_finite() && num.y[jf].is_finite()) {
                return Err(HybridError::Setup(format!(
                    "non-finite state at t = {:.4} s",
                    t + tau0 + h
                )));
            }
            if monitor.unstable() {
                return Err(HybridError::Unstable {
                    time: t + tau0 + h,
                    interface_work: monitor.interface_energy(),
                    excitation_work: monitor.input_energy(),
                });
            }
        }
    }
    Ok(out)
}

/// The peak excitation force (N) at which the bumper first closes: the excitation `unit`
/// (scaled to a peak |F| of 1 N) times the peak, bisected on whether `simulate` (a fresh test
/// of the scaled excitation) sees a contact, to a relative width of `1e-6`.
pub fn threshold(unit: &[f64], simulate: impl Fn(&[f64]) -> Result<HybridRun>) -> Result<f64> {
    let contact_at = |peak: f64| -> Result<bool> {
        let scaled: Vec<f64> = unit.iter().map(|f| f * peak).collect();
        Ok(!simulate(&scaled)?.contact_times.is_empty())
    };
    let mut hi = 1.0;
    while !contact_at(hi)? {
        hi *= 2.0;
        if hi > 1e9 {
            return Err(HybridError::Setup(
                "the bumper never closes, even at a peak of 1e9 N".into(),
            ));
        }
    }
    let mut lo = 0.0;
    while hi - lo > 1e-6 * hi {
        let mid = 0.5 * (lo + hi);
        if contact_at(mid)? {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    Ok(hi)
}

/// `signal` scaled to a peak |value| of 1.
pub fn unit_peak(signal: &[f64]) -> Result<Vec<f64>> {
    let peak = signal.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    if !(peak > 0.0 && peak.is_finite()) {
        return Err(HybridError::Setup(
            "the excitation is zero (or not finite) everywhere: nothing to scale".into(),
        ));
    }
    Ok(signal.iter().map(|x| x / peak).collect())
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// The structure of the hybrid tests (a calibrated-like frame with the paper's bumper).
    pub(crate) fn structure() -> Frame {
        Frame {
            mass: vec![4.6, 5.3, 4.9],
            damping: vec![8.0, 3.5, 2.6],
            stiffness: vec![3850.0, 4100.0, 4650.0],
            floor: 2,
            gap: 5e-4,
            contact_stiffness: 9000.0,
        }
    }

    /// A decaying 9 Hz sine and a 3.1 Hz cosine at 51.2 Hz: `n` samples.
    pub(crate) fn excitation(n: usize) -> Vec<f64> {
        (0..n)
            .map(|k| {
                let t = k as f64 / 51.2;
                (2.0 * std::f64::consts::PI * 9.0 * t).sin() * (-0.1 * t).exp()
                    + 0.5 * (2.0 * std::f64::consts::PI * 3.1 * t).cos()
            })
            .collect()
    }

    /// The whole structure, monolithic (RK4, the force on floor 1 linear between samples, `sub`
    /// steps a sample), linear (no bumper): floor j's displacement.
    pub(crate) fn whole(s: &Frame, force: &[f64], dt: f64, sub: u32) -> Vec<f64> {
        let n = s.storeys();
        let acc = |y: &[f64], v: &[f64], f: f64| -> Vec<f64> {
            // Storey i's force on floor i − 1 (0-based storey i joins floors i − 1 and i).
            let storey = |i: usize| {
                let (yb, vb) = if i == 0 {
                    (0.0, 0.0)
                } else {
                    (y[i - 1], v[i - 1])
                };
                s.damping[i] * (v[i] - vb) + s.stiffness[i] * (y[i] - yb)
            };
            (0..n)
                .map(|i| {
                    let above = if i + 1 < n { storey(i + 1) } else { 0.0 };
                    let load = if i == 0 { f } else { 0.0 };
                    (load - storey(i) + above) / s.mass[i]
                })
                .collect()
        };
        let h = dt / f64::from(sub);
        let (mut y, mut v) = (vec![0.0; n], vec![0.0; n]);
        let mut out = vec![0.0];
        let add = |a: &[f64], b: &[f64], c: f64| -> Vec<f64> {
            a.iter().zip(b).map(|(x, z)| x + c * z).collect()
        };
        for k in 0..force.len() - 1 {
            let slope = (force[k + 1] - force[k]) / dt;
            for j in 0..sub {
                let f = |tau: f64| force[k] + slope * (f64::from(j) * h + tau);
                let a1 = acc(&y, &v, f(0.0));
                let (y2, v2) = (add(&y, &v, h / 2.0), add(&v, &a1, h / 2.0));
                let a2 = acc(&y2, &v2, f(h / 2.0));
                let (y3, v3) = (add(&y, &v2, h / 2.0), add(&v, &a2, h / 2.0));
                let a3 = acc(&y3, &v3, f(h / 2.0));
                let (y4, v4) = (add(&y, &v3, h), add(&v, &a3, h));
                let a4 = acc(&y4, &v4, f(h));
                for i in 0..n {
                    y[i] += h / 6.0 * (v[i] + 2.0 * v2[i] + 2.0 * v3[i] + v4[i]);
                    v[i] += h / 6.0 * (a1[i] + 2.0 * a2[i] + 2.0 * a3[i] + a4[i]);
                }
            }
            out.push(y[s.floor - 1]);
        }
        out
    }

    /// With perfect control and the bumper open the hybrid assembly, cut either way, is the
    /// whole structure. Floor 2 numerical: the staggered coupling's error falls as h²
    /// (measured: 3.42e-3, 8.55e-4, 2.14e-4 of floor 2's peak displacement at 16, 32, 64
    /// control steps a sample: 4.0× per halving). Floor 2 in the specimen: MEASURED_PAPER.
    #[test]
    fn perfect_control_reproduces_the_whole_structure() {
        let mut s = structure();
        s.gap = 1.0; // never closes
        let force = excitation(512);
        let dt = 1.0 / 51.2;
        let reference = whole(&s, &force, dt, 256);
        let scale = reference.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        for split in Split::ALL {
            let error = |sub: u32| {
                let r = run(&s, split, &force, dt, sub, |y| y, 10.0).expect("run");
                r.yjp
                    .iter()
                    .zip(&reference)
                    .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()))
                    / scale
            };
            let (e16, e32, e64) = (error(16), error(32), error(64));
            eprintln!(
                "{split:?}: relative error at 16/32/64 control steps a sample: {e16:.2e} {e32:.2e} \
                 {e64:.2e}"
            );
            assert!(e64 < 3e-4, "{split:?}: {e64}");
            assert!(
                e16 / e32 > 3.5 && e32 / e64 > 3.5,
                "{split:?}: {e16} {e32} {e64}"
            );
        }
    }

    /// Buildings other than the paper's rig, their floors and storeys all different (so a
    /// swapped index shows): five storeys cut at floor 3, four cut at floor 1.
    pub(crate) fn other_buildings() -> Vec<Frame> {
        vec![
            Frame {
                mass: vec![4.6, 5.3, 4.9, 5.6, 4.2],
                damping: vec![8.0, 3.5, 2.6, 4.1, 3.0],
                stiffness: vec![3850.0, 4100.0, 4650.0, 3900.0, 4300.0],
                floor: 3,
                gap: 1.0,
                contact_stiffness: 9000.0,
            },
            Frame {
                mass: vec![5.1, 4.4, 5.8, 4.7],
                damping: vec![6.0, 2.9, 3.8, 2.2],
                stiffness: vec![4200.0, 3700.0, 4500.0, 4050.0],
                floor: 1,
                gap: 1.0,
                contact_stiffness: 9000.0,
            },
        ]
    }

    /// The same for five storeys cut at floor 3 and four cut at floor 1, either way: with perfect
    /// control and the bumper open the stepped loop is the whole structure to the staggered
    /// coupling's O(h²) (measured, either cut alike: 4.27e-3, 1.08e-3, 2.70e-4 of floor 3's peak
    /// for five storeys, 2.58e-3, 6.47e-4, 1.62e-4 of floor 1's for four, at 16, 32, 64 control
    /// steps a sample; the limit leaves 1.5× on the larger, the ratios 3.95–4.0 per halving).
    #[test]
    fn perfect_control_reproduces_the_whole_structure_of_other_buildings() {
        let force = excitation(512);
        let dt = 1.0 / 51.2;
        for s in other_buildings() {
            let reference = whole(&s, &force, dt, 256);
            let scale = reference.iter().fold(0.0f64, |m, x| m.max(x.abs()));
            for split in Split::ALL {
                let error = |sub: u32| {
                    let r = run(&s, split, &force, dt, sub, |y| y, 10.0).expect("run");
                    r.yjp
                        .iter()
                        .zip(&reference)
                        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()))
                        / scale
                };
                let (e16, e32, e64) = (error(16), error(32), error(64));
                eprintln!(
                    "N {}, j {}, {split:?}: relative error at 16/32/64 control steps a sample: \
                     {e16:.2e} {e32:.2e} {e64:.2e}",
                    s.storeys(),
                    s.floor
                );
                assert!(e64 < 4e-4, "{split:?}: {e64}");
                assert!(
                    e16 / e32 > 3.5 && e32 / e64 > 3.5,
                    "{split:?}: {e16} {e32} {e64}"
                );
            }
        }
    }

    /// Under an amplitude error the stepped loop converges to the one-ODE assembly of its own
    /// split, the paper's included (floor 2's inertia taken out of the numerical load): at
    /// a_err = −0.1, floor 2's achieved displacement against the one-ODE solve is off by 8.4e-2,
    /// 4.0e-2, 2.0e-2 of its peak at 16, 32, 64 control steps a sample (first order: the
    /// accelerations estimated from displacements), while the other split's one-ODE solve is
    /// 0.47 away (this lightly damped frame near resonance).
    #[test]
    fn under_an_amplitude_error_the_stepped_paper_split_converges_to_its_equations() {
        let mut s = structure();
        s.gap = 1.0;
        let force = excitation(512);
        let dt = 1.0 / 51.2;
        let a_err = -0.1;
        let gain = move |y: f64| (1.0 + a_err) * y;
        let one_ode = |split: Split| {
            monolithic::run(&s, split, &force, dt, 256, a_err)
                .expect("one ODE")
                .yjp
        };
        let (paper, other) = (
            one_ode(Split::FloorPhysical),
            one_ode(Split::FloorNumerical),
        );
        let scale = paper.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        let distance = |a: &[f64], b: &[f64]| {
            a.iter()
                .zip(b)
                .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
                / scale
        };
        let error = |sub: u32| {
            let r = run(&s, Split::FloorPhysical, &force, dt, sub, gain, 10.0).expect("run");
            distance(&r.yjp, &paper)
        };
        let (e16, e32, e64) = (error(16), error(32), error(64));
        let apart = distance(&other, &paper);
        eprintln!(
            "paper split, a_err −0.1: stepped against one ODE at 16/32/64 control steps a \
             sample: {e16:.2e} {e32:.2e} {e64:.2e}; the other split's one ODE {apart:.2e}"
        );
        assert!(e16 / e32 > 1.8 && e32 / e64 > 1.8, "{e16} {e32} {e64}");
        assert!(e64 < 0.06 * apart, "{e64} against {apart}");
    }

    /// Before the first contact the assembly is linear, so the threshold is the gap over the
    /// largest relative displacement of the unit-peak run: the bisection on the simulation
    /// agrees with that, for several amplitude errors and both splits.
    #[test]
    fn the_threshold_is_the_gap_over_the_linear_peak() {
        let s = structure();
        let unit = unit_peak(&excitation(512)).expect("unit");
        let dt = 1.0 / 51.2;
        for split in Split::ALL {
            for a_err in [-0.1, 0.0, 0.05] {
                let gain = move |y: f64| (1.0 + a_err) * y;
                let found =
                    threshold(&unit, |f| run(&s, split, f, dt, 32, gain, 10.0)).expect("threshold");
                let mut open = s.clone();
                open.gap = 1.0;
                let linear = run(&open, split, &unit, dt, 32, gain, 10.0).expect("run");
                let independent = s.gap / linear.max_relative;
                assert!(
                    (found - independent).abs() <= 2e-6 * independent,
                    "{split:?}, a_err {a_err}: {found} against {independent}"
                );
            }
        }
    }

    #[test]
    fn bad_input_is_refused_with_the_reason() {
        let mut s = structure();
        s.gap = -1e-3;
        let e = run(&s, Split::default(), &[0.0, 1.0], 0.01, 4, |y| y, 10.0)
            .unwrap_err()
            .to_string();
        assert!(e.contains("gap must be positive"), "{e}");
        let e = run(
            &structure(),
            Split::default(),
            &[0.0, f64::NAN],
            0.01,
            4,
            |y| y,
            10.0,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("sample 1 is not a finite number"), "{e}");
        assert!(unit_peak(&[0.0, 0.0]).is_err());
    }
}
