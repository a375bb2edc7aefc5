//! The device engine on arbitrary UART bytes: no panic, no hang, every
//! answer a valid frame, every sample in the DAC range, and afterwards a
//! clean volume shows exactly the picture a fresh engine shows.
//!
//! The clean volume sets the view and beam first (the noise may have set
//! them, validly: the order of the picture depends on them), and a fresh
//! engine is sent the same bytes.
//!
//! Input: one configuration byte (the feed chunk size, 1..=64, and the clock
//! step per chunk: 0, 2, 4 or 6 s, so that transfers time out), then the
//! bytes on the line. An even chunk size runs the engine as the firmware
//! does, contouring deferred (`defer_contouring`): bytes the engine does not
//! take yet are fed again after a few rows of `contour`. Every chunk is
//! followed by `update`, a transmit, and every third chunk by the frame on
//! screen as the board plays it (`Engine::replay_frames`: scheduled and
//! recorded, then replayed), through `split` while the next chunk is fed,
//! as the firmware does; it must equal the engine's frame.
#![no_main]

use isoscope_core::command::{Command, Point3};
use isoscope_core::engine::{Engine, EngineConfig};
use isoscope_core::output::Sample;
use isoscope_core::wire::{
    AXIS_X, AXIS_Y, AXIS_Z, FrameDecoder, Levels, Message, PROTOCOL_VERSION, SampleType, encode,
};
use isoscope_fuzz::EngineMem;
use libfuzzer_sys::fuzz_target;
use std::sync::OnceLock;

/// The most samples of a frame played and compared. A recording here lives
/// in the 2 KB of slice memory, two bytes a lit sample: a frame longer than
/// some thousand samples is not kept and plays live on both sides, where
/// comparing more of it only runs the scheduler twice (20,000 samples cost
/// a quarter of a run's time, most of it coverage callbacks).
const MAX_FRAME: usize = 4096;

/// The fewest line bytes fed between two frames played and compared.
/// Every third chunk is played through, but not more often than this:
/// with one-byte chunks a frame every third byte made playing the same
/// frame again most of a run, while the engine's state changes at most
/// once a frame on the line (some 20 bytes and up).
const FRAME_EVERY_BYTES: usize = 48;

/// A small volume every run ends with: 4x3x3, so that checking it (a
/// contouring, a commit and the surface compared) costs a fraction of a
/// run (a 6x5x4 one took some three quarters of the engine target's
/// instructions).
fn clean_volume() -> Vec<u8> {
    let mut out = vec![0u8];
    let mut push = |m: &Message<'_>| {
        let mut buf = [0u8; 1100];
        out.extend_from_slice(encode(m, &mut buf).expect("encodes"));
    };
    push(&Message::Hello { protocol: PROTOCOL_VERSION, firmware: [0, 0, 0], seq: 7 });
    // The view and beam the noise may have set (validly) are set again:
    // the picture's order depends on them.
    let view = isoscope_core::view::View::DEFAULT;
    push(&Message::SetView {
        seq: 7,
        yaw: view.yaw,
        pitch: view.pitch,
        roll: view.roll,
        fov_deg: 0.0,
        spin_deg_per_s: 0.0,
    });
    push(&Message::SetBeam { seq: 8, lit_step: 40, dwell_us: 2, settle_us: 40 });
    let (nx, ny, nz) = (4u16, 3u16, 3u16);
    push(&Message::BeginVolume {
        seq: 9,
        dims: [nx, ny, nz],
        sample_type: SampleType::U8,
        spacing: [1.0, 1.0, 1.0],
        levels: Levels::from_slice(&[50.5, 100.0]).expect("two levels"),
        axes: AXIS_X | AXIS_Y | AXIS_Z,
        every: 1,
    });
    for z in 0..nz {
        let slice: Vec<u8> = (0..nx * ny).map(|i| ((i * 37 + z * 91) % 160) as u8).collect();
        push(&Message::SliceData { seq: 10 + z, slice: z, offset: 0, data: &slice });
    }
    push(&Message::EndVolume { seq: 10 + nz });
    out
}

fn config() -> EngineConfig {
    EngineConfig::default()
}

/// Feed `bytes`: at once, or, deferring, around `contour` calls. Returns
/// what is left when the contouring waits for the engine's update
/// ([`Link::waits`](isoscope_core::engine::Link::waits)).
fn feed_all<'b>(link: &mut isoscope_core::engine::Link<'_, '_>, mut bytes: &'b [u8], now: u32) -> &'b [u8] {
    let mut idle = 0;
    while !bytes.is_empty() {
        if link.waits() {
            return bytes;
        }
        if link.busy() {
            link.contour(3);
            continue;
        }
        let n = link.feed(bytes, now);
        bytes = &bytes[n..];
        idle = if n == 0 { idle + 1 } else { 0 };
        assert!(idle < 2, "feed took nothing while no work was pending");
    }
    bytes
}

/// Feed all of `bytes`, with an update whenever the contouring waits for
/// one (a board's next frame boundary).
fn feed_updating(e: &mut Engine<'_>, mut bytes: &[u8], now: u32) {
    for _ in 0..64 {
        bytes = feed_all(&mut e.split().0, bytes, now);
        if bytes.is_empty() {
            return;
        }
        e.update(now);
    }
    panic!("the contouring waited on after 64 updates");
}

fn surface(e: &Engine<'_>) -> Vec<Command<[u32; 3]>> {
    let key = |p: Point3| [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()];
    e.surface().map(|g| g.commands().map(|c| c.map(key)).collect()).unwrap_or_default()
}

/// What a fresh engine shows for the clean volume.
fn expected() -> &'static Vec<Command<[u32; 3]>> {
    static WANT: OnceLock<Vec<Command<[u32; 3]>>> = OnceLock::new();
    WANT.get_or_init(|| {
        let mut mem = EngineMem::new();
        let mut e = Engine::new(config(), mem.buffers()).expect("engine");
        e.feed(&clean_volume(), 0);
        e.update(0);
        let s = surface(&e);
        assert!(!s.is_empty());
        s
    })
}

/// Drain the answers and check each is a valid frame.
fn drain(e: &mut Engine<'_>, dec: &mut FrameDecoder<256>) {
    let mut out = [0u8; 64];
    loop {
        let n = e.transmit(&mut out);
        if n == 0 {
            return;
        }
        for &b in &out[..n] {
            if let Some(r) = dec.push(b) {
                assert!(r.is_ok(), "the engine sent a bad frame: {r:?}");
            }
        }
    }
}

fuzz_target!(|data: &[u8]| {
    let Some((&cfg, line)) = data.split_first() else { return };
    let chunk = 1 + usize::from(cfg % 64);
    let step = u32::from(cfg >> 6) * 2000;
    let defer = chunk % 2 == 0;
    let mut mem = EngineMem::new();
    let mut e =
        Engine::new(EngineConfig { defer_contouring: defer, ..config() }, mem.buffers()).expect("engine");
    e.replay_frames(true);
    let mut dec = FrameDecoder::<256>::new();
    let mut now = 0u32;
    let mut since_frame = FRAME_EVERY_BYTES;
    for (k, c) in line.chunks(chunk).enumerate() {
        now = now.wrapping_add(step);
        since_frame += c.len();
        if k % 3 == 0 && since_frame >= FRAME_EVERY_BYTES {
            since_frame = 0;
            // The frame as the board plays it (scheduled, recorded or
            // replayed) is the engine's frame, sample for sample.
            let live: Vec<Sample> = e.frame().take(MAX_FRAME).collect();
            let (mut link, mut screen) = e.split();
            let mut frame = screen.frame();
            let mut played: Vec<Sample> = frame.by_ref().take(100).collect();
            let rest = feed_all(&mut link, c, now);
            played.extend(frame.take(MAX_FRAME - played.len()));
            // Every coordinate within 12 bits: one comparison of their
            // bits together, not two a sample (each a coverage callback).
            assert!(played.iter().fold(0, |m, s| m | s.x | s.y) <= 4095);
            assert_eq!(played, live, "the board's frame is not the engine's");
            if !rest.is_empty() {
                e.update(now);
                feed_updating(&mut e, rest, now);
            }
        } else {
            feed_updating(&mut e, c, now);
        }
        e.update(now);
        drain(&mut e, &mut dec);
    }
    // Recovery: a clean volume shows exactly what it shows on a fresh engine.
    // Its first byte, a frame delimiter, may complete a frame the noise left
    // (an `EndVolume` makes that volume the picture at the next `update`,
    // and until then new volume data is `Busy`, which a sender retries):
    // the update a board makes at its next frame boundary comes first.
    now = now.wrapping_add(1);
    // The slice memory back from the replay (a board's sender would be
    // answered Busy once, and retry: core/tests/engine.rs).
    e.replay_frames(false);
    let clean = clean_volume();
    let (delimiter, frames) = clean.split_at(1);
    feed_updating(&mut e, delimiter, now);
    e.update(now);
    feed_updating(&mut e, frames, now);
    e.update(now);
    drain(&mut e, &mut dec);
    assert_eq!(&surface(&e), expected(), "a clean volume after the noise shows something else");
});
