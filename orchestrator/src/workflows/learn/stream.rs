//! Stage 1, the streams: each record's physics-only run and the corrector's inputs and targets
//! on it ([`prepare`]), the corrected prediction from the GPs' means, and the GPs' tracked
//! points kept in step with their training sets.

use super::{LearnError, LearnOptions, Result};
use crate::evaluation::compare::nmse;
use crate::twin::data::Measurement;
use crate::twin::run::run_twin;
use crate::twin::Twin;
use crate::workflows::train::{physics_only, Channels};
use fmu_gp_corrector::model::{per_channel, GaussianProcess, Inputs, TrackedPoints, Tracking};
use fmu_gp_corrector::{lagged_inputs, FloorGp, Floors, Layout, TargetForm};

/// One record, ready to stream: the corrector's layout (the record's channels and
/// excitation), the whole lag vector and the targets (one per channel) at every sample, physics
/// and measured values per channel (SI, the layout's order), and the first sample after the
/// transient.
#[derive(Clone, Debug)]
pub struct Stream {
    pub name: String,
    pub layout: Layout,
    pub time: Vec<f64>,
    pub inputs: Vec<Vec<f64>>,
    pub targets: Vec<Vec<f64>>,
    pub physics: Vec<Vec<f64>>,
    pub measured: Vec<Vec<f64>>,
    pub first: usize,
}

impl Stream {
    pub fn len(&self) -> usize {
        self.time.len()
    }

    pub fn is_empty(&self) -> bool {
        self.time.is_empty()
    }

    /// NMSE per channel after the transient of a prediction over the whole record.
    pub fn nmse(&self, predicted: &[Vec<f64>]) -> Vec<f64> {
        (0..self.measured.len())
            .map(|f| nmse(&self.measured[f][self.first..], &predicted[f][self.first..]))
            .collect()
    }

    /// Channel `f`'s GP inputs at samples `range` (its columns of the whole lag vectors).
    pub(super) fn channel_inputs(
        &self,
        floors: &Floors,
        f: usize,
        range: std::ops::Range<usize>,
    ) -> Vec<Vec<f64>> {
        self.inputs[range]
            .iter()
            .map(|x| floors.input_of(f, x))
            .collect()
    }
}

/// Run the physics-only twin on every record (FMI) and build the GP's inputs and targets.
pub fn prepare(
    twin: &Twin,
    records: &[Measurement],
    options: &LearnOptions,
) -> Result<Vec<Stream>> {
    let physics = physics_only(twin);
    records
        .iter()
        .map(|data| {
            let prediction =
                run_twin(&physics, data, |_, _| {}).map_err(|source| LearnError::Physics {
                    record: data.path.display().to_string(),
                    source: Box::new(source),
                })?;
            let channels =
                Channels::of(data, &prediction).map_err(|e| LearnError::Setup(e.to_string()))?;
            let first =
                crate::evaluation::stats::first_after_transient(&data.time, options.transient)
                    .max(options.lags);
            if first >= data.len() {
                return Err(LearnError::Setup(format!(
                    "{}: nothing left after the {} s transient",
                    data.path.display(),
                    options.transient
                )));
            }
            Ok(Stream {
                name: data.path.display().to_string(),
                time: data.time.clone(),
                inputs: lagged_inputs(&channels.samples, options.lags),
                targets: (0..data.len())
                    .map(|k| channels.targets(k, options.target))
                    .collect(),
                layout: channels.layout,
                physics: channels.physics,
                measured: channels.measured,
                first,
            })
        })
        .collect::<Result<Vec<Stream>>>()
        .and_then(|streams| {
            // One corrector learns over all records: they measure the same channels.
            if let Some(first) = streams.first() {
                if let Some(other) = streams.iter().find(|s| s.layout != first.layout) {
                    return Err(LearnError::Setup(format!(
                        "{} measures {} under {}, but {} measures {} under {}: one corrector \
                         learns over records of the same channels",
                        other.name,
                        other.layout.names().join(", "),
                        other.layout.excitation_name(),
                        first.name,
                        first.layout.names().join(", "),
                        first.layout.excitation_name()
                    )));
                }
            }
            Ok(streams)
        })
}

/// The corrected prediction over a whole record from the GP means at the record's points
/// from `stream.first` on (`means[f][k − first]`); the physics alone before.
pub(super) fn corrected_from_means(
    stream: &Stream,
    tracked: &[TrackedPoints],
    target: TargetForm,
) -> Vec<Vec<f64>> {
    tracked
        .iter()
        .enumerate()
        .map(|(f, t)| {
            let mut out = stream.physics[f].clone();
            for (k, mean) in (stream.first..stream.len()).zip(t.means()) {
                out[k] = target.corrected(stream.physics[f][k], *mean);
            }
            out
        })
        .collect()
}

/// The corrected prediction over a whole record with the GPs' means (`E f(x) = k(x)ᵀ α`).
pub fn corrected(floors: &Floors, stream: &Stream, target: TargetForm) -> Result<Vec<Vec<f64>>> {
    let tracked = track(floors, stream)?;
    Ok(corrected_from_means(stream, &tracked, target))
}

pub(super) fn trained(gp: &FloorGp) -> Result<&GaussianProcess> {
    match gp {
        FloorGp::Trained(gp) => Ok(gp),
        FloorGp::Prior(_) => Err(LearnError::Setup(
            "a floor's GP has no training point".into(),
        )),
    }
}

/// Each channel's latent variances and means at the record's points from `first` on.
pub(super) fn track(floors: &Floors, stream: &Stream) -> Result<Vec<TrackedPoints>> {
    per_channel(floors.gps.len(), |f| -> Result<TrackedPoints> {
        let points =
            Inputs::from_rows(&stream.channel_inputs(floors, f, stream.first..stream.len()))
                .map_err(|e| LearnError::Gp(format!("{}: GP inputs: {e}", stream.name)))?;
        TrackedPoints::new(trained(&floors.gps[f])?, points)
            .map_err(|e| LearnError::Gp(format!("{}: {e}", floors.who(f))))
    })
    .into_iter()
    .collect()
}

/// From this many (training points × tracked points) on, the floors' tracked values are
/// brought up to date in parallel threads (`O(n m)` each, about 0.5 ms at this size, against
/// tens of µs to start two threads).
pub(super) const PARALLEL_TRACKING: usize = 1 << 20;

/// Brings the channels' tracked values to the current GPs, in parallel threads if asked;
/// returns how many were solved again.
pub(super) fn sync(
    tracked: &mut [TrackedPoints],
    floors: &Floors,
    parallel: bool,
) -> Result<usize> {
    let gps = floors
        .gps
        .iter()
        .map(trained)
        .collect::<Result<Vec<&GaussianProcess>>>()?;
    let outcome = |t: &mut TrackedPoints, gp: &GaussianProcess| {
        t.sync(gp)
            .map_err(|e| LearnError::Gp(format!("tracking the GP: {e}")))
    };
    let results: Vec<Result<Tracking>> = if parallel {
        std::thread::scope(|scope| {
            let handles: Vec<_> = tracked
                .iter_mut()
                .zip(&gps)
                .map(|(t, gp)| scope.spawn(move || outcome(t, gp)))
                .collect();
            handles
                .into_iter()
                .map(|h| match h.join() {
                    Ok(r) => r,
                    Err(payload) => std::panic::resume_unwind(payload),
                })
                .collect()
        })
    } else {
        tracked
            .iter_mut()
            .zip(&gps)
            .map(|(t, gp)| outcome(t, gp))
            .collect()
    };
    let mut rebuilt = 0;
    for r in results {
        if r? == Tracking::Rebuilt {
            rebuilt += 1;
        }
    }
    Ok(rebuilt)
}
