//! The chicken-wire surface: contour every slice of a volume along any set
//! of planes, at one or many levels (Zyda, section 1).
//!
//! Points come out in voxel coordinates (x the fastest axis). A crossing on a
//! volume edge is bit-identical whichever slice (and subgrid) draws it, so the
//! x-y, x-z and y-z contours meet exactly.

use crate::command::{Command, CommandSink, Point3};
use crate::contour::{ContourError, ContourStats, check_levels, contour_grid};
use crate::grid::{Plane, Planes, Volume};
use crate::sample::Sample;
use crate::trace::Traversal;

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
pub fn contour_slice<T: Sample, S: SurfaceSink>(
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

/// Contour every slice of every plane in `planes` at every level: the
/// chicken-wire contour surface. Slices go plane by plane (`xy, xz, yz`),
/// in increasing index.
///
/// # Errors
/// [`ContourError::NonFiniteLevel`] before anything is drawn, or the sink's
/// error.
pub fn contour_volume<T: Sample, S: SurfaceSink>(
    volume: &Volume<'_, T>,
    planes: Planes,
    levels: &[f32],
    traversal: Traversal,
    sink: &mut S,
) -> Result<ContourStats, ContourError<S::Error>> {
    check_levels(levels)?;
    let mut stats = ContourStats::default();
    for plane in planes.iter() {
        for index in 0..volume.slice_count(plane) {
            stats += contour_slice(volume, SliceId { plane, index }, levels, traversal, sink)?;
        }
    }
    Ok(stats)
}
