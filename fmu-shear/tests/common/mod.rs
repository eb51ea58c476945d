//! What the shear FMU's integration tests share.

/// A deterministic band-limited force at steps of `step` s, `steps + 1` samples: 100 sines from
/// 0.25 to 25 Hz with fixed phases, about 1 N RMS.
pub fn band_limited_force(steps: usize, step: f64) -> Vec<f64> {
    const COMPONENTS: usize = 100;
    let amplitude = (2.0 / COMPONENTS as f64).sqrt();
    (0..=steps)
        .map(|n| {
            let t = n as f64 * step;
            (1..=COMPONENTS)
                .map(|j| {
                    let phase = std::f64::consts::TAU * (j as f64 * 0.618_033_988_749_895).fract();
                    amplitude * (std::f64::consts::TAU * 0.25 * j as f64 * t + phase).sin()
                })
                .sum()
        })
        .collect()
}
