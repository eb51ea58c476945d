//! Files written whole or not at all: through a temporary file in the same directory, renamed
//! into place, readable by others (0644, not the temporary file's private 0600).

use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
#[error("cannot write {}", path.display())]
pub struct WriteError {
    pub path: PathBuf,
    #[source]
    pub source: std::io::Error,
}

/// Write `path` through a temporary file in its directory, then rename: a failure leaves no
/// partial file and the old one, if any, as it was.
pub fn write_atomically(
    path: &Path,
    write: impl FnOnce(&mut File) -> std::io::Result<()>,
) -> Result<(), WriteError> {
    let error = |source| WriteError {
        path: path.to_owned(),
        source,
    };
    let parent = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let mut tmp = tempfile::NamedTempFile::new_in(parent).map_err(error)?;
    write(tmp.as_file_mut()).map_err(error)?;
    tmp.as_file_mut().flush().map_err(error)?;
    persist_readable(tmp, path).map_err(error)
}

/// [`write_atomically`] of a text.
pub fn write_text_atomically(path: &Path, text: &str) -> Result<(), WriteError> {
    write_atomically(path, |f| f.write_all(text.as_bytes()))
}

/// Move a finished temporary file into place as an ordinary readable file (0644), not with the
/// temporary file's private 0600.
pub fn persist_readable(tmp: tempfile::NamedTempFile, path: &Path) -> std::io::Result<()> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(tmp.path(), std::fs::Permissions::from_mode(0o644))?;
    }
    tmp.persist(path).map_err(|e| e.error)?;
    Ok(())
}
