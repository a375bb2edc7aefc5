//! Everything of the engine but the frame decoder and the two surfaces:
//! the session, the stream, the settings in force, the answers and events
//! queued; and the commands it applies.

use super::session::{Session, Standing};
use super::stream::{Stream, VolumeSpec};
use super::{AbortReason, Counters, EVENT_QUEUE, EngineConfig, Event, TX_QUEUE};
use crate::beam::{BeamConfig, FrameStats};
use crate::command::Point3;
use crate::path::{Geometry, Stride};
use crate::view::{Bounds, Projection, View, ViewTransform};
use crate::wire::{DeviceState, Levels, Message, NackCode, PROTOCOL_VERSION, encode};
use heapless::Deque;

/// The committed volume.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Shown {
    pub(super) dims: [u16; 3],
    pub(super) spacing: [f32; 3],
    pub(super) points: u32,
    /// Its slices: as asked, or fewer when its surface did not fit
    /// ([`crate::path::thin`]).
    pub(super) stride: Stride,
    /// The box of the surface's points (voxel coordinates), which every
    /// view fits by its bounding sphere; the volume's box until the
    /// surface is known, or when it is empty.
    pub(super) bounds: Bounds,
}

/// Who has the slice memory, borrow after borrow
/// ([`Engine::split`](super::Engine::split)); it changes hands at a frame
/// boundary ([`Engine::update`](super::Engine::update)).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub(super) enum Lend {
    /// All of it to the stream (and the commit): a transfer, its spill,
    /// or nothing to replay.
    Stream,
    /// All of it to the replay of a still picture: nothing else needs it.
    Screen,
    /// The tail ([`Device::tail`] bytes) to the replay, holding the
    /// picture's recording, and the head to the stream: the picture keeps
    /// playing from memory while a volume arrives and is committed.
    Tail,
}

/// Everything but the frame decoder and the two surfaces.
#[derive(Debug)]
pub(super) struct Device<'a> {
    pub(super) cfg: EngineConfig,
    pub(super) session: Session,
    pub(super) stream: Stream<'a>,
    /// The volume on screen.
    pub(super) shown: Option<Shown>,
    /// A volume is complete in the back surface: it becomes the picture at
    /// the next [`Engine::update`](super::Engine::update); until then new volume data is `Busy`.
    pub(super) commit: bool,
    /// The commit due waited a frame for the picture on screen to be
    /// recorded into the tail ([`Engine::update_playing`](super::Engine::update_playing)):
    /// it waits no more.
    pub(super) commit_waited: bool,
    /// The picture's recording was thinned for the commit due
    /// ([`Engine::update_playing`](super::Engine::update_playing)): not again.
    pub(super) commit_thinned: bool,
    /// The fold due waits a frame for the picture on screen to be recorded
    /// into the tail as it plays (held still for it, if it spins).
    pub(super) fold_waited: bool,
    pub(super) view: View,
    pub(super) spin_deg_per_s: f32,
    /// When `view.yaw` held (ms), for the spin.
    pub(super) spin_epoch_ms: u32,
    pub(super) beam: BeamConfig,
    pub(super) levels: Levels,
    /// The view or beam changed: fit the view again, count the frame again.
    pub(super) dirty: bool,
    /// A volume was committed: report the status once its picture is drawn.
    pub(super) status_due: bool,
    pub(super) display_capacity: usize,
    /// The rate the board plays samples at ([`Engine::set_playback_rate`](super::Engine::set_playback_rate)).
    pub(super) playback_hz: u32,
    /// A frame of the picture, as last counted.
    pub(super) frame: FrameStats,
    /// The board counts a new picture's frame as it plays it
    /// ([`Engine::count_while_playing`](super::Engine::count_while_playing)).
    pub(super) board_counts: bool,
    /// A count is due from the board's next played frame.
    pub(super) count_due: bool,
    /// The board replays a still picture's frames from the slice memory
    /// ([`Engine::replay_frames`](super::Engine::replay_frames)).
    pub(super) replay_frames: bool,
    /// Who has the slice memory.
    pub(super) lend: Lend,
    /// Pieces (fragments) of the volume complete in the back and spill,
    /// for its commit.
    pub(super) pieces: u32,
    /// Bytes of the slice memory's tail a recording may keep through a
    /// transfer and its commit ([`replay_tail`](super::replay_tail)).
    pub(super) tail: usize,
    /// A volume of slices of this many bytes waits for the slice memory
    /// lent to the replay: it comes (all of it, or the head) at the next
    /// update.
    pub(super) reclaim: Option<usize>,
    /// When it last came back for a volume (ms), until the volume begins.
    pub(super) reclaimed_ms: Option<u32>,
    pub(super) refresh_centi_hz: u16,
    pub(super) tx: Deque<u8, TX_QUEUE>,
    pub(super) events: Deque<Event, EVENT_QUEUE>,
    pub(super) counters: Counters,
}

impl Device<'_> {
    pub(super) fn state(&self) -> DeviceState {
        match (self.stream.transfer.is_some(), self.shown.is_some()) {
            (true, _) => DeviceState::Receiving,
            (false, true) => DeviceState::Showing,
            (false, false) => DeviceState::Idle,
        }
    }

    /// The refresh rate from the last counted frame and the playback rate.
    pub(super) fn refresh(&mut self) {
        let fps = self.frame.fps(self.playback_hz as f32);
        self.refresh_centi_hz = (fps * 100.0).clamp(0.0, f32::from(u16::MAX)) as u16;
    }

    pub(super) fn event(&mut self, e: Event) {
        if self.events.push_back(e).is_err() {
            self.counters.events_dropped = self.counters.events_dropped.wrapping_add(1);
        }
    }

    /// Queue a message for the UART, whole or not at all.
    pub(super) fn send(&mut self, msg: &Message<'_>) {
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

    pub(super) fn nack(&mut self, seq: u16, code: NackCode) {
        self.counters.nacks = self.counters.nacks.wrapping_add(1);
        self.event(Event::Nacked { seq, code });
        self.send(&Message::Nack { seq, code });
    }

    pub(super) fn answer(&mut self, seq: u16, answer: Option<NackCode>) {
        match answer {
            None => self.send(&Message::Ack { seq }),
            Some(code) => self.nack(seq, code),
        }
    }

    pub(super) fn status(&mut self) {
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

    pub(super) fn abort(&mut self, reason: AbortReason) {
        if let Some(t) = self.stream.transfer.take() {
            self.counters.aborts = self.counters.aborts.wrapping_add(1);
            self.event(Event::Aborted { reason, slices: t.z });
        }
    }

    pub(super) fn check_timeout(&mut self, now_ms: u32) {
        if let Some(t) = self.stream.transfer
            && now_ms.wrapping_sub(t.last_ms) > self.cfg.transfer_timeout_ms
        {
            self.abort(AbortReason::Timeout);
            self.status();
        }
    }

    /// A message decoded from the line, or handed over whole
    /// ([`Link::accept`](super::Link::accept)): counted as a frame and
    /// handled.
    pub(super) fn take(&mut self, msg: Message<'_>, now_ms: u32, back: &mut Geometry<'_>, slots: &mut [u8]) {
        self.counters.frames = self.counters.frames.wrapping_add(1);
        self.handle(msg, now_ms, back, slots);
    }

    fn handle(&mut self, msg: Message<'_>, now_ms: u32, back: &mut Geometry<'_>, slots: &mut [u8]) {
        let seq = match msg {
            Message::Hello { protocol, seq, .. } => {
                self.abort(AbortReason::Restarted);
                // The host's first command will carry `seq`: a lost one,
                // the first included, shows as a gap and is sent again.
                self.session.reset(seq);
                self.event(Event::Hello { protocol });
                self.send(&Message::Hello { protocol: PROTOCOL_VERSION, firmware: self.cfg.firmware, seq });
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
            | Message::SetBeam { seq, .. } => {
                // A whole command, even one out of order or sent again,
                // shows the sender is still at it: on a noisy line the next
                // one may take a while to arrive whole, and the transfer
                // waits for it (only silence times it out).
                if let Some(t) = self.stream.transfer.as_mut() {
                    t.last_ms = now_ms;
                }
                seq
            }
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
                let answer = self.apply(msg, now_ms, back, slots).err();
                // Busy is "not now": the command is not taken, and the
                // same `seq` is expected again (a sender retries it).
                if answer != Some(NackCode::Busy) {
                    self.session.answered(seq, answer);
                }
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
    pub(super) fn apply(
        &mut self,
        msg: Message<'_>,
        now_ms: u32,
        back: &mut Geometry<'_>,
        slots: &mut [u8],
    ) -> Result<(), NackCode> {
        let volume_data = matches!(msg, Message::BeginVolume { .. } | Message::SliceData { .. });
        if volume_data && self.commit {
            // The last volume is not the picture yet (the next update makes
            // it so, between frames); its surface is still in the back.
            return Err(NackCode::Busy);
        }
        if let Message::BeginVolume { dims, sample_type, .. } = msg {
            // The slice memory holds the frame on screen, replayed: it
            // comes back at the next update, between frames; all of it,
            // or the head if the two slices fit there.
            let slices = 2 * usize::from(dims[0]) * usize::from(dims[1]) * sample_type.size();
            // (With the replay playing from the tail alone, the head is
            // lent here already: the volume may begin at once, if it is
            // contoured a few rows at a time and its slices fit.)
            let head = self.cfg.defer_contouring && !slots.is_empty() && slices <= slots.len();
            let short = match self.lend {
                Lend::Stream => false,
                Lend::Screen => !head,
                Lend::Tail => slots.len() < slices,
            };
            if short {
                self.reclaim = Some(slices);
                return Err(NackCode::Busy);
            }
            if self.lend == Lend::Screen {
                self.lend = Lend::Tail;
            }
        }
        match msg {
            Message::BeginVolume { dims, sample_type, spacing, levels, axes, every, .. } => {
                self.abort(AbortReason::Superseded);
                let levels = if levels.is_empty() { self.levels } else { levels };
                let spec = VolumeSpec { dims, sample_type, spacing, levels, axes, every: every.max(1) };
                if self.cfg.sample_types & sample_type.bit() == 0 {
                    return Err(NackCode::Invalid);
                }
                spec.check(self.stream.slice_capacity())?;
                let shift = Geometry::shift_for(dims);
                back.reset(shift);
                self.stream.begin(spec, now_ms, shift);
                self.event(Event::Begun { dims, sample_type, levels: levels.len() as u8 });
                Ok(())
            }
            Message::SliceData { slice, offset, data, .. } => {
                let defer = self.cfg.defer_contouring;
                let r = self.stream.chunk(slots, slice, offset, data, now_ms, back, defer);
                if r == Err(NackCode::Busy) && !self.stream.wants_fold() {
                    // A row waits for the whole memory (next update).
                    self.reclaim = Some(usize::MAX);
                }
                r
            }
            Message::EndVolume { .. } => {
                if !self.stream.finish(slots, back) {
                    if !self.stream.wants_fold() {
                        self.reclaim = Some(usize::MAX);
                    }
                    return Err(NackCode::Busy);
                }
                let t = self.stream.transfer.ok_or(NackCode::Aborted)?;
                if t.z < t.spec.dims[2] {
                    self.abort(AbortReason::Missing);
                    return Err(NackCode::Missing);
                }
                self.stream.transfer = None;
                let [nx, ny, nz] = t.spec.dims.map(usize::from);
                let bounds = Bounds::of_volume(nx, ny, nz)
                    .unwrap_or(Bounds::new(Point3::new(0.0, 0.0, 0.0), Point3::new(1.0, 1.0, 1.0)));
                self.shown = Some(Shown {
                    dims: t.spec.dims,
                    spacing: t.spec.spacing,
                    points: 0,
                    stride: t.stride,
                    bounds,
                });
                self.commit = true;
                self.pieces = t.frags;
                self.counters.volumes = self.counters.volumes.wrapping_add(1);
                let spilled = self.stream.spilled();
                self.event(Event::Committed {
                    dims: t.spec.dims,
                    commands: (back.len() + spilled.len()) as u32,
                    dropped: back.dropped().saturating_add(spilled.dropped()),
                    nonfinite_cells: t.stats.nonfinite_cells.min(u64::from(u32::MAX)) as u32,
                    asked: t.spec.every,
                    every: t.stride.every,
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
