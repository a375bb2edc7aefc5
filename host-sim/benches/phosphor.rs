//! Drawing a frame on the simulated phosphor, as `render` and the web page
//! do: `cargo bench -p isoscope-sim --bench phosphor`.
//!
//! The frame is hydrogen 32^3's at the default view and settings (the
//! page's first picture, some 17,700 samples). `phosphor/deposit` lays
//! its samples on a black 640x640 screen (the page's size), reported in
//! samples per second; `phosphor/pixels` turns the energy into the
//! canvas's RGBA bytes (glow, exposure, palette), in pixels per second.

use criterion::{Criterion, Throughput, black_box, criterion_group, criterion_main};
use isoscope_core::demo::Demo;
use isoscope_sim::link::WireVolume;
use isoscope_sim::phosphor::{Phosphor, PhosphorConfig};
use isoscope_sim::scene::{SceneConfig, build};
use isoscope_sim::volume::{Dims, Samples};

const SIZE: u32 = 640;

fn hydrogen32() -> Vec<isoscope_core::output::Sample> {
    let n = 32;
    let mut data = vec![0f32; n * n * n];
    Demo::Hydrogen.fill(n, &mut data).expect("demo");
    let vol = WireVolume::new(Dims(n, n, n), &Samples::F32(data), [1.0; 3]).expect("volume");
    let cfg = SceneConfig { levels: vec![Demo::Hydrogen.default_level()], ..SceneConfig::default() };
    build(&vol, &cfg).expect("scene").samples
}

fn bench(c: &mut Criterion) {
    let samples = hydrogen32();
    let cfg = PhosphorConfig::with_size(SIZE, SIZE);
    let mut g = c.benchmark_group("phosphor");
    g.throughput(Throughput::Elements(samples.len() as u64));
    g.bench_function("deposit", |b| {
        let mut screen = Phosphor::new(cfg.clone()).expect("phosphor");
        b.iter(|| {
            screen.clear();
            screen.deposit(black_box(samples.iter().copied()));
        });
    });
    let mut screen = Phosphor::new(cfg.clone()).expect("phosphor");
    screen.deposit(samples.iter().copied());
    g.throughput(Throughput::Elements(u64::from(SIZE * SIZE)));
    g.bench_function("pixels", |b| b.iter(|| black_box(screen.to_rgba8())));
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
