//! isoscope in the browser: a small API over `isoscope-sim`'s library,
//! compiled to WebAssembly.
//!
//! Nothing here draws or reads on its own: a volume is read by the host's
//! readers ([`LoadedVolume::read_known_bytes`], gzip included), its frame
//! is built by the one picture pipeline ([`scene::build`]: the board's
//! engine in process, as `isoscope-sim render` builds it), and drawn by the
//! same phosphor model ([`Screen`], one band: no threads in the page). This crate holds the page's state
//! (the volume, the settings, the last frame and picture) and turns it into
//! values JavaScript takes: RGBA pixels, the samples as text, and JSON.
//! Its exports are the command line's files, made by the same functions:
//! `render`'s PNG ([`Screen::encode_png`]), `render --samples`'s text
//! ([`scene::samples_text`]), `contour --format svg`'s SVG
//! ([`isoscope_sim::svg::write_svg`]) and `wav`'s WAV
//! ([`isoscope_sim::wav::write_wav`], with its defaults).
//!
//! The page runs it in a Web Worker (`web/worker.js`), so that loading a
//! volume and building a frame never hold up the page; long work is told
//! to the worker's global `isoscopeProgress(label, done, total)` function
//! if it has one (`total` 0: a step with no count).
//!
//! A board over Web Serial: [`Link`] is the command line's sender
//! ([`Sender`], the same state machine `isoscope-sim send` drives), driven
//! by the page's `web/serial.js` through the worker: the bytes the port
//! read go in, the bytes to write and the time to wake it come out. The
//! volume it sends is the page's, fitted as `send` fits it
//! ([`Scope::send_to`]).
//!
//! Every method that can fail returns a JavaScript error with the message
//! the command line would print; none panics on bad input.

use anyhow::{Context, Result, bail};
use isoscope_core::beam::BeamConfig;
use isoscope_core::contour::grid::Plane;
use isoscope_core::engine::Board;
use isoscope_core::engine::Capacity;
use isoscope_core::output::{Beam, Sample};
use isoscope_core::view::View;
use isoscope_sim::board::{OwnedBoard, frames_for};
use isoscope_sim::fit::{self, FitOptions, Limits};
use isoscope_sim::formats::Options;
use isoscope_sim::info::{LEVEL_BINS, Summary, summarize};
use isoscope_sim::link::{BoardInfo, SendConfig, SendProgress, Sender, State, ViewSetting, WireVolume};
use isoscope_sim::phosphor::{PhosphorConfig, Screen};
use isoscope_sim::progress::Progress;
use isoscope_sim::scene::{self, Scene, SceneConfig};
use isoscope_sim::volume::{DemoSpec, Dims, LoadedVolume};
use isoscope_sim::wav::{
    AUDIO_FPS, AudioFrame, WavConfig, audio_beam, audio_channels, audio_frame, write_wav,
};
use std::fmt::Write as _;
use std::time::Duration;
use wasm_bindgen::prelude::*;

/// The largest volume a page loads, in bytes of samples: a wasm32 page has
/// 4 GiB of address space at most, and loading holds the file's bytes, the
/// volume read and the volume as the board takes it at once.
pub const MAX_VOLUME_BYTES: usize = 256 << 20;

/// The zoom of `render`'s default margin (5%).
const DEFAULT_ZOOM: f64 = 0.9;

/// The largest picture, in pixels a side.
const MAX_SIZE: u32 = 2048;

/// A draft's slice stride, in strides of its frame ([`Scope::draft`]):
/// four: a quarter of the slices, about a fifth of the points of
/// `gyroid:128`'s frame.
const DRAFT_STRIDE: usize = 4;

/// A loaded volume and what the page shows of it.
struct Volume {
    /// Its name: the file's, or the demo's `NAME:N`.
    name: String,
    /// As read, to fit to a board ([`Scope::board_volume`]).
    loaded: LoadedVolume,
    wire: WireVolume,
    summary: Summary,
    /// The levels it is drawn at first: a demo's own, or the first level
    /// `info` suggests.
    default_levels: Vec<f32>,
    /// The readers' remarks.
    notes: Vec<String>,
}

/// The scope in the page: a volume, the settings, and the picture.
#[wasm_bindgen]
pub struct Scope {
    volume: Option<Volume>,
    levels: Vec<f32>,
    planes: Vec<Plane>,
    /// The slice stride asked for; 0: the volume's default
    /// ([`scene::auto_every`]).
    every: usize,
    yaw: f32,
    pitch: f32,
    zoom: f64,
    board: Option<Board>,
    /// The frame of the settings, `None` when they changed since.
    scene: Option<Scene>,
    /// A draft of the frame of the settings ([`Scope::draft`]), shown
    /// until the frame is built; `None` when they changed since.
    draft: Option<Scene>,
    /// The host memory, in points, the last frame's surface needed, and
    /// the settings it was for: a frame that differs only in its view
    /// starts there ([`scene::with_board_from`]).
    fit: Option<(Fit, usize)>,
    /// The volume fitted to the board preset (as `render --board` fits
    /// it), the settings it was fitted for, and the notes on it.
    fitted: Option<(Fit, WireVolume, Vec<String>)>,
    /// Milliseconds the last frame took to build and draw.
    build_ms: f64,
    draw_ms: f64,
    screen: Screen,
    /// Whether a frame is drawn on `screen` ([`Scope::set_drawing`]).
    drawing: bool,
    /// Whether the view is turning ([`Scope::set_turning`]).
    turning: bool,
    /// While turning, the board the frames are turned on.
    turn: Option<Turn>,
    /// The last frame's glow fades under the next instead of being
    /// cleared ([`Scope::set_persistence`]).
    persistence: bool,
    /// The spacing of the last [`Scope::audio`] frame.
    audio_step: f32,
}

/// A board kept between the frames of a turn ([`Scope::set_turning`]):
/// loaded once, then turned with `SetView` as the board turns its picture,
/// for the settings it was loaded with (every one but yaw and pitch).
struct Turn {
    board: OwnedBoard,
    capacity: Capacity,
    fit: Fit,
    zoom: f64,
}

impl Turn {
    /// The frame of `cfg`, the board turned to its view.
    fn turned(&mut self, wire: &WireVolume, cfg: &SceneConfig) -> Result<Scene> {
        report("turning the picture", 0, 0);
        self.board.with(|b| b.set_view(&cfg.view))?;
        Ok(scene::scene_of(self.board.board(), wire, self.capacity, cfg))
    }
}

/// What decides whether a surface fits a memory: every setting but the
/// view.
#[derive(Debug, Clone, PartialEq)]
struct Fit {
    levels: Vec<f32>,
    planes: Vec<Plane>,
    every: usize,
    board: Option<Board>,
}

/// An `anyhow` error, its causes included, as a JavaScript error.
fn js(e: anyhow::Error) -> JsError {
    JsError::new(&format!("{e:#}"))
}

#[cfg(target_arch = "wasm32")]
#[wasm_bindgen]
extern "C" {
    /// The worker's progress function (`catch`: an error, e.g. none
    /// defined, comes back as a value, not through the module's frames).
    #[wasm_bindgen(catch, js_name = isoscopeProgress)]
    fn progress_js(label: &str, done: usize, total: usize) -> Result<(), JsValue>;
}

/// Tell the page how long work goes: `label`, `done` of `total` units (0
/// of 0: a step with no count). Nothing off wasm32 or with no
/// `isoscopeProgress` in the global scope.
fn report(label: &'static str, done: usize, total: usize) {
    #[cfg(target_arch = "wasm32")]
    let _ = progress_js(label, done, total);
    #[cfg(not(target_arch = "wasm32"))]
    let _ = (label, done, total);
}

/// [`report`] for the frames fed to the board: after the last one the
/// board stitches and orders the surface, which takes a while of its own
/// on a large volume. (On the host the memory may grow and the volume be
/// fed again: counted again from 0.)
fn report_feeding(label: &'static str, done: usize, total: usize) {
    match done.checked_rem(total) {
        Some(0) => report("stitching and ordering the surface", 0, 0),
        Some(n) => report(label, n, total),
        None => report(label, done, total),
    }
}

/// Progress, `label`, over the frames of `wire` that `cfg` feeds the
/// engine, told to the page ([`report_feeding`]).
fn feeding(label: &'static str, wire: &WireVolume, cfg: &SceneConfig) -> Result<Progress> {
    Ok(Progress::with_hook(label, frames_for(wire, &cfg.send()?), report_feeding))
}

#[wasm_bindgen]
impl Scope {
    /// A scope drawing a `size` by `size` picture, showing nothing yet.
    ///
    /// # Errors
    /// A size of 0 or above 2048.
    #[wasm_bindgen(constructor)]
    pub fn new(size: u32) -> Result<Scope, JsError> {
        Self::with_size(size).map_err(js)
    }

    /// Load the built-in demo `NAME:N` (as `--demo`), e.g. `hydrogen:32`.
    ///
    /// # Errors
    /// An unknown demo or a size out of range.
    pub fn load_demo(&mut self, spec: &str) -> Result<(), JsError> {
        self.demo(spec).map_err(js)
    }

    /// Load a volume file from its bytes, in any format `isoscope-sim`
    /// reads by name or first bytes (gzipped or not); `name` is the file's.
    ///
    /// # Errors
    /// Not a volume file that names or bytes tell, or a bad one: the
    /// reader's message.
    pub fn load_file(&mut self, name: &str, bytes: &[u8]) -> Result<(), JsError> {
        self.file(name, bytes).map_err(js)
    }

    /// The contour levels (one to four).
    pub fn set_levels(&mut self, levels: Vec<f32>) {
        if levels != self.levels {
            self.levels = levels;
            self.stale();
        }
    }

    /// The view: yaw and pitch in degrees, and zoom, the share of the
    /// screen the volume's box fills (0.1 to 1; the default 0.9 is the
    /// board's 5% margin).
    pub fn set_view(&mut self, yaw: f32, pitch: f32, zoom: f64) {
        let zoom = if zoom.is_finite() { zoom.clamp(0.1, 1.0) } else { DEFAULT_ZOOM };
        if (yaw, pitch, zoom) != (self.yaw, self.pitch, self.zoom) {
            (self.yaw, self.pitch, self.zoom) = (yaw, pitch, zoom);
            self.stale();
        }
    }

    /// The slicing planes as `--axes` takes them, e.g. `xy,yz`.
    ///
    /// # Errors
    /// An unknown plane or none.
    pub fn set_planes(&mut self, axes: &str) -> Result<(), JsError> {
        let planes = planes(axes).map_err(js)?;
        if planes != self.planes {
            self.planes = planes;
            self.stale();
        }
        Ok(())
    }

    /// Draw every `every`-th slice of each plane; 0 for the volume's
    /// default (as `render`: longest axis / 32, rounded up).
    pub fn set_every(&mut self, every: u32) {
        let every = every as usize;
        if every != self.every {
            self.every = every;
            self.stale();
        }
    }

    /// Draw with a board's memory and clock (`f407`), or the host's (an
    /// empty name).
    ///
    /// # Errors
    /// An unknown board.
    pub fn set_board(&mut self, name: &str) -> Result<(), JsError> {
        let board = match name.trim() {
            "" | "host" => None,
            n => Some(Board::named(n).ok_or_else(|| JsError::new(&format!("unknown board `{n}`")))?),
        };
        if board != self.board {
            self.board = board;
            self.stale();
        }
        Ok(())
    }

    /// Persistence on: each new frame (a turn, a level) is drawn over the
    /// last one faded by the phosphor's persistence, as the frames of
    /// `render --animate` are, so a turning surface leaves a fading trail
    /// as on a long-persistence scope. Off (the default): each frame on a
    /// dark screen, as `render` draws one. Turning it off redraws.
    pub fn set_persistence(&mut self, on: bool) {
        if self.persistence && !on {
            self.stale();
        }
        self.persistence = on;
    }

    /// Draw each frame on the scope's own screen (the default), or only
    /// build it, for a [`Painter`] to draw from [`Scope::frame_samples`]
    /// (the page's second worker: the next frame is built while the last
    /// is drawn). Not drawing, [`Scope::pixels`] stays dark and
    /// [`Scope::png`] is the painter's.
    pub fn set_drawing(&mut self, on: bool) {
        self.drawing = on;
    }

    /// Whether the view is turning (spinning, or dragged with the mouse).
    /// While it is, a frame that differs from the last only in its yaw and
    /// pitch is the board's picture turned with `SetView` (as `render
    /// --animate` turns it, and the board turns its own): the volume is
    /// loaded once for the turn, not for every frame. Those frames are not
    /// `render --yaw`'s, whose order pass sees the volume from the new side
    /// from the start; when the turn stops the frame is built again, and is.
    pub fn set_turning(&mut self, on: bool) {
        if on != self.turning {
            self.turning = on;
            if !on && self.turn.take().is_some() {
                self.stale();
            }
        }
    }

    /// The frame's samples for a [`Painter`]: `x, y, beam` (1 lit, 0
    /// blanked) a sample (empty before the first frame); the draft's
    /// while only a draft is built ([`Scope::draft`]).
    pub fn frame_samples(&self) -> Vec<u16> {
        self.picture().map_or_else(Vec::new, |s| {
            s.samples.iter().flat_map(|p| [p.x, p.y, u16::from(p.beam == Beam::On)]).collect()
        })
    }

    /// Whether each frame is drawn on a dark screen: persistence off
    /// (see [`Scope::set_persistence`]); a [`Painter`] is told so.
    pub fn clears(&self) -> bool {
        !self.persistence
    }

    /// Build the frame and draw it if the settings changed; whether they
    /// had.
    ///
    /// # Errors
    /// No volume, or settings the pipeline refuses (no level, a level
    /// list the board cannot take, a volume too large for the board).
    pub fn update(&mut self) -> Result<bool, JsError> {
        if self.scene.is_some() {
            return Ok(false);
        }
        self.redraw().map_err(js)?;
        Ok(true)
    }

    /// Build a draft of the frame if the settings changed and no draft
    /// of them is drawn yet; whether one was. A draft is the frame with
    /// [`DRAFT_STRIDE`] times the slice stride (`render --every` that, in
    /// about a quarter of the time), for a page to show while it builds
    /// the frame itself with [`Scope::update`]: a level slider dragged
    /// across a large volume then answers at once, and the frame follows
    /// when the slider rests. None with the board preset (its fit depends
    /// on the stride), while the view turns (its frames are turned on the
    /// board, at once), or when no coarser stride keeps two slices of the
    /// longest axis. Exports and sound wait for the frame.
    ///
    /// # Errors
    /// As [`Scope::update`].
    pub fn draft(&mut self) -> Result<bool, JsError> {
        self.redraft().map_err(js)
    }

    /// The picture (a band's rows), RGBA pixels, row by row from the top.
    pub fn pixels(&self) -> Vec<u8> {
        self.screen.to_rgba8()
    }

    /// The picture's width and height in pixels.
    pub fn size(&self) -> u32 {
        self.screen.config().width
    }

    /// The frame's samples as `render --samples` writes them, `x y beam`
    /// a line (empty before the first frame).
    pub fn samples_text(&self) -> String {
        self.scene.as_ref().map_or_else(String::new, |s| scene::samples_text(&s.samples))
    }

    /// The picture as `render` writes it: an 8-bit RGB PNG file.
    ///
    /// # Errors
    /// No frame drawn for the settings.
    pub fn png(&self) -> Result<Vec<u8>, JsError> {
        self.png_bytes().map_err(js)
    }

    /// The frame's drawing commands as `contour --format svg` writes them.
    ///
    /// # Errors
    /// No frame drawn for the settings.
    pub fn svg(&self) -> Result<Vec<u8>, JsError> {
        self.svg_bytes().map_err(js)
    }

    /// The frame as `isoscope-sim wav` writes it with its defaults: drawn
    /// again with the beam made for a 48 kHz sound card
    /// ([`audio_beam`]), five seconds of it, stereo 16-bit PCM.
    ///
    /// # Errors
    /// No frame drawn for the settings.
    pub fn wav(&self) -> Result<Vec<u8>, JsError> {
        self.wav_bytes().map_err(js)
    }

    /// Send the page's volume to the board behind `link` (which has said
    /// what it takes), as `isoscope-sim send` sends it with the page's
    /// levels, planes, stride and view (yaw, pitch; `spin` degrees a
    /// second): with the board preset, fitted to that board as `send
    /// --board` fits it; else as `send` fits a volume to the board that
    /// answered ([`fit::fit_to_connected`]). What is sent, as JSON: `dims`,
    /// `dtype`, `every`, `levels` and the fit's `notes`.
    ///
    /// # Errors
    /// No volume, settings or a volume the board cannot take, or a link
    /// not connected.
    pub fn send_to(&mut self, link: &mut Link, spin: f32, now_ms: f64) -> Result<String, JsError> {
        self.send_plan(link, spin, now_ms).map_err(js)
    }

    /// The frame for a sound card playing at `rate_hz` (the page's
    /// AudioContext's rate), as `isoscope-sim wav --audio-rate RATE`
    /// draws it with its defaults ([`audio_beam`], spaced for
    /// [`AUDIO_FPS`] frames a second: [`audio_frame`]): X, then Y, then
    /// the beam (blanked +1, lit -1), one frame's samples each, at full
    /// scale +-1 ([`audio_channels`]: the WAV file's values). Its spacing
    /// is [`Scope::audio_step`] then.
    ///
    /// # Errors
    /// No frame drawn for the settings.
    pub fn audio(&mut self, rate_hz: u32) -> Result<Vec<f32>, JsError> {
        let frame = self.audio_frame(rate_hz).map_err(js)?;
        self.audio_step = frame.beam.lit_step;
        Ok(audio_channels(&frame.samples, frame.beam.bits, false))
    }

    /// The spacing of the samples of the last [`Scope::audio`], in DAC
    /// LSB along the path (0 before).
    pub fn audio_step(&self) -> f32 {
        self.audio_step
    }

    /// The volume as JSON: `name`, `dims`, `dtype`, `range` (or null),
    /// `histogram`, `suggested` and `default_levels`, and the readers'
    /// `notes`; `null` with no volume.
    pub fn info(&self) -> String {
        let Some(v) = &self.volume else { return "null".into() };
        let s = &v.summary;
        let mut o = Json::default();
        o.str("name", &v.name);
        o.raw("dims", &format!("[{},{},{}]", s.dims.0, s.dims.1, s.dims.2));
        o.str("dtype", s.dtype);
        o.raw("range", &s.range.map_or("null".into(), |(lo, hi)| format!("[{},{}]", num(lo), num(hi))));
        o.raw("histogram", &list(s.histogram.iter().map(u64::to_string)));
        o.raw("suggested", &list(s.suggested.iter().map(|&l| num(l))));
        o.raw("default_levels", &list(v.default_levels.iter().map(|&l| num(l))));
        o.raw("notes", &list(v.notes.iter().map(|n| quote(n))));
        o.end()
    }

    /// The last frame as JSON: `draft` (whether it is only a draft,
    /// [`Scope::draft`]), `points`, `polylines`, `samples`,
    /// `lit_samples`, `blank_ratio` (blanked travel over lit length),
    /// `fps` (refreshes a second at the sample rate), `sample_rate_hz`,
    /// `every`, `board`, `remarks` (what `render` says on stderr), and
    /// `build_ms`, `draw_ms`; `null` before the first frame.
    pub fn stats(&self) -> String {
        let Some(sc) = self.picture() else { return "null".into() };
        let mut o = Json::default();
        o.raw("draft", if self.scene.is_none() { "true" } else { "false" });
        o.raw("points", &sc.points.to_string());
        o.raw("polylines", &sc.polylines.to_string());
        o.raw("samples", &sc.frame.samples.to_string());
        o.raw("lit_samples", &sc.frame.lit_samples.to_string());
        o.raw("blank_ratio", &num(sc.blank_ratio()));
        o.raw("fps", &num(sc.fps()));
        o.raw("sample_rate_hz", &sc.sample_rate_hz.to_string());
        o.raw("every", &sc.loaded.every.to_string());
        o.str("board", sc.board.map_or("host", |b| b.name));
        let fitted = match (&self.board, &self.fitted) {
            (Some(_), Some((_, _, notes))) => notes.iter().map(|n| format!("note: {n}")).collect(),
            _ => Vec::new(),
        };
        o.raw("remarks", &list(fitted.iter().chain(&sc.remarks()).map(|r| quote(r))));
        o.raw("build_ms", &format!("{:.3}", self.build_ms));
        o.raw("draw_ms", &format!("{:.3}", self.draw_ms));
        o.end()
    }
}

/// A dark `size` by `size` screen of one band, as the page draws it (a
/// scope's own, or a painter's).
fn page_screen(size: u32) -> Result<Screen> {
    Screen::new(page_config(size)?, 1).context("invalid picture settings")
}

/// The phosphor of a `size` by `size` picture, as `render --size` draws it.
fn page_config(size: u32) -> Result<PhosphorConfig> {
    if !(1..=MAX_SIZE).contains(&size) {
        bail!("the picture must be 1 to {MAX_SIZE} pixels a side, not {size}");
    }
    Ok(PhosphorConfig::with_size(size, size))
}

/// A `size` by `size` picture's 8-bit RGB rows (the band painters'
/// [`Painter::rgb`], one after the other) as `render`'s PNG file.
///
/// # Errors
/// A size of 0 or above 2048, or not `size * size * 3` bytes.
#[wasm_bindgen]
pub fn png_of(size: u32, rgb: &[u8]) -> Result<Vec<u8>, JsError> {
    png_bytes_of(size, rgb).map_err(js)
}

fn png_bytes_of(size: u32, rgb: &[u8]) -> Result<Vec<u8>> {
    page_config(size)?;
    let want = size as usize * size as usize * 3;
    if rgb.len() != want {
        bail!("a {size} by {size} picture is {want} RGB bytes, not {}", rgb.len());
    }
    Ok(isoscope_sim::phosphor::encode_png(size, size as usize, rgb))
}

impl Scope {
    fn with_size(size: u32) -> Result<Self> {
        let screen = page_screen(size)?;
        Ok(Self {
            volume: None,
            levels: Vec::new(),
            planes: Plane::ALL.to_vec(),
            every: 0,
            yaw: View::DEFAULT.yaw,
            pitch: View::DEFAULT.pitch,
            zoom: DEFAULT_ZOOM,
            board: None,
            scene: None,
            draft: None,
            fit: None,
            fitted: None,
            build_ms: 0.0,
            draw_ms: 0.0,
            screen,
            drawing: true,
            turning: false,
            turn: None,
            persistence: false,
            audio_step: 0.0,
        })
    }

    fn demo(&mut self, spec: &str) -> Result<()> {
        let spec: DemoSpec = spec.trim().parse().map_err(anyhow::Error::msg)?;
        let bytes = spec.n.saturating_pow(3).saturating_mul(4);
        if bytes > MAX_VOLUME_BYTES {
            bail!(
                "the demo's {}^3 samples take {} MiB; a page takes {} MiB",
                spec.n,
                bytes >> 20,
                MAX_VOLUME_BYTES >> 20
            );
        }
        report("making the demo", 0, 0);
        let vol = LoadedVolume::demo(spec)?;
        let name = format!("{}:{}", spec.demo.name(), spec.n);
        self.set_volume(name, &vol, Some(vec![spec.demo.default_level()]), Vec::new())
    }

    fn file(&mut self, name: &str, bytes: &[u8]) -> Result<()> {
        let opts = Options { index: 0, max_bytes: MAX_VOLUME_BYTES, ..Options::default() };
        report("reading the file", 0, 0);
        let Some((vol, notes)) = LoadedVolume::read_known_bytes(name, bytes, &opts)? else {
            bail!(
                "{name}: not a volume file the page knows by its name or first bytes \
                 (.den, .nrrd, .nii, .mrc/.map/.ccp4, .cube, .vtk, any of them gzipped; \
                 raw files need isoscope-sim's --dims and --dtype)"
            );
        };
        self.set_volume(name.to_string(), &vol, None, notes)
    }

    /// Make `vol` the volume, drawn at `levels`, or for a file (`None`)
    /// at the level `render` draws it at: the first suggested over
    /// `LEVEL_BINS` bins, as in the summary the page shows.
    fn set_volume(
        &mut self,
        name: String,
        vol: &LoadedVolume,
        levels: Option<Vec<f32>>,
        notes: Vec<String>,
    ) -> Result<()> {
        report("summarizing the volume", 0, 0);
        let summary = summarize(vol, LEVEL_BINS);
        let levels = match levels {
            Some(l) => l,
            None => match summary.suggested.first() {
                Some(&l) => vec![l],
                None => bail!("{name}: its values suggest no level to draw (it is constant or empty)"),
            },
        };
        report("preparing the volume for the board", 0, 0);
        let wire = WireVolume::from_loaded(vol)?;
        self.levels.clone_from(&levels);
        self.volume =
            Some(Volume { name, loaded: vol.clone(), wire, summary, default_levels: levels, notes });
        self.stale();
        self.fit = None;
        self.fitted = None;
        self.turn = None;
        Ok(())
    }

    /// The stride drawn of a volume of `dims`: the one asked for, or
    /// `render`'s default for it.
    fn every_for(&self, dims: Dims) -> usize {
        match self.every {
            0 => scene::auto_every(dims),
            n => n,
        }
    }

    /// With the board preset, the volume fitted to the board as `render
    /// --board` fits it (`fit::fit_to_board_picture`, once for the
    /// settings it depends on); else the volume as read.
    fn board_volume(&mut self) -> Result<()> {
        let (Some(board), Some(vol)) = (self.board, self.volume.as_ref()) else { return Ok(()) };
        let key = self.fit_key();
        if self.fitted.as_ref().is_some_and(|(k, _, _)| *k == key) {
            return Ok(());
        }
        report("fitting the volume to the board", 0, 0);
        let cfg =
            SceneConfig { planes: self.planes.clone(), ..SceneConfig::board(board, self.levels.clone()) };
        let limits = Limits::of_board(&board);
        let fitted =
            fit::fit_to_board_picture(vol.loaded.clone(), &FitOptions::default(), &limits, &cfg, |d| {
                self.every_for(d)
            })?;
        let wire = WireVolume::from_loaded(&fitted.volume)?;
        self.fitted = Some((key, wire, fitted.notes));
        Ok(())
    }

    /// The volume the frame is of: fitted to the board preset
    /// ([`Scope::board_volume`]), or as read.
    fn wire(&self) -> Result<&WireVolume> {
        let vol = self.volume.as_ref().context("no volume loaded")?;
        match (self.board, &self.fitted) {
            (None, _) => Ok(&vol.wire),
            (Some(_), Some((key, wire, _))) if *key == self.fit_key() => Ok(wire),
            (Some(_), _) => bail!("the volume is not yet fitted to the board"),
        }
    }

    /// The scene configuration of `wire`, as `render` makes it from its
    /// flags.
    fn config(&self, wire: &WireVolume) -> SceneConfig {
        let view = View {
            yaw: self.yaw,
            pitch: self.pitch,
            // In f64, so that a zoom of 0.9 is render's margin of 0.05.
            margin: ((1.0 - self.zoom) / 2.0) as f32,
            spacing: wire.spacing,
            ..View::DEFAULT
        };
        let base = match self.board {
            Some(b) => SceneConfig::board(b, self.levels.clone()),
            None => SceneConfig { levels: self.levels.clone(), ..SceneConfig::default() },
        };
        let [nx, ny, nz] = wire.dims;
        let every = self.every_for(Dims(nx.into(), ny.into(), nz.into()));
        let beam = BeamConfig { bits: view.bits, ..BeamConfig::default() };
        SceneConfig { planes: self.planes.clone(), every, view, beam, ..base }
    }

    /// The frame of `cfg`, as [`scene::build`] makes it, its progress
    /// told to the page. On the host's memory it starts at the size the
    /// last frame needed: if only the view changed since, that size
    /// ([`scene::board_from`]: the same frame, without contouring the
    /// surface again at the sizes that did not fit); after a change of
    /// level, planes or stride, that size if the new surface outgrows the
    /// one below it ([`scene::board_near`]: the same frame, contoured once
    /// while a slider moves through levels of about one size). While the
    /// view turns, the board it was built on comes with it, to turn
    /// ([`Scope::set_turning`]).
    fn build(&self, wire: &WireVolume, cfg: &SceneConfig) -> Result<(Scene, Option<Turn>)> {
        let progress = feeding("contouring", wire, cfg)?;
        let (board, capacity) = match &self.fit {
            Some((fit, points)) if *fit == self.fit_key() => {
                scene::board_from(wire, cfg, *points, Some(&progress))?
            }
            Some((_, points)) => scene::board_near(wire, cfg, *points, Some(&progress))?,
            None => scene::board_from(wire, cfg, scene::HOST_START_POINTS, Some(&progress))?,
        };
        let built = scene::scene_of(board.board(), wire, capacity, cfg);
        let turn = self.turning.then(|| Turn { board, capacity, fit: self.fit_key(), zoom: self.zoom });
        Ok((built, turn))
    }

    /// [`Scope::send_to`].
    fn send_plan(&mut self, link: &mut Link, spin: f32, now_ms: f64) -> Result<String> {
        let info = *link.sender.board().context("the board has not said what it takes: connect first")?;
        let (wire, notes) = self.volume_for(&info)?;
        let [nx, ny, nz] = wire.dims;
        let every = self.every_for(Dims(nx.into(), ny.into(), nz.into()));
        let cfg = SendConfig {
            levels: self.levels.clone(),
            axes: scene::axes(&self.planes),
            every: u8::try_from(every)
                .with_context(|| format!("a stride of {every} slices goes to no board"))?,
            baud: link.baud,
            view: Some(ViewSetting {
                angles: [self.yaw, self.pitch, View::DEFAULT.roll],
                fov_deg: 0.0,
                spin_deg_per_s: spin,
            }),
            ..SendConfig::default()
        };
        link.sender.start(&wire, &cfg, at(now_ms))?;
        let mut o = Json::default();
        o.raw("dims", &format!("[{nx},{ny},{nz}]"));
        o.str("dtype", &format!("{:?}", wire.sample_type));
        o.raw("every", &every.to_string());
        o.raw("levels", &list(cfg.levels.iter().map(|&l| num(l))));
        o.raw("notes", &list(notes.iter().map(|n| quote(n))));
        Ok(o.end())
    }

    /// The volume to send to a board that said `info`, and the notes on
    /// its fit: with the board preset, the page's board volume (`send
    /// --board`); else fitted as `send` fits it to the board that answered.
    fn volume_for(&mut self, info: &BoardInfo) -> Result<(WireVolume, Vec<String>)> {
        if self.board.is_some() {
            self.board_volume()?;
            let (_, wire, notes) = self.fitted.as_ref().context("the volume is not fitted to the board")?;
            return Ok((wire.clone(), notes.clone()));
        }
        let vol = self.volume.as_ref().context("no volume loaded")?;
        report("fitting the volume to the board", 0, 0);
        let picture = |board: Board| {
            Ok(SceneConfig { planes: self.planes.clone(), ..SceneConfig::board(board, self.levels.clone()) })
        };
        let fitted = fit::fit_to_connected(vol.loaded.clone(), &FitOptions::default(), info, picture, |d| {
            self.every_for(d)
        })?;
        Ok((WireVolume::from_loaded(&fitted.volume)?, fitted.notes))
    }

    fn fit_key(&self) -> Fit {
        Fit { levels: self.levels.clone(), planes: self.planes.clone(), every: self.every, board: self.board }
    }

    /// What the page shows of the settings: the frame, else its draft.
    fn picture(&self) -> Option<&Scene> {
        self.scene.as_ref().or(self.draft.as_ref())
    }

    /// The frame on the screen, if it is of the settings.
    fn shown(&self) -> Result<&Scene> {
        self.scene.as_ref().context("no frame drawn for these settings: nothing to export")
    }

    fn png_bytes(&self) -> Result<Vec<u8>> {
        self.shown()?;
        if !self.drawing {
            bail!("this scope does not draw its frames: its painter has the picture");
        }
        Ok(self.screen.encode_png())
    }

    fn svg_bytes(&self) -> Result<Vec<u8>> {
        let scene = self.shown()?;
        let mut out = Vec::new();
        isoscope_sim::svg::write_svg(&mut out, &scene.commands, self.config(self.wire()?).view.bits)?;
        Ok(out)
    }

    fn wav_bytes(&self) -> Result<Vec<u8>> {
        self.shown()?;
        let wire = self.wire()?;
        let cfg = self.config(wire);
        // `wav`'s defaults: its --audio-rate and --seconds are
        // `WavConfig`'s, its frame scheduled for that rate as `wav` does.
        let wav = WavConfig { bits: cfg.view.bits, ..WavConfig::default() };
        let frame = self.audio_frame(wav.rate_hz)?;
        report("writing the WAV file", 0, 0);
        let mut out = std::io::Cursor::new(Vec::new());
        write_wav(&mut out, &frame.samples, &wav)?;
        Ok(out.into_inner())
    }

    /// The shown frame's commands scheduled for a sound card at `rate_hz`
    /// as `isoscope-sim wav` schedules them by default (the commands do
    /// not depend on the beam: `wav` builds the same ones).
    fn audio_frame(&self, rate_hz: u32) -> Result<AudioFrame> {
        let shown = self.shown()?;
        let beam = audio_beam(rate_hz, self.config(self.wire()?).view.bits);
        Ok(audio_frame(&shown.commands, &beam, rate_hz, Some(AUDIO_FPS)))
    }

    fn redraw(&mut self) -> Result<()> {
        let t0 = web_time::Instant::now();
        self.board_volume()?;
        let mut turn = self.turn.take().filter(|t| (&t.fit, t.zoom) == (&self.fit_key(), self.zoom));
        let wire = self.wire()?;
        let cfg = self.config(wire);
        let built = match &mut turn {
            Some(t) => t.turned(wire, &cfg)?,
            None => {
                let (built, board) = self.build(wire, &cfg)?;
                turn = board;
                built
            }
        };
        self.turn = turn;
        self.fit = Some((self.fit_key(), built.capacity.points));
        self.draw(&built, t0);
        self.scene = Some(built);
        self.draft = None;
        Ok(())
    }

    /// [`Scope::draft`].
    fn redraft(&mut self) -> Result<bool> {
        if self.scene.is_some() || self.draft.is_some() || self.board.is_some() || self.turning {
            return Ok(false);
        }
        let t0 = web_time::Instant::now();
        let wire = self.wire()?;
        let cfg = self.config(wire);
        let longest = wire.dims.iter().copied().max().map_or(0, usize::from);
        let every = cfg.every.saturating_mul(DRAFT_STRIDE).min(usize::from(u8::MAX));
        if every <= cfg.every || longest < 2 * every {
            return Ok(false);
        }
        let cfg = SceneConfig { every, ..cfg };
        let progress = feeding("contouring a draft", wire, &cfg)?;
        let (board, capacity) = scene::board_from(wire, &cfg, scene::HOST_START_POINTS, Some(&progress))?;
        let built = scene::scene_of(board.board(), wire, capacity, &cfg);
        self.draw(&built, t0);
        self.draft = Some(built);
        Ok(true)
    }

    /// Draw `built` (begun at `t0`) on the scope's screen if it draws: on
    /// a dark screen, as `render` draws it (one refresh), or over the last
    /// one, faded, as `render --animate` draws its frames. Its times are
    /// the frame's statistics.
    fn draw(&mut self, built: &Scene, t0: web_time::Instant) {
        let t1 = web_time::Instant::now();
        report("drawing the picture", 0, 0);
        if self.drawing {
            if !self.persistence {
                self.screen.clear();
            }
            scene::refresh(&mut self.screen, built, 1, None);
        }
        self.build_ms = (t1 - t0).as_secs_f64() * 1e3;
        self.draw_ms = t1.elapsed().as_secs_f64() * 1e3;
    }

    /// The settings changed: the frame and its draft are of the last.
    fn stale(&mut self) {
        self.scene = None;
        self.draft = None;
    }
}

/// The picture drawn in a worker of its own: a [`Scope`] that only builds
/// (`set_drawing(false)`) hands each frame's samples
/// ([`Scope::frame_samples`]) to a painter, which draws them as the scope
/// would have (the same [`Screen`], one band: `render`'s bytes), while
/// the scope builds the next frame.
#[wasm_bindgen]
pub struct Painter {
    screen: Screen,
    draw_ms: f64,
}

#[wasm_bindgen]
impl Painter {
    /// A painter of a `size` by `size` picture, dark.
    ///
    /// # Errors
    /// A size of 0 or above 2048.
    #[wasm_bindgen(constructor)]
    pub fn new(size: u32) -> Result<Painter, JsError> {
        Self::with_size(size).map_err(js)
    }

    /// A painter of band `band` of `bands` (rows split as `render` splits
    /// them on threads) of a `size` by `size` picture: several, in workers
    /// of their own, draw one picture from the same samples, each its
    /// rows ([`Painter::first_row`] on), `render`'s bytes together.
    ///
    /// # Errors
    /// A size of 0 or above 2048.
    pub fn band(size: u32, band: u32, bands: u32) -> Result<Painter, JsError> {
        Self::band_of(size, band, bands).map_err(js)
    }

    /// The first row of the picture this painter draws (0 for the whole).
    pub fn first_row(&self) -> u32 {
        self.screen.rows().start as u32
    }

    /// The rows this painter draws, as 8-bit RGB (what [`png_of`] takes,
    /// the bands' one after the other).
    pub fn rgb(&self) -> Vec<u8> {
        self.screen.to_rgb8()
    }

    /// Draw a frame of `samples` (`x, y, beam` a sample, as
    /// [`Scope::frame_samples`] gives them): on a dark screen if `clear`,
    /// else over the last frame, faded.
    ///
    /// # Errors
    /// A sample list whose length is not a multiple of 3.
    pub fn paint(&mut self, samples: &[u16], clear: bool) -> Result<(), JsError> {
        self.draw(samples, clear).map_err(js)
    }

    /// The picture (a band's rows), RGBA pixels, row by row from the top.
    pub fn pixels(&self) -> Vec<u8> {
        self.screen.to_rgba8()
    }

    /// The picture as `render` writes it: an 8-bit RGB PNG file.
    pub fn png(&self) -> Vec<u8> {
        self.screen.encode_png()
    }

    /// The picture's width and height in pixels.
    pub fn size(&self) -> u32 {
        self.screen.config().width
    }

    /// Milliseconds the last [`Painter::paint`] took.
    pub fn draw_ms(&self) -> f64 {
        self.draw_ms
    }
}

impl Painter {
    fn with_size(size: u32) -> Result<Self> {
        Ok(Self { screen: page_screen(size)?, draw_ms: 0.0 })
    }

    fn band_of(size: u32, band: u32, bands: u32) -> Result<Self> {
        let screen = Screen::band(page_config(size)?, band as usize, bands as usize)
            .context("invalid picture settings")?;
        Ok(Self { screen, draw_ms: 0.0 })
    }

    fn draw(&mut self, samples: &[u16], clear: bool) -> Result<()> {
        let t0 = web_time::Instant::now();
        let (triples, rest) = samples.as_chunks::<3>();
        if !rest.is_empty() {
            bail!("a frame's samples come in threes (x, y, beam), not {} numbers", samples.len());
        }
        let frame: Vec<Sample> = triples
            .iter()
            .map(|&[x, y, b]| Sample::new(x, y, if b == 0 { Beam::Off } else { Beam::On }))
            .collect();
        if clear {
            self.screen.clear();
        }
        self.screen.refresh(&frame);
        self.draw_ms = t0.elapsed().as_secs_f64() * 1e3;
        Ok(())
    }
}

/// The page's link to a board: the command line's sender ([`Sender`]),
/// driven by `web/serial.js` over Web Serial. Times are milliseconds on
/// one clock the caller keeps (the worker's `performance.now()`).
#[wasm_bindgen]
pub struct Link {
    sender: Sender,
    /// The port's line rate, for the report's efficiency.
    baud: u32,
}

/// A time in milliseconds as the sender's: negative, NaN and past a
/// million years are clamped (no panic on any number).
fn at(ms: f64) -> Duration {
    Duration::from_secs_f64(if ms.is_finite() { ms.clamp(0.0, 3.0e16) / 1e3 } else { 0.0 })
}

/// Milliseconds of a time of the sender's.
fn ms(t: Duration) -> f64 {
    t.as_secs_f64() * 1e3
}

#[wasm_bindgen]
impl Link {
    /// A link about to greet the board on a port opened at `baud` bit/s.
    #[wasm_bindgen(constructor)]
    pub fn new(now_ms: f64, baud: u32) -> Link {
        // The first command's sequence number: any, different from one
        // connection to the next.
        let seq0 = (at(now_ms).subsec_micros() as u16) ^ 0x5A5A;
        Link { sender: Sender::new(seq0, at(now_ms)), baud }
    }

    /// The bytes to write to the port now (none: empty).
    pub fn transmit(&mut self, now_ms: f64) -> Vec<u8> {
        let mut out = Vec::new();
        while let Some(bytes) = self.sender.transmit(at(now_ms)) {
            out.extend(bytes);
        }
        out
    }

    /// Bytes the port read.
    ///
    /// # Errors
    /// The board refused the transfer (the link has failed for good).
    pub fn receive(&mut self, bytes: &[u8], now_ms: f64) -> Result<(), JsError> {
        self.sender.receive(bytes, at(now_ms)).map_err(|e| JsError::new(&e.to_string()))
    }

    /// Wake the link at `now_ms` (at or after [`Link::deadline`]).
    ///
    /// # Errors
    /// The board gave no answer in time, too often.
    pub fn tick(&mut self, now_ms: f64) -> Result<(), JsError> {
        self.sender.on_time(at(now_ms)).map_err(|e| JsError::new(&e.to_string()))
    }

    /// The port closed.
    ///
    /// # Errors
    /// Unless the transfer was done.
    pub fn closed(&mut self, now_ms: f64) -> Result<(), JsError> {
        self.sender.closed(at(now_ms)).map_err(|e| JsError::new(&e.to_string()))
    }

    /// When to wake the link ([`Link::tick`]) if the board says nothing,
    /// in milliseconds; none when it waits for nothing.
    pub fn deadline(&self) -> Option<f64> {
        self.sender.deadline().map(ms)
    }

    /// Where the link is, as JSON: `state` (`greeting`, `connected`,
    /// `sending`, `picture`: waiting for the new picture, `done`,
    /// `failed`), `error`, `board` (what it takes: `firmware`,
    /// `slice_bytes`, `points`, `known`, the core's board of its
    /// capabilities, or null), `status` (its last status report: `state`,
    /// `points`, `refresh_hz`), `progress` (`frames_acked`, `frames`,
    /// `bytes_acked`, `bytes`, `retransmitted`, `timeouts`) and, once done,
    /// `report`, `send`'s `key=value` lines.
    pub fn state(&self) -> String {
        let mut o = Json::default();
        let (state, report) = match self.sender.state() {
            State::Greeting => ("greeting", None),
            State::Connected => ("connected", None),
            State::Sending => ("sending", None),
            State::Picture => ("picture", None),
            State::Done(r) => ("done", Some(r.report(self.baud))),
            State::Failed(_) => ("failed", None),
        };
        o.str("state", state);
        o.raw("error", &self.sender.error().map_or("null".into(), |e| quote(&e.to_string())));
        o.raw(
            "board",
            &self.sender.board().map_or("null".into(), |b| {
                let mut j = Json::default();
                j.str("firmware", &format!("{}.{}.{}", b.firmware[0], b.firmware[1], b.firmware[2]));
                j.raw("slice_bytes", &b.max_slice_samples.to_string());
                j.raw("points", &b.display_points.to_string());
                j.raw("known", &fit::known_board(b).map_or("null".into(), |k| quote(k.name)));
                j.end()
            }),
        );
        o.raw(
            "status",
            &self.sender.board_status().map_or("null".into(), |(state, points, centi_hz)| {
                let mut j = Json::default();
                j.str("state", &format!("{state:?}"));
                j.raw("points", &points.to_string());
                j.raw("refresh_hz", &format!("{:.2}", f64::from(centi_hz) / 100.0));
                j.end()
            }),
        );
        let SendProgress { frames_acked, frames, bytes_acked, bytes, retransmitted, timeouts } =
            self.sender.progress();
        let mut j = Json::default();
        for (k, v) in [
            ("frames_acked", frames_acked as u64),
            ("frames", frames as u64),
            ("bytes_acked", bytes_acked),
            ("bytes", bytes),
            ("retransmitted", retransmitted),
            ("timeouts", u64::from(timeouts)),
        ] {
            j.raw(k, &v.to_string());
        }
        o.raw("progress", &j.end());
        o.raw("report", &report.map_or("null".into(), |r| quote(&r)));
        o.end()
    }
}

/// Planes from `xy,xz,yz` (any of them, once each).
fn planes(axes: &str) -> Result<Vec<Plane>> {
    let mut out = Vec::new();
    for a in axes.split(',').map(str::trim).filter(|a| !a.is_empty()) {
        let p =
            Plane::from_name(a).with_context(|| format!("unknown plane `{a}` (expected xy, xz or yz)"))?;
        if !out.contains(&p) {
            out.push(p);
        }
    }
    if out.is_empty() {
        bail!("no slicing plane");
    }
    Ok(out)
}

/// A JSON object, built field by field.
#[derive(Default)]
struct Json(String);

impl Json {
    fn raw(&mut self, key: &str, value: &str) {
        self.0.push(if self.0.is_empty() { '{' } else { ',' });
        let _ = write!(self.0, "{}:{value}", quote(key));
    }

    fn str(&mut self, key: &str, value: &str) {
        self.raw(key, &quote(value));
    }

    fn end(mut self) -> String {
        if self.0.is_empty() {
            self.0.push('{');
        }
        self.0.push('}');
        self.0
    }
}

/// A JSON string.
fn quote(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 2);
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            c if u32::from(c) < 0x20 => {
                let _ = write!(out, "\\u{:04x}", u32::from(c));
            }
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

/// A JSON number (`null` for NaN or infinity, which JSON lacks).
fn num(x: f32) -> String {
    if x.is_finite() { format!("{x}") } else { "null".into() }
}

/// A JSON array of values already in JSON.
fn list(items: impl Iterator<Item = String>) -> String {
    format!("[{}]", items.collect::<Vec<_>>().join(","))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_page_draws_what_render_draws() {
        let mut s = Scope::with_size(64).unwrap();
        s.demo("hydrogen:16").unwrap();
        s.redraw().unwrap();
        let vol = LoadedVolume::demo("hydrogen:16".parse().unwrap()).unwrap();
        let cfg = SceneConfig { levels: vec![0.1], ..SceneConfig::default() };
        let want = scene::build(&WireVolume::from_loaded(&vol).unwrap(), &cfg).unwrap();
        assert_eq!(s.scene.as_ref().unwrap().samples, want.samples);
        assert_eq!(s.pixels().len(), 64 * 64 * 4);
        assert!(s.stats().contains("\"points\":"));
    }

    #[test]
    fn with_persistence_a_turn_is_drawn_over_the_last_frame_faded() {
        let mut s = Scope::with_size(64).unwrap();
        s.demo("torus:12").unwrap();
        s.set_persistence(true);
        s.redraw().unwrap();
        let a = s.scene.clone().unwrap();
        s.set_view(60.0, 10.0, DEFAULT_ZOOM);
        assert!(s.update().unwrap(), "a turn draws a new frame");
        let b = s.scene.clone().unwrap();
        assert_ne!(a.samples, b.samples);
        // `render --animate`'s frames: the last one decays, the new one
        // is deposited over it.
        let mut want = Screen::new(PhosphorConfig::with_size(64, 64), 1).unwrap();
        scene::refresh(&mut want, &a, 1, None);
        scene::refresh(&mut want, &b, 1, None);
        assert!(s.pixels() == want.to_rgba8(), "the turn over the last frame, faded");
        // Off: redrawn at once, on a dark screen, as `render` draws it.
        s.set_persistence(false);
        assert!(s.update().unwrap());
        let alone = scene::render(&b, PhosphorConfig::with_size(64, 64), 1, None).unwrap();
        assert!(s.pixels() == alone.to_rgba8() && alone.to_rgba8() != want.to_rgba8());
    }

    #[test]
    fn a_painter_draws_what_the_scope_draws() {
        // A scope that only builds, and a painter given its samples, against
        // a scope that draws: the same pixels and PNG, frame after frame,
        // persistence on (a turn over the last frame) and off.
        let mut drawing = Scope::with_size(64).unwrap();
        let mut building = Scope::with_size(64).unwrap();
        building.set_drawing(false);
        let mut painter = Painter::with_size(64).unwrap();
        for s in [&mut drawing, &mut building] {
            s.demo("torus:12").unwrap();
        }
        for (yaw, persistence) in [(30.0, false), (60.0, true), (90.0, true), (120.0, false)] {
            for s in [&mut drawing, &mut building] {
                s.set_view(yaw, 20.0, DEFAULT_ZOOM);
                s.set_persistence(persistence);
                assert!(s.update().unwrap());
            }
            let samples = building.frame_samples();
            assert_eq!(samples.len(), 3 * drawing.scene.as_ref().unwrap().samples.len());
            painter.draw(&samples, building.clears()).unwrap();
            assert!(painter.pixels() == drawing.pixels(), "yaw {yaw}, persistence {persistence}");
            assert_eq!(painter.png(), drawing.png_bytes().unwrap());
        }
        assert!(
            building.pixels() == Scope::with_size(64).unwrap().pixels(),
            "a scope that only builds stays dark"
        );
        assert!(building.png_bytes().is_err(), "a scope that does not draw has no PNG of its own");
        assert!(painter.draw(&[1, 2], true).is_err(), "samples come in threes");
        assert!(Painter::with_size(0).is_err());
    }

    #[test]
    fn band_painters_draw_the_painters_picture_together() {
        // Three painters of a band each (64 rows: 21, 21, 22), given the
        // same samples: their rows one after the other are the whole
        // painter's pixels, and their RGB as a PNG its PNG, frame after
        // frame, persistence on and off.
        let mut building = Scope::with_size(64).unwrap();
        building.set_drawing(false);
        building.demo("torus:12").unwrap();
        let mut whole = Painter::with_size(64).unwrap();
        let mut bands: Vec<Painter> = (0..3).map(|k| Painter::band_of(64, k, 3).unwrap()).collect();
        assert_eq!(bands.iter().map(Painter::first_row).collect::<Vec<_>>(), [0, 21, 42]);
        for (yaw, persistence) in [(30.0, false), (60.0, true), (90.0, true), (120.0, false)] {
            building.set_view(yaw, 20.0, DEFAULT_ZOOM);
            building.set_persistence(persistence);
            assert!(building.update().unwrap());
            let samples = building.frame_samples();
            whole.draw(&samples, building.clears()).unwrap();
            for b in &mut bands {
                b.draw(&samples, building.clears()).unwrap();
            }
            let pixels: Vec<u8> = bands.iter().flat_map(Painter::pixels).collect();
            assert!(pixels == whole.pixels(), "yaw {yaw}, persistence {persistence}");
            let rgb: Vec<u8> = bands.iter().flat_map(Painter::rgb).collect();
            assert_eq!(png_bytes_of(64, &rgb).unwrap(), whole.png());
        }
        assert!(whole.pixels().iter().any(|&v| v > 0 && v < 255), "a picture, not a dark screen");
        assert!(png_bytes_of(64, &[0; 5]).is_err(), "not 64 * 64 * 3 bytes");
        assert!(Painter::band_of(0, 0, 2).is_err());
        assert_eq!(Painter::band_of(64, 9, 2).unwrap().first_row(), 32, "past the last band: the last");
    }

    #[test]
    fn the_exports_are_the_command_lines_files() {
        let mut s = Scope::with_size(64).unwrap();
        s.demo("torus:12").unwrap();
        assert!(s.png_bytes().is_err() && s.svg_bytes().is_err() && s.wav_bytes().is_err(), "no frame yet");
        s.redraw().unwrap();
        let spec: DemoSpec = "torus:12".parse().unwrap();
        let vol = WireVolume::from_loaded(&LoadedVolume::demo(spec).unwrap()).unwrap();
        let cfg = SceneConfig { levels: vec![spec.demo.default_level()], ..SceneConfig::default() };
        let want = scene::build(&vol, &cfg).unwrap();
        let screen = scene::render(&want, PhosphorConfig::with_size(64, 64), 1, None).unwrap();
        assert_eq!(s.png_bytes().unwrap(), screen.encode_png());
        let mut svg = Vec::new();
        isoscope_sim::svg::write_svg(&mut svg, &want.commands, 12).unwrap();
        assert_eq!(s.svg_bytes().unwrap(), svg);
        let audio = scene::build(&vol, &SceneConfig { beam: audio_beam(48_000, 12), ..cfg }).unwrap();
        let mut wav = std::io::Cursor::new(Vec::new());
        write_wav(&mut wav, &audio.samples, &WavConfig::default()).unwrap();
        assert_eq!(s.wav_bytes().unwrap(), wav.into_inner());
        // The sound card's frame is the same one (the scene's commands do
        // not depend on the beam), as channels.
        assert_eq!(s.audio(48_000).expect("a frame"), audio_channels(&audio.samples, 12, false));
        assert_eq!(s.audio_step(), audio_beam(48_000, 12).lit_step);
        // A change of settings not drawn yet: nothing to export.
        s.set_levels(vec![0.5]);
        assert!(s.png_bytes().is_err());
    }

    #[test]
    fn a_turn_draws_what_render_draws_from_the_size_that_fit() {
        // gyroid:32 needs 262,144 points, four times the host's start.
        let mut s = Scope::with_size(64).unwrap();
        s.demo("gyroid:32").unwrap();
        s.redraw().unwrap();
        assert_eq!(s.fit.as_ref().unwrap().1, 4 * scene::HOST_START_POINTS);
        s.set_view(75.0, -20.0, 0.8);
        s.redraw().unwrap();
        let vol =
            WireVolume::from_loaded(&LoadedVolume::demo("gyroid:32".parse().unwrap()).unwrap()).unwrap();
        let cfg = s.config(s.wire().unwrap());
        assert_eq!(s.scene.as_ref().unwrap().samples, scene::build(&vol, &cfg).unwrap().samples);
        // Other levels start from the size the last one needed, and draw
        // render's frame whether it fits (0.1) or not (1.4: the first size
        // holds it, and it is contoured again from there).
        for level in [0.1, 1.4, 0.0] {
            s.set_levels(vec![level]);
            assert_ne!(s.fit.as_ref().unwrap().0, s.fit_key());
            s.redraw().unwrap();
            let cfg = s.config(s.wire().unwrap());
            let want = scene::build(&vol, &cfg).unwrap();
            assert_eq!(s.scene.as_ref().unwrap().samples, want.samples, "level {level}");
            assert_eq!(s.fit.as_ref().unwrap().1, want.capacity.points, "level {level}");
        }
    }

    /// A draft is `render --every` four times the stride's frame, drawn
    /// and handed out until the frame itself is built, which is the same
    /// as without a draft; one a change of settings, none where it cannot
    /// be coarser, on the board preset, or while the view turns.
    #[test]
    fn a_draft_is_renders_frame_at_four_times_the_stride() {
        let vol =
            WireVolume::from_loaded(&LoadedVolume::demo("gyroid:32".parse().unwrap()).unwrap()).unwrap();
        let mut s = Scope::with_size(64).unwrap();
        s.demo("gyroid:32").unwrap();
        s.redraw().unwrap();
        assert!(!s.draft().unwrap(), "the frame of these settings is drawn: no draft");
        let plain = Scope::with_size(64).map(|mut p| {
            p.demo("gyroid:32").unwrap();
            p.set_every(2);
            p.set_levels(vec![0.3]);
            p.redraw().unwrap();
            p
        });
        let plain = plain.unwrap();
        s.set_every(2);
        s.set_levels(vec![0.3]);
        assert!(s.stats() == "null" && s.frame_samples().is_empty(), "nothing of the old settings");
        assert!(s.draft().unwrap());
        let cfg = SceneConfig { every: 8, ..s.config(s.wire().unwrap()) };
        let want = scene::build(&vol, &cfg).unwrap();
        let draft = s.draft.as_ref().unwrap();
        assert_eq!(draft.samples, want.samples);
        assert_eq!(s.frame_samples().len(), 3 * want.samples.len());
        let drawn = scene::render(&want, PhosphorConfig::with_size(64, 64), 1, None).unwrap();
        assert!(s.pixels() == drawn.to_rgba8(), "the draft is drawn as render draws it");
        assert!(s.stats().contains("\"draft\":true") && s.stats().contains("\"every\":8"));
        assert!(s.png_bytes().is_err() && s.samples_text().is_empty(), "no export of a draft");
        assert!(!s.draft().unwrap(), "one draft a change");
        // The frame, as without the draft.
        assert!(s.update().unwrap());
        assert!(s.draft.is_none() && s.stats().contains("\"draft\":false"));
        assert_eq!(s.scene.as_ref().unwrap().samples, plain.scene.as_ref().unwrap().samples);
        assert_eq!(s.fit, plain.fit);
        assert!(s.pixels() == plain.pixels());
        // No stride four times as coarse keeps two slices of 32.
        s.set_every(5);
        assert!(!s.draft().unwrap());
        s.set_every(0);
        s.set_board("f407").unwrap();
        assert!(!s.draft().unwrap(), "the board preset fits the volume to the stride");
        s.set_board("").unwrap();
        s.set_turning(true);
        assert!(!s.draft().unwrap(), "a turn's frames come from the board, at once");
        s.set_turning(false);
        assert!(s.draft().unwrap());
    }

    /// While the view turns, a frame is the board's picture turned with
    /// `SetView` (the board loaded once, at the turn's first view), as
    /// `render --animate` turns it; when the turn stops, the still is
    /// `render`'s again. A change of level during a turn loads anew.
    #[test]
    fn a_turning_view_turns_the_boards_picture_and_stops_on_renders() {
        let mut s = Scope::with_size(64).unwrap();
        s.demo("torus:24").unwrap();
        s.set_turning(true);
        s.redraw().unwrap();
        let vol = s.wire().unwrap().clone();
        let first = s.config(&vol);
        assert_eq!(s.scene.as_ref().unwrap().samples, scene::build(&vol, &first).unwrap().samples);
        // The board a turn starts from, turned as the page turns.
        let (mut board, _) = scene::board_from(&vol, &first, scene::HOST_START_POINTS, None).unwrap();
        let mut turned_apart = false;
        for (k, yaw) in [40.0f32, 80.0, 120.0].into_iter().enumerate() {
            s.set_view(yaw, View::DEFAULT.pitch, DEFAULT_ZOOM);
            s.redraw().unwrap();
            let cfg = s.config(&vol);
            board.with(|b| b.set_view(&cfg.view)).unwrap();
            let want = scene::scene_of(board.board(), &vol, s.scene.as_ref().unwrap().capacity, &cfg);
            assert_eq!(s.scene.as_ref().unwrap().samples, want.samples, "frame {k} of the turn");
            turned_apart |= want.samples != scene::build(&vol, &cfg).unwrap().samples;
        }
        // (Else the test would not tell a turned frame from a built one.)
        assert!(turned_apart, "every turned frame is also render's");
        // The turn stops: render's still at the last view.
        s.set_turning(false);
        assert!(s.scene.is_none(), "a stopped turn is built again");
        s.redraw().unwrap();
        let cfg = s.config(&vol);
        assert_eq!(s.scene.as_ref().unwrap().samples, scene::build(&vol, &cfg).unwrap().samples);
        // A level changed while turning is loaded anew.
        s.set_turning(true);
        s.redraw().unwrap();
        s.set_levels(vec![0.3]);
        s.redraw().unwrap();
        let cfg = s.config(&vol);
        assert_eq!(s.scene.as_ref().unwrap().samples, scene::build(&vol, &cfg).unwrap().samples);
    }

    /// With the board preset, the page fits the volume to the board's
    /// picture as `render --board` does (gyroid:48: every 32nd slice whole,
    /// downsampled by 4 every 2nd), and says so among its remarks.
    #[test]
    fn the_board_preset_fits_the_volume_as_render_does() {
        let mut s = Scope::with_size(64).unwrap();
        s.demo("gyroid:48").unwrap();
        s.set_board("f407").unwrap();
        s.redraw().unwrap();
        let loaded = LoadedVolume::demo("gyroid:48".parse().unwrap()).unwrap();
        let board = Board::named("f407").unwrap();
        let cfg = SceneConfig { planes: s.planes.clone(), ..SceneConfig::board(board, s.levels.clone()) };
        let fitted = fit::fit_to_board_picture(
            loaded,
            &FitOptions::default(),
            &Limits::of_board(&board),
            &cfg,
            scene::auto_every,
        )
        .unwrap();
        assert_eq!(fitted.volume.dims, Dims(12, 12, 12));
        let wire = WireVolume::from_loaded(&fitted.volume).unwrap();
        let want = scene::build(&wire, &s.config(&wire)).unwrap();
        assert_eq!(s.scene.as_ref().unwrap().samples, want.samples);
        assert!(s.stats().contains("downsampled by 4"), "{}", s.stats());
        // Back on the host: the volume as read.
        s.set_board("host").unwrap();
        s.redraw().unwrap();
        assert_eq!(s.wire().unwrap().dims, [48, 48, 48]);
    }

    #[test]
    fn bad_input_is_an_error_not_a_panic() {
        let mut s = Scope::with_size(32).unwrap();
        assert!(s.file("x.nrrd", b"NRRD0004\ntype: float\n").is_err());
        assert!(s.file("x.bin", &[1, 2, 3]).unwrap_err().to_string().contains("not a volume file"));
        assert!(s.file("x.nii.gz", &[0x1f, 0x8b, 0, 0]).is_err());
        assert!(s.demo("nothing:3").is_err());
        assert!(s.redraw().is_err());
        s.demo("sphere:8").unwrap();
        s.set_levels(vec![]);
        assert!(s.redraw().is_err());
        s.set_levels(vec![f32::NAN]);
        assert!(s.redraw().is_err());
        assert!(planes("xy,ab").is_err());
        assert!(Scope::with_size(0).is_err());
    }

    /// The page's link, driven as serial.js drives it (bytes in, bytes
    /// out, woken at its deadline), puts the page's volume on a board in
    /// process, with the page's level, and says so in its state.
    #[test]
    fn the_link_sends_the_pages_volume_to_a_board() {
        use isoscope_core::engine::{Engine, EngineConfig};
        use isoscope_sim::board::{HostBuffers, host_capacity};
        let mut s = Scope::with_size(32).unwrap();
        s.demo("hydrogen:12").unwrap();
        s.set_levels(vec![0.05]);
        let mut link = Link::new(1000.0, 921_600);
        assert!(s.send_plan(&mut link, 0.0, 1000.0).is_err(), "sent before the board said hello");
        let mut mem = HostBuffers::new(&host_capacity(12 * 12 * 4, 16, 20_000));
        let mut board = Engine::new(EngineConfig::default(), mem.buffers()).unwrap();
        let mut sent = None;
        for t in 1000..60_000u32 {
            let now = f64::from(t);
            if link.state().contains("\"state\":\"connected\"") && sent.is_none() {
                sent = Some(s.send_plan(&mut link, 0.0, now).unwrap());
            }
            board.feed(&link.transmit(now), t);
            board.update(t);
            let mut out = [0u8; 4096];
            let n = board.transmit(&mut out);
            link.sender.receive(&out[..n], at(now)).unwrap();
            link.sender.on_time(at(now)).unwrap();
            if link.state().contains("\"state\":\"done\"") {
                break;
            }
        }
        let state = link.state();
        assert!(state.contains("\"state\":\"done\"") && state.contains("board_state=Showing"), "{state}");
        assert!(state.contains("\"bytes_acked\":6912,\"bytes\":6912"), "{state}");
        assert_eq!(
            sent.unwrap(),
            "{\"dims\":[12,12,12],\"dtype\":\"F32\",\"every\":1,\"levels\":[0.05],\"notes\":[]}"
        );
        assert!(board.surface().is_some());
        assert_eq!(at(f64::NAN), Duration::ZERO);
        assert_eq!(at(-5.0), Duration::ZERO);
        assert!(at(f64::MAX) > Duration::from_secs(1 << 40));
    }

    #[test]
    fn json_is_escaped() {
        assert_eq!(quote("a\"b\\\n"), "\"a\\\"b\\\\\\u000a\"");
        let mut o = Json::default();
        o.raw("n", &num(f32::NAN));
        assert_eq!(o.end(), "{\"n\":null}");
    }
}
