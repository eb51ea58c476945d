//! Exact stepping of gap contacts on any shear building: N storeys (1..=50), a force at floor K
//! or ground acceleration, the control force at its floor, any set of enabled contacts (storey
//! L joins floors L and L + 1, storey 0 the ground and floor 1; each closing on the positive,
//! the negative or both sides), the paper's rig among them.
//!
//! **The flow.** Between the instants where a gap opens or closes every bumper's force is
//! affine in its drift, so the model is linear in its *region* `r` (per enabled contact: open,
//! closed on the positive side, closed on the negative side). With both inputs ramps over the
//! communication step, `e(τ) = e₀ + ė τ` (the force at floor K or the ground acceleration) and
//! `c(τ) = c₀ + ċ τ` (the control force), the state augmented with `(e, ė, c, ċ, 1)` obeys an
//! autonomous linear system `ż = M_r z` (2N + 5 square, 2N + 3 with the control force folded
//! in, see **Speed**: the storeys' springs and dampers, each closed bumper's stiffness added to
//! its storey and its `∓k_c·gap` in the constant column,
//! `b_e = M⁻¹e_K` or `−1`, `b_c = −M⁻¹e_cf`, the ramps' `ė`, `ċ` integrating into `e`, `c`).
//! Its flow over δ is `exp(M_r δ)` (nalgebra's Padé approximant with scaling and squaring,
//! accurate to rounding for these norms; see [`exponential`] for the kernel). A region's flows over `h / 2^l`, `l = 0..=DEPTH`, are
//! built the first time the step needs that level (most steps use level 0 and the check level
//! alone) and cached per region in a table indexed by the region's base-3 code over the
//! enabled contacts; any piece `[k·2^{-l} h, (k+1)·2^{-l} h]` is then one 2N × (2N + 5) matrix–vector
//! product (the inputs' values at the piece's start are in the augmented state).
//!
//! **The kinks.** A step whose every switch (`d ∓ gap` of each enabled
//! side) stays clear of zero over the whole step — the cubic Hermite interpolant of the switch
//! from its values and slopes at both ends (the drift and its rate are in the state) at least
//! twice its interpolation error bound from zero — is one product. Otherwise the step advances
//! by pieces of `h / 2^L` (the region's check level, `ρ h / 2^L ≤ 1/4` with ρ a bound of the
//! region's fastest rate), a piece accepted unless the region at its end differs or a switch's
//! interpolant crosses zero inside it; a flagged piece's first crossing is located by the
//! interpolant's root and one Newton step on the exact flow (checked: the region unchanged a
//! tick before, changed at it) or, failing that, by bisection down to one tick `h / 2^DEPTH`.
//! That tick is taken with the old region's flow and the step goes on from the new region.
//!
//! **The error.** Inside a region each piece is the exact flow to rounding; the error comes
//! from the kinks alone, two sources whose bounds use neither N, the excitation nor the input
//! columns:
//! - *A located crossing* is past by at most one tick (`h / 2^24`, 1.2e-9 s at 51.2 Hz), over
//!   which the bumper's force is taken from the old region: a force error of `k_c |ḋ| · tick`
//!   at most, acting for one tick, per crossing.
//! - *A graze* (a switch that leaves zero and returns inside one piece, ends of one sign) is
//!   seen when the interpolant dips across zero. The drift is a combination of the region's
//!   modes plus the response to the ramps; the latter is affine in time when `M_r`'s
//!   state block is invertible, so the drift's fourth derivative is that of the modes, at most
//!   `ρ⁴` times its amplitude, and the cubic Hermite interpolant's error over a piece `δ` is at
//!   most `(ρ δ)⁴/384` of that amplitude (≤ 1e-5 of it at `ρ δ ≤ 1/4`). ρ bounds every rate for
//!   any N: `M⁻¹K_r` and `M⁻¹C` are similar to symmetric positive semi-definite matrices (a
//!   closed bumper adds a non-negative stiffness to its storey), so their eigenvalues are real,
//!   non-negative and under their Gershgorin row sums, and an eigenvalue λ of
//!   `λ² M + λ C + K_r` has `|λ| ≤ ρ(M⁻¹C) + √ρ(M⁻¹K_r)`. A graze shallower than that error is
//!   the only kind missed. The whole-step test uses the same bound over `h`,
//!   with the drift amplitude `√(2E/k_s)` that the energy `E` of the relative motion (kinetic,
//!   storey springs, closed bumpers; the larger of the step's ends) allows storey s.
//!
//! `tests/contact_storeys.rs` gives the measured errors for N = 1, 2, 5, 10 under both
//! excitations with contacts at low and high sites; `tests/rig_contacts_golden.rs` holds the
//! rig's runs to the states its former fixed-array stepper wrote.
//!
//! **When it does not apply.** Each region visited costs its flows (up to DEPTH + 1 exponentials
//! of a (2N + 5)-square matrix), worth it when a run keeps returning to a few regions. With more
//! than [`MAX_EXACT_CONTACTS`] contacts enabled the regions a run may visit (3^m) are too many
//! for a cache to pay, and the model steps them with the error-controlled path
//! (`integrate::dopri5_with_events`); the cache holds at most [`MAX_CACHED_REGIONS`] regions and
//! is emptied when it would grow past them (bounded memory: a level of a 50-storey region is
//! 100 × 105 numbers).
//!
//! **Speed.** A step allocates nothing: the state is a [`Buffer`] on the stack (a fixed array
//! when its length is known when compiling, as the rig's `[f64; 6]`, the flow's product then
//! unrolled; else a small vector inline up to its capacity), and a region's flows are one index
//! away. A control force on the floor the force excites is folded into one net input there
//! (`u = e − c`: three extra columns, not five). Up to four storeys the product is unrolled
//! for a small vector too. On the rig (`examples/contact_paths.rs`, instructions per step by
//! `scripts/bench-contact-paths.sh`): 4,529 on `[f64; 6]`, 6,077 on the small vector, against
//! 4,624 of the rig's former fixed-array stepper, whose states the rig's golden file holds to
//! the bit.

use nalgebra::{DMatrix, SMatrix};
use smallvec::SmallVec;
use structure::Excitation;

use crate::effects::contact::{SIDE_NEGATIVE, SIDE_POSITIVE};
use crate::effects::Contact;
use crate::hermite::{hermite_crosses, hermite_distance, hermite_root};
use crate::linear::{product_by_columns, same_step, StepInputs};
use crate::model::{ShearModel, ShearParameters};

/// Finest dyadic level: a tick is `h / 2^DEPTH`.
pub const DEPTH: u32 = 24;

/// Why the exact path cannot step.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ExactError {
    #[error("the region's system matrix is not finite (parameters {0})")]
    NotFinite(String),
    #[error("{0} contacts enabled: the exact path steps at most {MAX_EXACT_CONTACTS}")]
    TooManyContacts(usize),
}

/// The most contacts enabled at once that the exact path steps (3^8 possible regions); more go
/// to the error-controlled path.
pub const MAX_EXACT_CONTACTS: usize = 8;
/// The most regions cached at once; the cache is emptied when a new one would pass it.
pub const MAX_CACHED_REGIONS: usize = 64;
/// A piece between checks covers at most this much of the fastest mode's phase (radians).
const CHECK_PHASE: f64 = 0.25;
/// Columns of the augmented system after the 2N states: `e, ė, c, ċ, 1`, or `u, u̇, 1` when the
/// control force acts on the floor the force excites (`u = e − c`, the net force there).
const EXTRA: usize = 5;

/// A state `[y, ẏ]` inside a step, on the stack: a fixed array when the storey count is known
/// when compiling (the paper's rig, `[f64; 6]`), else inline up to [`INLINE_STOREYS`] storeys
/// (no allocation per piece or per step).
pub trait Buffer: Clone + AsRef<[f64]> + AsMut<[f64]> {
    /// `len` zeros.
    fn zeros(len: usize) -> Self;

    /// `flow · (x, extra)`: a flow's first 2N rows, column-major, times the augmented state.
    fn flowed(flow: &[f64], x: &Self, extra: &[f64]) -> Self {
        let n2 = x.as_ref().len();
        let mut out = Self::zeros(n2);
        product_by_columns(flow, x.as_ref(), extra, out.as_mut());
        out
    }
}

/// `flow · (x, extra)` for a state of `L` values and `E` extra columns: column by column, each
/// row's sum in column order.
#[inline(always)]
fn flowed_fixed<const L: usize, const E: usize>(
    flow: &[f64],
    x: &[f64; L],
    extra: &[f64; E],
) -> [f64; L] {
    let flow = &flow[..L * (L + E)];
    let mut out = [0.0; L];
    for (c, w) in x.iter().chain(extra).enumerate() {
        for (i, o) in out.iter_mut().enumerate() {
            *o += flow[c * L + i] * w;
        }
    }
    out
}

/// Storeys whose states [`Inline`] holds without allocating.
pub const INLINE_STOREYS: usize = 10;

/// A state of any length, inline up to [`INLINE_STOREYS`] storeys.
pub type Inline = SmallVec<[f64; 2 * INLINE_STOREYS]>;

impl<A: smallvec::Array<Item = f64> + Clone> Buffer for SmallVec<A> {
    fn zeros(len: usize) -> Self {
        SmallVec::from_elem(0.0, len)
    }

    /// Up to four storeys the fixed arrays' unrolled product (the same sums in the same order),
    /// else [`product_by_columns`].
    #[inline]
    fn flowed(flow: &[f64], x: &Self, extra: &[f64]) -> Self {
        macro_rules! fixed_rows {
            ($($len:literal)*) => {
                match x.len() {
                    $($len => {
                        if let Ok(x) = <&[f64; $len]>::try_from(x.as_slice()) {
                            return SmallVec::from_slice(&<[f64; $len]>::flowed(flow, x, extra));
                        }
                    })*
                    _ => {}
                }
            };
        }
        fixed_rows!(2 4 6 8);
        let mut out = Self::zeros(x.len());
        product_by_columns(flow, x.as_ref(), extra, out.as_mut());
        out
    }
}

impl<const L: usize> Buffer for [f64; L] {
    fn zeros(len: usize) -> Self {
        assert_eq!(len, L, "a state of {L} values");
        [0.0; L]
    }

    /// The same sums in the same order as [`product_by_columns`], the lengths known when
    /// compiling (the loops unrolled).
    #[inline(always)]
    fn flowed(flow: &[f64], x: &Self, extra: &[f64]) -> Self {
        match *extra {
            [u, slope, one] => flowed_fixed(flow, x, &[u, slope, one]),
            [e, de, c, dc, one] => flowed_fixed(flow, x, &[e, de, c, dc, one]),
            _ => unreachable!("3 or 5 extra columns"),
        }
    }
}

#[derive(Clone, Debug)]
struct Region {
    /// `M_r`, 2N + 5 square (2N + 3 folded).
    matrix: DMatrix<f64>,
    /// `levels[l]`: the first 2N rows of `exp(M_r h / 2^l)`, column-major, built when first
    /// used.
    levels: Vec<Option<Box<[f64]>>>,
    /// Pieces between checks are `h / 2^check_level`.
    check_level: u32,
    /// `(ρ h)⁴ / 384`: the cubic Hermite interpolant's error over the whole step, per unit of
    /// drift amplitude.
    whole_step_error: f64,
}

/// What the cached flows were built for.
#[derive(Clone, Debug)]
struct Key {
    step: f64,
    params: ShearParameters,
    /// The enabled contacts: (storey, law), storey 0 the ground's.
    contacts: Vec<(usize, Contact)>,
}

/// The cached flows of the regions visited so far, for one structure, set of contacts and step.
#[derive(Clone, Debug)]
pub struct AnyContactMaps {
    key: Key,
    /// Storeys.
    n: usize,
    /// The control force acts on the floor the force excites: one net input there (three
    /// extra columns, not five).
    folded: bool,
    /// Indexed by the region's code (3^m slots for m contacts, at most 3^8): a region's flows
    /// are one index away, as on a fixed table.
    regions: Vec<Option<Box<Region>>>,
    /// How many slots are filled.
    cached: usize,
}

/// The regions of `m` contacts (3^m; the exact path takes at most [`MAX_EXACT_CONTACTS`], so
/// at most 6,561 slots).
fn region_count(m: usize) -> usize {
    3usize.pow(m.min(MAX_EXACT_CONTACTS) as u32)
}

fn enabled_contacts(model: &ShearModel) -> impl Iterator<Item = (usize, &Contact)> + '_ {
    let lib = &model.effects.contact;
    lib.enabled_sites().map(move |s| (s, lib.effect(s)))
}

/// The drift of storey `s` and its rate, in the state `x = [y, ẏ]` (N floors, `x.len()` 2N:
/// a constant when the state is a fixed array).
#[inline(always)]
fn drift(x: &[f64], s: usize) -> (f64, f64) {
    let n = x.len() / 2;
    if s == 0 {
        (x[0], x[n])
    } else {
        (x[s] - x[s - 1], x[n + s] - x[n + s - 1])
    }
}

/// Whether `test` holds for one of a contact's switch offsets, in order: `+gap` when positive
/// drift closes it, `−gap` when negative drift does (two branches, no iterator: the step's
/// hot loop asks it of every piece).
#[inline(always)]
fn any_switch(c: &Contact, mut test: impl FnMut(f64) -> bool) -> bool {
    (c.side != SIDE_NEGATIVE && test(c.gap)) || (c.side != SIDE_POSITIVE && test(-c.gap))
}

impl AnyContactMaps {
    /// Whether the exact path steps this model: contacts are the only effects enabled, at most
    /// [`MAX_EXACT_CONTACTS`] of them.
    pub fn serves(model: &ShearModel) -> bool {
        Self::applies(model) && model.effects.contact.enabled_sites().count() <= MAX_EXACT_CONTACTS
    }

    /// Whether contacts are the only effects enabled (however many).
    pub fn applies(model: &ShearModel) -> bool {
        let e = &model.effects;
        e.contact.any_enabled()
            && !e.cubic.any_enabled()
            && !e.friction.any_enabled()
            && !e.discovered.any_enabled()
    }

    pub fn new(model: &ShearModel, step: f64) -> Self {
        AnyContactMaps {
            key: Key {
                step,
                params: model.params.clone(),
                contacts: enabled_contacts(model)
                    .map(|(s, c)| (s, c.clone()))
                    .collect(),
            },
            n: model.storeys(),
            folded: model.params.excitation
                == Excitation::Force {
                    floor: model.params.control_floor,
                },
            regions: vec![None; region_count(enabled_contacts(model).count())],
            cached: 0,
        }
    }

    /// Whether the flows were built for this model's structure and contacts and this step
    /// (equal to the last bits, as the linear step map: [`same_step`]).
    pub fn fits(&self, model: &ShearModel, step: f64) -> bool {
        let (p, q) = (&self.key.params, &model.params);
        same_step(self.key.step, step)
            && p.mass == q.mass
            && p.damping == q.damping
            && p.stiffness == q.stiffness
            && p.excitation == q.excitation
            && p.control_floor == q.control_floor
            && enabled_contacts(model).eq(self.key.contacts.iter().map(|(s, c)| (*s, c)))
    }

    /// The maps for this model and step, keeping every cached region whose system matrix is
    /// unchanged (with the same step its flows are the same to the bit): a fit of a contact's
    /// gap and stiffness keeps the open region's flows, the one most visited, from run to run.
    pub fn adapt(&mut self, model: &ShearModel, step: f64) {
        let same = self.n == model.storeys() && self.key.step == step;
        let old = std::mem::replace(self, AnyContactMaps::new(model, step));
        if !same {
            return;
        }
        for (code, region) in old.regions.into_iter().enumerate() {
            let Some(region) = region else { continue };
            if code < self.regions.len() && region.matrix == self.augmented(code as u64) {
                self.regions[code] = Some(region);
                self.cached += 1;
            }
        }
    }

    /// The regions whose flows are cached.
    pub fn regions_cached(&self) -> usize {
        self.cached
    }

    /// The region of a state: per enabled contact (in storey order) 0 open, 1 closed on the
    /// positive side, 2 on the negative side (the strict inequalities of
    /// [`Contact::force_at`]), in base 3.
    #[inline(always)]
    fn region_of(&self, x: &[f64]) -> u64 {
        let mut region = 0;
        let mut weight = 1;
        for (s, c) in &self.key.contacts {
            let (d, _) = drift(x, *s);
            if c.side != SIDE_NEGATIVE && d > c.gap {
                region += weight;
            } else if c.side != SIDE_POSITIVE && d < -c.gap {
                region += 2 * weight;
            }
            weight *= 3;
        }
        region
    }

    /// Columns after the 2N states: 5 (`e, ė, c, ċ, 1`), or 3 (`u, u̇, 1`) when folded.
    fn extra_columns(&self) -> usize {
        if self.folded {
            3
        } else {
            EXTRA
        }
    }

    /// Per storey, the stiffness with a closed bumper's added and the bumper's constant force
    /// `−(±k_c gap)`, in region `code`.
    fn closed_storeys(&self, code: u64) -> (Vec<f64>, Vec<f64>) {
        let mut stiffness = self.key.params.stiffness.clone();
        let mut constant = vec![0.0; self.n];
        let mut rest = code;
        for (s, c) in &self.key.contacts {
            let state = rest % 3;
            rest /= 3;
            if state != 0 {
                stiffness[*s] += c.stiffness;
                let sign = if state == 1 { 1.0 } else { -1.0 };
                constant[*s] = -c.stiffness * sign * c.gap;
            }
        }
        (stiffness, constant)
    }

    /// `M_r` of the augmented system `z = (y, ẏ, e, ė, c, ċ, 1)` (or `(y, ẏ, u, u̇, 1)`).
    fn augmented(&self, code: u64) -> DMatrix<f64> {
        let n = self.n;
        let p = &self.key.params;
        let (kt, f0) = self.closed_storeys(code);
        let size = 2 * n + self.extra_columns();
        let one = size - 1;
        let mut a = DMatrix::zeros(size, size);
        for i in 0..n {
            a[(i, n + i)] = 1.0;
        }
        // d_s = y_s − y_{s−1}; storey s pushes floor s by −force and floor s − 1 by +force.
        for s in 0..n {
            for (floor, sign) in [(s, -1.0), (s.wrapping_sub(1), 1.0)] {
                if floor >= n {
                    continue;
                }
                let row = n + floor;
                let scale = sign / p.mass[floor];
                a[(row, s)] += scale * kt[s];
                a[(row, n + s)] += scale * p.damping[s];
                if s > 0 {
                    a[(row, s - 1)] -= scale * kt[s];
                    a[(row, n + s - 1)] -= scale * p.damping[s];
                }
                a[(row, one)] += scale * f0[s];
            }
        }
        let e = 2 * n;
        match p.excitation {
            Excitation::Force { floor } => a[(n + floor - 1, e)] = 1.0 / p.mass[floor - 1],
            Excitation::Base => (0..n).for_each(|r| a[(n + r, e)] = -1.0),
        }
        a[(e, e + 1)] = 1.0;
        if !self.folded {
            let (c, floor) = (e + 2, p.control_floor);
            a[(n + floor - 1, c)] = -1.0 / p.mass[floor - 1];
            a[(c, c + 1)] = 1.0;
        }
        a
    }

    /// An upper bound of the region's fastest rate |λ|: Gershgorin bounds of M⁻¹C and M⁻¹K_r
    /// (see the module documentation).
    fn rate_bound(&self, a: &DMatrix<f64>) -> f64 {
        let n = self.n;
        let (mut kk, mut cc) = (0.0f64, 0.0f64);
        for row in n..2 * n {
            kk = kk.max((0..n).map(|j| a[(row, j)].abs()).sum::<f64>());
            cc = cc.max((n..2 * n).map(|j| a[(row, j)].abs()).sum::<f64>());
        }
        cc + kk.sqrt()
    }

    fn build(&self, code: u64) -> Result<Region, ExactError> {
        let matrix = self.augmented(code);
        if !matrix.iter().all(|v| v.is_finite()) || !self.key.step.is_finite() {
            return Err(self.not_finite());
        }
        let rate = self.rate_bound(&matrix);
        let phase = rate * self.key.step / CHECK_PHASE;
        let check_level = if phase > 1.0 {
            (phase.log2().ceil() as u32).min(DEPTH - 4)
        } else {
            0
        };
        let rate_step = rate * self.key.step;
        Ok(Region {
            matrix,
            levels: vec![None; DEPTH as usize + 1],
            check_level,
            whole_step_error: rate_step.powi(4) / 384.0,
        })
    }

    fn not_finite(&self) -> ExactError {
        ExactError::NotFinite(format!("{:?}", self.key))
    }

    /// The region `code`, built when first visited.
    #[inline(always)]
    fn region(&mut self, code: u64) -> Result<&mut Region, ExactError> {
        let slot = code as usize;
        if !matches!(self.regions.get(slot), Some(Some(_))) {
            self.visit(slot, code)?;
        }
        match self.regions[slot].as_deref_mut() {
            Some(r) => Ok(r),
            None => unreachable!("built by visit"),
        }
    }

    /// A region not cached yet: built (the cache emptied first when full), or the error of a
    /// code past the table.
    #[cold]
    #[inline(never)]
    fn visit(&mut self, slot: usize, code: u64) -> Result<(), ExactError> {
        if slot >= self.regions.len() {
            return Err(ExactError::TooManyContacts(self.key.contacts.len()));
        }
        if self.cached >= MAX_CACHED_REGIONS {
            self.regions.iter_mut().for_each(|r| *r = None);
            self.cached = 0;
        }
        self.regions[slot] = Some(Box::new(self.build(code)?));
        self.cached += 1;
        Ok(())
    }

    /// The region's flow over `size` ticks (a power of two) from `x`, the inputs `tau` seconds
    /// into the step.
    #[inline]
    fn apply<B: Buffer>(
        &mut self,
        code: u64,
        x: &B,
        size: u64,
        tau: f64,
        inputs: &StepInputs,
    ) -> Result<B, ExactError> {
        let n = self.n;
        let step = self.key.step;
        let self_extra = self.extra_columns();
        let extra = if self.folded {
            let (u, slope) = (
                inputs.excitation - inputs.control,
                inputs.excitation_slope - inputs.control_slope,
            );
            [u + slope * tau, slope, 1.0, 0.0, 0.0]
        } else {
            [
                inputs.excitation + inputs.excitation_slope * tau,
                inputs.excitation_slope,
                inputs.control + inputs.control_slope * tau,
                inputs.control_slope,
                1.0,
            ]
        };
        let level = (DEPTH - size.trailing_zeros()) as usize;
        let region = self.region(code)?;
        if region.levels[level].is_none() {
            let delta = step / f64::from(1u32 << level);
            let e = exponential(&region.matrix * delta);
            if !e.iter().all(|v| v.is_finite()) {
                return Err(ExactError::NotFinite(format!(
                    "the flow over {delta} s of region {code}"
                )));
            }
            // Column-major, the first 2N rows of each column (see `product_by_columns`).
            let width = 2 * n + self_extra;
            let mut flow = Vec::with_capacity(2 * n * width);
            for c in 0..width {
                flow.extend(e.column(c).iter().take(2 * n));
            }
            region.levels[level] = Some(flow.into_boxed_slice());
        }
        let Some(flow) = region.levels[level].as_deref() else {
            unreachable!("built above")
        };
        debug_assert_eq!(x.as_ref().len(), 2 * n);
        Ok(B::flowed(flow, x, &extra[..self_extra]))
    }

    /// Whether the piece from `a` to `b` (of `dt` seconds, in `region`) may hold a crossing: the
    /// region changed at its end, or a switch's cubic Hermite interpolant crosses zero inside.
    #[inline]
    fn flagged(&self, region: u64, a: &[f64], b: &[f64], dt: f64) -> bool {
        if self.region_of(b) != region {
            return true;
        }
        for (s, c) in &self.key.contacts {
            let (da, va) = drift(a, *s);
            let (db, vb) = drift(b, *s);
            if any_switch(c, |o| hermite_crosses(da - o, db - o, dt * va, dt * vb)) {
                return true;
            }
        }
        false
    }

    /// The energy of the relative motion: kinetic, storey springs and closed bumpers.
    fn energy(&self, x: &[f64]) -> f64 {
        let n = x.len() / 2;
        let p = &self.key.params;
        let mut e = 0.0;
        let mut contacts = self.key.contacts.iter().peekable();
        for s in 0..n {
            let (d, _) = drift(x, s);
            e += 0.5 * p.mass[s] * x[n + s] * x[n + s] + 0.5 * p.stiffness[s] * d * d;
            // The storey's bumper, if any (the contacts are in storey order).
            if let Some((_, c)) = contacts.next_if(|(site, _)| *site == s) {
                let f = c.force_at(d);
                if c.stiffness > 0.0 {
                    e += 0.5 * f * f / c.stiffness;
                }
            }
        }
        e
    }

    /// Whether the whole step from `a` to `b` (in `region`) stays clear of every switch: no
    /// crossing, and each switch's cubic Hermite interpolant at least twice its interpolation
    /// error bound `(ρ h)⁴/384 · D` from zero, `D = √(2E/k_s)` the largest drift of storey s the
    /// energy E (the larger of the two ends) allows.
    fn clear(&mut self, region: u64, a: &[f64], b: &[f64]) -> Result<bool, ExactError> {
        if self.region_of(b) != region {
            return Ok(false);
        }
        let error = self.region(region)?.whole_step_error;
        let h = self.key.step;
        let e = self.energy(a).max(self.energy(b));
        for (s, c) in &self.key.contacts {
            let amplitude = (2.0 * e / self.key.params.stiffness[*s]).sqrt();
            let margin = 2.0 * error * amplitude;
            if !margin.is_finite() {
                return Ok(false);
            }
            let (da, va) = drift(a, *s);
            let (db, vb) = drift(b, *s);
            if any_switch(c, |o| {
                hermite_distance(da - o, db - o, h * va, h * vb) <= margin
            }) {
                return Ok(false);
            }
        }
        Ok(true)
    }

    /// One communication step from `x0` (`[y, ẏ]`, 2N) under the inputs' ramps.
    pub fn advance(&mut self, x0: &[f64], inputs: &StepInputs) -> Result<Vec<f64>, ExactError> {
        let x: Inline = SmallVec::from_slice(x0);
        Ok(self.advance_in(&x, inputs)?.into_vec())
    }

    /// [`AnyContactMaps::advance`] on a state kept on the stack (a fixed array on the rig).
    pub fn advance_in<B: Buffer>(&mut self, x0: &B, inputs: &StepInputs) -> Result<B, ExactError> {
        let total: u64 = 1 << DEPTH;
        let tick = self.key.step / total as f64;
        let mut x = x0.clone();
        let mut pos: u64 = 0;
        let mut region = self.region_of(x.as_ref());
        let whole = self.apply(region, &x, total, 0.0, inputs)?;
        if self.clear(region, x.as_ref(), whole.as_ref())? {
            return Ok(whole);
        }
        while pos < total {
            let check = self.region(region)?.check_level;
            let left = total - pos;
            let mut size = (total >> check).min(1 << (63 - left.leading_zeros()));
            let at = pos as f64 * tick;
            let mut end = self.apply(region, &x, size, at, inputs)?;
            if !self.flagged(region, x.as_ref(), end.as_ref(), size as f64 * tick) {
                x = end;
                pos += size;
                continue;
            }
            if let Some((ticks, past)) =
                self.newton_event(region, &x, &end, pos, size, tick, inputs)?
            {
                x = past;
                pos += ticks;
                region = self.region_of(x.as_ref());
                continue;
            }
            // Bisect: the flagged piece is [pos, pos + size] from x to end.
            loop {
                if size == 1 {
                    x = end;
                    pos += 1;
                    region = self.region_of(x.as_ref());
                    break;
                }
                let half = size / 2;
                let mid = self.apply(region, &x, half, pos as f64 * tick, inputs)?;
                size = half;
                if self.flagged(region, x.as_ref(), mid.as_ref(), half as f64 * tick) {
                    end = mid;
                } else {
                    x = mid;
                    pos += half;
                    if !self.flagged(region, x.as_ref(), end.as_ref(), half as f64 * tick) {
                        x = end;
                        pos += half;
                        break;
                    }
                }
            }
        }
        Ok(x)
    }

    /// The state `count` ticks after `x` (at tick `pos`), as the flows of the binary digits of
    /// `count`.
    fn after_ticks<B: Buffer>(
        &mut self,
        region: u64,
        x: &B,
        pos: u64,
        count: u64,
        tick: f64,
        inputs: &StepInputs,
    ) -> Result<B, ExactError> {
        let mut x = x.clone();
        let mut at = pos;
        let mut rest = count;
        while rest > 0 {
            let digit = 1u64 << (63 - rest.leading_zeros());
            x = self.apply(region, &x, digit, at as f64 * tick, inputs)?;
            at += digit;
            rest -= digit;
        }
        Ok(x)
    }

    /// The first crossing inside a flagged piece `[pos, pos + size]` (from `a` to `b`): the
    /// earliest root of the switches' interpolants, one Newton step on the exact flow from a
    /// little before it, then a tick at a time (at most 4) until past; `(ticks, state)` of the
    /// first tick past it, checked, or `None` (the caller bisects).
    #[allow(clippy::too_many_arguments)]
    fn newton_event<B: Buffer>(
        &mut self,
        region: u64,
        a: &B,
        b: &B,
        pos: u64,
        size: u64,
        tick: f64,
        inputs: &StepInputs,
    ) -> Result<Option<(u64, B)>, ExactError> {
        let (a_state, b_state) = (a.as_ref(), b.as_ref());
        let dt = size as f64 * tick;
        let mut first: Option<(f64, usize, f64)> = None;
        for (s, c) in &self.key.contacts {
            let (da, va) = drift(a_state, *s);
            let (db, vb) = drift(b_state, *s);
            any_switch(c, |offset| {
                if let Some(theta) = hermite_root(da - offset, db - offset, dt * va, dt * vb) {
                    if first.is_none_or(|(t, _, _)| theta < t) {
                        first = Some((theta, *s, offset));
                    }
                }
                false
            });
        }
        let Some((theta, storey, offset)) = first else {
            return Ok(None);
        };
        let back = 2.0 + 1e-4 * size as f64;
        let k1 = ((theta * size as f64 - back).max(0.0).floor() as u64).min(size - 1);
        let x1 = self.after_ticks(region, a, pos, k1, tick, inputs)?;
        if self.region_of(x1.as_ref()) != region {
            return Ok(None);
        }
        let (d, v) = drift(x1.as_ref(), storey);
        let sigma = d - offset;
        if v == 0.0 || !(sigma / v).is_finite() {
            return Ok(None);
        }
        let ahead = -sigma / v / tick;
        if !(0.0..=(size - k1) as f64).contains(&ahead) {
            return Ok(None);
        }
        let k2 = k1 + (ahead.ceil() as u64).max(1) - 1;
        let mut before = self.after_ticks(region, &x1, pos + k1, k2 - k1, tick, inputs)?;
        if self.region_of(before.as_ref()) != region {
            return Ok(None);
        }
        let mut at = k2;
        for _ in 0..4 {
            if at >= size {
                return Ok(None);
            }
            let past = self.apply(region, &before, 1, (pos + at) as f64 * tick, inputs)?;
            at += 1;
            if self.region_of(past.as_ref()) != region {
                return Ok(Some((at, past)));
            }
            before = past;
        }
        Ok(None)
    }

    /// How many regions are cached (for tests and benches).
    pub fn cached_regions(&self) -> usize {
        self.cached
    }
}

/// `exp(m)` by nalgebra's Padé approximant with scaling and squaring. Up to four storeys (the
/// augmented matrix at most 13 square) in its fixed-size kernel: faster for these sizes, and
/// its products sum in their own column loop, as the rig's former fixed-array stepper did —
/// nalgebra hands a dynamic matrix past 5 × 5 to `matrixmultiply`, whose sums round otherwise
/// (1e-15 in a flow; a crossing's tick then lands one apart, 1e-10 of the rig's states).
fn exponential(m: DMatrix<f64>) -> DMatrix<f64> {
    macro_rules! fixed_size {
        ($($size:literal)*) => {
            match m.nrows() {
                $($size => {
                    let e = SMatrix::<f64, $size, $size>::from_column_slice(m.as_slice()).exp();
                    DMatrix::from_column_slice($size, $size, e.as_slice())
                })*
                _ => m.exp(),
            }
        };
    }
    fixed_size!(7 9 11 13)
}
