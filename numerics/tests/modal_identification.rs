//! Modal identification on synthetic records of known M, C, K: the modes found by SSI-COV
//! (output-only) and by LSCF + LSFD (input–output), chosen automatically from their
//! stabilisation diagrams, against the exact modes of `numerics::modal::eigen`.
//!
//! The records: shear buildings of 3 and 5 storeys (unequal floors and storeys), Rayleigh
//! damping of 1 % on the first mode and 2 % on the last, a white-noise force at the top floor,
//! simulated with the exact zero-order-hold discretisation of the state space (nalgebra's matrix
//! exponential), every floor's absolute acceleration measured with white noise of 2 % of its
//! RMS. Fixed seeds.

use nalgebra::{DMatrix, DVector};
use numerics::modal::spectral::{Run, Welch};
use numerics::modal::stabilisation::{
    select_modes, IdentifiedMode, SelectionOptions, StabilisationDiagram, StabilityTolerances,
};
use numerics::modal::{lscf, mac, modes, ssi, Mode};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

struct Building {
    m: DMatrix<f64>,
    c: DMatrix<f64>,
    k: DMatrix<f64>,
}

/// Floors' masses (kg) and storeys' stiffnesses (N/m), damping `(ζ_first, ζ_last)` Rayleigh.
fn building(mass: &[f64], stiffness: &[f64], damping: (f64, f64)) -> Building {
    let n = mass.len();
    let m = DMatrix::from_diagonal(&DVector::from_column_slice(mass));
    let mut k = DMatrix::zeros(n, n);
    for (i, ki) in stiffness.iter().enumerate() {
        k[(i, i)] += ki;
        if i > 0 {
            k[(i - 1, i - 1)] += ki;
            k[(i - 1, i)] -= ki;
            k[(i, i - 1)] -= ki;
        }
    }
    let undamped = modes(&m, &DMatrix::zeros(n, n), &k).expect("undamped modes");
    let w1 = undamped[0].eigenvalue.norm();
    let wn = undamped[n - 1].eigenvalue.norm();
    // ζ(ω) = a / 2ω + b ω / 2 through both targets.
    let b = 2.0 * (damping.1 * wn - damping.0 * w1) / (wn * wn - w1 * w1);
    let a = 2.0 * damping.0 * w1 - b * w1 * w1;
    let c = &m * a + &k * b;
    Building { m, c, k }
}

/// A record: the force at the top floor and every floor's absolute acceleration.
struct Record {
    dt: f64,
    force: Vec<f64>,
    accelerations: Vec<Vec<f64>>,
}

fn simulate(building: &Building, dt: f64, samples: usize, seed: u64) -> Record {
    let n = building.m.nrows();
    let m_inv = building.m.clone().try_inverse().expect("mass invertible");
    let mut load = DVector::zeros(n);
    load[n - 1] = 1.0;
    let mk = -(&m_inv * &building.k);
    let mc = -(&m_inv * &building.c);
    let ml = &m_inv * &load;
    // Augmented [[A, B], [0, 0]] so one exponential gives Ad and Bd.
    let mut augmented = DMatrix::zeros(2 * n + 1, 2 * n + 1);
    let mut output = DMatrix::zeros(n, 2 * n);
    for i in 0..n {
        augmented[(i, n + i)] = 1.0;
        augmented[(n + i, 2 * n)] = ml[i];
        for j in 0..n {
            augmented[(n + i, j)] = mk[(i, j)];
            augmented[(n + i, n + j)] = mc[(i, j)];
            output[(i, j)] = mk[(i, j)];
            output[(i, n + j)] = mc[(i, j)];
        }
    }
    let exponential = (augmented * dt).exp();
    let ad = exponential.view((0, 0), (2 * n, 2 * n)).into_owned();
    let bd = exponential.view((0, 2 * n), (2 * n, 1)).into_owned();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let unit = Normal::new(0.0, 1.0).expect("unit normal");
    // A force of about the building's weight / 100 keeps the numbers physical.
    let scale = 0.01 * 9.81 * building.m.trace();
    let force: Vec<f64> = (0..samples)
        .map(|_| scale * unit.sample(&mut rng))
        .collect();
    let mut state = DVector::zeros(2 * n);
    let mut accelerations = vec![Vec::with_capacity(samples); n];
    for u in &force {
        let y = &output * &state + &ml * *u;
        for (channel, value) in accelerations.iter_mut().zip(y.iter()) {
            channel.push(*value);
        }
        state = &ad * &state + &bd * *u;
    }
    for channel in &mut accelerations {
        let rms = (channel.iter().map(|v| v * v).sum::<f64>() / samples as f64).sqrt();
        for v in channel.iter_mut() {
            *v += 0.02 * rms * unit.sample(&mut rng);
        }
    }
    Record {
        dt,
        force,
        accelerations,
    }
}

struct Errors {
    frequency: f64,
    damping: f64,
    mac: f64,
}

/// Pairs each exact mode with the identified mode nearest in frequency; the worst relative
/// frequency and damping errors and the least MAC.
fn compare(exact: &[Mode], identified: &[IdentifiedMode], method: &str) -> Errors {
    assert_eq!(
        identified.len(),
        exact.len(),
        "{method}: {} modes identified, {} exact: {:?}",
        identified.len(),
        exact.len(),
        identified
            .iter()
            .map(|m| (m.frequency, m.damping))
            .collect::<Vec<_>>()
    );
    let mut errors = Errors {
        frequency: 0.0,
        damping: 0.0,
        mac: 1.0,
    };
    for (e, i) in exact.iter().zip(identified) {
        let frequency = (i.frequency / e.frequency - 1.0).abs();
        let damping = (i.damping / e.damping - 1.0).abs();
        let shape = mac(&e.shape, &i.shape);
        println!(
            "{method}: exact {:.4} Hz {:.4} %, identified {:.4} ± {:.4} Hz {:.4} ± {:.4} %, \
             MAC {:.5}, MPC {:.4}, MPD {:.2}°, {} orders",
            e.frequency,
            100.0 * e.damping,
            i.frequency,
            i.frequency_sd,
            100.0 * i.damping,
            100.0 * i.damping_sd,
            shape,
            i.mpc,
            i.mpd,
            i.orders.len()
        );
        errors.frequency = errors.frequency.max(frequency);
        errors.damping = errors.damping.max(damping);
        errors.mac = errors.mac.min(shape);
    }
    println!(
        "{method}: worst frequency error {:.3} %, damping {:.2} %, least MAC {:.5}",
        100.0 * errors.frequency,
        100.0 * errors.damping,
        errors.mac
    );
    errors
}

fn identify_ssi(record: &Record, options: &ssi::SsiOptions) -> Vec<IdentifiedMode> {
    let outputs: Vec<&[f64]> = record.accelerations.iter().map(|c| c.as_slice()).collect();
    let run = Run {
        input: None,
        outputs: &outputs,
    };
    let orders = ssi::ssi_cov(&[run], record.dt, options).expect("SSI-COV");
    let diagram =
        StabilisationDiagram::new(orders, StabilityTolerances::default()).expect("diagram");
    select_modes(&diagram, &SelectionOptions::default()).expect("selection")
}

fn identify_lscf(
    record: &Record,
    segment: usize,
    options: &lscf::LscfOptions,
) -> Vec<IdentifiedMode> {
    let outputs: Vec<&[f64]> = record.accelerations.iter().map(|c| c.as_slice()).collect();
    let run = Run {
        input: Some(&record.force),
        outputs: &outputs,
    };
    let frf = Welch::new(record.dt, segment)
        .expect("welch")
        .h1(&[run])
        .expect("H1");
    let orders = lscf::lscf(&frf, options).expect("LSCF");
    let diagram =
        StabilisationDiagram::new(orders, StabilityTolerances::default()).expect("diagram");
    select_modes(&diagram, &SelectionOptions::default()).expect("selection")
}

fn three_storeys() -> Building {
    building(&[6.0, 5.2, 4.5], &[4500.0, 4021.0, 3600.0], (0.01, 0.02))
}

fn five_storeys() -> Building {
    building(
        &[1.2e4, 1.1e4, 1.0e4, 0.9e4, 0.8e4],
        &[2.4e7, 2.2e7, 2.0e7, 1.8e7, 1.5e7],
        (0.01, 0.02),
    )
}

#[test]
fn ssi_cov_finds_the_exact_modes_output_only() {
    for (name, building, seed) in [
        ("3 storeys", three_storeys(), 11),
        ("5 storeys", five_storeys(), 12),
    ] {
        let exact = modes(&building.m, &building.c, &building.k).expect("exact modes");
        let record = simulate(&building, 0.01, 120_000, seed);
        let identified = identify_ssi(&record, &ssi::SsiOptions::default());
        // Exactly the physical modes (no spurious ones), at the bars (0.5 %, 10 %,
        // MAC 0.99). Measured (20 min at 100 Hz, orders 2..40): 3 storeys worst frequency
        // error 0.083 %, damping 4.6 %, least MAC 0.99999; 5 storeys 0.14 %, 4.2 %, 0.9993.
        let errors = compare(&exact, &identified, &format!("SSI-COV, {name}"));
        assert!(
            errors.frequency < 0.005,
            "{name}: frequency {}",
            errors.frequency
        );
        assert!(errors.damping < 0.10, "{name}: damping {}", errors.damping);
        assert!(errors.mac > 0.99, "{name}: MAC {}", errors.mac);
    }
}

#[test]
fn lscf_finds_the_exact_modes_input_output() {
    for (name, building, seed, band) in [
        ("3 storeys", three_storeys(), 21, (0.5, 12.0)),
        ("5 storeys", five_storeys(), 22, (0.5, 20.0)),
    ] {
        let exact = modes(&building.m, &building.c, &building.k).expect("exact modes");
        let record = simulate(&building, 0.01, 120_000, seed);
        let identified = identify_lscf(&record, 1 << 14, &lscf::LscfOptions::over(band));
        // Exactly the physical modes, at the bars. Measured (H1 of 14 segments of
        // 164 s, orders 2..40): 3 storeys worst frequency error 0.003 %, damping 1.4 %, least
        // MAC 1.00000; 5 storeys 0.001 %, 1.6 %, 1.00000 (the Hann window's leakage biases the
        // damping up by about 1.5 %).
        let errors = compare(&exact, &identified, &format!("LSCF, {name}"));
        assert!(
            errors.frequency < 0.005,
            "{name}: frequency {}",
            errors.frequency
        );
        assert!(errors.damping < 0.10, "{name}: damping {}", errors.damping);
        assert!(errors.mac > 0.99, "{name}: MAC {}", errors.mac);
    }
}
