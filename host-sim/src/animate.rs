//! The surface turning on the simulated screen, as a looping GIF or APNG:
//! a chicken-wire surface reads as 3D only when it moves.
//!
//! The volume goes to an in-process board once ([`crate::scene::with_board`]:
//! contoured, stitched and ordered by the board's engine); each animation
//! frame sets the board's view to the next yaw, as a `SetView` after the
//! volume would (the board re-projects the tour it made for the first
//! view, without ordering again; every view fits the surface's bounding
//! sphere, so the picture keeps its scale while it turns), and draws the
//! board's frame on one [`Screen`] (bands on the cores) that keeps
//! [`PhosphorConfig::persistence`] of the frames before, so a moving line
//! leaves the faint trail it leaves on a tube.
//!
//! # Timing
//!
//! Animation frame `k` (of [`AnimConfig::frames`]) shows the view at `yaw +
//! k * turn_deg / frames`, so with a whole turn (the default) the last frame
//! leads back into the first and the file loops seamlessly. Each animation
//! frame draws [`AnimConfig::refreshes`] of the board's frames of its view
//! (the phosphor decaying before each one). Before frame 0,
//! the views leading up to it are drawn (not written) until the picture
//! they leave has decayed below 1/1000, so frame 0 has its trail too.
//!
//! # Formats
//!
//! - [`AnimFormat::Gif`]: a global palette of 256 colours sampled from the
//!   picture's [`Palette`](crate::phosphor::Palette) at display values
//!   `i / 255` (for P31, a ramp from black through green to whitish green),
//!   each pixel mapped to the nearest entry (squared RGB distance; the
//!   picture's colours all lie on that ramp, so this is the nearest display
//!   value). Full frames, LZW-compressed; a `NETSCAPE2.0` loop count.
//! - [`AnimFormat::Apng`]: animated PNG, 8-bit RGB, exact colours; an
//!   ordinary PNG viewer shows the first frame.
//!
//! Both loop forever by default ([`AnimConfig::plays`]) with a delay of
//! [`AnimConfig::delay_cs`] hundredths of a second a frame.

use crate::board::InProcess;
use crate::link::WireVolume;
use crate::phosphor::{PhosphorConfig, Screen};
use crate::progress::Progress;
use crate::scene::{SceneConfig, with_board};
use anyhow::{Context, Result, anyhow, bail};
use std::collections::HashMap;
use std::io::Write;
use std::path::Path;
use std::time::Instant;

/// The file format of an animation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum AnimFormat {
    /// GIF with a 256-colour palette of the phosphor's ramp (the default:
    /// every viewer, browser and chat plays it).
    #[default]
    Gif,
    /// Animated PNG, exact 24-bit colour.
    Apng,
}

impl AnimFormat {
    /// The format a file name asks for: `.gif` is GIF, `.png` and `.apng`
    /// are APNG (case-insensitive); `None` for anything else.
    pub fn from_path(path: impl AsRef<Path>) -> Option<Self> {
        let ext = path.as_ref().extension()?.to_str()?.to_ascii_lowercase();
        match ext.as_str() {
            "gif" => Some(AnimFormat::Gif),
            "png" | "apng" => Some(AnimFormat::Apng),
            _ => None,
        }
    }
}

/// Largest number of animation frames.
pub const MAX_FRAMES: u32 = 100_000;

/// How the view turns and how the animation is written. See the [module
/// docs](self).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AnimConfig {
    /// Animation frames, `1 ..= MAX_FRAMES`.
    pub frames: u32,
    /// The yaw turned over the whole animation, degrees (finite; negative
    /// turns the other way): frame `k` is at `yaw + k * turn_deg / frames`.
    pub turn_deg: f32,
    /// Display time of each frame in hundredths of a second, `1 ..= 65535`
    /// (GIF's unit; many viewers show delays below 2 as 10).
    pub delay_cs: u16,
    /// Refresh-loop frames drawn on the phosphor per animation frame, `>= 1`.
    pub refreshes: u32,
    /// How many times a viewer plays the animation, 0 = forever.
    pub plays: u16,
    /// GIF or APNG.
    pub format: AnimFormat,
}

impl Default for AnimConfig {
    /// One whole turn in 72 frames of 5°, 4 cs each (25 frames a second, a
    /// turn in 2.9 s: slow enough for the eye to follow the wires in depth,
    /// smooth enough not to jump), one refresh per frame, looping forever,
    /// as a GIF.
    fn default() -> Self {
        Self { frames: 72, turn_deg: 360.0, delay_cs: 4, refreshes: 1, plays: 0, format: AnimFormat::Gif }
    }
}

impl AnimConfig {
    /// The yaw step between frames, degrees.
    pub fn step_deg(&self) -> f32 {
        self.turn_deg / self.frames.max(1) as f32
    }

    /// Check every field.
    ///
    /// # Errors
    /// The first field out of its documented range.
    pub fn validate(&self) -> Result<()> {
        if !(1..=MAX_FRAMES).contains(&self.frames) {
            bail!("an animation needs 1 to {MAX_FRAMES} frames, not {}", self.frames);
        }
        if !self.turn_deg.is_finite() {
            bail!("the turn must be a finite number of degrees");
        }
        if self.delay_cs == 0 {
            bail!("the frame delay must be at least 1 hundredth of a second");
        }
        if self.refreshes == 0 {
            bail!("each animation frame needs at least 1 refresh");
        }
        Ok(())
    }
}

/// What [`animate`] wrote and what it took.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AnimStats {
    /// Animation frames written.
    pub frames: u32,
    /// Frames drawn before the first one, for its trail.
    pub preroll: u32,
    /// Picture size in pixels.
    pub width: u32,
    /// Picture size in pixels.
    pub height: u32,
    /// The yaw step between frames, degrees.
    pub step_deg: f32,
    /// Beam samples of one refresh, averaged over the written frames.
    pub mean_samples: f64,
    /// Bytes written.
    pub bytes: u64,
    /// Seconds spent building scenes (contouring, projection, display
    /// list, ordering), drawing on the phosphor (beam schedule, deposit,
    /// decay, tone mapping), and encoding.
    pub seconds: [f64; 3],
}

/// Animate `volume` turning: put it on an in-process board once with
/// `scene`'s settings and memory, then draw the board's frame at each yaw.
///
/// # Errors
/// An invalid animation, picture, view or beam configuration, a volume
/// the board refuses, or the writer's error.
pub fn animate<W: Write>(
    volume: &WireVolume,
    scene: &SceneConfig,
    picture: PhosphorConfig,
    anim: &AnimConfig,
    out: W,
    progress: Option<&Progress>,
) -> Result<AnimStats> {
    anim.validate()?;
    if picture.bits != scene.beam.bits {
        bail!(
            "the picture's DAC resolution ({} bits) is not the beam's ({} bits)",
            picture.bits,
            scene.beam.bits
        );
    }
    let t0 = Instant::now();
    with_board(volume, scene, None, |board, _| {
        let loading = t0.elapsed().as_secs_f64();
        let mut stats = animate_board(board, scene, picture, anim, out, progress)?;
        stats.seconds[0] += loading;
        Ok(stats)
    })
}

/// Animate the picture on `board` turning: frame `k` sets the board's view
/// to `scene.view` yawed by `k * anim.step_deg()`.
///
/// # Errors
/// An invalid animation or picture configuration, a view the board
/// refuses, or the writer's error.
pub fn animate_board<W: Write>(
    board: &mut InProcess<'_>,
    scene: &SceneConfig,
    picture: PhosphorConfig,
    anim: &AnimConfig,
    out: W,
    progress: Option<&Progress>,
) -> Result<AnimStats> {
    anim.validate()?;
    let (width, height) = (picture.width, picture.height);
    let persistence = picture.persistence;
    let mut screen =
        Screen::new(picture, crate::scene::draw_threads()).context("invalid picture settings")?;
    let mut out = Counter { inner: out, bytes: 0 };
    let mut encoder = Encoder::new(&mut out, screen.config(), anim)?;
    let step = anim.step_deg();
    let preroll = preroll_frames(persistence, anim);
    let mut seconds = [0.0; 3];
    let mut samples = 0u64;
    let mut frame = Vec::new();
    for k in -i64::from(preroll)..i64::from(anim.frames) {
        let t0 = Instant::now();
        // In f64, then wrapped: `k * step` of a long animation keeps its
        // precision.
        let delta = ((k as f64 * f64::from(step)) % 360.0) as f32;
        board.set_view(&scene.view.yawed(delta)).with_context(|| format!("building frame {k}"))?;
        frame.clear();
        frame.extend(board.engine().frame());
        let t1 = Instant::now();
        for _ in 0..anim.refreshes {
            screen.refresh(&frame);
            if k >= 0 {
                samples += frame.len() as u64;
            }
        }
        let t2 = Instant::now();
        seconds[0] += (t1 - t0).as_secs_f64();
        seconds[1] += (t2 - t1).as_secs_f64();
        if k >= 0 {
            let rgb = screen.to_rgb8();
            let t3 = Instant::now();
            encoder.frame(&rgb)?;
            seconds[1] += (t3 - t2).as_secs_f64();
            seconds[2] += t3.elapsed().as_secs_f64();
            if let Some(p) = progress {
                p.inc();
            }
        }
    }
    let t = Instant::now();
    encoder.finish()?;
    out.flush().context("writing the animation")?;
    seconds[2] += t.elapsed().as_secs_f64();
    Ok(AnimStats {
        frames: anim.frames,
        preroll,
        width,
        height,
        step_deg: step,
        mean_samples: samples as f64 / f64::from(anim.frames) / f64::from(anim.refreshes),
        bytes: out.bytes,
        seconds,
    })
}

/// Animation frames to draw before frame 0 so that what they leave on the
/// phosphor for it has decayed below 1/1000 (`persistence^n < 0.001` over
/// `n` refreshes), at most one whole animation.
fn preroll_frames(persistence: f32, anim: &AnimConfig) -> u32 {
    let p = f64::from(persistence);
    if p <= 0.0 {
        return 0;
    }
    let refreshes = if p >= 1.0 { f64::INFINITY } else { (1e-3f64.ln() / p.ln()).ceil() };
    let frames = (refreshes / f64::from(anim.refreshes)).ceil();
    if frames >= f64::from(anim.frames) { anim.frames } else { frames as u32 }
}

/// Counts the bytes written through it.
struct Counter<W> {
    inner: W,
    bytes: u64,
}

impl<W: Write> Write for Counter<W> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.bytes += n as u64;
        Ok(n)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

enum Encoder<'a, W: Write> {
    Gif {
        enc: gif::Encoder<&'a mut W>,
        size: (u16, u16),
        palette: Vec<[u8; 3]>,
        /// Colours met so far and their palette entries.
        index: HashMap<[u8; 3], u8>,
        pixels: Vec<u8>,
        delay: u16,
    },
    Apng(png::Writer<&'a mut W>),
}

impl<'a, W: Write> Encoder<'a, W> {
    fn new(out: &'a mut W, picture: &PhosphorConfig, anim: &AnimConfig) -> Result<Self> {
        let (w, h) = (picture.width, picture.height);
        match anim.format {
            AnimFormat::Gif => {
                let size =
                    |v: u32| u16::try_from(v).map_err(|_| anyhow!("a GIF is at most 65535 pixels wide"));
                let palette = gif_palette(picture);
                let flat: Vec<u8> = palette.iter().flatten().copied().collect();
                let size = (size(w)?, size(h)?);
                let mut enc = gif::Encoder::new(out, size.0, size.1, &flat).context("writing the GIF")?;
                let repeat = match anim.plays {
                    0 => gif::Repeat::Infinite,
                    // The loop count is the repeats after the first play
                    // (none at all, for a single play: no extension).
                    n => gif::Repeat::Finite(n - 1),
                };
                enc.set_repeat(repeat).context("writing the GIF")?;
                let index = HashMap::from([(palette[0], 0)]);
                Ok(Encoder::Gif { enc, size, palette, index, pixels: Vec::new(), delay: anim.delay_cs })
            }
            AnimFormat::Apng => {
                let mut enc = png::Encoder::new(out, w, h);
                enc.set_color(png::ColorType::Rgb);
                enc.set_depth(png::BitDepth::Eight);
                enc.set_compression(png::Compression::Default);
                enc.set_animated(anim.frames, u32::from(anim.plays)).context("writing the APNG")?;
                enc.set_frame_delay(anim.delay_cs, 100).context("writing the APNG")?;
                Ok(Encoder::Apng(enc.write_header().context("writing the APNG")?))
            }
        }
    }

    fn frame(&mut self, rgb: &[u8]) -> Result<()> {
        match self {
            Encoder::Gif { enc, size, palette, index, pixels, delay } => {
                pixels.clear();
                pixels.extend(rgb.chunks_exact(3).map(|px| {
                    let c = [px[0], px[1], px[2]];
                    *index.entry(c).or_insert_with(|| nearest(palette, c))
                }));
                let frame = gif::Frame {
                    width: size.0,
                    height: size.1,
                    delay: *delay,
                    buffer: std::borrow::Cow::Borrowed(&pixels[..]),
                    ..gif::Frame::default()
                };
                enc.write_frame(&frame).context("writing the GIF")
            }
            Encoder::Apng(w) => w.write_image_data(rgb).context("writing the APNG"),
        }
    }

    fn finish(self) -> Result<()> {
        match self {
            Encoder::Gif { enc, .. } => enc.into_inner().map(|_| ()).context("writing the GIF"),
            Encoder::Apng(w) => w.finish().context("writing the APNG"),
        }
    }
}

/// The GIF's global palette: the picture's palette at display values
/// `i / 255`, rounded as the picture's colours are.
pub fn gif_palette(picture: &PhosphorConfig) -> Vec<[u8; 3]> {
    (0..256).map(|i| picture.palette.color(i as f32 / 255.0).map(|c| (c * 255.0 + 0.5) as u8)).collect()
}

/// The index of the palette entry nearest to `c` (squared RGB distance; the
/// first of equals).
fn nearest(palette: &[[u8; 3]], c: [u8; 3]) -> u8 {
    let d = |p: &[u8; 3]| (0..3).map(|k| (i32::from(p[k]) - i32::from(c[k])).pow(2)).sum::<i32>();
    let best = (0..palette.len()).min_by_key(|&i| (d(&palette[i]), i)).unwrap_or(0);
    best as u8
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::volume::{Dims, Samples};
    use isoscope_core::demo::Demo;
    use isoscope_core::view::View;
    use std::io::Cursor;

    fn hydrogen(n: usize) -> WireVolume {
        let mut data = vec![0f32; n * n * n];
        Demo::Hydrogen.fill(n, &mut data).unwrap();
        WireVolume::new(Dims(n, n, n), &Samples::F32(data), [1.0; 3]).unwrap()
    }

    fn scene_cfg() -> SceneConfig {
        SceneConfig { levels: vec![0.1], ..SceneConfig::default() }
    }

    fn small(format: AnimFormat) -> AnimConfig {
        AnimConfig { frames: 4, turn_deg: 360.0, format, ..AnimConfig::default() }
    }

    fn run(anim: &AnimConfig, size: u32) -> (Vec<u8>, AnimStats) {
        let volume = hydrogen(12);
        let mut out = Vec::new();
        let stats =
            animate(&volume, &scene_cfg(), PhosphorConfig::with_size(size, size), anim, &mut out, None)
                .unwrap();
        (out, stats)
    }

    /// Frames of a GIF as RGB, with the loop setting and each delay.
    fn decode_gif(bytes: &[u8]) -> (u16, u16, gif::Repeat, Vec<(u16, Vec<u8>)>) {
        let mut opts = gif::DecodeOptions::new();
        opts.set_color_output(gif::ColorOutput::RGBA);
        let mut d = opts.read_info(Cursor::new(bytes)).unwrap();
        let (w, h) = (d.width(), d.height());
        let mut frames = Vec::new();
        while let Some(f) = d.read_next_frame().unwrap() {
            assert_eq!((f.left, f.top, f.width, f.height), (0, 0, w, h));
            let rgb = f.buffer.chunks_exact(4).flat_map(|p| [p[0], p[1], p[2]]).collect();
            frames.push((f.delay, rgb));
        }
        (w, h, d.repeat(), frames)
    }

    /// Frames of an APNG as RGB, with the frame count and plays it declares.
    /// Width, height, the animation control and each frame's delay and RGB.
    type Apng = (u32, u32, png::AnimationControl, Vec<((u16, u16), Vec<u8>)>);

    fn decode_apng(bytes: &[u8]) -> Apng {
        let mut r = png::Decoder::new(Cursor::new(bytes)).read_info().unwrap();
        let info = r.info();
        let (w, h, actl) = (info.width, info.height, info.animation_control.unwrap());
        let mut frames = Vec::new();
        for _ in 0..actl.num_frames {
            let mut buf = vec![0; r.output_buffer_size()];
            let out = r.next_frame(&mut buf).unwrap();
            assert_eq!((out.width, out.height, out.color_type), (w, h, png::ColorType::Rgb));
            let fc = r.info().frame_control.unwrap();
            assert_eq!((fc.x_offset, fc.y_offset, fc.width, fc.height), (0, 0, w, h));
            buf.truncate(out.buffer_size());
            frames.push(((fc.delay_num, fc.delay_den), buf));
        }
        (w, h, actl, frames)
    }

    fn mean_abs_diff(a: &[u8], b: &[u8]) -> f64 {
        a.iter().zip(b).map(|(&x, &y)| f64::from(x.abs_diff(y))).sum::<f64>() / a.len() as f64
    }

    #[test]
    fn a_gif_decodes_with_its_frames_size_and_loop() {
        let (bytes, stats) = run(&small(AnimFormat::Gif), 64);
        assert_eq!(&bytes[..6], b"GIF89a");
        assert_eq!(stats.bytes, bytes.len() as u64);
        assert_eq!((stats.frames, stats.width, stats.height, stats.step_deg), (4, 64, 64, 90.0));
        assert_eq!(stats.preroll, 3, "0.05^3 < 1/1000");
        assert!(stats.mean_samples > 1000.0, "{}", stats.mean_samples);
        let (w, h, repeat, frames) = decode_gif(&bytes);
        assert_eq!((w, h, repeat), (64, 64, gif::Repeat::Infinite));
        assert_eq!(frames.len(), 4);
        for (delay, rgb) in &frames {
            assert_eq!(*delay, 4);
            // Lit, green, and black in the corner.
            let green = rgb.chunks_exact(3).filter(|p| p[1] > 60 && p[1] >= p[0] && p[1] >= p[2]).count();
            assert!(green > 100, "{green} green pixels");
            assert_eq!(&rgb[..3], &[0, 0, 0]);
            assert!(rgb.chunks_exact(3).all(|p| p[1] >= p[0] && p[1] >= p[2]), "every colour on the ramp");
        }
        // It turns: consecutive frames differ (the 3d_xy orbital turned by
        // 90° about y is not the same picture), and a frame differs from
        // what a still view would leave.
        for k in 0..4 {
            let d = mean_abs_diff(&frames[k].1, &frames[(k + 1) % 4].1);
            assert!(d > 1.0, "frames {k} and {} differ by {d}", (k + 1) % 4);
        }
    }

    #[test]
    fn gif_colours_are_the_nearest_palette_entries() {
        let picture = PhosphorConfig::with_size(48, 48);
        let palette = gif_palette(&picture);
        assert_eq!(palette.len(), 256);
        assert_eq!(palette[0], [0, 0, 0]);
        assert_eq!(palette[255], [230, 255, 230]);
        // A green ramp: green never below red or blue, rising brightness.
        assert!(palette.iter().all(|c| c[1] >= c[0] && c[1] >= c[2]));
        assert!(palette.windows(2).all(|w| w[1].iter().map(|&v| u32::from(v)).sum::<u32>()
            >= w[0].iter().map(|&v| u32::from(v)).sum::<u32>()));
        // Every palette colour maps to itself, or an identical entry.
        for (i, &c) in palette.iter().enumerate() {
            let j = usize::from(nearest(&palette, c));
            assert_eq!(palette[j], c, "entry {i}");
            assert!(j <= i);
        }
        // The APNG and the GIF of the same animation: the GIF's colours are
        // within a step of the ramp of the exact ones.
        let (gif, _) = run(&small(AnimFormat::Gif), 48);
        let (png, _) = run(&small(AnimFormat::Apng), 48);
        let (.., gif_frames) = decode_gif(&gif);
        let (.., png_frames) = decode_apng(&png);
        for ((_, g), (_, p)) in gif_frames.iter().zip(&png_frames) {
            let worst = g.iter().zip(p).map(|(&a, &b)| a.abs_diff(b)).max().unwrap();
            assert!(worst <= 4, "{worst}");
            assert!(mean_abs_diff(g, p) < 0.5);
        }
    }

    #[test]
    fn an_apng_decodes_with_its_frames_size_and_loop() {
        let anim = AnimConfig { delay_cs: 5, plays: 3, ..small(AnimFormat::Apng) };
        let (bytes, stats) = run(&anim, 64);
        assert_eq!(&bytes[1..4], b"PNG");
        assert_eq!(stats.bytes, bytes.len() as u64);
        let (w, h, actl, frames) = decode_apng(&bytes);
        assert_eq!((w, h), (64, 64));
        assert_eq!((actl.num_frames, actl.num_plays), (4, 3));
        assert_eq!(frames.len(), 4);
        for (delay, _) in &frames {
            assert_eq!(*delay, (5, 100));
        }
        for k in 0..4 {
            let d = mean_abs_diff(&frames[k].1, &frames[(k + 1) % 4].1);
            assert!(d > 1.0, "frames {k} and {} differ by {d}", (k + 1) % 4);
        }
        // Forever by default; a finite GIF loop count too.
        let (bytes, _) = run(&small(AnimFormat::Apng), 16);
        assert_eq!(decode_apng(&bytes).2.num_plays, 0);
        let (bytes, _) = run(&AnimConfig { plays: 2, ..small(AnimFormat::Gif) }, 16);
        assert_eq!(decode_gif(&bytes).2, gif::Repeat::Finite(1));
    }

    #[test]
    fn a_whole_turn_loops_seamlessly() {
        // 8 frames of 45°, and the same turn's first 8 frames of 16 at 22.5°:
        // the picture at each angle does not depend on the animation's length
        // beyond the trail. And a 4-frame full turn's frame 0 is a 4-frame
        // full turn's frame 4 (drawn after frame 3): the pre-roll is the
        // animation's own end.
        let volume = hydrogen(12);
        let picture = PhosphorConfig::with_size(48, 48);
        let anim = small(AnimFormat::Apng);
        let mut one = Vec::new();
        animate(&volume, &scene_cfg(), picture.clone(), &anim, &mut one, None).unwrap();
        let mut two = Vec::new();
        let twice = AnimConfig { frames: 8, turn_deg: 720.0, ..anim };
        animate(&volume, &scene_cfg(), picture, &twice, &mut two, None).unwrap();
        let (.., a) = decode_apng(&one);
        let (.., b) = decode_apng(&two);
        for k in 0..4 {
            assert!(mean_abs_diff(&a[k].1, &b[k + 4].1) < 0.01, "frame {k}");
        }
    }

    #[test]
    fn the_view_keeps_its_scale_while_turning() {
        // Seen level (pitch 0), a turn about the vertical axis leaves every
        // point's height alone: with the board's fit (the surface's
        // bounding sphere) the picture's height is the same at every yaw.
        // Every frame stays inside the margin.
        let volume = hydrogen(12);
        let heights: Vec<f32> = [0.0f32, 20.0, 45.0, 70.0]
            .iter()
            .map(|&yaw| {
                let view = View { yaw, pitch: 0.0, ..View::DEFAULT };
                let s = crate::scene::build(&volume, &SceneConfig { view, ..scene_cfg() }).unwrap();
                let ys: Vec<f32> = s.commands.iter().map(|c| c.point().y).collect();
                let (lo, hi) = ys.iter().fold((f32::MAX, f32::MIN), |(l, h), &y| (l.min(y), h.max(y)));
                assert!(lo >= 0.05 * 4095.0 - 1.0 && hi <= 0.95 * 4095.0 + 1.0);
                hi - lo
            })
            .collect();
        let (lo, hi) = heights.iter().fold((f32::MAX, f32::MIN), |(l, h), &e| (l.min(e), h.max(e)));
        assert!((hi - lo) / hi < 1e-3, "{heights:?}");
    }

    #[test]
    fn bad_arguments_are_refused() {
        let volume = hydrogen(8);
        let picture = PhosphorConfig::with_size(16, 16);
        let err = |scene: &SceneConfig, picture: PhosphorConfig, anim: AnimConfig| {
            let mut out = Vec::new();
            let e = animate(&volume, scene, picture, &anim, &mut out, None).unwrap_err();
            format!("{e:#}")
        };
        let base = small(AnimFormat::Gif);
        let s = scene_cfg();
        assert!(err(&s, picture.clone(), AnimConfig { frames: 0, ..base }).contains("frames"));
        assert!(err(&s, picture.clone(), AnimConfig { frames: MAX_FRAMES + 1, ..base }).contains("frames"));
        assert!(err(&s, picture.clone(), AnimConfig { turn_deg: f32::NAN, ..base }).contains("turn"));
        assert!(err(&s, picture.clone(), AnimConfig { turn_deg: f32::INFINITY, ..base }).contains("turn"));
        assert!(err(&s, picture.clone(), AnimConfig { delay_cs: 0, ..base }).contains("delay"));
        assert!(err(&s, picture.clone(), AnimConfig { refreshes: 0, ..base }).contains("refresh"));
        assert!(err(&s, PhosphorConfig { bits: 10, ..picture.clone() }, base).contains("bits"));
        assert!(err(&s, PhosphorConfig { width: 0, ..picture.clone() }, base).contains("picture"));
        assert!(err(&SceneConfig { levels: vec![], ..s.clone() }, picture.clone(), base).contains("level"));
        let mut bad_view = s.clone();
        bad_view.view.margin = 0.7;
        assert!(err(&bad_view, picture.clone(), base).contains("view"));
        // A writer that fails.
        struct Broken;
        impl Write for Broken {
            fn write(&mut self, _: &[u8]) -> std::io::Result<usize> {
                Err(std::io::Error::other("disk full"))
            }
            fn flush(&mut self) -> std::io::Result<()> {
                Ok(())
            }
        }
        for format in [AnimFormat::Gif, AnimFormat::Apng] {
            let e = animate(&volume, &s, picture.clone(), &small(format), Broken, None).unwrap_err();
            assert!(format!("{e:#}").contains("disk full"), "{e:#}");
        }
    }

    #[test]
    fn formats_from_file_names() {
        assert_eq!(AnimFormat::from_path("a/b.gif"), Some(AnimFormat::Gif));
        assert_eq!(AnimFormat::from_path("x.GIF"), Some(AnimFormat::Gif));
        assert_eq!(AnimFormat::from_path("x.png"), Some(AnimFormat::Apng));
        assert_eq!(AnimFormat::from_path("x.apng"), Some(AnimFormat::Apng));
        assert_eq!(AnimFormat::from_path("x.jpg"), None);
        assert_eq!(AnimFormat::from_path("gif"), None);
    }

    #[test]
    fn preroll_covers_the_trail() {
        let a = AnimConfig::default();
        assert_eq!(preroll_frames(0.0, &a), 0);
        assert_eq!(preroll_frames(0.05, &a), 3);
        assert_eq!(preroll_frames(0.05, &AnimConfig { refreshes: 2, ..a }), 2);
        assert_eq!(preroll_frames(0.5, &a), 10);
        assert_eq!(preroll_frames(0.99, &a), 72, "at most one whole animation");
        assert_eq!(preroll_frames(1.0, &AnimConfig { frames: 5, ..a }), 5);
    }
}
