//! The chicken-wire surface: contour every slice of a volume along any set
//! of planes, at one or many levels (Zyda, section 1).
//!
//! Points come out in voxel coordinates (x the fastest axis). A crossing on a
//! volume edge is bit-identical whichever slice (and subgrid) draws it, so the
//! x-y, x-z and y-z contours meet exactly.

use super::grid::{Plane, Planes, Volume};
use super::pen::Placement;
use super::sweep::{BLOCK, Scratch, Sweep, lane};
use super::trace::Traversal;
use super::voxel::Voxel;
use super::{ContourError, ContourStats, check_levels, contour_grid, contour_rows};
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

/// The number of cell rows of `plane`'s slices (along the slice's second
/// axis: y for XY, z for XZ and YZ); bands passed to [`contour_band`] index
/// these rows.
pub fn band_rows<T: Voxel>(volume: &Volume<'_, T>, plane: Plane) -> usize {
    let (_, ny, nz) = volume.dims();
    match plane {
        Plane::XY => ny - 1,
        Plane::XZ | Plane::YZ => nz - 1,
    }
}

/// Contour cell rows `rows` (see [`band_rows`]) of every slice of `plane`.
///
/// Within each slice, commands come in row-major cell order, exactly as
/// [`contour_slice`] gives them, so splitting a plane into bands and joining
/// each slice's commands band by band reproduces the slice. Across slices the
/// order follows memory: x-y and x-z slices one after the other, y-z slices
/// interleaved, swept with x innermost so that every sample is read from
/// contiguous memory (a y-z slice alone strides through the whole volume).
///
/// # Errors
/// [`ContourError::NonFiniteLevel`] before anything is drawn, or the sink's
/// error. Rows past the end are ignored.
pub fn contour_band<T: Voxel, S: SurfaceSink>(
    volume: &Volume<'_, T>,
    plane: Plane,
    rows: Range<usize>,
    levels: &[f32],
    traversal: Traversal,
    sink: &mut S,
) -> Result<ContourStats, ContourError<S::Error>> {
    check_levels(levels)?;
    let rows = rows.start..rows.end.min(band_rows(volume, plane));
    if plane != Plane::YZ {
        let mut stats = ContourStats::default();
        for index in 0..volume.slice_count(plane) {
            let slice = SliceId { plane, index };
            let grid = volume.slice(plane, index).map_err(ContourError::Grid)?;
            let s = index as f32;
            let mut adapter = SliceSink { sink, slice };
            let place = |u, v| plane.to_voxel(s, u, v);
            stats += contour_rows(&grid, rows.clone(), levels, traversal, place, &mut adapter)?;
        }
        return Ok(stats);
    }
    // y-z slices, x innermost: cell (y, z) of slice x has its corners in four
    // contiguous x rows.
    let (nx, ny, _) = volume.dims();
    let data = volume.data();
    let sweep = Sweep::new(levels, traversal);
    let mut stats = ContourStats::default();
    let mut scratch = Scratch::new();
    let mut adapter = LaneSink { sink };
    let rows_len = rows.len();
    for z in rows {
        for y in 0..ny - 1 {
            let row = |y: usize, z: usize| (z * ny + y) * nx;
            let mut x0 = 0;
            while x0 < nx {
                let n = (nx - x0).min(BLOCK);
                let [b0, b1, b2, b3] = &mut scratch.bufs;
                let lanes = [
                    lane(data, row(y, z) + x0, 1, n, b0),
                    lane(data, row(y + 1, z) + x0, 1, n, b1),
                    lane(data, row(y + 1, z + 1) + x0, 1, n, b2),
                    lane(data, row(y, z + 1) + x0, 1, n, b3),
                ];
                sweep
                    .run(
                        lanes,
                        &mut scratch.busy,
                        |_| Placement::new(y, z),
                        |k, u, v| (x0 + k, Point3::new((x0 + k) as f32, u, v)),
                        &mut adapter,
                        &mut stats,
                    )
                    .map_err(ContourError::Sink)?;
                x0 += n;
            }
        }
    }
    stats.cells = (nx * (ny - 1) * rows_len) as u64;
    Ok(stats)
}

/// Forwards y-z commands, whose points carry their slice (x) index.
struct LaneSink<'s, S> {
    sink: &'s mut S,
}

impl<S: SurfaceSink> CommandSink<(usize, Point3)> for LaneSink<'_, S> {
    type Error = S::Error;
    #[inline(always)]
    fn command(&mut self, level: usize, command: Command<(usize, Point3)>) -> Result<(), S::Error> {
        let index = command.point().0;
        self.sink.command(SliceId { plane: Plane::YZ, index }, level, command.map(|(_, p)| p))
    }
}

/// Contour every slice of every plane in `planes` at every level: the
/// chicken-wire contour surface. Planes go in `xy, xz, yz` order; within
/// each slice commands come in row-major cell order (see [`contour_band`]
/// for the order across slices).
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
    check_levels(levels)?;
    let mut stats = ContourStats::default();
    for plane in planes.iter() {
        stats += contour_band(volume, plane, 0..band_rows(volume, plane), levels, traversal, sink)?;
    }
    Ok(stats)
}
