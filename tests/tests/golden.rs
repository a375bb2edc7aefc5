//! The CSV export of a small gyroid (n = 8, levels 0 and 0.5, all planes, corrected
//! traversal, one thread), byte for byte against a golden file.
//!
//! Run with `ISOSCOPE_BLESS=1` to (re)write `golden/gyroid8.csv` after an
//! intended change of the output.

use isoscope_core::contour::grid::Plane;
use isoscope_core::demo::Demo;
use isoscope_sim::contour::write_csv;
use isoscope_tests::contour_demo;
use std::path::PathBuf;

const LEVELS: [f32; 2] = [0.0, 0.5];

/// Samples per axis. The gyroid's four periods make nearly every cell cross
/// both levels (8 commands a cell): n = 8 gives a 245 KB file, n = 10 would
/// give 520 KB.
const GOLDEN_N: usize = 8;

fn golden_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("golden").join("gyroid8.csv")
}

#[test]
fn gyroid8_matches_golden_csv() {
    let contoured = contour_demo(Demo::Gyroid, GOLDEN_N, &LEVELS, &Plane::ALL, 1);
    let mut csv = Vec::new();
    write_csv(&mut csv, &contoured, &LEVELS).expect("write_csv into a Vec");
    let path = golden_path();
    if std::env::var_os("ISOSCOPE_BLESS").is_some_and(|v| v == "1") {
        std::fs::create_dir_all(path.parent().expect("golden dir")).expect("create golden dir");
        std::fs::write(&path, &csv).expect("write golden file");
        eprintln!("blessed {} ({} bytes)", path.display(), csv.len());
        return;
    }
    let golden = std::fs::read(&path).unwrap_or_else(|e| {
        panic!("cannot read {}: {e} (run with ISOSCOPE_BLESS=1 to create it)", path.display())
    });
    if csv == golden {
        return;
    }
    let (got, want) = (String::from_utf8_lossy(&csv), String::from_utf8_lossy(&golden));
    let (mut g, mut w) = (got.lines(), want.lines());
    let mut line = 1;
    loop {
        match (g.next(), w.next()) {
            (Some(a), Some(b)) if a == b => line += 1,
            (None, None) => panic!(
                "the CSV differs from {} only in line endings or a final newline ({} bytes now, {} golden)",
                path.display(),
                csv.len(),
                golden.len()
            ),
            (a, b) => panic!(
                "the CSV differs from {} at line {line}:\n  golden: {}\n  now:    {}\n\
                 ({} lines now, {} golden; ISOSCOPE_BLESS=1 rewrites the file if the change is intended)",
                path.display(),
                b.unwrap_or("<end of file>"),
                a.unwrap_or("<end of file>"),
                got.lines().count(),
                want.lines().count(),
            ),
        }
    }
}
