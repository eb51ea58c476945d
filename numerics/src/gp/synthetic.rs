//! The seeded synthetic problem the GP benchmarks and the peer comparison fit: three outputs of
//! known functions on shared inputs, as the corrector's three floors are.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use super::{GpError, Inputs};

/// Standard deviation of the noise added to every output.
pub const BENCHMARK_NOISE_SD: f64 = 0.05;

/// `n` points uniform in [−2, 2]^dim (`dim ≥ 7`) and three outputs, each depending on a few
/// inputs only (the rest are irrelevant, for ARD to find), plus N(0, 0.05²) noise:
///
/// - `y₁ = sin x₀ + 0.5 x₁`
/// - `y₂ = 0.8 cos(1.3 x₂) + 0.3 x₃ x₄`
/// - `y₃ = tanh(x₅ + 0.5 x₆) + 0.2 x₀`
pub fn benchmark_problem(
    seed: u64,
    n: usize,
    dim: usize,
) -> Result<(Inputs, [Vec<f64>; 3]), GpError> {
    if dim < 7 {
        return Err(GpError::LengthMismatch {
            what: "benchmark inputs (at least 7)",
            expected: 7,
            found: dim,
        });
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let values: Vec<f64> = (0..n * dim).map(|_| rng.gen_range(-2.0..2.0)).collect();
    let inputs = Inputs::from_row_major(dim, values)?;
    let functions: [fn(&[f64]) -> f64; 3] = [
        |x| x[0].sin() + 0.5 * x[1],
        |x| 0.8 * (1.3 * x[2]).cos() + 0.3 * x[3] * x[4],
        |x| (x[5] + 0.5 * x[6]).tanh() + 0.2 * x[0],
    ];
    let outputs = functions.map(|f| {
        inputs
            .rows()
            .map(|x| {
                let e: f64 = StandardNormal.sample(&mut rng);
                f(x) + BENCHMARK_NOISE_SD * e
            })
            .collect()
    });
    Ok((inputs, outputs))
}
