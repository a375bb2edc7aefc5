//! The fitted view: [`ViewTransform`], made once per view change from a
//! [`View`] and the [`Bounds`] of a volume, then applied to every point.
//! See the [module documentation](super) for the conventions.

use super::{Bounds, MIN_CAMERA_DISTANCE, Projection, ScreenPoint, View, ViewError};
use crate::command::Point3;

/// A projected extent smaller than this fraction of the bounding sphere's
/// radius is a box seen edge-on or end-on (or a single point).
const DEGENERATE: f64 = 1e-9;

/// A 3-vector of `f64`, for the one-off set-up maths.
#[derive(Debug, Clone, Copy, PartialEq)]
struct V3 {
    x: f64,
    y: f64,
    z: f64,
}

impl V3 {
    const fn new(x: f64, y: f64, z: f64) -> Self {
        Self { x, y, z }
    }
    fn dot(self, o: V3) -> f64 {
        self.x * o.x + self.y * o.y + self.z * o.z
    }
    /// `sum |self_i| * o_i`: the largest `|self . q|` over `|q_i| <= o_i`.
    fn abs_dot(self, o: V3) -> f64 {
        libm::fabs(self.x) * o.x + libm::fabs(self.y) * o.y + libm::fabs(self.z) * o.z
    }
    fn scale(self, k: f64) -> V3 {
        V3::new(self.x * k, self.y * k, self.z * k)
    }
    fn add(self, o: V3) -> V3 {
        V3::new(self.x + o.x, self.y + o.y, self.z + o.z)
    }
    fn mul(self, o: V3) -> V3 {
        V3::new(self.x * o.x, self.y * o.y, self.z * o.z)
    }
}

/// One row of the 3x4 matrix: `x * qx + y * qy + z * qz + w`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
struct Row {
    x: f32,
    y: f32,
    z: f32,
    w: f32,
}

impl Row {
    /// The row in `f32`, or `None` when a coefficient overflows.
    fn of(v: V3, w: f64) -> Option<Row> {
        let r = Row { x: v.x as f32, y: v.y as f32, z: v.z as f32, w: w as f32 };
        (r.x.is_finite() && r.y.is_finite() && r.z.is_finite() && r.w.is_finite()).then_some(r)
    }

    #[inline(always)]
    fn eval(&self, qx: f32, qy: f32, qz: f32) -> f32 {
        self.x * qx + self.y * qy + self.z * qz + self.w
    }
}

/// Which shape the fit makes fill the screen.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Fit {
    /// The projected corners of the box.
    Box,
    /// The projected bounding sphere (independent of the rotation).
    Sphere,
}

/// A fitted view: projects voxel coordinates to screen coordinates in DAC
/// units. Made once per view change by [`ViewTransform::fit`] (a few hundred
/// `f64` operations), then applied to every point by
/// [`ViewTransform::project`].
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ViewTransform {
    /// The rotation centre in voxel coordinates (subtracted first).
    origin: Point3,
    /// Screen x (orthographic) or its numerator (perspective).
    sx: Row,
    /// Screen y (orthographic) or its numerator (perspective).
    sy: Row,
    /// Perspective: the depth divisor, 1 at the centre's depth.
    depth: Row,
    /// Perspective or orthographic.
    perspective: bool,
    /// The screen centre, `range / 2` (added after the division).
    centre: f32,
    /// The DAC full scale, `2^bits - 1`.
    range: f32,
    /// DAC units per physical unit at the depth of the centre.
    scale: f32,
}

impl ViewTransform {
    /// The transform that fits the bounds' eight corners, after spacing,
    /// rotation and projection, into the DAC range minus the margin: centred,
    /// the same scale on both axes, as large as possible. A flat box (one
    /// voxel thick, a 2D grid) fits on the extent it has; a box seen exactly
    /// edge-on or end-on, or a single point, fits its bounding sphere
    /// instead (a single point lands on the centre of the screen).
    ///
    /// # Errors
    /// A [`ViewError`] for non-finite angles or bounds, a field of view not
    /// in `(0, 180)`, a margin not in `[0, 0.5)`, bits not in `1 ..= 16`, a
    /// spacing that is not finite and positive, `min > max`, or numbers that
    /// overflow `f32`.
    pub fn fit(view: &View, bounds: Bounds) -> Result<Self, ViewError> {
        Self::build(view, bounds, Fit::Box)
    }

    /// Like [`ViewTransform::fit`], but the bounds' bounding sphere fills the
    /// usable area, so the scale depends on neither the angles nor the
    /// aspect of the box: the picture does not breathe while the view spins.
    /// Every point of the bounds lands inside the margin.
    ///
    /// # Errors
    /// As [`ViewTransform::fit`].
    pub fn fit_sphere(view: &View, bounds: Bounds) -> Result<Self, ViewError> {
        Self::build(view, bounds, Fit::Sphere)
    }

    fn build(view: &View, bounds: Bounds, fit: Fit) -> Result<Self, ViewError> {
        // Validate.
        if !(view.yaw.is_finite() && view.pitch.is_finite() && view.roll.is_finite()) {
            return Err(ViewError::NonFiniteAngle);
        }
        if !(1..=16).contains(&view.bits) {
            return Err(ViewError::InvalidBits { bits: view.bits });
        }
        if !(0.0..0.5).contains(&view.margin) {
            return Err(ViewError::InvalidMargin);
        }
        if !view.spacing.iter().all(|s| s.is_finite() && *s > 0.0) {
            return Err(ViewError::InvalidSpacing);
        }
        let fov = match view.projection {
            Projection::Orthographic => None,
            Projection::Perspective { fov_deg } if fov_deg > 0.0 && fov_deg < 180.0 => Some(fov_deg),
            Projection::Perspective { .. } => return Err(ViewError::InvalidFieldOfView),
        };
        let Bounds { min, max } = bounds;
        if ![min.x, min.y, min.z, max.x, max.y, max.z].iter().all(|v| v.is_finite()) {
            return Err(ViewError::NonFiniteBounds);
        }
        if min.x > max.x || min.y > max.y || min.z > max.z {
            return Err(ViewError::EmptyBounds);
        }

        // The rotation centre, exactly as `project` will subtract it, and the
        // box relative to it (voxel units, not quite symmetric after the
        // rounding of the centre).
        let origin = bounds.centre();
        let c = V3::new(origin.x.into(), origin.y.into(), origin.z.into());
        let lo = V3::new(min.x.into(), min.y.into(), min.z.into()).add(c.scale(-1.0));
        let hi = V3::new(max.x.into(), max.y.into(), max.z.into()).add(c.scale(-1.0));
        // Half extents (symmetric superset) and the bounding sphere.
        let hv = V3::new(hi.x.max(-lo.x), hi.y.max(-lo.y), hi.z.max(-lo.z));
        let [spx, spy, spz] = view.spacing;
        let spacing = V3::new(spx.into(), spy.into(), spz.into());
        let h = hv.mul(spacing);
        let r = libm::sqrt(h.dot(h));

        // Rotation rows (Rz(roll) Rx(pitch) Ry(yaw)), spacing folded in:
        // camera = (m0 . q, m1 . q, m2 . q), q = p - origin in voxel units.
        let rad = |deg: f32| libm::fmod(f64::from(deg), 360.0).to_radians();
        let (sa, ca) = (libm::sin(rad(view.yaw)), libm::cos(rad(view.yaw)));
        let (sb, cb) = (libm::sin(rad(view.pitch)), libm::cos(rad(view.pitch)));
        let (sg, cg) = (libm::sin(rad(view.roll)), libm::cos(rad(view.roll)));
        let a0 = V3::new(ca, 0.0, sa);
        let a1 = V3::new(sb * sa, cb, -sb * ca);
        let a2 = V3::new(-cb * sa, sb, cb * ca);
        let m0 = a0.scale(cg).add(a1.scale(-sg)).mul(spacing);
        let m1 = a0.scale(sg).add(a1.scale(cg)).mul(spacing);
        let m2 = a2.mul(spacing);

        // Perspective: camera distance D, the depth divisor
        // d = 1 - (m2 . q) / D (1 at the centre, > 0 in the whole box) and the
        // image radius of the bounding sphere with focal length D.
        let (dist, sphere_img) = match fov {
            None => (1.0, r),
            Some(_) if r <= 0.0 => (1.0, 0.0),
            Some(fov) => {
                let k = (1.0 / libm::sin(f64::from(fov).to_radians() * 0.5)).max(MIN_CAMERA_DISTANCE.into());
                let dist = r * k;
                (dist, dist * r / libm::sqrt(dist * dist - r * r))
            }
        };
        let wrow = m2.scale(-1.0 / dist);
        let divisor = |q: V3| if fov.is_some() { 1.0 + wrow.dot(q) } else { 1.0 };

        // The projected corners: extent and centre.
        let (mut umin, mut umax, mut wmin, mut wmax) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        let mut dmin = f64::MAX;
        for i in 0..8u8 {
            let pick = |bit: u8, a: f64, b: f64| if i & bit == 0 { a } else { b };
            let q = V3::new(pick(1, lo.x, hi.x), pick(2, lo.y, hi.y), pick(4, lo.z, hi.z));
            let d = divisor(q);
            let (u, w) = (m0.dot(q) / d, m1.dot(q) / d);
            (umin, umax, wmin, wmax) = (umin.min(u), umax.max(u), wmin.min(w), wmax.max(w));
            dmin = dmin.min(d);
        }
        let (ext, uc, wc) = match fit {
            Fit::Box => ((umax - umin).max(wmax - wmin) * 0.5, (umin + umax) * 0.5, (wmin + wmax) * 0.5),
            Fit::Sphere => (sphere_img, 0.0, 0.0),
        };
        // A box seen edge-on (or a point) has no extent to fit: fit its
        // bounding sphere instead.
        let ext = if ext > DEGENERATE * r { ext } else { sphere_img };
        if fov.is_some() && fit == Fit::Sphere {
            dmin = 1.0 - r / dist;
        }
        if !(ext.is_finite() && dmin.is_finite() && dmin > 0.0) {
            return Err(ViewError::Overflow);
        }

        // Rows at scale 1. Orthographic: x = m0 . q - uc. Perspective: the
        // numerator x * d with x = m0 . q / d - uc, i.e. (m0 + uc m2 / D) . q - uc.
        let (rx, ry) = match fov {
            None => (m0, m1),
            Some(_) => (m0.add(wrow.scale(-uc)), m1.add(wrow.scale(-wc))),
        };
        // The f32 guard: at least twice a first-order bound on the rounding of
        // `project` inside the box, in units of f32::EPSILON (two unit
        // roundoffs): about N (3 / dmin) for the numerator N, whose terms sum
        // to at most `scale * num1`, plus R (1.25 den / dmin + 1) for the
        // divisor (its error amplified by 1 / dmin) and the final additions.
        // The sphere fit uses rotation-invariant bounds (Cauchy-Schwarz:
        // sum |a_i| h_i <= r for a unit row a), so its scale is too.
        let range = f64::from(view.range());
        let eps = f64::from(f32::EPSILON);
        let (num1, den) = match fit {
            Fit::Box => (
                (rx.abs_dot(hv) + libm::fabs(uc)).max(ry.abs_dot(hv) + libm::fabs(wc)),
                wrow.abs_dot(hv) + 1.0,
            ),
            Fit::Sphere => (r, r / dist + 1.0),
        };
        let den = if fov.is_some() { den } else { 0.0 };
        let guard_fixed = eps * range * (3.0 * den / dmin + 2.0);
        let guard_per_scale = eps * 6.0 * num1 / dmin;
        let avail = (0.5 - f64::from(view.margin)) * range - guard_fixed;
        let scale = if ext > 0.0 { avail / (ext + guard_per_scale) } else { 1.0 };
        let scale = scale.max(0.0);

        let half = range * 0.5;
        let (sx, sy, depth) = match fov {
            None => (
                Row::of(rx.scale(scale), half - uc * scale),
                Row::of(ry.scale(scale), half - wc * scale),
                Row::of(V3::new(0.0, 0.0, 0.0), 1.0),
            ),
            Some(_) => (
                Row::of(rx.scale(scale), -uc * scale),
                Row::of(ry.scale(scale), -wc * scale),
                Row::of(wrow, 1.0),
            ),
        };
        let (Some(sx), Some(sy), Some(depth)) = (sx, sy, depth) else {
            return Err(ViewError::Overflow);
        };
        let scale32 = scale as f32;
        if !scale32.is_finite() {
            return Err(ViewError::Overflow);
        }
        Ok(Self {
            origin,
            sx,
            sy,
            depth,
            perspective: fov.is_some(),
            centre: half as f32,
            range: range as f32,
            scale: scale32,
        })
    }

    /// The screen position of a point in voxel coordinates, in DAC units.
    ///
    /// Points of the bounds land inside the margin; points outside them may
    /// land outside the DAC range (the beam scheduler clamps). A non-finite
    /// point, a point at or behind the perspective camera, or a projection
    /// that overflows gives `(NaN, NaN)`: test with `x.is_finite()`, or use
    /// [`ViewTransform::try_project`].
    #[inline]
    pub fn project(&self, p: Point3) -> ScreenPoint {
        self.try_project(p).unwrap_or(ScreenPoint::new(f32::NAN, f32::NAN))
    }

    /// The screen position of a point, or `None` where
    /// [`ViewTransform::project`] gives NaN.
    #[inline]
    pub fn try_project(&self, p: Point3) -> Option<ScreenPoint> {
        let s = self.project_raw(p);
        (s.x.is_finite() && s.y.is_finite()).then_some(s)
    }

    /// [`ViewTransform::project`] without the last check: a point behind
    /// the camera is NaN, one that overflows (or a NaN depth) infinite or
    /// NaN. For the beam
    /// scheduler, which skips both (and checks anyway): one check a point,
    /// not two.
    #[inline]
    pub(crate) fn project_raw(&self, p: Point3) -> ScreenPoint {
        let (qx, qy, qz) = (p.x - self.origin.x, p.y - self.origin.y, p.z - self.origin.z);
        let (mut x, mut y) = (self.sx.eval(qx, qy, qz), self.sy.eval(qx, qy, qz));
        if self.perspective {
            let d = self.depth.eval(qx, qy, qz);
            if d <= 0.0 {
                return ScreenPoint::new(f32::NAN, f32::NAN);
            }
            let inv = 1.0 / d;
            x = x * inv + self.centre;
            y = y * inv + self.centre;
        }
        ScreenPoint::new(x, y)
    }

    /// The same projection for points given in `1 / 2^shift` voxel (a
    /// surface store's fixed point), `shift <= 12`: the origin scaled up
    /// and the rows' coefficients down by the power of two, so that
    /// [`ViewTransform::project`] of a stored point's raw coordinates is
    /// bit for bit that of the point in voxels (a power of two scales
    /// every product and difference exactly), one multiplication a
    /// coordinate fewer.
    pub(crate) fn in_steps_of(&self, shift: u8) -> ViewTransform {
        let up = f32::from_bits((127 + u32::from(shift.min(12))) << 23);
        let down = f32::from_bits((127 - u32::from(shift.min(12))) << 23);
        let row = |r: Row| Row { x: r.x * down, y: r.y * down, z: r.z * down, w: r.w };
        ViewTransform {
            origin: Point3::new(self.origin.x * up, self.origin.y * up, self.origin.z * up),
            sx: row(self.sx),
            sy: row(self.sy),
            depth: row(self.depth),
            ..*self
        }
    }

    /// DAC units per physical unit (voxel size times spacing) at the depth
    /// of the centre of the bounds.
    pub fn scale(&self) -> f32 {
        self.scale
    }

    /// The DAC full scale, `2^bits - 1`: the screen spans `0.0 ..= range`.
    pub fn range(&self) -> f32 {
        self.range
    }

    /// Whether the projection is perspective.
    pub fn is_perspective(&self) -> bool {
        self.perspective
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const ORTHO: Projection = Projection::Orthographic;
    const PERSP: Projection = Projection::Perspective { fov_deg: 60.0 };

    fn view(yaw: f32, pitch: f32, roll: f32, projection: Projection) -> View {
        View { yaw, pitch, roll, projection, ..View::DEFAULT }
    }

    fn bounds(max: (f32, f32, f32)) -> Bounds {
        Bounds::new(Point3::new(0.0, 0.0, 0.0), Point3::new(max.0, max.1, max.2))
    }

    /// `(xmin, xmax, ymin, ymax)` of the projected corners, in `f64`.
    fn extent(t: &ViewTransform, b: Bounds) -> (f64, f64, f64, f64) {
        let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        for c in b.corners() {
            let s = t.try_project(c).expect("a corner projects");
            let (x, y) = (f64::from(s.x), f64::from(s.y));
            (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
        }
        (x0, x1, y0, y1)
    }

    /// The corners are inside the margin (within 1e-3 LSB); with `touch`,
    /// the picture is centred and one axis spans the whole usable range.
    fn check_fit(v: &View, b: Bounds, t: &ViewTransform, touch: bool) -> Result<(), TestCaseError> {
        let range = f64::from(v.range());
        let (lo, hi) = (f64::from(v.margin) * range, (1.0 - f64::from(v.margin)) * range);
        let (x0, x1, y0, y1) = extent(t, b);
        for e in [x0, x1, y0, y1] {
            prop_assert!(e >= lo - 1e-3 && e <= hi + 1e-3, "{e} outside {lo} ..= {hi}: {x0} {x1} {y0} {y1}");
        }
        if touch {
            let tol = 1e-3 + 1e-4 * range;
            prop_assert!(
                (x1 - x0).max(y1 - y0) >= hi - lo - tol,
                "not as large as possible: {x0} {x1} {y0} {y1}"
            );
            prop_assert!(((x0 + x1) * 0.5 - range * 0.5).abs() <= tol, "not centred in x: {x0} {x1}");
            prop_assert!(((y0 + y1) * 0.5 - range * 0.5).abs() <= tol, "not centred in y: {y0} {y1}");
        }
        Ok(())
    }

    /// The depth divisor of a point (perspective), 1 at the centre.
    fn depth(t: &ViewTransform, p: Point3) -> f32 {
        t.depth.eval(p.x - t.origin.x, p.y - t.origin.y, p.z - t.origin.z)
    }

    fn projection() -> impl Strategy<Value = Projection> {
        prop_oneof![Just(ORTHO), (1.0f32..179.0).prop_map(|fov_deg| Projection::Perspective { fov_deg })]
    }

    /// Any angle, with whole quarter turns (edge-on views) often.
    fn angle() -> impl Strategy<Value = f32> {
        prop_oneof![3 => -720.0f32..720.0, 1 => (-8i32..=8).prop_map(|k| k as f32 * 90.0)]
    }

    fn size() -> impl Strategy<Value = f32> {
        prop_oneof![1 => Just(0.0f32), 4 => 0.25f32..300.0]
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(2000))]

        #[test]
        fn corners_fill_the_usable_square(
            yaw in angle(), pitch in angle(), roll in angle(),
            projection in projection(), margin in 0.0f32..0.45, bits in 1u8..=16,
            min in (-1000.0f32..1000.0, -1000.0f32..1000.0, -1000.0f32..1000.0),
            size in (size(), size(), size()),
            spacing in (0.1f32..10.0, 0.1f32..10.0, 0.1f32..10.0),
            sphere in any::<bool>(),
        ) {
            let v = View { yaw, pitch, roll, projection, margin, bits, spacing: [spacing.0, spacing.1, spacing.2] };
            let b = Bounds::new(
                Point3::new(min.0, min.1, min.2),
                Point3::new(min.0 + size.0, min.1 + size.1, min.2 + size.2),
            );
            let t = if sphere { ViewTransform::fit_sphere(&v, b) } else { ViewTransform::fit(&v, b) }.unwrap();
            let zeros = [size.0, size.1, size.2].iter().filter(|s| **s == 0.0).count();
            // A line can be seen end-on (a point): no extent to fill then.
            check_fit(&v, b, &t, !sphere && zeros <= 1)?;
            if t.is_perspective() {
                for c in b.corners() {
                    prop_assert!(depth(&t, c) > 0.0);
                }
            }
            if zeros == 3 {
                let s = t.project(b.min);
                prop_assert!((s.x - t.centre).abs() < 1e-3 && (s.y - t.centre).abs() < 1e-3);
            }
        }

        #[test]
        fn ortho_centre_lands_on_screen_centre(
            yaw in angle(), pitch in angle(), roll in angle(),
            size in (size(), size(), size()),
            spacing in (0.1f32..10.0, 0.1f32..10.0, 0.1f32..10.0),
        ) {
            let v = View { spacing: [spacing.0, spacing.1, spacing.2], ..view(yaw, pitch, roll, ORTHO) };
            let b = bounds(size);
            let t = ViewTransform::fit(&v, b).unwrap();
            let s = t.project(b.centre());
            prop_assert!((s.x - 2047.5).abs() < 1e-3 && (s.y - 2047.5).abs() < 1e-3, "{s:?}");
        }

        /// A store's raw fixed-point coordinates through the transform
        /// scaled to them project bit for bit as the points in voxels.
        #[test]
        fn steps_of_a_store_project_bit_for_bit(
            yaw in angle(), pitch in angle(), roll in angle(), projection in projection(),
            dims in (2u16..600, 2u16..600, 2u16..600),
            q in (any::<u16>(), any::<u16>(), any::<u16>()),
        ) {
            let v = view(yaw, pitch, roll, projection);
            let top = |d: u16| f32::from(d - 1);
            let b = Bounds::new(Point3::new(0.0, 0.0, 0.0), Point3::new(top(dims.0), top(dims.1), top(dims.2)));
            let t = ViewTransform::fit(&v, b).unwrap();
            let shift = crate::path::Geometry::shift_for([dims.0, dims.1, dims.2]);
            let k = f32::from_bits((127 - u32::from(shift)) << 23);
            let voxels = Point3::new(f32::from(q.0) * k, f32::from(q.1) * k, f32::from(q.2) * k);
            let raw = Point3::new(f32::from(q.0), f32::from(q.1), f32::from(q.2));
            let (a, s) = (t.project_raw(voxels), t.in_steps_of(shift).project_raw(raw));
            prop_assert_eq!((a.x.to_bits(), a.y.to_bits()), (s.x.to_bits(), s.y.to_bits()), "{:?} vs {:?}", a, s);
        }

        /// Valid but extreme inputs: any finite bounds, angles and spacings.
        #[test]
        fn extreme_valid_inputs_fit_or_overflow(
            angles in prop::array::uniform3(prop::num::f32::NORMAL | prop::num::f32::ZERO | prop::num::f32::SUBNORMAL),
            a in prop::array::uniform3(prop::num::f32::NORMAL | prop::num::f32::ZERO | prop::num::f32::SUBNORMAL),
            b in prop::array::uniform3(prop::num::f32::NORMAL | prop::num::f32::ZERO | prop::num::f32::SUBNORMAL),
            spacing in prop::array::uniform3(prop::num::f32::POSITIVE | prop::num::f32::NORMAL | prop::num::f32::SUBNORMAL),
            projection in projection(), bits in 1u8..=16, sphere in any::<bool>(),
        ) {
            let v = View { yaw: angles[0], pitch: angles[1], roll: angles[2], projection, bits, spacing, margin: 0.05 };
            let bx = Bounds::new(
                Point3::new(a[0].min(b[0]), a[1].min(b[1]), a[2].min(b[2])),
                Point3::new(a[0].max(b[0]), a[1].max(b[1]), a[2].max(b[2])),
            );
            let t = if sphere { ViewTransform::fit_sphere(&v, bx) } else { ViewTransform::fit(&v, bx) };
            match t {
                Ok(t) => check_fit(&v, bx, &t, false)?,
                Err(e) => prop_assert_eq!(e, ViewError::Overflow),
            }
        }

        /// Anything at all: never a panic; a result is finite or NaN.
        #[test]
        fn no_panic_on_any_f32(
            angles in prop::array::uniform3(prop::num::f32::ANY),
            fov in prop::num::f32::ANY, persp in any::<bool>(),
            margin in prop_oneof![Just(0.05f32), prop::num::f32::ANY],
            bits in any::<u8>(),
            spacing in prop::array::uniform3(prop_oneof![Just(1.0f32), prop::num::f32::ANY]),
            a in prop::array::uniform3(prop::num::f32::ANY),
            b in prop::array::uniform3(prop::num::f32::ANY),
            points in prop::collection::vec(prop::array::uniform3(prop::num::f32::ANY), 8),
            yawed in prop::num::f32::ANY,
        ) {
            let projection = if persp { Projection::Perspective { fov_deg: fov } } else { ORTHO };
            let v = View { yaw: angles[0], pitch: angles[1], roll: angles[2], projection, margin, bits, spacing }
                .yawed(yawed);
            let bx = Bounds::new(Point3::new(a[0], a[1], a[2]), Point3::new(b[0], b[1], b[2]));
            for t in [ViewTransform::fit(&v, bx), ViewTransform::fit_sphere(&v, bx)].into_iter().flatten() {
                for p in points.iter().map(|p| Point3::new(p[0], p[1], p[2])).chain(bx.corners()) {
                    let s = t.project(p);
                    prop_assert!((s.x.is_finite() && s.y.is_finite()) || (s.x.is_nan() && s.y.is_nan()));
                    prop_assert_eq!(t.try_project(p).is_some(), s.x.is_finite());
                }
            }
        }

        /// The bounding-sphere fit does not depend on the angles.
        #[test]
        fn sphere_fit_scale_is_rotation_invariant(
            yaw in -360.0f32..360.0, pitch in -360.0f32..360.0, projection in projection(),
            size in (size(), size(), 0.25f32..100.0),
        ) {
            let b = bounds(size);
            let t0 = ViewTransform::fit_sphere(&view(0.0, 0.0, 0.0, projection), b).unwrap();
            let t1 = ViewTransform::fit_sphere(&view(yaw, pitch, 0.0, projection), b).unwrap();
            prop_assert!((t0.scale() - t1.scale()).abs() <= 1e-5 * t0.scale());
        }
    }

    #[test]
    fn identity_view_axes() {
        for projection in [ORTHO, PERSP] {
            let b = Bounds::of_volume(20, 20, 20).unwrap();
            let t = ViewTransform::fit(&View { projection, ..View::FRONT }, b).unwrap();
            let p = t.project(Point3::new(10.0, 10.0, 10.0));
            let px = t.project(Point3::new(11.0, 10.0, 10.0));
            let py = t.project(Point3::new(10.0, 11.0, 10.0));
            assert!(px.x > p.x + 1.0 && px.y == p.y, "{p:?} {px:?}");
            assert!(py.y > p.y + 1.0 && py.x == p.x, "{p:?} {py:?}");
            if projection == ORTHO {
                // z is the depth: no change at all.
                assert_eq!(t.project(Point3::new(10.0, 10.0, 13.0)), p);
                assert_eq!(t.project(Point3::new(3.0, 7.0, -5.0)), t.project(Point3::new(3.0, 7.0, 19.0)));
            } else {
                // The viewer is on the +z side.
                assert!(depth(&t, Point3::new(10.0, 10.0, 19.0)) < depth(&t, Point3::new(10.0, 10.0, 0.0)));
            }
        }
    }

    #[test]
    fn aspect_kept() {
        let v = View::FRONT;
        let usable = (1.0 - 2.0 * 0.05) * 4095.0;
        // 100 x 50 x 1 samples span 99 x 49 voxel spacings.
        let b = Bounds::of_volume(100, 50, 1).unwrap();
        let t = ViewTransform::fit(&v, b).unwrap();
        let (x0, x1, y0, y1) = extent(&t, b);
        // Fills the width up to the f32 guard (a few ulps of the range).
        assert!(((x1 - x0) - usable).abs() < 1e-2, "{x0} {x1}");
        assert!(((x1 - x0) / (y1 - y0) - 99.0 / 49.0).abs() < 1e-5, "{x0} {x1} {y0} {y1}");
        // A box exactly 100 x 50 x 0.
        let b = bounds((100.0, 50.0, 0.0));
        let t = ViewTransform::fit(&v, b).unwrap();
        let (x0, x1, y0, y1) = extent(&t, b);
        assert!(((x1 - x0) / (y1 - y0) - 2.0).abs() < 1e-5, "{x0} {x1} {y0} {y1}");
        assert!(((y0 + y1) * 0.5 - 2047.5).abs() < 1e-3);
        // Standing up: 50 x 100 fills the height.
        let b = bounds((50.0, 100.0, 0.0));
        let (x0, x1, y0, y1) = extent(&ViewTransform::fit(&v, b).unwrap(), b);
        assert!(((y1 - y0) - usable).abs() < 1e-2 && ((y1 - y0) / (x1 - x0) - 2.0).abs() < 1e-5);
    }

    #[test]
    fn yaw_pitch_roll_follow_the_right_hand_rule() {
        let b = Bounds::of_volume(21, 21, 21).unwrap();
        let c = Point3::new(10.0, 10.0, 10.0);
        let step = |t: &ViewTransform, dx: f32, dy: f32, dz: f32| {
            let (a, p) = (t.project(c), t.project(Point3::new(c.x + dx, c.y + dy, c.z + dz)));
            (p.x - a.x, p.y - a.y)
        };
        // Yaw 90: x becomes the depth (away from the viewer), +z goes right.
        let t = ViewTransform::fit(&view(90.0, 0.0, 0.0, ORTHO), b).unwrap();
        let (dx, dy) = step(&t, 5.0, 0.0, 0.0);
        assert!(dx.abs() < 1e-3 && dy.abs() < 1e-3, "{dx} {dy}");
        let (dx, dy) = step(&t, 0.0, 0.0, 5.0);
        assert!(dx > 100.0 && dy.abs() < 1e-3, "{dx} {dy}");
        let tp = ViewTransform::fit(&view(90.0, 0.0, 0.0, PERSP), b).unwrap();
        assert!(depth(&tp, Point3::new(20.0, 10.0, 10.0)) > depth(&tp, Point3::new(0.0, 10.0, 10.0)));
        // Small positive yaw: the +x end recedes and +z moves right.
        let tp = ViewTransform::fit(&view(10.0, 0.0, 0.0, PERSP), b).unwrap();
        assert!(depth(&tp, Point3::new(20.0, 10.0, 10.0)) > depth(&tp, Point3::new(0.0, 10.0, 10.0)));
        let t = ViewTransform::fit(&view(10.0, 0.0, 0.0, ORTHO), b).unwrap();
        assert!(step(&t, 0.0, 0.0, 5.0).0 > 0.0);
        // Pitch 90: y becomes the depth (the top comes towards the viewer),
        // +z goes down.
        let t = ViewTransform::fit(&view(0.0, 90.0, 0.0, ORTHO), b).unwrap();
        let (dx, dy) = step(&t, 0.0, 5.0, 0.0);
        assert!(dx.abs() < 1e-3 && dy.abs() < 1e-3, "{dx} {dy}");
        let (dx, dy) = step(&t, 0.0, 0.0, 5.0);
        assert!(dx.abs() < 1e-3 && dy < -100.0, "{dx} {dy}");
        let tp = ViewTransform::fit(&view(0.0, 20.0, 0.0, PERSP), b).unwrap();
        assert!(depth(&tp, Point3::new(10.0, 20.0, 10.0)) < depth(&tp, Point3::new(10.0, 0.0, 10.0)));
        // Roll 90: counter-clockwise, +x goes up.
        let t = ViewTransform::fit(&view(0.0, 0.0, 90.0, ORTHO), b).unwrap();
        let (dx, dy) = step(&t, 5.0, 0.0, 0.0);
        assert!(dx.abs() < 1e-3 && dy > 100.0, "{dx} {dy}");
        // Yaw before pitch: yaw 90 then pitch 90 puts +z (now along +X)
        // unchanged on the right; pitch first would have sent it down.
        let t = ViewTransform::fit(&view(90.0, 90.0, 0.0, ORTHO), b).unwrap();
        let (dx, dy) = step(&t, 0.0, 0.0, 5.0);
        assert!(dx > 100.0 && dy.abs() < 1e-3, "{dx} {dy}");
    }

    #[test]
    fn default_view_shows_front_left_and_top_faces() {
        let b = Bounds::of_volume(21, 21, 21).unwrap();
        let v = View { projection: PERSP, ..View::default() };
        assert_eq!((v.yaw, v.pitch, v.roll, v.margin, v.bits), (30.0, 20.0, 0.0, 0.05, 12));
        let t = ViewTransform::fit(&v, b).unwrap();
        // A face is visible when its centre is nearer than the opposite one.
        let nearer = |a: (f32, f32, f32), b: (f32, f32, f32)| {
            depth(&t, Point3::new(a.0, a.1, a.2)) < depth(&t, Point3::new(b.0, b.1, b.2))
        };
        assert!(nearer((10.0, 10.0, 20.0), (10.0, 10.0, 0.0)), "front (+z)");
        assert!(nearer((0.0, 10.0, 10.0), (20.0, 10.0, 10.0)), "left (-x)");
        assert!(nearer((10.0, 20.0, 10.0), (10.0, 0.0, 10.0)), "top (+y)");
    }

    #[test]
    fn perspective_makes_near_edges_longer() {
        let b = Bounds::of_volume(11, 11, 11).unwrap();
        for (yaw, pitch) in [(0.0, 0.0), (0.0, 20.0), (0.0, -35.0), (180.0, 10.0)] {
            let t = ViewTransform::fit(&view(yaw, pitch, 0.0, PERSP), b).unwrap();
            // The four x edges stay parallel to the screen under yaw 0/180
            // and any pitch.
            let mut edges: Vec<(f32, f32)> = [(0.0, 0.0), (10.0, 0.0), (0.0, 10.0), (10.0, 10.0)]
                .iter()
                .map(|&(y, z)| {
                    let (a, e) = (Point3::new(0.0, y, z), Point3::new(10.0, y, z));
                    for p in [a, e] {
                        assert!(depth(&t, p) > 0.0);
                    }
                    (depth(&t, a), t.project(a).distance(t.project(e)))
                })
                .collect();
            edges.sort_by(|a, b| a.0.total_cmp(&b.0));
            for w in edges.windows(2) {
                assert!(w[0].0 == w[1].0 || w[0].1 > w[1].1, "{yaw} {pitch}: {edges:?}");
            }
            assert!(edges[0].1 > edges[3].1 * 1.1, "{yaw} {pitch}: {edges:?}");
        }
        // Orthographic: all equal.
        let t = ViewTransform::fit(&view(0.0, 20.0, 0.0, ORTHO), b).unwrap();
        let near = t.project(Point3::new(0.0, 0.0, 10.0)).distance(t.project(Point3::new(10.0, 0.0, 10.0)));
        let far = t.project(Point3::new(0.0, 0.0, 0.0)).distance(t.project(Point3::new(10.0, 0.0, 0.0)));
        assert!((near - far).abs() < 1e-3);
    }

    #[test]
    fn spacing_is_honoured() {
        let aniso = bounds((10.0, 10.0, 10.0));
        let iso = bounds((10.0, 10.0, 20.0));
        for projection in [ORTHO, PERSP] {
            for (yaw, pitch, roll) in
                [(0.0, 0.0, 0.0), (30.0, 20.0, 0.0), (90.0, 0.0, 0.0), (-70.0, 55.0, 12.0)]
            {
                let v = view(yaw, pitch, roll, projection);
                let t_iso = ViewTransform::fit(&v, iso).unwrap();
                let t_aniso = ViewTransform::fit(&View { spacing: [1.0, 1.0, 2.0], ..v }, aniso).unwrap();
                assert_eq!(extent(&t_iso, iso), extent(&t_aniso, aniso));
                for (a, i) in aniso.corners().into_iter().zip(iso.corners()) {
                    let (sa, si) = (t_aniso.project(a), t_iso.project(i));
                    assert!(sa.distance(si) < 1e-3, "{v:?}: {sa:?} {si:?}");
                }
                assert!((t_iso.scale() - t_aniso.scale()).abs() < 1e-6 * t_iso.scale());
            }
        }
    }

    #[test]
    fn flat_grids_and_points() {
        // A 2D grid (nz = 1), face-on, at the default view and edge-on.
        let b = Bounds::of_volume(64, 32, 1).unwrap();
        for v in [View::FRONT, View::DEFAULT, view(90.0, 0.0, 0.0, ORTHO), view(0.0, 90.0, 0.0, PERSP)] {
            let t = ViewTransform::fit(&v, b).unwrap();
            check_fit(&v, b, &t, true).unwrap();
        }
        // Edge-on from yaw 90: a vertical line filling the height.
        let t = ViewTransform::fit(&view(90.0, 0.0, 0.0, ORTHO), b).unwrap();
        let (x0, x1, y0, y1) = extent(&t, b);
        assert!(x1 - x0 < 1e-3 && ((y1 - y0) - 0.9 * 4095.0).abs() < 1e-2);
        // A line seen end-on and a single point land on the centre.
        let line = Bounds::of_volume(64, 1, 1).unwrap();
        let point = Bounds::new(Point3::new(3.0, -4.0, 5.5), Point3::new(3.0, -4.0, 5.5));
        for (b, yaw) in [(line, 90.0), (point, 30.0)] {
            for projection in [ORTHO, PERSP] {
                let v = view(yaw, 0.0, 0.0, projection);
                for t in [ViewTransform::fit(&v, b).unwrap(), ViewTransform::fit_sphere(&v, b).unwrap()] {
                    for c in b.corners() {
                        let s = t.project(c);
                        assert!((s.x - 2047.5).abs() < 1e-3 && (s.y - 2047.5).abs() < 1e-3, "{s:?}");
                    }
                }
            }
        }
    }

    #[test]
    fn non_finite_and_behind_camera_give_nan() {
        let b = Bounds::of_volume(10, 10, 10).unwrap();
        for projection in [ORTHO, PERSP] {
            let t = ViewTransform::fit(&view(30.0, 20.0, 0.0, projection), b).unwrap();
            for p in [
                Point3::new(f32::NAN, 1.0, 1.0),
                Point3::new(1.0, f32::INFINITY, 1.0),
                Point3::new(1.0, 1.0, f32::NEG_INFINITY),
                Point3::new(3e38, -3e38, 3e38),
            ] {
                let s = t.project(p);
                assert!(s.x.is_nan() && s.y.is_nan(), "{s:?}");
                assert_eq!(t.try_project(p), None);
            }
        }
        // Far along +z at the front view is behind the perspective camera.
        let t = ViewTransform::fit(&View { projection: PERSP, ..View::FRONT }, b).unwrap();
        assert_eq!(t.try_project(Point3::new(4.5, 4.5, 1000.0)), None);
        assert!(t.try_project(Point3::new(4.5, 4.5, -1000.0)).is_some());
        // Outside the bounds is allowed to leave the DAC range.
        let t = ViewTransform::fit(&View::FRONT, b).unwrap();
        assert!(t.project(Point3::new(100.0, 4.5, 0.0)).x > t.range());
    }

    #[test]
    fn errors() {
        let b = Bounds::of_volume(4, 4, 4).unwrap();
        let ok = View::DEFAULT;
        let fit = |v: View| ViewTransform::fit(&v, b).err();
        for a in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            assert_eq!(fit(View { yaw: a, ..ok }), Some(ViewError::NonFiniteAngle));
            assert_eq!(fit(View { pitch: a, ..ok }), Some(ViewError::NonFiniteAngle));
            assert_eq!(fit(View { roll: a, ..ok }), Some(ViewError::NonFiniteAngle));
        }
        for fov_deg in [0.0, -0.0, -10.0, 180.0, 200.0, f32::NAN, f32::INFINITY] {
            let v = View { projection: Projection::Perspective { fov_deg }, ..ok };
            assert_eq!(fit(v), Some(ViewError::InvalidFieldOfView), "{fov_deg}");
        }
        for margin in [-0.01, 0.5, 0.7, f32::NAN, f32::INFINITY] {
            assert_eq!(fit(View { margin, ..ok }), Some(ViewError::InvalidMargin), "{margin}");
        }
        for bits in [0, 17, 255] {
            assert_eq!(fit(View { bits, ..ok }), Some(ViewError::InvalidBits { bits }));
        }
        for s in [0.0, -1.0, f32::NAN, f32::INFINITY] {
            assert_eq!(fit(View { spacing: [1.0, s, 1.0], ..ok }), Some(ViewError::InvalidSpacing), "{s}");
        }
        let nan = Bounds::new(Point3::new(0.0, f32::NAN, 0.0), Point3::new(1.0, 1.0, 1.0));
        let inf = Bounds::new(Point3::new(0.0, 0.0, 0.0), Point3::new(1.0, 1.0, f32::INFINITY));
        assert_eq!(ViewTransform::fit(&ok, nan), Err(ViewError::NonFiniteBounds));
        assert_eq!(ViewTransform::fit_sphere(&ok, inf), Err(ViewError::NonFiniteBounds));
        let inverted = Bounds::new(Point3::new(0.0, 2.0, 0.0), Point3::new(1.0, 1.0, 1.0));
        assert_eq!(ViewTransform::fit(&ok, inverted), Err(ViewError::EmptyBounds));
        assert_eq!(Bounds::of_volume(4, 0, 4), Err(ViewError::EmptyBounds));
        // Too small to scale up in f32.
        let tiny = Bounds::new(Point3::new(0.0, 0.0, 0.0), Point3::new(1e-44, 1e-44, 1e-44));
        assert_eq!(ViewTransform::fit(&ok, tiny), Err(ViewError::Overflow));
        // Every variant displays.
        for e in [
            ViewError::NonFiniteAngle,
            ViewError::InvalidFieldOfView,
            ViewError::InvalidMargin,
            ViewError::InvalidBits { bits: 0 },
            ViewError::InvalidSpacing,
            ViewError::NonFiniteBounds,
            ViewError::EmptyBounds,
            ViewError::Overflow,
        ] {
            assert!(!e.to_string().is_empty());
        }
    }
}
