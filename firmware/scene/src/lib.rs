//! The firmware's boot picture and engine settings, in code that both the
//! firmware and the host compile.
//!
//! The board is the core's device engine ([`isoscope_core::engine`]) behind
//! the UART. At boot it feeds its own engine the built-in volume (the
//! hydrogen 3d_xy orbital, the paper's Figure 1, at 12^3) as the host would
//! send it: `BeginVolume`, one `SliceData` per z slice, `EndVolume`
//! ([`boot_frames`]). So the boot picture costs no memory beside the
//! engine's, goes through exactly the code a received volume goes through,
//! and stays on screen until a host sends a volume.
//!
//! `no_std`, no `alloc`, no `unsafe`, `libm` maths: the MCU and the host
//! compute bit-identical samples. The QEMU end-to-end test relies on this
//! (firmware/host-ref runs the same engine with the same capacities).
#![no_std]
#![forbid(unsafe_code)]
#![warn(missing_docs)]
#![deny(clippy::panic, clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]

use isoscope_core::demo::Demo;
use isoscope_core::engine::{Board, EngineConfig, Geometry};
use isoscope_core::wire::{
    AXIS_X, AXIS_Y, AXIS_Z, Levels, MAX_FRAME_LEN, Message, SampleType, WireError, encode,
};

/// The built-in volume.
pub const DEMO: Demo = Demo::Hydrogen;
/// Its side, in samples (`SIDE`^3 voxels).
pub const SIDE: usize = 12;

/// The board as the core names it ([`Board::F407`]): its capacities and
/// sample clock, which the host simulator's `--board f407` applies too.
pub const BOARD: Board = Board::F407;

/// Bytes of the largest z slice the board takes (`nx * ny * sample size`):
/// 128x128 `u8`, `u16` or `i16`, or 90x90 `f32` (`nx` and `ny` at most
/// [`EXTENT`]). What a volume's two slices leave free holds the pieces of
/// its surface that the received surface has no room for (hydrogen 32^3,
/// 32x32 `f32` slices: 4,624 of its 12,816); between volumes the slice
/// buffers are the scratch for stitching and ordering the surface (about
/// 7 bytes a point): 64 KB order all [`POINTS`].
pub const SLICE_BYTES: usize = BOARD.capacity.slice_bytes;
/// The largest `nx` or `ny`.
pub const EXTENT: usize = BOARD.capacity.extent;
/// Points each of the two surfaces holds (6 bytes each, and 2 bits of
/// kind): the limit on picture complexity. A volume's pieces as contoured
/// are about 1.75 times its picture's points (stitching joins them at
/// their shared ends, merging thins collinear runs); those that do not
/// fit the received surface spill into the slice memory its slices leave
/// free. Both surfaces take 102,400 bytes of SRAM. The boot scene has 936
/// (after stitching).
pub const POINTS: usize = BOARD.capacity.points;
/// Bytes of each surface: [`POINTS`] points of 6 bytes and their kinds
/// (2 bits each).
pub const SURFACE_BYTES: usize = Geometry::bytes_for(POINTS);

/// Frames the firmware plays under QEMU for each picture it checks (the
/// boot picture, then the first volume received).
pub const QEMU_FRAMES: usize = 2;

/// DAC samples per second (both channels and the blank pin).
pub const SAMPLE_RATE_HZ: u32 = BOARD.sample_rate_hz;

/// The slowest sample rate the board's pacer ([`isoscope_core::beam::pace`])
/// may choose for a picture whose refill cannot keep up with
/// [`SAMPLE_RATE_HZ`]: a half buffer then lasts 3.2 ms (537,600 cycles).
/// The costliest refill measured is the first frame of gyroid 32^3,
/// scheduled and recorded for replay (`scripts/firmware-bench`: 413,501
/// est. cycles in its worst half, 77% of that); at 250 kS/s (2 ms) it was
/// late, and the DMA would have played a stale half.
pub const MIN_SAMPLE_RATE_HZ: u32 = 160_000;

/// The firmware's version, reported in `Hello`.
pub const FIRMWARE_VERSION: [u8; 3] = [0, 1, 0];

/// The engine's settings: the core's defaults (view, beam, passes, the
/// 5 s transfer timeout), the firmware's version and sample rate, and
/// contouring deferred ([`EngineConfig::defer_contouring`]: the main loop
/// contours a completed slice a few rows at a time between DMA refills, so the
/// display keeps refreshing). The simulator's virtual board (`isoscope-sim
/// device`) uses the same defaults but contours at once, which gives the
/// same surface: both draw the same samples for the same volume.
pub fn engine_config() -> EngineConfig {
    EngineConfig { firmware: FIRMWARE_VERSION, defer_contouring: true, ..BOARD.engine_config() }
}

/// Rows of a boot slice per `SliceData` chunk.
const BOOT_ROWS: usize = 3;
/// Bytes of one chunk of a boot slice (`f32`): `BOOT_ROWS` rows.
const BOOT_CHUNK: usize = BOOT_ROWS * SIDE * 4;
/// Bytes of an encoded boot frame: the chunk and a `SliceData` header,
/// CRC, COBS overhead and delimiter, with room to spare (checked by
/// `encode`, which fails rather than overflow).
const BOOT_FRAME: usize = BOOT_CHUNK + 64;
const _: () = assert!(SIDE % BOOT_ROWS == 0 && BOOT_FRAME <= MAX_FRAME_LEN);

/// The frames that put the boot volume on screen, each handed to `feed`
/// (delimiter included): `BeginVolume` (seq 0; the demo's level, every
/// plane, unit spacing), `SliceData` chunks of [`BOOT_ROWS`] rows, z slice
/// after z slice, `EndVolume`. Feed them to the engine, then drop its
/// answers. The samples are computed a chunk at a time ([`Demo::sample`]),
/// so this needs about 0.5 KB of stack and no volume buffer: the firmware
/// boots with the stack its main loop needs.
///
/// # Errors
/// Only if a frame cannot be encoded (never, for these sizes).
pub fn boot_frames(mut feed: impl FnMut(&[u8])) -> Result<(), WireError> {
    let mut buf = [0u8; BOOT_FRAME];
    let mut data = [0u8; BOOT_CHUNK];
    let side = SIDE as u16;
    let levels = Levels::from_slice(&[DEMO.default_level()]).unwrap_or_default();
    let begin = Message::BeginVolume {
        seq: 0,
        dims: [side; 3],
        sample_type: SampleType::F32,
        spacing: [1.0; 3],
        levels,
        axes: AXIS_X | AXIS_Y | AXIS_Z,
        every: 1,
    };
    feed(encode(&begin, &mut buf)?);
    let mut seq = 1;
    for k in 0..SIDE {
        for row in (0..SIDE).step_by(BOOT_ROWS) {
            for (idx, bytes) in data.chunks_exact_mut(4).enumerate() {
                let (i, j) = (idx % SIDE, row + idx / SIDE);
                bytes.copy_from_slice(&DEMO.sample(SIDE, i, j, k).to_le_bytes());
            }
            let offset = (row * SIDE * 4) as u32;
            let chunk = Message::SliceData { seq, slice: k as u16, offset, data: &data };
            feed(encode(&chunk, &mut buf)?);
            seq += 1;
        }
    }
    feed(encode(&Message::EndVolume { seq }, &mut buf)?);
    Ok(())
}
