//! The engine's memory: every buffer of [`Buffers`], in statics split
//! between SRAM and the core-coupled memory, lent once to the one
//! [`Engine`]. A change of `Buffers`' shape stays in this module.
//!
//! Sizes ([`isoscope_scene`]: `S` = [`SLICE_BYTES`],
//! `P` = [`isoscope_scene::POINTS`]):
//!
//! | buffer | bytes | where |
//! |---|---|---|
//! | slices, twice (the stitching and ordering scratch between volumes) | `2 S` = 64 KB | CCM |
//! | two surfaces: points (6 B) and their kinds (2 bits) | `12.5 P` = 102,400 | SRAM |
//! | the rows around the cells being contoured, and what the last two slices' rows share ([`RowMemory`]) | 3.2 KB | SRAM |
//!
//! The CCM (64 KB at 0x1000_0000) is reachable by the CPU only, which is
//! all the engine needs; the DMA buffers of the output path stay in SRAM.
//! The two slices fill it exactly. cortex-m-rt neither loads nor zeroes the
//! CCM (section `.ccmram`, NOLOAD, placed by `ccmram.x`), so its buffers
//! are zeroed here, at run time, before they are lent.
//!
//! QEMU's netduinoplus2 (7.2) has no CCM (a write there is a bus fault) but
//! maps all 192 KB of the STM32F405's SRAM at 0x2000_0000, so under the
//! `qemu` feature everything is in SRAM, with the same sizes (`build.rs`
//! links that build with a 192 KB RAM region).

use core::mem::MaybeUninit;
use core::sync::atomic::{AtomicBool, Ordering};
use isoscope_core::engine::{Buffers, Engine, EngineError, RowMemory};
use isoscope_scene::{SLICE_BYTES, SURFACE_BYTES, engine_config};

/// The slices, in the core-coupled memory (in SRAM under QEMU).
struct Ccm {
    slices: [u8; 2 * SLICE_BYTES],
}

/// The rest, in SRAM (.bss, zeroed by cortex-m-rt).
struct Sram {
    surfaces: [[u8; SURFACE_BYTES]; 2],
    rows: RowMemory,
}

/// Bytes of engine memory in the CCM (in SRAM under QEMU).
pub const CCM_BYTES: usize = core::mem::size_of::<Ccm>();
/// Bytes of engine memory in SRAM.
pub const SRAM_BYTES: usize = core::mem::size_of::<Sram>();
#[cfg(not(feature = "qemu"))]
const _: () = assert!(CCM_BYTES <= 64 * 1024, "the CCM holds 64 KB");

#[cfg_attr(not(feature = "qemu"), unsafe(link_section = ".ccmram"))]
static mut CCM: MaybeUninit<Ccm> = MaybeUninit::uninit();

static mut SRAM: Sram = Sram { surfaces: [[0; SURFACE_BYTES]; 2], rows: RowMemory::new() };

/// The engine itself (its frame decoder, answer and event queues), in
/// SRAM rather than on the stack.
static mut ENGINE: MaybeUninit<Engine<'static>> = MaybeUninit::uninit();

/// Bytes of the engine itself.
pub const ENGINE_BYTES: usize = core::mem::size_of::<Engine<'static>>();

/// The engine over all of its memory, with the firmware's settings
/// ([`engine_config`]). Returns `None` if called twice.
// Not inlined: `Engine::new` builds the engine (some 2.6 KB) on the stack
// before it is moved into its static, and that frame must be gone before
// the main loop starts.
#[inline(never)]
pub fn engine() -> Option<Result<&'static mut Engine<'static>, EngineError>> {
    static TAKEN: AtomicBool = AtomicBool::new(false);
    if TAKEN.swap(true, Ordering::SeqCst) {
        return None;
    }
    // SAFETY: reached once (TAKEN), so these are the only references to
    // the two statics. Every field of `Ccm` is plain data (integers) for
    // which all-zero bytes are a valid value, so zeroing the uninitialised
    // CCM makes it an initialised `Ccm`.
    let (ccm, sram) = unsafe {
        let ccm = &mut *core::ptr::addr_of_mut!(CCM);
        ccm.as_mut_ptr().write_bytes(0, 1);
        (ccm.assume_init_mut(), &mut *core::ptr::addr_of_mut!(SRAM))
    };
    let [front, back] = &mut sram.surfaces;
    let buffers = Buffers { slices: &mut ccm.slices, rows: &mut sram.rows, front, back, scratch: &mut [] };
    Some(Engine::new(engine_config(), buffers).map(|engine| {
        // SAFETY: reached once (TAKEN): the only reference to ENGINE.
        unsafe { (*core::ptr::addr_of_mut!(ENGINE)).write(engine) }
    }))
}
