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
