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
//! - when a volume is complete, runs the path pipeline ([`crate::path`]:
//!   cull, stitch, merge, splice crossing loops, tour) into the picture
//!   ([`ChainStats`]; the idle slice buffers are the scratch), the tour
//!   made for the screen of the view in force (in space while the view
//!   spins); a later view draws the same tour, costing no more than
//!   projecting each point as the beam reaches it (in space, a projection
//!   never lengthens a jump; a tour made for one screen has no such bound
//!   on another).
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
mod buffers;
mod config;
mod device;
mod event;
mod screen;
mod session;
mod stream;

pub use crate::path::{ChainStats, Commands, Geometry, Kind, Packed};
use crate::path::{Metric, Pass, Source};
pub use board::{Board, Capacity};
pub use buffers::{Buffers, QUIET_ROWS, RowMemory, StaticBuffers};
pub use config::{EngineConfig, EngineError};
use device::{Device, Lend};
pub use event::{AbortReason, Counters, Event};
pub use screen::{Frame, Projected, Screen};
pub use session::REPLAY;
pub use stream::VolumeSpec;

use crate::beam::replay::{self, Kept, Player, Replay};
use crate::beam::{BeamConfig, FrameStats, Scheduler, frame_stats};
use crate::command::Point3;
use crate::view::{Bounds, View, ViewTransform};
use crate::wire::{DeviceState, Levels, Message, NackCode, ProtocolDecoder, WireError};
use heapless::Deque;
use session::Session;
use stream::Stream;

/// Bytes of answers queued for the UART before more are dropped (the sender
/// retransmits what it never heard about).
pub const TX_QUEUE: usize = 512;

/// Events queued before more are dropped (and counted).
pub const EVENT_QUEUE: usize = 16;

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
    /// Extra scratch for [`path::chain`](crate::path).
    scratch: &'a mut [u8],
    /// The slice memory: the stream's, the replay's, or cut between them
    /// ([`Lend`]).
    slices: &'a mut [u8],
    /// What the replay keeps in the slice memory ([`Engine::replay_frames`]).
    kept: Kept,
    /// Where the frame played through a commit stood when it ended
    /// ([`Engine::unfinished`]).
    unfinished: Option<(u32, replay::Mark)>,
    generation: u32,
}

/// Bytes of the tail of a slice memory of `slice_memory` bytes that a
/// still picture's recording may keep while a volume arrives and is
/// committed (9/16 of it: 36,864 of the 64 KB of the STM32F407, a frame
/// of some 18,000 samples, a 55 Hz refresh at 1 MS/s). The rest, the head,
/// holds the volume's two slices and the scratch of its commit; a volume
/// that needs more (larger slices, or a surface larger than the back
/// holds) takes all of it, and the recording is lost.
pub const fn replay_tail(slice_memory: usize) -> usize {
    slice_memory / 16 * 9
}

/// How long after a volume took the slice memory back from the replay the
/// engine waits for it to begin before lending the memory again, in ms: a
/// sender answered `Busy` retries within a fraction of that.
pub const RELEND_MS: u32 = 1000;

/// Thinnings by two, at most, of a recording for a commit
/// ([`Engine::update_playing`]): down to a sixteenth of its samples.
const MAX_THINNING: usize = 4;

/// The receiving half of an [`Engine`] ([`Engine::split`]): feeding bytes
/// while the picture is being drawn.
#[derive(Debug)]
pub struct Link<'e, 'a> {
    decoder: &'e mut ProtocolDecoder,
    dev: &'e mut Device<'a>,
    back: &'e mut Geometry<'a>,
    /// The part of the slice memory the stream has ([`Lend`]).
    slots: &'e mut [u8],
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
        let front = Geometry::new(front);
        let back = Geometry::new(back);
        let stream = Stream::new(slices.len(), rows, front.capacity());
        let tail = replay_tail(slices.len());
        if stream.slice_capacity() < 16 {
            return Err(EngineError::Buffers);
        }
        let display_capacity = front.capacity().min(back.capacity());
        Ok(Self {
            decoder: ProtocolDecoder::new(),
            dev: Device {
                cfg,
                session: Session::new(),
                stream,
                shown: None,
                commit: false,
                commit_waited: false,
                commit_thinned: false,
                fold_waited: false,
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
                replay_frames: false,
                lend: Lend::Stream,
                pieces: 0,
                tail,
                reclaim: None,
                reclaimed_ms: None,
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
            slices,
            kept: Kept::with_tail(tail),
            unfinished: None,
            generation: 0,
        })
    }

    /// The receiving half and the picture, borrowed apart, so that the beam
    /// can play frames while bytes are fed. What the bytes change (a new
    /// volume, view or beam) shows after the next [`Engine::update`].
    pub fn split(&mut self) -> (Link<'_, 'a>, Screen<'_, 'a>) {
        let dev = &self.dev;
        // (With a commit due, only a recording in the tail plays: nothing
        // else is lent to the replay then.)
        // (While the volume arriving has the picture's store, the picture
        // plays from its recording alone, as it stood.)
        // (A picture about to be folded or committed away is held still
        // for a frame, to be recorded: `records_before_fold`,
        // `records_before_commit`.)
        let still = dev.shown.is_some()
            && ((dev.spin_deg_per_s == 0.0 && !dev.dirty)
                || dev.stream.front_taken
                || dev.fold_waited
                || dev.commit_waited);
        // (A picture whose store the volume has plays only if recorded.)
        let key = still.then_some(self.generation).filter(|&k| !dev.stream.front_taken || self.kept.holds(k));
        // A frame kept in the tail plays from the tail alone: the head is
        // the stream's meanwhile, so a volume may begin at once.
        let tail_alone = key.is_some_and(|k| self.kept.holds_in_tail(k));
        let lend = if dev.lend == Lend::Screen && tail_alone { Lend::Tail } else { dev.lend };
        let (slots, lent) = cut(self.slices, lend, dev.tail);
        let screen = Screen {
            front: &self.front,
            transform: self.transform,
            beam: self.dev.beam,
            replay: Replay::new(lent, &mut self.kept),
            key,
        };
        (Link { decoder: &mut self.decoder, dev: &mut self.dev, back: &mut self.back, slots }, screen)
    }

    /// Take received bytes at time `now_ms`: see [`Link::feed`].
    ///
    /// Not deferring ([`EngineConfig::defer_contouring`] off), a volume's
    /// back is folded here when it must be ([`Link::waits`]), so that all
    /// the bytes are taken; deferring, that waits for [`Engine::update`].
    pub fn feed(&mut self, bytes: &[u8], now_ms: u32) -> usize {
        let mut taken = 0;
        loop {
            taken += self.split().0.feed(bytes.get(taken..).unwrap_or_default(), now_ms);
            if self.dev.cfg.defer_contouring || !self.dev.stream.wants_fold() {
                return taken;
            }
            self.fold(&mut |_| {});
            let mut link = self.split().0;
            while !link.waits() && link.contour(usize::MAX) {}
        }
    }

    /// Take all of `bytes` at time `now_ms`, doing on the way what the
    /// engine defers ([`EngineConfig::defer_contouring`]): the contouring
    /// of each completed slice, and the [`Engine::update`] that contouring
    /// waits for ([`Link::waits`]: to fold the surface arriving). For an
    /// engine with no picture to keep playing meanwhile: a board's boot
    /// volume, the host's board in process. (A board playing frames feeds
    /// and contours between refills of its output instead.)
    ///
    /// Returns the bytes taken: all of them, unless the engine took none
    /// with nothing left to do, which it does not (the bytes left are then
    /// not taken, rather than tried for ever).
    pub fn feed_all(&mut self, bytes: &[u8], now_ms: u32) -> usize {
        let mut taken = 0;
        self.drive(now_ms, |link| {
            let rest = bytes.get(taken..).unwrap_or_default();
            if rest.is_empty() {
                return None;
            }
            let n = link.feed(rest, now_ms);
            taken += n;
            Some(n > 0)
        });
        taken
    }

    /// [`Engine::feed_all`] for one message handed over whole
    /// ([`Link::accept`]): the same work, and the same picture, as its
    /// frame fed whole, without encoding and decoding the frame. Returns
    /// whether it was taken (it is, unless the engine takes nothing with
    /// nothing left to do, which it does not).
    pub fn accept_all(&mut self, msg: &Message<'_>, now_ms: u32) -> bool {
        let mut taken = false;
        self.drive(now_ms, |link| {
            if taken {
                return None;
            }
            taken = link.accept(*msg, now_ms);
            Some(taken)
        });
        taken
    }

    /// The loop of [`Engine::feed_all`] and [`Engine::accept_all`]: the
    /// contouring deferred and the updates it waits for done, then `take`
    /// given the link, until it says it has nothing left (`None`), or it
    /// took nothing (`Some(false)`) with no contouring pending.
    fn drive(&mut self, now_ms: u32, mut take: impl FnMut(&mut Link<'_, '_>) -> Option<bool>) {
        loop {
            let (mut link, _) = self.split();
            while !link.waits() && link.contour(usize::MAX) {}
            if link.waits() {
                self.update(now_ms);
                continue;
            }
            match take(&mut link) {
                None => return,
                Some(false) if !link.busy() => return,
                Some(_) => {}
            }
        }
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
        self.update_playing(now_ms, &mut |_| {})
    }

    /// [`Engine::update`], with the picture on screen played on while a new
    /// volume is committed, as a board does: if the picture's frame is
    /// recorded in the slice memory's tail ([`replay_tail`]) and the commit
    /// fits the head, `refill` is called with that frame every few thousand
    /// cycles of the commit's work, to take the samples its output has room
    /// for (none, or a half buffer: it must not wait). The frame starts
    /// again each time it ends. When the commit is done, the frame in
    /// progress is left to finish ([`Engine::unfinished`]) before the new
    /// picture's first frame, so the switch falls on a frame boundary.
    /// Otherwise (no recording, or a commit that needs all of the memory)
    /// `refill` is not called, and the beam waits for the commit
    /// ([`Engine::commit_parks`]).
    // Never inlined: called once a frame, it costs nothing, and a board's
    // profile can then time what runs between frames as one function
    // (`scripts/firmware-dark`).
    #[inline(never)]
    pub fn update_playing(&mut self, now_ms: u32, refill: &mut dyn FnMut(&mut Player<'_>)) -> bool {
        self.dev.check_timeout(now_ms);
        if self.records_before_fold() {
            // One frame more of the picture on screen, held still and
            // recorded into the tail as it plays; the fold then plays it.
            self.dev.fold_waited = true;
            self.dev.lend = Lend::Tail;
            self.kept.clear();
        } else if self.dev.stream.wants_fold() {
            self.fold(refill);
            self.dev.fold_waited = false;
        } else {
            // (The transfer that waited for the fold was abandoned.)
            self.dev.fold_waited = false;
        }
        self.reclaim(now_ms);
        let mut changed = false;
        if self.records_before_commit() && self.dev.stream.spill_into_head(self.slices) {
            // One frame more of the picture on screen, recorded into the
            // tail as it plays (`Screen::frame`); the commit then plays it.
            self.dev.commit_waited = true;
            self.dev.lend = Lend::Tail;
            self.kept.clear();
        } else if self.thins_before_commit() {
            // The commit needs more of the memory than the recording of the
            // picture on screen leaves: thinned (a few milliseconds at most,
            // the beam held), it plays on, dimmer, through the commit at
            // the next update.
            self.dev.commit_thinned = true;
            let room = self.slices.len().saturating_sub(self.commit_needs(crate::path::stitch_least));
            for _ in 0..MAX_THINNING {
                if self.kept.len() <= room || self.kept.thin(self.slices, 2) == 0 {
                    break;
                }
            }
        } else if self.dev.commit {
            self.commit(refill);
            self.dev.stream.front_taken = false;
            self.dev.reclaimed_ms = None;
            changed = true;
        }
        if self.dev.stream.front_taken {
            // The picture on screen lives on as its recording alone (its
            // store holds the volume arriving): a new view, beam or spin
            // waits for the next picture.
            self.lend(now_ms);
            return false;
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
        self.lend(now_ms);
        changed
    }

    /// Whether the next [`Engine::update_playing`] commits a volume, or
    /// folds the back of one arriving ([`Stream::fold`]), without playing
    /// the picture on screen meanwhile (no recording of it in the tail yet,
    /// or a commit that needs all of the slice memory): a board then parks
    /// the beam for it.
    pub fn commit_parks(&self) -> bool {
        let recorded = self.kept.holds_in_tail(self.generation);
        (self.dev.commit && !self.commit_keeps_tail() && !self.records_before_commit())
            || (self.dev.stream.wants_fold() && !recorded && !self.records_before_fold())
    }

    /// The rest of the frame [`Engine::update_playing`] was playing when its
    /// commit ended (taken once): play it to its end before the new
    /// picture's first frame.
    pub fn unfinished(&mut self) -> Option<Player<'_>> {
        let (key, mark) = self.unfinished.take()?;
        let (_, lent) = cut(self.slices, self.dev.lend, self.dev.tail);
        replay::resume(lent, &self.kept, key, mark)
    }

    /// Keep a still picture's frame and play it again from memory
    /// (`on`), as a board does ([`crate::beam::replay`]): the first frame
    /// [`Screen::frame`] plays of a picture is recorded into the slice
    /// memory while no volume needs it, and the frames after it are played
    /// from the recording, the same samples at a few cycles a sample. A
    /// recording that fits the memory's tail ([`replay_tail`]) stays there
    /// while a volume whose slices fit the head arrives (with
    /// [`EngineConfig::defer_contouring`]) and while it is committed
    /// ([`Engine::update_playing`]); else the volume's first command is
    /// answered `Busy` once, and the memory comes back at the next
    /// [`Engine::update`]. Off by default.
    pub fn replay_frames(&mut self, on: bool) {
        self.dev.replay_frames = on;
        if !on {
            self.dev.lend = Lend::Stream;
            self.kept.clear();
        }
    }

    /// At a frame boundary, the slice memory back from the replay for what
    /// asked for it: a volume refused `Busy` (the head, if its slices fit
    /// there and the recording is in the tail; else all of it), or a row
    /// that waited for all of it.
    fn reclaim(&mut self, now_ms: u32) {
        let dev = &mut self.dev;
        let asked = dev.reclaim.take();
        let all = dev.stream.wants_all(true) || asked == Some(usize::MAX);
        if let Some(slices) = asked {
            let head = self.slices.len().saturating_sub(dev.tail);
            let tail = dev.cfg.defer_contouring && self.kept.in_tail() && slices <= head;
            dev.lend = if tail && dev.lend != Lend::Stream { Lend::Tail } else { Lend::Stream };
            dev.reclaimed_ms = Some(now_ms);
        }
        if all {
            dev.lend = Lend::Stream;
        }
        if dev.lend == Lend::Stream {
            // The stream may write anywhere.
            self.kept.clear();
        }
        // A transfer that took all of the memory (its first command came
        // while the recording was not in the tail) needs the head alone:
        // the tail goes back to the replay, which records the picture there
        // afresh (if the picture is still in its store).
        let head = self.slices.len().saturating_sub(dev.tail);
        if dev.lend == Lend::Stream
            && !all
            && dev.replay_frames
            && dev.cfg.defer_contouring
            && dev.shown.is_some()
            && !dev.commit
            && !dev.stream.front_taken
            && dev.stream.fits_head(head)
        {
            dev.lend = Lend::Tail;
        }
    }

    /// Lend the slice memory to the replay while nothing needs it: a picture
    /// shown, no volume arriving or waiting, none asked for in the last
    /// [`RELEND_MS`].
    fn lend(&mut self, now_ms: u32) {
        let dev = &mut self.dev;
        let waiting = dev.reclaimed_ms.is_some_and(|t| now_ms.wrapping_sub(t) < RELEND_MS);
        if !dev.replay_frames
            || dev.shown.is_none()
            || dev.commit
            || dev.reclaim.is_some()
            || waiting
            || !dev.stream.idle()
        {
            return;
        }
        dev.lend = Lend::Screen;
        dev.reclaimed_ms = None;
    }

    /// A row waits for the back to be folded into the front
    /// ([`Stream::fold`]): the picture on screen, recorded into the slice
    /// memory's tail first if it is not there yet (with
    /// [`Engine::replay_frames`]; a frame too long for the tail is lost),
    /// plays on from there through `refill` while the fold runs in the
    /// head, and until the volume's picture replaces it.
    // Never inlined, as `commit`: a board's profile times each fold
    // apart from the commit (`scripts/firmware-bench`).
    #[inline(never)]
    fn fold(&mut self, refill: &mut dyn FnMut(&mut Player<'_>)) {
        let key = self.generation;
        let dev = &mut self.dev;
        let head = self.slices.len().saturating_sub(dev.tail);
        let (head, tail) = self.slices.split_at_mut(head);
        if dev.replay_frames && dev.shown.is_some() && !self.kept.holds_in_tail(key) {
            let mut replay = Replay::new(&mut *tail, &mut self.kept);
            if let Some(mut rec) = replay.record(key) {
                let mut live = Scheduler::new(Projected::new(&self.front, self.transform), &dev.beam);
                while rec.fill_with(&mut live, 1024, |_| {}) == 1024 {}
                rec.finish(live.stats());
            }
        }
        if self.kept.holds_in_tail(key) {
            // The stream keeps to the head from now on.
            dev.lend = Lend::Tail;
        }
        let mut old = Replaying::new(tail, &self.kept, key);
        let mut poll = || old.poll(refill);
        poll();
        dev.stream.fold(head, &mut self.back, &mut self.front, &mut poll);
        self.unfinished = old.unfinished();
    }

    /// Whether the fold due waits one frame, for the picture on screen to
    /// be recorded into the tail as it plays (held still for that frame
    /// if it spins: [`Engine::split`]), rather than scheduled and recorded
    /// at once with the beam parked. Once a fold, as a board plays
    /// ([`Engine::replay_frames`], [`EngineConfig::defer_contouring`]), when
    /// the transfer keeps to the head (its slices and what spilled), so
    /// that the tail is free.
    fn records_before_fold(&self) -> bool {
        let dev = &self.dev;
        let head = self.slices.len().saturating_sub(dev.tail);
        dev.stream.wants_fold()
            && !dev.fold_waited
            && dev.replay_frames
            && dev.cfg.defer_contouring
            && dev.shown.is_some()
            && !self.front.is_empty()
            && !dev.stream.front_taken
            && !self.kept.holds_in_tail(self.generation)
            && dev.stream.fits_head(head)
            && dev.stream.spill_in_head()
    }

    /// Whether the commit due plays the picture on screen from the tail:
    /// its recording is there, what spilled lies in the head, and the
    /// commit fits the head ([`Engine::commit_fits_head`]).
    fn commit_keeps_tail(&self) -> bool {
        self.commit_replay().is_some()
    }

    /// The bytes at the end of the slice memory the commit due leaves to
    /// the replay of the picture on screen, if it can play it: its
    /// recording is in the tail and what spilled in the head, and the
    /// commit fits the head (the tail left), or else the memory less the
    /// recording's own bytes (the recording lies at the very end:
    /// [`Kept`]), where the stitch pass may have less than its reserve,
    /// down to [`stitch_least`](crate::path::stitch_least). The stitch
    /// pass makes the same picture in any room from that least on (more
    /// slowly in less), and the order pass's scratch is the head either
    /// way.
    fn commit_replay(&self) -> Option<usize> {
        let dev = &self.dev;
        if dev.lend != Lend::Tail || !self.kept.in_tail() || !dev.stream.spill_in_head() {
            return None;
        }
        if self.commit_fits_head() {
            return Some(dev.tail);
        }
        let room = self.slices.len().saturating_sub(self.kept.len());
        (self.commit_needs(crate::path::stitch_least) <= room).then_some(self.kept.len())
    }

    /// Bytes the commit due needs besides the order pass: what spilled,
    /// and the stitch pass's scratch as `stitch` (of the fragments and
    /// points) sizes it.
    fn commit_needs(&self, stitch: fn(usize, usize) -> usize) -> usize {
        let spilled = self.dev.stream.spilled().len();
        let points = self.back.len() + spilled;
        Geometry::bytes_for(spilled) + stitch(self.dev.pieces as usize, points)
    }

    /// Whether the commit due could do with the head of the slice memory
    /// alone: what spilled and the stitch pass's reserve fit there.
    fn commit_fits_head(&self) -> bool {
        self.commit_needs(crate::path::stitch_reserve) <= self.slices.len().saturating_sub(self.dev.tail)
    }

    /// Whether the commit due would park the beam only for want of the
    /// bytes the recording of the picture on screen takes (it is in the
    /// tail, what spilled in the head, and the commit's least needs less
    /// than the memory): the recording is thinned first
    /// ([`Kept::thin`](crate::beam::replay::Kept::thin)), once.
    fn thins_before_commit(&self) -> bool {
        let dev = &self.dev;
        dev.commit
            && !dev.commit_thinned
            && dev.lend == Lend::Tail
            && self.kept.holds_in_tail(self.generation)
            && dev.stream.spill_in_head()
            && self.commit_replay().is_none()
            && self.commit_needs(crate::path::stitch_least) < self.slices.len()
    }

    /// Whether the commit due waits one frame, for the picture on screen
    /// to be recorded into the tail as it plays, so that the commit can
    /// play it on (the volume's slices took all of the slice memory, and
    /// the recording with it, but its commit fits the head, where what
    /// spilled is moved first: [`Stream::spill_into_head`]), or the
    /// picture spins (it is held still for that frame). Once a commit, and
    /// only as a board plays ([`Engine::replay_frames`],
    /// [`EngineConfig::defer_contouring`]). What the commit makes is the
    /// same either way: its passes' scratch is the head whether or not a
    /// recording keeps the tail.
    fn records_before_commit(&self) -> bool {
        let dev = &self.dev;
        dev.commit
            && !dev.commit_waited
            && dev.replay_frames
            && dev.cfg.defer_contouring
            && !self.front.is_empty()
            && !dev.stream.front_taken
            && !self.kept.holds_in_tail(self.generation)
            && self.commit_fits_head()
    }

    /// The received surface becomes the picture, the picture on screen
    /// played on through `refill` meanwhile if it can be
    /// ([`Engine::update_playing`]).
    // Never inlined: called once a picture, it costs nothing, and a
    // board's profile can then time the commit alone, not a fold of the
    // same transfer (`scripts/firmware-bench`).
    #[inline(never)]
    fn commit(&mut self, refill: &mut dyn FnMut(&mut Player<'_>)) {
        let replay = self.commit_replay();
        if replay.is_none() {
            self.dev.lend = Lend::Stream;
            self.kept.clear();
        }
        let key = self.generation;
        let Self { dev, front, back, scratch: extra, slices, kept, chain, unfinished, .. } = self;
        dev.commit = false;
        dev.commit_waited = false;
        dev.commit_thinned = false;
        let Some(shown) = dev.shown.as_mut() else { return };
        let capacity = slices.len();
        let (slots, lent) = cut(slices, dev.lend, replay.unwrap_or(dev.tail));
        // The frame on screen, played over and over while the passes run.
        let mut old = Replaying::new(lent, kept, key);
        let mut poll = || old.poll(refill);
        // A half buffer's worth before anything else: the frame before
        // ended just now.
        poll();
        let view = View { spacing: shown.spacing, bits: dev.beam.bits, ..dev.view };
        let stitched = {
            let (mut spill, free) = dev.stream.take_spill(&mut *slots);
            let scratch = if free.len() >= extra.len() { free } else { &mut **extra };
            loop {
                let pieces = Source::two(back, &spill);
                // Every view fits the surface, not the volume: the box of its
                // pieces (stitching and merging keep their end points, so it is
                // the picture's box too).
                if let Some([lo, hi]) = pieces.extent(&mut poll) {
                    shown.bounds = Bounds::new(back.point(lo), back.point(hi));
                }
                // Merge within the tolerance at the largest scale a view can
                // give: the bounding sphere's fit, times the longest voxel side,
                // doubled.
                let tolerance = ViewTransform::fit_sphere(&view, shown.bounds).map_or(0.0, |t| {
                    let side = shown.spacing.iter().fold(0.0f32, |m, &s| m.max(s));
                    dev.cfg.merge_tolerance / (2.0 * t.scale() * side)
                });
                // Stitch the pieces (the back's, then those that spilled into
                // the slice memory) into maximal polylines (into the front), then
                // order those for short jumps (back into the back), and make that
                // the front. Collinear runs are merged once: in the order pass,
                // which then also joins polylines that touch where one ends and
                // the next is entered (merging first could take such a vertex
                // away); but in the stitch pass when the pieces are more than
                // the front holds (stitching joins them, merging thins them: the
                // surface fits again).
                let merge_first = pieces.len() > front.capacity();
                let (first, then) = if merge_first { (tolerance, 0.0) } else { (0.0, tolerance) };
                let stitched =
                    crate::path::chain(pieces, front, scratch, [0; 3], first, Pass::Stitch, &mut poll);
                // A picture the front cannot hold is thinned as the stream
                // thins one the memory cannot: every other slice goes, until it
                // fits or one slice of each plane is left.
                let coarser = if stitched.cut == 0 { None } else { shown.stride.coarser() };
                let Some(coarser) = coarser else { break (stitched, then) };
                shown.stride = coarser;
                crate::path::thin(back, &mut spill, &shown.stride, &mut poll);
            }
        };
        let (stitched, then) = stitched;
        let spec = *shown;
        // The order pass's scratch is the head of the slice memory whether
        // or not a recording keeps the tail: its picture depends on its
        // scratch (the grid of ends), and must not on what played before.
        let head = slots.len().min(capacity.saturating_sub(dev.tail));
        let slots = slots.get_mut(..head).unwrap_or_default();
        let scratch = if slots.len() >= extra.len() { slots } else { &mut **extra };
        // A still view orders for its own screen (a jump across the depth
        // costs it nothing); a spinning one in space, for every angle.
        let metric = match ViewTransform::fit_sphere(&view, spec.bounds) {
            Ok(t) if dev.spin_deg_per_s == 0.0 => {
                let park = dev.beam.park_sample();
                Metric::Screen { view: t, shift: front.shift(), park: [f32::from(park.x), f32::from(park.y)] }
            }
            _ => Metric::Space,
        };
        let ordered = crate::path::chain(
            Source::one(front),
            back,
            scratch,
            [0; 3],
            then,
            Pass::Order(metric),
            &mut poll,
        );
        *unfinished = old.unfinished();
        core::mem::swap(front, back);
        back.reset(back.shift());
        *chain = ChainStats {
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
            s.points = front.len() as u32;
        }
        dev.event(Event::Stitched {
            fragments: chain.fragments,
            points: chain.points_out,
            cut: chain.cut,
            ordered: chain.ordered,
            every: spec.stride.every,
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
    // Never inlined: called once a frame, it costs nothing, and a board's
    // profile then finds where each frame ended (`scripts/firmware-bench`).
    #[inline(never)]
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
            // (The order pass counted them: a walk over every point would
            // cost a board most of a half buffer.)
            polylines: self.chain.polylines,
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
        Projected::new(&self.front, self.transform)
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

    /// Whether the volume being received has outgrown the memory already:
    /// its slices thinned to a coarser stride than it asked for, or
    /// commands dropped. Its picture will not be the whole surface, so a
    /// host that can give an engine more memory stops sending here and
    /// starts again with more (`isoscope-sim`'s growing memory) rather
    /// than contour the rest for nothing. False between transfers.
    pub fn outgrown(&self) -> bool {
        self.dev.stream.transfer.is_some_and(|t| {
            t.stride.every > u16::from(t.spec.every.max(1))
                || self.back.dropped() > 0
                || self.dev.stream.spilled().dropped() > 0
        })
    }

    /// What stitching and ordering did to the last volume.
    pub fn chain_stats(&self) -> ChainStats {
        self.chain
    }

    /// The statistics of the picture's frame as last counted: at each
    /// picture, or from the frames played with
    /// [`Engine::count_while_playing`] (then a frame late; default until
    /// one is counted).
    pub fn frame_stats(&self) -> FrameStats {
        self.dev.frame
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

/// The picture on screen played over and over from its recording while a
/// long pass runs (a fold, a commit): at each poll, `refill` takes what
/// its output has room for, and the frame starts again when it ends.
struct Replaying<'r> {
    mem: &'r [u8],
    kept: &'r Kept,
    key: u32,
    player: Option<Player<'r>>,
    polled: bool,
}

impl<'r> Replaying<'r> {
    /// Picture `key`'s frame, if `mem` holds it (else nothing plays).
    fn new(mem: &'r [u8], kept: &'r Kept, key: u32) -> Self {
        Self { mem, kept, key, player: replay::play(mem, kept, key), polled: false }
    }

    fn poll(&mut self, refill: &mut dyn FnMut(&mut Player<'_>)) {
        if let Some(p) = self.player.as_mut() {
            self.polled = true;
            refill(p);
            if p.is_done() {
                self.player = replay::play(self.mem, self.kept, self.key);
            }
        }
    }

    /// Where the frame stood when the pass ended, if it played
    /// ([`Engine::unfinished`]).
    fn unfinished(self) -> Option<(u32, replay::Mark)> {
        let key = self.key;
        self.player.filter(|_| self.polled).map(|p| (key, p.mark()))
    }
}

/// The slice memory cut as `lend` says: the stream's part, the replay's.
fn cut(mem: &mut [u8], lend: Lend, tail: usize) -> (&mut [u8], &mut [u8]) {
    match lend {
        Lend::Stream => (mem, &mut []),
        Lend::Screen => (&mut [], mem),
        Lend::Tail => mem.split_at_mut(mem.len().saturating_sub(tail)),
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
    /// done) and takes none while that work is pending; and except while
    /// the contouring waits for an update ([`Link::waits`]), when it stops
    /// after the frame that made it wait.
    pub fn feed(&mut self, bytes: &[u8], now_ms: u32) -> usize {
        self.dev.check_timeout(now_ms);
        let defer = self.dev.cfg.defer_contouring;
        if (defer && self.dev.stream.busy()) || self.dev.stream.waits() {
            return 0;
        }
        for (n, &b) in bytes.iter().enumerate() {
            match self.decoder.push(b) {
                None => {}
                Some(Ok(msg)) => {
                    self.dev.take(msg, now_ms, self.back, self.slots);
                    if (defer && self.dev.stream.busy()) || self.dev.stream.waits() {
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

    /// Take `msg` at time `now_ms` as if its frame had just been decoded
    /// from the line ([`Link::feed`] without the bytes): for a sender in
    /// the same process, which has the message itself and no line to
    /// cross (the host's board in process, [`Engine::accept_all`]). Returns
    /// whether it was taken: not while a completed slice's deferred
    /// contouring is pending or the contouring waits for an update, as
    /// [`Link::feed`] takes no bytes then.
    pub fn accept(&mut self, msg: Message<'_>, now_ms: u32) -> bool {
        self.dev.check_timeout(now_ms);
        if (self.dev.cfg.defer_contouring && self.dev.stream.busy()) || self.dev.stream.waits() {
            return false;
        }
        self.dev.take(msg, now_ms, self.back, self.slots);
        true
    }

    /// Whether the contouring left waits for the next
    /// [`Engine::update`] (for the slice memory, or for the back to be
    /// folded): [`Link::contour`] does nothing until then, and a slice's
    /// data is answered `Busy`.
    pub fn waits(&self) -> bool {
        self.dev.stream.waits()
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
        self.dev.stream.work(self.slots, self.back, cells)
    }

    /// As [`Link::contour`], one whole row and then more while
    /// `more(cells done so far)` says so: for a time budget, as the firmware
    /// keeps one (making the contourer for a call costs about as much as a
    /// short row, so a call should do more than one when it can).
    pub fn contour_while(&mut self, more: impl FnMut(usize) -> bool) -> bool {
        self.contour_polling(more, &mut || {})
    }

    /// As [`Link::contour_while`], calling `poll` as a long pass over the
    /// whole surface goes on inside a row (thinning it when it outgrows
    /// the memory: several milliseconds on a board), for a board to refill
    /// its output from (never waiting).
    pub fn contour_polling(&mut self, more: impl FnMut(usize) -> bool, poll: &mut dyn FnMut()) -> bool {
        self.dev.stream.work_while(self.slots, self.back, more, poll)
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
