//! What a mode's run gives: per record its queries, NMSE after each update, refits and timings,
//! the possible changes flagged, and the Table 2 view of every mode.

use crate::blocks::supervisor::Mode;
use fmu_gp_corrector::Floors;
use serde::Serialize;

/// How the fixed threshold was set, for the report.
#[derive(Clone, Debug, Serialize)]
pub struct FixedThreshold {
    /// Per channel, in its unit squared ((m/s²)² for an acceleration).
    pub values: Vec<f64>,
    /// `given` (`--threshold`), `reference GP` or `1e-3 × measured variance`.
    pub rule: String,
    /// The reference GP's training stretch: record, first and last time (s), points.
    pub trained_on: Option<Stretch>,
    /// The unseen stretch the maximum is taken over.
    pub tested_on: Option<Stretch>,
}

#[derive(Clone, Debug, Serialize)]
pub struct Stretch {
    pub record: String,
    pub from: f64,
    pub to: f64,
    pub points: usize,
}

/// A run of consecutive queried samples long enough to suggest the structure changed.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct ChangeFlag {
    pub start: f64,
    pub end: f64,
    pub samples: usize,
}

#[derive(Clone, Debug, Serialize)]
pub struct NmsePoint {
    /// Queries in this record so far.
    pub update: usize,
    /// Time of the query (s); the record's first streamed time for update 0.
    pub time: f64,
    pub nmse: Vec<f64>,
}

#[derive(Clone, Debug, Serialize)]
pub struct RecordResult {
    pub record: String,
    pub queries: usize,
    pub query_times: Vec<f64>,
    pub nmse_physics: Vec<f64>,
    pub nmse_before: Vec<f64>,
    pub nmse_after_updates: Vec<NmsePoint>,
    pub final_nmse: Vec<f64>,
    pub training_points_at_end: usize,
    pub structure_may_have_changed: Vec<ChangeFlag>,
    pub threshold_at_end: Vec<f64>,
    /// Streamed samples and their decision-time latent variances and thresholds (for the plot).
    #[serde(skip)]
    pub trace: Trace,
}

#[derive(Clone, Debug, Default)]
pub struct Trace {
    /// The channels, in the corrector's order (that of the lists below).
    pub channels: Vec<String>,
    pub time: Vec<f64>,
    pub latent: Vec<Vec<f64>>,
    pub threshold: Vec<Vec<f64>>,
    /// The whole record: measured, and corrected with the record's final GP.
    pub measured: Vec<Vec<f64>>,
    pub corrected: Vec<Vec<f64>>,
}

#[derive(Clone, Debug, Serialize)]
pub struct ModeResult {
    pub mode: String,
    pub forgetting_factor: Option<f64>,
    pub initial_threshold: Vec<f64>,
    /// How the fixed mode's threshold was set (fixed mode only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fixed_threshold: Option<FixedThreshold>,
    pub total_queries: usize,
    pub records: Vec<RecordResult>,
    pub refits: Vec<RefitRecord>,
    /// Where the mode's time went.
    pub timing: Timing,
    /// The mode's run from the initial GPs (wall clock of its thread).
    pub seconds: f64,
    /// The initial fit, shared by the modes run together (not in `seconds`).
    pub initial_fit_seconds: f64,
    /// NMSE % per floor of the GPs at the end of the last record on every record (what the
    /// learned corrector does to the records learned before: `final_nmse` of a record is taken
    /// at its own end).
    pub final_gps_nmse: Vec<Vec<f64>>,
    /// The GPs at the end of the last record (what `--out` puts into the twin).
    #[serde(skip)]
    pub final_gps: Floors,
    /// What its plot calls the channels ([`channel_labels`]).
    #[serde(skip)]
    pub channel_labels: Vec<String>,
}

/// One hyperparameter refit of the channels' GPs.
#[derive(Clone, Debug, Serialize)]
pub struct RefitRecord {
    /// Record (0-based) and query count in it after which the refit ran.
    pub record: usize,
    pub query: usize,
    /// The refit at the end of a record (queries since the last one), not on the schedule.
    pub end_of_record: bool,
    pub training_points: usize,
    pub seconds: f64,
    /// Per channel: L-BFGS iterations, NLML before (old hyperparameters) and after.
    pub iterations: Vec<u64>,
    pub nlml_before: Vec<f64>,
    pub nlml_after: Vec<f64>,
    pub termination: Vec<String>,
    /// Per channel, the fitted signal and noise variances σ_f², σ_n² (its unit squared).
    pub signal_variance: Vec<f64>,
    pub noise_variance: Vec<f64>,
}

/// Seconds per part of a mode's run (wall clock of its thread).
#[derive(Clone, Debug, Default, Serialize)]
pub struct Timing {
    /// Building each record's tracked values (a blocked solve per floor).
    pub tracking_setup: f64,
    /// Appending queried points to the GPs.
    pub learning: f64,
    /// Hyperparameter refits.
    pub refits: f64,
    /// Bringing the tracked values up to date after queries and refits.
    pub tracking: f64,
    /// Thresholds, NMSE after each update, everything else in the loop.
    pub other: f64,
    /// Tracked values solved again from scratch (per floor).
    pub rebuilds: usize,
}

impl ModeResult {
    /// A file-name-safe tag of the mode (`learn-TAG.svg`).
    pub fn mode_tag(&self) -> String {
        match self.forgetting_factor {
            Some(f) => Mode::Adaptive(f).tag(),
            None => self.mode.clone(),
        }
    }
}

/// What a plot calls `channels` (a record's, by name): "floor i" on the paper's rig (and when
/// no record names them), the channel's name otherwise.
pub fn channel_labels(channels: &[String]) -> Vec<String> {
    if channels.is_empty() || ::structure::paper::is_paper_rig(channels) {
        (1..=::structure::paper::STOREYS)
            .map(|f| format!("floor {f}"))
            .collect()
    } else {
        channels.to_vec()
    }
}

/// Runs of at least `run` consecutive sample indices in `queries` (sorted).
pub fn change_flags(queries: &[usize], time: &[f64], run: usize) -> Vec<ChangeFlag> {
    let mut flags = Vec::new();
    let mut i = 0;
    while i < queries.len() {
        let mut j = i;
        while j + 1 < queries.len() && queries[j + 1] == queries[j] + 1 {
            j += 1;
        }
        if run > 0 && j - i + 1 >= run {
            flags.push(ChangeFlag {
                start: time[queries[i]],
                end: time[queries[j]],
                samples: j - i + 1,
            });
        }
        i = j + 1;
    }
    flags
}

/// The Table 2 view: queries per record per mode, then final NMSE per floor.
pub fn table(results: &[ModeResult]) -> String {
    let mut out = String::new();
    let records = results.first().map(|r| r.records.len()).unwrap_or(0);
    let width = 22;
    out.push_str(&format!("{:<12}", "queries"));
    for r in results {
        out.push_str(&format!("{:>width$}", r.mode));
    }
    out.push('\n');
    for k in 0..records {
        out.push_str(&format!("{:<12}", format!("record {}", k + 1)));
        for r in results {
            out.push_str(&format!("{:>width$}", r.records[k].queries));
        }
        out.push('\n');
    }
    out.push_str(&format!("{:<12}", "total"));
    for r in results {
        out.push_str(&format!("{:>width$}", r.total_queries));
    }
    out.push_str(&format!("\n{:<12}", "refits"));
    for r in results {
        out.push_str(&format!("{:>width$}", r.refits.len()));
    }
    out.push_str(&format!("\n{:<12}", "seconds"));
    for r in results {
        out.push_str(&format!("{:>width$.2}", r.seconds));
    }
    let channels = results
        .first()
        .and_then(|r| r.records.first())
        .map(|r| r.trace.channels.clone())
        .unwrap_or_default();
    if channels.is_empty() || ::structure::paper::is_paper_rig(channels.as_slice()) {
        out.push_str("\n\nfinal NMSE % (floors 1/2/3); physics only in the first column\n");
    } else {
        out.push_str(&format!(
            "\n\nfinal NMSE % ({}); physics only in the first column\n",
            channels.join("/")
        ));
    }
    out.push_str(&format!("{:<12}{:>width$}", "", "physics"));
    for r in results {
        out.push_str(&format!("{:>width$}", r.mode));
    }
    out.push('\n');
    let fmt = |n: &[f64]| {
        n.iter()
            .map(|v| format!("{v:.2}"))
            .collect::<Vec<_>>()
            .join("/")
    };
    for k in 0..records {
        out.push_str(&format!("{:<12}", format!("record {}", k + 1)));
        if let Some(r) = results.first() {
            out.push_str(&format!("{:>width$}", fmt(&r.records[k].nmse_physics)));
        }
        for r in results {
            out.push_str(&format!("{:>width$}", fmt(&r.records[k].final_nmse)));
        }
        out.push('\n');
    }
    out.push_str("\nNMSE % of the GPs at the end on every record\n");
    for k in 0..records {
        out.push_str(&format!(
            "{:<12}{:>width$}",
            format!("record {}", k + 1),
            ""
        ));
        for r in results {
            out.push_str(&format!("{:>width$}", fmt(&r.final_gps_nmse[k])));
        }
        out.push('\n');
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_rigs_channels_are_floors_and_any_others_their_names() {
        let names = |c: &[&str]| c.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        let floors = names(&["floor 1", "floor 2", "floor 3"]);
        assert_eq!(channel_labels(&names(&["acc1", "acc2", "acc3"])), floors);
        assert_eq!(channel_labels(&[]), floors);
        // Another order, or another channel set, is shown by name.
        let other = names(&["acc2", "acc1", "acc3"]);
        assert_eq!(channel_labels(&other), other);
        let five = names(&["acc1", "vel3", "disp5"]);
        assert_eq!(channel_labels(&five), five);
    }
}
