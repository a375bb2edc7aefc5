//! Contouring speed. `cargo bench -p isoscope-core --bench contour`
//!
//! - `surface/*`: all 3 x 256 axis slices of a 256^3 f32 gyroid at level 0,
//!   single thread (docs/performance.md's Mcells/s figure), and the same volume at a
//!   level no cell meets (the cost of the skip test alone).
//! - `cells/*`: the crossing cells of one x-y slice: building their trees
//!   (subgrid, direction code, template lookup) versus traversing them
//!   (traversal, placement, tidying: everything after the lookup).
//! - `levels/*`: ten levels on reused trees versus ten separate passes.

use criterion::{BenchmarkId, Criterion, Throughput, black_box, criterion_group, criterion_main};
use isoscope_core::command::{Command, CommandSink, Point2, Point3};
use isoscope_core::contour::contour_subgrid;
use isoscope_core::contour::grid::{Plane, Planes, Volume};
use isoscope_core::contour::pen::Placement;
use isoscope_core::contour::subgrid::Subgrid;
use isoscope_core::contour::surface::{SliceId, SurfaceSink, contour_volume};
use isoscope_core::contour::trace::Traversal;
use isoscope_core::contour::tree::Template;
use isoscope_core::demo::Demo;
use std::convert::Infallible;
use std::time::Duration;

/// A checksum of every point: cheap, and it keeps the compiler from
/// skipping the coordinates.
#[derive(Default)]
struct Count(u32);

impl Count {
    #[inline(always)]
    fn add(&mut self, x: f32, y: f32, z: f32) {
        self.0 =
            self.0.rotate_left(5) ^ x.to_bits() ^ y.to_bits().rotate_left(11) ^ z.to_bits().rotate_left(22);
    }
}

impl SurfaceSink for Count {
    type Error = Infallible;
    #[inline(always)]
    fn command(&mut self, _: SliceId, _: usize, c: Command<Point3>) -> Result<(), Infallible> {
        let p = c.point();
        self.add(p.x, p.y, p.z);
        Ok(())
    }
}

impl CommandSink<Point2> for Count {
    type Error = Infallible;
    #[inline(always)]
    fn command(&mut self, _: usize, c: Command<Point2>) -> Result<(), Infallible> {
        let p = c.point();
        self.add(p.x, p.y, 0.0);
        Ok(())
    }
}

fn gyroid(n: usize) -> Vec<f32> {
    let mut v = vec![0.0; n * n * n];
    Demo::Gyroid.fill(n, &mut v).unwrap();
    v
}

fn surface(c: &mut Criterion) {
    let n = 256;
    let data = gyroid(n);
    let vol = Volume::new(&data, n, n, n).unwrap();
    let cells = 3 * n * (n - 1) * (n - 1);
    let mut g = c.benchmark_group("surface");
    g.sample_size(10).measurement_time(Duration::from_secs(8)).throughput(Throughput::Elements(cells as u64));
    for (name, level) in [("gyroid256_level0", 0.0f32), ("gyroid256_no_crossing", 100.0)] {
        g.bench_function(name, |b| {
            b.iter(|| {
                let mut sink = Count::default();
                contour_volume(&vol, Planes::ALL, &[level], Traversal::Corrected, &mut sink).unwrap();
                sink.0
            })
        });
    }
    g.finish();
}

fn crossing_cells(n: usize) -> Vec<([f32; 4], (usize, usize))> {
    let data = gyroid(n);
    let vol = Volume::new(&data, n, n, n).unwrap();
    let g = vol.slice(Plane::XY, n / 2).unwrap();
    let mut out = vec![];
    for j in 0..n - 1 {
        for i in 0..n - 1 {
            let c = [g.get(i, j), g.get(i + 1, j), g.get(i + 1, j + 1), g.get(i, j + 1)].map(|v| v.unwrap());
            if c.iter().any(|&v| v <= 0.0) && c.iter().any(|&v| v >= 0.0) {
                out.push((c, (i, j)));
            }
        }
    }
    out
}

fn cells(c: &mut Criterion) {
    let cells = crossing_cells(256);
    let mut g = c.benchmark_group("cells");
    g.throughput(Throughput::Elements(cells.len() as u64));
    g.bench_function("tree_build", |b| {
        b.iter(|| {
            let mut acc = 0usize;
            for (v, _) in &cells {
                let sub = Subgrid::new(v[0], v[1], v[2], v[3]).unwrap();
                acc += Template::for_code(black_box(sub).code()).tree_count();
            }
            acc
        })
    });
    let built: Vec<_> = cells
        .iter()
        .map(|(v, at)| (Subgrid::new(v[0], v[1], v[2], v[3]).unwrap(), Placement::new(at.0, at.1)))
        .collect();
    g.bench_function("traverse", |b| {
        b.iter(|| {
            let mut sink = Count::default();
            for (sub, at) in &built {
                contour_subgrid(sub, *at, &[0.0], Traversal::Corrected, &Point2::new, &mut sink).unwrap();
            }
            sink.0
        })
    });
    g.finish();
}

fn levels(c: &mut Criterion) {
    let n = 128;
    let data = gyroid(n);
    let vol = Volume::new(&data, n, n, n).unwrap();
    let levels: Vec<f32> = (0..10).map(|i| -0.9 + 0.2 * i as f32).collect();
    let mut g = c.benchmark_group("levels");
    g.sample_size(10).throughput(Throughput::Elements((3 * n * (n - 1) * (n - 1)) as u64));
    g.bench_function(BenchmarkId::new("gyroid128_ten", "reused_trees"), |b| {
        b.iter(|| {
            let mut sink = Count::default();
            contour_volume(&vol, Planes::ALL, &levels, Traversal::Corrected, &mut sink).unwrap();
            sink.0
        })
    });
    g.bench_function(BenchmarkId::new("gyroid128_ten", "separate_passes"), |b| {
        b.iter(|| {
            let mut sink = Count::default();
            for l in &levels {
                contour_volume(&vol, Planes::ALL, std::slice::from_ref(l), Traversal::Corrected, &mut sink)
                    .unwrap();
            }
            sink.0
        })
    });
    g.bench_function(BenchmarkId::new("gyroid128_one", "level0"), |b| {
        b.iter(|| {
            let mut sink = Count::default();
            contour_volume(&vol, Planes::ALL, &[0.1], Traversal::Corrected, &mut sink).unwrap();
            sink.0
        })
    });
    g.finish();
}

criterion_group!(benches, surface, cells, levels);
criterion_main!(benches);
