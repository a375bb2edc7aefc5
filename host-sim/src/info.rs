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
    /// Smallest and largest finite value.
    pub range: (f32, f32),
    /// Mean of the finite values.
    pub mean: f64,
    /// Counts in equal-width bins over `range`.
    pub histogram: Vec<u64>,
    /// Levels worth contouring: Otsu's threshold (the level that best
    /// separates the two main populations, e.g. air and tissue), then
    /// Otsu's threshold within the upper population.
    pub suggested: Vec<f32>,
}

fn values(v: &LoadedVolume) -> (&'static str, Vec<f32>) {
    match &v.samples {
        Samples::U8(s) => ("u8", s.iter().map(|&x| f32::from(x)).collect()),
        Samples::U16(s) => ("u16", s.iter().map(|&x| f32::from(x)).collect()),
        Samples::I16(s) => ("i16", s.iter().map(|&x| f32::from(x)).collect()),
        Samples::F32(s) => ("f32", s.clone()),
    }
}

/// Otsu's threshold over a histogram of `bins` between `lo` and `hi`,
/// restricted to bins `from..`; returns the level at the chosen bin edge.
fn otsu(hist: &[u64], from: usize, lo: f32, hi: f32) -> Option<f32> {
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
    let width = (hi - lo) / hist.len() as f32;
    at.map(|b| lo + b as f32 * width)
}

/// Summarise a volume with a histogram of `bins` bins.
pub fn summarize(v: &LoadedVolume, bins: usize) -> Summary {
    let bins = bins.max(2);
    let (dtype, vals) = values(v);
    let finite: Vec<f32> = vals.iter().copied().filter(|x| x.is_finite()).collect();
    let (lo, hi) = finite.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
    let mean = finite.iter().map(|&x| f64::from(x)).sum::<f64>() / finite.len().max(1) as f64;
    let mut histogram = vec![0u64; bins];
    let mut suggested = vec![];
    if !finite.is_empty() && hi > lo {
        for &x in &finite {
            let b = (((x - lo) / (hi - lo)) * bins as f32) as usize;
            histogram[b.min(bins - 1)] += 1;
        }
        if let Some(t) = otsu(&histogram, 0, lo, hi) {
            suggested.push(t);
            let from = (((t - lo) / (hi - lo)) * bins as f32).round() as usize;
            if let Some(t2) = otsu(&histogram, from, lo, hi).filter(|&t2| t2 > t) {
                suggested.push(t2);
            }
        }
    }
    let d = v.dims;
    Summary {
        dims: (d.0, d.1, d.2),
        dtype,
        spacing: v.spacing,
        finite: finite.len(),
        nonfinite: vals.len() - finite.len(),
        range: if finite.is_empty() { (f32::NAN, f32::NAN) } else { (lo, hi) },
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
        let _ = writeln!(s, "min={}", self.range.0);
        let _ = writeln!(s, "max={}", self.range.1);
        let _ = writeln!(s, "mean={:.6}", self.mean);
        let levels: Vec<String> = self.suggested.iter().map(|l| format!("{l}")).collect();
        let _ = writeln!(s, "suggested_levels={}", levels.join(","));
        let peak = self.histogram.iter().copied().max().unwrap_or(1).max(1);
        let (lo, hi) = self.range;
        let width = (hi - lo) / self.histogram.len() as f32;
        for (i, &c) in self.histogram.iter().enumerate() {
            // Bars on a log scale: background peaks would flatten the rest.
            let frac = if c == 0 { 0.0 } else { (1.0 + c as f64).ln() / (1.0 + peak as f64).ln() };
            let bar = "#".repeat((frac * 40.0).round() as usize);
            let _ = writeln!(s, "# {:>12.4} {:>10} {bar}", lo + i as f32 * width, c);
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
        assert_eq!((sum.range, sum.finite, sum.nonfinite), ((8.0, 105.0), 1000, 0));
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
        assert_eq!((sum.finite, sum.nonfinite, sum.range), (2, 2, (1.0, 1.0)));
        assert!(sum.suggested.is_empty());
        let _ = sum.report();
    }
}
