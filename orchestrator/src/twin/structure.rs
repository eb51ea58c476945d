//! The twin of any shear building: the shear FMU made for a structure (its storeys, its
//! excitation, its nominal m/c/k), for `twin init --storeys N --excitation force:K|base`.
//!
//! One shear library serves every structure (`fmu_shear::variables::table`): what changes is the
//! FMU's `modelDescription.xml`, written from the Rust variable table of that structure, and
//! `resources/structure.json`, which the library reads at `fmi2Instantiate`. The archive is the
//! built-in shear FMU with those two entries replaced or added.

use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use fmu_shear::{ShearParameters, StructureResource};
use structure::{Excitation, Structure};

use super::{find_fmu, ParameterValue, Twin, TwinError, PHYSICS, SHEAR_FMU};

/// The structure file inside the FMU (under `resources/`).
const RESOURCE: &str = "resources/structure.json";

/// An engineer's estimate from drawings: `{"m": [...], "c": [...], "k": [...]}`, SI, one value
/// per floor / storey.
#[derive(Debug, Clone, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Nominal {
    pub m: Vec<f64>,
    pub c: Vec<f64>,
    pub k: Vec<f64>,
}

impl Nominal {
    pub fn read(path: &Path) -> Result<Nominal, TwinError> {
        let text = std::fs::read_to_string(path).map_err(|source| TwinError::Io {
            path: path.to_owned(),
            source,
        })?;
        Nominal::from_json(&text, path)
    }

    /// The nominal from its JSON text; `origin` names it in a refusal (a file, or the call).
    pub fn from_json(text: &str, origin: &Path) -> Result<Nominal, TwinError> {
        let invalid = |message: String| TwinError::Invalid {
            path: origin.to_owned(),
            message,
        };
        serde_json::from_str(text).map_err(|e| {
            invalid(format!(
                "{e}; expected {{\"m\": [...], \"c\": [...], \"k\": [...]}} (kg, N s/m, N/m)"
            ))
        })
    }
}

/// What `twin init` was asked for.
#[derive(Debug, Clone, Default)]
pub struct InitOptions {
    pub storeys: Option<usize>,
    pub excitation: Option<Excitation>,
    pub nominal: Option<(PathBuf, Nominal)>,
}

impl InitOptions {
    /// The structure: the nominal values when given (their length is the storey count), else
    /// the paper's floor and storey repeated; checked whole before anything is written.
    pub fn structure(&self) -> Result<Structure, TwinError> {
        let excitation = self.excitation.unwrap_or_default();
        let structure = match &self.nominal {
            Some((path, nominal)) => {
                let invalid = |message: String| TwinError::Invalid {
                    path: path.clone(),
                    message,
                };
                let n = nominal.m.len();
                if let Some(storeys) = self.storeys {
                    if storeys != n {
                        return Err(invalid(format!(
                            "\"m\" has {n} values but --storeys is {storeys}"
                        )));
                    }
                }
                let s = Structure {
                    mass: nominal.m.clone(),
                    damping: nominal.c.clone(),
                    stiffness: nominal.k.clone(),
                    excitation,
                };
                s.validate().map_err(|e| invalid(e.to_string()))?;
                s
            }
            None => {
                let defaults = Structure::default();
                let s = Structure::uniform(
                    self.storeys.unwrap_or(defaults.storeys()),
                    defaults.mass[0],
                    defaults.damping[0],
                    defaults.stiffness[0],
                    excitation,
                );
                s.validate()
                    .map_err(|e| TwinError::Message(e.to_string()))?;
                s
            }
        };
        Ok(structure)
    }
}

/// The shear FMU for `resource` as archive bytes: the built-in FMU with its modelDescription
/// written for the structure and `resources/structure.json` added.
pub fn shear_fmu_bytes(resource: &StructureResource) -> Result<Vec<u8>, TwinError> {
    let params = resource
        .parameters()
        .map_err(|e| TwinError::Message(format!("the structure: {e}")))?;
    let xml = fmu_shear::variables::table(&params).to_model_description_xml();
    let json = serde_json::to_string_pretty(resource)
        .map_err(|e| TwinError::Message(format!("the structure as JSON: {e}")))?;
    fmu_for_structure(SHEAR_FMU, &xml, &json)
}

/// The built-in FMU `fmu_name` as archive bytes with `xml` as its modelDescription and `json`
/// as its `resources/structure.json` (the library reads it at `fmi2Instantiate` and serves the
/// table `xml` was written from).
pub fn fmu_for_structure(fmu_name: &str, xml: &str, json: &str) -> Result<Vec<u8>, TwinError> {
    let base = find_fmu(fmu_name)?;
    let bad = |message: String| TwinError::Invalid {
        path: base.clone(),
        message,
    };
    let file = std::fs::File::open(&base).map_err(|source| TwinError::Io {
        path: base.clone(),
        source,
    })?;
    let mut archive = zip::ZipArchive::new(file).map_err(|e| bad(e.to_string()))?;
    let mut out = std::io::Cursor::new(Vec::new());
    {
        let zip_err = |e: zip::result::ZipError| bad(format!("zip: {e}"));
        let io_err = |e: std::io::Error| bad(e.to_string());
        let mut zip = zip::ZipWriter::new(&mut out);
        let deflated = zip::write::SimpleFileOptions::default()
            .compression_method(zip::CompressionMethod::Deflated);
        for i in 0..archive.len() {
            let mut entry = archive.by_index(i).map_err(zip_err)?;
            let name = entry.name().to_owned();
            if name == "modelDescription.xml" || name == RESOURCE {
                continue;
            }
            let mut bytes = Vec::new();
            entry.read_to_end(&mut bytes).map_err(io_err)?;
            let options = if name.starts_with("binaries/") {
                deflated.compression_method(zip::CompressionMethod::Stored)
            } else {
                deflated
            };
            zip.start_file(name, options).map_err(zip_err)?;
            zip.write_all(&bytes).map_err(io_err)?;
        }
        zip.start_file("modelDescription.xml", deflated)
            .map_err(zip_err)?;
        zip.write_all(xml.as_bytes()).map_err(io_err)?;
        zip.start_file(RESOURCE, deflated).map_err(zip_err)?;
        zip.write_all(json.as_bytes()).map_err(io_err)?;
        zip.finish().map_err(zip_err)?;
    }
    Ok(out.into_inner())
}

/// The structure a shear FMU archive models: its `resources/structure.json`, None when it has
/// none (the paper's rig).
pub fn structure_of_fmu(fmu: &Path) -> Result<Option<StructureResource>, TwinError> {
    let bad = |message: String| TwinError::Invalid {
        path: fmu.to_owned(),
        message,
    };
    let file = std::fs::File::open(fmu).map_err(|source| TwinError::Io {
        path: fmu.to_owned(),
        source,
    })?;
    let mut archive =
        zip::ZipArchive::new(file).map_err(|e| bad(format!("not a zip archive ({e})")))?;
    let mut entry = match archive.by_name(RESOURCE) {
        Ok(entry) => entry,
        Err(zip::result::ZipError::FileNotFound) => return Ok(None),
        Err(e) => return Err(bad(format!("{RESOURCE}: {e}"))),
    };
    let mut text = String::new();
    entry
        .read_to_string(&mut text)
        .map_err(|e| bad(format!("{RESOURCE}: {e}")))?;
    let resource: StructureResource =
        serde_json::from_str(&text).map_err(|e| bad(format!("{RESOURCE}: {e}")))?;
    resource
        .parameters()
        .map_err(|e| bad(format!("{RESOURCE}: {e}")))?;
    Ok(Some(resource))
}

impl Twin {
    /// The structure the twin models: its physics component's shear FMU's
    /// `resources/structure.json` (written by `twin init`; without it, the paper's rig), with
    /// the twin's own values of the parameters `m<i>`, `c<i>`, `k<i>` put in.
    pub fn structure(&self) -> Result<Structure, TwinError> {
        let physics = self.component(PHYSICS).ok_or_else(|| {
            TwinError::Message(format!(
                "{} has no '{PHYSICS}' component, so no structure",
                self.describe()
            ))
        })?;
        let mut structure = structure_of_fmu(&physics.fmu_path)
            .map_err(|e| TwinError::Component {
                twin: self.describe(),
                component: physics.name.clone(),
                fmu: format!("resources/{}", physics.fmu_name),
                inner: Box::new(super::strip_temporary_path(e, &physics.fmu_path)),
            })?
            .map(|r| r.structure)
            .unwrap_or_default();
        for (name, value) in &physics.parameters {
            if let ParameterValue::Real(x) = value {
                structure.set(name, *x);
            }
        }
        Ok(structure)
    }

    /// The default twin of `structure`: the paper's rig is [`Twin::default_twin`] itself;
    /// any other structure gets its own shear FMU (written to a temporary file that lives as
    /// long as the twin), the excitation's input and the control force connected in, every
    /// floor's acceleration out.
    pub fn for_structure(structure: &Structure) -> Result<Twin, TwinError> {
        let resource = StructureResource {
            structure: structure.clone(),
            control_floor: 1,
        };
        let params = resource
            .parameters()
            .map_err(|e| TwinError::Message(format!("the structure: {e}")))?;
        if params == ShearParameters::default() {
            return Twin::default_twin();
        }
        let bytes = shear_fmu_bytes(&resource)?;
        let dir = tempfile::tempdir().map_err(|source| TwinError::Io {
            path: std::env::temp_dir(),
            source,
        })?;
        let fmu_path = dir.path().join(SHEAR_FMU);
        std::fs::write(&fmu_path, bytes).map_err(|source| TwinError::Io {
            path: fmu_path.clone(),
            source,
        })?;
        let inputs = [structure.excitation.input_name(), "control_force"];
        let outputs: Vec<String> = (1..=structure.storeys())
            .map(|floor| format!("acc{floor}"))
            .collect();
        Ok(Twin::of_shear_fmu(
            fmu_path,
            &inputs,
            &outputs,
            vec![Arc::new(dir)],
        ))
    }
}
