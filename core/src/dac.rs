//! DAC output: the samples a beam scheduler produces and the one trait every
//! DAC implements.
//!
//! Shaped like embedded-graphics' `DrawTarget`: an associated `Error` and
//! one required method taking an iterator of samples. The STM32's on-chip
//! DACs, an SPI DAC, the host's virtual DAC and the heap-free `MockDac` all
//! implement it.

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
