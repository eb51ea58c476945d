//! A twin stored as an SSP 1.0 archive (`.ssp`): `SystemStructure.ssd` describing the system,
//! the FMUs under `resources/`, and each component's parameter values as an `.ssv` parameter
//! set bound to it. The same archive opens in any SSP tool (fmpy's `simulate_ssp` among them).
//!
//! The twin's own figures that are no FMU parameter (the noise variance of each floor's
//! measurement, used for the ±3σ band and by calibration) are parameter connectors of the
//! system, bound to `resources/twin.ssv`. Beside them, when the twin was calibrated and
//! validated: the Laplace posterior covariance of the calibrated physics parameters
//! (`covariance.A.B`, one Real per pair A ≤ B, in the parameters' own units), which widens the
//! comparison's band, and the worst validation NMSE (`validation_nmse`, %), which sets the
//! default tolerance of `twin compare` and `twin diagnose`. And the records the twin was fitted
//! and validated on (`record{i}.path`, absolute, `record{i}.sha256` of the file's bytes,
//! `record{i}.role`: String parameters), so that `twin add-physics` can refit over them and a
//! moved or changed file is named as such.

/// Measurement records live in [`crate::record`]; this path is kept for code written before.
pub use crate::record as data;
pub mod embedded;
pub mod guard;
pub mod linear;
pub mod noise;
pub mod run;
pub mod simulator;
mod ssp_xml;
pub mod structure;
pub mod system;

use ssp_xml::{ssv_xml, ssv_xml_with_strings};

use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};

use crate::cosim::import::{self, Fmu, ImportError, Instance, ScalarType, UnpackLimits};
pub use crate::cosim::ssp::Connection;
use crate::cosim::ssp::{self, parse_ssd, SsvValue};

/// The physics component's name in every twin.
pub const PHYSICS: &str = "physics";
/// The shear FMU's archive name.
pub const SHEAR_FMU: &str = "fmu_shear.fmu";
/// System inputs of the paper rig's twin (a twin of another structure takes `ground_acc` for
/// ground motion, see [`Twin::for_structure`]).
pub const INPUTS: [&str; 2] = ["force", "control_force"];

#[derive(Debug, thiserror::Error)]
pub enum TwinError {
    #[error(transparent)]
    Import(#[from] ImportError),
    #[error("{path}: {message}")]
    Invalid { path: PathBuf, message: String },
    #[error("{0}")]
    Message(String),
    #[error("{twin}: component '{component}' ({fmu}): {inner}")]
    Component {
        twin: String,
        component: String,
        fmu: String,
        inner: Box<TwinError>,
    },
    #[error("{path}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ParameterValue {
    Real(f64),
    Integer(i32),
    Boolean(bool),
}

impl std::fmt::Display for ParameterValue {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ParameterValue::Real(x) => write!(f, "{x}"),
            ParameterValue::Integer(i) => write!(f, "{i}"),
            ParameterValue::Boolean(b) => write!(f, "{b}"),
        }
    }
}

/// The posterior covariance of calibrated physics parameters, in their own units.
#[derive(Debug, Clone, PartialEq)]
pub struct ParameterCovariance {
    pub names: Vec<String>,
    /// `matrix[a][b]` = cov(names[a], names[b]).
    pub matrix: Vec<Vec<f64>>,
}

/// Where a twin keeps its calibration priors (`twin init --priors`).
const PRIORS_RESOURCE: &str = "resources/priors.json";

/// The prefix of the covariance's entries in `resources/twin.ssv`.
const COVARIANCE_PREFIX: &str = "covariance.";

/// One FMU of the twin, with the parameter values the twin gives it.
#[derive(Debug, Clone)]
pub struct Component {
    pub name: String,
    /// File name under `resources/` in the archive.
    pub fmu_name: String,
    /// Where the FMU file is on disk now.
    pub fmu_path: PathBuf,
    pub parameters: BTreeMap<String, ParameterValue>,
}

#[derive(Debug)]
pub struct Twin {
    pub name: String,
    pub components: Vec<Component>,
    pub connections: Vec<Connection>,
    /// Measurement noise variance per measured channel (SI²); None until calibrated.
    pub noise_variance: Option<noise::NoiseVariances>,
    /// The SSD's `DefaultExperiment` (start, stop), s; None: none written.
    pub default_experiment: Option<(f64, f64)>,
    /// Posterior covariance of the calibrated physics parameters; None unless calibrated.
    pub parameter_covariance: Option<ParameterCovariance>,
    /// Worst-floor NMSE (%) of the worst validation record the twin was accepted on.
    pub validation_nmse: Option<f64>,
    /// The records it was calibrated and validated on (stored with the noise variances).
    pub records: Vec<RecordRef>,
    /// The calibration's priors given at `twin init --priors P.json` (the file's JSON text,
    /// stored as `resources/priors.json`; see `workflows::calibrate::PriorSpec`).
    pub priors: Option<String>,
    /// Where it was read from; None for the default twin.
    pub source: Option<PathBuf>,
    /// Keeps what `fmu_path`s point into (the unpacked archive, a trained FMU's scratch
    /// directory) alive, shared by duplicates.
    keep_alive: Vec<std::sync::Arc<dyn std::any::Any + Send + Sync>>,
}

/// Where an FMU of the twin is: `$TWIN_FMU_DIR/<file_name>` when that is set (a developer's
/// freshly built FMUs), else the one built into this binary, written into the per-user FMU
/// cache on first use ([`embedded`]).
pub fn find_fmu(file_name: &str) -> Result<PathBuf, TwinError> {
    let not_found = |message: String| TwinError::Invalid {
        path: PathBuf::from(file_name),
        message,
    };
    if let Some(dir) = std::env::var_os("TWIN_FMU_DIR") {
        let path = PathBuf::from(dir).join(file_name);
        if path.is_file() {
            return Ok(path);
        }
        if embedded::embedded(file_name).is_none() {
            return Err(not_found(format!(
                "not in TWIN_FMU_DIR ({}) nor built into this binary; build the FMUs with \
                 scripts/build-fmus.sh",
                path.display()
            )));
        }
    }
    let fmu = embedded::embedded(file_name).ok_or_else(|| {
        not_found(
            "not built into this binary; set TWIN_FMU_DIR to the FMUs of scripts/build-fmus.sh"
                .into(),
        )
    })?;
    embedded::path_of(fmu)
        .map_err(|e| not_found(format!("cannot write the FMU built into this binary: {e}")))
}

impl Twin {
    /// The shear FMU with its default parameters (the paper's rig), force in, every floor's
    /// acceleration out.
    pub fn default_twin() -> Result<Self, TwinError> {
        let outputs: Vec<String> = (1..=::structure::Structure::default().storeys())
            .map(|floor| format!("acc{floor}"))
            .collect();
        Ok(Twin::of_shear_fmu(
            find_fmu(SHEAR_FMU)?,
            &INPUTS,
            &outputs,
            Vec::new(),
        ))
    }

    /// The shear FMU at `fmu_path` alone, each of `inputs` fed from the system's input of that
    /// name and each of `outputs` given out under its name; `keep_alive` holds what the path
    /// lives in (a temporary directory).
    pub(crate) fn of_shear_fmu(
        fmu_path: PathBuf,
        inputs: &[&str],
        outputs: &[impl AsRef<str>],
        keep_alive: Vec<std::sync::Arc<dyn std::any::Any + Send + Sync>>,
    ) -> Twin {
        let mut connections: Vec<Connection> = inputs
            .iter()
            .map(|input| Connection {
                start_element: None,
                start_connector: (*input).into(),
                end_element: Some(PHYSICS.into()),
                end_connector: (*input).into(),
            })
            .collect();
        for output in outputs {
            connections.push(Connection {
                start_element: Some(PHYSICS.into()),
                start_connector: output.as_ref().into(),
                end_element: None,
                end_connector: output.as_ref().into(),
            });
        }
        Twin {
            name: "shear-twin".into(),
            components: vec![Component {
                name: PHYSICS.into(),
                fmu_name: SHEAR_FMU.into(),
                fmu_path,
                parameters: BTreeMap::new(),
            }],
            connections,
            noise_variance: None,
            default_experiment: None,
            parameter_covariance: None,
            validation_nmse: None,
            records: Vec::new(),
            priors: None,
            source: None,
            keep_alive,
        }
    }

    /// `path` is an `.ssp` archive, or None for the default twin.
    pub fn load(path: Option<&Path>) -> Result<Self, TwinError> {
        match path {
            None => Self::default_twin(),
            Some(p) => Self::read(p),
        }
    }

    /// A copy to modify (e.g. with calibrated parameters); it shares the unpacked FMUs.
    pub fn duplicate(&self) -> Twin {
        Twin {
            name: self.name.clone(),
            components: self.components.clone(),
            connections: self.connections.clone(),
            noise_variance: self.noise_variance.clone(),
            default_experiment: self.default_experiment,
            parameter_covariance: self.parameter_covariance.clone(),
            validation_nmse: self.validation_nmse,
            records: self.records.clone(),
            priors: self.priors.clone(),
            source: self.source.clone(),
            keep_alive: self.keep_alive.clone(),
        }
    }

    /// Keep `resource` alive as long as this twin (and its duplicates): for files its
    /// components point into.
    pub fn keep_alive(&mut self, resource: std::sync::Arc<dyn std::any::Any + Send + Sync>) {
        self.keep_alive.push(resource);
    }

    /// The system's input connectors: the standard inputs (but for one the system outputs, as
    /// a controlled system does its control force) plus any a connection starts from.
    pub fn system_inputs(&self) -> Vec<String> {
        let outputs = self.system_outputs();
        let mut names: Vec<String> = INPUTS
            .iter()
            .map(|s| s.to_string())
            .filter(|s| !outputs.contains(s))
            .collect();
        for c in &self.connections {
            if c.start_element.is_none() && !names.contains(&c.start_connector) {
                names.push(c.start_connector.clone());
            }
        }
        names
    }

    /// The system's output connectors: those a connection ends at.
    pub fn system_outputs(&self) -> Vec<String> {
        let mut names: Vec<String> = Vec::new();
        for c in &self.connections {
            if c.end_element.is_none() && !names.contains(&c.end_connector) {
                names.push(c.end_connector.clone());
            }
        }
        names
    }

    /// A copy that gives out every one of `channels`: those it does not give out under their
    /// name wired from its physics component (whose shear FMU has `acc<i>`, `vel<i>` and
    /// `disp<i>` for every floor); None when it gives them all already.
    pub fn wired_for(&self, channels: &[::structure::channel::Channel]) -> Option<Twin> {
        let outputs = self.system_outputs();
        let missing: Vec<String> = channels
            .iter()
            .map(::structure::channel::Channel::name)
            .filter(|n| !outputs.contains(n))
            .collect();
        if missing.is_empty() {
            return None;
        }
        let mut copy = self.duplicate();
        for name in missing {
            copy.connections.push(Connection {
                start_element: Some(PHYSICS.into()),
                start_connector: name.clone(),
                end_element: None,
                end_connector: name,
            });
        }
        Some(copy)
    }

    /// The measurement noise variance the twin holds for `channel` (in its SI unit, squared);
    /// None for a channel it was never calibrated on, or an uncalibrated twin.
    pub fn noise_variance_of(&self, channel: ::structure::channel::Channel) -> Option<f64> {
        self.noise_variance.as_ref()?.get(channel)
    }

    pub fn component(&self, name: &str) -> Option<&Component> {
        self.components.iter().find(|c| c.name == name)
    }

    pub fn component_mut(&mut self, name: &str) -> Option<&mut Component> {
        self.components.iter_mut().find(|c| c.name == name)
    }

    pub fn describe(&self) -> String {
        self.source
            .as_ref()
            .map(|p| p.display().to_string())
            .unwrap_or_else(|| "default twin (shear FMU, default parameters)".into())
    }

    // -----------------------------------------------------------------------------------------
    // Reading

    pub fn read(path: &Path) -> Result<Self, TwinError> {
        let invalid = |message: String| TwinError::Invalid {
            path: path.to_owned(),
            message,
        };
        let unpacked = import::unpack_system(path, UnpackLimits::default())?;
        let root = unpacked.path();
        let ssd = std::fs::read_to_string(root.join("SystemStructure.ssd"))
            .map_err(|e| invalid(format!("no readable SystemStructure.ssd: {e}")))?;
        let parsed = parse_ssd(&ssd).map_err(|m| invalid(format!("SystemStructure.ssd: {m}")))?;
        let components = parsed
            .components
            .into_iter()
            .map(|c| read_component(root, c).map_err(invalid))
            .collect::<Result<Vec<_>, _>>()?;
        let mut system = SystemValues::default();
        for binding in parsed.system_bindings {
            system = read_system_values(root, &binding)
                .map_err(|m| invalid(format!("{binding}: {m}")))?;
        }
        let priors_path = root.join(PRIORS_RESOURCE);
        let priors = if priors_path.is_file() {
            Some(
                std::fs::read_to_string(&priors_path)
                    .map_err(|e| invalid(format!("{PRIORS_RESOURCE}: {e}")))?,
            )
        } else {
            None
        };
        Ok(Twin {
            name: parsed.name,
            components,
            connections: parsed.connections,
            noise_variance: system.noise_variance,
            default_experiment: parsed.start_time.zip(parsed.stop_time),
            parameter_covariance: system.parameter_covariance,
            validation_nmse: system.validation_nmse,
            records: system.records,
            priors,
            source: Some(path.to_owned()),
            keep_alive: vec![std::sync::Arc::new(unpacked)],
        })
    }

    // -----------------------------------------------------------------------------------------
    // Writing

    /// Write the archive to `path` (through a temporary file: a failure leaves nothing half-written).
    pub fn write(&self, path: &Path) -> Result<(), TwinError> {
        // The FMUs are opened first, so that a missing one is named as itself; each is copied
        // into the archive through a small buffer (read whole, a 1.5 MB FMU cost a fresh heap's
        // page faults, a tenth of a three-storey calibration's process).
        let mut fmus: Vec<(&str, std::fs::File)> = Vec::new();
        for c in &self.components {
            if !fmus.iter().any(|(name, _)| *name == c.fmu_name) {
                let file = std::fs::File::open(&c.fmu_path).map_err(|source| TwinError::Io {
                    path: c.fmu_path.clone(),
                    source,
                })?;
                fmus.push((&c.fmu_name, file));
            }
        }
        crate::fsutil::write_atomically(path, |file| {
            let zip_err = |e: zip::result::ZipError| std::io::Error::other(format!("zip: {e}"));
            let mut zip = zip::ZipWriter::new(file);
            let options = zip::write::SimpleFileOptions::default()
                .compression_method(zip::CompressionMethod::Deflated);
            zip.start_file("SystemStructure.ssd", options)
                .map_err(zip_err)?;
            zip.write_all(self.ssd_xml().as_bytes())?;
            // Stored: an FMU is itself an archive, and opening the twin should not inflate it
            // twice.
            let stored = options.compression_method(zip::CompressionMethod::Stored);
            for (name, file) in &mut fmus {
                zip.start_file(format!("resources/{name}"), stored)
                    .map_err(zip_err)?;
                std::io::copy(file, &mut zip)?;
            }
            for c in &self.components {
                zip.start_file(format!("resources/{}.ssv", c.name), options)
                    .map_err(zip_err)?;
                zip.write_all(ssv_xml(&c.name, &c.parameters).as_bytes())?;
            }
            if let Some(priors) = &self.priors {
                zip.start_file(PRIORS_RESOURCE, options).map_err(zip_err)?;
                zip.write_all(priors.as_bytes())?;
            }
            if self.has_system_values() {
                let values = self.system_values();
                zip.start_file("resources/twin.ssv", options)
                    .map_err(zip_err)?;
                zip.write_all(
                    ssv_xml_with_strings("twin", &values, &self.system_strings()).as_bytes(),
                )?;
            }
            zip.finish().map_err(zip_err)?;
            Ok(())
        })
        .map_err(|e| TwinError::Io {
            path: e.path,
            source: e.source,
        })
    }

    /// Whether the twin has values of its own for `resources/twin.ssv`: noise variances from a
    /// calibration on records, or a posterior covariance alone (a calibration on an FRF, which
    /// says nothing of the sensors' noise in time).
    fn has_system_values(&self) -> bool {
        self.noise_variance.is_some() || self.parameter_covariance.is_some()
    }

    /// The system's own parameters, written to `resources/twin.ssv` (only with noise variances
    /// or a posterior covariance).
    fn system_values(&self) -> BTreeMap<String, ParameterValue> {
        let mut values = BTreeMap::new();
        if !self.has_system_values() {
            return values;
        }
        if let Some(nv) = &self.noise_variance {
            values.extend(nv.parameters());
        }
        if let Some(c) = &self.parameter_covariance {
            for (a, na) in c.names.iter().enumerate() {
                for (b, nb) in c.names.iter().enumerate().skip(a) {
                    values.insert(
                        format!("{COVARIANCE_PREFIX}{na}.{nb}"),
                        ParameterValue::Real(c.matrix[a][b]),
                    );
                }
            }
        }
        if let Some(v) = self.validation_nmse {
            values.insert("validation_nmse".into(), ParameterValue::Real(v));
        }
        values
    }

    /// The system's String parameters in `resources/twin.ssv`: the records.
    fn system_strings(&self) -> BTreeMap<String, String> {
        let mut out = BTreeMap::new();
        for (i, r) in self.records.iter().enumerate() {
            let n = i + 1;
            out.insert(format!("record{n}.path"), r.path.display().to_string());
            out.insert(format!("record{n}.sha256"), r.sha256.clone());
            out.insert(format!("record{n}.role"), r.role.name().to_owned());
        }
        out
    }

    /// The twin's records, read and checked against their hashes (see [`RecordRef::load`]).
    pub fn load_records(&self) -> Result<Vec<data::Measurement>, TwinError> {
        self.records.iter().map(RecordRef::load).collect()
    }
}

/// What the twin's own parameter set (`resources/twin.ssv`) holds.
#[derive(Default)]
struct SystemValues {
    noise_variance: Option<noise::NoiseVariances>,
    parameter_covariance: Option<ParameterCovariance>,
    validation_nmse: Option<f64>,
    records: Vec<RecordRef>,
}

/// A component of the unpacked archive at `root`: its FMU, which must be there, and its
/// parameter values from its bindings.
fn read_component(root: &Path, c: ssp::SsdComponent) -> Result<Component, String> {
    let fmu_name = c
        .source
        .strip_prefix("resources/")
        .filter(|n| !n.contains('/'))
        .ok_or_else(|| {
            format!(
                "component '{}': source '{}' is not resources/<file>.fmu",
                c.name, c.source
            )
        })?
        .to_owned();
    let fmu_path = root.join("resources").join(&fmu_name);
    if !fmu_path.is_file() {
        return Err(format!(
            "component '{}': {} is missing from the archive",
            c.name, c.source
        ));
    }
    let mut parameters = BTreeMap::new();
    for binding in c.bindings {
        let ssv =
            std::fs::read_to_string(root.join(&binding)).map_err(|e| format!("{binding}: {e}"))?;
        for (name, value) in parse_ssv(&ssv).map_err(|m| format!("{binding}: {m}"))? {
            parameters.insert(name, value);
        }
    }
    Ok(Component {
        name: c.name,
        fmu_name,
        fmu_path,
        parameters,
    })
}

/// The system's parameter set `binding` of the unpacked archive at `root`: the noise
/// variances, the parameters' covariance, the validation NMSE and the records.
fn read_system_values(root: &Path, binding: &str) -> Result<SystemValues, String> {
    let ssv = std::fs::read_to_string(root.join(binding)).map_err(|e| e.to_string())?;
    // Gathered, then made a map at once: the file's names come sorted, and a map built from a
    // sorted list compares each name once (inserting one by one compared each about eleven
    // times: 1,900 names of a 20-storey twin, most of them `covariance.*`).
    let mut values: Vec<(String, ParameterValue)> = Vec::new();
    let mut strings: BTreeMap<String, String> = BTreeMap::new();
    for (name, value) in ssp::parse_ssv(&ssv)? {
        let value = match value {
            SsvValue::Real(x) => ParameterValue::Real(x),
            SsvValue::Integer(i) => ParameterValue::Integer(i),
            SsvValue::Boolean(b) => ParameterValue::Boolean(b),
            SsvValue::String(text) => {
                strings.insert(name, text);
                continue;
            }
            other => {
                return Err(format!(
                    "parameter '{name}': {other:?} is not a Real, Integer, Boolean or String"
                ))
            }
        };
        values.push((name, value));
    }
    // The last of a repeated name wins, as it did inserted one by one.
    let values: BTreeMap<String, ParameterValue> = values.into_iter().collect();
    let records = read_records(&strings)?;
    let noise_variance = noise::NoiseVariances::from_parameters(&values)?;
    let parameter_covariance = read_covariance(&values)?;
    let validation_nmse = match values.get("validation_nmse") {
        None => None,
        Some(ParameterValue::Real(x)) if *x >= 0.0 && x.is_finite() => Some(*x),
        Some(other) => {
            return Err(format!(
                "validation_nmse = {other} is not a non-negative real"
            ))
        }
    };
    Ok(SystemValues {
        noise_variance,
        parameter_covariance,
        records,
        validation_nmse,
    })
}

/// An error's text with the unpacked FMU's temporary path taken out (the caller names the
/// component instead).
pub(crate) fn strip_temporary_path(e: TwinError, fmu_path: &Path) -> TwinError {
    let text = e.to_string();
    let shown = fmu_path.display().to_string();
    if text.contains(&shown) {
        TwinError::Message(
            text.replace(&format!("{shown}: "), "")
                .replace(&shown, "the FMU"),
        )
    } else {
        e
    }
}

/// Set parameter values on an instance in initialization mode, by name.
pub fn apply_parameters(
    fmu: &Fmu,
    instance: &mut Instance,
    parameters: &BTreeMap<String, ParameterValue>,
) -> Result<(), TwinError> {
    for (name, value) in parameters {
        let variable =
            fmu.model_description
                .variable(name)
                .ok_or_else(|| ImportError::UnknownVariable {
                    fmu: fmu.path.display().to_string(),
                    name: name.clone(),
                })?;
        let vr = [variable.value_reference];
        match (variable.scalar_type, value) {
            (ScalarType::Real, ParameterValue::Real(x)) => instance.set_real(&vr, &[*x])?,
            (ScalarType::Integer | ScalarType::Enumeration, ParameterValue::Integer(i)) => {
                instance.set_integer(&vr, &[*i])?
            }
            (ScalarType::Boolean, ParameterValue::Boolean(b)) => {
                instance.set_boolean(&vr, &[*b])?
            }
            (ty, v) => {
                return Err(TwinError::Invalid {
                    path: fmu.path.clone(),
                    message: format!("parameter '{name}' is {ty:?} but the twin gives {v:?}"),
                })
            }
        }
    }
    Ok(())
}

/// What a twin did with a record.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RecordRole {
    /// Its parameters were fitted on it.
    Calibration,
    /// It was run on it after the fit, as evidence of fidelity (or of what it does not know).
    Validation,
}

impl RecordRole {
    pub fn name(self) -> &'static str {
        match self {
            RecordRole::Calibration => "calibration",
            RecordRole::Validation => "validation",
        }
    }
    fn parse(s: &str) -> Option<Self> {
        match s {
            "calibration" => Some(RecordRole::Calibration),
            "validation" => Some(RecordRole::Validation),
            _ => None,
        }
    }
}

/// A record a twin was fitted or validated on: where it was (absolute) and the SHA-256 of its
/// bytes, so that it can be read again and a moved or changed file is refused by name.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordRef {
    pub path: PathBuf,
    pub sha256: String,
    pub role: RecordRole,
}

/// The SHA-256 of `bytes` in lower-case hex.
fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::Digest;
    sha2::Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

impl RecordRef {
    /// The record at `path` as it is now.
    pub fn of(path: &Path, role: RecordRole) -> Result<Self, TwinError> {
        let io = |source| TwinError::Io {
            path: path.to_owned(),
            source,
        };
        let absolute = std::fs::canonicalize(path).map_err(io)?;
        let bytes = std::fs::read(&absolute).map_err(io)?;
        Ok(RecordRef {
            path: absolute,
            sha256: sha256_hex(&bytes),
            role,
        })
    }

    /// Read the record again, refusing a file that is gone or no longer the one the twin saw.
    pub fn load(&self) -> Result<data::Measurement, TwinError> {
        let role = self.role.name();
        let bytes = std::fs::read(&self.path).map_err(|e| {
            TwinError::Message(format!(
                "the twin's {role} record {} cannot be read ({e}): moved or deleted? Give the \
                 records explicitly (--records D1.csv D2.csv ...)",
                self.path.display()
            ))
        })?;
        let now = sha256_hex(&bytes);
        if now != self.sha256 {
            return Err(TwinError::Message(format!(
                "the twin's {role} record {} changed since the twin was fitted on it (SHA-256 \
                 {}, now {now}); give the records explicitly (--records D1.csv D2.csv ...)",
                self.path.display(),
                self.sha256
            )));
        }
        data::Measurement::read(&self.path).map_err(|e| TwinError::Message(e.to_string()))
    }
}

/// The records from `record{i}.path`, `.sha256`, `.role` String parameters, i = 1, 2, …
fn read_records(strings: &BTreeMap<String, String>) -> Result<Vec<RecordRef>, String> {
    let mut out = Vec::new();
    for i in 1.. {
        let key = |what: &str| format!("record{i}.{what}");
        let Some(path) = strings.get(&key("path")) else {
            break;
        };
        let sha256 = strings
            .get(&key("sha256"))
            .filter(|h| h.len() == 64 && h.bytes().all(|b| b.is_ascii_hexdigit()))
            .ok_or_else(|| format!("{} is missing or not a SHA-256 in hex", key("sha256")))?;
        let role = strings
            .get(&key("role"))
            .and_then(|r| RecordRole::parse(r))
            .ok_or_else(|| format!("{} must be 'calibration' or 'validation'", key("role")))?;
        out.push(RecordRef {
            path: PathBuf::from(path),
            sha256: sha256.clone(),
            role,
        });
    }
    Ok(out)
}

/// The covariance from `covariance.A.B` entries: the names are those with a diagonal entry,
/// every pair must be there (either order), finite, with non-negative variances.
fn read_covariance(
    values: &BTreeMap<String, ParameterValue>,
) -> Result<Option<ParameterCovariance>, String> {
    let mut names: Vec<&str> = Vec::new();
    let mut entries: Vec<(&str, &str, f64)> = Vec::new();
    for (key, value) in values {
        let Some(pair) = key.strip_prefix(COVARIANCE_PREFIX) else {
            continue;
        };
        let (a, b) = pair
            .split_once('.')
            .ok_or_else(|| format!("{key}: not {COVARIANCE_PREFIX}A.B"))?;
        let ParameterValue::Real(x) = value else {
            return Err(format!("{key} = {value} is not a real"));
        };
        if !x.is_finite() {
            return Err(format!("{key} = {x} is not finite"));
        }
        if a == b {
            if *x < 0.0 {
                return Err(format!("{key} = {x}: a variance cannot be negative"));
            }
            names.push(a);
        }
        entries.push((a, b, *x));
    }
    if entries.is_empty() {
        return Ok(None);
    }
    // Each entry (A, B) where the matrix has both; (B, A) where it gives no (A, B) itself.
    let index: BTreeMap<&str, usize> = names.iter().enumerate().map(|(i, n)| (*n, i)).collect();
    let n = names.len();
    let mut matrix: Vec<Vec<Option<f64>>> = vec![vec![None; n]; n];
    let placed: Vec<(usize, usize, f64)> = entries
        .iter()
        .filter_map(|(a, b, x)| Some((*index.get(a)?, *index.get(b)?, *x)))
        .collect();
    for &(i, j, x) in &placed {
        matrix[i][j] = Some(x);
    }
    for &(i, j, x) in &placed {
        matrix[j][i].get_or_insert(x);
    }
    let matrix = matrix
        .into_iter()
        .enumerate()
        .map(|(i, row)| {
            row.into_iter()
                .enumerate()
                .map(|(j, x)| {
                    x.ok_or_else(|| {
                        format!("{COVARIANCE_PREFIX}{}.{} is missing", names[i], names[j])
                    })
                })
                .collect::<Result<Vec<f64>, _>>()
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok(Some(ParameterCovariance {
        names: names.into_iter().map(str::to_owned).collect(),
        matrix,
    }))
}

/// An `.ssv` parameter set as twin parameters: Real, Integer and Boolean values.
fn parse_ssv(xml: &str) -> Result<Vec<(String, ParameterValue)>, String> {
    ssp::parse_ssv(xml)?
        .into_iter()
        .map(|(name, value)| {
            let value = match value {
                SsvValue::Real(x) => ParameterValue::Real(x),
                SsvValue::Integer(i) => ParameterValue::Integer(i),
                SsvValue::Boolean(b) => ParameterValue::Boolean(b),
                other => {
                    return Err(format!(
                        "parameter '{name}': {other:?} is not a Real, Integer or Boolean, the \
                         values a twin's components take"
                    ))
                }
            };
            Ok((name, value))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The covariance's names in the file's order, an entry given one way filling both, an
    /// entry given both ways kept as given, a missing pair named, an entry of a name without
    /// its variance left out.
    #[test]
    fn covariance_is_read_from_its_entries() {
        let real = |entries: &[(&str, f64)]| -> BTreeMap<String, ParameterValue> {
            entries
                .iter()
                .map(|(k, x)| (format!("{COVARIANCE_PREFIX}{k}"), ParameterValue::Real(*x)))
                .collect()
        };
        let values = real(&[
            ("k1.k1", 4.0),
            ("k2.k2", 9.0),
            ("k1.k2", 1.5),
            ("m1.m1", 0.25),
            ("m1.k1", -0.5),
            ("k1.m1", -0.25),
            ("m1.k2", 0.125),
            ("c9.k1", 7.0),
        ]);
        let c = read_covariance(&values).expect("read").expect("present");
        assert_eq!(c.names, ["k1", "k2", "m1"]);
        assert_eq!(
            c.matrix,
            [
                vec![4.0, 1.5, -0.25],
                vec![1.5, 9.0, 0.125],
                vec![-0.5, 0.125, 0.25]
            ]
        );
        let missing = real(&[("k1.k1", 4.0), ("k2.k2", 9.0)]);
        assert_eq!(
            read_covariance(&missing).unwrap_err(),
            "covariance.k1.k2 is missing"
        );
        assert!(read_covariance(&BTreeMap::new()).expect("read").is_none());
    }

    #[test]
    fn ssv_round_trips() {
        let mut p = BTreeMap::new();
        p.insert("k1".to_owned(), ParameterValue::Real(4321.125));
        p.insert("substeps".to_owned(), ParameterValue::Integer(16));
        p.insert(
            "contact23_enabled".to_owned(),
            ParameterValue::Boolean(true),
        );
        let xml = ssv_xml("physics", &p);
        let back: BTreeMap<String, ParameterValue> =
            parse_ssv(&xml).expect("parses").into_iter().collect();
        assert_eq!(back, p);
    }

    #[test]
    fn ssv_refuses_bad_values() {
        let xml = r#"<ssv:ParameterSet xmlns:ssv="x" version="1.0" name="p"><ssv:Parameters>
            <ssv:Parameter name="k1"><ssv:Real value="abc"/></ssv:Parameter></ssv:Parameters></ssv:ParameterSet>"#;
        let err = parse_ssv(xml).expect_err("bad real");
        assert!(err.contains("k1"), "{err}");
    }

    #[test]
    fn ssd_refuses_other_versions_and_garbage() {
        assert!(parse_ssd("<ssd:SystemStructureDescription version=\"2.0\" name=\"x\"/>").is_err());
        assert!(parse_ssd("<nothing/>").is_err());
        assert!(parse_ssd("<a><b></a>").is_err());
    }
}
