//! The inner loop: sweep rows of cells in blocks, skipping the cells no
//! level meets.
//!
//! Samples are gathered into `f32` lanes a block at a time and classified
//! once each (entirely above the highest level, entirely below the lowest,
//! or neither); a cell can be skipped when all four corners share "above" or
//! "below". These passes are branch-free and vectorise. Only the remaining
//! cells (a few percent in a real volume) build a subgrid and traverse its
//! contouring trees. Non-finite samples are never "above" or "below", so
//! cells touching them always reach the per-cell code, which skips and
//! counts them.

use crate::command::CommandSink;
use crate::contour::{ContourStats, contour_subgrid};
use crate::pen::Placement;
use crate::sample::Sample;
use crate::subgrid::Subgrid;
use crate::trace::Traversal;

/// Cells per block (stack use of the sweep is about 12 bytes per cell).
pub(crate) const BLOCK: usize = 128;

/// Copy `out.len()` samples, `stride` apart from `start`, as `f32` (NaN
/// past the end of `data`; the callers' views are checked, so that does not
/// happen).
#[inline(always)]
pub(crate) fn gather<T: Sample>(data: &[T], start: usize, stride: usize, out: &mut [f32]) {
    let n = out.len();
    if stride == 1 {
        if let Some(src) = data.get(start..start.saturating_add(n)) {
            for (o, s) in out.iter_mut().zip(src) {
                *o = s.to_f32();
            }
            return;
        }
    }
    for (k, o) in out.iter_mut().enumerate() {
        *o = data.get(start.wrapping_add(k.wrapping_mul(stride))).map_or(f32::NAN, |s| s.to_f32());
    }
}

/// `min` and `max` without NaN handling (one instruction each); NaN is
/// caught separately by the sum.
#[inline(always)]
fn min2(a: f32, b: f32) -> f32 {
    if a < b { a } else { b }
}

#[inline(always)]
fn max2(a: f32, b: f32) -> f32 {
    if a > b { a } else { b }
}

/// Mark the cells (corners in four lanes) that may meet a level in
/// `[klo, khi]`: not all corners above `khi`, not all below `klo`, or a
/// corner that is not finite (the corner sum is then NaN or infinite; a sum
/// that overflows from finite corners only sends the cell the slow way).
#[inline(always)]
fn mark(out: &mut [u8], [a, b, c, d]: [&[f32]; 4], klo: f32, khi: f32) {
    for ((((o, &a), &b), &c), &d) in out.iter_mut().zip(a).zip(b).zip(c).zip(d) {
        let lo = min2(min2(a, b), min2(c, d));
        let hi = max2(max2(a, b), max2(c, d));
        let sum = (a + b) + (c + d);
        let quiet = (lo > khi) | (hi < klo);
        *o = u8::from(!quiet | !sum.is_finite());
    }
}

/// Row buffers for one block: sample values and their classes.
pub(crate) struct Rows {
    pub v: [[f32; BLOCK + 1]; 4],
    busy: [u8; BLOCK],
}

impl Rows {
    pub(crate) const fn new() -> Self {
        Self { v: [[0.0; BLOCK + 1]; 4], busy: [0; BLOCK] }
    }
}

/// How a block's four corner lanes are laid out in [`Rows::v`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Layout {
    /// Two grid rows: `v[0]` is row `j`, `v[1]` row `j+1`, `n + 1` samples
    /// each; cell `k` has corners `v[0][k], v[0][k+1], v[1][k+1], v[1][k]`.
    TwoRows,
    /// Four lanes, `n` samples each: cell `k` has corners
    /// `v[0][k], v[1][k], v[2][k], v[3][k]` (LL, LR, UR, UL).
    FourLanes,
}

/// Levels and traversal of one contouring run.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Sweep<'l> {
    pub levels: &'l [f32],
    pub traversal: Traversal,
    klo: f32,
    khi: f32,
}

impl<'l> Sweep<'l> {
    /// A sweep over finite `levels` (checked by the caller).
    pub(crate) fn new(levels: &'l [f32], traversal: Traversal) -> Self {
        let (klo, khi) =
            levels.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &l| (a.min(l), b.max(l)));
        Self { levels, traversal, klo, khi }
    }

    /// Contour the `n` cells of a gathered block. Cell `k` sits at `at(k)` in
    /// its grid and its points are placed by `place(k, x, y)`.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn run<P, S: CommandSink<P>>(
        &self,
        rows: &mut Rows,
        layout: Layout,
        n: usize,
        at: impl Fn(usize) -> Placement,
        place: impl Fn(usize, f32, f32) -> P,
        sink: &mut S,
        stats: &mut ContourStats,
    ) -> Result<(), S::Error> {
        let n = n.min(BLOCK);
        let [v0, v1, v2, v3] = &rows.v;
        fn lane(v: &[f32; BLOCK + 1], from: usize, n: usize) -> &[f32] {
            v.get(from..from + n).unwrap_or(&[])
        }
        let lanes = match layout {
            Layout::TwoRows => [lane(v0, 0, n), lane(v0, 1, n), lane(v1, 1, n), lane(v1, 0, n)],
            Layout::FourLanes => [lane(v0, 0, n), lane(v1, 0, n), lane(v2, 0, n), lane(v3, 0, n)],
        };
        mark(&mut rows.busy, lanes, self.klo, self.khi);
        let busy = rows.busy.get(..n).unwrap_or(&[]);
        for (g, group) in busy.chunks(16).enumerate() {
            if group.iter().fold(0, |m, &x| m | x) == 0 {
                continue;
            }
            for (k, &b) in group.iter().enumerate() {
                if b == 0 {
                    continue;
                }
                let k = g * 16 + k;
                let [v0, v1, v2, v3] = &rows.v;
                let corners = match layout {
                    Layout::TwoRows => (v0.get(k), v0.get(k + 1), v1.get(k + 1), v1.get(k)),
                    Layout::FourLanes => (v0.get(k), v1.get(k), v2.get(k), v3.get(k)),
                };
                let (Some(&ll), Some(&lr), Some(&ur), Some(&ul)) = corners else { continue };
                self.cell([ll, lr, ur, ul], at(k), &|x, y| place(k, x, y), sink, stats)?;
            }
        }
        Ok(())
    }

    /// Contour one cell that the block test did not skip.
    #[inline(always)]
    fn cell<P, S: CommandSink<P>>(
        &self,
        [a, b, c, d]: [f32; 4],
        at: Placement,
        place: &impl Fn(f32, f32) -> P,
        sink: &mut S,
        stats: &mut ContourStats,
    ) -> Result<(), S::Error> {
        if !(a.is_finite() & b.is_finite() & c.is_finite() & d.is_finite()) {
            stats.nonfinite_cells += 1;
            return Ok(());
        }
        let lo = min2(min2(a, b), min2(c, d));
        let hi = max2(max2(a, b), max2(c, d));
        // A constant subgrid draws nothing; several levels may straddle the
        // cell (one level meets it, or the marking would have skipped it).
        if lo == hi || (self.levels.len() > 1 && !self.levels.iter().any(|&l| lo <= l && l <= hi)) {
            return Ok(());
        }
        let sub = Subgrid::from_finite(a, b, c, d);
        let sent = contour_subgrid(&sub, at, self.levels, self.traversal, place, sink)?;
        stats.crossing_cells += u64::from(sent > 0);
        stats.commands += sent;
        Ok(())
    }
}
