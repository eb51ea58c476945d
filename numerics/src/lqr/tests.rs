use super::*;
use structure::{Excitation, Structure};

fn frame() -> Structure {
    Structure::uniform(3, 5.2, 0.5, 4021.0, Excitation::Force { floor: 1 })
}

/// The shear building's model with the actuator at floor 1, where the shaker is.
fn plant(s: &Structure, state_scale: f64) -> Result<StateSpace, String> {
    let ss = s.state_space().map_err(|e| e.to_string())?;
    let (b, d) = s.force_input(1).map_err(|e| e.to_string())?;
    StateSpace::from_si(&ss.a, &ss.c, (&ss.b, &ss.d), (&b, &d), state_scale)
        .map_err(|e| e.to_string())
}

/// A in millimetres equals A in metres; B scales with 1/state_scale.
#[test]
fn state_units_scale_b_not_a() {
    let m = plant(&frame(), 1.0).expect("valid");
    let mm = plant(&frame(), 1e-3).expect("valid");
    assert_eq!(m.a, mm.a);
    assert!((mm.b[3] - 1000.0 * m.b[3]).abs() < 1e-12);
    assert!((m.b[3] - 1.0 / 5.2).abs() < 1e-15);
    // The accelerations of a static displacement are −M⁻¹K y.
    let w = DVector::from_column_slice(&[1e-3, 0.0, 0.0, 0.0, 0.0, 0.0]);
    let z = &m.c * w;
    assert!((z[0] + 2.0 * 4021.0 * 1e-3 / 5.2).abs() < 1e-12);
    assert!((z[1] - 4021.0 * 1e-3 / 5.2).abs() < 1e-12);
}

#[test]
fn bad_parameters_are_refused() {
    let mut bad = frame();
    bad.mass[1] = 0.0;
    assert!(plant(&bad, 1.0).is_err());
    bad = frame();
    bad.stiffness[2] = f64::NAN;
    assert!(plant(&bad, 1.0).is_err());
    let ok = plant(&frame(), 1.0).expect("valid");
    let integrate = Estimator::Integrate { highpass_hz: 0.2 };
    assert!(Controller::new(&ok, &[f64::NAN; 6], &integrate, 1e-3).is_err());
    assert!(Controller::new(&ok, &[0.0; 6], &integrate, 0.0).is_err());
    let kalman = Estimator::Kalman {
        process_sd: 0.1,
        sensor_sd: vec![0.01, -1.0, 0.01],
    };
    assert!(Controller::new(&ok, &[0.0; 6], &kalman, 1e-3).is_err());
}

/// The integrating estimator recovers a sine's velocity and displacement well above its
/// corner frequency, to the leak's own error.
#[test]
fn integration_recovers_velocity_and_displacement_of_a_resonance() {
    let model = plant(&frame(), 1.0).expect("valid");
    let dt = 1.0 / 1000.0;
    let f = 5.0;
    let w = 2.0 * std::f64::consts::PI * f;
    let mut c = Controller::new(
        &model,
        &[0.0; 6],
        &Estimator::Integrate { highpass_hz: 0.1 },
        dt,
    )
    .expect("valid");
    // From rest, a = sin(wt) integrates to v = (1 − cos wt)/w and a ramp in y; the leak
    // forgets those offsets, leaving v = −cos(wt)/w and y = −sin(wt)/w².
    let mut worst = 0.0f64;
    for k in 0..45_000 {
        let t = k as f64 * dt;
        let a = (w * t).sin();
        c.step(&[a, 0.0, 0.0], 0.0).expect("three accelerations");
        if t > 35.0 {
            let e = c.estimate_si();
            let (y, v) = (-(w * t).sin() / (w * w), -(w * t).cos() / w);
            worst = worst
                .max((e[0] - y).abs() * w * w)
                .max((e[3] - v).abs() * w);
        }
    }
    // Each leaky integration errs by f_c/|f + j f_c| ≈ 0.02 at 5 Hz: 0.04 for y.
    assert!(worst < 0.045, "relative error {worst}");
}

/// The Kalman observer converges to the true state of the model it runs on, from noisy
/// accelerations.
#[test]
fn kalman_observer_tracks_the_model() {
    let sm = frame();
    let model = plant(&sm, 1e-3).expect("valid");
    let dt = 1.0 / 409.6;
    let mut c = Controller::new(
        &model,
        &[0.0; 6],
        &Estimator::Kalman {
            process_sd: 0.05,
            sensor_sd: vec![1e-3; 3],
        },
        dt,
    )
    .expect("valid");
    // The truth: the same model stepped exactly with a smooth force, held per interval.
    let mut m = nalgebra::DMatrix::<f64>::zeros(7, 7);
    for i in 0..6 {
        for j in 0..6 {
            m[(i, j)] = model.a[(i, j)] * dt;
        }
        m[(i, 6)] = model.excitation_b[i] * dt;
    }
    let e = m.exp();
    let mut w = DVector::<f64>::zeros(6);
    let mut worst = 0.0f64;
    let mut peak = 0.0f64;
    for k in 0..8000 {
        let t = k as f64 * dt;
        let force = (2.0 * std::f64::consts::PI * 3.0 * t).sin()
            + 0.5 * (2.0 * std::f64::consts::PI * 7.3 * t).sin();
        let z = &model.c * &w + &model.excitation_d * force;
        let acc = [z[0] * 1e-3, z[1] * 1e-3, z[2] * 1e-3];
        c.step(&acc, force).expect("three accelerations");
        if t > 5.0 {
            let est = c.estimate_si();
            for i in 0..6 {
                worst = worst.max((est[i] - w[i] * 1e-3).abs());
                peak = peak.max((w[i] * 1e-3).abs());
            }
        }
        // Advance the truth with the force held (the observer assumes it linear: the
        // difference is the model error the process noise covers).
        let mut next = DVector::<f64>::zeros(6);
        for i in 0..6 {
            next[i] = (0..6).map(|j| e[(i, j)] * w[j]).sum::<f64>() + e[(i, 6)] * force;
        }
        w = next;
    }
    assert!(worst < 0.05 * peak, "worst {worst} of peak {peak}");
}

/// The model measuring the accelerations of `floors` (1-based) alone.
fn measuring(s: &Structure, floors: &[usize]) -> StateSpace {
    let full = plant(s, 1.0).expect("valid");
    let pick =
        |m: &DMatrix<f64>| DMatrix::from_fn(floors.len(), m.ncols(), |i, j| m[(floors[i] - 1, j)]);
    let pick_v =
        |v: &DVector<f64>| DVector::from_iterator(floors.len(), floors.iter().map(|&f| v[f - 1]));
    StateSpace {
        c: pick(&full.c),
        d: pick_v(&full.d),
        excitation_d: pick_v(&full.excitation_d),
        ground_in_reading: DVector::zeros(floors.len()),
        ..full
    }
}

/// A uniform chain of four storeys has mode shapes sin((2j − 1)π i / 9): the second mode
/// stands still at floor 3, so an accelerometer there alone cannot see it (both its
/// eigenvalues are named), and the Kalman observer refuses it; floor 2 or floors 1 and 3
/// see every mode.
#[test]
fn a_mode_with_a_node_at_every_sensor_is_unobservable() {
    let s = Structure::uniform(4, 5.2, 0.5, 4021.0, Excitation::Force { floor: 1 });
    let blind = measuring(&s, &[3]);
    let missed = blind.unobservable();
    assert_eq!(missed.len(), 2, "{missed:?}");
    // The second mode of the undamped chain: ω² = 4 (k/m) sin²(3π/18).
    let w2 = (4.0 * 4021.0 / 5.2 * (3.0 * std::f64::consts::PI / 18.0).sin().powi(2)).sqrt();
    for e in &missed {
        assert!(
            (e[0].hypot(e[1]) - w2).abs() < 1e-6 * w2,
            "{e:?} against {w2}"
        );
    }
    let kalman = Estimator::Kalman {
        process_sd: 0.1,
        sensor_sd: vec![0.01],
    };
    assert!(matches!(
        Controller::new(&blind, &[0.0; 8], &kalman, 1e-3),
        Err(LqrError::Unobservable(_))
    ));
    assert!(measuring(&s, &[2]).unobservable().is_empty());
    assert!(measuring(&s, &[1, 3]).unobservable().is_empty());
    assert!(plant(&s, 1.0).expect("valid").unobservable().is_empty());
}

/// Under ground motion the accelerometers read `ÿ + a_g`: the integrating estimator takes
/// the ground's part out, so a ground acceleration that moves nothing relative to it
/// integrates to no relative motion.
#[test]
fn integration_removes_the_grounds_part_of_the_reading() {
    let s = Structure::uniform(2, 5.2, 0.5, 4021.0, Excitation::Base);
    let ss = s.state_space().expect("valid");
    let (b, d) = s.force_input(1).expect("floor 1");
    let model = StateSpace::from_si(&ss.a, &ss.c, (&ss.b, &ss.d), (&b, &d), 1.0)
        .expect("valid")
        .with_ground_in_reading(DVector::from_element(2, 1.0))
        .expect("two readings");
    let mut c = Controller::new(
        &model,
        &[0.0; 4],
        &Estimator::Integrate { highpass_hz: 0.1 },
        1e-3,
    )
    .expect("valid");
    for k in 0..2000 {
        let a_g = (k as f64 * 0.01).sin();
        // A rigid structure moving with the ground: the readings are the ground's.
        c.step(&[a_g, a_g], a_g).expect("two readings");
    }
    assert!(c.estimate_si().iter().all(|x| x.abs() < 1e-15));
}

#[test]
fn schedule_switches_up_near_the_gap_and_back_after_the_dwell() {
    let mut s = Scheduler::new(
        Schedule {
            storey: 3,
            gap: 5e-4,
            side: -1,
            margin: 0.3,
            lookahead: 0.0,
            dwell: 0.5,
            variance_threshold: None,
        },
        3,
    )
    .expect("valid");
    let at = |drift: f64| [0.0, 0.0, drift, 0.0, 0.0, 0.0];
    assert!(!s.decide(0.0, &at(-3e-4), None), "far from the gap");
    assert!(
        !s.decide(0.1, &at(4e-4), None),
        "the positive side does not close it"
    );
    assert!(s.decide(0.2, &at(-4e-4), None), "within 30 % of closing");
    assert!(s.decide(0.5, &at(0.0), None), "held during the dwell");
    assert!(!s.decide(0.71, &at(0.0), None), "released after the dwell");
    assert!(Scheduler::new(
        Schedule {
            margin: 1.5,
            ..s.schedule.clone()
        },
        3
    )
    .is_err());
}
