//! What the engine did, for a log, and its counts.

use crate::wire::{NackCode, SampleType, WireError};

/// Why a transfer ended without a new picture (the old one stays).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum AbortReason {
    /// A new `BeginVolume` came.
    Superseded,
    /// The host said `Hello` again (it restarted).
    Restarted,
    /// `EndVolume` came with slices missing.
    Missing,
    /// Nothing came for [`EngineConfig::transfer_timeout_ms`](super::EngineConfig::transfer_timeout_ms).
    Timeout,
}

impl core::fmt::Display for AbortReason {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            Self::Superseded => "superseded by a new volume",
            Self::Restarted => "host restarted",
            Self::Missing => "slices missing at the end",
            Self::Timeout => "timed out",
        })
    }
}

/// Something the engine did, for a log (one line each).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Event {
    /// The host said hello.
    Hello {
        /// Its protocol version.
        protocol: u8,
    },
    /// A volume transfer began.
    Begun {
        /// Samples along x, y, z.
        dims: [u16; 3],
        /// Sample type.
        sample_type: SampleType,
        /// Number of levels.
        levels: u8,
    },
    /// A volume is complete and replaces the picture.
    Committed {
        /// Samples along x, y, z.
        dims: [u16; 3],
        /// Contour commands kept.
        commands: u32,
        /// Contour commands that did not fit.
        dropped: u32,
        /// Subgrids skipped for NaN or infinite samples.
        nonfinite_cells: u32,
        /// The slice stride the volume asked for.
        asked: u8,
        /// The stride kept: coarser than asked when the surface did not fit
        /// the memory (every other slice of each plane went, each time).
        every: u16,
    },
    /// A completed volume's pieces were stitched and ordered into the
    /// picture.
    Stitched {
        /// Contour fragments in (one a subgrid and level).
        fragments: u32,
        /// Points of the picture.
        points: u32,
        /// Points the picture had no room for (it is cut short).
        cut: u32,
        /// False when there was too little scratch to stitch and order:
        /// the pieces are drawn as they came, with more blanked travel.
        ordered: bool,
        /// The slice stride drawn: coarser than when committed when the
        /// stitched picture did not fit.
        every: u16,
    },
    /// A transfer ended without a picture; the old one stays.
    Aborted {
        /// Why.
        reason: AbortReason,
        /// Slices it had received.
        slices: u16,
    },
    /// A command was refused.
    Nacked {
        /// Its sequence number.
        seq: u16,
        /// Why.
        code: NackCode,
    },
    /// A frame could not be decoded.
    FrameError {
        /// Why.
        error: WireError,
    },
    /// New levels (for the next volume).
    LevelsSet,
    /// A new view.
    ViewSet,
    /// New beam settings.
    BeamSet,
    /// The picture changed (a new volume, view or beam).
    Redrawn {
        /// Polylines drawn (closed loops and dots included).
        polylines: u32,
        /// Points drawn.
        points: u32,
        /// Blanked travel as a share of lit length, per mille, in this view.
        blank_permille: u16,
        /// Refreshes per second at [`EngineConfig::sample_rate_hz`](super::EngineConfig::sample_rate_hz), times
        /// 100.
        refresh_centi_hz: u16,
    },
}

impl core::fmt::Display for Event {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            Self::Hello { protocol } => write!(f, "hello protocol={protocol}"),
            Self::Begun { dims: [x, y, z], sample_type, levels } => {
                write!(f, "begun dims={x}x{y}x{z} type={sample_type:?} levels={levels}")
            }
            Self::Committed { dims: [x, y, z], commands, dropped, nonfinite_cells, asked, every } => write!(
                f,
                "committed dims={x}x{y}x{z} commands={commands} dropped={dropped} nonfinite_cells={nonfinite_cells} every={every} (asked {asked})"
            ),
            Self::Stitched { fragments, points, cut, ordered, every } => write!(
                f,
                "stitched fragments={fragments} points={points} cut={cut} ordered={ordered} every={every}"
            ),
            Self::Aborted { reason, slices } => write!(f, "aborted slices={slices} reason={reason}"),
            Self::Nacked { seq, code } => write!(f, "nack seq={seq} code={code:?}"),
            Self::FrameError { error } => write!(f, "bad frame: {error}"),
            Self::LevelsSet => f.write_str("levels set (for the next volume)"),
            Self::ViewSet => f.write_str("view set"),
            Self::BeamSet => f.write_str("beam set"),
            Self::Redrawn { polylines, points, blank_permille, refresh_centi_hz } => write!(
                f,
                // Blanked travel over lit length (docs/scenes.md's measure): a
                // ratio, past 100% when the jumps outrun the lines (a few
                // dots far apart), so not written as a share.
                "redrawn polylines={polylines} points={points} blank/lit={}.{}% refresh_hz={}.{:02}",
                blank_permille / 10,
                blank_permille % 10,
                refresh_centi_hz / 100,
                refresh_centi_hz % 100
            ),
        }
    }
}

/// Counts since start.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Counters {
    /// Frames decoded into messages.
    pub frames: u32,
    /// Frames that failed to decode.
    pub frame_errors: u32,
    /// Commands refused (`Nack` sent).
    pub nacks: u32,
    /// Answers re-sent for retransmitted commands.
    pub replays: u32,
    /// Volumes committed.
    pub volumes: u32,
    /// Transfers aborted.
    pub aborts: u32,
    /// Answer frames dropped because the transmit queue was full.
    pub tx_dropped: u32,
    /// Events dropped because the event queue was full.
    pub events_dropped: u32,
}
