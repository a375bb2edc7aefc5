//! The chicken-wire surface: contour every slice of a volume along any set
//! of planes, at one or many levels (Zyda, section 1).
//!
//! Points come out in voxel coordinates (x the fastest axis). A crossing on a
//! volume edge is bit-identical whichever slice (and subgrid) draws it, so the
//! x-y, x-z and y-z contours meet exactly.

use super::grid::{Plane, Planes, Volume};
use super::pen::Placement;
use super::sweep::{BLOCK, Scratch, Sweep, and_across, each_busy, lane, quiet_bits};
use super::trace::Traversal;
use super::voxel::Voxel;
use super::{ContourError, ContourStats, check_levels, contour_grid};
use crate::command::{Command, CommandSink, Point3};
use core::ops::Range;

/// One slice of a volume.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SliceId {
    /// The slicing plane.
    pub plane: Plane,
    /// The slice's index along the plane's normal axis.
    pub index: usize,
}

/// Receives the commands of a chicken-wire surface, with the slice they
/// belong to.
pub trait SurfaceSink {
    /// Why the sink could not take a command.
    type Error;

    /// Take one command of `slice` at level index `level`.
    ///
    /// # Errors
    /// Whatever the sink defines; contouring stops and hands it back.
    fn command(&mut self, slice: SliceId, level: usize, command: Command<Point3>) -> Result<(), Self::Error>;
}

impl<S: SurfaceSink + ?Sized> SurfaceSink for &mut S {
    type Error = S::Error;
    #[inline]
    fn command(&mut self, slice: SliceId, level: usize, command: Command<Point3>) -> Result<(), Self::Error> {
        (**self).command(slice, level, command)
    }
}

struct SliceSink<'s, S> {
    sink: &'s mut S,
    slice: SliceId,
}

impl<S: SurfaceSink> CommandSink<Point3> for SliceSink<'_, S> {
    type Error = S::Error;
    #[inline(always)]
    fn command(&mut self, level: usize, command: Command<Point3>) -> Result<(), S::Error> {
        self.sink.command(self.slice, level, command)
    }
}

/// Contour one slice of a volume at every level.
///
/// # Errors
/// [`ContourError::Grid`] for a slice index out of range,
/// [`ContourError::NonFiniteLevel`], or the sink's error.
pub fn contour_slice<T: Voxel, S: SurfaceSink>(
    volume: &Volume<'_, T>,
    slice: SliceId,
    levels: &[f32],
    traversal: Traversal,
    sink: &mut S,
) -> Result<ContourStats, ContourError<S::Error>> {
    let grid = volume.slice(slice.plane, slice.index).map_err(ContourError::Grid)?;
    let s = slice.index as f32;
    let plane = slice.plane;
    let mut adapter = SliceSink { sink, slice };
    contour_grid(&grid, levels, traversal, |u, v| plane.to_voxel(s, u, v), &mut adapter)
}

/// Blocks of a row whose classes [`contour_slab`] keeps from one row to
/// the next: rows of up to `HELD * BLOCK + 1` samples (1025) are classed
/// twice, not four times (9 x 4 x 137 bytes of stack: the slab is the
/// host's; the board contours row by row).
const HELD: usize = 8;

/// Contour the z-slab `zs` of every slice of `planes` at every level: the
/// x-y slices `z` and the x-z and y-z cell rows `z` (the cells between the
/// x-y slices `z` and `z + 1`) for `z` in `zs`, all three planes at once,
/// in memory order.
///
/// For each `z` and each row `y` it reads the four sample rows around it
/// (`y` and `y + 1` of slices `z` and `z + 1`), contiguous in x, classes
/// each sample once ([`super::sweep`]), and finds the cells no level meets
/// in all three planes from those classes: the x-y cells of row `y`, the
/// x-z cells of row `z` of slice `y`, and the y-z cells `(y, z)` of every
/// slice `x`. Within each slice commands come in row-major cell order,
/// exactly as [`contour_slice`] gives them, so splitting a volume into
/// slabs and joining each slice's commands slab by slab reproduces the
/// slice; across slices they interleave.
///
/// # Errors
/// [`ContourError::NonFiniteLevel`] before anything is drawn, or the sink's
/// error. Slices past the end are ignored.
pub fn contour_slab<T: Voxel, S: SurfaceSink>(
    volume: &Volume<'_, T>,
    planes: Planes,
    zs: Range<usize>,
    levels: &[f32],
    traversal: Traversal,
    sink: &mut S,
) -> Result<ContourStats, ContourError<S::Error>> {
    check_levels(levels)?;
    let (nx, ny, nz) = volume.dims();
    let zs = zs.start..zs.end.min(nz);
    let (xy, xz, yz) = (planes.contains(Plane::XY), planes.contains(Plane::XZ), planes.contains(Plane::YZ));
    let data = volume.data();
    let sweep = Sweep::new(levels, traversal);
    let mut stats = ContourStats::default();
    let mut scratch = Scratch::new();
    // The classes of the four rows of each of the first `HELD` blocks of a
    // row, kept from one `y` to the next: rows (y + 1, z) and (y + 1, z + 1)
    // of one `y` are rows (y, z) and (y, z + 1) of the next, so a sample is
    // classed twice a `z`, not four times. Later blocks (a row longer than
    // `HELD * BLOCK + 1` samples) share the last set and class every row.
    let mut held = [[[0u8; BLOCK + 9]; 4]; HELD + 1];
    let row = |y: usize, z: usize| (z * ny + y) * nx;
    // The needed rows of a block, beside (y, z): (y + 1, z) for the x-y or
    // y-z cells, (y, z + 1) for the x-z or y-z cells, (y + 1, z + 1) for
    // the y-z cells.
    let (need_l1, need_h0) = (xy || yz, xz || yz);
    for z in zs.clone() {
        let up = z + 1 < nz;
        let fz = z as f32;
        // The `y` whose rows (y, z) and (y, z + 1) each held set has
        // classed (none yet this `z`).
        let mut held_for = [[usize::MAX; 2]; HELD + 1];
        for y in 0..ny {
            let right = y + 1 < ny;
            let (l1_in, h0_in, h1_in) = (right && need_l1, up && need_h0, right && up && yz);
            let mut x0 = 0;
            let mut block = 0;
            while x0 < nx {
                // Samples x0..=x1 (cells x0..x1 of x-y and x-z rows; y-z
                // slices x0..x1, the last block's up to nx).
                let x1 = (x0 + BLOCK).min(nx - 1);
                let n = x1 + 1 - x0;
                let ys = if x1 + 1 == nx { n } else { n - 1 };
                let slot = block.min(HELD);
                block += 1;
                let (Some([c0, c1, c2, c3]), Some(classed)) = (held.get_mut(slot), held_for.get_mut(slot))
                else {
                    break;
                };
                let [b0, b1, b2, b3] = &mut scratch.bufs;
                let [m, ..] = &mut scratch.classes;
                // Rows (y, z), (y + 1, z), (y, z + 1), (y + 1, z + 1).
                let l0 = lane(data, row(y, z) + x0, 1, n, b0);
                let l1 = if l1_in { lane(data, row(y + 1, z) + x0, 1, n, b1) } else { &[] };
                let h0 = if h0_in { lane(data, row(y, z + 1) + x0, 1, n, b2) } else { &[] };
                let h1 = if h1_in { lane(data, row(y + 1, z + 1) + x0, 1, n, b3) } else { &[] };
                if classed[0] != y {
                    sweep.classify(l0, c0);
                }
                if l1_in {
                    sweep.classify(l1, c1);
                }
                if h0_in && classed[1] != y {
                    sweep.classify(h0, c2);
                }
                if h1_in {
                    sweep.classify(h1, c3);
                }
                // A block whose samples share a class meets no level in any
                // plane: nothing to scan (the skip path's common case).
                let shared = quiet_bits(c0, n)
                    & (if l1_in { quiet_bits(c1, n) } else { !0 })
                    & (if h0_in { quiet_bits(c2, n) } else { !0 })
                    & (if h1_in { quiet_bits(c3, n) } else { !0 });
                if shared == 0 {
                    if xy && right {
                        let place = |_, u, v| Plane::XY.to_voxel(fz, u, v);
                        let mut to =
                            SliceSink { sink: &mut *sink, slice: SliceId { plane: Plane::XY, index: z } };
                        sweep
                            .run_classed(
                                l0,
                                l1,
                                [c0, c1],
                                m,
                                &mut scratch.batch,
                                |k| Placement::new(x0 + k, y),
                                place,
                                &mut to,
                                &mut stats,
                            )
                            .map_err(ContourError::Sink)?;
                    }
                    if xz && up {
                        let fy = y as f32;
                        let place = |_, u, v| Plane::XZ.to_voxel(fy, u, v);
                        let mut to =
                            SliceSink { sink: &mut *sink, slice: SliceId { plane: Plane::XZ, index: y } };
                        sweep
                            .run_classed(
                                l0,
                                h0,
                                [c0, c2],
                                m,
                                &mut scratch.batch,
                                |k| Placement::new(x0 + k, z),
                                place,
                                &mut to,
                                &mut stats,
                            )
                            .map_err(ContourError::Sink)?;
                    }
                    if h1_in {
                        and_across(m, [c0, c1, c2, c3], ys);
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
                            let batch = &mut scratch.batch;
                            batch.gather(m, ys, sweep.level(), |k| Some((corners(k)?, at)));
                            batch.each(|i, k, corners, program| {
                                let to = &mut SliceSink { sink: &mut *sink, slice: slice(k) };
                                match program {
                                    Some(p) => batch.draw(i, p, &place(k), to, &mut stats),
                                    None => sweep.cell(corners, at, &place(k), to, &mut stats),
                                }
                            })
                        } else {
                            each_busy(m, ys, |k| match corners(k) {
                                Some(c) => {
                                    let to = &mut SliceSink { sink: &mut *sink, slice: slice(k) };
                                    sweep.cell(c, at, &place(k), to, &mut stats)
                                }
                                None => Ok(()),
                            })
                        }
                        .map_err(ContourError::Sink)?;
                    }
                }
                // This `y`'s rows y + 1 are the next one's rows y.
                if slot < HELD {
                    if l1_in {
                        core::mem::swap(c0, c1);
                        classed[0] = y + 1;
                    }
                    if h1_in {
                        core::mem::swap(c2, c3);
                        classed[1] = y + 1;
                    }
                }
                x0 = if x1 + 1 == nx { nx } else { x1 };
            }
        }
        stats.cells += (u64::from(xy) * ((nx - 1) * (ny - 1)) as u64)
            + u64::from(up)
                * (u64::from(xz) * (ny * (nx - 1)) as u64 + u64::from(yz) * (nx * (ny - 1)) as u64);
    }
    Ok(stats)
}

/// Contour every slice of every plane in `planes` at every level: the
/// chicken-wire contour surface. Within each slice commands come in
/// row-major cell order; across slices they interleave (see
/// [`contour_slab`]).
///
/// # Errors
/// [`ContourError::NonFiniteLevel`] before anything is drawn, or the sink's
/// error.
pub fn contour_volume<T: Voxel, S: SurfaceSink>(
    volume: &Volume<'_, T>,
    planes: Planes,
    levels: &[f32],
    traversal: Traversal,
    sink: &mut S,
) -> Result<ContourStats, ContourError<S::Error>> {
    contour_slab(volume, planes, 0..volume.dims().2, levels, traversal, sink)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contour::sweep::BLOCK;

    /// Keeps every command with its slice, as bits.
    #[derive(Default)]
    struct Keep(Vec<(SliceId, usize, u8, [u32; 3])>);

    impl SurfaceSink for Keep {
        type Error = core::convert::Infallible;
        fn command(&mut self, slice: SliceId, level: usize, c: Command<Point3>) -> Result<(), Self::Error> {
            let p = c.point();
            self.0.push((slice, level, c.op() as u8, [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()]));
            Ok(())
        }
    }

    /// A volume whose rows are longer than the slab keeps classes for
    /// (`HELD` blocks), with a stretch no level meets (whole quiet blocks,
    /// one with a NaN), samples exactly at a level, and a ragged last
    /// block.
    fn long_rows() -> (Vec<f32>, [usize; 3]) {
        let (nx, ny, nz) = (HELD * BLOCK + 1 + 3 * BLOCK / 2, 4, 3);
        let mut h = 0x9E37_79B9u32;
        let mut v = Vec::with_capacity(nx * ny * nz);
        for k in 0..nx * ny * nz {
            h ^= h << 13;
            h ^= h >> 17;
            h ^= h << 5;
            let x = k % nx;
            v.push(match x {
                _ if (2 * BLOCK..5 * BLOCK).contains(&x) => -5.0 - (h % 7) as f32,
                _ if h.is_multiple_of(13) => 0.0,
                _ => (h % 4001) as f32 / 1000.0 - 2.0,
            });
        }
        v[3 * BLOCK + 7] = f32::NAN;
        v[nx * ny + 7 * BLOCK + 2] = f32::INFINITY;
        (v, [nx, ny, nz])
    }

    /// The slab, for every set of planes and one or two levels, draws each
    /// slice exactly as contouring that slice alone does, and counts the
    /// same: the classes kept from row to row and the quiet blocks skipped
    /// lose nothing.
    #[test]
    fn the_slab_draws_every_slice_as_the_slice_alone() {
        let (values, [nx, ny, nz]) = long_rows();
        let volume = Volume::new(&values, nx, ny, nz).unwrap();
        for levels in [&[0.0f32][..], &[0.0, 1.5], &[-6.0]] {
            for bits in 1..8u8 {
                let all = [Plane::XY, Plane::XZ, Plane::YZ];
                let planes = all.iter().enumerate().filter(|(k, _)| bits >> k & 1 != 0).map(|(_, &p)| p);
                let set = planes.clone().fold(Planes::NONE, Planes::with);
                for traversal in [Traversal::Compiled, Traversal::Corrected] {
                    let mut slab = Keep::default();
                    let slab_stats = contour_volume(&volume, set, levels, traversal, &mut slab).unwrap();
                    let mut alone = Keep::default();
                    let mut alone_stats = ContourStats::default();
                    for plane in planes.clone() {
                        for index in 0..volume.slice_count(plane) {
                            let slice = SliceId { plane, index };
                            alone_stats +=
                                contour_slice(&volume, slice, levels, traversal, &mut alone).unwrap();
                        }
                    }
                    // The slab interleaves slices; within each the order is
                    // the slice's own.
                    slab.0.sort_by_key(|&(slice, ..)| slice);
                    alone.0.sort_by_key(|&(slice, ..)| slice);
                    assert_eq!(slab.0, alone.0, "levels {levels:?}, planes {bits:03b}, {traversal:?}");
                    assert_eq!(slab_stats, alone_stats, "levels {levels:?}, planes {bits:03b}");
                    assert!(slab_stats.nonfinite_cells > 0);
                }
            }
        }
    }
}
