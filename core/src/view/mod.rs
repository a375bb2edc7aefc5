//! The 3D view: voxel coordinates ([`Point3`]) to screen coordinates in DAC
//! units ([`ScreenPoint`]).
//!
//! A [`View`] is the configuration (angles, projection, margin, DAC
//! resolution, voxel spacing); [`ViewTransform::fit`] turns it and the
//! [`Bounds`] of a volume into a precomputed transform whose
//! [`project`](ViewTransform::project) costs three subtractions, six
//! multiplications and six additions per point (plus one division and a few
//! more operations in perspective).
//!
//! # Conventions
//!
//! - **Frames.** Voxel coordinates are first scaled by [`View::spacing`] into
//!   physical units, relative to the centre of the bounds. The camera frame
//!   is right-handed: `X` to the right of the screen, `Y` up, `Z` out of the
//!   screen towards the viewer, who looks along `-Z`.
//! - **Identity view.** At `yaw = pitch = roll = 0` the volume's axes are the
//!   camera's: voxel x to the right, y up, z towards the viewer. The x-y
//!   slices face the viewer, and in orthographic mode z does not move a point
//!   on the screen.
//! - **Rotation.** About the centre of the bounds, in this order, each about
//!   a fixed camera axis and positive counter-clockwise when seen from the
//!   positive end of that axis (right-hand rule):
//!   1. `yaw` about the vertical screen axis `Y`: positive turns the volume's
//!      +x end away from the viewer (+x towards -Z) and its +z face to the
//!      right. Animating `yaw` spins the volume about its own y axis, like a
//!      turntable.
//!   2. `pitch` about the horizontal screen axis `X`: positive tilts the
//!      volume's top (+y) towards the viewer, so you look down onto it.
//!   3. `roll` about the view axis `Z`: positive turns the picture
//!      counter-clockwise on the screen.
//!
//!   In matrix form `camera = Rz(roll) · Rx(pitch) · Ry(yaw) · S · (p - c)`,
//!   `S` the spacing and `c` the centre of the bounds.
//! - **Default view.** `yaw = 30°`, `pitch = 20°`, `roll = 0`, orthographic:
//!   you look slightly down onto the volume and slightly from its -x side,
//!   seeing its front (+z), left (-x) and top (+y) faces at once.
//! - **Fit.** The eight corners of the bounds are projected and the picture
//!   is scaled (same scale on both axes) and centred so that they fill the
//!   square `margin · R ..= (1 - margin) · R` on both axes as far as possible,
//!   `R = 2^bits - 1`. A guard of a few `f32` rounding errors (far below one
//!   LSB) is kept inside the margin so that the corners, projected in `f32`,
//!   never leave it. [`ViewTransform::fit_sphere`] instead fits the bounding
//!   sphere, so the scale does not change while the view spins.
//! - **Perspective.** A pinhole camera on the `Z` axis at distance
//!   `D = r / sin(fov / 2)` from the centre, `r` the radius of the bounding
//!   sphere (never closer than [`MIN_CAMERA_DISTANCE`] radii), so every point
//!   of the bounds is strictly in front of it. The field of view sets the
//!   strength of the perspective; the fit then scales the picture to the
//!   screen as in orthographic mode.
//! - **Out of range.** Points outside the bounds may project outside the DAC
//!   range (the beam scheduler clamps). A point that is not finite, that lies
//!   at or behind the camera, or whose projection overflows projects to
//!   `(NaN, NaN)` with [`ViewTransform::project`] and to `None` with
//!   [`ViewTransform::try_project`]; later stages skip non-finite points.
//!
//! ```
//! use isoscope_core::command::Point3;
//! use isoscope_core::view::{Bounds, Projection, View, ViewTransform};
//!
//! let bounds = Bounds::of_volume(64, 64, 32).unwrap();
//! let view = View { projection: Projection::Perspective { fov_deg: 40.0 }, ..View::default() };
//! let t = ViewTransform::fit(&view, bounds).unwrap();
//! for c in bounds.corners() {
//!     let s = t.project(c);
//!     assert!(s.x >= 0.05 * 4095.0 - 1e-3 && s.x <= 0.95 * 4095.0 + 1e-3);
//!     assert!(s.y >= 0.05 * 4095.0 - 1e-3 && s.y <= 0.95 * 4095.0 + 1e-3);
//! }
//! // Spin the view by 5 degrees per frame.
//! let next = ViewTransform::fit(&view.yawed(5.0), bounds).unwrap();
//! assert!(next.project(Point3::new(0.0, 0.0, 0.0)).x.is_finite());
//! ```

mod screen;
mod transform;

pub use screen::ScreenPoint;
pub use transform::ViewTransform;

use crate::command::Point3;

/// The closest the perspective camera comes to the centre of the bounds, in
/// radii of their bounding sphere: fields of view wider than
/// `2 · asin(1 / 1.05) ≈ 144.3°` all place the camera here.
pub const MIN_CAMERA_DISTANCE: f32 = 1.05;

/// Why a view transform could not be made.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ViewError {
    /// `yaw`, `pitch` or `roll` is NaN or infinite.
    NonFiniteAngle,
    /// The perspective field of view is not strictly between 0 and 180
    /// degrees (or is NaN).
    InvalidFieldOfView,
    /// The margin is not in `0.0 .. 0.5` (or is NaN).
    InvalidMargin,
    /// The DAC resolution is not in `1 ..= 16` bits.
    InvalidBits {
        /// The offending resolution.
        bits: u8,
    },
    /// A voxel spacing is not finite and strictly positive.
    InvalidSpacing,
    /// A bound is NaN or infinite.
    NonFiniteBounds,
    /// `min > max` along some axis, or a volume extent is zero.
    EmptyBounds,
    /// The transform's numbers do not fit in `f32` (absurdly small or large
    /// bounds or spacings).
    Overflow,
}

impl core::fmt::Display for ViewError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            ViewError::NonFiniteAngle => f.write_str("a view angle is not finite"),
            ViewError::InvalidFieldOfView => {
                f.write_str("the field of view must be strictly between 0 and 180 degrees")
            }
            ViewError::InvalidMargin => f.write_str("the margin must be in 0.0 .. 0.5"),
            ViewError::InvalidBits { bits } => {
                write!(f, "a DAC resolution of {bits} bits is not in 1 ..= 16")
            }
            ViewError::InvalidSpacing => f.write_str("voxel spacings must be finite and positive"),
            ViewError::NonFiniteBounds => f.write_str("the bounds are not finite"),
            ViewError::EmptyBounds => f.write_str("the bounds are empty"),
            ViewError::Overflow => f.write_str("the view transform overflows f32"),
        }
    }
}

impl core::error::Error for ViewError {}

/// How 3D points are projected onto the screen plane.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Projection {
    /// Parallel projection along the view axis: depth does not change size.
    #[default]
    Orthographic,
    /// Pinhole camera: nearer things look larger.
    Perspective {
        /// Field of view in degrees, strictly between 0 and 180; it sets how
        /// close the camera stands (see [`MIN_CAMERA_DISTANCE`]), hence the
        /// strength of the perspective (40 to 60 looks natural).
        fov_deg: f32,
    },
}

/// The view configuration. See the [module documentation](self) for the
/// conventions.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct View {
    /// Rotation about the vertical screen axis, degrees, applied first;
    /// positive turns the volume's +x end away from the viewer.
    pub yaw: f32,
    /// Rotation about the horizontal screen axis, degrees, applied second;
    /// positive tilts the volume's top towards the viewer.
    pub pitch: f32,
    /// Rotation about the view axis, degrees, applied last; positive is
    /// counter-clockwise on the screen.
    pub roll: f32,
    /// Orthographic or perspective.
    pub projection: Projection,
    /// Fraction of the DAC range left free on each side, `0.0 .. 0.5`.
    pub margin: f32,
    /// DAC resolution in bits, `1 ..= 16`: the screen spans
    /// `0.0 ..= 2^bits - 1` on both axes.
    pub bits: u8,
    /// Physical size of a voxel along x, y and z (any unit, finite and
    /// positive), so that anisotropic volumes keep their true shape.
    pub spacing: [f32; 3],
}

impl View {
    /// The default view: yaw 30°, pitch 20°, roll 0, orthographic, 5 %
    /// margin, 12-bit DAC, isotropic voxels.
    pub const DEFAULT: View = View {
        yaw: 30.0,
        pitch: 20.0,
        roll: 0.0,
        projection: Projection::Orthographic,
        margin: 0.05,
        bits: 12,
        spacing: [1.0, 1.0, 1.0],
    };

    /// The identity orientation (yaw = pitch = roll = 0: x right, y up,
    /// looking along -z), otherwise as [`View::DEFAULT`]; right for 2D grids.
    pub const FRONT: View = View { yaw: 0.0, pitch: 0.0, roll: 0.0, ..View::DEFAULT };

    /// The same view with `yaw` turned by `delta_deg`, wrapped into
    /// `-180.0 .. 180.0` so that it never loses precision while animating.
    /// A non-finite yaw or delta gives a non-finite yaw (rejected by
    /// [`ViewTransform::fit`]).
    #[must_use]
    pub fn yawed(self, delta_deg: f32) -> View {
        View { yaw: wrap_deg(wrap_deg(self.yaw) + wrap_deg(delta_deg)), ..self }
    }

    /// The full scale of the DAC, `2^bits - 1`, in DAC units (as `f32`);
    /// `bits` is clamped to `1 ..= 16` here.
    pub fn range(&self) -> f32 {
        ((1u32 << self.bits.clamp(1, 16)) - 1) as f32
    }
}

impl Default for View {
    fn default() -> Self {
        View::DEFAULT
    }
}

/// An angle in degrees wrapped into `-180.0 .. 180.0` (NaN stays NaN).
fn wrap_deg(a: f32) -> f32 {
    let r = libm::fmodf(a, 360.0);
    if r >= 180.0 {
        r - 360.0
    } else if r < -180.0 {
        r + 360.0
    } else {
        r
    }
}

/// An axis-aligned box in voxel coordinates (both ends included).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Bounds {
    /// The smallest corner.
    pub min: Point3,
    /// The largest corner.
    pub max: Point3,
}

impl Bounds {
    /// The box between two corners.
    pub const fn new(min: Point3, max: Point3) -> Self {
        Self { min, max }
    }

    /// The bounds of an `nx x ny x nz` volume: `(0, 0, 0) ..= (nx-1, ny-1,
    /// nz-1)`. A volume with one sample along an axis is flat along it.
    ///
    /// # Errors
    /// [`ViewError::EmptyBounds`] when an extent is zero.
    pub fn of_volume(nx: usize, ny: usize, nz: usize) -> Result<Self, ViewError> {
        let last = |n: usize| n.checked_sub(1).map(|m| m as f32).ok_or(ViewError::EmptyBounds);
        Ok(Self { min: Point3::new(0.0, 0.0, 0.0), max: Point3::new(last(nx)?, last(ny)?, last(nz)?) })
    }

    /// The centre of the box.
    pub fn centre(&self) -> Point3 {
        let mid = |a: f32, b: f32| ((f64::from(a) + f64::from(b)) * 0.5) as f32;
        Point3::new(mid(self.min.x, self.max.x), mid(self.min.y, self.max.y), mid(self.min.z, self.max.z))
    }

    /// The eight corners; corner `i` takes `max` along x when bit 0 of `i`
    /// is set, along y for bit 1, along z for bit 2.
    pub fn corners(&self) -> [Point3; 8] {
        let (a, b) = (self.min, self.max);
        [
            Point3::new(a.x, a.y, a.z),
            Point3::new(b.x, a.y, a.z),
            Point3::new(a.x, b.y, a.z),
            Point3::new(b.x, b.y, a.z),
            Point3::new(a.x, a.y, b.z),
            Point3::new(b.x, a.y, b.z),
            Point3::new(a.x, b.y, b.z),
            Point3::new(b.x, b.y, b.z),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bounds(max: (f32, f32, f32)) -> Bounds {
        Bounds::new(Point3::new(0.0, 0.0, 0.0), Point3::new(max.0, max.1, max.2))
    }

    #[test]
    fn yawed_wraps() {
        let v = View::DEFAULT;
        assert_eq!(v.yawed(350.0).yaw, 20.0);
        assert_eq!(v.yawed(-60.0).yaw, -30.0);
        assert_eq!(v.yawed(150.0).yaw, -180.0);
        assert_eq!(v.yawed(1e9).pitch, 20.0);
        let mut s = v;
        for _ in 0..3600 {
            s = s.yawed(1.0);
            assert!((-180.0..180.0).contains(&s.yaw));
        }
        assert!((s.yaw - 30.0).abs() < 1e-3, "{}", s.yaw);
        assert!(v.yawed(f32::NAN).yaw.is_nan());
        let b = Bounds::of_volume(8, 8, 8).unwrap();
        let (t0, t1) = (ViewTransform::fit(&v, b).unwrap(), ViewTransform::fit(&v.yawed(720.0), b).unwrap());
        assert!(
            t0.project(Point3::new(1.0, 2.0, 3.0)).distance(t1.project(Point3::new(1.0, 2.0, 3.0))) < 1e-3
        );
    }

    #[test]
    fn bounds_helpers() {
        let b = Bounds::of_volume(5, 3, 1).unwrap();
        assert_eq!(b, bounds((4.0, 2.0, 0.0)));
        assert_eq!(b.centre(), Point3::new(2.0, 1.0, 0.0));
        let c = b.corners();
        assert_eq!((c[0], c[7]), (b.min, b.max));
        assert_eq!(c[5], Point3::new(4.0, 0.0, 0.0));
        assert_eq!(View::default().range(), 4095.0);
        assert_eq!(View { bits: 16, ..View::DEFAULT }.range(), 65535.0);
    }
}
