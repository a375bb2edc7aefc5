//! A volume file's orientation, reduced to what the pipeline can use: which
//! index axis of the file runs along each display axis, which way, and the
//! voxel spacing.
//!
//! The display axes are those of the core's 3D view (`core/src/view`): x to
//! the right of the screen, y up, z out of the screen towards the viewer.
//!
//! - A file in an anatomical space ([`Space::Ras`]: a NIfTI sform or qform,
//!   NRRD's `space: RAS`, `LPS` or `LAS`) is shown as a person facing the
//!   viewer: superior up (display +y), anterior towards the viewer (display
//!   +z), and so, for a right-handed frame and no mirror image, the person's
//!   left to the screen's right (display +x). The default view (yaw 30°,
//!   pitch 20°) then shows a head upright, its face turned a little to the
//!   right, seen from a little above.
//! - A file in a plain space ([`Space::Xyz`]: NRRD's `scanner-xyz` and
//!   other non-anatomical spaces, a cube file's axis vectors) is shown with
//!   its x, y and z along the display's.
//!
//! [`reduce`] takes the direction of each index axis (a column of the
//! file's affine without the offset), normalises it, and of the six ways to
//! give each display axis an index axis of its own takes the one whose
//! directions lie closest to the display axes (the largest sum of
//! `|cos|`; on a tie, the first of [`PERMUTATIONS`], which starts with the
//! identity), reversing an axis whose direction points against its display
//! axis. An oblique volume is thus shown along its nearest axes, not
//! resampled. The spacing is the length of each direction.
//!
//! Directions that are not finite, zero, (nearly) coplanar, or too long or
//! short for an `f32` voxel size are an [`OrientError`], never a panic; the
//! readers then keep the file's index order and say why.

use std::fmt;

/// The space a file's directions are given in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Space {
    /// Anatomical: x towards the person's right, y anterior, z superior
    /// (RAS+, NIfTI's world space).
    Ras,
    /// Plain x, y, z, shown as the display's.
    Xyz,
}

impl Space {
    /// A direction in this space in display coordinates.
    fn to_display(self, v: [f64; 3]) -> [f64; 3] {
        match self {
            // Display x = left = -R, y = superior, z = anterior.
            Space::Ras => [-v[0], v[2], v[1]],
            Space::Xyz => v,
        }
    }

    /// What display axis `d` is in this space, going `+` or `-`.
    fn axis_name(self, d: usize, negative: bool) -> &'static str {
        match (self, d, negative) {
            (Space::Ras, 0, false) => "left",
            (Space::Ras, 0, true) => "right",
            (Space::Ras, 1, false) => "superior",
            (Space::Ras, 1, true) => "inferior",
            (Space::Ras, _, false) => "anterior",
            (Space::Ras, _, true) => "posterior",
            (Space::Xyz, 0, false) => "+x",
            (Space::Xyz, 0, true) => "-x",
            (Space::Xyz, 1, false) => "+y",
            (Space::Xyz, 1, true) => "-y",
            (Space::Xyz, _, false) => "+z",
            (Space::Xyz, _, true) => "-z",
        }
    }
}

/// Where a file's index axes point: `columns[i]` is the step in space (in
/// the file's unit) from one voxel to the next along index axis `i` (i
/// fastest in the file, then j, then k).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Directions {
    /// The space of the columns.
    pub space: Space,
    /// The direction of index axes i, j and k.
    pub columns: [[f64; 3]; 3],
}

/// The six permutations of three axes, the identity first: the order in
/// which [`reduce`] breaks a tie.
pub const PERMUTATIONS: [[usize; 3]; 6] = [[0, 1, 2], [0, 2, 1], [1, 0, 2], [1, 2, 0], [2, 0, 1], [2, 1, 0]];

/// A rearrangement of a volume's axes: axis `d` of the result runs along
/// axis `from()[d]` of the original, reversed where `flip()[d]`. Always a
/// permutation (so applying it never loses or repeats a sample).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct AxisMap {
    from: [usize; 3],
    flip: [bool; 3],
}

impl AxisMap {
    /// Every axis where it was.
    pub const IDENTITY: AxisMap = AxisMap { from: [0, 1, 2], flip: [false; 3] };

    /// The map taking axis `from[d]` to axis `d`, reversed where `flip[d]`;
    /// `None` unless `from` is a permutation of 0, 1, 2.
    pub fn new(from: [usize; 3], flip: [bool; 3]) -> Option<AxisMap> {
        let mut seen = [false; 3];
        for &a in &from {
            *seen.get_mut(a)? = true;
        }
        seen.iter().all(|&s| s).then_some(AxisMap { from, flip })
    }

    /// The map that puts original axis `i` at axis `to[i]`, none reversed
    /// (data stored along permuted axes, such as an MRC map's or a cube
    /// file's); `None` unless `to` is a permutation.
    pub fn placing(to: [usize; 3]) -> Option<AxisMap> {
        AxisMap::new(to, [false; 3])?;
        let mut from = [0; 3];
        for (i, &d) in to.iter().enumerate() {
            *from.get_mut(d)? = i;
        }
        AxisMap::new(from, [false; 3])
    }

    /// For each axis of the result, the original axis it runs along.
    pub fn from(&self) -> [usize; 3] {
        self.from
    }

    /// For each axis of the result, whether it runs against the original.
    pub fn flip(&self) -> [bool; 3] {
        self.flip
    }

    /// Whether it leaves every axis where it was.
    pub fn is_identity(&self) -> bool {
        *self == AxisMap::IDENTITY
    }

    /// `x = -i, y = k, z = j`: each axis of the result as the original
    /// index axis it runs along.
    pub fn describe(&self) -> String {
        let ijk = ["i", "j", "k"];
        ["x", "y", "z"]
            .iter()
            .zip(self.from.iter().zip(&self.flip))
            .map(|(d, (&a, &f))| format!("{d} = {}{}", if f { "-" } else { "" }, ijk.get(a).unwrap_or(&"?")))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// A file's orientation as the pipeline uses it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Oriented {
    /// How to rearrange the file's index axes into display axes.
    pub map: AxisMap,
    /// The voxel size along each index axis of the file (the lengths of
    /// the directions), before the rearrangement.
    pub spacing: [f32; 3],
    /// The space the directions were in.
    pub space: Space,
}

impl Oriented {
    /// What each display axis shows, for a note: `x = -i (left), y = k
    /// (superior), z = j (anterior)`.
    pub fn describe(&self) -> String {
        let ijk = ["i", "j", "k"];
        let (from, flip) = (self.map.from(), self.map.flip());
        (0..3)
            .map(|d| {
                format!(
                    "{} = {}{} ({})",
                    ["x", "y", "z"][d],
                    if flip[d] { "-" } else { "" },
                    ijk.get(from[d]).unwrap_or(&"?"),
                    self.space.axis_name(d, false)
                )
            })
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// Why a file's directions cannot orient it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum OrientError {
    /// A direction has a NaN or infinite component.
    NotFinite {
        /// The index axis (0 = i).
        axis: usize,
    },
    /// A direction is zero.
    Zero {
        /// The index axis (0 = i).
        axis: usize,
    },
    /// A direction's length is no `f32` voxel size (too large or too small).
    Length {
        /// The index axis (0 = i).
        axis: usize,
        /// Its length.
        length: f64,
    },
    /// The directions are (nearly) coplanar: they span no volume.
    Degenerate {
        /// The determinant of the normalised directions (1 for orthogonal
        /// ones).
        det: f64,
    },
}

impl fmt::Display for OrientError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let name = |a: usize| ["i", "j", "k"].get(a).copied().unwrap_or("?");
        match *self {
            OrientError::NotFinite { axis } => {
                write!(f, "the direction of index axis {} is not finite", name(axis))
            }
            OrientError::Zero { axis } => write!(f, "the direction of index axis {} is zero", name(axis)),
            OrientError::Length { axis, length } => write!(
                f,
                "the direction of index axis {} is {length:e} long, which is no voxel size",
                name(axis)
            ),
            OrientError::Degenerate { det } => write!(
                f,
                "the directions of the index axes are (nearly) coplanar (determinant {det:.2e} of the unit \
                 directions, 1 for perpendicular ones)"
            ),
        }
    }
}

impl std::error::Error for OrientError {}

/// Unit directions whose determinant is smaller than this span no volume.
const MIN_DET: f64 = 1e-3;

/// The length of `v` without overflow for any finite components.
fn length(v: [f64; 3]) -> f64 {
    let m = v.iter().fold(0f64, |m, x| m.max(x.abs()));
    if m == 0.0 {
        return 0.0;
    }
    m * v.iter().map(|x| (x / m) * (x / m)).sum::<f64>().sqrt()
}

/// Reduce a file's directions to the rearrangement of its index axes that
/// brings it closest to the display axes (see the [module
/// documentation](self)), and the voxel spacing.
///
/// # Errors
/// An [`OrientError`] for directions that are not finite, zero, too long
/// or short for an `f32` voxel size, or (nearly) coplanar.
pub fn reduce(d: &Directions) -> Result<Oriented, OrientError> {
    let mut unit = [[0f64; 3]; 3];
    let mut spacing = [1f32; 3];
    for (axis, col) in d.columns.iter().enumerate() {
        if col.iter().any(|x| !x.is_finite()) {
            return Err(OrientError::NotFinite { axis });
        }
        let len = length(*col);
        if len == 0.0 {
            return Err(OrientError::Zero { axis });
        }
        let s = len as f32;
        if !(s.is_finite() && s.is_normal()) {
            return Err(OrientError::Length { axis, length: len });
        }
        spacing[axis] = s;
        unit[axis] = d.space.to_display(col.map(|x| x / len));
    }
    // unit[i][c]: display component c of index axis i's direction.
    let det = unit[0][0] * (unit[1][1] * unit[2][2] - unit[1][2] * unit[2][1])
        - unit[0][1] * (unit[1][0] * unit[2][2] - unit[1][2] * unit[2][0])
        + unit[0][2] * (unit[1][0] * unit[2][1] - unit[1][1] * unit[2][0]);
    if det.abs() < MIN_DET {
        return Err(OrientError::Degenerate { det });
    }
    let score = |p: &[usize; 3]| (0..3).map(|c| unit[p[c]][c].abs()).sum::<f64>();
    let mut best = PERMUTATIONS[0];
    for p in &PERMUTATIONS[1..] {
        if score(p) > score(&best) {
            best = *p;
        }
    }
    let flip = [0, 1, 2].map(|c| unit[best[c]][c] < 0.0);
    let map = AxisMap::new(best, flip).ok_or(OrientError::Degenerate { det })?;
    Ok(Oriented { map, spacing, space: d.space })
}

/// The directions of a NIfTI-1 qform (nifti1.h, method 2): the unit
/// quaternion `(b, c, d)` (`a` from them; renormalised when
/// `b² + c² + d²` is 1 or more, as nifti1_io does), the voxel sizes
/// `pixdim[1..=3]` (a size that is not positive counts as 1, as there) and
/// `qfac`, the sign of `pixdim[0]` (negative reverses k).
pub fn qform_directions(quatern: [f64; 3], pixdim: [f64; 4]) -> Directions {
    let [mut b, mut c, mut d] = quatern;
    let sum = b * b + c * c + d * d;
    let a = if 1.0 - sum < 1e-7 {
        let n = length([b, c, d]);
        (b, c, d) = (b / n, c / n, d / n);
        0.0
    } else {
        (1.0 - sum).sqrt()
    };
    let r = [
        [a * a + b * b - c * c - d * d, 2.0 * (b * c - a * d), 2.0 * (b * d + a * c)],
        [2.0 * (b * c + a * d), a * a + c * c - b * b - d * d, 2.0 * (c * d - a * b)],
        [2.0 * (b * d - a * c), 2.0 * (c * d + a * b), a * a + d * d - c * c - b * b],
    ];
    let size = |v: f64| if v > 0.0 { v } else { 1.0 };
    let qfac = if pixdim[0] < 0.0 { -1.0 } else { 1.0 };
    let scale = [size(pixdim[1]), size(pixdim[2]), size(pixdim[3]) * qfac];
    let columns = [0, 1, 2].map(|i| [r[0][i] * scale[i], r[1][i] * scale[i], r[2][i] * scale[i]]);
    Directions { space: Space::Ras, columns }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ras(columns: [[f64; 3]; 3]) -> Directions {
        Directions { space: Space::Ras, columns }
    }

    fn map(from: [usize; 3], flip: [bool; 3]) -> AxisMap {
        AxisMap::new(from, flip).unwrap()
    }

    const EYE: [[f64; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

    #[test]
    fn identity_in_plain_space_stays() {
        let o = reduce(&Directions { space: Space::Xyz, columns: EYE }).unwrap();
        assert!(o.map.is_identity());
        assert_eq!(o.spacing, [1.0; 3]);
    }

    /// A RAS-ordered volume (i right, j anterior, k superior) is shown with
    /// the person's left to the right, superior up, anterior towards the
    /// viewer: x = -i, y = k, z = j; the spacing stays per index axis.
    #[test]
    fn ras_identity_faces_the_viewer() {
        let o = reduce(&ras([[1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 3.0]])).unwrap();
        assert_eq!(o.map, map([0, 2, 1], [true, false, false]));
        assert_eq!(o.spacing, [1.0, 2.0, 3.0]);
        assert_eq!(o.describe(), "x = -i (left), y = k (superior), z = j (anterior)");
        assert_eq!(o.map.describe(), "x = -i, y = k, z = j");
    }

    /// NRRD's LPS (DICOM's frame): i towards the left, j posterior, k
    /// superior; given in RAS as the reader converts it (x and y negated).
    #[test]
    fn lps_nrrd() {
        // In LPS: (1,0,0) (0,1,0) (0,0,1); in RAS: (-1,0,0) (0,-1,0) (0,0,1).
        let o = reduce(&ras([[-1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]])).unwrap();
        assert_eq!(o.map, map([0, 2, 1], [false, false, true]));
    }

    /// The already shown-as-a-face layout (i left, j superior, k anterior:
    /// ITK's coronal KmeansTest head) is left alone.
    #[test]
    fn left_superior_anterior_is_the_identity() {
        let o = reduce(&ras([[-2.0, 0.0, 0.0], [0.0, 0.0, 2.0], [0.0, 3.0, 0.0]])).unwrap();
        assert!(o.map.is_identity(), "{:?}", o.map);
        assert_eq!(o.spacing, [2.0, 2.0, 3.0]);
    }

    /// A qform turning the volume by 90° about z (i anterior, j left), and
    /// 180° about (1,1,0) (i → y, j → x, k → -z), with qfac -1.
    #[test]
    fn rotated_qforms() {
        let h = std::f64::consts::FRAC_1_SQRT_2;
        // 90° about z: quaternion (cos 45°, 0, 0, sin 45°).
        let d = qform_directions([0.0, 0.0, h], [1.0, 1.0, 1.0, 1.0]);
        for (c, want) in d.columns.iter().zip([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]) {
            for (x, w) in c.iter().zip(want) {
                assert!((x - w).abs() < 1e-12, "{:?}", d.columns);
            }
        }
        // i anterior (z), j left (x), k superior (y).
        assert_eq!(reduce(&d).unwrap().map, map([1, 2, 0], [false; 3]));
        // b = c = 1/√2 (a = 0): i → +A... as the rotation matrix says:
        // columns (0,1,0), (1,0,0), (0,0,-1), then qfac -1 reverses k to +S.
        let d = qform_directions([h, h, 0.0], [-1.0, 2.0, 2.0, 3.0]);
        let o = reduce(&d).unwrap();
        assert_eq!(o.map, map([1, 2, 0], [true, false, false]));
        assert_eq!(o.spacing, [2.0, 2.0, 3.0]);
        // A quaternion a little over unit length is renormalised.
        let d = qform_directions([0.0, 0.0, 1.0 + 1e-9], [1.0; 4]);
        assert!((length(d.columns[0]) - 1.0).abs() < 1e-9);
        // pixdim[0] not negative counts as 1; a non-positive size as 1.
        let d = qform_directions([0.0; 3], [0.0, -2.0, 0.0, 5.0]);
        assert_eq!(d.columns, [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 5.0]]);
    }

    /// An oblique volume goes along its nearest axes: tilted 30° about x
    /// (j mostly anterior, a little superior) and 40° about z.
    #[test]
    fn oblique_picks_the_nearest_axes() {
        let (s, c) = (30f64.to_radians().sin(), 30f64.to_radians().cos());
        let o = reduce(&ras([[1.0, 0.0, 0.0], [0.0, c, s], [0.0, -s, c]])).unwrap();
        assert_eq!(o.map, map([0, 2, 1], [true, false, false]));
        let (s, c) = (40f64.to_radians().sin(), 40f64.to_radians().cos());
        // i: mostly right, a little anterior; j: mostly anterior, a little left.
        let o = reduce(&ras([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])).unwrap();
        assert_eq!(o.map, map([0, 2, 1], [true, false, false]));
        // Past 45° the other way round: i mostly anterior, j mostly left.
        let (s, c) = (50f64.to_radians().sin(), 50f64.to_radians().cos());
        let o = reduce(&ras([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])).unwrap();
        assert_eq!(o.map, map([1, 2, 0], [false; 3]));
        // Exactly 45°: a tie, broken by the order of PERMUTATIONS.
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let o = reduce(&ras([[h, h, 0.0], [-h, h, 0.0], [0.0, 0.0, 1.0]])).unwrap();
        assert_eq!(o.map, map([0, 2, 1], [true, false, false]));
    }

    /// Hostile directions are errors, never panics.
    #[test]
    fn bad_directions_are_errors() {
        let with = |i: usize, col: [f64; 3]| {
            let mut c = EYE;
            c[i] = col;
            reduce(&ras(c))
        };
        assert_eq!(with(1, [f64::NAN, 0.0, 1.0]), Err(OrientError::NotFinite { axis: 1 }));
        assert_eq!(with(2, [0.0, f64::INFINITY, 0.0]), Err(OrientError::NotFinite { axis: 2 }));
        assert_eq!(with(0, [0.0; 3]), Err(OrientError::Zero { axis: 0 }));
        assert!(matches!(with(0, [1e300, 1e300, 0.0]), Err(OrientError::Length { axis: 0, .. })));
        assert!(matches!(with(0, [1e-300, 0.0, 0.0]), Err(OrientError::Length { axis: 0, .. })));
        assert!(matches!(with(2, [1.0, 1.0, 0.0]), Err(OrientError::Degenerate { .. })));
        assert!(matches!(with(1, [2.0, 0.0, 0.0]), Err(OrientError::Degenerate { .. })));
        let e = with(1, [1.0, 1e-9, 0.0]).unwrap_err().to_string();
        assert!(e.contains("coplanar"), "{e}");
        assert_eq!(with(0, [0.0; 3]).unwrap_err().to_string(), "the direction of index axis i is zero");
        // Huge but finite, long but still a voxel size: fine.
        assert_eq!(with(0, [3e38, 0.0, 0.0]).unwrap().spacing[0], 3e38);
        // A NaN quaternion gives NaN directions: an error.
        let d = qform_directions([f64::NAN, 0.0, 0.0], [1.0; 4]);
        assert!(matches!(reduce(&d), Err(OrientError::NotFinite { .. })));
        let d = qform_directions([1e300, 1e300, 0.0], [1.0; 4]);
        assert!(reduce(&d).is_ok(), "{d:?}");
    }

    #[test]
    fn axis_maps_are_permutations() {
        assert!(AxisMap::new([0, 0, 1], [false; 3]).is_none());
        assert!(AxisMap::new([0, 1, 3], [false; 3]).is_none());
        assert_eq!(AxisMap::placing([2, 1, 0]).unwrap().from(), [2, 1, 0]);
        // MRC MAPC, MAPR, MAPS = 2, 3, 1: columns along y, rows z, sections x.
        assert_eq!(AxisMap::placing([1, 2, 0]).unwrap().from(), [2, 0, 1]);
        assert!(AxisMap::placing([1, 1, 0]).is_none());
        assert!(AxisMap::placing([0, 0, 1]).is_none());
    }
}
