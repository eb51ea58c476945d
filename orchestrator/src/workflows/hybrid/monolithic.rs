//! The hybrid assembly solved as one ODE, for an actuator without dynamics.
//!
//! When the actuator only scales (`y_jp = (1 + a_err) y_jn`, no delay, no lag) the loop is
//! algebraic: the substructures and the actuator are one system of ODEs in (y₁ .. y_jn ..
//! y_N), which is what the reference paper integrates for its Fig. 14 (its "simplified
//! simulation", the actuator without delay). Cut as the paper cuts it
//! ([`Split::FloorPhysical`]), eq (14) with the measured force of eq (13) makes floor j's
//! equation `m_j (1 + a_err) ÿ_jn = S_j − [c_{j+1} (ẏ_jp − ẏ_{j+1}) + k_{j+1} (y_jp −
//! y_{j+1}) + F_nl]` (`S_j` the numerical side's forces on floor j; the paper's N = 3, j = 2:
//! `S₂ = c₂ (ẏ₁ − ẏ₂ₙ) + k₂ (y₁ − y₂ₙ)`): the specimen's floor j moves at `(1 + a_err) ÿ_jn`.
//! With floor j numerical ([`Split::FloorNumerical`]) its mass is `m_j` alone. Solved here with RK4 at `substeps` sub-steps a sample and the
//! excitation linear between samples — the very scheme of the shear FMU — so with perfect
//! control it is the whole structure, to rounding. An actuator with dynamics needs the
//! stepped loop of [`super::run`].

use super::{Frame, HybridError, HybridRun, Result, Split};

/// Accelerations of all floors (1..j numerical, j+1..N physical; floor j's the numerical
/// side's y_jn) into `a`, and the measured force, at states `y`, `v`.
fn rates(s: &Frame, split: Split, a_err: f64, y: &[f64], v: &[f64], fe: f64, a: &mut [f64]) -> f64 {
    let n = y.len();
    let jf = s.floor - 1;
    let gain = 1.0 + a_err;
    // Storey i's extension force (0-based storey i joins floors i − 1 and i), i ≥ 1.
    let storey = |i: usize| s.damping[i] * (v[i] - v[i - 1]) + s.stiffness[i] * (y[i] - y[i - 1]);
    // The forces on floor i from below (with the excitation on floor 1).
    let below = |i: usize| {
        if i == 0 {
            fe - s.damping[0] * v[0] - s.stiffness[0] * y[0]
        } else {
            -storey(i)
        }
    };
    for i in 0..jf {
        a[i] = (below(i) + storey(i + 1)) / s.mass[i];
    }
    let (yjp, vjp) = (gain * y[jf], gain * v[jf]);
    let from_numerical = below(jf);
    // Storey j+1 with the bumper, floor j at the achieved motion.
    let above = s.damping[jf + 1] * (vjp - v[jf + 1])
        + s.stiffness[jf + 1] * (yjp - y[jf + 1])
        + s.contact_force(yjp - y[jf + 1]);
    let fm = match split {
        // F_m = m_j ÿ_jp + storey j+1 = the numerical side's force on floor j (eq 14).
        Split::FloorPhysical => {
            a[jf] = (from_numerical - above) / (s.mass[jf] * gain);
            from_numerical
        }
        Split::FloorNumerical => {
            a[jf] = (from_numerical - above) / s.mass[jf];
            above
        }
    };
    // The specimen's floors j+1..N, their bottom at the achieved motion.
    let mut below_force = above;
    for i in jf + 1..n {
        a[i] = if i + 1 < n {
            // Storey i + 1's force on floor i + 1 from below; floor i takes its reaction.
            let up = -storey(i + 1);
            let total = below_force - up;
            below_force = up;
            total
        } else {
            below_force
        } / s.mass[i];
    }
    fm
}

/// The assembly of `s` cut at its floor j as `split` says, with amplitude error `a_err`, driven
/// by `excitation` (N on floor 1) at step `dt`, RK4 with `substeps` sub-steps a sample.
pub fn run(
    s: &Frame,
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
    let n = s.storeys();
    let jf = s.floor - 1;
    let (mut y, mut v) = (vec![0.0; n], vec![0.0; n]);
    let mut closed = false;
    let add = |a: &[f64], b: &[f64], c: f64| -> Vec<f64> {
        a.iter().zip(b).map(|(x, z)| x + c * z).collect()
    };
    let rate = |y: &[f64], v: &[f64], fe: f64| {
        let mut a = vec![0.0; n];
        let fm = rates(s, split, a_err, y, v, fe, &mut a);
        (a, fm)
    };
    for k in 0..excitation.len() {
        let t = k as f64 * dt;
        let (_, fm) = rate(&y, &v, excitation[k]);
        out.time.push(t);
        out.y1.push(y[0]);
        out.yjn.push(y[jf]);
        out.yjp.push(gain * y[jf]);
        out.y_above.push(y[jf + 1]);
        out.force.push(fm);
        if k + 1 == excitation.len() {
            break;
        }
        let slope = (excitation[k + 1] - excitation[k]) / dt;
        for j in 0..substeps {
            let fe = |tau: f64| excitation[k] + slope * (f64::from(j) * h + tau);
            let a1 = rate(&y, &v, fe(0.0)).0;
            let (y2, v2) = (add(&y, &v, h / 2.0), add(&v, &a1, h / 2.0));
            let a2 = rate(&y2, &v2, fe(h / 2.0)).0;
            let (y3, v3) = (add(&y, &v2, h / 2.0), add(&v, &a2, h / 2.0));
            let a3 = rate(&y3, &v3, fe(h / 2.0)).0;
            let (y4, v4) = (add(&y, &v3, h), add(&v, &a3, h));
            let a4 = rate(&y4, &v4, fe(h)).0;
            for i in 0..n {
                y[i] += h / 6.0 * (v[i] + 2.0 * v2[i] + 2.0 * v3[i] + v4[i]);
                v[i] += h / 6.0 * (a1[i] + 2.0 * a2[i] + 2.0 * a3[i] + a4[i]);
            }
            let (a, fm) = rate(&y, &v, fe(h));
            let yr = gain * y[jf] - y[jf + 1];
            out.interface.ajp.push(gain * a[jf]);
            out.interface.yjn.push(y[jf]);
            out.interface.yjp.push(gain * y[jf]);
            out.interface.y_above.push(y[jf + 1]);
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
        let s = Frame {
            mass: vec![4.6, 5.3, 4.9],
            damping: vec![8.0, 3.5, 2.6],
            stiffness: vec![3850.0, 4100.0, 4650.0],
            floor: 2,
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
                mass: s.mass.clone(),
                damping: s.damping.clone(),
                stiffness: s.stiffness.clone(),
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
                .yjp
                .iter()
                .zip(&whole)
                .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
            eprintln!(
                "{split:?}: largest difference {:.2e} of the peak",
                worst / peak
            );
            assert!(worst <= 1e-9 * peak, "{}", worst / peak);
        }
    }
    /// Five storeys cut at floor 3 and four cut at floor 1, either way: with perfect control
    /// and the bumper open the one-ODE assembly is the shear FMU's model of the whole building
    /// (`ShearParameters::from_structure`), floor j's displacement to rounding
    /// (measured 2.5e-14 and 3.0e-14 of the peak; the limit is the paper rig's test's).
    #[test]
    fn perfect_control_is_the_whole_structure_of_other_buildings() {
        let dt = 1.0 / 51.2;
        let force: Vec<f64> = (0..1024)
            .map(|k| {
                let t = k as f64 * dt;
                (2.0 * std::f64::consts::PI * 4.0 * t).sin() + 0.3 * (7.1 * t).cos()
            })
            .collect();
        let substeps = 16;
        for s in crate::workflows::hybrid::tests::other_buildings() {
            let building = structure::Structure {
                mass: s.mass.clone(),
                damping: s.damping.clone(),
                stiffness: s.stiffness.clone(),
                excitation: structure::Excitation::Force { floor: 1 },
            };
            let params = ShearParameters {
                substeps,
                ..ShearParameters::from_structure(&building)
            };
            let mut model = ShearModel::new(params, Effects::default());
            let mut whole = vec![0.0];
            for k in 0..force.len() - 1 {
                model.force = RampInput {
                    value: force[k],
                    slope: (force[k + 1] - force[k]) / dt,
                };
                model.advance(dt);
                whole.push(model.displacement[s.floor - 1]);
            }
            let peak = whole.iter().fold(0.0f64, |m, x| m.max(x.abs()));
            for split in Split::ALL {
                let hybrid = run(&s, split, &force, dt, substeps, 0.0).expect("run");
                let worst = hybrid
                    .yjp
                    .iter()
                    .zip(&whole)
                    .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
                eprintln!(
                    "N {}, j {}, {split:?}: largest difference {:.2e} of the peak",
                    s.storeys(),
                    s.floor,
                    worst / peak
                );
                assert!(worst <= 1e-9 * peak, "{}", worst / peak);
            }
        }
    }
}
