//! The MCP4922 driver against embedded-hal-mock transaction lists.
//!
//! The SPI and pin mocks check each device's own sequence (and `.done()`
//! checks nothing is left over); thin wrappers also log every bus and pin
//! write in one shared list, so the tests can check the order *across*
//! devices (Z before or after the SPI words, /LDAC around them).

use std::cell::RefCell;
use std::rc::Rc;

use embedded_hal::digital::{ErrorType as PinErrorType, OutputPin};
use embedded_hal::spi::{self, ErrorKind, Operation, SpiDevice};
use embedded_hal_mock::eh1::MockError;
use embedded_hal_mock::eh1::digital::{Mock as PinMock, State, Transaction as PinTx};
use embedded_hal_mock::eh1::spi::{Mock as SpiMock, Transaction as SpiTx};
use isoscope_core::output::mcp4922::{
    Channel, Config, Gain, MAX_CODE, Mcp4922, NoPin, SpiDacError, VrefBuffer, ZPolarity,
};
use isoscope_core::output::{Beam, Dac, Sample};

const ON: Beam = Beam::On;
const OFF: Beam = Beam::Off;

/// One write on the bus or a pin, in the order the driver made it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Ev {
    /// An SPI transaction writing this 16-bit word (as two bytes, MSB first).
    Spi(u16),
    Z(State),
    Ldac(State),
}
use Ev::{Ldac, Spi, Z};
const HI: State = State::High;
const LO: State = State::Low;

type Log = Rc<RefCell<Vec<Ev>>>;

/// The SPI mock, logging its writes; fails the `fail_at`-th transaction
/// (0-based) with `ErrorKind::Other` without passing it to the mock.
struct LoggedSpi {
    mock: SpiMock<u8>,
    log: Log,
    count: usize,
    fail_at: Option<usize>,
}

impl spi::ErrorType for LoggedSpi {
    type Error = ErrorKind;
}

impl SpiDevice<u8> for LoggedSpi {
    fn transaction(&mut self, ops: &mut [Operation<'_, u8>]) -> Result<(), ErrorKind> {
        let n = self.count;
        self.count += 1;
        if self.fail_at == Some(n) {
            return Err(ErrorKind::Other);
        }
        for op in ops.iter() {
            match op {
                Operation::Write([hi, lo]) => self.log.borrow_mut().push(Spi(u16::from_be_bytes([*hi, *lo]))),
                other => panic!("unexpected SPI operation {other:?}"),
            }
        }
        self.mock.transaction(ops)
    }
}

/// A pin mock, logging its writes as `Z` or `Ldac`.
struct LoggedPin {
    mock: PinMock,
    log: Log,
    ev: fn(State) -> Ev,
}

impl PinErrorType for LoggedPin {
    type Error = MockError;
}

impl OutputPin for LoggedPin {
    fn set_low(&mut self) -> Result<(), MockError> {
        self.log.borrow_mut().push((self.ev)(LO));
        self.mock.set_low()
    }

    fn set_high(&mut self) -> Result<(), MockError> {
        self.log.borrow_mut().push((self.ev)(HI));
        self.mock.set_high()
    }
}

/// The mock transactions of one SpiDevice write of `word`.
fn word(word: u16) -> [SpiTx<u8>; 3] {
    [SpiTx::transaction_start(), SpiTx::write_vec(word.to_be_bytes().to_vec()), SpiTx::transaction_end()]
}

/// The SPI expectations for these words, in order.
fn spi_expect(words: &[u16]) -> Vec<SpiTx<u8>> {
    words.iter().flat_map(|&w| word(w)).collect()
}

/// The pin expectations for these levels (an error on the `err_at`-th).
fn pin_expect(levels: &[State], err_at: Option<usize>) -> Vec<PinTx> {
    levels
        .iter()
        .enumerate()
        .map(|(i, &s)| {
            let tx = PinTx::set(s);
            if err_at == Some(i) { tx.with_error(pin_error()) } else { tx }
        })
        .collect()
}

fn pin_error() -> MockError {
    MockError::Io(std::io::ErrorKind::NotConnected)
}

/// Expectations for one driver, and the shared log.
struct Rig {
    log: Log,
    spi: LoggedSpi,
    z: LoggedPin,
}

impl Rig {
    fn new(words: &[u16], z: &[State]) -> Self {
        Self::with_z_error(words, z, None)
    }

    fn with_z_error(words: &[u16], z: &[State], err_at: Option<usize>) -> Self {
        let log = Log::default();
        let spi =
            LoggedSpi { mock: SpiMock::new(&spi_expect(words)), log: log.clone(), count: 0, fail_at: None };
        let z = LoggedPin { mock: PinMock::new(&pin_expect(z, err_at)), log: log.clone(), ev: Z };
        Self { log, spi, z }
    }

    fn ldac(&self, levels: &[State], err_at: Option<usize>) -> LoggedPin {
        LoggedPin { mock: PinMock::new(&pin_expect(levels, err_at)), log: self.log.clone(), ev: Ldac }
    }

    /// A driver without /LDAC.
    fn dac(self, config: Config) -> (Mcp4922<LoggedSpi, LoggedPin, NoPin<MockError>>, Log) {
        (Mcp4922::new(self.spi, self.z, NoPin::new(), config), self.log)
    }
}

/// Release the driver and check every mock played out.
fn finish<L>(dac: Mcp4922<LoggedSpi, LoggedPin, L>) -> L
where
    L: OutputPin<Error = MockError>,
{
    let (mut spi, mut z, ldac) = dac.release();
    spi.mock.done();
    z.mock.done();
    ldac
}

fn events(log: &Log) -> Vec<Ev> {
    log.borrow().clone()
}

/// A Z pin that is high while the beam is lit (`BlankActiveLow`): the
/// polarity most of these tests were written for.
fn lit_high() -> Config {
    Config::new().with_z_polarity(ZPolarity::BlankActiveLow)
}

#[test]
fn command_words() {
    let c = Config::new();
    assert_eq!(c, Config::default());
    // Blanked while high, as the firmware's blank pin and wav's beam.
    assert_eq!(c.z_polarity, ZPolarity::BlankActiveHigh);
    assert_eq!(c.command_word(Channel::A, 0x123), 0x3123);
    assert_eq!(c.command_word(Channel::B, 0xABC), 0xBABC);
    assert_eq!(c.command_word(Channel::A, 0), 0x3000);
    assert_eq!(c.command_word(Channel::B, MAX_CODE), 0xBFFF);
    let buffered = c.with_vref_buffer(VrefBuffer::Buffered);
    assert_eq!(buffered.command_word(Channel::A, 0x123), 0x7123);
    let x2 = c.with_gain(Gain::X2);
    assert_eq!(x2.command_word(Channel::A, 0x123), 0x1123);
    assert_eq!(x2.with_vref_buffer(VrefBuffer::Buffered).command_word(Channel::B, 0x123), 0xD123);
    // Only the 12 data bits are taken from the code.
    assert_eq!(c.command_word(Channel::A, 0xF123), 0x3123);
}

#[test]
fn exact_spi_words() {
    let rig = Rig::new(&[0x3123, 0xBABC, 0x3000, 0xB000, 0x3FFF, 0xBFFF, 0x3800, 0xB001], &[LO]);
    let (mut dac, log) = rig.dac(lit_high());
    dac.write([
        Sample::new(0x123, 0xABC, OFF),
        Sample::new(0, 0, OFF),
        Sample::new(4095, 4095, OFF),
        Sample::new(2048, 1, OFF),
    ])
    .unwrap();
    assert_eq!(
        events(&log),
        [
            Z(LO),
            Spi(0x3123),
            Spi(0xBABC),
            Spi(0x3000),
            Spi(0xB000),
            Spi(0x3FFF),
            Spi(0xBFFF),
            Spi(0x3800),
            Spi(0xB001)
        ]
    );
    finish(dac);
}

#[test]
fn config_bits_reach_the_bus() {
    // Blanked: Z high, the default polarity.
    let rig = Rig::new(&[0x5123, 0xDABC], &[HI]);
    let config = Config::new().with_gain(Gain::X2).with_vref_buffer(VrefBuffer::Buffered);
    let (mut dac, _log) = rig.dac(config);
    assert_eq!(dac.config(), config);
    dac.write_sample(Sample::new(0x123, 0xABC, OFF)).unwrap();
    finish(dac);
}

#[test]
fn z_only_on_change_and_in_order_blank_active_low() {
    let rig = Rig::new(
        &[
            0x3001, 0xB001, // off (first sample: Z driven)
            0x3002, 0xB002, // off
            0x3002, 0xB002, // on
            0x3003, 0xB003, // on
            0x3004, 0xB004, // off
            0x3005, 0xB005, // on
        ],
        &[LO, HI, LO, HI],
    );
    let (mut dac, log) = rig.dac(lit_high());
    assert_eq!(dac.beam(), None);
    dac.write([
        Sample::new(1, 1, OFF),
        Sample::new(2, 2, OFF),
        Sample::new(2, 2, ON),
        Sample::new(3, 3, ON),
        Sample::new(4, 4, OFF),
        Sample::new(5, 5, ON),
    ])
    .unwrap();
    assert_eq!(dac.beam(), Some(ON));
    assert_eq!(
        events(&log),
        [
            Z(LO), // blank before the first move
            Spi(0x3001),
            Spi(0xB001),
            Spi(0x3002),
            Spi(0xB002),
            Spi(0x3002),
            Spi(0xB002),
            Z(HI), // Off -> On: after X and Y
            Spi(0x3003),
            Spi(0xB003),
            Z(LO), // On -> Off: before the move
            Spi(0x3004),
            Spi(0xB004),
            Spi(0x3005),
            Spi(0xB005),
            Z(HI),
        ]
    );
    finish(dac);
}

#[test]
fn z_only_on_change_and_in_order_by_default_blank_active_high() {
    let rig = Rig::new(&[0x3007, 0xB007, 0x3008, 0xB008, 0x3009, 0xB009, 0x300A, 0xB00A], &[LO, HI, LO]);
    let (mut dac, log) = rig.dac(Config::new());
    dac.write([
        Sample::new(7, 7, ON),
        Sample::new(8, 8, ON),
        Sample::new(9, 9, OFF),
        Sample::new(10, 10, ON),
    ])
    .unwrap();
    assert_eq!(
        events(&log),
        [
            Spi(0x3007),
            Spi(0xB007),
            Z(LO), // unknown -> On: after the move, low lights (high blanks)
            Spi(0x3008),
            Spi(0xB008),
            Z(HI), // On -> Off: high blanks, before the move
            Spi(0x3009),
            Spi(0xB009),
            Spi(0x300A),
            Spi(0xB00A),
            Z(LO),
        ]
    );
    finish(dac);
}

#[test]
fn blank_drives_z_once() {
    let rig = Rig::new(&[0x3001, 0xB001, 0x3001, 0xB001], &[LO, HI, LO]);
    let (mut dac, log) = rig.dac(lit_high());
    dac.blank().unwrap();
    dac.blank().unwrap(); // already off: no pin write
    dac.write_sample(Sample::new(1, 1, OFF)).unwrap();
    dac.write_sample(Sample::new(1, 1, ON)).unwrap();
    dac.blank().unwrap();
    assert_eq!(dac.beam(), Some(OFF));
    assert_eq!(events(&log), [Z(LO), Spi(0x3001), Spi(0xB001), Spi(0x3001), Spi(0xB001), Z(HI), Z(LO)]);
    finish(dac);
}

#[test]
fn ldac_pulses_after_both_words() {
    let rig = Rig::new(&[0x3123, 0xBABC, 0x3456, 0xB789, 0x3000, 0xB000], &[HI, LO]);
    let ldac = rig.ldac(&[HI, LO, HI, LO, HI, LO], None);
    let log = rig.log.clone();
    let mut dac = Mcp4922::new(rig.spi, rig.z, ldac, lit_high());
    dac.write([Sample::new(0x123, 0xABC, ON), Sample::new(0x456, 0x789, ON), Sample::new(0, 0, OFF)])
        .unwrap();
    assert_eq!(
        events(&log),
        [
            Ldac(HI), // hold the outputs
            Spi(0x3123),
            Spi(0xBABC),
            Ldac(LO), // X and Y change together
            Z(HI),    // then light the beam
            Ldac(HI),
            Spi(0x3456),
            Spi(0xB789),
            Ldac(LO),
            Z(LO), // blank before the move
            Ldac(HI),
            Spi(0x3000),
            Spi(0xB000),
            Ldac(LO),
        ]
    );
    let mut ldac = finish(dac);
    ldac.mock.done();
}

#[test]
fn out_of_range_before_any_traffic() {
    for (x, y) in [(4096, 0), (0, 4096), (u16::MAX, u16::MAX)] {
        let rig = Rig::new(&[], &[]);
        let ldac = rig.ldac(&[], None);
        let log = rig.log.clone();
        let mut dac = Mcp4922::new(rig.spi, rig.z, ldac, lit_high());
        assert_eq!(dac.write([Sample::new(x, y, ON)]), Err(SpiDacError::OutOfRange { x, y }));
        assert_eq!(dac.write_sample(Sample::new(x, y, OFF)), Err(SpiDacError::OutOfRange { x, y }));
        assert_eq!(dac.beam(), None);
        assert_eq!(events(&log), []);
        let mut ldac = finish(dac);
        ldac.mock.done();
    }
}

#[test]
fn out_of_range_stops_the_write_after_earlier_samples() {
    let rig = Rig::new(&[0x3FFF, 0xBFFF], &[HI]);
    let (mut dac, log) = rig.dac(lit_high());
    let result =
        dac.write([Sample::new(4095, 4095, ON), Sample::new(4095, 4096, OFF), Sample::new(1, 1, ON)]);
    assert_eq!(result, Err(SpiDacError::OutOfRange { x: 4095, y: 4096 }));
    // The bad sample did not even blank the beam; the one after it never ran.
    assert_eq!(events(&log), [Spi(0x3FFF), Spi(0xBFFF), Z(HI)]);
    assert_eq!(dac.beam(), Some(ON));
    finish(dac);
}

#[test]
fn spi_error_propagates_and_stops_the_sample() {
    // Transaction 0 (X of the first sample) fails: Z must not light.
    let mut rig = Rig::new(&[0x3002, 0xB002], &[HI]);
    rig.spi.fail_at = Some(0);
    let (mut dac, log) = rig.dac(lit_high());
    assert_eq!(
        dac.write([Sample::new(1, 1, ON), Sample::new(2, 2, ON)]),
        Err(SpiDacError::Spi(ErrorKind::Other))
    );
    assert_eq!(events(&log), []);
    assert_eq!(dac.beam(), None);
    // The next write goes on normally.
    dac.write_sample(Sample::new(2, 2, ON)).unwrap();
    assert_eq!(events(&log), [Spi(0x3002), Spi(0xB002), Z(HI)]);
    finish(dac);
}

#[test]
fn spi_error_on_y_leaves_ldac_high() {
    let mut rig = Rig::new(&[0x3001], &[LO]);
    rig.spi.fail_at = Some(1);
    let ldac = rig.ldac(&[HI], None);
    let log = rig.log.clone();
    let mut dac = Mcp4922::new(rig.spi, rig.z, ldac, lit_high());
    assert_eq!(dac.write_sample(Sample::new(1, 1, OFF)), Err(SpiDacError::Spi(ErrorKind::Other)));
    // /LDAC stays high: the half-written sample never reaches the outputs.
    assert_eq!(events(&log), [Z(LO), Ldac(HI), Spi(0x3001)]);
    let mut ldac = finish(dac);
    ldac.mock.done();
}

#[test]
fn z_pin_error_propagates_and_is_retried() {
    // Z fails when lighting: the state is unknown, so the next lit sample
    // drives Z again even though it was asked for On already.
    let rig = Rig::with_z_error(&[0x3001, 0xB001, 0x3002, 0xB002, 0x3003, 0xB003], &[HI, HI, LO], Some(0));
    let (mut dac, log) = rig.dac(lit_high());
    assert_eq!(dac.write([Sample::new(1, 1, ON), Sample::new(9, 9, ON)]), Err(SpiDacError::Pin(pin_error())));
    assert_eq!(dac.beam(), None);
    dac.write_sample(Sample::new(2, 2, ON)).unwrap();
    assert_eq!(dac.beam(), Some(ON));
    dac.write_sample(Sample::new(3, 3, OFF)).unwrap();
    assert_eq!(
        events(&log),
        [
            Spi(0x3001),
            Spi(0xB001),
            Z(HI), // fails
            Spi(0x3002),
            Spi(0xB002),
            Z(HI),
            Z(LO),
            Spi(0x3003),
            Spi(0xB003),
        ]
    );
    finish(dac);
}

#[test]
fn z_error_when_blanking_stops_before_the_move() {
    let rig = Rig::with_z_error(&[], &[LO], Some(0));
    let (mut dac, log) = rig.dac(lit_high());
    assert_eq!(dac.write_sample(Sample::new(5, 5, OFF)), Err(SpiDacError::Pin(pin_error())));
    assert_eq!(events(&log), [Z(LO)]);
    finish(dac);
}

#[test]
fn ldac_error_propagates() {
    let rig = Rig::new(&[0x3001, 0xB001], &[]);
    let ldac = rig.ldac(&[HI, LO], Some(1));
    let mut dac = Mcp4922::new(rig.spi, rig.z, ldac, lit_high());
    assert_eq!(dac.write_sample(Sample::new(1, 1, ON)), Err(SpiDacError::Pin(pin_error())));
    assert_eq!(dac.beam(), None); // Z never lit
    let mut ldac = finish(dac);
    ldac.mock.done();
}

#[test]
fn release_returns_the_parts() {
    let rig = Rig::new(&[0x3001, 0xB001], &[LO]);
    let ldac = rig.ldac(&[HI, LO], None);
    let mut dac = Mcp4922::new(rig.spi, rig.z, ldac, lit_high());
    dac.write_sample(Sample::new(1, 1, OFF)).unwrap();
    let (mut spi, mut z, mut ldac) = dac.release();
    // The same mocks, with their expectations played out.
    assert_eq!(spi.count, 2);
    spi.mock.done();
    z.mock.done();
    ldac.mock.done();
}

#[test]
fn no_pin_and_errors_display() {
    let mut pin: NoPin = NoPin::new();
    assert_eq!(pin.set_low(), Ok(()));
    assert_eq!(pin.set_high(), Ok(()));
    assert_eq!(pin, NoPin::default());
    assert_eq!(format!("{pin:?}"), "NoPin");

    type E = SpiDacError<ErrorKind, MockError>;
    let e: E = SpiDacError::OutOfRange { x: 4096, y: 3 };
    assert_eq!(e.to_string(), "sample (4096, 3) is outside the 12-bit DAC range 0..=4095");
    assert!(E::Spi(ErrorKind::Other).to_string().starts_with("SPI error"));
    assert!(E::Pin(pin_error()).to_string().contains("pin error"));
    let _: &dyn core::error::Error = &e;
}

#[test]
fn works_through_a_mut_reference() {
    let rig = Rig::new(&[0x3001, 0xB001], &[LO]);
    let (mut dac, _log) = rig.dac(lit_high());
    fn play<D: Dac>(mut d: D) -> Result<(), D::Error> {
        d.write([Sample::new(1, 1, OFF)])
    }
    play(&mut dac).unwrap();
    finish(dac);
}
