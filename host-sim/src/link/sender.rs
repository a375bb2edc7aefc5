//! The sender's side of the protocol as a state machine, without I/O: no
//! port, thread or clock of its own. Its driver hands it what the board
//! sent ([`Sender::receive`]) and the time ([`Sender::on_time`]), takes the
//! bytes to write ([`Sender::transmit`]) and waits at most until
//! [`Sender::deadline`]. Time is a [`Duration`] from any origin the driver
//! keeps (the blocking driver's `Instant`, a page's `performance.now()`),
//! so the same code runs on a host and in a browser.
//!
//! It says hello (three tries), learns what the board takes
//! ([`State::Connected`]), then sends a volume ([`Sender::start`]) with a
//! send window and go-back-N retransmission, and waits for the board's
//! status once the new picture is on screen ([`State::Done`]). The
//! conversation is docs/wire-format.md's; the behaviour on a noisy line is
//! docs/link.md's.

use super::{BoardInfo, MAX_STALLS, SendConfig, SendReport, WireVolume, volume_messages};
use core::fmt;
use core::time::Duration;
use isoscope_core::wire::{
    DeviceState, FrameDecoder, MAX_FRAME_LEN, Message, NackCode, PROTOCOL_VERSION, SampleType, WireError,
    encode,
};

/// Hellos sent before the board is given up on.
pub const HELLO_TRIES: u32 = 3;
/// How long each hello waits for the board's capabilities.
pub const HELLO_WAIT: Duration = Duration::from_millis(1500);
/// How long the sender waits, after the last acknowledgement, for the
/// board's status report (sent once the new picture is on screen).
pub const PICTURE_WAIT: Duration = Duration::from_secs(10);

/// Why a transfer failed.
#[derive(Debug, Clone, PartialEq)]
pub enum SendError {
    /// No capabilities after [`HELLO_TRIES`] hellos.
    NoAnswer,
    /// The board serves another client (`Nack Busy` before its hello).
    BoardBusy,
    /// The board speaks another protocol version.
    OtherProtocol(u8),
    /// The port closed before the board said hello.
    ClosedBeforeHello,
    /// The port closed during the transfer.
    PortClosed,
    /// A volume to send before the board said what it takes, or a second
    /// one on the same greeting.
    NotConnected,
    /// Settings the board cannot take (`SendConfig::check`'s message).
    Settings(String),
    /// Samples of a type the board does not take.
    SampleType(SampleType),
    /// A slice larger than the board holds.
    SliceTooLarge {
        /// Samples along x and y.
        dims: [u16; 2],
        /// Their type.
        sample_type: SampleType,
        /// Bytes in one slice.
        bytes: usize,
        /// The board's largest slice in bytes.
        max: u32,
    },
    /// A command that cannot be encoded.
    Encode(WireError),
    /// A frame sent `sends` times without an acknowledgement.
    TooNoisy {
        /// The frame (1-based) of `frames`.
        frame: usize,
        /// Frames in the transfer.
        frames: usize,
        /// Go-backs without progress.
        sends: u32,
        /// The last answer.
        code: NackCode,
    },
    /// The board refused the protocol version (`Nack BadVersion`).
    BadVersion,
    /// The board cannot hold the volume's slices (`Nack DimsOverCapacity`).
    DimsOverCapacity {
        /// Samples along x and y.
        dims: [u16; 2],
        /// The board's largest slice in bytes.
        max: u32,
    },
    /// The board refused a command as invalid.
    Invalid(u16),
    /// The board abandoned the transfer (`Missing` or `Aborted`).
    Abandoned(NackCode),
    /// Timeouts in a row past `SendConfig::max_timeouts`.
    StoppedAnswering(u32),
}

impl fmt::Display for SendError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::NoAnswer => {
                write!(f, "no answer from the board (is it connected, and is this its port and baud rate?)")
            }
            Self::BoardBusy => write!(f, "the board is busy with another client; try again once it is done"),
            Self::OtherProtocol(v) => {
                write!(f, "the board speaks protocol version {v}; this sender speaks {PROTOCOL_VERSION}")
            }
            Self::ClosedBeforeHello => write!(f, "the board closed the connection before it said hello"),
            Self::PortClosed => write!(f, "the port closed"),
            Self::NotConnected => write!(f, "the board has not said what it takes (connect first)"),
            Self::Settings(s) => f.write_str(s),
            Self::SampleType(t) => write!(f, "the board does not take {t:?} samples"),
            Self::SliceTooLarge { dims, sample_type, bytes, max } => write!(
                f,
                "a {}x{} slice of {sample_type:?} is {bytes} bytes; the board holds {max} \
                 (--downsample or --crop makes it smaller)",
                dims[0], dims[1]
            ),
            Self::Encode(e) => write!(f, "cannot encode a command: {e}"),
            Self::TooNoisy { frame, frames, sends, code } => write!(
                f,
                "frame {frame} of {frames} was sent {sends} times without an acknowledgement \
                 (last answer: {code:?}): the line is too noisy or the board keeps refusing; \
                 try a lower --baud, a smaller --chunk or --window"
            ),
            Self::BadVersion => write!(f, "the board does not speak protocol version {PROTOCOL_VERSION}"),
            Self::DimsOverCapacity { dims, max } => {
                write!(f, "the board cannot hold a {}x{} slice (its largest: {max} bytes)", dims[0], dims[1])
            }
            Self::Invalid(seq) => {
                write!(f, "the board refused command {seq} as invalid (levels, planes, view?)")
            }
            Self::Abandoned(code) => {
                write!(f, "the board abandoned the transfer ({code:?}); the old picture stays")
            }
            Self::StoppedAnswering(n) => write!(f, "the board stopped answering ({n} timeouts in a row)"),
        }
    }
}

impl std::error::Error for SendError {}

/// Where a [`Sender`] is.
#[derive(Debug, Clone, PartialEq)]
pub enum State {
    /// Saying hello.
    Greeting,
    /// The board said what it takes; [`Sender::start`] sends a volume.
    Connected,
    /// Sending a volume.
    Sending,
    /// Every frame acknowledged; waiting for the board's new picture.
    Picture,
    /// Done: the transfer's report.
    Done(SendReport),
    /// Failed for good.
    Failed(SendError),
}

/// How far a transfer has got.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SendProgress {
    /// Frames acknowledged in order.
    pub frames_acked: usize,
    /// Frames in the transfer.
    pub frames: usize,
    /// Sample bytes in the frames acknowledged.
    pub bytes_acked: u64,
    /// Sample bytes in the transfer.
    pub bytes: u64,
    /// Frames sent again so far (hellos included).
    pub retransmitted: u64,
    /// Timeouts so far.
    pub timeouts: u32,
}

/// A board's answer, owned.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Reply {
    Hello {
        protocol: u8,
        firmware: [u8; 3],
    },
    Capabilities {
        max_slice_samples: u32,
        sample_types: u8,
        display_points: u32,
    },
    Ack(u16),
    Nack(u16, NackCode),
    Status {
        state: DeviceState,
        points: u32,
        refresh_centi_hz: u16,
    },
    /// Another message, or a frame that did not decode.
    Other,
}

impl Reply {
    fn of(m: Result<Message<'_>, WireError>) -> Self {
        match m {
            Ok(Message::Hello { protocol, firmware, .. }) => Self::Hello { protocol, firmware },
            Ok(Message::Capabilities { max_slice_samples, sample_types, display_points, .. }) => {
                Self::Capabilities { max_slice_samples, sample_types, display_points }
            }
            Ok(Message::Ack { seq }) => Self::Ack(seq),
            Ok(Message::Nack { seq, code }) => Self::Nack(seq, code),
            Ok(Message::Status { state, points, refresh_centi_hz, .. }) => {
                Self::Status { state, points, refresh_centi_hz }
            }
            Ok(_) | Err(_) => Self::Other,
        }
    }
}

enum Phase {
    Greeting(Greeting),
    Connected(BoardInfo),
    Sending(Box<Transfer>),
    Picture { report: SendReport, end_sent_at: Option<Duration>, until: Duration },
    Done(SendReport),
    Failed(SendError),
}

struct Greeting {
    /// Hellos sent (or about to be).
    hellos: u32,
    /// The hello to write, `None` once written.
    pending: bool,
    /// Until when the last hello waits.
    until: Duration,
    firmware: Option<[u8; 3]>,
}

/// A volume on its way.
struct Transfer {
    /// The first frame's sequence number.
    seq0: u16,
    frames: Vec<Vec<u8>>,
    /// Sample bytes in each frame.
    payload: Vec<u32>,
    /// The largest window; answers are matched against it.
    window: usize,
    /// The window now: halved at each damaged frame, grown back by one at
    /// each acknowledgement.
    win: usize,
    /// Go-backs since the oldest frame in flight last advanced.
    stalls: u32,
    /// How long the oldest frame waits for an answer.
    timeout: Duration,
    max_timeouts: u32,
    dims: [u16; 2],
    report: SendReport,
    acked: Vec<bool>,
    sent_epoch: Vec<u32>,
    ever_sent: Vec<bool>,
    base: usize,
    next: usize,
    epoch: u32,
    /// The board answers frames in the order it receives them, so answers
    /// come in increasing frame order until a go-back's frames reach it.
    /// After a go-back, the answers still due for the frames in flight
    /// before it (OutOfOrder, after the loss that caused the go-back) are
    /// not new losses: an answer for a frame no later than the last one
    /// answered shows the resent frames have arrived (`settled`).
    last_idx: Option<usize>,
    settled: bool,
    timeouts_in_row: u32,
    bytes_acked: u64,
    /// When the transfer started, and when `EndVolume` was last written.
    t0: Duration,
    end_sent_at: Option<Duration>,
    /// The answer timer runs from here: the last frame written or answer
    /// read, or the end of a pause.
    since: Duration,
    /// No frame is written before this (a pause after `Busy`).
    resume_at: Option<Duration>,
}

/// The sender: see the module's documentation.
pub struct Sender {
    decoder: FrameDecoder<512>,
    seq0: u16,
    phase: Phase,
    /// The board's last status report, whenever it came.
    status: Option<(DeviceState, u32, u16)>,
}

impl fmt::Debug for Sender {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Sender").field("state", &self.state()).finish_non_exhaustive()
    }
}

fn frame(msg: &Message<'_>) -> Result<Vec<u8>, SendError> {
    let mut buf = vec![0u8; MAX_FRAME_LEN];
    Ok(encode(msg, &mut buf).map_err(SendError::Encode)?.to_vec())
}

fn crate_version() -> [u8; 3] {
    let mut v = env!("CARGO_PKG_VERSION").split('.').map(|x| x.parse().unwrap_or(0));
    [v.next().unwrap_or(0), v.next().unwrap_or(0), v.next().unwrap_or(0)]
}

impl Sender {
    /// A sender about to greet the board; every command it sends has a
    /// consecutive sequence number from `seq0`, which its hello announces.
    pub fn new(seq0: u16, now: Duration) -> Self {
        let greeting = Greeting { hellos: 1, pending: true, until: now, firmware: None };
        Self { decoder: FrameDecoder::new(), seq0, phase: Phase::Greeting(greeting), status: None }
    }

    /// Where it is.
    pub fn state(&self) -> State {
        match &self.phase {
            Phase::Greeting(_) => State::Greeting,
            Phase::Connected(_) => State::Connected,
            Phase::Sending(_) => State::Sending,
            Phase::Picture { .. } => State::Picture,
            Phase::Done(r) => State::Done(r.clone()),
            Phase::Failed(e) => State::Failed(e.clone()),
        }
    }

    /// What the board said it takes, once it has.
    pub fn board(&self) -> Option<&BoardInfo> {
        match &self.phase {
            Phase::Greeting(_) | Phase::Failed(_) => None,
            Phase::Connected(b) => Some(b),
            Phase::Sending(t) => Some(&t.report.board),
            Phase::Picture { report, .. } | Phase::Done(report) => Some(&report.board),
        }
    }

    /// The board's last status report: its state, points and refresh rate
    /// in hundredths of a hertz.
    pub fn board_status(&self) -> Option<(DeviceState, u32, u16)> {
        self.status
    }

    /// How far the transfer has got (zeros before it starts).
    pub fn progress(&self) -> SendProgress {
        let of = |r: &SendReport, acked: usize, bytes_acked: u64| SendProgress {
            frames_acked: acked,
            frames: r.frames as usize,
            bytes_acked,
            bytes: r.payload_bytes,
            retransmitted: r.retransmitted,
            timeouts: r.timeouts,
        };
        match &self.phase {
            Phase::Sending(t) => of(&t.report, t.base, t.bytes_acked),
            Phase::Picture { report, .. } | Phase::Done(report) => {
                of(report, report.frames as usize, report.payload_bytes)
            }
            _ => SendProgress::default(),
        }
    }

    /// The error it failed with, if it has.
    pub fn error(&self) -> Option<&SendError> {
        match &self.phase {
            Phase::Failed(e) => Some(e),
            _ => None,
        }
    }

    fn fail(&mut self, e: SendError) -> SendError {
        self.phase = Phase::Failed(e.clone());
        e
    }

    /// Fail unless it has failed already; then its error.
    fn check(&self) -> Result<(), SendError> {
        self.error().map_or(Ok(()), |e| Err(e.clone()))
    }

    /// Send `vol` as `cfg` says, once the board has said what it takes.
    ///
    /// # Errors
    /// Not connected, settings or a volume the board cannot take.
    pub fn start(&mut self, vol: &WireVolume, cfg: &SendConfig, now: Duration) -> Result<(), SendError> {
        self.check()?;
        let Phase::Connected(board) = self.phase else { return Err(SendError::NotConnected) };
        let levels = cfg.check().map_err(|e| SendError::Settings(format!("{e:#}")))?;
        if board.sample_types & vol.sample_type.bit() == 0 {
            return Err(SendError::SampleType(vol.sample_type));
        }
        if vol.slice_bytes() as u64 > u64::from(board.max_slice_samples) {
            return Err(SendError::SliceTooLarge {
                dims: [vol.dims[0], vol.dims[1]],
                sample_type: vol.sample_type,
                bytes: vol.slice_bytes(),
                max: board.max_slice_samples,
            });
        }
        let mut frames = Vec::new();
        let mut payload = Vec::new();
        for m in volume_messages(vol, cfg, levels, self.seq0) {
            payload.push(match &m {
                Message::SliceData { data, .. } => data.len() as u32,
                _ => 0,
            });
            frames.push(frame(&m)?);
        }
        let n = frames.len();
        let window = cfg.window.max(1);
        // Round trip allowance: a window of frames on the line, and time for
        // the board to contour a slice.
        let line_s = (frames.iter().take(window).map(Vec::len).sum::<usize>() * 10) as f64
            / f64::from(cfg.baud.max(1));
        let report = SendReport {
            board,
            payload_bytes: vol.bytes.len() as u64,
            wire_bytes: 0,
            frames: n as u64,
            // A Hello sent again is a frame retransmitted after a timeout.
            retransmitted: u64::from(board.hellos.saturating_sub(1)),
            nacks: Vec::new(),
            timeouts: board.hellos.saturating_sub(1),
            seconds: 0.0,
            end_ack_seconds: 0.0,
            picture_seconds: None,
            status: None,
        };
        self.phase = Phase::Sending(Box::new(Transfer {
            seq0: self.seq0,
            frames,
            payload,
            window,
            win: window,
            stalls: 0,
            timeout: Duration::from_secs_f64(0.5 + 2.0 * line_s),
            max_timeouts: cfg.max_timeouts,
            dims: [vol.dims[0], vol.dims[1]],
            report,
            acked: vec![false; n],
            sent_epoch: vec![0; n],
            ever_sent: vec![false; n],
            base: 0,
            next: 0,
            epoch: 0,
            last_idx: None,
            settled: true,
            timeouts_in_row: 0,
            bytes_acked: 0,
            t0: now,
            end_sent_at: None,
            since: now,
            resume_at: None,
        }));
        Ok(())
    }

    /// The next bytes to write now, if any: a hello, or a frame of the
    /// volume the window lets out. Call until `None`, then wait for the
    /// board until [`Sender::deadline`].
    pub fn transmit(&mut self, now: Duration) -> Option<Vec<u8>> {
        match &mut self.phase {
            Phase::Greeting(g) if g.pending => {
                g.pending = false;
                g.until = now + HELLO_WAIT;
                g.firmware = None;
                let msg =
                    Message::Hello { protocol: PROTOCOL_VERSION, firmware: crate_version(), seq: self.seq0 };
                match frame(&msg) {
                    Ok(f) => {
                        // A zero first flushes a partial frame in the board.
                        let mut hello = vec![0u8];
                        hello.extend(f);
                        Some(hello)
                    }
                    Err(e) => {
                        self.fail(e);
                        None
                    }
                }
            }
            Phase::Sending(t) => t.transmit(now),
            _ => None,
        }
    }

    /// When it must next be woken ([`Sender::on_time`]) if the board says
    /// nothing; `None`: it waits for nothing (connected, done or failed).
    pub fn deadline(&self) -> Option<Duration> {
        match &self.phase {
            Phase::Greeting(g) => Some(g.until),
            Phase::Sending(t) => Some(t.resume_at.unwrap_or(t.since + t.timeout)),
            Phase::Picture { until, .. } => Some(*until),
            Phase::Connected(_) | Phase::Done(_) | Phase::Failed(_) => None,
        }
    }

    /// The time is `now`: act on a deadline passed (a hello or a frame
    /// unanswered, the end of a pause, no status after the volume).
    ///
    /// # Errors
    /// The board gave no answer in time, too often.
    pub fn on_time(&mut self, now: Duration) -> Result<(), SendError> {
        self.check()?;
        match &mut self.phase {
            Phase::Greeting(g) if !g.pending && now >= g.until => {
                if g.hellos >= HELLO_TRIES {
                    return Err(self.fail(SendError::NoAnswer));
                }
                g.hellos += 1;
                g.pending = true;
            }
            Phase::Sending(t) => {
                if let Err(e) = t.on_time(now) {
                    return Err(self.fail(e));
                }
            }
            Phase::Picture { report, until, .. } if now >= *until => {
                self.phase = Phase::Done(std::mem::take(report));
            }
            _ => {}
        }
        Ok(())
    }

    /// `bytes` came from the board at `now`.
    ///
    /// # Errors
    /// The board refused the transfer, or speaks another protocol.
    pub fn receive(&mut self, bytes: &[u8], now: Duration) -> Result<(), SendError> {
        self.check()?;
        for &b in bytes {
            let Some(m) = self.decoder.push(b) else { continue };
            let reply = Reply::of(m);
            if let Err(e) = self.answer(reply, now) {
                return Err(self.fail(e));
            }
        }
        Ok(())
    }

    /// The port closed at `now`.
    ///
    /// # Errors
    /// Unless the transfer is done: the board closed before its hello, or
    /// the port closed.
    pub fn closed(&mut self, now: Duration) -> Result<(), SendError> {
        self.check()?;
        match &mut self.phase {
            Phase::Greeting(_) => Err(self.fail(SendError::ClosedBeforeHello)),
            Phase::Connected(_) | Phase::Sending(_) => Err(self.fail(SendError::PortClosed)),
            Phase::Picture { until, .. } => {
                // No status is coming: done without it.
                *until = now;
                self.on_time(now)
            }
            Phase::Done(_) | Phase::Failed(_) => Ok(()),
        }
    }

    fn answer(&mut self, reply: Reply, now: Duration) -> Result<(), SendError> {
        if let Reply::Status { state, points, refresh_centi_hz } = reply {
            self.status = Some((state, points, refresh_centi_hz));
        }
        match &mut self.phase {
            Phase::Greeting(g) => match reply {
                Reply::Hello { protocol, firmware } => {
                    if protocol != PROTOCOL_VERSION {
                        return Err(SendError::OtherProtocol(protocol));
                    }
                    g.firmware = Some(firmware);
                }
                Reply::Capabilities { max_slice_samples, sample_types, display_points } => {
                    self.phase = Phase::Connected(BoardInfo {
                        firmware: g.firmware.unwrap_or_default(),
                        max_slice_samples,
                        sample_types,
                        display_points,
                        hellos: g.hellos,
                    });
                }
                Reply::Nack(_, NackCode::Busy) if g.firmware.is_none() => return Err(SendError::BoardBusy),
                _ => {}
            },
            Phase::Sending(t) => {
                if t.answer(reply, now)? {
                    let mut report = std::mem::take(&mut t.report);
                    report.seconds = now.saturating_sub(t.t0).as_secs_f64();
                    report.end_ack_seconds =
                        t.end_sent_at.map_or(0.0, |e| now.saturating_sub(e).as_secs_f64());
                    // The board reports its status once the new picture is
                    // drawn.
                    report.status = None;
                    let end_sent_at = t.end_sent_at;
                    self.phase = Phase::Picture { report, end_sent_at, until: now + PICTURE_WAIT };
                }
            }
            Phase::Picture { report, end_sent_at, .. } => {
                if let Reply::Status { state, points, refresh_centi_hz } = reply {
                    report.status = Some((state, points, refresh_centi_hz));
                    report.picture_seconds = end_sent_at.map(|e| now.saturating_sub(e).as_secs_f64());
                    self.phase = Phase::Done(std::mem::take(report));
                }
            }
            Phase::Connected(_) | Phase::Done(_) | Phase::Failed(_) => {}
        }
        Ok(())
    }
}

impl Transfer {
    fn transmit(&mut self, now: Duration) -> Option<Vec<u8>> {
        let n = self.frames.len();
        if self.resume_at.is_some_and(|r| now < r) || self.next >= n || self.next >= self.base + self.win {
            return None;
        }
        self.resume_at = None;
        let k = self.next;
        self.report.wire_bytes += self.frames[k].len() as u64;
        if self.ever_sent[k] {
            self.report.retransmitted += 1;
        }
        self.ever_sent[k] = true;
        self.sent_epoch[k] = self.epoch;
        if k == n - 1 {
            self.end_sent_at = Some(now);
        }
        self.next += 1;
        self.since = self.since.max(now);
        Some(self.frames[k].clone())
    }

    fn on_time(&mut self, now: Duration) -> Result<(), SendError> {
        if let Some(r) = self.resume_at {
            if now >= r {
                self.resume_at = None;
            }
            return Ok(());
        }
        if now < self.since + self.timeout {
            return Ok(());
        }
        self.report.timeouts += 1;
        self.timeouts_in_row += 1;
        if self.timeouts_in_row > self.max_timeouts {
            return Err(SendError::StoppedAnswering(self.timeouts_in_row));
        }
        self.epoch += 1;
        self.next = self.base;
        // Whatever was in flight is lost or answered by now.
        self.settled = true;
        self.win = (self.win / 2).max(1);
        self.since = now;
        Ok(())
    }

    /// The frame an answer for `seq` is about, if it is in the window.
    fn index(&self, seq: u16) -> Option<usize> {
        let rel = usize::from(seq.wrapping_sub(self.seq0.wrapping_add(self.base as u16)));
        (rel < self.window && self.base + rel < self.frames.len()).then_some(self.base + rel)
    }

    /// Move the oldest frame in flight past those acknowledged.
    fn advance(&mut self, progress: bool) {
        while self.base < self.frames.len() && self.acked[self.base] {
            self.bytes_acked += u64::from(self.payload[self.base]);
            self.base += 1;
            if progress {
                self.stalls = 0;
                self.win = (self.win + 1).min(self.window);
            }
        }
    }

    /// Take the board's answer; whether every frame is acknowledged.
    fn answer(&mut self, reply: Reply, now: Duration) -> Result<bool, SendError> {
        let n = self.frames.len();
        self.since = self.since.max(now);
        match reply {
            Reply::Ack(s) => {
                self.timeouts_in_row = 0;
                if let Some(i) = self.index(s) {
                    self.acked[i] = true;
                    self.settled |= self.last_idx.is_some_and(|l| i <= l);
                    self.last_idx = Some(i);
                }
                self.advance(true);
            }
            Reply::Nack(s, code) => {
                self.timeouts_in_row = 0;
                match self.report.nacks.iter_mut().find(|(c, _)| *c == code) {
                    Some((_, k)) => *k += 1,
                    None => self.report.nacks.push((code, 1)),
                }
                let idx = self.index(s);
                if let Some(i) = idx {
                    self.settled |= self.last_idx.is_some_and(|l| i <= l);
                    self.last_idx = Some(i);
                }
                self.nack(s, code, idx, now)?;
            }
            Reply::Status { state, points, refresh_centi_hz } => {
                self.report.status = Some((state, points, refresh_centi_hz));
            }
            Reply::Hello { .. } | Reply::Capabilities { .. } | Reply::Other => {}
        }
        Ok(self.base >= n)
    }

    fn nack(&mut self, s: u16, code: NackCode, idx: Option<usize>, now: Duration) -> Result<(), SendError> {
        let n = self.frames.len();
        match code {
            // It has it already (a retransmission crossed an ack).
            NackCode::Duplicate => {
                if let Some(i) = idx {
                    self.acked[i] = true;
                }
                self.advance(false);
            }
            // Lost or damaged on the line (a damaged delimiter joins two
            // frames into one too long: Oversize), or the board busy for a
            // moment: go back to the oldest unacknowledged frame, once per
            // loss, with a smaller window after damage and a pause after
            // Busy.
            NackCode::OutOfOrder
            | NackCode::BadCrc
            | NackCode::Truncated
            | NackCode::UnknownMessage
            | NackCode::Oversize
            | NackCode::Busy => {
                let stale = idx.is_some_and(|i| self.sent_epoch[i] != self.epoch)
                    || (code == NackCode::OutOfOrder && !self.settled);
                if !stale && self.next > self.base {
                    self.epoch += 1;
                    self.next = self.base;
                    self.settled = false;
                    self.stalls += 1;
                    if self.stalls > MAX_STALLS {
                        return Err(SendError::TooNoisy {
                            frame: self.base + 1,
                            frames: n,
                            sends: self.stalls,
                            code,
                        });
                    }
                    if code == NackCode::Busy {
                        // 10, 20, 40 ... 200 ms.
                        let pause = Duration::from_millis((10u64 << self.stalls.min(6)).min(200));
                        self.resume_at = Some(now + pause);
                        self.since = now + pause;
                    } else if code != NackCode::OutOfOrder {
                        self.win = (self.win / 2).max(1);
                    }
                }
            }
            NackCode::BadVersion => return Err(SendError::BadVersion),
            NackCode::DimsOverCapacity => {
                return Err(SendError::DimsOverCapacity {
                    dims: self.dims,
                    max: self.report.board.max_slice_samples,
                });
            }
            NackCode::Invalid => return Err(SendError::Invalid(s)),
            NackCode::Missing | NackCode::Aborted => return Err(SendError::Abandoned(code)),
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::board::{HostBuffers, host_capacity};
    use crate::volume::LoadedVolume;
    use isoscope_core::engine::{Engine, EngineConfig};

    fn hydrogen(n: usize) -> WireVolume {
        let spec = format!("hydrogen:{n}").parse().unwrap();
        WireVolume::from_loaded(&LoadedVolume::demo(spec).unwrap()).unwrap()
    }

    fn cfg() -> SendConfig {
        SendConfig { levels: vec![0.1], chunk: 128, window: 4, ..SendConfig::default() }
    }

    /// What a run did: the bytes written, one entry a `transmit`.
    struct Run {
        written: Vec<Vec<u8>>,
        result: Result<SendReport, SendError>,
    }

    /// Drive `sender` against `board` (`None`: a silent line) on a clock
    /// of whole milliseconds, as a driver does: write what it gives,
    /// hand it the board's answers, wake it each millisecond. Loses the
    /// `lose`-th write. Sends `vol` once connected.
    fn run(mut board: Option<&mut Engine<'_>>, vol: &WireVolume, lose: Option<usize>) -> Run {
        let mut sender = Sender::new(0xBEEF, Duration::ZERO);
        let mut written = Vec::new();
        for t in 0..200_000u32 {
            let now = Duration::from_millis(u64::from(t));
            if sender.state() == State::Connected
                && let Err(e) = sender.start(vol, &cfg(), now)
            {
                return Run { written, result: Err(e) };
            }
            while let Some(bytes) = sender.transmit(now) {
                if let Some(b) = board.as_deref_mut()
                    && lose != Some(written.len())
                {
                    b.feed(&bytes, t);
                }
                written.push(bytes);
            }
            let mut out = [0u8; 4096];
            let n = board.as_deref_mut().map_or(0, |b| {
                b.update(t);
                b.transmit(&mut out)
            });
            let step = if n > 0 { sender.receive(&out[..n], now) } else { sender.on_time(now) };
            match (step, sender.state()) {
                (Err(e), _) => return Run { written, result: Err(e) },
                (Ok(()), State::Done(report)) => return Run { written, result: Ok(report) },
                _ => {}
            }
        }
        panic!("the sender neither finished nor failed in 200 s: {sender:?}");
    }

    fn engine(mem: &mut HostBuffers) -> Engine<'_> {
        Engine::new(EngineConfig::default(), mem.buffers()).unwrap()
    }

    /// On a clean line every frame is written once, and they are the
    /// flush, the hello and `volume_messages`' frames, in order.
    #[test]
    fn a_clean_line_carries_each_frame_once() {
        let vol = hydrogen(8);
        let mut mem = HostBuffers::new(&host_capacity(8 * 8 * 4, 16, 10_000));
        let mut board = engine(&mut mem);
        let Run { written, result } = run(Some(&mut board), &vol, None);
        let report = result.unwrap();
        let hello = Message::Hello { protocol: PROTOCOL_VERSION, firmware: crate_version(), seq: 0xBEEF };
        let mut want = vec![[vec![0], frame(&hello).unwrap()].concat()];
        let levels = cfg().check().unwrap();
        want.extend(volume_messages(&vol, &cfg(), levels, 0xBEEF).map(|m| frame(&m).unwrap()));
        assert_eq!(written, want);
        assert_eq!((report.retransmitted, report.timeouts, report.frames), (0, 0, want.len() as u64 - 1));
        assert_eq!(report.wire_bytes, want[1..].iter().map(|f| f.len() as u64).sum::<u64>());
        let (state, points, _) = report.status.expect("the board's status after the picture");
        assert_eq!(state, DeviceState::Showing);
        assert!(points > 0 && board.surface().is_some());
    }

    /// The loss of any one write, the hello's included, is recovered by
    /// the sender's deadlines alone (a go-back after the board's nack, or
    /// a timeout), and the board shows the clean run's picture.
    #[test]
    fn losing_any_one_write_is_recovered() {
        let vol = hydrogen(8);
        let clean = {
            let mut mem = HostBuffers::new(&host_capacity(8 * 8 * 4, 16, 10_000));
            let mut board = engine(&mut mem);
            run(Some(&mut board), &vol, None)
        };
        let points = clean.result.unwrap().status.unwrap().1;
        for k in 0..clean.written.len() {
            let mut mem = HostBuffers::new(&host_capacity(8 * 8 * 4, 16, 10_000));
            let mut board = engine(&mut mem);
            let report =
                run(Some(&mut board), &vol, Some(k)).result.unwrap_or_else(|e| panic!("write {k}: {e}"));
            assert!(report.retransmitted > 0, "write {k} lost: {report:?}");
            assert_eq!(report.status.map(|s| s.1), Some(points), "write {k} lost");
        }
    }

    /// A silent line: three hellos, each after the last waited
    /// `HELLO_WAIT`, then a plain error.
    #[test]
    fn a_silent_board_is_greeted_three_times() {
        let Run { written, result } = run(None, &hydrogen(4), None);
        assert_eq!(result.unwrap_err(), SendError::NoAnswer);
        assert_eq!(written.len(), HELLO_TRIES as usize);
        assert!(written.iter().all(|w| *w == written[0]));
        let mut s = Sender::new(7, Duration::ZERO);
        assert!(s.transmit(Duration::ZERO).is_some());
        assert_eq!(s.deadline(), Some(HELLO_WAIT));
        s.on_time(HELLO_WAIT - Duration::from_millis(1)).unwrap();
        assert!(s.transmit(HELLO_WAIT).is_none(), "a hello again before its deadline");
        assert_eq!(s.start(&hydrogen(4), &cfg(), HELLO_WAIT), Err(SendError::NotConnected));
        assert_eq!(s.closed(HELLO_WAIT), Err(SendError::ClosedBeforeHello));
        assert_eq!(s.on_time(HELLO_WAIT * 9), Err(SendError::ClosedBeforeHello), "failed for good");
    }

    /// A board that greets and then falls silent is given up on after
    /// `max_timeouts` timeouts in a row, each sending the window again.
    #[test]
    fn a_board_that_falls_silent_is_given_up_on() {
        let vol = hydrogen(8);
        let mut mem = HostBuffers::new(&host_capacity(8 * 8 * 4, 16, 10_000));
        let mut board = engine(&mut mem);
        let mut s = Sender::new(1, Duration::ZERO);
        let hello = s.transmit(Duration::ZERO).unwrap();
        board.feed(&hello, 0);
        board.update(0);
        let mut out = [0u8; 4096];
        let n = board.transmit(&mut out);
        s.receive(&out[..n], Duration::ZERO).unwrap();
        assert_eq!(s.state(), State::Connected);
        assert!(s.board().is_some_and(|b| b.hellos == 1));
        s.start(&vol, &cfg(), Duration::ZERO).unwrap();
        let mut now = Duration::ZERO;
        let mut err = None;
        for _ in 0..100 {
            while s.transmit(now).is_some() {}
            now = s.deadline().unwrap();
            if let Err(e) = s.on_time(now) {
                err = Some(e);
                break;
            }
        }
        let max = SendConfig::default().max_timeouts;
        assert_eq!(err, Some(SendError::StoppedAnswering(max + 1)));
        assert!(err.unwrap().to_string().contains("stopped answering"));
    }
}
