//! The virtual board's pseudo-terminal (Unix only): a pty pair in raw
//! mode. Real serial ports are opened with the `serialport` crate
//! ([`crate::link::open_port`]).

use anyhow::{Context, Result, bail};
use nix::sys::termios::{self, BaudRate, SetArg, SpecialCharacterIndices};
use std::fs::File;
use std::os::fd::{AsFd, OwnedFd};
use std::path::PathBuf;

/// The termios speed for `baud`.
fn speed(baud: u32) -> Result<BaudRate> {
    Ok(match baud {
        9600 => BaudRate::B9600,
        19200 => BaudRate::B19200,
        38400 => BaudRate::B38400,
        57600 => BaudRate::B57600,
        115_200 => BaudRate::B115200,
        230_400 => BaudRate::B230400,
        460_800 => BaudRate::B460800,
        500_000 => BaudRate::B500000,
        921_600 => BaudRate::B921600,
        1_000_000 => BaudRate::B1000000,
        1_500_000 => BaudRate::B1500000,
        2_000_000 => BaudRate::B2000000,
        3_000_000 => BaudRate::B3000000,
        4_000_000 => BaudRate::B4000000,
        _ => bail!(
            "unsupported baud rate {baud} (9600, 19200, 38400, 57600, 115200, 230400, 460800, 500000, 921600, 1000000, 1500000, 2000000, 3000000, 4000000)"
        ),
    })
}

/// Raw 8N1 at `baud`, reads returning after at most 0.1 s without data.
///
/// # Errors
/// Not a terminal, or an unsupported baud rate.
pub fn make_raw(fd: &impl AsFd, baud: u32) -> Result<()> {
    let mut t = termios::tcgetattr(fd).context("not a serial port or terminal")?;
    termios::cfmakeraw(&mut t);
    termios::cfsetspeed(&mut t, speed(baud)?).context("cannot set the baud rate")?;
    t.control_chars[SpecialCharacterIndices::VMIN as usize] = 0;
    t.control_chars[SpecialCharacterIndices::VTIME as usize] = 1;
    termios::tcsetattr(fd, SetArg::TCSANOW, &t).context("cannot set raw mode")?;
    Ok(())
}

/// A pseudo-terminal pair: the board's end (`master`), and the path a
/// sender opens (the slave, kept open here so the pty outlives senders).
#[derive(Debug)]
pub struct Pty {
    /// The board's end.
    pub master: File,
    /// The sender's end, held open.
    pub slave: OwnedFd,
    /// The path of the sender's end.
    pub path: PathBuf,
}

/// Open a pseudo-terminal in raw mode; the master does not block.
///
/// # Errors
/// No pseudo-terminals available.
pub fn open_pty() -> Result<Pty> {
    let pair = nix::pty::openpty(None, None).context("cannot open a pseudo-terminal")?;
    let path = nix::unistd::ttyname(&pair.slave).context("the pseudo-terminal has no name")?;
    make_raw(&pair.slave, 921_600)?;
    let master = File::from(pair.master);
    let flags = nix::fcntl::OFlag::from_bits_truncate(nix::fcntl::fcntl(&master, nix::fcntl::F_GETFL)?);
    nix::fcntl::fcntl(&master, nix::fcntl::F_SETFL(flags | nix::fcntl::OFlag::O_NONBLOCK))?;
    Ok(Pty { master, slave: pair.slave, path })
}
