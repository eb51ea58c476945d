//! `twin compare`: run the twin on a record's force and compare its accelerations with the
//! measured ones; a summary, and optionally a JSON report, the predictions and plots.

use std::path::PathBuf;

use anyhow::{bail, Result};

use super::{progress_bar, write_json, Compared};
use crate::evaluation::compare::Comparison;
use crate::twin::data::Measurement;
use crate::twin::run::Prediction;
use crate::twin::{guard, Twin};
use crate::workflows::compare::{compare, CompareOptions};
use crate::workflows::control::ControllerSpec;
use crate::workflows::options::check_svg;

#[derive(clap::Args)]
pub struct CompareArgs {
    #[command(flatten)]
    pub columns: super::ColumnsArg,
    /// The twin (.ssp); the default twin when absent.
    #[arg(long)]
    pub twin: Option<PathBuf>,
    /// Measurement CSV: time, the excitation (force or ground_acc) and any of the twin's
    /// response channels (acc<i>, vel<i>, disp<i>), units in the header.
    #[arg(long, required_unless_present = "frf")]
    pub data: Option<PathBuf>,
    /// JSON report.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// The twin's predictions as CSV: time and each measured channel by name, SI.
    #[arg(long)]
    pub predictions: Option<PathBuf>,
    /// Plot (.svg): measured, predicted, ±3σ band, residual, failing windows.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Alone (`--data D.csv --frf`): also draw the frequency-response view of the record.
    /// With a file (`--frf FRF.csv`, instead of --data): compare the twin's exact FRF with a
    /// measured one (CSV of `frequency` and `<ch>_re,<ch>_im` or `<ch>_db`, or a universal
    /// file, dataset 58): the error per channel (RMS dB over the band), both sets of resonances,
    /// and with --plot the overlay measured / twin / ±3σ band.
    #[arg(long, value_name = "FRF", num_args = 0..=1)]
    pub frf: Option<Option<PathBuf>>,
    /// With --frf FRF: the band compared, `LO:HI` Hz (default every line above 0 Hz).
    #[arg(long, value_parser = super::frf_band)]
    pub band: Option<(f64, f64)>,
    /// With --frf FRF: the file's dB reference is unknown; take the mean difference measured −
    /// twin off the measured magnitudes first (reported).
    #[arg(long)]
    pub gain_offset: bool,
    /// Threshold line of the latent-variance view (`<plot>-latent.svg`, drawn when the twin has
    /// a corrector), (m/s²)², every floor. Default: each floor's sensor-noise variance from the
    /// twin's calibration — above it the GP is less sure of the bias than a single measurement
    /// is, so the point would be worth learning; for an uncalibrated twin, 1e-3 × each floor's
    /// measured variance on this record.
    #[arg(long)]
    pub latent_threshold: Option<f64>,
    /// A `twin control` report: predict the record as the twin in a closed loop with its
    /// controller (for records of the controlled structure).
    #[arg(long)]
    pub controller: Option<PathBuf>,
    /// Which of the report's designs (its q); default the first stable one.
    #[arg(long, requires = "controller")]
    pub controller_q: Option<f64>,
    /// Also identify the record's modes (LSCF, SSI-COV) and set them beside the twin's, in the
    /// printout and the report's `modes` (information: the time-domain verdict stands). Off by
    /// default: the identification costs several times the comparison.
    #[arg(long)]
    pub modes: bool,
    /// Seconds at the start left out of the error measures.
    #[arg(long, default_value_t = CompareOptions::default().transient, value_parser = super::transient_seconds)]
    pub transient: f64,
    /// Practical significance, NMSE %: an out-of-band window whose NMSE is below it on every
    /// floor that left the band is not a failing window. Default: 2 × the twin's worst
    /// validation NMSE (`twin calibrate --validate`), else 0.5 %.
    #[arg(long)]
    pub tolerance: Option<f64>,
}

impl CompareArgs {
    /// The library's options from the flags.
    pub fn options(&self) -> CompareOptions {
        CompareOptions {
            transient: self.transient,
            tolerance: self.tolerance,
            latent_threshold: self.latent_threshold,
            controller_q: self.controller_q,
        }
    }
}

pub fn run(args: &CompareArgs) -> Result<()> {
    if let Some(plot) = &args.plot {
        check_svg(plot)?;
    }
    let frf_file = args.frf.as_ref().and_then(|f| f.as_deref());
    let data_path = match (&args.data, frf_file) {
        (Some(_), Some(_)) => {
            bail!("give --data D.csv (a time record) or --frf FRF (a measured FRF), not both")
        }
        (None, Some(frf)) => return run_frf(args, frf),
        (Some(data), None) => data,
        (None, None) => bail!("--data D.csv is needed (or --frf FRF with a measured FRF)"),
    };
    if args.band.is_some() || args.gain_offset {
        bail!("--band and --gain-offset go with --frf FRF (a measured FRF)");
    }
    let options = args.options();
    options.validate()?;
    // The record read while the twin's archive is opened.
    let (data, twin) = std::thread::scope(|scope| {
        let data = scope.spawn(|| args.columns.read_any(data_path));
        let twin = Twin::load(args.twin.as_deref());
        let data = data
            .join()
            .unwrap_or_else(|panic| std::panic::resume_unwind(panic));
        (data, twin)
    });
    let (data, twin) = (data?, twin?);
    guard::check_record(&twin, &data)?;
    options.validate_for(&data)?;
    let spec = args
        .controller
        .as_deref()
        .map(ControllerSpec::load)
        .transpose()?;
    let compared = compare(&twin, &data, &options, spec.as_ref(), progress_bar())?;
    // The record's modes, when asked for: identified once for the report and the printout.
    let modes = args.modes.then(|| {
        crate::workflows::modal::modal_evidence(
            &twin,
            &data,
            crate::workflows::modal::ModalBand::default(),
        )
    });
    let report =
        crate::report::json::compare(&twin, &data, &compared, args.transient, modes.as_ref());
    let Compared {
        prediction,
        comparison,
        parameter_variance,
        noise_nmse,
        band_nmse,
        tolerance,
        ..
    } = &compared;

    // Everything is computed before anything is written: a failure leaves no partial output.
    if let Some(path) = &args.predictions {
        crate::fsutil::write_atomically(path, |file| predictions_csv(file, prediction))?;
    }
    if let Some(path) = &args.report {
        write_json(path, &report)?;
    }
    if let Some(path) = &args.plot {
        plot(&twin, &data, &compared, &options, path, args.frf.is_some())?;
    }
    print_summary(&twin, &data, comparison);
    match &modes {
        Some(Ok(evidence)) => print_modes(evidence),
        Some(Err(e)) => println!("modes: not identified ({e})"),
        None => {}
    }
    if parameter_variance.is_some() {
        let join = |values: Vec<f64>| {
            values
                .iter()
                .map(|v| format!("{v:.3}"))
                .collect::<Vec<_>>()
                .join(" / ")
        };
        let explained = noise_nmse.iter().zip(band_nmse).map(|(n, b)| n + b);
        println!(
            "band: noise + parameter uncertainty, explains NMSE {} % (noise {} %)",
            join(explained.collect()),
            join(noise_nmse.clone())
        );
    }
    println!(
        "tolerance: {:.3} % NMSE ({}){}",
        tolerance.value,
        tolerance.source,
        match comparison.windows_below_tolerance {
            0 => String::new(),
            n => format!("; {n} out-of-band window(s) below it not counted"),
        }
    );
    Ok(())
}

/// `--plot PATH [--frf]`: what the plot shows computed (`workflows::compare::compare_plot`; an
/// error in it named by the plot's path), then drawn.
fn plot(
    twin: &Twin,
    data: &Measurement,
    compared: &Compared,
    options: &CompareOptions,
    path: &std::path::Path,
    frf: bool,
) -> Result<()> {
    let view = crate::workflows::compare::compare_plot(twin, data, compared, options, frf)
        .map_err(|message| crate::report::ReportError::BadInput {
            path: path.to_owned(),
            message,
        })?;
    crate::report::plot_compared(&compared.comparison, &data.excitation.channel, &view, path)?;
    Ok(())
}

/// `time` and every predicted channel by name (`acc1,acc2,acc3` on the paper's rig), in SI;
/// then the corrector's latent variance and sd of each channel it corrects, named as its
/// outputs are (`latent_var<i>`, `sd<i>` for `acc<i>`; `latent_var_vel2`, `sd_vel2` …).
fn predictions_csv(out: &mut impl std::io::Write, p: &Prediction) -> std::io::Result<()> {
    let mut columns: Vec<(String, &[f64])> = p
        .channels
        .iter()
        .map(|c| (c.channel.name(), c.values.as_slice()))
        .collect();
    for prefix in ["latent_var", "sd"] {
        for c in &p.channels {
            let band = if prefix == "sd" { &c.sd } else { &c.latent_var };
            if let Some(values) = band {
                columns.push((
                    fmu_gp_corrector::layout::band_name(prefix, &c.channel),
                    values.as_slice(),
                ));
            }
        }
    }
    crate::record::columns_csv(out, &p.time, &columns)
}

/// The record's modes beside the twin's, one line per paired mode.
pub(crate) fn print_modes(e: &crate::workflows::modal::ModalEvidence) {
    println!(
        "modes ({} on the record; band: {} sd, at least {} %):",
        e.method, e.band.sigmas, e.band.tolerance
    );
    for m in &e.modes {
        let sd = |v: Option<f64>| v.map(|s| format!(" ± {s:.4}")).unwrap_or_default();
        println!(
            "  mode {}: twin {:.4}{} Hz, record {:.4}{} Hz: {:+.2} %{}; ζ {:.2} → {:.2} %; MAC {:.3}{}",
            m.pair.twin_mode,
            m.pair.twin_frequency,
            sd(m.twin_frequency_sd),
            m.pair.observed_frequency,
            sd(m.observed_frequency_sd),
            m.pair.frequency_shift_percent,
            m.pair
                .frequency_shift_sd
                .map(|s| format!(" ({s:+.1} sd)"))
                .unwrap_or_default(),
            100.0 * m.twin_damping,
            100.0 * m.observed_damping,
            m.pair.mac,
            if m.outside { "  OUTSIDE the band" } else { "" }
        );
        if let Some(f) = m.other_frequency {
            println!("           (SSI-COV: {f:.4} Hz)");
        }
    }
    if !e.comparison.unpaired_twin.is_empty() {
        println!(
            "  twin modes not found on the record: {:?}",
            e.comparison.unpaired_twin
        );
    }
}

fn print_summary(twin: &Twin, data: &Measurement, c: &Comparison) {
    println!("twin: {}", twin.describe());
    println!(
        "data: {} ({} samples, {} Hz)",
        data.path.display(),
        data.len(),
        1.0 / data.dt
    );
    println!("{:<8} {:>10} {:>12}", "channel", "NMSE %", "noise sd");
    for (i, name) in c.names().iter().enumerate() {
        println!("{:<8} {:>10.3} {:>12.4e}", name, c.nmse[i], c.noise_sd[i]);
    }
    if c.failing_windows.is_empty() {
        println!("failing windows: none (the residual stays inside ±3σ)");
    } else {
        println!("failing windows ({}):", c.failing_windows.len());
        for w in &c.failing_windows {
            let nmse: Vec<String> = w.nmse.iter().map(|v| format!("{v:.1}")).collect();
            println!(
                "  {:>7.2}–{:<7.2} s  {:<14} NMSE {} %",
                w.start,
                w.end,
                w.channels.join(","),
                nmse.join(" / ")
            );
        }
    }
}

/// `twin compare --frf FRF`: the twin's exact FRF against a measured one.
fn run_frf(args: &CompareArgs, path: &std::path::Path) -> Result<()> {
    if args.controller.is_some() || args.predictions.is_some() {
        bail!("--controller and --predictions go with --data (a time record), not --frf FRF");
    }
    let frf = args.columns.read_frf(path)?;
    let twin = Twin::load(args.twin.as_deref())?;
    let view = crate::workflows::compare::frf_view(&twin, &frf, args.band, args.gain_offset)?;
    let svg = match &args.plot {
        Some(p) => Some(crate::report::frf_plot::draw_frf_comparison(
            &view,
            &format!("{} on {}", twin.describe(), path.display()),
            p,
        )?),
        None => None,
    };
    if let Some(report) = &args.report {
        write_json(report, &view)?;
    }
    if let (Some(p), Some(svg)) = (&args.plot, svg) {
        crate::fsutil::write_text_atomically(p, &svg)?;
    }
    println!("twin: {}", twin.describe());
    println!(
        "FRF: {} ({} channels, {} lines {:.3}–{:.3} Hz)",
        path.display(),
        view.channels.len(),
        view.frequency.len(),
        view.frequency[0],
        view.frequency[view.frequency.len() - 1]
    );
    if let Some(g) = view.gain_offset_db {
        println!("gain offset {g:+.2} dB taken off the measured magnitudes (unknown dB reference)");
    }
    println!(
        "{:<8} {:>16} {:>16}",
        "channel", "RMS error (dB)", "inside ±3σ %"
    );
    for c in &view.channels {
        println!(
            "{:<8} {:>16.2} {:>16}",
            c.channel,
            c.rms_error_db,
            c.inside_band
                .map(|b| format!("{:.1}", 100.0 * b))
                .unwrap_or_else(|| "–".into())
        );
    }
    println!("error: {}", view.error_measure);
    super::calibrate::print_modes(&view.twin_modes, &view.measured_peaks);
    println!("measured peaks: {}", view.peak_method);
    Ok(())
}
