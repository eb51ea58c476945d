//! The responses read: each floor's FRF from the force, the attenuation at each resonance of the
//! passive structure, the floors' RMS accelerations.

use super::closed_loop::Response;
use super::options::RESONANCE_BAND;
use super::report::Attenuation;
use crate::evaluation::frf::{welch_h1, FrequencyResponse, FRF_SEGMENT};
use crate::evaluation::stats::rms;

/// Per floor, the Welch H1 estimate from `force` to the run's acceleration (None where the
/// record is too short for a segment).
pub fn floor_frfs(force: &[f64], response: &Response, dt: f64) -> Vec<Option<FrequencyResponse>> {
    let n = force.len();
    response
        .acc
        .iter()
        .map(|acc| welch_h1(force, &acc[..n.min(acc.len())], dt, FRF_SEGMENT))
        .collect()
}

/// Peak of the FRF (dB) in the band around each resonance (rows), per floor (columns).
pub(super) fn resonance_peaks(
    force: &[f64],
    response: &Response,
    dt: f64,
    resonances: &[f64],
) -> Vec<Vec<f64>> {
    let floors = response.acc.len();
    let mut out = vec![vec![f64::NAN; floors]; resonances.len()];
    for floor in 0..floors {
        let n = force.len().min(response.acc[floor].len());
        let Some(h) = welch_h1(&force[..n], &response.acc[floor][..n], dt, FRF_SEGMENT) else {
            continue;
        };
        for (mode, &fr) in resonances.iter().enumerate() {
            let peak = h
                .frequency
                .iter()
                .zip(&h.magnitude_db)
                .filter(|(f, m)| {
                    (**f - fr).abs() <= RESONANCE_BAND * fr.max(h.frequency[0]) && m.is_finite()
                })
                .map(|(_, m)| *m)
                .fold(f64::NEG_INFINITY, f64::max);
            out[mode][floor] = peak;
        }
    }
    out
}

pub(super) fn attenuation(
    passive: &[Vec<f64>],
    controlled: &[Vec<f64>],
    resonances: &[f64],
) -> (Vec<Attenuation>, f64) {
    let mut list = Vec::new();
    let mut sum = 0.0;
    let mut count = 0;
    for mode in 0..resonances.len() {
        let floors = passive[mode].len();
        let mut floors_db = vec![f64::NAN; floors];
        for floor in 0..floors {
            floors_db[floor] = passive[mode][floor] - controlled[mode][floor];
            if floors_db[floor].is_finite() {
                sum += floors_db[floor];
                count += 1;
            }
        }
        list.push(Attenuation {
            mode: mode + 1,
            frequency_hz: resonances[mode],
            floors_db,
        });
    }
    (
        list,
        if count > 0 {
            sum / count as f64
        } else {
            f64::NAN
        },
    )
}

pub(super) fn acc_rms(r: &Response) -> Vec<f64> {
    r.acc.iter().map(|a| rms(a)).collect()
}
