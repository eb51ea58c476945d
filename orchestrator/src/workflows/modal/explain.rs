//! Which single change of the twin's structure explains the record's modes: for each floor's
//! mass and each storey's stiffness, the relative change that moves the twin's paired
//! frequencies closest to the identified ones, and how close. Every paired mode counts, moved
//! or not (a mode that stayed says the change left it alone), each weighted by the sd its band
//! stands for. The diagnosis of an ambient record names the best ([`super::super::diagnose`]).

use serde::Serialize;
use structure::Structure;

use super::evidence::ModalEvidence;
use super::twin::structure_modes;
use super::ModalError;

/// One parameter's change and its fit to the identified frequencies.
#[derive(Debug, Clone, Serialize)]
pub struct Explanation {
    /// `m<i>` or `k<i>`.
    pub parameter: String,
    /// The relative change, %.
    pub change_percent: f64,
    /// Σ ((f_obs − f_twin)/s)² over the paired modes, s the band's sd, with the change.
    pub misfit: f64,
    /// The twin's frequencies (Hz) with the change, per paired mode.
    pub frequencies: Vec<f64>,
}

/// The explanations of `evidence` by one parameter of `structure` each, best (smallest misfit)
/// first; and the misfit of the structure unchanged.
pub fn explain_shifts(
    structure: &Structure,
    evidence: &ModalEvidence,
) -> Result<(Vec<Explanation>, f64), ModalError> {
    let paired: Vec<(usize, f64, f64)> = evidence
        .modes
        .iter()
        .map(|m| {
            (
                m.pair.twin_mode - 1,
                m.pair.observed_frequency,
                (m.band / evidence.band.sigmas).max(f64::MIN_POSITIVE),
            )
        })
        .collect();
    let misfit_of = |s: &Structure| -> Result<(f64, Vec<f64>), ModalError> {
        let modes = structure_modes(s)?;
        let mut misfit = 0.0;
        let mut frequencies = Vec::with_capacity(paired.len());
        for &(i, observed, sd) in &paired {
            // A change that loses a mode (overdamped) is no explanation.
            let f = modes.get(i).map_or(f64::INFINITY, |m| m.frequency);
            misfit += ((observed - f) / sd).powi(2);
            frequencies.push(f);
        }
        Ok((misfit, frequencies))
    };
    let (unchanged, _) = misfit_of(structure)?;
    let mut explanations = Vec::new();
    for name in structure.parameter_names() {
        if !(name.starts_with('m') || name.starts_with('k')) {
            continue;
        }
        let nominal = structure.get(&name).unwrap_or(f64::NAN);
        let at = |log_factor: f64| -> Result<(f64, Vec<f64>), ModalError> {
            let mut s = structure.clone();
            s.set(&name, nominal * log_factor.exp());
            misfit_of(&s)
        };
        // A grid over factors 0.25–4 finds the basin, golden sections refine it.
        let (low, high) = (0.25f64.ln(), 4f64.ln());
        let steps = 80;
        let mut best = (0.0, unchanged);
        for j in 0..=steps {
            let x = low + (high - low) * j as f64 / steps as f64;
            let (m, _) = at(x)?;
            if m < best.1 {
                best = (x, m);
            }
        }
        let h = (high - low) / steps as f64;
        let (mut a, mut b) = (best.0 - h, best.0 + h);
        let ratio = (5f64.sqrt() - 1.0) / 2.0;
        for _ in 0..40 {
            let (c, d) = (b - ratio * (b - a), a + ratio * (b - a));
            if at(c)?.0 < at(d)?.0 {
                b = d;
            } else {
                a = c;
            }
        }
        let x = 0.5 * (a + b);
        let (misfit, frequencies) = at(x)?;
        let (x, misfit, frequencies) = if misfit <= best.1 {
            (x, misfit, frequencies)
        } else {
            let (m, f) = at(best.0)?;
            (best.0, m, f)
        };
        explanations.push(Explanation {
            parameter: name,
            change_percent: 100.0 * (x.exp() - 1.0),
            misfit,
            frequencies,
        });
    }
    explanations.sort_by(|a, b| a.misfit.total_cmp(&b.misfit));
    Ok((explanations, unchanged))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::workflows::modal::{ModalBand, ModeComparison, ModePair, ModeShift};
    use structure::Excitation;

    /// The exact modes of a uniform four-storey building with storey 2 20 % softer, as if
    /// identified: storey 2's stiffness −20 % explains them with no misfit left — and so does
    /// floor 3's mass +25 %, to 3e-6: in a uniform shear building a storey's stiffness and the
    /// mirrored floor's mass move every frequency alike, so the frequencies cannot tell them
    /// apart. Every other parameter leaves a misfit.
    #[test]
    fn the_softer_storey_explains_exact_shifts() {
        let twin = Structure::uniform(4, 5.2, 3.0, 4021.0, Excitation::Base);
        let mut softer = twin.clone();
        softer.stiffness[1] *= 0.8;
        let (before, after) = (
            structure_modes(&twin).unwrap(),
            structure_modes(&softer).unwrap(),
        );
        let band = ModalBand::default();
        let modes: Vec<ModeShift> = (0..4)
            .map(|i| ModeShift {
                pair: ModePair {
                    twin_mode: i + 1,
                    observed_mode: i + 1,
                    twin_frequency: before[i].frequency,
                    observed_frequency: after[i].frequency,
                    frequency_shift_percent: 0.0,
                    frequency_shift_sd: None,
                    damping_change: 0.0,
                    mac: 1.0,
                },
                twin_frequency_sd: None,
                observed_frequency_sd: None,
                twin_damping: 0.0,
                observed_damping: 0.0,
                band: band.half_width(before[i].frequency, None, None),
                other_frequency: None,
                outside: false,
            })
            .collect();
        let evidence = ModalEvidence {
            method: "exact".into(),
            floors: vec![1, 2, 3, 4],
            band,
            modes,
            shifted: Vec::new(),
            comparison: ModeComparison {
                floors: vec![1, 2, 3, 4],
                pairs: Vec::new(),
                mac_matrix: Vec::new(),
                unpaired_twin: Vec::new(),
                unpaired_observed: Vec::new(),
            },
        };
        let (explanations, unchanged) = explain_shifts(&twin, &evidence).unwrap();
        let mut best: Vec<&str> = explanations[..2]
            .iter()
            .map(|e| e.parameter.as_str())
            .collect();
        best.sort();
        assert_eq!(best, ["k2", "m3"], "{explanations:?}");
        let k2 = explanations.iter().find(|e| e.parameter == "k2").unwrap();
        assert!((k2.change_percent + 20.0).abs() < 0.01, "{k2:?}");
        for e in &explanations[..2] {
            assert!(e.misfit < 1e-4 * unchanged, "{e:?} against {unchanged}");
        }
        assert!(
            explanations[2].misfit > 0.05 * unchanged,
            "{explanations:?}"
        );
    }
}
