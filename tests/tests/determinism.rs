//! The host library's parallel contouring gives the same slices for any
//! thread count.

use isoscope_core::contour::grid::Plane;
use isoscope_core::demo::Demo;
use isoscope_tests::contour_demo;

fn check(demo: Demo, n: usize, levels: &[f32], planes: &[Plane]) {
    let one = contour_demo(demo, n, levels, planes, 1);
    let commands: usize = one.slices.iter().map(|(_, c)| c.len()).sum();
    assert!(commands > 100, "{demo:?}:{n}: only {commands} commands");
    assert_eq!(one.stats.commands, commands as u64);
    let slices: usize = planes.iter().map(|_| n).sum();
    assert_eq!(one.slices.len(), slices);
    for threads in [2, 4] {
        let many = contour_demo(demo, n, levels, planes, threads);
        assert!(many.slices == one.slices, "{demo:?}:{n}: {threads} threads differ from 1");
        assert_eq!(many.stats, one.stats, "{demo:?}:{n}: {threads} threads");
    }
}

#[test]
fn gyroid_any_thread_count() {
    check(Demo::Gyroid, 20, &[-0.3, 0.0, 0.4], &Plane::ALL);
}

#[test]
fn hydrogen_any_thread_count() {
    check(Demo::Hydrogen, 20, &[0.1], &Plane::ALL);
}

#[test]
fn single_plane_any_thread_count() {
    for plane in Plane::ALL {
        check(Demo::Gyroid, 13, &[0.2], &[plane]);
    }
}
