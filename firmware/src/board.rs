//! Everything specific to the board: the STM32F407G-DISC1 (STM32F407VG,
//! Cortex-M4F at 168 MHz, 8 MHz crystal), and QEMU's netduinoplus2 (an
//! STM32F405 with the same DAC, GPIO and USART registers) under the `qemu`
//! feature.
//!
//! | signal | pin | peripheral |
//! |---|---|---|
//! | X | PA4 | DAC channel 1 (12 bits, output buffer on) |
//! | Y | PA5 | DAC channel 2 |
//! | blank (Z) | PB0 | GPIO, high = blanked (feature `blank-active-low` inverts) |
//! | host link | PA2 TX, PA3 RX (pull-up) | USART2, AF7, 921,600 baud 8N1 ([`crate::serial`]) |
//!
//! # Output path
//!
//! X and Y change together and the blank pin switches on the same sample
//! clock: **one timer, TIM8, paces everything**. At every TIM8 update event
//! (1 MS/s: 168 MHz / 168; slower for a picture whose refill cannot keep
//! up, see below):
//!
//! - TIM8's TRGO (MMS = update) triggers both DAC channels (TSEL = 001,
//!   TEN1 = TEN2 = 1): each moves its holding register to its output at the
//!   same APB1 clock edge. The DAC then raises a DMA request (DMAEN1 only),
//!   and DMA1 stream 5 channel 7 (DAC1) writes the next 32-bit word of the
//!   X/Y buffer into the dual register DHR12RD (X in bits 0..12, Y in bits
//!   16..28): one write, both channels.
//! - TIM8's update DMA request (UDE) makes DMA2 stream 1 channel 7
//!   (TIM8_UP) write the next byte of the blank buffer into the low byte of
//!   GPIOB's ODR (pins PB0..PB7; GPIO registers take byte writes, RM0090
//!   section 8.4). It has to be DMA2: DMA1's peripheral port only reaches
//!   APB1, not the AHB1 GPIO ports (RM0090, figure 1 and section 10.3.3).
//!   A byte a sample rather than a BSRR word saves 3 KB of SRAM; the price
//!   is that **PB1..PB7 must not be GPIO outputs** (the DMA rewrites their
//!   output bits with 0 at every sample; as inputs, analog or alternate
//!   functions, which is how this firmware leaves them, the ODR does not
//!   reach them).
//!
//! Both streams are circular over buffers of the same length and advance by
//! one sample per update event, so they stay in lockstep. The DAC outputs at
//! event `k` the word loaded after event `k - 1`, while the GPIO takes word
//! `k` at event `k`; so the blank buffer holds each sample's beam one slot
//! later than the X/Y buffer holds its position ([`DmaOutput::fill`]), and a
//! sample's position and beam reach the pins at the same update event.
//!
//! TIM6 (the usual DAC trigger) has no DMA request on DMA2 and cannot be a
//! slave of anything, so it could only pace the blank pin through a second,
//! synchronised timer; TIM8 is both a DAC trigger and a DMA2 request, which
//! makes the common clock a matter of construction rather than of set-up.
//!
//! The buffers are double-buffered halves: the DMA1 stream 5 half- and
//! full-transfer interrupts tell the main loop which half to refill from
//! the beam scheduler ([`Streaming::fill_from`]; a frame may end inside a
//! half, and the next frame continues it). After each refill the DMA's
//! position (NDTR) tells how much of the other half has played meanwhile;
//! a [`isoscope_core::beam::pace::Pacer`] turns that into TIM8's period (ARR,
//! preloaded): a picture whose refill takes more than 7/8 of a half slows
//! the sample clock at once (down to [`MIN_SAMPLE_RATE_HZ`]), so the DMA
//! never replays a stale half, and a lighter one brings it back to
//! [`SAMPLE_RATE_HZ`]. A transfer error parks and
//! blanks the beam and stops feeding the independent watchdog, which then
//! resets the MCU.
//!
//! # Under QEMU (feature `qemu`)
//!
//! QEMU models neither the RCC (reads return 0, so the HAL's clock freeze
//! would wait forever: it is not called) nor the DAC, DMA, GPIO or TIM6-8
//! (it logs every access with `-d unimp`). The same [`Streaming`] API
//! hands out halves at once (no sample clock) and, while recording
//! ([`Streaming::record`]), the CPU writes each sample itself, in the same
//! order: DHR12RD, then the blank pin (through BSRR, the CPU's atomic way;
//! the beam each write encodes is the one the DMA's ODR byte would carry).
//! It models USART2
//! (its second `-serial`) and SysTick (at 168 MHz, as the board).

use crate::serial::{self, Rx, Tx};
use core::cell::UnsafeCell;
use core::sync::atomic::{Ordering, compiler_fence};
use isoscope_core::output::{Beam, Dac, RunSink, Sample, SampleSource, Samples, Steps};
use stm32f4xx_hal::gpio::{Alternate, Analog, Output, PinState, PushPull, gpioa, gpiob};
use stm32f4xx_hal::pac;
use stm32f4xx_hal::prelude::*;
use stm32f4xx_hal::watchdog::IndependentWatchdog;

/// Samples per second (both DAC channels and the blank pin): the engine's
/// setting ([`isoscope_scene::SAMPLE_RATE_HZ`]), so that beam times in
/// microseconds and the refresh rate it reports hold.
pub use isoscope_scene::SAMPLE_RATE_HZ;

/// The slowest rate the sample clock is paced down to
/// ([`isoscope_scene::MIN_SAMPLE_RATE_HZ`]).
#[cfg(not(feature = "qemu"))]
use isoscope_scene::MIN_SAMPLE_RATE_HZ;

/// The blank pin's number on its port (PB0).
pub const BLANK_PIN: u32 = 0;

/// True when a high blank pin blanks the beam.
pub const BLANK_ACTIVE_HIGH: bool = !cfg!(feature = "blank-active-low");

/// Samples in one half of the double buffer: 512 us at 1 MS/s.
pub const HALF: usize = 512;

/// The host link's line rate (QEMU ignores it).
pub const BAUD: u32 = 921_600;

/// QEMU's netduinoplus2 clocks the core (and SysTick) at 168 MHz whatever
/// the RCC is told; the HAL, reading the unmodelled RCC, would assume the
/// 16 MHz reset clock.
#[cfg(feature = "qemu")]
const QEMU_CORE_HZ: u32 = 168_000_000;

/// The DHR12RD word of a sample: X (channel 1) in bits 0..12, Y (channel 2)
/// in bits 16..28.
#[inline(always)]
pub const fn dac_word(s: Sample) -> u32 {
    ((s.y as u32 & 0xfff) << 16) | (s.x as u32 & 0xfff)
}

/// The BSRR word that puts the blank pin in `beam`'s state: the pin's set
/// bit (bit `n`) or reset bit (bit `n + 16`).
#[inline(always)]
pub const fn blank_word(beam: Beam) -> u32 {
    let high = matches!(beam, Beam::Off) == BLANK_ACTIVE_HIGH;
    if high { 1 << BLANK_PIN } else { 1 << (BLANK_PIN + 16) }
}

/// The ODR low byte (pins PB0..PB7) that puts the blank pin in `beam`'s
/// state, as the blank DMA writes it: the pin's bit, the other seven 0.
#[inline(always)]
const fn blank_byte(beam: Beam) -> u8 {
    let high = matches!(beam, Beam::Off) == BLANK_ACTIVE_HIGH;
    if high { 1 << BLANK_PIN } else { 0 }
}
const _: () = assert!(BLANK_PIN < 8, "the blank DMA writes the low byte of the port's ODR");

/// DAC_CR: channel enable, trigger enable, DMA enable (channel 1 bits;
/// channel 2's are 16 higher), and TSEL = 001 (TIM8 TRGO) for channel 1.
const DAC_EN1: u32 = 1 << 0;
#[cfg(not(feature = "qemu"))]
const DAC_TEN1: u32 = 1 << 2;
#[cfg(not(feature = "qemu"))]
const DAC_TSEL1_TIM8: u32 = 0b001 << 3;
#[cfg(not(feature = "qemu"))]
const DAC_DMAEN1: u32 = 1 << 12;
const DAC_CH2: u32 = 16;

/// The board's peripherals, set up.
pub struct Board {
    /// The X/Y DAC and the blank pin.
    pub out: Out,
    /// The independent watchdog (started by [`init`]).
    pub watchdog: IndependentWatchdog,
    /// Core clock, Hz.
    pub sysclk_hz: u32,
    /// USART2's bus clock (APB1), Hz.
    pub pclk1_hz: u32,
    /// The host link: received bytes.
    pub rx: Rx,
    /// The host link: bytes to send.
    pub tx: Tx,
    _link_pins: (gpioa::PA2<Alternate<7>>, gpioa::PA3<Alternate<7>>),
}

/// The output pins; owning them keeps anyone else from reconfiguring them.
pub struct Pins {
    _x: gpioa::PA4<Analog>,
    _y: gpioa::PA5<Analog>,
    _blank: gpiob::PB0<Output<PushPull>>,
}

/// Set up clocks, the millisecond clock ([`crate::clock`]), the host link
/// (USART2, receiving from here on), pins, the DAC (beam parked and
/// blanked) and the watchdog (`watchdog_ms`).
// Not inlined: its frame (the HAL's temporaries) is gone before the main
// loop starts.
#[inline(never)]
pub fn init(watchdog_ms: u32) -> Board {
    let Some(dp) = pac::Peripherals::take() else { fault() };
    let Some(cp) = cortex_m::Peripherals::take() else { fault() };
    // QEMU does not model the RCC: its reads return 0, so waiting for the
    // HSE or the PLL to be ready would never end; it runs the core at the
    // reset clock and needs no bus clocks.
    #[cfg(feature = "qemu")]
    let mut rcc = dp.RCC.constrain();
    #[cfg(not(feature = "qemu"))]
    let mut rcc = dp
        .RCC
        .freeze(stm32f4xx_hal::rcc::Config::hse(8.MHz()).sysclk(168.MHz()).pclk1(42.MHz()).pclk2(84.MHz()));
    #[cfg(not(feature = "qemu"))]
    let sysclk_hz = rcc.clocks.sysclk().raw();
    #[cfg(feature = "qemu")]
    let sysclk_hz = QEMU_CORE_HZ;
    let pclk1_hz = rcc.clocks.pclk1().raw();
    crate::clock::start(cp.SYST, sysclk_hz);
    rcc.apb1enr().modify(|_, w| w.dacen().set_bit().usart2en().set_bit());
    #[cfg(not(feature = "qemu"))]
    rcc.apb2enr().modify(|_, w| w.tim8en().set_bit());
    #[cfg(not(feature = "qemu"))]
    rcc.ahb1enr().modify(|_, w| w.dma1en().set_bit().dma2en().set_bit());

    let gpioa = dp.GPIOA.split(&mut rcc);
    let gpiob = dp.GPIOB.split(&mut rcc);
    // The host link first: the sender's hello may already be on the line.
    // RX pulled up, so an unconnected pin reads as an idle line.
    let link_pins = (gpioa.pa2.into_alternate::<7>(), gpioa.pa3.into_alternate::<7>().internal_pull_up(true));
    let (rx, tx) = serial::init(dp.USART2, pclk1_hz, BAUD);
    // The blank pin goes to its blanked level before it becomes an output.
    let blanked = if BLANK_ACTIVE_HIGH { PinState::High } else { PinState::Low };
    let pins = Pins {
        _x: gpioa.pa4.into_analog(),
        _y: gpioa.pa5.into_analog(),
        _blank: gpiob.pb0.into_push_pull_output_in_state(blanked),
    };

    let mut watchdog = IndependentWatchdog::new(dp.IWDG);
    // Halted by a debugger (probe-rs), the watchdog waits too.
    watchdog.stop_on_debug(&dp.DBGMCU, true);
    watchdog.start(watchdog_ms.millis());

    let out = Out::new(dp.DAC, pins, rcc.clocks.timclk2().raw());
    #[cfg(not(feature = "qemu"))]
    let out = out.with_dma(dp.TIM8, dp.DMA1, dp.DMA2);
    Board { out, watchdog, sysclk_hz, pclk1_hz, rx, tx, _link_pins: link_pins }
}

/// The X/Y DAC and the blank pin.
pub struct Out {
    dac: pac::DAC,
    park: Sample,
    #[cfg_attr(feature = "qemu", allow(dead_code))]
    timer_hz: u32,
    _pins: Pins,
    #[cfg(not(feature = "qemu"))]
    dma: Option<(pac::TIM8, pac::DMA1, pac::DMA2)>,
}

impl Out {
    fn new(dac: pac::DAC, pins: Pins, timer_hz: u32) -> Self {
        // Both channels on, output buffers on, no trigger: a CPU write to
        // the holding register reaches the output one APB1 clock later.
        dac.cr().write(|w| unsafe { w.bits(DAC_EN1 | (DAC_EN1 << DAC_CH2)) });
        Self {
            dac,
            park: Sample::default(),
            timer_hz,
            _pins: pins,
            #[cfg(not(feature = "qemu"))]
            dma: None,
        }
    }

    #[cfg(not(feature = "qemu"))]
    fn with_dma(mut self, tim8: pac::TIM8, dma1: pac::DMA1, dma2: pac::DMA2) -> Self {
        self.dma = Some((tim8, dma1, dma2));
        self
    }

    /// Where the beam rests when idle (blanked).
    pub fn set_park(&mut self, park: Sample) {
        self.park = Sample { beam: Beam::Off, ..park };
    }

    /// Write one sample from the CPU, in the output path's order: X and Y
    /// together (DHR12RD), then the blank pin (BSRR).
    #[inline(always)]
    pub fn write(&mut self, s: Sample) {
        self.dac.dhr12rd().write(|w| unsafe { w.bits(dac_word(s)) });
        gpiob_bsrr().write(|w| unsafe { w.bits(blank_word(s.beam)) });
    }

    /// Park and blank the beam (from the CPU).
    pub fn park(&mut self) {
        self.write(self.park);
    }
}

/// GPIOB's BSRR (the blank pin's port).
fn gpiob_bsrr() -> &'static pac::gpiob::BSRR {
    // SAFETY: BSRR writes are atomic set/reset operations on single pins;
    // the blank pin is owned by `Out` (through `Pins`), and nothing else
    // writes its bits.
    unsafe { (*pac::GPIOB::ptr()).bsrr() }
}

/// Park and blank the beam whatever state the peripherals are in: stop the
/// sample clock and both DMA streams, detach the DAC from its trigger and
/// write the corner `(0, 0)` from the CPU, blank the pin. For fault
/// handlers.
pub fn emergency_park() {
    // SAFETY: called when normal operation has ended (a fault); only
    // disables and writes registers, never relies on their state.
    let dp = unsafe { pac::Peripherals::steal() };
    dp.TIM8.cr1().write(|w| unsafe { w.bits(0) });
    dp.DMA1.st(5).cr().modify(|_, w| w.en().clear_bit());
    dp.DMA2.st(1).cr().modify(|_, w| w.en().clear_bit());
    dp.DAC.cr().write(|w| unsafe { w.bits(DAC_EN1 | (DAC_EN1 << DAC_CH2)) });
    dp.DAC.dhr12rd().write(|w| unsafe { w.bits(0) });
    gpiob_bsrr().write(|w| unsafe { w.bits(blank_word(Beam::Off)) });
}

/// The end after a fault: park and blank, then (under QEMU) exit with a
/// failure, or (on the board) wait for the watchdog to reset the MCU.
pub fn fault() -> ! {
    emergency_park();
    #[cfg(feature = "qemu")]
    exit(false);
    #[cfg(not(feature = "qemu"))]
    loop {
        cortex_m::asm::wfi();
    }
}

/// Leave QEMU through semihosting, with exit status 0 or 1.
#[cfg(feature = "qemu")]
pub fn exit(success: bool) -> ! {
    use cortex_m_semihosting::debug;
    debug::exit(if success { debug::EXIT_SUCCESS } else { debug::EXIT_FAILURE });
    loop {
        cortex_m::asm::wfi();
    }
}

/// What [`Streaming::fill_from`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Filled {
    /// A half is full and handed to the output.
    Half,
    /// The samples ran out inside a half, which stays open.
    FrameEnd,
}

/// A DMA transfer error; the beam is parked and blanked.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DmaError;

impl core::fmt::Display for DmaError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str("DMA transfer error: the beam is parked and blanked")
    }
}

/// The on-chip DAC as a [`Dac`], unclocked: each sample goes from the CPU
/// straight to the dual register and the blank pin, as fast as the caller
/// writes them (bring-up, a still park position, tests). The picture plays
/// through [`Streaming`], the clocked one.
impl Dac for Out {
    type Error = core::convert::Infallible;

    fn write<I: IntoIterator<Item = Sample>>(&mut self, samples: I) -> Result<(), Self::Error> {
        for s in samples {
            Out::write(self, s);
        }
        Ok(())
    }
}

/// The sample-clocked output (TIM8 paces the DAC and the blank pin) as a
/// [`Dac`]: the samples fill the double buffer as halves come free,
/// blocking while both are queued; a partial last half stays open for the
/// next write.
impl Dac for Streaming {
    type Error = DmaError;

    fn write<I: IntoIterator<Item = Sample>>(&mut self, samples: I) -> Result<(), DmaError> {
        let mut samples = Samples(samples.into_iter());
        loop {
            if self.fill_from(&mut samples)? == Filled::FrameEnd {
                return Ok(());
            }
        }
    }
}

#[cfg(feature = "qemu")]
pub use cpu::Streaming;
#[cfg(not(feature = "qemu"))]
pub use dma::Streaming;

/// A double buffer of `T`s in the DMA path's format: the CPU writes one
/// half while the DMA (on the board) reads the other.
#[repr(C, align(4))]
struct DmaBuf<T>(UnsafeCell<[T; 2 * HALF]>);

// SAFETY: accessed only through raw pointers, by [`write_slots`] and the
// DMA set-up (one `Streaming`), on halves the DMA is not reading.
unsafe impl<T> Sync for DmaBuf<T> {}

/// DHR12RD words (4 KB).
static XY: DmaBuf<u32> = DmaBuf(UnsafeCell::new([0; 2 * HALF]));
/// GPIOB ODR low bytes (1 KB).
static BLANK: DmaBuf<u8> = DmaBuf(UnsafeCell::new([0; 2 * HALF]));

/// Write samples into slots `start..end` of both buffers (at most to the
/// end of the buffers) until they are full or `samples` ends: sample `j`'s
/// position at slot `j` of the X/Y buffer, the beam of sample `j - 1` at
/// slot `j` of the blank buffer (`last` carries the beam from one call to
/// the next). `also` sees each sample written. Returns the next slot. The
/// caller makes sure the DMA is not reading those slots.
fn write_slots(
    samples: &mut impl SampleSource,
    start: usize,
    end: usize,
    last: &mut Beam,
    also: impl FnMut(Sample),
) -> usize {
    let end = end.min(2 * HALF);
    let mut slots = Slots {
        xy: XY.0.get().cast::<u32>(),
        blank: BLANK.0.get().cast::<u8>(),
        slot: start,
        end,
        prev: *last,
        also,
    };
    samples.fill_runs(end.saturating_sub(start), &mut slots);
    *last = slots.prev;
    compiler_fence(Ordering::SeqCst);
    slots.slot
}

/// The slots [`write_slots`] fills, as a [`RunSink`]: each run written in
/// a loop of its own, its state in registers.
struct Slots<A> {
    xy: *mut u32,
    blank: *mut u8,
    /// The next slot; never beyond `end`.
    slot: usize,
    /// At most `2 * HALF`.
    end: usize,
    /// The beam of the last sample written.
    prev: Beam,
    also: A,
}

impl<A: FnMut(Sample)> Slots<A> {
    /// How many of `n` samples fit before `end`.
    #[inline(always)]
    fn room(&self, n: usize) -> usize {
        n.min(self.end.saturating_sub(self.slot))
    }

    /// Write `s` (as `word`) and the blank byte `b` at the next slot. Only
    /// for as many samples as [`Slots::room`] gave.
    #[inline(always)]
    fn put(&mut self, word: u32, b: u8, s: Sample) {
        // SAFETY: `slot < end <= 2 * HALF` (the caller took `room`); the
        // DMA is not reading these slots (`write_slots`' caller's word).
        unsafe {
            self.xy.add(self.slot).write_volatile(word);
            self.blank.add(self.slot).write_volatile(b);
        }
        self.slot += 1;
        (self.also)(s);
    }
}

impl<A: FnMut(Sample)> RunSink for Slots<A> {
    fn repeat(&mut self, s: Sample, n: usize) {
        let n = self.room(n);
        if n == 0 {
            return;
        }
        let word = dac_word(s);
        // The blank buffer lags a sample: the first slot holds the beam of
        // the sample before the run.
        self.put(word, blank_byte(self.prev), s);
        let b = blank_byte(s.beam);
        for _ in 1..n {
            self.put(word, b, s);
        }
        self.prev = s.beam;
    }

    fn steps<S: Steps>(&mut self, steps: &mut S, n: usize) {
        let n = self.room(n);
        if n == 0 {
            return;
        }
        let (x, y) = steps.step();
        let s = Sample::new(x, y, Beam::On);
        self.put(dac_word(s), blank_byte(self.prev), s);
        let b = blank_byte(Beam::On);
        for _ in 1..n {
            let (x, y) = steps.step();
            let s = Sample::new(x, y, Beam::On);
            self.put(dac_word(s), b, s);
        }
        self.prev = Beam::On;
    }
}

#[cfg(feature = "qemu")]
mod cpu {
    //! The output under QEMU: the same API as the DMA path, without a
    //! sample clock. Halves are handed out at once. Every sample is written
    //! to the first half of the buffers as the DMA path writes them
    //! ([`super::write_slots`]: QEMU's instruction counts are the board's
    //! refill work); while recording, the CPU also writes it to the DAC and
    //! the blank pin.

    use super::{DmaError, Filled, HALF, Out, write_slots};
    use isoscope_core::output::{Beam, SampleSource, Samples};

    /// The running output.
    pub struct Streaming {
        out: Out,
        /// The next slot of the current half.
        slot: usize,
        /// The beam of the last sample written.
        last_beam: Beam,
        recording: bool,
    }

    impl Out {
        /// Start the output (not recording).
        pub fn start(self) -> Streaming {
            Streaming { out: self, slot: 0, last_beam: Beam::Off, recording: false }
        }
    }

    impl Streaming {
        /// As the DMA path's: fill the current half from `samples`.
        // Not inlined: a call a half costs nothing, and the refill is then
        // one function that `scripts/firmware-profile` can time run by run.
        #[inline(never)]
        pub fn fill_from(&mut self, samples: &mut impl SampleSource) -> Result<Filled, DmaError> {
            let Self { out, slot, last_beam, recording } = self;
            let recording = *recording;
            // SAFETY of the writes: nothing reads the buffers under QEMU.
            // The bench build never records: its refill is the DMA path's
            // alone, without a test of the flag a sample.
            let next = if cfg!(feature = "bench") {
                write_slots(samples, *slot, HALF, last_beam, |_| {})
            } else {
                write_slots(samples, *slot, HALF, last_beam, |s| {
                    if recording {
                        out.write(s);
                    }
                })
            };
            if next < HALF {
                *slot = next;
                return Ok(Filled::FrameEnd);
            }
            *slot = 0;
            Ok(Filled::Half)
        }

        /// As the DMA path's: finish the current half with the park sample.
        pub fn pad(&mut self) -> Result<(), DmaError> {
            let park = self.out.park;
            self.fill_from(&mut Samples(core::iter::repeat(park))).map(drop)
        }

        /// Write the samples played from now on to the DAC and the blank
        /// pin (or stop).
        pub fn record(&mut self, on: bool) {
            self.recording = on;
        }

        /// Park and blank the beam now (a marker in the log).
        pub fn park(&mut self) {
            self.out.park();
        }

        /// Halves refilled late: none without a sample clock.
        pub fn late(&self) -> u32 {
            0
        }

        /// As the DMA path's: the configured rate (there is no sample clock
        /// to slow).
        pub fn sample_rate_hz(&self) -> u32 {
            super::SAMPLE_RATE_HZ
        }

        /// As the DMA path's (there is no sample clock).
        pub fn restart_pacing(&mut self) {}

        /// As the DMA path's: always, without a sample clock.
        pub fn ready(&self) -> bool {
            true
        }

        /// As the DMA path's: finish the current half with the park sample
        /// before a long redraw.
        pub fn hold(&mut self) -> Result<(), DmaError> {
            if self.slot > 0 { self.pad() } else { Ok(()) }
        }

        /// As the DMA path's.
        pub fn release(&mut self) {}
    }
}

#[cfg(not(feature = "qemu"))]
mod dma {
    //! The DMA output path (see the module docs of `board`).

    use super::{
        BLANK, DAC_CH2, DAC_DMAEN1, DAC_EN1, DAC_TEN1, DAC_TSEL1_TIM8, DmaError, Filled, HALF,
        MIN_SAMPLE_RATE_HZ, Out, SAMPLE_RATE_HZ, XY, pac, write_slots,
    };
    use core::sync::atomic::{AtomicU8, AtomicU32, Ordering};
    use isoscope_core::beam::pace::{self, PaceConfig, Pacer};
    use isoscope_core::output::{Beam, SampleSource, Samples};
    use stm32f4xx_hal::interrupt;

    /// Halves the DMA has finished with (bit 0: first, bit 1: second), set
    /// by the interrupt, cleared by the main loop as it refills them.
    static FREE: AtomicU8 = AtomicU8::new(0);
    /// Set by the interrupt on a DMA transfer error.
    static ERROR: AtomicU8 = AtomicU8::new(0);
    /// Halves the interrupt found still unfilled (the main loop was late).
    static LATE: AtomicU32 = AtomicU32::new(0);

    // DMA1 HISR/HIFCR bits of stream 5.
    const S5_TE: u32 = 1 << 9;
    const S5_HT: u32 = 1 << 10;
    const S5_TC: u32 = 1 << 11;
    const S5_ALL: u32 = 0b11_1101 << 6;
    // DMA2 LISR/LIFCR bits of stream 1.
    const S1_TE: u32 = 1 << 9;
    const S1_ALL: u32 = 0b11_1101 << 6;

    /// The running output: the DMA streams play the buffers, the main loop
    /// refills them.
    pub struct Streaming {
        out: Out,
        /// The beam of the last sample written (the blank buffer runs one
        /// slot behind the X/Y buffer).
        last_beam: Beam,
        /// The half being filled and the next slot in it, if any.
        open: Option<(usize, usize)>,
        /// The late count when the beam was held ([`Self::hold`]).
        planned: u32,
        /// Late refills while the beam was held.
        forgiven: u32,
        /// The sample clock's period (TIM8's ARR + 1), slowed when a
        /// picture's refill cannot keep up.
        pacer: Pacer,
        /// Halves whose refill is not reported to the pacer: the first
        /// ones after the beam was held (they were free long before).
        unmeasured: u8,
    }

    impl Out {
        /// Fill the whole double buffer with the park sample (blanked),
        /// then start the sample clock.
        pub fn start(mut self) -> Streaming {
            // The first update event outputs the DAC's current holding
            // register: the park sample.
            self.park();
            let ticks = |hz: u32| (self.timer_hz / hz).max(1);
            let pace = PaceConfig {
                half: HALF as u32,
                fastest: ticks(SAMPLE_RATE_HZ),
                slowest: ticks(MIN_SAMPLE_RATE_HZ),
            };
            let Ok(pacer) = Pacer::new(pace) else { super::fault() };
            let mut st = Streaming {
                out: self,
                last_beam: Beam::Off,
                open: None,
                planned: 0,
                forgiven: 0,
                pacer,
                unmeasured: 0,
            };
            for half in 0..2 {
                let park = st.out.park;
                st.write(half, 0, &mut Samples(core::iter::repeat(park)));
            }
            st.arm();
            st
        }
    }

    impl Streaming {
        /// Write samples into half `half` of both buffers from slot `from`
        /// until the half is full or `samples` ends ([`write_slots`]).
        /// Returns the next slot of the half.
        fn write(&mut self, half: usize, from: usize, samples: &mut impl SampleSource) -> usize {
            // The DMA is not reading this half.
            write_slots(samples, half * HALF + from, (half + 1) * HALF, &mut self.last_beam, |_| ())
                - half * HALF
        }

        /// Fill the open half from `samples`, waiting for the DMA to free a
        /// half first if none is open. Returns [`Filled::Half`] when the
        /// half is full and handed to the DMA, [`Filled::FrameEnd`] when
        /// `samples` ran out first (the half stays open for the next
        /// frame), or `Err` after a DMA error (the beam is then parked and
        /// blanked).
        pub fn fill_from(&mut self, samples: &mut impl SampleSource) -> Result<Filled, DmaError> {
            let (half, from) = match self.open {
                Some(open) => open,
                None => (self.wait()?, 0),
            };
            let to = self.write(half, from, samples);
            if to < HALF {
                self.open = Some((half, to));
                return Ok(Filled::FrameEnd);
            }
            self.open = None;
            FREE.fetch_and(!(1 << half), Ordering::SeqCst);
            self.pace(half);
            Ok(Filled::Half)
        }

        /// Half `half` is refilled: tell the pacer how much of the other
        /// half the DMA has played meanwhile, and set the period it asks
        /// for (at the next update event: ARR is preloaded).
        fn pace(&mut self, half: usize) {
            if self.unmeasured > 0 {
                self.unmeasured -= 1;
                return;
            }
            let Some((tim8, dma1, _)) = self.out.dma.as_ref() else { super::fault() };
            // NDTR counts the words left in the circular buffer's round:
            // the DMA reads slot `2 * HALF - NDTR` next.
            let next = (2 * HALF).saturating_sub(dma1.st(5).ndtr().read().bits() as usize);
            if let Some(period) = self.pacer.filled(pace::played(next, half, HALF)) {
                tim8.arr().write(|w| unsafe { w.bits(period - 1) });
            }
        }

        /// The refill became cheap for good (a replayed frame): the sample
        /// clock back to [`SAMPLE_RATE_HZ`] at once ([`Pacer::restart`]).
        pub fn restart_pacing(&mut self) {
            let Some((tim8, _, _)) = self.out.dma.as_ref() else { super::fault() };
            if let Some(period) = self.pacer.restart() {
                tim8.arr().write(|w| unsafe { w.bits(period - 1) });
            }
        }

        /// The sample rate in force (the pacer slows it for a picture
        /// whose refill cannot keep up at [`SAMPLE_RATE_HZ`]).
        pub fn sample_rate_hz(&self) -> u32 {
            self.pacer.rate_hz(self.out.timer_hz)
        }

        /// Fill the rest of the open half (or a whole free one) with the
        /// park sample and hand it to the DMA: for a picture with no
        /// samples.
        pub fn pad(&mut self) -> Result<(), DmaError> {
            let park = self.out.park;
            self.fill_from(&mut Samples(core::iter::repeat(park))).map(drop)
        }

        /// Configure TIM8, the DAC trigger and both DMA streams, and start.
        fn arm(&mut self) {
            let Some((tim8, dma1, dma2)) = self.out.dma.as_ref() else { super::fault() };
            let dac = &self.out.dac;
            // TIM8: update event at SAMPLE_RATE_HZ, as TRGO and as a DMA request.
            let arr = self.pacer.period() - 1;
            tim8.cr1().write(|w| unsafe { w.bits(0) });
            tim8.psc().write(|w| unsafe { w.bits(0) });
            tim8.arr().write(|w| unsafe { w.bits(arr) });
            tim8.cr2().write(|w| unsafe { w.mms().bits(0b010) });
            tim8.dier().write(|w| w.ude().set_bit());

            // DMA1 stream 5, channel 7 (DAC1): X/Y buffer -> DHR12RD.
            let s5 = dma1.st(5);
            s5.cr().write(|w| unsafe { w.bits(0) });
            while s5.cr().read().en().bit_is_set() {}
            dma1.hifcr().write(|w| unsafe { w.bits(S5_ALL) });
            s5.par().write(|w| unsafe { w.bits(dac.dhr12rd().as_ptr() as u32) });
            s5.m0ar().write(|w| unsafe { w.bits(XY.0.get() as u32) });
            s5.ndtr().write(|w| unsafe { w.bits(2 * HALF as u32) });
            s5.cr().write(|w| unsafe {
                w.chsel().bits(7);
                w.pl().very_high();
                w.msize().bits32();
                w.psize().bits32();
                w.minc().incremented();
                w.circ().enabled();
                w.dir().memory_to_peripheral();
                w.htie().enabled();
                w.tcie().enabled();
                w.teie().enabled()
            });

            // DMA2 stream 1, channel 7 (TIM8_UP): blank buffer -> the low
            // byte of GPIOB's ODR (little-endian: its address), a byte a
            // sample.
            let s1 = dma2.st(1);
            s1.cr().write(|w| unsafe { w.bits(0) });
            while s1.cr().read().en().bit_is_set() {}
            dma2.lifcr().write(|w| unsafe { w.bits(S1_ALL) });
            // SAFETY: a read of the register block's address.
            let odr = unsafe { (*pac::GPIOB::ptr()).odr().as_ptr() as u32 };
            s1.par().write(|w| unsafe { w.bits(odr) });
            s1.m0ar().write(|w| unsafe { w.bits(BLANK.0.get() as u32) });
            s1.ndtr().write(|w| unsafe { w.bits(2 * HALF as u32) });
            s1.cr().write(|w| unsafe {
                w.chsel().bits(7);
                w.pl().very_high();
                w.msize().bits8();
                w.psize().bits8();
                w.minc().incremented();
                w.circ().enabled();
                w.dir().memory_to_peripheral();
                w.teie().enabled()
            });

            // DAC: both channels triggered by TIM8 TRGO, DMA request on
            // channel 1 only (one DHR12RD word serves both).
            let trig = DAC_EN1 | DAC_TEN1 | DAC_TSEL1_TIM8;
            dac.cr().write(|w| unsafe { w.bits(trig | DAC_DMAEN1 | (trig << DAC_CH2)) });

            FREE.store(0, Ordering::SeqCst);
            s1.cr().modify(|_, w| w.en().enabled());
            s5.cr().modify(|_, w| w.en().enabled());
            // SAFETY: the handlers only touch the statics above and the
            // DMA flags; unmasking cannot break a critical section here.
            unsafe {
                cortex_m::peripheral::NVIC::unmask(pac::Interrupt::DMA1_STREAM5);
                cortex_m::peripheral::NVIC::unmask(pac::Interrupt::DMA2_STREAM1);
            }
            // ARR preloaded: the pacer's new periods start at an update
            // event (a shorter ARR written mid-period would otherwise let
            // the counter run past it, round the whole 16 bits).
            tim8.cr1().write(|w| w.arpe().set_bit().cen().set_bit());
        }

        /// Whether [`Self::fill_from`] would start at once (a half is open
        /// or free): the main loop does other work until then.
        pub fn ready(&self) -> bool {
            self.open.is_some() || FREE.load(Ordering::SeqCst) != 0 || ERROR.load(Ordering::SeqCst) != 0
        }

        /// Wait for a free half; returns it.
        fn wait(&mut self) -> Result<usize, DmaError> {
            loop {
                if ERROR.load(Ordering::SeqCst) != 0 {
                    super::emergency_park();
                    return Err(DmaError);
                }
                let free = cortex_m::interrupt::free(|_| {
                    let free = FREE.load(Ordering::SeqCst);
                    if free == 0 {
                        // Sleeps until an interrupt is pending, even while
                        // masked here: no wake-up is lost.
                        cortex_m::asm::wfi();
                    }
                    free
                });
                match free {
                    0 => {}
                    1 => return Ok(0),
                    2 => return Ok(1),
                    // Both: the main loop was late (or held the beam), and
                    // the DMA is reading one of them again by now. Take the
                    // other (NDTR counts down: above HALF, it is in the
                    // first half) and forget the one being read (the
                    // interrupt frees it again when it is done).
                    _ => {
                        let Some((_, dma1, _)) = self.out.dma.as_ref() else { super::fault() };
                        let reading = if dma1.st(5).ndtr().read().bits() as usize > HALF { 0 } else { 1 };
                        FREE.fetch_and(!(1 << reading), Ordering::SeqCst);
                        return Ok(1 - reading);
                    }
                }
            }
        }

        /// Park and blank the beam for a while: fill the open half and the
        /// next free one with the park sample, so that the DMA plays only
        /// the park sample until the main loop refills again (before a
        /// long redraw: better a blank screen than a stale half buffer
        /// replayed). Takes up to three half buffers' time (1.5 ms): an
        /// open half is finished, and refilled whole once the DMA has
        /// played it.
        pub fn hold(&mut self) -> Result<(), DmaError> {
            if self.open.is_some() {
                self.pad()?;
            }
            self.pad()?;
            self.pad()?;
            self.planned = LATE.load(Ordering::Relaxed);
            Ok(())
        }

        /// Stop counting the refills that come late after [`Self::hold`]
        /// as late.
        pub fn release(&mut self) {
            let late = LATE.load(Ordering::Relaxed);
            self.forgiven = self.forgiven.wrapping_add(late.wrapping_sub(self.planned));
            self.unmeasured = 2;
        }

        /// Halves refilled too late so far (not counting the beam held
        /// parked on purpose, [`Self::hold`]).
        pub fn late(&self) -> u32 {
            LATE.load(Ordering::Relaxed).wrapping_sub(self.forgiven)
        }
    }

    #[interrupt]
    fn DMA1_STREAM5() {
        // SAFETY: reads the status and writes the clear register only.
        let dma1 = unsafe { &*pac::DMA1::ptr() };
        let flags = dma1.hisr().read().bits();
        dma1.hifcr().write(|w| unsafe { w.bits(flags & S5_ALL) });
        if flags & S5_TE != 0 {
            ERROR.store(1, Ordering::SeqCst);
        }
        for (flag, half) in [(S5_HT, 1u8), (S5_TC, 2u8)] {
            if flags & flag != 0 && FREE.fetch_or(half, Ordering::SeqCst) & half != 0 {
                LATE.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    #[interrupt]
    fn DMA2_STREAM1() {
        // SAFETY: reads the status and writes the clear register only.
        let dma2 = unsafe { &*pac::DMA2::ptr() };
        let flags = dma2.lisr().read().bits() & S1_ALL;
        dma2.lifcr().write(|w| unsafe { w.bits(flags) });
        // Only the transfer error interrupt is enabled on this stream (the
        // other flags are set all the same, and cleared here).
        if flags & S1_TE != 0 {
            ERROR.store(2, Ordering::SeqCst);
        }
    }
}
