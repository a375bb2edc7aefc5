//! The engine's memory, lent by the caller: as slices, or in arrays for a
//! `static` on the MCU.

use crate::contour::slab::SlabMemory;

/// What the engine's contouring keeps from one step to the next: the
/// samples (as `f32`) and classes of the four rows around a slab row,
/// so that each is decoded and classed once however the rows' work is cut
/// into steps, and what the rows of the last two slices share, so that
/// a quiet row is classed once a volume, not once in each of its two slabs
/// ([`QUIET_ROWS`] rows of a slice; about 3.2 KB in all).
#[derive(Debug)]
pub struct RowMemory(pub(crate) SlabMemory<1, QUIET_ROWS>);

/// Rows of a slice (of one block of 128 cells: a row of up to 129
/// samples) whose shared class the engine keeps from one slab to the next:
/// every row of a 128 x 128 slice. Rows past it are classed twice.
pub const QUIET_ROWS: usize = 128;

impl RowMemory {
    /// Memory that holds nothing yet.
    pub const fn new() -> Self {
        Self(SlabMemory::new())
    }
}

impl Default for RowMemory {
    fn default() -> Self {
        Self::new()
    }
}

/// The engine's memory, lent by the caller.
///
/// - `slices`: both slice buffers, one after the other: half of it is the
///   largest slice, `nx * ny * sample size` bytes. What a volume's two
///   slices leave free holds the part of its surface that does not fit
///   `back` (so a volume of small slices may have a larger surface: the
///   pieces as contoured are some 1.75 times the picture's points).
///   Between volumes it is the scratch for stitching and ordering, which
///   takes about 6 bytes a point of the surface (14 a fragment), 3 when
///   short of room: so the slices should hold at least `6 * points` bytes
///   in all, or a large surface is shown unordered.
/// - `rows`: what contouring keeps from one row of a slice to the next.
/// - `front`, `back`: the bytes of the two surfaces (on screen, being
///   received), [`Geometry::bytes_for`](crate::path::Geometry::bytes_for) the points each holds (6.25 bytes
///   a point).
/// - `scratch`: more room for stitching and ordering, where memory is
///   plenty (the host); the larger of it and the idle slices is used. Empty
///   on the MCU.
#[derive(Debug)]
pub struct Buffers<'a> {
    /// Both slices (the previous and the current one), one after the other.
    pub slices: &'a mut [u8],
    /// The rows around the cells being contoured.
    pub rows: &'a mut RowMemory,
    /// The picture on screen.
    pub front: &'a mut [u8],
    /// The surface being received.
    pub back: &'a mut [u8],
    /// Extra scratch (may be empty).
    pub scratch: &'a mut [u8],
}

impl<'a> Buffers<'a> {
    /// Buffers from one block of each kind: `surfaces` cut in two halves
    /// (front first); `slices` holds both slices as it is.
    pub fn halves(
        slices: &'a mut [u8],
        rows: &'a mut RowMemory,
        surfaces: &'a mut [u8],
        scratch: &'a mut [u8],
    ) -> Self {
        let (front, back) = surfaces.split_at_mut(surfaces.len() / 2);
        Self { slices, rows, front, back, scratch }
    }
}

/// The engine's memory in arrays, for a `static` on the MCU.
///
/// - `SLICE`: bytes in one slice (`nx * ny * sample size`), twice.
/// - `SURFACE`: bytes of each of the two surfaces:
///   [`Geometry::bytes_for`](crate::path::Geometry::bytes_for) the points it holds.
///
/// It takes `2 * SLICE + 2 * SURFACE` bytes; for slices of 128 x 128 `u16`
/// and 2 x 8192 points, 166 KB.
#[derive(Debug)]
pub struct StaticBuffers<const SLICE: usize, const SURFACE: usize> {
    slices: [[u8; SLICE]; 2],
    rows: RowMemory,
    surfaces: [[u8; SURFACE]; 2],
}

impl<const SLICE: usize, const SURFACE: usize> StaticBuffers<SLICE, SURFACE> {
    /// Zeroed buffers.
    pub const fn new() -> Self {
        Self { slices: [[0; SLICE]; 2], rows: RowMemory::new(), surfaces: [[0; SURFACE]; 2] }
    }

    /// The buffers, lent to an [`Engine`](super::Engine).
    pub fn buffers(&mut self) -> Buffers<'_> {
        Buffers::halves(
            self.slices.as_flattened_mut(),
            &mut self.rows,
            self.surfaces.as_flattened_mut(),
            &mut [],
        )
    }
}

impl<const SLICE: usize, const SURFACE: usize> Default for StaticBuffers<SLICE, SURFACE> {
    fn default() -> Self {
        Self::new()
    }
}
