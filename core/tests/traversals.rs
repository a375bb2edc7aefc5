//! The compiled traversal ([`Traversal::Compiled`], the default) draws the
//! corrected tree traversal's commands, bit for bit, on whole volumes: every
//! slice of every plane of the demos, at several levels, in `f32` and
//! quantised to small integers at integer levels (where many nodes lie
//! exactly at the level and the trees are walked).

use isoscope_core::command::{Command, Point3};
use isoscope_core::contour::grid::{Planes, Volume};
use isoscope_core::contour::surface::{SliceId, SurfaceSink, contour_volume};
use isoscope_core::contour::trace::Traversal;
use isoscope_core::demo::Demo;
use std::convert::Infallible;

#[derive(Default)]
struct Bits(Vec<(SliceId, usize, Command<[u32; 3]>)>);

impl SurfaceSink for Bits {
    type Error = Infallible;
    fn command(&mut self, slice: SliceId, level: usize, c: Command<Point3>) -> Result<(), Infallible> {
        self.0.push((slice, level, c.map(|p| [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()])));
        Ok(())
    }
}

fn both(data: &[f32], n: usize, levels: &[f32]) -> usize {
    let volume = Volume::new(data, n, n, n).unwrap();
    let run = |t| {
        let mut s = Bits::default();
        let stats = contour_volume(&volume, Planes::ALL, levels, t, &mut s).unwrap();
        (s.0, stats)
    };
    let (compiled, corrected) = (run(Traversal::Compiled), run(Traversal::Corrected));
    assert_eq!(compiled.1, corrected.1);
    assert!(compiled.0 == corrected.0, "the traversals differ at levels {levels:?}");
    compiled.0.len()
}

#[test]
fn compiled_equals_the_trees_on_the_demos() {
    let n = 24;
    let mut data = vec![0.0; n * n * n];
    for demo in [Demo::Hydrogen, Demo::Gyroid, Demo::Sphere, Demo::Torus] {
        demo.fill(n, &mut data).unwrap();
        let d = demo.default_level();
        let drawn = both(&data, n, &[d]) + both(&data, n, &[d * 0.5, d, d * 1.5 + 0.1]);
        assert!(drawn > 1000, "{demo:?}: {drawn}");
        // Quantised to 0..=16 and contoured at integer levels: nodes at
        // the level in many subgrids.
        let (lo, hi) = data.iter().fold((f32::MAX, f32::MIN), |(a, b), &v| (a.min(v), b.max(v)));
        let q: Vec<f32> = data.iter().map(|&v| ((v - lo) / (hi - lo) * 16.0).round()).collect();
        assert!(both(&q, n, &[4.0, 8.0, 12.0]) > 1000, "{demo:?} quantised");
    }
}
