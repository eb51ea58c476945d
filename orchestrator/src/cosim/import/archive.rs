//! Unpacking an archive (`.fmu`, `.ssp`) into a private temporary directory, refusing what a
//! hostile archive can do: absolute paths, `..` components, links (zip-slip) and bombs (too
//! many entries, too many bytes once inflated).

use std::fs::File;
use std::io::{self, Read};
use std::path::{Component, Path, PathBuf};

use super::ImportError;

/// Caps on what one archive may unpack to.
#[derive(Debug, Clone, Copy)]
pub struct UnpackLimits {
    pub max_entries: usize,
    pub max_total_bytes: u64,
}

impl Default for UnpackLimits {
    /// Far above any FMU of this project (a few MiB, a few files) and far below what fills a disk.
    fn default() -> Self {
        UnpackLimits {
            max_entries: 10_000,
            max_total_bytes: 1 << 30,
        }
    }
}

/// An unpacked archive; the directory is removed when this is dropped.
#[derive(Debug)]
pub struct Unpacked {
    dir: tempfile::TempDir,
}

impl Unpacked {
    pub fn path(&self) -> &Path {
        self.dir.path()
    }
}

/// Is `name` a relative path made only of normal components?
fn safe_relative_path(name: &str) -> Option<PathBuf> {
    if name.contains('\0') || name.contains('\\') {
        return None;
    }
    let path = Path::new(name);
    let mut out = PathBuf::new();
    for component in path.components() {
        match component {
            Component::Normal(part) => out.push(part),
            Component::CurDir => {}
            Component::ParentDir | Component::RootDir | Component::Prefix(_) => return None,
        }
    }
    (!out.as_os_str().is_empty()).then_some(out)
}

pub fn unpack(archive: &Path, limits: UnpackLimits) -> Result<Unpacked, ImportError> {
    let bad = |message: String| ImportError::Archive {
        path: archive.to_owned(),
        message,
    };
    let file = File::open(archive).map_err(|e| bad(format!("cannot open: {e}")))?;
    let mut zip = zip::ZipArchive::new(file).map_err(|e| bad(format!("not a zip archive: {e}")))?;
    if zip.len() > limits.max_entries {
        return Err(bad(format!(
            "{} entries, more than the limit of {}",
            zip.len(),
            limits.max_entries
        )));
    }
    let dir = tempfile::Builder::new()
        .prefix("twin-unpack-")
        .tempdir()
        .map_err(|e| bad(format!("cannot create a temporary directory: {e}")))?;
    let mut total: u64 = 0;
    for index in 0..zip.len() {
        let mut entry = zip
            .by_index(index)
            .map_err(|e| bad(format!("entry {index}: {e}")))?;
        let name = entry.name().to_owned();
        let Some(relative) = safe_relative_path(&name) else {
            return Err(bad(format!(
                "entry '{name}' has an absolute path or a '..' component (zip-slip); refused"
            )));
        };
        if entry.is_symlink() {
            return Err(bad(format!("entry '{name}' is a symbolic link; refused")));
        }
        let target = dir.path().join(&relative);
        if entry.is_dir() {
            std::fs::create_dir_all(&target).map_err(|e| bad(format!("entry '{name}': {e}")))?;
            continue;
        }
        if let Some(parent) = target.parent() {
            std::fs::create_dir_all(parent).map_err(|e| bad(format!("entry '{name}': {e}")))?;
        }
        let remaining = limits.max_total_bytes - total;
        let mut out = File::create(&target).map_err(|e| bad(format!("entry '{name}': {e}")))?;
        // Count what is really inflated, not what the header claims.
        let written = io::copy(&mut (&mut entry).take(remaining + 1), &mut out)
            .map_err(|e| bad(format!("entry '{name}': {e}")))?;
        total += written;
        if total > limits.max_total_bytes {
            return Err(bad(format!(
                "unpacks to more than {} bytes (zip bomb?); refused",
                limits.max_total_bytes
            )));
        }
        #[cfg(unix)]
        if let Some(mode) = entry.unix_mode() {
            use std::os::unix::fs::PermissionsExt;
            let _ = std::fs::set_permissions(
                &target,
                std::fs::Permissions::from_mode(mode & 0o755 | 0o600),
            );
        }
    }
    Ok(Unpacked { dir })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    fn write_zip(entries: &[(&str, &[u8])]) -> tempfile::NamedTempFile {
        let file = tempfile::NamedTempFile::new().expect("temp file");
        let mut zip = zip::ZipWriter::new(file.reopen().expect("reopen"));
        for (name, bytes) in entries {
            zip.start_file(*name, zip::write::SimpleFileOptions::default())
                .expect("start");
            zip.write_all(bytes).expect("write");
        }
        zip.finish().expect("finish");
        file
    }

    #[test]
    fn unpacks_a_plain_archive() {
        let z = write_zip(&[
            ("modelDescription.xml", b"<x/>"),
            ("binaries/linux64/a.so", b"elf"),
        ]);
        let u = unpack(z.path(), UnpackLimits::default()).expect("unpacks");
        assert_eq!(
            std::fs::read(u.path().join("binaries/linux64/a.so")).expect("file"),
            b"elf"
        );
    }

    #[test]
    fn refuses_zip_slip() {
        for name in ["../evil.txt", "/etc/evil", "a/../../evil"] {
            let z = write_zip(&[(name, b"x")]);
            let err = unpack(z.path(), UnpackLimits::default())
                .expect_err(name)
                .to_string();
            assert!(err.contains("zip-slip"), "{name}: {err}");
        }
    }

    #[test]
    fn refuses_bombs_by_size_and_count() {
        let big = vec![0u8; 10_000];
        let z = write_zip(&[("a", &big), ("b", &big)]);
        let err = unpack(
            z.path(),
            UnpackLimits {
                max_entries: 10,
                max_total_bytes: 15_000,
            },
        )
        .expect_err("too big");
        assert!(err.to_string().contains("zip bomb"), "{err}");
        let err = unpack(
            z.path(),
            UnpackLimits {
                max_entries: 1,
                max_total_bytes: 1 << 20,
            },
        )
        .expect_err("too many");
        assert!(err.to_string().contains("entries"), "{err}");
    }

    #[test]
    fn refuses_links() {
        let file = tempfile::NamedTempFile::new().expect("temp file");
        let mut zip = zip::ZipWriter::new(file.reopen().expect("reopen"));
        zip.add_symlink(
            "link",
            "/etc/passwd",
            zip::write::SimpleFileOptions::default(),
        )
        .expect("symlink");
        zip.finish().expect("finish");
        let err = unpack(file.path(), UnpackLimits::default()).expect_err("link");
        assert!(err.to_string().contains("symbolic link"), "{err}");
    }

    #[test]
    fn refuses_what_is_not_a_zip() {
        let mut f = tempfile::NamedTempFile::new().expect("temp");
        f.write_all(b"not a zip").expect("write");
        let err = unpack(f.path(), UnpackLimits::default()).expect_err("not zip");
        assert!(err.to_string().contains("not a zip"), "{err}");
    }
}
