//! The runs as identification takes them: checked against each other (one test, or a roving
//! one), their channels joined, their sampling and Welch segment, their signals.

use structure::channel::Channel;

use super::{IdentifyError, IdentifyOptions, DEFAULT_SEGMENTS};
use crate::record::Signal;
use numerics::modal::spectral::{Run, MIN_SEGMENT};
use numerics::modal::IdentificationError;

/// A run as identification sees it: its responses, and its excitation when it was measured.
pub(super) struct RunView<'a> {
    pub(super) path: &'a std::path::Path,
    pub(super) dt: f64,
    pub(super) excitation: Option<&'a Signal>,
    pub(super) responses: &'a [Signal],
}

impl RunView<'_> {
    pub(super) fn len(&self) -> usize {
        self.responses.first().map_or(0, |s| s.values.len())
    }

    pub(super) fn channel_names(&self) -> Vec<String> {
        self.responses.iter().map(|s| s.channel.name()).collect()
    }
}

/// Every run has the first's sampling interval, and its response channels in its order and
/// an excitation if the first has one — or, a roving test, every run has a measured
/// excitation (the same channel) and its own response channels: Ok(true).
pub(super) fn check_runs(runs: &[RunView<'_>]) -> Result<bool, IdentifyError> {
    let first = runs
        .first()
        .ok_or_else(|| IdentifyError::Options("no record given".into()))?;
    let roving = runs.iter().all(|r| {
        r.excitation.map(|s| s.channel) == first.excitation.map(|s| s.channel)
            && r.excitation.is_some()
    }) && runs[1..]
        .iter()
        .any(|r| r.channel_names() != first.channel_names());
    for run in &runs[1..] {
        let err = |message: String| IdentifyError::Record {
            path: run.path.display().to_string(),
            message,
        };
        if !roving
            && (run.channel_names() != first.channel_names()
                || run.excitation.map(|s| s.channel) != first.excitation.map(|s| s.channel))
        {
            let names = |r: &RunView<'_>| {
                r.excitation
                    .map(|s| s.channel.name())
                    .into_iter()
                    .chain(r.channel_names())
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            return Err(err(format!(
                "its channels ({}) differ from {}'s ({}): runs of one test share their \
                 channels, or (a roving test) each measures the same excitation",
                names(run),
                first.path.display(),
                names(first)
            )));
        }
        if ((run.dt - first.dt) / first.dt).abs() > 1e-9 {
            return Err(err(format!(
                "sampled every {} s, {} every {} s: runs of one test share their rate",
                run.dt,
                first.path.display(),
                first.dt
            )));
        }
    }
    Ok(roving)
}

/// The response channels of every run, each once, in the order they first appear; per
/// channel, the (run, index) pairs that measured it.
pub(super) fn all_channels(runs: &[RunView<'_>]) -> Vec<(Channel, Vec<(usize, usize)>)> {
    let mut all: Vec<(Channel, Vec<(usize, usize)>)> = Vec::new();
    for (r, run) in runs.iter().enumerate() {
        for (i, signal) in run.responses.iter().enumerate() {
            match all.iter_mut().find(|(c, _)| *c == signal.channel) {
                Some((_, at)) => at.push((r, i)),
                None => all.push((signal.channel, vec![(r, i)])),
            }
        }
    }
    all
}

/// Per run, per response, the index of its channel in `everywhere`.
pub(super) fn run_channels(
    runs: &[RunView<'_>],
    everywhere: &[(Channel, Vec<(usize, usize)>)],
) -> Vec<Vec<usize>> {
    runs.iter()
        .map(|run| {
            run.responses
                .iter()
                .map(|s| {
                    everywhere
                        .iter()
                        .position(|(c, _)| *c == s.channel)
                        .unwrap_or(0)
                })
                .collect()
        })
        .collect()
}

/// The runs' files, sampling interval and Welch segment length, checked against the options.
pub(super) struct Sampling {
    pub(super) records: Vec<String>,
    /// The files joined, for messages.
    pub(super) names: String,
    pub(super) dt: f64,
    pub(super) nyquist: f64,
    pub(super) segment_length: usize,
    /// Samples in the shortest run.
    pub(super) shortest: usize,
}

impl Sampling {
    /// The sampling of `runs`; refuses a segment longer than the shortest run and a band
    /// above Nyquist.
    pub(super) fn of(
        runs: &[RunView<'_>],
        options: &IdentifyOptions,
    ) -> Result<Sampling, IdentifyError> {
        let records: Vec<String> = runs.iter().map(|r| r.path.display().to_string()).collect();
        let names = records.join(", ");
        let dt = runs[0].dt;
        let nyquist = 0.5 / dt;
        let shortest = runs.iter().map(RunView::len).min().unwrap_or(0);
        let segment_length = match options.segment_length {
            Some(s) => s,
            None => default_segment(shortest),
        };
        if segment_length > shortest {
            return Err(IdentifyError::Options(format!(
                "--segment {segment_length}: longer than the shortest run ({shortest} samples)"
            )));
        }
        if let Some((_, high)) = options.band {
            if high > nyquist {
                return Err(IdentifyError::Options(format!(
                    "--band up to {high} Hz: above the record's Nyquist frequency, {nyquist} Hz"
                )));
            }
        }
        Ok(Sampling {
            records,
            names,
            dt,
            nyquist,
            segment_length,
            shortest,
        })
    }

    /// A method's failure on these records.
    pub(super) fn method_err(
        &self,
        method: &'static str,
    ) -> impl FnOnce(IdentificationError) -> IdentifyError {
        let records = self.names.clone();
        move |source| IdentifyError::Method {
            method,
            records,
            source,
        }
    }
}

/// The runs' responses as the spectral estimators take them: every run's together, and each
/// one alone (a channel of a roving test, from each run that measured it).
pub(super) struct Signals<'a> {
    pub(super) outputs: Vec<Vec<&'a [f64]>>,
    pub(super) single: Vec<[&'a [f64]; 1]>,
}

impl<'a> Signals<'a> {
    /// The responses of `runs`, alone in the order of `everywhere` (each channel, the runs and
    /// responses that measured it).
    pub(super) fn of(runs: &[RunView<'a>], everywhere: &[(Channel, Vec<(usize, usize)>)]) -> Self {
        let outputs = runs
            .iter()
            .map(|r| r.responses.iter().map(|s| s.values.as_slice()).collect())
            .collect();
        let single = everywhere
            .iter()
            .flat_map(|(_, at)| at.iter())
            .map(|(r, i)| [runs[*r].responses[*i].values.as_slice()])
            .collect();
        Signals { outputs, single }
    }

    /// Every run: its excitation and all its responses.
    pub(super) fn runs(&self, runs: &[RunView<'a>]) -> Vec<Run<'_>> {
        runs.iter()
            .zip(&self.outputs)
            .map(|(r, o)| Run {
                input: r.excitation.map(|s| s.values.as_slice()),
                outputs: o,
            })
            .collect()
    }

    /// A roving test: each channel's runs, each with its excitation and that channel alone
    /// (the measured force is the common reference, so FRFs of different runs share one scale
    /// and phase and join into one FRF matrix).
    pub(super) fn per_channel(
        &self,
        runs: &[RunView<'a>],
        everywhere: &[(Channel, Vec<(usize, usize)>)],
    ) -> Vec<Vec<Run<'_>>> {
        let mut next = 0;
        everywhere
            .iter()
            .map(|(_, at)| {
                at.iter()
                    .map(|(r, _)| {
                        let run = Run {
                            input: runs[*r].excitation.map(|s| s.values.as_slice()),
                            outputs: &self.single[next],
                        };
                        next += 1;
                        run
                    })
                    .collect()
            })
            .collect()
    }
}

/// The fewest Welch segments whose coherence and averaged FRF judge a mode's peak
/// ([`Estimation::averaged_frf`]) and whose spectral matrix FDD reads.
pub const EVIDENCE_SEGMENTS: usize = DEFAULT_SEGMENTS;

/// The largest power of two (at least the shortest segment accepted) giving
/// [`DEFAULT_SEGMENTS`] half-overlapping segments in `samples`: 256 for the paper rig's
/// 1,024-sample records (seven segments).
pub fn evidence_segment(samples: usize) -> usize {
    // k segments of L with 50 % overlap span (k + 1) L / 2 samples.
    let longest = 2 * samples / (DEFAULT_SEGMENTS + 1);
    let mut segment = MIN_SEGMENT;
    while segment * 2 <= longest {
        segment *= 2;
    }
    segment
}

/// [`evidence_segment`] — but never shorter than
/// [`RESOLVING_SEGMENT`] samples (or the whole run, when it is shorter): a short record cut in
/// four leaves bins too wide to resolve a lightly damped resonance. On the paper rig's 20 s
/// records (1024 samples) twelve segments of 128 left LSCF finding one or two of the three
/// modes, one of them 5.8 % off; the whole record finds all three within 0.45 % of the twin.
pub fn default_segment(samples: usize) -> usize {
    let segment = evidence_segment(samples);
    let mut resolving = MIN_SEGMENT;
    while resolving * 2 <= samples.min(RESOLVING_SEGMENT) {
        resolving *= 2;
    }
    segment.max(resolving)
}

/// The shortest default segment where the record allows it, samples.
pub const RESOLVING_SEGMENT: usize = 1024;
