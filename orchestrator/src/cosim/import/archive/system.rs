//! A system's archive (a twin's `.ssp`) unpacked with its stored FMUs kept once in the FMU
//! cache's [`SYSTEM_ARCHIVES`] folder and linked, held while in use, evicted when idle.

use super::{
    create_private_dir, fmu_cache_root, open_zip, safe_relative_path, unpack, unpack_entries,
    UnpackLimits, Unpacked, CACHE_ENTRIES, IDLE_BEFORE_EVICTION, SYSTEM_ARCHIVES,
};
use crate::cosim::import::ImportError;
use std::fs::File;
use std::io::{self, Read};
use std::path::{Path, PathBuf};

/// [`unpack`] of a system's archive (a twin's `.ssp`) whose FMUs are stored entries (not
/// deflated, as `Twin::write` stores them): each such FMU is kept in the FMU cache's
/// [`SYSTEM_ARCHIVES`] folder as a file of its own, named by the entry's name, CRC-32 and size
/// (the trust the cache already gives an FMU's own entries, see [`unpack_fmu`]), and the
/// unpacked directory has a symbolic link to it where the entry would be. Opening the same twin
/// again, or another twin with the same FMU, then copies nothing: unpacking the 1.5 MB FMU of a
/// 10-storey twin into the memory file system and removing it at exit were a tenth of a `twin
/// compare`'s CPU time. A file there is used only if it has the entry's size; one is written
/// through a temporary file (the zip reader checks its CRC-32) and renamed into place. Without
/// a cache, or when anything about it fails, the entry is unpacked as [`unpack`] does.
pub fn unpack_system(archive: &Path, limits: UnpackLimits) -> Result<Unpacked, ImportError> {
    let folder = fmu_cache_root().map(|root| root.join(SYSTEM_ARCHIVES));
    unpack_system_into(archive, limits, folder.as_deref())
}

/// [`unpack_system`] with the FMUs kept in `folder` (none: no cache).
pub(super) fn unpack_system_into(
    archive: &Path,
    limits: UnpackLimits,
    folder: Option<&Path>,
) -> Result<Unpacked, ImportError> {
    let mut zip = open_zip(archive, limits)?;
    let Some(folder) = folder else {
        return unpack_entries(&mut zip, archive, limits, |_| true);
    };
    let linked: Vec<CachedFmu> = (0..zip.len())
        .filter_map(|index| cached_fmu(&mut zip, index, folder, limits))
        .collect();
    let mut unpacked = unpack_entries(&mut zip, archive, limits, |name| {
        !linked.iter().any(|c| c.name == name)
    })?;
    for CachedFmu { name, file, .. } in &linked {
        let target = safe_relative_path(name).map(|r| unpacked.path().join(r));
        let made = target.as_ref().is_some_and(|target| {
            target
                .parent()
                .is_some_and(|p| std::fs::create_dir_all(p).is_ok())
                && symlink_file(file, target).is_ok()
        });
        if !made {
            return unpack(archive, limits);
        }
    }
    let files: Vec<PathBuf> = linked.iter().map(|c| c.file.clone()).collect();
    // The folder grows only when a file is written: only then may it be over its bound (as the
    // FMU cache evicts only when it unpacks); a hit costs no listing of the folder.
    let wrote = linked.iter().any(|c| c.written);
    unpacked.held = linked.into_iter().map(|c| c.held).collect();
    if wrote {
        evict_archives(folder, &files);
    }
    Ok(unpacked)
}

/// A system's FMU entry kept in the FMU cache's archives folder (see [`cached_fmu`]).
struct CachedFmu {
    /// The entry's name in the system's archive.
    name: String,
    /// The cache's file.
    file: PathBuf,
    /// The file opened and share-locked ([`hold`]).
    held: File,
    /// Written by this call (not there before).
    written: bool,
}

/// The FMU cache's file of entry `index` of a system's archive when the entry is a stored
/// `resources/….fmu` and the file is there or could be written, held (a shared lock, see
/// [`hold`]).
fn cached_fmu(
    zip: &mut zip::ZipArchive<File>,
    index: usize,
    folder: &Path,
    limits: UnpackLimits,
) -> Option<CachedFmu> {
    let entry = zip.by_index_raw(index).ok()?;
    let name = entry.name().to_owned();
    let stored = entry.compression() == zip::CompressionMethod::Stored;
    let file_name = name
        .strip_prefix("resources/")
        .filter(|n| n.ends_with(".fmu") && !n.contains('/') && safe_relative_path(n).is_some())?;
    if !stored || entry.is_dir() || entry.is_symlink() || entry.size() > limits.max_total_bytes {
        return None;
    }
    let stem = file_name.strip_suffix(".fmu").unwrap_or(file_name);
    let (size, crc) = (entry.size(), entry.crc32());
    drop(entry);
    let path = folder.join(format!("{stem}-{crc:08x}-{size:x}.fmu"));
    if std::fs::metadata(&path).is_ok_and(|m| m.is_file() && m.len() == size) {
        if let Some(held) = hold(&path) {
            // Marked as recently used, so that eviction spares it.
            let _ = held.set_modified(std::time::SystemTime::now());
            return Some(CachedFmu {
                name,
                file: path,
                held,
                written: false,
            });
        }
    }
    create_private_dir(folder).ok()?;
    let mut entry = zip.by_index(index).ok()?;
    let mut tmp = tempfile::NamedTempFile::new_in(folder).ok()?;
    let written = io::copy(&mut (&mut entry).take(size + 1), tmp.as_file_mut()).ok()?;
    if written != size {
        return None;
    }
    tmp.persist(&path).ok()?;
    let held = hold(&path)?;
    Some(CachedFmu {
        name,
        file: path,
        held,
        written: true,
    })
}

/// `path` opened and share-locked (`flock`), if it is still the file at `path` once locked (an
/// eviction may have removed it in between): what keeps [`evict_archives`] from removing it.
pub(super) fn hold(path: &Path) -> Option<File> {
    let file = File::open(path).ok()?;
    #[cfg(unix)]
    {
        use rustix::fs::{flock, FlockOperation};
        use std::os::unix::fs::MetadataExt;
        flock(&file, FlockOperation::NonBlockingLockShared).ok()?;
        let (held, now) = (file.metadata().ok()?, std::fs::metadata(path).ok()?);
        if (held.dev(), held.ino()) != (now.dev(), now.ino()) {
            return None;
        }
    }
    Some(file)
}

/// Remove `path` unless a process holds it ([`hold`]): taken exclusively, without waiting.
fn remove_unheld(path: &Path) {
    #[cfg(unix)]
    {
        use rustix::fs::{flock, FlockOperation};
        let Ok(file) = File::open(path) else {
            return;
        };
        if flock(&file, FlockOperation::NonBlockingLockExclusive).is_err() {
            return;
        }
        let _ = std::fs::remove_file(path);
    }
    #[cfg(not(unix))]
    let _ = std::fs::remove_file(path);
}

#[cfg(unix)]
fn symlink_file(file: &Path, link: &Path) -> io::Result<()> {
    std::os::unix::fs::symlink(file, link)
}

#[cfg(not(unix))]
fn symlink_file(file: &Path, link: &Path) -> io::Result<()> {
    std::fs::copy(file, link).map(|_| ())
}

/// Remove the oldest files of [`SYSTEM_ARCHIVES`] beyond [`CACHE_ENTRIES`] among those idle for
/// [`IDLE_BEFORE_EVICTION`], never the ones just `linked` nor one another process holds.
pub(super) fn evict_archives(folder: &Path, linked: &[PathBuf]) {
    let Ok(entries) = std::fs::read_dir(folder) else {
        return;
    };
    let now = std::time::SystemTime::now();
    let mut dated: Vec<(std::time::SystemTime, PathBuf)> = entries
        .flatten()
        .map(|e| e.path())
        .filter(|p| !linked.contains(p))
        .filter_map(|p| Some((std::fs::metadata(&p).ok()?.modified().ok()?, p)))
        .collect();
    if dated.len() + linked.len() <= CACHE_ENTRIES {
        return;
    }
    dated.sort();
    let excess = dated.len() + linked.len() - CACHE_ENTRIES;
    for (modified, path) in dated.into_iter().take(excess) {
        if now.duration_since(modified).unwrap_or_default() >= IDLE_BEFORE_EVICTION {
            remove_unheld(&path);
        }
    }
}
