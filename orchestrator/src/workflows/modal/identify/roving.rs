//! A roving test's modes, PoSER style with the measured force as the reference: each run's
//! modes are identified from its own FRF (LSCF, its own poles), the runs' modes are paired by
//! frequency, and each pair's pole is the mean of the runs'; each channel's shape component is
//! its run's LSFD residue at that run's own pole. The force is every run's common reference,
//! so the residues share one unit and phase and need no rescaling through a reference
//! accelerometer (PoSER's overlap step reduces to nothing), while each residue is read at the
//! pole its run's FRF holds. A joint fit of the FRFs of all runs (PreGER-like, what this
//! replaced) fails on short runs of lightly damped modes: 30 s runs put a 0.4 %-damped mode at slightly
//! different frequencies in different runs (±0.4 % in 0.12 Hz bins), one pole cannot sit on
//! all of them, and the residues it reads in the runs off its peak turn by up to 50°: the
//! lab frame's first mode had an MPC of 0.36 and was set aside.

use numerics::modal::lscf::{lscf, lsfd, LscfOptions};
use numerics::modal::spectral::Frf;
use numerics::modal::stabilisation::{
    normalised, screen_modes, IdentifiedMode, RejectedMode, Rejection, ScreenOptions,
};
use numerics::modal::{mpc, mpd, Complex};

use super::{fit_band, Estimation, IdentifyError, MethodModes, Peaks, DEFAULT_BAND_TOP};

/// One run's FRF, the band fitted and the modes found in it.
struct RunModes {
    frf: Frf,
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
            RejectedMode {
                mode: per_run[r].method.modes[i].identified.clone(),
                rejection: Rejection::FewRuns,
                reason: Rejection::FewRuns.reason().to_owned(),
            }
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
                let options = LscfOptions {
                    max_order: self.options.max_order,
                    weighting: self.options.weighting,
                    ..LscfOptions::over(band)
                };
                let orders = lscf(&frf, &options).map_err(self.sampling.method_err("LSCF"))?;
                let evidence = Peaks::of_frf(&frf);
                let method =
                    self.chosen_modes("LSCF", Some(band), orders, screen, &[], evidence)?;
                Ok(RunModes { frf, band, method })
            })
            .collect()
    }

    /// Per group, the mean pole of its runs and the shape at every channel: each run's LSFD
    /// residues at its own poles (the group's mean where it did not find the mode), the
    /// distance to its residues at the mean poles as the component's uncertainty.
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
        let zero = Complex::new(0.0, 0.0);
        let mut shapes = vec![vec![zero; channels]; groups.len()];
        let mut spread = vec![vec![0.0; channels]; groups.len()];
        let mut counts = vec![0usize; channels];
        let means: Vec<IdentifiedMode> = groups.iter().map(|g| mean_pole(per_run, g)).collect();
        let merged: Vec<Complex> = means.iter().map(eigenvalue).collect();
        for (r, run) in per_run.iter().enumerate() {
            let own: Vec<Complex> = groups
                .iter()
                .zip(&merged)
                .map(|(g, m)| {
                    g.iter()
                        .find(|(gr, _)| *gr == r)
                        .map_or(*m, |(_, i)| eigenvalue(&run.method.modes[*i].identified))
                })
                .collect();
            let lsfd_err = self.sampling.method_err("LSFD");
            let at_own = lsfd(&run.frf, run.band, &own).map_err(lsfd_err)?;
            let at_merged =
                lsfd(&run.frf, run.band, &merged).map_err(self.sampling.method_err("LSFD"))?;
            for (local, &global) in self.run_channels[r].iter().enumerate() {
                counts[global] += 1;
                for m in 0..groups.len() {
                    shapes[m][global] += at_own[m][local];
                    spread[m][global] += (at_own[m][local] - at_merged[m][local]).norm();
                }
            }
        }
        Ok(means
            .into_iter()
            .zip(shapes.into_iter().zip(spread))
            .map(|(mean, (shape, spread))| {
                let shape: Vec<Complex> = shape
                    .iter()
                    .zip(&counts)
                    .map(|(s, n)| *s / (*n).max(1) as f64)
                    .collect();
                let largest = shape.iter().map(|v| v.norm()).fold(0.0, f64::max);
                let shape = normalised(shape);
                IdentifiedMode {
                    mpc: mpc(&shape),
                    mpd: mpd(&shape),
                    shape_sd: spread
                        .iter()
                        .zip(&counts)
                        .map(|(s, n)| s / (*n).max(1) as f64 / largest.max(f64::MIN_POSITIVE))
                        .collect(),
                    shape,
                    ..mean
                }
            })
            .collect())
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
    let w = 2.0 * std::f64::consts::PI * mode.frequency;
    let z = mode.damping;
    Complex::new(-z * w, w * (1.0 - z * z).max(0.0).sqrt())
}
