//! The measured curves a method's modes must peak in (each channel's FRF, or the responses'
//! spectrum), and where they peak.

use numerics::modal::spectral::Frf;
use numerics::modal::stabilisation::{IdentifiedMode, PeakEvidence, PEAK_COHERENCE};

use super::SpectrumReport;

/// The measured magnitudes a method's modes must peak in: each channel's FRF magnitude for
/// the input–output method, the responses' total spectrum (its square root) for SSI-COV.
#[derive(Clone)]
pub(super) struct Peaks {
    pub(super) frequencies: Vec<f64>,
    pub(super) curves: Vec<Vec<f64>>,
    pub(super) coherence: Option<Vec<Vec<f64>>>,
}

impl Peaks {
    pub(super) fn of_frf(frf: &Frf) -> Peaks {
        Peaks {
            frequencies: frf.frequencies.clone(),
            curves: frf
                .response
                .iter()
                .map(|h| h.iter().map(|v| v.norm()).collect())
                .collect(),
            coherence: Some(frf.coherence.clone()),
        }
    }

    pub(super) fn of_spectrum(spectrum: &SpectrumReport) -> Peaks {
        Peaks {
            frequencies: spectrum.frequencies.clone(),
            curves: vec![spectrum.total.iter().map(|v| v.max(0.0).sqrt()).collect()],
            coherence: None,
        }
    }

    /// Hz: the frequencies within `band` where some curve peaks — the largest within two bins
    /// either side, coherent there (an FRF's [`PEAK_COHERENCE`]) and supported as a mode's peak
    /// would be ([`PeakEvidence::supports`]).
    pub(super) fn peaks_within(&self, band: (f64, f64)) -> Vec<f64> {
        let evidence = self.of();
        let mut peaks: Vec<f64> = Vec::new();
        let n = self.frequencies.len();
        for k in 2..n.saturating_sub(2) {
            let f = self.frequencies[k];
            if f < band.0 || f > band.1 || peaks.last() == Some(&f) {
                continue;
            }
            let peaked = self.curves.iter().enumerate().any(|(i, curve)| {
                // Coherent within the two bins either side, as the peak screen judges it: a
                // resonance narrower than a bin dips H1's coherence at its own bin (the lab
                // frame's 0.39 %-damped 3.17 Hz on 0.12 Hz bins: 0.17 there, 0.73–0.81 a bin
                // either side) by the leakage's bias, not by noise.
                let coherent = self
                    .coherence
                    .as_ref()
                    .is_none_or(|c| (k - 2..=k + 2).any(|j| c[i][j] >= PEAK_COHERENCE));
                coherent && (k - 2..=k + 2).all(|j| curve[j] <= curve[k])
            });
            if peaked && evidence.supports(f) {
                peaks.push(f);
            }
        }
        peaks
    }

    /// Whether some curve's coherence reaches `least` within two bins of `frequency` (a
    /// spectrum, without coherence: always). Two bins, as [`Peaks::peaks_within`] judges a
    /// peak coherent: a resonance narrower than a bin dips H1's coherence at its own bin.
    pub(super) fn coherent_near(&self, frequency: f64, least: f64) -> bool {
        let Some(coherence) = &self.coherence else {
            return true;
        };
        let near = match self.frequencies.as_slice() {
            [a, b, ..] => 2.0 * (b - a),
            _ => return true,
        };
        let bins: Vec<usize> = (0..self.frequencies.len())
            .filter(|k| (self.frequencies[*k] - frequency).abs() <= near)
            .collect();
        coherence
            .iter()
            .any(|c| bins.iter().any(|k| c.get(*k).is_some_and(|v| *v >= least)))
    }

    pub(super) fn of(&self) -> PeakEvidence<'_> {
        PeakEvidence {
            frequencies: &self.frequencies,
            curves: &self.curves,
            coherence: self.coherence.as_deref(),
        }
    }
}

/// Whether a mode of `modes` lies at the peak `frequency` (Hz): within the selection's
/// cluster distance (1 %) or two bins of `bins`' spacing, whichever is wider.
pub(super) fn explained(frequency: f64, modes: &[IdentifiedMode], bins: &[f64]) -> bool {
    let bin = match bins {
        [a, b, ..] => b - a,
        _ => 0.0,
    };
    let within = (0.01 * frequency).max(2.0 * bin);
    modes
        .iter()
        .any(|m| (m.frequency - frequency).abs() <= within)
}
