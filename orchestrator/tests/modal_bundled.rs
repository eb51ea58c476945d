//! `twin modal --data` on the project's own bundled records (data/dataset1.csv, dataset2.csv:
//! the paper's three-storey frame, 20 s at 51.2 Hz — 1,024 samples — force at floor 1, three
//! accelerometers). The first record a newcomer identifies: each method's default result holds
//! the frame's three modes and nothing else.
//!
//! The reference is the twin calibrated on the same record by `twin calibrate` (the MAP of the
//! time-domain likelihood, which uses no modal identification): its modes are 2.0025 / 5.9488
//! / 8.3788 Hz on dataset1 and 2.0014 / 5.9494 / 8.3801 Hz on dataset2 (`twin modal --twin`
//! of it, measured). dataset3 is held to less (its own test): the bumper between floors 2 and
//! 3 makes contact there, a nonlinear record whose FRF has coherent peaks of the contact's own
//! (12.8, 17.9, 18.9 Hz) and whose modes move with it.
//!
//! Before the averaged evidence (a short record's FRF judged over seven segments of 256, not
//! its single segment of 1,024 whose coherence is 1 everywhere) and the half-power merge of
//! same-shaped modes: dataset1 gave LSCF 6 modes (a 2.0187 Hz twin of the 1.9484 Hz mode;
//! 16.82 and 17.94 Hz at MPC 0.71 / 0.73) and FDD/EFDD 7 (0.46, 1.40, 4.66, 7.46 Hz of
//! noise); dataset2 LSCF 3, FDD/EFDD 6 (1.14, 3.31, 3.78 Hz).

use numerics::modal::modes;
use numerics::modal::stabilisation::Rejection;
use orchestrator::record::Measurement;
use orchestrator::synth::{synth_record, Scenario};
use orchestrator::workflows::modal::identify::{RecordMode, RecordModes};
use orchestrator::workflows::modal::{identify, IdentifyOptions};
use std::path::PathBuf;

fn bundled(name: &str) -> RecordModes {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join("data")
        .join(name);
    let record = Measurement::read(&path).expect("the bundled record reads");
    identify(&[record], &IdentifyOptions::default()).expect("identified")
}

/// The methods' modes (name, frequencies), each printed.
fn methods(found: &RecordModes) -> Vec<(&'static str, Vec<f64>)> {
    let io = found
        .input_output
        .as_ref()
        .expect("the force was measured: LSCF ran");
    let frequencies = |modes: &[RecordMode]| -> Vec<f64> {
        modes.iter().map(|m| m.identified.frequency).collect()
    };
    let all = vec![
        (io.method, frequencies(&io.modes)),
        (found.ssi.method, frequencies(&found.ssi.modes)),
        (found.fdd.method, frequencies(&found.fdd.modes)),
    ];
    for (method, f) in &all {
        println!("{method}: {f:.4?}");
    }
    all
}

/// Each method's default result is the calibrated twin's three modes, nothing else: LSCF
/// within 1 % (measured: dataset1 −0.08 / −0.08 / −0.19 %, dataset2 −0.04 / +0.24 / −0.05 %);
/// FDD/EFDD within 1.2 % (measured −0.66 / +0.83 / −0.27 % and −0.01 / −0.45 / −0.91 %:
/// EFDD's 0.2 Hz bins, seven segments of 256, make a bell of three to eight bins; before it
/// read its zero crossings only where the correlation decays, −0.67 / +0.94 / +0.80 % and
/// −0.01 / +1.37 / +0.72 %); SSI-COV within 2 % — the 1 % is not its on a 20 s record
/// forced by a band-limited (not white) force, which output-only methods take for white:
/// measured −1.96 / +0.08 / −0.14 % and −0.98 / −0.74 / +0.48 % (the first mode's −1.9 % stays
/// at 15–40 block rows: −1.84 to −1.96 %; it is the scatter of an output-only estimate on
/// 1,024 samples, not a bias: [`ssi_covs_first_mode_scatters_with_the_records_length`]).
/// The side-by-side table has three rows, each mode found by all
/// three methods.
#[test]
fn the_bundled_records_give_their_three_modes_and_nothing_else() {
    let references = [
        ("dataset1.csv", [2.0025, 5.9488, 8.3788]),
        ("dataset2.csv", [2.0014, 5.9494, 8.3801]),
    ];
    for (name, reference) in references {
        let found = bundled(name);
        for (method, frequencies) in methods(&found) {
            assert_eq!(
                frequencies.len(),
                reference.len(),
                "{name} {method}: {frequencies:?}"
            );
            let bar = match method {
                "LSCF" => 0.01,
                "FDD/EFDD" => 0.012,
                _ => 0.02,
            };
            for (f, r) in frequencies.iter().zip(&reference) {
                let error = f / r - 1.0;
                println!("{name} {method}: {f:.4} Hz, {:+.2} %", 100.0 * error);
                assert!(error.abs() < bar, "{name} {method}: {f} Hz for {r}");
            }
        }
        assert_eq!(found.verdicts.len(), reference.len(), "{name}");
        for verdict in &found.verdicts {
            assert_eq!(
                verdict.found_by.len(),
                3,
                "{name} {:.4} Hz",
                verdict.frequency
            );
            assert!(!verdict.one_method_only);
        }
    }
}

/// dataset3, the bumper's contact: LSCF reports the frame's three modes and sets the rest
/// aside with their reasons, not eight. Before the time-domain screen of the leaky modes
/// (identify/leaky.rs) it reported 2.0007, 5.9571, 6.0346, 8.7289, 9.0004, 17.2699, 17.8995
/// and 18.8498 Hz, the five extra ones damped 0.01–0.18 %. Now (measured) 2.0007 / 5.9571 /
/// 8.7289 Hz: the first two within 0.14 % of dataset1's calibrated twin (the contact hardly
/// moves them, bar 1 %), the third +4.2 % (the contact stiffens the storey it spans: bar
/// 0–6 %); 6.0346 and 9.0004 Hz set aside as one resonance with 5.96 and 8.73 Hz (MAC 0.99,
/// 0.98, within the peak screen's two 0.2 Hz bins), 17.27 / 17.90 / 18.85 Hz as not needed by
/// the record taken whole (its residual rises 0.26 / 0.20 / 0.06 % without them, bar 2 %).
#[test]
fn the_bumpers_record_gives_three_modes_and_sets_the_contacts_poles_aside() {
    let found = bundled("dataset3.csv");
    methods(&found);
    let io = found.input_output.as_ref().expect("LSCF ran");
    let frequencies: Vec<f64> = io.modes.iter().map(|m| m.identified.frequency).collect();
    assert_eq!(frequencies.len(), 3, "{frequencies:?}");
    let free = [2.0025, 5.9488, 8.3788];
    for (f, r) in frequencies.iter().zip(&free).take(2) {
        assert!((f / r - 1.0).abs() < 0.01, "{f} Hz for {r}");
    }
    let stiffened = frequencies[2] / free[2] - 1.0;
    assert!((0.0..0.06).contains(&stiffened), "{} Hz", frequencies[2]);
    let set_aside = |rejection: Rejection| -> Vec<f64> {
        io.rejected
            .iter()
            .filter(|r| r.rejection == rejection)
            .map(|r| r.mode.frequency)
            .collect()
    };
    let split = set_aside(Rejection::Unresolved);
    for duplicate in [6.03, 9.00] {
        assert!(
            split.iter().any(|f| (f - duplicate).abs() < 0.05),
            "{duplicate} Hz not set aside as one resonance: {split:?}"
        );
    }
    let unneeded = set_aside(Rejection::NotInRecord);
    assert_eq!(unneeded.len(), 3, "{unneeded:?}");
    assert!(
        unneeded.iter().all(|f| *f > 17.0 && *f < 19.0),
        "{unneeded:?}"
    );
}

/// SSI-COV's first mode on records like dataset1 (the rig's own generator, `twin synth`'s
/// defaults: three storeys, a white force at floor 1, 3 % sensor noise, 51.2 Hz), ten seeds,
/// the exact mode known (2.0024 Hz, 0.9 % damped). On 20 s (1,024 samples, dataset1's length)
/// its error scatters about no bias: measured mean +0.17 %, sd 0.81 %, −0.90 to +1.66 %
/// (LSCF through the measured force: within 0.03 % on nine seeds); on 200 s the sd is 0.19 %,
/// every seed within 0.46 % — the scatter shrinks as 1/√T, as a statistical error does.
/// dataset1's −1.96 % is 2.4 such sds: the 1 % is not an output-only method's on a
/// 20 s record of a 2 Hz mode (40 cycles, its decay 8.5 s), whatever the block rows or the
/// orders; SSI-COV's reported sd (the spread over model orders, 0.0009 Hz there) does not
/// show it. Bars: 20 s, the mean within 0.5 % (no bias); 200 s, every seed within the
/// issue's 1 % and the mean within 0.2 %.
#[test]
fn ssi_covs_first_mode_scatters_with_the_records_length() {
    for (duration, every, mean_bar) in [(20.0, f64::INFINITY, 0.005), (200.0, 0.01, 0.002)] {
        let errors = first_mode_errors(duration, |found| &found.ssi.modes);
        let mean = errors.iter().sum::<f64>() / errors.len() as f64;
        let sd =
            (errors.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / errors.len() as f64).sqrt();
        println!(
            "{duration} s: SSI-COV mode 1 {:+.2?} %, mean {:+.2} %, sd {:.2} %",
            errors.iter().map(|e| 100.0 * e).collect::<Vec<_>>(),
            100.0 * mean,
            100.0 * sd
        );
        assert!(mean.abs() < mean_bar, "{duration} s: mean {mean}");
        assert!(
            errors.iter().all(|e| e.abs() < every),
            "{duration} s: {errors:?}"
        );
    }
}

/// LSCF's (through the measured force) modes on the same ten 20 s records, every one of them.
/// On seed 6 LSCF made two poles of the 2.0024 Hz resonance, 2.0290 and 1.9394 Hz, and the
/// time-domain refinement of the kept one ran with the other still in the fit: +1.33 %. On
/// seed 7 the 8.379 Hz mode's cluster followed a pole of noise where its track split (8.35 Hz
/// to order 24, then 8.29 falling to 8.23 Hz): 8.2873 Hz, −1.09 %, the mode's own branch
/// (8.3946 Hz) set aside as one resonance with it. With the set-aside pole out of the refit,
/// and the record deciding which of one resonance's two modes stands, measured: the first mode
/// within 0.032 % on every seed (bar 0.1 %); every mode within 0.386 % (seed 9's 5.9258 Hz for
/// 5.9487; seed 7's third +0.186 %), the bar the 0.5 % (0.11 points of margin); three
/// modes and no other on each.
#[test]
fn lscfs_modes_hold_on_every_short_record() {
    let errors = mode_errors(20.0, |found| {
        &found
            .input_output
            .as_ref()
            .expect("LSCF ran: the force is measured")
            .modes
    });
    for (seed, (errors, count)) in (1..).zip(&errors) {
        println!(
            "20 s, seed {seed}: LSCF {count} modes, errors {:+.3?} %",
            errors.iter().map(|e| 100.0 * e).collect::<Vec<_>>()
        );
        assert_eq!(*count, errors.len(), "seed {seed}: a mode more or fewer");
        assert!(errors[0].abs() < 0.001, "seed {seed}: {errors:?}");
        assert!(
            errors.iter().all(|e| e.abs() < 0.005),
            "seed {seed}: {errors:?}"
        );
    }
}

/// Per seed 1..=10 of `twin synth`'s defaults over `duration` s, the relative error of the
/// nearest of `method`'s frequencies to the exact first mode.
fn first_mode_errors(duration: f64, method: impl Fn(&RecordModes) -> &[RecordMode]) -> Vec<f64> {
    mode_errors(duration, method)
        .into_iter()
        .map(|(errors, _)| errors[0])
        .collect()
}

/// Per seed 1..=10 of `twin synth`'s defaults over `duration` s: per exact mode, the relative
/// error of the nearest of `method`'s frequencies; and how many modes the method reported.
fn mode_errors(
    duration: f64,
    method: impl Fn(&RecordModes) -> &[RecordMode],
) -> Vec<(Vec<f64>, usize)> {
    (1..=10)
        .map(|seed| {
            let scenario = Scenario {
                seed,
                duration,
                ..Scenario::default()
            };
            let (made, _) = synth_record(&scenario).expect("a record");
            let s = scenario.structure();
            let exact = modes(&s.mass_matrix(), &s.damping_matrix(), &s.stiffness_matrix())
                .expect("exact modes");
            let found =
                identify(&[made.measurement], &IdentifyOptions::default()).expect("identified");
            let found = method(&found);
            let errors = exact
                .iter()
                .map(|e| {
                    found
                        .iter()
                        .map(|m| m.identified.frequency / e.frequency - 1.0)
                        .min_by(|a, b| a.abs().total_cmp(&b.abs()))
                        .expect("the method found a mode")
                })
                .collect();
            (errors, found.len())
        })
        .collect()
}
