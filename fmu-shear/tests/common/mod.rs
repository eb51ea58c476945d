//! What the shear FMU's integration tests share.

/// A deterministic band-limited force at steps of `step` s, `steps + 1` samples: 100 sines from
/// 0.25 to 25 Hz with fixed phases, about 1 N RMS.
#[allow(dead_code)]
pub fn band_limited_force(steps: usize, step: f64) -> Vec<f64> {
    sines(steps, step, 100, 0.25)
}

/// `steps + 1` samples at steps of `step` s of `components` sines at multiples of `lowest_hz`,
/// their phases fixed (the golden ratio's multiples), about 1 N RMS.
#[allow(dead_code)]
pub fn sines(steps: usize, step: f64, components: usize, lowest_hz: f64) -> Vec<f64> {
    let amplitude = (2.0 / components as f64).sqrt();
    (0..=steps)
        .map(|n| {
            let t = n as f64 * step;
            (1..=components)
                .map(|j| {
                    let phase = std::f64::consts::TAU * (j as f64 * 0.618_033_988_749_895).fract();
                    amplitude * (std::f64::consts::TAU * lowest_hz * j as f64 * t + phase).sin()
                })
                .sum()
        })
        .collect()
}

/// One host step of `model` over `[n·step, (n+1)·step]` with the force ramping from `force[n]`
/// to `force[n + 1]` (value and slope, as a master with first-order interpolation sets them);
/// the floor accelerations after it.
#[allow(dead_code)]
pub fn step_ramped(
    model: &mut fmu_shear::ShearModel,
    force: &[f64],
    n: usize,
    step: f64,
) -> [f64; 3] {
    use fmi2::CoSimModel;
    use fmu_shear::variables::{ACC, FORCE};
    model.set_real(FORCE, force[n]).expect("force");
    model
        .set_real_input_derivative(FORCE, (force[n + 1] - force[n]) / step)
        .expect("slope");
    model.do_step(n as f64 * step, step).expect("step");
    std::array::from_fn(|f| model.get_real(ACC + f as u32).expect("acc"))
}
