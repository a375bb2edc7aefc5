//! The board's engine on the host: its memory on the heap
//! ([`HostBuffers`]), and a board in process ([`InProcess`]) that is handed
//! the very messages `send` puts on the wire ([`crate::link::volume_messages`])
//! whole ([`Engine::accept_all`]), through the engine's session, streaming
//! contourer, stitch and order passes. Only the line is left out: encoding
//! each message into its frame and decoding it again, a fifth of a large
//! picture's work, gives the same message back (the wire's tests and the
//! `message_roundtrip` fuzz target), and the virtual board (`device`) and
//! the firmware take the frames themselves. Every host command that draws a picture (`render`,
//! `stats`, `wav`, `contour --format svg`, `render --animate`) draws it
//! this way, so its samples are the board's.

use crate::link::{SendConfig, WireVolume, volume_messages};
use crate::progress::Progress;
use anyhow::{Context, Result, bail};
use isoscope_core::engine::{Buffers, Capacity, Engine, EngineConfig, Event, Geometry, RowMemory};
use isoscope_core::view::View;
use isoscope_core::wire::{Levels, MAX_LEVELS, Message, NackCode, PROTOCOL_VERSION};
use std::mem::ManuallyDrop;
use std::ptr::NonNull;

/// The engine's memory on the heap.
#[derive(Debug)]
pub struct HostBuffers {
    slices: Vec<u8>,
    rows: Box<RowMemory>,
    surfaces: Vec<u8>,
    scratch: Vec<u8>,
}

impl HostBuffers {
    /// Memory of `capacity`.
    pub fn new(capacity: &Capacity) -> Self {
        Self {
            slices: vec![0; 2 * capacity.slice_bytes],
            rows: Box::default(),
            surfaces: vec![0; 2 * Geometry::bytes_for(capacity.points)],
            scratch: vec![0; capacity.scratch_bytes],
        }
    }

    /// The buffers, lent to an engine.
    pub fn buffers(&mut self) -> Buffers<'_> {
        Buffers::halves(&mut self.slices, &mut self.rows, &mut self.surfaces, &mut self.scratch)
    }
}

/// A board in process that owns its memory ([`HostBuffers`]), so that it
/// can be kept between calls: the web page turns one with `SetView` while
/// its view spins, as the board itself does. [`OwnedBoard::with`] lends the
/// board out.
#[derive(Debug)]
pub struct OwnedBoard {
    /// The board, borrowing `*mem` until it is dropped (first, in `Drop`).
    board: ManuallyDrop<InProcess<'static>>,
    /// The board's memory: a leaked `Box`, freed in `Drop` after the board.
    mem: NonNull<HostBuffers>,
}

impl OwnedBoard {
    /// A board of `capacity` with `cfg`, greeted, showing nothing
    /// ([`InProcess::new`]).
    ///
    /// # Errors
    /// As [`InProcess::new`].
    pub fn new(capacity: &Capacity, cfg: EngineConfig) -> Result<Self> {
        let mem = NonNull::from(Box::leak(Box::new(HostBuffers::new(capacity))));
        // SAFETY: `mem` is a live allocation that nothing else reaches; the
        // board's borrow of it ends when the board is dropped, which `Drop`
        // does before freeing it (and the error path below, the board not
        // made). `with` lends the board only for a lifetime its caller
        // cannot name, so no board outlives `self` or changes places.
        match InProcess::new(unsafe { &mut *mem.as_ptr() }, cfg) {
            Ok(board) => Ok(Self { board: ManuallyDrop::new(board), mem }),
            Err(e) => {
                // SAFETY: from `Box::leak` above; no borrow of it is left.
                drop(unsafe { Box::from_raw(mem.as_ptr()) });
                Err(e)
            }
        }
    }

    /// `f` of the board.
    pub fn with<R>(&mut self, f: impl for<'b> FnOnce(&mut InProcess<'b>) -> R) -> R {
        f(&mut self.board)
    }

    /// The board, to read.
    pub fn board(&self) -> &InProcess<'_> {
        &self.board
    }
}

impl Drop for OwnedBoard {
    fn drop(&mut self) {
        // SAFETY: the board is dropped once, here, before the memory it
        // borrows is freed; the memory came from `Box::leak` in `new`.
        unsafe {
            ManuallyDrop::drop(&mut self.board);
            drop(Box::from_raw(self.mem.as_ptr()));
        }
    }
}

/// Room on the host for `points` points a surface, with the scratch to
/// stitch and order them all (8 bytes a point), for slices of `slice_bytes`
/// (volumes fitted to rows of `extent`).
pub fn host_capacity(slice_bytes: usize, extent: usize, points: usize) -> Capacity {
    Capacity { slice_bytes, extent, points, scratch_bytes: 8 * points }
}

/// What the board did with the last volume, from its events.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Loaded {
    /// Contour commands kept (in the received surface and the slice memory).
    pub commands: u32,
    /// Contour commands with no room (the picture lacks them).
    pub dropped: u32,
    /// Subgrids skipped for NaN or infinite samples.
    pub nonfinite_cells: u32,
    /// Points of the stitched picture.
    pub points: u32,
    /// Points the picture had no room for (it is cut short).
    pub cut: u32,
    /// False when there was too little scratch to stitch and order.
    pub ordered: bool,
    /// The slice stride the volume asked for.
    pub asked: u16,
    /// The slice stride drawn: coarser than asked when the surface did not
    /// fit (every other slice of each plane dropped, each time).
    pub every: u16,
    /// Seconds: the transfer (decoding and contouring, slice by slice), and
    /// the commit (stitch, order, count a frame).
    pub seconds: [f64; 2],
}

impl Loaded {
    /// Whether the whole surface is drawn, at the stride asked, stitched
    /// and ordered.
    pub fn whole(&self) -> bool {
        self.dropped == 0 && self.cut == 0 && self.ordered && !self.thinned()
    }

    /// Whether the surface was drawn at a coarser stride than asked.
    pub fn thinned(&self) -> bool {
        self.every > self.asked
    }
}

/// A board in process: the engine, handed messages whole.
#[derive(Debug)]
pub struct InProcess<'a> {
    engine: Engine<'a>,
    /// The next command's sequence number.
    seq: u16,
    now_ms: u32,
    loaded: Loaded,
}

impl<'a> InProcess<'a> {
    /// A board over `mem` with `cfg`, greeted (`Hello`), showing nothing.
    ///
    /// # Errors
    /// Invalid settings or buffers.
    pub fn new(mem: &'a mut HostBuffers, cfg: EngineConfig) -> Result<Self> {
        let engine = Engine::new(cfg, mem.buffers()).context("cannot start the engine")?;
        let mut board = Self { engine, seq: 0, now_ms: 0, loaded: Loaded::default() };
        board.feed(&Message::Hello { protocol: PROTOCOL_VERSION, firmware: [0; 3], seq: 0 })?;
        Ok(board)
    }

    /// The engine.
    pub fn engine(&self) -> &Engine<'a> {
        &self.engine
    }

    /// What the last volume came to.
    pub fn loaded(&self) -> Loaded {
        self.loaded
    }

    /// Hand `msg` to the engine as if its frame had come over the UART,
    /// doing the contouring it defers; its answers are dropped, its events
    /// read.
    ///
    /// # Errors
    /// The board refused the command (a `Nack`).
    ///
    /// Contouring that waits for the engine (to fold the surface arriving,
    /// [`Link::waits`](isoscope_core::engine::Link::waits)) gets its update at once, and a command answered
    /// `Busy` meanwhile is sent again, as a sender would.
    fn feed(&mut self, msg: &Message<'_>) -> Result<()> {
        for _ in 0..BUSY_RETRIES {
            if !self.engine.accept_all(msg, self.now_ms) {
                bail!("the engine took no more messages (a volume's command left untaken)");
            }
            let mut sink = [0u8; 256];
            while self.engine.transmit(&mut sink) > 0 {}
            match self.events() {
                Err(e) if e.downcast_ref::<Refused>().is_some_and(|r| r.0 == NackCode::Busy) => {
                    self.engine.update(self.now_ms);
                }
                r => return r,
            }
        }
        Err(Refused(NackCode::Busy).into())
    }

    /// Read the engine's events into `loaded`; the first refusal is an
    /// error.
    fn events(&mut self) -> Result<()> {
        let mut refused = None;
        while let Some(ev) = self.engine.next_event() {
            match ev {
                Event::Committed { commands, dropped, nonfinite_cells, asked, every, .. } => {
                    let asked = u16::from(asked.max(1));
                    self.loaded =
                        Loaded { commands, dropped, nonfinite_cells, asked, every, ..Loaded::default() };
                }
                Event::Stitched { points, cut, ordered, every, .. } => {
                    self.loaded = Loaded { points, cut, ordered, every, ..self.loaded };
                }
                Event::Nacked { code, .. } => {
                    refused.get_or_insert(code);
                }
                _ => {}
            }
        }
        match refused {
            None => Ok(()),
            Some(code) => Err(Refused(code).into()),
        }
    }

    /// Put `vol` on the board as `send` would with `cfg` (its levels, axes,
    /// stride, chunk and view), and make it the picture; `progress` counts
    /// the frames fed ([`frames_for`]).
    ///
    /// # Errors
    /// More than [`MAX_LEVELS`] levels, or the board refuses the volume
    /// (a slice larger than it holds, invalid levels or view).
    pub fn load(
        &mut self,
        vol: &WireVolume,
        cfg: &SendConfig,
        progress: Option<&Progress>,
    ) -> Result<Loaded> {
        // Not giving up, it always has a picture to report.
        self.load_or_give_up(vol, cfg, progress, false).map(Option::unwrap_or_default)
    }

    /// [`InProcess::load`], given up, when `give_up` is set, as soon as
    /// the surface has outgrown the board's memory ([`Engine::outgrown`]):
    /// `None` then, and the board left in the middle of the transfer. For
    /// a memory that grows: the picture would not have been whole, so the
    /// rest of the volume need not be contoured before trying a larger one.
    ///
    /// # Errors
    /// As [`InProcess::load`].
    pub fn load_or_give_up(
        &mut self,
        vol: &WireVolume,
        cfg: &SendConfig,
        progress: Option<&Progress>,
        give_up: bool,
    ) -> Result<Option<Loaded>> {
        let levels = Levels::from_slice(&cfg.levels)
            .with_context(|| format!("at most {MAX_LEVELS} levels go to the board"))?;
        let t0 = web_time::Instant::now();
        for msg in volume_messages(vol, cfg, levels, self.seq) {
            self.seq = msg_seq(&msg).wrapping_add(1);
            self.feed(&msg)?;
            if let Some(p) = progress {
                p.inc();
            }
            if give_up && self.engine.outgrown() {
                return Ok(None);
            }
        }
        let t1 = web_time::Instant::now();
        self.engine.update(self.now_ms);
        self.loaded.seconds = [(t1 - t0).as_secs_f64(), t1.elapsed().as_secs_f64()];
        self.events()?;
        Ok(Some(self.loaded))
    }

    /// Set the view's angles and projection, as `send --yaw ...` does
    /// (`SetView`), and redraw.
    ///
    /// # Errors
    /// The board refuses the view.
    pub fn set_view(&mut self, view: &View) -> Result<()> {
        let fov_deg = match view.projection {
            isoscope_core::view::Projection::Orthographic => 0.0,
            isoscope_core::view::Projection::Perspective { fov_deg } => fov_deg,
        };
        let msg = Message::SetView {
            seq: self.seq,
            yaw: view.yaw,
            pitch: view.pitch,
            roll: view.roll,
            fov_deg,
            spin_deg_per_s: 0.0,
        };
        self.seq = self.seq.wrapping_add(1);
        self.feed(&msg)?;
        self.engine.update(self.now_ms);
        self.events()
    }
}

/// Times [`InProcess`] sends a command again that was answered `Busy`
/// (each after an update: the engine has folded the surface or lent the
/// memory back by then, so once is enough).
const BUSY_RETRIES: usize = 4;

/// Frames [`InProcess::load`] feeds for `vol` with `cfg`.
pub fn frames_for(vol: &WireVolume, cfg: &SendConfig) -> usize {
    volume_messages(vol, cfg, Levels::new(), 0).count()
}

/// A command's sequence number.
fn msg_seq(msg: &Message<'_>) -> u16 {
    match *msg {
        Message::BeginVolume { seq, .. }
        | Message::SliceData { seq, .. }
        | Message::EndVolume { seq }
        | Message::SetLevels { seq, .. }
        | Message::SetView { seq, .. }
        | Message::SetBeam { seq, .. }
        | Message::Ack { seq }
        | Message::Nack { seq, .. }
        | Message::Status { seq, .. } => seq,
        Message::Hello { .. } | Message::Capabilities { .. } => 0,
    }
}

/// The board refused a command (it answered `Nack` with this code).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Refused(pub NackCode);

impl std::fmt::Display for Refused {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "the board refused it: {}", refusal(self.0))
    }
}

impl std::error::Error for Refused {}

/// What a refusal means, in a user's words.
pub fn refusal(code: NackCode) -> &'static str {
    match code {
        NackCode::DimsOverCapacity => "the volume's slices are larger than the board holds",
        NackCode::Invalid => "invalid settings (levels, planes, stride, spacing or view)",
        NackCode::Busy => "busy with the last volume",
        NackCode::Missing => "slices were missing at the end",
        NackCode::Aborted => "the transfer was abandoned",
        NackCode::BadCrc | NackCode::Truncated | NackCode::Oversize | NackCode::UnknownMessage => {
            "a damaged frame"
        }
        NackCode::BadVersion => "another protocol version",
        NackCode::OutOfOrder | NackCode::Duplicate => "a command out of sequence",
    }
}

/// Check `levels` against what one volume on a board takes.
///
/// # Errors
/// None, or more than [`MAX_LEVELS`].
pub fn check_levels(levels: &[f32]) -> Result<()> {
    if levels.is_empty() {
        bail!("no contour level");
    }
    if levels.len() > MAX_LEVELS {
        bail!("{} levels given; a board draws at most {MAX_LEVELS} at once", levels.len());
    }
    Ok(())
}
