//! A board's capacities: how much memory it lends the engine and how fast
//! it plays samples. One board is named here, the STM32F407 of the
//! firmware; the host simulator runs the same engine with these numbers
//! (`--board f407`) to show exactly what that board shows, or with larger
//! ones for large volumes: more room, never other code.

use super::{EngineConfig, Geometry};

/// The engine's memory as sizes (what [`super::Buffers`] lends as slices).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Capacity {
    /// Bytes of one slice buffer (`nx * ny * sample size` of the largest
    /// slice); there are two.
    pub slice_bytes: usize,
    /// The largest `nx` or `ny` a volume is fitted to for this board
    /// (`isoscope-sim fit`): the engine takes any row its slices hold, but
    /// a slice of more than this many samples a side is more lines than
    /// its surfaces hold or its beam draws in a refresh.
    pub extent: usize,
    /// Points each of the two surfaces holds ([`Geometry::bytes_for`]).
    pub points: usize,
    /// Extra scratch for stitching and ordering, bytes (0 on a board: the
    /// idle slice buffers serve).
    pub scratch_bytes: usize,
}

impl Capacity {
    /// Bytes of memory these capacities take in all.
    pub const fn bytes(&self) -> usize {
        2 * self.slice_bytes + 2 * Geometry::bytes_for(self.points) + self.scratch_bytes
    }
}

/// A board: its name, the engine's capacities on it and its sample clock.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Board {
    /// The name a user gives it (`--board f407`).
    pub name: &'static str,
    /// What the engine holds on it.
    pub capacity: Capacity,
    /// DAC samples per second at full rate.
    pub sample_rate_hz: u32,
}

impl Board {
    /// The STM32F407 (STM32F407G-DISC1) of `firmware/`: slices of 32 KB
    /// (128x128 `u8`, `u16` or `i16`, 90x90 `f32`) in the 64 KB CCM, two
    /// surfaces of 8,192 points (102,400 bytes of SRAM), no extra scratch,
    /// 1 MS/s on the on-chip DAC.
    pub const F407: Board = Board {
        name: "f407",
        capacity: Capacity { slice_bytes: 32 * 1024, extent: 128, points: 8192, scratch_bytes: 0 },
        sample_rate_hz: 1_000_000,
    };

    /// Every board named here.
    pub const ALL: [Board; 1] = [Board::F407];

    /// The board called `name` (case-insensitive).
    pub fn named(name: &str) -> Option<Board> {
        Self::ALL.into_iter().find(|b| b.name.eq_ignore_ascii_case(name))
    }

    /// The engine's settings on this board: the defaults (view, beam,
    /// merge tolerance, timeouts) at its sample rate.
    pub fn engine_config(&self) -> EngineConfig {
        EngineConfig { sample_rate_hz: self.sample_rate_hz, ..EngineConfig::default() }
    }
}
