//! The device engine: streaming equals whole-volume contouring, the picture
//! survives every kind of bad transfer, retransmissions are answered without
//! being applied twice, and no input panics.

use isoscope_core::command::{Command, Point3};
use isoscope_core::contour::grid::{Planes, Volume};
use isoscope_core::contour::surface::{SliceId, SurfaceSink, contour_slice, contour_volume};
use isoscope_core::contour::trace::Traversal;
use isoscope_core::demo::Demo;
use isoscope_core::engine::{
    AbortReason, Buffers, Engine, EngineConfig, Event, Geometry, Packed, StaticBuffers,
};
use isoscope_core::output::SampleSource;
use isoscope_core::path::Stride;
use isoscope_core::wire::{
    AXIS_X, AXIS_Y, AXIS_Z, DeviceState, FrameDecoder, Levels, MAX_CHUNK, Message, NackCode,
    PROTOCOL_VERSION, SampleType, encode,
};
use proptest::prelude::*;

#[path = "common/cobs.rs"]
mod cobs;
#[path = "common/segments.rs"]
mod segments;
use cobs::cobs;
use segments::{Seg, segments};
use std::collections::HashSet;
use std::convert::Infallible;

/// Engine memory on the heap, for tests.
struct Mem {
    slices: Vec<u8>,
    rows: Box<isoscope_core::engine::RowMemory>,
    front: Vec<u8>,
    back: Vec<u8>,
    scratch: Vec<u8>,
}

impl Mem {
    /// Slices of `slice` bytes, surfaces of `points`, and scratch to stitch
    /// and order them all.
    fn new(slice: usize, points: usize) -> Self {
        Self::sized(2 * slice, [points; 2], 8 * points)
    }

    /// `slices` bytes of slice memory in all, a front and a back of
    /// `points`, and `scratch` bytes more.
    fn sized(slices: usize, [front, back]: [usize; 2], scratch: usize) -> Self {
        Self {
            slices: vec![0; slices],
            rows: Box::default(),
            front: vec![0; Geometry::bytes_for(front)],
            back: vec![0; Geometry::bytes_for(back)],
            scratch: vec![0; scratch],
        }
    }

    fn buffers(&mut self) -> Buffers<'_> {
        Buffers {
            slices: &mut self.slices,
            rows: &mut self.rows,
            front: &mut self.front,
            back: &mut self.back,
            scratch: &mut self.scratch,
        }
    }
}

/// The firmware's engine memory: slices of 32 KB, surfaces of
/// 8,192 points, no more scratch.
type Firmware = StaticBuffers<{ 32 * 1024 }, { Geometry::bytes_for(8192) }>;

/// A volume to send.
#[derive(Clone)]
struct Vol {
    dims: [u16; 3],
    ty: SampleType,
    bytes: Vec<u8>,
    values: Vec<f32>,
    levels: Vec<f32>,
    axes: u8,
    every: u8,
}

impl Vol {
    /// A demo volume quantised to `ty` (u8/u16 scaled to 0..=200 or 0..=40000).
    fn demo(demo: Demo, n: usize, ty: SampleType) -> Self {
        let mut values = vec![0.0; n * n * n];
        demo.fill(n, &mut values).unwrap();
        let (lo, hi) = values.iter().fold((f32::MAX, f32::MIN), |(a, b), &v| (a.min(v), b.max(v)));
        let scale = |v: f32, top: f32| ((v - lo) / (hi - lo) * top).round();
        let mut bytes = Vec::new();
        for v in &mut values {
            match ty {
                SampleType::U8 => {
                    *v = scale(*v, 200.0);
                    bytes.push(*v as u8);
                }
                SampleType::U16 => {
                    *v = scale(*v, 40000.0);
                    bytes.extend((*v as u16).to_le_bytes());
                }
                SampleType::I16 => {
                    *v = scale(*v, 40000.0) - 20000.0;
                    bytes.extend((*v as i16).to_le_bytes());
                }
                SampleType::F32 => bytes.extend(v.to_le_bytes()),
            }
        }
        let mid = |t: f32| lo + (hi - lo) * t;
        let levels = match ty {
            SampleType::U8 => vec![60.5, 120.0],
            SampleType::U16 => vec![15000.0],
            SampleType::I16 => vec![-5000.0, 2500.5],
            SampleType::F32 => vec![mid(0.3), mid(0.55)],
        };
        let d = n as u16;
        Self { dims: [d, d, d], ty, bytes, values, levels, axes: AXIS_X | AXIS_Y | AXIS_Z, every: 1 }
    }

    /// This volume at the corner of slices `nx` x `ny` (at least its
    /// own), the rest `fill` (a value below or above every level).
    fn padded(&self, nx: u16, ny: u16, fill: f32) -> Self {
        let [ix, iy, iz] = self.dims.map(usize::from);
        let (nx, ny) = (usize::from(nx).max(ix), usize::from(ny).max(iy));
        let size = self.ty.size();
        let fill_bytes: Vec<u8> = match self.ty {
            SampleType::U8 => vec![fill as u8],
            SampleType::U16 => (fill as u16).to_le_bytes().to_vec(),
            SampleType::I16 => (fill as i16).to_le_bytes().to_vec(),
            SampleType::F32 => fill.to_le_bytes().to_vec(),
        };
        let (mut values, mut bytes) = (Vec::new(), Vec::new());
        for z in 0..iz {
            for y in 0..ny {
                for x in 0..nx {
                    if x < ix && y < iy {
                        let i = (z * iy + y) * ix + x;
                        values.push(self.values[i]);
                        bytes.extend_from_slice(&self.bytes[i * size..(i + 1) * size]);
                    } else {
                        values.push(fill);
                        bytes.extend_from_slice(&fill_bytes);
                    }
                }
            }
        }
        Self { dims: [nx as u16, ny as u16, iz as u16], bytes, values, ..self.clone() }
    }

    fn slice_bytes(&self) -> usize {
        usize::from(self.dims[0]) * usize::from(self.dims[1]) * self.ty.size()
    }
}

/// Frames a host would send.
struct Host {
    seq: u16,
}

fn frame(msg: &Message<'_>) -> Vec<u8> {
    let mut buf = vec![0u8; 2048];
    encode(msg, &mut buf).unwrap().to_vec()
}

impl Host {
    fn new() -> Self {
        Self { seq: 100 }
    }

    fn next(&mut self) -> u16 {
        self.seq = self.seq.wrapping_add(1);
        self.seq
    }

    /// `Hello`, announcing this host's next command.
    fn hello(&self) -> Vec<u8> {
        frame(&Message::Hello {
            protocol: PROTOCOL_VERSION,
            firmware: [0, 0, 0],
            seq: self.seq.wrapping_add(1),
        })
    }

    fn begin(&mut self, v: &Vol) -> Vec<u8> {
        frame(&self.begin_message(v))
    }

    /// The `BeginVolume` of `v`, with this host's next sequence number.
    fn begin_message(&mut self, v: &Vol) -> Message<'static> {
        Message::BeginVolume {
            seq: self.next(),
            dims: v.dims,
            sample_type: v.ty,
            spacing: [1.0; 3],
            levels: Levels::from_slice(&v.levels).unwrap(),
            axes: v.axes,
            every: v.every,
        }
    }

    /// Every chunk of every slice, `chunk` bytes at most, one frame each.
    fn slices(&mut self, v: &Vol, chunk: usize) -> Vec<Vec<u8>> {
        self.first_slices(v, chunk, usize::MAX)
    }

    /// The first `count` chunks of [`Host::slices`].
    fn first_slices(&mut self, v: &Vol, chunk: usize, count: usize) -> Vec<Vec<u8>> {
        let mut out = Vec::new();
        for (z, slice) in v.bytes.chunks(v.slice_bytes()).enumerate() {
            for (k, data) in slice.chunks(chunk).enumerate() {
                if out.len() == count {
                    return out;
                }
                let seq = self.next();
                out.push(frame(&Message::SliceData {
                    seq,
                    slice: z as u16,
                    offset: (k * chunk) as u32,
                    data,
                }));
            }
        }
        out
    }

    fn end(&mut self) -> Vec<u8> {
        let seq = self.next();
        frame(&Message::EndVolume { seq })
    }

    /// Hello, then the whole volume.
    fn volume(&mut self, v: &Vol) -> Vec<u8> {
        let mut out = self.hello();
        out.extend(self.begin(v));
        out.extend(self.slices(v, MAX_CHUNK).concat());
        out.extend(self.end());
        out
    }
}

/// The engine's answers, decoded.
fn answers(e: &mut Engine<'_>) -> Vec<Message<'static>> {
    let mut bytes = vec![0u8; 1 << 16];
    let n = e.transmit(&mut bytes);
    let mut dec = FrameDecoder::<256>::new();
    let mut out = Vec::new();
    for &b in &bytes[..n] {
        if let Some(r) = dec.push(b) {
            let m = r.expect("the engine sends valid frames");
            out.push(match m {
                Message::Ack { seq } => Message::Ack { seq },
                Message::Nack { seq, code } => Message::Nack { seq, code },
                Message::Status { seq, state, slices, points, refresh_centi_hz } => {
                    Message::Status { seq, state, slices, points, refresh_centi_hz }
                }
                Message::Hello { protocol, firmware, seq } => Message::Hello { protocol, firmware, seq },
                Message::Capabilities { protocol, max_slice_samples, sample_types, display_points } => {
                    Message::Capabilities { protocol, max_slice_samples, sample_types, display_points }
                }
                other => panic!("the engine sent a host message: {other:?}"),
            });
        }
    }
    out
}

fn events(e: &mut Engine<'_>) -> Vec<Event> {
    std::iter::from_fn(|| e.next_event()).collect()
}

fn nacks(msgs: &[Message<'_>]) -> Vec<NackCode> {
    msgs.iter()
        .filter_map(|m| match m {
            Message::Nack { code, .. } => Some(*code),
            _ => None,
        })
        .collect()
}

/// The picture on the screen as comparable bits.
fn picture(e: &Engine<'_>) -> Vec<(u32, u32, bool)> {
    e.commands()
        .map(|c| (c.point().x.to_bits(), c.point().y.to_bits(), matches!(c, Command::MoveTo(_))))
        .collect()
}

/// The engine's picture as segments.
fn shown(e: &Engine<'_>) -> Vec<Seg> {
    let g = e.surface().expect("a picture");
    segments(g.commands(), g.shift())
}

struct Keep(Vec<Command<Point3>>);
impl SurfaceSink for Keep {
    type Error = Infallible;
    fn command(&mut self, _: SliceId, _: usize, c: Command<Point3>) -> Result<(), Infallible> {
        self.0.push(c);
        Ok(())
    }
}

/// The segments of the whole-volume contouring, in the engine's fixed point.
fn batch(v: &Vol) -> Vec<Seg> {
    batch_at(v, Stride::new(v.dims, v.every))
}

/// `v`'s slices `every` apart, as a board thins them ([`Stride`]).
fn stride_at(v: &Vol, every: u16) -> Stride {
    let mut s = Stride::new(v.dims, v.every);
    while s.every < every {
        s = s.coarser().expect("a stride the volume has");
    }
    assert_eq!(s.every, every);
    s
}

/// The segments of contouring the slices `stride` keeps.
fn batch_at(v: &Vol, stride: Stride) -> Vec<Seg> {
    let [nx, ny, nz] = v.dims.map(usize::from);
    let vol = Volume::new(&v.values, nx, ny, nz).unwrap();
    let mut planes = Planes::NONE;
    for (bit, plane) in [
        (AXIS_Z, isoscope_core::contour::grid::Plane::XY),
        (AXIS_Y, isoscope_core::contour::grid::Plane::XZ),
        (AXIS_X, isoscope_core::contour::grid::Plane::YZ),
    ] {
        if v.axes & bit != 0 {
            planes = planes.with(plane);
        }
    }
    let mut keep = Keep(Vec::new());
    if stride.every <= 1 {
        contour_volume(&vol, planes, &v.levels, Traversal::Corrected, &mut keep).unwrap();
    } else {
        for plane in planes.iter() {
            let axis = match plane {
                isoscope_core::contour::grid::Plane::XY => 2,
                isoscope_core::contour::grid::Plane::XZ => 1,
                isoscope_core::contour::grid::Plane::YZ => 0,
            };
            for index in (0..vol.slice_count(plane)).filter(|&i| stride.keeps(axis, i as u16)) {
                contour_slice(&vol, SliceId { plane, index }, &v.levels, Traversal::Corrected, &mut keep)
                    .unwrap();
            }
        }
    }
    segments(keep.0.into_iter(), Geometry::shift_for(v.dims))
}

/// An engine that merges nothing, so that its segments are the contour's.
fn engine(mem: &mut Mem) -> Engine<'_> {
    let cfg = EngineConfig { merge_tolerance: 0.0, ..EngineConfig::default() };
    Engine::new(cfg, mem.buffers()).unwrap()
}

fn big() -> Mem {
    Mem::new(64 * 64 * 4, 200_000)
}

#[test]
fn streaming_equals_whole_volume_contouring_for_every_sample_type() {
    for (demo, n, ty) in [
        (Demo::Hydrogen, 20, SampleType::U8),
        (Demo::Gyroid, 17, SampleType::U16),
        (Demo::Torus, 16, SampleType::I16),
        (Demo::Sphere, 15, SampleType::F32),
        (Demo::Gyroid, 18, SampleType::F32),
    ] {
        let v = Vol::demo(demo, n, ty);
        let mut mem = big();
        let mut e = engine(&mut mem);
        let mut host = Host::new();
        // Odd chunk sizes, so that chunks straddle rows.
        let mut bytes = host.hello();
        bytes.extend(host.begin(&v));
        bytes.extend(host.slices(&v, 333).concat());
        bytes.extend(host.end());
        e.feed(&bytes, 0);
        assert!(nacks(&answers(&mut e)).is_empty());
        assert!(e.update(1));
        let got = shown(&e);
        let want = batch(&v);
        assert!(!want.is_empty());
        assert_eq!(got.len(), want.len(), "{demo:?} {ty:?}");
        assert!(got == want, "{demo:?} {ty:?}: segments differ");
        let chain = e.chain_stats();
        assert!(chain.ordered && chain.polylines * 4 < chain.fragments, "{chain:?}");
        assert!(e.commands().next().is_some());
        assert_eq!(e.state(), DeviceState::Showing);
    }
}

#[test]
fn rows_longer_than_a_block_stream_whole() {
    // Rows of 300 samples: three blocks of cells, the last ones sharing
    // the kept classes (the board keeps one block's); features all along.
    let (nx, ny, nz) = (300usize, 5usize, 4usize);
    let mut values = Vec::with_capacity(nx * ny * nz);
    for z in 0..nz {
        for y in 0..ny {
            for x in 0..nx {
                let (fx, fy, fz) = (x as f32 * 0.21, y as f32 * 0.9, z as f32 * 1.1);
                values.push(
                    ((fx.sin() * fy.cos() + fy.sin() * fz.cos() + fz.sin() * fx.cos()) * 60.0 + 100.0)
                        .round(),
                );
            }
        }
    }
    let bytes = values.iter().map(|&v| v as u8).collect();
    let v = Vol {
        dims: [nx as u16, ny as u16, nz as u16],
        ty: SampleType::U8,
        bytes,
        values,
        levels: vec![100.5, 131.0],
        axes: AXIS_X | AXIS_Y | AXIS_Z,
        every: 1,
    };
    let mut mem = big();
    let mut e = engine(&mut mem);
    e.feed(&Host::new().volume(&v), 0);
    assert!(nacks(&answers(&mut e)).is_empty());
    assert!(e.update(1));
    let want = batch(&v);
    assert!(want.len() > 1000, "{}", want.len());
    assert!(shown(&e) == want, "segments differ");
}

#[test]
fn single_planes_and_every_nth_slice_stream_too() {
    for (axes, every) in
        [(AXIS_X, 1), (AXIS_Y, 1), (AXIS_Z, 1), (AXIS_X | AXIS_Z, 1), (AXIS_X | AXIS_Y | AXIS_Z, 3)]
    {
        let v = Vol { axes, every, ..Vol::demo(Demo::Hydrogen, 14, SampleType::U8) };
        let mut mem = big();
        let mut e = engine(&mut mem);
        e.feed(&Host::new().volume(&v), 0);
        e.update(0);
        assert_eq!(shown(&e), batch(&v), "axes {axes}");
    }
}

#[test]
fn every_command_is_answered_in_order_and_status_follows_the_end() {
    let v = Vol::demo(Demo::Sphere, 8, SampleType::U8);
    let mut mem = big();
    let mut e = engine(&mut mem);
    let mut host = Host::new();
    e.feed(&host.hello(), 0);
    let hi = answers(&mut e);
    assert!(matches!(hi[0], Message::Hello { protocol: PROTOCOL_VERSION, .. }));
    assert!(matches!(hi[1], Message::Capabilities { max_slice_samples: 16384, display_points: 200_000, .. }));
    assert!(matches!(hi[2], Message::Status { state: DeviceState::Idle, .. }));
    e.feed(&host.begin(&v), 0);
    for f in host.slices(&v, 20) {
        e.feed(&f, 1);
    }
    e.feed(&host.end(), 2);
    assert!(e.update(3));
    let a = answers(&mut e);
    let acks: Vec<u16> =
        a.iter().filter_map(|m| if let Message::Ack { seq } = m { Some(*seq) } else { None }).collect();
    assert_eq!(acks, (101..=host.seq).collect::<Vec<_>>());
    let Some(&Message::Status { state: DeviceState::Showing, slices: 0, points, refresh_centi_hz, .. }) =
        a.last()
    else {
        panic!("no status after the picture: {a:?}")
    };
    assert_eq!(points as usize, e.surface().unwrap().len());
    assert!(refresh_centi_hz > 100, "{refresh_centi_hz}");
    let ev = events(&mut e);
    assert!(matches!(ev[0], Event::Hello { .. }));
    assert!(matches!(ev[1], Event::Begun { dims: [8, 8, 8], .. }));
    assert!(matches!(ev[2], Event::Committed { dims: [8, 8, 8], dropped: 0, .. }));
}

#[test]
fn a_slowed_sample_clock_is_reported_in_the_refresh_rate() {
    let v = Vol::demo(Demo::Sphere, 8, SampleType::U8);
    let mut mem = big();
    let mut e = engine(&mut mem);
    let mut host = Host::new();
    e.feed(&host.volume(&v), 0);
    assert!(e.update(1));
    let samples = isoscope_core::beam::frame_stats(e.commands(), e.beam()).samples;
    let centi = |hz: u32| ((hz as f32 / samples as f32) * 100.0) as u16;
    let status = |e: &mut Engine<'_>| {
        answers(e);
        e.feed(&Host::new().hello(), 2);
        answers(e).into_iter().find_map(|m| match m {
            Message::Status { refresh_centi_hz, .. } => Some(refresh_centi_hz),
            _ => None,
        })
    };
    assert_eq!(status(&mut e), Some(centi(1_000_000)));
    // The board slowed its clock for this picture (crate::beam::pace): the same
    // samples, played at half the rate.
    e.set_playback_rate(500_000);
    assert_eq!(status(&mut e), Some(centi(500_000)));
    assert!((e.refresh_hz() - f32::from(centi(500_000)) / 100.0).abs() < 1e-6);
    // A new picture is counted at the rate in force.
    e.feed(&host.volume(&Vol::demo(Demo::Torus, 10, SampleType::U8)), 3);
    assert!(e.update(4));
    let samples = isoscope_core::beam::frame_stats(e.commands(), e.beam()).samples;
    assert_eq!(status(&mut e), Some(((500_000.0 / samples as f32) * 100.0) as u16));
}

/// A frame of the picture played to its end, as the firmware plays it (in
/// halves of 512 samples).
fn play(e: &Engine<'_>) -> isoscope_core::beam::FrameStats {
    let mut frame = e.frame();
    while frame.fill_with(512, |_| {}) == 512 {}
    frame.stats()
}

#[test]
fn a_board_that_counts_while_playing_reports_the_same_a_frame_later() {
    let v = Vol::demo(Demo::Torus, 10, SampleType::U8);
    // The engine that counts in `update`: its events and answers.
    let mut mem = big();
    let mut e = engine(&mut mem);
    e.feed(&Host::new().volume(&v), 0);
    let before = (events(&mut e), answers(&mut e));
    assert!(e.update(1));
    let (want_events, want_answers) = (events(&mut e), answers(&mut e));
    assert!(matches!(want_events.last(), Some(Event::Redrawn { .. })), "{want_events:?}");
    assert!(matches!(want_answers.last(), Some(Message::Status { state: DeviceState::Showing, .. })));
    // The board's: nothing counted, no status, until a frame is played.
    let mut mem = big();
    let mut e = engine(&mut mem);
    e.count_while_playing(true);
    let mut host = Host::new();
    e.feed(&host.volume(&v), 0);
    assert_eq!((events(&mut e), answers(&mut e)), before);
    assert!(e.update(1));
    let (mut got_events, mut got_answers) = (events(&mut e), answers(&mut e));
    assert!(!got_events.iter().any(|ev| matches!(ev, Event::Redrawn { .. })), "{got_events:?}");
    assert!(!got_answers.iter().any(|m| matches!(m, Message::Status { .. })), "{got_answers:?}");
    let stats = play(&e);
    assert_eq!(stats, isoscope_core::beam::frame_stats(e.commands(), e.beam()));
    e.played(stats);
    got_events.extend(events(&mut e));
    got_answers.extend(answers(&mut e));
    assert_eq!(got_events, want_events);
    assert_eq!(got_answers, want_answers);
    // Further frames count nothing.
    e.played(stats);
    assert!(events(&mut e).is_empty());
    // A new view is counted from its own first frame.
    let view = |host: &mut Host, yaw: f32| {
        let seq = host.next();
        frame(&Message::SetView { seq, yaw, pitch: 20.0, roll: 0.0, fov_deg: 0.0, spin_deg_per_s: 0.0 })
    };
    e.feed(&view(&mut host, 75.0), 2);
    assert!(e.update(2));
    assert!(!events(&mut e).iter().any(|ev| matches!(ev, Event::Redrawn { .. })));
    let turned = play(&e);
    assert_ne!(turned, stats);
    e.played(turned);
    let Some(Event::Redrawn { refresh_centi_hz, .. }) = events(&mut e).pop() else {
        panic!("no redraw counted")
    };
    assert_eq!(refresh_centi_hz, ((1_000_000.0 / turned.samples as f32) * 100.0) as u16);
    // Counting in `update` again: a count still due is made at once.
    e.feed(&view(&mut host, 30.0), 3);
    assert!(e.update(3));
    let _ = events(&mut e);
    e.count_while_playing(false);
    assert!(matches!(events(&mut e).pop(), Some(Event::Redrawn { .. })));
}

/// Commit `a`, then run `bad` (frames), then check the picture is `a`'s.
fn picture_survives(bad: impl FnOnce(&mut Engine<'_>, &mut Host, &Vol)) -> Vec<Event> {
    let a = Vol::demo(Demo::Torus, 12, SampleType::U8);
    let b = Vol::demo(Demo::Gyroid, 12, SampleType::U8);
    let mut mem = big();
    let mut e = engine(&mut mem);
    let mut host = Host::new();
    e.feed(&host.volume(&a), 0);
    e.update(0);
    let before = picture(&e);
    let generation = e.generation();
    answers(&mut e);
    events(&mut e);
    bad(&mut e, &mut host, &b);
    e.update(10);
    assert_eq!(e.generation(), generation, "the display list was rebuilt");
    assert_eq!(picture(&e), before, "the picture changed");
    let ev = events(&mut e);
    assert!(!ev.iter().any(|x| matches!(x, Event::Committed { .. })), "{ev:?}");
    // And the next good volume shows.
    e.feed(&host.volume(&b), 20);
    e.update(20);
    assert_eq!(shown(&e), batch(&b));
    ev
}

#[test]
fn corrupt_crc_is_nacked_and_retransmission_recovers() {
    picture_survives(|e, host, b| {
        e.feed(&host.hello(), 1);
        e.feed(&host.begin(b), 1);
        let chunks = host.slices(b, 500);
        let mut bad = chunks[3].clone();
        bad[10] ^= 0x40;
        for c in &chunks[..3] {
            e.feed(c, 1);
        }
        e.feed(&bad, 1);
        e.feed(&chunks[4], 1);
        let a = answers(e);
        assert!(
            a.contains(&Message::Nack { seq: host.seq - chunks.len() as u16 + 4, code: NackCode::BadCrc }),
            "{a:?}"
        );
        assert!(nacks(&a).contains(&NackCode::OutOfOrder));
        // Go back: resend from the lost one; stop half-way (abandoned below).
        for c in &chunks[3..6] {
            e.feed(c, 2);
        }
        let a = answers(e);
        assert!(nacks(&a).is_empty(), "{a:?}");
        assert_eq!(a.len(), 3);
    });
}

#[test]
fn truncated_frame_garbage_and_wrong_version() {
    let ev = picture_survives(|e, host, b| {
        let begin = host.begin(b);
        e.feed(&begin[..begin.len() / 2], 1);
        e.feed(&[0], 1); // the cut frame ends here
        e.feed(b"\x13\x37garbage\xFF\xFE", 1);
        e.feed(&[0], 1);
        let mut v2 = Vec::new();
        // Another version (3) with a good CRC: decoded, refused.
        let msg = frame(&Message::EndVolume { seq: 1 });
        let mut raw = msg[..msg.len() - 1].to_vec();
        let n = isoscope_core::wire::cobs_decode_in_place(&mut raw).unwrap();
        raw.truncate(n);
        raw[0] = isoscope_core::wire::PROTOCOL_VERSION + 1;
        let body = raw.len() - 4;
        let crc = isoscope_core::wire::crc32(&raw[..body]);
        raw[body..].copy_from_slice(&crc.to_le_bytes());
        v2.extend(cobs(&raw));
        e.feed(&v2, 1);
        let codes = nacks(&answers(e));
        // A cut frame fails the CRC or its COBS (where the cut falls decides);
        // the garbage's first code byte promises more than there is.
        assert!(matches!(codes[0], NackCode::BadCrc | NackCode::Truncated), "{codes:?}");
        assert_eq!(codes[1..], [NackCode::Truncated, NackCode::BadVersion], "{codes:?}");
    });
    assert!(ev.iter().any(|x| matches!(x, Event::FrameError { .. })));
}

#[test]
fn oversize_frame_is_nacked() {
    picture_survives(|e, _, _| {
        let mut f = vec![0x55u8; 5000];
        f.push(0);
        e.feed(&f, 1);
        assert_eq!(nacks(&answers(e)), [NackCode::Oversize]);
    });
}

#[test]
fn dims_over_capacity_and_invalid_volumes_are_refused() {
    picture_survives(|e, host, b| {
        // (Slices of 16 KB: 129 x 128 u8 is 64 bytes more; a row of any
        // length in slices that fit is taken, `rows_longer_than_a_block_stream_whole`.)
        let too_big = Vol { dims: [129, 128, 3], ..b.clone() };
        e.feed(&host.begin(&too_big), 1);
        let wide = Vol { dims: [4097, 4, 3], ..b.clone() };
        e.feed(&host.begin(&wide), 1);
        let flat = Vol { dims: [1, 50, 3], ..b.clone() };
        e.feed(&host.begin(&flat), 1);
        let no_axes = Vol { axes: 0, ..b.clone() };
        e.feed(&host.begin(&no_axes), 1);
        let nan_level = Vol { levels: vec![f32::NAN], ..b.clone() };
        e.feed(&host.begin(&nan_level), 1);
        assert_eq!(
            nacks(&answers(e)),
            [
                NackCode::DimsOverCapacity,
                NackCode::DimsOverCapacity,
                NackCode::Invalid,
                NackCode::Invalid,
                NackCode::Invalid
            ]
        );
        assert_eq!(e.state(), DeviceState::Showing);
    });
}

#[test]
fn slices_out_of_order_duplicate_and_missing() {
    let ev = picture_survives(|e, host, b| {
        e.feed(&host.begin(b), 1);
        let sb = b.slice_bytes();
        let slice = |z: usize| &b.bytes[z * sb..(z + 1) * sb];
        let mut send = |e: &mut Engine<'_>, z: u16, offset: u32, data: &[u8]| {
            let seq = host.next();
            e.feed(&frame(&Message::SliceData { seq, slice: z, offset, data }), 1);
        };
        send(e, 0, 0, slice(0));
        send(e, 2, 0, slice(2)); // skipped slice 1
        send(e, 0, 0, slice(0)); // again, with a new seq
        send(e, 1, 10, &slice(1)[10..]); // starts mid-slice
        send(e, 1, 0, &slice(1)[..sb - 1]);
        send(e, 1, (sb - 1) as u32, &[1, 2]); // runs past the slice
        send(e, 99, 0, slice(1)); // no such slice
        let end = host.end();
        e.feed(&end, 1);
        assert_eq!(
            nacks(&answers(e)),
            [
                NackCode::OutOfOrder,
                NackCode::Duplicate,
                NackCode::OutOfOrder,
                NackCode::Invalid,
                NackCode::Invalid,
                NackCode::Missing
            ]
        );
        assert_eq!(e.state(), DeviceState::Showing);
    });
    assert!(ev.contains(&Event::Aborted { reason: AbortReason::Missing, slices: 1 }), "{ev:?}");
}

#[test]
fn abandoned_transfer_times_out_and_is_superseded() {
    let ev = picture_survives(|e, host, b| {
        e.feed(&host.begin(b), 1000);
        for c in host.first_slices(b, MAX_CHUNK, 3) {
            e.feed(&c, 1000);
        }
        assert_eq!(e.state(), DeviceState::Receiving);
        e.update(1000 + 4999);
        assert_eq!(e.state(), DeviceState::Receiving);
        e.update(1000 + 5001);
        assert_eq!(e.state(), DeviceState::Showing);
        // Data for the dead transfer is refused.
        let seq = host.next();
        e.feed(&frame(&Message::SliceData { seq, slice: 3, offset: 0, data: &[1] }), 7000);
        assert_eq!(nacks(&answers(e)), [NackCode::Aborted]);
        // Half a transfer, then a new one begins and is abandoned too.
        e.feed(&host.begin(b), 8000);
        e.feed(&host.first_slices(b, MAX_CHUNK, 1)[0], 8000);
        e.feed(&host.begin(b), 8000);
    });
    assert!(ev.contains(&Event::Aborted { reason: AbortReason::Timeout, slices: 3 }), "{ev:?}");
    assert!(ev.contains(&Event::Aborted { reason: AbortReason::Superseded, slices: 1 }), "{ev:?}");
}

#[test]
fn a_sender_still_at_it_on_a_noisy_line_keeps_its_transfer() {
    // Frame 1 of the slices is lost again and again; the sender's later
    // frames (out of order) keep coming whole for 12 s, longer than the
    // transfer timeout, before frame 1 gets through: the transfer is kept
    // (on a 3e-3 line the board abandoned such transfers while the sender
    // was still retrying).
    let v = Vol::demo(Demo::Sphere, 10, SampleType::U8);
    let mut mem = big();
    let mut e = engine(&mut mem);
    let mut host = Host::new();
    e.feed(&host.hello(), 0);
    e.feed(&host.begin(&v), 1000);
    let slices = host.slices(&v, 40);
    e.feed(&slices[0], 1000);
    for t in (4000..=13_000).step_by(3000) {
        e.feed(&slices[2], t);
        e.update(t);
        assert_eq!(e.state(), DeviceState::Receiving, "at {t} ms");
    }
    assert!(nacks(&answers(&mut e)).contains(&NackCode::OutOfOrder));
    for s in &slices[1..] {
        e.feed(s, 14_000);
    }
    e.feed(&host.end(), 14_000);
    e.update(14_000);
    let ev = events(&mut e);
    assert!(!ev.iter().any(|x| matches!(x, Event::Aborted { .. })), "{ev:?}");
    assert_eq!(e.state(), DeviceState::Showing);
    assert_eq!(shown(&e), batch(&v));
    // Silence still times a transfer out (`abandoned_transfer_times_out...`).
}

#[test]
fn retransmitted_commands_are_answered_again_not_applied_twice() {
    let v = Vol::demo(Demo::Sphere, 10, SampleType::U8);
    let mut mem = big();
    let mut e = engine(&mut mem);
    let mut host = Host::new();
    e.feed(&host.hello(), 0);
    let begin = host.begin(&v);
    e.feed(&begin, 0);
    let chunks = host.slices(&v, 64);
    for c in &chunks {
        e.feed(c, 0);
        e.feed(c, 0); // the ack was lost: sent twice
    }
    e.feed(&begin, 0); // a very late duplicate: must not restart the transfer
    e.feed(&host.end(), 0);
    let a = answers(&mut e);
    assert!(nacks(&a).is_empty(), "{a:?}");
    assert_eq!(e.counters().replays as usize, chunks.len() + 1);
    e.update(0);
    assert_eq!(shown(&e), batch(&v));
}

#[test]
fn a_megabyte_of_noise_then_a_valid_volume_displays_correctly() {
    let v = Vol::demo(Demo::Hydrogen, 16, SampleType::U8);
    // The reference: a clean run.
    let mut mem = big();
    let mut clean = engine(&mut mem);
    clean.feed(&Host::new().volume(&v), 0);
    clean.update(0);
    let want = picture(&clean);
    let mut mem2 = big();
    let mut e = engine(&mut mem2);
    let mut rng = 0x2545F4914F6CDD1Du64;
    let noise: Vec<u8> = (0..1 << 20)
        .map(|_| {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            (rng >> 24) as u8
        })
        .collect();
    for c in noise.chunks(4096) {
        e.feed(c, 0);
        answers(&mut e);
    }
    assert!(e.counters().frame_errors > 1000);
    let mut stream = vec![0u8]; // flush the partial frame the noise left
    stream.extend(Host::new().volume(&v));
    e.feed(&stream, 1);
    e.update(1);
    assert_eq!(picture(&e), want);
}

#[test]
fn view_changes_reproject_without_the_volume() {
    let v = Vol::demo(Demo::Torus, 14, SampleType::U8);
    let mut mem = big();
    let mut e = engine(&mut mem);
    let mut host = Host::new();
    e.feed(&host.volume(&v), 0);
    e.update(0);
    let front = picture(&e);
    let view = |host: &mut Host, yaw: f32, spin: f32| {
        let seq = host.next();
        frame(&Message::SetView { seq, yaw, pitch: 20.0, roll: 0.0, fov_deg: 0.0, spin_deg_per_s: spin })
    };
    e.feed(&view(&mut host, 75.0, 0.0), 1);
    assert!(e.update(1));
    assert_ne!(picture(&e), front);
    e.feed(&view(&mut host, 30.0, 0.0), 2);
    e.update(2);
    assert_eq!(picture(&e), front, "the default view again");
    assert!(!e.update(3), "nothing changed");
    // Spinning: a new picture at every update.
    e.feed(&view(&mut host, 30.0, 90.0), 10);
    e.update(10);
    let p0 = picture(&e);
    assert!(e.update(510));
    assert_ne!(picture(&e), p0);
    // Refused views keep the old one.
    let seq = host.next();
    e.feed(
        &frame(&Message::SetView {
            seq,
            yaw: f32::NAN,
            pitch: 0.0,
            roll: 0.0,
            fov_deg: 0.0,
            spin_deg_per_s: 0.0,
        }),
        600,
    );
    let seq = host.next();
    e.feed(
        &frame(&Message::SetView {
            seq,
            yaw: 0.0,
            pitch: 0.0,
            roll: 0.0,
            fov_deg: 200.0,
            spin_deg_per_s: 0.0,
        }),
        600,
    );
    assert_eq!(nacks(&answers(&mut e)), [NackCode::Invalid, NackCode::Invalid]);
}

#[test]
fn levels_and_beam_settings() {
    let v = Vol::demo(Demo::Sphere, 10, SampleType::U8);
    let mut mem = big();
    let mut e = engine(&mut mem);
    let mut host = Host::new();
    e.feed(&host.hello(), 0);
    let seq = host.next();
    e.feed(&frame(&Message::SetLevels { seq, levels: Levels::from_slice(&[100.0]).unwrap() }), 0);
    // A volume with no levels of its own takes them.
    let none = Vol { levels: vec![], ..v.clone() };
    e.feed(&host.begin(&none), 0);
    e.feed(&host.slices(&none, MAX_CHUNK).concat(), 0);
    e.feed(&host.end(), 0);
    e.update(0);
    assert_eq!(shown(&e), batch(&Vol { levels: vec![100.0], ..v.clone() }));
    let samples_before = isoscope_core::beam::frame_stats(e.commands(), e.beam()).samples;
    let seq = host.next();
    e.feed(&frame(&Message::SetBeam { seq, lit_step: 4, dwell_us: 8, settle_us: 10 }), 1);
    assert!(e.update(1));
    assert_eq!(e.beam().lit_step, 4.0);
    assert_eq!(e.beam().point_dwell, 8);
    let samples_after = isoscope_core::beam::frame_stats(e.commands(), e.beam()).samples;
    assert!(samples_after > 3 * samples_before, "{samples_before} -> {samples_after}");
    let seq = host.next();
    e.feed(&frame(&Message::SetBeam { seq, lit_step: 0, dwell_us: 1, settle_us: 1 }), 2);
    let seq = host.next();
    e.feed(&frame(&Message::SetLevels { seq, levels: Levels::new() }), 2);
    assert_eq!(nacks(&answers(&mut e)), [NackCode::Invalid, NackCode::Invalid]);
}

/// From a commit: the stride asked, the stride kept, commands dropped.
type AtCommit = Option<(u8, u16, u32)>;
/// From a stitch: the stride drawn, points cut.
type AtStitch = Option<(u16, u32)>;

/// The stride a volume was committed and drawn at, from the events.
fn strides(ev: &[Event]) -> (AtCommit, AtStitch) {
    let committed = ev.iter().find_map(|x| match *x {
        Event::Committed { asked, every, dropped, .. } => Some((asked, every, dropped)),
        _ => None,
    });
    let stitched = ev.iter().find_map(|x| match *x {
        Event::Stitched { every, cut, .. } => Some((every, cut)),
        _ => None,
    });
    (committed, stitched)
}

/// What an engine with plenty of memory ([`big`]) makes of `v`.
fn with_plenty(v: &Vol) -> isoscope_core::engine::ChainStats {
    let mut mem = big();
    let mut whole = engine(&mut mem);
    whole.feed(&Host::new().volume(v), 0);
    whole.update(0);
    whole.chain_stats()
}

/// Volumes that outgrow a back of a third of their pieces, one of them
/// every 3rd slice: each demo, its size, the volume.
fn outgrowing() -> [(Demo, usize, Vol); 3] {
    [
        (Demo::Gyroid, 16, SampleType::U8, 1),
        (Demo::Hydrogen, 18, SampleType::F32, 1),
        (Demo::Torus, 20, SampleType::I16, 3),
    ]
    .map(|(demo, n, ty, every)| (demo, n, Vol { every, ..Vol::demo(demo, n, ty) }))
}

/// The messages of [`Host::volume`] (chunks of [`MAX_CHUNK`]), whole.
fn volume_messages(v: &Vol) -> Vec<Message<'_>> {
    let mut host = Host::new();
    let mut out = vec![Message::Hello { protocol: PROTOCOL_VERSION, firmware: [0, 0, 0], seq: host.seq + 1 }];
    out.push(host.begin_message(v));
    for (z, slice) in v.bytes.chunks(v.slice_bytes()).enumerate() {
        for (k, data) in slice.chunks(MAX_CHUNK).enumerate() {
            out.push(Message::SliceData {
                seq: host.next(),
                slice: z as u16,
                offset: (k * MAX_CHUNK) as u32,
                data,
            });
        }
    }
    out.push(Message::EndVolume { seq: host.next() });
    out
}

#[test]
fn a_message_handed_over_whole_does_exactly_what_its_frame_does() {
    // `accept_all` (the host's board in process) against `feed_all` of the
    // message's frame: the same answers, events, counters and picture,
    // eager and deferred, with memory to spare and with a back so small
    // that the surface is thinned (the contouring then waits for updates).
    let roomy = |v: &Vol| Mem::new(v.slice_bytes(), 200_000);
    let tight = |v: &Vol| {
        let pieces = with_plenty(v).points_in as usize;
        Mem::sized(2 * v.slice_bytes(), [pieces; 2].map(|p| p / 3), 8 * pieces)
    };
    let vols = [
        Vol::demo(Demo::Hydrogen, 12, SampleType::U8),
        Vol { axes: AXIS_X | AXIS_Z, ..Vol::demo(Demo::Torus, 14, SampleType::I16) },
        Vol { every: 3, ..Vol::demo(Demo::Gyroid, 13, SampleType::F32) },
    ];
    let mut cases = 0;
    for defer in [false, true] {
        let cfg = EngineConfig { merge_tolerance: 0.0, defer_contouring: defer, ..EngineConfig::default() };
        for v in vols.iter().chain(outgrowing().iter().map(|(_, _, v)| v)) {
            for mem in [roomy, tight] {
                let (mut ma, mut mb) = (mem(v), mem(v));
                let mut a = Engine::new(cfg, ma.buffers()).unwrap();
                let mut b = Engine::new(cfg, mb.buffers()).unwrap();
                for (t, m) in (0u32..).zip(&volume_messages(v)) {
                    let f = frame(m);
                    assert_eq!(a.feed_all(&f, t), f.len());
                    assert!(b.accept_all(m, t));
                    assert_eq!(answers(&mut a), answers(&mut b), "answers to {m:?}");
                    assert_eq!(events(&mut a), events(&mut b));
                }
                assert_eq!(a.counters(), b.counters());
                assert!(a.update(1_000) && b.update(1_000));
                assert_eq!(events(&mut a), events(&mut b));
                assert!(!picture(&a).is_empty());
                assert_eq!(picture(&a), picture(&b), "defer {defer}");
                assert_eq!(a.frame().collect::<Vec<_>>(), b.frame().collect::<Vec<_>>());
                cases += 1;
            }
        }
    }
    assert_eq!(cases, 24);
}

#[test]
fn a_link_takes_a_message_whole_exactly_when_it_would_take_its_frame() {
    // Deferring, as the firmware runs: while a completed slice's rows are
    // pending (or the contouring waits for an update) `accept` refuses the
    // message as `feed` takes none of its frame; the work done, both take it.
    let v = Vol::demo(Demo::Gyroid, 13, SampleType::F32);
    let cfg = EngineConfig { merge_tolerance: 0.0, defer_contouring: true, ..EngineConfig::default() };
    let (mut ma, mut mb) = (big(), big());
    let mut a = Engine::new(cfg, ma.buffers()).unwrap();
    let mut b = Engine::new(cfg, mb.buffers()).unwrap();
    let mut refused = 0;
    for m in &volume_messages(&v) {
        let f = frame(m);
        loop {
            let n = a.split().0.feed(&f, 0);
            let took = b.split().0.accept(*m, 0);
            assert_eq!(took, n == f.len(), "{m:?}");
            assert!(n == 0 || n == f.len());
            if took {
                break;
            }
            refused += 1;
            for e in [&mut a, &mut b] {
                let (mut link, _) = e.split();
                if link.waits() {
                    e.update(0);
                } else {
                    assert!(link.busy());
                    link.contour(50);
                }
            }
        }
    }
    assert!(refused > 0, "no message came while a slice was pending");
    assert!(a.update(1) && b.update(1));
    assert_eq!(picture(&a), picture(&b));
}

#[test]
fn a_surface_larger_than_memory_is_thinned_to_whole_slices_not_cut() {
    // A back of a third of the pieces and no room to spill: the stream
    // doubles the stride until the surface fits, and the picture is
    // exactly the surface contoured at that stride (whole slices of each
    // plane), not a part of the finer one.
    for (demo, _, v) in outgrowing() {
        let pieces = with_plenty(&v).points_in as usize;
        let mut mem = Mem::sized(2 * v.slice_bytes(), [pieces; 2].map(|p| p / 3), 8 * pieces);
        let mut e = engine(&mut mem);
        e.feed(&Host::new().volume(&v), 0);
        let (committed, _) = strides(&events(&mut e));
        let Some((asked, thinned, 0)) = committed else { panic!("{demo:?}: {committed:?}") };
        assert_eq!(asked, v.every);
        assert!(thinned >= 2 * u16::from(v.every), "{demo:?}: every {thinned}");
        e.update(0);
        let (_, stitched) = strides(&events(&mut e));
        assert_eq!(stitched, Some((thinned, 0)), "{demo:?}");
        assert_eq!(
            shown(&e),
            batch_at(&v, stride_at(&v, thinned)),
            "{demo:?}: the picture at every {thinned}"
        );
    }
}

#[test]
fn a_surface_said_to_have_outgrown_the_memory_is_never_drawn_whole() {
    // A host whose memory grows gives up a transfer once the engine says
    // the surface has outgrown it (`isoscope-sim`'s scenes), which is only
    // right if such a surface would not have been drawn whole: frame by
    // frame, over backs from a tenth of the pieces to all of them.
    let mut said = 0;
    for (demo, _, v) in outgrowing() {
        let pieces = with_plenty(&v).points_in as usize;
        for tenths in [1, 3, 5, 8, 10, 12] {
            let back = pieces * tenths / 10;
            let mut mem = Mem::sized(2 * v.slice_bytes(), [back; 2], 8 * back);
            let mut e = engine(&mut mem);
            let mut host = Host::new();
            let mut frames = vec![host.hello(), host.begin(&v)];
            frames.extend(host.slices(&v, 200));
            frames.push(host.end());
            let mut outgrown = false;
            for f in &frames {
                e.feed(f, 0);
                outgrown |= e.outgrown();
            }
            e.update(0);
            assert!(!e.outgrown(), "{demo:?}: outgrown between transfers");
            let (committed, stitched) = strides(&events(&mut e));
            let (Some((asked, drawn, dropped)), Some((every, cut))) = (committed, stitched) else {
                panic!("{demo:?} at {tenths}/10: {committed:?} {stitched:?}")
            };
            let asked = u16::from(asked.max(1));
            let drawn_whole = dropped == 0 && drawn == asked && every == drawn && cut == 0;
            assert!(!(outgrown && drawn_whole), "{demo:?} at {tenths}/10: said outgrown, drawn whole");
            // Thinned or dropped while arriving: said so on the way.
            assert_eq!(outgrown, drawn > asked || dropped > 0, "{demo:?} at {tenths}/10");
            said += usize::from(outgrown);
        }
    }
    assert!(said >= 3, "only {said} transfers outgrew their memory");
}

#[test]
fn a_surface_larger_than_memory_at_the_coarsest_stride_is_cut_and_counted() {
    // 500 points hold no stride of this gyroid: at the coarsest (every
    // 8th of 16: slices 0 and 8 of each plane) it is cut, and said to be.
    let v = Vol::demo(Demo::Gyroid, 16, SampleType::U8);
    let mut mem = Mem::new(16 * 16, 500);
    let mut e = engine(&mut mem);
    e.feed(&Host::new().volume(&v), 0);
    let ev = events(&mut e);
    let Some(Event::Committed { commands, dropped, every, .. }) =
        ev.iter().find(|x| matches!(x, Event::Committed { .. })).copied()
    else {
        panic!("{ev:?}")
    };
    assert_eq!(every, 8);
    assert!(commands <= 500 && commands > 450, "{commands}");
    assert!(dropped > 100, "{dropped}");
    e.update(0);
    assert!(e.commands().next().is_some());
}

#[test]
fn a_picture_larger_than_the_front_is_thinned_at_the_commit() {
    // Every piece fits the back; stitched they do not fit a front of a
    // third of them: the commit thins the pieces and stitches again.
    let v = Vol { levels: vec![0.1], ..Vol::demo(Demo::Hydrogen, 16, SampleType::F32) };
    let points = with_plenty(&v).points_out as usize;
    let mut mem = Mem::sized(2 * 16 * 16 * 4, [points / 3, 8000], 8 * 8000);
    let mut e = engine(&mut mem);
    e.feed(&Host::new().volume(&v), 0);
    let (committed, _) = strides(&events(&mut e));
    assert_eq!(committed, Some((1, 1, 0)));
    e.update(0);
    let (_, stitched) = strides(&events(&mut e));
    let Some((thinned, 0)) = stitched else { panic!("{stitched:?}") };
    assert!(thinned >= 2, "{thinned}");
    assert_eq!(shown(&e), batch_at(&v, stride_at(&v, thinned)));
    assert!(e.chain_stats().ordered);
}

#[test]
fn a_picture_larger_than_the_front_at_the_coarsest_stride_is_cut_and_said_to_be() {
    // Every piece fits the back; stitched and merged, not even slices 0
    // and 8 of each plane fit a front of 100 points.
    let v = Vol { levels: vec![0.1], ..Vol::demo(Demo::Hydrogen, 16, SampleType::F32) };
    let mut mem = Mem::sized(2 * 16 * 16 * 4, [100, 8000], 8 * 8000);
    let mut e = engine(&mut mem);
    e.feed(&Host::new().volume(&v), 0);
    let ev = events(&mut e);
    assert!(ev.iter().any(|x| matches!(x, Event::Committed { dropped: 0, .. })), "{ev:?}");
    e.update(0);
    let ev = events(&mut e);
    let Some(Event::Stitched { points, cut, ordered, every, .. }) =
        ev.iter().find(|x| matches!(x, Event::Stitched { .. })).copied()
    else {
        panic!("{ev:?}")
    };
    assert!(ordered, "{ev:?}");
    assert_eq!(every, 8);
    assert!(points <= 100 && cut > 50, "{ev:?}");
    assert_eq!(e.chain_stats().cut, cut);
}

/// The hydrogen orbital at 32^3 and the CLI's level: 12,816 points as
/// contoured, 7,308 once stitched and merged.
fn hydrogen32() -> Vol {
    Vol { levels: vec![0.1], ..Vol::demo(Demo::Hydrogen, 32, SampleType::F32) }
}

/// The vertices a picture draws.
fn vertices(e: &Engine<'_>) -> HashSet<Packed> {
    shown(e).into_iter().flat_map(|(a, b)| [a, b]).collect()
}

/// The length a picture draws, in codes.
fn drawn_length(e: &Engine<'_>) -> f64 {
    let d = |a: Packed, b: Packed| {
        a.iter().zip(b).map(|(&a, b)| (f64::from(a) - f64::from(b)).powi(2)).sum::<f64>().sqrt()
    };
    shown(e).into_iter().map(|(a, b)| d(a, b)).sum()
}

/// Hydrogen 32^3 in `buffers` must show whole: its 12,816 pieces kept (in
/// the back, and what spills into the slice memory), stitched and merged
/// into a front of 8,192 points, as long as with plenty of memory.
fn shows_hydrogen32_whole(buffers: Buffers<'_>) {
    let v = hydrogen32();
    let mut mem = big();
    let mut whole = Engine::new(EngineConfig::default(), mem.buffers()).unwrap();
    whole.feed(&Host::new().volume(&v), 0);
    whole.update(0);
    let mut e = Engine::new(EngineConfig::default(), buffers).unwrap();
    e.feed(&Host::new().volume(&v), 0);
    let ev = events(&mut e);
    // All 12,816 points of its pieces kept, whole (fewer where the back was
    // folded on the way).
    let kept = ev.iter().find_map(|x| match *x {
        Event::Committed {
            dims: [32, 32, 32],
            commands,
            dropped: 0,
            nonfinite_cells: 0,
            asked: 1,
            every: 1,
        } => Some(commands),
        _ => None,
    });
    assert!(kept.is_some_and(|k| k <= 12816), "{ev:?}");
    e.update(0);
    let (st, all) = (e.chain_stats(), whole.chain_stats());
    let stitched =
        Event::Stitched { fragments: st.fragments, points: st.points_out, cut: 0, ordered: true, every: 1 };
    assert!(events(&mut e).contains(&stitched), "{st:?}");
    assert_eq!(Some(st.points_in), kept);
    assert!(st.ordered);
    assert!(st.points_out <= 8192, "{st:?}");
    // The same surface, merged alike: within a few points and polylines
    // (merging first leaves a vertex where two loops touch less often), a
    // subset of the contour's vertices, and as long.
    assert!(st.points_out.abs_diff(all.points_out) <= all.points_out / 100, "{st:?} {all:?}");
    assert!(st.polylines.abs_diff(all.polylines) <= all.polylines / 10, "{st:?} {all:?}");
    let contour: HashSet<Packed> = batch(&v).into_iter().flat_map(|(a, b)| [a, b]).collect();
    assert!(vertices(&e).is_subset(&contour));
    let (a, b) = (drawn_length(&e), drawn_length(&whole));
    assert!((a - b).abs() <= b * 1e-3, "{a} {b}");
}

#[test]
fn pieces_more_than_the_front_holds_fit_it_once_stitched_and_merged() {
    // A front of 8,192 points, a back of twice that: the 12,816 pieces fit
    // the back, their 9,088 points stitched but unmerged would not fit the
    // front.
    let mut mem = Mem::sized(2 * 64 * 64 * 4, [8192, 16384], 8 * 16384);
    shows_hydrogen32_whole(mem.buffers());
}

#[test]
fn pieces_more_than_the_back_holds_spill_into_the_slice_memory_small_slices_leave() {
    // The firmware's memory: slices of 32 KB, surfaces of 8,192 points, no
    // more scratch. Hydrogen's 32 x 32 f32 slices take 8 KB of the 64:
    // 4,624 of its pieces go into the rest, and stitching finds its index
    // room beside them.
    let mut mem = Box::new(Firmware::new());
    shows_hydrogen32_whole(mem.buffers());
}

#[test]
fn a_spilled_surface_draws_exactly_the_segments_of_whole_volume_contouring() {
    // Surfaces of nine tenths of the pieces (stitched, they are fewer: a
    // joint is one point, not two), the last tenth spilled beside the
    // slices, and no merging: the picture is the contour's segments, each
    // once.
    for (demo, n, ty) in [
        (Demo::Gyroid, 14, SampleType::U8),
        (Demo::Torus, 16, SampleType::I16),
        (Demo::Sphere, 13, SampleType::F32),
        (Demo::Hydrogen, 18, SampleType::U16),
    ] {
        let v = Vol::demo(demo, n, ty);
        let pieces = with_plenty(&v).points_in as usize;
        // Stitching and ordering in scratch of their own (the slice memory
        // has just the room for the slices and the spill).
        let slices = 2 * v.slice_bytes() + Geometry::bytes_for(pieces);
        let mut spilled = Mem::sized(slices, [pieces * 9 / 10; 2], 8 * pieces);
        let mut e = engine(&mut spilled);
        e.feed(&Host::new().volume(&v), 0);
        let ev = events(&mut e);
        // All kept (fewer points where the back was folded on the way).
        let kept = ev.iter().find_map(|x| match *x {
            Event::Committed { dims, commands, dropped: 0, nonfinite_cells: 0, asked: 1, every: 1 }
                if dims == v.dims =>
            {
                Some(commands as usize)
            }
            _ => None,
        });
        assert!(kept.is_some_and(|k| k <= pieces), "{demo:?} {ev:?}");
        e.update(0);
        assert!(e.chain_stats().ordered, "{demo:?}");
        assert_eq!(shown(&e), batch(&v), "{demo:?}");
    }
}

#[test]
fn a_spill_leaves_nothing_behind() {
    // In the firmware's memory and settings: hydrogen 32^3 folds and
    // spills; then a transfer of it folds (taking the picture's store) and
    // is abandoned half way (superseded); the picture plays on from its
    // recording all the while, and a small volume then shows exactly as it
    // does on a fresh board.
    let cfg = EngineConfig { defer_contouring: true, ..EngineConfig::default() };
    let (h, small) = (hydrogen32(), Vol::demo(Demo::Gyroid, 20, SampleType::U16));
    let mut fresh = Box::new(Firmware::new());
    let mut f = Engine::new(cfg, fresh.buffers()).unwrap();
    feed_deferring(&mut f, &Host::new().volume(&small), 256, 2000);
    f.update(0);
    let mut mem = Box::new(Firmware::new());
    let mut e = Engine::new(cfg, mem.buffers()).unwrap();
    e.replay_frames(true);
    let mut host = Host::new();
    feed_deferring(&mut e, &host.volume(&h), 256, 2000);
    e.update(0);
    assert!(e.chain_stats().points_in < 12816, "folded on the way");
    let spilled = picture(&e);
    let (first, _) = board_frame(&mut e);
    assert_eq!(board_frame(&mut e), (first.clone(), true));
    answers(&mut e);
    // 28 of the 32 slices: the back folded, the picture's store taken.
    let mut half = vec![host.begin(&h)];
    half.extend(host.first_slices(&h, MAX_CHUNK, 28 * h.slice_bytes().div_ceil(MAX_CHUNK)));
    let frames = board_receives(&mut e, &half.concat(), 10);
    assert!(
        frames.iter().all(|f| *f == (first.clone(), true)),
        "the old picture plays on from its recording"
    );
    assert_eq!(nacks(&answers(&mut e)), []);
    assert_eq!(e.state(), DeviceState::Receiving);
    assert!(picture(&e).is_empty(), "the store is the volume's");
    // Superseded: the recording plays on until the small volume shows.
    let bytes = [host.begin(&small), host.slices(&small, MAX_CHUNK).concat(), host.end()].concat();
    let frames = board_receives(&mut e, &bytes, 100);
    assert!(
        frames.iter().all(|f| *f == (first.clone(), true)),
        "the old picture plays on from its recording"
    );
    assert_eq!(nacks(&answers(&mut e)), []);
    // (Its commit needs more than the memory less hydrogen's recording:
    // the recording is thinned first, and the commit plays it on.)
    assert!(e.commit_parks() && !e.update(200), "the recording thinned");
    assert!(!e.commit_parks() && e.update(201), "the commit, the old picture playing");
    assert!(picture(&e) == picture(&f));
    assert_ne!(picture(&e), spilled);
    assert_eq!(e.chain_stats(), f.chain_stats());
}

#[test]
fn nan_samples_are_skipped_and_counted() {
    let mut v = Vol::demo(Demo::Sphere, 10, SampleType::F32);
    v.bytes[4 * 555..4 * 556].copy_from_slice(&f32::NAN.to_le_bytes());
    let mut mem = big();
    let mut e = engine(&mut mem);
    e.feed(&Host::new().volume(&v), 0);
    let ev = events(&mut e);
    assert!(ev.iter().any(|x| matches!(x, Event::Committed { nonfinite_cells: 12, .. })), "{ev:?}");
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// Any damage to a valid stream: no panic, no hang, and a clean volume
    /// afterwards shows exactly what it should.
    #[test]
    fn damaged_streams_never_panic_and_recovery_is_exact(
        cuts in proptest::collection::vec((0usize..20_000, any::<u8>(), 0u8..4), 0..40),
        noise in proptest::collection::vec(any::<u8>(), 0..3000),
    ) {
        let v = Vol::demo(Demo::Torus, 10, SampleType::U16);
        let mut stream = Host::new().volume(&v);
        for &(at, byte, how) in &cuts {
            let at = at % (stream.len() + 1);
            match how {
                0 => { if at < stream.len() { stream[at] ^= byte | 1; } }
                1 => stream.insert(at, byte),
                2 => { if at < stream.len() { stream.remove(at); } }
                _ => { stream.splice(at..at, noise.iter().copied().take(usize::from(byte))); }
            }
        }
        let mut mem = Mem::new(10 * 10 * 2, 20_000);
        let mut e = engine(&mut mem);
        for (k, c) in stream.chunks(97).enumerate() {
            e.feed(c, k as u32 * 3);
            let mut sink = [0u8; 64];
            while e.transmit(&mut sink) > 0 {}
            e.update(k as u32 * 3);
        }
        e.feed(&[0], 1_000_000);
        e.feed(&Host::new().volume(&v), 1_000_000);
        e.update(1_000_001);
        prop_assert_eq!(shown(&e), batch(&v));
    }
}

#[test]
fn frames_play_on_while_the_next_volume_streams_in() {
    let a = Vol::demo(Demo::Torus, 12, SampleType::U8);
    let b = Vol::demo(Demo::Sphere, 12, SampleType::U8);
    let mut mem = big();
    let mut e = engine(&mut mem);
    e.feed(&Host::new().volume(&a), 0);
    e.update(0);
    let want: Vec<_> = e.frame().collect();
    assert!(want.len() > 100);
    let bytes = Host::new().volume(&b);
    let mut played = Vec::new();
    {
        let (mut link, mut screen) = e.split();
        let mut frame = screen.frame();
        // A few samples, a few bytes: the DMA refill and the UART interleave.
        let mut chunks = bytes.chunks(bytes.len() / want.len() + 1);
        loop {
            let s: Vec<_> = frame.by_ref().take(1).collect();
            if let Some(c) = chunks.next() {
                link.feed(c, 5);
            }
            if s.is_empty() {
                break;
            }
            played.extend(s);
        }
        for c in chunks {
            link.feed(c, 5);
        }
        assert!(link.pending() > 0, "answers wait for the UART");
    }
    assert_eq!(played, want, "the frame on screen is untouched while the next volume arrives");
    assert!(e.update(6));
    let next: Vec<_> = e.frame().collect();
    assert_ne!(next, want);
    assert_eq!(shown(&e), batch(&b));
}

/// An engine that defers contouring ([`EngineConfig::defer_contouring`]),
/// as the firmware runs it.
fn deferring(mem: &mut Mem) -> Engine<'_> {
    let cfg = EngineConfig { merge_tolerance: 0.0, defer_contouring: true, ..EngineConfig::default() };
    Engine::new(cfg, mem.buffers()).unwrap()
}

/// Feed `bytes` as the firmware does: `piece` bytes at a time, and while a
/// completed slice has work pending, `cells` cells of it (whole rows, at
/// least one) before anything else. Returns the most `contour` calls one
/// slice took.
fn feed_deferring(e: &mut Engine<'_>, bytes: &[u8], piece: usize, cells: usize) -> usize {
    let mut most = 0;
    let mut rest = bytes;
    while !rest.is_empty() {
        let mut owed = 0;
        while e.split().0.busy() {
            let (mut link, _) = e.split();
            assert_eq!(link.feed(rest, 0), 0, "no bytes taken while a slice is being contoured");
            if link.waits() {
                // For the next update (a board's next frame boundary): to
                // fold the surface arriving.
                e.update(0);
            } else {
                link.contour(cells);
                owed += 1;
            }
        }
        most = most.max(owed);
        let n = e.split().0.feed(&rest[..piece.min(rest.len())], 0);
        assert!(n > 0);
        rest = &rest[n..];
    }
    most
}

#[test]
fn deferred_contouring_draws_the_same_picture_a_few_rows_at_a_time() {
    for (demo, n, ty, axes, every) in [
        (Demo::Hydrogen, 16, SampleType::U8, AXIS_X | AXIS_Y | AXIS_Z, 1),
        (Demo::Gyroid, 13, SampleType::F32, AXIS_X | AXIS_Y | AXIS_Z, 1),
        (Demo::Torus, 14, SampleType::I16, AXIS_X | AXIS_Z, 1),
        (Demo::Hydrogen, 14, SampleType::U16, AXIS_X | AXIS_Y | AXIS_Z, 3),
    ] {
        let v = Vol { axes, every, ..Vol::demo(demo, n, ty) };
        let bytes = Host::new().volume(&v);
        let mut eager_mem = big();
        let mut eager = engine(&mut eager_mem);
        eager.feed(&bytes, 0);
        assert!(eager.update(0));
        for (piece, cells) in [(bytes.len(), 1), (100, 30), (7, 1000)] {
            let mut mem = big();
            let mut e = deferring(&mut mem);
            let most = feed_deferring(&mut e, &bytes, piece, cells);
            assert!(most >= 1, "{demo:?}: no slice was deferred");
            assert!(nacks(&answers(&mut e)).is_empty());
            assert!(e.update(1));
            // The same commands in the same order: the same picture, sample
            // for sample.
            assert_eq!(picture(&e), picture(&eager), "{demo:?} {ty:?} piece {piece} cells {cells}");
            assert_eq!(e.frame().collect::<Vec<_>>(), eager.frame().collect::<Vec<_>>());
            assert_eq!(shown(&e), batch(&v));
        }
    }
}

#[test]
fn a_transfer_that_stops_mid_job_times_out_and_keeps_the_picture() {
    let a = Vol::demo(Demo::Torus, 12, SampleType::U8);
    let b = Vol::demo(Demo::Sphere, 12, SampleType::U8);
    let mut mem = big();
    let mut e = deferring(&mut mem);
    feed_deferring(&mut e, &Host::new().volume(&a), 64, 5);
    assert!(e.update(0));
    let before = picture(&e);
    let mut host = Host::new();
    let mut bytes = host.hello();
    bytes.extend(host.begin(&b));
    bytes.extend(host.first_slices(&b, MAX_CHUNK, 3).concat());
    {
        let (mut link, _) = e.split();
        let mut rest = &bytes[..];
        while !rest.is_empty() && !link.busy() {
            let n = link.feed(rest, 10);
            rest = &rest[n..];
        }
        assert!(link.busy(), "the third slice left work pending");
        // The host goes away; nobody calls `contour`. Time passes.
        assert_eq!(link.feed(&[0], 10_000), 1, "the timeout drops the job with the transfer");
        assert!(!link.busy());
    }
    let ev = events(&mut e);
    assert!(ev.iter().any(|x| matches!(x, Event::Aborted { reason: AbortReason::Timeout, .. })), "{ev:?}");
    e.update(10_001);
    assert_eq!(picture(&e), before);
}

#[test]
fn contour_while_does_one_step_a_call_when_told_to_stop() {
    let n = 9usize;
    let v = Vol::demo(Demo::Gyroid, n, SampleType::U8);
    let mut mem = big();
    let mut e = deferring(&mut mem);
    let mut host = Host::new();
    let mut bytes = host.hello();
    bytes.extend(host.begin(&v));
    bytes.extend(host.slices(&v, MAX_CHUNK).concat());
    bytes.extend(host.end());
    // The steps a slice owes, as cells: slice 0 none; slice z the slab
    // between z - 1 and z, a row a step (the back has room for all three
    // planes: x-y n - 1 cells, x-z n - 1, y-z n; the last row has only its
    // x-z cells); the last slice that and its own x-y rows.
    let slab: Vec<usize> = std::iter::repeat_n(3 * n - 2, n - 1).chain([n - 1]).collect();
    let mut want = vec![slab.clone(); n - 2];
    want.push(slab.iter().copied().chain(std::iter::repeat_n(n - 1, n - 1)).collect());
    let (mut link, _) = e.split();
    let mut rest = &bytes[..];
    let (mut steps, mut calls_per_slice) = (Vec::new(), Vec::new());
    while !rest.is_empty() {
        let (mut cells, mut calls) = (Vec::new(), 0);
        while link.busy() {
            link.contour_while(|done| {
                cells.push(done);
                false
            });
            calls += 1;
        }
        if calls > 0 {
            steps.push(cells);
            calls_per_slice.push(calls);
        }
        let k = link.feed(rest, 0);
        rest = &rest[k..];
    }
    // One step a call (the last of a job ends it: no more is asked).
    assert_eq!(calls_per_slice, want.iter().map(Vec::len).collect::<Vec<_>>());
    assert_eq!(steps, want.iter().map(|s| s[..s.len() - 1].to_vec()).collect::<Vec<_>>());
    // A budget in cells: whole steps until it is reached.
    let budget = 2 * (n - 1) + 1;
    let calls_for = |slice: &[usize]| {
        let (mut calls, mut done) = (0, 0);
        for (k, &c) in slice.iter().enumerate() {
            done += c;
            if done >= budget || k + 1 == slice.len() {
                calls += 1;
                done = 0;
            }
        }
        calls
    };
    let mut e2_mem = big();
    let mut e2 = deferring(&mut e2_mem);
    let (mut link, _) = e2.split();
    let mut rest = &bytes[..];
    let mut calls = 0;
    while !rest.is_empty() {
        while link.busy() {
            link.contour(budget);
            calls += 1;
        }
        let k = link.feed(rest, 0);
        rest = &rest[k..];
    }
    assert_eq!(calls, want.iter().map(|s| calls_for(s)).sum::<usize>());
}

/// The samples of the board's next frame ([`Screen::frame`]), and whether it
/// was replayed.
fn board_frame(e: &mut Engine<'_>) -> (Vec<isoscope_core::output::Sample>, bool) {
    let (_, mut screen) = e.split();
    let frame = screen.frame();
    let replayed = frame.is_replay();
    (frame.collect(), replayed)
}

#[test]
fn a_still_picture_is_replayed_and_its_memory_given_back_for_a_volume() {
    let a = Vol::demo(Demo::Torus, 12, SampleType::U8);
    let b = Vol::demo(Demo::Sphere, 12, SampleType::U8);
    let mut mem = big();
    let mut e = engine(&mut mem);
    e.replay_frames(true);
    let mut host = Host::new();
    e.feed(&host.volume(&a), 0);
    assert!(e.update(0));
    let want: Vec<_> = e.frame().collect();
    assert!(want.len() > 100);
    assert_eq!(board_frame(&mut e), (want.clone(), false), "the first frame is scheduled (and kept)");
    for _ in 0..3 {
        assert_eq!(board_frame(&mut e), (want.clone(), true), "the frames after it are replayed");
    }
    assert!(!e.update(5), "nothing changed");
    assert_eq!(board_frame(&mut e), (want.clone(), true));

    // A new view: the kept frame is of the old one.
    let seq = host.next();
    e.feed(
        &frame(&Message::SetView {
            seq,
            yaw: 75.0,
            pitch: 20.0,
            roll: 0.0,
            fov_deg: 0.0,
            spin_deg_per_s: 0.0,
        }),
        6,
    );
    assert_eq!(board_frame(&mut e), (want.clone(), false), "until the update, the old view, live");
    assert!(e.update(6));
    let turned: Vec<_> = e.frame().collect();
    assert_ne!(turned, want);
    assert_eq!(board_frame(&mut e), (turned.clone(), false));
    assert_eq!(board_frame(&mut e), (turned.clone(), true));

    // A volume: its first command waits for the memory (Busy), which the
    // next update gives back; the retry is taken and the transfer goes on.
    let begin = host.begin(&b);
    let rest = [host.slices(&b, MAX_CHUNK).concat(), host.end()].concat();
    answers(&mut e);
    e.feed(&begin, 7);
    assert_eq!(nacks(&answers(&mut e)), [NackCode::Busy]);
    assert_eq!(board_frame(&mut e), (turned.clone(), true), "the picture plays on meanwhile");
    assert!(!e.update(8));
    assert_eq!(board_frame(&mut e), (turned.clone(), false), "live while the volume may come");
    e.feed(&begin, 20);
    e.feed(&rest, 20);
    assert_eq!(nacks(&answers(&mut e)), []);
    assert!(e.update(21));
    assert_eq!(shown(&e), batch(&b));
    let next: Vec<_> = e.frame().collect();
    assert_eq!(board_frame(&mut e), (next.clone(), false));
    assert_eq!(board_frame(&mut e), (next.clone(), true), "the new picture is kept at once");

    // Spinning: every frame is another; none is kept.
    let seq = host.next();
    e.feed(
        &frame(&Message::SetView {
            seq,
            yaw: 0.0,
            pitch: 20.0,
            roll: 0.0,
            fov_deg: 0.0,
            spin_deg_per_s: 90.0,
        }),
        30,
    );
    for t in [30, 40, 50] {
        e.update(t);
        let live: Vec<_> = e.frame().collect();
        assert_eq!(board_frame(&mut e), (live.clone(), false));
        assert_eq!(board_frame(&mut e), (live, false));
    }

    // Off: the memory is the stream's again, a volume is taken at once.
    e.replay_frames(false);
    e.feed(&host.volume(&a), 60);
    assert_eq!(nacks(&answers(&mut e)), []);
}

#[test]
fn a_frame_too_long_for_the_memory_plays_live_every_time() {
    let v = Vol::demo(Demo::Hydrogen, 16, SampleType::U8);
    let mut mem = Mem::sized(2 * v.slice_bytes(), [20_000; 2], 8 * 20_000);
    let mut e = engine(&mut mem);
    e.replay_frames(true);
    e.feed(&Host::new().volume(&v), 0);
    assert!(e.update(0));
    let want: Vec<_> = e.frame().collect();
    assert!(want.len() > 2 * 2 * v.slice_bytes(), "more samples than the memory has bytes");
    for _ in 0..3 {
        assert_eq!(board_frame(&mut e), (want.clone(), false));
    }
}

#[test]
fn hydrogen_32_orders_alike_in_the_head_a_recording_leaves() {
    // The board's picture: pieces folded in the back as they came (897
    // polylines and pieces at the end), the rest spilled into the slice
    // memory, stitched beside the spill, then ordered in the head of the
    // slice memory that a recording's tail leaves (28,672 of 65,536 bytes:
    // too little for u32 words, so in u16 words), whether a recording is
    // kept or not.
    let v = hydrogen32();
    let mut board = Box::new(Firmware::new());
    let mut a = Engine::new(EngineConfig::default(), board.buffers()).unwrap();
    a.feed(&Host::new().volume(&v), 0);
    assert!(a.update(0));
    let picture = |e: &Engine<'_>| e.surface().expect("a picture").commands().collect::<Vec<_>>();
    let sa = a.chain_stats();
    assert!(sa.ordered, "{sa:?}");
    assert_eq!((sa.fragments, sa.points_out, sa.polylines), (897, 7685, 4), "{sa:?}");
    assert_eq!(isoscope_core::engine::replay_tail(65_536), 36_864);
    // The same as in all 65,536 bytes (u32 words): the same stores and
    // slice memory (folded and spilled alike), then ordered in 65,536
    // bytes of extra scratch.
    let mut host = Mem::sized(65_536, [8192, 8192], 65_536);
    let mut b = Engine::new(EngineConfig::default(), host.buffers()).unwrap();
    b.feed(&Host::new().volume(&v), 0);
    assert!(b.update(0));
    assert_eq!(sa, b.chain_stats());
    assert!(picture(&a) == picture(&b), "the same picture, bit for bit");
}

#[test]
fn the_firmware_memory_keeps_hydrogen_32() {
    let v = hydrogen32();
    let mut mem = Box::new(Firmware::new());
    let mut e = Engine::new(EngineConfig::default(), mem.buffers()).unwrap();
    e.replay_frames(true);
    e.feed(&Host::new().volume(&v), 0);
    assert!(e.update(0));
    let want: Vec<_> = e.frame().collect();
    assert_eq!(board_frame(&mut e), (want.clone(), false));
    assert_eq!(board_frame(&mut e), (want, true), "hydrogen 32^3's frame fits the board's slice memory");
}

/// One frame as a board plays it while bytes arrive, at time `t`: between
/// refills of 512 samples (handed to `put`), some rows of a completed
/// slice contoured or up to 256 bytes of `rest` fed. Returns whether the
/// frame was replayed, and whether it was recorded as it played.
fn board_plays(
    e: &mut Engine<'_>,
    rest: &mut &[u8],
    t: u32,
    mut put: impl FnMut(isoscope_core::output::Sample),
) -> (bool, bool) {
    let (mut link, mut screen) = e.split();
    let mut frame = screen.frame();
    let recorded = matches!(frame, isoscope_core::engine::Frame::Recording(..));
    loop {
        let n = frame.fill_with(512, &mut put);
        if link.busy() {
            link.contour(2000);
        } else if !rest.is_empty() {
            let k = link.feed(&rest[..256.min(rest.len())], t);
            *rest = &rest[k..];
        }
        if n < 512 {
            break;
        }
    }
    (frame.is_replay(), recorded)
}

/// Play frames as a board does while `bytes` arrive ([`board_plays`]);
/// [`Engine::update`] at each frame boundary until every byte is taken
/// and contoured (the commit is left to the caller). Returns each frame's
/// samples and whether it was replayed.
fn board_receives(
    e: &mut Engine<'_>,
    bytes: &[u8],
    t0: u32,
) -> Vec<(Vec<isoscope_core::output::Sample>, bool)> {
    let mut rest = bytes;
    let mut frames = Vec::new();
    for t in t0.. {
        let mut got = Vec::new();
        let (replayed, _) = board_plays(e, &mut rest, t, |s| got.push(s));
        frames.push((got, replayed));

        if rest.is_empty() && !e.split().0.busy() {
            break;
        }
        assert!(frames.len() < 10_000, "the volume never went in");
        assert!(!e.update(t), "no new picture while the volume arrives");
    }
    frames
}

/// The board's settings: contouring deferred (and frames replayed,
/// [`board_showing_a_torus`]).
fn board_config() -> EngineConfig {
    EngineConfig { defer_contouring: true, ..EngineConfig::default() }
}

/// A board with nothing recorded, in `mem`, sent `new` and showing it: the
/// picture a board that played something else before must draw.
fn fresh_board<'m>(mem: &'m mut Firmware, new: &Vol) -> Engine<'m> {
    let mut f = Engine::new(board_config(), mem.buffers()).unwrap();
    feed_deferring(&mut f, &Host::new().volume(new), 256, 2000);
    assert!(f.update(0));
    f
}

/// The update at `now` that commits, as a board makes it: the samples the
/// commit's polls take (300 a poll) and the rest of the frame then
/// playing ([`Engine::unfinished`]), and how many polls there were.
fn commit_playing(e: &mut Engine<'_>, now: u32) -> (Vec<isoscope_core::output::Sample>, usize) {
    let mut during = Vec::new();
    let mut calls = 0;
    assert!(e.update_playing(now, &mut |p| {
        calls += 1;
        p.fill_with(300, |s| during.push(s));
    }));
    if let Some(p) = e.unfinished() {
        during.extend(p);
    }
    (during, calls)
}

/// A board over `mem` showing a still torus 12^3 (`u8`), whose recording
/// fits the tail; and the host that sent it.
fn board_showing_a_torus(mem: &mut Firmware) -> (Engine<'_>, Host) {
    let mut e = Engine::new(board_config(), mem.buffers()).unwrap();
    e.replay_frames(true);
    let mut host = Host::new();
    feed_deferring(&mut e, &host.volume(&Vol::demo(Demo::Torus, 12, SampleType::U8)), 256, 2000);
    assert!(e.update(0));
    (e, host)
}

/// A view at yaw 30 and pitch 20, spinning at 90 degrees a second.
fn spinning(host: &mut Host) -> Vec<u8> {
    let seq = host.next();
    frame(&Message::SetView { seq, yaw: 30.0, pitch: 20.0, roll: 0.0, fov_deg: 0.0, spin_deg_per_s: 90.0 })
}

#[test]
fn a_still_picture_plays_on_from_the_tail_through_a_volume_and_its_commit() {
    // The board's memory and settings, and a picture whose recording fits
    // the tail (36,864 bytes): `board_showing_a_torus`. The new volume's
    // slices fit the head and its pieces the back; or its pieces are
    // folded on the way and spill into the head (gyroid 28^3 `f32`, which
    // then thins, and hydrogen 32^3); or its two slices (128 x 128 `u8`,
    // 32 KB, as the MRI head's) are more than the head holds: they take
    // all of the slice memory, the old picture plays live, and is recorded
    // into the tail in one more frame before the commit.
    let wide = Vol::demo(Demo::Sphere, 12, SampleType::U8).padded(128, 128, 0.0);
    assert!(2 * wide.slice_bytes() > 65_536 - isoscope_core::engine::replay_tail(65_536));
    for (new, receive, plays) in [
        (Vol::demo(Demo::Sphere, 12, SampleType::U8), true, true),
        (Vol::demo(Demo::Gyroid, 28, SampleType::F32), true, true),
        (hydrogen32(), true, true),
        // Its spill and the stitch pass's reserve are more than the memory
        // less the recording: the stitch takes what is left (the same
        // picture, in longer walks).
        (Vol::demo(Demo::Torus, 24, SampleType::F32), true, true),
        (wide, false, true),
    ] {
        let mut board = Box::new(Firmware::new());
        let (mut e, mut host) = board_showing_a_torus(&mut board);
        let (first, replayed) = board_frame(&mut e);
        assert!(!replayed);
        assert_eq!(board_frame(&mut e), (first.clone(), true));

        // The recording is in the tail: the head is the stream's at once,
        // and the first command is taken.
        let begin = host.begin(&new);
        answers(&mut e);
        e.feed(&begin, 1);
        if receive {
            assert_eq!(nacks(&answers(&mut e)), []);
            assert_eq!(e.state(), DeviceState::Receiving);
            assert!(!e.update(2));
            let (again, replayed) = board_frame(&mut e);
            assert!(again == first && replayed, "from the tail");
        } else {
            // Slices the head cannot hold: `Busy` once, all of the memory
            // at the next frame boundary, and the volume begins again.
            assert_eq!(nacks(&answers(&mut e)), [NackCode::Busy]);
            assert!(!e.update(2));
            e.feed(&begin, 2);
            assert_eq!(nacks(&answers(&mut e)), []);
            assert_eq!(e.state(), DeviceState::Receiving);
        }
        let bytes = [host.slices(&new, MAX_CHUNK).concat(), host.end()].concat();
        let frames = board_receives(&mut e, &bytes, 3);
        assert_eq!(nacks(&answers(&mut e)), []);
        assert!(frames.iter().all(|(s, _)| *s == first), "the old picture plays on");
        let replayed = frames.iter().filter(|(_, r)| *r).count();
        if receive {
            assert_eq!(replayed, frames.len(), "every frame from the tail");
        } else {
            assert!(replayed < frames.len(), "live once the spill took the tail");
        }
        assert_eq!(e.commit_parks(), !plays, "{:?} {:?}", new.dims, new.ty);
        if plays && !receive {
            // A frame boundary: the tail is lent to the screen, which
            // records the old picture there as it plays it.
            assert!(!e.update(4), "the commit waits a frame");
            assert_eq!(board_frame(&mut e), (first.clone(), false), "recorded as it plays");
            assert!(!e.commit_parks());
        }

        // The commit: the old frame plays on, over and over, then to its end.
        let (during, calls) = commit_playing(&mut e, 4);
        assert!(e.unfinished().is_none(), "taken once");
        if plays {
            assert!(calls > 1, "{calls} polls");
            assert!(during.len() >= first.len() && during.len() % first.len() == 0, "{}", during.len());
            assert!(during.chunks(first.len()).all(|f| f == first), "whole frames of the old picture");
        } else {
            assert_eq!((calls, during.len()), (0, 0), "nothing to play: the beam waits");
        }

        // The new picture is the one a board with nothing recorded draws.
        let mut fresh = Box::new(Firmware::new());
        let f = fresh_board(&mut fresh, &new);
        assert_eq!(e.chain_stats(), f.chain_stats());
        assert!(picture(&e) == picture(&f), "the same picture, bit for bit");
        let want: Vec<_> = f.frame().collect();
        assert_eq!(board_frame(&mut e), (want.clone(), false));
        assert_eq!(board_frame(&mut e), (want, true), "and it is replayed in turn");
    }
}

/// A commit that needs more of the memory than the old picture's
/// recording leaves it (gyroid 32^3 sent whole after a torus 12^3: its
/// spill and the stitch's least scratch are 14.4 KB short) does not park:
/// at a frame boundary the recording is thinned in place (the beam held
/// for that alone), then the commit plays the old picture, thinned (a
/// subsequence of its frame, in under two thirds of its samples), over and
/// over; the new picture is a fresh board's.
#[test]
fn a_commit_short_of_memory_plays_the_old_picture_thinned() {
    let mut board = Box::new(Firmware::new());
    let (mut e, mut host) = board_showing_a_torus(&mut board);
    let (first, _) = board_frame(&mut e);
    assert!(board_frame(&mut e).1, "replayed");
    let new = Vol::demo(Demo::Gyroid, 32, SampleType::U8);
    let begin = host.begin(&new);
    answers(&mut e);
    e.feed(&begin, 1);
    assert_eq!(nacks(&answers(&mut e)), []);
    let bytes = [host.slices(&new, MAX_CHUNK).concat(), host.end()].concat();
    let frames = board_receives(&mut e, &bytes, 3);
    assert_eq!(nacks(&answers(&mut e)), []);
    assert!(frames.iter().all(|(s, _)| *s == first), "the old picture plays on");

    assert!(e.commit_parks(), "held for the thinning");
    assert!(!e.update(4), "the thinning, not yet the commit");
    let (thin, replayed) = board_frame(&mut e);
    assert!(replayed, "from the thinned recording");
    let mut it = first.iter();
    assert!(thin.iter().all(|s| it.any(|f| f == s)), "a subsequence of the frame");
    assert_eq!(thin.last(), first.last());
    assert!(3 * thin.len() < 2 * first.len(), "{} of {} samples", thin.len(), first.len());

    assert!(!e.commit_parks(), "the commit plays it on");
    let (during, calls) = commit_playing(&mut e, 5);
    assert!(calls > 1, "{calls} polls");
    assert!(during.len() >= thin.len() && during.len() % thin.len() == 0, "{}", during.len());
    assert!(during.chunks(thin.len()).all(|f| f == thin), "whole frames of the thinned picture");

    let mut fresh = Box::new(Firmware::new());
    let f = fresh_board(&mut fresh, &new);
    assert_eq!(e.chain_stats(), f.chain_stats());
    assert!(picture(&e) == picture(&f), "the same picture, bit for bit");
}

/// A spinning picture is not recorded as it plays (each frame is another
/// angle), so when a volume's back must be folded into the front (its
/// store), the picture must be recorded first: held still for one frame
/// and recorded as that frame plays, never scheduled at once with the beam
/// parked (some 30 ms for a large picture, more than a frame). Hydrogen
/// 32^3, which folds on the way, after a spinning torus 12^3.
#[test]
fn a_spinning_picture_is_held_and_recorded_as_it_plays_before_a_fold() {
    let mut board = Box::new(Firmware::new());
    let (mut e, mut host) = board_showing_a_torus(&mut board);
    e.feed(&spinning(&mut host), 1);
    assert!(e.update(1));
    let (a, _) = board_frame(&mut e);
    e.update(20);
    let (b, replayed) = board_frame(&mut e);
    assert!(a != b && !replayed, "it spins, frame after frame");

    let new = hydrogen32();
    // Nothing recorded: the first command waits for the slice memory
    // (`Busy`), which the next update gives back.
    let begin = host.begin(&new);
    answers(&mut e);
    e.feed(&begin, 21);
    assert_eq!(nacks(&answers(&mut e)), [NackCode::Busy]);
    e.update(22);
    e.feed(&begin, 23);
    assert_eq!(nacks(&answers(&mut e)), []);
    assert_eq!(e.state(), DeviceState::Receiving);
    let bytes = [host.slices(&new, MAX_CHUNK).concat(), host.end()].concat();
    let mut rest = &bytes[..];
    let (mut folds, mut held) = (0, 0);
    for t in 30.. {
        assert!(t < 20_000, "the volume never went in");
        let waits = e.split().0.waits();
        assert!(!(waits && e.commit_parks()), "a fold parks the beam at t={t}");
        folds += usize::from(waits);
        e.update(t);
        if rest.is_empty() && e.state() != DeviceState::Receiving && !e.split().0.busy() {
            assert!(!e.commit_parks(), "the commit parks the beam");
            e.update(t + 1);
            break;
        }
        let (_, recorded) = board_plays(&mut e, &mut rest, t, |_| {});
        held += usize::from(recorded);
        answers(&mut e);
    }
    assert!(folds > 0, "hydrogen 32^3 folds on the way");
    assert!(held > 0, "the spinning picture was held and recorded");
    // And the picture is a fresh board's that spins too (a spinning view
    // orders in space, for every angle).
    let mut fresh = Box::new(Firmware::new());
    let mut f = Engine::new(board_config(), fresh.buffers()).unwrap();
    let mut other = Host::new();
    f.feed(&spinning(&mut other), 0);
    feed_deferring(&mut f, &other.volume(&new), 256, 2000);
    assert!(f.update(0));
    assert_eq!(e.chain_stats(), f.chain_stats());
    // (Its frame is at another angle: the surface, in space.)
    let surface = |e: &Engine<'_>| e.surface().map(|g| g.commands().collect::<Vec<_>>()).unwrap();
    assert!(surface(&e) == surface(&f), "the same picture, bit for bit");
}

/// The beam parks for no fold and for the commits of all but the largest
/// surfaces: every demo volume the core tests use (torus, gyroid, sphere
/// and hydrogen at 20, 24, 28 and 32, `u8` and `f32`), sent to a board
/// after a still torus 12^3 and played as a board plays them. The two
/// that park need more than the slice memory less the recording for
/// their stitch (the spill, and the least scratch worth stitching in:
/// `stitch_least`).
#[test]
fn the_beam_parks_only_for_commits_that_need_all_of_the_memory() {
    let mut parking = Vec::new();
    let mut held = 0;
    for demo in [Demo::Torus, Demo::Gyroid, Demo::Sphere, Demo::Hydrogen] {
        for n in [20, 24, 28, 32] {
            for ty in [SampleType::U8, SampleType::F32] {
                let new = Vol::demo(demo, n, ty);
                let mut board = Box::new(Firmware::new());
                let (mut e, mut host) = board_showing_a_torus(&mut board);
                board_frame(&mut e);
                assert!(board_frame(&mut e).1, "recorded");
                let begin = host.begin(&new);
                answers(&mut e);
                e.feed(&begin, 1);
                if !nacks(&answers(&mut e)).is_empty() {
                    e.update(2);
                    e.feed(&begin, 2);
                    assert_eq!(nacks(&answers(&mut e)), []);
                }
                let bytes = [host.slices(&new, MAX_CHUNK).concat(), host.end()].concat();
                let mut rest = &bytes[..];
                for t in 3.. {
                    assert!(t < 50_000, "{demo:?} {n} {ty:?} never went in");
                    let done = rest.is_empty() && e.state() != DeviceState::Receiving && !e.split().0.busy();
                    let parks = e.commit_parks();
                    if parks {
                        assert!(!e.split().0.waits(), "{demo:?} {n} {ty:?}: a fold parks the beam");
                    }
                    let shown = e.counters().volumes;
                    e.update(t);
                    if parks && e.counters().volumes > shown {
                        parking.push(format!("{demo:?} {n} {ty:?}"));
                    } else if parks {
                        // Only the recording's thinning, a few ms: once.
                        held += 1;
                    }
                    if done {
                        break;
                    }
                    board_plays(&mut e, &mut rest, t, |_| {});
                    answers(&mut e);
                }
                assert_eq!(e.counters().volumes, 2, "{demo:?} {n} {ty:?} committed");
            }
        }
    }
    assert_eq!(parking, Vec::<String>::new());
    assert_eq!(held, 2, "gyroid 32^3 u8 and f32 thin the old picture's recording, each once");
}

/// A spinning picture is not recorded as it plays: before a commit it is
/// held still for a frame and recorded, so that the commit plays it on
/// rather than parking the beam. A sphere 12^3 after a spinning torus.
#[test]
fn a_spinning_picture_is_held_and_recorded_as_it_plays_before_a_commit() {
    let mut board = Box::new(Firmware::new());
    let (mut e, mut host) = board_showing_a_torus(&mut board);
    e.feed(&spinning(&mut host), 0);
    e.update(0);
    let new = Vol::demo(Demo::Sphere, 12, SampleType::U8);
    let begin = host.begin(&new);
    answers(&mut e);
    e.feed(&begin, 0);
    assert_eq!(nacks(&answers(&mut e)), [NackCode::Busy]);
    e.update(0);
    e.feed(&begin, 0);
    feed_deferring(&mut e, &[host.slices(&new, MAX_CHUNK).concat(), host.end()].concat(), 256, 2000);
    assert_eq!(nacks(&answers(&mut e)), []);
    assert_ne!(e.state(), DeviceState::Receiving);
    assert!(!e.commit_parks(), "the commit waits a frame instead");
    e.update(0);
    let (held, replayed) = board_frame(&mut e);
    assert!(!replayed, "recorded as it plays");
    assert!(!e.commit_parks(), "the commit plays it on");
    let (during, _) = commit_playing(&mut e, 0);
    assert!(
        !during.is_empty() && during.chunks(held.len()).all(|f| f == held),
        "the held frame, over and over: {} of {}",
        during.len(),
        held.len()
    );
}
