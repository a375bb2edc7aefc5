//! The slab: the cells of all three planes between two x-y slices, one row
//! of cells at a time, each sample classed once for all of them.
//!
//! Row `y` of the slab between slices `z` and `z + 1` reads four rows of
//! samples, contiguous in x: `(y, z)`, `(y + 1, z)`, `(y, z + 1)` and
//! `(y + 1, z + 1)`. From their classes ([`super::sweep`]) it finds the
//! cells no level meets in all three planes at once: the x-y cells of row
//! `y` of slice `z`, the x-z cells of row `z` of slice `y`, and the y-z
//! cells `(y, z)` of every slice `x`. Rows `y + 1` of one call are rows `y`
//! of the next, so their classes are kept: a sample is classed twice a
//! volume (once in each slab it belongs to), not five times.
//!
//! A whole volume in memory ([`super::surface::contour_slab`]) and the
//! engine's two slices as they arrive over the link
//! ([`crate::engine`]'s stream) are both contoured by [`Slab::row`]; they
//! differ only in where the samples come from ([`Rows`]).

use super::ContourStats;
use super::batch::Batch;
use super::grid::Plane;
use super::pen::Placement;
use super::surface::{SliceId, SurfaceSink};
use super::sweep::{BLOCK, Classes, Sweep, and_across, each_busy, quiet_bits};
use super::trace::Traversal;
use crate::command::{Command, CommandSink, Point3};

/// Samples in a lane: a block's cells and one.
pub(crate) const LANE: usize = BLOCK + 1;

/// One lane of samples, widened to `f32` (see [`Rows::lanes`]).
pub(crate) type Lane = [f32; LANE];

/// Where a slab row's samples come from: the four rows around cell row
/// `y` (see the module), as `f32`.
pub(crate) trait Rows {
    /// Whether the source widens into the lanes and takes the ones it
    /// filled before (then the slab keeps track of what each holds).
    const KEEPS: bool;

    /// Samples `x0..x0 + n` (`n` at most [`LANE`]) of the rows `(y, z)`,
    /// `(y + 1, z)`, `(y, z + 1)`, `(y + 1, z + 1)`, those `need`ed (the
    /// others may be empty): borrowed where they already are `f32`s,
    /// otherwise widened into `bufs`. For a source that [`Rows::KEEPS`]
    /// its lanes, a row needed but not to `fill` is in its buffer already
    /// (an earlier call widened it there); for others `fill` is `need`.
    fn lanes<'b>(
        &'b self,
        x0: usize,
        n: usize,
        need: [bool; 4],
        fill: [bool; 4],
        bufs: [&'b mut Lane; 4],
    ) -> [&'b [f32]; 4];
}

/// The planes a slab row contours, and which y-z slices.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Cut {
    /// The x-y cells of row `y` of slice `z`.
    pub xy: bool,
    /// The x-z cells of row `z` of slice `y`.
    pub xz: bool,
    /// The y-z cells `(y, z)` of the slices `x = first, first + step, ...`
    /// (none when `step` is 0).
    pub yz: Every,
}

impl Cut {
    /// The planes that have cells in a row: the x-y cells need the row
    /// `y + 1` (`right`), the x-z cells the slice `z + 1` (`up`), the y-z
    /// cells both.
    pub(crate) fn within(self, right: bool, up: bool) -> Cut {
        Cut { xy: self.xy && right, xz: self.xz && up, yz: if right && up { self.yz } else { Every::NONE } }
    }

    /// Whether no cell is cut.
    pub(crate) fn is_empty(self) -> bool {
        !(self.xy || self.xz || self.yz.step != 0)
    }
}

/// Slices `first, first + step, first + 2 step, ...`; none when `step` is 0.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Every {
    pub first: usize,
    pub step: usize,
}

impl Every {
    /// Every slice.
    pub const ALL: Every = Every { first: 0, step: 1 };
    /// No slice.
    pub const NONE: Every = Every { first: 0, step: 0 };

    /// How many of the slices `0..n` are taken.
    fn count(self, n: usize) -> usize {
        if self.step == 0 || self.first >= n { 0 } else { (n - self.first).div_ceil(self.step) }
    }
}

/// Which samples a row of classes or a lane holds: the block's first `x`,
/// and the row's index in the volume (`z * ny + y`), each plus one
/// ([`NOTHING`]: none yet; so that memory that holds nothing is all
/// zeros, and a board's `static` of it needs no initial bytes in flash).
/// Only rows of the volume are ever marked held, so a row named past its
/// end (the `y + 1` of its last row) is never taken for one.
type Tag = [usize; 2];

/// The tag of a row that holds nothing yet.
const NOTHING: Tag = [0; 2];

/// Whether two tags name the same row (word by word: the MCU's array
/// compare is a call to `memcmp`).
#[inline(always)]
fn same([a0, a1]: Tag, [b0, b1]: Tag) -> bool {
    (a0 == b0) & (a1 == b1)
}

/// Four rows (of classes, or of samples) that move down a slab row by row:
/// the rows `(y + 1, ..)` of one row are the rows `(y, ..)` of the next, so
/// each pair trades places by a flag, not a copy.
#[derive(Debug)]
struct Four<T> {
    rows: [T; 4],
    /// What each place holds.
    tags: [Tag; 4],
    /// Whether the rows of each pair (places `0, 1` and `2, 3`) are stored
    /// the other way round.
    flip: [bool; 2],
}

impl<T> Four<T> {
    const fn new(rows: [T; 4]) -> Self {
        Self { rows, tags: [NOTHING; 4], flip: [false; 2] }
    }

    /// Bring the rows wanted where the other place of their pair holds
    /// them (the last row's `y + 1`, wanted as this one's `y`) to their
    /// places; returns which places hold what they should.
    #[inline(always)]
    fn settle(&mut self, want: [Tag; 4]) -> [bool; 4] {
        let [t0, t1, t2, t3] = &mut self.tags;
        let [f0, f1] = &mut self.flip;
        let [w0, w1, w2, w3] = want;
        for (lo, hi, flip, w) in [(&mut *t0, &mut *t1, f0, w0), (&mut *t2, &mut *t3, f1, w2)] {
            if !same(*lo, w) && same(*hi, w) {
                core::mem::swap(lo, hi);
                *flip = !*flip;
            }
        }
        [same(*t0, w0), same(*t1, w1), same(*t2, w2), same(*t3, w3)]
    }

    /// Say that the places `on` now hold what `want` names.
    #[inline(always)]
    fn mark(&mut self, on: [bool; 4], want: [Tag; 4]) {
        for ((t, on), w) in self.tags.iter_mut().zip(on).zip(want) {
            if on {
                *t = w;
            }
        }
    }

    /// Settle the rows `want`ed and say that the places `on` hold them;
    /// returns those of `on` that did not hold them already (to be filled).
    #[inline(always)]
    fn bring(&mut self, on: [bool; 4], want: [Tag; 4]) -> [bool; 4] {
        let held = self.settle(want);
        self.mark(on, want);
        and_not(on, held)
    }

    /// Forget what every place holds.
    fn forget(&mut self) {
        self.tags = [NOTHING; 4];
    }

    /// The rows, in their places.
    #[inline(always)]
    fn places(&mut self) -> [&mut T; 4] {
        let [a, b, c, d] = &mut self.rows;
        let [f0, f1] = self.flip;
        let (p0, p1) = if f0 { (b, a) } else { (a, b) };
        let (p2, p3) = if f1 { (d, c) } else { (c, d) };
        [p0, p1, p2, p3]
    }
}

/// What a slab contourer keeps from one call to the next: the lanes of
/// the four rows around a slab row (one set: a source that widens samples
/// widens each once a slab when its rows are one block), the classes of
/// the first `SETS` blocks of them (the first `SETS - 1` blocks keep
/// theirs, rows of up to `(SETS - 1) * BLOCK + 1` samples; later blocks
/// share the last set, classed anew), the cells' AND, the busy cells'
/// batch, and what the rows of the last two x-y slices share ([`Quiet`],
/// `ROWS` rows a slice). About `2.2 KB + SETS * 0.55 KB + 2 * ROWS` where
/// the batch holds one cell (the MCU). At least one set (checked when it
/// is built).
#[derive(Debug)]
pub(crate) struct SlabMemory<const SETS: usize, const ROWS: usize> {
    lanes: Four<Lane>,
    m: Classes,
    batch: Batch,
    held: [Four<Classes>; SETS],
    quiet: Quiet<ROWS>,
}

impl<const SETS: usize, const ROWS: usize> SlabMemory<SETS, ROWS> {
    /// Memory that holds nothing yet.
    pub(crate) const fn new() -> Self {
        const { assert!(SETS > 0, "a slab keeps at least one set of classes") };
        Self {
            lanes: Four::new([[0.0; LANE]; 4]),
            m: [0; BLOCK + 9],
            batch: Batch::new(),
            held: [const { Four::new([[0; BLOCK + 9]; 4]) }; SETS],
            quiet: Quiet::new(),
        }
    }

    /// Forget what the rows held: their samples are about to change (a new
    /// volume, or new levels).
    pub(crate) fn forget(&mut self) {
        self.lanes.forget();
        for h in &mut self.held {
            h.forget();
        }
        self.quiet.forget();
    }
}

/// The class bits that every sample of a block of a row shares
/// ([`quiet_bits`]), for the rows of the last two x-y slices that slabs
/// classed as their upper rows: the next slab's lower rows. A slab row
/// whose four rows share a class bit draws nothing, so a lower row known
/// this way is neither classed nor widened again unless a level meets
/// the slab row: a sample of a quiet stretch of the volume is classed once,
/// not twice (once in each slab it belongs to).
///
/// An array of `ROWS` bytes for each slice parity, entry `block * ny + y`
/// ([`KNOWN`] set where written); rows past `ROWS` are classed twice, as
/// without it.
#[derive(Debug)]
struct Quiet<const ROWS: usize> {
    bits: [[u8; ROWS]; 2],
    /// The slice each array describes, plus one (0: none, so that memory
    /// holding nothing is all zeros).
    slice: [usize; 2],
}

/// An entry of [`Quiet`] that was written.
const KNOWN: u8 = 0x80;

impl<const ROWS: usize> Quiet<ROWS> {
    const fn new() -> Self {
        Self { bits: [[0; ROWS]; 2], slice: [0; 2] }
    }

    /// The bits that entry `i` of slice `z` shares, if known.
    #[inline(always)]
    fn get(&self, z: usize, i: usize) -> Option<u8> {
        let p = z & 1;
        if self.slice.get(p) != Some(&(z + 1)) {
            return None;
        }
        let b = *self.bits.get(p)?.get(i)?;
        (b & KNOWN != 0).then_some(b & !KNOWN)
    }

    /// Say that entry `i` of slice `z` shares `bits`.
    #[inline(always)]
    fn set(&mut self, z: usize, i: usize, bits: u8) {
        let p = z & 1;
        let (Some(arr), Some(slice)) = (self.bits.get_mut(p), self.slice.get_mut(p)) else { return };
        if *slice != z + 1 {
            arr.fill(0);
            *slice = z + 1;
        }
        if let Some(b) = arr.get_mut(i) {
            *b = bits | KNOWN;
        }
    }

    fn forget(&mut self) {
        self.slice = [0; 2];
    }
}

/// A slab contourer: levels and traversal, over its memory.
#[derive(Debug)]
pub(crate) struct Slab<'l, 'm, const SETS: usize, const ROWS: usize> {
    sweep: Sweep<'l>,
    mem: &'m mut SlabMemory<SETS, ROWS>,
}

impl<'l, 'm, const SETS: usize, const ROWS: usize> Slab<'l, 'm, SETS, ROWS> {
    /// A slab over finite `levels` (checked by the caller), in `mem`,
    /// which holds what earlier calls on the same samples and levels left
    /// (or was forgotten, [`SlabMemory::forget`]).
    pub(crate) fn new(levels: &'l [f32], traversal: Traversal, mem: &'m mut SlabMemory<SETS, ROWS>) -> Self {
        Self { sweep: Sweep::new(levels, traversal), mem }
    }

    /// Contour row `y` of the slab between slices `z` and `z + 1` (`up`:
    /// whether slice `z + 1` exists) of a volume `nx` by `ny`, the planes
    /// of `cut`, from the samples of `rows`. Within each slice, commands
    /// come in row-major cell order; across slices they interleave (x-y,
    /// then x-z, then the y-z slices in x order, block by block). The
    /// cells of the planes cut are counted in `stats`.
    ///
    /// Rows that an earlier call classed (or widened) and kept, for the
    /// same `z` and `y` or as its rows `y + 1` for the row before, are not
    /// classed (or widened) again: so a row may be cut plane by plane in
    /// several calls at the cost of one. The caller vouches that `rows`
    /// holds the same samples for them (other samples may give wrong
    /// commands, though nothing panics).
    ///
    /// # Errors
    /// The sink's error.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn row<R: Rows, S: SurfaceSink>(
        &mut self,
        rows: &R,
        [nx, ny]: [usize; 2],
        y: usize,
        z: usize,
        up: bool,
        cut: Cut,
        sink: &mut S,
        stats: &mut ContourStats,
    ) -> Result<(), S::Error> {
        let cut = cut.within(y + 1 < ny, up);
        let Cut { xy, xz, yz } = cut;
        stats.cells += (u64::from(xy) + u64::from(xz)) * nx.saturating_sub(1) as u64 + yz.count(nx) as u64;
        if cut.is_empty() {
            return Ok(());
        }
        let (l1_in, h0_in, h1_in) = (xy || yz.step != 0, xz || yz.step != 0, yz.step != 0);
        let need = [true, l1_in, h0_in, h1_in];
        let sweep = self.sweep;
        let fz = z as f32;
        let mut x0 = 0;
        let mut block = 0;
        while x0 < nx {
            // Samples x0..=x1 (cells x0..x1 of x-y and x-z rows; y-z
            // slices x0..x1, the last block's up to nx).
            let x1 = (x0 + BLOCK).min(nx - 1);
            let n = x1 + 1 - x0;
            let ys = if x1 + 1 == nx { n } else { n - 1 };
            let set = block.min(SETS - 1);
            // This block's entries of the slices' quiet rows.
            let (at_y, at_y1) = (block * ny + y, block * ny + y + 1);
            block += 1;
            let mem = &mut *self.mem;
            let Some(held) = mem.held.get_mut(set) else { break };
            let (r, up_r) = (z * ny + y + 1, (z + 1) * ny + y + 1);
            let want = [[x0 + 1, r], [x0 + 1, r + 1], [x0 + 1, up_r], [x0 + 1, up_r + 1]];
            let classed = held.settle(want);
            // The lower rows that the slab below classed as its upper rows
            // and found quiet need neither lanes nor classes unless this
            // row turns out busy (`lazy`); the others are brought `now`.
            let known = [
                if classed[0] { None } else { mem.quiet.get(z, at_y) },
                if l1_in && !classed[1] { mem.quiet.get(z, at_y1) } else { None },
            ];
            let lazy = [known[0].is_some(), known[1].is_some(), false, false];
            let now = and_not(need, lazy);
            // Lanes to fill: those brought now that a source keeping its
            // lanes does not have (every one needed, for a source that
            // borrows).
            let (first, fill) = if R::KEEPS { (now, mem.lanes.bring(now, want)) } else { (need, need) };
            let lanes = rows.lanes(x0, n, first, fill, mem.lanes.places());
            classify_rows(sweep, lanes, held.places(), and_not(now, classed));
            held.mark(now, want);
            let [c0, c1, c2, c3] = held.places();
            let q2 = if h0_in { quiet_bits(c2, n) } else { !0 };
            let q3 = if h1_in { quiet_bits(c3, n) } else { !0 };
            if h0_in {
                mem.quiet.set(z + 1, at_y, q2);
            }
            if h1_in {
                mem.quiet.set(z + 1, at_y1, q3);
            }
            // A block whose samples share a class meets no level in any
            // plane: nothing to scan (the skip path's common case).
            let shared = known[0].unwrap_or_else(|| quiet_bits(c0, n))
                & (if l1_in { known[1].unwrap_or_else(|| quiet_bits(c1, n)) } else { !0 })
                & q2
                & q3;
            if shared == 0 {
                // Busy: the lower rows left lazy are wanted after all.
                let lazy_any = lazy[0] || lazy[1];
                let lanes = if R::KEEPS && lazy_any {
                    let fill = mem.lanes.bring(lazy, want);
                    rows.lanes(x0, n, need, fill, mem.lanes.places())
                } else {
                    lanes
                };
                if lazy_any {
                    classify_rows(sweep, lanes, held.places(), lazy);
                    held.mark(lazy, want);
                }
                let [l0, l1, h0, h1] = lanes;
                let [c0, c1, c2, c3] = held.places();
                let (c0, c1, c2, c3) = (&*c0, &*c1, &*c2, &*c3);
                let (m, batch) = (&mut mem.m, &mut mem.batch);
                if xy {
                    let place = |_, u, v| Plane::XY.to_voxel(fz, u, v);
                    let mut to =
                        SliceSink { sink: &mut *sink, slice: SliceId { plane: Plane::XY, index: z } };
                    let at = |k| Placement::new(x0 + k, y);
                    sweep.run_classed(l0, l1, [c0, c1], m, batch, at, place, &mut to, stats)?;
                }
                if xz {
                    let fy = y as f32;
                    let place = |_, u, v| Plane::XZ.to_voxel(fy, u, v);
                    let mut to =
                        SliceSink { sink: &mut *sink, slice: SliceId { plane: Plane::XZ, index: y } };
                    let at = |k| Placement::new(x0 + k, z);
                    sweep.run_classed(l0, h0, [c0, c2], m, batch, at, place, &mut to, stats)?;
                }
                if yz.step != 0 {
                    draw_yz(
                        sweep,
                        [l0, l1, h0, h1],
                        [c0, c1, c2, c3],
                        m,
                        batch,
                        [x0, ys, y, z],
                        yz,
                        sink,
                        stats,
                    )?;
                }
            }
            x0 = if x1 + 1 == nx { nx } else { x1 };
        }
        Ok(())
    }
}

/// The y-z cells of a busy block of a slab row (see [`Slab::row`]): the
/// four rows' samples and classes, `m` and `batch` scratch, the block's
/// first sample `x0` and its `ys` cells, the row `y` of the slab `z`. A
/// call, as the x-y and x-z rows' [`Sweep::run_classed`] is: inlined into
/// the row, what they set up before the row's loop cost every row, most
/// of them quiet.
#[inline(never)]
#[allow(clippy::too_many_arguments)]
fn draw_yz<S: SurfaceSink>(
    sweep: Sweep<'_>,
    [l0, l1, h0, h1]: [&[f32]; 4],
    [c0, c1, c2, c3]: [&Classes; 4],
    m: &mut Classes,
    batch: &mut Batch,
    [x0, ys, y, z]: [usize; 4],
    yz: Every,
    sink: &mut S,
    stats: &mut ContourStats,
) -> Result<(), S::Error> {
    across_taken(m, [c0, c1, c2, c3], ys, x0, yz);
    // Cell `k` lies in the y-z slice at x0 + k, with
    // corners (y, z), (y + 1, z), (y + 1, z + 1), (y, z + 1).
    let at = Placement::new(y, z);
    let corners = |k: usize| match (l0.get(k), l1.get(k), h1.get(k), h0.get(k)) {
        (Some(&a), Some(&b), Some(&c), Some(&d)) => Some([a, b, c, d]),
        _ => None,
    };
    let slice = |k: usize| SliceId { plane: Plane::YZ, index: x0 + k };
    let place = |k: usize| {
        let fx = (x0 + k) as f32;
        move |u, v| Plane::YZ.to_voxel(fx, u, v)
    };
    if sweep.batched() {
        batch.gather(m, ys, sweep.level(), |k| Some((corners(k)?, at)));
        batch.each(|i, k, corners, program| {
            let to = &mut SliceSink { sink: &mut *sink, slice: slice(k) };
            match program {
                Some(p) => batch.draw(i, p, &place(k), to, stats),
                None => sweep.cell_aside(corners, at, &place(k), to, stats),
            }
        })?;
    } else {
        // The corners' classes, in the corners' order.
        let classes = |k: usize| match (c0.get(k), c1.get(k), c3.get(k), c2.get(k)) {
            (Some(&a), Some(&b), Some(&c), Some(&d)) => [a, b, c, d],
            _ => [0; 4],
        };
        // The classes help at one level only: the loop is chosen once.
        if sweep.classed() {
            each_busy(m, ys, |k| match corners(k) {
                Some(c) => {
                    let to = &mut SliceSink { sink: &mut *sink, slice: slice(k) };
                    sweep.cell_classed(c, classes(k), at, &place(k), to, stats)
                }
                None => Ok(()),
            })?;
        } else {
            each_busy(m, ys, |k| match corners(k) {
                Some(c) => {
                    let to = &mut SliceSink { sink: &mut *sink, slice: slice(k) };
                    sweep.cell(c, at, &place(k), to, stats)
                }
                None => Ok(()),
            })?;
        }
    }
    Ok(())
}

/// The classes of the rows `on` of `rows` into their places.
#[inline(always)]
fn classify_rows(sweep: Sweep<'_>, rows: [&[f32]; 4], classes: [&mut Classes; 4], on: [bool; 4]) {
    for ((row, c), on) in rows.into_iter().zip(classes).zip(on) {
        if on {
            sweep.classify(row, c);
        }
    }
}

/// `a` and not `b`, place by place.
#[inline(always)]
fn and_not([a0, a1, a2, a3]: [bool; 4], [b0, b1, b2, b3]: [bool; 4]) -> [bool; 4] {
    [a0 && !b0, a1 && !b1, a2 && !b2, a3 && !b3]
}

/// `m[k]` for the `n` y-z cells of slices `x0..x0 + n` with sample `k`'s
/// four rows of classes: their AND ([`and_across`]) where `every` takes
/// slice `x0 + k`, quiet elsewhere, so that nothing is drawn there. A
/// stride works out only the slices it takes: with every 16th, a row's
/// eight of 128 (the AND of all, then the rest marked quiet one by one,
/// was a tenth of a draft's build in the page).
#[inline(always)]
fn across_taken(m: &mut Classes, rows: [&Classes; 4], n: usize, x0: usize, every: Every) {
    if every == Every::ALL {
        and_across(m, rows, n);
        return;
    }
    let Some(cells) = m.get_mut(..n) else { return };
    cells.fill(super::sweep::ABOVE | super::sweep::BELOW);
    if every.step == 0 {
        return;
    }
    // The first slice taken at or after x0.
    let first = if x0 <= every.first {
        every.first - x0
    } else {
        (every.step - (x0 - every.first) % every.step) % every.step
    };
    let [a, b, c, d] = rows;
    for k in (first..n).step_by(every.step) {
        if let (Some(o), Some(&a), Some(&b), Some(&c), Some(&d)) =
            (cells.get_mut(k), a.get(k), b.get(k), c.get(k), d.get(k))
        {
            *o = a & b & c & d;
        }
    }
}

/// A [`SurfaceSink`] as the [`CommandSink`] of one slice.
pub(crate) struct SliceSink<'s, S> {
    pub sink: &'s mut S,
    pub slice: SliceId,
}

impl<S: SurfaceSink> CommandSink<Point3> for SliceSink<'_, S> {
    type Error = S::Error;
    #[inline(always)]
    fn command(&mut self, level: usize, command: Command<Point3>) -> Result<(), S::Error> {
        self.sink.command(self.slice, level, command)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contour::grid::{Planes, Volume};
    use crate::contour::surface::contour_volume;
    use crate::contour::surface::tests::Keep as Log;
    use proptest::prelude::*;

    /// A source that widens its samples into the lanes and keeps them, as
    /// the engine's does: `f32`s read through a copy, so a lane used
    /// without being filled shows.
    struct Widening<'v> {
        values: &'v [f32],
        nx: usize,
        ny: usize,
        y: usize,
        z: usize,
    }

    impl Rows for Widening<'_> {
        const KEEPS: bool = true;

        fn lanes<'b>(
            &'b self,
            x0: usize,
            n: usize,
            need: [bool; 4],
            fill: [bool; 4],
            bufs: [&'b mut Lane; 4],
        ) -> [&'b [f32]; 4] {
            let (y, z) = (self.y, self.z);
            let at = [(y, z), (y + 1, z), (y, z + 1), (y + 1, z + 1)];
            let mut k = 0;
            bufs.map(|buf| {
                let (on, fill, (ry, rz)) = (need[k], fill[k], at[k]);
                k += 1;
                let out = &mut buf[..if on { n } else { 0 }];
                if fill {
                    let start = (rz * self.ny + ry) * self.nx + x0;
                    for (o, i) in out.iter_mut().zip(start..) {
                        *o = self.values.get(i).copied().unwrap_or(f32::NAN);
                    }
                }
                &*out
            })
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(200))]
        /// A slab row cut into steps of any planes, its samples widened
        /// and kept in the lanes and classes from step to step (one set,
        /// as the engine's), draws within each slice exactly what the
        /// whole volume's contouring draws, in order, and counts the same;
        /// with every row whole, in the very order.
        #[test]
        fn rows_cut_into_any_steps_draw_the_whole_volume(
            (nx, ny, nz) in (1usize..=300, 1usize..=6, 1usize..=4),
            seed in any::<u64>(),
            levels in prop::collection::vec(prop::sample::select(vec![0.0f32, 0.5, -1.0, 1.5]), 1..3),
            steps in prop::collection::vec(prop::sample::select(vec![1u8, 2, 3]), 8),
        ) {
            let mut h = seed | 1;
            let values: Vec<f32> = (0..nx * ny * nz)
                .map(|_| {
                    h ^= h << 13;
                    h ^= h >> 7;
                    h ^= h << 17;
                    match h % 23 {
                        0 => f32::NAN,
                        1 => 0.5,
                        _ => (h % 4001) as f32 / 1000.0 - 2.0,
                    }
                })
                .collect();
            let volume = Volume::new(&values, nx, ny, nz).unwrap();
            let mut want = Log::default();
            let want_stats = contour_volume(&volume, Planes::ALL, &levels, Traversal::Compiled, &mut want).unwrap();
            let mut mem = SlabMemory::<1, 4>::new();
            let mut slab = Slab::new(&levels, Traversal::Compiled, &mut mem);
            let (mut got, mut stats) = (Log::default(), ContourStats::default());
            let mut k = 0;
            for z in 0..nz {
                for y in 0..ny {
                    let rows = Widening { values: &values, nx, ny, y, z };
                    let mut plane = 0;
                    while plane < 3 {
                        let end = (plane + steps[k % steps.len()]).min(3);
                        k += 1;
                        let cut = Cut {
                            xy: (plane..end).contains(&0),
                            xz: (plane..end).contains(&1),
                            yz: if (plane..end).contains(&2) { Every::ALL } else { Every::NONE },
                        };
                        slab.row(&rows, [nx, ny], y, z, z + 1 < nz, cut, &mut got, &mut stats).unwrap();
                        plane = end;
                    }
                }
            }
            prop_assert_eq!(stats, want_stats);
            if steps.iter().all(|&s| s == 3) {
                prop_assert_eq!(&got.0, &want.0);
            }
            got.0.sort_by_key(|&(slice, ..)| slice);
            want.0.sort_by_key(|&(slice, ..)| slice);
            prop_assert_eq!(got.0, want.0);
        }
    }

    #[test]
    fn every_counts_and_leaves_out_the_slices_it_does_not_take() {
        for step in 1..6 {
            for first in 0..7 {
                let every = Every { first, step };
                for nx in 0..40 {
                    let want = (0..nx).filter(|&x| x >= first && (x - first) % step == 0).count();
                    assert_eq!(every.count(nx), want, "{every:?}, nx {nx}");
                }
                for x0 in 0..20 {
                    // Four rows whose AND is zero at even samples only.
                    let row =
                        |bits: u8| -> Classes { core::array::from_fn(|k| if k % 2 == 0 { bits } else { 3 }) };
                    let rows = [row(1), row(2), row(3), row(3)];
                    let mut m: Classes = [7; BLOCK + 9];
                    across_taken(&mut m, [&rows[0], &rows[1], &rows[2], &rows[3]], 30, x0, every);
                    for (k, &c) in m[..30].iter().enumerate() {
                        let x = x0 + k;
                        let taken = x >= first && (x - first) % step == 0;
                        assert_eq!(c == 0, taken && k % 2 == 0, "{every:?}, x0 {x0}, k {k}");
                        assert!(c == 0 || c & 3 != 0, "a cell left out is quiet");
                    }
                    assert!(m[30..].iter().all(|&b| b == 7), "nothing past the cells");
                }
            }
        }
        assert_eq!(Every::NONE.count(10), 0);
    }
}
