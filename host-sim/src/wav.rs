//! The DAC sample stream as a WAV file, so that a DC-coupled sound card can
//! drive a real oscilloscope in XY mode (the "oscilloscope music"
//! convention).
//!
//! # Channels
//!
//! - [`WavChannels::Stereo`]: left = X, right = Y. With no Z input the scope
//!   shows the blanked jumps as faint lines (the scheduler keeps them short).
//! - [`WavChannels::WithBeam`]: a third channel carries the beam, **off
//!   (blanked) = +1.0 (full scale), on = -1.0**: the largest swing, which a
//!   Z-input driver or a comparator can threshold at 0 V whatever the
//!   card's output level. Z high is blanked, as on the firmware's blank pin
//!   (PB0) and the MCP4922 driver's Z pin: most scopes blank on a
//!   *positive* Z voltage (most Tektronix models: +5 V blanks). Set
//!   [`WavConfig::blank_active_low`] for one that blanks on a negative
//!   voltage (off = -1.0, on = +1.0), as the firmware's feature
//!   `blank-active-low` does. Play three channels on an interface with
//!   three or more DC-coupled outputs (the file's channel mask says front
//!   left, front right, front centre).
//!
//! Stereo 16-bit files have the classic PCM header (format tag 1); float
//! and three-channel files are `WAVE_FORMAT_EXTENSIBLE` (tag `0xFFFE`, PCM
//! or IEEE-float sub-format), as the format's specification requires.
//!
//! # Values
//!
//! DAC codes `0 ..= 2^bits - 1` map linearly onto `-1.0 ..= +1.0`:
//! `v = 2 c / (2^bits - 1) - 1`, so code 0 is -1.0, the top code +1.0 and
//! mid-scale is 0 (within half an LSB: code 2048 of 12 bits is +0.00024).
//! [`WavFormat::Pcm16`] stores `round(v * 32767)`, symmetric in
//! `-32767 ..= 32767` (never -32768); [`WavFormat::Float32`] stores `v`.
//! Codes above the top code (a stream made for more bits) are clamped to
//! +1.0 and counted in [`WavStats::clipped`].
//!
//! # Sample rate, spacing and refresh rate
//!
//! Each DAC sample becomes one audio sample frame at
//! [`WavConfig::rate_hz`]. The scheduler's [default beam](BeamConfig::default)
//! is for a 1 MS/s DAC and a ~1 MHz scope: 17 LSB a sample, a run of
//! samples ending at every corner. A sound card at 48 kHz (passband ~20
//! kHz, its reconstruction filter rounding anything faster) cannot follow
//! that, and at 17 LSB a sample a frame would last 21 times longer than on
//! the scope's DAC (the hydrogen demo: 17,300 samples, 0.36 s a frame).
//! Schedule the frame with [`audio_beam`] instead: samples spaced evenly
//! along each polyline, corners or not ([`Spacing::Constant`]: the card
//! rounds corners anyway), at least as far apart as a beam drawing a
//! full-scale line in 1 ms (85 LSB at 48 kHz and 12 bits, 43 at 96 kHz,
//! 21 at 192 kHz); then [`audio_frame`] widens the spacing until the
//! frame plays [`AUDIO_FPS`] (25) times a second at the rate. A frame then
//! lasts about its length over the spacing: a higher rate gives finer
//! steps at the same refresh rate; a long picture at a low rate is drawn
//! with coarser steps rather than flickering.
//!
//! Measured frames of the hydrogen demo (level 0.1, default view;
//! `isoscope-sim wav --demo hydrogen:N --every E --audio-rate R`, with
//! `--lit-step` for the fixed speed, 2026-12-06; before the constant
//! spacing, runs at the fixed speed gave 13.1 fps at 48 kHz and 13.8 at
//! 192 kHz for `hydrogen:32`):
//!
//! | volume | fixed speed, 48 kHz | 96 kHz | 192 kHz | spaced for 25 fps (default) |
//! |---|---|---|---|---|
//! | `hydrogen:32` | 3,412 samples, 14.1 fps | 6,812, 14.1 fps | 13,611, 14.1 fps | 153 LSB apart at 48 kHz, 76 at 96, 38 at 192 |
//! | `hydrogen:32`, every 2nd slice | 1,720, 27.9 fps | | 6,839, 28.1 fps | (fast enough at the fixed speed) |
//! | `hydrogen:32`, every 3rd slice | 1,128, 42.6 fps | | 4,470, 43.0 fps | (fast enough) |
//! | `hydrogen:16` | 1,600, 30.0 fps | | | (fast enough) |
//!
//! A P31 screen in a dim room shows a readable, flickering picture from
//! about 15 frames a second and a steady one from about 40. At 48 kHz
//! `hydrogen:32` at 25 fps has its samples 3.7% of the screen apart (the
//! command says so, as a note above 1/32 of the screen): its contours
//! are visibly polygonal; contour fewer slices (`every`), use a higher
//! rate or ask for fewer frames a second for a finer picture.

//! # Looping
//!
//! [`write_wav`] takes one frame of samples and repeats it until
//! [`WavConfig::seconds`] are written, each repeat starting where the last
//! ended: give it a frame made for a refresh loop
//! ([`crate::scene::refresh_samples`]: no return to the park position, so
//! the loop's only jump is the frame's own first one). The length is
//! `round(seconds * rate_hz)` sample frames exactly, so the last repeat may
//! be cut short; [`WavConfig::whole_loops`] rounds up to whole frames so
//! that a player looping the file loops the picture seamlessly.
//!
//! Sound cards are usually AC-coupled (a high-pass near 10 Hz): a still
//! picture then drifts towards the centre and its slow parts distort. Use
//! a DC-coupled interface (or one modified to be).
//!
//! ```
//! use isoscope_core::output::{Beam, Sample};
//! use isoscope_sim::wav::{WavChannels, WavConfig, write_wav};
//!
//! let frame = [Sample::new(0, 0, Beam::On), Sample::new(4095, 4095, Beam::Off)];
//! let cfg = WavConfig { channels: WavChannels::WithBeam, seconds: 0.01, ..WavConfig::default() };
//! let mut file = std::io::Cursor::new(Vec::new());
//! let stats = write_wav(&mut file, &frame, &cfg).unwrap();
//! assert_eq!(stats.sample_frames, 480); // 10 ms at 48 kHz
//! ```

use isoscope_core::beam::{BeamConfig, FrameStats, MIN_LIT_STEP, Scheduler, Spacing, fit_spacing};
use isoscope_core::command::Command;
use isoscope_core::output::{Beam, Sample};
use isoscope_core::view::ScreenPoint;
use std::fmt;
use std::io::{BufWriter, Seek, Write};
use std::path::Path;

/// Which channels the file has.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum WavChannels {
    /// Left = X, right = Y (the default: every sound card has two outputs).
    #[default]
    Stereo,
    /// X, Y, and the beam (blanked = +1.0, lit = -1.0; see
    /// [`WavConfig::blank_active_low`]).
    WithBeam,
}

impl WavChannels {
    /// Number of channels: 2 or 3.
    pub fn count(self) -> u16 {
        match self {
            WavChannels::Stereo => 2,
            WavChannels::WithBeam => 3,
        }
    }
}

/// How each value is stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum WavFormat {
    /// 16-bit signed integer PCM, `round(v * 32767)` (the default: every
    /// player and card takes it, and 16 bits hold a 12-bit DAC's codes).
    #[default]
    Pcm16,
    /// 32-bit IEEE float, `v` itself (exact for any DAC resolution).
    Float32,
}

/// The WAV file's shape and length. See the [module docs](self).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WavConfig {
    /// Sample frames per second, at least 1 (48,000, 96,000 and 192,000 are
    /// the sound-card rates; any is written).
    pub rate_hz: u32,
    /// Stereo, or with the beam.
    pub channels: WavChannels,
    /// 16-bit PCM or 32-bit float.
    pub format: WavFormat,
    /// Length in seconds (finite, positive; at least one sample frame).
    pub seconds: f64,
    /// DAC resolution the samples' codes are in, `1 ..= 16` (the beam's
    /// [`BeamConfig::bits`]).
    pub bits: u8,
    /// Beam channel blanked = -1.0, lit = +1.0 (for a Z input that blanks
    /// on a negative voltage; the default blanks on a positive one).
    pub blank_active_low: bool,
    /// Round the length up to a whole number of frames.
    pub whole_loops: bool,
}

impl Default for WavConfig {
    /// 48 kHz (every sound card has it), stereo, 16-bit PCM, 5 seconds (long
    /// enough to set up a scope while a player loops the file), 12 bits (the
    /// scheduler's default DAC), beam channel blanked high, exact length.
    fn default() -> Self {
        Self {
            rate_hz: 48_000,
            channels: WavChannels::Stereo,
            format: WavFormat::Pcm16,
            seconds: 5.0,
            bits: 12,
            blank_active_low: false,
            whole_loops: false,
        }
    }
}

/// What [`write_wav`] wrote.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WavStats {
    /// Sample frames written (samples per channel).
    pub sample_frames: u64,
    /// Samples in one display frame (the loop).
    pub frame_samples: usize,
    /// Display frames written, the last one possibly in part.
    pub loops: f64,
    /// Display frames per second at this rate: `rate_hz / frame_samples`.
    pub refresh_hz: f64,
    /// Length of the file's audio, in seconds.
    pub seconds: f64,
    /// Samples of the frame with a code above `2^bits - 1` (clamped).
    pub clipped: usize,
}

/// Why a WAV file could not be written.
#[derive(Debug)]
pub enum WavError {
    /// The sample rate is 0.
    ZeroRate,
    /// The frame has no samples.
    NoSamples,
    /// The duration is not finite and positive, or is under one sample.
    BadDuration(f64),
    /// The DAC resolution is not in `1 ..= 16` bits.
    BadBits(u8),
    /// The data would not fit in a WAV file (4 GiB).
    TooLong {
        /// Bytes of sample data asked for.
        bytes: u64,
    },
    /// Writing failed.
    Io(std::io::Error),
    /// The WAV encoder failed.
    Wav(hound::Error),
}

impl fmt::Display for WavError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            WavError::ZeroRate => write!(f, "the sample rate must be at least 1 Hz"),
            WavError::NoSamples => write!(f, "the frame has no samples to play"),
            WavError::BadDuration(s) => {
                write!(f, "the duration {s} s is not a positive number of seconds of at least one sample")
            }
            WavError::BadBits(b) => write!(f, "DAC resolution of {b} bits is not within 1..=16"),
            WavError::TooLong { bytes } => {
                write!(f, "{bytes} bytes of audio do not fit in a WAV file (4 GiB at most); shorten it")
            }
            WavError::Io(e) => write!(f, "{e}"),
            WavError::Wav(e) => write!(f, "WAV encoding: {e}"),
        }
    }
}

impl std::error::Error for WavError {
    /// The cause's own cause: its message is in this one's already (an
    /// error chain printed whole would say it twice).
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            WavError::Io(e) => e.source(),
            WavError::Wav(e) => e.source(),
            _ => None,
        }
    }
}

impl From<hound::Error> for WavError {
    fn from(e: hound::Error) -> Self {
        match e {
            hound::Error::IoError(e) => WavError::Io(e),
            e => WavError::Wav(e),
        }
    }
}

/// Largest sample data a WAV file holds: its RIFF size field is 32 bits,
/// and the headers (at most 68 bytes here) count in it.
const MAX_DATA_BYTES: u64 = u32::MAX as u64 - 128;

/// Beam speed of [`audio_beam`] in full scales per second: a full-scale
/// line in 1 ms.
pub const AUDIO_FULL_SCALES_PER_SECOND: f64 = 1000.0;

/// A beam configuration for a sound card at `rate_hz` and a `bits` DAC
/// (see the [module docs](self)): the beam moves at
/// [`AUDIO_FULL_SCALES_PER_SECOND`] (4.1 million LSB/s at 12 bits), so
/// `lit_step = 2^bits * 1000 / rate_hz` LSB (85 at 48 kHz and 12 bits, at
/// least [`MIN_LIT_STEP`]); time-based waits are converted to samples at
/// this rate:
///
/// - a blanked jump settles 40 µs plus 40 µs per full scale (at least one
///   sample; 2 + 2 at 48 kHz): the card's reconstruction filter rings for
///   a few samples after a step, longer the larger it is;
/// - [`Spacing::Constant`]: samples evenly along each polyline, corners
///   or not (the card's low-pass rounds a corner over a sample or two
///   anyway), none at a corner of its own;
/// - one sample of dwell at polyline ends (at 48 kHz a sample lasts
///   21 µs, as long as 20 samples of the scope's DAC), none at a
///   polyline's start beyond the required one;
/// - a dot dwells 80 µs (4 samples at 48 kHz).
///
/// Everything else (corner angle, park position) is
/// [`BeamConfig::default`]'s. A `bits` outside `1 ..= 16` is clamped; a
/// `rate_hz` of 0 is taken as 1.
pub fn audio_beam(rate_hz: u32, bits: u8) -> BeamConfig {
    let bits = bits.clamp(1, 16);
    let rate = f64::from(rate_hz.max(1));
    let full = f64::from(1u32 << bits);
    let samples = |seconds: f64| (seconds * rate).ceil().clamp(1.0, f64::from(u16::MAX));
    let settle = samples(40e-6);
    BeamConfig {
        bits,
        lit_step: ((full * AUDIO_FULL_SCALES_PER_SECOND / rate) as f32).max(MIN_LIT_STEP),
        settle_base: settle as f32,
        settle_per_lsb: (settle / full) as f32,
        settle_max: (2.0 * settle) as u16,
        dwell_start: 1,
        dwell_end: 1,
        corner_dwell: 0,
        point_dwell: samples(80e-6) as u16,
        spacing: Spacing::Constant,
        ..BeamConfig::default()
    }
}

/// Refreshes a second that `wav` and the web page's audio space a frame's
/// samples for by default ([`audio_frame`]): [`FLICKER_HZ`](crate::scene::FLICKER_HZ),
/// below which a scope's picture flickers.
pub const AUDIO_FPS: f32 = crate::scene::FLICKER_HZ;

/// A frame scheduled for a sound card: [`audio_frame`]'s answer.
#[derive(Debug, Clone, PartialEq)]
pub struct AudioFrame {
    /// The beam it was scheduled with (its `lit_step` the spacing chosen).
    pub beam: BeamConfig,
    /// The frame's samples, from the park position back to it.
    pub samples: Vec<Sample>,
    /// Its statistics.
    pub stats: FrameStats,
}

/// `commands` (a scene's, [`crate::scene::Scene::commands`]) scheduled
/// with `beam`; with `fps`, at the smallest spacing of at least
/// `beam.lit_step` at which the frame plays `fps` times a second or more
/// at `rate_hz` ([`fit_spacing`]: at most `floor(rate_hz / fps)`
/// samples), or as fast as its jumps and dwells let it. With
/// [`audio_beam`] the samples are spaced evenly along the path
/// ([`Spacing::Constant`]) and a picture too long for the rate is drawn
/// with fewer, farther samples rather than refreshed too slowly. An `fps`
/// that is not positive and finite is none.
///
/// The same samples as the board's scheduler would make with the beam
/// returned (the engine schedules its commands with [`Scheduler::new`]).
pub fn audio_frame(
    commands: &[Command<ScreenPoint>],
    beam: &BeamConfig,
    rate_hz: u32,
    fps: Option<f32>,
) -> AudioFrame {
    let mut beam = beam.sanitized();
    if let Some(fps) = fps.filter(|f| f.is_finite() && *f > 0.0) {
        let max = (f64::from(rate_hz) / f64::from(fps)).floor().max(1.0) as u64;
        beam = fit_spacing(commands.iter().copied(), &beam, max);
    }
    let mut sch = Scheduler::new(commands.iter().copied(), &beam);
    let samples: Vec<Sample> = sch.by_ref().collect();
    AudioFrame { beam, samples, stats: sch.stats() }
}

/// A frame's samples as an audio buffer's channels at full scale, one
/// after the other: X, then Y, then the beam (blanked +1.0, lit -1.0;
/// inverted with `blank_active_low`), `frame.len()` values each: the
/// values [`write_wav`] writes (its 16-bit PCM is `round(v * 32767)` of
/// these), for a player that takes floats (the web page's WebAudio).
pub fn audio_channels(frame: &[Sample], bits: u8, blank_active_low: bool) -> Vec<f32> {
    let x = frame.iter().map(|s| code_to_unit(s.x, bits) as f32);
    let y = frame.iter().map(|s| code_to_unit(s.y, bits) as f32);
    let beam = frame.iter().map(|s| beam_to_unit(s.beam, blank_active_low) as f32);
    x.chain(y).chain(beam).collect()
}

/// The beam channel's value: blanked +1.0 and lit -1.0 (Z high blanks),
/// the other way round with `blank_active_low`.
pub fn beam_to_unit(beam: Beam, blank_active_low: bool) -> f64 {
    if (beam == Beam::Off) != blank_active_low { 1.0 } else { -1.0 }
}

/// DAC code `code` of a `bits` DAC as a value in `-1.0 ..= 1.0`:
/// `2 code / (2^bits - 1) - 1`, codes above the top clamped to 1.0. `bits`
/// is clamped into `1 ..= 16`.
pub fn code_to_unit(code: u16, bits: u8) -> f64 {
    let max = f64::from(u16::MAX >> (16 - bits.clamp(1, 16)));
    (2.0 * f64::from(code).min(max) / max - 1.0).clamp(-1.0, 1.0)
}

/// A value in `-1.0 ..= 1.0` as 16-bit PCM: `round(v * 32767)`.
pub fn unit_to_pcm16(v: f64) -> i16 {
    (v.clamp(-1.0, 1.0) * 32767.0).round() as i16
}

/// Check `cfg` and work out the length in sample frames for a frame of
/// `frame_samples` samples: what [`write_wav`] writes.
///
/// # Errors
/// As [`write_wav`], for the configuration.
pub fn sample_frames(cfg: &WavConfig, frame_samples: usize) -> Result<u64, WavError> {
    if cfg.rate_hz == 0 {
        return Err(WavError::ZeroRate);
    }
    if !(1..=16).contains(&cfg.bits) {
        return Err(WavError::BadBits(cfg.bits));
    }
    if frame_samples == 0 {
        return Err(WavError::NoSamples);
    }
    let exact = cfg.seconds * f64::from(cfg.rate_hz);
    if !(cfg.seconds.is_finite() && exact.round() >= 1.0) {
        return Err(WavError::BadDuration(cfg.seconds));
    }
    let bytes_per_frame = u64::from(cfg.channels.count())
        * match cfg.format {
            WavFormat::Pcm16 => 2,
            WavFormat::Float32 => 4,
        };
    let max_frames = MAX_DATA_BYTES / bytes_per_frame;
    // Compared in f64 first: `as u64` would saturate an absurd duration.
    if exact.round() > max_frames as f64 {
        return Err(WavError::TooLong { bytes: (exact.round() * bytes_per_frame as f64) as u64 });
    }
    let mut n = exact.round() as u64;
    if cfg.whole_loops {
        n = n.div_ceil(frame_samples as u64) * frame_samples as u64;
        if n > max_frames {
            return Err(WavError::TooLong { bytes: n * bytes_per_frame });
        }
    }
    Ok(n)
}

/// Write `frame` (one display frame of DAC samples) as a WAV file to `out`,
/// repeated until [`WavConfig::seconds`] of audio are written (see the
/// [module docs](self)).
///
/// # Errors
/// A sample rate of 0, no samples, a duration that is not positive and
/// finite or under one sample frame, `bits` not in `1 ..= 16`, a file over
/// 4 GiB, or the writer's error.
pub fn write_wav<W: Write + Seek>(out: W, frame: &[Sample], cfg: &WavConfig) -> Result<WavStats, WavError> {
    write_wav_counted(out, frame, cfg, None)
}

/// [`write_wav`], counting the sample frames written in `progress` (its
/// total [`WavStats::sample_frames`]).
///
/// # Errors
/// As [`write_wav`].
pub fn write_wav_counted<W: Write + Seek>(
    out: W,
    frame: &[Sample],
    cfg: &WavConfig,
    progress: Option<&crate::progress::Progress>,
) -> Result<WavStats, WavError> {
    let total = sample_frames(cfg, frame.len())?;
    let max = u16::MAX >> (16 - cfg.bits);
    let clipped = frame.iter().filter(|s| s.x > max || s.y > max).count();
    let beam = |b: Beam| beam_to_unit(b, cfg.blank_active_low);
    // The frame's values, once: then the loop only copies.
    let with_beam = cfg.channels == WavChannels::WithBeam;
    let values: Vec<f64> = frame
        .iter()
        .flat_map(|s| {
            let v = [code_to_unit(s.x, cfg.bits), code_to_unit(s.y, cfg.bits), beam(s.beam)];
            v.into_iter().take(if with_beam { 3 } else { 2 })
        })
        .collect();
    let spec = hound::WavSpec {
        channels: cfg.channels.count(),
        sample_rate: cfg.rate_hz,
        bits_per_sample: match cfg.format {
            WavFormat::Pcm16 => 16,
            WavFormat::Float32 => 32,
        },
        sample_format: match cfg.format {
            WavFormat::Pcm16 => hound::SampleFormat::Int,
            WavFormat::Float32 => hound::SampleFormat::Float,
        },
    };
    let mut writer = hound::WavWriter::new(BufWriter::with_capacity(1 << 16, out), spec)?;
    // Whole repeats of the frame, then the part of one that is left.
    let channels = usize::from(cfg.channels.count());
    let repeats = total / frame.len() as u64;
    let rest = (total % frame.len() as u64) as usize * channels;
    let pieces = |all: usize| (0..repeats).map(move |_| all).chain([rest]);
    let written = |len: usize| {
        if let Some(p) = progress {
            p.add(len / channels);
        }
    };
    match cfg.format {
        WavFormat::Pcm16 => {
            let pcm: Vec<i16> = values.iter().map(|&v| unit_to_pcm16(v)).collect();
            for len in pieces(pcm.len()) {
                for chunk in pcm[..len].chunks(1 << 16) {
                    // `chunks` keeps the length within u32.
                    let mut w = writer.get_i16_writer(chunk.len() as u32);
                    for &v in chunk {
                        w.write_sample(v);
                    }
                    w.flush()?;
                }
                written(len);
            }
        }
        WavFormat::Float32 => {
            let float: Vec<f32> = values.iter().map(|&v| v as f32).collect();
            for len in pieces(float.len()) {
                for &v in &float[..len] {
                    writer.write_sample(v)?;
                }
                written(len);
            }
        }
    }
    writer.finalize()?;
    let rate = f64::from(cfg.rate_hz);
    Ok(WavStats {
        sample_frames: total,
        frame_samples: frame.len(),
        loops: total as f64 / frame.len() as f64,
        refresh_hz: rate / frame.len() as f64,
        seconds: total as f64 / rate,
        clipped,
    })
}

/// [`write_wav`] to a file at `path`, whole or not at all
/// ([`crate::outfile`]).
///
/// # Errors
/// As [`write_wav`] (the configuration is checked before the file is
/// created), or the file cannot be created or written; the path named.
pub fn write_wav_file(path: impl AsRef<Path>, frame: &[Sample], cfg: &WavConfig) -> anyhow::Result<WavStats> {
    write_wav_file_counted(path, frame, cfg, None)
}

/// [`write_wav_file`], with progress as [`write_wav_counted`] counts it.
///
/// # Errors
/// As [`write_wav_file`].
pub fn write_wav_file_counted(
    path: impl AsRef<Path>,
    frame: &[Sample],
    cfg: &WavConfig,
    progress: Option<&crate::progress::Progress>,
) -> anyhow::Result<WavStats> {
    use anyhow::Context as _;
    let path = path.as_ref();
    sample_frames(cfg, frame.len())?;
    crate::outfile::write_whole(path, |w| {
        write_wav_counted(w, frame, cfg, progress).with_context(|| format!("cannot write {}", path.display()))
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Cursor;

    const ON: Beam = Beam::On;
    const OFF: Beam = Beam::Off;

    fn s(x: u16, y: u16, beam: Beam) -> Sample {
        Sample::new(x, y, beam)
    }

    fn wav(frame: &[Sample], cfg: &WavConfig) -> (Vec<u8>, WavStats) {
        let mut out = Cursor::new(Vec::new());
        let stats = write_wav(&mut out, frame, cfg).unwrap();
        (out.into_inner(), stats)
    }

    fn read_i16(bytes: &[u8]) -> (hound::WavSpec, Vec<i16>) {
        let mut r = hound::WavReader::new(Cursor::new(bytes)).unwrap();
        let v = r.samples::<i16>().map(Result::unwrap).collect();
        (r.spec(), v)
    }

    fn read_f32(bytes: &[u8]) -> (hound::WavSpec, Vec<f32>) {
        let mut r = hound::WavReader::new(Cursor::new(bytes)).unwrap();
        let v = r.samples::<f32>().map(Result::unwrap).collect();
        (r.spec(), v)
    }

    fn u16_at(b: &[u8], i: usize) -> u16 {
        u16::from_le_bytes([b[i], b[i + 1]])
    }

    fn u32_at(b: &[u8], i: usize) -> u32 {
        u32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]])
    }

    /// The `fmt ` chunk's fields and the data chunk's size, by hand.
    fn header(b: &[u8]) -> (u16, u16, u32, u32, u16, u16, u32) {
        assert_eq!(&b[0..4], b"RIFF");
        assert_eq!(u32_at(b, 4) as usize, b.len() - 8, "RIFF size");
        assert_eq!(&b[8..12], b"WAVE");
        let (mut i, mut fmt, mut data) = (12, None, None);
        while i + 8 <= b.len() {
            let (id, len) = (&b[i..i + 4], u32_at(b, i + 4) as usize);
            match id {
                b"fmt " => fmt = Some(i + 8),
                b"data" => data = Some(len as u32),
                _ => {}
            }
            i += 8 + len + (len & 1);
        }
        let f = fmt.expect("a fmt chunk");
        let (tag, channels, rate, byte_rate, align, bits) = (
            u16_at(b, f),
            u16_at(b, f + 2),
            u32_at(b, f + 4),
            u32_at(b, f + 8),
            u16_at(b, f + 12),
            u16_at(b, f + 14),
        );
        (tag, channels, rate, byte_rate, align, bits, data.expect("a data chunk"))
    }

    #[test]
    fn headers_say_what_was_asked() {
        let frame = [s(0, 0, ON), s(100, 200, OFF)];
        for (channels, format, rate) in [
            (WavChannels::Stereo, WavFormat::Pcm16, 48_000),
            (WavChannels::Stereo, WavFormat::Float32, 96_000),
            (WavChannels::WithBeam, WavFormat::Pcm16, 192_000),
            (WavChannels::WithBeam, WavFormat::Float32, 44_100),
            (WavChannels::Stereo, WavFormat::Pcm16, 1),
        ] {
            let cfg = WavConfig { rate_hz: rate, channels, format, seconds: 3.0, ..WavConfig::default() };
            let (bytes, stats) = wav(&frame, &cfg);
            let n = 3 * u64::from(rate);
            assert_eq!(stats.sample_frames, n);
            let (tag, ch, r, byte_rate, align, bits, data) = header(&bytes);
            let width = if format == WavFormat::Pcm16 { 2 } else { 4 };
            assert_eq!(ch, channels.count());
            assert_eq!(r, rate);
            assert_eq!(bits, 8 * width);
            assert_eq!(align, ch * width);
            assert_eq!(byte_rate, rate * u32::from(align));
            assert_eq!(u64::from(data), n * u64::from(align));
            // Stereo PCM16: the classic header. Otherwise WAVE_FORMAT_EXTENSIBLE,
            // whose sub-format GUID starts with the classic tag (1 PCM, 3 float)
            // and whose channel mask is FL FR (FC).
            let sub = if format == WavFormat::Pcm16 { 1 } else { 3 };
            if ch == 2 && format == WavFormat::Pcm16 {
                assert_eq!((tag, bytes.len()), (1, 44 + data as usize));
            } else {
                assert_eq!((tag, bytes.len()), (0xFFFE, 68 + data as usize), "{channels:?} {format:?}");
                let ext = 20;
                assert_eq!(u16_at(&bytes, ext + 16), 22, "cbSize");
                assert_eq!(u16_at(&bytes, ext + 18), bits, "valid bits");
                assert_eq!(u32_at(&bytes, ext + 20), if ch == 3 { 7 } else { 3 }, "channel mask");
                assert_eq!(u16_at(&bytes, ext + 24), sub, "sub-format");
            }
            // And hound reads the same.
            let spec = hound::WavReader::new(Cursor::new(&bytes)).unwrap().spec();
            assert_eq!((spec.channels, spec.sample_rate, spec.bits_per_sample), (ch, rate, bits));
            let fmt = if format == WavFormat::Pcm16 {
                hound::SampleFormat::Int
            } else {
                hound::SampleFormat::Float
            };
            assert_eq!(spec.sample_format, fmt);
        }
    }

    #[test]
    fn codes_map_linearly_onto_full_scale() {
        assert_eq!(code_to_unit(0, 12), -1.0);
        assert_eq!(code_to_unit(4095, 12), 1.0);
        assert!(code_to_unit(2048, 12).abs() < 0.5 / 4095.0 * 2.0);
        assert_eq!(code_to_unit(u16::MAX, 16), 1.0);
        assert_eq!(code_to_unit(0, 1), -1.0);
        assert_eq!(code_to_unit(1, 1), 1.0);
        assert_eq!(code_to_unit(9999, 12), 1.0, "clamped");
        assert_eq!((unit_to_pcm16(-1.0), unit_to_pcm16(1.0), unit_to_pcm16(0.0)), (-32767, 32767, 0));
        // Linear: equal code steps are equal value steps.
        let d: Vec<f64> = (0..4095).map(|c| code_to_unit(c + 1, 12) - code_to_unit(c, 12)).collect();
        assert!(d.iter().all(|&x| (x - 2.0 / 4095.0).abs() < 1e-12));

        let frame = [s(0, 4095, ON), s(4095, 0, ON), s(2048, 2047, ON), s(1024, 3072, OFF)];
        let cfg = WavConfig { seconds: 4.0, rate_hz: 1, ..WavConfig::default() };
        let (_, v) = read_i16(&wav(&frame, &cfg).0);
        assert_eq!(&v[..4], &[-32767, 32767, 32767, -32767]);
        assert!(v[4].abs() <= 8 && v[5].abs() <= 8, "mid-scale {:?}", &v[4..6]);
        assert_eq!(v[4], -v[5], "symmetric about mid-scale");
        // 1024 of 4095: 2 * 1024 / 4095 - 1 = -0.49988.
        assert_eq!(v[6], (-0.499_877_899_877_899_9f64 * 32767.0).round() as i16);

        let cfg = WavConfig { format: WavFormat::Float32, ..cfg };
        let (_, v) = read_f32(&wav(&frame, &cfg).0);
        assert_eq!(&v[..4], &[-1.0, 1.0, 1.0, -1.0]);
        assert!(v[4].abs() < 2.5e-4 && v[5].abs() < 2.5e-4);
        assert_eq!(v[4], -v[5]);
    }

    #[test]
    fn the_third_channel_is_the_beam() {
        let frame = [s(10, 20, ON), s(30, 40, OFF), s(50, 60, ON)];
        let cfg =
            WavConfig { channels: WavChannels::WithBeam, rate_hz: 3, seconds: 1.0, ..WavConfig::default() };
        let (_, v) = read_i16(&wav(&frame, &cfg).0);
        assert_eq!(v.len(), 9);
        // Blanked high: on, off, on is low, high, low.
        let beam: Vec<i16> = v.chunks(3).map(|c| c[2]).collect();
        assert_eq!(beam, [-32767, 32767, -32767]);
        let xs: Vec<i16> = v.chunks(3).map(|c| c[0]).collect();
        assert_eq!(xs, [10, 30, 50].map(|c| unit_to_pcm16(code_to_unit(c, 12))));
        let low = WavConfig { blank_active_low: true, ..cfg };
        let (_, v) = read_i16(&wav(&frame, &low).0);
        assert_eq!(v.chunks(3).map(|c| c[2]).collect::<Vec<_>>(), [32767, -32767, 32767]);
        let float = WavConfig { format: WavFormat::Float32, ..cfg };
        let (spec, v) = read_f32(&wav(&frame, &float).0);
        assert_eq!(spec.channels, 3);
        assert_eq!(v.chunks(3).map(|c| c[2]).collect::<Vec<_>>(), [-1.0, 1.0, -1.0]);
    }

    #[test]
    fn the_frame_loops_for_exactly_the_duration() {
        let frame: Vec<Sample> =
            (0..7).map(|k| s(k * 500, 4095 - k * 500, if k == 6 { OFF } else { ON })).collect();
        let cfg = WavConfig { rate_hz: 1000, seconds: 0.5, ..WavConfig::default() };
        let (bytes, stats) = wav(&frame, &cfg);
        assert_eq!(stats.sample_frames, 500);
        assert_eq!(stats.frame_samples, 7);
        assert!((stats.loops - 500.0 / 7.0).abs() < 1e-12);
        assert!((stats.refresh_hz - 1000.0 / 7.0).abs() < 1e-9);
        assert_eq!(stats.seconds, 0.5);
        let (_, v) = read_i16(&bytes);
        assert_eq!(v.len(), 1000);
        for (i, xy) in v.chunks(2).enumerate() {
            let want = frame[i % 7];
            let code = |c| unit_to_pcm16(code_to_unit(c, 12));
            assert_eq!(xy, [code(want.x), code(want.y)], "sample frame {i}");
        }
        // Rounding to the nearest sample frame: 1/3 s at 1 kHz is 333.
        let (_, stats) = wav(&frame, &WavConfig { seconds: 1.0 / 3.0, ..cfg });
        assert_eq!(stats.sample_frames, 333);
        // Whole loops: 500 rounds up to 72 frames of 7.
        let (bytes, stats) = wav(&frame, &WavConfig { whole_loops: true, ..cfg });
        assert_eq!(stats.sample_frames, 504);
        assert_eq!(stats.loops, 72.0);
        assert_eq!(read_i16(&bytes).1.len(), 1008);
        // A frame longer than the file: cut short.
        let (_, stats) = wav(&frame, &WavConfig { rate_hz: 4, seconds: 1.0, ..cfg });
        assert_eq!(stats.sample_frames, 4);
        // The default: 5 s at 48 kHz.
        let (bytes, stats) = wav(&frame, &WavConfig::default());
        assert_eq!(stats.sample_frames, 240_000);
        assert_eq!(bytes.len(), 44 + 240_000 * 4);
    }

    #[test]
    fn bad_configs_are_refused() {
        let frame = [s(1, 2, ON)];
        let base = WavConfig::default();
        let err = |frame: &[Sample], cfg: WavConfig| {
            let e = write_wav(Cursor::new(Vec::new()), frame, &cfg).unwrap_err();
            assert!(!e.to_string().is_empty());
            e
        };
        assert!(matches!(err(&frame, WavConfig { rate_hz: 0, ..base }), WavError::ZeroRate));
        assert!(matches!(err(&[], base), WavError::NoSamples));
        for seconds in [0.0, -1.0, f64::NAN, f64::INFINITY, 1e-6] {
            assert!(
                matches!(err(&frame, WavConfig { seconds, ..base }), WavError::BadDuration(_)),
                "{seconds}"
            );
        }
        for bits in [0, 17] {
            assert!(matches!(err(&frame, WavConfig { bits, ..base }), WavError::BadBits(b) if b == bits));
        }
        let long = WavConfig {
            rate_hz: 192_000,
            channels: WavChannels::WithBeam,
            format: WavFormat::Float32,
            ..base
        };
        assert!(matches!(err(&frame, WavConfig { seconds: 2000.0, ..long }), WavError::TooLong { .. }));
        assert!(matches!(err(&frame, WavConfig { seconds: 1e300, ..long }), WavError::TooLong { .. }));
        // A file: the configuration is checked before it is created.
        let path = std::env::temp_dir().join(format!("isoscope-wav-bad-{}.wav", std::process::id()));
        assert!(write_wav_file(&path, &frame, &WavConfig { rate_hz: 0, ..base }).is_err());
        assert!(!path.exists());
        let e = write_wav_file("/nonexistent-dir/x.wav", &frame, &base).unwrap_err();
        assert!(format!("{e:#}").starts_with("cannot create /nonexistent-dir/x.wav"), "{e:#}");
    }

    #[test]
    fn codes_beyond_the_resolution_are_clamped_and_counted() {
        let frame = [s(4095, 0, ON), s(4096, 0, ON), s(0, 60000, OFF)];
        let cfg = WavConfig { rate_hz: 3, seconds: 1.0, ..WavConfig::default() };
        let (bytes, stats) = wav(&frame, &cfg);
        assert_eq!(stats.clipped, 2);
        assert_eq!(read_i16(&bytes).1, [32767, -32767, 32767, -32767, -32767, 32767]);
    }

    #[test]
    fn a_scene_round_trips_through_a_float_file() {
        use crate::link::WireVolume;
        use crate::scene::{SceneConfig, build};
        use crate::volume::{Dims, Samples};
        use isoscope_core::demo::Demo;
        let n = 12;
        let mut data = vec![0f32; n * n * n];
        Demo::Hydrogen.fill(n, &mut data).unwrap();
        let volume = WireVolume::new(Dims(n, n, n), &Samples::F32(data), [1.0; 3]).unwrap();
        let beam = audio_beam(48_000, 12);
        let scene =
            build(&volume, &SceneConfig { levels: vec![0.1], beam, ..SceneConfig::default() }).unwrap();
        let frame = scene.samples.clone();
        assert_eq!(frame.len() as u64, scene.frame.samples);
        let cfg = WavConfig {
            channels: WavChannels::WithBeam,
            format: WavFormat::Float32,
            seconds: 0.25,
            ..WavConfig::default()
        };
        let path = std::env::temp_dir().join(format!("isoscope-wav-{}.wav", std::process::id()));
        let stats = write_wav_file(&path, &frame, &cfg).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        std::fs::remove_file(&path).unwrap();
        assert_eq!(stats.sample_frames, 12_000);
        let (_, v) = read_f32(&bytes);
        assert_eq!(v.len(), 36_000);
        for (i, c) in v.chunks(3).enumerate() {
            let code = |u: f32| ((f64::from(u) + 1.0) * 4095.0 / 2.0).round() as u16;
            let beam = if c[2] > 0.0 { OFF } else { ON };
            assert_eq!(s(code(c[0]), code(c[1]), beam), frame[i % frame.len()], "sample frame {i}");
        }
        // And 16-bit PCM holds 12-bit codes exactly too.
        let (bytes, _) = wav(&frame, &WavConfig { format: WavFormat::Pcm16, ..cfg });
        let (_, v) = read_i16(&bytes);
        for (i, c) in v.chunks(3).enumerate().take(frame.len()) {
            let code = |u: i16| ((f64::from(u) / 32767.0 + 1.0) * 4095.0 / 2.0).round() as u16;
            assert_eq!((code(c[0]), code(c[1])), (frame[i].x, frame[i].y));
        }
    }

    #[test]
    fn audio_frames_fit_the_refresh_rate() {
        // A 100-LSB circle of 360 chords, 20 times over: about 12,600 LSB.
        let mut cmds = Vec::new();
        for k in 0..20 {
            let c = (500.0 + 150.0 * k as f32, 2000.0);
            cmds.push(Command::MoveTo(ScreenPoint::new(c.0 + 100.0, c.1)));
            for i in 1..=360 {
                let a = (i as f32).to_radians();
                cmds.push(Command::LineTo(ScreenPoint::new(c.0 + 100.0 * a.cos(), c.1 + 100.0 * a.sin())));
            }
        }
        let beam = audio_beam(48_000, 12);
        let slow = audio_frame(&cmds, &beam, 48_000, None);
        assert_eq!(slow.beam, beam);
        assert_eq!(slow.samples.len() as u64, slow.stats.samples);
        // 85 LSB a sample: about 148 samples of path, plus about 6 a
        // circle for its jump and ends; 200 frames/s is 240 samples.
        assert!(slow.stats.samples > 240, "{}", slow.stats.samples);
        let fit = audio_frame(&cmds, &beam, 48_000, Some(200.0));
        assert!(fit.stats.samples <= 240, "{}", fit.stats.samples);
        assert!(fit.beam.lit_step > beam.lit_step);
        assert_eq!(BeamConfig { lit_step: beam.lit_step, ..fit.beam }, beam);
        // Already fast enough: unchanged.
        assert_eq!(audio_frame(&cmds, &beam, 48_000, Some(10.0)), slow);
        // No refresh rate to fit: as none.
        assert_eq!(audio_frame(&cmds, &beam, 48_000, Some(f32::NAN)), slow);
        // The channels, as the WAV file's values.
        let ch = audio_channels(&fit.samples, 12, false);
        let n = fit.samples.len();
        assert_eq!(ch.len(), 3 * n);
        for (i, s) in fit.samples.iter().enumerate() {
            assert_eq!(f64::from(ch[i]), code_to_unit(s.x, 12) as f32 as f64);
            assert_eq!(f64::from(ch[n + i]), code_to_unit(s.y, 12) as f32 as f64);
            assert_eq!(ch[2 * n + i], if s.beam == OFF { 1.0 } else { -1.0 });
        }
        assert_eq!(audio_channels(&fit.samples, 12, true)[2 * n], -ch[2 * n]);
    }

    #[test]
    fn the_audio_beam_is_valid_and_keeps_its_speed() {
        for rate in [1, 8000, 44_100, 48_000, 96_000, 192_000, 1_000_000, u32::MAX] {
            for bits in [1, 8, 12, 16] {
                let b = audio_beam(rate, bits);
                b.validate().unwrap();
                assert_eq!(b.bits, bits);
                // The beam speed in LSB per second, unless the step is at its floor.
                let speed = f64::from(b.lit_step) * f64::from(rate);
                if b.lit_step > MIN_LIT_STEP {
                    let want = f64::from(1u32 << bits) * AUDIO_FULL_SCALES_PER_SECOND;
                    assert!((speed / want - 1.0).abs() < 1e-6, "{rate} {bits}");
                }
            }
        }
        let b = audio_beam(48_000, 12);
        assert!((b.lit_step - 85.333).abs() < 0.01, "{}", b.lit_step);
        assert_eq!((b.settle_base, b.settle_samples(4096.0), b.point_dwell), (2.0, 4, 4));
        assert_eq!((b.spacing, b.corner_dwell), (Spacing::Constant, 0));
        assert_eq!(audio_beam(0, 40), audio_beam(1, 16));
    }
}
