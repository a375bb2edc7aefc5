//! Playing the picture: the device engine's refill path, the one the
//! firmware runs between DMA halves. `cargo bench -p isoscope-core --bench frame`
//!
//! The engine holds a received hydrogen 16^3 volume (the firmware's boot
//! demo at the firmware's default settings); `frame/iter` plays one frame
//! through the scheduler's `Iterator`, `frame/fill` through
//! `Scheduler::fill` into 512-sample halves, as the firmware does before
//! a frame is kept, `frame/replay` from the kept frame (`Engine::replay_frames`)
//! as it does after. All report samples per second. `frame/project` is the
//! geometry and the view alone (no beam).
//!
//! `volume/hydrogen{16,24}` receives a whole volume: decoding, streaming
//! contouring and the commit (stitching and ordering).
//!
//! Under callgrind (`valgrind --tool=callgrind target/release/deps/frame-*
//! --bench --profile-time 2 frame/fill`) this shows where a sample's
//! instructions go.

use criterion::{Criterion, Throughput, black_box, criterion_group, criterion_main};
use isoscope_core::demo::Demo;
use isoscope_core::engine::{Engine, EngineConfig, Geometry, StaticBuffers};
use isoscope_core::output::{Sample, SampleSource};
use isoscope_core::wire::{AXIS_X, AXIS_Y, AXIS_Z, Levels, MAX_CHUNK, Message, SampleType, encode};

const SIDE: usize = 16;
/// Samples per DMA half in the firmware.
const HALF: usize = 512;

/// The firmware's engine memory: 32 KB slices, 128-sample rows, 8192
/// points a surface.
type Mem = StaticBuffers<{ 32 * 1024 }, { Geometry::bytes_for(8192) }>;

fn engine(mem: &mut Mem) -> Engine<'_> {
    Engine::new(EngineConfig::default(), mem.buffers()).expect("engine")
}

fn feed_demo(engine: &mut Engine<'_>, side: usize) {
    let mut buf = vec![0u8; 4096];
    let mut send = |m: &Message<'_>, e: &mut Engine<'_>| {
        let f = encode(m, &mut buf).expect("encodes").to_vec();
        e.feed(&f, 0);
    };
    let levels = Levels::from_slice(&[Demo::Hydrogen.default_level()]).expect("one level");
    let n = side;
    let side = n as u16;
    send(
        &Message::BeginVolume {
            seq: 0,
            dims: [side; 3],
            sample_type: SampleType::F32,
            spacing: [1.0; 3],
            levels,
            axes: AXIS_X | AXIS_Y | AXIS_Z,
            every: 1,
        },
        engine,
    );
    let mut data = vec![0u8; n * n * 4];
    let mut seq = 1u16;
    for k in 0..n {
        for (i, b) in data.chunks_exact_mut(4).enumerate() {
            b.copy_from_slice(&Demo::Hydrogen.sample(n, i % n, i / n, k).to_le_bytes());
        }
        for (j, chunk) in data.chunks(MAX_CHUNK).enumerate() {
            let offset = (j * MAX_CHUNK) as u32;
            send(&Message::SliceData { seq, slice: k as u16, offset, data: chunk }, engine);
            seq += 1;
        }
    }
    send(&Message::EndVolume { seq }, engine);
    assert!(engine.update(0), "the volume makes a picture");
}

/// Receiving a volume: decoding, streaming contouring, then the commit
/// (stitching and ordering) in `update`.
fn volume(c: &mut Criterion) {
    let mut mem = Box::new(Mem::new());
    let mut g = c.benchmark_group("volume");
    g.sample_size(20);
    for side in [16, 24] {
        g.bench_function(format!("hydrogen{side}"), |b| {
            b.iter(|| {
                let mut engine = engine(&mut mem);
                feed_demo(&mut engine, side);
                black_box(engine.counters().volumes)
            })
        });
    }
    g.finish();
}

fn frame(c: &mut Criterion) {
    let mut mem = Box::new(Mem::new());
    let mut engine = engine(&mut mem);
    feed_demo(&mut engine, SIDE);
    let samples = engine.frame().count() as u64;
    let commands = engine.commands().count();
    eprintln!("hydrogen {SIDE}^3: {commands} commands, {samples} samples a frame");
    let mut g = c.benchmark_group("frame");
    g.throughput(Throughput::Elements(samples));
    g.bench_function("iter", |b| {
        b.iter(|| {
            let mut sum = 0u32;
            for s in engine.frame() {
                sum = sum.wrapping_add(u32::from(s.x) ^ u32::from(s.y) << 1 ^ s.beam as u32);
            }
            black_box(sum)
        })
    });
    g.bench_function("fill", |b| {
        let mut half = [Sample::default(); HALF];
        b.iter(|| {
            let mut sum = 0u32;
            let mut f = engine.frame();
            loop {
                let n = f.fill(&mut half);
                for s in half.iter().take(n) {
                    sum = sum.wrapping_add(u32::from(s.x) ^ u32::from(s.y) << 1 ^ s.beam as u32);
                }
                if n < HALF {
                    break;
                }
            }
            black_box(sum)
        })
    });
    g.bench_function("project", |b| b.iter(|| engine.commands().fold(0f32, |a, c| a + c.point().x)));
    // The board's frames once the first is kept: replayed from memory.
    engine.replay_frames(true);
    engine.update(0);
    let (_, mut screen) = engine.split();
    assert_eq!(screen.frame().count() as u64, samples, "the first frame is recorded");
    assert!(screen.frame().is_replay(), "the frame is kept");
    g.bench_function("replay", |b| {
        b.iter(|| {
            let mut sum = 0u32;
            let mut f = screen.frame();
            loop {
                let n = f.fill_with(HALF, |s| {
                    sum = sum.wrapping_add(u32::from(s.x) ^ u32::from(s.y) << 1 ^ s.beam as u32);
                });
                if n < HALF {
                    break;
                }
            }
            black_box(sum)
        })
    });
    g.finish();
}

criterion_group!(benches, frame, volume);
criterion_main!(benches);
