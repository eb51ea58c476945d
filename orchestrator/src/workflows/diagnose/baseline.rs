//! Stage 1, set-up ([`super::diagnose`]'s first stage): the record and the options checked, the
//! record cut into fitted and held-out blocks, the twin as given and its physics alone run on the
//! record and scored, the residual localised and the record's modes identified, and the report
//! so far. The views the later stages read of it ([`Ground`], the selection's context, the
//! verdict's inputs).

use std::collections::BTreeMap;

use super::channels::Channels;
use super::fit::{climbs, Split};
use super::localise::{localise, missing_floor_force, missing_shear};
use super::physics::{prior_scales, run_physics, storeys_of, PhysicsReals, PhysicsRun};
use super::{
    check_sites, Action, Candidate, DiagnoseError, DiagnoseOptions, Diagnosis, LatentVariance,
    Localisation, Result, Scales, Series,
};
use crate::evaluation::compare::FailingWindow;
use crate::evaluation::stats::{first_after_transient, variance};
use crate::twin::data::Measurement;
use crate::twin::noise::NoiseVariances;
use crate::twin::run::{run_and_compare_with, Compared, Tolerance};
use crate::twin::Twin;
use crate::workflows::train::physics_only;

/// The diagnosis's first stage: the record checked against the twin, the twin as given and its
/// physics alone run on it, and the scores every later stage is measured against.
pub(super) struct Baseline {
    /// The record's samples: after the transient, fitted and held out.
    pub(super) samples: Samples,
    /// The building's storeys.
    pub(super) storeys: usize,
    /// The record's responses.
    pub(super) channels: Channels,
    /// How many.
    pub(super) nc: usize,
    /// The library's candidates, or the ones given.
    pub(super) candidates: Vec<Candidate>,
    /// The twin's physics alone.
    pub(super) physics: Twin,
    /// Its run on the record (accelerations, velocities, displacements, drifts).
    pub(super) base_run: PhysicsRun,
    /// The twin as given on the record.
    pub(super) scores: Scores,
    /// The physics' parameter values.
    pub(super) reals: PhysicsReals,
    /// Floor masses, floor 1 first.
    pub(super) mass: Vec<f64>,
    /// What the candidates' priors are scaled by.
    pub(super) scales: Scales,
    /// Whether the fits climb the ladder of the record's heads (see [`climbs`]).
    pub(super) climb: bool,
}

/// The record's samples and their split into fitted and held-out blocks.
pub(super) struct Samples {
    /// Samples in the record.
    pub(super) n: usize,
    /// The first sample after the transient.
    pub(super) first: usize,
    /// The fitted blocks' samples.
    pub(super) mask: Vec<bool>,
    /// The held-out blocks' samples.
    pub(super) held_out: Vec<usize>,
    /// Every sample after the transient.
    pub(super) after: Vec<usize>,
}

/// The twin as given on the record: its prediction, its NMSE per channel and what noise and
/// parameter uncertainty explain of it, and the practical bar.
pub(super) struct Scores {
    /// The twin's prediction per channel.
    pub(super) predicted: Vec<Vec<f64>>,
    /// NMSE per channel after the transient (%).
    pub(super) nmse_before: Vec<f64>,
    /// On the held-out samples.
    pub(super) nmse_before_held_out: Vec<f64>,
    /// The noise's share (%).
    pub(super) noise_nmse: Vec<f64>,
    /// On the held-out samples.
    pub(super) noise_nmse_held_out: Vec<f64>,
    /// The parameter uncertainty's share (%).
    pub(super) band_nmse: Vec<f64>,
    /// Noise and band together (%).
    pub(super) explained_nmse: Vec<f64>,
    /// The practical bar.
    pub(super) tolerance: Tolerance,
}

/// What the first report shows beside the scores.
pub(super) struct Shown {
    /// The comparison's failing windows.
    pub(super) failing_windows: Vec<FailingWindow>,
    /// The corrector's latent variance, when it has one.
    pub(super) latent_variance: Option<LatentVariance>,
    /// The storey shear the twin misses, per storey, and where it points.
    pub(super) missing_shear: Vec<Vec<f64>>,
    pub(super) localisation: Localisation,
    /// The record's modes beside the twin's, or why they could not be identified.
    pub(super) modes: Option<crate::workflows::modal::ModalEvidence>,
    pub(super) modes_error: Option<String>,
}

/// The first stage of [`diagnose`]: check the record and the options, run the twin and its
/// physics on the record, score them, locate the residual and identify the record's modes.
/// Also the report so far: the scores, the localisation and the modes, no verdict.
pub(super) fn baseline(
    twin: &Twin,
    data: &Measurement,
    options: &DiagnoseOptions,
) -> Result<(Baseline, Diagnosis)> {
    let noise = twin.noise_variance.clone().ok_or_else(|| {
        DiagnoseError::Setup(
            "the twin has no noise variances, so the noise level is unknown: diagnose a twin \
             made by `twin calibrate`"
                .into(),
        )
    })?;
    let samples = samples(data, options)?;
    let storeys = storeys_of(twin)?;
    let channels = Channels::of(data, storeys)?;
    let noise_variance = channel_noise(&noise, &channels, twin, data)?;
    let candidates = candidates_to_try(options, storeys)?;

    // 1. The twin as given, and its physics alone with drifts and velocities.
    let compared = compare_twin(twin, data, options)?;
    let physics = physics_only(twin);
    let base_run = run_physics(&physics, data, &BTreeMap::new(), &[], &[])?;
    let scores = Scores::of(&compared, &channels, &noise_variance, &samples);

    // Scales of the candidates' priors.
    let reals = PhysicsReals::of(&physics)?;
    let mass = (1..=storeys)
        .map(|f| reals.get(&format!("m{f}")))
        .collect::<Result<Vec<f64>>>()?;
    let scales = prior_scales(&reals, &base_run, data, samples.first)?;
    let mut baseline = Baseline {
        samples,
        storeys,
        nc: channels.len(),
        channels,
        candidates,
        physics,
        base_run,
        scores,
        reals,
        mass,
        scales,
        climb: false,
    };
    let shown = baseline.shown(twin, data, compared);
    baseline.climb = climbs(data.len(), &data.time, &shown.failing_windows);
    let diagnosis = baseline.report(twin, data, options, shown);
    Ok((baseline, diagnosis))
}

/// The record's samples under `options`: the block length checked, enough samples after the
/// transient, the fitted and held-out blocks.
pub(super) fn samples(data: &Measurement, options: &DiagnoseOptions) -> Result<Samples> {
    if !(options.block > 0.0 && options.block.is_finite()) {
        return Err(DiagnoseError::Setup(format!(
            "the block length must be a positive number of seconds, was {}",
            options.block
        )));
    }
    let n = data.len();
    let first = first_after_transient(&data.time, options.transient);
    if n - first < 20 {
        return Err(DiagnoseError::Setup(format!(
            "{}: {} samples after the {} s transient; a diagnosis needs more",
            data.path.display(),
            n - first,
            options.transient
        )));
    }
    let (mask, held_out) = blocks(&data.time, first, options.block);
    Ok(Samples {
        n,
        first,
        mask,
        held_out,
        after: (first..n).collect(),
    })
}

/// The fitted and held-out samples: after the transient, alternate blocks of `block` seconds.
pub fn blocks(time: &[f64], first: usize, block: f64) -> (Vec<bool>, Vec<usize>) {
    let mut mask = vec![false; time.len()];
    let mut held = Vec::new();
    let t0 = time.get(first).copied().unwrap_or(0.0);
    for k in first..time.len() {
        let b = ((time[k] - t0) / block).floor() as i64;
        if b % 2 == 0 {
            mask[k] = true;
        } else {
            held.push(k);
        }
    }
    (mask, held)
}

/// The twin's noise variance of each of the record's channels; Err names a channel it has none
/// for.
pub(super) fn channel_noise(
    noise: &NoiseVariances,
    channels: &Channels,
    twin: &Twin,
    data: &Measurement,
) -> Result<Vec<f64>> {
    channels
        .names
        .iter()
        .map(|name| {
            ::structure::channel::Channel::parse(name)
                .and_then(|c| noise.get(c))
                .ok_or_else(|| {
                    DiagnoseError::Setup(format!(
                        "{}: column '{name}': {} has no noise variance for it (calibrate the \
                         twin on a record that measures {name})",
                        data.path.display(),
                        twin.describe()
                    ))
                })
        })
        .collect()
}

/// The candidates given, checked against the building's `storeys`, else the whole library.
pub(super) fn candidates_to_try(
    options: &DiagnoseOptions,
    storeys: usize,
) -> Result<Vec<Candidate>> {
    Ok(match &options.candidates {
        Some(given) => {
            check_sites(given, storeys).map_err(DiagnoseError::Setup)?;
            given.clone()
        }
        None => Candidate::library(storeys),
    })
}

/// The twin as given run on the record and compared with it; its noise variances are known
/// here, so the comparison's band is theirs.
pub(super) fn compare_twin(
    twin: &Twin,
    data: &Measurement,
    options: &DiagnoseOptions,
) -> Result<Compared> {
    run_and_compare_with(twin, data, options.transient, options.tolerance, |_, _| {}).map_err(|e| {
        DiagnoseError::In {
            context: format!("running the twin on {}", data.path.display()),
            source: Box::new(e.into()),
        }
    })
}

impl Scores {
    /// The scores of the twin's comparison `compared` with the record, each channel's noise's
    /// share from its `noise_variance`.
    pub(super) fn of(
        compared: &Compared,
        channels: &Channels,
        noise_variance: &[f64],
        samples: &Samples,
    ) -> Scores {
        // The twin's results per channel: the comparison's are in the record's order, as
        // `channels` (Channels::of reads the record's responses in order).
        let predicted: Vec<Vec<f64>> = compared
            .prediction
            .channels
            .iter()
            .map(|c| c.values.clone())
            .collect();
        let noise_nmse_on = |idx: &[usize]| -> Vec<f64> {
            (0..channels.len())
                .map(|c| {
                    let y: Vec<f64> = idx.iter().map(|&k| channels.measured[c][k]).collect();
                    100.0 * noise_variance[c] / variance(&y)
                })
                .collect()
        };
        let noise_nmse = noise_nmse_on(&samples.after);
        let band_nmse = compared.band_nmse.clone();
        Scores {
            nmse_before: compared.comparison.nmse.clone(),
            nmse_before_held_out: channels.nmse_on(&predicted, &samples.held_out),
            noise_nmse_held_out: noise_nmse_on(&samples.held_out),
            explained_nmse: (0..channels.len())
                .map(|c| noise_nmse[c] + band_nmse[c])
                .collect(),
            predicted,
            noise_nmse,
            band_nmse,
            tolerance: compared.tolerance.clone(),
        }
    }
}

impl Baseline {
    /// What the first report shows beside the scores: the comparison's failing windows and
    /// the corrector's latent variance (of the twin's comparison `compared`), the missing storey
    /// shear localised from the twin's residual, the record's modes beside the twin's.
    pub(super) fn shown(&self, twin: &Twin, data: &Measurement, compared: Compared) -> Shown {
        let Samples { n, first, .. } = self.samples;
        let latent_variance = compared
            .prediction
            .channels
            .iter()
            .map(|c| c.latent_var.as_ref())
            .collect::<Option<Vec<&Vec<f64>>>>()
            .map(|v| LatentVariance {
                max: v
                    .iter()
                    .map(|v| v[first..].iter().copied().fold(0.0, f64::max))
                    .collect(),
                mean: v
                    .iter()
                    .map(|v| v[first..].iter().sum::<f64>() / (n - first) as f64)
                    .collect(),
            });
        // Localisation from the residual of the twin as given.
        let floor_force = missing_floor_force(
            &self.channels,
            &self.mass,
            &self.scores.predicted,
            self.storeys,
            data.dt,
        );
        let missing_shear = missing_shear(&floor_force);
        let localisation = localise(&missing_shear, &floor_force, &self.base_run, first);
        // The record's modes beside the twin's: shown with the verdict, and a `none` says so
        // when they moved beyond the twin's band. Without LSCF's sweep past its orders, which
        // finds a tall tower's top modes for `twin modal` and `compare --modes` at 2–8 s for
        // ten channels: a 10-storey diagnosis 9.8–10.8 → 6.4 s, its evidence 2 of the 10 modes
        // (8 with the sweep).
        let sweep = crate::workflows::modal::IdentifyOptions {
            extend_orders: false,
            ..Default::default()
        };
        let (modes, modes_error) = match crate::workflows::modal::modal_evidence_with(
            twin,
            data,
            crate::workflows::modal::ModalBand::default(),
            &sweep,
        ) {
            Ok(e) => (Some(e), None),
            Err(e) => (None, Some(e.to_string())),
        };
        Shown {
            failing_windows: compared.comparison.failing_windows,
            latent_variance,
            missing_shear,
            localisation,
            modes,
            modes_error,
        }
    }

    /// The report before any verdict: the record, the twin's scores and what `shown` has; the
    /// twin's prediction stands as the prediction after.
    pub(super) fn report(
        &self,
        twin: &Twin,
        data: &Measurement,
        options: &DiagnoseOptions,
        shown: Shown,
    ) -> Diagnosis {
        let s = &self.scores;
        Diagnosis {
            record: data.path.display().to_string(),
            changed_at: None,
            channels: self.channels.names.clone(),
            twin: twin
                .source
                .as_ref()
                .map(|p| p.display().to_string())
                .unwrap_or_else(|| "(default twin)".into()),
            nmse_before: s.nmse_before.clone(),
            noise_nmse: s.noise_nmse.clone(),
            band_nmse: s.band_nmse.clone(),
            explained_nmse: s.explained_nmse.clone(),
            tolerance: s.tolerance.value,
            tolerance_source: s.tolerance.source.clone(),
            statistically_significant: false,
            practically_significant: false,
            nmse_before_held_out: s.nmse_before_held_out.clone(),
            noise_nmse_held_out: s.noise_nmse_held_out.clone(),
            failing_windows: shown.failing_windows,
            latent_variance: shown.latent_variance,
            action: Action::None,
            reason: String::new(),
            effect: None,
            effects: Vec::new(),
            physics_moved: Vec::new(),
            selection: Vec::new(),
            discovery: None,
            sensor: None,
            sensor_candidates: Vec::new(),
            nmse_after: s.nmse_before.clone(),
            recalibration: None,
            candidates: Vec::new(),
            failed_candidates: Vec::new(),
            screened_out: Vec::new(),
            race_head: None,
            raced_out: Vec::new(),
            localisation: shown.localisation,
            sensing: self.channels.sensing(),
            modes: shown.modes,
            modes_error: shown.modes_error,
            gates: options.gates,
            block_seconds: options.block,
            seconds: 0.0,
            series: Series {
                time: data.time.clone(),
                first: self.samples.first,
                floors: self.channels.floors.iter().map(|f| f + 1).collect(),
                measured: self.channels.measured.clone(),
                before: s.predicted.clone(),
                after: s.predicted.clone(),
                drift: self.base_run.drift.clone(),
                missing_shear: shown.missing_shear,
                effect_force: None,
                evidence_axis: None,
            },
        }
    }
}

/// The views the stages after the baseline read of it.
impl Baseline {
    /// What round 1's stages share, on `data` under `options`.
    /// The record's fitted and held-out samples as the fits take them.
    pub(super) fn split(&self) -> Split<'_> {
        Split {
            mask: &self.samples.mask,
            held_out: &self.samples.held_out,
            first: self.samples.first,
            climb: self.climb,
        }
    }

    pub(super) fn ground<'a>(
        &'a self,
        data: &'a Measurement,
        options: &'a DiagnoseOptions,
    ) -> Ground<'a> {
        Ground {
            data,
            options,
            physics: &self.physics,
            storeys: self.storeys,
            split: self.split(),
            channels: &self.channels,
            reals: &self.reals,
            scales: &self.scales,
            base_run: &self.base_run,
        }
    }
}

/// What the stages after the baseline share: the record and its split into fitted and
/// held-out blocks, the structure, and the twin's physics with its run on the record.
#[derive(Clone, Copy)]
pub(super) struct Ground<'a> {
    pub(super) data: &'a Measurement,
    pub(super) options: &'a DiagnoseOptions,
    pub(super) physics: &'a Twin,
    pub(super) storeys: usize,
    pub(super) split: Split<'a>,
    pub(super) channels: &'a Channels,
    pub(super) reals: &'a PhysicsReals,
    pub(super) scales: &'a Scales,
    pub(super) base_run: &'a PhysicsRun,
}
