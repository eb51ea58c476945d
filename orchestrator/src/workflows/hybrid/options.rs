//! `twin hybrid`'s options, their defaults and checks, the test set up from them and the two
//! reports, once for the CLI and the Python package.

use std::collections::BTreeMap;
use std::io::Read;
use std::path::{Path, PathBuf};

use numerics::actuator::{ActuatorSpec, Compensation};
use numerics::excitation::ExcitationSpec;
use serde::Serialize;

use super::experiment::{
    runs, threshold_curve, Coupling, InterfaceNoise, RunOutcome, RunSummary, Setup, ThresholdCurve,
    ThresholdPoint,
};
use super::{unit_peak, Cut, HybridError, Split};
use crate::twin::{ParameterValue, Twin, TwinError, PHYSICS};
use crate::workflows::control::design::structure_of;
use crate::workflows::control::ControlError;
use crate::workflows::options::InvalidOption;

#[derive(Debug, thiserror::Error)]
pub enum HybridTestError {
    #[error(transparent)]
    Options(#[from] InvalidOption),
    #[error(transparent)]
    Hybrid(#[from] HybridError),
    #[error(transparent)]
    Twin(#[from] TwinError),
    #[error(transparent)]
    Control(#[from] ControlError),
    #[error(transparent)]
    Excitation(#[from] numerics::excitation::ExcitationError),
}

/// What `twin hybrid threshold` and `twin hybrid run` share.
#[derive(Clone, Debug, PartialEq)]
pub struct HybridOptions {
    /// A `time,force` CSV as the excitation (None: Clough–Penzien filtered noise under a
    /// build-up / strong / decay envelope, from `seed`, `duration`, `sample_rate`).
    pub excitation: Option<PathBuf>,
    pub seed: u64,
    /// s.
    pub duration: f64,
    /// Hz.
    pub sample_rate: f64,
    /// Control steps per excitation sample.
    pub substeps: u32,
    /// Gap d of the bumper between floors 2 and 3, m.
    pub gap: f64,
    /// Stiffness of the closed bumper, N/m.
    pub contact_stiffness: f64,
    /// The actuator's pure delay, s.
    pub delay: f64,
    /// The actuator's first-order lag time constant, s (0: none).
    pub lag: f64,
    /// Polynomial extrapolation order compensating delay and lag (None: none).
    pub compensate: Option<usize>,
    /// Stop a run when the interface has put more than this × the excitation's energy in.
    pub energy_factor: f64,
    /// The storey count of the building tested without a twin (the paper's floor and storey N
    /// times); with a twin it must be the twin's. None: the twin's.
    pub storeys: Option<usize>,
    /// Where the structure is cut: the floor the actuator drives and what the specimen holds
    /// (None: the paper's cut at floor 2, floor 1 for two storeys).
    pub split: Option<Cut>,
    pub coupling: Coupling,
}

impl Default for HybridOptions {
    /// The paper's section 5: 20 s at 512 Hz (seed 1), 4 control steps a sample, a 0.5 mm gap
    /// closing at 9 N/mm, an ideal actuator, runs stopped at 10 × the excitation's energy,
    /// the coupling chosen by the actuator.
    fn default() -> Self {
        HybridOptions {
            excitation: None,
            seed: 1,
            duration: 20.0,
            sample_rate: 512.0,
            substeps: 4,
            gap: 5e-4,
            contact_stiffness: 9000.0,
            delay: 0.0,
            lag: 0.0,
            compensate: None,
            energy_factor: 10.0,
            storeys: None,
            split: None,
            coupling: Coupling::Auto,
        }
    }
}

/// `twin hybrid threshold`'s amplitude errors by default: −0.1 to 0.1 by 0.02.
pub fn threshold_a_errs() -> Vec<f64> {
    (0..=10).map(|i| -0.1 + 0.02 * f64::from(i)).collect()
}

/// `twin hybrid run`'s amplitude errors by default.
pub const RUN_A_ERRS: [f64; 2] = [0.0, 0.05];
/// `twin hybrid run`'s peak excitation force by default, N.
pub const RUN_PEAK: f64 = 5.0;

impl Default for InterfaceNoise {
    /// 1 µm on the displacements, 1 mN on the force, 1 mm/s² on floor 2's acceleration, seed 1.
    fn default() -> Self {
        InterfaceNoise {
            displacement: 1e-6,
            force: 1e-3,
            acceleration: 1e-3,
            seed: 1,
        }
    }
}

impl InterfaceNoise {
    pub fn validate(&self) -> Result<(), InvalidOption> {
        for (name, x) in [
            ("--displacement-noise", self.displacement),
            ("--force-noise", self.force),
            ("--acceleration-noise", self.acceleration),
        ] {
            if !(x.is_finite() && x >= 0.0) {
                return Err(InvalidOption(format!(
                    "{name} must be a non-negative number, was {x}"
                )));
            }
        }
        Ok(())
    }
}

/// `--a-err`: each a finite number above −1.
pub fn check_a_err(a: &[f64]) -> Result<(), InvalidOption> {
    if let Some(x) = a.iter().find(|x| !(x.is_finite() && **x > -1.0)) {
        return Err(InvalidOption(format!(
            "--a-err must be a finite number above −1, was {x}"
        )));
    }
    Ok(())
}

/// What the reports share: the substructures' parameters and how the test was set up.
#[derive(Clone, Debug, Serialize)]
pub struct Header {
    pub parameters: BTreeMap<String, f64>,
    pub gap: f64,
    pub contact_stiffness: f64,
    pub control_step: f64,
    pub excitation: String,
    pub actuator: ActuatorSpec,
    /// What the specimen held, by name (`numerics::substructure::Cut`): specimen-floors-2-3
    /// (the paper's) or specimen-floor-3 on the paper's rig.
    pub split: String,
    pub coupling: Coupling,
}

impl HybridOptions {
    /// The test on `twin`'s structure (its m, c, k) as the options set it up, and the reports'
    /// header.
    pub fn setup(&self, twin: &Twin) -> Result<(Setup, Header), HybridTestError> {
        let c = self;
        let s = self.structure(twin)?;
        let n = s.storeys();
        let cut = self.checked_cut(twin, n)?;
        let structure = super::cut(&s, cut.floor, c.gap, c.contact_stiffness);
        structure.check().map_err(HybridError::Setup)?;
        if c.substeps == 0 {
            return Err(InvalidOption("--substeps must be at least 1".into()).into());
        }
        let (signal, dt, source) = self.excitation()?;
        let actuator = self.actuator();
        let mut parameters = BTreeMap::new();
        for i in 0..s.mass.len() {
            parameters.insert(format!("m{}", i + 1), s.mass[i]);
            parameters.insert(format!("c{}", i + 1), s.damping[i]);
            parameters.insert(format!("k{}", i + 1), s.stiffness[i]);
        }
        let split_name = Cut {
            storeys: None,
            ..cut
        }
        .name(n);
        let setup = Setup {
            structure,
            split: cut.split,
            unit: unit_peak(&signal)?,
            dt,
            substeps: c.substeps,
            actuator,
            energy_factor: c.energy_factor,
            coupling: c.coupling,
        };
        let header = Header {
            parameters,
            gap: c.gap,
            contact_stiffness: c.contact_stiffness,
            control_step: dt / f64::from(c.substeps),
            excitation: source,
            actuator,
            split: split_name,
            coupling: setup.resolved()?,
        };
        Ok((setup, header))
    }

    /// The cut (`--split`, else the paper's at floor min(n, 3) − 1), checked against the
    /// twin's `n` storeys: at least two, the same count the split names, the actuator's floor
    /// below the top.
    fn checked_cut(&self, twin: &Twin, n: usize) -> Result<Cut, HybridTestError> {
        if n < 2 {
            return Err(InvalidOption(format!(
                "{}: a {n}-storey structure cannot be split (the actuator drives a floor with a \
                 storey above it)",
                if self.storeys.is_some() {
                    "--storeys".to_string()
                } else {
                    twin.describe()
                }
            ))
            .into());
        }
        let cut = self.split.unwrap_or(Cut {
            floor: n.min(3) - 1,
            split: Split::FloorPhysical,
            storeys: None,
        });
        if let Some(stated) = cut.storeys.filter(|&stated| stated != n) {
            return Err(InvalidOption(format!(
                "--split {cut}: names a {stated}-storey structure; {} has {n} storeys",
                twin.describe()
            ))
            .into());
        }
        if !(1..n).contains(&cut.floor) {
            return Err(InvalidOption(format!(
                "--split {cut}: the actuator's floor must be 1 to {} of {}'s {n} storeys (the \
                 specimen holds the storey above it, with the bumper)",
                n - 1,
                twin.describe()
            ))
            .into());
        }
        Ok(cut)
    }

    /// The excitation force (`--excitation`'s file, else Clough–Penzien filtered noise of
    /// unit peak), its sample interval and where it came from.
    fn excitation(&self) -> Result<(Vec<f64>, f64, String), HybridTestError> {
        let c = self;
        Ok(match &c.excitation {
            Some(path) => {
                let (force, dt) = crate::record::excitation::read_excitation(path)
                    .map_err(|e| HybridError::Setup(e.to_string()))?;
                (force, dt, path.display().to_string())
            }
            None => {
                let spec = ExcitationSpec {
                    duration: c.duration,
                    sample_rate: c.sample_rate,
                    seed: c.seed,
                    peak_force: 1.0,
                    ..ExcitationSpec::default()
                };
                let force = spec.generate()?;
                (
                    force,
                    1.0 / c.sample_rate,
                    format!(
                        "Clough–Penzien filtered noise, {} s at {} Hz, seed {}",
                        c.duration, c.sample_rate, c.seed
                    ),
                )
            }
        })
    }

    /// The actuator: its delay, lag and compensation, no amplitude error.
    fn actuator(&self) -> ActuatorSpec {
        ActuatorSpec {
            amplitude_error: 0.0,
            delay: self.delay,
            lag: self.lag,
            compensation: match self.compensate {
                Some(order) => Compensation::Polynomial { order },
                None => Compensation::None,
            },
        }
    }
}

impl HybridOptions {
    /// The building tested: `--storeys N` of the paper's floor and storey on the default twin,
    /// else the twin's structure (which `--storeys` must match).
    pub fn structure(&self, twin: &Twin) -> Result<structure::Structure, HybridTestError> {
        match self.storeys {
            Some(n) if twin.source.is_none() => {
                let paper = structure::Structure::default();
                let s = structure::Structure::uniform(
                    n,
                    paper.mass[0],
                    paper.damping[0],
                    paper.stiffness[0],
                    paper.excitation,
                );
                s.validate()
                    .map_err(|e| InvalidOption(format!("--storeys {n}: {e}")))?;
                Ok(s)
            }
            Some(n) => {
                let s = twin_structure(twin)?;
                if s.storeys() != n {
                    return Err(InvalidOption(format!(
                        "--storeys {n}: {} has {} storeys",
                        twin.describe(),
                        s.storeys()
                    ))
                    .into());
                }
                Ok(s)
            }
            None => twin_structure(twin),
        }
    }
}

/// The structure file in a shear FMU built for its building (`twin init --storeys N`).
const STRUCTURE_RESOURCE: &str = "resources/structure.json";

/// The twin's structure: its shear FMU's `resources/structure.json` (what `twin init --storeys
/// N` writes; without it the paper's rig, [`structure_of`]) with the twin's m, c, k set over it.
fn twin_structure(twin: &Twin) -> Result<structure::Structure, HybridTestError> {
    let physics = twin.component(PHYSICS).ok_or_else(|| {
        HybridError::Setup(format!(
            "{} has no '{PHYSICS}' component to split",
            twin.describe()
        ))
    })?;
    let Some(mut s) = structure_resource(&physics.fmu_path)? else {
        return Ok(structure_of(twin)?);
    };
    for name in s.parameter_names() {
        match physics.parameters.get(&name) {
            None => {}
            Some(ParameterValue::Real(x)) if x.is_finite() => {
                s.set(&name, *x);
            }
            Some(other) => {
                return Err(HybridError::Setup(format!(
                    "{}: parameter '{name}' is {other:?}, not a finite real",
                    twin.describe()
                ))
                .into())
            }
        }
    }
    s.validate()
        .map_err(|e| HybridError::Setup(format!("{}: {e}", twin.describe())))?;
    Ok(s)
}

/// The structure in the shear FMU archive at `fmu`, if it carries one.
fn structure_resource(fmu: &Path) -> Result<Option<structure::Structure>, HybridTestError> {
    let bad = |e: String| HybridError::Setup(format!("{}: {e}", fmu.display()));
    let file = std::fs::File::open(fmu).map_err(|e| bad(e.to_string()))?;
    let mut archive = zip::ZipArchive::new(file).map_err(|e| bad(e.to_string()))?;
    let mut entry = match archive.by_name(STRUCTURE_RESOURCE) {
        Ok(entry) => entry,
        Err(zip::result::ZipError::FileNotFound) => return Ok(None),
        Err(e) => return Err(bad(e.to_string()).into()),
    };
    let mut text = String::new();
    entry
        .read_to_string(&mut text)
        .map_err(|e| bad(format!("{STRUCTURE_RESOURCE}: {e}")))?;
    let resource: fmu_shear::StructureResource =
        serde_json::from_str(&text).map_err(|e| bad(format!("{STRUCTURE_RESOURCE}: {e}")))?;
    Ok(Some(resource.structure))
}

/// `twin hybrid threshold --report`.
#[derive(Clone, Debug, Serialize)]
pub struct ThresholdReport {
    #[serde(flatten)]
    pub header: Header,
    pub thresholds: Vec<ThresholdPoint>,
    pub failed: Vec<(f64, String)>,
    pub seconds: f64,
}

/// `twin hybrid run --report`.
#[derive(Clone, Debug, Serialize)]
pub struct RunReport {
    #[serde(flatten)]
    pub header: Header,
    pub peak: f64,
    pub noise: InterfaceNoise,
    pub runs: Vec<RunSummary>,
}

/// `twin hybrid threshold`: the peak force at which contact starts for each amplitude error
/// (None: [`threshold_a_errs`]). The report and the curve (for the plot).
pub fn threshold(
    twin: &Twin,
    options: &HybridOptions,
    a_errs: Option<&[f64]>,
) -> Result<(ThresholdReport, ThresholdCurve, Setup), HybridTestError> {
    let a_errs = a_errs.map_or_else(threshold_a_errs, <[f64]>::to_vec);
    check_a_err(&a_errs)?;
    let (setup, header) = options.setup(twin)?;
    let curve = threshold_curve(&setup, &a_errs)?;
    let report = ThresholdReport {
        header,
        thresholds: curve.thresholds.clone(),
        failed: curve.failed.clone(),
        seconds: curve.seconds,
    };
    Ok((report, curve, setup))
}

/// `twin hybrid run`: the test at `peak` N for each amplitude error (None: [`RUN_A_ERRS`]),
/// the interface measured with `noise` (its seed: the options' seed). The report and the runs
/// (for the plot).
pub fn run(
    twin: &Twin,
    options: &HybridOptions,
    peak: f64,
    a_errs: Option<&[f64]>,
    noise: InterfaceNoise,
) -> Result<(RunReport, Vec<RunOutcome>, Setup), HybridTestError> {
    let a_errs = a_errs.map_or_else(|| RUN_A_ERRS.to_vec(), <[f64]>::to_vec);
    check_a_err(&a_errs)?;
    noise.validate()?;
    let (setup, header) = options.setup(twin)?;
    let noise = InterfaceNoise {
        seed: options.seed,
        ..noise
    };
    let outcomes = runs(&setup, peak, &a_errs, noise)?;
    let report = RunReport {
        header,
        peak,
        noise,
        runs: outcomes.iter().map(|o| o.summary.clone()).collect(),
    };
    Ok((report, outcomes, setup))
}
