//! A frame on the host, exactly as a board draws it: the volume goes to an
//! in-process board ([`crate::board::InProcess`]) as the frames `send`
//! puts on the wire; the board's engine contours, culls, stitches, merges,
//! splices and orders it in its bounded memory, and its frame
//! ([`isoscope_core::engine::Engine::frame`]) is the samples the firmware
//! plays. There is no other picture pipeline on the host.
//!
//! With [`Memory::Board`] the engine gets that board's capacities (a
//! surface that does not fit is cut as on the board, and said); with
//! [`Memory::Host`] it gets room for the whole surface (it grows until the
//! surface fits): the same code, more memory.

use crate::board::{InProcess, Loaded, OwnedBoard, Refused, check_levels, host_capacity};
use crate::link::{SendConfig, WireVolume};
use crate::progress::Progress;
use anyhow::{Context, Result, bail};
use isoscope_core::beam::replay::{Kept, Replay};
use isoscope_core::beam::{BeamConfig, FrameStats};
use isoscope_core::command::Command;
use isoscope_core::contour::grid::Plane;
use isoscope_core::engine::{Board, Capacity, ChainStats, EngineConfig};
use isoscope_core::output::{Sample, SampleSource};
use isoscope_core::path::Geometry;
use isoscope_core::view::{ScreenPoint, View};
use isoscope_core::wire::{AXIS_X, AXIS_Y, AXIS_Z, MAX_CHUNK, NackCode};

/// How much memory the engine gets.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Memory {
    /// Room for the whole surface (grown until it fits).
    #[default]
    Host,
    /// A board's capacities: what it would show, cut where it is cut.
    Board(Board),
}

/// What to put on the screen.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneConfig {
    /// Slicing planes.
    pub planes: Vec<Plane>,
    /// Contour levels (at most [`isoscope_core::wire::MAX_LEVELS`]).
    pub levels: Vec<f32>,
    /// Contour every `every`-th slice of each plane (1 = all, at most 255).
    pub every: usize,
    /// The 3D view (its spacing is the volume's; its bits are the beam's).
    pub view: View,
    /// The beam.
    pub beam: BeamConfig,
    /// DAC samples per second, for the refresh rate.
    pub sample_rate_hz: u32,
    /// How much memory the engine gets.
    pub memory: Memory,
}

impl Default for SceneConfig {
    fn default() -> Self {
        let e = EngineConfig::default();
        Self {
            planes: Plane::ALL.to_vec(),
            levels: vec![],
            every: 1,
            view: e.view,
            beam: e.beam,
            sample_rate_hz: e.sample_rate_hz,
            memory: Memory::Host,
        }
    }
}

impl SceneConfig {
    /// The settings of `board` (its sample clock, the engine's view and
    /// beam), its capacities, and `levels`.
    pub fn board(board: Board, levels: Vec<f32>) -> Self {
        let e = board.engine_config();
        Self {
            levels,
            view: e.view,
            beam: e.beam,
            sample_rate_hz: e.sample_rate_hz,
            memory: Memory::Board(board),
            ..Self::default()
        }
    }

    /// The engine's settings.
    pub fn engine(&self) -> EngineConfig {
        EngineConfig {
            view: self.view,
            beam: self.beam,
            sample_rate_hz: self.sample_rate_hz,
            ..EngineConfig::default()
        }
    }

    /// How the volume goes to the board: levels, planes, stride.
    ///
    /// # Errors
    /// No level or more than a board takes, a stride of 0 or above 255, or
    /// no plane.
    pub fn send(&self) -> Result<SendConfig> {
        check_levels(&self.levels)?;
        if self.planes.is_empty() {
            bail!("no slicing plane");
        }
        let every = match u8::try_from(self.every) {
            Ok(0) => bail!("the slice stride must be at least 1"),
            Ok(n) => n,
            Err(_) => bail!("the slice stride is {}; a board takes at most 255", self.every),
        };
        Ok(SendConfig {
            levels: self.levels.clone(),
            axes: axes(&self.planes),
            every,
            chunk: MAX_CHUNK,
            ..SendConfig::default()
        })
    }
}

/// The wire's axis bits of `planes` (a plane is named by the axis it is
/// normal to).
pub fn axes(planes: &[Plane]) -> u8 {
    planes.iter().fold(0u8, |m, p| {
        m | match p {
            Plane::XY => AXIS_Z,
            Plane::XZ => AXIS_Y,
            Plane::YZ => AXIS_X,
        }
    })
}

/// Points a host surface starts with; it grows four-fold until the surface
/// fits, up to [`HOST_MAX_POINTS`].
pub const HOST_START_POINTS: usize = 1 << 16;
/// The most points a host surface grows to (16.7M: 210 MB of surfaces).
pub const HOST_MAX_POINTS: usize = 1 << 24;
/// How many times larger each size of a growing host memory is than the
/// last: [`board_from`] grows by it, and [`board_near`] asks whether the
/// size it divides down to would have held a surface.
const HOST_GROWTH: usize = 4;

/// A frame as the board plays it, and what it took.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    /// One frame's DAC samples, from the park position back to it, as the
    /// board plays them over and over.
    pub samples: Vec<Sample>,
    /// The picture's drawing commands on the screen, in drawing order.
    pub commands: Vec<Command<ScreenPoint>>,
    /// The frame's statistics.
    pub frame: FrameStats,
    /// What culling, stitching, merging and ordering did.
    pub chain: ChainStats,
    /// What the board kept of the volume.
    pub loaded: Loaded,
    /// Polylines drawn (loops and dots included).
    pub polylines: usize,
    /// Points drawn.
    pub points: usize,
    /// The engine's memory.
    pub capacity: Capacity,
    /// Which board's memory, if one's.
    pub board: Option<Board>,
    /// DAC samples per second.
    pub sample_rate_hz: u32,
    /// Seconds: the transfer (decoding and contouring, slice by slice), and
    /// the commit (stitch, order, count a frame).
    pub seconds: [f64; 2],
    /// Bytes of the frame recorded for replay ([`isoscope_core::beam::replay`]):
    /// what a board keeps of a still picture to play it at full rate.
    pub replay_bytes: usize,
    /// The contour levels asked for.
    pub levels: Vec<f32>,
    /// The slicing planes asked for.
    pub planes: Vec<Plane>,
    /// The volume's extents.
    pub dims: [u16; 3],
    /// For a picture with nothing drawn: the volume's values and the
    /// levels `info` suggests ([`crate::info::summarize`]), to say why and
    /// what to draw instead (`None` when something is drawn).
    pub values: Option<crate::info::Summary>,
}

/// The memory to start with for `vol` under `memory`: on the host, the
/// largest size it grows through ([`HOST_START_POINTS`] times a power of
/// four) of at most `points` points, and at least the first.
fn first_capacity(vol: &WireVolume, memory: Memory, points: usize) -> Capacity {
    match memory {
        Memory::Board(b) => b.capacity,
        Memory::Host => {
            let extent = usize::from(vol.dims[0].max(vol.dims[1])).max(2);
            let mut start = HOST_START_POINTS;
            while start * HOST_GROWTH <= points.min(HOST_MAX_POINTS) {
                start *= HOST_GROWTH;
            }
            host_capacity(vol.slice_bytes().max(64), extent, start)
        }
    }
}

/// Put `vol` on an in-process board with `cfg`'s memory and settings, and
/// hand it to `f`. With [`Memory::Host`] the memory grows until the whole
/// surface fits: a size the surface outgrows is given up as soon as the
/// engine says so ([`isoscope_core::engine::Engine::outgrown`]), and the volume sent again
/// to one four times larger. `progress` counts the frames
/// fed ([`crate::board::frames_for`]).
///
/// # Errors
/// Invalid settings, a volume the board refuses, or `f`'s error.
pub fn with_board<R>(
    vol: &WireVolume,
    cfg: &SceneConfig,
    progress: Option<&Progress>,
    f: impl FnOnce(&mut InProcess<'_>, Capacity) -> Result<R>,
) -> Result<R> {
    with_board_from(vol, cfg, HOST_START_POINTS, progress, f)
}

/// As [`with_board`], with the host's memory starting at `points` points
/// (rounded down to a size it grows through: [`HOST_START_POINTS`] times a
/// power of four, at most [`HOST_MAX_POINTS`]) rather than at the first.
///
/// Give it the [`Scene::capacity`] a frame of the same volume, levels,
/// planes, stride and beam's bits needed at another view, and the surface
/// is contoured once rather than again at each size on the way: a view
/// that turns a large surface saves the passes that did not fit. The frame
/// is [`with_board`]'s then, because whether a surface fits does not
/// depend on the view (its pieces are culled, stitched, merged and ordered
/// in space, with the merge tolerance of the bounding sphere's fit, the
/// same from every side), so [`with_board`] would grow to that size too,
/// and a board of one size draws one picture. (Not so after a change of
/// levels, planes or stride: a surface that fits a smaller size may be
/// drawn differently in a larger one, whose order pass has more scratch.) With
/// a board's memory `points` is not used.
///
/// # Errors
/// As [`with_board`].
pub fn with_board_from<R>(
    vol: &WireVolume,
    cfg: &SceneConfig,
    points: usize,
    progress: Option<&Progress>,
    f: impl FnOnce(&mut InProcess<'_>, Capacity) -> Result<R>,
) -> Result<R> {
    let (mut board, capacity) = board_from(vol, cfg, points, progress)?;
    board.with(|board| f(board, capacity))
}

/// The board [`with_board_from`] hands its function, to keep, and its
/// memory's size.
///
/// # Errors
/// As [`with_board`], but for `f`'s.
pub fn board_from(
    vol: &WireVolume,
    cfg: &SceneConfig,
    points: usize,
    progress: Option<&Progress>,
) -> Result<(OwnedBoard, Capacity)> {
    let send = cfg.send()?;
    cfg.beam.validate().context("invalid beam settings")?;
    let mut capacity = first_capacity(vol, cfg.memory, points);
    loop {
        let mut board = OwnedBoard::new(&capacity, cfg.engine())?;
        // A memory that can grow gives up on a surface as soon as it has
        // outgrown it: the picture is the larger memory's either way.
        let can_grow = cfg.memory == Memory::Host && capacity.points < HOST_MAX_POINTS;
        let whole = match board.with(|b| b.load_or_give_up(vol, &send, progress, can_grow)) {
            Ok(loaded) => loaded.is_some_and(|l| l.whole()),
            Err(e) if e.downcast_ref::<Refused>() == Some(&Refused(NackCode::DimsOverCapacity)) => bail!(
                "a {}x{} slice of {:?} is {} bytes; {} holds {} (send a smaller or resampled volume)",
                vol.dims[0],
                vol.dims[1],
                vol.sample_type,
                vol.slice_bytes(),
                match cfg.memory {
                    Memory::Board(b) => format!("the {} board", b.name),
                    Memory::Host => "the host's memory".into(),
                },
                capacity.slice_bytes
            ),
            Err(e) => return Err(e.context("putting the volume on the board")),
        };
        if can_grow && !whole {
            capacity = host_capacity(capacity.slice_bytes, capacity.extent, capacity.points * HOST_GROWTH);
            // The volume is fed again from its first frame.
            if let Some(p) = progress {
                p.restart();
            }
            continue;
        }
        return Ok((board, capacity));
    }
}

/// The board [`with_board`] builds, to keep, and its memory's size, with
/// the host's memory started at `points`, the size a frame of another
/// surface of the volume needed (another level, planes or stride): a
/// slider moved from one level to the next contours a large surface once
/// at the size the last one needed, rather than again at each size on the
/// way.
///
/// The frame is [`with_board`]'s all the same (its samples, byte for
/// byte). [`with_board`] keeps the first size that holds the surface whole,
/// and a surface may be drawn otherwise in a larger memory (its order pass
/// has more scratch). So a start that holds the surface whole is kept only
/// when the surface has more points than the size below it has room for,
/// in its surface and its whole slice memory (then that size would have
/// thinned or dropped some, and [`with_board`] grown past it); else the
/// volume is contoured again from the first size. A start too small grows
/// as [`with_board`] does from there: it could not have held the surface
/// at any smaller size either. With a board's memory `points` is not used.
///
/// # Errors
/// As [`board_from`].
pub fn board_near(
    vol: &WireVolume,
    cfg: &SceneConfig,
    points: usize,
    progress: Option<&Progress>,
) -> Result<(OwnedBoard, Capacity)> {
    let start = first_capacity(vol, cfg.memory, points);
    let (board, capacity) = board_from(vol, cfg, points, progress)?;
    let first = first_capacity(vol, cfg.memory, HOST_START_POINTS);
    if cfg.memory != Memory::Host || capacity != start || capacity == first {
        return Ok((board, capacity));
    }
    // What the size below holds at most: its surface, and its two slices'
    // memory given over to the spill.
    let room = capacity.points / HOST_GROWTH + Geometry::points_in(2 * capacity.slice_bytes);
    if board.board().loaded().commands as usize > room {
        return Ok((board, capacity));
    }
    drop(board);
    if let Some(p) = progress {
        p.restart();
    }
    board_from(vol, cfg, HOST_START_POINTS, progress)
}

/// Build the frame of `vol` as `cfg` says.
///
/// # Errors
/// As [`with_board`].
pub fn build(vol: &WireVolume, cfg: &SceneConfig) -> Result<Scene> {
    with_board(vol, cfg, None, |board, capacity| Ok(scene_of(board, vol, capacity, cfg)))
}

/// The scene the board shows now, of `vol` put on it with `cfg`.
pub fn scene_of(board: &InProcess<'_>, vol: &WireVolume, capacity: Capacity, cfg: &SceneConfig) -> Scene {
    let engine = board.engine();
    let mut frame = engine.frame();
    let (samples, replay_bytes) = recorded(&mut frame, engine.frame_stats().samples);
    let replay_bytes = replay_bytes.unwrap_or_else(|| self::replay_bytes(engine.frame(), samples.len()));
    let surface = engine.surface();
    let frame = frame.stats();
    // Only an empty picture needs the values (a pass over the volume).
    let values = (frame.lit_samples == 0).then(|| values(vol)).flatten();
    Scene {
        samples,
        commands: engine.commands().collect(),
        frame,
        chain: engine.chain_stats(),
        loaded: board.loaded(),
        polylines: surface.map_or(0, |s| s.polylines()),
        points: surface.map_or(0, |s| s.len()),
        capacity,
        board: match cfg.memory {
            Memory::Board(b) => Some(b),
            Memory::Host => None,
        },
        sample_rate_hz: cfg.sample_rate_hz,
        seconds: board.loaded().seconds,
        replay_bytes,
        levels: cfg.levels.clone(),
        planes: cfg.planes.clone(),
        dims: vol.dims,
        values,
    }
}

/// `vol`'s summary as `info` gives it, over the bins whose first suggested
/// level a file is drawn at when none is given.
fn values(vol: &WireVolume) -> Option<crate::info::Summary> {
    use crate::volume::{Dims, Dtype, LoadedVolume};
    use isoscope_core::wire::SampleType;
    let [nx, ny, nz] = vol.dims.map(usize::from);
    let dtype = match vol.sample_type {
        SampleType::U8 => Dtype::U8,
        SampleType::U16 => Dtype::U16,
        SampleType::I16 => Dtype::I16,
        SampleType::F32 => Dtype::F32,
    };
    let loaded = LoadedVolume::from_bytes(&vol.bytes, Dims(nx, ny, nz), dtype).ok()?;
    Some(crate::info::summarize(&loaded, crate::info::LEVEL_BINS))
}

/// The samples of `frame` and the bytes a board's replay of it takes, in
/// one pass of the schedule (not one for the samples and one for the
/// recording), with memory for the `counted` samples the engine counted
/// the picture's frame at: no bytes if it had more (a count of another
/// frame), to be worked out apart.
fn recorded(frame: &mut impl SampleSource, counted: u64) -> (Vec<Sample>, Option<usize>) {
    // No count to size the memory by: none, and nothing is recorded.
    let counted = usize::try_from(counted).ok().filter(|&n| n < usize::MAX / 16);
    let mut samples = Vec::with_capacity(counted.unwrap_or(0));
    let mut mem = vec![0u8; counted.map_or(0, replay_memory)];
    let mut kept = Kept::new();
    let mut replay = Replay::new(&mut mem, &mut kept);
    let Some(mut rec) = replay.record(0) else {
        frame.fill_with(usize::MAX, |s| samples.push(s));
        return (samples, None);
    };
    rec.fill_with(frame, usize::MAX, |s| samples.push(s));
    rec.finish(FrameStats::default());
    let fits = counted.is_some_and(|n| samples.len() <= n);
    (samples, fits.then(|| replay.len()))
}

/// Memory enough to record a frame of `samples` samples: a repeat run,
/// the longest a sample takes, is 8 bytes.
fn replay_memory(samples: usize) -> usize {
    8 * samples + 8
}

/// Bytes a board's replay of `frame` (of `samples` samples) takes, as the
/// core records it.
fn replay_bytes(mut frame: impl SampleSource, samples: usize) -> usize {
    let mut mem = vec![0u8; replay_memory(samples)];
    let mut kept = Kept::new();
    let mut replay = Replay::new(&mut mem, &mut kept);
    let Some(mut rec) = replay.record(0) else { return 0 };
    rec.fill_with(&mut frame, usize::MAX, |_| {});
    rec.finish(FrameStats::default());
    replay.len()
}

impl Scene {
    /// Blanked travel as a share of lit length.
    pub fn blank_ratio(&self) -> f32 {
        self.frame.blank_length / self.frame.lit_length.max(f32::MIN_POSITIVE)
    }

    /// Refreshes per second at the sample rate.
    pub fn fps(&self) -> f32 {
        self.frame.fps(self.sample_rate_hz as f32)
    }

    /// A `note:` line when the board's memory cut the picture short, and a
    /// warning when nothing is drawn or the frame refreshes below
    /// [`FLICKER_HZ`].
    pub fn remarks(&self) -> Vec<String> {
        let mut out = Vec::new();
        let l = &self.loaded;
        if !l.whole() {
            let holder = match self.board {
                Some(b) => format!("the {} board", b.name),
                None => "the host's memory".into(),
            };
            let mut what = Vec::new();
            if l.thinned() {
                what.push(format!(
                    "it draws {} of each plane (counted from the middle), not {}",
                    stride(l.every),
                    stride(l.asked),
                ));
            }
            if l.dropped > 0 {
                let pieces = u64::from(l.commands) + u64::from(l.dropped);
                what.push(format!("{} of the surface's {pieces} pieces were dropped", l.dropped));
            }
            if l.cut > 0 {
                what.push(format!("{} points did not fit its {}-point picture", l.cut, self.capacity.points));
            }
            if !l.ordered {
                what.push("there was no room to stitch and order it (drawn as contoured)".into());
            }
            let advice = if l.dropped > 0 || l.cut > 0 || !l.ordered {
                "draw fewer slices (--every), fewer planes (--axes) or fewer levels for the whole of it"
            } else {
                "draw fewer planes (--axes) or fewer levels for more of its slices"
            };
            out.push(format!("note: {holder} holds less than this surface: {}; {advice}", what.join(", ")));
        }
        if let Some(b) = self.board
            && self.replay_bytes > self.replay_capacity()
        {
            out.push(format!(
                "note: the {} board cannot keep this frame to replay it ({} bytes, its slice memory holds {}): \
                 it schedules every frame anew, and slows its sample clock for it (fewer points or samples \
                 fit: --every, --axes, fewer levels)",
                b.name,
                self.replay_bytes,
                self.replay_capacity()
            ));
        }
        if self.frame.lit_samples == 0 {
            out.push(nothing_drawn("the picture", &self.levels, self.values.as_ref()));
        } else if self.fps() < FLICKER_HZ {
            out.push(self.flickers());
        }
        out
    }

    /// The warning for a frame that refreshes below [`FLICKER_HZ`], with
    /// the ways to shorten it that apply to this picture.
    fn flickers(&self) -> String {
        let mut ways = Vec::new();
        // The frame's length goes about as the slices drawn, less its
        // jumps and dwells, which shrink more slowly: a quarter more.
        let drawn = f32::from(self.loaded.every.max(1));
        let every = (1.25 * drawn * FLICKER_HZ / self.fps().max(f32::MIN_POSITIVE)).ceil();
        let longest = self.dims.iter().copied().max().unwrap_or(0);
        if every < f32::from(longest.min(255)) {
            ways.push(format!("fewer slices (--every {every})"));
        }
        if self.planes.len() > 1 {
            ways.push("fewer planes (--axes)".into());
        }
        if self.levels.len() > 1 {
            ways.push(format!("fewer levels (of these {})", self.levels.len()));
        }
        if self.dims.iter().all(|&n| n >= 4) {
            ways.push("a coarser volume (--downsample 2)".into());
        }
        let advice = match ways.as_slice() {
            [] => String::new(),
            [one] => format!("; draw {one}"),
            [init @ .., last] => format!("; draw {} or {last}", init.join(", ")),
        };
        format!(
            "warning: the picture flickers: one frame is {} samples, {:.1} frames/s at {} samples/s \
             (below {FLICKER_HZ} a scope's picture flickers){advice}",
            self.frame.samples,
            self.fps(),
            self.sample_rate_hz
        )
    }

    /// Bytes a board lends to the replay: its two slice buffers (none on
    /// the host).
    pub fn replay_capacity(&self) -> usize {
        if self.board.is_some() { 2 * self.capacity.slice_bytes } else { 0 }
    }

    /// The frame statistics as `key=value` lines.
    pub fn report(&self) -> String {
        let f = &self.frame;
        let c = &self.chain;
        let mut s = String::new();
        let mut kv = |k: &str, v: String| {
            s.push_str(k);
            s.push('=');
            s.push_str(&v);
            s.push('\n');
        };
        kv("board", self.board.map_or("host".into(), |b| b.name.to_string()));
        kv("dims", format!("{}x{}x{}", self.dims[0], self.dims[1], self.dims[2]));
        kv("capacity_points", self.capacity.points.to_string());
        kv("fragments", c.fragments.to_string());
        kv("every", self.loaded.every.to_string());
        kv("pieces_dropped", self.loaded.dropped.to_string());
        kv("points_cut", self.loaded.cut.to_string());
        kv("polylines", self.polylines.to_string());
        kv("points", self.points.to_string());
        kv("dots", f.points.to_string());
        kv("lit_length", format!("{:.1}", f.lit_length));
        kv("blank_length", format!("{:.1}", f.blank_length));
        kv("blank_ratio", format!("{:.4}", self.blank_ratio()));
        kv("samples", f.samples.to_string());
        kv("lit_samples", f.lit_samples.to_string());
        kv("sample_rate_hz", self.sample_rate_hz.to_string());
        kv("fps", format!("{:.2}", self.fps()));
        if self.board.is_some() {
            kv("replay_bytes", self.replay_bytes.to_string());
            kv("replay_capacity_bytes", self.replay_capacity().to_string());
        }
        kv("duplicate_segments", c.duplicate_segments.to_string());
        kv("merged_points", c.merged.to_string());
        kv("transfer_ms", format!("{:.3}", self.seconds[0] * 1e3));
        kv("commit_ms", format!("{:.3}", self.seconds[1] * 1e3));
        kv("pipeline_ms", format!("{:.3}", self.seconds.iter().sum::<f64>() * 1e3));
        s
    }
}

/// Refreshes a second below which a picture flickers on a P31 screen
/// (from about 15 it is readable but flickering, from about 40 steady).
pub const FLICKER_HZ: f32 = 25.0;

/// The warning for `what` (a picture, an export) with nothing drawn at
/// `levels`: why, from the volume's `values` (its summary, as `info` gives
/// it; over [`crate::info::LEVEL_BINS`], the level a file is drawn at
/// without one is its first suggestion) when known, and the level to try
/// instead.
pub fn nothing_drawn(what: &str, levels: &[f32], values: Option<&crate::info::Summary>) -> String {
    let list = |l: &[f32]| l.iter().map(|x| x.to_string()).collect::<Vec<_>>().join(", ");
    let (asked, is) = match levels {
        [one] => (format!("level {one}"), "is"),
        many => (format!("levels {}", list(many)), "are"),
    };
    let why = match values.map(|v| (v.range, v.suggested.as_slice())) {
        None => format!("no contour at {asked} on these slices"),
        Some((None, _)) => format!("nothing to contour at {asked}: the volume has no finite value"),
        Some((Some((lo, hi)), suggested)) => {
            let mut why = if levels.iter().any(|&l| (lo..=hi).contains(&l)) {
                format!("no contour at {asked} on these slices; the volume's values run from {lo} to {hi}")
            } else {
                format!("{asked} {is} outside the volume's values, {lo} to {hi}")
            };
            match suggested {
                [] => why.push_str(" (no level to suggest: it is constant)"),
                [one] => why.push_str(&format!("; try --level {one} (Otsu's threshold, see `info`)")),
                [first, ..] => why.push_str(&format!(
                    "; try --level {first} (suggested levels {}, see `info`)",
                    list(suggested)
                )),
            }
            why
        }
    };
    format!("warning: {what} is empty: {why}")
}

/// "every slice", "every 2nd slice", "every 16th slice".
pub fn stride(every: u16) -> String {
    let suffix = match (every % 10, every % 100) {
        (_, 11..=13) => "th",
        (1, _) => "st",
        (2, _) => "nd",
        (3, _) => "rd",
        _ => "th",
    };
    if every <= 1 { "every slice".into() } else { format!("every {every}{suffix} slice") }
}

/// Write `samples` as text, `x y beam` a line (beam 1 lit, 0 blanked): the
/// format of `device --samples`, `render --samples`, `stats --samples` and
/// `wav --samples`.
///
/// # Errors
/// The file cannot be written.
pub fn write_samples(samples: &[Sample], path: &std::path::Path) -> Result<()> {
    let text = samples_text(samples);
    crate::outfile::write_whole(path, |w| {
        std::io::Write::write_all(w, text.as_bytes())
            .with_context(|| format!("cannot write {}", path.display()))
    })
}

/// `samples` as the text [`write_samples`] writes, `x y beam` a line.
pub fn samples_text(samples: &[Sample]) -> String {
    use isoscope_core::output::Beam;
    use std::fmt::Write as _;
    let mut text = String::with_capacity(samples.len() * 12);
    for s in samples {
        let _ = writeln!(text, "{} {} {}", s.x, s.y, u8::from(s.beam == Beam::On));
    }
    text
}

/// The slice stride a volume of `dims` is drawn at when none is given
/// (`render`'s default): every slice up to 32 along the longest axis, then
/// every n-th, n = longest / 32 rounded up.
pub fn auto_every(dims: crate::volume::Dims) -> usize {
    let crate::volume::Dims(nx, ny, nz) = dims;
    nx.max(ny).max(nz).div_ceil(32).max(1)
}

/// Refresh `screen` with the scene's frame `frames` times: each time the
/// phosphor decays, then the frame's samples are deposited.
pub fn refresh(
    screen: &mut crate::phosphor::Screen,
    scene: &Scene,
    frames: u32,
    progress: Option<&Progress>,
) {
    for _ in 0..frames.max(1) {
        screen.refresh(&scene.samples);
        if let Some(p) = progress {
            p.inc();
        }
    }
}

/// Draw `frames` refreshes of the scene's frame on a simulated phosphor,
/// as the scope would show it.
///
/// # Errors
/// An invalid picture configuration.
pub fn render(
    scene: &Scene,
    picture: crate::phosphor::PhosphorConfig,
    frames: u32,
    progress: Option<&crate::progress::Progress>,
) -> Result<crate::phosphor::Screen> {
    let mut screen =
        crate::phosphor::Screen::new(picture, draw_threads()).context("invalid picture settings")?;
    refresh(&mut screen, scene, frames, progress);
    Ok(screen)
}

/// Threads a picture is drawn on ([`crate::phosphor::Screen`]): the
/// machine's cores, at most 8 (a band's glow margin is drawn by both its
/// neighbours, so thinner bands gain less).
pub fn draw_threads() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get()).min(8)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::volume::{Dims, LoadedVolume, Samples};
    use isoscope_core::demo::Demo;

    fn demo(d: Demo, n: usize) -> WireVolume {
        let mut data = vec![0f32; n * n * n];
        d.fill(n, &mut data).unwrap();
        WireVolume::new(Dims(n, n, n), &Samples::F32(data), [1.0; 3]).unwrap()
    }

    /// A surface larger than the host's first memory is fed again with
    /// more: the progress counts that pass anew, and so ends at its total
    /// (it counted past it, to 200%, when each pass added to the last).
    #[test]
    fn progress_ends_at_its_total_when_the_memory_grows() {
        let vol = demo(Demo::Gyroid, 32);
        let cfg = SceneConfig { levels: vec![Demo::Gyroid.default_level()], ..SceneConfig::default() };
        let progress =
            Progress::with_output("contouring", crate::board::frames_for(&vol, &cfg.send().unwrap()), false);
        let scene = with_board(&vol, &cfg, Some(&progress), |board, capacity| {
            Ok(scene_of(board, &vol, capacity, &cfg))
        })
        .unwrap();
        assert!(scene.capacity.points > HOST_START_POINTS, "the memory did not grow: {:?}", scene.capacity);
        assert_eq!(progress.done(), progress.total());
    }

    /// One pass of the schedule gives the samples and the replay's bytes
    /// that a pass for each gives; a count short of the frame gives its
    /// samples and leaves the bytes to the second pass.
    #[test]
    fn one_pass_records_what_two_passes_do() {
        for (d, n, on_board) in
            [(Demo::Hydrogen, 16, false), (Demo::Torus, 12, true), (Demo::Gyroid, 16, false)]
        {
            let vol = demo(d, n);
            let mut cfg = SceneConfig { levels: vec![d.default_level()], ..SceneConfig::default() };
            if on_board {
                cfg.memory = Memory::Board(Board::F407);
            }
            with_board(&vol, &cfg, None, |board, _| {
                let engine = board.engine();
                let counted = engine.frame_stats().samples;
                let want: Vec<Sample> = engine.frame().collect();
                assert_eq!(counted, want.len() as u64, "{d:?}: the engine counted this frame");
                let bytes = replay_bytes(engine.frame(), want.len());
                assert!(bytes > 0, "{d:?}");
                assert_eq!(recorded(&mut engine.frame(), counted), (want.clone(), Some(bytes)), "{d:?}");
                assert_eq!(recorded(&mut engine.frame(), counted - 1), (want.clone(), None), "{d:?}: short");
                assert_eq!(recorded(&mut engine.frame(), u64::MAX), (want, None), "{d:?}: no count");
                Ok(())
            })
            .unwrap();
        }
    }

    #[test]
    fn starting_at_the_size_another_level_needed_draws_the_same_frame() {
        use std::sync::atomic::{AtomicUsize, Ordering};
        // Frames fed to the boards, restarts included: the count told
        // last, and the counts told last before each restart.
        static FED: AtomicUsize = AtomicUsize::new(0);
        static LAST: AtomicUsize = AtomicUsize::new(0);
        fn count(_: &'static str, done: usize, _: usize) {
            let last = LAST.swap(done, Ordering::Relaxed);
            if done < last {
                FED.fetch_add(last, Ordering::Relaxed);
            }
        }
        let vol =
            WireVolume::from_loaded(&LoadedVolume::demo("gyroid:32".parse().unwrap()).unwrap()).unwrap();
        let frames = |cfg: &SceneConfig| crate::board::frames_for(&vol, &cfg.send().unwrap());
        // Level 0 needs 262,144 points (contoured twice from the start);
        // 1.4, near the values' end, fits the first size.
        for (level, needs, started, once) in [
            (0.0, 4 * HOST_START_POINTS, 4 * HOST_START_POINTS, true),
            // Also room at the size below: contoured again from the first.
            (0.0, 4 * HOST_START_POINTS, 16 * HOST_START_POINTS, false),
            (1.4, HOST_START_POINTS, 4 * HOST_START_POINTS, false),
            (1.4, HOST_START_POINTS, HOST_START_POINTS, true),
        ] {
            let cfg = SceneConfig { levels: vec![level], ..SceneConfig::default() };
            let want = build(&vol, &cfg).unwrap();
            assert_eq!(want.capacity.points, needs, "level {level}");
            FED.store(0, Ordering::Relaxed);
            LAST.store(0, Ordering::Relaxed);
            let progress = Progress::with_hook("contouring", frames(&cfg), count);
            let (board, capacity) = board_near(&vol, &cfg, started, Some(&progress)).unwrap();
            let got = scene_of(board.board(), &vol, capacity, &cfg);
            assert_eq!(got.capacity, want.capacity, "level {level} from {started}");
            assert_eq!(got.samples, want.samples, "level {level} from {started}");
            assert_eq!(got.commands, want.commands, "level {level} from {started}");
            let fed = FED.load(Ordering::Relaxed) + LAST.load(Ordering::Relaxed);
            assert_eq!(fed == frames(&cfg), once, "level {level} from {started}: {fed} frames fed");
        }
    }

    #[test]
    fn starting_at_the_size_another_view_needed_draws_the_same_frame() {
        // gyroid:32 needs 262,144 points: contoured twice from the start.
        let vol =
            WireVolume::from_loaded(&LoadedVolume::demo("gyroid:32".parse().unwrap()).unwrap()).unwrap();
        let cfg = SceneConfig { levels: vec![0.0], ..SceneConfig::default() };
        let first = build(&vol, &cfg).unwrap();
        assert_eq!(first.capacity.points, 4 * HOST_START_POINTS);
        let turned = SceneConfig { view: View { yaw: 75.0, pitch: -20.0, ..cfg.view }, ..cfg };
        let want = build(&vol, &turned).unwrap();
        // A size between two is rounded down to the smaller.
        for points in [first.capacity.points, first.capacity.points + 1] {
            let got = with_board_from(&vol, &turned, points, None, |b, c| Ok(scene_of(b, &vol, c, &turned)))
                .unwrap();
            assert_eq!(got.capacity, want.capacity);
            assert_eq!(got.samples, want.samples);
            assert_eq!(got.commands, want.commands);
        }
    }
}
