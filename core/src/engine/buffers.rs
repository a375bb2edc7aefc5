//! The engine's memory, lent by the caller: as slices, or in arrays for a
//! `static` on the MCU.

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
/// - `rows`: two row buffers; each sets the largest `nx` and `ny`.
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
    /// Two rows of samples widened to `f32`.
    pub rows: [&'a mut [f32]; 2],
    /// The picture on screen.
    pub front: &'a mut [u8],
    /// The surface being received.
    pub back: &'a mut [u8],
    /// Extra scratch (may be empty).
    pub scratch: &'a mut [u8],
}

impl<'a> Buffers<'a> {
    /// Buffers from one block of each kind, cut in two halves: `rows` into
    /// the two rows, `surfaces` into the two surfaces (front first).
    /// `slices` holds both slices as it is.
    pub fn halves(
        slices: &'a mut [u8],
        rows: &'a mut [f32],
        surfaces: &'a mut [u8],
        scratch: &'a mut [u8],
    ) -> Self {
        let (r0, r1) = rows.split_at_mut(rows.len() / 2);
        let (front, back) = surfaces.split_at_mut(surfaces.len() / 2);
        Self { slices, rows: [r0, r1], front, back, scratch }
    }
}

/// The engine's memory in arrays, for a `static` on the MCU.
///
/// - `SLICE`: bytes in one slice (`nx * ny * sample size`), twice.
/// - `EXTENT`: the largest `nx` or `ny`.
/// - `SURFACE`: bytes of each of the two surfaces:
///   [`Geometry::bytes_for`](crate::path::Geometry::bytes_for) the points it holds.
///
/// It takes `2 * SLICE + 8 * EXTENT + 2 * SURFACE` bytes; for slices of
/// 128 x 128 `u16` and 2 x 8192 points, 167 KB.
#[derive(Debug, Clone, PartialEq)]
pub struct StaticBuffers<const SLICE: usize, const EXTENT: usize, const SURFACE: usize> {
    slices: [[u8; SLICE]; 2],
    rows: [[f32; EXTENT]; 2],
    surfaces: [[u8; SURFACE]; 2],
}

impl<const SLICE: usize, const EXTENT: usize, const SURFACE: usize> StaticBuffers<SLICE, EXTENT, SURFACE> {
    /// Zeroed buffers.
    pub const fn new() -> Self {
        Self { slices: [[0; SLICE]; 2], rows: [[0.0; EXTENT]; 2], surfaces: [[0; SURFACE]; 2] }
    }

    /// The buffers, lent to an [`Engine`](super::Engine).
    pub fn buffers(&mut self) -> Buffers<'_> {
        Buffers::halves(
            self.slices.as_flattened_mut(),
            self.rows.as_flattened_mut(),
            self.surfaces.as_flattened_mut(),
            &mut [],
        )
    }
}

impl<const SLICE: usize, const EXTENT: usize, const SURFACE: usize> Default
    for StaticBuffers<SLICE, EXTENT, SURFACE>
{
    fn default() -> Self {
        Self::new()
    }
}
