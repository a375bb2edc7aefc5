//! The busy cells of a block at one level, worked out together: where a
//! target has vectors, the nodes, direction codes and crossings of all of
//! them in loops the compiler vectorises, then each cell's program drawn
//! from the crossings worked out.
//!
//! A cell's program ([`compiled`](super::compiled)) names up to eight of
//! its edges; drawn one at a time (the lazy way, [`contour_subgrid`]) each
//! costs a division and a placement in scalar code. Here every edge of
//! every busy cell is divided, four or more lanes at a time, with the
//! very operations [`Subgrid::crossing_inside`] does, so every crossing is
//! bit-identical; the MCU, with no vectors, keeps the lazy way (dividing
//! all eight edges would cost it twice the divisions it needs).
//!
//! Cells the table does not hold (a node at the level, a non-finite
//! corner, a constant cell) go the lazy way.
//!
//! [`contour_subgrid`]: super::contour_subgrid

use super::compiled;
use super::pen::{Placement, along_in};
use super::subgrid::DirectionCode;
use super::sweep::{BLOCK, Classes, Sweep, each_busy};
use super::{ContourStats, draw_program};
use crate::command::CommandSink;

/// Whether the target has vectors: x86-64, AArch64, WebAssembly built
/// with `simd128`; not the MCU.
const VECTORS: bool = cfg!(any(target_feature = "sse2", target_feature = "neon", target_feature = "simd128"));

/// Cells a batch holds: a block's where the batch is taken
/// ([`Sweep::batched`]); one elsewhere (the board keeps no idle 14 KiB).
const LANES: usize = if VECTORS { BLOCK } else { 1 };

/// Bit of [`Batch::key`] for a cell drawn by its program here.
const FAST: u16 = 1 << 15;

/// Scratch for the busy cells of one block: their corners, placements,
/// crossings and keys. About 116 bytes a cell (14.5 KiB).
#[derive(Debug)]
pub(crate) struct Batch {
    /// Busy cells, as indices into the block.
    n: usize,
    idx: [u8; LANES],
    /// Corners LL, LR, UR, UL of each busy cell, then the centre
    /// ([`Batch::solve`]'s).
    v: [[f32; LANES]; 5],
    /// Each cell's grid columns `x0, x1` and rows `y0, y1` (its
    /// [`Placement`]).
    sides: [[f32; LANES]; 4],
    /// The point where the level crosses each of the eight edges (as
    /// [`Placement::along`] of
    /// [`Subgrid::crossing_inside`](super::subgrid::Subgrid::crossing_inside)).
    px: [[f32; LANES]; 8],
    py: [[f32; LANES]; 8],
    /// Direction code, and the nodes below the level in bits 8 to 12; bit
    /// 15 when the cell takes its program (finite, not constant, the level
    /// in its range and at none of its nodes).
    key: [u16; LANES],
}

impl Batch {
    pub(crate) const fn new() -> Self {
        Self {
            n: 0,
            idx: [0; LANES],
            v: [[0.0; LANES]; 5],
            sides: [[0.0; LANES]; 4],
            px: [[0.0; LANES]; 8],
            py: [[0.0; LANES]; 8],
            key: [0; LANES],
        }
    }

    /// A block's busy cells (the zero bytes of `m[..n]`, [`each_busy`]),
    /// each with its corners LL, LR, UR, UL and placement as `cell(k)`
    /// gives them (none: left out), worked out at `level` ([`Batch::solve`]).
    #[inline(always)]
    pub(crate) fn gather(
        &mut self,
        m: &Classes,
        n: usize,
        level: f32,
        cell: impl Fn(usize) -> Option<([f32; 4], Placement)>,
    ) {
        self.n = 0;
        let _ = each_busy::<()>(m, n, |k| {
            if let Some((corners, at)) = cell(k) {
                self.push(k, corners, at);
            }
            Ok(())
        });
        self.solve(level);
    }

    /// Add cell `k` (below `BLOCK`) with corners LL, LR, UR, UL, placed at
    /// `at`.
    #[inline(always)]
    fn push(&mut self, k: usize, [a, b, c, d]: [f32; 4], at: Placement) {
        let i = self.n;
        let [v0, v1, v2, v3, _] = &mut self.v;
        let [x0, x1, y0, y1] = &mut self.sides;
        let ([sx0, sx1], [sy0, sy1]) = at.sides();
        if let (Some(x), Some(va), Some(vb), Some(vc), Some(vd)) =
            (self.idx.get_mut(i), v0.get_mut(i), v1.get_mut(i), v2.get_mut(i), v3.get_mut(i))
            && let (Some(ox0), Some(ox1), Some(oy0), Some(oy1)) =
                (x0.get_mut(i), x1.get_mut(i), y0.get_mut(i), y1.get_mut(i))
        {
            *x = k as u8;
            (*va, *vb, *vc, *vd) = (a, b, c, d);
            (*ox0, *ox1, *oy0, *oy1) = (sx0, sx1, sy0, sy1);
            self.n = i + 1;
        }
    }

    /// Work out every cell's centre, key and crossings at `level`.
    #[inline(always)]
    fn solve(&mut self, level: f32) {
        let n = self.n.min(LANES);
        let [va, vb, vc, vd, ve] = &mut self.v;
        let cells = first(va, n).iter().zip(first(vb, n)).zip(first(vc, n)).zip(first(vd, n));
        let outs = first_mut(ve, n).iter_mut().zip(first_mut(&mut self.key, n));
        // Whether some cell that takes its program has a spread `hi - lo`
        // that is not finite. Only then may one of its edges' differences
        // `level - va` and `vb - va` overflow: its nodes and (taking its
        // program) the level lie within its range, so each difference is
        // at most the spread, and rounding keeps that order. The other
        // cells' crossings are never read.
        let mut wide = 0u32;
        for ((((a, b), c), d), (e, key)) in cells.zip(outs) {
            let (a, b, c, d) = (*a, *b, *c, *d);
            // As `Subgrid::from_finite`.
            let ctr = (a * 0.25 + b * 0.25) + (c * 0.25 + d * 0.25);
            let lo = min2(min2(a, b), min2(c, d));
            let hi = max2(max2(a, b), max2(c, d));
            let m = min2(max2(ctr, lo), hi);
            *e = m;
            // As `Subgrid::code` and `Subgrid::below`.
            let code = u16::from(a >= b)
                | (u16::from(b >= c) << 1)
                | (u16::from(c >= d) << 2)
                | (u16::from(d >= a) << 3)
                | (u16::from(a >= m) << 4)
                | (u16::from(b >= m) << 5)
                | (u16::from(c >= m) << 6)
                | (u16::from(d >= m) << 7);
            let below = u16::from(a <= level)
                | (u16::from(b <= level) << 1)
                | (u16::from(c <= level) << 2)
                | (u16::from(d <= level) << 3)
                | (u16::from(m <= level) << 4);
            let on = (a == level) | (b == level) | (c == level) | (d == level) | (m == level);
            let finite = a.is_finite() & b.is_finite() & c.is_finite() & d.is_finite();
            let fast = finite & !on & (lo != hi) & (lo <= level) & (level <= hi);
            *key = code | (below << 8) | (u16::from(fast) << 15);
            wide |= not_finite(if fast { hi - lo } else { 0.0 });
        }
        // Each edge's crossings, an edge a loop: the canonical ends (see
        // `Edge::canonical`), B0 to B3 then the spokes S0 to S3.
        let (v, s) = (&self.v, &self.sides);
        let [px0, px1, px2, px3, px4, px5, px6, px7] = &mut self.px;
        let [py0, py1, py2, py3, py4, py5, py6, py7] = &mut self.py;
        let [a, b, c, d, e] = v;
        let wide = wide != 0;
        edge::<0>(a, b, s, level, px0, py0, n, wide);
        edge::<1>(b, c, s, level, px1, py1, n, wide);
        edge::<2>(d, c, s, level, px2, py2, n, wide);
        edge::<3>(a, d, s, level, px3, py3, n, wide);
        edge::<4>(a, e, s, level, px4, py4, n, wide);
        edge::<5>(b, e, s, level, px5, py5, n, wide);
        edge::<6>(c, e, s, level, px6, py6, n, wide);
        edge::<7>(d, e, s, level, px7, py7, n, wide);
    }

    /// The busy cells in order: their place in the batch and the block,
    /// corners, and the program to draw when the batch settled it.
    #[inline(always)]
    pub(crate) fn each<E>(
        &self,
        mut f: impl FnMut(usize, usize, [f32; 4], Option<compiled::Program>) -> Result<(), E>,
    ) -> Result<(), E> {
        let n = self.n.min(LANES);
        let [v0, v1, v2, v3, _] = &self.v;
        for i in 0..n {
            let (Some(&k), Some(&a), Some(&b), Some(&c), Some(&d), Some(&key)) =
                (self.idx.get(i), v0.get(i), v1.get(i), v2.get(i), v3.get(i), self.key.get(i))
            else {
                break;
            };
            let program = if key & FAST != 0 {
                compiled::program(DirectionCode(key as u8), (key >> 8) as u8 & 31)
            } else {
                None
            };
            f(i, usize::from(k), [a, b, c, d], program)?;
        }
        Ok(())
    }

    /// Draw busy cell `i`'s `program`, at level 0 of one: as
    /// [`contour_subgrid`](super::contour_subgrid) draws it.
    #[inline(always)]
    pub(crate) fn draw<P, S: CommandSink<P>>(
        &self,
        i: usize,
        program: compiled::Program,
        place: &impl Fn(f32, f32) -> P,
        sink: &mut S,
        stats: &mut ContourStats,
    ) -> Result<(), S::Error> {
        let mut sent = 0u64;
        let point =
            |e: usize| match (self.px.get(e).and_then(|r| r.get(i)), self.py.get(e).and_then(|r| r.get(i))) {
                (Some(&x), Some(&y)) => Some((x, y)),
                _ => None,
            };
        draw_program(program, point, |c| {
            sent += 1;
            sink.command(0, c.map(|(x, y)| place(x, y)))
        })?;
        stats.crossing_cells += u64::from(sent > 0);
        stats.commands += sent;
        Ok(())
    }
}

/// The crossings of edge `E` (its ends' values `from` and `to` in its
/// canonical order) of the first `n` cells, placed by their `sides`. Where
/// a difference of two values may not be finite (`wide`: values near the
/// ends of the `f32` range), the edge as `crossing_inside` halves it.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn edge<const E: usize>(
    from: &[f32; LANES],
    to: &[f32; LANES],
    [x0, x1, y0, y1]: &[[f32; LANES]; 4],
    level: f32,
    px: &mut [f32; LANES],
    py: &mut [f32; LANES],
    n: usize,
    wide: bool,
) {
    let ends = first(from, n).iter().zip(first(to, n));
    let sides = first(x0, n).iter().zip(first(x1, n)).zip(first(y0, n)).zip(first(y1, n));
    let cells = ends.zip(sides).zip(first_mut(px, n)).zip(first_mut(py, n).iter_mut());
    if wide {
        for ((((va, vb), (((x0, x1), y0), y1)), ox), oy) in cells {
            (*ox, *oy) = along_in([*x0, *x1], [*y0, *y1], E, frac(*va, *vb, level));
        }
    } else {
        for ((((va, vb), (((x0, x1), y0), y1)), ox), oy) in cells {
            (*ox, *oy) = along_in([*x0, *x1], [*y0, *y1], E, clamp((level - *va) / (*vb - *va)));
        }
    }
}

impl Sweep<'_> {
    /// Whether this sweep takes the batch: one level, the compiled
    /// traversal, a target with vectors ([`VECTORS`]).
    #[inline(always)]
    pub(crate) fn batched(&self) -> bool {
        VECTORS && self.levels.len() == 1 && self.traversal == super::trace::Traversal::Compiled
    }

    /// The level of a batched sweep (its one level).
    #[inline(always)]
    pub(crate) fn level(&self) -> f32 {
        self.levels.first().copied().unwrap_or(0.0)
    }
}

/// The first `n` of a batch's values and those up to a whole eight (at
/// most [`LANES`]): slices whose lengths the compiler sees, so that the
/// loops over them vectorise, and whole vectors' worth, so that only the
/// vector body runs. The lanes past `n` hold earlier cells' values (any
/// `f32`), worked out and never read. Run for the last `n % 8` cells, the
/// loops' scalar tails doubled the busy path's code and, in callgrind's
/// model of this machine's caches, missed the instruction cache 1.9
/// million times contouring `gyroid:128` (10 thousand since).
#[inline(always)]
fn first<T>(a: &[T; LANES], n: usize) -> &[T] {
    a.get(..n.next_multiple_of(8).min(LANES)).unwrap_or_default()
}

/// [`first`], to write.
#[inline(always)]
fn first_mut<T>(a: &mut [T; LANES], n: usize) -> &mut [T] {
    a.get_mut(..n.next_multiple_of(8).min(LANES)).unwrap_or_default()
}

/// The smaller of two values (as `Subgrid`'s, a select).
#[inline(always)]
fn min2(a: f32, b: f32) -> f32 {
    if a < b { a } else { b }
}

/// The larger of two values.
#[inline(always)]
fn max2(a: f32, b: f32) -> f32 {
    if a > b { a } else { b }
}

/// [`Subgrid::crossing_inside`](super::subgrid::Subgrid::crossing_inside)
/// of the edge from `va` to `vb`, branch-free.
#[inline(always)]
fn frac(va: f32, vb: f32, level: f32) -> f32 {
    let (n1, d1) = (level - va, vb - va);
    let wide = !(n1.is_finite() & d1.is_finite());
    let (n2, d2) = (level * 0.5 - va * 0.5, vb * 0.5 - va * 0.5);
    let (num, den) = if wide { (n2, d2) } else { (n1, d1) };
    clamp(num / den)
}

/// Not zero when `d` is not finite: `d - d` is +0.0 for a finite `d`,
/// else NaN. Branch-free, for an OR over a loop that vectorises.
#[inline(always)]
#[allow(clippy::eq_op)]
fn not_finite(d: f32) -> u32 {
    (d - d).to_bits()
}

/// `t` clamped to `[0, 1]`, NaN to 0.
#[inline(always)]
fn clamp(t: f32) -> f32 {
    let t = if t >= 0.0 { t } else { 0.0 };
    if t <= 1.0 { t } else { 1.0 }
}
