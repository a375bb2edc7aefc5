//! The device engine: the board's whole behaviour behind the UART, heap-free,
//! the same code on the MCU and in the simulator.
//!
//! Fed received bytes and the time, it
//!
//! - decodes frames ([`crate::wire`]), takes commands strictly in `seq`
//!   order, answers each with `Ack` or `Nack` (answering a retransmission
//!   again from memory, without applying it twice);
//! - streams a volume one z slice at a time through two slice buffers,
//!   contouring each slice as it completes, so memory is `O(nx * ny)` and
//!   volumes deeper than RAM work;
//! - keeps two surfaces in voxel coordinates ([`Geometry`], 6.25 bytes a
//!   point): the picture on screen, untouched until a new volume is
//!   complete (so an aborted, corrupt or abandoned transfer never costs it),
//!   and the one being received (whose pieces go on, once it is full, in
//!   the slice memory the volume's slices leave free);
//! - when a volume is complete, stitches and orders it in 3D into the
//!   picture ([`ChainStats`]; the idle slice buffers are the scratch), so
//!   that any view draws it with short jumps: a new view, or a spinning
//!   one, costs no more than projecting each point as the beam reaches it.
//!
//! What it answers is queued as bytes for the UART ([`Engine::transmit`]):
//! an `Ack` or `Nack` for every command, and a `Status` once a new volume's
//! picture is drawn (so the host can time "last slice to picture") or a
//! transfer is abandoned; what happened is queued as [`Event`]s for a log
//! ([`Engine::next_event`]). [`Engine::frame`] is the beam schedule of one
//! frame, what every board plays.
//!
//! The caller owns the memory ([`Buffers`]; [`StaticBuffers`] holds it in
//! arrays for the MCU) and the clock (milliseconds, wrapping).
//!
//! Changing the levels needs the volume again (they apply to the next
//! volume); changing the view or the beam does not.

mod board;
mod chain;
mod geometry;
mod session;
mod stream;

pub use board::{Board, Capacity};
pub use chain::ChainStats;
use chain::{Metric, Pass};
use geometry::Source;
pub use geometry::{Commands, Geometry, Kind, Packed};
pub use session::REPLAY;
pub use stream::VolumeSpec;

use crate::beam::{BeamConfig, BeamConfigError, FrameStats, Scheduler, frame_stats};
use crate::command::{Command, Point3};
use crate::view::{Bounds, Projection, ScreenPoint, View, ViewError, ViewTransform};
use crate::wire::{
    DeviceState, Levels, Message, NackCode, PROTOCOL_VERSION, ProtocolDecoder, SampleType, WireError, encode,
};
use heapless::Deque;
use session::{Session, Standing};
use stream::Stream;

/// Bytes of answers queued for the UART before more are dropped (the sender
/// retransmits what it never heard about).
pub const TX_QUEUE: usize = 512;

/// Events queued before more are dropped (and counted).
pub const EVENT_QUEUE: usize = 16;

/// The engine's memory, lent by the caller.
///
/// - `slices`: both slice buffers, one after the other: half of it is the
///   largest slice, `nx * ny * sample size` bytes. What a volume's two
///   slices leave free holds the part of its surface that does not fit
///   `back` (so a volume of small slices may have a larger surface: the
///   pieces as contoured are some 1.75 times the picture's points).
///   Between volumes it is the scratch for stitching and ordering, which
///   takes about 6 bytes a point of the surface (14 a fragment), 3 when
///   short of room: so the slices should hold at least `6 * points` bytes
///   in all, or a large surface is shown unordered.
/// - `rows`: two row buffers; each sets the largest `nx` and `ny`.
/// - `front`, `back`: the bytes of the two surfaces (on screen, being
///   received), [`Geometry::bytes_for`] the points each holds (6.25 bytes
///   a point).
/// - `scratch`: more room for stitching and ordering, where memory is
///   plenty (the host); the larger of it and the idle slices is used. Empty
///   on the MCU.
#[derive(Debug)]
pub struct Buffers<'a> {
    /// Both slices (the previous and the current one), one after the other.
    pub slices: &'a mut [u8],
    /// Two rows of samples widened to `f32`.
    pub rows: [&'a mut [f32]; 2],
    /// The picture on screen.
    pub front: &'a mut [u8],
    /// The surface being received.
    pub back: &'a mut [u8],
    /// Extra scratch (may be empty).
    pub scratch: &'a mut [u8],
}

impl<'a> Buffers<'a> {
    /// Buffers from one block of each kind, cut in two halves: `rows` into
    /// the two rows, `surfaces` into the two surfaces (front first).
    /// `slices` holds both slices as it is.
    pub fn halves(
        slices: &'a mut [u8],
        rows: &'a mut [f32],
        surfaces: &'a mut [u8],
        scratch: &'a mut [u8],
    ) -> Self {
        let (r0, r1) = rows.split_at_mut(rows.len() / 2);
        let (front, back) = surfaces.split_at_mut(surfaces.len() / 2);
        Self { slices, rows: [r0, r1], front, back, scratch }
    }
}

/// The engine's memory in arrays, for a `static` on the MCU.
///
/// - `SLICE`: bytes in one slice (`nx * ny * sample size`), twice.
/// - `EXTENT`: the largest `nx` or `ny`.
/// - `SURFACE`: bytes of each of the two surfaces:
///   [`Geometry::bytes_for`] the points it holds.
///
/// It takes `2 * SLICE + 8 * EXTENT + 2 * SURFACE` bytes; for slices of
/// 128 x 128 `u16` and 2 x 8192 points, 167 KB.
#[derive(Debug, Clone, PartialEq)]
pub struct StaticBuffers<const SLICE: usize, const EXTENT: usize, const SURFACE: usize> {
    slices: [[u8; SLICE]; 2],
    rows: [[f32; EXTENT]; 2],
    surfaces: [[u8; SURFACE]; 2],
}

impl<const SLICE: usize, const EXTENT: usize, const SURFACE: usize> StaticBuffers<SLICE, EXTENT, SURFACE> {
    /// Zeroed buffers.
    pub const fn new() -> Self {
        Self { slices: [[0; SLICE]; 2], rows: [[0.0; EXTENT]; 2], surfaces: [[0; SURFACE]; 2] }
    }

    /// The buffers, lent to an [`Engine`].
    pub fn buffers(&mut self) -> Buffers<'_> {
        Buffers::halves(
            self.slices.as_flattened_mut(),
            self.rows.as_flattened_mut(),
            self.surfaces.as_flattened_mut(),
            &mut [],
        )
    }
}

impl<const SLICE: usize, const EXTENT: usize, const SURFACE: usize> Default
    for StaticBuffers<SLICE, EXTENT, SURFACE>
{
    fn default() -> Self {
        Self::new()
    }
}

/// What the engine is set up with.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct EngineConfig {
    /// Firmware version reported in `Hello` (major, minor, patch).
    pub firmware: [u8; 3],
    /// Sample types taken: a set of [`SampleType::bit`].
    pub sample_types: u8,
    /// DAC samples per second (for beam times in microseconds and the
    /// refresh rate reported).
    pub sample_rate_hz: u32,
    /// The view until the host sets one (its `spacing` is replaced by each
    /// volume's, its `bits` by the beam's).
    pub view: View,
    /// The beam until the host sets it.
    pub beam: BeamConfig,
    /// Merging collinear runs: the largest distance, in DAC units (at the
    /// largest scale any view gives the picture), of a dropped vertex from
    /// the chord that replaces it; 0 merges nothing. Default: half an LSB.
    pub merge_tolerance: f32,
    /// A transfer with no accepted message for this long is abandoned (ms).
    pub transfer_timeout_ms: u32,
    /// Contour a completed slice later, a few rows at a time
    /// ([`Link::contour`]), instead of inside [`Link::feed`]: for a device
    /// that must keep its display refreshed (the firmware), where a slice
    /// of 128 x 128 takes tens of milliseconds. [`Link::feed`] then stops
    /// taking bytes while that work is pending.
    pub defer_contouring: bool,
}

impl Default for EngineConfig {
    /// Every sample type, 1 MS/s, the default view, beam and tolerance, and
    /// a 5 s transfer timeout; slices contoured as they complete.
    fn default() -> Self {
        Self {
            firmware: [0, 1, 0],
            sample_types: SampleType::ALL.iter().fold(0, |m, t| m | t.bit()),
            sample_rate_hz: 1_000_000,
            view: View::DEFAULT,
            beam: BeamConfig::default(),
            merge_tolerance: 0.5,
            transfer_timeout_ms: 5_000,
            defer_contouring: false,
        }
    }
}

/// Why an [`Engine`] could not be made.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EngineError {
    /// The beam configuration is invalid.
    Beam(BeamConfigError),
    /// The view is invalid.
    View(ViewError),
    /// The slice or row buffers are too small for a 2x2 slice of `f32`.
    Buffers,
}

impl core::fmt::Display for EngineError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Beam(e) => write!(f, "invalid beam settings: {e}"),
            Self::View(e) => write!(f, "invalid view: {e}"),
            Self::Buffers => f.write_str("engine buffers too small (slices or rows)"),
        }
    }
}

impl core::error::Error for EngineError {}

/// Why a transfer ended without a new picture (the old one stays).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum AbortReason {
    /// A new `BeginVolume` came.
    Superseded,
    /// The host said `Hello` again (it restarted).
    Restarted,
    /// `EndVolume` came with slices missing.
    Missing,
    /// Nothing came for [`EngineConfig::transfer_timeout_ms`].
    Timeout,
}

impl core::fmt::Display for AbortReason {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            Self::Superseded => "superseded by a new volume",
            Self::Restarted => "host restarted",
            Self::Missing => "slices missing at the end",
            Self::Timeout => "timed out",
        })
    }
}

/// Something the engine did, for a log (one line each).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Event {
    /// The host said hello.
    Hello {
        /// Its protocol version.
        protocol: u8,
    },
    /// A volume transfer began.
    Begun {
        /// Samples along x, y, z.
        dims: [u16; 3],
        /// Sample type.
        sample_type: SampleType,
        /// Number of levels.
        levels: u8,
    },
    /// A volume is complete and replaces the picture.
    Committed {
        /// Samples along x, y, z.
        dims: [u16; 3],
        /// Contour commands kept.
        commands: u32,
        /// Contour commands that did not fit.
        dropped: u32,
        /// Subgrids skipped for NaN or infinite samples.
        nonfinite_cells: u32,
    },
    /// A completed volume's pieces were stitched and ordered into the
    /// picture.
    Stitched {
        /// Contour fragments in (one a subgrid and level).
        fragments: u32,
        /// Points of the picture.
        points: u32,
        /// Points the picture had no room for (it is cut short).
        cut: u32,
        /// False when there was too little scratch to stitch and order:
        /// the pieces are drawn as they came, with more blanked travel.
        ordered: bool,
    },
    /// A transfer ended without a picture; the old one stays.
    Aborted {
        /// Why.
        reason: AbortReason,
        /// Slices it had received.
        slices: u16,
    },
    /// A command was refused.
    Nacked {
        /// Its sequence number.
        seq: u16,
        /// Why.
        code: NackCode,
    },
    /// A frame could not be decoded.
    FrameError {
        /// Why.
        error: WireError,
    },
    /// New levels (for the next volume).
    LevelsSet,
    /// A new view.
    ViewSet,
    /// New beam settings.
    BeamSet,
    /// The picture changed (a new volume, view or beam).
    Redrawn {
        /// Polylines drawn (closed loops and dots included).
        polylines: u32,
        /// Points drawn.
        points: u32,
        /// Blanked travel as a share of lit length, per mille, in this view.
        blank_permille: u16,
        /// Refreshes per second at [`EngineConfig::sample_rate_hz`], times
        /// 100.
        refresh_centi_hz: u16,
    },
}

impl core::fmt::Display for Event {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            Self::Hello { protocol } => write!(f, "hello protocol={protocol}"),
            Self::Begun { dims: [x, y, z], sample_type, levels } => {
                write!(f, "begun dims={x}x{y}x{z} type={sample_type:?} levels={levels}")
            }
            Self::Committed { dims: [x, y, z], commands, dropped, nonfinite_cells } => write!(
                f,
                "committed dims={x}x{y}x{z} commands={commands} dropped={dropped} nonfinite_cells={nonfinite_cells}"
            ),
            Self::Stitched { fragments, points, cut, ordered } => {
                write!(f, "stitched fragments={fragments} points={points} cut={cut} ordered={ordered}")
            }
            Self::Aborted { reason, slices } => write!(f, "aborted slices={slices} reason={reason}"),
            Self::Nacked { seq, code } => write!(f, "nack seq={seq} code={code:?}"),
            Self::FrameError { error } => write!(f, "bad frame: {error}"),
            Self::LevelsSet => f.write_str("levels set (for the next volume)"),
            Self::ViewSet => f.write_str("view set"),
            Self::BeamSet => f.write_str("beam set"),
            Self::Redrawn { polylines, points, blank_permille, refresh_centi_hz } => write!(
                f,
                "redrawn polylines={polylines} points={points} blank={}.{}% refresh_hz={}.{:02}",
                blank_permille / 10,
                blank_permille % 10,
                refresh_centi_hz / 100,
                refresh_centi_hz % 100
            ),
        }
    }
}

/// Counts since start.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Counters {
    /// Frames decoded into messages.
    pub frames: u32,
    /// Frames that failed to decode.
    pub frame_errors: u32,
    /// Commands refused (`Nack` sent).
    pub nacks: u32,
    /// Answers re-sent for retransmitted commands.
    pub replays: u32,
    /// Volumes committed.
    pub volumes: u32,
    /// Transfers aborted.
    pub aborts: u32,
    /// Answer frames dropped because the transmit queue was full.
    pub tx_dropped: u32,
    /// Events dropped because the event queue was full.
    pub events_dropped: u32,
}

/// The committed volume.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Shown {
    dims: [u16; 3],
    spacing: [f32; 3],
    points: u32,
    /// The box of the surface's points (voxel coordinates), which every
    /// view fits by its bounding sphere; the volume's box until the
    /// surface is known, or when it is empty.
    bounds: Bounds,
}

/// Everything but the frame decoder and the two surfaces.
#[derive(Debug)]
struct Device<'a> {
    cfg: EngineConfig,
    session: Session,
    stream: Stream<'a>,
    /// The volume on screen.
    shown: Option<Shown>,
    /// A volume is complete in the back surface: it becomes the picture at
    /// the next [`Engine::update`]; until then new volume data is `Busy`.
    commit: bool,
    view: View,
    spin_deg_per_s: f32,
    /// When `view.yaw` held (ms), for the spin.
    spin_epoch_ms: u32,
    beam: BeamConfig,
    levels: Levels,
    /// The view or beam changed: fit the view again, count the frame again.
    dirty: bool,
    /// A volume was committed: report the status once its picture is drawn.
    status_due: bool,
    display_capacity: usize,
    /// The rate the board plays samples at ([`Engine::set_playback_rate`]).
    playback_hz: u32,
    /// A frame of the picture, as last counted.
    frame: FrameStats,
    /// The board counts a new picture's frame as it plays it
    /// ([`Engine::count_while_playing`]).
    board_counts: bool,
    /// A count is due from the board's next played frame.
    count_due: bool,
    refresh_centi_hz: u16,
    tx: Deque<u8, TX_QUEUE>,
    events: Deque<Event, EVENT_QUEUE>,
    counters: Counters,
}

/// The device engine. See the [module documentation](self).
#[derive(Debug)]
pub struct Engine<'a> {
    decoder: ProtocolDecoder,
    dev: Device<'a>,
    /// The picture on screen.
    front: Geometry<'a>,
    /// The surface being received.
    back: Geometry<'a>,
    /// The view fitted to the picture, `None` with nothing to show.
    transform: Option<ViewTransform>,
    chain: ChainStats,
    /// Extra scratch for [`chain::chain`].
    scratch: &'a mut [u8],
    generation: u32,
}

/// The picture half of an [`Engine`] ([`Engine::split`]): the surface on
/// screen, its view and the beam settings it is played with.
#[derive(Debug, Clone, Copy)]
pub struct Screen<'e, 'a> {
    front: &'e Geometry<'a>,
    transform: Option<ViewTransform>,
    beam: BeamConfig,
}

impl<'e> Screen<'e, '_> {
    /// One frame, as [`Engine::frame`].
    pub fn frame(&self) -> Scheduler<Projected<'e>> {
        Scheduler::new(self.commands(), &self.beam)
    }

    /// The picture's drawing commands on the screen, in drawing order.
    pub fn commands(&self) -> Projected<'e> {
        Projected { commands: self.front.commands(), transform: self.transform }
    }

    /// The beam settings.
    pub fn beam(&self) -> &BeamConfig {
        &self.beam
    }
}

/// The picture's commands projected on the screen (nothing without a
/// picture).
#[derive(Debug, Clone)]
pub struct Projected<'e> {
    commands: Commands<'e, 'e>,
    transform: Option<ViewTransform>,
}

impl Iterator for Projected<'_> {
    type Item = Command<ScreenPoint>;

    #[inline]
    fn next(&mut self) -> Option<Command<ScreenPoint>> {
        // By reference: the transform is some twenty words, and this runs
        // for every point of every frame.
        let t = self.transform.as_ref()?;
        // Unchecked: the scheduler skips points that are not finite.
        self.commands.next().map(|c| c.map(|p| t.project_raw(p)))
    }
}

/// The receiving half of an [`Engine`] ([`Engine::split`]): feeding bytes
/// while the picture is being drawn.
#[derive(Debug)]
pub struct Link<'e, 'a> {
    decoder: &'e mut ProtocolDecoder,
    dev: &'e mut Device<'a>,
    back: &'e mut Geometry<'a>,
}

impl<'a> Engine<'a> {
    /// An engine over `buffers`, showing nothing.
    ///
    /// # Errors
    /// [`EngineError`] for an invalid beam or view, or buffers too small.
    pub fn new(cfg: EngineConfig, buffers: Buffers<'a>) -> Result<Self, EngineError> {
        cfg.beam.validate().map_err(EngineError::Beam)?;
        ViewTransform::fit(
            &cfg.view,
            Bounds { min: Point3::new(0.0, 0.0, 0.0), max: Point3::new(1.0, 1.0, 1.0) },
        )
        .map_err(EngineError::View)?;
        let Buffers { slices, rows, front, back, scratch } = buffers;
        let stream = Stream::new(slices, rows);
        if stream.slice_capacity() < 16 || stream.row_capacity() < 2 {
            return Err(EngineError::Buffers);
        }
        let front = Geometry::new(front);
        let back = Geometry::new(back);
        let display_capacity = front.capacity().min(back.capacity());
        Ok(Self {
            decoder: ProtocolDecoder::new(),
            dev: Device {
                cfg,
                session: Session::new(),
                stream,
                shown: None,
                commit: false,
                view: cfg.view,
                spin_deg_per_s: 0.0,
                spin_epoch_ms: 0,
                beam: cfg.beam,
                levels: Levels::new(),
                dirty: false,
                status_due: false,
                display_capacity,
                playback_hz: cfg.sample_rate_hz,
                frame: FrameStats::default(),
                board_counts: false,
                count_due: false,
                refresh_centi_hz: 0,
                tx: Deque::new(),
                events: Deque::new(),
                counters: Counters::default(),
            },
            front,
            back,
            transform: None,
            chain: ChainStats::default(),
            scratch,
            generation: 0,
        })
    }

    /// The receiving half and the picture, borrowed apart, so that the beam
    /// can play frames while bytes are fed. What the bytes change (a new
    /// volume, view or beam) shows after the next [`Engine::update`].
    pub fn split(&mut self) -> (Link<'_, 'a>, Screen<'_, 'a>) {
        let screen = Screen { front: &self.front, transform: self.transform, beam: self.dev.beam };
        (Link { decoder: &mut self.decoder, dev: &mut self.dev, back: &mut self.back }, screen)
    }

    /// Take received bytes at time `now_ms`: see [`Link::feed`].
    pub fn feed(&mut self, bytes: &[u8], now_ms: u32) -> usize {
        self.split().0.feed(bytes, now_ms)
    }

    /// Move answer bytes for the UART into `out`; returns how many.
    pub fn transmit(&mut self, out: &mut [u8]) -> usize {
        self.split().0.transmit(out)
    }

    /// The oldest event not yet taken.
    pub fn next_event(&mut self) -> Option<Event> {
        self.dev.events.pop_front()
    }

    /// Between frames: abandon a stalled transfer; make a complete volume
    /// the picture (stitch and order it, in the idle slice buffers); fit a
    /// new or spinning view. Returns whether the picture changed.
    pub fn update(&mut self, now_ms: u32) -> bool {
        self.dev.check_timeout(now_ms);
        let mut changed = false;
        if self.dev.commit {
            self.commit();
            changed = true;
        }
        let spinning = self.dev.spin_deg_per_s != 0.0 && self.dev.shown.is_some();
        if changed || self.dev.dirty || spinning {
            // A spin alone only turns the view; anything else counts the
            // frame again (a pass of the scheduler).
            let count = changed || self.dev.dirty;
            self.dev.dirty = false;
            self.fit(now_ms);
            if count && self.dev.board_counts {
                self.dev.count_due = true;
            } else if count {
                self.count();
            }
            self.generation = self.generation.wrapping_add(1);
            changed = true;
        }
        changed
    }

    /// The received surface becomes the picture.
    fn commit(&mut self) {
        let dev = &mut self.dev;
        dev.commit = false;
        let Some(spec) = dev.shown.as_mut() else { return };
        let (spill, free) = dev.stream.take_spill();
        let pieces = Source::two(&self.back, &spill);
        // Every view fits the surface, not the volume: the box of its
        // pieces (stitching and merging keep their end points, so it is the
        // picture's box too).
        if let Some([lo, hi]) = pieces.extent() {
            spec.bounds = Bounds::new(self.back.point(lo), self.back.point(hi));
        }
        let spec = *spec;
        // Merge within the tolerance at the largest scale a view can give:
        // the bounding sphere's fit, times the longest voxel side, doubled.
        let tolerance = ViewTransform::fit_sphere(
            &View { spacing: spec.spacing, bits: dev.beam.bits, ..dev.view },
            spec.bounds,
        )
        .map_or(0.0, |t| {
            let side = spec.spacing.iter().fold(0.0f32, |m, &s| m.max(s));
            dev.cfg.merge_tolerance / (2.0 * t.scale() * side)
        });
        // Stitch the pieces (the back's, then those that spilled into the
        // slice memory) into maximal polylines (into the front), then order
        // those for short jumps (back into the back), and make that the
        // front. Collinear runs are merged once: in the order pass, which
        // then also joins polylines that touch where one ends and the next
        // is entered (merging first could take such a vertex away); but in
        // the stitch pass when the pieces are more than the front holds
        // (stitching joins them, merging thins them: the surface fits
        // again).
        let merge_first = pieces.len() > self.front.capacity();
        let (first, then) = if merge_first { (tolerance, 0.0) } else { (0.0, tolerance) };
        let scratch = if free.len() >= self.scratch.len() { free } else { &mut *self.scratch };
        let stitched = chain::chain(pieces, &mut self.front, scratch, [0; 3], first, Pass::Stitch);
        let slices = dev.stream.idle_scratch().unwrap_or(&mut []);
        let scratch = if slices.len() >= self.scratch.len() { slices } else { &mut *self.scratch };
        // A still view orders for its own screen (a jump across the depth
        // costs it nothing); a spinning one in space, for every angle.
        let view = View { spacing: spec.spacing, bits: dev.beam.bits, ..dev.view };
        let metric = match ViewTransform::fit_sphere(&view, spec.bounds) {
            Ok(t) if dev.spin_deg_per_s == 0.0 => {
                let park = dev.beam.park_sample();
                Metric::Screen {
                    view: t,
                    shift: self.front.shift(),
                    park: [f32::from(park.x), f32::from(park.y)],
                }
            }
            _ => Metric::Space,
        };
        let ordered = chain::chain(
            Source::one(&self.front),
            &mut self.back,
            scratch,
            [0; 3],
            then,
            Pass::Order(metric),
        );
        core::mem::swap(&mut self.front, &mut self.back);
        self.back.reset(self.back.shift());
        self.chain = ChainStats {
            fragments: stitched.fragments,
            points_in: stitched.points_in,
            ordered: stitched.ordered && ordered.ordered,
            duplicate_segments: stitched.duplicate_segments,
            culled_dots: stitched.culled_dots,
            merged: stitched.merged + ordered.merged,
            cut: stitched.cut.saturating_add(ordered.cut),
            ..ordered
        };
        if let Some(s) = dev.shown.as_mut() {
            s.points = self.front.len() as u32;
        }
        dev.event(Event::Stitched {
            fragments: self.chain.fragments,
            points: self.chain.points_out,
            cut: self.chain.cut,
            ordered: self.chain.ordered,
        });
        dev.status_due = true;
    }

    /// Fit the view to the picture at time `now_ms` (for the spin).
    fn fit(&mut self, now_ms: u32) {
        let dev = &self.dev;
        let Some(shown) = dev.shown else {
            self.transform = None;
            return;
        };
        let elapsed_s = now_ms.wrapping_sub(dev.spin_epoch_ms) as f32 / 1000.0;
        let turn = libm::fmodf(dev.spin_deg_per_s * elapsed_s, 360.0);
        let view = View { spacing: shown.spacing, bits: dev.beam.bits, ..dev.view }.yawed(turn);
        // The surface's bounding sphere fills the screen: the scale is the
        // same from every side, so a spinning view neither breathes nor
        // clips, and turning the view keeps the picture's size.
        if let Ok(t) = ViewTransform::fit_sphere(&view, shown.bounds) {
            self.transform = Some(t);
        }
    }

    /// Leave the frame count of a new picture to the board (`on`): then
    /// [`Engine::update`] does not run the beam scheduler over the whole
    /// picture once more before it is shown (for hydrogen 32^3 on the
    /// Cortex-M4 about 3.3M instructions, 20 ms with the beam parked), and
    /// the board hands over the first frame it plays of it with
    /// [`Engine::played`]. The `Redrawn` event and the status that follows a
    /// new volume then come a frame later; the refresh rate reported meanwhile
    /// is the last picture's.
    pub fn count_while_playing(&mut self, on: bool) {
        self.dev.board_counts = on;
        if !on && core::mem::take(&mut self.dev.count_due) {
            self.count();
        }
    }

    /// The board played a whole frame of the picture (from
    /// [`Engine::frame`], to its end): its statistics count the picture, if
    /// a count is due ([`Engine::count_while_playing`]). A frame of another
    /// picture than the one [`Engine::update`] made last must not be passed.
    pub fn played(&mut self, frame: FrameStats) {
        if core::mem::take(&mut self.dev.count_due) {
            self.counted(frame);
        }
    }

    /// Count one frame: the refresh rate and the blank share, reported.
    fn count(&mut self) {
        self.counted(frame_stats(self.commands(), &self.dev.beam));
    }

    /// The counted frame `stats` of the picture.
    fn counted(&mut self, stats: FrameStats) {
        let dev = &mut self.dev;
        dev.frame = stats;
        dev.refresh();
        let blank = stats.blank_length / stats.lit_length.max(f32::MIN_POSITIVE);
        dev.event(Event::Redrawn {
            polylines: self.front.polylines() as u32,
            points: self.front.len() as u32,
            blank_permille: (blank * 1000.0).clamp(0.0, 60000.0) as u16,
            refresh_centi_hz: dev.refresh_centi_hz,
        });
        if core::mem::take(&mut dev.status_due) {
            dev.status();
        }
    }

    /// One frame of the picture as the board plays it: the beam schedule of
    /// the picture's projected commands, from the park position back to it
    /// (blanked). The board plays it over and over, and the park position
    /// between frames when there is nothing to show. Every board (the
    /// firmware, the simulator's virtual board) plays exactly these samples.
    pub fn frame(&self) -> Scheduler<Projected<'_>> {
        Scheduler::new(self.commands(), &self.dev.beam)
    }

    /// The picture's drawing commands on the screen, in drawing order. A
    /// point the view cannot project (behind a perspective camera) is not
    /// finite, and the beam scheduler skips it.
    pub fn commands(&self) -> Projected<'_> {
        Projected { commands: self.front.commands(), transform: self.transform }
    }

    /// The board plays the samples at `hz` instead of
    /// [`EngineConfig::sample_rate_hz`]: it slowed its sample clock for a
    /// picture its refill cannot keep up with ([`crate::beam::pace`]). The
    /// refresh rate reported from now on (in `Status`) follows it; the
    /// samples, and beam times set in microseconds, do not change.
    pub fn set_playback_rate(&mut self, hz: u32) {
        if hz != self.dev.playback_hz {
            self.dev.playback_hz = hz;
            self.dev.refresh();
        }
    }

    /// The refresh rate of the picture at the playback rate, in Hz.
    pub fn refresh_hz(&self) -> f32 {
        f32::from(self.dev.refresh_centi_hz) / 100.0
    }

    /// Counts up each time the picture changes.
    pub fn generation(&self) -> u32 {
        self.generation
    }

    /// The beam settings in force.
    pub fn beam(&self) -> &BeamConfig {
        &self.dev.beam
    }

    /// The picture in voxel coordinates: stitched and ordered.
    pub fn surface(&self) -> Option<&Geometry<'a>> {
        self.dev.shown.and(Some(&self.front))
    }

    /// What stitching and ordering did to the last volume.
    pub fn chain_stats(&self) -> ChainStats {
        self.chain
    }

    /// What the engine is doing.
    pub fn state(&self) -> DeviceState {
        self.dev.state()
    }

    /// Counts since start.
    pub fn counters(&self) -> Counters {
        self.dev.counters
    }
}

impl Link<'_, '_> {
    /// What the engine is doing ([`Engine::state`]).
    pub fn state(&self) -> DeviceState {
        self.dev.state()
    }

    /// Take received bytes at time `now_ms` (milliseconds, wrapping): decode
    /// frames, apply commands, queue answers and events. Never panics, for
    /// any bytes. Returns how many bytes it took: all of them, except with
    /// [`EngineConfig::defer_contouring`], where it stops after the frame
    /// that completed a slice (feed the rest once [`Link::contour`] is
    /// done) and takes none while that work is pending.
    pub fn feed(&mut self, bytes: &[u8], now_ms: u32) -> usize {
        self.dev.check_timeout(now_ms);
        let defer = self.dev.cfg.defer_contouring;
        if defer && self.dev.stream.busy() {
            return 0;
        }
        for (n, &b) in bytes.iter().enumerate() {
            match self.decoder.push(b) {
                None => {}
                Some(Ok(msg)) => {
                    self.dev.counters.frames = self.dev.counters.frames.wrapping_add(1);
                    self.dev.handle(msg, now_ms, self.back);
                    if defer && self.dev.stream.busy() {
                        return n + 1;
                    }
                }
                Some(Err(error)) => {
                    self.dev.counters.frame_errors = self.dev.counters.frame_errors.wrapping_add(1);
                    self.dev.event(Event::FrameError { error });
                    // Ask for everything from the next expected command.
                    let code = match error {
                        WireError::BadCrc => NackCode::BadCrc,
                        WireError::Truncated | WireError::BadCobs => NackCode::Truncated,
                        WireError::Oversize => NackCode::Oversize,
                        WireError::BadVersion { .. } => NackCode::BadVersion,
                        WireError::UnknownMessage | WireError::BufferTooSmall => NackCode::UnknownMessage,
                    };
                    let seq = self.dev.session.expected();
                    self.dev.nack(seq, code);
                }
            }
        }
        bytes.len()
    }

    /// Whether a completed slice still has contouring to do (with
    /// [`EngineConfig::defer_contouring`]): call [`Link::contour`] before
    /// feeding more.
    pub fn busy(&self) -> bool {
        self.dev.stream.busy()
    }

    /// Contour whole rows of subgrids of the slice completed last, at
    /// least one and until about `cells` cells are done (a row is one row
    /// of cells of one plane, `nx - 1` or `ny - 1` of them; a slice of
    /// `n x n` owes about `3 n` rows). Returns whether some are left.
    pub fn contour(&mut self, cells: usize) -> bool {
        self.dev.stream.work(self.back, cells)
    }

    /// As [`Link::contour`], one whole row and then more while
    /// `more(cells done so far)` says so: for a time budget, as the firmware
    /// keeps one (making the contourer for a call costs about as much as a
    /// short row, so a call should do more than one when it can).
    pub fn contour_while(&mut self, more: impl FnMut(usize) -> bool) -> bool {
        self.dev.stream.work_while(self.back, more)
    }

    /// Move answer bytes for the UART into `out`; returns how many.
    pub fn transmit(&mut self, out: &mut [u8]) -> usize {
        let mut n = 0;
        for slot in out.iter_mut() {
            let Some(b) = self.dev.tx.pop_front() else { break };
            *slot = b;
            n += 1;
        }
        n
    }

    /// Answer bytes waiting.
    pub fn pending(&self) -> usize {
        self.dev.tx.len()
    }
}

impl Device<'_> {
    fn state(&self) -> DeviceState {
        match (self.stream.transfer.is_some(), self.shown.is_some()) {
            (true, _) => DeviceState::Receiving,
            (false, true) => DeviceState::Showing,
            (false, false) => DeviceState::Idle,
        }
    }

    /// The refresh rate from the last counted frame and the playback rate.
    fn refresh(&mut self) {
        let fps = self.frame.fps(self.playback_hz as f32);
        self.refresh_centi_hz = (fps * 100.0).clamp(0.0, f32::from(u16::MAX)) as u16;
    }

    fn event(&mut self, e: Event) {
        if self.events.push_back(e).is_err() {
            self.counters.events_dropped = self.counters.events_dropped.wrapping_add(1);
        }
    }

    /// Queue a message for the UART, whole or not at all.
    fn send(&mut self, msg: &Message<'_>) {
        let mut buf = [0u8; 96];
        let Ok(frame) = encode(msg, &mut buf) else { return };
        if self.tx.capacity() - self.tx.len() < frame.len() {
            self.counters.tx_dropped = self.counters.tx_dropped.wrapping_add(1);
            return;
        }
        for &b in frame {
            let _ = self.tx.push_back(b);
        }
    }

    fn nack(&mut self, seq: u16, code: NackCode) {
        self.counters.nacks = self.counters.nacks.wrapping_add(1);
        self.event(Event::Nacked { seq, code });
        self.send(&Message::Nack { seq, code });
    }

    fn answer(&mut self, seq: u16, answer: Option<NackCode>) {
        match answer {
            None => self.send(&Message::Ack { seq }),
            Some(code) => self.nack(seq, code),
        }
    }

    fn status(&mut self) {
        let slices = self.stream.transfer.map_or(0, |t| t.z);
        let points = self.shown.map_or(0, |s| s.points);
        let msg = Message::Status {
            seq: self.session.last(),
            state: self.state(),
            slices,
            points,
            refresh_centi_hz: self.refresh_centi_hz,
        };
        self.send(&msg);
    }

    fn abort(&mut self, reason: AbortReason) {
        if let Some(t) = self.stream.transfer.take() {
            self.counters.aborts = self.counters.aborts.wrapping_add(1);
            self.event(Event::Aborted { reason, slices: t.z });
        }
    }

    fn check_timeout(&mut self, now_ms: u32) {
        if let Some(t) = self.stream.transfer
            && now_ms.wrapping_sub(t.last_ms) > self.cfg.transfer_timeout_ms
        {
            self.abort(AbortReason::Timeout);
            self.status();
        }
    }

    fn handle(&mut self, msg: Message<'_>, now_ms: u32, back: &mut Geometry<'_>) {
        let seq = match msg {
            Message::Hello { protocol, .. } => {
                self.abort(AbortReason::Restarted);
                self.session.reset();
                self.event(Event::Hello { protocol });
                self.send(&Message::Hello { protocol: PROTOCOL_VERSION, firmware: self.cfg.firmware });
                self.send(&Message::Capabilities {
                    protocol: PROTOCOL_VERSION,
                    max_slice_samples: self.stream.slice_capacity().min(u32::MAX as usize) as u32,
                    sample_types: self.cfg.sample_types,
                    display_points: self.display_capacity.min(u32::MAX as usize) as u32,
                });
                self.status();
                return;
            }
            Message::BeginVolume { seq, .. }
            | Message::SliceData { seq, .. }
            | Message::EndVolume { seq }
            | Message::SetLevels { seq, .. }
            | Message::SetView { seq, .. }
            | Message::SetBeam { seq, .. } => seq,
            // The MCU's own messages have no business coming in.
            Message::Capabilities { .. }
            | Message::Ack { .. }
            | Message::Nack { .. }
            | Message::Status { .. } => {
                self.nack(self.session.expected(), NackCode::UnknownMessage);
                return;
            }
        };
        match self.session.standing(seq) {
            Standing::Next => {
                let answer = self.apply(msg, now_ms, back).err();
                self.session.answered(seq, answer);
                self.answer(seq, answer);
            }
            Standing::Seen(answer) => {
                self.counters.replays = self.counters.replays.wrapping_add(1);
                match answer {
                    None => self.send(&Message::Ack { seq }),
                    Some(code) => self.send(&Message::Nack { seq, code }),
                }
            }
            Standing::Stale => self.nack(seq, NackCode::Duplicate),
            Standing::Gap => self.nack(seq, NackCode::OutOfOrder),
        }
    }

    /// Apply the next command.
    fn apply(&mut self, msg: Message<'_>, now_ms: u32, back: &mut Geometry<'_>) -> Result<(), NackCode> {
        let volume_data = matches!(msg, Message::BeginVolume { .. } | Message::SliceData { .. });
        if volume_data && self.commit {
            // The last volume is not the picture yet (the next update makes
            // it so, between frames); its surface is still in the back.
            return Err(NackCode::Busy);
        }
        match msg {
            Message::BeginVolume { dims, sample_type, spacing, levels, axes, every, .. } => {
                self.abort(AbortReason::Superseded);
                let levels = if levels.is_empty() { self.levels } else { levels };
                let spec = VolumeSpec { dims, sample_type, spacing, levels, axes, every: every.max(1) };
                if self.cfg.sample_types & sample_type.bit() == 0 {
                    return Err(NackCode::Invalid);
                }
                spec.check(self.stream.slice_capacity(), self.stream.row_capacity())?;
                let shift = Geometry::shift_for(dims);
                back.reset(shift);
                self.stream.begin(spec, now_ms, shift);
                self.event(Event::Begun { dims, sample_type, levels: levels.len() as u8 });
                Ok(())
            }
            Message::SliceData { slice, offset, data, .. } => {
                self.stream.chunk(slice, offset, data, now_ms, back, self.cfg.defer_contouring)
            }
            Message::EndVolume { .. } => {
                self.stream.finish(back);
                let t = self.stream.transfer.ok_or(NackCode::Aborted)?;
                if t.z < t.spec.dims[2] {
                    self.abort(AbortReason::Missing);
                    return Err(NackCode::Missing);
                }
                self.stream.transfer = None;
                let [nx, ny, nz] = t.spec.dims.map(usize::from);
                let bounds = Bounds::of_volume(nx, ny, nz)
                    .unwrap_or(Bounds::new(Point3::new(0.0, 0.0, 0.0), Point3::new(1.0, 1.0, 1.0)));
                self.shown = Some(Shown { dims: t.spec.dims, spacing: t.spec.spacing, points: 0, bounds });
                self.commit = true;
                self.counters.volumes = self.counters.volumes.wrapping_add(1);
                let spilled = self.stream.spilled();
                self.event(Event::Committed {
                    dims: t.spec.dims,
                    commands: (back.len() + spilled.len()) as u32,
                    dropped: back.dropped().saturating_add(spilled.dropped()),
                    nonfinite_cells: t.stats.nonfinite_cells.min(u64::from(u32::MAX)) as u32,
                });
                Ok(())
            }
            Message::SetLevels { levels, .. } => {
                if levels.is_empty() || !levels.as_slice().iter().all(|l| l.is_finite()) {
                    return Err(NackCode::Invalid);
                }
                self.levels = levels;
                self.event(Event::LevelsSet);
                Ok(())
            }
            Message::SetView { yaw, pitch, roll, fov_deg, spin_deg_per_s, .. } => {
                let projection = if fov_deg == 0.0 {
                    Projection::Orthographic
                } else {
                    Projection::Perspective { fov_deg }
                };
                let view = View { yaw, pitch, roll, projection, ..self.view };
                let unit = Bounds { min: Point3::new(0.0, 0.0, 0.0), max: Point3::new(1.0, 1.0, 1.0) };
                if ViewTransform::fit(&view, unit).is_err() || !spin_deg_per_s.is_finite() {
                    return Err(NackCode::Invalid);
                }
                self.view = view;
                self.spin_deg_per_s = spin_deg_per_s;
                self.spin_epoch_ms = now_ms;
                self.dirty = true;
                self.event(Event::ViewSet);
                Ok(())
            }
            Message::SetBeam { lit_step, dwell_us, settle_us, .. } => {
                let per_us = self.cfg.sample_rate_hz as f32 / 1e6;
                let samples =
                    |us: u16| libm::roundf(f32::from(us) * per_us).clamp(1.0, f32::from(u16::MAX)) as u16;
                let beam = BeamConfig {
                    lit_step: f32::from(lit_step),
                    point_dwell: samples(dwell_us),
                    settle_base: f32::from(settle_us) * per_us,
                    ..self.beam
                };
                beam.validate().map_err(|_| NackCode::Invalid)?;
                self.beam = beam;
                self.dirty = true;
                self.event(Event::BeamSet);
                Ok(())
            }
            // Handled before.
            Message::Hello { .. }
            | Message::Capabilities { .. }
            | Message::Ack { .. }
            | Message::Nack { .. }
            | Message::Status { .. } => Err(NackCode::UnknownMessage),
        }
    }
}
