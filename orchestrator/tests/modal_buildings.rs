//! `twin modal` on synthetic buildings of 5–10 storeys under band-limited forces (coloured
//! sensor noise, light damping): every mode found, none invented, by LSCF, SSI-COV and the
//! FDD/EFDD cross-check.

use numerics::modal::mac;
use numerics::modal::stabilisation::Rejection;
use orchestrator::workflows::modal::{identify, IdentifyOptions};

mod common;
use common::modal_records::*;

/// The five-storey record of the LSCF and FDD tests below: the force at floor 2 band-limited to
/// 0.5–40 Hz, 200 Hz for 300 s, every floor measured, 5 % coloured noise, seed 11.
fn five_storeys() -> (
    orchestrator::record::Measurement,
    Vec<numerics::modal::Mode>,
) {
    record(
        5,
        (&[5.2; 5], &[64_000.0; 5], &[14.0; 5]),
        2,
        (200.0, 300.0),
        (0.5, 40.0),
        &[1, 2, 3, 4, 5],
        0.05,
        11,
    )
}

/// Five storeys (5.0–33.9 Hz, damping 0.35–2.3 %), the force at floor 2 band-limited to
/// 0.5–40 Hz (the fifth mode near the band's top), 200 Hz for 300 s, every floor measured,
/// 2 % white and 5 % coloured noise. The default LSCF finds every mode and nothing else:
/// measured within 0.007 %, MAC 1.0000 (bars 0.5 %, 0.95); fitted over 2.98–40.0 Hz (the
/// coloured noise takes the coherence below 0.5 under 3 Hz).
#[test]
fn lscf_finds_every_mode_of_a_band_limited_record_and_nothing_else() {
    let (data, exact) = five_storeys();
    let found = identify(&[data], &IdentifyOptions::default()).expect("identified");
    let io = found.input_output.as_ref().expect("LSCF ran");
    println!("band {:?}", io.band);
    for e in &exact {
        println!("exact {:.4} Hz ζ {:.3} %", e.frequency, 100.0 * e.damping);
    }
    for m in &io.modes {
        println!(
            "LSCF {:.4} Hz ζ {:.3} % ± {:.3} %",
            m.identified.frequency,
            100.0 * m.identified.damping,
            100.0 * m.identified.damping_sd
        );
    }
    for m in &found.ssi.modes {
        println!(
            "SSI {:.4} Hz ζ {:.3} %",
            m.identified.frequency,
            100.0 * m.identified.damping
        );
    }
    let (nearest, spurious) = matched(&lscf_frequencies(&found), &exact);
    for ((i, error), e) in nearest.iter().zip(&exact) {
        let m = &io.modes[*i];
        let shape = mac(&m.displacement_shape, &e.shape);
        println!(
            "{:.4} Hz: {:+.4} %, MAC {shape:.5}",
            e.frequency,
            100.0 * error
        );
        assert!(error.abs() < 0.005, "{} Hz: {error}", e.frequency);
        assert!(shape > 0.95, "{} Hz: MAC {shape}", e.frequency);
    }
    assert!(spurious.is_empty(), "spurious {spurious:?}");
    assert_eq!(io.modes.len(), exact.len());
    // SSI-COV on the same record (the issue saw it add modes at 38.3 and 39.8 Hz, the
    // force's band edge, on a record like this one from another generator; such modes are
    // set aside by the edge and peak screens). Measured: the five modes within −0.09 to
    // +0.14 %, none spurious (bars 0.5 %, none).
    let ssi: Vec<f64> = frequencies_of(&found.ssi.modes);
    let (nearest, spurious) = matched(&ssi, &exact);
    for ((_, error), e) in nearest.iter().zip(&exact) {
        assert!(error.abs() < 0.005, "SSI-COV {} Hz: {error}", e.frequency);
    }
    assert!(spurious.is_empty(), "SSI-COV spurious {spurious:?}");
    assert_eq!(ssi.len(), exact.len(), "SSI-COV {ssi:?}");
}

/// Ten storeys (2.6–35 Hz), the force at floor 2 band-limited to 0.5–40 Hz, 200 Hz for
/// 300 s, every floor measured, 2 % white and 5 % coloured noise: the tallest of the
/// issue's 3–10-storey buildings. (At floor 3 the force sits on a node of mode 4 — a
/// uniform chain's mode j is sin((2j − 1) i π / 21) at floor i — and no method can see it.)
/// Measured: LSCF's ten modes within 0.007 %, damping within 0.8 % of the exact; SSI-COV 7
/// of 10 (not 2.64, 33.74, 34.92 Hz), none spurious. Bars: the 0.5 % and damping
/// within the larger of 10 % and 2.5 reported sds for LSCF, nothing spurious for both.
/// FDD/EFDD, the cross-check, kept 4.1457 Hz beside its modes, no mode: a peak of the noise
/// between modes 1 and 2 (the first singular value 5.0 times the second there; at the modes'
/// peaks 6,393 to 300,196 times), now set aside `unseparated`. Measured: modes 1–5 and 8
/// (2.64–22.0 and 31.8 Hz) within +0.00 to +0.30 %, none spurious. Bars: the 0.5 %
/// for those six, nothing spurious.
#[test]
fn every_mode_of_a_ten_storey_building_under_a_band_limited_force() {
    let (data, exact) = record(
        10,
        (&[5.2; 10], &[64_000.0; 10], &[14.0; 10]),
        2,
        (200.0, 300.0),
        (0.5, 40.0),
        &(1..=10).collect::<Vec<_>>(),
        0.05,
        21,
    );
    let found = identify(&[data], &IdentifyOptions::default()).expect("identified");
    let io = found.input_output.as_ref().expect("LSCF ran");
    println!("band {:?}", io.band);
    println!(
        "exact {:.4?}",
        exact.iter().map(|e| e.frequency).collect::<Vec<_>>()
    );
    println!("LSCF {:.4?}", lscf_frequencies(&found));
    println!("SSI {:.4?}", frequencies_of(&found.ssi.modes));
    println!("FDD {:.4?}", frequencies_of(&found.fdd.modes));
    lscf_holds_every_mode(&found, &exact);
    assert_eq!(io.modes.len(), exact.len());
    let ssi = frequencies_of(&found.ssi.modes);
    println!("SSI-COV {ssi:.4?}");
    let (_, spurious) = matched(&ssi, &exact);
    assert!(spurious.is_empty(), "SSI-COV spurious {spurious:?}");
    let fdd = frequencies_of(&found.fdd.modes);
    let (nearest, spurious) = matched(&fdd, &exact);
    assert!(spurious.is_empty(), "FDD/EFDD spurious {spurious:?}");
    for k in [0, 1, 2, 3, 4, 7] {
        let (_, error) = nearest[k];
        println!("{:.4} Hz: FDD {:+.3} %", exact[k].frequency, 100.0 * error);
        assert!(
            error.abs() < 0.005,
            "FDD/EFDD {} Hz: {error}",
            exact[k].frequency
        );
    }
    // The two light modes' damping, from their bells fitted through the Welch window's kernel
    // (half-power widths 0.8 and 7.0 bins). Measured: 2.64 Hz +62 % (0.2931 ± 0.0382 % for
    // 0.1814 %; +197 % from the correlation's decay), bar +100 %; 7.86 Hz −7 %, 0.4 sd
    // (−57 % before), bar 2.5 sd.
    let damping = |k: usize| {
        let m = &found.fdd.modes[nearest[k].0].identified;
        println!(
            "{:.4} Hz: EFDD ζ {:.4} ± {:.4} % (exact {:.4} %)",
            exact[k].frequency,
            100.0 * m.damping,
            100.0 * m.damping_sd,
            100.0 * exact[k].damping
        );
        (
            m.damping / exact[k].damping - 1.0,
            (m.damping - exact[k].damping) / m.damping_sd,
        )
    };
    let (first, _) = damping(0);
    println!("2.64 Hz: EFDD damping {:+.1} %", 100.0 * first);
    assert!(first.abs() < 1.0, "2.64 Hz damping {first}");
    let (second, sds) = damping(1);
    println!(
        "7.86 Hz: EFDD damping {:+.1} % ({sds:+.2} sd)",
        100.0 * second
    );
    assert!(sds.abs() < 2.5, "7.86 Hz damping {second}, {sds} sd");
    let unseparated: Vec<f64> = found
        .fdd
        .rejected
        .iter()
        .filter(|r| r.rejection == Rejection::Unseparated)
        .map(|r| r.mode.frequency)
        .collect();
    println!("FDD/EFDD set aside unseparated {unseparated:.4?}");
    assert!(
        unseparated.iter().any(|f| (f / 4.1457 - 1.0).abs() < 0.001),
        "the noise's 4.1457 Hz peak: {unseparated:?}"
    );
}

/// Towers whose modes sit low in a broad force's band: five storeys (1.26–8.49 Hz) under a
/// force at the top over the whole record's band, 0–50 Hz at 100 Hz for 410 s (the
/// `twin synth --storeys 5 --excitation force:5` tower), seven storeys (0.93–8.66 Hz) and
/// eight (0.82–8.70 Hz) under 0.5–30 Hz; every floor measured, 2 % white and 2 % coloured
/// noise. LSCF fits the whole excited band, and a z-domain fit spends its orders on the
/// empty part: at orders up to 40 (`twin synth`'s records of the same towers) the
/// five-storey tower's fourth and fifth modes stood from order 32 only, too few orders to
/// make a cluster, the seven-storey one gave two of seven modes and the eight-storey one
/// one of eight. The sweep now goes on while modes are still forming at its top order.
/// Measured: five storeys at order 40, within +0.032 %; seven and eight at order 60,
/// within +0.011 % and +0.012 % (eight storeys' mode 1, 0.19 % damped, a tenth of a bin
/// wide, was −0.412 % before the leaky modes were refined in the time domain); none
/// spurious. Bars: the 0.5 %, none spurious.
#[test]
fn lscf_finds_every_mode_of_a_tower_low_in_a_broad_band() {
    let cases = [
        (5, 5, (100.0, 410.0), (0.0, 50.0), 1),
        (7, 7, (100.0, 300.0), (0.5, 30.0), 2),
        (8, 2, (100.0, 300.0), (0.5, 30.0), 2),
    ];
    for (storeys, floor, sampling, band, seed) in cases {
        let floors: Vec<usize> = (1..=storeys).collect();
        let (data, exact) = record(
            storeys,
            (
                &vec![5.2; storeys],
                &vec![4021.0; storeys],
                &vec![3.0; storeys],
            ),
            floor,
            sampling,
            band,
            &floors,
            0.02,
            seed,
        );
        let found = identify(&[data], &IdentifyOptions::default()).expect("identified");
        let io = found.input_output.as_ref().expect("LSCF ran");
        let top = io.diagram.orders.last().map_or(0, |o| o.order);
        let (nearest, spurious) = matched(&lscf_frequencies(&found), &exact);
        println!(
            "{storeys} storeys over {:?} Hz to order {top}: {:+.3?} %, spurious {spurious:?}, \
             set aside {:?}",
            io.band,
            nearest.iter().map(|(_, e)| 100.0 * e).collect::<Vec<_>>(),
            io.rejected
                .iter()
                .map(|r| (r.mode.frequency, r.rejection))
                .collect::<Vec<_>>()
        );
        for ((_, error), e) in nearest.iter().zip(&exact) {
            assert!(
                error.abs() < 0.005,
                "{storeys}: {} Hz: {error}",
                e.frequency
            );
        }
        assert!(spurious.is_empty(), "{storeys}: spurious {spurious:?}");
        assert_eq!(io.modes.len(), exact.len(), "{storeys} storeys");
    }
}

/// An eight-storey tower (0.82–8.70 Hz, the `twin synth --storeys 8` tower) under a force at
/// its top over the record's whole band, 0–50 Hz at 100 Hz for 410 s, every floor
/// measured, 2 % white noise. LSCF fitted 0.02–40 Hz, where its modes take the lowest
/// fifth: at the default orders (to 40) nothing stood, no pole was forming at order 40,
/// and the sweep stopped there — 0 modes (as on `twin synth`'s record of this tower). The
/// sweep now goes on while the FRF peaks where no mode stands yet. Measured: to order 80,
/// all eight within +0.078 % (the same tower from `twin synth --seed 3 --noise-fraction
/// 0.02`: 0 modes before, 8 now); none spurious. Bars: the 0.5 %, none spurious.
#[test]
fn an_eight_storey_tower_forced_at_its_top_over_a_broad_band() {
    let (data, exact) = record(
        8,
        (&[5.2; 8], &[4021.0; 8], &[3.0; 8]),
        8,
        (100.0, 410.0),
        (0.0, 50.0),
        &(1..=8).collect::<Vec<_>>(),
        0.0,
        3,
    );
    let found = identify(&[data], &IdentifyOptions::default()).expect("identified");
    let io = found.input_output.as_ref().expect("LSCF ran");
    let top = io.diagram.orders.last().map_or(0, |o| o.order);
    let frequencies = lscf_frequencies(&found);
    let (nearest, spurious) = matched(&frequencies, &exact);
    println!(
        "to order {top}: {frequencies:.4?}, {:+.3?} %, spurious {spurious:?}",
        nearest.iter().map(|(_, e)| 100.0 * e).collect::<Vec<_>>()
    );
    let within = nearest.iter().filter(|(_, e)| e.abs() < 0.005).count();
    assert_eq!(within, exact.len(), "{frequencies:?}");
    assert!(spurious.is_empty(), "spurious {spurious:?}");
}

/// A ten-storey tower (0.66–8.75 Hz, damping 0.16–2.05 %; the `twin synth --storeys 10`
/// tower) under a force at its top over 0–50 Hz, 100 Hz for 300 s, every floor measured,
/// 2 % white noise. Its top two modes, 8.458 and 8.753 Hz, are 3.5 % apart at 2 %
/// damping: one hump in the FRF, the top mode a shoulder of it, and the peak screen set it
/// aside (measured: 9 of 10 modes, 8.7629 Hz "no peak", on this record and on `twin
/// synth`'s). It is judged now after the other modes' fitted contributions are taken away.
/// Measured: ten modes within +0.118 % (the top one); none spurious. Bars: the issue's
/// 0.5 %, none spurious. (With 2 % coloured noise as well, LSCF's diagram holds no cluster
/// at the top mode at all — 9 of 10, not held here.)
#[test]
fn a_mode_on_its_neighbours_shoulder_is_kept() {
    let (data, exact) = record(
        10,
        (&[5.2; 10], &[4021.0; 10], &[3.0; 10]),
        10,
        (100.0, 300.0),
        (0.0, 50.0),
        &(1..=10).collect::<Vec<_>>(),
        0.0,
        1,
    );
    let found = identify(&[data], &IdentifyOptions::default()).expect("identified");
    let io = found.input_output.as_ref().expect("LSCF ran");
    let (nearest, spurious) = matched(&lscf_frequencies(&found), &exact);
    println!(
        "{:+.3?} %, spurious {spurious:?}, set aside {:?}",
        nearest.iter().map(|(_, e)| 100.0 * e).collect::<Vec<_>>(),
        io.rejected
            .iter()
            .map(|r| (r.mode.frequency, r.rejection))
            .collect::<Vec<_>>()
    );
    for ((_, error), e) in nearest.iter().zip(&exact) {
        assert!(error.abs() < 0.005, "{} Hz: {error}", e.frequency);
    }
    assert!(spurious.is_empty(), "spurious {spurious:?}");
    assert_eq!(io.modes.len(), exact.len());
}

/// FDD/EFDD (output-only, non-parametric: the spectral matrix's first singular value,
/// EFDD's SDOF bells) on the band-limited five-storey record, a cross-check: it finds the
/// five modes, and the verdicts table holds each with all three methods. What FDD alone
/// found (peaks of the coloured noise under 1.2 Hz, one at 11.37 Hz) was marked one method
/// only; its peaks are now screened, those under 1.2 Hz set aside `unseparated` (the first
/// singular value 2.4–4.4 times the second), and none is left. Measured: frequencies −0.16
/// to +0.18 % (−0.19 to +0.36 % before EFDD read its crossings where the correlation
/// decays), damping −16 to +14 % (mode 1, 0.35 % and 2.8 bins wide, fitted through the
/// window's kernel: +0.2 %, 0.01 sd; −26 % from the correlation's decay), MAC with the
/// other methods 0.940 (mode 3) to 1.000; no FDD-only peak. Bars: 0.5 %, 30 %, mode 1
/// within 2.5 sd, MAC 0.90, none FDD-only.
#[test]
fn fdd_cross_checks_the_parametric_methods() {
    let (data, exact) = five_storeys();
    let found = identify(&[data], &IdentifyOptions::default()).expect("identified");
    for m in &found.fdd.modes {
        println!(
            "FDD {:.4} ± {:.4} Hz ζ {:.3} ± {:.3} %",
            m.identified.frequency,
            m.identified.frequency_sd,
            100.0 * m.identified.damping,
            100.0 * m.identified.damping_sd
        );
    }
    let fdd: Vec<f64> = frequencies_of(&found.fdd.modes);
    let (nearest, spurious) = matched(&fdd, &exact);
    for ((i, error), e) in nearest.iter().zip(&exact) {
        let damping = found.fdd.modes[*i].identified.damping / e.damping - 1.0;
        println!(
            "{:.4} Hz: FDD {:+.3} %, damping {:+.1} %",
            e.frequency,
            100.0 * error,
            100.0 * damping
        );
        assert!(error.abs() < 0.005, "{} Hz: {error}", e.frequency);
        assert!(
            damping.abs() < 0.30,
            "{} Hz: damping {damping}",
            e.frequency
        );
    }
    let first = &found.fdd.modes[nearest[0].0].identified;
    let sds = (first.damping - exact[0].damping) / first.damping_sd;
    println!("mode 1: damping {sds:+.2} sd");
    assert!(sds.abs() < 2.5, "mode 1 damping {sds} sd");
    for v in &found.verdicts {
        let near_exact = exact
            .iter()
            .any(|e| (v.frequency / e.frequency - 1.0).abs() < 0.01);
        let methods: Vec<&str> = v.found_by.iter().map(|m| m.method).collect();
        println!(
            "verdict {:.4} Hz: {methods:?}, one method only {}",
            v.frequency, v.one_method_only
        );
        if near_exact {
            assert_eq!(methods.len(), 3, "{} Hz: {methods:?}", v.frequency);
            println!(
                "  MACs {:?}",
                v.macs.iter().map(|a| a.mac).collect::<Vec<_>>()
            );
            assert!(v.macs.iter().all(|a| a.mac > 0.90), "{:?}", v.macs);
        } else {
            assert!(v.one_method_only && methods == ["FDD/EFDD"], "{methods:?}");
        }
    }
    println!("FDD-only peaks {spurious:.4?}");
    assert!(spurious.is_empty(), "FDD-only peaks {spurious:?}");
}
