//! A roving test's modes, PoSER style with the measured force as the reference: each run's
//! modes are found in its own FRF (LSCF), the runs' modes are paired by frequency, then each
//! run is taken whole in the time domain through its force ([`time_fit`]): its poles refined
//! from the pairs' LSCF means, a pair's pole the mean of its runs' refined ones, and each
//! channel's shape component its run's residue at that mean pole. The force is every run's
//! common reference, so the residues share one unit and phase and need no rescaling through
//! a reference accelerometer (PoSER's overlap step reduces to nothing). The time domain
//! because the Welch FRF of a short run leaks a lightly damped mode whose decay outlasts a
//! segment: the lab frame's 0.39 %-damped first mode came out of the runs' FRFs at 0.90 %,
//! and the residues read off its smeared peaks gave a shape of MAC 0.93; taken whole, the
//! runs give 0.395 % and MAC 0.99998. A joint fit of the FRFs of all runs (PreGER-like, an
//! earlier version) fails on the same runs: they put the mode at frequencies ±0.4 % apart in
//! 0.12 Hz bins, one pole cannot sit on all of them, and the residues it read off their peaks
//! turned by up to 50° (MPC 0.36: the mode was set aside).

use numerics::modal::stabilisation::{
    normalised, screen_modes, IdentifiedMode, RejectedMode, Rejection, ScreenOptions,
};
use numerics::modal::time_fit;
use numerics::modal::{mpc, mpd, Complex};

use super::{fit_band, Estimation, IdentifyError, MethodModes, Peaks, DEFAULT_BAND_TOP};

/// One run's band fitted and the modes LSCF found in it.
struct RunModes {
    band: (f64, f64),
    method: MethodModes,
}

/// A mode found in several runs: per run that found it, the index of its mode.
type Group = Vec<(usize, usize)>;

impl Estimation<'_> {
    /// The modes of a roving test (every run with the measured force and its own channels).
    pub(super) fn roving_modes(
        &self,
        force_psd: &[f64],
        floors: &[(usize, (usize, i32))],
        screen: &ScreenOptions,
    ) -> Result<MethodModes, IdentifyError> {
        let per_run = self.per_run_modes(force_psd, screen)?;
        let tolerance = 2.0 * self.options.selection.cluster_frequency;
        let (groups, few): (Vec<Group>, Vec<Group>) = group_across_runs(&per_run, tolerance)
            .into_iter()
            .partition(|g| 2 * g.len() >= per_run.len());
        let merged = self.merged_modes(&per_run, &groups)?;
        let (modes, mut rejected) = screen_modes(merged, screen);
        rejected.extend(few.iter().map(|g| {
            let (r, i) = g[0];
            RejectedMode::new(
                per_run[r].method.modes[i].identified.clone(),
                Rejection::FewRuns,
            )
        }));
        for run in &per_run {
            rejected.extend(run.method.rejected.iter().cloned());
        }
        rejected.sort_by(|a, b| a.mode.frequency.total_cmp(&b.mode.frequency));
        let band = per_run
            .iter()
            .map(|r| r.band)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), (a, b)| {
                (l.min(a), h.max(b))
            });
        let diagram = per_run
            .into_iter()
            .next()
            .map(|r| r.method.diagram)
            .ok_or(IdentifyError::Options("no run".into()))?;
        Ok(MethodModes {
            method: "LSCF",
            band: Some(band),
            modes: super::record_modes(modes, floors),
            rejected,
            diagram,
        })
    }

    /// Every run's FRF and its LSCF modes over its band (chosen and screened as a single
    /// record's).
    fn per_run_modes(
        &self,
        force_psd: &[f64],
        screen: &ScreenOptions,
    ) -> Result<Vec<RunModes>, IdentifyError> {
        let top = DEFAULT_BAND_TOP * self.sampling.nyquist;
        self.spectral_runs
            .iter()
            .map(|run| {
                let frf = self
                    .welch
                    .h1(std::slice::from_ref(run))
                    .map_err(self.sampling.method_err("the FRF"))?;
                let band = self
                    .options
                    .band
                    .unwrap_or_else(|| fit_band(&frf, force_psd, top));
                let evidence = Peaks::of_frf(&frf);
                let method = self.lscf_modes(&frf, band, evidence, screen, &[])?;
                Ok(RunModes { band, method })
            })
            .collect()
    }

    /// Per group, the mean pole of its runs and the shape at every channel, both from the
    /// runs taken whole in the time domain through the measured force ([`time_fit`]): each
    /// run's poles refined from the LSCF ones, the pole of a group the mean over the runs that
    /// found it, each channel's component its run's residue at that mean pole, and the
    /// residue's shift to its run's own refined pole the component's uncertainty.
    fn merged_modes(
        &self,
        per_run: &[RunModes],
        groups: &[Group],
    ) -> Result<Vec<IdentifiedMode>, IdentifyError> {
        let channels = self
            .run_channels
            .iter()
            .flatten()
            .max()
            .map_or(0, |c| c + 1);
        let lscf: Vec<IdentifiedMode> = groups.iter().map(|g| mean_pole(per_run, g)).collect();
        let refined = self.refined_poles(&lscf)?;
        let means: Vec<IdentifiedMode> = groups
            .iter()
            .zip(lscf)
            .enumerate()
            .map(|(m, (g, mode))| refined_pole(mode, g.iter().map(|(r, _)| refined[*r][m])))
            .collect();
        let merged: Vec<Complex> = means.iter().map(eigenvalue).collect();
        let zero = Complex::new(0.0, 0.0);
        let mut shapes = vec![vec![zero; channels]; groups.len()];
        let mut spread = vec![vec![0.0; channels]; groups.len()];
        let mut counts = vec![0usize; channels];
        for (r, run) in self.spectral_runs.iter().enumerate() {
            let own: Vec<Complex> = refined[r].iter().map(|(f, z)| pole(*f, *z)).collect();
            let input = run.input.unwrap_or_default();
            let fit = |poles: &[Complex]| {
                time_fit::fit_residues(self.sampling.dt, input, run.outputs, poles)
                    .map(|f| f.residues)
                    .ok_or_else(|| {
                        IdentifyError::Options(format!(
                            "roving run {}: the time-domain fit of its modes is singular",
                            r + 1
                        ))
                    })
            };
            let (at_merged, at_own) = (fit(&merged)?, fit(&own)?);
            for (local, &global) in self.run_channels[r].iter().enumerate() {
                counts[global] += 1;
                for m in 0..groups.len() {
                    shapes[m][global] += at_merged[m][local];
                    spread[m][global] += (at_own[m][local] - at_merged[m][local]).norm();
                }
            }
        }
        Ok(means
            .into_iter()
            .zip(shapes.into_iter().zip(spread))
            .map(|(mean, (shape, spread))| with_shape(mean, shape, spread, &counts))
            .collect())
    }

    /// Per run, the groups' poles (Hz, damping ratio) refined in the time domain from their
    /// LSCF means (every run holds the measured force, so every run refines every pole).
    fn refined_poles(
        &self,
        lscf: &[IdentifiedMode],
    ) -> Result<Vec<Vec<(f64, f64)>>, IdentifyError> {
        let start: Vec<(f64, f64)> = lscf.iter().map(|m| (m.frequency, m.damping)).collect();
        self.spectral_runs
            .iter()
            .enumerate()
            .map(|(r, run)| {
                let input = run.input.ok_or_else(|| {
                    IdentifyError::Options(format!("roving run {}: no measured force", r + 1))
                })?;
                time_fit::refine_poles(self.sampling.dt, input, run.outputs, &start).ok_or_else(
                    || {
                        IdentifyError::Options(format!(
                            "roving run {}: the time-domain fit of its modes is singular",
                            r + 1
                        ))
                    },
                )
            })
            .collect()
    }
}

/// The group's mode with frequency and damping the means of its runs' refined poles, each sd
/// their scatter (the LSCF sd when one run found it).
fn refined_pole(lscf: IdentifiedMode, poles: impl Iterator<Item = (f64, f64)>) -> IdentifiedMode {
    let poles: Vec<(f64, f64)> = poles.collect();
    let n = poles.len() as f64;
    let frequency = poles.iter().map(|p| p.0).sum::<f64>() / n;
    let damping = poles.iter().map(|p| p.1).sum::<f64>() / n;
    let scatter = |f: fn(&(f64, f64)) -> f64, centre: f64, fallback: f64| {
        if poles.len() < 2 {
            return fallback;
        }
        (poles.iter().map(|p| (f(p) - centre).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
    };
    IdentifiedMode {
        frequency,
        frequency_sd: scatter(|p| p.0, frequency, lscf.frequency_sd),
        damping,
        damping_sd: scatter(|p| p.1, damping, lscf.damping_sd),
        ..lscf
    }
}

/// A merged mode's shape: each channel's summed residues over its runs averaged, normalised,
/// with its MPC, MPD and per-channel sd (relative to the largest component).
fn with_shape(
    mean: IdentifiedMode,
    shape: Vec<Complex>,
    spread: Vec<f64>,
    counts: &[usize],
) -> IdentifiedMode {
    let shape: Vec<Complex> = shape
        .iter()
        .zip(counts)
        .map(|(s, n)| *s / (*n).max(1) as f64)
        .collect();
    let largest = shape.iter().map(|v| v.norm()).fold(0.0, f64::max);
    let shape = normalised(shape);
    IdentifiedMode {
        mpc: mpc(&shape),
        mpd: mpd(&shape),
        shape_sd: spread
            .iter()
            .zip(counts)
            .map(|(s, n)| s / (*n).max(1) as f64 / largest.max(f64::MIN_POSITIVE))
            .collect(),
        shape,
        ..mean
    }
}

/// The modes of every run, grouped by frequency (ascending): a mode joins the group of the
/// next lower mode when it is within `tolerance` (relative) of the group's first mode and its
/// run has no mode in the group yet.
fn group_across_runs(per_run: &[RunModes], tolerance: f64) -> Vec<Group> {
    let mut all: Vec<(usize, usize, f64)> = per_run
        .iter()
        .enumerate()
        .flat_map(|(r, run)| {
            run.method
                .modes
                .iter()
                .enumerate()
                .map(move |(i, m)| (r, i, m.identified.frequency))
        })
        .collect();
    all.sort_by(|a, b| a.2.total_cmp(&b.2));
    let mut groups: Vec<Vec<(usize, usize, f64)>> = Vec::new();
    for (r, i, f) in all {
        match groups.last_mut() {
            Some(g) if (f / g[0].2 - 1.0).abs() <= tolerance && g.iter().all(|m| m.0 != r) => {
                g.push((r, i, f))
            }
            _ => groups.push(vec![(r, i, f)]),
        }
    }
    groups
        .into_iter()
        .map(|g| g.into_iter().map(|(r, i, _)| (r, i)).collect())
        .collect()
}

/// The group's mode: frequency and damping the means over its runs, each sd the larger of
/// their scatter over the runs and the runs' own mean sd; the orders of its largest cluster.
fn mean_pole(per_run: &[RunModes], group: &Group) -> IdentifiedMode {
    let members: Vec<&IdentifiedMode> = group
        .iter()
        .map(|(r, i)| &per_run[*r].method.modes[*i].identified)
        .collect();
    let n = members.len() as f64;
    let mean = |f: fn(&IdentifiedMode) -> f64| members.iter().map(|m| f(m)).sum::<f64>() / n;
    let scatter = |f: fn(&IdentifiedMode) -> f64, centre: f64| {
        if members.len() < 2 {
            return 0.0;
        }
        (members.iter().map(|m| (f(m) - centre).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
    };
    let frequency = mean(|m| m.frequency);
    let damping = mean(|m| m.damping);
    let largest = members
        .iter()
        .max_by_key(|m| m.orders.len())
        .map_or_else(Vec::new, |m| m.orders.clone());
    IdentifiedMode {
        frequency,
        frequency_sd: scatter(|m| m.frequency, frequency).max(mean(|m| m.frequency_sd)),
        damping,
        damping_sd: scatter(|m| m.damping, damping).max(mean(|m| m.damping_sd)),
        shape: Vec::new(),
        shape_sd: Vec::new(),
        mpc: 1.0,
        mpd: 0.0,
        orders: largest,
    }
}

/// The pole (rad/s, positive imaginary part) of a mode's frequency and damping.
fn eigenvalue(mode: &IdentifiedMode) -> Complex {
    pole(mode.frequency, mode.damping)
}

/// The pole (rad/s, positive imaginary part) of a frequency (Hz) and damping ratio.
pub(super) fn pole(frequency: f64, damping: f64) -> Complex {
    let w = 2.0 * std::f64::consts::PI * frequency;
    Complex::new(-damping * w, w * (1.0 - damping * damping).max(0.0).sqrt())
}
