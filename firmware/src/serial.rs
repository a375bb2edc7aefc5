//! The host link: USART2 (PA2 TX, PA3 RX, AF7), 8N1, received by the RXNE
//! interrupt into a lock-free single-producer single-consumer ring
//! ([`heapless::spsc::Queue`], [`RX_QUEUE`] bytes), transmitted from a
//! second ring by the TXE interrupt.
//!
//! The ring holds what arrives while the main loop is busy (contouring a
//! slice inside `Link::feed`, redrawing in `update`):
//! at 921,600 baud that is 92 bytes a millisecond. A byte that finds the
//! ring full is dropped and counted ([`Stats::dropped`]); the host
//! retransmits the frame it spoiled (go-back-N), so an overflow costs time,
//! never the picture.
//!
//! Under QEMU (feature `qemu`) the baud rate is ignored and TXE is always
//! set (QEMU 7.2 raises no TXE interrupt): [`Tx::pump`] then writes the
//! whole ring from the main loop. QEMU's USART model offers the next byte
//! only once the last one is read, so there a full ring holds the byte in
//! the data register instead ([`HOLD_BACK`]): the interrupt masks itself
//! in the NVIC and [`Rx::read`] unmasks it, and nothing is lost however
//! long the main loop is busy. (On a board the line does not wait: a held byte would
//! overrun the next one, so there a byte that finds the ring full is
//! dropped.)

use core::cell::RefCell;
use core::sync::atomic::{AtomicU32, Ordering};
use cortex_m::interrupt::Mutex;
use heapless::spsc::{Consumer, Producer, Queue};
use stm32f4xx_hal::{interrupt, pac};

/// Bytes the receive ring holds (one slot of the queue stays empty): a
/// whole send window (8 frames of at most 1,049 bytes) and then some, so
/// that what the host may have in flight fits while the engine is busy.
#[cfg(not(feature = "qemu"))]
pub const RX_QUEUE: usize = 9 * 1024;
/// Under QEMU, whose USART model holds back bytes until the last one is
/// read (no loss), a smaller ring leaves the stack more room.
#[cfg(feature = "qemu")]
pub const RX_QUEUE: usize = 4 * 1024;
/// A full receive ring leaves the byte in the data register and masks the
/// interrupt until the main loop has read (QEMU only: see the module
/// documentation).
const HOLD_BACK: bool = cfg!(feature = "qemu");

/// Bytes the transmit ring holds.
pub const TX_QUEUE: usize = 512;

// USART_SR and USART_CR1 bits (RM0090 30.6).
const SR_ORE: u16 = 1 << 3;
const SR_RXNE: u16 = 1 << 5;
const SR_TXE: u16 = 1 << 7;
const CR1_RE: u16 = 1 << 2;
const CR1_TE: u16 = 1 << 3;
const CR1_RXNEIE: u16 = 1 << 5;
const CR1_TXEIE: u16 = 1 << 7;
const CR1_UE: u16 = 1 << 13;

static mut RX: Queue<u8, { RX_QUEUE + 1 }> = Queue::new();
static mut TX: Queue<u8, { TX_QUEUE + 1 }> = Queue::new();
/// The interrupt's ends of the rings: it fills the receive ring and
/// empties the transmit ring.
type IsrEnds = (Producer<'static, u8, { RX_QUEUE + 1 }>, Consumer<'static, u8, { TX_QUEUE + 1 }>);
/// The interrupt's ends, handed over once by [`init`].
static ISR_ENDS: Mutex<RefCell<Option<IsrEnds>>> = Mutex::new(RefCell::new(None));

static DROPPED: AtomicU32 = AtomicU32::new(0);
static OVERRUNS: AtomicU32 = AtomicU32::new(0);
static RECEIVED: AtomicU32 = AtomicU32::new(0);

/// Counts since start.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub struct Stats {
    /// Bytes received.
    pub received: u32,
    /// Bytes dropped because the receive ring was full.
    pub dropped: u32,
    /// Bytes lost in the USART (overrun: the interrupt came too late).
    pub overruns: u32,
}

/// The main loop's end of the receive ring.
pub struct Rx {
    rx: Consumer<'static, u8, { RX_QUEUE + 1 }>,
}

/// The main loop's end of the transmit ring.
pub struct Tx {
    tx: Producer<'static, u8, { TX_QUEUE + 1 }>,
}

fn usart2() -> &'static pac::usart1::RegisterBlock {
    // SAFETY: the USART2 registers are only touched here: the interrupt
    // reads SR and DR and writes DR and CR1; the main loop writes CR1 and
    // DR with the interrupt masked.
    unsafe { &*pac::USART2::ptr() }
}

/// Enable USART2 at `baud` on a bus clock of `pclk1_hz` (the pins must be
/// in AF7 already), receiving by interrupt from now on. Call once, early:
/// bytes that arrive before are lost.
pub fn init(usart: pac::USART2, pclk1_hz: u32, baud: u32) -> (Rx, Tx) {
    // The clock is enabled by the caller (board::init).
    // SAFETY: called once (the caller gives up USART2, of which there is
    // one); the queues are split here and never touched directly again.
    let (rx_p, rx_c) = unsafe { (*core::ptr::addr_of_mut!(RX)).split() };
    let (tx_p, tx_c) = unsafe { (*core::ptr::addr_of_mut!(TX)).split() };
    cortex_m::interrupt::free(|cs| ISR_ENDS.borrow(cs).replace(Some((rx_p, tx_c))));
    // Oversampling by 16: BRR = f_PCLK / baud, rounded (mantissa and
    // fraction in 1/16ths).
    let brr = (pclk1_hz + baud / 2) / baud;
    usart.brr().write(|w| unsafe { w.bits(brr.min(0xffff) as u16) });
    usart.cr2().write(|w| unsafe { w.bits(0) });
    usart.cr3().write(|w| unsafe { w.bits(0) });
    usart.cr1().write(|w| unsafe { w.bits(CR1_UE | CR1_TE | CR1_RE | CR1_RXNEIE) });
    // SAFETY: the handler only touches the interrupt's ring ends and the
    // USART; unmasking cannot break a critical section here.
    unsafe { cortex_m::peripheral::NVIC::unmask(pac::Interrupt::USART2) };
    (Rx { rx: rx_c }, Tx { tx: tx_p })
}

/// The baud rate USART2 really runs at for `baud` on `pclk1_hz`, in bit/s.
pub fn actual_baud(pclk1_hz: u32, baud: u32) -> u32 {
    let brr = (pclk1_hz + baud / 2) / baud;
    pclk1_hz / brr.max(1)
}

impl Rx {
    /// Move received bytes into `buf`; returns how many.
    pub fn read(&mut self, buf: &mut [u8]) -> usize {
        let mut n = 0;
        for slot in buf.iter_mut() {
            let Some(b) = self.rx.dequeue() else { break };
            *slot = b;
            n += 1;
        }
        if HOLD_BACK && n > 0 {
            // There is room again: take the held byte (if any).
            // SAFETY: as in `init`.
            unsafe { cortex_m::peripheral::NVIC::unmask(pac::Interrupt::USART2) };
        }
        n
    }
}

impl Tx {
    /// Room in the transmit ring.
    pub fn room(&self) -> usize {
        self.tx.capacity() - self.tx.len()
    }

    /// Queue `bytes` (as many as fit; returns how many) and start sending.
    pub fn write(&mut self, bytes: &[u8]) -> usize {
        let mut n = 0;
        for &b in bytes {
            if self.tx.enqueue(b).is_err() {
                break;
            }
            n += 1;
        }
        self.pump();
        n
    }

    /// Start sending what is queued: enable the TXE interrupt, which sends
    /// the ring and disables itself when it is empty. (Under QEMU, which
    /// raises no TXE interrupt, the interrupt handler is called from here.)
    pub fn pump(&mut self) {
        if self.tx.len() == 0 {
            return;
        }
        cortex_m::interrupt::free(|_| {
            usart2().cr1().modify(|r, w| unsafe { w.bits(r.bits() | CR1_TXEIE) });
        });
        #[cfg(feature = "qemu")]
        cortex_m::interrupt::free(service);
    }

    /// Bytes not yet handed to the USART.
    #[cfg(feature = "qemu")]
    pub fn pending(&self) -> usize {
        self.tx.len()
    }
}

/// Counts since start.
pub fn stats() -> Stats {
    Stats {
        received: RECEIVED.load(Ordering::Relaxed),
        dropped: DROPPED.load(Ordering::Relaxed),
        overruns: OVERRUNS.load(Ordering::Relaxed),
    }
}

/// Take every received byte and send queued bytes while the USART has room.
fn service(cs: &cortex_m::interrupt::CriticalSection) {
    let usart = usart2();
    let mut ends = ISR_ENDS.borrow(cs).borrow_mut();
    let Some((rx, tx)) = ends.as_mut() else { return };
    loop {
        let sr = usart.sr().read().bits();
        let mut busy = false;
        if HOLD_BACK && sr & SR_RXNE != 0 && !rx.ready() {
            // Leave the byte in DR until the main loop makes room. (QEMU
            // lowers the interrupt line only when DR is read, so it is the
            // NVIC that masks it.)
            cortex_m::peripheral::NVIC::mask(pac::Interrupt::USART2);
        } else if sr & (SR_RXNE | SR_ORE) != 0 {
            // Reading SR then DR clears RXNE and ORE.
            let b = usart.dr().read().bits() as u8;
            if sr & SR_ORE != 0 {
                OVERRUNS.fetch_add(1, Ordering::Relaxed);
            }
            if sr & SR_RXNE != 0 {
                RECEIVED.fetch_add(1, Ordering::Relaxed);
                if rx.enqueue(b).is_err() {
                    DROPPED.fetch_add(1, Ordering::Relaxed);
                }
            }
            busy = true;
        }
        if sr & SR_TXE != 0 && usart.cr1().read().bits() & CR1_TXEIE != 0 {
            match tx.dequeue() {
                Some(b) => {
                    usart.dr().write(|w| unsafe { w.bits(u16::from(b)) });
                    busy = true;
                }
                None => {
                    usart.cr1().modify(|r, w| unsafe { w.bits(r.bits() & !CR1_TXEIE) });
                }
            }
        }
        if !busy {
            return;
        }
    }
}

#[interrupt]
fn USART2() {
    cortex_m::interrupt::free(service);
}
