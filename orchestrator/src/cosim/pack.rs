//! Writing an FMI 2.0 `.fmu` archive with the `zip` crate: `modelDescription.xml`,
//! `binaries/linux64/<modelIdentifier>.so`, `documentation/` and `resources/`.

use std::fs::File;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use zip::write::SimpleFileOptions;

#[derive(Debug, thiserror::Error)]
pub enum PackError {
    #[error("{path}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: {message}")]
    Invalid { path: PathBuf, message: String },
    #[error("writing the archive {path}")]
    Zip {
        path: PathBuf,
        source: zip::result::ZipError,
    },
}

/// What goes into one FMU.
#[derive(Debug, Clone)]
pub struct FmuContents {
    pub model_description: PathBuf,
    /// The cdylib built by cargo (`lib<crate>.so`); stored as `binaries/linux64/<modelIdentifier>.so`.
    pub library: PathBuf,
    pub documentation: Option<PathBuf>,
    pub resources: Option<PathBuf>,
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> PackError + '_ {
    move |source| PackError::Io {
        path: path.to_owned(),
        source,
    }
}

/// The `modelIdentifier` of the `CoSimulation` element of a modelDescription.
pub fn model_identifier(xml: &str, path: &Path) -> Result<String, PackError> {
    use quick_xml::events::Event;
    let mut reader = quick_xml::Reader::from_str(xml);
    loop {
        match reader.read_event() {
            Ok(Event::Start(e) | Event::Empty(e)) if e.name().as_ref() == b"CoSimulation" => {
                for attr in e.attributes().flatten() {
                    if attr.key.as_ref() == b"modelIdentifier" {
                        let value = attr.unescape_value().map_err(|err| PackError::Invalid {
                            path: path.to_owned(),
                            message: format!("modelIdentifier: {err}"),
                        })?;
                        return Ok(value.into_owned());
                    }
                }
                return Err(PackError::Invalid {
                    path: path.to_owned(),
                    message: "CoSimulation has no modelIdentifier".into(),
                });
            }
            Ok(Event::Eof) => {
                return Err(PackError::Invalid {
                    path: path.to_owned(),
                    message: "no CoSimulation element".into(),
                })
            }
            Err(err) => {
                return Err(PackError::Invalid {
                    path: path.to_owned(),
                    message: format!("malformed XML at byte {}: {err}", reader.error_position()),
                })
            }
            _ => {}
        }
    }
}

/// Files below `dir`, sorted, as (path on disk, path relative to `dir` with '/' separators).
fn files_below(dir: &Path) -> Result<Vec<(PathBuf, String)>, PackError> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_owned()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).map_err(io_err(&d))? {
            let entry = entry.map_err(io_err(&d))?;
            let path = entry.path();
            if path.is_dir() {
                stack.push(path);
            } else {
                let relative = path
                    .strip_prefix(dir)
                    .unwrap_or(&path)
                    .to_string_lossy()
                    .replace('\\', "/");
                out.push((path, relative));
            }
        }
    }
    out.sort_by(|a, b| a.1.cmp(&b.1));
    Ok(out)
}

/// Pack an FMU into `out` (written to a temporary file beside it, then renamed: a failed pack
/// leaves no half archive). Returns the model identifier.
pub fn pack_fmu(contents: &FmuContents, out: &Path) -> Result<String, PackError> {
    let xml = std::fs::read_to_string(&contents.model_description)
        .map_err(io_err(&contents.model_description))?;
    let identifier = model_identifier(&xml, &contents.model_description)?;
    let mut library = Vec::new();
    File::open(&contents.library)
        .and_then(|mut f| f.read_to_end(&mut library))
        .map_err(io_err(&contents.library))?;

    let mut entries: Vec<(String, Vec<u8>)> = vec![
        ("modelDescription.xml".into(), xml.into_bytes()),
        (format!("binaries/linux64/{identifier}.so"), library),
    ];
    for (folder, dir) in [
        ("documentation", &contents.documentation),
        ("resources", &contents.resources),
    ] {
        if let Some(dir) = dir {
            for (path, relative) in files_below(dir)? {
                let bytes = std::fs::read(&path).map_err(io_err(&path))?;
                entries.push((format!("{folder}/{relative}"), bytes));
            }
        }
    }

    let parent = out
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    std::fs::create_dir_all(parent).map_err(io_err(parent))?;
    let tmp = tempfile::NamedTempFile::new_in(parent).map_err(io_err(parent))?;
    let zip_err = |source| PackError::Zip {
        path: out.to_owned(),
        source,
    };
    {
        let mut zip = zip::ZipWriter::new(tmp.as_file());
        let options =
            SimpleFileOptions::default().compression_method(zip::CompressionMethod::Deflated);
        for (name, bytes) in &entries {
            // The shared library is stored, not deflated: inflating it was most of the time a
            // host spends opening the FMU, and it barely compresses below a third anyway.
            let entry_options = if name.starts_with("binaries/") {
                options.compression_method(zip::CompressionMethod::Stored)
            } else {
                options
            };
            zip.start_file(name.as_str(), entry_options)
                .map_err(zip_err)?;
            zip.write_all(bytes).map_err(io_err(out))?;
        }
        zip.finish().map_err(zip_err)?;
    }
    crate::fsutil::persist_readable(tmp, out).map_err(|source| PackError::Io {
        path: out.to_owned(),
        source,
    })?;
    Ok(identifier)
}
