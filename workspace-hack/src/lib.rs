//! No code: this crate's manifest gives the workspace's builds one feature set for the
//! dependencies they share (see its Cargo.toml).
