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
}
