//! The device engine: the board's whole behaviour behind the UART, heap-free,
//! the same code on the MCU and in the simulator.
//!
//! Fed received bytes and the time, it
//!
//! - decodes frames ([`crate::wire`]), takes commands strictly in `seq`
//!   order, answers each with `Ack` or `Nack` (answering a retransmission
//!   again from memory, without applying it twice);
//! - streams a volume one z slice at a time through two slice buffers,
//!   contouring each slice as it completes (see [`stream`](self) below), so
//!   volumes deeper than RAM work;
//! - keeps the committed surface in voxel coordinates ([`Geometry`]), two of
//!   them: the one on screen stays untouched until a new volume is complete,
//!   so an aborted, corrupt or abandoned transfer never costs the picture;
//! - re-projects the surface when the view changes (no volume needed) and
//!   builds the display list: project, cull, stitch, merge, order.
//!
//! What it answers is queued as bytes for the UART ([`Engine::transmit`]):
//! an `Ack` or `Nack` for every command, and a `Status` once a new volume's
//! picture is drawn (so the host can time "last slice to picture") or a
//! transfer is abandoned;
//! what happened is queued as [`Event`]s for a log ([`Engine::next_event`]).
//!
//! The caller owns the memory ([`Buffers`]; [`StaticBuffers`] holds it in
//! arrays for the MCU) and the clock (milliseconds, wrapping).
//!
//! Changing the levels needs the volume again (they apply to the next
//! volume); changing the view or the beam does not.

mod geometry;
mod session;
mod stream;

pub use geometry::Geometry;
pub use session::REPLAY;
pub use stream::VolumeSpec;

use crate::beam::{BeamConfig, BeamConfigError, Scheduler, frame_stats};
use crate::command::{Command, Point3};
use crate::display::{DisplayStore, OptimizeConfig, OrderConfig, ScratchStore};
use crate::screen::ScreenPoint;
use crate::view::{Bounds, Projection, View, ViewError, ViewTransform};
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

/// The display list the engine draws: the core's [`DisplayStore`] over
/// caller memory.
pub type ScreenList<'a> = DisplayStore<&'a mut [ScreenPoint], &'a mut [u8]>;

/// Scratch for optimising and ordering the display list, over caller memory.
pub type ScreenScratch<'a> = ScratchStore<&'a mut [u32], &'a mut [u64], &'a mut [ScreenPoint], &'a mut [u8]>;

/// The engine's memory, lent by the caller.
///
/// - `slices`: two slice buffers of raw sample bytes; each sets the largest
///   slice, `nx * ny * sample size` bytes.
/// - `rows`: two row buffers; each sets the largest `nx` and `ny`.
/// - `geometry`: two surfaces (on screen, being received) of points and
///   command kinds, 13 bytes a command.
/// - `screen`: the display list (9 bytes a point) and `scratch` (32 bytes a
///   point, at least the display list's capacity).
#[derive(Debug)]
pub struct Buffers<'a> {
    /// The previous and the current slice.
    pub slices: [&'a mut [u8]; 2],
    /// Two rows of samples widened to `f32`.
    pub rows: [&'a mut [f32]; 2],
    /// Two surfaces: points and their command kinds.
    pub geometry: [(&'a mut [Point3], &'a mut [u8]); 2],
    /// The display list's points and flags.
    pub screen: (&'a mut [ScreenPoint], &'a mut [u8]),
    /// Scratch for the display list.
    pub scratch: ScreenScratch<'a>,
}

/// The engine's memory in arrays, for a `static` on the MCU.
///
/// - `SLICE`: bytes in one slice (`nx * ny * sample size`), twice.
/// - `EXTENT`: the largest `nx` or `ny`.
/// - `POINTS`: commands in each of the two surfaces, and points in the
///   display list.
///
/// It takes `2 * SLICE + 8 * EXTENT + 67 * POINTS` bytes.
#[derive(Debug, Clone, PartialEq)]
pub struct StaticBuffers<const SLICE: usize, const EXTENT: usize, const POINTS: usize> {
    slices: [[u8; SLICE]; 2],
    rows: [[f32; EXTENT]; 2],
    points: [[Point3; POINTS]; 2],
    kinds: [[u8; POINTS]; 2],
    screen: [ScreenPoint; POINTS],
    flags: [u8; POINTS],
    index: [[u32; POINTS]; 4],
    edges: [u64; POINTS],
    back: [ScreenPoint; POINTS],
    back_flags: [u8; POINTS],
}

impl<const SLICE: usize, const EXTENT: usize, const POINTS: usize> StaticBuffers<SLICE, EXTENT, POINTS> {
    /// Zeroed buffers.
    pub const fn new() -> Self {
        Self {
            slices: [[0; SLICE]; 2],
            rows: [[0.0; EXTENT]; 2],
            points: [[Point3::new(0.0, 0.0, 0.0); POINTS]; 2],
            kinds: [[0; POINTS]; 2],
            screen: [ScreenPoint::new(0.0, 0.0); POINTS],
            flags: [0; POINTS],
            index: [[0; POINTS]; 4],
            edges: [0; POINTS],
            back: [ScreenPoint::new(0.0, 0.0); POINTS],
            back_flags: [0; POINTS],
        }
    }

    /// The buffers, lent to an [`Engine`].
    pub fn buffers(&mut self) -> Buffers<'_> {
        let [s0, s1] = &mut self.slices;
        let [r0, r1] = &mut self.rows;
        let [p0, p1] = &mut self.points;
        let [k0, k1] = &mut self.kinds;
        let [a, b, c, d] = &mut self.index;
        Buffers {
            slices: [s0, s1],
            rows: [r0, r1],
            geometry: [(p0, k0), (p1, k1)],
            screen: (&mut self.screen, &mut self.flags),
            scratch: ScratchStore::with_storage(
                a,
                b,
                c,
                d,
                &mut self.edges,
                &mut self.back,
                &mut self.back_flags,
            ),
        }
    }
}

impl<const SLICE: usize, const EXTENT: usize, const POINTS: usize> Default
    for StaticBuffers<SLICE, EXTENT, POINTS>
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
    /// Display-list optimisation.
    pub optimize: OptimizeConfig,
    /// Display-list ordering (its `start` is replaced by the park position).
    pub order: OrderConfig,
    /// A transfer with no accepted message for this long is abandoned (ms).
    pub transfer_timeout_ms: u32,
}

impl Default for EngineConfig {
    /// Every sample type, 1 MS/s, the default view, beam and passes, and a
    /// 5 s transfer timeout.
    fn default() -> Self {
        Self {
            firmware: [0, 1, 0],
            sample_types: SampleType::ALL.iter().fold(0, |m, t| m | t.bit()),
            sample_rate_hz: 1_000_000,
            view: View::DEFAULT,
            beam: BeamConfig::default(),
            optimize: OptimizeConfig::default(),
            order: OrderConfig::default(),
            transfer_timeout_ms: 5_000,
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
    /// A slice or row buffer is too small for a 2x2 slice of `f32`, or the
    /// scratch is smaller than the display list.
    Buffers,
}

impl core::fmt::Display for EngineError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Beam(e) => write!(f, "invalid beam settings: {e}"),
            Self::View(e) => write!(f, "invalid view: {e}"),
            Self::Buffers => f.write_str("engine buffers too small (slices, rows or scratch)"),
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
    /// The display list was rebuilt (new volume or view).
    Redrawn {
        /// Polylines drawn.
        polylines: u32,
        /// Points drawn.
        points: u32,
        /// Points that did not fit the display list.
        dropped: u32,
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
            Self::Aborted { reason, slices } => write!(f, "aborted slices={slices} reason={reason}"),
            Self::Nacked { seq, code } => write!(f, "nack seq={seq} code={code:?}"),
            Self::FrameError { error } => write!(f, "bad frame: {error}"),
            Self::LevelsSet => f.write_str("levels set (for the next volume)"),
            Self::ViewSet => f.write_str("view set"),
            Self::BeamSet => f.write_str("beam set"),
            Self::Redrawn { polylines, points, dropped, refresh_centi_hz } => write!(
                f,
                "redrawn polylines={polylines} points={points} dropped={dropped} refresh_hz={}.{:02}",
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
}

/// Everything but the frame decoder and the display list.
#[derive(Debug)]
struct Device<'a> {
    cfg: EngineConfig,
    session: Session,
    stream: Stream<'a>,
    geometry: [Geometry<'a>; 2],
    /// The surface on screen (the other one receives).
    front: usize,
    shown: Option<Shown>,
    view: View,
    spin_deg_per_s: f32,
    /// When `view.yaw` held (ms), for the spin.
    spin_epoch_ms: u32,
    beam: BeamConfig,
    levels: Levels,
    /// The display list must be rebuilt.
    dirty: bool,
    /// A volume was committed: report the status once its picture is drawn.
    status_due: bool,
    display_capacity: usize,
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
    list: ScreenList<'a>,
    scratch: ScreenScratch<'a>,
    generation: u32,
}

/// The picture half of an [`Engine`] ([`Engine::split`]): the display list
/// and the beam settings it is played with.
#[derive(Debug, Clone, Copy)]
pub struct Screen<'e, 'a> {
    list: &'e ScreenList<'a>,
    beam: BeamConfig,
}

impl<'e> Screen<'e, '_> {
    /// One frame, as [`Engine::frame`].
    pub fn frame(&self) -> Scheduler<impl Iterator<Item = Command<ScreenPoint>> + 'e> {
        frame(self.list, &self.beam)
    }

    /// The display list.
    pub fn display(&self) -> &'e ScreenList<'_> {
        self.list
    }

    /// The beam settings.
    pub fn beam(&self) -> &BeamConfig {
        &self.beam
    }
}

fn frame<'e>(
    list: &'e ScreenList<'_>,
    beam: &BeamConfig,
) -> Scheduler<impl Iterator<Item = Command<ScreenPoint>> + 'e> {
    Scheduler::new(list.commands(), beam)
}

/// The receiving half of an [`Engine`] ([`Engine::split`]): feeding bytes
/// while the display list is being drawn.
#[derive(Debug)]
pub struct Link<'e, 'a> {
    decoder: &'e mut ProtocolDecoder,
    dev: &'e mut Device<'a>,
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
        let Buffers { slices, rows, geometry: [(p0, k0), (p1, k1)], screen, scratch } = buffers;
        let stream = Stream::new(slices, rows);
        let list = DisplayStore::with_storage(screen.0, screen.1);
        let mut scratch = scratch;
        if stream.slice_capacity() < 16 || stream.row_capacity() < 2 || !scratch.fits(list.capacity()) {
            return Err(EngineError::Buffers);
        }
        let display_capacity = list.capacity();
        Ok(Self {
            decoder: ProtocolDecoder::new(),
            dev: Device {
                cfg,
                session: Session::new(),
                stream,
                geometry: [Geometry::new(p0, k0), Geometry::new(p1, k1)],
                front: 0,
                shown: None,
                view: cfg.view,
                spin_deg_per_s: 0.0,
                spin_epoch_ms: 0,
                beam: cfg.beam,
                levels: Levels::new(),
                dirty: false,
                status_due: false,
                display_capacity,
                refresh_centi_hz: 0,
                tx: Deque::new(),
                events: Deque::new(),
                counters: Counters::default(),
            },
            list,
            scratch,
            generation: 0,
        })
    }

    /// The receiving half and the picture, borrowed apart, so that the beam
    /// can play frames while bytes are fed. What the bytes change (a new
    /// volume, view or beam) shows after the next [`Engine::update`].
    pub fn split(&mut self) -> (Link<'_, 'a>, Screen<'_, 'a>) {
        let beam = self.dev.beam;
        (Link { decoder: &mut self.decoder, dev: &mut self.dev }, Screen { list: &self.list, beam })
    }

    /// Take received bytes at time `now_ms`: see [`Link::feed`].
    pub fn feed(&mut self, bytes: &[u8], now_ms: u32) {
        self.split().0.feed(bytes, now_ms);
    }

    /// Move answer bytes for the UART into `out`; returns how many.
    pub fn transmit(&mut self, out: &mut [u8]) -> usize {
        self.split().0.transmit(out)
    }

    /// The oldest event not yet taken.
    pub fn next_event(&mut self) -> Option<Event> {
        self.dev.events.pop_front()
    }

    /// Between frames: abandon a stalled transfer, turn a spinning view, and
    /// rebuild the display list if the picture or the view changed. Returns
    /// whether the display list changed.
    pub fn update(&mut self, now_ms: u32) -> bool {
        self.dev.check_timeout(now_ms);
        let spinning = self.dev.spin_deg_per_s != 0.0 && self.dev.shown.is_some();
        if !(self.dev.dirty || spinning) {
            return false;
        }
        self.dev.dirty = false;
        self.rebuild(now_ms);
        true
    }

    /// Project the surface on screen under the current view, cull, stitch,
    /// merge and order it.
    fn rebuild(&mut self, now_ms: u32) {
        let dev = &mut self.dev;
        self.list.clear();
        self.list.reset_counters();
        self.generation = self.generation.wrapping_add(1);
        let Some(shown) = dev.shown else { return };
        let elapsed_s = now_ms.wrapping_sub(dev.spin_epoch_ms) as f32 / 1000.0;
        let turn = libm::fmodf(dev.spin_deg_per_s * elapsed_s, 360.0);
        let view = View { spacing: shown.spacing, bits: dev.beam.bits, ..dev.view }.yawed(turn);
        let [nx, ny, nz] = shown.dims.map(usize::from);
        let fitted = Bounds::of_volume(nx, ny, nz).and_then(|b| {
            // A spinning view fits its bounding sphere, so it does not breathe.
            if dev.spin_deg_per_s != 0.0 {
                ViewTransform::fit_sphere(&view, b)
            } else {
                ViewTransform::fit(&view, b)
            }
        });
        let Ok(vt) = fitted else { return };
        for c in dev.geometry.get(dev.front).into_iter().flat_map(Geometry::commands) {
            let _ = self.list.push(c.map(|p| vt.project(p)));
        }
        self.list.optimize(&mut self.scratch, &dev.cfg.optimize);
        let park = dev.beam.park_sample();
        let start = ScreenPoint::new(f32::from(park.x), f32::from(park.y));
        self.list.order(&mut self.scratch, &OrderConfig { start, ..dev.cfg.order });
        let fps = frame_stats(self.list.commands(), &dev.beam).fps(dev.cfg.sample_rate_hz as f32);
        dev.refresh_centi_hz = (fps * 100.0).clamp(0.0, f32::from(u16::MAX)) as u16;
        dev.event(Event::Redrawn {
            polylines: self.list.polyline_count() as u32,
            points: self.list.len() as u32,
            dropped: self.list.dropped().min(u64::from(u32::MAX)) as u32,
            refresh_centi_hz: dev.refresh_centi_hz,
        });
        if core::mem::take(&mut dev.status_due) {
            dev.status();
        }
    }

    /// The display list on screen, in drawing order.
    pub fn display(&self) -> &ScreenList<'a> {
        &self.list
    }

    /// One frame of the picture as the board plays it: the beam schedule of
    /// the display list, from the park position back to it (blanked). The
    /// board plays it over and over, and the park position between frames
    /// when there is nothing to show. Every board (the firmware, the
    /// simulator's virtual board) plays exactly these samples.
    pub fn frame(&self) -> Scheduler<impl Iterator<Item = Command<ScreenPoint>> + '_> {
        frame(&self.list, &self.dev.beam)
    }

    /// Counts up each time the display list is rebuilt.
    pub fn generation(&self) -> u32 {
        self.generation
    }

    /// The beam settings in force.
    pub fn beam(&self) -> &BeamConfig {
        &self.dev.beam
    }

    /// The surface on screen, in voxel coordinates.
    pub fn surface(&self) -> Option<&Geometry<'a>> {
        self.dev.shown.and(self.dev.geometry.get(self.dev.front))
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
    /// Take received bytes at time `now_ms` (milliseconds, wrapping): decode
    /// frames, apply commands, queue answers and events. Never panics, for
    /// any bytes.
    pub fn feed(&mut self, bytes: &[u8], now_ms: u32) {
        self.dev.check_timeout(now_ms);
        for &b in bytes {
            match self.decoder.push(b) {
                None => {}
                Some(Ok(msg)) => {
                    self.dev.counters.frames = self.dev.counters.frames.wrapping_add(1);
                    self.dev.handle(msg, now_ms);
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
        let points = self.geometry.get(self.front).map_or(0, |g| g.len() as u32);
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
        if let Some(t) = self.stream.transfer {
            if now_ms.wrapping_sub(t.last_ms) > self.cfg.transfer_timeout_ms {
                self.abort(AbortReason::Timeout);
                self.status();
            }
        }
    }

    fn handle(&mut self, msg: Message<'_>, now_ms: u32) {
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
                let answer = self.apply(msg, now_ms).err();
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
    fn apply(&mut self, msg: Message<'_>, now_ms: u32) -> Result<(), NackCode> {
        match msg {
            Message::BeginVolume { dims, sample_type, spacing, levels, axes, every, .. } => {
                self.abort(AbortReason::Superseded);
                let levels = if levels.is_empty() { self.levels } else { levels };
                let spec = VolumeSpec { dims, sample_type, spacing, levels, axes, every: every.max(1) };
                if self.cfg.sample_types & sample_type.bit() == 0 {
                    return Err(NackCode::Invalid);
                }
                spec.check(self.stream.slice_capacity(), self.stream.row_capacity())?;
                if let Some(g) = self.geometry.get_mut(1 - self.front) {
                    g.clear();
                }
                self.stream.begin(spec, now_ms);
                self.event(Event::Begun { dims, sample_type, levels: levels.len() as u8 });
                Ok(())
            }
            Message::SliceData { slice, offset, data, .. } => {
                let back = self.geometry.get_mut(1 - self.front).ok_or(NackCode::Busy)?;
                self.stream.chunk(slice, offset, data, now_ms, back)
            }
            Message::EndVolume { .. } => {
                let t = self.stream.transfer.ok_or(NackCode::Aborted)?;
                if t.z < t.spec.dims[2] {
                    self.abort(AbortReason::Missing);
                    return Err(NackCode::Missing);
                }
                self.stream.transfer = None;
                self.front = 1 - self.front;
                self.shown = Some(Shown { dims: t.spec.dims, spacing: t.spec.spacing });
                self.dirty = true;
                self.status_due = true;
                self.counters.volumes = self.counters.volumes.wrapping_add(1);
                let (commands, dropped) =
                    self.geometry.get(self.front).map_or((0, 0), |g| (g.len() as u32, g.dropped()));
                self.event(Event::Committed {
                    dims: t.spec.dims,
                    commands,
                    dropped,
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
