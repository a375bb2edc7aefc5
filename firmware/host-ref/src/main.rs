//! The host side of the firmware's QEMU end-to-end test.
//!
//! It runs the core's device engine with the firmware's settings and
//! capacities ([`isoscope_scene`], compiled here for the host), feeds it the
//! firmware's boot volume ([`isoscope_scene::boot_frames`]), and
//!
//! - `isoscope-fw-ref stats` prints what drawing the boot picture did
//!   (`key=value`);
//! - `isoscope-fw-ref samples` prints the samples the firmware plays under
//!   QEMU before a host speaks, one `x y beam` line each (beam 1 = lit):
//!   the park sample, [`QEMU_FRAMES`] frames of the boot picture
//!   (`Engine::frame`), the park sample;
//! - `isoscope-fw-ref check LOG [--received FRAME] [--blank-port NAME]
//!   [--blank-pin N] [--blank-active-low]` reads QEMU's `-d unimp` log of a
//!   run of the firmware built with `--features qemu`, decodes the DAC's
//!   dual data register (DHR12RD, offset 0x20 of the DAC) and the blank
//!   pin's BSRR (offset 0x18 of its GPIO port) writes into samples, and
//!   requires them to equal, sample for sample, the samples above followed
//!   (with `--received`) by [`QEMU_FRAMES`] repetitions of the frame in
//!   FRAME (`x y beam` lines, as `isoscope-sim device --samples` writes
//!   them for the volume sent) and the park sample. Exit status 0 when they
//!   do, 1 when not (the first differences are printed), 2 on bad usage or
//!   an unreadable log;
//! - `isoscope-fw-ref inject HOST:PORT` talks to the board (QEMU's USART2)
//!   over TCP and leaves it a damaged, abandoned transfer: hello, a
//!   32x32x32 `f32` volume begun (sent again while the board answers
//!   `Busy`: its slice memory holds the replayed picture until its next
//!   frame boundary) and three full slices sent (each
//!   acknowledged: contoured), then the fourth slice's first frame cut in
//!   half, random bytes, and a frame with a corrupt CRC. The next sender's
//!   hello abandons that transfer; the picture must not change.
//!
//! The decoding is written from the register definitions (RM0090), not
//! taken from the firmware: DHR12RD holds channel 1 (X) in bits 0..12 and
//! channel 2 (Y) in bits 16..28; BSRR bit `n` sets pin `n` high, bit
//! `n + 16` sets it low. The firmware writes DHR12RD, then BSRR, for every
//! sample; BSRR writes before the first DHR12RD (setting up the pin) must
//! leave the beam blanked.

use isoscope_core::demo::Demo;
use isoscope_core::engine::{Engine, Event, StaticBuffers};
use isoscope_core::output::{Beam, Sample};
use isoscope_core::wire::{
    AXIS_X, AXIS_Y, AXIS_Z, FrameDecoder, Levels, MAX_CHUNK, MAX_FRAME_LEN, Message, PROTOCOL_VERSION,
    SampleType, encode,
};
use isoscope_scene::{EXTENT, POINTS, QEMU_FRAMES, SLICE_BYTES, SURFACE_BYTES, boot_frames, engine_config};
use std::fmt::Write as _;
use std::io::{Read, Write as _};
use std::net::TcpStream;
use std::process::ExitCode;
use std::time::{Duration, Instant};

/// Offset of DHR12RD in the DAC block.
const DHR12RD: u64 = 0x20;
/// Offset of BSRR in a GPIO port block.
const BSRR: u64 = 0x18;

/// One register write from the unimp log.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Write {
    device: [u8; 16],
    offset: u64,
    value: u64,
    line: usize,
}

impl Write {
    fn is(&self, device: &str, offset: u64) -> bool {
        self.offset == offset && self.device_name() == device
    }
    fn device_name(&self) -> &str {
        let end = self.device.iter().position(|&b| b == 0).unwrap_or(self.device.len());
        std::str::from_utf8(&self.device[..end]).unwrap_or("")
    }
}

/// Parse one line of QEMU's unimp log:
/// `DAC: unimplemented device write (size 4, offset 0x020, value 0x04f6068c)`.
/// Reads and other lines give `None`.
fn parse_write(line: &str, number: usize) -> Option<Write> {
    let (device, rest) = line.split_once(": unimplemented device write (")?;
    let rest = rest.strip_suffix(')')?;
    let mut offset = None;
    let mut value = None;
    for field in rest.split(", ") {
        let (key, v) = field.split_once(' ')?;
        let hex = |v: &str| u64::from_str_radix(v.strip_prefix("0x")?, 16).ok();
        match key {
            "offset" => offset = hex(v),
            "value" => value = hex(v),
            _ => {}
        }
    }
    let mut name = [0u8; 16];
    let bytes = device.trim().as_bytes();
    name.get_mut(..bytes.len())?.copy_from_slice(bytes);
    Some(Write { device: name, offset: offset?, value: value?, line: number })
}

/// How the blank pin is wired.
#[derive(Debug, Clone)]
struct BlankPin {
    port: String,
    pin: u32,
    active_high: bool,
}

impl BlankPin {
    /// The beam a BSRR write leaves, or `None` unless it sets or resets
    /// exactly the blank pin (the output path touches no other pin).
    fn beam(&self, value: u64) -> Option<Beam> {
        let high = if value == 1 << self.pin {
            true
        } else if value == 1 << (self.pin + 16) {
            false
        } else {
            return None;
        };
        Some(if high == self.active_high { Beam::Off } else { Beam::On })
    }
}

/// Decode the log's writes into samples.
fn decode(log: &str, blank: &BlankPin) -> Result<Vec<Sample>, String> {
    let writes = log.lines().enumerate().filter_map(|(i, l)| parse_write(l, i + 1));
    let mut samples = Vec::new();
    // The sample whose X/Y was written and whose beam is awaited.
    let mut pending: Option<(u16, u16, usize)> = None;
    for w in writes {
        if w.is("DAC", DHR12RD) {
            if let Some((_, _, line)) = pending {
                return Err(format!(
                    "line {}: DHR12RD written twice without a BSRR write (first at line {line})",
                    w.line
                ));
            }
            if w.value & !0x0fff_0fff != 0 {
                return Err(format!(
                    "line {}: DHR12RD value {:#x} has bits outside the two 12-bit fields",
                    w.line, w.value
                ));
            }
            pending = Some(((w.value & 0xfff) as u16, (w.value >> 16 & 0xfff) as u16, w.line));
        } else if w.is(&blank.port, BSRR) {
            let beam = blank.beam(w.value).ok_or_else(|| {
                format!(
                    "line {}: BSRR value {:#x} does not just set or reset pin {}",
                    w.line, w.value, blank.pin
                )
            })?;
            match pending.take() {
                Some((x, y, _)) => samples.push(Sample::new(x, y, beam)),
                None if samples.is_empty() && beam == Beam::Off => {} // pin set-up, blanked
                None => {
                    return Err(format!("line {}: BSRR written without a DHR12RD write before it", w.line));
                }
            }
        }
    }
    if let Some((_, _, line)) = pending {
        return Err(format!("line {line}: the last DHR12RD write has no BSRR write after it"));
    }
    Ok(samples)
}

/// The firmware's engine memory, on the heap.
type Memory = StaticBuffers<SLICE_BYTES, SURFACE_BYTES>;

/// What drawing the boot picture did.
struct Boot {
    frame: Vec<Sample>,
    park: Sample,
    commands: usize,
    points: usize,
    polylines: usize,
    dropped: u64,
}

/// Feed the boot volume to an engine like the firmware's, draw it, and
/// take one frame.
fn boot_reference() -> Result<Boot, String> {
    let mut mem = Box::new(Memory::new());
    let mut engine = Engine::new(engine_config(), mem.buffers()).map_err(|e| format!("engine: {e}"))?;
    boot_frames(|f| {
        engine.feed_all(f, 0);
    })
    .map_err(|e| format!("boot volume: {e}"))?;
    engine.update(0);
    let (mut points, mut polylines) = (0, 0);
    while let Some(ev) = engine.next_event() {
        if let Event::Redrawn { polylines: l, points: p, .. } = ev {
            (points, polylines) = (p as usize, l as usize);
        }
    }
    Ok(Boot {
        frame: engine.frame().collect(),
        park: engine.beam().park_sample(),
        commands: engine.surface().map_or(0, |g| g.len()),
        points,
        polylines,
        dropped: engine.surface().map_or(0, |g| u64::from(g.dropped())),
    })
}

/// What the firmware plays under QEMU before a host speaks.
fn boot_sequence(boot: &Boot) -> Vec<Sample> {
    let mut v = vec![boot.park];
    for _ in 0..QEMU_FRAMES {
        v.extend_from_slice(&boot.frame);
    }
    v.push(boot.park);
    v
}

fn beam_digit(b: Beam) -> u8 {
    u8::from(b == Beam::On)
}

/// Read `x y beam` lines.
fn read_frame(path: &str) -> Result<Vec<Sample>, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("reading {path}: {e}"))?;
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, l)| {
            let f: Vec<&str> = l.split_whitespace().collect();
            let bad = || format!("{path}:{}: expected `x y beam`, got `{l}`", i + 1);
            let [x, y, b] = f.as_slice() else { return Err(bad()) };
            let beam = match *b {
                "1" => Beam::On,
                "0" => Beam::Off,
                _ => return Err(bad()),
            };
            Ok(Sample::new(x.parse().map_err(|_| bad())?, y.parse().map_err(|_| bad())?, beam))
        })
        .collect()
}

fn check(args: &[String]) -> Result<bool, String> {
    let mut log_path = None;
    let mut received = None;
    let mut blank = BlankPin { port: "GPIOB".into(), pin: 0, active_high: true };
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--received" => received = Some(it.next().ok_or("--received needs a file")?.clone()),
            "--blank-port" => blank.port = it.next().ok_or("--blank-port needs a value")?.clone(),
            "--blank-pin" => {
                blank.pin = it
                    .next()
                    .and_then(|v| v.parse().ok())
                    .filter(|&p| p < 16)
                    .ok_or("--blank-pin needs a pin number 0..16")?;
            }
            "--blank-active-low" => blank.active_high = false,
            s if s.starts_with('-') => return Err(format!("unknown option {s}")),
            s => log_path = Some(s.to_string()),
        }
    }
    let log_path = log_path.ok_or("check needs the path of QEMU's unimp log")?;
    let log = std::fs::read_to_string(&log_path).map_err(|e| format!("reading {log_path}: {e}"))?;
    let got = decode(&log, &blank)?;
    let boot = boot_reference()?;
    let mut want = boot_sequence(&boot);
    let boot_len = want.len();
    let mut received_frame = 0;
    if let Some(path) = &received {
        let frame = read_frame(path)?;
        if frame.is_empty() {
            return Err(format!("{path} holds no samples"));
        }
        received_frame = frame.len();
        for _ in 0..QEMU_FRAMES {
            want.extend_from_slice(&frame);
        }
        want.push(boot.park);
    }
    let mismatches: Vec<usize> =
        (0..got.len().max(want.len())).filter(|&i| got.get(i) != want.get(i)).collect();
    let lit = got.iter().filter(|s| s.beam == Beam::On).count();
    println!(
        "firmware samples={} expected={} lit={} boot_frame={} received_frame={} frames={}",
        got.len(),
        want.len(),
        lit,
        boot.frame.len(),
        received_frame,
        QEMU_FRAMES
    );
    if mismatches.is_empty() && !want.is_empty() {
        println!(
            "ok: the firmware's DAC and blank writes equal the host's samples, sample for sample ({} boot{})",
            boot_len,
            if received.is_some() { " + received volume" } else { "" }
        );
        return Ok(true);
    }
    let show = |s: Option<&Sample>| {
        s.map_or_else(|| "(none)".to_string(), |s| format!("x={} y={} beam={}", s.x, s.y, beam_digit(s.beam)))
    };
    let mut report = format!("MISMATCH: {} samples differ", mismatches.len());
    for &i in mismatches.iter().take(10) {
        let part = if i < boot_len { "boot" } else { "received" };
        let _ = write!(
            report,
            "\n  sample {i} ({part}): firmware {} expected {}",
            show(got.get(i)),
            show(want.get(i))
        );
    }
    println!("{report}");
    Ok(false)
}

/// A fixed-seed generator for the garbage (xorshift32).
struct Noise(u32);

impl Noise {
    fn byte(&mut self) -> u8 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 17;
        self.0 ^= self.0 << 5;
        (self.0 >> 24) as u8
    }
}

fn frame(msg: &Message<'_>) -> Result<Vec<u8>, String> {
    let mut buf = vec![0u8; MAX_FRAME_LEN];
    Ok(encode(msg, &mut buf).map_err(|e| format!("encoding {msg:?}: {e}"))?.to_vec())
}

/// Read the board's answers for up to `wait`, until `done` says so.
fn listen(
    s: &mut TcpStream,
    dec: &mut FrameDecoder<512>,
    wait: Duration,
    mut seen: impl FnMut(Result<Message<'_>, isoscope_core::wire::WireError>) -> bool,
) -> Result<bool, String> {
    let deadline = Instant::now() + wait;
    let mut buf = [0u8; 1024];
    while Instant::now() < deadline {
        let n = match s.read(&mut buf) {
            Ok(0) => return Err("the board closed the connection".into()),
            Ok(n) => n,
            Err(e) if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) => {
                continue;
            }
            Err(e) => return Err(format!("reading: {e}")),
        };
        for &b in &buf[..n] {
            if let Some(r) = dec.push(b) {
                if seen(r) {
                    return Ok(true);
                }
            }
        }
    }
    Ok(false)
}

fn inject(args: &[String]) -> Result<bool, String> {
    let addr = args.first().ok_or("inject needs HOST:PORT")?;
    let mut s = TcpStream::connect(addr).map_err(|e| format!("connecting to {addr}: {e}"))?;
    s.set_read_timeout(Some(Duration::from_millis(50))).map_err(|e| e.to_string())?;
    let mut dec = FrameDecoder::<512>::new();
    // Hello until the board answers (it drops what comes before its USART
    // is enabled).
    let mut hello = vec![0u8];
    hello.extend(frame(&Message::Hello { protocol: PROTOCOL_VERSION, firmware: [0, 0, 0], seq: 100 })?);
    let mut capacity = None;
    for _ in 0..10 {
        s.write_all(&hello).map_err(|e| e.to_string())?;
        let got = listen(&mut s, &mut dec, Duration::from_millis(1500), |r| {
            if let Ok(Message::Capabilities { max_slice_samples, .. }) = r {
                capacity = Some(max_slice_samples);
                return true;
            }
            false
        })?;
        if got {
            break;
        }
    }
    let capacity = capacity.ok_or("no answer to hello")?;
    // A volume whose slices fill the board's slice buffer.
    let n = 32usize;
    let slice_bytes = n * n * 4;
    if slice_bytes > capacity as usize {
        return Err(format!(
            "the board takes {capacity}-byte slices; the injected volume needs {slice_bytes}"
        ));
    }
    let seq0 = 100u16;
    let levels = Levels::from_slice(&[Demo::Hydrogen.default_level()]).unwrap_or_default();
    let mut frames = vec![frame(&Message::BeginVolume {
        seq: seq0,
        dims: [n as u16; 3],
        sample_type: SampleType::F32,
        spacing: [1.0; 3],
        levels,
        axes: AXIS_X | AXIS_Y | AXIS_Z,
        every: 1,
    })?];
    let full_slices = 3;
    let mut next_slice_frames = Vec::new();
    for k in 0..=full_slices {
        let bytes: Vec<u8> =
            (0..n * n).flat_map(|idx| Demo::Hydrogen.sample(n, idx % n, idx / n, k).to_le_bytes()).collect();
        for (c, data) in bytes.chunks(MAX_CHUNK).enumerate() {
            let seq = seq0 + frames.len() as u16 + next_slice_frames.len() as u16;
            let f =
                frame(&Message::SliceData { seq, slice: k as u16, offset: (c * MAX_CHUNK) as u32, data })?;
            if k < full_slices { frames.push(f) } else { next_slice_frames.push(f) }
        }
    }
    let last = seq0 + frames.len() as u16 - 1;
    // The begin alone first: a board replaying its picture from the slice
    // memory answers it Busy until its next frame boundary gives the
    // memory back, and takes it when sent again.
    let mut nacks = Vec::new();
    let mut begun = false;
    for _ in 0..20 {
        s.write_all(&frames[0]).map_err(|e| e.to_string())?;
        let mut busy = false;
        begun = listen(&mut s, &mut dec, Duration::from_secs(2), |r| match r {
            Ok(Message::Ack { seq }) => seq == seq0,
            Ok(Message::Nack { seq, code }) => {
                nacks.push(format!("{seq}:{code:?}"));
                busy = code == isoscope_core::wire::NackCode::Busy;
                busy
            }
            _ => false,
        })? && !busy;
        if begun {
            break;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    if !begun {
        return Err(format!("the board never took the volume's begin (nacks: {nacks:?})"));
    }
    for f in &frames[1..] {
        s.write_all(f).map_err(|e| e.to_string())?;
    }
    let mut acked = 1;
    let all = listen(&mut s, &mut dec, Duration::from_secs(20), |r| match r {
        Ok(Message::Ack { seq }) => {
            acked += 1;
            seq == last
        }
        Ok(Message::Nack { seq, code }) => {
            nacks.push(format!("{seq}:{code:?}"));
            false
        }
        _ => false,
    })?;
    if !all {
        return Err(format!("only {acked} of {} commands acknowledged (nacks: {nacks:?})", frames.len()));
    }
    // The damage: half a frame, noise, a frame with a bad CRC.
    let cut = &next_slice_frames[0];
    let mut damage = cut[..cut.len() / 2].to_vec();
    let mut noise = Noise(0x1234_5678);
    damage.extend((0..3000).map(|_| noise.byte()));
    let mut bad = next_slice_frames[1].clone();
    let mid = bad.len() / 2;
    bad[mid] = bad[mid].wrapping_add(1).max(1);
    damage.extend(&bad);
    s.write_all(&damage).map_err(|e| e.to_string())?;
    let mut errors = 0;
    listen(&mut s, &mut dec, Duration::from_millis(500), |r| {
        if let Ok(Message::Nack { seq, code }) = r {
            nacks.push(format!("{seq}:{code:?}"));
            errors += 1;
        }
        false
    })?;
    println!(
        "inject: {acked} commands acknowledged ({} full {n}x{n} f32 slices), then {} damaged bytes; {errors} nacks: {}",
        full_slices,
        damage.len(),
        nacks.join(" ")
    );
    if errors == 0 {
        return Err("the board did not complain about the damage".into());
    }
    Ok(true)
}

fn run(args: &[String]) -> Result<bool, String> {
    match args.first().map(String::as_str) {
        Some("stats") => {
            let b = boot_reference()?;
            println!("demo={} side={}", isoscope_scene::DEMO.name(), isoscope_scene::SIDE);
            println!("slice_bytes={SLICE_BYTES} extent={EXTENT} points={POINTS}");
            println!("surface_points={}", b.commands);
            println!("polylines={}", b.polylines);
            println!("points={}", b.points);
            println!("dropped={}", b.dropped);
            println!("frame_samples={}", b.frame.len());
            println!("lit_samples={}", b.frame.iter().filter(|s| s.beam == Beam::On).count());
            Ok(true)
        }
        Some("samples") => {
            let b = boot_reference()?;
            let mut out = String::new();
            for s in boot_sequence(&b) {
                let _ = writeln!(out, "{} {} {}", s.x, s.y, beam_digit(s.beam));
            }
            print!("{out}");
            Ok(true)
        }
        Some("check") => check(&args[1..]),
        Some("inject") => inject(&args[1..]),
        _ => Err("usage: isoscope-fw-ref stats | samples | check LOG [--received FRAME] [--blank-port GPIOB] [--blank-pin 0] [--blank-active-low] | inject HOST:PORT".into()),
    }
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match run(&args) {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::from(1),
        Err(e) => {
            eprintln!("isoscope-fw-ref: error: {e}");
            ExitCode::from(2)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_boot_picture_fits() {
        let b = boot_reference().unwrap();
        assert_eq!(b.dropped, 0);
        assert!(b.commands > 500 && b.commands <= POINTS, "{} points", b.commands);
        assert!(b.frame.len() > 1000);
        assert_eq!(b.frame.first().map(|s| s.beam), Some(Beam::Off));
    }

    #[test]
    fn parses_unimp_lines() {
        let w = parse_write("DAC: unimplemented device write (size 4, offset 0x020, value 0x04f6068c)", 7)
            .unwrap();
        assert!(w.is("DAC", 0x20));
        assert_eq!((w.value, w.line), (0x04f6_068c, 7));
        assert!(parse_write("GPIOB: unimplemented device read  (size 4, offset 0x000)", 1).is_none());
    }

    #[test]
    fn decodes_and_rejects() {
        let blank = BlankPin { port: "GPIOB".into(), pin: 0, active_high: true };
        let log = "GPIOB: unimplemented device write (size 4, offset 0x018, value 0x00000001)\n\
                   DAC: unimplemented device write (size 4, offset 0x020, value 0x00020001)\n\
                   GPIOB: unimplemented device write (size 4, offset 0x018, value 0x00010000)\n";
        assert_eq!(decode(log, &blank).unwrap(), [Sample::new(1, 2, Beam::On)]);
        let low = BlankPin { active_high: false, ..blank.clone() };
        assert!(decode(log, &low).is_err(), "the set-up write would light the beam");
        let twice = "DAC: unimplemented device write (size 4, offset 0x020, value 0x0)\n\
                     DAC: unimplemented device write (size 4, offset 0x020, value 0x0)\n";
        assert!(decode(twice, &blank).is_err());
    }
}
