//! The FMUs built into this binary (orchestrator/build.rs: the FMU crates built and packed as
//! `scripts/build-fmus.sh` does, the archives included with `include_bytes!`), so an installed
//! `twin` or Python package needs neither the repository nor an environment variable.
//!
//! An embedded FMU is written, when first asked for, into the per-user FMU cache
//! ([`fmu_cache_root`]) as `embedded/<modelIdentifier>-<hash>.fmu`, the hash (64-bit FNV-1a,
//! computed by build.rs) being of the archive's bytes: a new build never uses an old build's
//! file, and the import layer then unpacks it into the cache like any other FMU. A file already
//! there is used only if it has the embedded archive's size and end (its central directory, see
//! [`written_file`]); other builds' files of the same FMU idle for a day are removed. Without a
//! usable cache (`TWIN_FMU_CACHE=off`, no home, a read-only one) the archives go into a temporary
//! directory of this process's own.

use std::io;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, OnceLock};
use std::time::{Duration, SystemTime};

use crate::cosim::import::{fmu_cache_root, EMBEDDED_ARCHIVES};

/// One FMU archive built into the binary.
pub struct EmbeddedFmu {
    /// `<modelIdentifier>.fmu`.
    pub file_name: &'static str,
    /// 64-bit FNV-1a of `bytes`.
    pub hash: u64,
    pub bytes: &'static [u8],
}

// `pub static EMBEDDED: &[EmbeddedFmu]`, written by build.rs (empty where the packer has no
// platform directory for the target).
include!(concat!(env!("OUT_DIR"), "/embedded_fmus.rs"));

/// A file of another build unused for this long is removed when a new one is written.
const IDLE_BEFORE_REMOVAL: Duration = Duration::from_secs(24 * 3600);

/// The embedded FMU of that file name, if this binary carries it.
pub fn embedded(file_name: &str) -> Option<&'static EmbeddedFmu> {
    EMBEDDED.iter().find(|f| f.file_name == file_name)
}

/// The path of the embedded FMU `fmu` on disk, written there on the first call of a process
/// (see the module's documentation).
pub fn path_of(fmu: &'static EmbeddedFmu) -> io::Result<PathBuf> {
    static WRITTEN: Mutex<Vec<(&'static str, PathBuf)>> = Mutex::new(Vec::new());
    let mut written = WRITTEN.lock().unwrap_or_else(|p| p.into_inner());
    if let Some((_, path)) = written.iter().find(|(name, _)| *name == fmu.file_name) {
        return Ok(path.clone());
    }
    let in_cache = fmu_cache_root()
        .map(|root| root.join(EMBEDDED_ARCHIVES))
        .and_then(|dir| write_into(&dir, fmu).ok());
    let path = match in_cache {
        Some(path) => path,
        None => write_into(process_directory()?, fmu)?,
    };
    written.push((fmu.file_name, path.clone()));
    Ok(path)
}

/// Write the embedded FMUs into `dir` as `<modelIdentifier>.fmu` (`twin export-fmus`).
pub fn export(dir: &Path) -> io::Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir)?;
    let mut paths = Vec::new();
    for fmu in EMBEDDED {
        let path = dir.join(fmu.file_name);
        crate::fsutil::write_atomically(&path, |f| io::Write::write_all(f, fmu.bytes))
            .map_err(|e| io::Error::new(e.source.kind(), e.to_string()))?;
        paths.push(path);
    }
    Ok(paths)
}

fn write_into(dir: &Path, fmu: &EmbeddedFmu) -> io::Result<PathBuf> {
    let stem = fmu.file_name.strip_suffix(".fmu").unwrap_or(fmu.file_name);
    let path = dir.join(format!("{stem}-{:016x}.fmu", fmu.hash));
    if let Some(file) = written_file(&path, fmu.bytes) {
        // Marks it as in use, so another build's process does not remove it.
        let _ = file.set_modified(SystemTime::now());
        return Ok(path);
    }
    let mut builder = std::fs::DirBuilder::new();
    builder.recursive(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::DirBuilderExt;
        builder.mode(0o700);
    }
    builder.create(dir)?;
    crate::fsutil::write_atomically(&path, |f| io::Write::write_all(f, fmu.bytes))
        .map_err(|e| io::Error::new(e.source.kind(), e.to_string()))?;
    remove_other_builds(dir, stem, &path);
    Ok(path)
}

/// The archive's bytes [`written_file`] compares: its end, where a zip archive keeps its central
/// directory (every entry's name, size and CRC-32) — far more than an FMU's few entries take.
const COMPARED_TAIL: usize = 64 * 1024;

/// The file at `path`, opened, when it is `bytes` as far as the FMU cache trusts an archive: the
/// same size and the same [`COMPARED_TAIL`], so the same entries with the same CRC-32s, which the
/// import layer checks each entry's bytes against as it unpacks them (the cache's key is made
/// of them too). Reading the whole archive back to compare it was a fifth of a `twin compare` of
/// the bundled record with the default twin (a 1.5 MB read, and as much of the binary paged in).
fn written_file(path: &Path, bytes: &[u8]) -> Option<std::fs::File> {
    use std::io::{Read, Seek, SeekFrom};
    let mut file = std::fs::File::open(path).ok()?;
    if file.metadata().ok()?.len() != bytes.len() as u64 {
        return None;
    }
    let tail = &bytes[bytes.len().saturating_sub(COMPARED_TAIL)..];
    file.seek(SeekFrom::End(-(tail.len() as i64))).ok()?;
    let mut read = vec![0; tail.len()];
    file.read_exact(&mut read).ok()?;
    (read == tail).then_some(file)
}

/// Remove `<stem>-<other hash>.fmu` files idle for [`IDLE_BEFORE_REMOVAL`].
fn remove_other_builds(dir: &Path, stem: &str, keep: &Path) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let now = SystemTime::now();
    for entry in entries.flatten() {
        let path = entry.path();
        let name = entry.file_name();
        let Some(rest) = name.to_str().and_then(|n| n.strip_prefix(stem)) else {
            continue;
        };
        let is_other_build = rest.len() == 1 + 16 + 4
            && rest.starts_with('-')
            && rest.ends_with(".fmu")
            && rest[1..17].bytes().all(|b| b.is_ascii_hexdigit());
        let idle = entry
            .metadata()
            .and_then(|m| m.modified())
            .map(|t| now.duration_since(t).unwrap_or_default());
        if is_other_build && path != keep && idle.is_ok_and(|d| d >= IDLE_BEFORE_REMOVAL) {
            let _ = std::fs::remove_file(&path);
        }
    }
}

/// This process's directory for the archives when the cache cannot hold them.
fn process_directory() -> io::Result<&'static Path> {
    static DIR: OnceLock<tempfile::TempDir> = OnceLock::new();
    if let Some(dir) = DIR.get() {
        return Ok(dir.path());
    }
    let dir = tempfile::Builder::new()
        .prefix("shear-twin-fmu-")
        .tempdir()?;
    Ok(DIR.get_or_init(|| dir).path())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_fmu_of_the_twin_is_embedded_with_its_hash() {
        for name in [
            crate::twin::SHEAR_FMU,
            "fmu_gp_corrector.fmu",
            "fmu_lqr.fmu",
            "fmu_substructure.fmu",
        ] {
            let fmu = embedded(name).unwrap_or_else(|| panic!("{name} is not embedded"));
            let mut hash: u64 = 0xcbf2_9ce4_8422_2325;
            for b in fmu.bytes {
                hash = (hash ^ u64::from(*b)).wrapping_mul(0x0100_0000_01b3);
            }
            assert_eq!(hash, fmu.hash, "{name}");
            // An FMU archive: a zip file's local header signature.
            assert_eq!(&fmu.bytes[..4], b"PK\x03\x04", "{name}");
        }
    }

    #[test]
    fn written_once_verified_and_old_builds_removed() {
        let dir = tempfile::tempdir().expect("tempdir");
        let fmu = embedded(crate::twin::SHEAR_FMU).expect("embedded");
        // Another build's file, idle for two days, and one used an hour ago.
        let old = dir.path().join("fmu_shear-00000000000000aa.fmu");
        let recent = dir.path().join("fmu_shear-00000000000000bb.fmu");
        for (path, age) in [(&old, 48), (&recent, 1)] {
            std::fs::write(path, b"old").expect("write");
            let f = std::fs::File::options()
                .write(true)
                .open(path)
                .expect("open");
            f.set_modified(SystemTime::now() - Duration::from_secs(age * 3600))
                .expect("mtime");
        }
        let path = write_into(dir.path(), fmu).expect("written");
        assert_eq!(std::fs::read(&path).expect("read"), fmu.bytes);
        assert!(!old.exists(), "a build idle for two days is removed");
        assert!(recent.exists(), "a build used an hour ago stays");
        // A damaged file of the same name is replaced, not used: one cut short, and one of the
        // right size whose central directory (at its end) was overwritten.
        std::fs::write(&path, b"truncated").expect("write");
        assert_eq!(write_into(dir.path(), fmu).expect("again"), path);
        assert_eq!(std::fs::read(&path).expect("read"), fmu.bytes);
        let mut damaged = fmu.bytes.to_vec();
        let last = damaged.len() - 30;
        damaged[last] ^= 0xff;
        std::fs::write(&path, &damaged).expect("write");
        assert_eq!(write_into(dir.path(), fmu).expect("again"), path);
        assert_eq!(std::fs::read(&path).expect("read"), fmu.bytes);
    }
}
