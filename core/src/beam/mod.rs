//! The beam scheduler: drawing commands in display order in, DAC samples out.
//!
//! Here: the beam's configuration ([`BeamConfig`], [`Park`]) and the park
//! samples; the [`Scheduler`] itself; what a frame costs ([`FrameStats`],
//! [`frame_stats`]); and [`pace`], slowing the sample clock to what the
//! refill keeps up with.
//!
//! [`Scheduler`] turns a stream of
//! [`Command<ScreenPoint>`](crate::command::Command)s into a stream of
//! [`Sample`]s, one per DAC tick, without storing either: it holds one
//! command of lookahead (to know whether a polyline ends or turns a corner
//! at the vertex it is drawing towards) and the few counters of the command
//! it is expanding.
//!
//! # Input
//!
//! Commands come in display order, in DAC units (see
//! [`ScreenPoint`](crate::view::ScreenPoint)):
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
//!   `L > 0`: the beam runs along the polyline at `lit_step` LSB a sample
//!   (constant speed, hence even brightness), and a lit sample falls
//!   wherever the path since the last lit sample reaches `lit_step`:
//!   steps are measured along the path across vertices, so a segment
//!   shorter than a step takes no sample of its own. A **run** of the path
//!   goes from a polyline's start, or a corner, to the next corner or the
//!   polyline's end; it takes `ceil(T / lit_step)` lit samples for its
//!   length `T`, every `lit_step` along it and the last exactly at its end.
//!   At `p`:
//!   - if the next command continues the polyline with a `LineTo(q)` and the
//!     direction turns by at most `corner_angle_deg` at `p` (the angle
//!     between `p - a` and `q - p`), the run goes on: no sample of its own
//!     at `p` unless a step falls there;
//!   - if it turns by more, `p` is a corner: the run ends with a sample at
//!     `p` and `corner_dwell` more, and the next run's first step is a
//!     whole `lit_step` on;
//!   - if the polyline ends at `p` (the next command is not a `LineTo`, or
//!     there is none): a sample at `p` and `dwell_end` more.
//!
//!   With [`Spacing::Constant`] (for audio rates) a corner does not end
//!   the run: the steps go on every `lit_step` along the whole polyline,
//!   a vertex gets no sample of its own, and only the polyline's end does
//!   (and `dwell_end` more); with a `corner_dwell` above 0 a corner still
//!   gets a sample and its dwell, but the next step falls where it would
//!   have without them. A polyline of length `T` then takes `ceil(T /
//!   lit_step)` lit samples besides its dwells, wherever its vertices are
//!   ([`fit_spacing`] picks the `lit_step` that fits a frame into a number
//!   of samples).
//!
//!   Positions are computed in fixed point (1/32768 LSB; each step
//!   truncated toward the segment's start, so the `k`-th step of a segment
//!   lags its exact place by less than `k` / 32768 LSB, under 0.015 LSB at
//!   the default beam), an add a coordinate a sample.
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
//! Off×settle(|a - start|) at a, On×2 at a, On×(ceil(|b-a|/16) - 1) towards
//! b, On×2 at b, On×(ceil(|c-b|/16) - 1) towards c, On×2 at c, ...
//! ```
//!
//! **Lit samples trace exactly the display list.** Before rounding, every
//! lit position is on an input segment (or is an input point), so every lit
//! sample lies within `sqrt(2)/2` LSB of one (and the steps' lag above);
//! every input segment of non-zero length (after cleaning) is
//! covered: each of its points is within `lit_step / 2` of the path's
//! nearest lit sample, consecutive ones at most `lit_step + sqrt(2)` LSB
//! apart after rounding. Corners, starts and ends are sampled exactly;
//! across a gentle bend the beam's straight step cuts the vertex by at
//! most `lit_step / 4 * sin(corner_angle_deg)` (about 3.5 LSB at the
//! defaults, under the amplifiers' own lag). Blanked samples only ever sit
//! at targets (points of the input, or the park position).
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

pub mod pace;
pub mod replay;
mod scheduler;
mod stats;

pub use scheduler::{LitSteps, Scheduler};
pub use stats::{FrameStats, fit_spacing, frame_stats};

use crate::fastmath::ceil;
use crate::output::{Beam, Sample};

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
    /// Largest step between consecutive lit samples, in LSB along the path
    /// (`>=` [`MIN_LIT_STEP`], finite). It sets the beam speed, hence the
    /// line brightness: a run of path of length `T` (from a start or corner
    /// to the next corner or end) takes `ceil(T / lit_step)` samples.
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
    /// Lit samples for a [`Command::Point`](crate::command::Command::Point)
    /// (`>= 1`).
    pub point_dwell: u16,
    /// The park position and whether frames return there.
    pub park: Park,
    /// How lit samples are spaced along a polyline: [`Spacing::PerRun`]
    /// (a run of steps ends at every corner, for a scope's DAC) or
    /// [`Spacing::Constant`] (one even spacing along the whole polyline,
    /// for a sound card).
    pub spacing: Spacing,
}

/// How the scheduler spaces a polyline's lit samples (see the [module
/// docs](self)).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Spacing {
    /// Runs: a sample every `lit_step` along the path from a polyline's
    /// start or a corner to the next corner or its end, where a sample
    /// falls exactly (and [`BeamConfig::corner_dwell`] more), so corners
    /// stay sharp on a fast scope. A run of length `T` takes
    /// `ceil(T / lit_step)` samples. The default, and the firmware's.
    #[default]
    PerRun,
    /// Constant: a sample every `lit_step` along the whole polyline,
    /// across its corners, and one at its end; a vertex gets no sample of
    /// its own unless [`BeamConfig::corner_dwell`] is above 0 and it is a
    /// corner (a sample there and its dwell, the steps' spacing going on
    /// from where it was). A polyline of length `T` takes `ceil(T /
    /// lit_step)` lit samples besides its dwells, at most `lit_step`
    /// apart along the path. For audio rates: a sound card's low-pass
    /// (about 0.45 times its rate) rounds corners anyway, and samples go
    /// where the path is, not where its vertices are, so the frame lasts
    /// its length over `lit_step` (see [`fit_spacing`]).
    Constant,
}

impl Default for BeamConfig {
    /// Defaults for a ~1 MHz-bandwidth XY scope and a 12-bit DAC at 1 MS/s:
    ///
    /// - `bits: 12`.
    /// - `lit_step: 17.0`: 17 LSB/µs, a full-screen line in 241 µs. A spot of
    ///   ~0.5 mm on a 10 cm screen is ~20 LSB wide, so consecutive samples
    ///   overlap and lines look solid, while the amplifiers (time constant
    ///   ~0.16 µs) lag the beam by only ~3 LSB, so corners stay sharp. An
    ///   18 ms frame (55 Hz, flicker-free on P31 phosphor) has room for
    ///   ~306,000 LSB of line, about 75 screen widths, less jumps and
    ///   dwells: the paper's hydrogen 32^3 (289,000 LSB at the default view)
    ///   plays at 57.7 Hz, where 16 LSB would give 54.4.
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
    /// - `spacing`: [`Spacing::PerRun`].
    fn default() -> Self {
        Self {
            bits: 12,
            lit_step: 17.0,
            settle_base: 2.0,
            settle_per_lsb: 1.0 / 256.0,
            settle_max: 32,
            dwell_start: 2,
            dwell_end: 1,
            corner_dwell: 1,
            corner_angle_deg: 60.0,
            point_dwell: 4,
            park: Park::default(),
            spacing: Spacing::PerRun,
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
            spacing: self.spacing,
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

    /// The lit samples one run of path (from a start or corner to the next
    /// corner or end) of `length` LSB takes: `ceil(length / lit_step)`, at
    /// least 1 for a positive length, 0 for zero (or NaN), capped at
    /// `floor(2^(bits+1) / lit_step) + 1`.
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

    /// The most lit steps one segment may take:
    /// `floor(2^(bits+1) / lit_step) + 1` (more than the screen's diagonal
    /// needs: a guard against float accidents only).
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

#[cfg(test)]
mod tests {
    use super::*;
    use std::vec::Vec;

    fn off(x: u16, y: u16) -> Sample {
        Sample::new(x, y, Beam::Off)
    }

    #[test]
    fn defaults_are_valid_and_documented() {
        let d = BeamConfig::default();
        assert_eq!(d.validate(), Ok(()));
        assert_eq!(d.sanitized(), d);
        assert_eq!(d.bits, 12);
        assert_eq!(d.max_code(), 4095);
        assert_eq!(d.lit_step, 17.0);
        assert_eq!((d.settle_base, d.settle_per_lsb, d.settle_max), (2.0, 1.0 / 256.0, 32));
        assert_eq!((d.dwell_start, d.dwell_end, d.corner_dwell, d.point_dwell), (2, 1, 1, 4));
        assert_eq!(d.corner_angle_deg, 60.0);
        assert_eq!(d.park, Park { x: 0, y: 0, return_at_end: true });
        assert_eq!(d.spacing, Spacing::PerRun);
        // Full-scale jump: 2 + 16 samples; the diagonal 2 + 22.6 -> 25.
        assert_eq!(d.settle_samples(4096.0), 18);
        assert_eq!(d.settle_samples(4095.0 * core::f32::consts::SQRT_2), 25);
        assert_eq!(d.settle_samples(1.0), 3);
        assert_eq!(d.segment_cap(), 482);
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
            spacing: Spacing::Constant,
        };
        let s = garbage.sanitized();
        assert_eq!(s.validate(), Ok(()));
        assert_eq!((s.bits, s.lit_step, s.corner_angle_deg), (16, MIN_LIT_STEP, 0.0));
        assert_eq!((s.settle_base, s.settle_per_lsb), (2.0, 1.0 / 256.0));
        assert_eq!((s.dwell_start, s.point_dwell, s.spacing), (1, 1, Spacing::Constant));
        let s = BeamConfig { bits: 0, lit_step: f32::NAN, ..garbage }.sanitized();
        assert_eq!(s.validate(), Ok(()));
        assert_eq!((s.bits, s.lit_step, s.park.x), (1, 17.0, 1));
    }

    #[test]
    fn park_samples_are_blanked() {
        let cfg = BeamConfig { park: Park { x: 9000, y: 7, return_at_end: true }, ..BeamConfig::default() };
        let idle: Vec<Sample> = park_samples(&cfg, 3).collect();
        assert_eq!(idle, [off(4095, 7); 3]);
        assert_eq!(park_samples(&cfg, 0).count(), 0);
    }
}
