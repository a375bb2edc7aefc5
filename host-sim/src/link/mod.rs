//! The host side of the UART link: stream a volume to the board with a
//! send window, go-back-N retransmission, and a report of throughput and
//! payload efficiency.
//!
//! One implementation of the protocol: [`Sender`], a state machine with no
//! I/O, threads or clock of its own (it is given the bytes the board sent
//! and the time, and asked for the bytes to write and its next deadline).
//! [`send_volume`] and [`connect`] drive it over blocking `Read`/`Write`
//! ports ([`open_port`]: a tty, a pseudo-terminal, or a TCP socket such as
//! QEMU's serial chardev); the web page drives the very same [`Sender`]
//! over Web Serial.

#[cfg(not(target_arch = "wasm32"))]
mod driver;
#[cfg(not(target_arch = "wasm32"))]
mod port;
mod report;
mod sender;
mod volume;

#[cfg(not(target_arch = "wasm32"))]
pub use driver::{Connection, connect, send_volume};
#[cfg(not(target_arch = "wasm32"))]
pub use port::open_port;
pub use report::{BoardInfo, SendReport};
pub use sender::{HELLO_TRIES, HELLO_WAIT, PICTURE_WAIT, SendError, SendProgress, Sender, State};
pub use volume::{WireVolume, volume_messages};

use anyhow::{Context, Result, anyhow, bail};
use isoscope_core::wire::{Levels, MAX_CHUNK};

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

/// Timeouts in a row before the board is given up on, unless asked
/// otherwise (`send --patience`).
pub const MAX_TIMEOUTS: u32 = 8;

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
            max_timeouts: MAX_TIMEOUTS,
        }
    }
}

/// Go-backs without progress after which `send_volume` gives up.
pub const MAX_STALLS: u32 = 64;
