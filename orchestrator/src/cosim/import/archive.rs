//! Unpacking an archive (`.fmu`, `.ssp`) into a private temporary directory, refusing what a
//! hostile archive can do: absolute paths, `..` components, links (zip-slip) and bombs (too
//! many entries, too many bytes once inflated).
//!
//! The directory is in memory when the machine has a memory file system that may hold code
//! (see [`memory_root`]): on a disk file system the files' creation and removal were most of a
//! `twin compare`'s time (12 of 19 ms on this project's machine, with the FMU's binary only
//! copied), and nothing of an unpacked archive outlives the process.

use std::collections::BTreeSet;
use std::fs::File;
use std::io::{self, Read};
use std::path::{Component, Path, PathBuf};
use std::sync::Mutex;

use super::ImportError;

mod system;
pub use system::unpack_system;
#[cfg(test)]
use system::{evict_archives, hold, unpack_system_into};

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

/// An unpacked archive: a private temporary directory, removed when this is dropped, or an
/// FMU's directory in the FMU cache ([`unpack_fmu`]), left there for the next process.
#[derive(Debug)]
pub struct Unpacked {
    place: Place,
    /// Shared locks on the FMU cache's archive files this directory links to
    /// ([`unpack_system`]), held while it lives: eviction leaves a locked file alone, so a
    /// long-running process (a watch) can still read its twin's FMU days later.
    held: Vec<File>,
}

#[derive(Debug)]
enum Place {
    Temporary(tempfile::TempDir),
    Cached {
        dir: PathBuf,
        key: String,
    },
    /// A private directory with the archive's resources and links to a cache entry's files.
    Linked {
        dir: tempfile::TempDir,
        key: String,
        entry: PathBuf,
    },
}

impl Unpacked {
    pub fn path(&self) -> &Path {
        match &self.place {
            Place::Temporary(dir) | Place::Linked { dir, .. } => dir.path(),
            Place::Cached { dir, .. } => dir,
        }
    }

    /// Whether this is a directory of the FMU cache, or links into one.
    pub fn is_cached(&self) -> bool {
        self.cache_entry().is_some()
    }

    /// The FMU cache's directory of this archive, when it is one or links into one: where what
    /// is derived from the archive's files alone may be kept for the next process.
    pub fn cache_entry(&self) -> Option<&Path> {
        match &self.place {
            Place::Cached { dir, .. } | Place::Linked { entry: dir, .. } => Some(dir),
            Place::Temporary(_) => None,
        }
    }
}

impl Drop for Unpacked {
    fn drop(&mut self) {
        if let Place::Cached { key, .. } | Place::Linked { key, .. } = &self.place {
            cache_keys_in_use().remove(key);
        }
    }
}

/// The cache keys this process has open: a second open of the same FMU while the first is
/// loaded gets a private copy, so that each open has its own copy of the library (loading one
/// path twice would share one copy and its globals), as without the cache.
fn cache_keys_in_use() -> std::sync::MutexGuard<'static, BTreeSet<String>> {
    static IN_USE: Mutex<BTreeSet<String>> = Mutex::new(BTreeSet::new());
    IN_USE
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// The cache's folder of the FMU archives built into the binary (`crate::twin::embedded`),
/// which [`evict`] leaves alone.
pub const EMBEDDED_ARCHIVES: &str = "embedded";

/// The cache's folder of the FMU archives stored in twins' archives ([`unpack_system`]), which
/// [`evict`] leaves alone (they have their own limit).
pub const SYSTEM_ARCHIVES: &str = "archives";

/// How many FMUs the cache keeps; beyond, the oldest idle ones are removed when one is added.
const CACHE_ENTRIES: usize = 16;

/// An entry used more recently than this is never evicted (another process may be opening it).
const IDLE_BEFORE_EVICTION: std::time::Duration = std::time::Duration::from_secs(24 * 3600);

/// The FMU cache's directory: `$TWIN_FMU_CACHE` (empty or `off`: no cache), else
/// `$XDG_CACHE_HOME/shear-twin/fmu`, else `$HOME/.cache/shear-twin/fmu`.
pub fn fmu_cache_root() -> Option<PathBuf> {
    if let Some(dir) = std::env::var_os("TWIN_FMU_CACHE") {
        return (!dir.is_empty() && dir != "off").then(|| PathBuf::from(dir));
    }
    let base = std::env::var_os("XDG_CACHE_HOME")
        .filter(|d| !d.is_empty())
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache")))?;
    Some(base.join("shear-twin").join("fmu"))
}

/// An FMU unpacked once per version and then reused: a `twin` process otherwise spends most of
/// its start inflating the FMU's library out of the archive and removing it at exit.
///
/// The cache holds an FMU's files outside `resources/` (an FMU may keep state there, so each
/// open gets its own copy of those, unpacked from the archive into a private directory beside
/// links to the cache's files). The key is a 64-bit FNV-1a hash of those entries of the
/// archive's central directory: every entry's name, CRC-32, sizes and kind, so a rebuilt FMU is
/// a new entry; an entry is unpacked into a temporary directory beside the others and renamed
/// into place, so a reader never sees half of one, and two processes filling the same entry
/// both succeed. A second open of the same FMU while the first is loaded gets a private
/// directory with the cache's files copied (its own copy of the library, see
/// [`cache_keys_in_use`]). Anything that goes wrong with the cache falls back to [`unpack`],
/// which also gives refusals of hostile archives their usual message.
pub fn unpack_fmu(archive: &Path, limits: UnpackLimits) -> Result<Unpacked, ImportError> {
    if let Some(root) = fmu_cache_root() {
        if let Some(unpacked) = unpack_cached(archive, &root, limits) {
            return Ok(unpacked);
        }
    }
    unpack(archive, limits)
}

/// Is this entry of an FMU in its `resources/` folder?
fn is_resource(name: &str) -> bool {
    name == "resources" || name.starts_with("resources/")
}

/// What the cache needs of an archive: its key, and whether it has resources.
struct CacheKey {
    key: String,
    resources: bool,
    declared: u64,
}

fn cache_key(
    archive: &Path,
    zip: &mut zip::ZipArchive<File>,
    limits: UnpackLimits,
) -> Option<CacheKey> {
    if zip.len() > limits.max_entries {
        return None;
    }
    let mut hash = Fnv1a::new();
    let mut declared: u64 = 0;
    let mut resources = false;
    for index in 0..zip.len() {
        let entry = zip.by_index_raw(index).ok()?;
        let name = entry.name();
        if safe_relative_path(name).is_none() || entry.is_symlink() {
            return None;
        }
        declared = declared.saturating_add(entry.size());
        if is_resource(name) {
            resources = true;
            continue;
        }
        hash.write(name.as_bytes());
        hash.write(&[0, u8::from(entry.is_dir())]);
        hash.write(&entry.crc32().to_le_bytes());
        hash.write(&entry.size().to_le_bytes());
        hash.write(&entry.compressed_size().to_le_bytes());
    }
    if declared > limits.max_total_bytes {
        return None;
    }
    let stem = archive.file_stem()?.to_string_lossy();
    let stem: String = stem
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' || c == '-' {
                c
            } else {
                '_'
            }
        })
        .take(64)
        .collect();
    Some(CacheKey {
        key: format!("{stem}-{:016x}", hash.finish()),
        resources,
        declared,
    })
}

fn unpack_cached(archive: &Path, root: &Path, limits: UnpackLimits) -> Option<Unpacked> {
    let file = File::open(archive).ok()?;
    let mut zip = zip::ZipArchive::new(file).ok()?;
    let CacheKey {
        key,
        resources,
        declared,
    } = cache_key(archive, &mut zip, limits)?;
    let mut in_use = cache_keys_in_use();
    let dir = root.join(&key);
    // A hit marks the entry as used now: eviction spares entries used within IDLE_BEFORE_EVICTION.
    let touched = File::open(&dir)
        .and_then(|d| d.set_modified(std::time::SystemTime::now()))
        .is_ok();
    if !touched || !dir.join("modelDescription.xml").is_file() {
        create_private_dir(root).ok()?;
        let fresh = unpack_into(&mut zip, root, archive, limits, |n| !is_resource(n))
            .ok()?
            .keep();
        if std::fs::rename(&fresh, &dir).is_err() {
            // Another process put it there first (or the rename failed): ours goes.
            let _ = std::fs::remove_dir_all(&fresh);
            if !dir.join("modelDescription.xml").is_file() {
                return None;
            }
        } else {
            evict(root, &key, &in_use);
        }
    }
    let first = !in_use.contains(&key);
    if first && !resources {
        in_use.insert(key.clone());
        return Some(Unpacked {
            place: Place::Cached { dir, key },
            held: Vec::new(),
        });
    }
    // A directory of this open's own: the resources from the archive, the rest linked to the
    // entry (the first open) or copied from it (a second one in this process).
    let own_root = memory_root(declared).unwrap_or_else(std::env::temp_dir);
    let own = unpack_into(&mut zip, &own_root, archive, limits, is_resource).ok()?;
    link_or_copy(&dir, own.path(), first).ok()?;
    Some(Unpacked {
        place: if first {
            in_use.insert(key.clone());
            Place::Linked {
                dir: own,
                key,
                entry: dir,
            }
        } else {
            Place::Temporary(own)
        },
        held: Vec::new(),
    })
}

/// Every file under `from` into the same place under `to`: a symbolic link to it (`link`), or
/// a copy.
fn link_or_copy(from: &Path, to: &Path, link: bool) -> io::Result<()> {
    for entry in std::fs::read_dir(from)? {
        let entry = entry?;
        let (source, target) = (entry.path(), to.join(entry.file_name()));
        if entry.file_type()?.is_dir() {
            std::fs::create_dir_all(&target)?;
            link_or_copy(&source, &target, link)?;
        } else if link {
            #[cfg(unix)]
            std::os::unix::fs::symlink(&source, &target)?;
            #[cfg(not(unix))]
            std::fs::copy(&source, &target)?;
        } else {
            std::fs::copy(&source, &target)?;
        }
    }
    Ok(())
}

/// `dir` and its parents, `dir` itself readable by its owner only.
fn create_private_dir(dir: &Path) -> io::Result<()> {
    let mut builder = std::fs::DirBuilder::new();
    builder.recursive(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::DirBuilderExt;
        builder.mode(0o700);
    }
    builder.create(dir)
}

/// Remove the oldest entries beyond [`CACHE_ENTRIES`] among those unused for
/// [`IDLE_BEFORE_EVICTION`] (the cache may hold more while they are in recent use), never
/// `keep` or this process's entries in use; leftovers of interrupted unpacks go the same way.
/// An entry is touched when it is used, so another process does not lose an entry while it
/// opens it (a process that has loaded an evicted FMU keeps its mapping of the library).
fn evict(root: &Path, keep: &str, in_use: &BTreeSet<String>) {
    let Ok(entries) = std::fs::read_dir(root) else {
        return;
    };
    let now = std::time::SystemTime::now();
    let mut dated: Vec<(std::time::SystemTime, PathBuf)> = entries
        .flatten()
        .filter(|e| {
            let name = e.file_name();
            name != keep
                && name != EMBEDDED_ARCHIVES
                && name != SYSTEM_ARCHIVES
                && !name.to_str().is_some_and(|n| in_use.contains(n))
        })
        .filter_map(|e| Some((e.metadata().ok()?.modified().ok()?, e.path())))
        .collect();
    if dated.len() < CACHE_ENTRIES {
        return;
    }
    dated.sort();
    let excess = dated.len() + 1 - CACHE_ENTRIES;
    for (modified, path) in dated.into_iter().take(excess) {
        let idle = now.duration_since(modified).unwrap_or_default();
        if idle >= IDLE_BEFORE_EVICTION {
            let _ = std::fs::remove_dir_all(&path);
        }
    }
}

/// 64-bit FNV-1a.
struct Fnv1a(u64);

impl Fnv1a {
    fn new() -> Self {
        Self(0xcbf2_9ce4_8422_2325)
    }

    fn write(&mut self, bytes: &[u8]) {
        for b in bytes {
            self.0 = (self.0 ^ u64::from(*b)).wrapping_mul(0x0100_0000_01b3);
        }
    }

    fn finish(&self) -> u64 {
        self.0
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
    let mut zip = open_zip(archive, limits)?;
    unpack_entries(&mut zip, archive, limits, |_| true)
}

/// The archive at `archive` as a zip, refused with its name when it is none or has more
/// entries than `limits` allow.
fn open_zip(archive: &Path, limits: UnpackLimits) -> Result<zip::ZipArchive<File>, ImportError> {
    let bad = |message: String| ImportError::Archive {
        path: archive.to_owned(),
        message,
    };
    let file = File::open(archive).map_err(|e| bad(format!("cannot open: {e}")))?;
    let zip = zip::ZipArchive::new(file).map_err(|e| bad(format!("not a zip archive: {e}")))?;
    if zip.len() > limits.max_entries {
        return Err(bad(format!(
            "{} entries, more than the limit of {}",
            zip.len(),
            limits.max_entries
        )));
    }
    Ok(zip)
}

/// The entries of `zip` that `wanted` takes, into a temporary directory: in memory when there is
/// room (see [`memory_root`]), else in the system's temporary directory.
fn unpack_entries(
    zip: &mut zip::ZipArchive<File>,
    archive: &Path,
    limits: UnpackLimits,
    wanted: impl Fn(&str) -> bool + Copy,
) -> Result<Unpacked, ImportError> {
    let declared: u64 = (0..zip.len())
        .filter_map(|i| zip.by_index_raw(i).ok().map(|e| e.size()))
        .fold(0, u64::saturating_add);
    if let Some(root) = memory_root(declared) {
        // In memory no more than the entries declare (so a bomb cannot fill the memory), and
        // any failure there is no reason to fail: the unpack is done again in the system's
        // temporary directory, which refuses what is to be refused with the usual message.
        let in_memory = UnpackLimits {
            max_total_bytes: limits.max_total_bytes.min(declared),
            ..limits
        };
        if let Ok(dir) = unpack_into(zip, &root, archive, in_memory, wanted) {
            return Ok(Unpacked {
                place: Place::Temporary(dir),
                held: Vec::new(),
            });
        }
    }
    let dir = unpack_into(zip, &std::env::temp_dir(), archive, limits, wanted)?;
    Ok(Unpacked {
        place: Place::Temporary(dir),
        held: Vec::new(),
    })
}

/// A directory of a memory file system (tmpfs) to unpack `declared` bytes into, when there is
/// one: `$XDG_RUNTIME_DIR`, then `/dev/shm`, if it is tmpfs, not mounted `noexec` (an FMU's
/// library is loaded from it) and has at least four times `declared` bytes free. `TMPDIR`, when
/// set, wins: the user chose where temporary files go.
fn memory_root(declared: u64) -> Option<PathBuf> {
    #[cfg(target_os = "linux")]
    {
        const TMPFS_MAGIC: u64 = 0x0102_1994;
        if std::env::var_os("TMPDIR").is_some() {
            return None;
        }
        let candidates = std::env::var_os("XDG_RUNTIME_DIR")
            .map(PathBuf::from)
            .into_iter()
            .chain([PathBuf::from("/dev/shm")]);
        for dir in candidates {
            let (Ok(fs), Ok(vfs)) = (rustix::fs::statfs(&dir), rustix::fs::statvfs(&dir)) else {
                continue;
            };
            let free = vfs.f_bavail.saturating_mul(vfs.f_frsize);
            if fs.f_type as u64 == TMPFS_MAGIC
                && !vfs.f_flag.contains(rustix::fs::StatVfsMountFlags::NOEXEC)
                && !vfs.f_flag.contains(rustix::fs::StatVfsMountFlags::RDONLY)
                && free / 4 >= declared
            {
                return Some(dir);
            }
        }
        None
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = declared;
        None
    }
}

/// The entries of `zip` whose names `wanted` takes, into a new temporary directory under `root`.
fn unpack_into(
    zip: &mut zip::ZipArchive<File>,
    root: &Path,
    archive: &Path,
    limits: UnpackLimits,
    wanted: impl Fn(&str) -> bool,
) -> Result<tempfile::TempDir, ImportError> {
    let bad = |message: String| ImportError::Archive {
        path: archive.to_owned(),
        message,
    };
    let dir = tempfile::Builder::new()
        .prefix("twin-unpack-")
        .tempdir_in(root)
        .map_err(|e| bad(format!("cannot create a temporary directory: {e}")))?;
    let mut total: u64 = 0;
    for index in 0..zip.len() {
        let mut entry = zip
            .by_index(index)
            .map_err(|e| bad(format!("entry {index}: {e}")))?;
        let name = entry.name().to_owned();
        if !wanted(&name) {
            continue;
        }
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
    Ok(dir)
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

    /// The cache: filled once, reused after; a second open while the first is alive gets a
    /// private copy (from the cache); another version is another entry; an FMU with resources
    /// gets them fresh in a directory of its own, the rest linked to the cache; hostile
    /// archives are not cached; the oldest entries go beyond the limit.
    #[test]
    fn the_fmu_cache_reuses_an_entry_and_isolates_concurrent_opens() {
        let root = tempfile::tempdir().expect("temp dir");
        let limits = UnpackLimits::default();
        let v1 = write_zip(&[
            ("modelDescription.xml", b"<x/>"),
            ("binaries/linux64/a.so", b"one"),
        ]);
        let first = unpack_cached(v1.path(), root.path(), limits).expect("cached");
        assert!(first.is_cached() && first.path().starts_with(root.path()));
        assert_eq!(
            std::fs::read(first.path().join("binaries/linux64/a.so")).expect("so"),
            b"one"
        );
        let second = unpack_cached(v1.path(), root.path(), limits).expect("a copy");
        let library = |u: &Unpacked| u.path().join("binaries/linux64/a.so");
        assert!(
            !second.path().starts_with(root.path())
                && !std::fs::symlink_metadata(library(&second))
                    .expect("so")
                    .is_symlink()
                && std::fs::read(library(&second)).expect("so") == b"one",
            "a second open while the first is loaded must get its own copy"
        );
        let dir = first.path().to_owned();
        drop(first);
        drop(second);
        assert!(dir.is_dir(), "a cache entry outlives its user");
        let again = unpack_cached(v1.path(), root.path(), limits).expect("cached");
        assert_eq!(again.path(), dir);

        let v2 = write_zip(&[
            ("modelDescription.xml", b"<x/>"),
            ("binaries/linux64/a.so", b"two"),
        ]);
        let other = unpack_cached(v2.path(), root.path(), limits).expect("cached");
        assert_ne!(other.path(), dir);
        assert_eq!(
            std::fs::read(other.path().join("binaries/linux64/a.so")).expect("so"),
            b"two"
        );

        let with_resources = write_zip(&[
            ("modelDescription.xml", b"<x/>"),
            ("binaries/linux64/r.so", b"code"),
            ("resources/t.json", b"{}"),
        ]);
        let linked = unpack_cached(with_resources.path(), root.path(), limits).expect("linked");
        let so = linked.path().join("binaries/linux64/r.so");
        assert!(linked.is_cached() && !linked.path().starts_with(root.path()));
        assert!(std::fs::symlink_metadata(&so).expect("so").is_symlink());
        assert_eq!(std::fs::read(&so).expect("so"), b"code");
        assert!(std::fs::canonicalize(&so)
            .expect("target")
            .starts_with(std::fs::canonicalize(root.path()).expect("root")));
        // The resources are this open's own: a change there is not seen by the next open.
        let resource = linked.path().join("resources/t.json");
        std::fs::write(&resource, b"changed").expect("write");
        let copied = unpack_cached(with_resources.path(), root.path(), limits).expect("copy");
        assert_eq!(
            std::fs::read(copied.path().join("resources/t.json")).expect("t"),
            b"{}"
        );
        assert!(
            !std::fs::symlink_metadata(copied.path().join("binaries/linux64/r.so"))
                .expect("so")
                .is_symlink()
        );
        let linked_dir = linked.path().to_owned();
        drop(linked);
        drop(copied);
        assert!(
            !linked_dir.exists(),
            "a linked open's directory goes with it"
        );
        assert!(
            std::fs::read_dir(root.path())
                .expect("root")
                .flatten()
                .all(|e| !e.path().join("resources").exists()),
            "the cache holds no resources"
        );
        let hostile = write_zip(&[("../evil", b"x")]);
        assert!(unpack_cached(hostile.path(), root.path(), limits).is_none());
        assert!(unpack_fmu(hostile.path(), limits)
            .expect_err("refused")
            .to_string()
            .contains("zip-slip"));

        // v1, v2 and the FMU with resources.
        let entries = || std::fs::read_dir(root.path()).expect("list").count();
        assert_eq!(entries(), 3);
        drop((again, other));
        let fill = |from: usize, to: usize| -> Vec<tempfile::NamedTempFile> {
            (from..to)
                .map(|k| {
                    let z = write_zip(&[
                        ("modelDescription.xml", b"<x/>"),
                        ("binaries/linux64/a.so", format!("v{k}").as_bytes()),
                    ]);
                    drop(unpack_cached(z.path(), root.path(), limits).expect("cached"));
                    z
                })
                .collect()
        };
        // Entries in recent use are never evicted, however many.
        let recent = fill(0, CACHE_ENTRIES + 3);
        assert_eq!(entries(), CACHE_ENTRIES + 6);
        // Once idle for a day, the oldest go beyond the limit.
        let day_ago = std::time::SystemTime::now() - IDLE_BEFORE_EVICTION;
        for entry in std::fs::read_dir(root.path()).expect("list").flatten() {
            File::open(entry.path())
                .and_then(|d| d.set_modified(day_ago))
                .expect("age the entry");
        }
        let last = fill(100, 101);
        assert_eq!(entries(), CACHE_ENTRIES);
        // A used entry was touched: an entry that was just used is found again.
        let again = unpack_cached(last[0].path(), root.path(), limits).expect("cached");
        assert!(again.path().join("binaries/linux64/a.so").is_file());
        drop((recent, last));
    }

    /// A twin's stored FMU is kept once in the cache's folder and linked, its other entries
    /// unpacked; a deflated FMU, or no cache, is unpacked as before; a damaged file in the
    /// folder (another size) is written again.
    #[test]
    fn a_systems_stored_fmus_are_linked_from_the_cache() {
        let fmu_bytes = vec![7u8; 70_000];
        let ssp = |method: zip::CompressionMethod| {
            let file = tempfile::NamedTempFile::new().expect("tmp");
            let mut zip = zip::ZipWriter::new(file.reopen().expect("reopen"));
            let deflated = zip::write::SimpleFileOptions::default();
            zip.start_file("SystemStructure.ssd", deflated)
                .expect("ssd");
            zip.write_all(b"<ssd/>").expect("write");
            let options = deflated.compression_method(method);
            zip.start_file("resources/fmu_shear.fmu", options)
                .expect("fmu");
            zip.write_all(&fmu_bytes).expect("write");
            zip.finish().expect("finish");
            file
        };
        let (stored, deflated) = (
            ssp(zip::CompressionMethod::Stored),
            ssp(zip::CompressionMethod::Deflated),
        );
        let folder = tempfile::tempdir().expect("folder");
        let limits = UnpackLimits::default();
        let open = |archive: &Path, folder: Option<&Path>| {
            let unpacked = unpack_system_into(archive, limits, folder).expect("unpacked");
            let fmu = unpacked.path().join("resources/fmu_shear.fmu");
            assert_eq!(std::fs::read(&fmu).expect("fmu"), fmu_bytes);
            let ssd = std::fs::read(unpacked.path().join("SystemStructure.ssd")).expect("ssd");
            assert_eq!(ssd, b"<ssd/>");
            let linked = std::fs::symlink_metadata(&fmu)
                .expect("meta")
                .file_type()
                .is_symlink();
            (unpacked, linked)
        };
        let cached = || {
            std::fs::read_dir(folder.path())
                .expect("folder")
                .map(|e| e.expect("entry").path())
                .collect::<Vec<_>>()
        };
        let (first, linked) = open(stored.path(), Some(folder.path()));
        assert!(linked && cfg!(unix), "the stored FMU is linked");
        let files = cached();
        assert_eq!(files.len(), 1, "{files:?}");
        drop(first);
        assert!(files[0].is_file(), "the cache's file outlives the twin");
        let (_again, linked) = open(stored.path(), Some(folder.path()));
        assert!(linked);
        assert_eq!(cached(), files, "the same file reused");
        std::fs::write(&files[0], b"damaged").expect("damage");
        let (_repaired, _) = open(stored.path(), Some(folder.path()));
        assert_eq!(std::fs::read(&files[0]).expect("read"), fmu_bytes);
        let (_deflated, linked) = open(deflated.path(), Some(folder.path()));
        assert!(!linked, "a deflated FMU is unpacked");
        let (_uncached, linked) = open(stored.path(), None);
        assert!(!linked, "without a cache the FMU is unpacked");
    }

    /// Beyond the cache's limit the oldest idle archive files go, but not one a process holds
    /// (a twin open in a long-running watch reads its FMU long after opening it).
    #[test]
    fn eviction_spares_an_archive_a_process_holds() {
        let folder = tempfile::tempdir().expect("folder");
        let files: Vec<PathBuf> = (0..CACHE_ENTRIES + 2)
            .map(|i| {
                let path = folder.path().join(format!("fmu_shear-{i:08x}-10.fmu"));
                std::fs::write(&path, b"archive").expect("write");
                let age = std::time::Duration::from_secs(3600 * (100 - i as u64));
                let f = File::options().write(true).open(&path).expect("open");
                f.set_modified(std::time::SystemTime::now() - age)
                    .expect("mtime");
                path
            })
            .collect();
        // The oldest is held; the two oldest are beyond the limit.
        let held = hold(&files[0]).expect("held");
        evict_archives(folder.path(), &[]);
        assert!(files[0].exists(), "a held archive stays");
        assert_eq!(
            files[1].exists(),
            !cfg!(unix),
            "an idle one beyond the limit goes"
        );
        assert!(files[2..].iter().all(|f| f.exists()));
        drop(held);
        evict_archives(folder.path(), &[]);
        assert!(!files[0].exists() || !cfg!(unix), "released, it goes too");
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
