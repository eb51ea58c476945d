//! `twin serve`: the live page over what is already there — a finished watch (its alerts,
//! checkpoint and diagnoses), a record against its twin (`twin compare`'s series), or a fleet
//! report (one row per structure, each opening its own view where one exists).

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, Result};

use crate::serve::finished::{publish_comparison, publish_fleet, publish_watch, read_fleet};
use crate::serve::hub::{Hub, Limits};
use crate::twin::Twin;
use crate::workflows::compare::{compare, CompareOptions};

#[derive(clap::Args)]
#[command(group(clap::ArgGroup::new("what").required(true).args(["alerts", "data", "fleet"])))]
pub struct ServeArgs {
    /// A finished watch's alerts (JSON lines; its diagnoses' reports and acknowledgements are
    /// read from beside it).
    #[arg(long)]
    pub alerts: Option<PathBuf>,
    /// The watch's checkpoint, for the state panel.
    #[arg(long, requires = "alerts")]
    pub checkpoint: Option<PathBuf>,
    /// A record (CSV) to show against --twin, as `twin compare` compares them.
    #[arg(long, requires = "twin")]
    pub data: Option<PathBuf>,
    /// The twin (.ssp) of --data.
    #[arg(long)]
    pub twin: Option<PathBuf>,
    #[command(flatten)]
    pub columns: super::ColumnsArg,
    /// A fleet report (`twin fleet`'s fleet.csv). A structure NAME whose finished watch is
    /// beside it (NAME/alerts.jsonl or NAME.alerts.jsonl) opens its own view.
    #[arg(long)]
    pub fleet: Option<PathBuf>,
    /// Seconds of the rolling NMSE of a record's view.
    #[arg(long, default_value_t = crate::workflows::watch::WINDOW)]
    pub window: f64,
    /// Where to serve (port 0: a free one); the URL goes to standard error as `serving URL`.
    #[arg(long, default_value = "127.0.0.1:8080")]
    pub addr: SocketAddr,
    /// Allow an address other machines reach (not loopback).
    #[arg(long)]
    pub public: bool,
    /// Stop after this many seconds (default: serve until stopped).
    #[arg(long, value_parser = super::transient_seconds)]
    pub seconds: Option<f64>,
}

/// A fleet structure's own finished watch, if one is beside the report.
fn structure_alerts(fleet: &Path, name: &str) -> Option<PathBuf> {
    let dir = fleet.parent().unwrap_or(Path::new("."));
    [
        dir.join(name).join("alerts.jsonl"),
        dir.join(format!("{name}.alerts.jsonl")),
    ]
    .into_iter()
    .find(|p| p.is_file())
}

pub fn run(args: &ServeArgs) -> Result<()> {
    crate::serve::check_bind(args.addr, args.public, "--addr", "--public")?;
    let hub = Hub::new(Limits::default());
    let mut views = BTreeMap::new();
    if let Some(alerts) = &args.alerts {
        publish_watch(&hub, alerts, args.checkpoint.as_deref())?;
    } else if let Some(data) = &args.data {
        let twin = Twin::load(args.twin.as_deref())?;
        let record = args.columns.read_any(data)?;
        let compared = compare(&twin, &record, &CompareOptions::default(), None, |_, _| {})
            .with_context(|| format!("comparing {} with the twin", data.display()))?;
        publish_comparison(
            &hub,
            format!("{} against {}", data.display(), twin_name(args)),
            &compared.comparison,
            args.window,
        );
    } else if let Some(fleet) = &args.fleet {
        let mut rows = read_fleet(fleet)?;
        for row in &mut rows {
            if let Some(alerts) = structure_alerts(fleet, &row.name) {
                let view = Hub::new(Limits::default());
                publish_watch(&view, &alerts, None)?;
                views.insert(row.name.clone(), view);
                row.view = true;
            }
        }
        publish_fleet(&hub, format!("fleet {}", fleet.display()), &rows);
    }
    let server = crate::serve::start(args.addr, hub, views, Default::default())?;
    eprintln!("serving {}", server.url());
    let until = args
        .seconds
        .map(|s| Instant::now() + Duration::from_secs_f64(s));
    while server.running() && until.is_none_or(|u| Instant::now() < u) {
        std::thread::sleep(Duration::from_millis(100));
    }
    server.stop();
    Ok(())
}

fn twin_name(args: &ServeArgs) -> String {
    args.twin
        .as_ref()
        .map_or_else(|| "the default twin".into(), |p| p.display().to_string())
}
