//! The `twin` commands: arguments → validated configuration → work → files written atomically.
//! One file per subcommand; everything that parses arguments, prints or writes a report lives
//! here, and the library underneath returns typed errors.

use crate::choice::Choice;
use std::io::Write;
use std::path::Path;

use anyhow::Result;
use clap::{Parser, Subcommand};

use crate::record::{ColumnMap, Measurement, ReadOptions};
pub(crate) use crate::twin::run::Compared;
use crate::twin::run::Progress;

pub mod add_physics;
pub mod calibrate;
pub mod compare;
pub mod control;
pub mod diagnose;
pub mod export_fmus;
pub mod fleet;
pub mod hybrid;
pub mod init;
pub mod learn;
pub mod modal;
pub mod pack_fmu;
pub mod run;
pub mod serve;
pub mod synth;
pub mod train;
pub mod watch;

#[derive(Parser)]
#[command(
    name = "twin",
    version,
    about = "shear-twin: an operational digital twin of a shear frame, on FMI 2.0"
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand)]
pub enum Command {
    /// Run the twin on a measurement's force and compare its accelerations with the measured ones.
    Compare(compare::CompareArgs),
    /// MAP calibration of the physics parameters and noise variances on a measurement.
    Calibrate(calibrate::CalibrateArgs),
    /// Train the Gaussian-process bias corrector on a record and put it behind the physics FMU.
    Train(train::TrainArgs),
    /// Package a built FMU library and its modelDescription.xml into a .fmu archive.
    PackFmu(pack_fmu::PackArgs),
    /// Write the FMUs built into this twin (shear, GP corrector, LQR, substructure) as
    /// DIR/<modelIdentifier>.fmu, for other FMI tools.
    ExportFmus(export_fmus::ExportFmusArgs),
    /// Write the default twin (the shear FMU, default parameters) as an SSP archive.
    Init(init::InitArgs),
    /// Make a synthetic measurement record (the synthetic physical twin) and its truth JSON.
    Synth(synth::SynthArgs),
    /// Stream-based active learning of the GP corrector over records (paper Algorithm 1).
    Learn(learn::LearnArgs),
    /// Diagnose a failing twin: none, recalibrate, add physics (which effect, where, how
    /// strong) or update the data-based model, with the evidence.
    Diagnose(diagnose::DiagnoseArgs),
    /// The structure by its modes: natural frequencies, damping ratios and mode shapes of the
    /// twin, each with its sd from the calibration's posterior.
    Modal(modal::ModalArgs),
    /// Switch an effect of the shear FMU's library on, estimate its parameters, write the twin.
    AddPhysics(add_physics::AddPhysicsArgs),
    /// Run any FMI 2.0 co-simulation FMU or SSP system and record its outputs as CSV.
    Run(run::RunArgs),
    /// LQR control designed on the twin: attenuation, control effort and contact initiations,
    /// passive and under each design; retuning and gain scheduling informed by the twin.
    Control(control::ControlArgs),
    /// The simulated real-time hybrid test: numerical and physical substructures joined by an
    /// actuator; the excitation at which contact starts, spectra, the contact law learned.
    Hybrid(hybrid::HybridArgs),
    /// The operational twin on a live stream (standard input or a growing CSV file): the twin
    /// stepped per sample, rolling NMSE, failing windows online, alerts as JSON lines,
    /// checkpoints to resume from.
    Watch(watch::WatchArgs),
    /// Run compare, diagnose and calibrate for many structures (a manifest) as tasks on Dask:
    /// a LocalCluster, or `--scheduler tcp://HOST:PORT`; a fleet report (CSV, Parquet, plot).
    /// Runs `python -m shear_twin.fleet` in the project's venv (`twin fleet -- --help`: its options).
    Fleet(fleet::FleetArgs),
    /// The live page over what is already there: a finished watch (its alerts, checkpoint and
    /// diagnoses), a record against its twin, or a fleet report.
    Serve(serve::ServeArgs),
}

pub fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Compare(args) => compare::run(&args),
        Command::Calibrate(args) => calibrate::run(&args),
        Command::Train(args) => train::run(&args),
        Command::PackFmu(args) => pack_fmu::run(args),
        Command::ExportFmus(args) => export_fmus::run(&args),
        Command::Init(args) => init::run(&args),
        Command::Synth(args) => synth::run(&args),
        Command::Learn(args) => learn::run(&args),
        Command::Diagnose(args) => diagnose::run(&args),
        Command::Modal(args) => modal::run(&args),
        Command::AddPhysics(args) => add_physics::run(&args),
        Command::Run(args) => run::run(&args),
        Command::Control(args) => control::run(&args),
        Command::Hybrid(args) => hybrid::run(&args),
        Command::Watch(args) => watch::run(&args),
        Command::Fleet(args) => fleet::run(&args),
        Command::Serve(args) => serve::run(&args),
    }
}

/// `--transient`: seconds at the start of a record left out; checked here once for every command.
pub(crate) fn transient_seconds(text: &str) -> Result<f64, String> {
    match text.trim().parse::<f64>() {
        Ok(t) if t >= 0.0 && t.is_finite() => Ok(t),
        _ => Err("must be a non-negative number of seconds".into()),
    }
}

/// The parser of an option whose values the library names ([`Choice`]): each name with its
/// line of help in `--help`, the value itself parsed.
pub(crate) fn choice<T: Choice + Send + Sync>() -> impl clap::builder::TypedValueParser<Value = T> {
    use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
    PossibleValuesParser::new(
        T::CHOICES
            .iter()
            .map(|&(name, help, _)| PossibleValue::new(name).help(help)),
    )
    .map(|name| T::from_name(&name).expect("clap accepts the listed names only"))
}

pub(crate) use crate::fsutil::{write_atomically, write_text_atomically};

/// `value` as pretty JSON and a newline, written atomically.
pub(crate) fn write_json(path: &Path, value: &impl serde::Serialize) -> Result<()> {
    write_atomically(path, |f| {
        // Buffered: serde_json writes token by token, a syscall each on a bare file (a modal
        // report of a one-hour record spent half its time there).
        let mut w = std::io::BufWriter::new(&mut *f);
        serde_json::to_writer_pretty(&mut w, value)?;
        w.write_all(b"\n")?;
        w.flush()
    })?;
    Ok(())
}

pub(crate) fn progress_bar() -> impl FnMut(u64, u64) {
    let mut bar: Option<indicatif::ProgressBar> = None;
    let mut progress = Progress::new(move |done, total| {
        let b = bar.get_or_insert_with(|| indicatif::ProgressBar::new(total));
        b.set_position(done);
        if done == total {
            b.finish_and_clear();
        }
    });
    move |done, total| progress.tick(done, total)
}

/// `--columns MAP.json` of the commands that read records.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct ColumnsArg {
    /// Header names the records use for the twin's, as a JSON object, e.g.
    /// `{"dotx1 (m/s)": "vel1", "fp (N)": "force"}` (a key without a unit matches the name
    /// with any unit, which goes with it).
    #[arg(long, value_name = "MAP.json")]
    pub columns: Option<std::path::PathBuf>,
}

impl ColumnsArg {
    /// Read a record with the column map applied, whatever it measures; check it against the
    /// twin with `twin::guard` before any work.
    pub fn read_any(&self, path: &Path) -> Result<Measurement> {
        let columns = match &self.columns {
            Some(map) => ColumnMap::read(map)?,
            None => ColumnMap::default(),
        };
        Ok(Measurement::read_with(path, &ReadOptions { columns })?)
    }

    /// Read a record that may lack the excitation: Ok(Err(ambient)) when its header has none.
    pub fn read_or_ambient(
        &self,
        path: &Path,
    ) -> Result<std::result::Result<Measurement, crate::record::AmbientRecord>> {
        let columns = match &self.columns {
            Some(map) => ColumnMap::read(map)?,
            None => ColumnMap::default(),
        };
        let options = ReadOptions { columns };
        Ok(if crate::record::has_excitation_column(path, &options)? {
            Ok(Measurement::read_with(path, &options)?)
        } else {
            Err(crate::record::AmbientRecord::read(path, &options)?)
        })
    }

    /// Read a measured FRF with the column map applied.
    pub fn read_frf(&self, path: &Path) -> Result<crate::record::frf::MeasuredFrf> {
        let columns = match &self.columns {
            Some(map) => ColumnMap::read(map)?,
            None => ColumnMap::default(),
        };
        Ok(crate::record::frf::MeasuredFrf::read(path, &columns)?)
    }
}

/// `--band LO:HI` (Hz).
pub fn frf_band(text: &str) -> Result<(f64, f64), String> {
    let (lo, hi) = text
        .split_once(':')
        .ok_or_else(|| format!("'{text}': give the band as LO:HI in Hz, e.g. 3:40"))?;
    let number = |s: &str| {
        s.trim()
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite() && *v >= 0.0)
            .ok_or_else(|| format!("'{s}' in the band '{text}' is not a non-negative number (Hz)"))
    };
    let (lo, hi) = (number(lo)?, number(hi)?);
    if hi <= lo {
        return Err(format!("the band '{text}' is empty: LO must be below HI"));
    }
    Ok((lo, hi))
}
