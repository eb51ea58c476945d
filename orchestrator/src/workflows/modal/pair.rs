//! The twin's modes beside modes identified from a record: pairs by shape and frequency, each
//! pair's frequency shift (% and in units of the combined sd), its damping change and MAC, and
//! the whole MAC matrix.

use serde::Serialize;

use super::TwinModes;
use numerics::modal::indicators::{complex_shape, mac};
use numerics::modal::Complex;

/// A mode identified from a record, its shape at the floors the record measures.
#[derive(Debug, Clone)]
pub struct ObservedMode {
    pub frequency: f64,
    pub frequency_sd: Option<f64>,
    pub damping: f64,
    pub damping_sd: Option<f64>,
    pub shape: Vec<Complex>,
}

#[derive(Debug, Clone, Serialize)]
pub struct ModePair {
    /// The twin's mode number (1-based) and the observed mode's (1-based, as listed).
    pub twin_mode: usize,
    pub observed_mode: usize,
    pub twin_frequency: f64,
    pub observed_frequency: f64,
    /// (observed − twin) / twin, %.
    pub frequency_shift_percent: f64,
    /// (observed − twin) / sqrt(twin sd² + observed sd²); None when neither has an sd.
    pub frequency_shift_sd: Option<f64>,
    /// observed − twin damping ratio.
    pub damping_change: f64,
    pub mac: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct ModeComparison {
    /// Floors (1-based) the shapes are compared at.
    pub floors: Vec<usize>,
    pub pairs: Vec<ModePair>,
    /// MAC of every twin mode (rows) against every observed mode (columns).
    pub mac_matrix: Vec<Vec<f64>>,
    /// Twin modes with no observed partner (1-based).
    pub unpaired_twin: Vec<usize>,
    pub unpaired_observed: Vec<usize>,
}

impl ModeComparison {
    /// The largest frequency drop beyond the uncertainty: the pair with the most negative
    /// shift in sd units.
    pub fn largest_drop(&self) -> Option<&ModePair> {
        self.pairs
            .iter()
            .filter(|p| p.frequency_shift_sd.is_some())
            .min_by(|a, b| {
                a.frequency_shift_sd
                    .unwrap_or(0.0)
                    .total_cmp(&b.frequency_shift_sd.unwrap_or(0.0))
            })
    }
}

/// How far apart (relative) two frequencies may be and still be the same mode.
const PAIRING_BAND: f64 = 0.3;

/// Pairs `observed` (shapes at `floors`, 1-based) with the twin's modes: greedily by a score
/// that is the MAC less the relative frequency distance, among candidates within ±30 % in
/// frequency. With one measured floor the MAC says nothing and the frequency decides.
pub fn pair_modes(twin: &TwinModes, observed: &[ObservedMode], floors: &[usize]) -> ModeComparison {
    let twin_shapes: Vec<Vec<Complex>> = twin
        .modes
        .iter()
        .map(|m| {
            complex_shape(
                &floors
                    .iter()
                    .map(|&f| m.shape.get(f.wrapping_sub(1)).copied().unwrap_or(0.0))
                    .collect::<Vec<_>>(),
            )
        })
        .collect();
    let mac_matrix: Vec<Vec<f64>> = twin_shapes
        .iter()
        .map(|a| observed.iter().map(|o| mac(a, &o.shape)).collect())
        .collect();
    let mut candidates = Vec::new();
    for (i, t) in twin.modes.iter().enumerate() {
        for (j, o) in observed.iter().enumerate() {
            let distance = (o.frequency - t.frequency).abs() / t.frequency;
            if distance <= PAIRING_BAND {
                let shape_term = if floors.len() > 1 {
                    mac_matrix[i][j]
                } else {
                    1.0
                };
                candidates.push((shape_term - distance, i, j));
            }
        }
    }
    candidates.sort_by(|a, b| b.0.total_cmp(&a.0));
    let (mut twin_used, mut obs_used) =
        (vec![false; twin.modes.len()], vec![false; observed.len()]);
    let mut pairs = Vec::new();
    for (_, i, j) in candidates {
        if twin_used[i] || obs_used[j] {
            continue;
        }
        twin_used[i] = true;
        obs_used[j] = true;
        let (t, o) = (&twin.modes[i], &observed[j]);
        let variance =
            t.frequency_sd.unwrap_or(0.0).powi(2) + o.frequency_sd.unwrap_or(0.0).powi(2);
        let shift = o.frequency - t.frequency;
        pairs.push(ModePair {
            twin_mode: i + 1,
            observed_mode: j + 1,
            twin_frequency: t.frequency,
            observed_frequency: o.frequency,
            frequency_shift_percent: 100.0 * shift / t.frequency,
            frequency_shift_sd: (variance > 0.0).then(|| shift / variance.sqrt()),
            damping_change: o.damping - t.damping,
            mac: mac_matrix[i][j],
        });
    }
    pairs.sort_by_key(|p| p.twin_mode);
    ModeComparison {
        floors: floors.to_vec(),
        pairs,
        mac_matrix,
        unpaired_twin: (1..=twin.modes.len())
            .filter(|&i| !twin_used[i - 1])
            .collect(),
        unpaired_observed: (1..=observed.len()).filter(|&j| !obs_used[j - 1]).collect(),
    }
}
