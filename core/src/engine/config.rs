//! What an engine is set up with, and why one could not be made.

use crate::beam::{BeamConfig, BeamConfigError};
use crate::view::{View, ViewError};
use crate::wire::SampleType;

/// What the engine is set up with.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct EngineConfig {
    /// Firmware version reported in `Hello` (major, minor, patch).
    pub firmware: [u8; 3],
    /// Sample types taken: a set of [`SampleType::bit`].
    pub sample_types: u8,
    /// DAC samples per second (for beam times in microseconds and the
    /// refresh rate reported).
    pub sample_rate_hz: u32,
    /// The view until the host sets one (its `spacing` is replaced by each
    /// volume's, its `bits` by the beam's).
    pub view: View,
    /// The beam until the host sets it.
    pub beam: BeamConfig,
    /// Merging collinear runs: the largest distance, in DAC units (at the
    /// largest scale any view gives the picture), of a dropped vertex from
    /// the chord that replaces it; 0 merges nothing. Default: half an LSB.
    pub merge_tolerance: f32,
    /// A transfer with no accepted message for this long is abandoned (ms).
    pub transfer_timeout_ms: u32,
    /// Contour a completed slice later, a few rows at a time
    /// ([`Link::contour`](super::Link::contour)), instead of inside [`Link::feed`](super::Link::feed): for a device
    /// that must keep its display refreshed (the firmware), where a slice
    /// of 128 x 128 takes tens of milliseconds. [`Link::feed`](super::Link::feed) then stops
    /// taking bytes while that work is pending.
    pub defer_contouring: bool,
}

impl Default for EngineConfig {
    /// Every sample type, 1 MS/s, the default view, beam and tolerance, and
    /// a 5 s transfer timeout; slices contoured as they complete.
    fn default() -> Self {
        Self {
            firmware: [0, 1, 0],
            sample_types: SampleType::ALL.iter().fold(0, |m, t| m | t.bit()),
            sample_rate_hz: 1_000_000,
            view: View::DEFAULT,
            beam: BeamConfig::default(),
            merge_tolerance: 0.5,
            transfer_timeout_ms: 5_000,
            defer_contouring: false,
        }
    }
}

/// Why an [`Engine`](super::Engine) could not be made.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EngineError {
    /// The beam configuration is invalid.
    Beam(BeamConfigError),
    /// The view is invalid.
    View(ViewError),
    /// The slice or row buffers are too small for a 2x2 slice of `f32`.
    Buffers,
}

impl core::fmt::Display for EngineError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Beam(e) => write!(f, "invalid beam settings: {e}"),
            Self::View(e) => write!(f, "invalid view: {e}"),
            Self::Buffers => f.write_str("engine buffers too small (slices)"),
        }
    }
}

impl core::error::Error for EngineError {}
