//! The chicken-wire surface: contour every slice of a volume along any set
//! of planes, at one or many levels (Zyda, section 1).
//!
//! Points come out in voxel coordinates (x the fastest axis). A crossing on a
//! volume edge is bit-identical whichever slice (and subgrid) draws it, so the
//! x-y, x-z and y-z contours meet exactly.

use super::grid::{Plane, Planes, Volume};
use super::pen::Placement;
use super::sweep::{BLOCK, Scratch, Sweep, and_across, each_busy, lane};
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
    let row = |y: usize, z: usize| (z * ny + y) * nx;
    for z in zs.clone() {
        let up = z + 1 < nz;
        let fz = z as f32;
        for y in 0..ny {
            let right = y + 1 < ny;
            let mut x0 = 0;
            while x0 < nx {
                // Samples x0..=x1 (cells x0..x1 of x-y and x-z rows; y-z
                // slices x0..x1, the last block's up to nx).
                let x1 = (x0 + BLOCK).min(nx - 1);
                let n = x1 + 1 - x0;
                let ys = if x1 + 1 == nx { n } else { n - 1 };
                let [b0, b1, b2, b3] = &mut scratch.bufs;
                let [c0, c1, c2, c3, m] = &mut scratch.classes;
                // Rows (y, z), (y + 1, z), (y, z + 1), (y + 1, z + 1).
                let l0 = lane(data, row(y, z) + x0, 1, n, b0);
                sweep.classify(l0, c0);
                let l1 = if right { lane(data, row(y + 1, z) + x0, 1, n, b1) } else { &[] };
                let h0 = if up { lane(data, row(y, z + 1) + x0, 1, n, b2) } else { &[] };
                let h1 = if right && up { lane(data, row(y + 1, z + 1) + x0, 1, n, b3) } else { &[] };
                if xy && right {
                    sweep.classify(l1, c1);
                    let place = |_, u, v| Plane::XY.to_voxel(fz, u, v);
                    let mut to =
                        SliceSink { sink: &mut *sink, slice: SliceId { plane: Plane::XY, index: z } };
                    sweep
                        .run_classed(
                            l0,
                            l1,
                            [c0, c1],
                            m,
                            |k| Placement::new(x0 + k, y),
                            place,
                            &mut to,
                            &mut stats,
                        )
                        .map_err(ContourError::Sink)?;
                }
                if xz && up {
                    sweep.classify(h0, c2);
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
                            |k| Placement::new(x0 + k, z),
                            place,
                            &mut to,
                            &mut stats,
                        )
                        .map_err(ContourError::Sink)?;
                }
                if yz && right && up {
                    if !xy {
                        sweep.classify(l1, c1);
                    }
                    if !xz {
                        sweep.classify(h0, c2);
                    }
                    sweep.classify(h1, c3);
                    and_across(m, [c0, c1, c2, c3], ys);
                    each_busy(m, ys, |k| {
                        let (Some(&a), Some(&b), Some(&c), Some(&d)) =
                            (l0.get(k), l1.get(k), h1.get(k), h0.get(k))
                        else {
                            return Ok(());
                        };
                        let slice = SliceId { plane: Plane::YZ, index: x0 + k };
                        let fx = (x0 + k) as f32;
                        let place = |u, v| Plane::YZ.to_voxel(fx, u, v);
                        let at = Placement::new(y, z);
                        sweep.cell(
                            [a, b, c, d],
                            at,
                            &place,
                            &mut SliceSink { sink: &mut *sink, slice },
                            &mut stats,
                        )
                    })
                    .map_err(ContourError::Sink)?;
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
