//! Writing chains: the beam's walk from fragment to fragment, runs of
//! nearly collinear points merged, a chain back at its start closed.

use super::ChainStats;
use super::index::{Index, length};
use super::store::{Geometry, Kind, Packed};

/// Dropped points remembered to check a merged chord against.
pub(super) const MERGE_SPAN: usize = 8;

/// Where the beam is, and the chain being written.
pub(super) struct Walk {
    pub(super) out: Out,
    /// The last point drawn, and the one before it.
    pub(super) cur: Packed,
    pub(super) prev: Option<Packed>,
}

impl Walk {
    /// Take and draw fragment `f`, entering at its end `end`: a
    /// continuation of the chain when it starts where the chain ends (and
    /// `join` allows, or the ends meet exactly), else a new chain after a
    /// jump.
    pub(super) fn take(
        &mut self,
        x: &mut Index<'_, '_>,
        dst: &mut Geometry<'_>,
        (end, f): (usize, usize),
        join: bool,
        stats: &mut ChainStats,
    ) {
        x.take(f);
        self.draw(x, dst, f, end, join, stats);
    }

    pub(super) fn draw(
        &mut self,
        x: &Index<'_, '_>,
        dst: &mut Geometry<'_>,
        f: usize,
        end: usize,
        join: bool,
        stats: &mut ChainStats,
    ) {
        let (from, to) = x.span(f);
        let first = x.point(end);
        if !(join || first == self.cur) || !self.out.open {
            self.out.finish(dst, stats);
            stats.travel += length(first, self.cur) / f32::from(1u16 << x.src.shift());
        }
        // Only a fragment's first point may be a dot (the rest are lines).
        let dot = x.kind(from) == Kind::Dot;
        let mut emit = |i: usize| {
            // (A fragment may be a long polyline: stitched as a volume
            // arrived, [`crate::path::thin`].)
            x.poll.tick(1);
            let q = x.point(i);
            self.out.point(dst, q, dot && i == from, stats);
            if self.cur != q {
                self.prev = Some(self.cur);
                self.cur = q;
            }
        };
        if x.is_loop(f) {
            // Entered at `end`: round to it again.
            (end..to).chain(from..=end).for_each(&mut emit);
        } else if end + 1 == to && end != from {
            (from..to).rev().for_each(&mut emit);
        } else {
            (from..to).for_each(&mut emit);
        }
    }
}

/// The chain being written: merges collinear runs, closes loops.
pub(super) struct Out {
    pub(super) open: bool,
    /// Index in `dst` of the chain's first point.
    pub(super) first: usize,
    /// Merging: the last point kept for good, the last point written (it
    /// may yet be merged away), and the points merged away since `kept`.
    pub(super) kept: Option<Packed>,
    pub(super) last: Option<Packed>,
    pub(super) dropped: [Packed; MERGE_SPAN],
    pub(super) n_dropped: usize,
    tol2: f32,
}

impl Out {
    pub(super) fn new(tolerance: f32, shift: u8) -> Self {
        let scale = f32::from(1u16 << shift);
        let t = tolerance.max(0.0) * scale;
        Self {
            open: false,
            first: 0,
            kept: None,
            last: None,
            dropped: [[0; 3]; MERGE_SPAN],
            n_dropped: 0,
            tol2: if t.is_finite() { t * t } else { 0.0 },
        }
    }

    /// Add a point to the chain (a dot is a chain of its own).
    pub(super) fn point(&mut self, dst: &mut Geometry<'_>, q: Packed, dot: bool, stats: &mut ChainStats) {
        if dot {
            self.finish(dst, stats);
            if dst.push_raw(q, Kind::Dot) {
                stats.polylines += 1;
            }
            return;
        }
        if !self.open {
            self.open = true;
            self.first = dst.len();
            self.kept = None;
            self.n_dropped = 0;
            self.last = dst.push_raw(q, Kind::Move).then_some(q);
            stats.polylines += 1;
            return;
        }
        if self.last == Some(q) {
            return; // the joint of two fragments
        }
        // Merge: drop `last` if it, and every point dropped since the kept
        // one, lies within the tolerance of the chord kept -> q.
        if let (Some(kept), Some(last)) = (self.kept, self.last) {
            if self.tol2 > 0.0 && self.n_dropped < MERGE_SPAN {
                let chord = Chord::new(kept, q);
                let near = |p: Packed| chord.dist2(p) <= self.tol2;
                if near(last) && self.dropped.iter().take(self.n_dropped).all(|&p| near(p)) {
                    dst.pop();
                    if let Some(slot) = self.dropped.get_mut(self.n_dropped) {
                        *slot = last;
                    }
                    self.n_dropped += 1;
                    stats.merged += 1;
                    self.last = dst.push_raw(q, Kind::Line).then_some(q);
                    return;
                }
            }
            self.kept = Some(last);
        } else {
            self.kept = self.last;
        }
        self.n_dropped = 0;
        self.last = dst.push_raw(q, Kind::Line).then_some(q);
    }

    /// End the chain: a chain back at its first point is a closed loop.
    pub(super) fn finish(&mut self, dst: &mut Geometry<'_>, stats: &mut ChainStats) {
        if !self.open {
            return;
        }
        self.open = false;
        let first = dst.get(self.first).map(|(q, _)| q);
        let n = dst.len().saturating_sub(self.first);
        if n == 1 {
            // All its points fell on one code: nothing to draw.
            dst.pop();
            stats.polylines = stats.polylines.saturating_sub(1);
            return;
        }
        if n >= 4 && first.is_some() && self.last == first {
            dst.pop();
            dst.close_at(self.first);
            stats.loops += 1;
        }
    }
}

/// A chord `a`-`b` (fixed point codes), worked out once for the points
/// checked against it.
#[derive(Debug, Clone, Copy)]
struct Chord {
    a: [f32; 3],
    ab: [f32; 3],
    len2: f32,
}

impl Chord {
    fn new(a: Packed, b: Packed) -> Self {
        let (a, b) = (as_f32(a), as_f32(b));
        let ab = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
        Self { a, ab, len2: ab[0] * ab[0] + ab[1] * ab[1] + ab[2] * ab[2] }
    }

    /// Squared distance from `p` to the segment.
    fn dist2(&self, p: Packed) -> f32 {
        let (a, ab, len2, p) = (self.a, self.ab, self.len2, as_f32(p));
        let ap = [p[0] - a[0], p[1] - a[1], p[2] - a[2]];
        let t = if len2 > 0.0 {
            ((ap[0] * ab[0] + ap[1] * ab[1] + ap[2] * ab[2]) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let d = [ap[0] - t * ab[0], ap[1] - t * ab[1], ap[2] - t * ab[2]];
        d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
    }
}

/// A code's coordinates as `f32` (exact).
fn as_f32(q: Packed) -> [f32; 3] {
    [f32::from(q[0]), f32::from(q[1]), f32::from(q[2])]
}
