//! Hostile and broken `.fmu` and `.ssp` files: each is refused with an error naming the file and
//! the problem, never a panic; through the CLI, a one-line error and no partial output. Also a
//! simulation that diverges mid-run.
//!
//! Archives are built here with the zip crate; the well-formed parts are taken from the shear
//! FMU (`scripts/build-fmus.sh`, found through `TWIN_FMU_DIR`).

use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use orchestrator::import::{Fmu, ImportError, UnpackLimits};
use zip::write::SimpleFileOptions;

mod common;
use common::{fmu_dir, twin, workspace};

fn shear_fmu() -> PathBuf {
    fmu_dir().join("fmu_shear.fmu")
}

fn s(path: &Path) -> &str {
    path.to_str().expect("temporary paths are UTF-8")
}

/// Every entry of a zip archive, in order.
fn entries(path: &Path) -> Vec<(String, Vec<u8>)> {
    let mut zip =
        zip::ZipArchive::new(std::fs::File::open(path).expect("open")).expect("a zip archive");
    (0..zip.len())
        .map(|i| {
            let mut entry = zip.by_index(i).expect("entry");
            let mut bytes = Vec::new();
            entry.read_to_end(&mut bytes).expect("read entry");
            (entry.name().to_owned(), bytes)
        })
        .collect()
}

/// Entries stored uncompressed (quick in a debug build); `deflated` compresses them.
fn write_zip(path: &Path, entries: &[(String, Vec<u8>)]) {
    write_zip_with(path, entries, zip::CompressionMethod::Stored)
}

fn write_zip_with(path: &Path, entries: &[(String, Vec<u8>)], method: zip::CompressionMethod) {
    let mut zip = zip::ZipWriter::new(std::fs::File::create(path).expect("create"));
    let options = SimpleFileOptions::default()
        .compression_method(method)
        .large_file(false);
    for (name, bytes) in entries {
        zip.start_file(name.as_str(), options).expect("start entry");
        zip.write_all(bytes).expect("write entry");
    }
    zip.finish().expect("finish");
}

/// The shear FMU's modelDescription.xml.
fn shear_model_description() -> Vec<u8> {
    entries(&shear_fmu())
        .into_iter()
        .find(|(n, _)| n == "modelDescription.xml")
        .expect("the FMU has a modelDescription")
        .1
}

fn entry(name: &str, bytes: impl Into<Vec<u8>>) -> (String, Vec<u8>) {
    (name.to_owned(), bytes.into())
}

/// Open `path` as an FMU and return the error, failing the test if it opened.
fn refused(path: &Path, limits: UnpackLimits) -> String {
    match Fmu::open_with_limits(path, limits) {
        Ok(_) => panic!("{} was accepted", path.display()),
        Err(e) => {
            eprintln!("{}: refused: {e}", path.display());
            e.to_string()
        }
    }
}

fn assert_names(message: &str, path: &Path, problem: &str) {
    assert!(
        message.contains(s(path)),
        "the message names the file {}: {message}",
        path.display()
    );
    assert!(
        message.contains(problem),
        "the message says '{problem}': {message}"
    );
}

#[test]
fn zip_slip_and_absolute_entries_are_refused_and_nothing_lands_outside() {
    let dir = tempfile::tempdir().expect("temp dir");
    // Unique names, so that "nothing was written there" means something.
    let escape_name = format!("twin-hostile-{}", std::process::id());
    let outside = dir.path().join("outside");
    std::fs::create_dir(&outside).expect("mkdir");
    let cases = [
        ("slip.fmu", format!("../{escape_name}")),
        ("deep_slip.fmu", format!("resources/../../../{escape_name}")),
        (
            "absolute.fmu",
            format!("{}/{escape_name}", outside.display()),
        ),
    ];
    for (file, hostile) in cases {
        let path = dir.path().join(file);
        write_zip(
            &path,
            &[
                entry("modelDescription.xml", shear_model_description()),
                entry(&hostile, b"evil".to_vec()),
            ],
        );
        let message = refused(&path, UnpackLimits::default());
        assert_names(&message, &path, "zip-slip");
        assert!(
            message.contains(&hostile),
            "the message names the entry: {message}"
        );
    }
    assert!(
        !std::env::temp_dir().join(&escape_name).exists(),
        "a '..' entry escaped the unpack directory"
    );
    assert!(
        !outside.join(&escape_name).exists(),
        "an absolute entry was written"
    );
}

#[test]
fn symbolic_link_entries_are_refused() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("link.fmu");
    let mut zip = zip::ZipWriter::new(std::fs::File::create(&path).expect("create"));
    zip.start_file("modelDescription.xml", SimpleFileOptions::default())
        .expect("start");
    zip.write_all(&shear_model_description()).expect("write");
    zip.add_symlink(
        "binaries/linux64/fmu_shear.so",
        "/lib/x86_64-linux-gnu/libc.so.6",
        SimpleFileOptions::default(),
    )
    .expect("symlink");
    zip.finish().expect("finish");
    let message = refused(&path, UnpackLimits::default());
    assert_names(&message, &path, "symbolic link");
}

#[test]
fn a_zip_bomb_is_stopped_at_the_size_limit() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("bomb.fmu");
    // 16 MiB of zeros deflate to ~16 KiB; the limit here is 1 MiB, so unpacking must stop.
    let zeros = vec![0u8; 16 << 20];
    write_zip_with(
        &path,
        &[
            entry("modelDescription.xml", shear_model_description()),
            entry("binaries/linux64/fmu_shear.so", zeros),
        ],
        zip::CompressionMethod::Deflated,
    );
    let packed = std::fs::metadata(&path).expect("metadata").len();
    assert!(
        packed < 1 << 20,
        "the bomb must be small packed to test anything: {packed} bytes"
    );
    let message = refused(
        &path,
        UnpackLimits {
            max_entries: 100,
            max_total_bytes: 1 << 20,
        },
    );
    assert_names(&message, &path, "zip bomb");
}

#[test]
fn an_archive_over_the_default_entry_limit_is_refused() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("many.fmu");
    let limit = UnpackLimits::default().max_entries;
    let mut zip = zip::ZipWriter::new(std::fs::File::create(&path).expect("create"));
    let options = SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
    zip.start_file("modelDescription.xml", options)
        .expect("start");
    zip.write_all(&shear_model_description()).expect("write");
    for i in 0..limit {
        zip.start_file(format!("resources/{i}"), options)
            .expect("start");
    }
    zip.finish().expect("finish");
    let message = refused(&path, UnpackLimits::default());
    assert_names(
        &message,
        &path,
        &format!("{} entries, more than the limit of {limit}", limit + 1),
    );
}

#[test]
fn missing_and_foreign_binaries_are_refused_naming_the_platforms_present() {
    let dir = tempfile::tempdir().expect("temp dir");
    let missing = dir.path().join("no_binary.fmu");
    write_zip(
        &missing,
        &[entry("modelDescription.xml", shear_model_description())],
    );
    let message = refused(&missing, UnpackLimits::default());
    assert_names(
        &message,
        &missing,
        "no binary binaries/linux64/fmu_shear.so",
    );
    assert!(message.contains("platforms present: none"), "{message}");

    let foreign = dir.path().join("win64_only.fmu");
    write_zip(
        &foreign,
        &[
            entry("modelDescription.xml", shear_model_description()),
            entry("binaries/win64/x.dll", b"MZ".to_vec()),
        ],
    );
    let message = refused(&foreign, UnpackLimits::default());
    assert_names(
        &message,
        &foreign,
        "no binary binaries/linux64/fmu_shear.so",
    );
    assert!(message.contains("platforms present: win64"), "{message}");

    // A file where the library should be that is no shared library at all.
    let garbage = dir.path().join("garbage_binary.fmu");
    write_zip(
        &garbage,
        &[
            entry("modelDescription.xml", shear_model_description()),
            entry("binaries/linux64/fmu_shear.so", b"not an ELF file".to_vec()),
        ],
    );
    let message = refused(&garbage, UnpackLimits::default());
    assert_names(&message, &garbage, "cannot load");
}

#[test]
fn a_guid_mismatch_fails_at_instantiation_saying_so() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("other_guid.fmu");
    let md = String::from_utf8(shear_model_description()).expect("UTF-8");
    let start = md.find("guid=\"").expect("a guid attribute") + "guid=\"".len();
    let end = start + md[start..].find('"').expect("closing quote");
    let real = md[start..end].to_owned();
    let fake = "{00000000-0000-0000-0000-000000000000}";
    assert_ne!(real, fake);
    let changed = format!("{}{fake}{}", &md[..start], &md[end..]);
    let rebuilt: Vec<_> = entries(&shear_fmu())
        .into_iter()
        .map(|(name, bytes)| {
            if name == "modelDescription.xml" {
                (name, changed.clone().into_bytes())
            } else {
                (name, bytes)
            }
        })
        .collect();
    write_zip(&path, &rebuilt);

    // The archive itself is well formed: it opens, and the mismatch shows at fmi2Instantiate.
    let fmu = Fmu::open(&path).expect("a well-formed archive opens");
    assert_eq!(fmu.model_description.guid, fake);
    let err = match fmu.instantiate("hostile") {
        Ok(_) => panic!("an instance was made despite the GUID mismatch"),
        Err(e) => e,
    };
    assert!(
        matches!(
            err,
            ImportError::Call {
                call: "fmi2Instantiate",
                ..
            }
        ),
        "{err:?}"
    );
    let message = err.to_string();
    assert!(message.contains("GUID"), "the message says GUID: {message}");
    assert!(
        message.contains(fake) && message.contains(&real),
        "the message gives both GUIDs: {message}"
    );
    assert!(
        message.contains("hostile"),
        "the message names the instance: {message}"
    );
}

#[test]
fn malformed_model_descriptions_and_non_archives_are_refused() {
    let dir = tempfile::tempdir().expect("temp dir");
    // (file, its entries, a word of the problem)
    type Case = (&'static str, Vec<(String, Vec<u8>)>, &'static str);
    let cases: Vec<Case> = vec![
        (
            "malformed.fmu",
            vec![entry(
                "modelDescription.xml",
                b"<fmiModelDescription fmiVersion=\"2.0\"".to_vec(),
            )],
            "malformed",
        ),
        (
            "no_md.fmu",
            vec![entry("binaries/linux64/fmu_shear.so", b"x".to_vec())],
            "no readable modelDescription.xml",
        ),
        (
            "fmi3.fmu",
            vec![entry(
                "modelDescription.xml",
                String::from_utf8(shear_model_description())
                    .expect("UTF-8")
                    .replace("fmiVersion=\"2.0\"", "fmiVersion=\"3.0\""),
            )],
            "only FMI 2.0",
        ),
    ];
    for (file, content, problem) in cases {
        let path = dir.path().join(file);
        write_zip(&path, &content);
        assert_names(&refused(&path, UnpackLimits::default()), &path, problem);
    }

    let not_zip = dir.path().join("not_a_zip.fmu");
    std::fs::write(&not_zip, b"PK? no, just text").expect("write");
    assert_names(
        &refused(&not_zip, UnpackLimits::default()),
        &not_zip,
        "not a zip archive",
    );

    let empty = dir.path().join("empty.fmu");
    std::fs::write(&empty, b"").expect("write");
    assert_names(
        &refused(&empty, UnpackLimits::default()),
        &empty,
        "not a zip archive",
    );

    // The real FMU cut in half: the central directory is gone.
    let truncated = dir.path().join("truncated.fmu");
    let bytes = std::fs::read(shear_fmu()).expect("read");
    std::fs::write(&truncated, &bytes[..bytes.len() / 2]).expect("write");
    assert_names(
        &refused(&truncated, UnpackLimits::default()),
        &truncated,
        "not a zip archive",
    );

    let absent = dir.path().join("absent.fmu");
    assert_names(
        &refused(&absent, UnpackLimits::default()),
        &absent,
        "cannot open",
    );
}

// ---------------------------------------------------------------------------------------------
// Through the CLI.

/// `twin init` into `dir`, then the entries for which `replace` returns bytes replaced.
fn rewritten_twin(dir: &Path, name: &str, replace: impl Fn(&str) -> Option<Vec<u8>>) -> PathBuf {
    let default = dir.join("default.ssp");
    if !default.exists() {
        let output = twin(&["init", "--out", s(&default)]);
        assert!(
            output.status.success(),
            "twin init: {}",
            String::from_utf8_lossy(&output.stderr)
        );
    }
    let path = dir.join(name);
    let mut replaced = 0;
    let rebuilt: Vec<_> = entries(&default)
        .into_iter()
        .map(|(n, bytes)| match replace(&n) {
            Some(new) => {
                replaced += 1;
                (n, new)
            }
            None => (n, bytes),
        })
        .collect();
    assert!(replaced > 0, "nothing of the twin archive was replaced");
    write_zip(&path, &rebuilt);
    path
}

fn physics_ssv(parameters: &str) -> Vec<u8> {
    format!(
        "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<ssv:ParameterSet xmlns:ssv=\"http://ssp-standard.org/SSP1/SystemStructureParameterValues\" version=\"1.0\" name=\"physics\">\n<ssv:Parameters>{parameters}</ssv:Parameters>\n</ssv:ParameterSet>\n"
    )
    .into_bytes()
}

/// `twin compare --twin <archive>` on dataset1 fails with one line containing every `needles`,
/// and leaves the report and predictions as they were (absent, or a previous report untouched).
fn compare_fails(archive: &Path, needles: &[&str]) -> String {
    let dir = archive.parent().expect("parent");
    let report = dir.join("report.json");
    let predictions = dir.join("predictions.csv");
    let _ = std::fs::remove_file(&predictions);
    std::fs::write(&report, "previous report\n").expect("write");
    let data = workspace().join("data/dataset1.csv");
    let output = twin(&[
        "compare",
        "--twin",
        s(archive),
        "--data",
        s(&data),
        "--report",
        s(&report),
        "--predictions",
        s(&predictions),
    ]);
    let stderr = String::from_utf8_lossy(&output.stderr).into_owned();
    assert_eq!(
        output.status.code(),
        Some(1),
        "{}: exit code; stderr:\n{stderr}",
        archive.display()
    );
    let message = stderr.trim_end();
    eprintln!("{}: {message}", archive.display());
    assert_eq!(
        message.lines().count(),
        1,
        "{}: one line:\n{stderr}",
        archive.display()
    );
    assert!(!message.contains("panicked"), "{message}");
    for needle in needles {
        assert!(
            message.contains(needle),
            "{}: the message says '{needle}': {message}",
            archive.display()
        );
    }
    assert_eq!(
        std::fs::read_to_string(&report).expect("report"),
        "previous report\n",
        "the previous report was overwritten"
    );
    assert!(!predictions.exists(), "predictions were written");
    message.to_owned()
}

#[test]
fn hostile_twin_archives_fail_the_cli_with_one_line_and_no_output() {
    let dir = tempfile::tempdir().expect("temp dir");

    let not_zip = dir.path().join("not_a_zip.ssp");
    std::fs::write(&not_zip, b"hello").expect("write");
    compare_fails(&not_zip, &[s(&not_zip), "not a zip archive"]);

    let slip = dir.path().join("slip.ssp");
    write_zip(
        &slip,
        &[
            entry("SystemStructure.ssd", b"<x/>".to_vec()),
            entry("../evil", b"x".to_vec()),
        ],
    );
    compare_fails(&slip, &[s(&slip), "zip-slip"]);

    let other_guid = rewritten_twin(dir.path(), "other_guid.ssp", |name| {
        (name == "resources/fmu_shear.fmu").then(|| {
            let md = String::from_utf8(shear_model_description()).expect("UTF-8");
            let start = md.find("guid=\"").expect("guid") + "guid=\"".len();
            let end = start + md[start..].find('"').expect("quote");
            let changed = format!(
                "{}{{11111111-2222-3333-4444-555555555555}}{}",
                &md[..start],
                &md[end..]
            );
            let fmu = dir.path().join("other_guid_inner.fmu");
            let rebuilt: Vec<_> = entries(&shear_fmu())
                .into_iter()
                .map(|(n, b)| {
                    if n == "modelDescription.xml" {
                        (n, changed.clone().into_bytes())
                    } else {
                        (n, b)
                    }
                })
                .collect();
            write_zip(&fmu, &rebuilt);
            std::fs::read(&fmu).expect("read")
        })
    });
    compare_fails(&other_guid, &["GUID mismatch", "physics"]);

    let broken_fmu = rewritten_twin(dir.path(), "broken_fmu.ssp", |name| {
        (name == "resources/fmu_shear.fmu").then(|| b"garbage".to_vec())
    });
    compare_fails(&broken_fmu, &["fmu_shear.fmu", "not a zip archive"]);

    let bad_ssd = rewritten_twin(dir.path(), "bad_ssd.ssp", |name| {
        (name == "SystemStructure.ssd").then(|| b"<ssd:System".to_vec())
    });
    compare_fails(&bad_ssd, &[s(&bad_ssd), "SystemStructure.ssd"]);

    let unknown_parameter = rewritten_twin(dir.path(), "unknown_parameter.ssp", |name| {
        (name == "resources/physics.ssv").then(|| {
            physics_ssv(r#"<ssv:Parameter name="k9"><ssv:Real value="1"/></ssv:Parameter>"#)
        })
    });
    compare_fails(&unknown_parameter, &["k9"]);

    compare_fails(&dir.path().join("absent.ssp"), &["absent.ssp"]);
}

#[test]
fn a_diverging_simulation_fails_with_the_time_and_no_output() {
    let dir = tempfile::tempdir().expect("temp dir");
    // k1 = 1e12 N/m with one RK4 step per sample: ω·h ≈ 8.6e3, far outside RK4's stability
    // region, so the state overflows within a few dozen steps and fmi2DoStep reports an error.
    let stiff = rewritten_twin(dir.path(), "diverging.ssp", |name| {
        (name == "resources/physics.ssv").then(|| {
            physics_ssv(
                r#"<ssv:Parameter name="k1"><ssv:Real value="1e12"/></ssv:Parameter><ssv:Parameter name="substeps"><ssv:Integer value="1"/></ssv:Parameter>"#,
            )
        })
    });
    let message = compare_fails(&stiff, &["at t = ", "fmi2DoStep", "fmi2Error", "diverged"]);
    let time: f64 = message
        .split("at t = ")
        .nth(1)
        .and_then(|rest| rest.split(':').next())
        .and_then(|t| t.trim().trim_end_matches(" s").parse().ok())
        .unwrap_or_else(|| panic!("no time in: {message}"));
    assert!(
        time > 0.0 && time < 20.0,
        "the failure time {time} lies inside the record"
    );
}
