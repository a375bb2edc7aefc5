//! The inner loop: sweep rows of cells in blocks, skipping the cells no
//! level meets.
//!
//! A block of up to [`BLOCK`] cells is seen as four lanes of corner values
//! (lower-left, lower-right, upper-right, upper-left), borrowed straight from
//! the samples when they are contiguous `f32`s and converted into scratch
//! buffers otherwise. A branch-free pass marks the cells that may meet a
//! level (not all corners above the highest level, not all below the
//! lowest, or a corner that is not finite); it vectorises. Only the marked
//! cells (a few percent in a real volume) build a subgrid and traverse its
//! contouring trees; those touching a non-finite sample are skipped there
//! and counted.

use crate::command::CommandSink;
use crate::contour::{ContourStats, contour_subgrid};
use crate::pen::Placement;
use crate::sample::Sample;
use crate::subgrid::Subgrid;
use crate::trace::Traversal;

/// Cells per block. The scratch space is about 17 bytes per cell (2.2 KiB
/// of stack).
pub(crate) const BLOCK: usize = 128;

/// `n` samples, `stride` apart from `start`, as `f32`: borrowed from
/// `data` when they are contiguous `f32`s, otherwise converted into `buf`
/// (NaN past the end of `data`; the callers' views are checked, so that does
/// not happen).
#[inline(always)]
pub(crate) fn lane<'a, T: Sample>(
    data: &'a [T],
    start: usize,
    stride: usize,
    n: usize,
    buf: &'a mut [f32; BLOCK + 1],
) -> &'a [f32] {
    let n = n.min(BLOCK + 1);
    if stride == 1
        && let Some(src) = data.get(start..start.saturating_add(n))
    {
        if let Some(f) = T::as_f32s(src) {
            return f;
        }
        for (o, s) in buf.iter_mut().zip(src) {
            *o = s.to_f32();
        }
        return buf.get(..n).unwrap_or(&[]);
    }
    for (k, o) in buf.iter_mut().take(n).enumerate() {
        *o = data.get(start.wrapping_add(k.wrapping_mul(stride))).map_or(f32::NAN, |s| s.to_f32());
    }
    buf.get(..n).unwrap_or(&[])
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

/// Scratch space for one block: lane buffers for samples that need
/// converting, and the marks.
#[derive(Debug)]
pub(crate) struct Scratch {
    pub bufs: [[f32; BLOCK + 1]; 4],
    pub busy: [u8; BLOCK],
}

impl Scratch {
    pub(crate) const fn new() -> Self {
        Self { bufs: [[0.0; BLOCK + 1]; 4], busy: [0; BLOCK] }
    }
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

    /// Contour the cells of a block: cell `k` has corners `ll[k], lr[k],
    /// ur[k], ul[k]`, sits at `at(k)` in its grid, and its points are placed
    /// by `place(k, x, y)`.
    #[inline(always)]
    pub(crate) fn run<P, S: CommandSink<P>>(
        &self,
        [ll, lr, ur, ul]: [&[f32]; 4],
        busy: &mut [u8; BLOCK],
        at: impl Fn(usize) -> Placement,
        place: impl Fn(usize, f32, f32) -> P,
        sink: &mut S,
        stats: &mut ContourStats,
    ) -> Result<(), S::Error> {
        let n = ll.len().min(lr.len()).min(ur.len()).min(ul.len()).min(BLOCK);
        mark(busy, [ll, lr, ur, ul], self.klo, self.khi);
        let busy = busy.get(..n).unwrap_or(&[]);
        for (g, group) in busy.chunks(16).enumerate() {
            if group.iter().fold(0, |m, &x| m | x) == 0 {
                continue;
            }
            for (k, &b) in group.iter().enumerate() {
                if b == 0 {
                    continue;
                }
                let k = g * 16 + k;
                let (Some(&a), Some(&b), Some(&c), Some(&d)) = (ll.get(k), lr.get(k), ur.get(k), ul.get(k))
                else {
                    continue;
                };
                self.cell([a, b, c, d], at(k), &|x, y| place(k, x, y), sink, stats)?;
            }
        }
        Ok(())
    }

    /// Contour one cell that the marking did not skip.
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
        let sub = Subgrid::from_finite(a, b, c, d);
        let (lo, hi) = sub.range();
        // A constant subgrid draws nothing; with several levels, none may
        // meet the cell even though the marking kept it.
        if lo == hi || (self.levels.len() > 1 && !self.levels.iter().any(|&l| lo <= l && l <= hi)) {
            return Ok(());
        }
        let sent = contour_subgrid(&sub, at, self.levels, self.traversal, place, sink)?;
        stats.crossing_cells += u64::from(sent > 0);
        stats.commands += sent;
        Ok(())
    }
}
