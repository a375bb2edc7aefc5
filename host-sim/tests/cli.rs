//! End-to-end tests of `isoscope-sim contour`: the binary is run as a child
//! process and its standard output, standard error and exit status checked.

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::atomic::{AtomicUsize, Ordering};

const HEADER: &str = "level,axis,slice,op,x,y,z";

/// Run `isoscope-sim` with `args`.
fn run(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_isoscope-sim"))
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("cannot run isoscope-sim {args:?}: {e}"))
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8(bytes.to_vec()).expect("output is not UTF-8")
}

/// Run `contour` and expect success; the CSV on standard output.
fn contour_ok(args: &[&str]) -> String {
    let mut all = vec!["contour"];
    all.extend_from_slice(args);
    let out = run(&all);
    assert!(out.status.success(), "isoscope-sim {all:?} failed with {}:\n{}", out.status, text(&out.stderr));
    text(&out.stdout)
}

/// A temporary directory, removed on drop.
struct TempDir(PathBuf);

impl TempDir {
    fn new(name: &str) -> Self {
        static NEXT: AtomicUsize = AtomicUsize::new(0);
        let n = NEXT.fetch_add(1, Ordering::Relaxed);
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.subsec_nanos());
        let dir =
            std::env::temp_dir().join(format!("isoscope-cli-{}-{name}-{n}-{nanos}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("cannot create a temporary directory");
        Self(dir)
    }

    /// Write `bytes` to `name` in the directory; its path as a string.
    fn file(&self, name: &str, bytes: &[u8]) -> String {
        let p = self.0.join(name);
        std::fs::write(&p, bytes).expect("cannot write a temporary file");
        path_str(&p)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn path_str(p: &Path) -> String {
    p.to_str().expect("temporary path is not UTF-8").to_owned()
}

fn le_u16(v: &[u16]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

fn le_i16(v: &[i16]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

fn le_f32(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// One CSV record.
#[derive(Debug, Clone, PartialEq)]
struct Rec {
    level: String,
    axis: String,
    slice: usize,
    op: char,
    p: [f32; 3],
}

/// Parse a CSV export, checking the header and the shape of every line.
fn parse_csv(csv: &str) -> Vec<Rec> {
    let mut lines = csv.lines();
    assert_eq!(lines.next(), Some(HEADER), "missing or wrong header");
    lines
        .enumerate()
        .map(|(i, line)| {
            let f: Vec<&str> = line.split(',').collect();
            assert_eq!(f.len(), 7, "line {}: `{line}` has {} fields", i + 2, f.len());
            let op = match f[3] {
                "M" => 'M',
                "L" => 'L',
                "P" => 'P',
                other => panic!("line {}: op `{other}` is not M, L or P", i + 2),
            };
            assert!(matches!(f[1], "xy" | "xz" | "yz"), "line {}: axis `{}`", i + 2, f[1]);
            let level: f32 = f[0].parse().unwrap_or_else(|_| panic!("line {}: level `{}`", i + 2, f[0]));
            assert!(level.is_finite(), "line {}: level {level}", i + 2);
            let slice = f[2].parse().unwrap_or_else(|_| panic!("line {}: slice `{}`", i + 2, f[2]));
            let mut p = [0f32; 3];
            for (k, c) in p.iter_mut().enumerate() {
                *c = f[4 + k].parse().unwrap_or_else(|_| panic!("line {}: coordinate `{}`", i + 2, f[4 + k]));
                assert!(c.is_finite(), "line {}: coordinate {c} is not finite", i + 2);
            }
            Rec { level: f[0].to_owned(), axis: f[1].to_owned(), slice, op, p }
        })
        .collect()
}

/// Every (level, axis, slice) starts its commands with M or P, and every
/// point lies in `[0, max]^3` with the slice coordinate equal to the slice.
fn check_records(recs: &[Rec], max: [f32; 3]) {
    let mut started: HashSet<(&str, &str, usize)> = HashSet::new();
    for (i, r) in recs.iter().enumerate() {
        if started.insert((&r.level, &r.axis, r.slice)) {
            assert_ne!(r.op, 'L', "line {}: {r:?} is an L with no M or P before it in its slice", i + 2);
        }
        for (c, m) in r.p.iter().zip(max) {
            assert!((0.0..=m).contains(c), "line {}: {r:?} outside the volume", i + 2);
        }
        let normal = match r.axis.as_str() {
            "xy" => r.p[2],
            "xz" => r.p[1],
            _ => r.p[0],
        };
        assert_eq!(normal, r.slice as f32, "line {}: {r:?} is not on its slice", i + 2);
    }
}

/// Parse the `key=value` lines of `--stats`.
fn parse_stats(stderr: &str) -> HashMap<String, String> {
    stderr.lines().filter_map(|l| l.split_once('=')).map(|(k, v)| (k.to_owned(), v.to_owned())).collect()
}

fn stat_u64(stats: &HashMap<String, String>, key: &str) -> u64 {
    stats
        .get(key)
        .unwrap_or_else(|| panic!("--stats has no {key}: {stats:?}"))
        .parse()
        .unwrap_or_else(|_| panic!("{key} is not a whole number: {stats:?}"))
}

#[test]
fn demo_hydrogen_csv_is_well_formed() {
    let csv = contour_ok(&["--demo", "hydrogen:32"]);
    let recs = parse_csv(&csv);
    assert!(recs.len() > 1000, "only {} commands", recs.len());
    check_records(&recs, [31.0; 3]);
    for axis in ["xy", "xz", "yz"] {
        assert!(recs.iter().any(|r| r.axis == axis), "no {axis} commands");
    }
    // The default level of the hydrogen demo.
    assert!(recs.iter().all(|r| r.level == "0.1"));
}

#[test]
fn output_file_equals_standard_output() {
    let dir = TempDir::new("output");
    let path = path_str(&dir.0.join("out.csv"));
    let stdout = contour_ok(&["--demo", "gyroid:8", "--threads", "2"]);
    let quiet = contour_ok(&["--demo", "gyroid:8", "--threads", "2", "-o", &path]);
    assert_eq!(quiet, "", "-o still wrote to standard output");
    assert_eq!(std::fs::read_to_string(&path).unwrap(), stdout);
}

#[test]
fn stats_without_output() {
    let out = run(&["contour", "--demo", "hydrogen:32", "--format", "none", "--stats"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(out.stdout.is_empty(), "--format none wrote {} bytes", out.stdout.len());
    let stats = parse_stats(&text(&out.stderr));
    for key in [
        "cells",
        "crossing_cells",
        "nonfinite_cells",
        "commands",
        "levels",
        "threads",
        "seconds",
        "mcells_per_s",
    ] {
        assert!(stats.contains_key(key), "--stats has no {key}:\n{}", text(&out.stderr));
    }
    assert_eq!(stat_u64(&stats, "cells"), 3 * 32 * 31 * 31);
    assert_eq!(stat_u64(&stats, "nonfinite_cells"), 0);
    assert_eq!(stat_u64(&stats, "levels"), 1);
    assert!(stat_u64(&stats, "threads") >= 1);
    let crossing = stat_u64(&stats, "crossing_cells");
    assert!(crossing > 0 && crossing <= 3 * 32 * 31 * 31);
    for key in ["seconds", "mcells_per_s"] {
        let v: f64 = stats[key].parse().unwrap_or_else(|_| panic!("{key} is not a number: {stats:?}"));
        assert!(v.is_finite() && v >= 0.0, "{key}={v}");
    }
    // The commands counted are the commands written.
    let csv = contour_ok(&["--demo", "hydrogen:32"]);
    assert_eq!(stat_u64(&stats, "commands"), csv.lines().count() as u64 - 1);
}

#[test]
fn stats_count_cells_of_the_chosen_planes_and_levels() {
    let out = run(&[
        "contour",
        "--demo",
        "gyroid:12",
        "--axes",
        "xz",
        "--level",
        "0",
        "--level",
        "0.5",
        "--threads",
        "3",
        "--format",
        "none",
        "--stats",
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let stats = parse_stats(&text(&out.stderr));
    assert_eq!(stat_u64(&stats, "cells"), 12 * 11 * 11);
    assert_eq!(stat_u64(&stats, "levels"), 2);
    assert_eq!(stat_u64(&stats, "threads"), 3);
}

const GYROID_TWO_LEVELS: [&str; 6] = ["--demo", "gyroid:20", "--level", "-0.3", "--level", "0.4"];

#[test]
fn output_does_not_depend_on_thread_count() {
    let with = |t: &str| {
        let mut a = GYROID_TWO_LEVELS.to_vec();
        a.extend(["--threads", t]);
        contour_ok(&a)
    };
    let one = with("1");
    let recs = parse_csv(&one);
    check_records(&recs, [19.0; 3]);
    for level in ["-0.3", "0.4"] {
        assert!(recs.iter().any(|r| r.level == level), "no commands at level {level}");
    }
    for t in ["2", "3"] {
        assert!(with(t) == one, "--threads {t} differs from --threads 1");
    }
}

#[test]
fn one_plane_is_its_lines_of_all_planes() {
    let all = contour_ok(&GYROID_TWO_LEVELS);
    for axis in ["xy", "xz", "yz"] {
        let mut a = GYROID_TWO_LEVELS.to_vec();
        a.extend(["--axes", axis]);
        let one = contour_ok(&a);
        let expected: Vec<&str> = all.lines().skip(1).filter(|l| l.split(',').nth(1) == Some(axis)).collect();
        let got: Vec<&str> = one.lines().skip(1).collect();
        assert!(!got.is_empty());
        assert!(got == expected, "--axes {axis} differs from the {axis} lines of all planes");
    }
    // Repeated and reordered planes: each once, in the order given.
    let mut a = GYROID_TWO_LEVELS.to_vec();
    a.extend(["--axes", "yz,xy,yz"]);
    let two = contour_ok(&a);
    let axes: Vec<&str> = two.lines().skip(1).filter_map(|l| l.split(',').nth(1)).collect();
    let first_xy = axes.iter().position(|a| *a == "xy").expect("no xy lines");
    assert!(axes[..first_xy].iter().all(|a| *a == "yz") && axes[first_xy..].iter().all(|a| *a == "xy"));
}

// --- Raw volume files -------------------------------------------------------

/// The paper's Figure 5 subgrid, x fastest: LL, LR, UL, UR.
const FIGURE5: [u16; 4] = [150, 40, 30, 60];

/// The Figure 5 commands at level 100: op, x, y.
const FIGURE5_AT_100: [(char, f32, f32); 3] =
    [('M', 50.0 / 110.0, 0.0), ('L', 0.3125, 0.3125), ('L', 0.0, 50.0 / 120.0)];

fn assert_figure5(csv: &str, level: &str) {
    let recs = parse_csv(csv);
    assert_eq!(recs.len(), FIGURE5_AT_100.len(), "{csv}");
    for (r, &(op, x, y)) in recs.iter().zip(&FIGURE5_AT_100) {
        assert_eq!((r.level.as_str(), r.axis.as_str(), r.slice, r.op), (level, "xy", 0, op), "{csv}");
        let close = (r.p[0] - x).abs() < 1e-4 && (r.p[1] - y).abs() < 1e-4 && r.p[2] == 0.0;
        assert!(close, "{r:?} is not ({x}, {y}, 0):\n{csv}");
    }
}

#[test]
fn raw_figure5_in_every_sample_type() {
    let dir = TempDir::new("figure5");
    let bytes_u8: Vec<u8> = FIGURE5.iter().map(|&v| v as u8).collect();
    let f32s: Vec<f32> = FIGURE5.iter().map(|&v| f32::from(v)).collect();
    let i16s: Vec<i16> = FIGURE5.iter().map(|&v| v as i16).collect();
    let files = [
        ("u8", dir.file("f5.u8", &bytes_u8)),
        ("u16", dir.file("f5.u16", &le_u16(&FIGURE5))),
        ("i16", dir.file("f5.i16", &le_i16(&i16s))),
        ("f32", dir.file("f5.f32", &le_f32(&f32s))),
    ];
    let mut first = None;
    for (dtype, path) in &files {
        let csv = contour_ok(&[path, "--dims", "2x2x1", "--dtype", dtype, "--axes", "xy", "--level", "100"]);
        assert_figure5(&csv, "100");
        // Every sample type widens exactly: the same bits.
        match &first {
            None => first = Some(csv),
            Some(f) => assert_eq!(&csv, f, "--dtype {dtype} differs from --dtype u8"),
        }
    }
    // The other planes of a one-slice volume have no cells.
    let (_, path) = &files[0];
    let csv = contour_ok(&[path, "--dims", "2x2x1", "--dtype", "u8", "--axes", "xz,yz", "--level", "100"]);
    assert_eq!(csv, format!("{HEADER}\n"));
}

#[test]
fn raw_i16_with_negative_samples() {
    let dir = TempDir::new("i16");
    // Figure 5 negated, at level -100: the same crossing points.
    let neg: Vec<i16> = FIGURE5.iter().map(|&v| -(v as i16)).collect();
    let path = dir.file("neg.i16", &le_i16(&neg));
    let csv = contour_ok(&[&path, "--dims", "2x2x1", "--dtype", "i16", "--axes", "xy", "--level=-100"]);
    // (The contouring tree of the negated values is traversed from another
    // root, so the same lines may come as two polylines.)
    let recs = parse_csv(&csv);
    check_records(&recs, [1.0, 1.0, 0.0]);
    let near =
        |r: &Rec, x: f32, y: f32| (r.p[0] - x).abs() < 1e-4 && (r.p[1] - y).abs() < 1e-4 && r.p[2] == 0.0;
    for r in &recs {
        assert_eq!((r.level.as_str(), r.axis.as_str()), ("-100", "xy"), "{csv}");
        assert!(
            FIGURE5_AT_100.iter().any(|&(_, x, y)| near(r, x, y)),
            "{r:?} is not a Figure 5 point:\n{csv}"
        );
    }
    for &(_, x, y) in &FIGURE5_AT_100 {
        assert!(recs.iter().any(|r| near(r, x, y)), "no point near ({x}, {y}, 0):\n{csv}");
    }

    // A 5x4x3 ramp through zero, as i16 and as f32: the same CSV, and the
    // plane v = -250 (read as u16, the samples would never cross it).
    let (nx, ny, nz) = (5usize, 4usize, 3usize);
    let ramp: Vec<i16> = (0..nx * ny * nz)
        .map(|i| {
            let (x, y, z) = (i % nx, i / nx % ny, i / (nx * ny));
            (x as i16 * 300 + y as i16 * 200 + z as i16 * 100) - 1000
        })
        .collect();
    assert!(ramp.iter().any(|&v| v < -250) && ramp.iter().any(|&v| v > -250));
    let as_f32: Vec<f32> = ramp.iter().map(|&v| f32::from(v)).collect();
    let pi = dir.file("ramp.i16", &le_i16(&ramp));
    let pf = dir.file("ramp.f32", &le_f32(&as_f32));
    let args = |p: &str, dtype: &str| {
        contour_ok(&[
            p,
            "--dims",
            "5x4x3",
            "--dtype",
            dtype,
            "--level=-250",
            "--level",
            "0",
            "--threads",
            "2",
        ])
    };
    let csv_i = args(&pi, "i16");
    assert_eq!(csv_i, args(&pf, "f32"));
    let recs = parse_csv(&csv_i);
    check_records(&recs, [4.0, 3.0, 2.0]);
    assert!(recs.iter().any(|r| r.level == "-250"), "no crossing of -250:\n{csv_i}");
    assert!(recs.iter().any(|r| r.level == "0"), "no crossing of 0:\n{csv_i}");
}

#[test]
fn nan_samples_are_skipped_not_fatal() {
    let dir = TempDir::new("nan");
    let n = 6usize;
    let mut v: Vec<f32> = (0..n * n * n).map(|i| (i % n + i / n % n + i / (n * n)) as f32 - 7.5).collect();
    v[(2 * n + 2) * n + 2] = f32::NAN;
    v[(4 * n + 1) * n + 3] = f32::INFINITY;
    let path = dir.file("nan.f32", &le_f32(&v));
    let out = run(&["contour", &path, "--dims", "6x6x6", "--dtype", "f32", "--level", "0.25", "--stats"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let stats = parse_stats(&text(&out.stderr));
    let nonfinite = stat_u64(&stats, "nonfinite_cells");
    assert!(nonfinite > 0, "{stats:?}");
    // Each of the two bad samples touches up to 4 cells in each of 3 slices.
    assert!(nonfinite <= 24, "{stats:?}");
    assert_eq!(stat_u64(&stats, "cells"), 3 * 6 * 5 * 5);
    let recs = parse_csv(&text(&out.stdout));
    assert!(!recs.is_empty());
    check_records(&recs, [5.0; 3]);
    assert_eq!(stat_u64(&stats, "commands"), recs.len() as u64);
}

// --- Bad input ----------------------------------------------------------------

/// Run `contour` and expect it to fail with an `isoscope-sim: error:` line
/// naming every one of `causes`, nothing but (at most) the header on
/// standard output.
fn assert_error(args: &[&str], causes: &[&str]) {
    let mut all = vec!["contour"];
    all.extend_from_slice(args);
    let out = run(&all);
    let (stdout, stderr) = (text(&out.stdout), text(&out.stderr));
    assert!(!out.status.success(), "isoscope-sim {all:?} succeeded:\n{stderr}");
    // 1 for a failure while running, 2 for a usage error.
    assert!(matches!(out.status.code(), Some(1 | 2)), "isoscope-sim {all:?}: {}\n{stderr}", out.status);
    assert!(stdout.is_empty() || stdout == format!("{HEADER}\n"), "isoscope-sim {all:?} wrote:\n{stdout}");
    assert!(stderr.starts_with("isoscope-sim: error: "), "isoscope-sim {all:?}: {stderr}");
    for cause in causes {
        assert!(stderr.contains(cause), "isoscope-sim {all:?}: `{cause}` not in: {stderr}");
    }
    assert!(!stderr.contains("panicked"), "{stderr}");
}

/// Run `contour` and expect a command-line usage error from clap (exit code
/// 2, `error: ...` naming every one of `causes`), nothing on standard output.
fn assert_usage_error(args: &[&str], causes: &[&str]) {
    let mut all = vec!["contour"];
    all.extend_from_slice(args);
    let out = run(&all);
    let (stdout, stderr) = (text(&out.stdout), text(&out.stderr));
    assert_eq!(out.status.code(), Some(2), "isoscope-sim {all:?}: {}\n{stderr}", out.status);
    assert!(stdout.is_empty(), "isoscope-sim {all:?} wrote:\n{stdout}");
    assert!(stderr.starts_with("isoscope-sim: error: "), "isoscope-sim {all:?}: {stderr}");
    for cause in causes {
        assert!(stderr.contains(cause), "isoscope-sim {all:?}: `{cause}` not in: {stderr}");
    }
}

#[test]
fn missing_file() {
    let dir = TempDir::new("missing");
    let path = path_str(&dir.0.join("no-such-volume.raw"));
    assert_error(&[&path, "--dims", "2x2x1", "--dtype", "u8", "--level", "1"], &["cannot read", &path]);
}

#[test]
fn file_too_short_or_too_long() {
    let dir = TempDir::new("size");
    let path = dir.file("v.u16", &le_u16(&[1, 2, 3, 4, 5, 6, 7]));
    // 14 bytes; 2x2x2 u16 needs 16.
    assert_error(
        &[&path, "--dims", "2x2x2", "--dtype", "u16", "--level", "1"],
        &[&path, "2x2x2 U16 samples need 16 bytes", "the data stop after 14 of 16 bytes (truncated?)"],
    );
    // 14 bytes; 3x2x1 u16 needs 12.
    assert_error(
        &[&path, "--dims", "3x2x1", "--dtype", "u16", "--level", "1"],
        &[&path, "12 bytes of data expected, and 2 more follow"],
    );
    // An odd length for 2-byte samples.
    let odd = dir.file("odd.i16", &[0u8; 9]);
    assert_error(
        &[&odd, "--dims", "2x2x1", "--dtype", "i16", "--level", "1"],
        &["8 bytes of data expected, and 1 more follow"],
    );
    // The empty file.
    let empty = dir.file("empty.f32", &[]);
    assert_error(
        &[&empty, "--dims", "1x1x1", "--dtype", "f32", "--level", "1"],
        &["the data stop after 0 of 4 bytes (truncated?)"],
    );
}

#[test]
fn extents_that_overflow() {
    let dir = TempDir::new("overflow");
    let path = dir.file("v.u8", &[0u8; 4]);
    let huge = format!("{}x4x1", usize::MAX / 2);
    assert_error(&[&path, "--dims", &huge, "--dtype", "u8", "--level", "1"], &["overflow"]);
}

#[test]
fn a_file_needs_dims_dtype_and_level() {
    let dir = TempDir::new("flags");
    let path = dir.file("v.u8", &[0u8, 1, 2, 3]);
    assert_error(&[&path, "--dtype", "u8", "--level", "1"], &["--dims"]);
    assert_error(&[&path, "--dims", "2x2x1", "--level", "1"], &["--dtype"]);
    assert_error(&[&path, "--dims", "2x2x1", "--dtype", "u8"], &["--level"]);
}

#[test]
fn no_source_at_all() {
    assert_error(&[], &["--demo"]);
    assert_error(&["--level", "1"], &["--demo"]);
}

#[test]
fn unknown_dtype() {
    let dir = TempDir::new("dtype");
    let path = dir.file("v.u8", &[0u8; 4]);
    assert_usage_error(&[&path, "--dims", "2x2x1", "--dtype", "u32", "--level", "1"], &["u32", "--dtype"]);
}

#[test]
fn malformed_dims() {
    let dir = TempDir::new("dims");
    let path = dir.file("v.u8", &[0u8; 4]);
    for (dims, cause) in
        [("12x12", "NXxNYxNZ"), ("0x2x2", "at least 1"), ("axbxc", "NXxNYxNZ"), ("2x2x1x1", "NXxNYxNZ")]
    {
        assert_usage_error(
            &[&path, "--dims", dims, "--dtype", "u8", "--level", "1"],
            &[dims, "--dims", cause],
        );
    }
}

#[test]
fn bad_demo() {
    assert_usage_error(&["--demo", "nosuch:8"], &["nosuch", "hydrogen", "gyroid"]);
    assert_usage_error(&["--demo", "gyroid:1"], &["gyroid:1", "between 2 and"]);
    assert_usage_error(&["--demo", "gyroid:big"], &["gyroid:big", "whole number"]);
    assert_usage_error(&["--demo", "gyroid:4096"], &["between 2 and"]);
}

#[test]
fn file_and_demo_together() {
    let dir = TempDir::new("both");
    let path = dir.file("v.u8", &[0u8; 8]);
    assert_usage_error(&[&path, "--demo", "gyroid:4"], &["--demo"]);
}

#[test]
fn non_finite_levels() {
    assert_error(&["--demo", "gyroid:4", "--level", "NaN"], &["--level", "NaN", "not a finite number"]);
    assert_error(&["--demo", "gyroid:4", "--level", "inf"], &["--level", "inf", "not a finite number"]);
    assert_error(&["--demo", "gyroid:4", "--level", "0", "--level=-inf"], &["-inf", "not a finite number"]);
    assert_error(&["--demo", "gyroid:4", "--level", "1e40"], &["1e40", "outside the range"]);
    assert_error(&["--demo", "gyroid:4", "--level", "abc"], &["abc", "not a number"]);
    let dir = TempDir::new("nan-level");
    let path = dir.file("v.u8", &[0u8; 8]);
    assert_error(&[&path, "--dims", "2x2x2", "--dtype", "u8", "--level", "nan"], &["not a finite number"]);
}

#[test]
fn negative_infinite_level_as_separate_argument() {
    assert_error(&["--demo", "gyroid:4", "--level", "-inf"], &["not a finite number"]);
}

#[test]
fn bad_axes() {
    assert_error(&["--demo", "gyroid:4", "--axes", "xq"], &["xq", "xy, xz or yz"]);
    assert_error(&["--demo", "gyroid:4", "--axes", "xy,zz"], &["zz"]);
}

#[test]
fn zero_threads() {
    assert_error(&["--demo", "gyroid:4", "--threads", "0"], &["--threads", "at least 1"]);
}

#[test]
fn unwritable_output() {
    let dir = TempDir::new("unwritable");
    let path = path_str(&dir.0.join("no-such-dir").join("out.csv"));
    assert_error(&["--demo", "gyroid:4", "-o", &path], &["cannot create", &path]);
}

#[test]
fn every_error_has_the_isoscope_prefix() {
    let dir = TempDir::new("prefix");
    let path = dir.file("v.u8", &[0u8; 4]);
    assert_error(&[&path, "--dims", "2x2x1", "--dtype", "u32", "--level", "1"], &["u32"]);
    assert_error(&[&path, "--dims", "12x12", "--dtype", "u8", "--level", "1"], &["12x12"]);
    assert_error(&["--demo", "nosuch:8"], &["nosuch"]);
    assert_error(&["--demo", "gyroid:1"], &["gyroid:1"]);
}

/// `stats` prints the frame statistics of the board's picture, on the
/// host's memory or a named board's.
#[test]
fn stats_reports_the_frame() {
    let kv = |extra: &[&str]| -> std::collections::HashMap<String, String> {
        let mut args = vec!["stats", "--demo", "hydrogen:16"];
        args.extend_from_slice(extra);
        let out = run(&args);
        assert!(out.status.success(), "{}", text(&out.stderr));
        text(&out.stdout)
            .lines()
            .map(|l| {
                let (k, v) = l.split_once('=').unwrap();
                (k.to_string(), v.to_string())
            })
            .collect()
    };
    let num = |m: &std::collections::HashMap<String, String>, k: &str| -> f64 {
        m.get(k).unwrap_or_else(|| panic!("{k} missing: {m:?}")).parse().unwrap()
    };
    let (host, board) = (kv(&[]), kv(&["--board", "f407"]));
    assert_eq!(host["board"], "host");
    assert_eq!(board["board"], "f407");
    assert_eq!(num(&board, "capacity_points"), 8192.0);
    for m in [&host, &board] {
        for k in ["fragments", "polylines", "points", "lit_length", "blank_length", "samples", "fps"] {
            assert!(num(m, k) > 0.0, "{k}");
        }
        assert!(num(m, "polylines") < num(m, "fragments"), "stitched");
        assert!(num(m, "blank_ratio") < 0.2);
        assert_eq!(num(m, "points_cut"), 0.0);
    }
    let out = run(&["stats", "--demo", "hydrogen:16", "--board", "nosuch"]);
    assert!(!out.status.success());
    assert!(text(&out.stderr).contains("unknown board `nosuch` (known: f407)"), "{}", text(&out.stderr));
}

#[test]
fn stats_rejects_bad_view_and_beam_settings() {
    for args in [
        &["stats", "--demo", "gyroid:8", "--every", "0"][..],
        &["stats", "--demo", "gyroid:8", "--bits", "0"],
        &["stats", "--demo", "gyroid:8", "--lit-step", "-1"],
        &["stats", "--demo", "gyroid:8", "--perspective", "200"],
        &["stats", "--demo", "gyroid:8", "--margin", "0.7"],
    ] {
        let out = run(args);
        assert!(!out.status.success(), "{args:?} succeeded");
        assert!(text(&out.stderr).starts_with("isoscope-sim: error: "), "{args:?}: {}", text(&out.stderr));
        assert!(!text(&out.stderr).contains("panicked"));
    }
}

/// `render` writes the PNG the scope would show.
#[test]
fn render_writes_a_png() {
    let dir = TempDir::new("render");
    let out_path = path_str(&dir.0.join("h.png"));
    let out = run(&["render", "--demo", "hydrogen:12", "--size", "96", "-o", &out_path]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(text(&out.stderr).contains("wrote"), "{}", text(&out.stderr));
    let bytes = std::fs::read(&out_path).unwrap();
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    // IHDR: width and height 96.
    assert_eq!(&bytes[16..24], &[0, 0, 0, 96, 0, 0, 0, 96]);
}

#[test]
fn render_rejects_bad_picture_settings() {
    let dir = TempDir::new("render-bad");
    let out_path = path_str(&dir.0.join("h.png"));
    for args in [
        &["render", "--demo", "gyroid:8", "--size", "0", "-o", &out_path][..],
        &["render", "--demo", "gyroid:8", "--size", "100000", "-o", &out_path],
        &["render", "--demo", "gyroid:8", "--frames", "0", "-o", &out_path],
        &["render", "--demo", "gyroid:8", "--show-blanked", "-1", "-o", &out_path],
        &["render", "--demo", "gyroid:8", "-o", "/nonexistent-dir/x.png"],
    ] {
        let out = run(args);
        assert!(!out.status.success(), "{args:?} succeeded");
        assert!(text(&out.stderr).starts_with("isoscope-sim: error: "), "{args:?}: {}", text(&out.stderr));
        assert!(!text(&out.stderr).contains("panicked"));
    }
}

/// `info` describes a volume and suggests levels.
#[test]
fn info_describes_a_volume() {
    let out = run(&["info", "--demo", "sphere:16", "--bins", "8"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let t = text(&out.stdout);
    for k in [
        "dims=16x16x16",
        "dtype=f32",
        "spacing=1x1x1",
        "samples=4096",
        "nonfinite=0",
        "min=",
        "max=",
        "suggested_levels=",
    ] {
        assert!(t.contains(k), "{k} not in:\n{t}");
    }
    assert_eq!(t.lines().filter(|l| l.starts_with("# ")).count(), 8);
}

/// `--format svg` writes the display list; `--every N` keeps every N-th
/// slice in the CSV.
#[test]
fn contour_svg_and_slice_stride() {
    let out = run(&["contour", "--demo", "torus:16", "--format", "svg"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let svg = text(&out.stdout);
    assert!(svg.starts_with("<?xml") && svg.trim_end().ends_with("</svg>"));
    assert!(svg.contains("<polygon") || svg.contains("<polyline"));
    let out = run(&["contour", "--demo", "torus:16", "--every", "5"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let slices: std::collections::BTreeSet<usize> =
        text(&out.stdout).lines().skip(1).map(|l| l.split(',').nth(2).unwrap().parse().unwrap()).collect();
    assert!(!slices.is_empty());
    assert!(slices.iter().all(|s| s % 5 == 0), "{slices:?}");
    let out = run(&["contour", "--demo", "torus:16", "--every", "0"]);
    assert!(!out.status.success());
}

/// `wav` writes the beam as audio; `render --animate` a turning GIF.
#[test]
fn wav_and_animation() {
    let dir = TempDir::new("wav-anim");
    let wav = path_str(&dir.0.join("s.wav"));
    let out = run(&["wav", "--demo", "sphere:10", "-o", &wav, "--seconds", "0.25", "--audio-rate", "96000"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let b = std::fs::read(&wav).unwrap();
    assert_eq!(&b[..4], b"RIFF");
    assert_eq!(&b[8..12], b"WAVE");
    // 0.25 s at 96 kHz, 2 channels of 16 bits.
    assert!(b.len() >= 24_000 * 4, "{} bytes", b.len());
    let gif = path_str(&dir.0.join("a.gif"));
    let out = run(&["render", "--demo", "torus:12", "--size", "64", "--animate", &gif, "--anim-frames", "6"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert_eq!(&std::fs::read(&gif).unwrap()[..6], b"GIF89a");
    let out = run(&["render", "--demo", "torus:12", "--animate", &path_str(&dir.0.join("a.bmp"))]);
    assert!(!out.status.success());
    assert!(text(&out.stderr).contains(".gif"), "{}", text(&out.stderr));
    let out = run(&["wav", "--demo", "torus:12", "--audio-rate", "0", "-o", &wav]);
    assert!(!out.status.success());
    assert!(text(&out.stderr).starts_with("isoscope-sim: error: "));
}

/// `--endian big` reads a big-endian raw file like its little-endian twin.
#[test]
fn big_endian_raw_files() {
    let dir = TempDir::new("endian");
    let vals: Vec<i16> = vec![150, 40, 30, 60, -5, 7, 900, -300];
    let le: Vec<u8> = vals.iter().flat_map(|v| v.to_le_bytes()).collect();
    let be: Vec<u8> = vals.iter().flat_map(|v| v.to_be_bytes()).collect();
    let (pl, pb) = (dir.file("le.raw", &le), dir.file("be.raw", &be));
    let csv = |p: &str, extra: &[&str]| {
        let mut a = vec!["contour", p, "--dims", "2x2x2", "--dtype", "i16", "--level", "45"];
        a.extend_from_slice(extra);
        let out = run(&a);
        assert!(out.status.success(), "{}", text(&out.stderr));
        text(&out.stdout)
    };
    let little = csv(&pl, &[]);
    assert!(little.lines().count() > 1);
    assert_eq!(csv(&pb, &["--endian", "big"]), little);
    assert_ne!(csv(&pb, &[]), little);
    let out =
        run(&["contour", &pb, "--dims", "2x2x2", "--dtype", "i16", "--level", "1", "--endian", "middle"]);
    assert!(!out.status.success());
}

/// `--board` shows what that board would: a note where it thins the
/// surface, a note where it downsamples a volume too large for it, and a
/// plain refusal of slices it cannot hold at the `--downsample` given,
/// before `send` opens the port.
#[test]
fn board_preset_says_what_the_board_cannot_hold() {
    let out = run(&["stats", "--demo", "gyroid:48", "--board", "f407", "--downsample", "1"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let err = text(&out.stderr);
    assert!(err.contains("note: the f407 board holds less than this surface"), "{err}");
    assert!(
        err.contains("it draws every 32nd slice of each plane (counted from the middle), not every slice"),
        "{err}"
    );
    let out = run(&["stats", "--demo", "gyroid:48"]);
    assert!(!text(&out.stderr).contains("note: the"), "{}", text(&out.stderr));
    // Without --downsample, the board's picture of a coarser grid, whose
    // drawn slices lie closer together in the volume.
    let out = run(&["stats", "--demo", "gyroid:48", "--board", "f407"]);
    let err = text(&out.stderr);
    assert!(
        err.contains(
            "note: the f407 board draws every 32nd slice of a 48x48x48 volume (slices 32 voxels apart), \
             and every 2nd slice once downsampled by 4 (8 voxels apart): downsampling by 4 (the factor \
             whose drawn slices lie closest together; --downsample or --crop to choose)"
        ),
        "{err}"
    );
    assert!(text(&out.stdout).contains("every=2\n"), "{}", text(&out.stdout));
    // The volume the picture is of, as stats says it (scripts/scene-figures).
    assert!(text(&out.stdout).contains("\ndims=12x12x12\n"), "{}", text(&out.stdout));
    // Too wide for a slice: from the smallest factor that fits on.
    let out = run(&["stats", "--demo", "gyroid:100", "--board", "f407"]);
    let err = text(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(
        err.contains("the f407 board draws every 32nd slice of a 50x50x50 volume (slices 64 voxels apart)")
            && err.contains("7x7x7 block, 14x14x14 F32"),
        "{err}"
    );
    for cmd in ["render", "send"] {
        let out = run(&[
            cmd,
            "--demo",
            "gyroid:100",
            "--board",
            "f407",
            "--downsample",
            "1",
            "--port",
            "tcp:127.0.0.1:1",
            "-o",
            "/dev/null",
        ]
        .into_iter()
        .filter(|a| cmd == "send" || !a.starts_with("--port") && !a.starts_with("tcp:"))
        .filter(|a| cmd == "render" || (*a != "-o" && *a != "/dev/null"))
        .collect::<Vec<_>>());
        assert!(!out.status.success());
        let err = text(&out.stderr);
        assert!(
            err.contains(
                "the f407 board takes slices of at most 32768 bytes and 128 samples a side; \
                 a 100x100x100 F32 volume does not fit (--downsample 2 fits)"
            ),
            "{cmd}: {err}"
        );
        assert!(!err.contains("Connection refused"), "{cmd} tried the port: {err}");
    }
}

/// A reader that goes away (`| head`) ends the output quietly; a full
/// disk is a plain error; neither panics.
#[test]
fn closed_pipes_and_full_disks_do_not_panic() {
    for args in [&["stats", "--demo", "hydrogen:16"][..], &["info", "--demo", "hydrogen:16"]] {
        let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_isoscope-sim"))
            .args(args)
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        // The reader leaves before the first line.
        drop(child.stdout.take());
        let out = child.wait_with_output().unwrap();
        let err = text(&out.stderr);
        assert!(!err.contains("panicked"), "{args:?}: {err}");
        assert!(out.status.success(), "{args:?}: {err}");
        if std::path::Path::new("/dev/full").exists() {
            let full = std::fs::OpenOptions::new().write(true).open("/dev/full").unwrap();
            let out = std::process::Command::new(env!("CARGO_BIN_EXE_isoscope-sim"))
                .args(args)
                .stdout(full)
                .output()
                .unwrap();
            let err = text(&out.stderr);
            assert!(!out.status.success());
            assert!(err.starts_with("isoscope-sim: error: cannot write to standard output"), "{err}");
        }
    }
}

/// `--samples` writes one frame, so an animation refuses it rather than
/// ignore it; `send --board` says what is wrong with its own options.
#[test]
fn options_that_cannot_apply_are_refused_plainly() {
    let out = run(&[
        "render",
        "--demo",
        "hydrogen:8",
        "--animate",
        "/tmp/isoscope-never.gif",
        "--samples",
        "/tmp/x",
    ]);
    assert!(!out.status.success());
    assert!(text(&out.stderr).contains("--samples writes one frame"), "{}", text(&out.stderr));
    let out = run(&[
        "send",
        "--demo",
        "hydrogen:8",
        "--board",
        "f407",
        "--every",
        "0",
        "--port",
        "tcp:127.0.0.1:1",
    ]);
    assert!(!out.status.success());
    let err = text(&out.stderr);
    assert!(err.contains("the slice stride must be at least 1") && !err.contains("cannot take"), "{err}");
}

/// Size and count options are checked where they are parsed, against a
/// documented range, before anything is allocated or run (issue 16: these
/// panicked on overflow, aborted on allocation or ran unbounded).
#[test]
fn size_and_count_options_have_ranges() {
    for args in [
        &["device", "--tcp", "127.0.0.1:0", "--max-slice-bytes", "18446744073709551615"][..],
        &["device", "--tcp", "127.0.0.1:0", "--max-slice-bytes", "100000000000"],
        &["device", "--tcp", "127.0.0.1:0", "--points", "4294967295"],
        &["device", "--tcp", "127.0.0.1:0", "--points", "0"],
        &["device", "--pty", "--size", "0"],
        &["device", "--pty", "--exit-after", "0"],
        &["info", "--demo", "hydrogen:8", "--bins", "1000000000"],
        &["info", "--demo", "hydrogen:8", "--bins", "0"],
        &["render", "--demo", "hydrogen:8", "--frames", "4294967295"],
        &["send", "--demo", "hydrogen:8", "--port", "tcp:127.0.0.1:1", "--window", "0"],
        &["send", "--demo", "hydrogen:8", "--port", "tcp:127.0.0.1:1", "--baud", "0"],
        &["send", "--demo", "hydrogen:8", "--port", "tcp:127.0.0.1:1", "--patience", "0"],
        &["send", "--demo", "hydrogen:8", "--port", "tcp:127.0.0.1:1", "--patience", "1001"],
    ] {
        let out = run(args);
        let err = text(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains("out of range: give"), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{args:?}: {err}");
    }
}

/// A command that fails, is refused or is killed half-way leaves the file
/// it was to write as it was: outputs are written whole or not at all.
#[test]
fn outputs_are_written_whole_or_not_at_all() {
    let dir = TempDir::new("whole");
    let old = b"the picture from yesterday";
    for (name, args) in [
        ("k.gif", &["render", "--demo", "sphere:12", "--animate", "OUT", "--anim-frames", "0"][..]),
        ("k.gif", &["render", "--demo", "sphere:12", "--animate", "OUT", "--turn", "nan"]),
        ("k.png", &["render", "--demo", "sphere:12", "-o", "OUT", "--size", "0"]),
        ("k.wav", &["wav", "--demo", "sphere:12", "-o", "OUT", "--seconds", "0"]),
        ("k.svg", &["contour", "--demo", "sphere:12", "--format", "svg", "-o", "OUT", "--yaw", "inf"]),
    ] {
        let path = dir.file(name, old);
        let args: Vec<&str> = args.iter().map(|a| if *a == "OUT" { path.as_str() } else { a }).collect();
        let out = run(&args);
        assert!(!out.status.success(), "{args:?} should fail");
        assert_eq!(std::fs::read(&path).unwrap(), old, "{args:?} touched {name}");
    }
    // Killed while it writes: the old file stays (and a good run replaces it).
    let path = dir.file("turning.gif", old);
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_isoscope-sim"))
        .args([
            "render",
            "--demo",
            "hydrogen:32",
            "--animate",
            &path,
            "--anim-frames",
            "400",
            "--size",
            "512",
        ])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(1500));
    child.kill().unwrap();
    child.wait().unwrap();
    assert_eq!(std::fs::read(&path).unwrap(), old, "a killed render touched the animation");
    let out =
        run(&["render", "--demo", "sphere:8", "--animate", &path, "--anim-frames", "2", "--size", "32"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(std::fs::read(&path).unwrap().starts_with(b"GIF89a"));
}

/// Numbers a user would act on are right or refused: a raw file or a demo
/// has no second volume, a bad view is refused before the port opens, an
/// all-NaN volume has no mean (not -0), and a volume spanning past the f32
/// range still gets finite histogram edges and suggested levels.
#[test]
fn wrong_numbers_are_refused_or_said_plainly() {
    let dir = TempDir::new("numbers");
    let raw = dir.file("z.raw", &[0u8; 64]);
    let out = run(&["info", &raw, "--dims", "4x4x4", "--dtype", "u8", "--volume", "5"]);
    assert!(!out.status.success());
    assert!(text(&out.stderr).contains("a raw file holds one volume; --volume 5 asks for another"));
    let out = run(&["info", "--demo", "sphere:8", "--volume", "1"]);
    assert!(text(&out.stderr).contains("a demo is one volume"), "{}", text(&out.stderr));
    let out = run(&["send", "--demo", "sphere:8", "--yaw", "inf", "--port", "tcp:127.0.0.1:1"]);
    let err = text(&out.stderr);
    assert!(!out.status.success() && err.contains("invalid view"), "{err}");
    assert!(!err.contains("Connection refused"), "the port was opened first: {err}");
    let nan: Vec<u8> = std::iter::repeat_n(f32::NAN.to_le_bytes(), 8).flatten().collect();
    let nan = dir.file("nan.raw", &nan);
    let out = run(&["info", &nan, "--dims", "2x2x2", "--dtype", "f32"]);
    let report = text(&out.stdout);
    assert!(report.contains("min=none\nmax=none\nmean=none\n"), "{report}");
    let wide: Vec<u8> = (0..64)
        .flat_map(|i| (if i % 3 == 0 { -3e38f32 } else { 3e38 - i as f32 * 1e36 }).to_le_bytes())
        .collect();
    let wide = dir.file("wide.raw", &wide);
    let out = run(&["info", &wide, "--dims", "4x4x4", "--dtype", "f32"]);
    let report = text(&out.stdout);
    assert!(!report.contains("NaN") && !report.contains("inf"), "{report}");
    let levels = report.lines().find_map(|l| l.strip_prefix("suggested_levels=")).unwrap_or("");
    assert!(!levels.is_empty(), "{report}");
}

#[test]
fn a_negative_margin_is_a_value_with_a_plain_error() {
    // Not "unexpected argument '-0.3'": the value reaches the view's check.
    let out = run(&["stats", "--demo", "hydrogen:8", "--margin", "-0.3"]);
    assert!(!out.status.success());
    let err = text(&out.stderr);
    assert!(err.contains("the margin must be in 0.0 .. 0.5"), "{err}");
    assert!(!err.contains("unexpected argument"), "{err}");
}

#[test]
fn the_chosen_stride_is_named_in_plain_english() {
    // gyroid:96: render picks every 96 / 32 = 3rd slice, and says so.
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("g.png");
    let out = run(&["render", "--demo", "gyroid:96", "--size", "64", "-o", &path_str(&png)]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let err = text(&out.stderr);
    assert!(err.contains("drawing every 3rd slice"), "{err}");
    assert!(!err.contains("3th"), "{err}");
}

/// `ports` lists the serial ports, a line each, or says plainly that there
/// are none (as in most containers); it succeeds either way.
#[test]
fn ports_lists_the_serial_ports_or_says_there_are_none() {
    let out = run(&["ports"]);
    let stdout = text(&out.stdout);
    assert!(out.status.success(), "ports failed with {}:\n{}", out.status, text(&out.stderr));
    assert!(stdout.ends_with('\n'), "{stdout:?}");
    if stdout != "no serial ports found\n" {
        for line in stdout.lines() {
            let mut words = line.split("  ");
            assert!(words.next().is_some_and(|name| !name.is_empty()), "no port name in {line:?}");
            assert!(
                words.next().is_some_and(
                    |how| how.starts_with("usb ") || ["pci", "bluetooth", "other"].contains(&how)
                ),
                "no attachment in {line:?}"
            );
        }
    }
}

/// `send --port auto` without exactly one likely board says so plainly and
/// asks for `--port NAME`, after a plain-English list of the candidates.
#[test]
fn send_to_port_auto_without_a_board_asks_for_a_port_name() {
    let listed = text(&run(&["ports"]).stdout);
    if listed.matches("likely board").count() == 1 {
        eprintln!("a board is connected: not sending it a volume from a test");
        return;
    }
    let out = run(&["send", "--demo", "sphere:8", "--port", "auto"]);
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.starts_with("isoscope-sim: error: --port auto: "), "{err}");
    assert!(err.contains("pass --port NAME"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
}

// --- Packaging: shell completions and the manual page ----------------------

#[test]
fn completions_for_every_shell_name_the_subcommands() {
    for shell in ["bash", "zsh", "fish", "powershell", "elvish"] {
        let out = run(&["completions", shell]);
        let (script, err) = (text(&out.stdout), text(&out.stderr));
        assert!(out.status.success(), "completions {shell} failed with {}:\n{err}", out.status);
        assert!(err.is_empty(), "completions {shell} said: {err}");
        assert!(script.contains("isoscope-sim"), "completions {shell}:\n{script}");
        for sub in ["render", "contour", "completions", "manpage"] {
            assert!(script.contains(sub), "completions {shell} do not mention `{sub}`:\n{script}");
        }
    }
    // The bash script is at least valid bash (where bash is at hand).
    let script = run(&["completions", "bash"]).stdout;
    if let Ok(mut bash) = Command::new("bash")
        .arg("-n")
        .stdin(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
    {
        use std::io::Write;
        bash.stdin.take().unwrap().write_all(&script).unwrap();
        let out = bash.wait_with_output().unwrap();
        assert!(out.status.success(), "bash -n: {}", text(&out.stderr));
    }
}

#[test]
fn completions_for_an_unknown_shell_is_a_plain_usage_error() {
    for args in [&["completions", "tcsh"][..], &["completions"][..]] {
        let out = run(args);
        let (stdout, stderr) = (text(&out.stdout), text(&out.stderr));
        assert_eq!(out.status.code(), Some(2), "isoscope-sim {args:?}: {}\n{stderr}", out.status);
        assert!(stdout.is_empty(), "isoscope-sim {args:?} wrote:\n{stdout}");
        assert!(stderr.starts_with("isoscope-sim: error: "), "isoscope-sim {args:?}: {stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
    }
    let err = text(&run(&["completions", "tcsh"]).stderr);
    assert!(err.contains("invalid value 'tcsh'"), "{err}");
    for shell in ["bash", "elvish", "fish", "powershell", "zsh"] {
        assert!(err.contains(shell), "the possible values are not listed: {err}");
    }
}

#[test]
fn the_manual_page_is_one_roff_page_with_every_subcommand() {
    let out = run(&["manpage"]);
    let page = text(&out.stdout);
    assert!(out.status.success(), "manpage failed with {}:\n{}", out.status, text(&out.stderr));
    assert!(page.contains(".TH isoscope-sim 1"), "{page}");
    for sub in
        ["contour", "stats", "info", "wav", "render", "send", "device", "relay", "completions", "manpage"]
    {
        assert!(page.contains(&format!(".SS \"isoscope\\-sim {sub}\"\n")), "no section for `{sub}`:\n{page}");
    }
    // A subcommand's options are on the page, not only its name.
    assert!(page.contains("\\-\\-level"), "{page}");
    // The set-up for apostrophes once, at the top; no page that does not
    // exist is referred to.
    assert!(page.starts_with(".ie \\n(.g .ds Aq"), "{page}");
    assert_eq!(page.matches(".ds Aq").count(), 2, "{page}");
    assert!(!page.contains("isoscope\\-sim\\-render(1)"), "{page}");

    // `man -o FILE` (the alias) writes the same page, and nothing to stdout.
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("isoscope-sim.1");
    let out = run(&["man", "-o", &path_str(&file)]);
    assert!(out.status.success(), "man -o failed: {}", text(&out.stderr));
    assert!(out.stdout.is_empty(), "{}", text(&out.stdout));
    assert_eq!(std::fs::read_to_string(&file).unwrap(), page);
}

// --- Telling the truth (issue 19) -------------------------------------------

/// Standard error, its lines without the `isoscope-sim: ` prefix.
fn said(out: &Output) -> String {
    text(&out.stderr)
}

/// The subcommands that take a volume file (`[INPUT]`).
const INPUT_COMMANDS: [&str; 6] = ["contour", "stats", "info", "wav", "render", "send"];

/// A file that no format's name or first bytes tell is refused by naming
/// the formats that load (not by asking for a raw file's --dims), and a
/// file that is not there by saying so; the help names every format and
/// every name ending that loads.
#[test]
fn an_unknown_format_is_refused_by_naming_the_formats_that_load() {
    use isoscope_sim::formats::Format;
    let dir = TempDir::new("unknown-format");
    let odd = dir.file("notes.xyz", b"hello, this is not a volume\n");
    for cmd in INPUT_COMMANDS {
        let mut args = vec![cmd, odd.as_str()];
        if cmd == "send" {
            args.extend(["--port", "tcp:127.0.0.1:1"]);
        }
        let out = run(&args);
        let err = said(&out);
        assert_eq!(out.status.code(), Some(1), "{cmd}: {err}");
        assert!(
            err.starts_with(&format!("isoscope-sim: error: {odd}: neither its name nor")),
            "{cmd}: {err}"
        );
        for f in Format::ALL {
            assert!(err.contains(f.name()), "{cmd}: {} is not named: {err}", f.name());
            for e in f.extensions() {
                assert!(err.contains(&format!(".{e}")), "{cmd}: .{e} is not named: {err}");
            }
        }
        assert!(err.contains(".den") && err.contains(".gz"), "{cmd}: {err}");
        assert!(err.contains("--dims NXxNYxNZ") && err.contains("--dtype"), "{cmd}: {err}");
        assert_eq!(err.lines().count(), 1, "{cmd}: {err}");
    }
    let gone = path_str(&dir.0.join("gone.xyz"));
    let err = said(&run(&["info", &gone]));
    assert!(err.starts_with(&format!("isoscope-sim: error: cannot read {gone}: ")), "{err}");
    // The help, wrapped or not, names every format and ending.
    let flat = |args: &[&str]| text(&run(args).stdout).split_whitespace().collect::<Vec<_>>().join(" ");
    let mut helps = vec![("isoscope-sim --help".to_owned(), flat(&["--help"]))];
    helps.extend(INPUT_COMMANDS.map(|c| (format!("{c} --help"), flat(&[c, "--help"]))));
    for (what, help) in &helps {
        for f in Format::ALL {
            assert!(help.contains(f.name()), "{what} does not name {}", f.name());
            for e in f.extensions() {
                assert!(help.contains(&format!(".{e}")), "{what} does not name .{e}");
            }
        }
        assert!(help.contains("VolPack (.den)") && help.contains(".gz"), "{what}: {help}");
    }
}

/// A VolPack `.den` file loads gzipped (`.den.gz`, any case), as the help
/// says every format does: the same volume as the plain file.
#[test]
fn a_gzipped_den_file_loads_like_the_plain_one() {
    use std::io::Write as _;
    // The 62-byte header, big-endian: version 1, then map_len (shorts 25
    // to 27) 3x2x2 and the sample count; then the samples.
    let mut den = vec![0u8; 62];
    den[1] = 1;
    for (i, n) in [3u16, 2, 2].into_iter().enumerate() {
        den[50 + 2 * i..52 + 2 * i].copy_from_slice(&n.to_be_bytes());
    }
    den[58..62].copy_from_slice(&12i32.to_be_bytes());
    den.extend([0u8, 10, 200, 30, 40, 250, 60, 70, 80, 90, 100, 110]);
    let mut z = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    z.write_all(&den).unwrap();
    let gz = z.finish().unwrap();
    let dir = TempDir::new("den-gz");
    let plain = run(&["info", &dir.file("head.den", &den)]);
    assert!(plain.status.success(), "{}", said(&plain));
    assert!(text(&plain.stdout).starts_with("dims=3x2x2\ndtype=u8\n"), "{}", text(&plain.stdout));
    for name in ["head.den.gz", "HEAD.DEN.GZ"] {
        let out = run(&["info", &dir.file(name, &gz)]);
        assert!(out.status.success(), "{name}: {}", said(&out));
        assert_eq!(text(&out.stdout), text(&plain.stdout), "{name}");
    }
}

/// A file that cannot be written is one plain error line that says why
/// once: not the system's message twice, nor the temporary file's name.
#[test]
fn a_write_error_says_its_cause_once() {
    let dir = TempDir::new("write-error");
    let missing = dir.0.join("no-such-dir");
    let cases: [(&str, &[&str]); 7] = [
        ("x.png", &["render", "--demo", "sphere:8", "--size", "32", "-o", "OUT"]),
        (
            "x.gif",
            &["render", "--demo", "sphere:8", "--size", "32", "--anim-frames", "2", "--animate", "OUT"],
        ),
        ("x.wav", &["wav", "--demo", "sphere:8", "--seconds", "0.01", "-o", "OUT"]),
        ("x.csv", &["contour", "--demo", "sphere:8", "-o", "OUT"]),
        ("x.svg", &["contour", "--demo", "sphere:8", "--format", "svg", "-o", "OUT"]),
        ("x.txt", &["stats", "--demo", "sphere:8", "--samples", "OUT"]),
        ("x.1", &["manpage", "-o", "OUT"]),
    ];
    for (name, args) in cases {
        let path = path_str(&missing.join(name));
        let cause = std::fs::File::create(&path).unwrap_err().to_string();
        let args: Vec<&str> = args.iter().map(|a| if *a == "OUT" { path.as_str() } else { a }).collect();
        let out = run(&args);
        assert_eq!(out.status.code(), Some(1), "{args:?}");
        let err = said(&out);
        let last = err.lines().last().unwrap_or_default();
        assert_eq!(last, format!("isoscope-sim: error: cannot create {path}: {cause}"), "{args:?}: {err}");
    }
    // A full disk, where there is one to try.
    if std::path::Path::new("/dev/full").exists() {
        let cause = {
            use std::io::Write as _;
            let mut full = std::fs::OpenOptions::new().write(true).open("/dev/full").unwrap();
            full.write_all(&[0; 1 << 16]).and_then(|()| full.flush()).unwrap_err().to_string()
        };
        for args in [
            &["render", "--demo", "sphere:8", "--size", "32", "-o", "/dev/full"][..],
            &["wav", "--demo", "sphere:8", "--seconds", "0.01", "-o", "/dev/full"],
            &["contour", "--demo", "sphere:8", "-o", "/dev/full"],
        ] {
            let out = run(args);
            let err = said(&out);
            let last = err.lines().last().unwrap_or_default();
            assert_eq!(
                last,
                format!("isoscope-sim: error: cannot write /dev/full: {cause}"),
                "{args:?}: {err}"
            );
        }
    }
}

/// A picture with nothing drawn says so, on every command that makes one
/// (and `contour`'s export): the volume's values and the levels `info`
/// suggests, and no false note that there was no room to order it.
#[test]
fn an_empty_picture_says_why_and_what_to_draw() {
    // The bins whose first suggestion a file is drawn at without --level.
    let bins = isoscope_sim::info::LEVEL_BINS.to_string();
    let info = text(&run(&["info", "--demo", "hydrogen:16", "--bins", &bins]).stdout);
    let field =
        |k: &str| info.lines().find_map(|l| l.strip_prefix(k)).unwrap_or_else(|| panic!("{k}: {info}"));
    let (min, max, suggested) = (field("min="), field("max="), field("suggested_levels="));
    let first = suggested.split(',').next().unwrap();
    let dir = TempDir::new("empty");
    let file = |name: &str| path_str(&dir.0.join(name));
    let (png, gif, wav) = (file("e.png"), file("e.gif"), file("e.wav"));
    for (what, args) in [
        ("picture", vec!["render", "--size", "32", "-o", &png]),
        ("picture", vec!["render", "--size", "32", "--anim-frames", "2", "--animate", &gif]),
        ("picture", vec!["stats"]),
        ("picture", vec!["wav", "--seconds", "0.01", "-o", &wav]),
        ("picture", vec!["contour", "--format", "svg"]),
        ("export", vec!["contour"]),
    ] {
        let mut all = args.clone();
        all.extend(["--demo", "hydrogen:16", "--level", "5"]);
        let err = said(&run(&all));
        let want = format!(
            "isoscope-sim: warning: the {what} is empty: level 5 is outside the volume's values, {min} to {max}; \
             try --level {first} (suggested levels {}, see `info`)\n",
            suggested.replace(',', ", ")
        );
        assert!(err.contains(&want), "{args:?}: {err}");
        assert!(!err.contains("no room"), "{args:?}: {err}");
    }
    // A level within the values that meets no slice says so.
    let err =
        said(&run(&["stats", "--demo", "hydrogen:16", "--level", "0.5", "--axes", "xy", "--every", "20"]));
    assert!(
        err.contains(&format!(
            "no contour at level 0.5 on these slices; the volume's values run from {min} to {max}"
        )),
        "{err}"
    );
    // A picture with something in it says nothing of the kind.
    let err = said(&run(&["stats", "--demo", "hydrogen:16"]));
    assert!(!err.contains("empty"), "{err}");
}

/// `wav` spaces the samples for 25 frames/s unless told otherwise, says
/// the spacing and frame rate, and says which option fixes a flickering
/// one.
#[test]
fn wav_spaces_the_samples_for_the_refresh_rate() {
    let dir = TempDir::new("wav-fps");
    let wav = path_str(&dir.0.join("f.wav"));
    let wrote = |args: &[&str]| -> (f64, f64, String) {
        let all: Vec<&str> = ["wav", "--demo", "hydrogen:24", "--seconds", "0.01", "-o", &wav]
            .into_iter()
            .chain(args.iter().copied())
            .collect();
        let out = run(&all);
        assert!(out.status.success(), "{all:?}: {}", said(&out));
        let err = said(&out);
        let line = err.lines().find(|l| l.contains("wrote")).unwrap_or_else(|| panic!("{err}")).to_string();
        let num = |after: &str, before: &str| -> f64 {
            let tail = line.split(before).next().unwrap();
            tail.rsplit(after).next().unwrap().trim().parse().unwrap_or_else(|_| panic!("{line}"))
        };
        (num(",", " LSB apart"), num(":", " frames/s"), err)
    };
    // The default: 25 frames/s at 48 kHz, the samples farther apart than
    // a full-scale line a millisecond (85.3 LSB).
    let (apart, fps, err) = wrote(&[]);
    assert!(apart > 86.0 && (25.0..26.0).contains(&fps), "{err}");
    assert!(!err.contains("flickers"), "{err}");
    // A higher rate: the same refresh, finer steps.
    let (fine, fps, _) = wrote(&["--audio-rate", "192000"]);
    assert!(fine < apart / 3.0 && (25.0..25.5).contains(&fps), "{fine} {fps}");
    // Asked for 40.
    let (_, fps, _) = wrote(&["--fps", "40"]);
    assert!((40.0..41.0).contains(&fps), "{fps}");
    // A spacing given: the frame rate follows, and the warning says what
    // gives the default back.
    let (apart, fps, err) = wrote(&["--lit-step", "85.3"]);
    assert!(apart == 85.3 && fps < 20.0, "{err}");
    assert!(
        err.contains("warning: ")
            && err.contains("drop --lit-step to space the samples for 25 frames/s (--fps)"),
        "{err}"
    );
    let err = said(&run(&["wav", "--demo", "sphere:8", "--lit-step", "20", "--fps", "30", "-o", &wav]));
    assert!(err.contains("cannot be used with"), "{err}");
    for bad in ["0", "-3", "inf", "x"] {
        let out = run(&["wav", "--demo", "sphere:8", "--fps", bad, "-o", &wav]);
        assert!(!out.status.success() && said(&out).contains(bad), "{bad}: {}", said(&out));
    }
}

/// A frame that refreshes below 25 times a second is said to flicker, at
/// the rate it plays (a WAV file's audio rate, the DAC's for the others),
/// with the ways to shorten it that apply; a steady one is not.
#[test]
fn a_flickering_picture_is_said_to_flicker() {
    let dir = TempDir::new("flicker");
    let (wav, png) = (path_str(&dir.0.join("f.wav")), path_str(&dir.0.join("f.png")));
    // hydrogen:24 at 48 kHz: about 10 frames/s with the samples 85 LSB
    // apart; every 3rd slice is above 25.
    let base = ["--demo", "hydrogen:24"];
    for args in [
        vec!["wav", "--seconds", "0.01", "--lit-step", "85.3", "-o", &wav],
        vec!["render", "--size", "32", "--rate", "40000", "-o", &png],
        vec!["stats", "--rate", "40000"],
    ] {
        let all: Vec<&str> = args.iter().copied().chain(base).collect();
        let out = run(&all);
        assert!(out.status.success(), "{all:?}: {}", said(&out));
        let err = said(&out);
        let line = err.lines().find(|l| l.contains("flickers")).unwrap_or_else(|| panic!("{all:?}: {err}"));
        assert!(line.starts_with("isoscope-sim: warning: the picture flickers: one frame is "), "{line}");
        let rate = if args[0] == "wav" { "48000" } else { "40000" };
        assert!(line.contains(&format!(" frames/s at {rate} samples/s (below 25 ")), "{line}");
        assert!(line.contains("draw fewer slices (--every ") && line.contains("--downsample 2"), "{line}");
        // One level: fewer levels is no way; three planes: fewer is.
        assert!(!line.contains("levels") && line.contains("fewer planes (--axes)"), "{line}");
        let every: usize = line.split("--every ").nth(1).unwrap().split(')').next().unwrap().parse().unwrap();
        // The stride it names does make the picture steady.
        let mut again = all.clone();
        let every = every.to_string();
        again.extend(["--every", &every]);
        let err = said(&run(&again));
        assert!(!err.contains("flickers"), "{again:?}: {err}");
    }
    // One plane and two levels: the advice follows the options.
    let err = said(&run(&[
        "stats",
        "--demo",
        "hydrogen:24",
        "--rate",
        "20000",
        "--axes",
        "xy",
        "--level",
        "0.1",
        "--level",
        "0.2",
    ]));
    assert!(err.contains("fewer levels (of these 2)") && !err.contains("--axes"), "{err}");
    // At 1 MS/s the demo is steady.
    assert!(!said(&run(&["stats", "--demo", "hydrogen:24"])).contains("flickers"));
}

/// Run `isoscope-sim` with standard error on a terminal (a
/// pseudo-terminal): what it wrote there, once it has exited.
#[cfg(unix)]
fn run_on_a_terminal(args: &[&str]) -> String {
    use std::io::Read as _;
    let pty = isoscope_sim::tty::open_pty().expect("no pseudo-terminal");
    let slave = std::fs::File::from(pty.slave.try_clone().unwrap());
    let mut child = Command::new(env!("CARGO_BIN_EXE_isoscope-sim"))
        .args(args)
        .stdout(std::process::Stdio::null())
        .stderr(slave)
        .spawn()
        .unwrap();
    let (mut master, mut seen, mut buf) = (&pty.master, Vec::new(), [0u8; 4096]);
    let mut drain = |seen: &mut Vec<u8>| {
        while let Ok(n @ 1..) = master.read(&mut buf) {
            seen.extend_from_slice(&buf[..n]);
        }
    };
    let status = loop {
        drain(&mut seen);
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    };
    drain(&mut seen);
    let seen = String::from_utf8_lossy(&seen).into_owned();
    assert!(status.success(), "{args:?}: {seen}");
    seen
}

/// The progress lines a terminal was shown: `(label, done, total)`, the
/// last of each redraw.
#[cfg(unix)]
fn progress_lines(seen: &str) -> Vec<(String, u64, u64)> {
    seen.split(['\r', '\n'])
        .filter_map(|l| {
            let (label, rest) = l.rsplit_once(": ")?;
            let (count, pct) = rest.split_once(" (")?;
            let (done, total) = count.split_once('/')?;
            pct.strip_suffix("%)")?;
            Some((label.to_owned(), done.parse().ok()?, total.parse().ok()?))
        })
        .collect()
}

/// On a terminal, `wav` shows its progress as the other commands do (the
/// contouring, then the writing), and no progress line passes its total:
/// `render` of a surface that outgrows the host's first memory counted to
/// 200% when its second pass added to the first.
#[cfg(unix)]
#[test]
fn progress_is_shown_for_wav_and_never_passes_its_total() {
    let dir = TempDir::new("progress");
    let (wav, png) = (path_str(&dir.0.join("p.wav")), path_str(&dir.0.join("p.png")));
    let seen = run_on_a_terminal(&["wav", "--demo", "hydrogen:16", "--seconds", "0.5", "-o", &wav]);
    let lines = progress_lines(&seen);
    for label in ["contouring (frames fed to the board)", "writing audio (sample frames)"] {
        let last = lines.iter().rfind(|(l, ..)| l == label).unwrap_or_else(|| panic!("no {label}: {seen:?}"));
        assert_eq!(last.1, last.2, "{label} did not finish: {seen:?}");
    }
    assert!(lines.iter().any(|(_, done, total)| (done, total) == (&24_000, &24_000)), "{seen:?}");
    // gyroid:32 outgrows the host's first 65,536 points.
    let seen = run_on_a_terminal(&["render", "--demo", "gyroid:32", "--size", "32", "-o", &png]);
    let lines = progress_lines(&seen);
    assert!(lines.iter().any(|(l, ..)| l.starts_with("contouring")), "{seen:?}");
    for (label, done, total) in &lines {
        assert!(done <= total, "{label}: {done}/{total}: {seen:?}");
    }
}

/// An output whose name says another format than the one written is
/// warned of (and written all the same: its content is what the command
/// makes); a name that agrees, in any case, or has no extension is not.
#[test]
fn an_output_named_for_another_format_is_warned_of() {
    let dir = TempDir::new("misnamed");
    let file = |name: &str| path_str(&dir.0.join(name));
    for (name, format, usual, args) in [
        ("x.jpg", "a PNG", "png", vec!["render", "--demo", "sphere:8", "--size", "32", "-o"]),
        ("x.mp3", "a WAV file", "wav", vec!["wav", "--demo", "sphere:8", "--seconds", "0.01", "-o"]),
        ("x.csv", "SVG", "svg", vec!["contour", "--demo", "sphere:8", "--format", "svg", "-o"]),
        ("x.svg", "CSV", "csv", vec!["contour", "--demo", "sphere:8", "-o"]),
    ] {
        let path = file(name);
        let ext = name.rsplit('.').next().unwrap();
        let mut all = args.clone();
        all.push(&path);
        let out = run(&all);
        assert!(out.status.success(), "{all:?}: {}", said(&out));
        let want = format!(
            "isoscope-sim: warning: {path}: written as {format}, whatever its .{ext} says; name it .{usual}\n"
        );
        assert!(said(&out).starts_with(&want), "{all:?}: {}", said(&out));
        assert!(std::fs::metadata(&path).unwrap().len() > 0);
        // Named for what it is (in any case), or not named for anything: no warning.
        for good in [format!("y.{usual}"), format!("Z.{}", usual.to_uppercase()), "plain".to_owned()] {
            let path = file(&good);
            let mut all = args.clone();
            all.push(&path);
            let err = said(&run(&all));
            assert!(!err.contains("whatever its"), "{all:?}: {err}");
        }
    }
    assert!(std::fs::read(file("x.jpg")).unwrap().starts_with(b"\x89PNG"));
}

/// The README's sentence on its main job says the size that command
/// writes (render's default `--size`) and the size of the picture shown
/// above it (`docs/img/hydrogen.png`), which differ.
#[test]
fn the_readme_says_the_main_jobs_picture_size() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let readme = std::fs::read_to_string(root.join("README.md")).unwrap();
    let flat = readme.split_whitespace().collect::<Vec<_>>().join(" ");
    let start = flat.find("The first command").expect("no sentence on the main job");
    let sentence = &flat[start..start + flat[start..].find(". ").unwrap_or(flat.len() - start)];
    let help = text(&run(&["render", "--help"]).stdout);
    let size: u32 = help
        .split("--size <SIZE>")
        .nth(1)
        .and_then(|h| h.split("[default: ").nth(1))
        .and_then(|d| d.split(']').next())
        .and_then(|d| d.parse().ok())
        .unwrap_or_else(|| panic!("no default --size in:\n{help}"));
    let png = std::fs::read(root.join("docs/img/hydrogen.png")).unwrap();
    let shown = u32::from_be_bytes(png[16..20].try_into().unwrap());
    assert!(sentence.contains(&format!("{size}x{size}")), "the default {size} is not said: {sentence}");
    assert!(sentence.contains(&format!("{shown}x{shown}")), "the picture's {shown} is not said: {sentence}");
    assert!(sentence.contains(&format!("--size {shown}")), "{sentence}");
}

/// `wav --beam-channel` blanks high, as the firmware's blank pin (PB0)
/// does by default: +1 while the beam is off, -1 while it draws; and
/// `--blank-active-low` turns it over, as the firmware's feature of that
/// name does. The old `--invert-beam` is gone, not quietly the default.
#[test]
fn the_beam_channel_blanks_high_as_the_firmware_does() {
    let dir = TempDir::new("beam-channel");
    let (wav, samples) = (path_str(&dir.0.join("z.wav")), path_str(&dir.0.join("z.txt")));
    let base = [
        "wav",
        "--demo",
        "sphere:8",
        "--seconds",
        "0.05",
        "--beam-channel",
        "-o",
        &wav,
        "--samples",
        &samples,
    ];
    for (extra, blanked) in [(None, 32767i16), (Some("--blank-active-low"), -32767)] {
        let args: Vec<&str> = base.iter().copied().chain(extra).collect();
        let out = run(&args);
        assert!(out.status.success(), "{args:?}: {}", said(&out));
        let lit: Vec<bool> = std::fs::read_to_string(&samples)
            .unwrap()
            .lines()
            .map(|l| l.split(' ').nth(2) == Some("1"))
            .collect();
        assert!(lit.contains(&true) && lit.contains(&false));
        let mut r = hound::WavReader::open(&wav).unwrap();
        assert_eq!(r.spec().channels, 3);
        let z: Vec<i16> = r.samples::<i16>().map(Result::unwrap).skip(2).step_by(3).collect();
        for (i, (&z, &lit)) in z.iter().zip(lit.iter().cycle()).enumerate() {
            assert_eq!(z, if lit { -blanked } else { blanked }, "{extra:?}: sample frame {i}");
        }
    }
    for args in [
        &["wav", "--demo", "sphere:8", "--beam-channel", "--invert-beam", "-o", &wav][..],
        &["wav", "--demo", "sphere:8", "--blank-active-low", "-o", &wav],
    ] {
        assert_eq!(run(args).status.code(), Some(2), "{args:?}");
    }
}
