//! `isoscope-sim info`: what a volume holds, and which levels to contour.

use crate::volume::{LoadedVolume, Samples};
use std::fmt::Write;

/// A volume's summary.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    /// Extents.
    pub dims: (usize, usize, usize),
    /// Sample type name.
    pub dtype: &'static str,
    /// Voxel spacing.
    pub spacing: [f32; 3],
    /// Finite samples.
    pub finite: usize,
    /// NaN or infinite samples.
    pub nonfinite: usize,
    /// Smallest and largest finite value (`None`: no finite sample).
    pub range: Option<(f32, f32)>,
    /// Mean of the finite values (`None`: no finite sample).
    pub mean: Option<f64>,
    /// Counts in equal-width bins over `range`.
    pub histogram: Vec<u64>,
    /// Levels worth contouring: Otsu's threshold (the level that best
    /// separates the two main populations, e.g. air and tissue), then
    /// Otsu's threshold within the upper population.
    pub suggested: Vec<f32>,
}

/// The sample type's name.
fn dtype(v: &LoadedVolume) -> &'static str {
    match &v.samples {
        Samples::U8(_) => "u8",
        Samples::U16(_) => "u16",
        Samples::I16(_) => "i16",
        Samples::F32(_) => "f32",
    }
}

/// `f` of every finite sample, as `f32`, in place: no copy of the volume
/// (a volume at the readers' memory limit has no room for one).
fn each_finite(v: &LoadedVolume, mut f: impl FnMut(f32)) {
    match &v.samples {
        Samples::U8(s) => s.iter().for_each(|&x| f(f32::from(x))),
        Samples::U16(s) => s.iter().for_each(|&x| f(f32::from(x))),
        Samples::I16(s) => s.iter().for_each(|&x| f(f32::from(x))),
        Samples::F32(s) => s.iter().filter(|x| x.is_finite()).for_each(|&x| f(x)),
    }
}

/// Otsu's threshold over a histogram of `bins` between `lo` and `hi`,
/// restricted to bins `from..`; returns the level at the chosen bin edge.
/// (In `f64`: the span of two `f32` may be past the `f32` range.)
fn otsu(hist: &[u64], from: usize, lo: f64, hi: f64) -> Option<f32> {
    let h = hist.get(from..)?;
    let total: f64 = h.iter().map(|&c| c as f64).sum();
    if total == 0.0 || h.len() < 2 {
        return None;
    }
    let sum: f64 = h.iter().enumerate().map(|(i, &c)| i as f64 * c as f64).sum();
    let (mut w0, mut s0, mut best, mut at) = (0.0, 0.0, -1.0, None);
    for (i, &c) in h.iter().enumerate().take(h.len() - 1) {
        w0 += c as f64;
        s0 += i as f64 * c as f64;
        let w1 = total - w0;
        if w0 == 0.0 || w1 == 0.0 {
            continue;
        }
        let (m0, m1) = (s0 / w0, (sum - s0) / w1);
        let between = w0 * w1 * (m0 - m1) * (m0 - m1);
        if between > best {
            best = between;
            at = Some(from + i + 1);
        }
    }
    let width = (hi - lo) / hist.len() as f64;
    at.map(|b| (lo + b as f64 * width) as f32)
}

/// Histogram bins whose first suggested level is the one a volume file is
/// drawn at when no level is given ([`default_level`]).
pub const LEVEL_BINS: usize = 64;

/// The level a volume file is drawn at when no level is given: the first
/// level [`summarize`] suggests over [`LEVEL_BINS`] bins (Otsu's
/// threshold); `None` for a constant or empty volume.
pub fn default_level(v: &LoadedVolume) -> Option<f32> {
    summarize(v, LEVEL_BINS).suggested.first().copied()
}

/// Summarise a volume with a histogram of `bins` bins.
pub fn summarize(v: &LoadedVolume, bins: usize) -> Summary {
    let bins = bins.max(2);
    // One pass for the range and the mean (summed in f64: a sum of f32
    // samples may pass the f32 range), one for the histogram.
    let (mut range, mut sum, mut finite) = (None::<(f32, f32)>, 0.0f64, 0usize);
    each_finite(v, |x| {
        range = Some(range.map_or((x, x), |(a, b)| (a.min(x), b.max(x))));
        sum += f64::from(x);
        finite += 1;
    });
    let mean = (finite > 0).then(|| sum / finite as f64);
    let mut histogram = vec![0u64; bins];
    let mut suggested = vec![];
    if let Some((lo, hi)) = range.map(|(a, b)| (f64::from(a), f64::from(b)))
        && hi > lo
    {
        let bin = |x: f64| ((((x - lo) / (hi - lo)) * bins as f64) as usize).min(bins - 1);
        each_finite(v, |x| {
            if let Some(c) = histogram.get_mut(bin(f64::from(x))) {
                *c += 1;
            }
        });
        if let Some(t) = otsu(&histogram, 0, lo, hi) {
            suggested.push(t);
            let from = (((f64::from(t) - lo) / (hi - lo)) * bins as f64).round() as usize;
            if let Some(t2) = otsu(&histogram, from, lo, hi).filter(|&t2| t2 > t) {
                suggested.push(t2);
            }
        }
    }
    let d = v.dims;
    Summary {
        dims: (d.0, d.1, d.2),
        dtype: dtype(v),
        spacing: v.spacing,
        finite,
        nonfinite: v.dims.count().unwrap_or(finite).saturating_sub(finite),
        range,
        mean,
        histogram,
        suggested,
    }
}

impl Summary {
    /// The summary as text: `key=value` lines, then the histogram as bars.
    pub fn report(&self) -> String {
        let mut s = String::new();
        let (nx, ny, nz) = self.dims;
        let _ = writeln!(s, "dims={nx}x{ny}x{nz}");
        let _ = writeln!(s, "dtype={}", self.dtype);
        let _ = writeln!(s, "spacing={}x{}x{}", self.spacing[0], self.spacing[1], self.spacing[2]);
        let _ = writeln!(s, "samples={}", self.finite + self.nonfinite);
        let _ = writeln!(s, "nonfinite={}", self.nonfinite);
        // No finite sample: no minimum, maximum or mean (not NaN or -0).
        match self.range {
            Some((lo, hi)) => {
                let _ = writeln!(s, "min={lo}");
                let _ = writeln!(s, "max={hi}");
            }
            None => s.push_str("min=none\nmax=none\n"),
        }
        match self.mean {
            Some(m) => {
                let _ = writeln!(s, "mean={m:.6}");
            }
            None => s.push_str("mean=none\n"),
        }
        let levels: Vec<String> = self.suggested.iter().map(|l| format!("{l}")).collect();
        let _ = writeln!(s, "suggested_levels={}", levels.join(","));
        let peak = self.histogram.iter().copied().max().unwrap_or(1).max(1);
        let Some((lo, hi)) = self.range else { return s };
        let (lo, hi) = (f64::from(lo), f64::from(hi));
        let width = (hi - lo) / self.histogram.len() as f64;
        for (i, &c) in self.histogram.iter().enumerate() {
            // Bars on a log scale: background peaks would flatten the rest.
            let frac = if c == 0 { 0.0 } else { (1.0 + c as f64).ln() / (1.0 + peak as f64).ln() };
            let bar = "#".repeat((frac * 40.0).round() as usize);
            let _ = writeln!(s, "# {:>12.4} {:>10} {bar}", lo + i as f64 * width, c);
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::volume::{Dims, UNIT_SPACING};

    #[test]
    fn two_populations_give_a_threshold_between_them() {
        // 600 voxels near 10, 400 near 100.
        let s: Vec<u8> =
            (0..1000).map(|i| if i < 600 { 8 + (i % 5) as u8 } else { 95 + (i % 11) as u8 }).collect();
        let v = LoadedVolume { dims: Dims(10, 10, 10), samples: Samples::U8(s), spacing: UNIT_SPACING };
        let sum = summarize(&v, 64);
        assert_eq!((sum.range, sum.finite, sum.nonfinite), (Some((8.0, 105.0)), 1000, 0));
        assert!(sum.suggested[0] > 12.0 && sum.suggested[0] < 95.0, "{:?}", sum.suggested);
        assert_eq!(sum.histogram.iter().sum::<u64>(), 1000);
        let r = sum.report();
        assert!(r.contains("dims=10x10x10") && r.contains("dtype=u8") && r.contains("suggested_levels="));
    }

    #[test]
    fn nan_and_constant_volumes_are_reported_not_fatal() {
        let v = LoadedVolume {
            dims: Dims(2, 2, 1),
            samples: Samples::F32(vec![f32::NAN, 1.0, 1.0, f32::INFINITY]),
            spacing: UNIT_SPACING,
        };
        let sum = summarize(&v, 8);
        assert_eq!((sum.finite, sum.nonfinite, sum.range), (2, 2, Some((1.0, 1.0))));
        assert!(sum.suggested.is_empty());
        let _ = sum.report();
        // All NaN: no range and no mean, said so (not NaN, not -0).
        let v = LoadedVolume { samples: Samples::F32(vec![f32::NAN; 4]), ..v };
        let r = summarize(&v, 8).report();
        assert!(r.contains("min=none\nmax=none\nmean=none\n"), "{r}");
        assert!(!r.contains("NaN") && !r.contains("-0"), "{r}");
    }

    #[test]
    fn a_volume_spanning_past_the_f32_range_has_finite_edges_and_levels() {
        // -3e38 .. 3e38: their difference is past f32::MAX.
        let s: Vec<f32> = (0..1000)
            .map(|i| if i < 600 { -3e38 + i as f32 * 1e33 } else { 3e38 - i as f32 * 1e33 })
            .collect();
        let v = LoadedVolume { dims: Dims(10, 10, 10), samples: Samples::F32(s), spacing: UNIT_SPACING };
        let sum = summarize(&v, 16);
        assert_eq!(sum.histogram.iter().sum::<u64>(), 1000);
        assert!(
            !sum.suggested.is_empty() && sum.suggested.iter().all(|l| l.is_finite()),
            "{:?}",
            sum.suggested
        );
        let (lo, hi) = sum.range.unwrap();
        assert!(sum.suggested[0] > lo && sum.suggested[0] < hi);
        let r = sum.report();
        assert!(!r.contains("NaN") && !r.contains("inf"), "{r}");
        assert!(sum.mean.unwrap().is_finite());
    }
}
