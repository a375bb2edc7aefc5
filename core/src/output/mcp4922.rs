//! A [`Dac`] on the Microchip MCP4922: a dual 12-bit SPI DAC for X and Y,
//! and a GPIO for the beam (Z / blank). Needs the `embedded-hal` feature.
//!
//! [`Mcp4922`] is generic over an embedded-hal 1.0 [`SpiDevice<u8>`] (which
//! owns chip select), an [`OutputPin`] for Z and an optional [`OutputPin`]
//! for /LDAC ([`NoPin`] when /LDAC is tied low). It needs no heap, never
//! panics and never waits.
//!
//! # Wiring
//!
//! MCP4922 (14-pin PDIP/SOIC/TSSOP), VDD 2.7 ..= 5.5 V:
//!
//! | pin | name   | connect to |
//! |-----|--------|------------|
//! | 1   | VDD    | supply, 100 nF to VSS |
//! | 3   | /CS    | the `SpiDevice`'s chip select |
//! | 4   | SCK    | SPI clock: mode 0 ([`MODE`]), at most 20 MHz ([`MAX_FREQUENCY_HZ`]) |
//! | 5   | SDI    | SPI MOSI (the chip has no output: no MISO) |
//! | 8   | /LDAC  | GND, or a GPIO given as the `ldac` pin |
//! | 9   | /SHDN  | VDD |
//! | 10  | VOUTB  | Y stage |
//! | 11  | VREFB  | the reference |
//! | 12  | VSS    | ground |
//! | 13  | VREFA  | the reference |
//! | 14  | VOUTA  | X stage |
//!
//! Channel A is X, channel B is Y. Feed both VREF pins from one low-noise
//! reference (e.g. 4.096 V; unbuffered VREF accepts 0 V ..= VDD, see
//! [`VrefBuffer`]); with [`Gain::X1`] each output spans
//! `0 ..= VREF * 4095/4096`. The outputs cannot drive a scope input or a
//! cable directly and are unipolar, so each goes through an op-amp
//! difference stage on ±12 V rails (TL072, OPA2171, ...):
//! `V_scope = k * (V_dac - VREF/2)`, with the 4-resistor difference
//! amplifier's `R2/R1 = k = 10 V / VREF` (about 2.44 for 4.096 V) and
//! `VREF/2` from a buffered divider. Code 2048 is then the screen centre
//! and codes 0 and 4095 are -5 V and +5 V on the scope's X and Y inputs
//! (set to DC coupling, XY mode). The Z pin drives the scope's Z input
//! (or a blanking circuit) through a resistor. By default it is high while
//! the beam is blanked, as the firmware's blank pin is (most Z inputs,
//! Tektronix's among them, blank on a positive voltage): use
//! [`ZPolarity::BlankActiveLow`] for a Z input that blanks on a low one.
//!
//! # Commands
//!
//! Each channel is one 16-bit command word, sent MSB first as two bytes in
//! its own `SpiDevice` transaction (the chip latches a word when /CS rises):
//!
//! | bit | 15  | 14  | 13  | 12    | 11 ..= 0 |
//! |-----|-----|-----|-----|-------|----------|
//! |     | /A B | BUF | /GA | /SHDN | code    |
//!
//! With the default [`Config`] (unbuffered VREF, gain 1x, active), X code
//! `0x123` is word `0x3123` (bytes `31 23`) and Y code `0xABC` is word
//! `0xBABC` (bytes `BA BC`); see [`Config::command_word`].
//!
//! # One sample
//!
//! [`Mcp4922::write_sample`] (and so [`Dac::write`], once per sample):
//!
//! 1. rejects a code above [`MAX_CODE`] with [`SpiDacError::OutOfRange`]
//!    before touching the bus or a pin;
//! 2. if the beam turns off: drives Z to its *off* level first, so the move
//!    does not streak;
//! 3. drives /LDAC high, writes X (channel A) then Y (channel B), and drives
//!    /LDAC low: both outputs change together on that falling edge. /LDAC
//!    stays low until the next sample, so the pulse lasts a whole sample
//!    period (the chip needs 100 ns) without a delay in the driver. With
//!    [`NoPin`] (/LDAC tied low) each output changes as its word is
//!    latched, X a word before Y;
//! 4. if the beam turns on: drives Z to its *on* level last, once X and Y
//!    have been written.
//!
//! The Z pin is only driven when the beam changes state: the driver caches
//! the last state it set ([`Mcp4922::beam`]). It does not know the pin's
//! level before the first sample (or after a pin error), so it drives Z on
//! the first sample either way; create the pin at its blank level, or call
//! [`Mcp4922::blank`] right after [`Mcp4922::new`]. The beam scheduler
//! ([`crate::beam`]) already emits blanked settle samples at the target of
//! a jump before it lights the beam there.
//!
//! # Pacing
//!
//! The driver never waits: [`Dac::write`] plays its samples back to back as
//! fast as the bus goes (two 16-bit transactions and at most four pin
//! writes a sample). Pacing to the sample rate is the caller's job: call
//! [`Mcp4922::write_sample`] once per timer tick, or write short chunks
//! and wait between them. With a 20 MHz clock the bus alone takes about
//! 1.6 µs a sample, plus the HAL's chip-select and call overheads.
//!
//! # Example
//!
//! ```
//! use embedded_hal_mock::eh1::digital::{Mock as PinMock, State, Transaction as PinTx};
//! use embedded_hal_mock::eh1::spi::{Mock as SpiMock, Transaction as SpiTx};
//! use isoscope_core::output::{Beam, Dac, Sample};
//! use isoscope_core::output::mcp4922::{Config, Mcp4922, NoPin};
//!
//! let spi = SpiMock::new(&[
//!     SpiTx::transaction_start(), SpiTx::write_vec(vec![0x30, 0x00]), SpiTx::transaction_end(),
//!     SpiTx::transaction_start(), SpiTx::write_vec(vec![0xB0, 0x00]), SpiTx::transaction_end(),
//!     SpiTx::transaction_start(), SpiTx::write_vec(vec![0x3F, 0xFF]), SpiTx::transaction_end(),
//!     SpiTx::transaction_start(), SpiTx::write_vec(vec![0xBF, 0xFF]), SpiTx::transaction_end(),
//! ]);
//! // Z high blanks the beam (the default, `ZPolarity::BlankActiveHigh`).
//! let z = PinMock::new(&[PinTx::set(State::High), PinTx::set(State::Low)]);
//! let mut dac = Mcp4922::new(spi, z, NoPin::new(), Config::new());
//! dac.write([Sample::new(0, 0, Beam::Off), Sample::new(4095, 4095, Beam::On)]).unwrap();
//! assert_eq!(dac.beam(), Some(Beam::On));
//! let (mut spi, mut z, _) = dac.release();
//! spi.done();
//! z.done();
//! ```

use core::convert::Infallible;
use core::fmt;
use core::hash::{Hash, Hasher};
use core::marker::PhantomData;

use embedded_hal::digital::{self, ErrorType, OutputPin};
use embedded_hal::spi::{self, SpiDevice};

use super::{Beam, Dac, Sample};

/// Resolution of the MCP4922, in bits (the beam scheduler's `bits`).
pub const BITS: u8 = 12;

/// The largest code the MCP4922 takes: `2^12 - 1`.
pub const MAX_CODE: u16 = (1 << BITS) - 1;

/// The SPI mode to configure the bus with (the chip also accepts mode 3).
pub const MODE: spi::Mode = spi::MODE_0;

/// The fastest SPI clock the MCP4922 accepts, in Hz.
pub const MAX_FREQUENCY_HZ: u32 = 20_000_000;

/// Bit 15: /A B, the channel select (1 = channel B).
const CHANNEL_B: u16 = 1 << 15;
/// Bit 14: BUF, VREF input buffered.
const BUF: u16 = 1 << 14;
/// Bit 13: /GA, 1 = gain 1x.
const GAIN_1X: u16 = 1 << 13;
/// Bit 12: /SHDN, 1 = output active.
const ACTIVE: u16 = 1 << 12;

/// One of the two DAC channels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Channel {
    /// Channel A (VOUTA): X.
    A,
    /// Channel B (VOUTB): Y.
    B,
}

/// Output gain (the /GA bit).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Gain {
    /// `V_out = VREF * code / 4096` (/GA = 1).
    #[default]
    X1,
    /// `V_out = 2 * VREF * code / 4096` (/GA = 0), limited by VDD.
    X2,
}

/// Whether the VREF input is buffered (the BUF bit).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum VrefBuffer {
    /// Unbuffered (BUF = 0): VREF may span 0 V ..= VDD, and loads the
    /// reference with the resistor ladder.
    #[default]
    Unbuffered,
    /// Buffered (BUF = 1): high input impedance, VREF within about 40 mV
    /// of the rails.
    Buffered,
}

/// Which level of the Z pin blanks the beam: named as the firmware's
/// blank pin (`BLANK_ACTIVE_HIGH`, feature `blank-active-low`) and `wav
/// --blank-active-low` are.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ZPolarity {
    /// High blanks the beam, low lights it (most Z inputs: they blank on a
    /// positive voltage).
    #[default]
    BlankActiveHigh,
    /// Low blanks the beam, high lights it.
    BlankActiveLow,
}

impl ZPolarity {
    /// Whether the Z pin is high for `beam`.
    const fn is_high(self, beam: Beam) -> bool {
        matches!(
            (self, beam),
            (ZPolarity::BlankActiveHigh, Beam::Off) | (ZPolarity::BlankActiveLow, Beam::On)
        )
    }
}

/// Settings of an [`Mcp4922`]. The default is unbuffered VREF, gain 1x and
/// a Z pin that is high while the beam is blanked.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Config {
    /// Which Z level blanks the beam.
    pub z_polarity: ZPolarity,
    /// Output gain of both channels.
    pub gain: Gain,
    /// VREF buffering of both channels.
    pub vref_buffer: VrefBuffer,
}

impl Config {
    /// The default settings, usable in a `const`.
    pub const fn new() -> Self {
        Self { z_polarity: ZPolarity::BlankActiveHigh, gain: Gain::X1, vref_buffer: VrefBuffer::Unbuffered }
    }

    /// These settings with another Z polarity.
    #[must_use]
    pub const fn with_z_polarity(self, z_polarity: ZPolarity) -> Self {
        Self { z_polarity, ..self }
    }

    /// These settings with another gain.
    #[must_use]
    pub const fn with_gain(self, gain: Gain) -> Self {
        Self { gain, ..self }
    }

    /// These settings with another VREF buffering.
    #[must_use]
    pub const fn with_vref_buffer(self, vref_buffer: VrefBuffer) -> Self {
        Self { vref_buffer, ..self }
    }

    /// The 16-bit command word that sets `channel` to `code`, output active
    /// (only the low 12 bits of `code` are used).
    ///
    /// ```
    /// use isoscope_core::output::mcp4922::{Channel, Config, Gain, VrefBuffer};
    ///
    /// assert_eq!(Config::new().command_word(Channel::A, 0x123), 0x3123);
    /// assert_eq!(Config::new().command_word(Channel::B, 0xABC), 0xBABC);
    /// let buffered_2x = Config::new().with_vref_buffer(VrefBuffer::Buffered).with_gain(Gain::X2);
    /// assert_eq!(buffered_2x.command_word(Channel::A, 0xFFF), 0x5FFF);
    /// ```
    pub const fn command_word(&self, channel: Channel, code: u16) -> u16 {
        let channel = match channel {
            Channel::A => 0,
            Channel::B => CHANNEL_B,
        };
        let buf = match self.vref_buffer {
            VrefBuffer::Unbuffered => 0,
            VrefBuffer::Buffered => BUF,
        };
        let gain = match self.gain {
            Gain::X1 => GAIN_1X,
            Gain::X2 => 0,
        };
        channel | buf | gain | ACTIVE | (code & MAX_CODE)
    }
}

/// Why an [`Mcp4922`] could not play a sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SpiDacError<SpiE, PinE> {
    /// The SPI device failed.
    Spi(SpiE),
    /// The Z or the /LDAC pin failed.
    Pin(PinE),
    /// A code is above [`MAX_CODE`]; nothing of the sample was sent.
    OutOfRange {
        /// X code of the sample.
        x: u16,
        /// Y code of the sample.
        y: u16,
    },
}

impl<SpiE: fmt::Debug, PinE: fmt::Debug> fmt::Display for SpiDacError<SpiE, PinE> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SpiDacError::Spi(e) => write!(f, "SPI error: {e:?}"),
            SpiDacError::Pin(e) => write!(f, "Z or LDAC pin error: {e:?}"),
            SpiDacError::OutOfRange { x, y } => {
                write!(f, "sample ({x}, {y}) is outside the 12-bit DAC range 0..={MAX_CODE}")
            }
        }
    }
}

impl<SpiE: fmt::Debug, PinE: fmt::Debug> core::error::Error for SpiDacError<SpiE, PinE> {}

/// An absent output pin: every write succeeds and does nothing. Use it for
/// /LDAC when the pin is tied low.
///
/// Its error type `E` is [`Infallible`] by default; [`Mcp4922`] takes the Z
/// pin's error type for it, so `NoPin::new()` fits any Z pin.
pub struct NoPin<E = Infallible> {
    _error: PhantomData<fn() -> E>,
}

impl<E> NoPin<E> {
    /// An absent pin.
    pub const fn new() -> Self {
        Self { _error: PhantomData }
    }
}

impl<E> fmt::Debug for NoPin<E> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("NoPin")
    }
}

impl<E> Clone for NoPin<E> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<E> Copy for NoPin<E> {}

impl<E> PartialEq for NoPin<E> {
    fn eq(&self, _other: &Self) -> bool {
        true
    }
}

impl<E> Eq for NoPin<E> {}

impl<E> Hash for NoPin<E> {
    fn hash<H: Hasher>(&self, _state: &mut H) {}
}

impl<E> Default for NoPin<E> {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(feature = "defmt")]
impl<E> defmt::Format for NoPin<E> {
    fn format(&self, f: defmt::Formatter<'_>) {
        defmt::write!(f, "NoPin")
    }
}

impl<E: digital::Error> ErrorType for NoPin<E> {
    type Error = E;
}

impl<E: digital::Error> OutputPin for NoPin<E> {
    fn set_low(&mut self) -> Result<(), E> {
        Ok(())
    }

    fn set_high(&mut self) -> Result<(), E> {
        Ok(())
    }
}

/// The MCP4922 driver: X on channel A, Y on channel B, the beam on the Z
/// pin, and optionally an /LDAC pin (the same error type as Z, or
/// [`NoPin`]). See the [module docs](self) for the wiring and the order of
/// the writes.
#[derive(Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Mcp4922<SPI, Z, LDAC = NoPin> {
    spi: SPI,
    z: Z,
    ldac: LDAC,
    config: Config,
    /// The beam state last set on the Z pin; `None` while unknown.
    beam: Option<Beam>,
}

impl<SPI, Z, LDAC> Mcp4922<SPI, Z, LDAC>
where
    SPI: SpiDevice<u8>,
    Z: OutputPin,
    LDAC: OutputPin<Error = Z::Error>,
{
    /// A driver on these parts. Touches neither the bus nor the pins: the
    /// Z pin is driven on the first sample (or by [`Mcp4922::blank`]).
    pub const fn new(spi: SPI, z: Z, ldac: LDAC, config: Config) -> Self {
        Self { spi, z, ldac, config, beam: None }
    }

    /// The settings.
    pub const fn config(&self) -> Config {
        self.config
    }

    /// The beam state last set on the Z pin: `None` before the first sample
    /// and after a failed Z write.
    pub const fn beam(&self) -> Option<Beam> {
        self.beam
    }

    /// The SPI device, the Z pin and the /LDAC pin back. /LDAC is left low
    /// (or as it was if no sample was played), Z as last set.
    pub fn release(self) -> (SPI, Z, LDAC) {
        (self.spi, self.z, self.ldac)
    }

    /// Blank the beam now (drive Z to its off level) unless it is already
    /// known to be off. The DAC outputs do not change.
    ///
    /// # Errors
    /// [`SpiDacError::Pin`] if the Z pin fails.
    pub fn blank(&mut self) -> Result<(), SpiDacError<SPI::Error, Z::Error>> {
        if self.beam != Some(Beam::Off) {
            self.set_beam(Beam::Off)?;
        }
        Ok(())
    }

    /// Play one sample now, in the order given in the [module docs](self).
    ///
    /// # Errors
    /// - [`SpiDacError::OutOfRange`] if `x` or `y` is above [`MAX_CODE`],
    ///   before any bus or pin traffic;
    /// - [`SpiDacError::Spi`] or [`SpiDacError::Pin`] if a write fails; the
    ///   rest of the sample is not played.
    pub fn write_sample(&mut self, sample: Sample) -> Result<(), SpiDacError<SPI::Error, Z::Error>> {
        let Sample { x, y, beam } = sample;
        if x > MAX_CODE || y > MAX_CODE {
            return Err(SpiDacError::OutOfRange { x, y });
        }
        if beam == Beam::Off && self.beam != Some(Beam::Off) {
            self.set_beam(Beam::Off)?;
        }
        self.ldac.set_high().map_err(SpiDacError::Pin)?;
        self.send(Channel::A, x)?;
        self.send(Channel::B, y)?;
        self.ldac.set_low().map_err(SpiDacError::Pin)?;
        if beam == Beam::On && self.beam != Some(Beam::On) {
            self.set_beam(Beam::On)?;
        }
        Ok(())
    }

    /// Write one channel's command word, in its own transaction.
    fn send(&mut self, channel: Channel, code: u16) -> Result<(), SpiDacError<SPI::Error, Z::Error>> {
        let word = self.config.command_word(channel, code);
        self.spi.write(&word.to_be_bytes()).map_err(SpiDacError::Spi)
    }

    /// Drive the Z pin for `beam` and remember it (forget it on failure).
    fn set_beam(&mut self, beam: Beam) -> Result<(), SpiDacError<SPI::Error, Z::Error>> {
        self.beam = None;
        if self.config.z_polarity.is_high(beam) { self.z.set_high() } else { self.z.set_low() }
            .map_err(SpiDacError::Pin)?;
        self.beam = Some(beam);
        Ok(())
    }
}

impl<SPI, Z, LDAC> Dac for Mcp4922<SPI, Z, LDAC>
where
    SPI: SpiDevice<u8>,
    Z: OutputPin,
    LDAC: OutputPin<Error = Z::Error>,
{
    type Error = SpiDacError<SPI::Error, Z::Error>;

    /// Play the samples back to back with [`Mcp4922::write_sample`], with
    /// no pacing (see the [module docs](self#pacing)).
    fn write<I>(&mut self, samples: I) -> Result<(), Self::Error>
    where
        I: IntoIterator<Item = Sample>,
    {
        samples.into_iter().try_for_each(|sample| self.write_sample(sample))
    }
}
