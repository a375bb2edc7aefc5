//! Shared helpers of isoscope's cross-crate tests (the tests themselves are
//! in `tests/`): build a demo volume and contour it with the host library.

use isoscope_core::demo::Demo;
use isoscope_core::grid::{Plane, Volume};
use isoscope_core::trace::Traversal;
use isoscope_sim::contour::{Contoured, Job, contour_volume};

/// The `n`^3 samples of a built-in demo, x fastest.
pub fn demo_samples(demo: Demo, n: usize) -> Vec<f32> {
    let mut data = vec![0f32; n * n * n];
    demo.fill(n, &mut data).expect("demo fill");
    data
}

/// Contour the `n`^3 demo at `levels` on `planes` with the corrected
/// traversal on `threads` threads, keeping the commands.
pub fn contour_demo(demo: Demo, n: usize, levels: &[f32], planes: &[Plane], threads: usize) -> Contoured {
    let data = demo_samples(demo, n);
    let volume = Volume::new(&data, n, n, n).expect("demo volume");
    let job = Job { planes, levels, traversal: Traversal::Corrected, threads, keep: true };
    contour_volume(&volume, &job, None).expect("contouring a demo")
}
