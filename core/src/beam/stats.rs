//! What a frame costs: [`FrameStats`], and [`frame_stats`] to count a whole
//! frame without keeping its samples.

use super::{BeamConfig, Scheduler};
use crate::command::Command;
use crate::view::ScreenPoint;

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
    /// [`Park::return_at_end`](super::Park::return_at_end), the one back to
    /// the park position.
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

/// Bisections [`fit_spacing`] makes: the step it finds is within
/// `2^-FIT_ROUNDS` of the range it searches, in ratio (under 0.01%).
const FIT_ROUNDS: u32 = 24;

/// `cfg` with the smallest `lit_step` of at least `cfg`'s (sanitized) at
/// which the frame of `commands` takes at most `max_samples` samples: the
/// spacing that makes a picture refresh at `rate / max_samples` Hz or
/// faster, for [`Spacing::Constant`](super::Spacing::Constant) at a sound
/// card's rate (any [`Spacing`](super::Spacing) works: the samples of a
/// frame never grow with its step).
///
/// A frame that fits at `cfg.lit_step` keeps it. One that does not fit
/// even at the largest step searched, twice the DAC's span (where every
/// polyline takes its dwells and about one step: what is left is jumps,
/// dwells and dots), gets that step; check the result's [`frame_stats`].
/// Otherwise the step is found by bisection to within 0.01%, in
/// `FIT_ROUNDS + 2` (26) passes of [`frame_stats`] over `commands`.
/// Never panics; heap-free.
pub fn fit_spacing<I>(commands: I, cfg: &BeamConfig, max_samples: u64) -> BeamConfig
where
    I: IntoIterator<Item = Command<ScreenPoint>> + Clone,
{
    let cfg = cfg.sanitized();
    let with = |lit_step: f32| BeamConfig { lit_step, ..cfg };
    let fits = |lit_step: f32| frame_stats(commands.clone(), &with(lit_step)).samples <= max_samples;
    let mut lo = cfg.lit_step;
    if fits(lo) {
        return cfg;
    }
    let mut hi = (2.0 * (f32::from(cfg.max_code()) + 1.0)).max(lo);
    if !fits(hi) {
        return with(hi);
    }
    // `lo` does not fit, `hi` does: halve the ratio between them.
    for _ in 0..FIT_ROUNDS {
        let mid = crate::fastmath::sqrt(lo * hi);
        if !(mid > lo && mid < hi) {
            break;
        }
        if fits(mid) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    with(hi)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::output::Beam;

    fn m(x: f32, y: f32) -> Command<ScreenPoint> {
        Command::MoveTo(ScreenPoint::new(x, y))
    }
    fn l(x: f32, y: f32) -> Command<ScreenPoint> {
        Command::LineTo(ScreenPoint::new(x, y))
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

    #[test]
    fn fit_spacing_finds_the_smallest_step_that_fits() {
        use crate::beam::Spacing;
        // A 4000-LSB zigzag of 100 segments.
        let mut cmds = std::vec![m(0.0, 0.0)];
        for k in 1..=100 {
            cmds.push(l(40.0 * k as f32, if k % 2 == 0 { 0.0 } else { 30.0 }));
        }
        let cfg = BeamConfig { spacing: Spacing::Constant, corner_dwell: 0, ..BeamConfig::default() };
        let at = |c: &BeamConfig| frame_stats(cmds.iter().copied(), c).samples;
        let fast = at(&cfg);
        // Fits already: unchanged.
        assert_eq!(fit_spacing(cmds.iter().copied(), &cfg, fast), cfg);
        for budget in [fast / 2, fast / 5, 60] {
            let fit = fit_spacing(cmds.iter().copied(), &cfg, budget);
            assert!(at(&fit) <= budget, "{budget}: {} samples", at(&fit));
            // The smallest: a hair less does not fit.
            let less = BeamConfig { lit_step: fit.lit_step * 0.999, ..fit };
            assert!(at(&less) > budget, "{budget}: step {} is not the smallest", fit.lit_step);
            assert_eq!(BeamConfig { lit_step: cfg.lit_step, ..fit }, cfg);
        }
        // Out of reach (the jumps and dwells alone take more): the largest
        // step searched.
        let fit = fit_spacing(cmds.iter().copied(), &cfg, 3);
        assert_eq!(fit.lit_step, 8192.0);
        // Nothing to draw: any step fits.
        assert_eq!(fit_spacing(core::iter::empty(), &cfg, 0), cfg);
    }
}
