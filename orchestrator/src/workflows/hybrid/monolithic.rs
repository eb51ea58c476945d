//! The hybrid assembly solved as one ODE, for an actuator without dynamics.
//!
//! When the actuator only scales (`y₂ₚ = (1 + a_err) y₂ₙ`, no delay, no lag) the loop is
//! algebraic: the substructures and the actuator are one system of ODEs in (y₁, y₂ₙ, y₃),
//! which is what the reference paper integrates for its Fig. 14 (its "simplified simulation",
//! the actuator without delay). Cut as the paper cuts it ([`Split::SpecimenFloors23`]), eq
//! (14) with the measured force of eq (13) makes floor 2's equation
//! `m₂ (1 + a_err) ÿ₂ₙ = c₂ (ẏ₁ − ẏ₂ₙ) + k₂ (y₁ − y₂ₙ) − [c₃ (ẏ₂ₚ − ẏ₃) + k₃ (y₂ₚ − y₃) + F_nl]`:
//! the specimen's floor 2 moves at `(1 + a_err) ÿ₂ₙ`. With floor 2 numerical
//! ([`Split::SpecimenFloor3`]) its mass is `m₂` alone. Solved here with RK4 at `substeps` sub-steps a sample and the
//! excitation linear between samples — the very scheme of the shear FMU — so with perfect
//! control it is the whole structure, to rounding. An actuator with dynamics needs the
//! stepped loop of [`super::run`].

use super::{HybridError, HybridRun, Result, Split, Structure};

/// Accelerations of (y₁, y₂ₙ, y₃) and the measured force, at states `y`, `v`.
fn rates(
    s: &Structure,
    split: Split,
    a_err: f64,
    y: [f64; 3],
    v: [f64; 3],
    fe: f64,
) -> ([f64; 3], f64) {
    let [m1, m2, m3] = s.mass;
    let [c1, c2, c3] = s.damping;
    let [k1, k2, k3] = s.stiffness;
    let gain = 1.0 + a_err;
    let (y2p, v2p) = (gain * y[1], gain * v[1]);
    let storey2 = c2 * (v[1] - v[0]) + k2 * (y[1] - y[0]);
    let storey3 = c3 * (v2p - v[2]) + k3 * (y2p - y[2]) + s.contact_force(y2p - y[2]);
    let (a2, fm) = match split {
        // F_m = m₂ ÿ₂ₚ + storey 3 = −storey 2's force (eq 14).
        Split::SpecimenFloors23 => ((-storey2 - storey3) / (m2 * gain), -storey2),
        Split::SpecimenFloor3 => ((-storey2 - storey3) / m2, storey3),
    };
    (
        [
            (fe - c1 * v[0] - k1 * y[0] + storey2) / m1,
            a2,
            storey3 / m3,
        ],
        fm,
    )
}

/// The assembly cut at `split` with amplitude error `a_err`, driven by `excitation` (N on
/// floor 1) at step `dt`, RK4 with `substeps` sub-steps a sample.
pub fn run(
    s: &Structure,
    split: Split,
    excitation: &[f64],
    dt: f64,
    substeps: u32,
    a_err: f64,
) -> Result<HybridRun> {
    let h = super::check_inputs(s, excitation, dt, substeps)?;
    if !(a_err.is_finite() && a_err > -1.0) {
        return Err(HybridError::Setup(format!(
            "the amplitude error must be a finite number above −1, was {a_err}"
        )));
    }
    let gain = 1.0 + a_err;
    let mut out = HybridRun {
        excitation: excitation.to_vec(),
        max_relative: f64::NEG_INFINITY,
        split,
        ..HybridRun::default()
    };
    out.interface.step = h;
    let (mut y, mut v) = ([0.0; 3], [0.0; 3]);
    let mut closed = false;
    let add = |a: [f64; 3], b: [f64; 3], c: f64| [0, 1, 2].map(|i| a[i] + c * b[i]);
    for k in 0..excitation.len() {
        let t = k as f64 * dt;
        let (_, fm) = rates(s, split, a_err, y, v, excitation[k]);
        out.time.push(t);
        out.y1.push(y[0]);
        out.y2n.push(y[1]);
        out.y2p.push(gain * y[1]);
        out.y3.push(y[2]);
        out.force.push(fm);
        if k + 1 == excitation.len() {
            break;
        }
        let slope = (excitation[k + 1] - excitation[k]) / dt;
        for j in 0..substeps {
            let fe = |tau: f64| excitation[k] + slope * (f64::from(j) * h + tau);
            let a1 = rates(s, split, a_err, y, v, fe(0.0)).0;
            let (y2, v2) = (add(y, v, h / 2.0), add(v, a1, h / 2.0));
            let a2 = rates(s, split, a_err, y2, v2, fe(h / 2.0)).0;
            let (y3, v3) = (add(y, v2, h / 2.0), add(v, a2, h / 2.0));
            let a3 = rates(s, split, a_err, y3, v3, fe(h / 2.0)).0;
            let (y4, v4) = (add(y, v3, h), add(v, a3, h));
            let a4 = rates(s, split, a_err, y4, v4, fe(h)).0;
            for i in 0..3 {
                y[i] += h / 6.0 * (v[i] + 2.0 * v2[i] + 2.0 * v3[i] + v4[i]);
                v[i] += h / 6.0 * (a1[i] + 2.0 * a2[i] + 2.0 * a3[i] + a4[i]);
            }
            let (a, fm) = rates(s, split, a_err, y, v, fe(h));
            let yr = gain * y[1] - y[2];
            out.interface.a2p.push(gain * a[1]);
            out.interface.y2n.push(y[1]);
            out.interface.y2p.push(gain * y[1]);
            out.interface.y3.push(y[2]);
            out.interface.force.push(fm);
            out.max_relative = out.max_relative.max(yr);
            let now = yr > s.gap;
            if now && !closed {
                out.contact_times.push(t + f64::from(j + 1) * h);
            }
            closed = now;
            if !(y.iter().chain(&v).all(|x| x.is_finite())) {
                return Err(HybridError::Setup(format!(
                    "non-finite state at t = {:.4} s",
                    t + f64::from(j + 1) * h
                )));
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use fmu_shear::effects::Effects;
    use fmu_shear::model::RampInput;
    use fmu_shear::{ShearModel, ShearParameters};

    /// With perfect control and the bumper open, the assembly cut either way is the shear FMU's own model
    /// (RK4, the same sub-steps, the force linear between samples): floor 2's displacement
    /// agrees to rounding (measured 5.4e-15 of its peak).
    #[test]
    fn perfect_control_is_the_whole_structure_to_rounding() {
        let s = Structure {
            mass: [4.6, 5.3, 4.9],
            damping: [8.0, 3.5, 2.6],
            stiffness: [3850.0, 4100.0, 4650.0],
            gap: 1.0,
            contact_stiffness: 9000.0,
        };
        let dt = 1.0 / 51.2;
        let force: Vec<f64> = (0..1024)
            .map(|k| {
                let t = k as f64 * dt;
                (2.0 * std::f64::consts::PI * 4.0 * t).sin() + 0.3 * (7.1 * t).cos()
            })
            .collect();
        let substeps = 16;
        for split in Split::ALL {
            let hybrid = run(&s, split, &force, dt, substeps, 0.0).expect("run");
            let params = ShearParameters {
                mass: s.mass.to_vec(),
                damping: s.damping.to_vec(),
                stiffness: s.stiffness.to_vec(),
                substeps,
                ..ShearParameters::default()
            };
            let mut model = ShearModel::new(params, Effects::default());
            let mut whole = vec![0.0];
            for k in 0..force.len() - 1 {
                let slope = (force[k + 1] - force[k]) / dt;
                model.force = RampInput {
                    value: force[k],
                    slope,
                };
                model.advance(dt);
                whole.push(model.displacement[1]);
            }
            let peak = whole.iter().fold(0.0f64, |m, x| m.max(x.abs()));
            let worst = hybrid
                .y2p
                .iter()
                .zip(&whole)
                .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
            eprintln!(
                "{split}: largest difference {:.2e} of the peak",
                worst / peak
            );
            assert!(worst <= 1e-9 * peak, "{}", worst / peak);
        }
    }
}
