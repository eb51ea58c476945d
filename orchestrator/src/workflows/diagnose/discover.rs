//! Effects outside the library, discovered by sparse regression.
//!
//! When neither recalibration nor any combination of library effects explains a record, the
//! force the model misses is looked for as a sparse sum of candidate functions at one site, in
//! the spirit of equation discovery (SINDy), then added to the physics as the shear FMU's
//! generic `discovered` effect and refitted through FMI like any candidate.
//!
//! 1. **Candidates.** At each storey (its drift `x` and drift rate `v`) and each floor (its
//!    displacement and velocity): every function of the FMU's list ([`Function::ALL`]: `x`,
//!    `x^2`, `x^3`, `x|x|`, `v`, `v^2`, `v|v|`, `v^3`, `sign(v)`, `x^2*v`, …), `tanh(v/s)` at
//!    two widths (5 % and 20 % of the site's velocity RMS), and the one-sided ramps
//!    `max(0, x − s)`, `min(0, x + s)` with `s` at the 80th, 90th and 95th percentiles of `|x|`
//!    (a gap the data reach). The states are the base model's run: the twin as the forward
//!    selection left it.
//! 2. **Linearised output error.** A missing force `Σ θ_i φ_i(x, v)` at a site does not show up
//!    in the acceleration residual as itself but filtered by the structure. So each candidate
//!    `φ_i(t)` (along the base run) is driven through the base model's linear part (`M, C, K`,
//!    RK4, [`SUBSTEPS`] per sample, the force linear between samples): its response `s_i(t)` is
//!    the sensitivity of the accelerations to `θ_i` at `θ = 0`, and the residual is regressed on
//!    the `s_i`, every floor weighted by its measured variance (an NMSE fit) — a Gauss–Newton
//!    step from "no effect", which the FMI refit then finishes.
//! 3. **Sparse, localised.** Per site, greedy forward selection of at most [`MAX_TERMS_FOUND`]
//!    terms (least squares on the fitted blocks, from the Gram matrices), each size polished by
//!    single swaps while one lowers the fitted residual. SINDy's classic
//!    sequentially thresholded least squares was the first choice; with candidates as
//!    correlated as `x`, `x|x|`, `x^3` and the ramps it trades large cancelling coefficients,
//!    while a greedy path scored on the held-out blocks stays sparse by construction. The path
//!    stops at the smallest size within [`PARSIMONY`] (1 % of the residual before) of its best
//!    held-out error. The site whose model
//!    cuts the held-out residual most wins; a model of only `x` and `v` is a parameter change,
//!    not an effect, and is passed over.
//! 4. The caller adds the terms to the FMU (`discovered{i}_*`), refits their coefficients and
//!    the physics through FMI, and gates the result like any candidate.

use std::time::Instant;

use nalgebra::{DMatrix, DVector};

use structure::channel::Quantity;
use structure::effects::{Function, Kind, Placement, Site, Term};

use super::{
    effect_report, estimates, select, worst, Addition, Candidate, DiagnoseError, DiscoveryReport,
    EffectReport, Estimates, Fitted, PhysicsRun, Result,
};
use crate::evaluation::stats::variance;

mod columns;
mod sensitivity;

use columns::{columns, quantile, site_states};
use sensitivity::sensitivity;

pub use super::report::{Found, SiteModel};

/// RK4 sub-steps per sample of the sensitivity runs.
pub const SUBSTEPS: u32 = 8;

/// Terms a discovered effect has at most.
pub const MAX_TERMS_FOUND: usize = 3;

/// The path stops at the smallest size whose held-out residual is within this share of the
/// residual before of the path's best: a term that explains less than 1 % is not worth it.
pub const PARSIMONY: f64 = 0.01;

/// The linear part of the base model: per floor (mass) and storey (damping, stiffness), 1
/// first.
#[derive(Clone, Debug)]
pub struct LinearPart {
    pub mass: Vec<f64>,
    pub damping: Vec<f64>,
    pub stiffness: Vec<f64>,
}

impl LinearPart {
    pub fn storeys(&self) -> usize {
        self.mass.len()
    }
}

/// The base model's states along the record, every storey and floor, 1 first.
pub struct States<'a> {
    /// Storey drifts (storey 1 = floor 1's displacement).
    pub drift: &'a [Vec<f64>],
    /// Floor velocities.
    pub velocity: &'a [Vec<f64>],
    /// Floor accelerations.
    pub acceleration: &'a [Vec<f64>],
}

/// What the regression sees.
pub struct Problem<'a> {
    pub linear: LinearPart,
    pub states: States<'a>,
    /// The measured channels' floors (from 0) and quantities, in the record's order: each
    /// sensitivity is read in the channel's own quantity.
    pub sensors: &'a [(usize, Quantity)],
    /// Measured minus base-model responses, per channel, in its quantity.
    pub residual: Vec<Vec<f64>>,
    /// Variance of each channel's measured response (the NMSE's denominator).
    pub variance: Vec<f64>,
    pub dt: f64,
    pub fitted: &'a [usize],
    pub held_out: &'a [usize],
    pub first: usize,
}

impl Problem<'_> {
    /// The nuisance columns, in every model: the sensitivities to the physics parameters (each
    /// storey's `x` and `v`, each floor's mass as the force `δm·ÿ`), so a parameter that is
    /// also off takes its own share and the sparse terms only what no parameter can.
    fn nuisance(&self) -> Vec<Vec<Vec<f64>>> {
        let mut nuisance: Vec<Vec<Vec<f64>>> = Vec::new();
        for storey in 1..=self.linear.storeys() {
            let site = Site::Storey(storey);
            let (x, v) = site_states(&self.states, site);
            nuisance.push(sensitivity(&self.linear, site, &x, self.dt, self.sensors));
            nuisance.push(sensitivity(&self.linear, site, &v, self.dt, self.sensors));
        }
        for floor in 1..=self.linear.storeys() {
            nuisance.push(sensitivity(
                &self.linear,
                Site::Floor(floor),
                &self.states.acceleration[floor - 1],
                self.dt,
                self.sensors,
            ));
        }
        nuisance
    }

    fn weights(&self) -> Vec<f64> {
        self.variance
            .iter()
            .map(|&v| if v > 0.0 { 1.0 / v } else { 0.0 })
            .collect()
    }
}

/// Screen the library's candidates before any is fitted through the FMU: for each, the share
/// of the held-out residual (the physics parameters' sensitivities always in the model) that
/// its force, linearised through the structure as in [`regress`], leaves — the lowest over a
/// few shapes of its law: contact at a storey as a one-sided ramp of the drift beyond a gap
/// (the 80th, 90th and 95th percentiles of `|x|`) above, below or both (every side of a storey
/// gets the storey's score, so a sign convention cannot drop the right side); cubic as `x^3`;
/// friction on a floor as `sign(v)` or `tanh(v/s)` (`s` 5 % and 20 % of its velocity RMS).
/// 1 means the candidate explains nothing the parameters do not; the lowest are worth fitting.
pub fn screen(problem: &Problem, candidates: &[Candidate], threads: usize) -> Vec<f64> {
    let w = problem.weights();
    let nuisance = problem.nuisance();
    let shared = Shared::new(problem, &nuisance, &w);
    // Every kind at every site once (the sides of a contact share their storey's score), the
    // sites over the threads.
    let mut sites: Vec<(Kind, usize, Placement)> = Vec::new();
    for c in candidates {
        if !sites.iter().any(|&(k, at, _)| (k, at) == (c.kind, c.at)) {
            sites.push((c.kind, c.at, c.placement()));
        }
    }
    let scores = crate::parallel::on_threads(&sites, threads, |&(kind, at, placement)| {
        site_score(problem, &shared, &nuisance, &w, kind, at, placement)
    });
    candidates
        .iter()
        .map(|c| {
            let i = sites
                .iter()
                .position(|&(k, at, _)| (k, at) == (c.kind, c.at))
                .expect("every candidate's site is scored");
            scores[i]
        })
        .collect()
}

/// The screen's score of `kind` at a site (see [`screen`]).
fn site_score(
    problem: &Problem,
    shared: &Shared,
    nuisance: &[Vec<Vec<f64>>],
    w: &[f64],
    kind: Kind,
    at: usize,
    placement: Placement,
) -> f64 {
    let q = nuisance.len();
    let base: Vec<usize> = (0..q).collect();
    let site = match placement {
        Placement::Storey => Site::Storey(at),
        Placement::Floor => Site::Floor(at),
    };
    let (x, v) = site_states(&problem.states, site);
    let after_x = &x[problem.first..];
    let after_v = &v[problem.first..];
    let v_rms = (after_v.iter().map(|a| a * a).sum::<f64>() / after_v.len().max(1) as f64).sqrt();
    let shapes: Vec<Vec<(Function, f64)>> = match kind {
        Kind::Cubic => vec![vec![(Function::X3, 1.0)]],
        Kind::Friction => vec![
            vec![(Function::SignV, 1.0)],
            vec![(Function::TanhV, 0.05 * v_rms)],
            vec![(Function::TanhV, 0.2 * v_rms)],
        ],
        Kind::Contact => [0.8, 0.9, 0.95]
            .iter()
            .flat_map(|&p| {
                let gap = quantile(after_x, p);
                [
                    vec![(Function::RampUp, gap)],
                    vec![(Function::RampDown, gap)],
                    vec![(Function::RampUp, gap), (Function::RampDown, gap)],
                ]
            })
            .collect(),
    };
    let mut columns = nuisance.to_vec();
    let mut sets = Vec::new();
    for shape in &shapes {
        let mut set = base.clone();
        for &(function, scale) in shape {
            let phi: Vec<f64> = x
                .iter()
                .zip(&v)
                .map(|(&a, &b)| function.eval(a, b, scale))
                .collect();
            set.push(columns.len());
            columns.push(sensitivity(
                &problem.linear,
                site,
                &phi,
                problem.dt,
                problem.sensors,
            ));
        }
        sets.push(set);
    }
    let (fit, held) = shared.extended(problem, &columns, w);
    let reference = solve(&fit, &base)
        .map(|theta| left(&held, &base, &theta))
        .unwrap_or(held.energy);
    sets.iter()
        .filter_map(|set| solve(&fit, set).map(|theta| left(&held, set, &theta)))
        .map(|e| e / reference)
        .filter(|x| x.is_finite())
        .fold(1.0, f64::min)
}

/// Weighted Gram matrix, right-hand side and residual energy over `rows`.
struct Normal {
    gram: DMatrix<f64>,
    rhs: DVector<f64>,
    energy: f64,
}

/// `columns` and `residual` per channel.
fn normal(columns: &[Vec<Vec<f64>>], residual: &[Vec<f64>], w: &[f64], rows: &[usize]) -> Normal {
    let p = columns.len();
    let empty = Normal {
        gram: DMatrix::zeros(0, 0),
        rhs: DVector::zeros(0),
        energy: 0.0,
    };
    let mut gram = DMatrix::zeros(p, p);
    let mut rhs = DVector::zeros(p);
    let mut energy = 0.0;
    for f in 0..residual.len() {
        for &k in rows {
            let r = residual[f][k];
            energy += w[f] * r * r;
        }
    }
    fill(&mut gram, &mut rhs, &empty, columns, residual, w, rows);
    Normal { gram, rhs, energy }
}

/// The nuisance columns' normal equations on the fitted and the held-out rows: the block every
/// site's model shares, computed once per screen or regression instead of once per site (at 20
/// storeys the 60 nuisance columns' block was nine tenths of each site's products).
struct Shared {
    fit: Normal,
    held: Normal,
}

impl Shared {
    fn new(problem: &Problem, nuisance: &[Vec<Vec<f64>>], w: &[f64]) -> Self {
        Shared {
            fit: normal(nuisance, &problem.residual, w, problem.fitted),
            held: normal(nuisance, &problem.residual, w, problem.held_out),
        }
    }

    /// The normal equations of `columns` (the nuisance columns first, as in `self`) on the
    /// fitted and the held-out rows: every entry summed over the channels and rows in the same
    /// order as [`normal`] would, so the same numbers to the last bit.
    fn extended(
        &self,
        problem: &Problem,
        columns: &[Vec<Vec<f64>>],
        w: &[f64],
    ) -> (Normal, Normal) {
        let grow = |base: &Normal, rows: &[usize]| {
            let p = columns.len();
            let mut gram = DMatrix::zeros(p, p);
            let mut rhs = DVector::zeros(p);
            fill(
                &mut gram,
                &mut rhs,
                base,
                columns,
                &problem.residual,
                w,
                rows,
            );
            Normal {
                gram,
                rhs,
                energy: base.energy,
            }
        };
        (
            grow(&self.fit, problem.fitted),
            grow(&self.held, problem.held_out),
        )
    }
}

/// The Gram matrix and right-hand side of `columns` over `rows`, the leading block (and right-
/// hand side) copied from `known` and only the entries involving a later column summed: each
/// entry over the channels, then the rows in their order, `w·s_i·s_j` (and `w·s_i·r`).
fn fill(
    gram: &mut DMatrix<f64>,
    rhs: &mut DVector<f64>,
    known: &Normal,
    columns: &[Vec<Vec<f64>>],
    residual: &[Vec<f64>],
    w: &[f64],
    rows: &[usize],
) {
    let p = columns.len();
    let q = known.rhs.len();
    for i in 0..q {
        rhs[i] = known.rhs[i];
        for j in 0..q {
            gram[(i, j)] = known.gram[(i, j)];
        }
    }
    for i in q..p {
        let mut acc = 0.0;
        for (f, channel) in columns[i].iter().enumerate() {
            for &k in rows {
                acc += w[f] * channel[k] * residual[f][k];
            }
        }
        rhs[i] = acc;
    }
    for j in q..p {
        for i in 0..=j {
            let mut acc = 0.0;
            for f in 0..residual.len() {
                let (si, sj) = (&columns[i][f], &columns[j][f]);
                for &k in rows {
                    acc += w[f] * si[k] * sj[k];
                }
            }
            gram[(i, j)] = acc;
            gram[(j, i)] = acc;
        }
    }
}

/// Least squares on the `active` columns: the coefficients, or `None` when singular. The
/// columns are scaled to unit norm first (their natural sizes differ by ten orders of
/// magnitude between `x^3` and `sign(v)`).
fn solve(n: &Normal, active: &[usize]) -> Option<DVector<f64>> {
    let k = active.len();
    let d: Vec<f64> = active
        .iter()
        .map(|&i| {
            let g = n.gram[(i, i)];
            if g > 0.0 {
                1.0 / g.sqrt()
            } else {
                0.0
            }
        })
        .collect();
    if d.iter().any(|&x| x == 0.0 || !x.is_finite()) {
        return None;
    }
    let mut g = DMatrix::zeros(k, k);
    let mut b = DVector::zeros(k);
    for (a, &i) in active.iter().enumerate() {
        b[a] = d[a] * n.rhs[i];
        for (c, &j) in active.iter().enumerate() {
            g[(a, c)] = d[a] * n.gram[(i, j)] * d[c];
        }
    }
    // A whisper of ridge against exactly collinear candidates.
    for i in 0..k {
        g[(i, i)] += 1e-12;
    }
    let z = g.cholesky()?.solve(&b);
    Some(DVector::from_iterator(k, (0..k).map(|a| d[a] * z[a])))
}

/// The residual energy left by `theta` on `active` under `n`.
fn left(n: &Normal, active: &[usize], theta: &DVector<f64>) -> f64 {
    let mut e = n.energy;
    for (a, &i) in active.iter().enumerate() {
        e -= 2.0 * theta[a] * n.rhs[i];
        for (c, &j) in active.iter().enumerate() {
            e += theta[a] * theta[c] * n.gram[(i, j)];
        }
    }
    e
}

/// The response at `sensors` the base model's linear part gives to `term`'s force along
/// `states`: its linearised share of the response (a pass after a refit adds it back to the
/// residual to linearise again around the better trajectory).
pub fn term_response(
    linear: &LinearPart,
    states: &States,
    term: &Term,
    dt: f64,
    sensors: &[(usize, Quantity)],
) -> Vec<Vec<f64>> {
    let (x, v) = site_states(states, term.site);
    let phi: Vec<f64> = x
        .iter()
        .zip(&v)
        .map(|(&a, &b)| term.force_at(a, b))
        .collect();
    sensitivity(linear, term.site, &phi, dt, sensors)
}

/// Improve `active` (its first `q` columns fixed) by single swaps with the columns `q..p` while
/// one lowers the fitted residual; the final coefficients.
fn swap(fit: &Normal, active: &mut [usize], q: usize, p: usize) -> DVector<f64> {
    let energy = |set: &[usize]| solve(fit, set).map(|t| (left(fit, set, &t), t));
    let Some((mut best, mut theta)) = energy(active) else {
        return DVector::zeros(active.len());
    };
    for _ in 0..MAX_TERMS_FOUND * 4 {
        let mut improved = false;
        for position in q..active.len() {
            for candidate in q..p {
                if active.contains(&candidate) {
                    continue;
                }
                let old = active[position];
                active[position] = candidate;
                match energy(active) {
                    Some((e, t)) if e < best * (1.0 - 1e-9) => {
                        best = e;
                        theta = t;
                        improved = true;
                    }
                    _ => active[position] = old,
                }
            }
        }
        if !improved {
            break;
        }
    }
    theta
}

/// The greedy path from the physics parameters alone (`base`): at each step the candidate
/// among the `count` responses that most lowers the fitted blocks' residual, then swaps while
/// one lowers it more; each step's set, coefficients and held-out residual.
fn greedy_path(
    fit: &Normal,
    held: &Normal,
    base: &[usize],
    count: usize,
) -> Vec<(Vec<usize>, DVector<f64>, f64)> {
    let q = base.len();
    let mut active: Vec<usize> = base.to_vec();
    let mut path: Vec<(Vec<usize>, DVector<f64>, f64)> = Vec::new();
    while active.len() < q + MAX_TERMS_FOUND {
        let mut step: Option<(usize, DVector<f64>, f64)> = None;
        for i in q..count {
            if active.contains(&i) {
                continue;
            }
            let mut trial = active.clone();
            trial.push(i);
            let Some(theta) = solve(fit, &trial) else {
                continue;
            };
            let e = left(fit, &trial, &theta);
            if step.as_ref().is_none_or(|s| e < s.2) {
                step = Some((i, theta, e));
            }
        }
        let Some((i, _, _)) = step else { break };
        active.push(i);
        // Swaps: each chosen term against every other candidate, while one lowers the
        // fitted-block residual (greedy picks are often a near-twin of the truth first,
        // `v^3` for `v|v|`).
        let theta = swap(fit, &mut active, q, count);
        let e_held = left(held, &active, &theta);
        path.push((active.clone(), theta, e_held));
    }
    path
}

/// The path's first step whose held-out residual is within [`PARSIMONY`] × `reference` of the
/// path's least (None for an empty path).
fn parsimonious(
    path: &[(Vec<usize>, DVector<f64>, f64)],
    reference: f64,
) -> Option<(Vec<usize>, DVector<f64>, f64)> {
    let min_held = path.iter().map(|p| p.2).min_by(f64::total_cmp)?;
    path.iter()
        .find(|p| p.2 <= min_held + PARSIMONY * reference)
        .cloned()
}

/// Find the sparse model of the missing force (see the module documentation); `None` when no
/// site's model cuts the held-out residual the physics parameters alone leave by `min_cut`.
pub fn regress(problem: &Problem, min_cut: f64) -> Option<Found> {
    let w = problem.weights();
    let dt = problem.dt;
    let storeys = problem.linear.storeys();
    let nuisance = problem.nuisance();
    let shared = Shared::new(problem, &nuisance, &w);
    let q = nuisance.len();
    let base: Vec<usize> = (0..q).collect();
    let mut best: Option<(f64, Vec<Term>, String)> = None;
    let mut sites = Vec::new();
    for site in Site::all(storeys) {
        let (x, v) = site_states(&problem.states, site);
        let after = |s: &[f64]| s[problem.first..].to_vec();
        let cols = columns(site, &after(&x), &after(&v));
        let mut responses = nuisance.clone();
        responses.extend(cols.iter().map(|c| {
            let phi: Vec<f64> = x
                .iter()
                .zip(&v)
                .map(|(&a, &b)| c.function.eval(a, b, c.scale))
                .collect();
            sensitivity(&problem.linear, site, &phi, dt, problem.sensors)
        }));
        let (fit, held) = shared.extended(problem, &responses, &w);
        // What the physics parameters alone leave on the held-out blocks: the reference.
        let reference = solve(&fit, &base)
            .map(|theta| left(&held, &base, &theta))
            .unwrap_or(held.energy);
        let path = greedy_path(&fit, &held, &base, responses.len());
        let Some((set, theta, e_held)) = parsimonious(&path, reference) else {
            continue;
        };
        let fraction = e_held / reference;
        let chosen: Vec<(usize, f64)> = set
            .iter()
            .zip(theta.iter())
            .skip(q)
            .map(|(&i, &c)| (i - q, c))
            .collect();
        sites.push(SiteModel {
            site: site.to_string(),
            terms: chosen.iter().map(|&(i, _)| cols[i].label()).collect(),
            held_out_fraction: fraction,
        });
        let terms: Vec<Term> = chosen
            .iter()
            .map(|&(i, coefficient)| Term {
                function: cols[i].function,
                site,
                coefficient,
                scale: cols[i].scale,
            })
            .collect();
        if fraction * min_cut <= 1.0 && best.as_ref().is_none_or(|b| e_held < b.0) {
            best = Some((e_held, terms, site.to_string()));
        }
    }
    sites.sort_by(|a, b| a.held_out_fraction.total_cmp(&b.held_out_fraction));
    let (_, terms, site) = best?;
    let held_out_fraction = sites
        .iter()
        .find(|s| s.site == site)
        .map(|s| s.held_out_fraction)
        .unwrap_or(f64::NAN);
    Some(Found {
        terms,
        site,
        held_out_fraction,
        sites,
    })
}

// -- the search through the FMU ------------------------------------------------------

/// What discovery found and, when it passes the gates, its terms and fit.
pub(super) type Discovered = (DiscoveryReport, Option<(Vec<Term>, Fitted)>);

/// The regression problem around the run of the model at `values`, with `terms` (their
/// linearised response) added back to the residual, solved: the sparse terms that cut the
/// residual on the samples `fitted_idx`.
fn regression_problem(
    ctx: &select::Context,
    fitted_idx: &[usize],
    values: &Estimates,
    run: &PhysicsRun,
    terms: &[Term],
) -> Result<Found> {
    let data = ctx.data;
    let value = |name: &str| -> Result<f64> {
        match values.get(name) {
            Some(&(v, _)) => Ok(v),
            None => ctx.reals.get(name),
        }
    };
    let per_storey = |p: char| -> Result<Vec<f64>> {
        (1..=ctx.reals.storeys)
            .map(|i| value(&format!("{p}{i}")))
            .collect()
    };
    let linear = LinearPart {
        mass: per_storey('m')?,
        damping: per_storey('c')?,
        stiffness: per_storey('k')?,
    };
    let states = States {
        drift: &run.drift,
        velocity: &run.velocity,
        acceleration: &run.acc,
    };
    let channels = ctx.channels;
    let sensors = channels.sensors();
    let mut residual = channels.residuals(run);
    for t in terms {
        let share = term_response(&linear, &states, t, data.dt, &sensors);
        for (residual, share) in residual.iter_mut().zip(&share) {
            for (r, s) in residual.iter_mut().zip(share) {
                *r += s;
            }
        }
    }
    let problem = Problem {
        linear,
        states,
        sensors: &sensors,
        residual,
        variance: channels
            .measured
            .iter()
            .map(|m| variance(&m[ctx.split.first..]))
            .collect(),
        dt: data.dt,
        fitted: fitted_idx,
        held_out: ctx.split.held_out,
        first: ctx.split.first,
    };
    regress(&problem, ctx.options.gates.step_cut)
        .ok_or_else(|| DiagnoseError::Setup("no sparse model cuts the residual".into()))
}

/// `terms` refitted through the FMU with the physics of `chosen` at `values`: the terms with
/// their fitted coefficients, and the fit.
fn refit_terms(
    ctx: &select::Context,
    chosen: &[Candidate],
    values: &Estimates,
    terms: &[Term],
) -> Result<(Vec<Term>, Fitted)> {
    ctx.options.tell(&format!(
        "refitting {} through the FMU",
        terms
            .iter()
            .map(|t| t.to_string())
            .collect::<Vec<_>>()
            .join(" + ")
    ));
    let fitted = ctx.fit_addition(chosen, values, &Addition::Discovered(terms.to_vec()))?;
    let mut terms = terms.to_vec();
    let names = Addition::Discovered(terms.clone()).parameters(ctx.scales);
    for (t, (name, _, _)) in terms.iter_mut().zip(&names) {
        if let Some(p) = fitted
            .calibration
            .parameters
            .iter()
            .find(|p| &p.name == name)
        {
            t.coefficient = p.value;
        }
    }
    Ok((terms, fitted))
}

/// Sparse regression of the missing force on top of the model of `chosen` at `values` (whose
/// physics run is `run`), refitted through FMI with the physics (see the module documentation).
pub(super) fn missing(
    ctx: &select::Context,
    chosen: &[Candidate],
    values: &Estimates,
    run: &PhysicsRun,
    before_worst: f64,
    recal_worst: f64,
) -> Result<Discovered> {
    let started = Instant::now();
    let gates = ctx.options.gates;
    let data = ctx.data;
    let n = data.len();
    let fitted_idx: Vec<usize> = (0..n).filter(|&k| ctx.split.mask[k]).collect();
    let problem = |values: &Estimates, run: &PhysicsRun, terms: &[Term]| {
        regression_problem(ctx, &fitted_idx, values, run, terms)
    };
    let refit = |terms: &[Term]| refit_terms(ctx, chosen, values, terms);
    let found = problem(values, run, &[]).ok();
    let mut report = DiscoveryReport {
        regression: found.clone(),
        relinearised: None,
        terms: Vec::new(),
        nmse_held_out: None,
        nmse_after: None,
        passes: false,
        seconds: 0.0,
    };
    let Some(found) = found else {
        report.seconds = started.elapsed().as_secs_f64();
        return Ok((report, None));
    };
    let mut best = refit(&found.terms)?;
    // A second pass around the refitted model's trajectory, closer to the structure's: the
    // first linearisation sees the states of a model without the force, which can make a
    // near-twin (`v^3` for `v|v|`) look better than the truth.
    let mut refitted_values = values.clone();
    refitted_values.extend(estimates(&best.1.calibration));
    if let Ok(again) = problem(&refitted_values, &best.1.run, &best.0) {
        let same =
            again.terms.len() == best.0.len()
                && again.terms.iter().zip(&best.0).all(|(a, b)| {
                    a.function == b.function && a.site == b.site && a.scale == b.scale
                });
        if !same {
            let second = refit(&again.terms)?;
            if worst(&second.1.nmse_held_out) < worst(&best.1.nmse_held_out) {
                best = second;
            }
        }
        report.relinearised = Some(again);
    }
    let (terms, fitted) = best;
    let addition = Addition::Discovered(terms.clone());
    let w = worst(&fitted.nmse_held_out);
    report.passes =
        w * gates.required_cut <= before_worst && w * gates.beat_recalibration <= recal_worst;
    report.terms = effect_report(&addition, &estimates(&fitted.calibration), ctx.scales).terms;
    report.nmse_held_out = Some(fitted.nmse_held_out.clone());
    report.nmse_after = Some(fitted.nmse_after.clone());
    report.seconds = started.elapsed().as_secs_f64();
    let pass = report.passes.then_some((terms, fitted));
    Ok((report, pass))
}

/// The discovered terms' storey force along `run` (drift and drift rate of their storey), when
/// they sit at a storey, and the axis to draw it against: the drift rate when every term is a
/// function of the rate alone, else the drift (a curve when every term is of the drift alone).
pub(super) fn storey_force(
    terms: &[Term],
    run: &PhysicsRun,
) -> Option<(Vec<f64>, super::EvidenceAxis)> {
    let Site::Storey(storey) = terms.first()?.site else {
        return None;
    };
    let s = storey - 1;
    let rate: Vec<f64> = (0..run.drift[s].len())
        .map(|k| {
            if s == 0 {
                run.velocity[0][k]
            } else {
                run.velocity[s][k] - run.velocity[s - 1][k]
            }
        })
        .collect();
    let force = run.drift[s]
        .iter()
        .zip(&rate)
        .map(|(&x, &v)| terms.iter().map(|t| t.force_at(x, v)).sum())
        .collect();
    let of_rate = |f: Function| {
        matches!(
            f,
            Function::V
                | Function::V2
                | Function::VAbsV
                | Function::V3
                | Function::SignV
                | Function::TanhV
        )
    };
    let axis = if terms.iter().all(|t| of_rate(t.function)) {
        super::EvidenceAxis {
            label: format!("drift rate of storey {storey} (m/s)"),
            values: rate,
            curve: true,
        }
    } else {
        super::EvidenceAxis {
            label: format!("drift of storey {storey} (m)"),
            values: run.drift[s].clone(),
            curve: terms
                .iter()
                .all(|t| !of_rate(t.function) && t.function != Function::X2V),
        }
    };
    Some((force, axis))
}

/// `c·v|v| + c·x^3 at storey 2`: a discovered effect's terms in words.
pub(super) fn describe_terms(e: &EffectReport) -> String {
    let terms: Vec<String> = e
        .terms
        .iter()
        .map(|t| {
            format!(
                "{:.3e}·{}{}",
                t.coefficient,
                t.function,
                t.scale
                    .map(|s| format!(" (s = {s:.2e})"))
                    .unwrap_or_default()
            )
        })
        .collect();
    format!(
        "{} at {} {}",
        terms.join(" + "),
        e.name.site.unwrap_or("?"),
        e.name.location.first().copied().unwrap_or(0)
    )
}

#[cfg(test)]
mod tests;
