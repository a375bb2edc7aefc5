//! Voxels: the sample types a grid may hold.
//!
//! Real data comes in several widths: CT scans are `i16`, MRI is often `u8`,
//! electron microscopy and simulations `f32`. Every sample is widened to `f32`
//! for contouring; the integer types convert exactly (all are below 2^24).

/// A voxel: a scalar grid sample that can be contoured (not to be confused
/// with a DAC's [`Sample`](crate::output::Sample)).
///
/// Sealed: the core implements it for `u8`, `u16`, `i16` and `f32`.
pub trait Voxel: Copy + sealed::Sealed {
    /// The sample as an `f32` (exact for the integer types).
    fn to_f32(self) -> f32;

    /// The samples as `f32`s without copying, when they already are.
    #[inline(always)]
    fn as_f32s(samples: &[Self]) -> Option<&[f32]> {
        let _ = samples;
        None
    }
}

mod sealed {
    pub trait Sealed {}
    impl Sealed for u8 {}
    impl Sealed for u16 {}
    impl Sealed for i16 {}
    impl Sealed for f32 {}
}

impl Voxel for u8 {
    #[inline(always)]
    fn to_f32(self) -> f32 {
        f32::from(self)
    }
}

impl Voxel for u16 {
    #[inline(always)]
    fn to_f32(self) -> f32 {
        f32::from(self)
    }
}

impl Voxel for i16 {
    #[inline(always)]
    fn to_f32(self) -> f32 {
        f32::from(self)
    }
}

impl Voxel for f32 {
    #[inline(always)]
    fn to_f32(self) -> f32 {
        self
    }

    #[inline(always)]
    fn as_f32s(samples: &[Self]) -> Option<&[f32]> {
        Some(samples)
    }
}
