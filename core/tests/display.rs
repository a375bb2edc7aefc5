//! Display list: culling, stitching, merging and ordering keep the picture.

use isoscope_core::command::Command;
use isoscope_core::display::{DisplayList, OptimizeConfig, OrderConfig, Scratch};
use isoscope_core::screen::ScreenPoint;
use proptest::prelude::*;
use std::collections::BTreeSet;

type Seg = ((u32, u32), (u32, u32));

fn k(p: ScreenPoint) -> (u32, u32) {
    ((p.x + 0.0).to_bits(), (p.y + 0.0).to_bits())
}

/// Lit segments (undirected, zero-length ones dropped) and dots not on a line.
fn picture<const N: usize>(l: &DisplayList<N>) -> (BTreeSet<Seg>, BTreeSet<(u32, u32)>) {
    let mut segs = BTreeSet::new();
    let mut dots = BTreeSet::new();
    let mut at: Option<ScreenPoint> = None;
    for c in l.commands() {
        match c {
            Command::MoveTo(p) => at = Some(p),
            Command::LineTo(p) => {
                if let Some(a) = at
                    && k(a) != k(p)
                {
                    let (x, y) = (k(a), k(p));
                    segs.insert(if x < y { (x, y) } else { (y, x) });
                }
                at = Some(p);
            }
            Command::Point(p) => {
                dots.insert(k(p));
            }
        }
    }
    let ends: BTreeSet<_> = segs.iter().flat_map(|&(a, b)| [a, b]).collect();
    dots.retain(|d| !ends.contains(d));
    (segs, dots)
}

fn p(x: f32, y: f32) -> ScreenPoint {
    ScreenPoint::new(x, y)
}

#[test]
fn push_hands_the_command_back_when_full() {
    let mut l = DisplayList::<3>::new();
    assert_eq!(l.push(Command::MoveTo(p(0.0, 0.0))), Ok(()));
    assert_eq!(l.push(Command::LineTo(p(1.0, 0.0))), Ok(()));
    assert_eq!(l.push(Command::Point(p(5.0, 5.0))), Ok(()));
    assert_eq!(l.push(Command::LineTo(p(2.0, 0.0))), Err(Command::LineTo(p(2.0, 0.0))));
    assert_eq!((l.len(), l.dropped()), (3, 1));
    assert_eq!(l.push(Command::MoveTo(p(f32::NAN, 0.0))), Ok(()));
    assert_eq!(l.skipped(), 1);
    assert_eq!(l.polyline_count(), 2);
}

#[test]
fn fragments_of_a_square_stitch_into_one_closed_loop() {
    let mut l = DisplayList::<16>::new();
    let sq = [p(0.0, 0.0), p(10.0, 0.0), p(10.0, 10.0), p(0.0, 10.0)];
    // Four fragments, two of them backwards, one edge twice.
    for (a, b) in [(0, 1), (2, 1), (2, 3), (0, 3), (1, 0)] {
        l.push(Command::MoveTo(sq[a])).unwrap();
        l.push(Command::LineTo(sq[b])).unwrap();
    }
    let before = picture(&l);
    let mut s = Scratch::<16>::new();
    let st = l.optimize(&mut s, &OptimizeConfig::default());
    assert_eq!((st.fragments, st.polylines, st.duplicate_segments), (5, 1, 1));
    let lines: Vec<_> = l.polylines().collect();
    assert_eq!(lines.len(), 1);
    assert!(lines[0].closed);
    assert_eq!(lines[0].points.len(), 4);
    assert_eq!(picture(&l), before);
    assert_eq!(l.lit_length(), 40.0);
}

#[test]
fn collinear_runs_merge_within_tolerance() {
    let mut l = DisplayList::<16>::new();
    l.push(Command::MoveTo(p(0.0, 0.0))).unwrap();
    for i in 1..=10 {
        // A straight line with a 0.2 LSB wiggle.
        l.push(Command::LineTo(p(i as f32 * 10.0, if i % 2 == 0 { 0.2 } else { 0.0 }))).unwrap();
    }
    l.push(Command::LineTo(p(100.0, 50.0))).unwrap();
    let mut s = Scratch::<16>::new();
    let st = l.optimize(&mut s, &OptimizeConfig { tolerance: 0.5 });
    let pts: Vec<_> = l.polylines().next().unwrap().points.to_vec();
    assert_eq!(pts.len(), 3, "{pts:?}");
    assert_eq!(st.merged_points, 9);
}

#[test]
fn dots_on_lines_and_repeated_dots_are_culled() {
    let mut l = DisplayList::<16>::new();
    l.push(Command::MoveTo(p(0.0, 0.0))).unwrap();
    l.push(Command::LineTo(p(5.0, 0.0))).unwrap();
    l.push(Command::Point(p(5.0, 0.0))).unwrap();
    l.push(Command::Point(p(7.0, 7.0))).unwrap();
    l.push(Command::Point(p(7.0, 7.0))).unwrap();
    let mut s = Scratch::<16>::new();
    let st = l.optimize(&mut s, &OptimizeConfig::default());
    assert_eq!(st.culled_dots, 2);
    let cmds: Vec<_> = l.commands().collect();
    assert_eq!(
        cmds,
        [Command::MoveTo(p(0.0, 0.0)), Command::LineTo(p(5.0, 0.0)), Command::Point(p(7.0, 7.0))]
    );
}

#[test]
fn ordering_reverses_and_rotates_to_shorten_travel() {
    let mut l = DisplayList::<32>::new();
    // Far segment first, near one second, a loop in between.
    l.push(Command::MoveTo(p(100.0, 0.0))).unwrap();
    l.push(Command::LineTo(p(90.0, 0.0))).unwrap();
    l.push(Command::MoveTo(p(1.0, 0.0))).unwrap();
    l.push(Command::LineTo(p(10.0, 0.0))).unwrap();
    for q in [p(50.0, 0.0), p(60.0, 0.0), p(60.0, 10.0), p(50.0, 10.0), p(50.0, 0.0)] {
        if q == p(50.0, 0.0) && l.len() == 4 {
            l.push(Command::MoveTo(q)).unwrap();
        } else {
            l.push(Command::LineTo(q)).unwrap();
        }
    }
    let before = picture(&l);
    let mut s = Scratch::<32>::new();
    l.optimize(&mut s, &OptimizeConfig::default());
    let st = l.order(&mut s, &OrderConfig::default());
    assert!(st.blank_after <= st.blank_nearest + 1e-3);
    assert!(st.blank_after < st.blank_before);
    assert_eq!(picture(&l), before);
    let firsts: Vec<_> = l.polylines().map(|pl| pl.points[0]).collect();
    assert_eq!(firsts[0], p(1.0, 0.0));
    assert_eq!(firsts[1], p(50.0, 0.0));
    assert_eq!(firsts[2], p(90.0, 0.0));
    // Blank travel: 1 to the first segment, 40 to the loop, 40 to the last.
    assert!((l.blank_length(p(0.0, 0.0)) - 81.0).abs() < 1e-3);
}

#[test]
fn ordering_closes_the_refresh_loop() {
    // A 4x4 grid of dots 10 apart: the shortest refresh loop visits them
    // in a ring of 16 steps of 10, whatever the park position.
    let mut l = DisplayList::<16>::new();
    for k in 0..16u8 {
        // Scrambled: 7k mod 16 visits every cell once.
        let c = (7 * k) % 16;
        l.push(Command::Point(p(1000.0 + 10.0 * f32::from(c % 4), 500.0 + 10.0 * f32::from(c / 4)))).unwrap();
    }
    let mut s = Scratch::<16>::new();
    let st = l.order(&mut s, &OrderConfig::default());
    assert!((l.cycle_blank_length() - 160.0).abs() < 1e-3, "{}", l.cycle_blank_length());
    assert!((st.cycle_after - l.cycle_blank_length()).abs() < 1e-3);
    assert!(st.cycle_after < st.cycle_before);
    // The loop starts at the dot nearest the park position.
    assert_eq!(l.polylines().next().unwrap().points[0], p(1000.0, 500.0));
    assert!((st.blank_after - (p(0.0, 0.0).distance(p(1000.0, 500.0)) + 150.0)).abs() < 1e-2);
}

#[test]
fn ordering_enters_loops_where_it_suits_both_neighbours() {
    // Two squares side by side and a segment above: each square must be
    // entered at a corner near its neighbours, not where it was stored.
    let mut l = DisplayList::<32>::new();
    let square = |l: &mut DisplayList<32>, x: f32, y: f32| {
        l.push(Command::MoveTo(p(x + 10.0, y + 10.0))).unwrap();
        for q in [p(x, y + 10.0), p(x, y), p(x + 10.0, y), p(x + 10.0, y + 10.0)] {
            l.push(Command::LineTo(q)).unwrap();
        }
    };
    square(&mut l, 100.0, 100.0);
    square(&mut l, 130.0, 100.0);
    l.push(Command::MoveTo(p(110.0, 130.0))).unwrap();
    l.push(Command::LineTo(p(130.0, 130.0))).unwrap();
    let before = picture(&l);
    let mut s = Scratch::<32>::new();
    l.optimize(&mut s, &OptimizeConfig::default());
    assert_eq!(l.polylines().filter(|pl| pl.closed).count(), 2);
    let st = l.order(&mut s, &OrderConfig::default());
    assert_eq!(picture(&l), before);
    // The loop: segment end (130,130) -> corner (130,110) 20, corner
    // (110,110) of the other square 20, back to the segment (110,130) 20.
    assert!((st.cycle_after - 60.0).abs() < 1e-3, "{st:?}");
    assert!((l.cycle_blank_length() - 60.0).abs() < 1e-3);
}

fn arb_commands() -> impl Strategy<Value = Vec<Command<ScreenPoint>>> {
    // Points on a coarse lattice so fragments share endpoints often.
    let pt = (0u8..8, 0u8..8).prop_map(|(x, y)| p(f32::from(x) * 8.0, f32::from(y) * 8.0));
    prop::collection::vec(
        prop_oneof![
            4 => pt.clone().prop_map(Command::MoveTo),
            6 => pt.clone().prop_map(Command::LineTo),
            1 => pt.prop_map(Command::Point),
        ],
        0..120,
    )
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, failure_persistence: None, .. ProptestConfig::default() })]

    #[test]
    fn stitching_and_ordering_keep_every_lit_segment(cmds in arb_commands()) {
        let mut l = DisplayList::<128>::new();
        for c in &cmds {
            let _ = l.push(*c);
        }
        let before = picture(&l);
        let lit_before: f32 = before.0.iter().map(|&((ax, ay), (bx, by))| {
            p(f32::from_bits(ax), f32::from_bits(ay)).distance(p(f32::from_bits(bx), f32::from_bits(by)))
        }).sum();
        let mut s = Scratch::<128>::new();
        let st = l.optimize(&mut s, &OptimizeConfig { tolerance: 0.0 });
        prop_assert_eq!(&picture(&l), &before);
        // Each polyline draws at least one segment or is a dot. (Fewer
        // polylines than fragments is typical but not guaranteed: the walk
        // takes the straightest way through junctions rather than a
        // minimum path cover.)
        prop_assert!(st.polylines <= before.0.len() + before.1.len());
        prop_assert!((l.lit_length() - lit_before).abs() <= 1e-3 * lit_before.max(1.0));
        let o = l.order(&mut s, &OrderConfig::default());
        prop_assert_eq!(&picture(&l), &before);
        prop_assert!(o.blank_after <= o.blank_nearest + 1e-2);
        prop_assert!((l.blank_length(OrderConfig::default().start) - o.blank_after).abs() < 1e-2);
    }

    #[test]
    fn ordering_never_loses_to_nearest_neighbour(
        cmds in arb_commands(),
        start in (-20i16..80, -20i16..80),
        window in 0usize..4,
        passes in 0usize..4,
        kicks in 0usize..60,
        min_kicks in 0usize..200,
        optimize in any::<bool>(),
    ) {
        let mut l = DisplayList::<128>::new();
        for c in &cmds {
            let _ = l.push(*c);
        }
        let mut s = Scratch::<128>::new();
        if optimize {
            l.optimize(&mut s, &OptimizeConfig { tolerance: 0.0 });
        }
        let before = picture(&l);
        let (count, lit) = (l.polyline_count(), l.lit_length());
        let start = p(f32::from(start.0), f32::from(start.1));
        let cfg = OrderConfig { start, window, passes, kicks, min_kicks };
        let o = l.order(&mut s, &cfg);
        // The same picture, polyline for polyline.
        prop_assert_eq!(&picture(&l), &before);
        prop_assert_eq!(l.polyline_count(), count);
        prop_assert!((l.lit_length() - lit).abs() <= 1e-3 * lit.max(1.0));
        // Never worse than nearest neighbour, as a path from the start or
        // as a refresh loop; the figures are those of the list.
        prop_assert!(o.blank_after <= o.blank_nearest + 1e-2, "{:?}", o);
        prop_assert!(o.cycle_after <= o.cycle_nearest + 1e-2, "{:?}", o);
        prop_assert!((l.blank_length(start) - o.blank_after).abs() < 1e-2);
        prop_assert!((l.cycle_blank_length() - o.cycle_after).abs() < 1e-2);
    }

    #[test]
    fn merging_keeps_every_vertex_within_tolerance(cmds in arb_commands(), tol in 0.0f32..3.0) {
        let mut l = DisplayList::<128>::new();
        for c in &cmds {
            let _ = l.push(*c);
        }
        let (segs, _) = picture(&l);
        let mut s = Scratch::<128>::new();
        l.optimize(&mut s, &OptimizeConfig { tolerance: tol });
        // Every original segment end lies within `tol` of the new picture.
        let news: Vec<(ScreenPoint, ScreenPoint)> = picture(&l).0.iter().map(|&((ax, ay), (bx, by))| {
            (p(f32::from_bits(ax), f32::from_bits(ay)), p(f32::from_bits(bx), f32::from_bits(by)))
        }).collect();
        for &(a, b) in &segs {
            for q in [a, b] {
                let q = p(f32::from_bits(q.0), f32::from_bits(q.1));
                let near = news.iter().any(|&(u, v)| {
                    let (vx, vy) = (v.x - u.x, v.y - u.y);
                    let l2 = vx * vx + vy * vy;
                    let t = if l2 > 0.0 { (((q.x - u.x) * vx + (q.y - u.y) * vy) / l2).clamp(0.0, 1.0) } else { 0.0 };
                    q.distance(p(u.x + t * vx, u.y + t * vy)) <= tol + 1e-3
                });
                prop_assert!(near, "{q:?} is farther than {tol} from the merged picture");
            }
        }
    }
}
