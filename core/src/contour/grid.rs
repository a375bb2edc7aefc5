//! Zero-copy views of 2D grids and 3D volumes over borrowed sample slices.
//!
//! A [`Grid2`] addresses its samples through strides, so every x-y, x-z and
//! y-z slice of a [`Volume`] is contoured in place, without copying.

use super::voxel::Voxel;

/// Largest extent along one axis: grid coordinates are `f32`, exact for
/// integers up to 2^24.
pub const MAX_EXTENT: usize = 1 << 24;

/// Why a grid or volume view could not be made.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum GridError {
    /// An extent is zero.
    Empty,
    /// An extent is larger than [`MAX_EXTENT`].
    TooLarge {
        /// The offending extent.
        extent: usize,
    },
    /// The sample slice does not hold exactly the samples the extents need.
    SizeMismatch {
        /// Samples the extents need.
        expected: usize,
        /// Samples the slice holds.
        actual: usize,
    },
    /// A strided view reaches past the end of the sample slice.
    OutOfBounds {
        /// Index of the last sample the view would read.
        last: usize,
        /// Samples the slice holds.
        len: usize,
    },
    /// Extents, offset and strides overflow `usize`.
    Overflow,
    /// A slice index is past the end of the volume along its axis.
    SliceOutOfRange {
        /// The requested slice.
        index: usize,
        /// Slices along that axis.
        count: usize,
    },
}

impl core::fmt::Display for GridError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            GridError::Empty => f.write_str("a grid extent is zero"),
            GridError::TooLarge { extent } => {
                write!(f, "grid extent {extent} is larger than the maximum {MAX_EXTENT}")
            }
            GridError::SizeMismatch { expected, actual } => {
                write!(f, "the extents need {expected} samples but {actual} were given")
            }
            GridError::OutOfBounds { last, len } => {
                write!(f, "the view reads sample {last} but only {len} samples were given")
            }
            GridError::Overflow => f.write_str("grid extents and strides overflow"),
            GridError::SliceOutOfRange { index, count } => {
                write!(f, "slice {index} is out of range (the axis has {count} slices)")
            }
        }
    }
}

impl core::error::Error for GridError {}

fn check_extent(n: usize) -> Result<(), GridError> {
    if n == 0 {
        Err(GridError::Empty)
    } else if n > MAX_EXTENT {
        Err(GridError::TooLarge { extent: n })
    } else {
        Ok(())
    }
}

/// A 2D grid of samples viewed through strides: sample `(i, j)` is
/// `data[offset + i * sx + j * sy]`, `i` along x (the first axis).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Grid2<'a, T> {
    data: &'a [T],
    offset: usize,
    nx: usize,
    ny: usize,
    sx: usize,
    sy: usize,
}

impl<'a, T: Voxel> Grid2<'a, T> {
    /// A contiguous grid, x fastest: `data.len()` must be `nx * ny`.
    ///
    /// # Errors
    /// [`GridError`] when an extent is zero or too large, or the length is
    /// not `nx * ny`.
    pub fn new(data: &'a [T], nx: usize, ny: usize) -> Result<Self, GridError> {
        check_extent(nx)?;
        check_extent(ny)?;
        let expected = nx.checked_mul(ny).ok_or(GridError::Overflow)?;
        if data.len() != expected {
            return Err(GridError::SizeMismatch { expected, actual: data.len() });
        }
        Ok(Self { data, offset: 0, nx, ny, sx: 1, sy: nx })
    }

    /// A strided view: sample `(i, j)` is `data[offset + i * sx + j * sy]`.
    ///
    /// # Errors
    /// [`GridError`] when an extent is zero or too large, or the view would
    /// read outside `data`.
    pub fn strided(
        data: &'a [T],
        offset: usize,
        (nx, ny): (usize, usize),
        (sx, sy): (usize, usize),
    ) -> Result<Self, GridError> {
        check_extent(nx)?;
        check_extent(ny)?;
        let last = (nx - 1)
            .checked_mul(sx)
            .and_then(|a| (ny - 1).checked_mul(sy).and_then(|b| a.checked_add(b)))
            .and_then(|a| a.checked_add(offset))
            .ok_or(GridError::Overflow)?;
        if last >= data.len() {
            return Err(GridError::OutOfBounds { last, len: data.len() });
        }
        Ok(Self { data, offset, nx, ny, sx, sy })
    }

    /// Samples along x.
    pub fn nx(&self) -> usize {
        self.nx
    }

    /// Samples along y.
    pub fn ny(&self) -> usize {
        self.ny
    }

    /// Number of 2x2 subgrids (cells).
    pub fn cells(&self) -> usize {
        (self.nx - 1).saturating_mul(self.ny - 1)
    }

    /// The sample at `(i, j)`, or `None` outside the grid.
    #[inline(always)]
    pub fn get(&self, i: usize, j: usize) -> Option<T> {
        if i < self.nx && j < self.ny {
            self.data.get(self.offset + i * self.sx + j * self.sy).copied()
        } else {
            None
        }
    }

    /// The samples, offset and strides `(sx, sy)`: sample `(i, j)` is
    /// `data[offset + i * sx + j * sy]`.
    #[inline(always)]
    pub(crate) fn layout(&self) -> (&'a [T], usize, usize, usize) {
        (self.data, self.offset, self.sx, self.sy)
    }
}

/// A slicing plane of a volume.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Plane {
    /// x-y slices, one per z.
    XY,
    /// x-z slices, one per y.
    XZ,
    /// y-z slices, one per x.
    YZ,
}

impl Plane {
    /// All three planes.
    pub const ALL: [Plane; 3] = [Plane::XY, Plane::XZ, Plane::YZ];

    /// The plane's name as written on the command line and in CSV: `xy`,
    /// `xz` or `yz`.
    pub const fn name(self) -> &'static str {
        match self {
            Plane::XY => "xy",
            Plane::XZ => "xz",
            Plane::YZ => "yz",
        }
    }

    /// The plane with this name (`xy`, `xz`, `yz`; also `yx`, `zx`, `zy`).
    pub fn from_name(name: &str) -> Option<Plane> {
        match name {
            "xy" | "yx" => Some(Plane::XY),
            "xz" | "zx" => Some(Plane::XZ),
            "yz" | "zy" => Some(Plane::YZ),
            _ => None,
        }
    }

    /// The axis its slices are indexed along (0 x, 1 y, 2 z): z for the
    /// x-y slices, y for the x-z, x for the y-z.
    pub const fn axis(self) -> usize {
        match self {
            Plane::XY => 2,
            Plane::XZ => 1,
            Plane::YZ => 0,
        }
    }

    /// Bit of this plane in a [`Planes`] set.
    const fn bit(self) -> u8 {
        match self {
            Plane::XY => 1,
            Plane::XZ => 2,
            Plane::YZ => 4,
        }
    }

    /// Map in-slice grid coordinates `(u, v)` of slice `s` to voxel
    /// coordinates. XY: `(u, v, s)`; XZ: `(u, s, v)`; YZ: `(s, u, v)`.
    #[inline(always)]
    pub fn to_voxel(self, s: f32, u: f32, v: f32) -> crate::command::Point3 {
        use crate::command::Point3;
        match self {
            Plane::XY => Point3::new(u, v, s),
            Plane::XZ => Point3::new(u, s, v),
            Plane::YZ => Point3::new(s, u, v),
        }
    }
}

impl core::fmt::Display for Plane {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

/// A set of slicing planes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Planes(u8);

impl Planes {
    /// No planes.
    pub const NONE: Planes = Planes(0);
    /// All three planes: the full chicken-wire surface.
    pub const ALL: Planes = Planes(7);

    /// This set with `plane` added.
    pub const fn with(self, plane: Plane) -> Planes {
        Planes(self.0 | plane.bit())
    }

    /// True when `plane` is in the set.
    pub const fn contains(self, plane: Plane) -> bool {
        self.0 & plane.bit() != 0
    }

    /// The planes in the set, in `xy, xz, yz` order.
    pub fn iter(self) -> impl Iterator<Item = Plane> {
        Plane::ALL.into_iter().filter(move |p| self.contains(*p))
    }
}

impl From<Plane> for Planes {
    fn from(p: Plane) -> Self {
        Planes::NONE.with(p)
    }
}

/// A 3D volume of samples, x fastest, then y, then z.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Volume<'a, T> {
    data: &'a [T],
    nx: usize,
    ny: usize,
    nz: usize,
}

impl<'a, T: Voxel> Volume<'a, T> {
    /// A volume over `data`, which must hold exactly `nx * ny * nz` samples.
    ///
    /// # Errors
    /// [`GridError`] when an extent is zero or too large or the length is
    /// wrong.
    pub fn new(data: &'a [T], nx: usize, ny: usize, nz: usize) -> Result<Self, GridError> {
        check_extent(nx)?;
        check_extent(ny)?;
        check_extent(nz)?;
        let expected = nx.checked_mul(ny).and_then(|a| a.checked_mul(nz)).ok_or(GridError::Overflow)?;
        if data.len() != expected {
            return Err(GridError::SizeMismatch { expected, actual: data.len() });
        }
        Ok(Self { data, nx, ny, nz })
    }

    /// Extents `(nx, ny, nz)`.
    pub fn dims(&self) -> (usize, usize, usize) {
        (self.nx, self.ny, self.nz)
    }

    /// The samples.
    pub fn data(&self) -> &'a [T] {
        self.data
    }

    /// How many slices a plane has (nz for XY, ny for XZ, nx for YZ).
    pub fn slice_count(&self, plane: Plane) -> usize {
        match plane {
            Plane::XY => self.nz,
            Plane::XZ => self.ny,
            Plane::YZ => self.nx,
        }
    }

    /// Slice `index` of `plane` as a zero-copy grid: XY has `(u, v) = (x,
    /// y)`, XZ `(x, z)`, YZ `(y, z)`.
    ///
    /// # Errors
    /// [`GridError::SliceOutOfRange`] for an index past the axis.
    pub fn slice(&self, plane: Plane, index: usize) -> Result<Grid2<'a, T>, GridError> {
        let count = self.slice_count(plane);
        if index >= count {
            return Err(GridError::SliceOutOfRange { index, count });
        }
        let (nx, ny, nxy) = (self.nx, self.ny, self.nx * self.ny);
        match plane {
            Plane::XY => Grid2::strided(self.data, index * nxy, (nx, ny), (1, nx)),
            Plane::XZ => Grid2::strided(self.data, index * nx, (nx, self.nz), (1, nxy)),
            Plane::YZ => Grid2::strided(self.data, index, (ny, self.nz), (nx, nxy)),
        }
    }
}
