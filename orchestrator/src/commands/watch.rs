//! `twin watch`: the operational twin on a live stream of CSV lines (standard input, a file
//! that grows, or an MQTT topic); alerts as JSON lines (and MQTT messages), a checkpoint to
//! resume from.

use std::io::IsTerminal;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use anyhow::Result;

use crate::serve::http::Actions;
use crate::serve::hub::{Hub, Limits};
use crate::twin::Twin;
use crate::workflows::options::check_tolerance;
use crate::workflows::watch::background::DiagnosisOptions;
use crate::workflows::watch::modes::TrackOptions;
use crate::workflows::watch::supervise::LearnOptions;
use crate::workflows::watch::{
    watch_observed, Status, StreamSource, Summary, WatchOptions, CHECKPOINT_EVERY, WINDOW,
};

#[derive(clap::Args)]
pub struct WatchArgs {
    /// The twin (.ssp), calibrated (its noise variances make the ±3σ band).
    #[arg(long)]
    pub twin: Option<PathBuf>,
    /// `-`: CSV lines on standard input (a header first, naming the columns as a record's does:
    /// `time`, `force` or `ground_acc`, any of `acc<i>`, `vel<i>`, `disp<i>`, a unit in
    /// brackets, `acc1 (g)`), read to the end; `mqtt://HOST[:PORT]/TOPIC`: messages of one or
    /// more CSV lines (a header line in the first, else `time`, the excitation and `acc1..accN`)
    /// subscribed with QoS 1 on a persistent session, alerts published to TOPIC/alerts; else a
    /// CSV file (see --follow).
    #[arg(long)]
    pub source: String,
    /// Header names the stream uses for the twin's, a JSON object (`{"fp (N)": "force"}`), as
    /// other commands take it.
    #[arg(long)]
    pub columns: Option<PathBuf>,
    /// The MQTT client id (default `twin-watch-` and the topic): a restarted watcher with the
    /// same id gets what the broker kept for it.
    #[arg(long)]
    pub client_id: Option<String>,
    /// Keep reading the file as lines are appended (polled every 100 ms) until --idle seconds
    /// pass without a new line; without it the file is read to its end.
    #[arg(long)]
    pub follow: bool,
    /// Seconds without a new line (--follow; default 10) or message (MQTT; default: never)
    /// that end the stream.
    #[arg(long)]
    pub idle: Option<f64>,
    /// Alerts, one JSON object a line (kinds failing, recovered, diagnosis, bad_sample, gap,
    /// connection, end), each flushed as it is written. A diagnosis's whole report goes beside
    /// it, ALERTS.diagnosis-K.json (for `twin add-physics --diagnosis`).
    #[arg(long)]
    pub alerts: PathBuf,
    /// Checkpoint file (JSON): saved every --checkpoint-every samples and at the end; when it
    /// exists at the start, the watcher resumes from it, skipping the samples it consumed.
    #[arg(long)]
    pub checkpoint: Option<PathBuf>,
    #[arg(long, default_value_t = CHECKPOINT_EVERY)]
    pub checkpoint_every: u64,
    /// Seconds of the rolling NMSE.
    #[arg(long, default_value_t = WINDOW)]
    pub window: f64,
    /// Practical significance, NMSE % (as `twin compare`'s); default: 2 × the twin's worst
    /// validation NMSE, else 0.5 %.
    #[arg(long)]
    pub tolerance: Option<f64>,
    /// Seconds after the stream's start (and after each gap) left out of the comparison.
    #[arg(long, default_value_t = crate::evaluation::compare::DEFAULT_TRANSIENT, value_parser = super::transient_seconds)]
    pub transient: f64,
    /// Sampling rate (Hz); default: from the first two samples' times.
    #[arg(long)]
    pub rate: Option<f64>,
    /// No diagnosis of failing windows in the background.
    #[arg(long)]
    pub no_diagnosis: bool,
    /// Seconds of the stream a failing window's diagnosis is run on (the last ones when it
    /// starts).
    #[arg(long, default_value_t = DiagnosisOptions::default().record)]
    pub diagnosis_record: f64,
    /// Seconds after a failing window opens that its diagnosis starts if the window is still
    /// open (it starts at once when the window closes).
    #[arg(long, default_value_t = DiagnosisOptions::default().after)]
    pub diagnosis_after: f64,
    /// After a located change: the post-change seconds of the first diagnosis, and the step
    /// of the next ones while the window stays open (up to 30 s, until two agree).
    #[arg(long, default_value_t = DiagnosisOptions::default().post)]
    pub diagnosis_post: f64,
    /// Wait for each background diagnosis before reading on: for a recorded stream replayed
    /// at full speed, which would otherwise outrun its diagnoses (a live stream never waits).
    #[arg(long, conflicts_with = "no_diagnosis")]
    pub diagnosis_wait: bool,
    /// Unattended operation: adopt a firm `recalibrate` or `add_physics` verdict (two looks
    /// after a located change agree; library effects) — the twin it names written beside the
    /// alerts (ALERTS.twin-K.ssp) and swapped into the running watch at once, going on from
    /// its own state over the samples kept; an `adopted` alert, and the checkpoint records
    /// which twin is live from when.
    #[arg(long, conflicts_with = "no_diagnosis")]
    pub adopt: bool,
    /// With a GP corrector: query where its latent variance V(f) exceeds this (m²/s⁴);
    /// default: the largest V(f) over the first 100 samples after the transient.
    #[arg(long)]
    pub query_threshold: Option<f64>,
    /// With a GP corrector: watch its latent variances, learn nothing.
    #[arg(long)]
    pub no_learning: bool,
    /// With a GP corrector: the most training points a floor keeps (the oldest go first).
    #[arg(long, default_value_t = LearnOptions::default().budget)]
    pub budget: u32,
    /// With a GP corrector: refit its hyperparameters after this many learned points (0:
    /// never; a refit holds the stream up for as long as it takes).
    #[arg(long, default_value_t = LearnOptions::default().refit_every)]
    pub refit_every: u32,
    /// Track the natural frequencies: every --modes-every seconds of stream, identify the modes
    /// of the last --modes-window seconds (output-only, SSI-COV) against the twin's and its
    /// band; alerts `modes` (each identification), `frequency` (a mode left its band),
    /// `frequency_back`.
    #[arg(long)]
    pub track_modes: bool,
    #[arg(long, default_value_t = TrackOptions::default().window, requires = "track_modes")]
    pub modes_window: f64,
    #[arg(long, default_value_t = TrackOptions::default().every, requires = "track_modes")]
    pub modes_every: f64,
    /// The band's least half-width, % of the twin's frequency (it is otherwise 3 combined sds
    /// of the twin's and the identified frequency).
    #[arg(long, default_value_t = TrackOptions::default().tolerance, requires = "track_modes")]
    pub modes_tolerance: f64,
    /// At the end, the tracked frequencies against time with the twin's bands (.svg), from the
    /// alerts file's `modes` lines.
    #[arg(long, requires = "track_modes")]
    pub modes_plot: Option<PathBuf>,
    /// Serve a live page of the watch at ADDRESS (`127.0.0.1:8080`; port 0: a free one); the
    /// URL goes to standard error as `serving http://ADDRESS/`. Read-only without --token.
    #[arg(long, value_name = "ADDRESS")]
    pub serve: Option<std::net::SocketAddr>,
    /// Allow --serve on an address other machines reach (not loopback).
    #[arg(long, requires = "serve")]
    pub serve_public: bool,
    /// The token the page's changes need (acknowledge an alert, accept a diagnosis and add its
    /// physics into a new twin beside --twin), sent as `Authorization: Bearer TOKEN`.
    #[arg(long, requires = "serve")]
    pub token: Option<String>,
    /// Seconds the page stays up after the stream ends.
    #[arg(long, default_value_t = 0.0, requires = "serve", value_parser = super::transient_seconds)]
    pub serve_linger: f64,
}

impl WatchArgs {
    /// The library's options from the flags, checked.
    pub fn options(&self) -> Result<WatchOptions> {
        check_tolerance(self.tolerance)?;
        let source =
            StreamSource::parse(&self.source, self.follow, self.idle, self.client_id.clone())?;
        let options = WatchOptions {
            learning: LearnOptions {
                threshold: self.query_threshold,
                learn: !self.no_learning,
                budget: self.budget,
                refit_every: self.refit_every,
            },
            diagnosis: (!self.no_diagnosis).then_some(DiagnosisOptions {
                record: self.diagnosis_record,
                after: self.diagnosis_after,
                post: self.diagnosis_post,
                transient: self.transient,
                wait: self.diagnosis_wait,
                ..DiagnosisOptions::default()
            }),
            checkpoint: self.checkpoint.clone(),
            checkpoint_every: self.checkpoint_every,
            window: self.window,
            tolerance: self.tolerance,
            transient: self.transient,
            rate: self.rate,
            adopt: self.adopt,
            modes: self.track_modes.then_some(TrackOptions {
                window: self.modes_window,
                every: self.modes_every,
                tolerance: self.modes_tolerance,
                ..TrackOptions::default()
            }),
            columns: match &self.columns {
                Some(path) => crate::record::ColumnMap::read(path)?,
                None => Default::default(),
            },
            ..WatchOptions::new(source, self.alerts.clone())
        };
        options.validate()?;
        Ok(options)
    }
}

pub fn run(args: &WatchArgs) -> Result<()> {
    if let Some(plot) = &args.modes_plot {
        crate::workflows::options::check_svg(plot)?;
    }
    let options = args.options()?;
    let twin = Twin::load(args.twin.as_deref())?;
    let page = match args.serve {
        Some(addr) => Some(serve_page(args, addr)?),
        None => None,
    };
    let mut view = page.as_ref().map(|(hub, _)| {
        crate::serve::live::LiveView::new(
            hub.clone(),
            match args.source.as_str() {
                "-" => "twin watch: standard input".to_owned(),
                source => format!("twin watch: {source}"),
            },
            args.token.is_some(),
        )
    });
    let spinner = std::io::stderr().is_terminal().then(|| {
        let s = indicatif::ProgressBar::new_spinner();
        s.enable_steady_tick(Duration::from_millis(120));
        s
    });
    let observer = view
        .as_mut()
        .map(|v| v as &mut dyn crate::workflows::watch::Observer);
    let watched = watch_observed(
        &twin,
        &options,
        |status: &Status| {
            if let Some(s) = &spinner {
                s.set_message(status_line(status));
            }
        },
        &mut |_| Ok(()),
        observer,
    );
    if let Some(s) = spinner {
        s.finish_and_clear();
    }
    let summary = match watched {
        Ok(summary) => summary,
        Err(e) => {
            // The page shows why the watch stopped, for as long as it lingers.
            if let Some((hub, _)) = &page {
                hub.publish(
                    crate::serve::hub::Kind::Other,
                    serde_json::json!({"type": "stopped", "error": e.to_string()}),
                );
            }
            linger(args, page);
            return Err(e.into());
        }
    };
    print_summary(&summary);
    println!("alerts: {}", args.alerts.display());
    if let Some(plot) = &args.modes_plot {
        let tracked = crate::workflows::watch::modes::read_tracked(&args.alerts)
            .map_err(anyhow::Error::msg)?;
        crate::report::mode_plot::plot_tracked_frequencies(&tracked, plot)?;
        println!("tracked frequencies: {}", plot.display());
    }
    linger(args, page);
    Ok(())
}

/// The spinner's line: samples, rate, each channel's rolling NMSE, an open window, a
/// diagnosis under way.
fn status_line(status: &Status) -> String {
    let nmse: Vec<String> = status
        .channels
        .iter()
        .zip(&status.rolling_nmse)
        .map(|(name, v)| {
            if v.is_finite() {
                format!("{name} {v:.2}")
            } else {
                format!("{name} -")
            }
        })
        .collect();
    format!(
        "{} samples (t = {:.1} s), {:.0} samples/s, rolling NMSE % {}{}{}",
        status.samples,
        status.time,
        status.samples_per_second,
        nmse.join(", "),
        if status.open_window { ", FAILING" } else { "" },
        if status.diagnosing {
            ", diagnosing in the background"
        } else {
            ""
        }
    )
}

/// What the watch saw: lines, gaps and windows, the NMSE, the speed, MQTT and the corrector.
fn print_summary(summary: &Summary) {
    let nmse: Vec<String> = summary
        .channels
        .iter()
        .zip(&summary.nmse)
        .map(|(name, v)| {
            if v.is_finite() {
                format!("{name} {v:.3}")
            } else {
                format!("{name} -")
            }
        })
        .collect();
    println!(
        "watched {} samples ({} this run): {} bad lines, {} gaps ({} samples missing), {} failing windows",
        summary.samples,
        summary.samples_this_run,
        summary.bad_lines,
        summary.gaps,
        summary.missing_samples,
        summary.failing_windows
    );
    println!(
        "NMSE % over the stream (after the transient): {}; tolerance {:.3} %; band: {}",
        nmse.join(", "),
        summary.tolerance,
        summary.noise_source
    );
    println!(
        "{:.0} samples/s ({:.0}× real time); per-sample latency median {:.1} µs, p99 {:.1} µs",
        summary.samples_per_second,
        summary.real_time_factor,
        summary.latency_median_us,
        summary.latency_p99_us
    );
    if let Some(m) = &summary.mqtt {
        println!(
            "MQTT: {} messages ({} delivered again, {} duplicate samples dropped), {} connections, {} lost",
            m.messages, m.redelivered, summary.duplicates, m.connections, m.disconnections
        );
    }
    if let Some(l) = &summary.learning {
        println!(
            "corrector: {} queries{}, {} training points (budget {})",
            l.queries,
            if l.learned {
                " learned"
            } else {
                " (not learned)"
            },
            l.training_points.map_or("-".into(), |n| n.to_string()),
            l.budget
                .map_or("the FMU's own, 2048".into(), |b| b.to_string())
        );
    }
}

/// Start the page's server: `serving URL` on standard error (one line, for scripts).
fn serve_page(
    args: &WatchArgs,
    addr: std::net::SocketAddr,
) -> Result<(Arc<Hub>, crate::serve::Server)> {
    crate::serve::check_bind(addr, args.serve_public, "--serve", "--serve-public")?;
    let hub = Hub::new(Limits::default());
    let acks = {
        let stem = args
            .alerts
            .file_stem()
            .map_or_else(|| "alerts".into(), |s| s.to_string_lossy().into_owned());
        args.alerts.with_file_name(format!("{stem}.acks.jsonl"))
    };
    let actions = Actions {
        token: args.token.clone(),
        acks: Some(acks),
        twin: args.twin.clone(),
        binary: std::env::current_exe().ok(),
    };
    let server = crate::serve::start(addr, hub.clone(), Default::default(), actions)?;
    eprintln!("serving {}", server.url());
    Ok((hub, server))
}

/// Keep the page up for --serve-linger seconds after the stream (while its server runs).
fn linger(args: &WatchArgs, page: Option<(Arc<Hub>, crate::serve::Server)>) {
    let Some((_, server)) = page else {
        return;
    };
    let until = std::time::Instant::now() + Duration::from_secs_f64(args.serve_linger);
    while std::time::Instant::now() < until && server.running() {
        std::thread::sleep(Duration::from_millis(100));
    }
    server.stop();
}
