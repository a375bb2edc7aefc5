//! The host side of the firmware's QEMU end-to-end test.
//!
//! It builds the firmware's scene with the very same code
//! ([`isoscope_scene`], compiled here for the host) and
//!
//! - `isoscope-fw-ref stats` prints what building it did (`key=value`);
//! - `isoscope-fw-ref samples` prints the samples the firmware plays under
//!   QEMU ([`isoscope_scene::qemu_sequence`]), one `x y beam` line each
//!   (beam 1 = lit);
//! - `isoscope-fw-ref check LOG [--blank-port NAME] [--blank-pin N]
//!   [--blank-active-low]` reads QEMU's `-d unimp` log of a run of the
//!   firmware built with `--features qemu`, decodes the DAC's dual data
//!   register (DHR12RD, offset 0x20 of the DAC) and the blank pin's BSRR
//!   (offset 0x18 of its GPIO port) writes into samples, and requires them
//!   to equal the host's, sample for sample. Exit status 0 when they do, 1
//!   when not (the first differences are printed), 2 on bad usage or an
//!   unreadable log.
//!
//! The decoding is written from the register definitions (RM0090), not
//! taken from the firmware: DHR12RD holds channel 1 (X) in bits 0..12 and
//! channel 2 (Y) in bits 16..28; BSRR bit `n` sets pin `n` high, bit
//! `n + 16` sets it low. The firmware writes DHR12RD, then BSRR, for every
//! sample; BSRR writes before the first DHR12RD (setting up the pin) must
//! leave the beam blanked.

use isoscope_core::dac::{Beam, Sample};
use isoscope_scene::{Buffers, beam_config, build, qemu_sequence};
use std::fmt::Write as _;
use std::process::ExitCode;

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

fn reference() -> Result<(Box<Buffers>, isoscope_scene::Built), String> {
    let mut buf = Box::new(Buffers::new());
    let built = build(&mut buf).map_err(|e| format!("building the scene: {e:?}"))?;
    Ok((buf, built))
}

fn beam_digit(b: Beam) -> u8 {
    u8::from(b == Beam::On)
}

fn check(args: &[String]) -> Result<bool, String> {
    let mut log_path = None;
    let mut blank = BlankPin { port: "GPIOB".into(), pin: 0, active_high: true };
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
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
    let (buf, built) = reference()?;
    let want: Vec<Sample> = qemu_sequence(&buf.list, &beam_config(), &built).collect();
    let mismatches: Vec<usize> =
        (0..got.len().max(want.len())).filter(|&i| got.get(i) != want.get(i)).collect();
    let lit = got.iter().filter(|s| s.beam == Beam::On).count();
    println!(
        "firmware samples={} host samples={} lit={} frame_samples={} frames={}",
        got.len(),
        want.len(),
        lit,
        built.frame_samples,
        isoscope_scene::QEMU_FRAMES
    );
    if mismatches.is_empty() && !want.is_empty() {
        println!("ok: the firmware's DAC and blank writes equal the host's samples, sample for sample");
        return Ok(true);
    }
    let show = |s: Option<&Sample>| {
        s.map_or_else(|| "(none)".to_string(), |s| format!("x={} y={} beam={}", s.x, s.y, beam_digit(s.beam)))
    };
    let mut report = format!("MISMATCH: {} samples differ", mismatches.len());
    for &i in mismatches.iter().take(10) {
        let _ = write!(report, "\n  sample {i}: firmware {} host {}", show(got.get(i)), show(want.get(i)));
    }
    println!("{report}");
    Ok(false)
}

fn run(args: &[String]) -> Result<bool, String> {
    match args.first().map(String::as_str) {
        Some("stats") => {
            let (buf, b) = reference()?;
            println!("demo={} side={}", isoscope_scene::DEMO.name(), isoscope_scene::SIDE);
            println!("capacity={}", isoscope_scene::CAPACITY);
            println!("fragments={}", b.fragments);
            println!("points_in={}", b.points_in);
            println!("dropped={}", b.dropped);
            println!("polylines={}", b.optimize.polylines);
            println!("points={}", buf.list.len());
            println!("frame_samples={}", b.frame_samples);
            println!("lit_samples={}", b.lit_samples);
            println!("cycle_blank_length={:.1}", b.order.cycle_after);
            Ok(true)
        }
        Some("samples") => {
            let (buf, built) = reference()?;
            let mut out = String::new();
            for s in qemu_sequence(&buf.list, &beam_config(), &built) {
                let _ = writeln!(out, "{} {} {}", s.x, s.y, beam_digit(s.beam));
            }
            print!("{out}");
            Ok(true)
        }
        Some("check") => check(&args[1..]),
        _ => Err("usage: isoscope-fw-ref stats | samples | check LOG [--blank-port GPIOB] [--blank-pin 0] [--blank-active-low]".into()),
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
    fn the_scene_fits_its_display_list() {
        let (buf, b) = reference().unwrap();
        assert_eq!(b.dropped, 0);
        assert!(b.points_in <= isoscope_scene::CAPACITY, "{} points", b.points_in);
        assert!(!buf.list.is_empty() && b.frame_samples > 1000);
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
