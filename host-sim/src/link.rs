//! The host side of the UART link: open a serial port (a tty, a
//! pseudo-terminal, or a TCP socket such as QEMU's serial chardev) and
//! stream a volume to the board with a send window, go-back-N
//! retransmission, and a report of throughput and payload efficiency.

use crate::progress::Progress;
use crate::volume::{Dims, LoadedVolume, Samples};
use anyhow::{Context, Result, anyhow, bail};
use isoscope_core::wire::{
    DeviceState, FrameDecoder, Levels, MAX_CHUNK, Message, NackCode, PROTOCOL_VERSION, SampleType, WireError,
    encode,
};
use std::io::{ErrorKind, Read, Write};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// A volume as it goes on the wire: little-endian samples, z slice by z
/// slice.
#[derive(Debug, Clone, PartialEq)]
pub struct WireVolume {
    /// Samples along x, y, z.
    pub dims: [u16; 3],
    /// The samples' type.
    pub sample_type: SampleType,
    /// Voxel spacing.
    pub spacing: [f32; 3],
    /// All samples, little-endian, x fastest.
    pub bytes: Vec<u8>,
}

impl WireVolume {
    /// The volume in its own sample type.
    ///
    /// # Errors
    /// An extent above 65535.
    pub fn from_loaded(v: &LoadedVolume) -> Result<Self> {
        Self::new(v.dims, &v.samples, v.spacing)
    }

    /// `samples` (x fastest) of a `dims` volume with voxel `spacing`.
    ///
    /// # Errors
    /// An extent above 65535.
    pub fn new(dims: Dims, samples: &Samples, spacing: [f32; 3]) -> Result<Self> {
        let Dims(nx, ny, nz) = dims;
        let d = |n: usize, axis: &str| {
            u16::try_from(n)
                .map_err(|_| anyhow!("the volume has {n} samples along {axis}; the protocol takes 65535"))
        };
        let dims = [d(nx, "x")?, d(ny, "y")?, d(nz, "z")?];
        let (sample_type, bytes) = match samples {
            Samples::U8(s) => (SampleType::U8, s.clone()),
            Samples::U16(s) => (SampleType::U16, s.iter().flat_map(|x| x.to_le_bytes()).collect()),
            Samples::I16(s) => (SampleType::I16, s.iter().flat_map(|x| x.to_le_bytes()).collect()),
            Samples::F32(s) => (SampleType::F32, s.iter().flat_map(|x| x.to_le_bytes()).collect()),
        };
        Ok(Self { dims, sample_type, spacing, bytes })
    }

    /// Bytes in one z slice.
    pub fn slice_bytes(&self) -> usize {
        usize::from(self.dims[0]) * usize::from(self.dims[1]) * self.sample_type.size()
    }
}

/// A view to set on the board before the volume.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewSetting {
    /// Yaw, pitch, roll in degrees.
    pub angles: [f32; 3],
    /// Field of view (0: orthographic).
    pub fov_deg: f32,
    /// Spin, degrees per second.
    pub spin_deg_per_s: f32,
}

impl ViewSetting {
    /// The perspective's field of view, `None` for orthographic.
    pub fn perspective(&self) -> Option<f32> {
        (self.fov_deg != 0.0).then_some(self.fov_deg)
    }

    /// Check it as the board will (the core's view fit), so that a bad
    /// angle is refused before a port is opened, not by the board after
    /// the volume.
    ///
    /// # Errors
    /// An angle or the spin is not finite, or the field of view is out of
    /// the core's range.
    pub fn check(&self) -> Result<()> {
        use isoscope_core::view::{Bounds, Projection, View, ViewTransform};
        let [yaw, pitch, roll] = self.angles;
        let projection = match self.perspective() {
            Some(fov_deg) => Projection::Perspective { fov_deg },
            None => Projection::Orthographic,
        };
        let view = View { yaw, pitch, roll, projection, ..View::DEFAULT };
        let unit = Bounds::of_volume(2, 2, 2).map_err(|e| anyhow!("{e}"))?;
        ViewTransform::fit(&view, unit).map_err(|e| anyhow!("invalid view: {e}"))?;
        if !self.spin_deg_per_s.is_finite() {
            bail!("invalid view: the spin is not finite");
        }
        Ok(())
    }
}

/// How to send.
#[derive(Debug, Clone, PartialEq)]
pub struct SendConfig {
    /// Contour levels (at most 8).
    pub levels: Vec<f32>,
    /// Slicing planes: a set of `wire::AXIS_*` bits.
    pub axes: u8,
    /// Contour every `every`-th slice of each plane.
    pub every: u8,
    /// Frames in flight before waiting for acknowledgements.
    pub window: usize,
    /// Data bytes per chunk (at most [`MAX_CHUNK`]).
    pub chunk: usize,
    /// The line rate in bit/s (for the timeout and the efficiency).
    pub baud: u32,
    /// A view to set first.
    pub view: Option<ViewSetting>,
    /// Timeouts in a row before giving up.
    pub max_timeouts: u32,
}

impl SendConfig {
    /// Check what can be checked before a port is opened: the levels (at
    /// most [`isoscope_core::wire::MAX_LEVELS`], finite), the chunk size,
    /// the window and the view.
    ///
    /// # Errors
    /// Which setting is wrong and why.
    pub fn check(&self) -> Result<Levels> {
        let levels = Levels::from_slice(&self.levels)
            .with_context(|| format!("at most {} levels go to the board", isoscope_core::wire::MAX_LEVELS))?;
        if !self.levels.iter().all(|l| l.is_finite()) {
            bail!("a level is not finite");
        }
        if self.chunk == 0 || self.chunk > MAX_CHUNK {
            bail!("the chunk size must be 1..={MAX_CHUNK} bytes");
        }
        if self.window == 0 {
            bail!("the send window must be at least 1 frame");
        }
        if let Some(v) = &self.view {
            v.check()?;
        }
        Ok(levels)
    }
}

impl Default for SendConfig {
    fn default() -> Self {
        Self {
            levels: Vec::new(),
            axes: isoscope_core::wire::AXIS_X | isoscope_core::wire::AXIS_Y | isoscope_core::wire::AXIS_Z,
            every: 1,
            window: 8,
            chunk: MAX_CHUNK,
            baud: 921_600,
            view: None,
            max_timeouts: 8,
        }
    }
}

/// What the board said about itself.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BoardInfo {
    /// Its firmware version.
    pub firmware: [u8; 3],
    /// The largest slice in bytes of `u8` samples.
    pub max_slice_samples: u32,
    /// Sample types it takes (bit set).
    pub sample_types: u8,
    /// Points its display list holds.
    pub display_points: u32,
    /// Hellos sent before it answered (1 on a clean line; each more is a
    /// timeout and a retransmission).
    pub hellos: u32,
}

/// What a transfer did.
#[derive(Debug, Clone, PartialEq)]
pub struct SendReport {
    /// The board.
    pub board: BoardInfo,
    /// Sample bytes delivered.
    pub payload_bytes: u64,
    /// Bytes written to the line (all frames, retransmissions included).
    pub wire_bytes: u64,
    /// Frames in the transfer.
    pub frames: u64,
    /// Frames sent again.
    pub retransmitted: u64,
    /// Nacks received, by code.
    pub nacks: Vec<(NackCode, u32)>,
    /// Timeouts (no acknowledgement in time).
    pub timeouts: u32,
    /// From the first frame of the volume to the last acknowledgement.
    pub seconds: f64,
    /// From writing `EndVolume` (right after the last slice) to its
    /// acknowledgement.
    pub end_ack_seconds: f64,
    /// From writing `EndVolume` to the board's status report, which it sends
    /// once the new picture is on screen (contoured, stitched, ordered).
    pub picture_seconds: Option<f64>,
    /// The board's status after the volume.
    pub status: Option<(DeviceState, u32, u16)>,
}

impl SendReport {
    /// Payload bytes per second.
    pub fn throughput(&self) -> f64 {
        self.payload_bytes as f64 / self.seconds.max(1e-9)
    }

    /// Payload throughput as a share of the line rate (8N1: 10 bits a byte).
    pub fn efficiency(&self, baud: u32) -> f64 {
        self.throughput() * 10.0 / f64::from(baud.max(1))
    }

    /// The report as `key=value` lines.
    pub fn report(&self, baud: u32) -> String {
        let mut s = String::new();
        let mut kv = |k: &str, v: String| s.push_str(&format!("{k}={v}\n"));
        kv("payload_bytes", self.payload_bytes.to_string());
        kv("wire_bytes", self.wire_bytes.to_string());
        kv("frames", self.frames.to_string());
        kv("retransmitted_frames", self.retransmitted.to_string());
        kv("timeouts", self.timeouts.to_string());
        let nacks: Vec<String> = self.nacks.iter().map(|(c, n)| format!("{c:?}:{n}")).collect();
        kv("nacks", if nacks.is_empty() { "0".into() } else { nacks.join(",") });
        kv("seconds", format!("{:.3}", self.seconds));
        kv("throughput_bytes_per_s", format!("{:.0}", self.throughput()));
        kv("line_rate_bytes_per_s", format!("{:.0}", f64::from(baud) / 10.0));
        kv("payload_efficiency", format!("{:.4}", self.efficiency(baud)));
        kv("end_to_ack_ms", format!("{:.1}", self.end_ack_seconds * 1e3));
        if let Some(p) = self.picture_seconds {
            kv("last_slice_to_picture_ms", format!("{:.1}", p * 1e3));
        }
        if let Some((state, points, centi_hz)) = self.status {
            kv("board_state", format!("{state:?}"));
            kv("board_points", points.to_string());
            kv("board_refresh_hz", format!("{:.2}", f64::from(centi_hz) / 100.0));
        }
        s
    }
}

/// A message from the board, owned.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Reply {
    Msg(OwnedReply),
    Bad(WireError),
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum OwnedReply {
    Hello { protocol: u8, firmware: [u8; 3] },
    Capabilities { max_slice_samples: u32, sample_types: u8, display_points: u32 },
    Ack(u16),
    Nack(u16, NackCode),
    Status { state: DeviceState, points: u32, refresh_centi_hz: u16 },
    Other,
}

/// Reads the board's frames on a thread.
struct Listener {
    rx: Receiver<Reply>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl Listener {
    fn start<R: Read + Send + 'static>(mut reader: R) -> Self {
        let (tx, rx) = mpsc::channel();
        let stop = Arc::new(AtomicBool::new(false));
        let halt = stop.clone();
        let thread = std::thread::spawn(move || {
            let mut dec = FrameDecoder::<512>::new();
            let mut buf = [0u8; 4096];
            while !halt.load(Ordering::Relaxed) {
                let n = match reader.read(&mut buf) {
                    Ok(0) => {
                        std::thread::sleep(Duration::from_millis(2));
                        continue;
                    }
                    Ok(n) => n,
                    Err(e)
                        if matches!(
                            e.kind(),
                            ErrorKind::WouldBlock | ErrorKind::TimedOut | ErrorKind::Interrupted
                        ) =>
                    {
                        continue;
                    }
                    Err(_) => return,
                };
                for &b in &buf[..n] {
                    let Some(r) = dec.push(b) else { continue };
                    let reply = match r {
                        Err(e) => Reply::Bad(e),
                        Ok(m) => Reply::Msg(match m {
                            Message::Hello { protocol, firmware, .. } => {
                                OwnedReply::Hello { protocol, firmware }
                            }
                            Message::Capabilities {
                                max_slice_samples, sample_types, display_points, ..
                            } => OwnedReply::Capabilities { max_slice_samples, sample_types, display_points },
                            Message::Ack { seq } => OwnedReply::Ack(seq),
                            Message::Nack { seq, code } => OwnedReply::Nack(seq, code),
                            Message::Status { state, points, refresh_centi_hz, .. } => {
                                OwnedReply::Status { state, points, refresh_centi_hz }
                            }
                            _ => OwnedReply::Other,
                        }),
                    };
                    if tx.send(reply).is_err() {
                        return;
                    }
                }
            }
        });
        Self { rx, stop, thread: Some(thread) }
    }
}

impl Drop for Listener {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn frame(msg: &Message<'_>) -> Result<Vec<u8>> {
    let mut buf = vec![0u8; isoscope_core::wire::MAX_FRAME_LEN];
    Ok(encode(msg, &mut buf).map_err(|e| anyhow!("cannot encode {msg:?}: {e}"))?.to_vec())
}

/// Say hello and read the board's capabilities (three tries).
fn handshake(w: &mut impl Write, l: &Listener, seq0: u16) -> Result<BoardInfo> {
    let mut hello = vec![0u8]; // flush a partial frame in the board
    hello.extend(frame(&Message::Hello {
        protocol: PROTOCOL_VERSION,
        firmware: crate_version(),
        seq: seq0,
    })?);
    for hellos in 1..=3 {
        w.write_all(&hello).context("cannot write to the port")?;
        w.flush()?;
        let deadline = Instant::now() + Duration::from_millis(1500);
        let mut firmware = None;
        while let Some(left) = deadline.checked_duration_since(Instant::now()) {
            match l.rx.recv_timeout(left) {
                Ok(Reply::Msg(OwnedReply::Hello { protocol, firmware: f })) => {
                    if protocol != PROTOCOL_VERSION {
                        bail!(
                            "the board speaks protocol version {protocol}; this sender speaks {PROTOCOL_VERSION}"
                        );
                    }
                    firmware = Some(f);
                }
                Ok(Reply::Msg(OwnedReply::Capabilities {
                    max_slice_samples,
                    sample_types,
                    display_points,
                })) => {
                    return Ok(BoardInfo {
                        firmware: firmware.unwrap_or_default(),
                        max_slice_samples,
                        sample_types,
                        display_points,
                        hellos,
                    });
                }
                Ok(Reply::Msg(OwnedReply::Nack(_, NackCode::Busy))) if firmware.is_none() => {
                    bail!("the board is busy with another client; try again once it is done")
                }
                Ok(_) => {}
                Err(RecvTimeoutError::Timeout) => break,
                Err(RecvTimeoutError::Disconnected) => {
                    bail!("the board closed the connection before it said hello")
                }
            }
        }
    }
    bail!("no answer from the board (is it connected, and is this its port and baud rate?)")
}

fn crate_version() -> [u8; 3] {
    let mut v = env!("CARGO_PKG_VERSION").split('.').map(|x| x.parse().unwrap_or(0));
    [v.next().unwrap_or(0), v.next().unwrap_or(0), v.next().unwrap_or(0)]
}

/// The commands that put `vol` on a board as `cfg` says, with consecutive
/// sequence numbers from `seq0`: `SetView` (if `cfg.view`), `BeginVolume`,
/// `SliceData` chunks of `cfg.chunk` bytes z slice by z slice, `EndVolume`.
/// What [`send_volume`] sends, and what the host's in-process board
/// ([`crate::scene`]) is fed: one way onto a board.
pub fn volume_messages<'v>(
    vol: &'v WireVolume,
    cfg: &SendConfig,
    levels: Levels,
    seq0: u16,
) -> impl Iterator<Item = Message<'v>> + 'v {
    let (chunk, slice_bytes) = (cfg.chunk.max(1), vol.slice_bytes().max(1));
    let seq = move |k: usize| seq0.wrapping_add(k as u16);
    let head = usize::from(cfg.view.is_some());
    let view = cfg.view.map(|v| {
        let [yaw, pitch, roll] = v.angles;
        Message::SetView {
            seq: seq(0),
            yaw,
            pitch,
            roll,
            fov_deg: v.fov_deg,
            spin_deg_per_s: v.spin_deg_per_s,
        }
    });
    let begin = Message::BeginVolume {
        seq: seq(head),
        dims: vol.dims,
        sample_type: vol.sample_type,
        spacing: vol.spacing,
        levels,
        axes: cfg.axes,
        every: cfg.every,
    };
    let data = vol
        .bytes
        .chunks(slice_bytes)
        .enumerate()
        .flat_map(move |(z, slice)| {
            slice.chunks(chunk).enumerate().map(move |(k, data)| (z as u16, (k * chunk) as u32, data))
        })
        .enumerate()
        .map(move |(k, (slice, offset, data))| Message::SliceData {
            seq: seq(head + 1 + k),
            slice,
            offset,
            data,
        });
    let chunks: usize = vol.bytes.chunks(slice_bytes).map(|s| s.len().div_ceil(chunk)).sum();
    let end = Message::EndVolume { seq: seq(head + 1 + chunks) };
    view.into_iter().chain(core::iter::once(begin)).chain(data).chain(core::iter::once(end))
}

/// Go-backs without progress after which `send_volume` gives up.
pub const MAX_STALLS: u32 = 64;

/// Stream `vol` to the board behind `reader`/`writer`: [`connect`], then
/// [`Connection::send`].
///
/// # Errors
/// No answer, a volume the board cannot take, or a refused command.
pub fn send_volume<R, W>(
    reader: R,
    writer: W,
    vol: &WireVolume,
    cfg: &SendConfig,
    progress: Option<&Progress>,
) -> Result<SendReport>
where
    R: Read + Send + 'static,
    W: Write,
{
    cfg.check()?;
    connect(reader, writer)?.send(vol, cfg, progress)
}

/// A board that has said hello: what it takes ([`Connection::board`]) is
/// known before a volume is chosen for it.
pub struct Connection<W> {
    listener: Listener,
    writer: W,
    seq0: u16,
    board: BoardInfo,
}

impl<W> std::fmt::Debug for Connection<W> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Connection").field("board", &self.board).finish_non_exhaustive()
    }
}

/// Greet the board behind `reader`/`writer` and learn what it takes.
///
/// # Errors
/// No answer, or another protocol version.
pub fn connect<R, W>(reader: R, mut writer: W) -> Result<Connection<W>>
where
    R: Read + Send + 'static,
    W: Write,
{
    let listener = Listener::start(reader);
    // Every command frame, in order, with consecutive sequence numbers from
    // seq0, which the Hello announces.
    let seq0 = (Instant::now().elapsed().subsec_nanos() as u16) ^ 0x5A5A;
    let board = handshake(&mut writer, &listener, seq0)?;
    Ok(Connection { listener, writer, seq0, board })
}

impl<W: Write> Connection<W> {
    /// What the board said it takes.
    pub fn board(&self) -> &BoardInfo {
        &self.board
    }

    /// Stream `vol` to the board.
    ///
    /// # Errors
    /// A volume the board cannot take, a refused command, or no answer.
    pub fn send(self, vol: &WireVolume, cfg: &SendConfig, progress: Option<&Progress>) -> Result<SendReport> {
        let Connection { listener, mut writer, seq0, board } = self;
        send_on(&listener, &mut writer, seq0, board, vol, cfg, progress)
    }
}

/// The transfer of [`Connection::send`].
fn send_on<W: Write>(
    listener: &Listener,
    writer: &mut W,
    seq0: u16,
    board: BoardInfo,
    vol: &WireVolume,
    cfg: &SendConfig,
    progress: Option<&Progress>,
) -> Result<SendReport> {
    let levels = cfg.check()?;
    if board.sample_types & vol.sample_type.bit() == 0 {
        bail!("the board does not take {:?} samples", vol.sample_type);
    }
    if vol.slice_bytes() as u64 > u64::from(board.max_slice_samples) {
        bail!(
            "a {}x{} slice of {:?} is {} bytes; the board holds {} (--downsample or --crop makes it smaller)",
            vol.dims[0],
            vol.dims[1],
            vol.sample_type,
            vol.slice_bytes(),
            board.max_slice_samples
        );
    }
    let seq = |k: usize| seq0.wrapping_add(k as u16);
    let frames = volume_messages(vol, cfg, levels, seq0).map(|m| frame(&m)).collect::<Result<Vec<_>>>()?;
    let n = frames.len();
    // The window shrinks by half at each damaged frame and grows back by
    // one at each acknowledgement; answers are matched against the largest.
    let window = cfg.window.max(1);
    let mut win = window;
    // Go-backs since the oldest frame in flight last advanced: past
    // MAX_STALLS the line is too noisy (or the board refuses for good).
    let mut stalls = 0u32;
    // Round trip allowance: a window of frames on the line, and time for
    // the board to contour a slice.
    let line_s =
        (frames.iter().take(window).map(Vec::len).sum::<usize>() * 10) as f64 / f64::from(cfg.baud.max(1));
    let timeout = Duration::from_secs_f64(0.5 + 2.0 * line_s);

    let mut report = SendReport {
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
    let mut acked = vec![false; n];
    let mut sent_epoch = vec![0u32; n];
    let mut ever_sent = vec![false; n];
    let (mut base, mut next, mut epoch) = (0usize, 0usize, 0u32);
    // The board answers frames in the order it receives them, so answers
    // come in increasing frame order until a go-back's frames reach it.
    // After a go-back, the answers still due for the frames in flight
    // before it (OutOfOrder, after the loss that caused the go-back) are
    // not new losses: an answer for a frame no later than the last one
    // answered shows the resent frames have arrived (`settled`).
    let (mut last_idx, mut settled) = (None::<usize>, true);
    let mut timeouts_in_row = 0;
    let mut end_sent_at = None;
    let t0 = Instant::now();
    while base < n {
        while next < n && next < base + win {
            writer.write_all(&frames[next]).context("cannot write to the port")?;
            report.wire_bytes += frames[next].len() as u64;
            if ever_sent[next] {
                report.retransmitted += 1;
            }
            ever_sent[next] = true;
            sent_epoch[next] = epoch;
            if next == n - 1 {
                end_sent_at = Some(Instant::now());
            }
            next += 1;
        }
        writer.flush()?;
        match listener.rx.recv_timeout(timeout) {
            Ok(Reply::Msg(OwnedReply::Ack(s))) => {
                timeouts_in_row = 0;
                let rel = usize::from(s.wrapping_sub(seq(base)));
                if rel < window && base + rel < n {
                    acked[base + rel] = true;
                    settled |= last_idx.is_some_and(|l| base + rel <= l);
                    last_idx = Some(base + rel);
                }
                while base < n && acked[base] {
                    base += 1;
                    stalls = 0;
                    win = (win + 1).min(window);
                    if let Some(p) = progress {
                        p.inc();
                    }
                }
            }
            Ok(Reply::Msg(OwnedReply::Nack(s, code))) => {
                timeouts_in_row = 0;
                match report.nacks.iter_mut().find(|(c, _)| *c == code) {
                    Some((_, k)) => *k += 1,
                    None => report.nacks.push((code, 1)),
                }
                let rel = usize::from(s.wrapping_sub(seq(base)));
                let idx = (rel < window && base + rel < n).then_some(base + rel);
                if let Some(i) = idx {
                    settled |= last_idx.is_some_and(|l| i <= l);
                    last_idx = Some(i);
                }
                match code {
                    // It has it already (a retransmission crossed an ack).
                    NackCode::Duplicate => {
                        if let Some(i) = idx {
                            acked[i] = true;
                        }
                        while base < n && acked[base] {
                            base += 1;
                        }
                    }
                    // Lost or damaged on the line (a damaged delimiter joins
                    // two frames into one too long: Oversize), or the board
                    // busy for a moment: go back to the oldest unacknowledged
                    // frame, once per loss, with a smaller window after
                    // damage and a pause after Busy.
                    NackCode::OutOfOrder
                    | NackCode::BadCrc
                    | NackCode::Truncated
                    | NackCode::UnknownMessage
                    | NackCode::Oversize
                    | NackCode::Busy => {
                        let stale = idx.is_some_and(|i| sent_epoch[i] != epoch)
                            || (code == NackCode::OutOfOrder && !settled);
                        if !stale && next > base {
                            epoch += 1;
                            next = base;
                            settled = false;
                            stalls += 1;
                            if stalls > MAX_STALLS {
                                bail!(
                                    "frame {} of {n} was sent {stalls} times without an acknowledgement \
                                     (last answer: {code:?}): the line is too noisy or the board keeps \
                                     refusing; try a lower --baud, a smaller --chunk or --window",
                                    base + 1
                                );
                            }
                            if code == NackCode::Busy {
                                // 10, 20, 40 ... 200 ms.
                                let pause = 10u64 << stalls.min(6);
                                std::thread::sleep(Duration::from_millis(pause.min(200)));
                            } else if code != NackCode::OutOfOrder {
                                win = (win / 2).max(1);
                            }
                        }
                    }
                    NackCode::BadVersion => {
                        bail!("the board does not speak protocol version {PROTOCOL_VERSION}")
                    }
                    NackCode::DimsOverCapacity => bail!(
                        "the board cannot hold a {}x{} slice (its largest: {} bytes)",
                        vol.dims[0],
                        vol.dims[1],
                        board.max_slice_samples
                    ),
                    NackCode::Invalid => {
                        bail!("the board refused command {s} as invalid (levels, planes, view?)")
                    }
                    NackCode::Missing | NackCode::Aborted => {
                        bail!("the board abandoned the transfer ({code:?}); the old picture stays")
                    }
                }
            }
            Ok(Reply::Msg(OwnedReply::Status { state, points, refresh_centi_hz })) => {
                report.status = Some((state, points, refresh_centi_hz));
            }
            Ok(_) => {}
            Err(RecvTimeoutError::Timeout) => {
                report.timeouts += 1;
                timeouts_in_row += 1;
                if timeouts_in_row > cfg.max_timeouts {
                    bail!("the board stopped answering ({} timeouts in a row)", timeouts_in_row);
                }
                epoch += 1;
                next = base;
                // Whatever was in flight is lost or answered by now.
                settled = true;
                win = (win / 2).max(1);
            }
            Err(RecvTimeoutError::Disconnected) => bail!("the port closed"),
        }
    }
    report.seconds = t0.elapsed().as_secs_f64();
    report.end_ack_seconds = end_sent_at.map_or(0.0, |t| t.elapsed().as_secs_f64());
    // The board reports its status once the new picture is drawn.
    report.status = None;
    let deadline = Instant::now() + Duration::from_secs(10);
    while report.status.is_none() {
        let Some(left) = deadline.checked_duration_since(Instant::now()) else { break };
        match listener.rx.recv_timeout(left) {
            Ok(Reply::Msg(OwnedReply::Status { state, points, refresh_centi_hz })) => {
                report.status = Some((state, points, refresh_centi_hz));
                report.picture_seconds = end_sent_at.map(|t| t.elapsed().as_secs_f64());
            }
            Ok(_) => {}
            Err(_) => break,
        }
    }
    Ok(report)
}

/// How long a read of a serial port waits for data before it returns (and
/// the reader looks whether it is to stop).
#[cfg(not(target_arch = "wasm32"))]
const READ_TIMEOUT: Duration = Duration::from_millis(100);

/// How long a write may wait for the port to take a byte before the port
/// is given up on.
#[cfg(not(target_arch = "wasm32"))]
const WRITE_STALL: Duration = Duration::from_secs(10);

/// A port to the board: a serial device or pseudo-terminal path, opened at
/// `baud`, 8N1, no flow control, or `tcp:HOST:PORT`. Returns a reader
/// (with a short read timeout) and a writer.
///
/// # Errors
/// The port cannot be opened or set up.
#[cfg(not(target_arch = "wasm32"))]
pub fn open_port(spec: &str, baud: u32) -> Result<(Box<dyn Read + Send>, Box<dyn Write + Send>)> {
    if let Some(addr) = spec.strip_prefix("tcp:") {
        let s = std::net::TcpStream::connect(addr).with_context(|| format!("cannot connect to {addr}"))?;
        s.set_nodelay(true)?;
        s.set_read_timeout(Some(Duration::from_millis(50)))?;
        let r = s.try_clone()?;
        return Ok((Box::new(r), Box::new(s)));
    }
    let builder = serialport::new(spec, baud)
        .data_bits(serialport::DataBits::Eight)
        .parity(serialport::Parity::None)
        .stop_bits(serialport::StopBits::One)
        .flow_control(serialport::FlowControl::None)
        .timeout(READ_TIMEOUT);
    // Not exclusive (TIOCEXCL): on a pseudo-terminal whose other end the
    // virtual board holds open, it would outlive this sender and lock out
    // the next one.
    #[cfg(unix)]
    let builder = builder.exclusive(false);
    let port = builder.open().map_err(|e| {
        // A file or device that is no terminal (/dev/null) fails its
        // terminal settings with ENOTTY: say so plainly.
        #[cfg(unix)]
        if e.description == nix::errno::Errno::ENOTTY.desc() {
            return anyhow!("cannot open the serial port {spec}: not a serial port or terminal");
        }
        anyhow!("cannot open the serial port {spec}: {e}")
    })?;
    let reader = port.try_clone().map_err(|e| anyhow!("cannot set up {spec}: {e}"))?;
    Ok((Box::new(reader), Box::new(PatientWriter { port })))
}

/// A serial port's writer that waits for a slow line: a write the port's
/// read timeout cut short is tried again, up to [`WRITE_STALL`] without
/// progress.
#[cfg(not(target_arch = "wasm32"))]
struct PatientWriter {
    port: Box<dyn serialport::SerialPort>,
}

#[cfg(not(target_arch = "wasm32"))]
impl Write for PatientWriter {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let t0 = Instant::now();
        loop {
            match self.port.write(buf) {
                Ok(0) if !buf.is_empty() => {}
                Err(e)
                    if matches!(
                        e.kind(),
                        ErrorKind::TimedOut | ErrorKind::WouldBlock | ErrorKind::Interrupted
                    ) => {}
                r => return r,
            }
            if t0.elapsed() > WRITE_STALL {
                return Err(std::io::Error::new(
                    ErrorKind::TimedOut,
                    format!("the port took no byte for {} s", WRITE_STALL.as_secs()),
                ));
            }
        }
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.port.flush()
    }
}
