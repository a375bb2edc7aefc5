//! A noisy line between a sender and a board (`isoscope-sim relay`): every
//! byte that passes, either way, may be flipped, dropped or sent twice,
//! and whole frames (up to a `0x00` delimiter) dropped or sent twice, at
//! rates given, from a seed; so a link's recovery can be tried between real
//! processes (`send` and `device`, or a board on a TCP serial bridge) and
//! its goodput measured against the error rate (`scripts/link-figures`).
//!
//! The damage is decided on the stream as sent, per direction, by its own
//! generator, so a seed gives the same damage to the same bytes whatever
//! the timing.

use anyhow::{Context, Result, bail};
use std::io::{ErrorKind, Read, Write};
use std::net::{Shutdown, TcpListener, TcpStream};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

/// What the line does to the bytes of one direction. Rates are
/// probabilities per byte or per frame, `0.0 ..= 1.0`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Noise {
    /// A byte has one bit flipped.
    pub flip: f64,
    /// A byte is lost.
    pub drop: f64,
    /// A byte arrives twice.
    pub dup: f64,
    /// A whole frame is lost.
    pub drop_frame: f64,
    /// A whole frame arrives twice.
    pub dup_frame: f64,
    /// These frames towards the board (counted from 0 on each connection,
    /// a lone delimiter not counted) are lost.
    pub lose: Vec<u64>,
}

impl Noise {
    /// Check the rates.
    ///
    /// # Errors
    /// A rate that is not a probability.
    pub fn check(&self) -> Result<()> {
        for (name, p) in [
            ("flip", self.flip),
            ("drop", self.drop),
            ("dup", self.dup),
            ("drop-frame", self.drop_frame),
            ("dup-frame", self.dup_frame),
        ] {
            if !(0.0..=1.0).contains(&p) {
                bail!("the {name} rate is {p}: give a probability, 0 to 1");
            }
        }
        Ok(())
    }
}

/// What the line did, both ways.
#[derive(Debug, Default)]
pub struct Damage {
    /// Bytes that went in.
    pub bytes: AtomicU64,
    /// Frames that went in.
    pub frames: AtomicU64,
    /// Bytes flipped, dropped and doubled; frames dropped and doubled.
    pub flipped: AtomicU64,
    /// Bytes lost.
    pub dropped: AtomicU64,
    /// Bytes sent twice.
    pub doubled: AtomicU64,
    /// Frames lost.
    pub frames_dropped: AtomicU64,
    /// Frames sent twice.
    pub frames_doubled: AtomicU64,
}

impl Damage {
    /// One line, `key=value` pairs.
    pub fn report(&self) -> String {
        let g = |a: &AtomicU64| a.load(Ordering::Relaxed);
        format!(
            "bytes={} frames={} flipped={} dropped={} doubled={} frames_dropped={} frames_doubled={}",
            g(&self.bytes),
            g(&self.frames),
            g(&self.flipped),
            g(&self.dropped),
            g(&self.doubled),
            g(&self.frames_dropped),
            g(&self.frames_doubled)
        )
    }
}

/// xorshift64*: small, seeded, the same everywhere.
#[derive(Debug, Clone)]
struct Rng(u64);

impl Rng {
    fn new(seed: u64) -> Self {
        // Never the all-zero state.
        Self(seed ^ 0x9E37_79B9_7F4A_7C15 | 1)
    }

    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// True with probability `p`.
    fn chance(&mut self, p: f64) -> bool {
        p > 0.0 && ((self.next() >> 11) as f64) < p * (1u64 << 53) as f64
    }
}

/// One direction's damage over the frames it carries.
struct Line<'a> {
    noise: &'a Noise,
    /// Frames to lose by number ([`Noise::lose`] towards the board, none
    /// back).
    lose: &'a [u64],
    rng: Rng,
    damage: &'a Damage,
    /// The frame being gathered (sent at its delimiter).
    frame: Vec<u8>,
    /// Frames passed so far.
    index: u64,
}

impl Line<'_> {
    /// Take `bytes`; what the far end gets goes to `out`.
    fn pass(&mut self, bytes: &[u8], out: &mut Vec<u8>) {
        let add = |a: &AtomicU64, n: u64| a.fetch_add(n, Ordering::Relaxed);
        add(&self.damage.bytes, bytes.len() as u64);
        for &b in bytes {
            self.frame.push(b);
            if b == 0 {
                self.end_frame(out);
            }
        }
    }

    /// The frame gathered so far goes out (lost, once or twice; each byte
    /// damaged on the way).
    fn end_frame(&mut self, out: &mut Vec<u8>) {
        let add = |a: &AtomicU64| a.fetch_add(1, Ordering::Relaxed);
        let frame = std::mem::take(&mut self.frame);
        // A lone delimiter (a sender's resynchronisation) is no frame.
        let counted = frame.len() > 1;
        if counted {
            add(&self.damage.frames);
        }
        let index = self.index;
        self.index += u64::from(counted);
        if counted && (self.lose.contains(&index) || self.rng.chance(self.noise.drop_frame)) {
            add(&self.damage.frames_dropped);
            return;
        }
        let copies = if self.rng.chance(self.noise.dup_frame) {
            add(&self.damage.frames_doubled);
            2
        } else {
            1
        };
        for _ in 0..copies {
            for &b in &frame {
                if self.rng.chance(self.noise.drop) {
                    add(&self.damage.dropped);
                    continue;
                }
                let b = if self.rng.chance(self.noise.flip) {
                    add(&self.damage.flipped);
                    b ^ (1 << (self.rng.next() % 8))
                } else {
                    b
                };
                out.push(b);
                if self.rng.chance(self.noise.dup) {
                    add(&self.damage.doubled);
                    out.push(b);
                }
            }
        }
    }
}

/// Carry bytes from `from` to `to` through `line` until `from` closes;
/// then close `to`'s writing half. Once `to` is gone, what `from` still
/// says is read and dropped until it closes too: so a relay is done with a
/// board only when the board has closed (a next client is not turned away
/// as busy by a board still closing the last one).
fn pump(mut from: TcpStream, mut to: TcpStream, mut line: Line<'_>) {
    let mut buf = vec![0u8; 4096];
    let mut out = Vec::with_capacity(8192);
    let mut open = true;
    loop {
        match from.read(&mut buf) {
            Ok(0) => break,
            Ok(n) if open => {
                out.clear();
                line.pass(buf.get(..n).unwrap_or(&[]), &mut out);
                if to.write_all(&out).is_err() {
                    open = false;
                    let _ = to.shutdown(Shutdown::Both);
                }
            }
            Ok(_) => {}
            Err(e) if e.kind() == ErrorKind::Interrupted => {}
            Err(_) => break,
        }
    }
    // What is left of an unfinished frame goes too.
    out.clear();
    if !line.frame.is_empty() {
        line.end_frame(&mut out);
        let _ = to.write_all(&out);
    }
    let _ = to.shutdown(Shutdown::Write);
    let _ = from.shutdown(Shutdown::Read);
}

/// Relay one client to the board at `to` through `noise` both ways (the
/// answers' generator seeded apart from the commands'), until either end
/// closes. What was done is counted in `damage`.
///
/// # Errors
/// The board cannot be reached.
pub fn relay(client: TcpStream, to: &str, noise: &Noise, seed: u64, damage: &Arc<Damage>) -> Result<()> {
    let board = TcpStream::connect(to).with_context(|| format!("cannot connect to the board at {to}"))?;
    for s in [&client, &board] {
        s.set_nodelay(true)?;
        s.set_read_timeout(Some(Duration::from_secs(3600)))?;
    }
    let (c2, b2) = (client.try_clone()?, board.try_clone()?);
    std::thread::scope(|s| {
        s.spawn(move || {
            let lose = &noise.lose;
            let line = Line { noise, lose, rng: Rng::new(seed), damage, frame: Vec::new(), index: 0 };
            pump(client, board, line);
        });
        s.spawn(move || {
            let line = Line { noise, lose: &[], rng: Rng::new(!seed), damage, frame: Vec::new(), index: 0 };
            pump(b2, c2, line);
        });
    });
    Ok(())
}

/// Serve clients on `listener` one after another, each relayed to `to`
/// through `noise` (the `n`-th client's seed is `seed + n`); after each,
/// `done(damage)` is told what the line did, and the relay stops when it
/// returns false.
///
/// # Errors
/// Accepting fails, or a board cannot be reached.
pub fn serve(
    listener: &TcpListener,
    to: &str,
    noise: &Noise,
    seed: u64,
    mut done: impl FnMut(&Damage) -> bool,
) -> Result<()> {
    noise.check()?;
    for n in 0u64.. {
        let (client, _) = listener.accept().context("cannot accept a client")?;
        let damage = Arc::new(Damage::default());
        relay(client, to, noise, seed.wrapping_add(n), &damage)?;
        if !done(&damage) {
            break;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(noise: &Noise, seed: u64, input: &[u8]) -> (Vec<u8>, String) {
        let damage = Damage::default();
        let mut line = Line {
            noise,
            lose: &noise.lose,
            rng: Rng::new(seed),
            damage: &damage,
            frame: Vec::new(),
            index: 0,
        };
        let mut out = Vec::new();
        // In uneven pieces: the damage does not depend on how bytes arrive.
        for piece in input.chunks(7) {
            line.pass(piece, &mut out);
        }
        (out, damage.report())
    }

    #[test]
    fn a_clean_line_passes_everything_and_a_seed_repeats_its_damage() {
        let frames: Vec<u8> = (0..100u8).flat_map(|i| [1 + i % 200, 2, 3, 0]).collect();
        assert_eq!(run(&Noise::default(), 1, &frames).0, frames);
        let noisy =
            Noise { flip: 0.05, drop: 0.01, dup: 0.01, drop_frame: 0.05, dup_frame: 0.05, lose: vec![] };
        let (a, report) = run(&noisy, 7, &frames);
        assert_eq!(run(&noisy, 7, &frames).0, a);
        assert_ne!(run(&noisy, 8, &frames).0, a);
        assert_ne!(a, frames);
        assert!(report.starts_with("bytes=400 frames=100 "), "{report}");
    }

    #[test]
    fn named_frames_are_lost_whole() {
        // A lone delimiter is not counted.
        let frames = [0, 1, 2, 0, 3, 4, 0, 5, 0];
        let lose = Noise { lose: vec![1], ..Noise::default() };
        assert_eq!(run(&lose, 1, &frames).0, [0, 1, 2, 0, 5, 0]);
        let twice = Noise { dup_frame: 1.0, ..Noise::default() };
        assert_eq!(run(&twice, 1, &[9, 0]).0, [9, 0, 9, 0]);
        assert!(Noise { flip: 1.5, ..Noise::default() }.check().is_err());
        assert!(Noise { drop: f64::NAN, ..Noise::default() }.check().is_err());
    }

    #[test]
    fn rates_come_out_as_asked() {
        let mut rng = Rng::new(3);
        let hits = (0..1_000_000).filter(|_| rng.chance(1e-3)).count();
        assert!((900..1100).contains(&hits), "{hits}");
        assert!(!(0..1000).any(|_| rng.chance(0.0)));
        assert!((0..1000).all(|_| rng.chance(1.0)));
    }
}
