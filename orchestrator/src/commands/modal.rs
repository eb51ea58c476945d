//! `twin modal`: the twin's natural frequencies, damping ratios and mode shapes, each with its
//! sd from the calibration's posterior (checked against sampling it); with `--data`, the modes
//! identified from a record (SSI-COV, and LSCF when the excitation was measured), beside the
//! twin's when `--twin` is given too.

use std::path::{Path, PathBuf};

use anyhow::{bail, Result};

use super::write_json;
use crate::record::{has_excitation_column, AmbientRecord, Measurement, ReadOptions};
use crate::twin::Twin;
use crate::workflows::modal::identify::{FddModes, MethodModes, RecordModes};
use crate::workflows::modal::ModeVerdict;
use crate::workflows::modal::{
    identify, identify_ambient, pair_modes, twin_modes, IdentifyOptions, ModalOptions,
    ModeComparison, TwinModes,
};
use crate::workflows::options::check_svg;

#[derive(clap::Args)]
pub struct ModalArgs {
    /// The twin (.ssp); the default twin when absent.
    #[arg(long)]
    pub twin: Option<PathBuf>,
    /// JSON report.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Plot (.svg): the mode shapes along the height with their ±2 sd.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Draws from the posterior that check the linearised sds (0: no check).
    #[arg(long, default_value_t = ModalOptions::default().samples)]
    pub samples: usize,
    /// A record (CSV) to identify the modes of; repeat for several runs of one test (the same
    /// channels, or — a roving test — each with the measured force and its own response
    /// channels: each run fitted alone, the modes merged through the force). With --plot,
    /// P.svg is the stabilisation diagram over the spectrum and P-frf.svg the FRFs.
    #[arg(long, value_name = "D.csv")]
    pub data: Vec<PathBuf>,
    /// Samples per Welch segment (FRF, spectrum); default: a power of two giving 4 segments.
    #[arg(long)]
    pub segment: Option<usize>,
    /// The band LSCF fits, LOW:HIGH Hz; default: where the force has power and the coherence
    /// reaches 0.5, at most up to 0.8 × Nyquist.
    #[arg(long, value_name = "LOW:HIGH", value_parser = parse_band)]
    pub band: Option<(f64, f64)>,
    /// The largest model order of both methods (even); LSCF goes on, 20 orders at a time up
    /// to three times it, while modes are still forming at its highest order.
    #[arg(long, default_value_t = IdentifyOptions::default().max_order)]
    pub max_order: usize,
    /// SSI-COV's block rows; default: enough for the order, at least 20.
    #[arg(long)]
    pub block_rows: Option<usize>,
    /// SSI-COV only, even when the excitation was measured.
    #[arg(long)]
    pub output_only: bool,
}

fn parse_band(text: &str) -> Result<(f64, f64), String> {
    let (low, high) = text
        .split_once(':')
        .ok_or_else(|| format!("'{text}' is not LOW:HIGH (Hz)"))?;
    let number = |t: &str| {
        t.trim()
            .parse::<f64>()
            .map_err(|_| format!("'{t}' in '{text}' is not a number of Hz"))
    };
    Ok((number(low)?, number(high)?))
}

pub fn run(args: &ModalArgs) -> Result<()> {
    if let Some(plot) = &args.plot {
        check_svg(plot)?;
    }
    if !args.data.is_empty() {
        return run_data(args);
    }
    let twin = Twin::load(args.twin.as_deref())?;
    let options = ModalOptions {
        samples: args.samples,
        ..ModalOptions::default()
    };
    let modes = twin_modes(&twin, &options)?;
    print_twin_modes(&modes);
    if let Some(path) = &args.report {
        write_json(path, &serde_json::json!({ "twin": &modes }))?;
    }
    if let Some(path) = &args.plot {
        crate::report::mode_plot::plot_mode_shapes(&modes, None, path)?;
    }
    Ok(())
}

pub(crate) fn print_twin_modes(modes: &TwinModes) {
    println!(
        "{}: {} storeys, excitation {}",
        modes.twin, modes.storeys, modes.excitation
    );
    if modes.uncertain_parameters.is_empty() {
        println!("  uncalibrated twin: no posterior, no sds");
    } else {
        println!(
            "  sds from the posterior of {} (sampled sd beside the linearised one)",
            modes.uncertain_parameters.join(", ")
        );
    }
    for m in &modes.modes {
        let shape: Vec<String> = m.shape.iter().map(|x| format!("{x:+.3}")).collect();
        let sampled = m
            .sampled
            .as_ref()
            .map(|s| {
                format!(
                    " [sampled {:.4} Hz, {:.4} %]",
                    s.frequency_sd,
                    100.0 * s.damping_sd
                )
            })
            .unwrap_or_default();
        println!(
            "  mode {}: {:.4}{} Hz  ζ {:.4}{} %{}  shape [{}]",
            m.number,
            m.frequency,
            m.frequency_sd
                .map(|s| format!(" ± {s:.4}"))
                .unwrap_or_default(),
            100.0 * m.damping,
            m.damping_sd
                .map(|s| format!(" ± {:.4}", 100.0 * s))
                .unwrap_or_default(),
            sampled,
            shape.join(" ")
        );
    }
}

fn names(paths: &[std::path::PathBuf], measured: &[bool], which: bool) -> String {
    paths
        .iter()
        .zip(measured)
        .filter(|(_, &m)| m == which)
        .map(|(p, _)| p.display().to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

/// `--data`: the record's modes, beside the twin's with `--twin`.
fn run_data(args: &ModalArgs) -> Result<()> {
    let options = IdentifyOptions {
        segment_length: args.segment,
        band: args.band,
        max_order: args.max_order,
        block_rows: args.block_rows,
        input_output: !args.output_only,
        ..IdentifyOptions::default()
    };
    options.validate()?;
    let record = identify_records(&args.data, &options)?;
    print_record_modes(&record);
    let twin = match &args.twin {
        Some(path) => Some(beside_the_twin(path, args.samples, &record)?),
        None => None,
    };
    if let Some(path) = &args.report {
        let value = match &twin {
            Some((modes, comparison)) => serde_json::json!({
                "record": &record, "twin": modes, "comparison": comparison
            }),
            None => serde_json::json!({ "record": &record }),
        };
        write_json(path, &value)?;
    }
    if let Some(path) = &args.plot {
        plot_data(&record, twin.as_ref(), path)?;
    }
    Ok(())
}

/// The records' modes: records with the excitation, or ambient ones (responses only: SSI-COV
/// alone); a mix of the two is refused.
fn identify_records(data: &[PathBuf], options: &IdentifyOptions) -> Result<RecordModes> {
    let read = ReadOptions::default();
    let measured = data
        .iter()
        .map(|path| has_excitation_column(path, &read))
        .collect::<Result<Vec<_>, _>>()?;
    if measured.iter().all(|&m| m) {
        let runs = data
            .iter()
            .map(|path| Measurement::read_with(path, &read))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(identify(&runs, options)?)
    } else if measured.iter().all(|&m| !m) {
        let runs = data
            .iter()
            .map(|path| AmbientRecord::read(path, &read))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(identify_ambient(&runs, options)?)
    } else {
        bail!(
            "runs of one test share their channels: {} have the excitation, {} do not",
            names(data, &measured, true),
            names(data, &measured, false)
        );
    }
}

/// The twin's modes paired with the record's, both printed.
fn beside_the_twin(
    path: &Path,
    samples: usize,
    record: &RecordModes,
) -> Result<(TwinModes, ModeComparison)> {
    let twin = Twin::load(Some(path))?;
    let modes = twin_modes(
        &twin,
        &ModalOptions {
            samples,
            ..ModalOptions::default()
        },
    )?;
    let comparison = pair_modes(&modes, &record.observed(), &record.floors);
    print_twin_modes(&modes);
    print_comparison(record, &comparison);
    Ok((modes, comparison))
}

/// The stabilisation diagram at `path` and the FRFs beside it; with the twin, its shapes along
/// the height with the record's beside them (`<stem>-shapes.svg`) and the MAC matrix
/// (`<stem>-mac.svg`).
fn plot_data(
    record: &RecordModes,
    twin: Option<&(TwinModes, ModeComparison)>,
    path: &Path,
) -> Result<()> {
    crate::report::modal_plot::plot_stabilisation(record, path)?;
    if record.frf.is_some() {
        let frf_path = crate::report::modal_plot::frf_path(path);
        crate::report::modal_plot::plot_frf(record, &frf_path)?;
    }
    let Some((modes, comparison)) = twin else {
        return Ok(());
    };
    let sibling = |suffix: &str| {
        let stem = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "modal".into());
        path.with_file_name(format!("{stem}-{suffix}.svg"))
    };
    let observed: Vec<(f64, Vec<f64>)> = record
        .observed()
        .iter()
        .map(|o| (o.frequency, o.shape.iter().map(|c| c.re).collect()))
        .collect();
    let shapes = crate::report::mode_plot::ObservedShapes {
        floors: &record.floors,
        modes: observed,
        comparison: Some(comparison),
    };
    crate::report::mode_plot::plot_mode_shapes(modes, Some(&shapes), &sibling("shapes"))?;
    if !comparison.mac_matrix.is_empty()
        && comparison.mac_matrix.first().is_some_and(|r| !r.is_empty())
    {
        crate::report::mode_plot::plot_mac_matrix(comparison, &sibling("mac"))?;
    }
    Ok(())
}

fn print_method(method: &MethodModes) {
    let orders = &method.diagram.orders;
    let span = match (orders.first(), orders.last()) {
        (Some(a), Some(b)) => format!("orders {}..{}", a.order, b.order),
        _ => "no orders".into(),
    };
    let band = method
        .band
        .map(|(l, h)| format!(", band {l:.3}..{h:.3} Hz"))
        .unwrap_or_default();
    println!(
        "  {} ({span}{band}): {} modes",
        method.method,
        method.modes.len()
    );
    for (i, m) in method.modes.iter().enumerate() {
        let id = &m.identified;
        let shape: Vec<String> = m
            .displacement_shape
            .iter()
            .map(|x| format!("{:+.3}", if x.re < 0.0 { -x.norm() } else { x.norm() }))
            .collect();
        println!(
            "    mode {}: {:.4} ± {:.4} Hz  ζ {:.4} ± {:.4} %  MPC {:.3}  MPD {:.1}°  ({} orders)  \
             shape [{}]",
            i + 1,
            id.frequency,
            id.frequency_sd,
            100.0 * id.damping,
            100.0 * id.damping_sd,
            id.mpc,
            id.mpd,
            id.orders.len(),
            shape.join(" ")
        );
    }
    for r in &method.rejected {
        println!(
            "    set aside: {:.4} Hz  ζ {:.4} %  MPC {:.3}: {}",
            r.mode.frequency,
            100.0 * r.mode.damping,
            r.mode.mpc,
            r.reason
        );
    }
}

pub(crate) fn print_record_modes(record: &RecordModes) {
    println!(
        "{}: {}, excitation {}, {} samples at {:.6} Hz; shapes at floors {:?}",
        record.records.join(", "),
        record.channels.join(", "),
        record.excitation,
        record.samples.iter().sum::<usize>(),
        1.0 / record.dt,
        record.floors
    );
    if let Some(io) = &record.input_output {
        print_method(io);
    }
    print_method(&record.ssi);
    print_fdd(&record.fdd);
    print_verdicts(&record.verdicts);
}

fn print_fdd(fdd: &FddModes) {
    println!(
        "  {} (band {:.3}..{:.3} Hz): {} modes",
        fdd.method,
        fdd.band.0,
        fdd.band.1,
        fdd.modes.len()
    );
    for (i, m) in fdd.modes.iter().enumerate() {
        let id = &m.identified;
        println!(
            "    mode {}: {:.4} ± {:.4} Hz  ζ {:.4} ± {:.4} %  MPC {:.3}",
            i + 1,
            id.frequency,
            id.frequency_sd,
            100.0 * id.damping,
            100.0 * id.damping_sd,
            id.mpc
        );
    }
}

/// The methods' verdicts, one line per mode: who found it, where, its damping, the MACs.
fn print_verdicts(verdicts: &[ModeVerdict]) {
    println!("  the methods side by side:");
    for v in verdicts {
        let found: Vec<String> = v
            .found_by
            .iter()
            .map(|m| {
                format!(
                    "{} {:.4} Hz ζ {:.3} %",
                    m.method,
                    m.frequency,
                    100.0 * m.damping
                )
            })
            .collect();
        let macs: Vec<String> = v
            .macs
            .iter()
            .map(|a| format!("MAC {}–{} {:.3}", a.methods.0, a.methods.1, a.mac))
            .collect();
        println!(
            "    {:.4} Hz: {}{}{}",
            v.frequency,
            found.join(", "),
            if macs.is_empty() {
                String::new()
            } else {
                format!("; {}", macs.join(", "))
            },
            if v.one_method_only {
                "  [one method only]"
            } else {
                ""
            }
        );
    }
}

fn print_comparison(record: &RecordModes, comparison: &ModeComparison) {
    let method = record
        .input_output
        .as_ref()
        .map_or(record.ssi.method, |m| m.method);
    println!("  the record's modes ({method}) beside the twin's:");
    for p in &comparison.pairs {
        println!(
            "    twin mode {} {:.4} Hz ↔ record mode {} {:.4} Hz: {:+.2} %{}, damping {:+.4} %, MAC {:.4}",
            p.twin_mode,
            p.twin_frequency,
            p.observed_mode,
            p.observed_frequency,
            p.frequency_shift_percent,
            p.frequency_shift_sd
                .map(|s| format!(" ({s:+.1} sd)"))
                .unwrap_or_default(),
            100.0 * p.damping_change,
            p.mac
        );
    }
    if !comparison.unpaired_twin.is_empty() {
        println!(
            "    twin modes without a partner: {:?}",
            comparison.unpaired_twin
        );
    }
    if !comparison.unpaired_observed.is_empty() {
        println!(
            "    record modes without a partner: {:?}",
            comparison.unpaired_observed
        );
    }
}
