//! The chicken-wire surface closes: a crossing strictly inside a volume edge
//! is drawn, bit for bit, by both slices that contain that edge.
//!
//! An edge along x (y and z integers) lies in the x-y slice through its z and
//! the x-z slice through its y; an edge along y in an x-y and a y-z slice; an
//! edge along z in an x-z and a y-z slice.

use isoscope_core::contour::grid::Plane;
use isoscope_core::demo::Demo;
use isoscope_sim::contour::Contoured;
use isoscope_tests::contour_demo;
use std::collections::HashSet;

type Bits = (usize, [u32; 3]);

/// The points of `plane` (with their level index) as f32 bit triples.
fn points(c: &Contoured, plane: Plane) -> HashSet<Bits> {
    c.slices
        .iter()
        .filter(|(s, _)| s.plane == plane)
        .flat_map(|(_, cmds)| cmds.iter())
        .map(|(level, cmd)| {
            let p = cmd.point();
            (*level as usize, [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()])
        })
        .collect()
}

fn is_int(bits: u32) -> bool {
    let v = f32::from_bits(bits);
    v.fract() == 0.0
}

/// The points strictly inside an edge along `axis` (0 = x, 1 = y, 2 = z):
/// that coordinate fractional, the other two integers.
fn on_edges_along(set: &HashSet<Bits>, axis: usize) -> HashSet<Bits> {
    set.iter().filter(|(_, p)| (0..3).all(|k| is_int(p[k]) != (k == axis))).copied().collect()
}

fn show(b: &Bits) -> String {
    let [x, y, z] = b.1.map(f32::from_bits);
    format!("level #{} ({x}, {y}, {z})", b.0)
}

fn check(name: &str, demo: Demo, n: usize, levels: &[f32]) {
    let c = contour_demo(demo, n, levels, &Plane::ALL, 2);
    let [xy, xz, yz] = Plane::ALL.map(|p| points(&c, p));
    let pairs = [
        (0, "x", (&xy, "x-y"), (&xz, "x-z")),
        (1, "y", (&xy, "x-y"), (&yz, "y-z")),
        (2, "z", (&xz, "x-z"), (&yz, "y-z")),
    ];
    for (axis, axis_name, (a, a_name), (b, b_name)) in pairs {
        let (ea, eb) = (on_edges_along(a, axis), on_edges_along(b, axis));
        assert!(ea.len() > 20, "{name}: only {} {a_name} points on edges along {axis_name}", ea.len());
        for (from, from_name, to, to_name) in [(&ea, a_name, &eb, b_name), (&eb, b_name, &ea, a_name)] {
            let mut missing: Vec<&Bits> = from.difference(to).collect();
            missing.sort();
            assert!(
                missing.is_empty(),
                "{name}: {} of {} {from_name} points on edges along {axis_name} are not drawn by the \
                 {to_name} slices, e.g. {}",
                missing.len(),
                from.len(),
                missing.iter().take(3).map(|b| show(b)).collect::<Vec<_>>().join(", ")
            );
        }
    }
}

#[test]
fn gyroid_slices_meet_on_shared_edges() {
    check("gyroid:24", Demo::Gyroid, 24, &[0.0, 0.7]);
}

#[test]
fn hydrogen_slices_meet_on_shared_edges() {
    check("hydrogen:24", Demo::Hydrogen, 24, &[0.1, 0.4]);
}

#[test]
fn edge_classification() {
    let set: HashSet<Bits> =
        [[0.5f32, 1.0, 2.0], [1.0, 0.25, 3.0], [1.0, 2.0, 0.75], [1.0, 2.0, 3.0], [0.5, 0.5, 1.0]]
            .iter()
            .map(|p| (0, p.map(f32::to_bits)))
            .collect();
    for axis in 0..3 {
        let e = on_edges_along(&set, axis);
        assert_eq!(e.len(), 1, "axis {axis}: {e:?}");
        assert!(!is_int(e.iter().next().unwrap().1[axis]));
    }
}
