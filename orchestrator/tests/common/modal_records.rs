//! Records of buildings unlike the twin's own for the modal identification tests (band-limited
//! forces, light damping, coloured sensor noise, one accelerometer per run, made by `twin
//! synth`'s generator), and how a method's modes are matched against the exact ones.

use numerics::modal::stabilisation::IdentifiedMode;
use numerics::modal::{modes, Mode};
use orchestrator::record::Measurement;
use orchestrator::synth::{synth_record, NoiseLevel, Scenario};
use orchestrator::workflows::modal::identify::{RecordMode, RecordModes};
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use structure::channel::{Channel, Quantity, Unit};
use structure::Excitation;

/// A record of a building (`mass` kg per floor, `stiffness` N/m, `damping` N s/m per storey)
/// under a force at `floor`, band-limited to `band` Hz, measured at `floors` by
/// accelerometers with white noise of 2 % of each channel's RMS plus coloured noise (a
/// first-order low-pass of white noise, pole 0.98 per sample: most of its power below
/// 1 % of the sample rate) of `coloured` × the channel's RMS.
#[allow(clippy::too_many_arguments)]
pub fn record(
    storeys: usize,
    (mass, stiffness, damping): (&[f64], &[f64], &[f64]),
    floor: usize,
    (rate, duration): (f64, f64),
    band: (f64, f64),
    floors: &[usize],
    coloured: f64,
    seed: u64,
) -> (Measurement, Vec<Mode>) {
    let mut s = Scenario::default();
    s.set_storeys(storeys);
    s.mass = mass.to_vec();
    s.stiffness = stiffness.to_vec();
    s.damping = damping.to_vec();
    s.excitation = Excitation::Force { floor };
    s.seed = seed;
    s.sample_rate = rate;
    s.duration = duration;
    s.oversample = 16;
    s.force.low_hz = band.0;
    s.force.band_hz = Some(band.1);
    s.force.rms = 1.0;
    s.noise.level = NoiseLevel::Fraction(vec![0.02]);
    s.channels = Some(
        floors
            .iter()
            .map(|&floor| {
                (
                    Channel::Response {
                        quantity: Quantity::Acceleration,
                        floor,
                    },
                    Unit::MetrePerSecond2,
                )
            })
            .collect(),
    );
    s.validate("test").expect("a valid scenario");
    let (mut made, _) = synth_record(&s).expect("a record");
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed + 1000);
    for signal in &mut made.measurement.responses {
        let n = signal.values.len() as f64;
        let rms = (signal.values.iter().map(|v| v * v).sum::<f64>() / n).sqrt();
        let mut state = 0.0;
        let drift: Vec<f64> = (0..signal.values.len())
            .map(|_| {
                let w: f64 = StandardNormal.sample(&mut rng);
                state = 0.98 * state + w;
                state
            })
            .collect();
        let drift_rms = (drift.iter().map(|v| v * v).sum::<f64>() / n).sqrt();
        for (v, d) in signal.values.iter_mut().zip(&drift) {
            *v += coloured * rms * d / drift_rms;
        }
    }
    let structure = s.structure();
    let exact = modes(
        &structure.mass_matrix(),
        &structure.damping_matrix(),
        &structure.stiffness_matrix(),
    )
    .expect("exact modes");
    (made.measurement, exact)
}

/// Per exact mode, the found mode nearest in frequency and its relative frequency error;
/// and the found modes no exact mode is within 1 % of (spurious).
pub fn matched(found: &[f64], exact: &[Mode]) -> (Vec<(usize, f64)>, Vec<f64>) {
    let nearest = exact
        .iter()
        .map(|e| {
            found
                .iter()
                .enumerate()
                .map(|(i, f)| (i, f / e.frequency - 1.0))
                .min_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
                .unwrap_or((usize::MAX, f64::INFINITY))
        })
        .collect();
    let spurious = found
        .iter()
        .copied()
        .filter(|f| exact.iter().all(|e| (f / e.frequency - 1.0).abs() > 0.01))
        .collect();
    (nearest, spurious)
}

/// The damping bar: `m`'s damping within the larger of 10 % of the exact mode's and
/// 2.5 of its reported sds.
pub fn damping_within_bar(m: &IdentifiedMode, e: &Mode) -> bool {
    (m.damping - e.damping).abs() <= (0.10 * e.damping).max(2.5 * m.damping_sd)
}

/// Every exact mode found by LSCF within the 0.5 % and its damping within the
/// larger of 10 % and 2.5 reported sds, and no LSCF mode 1 % from every exact one.
pub fn lscf_holds_every_mode(found: &RecordModes, exact: &[Mode]) {
    let io = found.input_output.as_ref().expect("LSCF ran");
    let (nearest, spurious) = matched(&lscf_frequencies(found), exact);
    for ((i, error), e) in nearest.iter().zip(exact) {
        let m = &io.modes[*i].identified;
        println!(
            "{:.4} Hz: LSCF {:.4} Hz ({:+.4} %), ζ {:.3} ± {:.3} % for {:.3} %",
            e.frequency,
            m.frequency,
            100.0 * error,
            100.0 * m.damping,
            100.0 * m.damping_sd,
            100.0 * e.damping
        );
        assert!(error.abs() < 0.005, "{} Hz: {error}", e.frequency);
        assert!(
            damping_within_bar(m, e),
            "{} Hz: ζ {} for {}",
            e.frequency,
            m.damping,
            e.damping
        );
    }
    assert!(spurious.is_empty(), "LSCF spurious {spurious:?}");
}

pub fn lscf_frequencies(found: &RecordModes) -> Vec<f64> {
    frequencies_of(&found.input_output.as_ref().expect("LSCF ran").modes)
}

/// The identified frequencies of a method's modes, in its order.
pub fn frequencies_of(modes: &[RecordMode]) -> Vec<f64> {
    modes.iter().map(|m| m.identified.frequency).collect()
}

/// The lab frame of the issue: three storeys of 5.201 kg, storey stiffnesses 9562, 11806
/// and 11332 N/m (modes at 3.170, 9.030 and 13.430 Hz, the peaks of its FRF), storey
/// dampers of 4 N s/m (0.39, 1.05 and 1.48 %), a shaker at floor 1 band-limited to
/// 1–60 Hz, 500 Hz for 30 s per run, one accelerometer per run (floors 1, 2, 3), 2 % white
/// and 5 % coloured noise.
pub fn lab_frame_runs() -> Vec<(Measurement, Vec<Mode>)> {
    lab_frame_runs_with(0.05)
}

/// [`lab_frame_runs`] with `coloured` × each channel's RMS of coloured noise.
pub fn lab_frame_runs_with(coloured: f64) -> Vec<(Measurement, Vec<Mode>)> {
    (1..=3)
        .map(|floor| {
            record(
                3,
                (&[5.201; 3], &[9562.0, 11806.0, 11332.0], &[4.0; 3]),
                1,
                (500.0, 30.0),
                (1.0, 60.0),
                &[floor],
                coloured,
                40 + floor as u64,
            )
        })
        .collect()
}
