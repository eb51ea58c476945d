//! `twin modal`'s twin side: the modes of a twin are its structure's exact modes, and their
//! linearised posterior sds agree with sampling the posterior.

use orchestrator::twin::{ParameterCovariance, Twin};
use orchestrator::workflows::modal::{pair_modes, twin_modes, ModalOptions, ObservedMode};
use structure::{Excitation, Structure};

fn five_storeys() -> Structure {
    Structure {
        mass: vec![1200.0, 1150.0, 1100.0, 1050.0, 900.0],
        damping: vec![900.0, 850.0, 800.0, 750.0, 700.0],
        stiffness: vec![2.4e6, 2.2e6, 2.0e6, 1.8e6, 1.5e6],
        excitation: Excitation::Base,
    }
}

/// A posterior with sds of 3 % on the stiffnesses, 2 % on the masses and 10 % on the
/// dampings, stiffnesses of neighbouring storeys correlated 0.5 and each mass with its storey's
/// stiffness 0.3 (a calibration's covariance looks like this: mass and stiffness trade off).
fn posterior(s: &Structure) -> ParameterCovariance {
    let names = s.parameter_names();
    let sd: Vec<f64> = names
        .iter()
        .map(|n| {
            let v = s.get(n).unwrap();
            v * match &n[..1] {
                "k" => 0.03,
                "m" => 0.02,
                _ => 0.10,
            }
        })
        .collect();
    let matrix = (0..names.len())
        .map(|a| {
            (0..names.len())
                .map(|b| {
                    let (na, nb) = (&names[a], &names[b]);
                    let (ka, kb) = (&na[..1], &nb[..1]);
                    let (ia, ib): (i32, i32) = (na[1..].parse().unwrap(), nb[1..].parse().unwrap());
                    let r = if a == b {
                        1.0
                    } else if ka == "k" && kb == "k" && (ia - ib).abs() == 1 {
                        0.5
                    } else if ((ka, kb) == ("m", "k") || (ka, kb) == ("k", "m")) && ia == ib {
                        0.3
                    } else {
                        0.0
                    };
                    r * sd[a] * sd[b]
                })
                .collect()
        })
        .collect();
    ParameterCovariance { names, matrix }
}

#[test]
fn a_twins_modes_are_its_structures_with_sds_that_sampling_confirms() {
    let structure = five_storeys();
    let mut twin = Twin::for_structure(&structure).unwrap();
    let uncalibrated = twin_modes(&twin, &ModalOptions::default()).unwrap();
    assert_eq!(uncalibrated.modes.len(), 5);
    assert!(uncalibrated.modes.iter().all(|m| m.frequency_sd.is_none()));
    // Undamped natural frequencies of the structure: the twin's differ by the damping only
    // (|λ| is the undamped ω for proportional damping; here nearly so): ≤ 3e-6 seen, 1e-4 asked.
    let undamped = structure.natural_frequencies();
    for (m, f) in uncalibrated.modes.iter().zip(&undamped) {
        assert!((m.frequency - f).abs() / f < 1e-4, "{} vs {f}", m.frequency);
        assert!(m.damping > 0.0 && m.damping < 0.05);
        assert!(m.shape.iter().any(|x| (x - 1.0).abs() < 1e-12));
    }

    twin.parameter_covariance = Some(posterior(&structure));
    let options = ModalOptions {
        samples: 20000,
        seed: 7,
    };
    let modes = twin_modes(&twin, &options).unwrap();
    assert_eq!(modes.uncertain_parameters.len(), 15);
    for m in &modes.modes {
        let sampled = m.sampled.as_ref().unwrap();
        assert_eq!(sampled.draws, 20000);
        let (f_sd, z_sd) = (m.frequency_sd.unwrap(), m.damping_sd.unwrap());
        // The frequency is nearly linear in the parameters over a few %: the linearised sds are
        // within 0.4 % (frequency) and 0.9 % (damping) of the sampled ones (seen); 20000 draws
        // estimate an sd to ±0.5 % (1 σ), so 6 % leaves room for the sampling and the curvature.
        let f_err = (f_sd - sampled.frequency_sd).abs() / sampled.frequency_sd;
        let z_err = (z_sd - sampled.damping_sd).abs() / sampled.damping_sd;
        eprintln!(
            "mode {}: f {f_sd:.5} vs {:.5} ({f_err:.4}); ζ {z_sd:.3e} vs {:.3e} ({z_err:.4})",
            m.number, sampled.frequency_sd, sampled.damping_sd
        );
        assert!(
            f_err < 0.06,
            "mode {}: frequency sd {f_sd} vs sampled {}",
            m.number,
            sampled.frequency_sd
        );
        assert!(
            z_err < 0.06,
            "mode {}: damping sd {z_sd} vs sampled {}",
            m.number,
            sampled.damping_sd
        );
        // A frequency sd of 1–2 % for stiffness sds of 3 % and mass sds of 2 %.
        assert!(f_sd / m.frequency > 0.005 && f_sd / m.frequency < 0.03);
        assert!(m.shape_sd.as_ref().unwrap().iter().all(|s| s.is_finite()));
    }
}

#[test]
fn a_softer_storey_pairs_as_a_frequency_drop_in_units_of_the_sd() {
    let structure = five_storeys();
    let mut twin = Twin::for_structure(&structure).unwrap();
    twin.parameter_covariance = Some(posterior(&structure));
    let modes = twin_modes(
        &twin,
        &ModalOptions {
            samples: 0,
            seed: 1,
        },
    )
    .unwrap();
    // The "record": the same building with storey 2 15 % softer, measured at floors 1, 3 and 5,
    // its modes listed in another order.
    let mut damaged = structure.clone();
    damaged.stiffness[1] *= 0.85;
    let exact = orchestrator::workflows::modal::twin::structure_modes(&damaged).unwrap();
    let floors = [1usize, 3, 5];
    let observed: Vec<ObservedMode> = exact
        .iter()
        .rev()
        .map(|m| ObservedMode {
            frequency: m.frequency,
            frequency_sd: Some(0.001 * m.frequency),
            damping: m.damping,
            damping_sd: None,
            shape: floors.iter().map(|&f| m.shape[f - 1]).collect(),
        })
        .collect();
    let comparison = pair_modes(&modes, &observed, &floors);
    assert_eq!(comparison.pairs.len(), 5);
    for p in &comparison.pairs {
        // Listed in reverse: twin mode i is observed mode 6 − i.
        assert_eq!(p.observed_mode, 6 - p.twin_mode);
        assert!(p.frequency_shift_percent < 0.0);
        assert!(p.mac > 0.9);
    }
    let first = &comparison.pairs[0];
    let drop = comparison.largest_drop().unwrap();
    assert!(drop.frequency_shift_sd.unwrap() < first.frequency_shift_sd.unwrap() + 1e-12);
    assert_eq!(comparison.mac_matrix.len(), 5);
}

// ---------------------------------------------------------------------------------------------
// Modes identified from records unlike the twin's own: band-limited forces, light damping,
// coloured sensor noise, one accelerometer per run (made by `twin synth`'s generator).
// ---------------------------------------------------------------------------------------------

mod records {
    use numerics::modal::stabilisation::{IdentifiedMode, Rejection};
    use numerics::modal::{mac, modes, Mode};
    use orchestrator::record::{AmbientRecord, Measurement};
    use orchestrator::synth::{synth_record, NoiseLevel, Scenario};
    use orchestrator::workflows::modal::identify::{RecordMode, RecordModes};
    use orchestrator::workflows::modal::{identify, identify_ambient, IdentifyOptions};
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
    fn record(
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
    fn matched(found: &[f64], exact: &[Mode]) -> (Vec<(usize, f64)>, Vec<f64>) {
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
    fn damping_within_bar(m: &IdentifiedMode, e: &Mode) -> bool {
        (m.damping - e.damping).abs() <= (0.10 * e.damping).max(2.5 * m.damping_sd)
    }

    /// Every exact mode found by LSCF within the 0.5 % and its damping within the
    /// larger of 10 % and 2.5 reported sds, and no LSCF mode 1 % from every exact one.
    fn lscf_holds_every_mode(found: &RecordModes, exact: &[Mode]) {
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

    fn lscf_frequencies(found: &RecordModes) -> Vec<f64> {
        frequencies_of(&found.input_output.as_ref().expect("LSCF ran").modes)
    }

    /// The identified frequencies of a method's modes, in its order.
    fn frequencies_of(modes: &[RecordMode]) -> Vec<f64> {
        modes.iter().map(|m| m.identified.frequency).collect()
    }

    /// Five storeys (5.0–33.9 Hz, damping 0.35–2.3 %), the force at floor 2 band-limited to
    /// 0.5–40 Hz (the fifth mode near the band's top), 200 Hz for 300 s, every floor measured,
    /// 2 % white and 5 % coloured noise. The default LSCF finds every mode and nothing else:
    /// measured within 0.007 %, MAC 1.0000 (bars 0.5 %, 0.95); fitted over 2.98–40.0 Hz (the
    /// coloured noise takes the coherence below 0.5 under 3 Hz).
    #[test]
    fn lscf_finds_every_mode_of_a_band_limited_record_and_nothing_else() {
        let (data, exact) = record(
            5,
            (&[5.2; 5], &[64_000.0; 5], &[14.0; 5]),
            2,
            (200.0, 300.0),
            (0.5, 40.0),
            &[1, 2, 3, 4, 5],
            0.05,
            11,
        );
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
    /// FDD, a cross-check, kept 4.1457 Hz, no mode: printed, not asserted (open).
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

    /// A five-storey tower (1.26–8.49 Hz, damping 0.30–2.0 %) driven at its top floor by a
    /// mass damper's narrow-band force, 1.0–1.5 Hz, 100 Hz for 410 s, every floor measured,
    /// 2 % white and 2 % coloured noise: only the first mode is in the force's band, so it is
    /// the one mode the FRF supports. The default identification fits LSCF over the force's
    /// band alone (before, the empty bins set the force's typical level, every bin counted as
    /// excited, the fit ran over 0–10 Hz and found nothing; then its basis lost rank at order
    /// 16 and `twin modal` failed) and reports poles at that mode only; FDD/EFDD over the same
    /// band and SSI-COV invent nothing elsewhere. The mode's half-power width (0.0074 Hz) is
    /// 1.2 bins of the FRF (0.0061 Hz, 16,384-sample segments), and LSCF splits its leaky peak
    /// into two modes of one shape, 1.2543 and 1.2616 Hz (−0.43 / +0.15 %, damping 0.245 and
    /// 0.364 % for 0.295 %, MAC 1.0000 both): the one of fewer poles (1.2616 Hz) is now set
    /// aside as the same resonance, and the mode reported once; refined in the time domain
    /// (a leaky mode), it is 1.2597 Hz (+0.000 %), damping 0.295 % for 0.295 %. FDD
    /// 1.2576 Hz. Bars: 1 %, MAC 0.95, one LSCF mode, nothing elsewhere.
    #[test]
    fn a_mass_dampers_narrow_band_shows_the_one_mode_it_excites() {
        let (data, exact) = record(
            5,
            (&[5.2; 5], &[4021.0; 5], &[3.0; 5]),
            5,
            (100.0, 410.0),
            (1.0, 1.5),
            &[1, 2, 3, 4, 5],
            0.02,
            3,
        );
        let found = identify(&[data], &IdentifyOptions::default()).expect("identified");
        let io = found.input_output.as_ref().expect("LSCF ran");
        let (low, high) = io.band.expect("LSCF's band");
        assert!(
            low >= 0.95 && high <= 1.55,
            "the fit band {low}–{high} Hz is the force's"
        );
        let first = &exact[0];
        for r in &io.rejected {
            println!(
                "set aside {:.4} Hz (ζ {:.3} %): {}",
                r.mode.frequency,
                100.0 * r.mode.damping,
                r.reason
            );
        }
        // The one resonance reported once (LSCF split its leaky peak into two poles of one
        // shape; the weaker is set aside as the same resonance).
        assert_eq!(io.modes.len(), 1, "{:?}", lscf_frequencies(&found));
        for m in &io.modes {
            let error = m.identified.frequency / first.frequency - 1.0;
            let shape = mac(&m.displacement_shape, &first.shape);
            println!(
                "LSCF {:.4} Hz ({:+.3} %), ζ {:.3} ± {:.3} % for {:.3} %, MAC {shape:.5}",
                m.identified.frequency,
                100.0 * error,
                100.0 * m.identified.damping,
                100.0 * m.identified.damping_sd,
                100.0 * first.damping
            );
            assert!(
                error.abs() < 0.01,
                "LSCF {} Hz: {error}",
                m.identified.frequency
            );
            assert!(shape > 0.95, "MAC {shape}");
        }
        let ssi: Vec<f64> = frequencies_of(&found.ssi.modes);
        let (_, spurious) = matched(&ssi, &exact);
        assert!(spurious.is_empty(), "SSI-COV spurious {spurious:?}");
        let fdd: Vec<f64> = frequencies_of(&found.fdd.modes);
        println!("FDD {fdd:?}");
        let (_, spurious) = matched(&fdd, &exact[..1]);
        assert!(
            spurious.is_empty(),
            "FDD/EFDD outside the band: {spurious:?}"
        );
    }

    /// FDD/EFDD (output-only, non-parametric: the spectral matrix's first singular value,
    /// EFDD's SDOF bells) on the band-limited five-storey record, a cross-check: it finds the
    /// five modes, and the verdicts table holds each with all three methods; what FDD alone
    /// finds (peaks of the coloured noise under 1.2 Hz, one at 11.37 Hz) is marked one method
    /// only. Measured: frequencies −0.16 to +0.18 % (−0.19 to +0.36 % before EFDD read its
    /// crossings where the correlation decays), damping −26 (mode 1, 0.35 %) to +14 %,
    /// MAC with the other methods 0.940 (mode 3) to 1.000; four FDD-only peaks. Bars: 0.5 %,
    /// 30 %, MAC 0.90.
    #[test]
    fn fdd_cross_checks_the_parametric_methods() {
        let (data, exact) = record(
            5,
            (&[5.2; 5], &[64_000.0; 5], &[14.0; 5]),
            2,
            (200.0, 300.0),
            (0.5, 40.0),
            &[1, 2, 3, 4, 5],
            0.05,
            11,
        );
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
    }

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
            let found = identify(std::slice::from_ref(data), &IdentifyOptions::default())
                .expect("identified");
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

    /// The lab frame of the issue: three storeys of 5.201 kg, storey stiffnesses 9562, 11806
    /// and 11332 N/m (modes at 3.170, 9.030 and 13.430 Hz, the peaks of its FRF), storey
    /// dampers of 4 N s/m (0.39, 1.05 and 1.48 %), a shaker at floor 1 band-limited to
    /// 1–60 Hz, 500 Hz for 30 s per run, one accelerometer per run (floors 1, 2, 3), 2 % white
    /// and 5 % coloured noise.
    fn lab_frame_runs() -> Vec<(Measurement, Vec<Mode>)> {
        lab_frame_runs_with(0.05)
    }

    /// [`lab_frame_runs`] with `coloured` × each channel's RMS of coloured noise.
    fn lab_frame_runs_with(coloured: f64) -> Vec<(Measurement, Vec<Mode>)> {
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
            let found = identify(std::slice::from_ref(data), &IdentifyOptions::default())
                .expect("identified");
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
            let found = identify(std::slice::from_ref(&data), &IdentifyOptions::default())
                .expect("identified");
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

    /// A five-storey tower driven at its top by a mass damper: the damper's force narrow-band
    /// around `centre` Hz (±0.1 Hz, RMS 1 N) over a broadband floor (0–50 Hz, RMS `floor_rms`
    /// N, the actuator's and the wind's share), 100 Hz for 410 s, every floor measured, 2 %
    /// white and 2 % coloured noise on each part. The structure is linear, so the record is
    /// the sum of the two parts' records.
    fn mass_damper_record(centre: f64, floor_rms: f64, seed: u64) -> (Measurement, Vec<Mode>) {
        let tower = (&[5.2; 5][..], &[4021.0; 5][..], &[3.0; 5][..]);
        let floors = [1, 2, 3, 4, 5];
        let (mut data, exact) = record(
            5,
            tower,
            5,
            (100.0, 410.0),
            (centre - 0.1, centre + 0.1),
            &floors,
            0.02,
            seed,
        );
        let (broad, _) = record(
            5,
            tower,
            5,
            (100.0, 410.0),
            (0.0, 50.0),
            &floors,
            0.02,
            seed + 7,
        );
        let scale = floor_rms;
        for (v, b) in data
            .excitation
            .values
            .iter_mut()
            .zip(&broad.excitation.values)
        {
            *v += scale * b;
        }
        for (r, b) in data.responses.iter_mut().zip(&broad.responses) {
            for (v, w) in r.values.iter_mut().zip(&b.values) {
                *v += scale * w;
            }
        }
        (data, exact)
    }

    /// A five-storey tower (1.26–8.49 Hz, damping 0.30–2.0 %) driven at its top by a mass
    /// damper whose force is narrow-band at 2.4–2.6 Hz, between modes 1 and 2, over a floor
    /// 50 dB lower (0–50 Hz: [`mass_damper_record`]); 100 Hz for 410 s, every floor measured.
    /// Before: `twin modal` failed outright (LSCF fitted the narrow band alone, 34 bins, too
    /// few for order 40: the floor's bins were below 1 % of the force's typical level); the
    /// same responses without the force (`identify_ambient`) gave SSI-COV 2.5004 Hz (ζ
    /// 0.14 %, MPC 1.000) as a mode and FDD 2.4893 Hz. Now the band is widened to where the
    /// FRF is coherent (0.95–40 Hz), and a mode at the force's own peak that the FRF does not
    /// peak at is set aside `excitation`. Measured: LSCF 5/5 within 0.03 %, damping +0.0 to
    /// +2.3 % (3.68 Hz), none spurious; SSI-COV's 2.5004 Hz and (with the floor at 58 dB) FDD's
    /// 2.4893 Hz set aside `excitation`. Bars: the 0.5 % and damping within the larger
    /// of 10 % and 2.5 reported sds; nothing kept at the force's peak.
    #[test]
    fn a_mass_dampers_force_peak_is_set_aside_as_excitation() {
        let (data, exact) = mass_damper_record(2.5, 0.05, 5);
        let found =
            identify(std::slice::from_ref(&data), &IdentifyOptions::default()).expect("identified");
        let io = found.input_output.as_ref().expect("LSCF ran");
        let (low, high) = io.band.expect("LSCF's band");
        println!("LSCF over {low:.3}–{high:.3} Hz");
        assert!(low < exact[0].frequency && high > exact[4].frequency);
        lscf_holds_every_mode(&found, &exact);
        assert_eq!(io.modes.len(), exact.len());
        let at_peak = |f: f64| (2.4..=2.6).contains(&f);
        let methods = [
            (io.method, &io.modes, &io.rejected),
            (found.ssi.method, &found.ssi.modes, &found.ssi.rejected),
            (found.fdd.method, &found.fdd.modes, &found.fdd.rejected),
        ];
        for (method, modes, rejected) in methods {
            let kept = frequencies_of(modes);
            let excitation: Vec<f64> = rejected
                .iter()
                .filter(|r| r.rejection == Rejection::Excitation)
                .map(|r| r.mode.frequency)
                .collect();
            println!("{method}: kept {kept:.4?}, excitation {excitation:.4?}");
            assert!(!kept.iter().any(|f| at_peak(*f)), "{method} kept {kept:?}");
            assert!(excitation.iter().all(|f| at_peak(*f)), "{excitation:?}");
        }
        let ssi_excitation = found
            .ssi
            .rejected
            .iter()
            .filter(|r| r.rejection == Rejection::Excitation);
        assert_eq!(
            ssi_excitation.count(),
            1,
            "SSI-COV's pole at the force's peak"
        );
        // The same responses without the force: output-only, nothing tells the force's peak
        // from a mode (a narrow-band random force is a resonance of what drives the tower).
        // Measured: SSI-COV 2.5004 Hz (ζ 0.14 %) kept beside 3.67–8.49 Hz; printed only.
        let ambient = AmbientRecord {
            path: data.path.clone(),
            time: data.time.clone(),
            dt: data.dt,
            responses: data.responses.clone(),
            header_line: None,
        };
        let found = identify_ambient(&[ambient], &IdentifyOptions::default()).expect("ambient");
        println!(
            "without the force: SSI-COV {:.4?}",
            frequencies_of(&found.ssi.modes)
        );
    }

    /// The same tower driven by the mass damper's narrow band alone (2.4–2.6 Hz, no floor):
    /// the band the force excites is the whole of its power, and no method may read it as a
    /// mode. Before: the identification failed (the band's 41 bins short of LSCF's order 40),
    /// and on a `twin synth` record of the same kind FDD kept 2.54 Hz (ζ 2.9 %), the force's
    /// band read as a resonance (the tower's modes are 1.26 and 3.68 Hz either side). Now LSCF
    /// fits the orders the band's bins allow, the band itself is the force's peak
    /// (`narrow_band`), and what sits in it without an FRF peak is set aside `excitation`.
    /// Measured: SSI-COV keeps 3.6965 Hz (+0.53 %) and sets aside 2.5021 Hz, FDD sets aside
    /// 2.4893 Hz, LSCF keeps nothing. Bars: nothing kept at the force's band, whatever is kept
    /// within the 1 % of a mode.
    #[test]
    fn a_force_all_in_one_narrow_band_is_no_mode() {
        let (data, exact) = mass_damper_record(2.5, 0.0, 5);
        let found =
            identify(std::slice::from_ref(&data), &IdentifyOptions::default()).expect("identified");
        let at_peak = |f: f64| (2.35..=2.65).contains(&f);
        let mut methods = vec![
            (found.ssi.method, &found.ssi.modes, &found.ssi.rejected),
            (found.fdd.method, &found.fdd.modes, &found.fdd.rejected),
        ];
        if let Some(io) = &found.input_output {
            methods.push((io.method, &io.modes, &io.rejected));
        }
        for (method, modes, rejected) in methods {
            let kept = frequencies_of(modes);
            let set_aside: Vec<(f64, Rejection)> = rejected
                .iter()
                .map(|r| (r.mode.frequency, r.rejection))
                .collect();
            println!("{method}: kept {kept:.4?}, set aside {set_aside:.4?}");
            assert!(!kept.iter().any(|f| at_peak(*f)), "{method} kept {kept:?}");
            // Whatever is kept is one of the tower's modes (within the 1 %).
            for f in kept {
                let nearest = exact
                    .iter()
                    .map(|e| (f / e.frequency - 1.0).abs())
                    .fold(f64::INFINITY, f64::min);
                assert!(nearest < 0.01, "{method} kept {f} Hz, no mode of the tower");
            }
        }
    }
}
