//! DAC output: the samples a beam scheduler produces and the one trait every
//! DAC implements.
//!
//! Shaped like embedded-graphics' `DrawTarget`: an associated `Error` and
//! one required method taking an iterator of samples. The STM32's on-chip
//! DACs, an SPI DAC, the host's virtual DAC and the heap-free `MockDac` all
//! implement it.
//!
//! - `mcp4922` (feature `embedded-hal`): the MCP4922 dual SPI DAC and a Z
//!   pin, over embedded-hal 1.0.
//! - [`mock`]: [`mock::MockDac`], a heap-free DAC that draws ASCII art, for
//!   tests.

#[cfg(feature = "embedded-hal")]
pub mod mcp4922;
pub mod mock;

/// Whether the beam is lit for a sample (the Z / blank output).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Beam {
    /// Blanked: the beam moves without drawing.
    #[default]
    Off,
    /// Lit: the beam draws.
    On,
}

/// One DAC sample: an X code, a Y code (0 ..= 2^bits - 1) and the beam.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Sample {
    /// X code.
    pub x: u16,
    /// Y code.
    pub y: u16,
    /// Beam on or off.
    pub beam: Beam,
}

impl Sample {
    /// A sample from its parts.
    pub const fn new(x: u16, y: u16, beam: Beam) -> Self {
        Self { x, y, beam }
    }
}

/// Samples handed out in runs: what a DMA refill loop pulls from.
///
/// The beam scheduler ([`crate::beam::Scheduler`]) implements it with a
/// loop per run (a settle, a dwell, a segment's steps) rather than a state
/// machine round per sample; any iterator does through [`Samples`].
pub trait SampleSource {
    /// Hand the next samples to `put`, at most `max` of them; returns how
    /// many. Fewer than `max` only when the source has run out.
    fn fill_with<F: FnMut(Sample)>(&mut self, max: usize, put: F) -> usize;

    /// The same samples as [`SampleSource::fill_with`], handed to `sink` in
    /// runs (the scheduler's settles, dwells and segments; a run of one
    /// sample each by default).
    fn fill_runs<R: RunSink>(&mut self, max: usize, sink: &mut R) -> usize {
        self.fill_with(max, |s| sink.repeat(s, 1))
    }

    /// The next sample, if any: [`SampleSource::fill_with`] for one (what
    /// a source's `Iterator::next` is).
    fn next_sample(&mut self) -> Option<Sample> {
        let mut out = None;
        self.fill_with(1, |s| out = Some(s));
        out
    }
}

/// Where [`SampleSource::fill_runs`] hands samples, a run at a time, so
/// that a refill writes each run in a loop of its own (no per-sample
/// dispatch, its state in registers).
pub trait RunSink {
    /// `n` samples equal to `s`.
    fn repeat(&mut self, s: Sample, n: usize);

    /// `n` lit samples, each from [`Steps::step`]: a segment's steps
    /// ([`LitSteps`](crate::beam::LitSteps)) or a replayed frame's
    /// ([`Deltas`](crate::beam::replay::Deltas)).
    fn steps<S: Steps>(&mut self, steps: &mut S, n: usize);
}

/// A run of lit samples, one [`Steps::step`] a sample: what
/// [`RunSink::steps`] takes. Cloned, it gives the same samples again (a
/// recording sink reads a run before handing it on).
pub trait Steps: Clone {
    /// The codes of the next lit sample. Called only as many times as the
    /// run says (past its end the codes are meaningless, never a panic).
    fn step(&mut self) -> (u16, u16);
}

/// A [`RunSink`] handing each sample of a run to a closure: how a
/// [`SampleSource`] of runs gives its samples one by one.
pub(crate) struct Each<F>(pub F);

impl<F: FnMut(Sample)> RunSink for Each<F> {
    #[inline(always)]
    fn repeat(&mut self, s: Sample, n: usize) {
        for _ in 0..n {
            (self.0)(s);
        }
    }

    #[inline(always)]
    fn steps<S: Steps>(&mut self, steps: &mut S, n: usize) {
        for _ in 0..n {
            let (x, y) = steps.step();
            (self.0)(Sample::new(x, y, Beam::On));
        }
    }
}

/// Any iterator of samples as a [`SampleSource`], one `next` at a time.
#[derive(Debug, Clone)]
pub struct Samples<I>(pub I);

impl<I: Iterator<Item = Sample>> SampleSource for Samples<I> {
    #[inline]
    fn fill_with<F: FnMut(Sample)>(&mut self, max: usize, mut put: F) -> usize {
        let mut n = 0;
        while n < max {
            let Some(s) = self.0.next() else { break };
            put(s);
            n += 1;
        }
        n
    }
}

impl<S: SampleSource + ?Sized> SampleSource for &mut S {
    #[inline]
    fn fill_with<F: FnMut(Sample)>(&mut self, max: usize, put: F) -> usize {
        (**self).fill_with(max, put)
    }

    #[inline]
    fn fill_runs<R: RunSink>(&mut self, max: usize, sink: &mut R) -> usize {
        (**self).fill_runs(max, sink)
    }
}

/// A device that plays samples: X and Y to the scope's inputs, the beam to
/// its Z input (or a blanking circuit).
pub trait Dac {
    /// Why the device could not take a sample.
    type Error;

    /// Play the samples, in order, at the device's sample rate.
    ///
    /// # Errors
    /// The device's error; samples after the failing one are not played.
    fn write<I>(&mut self, samples: I) -> Result<(), Self::Error>
    where
        I: IntoIterator<Item = Sample>;
}

impl<D: Dac + ?Sized> Dac for &mut D {
    type Error = D::Error;
    fn write<I>(&mut self, samples: I) -> Result<(), Self::Error>
    where
        I: IntoIterator<Item = Sample>,
    {
        (**self).write(samples)
    }
}
