//! The virtual board: the core's device engine behind a pseudo-terminal or
//! a TCP port, fed at the line rate of a real UART, drawing through the
//! beam scheduler onto the simulated phosphor.

use crate::board::HostBuffers;
use crate::phosphor::{Phosphor, PhosphorConfig};
use crate::scene::write_samples;
use crate::virtual_dac::VirtualDac;
use anyhow::{Context, Result};
use isoscope_core::engine::{Engine, EngineConfig, Event};
use isoscope_core::output::Dac;
use std::io::{ErrorKind, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// Line time the paced port may deliver at once after a pause (a DMA ring
/// buffer's worth; it bounds how far the pacing can run ahead of the line).
const BURST_SECONDS: f64 = 0.005;

/// How the virtual board runs.
#[derive(Debug, Clone, PartialEq)]
pub struct DeviceOptions {
    /// The UART's line rate: bytes are taken no faster than `baud / 10` a
    /// second (8N1), as a real board receives them; 0 takes them at once.
    pub baud: u32,
    /// Rewrite this PNG whenever the picture changes.
    pub snapshot: Option<PathBuf>,
    /// The snapshot's width and height in pixels.
    pub size: u32,
    /// Rewrite this text file with one frame's DAC samples (`x y beam`)
    /// whenever the picture changes.
    pub samples: Option<PathBuf>,
    /// Stop after this many volumes are shown.
    pub exit_after: Option<u32>,
    /// The engine's settings.
    pub engine: EngineConfig,
    /// Largest slice in bytes.
    pub slice_bytes: usize,
    /// Commands per surface and points in the display list.
    pub points: usize,
    /// Drop a client that has sent no whole frame for this long (an idle
    /// or trickling connection would keep every other sender out); `None`
    /// keeps it (a pty has one client for good).
    pub idle_timeout: Option<Duration>,
}

/// How long a client may leave the board's answers unread before it is
/// dropped.
pub const WRITE_TIMEOUT: Duration = Duration::from_secs(2);

impl Default for DeviceOptions {
    fn default() -> Self {
        Self {
            baud: 921_600,
            snapshot: None,
            size: 512,
            samples: None,
            exit_after: None,
            engine: EngineConfig::default(),
            slice_bytes: 512 * 512 * 4,
            points: 1 << 19,
            idle_timeout: None,
        }
    }
}

/// What a run of the virtual board did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DeviceSummary {
    /// Volumes shown.
    pub volumes: u32,
    /// The last picture's latency: from the bytes that completed the volume
    /// to the display list ready, seconds.
    pub last_latency: f64,
}

/// A byte stream that returns `WouldBlock` when nothing is waiting, and
/// `Ok(0)` only when the other end has closed it.
pub trait Port: Read + Write {}
impl<T: Read + Write> Port for T {}

/// Why [`Board::serve`] returned.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Stop {
    /// `exit_after` volumes were shown.
    Done,
    /// The other end closed the port (TCP); the board keeps its picture
    /// for the next connection.
    Closed,
    /// The connection failed (reset, broken), sent nothing whole for
    /// [`DeviceOptions::idle_timeout`], or left the answers unread for
    /// [`WRITE_TIMEOUT`]: why. The board keeps its picture (a transfer left
    /// half done times out) for the next connection.
    Lost(String),
}

/// The virtual board: the engine and its clock, across connections.
#[derive(Debug)]
pub struct Board<'a> {
    engine: Engine<'a>,
    start: Instant,
    summary: DeviceSummary,
    /// The feed that completed the last volume began here.
    committed_at: Option<Instant>,
    last_snapshot: Option<Instant>,
}

impl<'a> Board<'a> {
    /// A board over `mem`.
    ///
    /// # Errors
    /// Invalid engine settings or buffers.
    pub fn new(mem: &'a mut HostBuffers, opts: &DeviceOptions) -> Result<Self> {
        let mut engine = Engine::new(opts.engine, mem.buffers()).context("cannot start the engine")?;
        // As the firmware: the slice memory is lent to the frame's replay
        // while idle, so a volume's first command is answered Busy once.
        engine.replay_frames(true);
        Ok(Self {
            engine,
            start: Instant::now(),
            summary: DeviceSummary::default(),
            committed_at: None,
            last_snapshot: None,
        })
    }

    /// What the board did so far.
    pub fn summary(&self) -> DeviceSummary {
        self.summary
    }

    /// The engine.
    pub fn engine(&self) -> &Engine<'a> {
        &self.engine
    }

    /// Write the engine's queued answers to the port; `Err` says why the
    /// client is lost.
    fn answer(&mut self, port: &mut dyn Port, out: &mut [u8]) -> std::result::Result<(), String> {
        loop {
            let n = self.engine.transmit(out);
            if n == 0 {
                return Ok(());
            }
            let mut rest = &out[..n];
            let since = Instant::now();
            while !rest.is_empty() {
                match port.write(rest) {
                    Ok(0) => return Err("the port closed while writing".into()),
                    Ok(k) => rest = &rest[k..],
                    // A non-blocking port with its buffer full: the host is
                    // slow to read, or does not read at all.
                    Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::Interrupted) => {
                        if since.elapsed() > WRITE_TIMEOUT {
                            return Err(format!("the answers went unread for {} s", WRITE_TIMEOUT.as_secs()));
                        }
                        std::thread::sleep(Duration::from_micros(200));
                    }
                    Err(e) => return Err(format!("writing the port: {e}")),
                }
            }
            let _ = port.flush();
        }
    }

    fn stamp(&self) -> String {
        format!("t={:.3}", self.start.elapsed().as_secs_f64())
    }

    /// Serve `port` until `exit_after` volumes are shown in all or the port
    /// closes. Event lines go to `log`.
    ///
    /// # Errors
    /// The port fails, or a snapshot cannot be written.
    pub fn serve(&mut self, port: &mut dyn Port, opts: &DeviceOptions, log: &mut dyn Write) -> Result<Stop> {
        let start = self.start;
        let ms = |t: Instant| t.duration_since(start).as_millis() as u32;
        let mut buf = vec![0u8; 4096];
        let mut out = vec![0u8; 4096];
        let mut allowance = 0.0f64;
        let mut last = Instant::now();
        // When the client last completed a frame (or connected).
        let (mut frames, mut heard) = (self.engine.counters().frames, Instant::now());
        loop {
            if let Some(idle) = opts.idle_timeout {
                let now_frames = self.engine.counters().frames;
                if now_frames != frames {
                    (frames, heard) = (now_frames, Instant::now());
                } else if heard.elapsed() > idle {
                    // Its transfer, if any, times out in the engine.
                    self.engine.update(ms(Instant::now()));
                    return Ok(Stop::Lost(format!("no whole frame for {:.1} s", idle.as_secs_f64())));
                }
            }
            let now = Instant::now();
            let budget = if opts.baud == 0 {
                buf.len()
            } else {
                // A UART delivers baud/10 bytes a second (8N1), no faster.
                allowance = (allowance
                    + now.duration_since(last).as_secs_f64() * f64::from(opts.baud) / 10.0)
                    .min(f64::from(opts.baud) / 10.0 * BURST_SECONDS);
                allowance as usize
            };
            last = now;
            let mut got = 0;
            if budget > 0 {
                match port.read(&mut buf[..budget]) {
                    Ok(0) => return Ok(Stop::Closed),
                    Ok(n) => got = n,
                    Err(e)
                        if matches!(
                            e.kind(),
                            ErrorKind::WouldBlock | ErrorKind::Interrupted | ErrorKind::TimedOut
                        ) => {}
                    Err(e) => return Ok(Stop::Lost(format!("reading the port: {e}"))),
                }
            }
            if got > 0 {
                allowance -= got as f64;
                let feed_start = Instant::now();
                self.engine.feed(&buf[..got], ms(feed_start));
                if let Err(why) = self.answer(port, &mut out) {
                    return Ok(Stop::Lost(why));
                }
                while let Some(ev) = self.engine.next_event() {
                    if matches!(ev, Event::Committed { .. }) {
                        self.committed_at = Some(feed_start);
                    }
                    writeln!(log, "{} {ev}", self.stamp())?;
                }
                log.flush()?;
            }
            let redrawn = self.engine.update(ms(Instant::now()));
            // A status follows a new picture, an abandoned transfer answers late.
            if let Err(why) = self.answer(port, &mut out) {
                return Ok(Stop::Lost(why));
            }
            if redrawn {
                let mut shown_volume = false;
                while let Some(ev) = self.engine.next_event() {
                    let mut line = format!("{} {ev}", self.stamp());
                    // The redraw of a committed volume (other events, such as
                    // its stitching, come before it in the same update).
                    let redraw = matches!(ev, Event::Redrawn { .. });
                    if let Some(t) = self.committed_at.take_if(|_| redraw) {
                        self.summary.last_latency = t.elapsed().as_secs_f64();
                        line.push_str(&format!(" latency_ms={:.1}", self.summary.last_latency * 1e3));
                        self.summary.volumes += 1;
                        shown_volume = true;
                    }
                    writeln!(log, "{line}")?;
                }
                // A spinning view redraws at every update: snapshot twice a second.
                let due = shown_volume
                    || self.last_snapshot.is_none_or(|t| t.elapsed() > Duration::from_millis(500));
                if let (Some(path), true) = (&opts.samples, shown_volume) {
                    write_samples(play_frame(&self.engine, 1e6).samples(), path)?;
                    writeln!(log, "{} samples {}", self.stamp(), path.display())?;
                }
                if let (Some(path), true) = (&opts.snapshot, due) {
                    snapshot(&self.engine, opts.size, path)?;
                    self.last_snapshot = Some(Instant::now());
                    if shown_volume {
                        writeln!(log, "{} snapshot {}", self.stamp(), path.display())?;
                    }
                }
                log.flush()?;
                if opts.exit_after.is_some_and(|n| self.summary.volumes >= n) {
                    return Ok(Stop::Done);
                }
            }
            if got == 0 {
                std::thread::sleep(Duration::from_micros(500));
            }
        }
    }
}

/// One frame of the board's picture, played into the virtual DAC.
pub fn play_frame(engine: &Engine<'_>, rate_hz: f64) -> VirtualDac {
    let mut dac = VirtualDac::new(rate_hz);
    let Ok(()) = dac.write(engine.frame());
    dac
}

/// Draw one frame of the board's picture from the virtual DAC on a fresh
/// phosphor and write it.
fn snapshot(engine: &Engine<'_>, size: u32, path: &Path) -> Result<()> {
    let beam = *engine.beam();
    let mut cfg = PhosphorConfig::with_size(size, size);
    cfg.bits = beam.bits;
    let mut screen = Phosphor::new(cfg).context("invalid picture settings")?;
    screen.deposit(play_frame(engine, 1e6).samples().iter().copied());
    // Whole or not at all: a viewer watching the file never reads half.
    screen.write_png(path)
}

/// A connection the acceptor took, or turned away.
enum Arrival {
    Client(TcpStream, SocketAddr),
    TurnedAway(SocketAddr),
}

/// Serve TCP clients on `listener` one at a time, for good (or until
/// `exit_after` volumes are shown): a client that leaves badly (reset,
/// broken pipe), idles past [`DeviceOptions::idle_timeout`] or leaves the
/// answers unread is dropped and logged, and the board, its picture kept,
/// takes the next. A client that connects while another is served is told
/// the board is busy (a `Nack` with `Busy` before any `Hello`) and closed.
///
/// # Errors
/// Writing the log, a snapshot or the samples file.
pub fn serve_tcp(
    board: &mut Board<'_>,
    listener: TcpListener,
    opts: &DeviceOptions,
    log: &mut dyn Write,
) -> Result<()> {
    let serving = Arc::new(AtomicBool::new(false));
    let (tx, rx) = mpsc::channel();
    let busy = Arc::clone(&serving);
    std::thread::spawn(move || {
        for conn in listener.incoming() {
            let Ok(mut stream) = conn else { continue };
            let Ok(peer) = stream.peer_addr() else { continue };
            let arrival = if busy.swap(true, Ordering::AcqRel) {
                let mut buf = [0u8; 32];
                let msg =
                    isoscope_core::wire::Message::Nack { seq: 0, code: isoscope_core::wire::NackCode::Busy };
                if let Ok(frame) = isoscope_core::wire::encode(&msg, &mut buf) {
                    let _ = stream.write_all(frame);
                    let _ = stream.flush();
                }
                Arrival::TurnedAway(peer)
            } else {
                Arrival::Client(stream, peer)
            };
            if tx.send(arrival).is_err() {
                return;
            }
        }
    });
    for arrival in rx {
        match arrival {
            Arrival::TurnedAway(peer) => {
                writeln!(log, "{} turned away {peer}: busy with another client", board.stamp())?
            }
            Arrival::Client(mut stream, peer) => {
                let _ = stream.set_nodelay(true);
                stream.set_nonblocking(true).context("setting up a connection")?;
                writeln!(log, "{} connected {peer}", board.stamp())?;
                log.flush()?;
                let stop = board.serve(&mut stream, opts, log)?;
                serving.store(false, Ordering::Release);
                match stop {
                    Stop::Done => return Ok(()),
                    Stop::Closed => writeln!(log, "{} disconnected {peer}", board.stamp())?,
                    Stop::Lost(why) => writeln!(log, "{} dropped {peer}: {why}", board.stamp())?,
                }
            }
        }
        log.flush()?;
    }
    Ok(())
}
