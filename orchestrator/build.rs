//! The FMI logger (C), and the FMUs built into `twin`: the four FMU crates built as shared
//! libraries by a nested `cargo build --release`, packed into `.fmu` archives by the same packer
//! as `twin pack-fmu` (src/cosim/pack.rs), and embedded with `include_bytes!`
//! (src/twin/embedded.rs), so that an installed `twin` (`cargo install --path orchestrator`) or
//! Python package (`pip install ./python`) finds its FMUs without the repository.

use std::path::{Path, PathBuf};
use std::process::Command;

// The packer of `twin pack-fmu`, so the embedded archives are byte for byte what
// scripts/build-fmus.sh would write.
#[allow(dead_code)]
#[path = "src/fsutil.rs"]
mod fsutil;
#[allow(dead_code)]
#[path = "src/cosim/pack.rs"]
mod pack;

/// (crate, modelIdentifier) of each embedded FMU.
const FMUS: [(&str, &str); 4] = [
    ("fmu-shear", "fmu_shear"),
    ("fmu-gp-corrector", "fmu_gp_corrector"),
    ("fmu-lqr", "fmu_lqr"),
    ("fmu-substructure", "fmu_substructure"),
];

fn main() {
    println!("cargo:rerun-if-changed=src/cosim/import/logger.c");
    cc::Build::new()
        .file("src/cosim/import/logger.c")
        .warnings(true)
        .compile("twin_fmi2_logger");
    embed_fmus();
}

fn env(name: &str) -> String {
    std::env::var(name).unwrap_or_else(|_| panic!("cargo sets {name} for build scripts"))
}

fn embed_fmus() {
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-changed=src/cosim/pack.rs");
    let out_dir = PathBuf::from(env("OUT_DIR"));
    let generated = out_dir.join("embedded_fmus.rs");
    let manifest_dir = PathBuf::from(env("CARGO_MANIFEST_DIR"));
    let workspace = manifest_dir
        .parent()
        .expect("the orchestrator crate sits in the workspace")
        .to_owned();

    // The archives name their library binaries/linux64/<id>.so (the packer's only platform).
    if env("CARGO_CFG_TARGET_OS") != "linux" || env("CARGO_CFG_TARGET_POINTER_WIDTH") != "64" {
        println!("cargo:warning=no FMUs embedded: the packer writes linux64 FMUs only");
        write_table(&generated, &[]);
        return;
    }

    let libraries = prebuilt_libraries(&workspace, &out_dir)
        .unwrap_or_else(|| build_libraries(&workspace, &out_dir));
    let fmu_dir = out_dir.join("fmu");
    let mut table = Vec::new();
    for (krate, id) in FMUS {
        let crate_dir = workspace.join(krate);
        let folder = |name: &str| Some(crate_dir.join(name)).filter(|d| d.is_dir());
        let contents = pack::FmuContents {
            model_description: workspace.join("modelDescription").join(format!("{id}.xml")),
            library: libraries.join(format!("lib{}.so", krate.replace('-', "_"))),
            documentation: folder("documentation"),
            resources: folder("resources"),
        };
        let archive = fmu_dir.join(format!("{id}.fmu"));
        if let Err(err) = pack::pack_fmu(&contents, &archive) {
            panic!("packing {}: {err}", archive.display());
        }
        for path in [&contents.model_description, &crate_dir.join("Cargo.toml")] {
            println!("cargo:rerun-if-changed={}", path.display());
        }
        for dir in [&contents.documentation, &contents.resources]
            .into_iter()
            .flatten()
        {
            println!("cargo:rerun-if-changed={}", dir.display());
        }
        table.push((format!("{id}.fmu"), archive));
    }
    write_table(&generated, &table);
}

/// `src/twin/embedded.rs` includes this: the file names and bytes of the archives.
fn write_table(path: &Path, archives: &[(String, PathBuf)]) {
    let mut code = String::from("pub static EMBEDDED: &[EmbeddedFmu] = &[\n");
    for (name, archive) in archives {
        let bytes = std::fs::read(archive)
            .unwrap_or_else(|err| panic!("reading {}: {err}", archive.display()));
        // 64-bit FNV-1a of the archive: its file name in the FMU cache.
        let mut hash: u64 = 0xcbf2_9ce4_8422_2325;
        for b in &bytes {
            hash = (hash ^ u64::from(*b)).wrapping_mul(0x0100_0000_01b3);
        }
        code.push_str(&format!(
            "    EmbeddedFmu {{ file_name: {name:?}, hash: {hash:#018x}, bytes: include_bytes!({:?}) }},\n",
            archive.display().to_string()
        ));
    }
    code.push_str("];\n");
    if let Err(err) = std::fs::write(path, code) {
        panic!("writing {}: {err}", path.display());
    }
}

/// The libraries scripts/build-fmus.sh built just before `twin`, in `<target>/fmu-libs` (each
/// with its dep-info), when they are newer than every source they were built from; else None.
///
/// That script builds them in the outer target directory with the features `twin`'s build
/// gives the shared dependencies (workspace-hack), so nalgebra, faer, rustfft and the rest are
/// compiled once for both; the nested build below compiles them a second time in a target
/// directory of its own (255 s of `.ci/run`'s 920-s FMU build, measured on a clean clone).
fn prebuilt_libraries(workspace: &Path, out_dir: &Path) -> Option<PathBuf> {
    if env("TARGET") != env("HOST") {
        return None;
    }
    // OUT_DIR is <target>/<profile>/build/<package>-<hash>/out.
    let dir = out_dir.ancestors().nth(4)?.join("fmu-libs");
    if !dir.is_dir() {
        return None;
    }
    let mtime = |path: &Path| std::fs::metadata(path).and_then(|m| m.modified()).ok();
    let mut watched = Vec::new();
    for (krate, _) in FMUS {
        let stem = format!("lib{}", krate.replace('-', "_"));
        let library = dir.join(format!("{stem}.so"));
        let dep_info = dir.join(format!("{stem}.d"));
        let built = mtime(&library)?;
        let text = std::fs::read_to_string(&dep_info).ok()?;
        let mut sources = dep_info_paths(&text);
        sources.extend(
            [
                "Cargo.lock",
                "Cargo.toml",
                "fmi2/Cargo.toml",
                "numerics/Cargo.toml",
            ]
            .iter()
            .map(|name| workspace.join(name)),
        );
        sources.push(workspace.join(krate).join("Cargo.toml"));
        if let Some(newer) = sources
            .iter()
            .find(|s| mtime(s).map_or(true, |t| t > built))
        {
            println!(
                "cargo:warning={} is older than {}: the FMUs are built again (scripts/build-fmus.sh refreshes it)",
                library.display(),
                newer.display()
            );
            return None;
        }
        watched.push(library);
        watched.extend(sources.into_iter().filter(|s| s.starts_with(workspace)));
    }
    for path in watched {
        println!("cargo:rerun-if-changed={}", path.display());
    }
    Some(dir)
}

/// Build the FMU crates' shared libraries (with `exports`, the fmi2* C names) in release mode;
/// returns the directory that holds them.
///
/// The nested cargo has a target directory of its own, so it never waits on the lock of the
/// build that runs this script: `embedded-fmus` in the outer target directory (the nearest
/// ancestor of OUT_DIR holding cargo's CACHEDIR.TAG), shared by the debug and release builds,
/// `cargo install --target-dir` and maturin, so the FMUs are compiled once per target
/// directory; else a directory in OUT_DIR. The outer build's jobserver (CARGO_MAKEFLAGS) is
/// inherited, so the nested build shares its job slots.
fn build_libraries(workspace: &Path, out_dir: &Path) -> PathBuf {
    let target_dir = out_dir
        .ancestors()
        .skip(1)
        .find(|dir| dir.join("CACHEDIR.TAG").is_file())
        .map(|dir| dir.join("embedded-fmus"))
        .unwrap_or_else(|| out_dir.join("embedded-fmus"));
    let target = env("TARGET");
    let cross = target != env("HOST");

    // One `cargo rustc` per FMU: the crates are rlibs (what `twin` links) and become the
    // FMU's cdylib only here, with `exports`.
    for (krate, _) in FMUS {
        let mut command = Command::new(env("CARGO"));
        command
            .arg("rustc")
            .arg("--release")
            .arg("--manifest-path")
            .arg(workspace.join("Cargo.toml"))
            .arg("--target-dir")
            .arg(&target_dir)
            .args([
                "-p",
                krate,
                "--lib",
                "--crate-type",
                "cdylib",
                "--features",
                "exports",
            ]);
        if cross {
            command.arg("--target").arg(&target);
        }
        // What the outer build sets for itself must not steer (or lock) the nested one: its
        // target and build directories, its target triple, and wrappers such as clippy-driver.
        // The target's compiler flags carry over, through the variable cargo documents for that.
        for name in [
            "CARGO_TARGET_DIR",
            "CARGO_BUILD_TARGET_DIR",
            "CARGO_BUILD_BUILD_DIR",
            "CARGO_BUILD_TARGET",
            "RUSTFLAGS",
            "CARGO_BUILD_RUSTFLAGS",
            "RUSTC_WORKSPACE_WRAPPER",
            "CARGO_PRIMARY_PACKAGE",
        ] {
            command.env_remove(name);
        }
        match std::env::var("CARGO_ENCODED_RUSTFLAGS") {
            Ok(flags) => command.env("CARGO_ENCODED_RUSTFLAGS", flags),
            Err(_) => command.env_remove("CARGO_ENCODED_RUSTFLAGS"),
        };

        let status = command
            .status()
            .unwrap_or_else(|err| panic!("running {command:?}: {err}"));
        if !status.success() {
            panic!("building the FMUs failed ({status}): {command:?}");
        }
    }
    let mut libraries = target_dir;
    if cross {
        libraries.push(&target);
    }
    libraries.push("release");

    // Rebuild when a source of an FMU (its crate or a workspace crate it uses) changes: the
    // files listed in the libraries' dep-info, those under the workspace, and the lock file.
    println!(
        "cargo:rerun-if-changed={}",
        workspace.join("Cargo.lock").display()
    );
    println!(
        "cargo:rerun-if-changed={}",
        workspace.join("Cargo.toml").display()
    );
    let mut sources = std::collections::BTreeSet::new();
    for (krate, _) in FMUS {
        let dep_info = libraries.join(format!("lib{}.d", krate.replace('-', "_")));
        let text = std::fs::read_to_string(&dep_info)
            .unwrap_or_else(|err| panic!("reading {}: {err}", dep_info.display()));
        sources.extend(
            dep_info_paths(&text)
                .into_iter()
                .filter(|p| p.starts_with(workspace)),
        );
    }
    for crate_dir in ["fmi2", "numerics"] {
        sources.insert(workspace.join(crate_dir).join("Cargo.toml"));
    }
    for source in sources {
        println!("cargo:rerun-if-changed={}", source.display());
    }
    libraries
}

/// The prerequisites of a makefile-style dep-info file (`target: dep dep …`, spaces in names
/// escaped with a backslash).
fn dep_info_paths(text: &str) -> Vec<PathBuf> {
    let mut paths = Vec::new();
    for line in text.lines() {
        let Some((_, deps)) = line.split_once(": ") else {
            continue;
        };
        let mut current = String::new();
        let mut chars = deps.chars();
        while let Some(c) = chars.next() {
            match c {
                '\\' => current.extend(chars.next()),
                ' ' => {
                    if !current.is_empty() {
                        paths.push(PathBuf::from(std::mem::take(&mut current)));
                    }
                }
                _ => current.push(c),
            }
        }
        if !current.is_empty() {
            paths.push(PathBuf::from(current));
        }
    }
    paths
}
