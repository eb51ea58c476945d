//! `twin calibrate`: MAP calibration of the physics parameters and noise variances.

use std::path::PathBuf;

use anyhow::{bail, Result};

use super::write_json;
use crate::twin::data::Measurement;
use crate::twin::{RecordRef, RecordRole, Twin};
use crate::workflows::calibrate::validated::{check_plot, ChannelNmse};
use crate::workflows::calibrate::{
    calibrate_validated, default_parameters, read_priors, Calibration, CalibrationSetup,
    RecordCalibration,
};
use crate::workflows::options::check_svg;

#[derive(clap::Args)]
pub struct CalibrateArgs {
    #[command(flatten)]
    pub columns: super::ColumnsArg,
    /// Measurement CSV(s) to calibrate on. Several are runs of one test (one MAP over all: the
    /// structure's parameters shared, each run its own excitation, measured channels and noise
    /// variances), e.g. a roving accelerometer moved floor to floor.
    #[arg(long, num_args = 1.., required_unless_present = "frf", conflicts_with = "frf")]
    pub data: Vec<PathBuf>,
    /// A measured FRF to calibrate on instead of records (CSV: `frequency` and per channel
    /// `<ch>_re,<ch>_im` or `<ch>_db`; or a universal file, dataset 58): the MAP of the twin's
    /// linear structure (m, c, k) on the log magnitude (and the phase where given), resonances
    /// weighted.
    #[arg(long, value_name = "FRF")]
    pub frf: Option<PathBuf>,
    /// With --frf: the band used, `LO:HI` Hz (default every line above 0 Hz).
    #[arg(long, requires = "frf", value_parser = super::frf_band)]
    pub band: Option<(f64, f64)>,
    /// With --frf: the file's dB reference is unknown; fit a gain offset (dB) on the magnitudes
    /// as a nuisance parameter, reported.
    #[arg(long, requires = "frf")]
    pub gain_offset: bool,
    /// The twin to start from (.ssp); the default twin when absent. It is not modified.
    #[arg(long)]
    pub twin: Option<PathBuf>,
    /// The calibrated twin (.ssp) to write.
    #[arg(long)]
    pub out: PathBuf,
    /// A real parameter of the physics FMU to calibrate (repeat); default every floor's mass
    /// and storey's damping and stiffness, m1..mN, c1..cN, k1..kN.
    #[arg(long = "param")]
    pub params: Vec<String>,
    /// JSON file of priors over the twin's (`twin init --priors`) and the defaults (the paper's
    /// rig: Table 1; a structure from `twin init --nominal`: centred on the nominal, mass sd
    /// 10 %, stiffness log-sd 0.25, damping log-sd 1). Keys a family (m, c, k) or a parameter;
    /// fields space (linear|log), value or mean, and one of sd, variance, relative_sd:
    /// {"k": {"relative_sd": 0.3}, "k1": {"space": "linear", "mean": 4021, "variance": 10000}}.
    #[arg(long, value_name = "P.json")]
    pub priors: Option<PathBuf>,
    /// Seconds at the start of the record left out of the likelihood.
    #[arg(long, default_value_t = CalibrationSetup::default().transient, value_parser = super::transient_seconds)]
    pub transient: f64,
    /// Optimiser starts (the prior mean plus draws from the widened prior); default 12, with
    /// --frf 4 (each start is cheap there, and the prior mean start is usually the best).
    #[arg(long)]
    pub starts: Option<usize>,
    #[arg(long, default_value_t = CalibrationSetup::default().seed)]
    pub seed: u64,
    /// Other records to report the calibrated twin's NMSE on.
    #[arg(long, num_args = 1..)]
    pub validate: Vec<PathBuf>,
    /// JSON report.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Plot (.svg) of the calibrated twin on the calibration record.
    #[arg(long)]
    pub plot: Option<PathBuf>,
}

pub fn run(args: &CalibrateArgs) -> Result<()> {
    if args.twin.as_deref() == Some(args.out.as_path()) {
        bail!(
            "--out {} is the input twin; the old twin is kept, so write the new one elsewhere",
            args.out.display()
        );
    }
    if let Some(plot) = &args.plot {
        check_svg(plot)?;
    }
    if let Some(frf) = &args.frf {
        if !args.validate.is_empty() {
            bail!("--validate takes time records; with --frf, compare the twin on them afterwards");
        }
        return run_frf(args, frf);
    }
    let runs = args
        .data
        .iter()
        .map(|p| args.columns.read_any(p))
        .collect::<Result<Vec<_>, _>>()?;
    let validation = args
        .validate
        .iter()
        .map(|p| args.columns.read_any(p))
        .collect::<Result<Vec<_>, _>>()?;
    let twin = Twin::load(args.twin.as_deref())?;
    let runs: Vec<&Measurement> = runs.iter().collect();
    if args.plot.is_some() {
        check_plot(&twin, &runs)?;
    }
    let mut setup = CalibrationSetup {
        transient: args.transient,
        starts: args.starts.unwrap_or(CalibrationSetup::default().starts),
        seed: args.seed,
        parameters: default_parameters(&twin)?,
        ..CalibrationSetup::default()
    };
    if !args.params.is_empty() {
        setup.parameters = args.params.clone();
    }
    if let Some(path) = &args.priors {
        setup.prior_spec = Some(read_priors(path).map_err(anyhow::Error::msg)?);
    }
    let validation: Vec<&Measurement> = validation.iter().collect();
    let mut result = calibrate_validated(&twin, &runs, &validation, &setup)?;
    // The records, for `twin add-physics` to refit over.
    result.twin.records = args
        .data
        .iter()
        .map(|p| RecordRef::of(p, RecordRole::Calibration))
        .chain(
            args.validate
                .iter()
                .map(|p| RecordRef::of(p, RecordRole::Validation)),
        )
        .collect::<Result<_, _>>()?;
    let data = runs[0];

    // All computed: now write, each file atomically.
    result.twin.write(&args.out)?;
    if let Some(path) = &args.report {
        let report =
            crate::report::json::calibrate(&twin, Some(&args.out), data, args.transient, &result);
        write_json(path, &report)?;
    }
    if let Some(path) = &args.plot {
        let comparison =
            crate::twin::run::run_and_compare(&result.twin, data, args.transient, |_, _| {})?
                .comparison;
        crate::report::plot_calibrated(&comparison, data, path)?;
    }

    print_calibration(&runs, &result.calibration, &result.validated);
    let tolerance = &result.tolerance;
    println!(
        "tolerance of compare and diagnose: {:.3} % NMSE ({})",
        tolerance.value, tolerance.source
    );
    println!("wrote {}", args.out.display());
    Ok(())
}

/// What `twin calibrate` prints of a calibration on `runs` (the first the report's record): the
/// starts and the ladder, the MAP table, the noise, the strongest correlations, the NMSE on
/// every run and on every validation record.
/// Whether the calibration was on one record that measured the paper rig's channels alone, in
/// any order (it is then printed as it has always been, per floor). Sorted, the rig's names
/// are in floor order.
/// One record of the rig's accelerometers in the rig's order: its noise and NMSE lines are
/// printed floor by floor (`noise1`, …). Any other order prints each line by its channel's
/// name (floor by floor would label a channel by its column).
fn is_rig_record(records: &[RecordCalibration]) -> bool {
    let [record] = records else {
        return false;
    };
    ::structure::paper::is_paper_rig(record.channels.as_slice())
}

fn print_calibration(runs: &[&Measurement], calibration: &Calibration, validated: &[ChannelNmse]) {
    let names: Vec<String> = runs.iter().map(|r| r.path.display().to_string()).collect();
    println!(
        "calibrated on {} ({} starts, {} simulations, {:.2} s)",
        names.join(", "),
        calibration.starts.len(),
        calibration.simulations,
        calibration.seconds
    );
    if let Some((first, higher)) = calibration.heads.split_first() {
        let then: String = higher
            .iter()
            .map(|n| format!("on the first {n} samples, then "))
            .collect();
        println!(
            "long records: the starts screened on the first {first} samples of each, the best \
             refined {then}on every sample"
        );
    }
    print_parameters(calibration);
    let paper = is_rig_record(&calibration.records);
    print_noise(calibration, paper);
    print_correlations(calibration);
    if paper {
        println!(
            "NMSE % on {}: {}",
            runs[0].path.display(),
            per_floor(&calibration.nmse)
        );
    } else {
        for r in &calibration.records {
            println!(
                "NMSE % on {}: {}",
                r.record,
                per_channel(&r.channels, &r.nmse)
            );
        }
    }
    for v in validated {
        let shown = if ::structure::paper::is_paper_rig(v.channels.as_slice()) {
            per_floor(&v.nmse)
        } else {
            per_channel(&v.channels, &v.nmse)
        };
        println!(
            "NMSE % on {}: {shown}{}",
            v.data,
            if v.accepted {
                ""
            } else {
                " (above the cap: not taken as the twin's validation level)"
            }
        );
    }
}

/// The MAP, sd and prior mean of each parameter, a row each.
fn print_parameters(calibration: &Calibration) {
    println!(
        "{:<10} {:>12} {:>12} {:>14}",
        "parameter", "MAP", "sd", "prior mean"
    );
    for p in &calibration.parameters {
        println!(
            "{:<10} {:>12.4} {:>12.4} {:>14.4}",
            p.name,
            p.value,
            p.sd,
            p.prior.value(p.prior.mean)
        );
    }
}

/// The noise variances: the paper's rig's as it has always been printed (`noise1..`), any
/// other record's by channel and record.
fn print_noise(calibration: &Calibration, paper: bool) {
    if paper {
        let noise = calibration
            .noise_variance
            .iter()
            .zip(&calibration.noise_log_sd);
        for (f, (variance, log_sd)) in noise.enumerate() {
            println!(
                "noise{}     {:>12.4e} (σ² in (m/s²)²; sd of log σ² {:.3})",
                f + 1,
                variance,
                log_sd
            );
        }
        return;
    }
    for r in &calibration.records {
        for (c, name) in r.channels.iter().enumerate() {
            println!(
                "noise {:<6} {:>12.4e} (σ² in SI²; sd of log σ² {:.3}) on {}",
                name, r.noise_variance[c], r.noise_log_sd[c], r.record
            );
        }
    }
}

/// The three strongest posterior correlations between parameters.
fn print_correlations(calibration: &Calibration) {
    let names: Vec<&str> = calibration
        .parameters
        .iter()
        .map(|p| p.name.as_str())
        .collect();
    let mut strongest = Vec::new();
    for a in 0..names.len() {
        for b in a + 1..names.len() {
            strongest.push((calibration.correlation[a][b], names[a], names[b]));
        }
    }
    strongest.sort_by(|x, y| y.0.abs().total_cmp(&x.0.abs()));
    let shown: Vec<String> = strongest
        .iter()
        .take(3)
        .map(|(r, a, b)| format!("{a}–{b} {r:+.2}"))
        .collect();
    println!("strongest correlations: {}", shown.join(", "));
}

/// The rig's NMSE, floor by floor (its channels are its floors).
fn per_floor(nmse: &[f64]) -> String {
    let shown: Vec<String> = nmse.iter().map(|n| format!("{n:.3}")).collect();
    shown.join(" / ")
}

fn per_channel(channels: &[String], nmse: &[f64]) -> String {
    channels
        .iter()
        .zip(nmse)
        .map(|(c, n)| format!("{c} {n:.3}"))
        .collect::<Vec<_>>()
        .join(" / ")
}

/// `twin calibrate --frf FRF --out T.ssp`.
fn run_frf(args: &CalibrateArgs, path: &std::path::Path) -> Result<()> {
    use crate::workflows::calibrate::frf::{calibrate_frf, FrfSetup};
    let frf = args.columns.read_frf(path)?;
    let twin = Twin::load(args.twin.as_deref())?;
    let setup = FrfSetup {
        parameters: args.params.clone(),
        prior_spec: match &args.priors {
            Some(p) => Some(read_priors(p).map_err(anyhow::Error::msg)?),
            None => None,
        },
        band: args.band,
        gain_offset: args.gain_offset,
        starts: args.starts.unwrap_or(FrfSetup::default().starts),
        seed: args.seed,
    };
    let (new_twin, calibration) = calibrate_frf(&twin, &frf, &setup)?;
    let plot = match &args.plot {
        Some(p) => Some(crate::report::frf_plot::draw_frf_comparison(
            &crate::workflows::compare::frf_view(&new_twin, &frf, args.band, args.gain_offset)?,
            &format!("{} on {}", new_twin.describe(), path.display()),
            p,
        )?),
        None => None,
    };
    // All computed: now write, each file atomically.
    new_twin.write(&args.out)?;
    if let Some(report) = &args.report {
        write_json(report, &calibration)?;
    }
    if let (Some(p), Some(svg)) = (&args.plot, plot) {
        crate::fsutil::write_text_atomically(p, &svg)?;
    }
    println!(
        "calibrated on the FRF {} ({} channels, {} lines {:.3}–{:.3} Hz; {} starts, {:.2} s)",
        path.display(),
        calibration.channels.len(),
        calibration.lines,
        calibration.band_hz.0,
        calibration.band_hz.1,
        calibration.starts.len(),
        calibration.seconds
    );
    println!(
        "{:<10} {:>12} {:>12} {:>14}",
        "parameter", "MAP", "sd", "prior mean"
    );
    for p in &calibration.parameters {
        println!(
            "{:<10} {:>12.4} {:>12.4} {:>14.4}",
            p.name,
            p.value,
            p.sd,
            p.prior.value(p.prior.mean)
        );
    }
    if let Some(g) = &calibration.gain_offset_db {
        println!(
            "gain offset {:+.2} ± {:.2} dB (measured − twin; the file's dB reference is unknown)",
            g.value, g.sd
        );
    }
    for (c, name) in calibration.channels.iter().enumerate() {
        println!(
            "{name:<6} magnitude error RMS {:.2} dB (resonance-weighted sd {:.2} dB){}",
            calibration.rms_error_db[c],
            calibration.magnitude_sd_db[c],
            calibration.phase_sd_rad[c]
                .map(|s| format!(", phase sd {s:.3} rad"))
                .unwrap_or_default()
        );
    }
    print_modes(&calibration.twin_modes, &calibration.measured_peaks);
    println!("wrote {}", args.out.display());
    Ok(())
}

/// The twin's modes beside the measured peaks, nearest first.
pub fn print_modes(
    twin: &[crate::workflows::calibrate::frf::TwinMode],
    measured: &[crate::workflows::calibrate::frf::MeasuredPeak],
) {
    println!(
        "{:<5} {:>18} {:>9} {:>14} {:>9} {:>8}",
        "mode", "twin f (Hz) ± sd", "twin ζ %", "measured peak", "ζ % (½P)", "Δf %"
    );
    for (i, m) in twin.iter().enumerate() {
        let nearest = measured.iter().min_by(|a, b| {
            (a.frequency_hz - m.frequency_hz.value)
                .abs()
                .total_cmp(&(b.frequency_hz - m.frequency_hz.value).abs())
        });
        let (peak, zeta, shift) = match nearest {
            Some(p) => (
                format!("{:.3}", p.frequency_hz),
                p.damping_ratio
                    .map(|z| format!("{:.2}", 100.0 * z))
                    .unwrap_or_else(|| "–".into()),
                format!(
                    "{:+.2}",
                    100.0 * (m.frequency_hz.value - p.frequency_hz) / p.frequency_hz
                ),
            ),
            None => ("–".into(), "–".into(), "–".into()),
        };
        println!(
            "{:<5} {:>10.3} ± {:<6.3} {:>9.2} {:>14} {:>9} {:>8}",
            i + 1,
            m.frequency_hz.value,
            m.frequency_hz.sd,
            100.0 * m.damping_ratio,
            peak,
            zeta,
            shift
        );
    }
}
