//! The band a measured force excites, and what LSCF fits by default: the force's spectrum
//! against its typical level, trimmed to where the FRF is coherent; the screen's options from
//! it.

use numerics::modal::spectral::Frf;
use numerics::modal::stabilisation::ScreenOptions;

use super::IdentifyOptions;

/// What sets an identified mode aside, with the band the force excites (when it was measured,
/// with its FRF: [`measured_band`]).
pub(super) fn screen_options(
    force: Option<(&[f64], &Frf)>,
    frequencies: &[f64],
    options: &IdentifyOptions,
) -> ScreenOptions {
    let excitation =
        force.and_then(|(psd, frf)| measured_band(frequencies, psd, Some(&frf.coherence)));
    ScreenOptions {
        excited: excitation.map(|e| e.0),
        edges: excitation.map_or((false, false), |e| e.1),
        // One Welch bin: two modes closer than that are one resonance split by the fit.
        resolution: options
            .screen
            .resolution
            .or_else(|| frequencies.get(1).copied().filter(|f| *f > 0.0)),
        ..options.screen
    }
}

/// A bin is excited when the force's PSD there is at least this fraction of its typical
/// level ([`typical_level`]): 20 dB down.
pub const EXCITED_FRACTION: f64 = 0.01;

/// The force's typical PSD level over the bins above DC (`levels`, sorted ascending): the
/// 90th percentile, or — for a force whose power sits in a narrow band, as a mass damper's or
/// a sine sweep's over part of the range, where nine bins in ten hold next to nothing — the
/// level at which the bins above it hold half the power, whichever is higher. For a broadband
/// force the percentile is the higher (Welch's levels scatter little about their mean).
pub(super) fn typical_level(levels: &[f64]) -> f64 {
    let percentile = levels[((0.9 * levels.len() as f64) as usize).min(levels.len() - 1)];
    let total: f64 = levels.iter().sum();
    let mut above = 0.0;
    let mut half_power = 0.0;
    for &level in levels.iter().rev() {
        above += level;
        half_power = level;
        if above >= 0.5 * total {
            break;
        }
    }
    percentile.max(half_power)
}

/// The default band's ends are the outermost excited bins where some output's coherence
/// reaches this.
pub const BAND_COHERENCE: f64 = 0.5;

/// The band the force excites, Hz: from the lowest to the highest bin above DC where its PSD
/// is [`EXCITED_FRACTION`] of its typical level; and whether each end is an edge (at least two
/// bins beyond it, inside the record's band, are not excited). None when the force has no
/// power.
pub fn excited_band(frequencies: &[f64], force_psd: &[f64]) -> Option<((f64, f64), (bool, bool))> {
    let bins = frequencies.len().min(force_psd.len());
    if bins < 2 {
        return None;
    }
    let mut levels: Vec<f64> = force_psd[1..bins].to_vec();
    levels.sort_by(f64::total_cmp);
    let typical = typical_level(&levels);
    if typical <= 0.0 || !typical.is_finite() {
        return None;
    }
    let excited = |k: &usize| force_psd[*k] >= EXCITED_FRACTION * typical;
    let low = (1..bins).find(excited)?;
    let high = (1..bins).rev().find(excited)?;
    Some((
        (frequencies[low], frequencies[high]),
        (low >= 3, high + 2 < bins - 1),
    ))
}

/// A bin outside the force's [`excited_band`] is measured all the same where some output's
/// coherence with the force is at least this over [`COHERENT_RUN`] bins in a row.
pub const MEASURED_COHERENCE: f64 = 0.8;
/// How many bins in a row [`MEASURED_COHERENCE`] must hold: noise alone reaches it at a bin
/// now and then (a Welch average of four segments: about one bin in a thousand), not over a
/// run of bins.
pub const COHERENT_RUN: usize = 5;

/// [`excited_band`], widened to the bins where the FRF is measured although the force is
/// weak there beside its strongest part: a mass damper's force, narrow-band around its own
/// frequency, over a floor 50 dB lower (the actuator's and the wind's share), drives the
/// tower's modes well above the sensors' noise (coherence 0.9 and more at them) while every
/// bin of the floor is below [`EXCITED_FRACTION`] of the narrow band's level. The band's
/// ends are from the runs of [`COHERENT_RUN`] bins at [`MEASURED_COHERENCE`] (`coherence`:
/// per output, per bin); an end so widened is not an edge (the response fading into the
/// noise there is not the force falling off).
pub fn measured_band(
    frequencies: &[f64],
    force_psd: &[f64],
    coherence: Option<&[Vec<f64>]>,
) -> Option<((f64, f64), (bool, bool))> {
    let ((low, high), (low_edge, high_edge)) = excited_band(frequencies, force_psd)?;
    let Some((first, last)) = coherence.and_then(|c| coherent_runs(c, frequencies.len())) else {
        return Some(((low, high), (low_edge, high_edge)));
    };
    let (f_first, f_last) = (frequencies[first], frequencies[last]);
    Some((
        (low.min(f_first), high.max(f_last)),
        (low_edge && f_first >= low, high_edge && f_last <= high),
    ))
}

/// The first and last bin (above DC) of the runs of at least [`COHERENT_RUN`] bins where some
/// output's coherence is [`MEASURED_COHERENCE`] or more.
fn coherent_runs(coherence: &[Vec<f64>], bins: usize) -> Option<(usize, usize)> {
    let bins = coherence.iter().map(Vec::len).fold(bins, usize::min);
    let coherent = |k: usize| coherence.iter().any(|c| c[k] >= MEASURED_COHERENCE);
    let (mut first, mut last, mut run) = (None, None, 0);
    for k in 1..bins {
        run = if coherent(k) { run + 1 } else { 0 };
        if run >= COHERENT_RUN {
            first.get_or_insert(k + 1 - COHERENT_RUN);
            last = Some(k);
        }
    }
    first.zip(last)
}

/// The band LSCF fits by default: from the lowest to the highest bin (below `top` Hz) where
/// the force has power ([`EXCITED_FRACTION`] of its typical level, or the FRF is measured all
/// the same: [`measured_band`]) and some output's
/// coherence with it is at least [`BAND_COHERENCE`]. Outside it the FRF is noise divided by
/// next to nothing, which a rational fit turns into poles. Falls back to the first bin to
/// `top` when no bin qualifies (the fit then says so by its diagram).
pub fn fit_band(frf: &Frf, force_psd: &[f64], top: f64) -> (f64, f64) {
    let fallback = (frf.frequencies[1], top);
    let Some(((low, high), _)) = measured_band(&frf.frequencies, force_psd, Some(&frf.coherence))
    else {
        return fallback;
    };
    let usable: Vec<usize> = (1..frf.frequencies.len())
        .filter(|k| {
            let f = frf.frequencies[*k];
            f >= low && f <= high.min(top)
        })
        .collect();
    let good = |k: &usize| frf.coherence.iter().any(|c| c[*k] >= BAND_COHERENCE);
    let first = usable.iter().copied().find(good);
    let last = usable.iter().rev().copied().find(good);
    match (first, last) {
        (Some(l), Some(h)) if h > l => (frf.frequencies[l], frf.frequencies[h]),
        _ => fallback,
    }
}
