//! One picture pipeline: for the same volume, levels, planes, stride, view,
//! beam and memory, the virtual board (`device`, fed by the real `send`
//! over TCP), `render --samples`, `stats --samples` and `wav --scope-beam
//! --samples` (before resampling to audio) write the very same DAC samples, byte for
//! byte. Scenes: the four demos at two views, a real MRI file, a surface
//! larger than the board holds, and a perspective view; all with the
//! STM32F407's memory (`--board f407`), one also with the host's.

mod common;
use common::real_data;
use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_isoscope-sim")
}

/// Kills the board if the test fails before it exits.
struct Board(Child);

impl Drop for Board {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn run(args: &[&str]) -> String {
    let out = Command::new(bin()).args(args).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{args:?} failed:\n{err}");
    assert!(!err.contains("panicked"), "{err}");
    err
}

/// The board's samples for `input` sent with `view` (send's flags), and
/// the same from `render`, `stats` and `wav --scope-beam`.
fn same(name: &str, input: &[&str], view: &[&str], board: &[&str]) {
    let dir = common::Scratch::new(&format!("same-{name}"));
    let file = |f: &str| dir.path(f);
    let (device, rendered, counted, audio) = (file("device"), file("render"), file("stats"), file("wav"));
    let mut child = Command::new(bin());
    child.args(["device", "--tcp", "127.0.0.1:0", "--baud", "0", "--exit-after", "1", "--samples", &device]);
    let board_child = Board(child.args(board).stdout(Stdio::piped()).stderr(Stdio::null()).spawn().unwrap());
    let mut board_child = board_child;
    let mut lines = BufReader::new(board_child.0.stdout.take().unwrap()).lines();
    let addr = lines.next().unwrap().unwrap();
    let port = format!("tcp:{addr}");
    let mut send = vec!["send", "--port", &port, "--baud", "921600"];
    send.extend_from_slice(input);
    send.extend_from_slice(view);
    run(&send);
    // The board writes its samples once the picture is shown, then exits.
    let deadline = Instant::now() + Duration::from_secs(60);
    while board_child.0.try_wait().unwrap().is_none() {
        assert!(Instant::now() < deadline, "{name}: the board did not show the volume");
        std::thread::sleep(Duration::from_millis(20));
    }
    let want = std::fs::read(&device).unwrap();
    assert!(want.len() > 1000, "{name}: {} bytes of samples", want.len());
    let png = file("render.png");
    for (cmd, out, extra) in [
        ("render", &rendered, vec!["--size", "64", "-o", &png]),
        ("stats", &counted, vec![]),
        ("wav", &audio, vec!["--scope-beam", "--seconds", "0.01", "-o", &file("a.wav")]),
    ] {
        let mut args = vec![cmd];
        args.extend_from_slice(input);
        args.extend_from_slice(view);
        args.extend_from_slice(board);
        args.extend(extra);
        args.extend(["--samples", out.as_str()]);
        run(&args);
        let got = std::fs::read(out).unwrap();
        assert!(
            got == want,
            "{name}: {cmd} --samples differs from the board's ({} and {} bytes)",
            got.len(),
            want.len()
        );
    }
    // The comparison can fail: the view turned by a degree more draws
    // other samples.
    let mut args = vec!["stats"];
    args.extend_from_slice(input);
    args.extend_from_slice(board);
    let turned = file("turned");
    args.extend(["--yaw", "31", "--samples", turned.as_str()]);
    run(&args);
    assert!(std::fs::read(&turned).unwrap() != want, "{name}: another view drew the same samples");
}

const F407: &[&str] = &["--board", "f407"];

#[test]
fn the_four_demos_at_two_views_are_the_boards_samples() {
    for demo in ["hydrogen:24", "gyroid:20", "sphere:20", "torus:24"] {
        let input = ["--demo", demo, "--every", "1"];
        same(demo, &input, &[], F407);
        same(demo, &input, &["--yaw", "-65", "--pitch", "40", "--roll", "10"], F407);
    }
}

#[test]
fn a_real_file_a_perspective_and_an_overflow_are_the_boards_samples() {
    let head = real_data("brainsmall.den").to_string_lossy().into_owned();
    same("head", &[&head, "--level", "40", "--every", "6", "--axes", "xy,yz"], &["--pitch", "60"], F407);
    same(
        "perspective",
        &["--demo", "torus:20", "--every", "1"],
        &["--perspective", "50", "--yaw", "15"],
        F407,
    );
    // 288,411 pieces: the board keeps what it can, the rest is dropped
    // (and said), on the board and in every command alike.
    same("overflow", &["--demo", "gyroid:48", "--every", "1"], &[], F407);
    let err = run(&["stats", "--demo", "gyroid:48", "--board", "f407"]);
    assert!(err.contains("note: the f407 board holds less than this surface"), "{err}");
    // The host's memory (the virtual board's default sizes hold it all).
    same("host", &["--demo", "hydrogen:20", "--every", "1"], &[], &[]);
}
