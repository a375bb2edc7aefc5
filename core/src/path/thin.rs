//! Thinning a surface the memory cannot hold: a coarser slice stride, not
//! a part of the surface.
//!
//! A volume asks for every `n`-th slice of each plane ([`Stride`]). When
//! its pieces outgrow the memory (the stream's stores while contouring,
//! or the picture when stitched), every other of those slices goes
//! ([`thin`]) and contouring goes on at twice the stride: what is kept is
//! whole slices across the whole volume, so the board still draws the
//! whole object, coarser, and the picture is exactly the surface
//! contoured at the stride it ends at.
//!
//! The strides are counted from the middle slice of each axis (rounded
//! down to a slice asked for), both ways: at the stride asked for, that
//! is the slices `0, n, 2n, ...` the wire format names; at the coarsest,
//! it is the middle slice of each plane, not a border slice, which on real
//! data (a head in air) is often empty.

use super::store::{Geometry, Kind, Packed};

/// Which slices of each plane are contoured: those `every` apart, from
/// `anchor` (per axis: x for the y-z slices, y for the x-z, z for the
/// x-y) both ways.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Stride {
    /// Slices apart (at least 1).
    pub every: u16,
    /// A slice kept along each axis.
    pub anchor: [u16; 3],
    /// The most slices apart worth thinning to: one less than the longest
    /// extent (past it, one slice of each plane is left anyway).
    most: u16,
}

impl Stride {
    /// What a volume of `dims` asking for every `every`-th slice
    /// contours: the slices `0, every, 2 every, ...` of each plane.
    pub fn new(dims: [u16; 3], every: u8) -> Self {
        let every = u16::from(every.max(1));
        let anchor = dims.map(|n| n / 2 / every * every);
        let most = dims.iter().fold(0, |m, &d| m.max(d)).saturating_sub(1);
        Self { every, anchor, most }
    }

    /// Whether slice `index` along `axis` (0 x, 1 y, 2 z) is contoured.
    #[inline]
    pub fn keeps(&self, axis: usize, index: u16) -> bool {
        self.anchor.get(axis).is_some_and(|&c| index.abs_diff(c).is_multiple_of(self.every.max(1)))
    }

    /// The first slice at or after `index` along `axis` that is contoured.
    pub fn next(&self, axis: usize, index: usize) -> usize {
        let e = usize::from(self.every.max(1));
        let r = self.anchor.get(axis).map_or(0, |&c| usize::from(c) % e);
        index.saturating_add((r + e - index % e) % e)
    }

    /// Twice as many slices apart; `None` when that would leave no slice
    /// out.
    pub fn coarser(&self) -> Option<Self> {
        (self.every <= self.most / 2).then(|| Self { every: 2 * self.every, ..*self })
    }
}

/// Keep only the pieces of `back` then `spill` (one sequence, as the
/// stitch pass reads them) that lie in a slice `stride` keeps: a piece is
/// kept when, along some axis, all its points share one whole voxel
/// coordinate and that slice is kept (the x-y slice `z`, the x-z slice
/// `y`, the y-z slice `x`). What is kept stays in order and is packed from
/// the start of `back` on, into `spill` when `back` is full. Returns the
/// pieces kept.
///
/// A piece that lies in several slices (a dot at a grid node, a line along
/// a grid line) stays if any of them does.
///
/// A polyline that lies in no one slice (pieces of several slices already
/// stitched together while the volume arrived: [`crate::path::chain`] with
/// no merging, so that each of its segments still lies in the slice it
/// came from) is thinned segment by segment by the same test: what is left
/// of it is written as the runs of segments kept, each a polyline of its
/// own (a loop's run across its first point joined into one).
///
/// `poll` is called every 256 points passed over (for a board that keeps its output
/// fed meanwhile: this passes over the whole surface).
pub(crate) fn thin(
    back: &mut Geometry<'_>,
    spill: &mut Geometry<'_>,
    stride: &Stride,
    poll: &mut dyn FnMut(),
) -> u32 {
    let old = back.len();
    let room = back.capacity();
    let shift = back.shift().min(12);
    let whole = (1u16 << shift) - 1;
    let read = |back: &Geometry<'_>, spill: &Geometry<'_>, i: usize| {
        if i < old { back.get(i) } else { spill.get(i - old) }
    };
    let (mut r, mut w, mut kept) = (0usize, 0usize, 0u32);
    // Points passed over since the start: `poll` every 256.
    let mut work = 0u32;
    let mut tick = |poll: &mut dyn FnMut()| {
        work = work.wrapping_add(1);
        if work.is_multiple_of(256) {
            poll();
        }
    };
    // Writes stay behind reads (`w <= i` when point `i` is read), in
    // either store.
    let put = |back: &mut Geometry<'_>, spill: &mut Geometry<'_>, w: usize, q: Packed, k: Kind| {
        if w < room {
            back.put(w, q, k);
        } else {
            spill.put(w - room, q, k);
        }
    };
    // Whether `stride` keeps a slice that both `a` and `b` lie in.
    let keeps_segment = |a: Packed, b: Packed| {
        a.iter()
            .zip(b)
            .enumerate()
            .any(|(axis, (&c, d))| c & whole == 0 && c == d && stride.keeps(axis, c >> shift))
    };
    while let Some((first, kind)) = read(back, spill, r) {
        tick(poll);
        // The piece: `r` and the `Line`s after it.
        let mut end = r + 1;
        // Axes along which every point so far is at `first`'s whole voxel.
        let mut axes = first.map(|c| c & whole == 0);
        while let Some((q, Kind::Line)) = read(back, spill, end) {
            tick(poll);
            for ((on, c), f) in axes.iter_mut().zip(q).zip(first) {
                *on &= c == f;
            }
            end += 1;
        }
        if axes.iter().any(|&on| on) {
            // In one slice (or several): kept whole or not at all.
            let keep =
                axes.iter().zip(first).enumerate().any(|(a, (&on, c))| on && stride.keeps(a, c >> shift));
            if keep {
                kept += 1;
                for i in r..end {
                    tick(poll);
                    if let Some((q, k)) = read(back, spill, i) {
                        put(back, spill, w, q, k);
                    }
                    w += 1;
                }
            }
        } else {
            // Across slices: the runs of segments kept, each from a `Move`.
            // A loop kept whole stays a loop; a loop cut keeps a run
            // across its first point as one. Every case writes at most the
            // points read (a run costs a point more than its segments, and
            // runs are parted by segments dropped): see the counts below.
            let closed = kind == Kind::Loop;
            let start = w;
            let (mut open, mut dropped) = (false, false);
            // The first run's points, when it begins at the first point.
            let mut first_run: Option<usize> = None;
            let mut prev = first;
            let mut seg0 = false;
            for i in r + 1..end {
                tick(poll);
                let q = read(back, spill, i).map_or(prev, |(q, _)| q);
                if keeps_segment(prev, q) {
                    seg0 |= i == r + 1;
                    if !open {
                        put(back, spill, w, prev, Kind::Move);
                        w += 1;
                        kept += 1;
                        open = true;
                    }
                    put(back, spill, w, q, Kind::Line);
                    w += 1;
                } else {
                    if open && !dropped && seg0 {
                        first_run = Some(w - start);
                    }
                    open = false;
                    dropped = true;
                }
                prev = q;
            }
            if closed && keeps_segment(prev, first) {
                // The closing segment, from the last point to the first.
                let get = |back: &Geometry<'_>, spill: &Geometry<'_>, j: usize| {
                    if j < room { back.get(j) } else { spill.get(j - room) }
                };
                if !dropped {
                    // Whole (`w - start` is the loop's points).
                    put(back, spill, start, first, Kind::Loop);
                } else if open && seg0 {
                    // The last run, the closing segment and the first run
                    // are one: the first run rotated to the end, behind the
                    // last (the same points).
                    let a = first_run.unwrap_or(0);
                    let reverse = |back: &mut Geometry<'_>,
                                   spill: &mut Geometry<'_>,
                                   lo: usize,
                                   hi: usize| {
                        let (mut i, mut j) = (lo, hi);
                        while i + 1 < j {
                            j -= 1;
                            if let (Some((p, k)), Some((q, l))) = (get(back, spill, i), get(back, spill, j)) {
                                put(back, spill, i, q, l);
                                put(back, spill, j, p, k);
                            }
                            i += 1;
                        }
                    };
                    reverse(back, spill, start, start + a);
                    reverse(back, spill, start + a, w);
                    reverse(back, spill, start, w);
                    put(back, spill, w - a, first, Kind::Line);
                    kept = kept.saturating_sub(1);
                } else if open {
                    // The last run goes on to the first point: one point
                    // more, and the first segment was dropped, so the gaps
                    // are as many as the runs.
                    put(back, spill, w, first, Kind::Line);
                    w += 1;
                } else if seg0 {
                    // The first run starts one point earlier: all moved up
                    // one (the segment before the last point was dropped:
                    // as many gaps as runs).
                    for j in (start..w).rev() {
                        tick(poll);
                        if let Some((p, k)) = get(back, spill, j) {
                            put(back, spill, j + 1, p, k);
                        }
                    }
                    put(back, spill, start, prev, Kind::Move);
                    put(back, spill, start + 1, first, Kind::Line);
                    w += 1;
                } else {
                    // A run of its own: two points, and a gap more than the
                    // runs before it.
                    put(back, spill, w, prev, Kind::Move);
                    put(back, spill, w + 1, first, Kind::Line);
                    w += 2;
                    kept += 1;
                }
            }
        }
        r = end;
    }
    back.set_len(w.min(room));
    spill.set_len(w.saturating_sub(room));
    kept
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::path::{Packed, Source};

    fn store(n: usize) -> Vec<u8> {
        vec![0; Geometry::bytes_for(n)]
    }

    #[test]
    fn the_stride_asked_is_every_nth_from_zero_and_coarser_keeps_the_middle() {
        let s = Stride::new([128, 128, 84], 4);
        assert_eq!(s.anchor, [64, 64, 40]);
        let kept = |s: &Stride, axis: usize, n: u16| (0..n).filter(|&i| s.keeps(axis, i)).collect::<Vec<_>>();
        assert_eq!(kept(&s, 2, 84), (0..84).step_by(4).collect::<Vec<_>>());
        let mut c = s;
        let mut seen = vec![kept(&s, 2, 84)];
        while let Some(next) = c.coarser() {
            c = next;
            let k = kept(&c, 2, 84);
            // Each stride keeps a subset of the last one's slices, the
            // middle among them.
            assert!(k.iter().all(|i| seen.last().unwrap().contains(i)), "{k:?}");
            assert!(k.contains(&40));
            // `next` finds exactly the kept slices.
            let mut walk = Vec::new();
            let mut i = c.next(2, 0);
            while i < 84 {
                walk.push(i as u16);
                i = c.next(2, i + 1);
            }
            assert_eq!(walk, k);
            seen.push(k);
        }
        assert_eq!(c.every, 64);
        assert_eq!(seen.last().unwrap(), &[40]);
        assert_eq!(kept(&c, 0, 128), [0, 64]);
        assert_eq!(Stride::new([2, 2, 1], 1).coarser(), None);
    }

    #[test]
    fn thinning_keeps_whole_slices_in_order_packed_from_the_front() {
        // Pieces in slices of all three planes (index 0..7), one to three
        // points each; the other coordinates off the grid, so that one
        // axis alone is whole. Kinds cycle through the starts.
        let shift = 4u8;
        let whole = |c: u16| c << shift;
        let index = |i: u16| i * 5 % 7;
        let pieces: Vec<Vec<Packed>> = (0..40u16)
            .map(|i| {
                let (axis, len) = (usize::from(i % 3), 1 + i % 3);
                (0..len)
                    .map(|k| {
                        let mut q = [3 + 16 * k + i, 7 + 32 * k, 9 + 8 * i];
                        q[axis] = whole(index(i));
                        q
                    })
                    .collect()
            })
            .collect();
        let starts = [Kind::Move, Kind::Loop, Kind::Dot];
        let points: usize = pieces.iter().map(Vec::len).sum();
        let mut stride = Stride::new([7, 7, 7], 1);
        loop {
            for room in [0, 1, 5, 17, points] {
                let (mut a, mut b) = (store(room), store(points));
                let (mut back, mut spill) = (Geometry::new(&mut a), Geometry::new(&mut b));
                back.reset(shift);
                spill.reset(shift);
                let mut want = Vec::new();
                for (i, piece) in pieces.iter().enumerate() {
                    let i = i as u16;
                    for (k, &q) in piece.iter().enumerate() {
                        let kind = if k == 0 { starts[usize::from(i % 3)] } else { Kind::Line };
                        if !back.push_raw(q, kind) {
                            assert!(spill.push_raw(q, kind));
                        }
                        if stride.keeps(usize::from(i % 3), index(i)) {
                            want.push((q, kind));
                        }
                    }
                }
                let kept = thin(&mut back, &mut spill, &stride, &mut || {});
                let wanted = (0..40u16).filter(|&i| stride.keeps(usize::from(i % 3), index(i))).count();
                assert_eq!(kept as usize, wanted, "{stride:?}, room {room}");
                let s = Source::two(&back, &spill);
                let got: Vec<_> = (0..s.len()).filter_map(|i| s.get(i)).collect();
                assert_eq!(got, want, "{stride:?}, room {room}");
                assert_eq!(back.len(), want.len().min(room), "the back fills first");
            }
            let Some(next) = stride.coarser() else { break };
            stride = next;
        }
        assert_eq!(stride.every, 4);
        // A dot at a grid node stays if any of its slices does; a line
        // along a grid line too.
        let (mut a, mut b) = (store(4), store(0));
        let (mut back, mut spill) = (Geometry::new(&mut a), Geometry::new(&mut b));
        back.reset(shift);
        assert!(back.push_raw([whole(3), whole(5), whole(4)], Kind::Dot));
        assert!(back.push_raw([whole(1), whole(3), 5], Kind::Move));
        assert!(back.push_raw([whole(1), whole(3), 21], Kind::Line));
        assert!(back.push_raw([whole(3), whole(3), whole(3)], Kind::Dot));
        let four = Stride { every: 4, anchor: [0; 3], most: 100 };
        assert_eq!(thin(&mut back, &mut spill, &four, &mut || {}), 1);
        assert_eq!(back.get(0), Some(([whole(3), whole(5), whole(4)], Kind::Dot)));
        assert_eq!(back.len(), 1);
    }

    /// A polyline of pieces of several slices (as the stream's stitching
    /// on the way leaves them) thins to exactly its segments in slices
    /// kept, each run a polyline, written in place over any split of back
    /// and spill; a loop kept whole stays a loop.
    mod across_slices {
        use super::*;
        use proptest::prelude::*;

        const SHIFT: u8 = 4;

        /// Polylines from steps: each step either stays in the plane of
        /// an axis (that coordinate whole and kept from the point before)
        /// or leaves every plane.
        fn polylines() -> impl Strategy<Value = Vec<(bool, Vec<Packed>)>> {
            // A coordinate: whole voxel `c` most of the time, else a step
            // past it.
            let coord = (0u16..4, prop::sample::select(vec![0u16, 0, 0, 0, 0, 3, 9]))
                .prop_map(|(c, f)| (c << SHIFT) + f);
            let point = prop::array::uniform3(coord);
            let step = (0usize..4, point.clone());
            let line = (any::<bool>(), point, prop::collection::vec(step, 1..9));
            prop::collection::vec(line, 1..12).prop_map(|lines| {
                lines
                    .into_iter()
                    .map(|(closed, p0, steps)| {
                        let mut pts = vec![p0];
                        for (axis, mut q) in steps {
                            // In the plane of `axis` of the point before (if
                            // that coordinate is whole), or anywhere.
                            if let (Some(c), Some(last)) = (q.get_mut(axis), pts.last()) {
                                *c = last[axis];
                            }
                            pts.push(q);
                        }
                        (closed && pts.len() >= 3, pts)
                    })
                    .collect()
            })
        }

        fn in_kept(stride: &Stride, a: Packed, b: Packed) -> bool {
            let whole = (1u16 << SHIFT) - 1;
            (0..3).any(|x| a[x] & whole == 0 && a[x] == b[x] && stride.keeps(x, a[x] >> SHIFT))
        }

        proptest! {
            #[test]
            fn keeps_exactly_the_segments_in_slices_kept(
                lines in polylines(),
                room in 0usize..60,
                every in 1u8..4,
                anchor in prop::array::uniform3(0u16..7),
            ) {
                let stride = Stride { every: u16::from(every), anchor, most: 100 };
                let points: usize = lines.iter().map(|(_, p)| p.len()).sum();
                let room = room.min(points);
                let (mut a, mut b) = (store(room), store(points));
                let (mut back, mut spill) = (Geometry::new(&mut a), Geometry::new(&mut b));
                back.reset(SHIFT);
                spill.reset(SHIFT);
                let mut want = Vec::new();
                let mut whole_loops = 0;
                let mut single = Vec::new();
                let whole = (1u16 << SHIFT) - 1;
                for (closed, pts) in &lines {
                    for (k, &q) in pts.iter().enumerate() {
                        let kind = match (k, closed) { (0, true) => Kind::Loop, (0, false) => Kind::Move, _ => Kind::Line };
                        if !back.push_raw(q, kind) {
                            prop_assert!(spill.push_raw(q, kind));
                        }
                    }
                    // One slice for all of it: the piece rule, tested above.
                    let one = (0..3).any(|x| pts.iter().all(|p| p[x] & whole == 0 && p[x] == pts[0][x]));
                    single.push(one);
                    if one {
                        continue;
                    }
                    let mut segs: Vec<[Packed; 2]> = pts.windows(2).map(|w| [w[0], w[1]]).collect();
                    if *closed {
                        segs.push([pts[pts.len() - 1], pts[0]]);
                    }
                    if segs.iter().all(|s| in_kept(&stride, s[0], s[1])) && *closed {
                        whole_loops += 1;
                    }
                    want.extend(segs.into_iter().filter(|s| in_kept(&stride, s[0], s[1])));
                }
                prop_assume!(single.iter().all(|&one| !one));
                let _ = whole;
                let kept = thin(&mut back, &mut spill, &stride, &mut || {});
                let s = Source::two(&back, &spill);
                let got: Vec<(Packed, Kind)> = (0..s.len()).filter_map(|i| s.get(i)).collect();
                prop_assert_eq!(back.len(), got.len().min(room));
                // The polylines written, as segments.
                let mut segs = Vec::new();
                let mut loops = 0;
                let mut i = 0;
                while i < got.len() {
                    let (p0, k0) = got[i];
                    prop_assert!(k0 == Kind::Move || k0 == Kind::Loop, "{got:?}");
                    let mut j = i + 1;
                    while j < got.len() && got[j].1 == Kind::Line {
                        segs.push([got[j - 1].0, got[j].0]);
                        j += 1;
                    }
                    prop_assert!(j > i + 1, "a lone point: {got:?}");
                    if k0 == Kind::Loop {
                        loops += 1;
                        segs.push([got[j - 1].0, p0]);
                    }
                    i = j;
                }
                let norm = |v: &mut Vec<[Packed; 2]>| {
                    for s in v.iter_mut() { s.sort(); }
                    v.sort();
                };
                norm(&mut segs);
                norm(&mut want);
                prop_assert_eq!(segs, want);
                prop_assert_eq!(loops, whole_loops);
                let starts = got.iter().filter(|(_, k)| k.starts()).count();
                prop_assert_eq!(kept as usize, starts);
            }
        }
    }
}
