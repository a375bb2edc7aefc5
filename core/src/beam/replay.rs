//! A frame kept to play again.
//!
//! While a picture stands still (a still view, the beam settings unchanged,
//! no volume arriving) every frame is the same samples. A board records the
//! first frame it plays of such a picture into memory that is idle
//! meanwhile ([`Replay`]), and from the next frame on plays the recording
//! ([`Player`]): a refill then costs a few cycles a sample instead of the
//! scheduler's work a command, which on a dense picture is several times
//! what a sample may take at the full sample clock. The recording is
//! exact: the same samples, bit for bit, as the frame it was made from.
//!
//! # Format
//!
//! A recording is a sequence of runs, one after the other:
//!
//! | bytes | samples |
//! |---|---|
//! | `0`, `x` (u16 LE), `y` (u16 LE), `beam` (`0` off, `1` on), `n` (u16 LE, at least 1) | `n` samples at `(x, y)` |
//! | `h` (`1 ..= 255`), then `h` pairs `dx`, `dy` (`i8`) | `h` lit samples, each the sample before it moved by `(dx, dy)` |
//!
//! The position before a frame's first sample is `(0, 0)`. A segment's
//! lit steps move the beam by about the beam speed
//! ([`BeamConfig::lit_step`](super::BeamConfig::lit_step), 17 LSB by
//! default), so the lines, most of a frame, take two bytes a sample and a
//! byte more for each 255; a jump's settle or a dwell takes eight bytes.
//! A frame that does not fit the memory is played live, frame after frame
//! (the recording is tried once a picture).
//!
//! ```
//! use isoscope_core::beam::replay::{Kept, Replay};
//! use isoscope_core::output::{Beam, Sample, SampleSource, Samples};
//!
//! let frame = [
//!     Sample::new(100, 100, Beam::Off),
//!     Sample::new(100, 100, Beam::Off),
//!     Sample::new(117, 100, Beam::On),
//!     Sample::new(134, 104, Beam::On),
//! ];
//! let mut mem = [0u8; 64];
//! let mut kept = Kept::new();
//! let mut replay = Replay::new(&mut mem, &mut kept);
//! let mut played = Vec::new();
//! let mut live = Samples(frame.iter().copied());
//! let mut rec = replay.record(7).unwrap();
//! let n = rec.fill_with(&mut live, 16, |s| played.push(s));
//! assert_eq!(n, 4);
//! rec.finish(Default::default());
//! assert_eq!(played, frame);
//! // Picture 7 is kept; from now on it plays from memory.
//! let again: Vec<_> = replay.play(7).unwrap().collect();
//! assert_eq!(again, frame);
//! assert_eq!(replay.len(), 8 + 1 + 2 + 2);
//! ```

use super::FrameStats;
use crate::output::{Beam, Each, RunSink, Sample, SampleSource, Steps};

/// The most samples one repeat run holds; longer runs are split.
const MAX_REPEAT: usize = u16::MAX as usize;

/// The most lit samples one delta run holds.
const MAX_DELTAS: u8 = u8::MAX;

/// Lit repeats of at most this many samples are kept as steps of no
/// length (two bytes each) rather than as a repeat run (eight).
const SHORT_DWELL: usize = 3;

/// A picture's frame kept in borrowed memory, to play again. See the
/// [module docs](self).
///
/// The memory is lent for as long as it is idle, and what it holds is
/// kept apart from it ([`Kept`]), so that the owner of the memory may lend
/// it again whole or in part, borrow after borrow. The frame is the picture
/// that a key names (an engine's generation), so a recording of an older
/// picture is never played for a newer one.
#[derive(Debug)]
pub struct Replay<'m> {
    mem: &'m mut [u8],
    kept: &'m mut Kept,
}

/// What a [`Replay`]'s memory holds, kept between the borrows of that
/// memory.
///
/// A recording is written at the start of the memory lent. With a tail
/// ([`Kept::with_tail`]), a finished recording that fits it is moved to the
/// very end of the memory, within its last `tail` bytes, so that it stays
/// playable while only those (or only its own bytes) are lent, the rest
/// of the memory then free for other work.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Kept {
    held: Held,
    tail: usize,
}

/// What a [`Replay`]'s memory holds.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
enum Held {
    /// Nothing (or a recording never finished).
    #[default]
    Nothing,
    /// The frame of picture `key`: `len` bytes that start `from_end` bytes
    /// before the end of the memory, and the frame's statistics.
    Frame { key: u32, from_end: usize, len: usize, stats: FrameStats },
    /// Picture `key`'s frame did not fit.
    TooLong { key: u32 },
}

impl Kept {
    /// Nothing kept; recordings stay where they are written.
    pub const fn new() -> Self {
        Self { held: Held::Nothing, tail: 0 }
    }

    /// Nothing kept; a finished recording of at most `tail` bytes is moved
    /// to the end of the memory (within its last `tail` bytes).
    pub const fn with_tail(tail: usize) -> Self {
        Self { held: Held::Nothing, tail }
    }

    /// Bytes of the recording held (0 without one).
    pub fn len(&self) -> usize {
        match self.held {
            Held::Frame { len, .. } => len,
            _ => 0,
        }
    }

    /// Whether no recording is held.
    pub fn is_empty(&self) -> bool {
        !matches!(self.held, Held::Frame { .. })
    }

    /// Whether a recording is held in the memory's tail
    /// ([`Kept::with_tail`]): playable from those bytes alone.
    pub fn in_tail(&self) -> bool {
        matches!(self.held, Held::Frame { from_end, .. } if self.tail > 0 && from_end <= self.tail)
    }

    /// Whether picture `key`'s frame is held.
    pub fn holds(&self, key: u32) -> bool {
        matches!(self.held, Held::Frame { key: k, .. } if k == key)
    }

    /// Whether picture `key`'s frame is held in the tail
    /// ([`Kept::holds`] and [`Kept::in_tail`]).
    pub fn holds_in_tail(&self, key: u32) -> bool {
        self.holds(key) && self.in_tail()
    }

    /// Forget the recording (its memory is written over).
    pub fn clear(&mut self) {
        self.held = Held::Nothing;
    }

    /// Thin the recording held in `mem` (the memory it was recorded in, or
    /// any that ends where that ends) in place: of each run of lit steps
    /// every `every`-th sample and the run's last are kept (a kept step
    /// that would not fit a delta keeps the sample before it too), and a
    /// repeat run keeps `1 / every` of its samples, at least one. The
    /// samples left are a subsequence of the frame's, every run's end
    /// among them: the same picture, drawn faster and so dimmer, in about
    /// `1 / every` of the bytes and samples, for a commit that needs the
    /// rest of the memory while the picture plays on. A recording at the
    /// very end of the memory stays there. Returns the bytes it takes
    /// now; a recording that does not read whole is forgotten (0).
    pub fn thin(&mut self, mem: &mut [u8], every: u8) -> usize {
        let Held::Frame { key, from_end, len, mut stats } = self.held else { return 0 };
        let every = u32::from(every.max(1));
        let at_end = from_end == len;
        let Some(rec) = mem.len().checked_sub(from_end).and_then(|start| mem.get_mut(start..start + len))
        else {
            self.held = Held::Nothing;
            return 0;
        };
        let Some((w, samples, lit)) = thin_runs(rec, every) else {
            self.held = Held::Nothing;
            return 0;
        };
        (stats.samples, stats.lit_samples) = (samples, lit);
        let from_end = if at_end {
            let end = mem.len();
            mem.copy_within(end - len..end - len + w, end - w);
            w
        } else {
            from_end
        };
        self.held = Held::Frame { key, from_end, len: w, stats };
        w
    }
}

/// [`Kept::thin`] over the bytes of a recording: the thinned runs are
/// written from its start (never past what has been read); their length,
/// samples and lit samples, or `None` for runs that do not read whole.
fn thin_runs(rec: &mut [u8], every: u32) -> Option<(usize, u64, u64)> {
    let (mut r, mut w) = (0usize, 0usize);
    let (mut samples, mut lit) = (0u64, 0u64);
    while r < rec.len() {
        let head = *rec.get(r)?;
        if head == 0 {
            let run: [u8; 8] = *rec.get(r..r + 8)?.first_chunk()?;
            let n = u32::from(u16::from_le_bytes([run[6], run[7]]));
            let kept = n.div_ceil(every).max(1);
            let [nl, nh] = (kept as u16).to_le_bytes(); // kept <= n <= u16::MAX
            *rec.get_mut(w..w + 8)?.first_chunk_mut()? = [0, run[1], run[2], run[3], run[4], run[5], nl, nh];
            samples += u64::from(kept);
            lit += if run[5] == 0 { 0 } else { u64::from(kept) };
            (r, w) = (r + 8, w + 8);
            continue;
        }
        let h = usize::from(head);
        rec.get(r + 1..r + 1 + 2 * h)?;
        // Pairs out so far, and the steps taken since the last one out.
        let (mut out, mut since) = (0usize, 0u32);
        let (mut ax, mut ay) = (0i16, 0i16);
        for i in 0..h {
            let (dx, dy) =
                (i16::from(*rec.get(r + 1 + 2 * i)? as i8), i16::from(*rec.get(r + 2 + 2 * i)? as i8));
            let (nx, ny) = (ax + dx, ay + dy);
            if since > 0 && (i8::try_from(nx).is_err() || i8::try_from(ny).is_err()) {
                // Too far for one delta: the sample before goes out too.
                *rec.get_mut(w + 1 + 2 * out..w + 3 + 2 * out)?.first_chunk_mut()? = [ax as u8, ay as u8];
                out += 1;
                (ax, ay, since) = (dx, dy, 1);
            } else {
                (ax, ay, since) = (nx, ny, since + 1);
            }
            if since == every || i + 1 == h {
                *rec.get_mut(w + 1 + 2 * out..w + 3 + 2 * out)?.first_chunk_mut()? = [ax as u8, ay as u8];
                out += 1;
                (ax, ay, since) = (0, 0, 0);
            }
        }
        // At most one out a step: `out <= h`.
        *rec.get_mut(w)? = out as u8;
        samples += out as u64;
        lit += out as u64;
        (r, w) = (r + 1 + 2 * h, w + 1 + 2 * out);
    }
    Some((w, samples, lit))
}

impl<'m> Replay<'m> {
    /// A replay over `mem` (any size; nothing fits in none), holding what
    /// `kept` says.
    pub fn new(mem: &'m mut [u8], kept: &'m mut Kept) -> Self {
        Self { mem, kept }
    }

    /// Bytes of memory.
    pub fn capacity(&self) -> usize {
        self.mem.len()
    }

    /// Bytes of the recording held (0 without one).
    pub fn len(&self) -> usize {
        self.kept.len()
    }

    /// Whether no recording is held.
    pub fn is_empty(&self) -> bool {
        self.kept.is_empty()
    }

    /// Whether picture `key`'s frame is held, to play.
    pub fn holds(&self, key: u32) -> bool {
        self.kept.holds(key)
    }

    /// Whether picture `key`'s frame was found too long for the memory.
    pub fn too_long(&self, key: u32) -> bool {
        self.kept.held == Held::TooLong { key }
    }

    /// Play picture `key`'s frame, if it is the one held (and lies in the
    /// memory lent).
    pub fn play(&self, key: u32) -> Option<Player<'_>> {
        play(self.mem, self.kept, key)
    }

    /// Record picture `key`'s frame as it plays, in place of what the
    /// memory held; `None` without memory, or if that frame was found too
    /// long before (it is not tried again).
    pub fn record(&mut self, key: u32) -> Option<Recorder<'_, 'm>> {
        if self.mem.is_empty() || self.too_long(key) {
            return None;
        }
        self.kept.held = Held::Nothing;
        Some(Recorder { replay: self, key, enc: Encoder::default(), done: false })
    }
}

/// Picture `key`'s frame from `mem` as `kept` says, if it is the one held
/// and lies in `mem`: what [`Replay::play`] plays, for an owner that lends
/// the memory in parts.
pub fn play<'r>(mem: &'r [u8], kept: &Kept, key: u32) -> Option<Player<'r>> {
    match kept.held {
        Held::Frame { key: k, from_end, len, stats } if k == key => {
            let start = mem.len().checked_sub(from_end)?;
            let rest = mem.get(start..start.checked_add(len)?)?;
            Some(Player { rest, x: 0, y: 0, run: Run::Done, stats })
        }
        _ => None,
    }
}

/// Records a frame as it is played ([`Replay::record`]): every sample
/// handed on is also written to the replay's memory. The recording is kept
/// once [`Recorder::finish`] says the frame ended.
#[derive(Debug)]
pub struct Recorder<'r, 'm> {
    replay: &'r mut Replay<'m>,
    key: u32,
    enc: Encoder,
    done: bool,
}

impl Recorder<'_, '_> {
    /// Take at most `max` samples of `live` into `sink` (as
    /// [`SampleSource::fill_runs`], the same runs), recording them; returns
    /// how many.
    pub fn fill_runs<S: SampleSource, R: RunSink>(
        &mut self,
        live: &mut S,
        max: usize,
        sink: &mut R,
    ) -> usize {
        if self.done {
            return live.fill_runs(max, sink);
        }
        let mut tee = Tee { sink, enc: &mut self.enc, mem: &mut *self.replay.mem };
        live.fill_runs(max, &mut tee)
    }

    /// [`Recorder::fill_runs`], a sample at a time to `put`.
    pub fn fill_with<S: SampleSource, F: FnMut(Sample)>(
        &mut self,
        live: &mut S,
        max: usize,
        put: F,
    ) -> usize {
        self.fill_runs(live, max, &mut Each(put))
    }

    /// The frame ended, with statistics `stats` (those a replay reports):
    /// keep the recording if it fit. Later calls change nothing.
    pub fn finish(&mut self, stats: FrameStats) {
        if core::mem::replace(&mut self.done, true) {
            return;
        }
        self.enc.close(self.replay.mem);
        let key = self.key;
        let (mem, kept) = (&mut *self.replay.mem, &mut *self.replay.kept);
        let len = self.enc.len;
        kept.held = if self.enc.full {
            Held::TooLong { key }
        } else if kept.tail > 0 && len <= kept.tail && len <= mem.len() {
            // To the very end of the memory, in its tail: playable from
            // the tail alone, or from any end of the memory that holds it
            // (a commit that needs more than the head takes the rest).
            let at = mem.len() - len;
            mem.copy_within(..len, at);
            Held::Frame { key, from_end: len, stats, len }
        } else {
            Held::Frame { key, from_end: mem.len(), len, stats }
        };
    }
}

/// Where a recording stands.
#[derive(Debug, Default, Clone, Copy)]
struct Encoder {
    /// Bytes written (a delta run's count byte is written when it closes).
    len: usize,
    /// The run still open, which the next samples may extend.
    open: Open,
    /// The last sample.
    last: Sample,
    /// A run did not fit: the rest is not written.
    full: bool,
}

/// The run an [`Encoder`] may extend.
#[derive(Debug, Default, Clone, Copy)]
enum Open {
    #[default]
    None,
    /// A delta run of `count` pairs whose count byte is at `at`.
    Deltas { at: usize, count: u8 },
    /// A repeat run of the last sample that starts at this byte.
    Repeat(usize),
}

impl Encoder {
    /// Append `bytes`, or mark the recording full.
    #[inline]
    fn put<const N: usize>(&mut self, mem: &mut [u8], bytes: [u8; N]) -> bool {
        let end = self.len.saturating_add(N);
        match mem.get_mut(self.len..end).and_then(|to| <&mut [u8; N]>::try_from(to).ok()) {
            Some(to) if !self.full => {
                *to = bytes;
                self.len = end;
                true
            }
            _ => {
                self.full = true;
                false
            }
        }
    }

    /// Write the open delta run's count, if one is open: no delta run is
    /// open after (an open repeat run stays open).
    fn close(&mut self, mem: &mut [u8]) {
        if let Open::Deltas { at, count } = self.open {
            if let Some(h) = mem.get_mut(at) {
                *h = count;
            }
            self.open = Open::None;
        }
    }

    /// `n` lit samples from `steps`: the lines of a frame, most of it.
    #[inline(always)]
    fn lits<S: Steps>(&mut self, mem: &mut [u8], steps: &mut S, n: usize) {
        for _ in 0..n {
            let (x, y) = steps.step();
            self.lit(mem, x, y);
        }
    }

    /// One lit sample at `(x, y)`: a pair more in the open delta run (a
    /// few operations), or [`Encoder::lit_slow`].
    #[inline(always)]
    fn lit(&mut self, mem: &mut [u8], x: u16, y: u16) {
        // Wrapping: the player adds the deltas wrapping too, so any pair
        // within an i8 is exact.
        let (dx, dy) = (x.wrapping_sub(self.last.x) as i16, y.wrapping_sub(self.last.y) as i16);
        if let (Ok(dx), Ok(dy)) = (i8::try_from(dx), i8::try_from(dy))
            && let Open::Deltas { count, .. } = &mut self.open
            && *count < MAX_DELTAS
            && let Some(pair) = mem.get_mut(self.len..).and_then(|m| m.first_chunk_mut::<2>())
        {
            *pair = [dx as u8, dy as u8];
            *count += 1;
            self.len += 2;
            self.last = Sample::new(x, y, Beam::On);
            return;
        }
        self.lit_slow(mem, x, y);
    }

    /// [`Encoder::lit`] opening a delta run, or as a repeat run of one if
    /// the step is too far for a delta.
    #[inline(never)]
    fn lit_slow(&mut self, mem: &mut [u8], x: u16, y: u16) {
        let s = Sample::new(x, y, Beam::On);
        let (dx, dy) = (x.wrapping_sub(self.last.x) as i16, y.wrapping_sub(self.last.y) as i16);
        let (Ok(dx), Ok(dy)) = (i8::try_from(dx), i8::try_from(dy)) else {
            return self.same(mem, s, 1);
        };
        self.close(mem);
        let at = self.len;
        if self.put(mem, [0, dx as u8, dy as u8]) {
            self.open = Open::Deltas { at, count: 1 };
        }
        self.last = s;
    }

    /// `n` samples equal to `s`: a short dwell of a lit beam as steps of
    /// no length, the rest as a repeat run.
    fn repeat(&mut self, mem: &mut [u8], s: Sample, n: usize) {
        if s.beam == Beam::On && n <= SHORT_DWELL {
            for _ in 0..n {
                self.lit(mem, s.x, s.y);
            }
        } else {
            self.same(mem, s, n);
        }
    }

    /// `n` samples equal to `s` as repeat runs (extending the open one if
    /// it repeats `s`).
    fn same(&mut self, mem: &mut [u8], s: Sample, n: usize) {
        let mut left = n;
        if let Open::Repeat(at) = self.open
            && self.last == s
            && let Some(count) = mem.get_mut(at + 6..at + 8).and_then(|c| <&mut [u8; 2]>::try_from(c).ok())
        {
            let had = usize::from(u16::from_le_bytes(*count));
            let k = left.min(MAX_REPEAT - had.min(MAX_REPEAT));
            *count = ((had + k) as u16).to_le_bytes(); // had + k <= u16::MAX
            left -= k;
        }
        self.close(mem);
        let [xl, xh] = s.x.to_le_bytes();
        let [yl, yh] = s.y.to_le_bytes();
        let beam = u8::from(s.beam == Beam::On);
        while left > 0 {
            let k = left.min(MAX_REPEAT);
            let [nl, nh] = (k as u16).to_le_bytes(); // k <= u16::MAX
            self.open = Open::Repeat(self.len);
            if !self.put(mem, [0, xl, xh, yl, yh, beam, nl, nh]) {
                break;
            }
            left -= k;
        }
        self.last = s;
    }
}

/// A [`RunSink`] that records every run into a replay's memory and hands it
/// on.
struct Tee<'t, R> {
    sink: &'t mut R,
    enc: &'t mut Encoder,
    mem: &'t mut [u8],
}

impl<R: RunSink> RunSink for Tee<'_, R> {
    fn repeat(&mut self, s: Sample, n: usize) {
        self.enc.repeat(self.mem, s, n);
        self.sink.repeat(s, n);
    }

    fn steps<S: Steps>(&mut self, steps: &mut S, n: usize) {
        self.enc.lits(self.mem, &mut steps.clone(), n);
        self.sink.steps(steps, n);
    }
}

/// Where a [`Player`] stands in its recording ([`Player::mark`]).
#[derive(Debug, Clone, Copy)]
pub struct Mark {
    /// Bytes of the recording not yet begun.
    left: usize,
    x: u16,
    y: u16,
    run: Run,
}

/// Picture `key`'s frame from `mem` as `kept` says ([`play`]), taken up
/// where `mark` stood: the rest of the frame a player was playing.
pub fn resume<'r>(mem: &'r [u8], kept: &Kept, key: u32, mark: Mark) -> Option<Player<'r>> {
    let mut p = play(mem, kept, key)?;
    p.rest = p.rest.get(p.rest.len().checked_sub(mark.left)?..)?;
    (p.x, p.y, p.run) = (mark.x, mark.y, mark.run);
    Some(p)
}

/// A kept frame played again ([`Replay::play`]): a [`SampleSource`] (and
/// an iterator) of the recorded samples.
#[derive(Debug, Clone)]
pub struct Player<'r> {
    /// The runs not yet begun.
    rest: &'r [u8],
    /// The last sample's position.
    x: u16,
    y: u16,
    /// The run being played.
    run: Run,
    stats: FrameStats,
}

/// The run a [`Player`] is in.
#[derive(Debug, Clone, Copy)]
enum Run {
    /// Between runs.
    Done,
    /// This many more samples equal to this one.
    Same(Sample, usize),
    /// This many more lit samples from deltas (at the start of `rest`).
    Lit(usize),
}

impl Player<'_> {
    /// The statistics of the frame as it was recorded.
    pub fn stats(&self) -> FrameStats {
        self.stats
    }

    /// Where the player stands, to take it up again later ([`resume`]).
    pub fn mark(&self) -> Mark {
        Mark { left: self.rest.len(), x: self.x, y: self.y, run: self.run }
    }

    /// Whether the frame has no samples left.
    pub fn is_done(&self) -> bool {
        self.rest.is_empty() && matches!(self.run, Run::Done | Run::Same(_, 0) | Run::Lit(0))
    }
}

impl SampleSource for Player<'_> {
    fn fill_with<F: FnMut(Sample)>(&mut self, max: usize, put: F) -> usize {
        self.fill_runs(max, &mut Each(put))
    }

    fn fill_runs<R: RunSink>(&mut self, max: usize, sink: &mut R) -> usize {
        let mut done = 0;
        while done < max {
            let room = max - done;
            match self.run {
                Run::Same(s, left) if left > 0 => {
                    let n = left.min(room);
                    sink.repeat(s, n);
                    self.run = Run::Same(s, left - n);
                    done += n;
                }
                Run::Lit(left) if left > 0 => {
                    let n = left.min(room);
                    let (pairs, _) = self.rest.as_chunks::<2>();
                    // A recording is whole (the encoder wrote it); a cut
                    // one ends here rather than inventing samples.
                    let (Some(run), Some(rest)) = (pairs.get(..n), self.rest.get(2 * n..)) else {
                        self.rest = &[];
                        self.run = Run::Done;
                        break;
                    };
                    let mut deltas = Deltas { pairs: run.iter(), x: self.x, y: self.y };
                    sink.steps(&mut deltas, n);
                    (self.x, self.y) = (deltas.x, deltas.y);
                    self.rest = rest;
                    self.run = Run::Lit(left - n);
                    done += n;
                }
                _ => {
                    let Some((&head, rest)) = self.rest.split_first() else { break };
                    if head != 0 {
                        self.run = Run::Lit(usize::from(head));
                        self.rest = rest;
                        continue;
                    }
                    let Some(([xl, xh, yl, yh, beam, nl, nh], rest)) = rest.split_first_chunk::<7>() else {
                        self.rest = &[];
                        break;
                    };
                    let beam = if *beam == 0 { Beam::Off } else { Beam::On };
                    let s = Sample::new(u16::from_le_bytes([*xl, *xh]), u16::from_le_bytes([*yl, *yh]), beam);
                    (self.x, self.y) = (s.x, s.y);
                    self.run = Run::Same(s, usize::from(u16::from_le_bytes([*nl, *nh])));
                    self.rest = rest;
                }
            }
        }
        done
    }
}

impl Iterator for Player<'_> {
    type Item = Sample;

    fn next(&mut self) -> Option<Sample> {
        self.next_sample()
    }
}

impl core::iter::FusedIterator for Player<'_> {}

/// The lit samples of a replayed delta run, as [`RunSink::steps`] takes
/// them: an add a coordinate a sample.
#[derive(Debug, Clone)]
pub struct Deltas<'r> {
    pairs: core::slice::Iter<'r, [u8; 2]>,
    x: u16,
    y: u16,
}

impl Steps for Deltas<'_> {
    #[inline(always)]
    fn step(&mut self) -> (u16, u16) {
        if let Some(&[dx, dy]) = self.pairs.next() {
            self.x = self.x.wrapping_add_signed(i16::from(dx as i8));
            self.y = self.y.wrapping_add_signed(i16::from(dy as i8));
        }
        (self.x, self.y)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::output::Samples;
    use proptest::prelude::*;
    use std::vec::Vec;

    /// Record `frame` into `cap` bytes through runs handed out `chunk`
    /// samples at a time; the samples handed on, and the replay.
    fn record(frame: &[Sample], cap: usize, chunk: usize) -> (Vec<Sample>, Option<Vec<Sample>>, usize) {
        let mut mem = std::vec![0u8; cap];
        let mut kept = Kept::new();
        let mut replay = Replay::new(&mut mem, &mut kept);
        let mut live = Samples(frame.iter().copied());
        let mut played = Vec::new();
        let mut rec = replay.record(1).unwrap();
        while rec.fill_with(&mut live, chunk, |s| played.push(s)) == chunk {}
        rec.finish(FrameStats { samples: frame.len() as u64, ..FrameStats::default() });
        let len = replay.len();
        let again = replay.play(1).map(|p| {
            // Refilled in chunks too.
            let mut p = p;
            let mut out = Vec::new();
            while p.fill_with(chunk, |s| out.push(s)) == chunk {}
            out
        });
        (played, again, len)
    }

    fn sample() -> impl Strategy<Value = Sample> {
        // Mostly small moves of a lit beam, some jumps, some repeats, in a
        // 12-bit range with codes near both ends.
        prop_oneof![
            (0u16..4096, 0u16..4096, any::<bool>()).prop_map(|(x, y, on)| Sample::new(
                x,
                y,
                if on { Beam::On } else { Beam::Off }
            )),
            (0u16..40, 0u16..40).prop_map(|(x, y)| Sample::new(x, y, Beam::On)),
            (4050u16..4096, 4050u16..4096).prop_map(|(x, y)| Sample::new(x, y, Beam::On)),
        ]
    }

    /// Frames of runs: a start sample repeated, or a walk of small steps.
    fn frame() -> impl Strategy<Value = Vec<Sample>> {
        prop::collection::vec((sample(), 1usize..400, -130i32..130, -130i32..130, any::<bool>()), 0..40)
            .prop_map(|runs| {
                let mut out = Vec::new();
                for (s, n, dx, dy, walk) in runs {
                    for k in 0..n as i32 {
                        let t = if walk { k } else { 0 };
                        let x = (i32::from(s.x) + t * dx / 16).clamp(0, 65535) as u16;
                        let y = (i32::from(s.y) + t * dy / 16).clamp(0, 65535) as u16;
                        out.push(Sample::new(x, y, s.beam));
                    }
                }
                out
            })
    }

    #[test]
    fn thinning_a_line_by_two_keeps_every_second_sample_in_half_the_bytes() {
        // A settle, then 250 lit steps of 10 LSB along x (one delta run).
        let mut frame = std::vec![Sample::new(100, 200, Beam::Off); 40];
        frame.extend((1..=250).map(|k| Sample::new(100 + 10 * k, 200, Beam::On)));
        let mut mem = std::vec![0u8; 4096];
        let mut kept = Kept::with_tail(4096);
        let mut replay = Replay::new(&mut mem, &mut kept);
        let mut rec = replay.record(1).unwrap();
        rec.fill_with(&mut Samples(frame.iter().copied()), 2000, |_| {});
        rec.finish(FrameStats::default());
        let before = kept.len();
        let after = kept.thin(&mut mem, 2);
        let thin: Vec<Sample> = play(&mem, &kept, 1).unwrap().collect();
        let mut want = std::vec![Sample::new(100, 200, Beam::Off); 20];
        want.extend((1..=125).map(|k| Sample::new(100 + 20 * k, 200, Beam::On)));
        assert!(thin == want, "{} samples", thin.len());
        assert_eq!((before, after), (8 + 1 + 2 * 250, 8 + 1 + 2 * 125));
        assert!(kept.in_tail(), "still at the end of the memory");
    }

    /// Whether `small` is a subsequence of `big`.
    fn subsequence(small: &[Sample], big: &[Sample]) -> bool {
        let mut it = big.iter();
        small.iter().all(|s| it.any(|b| b == s))
    }

    proptest! {
        /// A thinned recording plays a subsequence of the frame with its
        /// last sample, in about `1 / every` of the samples, and stays at
        /// the end of the memory when it was there.
        #[test]
        fn a_thinned_recording_is_a_subsequence_of_the_frame(frame in frame(), every in 1u8..6, tail in any::<bool>()) {
            let cap = 1 << 16;
            let mut mem = std::vec![0u8; cap];
            let mut kept = if tail { Kept::with_tail(cap) } else { Kept::new() };
            let mut replay = Replay::new(&mut mem, &mut kept);
            let mut live = Samples(frame.iter().copied());
            let mut rec = replay.record(1).unwrap();
            while rec.fill_with(&mut live, 512, |_| {}) == 512 {}
            rec.finish(FrameStats { samples: frame.len() as u64, ..FrameStats::default() });
            let before = kept.len();
            let after = kept.thin(&mut mem, every);
            prop_assert_eq!(after, kept.len());
            prop_assert!(after <= before);
            prop_assert_eq!(kept.in_tail(), tail);
            let thin: Vec<Sample> = play(&mem, &kept, 1).unwrap().collect();
            prop_assert!(subsequence(&thin, &frame), "not a subsequence");
            prop_assert_eq!(thin.last(), frame.last());
            prop_assert_eq!(play(&mem, &kept, 1).unwrap().stats().samples, thin.len() as u64);
            if every == 1 {
                prop_assert_eq!(&thin, &frame);
            } else {
                // Each run keeps at most one sample in `every`, plus its
                // end and the samples before too-far steps.
                prop_assert!(thin.len() <= frame.len());
            }
        }

        /// What is played while recording, and every replay, is the frame.
        #[test]
        fn a_replay_is_the_recorded_frame(frame in frame(), chunk in 1usize..600) {
            let (played, again, _) = record(&frame, 1 << 16, chunk);
            prop_assert_eq!(&played, &frame);
            prop_assert_eq!(again.as_ref(), Some(&frame));
        }

        /// A frame the memory cannot hold plays whole, and is not kept.
        #[test]
        fn a_frame_too_long_is_played_not_kept(frame in frame(), chunk in 1usize..600) {
            let (_, _, need) = record(&frame, 1 << 16, chunk);
            prop_assume!(need > 0);
            let (played, again, len) = record(&frame, need - 1, chunk);
            prop_assert_eq!(&played, &frame);
            prop_assert_eq!(again, None);
            prop_assert_eq!(len, 0);
        }
    }

    #[test]
    fn long_runs_split_and_replay() {
        let mut frame = std::vec![Sample::new(5, 6, Beam::Off); 70_000];
        frame.extend((0..600).map(|k| Sample::new(k * 3, 4000 - k * 5, Beam::On)));
        let (played, again, len) = record(&frame, 4096, 512);
        assert_eq!(played, frame);
        assert_eq!(again, Some(frame));
        // Two repeats for the settle, one for the first lit sample (too far
        // from it for a delta), then three delta runs of 255 + 255 + 89.
        assert_eq!(len, 3 * 8 + 3 + 2 * 599);
    }

    #[test]
    fn a_frame_too_long_is_tried_once() {
        let frame: Vec<_> = (0..100).map(|k| Sample::new(k * 200, 0, Beam::Off)).collect();
        let mut mem = [0u8; 64];
        let mut kept = Kept::new();
        let mut replay = Replay::new(&mut mem, &mut kept);
        let mut rec = replay.record(3).unwrap();
        rec.fill_with(&mut Samples(frame.iter().copied()), 1000, |_| {});
        rec.finish(FrameStats::default());
        assert!(replay.too_long(3));
        assert!(replay.record(3).is_none());
        assert!(replay.play(3).is_none());
        // Another picture is tried.
        assert!(replay.record(4).is_some());
    }

    #[test]
    fn an_unfinished_recording_is_not_played() {
        let frame = [Sample::new(1, 2, Beam::On); 10];
        let mut mem = [0u8; 64];
        let mut kept = Kept::new();
        let mut replay = Replay::new(&mut mem, &mut kept);
        let mut rec = replay.record(3).unwrap();
        rec.fill_with(&mut Samples(frame.iter().copied()), 5, |_| {});
        // The recorder goes without `finish`: the frame was cut short.
        assert!(replay.play(3).is_none());
        assert!(replay.is_empty());
    }

    #[test]
    fn a_replay_of_another_picture_is_not_played() {
        let frame = [Sample::new(1, 2, Beam::On); 10];
        let mut mem = [0u8; 64];
        let mut kept = Kept::new();
        let mut replay = Replay::new(&mut mem, &mut kept);
        let mut rec = replay.record(3).unwrap();
        rec.fill_with(&mut Samples(frame.iter().copied()), 50, |_| {});
        rec.finish(FrameStats::default());
        assert!(replay.play(3).is_some());
        assert!(replay.play(4).is_none());
        assert!(Replay::new(&mut [], &mut Kept::new()).record(5).is_none(), "no memory: nothing recorded");
    }

    proptest! {
        /// A recording that fits the tail is moved there and plays from
        /// the tail alone, or from the whole memory; one that does not
        /// stays at the start and plays from the whole memory only.
        #[test]
        fn a_recording_that_fits_the_tail_plays_from_it(frame in frame(), tail in 1usize..3000) {
            let mut mem = std::vec![0u8; 1 << 16];
            let mut kept = Kept::with_tail(tail);
            let mut replay = Replay::new(&mut mem, &mut kept);
            let mut rec = replay.record(1).unwrap();
            rec.fill_with(&mut Samples(frame.iter().copied()), usize::MAX, |_| {});
            rec.finish(FrameStats::default());
            let len = replay.len();
            let whole: Vec<_> = replay.play(1).unwrap().collect();
            prop_assert_eq!(&whole, &frame);
            let (head, rest) = mem.split_at(mem.len() - tail);
            prop_assert_eq!(kept.in_tail(), len <= tail);
            let from_tail: Option<Vec<_>> = play(rest, &kept, 1).map(Iterator::collect);
            if len <= tail {
                prop_assert_eq!(from_tail.as_ref(), Some(&frame));
            } else {
                prop_assert!(from_tail.is_none());
                prop_assert!(play(head, &kept, 1).is_none());
            }
        }
    }

    #[test]
    fn a_player_says_when_its_frame_is_done() {
        let frame = [Sample::new(1, 2, Beam::On), Sample::new(3, 2, Beam::On), Sample::new(9, 9, Beam::Off)];
        let mut mem = [0u8; 64];
        let mut kept = Kept::new();
        let mut replay = Replay::new(&mut mem, &mut kept);
        let mut rec = replay.record(3).unwrap();
        rec.fill_with(&mut Samples(frame.iter().copied()), 50, |_| {});
        rec.finish(FrameStats::default());
        let mut p = replay.play(3).unwrap();
        for _ in 0..3 {
            assert!(!p.is_done());
            assert!(p.next().is_some());
        }
        assert!(p.is_done());
        assert!(p.next().is_none());
    }
}
