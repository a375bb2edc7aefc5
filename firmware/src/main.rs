//! isoscope firmware: a contour surface on an XY oscilloscope, from an
//! STM32F407G-DISC1 (see `board` for the pins and the output path).
//!
//! For now it draws a built-in scene (the hydrogen 3d_xy orbital at 12^3,
//! [`isoscope_scene`]) forever: the display list is built once at boot, then
//! the beam scheduler refills the DMA double buffer frame after frame. The
//! UART link comes with the device engine.
//!
//! Under the `qemu` feature it plays [`isoscope_scene::QEMU_FRAMES`] frames
//! from the CPU and exits QEMU, for the end-to-end test
//! (`scripts/firmware-qemu-test`).
#![no_std]
#![no_main]

mod board;

use core::sync::atomic::{AtomicBool, Ordering};
use cortex_m_rt::{ExceptionFrame, entry, exception};
use isoscope_scene::Buffers;
use panic_probe as _;

#[cfg(not(feature = "qemu"))]
use defmt_rtt as _;
#[cfg(feature = "qemu")]
use defmt_semihosting as _;

/// Watchdog timeout while the scene is built (the longest stretch without
/// feeding it; LSI tolerance can shorten it to about 0.7 of this).
const BUILD_WATCHDOG_MS: u32 = 3_000;
/// Watchdog timeout while streaming (fed every half buffer, 512 us).
#[cfg(not(feature = "qemu"))]
const RUN_WATCHDOG_MS: u32 = 50;

/// The scene's buffers (89 KB, zero-initialised in .bss: never on the
/// stack), handed out once.
fn buffers() -> &'static mut Buffers {
    static TAKEN: AtomicBool = AtomicBool::new(false);
    static mut BUFFERS: Buffers = Buffers::new();
    if TAKEN.swap(true, Ordering::SeqCst) {
        board::fault();
    }
    // SAFETY: reached once (TAKEN), so this is the only reference.
    unsafe { &mut *core::ptr::addr_of_mut!(BUFFERS) }
}

#[entry]
fn main() -> ! {
    let mut board = board::init(BUILD_WATCHDOG_MS);
    let beam = isoscope_scene::beam_config();
    board.out.set_park(beam.park_sample());
    board.out.park();
    defmt::info!(
        "isoscope: {} Hz core, {} samples/s; building the scene",
        board.sysclk_hz,
        board::SAMPLE_RATE_HZ
    );

    let buf = buffers();
    let built = match isoscope_scene::build(buf) {
        Ok(b) => b,
        Err(_) => {
            defmt::error!("isoscope: the built-in scene failed to build");
            board::fault();
        }
    };
    board.watchdog.feed();
    defmt::info!(
        "isoscope: {} fragments ({} points) -> {} polylines ({} points), {} dropped; frame {} samples ({} lit)",
        built.fragments,
        built.points_in,
        built.optimize.polylines,
        built.optimize.points_out,
        built.dropped,
        built.frame_samples,
        built.lit_samples,
    );
    let list = &buf.list;
    let mut samples = isoscope_scene::refresh(list, &beam);

    #[cfg(feature = "qemu")]
    {
        let n = usize::try_from(built.frame_samples).unwrap_or(0) * isoscope_scene::QEMU_FRAMES;
        for s in samples.by_ref().take(n) {
            board.out.write(s);
        }
        board.out.park();
        defmt::info!("isoscope: played {} samples, exiting", n);
        board::exit(true);
    }

    #[cfg(not(feature = "qemu"))]
    {
        use stm32f4xx_hal::prelude::*;
        board.watchdog.start(RUN_WATCHDOG_MS.millis());
        let mut out = board.out.start(&mut samples);
        let mut late = 0;
        loop {
            if !out.refill(&mut samples) {
                defmt::error!("isoscope: DMA transfer error; beam parked, waiting for the watchdog");
                board::fault();
            }
            board.watchdog.feed();
            if out.late() != late {
                late = out.late();
                defmt::warn!("isoscope: {} half buffers refilled late", late);
            }
        }
    }
}

#[exception]
unsafe fn HardFault(_frame: &ExceptionFrame) -> ! {
    board::fault()
}
