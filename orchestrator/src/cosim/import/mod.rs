//! Import of FMI 2.0 co-simulation FMUs: unpack with limits, read the modelDescription, load
//! the library, and drive instances through a safe wrapper.

pub mod archive;
pub mod library;
pub mod model_description;

use std::path::{Path, PathBuf};

pub use archive::{
    fmu_cache_root, unpack, unpack_fmu, unpack_system, UnpackLimits, Unpacked, EMBEDDED_ARCHIVES,
};
pub use library::{
    file_uri, FmuMessage, Instance, Library, StateCapabilities, StateHandle, StepEnd,
};
pub use model_description::{Causality, ModelDescription, ScalarType, ScalarVariable};

#[derive(Debug, thiserror::Error)]
pub enum ImportError {
    #[error("{path}: {message}")]
    Archive { path: PathBuf, message: String },
    #[error("{path}: modelDescription.xml: {message}")]
    ModelDescription { path: PathBuf, message: String },
    #[error("{path}: {message}")]
    Library { path: PathBuf, message: String },
    #[error("{instance} ({fmu}): {call} {status}{}", if messages.is_empty() { String::new() } else { format!(": {messages}") })]
    Call {
        instance: String,
        /// The `.fmu` the instance came from.
        fmu: String,
        call: &'static str,
        status: String,
        messages: String,
    },
    #[error("{instance}: the FMU does not provide {what}")]
    Unsupported {
        instance: String,
        what: &'static str,
    },
    #[error("{fmu}: no variable named '{name}'")]
    UnknownVariable { fmu: String, name: String },
}

/// An FMU unpacked and its modelDescription read, its code not yet loaded: what a run's
/// configuration is checked against before any FMU code runs.
pub struct UnpackedFmu {
    pub path: PathBuf,
    pub model_description: ModelDescription,
    unpacked: Unpacked,
}

impl UnpackedFmu {
    pub fn open(path: &Path) -> Result<Self, ImportError> {
        Self::open_with_limits(path, UnpackLimits::default())
    }

    pub fn open_with_limits(path: &Path, limits: UnpackLimits) -> Result<Self, ImportError> {
        let cached = unpack_fmu(path, limits)?;
        if cached.is_cached() {
            // A cache entry that lost its files (removed by hand, or by another process's
            // eviction racing this open) is no reason to fail: a private copy then.
            match Self::read(path, cached) {
                Ok(fmu) if fmu.binary().is_file() => return Ok(fmu),
                _ => return Self::read(path, unpack(path, limits)?),
            }
        }
        Self::read(path, cached)
    }

    /// The library for this platform, as the modelDescription names it.
    fn binary(&self) -> PathBuf {
        self.unpacked
            .path()
            .join("binaries/linux64")
            .join(format!("{}.so", self.model_description.model_identifier))
    }

    fn read(path: &Path, unpacked: Unpacked) -> Result<Self, ImportError> {
        let model_description = match unpacked.cache_entry() {
            Some(entry) => ModelDescription::read_cached(entry, path)?,
            None => {
                ModelDescription::read_file(&unpacked.path().join("modelDescription.xml"), path)?
            }
        };
        Ok(UnpackedFmu {
            path: path.to_owned(),
            model_description,
            unpacked,
        })
    }

    /// Load the library for this platform (the FMU's code runs from here on).
    pub fn load(self) -> Result<Fmu, ImportError> {
        let UnpackedFmu {
            path,
            model_description,
            unpacked,
        } = self;
        let path = path.as_path();
        let platform_dir = unpacked.path().join("binaries/linux64");
        let binary = platform_dir.join(format!("{}.so", model_description.model_identifier));
        if platform_dir.is_dir() && !binary.is_file() {
            let mut present: Vec<String> = std::fs::read_dir(&platform_dir)
                .map(|d| {
                    d.flatten()
                        .map(|e| e.file_name().to_string_lossy().into_owned())
                        .collect()
                })
                .unwrap_or_default();
            present.sort();
            return Err(ImportError::Archive {
                path: path.to_owned(),
                message: format!(
                    "binaries/linux64/ is there but has no {}.so, the library the modelIdentifier \
                     names (it has: {})",
                    model_description.model_identifier,
                    if present.is_empty() {
                        "nothing".to_owned()
                    } else {
                        present.join(", ")
                    }
                ),
            });
        }
        if !binary.is_file() {
            let present: Vec<String> = std::fs::read_dir(unpacked.path().join("binaries"))
                .map(|d| {
                    d.flatten()
                        .map(|e| e.file_name().to_string_lossy().into_owned())
                        .collect()
                })
                .unwrap_or_default();
            return Err(ImportError::Archive {
                path: path.to_owned(),
                message: format!(
                    "no binary binaries/linux64/{}.so for this platform (platforms present: {})",
                    model_description.model_identifier,
                    if present.is_empty() {
                        "none".to_owned()
                    } else {
                        present.join(", ")
                    }
                ),
            });
        }
        let library = Library::load(
            &binary,
            &model_description.guid,
            &unpacked.path().join("resources"),
        )
        .map(|l| {
            l.with_input_interpolation(model_description.can_interpolate_inputs)
                .with_state_capabilities(StateCapabilities {
                    get_and_set: model_description.can_get_and_set_fmu_state,
                    serialize: model_description.can_serialize_fmu_state,
                })
                .with_source(path)
        })
        .map_err(|e| match e {
            ImportError::Library { message, .. } => ImportError::Library {
                path: path.to_owned(),
                message,
            },
            other => other,
        })?;
        Ok(Fmu {
            path: path.to_owned(),
            model_description,
            library,
            _unpacked: unpacked,
        })
    }
}

/// An FMU unpacked and loaded, ready to instantiate.
pub struct Fmu {
    pub path: PathBuf,
    pub model_description: ModelDescription,
    library: Library,
    // Dropped after `library`, so the .so file outlives its mapping.
    _unpacked: Unpacked,
}

impl Fmu {
    pub fn open(path: &Path) -> Result<Self, ImportError> {
        Self::open_with_limits(path, UnpackLimits::default())
    }

    pub fn open_with_limits(path: &Path, limits: UnpackLimits) -> Result<Self, ImportError> {
        UnpackedFmu::open_with_limits(path, limits)?.load()
    }

    pub fn instantiate(&self, instance_name: &str) -> Result<Instance, ImportError> {
        self.library.instantiate(instance_name)
    }

    pub fn value_reference(&self, name: &str) -> Result<u32, ImportError> {
        self.model_description
            .variable(name)
            .map(|v| v.value_reference)
            .ok_or_else(|| ImportError::UnknownVariable {
                fmu: self.path.display().to_string(),
                name: name.to_owned(),
            })
    }
}
