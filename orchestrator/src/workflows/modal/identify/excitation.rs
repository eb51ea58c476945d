//! The measured force's own spectral peaks (a mass damper's or a shaker's narrow band over a
//! broad floor), and the modes set aside there as the excitation's: a response peak the force
//! makes where the structure does not resonate (no FRF peak) is no mode of the structure.

use numerics::modal::stabilisation::{RejectedMode, Rejection};

use super::band::MEASURED_COHERENCE;
use super::peaks::Peaks;
use super::report::RecordMode;

/// A run of bins stands as the force's own peak when its PSD is at least this many times the
/// force's median over the band it excites: 10 dB. A Welch average of four segments puts a
/// bin of a flat force this far above the median about once in 10¹⁰ bins.
pub const FORCE_PEAK: f64 = 10.0;
/// The widest a force's peak is, relative to its centre: a narrow band (a mass damper's
/// ±0.1 Hz at 2.5 Hz is 8 %), not a force whose level merely slopes across its band.
pub const FORCE_PEAK_WIDTH: f64 = 0.25;

/// Hz, the force's own peaks within `band`, the band it excites: each run of bins where
/// `force_psd` stands [`FORCE_PEAK`] times above its median over `band`, at most
/// [`FORCE_PEAK_WIDTH`] of its centre wide, widened by a bin each side; else, for a force whose
/// power is all in one narrow band, that band ([`narrow_band`]). None for a force flat over a
/// broad band (a shaker's band-limited noise).
pub(super) fn force_peaks(
    frequencies: &[f64],
    force_psd: &[f64],
    band: (f64, f64),
) -> Vec<(f64, f64)> {
    let within = peaks_within(frequencies, force_psd, band);
    if !within.is_empty() {
        return within;
    }
    narrow_band(frequencies, force_psd, band)
        .into_iter()
        .collect()
}

/// The band a force excites, widened by a bin each side, when the force's power is all there
/// and the band is narrow: at most [`FORCE_PEAK_WIDTH`] of its centre wide, its median PSD
/// [`FORCE_PEAK`] times above the median of the rest of the spectrum (a mass damper or a
/// shaker held at one frequency, with no floor for a peak to stand above inside the band). On
/// a 5-storey tower driven at 2.4–2.6 Hz alone, FDD read the force's band as a 2.54 Hz mode
/// (its modes 1.26 and 3.68 Hz on either side).
fn narrow_band(frequencies: &[f64], force_psd: &[f64], band: (f64, f64)) -> Option<(f64, f64)> {
    let (low, high) = band;
    if high - low > FORCE_PEAK_WIDTH * 0.5 * (low + high) || frequencies.len() < 2 {
        return None;
    }
    let bins = |inside: bool| {
        (1..frequencies.len().min(force_psd.len()))
            .filter(move |&k| (frequencies[k] >= low && frequencies[k] <= high) == inside)
    };
    let bin = frequencies[1] - frequencies[0];
    let (inside, outside) = (
        median_level(force_psd, bins(true))?,
        median_level(force_psd, bins(false))?,
    );
    (inside > 0.0 && inside >= FORCE_PEAK * outside).then_some((low - bin, high + bin))
}

/// [`force_peaks`]'s runs of bins standing above the force's median over `band`.
fn peaks_within(frequencies: &[f64], force_psd: &[f64], band: (f64, f64)) -> Vec<(f64, f64)> {
    let bins: Vec<usize> = (1..frequencies.len().min(force_psd.len()))
        .filter(|&k| frequencies[k] >= band.0 && frequencies[k] <= band.1)
        .collect();
    if bins.len() < 3 {
        return Vec::new();
    }
    let Some(median) = median_level(force_psd, bins.iter().copied()) else {
        return Vec::new();
    };
    let bin = frequencies[1] - frequencies[0];
    let mut peaks = Vec::new();
    let mut run: Option<(f64, f64)> = None;
    for &k in &bins {
        let f = frequencies[k];
        if force_psd[k] >= FORCE_PEAK * median && median > 0.0 {
            run = Some(run.map_or((f, f), |(low, _)| (low, f)));
        } else if let Some(r) = run.take() {
            peaks.push(r);
        }
    }
    peaks.extend(run);
    peaks
        .into_iter()
        .filter(|(low, high)| high - low <= FORCE_PEAK_WIDTH * 0.5 * (low + high))
        .map(|(low, high)| (low - bin, high + bin))
        .collect()
}

/// The median of `force_psd` over `bins`; None when there are none.
fn median_level(force_psd: &[f64], bins: impl Iterator<Item = usize>) -> Option<f64> {
    let mut levels: Vec<f64> = bins.map(|k| force_psd[k]).collect();
    levels.sort_by(f64::total_cmp);
    levels.get(levels.len() / 2).copied()
}

/// Moves the modes of `modes` that lie in one of the force's `peaks` and that no FRF peak
/// supports (`frf`: each channel's FRF magnitude, with its coherence; judged on the bins where
/// it is measured, [`coherent_only`]) to `rejected`
/// ([`Rejection::Excitation`]). An output-only method reads the responses, whose spectrum
/// peaks where the force does; the FRF divides the force out, and peaks there only where
/// the structure resonates (a mass damper tuned to a mode: kept).
pub(super) fn set_aside_excitation(
    modes: &mut Vec<RecordMode>,
    rejected: &mut Vec<RejectedMode>,
    peaks: &[(f64, f64)],
    frf: &Peaks,
) {
    if peaks.is_empty() {
        return;
    }
    let coherent = coherent_only(frf);
    let evidence = coherent.of();
    let (forced, kept): (Vec<RecordMode>, Vec<RecordMode>) =
        std::mem::take(modes).into_iter().partition(|m| {
            let f = m.identified.frequency;
            peaks.iter().any(|(low, high)| f >= *low && f <= *high) && !evidence.supports(f)
        });
    *modes = kept;
    if forced.is_empty() {
        return;
    }
    rejected.extend(
        forced
            .into_iter()
            .map(|m| RejectedMode::new(m.identified, Rejection::Excitation)),
    );
    rejected.sort_by(|a, b| a.mode.frequency.total_cmp(&b.mode.frequency));
}

/// `frf` with each curve's bins of coherence below [`MEASURED_COHERENCE`] left out (NaN: the
/// peak test takes neither a peak nor a valley there). Beside a force's narrow peak over a
/// weak floor, the FRF is exact inside the peak and noise over the floor just outside it,
/// whose dips made a smooth FRF look like a peak at a mass damper's 2.5 Hz (between the
/// tower's 1.26 and 3.68 Hz modes) with a floor 58 dB below it.
fn coherent_only(frf: &Peaks) -> Peaks {
    let Some(coherence) = &frf.coherence else {
        return frf.clone();
    };
    let curves = frf
        .curves
        .iter()
        .zip(coherence)
        .map(|(curve, c)| {
            curve
                .iter()
                .zip(c)
                .map(|(v, c)| {
                    if *c >= MEASURED_COHERENCE {
                        *v
                    } else {
                        f64::NAN
                    }
                })
                .collect()
        })
        .collect();
    Peaks {
        curves,
        ..frf.clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A narrow band 10⁴ times above a broad floor is the force's peak; a flat band-limited
    /// force has none; a force that is all one narrow band has that band (a flat spectrum
    /// read over a narrow band has none).
    #[test]
    fn a_narrow_band_over_a_floor_is_the_forces_peak() {
        let frequencies: Vec<f64> = (0..500).map(|k| 0.1 * k as f64).collect();
        let floor_and_peak: Vec<f64> = (0..500)
            .map(|k| if (24..=26).contains(&k) { 1.0 } else { 1e-4 })
            .collect();
        let peaks = force_peaks(&frequencies, &floor_and_peak, (0.1, 49.9));
        assert_eq!(peaks.len(), 1);
        let (low, high) = peaks[0];
        assert!(
            (low - 2.3).abs() < 1e-9 && (high - 2.7).abs() < 1e-9,
            "{peaks:?}"
        );
        let flat = vec![1.0; 500];
        assert!(force_peaks(&frequencies, &flat, (0.1, 49.9)).is_empty());
        let narrow = force_peaks(&frequencies, &floor_and_peak, (2.4, 2.6));
        assert_eq!(narrow.len(), 1, "{narrow:?}");
        assert!(
            (narrow[0].0 - 2.3).abs() < 1e-9 && (narrow[0].1 - 2.7).abs() < 1e-9,
            "{narrow:?}"
        );
        assert!(force_peaks(&frequencies, &flat, (2.4, 2.6)).is_empty());
        // All its power in 1–4 Hz, wider than a quarter of its centre: a band-limited force,
        // not a peak.
        let band_limited: Vec<f64> = (0..500)
            .map(|k| if (10..=40).contains(&k) { 1.0 } else { 1e-4 })
            .collect();
        assert!(force_peaks(&frequencies, &band_limited, (1.0, 4.0)).is_empty());
    }
}
