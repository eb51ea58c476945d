fn main() {
    println!("cargo:rerun-if-changed=src/cosim/import/logger.c");
    cc::Build::new()
        .file("src/cosim/import/logger.c")
        .warnings(true)
        .compile("twin_fmi2_logger");
}
