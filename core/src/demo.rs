//! Built-in demonstration volumes, computed (with `libm`) rather than stored.
//!
//! - [`Demo::Hydrogen`]: the paper's Figure 1, the probability density
//!   |psi|^2 of the hydrogen 3d_xy orbital, proportional to
//!   x^2 y^2 exp(-2r/3) in Bohr radii, sampled on [-20, 20]^3 and scaled so its
//!   maximum (at r = 6 on the diagonals of the x-y plane) is 1.
//! - [`Demo::Gyroid`]: sin x cos y + sin y cos z + sin z cos x sampled at
//!   t_i = 8 pi i / (N - 1) on each axis (four periods).
//! - [`Demo::Sphere`]: the distance from the centre, the cube spanning
//!   [-1, 1]^3; level 0.8 is a sphere of radius 0.8.
//! - [`Demo::Torus`]: the distance from a ring of radius 0.6 in the x-y
//!   plane; level 0.25 is a torus of tube radius 0.25.

use crate::contour::grid::GridError;

/// A built-in volume.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Demo {
    /// Hydrogen 3d_xy orbital, wavefunction squared (the paper's Figure 1).
    Hydrogen,
    /// Gyroid minimal surface, four periods per axis.
    Gyroid,
    /// Distance from the centre: spheres.
    Sphere,
    /// Distance from a ring: tori.
    Torus,
}

/// Half the side of the hydrogen demo's cube, in Bohr radii.
pub const HYDROGEN_EXTENT: f32 = 20.0;

/// Maximum of x^2 y^2 exp(-2r/3): 324 exp(-4), at x = y = 3 sqrt 2, z = 0.
pub const HYDROGEN_PEAK: f32 = 5.934_267;

impl Demo {
    /// Both demos.
    pub const ALL: [Demo; 4] = [Demo::Hydrogen, Demo::Gyroid, Demo::Sphere, Demo::Torus];

    /// The demo's name on the command line.
    pub const fn name(self) -> &'static str {
        match self {
            Demo::Hydrogen => "hydrogen",
            Demo::Gyroid => "gyroid",
            Demo::Sphere => "sphere",
            Demo::Torus => "torus",
        }
    }

    /// The demo with this name.
    pub fn from_name(name: &str) -> Option<Demo> {
        Demo::ALL.into_iter().find(|d| d.name() == name)
    }

    /// A level that shows the demo's characteristic surface: the four lobes
    /// of the orbital, the gyroid's zero set, a sphere of radius 0.8, a
    /// torus of tube radius 0.25.
    pub const fn default_level(self) -> f32 {
        match self {
            Demo::Hydrogen => 0.1,
            Demo::Gyroid => 0.0,
            Demo::Sphere => 0.8,
            Demo::Torus => 0.25,
        }
    }

    /// The sample at voxel `(i, j, k)` of an `n`^3 volume. [`Demo::fill`]
    /// writes exactly these values.
    pub fn sample(self, n: usize, i: usize, j: usize, k: usize) -> f32 {
        let step = if n > 1 { 1.0 / (n - 1) as f32 } else { 0.0 };
        let (fi, fj, fk) = (i as f32 * step, j as f32 * step, k as f32 * step);
        match self {
            Demo::Hydrogen => {
                let s = |f: f32| HYDROGEN_EXTENT * (2.0 * f - 1.0);
                let (x, y, z) = (s(fi), s(fj), s(fk));
                let r = libm::sqrtf(x * x + y * y + z * z);
                x * x * y * y * libm::expf(-2.0 * r / 3.0) / HYDROGEN_PEAK
            }
            Demo::Gyroid => {
                let t = 8.0 * core::f32::consts::PI;
                let (x, y, z) = (t * fi, t * fj, t * fk);
                let (sx, cx) = (libm::sinf(x), libm::cosf(x));
                let (sy, cy) = (libm::sinf(y), libm::cosf(y));
                let (sz, cz) = (libm::sinf(z), libm::cosf(z));
                sx * cy + sy * cz + sz * cx
            }
            Demo::Sphere | Demo::Torus => {
                let s = |f: f32| 2.0 * f - 1.0;
                let (x, y, z) = (s(fi), s(fj), s(fk));
                if self == Demo::Sphere {
                    libm::sqrtf(x * x + y * y + z * z)
                } else {
                    let ring = libm::sqrtf(x * x + y * y) - 0.6;
                    libm::sqrtf(ring * ring + z * z)
                }
            }
        }
    }

    /// Fill `out` (x fastest) with the `n`^3 demo volume.
    ///
    /// # Errors
    /// [`GridError::SizeMismatch`] unless `out.len() == n^3`,
    /// [`GridError::Empty`] for `n == 0`.
    pub fn fill(self, n: usize, out: &mut [f32]) -> Result<(), GridError> {
        if n == 0 {
            return Err(GridError::Empty);
        }
        let expected = n.checked_mul(n).and_then(|a| a.checked_mul(n)).ok_or(GridError::Overflow)?;
        if out.len() != expected {
            return Err(GridError::SizeMismatch { expected, actual: out.len() });
        }
        match self {
            Demo::Gyroid => fill_gyroid(n, out),
            Demo::Hydrogen | Demo::Sphere | Demo::Torus => {
                for (idx, v) in out.iter_mut().enumerate() {
                    let (i, j, k) = (idx % n, idx / n % n, idx / (n * n));
                    *v = self.sample(n, i, j, k);
                }
            }
        }
        Ok(())
    }
}

/// The gyroid, separably: its sines and cosines depend on one axis each, so
/// they are computed once per axis value (in blocks of 64 along x, on the
/// stack) rather than six times per sample. The values equal
/// [`Demo::sample`] bit for bit: the same `libm` calls on the same inputs.
fn fill_gyroid(n: usize, out: &mut [f32]) {
    const B: usize = 64;
    let sc = |i: usize| {
        let step = if n > 1 { 1.0 / (n - 1) as f32 } else { 0.0 };
        let t = 8.0 * core::f32::consts::PI * (i as f32 * step);
        (libm::sinf(t), libm::cosf(t))
    };
    let mut xs = [(0.0f32, 0.0f32); B];
    let mut i0 = 0;
    while i0 < n {
        let m = (n - i0).min(B);
        for (d, x) in xs.iter_mut().take(m).enumerate() {
            *x = sc(i0 + d);
        }
        for k in 0..n {
            let (sz, cz) = sc(k);
            for j in 0..n {
                let (sy, cy) = sc(j);
                let row = (k * n + j) * n + i0;
                let Some(dst) = out.get_mut(row..row + m) else { return };
                for (v, &(sx, cx)) in dst.iter_mut().zip(&xs) {
                    *v = sx * cy + sy * cz + sz * cx;
                }
            }
        }
        i0 += m;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fill_writes_exactly_the_samples() {
        for demo in Demo::ALL {
            for n in [1usize, 2, 7, 70] {
                let mut v = vec![f32::NAN; n * n * n];
                demo.fill(n, &mut v).unwrap();
                for (idx, &x) in v.iter().enumerate() {
                    let (i, j, k) = (idx % n, idx / n % n, idx / (n * n));
                    assert_eq!(
                        x.to_bits(),
                        demo.sample(n, i, j, k).to_bits(),
                        "{demo:?} n={n} at {i},{j},{k}"
                    );
                }
            }
        }
    }

    #[test]
    fn fill_rejects_wrong_sizes() {
        let mut v = vec![0.0; 7];
        assert_eq!(Demo::Gyroid.fill(2, &mut v), Err(GridError::SizeMismatch { expected: 8, actual: 7 }));
        assert_eq!(Demo::Gyroid.fill(0, &mut v), Err(GridError::Empty));
    }

    #[test]
    fn hydrogen_peak_is_one() {
        // The density's maximum, x = y = 3 sqrt 2, z = 0, evaluated directly.
        let s = 3.0 * core::f32::consts::SQRT_2;
        let r = libm::sqrtf(2.0 * s * s);
        let peak = s * s * s * s * libm::expf(-2.0 * r / 3.0) / HYDROGEN_PEAK;
        assert!((peak - 1.0).abs() < 1e-5, "{peak}");
    }
}
