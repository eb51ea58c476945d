//! `twin modal` on a laboratory three-storey frame like the (a shaker at floor 1, one
//! accelerometer per run, band-limited or white forces, coloured sensor noise): every FRF peak
//! found, nothing invented, light damping kept, roving runs merged into shapes at every floor.

use numerics::modal::{mac, Mode};
use orchestrator::record::Measurement;
use orchestrator::workflows::modal::{identify, IdentifyOptions};

mod common;
use common::modal_records::*;

/// A laboratory frame like the Swansea rig of `shared/data/frf` (three storeys of 5.2 kg,
/// storey stiffness 52.5 kN/m: 7.1, 19.9 and 28.7 Hz; damping 0.4–1.6 %), a shaker at
/// floor 1 band-limited to 1–100 Hz, 500 Hz for 30 s per run, one accelerometer moved
/// floor to floor over three runs, 2 % white and 5 % coloured noise. Each run alone gives
/// no mode the structure lacks and modes 2 and 3 within 1 %; the three runs together (a
/// roving test, merged through the measured force, each run's modes fitted alone) give
/// the three modes with shapes at the three floors: measured +0.0008, −0.0001, +0.0001 %,
/// damping 0.422 / 1.194 / 1.726 % for 0.426 / 1.194 / 1.725 %, MAC 0.99999, 1.00000,
/// 1.00000 (bars 1 %, 0.95, damping within 10 %; before the runs were taken whole in the
/// time domain: +0.051 %, damping 0.80 % and MAC 0.965 for mode 1).
#[test]
fn a_roving_accelerometer_gives_every_mode_and_its_shape_at_every_floor() {
    let runs: Vec<(Measurement, Vec<Mode>)> = (1..=3)
        .map(|floor| {
            record(
                3,
                (&[5.201; 3], &[52_460.0; 3], &[10.0; 3]),
                1,
                (500.0, 30.0),
                (1.0, 100.0),
                &[floor],
                0.05,
                20 + floor as u64,
            )
        })
        .collect();
    let exact = runs[0].1.clone();
    for e in &exact {
        println!("exact {:.4} Hz ζ {:.3} %", e.frequency, 100.0 * e.damping);
    }
    for (data, _) in &runs {
        let found =
            identify(std::slice::from_ref(data), &IdentifyOptions::default()).expect("identified");
        let frequencies = lscf_frequencies(&found);
        println!(
            "{}: LSCF {frequencies:.4?} over {:?}; SSI-COV {:.4?}",
            data.responses[0].channel.name(),
            found.input_output.as_ref().and_then(|m| m.band),
            frequencies_of(&found.ssi.modes)
        );
        let (nearest, spurious) = matched(&frequencies, &exact);
        // Modes 2 and 3 in every run. Mode 1 (0.43 %: a quarter of a 0.24 Hz bin wide)
        // is in every run's diagram, within 0.4 % at most orders, but its leakage-made
        // damping (0.9–2 %) jumps by more than the 5 % damping tolerance between orders,
        // so runs 2 and 3 do not make it a mode alone: measured +0.35 %, missed, missed.
        for ((_, error), e) in nearest.iter().zip(&exact).skip(1) {
            assert!(error.abs() < 0.01, "{} Hz: {error}", e.frequency);
        }
        assert!(spurious.is_empty(), "spurious {spurious:?}");
    }
    let data: Vec<Measurement> = runs.into_iter().map(|(d, _)| d).collect();
    let found = identify(&data, &IdentifyOptions::default()).expect("a roving test");
    assert_eq!(found.floors, vec![1, 2, 3]);
    let io = found.input_output.as_ref().expect("LSCF ran");
    assert_eq!(
        io.modes.len(),
        exact.len(),
        "{:?}",
        lscf_frequencies(&found)
    );
    for (m, e) in io.modes.iter().zip(&exact) {
        let error = m.identified.frequency / e.frequency - 1.0;
        let shape = mac(&m.displacement_shape, &e.shape);
        println!(
            "roving: {:.4} Hz ({:+.4} %), ζ {:.3} %, MAC {shape:.5}",
            m.identified.frequency,
            100.0 * error,
            100.0 * m.identified.damping
        );
        assert!(error.abs() < 0.01, "{} Hz: {error}", e.frequency);
        assert!(shape >= 0.95, "{} Hz: MAC {shape}", e.frequency);
        let damping = m.identified.damping / e.damping - 1.0;
        assert!(
            damping.abs() < 0.10,
            "{} Hz: damping {damping}",
            e.frequency
        );
    }
}

/// Each run alone: the default `twin modal` finds the three peaks within 1 % and no mode
/// the frame lacks. Before the fit's damping was freed from order-to-order stability, the
/// four-segment default and the peak screen, LSCF found 2, 3 and 2 modes on such runs made
/// by `twin synth` (mode 1 missed in runs 1 and 3; a 13.3 Hz double in run 3). Measured
/// now (the leaky modes refined in the time domain; before that, mode 1 −0.73, −0.33,
/// +0.27 %): every mode within 0.01 %; none spurious (bars 1 %, none).
/// SSI-COV, output-only on one channel, is not held to it: it finds 0, 1 and 2 of the
/// modes (printed).
/// The same runs with white sensor noise alone (no coloured noise) had LSCF report a pole
/// of noise beside the three modes on runs 2 and 3, 55.64 Hz and 39.41 Hz, each from 7
/// of the sweep's 20 orders where the modes hold 12–17. An FRF fit's mode now needs 0.45
/// of the best-supported mode's orders (identify/orders.rs: 39.41 Hz, 7 of 17, set aside
/// `few-orders`) and its own fitted term 1.4 times the fit's misfit around it
/// (identify/shoulder.rs: 55.64 Hz, 7 of 14 orders, 0.93, set aside `below-misfit`; the
/// modes 1.70–23.9). Measured with both: every mode within 0.01 %, none spurious.
/// FDD/EFDD beside them reported 49.62 Hz on run 3 (5 % coloured noise), a maximum of the
/// singular value where the FRF's coherence stays below 0.7; FDD's peaks now need the
/// FRF's coherence 0.7 within two bins (`FDD_PEAK_COHERENCE`, the bar for a peak):
/// measured −0.69 to +0.51 %, none spurious (bar: none).
#[test]
fn every_peak_of_a_lab_frames_runs_is_found_and_nothing_else() {
    for coloured in [0.05, 0.0] {
        every_peak_is_found_and_nothing_else(lab_frame_runs_with(coloured));
    }
}

/// The lab frame's runs forced by white noise over the whole band (0–250 Hz at 500 Hz),
/// one accelerometer per run as in [`lab_frame_runs`], and one run of every floor.
fn white_lab_frame_runs(floors: &[&[usize]], coloured: f64) -> Vec<(Measurement, Vec<Mode>)> {
    floors
        .iter()
        .enumerate()
        .map(|(i, measured)| {
            record(
                3,
                (&[5.201; 3], &[9562.0, 11806.0, 11332.0], &[4.0; 3]),
                1,
                (500.0, 30.0),
                (0.0, 250.0),
                measured,
                coloured,
                60 + i as u64,
            )
        })
        .collect()
}

/// The lab frame forced by white noise over its whole band, every floor measured, white
/// sensor noise: the default `twin modal` finds the three peaks within 1 %, none spurious.
/// Before, LSCF's sweep stopped at order 40 with 9.03 and 13.43 Hz only on runs 2 and 3:
/// the 0.39 %-damped 3.17 Hz (a fifth of a 0.12 Hz bin wide) dips H1's coherence at its
/// own bin to 0.17, so the FRF's peaks did not list it, and the sweep went on only while
/// no mode stood at all; once swept on (formed above order 40) its 9 orders were few
/// beside modes standing since order 20. Now a peak coherent within two bins, below the highest
/// mode and unexplained, takes the sweep on, and a mode formed above the orders asked for
/// is judged against the orders since it formed. Measured: 3.17 / 9.03 / 13.43 Hz within
/// 0.001 % on all three runs; `twin synth`'s same frame (seeds 1–3) 2 / 2 / 2 → 3 / 3 / 3
/// modes, 3.1700 Hz each. With 5 % coloured sensor noise as well: within 0.004 %, none
/// spurious. FDD/EFDD beside them finds the three modes and, now its peaks are screened,
/// nothing else (before: 14.01 Hz on run 1, a broad bell of noise peaking at 17.09 Hz;
/// 8.48 and 14.56 Hz on run 3, where no FRF peaks).
#[test]
fn every_peak_of_a_lab_frame_forced_over_its_whole_band_is_found() {
    let every_floor: &[&[usize]] = &[&[1, 2, 3], &[1, 2, 3], &[1, 2, 3]];
    for coloured in [0.0, 0.05] {
        println!("coloured noise {coloured}");
        every_peak_is_found_and_nothing_else(white_lab_frame_runs(every_floor, coloured));
    }
}

/// The lab frame forced over its whole band with one accelerometer per run (floors 1, 2
/// and 3), white sensor noise, then 5 % coloured noise as well: the default `twin modal`
/// finds the three peaks within 1 %, none spurious. Before, the sweep did not go past
/// the 40 orders asked for on fewer than three channels, where runs 1 and 3 had 9.03 and
/// 13.43 Hz only (run 1: +185 % for 3.17 Hz, its nearest mode 182 Hz). Now it goes on
/// for the FRF peaks unexplained at order 40, and adds only the modes at them
/// (`identify/orders.rs`, `with_sought`). Measured: white noise within 0.033 %,
/// coloured within 0.109 % (run 3's 13.43 Hz); none spurious; the modes of noise the
/// higher orders made (44–150 Hz) set aside `unsought`.
#[test]
fn every_peak_of_a_whole_band_lab_frames_single_channel_runs_is_found() {
    let one_each: &[&[usize]] = &[&[1], &[2], &[3]];
    for coloured in [0.0, 0.05] {
        println!("coloured noise {coloured}");
        every_peak_is_found_and_nothing_else(white_lab_frame_runs(one_each, coloured));
    }
}

/// Each run's LSCF modes within 1 % of the exact ones, none spurious; and no FDD/EFDD
/// mode away from the exact ones either.
fn every_peak_is_found_and_nothing_else(runs: Vec<(Measurement, Vec<Mode>)>) {
    let exact = runs[0].1.clone();
    for e in &exact {
        println!("exact {:.4} Hz ζ {:.3} %", e.frequency, 100.0 * e.damping);
    }
    for (data, _) in &runs {
        let found =
            identify(std::slice::from_ref(data), &IdentifyOptions::default()).expect("identified");
        let frequencies = lscf_frequencies(&found);
        let (nearest, spurious) = matched(&frequencies, &exact);
        let io = found.input_output.as_ref().expect("LSCF ran");
        println!(
            "{}: LSCF {:+.3?} % over {:?}, set aside {:?}; SSI-COV {:.4?}",
            data.responses[0].channel.name(),
            nearest.iter().map(|(_, e)| 100.0 * e).collect::<Vec<_>>(),
            io.band,
            io.rejected
                .iter()
                .map(|r| (r.mode.frequency, r.mode.orders.len(), r.rejection))
                .collect::<Vec<_>>(),
            frequencies_of(&found.ssi.modes)
        );
        let fdd: Vec<f64> = frequencies_of(&found.fdd.modes);
        let (fdd_nearest, fdd_spurious) = matched(&fdd, &exact);
        println!(
            "FDD {:+.3?} %, spurious {fdd_spurious:.3?}, set aside {:.3?}",
            fdd_nearest
                .iter()
                .map(|(_, e)| 100.0 * e)
                .collect::<Vec<_>>(),
            found
                .fdd
                .rejected
                .iter()
                .map(|r| (r.mode.frequency, r.rejection))
                .collect::<Vec<_>>()
        );
        for ((_, error), e) in nearest.iter().zip(&exact) {
            assert!(error.abs() < 0.01, "{} Hz: {error}", e.frequency);
        }
        assert!(spurious.is_empty(), "spurious {spurious:?}");
        assert!(fdd_spurious.is_empty(), "FDD spurious {fdd_spurious:?}");
    }
}

/// Lightly damped modes on single records, narrower than a bin of the Welch FRF: the lab
/// frame's 0.39 %-damped first mode on each 30 s run (a third of a 0.13 Hz bin wide) and
/// the band-limited five-storey building's 0.35 %-damped one (2.6 bins). LSCF's damping
/// of such a mode is the window's leakage (measured on these runs before: 0.89–1.11 % for
/// 0.39 %); the record taken whole in the time domain through its force gives the
/// structure's. Measured: the lab runs' mode 1 0.396 / 0.394 / 0.394 % for 0.387 %
/// (+2.4 / +2.0 / +1.9 %; its reported sd, 0.002 %, is the white-residual one, too small
/// under the coloured noise), modes 2–3 within 0.2 %; the five storeys' mode 1 0.3453 %
/// for 0.3454 %, all five within 0.1 %; none spurious. Bar (the issue's): within the
/// larger of 10 % and 2.5 reported sds.
#[test]
fn lightly_damped_modes_keep_their_damping_on_single_records() {
    let mut records: Vec<(String, Measurement, Vec<Mode>)> = lab_frame_runs()
        .into_iter()
        .map(|(d, e)| (format!("lab {}", d.responses[0].channel.name()), d, e))
        .collect();
    let (five, exact) = record(
        5,
        (&[5.2; 5], &[64_000.0; 5], &[14.0; 5]),
        2,
        (200.0, 300.0),
        (0.5, 40.0),
        &[1, 2, 3, 4, 5],
        0.05,
        11,
    );
    records.push(("five storeys".into(), five, exact));
    for (name, data, exact) in records {
        let found =
            identify(std::slice::from_ref(&data), &IdentifyOptions::default()).expect("identified");
        let io = found.input_output.as_ref().expect("LSCF ran");
        let (nearest, spurious) = matched(&lscf_frequencies(&found), &exact);
        assert!(spurious.is_empty(), "{name}: spurious {spurious:?}");
        for ((i, _), e) in nearest.iter().zip(&exact) {
            let m = &io.modes[*i].identified;
            let error = m.damping / e.damping - 1.0;
            println!(
                "{name}: {:.4} Hz ζ {:.4} ± {:.4} % for {:.4} % ({:+.1} %)",
                m.frequency,
                100.0 * m.damping,
                100.0 * m.damping_sd,
                100.0 * e.damping,
                100.0 * error
            );
            assert!(
                damping_within_bar(m, e),
                "{name}: {} Hz: damping {} for {}",
                e.frequency,
                m.damping,
                e.damping
            );
        }
    }
}

/// The three runs of the lab frame together (a roving test, merged PoSER style through the
/// measured force: each run's own poles, each channel's residue at its run's pole) give the
/// three modes with shapes at the three floors, with their damping. Before, the runs' FRFs
/// fitted jointly gave modes 2 and 3 only (mode 1 at 3.166 Hz in the diagram with an MPC of
/// 0.36, the runs' peaks ±0.4 % apart); then, each run's residues read off its own FRF,
/// mode 1 at −0.27 %, damping 0.90 % for 0.39 %, MAC 0.934 (its 13 s decay outlasts the
/// 8 s Welch segments: a smeared, random peak). With the runs taken whole in the time
/// domain, measured: −0.005 / +0.001 / −0.005 %, damping 0.395 / 1.055 / 1.478 % for
/// 0.387 / 1.054 / 1.479 % (+2.1 / +0.1 / −0.1 %), MAC 0.99998 / 1.00000 / 1.00000.
/// Bars (the issue's): 1 % in frequency, MAC 0.95, damping within 10 %.
#[test]
fn a_lab_frames_roving_runs_merge_into_three_modes_at_three_floors() {
    let runs = lab_frame_runs();
    let exact = runs[0].1.clone();
    let data: Vec<Measurement> = runs.into_iter().map(|(d, _)| d).collect();
    let started = std::time::Instant::now();
    let found = identify(&data, &IdentifyOptions::default()).expect("a roving test");
    println!("identified in {:.2?}", started.elapsed());
    assert_eq!(found.floors, vec![1, 2, 3]);
    let io = found.input_output.as_ref().expect("LSCF ran");
    for r in &io.rejected {
        println!("set aside {:.4} Hz: {}", r.mode.frequency, r.reason);
    }
    assert_eq!(
        io.modes.len(),
        exact.len(),
        "{:?}",
        lscf_frequencies(&found)
    );
    let mut measured = Vec::new();
    for (m, e) in io.modes.iter().zip(&exact) {
        let error = m.identified.frequency / e.frequency - 1.0;
        let shape = mac(&m.displacement_shape, &e.shape);
        let damping = m.identified.damping / e.damping - 1.0;
        measured.push((e.frequency, error, shape, damping));
        println!(
            "roving: {:.4} ± {:.4} Hz ({:+.3} %), ζ {:.3} ± {:.3} %, MAC {shape:.5}, \
             MPC {:.3}, shape sd {:.3?}",
            m.identified.frequency,
            m.identified.frequency_sd,
            100.0 * error,
            100.0 * m.identified.damping,
            100.0 * m.identified.damping_sd,
            m.identified.mpc,
            m.identified.shape_sd
        );
    }
    for (frequency, error, shape, damping) in measured {
        assert!(error.abs() < 0.01, "{frequency} Hz: {error}");
        assert!(shape >= 0.95, "{frequency} Hz: MAC {shape}");
        assert!(damping.abs() < 0.10, "{frequency} Hz: damping {damping}");
    }
}
