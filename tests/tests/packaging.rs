//! Packaging metadata: the licence files the crates' `MIT OR Apache-2.0`
//! refers to are at the repository root, and every Cargo manifest of the
//! repository (the host workspace, the firmware's, the fuzz targets') says
//! what it is, under which licence, points at a readme that exists and at
//! no made-up address.

use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

const MANIFESTS: [&str; 9] = [
    "Cargo.toml",
    "core/Cargo.toml",
    "host-sim/Cargo.toml",
    "tests/Cargo.toml",
    "web/Cargo.toml",
    "firmware/Cargo.toml",
    "firmware/scene/Cargo.toml",
    "firmware/host-ref/Cargo.toml",
    "fuzz/Cargo.toml",
];

fn read(rel: &str) -> String {
    let path = root().join(rel);
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()))
}

/// The value of `key = "..."` in `toml`, or `Some("workspace")` for
/// `key.workspace = true`.
fn field<'a>(toml: &'a str, key: &str) -> Option<&'a str> {
    toml.lines().find_map(|l| {
        if l.trim() == format!("{key}.workspace = true") {
            return Some("workspace");
        }
        let v = l.strip_prefix(key)?.trim_start().strip_prefix('=')?.trim();
        v.strip_prefix('"')?.strip_suffix('"')
    })
}

#[test]
fn licence_files_are_at_the_root() {
    let mit = read("LICENSE-MIT");
    assert!(mit.starts_with("Copyright (c) 2026 the isoscope developers\n"), "{mit}");
    assert!(mit.contains("Permission is hereby granted, free of charge"), "{mit}");
    let apache = read("LICENSE-APACHE");
    assert!(apache.contains("Apache License") && apache.contains("Version 2.0, January 2004"));
    assert!(apache.contains("END OF TERMS AND CONDITIONS"));
}

#[test]
fn every_manifest_is_honest() {
    let workspace = read("Cargo.toml");
    for rel in MANIFESTS {
        let toml = read(rel);
        assert!(!toml.contains(".invalid"), "{rel} names a made-up address");
        if rel == "Cargo.toml" {
            assert_eq!(field(&toml, "license"), Some("MIT OR Apache-2.0"), "{rel}");
            assert_eq!(field(&toml, "readme"), Some("README.md"), "{rel}");
            continue;
        }
        let dir = root().join(rel).parent().unwrap().to_owned();
        assert!(field(&toml, "description").is_some_and(|d| !d.is_empty()), "{rel}: no description");
        let license = match field(&toml, "license") {
            Some("workspace") => field(&workspace, "license"),
            l => l,
        };
        assert_eq!(license, Some("MIT OR Apache-2.0"), "{rel}");
        let readme = match field(&toml, "readme") {
            Some("workspace") => root().join(field(&workspace, "readme").unwrap()),
            Some(r) => dir.join(r),
            None => panic!("{rel}: no readme"),
        };
        assert!(readme.is_file(), "{rel}: readme {} does not exist", readme.display());
    }
}
