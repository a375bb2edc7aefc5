//! `sqrtf` and `ceilf` for the hot paths (the beam scheduler per segment,
//! stitching and ordering per candidate). `libm`'s are software on
//! `thumbv7em` (about a hundred instructions each); these are a few float
//! operations, and host and MCU compute them bit for bit alike.

/// `ceilf` for hot paths: exact below 2^31 (a float conversion and a
/// compare instead of a software call on the MCU); `libm` beyond, and for
/// NaN.
#[inline]
pub(crate) fn ceil(v: f32) -> f32 {
    if v.is_finite() && v.abs() < 2_147_483_648.0 {
        let t = v as i32 as f32; // truncates toward zero, exactly
        if t < v {
            t + 1.0
        } else if v.is_sign_negative() && t == 0.0 {
            -0.0 // ceil(-0.5) and ceil(-0.0) are -0.0, as ceilf says
        } else {
            t
        }
    } else {
        libm::ceilf(v)
    }
}

/// `sqrtf` for hot paths. `libm`'s is software on `thumbv7em` (stable
/// `no_std` Rust cannot reach the FPU's `VSQRT`) and costs about a hundred
/// instructions; this one is the bit-pattern estimate of `1 / sqrt(x)`, three
/// Newton steps (relative error below 1e-6) and `x * r`, then snapped to
/// the nearest whole number when that squares back to `x` exactly, so that
/// whole lengths (axis-aligned segments, 3-4-5 triangles) stay whole and
/// sample counts do not flip. Zero, subnormals, infinity and NaN go to
/// `libm`.
#[inline]
pub(crate) fn sqrt(x: f32) -> f32 {
    sqrt_recip(x).0
}

/// [`sqrt`] and, for free, about `1 / sqrt(x)` (the Newton estimate,
/// relative error below 1e-6; `1 / libm::sqrtf(x)` where [`sqrt`] goes to
/// `libm`, so infinite for zero): a length and what turns a difference
/// into a unit direction, without the FPU's 14-cycle division.
#[inline]
pub(crate) fn sqrt_recip(x: f32) -> (f32, f32) {
    if !(f32::MIN_POSITIVE..f32::INFINITY).contains(&x) {
        let s = libm::sqrtf(x);
        return (s, 1.0 / s);
    }
    let h = 0.5 * x;
    let mut r = f32::from_bits(0x5f37_5a86 - (x.to_bits() >> 1));
    r *= 1.5 - h * r * r;
    r *= 1.5 - h * r * r;
    r *= 1.5 - h * r * r;
    let s = x * r;
    if s < 16_777_216.0 {
        let m = (s + 0.5) as u32 as f32;
        if m * m == x {
            return (m, r);
        }
    }
    (s, r)
}

/// `roundf(x)` (halves away from zero) clamped into `0..=65535`, NaN to
/// 0: a point's fixed-point code. `libm`'s `roundf` is software on
/// `thumbv7em`; here one add, one truncating conversion to `i32` (it
/// saturates, and takes NaN to 0), one clamp (a `usat` on the M4, where
/// the unsigned conversion's clamp took a compare and a conditional move)
/// and one select. `x + 0.5` rounded to `f32` has the same
/// floor as the exact sum for `0.5 <= x < 2^23`: the sum is a multiple of
/// `x`'s ulp, and where it rounds (in the next binade up) it stays in
/// `[n, n + 1)` for the integer `n` below it. Below 0.5 the answer is 0
/// (`0.49999997 + 0.5` rounds to 1.0); from 65534.5 on it is 65535.
#[inline(always)]
pub(crate) fn round_u16(x: f32) -> u16 {
    let t = ((x + 0.5) as i32).clamp(0, i32::from(u16::MAX)) as u16;
    if x >= 0.5 { t } else { 0 }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What `round_u16` stands for.
    fn round_u16_libm(x: f32) -> u16 {
        let r = libm::roundf(x);
        if r >= 65535.0 {
            u16::MAX
        } else if r > 0.0 {
            r as u16
        } else {
            0
        }
    }

    #[test]
    fn round_u16_matches_libm_at_every_half_and_across_the_range() {
        let check = |x: f32| assert_eq!(round_u16(x), round_u16_libm(x), "round_u16({x:e})");
        // Every float within 40 ulps of each half and each whole number.
        for n in 0..=65_536u32 {
            for v in [n as f32, n as f32 + 0.5] {
                let b = v.to_bits();
                for b in b.saturating_sub(40)..=b + 40 {
                    check(f32::from_bits(b));
                }
            }
        }
        // A stride through every positive float up to infinity, and a few
        // negative ones.
        let mut b = 0u32;
        while b <= f32::INFINITY.to_bits() {
            check(f32::from_bits(b));
            check(-f32::from_bits(b));
            b += 997;
        }
        for v in [0.0f32, -0.0, 0.5, -0.5, 65_534.5, 65_535.0, f32::INFINITY, f32::NEG_INFINITY, f32::NAN] {
            check(v);
        }
    }

    #[test]
    fn hot_path_sqrt_and_ceil_match_libm() {
        // Whole squares come out whole; everything else within 1e-6.
        for k in 1..=5000u32 {
            let v = (k * k) as f32;
            assert_eq!(sqrt(v), k as f32, "sqrt({v})");
        }
        assert_eq!(sqrt(3.0 * 3.0 + 4.0 * 4.0), 5.0);
        for x in [1e-40f32, 0.0, 1e-30, 0.7, 2.0, 1234.5, 4095.0 * 4095.0 * 2.0, 1e30] {
            let (s, r) = sqrt_recip(x);
            assert_eq!(s, sqrt(x));
            let want = 1.0 / f64::from(libm::sqrtf(x));
            assert!(
                ((f64::from(r) - want) / want).abs() < 1e-6 || (x == 0.0 && r.is_infinite()),
                "1/sqrt({x}) = {r}"
            );
        }
        let mut x = 1.17e-38f32;
        while x < 1e30 {
            let (a, b) = (sqrt(x), libm::sqrtf(x));
            assert!(((a - b) / b).abs() < 1e-6, "sqrt({x}) = {a}, libm {b}");
            x *= 1.0137;
        }
        for v in [0.0f32, -0.0, 1e-45, -1.0, f32::INFINITY, f32::NAN] {
            assert_eq!(sqrt(v).to_bits(), libm::sqrtf(v).to_bits(), "{v}");
        }
        let mut v = -70_000.25f32;
        while v < 70_000.0 {
            assert_eq!(ceil(v).to_bits(), libm::ceilf(v).to_bits(), "ceil({v})");
            v += 0.37;
        }
        for v in [0.0f32, -0.0, -0.5, 0.5, 2.0, 3e9, -3e9, 16_777_217.0, f32::INFINITY, f32::NAN] {
            assert_eq!(ceil(v).to_bits(), libm::ceilf(v).to_bits(), "ceil({v})");
        }
    }
}
