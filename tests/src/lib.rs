//! Shared helpers of isoscope's cross-crate tests (the tests themselves are
//! in `tests/`): build a demo volume and contour it with the host library.

use isoscope_core::contour::grid::{Plane, Volume};
use isoscope_core::contour::trace::Traversal;
use isoscope_core::demo::Demo;
use isoscope_sim::contour::{Contoured, Job, contour_volume};

/// The `n`^3 samples of a built-in demo, x fastest.
pub fn demo_samples(demo: Demo, n: usize) -> Vec<f32> {
    let mut data = vec![0f32; n * n * n];
    demo.fill(n, &mut data).expect("demo fill");
    data
}

/// The `n`^3 samples of a built-in demo as they go to a board.
pub fn demo_wire(demo: Demo, n: usize) -> isoscope_sim::link::WireVolume {
    let samples = isoscope_sim::volume::Samples::F32(demo_samples(demo, n));
    isoscope_sim::link::WireVolume::new(isoscope_sim::volume::Dims(n, n, n), &samples, [1.0; 3])
        .expect("demo volume")
}

/// A cached real data file (see [`real_data`]) as it goes to a board.
pub fn real_wire(name: &str) -> isoscope_sim::link::WireVolume {
    let v = isoscope_sim::volume::LoadedVolume::read_known(&real_data(name))
        .expect("a readable file")
        .expect("a known format");
    isoscope_sim::link::WireVolume::from_loaded(&v).expect("a volume a board takes")
}

/// Contour the `n`^3 demo at `levels` on `planes` with the corrected
/// traversal on `threads` threads, keeping the commands.
pub fn contour_demo(demo: Demo, n: usize, levels: &[f32], planes: &[Plane], threads: usize) -> Contoured {
    let data = demo_samples(demo, n);
    let volume = Volume::new(&data, n, n, n).expect("demo volume");
    let job = Job { planes, levels, traversal: Traversal::Compiled, threads, keep: true, every: 1 };
    contour_volume(&volume, &job, None).expect("contouring a demo")
}

/// Path of a cached real data file (fetched by `scripts/fetch-data`, which
/// `scripts/test` runs first). Panics with the command to run when absent,
/// so a missing file fails the test rather than skipping it.
pub fn real_data(name: &str) -> std::path::PathBuf {
    let dir = std::env::var_os("ISOSCOPE_DATA")
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/isoscope-data"));
    let path = dir.join(name);
    assert!(path.is_file(), "{} is missing: run scripts/fetch-data (scripts/test does)", path.display());
    path
}
