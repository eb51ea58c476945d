fn main() {
    println!("cargo:rerun-if-changed=src/import/logger.c");
    cc::Build::new()
        .file("src/import/logger.c")
        .warnings(true)
        .compile("twin_fmi2_logger");
}
