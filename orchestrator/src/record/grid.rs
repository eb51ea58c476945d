//! The nominal sampling grid behind a record's written times.
//!
//! Loggers write times rounded: to 1 ms or 10 µs, or to 9 significant digits (`1074.17969`,
//! 10 µs an hour in). Taken as they are, the steps between them differ, and a twin stepping on
//! them steps unequally (the shear FMU then rebuilds its exact step map at nearly every step:
//! a one-hour 51.2 Hz record took 67 s instead of 0.57 s). The grid `t0 + k·dt` is recovered
//! instead: `t0` the first time, `dt` the interval of the coarsest round rate (to 1, 0.1, 0.01
//! or 0.001 Hz) on whose grid every written time sits within its own rounding, else the mean
//! step. Sampling that is really irregular (a sample off the mean grid by more than 1 % of a
//! step beyond its rounding) is refused at that sample.

/// A sampling problem at sample `sample` (from 0).
#[derive(Debug, Clone, PartialEq)]
pub struct GridError {
    pub sample: usize,
    pub message: String,
}

/// A sample further than this fraction of a step from the mean grid is irregular sampling.
pub const IRREGULAR_FRACTION: f64 = 0.01;

/// The rounding step of a written number: `1074.17969` → 1e-5, `0.001` → 1e-3, `5e-3` → 1e-3,
/// `12` → 1.
pub fn resolution(field: &str) -> f64 {
    let s = field.trim().trim_start_matches(['+', '-']);
    let (mantissa, exponent) = match s.find(['e', 'E']) {
        Some(i) => (&s[..i], s[i + 1..].parse::<i32>().unwrap_or(0)),
        None => (s, 0),
    };
    let decimals = mantissa.split_once('.').map_or(0, |(_, d)| d.len() as i32);
    10f64.powi(exponent - decimals)
}

/// `(t0, dt)` of the grid the increasing `time` was written from, each time written to within
/// ± `resolution[k] / 2` (one entry per sample).
pub fn nominal_grid(time: &[f64], resolution: &[f64]) -> Result<(f64, f64), GridError> {
    let n = time.len();
    for k in 1..n {
        if time[k] <= time[k - 1] {
            return Err(GridError {
                sample: k,
                message: format!(
                    "time {} does not increase (previous {})",
                    time[k],
                    time[k - 1]
                ),
            });
        }
    }
    let t0 = time[0];
    let mean = (time[n - 1] - t0) / (n - 1) as f64;
    // A written time is off its grid point by up to half its last digit (and the first time by
    // as much), but never by a quarter step: digits that coarse do not resolve the sampling
    // (`0,1,3` is irregular, not rounded).
    let rounding = |k: usize| (0.5 * (resolution[k] + resolution[0])).min(0.25 * mean);
    for (k, t) in time.iter().enumerate() {
        let grid = t0 + k as f64 * mean;
        if (t - grid).abs() > IRREGULAR_FRACTION * mean + rounding(k) {
            return Err(GridError {
                sample: k,
                message: format!(
                    "non-uniform sampling: time {t} is off the {mean} s grid (expected {grid}) \
                     by more than {} % of a step and its rounding; resample the record first",
                    100.0 * IRREGULAR_FRACTION
                ),
            });
        }
    }
    let fits = |dt: f64| {
        time.iter().enumerate().all(|(k, t)| {
            let bound = rounding(k) + 8.0 * f64::EPSILON * t.abs();
            (t - (t0 + k as f64 * dt)).abs() <= bound
        })
    };
    for step in [1.0, 0.1, 0.01, 0.001] {
        let rate = (1.0 / mean / step).round() * step;
        if rate > 0.0 && fits(1.0 / rate) {
            return Ok((t0, 1.0 / rate));
        }
    }
    Ok((t0, mean))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resolutions_of_written_numbers() {
        assert_eq!(resolution("1074.17969"), 1e-5);
        assert_eq!(resolution("0.001"), 1e-3);
        assert_eq!(resolution("12"), 1.0);
        assert_eq!(resolution("-2.5e-3"), 1e-4);
    }

    /// Times of a 51.2 Hz hour written as loggers do: to 9 significant digits, to 10 µs, to
    /// 1 ms. Each gives back exactly the grid of 1/51.2 s; taken as they are, the steps differ.
    #[test]
    fn rounded_times_give_back_the_exact_grid() {
        let n = 3600 * 512 / 10;
        let exact: Vec<f64> = (0..n).map(|k| k as f64 / 51.2).collect();
        let writers: [(&str, fn(f64) -> String); 3] = [
            ("9 significant digits", |t| crate::record::format_g9(t)),
            ("10 µs", |t| format!("{t:.5}")),
            ("1 ms", |t| format!("{t:.3}")),
        ];
        for (what, write) in writers {
            let text: Vec<String> = exact.iter().map(|&t| write(t)).collect();
            let time: Vec<f64> = text.iter().map(|s| s.parse().unwrap()).collect();
            let res: Vec<f64> = text.iter().map(|s| resolution(s)).collect();
            let steps: std::collections::BTreeSet<u64> =
                time.windows(2).map(|w| (w[1] - w[0]).to_bits()).collect();
            assert!(steps.len() > 1, "{what}: the written steps differ");
            assert_eq!(nominal_grid(&time, &res), Ok((0.0, 1.0 / 51.2)), "{what}");
        }
    }

    #[test]
    fn a_rate_off_the_round_ones_keeps_its_mean_step() {
        // 51.2003 Hz (a drifting clock) written to 1 µs for ten minutes: 51.2 Hz would put the
        // last sample 0.07 ms off, far beyond the 0.5 µs rounding.
        let rate = 51.2003;
        let text: Vec<String> = (0..30720)
            .map(|k| format!("{:.6}", k as f64 / rate))
            .collect();
        let time: Vec<f64> = text.iter().map(|s| s.parse().unwrap()).collect();
        let res: Vec<f64> = text.iter().map(|s| resolution(s)).collect();
        let (_, dt) = nominal_grid(&time, &res).expect("uniform");
        assert!((dt * rate - 1.0).abs() < 1e-9, "{dt}");
    }

    #[test]
    fn irregular_sampling_is_refused_at_its_sample() {
        let mut time: Vec<f64> = (0..100).map(|k| k as f64 * 0.01).collect();
        time[40] += 0.002;
        let e = nominal_grid(&time, &[1e-6; 100]).expect_err("irregular");
        assert_eq!(e.sample, 40);
        assert!(e.message.contains("non-uniform"), "{}", e.message);
    }
}
