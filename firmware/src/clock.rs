//! Time for the engine: SysTick interrupts at 1 kHz count milliseconds
//! (wrapping, as the engine takes them); [`cycles`] adds the SysTick
//! counter for sub-millisecond timing.
//!
//! SysTick runs on the core clock, on the board and under QEMU (whose
//! netduinoplus2 clocks it at 168 MHz, like the board; the DWT cycle counter
//! is not modelled there). Under QEMU with `-icount shift=0` the virtual
//! clock advances 1 ns per instruction, so [`cycles`] then counts
//! instructions times 0.168.

use core::sync::atomic::{AtomicU32, Ordering};
use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::{SCB, SYST};
use cortex_m_rt::exception;

static MS: AtomicU32 = AtomicU32::new(0);
static RELOAD: AtomicU32 = AtomicU32::new(0);
/// The last value [`cycles`] returned.
static LAST: AtomicU32 = AtomicU32::new(0);

/// Start the millisecond clock on a core clock of `core_hz`.
pub fn start(mut syst: SYST, core_hz: u32) {
    let reload = core_hz / 1_000 - 1;
    RELOAD.store(reload, Ordering::Relaxed);
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(reload);
    syst.clear_current();
    syst.enable_interrupt();
    syst.enable_counter();
    // SYST is given up here: from now on the exception and `cycles` only
    // read it.
}

/// Milliseconds since [`start`], wrapping.
pub fn now_ms() -> u32 {
    MS.load(Ordering::Relaxed)
}

/// Core clock cycles since [`start`], wrapping (about 25 s at 168 MHz),
/// from the main loop (not from interrupts).
pub fn cycles() -> u32 {
    let reload = RELOAD.load(Ordering::Relaxed);
    loop {
        let ms = MS.load(Ordering::SeqCst);
        let val = SYST::get_current().min(reload);
        let pending = SCB::is_pendst_pending();
        // A tick counted between the reads: read again.
        if MS.load(Ordering::SeqCst) != ms {
            continue;
        }
        // The counter wrapped but the exception has not run yet (masked,
        // or not yet taken): count its millisecond.
        let ms = if pending && val > reload / 2 { ms.wrapping_add(1) } else { ms };
        let now = ms.wrapping_mul(reload + 1).wrapping_add(reload - val);
        // Never backwards: QEMU raises the exception a little after the
        // counter wraps (the pending bit is not set yet either), which
        // would read as a millisecond back. (Called from the main loop
        // only.)
        let last = LAST.load(Ordering::Relaxed);
        if now.wrapping_sub(last) > u32::MAX / 2 {
            return last;
        }
        LAST.store(now, Ordering::Relaxed);
        return now;
    }
}

#[exception]
fn SysTick() {
    MS.fetch_add(1, Ordering::Relaxed);
}
