//! The chicken-wire surface: contour every slice of a volume along any set
//! of planes, at one or many levels (Zyda, section 1).
//!
//! Points come out in voxel coordinates (x the fastest axis). A crossing on a
//! volume edge is bit-identical whichever slice (and subgrid) draws it, so the
//! x-y, x-z and y-z contours meet exactly.

use super::grid::{Plane, Planes, Volume};
use super::slab::{Cut, Every, Lane, Rows, Slab, SlabMemory, SliceSink};
use super::sweep::lane;
use super::trace::Traversal;
use super::voxel::Voxel;
use super::{ContourError, ContourStats, check_levels, contour_grid};
use crate::command::{Command, Point3};
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
/// the next, and one more: rows of up to `(SETS - 1) * BLOCK + 1` samples
/// (1025) are classed twice, not four times (9 x 4 x 137 bytes of stack).
const SETS: usize = 9;

/// Rows of a slice (blocks of a row times its rows) whose shared class
/// [`contour_slab`] keeps for the next slab (`2 x 4096` bytes of stack):
/// rows of one block up to 4096 rows a slice, of 1025 samples up to 512.
const QUIET_ROWS: usize = 4096;

/// Contour the z-slab `zs` of every slice of `planes` at every level: the
/// x-y slices `z` and the x-z and y-z cell rows `z` (the cells between the
/// x-y slices `z` and `z + 1`) for `z` in `zs`, all three planes at once,
/// in memory order, row by row ([`super::slab`]: each sample is classed
/// once a slab). Within each slice commands come in row-major cell order,
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
    let cut = Cut {
        xy: planes.contains(Plane::XY),
        xz: planes.contains(Plane::XZ),
        yz: if planes.contains(Plane::YZ) { Every::ALL } else { Every::NONE },
    };
    let mut stats = ContourStats::default();
    let mut mem = SlabMemory::<SETS, QUIET_ROWS>::new();
    let mut slab = Slab::new(levels, traversal, &mut mem);
    for z in zs {
        for y in 0..ny {
            let at = [(y, z), (y + 1, z), (y, z + 1), (y + 1, z + 1)].map(|(y, z)| (z * ny + y) * nx);
            let rows = VolumeRows { data: volume.data(), at };
            slab.row(&rows, [nx, ny], y, z, z + 1 < nz, cut, sink, &mut stats).map_err(ContourError::Sink)?;
        }
    }
    Ok(stats)
}

/// A slab row's samples in a volume in memory: where each of its four rows
/// starts in `data` (rows past the end are never `need`ed).
struct VolumeRows<'d, T> {
    data: &'d [T],
    at: [usize; 4],
}

impl<T: Voxel> Rows for VolumeRows<'_, T> {
    const KEEPS: bool = false;

    #[inline(always)]
    fn lanes<'b>(
        &'b self,
        x0: usize,
        n: usize,
        need: [bool; 4],
        _fill: [bool; 4],
        [b0, b1, b2, b3]: [&'b mut Lane; 4],
    ) -> [&'b [f32]; 4] {
        // (Each row needed is borrowed or widened anew: volumes in memory
        // are mostly `f32`.)
        let [a0, a1, a2, a3] = self.at;
        let [n0, n1, n2, n3] = need;
        let data = self.data;
        let at = |on: bool, start: usize, buf: &'b mut Lane| -> &'b [f32] {
            if on { lane(data, start + x0, 1, n, buf) } else { &[] }
        };
        [at(n0, a0, b0), at(n1, a1, b1), at(n2, a2, b2), at(n3, a3, b3)]
    }
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
pub(crate) mod tests {
    use super::*;
    use crate::contour::sweep::BLOCK;

    /// Keeps every command with its slice, as bits.
    #[derive(Default)]
    pub(crate) struct Keep(pub(crate) Vec<(SliceId, usize, u8, [u32; 3])>);

    impl SurfaceSink for Keep {
        type Error = core::convert::Infallible;
        fn command(&mut self, slice: SliceId, level: usize, c: Command<Point3>) -> Result<(), Self::Error> {
            let p = c.point();
            self.0.push((slice, level, c.op() as u8, [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()]));
            Ok(())
        }
    }

    /// A volume whose rows are longer than the slab keeps classes for
    /// (`SETS - 1` blocks), with a stretch no level meets (whole quiet blocks,
    /// one with a NaN), samples exactly at a level, and a ragged last
    /// block.
    fn long_rows() -> (Vec<f32>, [usize; 3]) {
        let (nx, ny, nz) = ((SETS - 1) * BLOCK + 1 + 3 * BLOCK / 2, 4, 3);
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
