//! Size bombs and streams without end: the raw reader takes exactly the
//! bytes `--dims` and `--dtype` declare, so a data file that is
//! `/dev/zero` fails at once with a plain error, and a volume larger than
//! `--max-volume-mb` is refused before anything is read.
//!
//! The binary runs under `ulimit -v` (address space, [`MEMORY_KB`]): a
//! reader that held a whole inflated stream, or read `/dev/zero` to its
//! end, could not allocate, and would not give the error these tests ask
//! for. Each must also answer within [`SECONDS`].

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

/// Address space the binary may take, in KiB: its own needs and a few
/// buffers, not a volume of the bombs.
const MEMORY_KB: u32 = 200_000;
/// Time a bomb may take to be refused (a debug build; it takes well under
/// a second).
const SECONDS: u64 = 20;

/// Run `isoscope-sim` with `args` under [`MEMORY_KB`]; its output, and how
/// long it took.
fn run_limited(args: &[&str]) -> (Output, Duration) {
    let start = Instant::now();
    let out = Command::new("sh")
        .arg("-c")
        .arg(format!("ulimit -v {MEMORY_KB} && exec \"$0\" \"$@\""))
        .arg(env!("CARGO_BIN_EXE_isoscope-sim"))
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("cannot run isoscope-sim {args:?}: {e}"));
    (out, start.elapsed())
}

/// Run `info` on `args` and expect a quick failure whose error names
/// every one of `causes`.
fn refused(args: &[&str], causes: &[&str]) {
    let mut all = vec!["info"];
    all.extend_from_slice(args);
    let (out, took) = run_limited(&all);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "isoscope-sim {all:?}: {}\n{stderr}", out.status);
    assert!(stderr.starts_with("isoscope-sim: error: "), "isoscope-sim {all:?}: {stderr}");
    for cause in causes {
        assert!(stderr.contains(cause), "isoscope-sim {all:?}: `{cause}` not in: {stderr}");
    }
    assert!(took < Duration::from_secs(SECONDS), "isoscope-sim {all:?} took {took:?}");
}

/// Run `info` on `args` and expect a quick success; its report.
fn loaded(args: &[&str]) -> String {
    let mut all = vec!["info"];
    all.extend_from_slice(args);
    let (out, took) = run_limited(&all);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "isoscope-sim {all:?}: {}\n{stderr}", out.status);
    assert!(took < Duration::from_secs(SECONDS), "isoscope-sim {all:?} took {took:?}");
    String::from_utf8_lossy(&out.stdout).into_owned()
}

#[test]
fn raw_dev_zero_stops_at_the_dims() {
    refused(
        &["/dev/zero", "--dims", "4x4x4", "--dtype", "u8"],
        &["/dev/zero", "64 bytes of data expected, more follow"],
    );
}

/// The limit is checked from the dims and type, before reading: 4 GiB of
/// f32 from /dev/zero is refused at once.
#[test]
fn a_volume_over_the_limit_is_refused_before_reading() {
    refused(
        &["/dev/zero", "--dims", "1024x1024x1024", "--dtype", "f32"],
        &["/dev/zero", "take 4294967296 bytes (4096 MiB), more than the limit of 2048 MiB (--max-volume-mb"],
    );
    refused(
        &["/dev/zero", "--dims", "1024x1024x1024", "--dtype", "u8", "--max-volume-mb", "1000"],
        &["take 1073741824 bytes (1024 MiB), more than the limit of 1000 MiB"],
    );
}

/// A cached real data file (`scripts/fetch-data`); a missing one fails.
fn real_data(name: &str) -> String {
    let dir = std::env::var_os("ISOSCOPE_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/isoscope-data"));
    let path = dir.join(name);
    assert!(path.is_file(), "{} is missing: run scripts/fetch-data", path.display());
    path.to_str().unwrap().to_owned()
}

/// `--max-volume-mb` on every command that reads a volume: a real file
/// over it is refused, raising it lets the file through.
#[test]
fn max_volume_mb_refuses_and_admits_a_real_file() {
    let den = real_data("brainsmall.den");
    let over = "take 1376256 bytes (1.3 MiB), more than the limit of 1 MiB";
    refused(&[&den, "--max-volume-mb", "1"], &[&den, over]);
    assert!(loaded(&[&den, "--max-volume-mb", "2"]).contains("dims=128x128x84"));
    for cmd in [&["contour", "--format", "none", "--level", "60"][..], &["stats", "--level", "60"]] {
        let mut args = cmd.to_vec();
        args.extend_from_slice(&[&den, "--max-volume-mb", "1"]);
        let (out, _) = run_limited(&args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && stderr.contains(over), "{args:?}: {stderr}");
    }
    // Checked when parsed.
    let (out, _) = run_limited(&["info", &den, "--max-volume-mb", "0"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("`0` is out of range: give 1 to 16777216"), "{stderr}");
}
