//! The beam scheduler itself: [`Scheduler`], commands in, samples out, as
//! the [module docs](super) describe.

use super::{BeamConfig, FrameStats, Spacing};
use crate::command::Command;
use crate::fastmath::{sqrt, sqrt_recip};
use crate::output::{Beam, Each, RunSink, Sample, SampleSource, Steps};
use crate::view::ScreenPoint;

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
/// target, then lit steps along the segment from the previous position,
/// then lit samples at the target.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
struct Plan {
    to: Pos,
    /// The lit steps' positions.
    walk: LitSteps,
    /// `to` rounded to DAC codes.
    code: (u16, u16),
    blank: u16,
    step: u32,
    steps: u32,
    /// Lit samples at `to`: the sample that ends a run (a corner or the
    /// polyline's end) and its dwell, or a start's or a dot's dwell.
    lit: u32,
}

/// Fractional bits of the fixed-point positions of lit steps: a code of up
/// to 16 bits and 15 fractional bits fit an `i32` with room for rounding.
const FRAC: u32 = 15;

/// `2^FRAC`, to scale a position into fixed point.
const ONE: f32 = (1u32 << FRAC) as f32;

/// One coordinate of a segment's lit steps, in fixed point: a step is an
/// add. The step and the first offset are truncated toward the segment's
/// start, so the steps never pass its end and lag their exact places by
/// at most one 1/32768 LSB a step (under 0.015 LSB over the longest
/// segment at the default beam); two registers a coordinate, so the
/// refill's loop keeps its state in registers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
struct Walk {
    /// Position of the next step, fixed point.
    at: i32,
    /// The step, fixed point.
    q: i32,
}

impl Walk {
    /// `v` (finite, in `0 ..= 65535`) in fixed point, rounded.
    #[inline]
    fn fixed(v: f32) -> i32 {
        (v * ONE + 0.5) as i32
    }

    /// Steps along `d` (the segment's extent along this axis, fixed point)
    /// from `at`: the first `first` of the way (in 1/2^31 of the segment),
    /// the others `step` apart. A multiplication each (`SMULL`). The
    /// fractions are at most 1 (`i32::MAX`) while a step lies on the
    /// segment, and the products are truncated toward zero, so the steps
    /// stay on the segment.
    #[inline]
    fn new(at: i32, d: i32, first: i32, step: i32) -> Self {
        // |d * fraction| < 2^62; the quotients fit an i32 (at most |d|
        // while the fraction is at most 1).
        let part = |f: i32| ((i64::from(d) * i64::from(f)) / (1 << 31)) as i32;
        Self { at: at.wrapping_add(part(first)), q: part(step) }
    }

    /// `v` (a fraction of a segment, `0 ..= 1` but for rounding) in 1/2^31:
    /// `as` saturates, so 1 and a hair above become `i32::MAX`.
    #[inline]
    fn ratio(v: f32) -> i32 {
        (v * 2_147_483_648.0) as i32
    }

    /// The code of the current step (rounded half up), then advance. The
    /// steps stay on the segment, so the code is within the DAC range (the
    /// add after a segment's last step may wrap: it is never drawn).
    #[inline(always)]
    fn step(&mut self) -> u16 {
        let code = (self.at.wrapping_add(1 << (FRAC - 1)) >> FRAC) as u16;
        self.at = self.at.wrapping_add(self.q);
        code
    }
}

/// A run of lit samples along one straight segment, as
/// [`Scheduler::fill_runs`] hands it to a [`RunSink`]: [`Steps::step`]
/// gives each sample's codes, an add and a shift a coordinate, so a DMA
/// refill writes the run in a loop of its own.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LitSteps {
    x: Walk,
    y: Walk,
}

impl Steps for LitSteps {
    #[inline(always)]
    fn step(&mut self) -> (u16, u16) {
        (self.x.step(), self.y.step())
    }
}

/// The beam scheduler: an iterator of DAC [`Sample`]s drawing a stream of
/// commands. See the [module docs](super) for the exact semantics.
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
    /// turn is below this (-2, never, for [`Spacing::Constant`] without a
    /// corner dwell: its corners take no sample).
    corner_cos: f32,
    /// [`Spacing::Constant`]: the steps' spacing goes on across a corner's
    /// sample rather than starting again after it.
    keep_phase: bool,
    /// [`BeamConfig::segment_cap`].
    cap: u32,
    /// `1 / lit_step`.
    per_lsb: f32,
    pos: Pos,
    /// `pos` in the lit steps' fixed point ([`Walk::fixed`]), kept from the
    /// command that went there rather than converted again.
    fixed: (i32, i32),
    /// How far along the path from `pos` the next lit step falls, in
    /// `(0, lit_step]` (a full step after a run's start or end).
    ahead_by: f32,
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
    /// when [`Park::return_at_end`](super::Park::return_at_end) is off. A
    /// `start` that is not finite means the park position; it is clamped
    /// into range.
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
        let keep_phase = cfg.spacing == Spacing::Constant;
        let corner_cos = if keep_phase && cfg.corner_dwell == 0 {
            // Below any cosine: no vertex is a corner.
            -2.0
        } else {
            libm::cosf(cfg.corner_angle_deg * (core::f32::consts::PI / 180.0))
        };
        let mut src = Clean { src: commands.into_iter(), pen: None, max, skipped: 0 };
        let ahead = src.next_step();
        Self {
            src,
            ahead,
            cap: cfg.segment_cap(),
            per_lsb: 1.0 / cfg.lit_step,
            ahead_by: cfg.lit_step,
            cfg,
            corner_cos,
            keep_phase,
            pos: start,
            fixed: (Walk::fixed(start.x), Walk::fixed(start.y)),
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
    /// beam (the park position with
    /// [`Park::return_at_end`](super::Park::return_at_end)).
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
        self.fixed = (Walk::fixed(to.x), Walk::fixed(to.y));
        self.ahead_by = self.cfg.lit_step;
        let d = self.pos.distance(to);
        self.stats.blank_length += d;
        Plan {
            to,
            walk: LitSteps::default(),
            code: self.code(to),
            blank: self.cfg.settle_samples(d),
            step: 0,
            steps: 0,
            lit: u32::from(lit),
        }
    }

    /// The lit steps along the segment from the beam's position to `p`
    /// (`length` LSB away, `inv` about `1 / length`, `(dx, dy) = p - pos`):
    /// one wherever the path since the last lit sample reaches `lit_step`,
    /// strictly before `p` if the run ends at `p` (its sample there is the
    /// plan's `lit`), up to `p` itself otherwise. Sets where the next step
    /// falls and the fixed-point position of `p`.
    fn steps_to(&mut self, p: Pos, length: f32, inv: f32, run_ends: bool) -> (u32, LitSteps) {
        let (s, first) = (self.cfg.lit_step, self.ahead_by);
        let (ax, ay) = self.fixed;
        let (tx, ty) = (Walk::fixed(p.x), Walk::fixed(p.y));
        self.fixed = (tx, ty);
        // Steps at `first + k s <= length` for `k < n`; `next`, where step
        // `n` falls, is beyond: the next segment's first step is there.
        // Counted by a multiplication, then made exact in the float
        // arithmetic (the estimate is off by one at most).
        let (mut n, mut next) = if first <= length {
            // `as` saturates: a float accident counts at most u32::MAX,
            // capped below.
            let n = (((length - first) * self.per_lsb) as u32).saturating_add(1);
            (n, first + n as f32 * s)
        } else {
            (0, first)
        };
        if n > 0 && next - s > length {
            n -= 1;
            next -= s;
        } else if next <= length {
            n += 1;
            next += s;
        }
        self.ahead_by = next - length;
        if run_ends {
            // The run's end sample is at `p`: not twice.
            if n > 0 && next - s >= length {
                n -= 1;
            }
            // A new run starts a whole step on; with constant spacing the
            // steps go on where they fall (a polyline's end is followed by
            // a jump, which starts them again).
            if !self.keep_phase {
                self.ahead_by = s;
            }
        }
        let n = n.min(self.cap);
        if n == 0 {
            return (0, LitSteps::default());
        }
        // Fractions of the segment: the first step's and a step's (at most
        // 1 when there is a second step).
        let (f0, f) = (Walk::ratio(first * inv), Walk::ratio(s * inv));
        // Fixed-point positions are at most 2^31 - 2^15: differences fit.
        let x = Walk::new(ax, tx.wrapping_sub(ax), f0, f);
        (n, LitSteps { x, y: Walk::new(ay, ty.wrapping_sub(ay), f0, f) })
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
                    let (dx, dy) = (p.x - from.x, p.y - from.y);
                    let (length, inv) = sqrt_recip(dx * dx + dy * dy);
                    self.stats.lit_length += length;
                    // Whether the run of steps ends at `p`, and the lit
                    // samples there if so.
                    let end = match self.ahead {
                        Some(Step::Line(q)) => {
                            let (bx, by) = (q.x - p.x, q.y - p.y);
                            // cos = dot / sqrt(norms) < corner_cos, without
                            // the square root: compare squares, signs apart.
                            let norms = (dx * dx + dy * dy) * (bx * bx + by * by);
                            let dot = dx * bx + dy * by;
                            let c = self.corner_cos;
                            let bound = c * c * norms;
                            // A zero or underflowed product is no corner.
                            let corner = norms > 0.0
                                && if c >= 0.0 {
                                    dot < 0.0 || dot * dot < bound
                                } else {
                                    dot < 0.0 && dot * dot > bound
                                };
                            corner.then_some(self.cfg.corner_dwell)
                        }
                        _ => Some(self.cfg.dwell_end),
                    };
                    let (steps, walk) = self.steps_to(p, length, inv, end.is_some());
                    Plan {
                        to: p,
                        walk,
                        code: self.code(p),
                        blank: 0,
                        step: 0,
                        steps,
                        lit: end.map_or(0, |dwell| u32::from(dwell) + 1),
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
    /// this for one), which one may mix with this: [`Self::fill_runs`]
    /// with a sink that hands each sample of a run to `put`.
    pub fn fill_with<F: FnMut(Sample)>(&mut self, max: usize, put: F) -> usize {
        self.fill_runs(max, &mut Each(put))
    }

    /// The next samples of the frame as runs handed to `sink`, at most
    /// `max` samples; returns how many. Fewer than `max` only when the
    /// frame has ended. A run of repeated samples (a jump's settle, a
    /// dwell) is one [`RunSink::repeat`] and a segment's steps one
    /// [`RunSink::steps`], not a state machine round per sample: the
    /// firmware refills its DMA halves this way, a loop per run.
    pub fn fill_runs<R: RunSink>(&mut self, max: usize, sink: &mut R) -> usize {
        let mut done = 0usize;
        while done < max {
            let room = max - done;
            let plan = &mut self.plan;
            if plan.blank > 0 {
                let n = usize::from(plan.blank).min(room);
                plan.blank -= n as u16; // n <= blank
                let (x, y) = plan.code;
                sink.repeat(Sample::new(x, y, Beam::Off), n);
                self.ran(n, Beam::Off);
                done += n;
                continue;
            }
            if plan.step < plan.steps {
                let left = plan.steps - plan.step;
                let n = if (left as usize) < room { left } else { room as u32 };
                sink.steps(&mut plan.walk, n as usize);
                plan.step += n;
                self.ran(n as usize, Beam::On);
                done += n as usize;
                continue;
            }
            if plan.lit > 0 {
                let n = (plan.lit as usize).min(room);
                plan.lit -= n as u32; // n <= lit
                let (x, y) = plan.code;
                sink.repeat(Sample::new(x, y, Beam::On), n);
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
            self.ran(lit as usize, Beam::On);
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
        self.next_sample()
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

    #[inline]
    fn fill_runs<R: RunSink>(&mut self, max: usize, sink: &mut R) -> usize {
        Scheduler::fill_runs(self, max, sink)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::beam::{Park, frame_stats};
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
            spacing: Spacing::PerRun,
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
        // 100 LSB: a step every 16, the last (to the end) 4: ceil(100 / 16)
        // = 7 samples.
        let s = run(&[m(1000.0, 1000.0), l(1100.0, 1000.0)], &cfg);
        let lit: Vec<u16> = s.iter().filter(|s| s.beam == Beam::On).map(|s| s.x).collect();
        assert_eq!(lit, [1000, 1000, 1016, 1032, 1048, 1064, 1080, 1096, 1100, 1100]);
        // A whole number of steps ends on the end point, once.
        let s = run(&[m(1000.0, 1000.0), l(1000.0, 1064.0)], &cfg);
        let lit: Vec<u16> = s.iter().filter(|s| s.beam == Beam::On).map(|s| s.y).collect();
        assert_eq!(lit, [1000, 1000, 1016, 1032, 1048, 1064, 1064]);
        // Sub-LSB end points are rounded to the nearest code, half away.
        let s = run(&[m(10.4, 10.5), l(30.6, 10.5)], &cfg);
        let lit: Vec<Sample> = s.into_iter().filter(|s| s.beam == Beam::On).collect();
        assert_eq!(lit.first(), Some(&on(10, 11)));
        assert_eq!(lit.last(), Some(&on(31, 11)));
        assert_eq!(lit.len(), 2 + 2 + 1);
    }

    #[test]
    fn steps_run_on_across_smooth_vertices() {
        let cfg = BeamConfig { lit_step: 16.0, ..BeamConfig::default() };
        // 10 + 10 + 30 LSB along x then a gentle bend (no corner): the
        // steps fall every 16 LSB of path, not at the vertices: 16, 32, 48
        // and the end at 50. Per segment, it would take 1 + 1 + 2.
        let bend = [m(0.0, 100.0), l(10.0, 100.0), l(20.0, 100.0), l(50.0, 100.0)];
        let lit: Vec<Sample> = run(&bend, &cfg).into_iter().filter(|s| s.beam == Beam::On).collect();
        assert_eq!(
            lit,
            [on(0, 100), on(0, 100), on(16, 100), on(32, 100), on(48, 100), on(50, 100), on(50, 100)]
        );
        // Around a gentle bend the step is measured along the path: 6 LSB
        // to (16, 0), then 10 more up the 45 degree leg.
        let turn = [m(0.0, 0.0), l(10.0, 0.0), l(10.0 + 100.0 / 2f32.sqrt(), 100.0 / 2f32.sqrt())];
        let lit: Vec<Sample> = run(&turn, &cfg).into_iter().filter(|s| s.beam == Beam::On).collect();
        let d = 6.0 / 2f32.sqrt();
        assert_eq!(lit[2], on((10.0 + d).round() as u16, d.round() as u16));
        // A corner ends the run: a sample at the vertex, its dwell, and
        // the next step a whole step after it.
        let corner = [m(0.0, 0.0), l(10.0, 0.0), l(10.0, 40.0)];
        let lit: Vec<Sample> = run(&corner, &cfg).into_iter().filter(|s| s.beam == Beam::On).collect();
        assert_eq!(
            lit,
            [on(0, 0), on(0, 0), on(10, 0), on(10, 0), on(10, 16), on(10, 32), on(10, 40), on(10, 40)]
        );
        // Segments shorter than a step do not each take a sample: a circle
        // of 64 chords of 4.9 LSB takes its length over 16, not 64.
        let r = 50.0f32;
        let mut circle = std::vec![m(1000.0 + r, 1000.0)];
        for k in 1..=64 {
            let a = k as f32 * core::f32::consts::TAU / 64.0;
            circle.push(l(1000.0 + r * libm::cosf(a), 1000.0 + r * libm::sinf(a)));
        }
        let st = frame_stats(circle.iter().copied(), &cfg);
        let want = libm::ceilf(st.lit_length / 16.0) as u64;
        assert_eq!(st.lit_samples, u64::from(cfg.dwell_start) + want + u64::from(cfg.dwell_end));
        assert_eq!(want, 20);
    }

    #[test]
    fn constant_spacing_runs_on_across_corners() {
        let lit = |cmds: &[Command<ScreenPoint>], cfg: &BeamConfig| -> Vec<Sample> {
            run(cmds, cfg).into_iter().filter(|s| s.beam == Beam::On).collect()
        };
        let per_run = BeamConfig { lit_step: 16.0, ..BeamConfig::default() };
        let constant = BeamConfig { spacing: Spacing::Constant, corner_dwell: 0, ..per_run };
        // 10 LSB along x, a right-angle corner, 40 up: 50 LSB of path.
        let corner = [m(0.0, 0.0), l(10.0, 0.0), l(10.0, 40.0)];
        // Runs: a sample at the corner, its dwell, and steps again from
        // there.
        assert_eq!(
            lit(&corner, &per_run),
            [on(0, 0), on(0, 0), on(10, 0), on(10, 0), on(10, 16), on(10, 32), on(10, 40), on(10, 40)]
        );
        // Constant: every 16 LSB of path from the start, across the corner
        // (which takes no sample): 16, 32, 48, and the end.
        assert_eq!(
            lit(&corner, &constant),
            [on(0, 0), on(0, 0), on(10, 6), on(10, 22), on(10, 38), on(10, 40), on(10, 40)]
        );
        // With a corner dwell the corner is sampled and dwells, and the
        // steps go on from where they were.
        let dwell = BeamConfig { corner_dwell: 1, ..constant };
        assert_eq!(
            lit(&corner, &dwell),
            [
                on(0, 0),
                on(0, 0),
                on(10, 0),
                on(10, 0),
                on(10, 6),
                on(10, 22),
                on(10, 38),
                on(10, 40),
                on(10, 40)
            ]
        );
        // A zigzag of 100 corners: ceil(length / step) samples besides the
        // dwells (89), where runs take two a corner (its sample and dwell).
        let mut zig = std::vec![m(0.0, 0.0)];
        for k in 1..=100 {
            zig.push(l(10.0 * k as f32, if k % 2 == 0 { 0.0 } else { 10.0 }));
        }
        let st = frame_stats(zig.iter().copied(), &constant);
        let steps = libm::ceilf(st.lit_length / 16.0) as u64;
        assert_eq!(st.lit_samples, 2 + steps + 1);
        assert!(frame_stats(zig.iter().copied(), &per_run).lit_samples > st.lit_samples + 100);
        // Straight or gently bent paths, dots and jumps: as runs.
        let straight = [m(0.0, 100.0), l(10.0, 100.0), l(20.0, 100.0), l(50.0, 100.0), p(7.0, 9.0)];
        assert_eq!(run(&straight, &constant), run(&straight, &per_run));
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
}
