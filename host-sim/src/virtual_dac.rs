//! The host's virtual DAC: records every sample with its time on the sample
//! clock, for the phosphor rasteriser and for tests. It implements the same
//! [`Dac`] trait as the firmware's DACs.

use isoscope_core::output::{Beam, Dac, Sample};
use std::convert::Infallible;

/// A DAC that keeps what it is given.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct VirtualDac {
    rate_hz: f64,
    samples: Vec<Sample>,
}

impl VirtualDac {
    /// A DAC clocked at `rate_hz` samples per second.
    pub fn new(rate_hz: f64) -> Self {
        Self { rate_hz, samples: Vec::new() }
    }

    /// Samples per second.
    pub fn rate_hz(&self) -> f64 {
        self.rate_hz
    }

    /// Everything played so far.
    pub fn samples(&self) -> &[Sample] {
        &self.samples
    }

    /// Samples with their time in seconds on the sample clock.
    pub fn timed(&self) -> impl Iterator<Item = (f64, Sample)> + '_ {
        let dt = if self.rate_hz > 0.0 { 1.0 / self.rate_hz } else { 0.0 };
        self.samples.iter().enumerate().map(move |(i, &s)| (i as f64 * dt, s))
    }

    /// Seconds of signal recorded.
    pub fn duration(&self) -> f64 {
        if self.rate_hz > 0.0 { self.samples.len() as f64 / self.rate_hz } else { 0.0 }
    }

    /// Lit samples recorded.
    pub fn lit(&self) -> usize {
        self.samples.iter().filter(|s| s.beam == Beam::On).count()
    }

    /// Forget what was recorded.
    pub fn clear(&mut self) {
        self.samples.clear();
    }
}

impl Dac for VirtualDac {
    type Error = Infallible;

    fn write<I>(&mut self, samples: I) -> Result<(), Infallible>
    where
        I: IntoIterator<Item = Sample>,
    {
        self.samples.extend(samples);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use isoscope_core::beam::{BeamConfig, Scheduler};
    use isoscope_core::command::Command;
    use isoscope_core::view::ScreenPoint;

    #[test]
    fn records_a_scheduled_frame_with_its_clock() {
        let cmds = [
            Command::MoveTo(ScreenPoint::new(100.0, 100.0)),
            Command::LineTo(ScreenPoint::new(300.0, 100.0)),
        ];
        let cfg = BeamConfig::default();
        let mut sched = Scheduler::new(cmds, &cfg);
        let mut dac = VirtualDac::new(1e6);
        dac.write(&mut sched).unwrap();
        let stats = sched.stats();
        assert_eq!(dac.samples().len() as u64, stats.samples);
        assert_eq!(dac.lit() as u64, stats.lit_samples);
        assert!((dac.duration() - stats.samples as f64 * 1e-6).abs() < 1e-12);
        let (t, last) = dac.timed().last().unwrap();
        assert_eq!(last.beam, Beam::Off);
        assert!((t - (stats.samples - 1) as f64 * 1e-6).abs() < 1e-12);
        // The lit run ends on the end point of the line.
        let lit: Vec<_> = dac.samples().iter().filter(|s| s.beam == Beam::On).collect();
        assert_eq!((lit.last().unwrap().x, lit.last().unwrap().y), (300, 100));
    }
}
