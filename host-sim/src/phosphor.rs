//! The phosphor: what a CRT in XY mode shows for a stream of DAC samples.
//!
//! [`Phosphor`] is an additive `f32` energy buffer, one value a pixel, that
//! DAC [`Sample`]s are deposited into (it is a [`Dac`] itself), and a tone
//! mapping from that energy to an RGB picture of a green P31 screen, which
//! it can encode as a PNG.
//!
//! # Geometry
//!
//! Codes `0 ..= 2^bits - 1` cover the whole image on both axes, y up: code
//! `c` on X is at pixel coordinate `(c + 0.5) * width / 2^bits` (pixel `i`
//! covers `i .. i + 1`, its centre is at `i + 0.5`), code `c` on Y at
//! `height - (c + 0.5) * height / 2^bits`. So code 0 is in the bottom row,
//! code `2^bits - 1` in the top row, and `(0, 2^bits - 1)` is the top-left
//! corner. Energy that falls outside the image is lost (as it would be off
//! the edge of the tube's graticule); codes above `2^bits - 1` land outside.
//!
//! # The physical model
//!
//! The beam moves from sample to sample at the DAC's clock, so each sample
//! period it sweeps the straight step from sample `i - 1` to sample `i`. The
//! beam current is constant, so **every step deposits the same energy**,
//! [`PhosphorConfig::energy_per_sample`], whatever its length: spread
//! uniformly along the step and blurred by the beam's Gaussian spot (standard
//! deviation [`PhosphorConfig::spot_sigma`] pixels). A slow beam (short
//! steps, many samples per unit of length) therefore draws a bright line and
//! a fast one a dim line, as on a real tube, and a **dwell** (a sample at the
//! same code as the one before) deposits its whole energy as a spot there.
//!
//! The intensity of step `i` is set by sample `i`'s beam: 1 for
//! [`Beam::On`], [`PhosphorConfig::show_blanked`] for [`Beam::Off`] (0 for a
//! scope whose Z input blanks the beam; a small value shows the faint jumps
//! and settling spots of a scope without one). The very first sample (no
//! step before it) is a spot. Repeated samples are merged into one spot of
//! the summed energy (within one [`Phosphor::deposit`] call), so a huge dwell
//! costs as much as a single one. Likewise a straight run of steps at one
//! speed is deposited as one segment, a *stroke* (the same integral, in a
//! half of the pixel work for a contour's runs of a few steps): the DAC's
//! codes round a straight line by up to half an LSB, so a step joins a run
//! while every sample of it lies within [`STROKE_TOLERANCE`] `σ` of the
//! uniform sweep from the run's start to the new end. A stroke ends with
//! each [`Phosphor::deposit`] call, so a frame streamed in chunks is the
//! frame in one call within that tolerance.
//!
//! A step from `a` to `b` of length `L > 0`, energy `E`, deposits at a pixel
//! centre at distance `d` from the line through `a` and `b`, and at
//! coordinate `u` along it (`u = 0` at `a`, `u = L` at `b`), the exact
//! integral of the spot along the step:
//!
//! ```text
//! E / L * ∫_0^L G(u - s, d) ds
//!   = E * exp(-d² / 2σ²) / (√(2π) σ) * [erf(u / (√2 σ)) - erf((u - L) / (√2 σ))] / (2 L)
//! ```
//!
//! with `G` the normalised 2D Gaussian, and a spot (`L = 0`, or `L` below
//! 1/1000 of `σ`, where the difference of erfs would lose precision) deposits
//! `E * exp(-r² / 2σ²) / (2π σ²)`. Values are point samples at pixel centres
//! (per unit of area, a pixel being one unit), so the total over the image
//! is the energy deposited as long as the spot is not much narrower than a
//! pixel (`σ >= 0.7` keeps the sum within 0.1% of the integral). Each step
//! is evaluated only within [`WINDOW_SIGMAS`] `σ` of the segment (a rotated
//! rectangle, walked row by row), which keeps more than 99.9% of its energy.
//!
//! `erf` is Abramowitz and Stegun's formula 7.1.26
//! (`1 - (a1 t + ... + a5 t^5) exp(-x²)`, `t = 1 / (1 + p x)`), absolute
//! error below `1.5e-7`, below `5e-7` as evaluated here in `f32`; `exp` is a
//! branch-free `2^n e^f` with a polynomial for `e^f` (relative error below
//! `3e-7`).
//! Both are plain arithmetic, so the per-row loop over pixels runs as a
//! vector loop (SSE2 on the baseline x86-64 target; SIMD128 in the web
//! page, where the drawing functions are built with that feature one by
//! one: plain IEEE lanes, so the page's picture is `render`'s byte for
//! byte. Not the whole crate: so built, rustc 1.95 miscompiled the audio
//! frame's code-to-unit conversion). Unit tests check both errors against
//! references.
//!
//! # Tone mapping
//!
//! [`Phosphor::to_rgb8`] adds an optional glow (a wide, low Gaussian halo:
//! [`Glow`]; from a radius of 3 pixels up worked out on a grid of 2x2 pixel
//! blocks and interpolated back, within a twentieth of the halo's peak, in
//! a fifth of the work) to the energy `E` of each pixel, then maps it to a display
//! value `t = (1 - exp(-exposure * E))^(1 / gamma)`, a saturating curve like
//! film or an eye, then `t` through the [`Palette`] (P31 green by default,
//! whitish at saturation). Frames can be accumulated: [`Phosphor::decay`]
//! multiplies the buffer by [`PhosphorConfig::persistence`] before the next
//! frame is deposited.
//!
//! # Example
//!
//! ```
//! use isoscope_core::output::{Beam, Sample};
//! use isoscope_sim::phosphor::{Phosphor, PhosphorConfig};
//!
//! let mut screen = Phosphor::new(PhosphorConfig::with_size(64, 64)).unwrap();
//! // A horizontal line across the middle, 16 LSB a sample.
//! screen.deposit((0..=255).map(|k| Sample::new(k * 16, 2048, Beam::On)));
//! let rgb = screen.to_rgb8();
//! assert_eq!(rgb.len(), 64 * 64 * 3);
//! let png = screen.encode_png();
//! assert_eq!(&png[1..4], b"PNG");
//! ```

use isoscope_core::output::{Beam, Dac, Sample};
use std::convert::Infallible;
use std::fmt;
use std::io::Write;
use std::ops::Range;
use std::path::Path;

/// Largest accepted image width or height, in pixels.
pub const MAX_SIZE: u32 = 8192;

/// Largest accepted [`PhosphorConfig::spot_sigma`] and [`Glow::radius`], in
/// pixels.
pub const MAX_SIGMA: f32 = 256.0;

/// How far from a segment, in spot standard deviations, its energy is
/// evaluated. A 2D Gaussian keeps more than 99.9% of its mass within 3.5 σ
/// of its centre on each axis; beyond, the spot is below 0.22% of its peak.
pub const WINDOW_SIGMAS: f32 = 3.5;

/// The size the [default](PhosphorConfig::default) configuration is tuned
/// for; [`PhosphorConfig::with_size`] scales from it.
pub const REFERENCE_SIZE: u32 = 1024;

/// A halo around bright lines: a wide Gaussian blur of the energy, added on
/// top at [`Glow::strength`] times its value (light scattered in the glass
/// and the phosphor, and the eye's own glare).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Glow {
    /// Weight of the blurred energy added to the energy (`>= 0`, finite;
    /// 0 turns the glow off). Energy is conserved by the blur, so a strength
    /// of 0.1 adds 10% of the picture's energy, spread thin.
    pub strength: f32,
    /// Standard deviation of the blur, in pixels (`> 0` and at most
    /// [`MAX_SIGMA`] when `strength > 0`).
    pub radius: f32,
}

/// A colour ramp from the display value `t` in `0 ..= 1` to RGB.
///
/// `stops` are `(t, [r, g, b])`, `t` non-decreasing in `0 ..= 1`, colours in
/// `0 ..= 1` (display values, as written to the PNG). Between two stops the
/// colour is interpolated linearly; before the first stop it is the first
/// colour, after the last the last.
#[derive(Debug, Clone, PartialEq)]
pub struct Palette {
    /// The stops, at least one.
    pub stops: Vec<(f32, [f32; 3])>,
}

impl Palette {
    /// P31 (the common green oscilloscope phosphor, ZnS:Cu, emission peak
    /// near 530 nm), as a screen looks to the eye or a camera:
    ///
    /// | t | colour | |
    /// |---|---|---|
    /// | 0 | (0, 0, 0) | the unlit screen |
    /// | 0.5 | (0.1, 0.6, 0.2) | a dim trace: saturated green |
    /// | 0.85 | (0.6, 1.0, 0.6) | a bright trace: pale green |
    /// | 1 | (0.9, 1.0, 0.9) | saturation: a whitish-green core |
    ///
    /// P31's chromaticity (x ≈ 0.23, y ≈ 0.53) is outside sRGB; the nearest
    /// sRGB colour is a slightly bluish green. A dim trace shows it; at
    /// high intensity the eye's green cones (and a camera's green channel)
    /// saturate while red and blue keep rising, so the core of a bright line
    /// or a dwell spot looks whitish green, which the upper stops imitate.
    pub fn p31() -> Self {
        Self {
            stops: vec![
                (0.0, [0.0, 0.0, 0.0]),
                (0.5, [0.1, 0.6, 0.2]),
                (0.85, [0.6, 1.0, 0.6]),
                (1.0, [0.9, 1.0, 0.9]),
            ],
        }
    }

    /// Black to white.
    pub fn gray() -> Self {
        Self { stops: vec![(0.0, [0.0; 3]), (1.0, [1.0; 3])] }
    }

    /// The colour at display value `t` (clamped into `0 ..= 1`; NaN is 0).
    pub fn color(&self, t: f32) -> [f32; 3] {
        let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
        let Some(&(t0, c0)) = self.stops.first() else {
            return [0.0; 3];
        };
        if t <= t0 {
            return c0;
        }
        let mut prev = (t0, c0);
        for &(t1, c1) in &self.stops[1..] {
            if t <= t1 {
                let f = if t1 > prev.0 { (t - prev.0) / (t1 - prev.0) } else { 1.0 };
                return [0, 1, 2].map(|k| prev.1[k] + (c1[k] - prev.1[k]) * f);
            }
            prev = (t1, c1);
        }
        prev.1
    }

    fn validate(&self) -> Result<(), PhosphorError> {
        if self.stops.is_empty() {
            return Err(PhosphorError::BadPalette("no stops"));
        }
        let mut last = 0.0;
        for &(t, c) in &self.stops {
            if !(0.0..=1.0).contains(&t) {
                return Err(PhosphorError::BadPalette("a stop position is not in 0..=1"));
            }
            if t < last {
                return Err(PhosphorError::BadPalette("stop positions decrease"));
            }
            last = t;
            if !c.iter().all(|v| (0.0..=1.0).contains(v)) {
                return Err(PhosphorError::BadPalette("a stop colour is not in 0..=1"));
            }
        }
        Ok(())
    }
}

impl Default for Palette {
    /// [`Palette::p31`].
    fn default() -> Self {
        Self::p31()
    }
}

/// How the screen is rendered. See the [module docs](self) for the model.
#[derive(Debug, Clone, PartialEq)]
pub struct PhosphorConfig {
    /// Image width in pixels, `1 ..= MAX_SIZE`.
    pub width: u32,
    /// Image height in pixels, `1 ..= MAX_SIZE`.
    pub height: u32,
    /// DAC resolution in bits, `1 ..= 16`: codes `0 ..= 2^bits - 1` span the
    /// image.
    pub bits: u8,
    /// Standard deviation of the beam's Gaussian spot, in pixels (finite,
    /// `0 < σ <= MAX_SIGMA`; below ~0.7 the spot falls between pixel centres
    /// and lines look dotted).
    pub spot_sigma: f32,
    /// Energy one sample deposits (finite, `>= 0`): the unit of the energy
    /// buffer.
    pub energy_per_sample: f32,
    /// Tone-mapping scale: a pixel of energy `E` shows
    /// `1 - exp(-exposure * E)` of full brightness before gamma (finite,
    /// `> 0`).
    pub exposure: f32,
    /// Display gamma (finite, `> 0`): the tone-mapped value is raised to
    /// `1 / gamma`.
    pub gamma: f32,
    /// The halo.
    pub glow: Glow,
    /// Fraction of the energy [`Phosphor::decay`] keeps, `0 ..= 1`.
    pub persistence: f32,
    /// Display value to colour.
    pub palette: Palette,
    /// Intensity of blanked samples relative to lit ones, `0 ..= 1`: 0 for a
    /// scope with a Z input (blanked moves are invisible), e.g. 0.05 for a
    /// scope without one (faint jump lines and settling spots).
    pub show_blanked: f32,
}

impl Default for PhosphorConfig {
    /// [`PhosphorConfig::with_size`]`(1024, 1024)`:
    ///
    /// - `bits: 12`, the beam scheduler's default DAC.
    /// - `spot_sigma: 1.25` px: a ~0.5 mm spot (full width at half maximum
    ///   ≈ 2.35 σ) on a ~10 cm screen is ~5 px of 1024, i.e. σ ≈ 2; 1.25
    ///   keeps the lines crisp at that size while still smooth (no aliasing:
    ///   the scheduler's 17 LSB steps are 4.25 px, the line is continuous).
    /// - `energy_per_sample: 1.0`: the buffer counts samples.
    /// - `exposure: 4.0`: a line drawn at the scheduler's default speed
    ///   (17 LSB = 4.25 px a sample, so 0.24 samples a pixel of length, peak
    ///   0.24 / (√(2π) σ) = 0.075 a pixel) tone-maps to 0.26, shown at 0.54
    ///   after gamma: a bright, saturated green line. Two lines crossing (or
    ///   lying close, at a surface's silhouette) show at 0.71, pale green,
    ///   and the scheduler's dwell spots (2 samples at a polyline's start, 4
    ///   for a dot) at 0.8 to 0.95, towards the whitish core. Tuned by eye
    ///   on the hydrogen demo (32³, level 0.1, default view and beam: about
    ///   15,000 samples).
    /// - `gamma: 2.2`, as for sRGB.
    /// - `glow: { strength: 0.04, radius: 6.0 }`: a faint halo 6 px wide,
    ///   visible around bright spots and dense bundles of lines, invisible
    ///   elsewhere; much more makes the picture look out of focus.
    /// - `persistence: 0.05`: P31 falls to 10% of its brightness within
    ///   tens of microseconds, and to a long low tail after that; at a 50 Hz
    ///   refresh about 5% of a frame still shows (faint trails behind moving
    ///   lines in a dark room).
    /// - `palette: Palette::p31()`.
    /// - `show_blanked: 0.0`: a scope with a Z input.
    fn default() -> Self {
        Self::with_size(REFERENCE_SIZE, REFERENCE_SIZE)
    }
}

impl PhosphorConfig {
    /// The default look at another image size: `spot_sigma` and the glow
    /// radius scale with `min(width, height) / 1024` (the spot no narrower
    /// than 0.75 px, the glow no narrower than 1 px), and `exposure` so that
    /// a line keeps its brightness (a line's peak energy goes as one over
    /// pixels per LSB times `spot_sigma`).
    pub fn with_size(width: u32, height: u32) -> Self {
        let scale = width.min(height).max(1) as f32 / REFERENCE_SIZE as f32;
        let spot_sigma = (1.25 * scale).max(0.75);
        Self {
            width,
            height,
            bits: 12,
            spot_sigma,
            energy_per_sample: 1.0,
            exposure: 4.0 * scale * spot_sigma / 1.25,
            gamma: 2.2,
            glow: Glow { strength: 0.04, radius: (6.0 * scale).max(1.0) },
            persistence: 0.05,
            palette: Palette::p31(),
            show_blanked: 0.0,
        }
    }

    /// Check every field.
    ///
    /// # Errors
    /// The first field out of its documented range.
    pub fn validate(&self) -> Result<(), PhosphorError> {
        let (width, height) = (self.width, self.height);
        if width == 0 || height == 0 {
            return Err(PhosphorError::ZeroSize { width, height });
        }
        if width > MAX_SIZE || height > MAX_SIZE {
            return Err(PhosphorError::TooLarge { width, height });
        }
        if !(1..=16).contains(&self.bits) {
            return Err(PhosphorError::BadBits(self.bits));
        }
        if !(self.spot_sigma > 0.0 && self.spot_sigma <= MAX_SIGMA) {
            return Err(PhosphorError::BadSigma(self.spot_sigma));
        }
        if !(self.energy_per_sample.is_finite() && self.energy_per_sample >= 0.0) {
            return Err(PhosphorError::BadEnergy(self.energy_per_sample));
        }
        if !(self.exposure.is_finite() && self.exposure > 0.0) {
            return Err(PhosphorError::BadExposure(self.exposure));
        }
        if !(self.gamma.is_finite() && self.gamma > 0.0) {
            return Err(PhosphorError::BadGamma(self.gamma));
        }
        let Glow { strength, radius } = self.glow;
        let radius_ok = radius > 0.0 && radius <= MAX_SIGMA;
        if !(strength.is_finite() && strength >= 0.0 && (strength == 0.0 || radius_ok)) {
            return Err(PhosphorError::BadGlow { strength, radius });
        }
        if !(0.0..=1.0).contains(&self.persistence) {
            return Err(PhosphorError::BadPersistence(self.persistence));
        }
        if !(0.0..=1.0).contains(&self.show_blanked) {
            return Err(PhosphorError::BadShowBlanked(self.show_blanked));
        }
        self.palette.validate()
    }
}

/// Why a phosphor could not be made or its picture written.
#[derive(Debug)]
#[non_exhaustive]
pub enum PhosphorError {
    /// The image has no pixels.
    ZeroSize {
        /// Width asked for.
        width: u32,
        /// Height asked for.
        height: u32,
    },
    /// The image is wider or taller than [`MAX_SIZE`].
    TooLarge {
        /// Width asked for.
        width: u32,
        /// Height asked for.
        height: u32,
    },
    /// DAC resolution outside `1 ..= 16` bits.
    BadBits(u8),
    /// Spot size not finite, not positive, or above [`MAX_SIGMA`].
    BadSigma(f32),
    /// Energy per sample not finite or negative.
    BadEnergy(f32),
    /// Exposure not finite or not positive.
    BadExposure(f32),
    /// Gamma not finite or not positive.
    BadGamma(f32),
    /// Glow strength not finite or negative, or (with a non-zero strength)
    /// radius not in `0 < radius <= MAX_SIGMA`.
    BadGlow {
        /// Strength asked for.
        strength: f32,
        /// Radius asked for.
        radius: f32,
    },
    /// Persistence not in `0 ..= 1`.
    BadPersistence(f32),
    /// Blanked intensity not in `0 ..= 1`.
    BadShowBlanked(f32),
    /// An invalid palette, and why.
    BadPalette(&'static str),
    /// The PNG file could not be written.
    Io(std::io::Error),
    /// The PNG encoder failed.
    Png(png::EncodingError),
}

impl fmt::Display for PhosphorError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::ZeroSize { width, height } => write!(f, "image size {width}x{height} has no pixels"),
            Self::TooLarge { width, height } => {
                write!(f, "image size {width}x{height} is larger than {MAX_SIZE}x{MAX_SIZE}")
            }
            Self::BadBits(b) => write!(f, "DAC resolution {b} bits is not in 1..=16"),
            Self::BadSigma(s) => write!(f, "spot sigma {s} px is not in (0, {MAX_SIGMA}]"),
            Self::BadEnergy(e) => write!(f, "energy per sample {e} is not a finite non-negative number"),
            Self::BadExposure(e) => write!(f, "exposure {e} is not a finite positive number"),
            Self::BadGamma(g) => write!(f, "gamma {g} is not a finite positive number"),
            Self::BadGlow { strength, radius } => write!(
                f,
                "glow strength {strength} must be finite and >= 0, and with it the radius {radius} px \
                 in (0, {MAX_SIGMA}]"
            ),
            Self::BadPersistence(p) => write!(f, "persistence {p} is not in 0..=1"),
            Self::BadShowBlanked(s) => write!(f, "blanked intensity {s} is not in 0..=1"),
            Self::BadPalette(why) => write!(f, "invalid palette: {why}"),
            Self::Io(e) => write!(f, "{e}"),
            Self::Png(e) => write!(f, "cannot encode the PNG: {e}"),
        }
    }
}

impl std::error::Error for PhosphorError {
    /// The cause's own cause: its message is in this one's already (an
    /// error chain printed whole would say it twice).
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Self::Io(e) => e.source(),
            Self::Png(e) => e.source(),
            _ => None,
        }
    }
}

impl From<png::EncodingError> for PhosphorError {
    fn from(e: png::EncodingError) -> Self {
        match e {
            png::EncodingError::IoError(e) => Self::Io(e),
            e => Self::Png(e),
        }
    }
}

/// Entries of the tone-mapping table, over `1 - exp(-exposure * E)` in
/// `0 ..= 1`.
const LUT_SIZE: usize = 1 << 14;

/// The screen: an energy buffer, the beam's last position, and the tone
/// mapping. See the [module docs](self).
#[derive(Debug, Clone)]
pub struct Phosphor {
    cfg: PhosphorConfig,
    width: usize,
    height: usize,
    /// The picture's rows this phosphor draws ([`Phosphor::band`]).
    rows: Range<usize>,
    /// The rows whose energy it keeps: `rows` and the glow's reach above
    /// and below, within the picture.
    kept: Range<usize>,
    /// The energy of the `kept` rows.
    energy: Vec<f32>,
    /// The last sample deposited: where the beam is.
    prev: Option<Sample>,
    /// Pixels per code on X and on Y.
    px_per_code: (f32, f32),
    /// `1 / (2 σ²)`.
    inv_2s2: f32,
    /// `1 / (√2 σ)`.
    inv_sqrt2_s: f32,
    /// `1 / (√(2π) σ)`.
    norm1: f32,
    /// `1 / (2π σ²)`.
    norm2: f32,
    /// [`WINDOW_SIGMAS`] σ.
    reach: f32,
    /// Display value table: `1 - exp(-exposure * E)` to RGB.
    lut: Vec<[u8; 3]>,
    /// Per-column Gaussian factors of a spot.
    scratch: Vec<f32>,
    /// The straight run of steps not yet deposited ([`Stroke`]).
    stroke: Stroke,
    /// Segments deposited (strokes and steps; spots not counted).
    segments: u64,
}

/// Most steps one [`Stroke`] holds.
const STROKE_STEPS: usize = 32;

/// Consecutive steps of equal energy that the beam takes along one straight
/// line at one speed, deposited as one segment once the run ends: the same
/// integral (energy per unit of length is the step's energy over its
/// length, so the run is uniform), in a third to a half of the pixel work
/// for the 2 to 4 steps a contour's runs hold, since the spot's
/// [`WINDOW_SIGMAS`] reach at either end of each step is paid once a run.
///
/// A step joins the run while every sample of the run stays within
/// [`STROKE_TOLERANCE`] `σ` (on each axis) of where a uniform sweep from
/// the run's start to the new end puts it: the DAC's codes round the
/// scheduler's straight lines by up to half an LSB, so the steps of one line
/// are not exactly equal, and the tube's deflection, which smooths each
/// step, does not draw the rounding either.
#[derive(Debug, Clone)]
struct Stroke {
    /// Where the run starts (pixel coordinates).
    start: (f32, f32),
    /// The ends of its steps, in order: `ends[..steps]`.
    ends: [(f32, f32); STROKE_STEPS],
    /// Steps in the run; 0 for none.
    steps: usize,
    /// Energy of each step.
    energy: f32,
}

/// How far (in units of the spot's `σ`, on each axis) a sample of a
/// [`Stroke`] may lie from the straight, uniform sweep it is drawn as:
/// 0.2 σ is a sixth of a pixel at 640x640 (one LSB of 12 bits), a quarter
/// at 1024x1024.
pub const STROKE_TOLERANCE: f32 = 0.2;

impl Phosphor {
    /// A black screen.
    ///
    /// # Errors
    /// [`PhosphorConfig::validate`]'s.
    pub fn new(cfg: PhosphorConfig) -> Result<Self, PhosphorError> {
        let rows = 0..cfg.height as usize;
        Self::band(cfg, rows)
    }

    /// A black screen that draws only the picture's rows `rows` (clamped
    /// to the picture): exactly the bytes of those rows of the whole
    /// picture, from the same samples. It deposits into them and as many
    /// rows on either side as the glow reaches, so bands of one picture
    /// drawn apart (on several cores) and stacked are the picture, bit for
    /// bit: each pixel adds the same steps in the same order.
    ///
    /// # Errors
    /// [`PhosphorConfig::validate`]'s.
    pub fn band(cfg: PhosphorConfig, rows: Range<usize>) -> Result<Self, PhosphorError> {
        cfg.validate()?;
        let (width, height) = (cfg.width as usize, cfg.height as usize);
        let rows = rows.start.min(height)..rows.end.min(height);
        let rows = rows.start..rows.end.max(rows.start);
        let kept =
            if cfg.glow.strength > 0.0 { glow_kept(&rows, height, cfg.glow.radius) } else { rows.clone() };
        let codes = (1u32 << cfg.bits) as f32;
        let s = cfg.spot_sigma;
        let inv_gamma = 1.0 / cfg.gamma;
        let lut = (0..LUT_SIZE)
            .map(|i| {
                let v = i as f32 / (LUT_SIZE - 1) as f32;
                cfg.palette.color(v.powf(inv_gamma)).map(|c| (c * 255.0 + 0.5) as u8)
            })
            .collect();
        Ok(Self {
            width,
            height,
            energy: vec![0.0; width * kept.len()],
            rows,
            kept,
            prev: None,
            px_per_code: (cfg.width as f32 / codes, cfg.height as f32 / codes),
            inv_2s2: 1.0 / (2.0 * s * s),
            inv_sqrt2_s: 1.0 / (std::f32::consts::SQRT_2 * s),
            norm1: 1.0 / ((2.0 * std::f32::consts::PI).sqrt() * s),
            norm2: 1.0 / (2.0 * std::f32::consts::PI * s * s),
            reach: WINDOW_SIGMAS * s,
            lut,
            scratch: Vec::new(),
            stroke: Stroke { start: (0.0, 0.0), ends: [(0.0, 0.0); STROKE_STEPS], steps: 0, energy: 0.0 },
            segments: 0,
            cfg,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &PhosphorConfig {
        &self.cfg
    }

    /// Image width in pixels.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Image height in pixels.
    pub fn height(&self) -> usize {
        self.height
    }

    /// The energy of every pixel, row by row from the top, in units of
    /// [`PhosphorConfig::energy_per_sample`] per pixel: of the rows kept
    /// ([`Phosphor::kept`]), all of them for a whole picture.
    pub fn energy(&self) -> &[f32] {
        &self.energy
    }

    /// The picture's rows this phosphor draws ([`Phosphor::band`]).
    pub fn rows(&self) -> Range<usize> {
        self.rows.clone()
    }

    /// The rows whose energy [`Phosphor::energy`] holds: [`Phosphor::rows`]
    /// and the glow's reach on either side, within the picture.
    pub fn kept(&self) -> Range<usize> {
        self.kept.clone()
    }

    /// Row `j`'s pixels `i0 ..= i1` of the energy, if `j` is kept.
    fn energy_row(&mut self, j: usize, i0: usize, i1: usize) -> Option<&mut [f32]> {
        let r = j.checked_sub(self.kept.start).filter(|_| j < self.kept.end)?;
        self.energy.get_mut(r * self.width + i0..=r * self.width + i1)
    }

    /// The sum of [`Phosphor::energy`].
    pub fn total_energy(&self) -> f64 {
        self.energy.iter().map(|&e| f64::from(e)).sum()
    }

    /// The last sample deposited (where the beam is), if any since the
    /// phosphor was made or cleared.
    pub fn beam(&self) -> Option<Sample> {
        self.prev
    }

    /// Deposit samples, in order, one DAC tick each (see the
    /// [module docs](self)). The beam's position is kept across calls, so a
    /// frame can be streamed in chunks.
    pub fn deposit(&mut self, samples: impl IntoIterator<Item = Sample>) {
        let blanked = self.cfg.show_blanked;
        // Energy (in samples) waiting to be deposited as a spot at `prev`.
        let mut spot = 0.0f64;
        for s in samples {
            let w = match s.beam {
                Beam::On => 1.0,
                Beam::Off => blanked,
            };
            match self.prev {
                Some(p) if (p.x, p.y) != (s.x, s.y) => {
                    self.flush_spot(p, spot);
                    spot = 0.0;
                    if w > 0.0 {
                        self.step(self.position(p), self.position(s), w * self.cfg.energy_per_sample);
                    } else {
                        self.flush_stroke();
                    }
                }
                _ => {
                    self.flush_stroke();
                    spot += f64::from(w);
                }
            }
            self.prev = Some(s);
        }
        self.flush_stroke();
        if let Some(p) = self.prev {
            self.flush_spot(p, spot);
        }
    }

    /// The beam's step from `a` to `b`, of energy `e`: onto the stroke if it
    /// continues it ([`Stroke`]), else the stroke deposited and a new one
    /// begun with this step.
    fn step(&mut self, a: (f32, f32), b: (f32, f32), e: f32) {
        let tol = STROKE_TOLERANCE * self.cfg.spot_sigma;
        let k = &mut self.stroke;
        let joins = k.steps > 0 && k.steps < STROKE_STEPS && k.energy == e && {
            // Sample i of n + 1 steps is due at start + (b - start) i / (n + 1).
            let n = (k.steps + 1) as f32;
            let (dx, dy) = ((b.0 - k.start.0) / n, (b.1 - k.start.1) / n);
            (1..).zip(&k.ends[..k.steps]).all(|(i, &(x, y))| {
                let t = i as f32;
                (x - (k.start.0 + dx * t)).abs() <= tol && (y - (k.start.1 + dy * t)).abs() <= tol
            })
        };
        if !joins {
            self.flush_stroke();
            let k = &mut self.stroke;
            (k.start, k.energy) = (a, e);
        }
        let k = &mut self.stroke;
        k.ends[k.steps] = b;
        k.steps += 1;
    }

    /// Deposit the stroke waiting, if any: one segment from its start to
    /// its last end, of all its steps' energy.
    fn flush_stroke(&mut self) {
        let k = &self.stroke;
        if let Some(&end) = k.steps.checked_sub(1).and_then(|last| k.ends.get(last)) {
            let (start, e) = (k.start, k.energy * k.steps as f32);
            self.stroke.steps = 0;
            self.segments += 1;
            self.segment(start, end, e);
        }
    }

    /// Let the phosphor fade between frames: multiply every pixel's energy by
    /// [`PhosphorConfig::persistence`].
    #[cfg_attr(target_arch = "wasm32", target_feature(enable = "simd128"))]
    pub fn decay(&mut self) {
        let k = self.cfg.persistence;
        self.energy.iter_mut().for_each(|e| *e *= k);
    }

    /// A black screen again, and no beam position (the next sample is a
    /// spot).
    pub fn clear(&mut self) {
        self.energy.fill(0.0);
        self.prev = None;
    }

    /// The picture: `width * height` RGB pixels, 8 bits a channel, row by row
    /// from the top (of a band, its rows alone). Glow, then
    /// `t = (1 - exp(-exposure * E))^(1 / gamma)`, then the palette.
    pub fn to_rgb8(&self) -> Vec<u8> {
        self.to_pixels::<3>()
    }

    /// The picture as [`Phosphor::to_rgb8`] gives it, with an opaque alpha
    /// byte after each pixel's RGB: a canvas's `ImageData`.
    pub fn to_rgba8(&self) -> Vec<u8> {
        self.to_pixels::<4>()
    }

    /// The picture, `N` bytes a pixel: RGB, then 255 for the rest.
    #[cfg_attr(target_arch = "wasm32", target_feature(enable = "simd128"))]
    fn to_pixels<const N: usize>(&self) -> Vec<u8> {
        let glow = self.cfg.glow;
        let w = self.width;
        // The rows drawn, within the rows kept.
        let drawn = self.rows.start - self.kept.start..self.rows.end - self.kept.start;
        let energy = self.energy.get(drawn.start * w..drawn.end * w).unwrap_or_default();
        // The energy seen, glow included.
        let seen = if glow.strength > 0.0 {
            let mut halo =
                glow_of(&self.energy, w, self.kept.clone(), self.rows.clone(), self.height, glow.radius);
            for (h, &e) in halo.iter_mut().zip(energy) {
                *h = e + glow.strength * *h;
            }
            halo
        } else {
            energy.to_vec()
        };
        // To table indices (a vector loop), then colours.
        let (exposure, top) = (self.cfg.exposure, (LUT_SIZE - 1) as f32);
        // A plain loop, not `map` and `collect`: the closure would be a
        // function of its own, without this one's SIMD.
        let mut index = vec![0u32; seen.len()];
        for (i, &e) in index.iter_mut().zip(&seen) {
            // `v` is in 0..=1 (NaN only for a NaN energy, which `as` maps to 0).
            *i = ((1.0 - exp_neg(-exposure * e)) * top + 0.5).clamp(0.0, top) as u32;
        }
        let mut out = vec![u8::MAX; seen.len() * N];
        for (px, &i) in out.chunks_exact_mut(N).zip(&index) {
            px[..3].copy_from_slice(&self.lut[(i as usize).min(LUT_SIZE - 1)]);
        }
        out
    }

    /// The picture as an 8-bit RGB PNG file, written whole or not at all
    /// ([`crate::outfile`]).
    ///
    /// # Errors
    /// The file cannot be created or written ([`PhosphorError::Io`] or
    /// [`PhosphorError::Png`] inside, the path named).
    pub fn write_png(&self, path: impl AsRef<Path>) -> anyhow::Result<()> {
        write_png(path.as_ref(), self.cfg.width, self.rows.len(), &self.to_rgb8())
    }

    /// The picture as the bytes of an 8-bit RGB PNG file (of a band, its
    /// rows; none for a band of no rows).
    pub fn encode_png(&self) -> Vec<u8> {
        encode_png(self.cfg.width, self.rows.len(), &self.to_rgb8())
    }

    /// A sample's position in pixel coordinates (y down).
    fn position(&self, s: Sample) -> (f32, f32) {
        let (kx, ky) = self.px_per_code;
        ((f32::from(s.x) + 0.5) * kx, self.height as f32 - (f32::from(s.y) + 0.5) * ky)
    }

    fn flush_spot(&mut self, at: Sample, samples: f64) {
        let e = samples * f64::from(self.cfg.energy_per_sample);
        if e > 0.0 {
            self.spot(self.position(at), e as f32);
        }
    }

    /// The pixel index range whose centres `i + 0.5` lie in `lo ..= hi`,
    /// within `0 .. n`; `None` if empty.
    fn pixel_range(lo: f32, hi: f32, n: usize) -> Option<(usize, usize)> {
        // NaN compares false: an empty range.
        if lo.is_nan() || hi.is_nan() || lo > hi {
            return None;
        }
        // `as` saturates, so huge or infinite bounds are safe.
        let first = ceil_i64(lo - 0.5).max(0);
        let last = floor_i64(hi - 0.5).min(n as i64 - 1);
        (first <= last).then_some((first as usize, last as usize))
    }

    /// A Gaussian spot of energy `e` at `c`.
    #[cfg_attr(target_arch = "wasm32", target_feature(enable = "simd128"))]
    fn spot(&mut self, c: (f32, f32), e: f32) {
        let r = self.reach;
        let (Some((i0, i1)), Some((j0, j1))) = (
            Self::pixel_range(c.0 - r, c.0 + r, self.width),
            Self::pixel_range(c.1 - r, c.1 + r, self.height),
        ) else {
            return;
        };
        let a = self.inv_2s2;
        let mut gx = std::mem::take(&mut self.scratch);
        gx.clear();
        gx.resize(i1 - i0 + 1, 0.0);
        for (g, i) in gx.iter_mut().zip(i0..) {
            let d = i as f32 + 0.5 - c.0;
            *g = exp_neg(-d * d * a);
        }
        let scale = e * self.norm2;
        for j in j0.max(self.kept.start)..=j1.min(self.kept.end.saturating_sub(1)) {
            let d = j as f32 + 0.5 - c.1;
            let gy = scale * exp_neg(-d * d * a);
            let Some(row) = self.energy_row(j, i0, i1) else { continue };
            for (px, &g) in row.iter_mut().zip(&gx) {
                *px += gy * g;
            }
        }
        self.scratch = gx;
    }

    /// A step from `a` to `b` depositing energy `e`: the spot integrated
    /// along the segment.
    #[cfg_attr(target_arch = "wasm32", target_feature(enable = "simd128"))]
    fn segment(&mut self, a: (f32, f32), b: (f32, f32), e: f32) {
        let (dx, dy) = (b.0 - a.0, b.1 - a.1);
        let len = (dx * dx + dy * dy).sqrt();
        if len < 1e-3 * self.cfg.spot_sigma {
            self.spot(((a.0 + b.0) * 0.5, (a.1 + b.1) * 0.5), e);
            return;
        }
        let (ux, uy) = (dx / len, dy / len);
        let r = self.reach;
        let Some((j0, j1)) = Self::pixel_range(a.1.min(b.1) - r, a.1.max(b.1) + r, self.height) else {
            return;
        };
        let (a2, k) = (self.inv_2s2, self.inv_sqrt2_s);
        let scale = e * self.norm1 / (2.0 * len);
        let (xlo, xhi) = (a.0.min(b.0) - r, a.0.max(b.0) + r);
        let (inv_ux, inv_uy) = (1.0 / ux, 1.0 / uy);
        for j in j0.max(self.kept.start)..=j1.min(self.kept.end.saturating_sub(1)) {
            let ry = j as f32 + 0.5 - a.1;
            // Along the row, x = a.0 + t: the along coordinate is
            // u = t ux + ry uy, the signed distance d = -t uy + ry ux. Keep
            // the pixels of the rectangle -r <= u <= len + r, |d| <= r.
            let mut span = (xlo - a.0, xhi - a.0);
            clip(&mut span, ux, inv_ux, ry * uy, -r, len + r);
            clip(&mut span, -uy, -inv_uy, ry * ux, -r, r);
            let Some((i0, i1)) = Self::pixel_range(span.0 + a.0, span.1 + a.0, self.width) else {
                continue;
            };
            let t0 = i0 as f32 + 0.5 - a.0;
            let (u0, d0) = (t0 * ux + ry * uy, -t0 * uy + ry * ux);
            let Some(row) = self.energy_row(j, i0, i1) else { continue };
            for (n, px) in (0i32..).zip(row.iter_mut()) {
                let m = n as f32;
                let (u, d) = (u0 + m * ux, d0 - m * uy);
                *px += scale * exp_neg(-d * d * a2) * (erf(u * k) - erf((u - len) * k));
            }
        }
    }
}

/// A picture drawn in bands of rows on threads of their own, each band a
/// [`Phosphor::band`]: the bytes of one [`Phosphor`] from the same samples,
/// in about `1 / n` of the time on `n` cores. (On one band, or where
/// there are no threads, the band is drawn where it is called.)
#[derive(Debug, Clone)]
pub struct Screen {
    cfg: PhosphorConfig,
    bands: Vec<Phosphor>,
}

impl Screen {
    /// A black screen of `bands` bands (at least one, at most a row each).
    ///
    /// # Errors
    /// [`PhosphorConfig::validate`]'s.
    pub fn new(cfg: PhosphorConfig, bands: usize) -> Result<Self, PhosphorError> {
        let n = Self::band_count(&cfg, bands);
        let bands = (0..n)
            .map(|k| Phosphor::band(cfg.clone(), Self::band_rows(&cfg, k, n)))
            .collect::<Result<_, _>>()?;
        Ok(Self { cfg, bands })
    }

    /// Band `band` of the `bands` of [`Screen::new`] alone: a screen of
    /// its rows, drawn from the same samples as the whole picture (another
    /// thread or worker draws the others). `band` past the last is the
    /// last.
    ///
    /// # Errors
    /// [`PhosphorConfig::validate`]'s.
    pub fn band(cfg: PhosphorConfig, band: usize, bands: usize) -> Result<Self, PhosphorError> {
        let n = Self::band_count(&cfg, bands);
        let rows = Self::band_rows(&cfg, band.min(n - 1), n);
        let bands = vec![Phosphor::band(cfg.clone(), rows)?];
        Ok(Self { cfg, bands })
    }

    /// How many bands a picture of `cfg` is drawn in when `bands` are
    /// asked for: at least one, at most a row each.
    fn band_count(cfg: &PhosphorConfig, bands: usize) -> usize {
        bands.clamp(1, (cfg.height as usize).max(1))
    }

    /// The rows of band `k` of `n`.
    fn band_rows(cfg: &PhosphorConfig, k: usize, n: usize) -> Range<usize> {
        let height = cfg.height as usize;
        k * height / n..(k + 1) * height / n
    }

    /// The picture's rows this screen draws: all of them, or a band's.
    pub fn rows(&self) -> Range<usize> {
        let start = self.bands.first().map_or(0, |b| b.rows().start);
        start..self.bands.last().map_or(start, |b| b.rows().end)
    }

    /// The configuration.
    pub fn config(&self) -> &PhosphorConfig {
        &self.cfg
    }

    /// [`Phosphor::clear`], every band.
    pub fn clear(&mut self) {
        self.bands.iter_mut().for_each(Phosphor::clear);
    }

    /// [`Phosphor::decay`], every band.
    pub fn decay(&mut self) {
        // A closure: on wasm `decay` has a target feature, which a function
        // pointer cannot carry.
        #[allow(clippy::redundant_closure_for_method_calls)]
        self.bands.iter_mut().for_each(|p| p.decay());
    }

    /// One refresh of a frame: the phosphor fades ([`Screen::decay`]),
    /// then `samples` are deposited ([`Screen::deposit`]).
    pub fn refresh(&mut self, samples: &[Sample]) {
        self.decay();
        self.deposit(samples);
    }

    /// [`Phosphor::deposit`] of `samples`, every band on a thread.
    pub fn deposit(&mut self, samples: &[Sample]) {
        self.each(|p| p.deposit(samples.iter().copied()));
    }

    /// [`Phosphor::to_rgb8`]: the bands' rows, worked out on threads.
    pub fn to_rgb8(&self) -> Vec<u8> {
        self.pixels(Phosphor::to_rgb8)
    }

    /// [`Phosphor::to_rgba8`]: the bands' rows, worked out on threads.
    pub fn to_rgba8(&self) -> Vec<u8> {
        self.pixels(Phosphor::to_rgba8)
    }

    /// [`Phosphor::write_png`].
    ///
    /// # Errors
    /// As [`Phosphor::write_png`].
    pub fn write_png(&self, path: impl AsRef<Path>) -> anyhow::Result<()> {
        write_png(path.as_ref(), self.config().width, self.config().height as usize, &self.to_rgb8())
    }

    /// [`Phosphor::encode_png`].
    pub fn encode_png(&self) -> Vec<u8> {
        encode_png(self.config().width, self.config().height as usize, &self.to_rgb8())
    }

    fn each(&mut self, f: impl Fn(&mut Phosphor) + Sync) {
        match self.bands.as_mut_slice() {
            [one] => f(one),
            bands => std::thread::scope(|s| {
                let f = &f;
                for b in bands {
                    s.spawn(move || f(b));
                }
            }),
        }
    }

    fn pixels(&self, f: impl Fn(&Phosphor) -> Vec<u8> + Sync) -> Vec<u8> {
        match self.bands.as_slice() {
            [one] => f(one),
            bands => std::thread::scope(|s| {
                let f = &f;
                let parts: Vec<_> = bands.iter().map(|b| s.spawn(move || f(b))).collect();
                // A band's panic (a bug) is the caller's.
                parts
                    .into_iter()
                    .flat_map(|h| h.join().unwrap_or_else(|e| std::panic::resume_unwind(e)))
                    .collect()
            }),
        }
    }
}

/// An 8-bit RGB PNG of `rgb` (`width` pixels by `rows`), written whole or
/// not at all ([`crate::outfile`]).
fn write_png(path: &Path, width: u32, rows: usize, rgb: &[u8]) -> anyhow::Result<()> {
    crate::outfile::write_whole(path, |w| {
        anyhow::Context::with_context(png_to(w, width, rows, rgb).map_err(PhosphorError::from), || {
            format!("cannot write {}", path.display())
        })
    })
}

/// The bytes of an 8-bit RGB PNG of `rgb` (`width` pixels by `rows`):
/// none for no rows (writing to a `Vec` cannot fail otherwise, and the
/// header matches the data: a validated size, three bytes a pixel).
pub fn encode_png(width: u32, rows: usize, rgb: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    match png_to(&mut out, width, rows, rgb) {
        Ok(()) => out,
        Err(_) => Vec::new(),
    }
}

fn png_to<W: Write>(w: W, width: u32, rows: usize, rgb: &[u8]) -> Result<(), png::EncodingError> {
    let mut enc = png::Encoder::new(w, width, u32::try_from(rows).unwrap_or(u32::MAX));
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    let mut writer = enc.write_header()?;
    writer.write_image_data(rgb)?;
    writer.finish()
}

/// The largest integer `<= x` (saturating; NaN gives 0).
fn floor_i64(x: f32) -> i64 {
    let i = x as i64;
    if (i as f32) > x { i - 1 } else { i }
}

/// The smallest integer `>= x` (saturating; NaN gives 0).
fn ceil_i64(x: f32) -> i64 {
    let i = x as i64;
    if (i as f32) < x { i + 1 } else { i }
}

/// Narrow `span` (values of `t`) to where `lo <= coef * t + c <= hi`;
/// `inv` is `1 / coef`.
fn clip(span: &mut (f32, f32), coef: f32, inv: f32, c: f32, lo: f32, hi: f32) {
    if coef.abs() < 1e-6 {
        if c < lo || c > hi {
            *span = (1.0, 0.0);
        }
        return;
    }
    let (p, q) = ((lo - c) * inv, (hi - c) * inv);
    span.0 = span.0.max(p.min(q));
    span.1 = span.1.min(p.max(q));
}

/// `exp(x)` for `x <= 0` (clamped into `-80 ..= 0`; -80 gives about
/// 1.8e-35), in plain `f32` arithmetic and bit operations so that loops
/// over it vectorise: `x = n ln 2 + f` with `n` the nearest integer to
/// `x / ln 2` (by the 1.5 * 2^23 rounding trick) and `f` in about
/// `-0.35 ..= 0.35` (Cody and Waite's two-part `ln 2`, so `f` is nearly
/// exact), `e^f` by its degree-7 Taylor polynomial (truncation error below
/// 5e-9), and `n` added to the exponent bits. Relative error below 3e-7
/// (a unit test checks it), from `f32` rounding.
#[inline(always)]
fn exp_neg(x: f32) -> f32 {
    const MAGIC: f32 = 12_582_912.0; // 1.5 * 2^23
    const LN2_HI: f32 = 0.693_145_75; // 0x3f317200: 16 significant bits, so n * LN2_HI is exact
    const LN2_LO: f32 = 1.428_606_8e-6;
    let x = x.clamp(-80.0, 0.0);
    let r = x * std::f32::consts::LOG2_E + MAGIC;
    let n = r - MAGIC;
    let i = (r.to_bits() as i32).wrapping_sub(MAGIC.to_bits() as i32);
    let f = (x - n * LN2_HI) - n * LN2_LO;
    let p = 1.0
        + f * (1.0
            + f * (1.0 / 2.0
                + f * (1.0 / 6.0
                    + f * (1.0 / 24.0 + f * (1.0 / 120.0 + f * (1.0 / 720.0 + f * (1.0 / 5040.0)))))));
    f32::from_bits((p.to_bits() as i32).wrapping_add(i.wrapping_shl(23)) as u32)
}

/// The error function, Abramowitz and Stegun 7.1.26:
/// `erf x = 1 - (a1 t + a2 t² + a3 t³ + a4 t⁴ + a5 t⁵) exp(-x²)`,
/// `t = 1 / (1 + p x)` for `x >= 0`, odd. The formula's absolute error is
/// below 1.5e-7; in `f32` with [`exp_neg`], below 5e-7 (a unit test checks
/// it against a series). Branch-free, so loops over it vectorise.
#[inline(always)]
fn erf(x: f32) -> f32 {
    const P: f32 = 0.327_591_1;
    const A: [f32; 5] = [0.254_829_6, -0.284_496_74, 1.421_413_8, -1.453_152, 1.061_405_4];
    // A select, not `f32::min`: the same value for every input (NaN
    // included), where wasm's `f32.min` is not Rust's and `min` took a
    // longer sequence there.
    let a = x.abs();
    let a = if a < 10.0 { a } else { 10.0 };
    let t = 1.0 / (1.0 + P * a);
    let poly = t * (A[0] + t * (A[1] + t * (A[2] + t * (A[3] + t * A[4]))));
    (1.0 - poly * exp_neg(-a * a)).copysign(x)
}

/// Rows a blur of standard deviation `sigma` reaches on either side: its
/// kernel's half width.
fn glow_reach(sigma: f32) -> usize {
    (3.0 * sigma).ceil() as usize
}

/// The smallest glow radius (pixels) worked out on the grid of 2x2 pixel
/// blocks ([`glow_of`]): from 512x512 pictures up with the default
/// settings. Below it a block is too coarse for the halo (at a radius of 2
/// pixels the halo of a bright spot is off by a tenth of its peak; from 3
/// up by at most a twentieth, a test checks).
const COARSE_GLOW_RADIUS: f32 = 3.0;

/// The rows whose energy the glow of rows `rows` needs ([`glow_of`]), within
/// the picture's `height` rows: on the grid of blocks, whole blocks.
fn glow_kept(rows: &Range<usize>, height: usize, radius: f32) -> Range<usize> {
    if radius < COARSE_GLOW_RADIUS {
        let reach = glow_reach(radius);
        return rows.start.saturating_sub(reach)..(rows.end + reach).min(height);
    }
    // Output rows y need blocks y / 2 - 1 ..= y / 2 + 1, each the blur's
    // reach of blocks around it: 2 (reach + 2) rows either side, in pairs.
    let reach = 2 * (glow_reach(coarse_sigma(radius)) + 2);
    let start = rows.start.saturating_sub(reach) & !1;
    start..(rows.end + reach).next_multiple_of(2).min(height)
}

/// The standard deviation, in blocks, of the blur on the grid of 2x2
/// blocks whose result matches a blur of `radius` pixels: averaging a block
/// and interpolating back each widen it by their own variance (1/4 px²
/// and 1/2 px² for blocks of two), taken off here.
fn coarse_sigma(radius: f32) -> f32 {
    (radius * radius - 0.75).max(0.25).sqrt() / 2.0
}

/// The glow's blur ([`Glow`]) of rows `out` of the picture, from the
/// energy `src` of its rows `kept` ([`glow_kept`]): a Gaussian of standard
/// deviation `radius` pixels ([`blur`]); from [`COARSE_GLOW_RADIUS`] up on
/// the grid of 2x2 pixel blocks (their mean, blurred by
/// [`coarse_sigma`], interpolated back bilinearly, edges clamped), in a
/// fifth of the work: the halo is wide and faint, and a block's detail is
/// below what it shows.
#[cfg_attr(target_arch = "wasm32", target_feature(enable = "simd128"))]
fn glow_of(
    src: &[f32],
    width: usize,
    kept: Range<usize>,
    out: Range<usize>,
    height: usize,
    radius: f32,
) -> Vec<f32> {
    if radius < COARSE_GLOW_RADIUS {
        return blur(src, width, kept, out, height, radius);
    }
    // The blocks: kept starts on an even row and ends on one or at the
    // picture's end (glow_kept); a last odd row or column is a half block.
    let (cw, ch) = (width.div_ceil(2), height.div_ceil(2));
    let ckept = kept.start / 2..kept.end.div_ceil(2);
    let mut coarse = vec![0.0f32; ckept.len() * cw];
    for (k, crow) in coarse.chunks_exact_mut(cw).enumerate() {
        for row in src.chunks_exact(width).skip(2 * k).take(2) {
            let (pairs, last) = row.as_chunks::<2>();
            for (c, &[a, b]) in crow.iter_mut().zip(pairs) {
                *c += 0.25 * (a + b);
            }
            if let (Some(&a), Some(c)) = (last.first(), crow.last_mut()) {
                *c += 0.25 * a;
            }
        }
    }
    // The blocks the output rows interpolate between, blurred.
    let cout = (out.start / 2).saturating_sub(1)..(out.end.div_ceil(2) + 1).min(ch);
    let blurred = blur(&coarse, cw, ckept, cout.clone(), ch, coarse_sigma(radius));
    let block_row = |b: usize| b.checked_sub(cout.start).and_then(|r| blurred.get(r * cw..(r + 1) * cw));
    // Back to pixels: pixel y is at block y / 2 - 1/4 (even y) or y / 2 +
    // 1/4 (odd y), and x likewise; the neighbour past an edge is the edge.
    let neighbour = |i: usize, n: usize| {
        if i.is_multiple_of(2) { (i / 2).saturating_sub(1) } else { (i / 2 + 1).min(n - 1) }
    };
    let mut dst = vec![0.0f32; out.len() * width];
    let mut line = vec![0.0f32; cw];
    for (y, orow) in out.zip(dst.chunks_exact_mut(width)) {
        let (Some(near), Some(far)) = (block_row(y / 2), block_row(neighbour(y, ch))) else { continue };
        for ((l, &n), &f) in line.iter_mut().zip(near).zip(far) {
            *l = 0.75 * n + 0.25 * f;
        }
        let (pairs, last) = orow.as_chunks_mut::<2>();
        for (x, px) in pairs.iter_mut().enumerate() {
            // x < width / 2 <= cw.
            let (l, c, r) = (line[x.saturating_sub(1)], line[x], line[(x + 1).min(cw - 1)]);
            *px = [0.75 * c + 0.25 * l, 0.75 * c + 0.25 * r];
        }
        if let Some(px) = last.first_mut() {
            // The last column of an odd width: block cw - 1, an even pixel.
            *px = 0.75 * line[cw - 1] + 0.25 * line[(cw - 1).saturating_sub(1)];
        }
    }
    dst
}

/// A separable Gaussian blur of standard deviation `sigma` pixels (kernel
/// cut at 3 σ and normalised, zero outside the image of `height` rows):
/// rows `out` of it, from `src`, the image's rows `kept` (which must hold
/// `out` and [`glow_reach`] rows on either side, within the image).
#[cfg_attr(target_arch = "wasm32", target_feature(enable = "simd128"))]
fn blur(
    src: &[f32],
    width: usize,
    kept: Range<usize>,
    out: Range<usize>,
    height: usize,
    sigma: f32,
) -> Vec<f32> {
    let half = glow_reach(sigma);
    let mut kernel: Vec<f32> = (0..=2 * half)
        .map(|i| {
            let d = i as f32 - half as f32;
            (-d * d / (2.0 * sigma * sigma)).exp()
        })
        .collect();
    let sum: f32 = kernel.iter().sum();
    kernel.iter_mut().for_each(|k| *k /= sum);
    // Horizontal: out[x] += k[t] * src[x + t - half].
    let mut tmp = vec![0.0f32; src.len()];
    for (out, row) in tmp.chunks_exact_mut(width).zip(src.chunks_exact(width)) {
        for (t, &k) in kernel.iter().enumerate() {
            // Source x = out x + t - half.
            let (o0, s0) = if t < half { (half - t, 0) } else { (0, t - half) };
            if o0 >= width || s0 >= width {
                continue;
            }
            let n = (width - o0).min(width - s0);
            for (o, &s) in out[o0..o0 + n].iter_mut().zip(&row[s0..s0 + n]) {
                *o += k * s;
            }
        }
    }
    // Vertical: out row y += k[t] * tmp row (y + t - half).
    let mut dst = vec![0.0f32; out.len() * width];
    for (y, orow) in out.zip(dst.chunks_exact_mut(width)) {
        for (t, &k) in kernel.iter().enumerate() {
            let Some(sy) = (y + t).checked_sub(half).filter(|&sy| sy < height) else {
                continue;
            };
            let Some(trow) = sy.checked_sub(kept.start).and_then(|r| tmp.get(r * width..(r + 1) * width))
            else {
                continue;
            };
            for (o, &s) in orow.iter_mut().zip(trow) {
                *o += k * s;
            }
        }
    }
    dst
}

impl Dac for Phosphor {
    type Error = Infallible;

    /// [`Phosphor::deposit`].
    fn write<I>(&mut self, samples: I) -> Result<(), Infallible>
    where
        I: IntoIterator<Item = Sample>,
    {
        self.deposit(samples);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MAX: u16 = 4095;

    fn on(x: u16, y: u16) -> Sample {
        Sample::new(x, y, Beam::On)
    }

    fn off(x: u16, y: u16) -> Sample {
        Sample::new(x, y, Beam::Off)
    }

    fn small() -> PhosphorConfig {
        PhosphorConfig { glow: Glow { strength: 0.0, radius: 1.0 }, ..PhosphorConfig::with_size(64, 64) }
    }

    fn screen(cfg: PhosphorConfig) -> Phosphor {
        Phosphor::new(cfg).unwrap()
    }

    /// A horizontal line at code `y` from code `x0` to `x1` in `n` equal
    /// steps (`n + 1` samples, the first a spot).
    fn hline(y: u16, x0: u16, x1: u16, n: u16) -> Vec<Sample> {
        (0..=n).map(|k| on(x0 + ((u32::from(x1 - x0) * u32::from(k)) / u32::from(n)) as u16, y)).collect()
    }

    /// Bands of a picture drawn apart and stacked are the picture, byte for
    /// byte: with and without glow, a frame and a faded second one over it,
    /// lines, dwells, blanked jumps and samples off the screen's edge.
    #[test]
    fn bands_drawn_apart_are_the_picture() {
        let mut frame = vec![on(0, 0), on(MAX, MAX), off(100, 3000), on(100, 3000), on(100, 3000)];
        frame.extend(hline(2048, 10, 4000, 37));
        let mut x = 12_345u32;
        for _ in 0..300 {
            x = x.wrapping_mul(1_103_515_245).wrapping_add(12_345);
            let s = Sample::new((x >> 8) as u16 % 4200, (x >> 18) as u16 % 4096, Beam::On);
            frame.push(s);
        }
        let glows = [
            Glow { strength: 0.0, radius: 1.0 },
            Glow { strength: 0.04, radius: 1.5 },
            Glow { strength: 0.04, radius: 3.0 },
            Glow { strength: 0.3, radius: 7.5 },
        ];
        // (An odd size: a half block of the coarse glow at the right and
        // the bottom, as in the sizes below.)
        for (glow, (w, h)) in glows.into_iter().zip([(96, 80), (96, 80), (97, 81), (96, 80)]) {
            let cfg = PhosphorConfig { glow, ..PhosphorConfig::with_size(w, h) };
            let (w, h) = (w as usize, h as usize);
            let draw = |p: &mut Phosphor| {
                p.deposit(frame.iter().copied());
                p.decay();
                p.deposit(frame.iter().rev().copied());
                (p.to_rgb8(), p.to_rgba8())
            };
            let whole = draw(&mut screen(cfg.clone()));
            for cuts in [vec![0, h], vec![0, 40, h], vec![0, 1, 2, 79, h], vec![0, 13, 13, 50, 67, h]] {
                let (mut rgb, mut rgba) = (Vec::new(), Vec::new());
                for cut in cuts.windows(2) {
                    let mut band = Phosphor::band(cfg.clone(), cut[0]..cut[1]).unwrap();
                    assert_eq!(band.rows(), cut[0]..cut[1]);
                    let (a, b) = draw(&mut band);
                    assert_eq!(a.len(), w * 3 * (cut[1] - cut[0]));
                    rgb.extend(a);
                    rgba.extend(b);
                }
                assert!(rgb == whole.0, "glow {glow:?}, bands {cuts:?}: RGB differs");
                assert!(rgba == whole.1, "glow {glow:?}, bands {cuts:?}: RGBA differs");
            }
        }
        // A screen of bands on threads draws the same bytes and PNG.
        let cfg = PhosphorConfig::with_size(96, 80);
        for n in [1, 2, 3, 80, 1000] {
            let mut bands = Screen::new(cfg.clone(), n).unwrap();
            bands.deposit(&frame);
            bands.decay();
            bands.deposit(&frame);
            let mut one = screen(cfg.clone());
            one.deposit(frame.iter().copied());
            one.decay();
            one.deposit(frame.iter().copied());
            assert!(bands.to_rgba8() == one.to_rgba8(), "{n} bands");
            assert_eq!(bands.encode_png(), one.encode_png(), "{n} bands");
        }
        // Rows past the picture are clamped: an empty band draws nothing.
        let mut past = Phosphor::band(small(), 70..90).unwrap();
        assert_eq!(past.rows(), 64..64);
        past.deposit(frame.iter().copied());
        assert!(past.to_rgb8().is_empty());
    }

    /// The energy summed over pixel rows `rows`, columns `cols`.
    fn sum(p: &Phosphor, rows: std::ops::Range<usize>, cols: std::ops::Range<usize>) -> f64 {
        rows.flat_map(|j| cols.clone().map(move |i| (j, i)))
            .map(|(j, i)| f64::from(p.energy()[j * p.width() + i]))
            .sum()
    }

    /// erf by its Maclaurin series (f64, converges for all x; accurate to
    /// ~1e-9 up to |x| = 4, where it is within 1.6e-8 of 1), and ±1 beyond.
    fn erf_ref(x: f64) -> f64 {
        if x.abs() > 4.0 {
            return x.signum();
        }
        let (mut term, mut total, mut n) = (x, x, 0.0);
        while term.abs() > 1e-17 {
            n += 1.0;
            term *= -x * x / n;
            total += term / (2.0 * n + 1.0);
        }
        total * 2.0 / std::f64::consts::PI.sqrt()
    }

    #[test]
    fn exp_and_erf_are_within_their_documented_errors() {
        let mut worst = 0.0f64;
        for i in 0..=200_000 {
            let x = -(i as f32) * 4e-4; // 0 down to -80
            let want = f64::from(x).exp();
            worst = worst.max((f64::from(exp_neg(x)) - want).abs() / want);
        }
        assert!(worst < 3e-7, "max relative exp error {worst:e}");
        assert_eq!(exp_neg(0.0), 1.0);
        assert!(exp_neg(-1000.0) > 0.0 && exp_neg(-1000.0) < 1e-34);
        assert_eq!(exp_neg(5.0), 1.0);

        let mut worst = 0.0f64;
        for i in -8000..=8000 {
            let x = i as f32 * 1e-3;
            worst = worst.max((f64::from(erf(x)) - erf_ref(f64::from(x))).abs());
        }
        assert!(worst < 5e-7, "max |erf error| {worst:e}");
        assert_eq!(erf(0.0), 0.0);
        assert_eq!(erf(100.0), 1.0);
        assert_eq!(erf(-100.0), -1.0);
        assert_eq!(erf(f32::INFINITY), 1.0);
        assert_eq!(erf(f32::NEG_INFINITY), -1.0);
    }

    #[test]
    fn energy_is_conserved() {
        // Spot well inside: 1 px on 64 px is 64 codes; keep 4σ = 3 px clear.
        let mut p = screen(small());
        let samples = [on(2048, 2048), on(2048, 2048), on(2048, 2048)];
        p.deposit(samples);
        assert!((p.total_energy() - 3.0).abs() < 0.01 * 3.0, "{}", p.total_energy());

        // Lines in every direction, far from the border, at several speeds.
        for (angle, step) in [
            (0.0f32, 16.0f32),
            (0.3, 16.0),
            (0.785, 40.0),
            (1.2, 5.0),
            (2.0, 100.0),
            (std::f32::consts::FRAC_PI_2, 64.0),
        ] {
            let mut p = screen(small());
            let (c, s) = (angle.cos(), angle.sin());
            let n = (1500.0 / step) as usize;
            let samples: Vec<_> = (0..=n)
                .map(|k| {
                    let t = k as f32 * step - 750.0;
                    on((2048.0 + t * c).round() as u16, (2048.0 + t * s).round() as u16)
                })
                .collect();
            p.deposit(samples.iter().copied());
            let expected = samples.len() as f64;
            let got = p.total_energy();
            assert!(
                (got - expected).abs() < 0.01 * expected,
                "angle {angle} step {step}: {got} vs {expected}"
            );
        }
    }

    #[test]
    fn energy_per_sample_scales_everything() {
        let mut a = screen(small());
        let mut b = screen(PhosphorConfig { energy_per_sample: 2.5, ..small() });
        let line = hline(2048, 1000, 3000, 50);
        a.deposit(line.iter().copied());
        b.deposit(line);
        assert!((b.total_energy() - 2.5 * a.total_energy()).abs() < 1e-3 * b.total_energy());
    }

    #[test]
    fn a_slow_line_is_brighter_than_a_fast_one() {
        // The same line, drawn in 64 and in 128 steps: twice the samples,
        // twice the energy per unit of length, everywhere along it.
        let mut fast = screen(small());
        let mut slow = screen(small());
        fast.deposit(hline(2048, 512, 3584, 64));
        slow.deposit(hline(2048, 512, 3584, 128));
        // The middle of the line: rows around y = 32, columns 16 to 48.
        let (f, s) = (sum(&fast, 28..36, 16..48), sum(&slow, 28..36, 16..48));
        assert!((s / f - 2.0).abs() < 0.02, "slow {s} fast {f}");
        // And the peak pixel on the line.
        let row = 31; // code 2048 is at y = 64 - 32.0078 = 31.99: rows 31 and 32 share it.
        let (pf, ps) = (fast.energy()[row * 64 + 32], slow.energy()[row * 64 + 32]);
        assert!((ps / pf - 2.0).abs() < 0.02, "slow {ps} fast {pf}");
        // A uniform line: along it (away from its ends) the energy is flat.
        let profile: Vec<f32> = (16..48).map(|i| slow.energy()[row * 64 + i]).collect();
        let (lo, hi) = profile.iter().fold((f32::MAX, 0.0f32), |(l, h), &v| (l.min(v), h.max(v)));
        assert!(hi / lo < 1.01, "{profile:?}");
    }

    #[test]
    fn blanked_moves_are_invisible_by_default_and_faint_if_asked() {
        let jump = [on(500, 500), off(3500, 3500), off(3500, 3500), off(500, 3500)];
        let mut p = screen(small());
        p.deposit(jump);
        // Only the first (lit) spot: one sample's energy.
        assert!((p.total_energy() - 1.0).abs() < 0.01);
        let mid = sum(&p, 20..44, 20..44);
        assert_eq!(mid, 0.0);

        let mut faint = screen(PhosphorConfig { show_blanked: 0.05, ..small() });
        faint.deposit(jump);
        // 1 lit spot + 3 blanked steps at 5%.
        assert!((faint.total_energy() - 1.15).abs() < 0.01, "{}", faint.total_energy());
        // The diagonal jump crosses the middle, faintly.
        let mid = sum(&faint, 28..36, 28..36);
        assert!(mid > 0.0 && mid < 0.05, "{mid}");
    }

    #[test]
    fn y_is_up() {
        let mut p = screen(small());
        p.deposit([on(0, MAX)]);
        let e = p.energy();
        let argmax = (0..e.len()).max_by(|&a, &b| e[a].total_cmp(&e[b])).unwrap();
        assert_eq!(argmax, 0, "the top-left pixel");
        // And code (0, 0) is bottom-left, (max, 0) bottom-right.
        for (s, want) in [(on(0, 0), 63 * 64), (on(MAX, 0), 63 * 64 + 63), (on(MAX, MAX), 63)] {
            p.clear();
            p.deposit([s]);
            let e = p.energy();
            let argmax = (0..e.len()).max_by(|&a, &b| e[a].total_cmp(&e[b])).unwrap();
            assert_eq!(argmax, want, "{s:?}");
        }
        // In the picture, too: the top-left pixel is green.
        p.clear();
        p.deposit([on(0, MAX); 5]);
        let rgb = p.to_rgb8();
        assert!(rgb[1] > 100 && rgb[1] >= rgb[0] && rgb[1] >= rgb[2], "{:?}", &rgb[..3]);
        let last = rgb.len() - 3;
        assert_eq!(&rgb[last..], &[0, 0, 0]);
    }

    #[test]
    fn persistence_decays() {
        let mut p = screen(PhosphorConfig { persistence: 0.25, ..small() });
        p.deposit(hline(2048, 1000, 3000, 20));
        let before = p.total_energy();
        let px = p.energy()[31 * 64 + 32];
        p.decay();
        assert!((p.total_energy() - 0.25 * before).abs() < 1e-6 * before);
        assert_eq!(p.energy()[31 * 64 + 32], px * 0.25);
        // Steady state of a refresh loop: frame / (1 - persistence).
        for _ in 0..40 {
            p.deposit(hline(2048, 1000, 3000, 20));
            p.decay();
        }
        let steady = p.total_energy() / 0.25;
        assert!((steady - before / 0.75).abs() < 1e-3 * before, "{steady} vs {}", before / 0.75);
        p.clear();
        assert_eq!(p.total_energy(), 0.0);
        assert_eq!(p.beam(), None);
    }

    #[test]
    fn dwell_makes_a_brighter_spot() {
        let mut once = screen(small());
        let mut dwell = screen(small());
        once.deposit([on(2048, 2048)]);
        dwell.deposit([on(2048, 2048); 5]);
        let centre = 31 * 64 + 32;
        let ratio = dwell.energy()[centre] / once.energy()[centre];
        assert!((ratio - 5.0).abs() < 1e-3, "{ratio}");
        // A dwell in chunks is the same as in one go.
        let mut chunks = screen(small());
        for _ in 0..5 {
            chunks.deposit([on(2048, 2048)]);
        }
        assert!((chunks.energy()[centre] - dwell.energy()[centre]).abs() < 1e-5);
        // A dwell at the end of a line: the end is brighter by exactly the
        // dwell's spot.
        let mut plain = screen(small());
        let mut dwelled = screen(small());
        plain.deposit(hline(2048, 1024, 3072, 32));
        let mut s = hline(2048, 1024, 3072, 32);
        s.extend([on(3072, 2048); 3]);
        dwelled.deposit(s);
        let end = 31 * 64 + 48;
        let (a, b) = (plain.energy()[end], dwelled.energy()[end]);
        assert!(b > 1.5 * a, "plain {a} dwelled {b}");
        assert!((b - a - 3.0 * once.energy()[end - 16]).abs() < 1e-4, "{a} {b}");
    }

    /// A frame streamed in chunks is the frame in one call: the same
    /// energy, the same spots and blanked jumps, and the same lines within
    /// rounding (a straight run, [`Stroke`], ends with each call, so a line
    /// is deposited in as many pieces as the chunks cut it into).
    #[test]
    fn streaming_in_chunks_equals_one_call() {
        let line: Vec<_> = (0..200u16)
            .map(|k| if k % 50 == 49 { off(k * 20, 4000 - k * 20) } else { on(k * 20, k * 15) })
            .chain([on(3000, 3000); 4])
            .collect();
        let mut one = screen(PhosphorConfig { show_blanked: 0.1, ..small() });
        one.deposit(line.iter().copied());
        let mut many = screen(PhosphorConfig { show_blanked: 0.1, ..small() });
        for chunk in line.chunks(7) {
            many.deposit(chunk.iter().copied());
        }
        // (A piece of line loses the spot's tail beyond WINDOW_SIGMAS at
        // either end, some 2e-4 of it: more pieces, a little less energy.)
        let peak = peak(one.energy());
        for (a, b) in one.energy().iter().zip(many.energy()) {
            assert!((a - b).abs() <= 5e-4 * peak, "{a} vs {b} (peak {peak})");
        }
        assert!((one.total_energy() - many.total_energy()).abs() < 1e-3 * one.total_energy());
        assert_eq!(many.beam(), line.last().copied());
    }

    /// The glow worked out on 2x2 blocks is the full-resolution blur within
    /// a few percent of its peak, and keeps its energy: radii from the
    /// coarse grid's smallest up, even and odd sizes.
    #[test]
    fn coarse_glow_is_the_blur() {
        let mut frame = hline(2048, 300, 3800, 40);
        frame.extend([on(1000, 1000); 30]);
        frame.extend((0..60).map(|k| on(3500 - k * 40, 600 + k * 55)));
        for (w, h) in [(96, 80), (97, 81), (200, 150)] {
            let mut p = screen(PhosphorConfig::with_size(w, h));
            p.deposit(frame.iter().copied());
            let (w, h) = (w as usize, h as usize);
            for radius in [COARSE_GLOW_RADIUS, 4.5, 6.25, 12.0] {
                let fine = blur(p.energy(), w, 0..h, 0..h, h, radius);
                let coarse = glow_of(p.energy(), w, 0..h, 0..h, h, radius);
                let (peak, worst) = (peak(&fine), worst(&fine, &coarse));
                assert!(worst <= 0.05 * peak, "{w}x{h}, radius {radius}: off by {worst} of a peak of {peak}");
                let sum = |v: &[f32]| v.iter().map(|&e| f64::from(e)).sum::<f64>();
                let (a, b) = (sum(&fine), sum(&coarse));
                assert!((a - b).abs() <= 0.02 * a, "{w}x{h}, radius {radius}: energy {b} vs {a}");
            }
        }
    }

    /// The largest value of `v` (0 for none).
    fn peak(v: &[f32]) -> f32 {
        v.iter().fold(0.0, |m, &e| m.max(e))
    }

    /// The largest difference between `a` and `b`, value by value.
    fn worst(a: &[f32], b: &[f32]) -> f32 {
        a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f32::max)
    }

    /// `samples` deposited one a call: every step a segment of its own (a
    /// call ends its stroke), the model without [`Stroke`]s.
    fn step_by_step(cfg: PhosphorConfig, samples: &[Sample]) -> Phosphor {
        let mut p = screen(cfg);
        for &s in samples {
            p.deposit([s]);
        }
        p
    }

    /// A line from `from` in `n` steps of `step` codes.
    fn line(from: (i32, i32), step: (i32, i32), n: i32) -> Vec<Sample> {
        (0..=n).map(|k| on((from.0 + k * step.0) as u16, (from.1 + k * step.1) as u16)).collect()
    }

    /// Paths drawn in strokes are the paths drawn step by step, within the
    /// stroke's tolerance: straight runs become one segment each (counted),
    /// and corners, changes of speed, blanked steps and dwells end a
    /// stroke (a stroke across a corner would be off by the whole line).
    #[test]
    fn strokes_draw_what_the_steps_draw() {
        let cfg = PhosphorConfig { show_blanked: 0.5, ..small() };
        // Rounded codes along lines at several angles: one stroke each
        // (up to STROKE_STEPS steps).
        let rounded = |angle: f32| -> Vec<Sample> {
            let (c, s) = (angle.cos(), angle.sin());
            (0..=24)
                .map(|k| {
                    let t = k as f32 * 61.0 - 732.0;
                    on((2048.0 + t * c).round() as u16, (2048.0 + t * s).round() as u16)
                })
                .collect()
        };
        let mut corner = line((300, 300), (64, 0), 20);
        corner.extend(line((1580, 300), (0, 64), 20).into_iter().skip(1));
        let mut faster = line((300, 300), (48, 48), 12);
        faster.extend(line((876, 876), (96, 96), 12).into_iter().skip(1));
        let mut blanked = line((300, 2000), (64, 0), 30);
        blanked[15].beam = Beam::Off;
        let mut dwell = line((300, 2000), (64, 0), 30);
        dwell.insert(15, dwell[15]);
        let zigzag: Vec<_> =
            (0..40).map(|k| on(200 + k * 90, if k % 2 == 0 { 1800 } else { 2300 })).collect();
        let cases: Vec<(&str, Vec<Sample>, usize)> = vec![
            ("rounded 0", rounded(0.0), 1),
            ("rounded 0.3", rounded(0.3), 1),
            ("rounded 0.785", rounded(0.785), 1),
            ("rounded 1.2", rounded(1.2), 1),
            ("rounded 2.5", rounded(2.5), 1),
            ("rounded 4.0", rounded(4.0), 1),
            ("corner", corner, 2),
            ("faster", faster, 2),
            ("blanked", blanked, 3),
            ("dwell", dwell, 2),
            ("zigzag", zigzag, 39),
            ("long", line((0, 0), (30, 30), 100), 100usize.div_ceil(STROKE_STEPS)),
        ];
        for (name, samples, strokes) in cases {
            let mut p = screen(cfg.clone());
            p.deposit(samples.iter().copied());
            assert_eq!(p.segments, strokes as u64, "{name}: strokes");
            let q = step_by_step(cfg.clone(), &samples);
            let (peak, worst) = (peak(q.energy()), worst(p.energy(), q.energy()));
            assert!(worst <= 0.15 * peak, "{name}: off by {worst} of a peak of {peak}");
            let (e, f) = (p.total_energy(), q.total_energy());
            // (Each segment loses its spot's tails beyond WINDOW_SIGMAS.)
            assert!((e - f).abs() <= 1e-3 * f, "{name}: energy {e} vs {f}");
        }
    }

    #[test]
    fn png_round_trips() {
        let mut p = screen(PhosphorConfig::with_size(48, 32));
        p.deposit(hline(1024, 0, MAX, 200));
        p.deposit([on(2048, 3000); 200]);
        let bytes = p.encode_png();
        let decoder = png::Decoder::new(std::io::Cursor::new(bytes));
        let mut reader = decoder.read_info().unwrap();
        let mut buf = vec![0; reader.output_buffer_size()];
        let info = reader.next_frame(&mut buf).unwrap();
        assert_eq!((info.width, info.height), (48, 32));
        assert_eq!((info.color_type, info.bit_depth), (png::ColorType::Rgb, png::BitDepth::Eight));
        let rgb = p.to_rgb8();
        assert_eq!(&buf[..info.buffer_size()], &rgb[..]);
        // A few pixels: black corner, green line, saturated spot.
        let px = |x: usize, y: usize| &buf[(y * 48 + x) * 3..(y * 48 + x) * 3 + 3];
        assert_eq!(px(0, 0), &[0, 0, 0]);
        let line = px(24, 24); // code 1024 of 4096 on 32 rows: y = 32 - 8.0 = 24.
        assert!(line[1] > 80 && line[1] > line[0] && line[1] > line[2], "{line:?}");
        let spot = px(24, 8); // code 3000: y = 32 - 23.4 = 8.6.
        assert!(spot.iter().all(|&c| c > 200), "{spot:?}");
        // And a file.
        let path = std::env::temp_dir().join(format!("isoscope-phosphor-{}.png", std::process::id()));
        p.write_png(&path).unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), p.encode_png());
        std::fs::remove_file(&path).unwrap();
        let err = p.write_png("/nonexistent-dir/x.png").unwrap_err();
        assert!(format!("{err:#}").starts_with("cannot create /nonexistent-dir/x.png"), "{err:#}");
    }

    #[test]
    fn bad_configs_are_refused() {
        use PhosphorError as E;
        let base = small();
        macro_rules! refused {
            ($($field:ident: $value:expr),+ => $want:pat) => {{
                let cfg = PhosphorConfig { $($field: $value,)+ ..base.clone() };
                let err = Phosphor::new(cfg).unwrap_err();
                assert!(matches!(err, $want), "{}: {err:?}", stringify!($($field = $value),+));
                assert!(!err.to_string().is_empty());
            }};
        }
        let glow = |strength, radius| Glow { strength, radius };
        let palette = |stops: &[(f32, [f32; 3])]| Palette { stops: stops.to_vec() };
        refused!(width: 0 => E::ZeroSize { width: 0, height: 64 });
        refused!(height: 0 => E::ZeroSize { width: 64, height: 0 });
        refused!(width: 8193 => E::TooLarge { width: 8193, .. });
        refused!(height: u32::MAX => E::TooLarge { .. });
        refused!(bits: 0 => E::BadBits(0));
        refused!(bits: 17 => E::BadBits(17));
        for sigma in [0.0, -1.0, f32::NAN, f32::INFINITY, MAX_SIGMA * 1.01] {
            refused!(spot_sigma: sigma => E::BadSigma(_));
        }
        for energy in [-1.0, f32::NAN, f32::INFINITY] {
            refused!(energy_per_sample: energy => E::BadEnergy(_));
        }
        for exposure in [0.0, -1.0, f32::NAN, f32::INFINITY] {
            refused!(exposure: exposure => E::BadExposure(_));
        }
        for gamma in [0.0, -2.2, f32::NAN, f32::INFINITY] {
            refused!(gamma: gamma => E::BadGamma(_));
        }
        for g in [
            glow(-0.1, 5.0),
            glow(0.1, 0.0),
            glow(0.1, -1.0),
            glow(0.1, 1e6),
            glow(f32::NAN, 1.0),
            glow(0.1, f32::NAN),
        ] {
            refused!(glow: g => E::BadGlow { .. });
        }
        for persistence in [-0.1, 1.5, f32::NAN] {
            refused!(persistence: persistence => E::BadPersistence(_));
        }
        for blanked in [-0.1, 1.5, f32::NAN] {
            refused!(show_blanked: blanked => E::BadShowBlanked(_));
        }
        refused!(palette: palette(&[]) => E::BadPalette(_));
        refused!(palette: palette(&[(0.5, [0.0; 3]), (0.2, [1.0; 3])]) => E::BadPalette(_));
        refused!(palette: palette(&[(0.0, [2.0; 3])]) => E::BadPalette(_));
        refused!(palette: palette(&[(f32::NAN, [0.0; 3])]) => E::BadPalette(_));
        refused!(palette: palette(&[(0.0, [f32::NAN; 3])]) => E::BadPalette(_));
        // Zero glow strength needs no radius; the edges of each range are fine.
        for ok in [
            PhosphorConfig { glow: glow(0.0, 0.0), ..base.clone() },
            PhosphorConfig { width: MAX_SIZE, height: 1, ..base.clone() },
            PhosphorConfig { bits: 1, persistence: 0.0, show_blanked: 1.0, ..base.clone() },
            PhosphorConfig { bits: 16, persistence: 1.0, energy_per_sample: 0.0, ..base.clone() },
        ] {
            Phosphor::new(ok).unwrap();
        }
        assert_eq!(
            PhosphorError::TooLarge { width: 9000, height: 1 }.to_string(),
            "image size 9000x1 is larger than 8192x8192"
        );
    }

    #[test]
    fn extreme_inputs_do_not_panic() {
        let mut p = screen(PhosphorConfig { show_blanked: 0.5, ..small() });
        // Corners and edges, lit and blanked, and codes beyond 12 bits.
        let extremes = [0, 1, MAX - 1, MAX, 4096, u16::MAX];
        for &x in &extremes {
            for &y in &extremes {
                p.deposit([on(x, y), off(y, x), on(u16::MAX - x, y)]);
            }
        }
        // A million samples at one point (one spot of that energy).
        p.deposit(std::iter::repeat_n(on(MAX, 0), 1_000_000));
        p.deposit(std::iter::repeat_n(off(0, 0), 1_000_000));
        assert!(p.energy().iter().all(|e| e.is_finite() && *e >= 0.0));
        let rgb = p.to_rgb8();
        assert_eq!(rgb.len(), 64 * 64 * 3);
        // The saturated corner is white-ish, not wrapped around.
        let corner = &rgb[(63 * 64 + 63) * 3..];
        assert!(corner.iter().all(|&c| c > 200), "{corner:?}");
        // Edge cases of the configuration: a 1x1 image, a huge spot, tiny
        // and huge exposure, 1-bit and 16-bit DACs.
        for cfg in [
            PhosphorConfig { width: 1, height: 1, ..small() },
            PhosphorConfig { spot_sigma: MAX_SIGMA, ..small() },
            PhosphorConfig { spot_sigma: 1e-6, ..small() },
            PhosphorConfig { exposure: 1e-30, gamma: 0.01, ..small() },
            PhosphorConfig { exposure: 1e30, gamma: 100.0, ..small() },
            PhosphorConfig { bits: 1, ..small() },
            PhosphorConfig { bits: 16, width: 3, height: 1000, ..small() },
            PhosphorConfig { glow: Glow { strength: 1.0, radius: MAX_SIGMA }, ..small() },
        ] {
            let mut p = screen(cfg);
            p.deposit([on(0, 0), on(MAX, MAX), on(0, MAX), on(u16::MAX, u16::MAX), on(0, 0), on(0, 0)]);
            assert!(p.energy().iter().all(|e| e.is_finite() && *e >= 0.0));
            assert_eq!(p.to_rgb8().len(), p.width() * p.height() * 3);
            p.encode_png();
        }
    }

    #[test]
    fn is_a_dac() {
        let mut p = screen(small());
        let mut reference = screen(small());
        let samples = hline(3000, 100, 4000, 30);
        fn play<D: Dac<Error = Infallible>>(mut dac: D, s: &[Sample]) {
            dac.write(s.iter().copied()).unwrap();
        }
        // Through the `&mut D` impl.
        play(&mut p, &samples);
        reference.deposit(samples.iter().copied());
        assert_eq!(p.energy(), reference.energy());
        // Straight from the beam scheduler.
        use isoscope_core::beam::{BeamConfig, Scheduler};
        use isoscope_core::command::Command;
        use isoscope_core::view::ScreenPoint;
        p.clear();
        let cmds = [
            Command::MoveTo(ScreenPoint::new(500.0, 500.0)),
            Command::LineTo(ScreenPoint::new(3500.0, 500.0)),
        ];
        let cfg = BeamConfig::default();
        let mut sched = Scheduler::new(cmds, &cfg);
        p.write(&mut sched).unwrap();
        let lit = sched.stats().lit_samples as f64;
        assert!((p.total_energy() - lit).abs() < 0.01 * lit, "{} vs {lit}", p.total_energy());
    }

    #[test]
    fn palette_interpolates() {
        let p = Palette::p31();
        assert_eq!(p.color(0.0), [0.0; 3]);
        assert_eq!(p.color(1.0), [0.9, 1.0, 0.9]);
        assert_eq!(p.color(0.5), [0.1, 0.6, 0.2]);
        let q = p.color(0.25);
        assert!((q[1] - 0.3).abs() < 1e-6);
        assert_eq!(p.color(f32::NAN), [0.0; 3]);
        assert_eq!(p.color(7.0), p.color(1.0));
        assert_eq!(Palette::gray().color(0.5), [0.5; 3]);
        // The default picture's colours are green everywhere below white.
        for i in 0..=100 {
            let c = p.color(i as f32 / 100.0);
            assert!(c[1] >= c[0] && c[1] >= c[2]);
        }
    }
}
