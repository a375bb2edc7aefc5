//! The blocking driver of the [`Sender`]: a board behind a `Read` (read on
//! a thread of its own, as a serial port's reads block) and a `Write`, the
//! time from [`Instant`]. Nothing of the protocol is here: this loop only
//! moves bytes and time between the port and the sender.

use super::{BoardInfo, SendConfig, SendReport, Sender, State, WireVolume};
use crate::progress::Progress;
use anyhow::{Context, Result};
use std::io::{ErrorKind, Read, Write};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

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
    line: Line<W>,
    sender: Sender,
    board: BoardInfo,
}

impl<W> std::fmt::Debug for Connection<W> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Connection").field("sender", &self.sender).finish_non_exhaustive()
    }
}

/// Greet the board behind `reader`/`writer` and learn what it takes.
///
/// # Errors
/// No answer, or another protocol version.
pub fn connect<R, W>(reader: R, writer: W) -> Result<Connection<W>>
where
    R: Read + Send + 'static,
    W: Write,
{
    let mut line = Line::start(reader, writer);
    let (sender, board) = greet(&mut line)?;
    Ok(Connection { line, sender, board })
}

/// A new sender's hello, answered: every command frame after it, in
/// order, has consecutive sequence numbers from the `seq0` it announces.
fn greet<W: Write>(line: &mut Line<W>) -> Result<(Sender, BoardInfo)> {
    let seq0 = (Instant::now().elapsed().subsec_nanos() as u16) ^ 0x5A5A;
    let mut sender = Sender::new(seq0, line.now());
    line.run(&mut sender, None)?;
    let board = *sender.board().context("the board said no capabilities")?;
    Ok((sender, board))
}

impl<W: Write> Connection<W> {
    /// What the board said it takes.
    pub fn board(&self) -> &BoardInfo {
        &self.board
    }

    /// Say hello again, answered, while the host works on something before
    /// it sends (fitting the volume to the board): a board may drop a
    /// client silent for long (`isoscope-sim device --tcp`'s
    /// `--idle-timeout`). What the board takes is read again.
    ///
    /// # Errors
    /// No answer, or another protocol version.
    pub fn greet(&mut self) -> Result<()> {
        (self.sender, self.board) = greet(&mut self.line)?;
        Ok(())
    }

    /// Stream `vol` to the board.
    ///
    /// # Errors
    /// A volume the board cannot take, a refused command, or no answer.
    pub fn send(self, vol: &WireVolume, cfg: &SendConfig, progress: Option<&Progress>) -> Result<SendReport> {
        let Connection { mut line, mut sender, .. } = self;
        cfg.check()?;
        sender.start(vol, cfg, line.now())?;
        match line.run(&mut sender, progress)? {
            State::Done(report) => Ok(report),
            other => anyhow::bail!("the transfer stopped at {other:?}"),
        }
    }
}

/// The port: its writer, and its reader on a thread.
struct Line<W> {
    rx: Receiver<Vec<u8>>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
    writer: W,
    t0: Instant,
}

impl<W: Write> Line<W> {
    fn start<R: Read + Send + 'static>(mut reader: R, writer: W) -> Self {
        let (tx, rx) = mpsc::channel();
        let stop = Arc::new(AtomicBool::new(false));
        let halt = stop.clone();
        let thread = std::thread::spawn(move || {
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
                if tx.send(buf[..n].to_vec()).is_err() {
                    return;
                }
            }
        });
        Self { rx, stop, thread: Some(thread), writer, t0: Instant::now() }
    }

    /// The sender's time.
    fn now(&self) -> Duration {
        self.t0.elapsed()
    }

    /// Drive `sender` until it waits for nothing (connected, or done), its
    /// frames acknowledged told to `progress`.
    fn run(&mut self, sender: &mut Sender, progress: Option<&Progress>) -> Result<State> {
        let mut told = 0;
        loop {
            if let Some(p) = progress {
                let acked = sender.progress().frames_acked;
                p.add(acked.saturating_sub(told));
                told = told.max(acked);
            }
            let Some(deadline) = sender.deadline() else {
                return match sender.state() {
                    State::Failed(e) => Err(e.into()),
                    s => Ok(s),
                };
            };
            let mut wrote = false;
            while let Some(bytes) = sender.transmit(self.now()) {
                self.writer.write_all(&bytes).context("cannot write to the port")?;
                wrote = true;
            }
            if wrote {
                self.writer.flush().context("cannot write to the port")?;
            }
            // The deadline again: writing may have moved it.
            let deadline = sender.deadline().unwrap_or(deadline);
            match self.rx.recv_timeout(deadline.saturating_sub(self.now())) {
                Ok(bytes) => sender.receive(&bytes, self.now())?,
                Err(RecvTimeoutError::Timeout) => sender.on_time(self.now())?,
                Err(RecvTimeoutError::Disconnected) => sender.closed(self.now())?,
            }
        }
    }
}

impl<W> Drop for Line<W> {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}
