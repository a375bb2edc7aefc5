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
//!
//! Where the cells lie between two rows of samples ([`Sweep::run_rows`]:
//! the engine's streaming rows, [`crate::contour::contour_rows`]), each
//! sample is classed once instead (finite and above every level, finite
//! and below every level) into bits, 32 cells a word, and the marked cells
//! are the words' zero bits.

use super::pen::Placement;
use super::subgrid::Subgrid;
use super::trace::Traversal;
use super::voxel::Voxel;
use super::{ContourStats, contour_subgrid};
use crate::command::CommandSink;

/// Cells per block. The scratch space is about 17 bytes per cell (2.2 KiB
/// of stack).
pub(crate) const BLOCK: usize = 128;

/// `n` samples, `stride` apart from `start`, as `f32`: borrowed from
/// `data` when they are contiguous `f32`s, otherwise converted into `buf`
/// (NaN past the end of `data`; the callers' views are checked, so that does
/// not happen).
#[inline(always)]
pub(crate) fn lane<'a, T: Voxel>(
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

/// A float's bits as an integer in the same order (`-0.0` just below
/// `+0.0`, NaNs beyond the infinities): an integer compare instead of a
/// float compare and a move of the flags on the MCU.
#[inline(always)]
fn key(v: f32) -> i32 {
    let b = v.to_bits() as i32;
    b ^ ((b >> 31) & 0x7FFF_FFFF)
}

/// Keys strictly between `lo` and `hi` (`lo < hi`): one subtraction and
/// one unsigned compare, as a borrow.
#[derive(Debug, Clone, Copy)]
struct Between {
    /// `lo + 1`.
    from: i32,
    /// Keys from `from` on that are in.
    span: u32,
}

impl Between {
    fn new(lo: i32, hi: i32) -> Self {
        Self { from: lo.wrapping_add(1), span: (hi.wrapping_sub(lo) as u32).wrapping_sub(1) }
    }

    /// All ones when `k` is in, else 0: the borrow of `k - from` less
    /// `span`, as a 64-bit subtraction's high word (a subtraction and a
    /// subtraction with carry on the M4, where a compare made a flag into
    /// a value with a conditional move: 38 instructions a column of two
    /// samples became 32).
    #[inline(always)]
    fn mask(self, k: i32) -> u32 {
        let x = u64::from(k.wrapping_sub(self.from) as u32);
        (x.wrapping_sub(u64::from(self.span)) >> 32) as u32
    }
}

/// Words of sample bits a row pair's block takes (`BLOCK + 1` samples).
const WORDS: usize = BLOCK / 32 + 1;

/// The cells between `lower` and `upper` (of equal length) whose four
/// corners all lie in `above`, and those whose four all lie in `below`:
/// bit `k % 32` of word `k / 32` is cell `k` (corners `k` and `k + 1` of
/// both rows).
// Not inlined: inside the engine's row contouring its dozen live values
// spilled to the stack, and the Cortex-M4 counted 3.9M instructions for
// hydrogen 32^3's classes, against 1.3M as a function of its own (one
// profile run each; later runs of this code counted 1.3M to 2.1M).
#[inline(never)]
fn all_four(lower: &[f32], upper: &[f32], above: Between, below: Between) -> [[u32; WORDS]; 2] {
    // First the columns (both samples in), one word of 32 at a time, shifted
    // in from the top so that sample `k` lands on bit `k`.
    let mut out = [[0u32; WORDS]; 2];
    let [a_out, b_out] = &mut out;
    for (((a_w, b_w), l), u) in
        a_out.iter_mut().zip(b_out.iter_mut()).zip(lower.chunks(32)).zip(upper.chunks(32))
    {
        let (mut a, mut b) = (0u32, 0u32);
        for (&l, &u) in l.iter().zip(u).rev() {
            let (kl, ku) = (key(l), key(u));
            a = (a << 1) | ((above.mask(kl) & above.mask(ku)) >> 31);
            b = (b << 1) | ((below.mask(kl) & below.mask(ku)) >> 31);
        }
        (*a_w, *b_w) = (a, b);
    }
    // Then a cell is its column and the next (bit `k + 1` at `k`, across
    // words).
    for words in &mut out {
        let mut next_word = 0u32;
        for w in words.iter_mut().rev() {
            let c = *w;
            *w = c & ((c >> 1) | (next_word << 31));
            next_word = c;
        }
    }
    out
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
    /// Finite samples above every level, and below every level.
    above: Between,
    below: Between,
}

impl<'l> Sweep<'l> {
    /// A sweep over finite `levels` (checked by the caller).
    pub(crate) fn new(levels: &'l [f32], traversal: Traversal) -> Self {
        let (klo, khi) =
            levels.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &l| (a.min(l), b.max(l)));
        // Above `khi` in the float order (`-0.0` is not above `0.0`) and
        // below `klo` (`0.0` is not below `-0.0`), and finite.
        let above = Between::new(key(khi + 0.0), key(f32::INFINITY));
        let below = Between::new(key(f32::NEG_INFINITY), key(if klo == 0.0 { -0.0 } else { klo }));
        Self { levels, traversal, klo, khi, above, below }
    }

    /// [`Sweep::run`] for the cells between two rows of samples: cell `k`
    /// has corners `lower[k], lower[k + 1], upper[k + 1], upper[k]` (the
    /// shorter row, up to `BLOCK + 1` samples, sets the cells). The cells
    /// no level meets are found from two bits a sample (above every level,
    /// below every level; a non-finite sample is neither), 32 cells a word,
    /// instead of four corners a cell.
    #[inline(always)]
    pub(crate) fn run_rows<P, S: CommandSink<P>>(
        &self,
        lower: &[f32],
        upper: &[f32],
        at: impl Fn(usize) -> Placement,
        place: impl Fn(usize, f32, f32) -> P,
        sink: &mut S,
        stats: &mut ContourStats,
    ) -> Result<(), S::Error> {
        let samples = lower.len().min(upper.len()).min(BLOCK + 1);
        let (lower, upper) = (lower.get(..samples).unwrap_or(&[]), upper.get(..samples).unwrap_or(&[]));
        let cells = samples.saturating_sub(1);
        let [above, below] = all_four(lower, upper, self.above, self.below);
        for (w, (above, below)) in above.into_iter().zip(below).enumerate() {
            let first = 32 * w;
            if first >= cells {
                break;
            }
            let valid = if cells - first >= 32 { u32::MAX } else { (1u32 << (cells - first)) - 1 };
            let mut busy = !(above | below) & valid;
            while busy != 0 {
                let k = first + busy.trailing_zeros() as usize;
                busy &= busy - 1;
                let (Some(&a), Some(&b), Some(&c), Some(&d)) =
                    (lower.get(k), lower.get(k + 1), upper.get(k + 1), upper.get(k))
                else {
                    continue;
                };
                self.cell([a, b, c, d], at(k), &|x, y| place(k, x, y), sink, stats)?;
            }
        }
        Ok(())
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::command::Command;
    use proptest::prelude::*;

    /// A cell's index and a point.
    type Placed = (usize, f32, f32);

    #[test]
    fn between_mask_is_the_unsigned_compare() {
        let edges = [i32::MIN, i32::MIN + 1, -2, -1, 0, 1, 2, 0x7F80_0000, i32::MAX - 1, i32::MAX];
        for &lo in &edges {
            for &hi in &edges {
                if lo >= hi {
                    continue;
                }
                let b = Between::new(lo, hi);
                for &k in &edges {
                    let want = lo < k && k < hi;
                    assert_eq!(b.mask(k), if want { u32::MAX } else { 0 }, "lo, hi, k = {:?}", (lo, hi, k));
                }
            }
        }
    }

    proptest! {
        #[test]
        fn between_mask_is_the_unsigned_compare_anywhere(lo in any::<i32>(), hi in any::<i32>(), k in any::<i32>()) {
            prop_assume!(lo < hi);
            let b = Between::new(lo, hi);
            prop_assert_eq!(b.mask(k), if lo < k && k < hi { u32::MAX } else { 0 });
        }
    }

    /// Records every command with its level.
    struct Record(Vec<(usize, Command<Placed>)>);

    impl CommandSink<Placed> for Record {
        type Error = core::convert::Infallible;
        fn command(&mut self, level: usize, c: Command<Placed>) -> Result<(), Self::Error> {
            self.0.push((level, c));
            Ok(())
        }
    }

    /// Samples where the two ways of finding quiet cells could part: the
    /// levels themselves, signed zeros, non-finite and huge values.
    fn sample() -> impl Strategy<Value = f32> {
        prop_oneof![
            2 => -3.0f32..3.0,
            1 => prop::sample::select(vec![
                0.0f32, -0.0, 1.0, -1.0, 0.5, f32::NAN, f32::INFINITY, f32::NEG_INFINITY, f32::MAX, -f32::MAX,
                f32::MIN_POSITIVE, -1e-45,
            ]),
        ]
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(400))]
        #[test]
        fn rows_find_the_cells_four_lanes_find(
            lower in prop::collection::vec(sample(), 0..=BLOCK + 1),
            upper in prop::collection::vec(sample(), 0..=BLOCK + 1),
            levels in prop::collection::vec(prop::sample::select(vec![0.0f32, -0.0, 0.5, 1.0, -1.0, 2.5]), 1..3),
        ) {
            let sweep = Sweep::new(&levels, Traversal::Corrected);
            let place = |k: usize, x: f32, y: f32| (k, x, y);
            let at = |k: usize| Placement::new(k, 7);
            let (mut rows, mut lanes) = (Record(Vec::new()), Record(Vec::new()));
            let (mut rows_stats, mut lanes_stats) = (ContourStats::default(), ContourStats::default());
            let _ = sweep.run_rows(&lower, &upper, at, place, &mut rows, &mut rows_stats);
            let n = lower.len().min(upper.len()).min(BLOCK + 1);
            let (r0, r1) = (&lower[..n], &upper[..n]);
            let (l0, l1) = (r0.get(1..).unwrap_or(&[]), r1.get(1..).unwrap_or(&[]));
            let mut busy = [0u8; BLOCK];
            let _ = sweep.run([r0, l0, l1, r1], &mut busy, at, place, &mut lanes, &mut lanes_stats);
            let bits = |r: &Record| r.0.iter().map(|(l, c)| (*l, c.map(|(k, x, y)| (k, x.to_bits(), y.to_bits())))).collect::<Vec<_>>();
            prop_assert_eq!(bits(&rows), bits(&lanes));
            prop_assert_eq!(rows_stats, lanes_stats);
            // And exactly the quiet cells are found quiet (a busy cell
            // taken for quiet is lost; the converse only costs time).
            let cells = n.saturating_sub(1);
            let (klo, khi) = levels.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &l| (a.min(l), b.max(l)));
            let [above, below] = all_four(r0, r1, sweep.above, sweep.below);
            for k in 0..cells {
                let corners = [r0[k], r0[k + 1], r1[k + 1], r1[k]];
                let all = |f: &dyn Fn(f32) -> bool| corners.iter().all(|&v| v.is_finite() && f(v));
                prop_assert_eq!(above[k / 32] >> (k % 32) & 1 == 1, all(&|v| v > khi), "cell {} above", k);
                prop_assert_eq!(below[k / 32] >> (k % 32) & 1 == 1, all(&|v| v < klo), "cell {} below", k);
            }
        }
    }
}
