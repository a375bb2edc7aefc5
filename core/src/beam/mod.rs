//! The beam scheduler: drawing commands in display order in, DAC samples out.
//!
//! [`Scheduler`] turns a stream of [`Command<ScreenPoint>`]s into a stream of
//! [`Sample`]s, one per DAC tick, without storing either: it holds one
//! command of lookahead (to know whether a polyline ends or turns a corner
//! at the vertex it is drawing towards) and the few counters of the command
//! it is expanding.
//!
//! # Input
//!
//! Commands come in display order, in DAC units (see [`ScreenPoint`]):
//!
//! - `MoveTo(p)` starts a polyline at `p`;
//! - `LineTo(p)` continues the open polyline with a line to `p` (a closed
//!   loop simply ends with a `LineTo` back to its start); a `LineTo` with no
//!   open polyline (at the start of the frame, after a `Point`, or after a
//!   skipped command) starts one at `p`, like a `MoveTo`;
//! - `Point(p)` is a dot at `p`; it closes any open polyline.
//!
//! Every point is cleaned first:
//!
//! - a point with a NaN or infinite coordinate cannot be drawn: its command
//!   is skipped (counted in [`FrameStats::skipped`]) and the open polyline
//!   ends there, so no line is drawn to or from it;
//! - finite coordinates are clamped into `0.0 ..= 2^bits - 1` (no clipping:
//!   a line leaving the screen runs along its edge, as a saturating DAC
//!   would draw it; clip in the view stage);
//! - a `LineTo` to where the pen already is (zero length after clamping)
//!   draws nothing and is dropped, and a polyline without a line of
//!   non-zero length (a `MoveTo` followed by anything but a `LineTo`) draws
//!   nothing at all: the beam does not even go there.
//!
//! # Output: beam semantics
//!
//! The beam has a position (where the DAC was last sent, in `f32` DAC units
//! before rounding) and is either lit or blanked. A frame starts with the
//! beam blanked and settled at the [park position](Park) (or at the
//! position given to [`Scheduler::with_start`]). Sample codes are the
//! positions rounded to the nearest integer and clamped into
//! `0 ..= 2^bits - 1`.
//!
//! A **blanked jump** of length `d > 0` (Euclidean, in LSB) to a target `t`
//! emits `settle(d)` samples at `t` with the beam off: the first one moves
//! the DAC (and blanks the beam while the amplifiers slew), the others wait
//! for them to settle, where
//!
//! ```text
//! settle(d) = clamp(ceil(settle_base + settle_per_lsb * d), 1, max(settle_max, 1))
//! ```
//!
//! A jump of zero length emits nothing (the beam is already there, settled,
//! and may stay lit).
//!
//! - **`MoveTo(p)`** (of a polyline that draws something): a blanked jump to
//!   `p`, then `dwell_start` lit samples at `p` (at least one).
//! - **`LineTo(p)`** from the current position `a`, a segment of length
//!   `L > 0`: `n = ceil(L / lit_step)` lit samples at `a + (p - a) * k / n`
//!   for `k = 1 ..= n` (constant beam speed: evenly spaced, at most
//!   `lit_step` apart before rounding, the last exactly at `p`). The steps
//!   are computed exactly in fixed point (`a` and `p` rounded to 1/32768
//!   LSB, no error accumulating along the segment), a few integer
//!   operations a sample. Then, at `p`:
//!   - if the next command continues the polyline with a `LineTo(q)` and the
//!     direction turns by more than `corner_angle_deg` at `p` (the angle
//!     between `p - a` and `q - p`): `corner_dwell` more lit samples at `p`;
//!     on a straight or gently bending run, none;
//!   - if the polyline ends at `p` (the next command is not a `LineTo`, or
//!     there is none): `dwell_end` more lit samples at `p`.
//! - **`Point(p)`**: a blanked jump to `p`, then `point_dwell` lit samples at
//!   `p` (at least one).
//! - **End of the frame**: if [`Park::return_at_end`], a blanked jump to the
//!   park position; otherwise the beam is blanked where it is. Either way,
//!   if the last sample so far is lit, one more sample at the same place
//!   with the beam off follows, so **the last sample of every frame is
//!   blanked** (an empty frame, or one that only jumps, may have no samples
//!   at all). Then the iterator ends (it is fused); the beam must never be
//!   left lit when idle, as a still spot burns the phosphor: feed the DAC
//!   [`park_samples`] while there is no frame to draw.
//!
//! So, with the defaults, a polyline `MoveTo a, LineTo b, LineTo c` with a
//! sharp corner at `b` plays as
//!
//! ```text
//! Off×settle(|a - start|) at a, On×2 at a, On×ceil(|b-a|/16) towards b,
//! On×1 at b, On×ceil(|c-b|/16) towards c, On×1 at c, ...
//! ```
//!
//! **Lit samples trace exactly the display list.** Before rounding, every
//! lit position is on an input segment (or is an input point), so every lit
//! sample lies within `sqrt(2)/2` LSB of one; every input segment of
//! non-zero length (after cleaning) is covered by lit samples from its start
//! to its end, consecutive ones at most `lit_step + sqrt(2)` LSB apart after
//! rounding. Blanked samples only ever sit at targets (points of the input,
//! or the park position).
//!
//! **Bounded work.** Each segment takes at most
//! `floor(2^(bits+1) / lit_step) + 1` samples (more than the screen's
//! diagonal needs, so it only guards against float accidents), each jump at
//! most `max(settle_max, 1)`, each dwell at most `u16::MAX`; the scheduler
//! never panics and ends when its input ends. It works with any
//! [`BeamConfig`]: [`Scheduler::new`] uses [`BeamConfig::sanitized`].
//!
//! # Example
//!
//! ```
//! use isoscope_core::beam::{BeamConfig, Park, Scheduler};
//! use isoscope_core::command::Command;
//! use isoscope_core::output::{Beam, Sample};
//! use isoscope_core::view::ScreenPoint;
//!
//! let cfg = BeamConfig {
//!     bits: 4,
//!     lit_step: 4.0,
//!     settle_base: 1.0,
//!     settle_per_lsb: 0.0,
//!     dwell_start: 1,
//!     dwell_end: 1,
//!     park: Park { x: 0, y: 0, return_at_end: true },
//!     ..BeamConfig::default()
//! };
//! let commands = [
//!     Command::MoveTo(ScreenPoint::new(2.0, 0.0)),
//!     Command::LineTo(ScreenPoint::new(10.0, 0.0)),
//! ];
//! let samples: Vec<Sample> = Scheduler::new(commands, &cfg).collect();
//! let (off, on) = (Beam::Off, Beam::On);
//! assert_eq!(samples, [
//!     Sample::new(2, 0, off),  // jump from the park position, settle
//!     Sample::new(2, 0, on),   // dwell_start
//!     Sample::new(6, 0, on),   // 8 LSB at 4 LSB a sample: two steps
//!     Sample::new(10, 0, on),
//!     Sample::new(10, 0, on),  // dwell_end
//!     Sample::new(0, 0, off),  // back to park, beam off
//! ]);
//! ```

use crate::command::Command;
use crate::fastmath::{ceil, sqrt};
use crate::output::{Beam, Sample, SampleSource};
use crate::view::ScreenPoint;

/// The smallest accepted [`BeamConfig::lit_step`], in LSB per sample.
///
/// Slower beams repeat each code more than 64 times; use a dwell instead.
/// It also bounds the samples one segment can take (`2^17 * 64` at 16 bits).
pub const MIN_LIT_STEP: f32 = 1.0 / 64.0;

/// Where the beam rests, blanked, between frames, and whether frames return
/// there.
///
/// Defaults: the corner `(0, 0)`, returning at the end of every frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Park {
    /// X code of the park position (`0 ..= 2^bits - 1`).
    pub x: u16,
    /// Y code of the park position (`0 ..= 2^bits - 1`).
    pub y: u16,
    /// End every frame with a blanked (and settled) jump back to the park
    /// position, so every frame starts and ends there and frames can be
    /// played back to back or with any idle time between them. If `false`,
    /// the beam is blanked where the frame ends; to chain frames then, start
    /// the next one with [`Scheduler::with_start`] at the previous one's
    /// [`Scheduler::position`].
    pub return_at_end: bool,
}

impl Default for Park {
    /// The corner `(0, 0)`, returning at the end of every frame.
    ///
    /// A corner, because a badly blanked spot (an AC-coupled Z input droops
    /// back on during a long idle) does least harm at the edge of the
    /// screen, and because code 0 is in range at any resolution. Returning,
    /// because then a frame's first jump really starts where the scheduler
    /// assumes (the cost, one settled jump a frame, is tens of microseconds).
    fn default() -> Self {
        Self { x: 0, y: 0, return_at_end: true }
    }
}

/// How the beam is driven: DAC resolution, beam speed, settling and dwell
/// times, park position. All times are in samples (DAC ticks), all lengths
/// in DAC LSB.
///
/// The [defaults](BeamConfig::default) suit a typical analog oscilloscope
/// in XY mode (X and Y amplifiers of about 1 MHz bandwidth, a Z input for
/// blanking) driven by a 12-bit DAC at 1 MS/s.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct BeamConfig {
    /// DAC resolution in bits, `1 ..= 16`: codes are `0 ..= 2^bits - 1`.
    pub bits: u8,
    /// Largest step between consecutive lit samples, in LSB (`>=`
    /// [`MIN_LIT_STEP`], finite). It sets the beam speed, hence the line
    /// brightness: a segment of length `L` takes `ceil(L / lit_step)`
    /// samples.
    pub lit_step: f32,
    /// Samples a blanked jump waits at its target whatever its length
    /// (finite, `>= 0`).
    pub settle_base: f32,
    /// Extra samples a blanked jump waits per LSB of its length (finite,
    /// `>= 0`).
    pub settle_per_lsb: f32,
    /// Most samples a blanked jump waits (0 acts as 1: a jump always takes
    /// one blanked sample).
    pub settle_max: u16,
    /// Lit samples at a polyline's start point before the beam moves
    /// (`>= 1`).
    pub dwell_start: u16,
    /// Extra lit samples at a polyline's end point, after the sample that
    /// reaches it.
    pub dwell_end: u16,
    /// Extra lit samples at a vertex where the polyline turns by more than
    /// [`BeamConfig::corner_angle_deg`].
    pub corner_dwell: u16,
    /// The turn, in degrees (`0 ..= 180`), above which a vertex is a corner:
    /// the angle between the incoming and the outgoing direction (0 is
    /// straight on, 180 a U-turn).
    pub corner_angle_deg: f32,
    /// Lit samples for a [`Command::Point`] (`>= 1`).
    pub point_dwell: u16,
    /// The park position and whether frames return there.
    pub park: Park,
}

impl Default for BeamConfig {
    /// Defaults for a ~1 MHz-bandwidth XY scope and a 12-bit DAC at 1 MS/s:
    ///
    /// - `bits: 12`.
    /// - `lit_step: 16.0`: 16 LSB/µs, a full-screen line in 256 µs. A spot of
    ///   ~0.5 mm on a 10 cm screen is ~20 LSB wide, so consecutive samples
    ///   overlap and lines look solid, while the amplifiers (time constant
    ///   ~0.16 µs) lag the beam by only ~3 LSB, so corners stay sharp. A
    ///   20 ms frame (50 Hz, flicker-free on P31 phosphor) has room for
    ///   ~320,000 LSB of line, about 78 screen widths, less jumps and dwells.
    /// - `settle_base: 2.0`, `settle_per_lsb: 1/256`, `settle_max: 32`: a
    ///   small jump waits 3 samples (the exponential tail of a ~1 MHz
    ///   amplifier, about 9 time constants to 0.5 LSB, plus the Z input's
    ///   delay); a long one is slew-limited, 16 extra samples for a
    ///   full-scale 4096-LSB jump (25 for the diagonal).
    /// - `dwell_start: 2`, `dwell_end: 1`: two lit samples at each end of a
    ///   polyline (the Z input switches on late and the amplifiers lag the
    ///   last step), so ends are neither dim nor short.
    /// - `corner_dwell: 1` above `corner_angle_deg: 60.0`: one extra sample
    ///   at sharp vertices so they are not rounded; smooth contours (many
    ///   small turns) run at constant speed and brightness.
    /// - `point_dwell: 4`: a line gives each spot width (~20 LSB) about 1.3
    ///   samples; a dot gets 4, as much as a short dash, so isolated points
    ///   (contours that pinch to a node) stay visible.
    /// - `park`: [`Park::default`], the corner `(0, 0)`, returning there at
    ///   the end of each frame.
    fn default() -> Self {
        Self {
            bits: 12,
            lit_step: 16.0,
            settle_base: 2.0,
            settle_per_lsb: 1.0 / 256.0,
            settle_max: 32,
            dwell_start: 2,
            dwell_end: 1,
            corner_dwell: 1,
            corner_angle_deg: 60.0,
            point_dwell: 4,
            park: Park::default(),
        }
    }
}

/// Why a [`BeamConfig`] is invalid.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BeamConfigError {
    /// `bits` is not within `1 ..= 16`.
    Bits {
        /// The resolution given.
        bits: u8,
    },
    /// `lit_step` is NaN, infinite or below [`MIN_LIT_STEP`].
    LitStep,
    /// `settle_base` is NaN, infinite or negative.
    SettleBase,
    /// `settle_per_lsb` is NaN, infinite or negative.
    SettlePerLsb,
    /// `dwell_start` is 0 (a polyline's start would not be lit).
    DwellStart,
    /// `point_dwell` is 0 (points would not be drawn).
    PointDwell,
    /// `corner_angle_deg` is NaN or not within `0 ..= 180`.
    CornerAngle,
    /// The park position is outside `0 ..= 2^bits - 1`.
    Park {
        /// X code of the park position.
        x: u16,
        /// Y code of the park position.
        y: u16,
    },
}

impl core::fmt::Display for BeamConfigError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            BeamConfigError::Bits { bits } => write!(f, "DAC resolution of {bits} bits is not within 1..=16"),
            BeamConfigError::LitStep => {
                write!(f, "lit_step must be finite and at least {MIN_LIT_STEP} LSB per sample")
            }
            BeamConfigError::SettleBase => write!(f, "settle_base must be finite and not negative"),
            BeamConfigError::SettlePerLsb => write!(f, "settle_per_lsb must be finite and not negative"),
            BeamConfigError::DwellStart => write!(f, "dwell_start must be at least 1 sample"),
            BeamConfigError::PointDwell => write!(f, "point_dwell must be at least 1 sample"),
            BeamConfigError::CornerAngle => write!(f, "corner_angle_deg must be within 0..=180 degrees"),
            BeamConfigError::Park { x, y } => {
                write!(f, "park position ({x}, {y}) is outside the DAC range")
            }
        }
    }
}

impl core::error::Error for BeamConfigError {}

impl BeamConfig {
    /// The largest DAC code, `2^bits - 1` (with `bits` clamped into
    /// `1 ..= 16`).
    pub fn max_code(&self) -> u16 {
        let bits = self.bits.clamp(1, 16);
        u16::MAX >> (16 - bits)
    }

    /// Check every field.
    ///
    /// # Errors
    /// The first invalid field found, in declaration order (`bits` first,
    /// since the park range depends on it).
    pub fn validate(&self) -> Result<(), BeamConfigError> {
        if !(1..=16).contains(&self.bits) {
            return Err(BeamConfigError::Bits { bits: self.bits });
        }
        if !(self.lit_step.is_finite() && self.lit_step >= MIN_LIT_STEP) {
            return Err(BeamConfigError::LitStep);
        }
        if !(self.settle_base.is_finite() && self.settle_base >= 0.0) {
            return Err(BeamConfigError::SettleBase);
        }
        if !(self.settle_per_lsb.is_finite() && self.settle_per_lsb >= 0.0) {
            return Err(BeamConfigError::SettlePerLsb);
        }
        if self.dwell_start == 0 {
            return Err(BeamConfigError::DwellStart);
        }
        if !(0.0..=180.0).contains(&self.corner_angle_deg) {
            return Err(BeamConfigError::CornerAngle);
        }
        if self.point_dwell == 0 {
            return Err(BeamConfigError::PointDwell);
        }
        let max = self.max_code();
        if self.park.x > max || self.park.y > max {
            return Err(BeamConfigError::Park { x: self.park.x, y: self.park.y });
        }
        Ok(())
    }

    /// The nearest valid configuration: a valid one is returned unchanged.
    ///
    /// `bits` is clamped into `1 ..= 16`; a positive finite `lit_step` below
    /// [`MIN_LIT_STEP`] becomes `MIN_LIT_STEP`, and any other invalid float
    /// (NaN, infinite, negative) becomes its default; a corner angle outside
    /// `0 ..= 180` is clamped (NaN becomes the default); zero dwells that
    /// must be at least 1 become 1; the park position is clamped into range.
    pub fn sanitized(&self) -> BeamConfig {
        let d = BeamConfig::default();
        let nonneg = |v: f32, default: f32| if v.is_finite() && v >= 0.0 { v } else { default };
        let bits = self.bits.clamp(1, 16);
        let lit_step = if !self.lit_step.is_finite() || self.lit_step <= 0.0 {
            d.lit_step
        } else {
            self.lit_step.max(MIN_LIT_STEP)
        };
        let corner_angle_deg = if self.corner_angle_deg.is_nan() {
            d.corner_angle_deg
        } else {
            self.corner_angle_deg.clamp(0.0, 180.0)
        };
        let max = u16::MAX >> (16 - bits);
        BeamConfig {
            bits,
            lit_step,
            settle_base: nonneg(self.settle_base, d.settle_base),
            settle_per_lsb: nonneg(self.settle_per_lsb, d.settle_per_lsb),
            settle_max: self.settle_max,
            dwell_start: self.dwell_start.max(1),
            dwell_end: self.dwell_end,
            corner_dwell: self.corner_dwell,
            corner_angle_deg,
            point_dwell: self.point_dwell.max(1),
            park: Park { x: self.park.x.min(max), y: self.park.y.min(max), ..self.park },
        }
    }

    /// Blanked samples a jump of `length` LSB takes: 0 for a jump of zero
    /// length (or NaN), else
    /// `clamp(ceil(settle_base + settle_per_lsb * length), 1, max(settle_max, 1))`.
    ///
    /// Meaningful for a valid configuration (the scheduler uses its
    /// [sanitized](BeamConfig::sanitized) copy); never panics.
    pub fn settle_samples(&self, length: f32) -> u16 {
        if length.is_nan() || length <= 0.0 {
            return 0;
        }
        let wait = ceil(self.settle_base + self.settle_per_lsb * length);
        // `as` saturates (and maps NaN to 0), so this never wraps.
        let wait = if wait.is_nan() { 0 } else { wait as u32 };
        let max = u32::from(self.settle_max.max(1));
        // `min(max)` keeps it within u16.
        u16::try_from(wait.clamp(1, max)).unwrap_or(u16::MAX)
    }

    /// The samples one lit segment of `length` LSB takes:
    /// `ceil(length / lit_step)`, at least 1 for a positive length, 0 for
    /// zero (or NaN), capped at `floor(2^(bits+1) / lit_step) + 1`.
    ///
    /// Meaningful for a valid configuration; never panics.
    pub fn segment_samples(&self, length: f32) -> u32 {
        self.segment_samples_within(length, self.segment_cap())
    }

    /// [`BeamConfig::segment_samples`] with the cap given (the scheduler
    /// computes it once, not once a segment).
    fn segment_samples_within(&self, length: f32, cap: u32) -> u32 {
        if length.is_nan() || length <= 0.0 {
            return 0;
        }
        let steps = ceil(length / self.lit_step);
        let steps = if steps.is_nan() { 1 } else { (steps as u32).max(1) };
        steps.min(cap)
    }

    /// The most samples one lit segment may take:
    /// `floor(2^(bits+1) / lit_step) + 1`.
    pub fn segment_cap(&self) -> u32 {
        let span = f32::from(self.max_code()) + 1.0;
        let cap = libm::floorf(2.0 * span / self.lit_step);
        let cap = if cap.is_nan() { 0 } else { cap as u32 };
        cap.saturating_add(1)
    }

    /// One blanked sample at the park position (clamped into range).
    pub fn park_sample(&self) -> Sample {
        let max = self.max_code();
        Sample::new(self.park.x.min(max), self.park.y.min(max), Beam::Off)
    }
}

/// `n` blanked samples at the park position: what to play while there is
/// no frame to draw (a still, lit spot burns the phosphor).
pub fn park_samples(cfg: &BeamConfig, n: usize) -> core::iter::RepeatN<Sample> {
    core::iter::repeat_n(cfg.park_sample(), n)
}

/// What a frame costs: counts, lengths and samples.
///
/// [`Scheduler::stats`] accumulates it as the samples are produced (a
/// command's lengths and counts are added as its first sample is produced);
/// [`frame_stats`] runs a whole frame.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FrameStats {
    /// Polylines drawn (those with at least one line of non-zero length).
    pub polylines: u32,
    /// Dots drawn ([`Command::Point`]s).
    pub points: u32,
    /// Commands skipped because a coordinate is NaN or infinite.
    pub skipped: u32,
    /// Sum of the Euclidean lengths of the lit segments, in LSB (after
    /// clamping into range).
    pub lit_length: f32,
    /// Sum of the Euclidean lengths of the blanked jumps, in LSB, including
    /// the first one from the frame's start position (the park position
    /// unless given to [`Scheduler::with_start`]) and, with
    /// [`Park::return_at_end`], the one back to the park position.
    pub blank_length: f32,
    /// Samples produced.
    pub samples: u64,
    /// Samples produced with the beam lit.
    pub lit_samples: u64,
}

impl FrameStats {
    /// Frames per second when played at `sample_rate_hz`:
    /// `sample_rate_hz / samples`.
    ///
    /// An empty frame (no samples) gives `0.0`, not infinity: nothing is
    /// drawn, and the caller idles at the park position anyway; this keeps
    /// averages and logs finite.
    pub fn fps(&self, sample_rate_hz: f32) -> f32 {
        if self.samples == 0 { 0.0 } else { sample_rate_hz / self.samples as f32 }
    }

    /// Samples produced with the beam blanked.
    pub fn blank_samples(&self) -> u64 {
        self.samples.saturating_sub(self.lit_samples)
    }
}

/// Run the scheduler over a whole frame (from the park position) and return
/// its statistics, without storing any sample.
pub fn frame_stats<I>(commands: I, cfg: &BeamConfig) -> FrameStats
where
    I: IntoIterator<Item = Command<ScreenPoint>>,
{
    let mut scheduler = Scheduler::new(commands, cfg);
    scheduler.skip_to_end();
    scheduler.stats()
}

/// A cleaned command: finite, clamped, zero-length lines dropped.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
enum Step {
    /// A polyline starts here (a `MoveTo`, or a `LineTo` with no open
    /// polyline).
    Start(Pos),
    /// A line of non-zero length from the pen to here.
    Line(Pos),
    /// A dot.
    Dot(Pos),
}

/// A position in DAC units, finite and in range.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
struct Pos {
    x: f32,
    y: f32,
}

impl Pos {
    fn distance(self, o: Pos) -> f32 {
        let (dx, dy) = (o.x - self.x, o.y - self.y);
        sqrt(dx * dx + dy * dy)
    }
}

/// Cleans the raw commands (see the module docs).
#[derive(Debug, Clone)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
struct Clean<I> {
    src: I,
    /// Where the open polyline's pen is; `None` when no polyline is open.
    pen: Option<Pos>,
    max: f32,
    skipped: u32,
}

impl<I: Iterator<Item = Command<ScreenPoint>>> Clean<I> {
    /// The next cleaned command (consuming as much input as it takes).
    fn next_step(&mut self) -> Option<Step> {
        loop {
            let command = self.src.next()?;
            let p = *command.point();
            if !(p.x.is_finite() && p.y.is_finite()) {
                self.skipped = self.skipped.saturating_add(1);
                self.pen = None;
                continue;
            }
            // Not `f32::clamp`, which checks its bounds every call.
            let fit = |v: f32| {
                if v < 0.0 {
                    0.0
                } else if v > self.max {
                    self.max
                } else {
                    v
                }
            };
            let p = Pos { x: fit(p.x), y: fit(p.y) };
            match command {
                Command::MoveTo(_) => {
                    self.pen = Some(p);
                    return Some(Step::Start(p));
                }
                Command::LineTo(_) => match self.pen {
                    None => {
                        self.pen = Some(p);
                        return Some(Step::Start(p));
                    }
                    Some(pen) if pen == p => continue,
                    Some(_) => {
                        self.pen = Some(p);
                        return Some(Step::Line(p));
                    }
                },
                Command::Point(_) => {
                    self.pen = None;
                    return Some(Step::Dot(p));
                }
            }
        }
    }
}

/// The expansion of one command into samples: blanked samples at the
/// target, then lit steps from `from` to the target, then lit samples at
/// the target.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
struct Plan {
    to: Pos,
    /// The lit steps' positions, in fixed point.
    x: Dda,
    y: Dda,
    /// `to` rounded to DAC codes.
    code: (u16, u16),
    blank: u16,
    step: u32,
    steps: u32,
    lit: u16,
}

/// Fractional bits of the fixed-point positions of lit steps: a code of up
/// to 16 bits and 15 fractional bits fit an `i32` with room for rounding,
/// and a whole move (at most `2^31 - 2^15`) does too.
const FRAC: u32 = 15;

/// One coordinate of a segment's lit steps, exactly: step `k` of `n` is at
/// `from + floor(d * k / n)` in fixed point (`d = to - from`), kept as a
/// quotient and a remainder so that a step is two additions and a compare,
/// with no error that grows along the segment.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
struct Dda {
    /// Position of the last step, fixed point, in `0 ..= max << FRAC`.
    at: i32,
    /// `d * k mod n` of the last step, in `0 .. n`.
    err: i32,
    /// `floor(d / n)`.
    q: i32,
    /// `d mod n` (Euclidean), in `0 .. n`.
    r: i32,
}

impl Dda {
    /// `v` (finite, in `0 ..= 65535`) in fixed point, rounded.
    #[inline]
    fn fixed(v: f32) -> i32 {
        (v * (1u32 << FRAC) as f32 + 0.5) as i32
    }

    /// Steps from `at` to `to` (both [`Dda::fixed`]) in `n > 0` steps.
    #[inline]
    fn new(at: i32, to: i32, n: i32) -> Self {
        let d = to - at;
        Self { at, err: 0, q: d.div_euclid(n), r: d.rem_euclid(n) }
    }

    /// Advance one step (of `n`) and return the code there (rounded half
    /// up; never beyond the segment's ends, so within the DAC range).
    #[inline(always)]
    fn step(&mut self, n: i32) -> u16 {
        self.at += self.q;
        self.err += self.r;
        if self.err >= n {
            self.err -= n;
            self.at += 1;
        }
        ((self.at + (1 << (FRAC - 1))) >> FRAC) as u16
    }
}

/// The beam scheduler: an iterator of DAC [`Sample`]s drawing a stream of
/// commands. See the [module docs](self) for the exact semantics.
///
/// It holds one command of lookahead and a few counters, never allocates,
/// and never panics; it ends (and stays ended) when the commands end and
/// the beam is blanked.
#[derive(Debug, Clone)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Scheduler<I> {
    src: Clean<I>,
    ahead: Option<Step>,
    cfg: BeamConfig,
    /// `cos(corner_angle_deg)`: a vertex is a corner when the cosine of its
    /// turn is below this.
    corner_cos: f32,
    /// [`BeamConfig::segment_cap`].
    cap: u32,
    pos: Pos,
    /// `pos` in the lit steps' fixed point ([`Dda::fixed`]), kept from the
    /// command that went there rather than converted again.
    fixed: (i32, i32),
    lit: bool,
    plan: Plan,
    ended: bool,
    stats: FrameStats,
}

impl<I: Iterator<Item = Command<ScreenPoint>>> Scheduler<I> {
    /// A scheduler drawing `commands` with `cfg` (sanitized, see
    /// [`BeamConfig::sanitized`]), starting from the park position.
    pub fn new<C>(commands: C, cfg: &BeamConfig) -> Self
    where
        C: IntoIterator<IntoIter = I, Item = Command<ScreenPoint>>,
    {
        let cfg = cfg.sanitized();
        let park = cfg.park_sample();
        Self::with_start(commands, &cfg, ScreenPoint::new(f32::from(park.x), f32::from(park.y)))
    }

    /// A scheduler whose beam starts (blanked and settled) at `start`
    /// instead of the park position, e.g. where the previous frame ended
    /// when [`Park::return_at_end`] is off. A `start` that is not finite
    /// means the park position; it is clamped into range.
    pub fn with_start<C>(commands: C, cfg: &BeamConfig, start: ScreenPoint) -> Self
    where
        C: IntoIterator<IntoIter = I, Item = Command<ScreenPoint>>,
    {
        let cfg = cfg.sanitized();
        let max = f32::from(cfg.max_code());
        let park = cfg.park_sample();
        let start = if start.x.is_finite() && start.y.is_finite() {
            Pos { x: start.x.clamp(0.0, max), y: start.y.clamp(0.0, max) }
        } else {
            Pos { x: f32::from(park.x), y: f32::from(park.y) }
        };
        let corner_cos = libm::cosf(cfg.corner_angle_deg * (core::f32::consts::PI / 180.0));
        let mut src = Clean { src: commands.into_iter(), pen: None, max, skipped: 0 };
        let ahead = src.next_step();
        Self {
            src,
            ahead,
            cap: cfg.segment_cap(),
            cfg,
            corner_cos,
            pos: start,
            fixed: (Dda::fixed(start.x), Dda::fixed(start.y)),
            lit: false,
            plan: Plan { to: start, ..Plan::default() },
            ended: false,
            stats: FrameStats::default(),
        }
    }

    /// The statistics of the samples produced so far; once the iterator has
    /// ended, those of the whole frame.
    pub fn stats(&self) -> FrameStats {
        FrameStats { skipped: self.src.skipped, ..self.stats }
    }

    /// The configuration in use (the sanitized one).
    pub fn config(&self) -> &BeamConfig {
        &self.cfg
    }

    /// Where the beam is headed, in DAC units: the target of the command
    /// being drawn; once the iterator has ended, where the frame left the
    /// beam (the park position with [`Park::return_at_end`]).
    pub fn position(&self) -> ScreenPoint {
        ScreenPoint::new(self.pos.x, self.pos.y)
    }

    #[inline]
    fn code(&self, p: Pos) -> (u16, u16) {
        // A `Pos` is finite and in `0 ..= max` (cleaned, or the park
        // position). Round half away from zero, as `roundf`: `v + 0.5` is
        // exact below 2^22 (codes are at most 65535), and `as` truncates
        // (and saturates, should anything slip through). A few instructions
        // instead of a call: this runs for every command.
        let c = |v: f32| (v + 0.5) as u16;
        (c(p.x), c(p.y))
    }

    /// Pop the lookahead and refill it.
    fn take(&mut self) -> Option<Step> {
        let step = self.ahead.take();
        if step.is_some() {
            self.ahead = self.src.next_step();
        }
        step
    }

    /// A plan that jumps (blanked) to `to`, then dwells `lit` samples there.
    fn jump(&mut self, to: Pos, lit: u16) -> Plan {
        self.fixed = (Dda::fixed(to.x), Dda::fixed(to.y));
        let d = self.pos.distance(to);
        self.stats.blank_length += d;
        Plan {
            to,
            x: Dda::default(),
            y: Dda::default(),
            code: self.code(to),
            blank: self.cfg.settle_samples(d),
            step: 0,
            steps: 0,
            lit,
        }
    }

    /// The plan of the next command, or `None` at the end of the frame.
    fn next_plan(&mut self) -> Option<Plan> {
        loop {
            let plan = match self.take() {
                Some(Step::Start(p)) => {
                    if !matches!(self.ahead, Some(Step::Line(_))) {
                        // Nothing to draw: the beam need not go there.
                        continue;
                    }
                    self.stats.polylines = self.stats.polylines.saturating_add(1);
                    self.jump(p, self.cfg.dwell_start)
                }
                Some(Step::Line(p)) => {
                    let from = self.pos;
                    let length = from.distance(p);
                    self.stats.lit_length += length;
                    let lit = match self.ahead {
                        Some(Step::Line(q)) => {
                            let (ax, ay) = (p.x - from.x, p.y - from.y);
                            let (bx, by) = (q.x - p.x, q.y - p.y);
                            // cos = dot / sqrt(norms) < corner_cos, without
                            // the square root: compare squares, signs apart.
                            let norms = (ax * ax + ay * ay) * (bx * bx + by * by);
                            let dot = ax * bx + ay * by;
                            let c = self.corner_cos;
                            let bound = c * c * norms;
                            // A zero or underflowed product is no corner.
                            let corner = norms > 0.0
                                && if c >= 0.0 {
                                    dot < 0.0 || dot * dot < bound
                                } else {
                                    dot < 0.0 && dot * dot > bound
                                };
                            if corner { self.cfg.corner_dwell } else { 0 }
                        }
                        _ => self.cfg.dwell_end,
                    };
                    let steps = self.cfg.segment_samples_within(length, self.cap);
                    // At most 2^17 / MIN_LIT_STEP + 1 (the cap): an i32.
                    let n = i32::try_from(steps.max(1)).unwrap_or(i32::MAX);
                    let (ax, ay) = self.fixed;
                    let (tx, ty) = (Dda::fixed(p.x), Dda::fixed(p.y));
                    self.fixed = (tx, ty);
                    Plan {
                        to: p,
                        x: Dda::new(ax, tx, n),
                        y: Dda::new(ay, ty, n),
                        code: self.code(p),
                        blank: 0,
                        step: 0,
                        steps,
                        lit,
                    }
                }
                Some(Step::Dot(p)) => {
                    self.stats.points = self.stats.points.saturating_add(1);
                    self.jump(p, self.cfg.point_dwell)
                }
                None => {
                    if self.ended {
                        return None;
                    }
                    self.ended = true;
                    let to = if self.cfg.park.return_at_end {
                        let park = self.cfg.park_sample();
                        Pos { x: f32::from(park.x), y: f32::from(park.y) }
                    } else {
                        self.pos
                    };
                    let mut plan = self.jump(to, 0);
                    if plan.blank == 0 && self.lit {
                        plan.blank = 1;
                    }
                    plan
                }
            };
            self.pos = plan.to;
            return Some(plan);
        }
    }
}

impl<I: Iterator<Item = Command<ScreenPoint>>> Scheduler<I> {
    /// The next samples of the frame, handed to `put` one by one, at most
    /// `max` of them; returns how many. Fewer than `max` only when the frame
    /// has ended. The same samples, statistics and state as taking them
    /// from the iterator one [`next`](Iterator::next) at a time (which is
    /// this for one), which one
    /// may mix with this; but a run of repeated samples (a jump's settle, a
    /// dwell) or a segment's steps costs one loop here, not a state machine
    /// round per sample. The firmware refills its DMA halves this way.
    pub fn fill_with<F: FnMut(Sample)>(&mut self, max: usize, mut put: F) -> usize {
        let mut done = 0usize;
        while done < max {
            let room = max - done;
            let plan = &mut self.plan;
            if plan.blank > 0 {
                let n = usize::from(plan.blank).min(room);
                plan.blank -= n as u16; // n <= blank
                let (x, y) = plan.code;
                let s = Sample::new(x, y, Beam::Off);
                for _ in 0..n {
                    put(s);
                }
                self.ran(n, Beam::Off);
                done += n;
                continue;
            }
            if plan.step < plan.steps {
                let left = plan.steps - plan.step;
                let n = if (left as usize) < room { left } else { room as u32 };
                // The steps before the last in registers (the DDA's state is
                // written back once), then the last, exactly at the target.
                let last = n == left;
                let steps = plan.steps as i32; // at most the cap, an i32
                let (mut x, mut y) = (plan.x, plan.y);
                for _ in 0..n - u32::from(last) {
                    put(Sample::new(x.step(steps), y.step(steps), Beam::On));
                }
                if last {
                    put(Sample::new(plan.code.0, plan.code.1, Beam::On));
                }
                (plan.x, plan.y) = (x, y);
                plan.step += n;
                self.ran(n as usize, Beam::On);
                done += n as usize;
                continue;
            }
            if plan.lit > 0 {
                let n = usize::from(plan.lit).min(room);
                plan.lit -= n as u16; // n <= lit
                let (x, y) = plan.code;
                let s = Sample::new(x, y, Beam::On);
                for _ in 0..n {
                    put(s);
                }
                self.ran(n, Beam::On);
                done += n;
                continue;
            }
            match self.next_plan() {
                Some(plan) => self.plan = plan,
                None => break,
            }
        }
        done
    }

    /// [`Self::fill_with`] into a slice: fills `out` from the start and
    /// returns how many samples it wrote, fewer than `out.len()` only at the
    /// end of the frame.
    pub fn fill(&mut self, out: &mut [Sample]) -> usize {
        let mut slots = out.iter_mut();
        self.fill_with(slots.len(), |s| {
            if let Some(slot) = slots.next() {
                *slot = s;
            }
        })
    }

    /// Run to the end of the frame without making the samples, only
    /// counting them: [`Scheduler::stats`] is then the frame's, as if every
    /// sample had been taken (a few operations a command, not a few a
    /// sample).
    pub fn skip_to_end(&mut self) {
        loop {
            let plan = &mut self.plan;
            let (blank, steps, lit) = (plan.blank, plan.steps - plan.step.min(plan.steps), plan.lit);
            (plan.blank, plan.step, plan.lit) = (0, plan.steps, 0);
            self.ran(usize::from(blank), Beam::Off);
            self.ran(steps as usize, Beam::On);
            self.ran(usize::from(lit), Beam::On);
            match self.next_plan() {
                Some(plan) => self.plan = plan,
                None => break,
            }
        }
    }

    /// Account for `n` samples just emitted with `beam`.
    #[inline(always)]
    fn ran(&mut self, n: usize, beam: Beam) {
        if n > 0 {
            self.lit = beam == Beam::On;
            self.stats.samples += n as u64;
            if self.lit {
                self.stats.lit_samples += n as u64;
            }
        }
    }
}

impl<I: Iterator<Item = Command<ScreenPoint>>> Iterator for Scheduler<I> {
    type Item = Sample;

    /// One sample: [`Scheduler::fill_with`] for one.
    fn next(&mut self) -> Option<Sample> {
        let mut out = None;
        self.fill_with(1, |s| out = Some(s));
        out
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        let p = &self.plan;
        let left = u64::from(p.blank) + u64::from(p.steps - p.step.min(p.steps)) + u64::from(p.lit);
        (usize::try_from(left).unwrap_or(usize::MAX), None)
    }
}

impl<I: Iterator<Item = Command<ScreenPoint>>> core::iter::FusedIterator for Scheduler<I> {}

impl<I: Iterator<Item = Command<ScreenPoint>>> SampleSource for Scheduler<I> {
    #[inline]
    fn fill_with<F: FnMut(Sample)>(&mut self, max: usize, put: F) -> usize {
        Scheduler::fill_with(self, max, put)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::vec::Vec;

    fn m(x: f32, y: f32) -> Command<ScreenPoint> {
        Command::MoveTo(ScreenPoint::new(x, y))
    }
    fn l(x: f32, y: f32) -> Command<ScreenPoint> {
        Command::LineTo(ScreenPoint::new(x, y))
    }
    fn p(x: f32, y: f32) -> Command<ScreenPoint> {
        Command::Point(ScreenPoint::new(x, y))
    }
    fn run(cmds: &[Command<ScreenPoint>], cfg: &BeamConfig) -> Vec<Sample> {
        Scheduler::new(cmds.iter().copied(), cfg).collect()
    }
    fn on(x: u16, y: u16) -> Sample {
        Sample::new(x, y, Beam::On)
    }
    fn off(x: u16, y: u16) -> Sample {
        Sample::new(x, y, Beam::Off)
    }
    /// Runs of equal samples: (sample, count).
    fn runs(samples: &[Sample]) -> Vec<(Sample, usize)> {
        let mut out: Vec<(Sample, usize)> = Vec::new();
        for &s in samples {
            match out.last_mut() {
                Some((last, n)) if *last == s => *n += 1,
                _ => out.push((s, 1)),
            }
        }
        out
    }

    #[test]
    fn defaults_are_valid_and_documented() {
        let d = BeamConfig::default();
        assert_eq!(d.validate(), Ok(()));
        assert_eq!(d.sanitized(), d);
        assert_eq!(d.bits, 12);
        assert_eq!(d.max_code(), 4095);
        assert_eq!(d.lit_step, 16.0);
        assert_eq!((d.settle_base, d.settle_per_lsb, d.settle_max), (2.0, 1.0 / 256.0, 32));
        assert_eq!((d.dwell_start, d.dwell_end, d.corner_dwell, d.point_dwell), (2, 1, 1, 4));
        assert_eq!(d.corner_angle_deg, 60.0);
        assert_eq!(d.park, Park { x: 0, y: 0, return_at_end: true });
        // Full-scale jump: 2 + 16 samples; the diagonal 2 + 22.6 -> 25.
        assert_eq!(d.settle_samples(4096.0), 18);
        assert_eq!(d.settle_samples(4095.0 * core::f32::consts::SQRT_2), 25);
        assert_eq!(d.settle_samples(1.0), 3);
        assert_eq!(d.segment_cap(), 513);
    }

    #[test]
    fn validate_rejects_each_bad_field() {
        let d = BeamConfig::default();
        let bad = |c: BeamConfig| c.validate().unwrap_err();
        assert_eq!(bad(BeamConfig { bits: 0, ..d }), BeamConfigError::Bits { bits: 0 });
        assert_eq!(bad(BeamConfig { bits: 17, ..d }), BeamConfigError::Bits { bits: 17 });
        for s in [0.0, -1.0, f32::NAN, f32::INFINITY, MIN_LIT_STEP / 2.0] {
            assert_eq!(bad(BeamConfig { lit_step: s, ..d }), BeamConfigError::LitStep);
        }
        assert_eq!(bad(BeamConfig { settle_base: -0.5, ..d }), BeamConfigError::SettleBase);
        assert_eq!(bad(BeamConfig { settle_per_lsb: f32::NAN, ..d }), BeamConfigError::SettlePerLsb);
        assert_eq!(bad(BeamConfig { dwell_start: 0, ..d }), BeamConfigError::DwellStart);
        assert_eq!(bad(BeamConfig { point_dwell: 0, ..d }), BeamConfigError::PointDwell);
        assert_eq!(bad(BeamConfig { corner_angle_deg: 181.0, ..d }), BeamConfigError::CornerAngle);
        assert_eq!(bad(BeamConfig { corner_angle_deg: f32::NAN, ..d }), BeamConfigError::CornerAngle);
        let park = Park { x: 4096, y: 0, return_at_end: true };
        assert_eq!(bad(BeamConfig { park, ..d }), BeamConfigError::Park { x: 4096, y: 0 });
        assert!(BeamConfig { bits: 16, park: Park { x: u16::MAX, ..park }, ..d }.validate().is_ok());
        assert!(BeamConfig { lit_step: MIN_LIT_STEP, ..d }.validate().is_ok());
        // Every error says what is wrong.
        assert!(std::format!("{}", BeamConfigError::Bits { bits: 0 }).contains("0 bits"));
        assert!(std::format!("{}", BeamConfigError::Park { x: 1, y: 2 }).contains("(1, 2)"));
    }

    #[test]
    fn sanitized_is_valid_for_garbage() {
        let garbage = BeamConfig {
            bits: 200,
            lit_step: 1e-30,
            settle_base: f32::NEG_INFINITY,
            settle_per_lsb: -3.0,
            settle_max: 0,
            dwell_start: 0,
            dwell_end: 0,
            corner_dwell: 0,
            corner_angle_deg: -5.0,
            point_dwell: 0,
            park: Park { x: u16::MAX, y: 7, return_at_end: false },
        };
        let s = garbage.sanitized();
        assert_eq!(s.validate(), Ok(()));
        assert_eq!((s.bits, s.lit_step, s.corner_angle_deg), (16, MIN_LIT_STEP, 0.0));
        assert_eq!((s.settle_base, s.settle_per_lsb), (2.0, 1.0 / 256.0));
        assert_eq!((s.dwell_start, s.point_dwell), (1, 1));
        let s = BeamConfig { bits: 0, lit_step: f32::NAN, ..garbage }.sanitized();
        assert_eq!(s.validate(), Ok(()));
        assert_eq!((s.bits, s.lit_step, s.park.x), (1, 16.0, 1));
    }

    #[test]
    fn exact_samples_of_a_polyline_with_a_corner() {
        let cfg = BeamConfig {
            bits: 6,
            lit_step: 4.0,
            settle_base: 1.0,
            settle_per_lsb: 0.25,
            settle_max: 10,
            dwell_start: 2,
            dwell_end: 3,
            corner_dwell: 1,
            corner_angle_deg: 45.0,
            point_dwell: 2,
            park: Park { x: 0, y: 0, return_at_end: true },
        };
        let s = run(&[m(8.0, 0.0), l(16.0, 0.0), l(16.0, 4.0), p(20.0, 4.0)], &cfg);
        let want = [
            off(8, 0),
            off(8, 0),
            off(8, 0), // |(8,0)| = 8: ceil(1 + 2) = 3
            on(8, 0),
            on(8, 0), // dwell_start
            on(12, 0),
            on(16, 0), // 8 LSB in 2 steps
            on(16, 0), // a 90 degree corner
            on(16, 4), // 4 LSB in 1 step
            on(16, 4),
            on(16, 4),
            on(16, 4), // dwell_end
            off(20, 4),
            off(20, 4), // jump of 4: ceil(1 + 1) = 2
            on(20, 4),
            on(20, 4), // point_dwell
            off(0, 0),
            off(0, 0),
            off(0, 0),
            off(0, 0),
            off(0, 0),
            off(0, 0), // back to park: |(20,4)| = 20.4: ceil(1 + 5.1) = 7
            off(0, 0),
        ];
        assert_eq!(s, want);
        let st = frame_stats([m(8.0, 0.0), l(16.0, 0.0), l(16.0, 4.0), p(20.0, 4.0)], &cfg);
        assert_eq!((st.polylines, st.points, st.skipped), (1, 1, 0));
        assert_eq!(st.lit_length, 12.0);
        assert!((st.blank_length - (8.0 + 4.0 + 416f32.sqrt())).abs() < 1e-4);
        assert_eq!((st.samples, st.lit_samples, st.blank_samples()), (23, 11, 12));
        assert_eq!(st.fps(23_000.0), 1000.0);
    }

    #[test]
    fn empty_frames() {
        let d = BeamConfig::default();
        assert!(run(&[], &d).is_empty());
        // Bare moves, NaN and zero-length lines draw nothing at all.
        let nothing = [m(100.0, 100.0), m(5.0, 5.0), l(5.0, 5.0), l(f32::NAN, 1.0), m(9.0, f32::INFINITY)];
        assert!(run(&nothing, &d).is_empty());
        let st = frame_stats(nothing, &d);
        assert_eq!(st, FrameStats { skipped: 2, ..FrameStats::default() });
        assert_eq!(st.fps(1e6), 0.0);
        // Starting elsewhere, the empty frame still returns to park.
        let s: Vec<Sample> =
            Scheduler::with_start(core::iter::empty(), &d, ScreenPoint::new(4095.0, 0.0)).collect();
        assert_eq!(s, std::vec![off(0, 0); 18]);
    }

    #[test]
    fn frame_ends_blanked_in_place_without_return() {
        let cfg = BeamConfig { park: Park { x: 0, y: 0, return_at_end: false }, ..BeamConfig::default() };
        let mut sch = Scheduler::new([p(100.0, 200.0)], &cfg);
        let s: Vec<Sample> = sch.by_ref().collect();
        assert_eq!(s.last(), Some(&off(100, 200)));
        assert_eq!(s.iter().filter(|s| s.beam == Beam::On).count(), 4);
        assert_eq!(sch.position(), ScreenPoint::new(100.0, 200.0));
        assert_eq!(sch.next(), None);
        // Chaining: the next frame starts from there; a dot at the same
        // place needs no jump.
        let s: Vec<Sample> = Scheduler::with_start([p(100.0, 200.0)], &cfg, sch.position()).collect();
        assert_eq!(s, [on(100, 200), on(100, 200), on(100, 200), on(100, 200), off(100, 200)]);
    }

    #[test]
    fn settle_grows_with_jump_length() {
        let d = BeamConfig::default();
        let mut last = 0;
        let stay = BeamConfig { park: Park { return_at_end: false, ..d.park }, ..d };
        for len in [0.5f32, 1.0, 100.0, 256.0, 1000.0, 2048.0, 3000.0, 4095.0] {
            let s = run(&[p(len, 0.0)], &stay);
            let blank_before = s.iter().take_while(|s| s.beam == Beam::Off).count();
            assert_eq!(blank_before, usize::from(d.settle_samples(len)), "jump of {len}");
            assert!(blank_before >= last, "settle shrank at {len}");
            last = blank_before;
        }
        // The diagonal, the longest jump: 2 + 22.6 -> 25.
        let s = run(&[p(4095.0, 4095.0)], &stay);
        assert_eq!(s.iter().take_while(|s| s.beam == Beam::Off).count(), 25);
        assert_eq!(d.settle_samples(0.0), 0);
        assert_eq!(d.settle_samples(0.5), 3);
        assert_eq!(d.settle_samples(1000.0), 6);
        assert_eq!(d.settle_samples(4096.0), 18);
        // The cap.
        let steep = BeamConfig { settle_per_lsb: 1.0, ..d };
        assert_eq!(steep.settle_samples(4096.0), 32);
        assert_eq!(BeamConfig { settle_max: 0, ..steep }.settle_samples(4096.0), 1);
        assert_eq!(d.settle_samples(f32::INFINITY), 32);
        assert_eq!(d.settle_samples(f32::NAN), 0);
    }

    #[test]
    fn corner_dwell_only_at_sharp_corners() {
        // lit_step 10.5 and 10-LSB segments: one sample per segment, so a
        // run of two equal lit samples in the middle is a corner dwell.
        let cfg = BeamConfig { lit_step: 10.5, ..BeamConfig::default() };
        let dwell_at = |cmds: &[Command<ScreenPoint>]| -> Vec<usize> {
            runs(&run(cmds, &cfg)).iter().filter(|(s, _)| s.beam == Beam::On).map(|&(_, n)| n).collect()
        };
        // Straight on: dwell_start (2) at the start, 1 + dwell_end (1) at the end.
        let straight = [m(100.0, 100.0), l(110.0, 100.0), l(120.0, 100.0), l(130.0, 100.0)];
        assert_eq!(dwell_at(&straight), [2, 1, 1, 2]);
        // A 30 degree bend: not a corner.
        let c30 = libm::cosf(30f32.to_radians()) * 10.0;
        let s30 = libm::sinf(30f32.to_radians()) * 10.0;
        let bend = [m(100.0, 100.0), l(110.0, 100.0), l(110.0 + c30, 100.0 + s30)];
        assert_eq!(dwell_at(&bend), [2, 1, 2]);
        // Turns of 90 and 135 degrees: corners (1 + corner_dwell samples).
        let square = [m(100.0, 100.0), l(110.0, 100.0), l(110.0, 110.0), l(100.0, 110.0)];
        assert_eq!(dwell_at(&square), [2, 2, 2, 2]);
        let sharp = [m(100.0, 100.0), l(110.0, 100.0), l(100.0, 100.0 + 1e-3)];
        assert_eq!(dwell_at(&sharp), [2, 2, 2]);
        // A U-turn.
        let back = [m(100.0, 100.0), l(110.0, 100.0), l(100.0, 100.0)];
        assert_eq!(dwell_at(&back), [2, 2, 2]);
        // Threshold 180: never a corner; 0: every bend.
        let never = BeamConfig { corner_angle_deg: 180.0, ..cfg };
        assert_eq!(run(&back, &never).iter().filter(|s| s.beam == Beam::On).count(), 5);
        let always = BeamConfig { corner_angle_deg: 0.0, ..cfg };
        assert_eq!(run(&bend, &always).iter().filter(|s| s.beam == Beam::On).count(), 6);
    }

    #[test]
    fn constant_speed_and_exact_end_points() {
        let cfg = BeamConfig { lit_step: 16.0, ..BeamConfig::default() };
        // 100 LSB: ceil(100 / 16) = 7 steps of 14.29.
        let s = run(&[m(1000.0, 1000.0), l(1100.0, 1000.0)], &cfg);
        let lit: Vec<u16> = s.iter().filter(|s| s.beam == Beam::On).map(|s| s.x).collect();
        assert_eq!(lit, [1000, 1000, 1014, 1029, 1043, 1057, 1071, 1086, 1100, 1100]);
        // Sub-LSB end points are rounded to the nearest code, half away.
        let s = run(&[m(10.4, 10.5), l(30.6, 10.5)], &cfg);
        let lit: Vec<Sample> = s.into_iter().filter(|s| s.beam == Beam::On).collect();
        assert_eq!(lit.first(), Some(&on(10, 11)));
        assert_eq!(lit.last(), Some(&on(31, 11)));
        assert_eq!(lit.len(), 2 + 2 + 1);
    }

    #[test]
    fn out_of_range_and_non_finite_points() {
        let cfg =
            BeamConfig { bits: 8, lit_step: 1000.0, dwell_start: 1, dwell_end: 0, ..BeamConfig::default() };
        // Clamped: a line from far left to far right along y = 300 (> 255).
        let s = run(&[m(-1e30, 300.0), l(f32::MAX, 300.0)], &cfg);
        let lit: Vec<Sample> = s.into_iter().filter(|s| s.beam == Beam::On).collect();
        assert_eq!(lit, [on(0, 255), on(255, 255)]);
        // A NaN in the middle of a polyline breaks it: no line to or from it.
        let s = run(&[m(0.0, 0.0), l(10.0, 0.0), l(f32::NAN, 5.0), l(20.0, 0.0), l(30.0, 0.0)], &cfg);
        let st = frame_stats([m(0.0, 0.0), l(10.0, 0.0), l(f32::NAN, 5.0), l(20.0, 0.0), l(30.0, 0.0)], &cfg);
        let lit: Vec<Sample> = s.into_iter().filter(|s| s.beam == Beam::On).collect();
        assert_eq!(lit, [on(0, 0), on(10, 0), on(20, 0), on(30, 0)]);
        assert_eq!((st.polylines, st.skipped, st.lit_length), (2, 1, 20.0));
        // A LineTo after a Point starts a new polyline at its own point.
        let st = frame_stats([p(5.0, 5.0), l(15.0, 5.0), l(25.0, 5.0)], &cfg);
        assert_eq!((st.points, st.polylines, st.lit_length), (1, 1, 10.0));
    }

    #[test]
    fn park_samples_are_blanked() {
        let cfg = BeamConfig { park: Park { x: 9000, y: 7, return_at_end: true }, ..BeamConfig::default() };
        let idle: Vec<Sample> = park_samples(&cfg, 3).collect();
        assert_eq!(idle, [off(4095, 7); 3]);
        assert_eq!(park_samples(&cfg, 0).count(), 0);
    }

    #[test]
    fn stats_accumulate_while_running() {
        let cmds = [m(0.0, 100.0), l(160.0, 100.0)];
        let mut sch = Scheduler::new(cmds, &BeamConfig::default());
        assert_eq!(sch.stats(), FrameStats::default());
        let first = sch.next();
        assert_eq!(first.map(|s| s.beam), Some(Beam::Off));
        assert_eq!((sch.stats().samples, sch.stats().polylines, sch.stats().blank_length), (1, 1, 100.0));
        let rest = sch.by_ref().count() as u64;
        let st = sch.stats();
        assert_eq!(st.samples, rest + 1);
        assert_eq!(st.lit_samples, 2 + 10 + 1);
        assert_eq!(st.lit_length, 160.0);
        assert!((st.blank_length - (100.0 + libm::sqrtf(160.0 * 160.0 + 100.0 * 100.0))).abs() < 1e-3);
        assert_eq!(st, frame_stats(cmds, &BeamConfig::default()));
    }
}
