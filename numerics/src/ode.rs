//! Fixed-step integrators for small first-order systems `ẋ = f(t, x)`, with or without
//! event splitting at the kinks of a piecewise-smooth `f`.

/// One classical 4th-order Runge–Kutta step of size `h` from `(t, x)`.
#[inline]
pub fn rk4_step<const N: usize>(
    f: impl Fn(f64, &[f64; N]) -> [f64; N],
    t: f64,
    x: &[f64; N],
    h: f64,
) -> [f64; N] {
    let axpy = |a: &[f64; N], s: f64, b: &[f64; N]| -> [f64; N] {
        std::array::from_fn(|i| a[i] + s * b[i])
    };
    let k1 = f(t, x);
    let k2 = f(t + 0.5 * h, &axpy(x, 0.5 * h, &k1));
    let k3 = f(t + 0.5 * h, &axpy(x, 0.5 * h, &k2));
    let k4 = f(t + h, &axpy(x, h, &k3));
    std::array::from_fn(|i| x[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]))
}

/// `n` RK4 sub-steps covering `[t, t + h]`.
pub fn rk4_substeps<const N: usize>(
    f: impl Fn(f64, &[f64; N]) -> [f64; N],
    t: f64,
    x: &[f64; N],
    h: f64,
    n: u32,
) -> [f64; N] {
    let n = n.max(1);
    let dt = h / f64::from(n);
    let mut state = *x;
    for i in 0..n {
        state = rk4_step(&f, t + f64::from(i) * dt, &state, dt);
    }
    state
}

/// At most this many splits inside one sub-step; past it the rest is taken as one RK4 step.
pub const MAX_SPLITS: usize = 16;

/// `n` RK4 sub-steps covering `[0, h]` (time measured from the step's start), each split just
/// past every sign change of a switch function.
///
/// `switches(x)` lists the values of the switch functions at the state `x`, always the same
/// functions in the same order; a sign change between the two ends of a sub-step marks a kink of
/// `f` inside it (a contact gap closing, a hysteresis law changing branch). An RK4 step across
/// a kink loses its order, so the sub-step is cut just past the earliest crossing, located by
/// regula falsi on the switch along the RK4 step ([`locate`]), and goes on from there: at most
/// [`MAX_SPLITS`] times, after which the rest of the sub-step is one RK4 step.
pub fn rk4_with_events<const N: usize, S: AsRef<[f64]>>(
    f: impl Fn(f64, &[f64; N]) -> [f64; N],
    switches: impl Fn(&[f64; N]) -> S,
    x: &[f64; N],
    h: f64,
    n: u32,
) -> [f64; N] {
    let n = n.max(1);
    let dt = h / f64::from(n);
    let mut state = *x;
    for i in 0..n {
        let mut tau = f64::from(i) * dt;
        let end = f64::from(i + 1) * dt;
        for _split in 0..=MAX_SPLITS {
            let remaining = end - tau;
            if remaining <= 1e-14 * dt {
                break;
            }
            let next = rk4_step(&f, tau, &state, remaining);
            let (s0, s1) = (switches(&state), switches(&next));
            let (s0, s1) = (s0.as_ref(), s1.as_ref());
            // The earliest crossing among the switches that change sign.
            let mut theta = 1.0f64;
            for (j, (&a, &b)) in s0.iter().zip(s1).enumerate() {
                if a != 0.0 && a.signum() != b.signum() {
                    let g =
                        |th: f64| switches(&rk4_step(&f, tau, &state, th * remaining)).as_ref()[j];
                    theta = theta.min(locate(g, a, b));
                }
            }
            if theta >= 1.0 {
                state = next;
                break;
            }
            // Step to just past the crossing, then go on from there.
            state = rk4_step(&f, tau, &state, theta * remaining);
            tau += theta * remaining;
        }
    }
    state
}

/// The smallest θ ∈ (0, 1] past the sign change of `g` (g(0) = a, g(1) = b, opposite signs):
/// Illinois-modified regula falsi, returning the end of the final bracket on the far side.
pub fn locate(g: impl Fn(f64) -> f64, a: f64, b: f64) -> f64 {
    let (mut lo, mut hi, mut g_lo, mut g_hi) = (0.0f64, 1.0f64, a, b);
    let mut side = 0i8;
    for _ in 0..60 {
        if hi - lo < 1e-12 {
            break;
        }
        let mid = (lo * g_hi - hi * g_lo) / (g_hi - g_lo);
        let mid = if mid > lo && mid < hi {
            mid
        } else {
            0.5 * (lo + hi)
        };
        let g_mid = g(mid);
        if g_mid == 0.0 {
            return mid;
        }
        if g_mid.signum() == g_lo.signum() {
            lo = mid;
            g_lo = g_mid;
            if side == -1 {
                g_hi *= 0.5;
            }
            side = -1;
        } else {
            hi = mid;
            g_hi = g_mid;
            if side == 1 {
                g_lo *= 0.5;
            }
            side = 1;
        }
    }
    hi
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Harmonic oscillator ẍ = −x: exact solution cos t. The global error of RK4 falls 16× when
    /// the step halves; measured orders sit at 4.0 ± 0.05, the margin allows 0.2.
    #[test]
    fn rk4_converges_at_fourth_order() {
        let f = |_t: f64, x: &[f64; 2]| [x[1], -x[0]];
        let error = |n: u32| {
            let x = rk4_substeps(f, 0.0, &[1.0, 0.0], 2.0, n);
            (x[0] - 2.0f64.cos()).abs()
        };
        for n in [10, 20, 40] {
            let order = (error(n) / error(2 * n)).log2();
            assert!((order - 4.0).abs() < 0.2, "order {order} at n = {n}");
        }
    }

    /// A bouncing contact: ẍ = −x − k·max(x − gap, 0), a kink at x = gap. Split at the kink the
    /// error falls steadily, at least 16× per halving of the step (measured 26–31×); unsplit it
    /// wanders (measured ratios from 0.14 to 350) and at 32 sub-steps is 130× larger.
    #[test]
    fn splitting_at_a_kink_keeps_the_order() {
        let (k, gap) = (400.0, 0.3);
        let f = move |_t: f64, x: &[f64; 2]| [x[1], -x[0] - k * (x[0] - gap).max(0.0)];
        let run = |n: u32, split: bool| {
            let switches = |x: &[f64; 2]| if split { vec![x[0] - gap] } else { Vec::new() };
            let mut x = [1.0, 0.0];
            for _ in 0..20 {
                x = rk4_with_events(f, switches, &x, 0.25, n);
            }
            x[0]
        };
        let reference = run(4096, true);
        let error = |n: u32, split: bool| (run(n, split) - reference).abs();
        for n in [8, 16, 32, 64, 128] {
            println!(
                "n {n}: split {:e}, unsplit {:e}",
                error(n, true),
                error(n, false)
            );
        }
        for n in [16, 32, 64] {
            let ratio = error(n, true) / error(2 * n, true);
            assert!(
                ratio > 16.0,
                "error ratio {ratio} from {n} to {} sub-steps",
                2 * n
            );
        }
        assert!(error(32, false) > 100.0 * error(32, true));
    }

    #[test]
    fn locate_finds_the_root_from_the_far_side() {
        let theta = locate(|t| t * t - 0.25, -0.25, 0.75);
        assert!(theta >= 0.5 && theta - 0.5 < 1e-11, "{theta}");
    }

    #[test]
    fn rk4_integrates_a_cubic_in_time_exactly() {
        // ẋ = 3t² is integrated exactly by Simpson's rule, which RK4 reduces to.
        let f = |t: f64, _x: &[f64; 1]| [3.0 * t * t];
        let x = rk4_step(f, 1.0, &[1.0], 0.5);
        assert!((x[0] - 1.5f64.powi(3)).abs() < 1e-14);
    }
}
