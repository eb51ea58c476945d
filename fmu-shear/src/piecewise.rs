//! Exact stepping of the shear model with gap contacts (and no other effect).
//!
//! A bumper's force is piecewise linear in the drift, so between the instants where a gap opens
//! or closes the model is linear, `ẋ = A_r x + b u + c_r` in its *region* r (each enabled
//! contact open, closed on its positive side or closed on its negative side), with the input a
//! ramp `u = u₀ + u̇ τ` inside the communication step. Augmented with `(u, u̇, 1)` the system is
//! `ż = M_r z`, and its flow over any time δ is the matrix exponential `exp(M_r δ)`, computed
//! with nalgebra's `Matrix::exp` (Padé with scaling and squaring) once per region, parameters
//! and step size.
//!
//! The step `[0, h]` is cut into dyadic pieces: the flows over `h / 2^l` for `l = 0..=DEPTH` are
//! cached per region, so any piece `[k·2^{-l} h, (k+1)·2^{-l} h]` is one 6×9 matrix–vector
//! product. A step advances by pieces of `h / 2^L` (the region's *check level*, chosen so that
//! `ω_max h / 2^L ≤ 1/4`), and a piece is accepted unless it changes the region at its end or the
//! cubic Hermite interpolant of a switch function (`d ∓ gap`, whose values and slopes — the
//! drift and its rate — are in the state at both ends) crosses zero inside it (a graze that
//! enters and leaves within the piece). A flagged piece is bisected, its halves tested in turn,
//! down to one tick of `h / 2^DEPTH`, the one that holds the crossing; that tick is taken with
//! the old region's map and the step goes on in the new region. The only error left is that
//! tick (≈ 1e-9 s at 51.2 Hz: a force error of the contact's slope times the drift rate over
//! 1e-9 s, for 1e-9 s) and a graze shallower than the cubic interpolation error (≤ 1e-5 of the
//! response at `ω δ ≤ 1/4`; the fixed 64 RK4 sub-steps miss grazes up to ~4e-5 of it).

use nalgebra::SMatrix;

use crate::effects::Contact;
use crate::integrate::State;
use crate::model::ShearModel;

/// Finest dyadic level: a tick is `h / 2^DEPTH`.
pub const DEPTH: u32 = 24;
/// A piece between checks covers at most this much of the fastest mode's phase (radians).
const CHECK_PHASE: f64 = 0.25;
/// Regions: 3 contact locations × {open, closed +, closed −}.
const REGIONS: usize = 27;

type Augmented = SMatrix<f64, 9, 9>;
/// The first six rows of `exp(M_r δ)`: the new state from `(x, u, u̇, 1)`.
type Flow = [[f64; 9]; 6];

#[derive(Clone, Debug)]
struct Region {
    /// `M_r`, what the flows were built from.
    matrix: Augmented,
    /// `levels[l]`: the flow over `h / 2^l`.
    levels: Vec<Flow>,
    /// Pieces between checks are `h / 2^check_level`.
    check_level: u32,
    /// `(ρ h)⁴ / 384` with ρ the region's rate bound: the cubic Hermite interpolant's error over
    /// the whole step, per unit of drift amplitude.
    whole_step_error: f64,
}

/// What the cached flows were built for.
#[derive(Clone, Debug, PartialEq)]
struct Key {
    step: f64,
    mass: [f64; 3],
    damping: [f64; 3],
    stiffness: [f64; 3],
    contacts: [Option<Contact>; 3],
}

/// The cached flows of the regions visited so far, for one set of parameters and step size.
#[derive(Clone, Debug)]
pub struct ContactMaps {
    key: Key,
    regions: Vec<Option<Box<Region>>>,
}

/// Why the exact path cannot step.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ExactError {
    #[error("the region's system matrix is not finite (parameters {0})")]
    NotFinite(String),
    #[error("{0} contacts enabled: the exact path steps at most {max}", max = crate::piecewise_any::MAX_EXACT_CONTACTS)]
    TooManyContacts(usize),
}

fn key(model: &ShearModel, step: f64) -> Key {
    let lib = &model.effects.contact;
    Key {
        step,
        // The exact contact path runs in the paper's layout only (three storeys).
        mass: std::array::from_fn(|i| model.params.mass[i]),
        damping: std::array::from_fn(|i| model.params.damping[i]),
        stiffness: std::array::from_fn(|i| model.params.stiffness[i]),
        contacts: std::array::from_fn(|s| lib.is_enabled(s).then(|| lib.effect(s).clone())),
    }
}

/// The drift of storey `s` and its rate.
#[inline]
fn drift(x: &State, s: usize) -> (f64, f64) {
    if s == 0 {
        (x[0], x[3])
    } else {
        (x[s] - x[s - 1], x[3 + s] - x[2 + s])
    }
}

impl ContactMaps {
    /// Whether the exact path applies: contacts are the only effects enabled.
    pub fn applies(model: &ShearModel) -> bool {
        let e = &model.effects;
        e.contact.any_enabled()
            && !e.cubic.any_enabled()
            && !e.friction.any_enabled()
            && !e.discovered.any_enabled()
    }

    pub fn new(model: &ShearModel, step: f64) -> Self {
        ContactMaps {
            key: key(model, step),
            regions: vec![None; REGIONS],
        }
    }

    pub fn fits(&self, model: &ShearModel, step: f64) -> bool {
        self.key == key(model, step)
    }

    /// The regions whose flows are cached.
    pub fn regions_cached(&self) -> usize {
        self.regions.iter().flatten().count()
    }

    /// The maps for this model and step, keeping every cached region whose system matrix is
    /// unchanged (with the same step its flows are the same to the bit): a fit of a contact's
    /// gap and stiffness keeps the open region's flows from run to run.
    pub fn adapt(&mut self, model: &ShearModel, step: f64) {
        let same_step = self.key.step == step;
        let old = std::mem::replace(self, ContactMaps::new(model, step));
        if !same_step {
            return;
        }
        for (code, region) in old.regions.into_iter().enumerate() {
            if let Some(region) = region.filter(|r| r.matrix == self.augmented(code)) {
                self.regions[code] = Some(region);
            }
        }
    }

    /// The region of a state: per location 0 open, 1 closed on the positive side, 2 on the
    /// negative side (the same strict inequalities as [`Contact::force_at`]), in base 3.
    #[inline]
    fn region_of(&self, x: &State) -> usize {
        let mut region = 0;
        let mut weight = 1;
        for (s, contact) in self.key.contacts.iter().enumerate() {
            if let Some(c) = contact {
                let (d, _) = drift(x, s);
                let closes_positive = c.side != crate::effects::contact::SIDE_NEGATIVE;
                let closes_negative = c.side != crate::effects::contact::SIDE_POSITIVE;
                if closes_positive && d > c.gap {
                    region += weight;
                } else if closes_negative && d < -c.gap {
                    region += 2 * weight;
                }
            }
            weight *= 3;
        }
        region
    }

    /// `M_r` of the augmented system `z = (y, ẏ, u, u̇, 1)`.
    fn augmented(&self, region: usize) -> Augmented {
        let Key {
            mass: m,
            damping: c,
            stiffness: k,
            ..
        } = &self.key;
        // Storey i: force k_i d_i + c_i ḋ_i + f0_i, with the closed bumper's stiffness added and
        // its offset in f0.
        let mut kt = *k;
        let mut f0 = [0.0; 3];
        let mut code = region;
        for s in 0..3 {
            let state = code % 3;
            code /= 3;
            if let (Some(contact), 1 | 2) = (&self.key.contacts[s], state) {
                kt[s] += contact.stiffness;
                let sign = if state == 1 { 1.0 } else { -1.0 };
                f0[s] = -contact.stiffness * sign * contact.gap;
            }
        }
        let mut a = Augmented::zeros();
        for i in 0..3 {
            a[(i, 3 + i)] = 1.0;
        }
        // d_s = y_s − y_{s−1}; storey s pushes floor s by −force and floor s−1 by +force.
        for s in 0..3usize {
            for (floor, sign) in [(s, -1.0), (s.wrapping_sub(1), 1.0)] {
                if floor >= 3 {
                    continue;
                }
                let row = 3 + floor;
                let scale = sign / m[floor];
                a[(row, s)] += scale * kt[s];
                a[(row, 3 + s)] += scale * c[s];
                if s > 0 {
                    a[(row, s - 1)] -= scale * kt[s];
                    a[(row, 3 + s - 1)] -= scale * c[s];
                }
                a[(row, 8)] += scale * f0[s];
            }
        }
        a[(3, 6)] = 1.0 / m[0];
        a[(6, 7)] = 1.0;
        a
    }

    /// An upper bound of the region's fastest rate |λ|: Gershgorin bounds of M⁻¹C and M⁻¹K
    /// (similar to symmetric matrices, so their eigenvalues are real and non-negative), then
    /// |λ| ≤ ρ(M⁻¹C) + √ρ(M⁻¹K) for `λ² M + λ C + K` singular.
    fn rate_bound(a: &Augmented) -> f64 {
        let row_sum = |offset: usize, row: usize| -> f64 {
            (0..3).map(|j| a[(3 + row, offset + j)].abs()).sum::<f64>()
        };
        let (mut kk, mut cc) = (0.0f64, 0.0f64);
        for row in 0..3 {
            kk = kk.max(row_sum(0, row));
            cc = cc.max(row_sum(3, row));
        }
        cc + kk.sqrt()
    }

    fn build(&self, region: usize) -> Result<Region, ExactError> {
        let a = self.augmented(region);
        if !a.iter().all(|v| v.is_finite()) || !self.key.step.is_finite() {
            return Err(ExactError::NotFinite(format!("{:?}", self.key)));
        }
        let mut levels = Vec::with_capacity(DEPTH as usize + 1);
        for l in 0..=DEPTH {
            let delta = self.key.step / f64::from(1u32 << l);
            let e = (a * delta).exp();
            if !e.iter().all(|v| v.is_finite()) {
                return Err(ExactError::NotFinite(format!("{:?}", self.key)));
            }
            levels.push(std::array::from_fn(|i| std::array::from_fn(|j| e[(i, j)])));
        }
        let phase = Self::rate_bound(&a) * self.key.step / CHECK_PHASE;
        let check_level = if phase > 1.0 {
            (phase.log2().ceil() as u32).min(DEPTH - 4)
        } else {
            0
        };
        let rate_step = Self::rate_bound(&a) * self.key.step;
        Ok(Region {
            matrix: a,
            levels,
            check_level,
            whole_step_error: rate_step.powi(4) / 384.0,
        })
    }

    fn region(&mut self, region: usize) -> Result<&Region, ExactError> {
        if self.regions[region].is_none() {
            self.regions[region] = Some(Box::new(self.build(region)?));
        }
        match &self.regions[region] {
            Some(r) => Ok(r),
            None => unreachable!("built above"),
        }
    }

    /// Whether the piece from `a` to `b` (of `dt` seconds, in `region`) may hold a crossing: the
    /// region changed at its end, or a switch's cubic Hermite interpolant crosses zero inside.
    #[inline]
    fn flagged(&self, region: usize, a: &State, b: &State, dt: f64) -> bool {
        if self.region_of(b) != region {
            return true;
        }
        for (s, contact) in self.key.contacts.iter().enumerate() {
            let Some(c) = contact else { continue };
            let (da, va) = drift(a, s);
            let (db, vb) = drift(b, s);
            let offsets = [
                (c.side != crate::effects::contact::SIDE_NEGATIVE).then_some(c.gap),
                (c.side != crate::effects::contact::SIDE_POSITIVE).then_some(-c.gap),
            ];
            for offset in offsets.into_iter().flatten() {
                if hermite_crosses(da - offset, db - offset, dt * va, dt * vb) {
                    return true;
                }
            }
        }
        false
    }

    /// Whether the whole step from `a` to `b` (in `region`) stays clear of every switch: no
    /// crossing, and each switch's cubic Hermite interpolant at least twice its interpolation
    /// error bound `(ρ h)⁴/384 · D` from zero, with `D = √(2E/k_s)` the largest drift of storey s
    /// the energy E (kinetic, storey springs, closed bumpers; the larger of the two ends) allows.
    fn clear(&mut self, region: usize, a: &State, b: &State) -> Result<bool, ExactError> {
        if self.region_of(b) != region {
            return Ok(false);
        }
        let error = self.region(region)?.whole_step_error;
        let (m, k, h) = (self.key.mass, self.key.stiffness, self.key.step);
        let energy = |x: &State| -> f64 {
            let mut e = 0.0;
            for s in 0..3 {
                let (d, _) = drift(x, s);
                e += 0.5 * m[s] * x[3 + s] * x[3 + s] + 0.5 * k[s] * d * d;
                if let Some(c) = &self.key.contacts[s] {
                    let f = c.force_at(d);
                    if c.stiffness > 0.0 {
                        e += 0.5 * f * f / c.stiffness;
                    }
                }
            }
            e
        };
        let e = energy(a).max(energy(b));
        for (s, contact) in self.key.contacts.iter().enumerate() {
            let Some(c) = contact else { continue };
            let amplitude = (2.0 * e / k[s]).sqrt();
            let margin = 2.0 * error * amplitude;
            if !margin.is_finite() {
                return Ok(false);
            }
            let (da, va) = drift(a, s);
            let (db, vb) = drift(b, s);
            let offsets = [
                (c.side != crate::effects::contact::SIDE_NEGATIVE).then_some(c.gap),
                (c.side != crate::effects::contact::SIDE_POSITIVE).then_some(-c.gap),
            ];
            for offset in offsets.into_iter().flatten() {
                if hermite_distance(da - offset, db - offset, h * va, h * vb) <= margin {
                    return Ok(false);
                }
            }
        }
        Ok(true)
    }

    /// One communication step from `x0` with the net input `u0 + slope·τ`.
    pub fn advance(&mut self, x0: &State, u0: f64, slope: f64) -> Result<State, ExactError> {
        let total: u64 = 1 << DEPTH;
        let tick = self.key.step / total as f64;
        let mut x = *x0;
        let mut pos: u64 = 0;
        let mut region = self.region_of(&x);
        // The whole step at once when every switch stays clear of zero by more than its cubic
        // interpolant's error bound (twice it), from the drift amplitude the energy allows.
        let whole = self.apply(region, &x, total, u0, slope)?;
        if self.clear(region, &x, &whole)? {
            return Ok(whole);
        }
        while pos < total {
            let check = self.region(region)?.check_level;
            // The largest power of two of ticks left, no longer than the check size (a flow is
            // the same wherever the piece starts: the input's value is in the state).
            let left = total - pos;
            let mut size = (total >> check).min(1 << (63 - left.leading_zeros()));
            let mut end = self.apply(region, &x, size, u0 + slope * (pos as f64 * tick), slope)?;
            if !self.flagged(region, &x, &end, size as f64 * tick) {
                x = end;
                pos += size;
                continue;
            }
            if let Some((ticks, past)) =
                self.newton_event(region, &x, &end, pos, size, tick, u0, slope)?
            {
                x = past;
                pos += ticks;
                region = self.region_of(&x);
                continue;
            }
            // Bisect: the flagged piece is [pos, pos + size] from x to end.
            loop {
                if size == 1 {
                    x = end;
                    pos += 1;
                    region = self.region_of(&x);
                    break;
                }
                let half = size / 2;
                let mid = self.apply(region, &x, half, u0 + slope * (pos as f64 * tick), slope)?;
                size = half;
                if self.flagged(region, &x, &mid, half as f64 * tick) {
                    end = mid;
                } else {
                    x = mid;
                    pos += half;
                    if !self.flagged(region, &x, &end, half as f64 * tick) {
                        x = end;
                        pos += half;
                        break;
                    }
                }
            }
        }
        Ok(x)
    }

    /// The state `n` ticks after `x` (at tick `pos`), as the flows of the binary digits of `n`.
    #[allow(clippy::too_many_arguments)]
    fn after_ticks(
        &mut self,
        region: usize,
        x: &State,
        pos: u64,
        n: u64,
        tick: f64,
        u0: f64,
        slope: f64,
    ) -> Result<State, ExactError> {
        let mut x = *x;
        let mut at = pos;
        let mut rest = n;
        while rest > 0 {
            let digit = 1u64 << (63 - rest.leading_zeros());
            x = self.apply(region, &x, digit, u0 + slope * (at as f64 * tick), slope)?;
            at += digit;
            rest -= digit;
        }
        Ok(x)
    }

    /// The first crossing inside a flagged piece `[pos, pos + size]` (from `a` to `b`), found
    /// from the switches' cubic Hermite interpolants and one Newton step on the exact flow:
    /// `(ticks, state)` of the first tick past it, checked (the region unchanged one tick
    /// before, changed at it), or `None` when the estimate does not check out (the caller
    /// bisects).
    #[allow(clippy::too_many_arguments)]
    fn newton_event(
        &mut self,
        region: usize,
        a: &State,
        b: &State,
        pos: u64,
        size: u64,
        tick: f64,
        u0: f64,
        slope: f64,
    ) -> Result<Option<(u64, State)>, ExactError> {
        let dt = size as f64 * tick;
        // The earliest root of the interpolants: (θ, storey, offset).
        let mut first: Option<(f64, usize, f64)> = None;
        for (s, contact) in self.key.contacts.iter().enumerate() {
            let Some(c) = contact else { continue };
            let (da, va) = drift(a, s);
            let (db, vb) = drift(b, s);
            let offsets = [
                (c.side != crate::effects::contact::SIDE_NEGATIVE).then_some(c.gap),
                (c.side != crate::effects::contact::SIDE_POSITIVE).then_some(-c.gap),
            ];
            for offset in offsets.into_iter().flatten() {
                if let Some(theta) = hermite_root(da - offset, db - offset, dt * va, dt * vb) {
                    if first.is_none_or(|(t, _, _)| theta < t) {
                        first = Some((theta, s, offset));
                    }
                }
            }
        }
        let Some((theta, storey, offset)) = first else {
            return Ok(None);
        };
        // Start the Newton step a little before the estimate (the interpolant's error is about
        // 1e-5 of the piece at the check size), so that it starts on this side.
        let back = 2.0 + 1e-4 * size as f64;
        let k1 = ((theta * size as f64 - back).max(0.0).floor() as u64).min(size - 1);
        let x1 = self.after_ticks(region, a, pos, k1, tick, u0, slope)?;
        if self.region_of(&x1) != region {
            return Ok(None);
        }
        let (d, v) = drift(&x1, storey);
        let sigma = d - offset;
        if v == 0.0 || !(sigma / v).is_finite() {
            return Ok(None);
        }
        let ahead = -sigma / v / tick;
        if !(0.0..=(size - k1) as f64).contains(&ahead) {
            return Ok(None);
        }
        // The tick just before the crossing, then step a tick at a time (at most 4) until past.
        let k2 = k1 + (ahead.ceil() as u64).max(1) - 1;
        let mut before = self.after_ticks(region, &x1, pos + k1, k2 - k1, tick, u0, slope)?;
        if self.region_of(&before) != region {
            return Ok(None);
        }
        let mut at = k2;
        for _ in 0..4 {
            if at >= size {
                return Ok(None);
            }
            let past = self.apply(
                region,
                &before,
                1,
                u0 + slope * ((pos + at) as f64 * tick),
                slope,
            )?;
            at += 1;
            if self.region_of(&past) != region {
                return Ok(Some((at, past)));
            }
            before = past;
        }
        Ok(None)
    }

    /// The region's flow over `size` ticks (a power of two) from `x` with the input at `u`.
    #[inline]
    fn apply(
        &mut self,
        region: usize,
        x: &State,
        size: u64,
        u: f64,
        slope: f64,
    ) -> Result<State, ExactError> {
        let level = DEPTH - size.trailing_zeros();
        let flow = &self.region(region)?.levels[level as usize];
        Ok(std::array::from_fn(|i| {
            let r = &flow[i];
            r[0] * x[0]
                + r[1] * x[1]
                + r[2] * x[2]
                + r[3] * x[3]
                + r[4] * x[4]
                + r[5] * x[5]
                + r[6] * u
                + r[7] * slope
                + r[8]
        }))
    }
}

/// The earliest θ ∈ (0, 1] where the cubic Hermite interpolant (values `p0`, `p1`, slopes per
/// unit θ `m0`, `m1`) changes sign, if it does: bisection on the cubic, bracketed by the ends or
/// by its extremum on the other side.
pub(crate) fn hermite_root(p0: f64, p1: f64, m0: f64, m1: f64) -> Option<f64> {
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
pub(crate) fn hermite_distance(p0: f64, p1: f64, m0: f64, m1: f64) -> f64 {
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
pub(crate) fn hermite_crosses(p0: f64, p1: f64, m0: f64, m1: f64) -> bool {
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
