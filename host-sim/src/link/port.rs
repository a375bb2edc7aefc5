//! The machine's ports to a board: a serial device, a pseudo-terminal or
//! a TCP socket.

use anyhow::{Context, Result, anyhow};
use std::io::{ErrorKind, Read, Write};
use std::time::{Duration, Instant};

/// How long a read of a serial port waits for data before it returns (and
/// the reader looks whether it is to stop).
const READ_TIMEOUT: Duration = Duration::from_millis(100);

/// How long a write may wait for the port to take a byte before the port
/// is given up on.
const WRITE_STALL: Duration = Duration::from_secs(10);

/// A port to the board: a serial device or pseudo-terminal path, opened at
/// `baud`, 8N1, no flow control, or `tcp:HOST:PORT`. Returns a reader
/// (with a short read timeout) and a writer.
///
/// # Errors
/// The port cannot be opened or set up.
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
struct PatientWriter {
    port: Box<dyn serialport::SerialPort>,
}

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
