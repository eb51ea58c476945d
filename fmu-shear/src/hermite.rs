//! The cubic Hermite interpolant of a contact's switch function over a piece of a step (its
//! values and slopes — the drift and its rate — at both ends are in the state): whether it
//! crosses zero inside, where first, and how close to zero it comes. The exact contact stepper
//! (`piecewise_any`) flags, locates and clears its pieces with them.

/// The earliest θ ∈ (0, 1] where the cubic Hermite interpolant (values `p0`, `p1`, slopes per
/// unit θ `m0`, `m1`) changes sign, if it does: bisection on the cubic, bracketed by the ends or
/// by its extremum on the other side.
pub fn hermite_root(p0: f64, p1: f64, m0: f64, m1: f64) -> Option<f64> {
    let b = 3.0 * (p1 - p0) - 2.0 * m0 - m1;
    let c = 2.0 * (p0 - p1) + m0 + m1;
    let p = |t: f64| p0 + t * (m0 + t * (b + t * c));
    let positive = p0 > 0.0;
    let other = |t: f64| (p(t) > 0.0) != positive;
    // The far end of the bracket: the smallest stationary point on the other side, else 1.
    let mut hi: Option<f64> = None;
    let (qa, qb, qc) = (3.0 * c, 2.0 * b, m0);
    let mut stationary = [f64::NAN; 2];
    if qa == 0.0 {
        if qb != 0.0 {
            stationary[0] = -qc / qb;
        }
    } else {
        let disc = qb * qb - 4.0 * qa * qc;
        if disc >= 0.0 {
            let q = -0.5 * (qb + qb.signum() * disc.sqrt());
            stationary[0] = q / qa;
            if q != 0.0 {
                stationary[1] = qc / q;
            }
        }
    }
    for t in stationary {
        if t > 0.0 && t < 1.0 && other(t) && hi.is_none_or(|h| t < h) {
            hi = Some(t);
        }
    }
    if hi.is_none() && other(1.0) {
        hi = Some(1.0);
    }
    let mut hi = hi?;
    let mut lo = 0.0f64;
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if other(mid) {
            hi = mid;
        } else {
            lo = mid;
        }
        // Finer than the Newton step needs (it starts 1e-4 of the piece before the estimate).
        if hi - lo < 1e-7 {
            break;
        }
    }
    Some(hi)
}

/// The smallest |p(θ)| of the cubic Hermite interpolant on θ ∈ [0, 1] (values `p0`, `p1`,
/// slopes per unit θ `m0`, `m1`), 0 when it crosses zero.
pub fn hermite_distance(p0: f64, p1: f64, m0: f64, m1: f64) -> f64 {
    if hermite_crosses(p0, p1, m0, m1) {
        return 0.0;
    }
    let b = 3.0 * (p1 - p0) - 2.0 * m0 - m1;
    let c = 2.0 * (p0 - p1) + m0 + m1;
    let p = |t: f64| p0 + t * (m0 + t * (b + t * c));
    let mut smallest = p0.abs().min(p1.abs());
    let (qa, qb, qc) = (3.0 * c, 2.0 * b, m0);
    let mut consider = |t: f64| {
        if t > 0.0 && t < 1.0 {
            smallest = smallest.min(p(t).abs());
        }
    };
    if qa == 0.0 {
        if qb != 0.0 {
            consider(-qc / qb);
        }
    } else {
        let disc = qb * qb - 4.0 * qa * qc;
        if disc >= 0.0 {
            let q = -0.5 * (qb + qb.signum() * disc.sqrt());
            consider(q / qa);
            if q != 0.0 {
                consider(qc / q);
            }
        }
    }
    smallest
}

/// Whether the cubic Hermite interpolant on θ ∈ [0, 1] with values `p0`, `p1` and slopes (per
/// unit θ) `m0`, `m1` takes the other sign than `p0` somewhere inside (ends of the same sign).
#[inline]
pub fn hermite_crosses(p0: f64, p1: f64, m0: f64, m1: f64) -> bool {
    let positive = p0 > 0.0;
    if (p1 > 0.0) != positive {
        return true;
    }
    // p = p0 h00 + p1 h01 + m0 h10 + m1 h11 with h00 + h01 = 1, h00, h01 ≥ 0 and |h10|, |h11|
    // ≤ 4/27: no crossing when the ends are further from zero than the slopes can bend it.
    if p0.abs().min(p1.abs()) > 0.15 * (m0.abs() + m1.abs()) {
        return false;
    }
    // p(θ) = p0 + m0 θ + B θ² + C θ³; p'(θ) = m0 + 2B θ + 3C θ².
    let b = 3.0 * (p1 - p0) - 2.0 * m0 - m1;
    let c = 2.0 * (p0 - p1) + m0 + m1;
    let p = |t: f64| p0 + t * (m0 + t * (b + t * c));
    let crosses = |t: f64| t > 0.0 && t < 1.0 && (p(t) > 0.0) != positive;
    let (qa, qb, qc) = (3.0 * c, 2.0 * b, m0);
    if qa == 0.0 {
        return qb != 0.0 && crosses(-qc / qb);
    }
    let disc = qb * qb - 4.0 * qa * qc;
    if disc < 0.0 {
        return false;
    }
    let root = disc.sqrt();
    // Roots without cancellation.
    let q = -0.5 * (qb + qb.signum() * root);
    let t1 = q / qa;
    let t2 = if q != 0.0 { qc / q } else { t1 };
    crosses(t1) || crosses(t2)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hermite_sees_a_graze_between_ends_of_one_sign() {
        // p(θ) = 1 − 8 θ (1 − θ) · 0.6: dips to −0.2 at θ = ½, ends at 1.
        let (p0, p1) = (1.0, 1.0);
        let (m0, m1) = (-4.8, 4.8);
        assert!(hermite_crosses(p0, p1, m0, m1));
        // The same shape shallower: dips to 0.4 only.
        assert!(!hermite_crosses(1.0, 1.0, -2.4, 2.4));
        // Ends of opposite signs always count.
        assert!(hermite_crosses(1.0, -1.0, 0.0, 0.0));
        assert!(!hermite_crosses(-1.0, -2.0, -1.0, -1.0));
    }
}
