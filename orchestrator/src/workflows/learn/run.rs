//! One mode's run over the streams (Algorithm 1): per record, every streamed sample judged by
//! the supervisor, a query appended to the GPs, the threshold updated and the GPs refitted on
//! schedule; the training set carried to the next record.

use super::refit::{refit_floors, RefitSchedule};
use super::results::FixedThreshold;
use super::results::{
    change_flags, channel_labels, ModeResult, NmsePoint, RecordResult, RefitRecord, Timing, Trace,
};
use super::stream::{
    corrected, corrected_from_means, sync, track, trained, Stream, PARALLEL_TRACKING,
};
use super::{LearnError, LearnOptions, Result};
use crate::blocks::supervisor::{Mode, Supervisor};
use crate::cosim::master::Block;
use fmu_gp_corrector::model::{Inputs, TrackedPoints};
use fmu_gp_corrector::training::MAX_TRAINING_POINTS;
use fmu_gp_corrector::{Floors, TargetForm};

/// Algorithm 1 over all records in one mode, from the initial GPs.
/// One mode over the records from the initial GPs; `fixed` is the fixed mode's threshold (see
/// [`fixed_threshold`]; needed by the fixed mode only).
pub fn run_mode(
    streams: &[Stream],
    initial: &Floors,
    mode: Mode,
    fixed: Option<&FixedThreshold>,
    options: &LearnOptions,
) -> Result<ModeResult> {
    let started = std::time::Instant::now();
    let mut run = ModeRun::start(streams, initial, mode, fixed, options)?;
    let mut records = Vec::new();
    let mut total = 0;
    for (r, stream) in streams.iter().enumerate() {
        let record = run.record(r, stream)?;
        total += record.queries;
        records.push(record);
    }
    run.finish(started, fixed, total, records)
}

/// The adaptive threshold's reference set (Algorithm 1, line 12): every point streamed so far,
/// the initial ones included, that is not in the training set (see the module doc). The
/// current record's points are tracked whole (its means give the NMSE); the points of earlier
/// records outside the training set, and those the size limit drops later, are tracked apart.
pub(super) struct Reference {
    /// The training set's points in the order the GPs hold them: (record, tracked index).
    pub(super) members: std::collections::VecDeque<(usize, usize)>,
    /// Per record, per tracked index: whether the point is in the training set.
    pub(super) inside: Vec<Vec<bool>>,
    /// Earlier records' points outside the training set, per channel.
    pub(super) earlier: Vec<TrackedPoints>,
}

impl Reference {
    pub(super) fn new(floors: &Floors, streams: &[Stream]) -> Result<Self> {
        let earlier = (0..floors.gps.len())
            .map(|f| {
                let dim = floors.columns[f].len() * (floors.lags + 1);
                let none = Inputs::from_row_major(dim, Vec::new())
                    .map_err(|e| LearnError::Gp(format!("GP inputs: {e}")))?;
                trained(&floors.gps[f]).and_then(|gp| {
                    TrackedPoints::new(gp, none).map_err(|e| LearnError::Gp(format!("{e}")))
                })
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Reference {
            members: Default::default(),
            inside: streams
                .iter()
                .map(|s| vec![false; s.len() - s.first])
                .collect(),
            earlier,
        })
    }

    /// Point `j` of record `r` joined the training set; `dropped`: the oldest one left it.
    pub(super) fn learned(
        &mut self,
        r: usize,
        j: usize,
        dropped: bool,
        current: usize,
    ) -> Option<(usize, usize)> {
        self.members.push_back((r, j));
        self.inside[r][j] = true;
        if !dropped {
            return None;
        }
        let (r0, j0) = self.members.pop_front()?;
        self.inside[r0][j0] = false;
        // An earlier record's point: now tracked apart (a current one is tracked already).
        (r0 < current).then_some((r0, j0))
    }

    /// The largest latent variance per channel over the reference set: the current record's
    /// points up to `j` outside the training set, and the earlier ones; `None` while empty.
    pub(super) fn max(&self, tracked: &[TrackedPoints], r: usize, j: usize) -> Vec<Option<f64>> {
        (0..tracked.len())
            .map(|f| {
                let current = (0..=j)
                    .filter(|&i| !self.inside[r][i])
                    .map(|i| tracked[f].latent_variance(i));
                let earlier =
                    (0..self.earlier[f].len()).map(|i| self.earlier[f].latent_variance(i));
                current.chain(earlier).reduce(f64::max)
            })
            .collect()
    }
}

/// One mode's run over the records: the GPs and what is kept up to date with them (the tracked
/// points, the reference set, the supervisor, the refit schedule), the refits made and where
/// the time went.
pub(super) struct ModeRun<'a> {
    pub(super) streams: &'a [Stream],
    pub(super) options: &'a LearnOptions,
    pub(super) mode: Mode,
    pub(super) adaptive: bool,
    /// Channels, one GP each.
    pub(super) m: usize,
    /// The first record's first streamed sample (after the initial set).
    pub(super) initial_end: usize,
    pub(super) floors: Floors,
    /// The current record's tracked points.
    pub(super) tracked: Vec<TrackedPoints>,
    pub(super) reference: Reference,
    pub(super) initial_threshold: Vec<f64>,
    pub(super) supervisor: Supervisor,
    pub(super) schedule: RefitSchedule,
    pub(super) timing: Timing,
    pub(super) refits: Vec<RefitRecord>,
}

/// What one record gathers as it is streamed: its first streamed sample, its scores before
/// any query, its queries, the NMSE after updates and the trace.
pub(super) struct RecordProgress {
    pub(super) start: usize,
    pub(super) nmse_physics: Vec<f64>,
    pub(super) nmse_before: Vec<f64>,
    /// Queried samples.
    pub(super) query_indices: Vec<usize>,
    pub(super) nmse_after: Vec<NmsePoint>,
    pub(super) trace: Trace,
    /// The supervisor's outputs: the learn flag, then a threshold per channel.
    pub(super) outputs: Vec<f64>,
}

/// The corrected prediction's NMSE over a whole record from the tracked means.
pub(super) fn nmse_now(stream: &Stream, tracked: &[TrackedPoints], target: TargetForm) -> Vec<f64> {
    stream.nmse(&corrected_from_means(stream, tracked, target))
}

/// The mode's threshold before the stream: the fixed mode's own, the largest latent variance
/// over the `initial` points that follow the initial set (adaptive), or none (uniform).
pub(super) fn initial_threshold(
    mode: Mode,
    fixed: Option<&FixedThreshold>,
    tracked: &[TrackedPoints],
    first: &Stream,
    initial_end: usize,
    options: &LearnOptions,
) -> Result<Vec<f64>> {
    let m = tracked.len();
    Ok(match mode {
        Mode::Fixed => match fixed {
            Some(fixed) => fixed.values.clone(),
            None => {
                return Err(LearnError::Setup(
                    "the fixed mode needs its threshold".into(),
                ))
            }
        },
        Mode::Adaptive(_) => {
            // Held out: the initial points themselves are interpolated (V(f) ≈ 0 there).
            let held_out = (initial_end - first.first)
                ..(initial_end + options.initial).min(first.len()) - first.first;
            (0..m)
                .map(|f| {
                    held_out
                        .clone()
                        .map(|j| tracked[f].latent_variance(j))
                        .fold(0.0, f64::max)
                })
                .collect()
        }
        Mode::Uniform => vec![f64::INFINITY; m],
    })
}

impl<'a> ModeRun<'a> {
    /// The initial GPs tracked on the first record, with the initial set in the training set,
    /// and the supervisor from the mode's initial threshold.
    pub(super) fn start(
        streams: &'a [Stream],
        initial: &Floors,
        mode: Mode,
        fixed: Option<&FixedThreshold>,
        options: &'a LearnOptions,
    ) -> Result<Self> {
        let Some(first) = streams.first() else {
            return Err(LearnError::Setup("no record to learn from".into()));
        };
        let floors = initial.clone();
        let m = floors.gps.len();
        let mut timing = Timing::default();
        let schedule = RefitSchedule::new(options, floors.len());
        let initial_end = first.first + options.initial;
        let clock = std::time::Instant::now();
        let tracked = track(&floors, first)?;
        let adaptive = matches!(mode, Mode::Adaptive(_));
        let mut reference = Reference::new(&floors, streams)?;
        for j in 0..options.initial {
            reference.learned(0, j, false, 0);
        }
        timing.tracking_setup += clock.elapsed().as_secs_f64();
        timing.rebuilds += m;
        let initial_threshold =
            initial_threshold(mode, fixed, &tracked, first, initial_end, options)?;
        let supervisor = Supervisor::new(mode, initial_threshold.clone(), options.uniform_every);
        Ok(ModeRun {
            streams,
            options,
            mode,
            adaptive,
            m,
            initial_end,
            floors,
            tracked,
            reference,
            initial_threshold,
            supervisor,
            schedule,
            timing,
            refits: Vec::new(),
        })
    }

    /// Record `r` streamed sample by sample (a decision at each, a query where it says so),
    /// then its end-of-record refit, its points outside the training set carried to the
    /// reference set, and its result.
    pub(super) fn record(&mut self, r: usize, stream: &Stream) -> Result<RecordResult> {
        let mut progress = self.begin_record(r, stream)?;
        for t in progress.start..stream.len() {
            if !self.passes(stream, t, &mut progress)? {
                self.query(r, stream, t, &mut progress)?;
            }
        }
        if self.options.refit_every > 0 && self.schedule.since > 0 {
            self.end_of_record_refit(r, stream, progress.query_indices.len())?;
        }
        if self.adaptive && r + 1 < self.streams.len() {
            self.carry_outside(r, stream)?;
        }
        Ok(self.record_result(stream, progress))
    }

    /// The supervisor told a new record starts, the record tracked (the first one is already),
    /// and its scores before any query in it.
    pub(super) fn begin_record(&mut self, r: usize, stream: &Stream) -> Result<RecordProgress> {
        self.supervisor.start_record();
        // Tracked index j is sample stream.first + j.
        let start = if r == 0 {
            self.initial_end
        } else {
            stream.first
        };
        if r > 0 {
            let clock = std::time::Instant::now();
            self.tracked = track(&self.floors, stream)?;
            self.timing.rebuilds += self.m;
            self.timing.tracking_setup += clock.elapsed().as_secs_f64();
        }
        let nmse_physics = stream.nmse(&stream.physics);
        let nmse_before = nmse_now(stream, &self.tracked, self.options.target);
        let nmse_after = vec![NmsePoint {
            update: 0,
            time: stream.time[start.min(stream.len() - 1)],
            nmse: nmse_before.clone(),
        }];
        Ok(RecordProgress {
            start,
            nmse_physics,
            nmse_before,
            query_indices: Vec::new(),
            nmse_after,
            trace: Trace {
                channels: stream.layout.names(),
                latent: vec![Vec::new(); self.m],
                threshold: vec![Vec::new(); self.m],
                ..Trace::default()
            },
            outputs: vec![0.0; self.m + 1],
        })
    }

    /// The supervisor's decision at sample `t` from the latent variances there, traced; whether
    /// the point passes without a query.
    pub(super) fn passes(
        &mut self,
        stream: &Stream,
        t: usize,
        progress: &mut RecordProgress,
    ) -> Result<bool> {
        let (j, m) = (t - stream.first, self.m);
        let latent: Vec<f64> = (0..m).map(|f| self.tracked[f].latent_variance(j)).collect();
        self.supervisor
            .evaluate(stream.time[t], &latent, &mut progress.outputs)?;
        let trace = &mut progress.trace;
        trace.time.push(stream.time[t]);
        for (f, &v) in latent.iter().enumerate() {
            trace.latent[f].push(v);
            trace.threshold[f].push(progress.outputs[1 + f]);
        }
        Ok(progress.outputs[0] < 0.5)
    }

    /// A query at sample `t`: the point learned on every channel and a refit on the schedule,
    /// the tracked values brought up to date, the adaptive threshold updated and the NMSE
    /// scored every `nmse_every` queries.
    pub(super) fn query(
        &mut self,
        r: usize,
        stream: &Stream,
        t: usize,
        progress: &mut RecordProgress,
    ) -> Result<()> {
        let j = t - stream.first;
        let clock = std::time::Instant::now();
        let before = self.floors.len();
        self.floors
            .learn(
                &stream.inputs[t],
                &stream.targets[t],
                0,
                MAX_TRAINING_POINTS,
            )
            .map_err(|e| LearnError::Gp(format!("t = {} s: {e}", stream.time[t])))?;
        progress.query_indices.push(t);
        let dropped = self.reference.learned(r, j, self.floors.len() == before, r);
        self.timing.learning += clock.elapsed().as_secs_f64();
        let refit_due = self.schedule.query();
        if refit_due {
            let queries = progress.query_indices.len();
            let refit = refit_floors(&mut self.floors, self.options, r, queries, false)
                .map_err(|e| LearnError::Gp(format!("t = {} s: {e}", stream.time[t])))?;
            self.refitted(refit);
        }
        self.sync_after_query(refit_due, dropped)?;
        if self.adaptive {
            self.update_threshold(r, j);
        }
        let (queries, options) = (progress.query_indices.len(), self.options);
        if queries % options.nmse_every.max(1) == 0 {
            progress.nmse_after.push(NmsePoint {
                update: queries,
                time: stream.time[t],
                nmse: nmse_now(stream, &self.tracked, self.options.target),
            });
        }
        Ok(())
    }

    /// A refit recorded, and the schedule restarted from it.
    pub(super) fn refitted(&mut self, refit: RefitRecord) {
        self.schedule.refitted(self.floors.len());
        self.timing.refits += refit.seconds;
        self.refits.push(refit);
    }

    /// The tracked points and (adaptive) the reference set's earlier points brought to the GPs
    /// after a query; `dropped`, an earlier record's point the size limit took out of the
    /// training set, is tracked apart from now on.
    pub(super) fn sync_after_query(
        &mut self,
        refit_due: bool,
        dropped: Option<(usize, usize)>,
    ) -> Result<()> {
        let clock = std::time::Instant::now();
        // Parallel floors when the work outweighs starting two threads.
        let parallel = refit_due || self.floors.len() * self.tracked[0].len() >= PARALLEL_TRACKING;
        self.timing.rebuilds += sync(&mut self.tracked, &self.floors, parallel)?;
        if self.adaptive {
            let parallel = refit_due
                || self.floors.len() * self.reference.earlier[0].len() >= PARALLEL_TRACKING;
            self.timing.rebuilds += sync(&mut self.reference.earlier, &self.floors, parallel)?;
            if let Some((r0, j0)) = dropped {
                for f in 0..self.m {
                    let at = self.streams[r0].first + j0;
                    let x = Inputs::from_rows(&self.streams[r0].channel_inputs(
                        &self.floors,
                        f,
                        at..at + 1,
                    ))
                    .map_err(|e| LearnError::Gp(format!("GP inputs: {e}")))?;
                    self.reference.earlier[f]
                        .extend(trained(&self.floors.gps[f])?, &x)
                        .map_err(|e| LearnError::Gp(format!("tracking the GP: {e}")))?;
                }
            }
        }
        self.timing.tracking += clock.elapsed().as_secs_f64();
        Ok(())
    }

    /// Line 12: the largest latent variance, under the updated GPs, over the reference set
    /// (record `r`'s points up to tracked index `j`, and the earlier ones); an empty one leaves
    /// the threshold as it is.
    pub(super) fn update_threshold(&mut self, r: usize, j: usize) {
        let old = self.supervisor.threshold();
        let max = self.reference.max(&self.tracked, r, j);
        self.supervisor.update_threshold(
            (0..self.m)
                .map(|f| max[f].unwrap_or(old[f]))
                .collect::<Vec<_>>(),
        );
    }

    /// The record's final GPs get hyperparameters fitted to all that was learned in it
    /// (Algorithm 1 refits after every query; the schedule thins that out, and the end of a
    /// record is where its final NMSE and the carried-over GPs are taken).
    pub(super) fn end_of_record_refit(
        &mut self,
        r: usize,
        stream: &Stream,
        queries: usize,
    ) -> Result<()> {
        let refit = refit_floors(&mut self.floors, self.options, r, queries, true)
            .map_err(|e| LearnError::Gp(format!("{}: end of record: {e}", stream.name)))?;
        self.refitted(refit);
        let clock = std::time::Instant::now();
        self.timing.rebuilds += sync(&mut self.tracked, &self.floors, true)?;
        if self.adaptive {
            self.timing.rebuilds += sync(&mut self.reference.earlier, &self.floors, true)?;
            self.update_threshold(r, stream.len() - 1 - stream.first);
        }
        self.timing.tracking += clock.elapsed().as_secs_f64();
        Ok(())
    }

    /// Record `r`'s points outside the training set join the earlier ones in the reference set.
    pub(super) fn carry_outside(&mut self, r: usize, stream: &Stream) -> Result<()> {
        let seen_from = stream.first;
        let clock = std::time::Instant::now();
        let outside: Vec<usize> = (0..stream.len() - seen_from)
            .filter(|&i| !self.reference.inside[r][i])
            .collect();
        if !outside.is_empty() {
            for f in 0..self.m {
                let rows: Vec<Vec<f64>> = outside
                    .iter()
                    .map(|&i| self.floors.input_of(f, &stream.inputs[seen_from + i]))
                    .collect();
                let x = Inputs::from_rows(&rows)
                    .map_err(|e| LearnError::Gp(format!("GP inputs: {e}")))?;
                self.reference.earlier[f]
                    .extend(trained(&self.floors.gps[f])?, &x)
                    .map_err(|e| LearnError::Gp(format!("tracking the GP: {e}")))?;
            }
        }
        self.timing.tracking_setup += clock.elapsed().as_secs_f64();
        Ok(())
    }

    /// The record's result: the corrected prediction and NMSE of its final GPs (the last NMSE
    /// point), its queries and the runs of them that suggest a change.
    pub(super) fn record_result(&self, stream: &Stream, progress: RecordProgress) -> RecordResult {
        let RecordProgress {
            start,
            nmse_physics,
            nmse_before,
            query_indices,
            mut nmse_after,
            mut trace,
            ..
        } = progress;
        let final_prediction = corrected_from_means(stream, &self.tracked, self.options.target);
        let final_nmse = stream.nmse(&final_prediction);
        // The last point is the record's final GPs (after an end-of-record refit).
        match nmse_after.last_mut() {
            Some(last) if last.update == query_indices.len() => last.nmse = final_nmse.clone(),
            _ => nmse_after.push(NmsePoint {
                update: query_indices.len(),
                time: query_indices
                    .last()
                    .map(|&t| stream.time[t])
                    .unwrap_or(stream.time[start.min(stream.len() - 1)]),
                nmse: final_nmse.clone(),
            }),
        }
        trace.corrected = final_prediction;
        trace.measured = stream.measured.clone();
        RecordResult {
            record: stream.name.clone(),
            queries: query_indices.len(),
            query_times: query_indices.iter().map(|&t| stream.time[t]).collect(),
            nmse_physics,
            nmse_before,
            nmse_after_updates: nmse_after,
            final_nmse,
            training_points_at_end: self.floors.len(),
            structure_may_have_changed: change_flags(
                &query_indices,
                &stream.time,
                self.options.change_run,
            ),
            threshold_at_end: self.supervisor.threshold(),
            trace,
        }
    }

    /// The mode's result: its records, refits and time split, and the final GPs scored on every
    /// record.
    pub(super) fn finish(
        self,
        started: std::time::Instant,
        fixed: Option<&FixedThreshold>,
        total: usize,
        records: Vec<RecordResult>,
    ) -> Result<ModeResult> {
        let ModeRun {
            streams,
            options,
            mode,
            floors,
            initial_threshold,
            mut timing,
            refits,
            ..
        } = self;
        let seconds = started.elapsed().as_secs_f64();
        timing.other =
            seconds - timing.tracking_setup - timing.learning - timing.refits - timing.tracking;
        let channel_labels = channel_labels(records.first().map_or(&[][..], |r| &r.trace.channels));
        Ok(ModeResult {
            mode: mode.name(),
            forgetting_factor: match mode {
                Mode::Adaptive(f) => Some(f),
                _ => None,
            },
            initial_threshold,
            fixed_threshold: fixed.filter(|_| mode == Mode::Fixed).cloned(),
            total_queries: total,
            records,
            refits,
            timing,
            seconds,
            initial_fit_seconds: 0.0,
            final_gps_nmse: streams
                .iter()
                .map(|stream| Ok(stream.nmse(&corrected(&floors, stream, options.target)?)))
                .collect::<Result<_>>()?,
            final_gps: floors,
            channel_labels,
        })
    }
}
