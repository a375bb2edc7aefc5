//! Helpers shared by the host tool's integration tests.

use std::path::{Path, PathBuf};

/// A cached real data file (`scripts/fetch-data`, which `scripts/test`
/// runs first); a missing one fails the test.
pub fn real_data(name: &str) -> PathBuf {
    let dir = std::env::var_os("ISOSCOPE_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/isoscope-data"));
    let path = dir.join(name);
    assert!(path.is_file(), "{} is missing: run scripts/fetch-data", path.display());
    path
}
