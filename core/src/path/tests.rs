//! The path pipeline's tests: the index, both passes, the tour.

use super::index::*;
use super::order::*;
use super::store::*;
use super::*;
use crate::command::{Command, Point3};
use crate::view::ViewTransform;

/// [`super::chain`] with no poll.
fn chain(
    src: Source<'_>,
    dst: &mut Geometry<'_>,
    scratch: &mut [u8],
    start: Packed,
    tolerance: f32,
    pass: Pass,
) -> ChainStats {
    super::chain(src, dst, scratch, start, tolerance, pass, &mut || {})
}

fn store(n: usize) -> Vec<u8> {
    vec![0; Geometry::bytes_for(n)]
}

/// Pieces on a small lattice, as the property tests draw them: shape 0
/// a dot, 1 a three-point fragment (an elbow), else a segment.
fn push_lattice(g: &mut Geometry<'_>, segs: &[(Packed, Packed, u8)]) {
    for &(a, b, shape) in segs {
        match shape {
            0 => {
                g.push_raw(a, Kind::Dot);
            }
            1 => {
                g.push_raw(a, Kind::Move);
                g.push_raw([b[0], a[1], a[2]], Kind::Line);
                g.push_raw(b, Kind::Line);
            }
            _ => {
                g.push_raw(a, Kind::Move);
                g.push_raw(b, Kind::Line);
            }
        }
    }
}

fn seg(g: &mut Geometry<'_>, a: [f32; 3], b: [f32; 3]) {
    g.push(Command::MoveTo(Point3::new(a[0], a[1], a[2]))).unwrap();
    g.push(Command::LineTo(Point3::new(b[0], b[1], b[2]))).unwrap();
}

/// 2-opt as it was before the lengths were kept: every jump measured
/// afresh, every candidate's two new jumps computed. The oracle of
/// `two_opt_keeps_lengths_without_changing_a_move`.
fn two_opt_afresh(tour: &Tour, x: &mut Index<'_, '_>, window: usize, budget: &mut u64) -> bool {
    let n = tour.len;
    let length = |a: Packed, b: Packed| tour.metric.d(a, b);
    let mut improved = false;
    for i in 0..n.saturating_sub(1) {
        if n < 3 || *budget == 0 {
            break;
        }
        let out_i = tour.ends(x, i).1;
        let in_i1 = tour.ends(x, i + 1).0;
        let before = length(out_i, in_i1);
        for j in i + 2..n.min(i + 2 + window) {
            *budget = budget.saturating_sub(1);
            let out_j = tour.ends(x, j).1;
            let after = if j + 1 < n { Some(tour.ends(x, j + 1).0) } else { None };
            let old = before + after.map_or(0.0, |a| length(out_j, a));
            let new = length(out_i, out_j) + after.map_or(0.0, |a| length(in_i1, a));
            if new + 1e-3 < old {
                tour.reverse(x, i + 1, j);
                *budget = budget.saturating_sub((j - i) as u64);
                improved = true;
                break;
            }
        }
    }
    improved
}

/// Loop entries as they were chosen before the pruning: every vertex's
/// two jumps measured. The oracle of
/// `best_entries_prunes_without_changing_an_entry`.
fn best_entries_afresh(tour: &Tour, x: &mut Index<'_, '_>, start: Packed) {
    let m = tour.metric;
    let mut prev: Option<Packed> = None;
    for k in 0..tour.len {
        let (end, _) = tour.get(&x.w, k);
        let f = x.frag_of(end);
        if x.is_loop(f) {
            let next = if k + 1 < tour.len { Some(tour.ends(x, k + 1).0) } else { None };
            let into = |v: Packed| prev.map_or_else(|| m.first_jump(start, v), |p| m.d(p, v));
            let cost = |v: Packed| into(v) + next.map_or(0.0, |n| m.d(v, n));
            let (from, to) = x.span(f);
            let mut best = (cost(x.point(end)), end);
            for i in from..to {
                let c = cost(x.point(i));
                if c < best.0 {
                    best = (c, i);
                }
            }
            tour.set(&mut x.w, k, best.1, best.1);
        }
        prev = Some(tour.ends(x, k).1);
    }
}

/// The metrics the tour tests run with: space, and the screen of a
/// view of the lattice they draw on.
fn metrics() -> [Metric; 2] {
    let view = crate::view::View { spacing: [1.0; 3], ..crate::view::View::DEFAULT };
    let bounds = crate::view::Bounds::new(Point3::new(0.0, 0.0, 0.0), Point3::new(60.0, 60.0, 6.0));
    let t = ViewTransform::fit_sphere(&view, bounds).expect("a view");
    [Metric::Space, Metric::Screen { view: t, shift: 0, park: [0.0, 0.0] }]
}

#[test]
fn dist2f_is_the_exact_square_rounded_once_at_the_extremes() {
    let far = [0u16, 65535, 37837, 37838, 46341, 46340, 1, 65534];
    for &a in &far {
        for &b in &far {
            for &c in &far {
                let (p, q) = ([a, b, c], [0, 0, 0]);
                assert_eq!(dist2f(p, q).to_bits(), (dist2(p, q) as f32).to_bits(), "{p:?}");
                assert_eq!(dist2f(q, p).to_bits(), (dist2(p, q) as f32).to_bits(), "{p:?}");
            }
        }
    }
}

proptest::proptest! {
    #[test]
    fn dist2f_is_the_exact_square_rounded_once(a in proptest::array::uniform3(proptest::num::u16::ANY), b in proptest::array::uniform3(proptest::num::u16::ANY)) {
        proptest::prop_assert_eq!(dist2f(a, b).to_bits(), (dist2(a, b) as f32).to_bits());
    }
}

proptest::proptest! {
    #[test]
    fn frag_of_finds_the_fragment_of_every_point(
        lens in proptest::collection::vec(1usize..40, 1..120),
        long in proptest::option::of((0usize..120, 100usize..900)),
    ) {
        // Fragments of uneven lengths, one of them perhaps very long,
        // some taken (drawn: the flag shares the start's word).
        let mut lens = lens;
        if let Some((at, n)) = long {
            let at = at.min(lens.len() - 1);
            lens[at] = n;
        }
        let points: usize = lens.iter().sum();
        let mut p = store(points);
        let mut src = Geometry::new(&mut p);
        src.reset(0);
        let mut starts = Vec::new();
        for (f, &n) in lens.iter().enumerate() {
            starts.push(src.len());
            for j in 0..n {
                let q = [f as u16, j as u16, 0];
                src.push_raw(q, if j == 0 { if n == 1 { Kind::Dot } else { Kind::Move } } else { Kind::Line });
            }
        }
        let mut scratch = vec![0u8; 16 * points + 4096];
        let mut x = Index::build(Source::one(&src), &mut scratch, false, true, Width::Fit, Poll::none()).expect("room");
        for f in (0..lens.len()).step_by(3) {
            x.take(f);
        }
        for i in 0..points {
            let want = starts.partition_point(|&s| s <= i) - 1;
            proptest::prop_assert_eq!(x.frag_of(i), want, "point {}", i);
        }
    }
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(300))]
    #[test]
    fn two_opt_keeps_lengths_without_changing_a_move(
        frags in proptest::collection::vec(
            (proptest::collection::vec([0u16..400, 0u16..400, 0u16..40], 1..4), proptest::bool::ANY),
            3..60,
        ),
    ) {
        // Open polylines (some closed into loops, some single dots) in
        // the order given: a poor tour, so 2-opt has moves to make.
        let mut p = store(256);
        let mut src = Geometry::new(&mut p);
        src.reset(0);
        for (pts, closed) in &frags {
            let kind = match (pts.len(), closed) {
                (1, _) => Kind::Dot,
                (_, true) => Kind::Loop,
                _ => Kind::Move,
            };
            for (n, &q) in pts.iter().enumerate() {
                src.push_raw(q, if n == 0 { kind } else { Kind::Line });
            }
        }
        for metric in metrics() {
            let mut tours = Vec::new();
            for afresh in [false, true] {
                let mut scratch = vec![0u8; 64 * 1024];
                let mut x = Index::build(Source::one(&src), &mut scratch, true, false, Width::Fit, Poll::none()).expect("room");
                let mut tour = Tour { base: x.tour_base(), len: 0, metric };
                for f in 0..x.frags {
                    let end = x.span(f).0;
                    tour.push(&mut x, f, end);
                }
                let mut budget = 8 * WINDOW as u64 * tour.len as u64;
                // Passes until one finds nothing, as the order pass runs it.
                for _ in 0..8 {
                    let moved = if afresh {
                        tour.measure_all(&mut x);
                        two_opt_afresh(&tour, &mut x, WINDOW, &mut budget)
                    } else {
                        tour.two_opt(&mut x, None, WINDOW, &mut budget)
                    };
                    if !moved || budget == 0 {
                        break;
                    }
                }
                tours.push((0..tour.len).map(|k| tour.get(&x.w, k)).collect::<Vec<_>>());
            }
            proptest::prop_assert_eq!(&tours[0], &tours[1]);
        }
    }
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(300))]
    #[test]
    fn best_entries_prunes_without_changing_an_entry(
        loops in proptest::collection::vec(
            (proptest::collection::vec([0u16..60, 0u16..60, 0u16..6], 3..14), 0usize..14),
            1..30,
        ),
        start in [0u16..60, 0u16..60, 0u16..6],
    ) {
        // Loops on a coarse lattice (ties between vertices are common),
        // each entered at some vertex, in the order given.
        let mut p = store(512);
        let mut src = Geometry::new(&mut p);
        src.reset(0);
        for (pts, _) in &loops {
            for (n, &q) in pts.iter().enumerate() {
                src.push_raw(q, if n == 0 { Kind::Loop } else { Kind::Line });
            }
        }
        for metric in metrics() {
            let mut tours = Vec::new();
            for afresh in [false, true] {
                let mut scratch = vec![0u8; 64 * 1024];
                let mut x = Index::build(Source::one(&src), &mut scratch, true, false, Width::Fit, Poll::none()).expect("room");
                let mut tour = Tour { base: x.tour_base(), len: 0, metric };
                for (f, (_, at)) in loops.iter().enumerate() {
                    let (from, to) = x.span(f);
                    tour.push(&mut x, f, from + at % (to - from));
                }
                if afresh {
                    best_entries_afresh(&tour, &mut x, start)
                } else {
                    tour.best_entries(&mut x, start)
                }
                tours.push((0..tour.len).map(|k| tour.get(&x.w, k)).collect::<Vec<_>>());
            }
            proptest::prop_assert_eq!(&tours[0], &tours[1]);
        }
    }
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(300))]
    #[test]
    fn stitching_in_hashed_buckets_u16_words_or_any_room_equals_stitching_in_cells(
        segs in proptest::collection::vec(([0u16..6, 0u16..6, 0u16..3], [0u16..6, 0u16..6, 0u16..3], 0u8..8), 1..120),
    ) {
        // Segments, dots and three-point fragments on a small lattice:
        // many ends meet, equal segments and dots on lines get culled.
        let mut p = store(512);
        let mut src = Geometry::new(&mut p);
        src.reset(0);
        push_lattice(&mut src, &segs);
        // Too little room for `u32` words and a list an end: `u16`s.
        let frags = (0..src.len()).filter(|&i| src.kind(i).is_some_and(Kind::starts)).count();
        // The starts, two links a fragment, a list for every other end.
        let tight = 2 * (frags + 2 * frags + frags);
        proptest::prop_assert!(matches!(
            Index::build(Source::one(&src), &mut vec![0u8; tight], false, true, Width::Fit, Poll::none()).map(|x| x.w),
            Some(Words::Narrow(_))
        ));
        let mut out = Vec::new();
        // (The engine keeps a recording in the slice memory's tail through
        // a commit when the head holds `stitch_reserve`: the stitch must
        // not depend on how much more it would have had.)
        // (When the memory less the recording is short of that, the
        // commit stitches in what is left, down to `stitch_least`.)
        let reserve = stitch_reserve(frags, src.len());
        let least = stitch_least(frags, src.len());
        for (hashed, bytes) in [
            (true, 16 * 1024),
            (false, 16 * 1024),
            (true, tight),
            (true, reserve),
            (true, reserve + 7),
            (true, least),
            (true, least + 3),
            // One list for all the ends: three words a fragment and one.
            (true, 2 * (3 * frags + 1)),
        ] {
            let mut p2 = store(512);
            let mut dst = Geometry::new(&mut p2);
            let mut scratch = vec![0u8; bytes];
            let st = chain_on(Source::one(&src), &mut dst, &mut scratch, [0; 3], 0.0, Pass::Stitch, hashed, Width::Fit, &mut || {});
            proptest::prop_assert!(st.ordered);
            out.push((dst.commands().collect::<Vec<_>>(), st.polylines, st.culled_dots, st.duplicate_segments));
        }
        for o in &out[1..] {
            proptest::prop_assert_eq!(&out[0], o);
        }
    }
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(300))]
    #[test]
    fn open_paths_and_loops_cut_shuffled_and_turned_stitch_whole(
        shapes in proptest::collection::vec((2usize..9, proptest::bool::ANY), 1..12),
        cuts in proptest::collection::vec(1usize..4, 64),
        order in proptest::collection::vec(proptest::num::u32::ANY, 64),
    ) {
        // Open paths along x (at y = k, z = 5) and square loops (at
        // y = k, z in 0..=1), apart from each other: each must come out
        // as one polyline, whatever the fragments' order and direction.
        let mut frags: Vec<Vec<Packed>> = Vec::new();
        let mut cut = cuts.iter().cycle();
        for (k, &(n, closed)) in shapes.iter().enumerate() {
            let y = k as u16;
            let pts: Vec<Packed> = if closed {
                vec![[0, y, 0], [1, y, 0], [1, y, 1], [0, y, 1], [0, y, 0]]
            } else {
                (0..n as u16).map(|j| [j, y, 5]).collect()
            };
            let mut at = 0;
            while at + 1 < pts.len() {
                let end = (at + cut.next().copied().unwrap_or(1)).min(pts.len() - 1);
                frags.push(pts[at..=end].to_vec());
                at = end;
            }
        }
        let mut keyed: Vec<(u32, Vec<Packed>)> =
            frags.into_iter().zip(order.iter().cycle()).map(|(f, &o)| (o, f)).collect();
        keyed.sort_by_key(|(o, _)| *o);
        let mut p = store(256);
        let mut src = Geometry::new(&mut p);
        src.reset(0);
        for (o, mut f) in keyed {
            if o % 2 == 1 {
                f.reverse();
            }
            for (j, &q) in f.iter().enumerate() {
                src.push_raw(q, if j == 0 { Kind::Move } else { Kind::Line });
            }
        }
        let mut p2 = store(256);
        let mut dst = Geometry::new(&mut p2);
        let mut scratch = vec![0u8; 16 * 1024];
        let st = chain(Source::one(&src), &mut dst, &mut scratch, [0; 3], 0.0, Pass::Stitch);
        let loops = shapes.iter().filter(|s| s.1).count() as u32;
        proptest::prop_assert_eq!((st.polylines, st.loops), (shapes.len() as u32, loops));
    }
}

/// The undirected segments (zero-length ones left out) and the dots a
/// geometry draws, sorted.
fn drawn(g: &Geometry<'_>) -> (Vec<[Packed; 2]>, Vec<Packed>) {
    let code = |p: Point3| [p.x as u16, p.y as u16, p.z as u16];
    let (mut segs, mut dots, mut pen) = (Vec::new(), Vec::new(), None);
    for c in g.commands() {
        match c {
            Command::MoveTo(p) => pen = Some(code(p)),
            Command::LineTo(p) => {
                let q = code(p);
                if let Some(a) = pen.filter(|&a| a != q) {
                    segs.push(if a < q { [a, q] } else { [q, a] });
                }
                pen = Some(q);
            }
            Command::Point(p) => {
                dots.push(code(p));
                pen = None;
            }
        }
    }
    segs.sort_unstable();
    dots.sort_unstable();
    (segs, dots)
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(300))]
    #[test]
    fn the_order_pass_draws_every_segment_and_dot_once(
        frags in proptest::collection::vec(
            (proptest::collection::vec([0u16..12, 0u16..12, 0u16..3], 1..7), 0u8..3),
            1..40,
        ),
        tight in proptest::bool::ANY,
    ) {
        // Dots, open polylines and closed loops on a small lattice, in
        // the order given: they touch, cross and repeat, so the tour
        // takes loops whose vertices other loops still list, and (with
        // a tight scratch: a coarse grid) searches crowded cells.
        let mut p = store(256);
        let mut src = Geometry::new(&mut p);
        src.reset(0);
        push_fragments(&mut src, &frags);
        let mut p2 = store(512);
        let mut dst = Geometry::new(&mut p2);
        let mut scratch = vec![0u8; if tight { 20 * src.len() + 32 } else { 64 * 1024 }];
        for metric in metrics() {
            let st = chain(Source::one(&src), &mut dst, &mut scratch, [0; 3], 0.0, Pass::Order(metric));
            proptest::prop_assert!(st.ordered);
            proptest::prop_assert_eq!(drawn(&dst), drawn(&src));
        }
    }
}

/// Push `frags` (points and a kind selector) as fragments: one point is a
/// dot, two points or selector 0 an open polyline, the rest a loop.
fn push_fragments(g: &mut Geometry<'_>, frags: &[(Vec<Packed>, u8)]) {
    for (pts, kind) in frags {
        let first = match (pts.len(), kind) {
            (1, _) => Kind::Dot,
            (2, _) | (_, 0) => Kind::Move,
            _ => Kind::Loop,
        };
        for (n, &q) in pts.iter().enumerate() {
            g.push_raw(q, if n == 0 { first } else { Kind::Line });
        }
    }
}

/// The tour's length by its metric: from the start, each jump.
fn tour_length(tour: &Tour, x: &Index<'_, '_>, start: Packed) -> f32 {
    let m = tour.metric;
    let mut at: Option<Packed> = None;
    let mut sum = 0.0;
    for k in 0..tour.len {
        let (e, o) = tour.ends(x, k);
        sum += at.map_or_else(|| m.first_jump(start, e), |a| m.d(a, e));
        at = Some(o);
    }
    sum
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(200))]
    #[test]
    fn the_tours_moves_only_shorten_it_and_keep_every_step(
        frags in proptest::collection::vec(
            (proptest::collection::vec([0u16..60, 0u16..60, 0u16..6], 1..5), 0u8..3),
            8..60,
        ),
        start in [0u16..60, 0u16..60, 0u16..6],
    ) {
        // Dots, open polylines and loops scattered on a lattice, toured
        // in the order given: the neighbours' moves (and, in space, the
        // windowed ones) only shorten it, and every fragment stays once.
        let mut p = store(512);
        let mut src = Geometry::new(&mut p);
        src.reset(0);
        push_fragments(&mut src, &frags);
        for metric in metrics() {
            let mut scratch = vec![0u8; 64 * 1024];
            let mut x = Index::build(Source::one(&src), &mut scratch, true, false, Width::Fit, Poll::none()).expect("room");
            x.relink(false);
            let mut tour = Tour { base: x.tour_base(), len: 0, metric };
            for f in 0..x.frags {
                let end = x.span(f).0;
                tour.push(&mut x, f, end);
            }
            tour.measure_all(&mut x);
            if matches!(metric, Metric::Screen { .. }) {
                proptest::prop_assert!(Near::build(&mut x, &tour).is_some(), "no neighbours");
            }
            // Each kind of move alone only shortens the tour, from the tour
            // as given and from a good one.
            for round in 0..2 {
                if let Some(near) = Near::build(&mut x, &tour) {
                    let mut budget = SEARCH_BUDGET;
                    let l0 = tour_length(&tour, &x, start);
                    tour.or_opt(&mut x, Some(&near), 0, &mut budget);
                    let l1 = tour_length(&tour, &x, start);
                    proptest::prop_assert!(l1 <= l0 * 1.000_01 + 1e-3, "or-opt: {l1} > {l0}");
                    tour.two_opt(&mut x, Some(&near), 0, &mut budget);
                    let l2 = tour_length(&tour, &x, start);
                    proptest::prop_assert!(l2 <= l1 * 1.000_01 + 1e-3, "2-opt: {l2} > {l1}");
                }
                if round == 0 {
                    tour.improve(&mut x, start);
                }
            }
            let mut seen: Vec<usize> = (0..tour.len).map(|k| x.frag_of(tour.get(&x.w, k).0)).collect();
            seen.sort_unstable();
            proptest::prop_assert_eq!(seen, (0..x.frags).collect::<Vec<_>>());
        }
    }
}

#[test]
fn loops_that_cross_are_drawn_in_one_polyline() {
    // Square A in z = 0 and square B in x = 2 share two vertices (as
    // the slices of a chicken-wire surface do); C stands apart.
    let a = [[0, 0, 0], [2, 0, 0], [4, 0, 0], [4, 4, 0], [2, 4, 0], [0, 4, 0]];
    let b = [[2, 0, 0], [2, 0, 4], [2, 4, 4], [2, 4, 0]];
    let c = [[9, 9, 9], [11, 9, 9], [11, 11, 9]];
    let mut p = store(64);
    let mut src = Geometry::new(&mut p);
    src.reset(0);
    for l in [&a[..], &b[..], &c[..]] {
        for (n, &q) in l.iter().enumerate() {
            src.push_raw(q, if n == 0 { Kind::Loop } else { Kind::Line });
        }
    }
    for metric in metrics() {
        let mut p2 = store(64);
        let mut dst = Geometry::new(&mut p2);
        let mut scratch = vec![0u8; 4096];
        let st = chain(Source::one(&src), &mut dst, &mut scratch, [0; 3], 0.0, Pass::Order(metric));
        assert_eq!(drawn(&dst), drawn(&src));
        assert_eq!((st.polylines, st.spliced), (2, 1), "{st:?}");
        // One jump: from A and B to C (and none from the start, which
        // chain() does not count).
        assert!(st.travel > 0.0);
    }
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(300))]
    #[test]
    fn pieces_in_two_stores_chain_as_in_one(
        segs in proptest::collection::vec(([0u16..6, 0u16..6, 0u16..3], [0u16..6, 0u16..6, 0u16..3], 0u8..8), 1..120),
        cut in 0usize..400,
    ) {
        let mut p = store(512);
        let mut one = Geometry::new(&mut p);
        one.reset(3);
        push_lattice(&mut one, &segs);
        // The same points, the first `cut` in one store and the rest in
        // another (a polyline may straddle them).
        let cut = cut.min(one.len());
        let (mut p1, mut p2) = (store(512), store(512));
        let (mut head, mut tail) = (Geometry::new(&mut p1), Geometry::new(&mut p2));
        head.reset(3);
        tail.reset(3);
        for i in 0..one.len() {
            let (q, k) = one.get(i).unwrap();
            if i < cut { head.push_raw(q, k) } else { tail.push_raw(q, k) };
        }
        for pass in [Pass::Stitch, Pass::Order(Metric::Space)] {
            let mut out = Vec::new();
            for src in [Source::one(&one), Source::two(&head, &tail)] {
                let mut q = store(512);
                let mut dst = Geometry::new(&mut q);
                let mut scratch = vec![0u8; 16 * 1024];
                let st = chain(src, &mut dst, &mut scratch, [0; 3], 0.0, pass);
                out.push((dst.commands().collect::<Vec<_>>(), st));
            }
            proptest::prop_assert_eq!(&out[0], &out[1]);
        }
    }
}

#[test]
fn a_square_of_four_fragments_in_any_order_becomes_one_closed_loop() {
    let mut p = store(16);
    let mut src = Geometry::new(&mut p);
    src.reset(8);
    // Shuffled and with two fragments backwards.
    seg(&mut src, [1.0, 0.0, 0.0], [1.0, 1.0, 0.0]);
    seg(&mut src, [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]);
    seg(&mut src, [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]);
    seg(&mut src, [0.0, 0.0, 0.0], [1.0, 0.0, 0.0]);
    let mut p2 = store(16);
    let mut dst = Geometry::new(&mut p2);
    let mut scratch = [0u8; 256];
    let st = chain(Source::one(&src), &mut dst, &mut scratch, [0; 3], 0.0, Pass::Order(Metric::Space));
    assert!(st.ordered);
    assert_eq!((st.fragments, st.polylines, st.loops, st.points_out), (4, 1, 1, 4));
    assert_eq!(st.travel, 0.0);
    let cmds: Vec<_> = dst.commands().collect();
    assert_eq!(cmds.len(), 5);
    assert_eq!(cmds[0], Command::MoveTo(Point3::new(0.0, 0.0, 0.0)));
    assert_eq!(cmds[4], Command::LineTo(Point3::new(0.0, 0.0, 0.0)));
}

#[test]
fn a_crossing_is_stitched_straight_through_in_any_order() {
    // Four arms from (2, 2, 0); every order and every direction of the
    // pieces must come out as the two straight lines through it.
    let arms = [[0.0, 2.0, 0.0], [4.0, 2.0, 0.0], [2.0, 0.0, 0.0], [2.0, 4.0, 0.0]];
    let c = [2.0, 2.0, 0.0];
    let mut orders: Vec<Vec<usize>> = vec![vec![]];
    for _ in 0..4 {
        let mut next = Vec::new();
        for o in &orders {
            for a in (0..4).filter(|a| !o.contains(a)) {
                next.push([o.clone(), vec![a]].concat());
            }
        }
        orders = next;
    }
    assert_eq!(orders.len(), 24);
    for order in &orders {
        for flips in 0..16 {
            let mut p = store(16);
            let mut src = Geometry::new(&mut p);
            src.reset(8);
            for (k, &a) in order.iter().enumerate() {
                if flips >> k & 1 == 0 { seg(&mut src, arms[a], c) } else { seg(&mut src, c, arms[a]) }
            }
            let mut p2 = store(16);
            let mut dst = Geometry::new(&mut p2);
            let mut scratch = [0u8; 512];
            let st = chain(Source::one(&src), &mut dst, &mut scratch, [0; 3], 0.0, Pass::Stitch);
            assert_eq!((st.polylines, st.points_out), (2, 6), "{order:?} {flips}");
            let cmds: Vec<_> = dst.commands().collect();
            for line in cmds.chunks(3) {
                let [Command::MoveTo(a), Command::LineTo(m), Command::LineTo(b)] = line else {
                    panic!("{order:?} {flips}: {cmds:?}")
                };
                assert_eq!(*m, Point3::new(2.0, 2.0, 0.0), "{order:?} {flips}");
                assert!(
                    a.x + b.x == 4.0 && a.y + b.y == 4.0,
                    "bent at the crossing: {order:?} {flips}: {cmds:?}"
                );
            }
        }
    }
}

#[test]
fn collinear_points_merge_within_tolerance_only() {
    let mut p = store(16);
    let mut src = Geometry::new(&mut p);
    src.reset(8);
    seg(&mut src, [0.0, 0.0, 0.0], [1.0, 0.001, 0.0]);
    seg(&mut src, [1.0, 0.001, 0.0], [2.0, 0.0, 0.0]);
    seg(&mut src, [2.0, 0.0, 0.0], [2.0, 1.0, 0.0]);
    let mut p2 = store(16);
    let mut dst = Geometry::new(&mut p2);
    let mut scratch = [0u8; 256];
    let st = chain(Source::one(&src), &mut dst, &mut scratch, [0; 3], 0.01, Pass::Order(Metric::Space));
    assert_eq!((st.polylines, st.merged, st.points_out), (1, 1, 3));
    let st = chain(Source::one(&src), &mut dst, &mut scratch, [0; 3], 0.0, Pass::Order(Metric::Space));
    assert_eq!((st.merged, st.points_out), (0, 4));
}

/// An empty surface is in order: there is nothing to stitch or order, so
/// no note of "no room to order it" may follow from it.
#[test]
fn an_empty_surface_is_in_order() {
    let mut p = store(16);
    let mut src = Geometry::new(&mut p);
    src.reset(8);
    let mut p2 = store(16);
    let mut dst = Geometry::new(&mut p2);
    for pass in [Pass::Stitch, Pass::Order(Metric::Space)] {
        let st = chain(Source::one(&src), &mut dst, &mut [0u8; 64], [0; 3], 0.0, pass);
        assert!(st.ordered, "{pass:?}: {st:?}");
        assert_eq!((st.points_out, dst.len()), (0, 0));
    }
}

#[test]
fn too_little_scratch_copies_in_order() {
    let mut p = store(16);
    let mut src = Geometry::new(&mut p);
    src.reset(8);
    seg(&mut src, [5.0, 0.0, 0.0], [6.0, 0.0, 0.0]);
    seg(&mut src, [0.0, 0.0, 0.0], [1.0, 0.0, 0.0]);
    let mut p2 = store(16);
    let mut dst = Geometry::new(&mut p2);
    let st = chain(Source::one(&src), &mut dst, &mut [0u8; 8], [0; 3], 0.0, Pass::Order(Metric::Space));
    assert!(!st.ordered);
    let a: Vec<_> = src.commands().collect();
    let b: Vec<_> = dst.commands().collect();
    assert_eq!(a, b);
}

/// Words of the order pass's index besides its grid and its buckets, at
/// `width`: the starts, a link a point, the tour, the drawn bits.
fn order_overhead(frags: usize, points: usize, width: Width) -> usize {
    let (step, bits) = if width == Width::Narrow { (4, 16) } else { (3, 32) };
    frags + points + step * frags + points.div_ceil(bits)
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(300))]
    #[test]
    fn the_order_pass_orders_alike_in_u16_and_u32_words(
        frags in proptest::collection::vec(
            (proptest::collection::vec([0u16..40, 0u16..40, 0u16..6], 1..7), 0u8..3),
            1..40,
        ),
        start in [0u16..40, 0u16..40, 0u16..6],
        spare in 1usize..600,
    ) {
        // Dots, open polylines and loops that touch and cross (splices,
        // and ties the tour breaks by the order of its lists), ordered in
        // plenty of room, and in as many words for the grid and the
        // buckets either way (a tight scratch: a coarse grid, buckets in
        // the grid's heads). The same picture, stats and all.
        let mut p = store(256);
        let mut src = Geometry::new(&mut p);
        src.reset(0);
        push_fragments(&mut src, &frags);
        let (f, n) = ((0..src.len()).filter(|&i| src.kind(i).is_some_and(Kind::starts)).count(), src.len());
        let room = |width: Width, spare: usize| {
            let word = if width == Width::Narrow { 2 } else { 4 };
            word * (order_overhead(f, n, width) + spare)
        };
        for metric in metrics() {
            for spare in [4 * n, spare] {
                let mut out = Vec::new();
                for width in [Width::Wide, Width::Narrow] {
                    let mut p2 = store(512);
                    let mut dst = Geometry::new(&mut p2);
                    let mut scratch = vec![0u8; room(width, spare)];
                    let pass = Pass::Order(metric);
                    let st = chain_on(Source::one(&src), &mut dst, &mut scratch, start, 0.0, pass, false, width, &mut || {});
                    proptest::prop_assert!(st.ordered);
                    out.push((dst.commands().collect::<Vec<_>>(), st));
                }
                proptest::prop_assert_eq!(&out[0], &out[1]);
            }
        }
    }
}

#[test]
fn the_order_pass_takes_u16_words_only_where_u32_words_leave_no_cell() {
    // 200 points in 40 loops: u32 words want 4 x (4 x 40 + 200 + 7 + 1)
    // bytes for a grid of one cell; below that, u16 words. (Above it the
    // u32 index orders as it always did: the picture depends on the grid.)
    let mut p = store(256);
    let mut src = Geometry::new(&mut p);
    src.reset(0);
    for l in 0..40u16 {
        for (k, q) in [[0, 0], [1, 0], [1, 1], [0, 1], [0, 2]].into_iter().enumerate() {
            src.push_raw([q[0] + 3 * l, q[1], l % 5], if k == 0 { Kind::Loop } else { Kind::Line });
        }
    }
    let wide_least = 4 * (order_overhead(40, 200, Width::Wide) + 1);
    assert_eq!(wide_least, 4 * (4 * 40 + 200 + 7 + 1));
    for (bytes, narrow) in [(wide_least, false), (wide_least - 4, true), (order_reserve(40, 200), true)] {
        let mut scratch = vec![0u8; bytes];
        let x = Index::build(Source::one(&src), &mut scratch, true, false, Width::Fit, Poll::none())
            .expect("room");
        assert_eq!(matches!(x.w, Words::Narrow(_)), narrow, "{bytes} bytes");
    }
    // The reserve: u16 words, a cell for every four points.
    assert_eq!(order_reserve(40, 200), 2 * (order_overhead(40, 200, Width::Narrow) + 50 + 1));
    // Too many points for u16 words: u32, and a narrow index refused.
    assert_eq!(order_reserve(10, NARROW_LIMIT), 4 * (40 + NARROW_LIMIT + 1024 + NARROW_LIMIT / 4 + 1));
}

#[test]
fn drawn_bits_and_jumps_keep_their_bits_in_u16_words() {
    // The drawn bits past a word's 16 and the jumps' two halves.
    let mut bytes = [0u8; 64];
    let mut w = Words::narrow(&mut bytes);
    w.clear_bits(2, 60);
    w.set_bits(2, 13, 37);
    w.set_bits(2, 59, 60);
    let set: Vec<usize> = (0..64).filter(|&b| w.bit(2, b)).collect();
    assert_eq!(set, (13..37).chain([59]).collect::<Vec<_>>());
    assert_eq!(w.get(3), NONE, "all 16 bits of word 3, read as an index");
    for v in [0.0f32, -1.5e-7, 3.25e9, f32::MAX] {
        w.set32(20, v.to_bits());
        assert_eq!(f32::from_bits(w.get32(20)), v);
    }
    // The last word's half past the end is dropped, not a panic.
    w.set32(31, u32::MAX);
    assert_eq!(w.get32(31), 0xFFFF);
}
