//! Frequency responses: estimated from records (the Welch-averaged H1 estimate, on rustfft), the
//! exact one of a linear shear building with its parameter sensitivities, and resonance peaks.

use std::f64::consts::PI;

use rustfft::num_complex::Complex;
use rustfft::FftPlanner;

/// Samples per Welch segment of the frequency views (`twin compare --frf`, `twin control`): at
/// 51.2 Hz, 5 s and 0.2 Hz resolution.
pub const FRF_SEGMENT: usize = 256;

/// A frequency-response estimate, DC left out (every segment has its mean removed).
#[derive(Debug, Clone, PartialEq)]
pub struct FrequencyResponse {
    /// Hz, from one bin (1 / (segment · dt)) up to Nyquist.
    pub frequency: Vec<f64>,
    /// 20 log10 |H|; not finite where the input has no power.
    pub magnitude_db: Vec<f64>,
    /// Segments averaged.
    pub segments: usize,
}

/// The frequency view of a comparison (`twin compare --frf`): per channel, the H1 estimates
/// ([`welch_h1`], segments of [`FRF_SEGMENT`]) from the excitation to the measured and to the
/// predicted value, over the samples after the transient.
#[derive(Debug, Clone, PartialEq)]
pub struct ComparisonResponses {
    /// Per channel of the comparison: `[measured, predicted]`.
    pub channels: Vec<[FrequencyResponse; 2]>,
    /// Samples per segment (fewer when the record after the transient is shorter).
    pub segment_len: usize,
    /// The sampling interval (s), from the comparison's time axis.
    pub dt: f64,
}

/// The frequency view of comparison `c` under `excitation` (force or ground acceleration, one
/// sample per time sample); an error in words when the lengths differ or fewer than 4 samples
/// follow the transient.
pub fn comparison_responses(
    c: &crate::evaluation::compare::Comparison,
    excitation: &crate::record::Signal,
) -> Result<ComparisonResponses, String> {
    let n = c.time.len();
    let force = &excitation.values;
    if force.len() != n {
        return Err(format!(
            "{} {} samples for {n} time samples",
            force.len(),
            excitation.channel.name()
        ));
    }
    let first = c.first.min(n);
    let dt = if n >= 2 {
        (c.time[n - 1] - c.time[0]) / (n - 1) as f64
    } else {
        f64::NAN
    };
    let estimate = |response: &[f64]| {
        let response = response.get(first..).unwrap_or(&[]);
        welch_h1(&force[first..], response, dt, FRF_SEGMENT).ok_or_else(|| {
            format!(
                "the frequency view needs at least 4 samples after the transient and a positive sampling interval; \
                 there are {} samples, every {dt} s",
                n - first
            )
        })
    };
    let channels = (0..c.channels.len())
        .map(|i| Ok([estimate(&c.measured[i])?, estimate(&c.predicted[i])?]))
        .collect::<Result<_, String>>()?;
    Ok(ComparisonResponses {
        channels,
        segment_len: FRF_SEGMENT.min(n - first),
        dt,
    })
}

/// H1 estimate `H = Σ conj(X)·Y / Σ |X|²` of the response `output` to `input` (sampled every
/// `dt` s), Welch-averaged over Hann-windowed segments of `segment_len` samples with 50 %
/// overlap, each with its mean removed; trailing samples that do not fill a segment are
/// unused. A record shorter than one segment is one segment. `None` if the two signals differ
/// in length, `dt` is not positive, or there are fewer than 4 samples.
pub fn welch_h1(
    input: &[f64],
    output: &[f64],
    dt: f64,
    segment_len: usize,
) -> Option<FrequencyResponse> {
    let n = input.len();
    let segment_len = segment_len.min(n);
    if output.len() != n || !(dt.is_finite() && dt > 0.0) || segment_len < 4 {
        return None;
    }
    // Periodic Hann window; its scale cancels in the ratio.
    let window: Vec<f64> = (0..segment_len)
        .map(|k| 0.5 - 0.5 * (2.0 * PI * k as f64 / segment_len as f64).cos())
        .collect();
    let fft = FftPlanner::<f64>::new().plan_fft_forward(segment_len);
    let windowed = |samples: &[f64]| -> Vec<Complex<f64>> {
        let mean = samples.iter().sum::<f64>() / samples.len() as f64;
        samples
            .iter()
            .zip(&window)
            .map(|(s, w)| Complex::new((s - mean) * w, 0.0))
            .collect()
    };
    let bins = segment_len / 2;
    let mut sxx = vec![0.0; bins + 1];
    let mut sxy = vec![Complex::new(0.0, 0.0); bins + 1];
    let mut segments = 0;
    let step = segment_len / 2;
    let mut start = 0;
    while start + segment_len <= n {
        let mut x = windowed(&input[start..start + segment_len]);
        let mut y = windowed(&output[start..start + segment_len]);
        fft.process(&mut x);
        fft.process(&mut y);
        for k in 1..=bins {
            sxx[k] += x[k].norm_sqr();
            sxy[k] += x[k].conj() * y[k];
        }
        segments += 1;
        start += step;
    }
    let df = 1.0 / (segment_len as f64 * dt);
    Some(FrequencyResponse {
        frequency: (1..=bins).map(|k| k as f64 * df).collect(),
        magnitude_db: (1..=bins)
            .map(|k| 20.0 * (sxy[k].norm() / sxx[k]).log10())
            .collect(),
        segments,
    })
}

/// The exact frequency response of a linear shear building (`M ÿ + C ẏ + K y = L u`, see
/// [`Structure::load_vector`]) at `frequency` (Hz) for one response channel, per unit of its
/// excitation: receptance `H = (K − ω²M + iωC)⁻¹ L` for `disp<i>` (relative to the ground under
/// ground motion, as the twin's FMU gives it), mobility `iω H` for `vel<i>`, accelerance `−ω² H`
/// for `acc<i>` (absolute under ground motion: `−ω² H + 1`, per m/s² of ground acceleration).
/// Only the linear structure: a twin's effects (contacts, cubic springs, …) are not in it.
///
/// With `parameters` (names `m<i>`, `c<i>`, `k<i>`), also `∂H/∂p` for each, from
/// `∂H = Z⁻¹ (∂L − ∂Z H)` at the same factorisation.
pub struct StructureFrf {
    /// Per channel, per frequency.
    pub values: Vec<Vec<Complex<f64>>>,
    /// Per channel, per parameter, per frequency (empty without parameters).
    pub sensitivities: Vec<Vec<Vec<Complex<f64>>>>,
}

#[derive(Debug, thiserror::Error)]
pub enum FrfError {
    #[error(
        "'{0}' is not a response channel (acc<i>, vel<i>, disp<i>) of this {1}-storey building"
    )]
    Channel(String, usize),
    #[error("'{0}' is not a parameter of the linear building (m<i>, c<i>, k<i>, i ≤ {1})")]
    Parameter(String, usize),
    #[error("the dynamic stiffness is singular at {0} Hz")]
    Singular(f64),
}

/// Where a parameter sits: family and 0-based floor / storey.
fn parameter_site(name: &str, storeys: usize) -> Option<(char, usize)> {
    let mut chars = name.chars();
    let family = chars.next().filter(|c| matches!(c, 'm' | 'c' | 'k'))?;
    let digits = chars.as_str();
    if digits.starts_with('0') {
        return None;
    }
    let i: usize = digits.parse().ok()?;
    (1..=storeys).contains(&i).then_some((family, i - 1))
}

/// The exact FRF of `structure` (see [`StructureFrf`]).
pub fn structure_frf(
    structure: &::structure::Structure,
    channels: &[::structure::channel::Channel],
    frequency: &[f64],
    parameters: &[String],
) -> Result<StructureFrf, FrfError> {
    use ::structure::channel::{Channel, Quantity};
    use ::structure::Excitation;
    use nalgebra::{DMatrix, DVector};
    let n = structure.storeys();
    let sites: Vec<(Quantity, usize)> = channels
        .iter()
        .map(|c| match *c {
            Channel::Response { quantity, floor } if (1..=n).contains(&floor) => {
                Ok((quantity, floor - 1))
            }
            _ => Err(FrfError::Channel(c.name(), n)),
        })
        .collect::<Result<_, _>>()?;
    let params: Vec<(char, usize)> = parameters
        .iter()
        .map(|p| parameter_site(p, n).ok_or_else(|| FrfError::Parameter(p.clone(), n)))
        .collect::<Result<_, _>>()?;
    let base = structure.excitation == Excitation::Base;
    let to_complex = |m: DMatrix<f64>| m.map(|x| Complex::new(x, 0.0));
    let (m, c, k) = (
        to_complex(structure.mass_matrix()),
        to_complex(structure.damping_matrix()),
        to_complex(structure.stiffness_matrix()),
    );
    let load: DVector<Complex<f64>> = structure.load_vector().map(|x| Complex::new(x, 0.0));
    let mut values = vec![Vec::with_capacity(frequency.len()); channels.len()];
    let mut sensitivities =
        vec![vec![Vec::with_capacity(frequency.len()); params.len()]; channels.len()];
    for &f in frequency {
        let w = 2.0 * PI * f;
        let iw = Complex::new(0.0, w);
        let z = &k + &c * iw - &m * Complex::new(w * w, 0.0);
        let lu = z.lu();
        let h = lu.solve(&load).ok_or(FrfError::Singular(f))?;
        // The channel's factor on H (and the ground's own acceleration added to an absolute one).
        let scale = |q: Quantity| match q {
            Quantity::Velocity => iw,
            Quantity::Acceleration => Complex::new(-w * w, 0.0),
            _ => Complex::new(1.0, 0.0),
        };
        for (ch, &(q, i)) in sites.iter().enumerate() {
            let offset = if base && q == Quantity::Acceleration {
                1.0
            } else {
                0.0
            };
            values[ch].push(scale(q) * h[i] + offset);
        }
        for (j, &(family, i)) in params.iter().enumerate() {
            // rhs = ∂L − ∂Z H, ∂Z of one storey or floor.
            let mut rhs = DVector::from_element(n, Complex::new(0.0, 0.0));
            match family {
                'm' => {
                    rhs[i] += Complex::new(w * w, 0.0) * h[i];
                    if base {
                        rhs[i] -= 1.0;
                    }
                }
                _ => {
                    let factor = if family == 'c' {
                        iw
                    } else {
                        Complex::new(1.0, 0.0)
                    };
                    // Storey i joins floor i − 1 (the ground for i = 0) and floor i.
                    let below = if i > 0 {
                        h[i - 1]
                    } else {
                        Complex::new(0.0, 0.0)
                    };
                    let drift = h[i] - below;
                    rhs[i] -= factor * drift;
                    if i > 0 {
                        rhs[i - 1] += factor * drift;
                    }
                }
            }
            let dh = lu.solve(&rhs).ok_or(FrfError::Singular(f))?;
            for (ch, &(q, i)) in sites.iter().enumerate() {
                sensitivities[ch][j].push(scale(q) * dh[i]);
            }
        }
    }
    Ok(StructureFrf {
        values,
        sensitivities,
    })
}

/// A structure's modes from its state space: natural frequency (Hz, `|λ|/2π`) and damping ratio
/// (`−Re λ/|λ|`) of each complex pair, ascending; overdamped (real) poles left out.
pub fn structure_modes(structure: &::structure::Structure) -> Vec<(f64, f64)> {
    let Ok(ss) = structure.state_space() else {
        return Vec::new();
    };
    let mut modes: Vec<(f64, f64)> =
        ss.a.complex_eigenvalues()
            .iter()
            .filter(|l| l.im > 0.0)
            .map(|l| (l.norm() / (2.0 * PI), -l.re / l.norm()))
            .collect();
    modes.sort_by(|a, b| a.0.total_cmp(&b.0));
    modes
}

/// Resonances of a measured magnitude (dB): local maxima standing at least `prominence_db`
/// above the lowest point between them and any higher peak on each side (or the band's edge),
/// each with its damping ratio from the half-power (−3 dB) bandwidth `(f₂ − f₁)/(2 f₀)`, the
/// crossings interpolated linearly in dB; None where a crossing lies outside the band.
pub fn peaks(
    frequency: &[f64],
    magnitude_db: &[f64],
    prominence_db: f64,
) -> Vec<(f64, Option<f64>)> {
    let n = magnitude_db.len().min(frequency.len());
    let mut out = Vec::new();
    for k in 1..n.saturating_sub(1) {
        let v = magnitude_db[k];
        if !(v > magnitude_db[k - 1] && v >= magnitude_db[k + 1]) {
            continue;
        }
        // The lowest point on each side before a higher one (or the edge).
        let side = |range: &mut dyn Iterator<Item = usize>| {
            let mut lowest = v;
            for j in range {
                if magnitude_db[j] > v {
                    break;
                }
                lowest = lowest.min(magnitude_db[j]);
            }
            v - lowest
        };
        let left = side(&mut (0..k).rev());
        let right = side(&mut (k + 1..n));
        if left.min(right) < prominence_db {
            continue;
        }
        let crossing = |range: &mut dyn Iterator<Item = usize>, step: isize| {
            for j in range {
                let prev = (j as isize - step) as usize;
                if magnitude_db[j] <= v - 3.0 {
                    let t =
                        (magnitude_db[prev] - (v - 3.0)) / (magnitude_db[prev] - magnitude_db[j]);
                    return Some(frequency[prev] + t * (frequency[j] - frequency[prev]));
                }
            }
            None
        };
        let f1 = crossing(&mut (0..k).rev(), -1);
        let f2 = crossing(&mut (k + 1..n), 1);
        let zeta = match (f1, f2) {
            (Some(a), Some(b)) => Some((b - a) / (2.0 * frequency[k])),
            _ => None,
        };
        out.push((frequency[k], zeta));
    }
    out
}

#[cfg(test)]
mod structure_tests {
    use super::*;
    use ::structure::channel::Channel;
    use ::structure::{Excitation, Structure};
    use nalgebra::DMatrix;

    fn buildings() -> Vec<Structure> {
        vec![
            Structure::uniform(3, 5.2, 1.5, 4021.0, Excitation::Force { floor: 1 }),
            Structure {
                mass: vec![5.2, 5.0, 4.8, 4.6, 4.4],
                damping: vec![1.0, 1.2, 0.8, 1.0, 1.1],
                stiffness: vec![5460.0, 4464.0, 4752.0, 3800.0, 3960.0],
                excitation: Excitation::Base,
            },
            Structure {
                mass: vec![5.2, 5.0, 4.8, 4.6, 4.4],
                damping: vec![1.0, 1.2, 0.8, 1.0, 1.1],
                stiffness: vec![5460.0, 4464.0, 4752.0, 3800.0, 3960.0],
                excitation: Excitation::Force { floor: 3 },
            },
        ]
    }

    /// Against the state space's own transfer function `C (iωI − A)⁻¹ B + D` (the twin's
    /// accelerometers), an independent route to the same numbers.
    #[test]
    fn accelerance_matches_the_state_space_transfer_function() {
        for s in buildings() {
            let n = s.storeys();
            let ss = s.state_space().expect("valid");
            let channels: Vec<Channel> = (1..=n)
                .map(|f| Channel::parse(&format!("acc{f}")).expect("acc"))
                .collect();
            let freqs = [0.5, 3.0, 7.1, 19.0, 40.0];
            let frf = structure_frf(&s, &channels, &freqs, &[]).expect("frf");
            for (k, f) in freqs.iter().enumerate() {
                let iw = Complex::new(0.0, 2.0 * PI * f);
                let a = ss.a.map(|x| Complex::new(x, 0.0));
                let shifted = DMatrix::identity(2 * n, 2 * n) * iw - a;
                let x = shifted
                    .lu()
                    .solve(&ss.b.map(|x| Complex::new(x, 0.0)))
                    .expect("regular");
                let y = ss.c.map(|x| Complex::new(x, 0.0)) * x;
                for i in 0..n {
                    let expected = y[i] + ss.d[i];
                    let got = frf.values[i][k];
                    assert!(
                        // Under ground motion the absolute acceleration is 1 − ω²H: a small
                        // difference of two near-unit numbers far above the resonances.
                        (got - expected).norm() <= 1e-9 * expected.norm() + 1e-14,
                        "{:?} floor {} at {f} Hz: {got} vs {expected}",
                        s.excitation,
                        i + 1
                    );
                }
            }
        }
    }

    /// `∂H/∂p` against central differences, every parameter, every quantity.
    #[test]
    fn sensitivities_match_central_differences() {
        for s in buildings() {
            let n = s.storeys();
            let names = s.parameter_names();
            let channels: Vec<Channel> = ["acc", "vel", "disp"]
                .iter()
                .flat_map(|q| (1..=n).map(move |f| Channel::parse(&format!("{q}{f}")).expect("c")))
                .collect();
            let freqs = [2.0, 6.5, 21.0];
            let frf = structure_frf(&s, &channels, &freqs, &names).expect("frf");
            for (j, name) in names.iter().enumerate() {
                let value = s.get(name).expect("parameter");
                let h = 1e-5 * value;
                let shifted = |d: f64| {
                    let mut t = s.clone();
                    t.set(name, value + d);
                    structure_frf(&t, &channels, &freqs, &[])
                        .expect("frf")
                        .values
                };
                let (plus, minus) = (shifted(h), shifted(-h));
                for c in 0..channels.len() {
                    for k in 0..freqs.len() {
                        let fd = (plus[c][k] - minus[c][k]) / (2.0 * h);
                        let got = frf.sensitivities[c][j][k];
                        assert!(
                            // Central differences hold ~5 digits here (near a resonance the
                            // dynamic stiffness is ill-conditioned): 1e-4 of the derivative.
                            // Rounding of the differenced values (near 1 for an absolute
                            // acceleration under ground motion) adds ~eps·(1 + |H|)/h.
                            (got - fd).norm()
                                <= 1e-4 * fd.norm() + 1e-14 * (1.0 + frf.values[c][k].norm()) / h,
                            "{name} on {} at {} Hz: {got} vs {fd}",
                            channels[c].name(),
                            freqs[k]
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn peaks_and_half_power_damping_of_a_single_mode() {
        // One mode at 10 Hz with ζ = 2 %, sampled finely: the half-power width gives ζ back.
        let (fn_, zeta) = (10.0, 0.02);
        let freqs: Vec<f64> = (1..4000).map(|k| k as f64 * 0.005).collect();
        let mag: Vec<f64> = freqs
            .iter()
            .map(|f| {
                let r = f / fn_;
                -10.0 * ((1.0 - r * r).powi(2) + (2.0 * zeta * r).powi(2)).log10()
            })
            .collect();
        let found = peaks(&freqs, &mag, 10.0);
        assert_eq!(found.len(), 1, "{found:?}");
        assert!((found[0].0 - fn_).abs() < 0.01, "{found:?}");
        let z = found[0].1.expect("both crossings");
        assert!((z - zeta).abs() < 0.05 * zeta, "{z}");
    }
}
