//! The link between real processes on a noisy line: `send` to `device
//! --tcp` through `relay`, which flips, drops and doubles bytes and frames
//! both ways from a seed. Every transfer completes, and the board's
//! samples equal a clean run's, sample for sample (issue 16: at a bit-flip
//! rate of 1e-3 a byte in either direction, with bytes and frames lost and
//! doubled, and with any one frame lost).

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::Duration;

fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_isoscope-sim")
}

/// A process whose first line of output is its address.
struct Served {
    child: Child,
    addr: String,
}

impl Served {
    fn start(args: &[&str]) -> Self {
        let mut child =
            Command::new(bin()).args(args).stdout(Stdio::piped()).stderr(Stdio::inherit()).spawn().unwrap();
        let mut out = BufReader::new(child.stdout.take().unwrap());
        let mut addr = String::new();
        out.read_line(&mut addr).unwrap();
        // The rest of its log is read and dropped, so it never blocks.
        std::thread::spawn(move || for _ in out.lines().map_while(Result::ok) {});
        Self { child, addr: addr.trim().to_string() }
    }

    /// Wait for it to exit by itself (at most `secs`).
    fn wait(mut self, secs: u64) {
        for _ in 0..secs * 20 {
            if self.child.try_wait().unwrap().is_some() {
                return;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        panic!("{} did not exit", self.addr);
    }
}

impl Drop for Served {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn temp(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("isoscope-noisy-{}-{name}", std::process::id()))
}

/// Send hydrogen 20^3 to a fresh board, through a relay with `noise` (none:
/// straight); the board's samples, and `send`'s output.
fn run(name: &str, noise: Option<&[&str]>) -> (String, Output) {
    let samples = temp(&format!("{name}.txt"));
    let _ = std::fs::remove_file(&samples);
    let board = Served::start(&[
        "device",
        "--tcp",
        "127.0.0.1:0",
        "--samples",
        samples.to_str().unwrap(),
        "--exit-after",
        "1",
    ]);
    let relay = noise.map(|n| {
        let mut args = vec!["relay", "--to", &board.addr, "--exit-after", "1"];
        args.extend_from_slice(n);
        Served::start(&args)
    });
    let port = format!("tcp:{}", relay.as_ref().map_or(&board.addr, |r| &r.addr));
    let out = Command::new(bin())
        .args(["send", "--demo", "hydrogen:20", "--level", "0.1", "--port", &port])
        .output()
        .unwrap();
    assert!(out.status.success(), "{name}: send failed: {}", String::from_utf8_lossy(&out.stderr));
    board.wait(30);
    let got = read(&samples);
    let _ = std::fs::remove_file(&samples);
    (got, out)
}

fn read(p: &Path) -> String {
    std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// A figure of `send`'s report (its `key=` line).
fn figure(out: &Output, key: &str) -> u64 {
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .find_map(|l| l.strip_prefix(key)?.strip_prefix('=')?.parse().ok())
        .unwrap_or_else(|| panic!("no {key}= line"))
}

/// How many frames `send` sent again (a lost Hello is sent again after a
/// timeout, not counted as a retransmission).
fn retransmitted(out: &Output) -> u64 {
    figure(out, "retransmitted_frames") + figure(out, "timeouts")
}

#[test]
fn a_noisy_line_between_processes_delivers_the_clean_picture() {
    let (clean, out) = run("clean", None);
    assert!(clean.lines().count() > 1000, "a picture: {} samples", clean.lines().count());
    assert_eq!(retransmitted(&out), 0);
    for (name, noise) in [
        ("flip-1", &["--flip", "1e-3", "--seed", "1"][..]),
        ("flip-2", &["--flip", "1e-3", "--seed", "2"]),
        (
            "mixed",
            &[
                "--flip",
                "1e-3",
                "--drop",
                "1e-4",
                "--dup",
                "1e-4",
                "--drop-frame",
                "0.01",
                "--dup-frame",
                "0.01",
                "--seed",
                "3",
            ],
        ),
    ] {
        let (got, out) = run(name, Some(noise));
        assert!(retransmitted(&out) > 0, "{name}: the line did nothing?");
        assert!(got == clean, "{name}: the board's samples differ from a clean run's");
    }
}

#[test]
fn losing_any_one_frame_between_processes_is_recovered() {
    let (clean, _) = run("clean-lose", None);
    // Hydrogen 20^3 f32 is 40 chunks of 800 bytes: Hello (0), BeginVolume
    // (1), the chunks (2 to 41), EndVolume (42).
    for lose in ["0", "1", "2", "21", "41", "42"] {
        let (got, out) = run(&format!("lose-{lose}"), Some(&["--lose-frame", lose]));
        assert!(retransmitted(&out) > 0, "frame {lose}: nothing retransmitted");
        assert!(got == clean, "frame {lose} lost: the board's samples differ from a clean run's");
    }
}
