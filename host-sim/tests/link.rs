//! The UART link end to end: the real sender against the virtual board, over
//! a pseudo-terminal (both as child processes), and over an in-process line
//! that loses and corrupts frames.

use isoscope_core::command::{Command, Point3};
use isoscope_core::contour::grid::{Planes, Volume};
use isoscope_core::contour::surface::{SliceId, SurfaceSink, contour_volume};
use isoscope_core::contour::trace::Traversal;
use isoscope_core::demo::Demo;
use isoscope_core::engine::{Engine, EngineConfig, Geometry};
use isoscope_sim::board::{HostBuffers, host_capacity};
use isoscope_sim::link::{SendConfig, WireVolume, send_volume};
use isoscope_sim::volume::{DemoSpec, LoadedVolume};
use std::convert::Infallible;

mod common;

#[path = "../../core/tests/common/segments.rs"]
mod segments;
use segments::segments;
use std::io::{BufRead, BufReader, ErrorKind, Read, Write};
use std::process::{Command as Process, Stdio};
use std::sync::mpsc::{Receiver, Sender, channel};
use std::sync::{Arc, Mutex};
use std::time::Duration;

fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_isoscope-sim")
}

struct Keep(Vec<Command<Point3>>);
impl SurfaceSink for Keep {
    type Error = Infallible;
    fn command(&mut self, _: SliceId, _: usize, c: Command<Point3>) -> Result<(), Infallible> {
        self.0.push(c);
        Ok(())
    }
}

fn demo(n: usize) -> (LoadedVolume, Vec<f32>) {
    let v = LoadedVolume::demo(DemoSpec { demo: Demo::Hydrogen, n }).unwrap();
    let mut values = vec![0.0; n * n * n];
    Demo::Hydrogen.fill(n, &mut values).unwrap();
    (v, values)
}

/// The board side of an in-process line: every byte the host writes goes
/// through `damage`, then to the engine; its answers come back through a
/// channel, also damaged.
struct Line {
    engine: Arc<Mutex<Engine<'static>>>,
    answers: Sender<Vec<u8>>,
    rng: u64,
    /// One in `corrupt` bytes towards the board is flipped.
    corrupt: u64,
    /// One in `lose` answer batches is lost.
    lose: u64,
    bytes: u64,
}

impl Line {
    fn next(&mut self) -> u64 {
        self.rng ^= self.rng << 13;
        self.rng ^= self.rng >> 7;
        self.rng ^= self.rng << 17;
        self.rng
    }
}

impl Write for Line {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let mut data = buf.to_vec();
        for b in &mut data {
            if self.next().is_multiple_of(self.corrupt) {
                *b ^= 0x10;
            }
        }
        self.bytes += data.len() as u64;
        let mut e = self.engine.lock().unwrap();
        let now = (self.bytes / 92) as u32; // the clock of a 921600-baud line
        e.feed(&data, now);
        e.update(now);
        let mut out = vec![0u8; 4096];
        let n = e.transmit(&mut out);
        drop(e);
        if n > 0 && !self.next().is_multiple_of(self.lose) {
            let _ = self.answers.send(out[..n].to_vec());
        }
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// The host's end of the answers.
struct Answers(Receiver<Vec<u8>>, Vec<u8>);

impl Read for Answers {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        if self.1.is_empty() {
            match self.0.recv_timeout(Duration::from_millis(20)) {
                Ok(v) => self.1 = v,
                Err(_) => return Err(ErrorKind::WouldBlock.into()),
            }
        }
        let n = buf.len().min(self.1.len());
        buf[..n].copy_from_slice(&self.1[..n]);
        self.1.drain(..n);
        Ok(n)
    }
}

#[test]
fn a_lossy_line_delivers_the_exact_surface_by_retransmission() {
    let (vol, values) = demo(20);
    let mem: &'static mut HostBuffers =
        Box::leak(Box::new(HostBuffers::new(&host_capacity(20 * 20 * 4, 64, 100_000))));
    // No merging, so that the picture's segments are the contour's.
    let cfg = EngineConfig { merge_tolerance: 0.0, ..EngineConfig::default() };
    let engine = Arc::new(Mutex::new(Engine::new(cfg, mem.buffers()).unwrap()));
    let (tx, rx) = channel();
    let line = Line {
        engine: engine.clone(),
        answers: tx,
        rng: 0x9E37_79B9_7F4A_7C15,
        corrupt: 9000,
        lose: 12,
        bytes: 0,
    };
    let wire = WireVolume::from_loaded(&vol).unwrap();
    let cfg = SendConfig { levels: vec![0.1], chunk: 200, window: 6, ..SendConfig::default() };
    let report = send_volume(Answers(rx, Vec::new()), line, &wire, &cfg, None).unwrap();
    assert!(report.retransmitted > 0, "the line lost nothing? {report:?}");
    assert!(
        report.nacks.iter().any(|(c, _)| matches!(
            c,
            isoscope_core::wire::NackCode::BadCrc
                | isoscope_core::wire::NackCode::Truncated
                | isoscope_core::wire::NackCode::OutOfOrder
        )),
        "{report:?}"
    );
    let mut e = engine.lock().unwrap();
    e.update(u32::MAX / 2);
    let g = e.surface().expect("a picture");
    let got = segments(g.commands(), g.shift());
    let volume = Volume::new(&values, 20, 20, 20).unwrap();
    let mut keep = Keep(Vec::new());
    contour_volume(&volume, Planes::ALL, &[0.1], Traversal::Corrected, &mut keep).unwrap();
    assert_eq!(got, segments(keep.0.into_iter(), Geometry::shift_for([20, 20, 20])));
}

#[test]
fn send_to_the_virtual_board_over_a_pty_and_snapshot_the_screen() {
    let dir = std::env::temp_dir().join(format!("isoscope-link-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let snap = dir.join("screen.png");
    let samples = dir.join("frame.txt");
    let mut device = Process::new(bin())
        .args(["device", "--pty", "--board", "f407", "--exit-after", "1", "--size", "256", "--snapshot"])
        .arg(&snap)
        .arg("--samples")
        .arg(&samples)
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .unwrap();
    // The device exits once it shows the volume.
    let watchdog = common::Watchdog::new(device.id());
    let mut lines = BufReader::new(device.stdout.take().unwrap()).lines();
    let pty = lines.next().unwrap().unwrap();
    assert!(pty.starts_with("/dev/"), "first line is the pty: {pty}");
    let sent = Process::new(bin())
        .args(["send", "--demo", "hydrogen:16", "--port", &pty, "--baud", "921600"])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&sent.stdout);
    assert!(sent.status.success(), "send failed: {}", String::from_utf8_lossy(&sent.stderr));
    for key in
        ["payload_efficiency=", "retransmitted_frames=0", "board_state=Showing", "last_slice_to_picture_ms="]
    {
        assert!(stdout.contains(key), "no {key} in\n{stdout}");
    }
    let log: Vec<String> = lines.map(Result::unwrap).collect();
    let status = device.wait().unwrap();
    assert!(!watchdog.stopped_it(), "the device did not exit after showing the volume: {log:#?}");
    assert!(status.success());
    let find = |word: &str| log.iter().any(|l| l.split_whitespace().nth(1) == Some(word));
    for word in ["hello", "begun", "committed", "redrawn", "snapshot", "samples"] {
        assert!(find(word), "no `{word}` event in {log:#?}");
    }
    // One frame of DAC samples: from the park corner back to it, blanked.
    let frame: Vec<[u16; 3]> = std::fs::read_to_string(&samples)
        .unwrap()
        .lines()
        .map(|l| {
            let v: Vec<u16> = l.split(' ').map(|x| x.parse().unwrap()).collect();
            [v[0], v[1], v[2]]
        })
        .collect();
    assert!(frame.len() > 1000, "{} samples", frame.len());
    assert_eq!(frame.last(), Some(&[0, 0, 0]));
    assert!(frame.iter().filter(|s| s[2] == 1).count() > frame.len() / 2);
    // `render` and `stats` with the board's capacities draw the very same
    // samples, and the same picture.
    let want = dir.join("render.png");
    let (rendered, counted) = (dir.join("render.txt"), dir.join("stats.txt"));
    let r = Process::new(bin())
        .args(["render", "--demo", "hydrogen:16", "--board", "f407", "--size", "256", "-o"])
        .arg(&want)
        .arg("--samples")
        .arg(&rendered)
        .output()
        .unwrap();
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let r = Process::new(bin())
        .args(["stats", "--demo", "hydrogen:16", "--board", "f407", "--samples"])
        .arg(&counted)
        .output()
        .unwrap();
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let board = std::fs::read(&samples).unwrap();
    assert!(std::fs::read(&rendered).unwrap() == board, "render --samples differs from the board's");
    assert!(std::fs::read(&counted).unwrap() == board, "stats --samples differs from the board's");
    let (a, b) = (gray(&snap), gray(&want));
    let lit = |img: &[u8]| img.iter().filter(|&&v| v > 64).count();
    assert!(lit(&a) > 500, "the snapshot is dark");
    assert!(a == b, "the board's snapshot and render's picture differ");
    std::fs::remove_dir_all(&dir).ok();
}

/// A PNG's green channel.
fn gray(path: &std::path::Path) -> Vec<u8> {
    let dec = png::Decoder::new(std::fs::File::open(path).unwrap());
    let mut r = dec.read_info().unwrap();
    let mut buf = vec![0; r.output_buffer_size()];
    let info = r.next_frame(&mut buf).unwrap();
    let ch = info.color_type.samples();
    buf[..info.buffer_size()].chunks(ch).map(|p| p[1.min(ch - 1)]).collect()
}

#[test]
fn send_reports_plain_errors() {
    let out = Process::new(bin())
        .args(["send", "--demo", "sphere:8", "--port", "/nonexistent/tty"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("isoscope-sim: error: cannot open the serial port /nonexistent/tty"), "{err}");
    let out =
        Process::new(bin()).args(["send", "--demo", "sphere:8", "--port", "/dev/null"]).output().unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("not a serial port"), "{err}");
}

/// A line that damages one byte in a thousand towards the board (and loses
/// one answer batch in twenty back): every transfer still completes, with
/// the exact surface of a clean line (issue 16: at 1e-3 they all failed,
/// a damaged delimiter's `Oversize` ending the transfer).
#[test]
fn a_line_damaging_one_byte_in_a_thousand_still_delivers_the_surface() {
    let (vol, values) = demo(20);
    let want = {
        let volume = Volume::new(&values, 20, 20, 20).unwrap();
        let mut keep = Keep(Vec::new());
        contour_volume(&volume, Planes::ALL, &[0.1], Traversal::Corrected, &mut keep).unwrap();
        segments(keep.0.into_iter(), Geometry::shift_for([20, 20, 20]))
    };
    for (seed, chunk) in
        [(0x9E37_79B9_7F4A_7C15u64, 1024), (0x2545_F491_4F6C_DD1D, 256), (0xDEAD_BEEF_CAFE_F00D, 1024)]
    {
        let mem: &'static mut HostBuffers =
            Box::leak(Box::new(HostBuffers::new(&host_capacity(20 * 20 * 4, 64, 100_000))));
        let cfg = EngineConfig { merge_tolerance: 0.0, ..EngineConfig::default() };
        let engine = Arc::new(Mutex::new(Engine::new(cfg, mem.buffers()).unwrap()));
        let (tx, rx) = channel();
        let line = Line { engine: engine.clone(), answers: tx, rng: seed, corrupt: 1000, lose: 20, bytes: 0 };
        let wire = WireVolume::from_loaded(&vol).unwrap();
        let cfg = SendConfig { levels: vec![0.1], chunk, ..SendConfig::default() };
        let report = send_volume(Answers(rx, Vec::new()), line, &wire, &cfg, None)
            .unwrap_or_else(|e| panic!("seed {seed:x}, chunk {chunk}: {e:#}"));
        assert!(report.retransmitted > 0, "{report:?}");
        let mut e = engine.lock().unwrap();
        e.update(u32::MAX / 2);
        let g = e.surface().expect("a picture");
        assert_eq!(segments(g.commands(), g.shift()), want, "seed {seed:x}, chunk {chunk}");
    }
}

/// A board that says hello and then answers every command with `Busy`:
/// `send` gives up with a plain error after a bounded number of tries and
/// a bounded time, instead of retrying for good.
#[test]
fn send_gives_up_on_a_board_that_is_always_busy() {
    use isoscope_core::wire::{Message, NackCode, PROTOCOL_VERSION, ProtocolDecoder, encode};
    struct Busy {
        decoder: ProtocolDecoder,
        answers: Sender<Vec<u8>>,
    }
    impl Write for Busy {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            for &b in buf {
                let reply = match self.decoder.push(b) {
                    Some(Ok(Message::Hello { .. })) => vec![
                        Message::Hello { protocol: PROTOCOL_VERSION, firmware: [0; 3], seq: 0 },
                        Message::Capabilities {
                            protocol: PROTOCOL_VERSION,
                            max_slice_samples: 1 << 20,
                            sample_types: 0xFF,
                            display_points: 1 << 16,
                        },
                    ],
                    Some(Ok(Message::BeginVolume { seq, .. } | Message::SliceData { seq, .. })) => {
                        vec![Message::Nack { seq, code: NackCode::Busy }]
                    }
                    _ => vec![],
                };
                for m in reply {
                    let mut out = [0u8; 64];
                    let _ = self.answers.send(encode(&m, &mut out).unwrap().to_vec());
                }
            }
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }
    let (vol, _) = demo(12);
    let wire = WireVolume::from_loaded(&vol).unwrap();
    let (tx, rx) = channel();
    let board = Busy { decoder: ProtocolDecoder::new(), answers: tx };
    let cfg = SendConfig { levels: vec![0.1], ..SendConfig::default() };
    let t0 = std::time::Instant::now();
    let (done_tx, done_rx) = channel();
    std::thread::spawn(move || {
        let r = send_volume(Answers(rx, Vec::new()), board, &wire, &cfg, None);
        let _ = done_tx.send(r.map(|_| ()).map_err(|e| format!("{e:#}")));
    });
    let result = done_rx.recv_timeout(Duration::from_secs(90)).expect("send still retrying after 90 s");
    let err = result.expect_err("a board that is always busy took the volume");
    assert!(err.contains("without an acknowledgement") && err.contains("Busy"), "{err}");
    assert!(t0.elapsed() < Duration::from_secs(60), "{:?}", t0.elapsed());
}

/// The board side of a line that loses exactly one frame: the `drop`-th
/// the host writes (counting delimited frames, retransmissions included).
struct DropOne {
    engine: Arc<Mutex<Engine<'static>>>,
    answers: Sender<Vec<u8>>,
    drop: usize,
    seen: usize,
    frame: Vec<u8>,
    bytes: u64,
}

impl Write for DropOne {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        for &b in buf {
            self.frame.push(b);
            if b != 0 {
                continue;
            }
            let whole = std::mem::take(&mut self.frame);
            if whole.len() > 1 {
                self.seen += 1;
                if self.seen - 1 == self.drop {
                    continue;
                }
            }
            self.bytes += whole.len() as u64;
            let now = (self.bytes / 92) as u32;
            let mut e = self.engine.lock().unwrap();
            e.feed(&whole, now);
            e.update(now);
            let mut out = vec![0u8; 4096];
            let n = e.transmit(&mut out);
            if n > 0 {
                let _ = self.answers.send(out[..n].to_vec());
            }
        }
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// Issue 16: the loss of any one frame, the first command's included
/// (which the board once took as the start of the sequence, then counted
/// its retransmission a duplicate), is recovered, with the exact surface.
#[test]
fn losing_any_one_frame_of_a_transfer_is_recovered() {
    let (vol, values) = demo(8);
    let want = {
        let volume = Volume::new(&values, 8, 8, 8).unwrap();
        let mut keep = Keep(Vec::new());
        contour_volume(&volume, Planes::ALL, &[0.1], Traversal::Corrected, &mut keep).unwrap();
        segments(keep.0.into_iter(), Geometry::shift_for([8, 8, 8]))
    };
    let wire = WireVolume::from_loaded(&vol).unwrap();
    let cfg = SendConfig { levels: vec![0.1], chunk: 128, window: 4, ..SendConfig::default() };
    // Hello, BeginVolume, 16 chunks, EndVolume.
    for drop in 0..19 {
        let mem: &'static mut HostBuffers =
            Box::leak(Box::new(HostBuffers::new(&host_capacity(8 * 8 * 4, 16, 10_000))));
        let ecfg = EngineConfig { merge_tolerance: 0.0, ..EngineConfig::default() };
        let engine = Arc::new(Mutex::new(Engine::new(ecfg, mem.buffers()).unwrap()));
        let (tx, rx) = channel();
        let line =
            DropOne { engine: engine.clone(), answers: tx, drop, seen: 0, frame: Vec::new(), bytes: 0 };
        let report = send_volume(Answers(rx, Vec::new()), line, &wire, &cfg, None)
            .unwrap_or_else(|e| panic!("frame {drop} lost: {e:#}"));
        let mut e = engine.lock().unwrap();
        e.update(u32::MAX / 2);
        let g = e.surface().unwrap_or_else(|| panic!("frame {drop} lost: no picture; {report:?}"));
        assert_eq!(segments(g.commands(), g.shift()), want, "frame {drop} lost");
    }
}

/// A board that replays its picture from the slice memory answers the next
/// volume's first command Busy (the memory comes back at its next frame
/// boundary); the answers still due for the frames sent behind it
/// (OutOfOrder) are not new losses: the window goes back once, not once a
/// frame (which sent the whole volume again, 64 frames for torus 16^3).
#[test]
fn a_busy_first_command_costs_one_go_back() {
    let (vol, _) = demo(12);
    let mem: &'static mut HostBuffers =
        Box::leak(Box::new(HostBuffers::new(&host_capacity(12 * 12 * 4, 16, 20_000))));
    let engine = Arc::new(Mutex::new(Engine::new(EngineConfig::default(), mem.buffers()).unwrap()));
    engine.lock().unwrap().replay_frames(true);
    let wire = WireVolume::from_loaded(&vol).unwrap();
    let cfg = SendConfig { levels: vec![0.1], chunk: 128, window: 8, ..SendConfig::default() };
    let mut reports = Vec::new();
    for _ in 0..2 {
        let (tx, rx) = channel();
        let line =
            Line { engine: engine.clone(), answers: tx, rng: 1, corrupt: u64::MAX, lose: u64::MAX, bytes: 0 };
        reports.push(send_volume(Answers(rx, Vec::new()), line, &wire, &cfg, None).unwrap());
    }
    let [first, second] = &reports[..] else { unreachable!() };
    assert_eq!((first.retransmitted, first.nacks.len()), (0, 0), "{first:?}");
    assert!(
        second.nacks.iter().any(|&(c, k)| c == isoscope_core::wire::NackCode::Busy && k == 1),
        "{second:?}"
    );
    assert!(second.frames > 3 * 8, "{second:?}");
    assert!(second.retransmitted <= 8, "one window sent again: {second:?}");
}
