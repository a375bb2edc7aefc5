//! The protocol messages, shared by host and MCU.

use serde::de::{Error as _, SeqAccess, Visitor};
use serde::ser::SerializeSeq;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// Bit of the `axes` set in [`Message::BeginVolume`]: slice along X.
pub const AXIS_X: u8 = 1 << 0;
/// Bit of the `axes` set: slice along Y.
pub const AXIS_Y: u8 = 1 << 1;
/// Bit of the `axes` set: slice along Z.
pub const AXIS_Z: u8 = 1 << 2;

/// The most contour levels one message carries.
pub const MAX_LEVELS: usize = 8;

/// The type of the samples of a volume (postcard: one varint, the variant
/// index `0..=3`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SampleType {
    /// `u8` samples.
    #[default]
    U8,
    /// `u16` samples, little-endian in [`Message::SliceData`].
    U16,
    /// `i16` samples, little-endian.
    I16,
    /// `f32` samples, little-endian IEEE 754.
    F32,
}

impl SampleType {
    /// All sample types, in wire order.
    pub const ALL: [Self; 4] = [Self::U8, Self::U16, Self::I16, Self::F32];

    /// This type's bit in [`Message::Capabilities`]' `sample_types` set:
    /// `1 << variant index`.
    pub const fn bit(self) -> u8 {
        match self {
            Self::U8 => 1,
            Self::U16 => 2,
            Self::I16 => 4,
            Self::F32 => 8,
        }
    }

    /// Bytes per sample.
    pub const fn size(self) -> usize {
        match self {
            Self::U8 => 1,
            Self::U16 | Self::I16 => 2,
            Self::F32 => 4,
        }
    }
}

/// Why the MCU refused a message (postcard: the variant index as a varint).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum NackCode {
    /// 0: the frame CRC did not match.
    BadCrc,
    /// 1: the frame was too short.
    Truncated,
    /// 2: the frame or the data did not fit.
    Oversize,
    /// 3: the message could not be deserialised.
    UnknownMessage,
    /// 4: the protocol version is not supported.
    BadVersion,
    /// 5: the volume's dimensions exceed the MCU's capacity.
    DimsOverCapacity,
    /// 6: a slice or chunk arrived out of order.
    OutOfOrder,
    /// 7: a slice or chunk arrived twice.
    Duplicate,
    /// 8: `EndVolume` arrived with slices missing.
    Missing,
    /// 9: the transfer was aborted (e.g. a new `BeginVolume`).
    Aborted,
    /// 10: the MCU cannot take the message now.
    Busy,
    /// 11: the message is well formed but its contents are not acceptable
    /// (no or non-finite levels, no planes, spacing not finite and positive,
    /// dims below 2x2, an empty chunk or one running past its slice, a view
    /// or beam setting out of range).
    Invalid,
}

/// What the MCU is doing, reported in [`Message::Status`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DeviceState {
    /// 0: nothing to show.
    #[default]
    Idle,
    /// 1: a volume transfer is in progress.
    Receiving,
    /// 2: drawing a volume.
    Showing,
}

/// Up to [`MAX_LEVELS`] contour levels, without a heap.
///
/// On the wire it is a postcard sequence: a varint count, then each level as
/// a little-endian `f32`. Deserialising more than [`MAX_LEVELS`] levels fails.
#[derive(Debug, Clone, Copy, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Levels {
    values: [f32; MAX_LEVELS],
    len: u8,
}

impl Levels {
    /// No levels.
    pub const fn new() -> Self {
        Self { values: [0.0; MAX_LEVELS], len: 0 }
    }

    /// The given levels, or `None` if there are more than [`MAX_LEVELS`].
    pub fn from_slice(levels: &[f32]) -> Option<Self> {
        let mut out = Self::new();
        for &l in levels {
            out.push(l).ok()?;
        }
        Some(out)
    }

    /// Appends a level; hands it back when full.
    ///
    /// # Errors
    ///
    /// The level, when [`MAX_LEVELS`] are already held.
    pub fn push(&mut self, level: f32) -> Result<(), f32> {
        let slot = self.values.get_mut(usize::from(self.len)).ok_or(level)?;
        *slot = level;
        self.len += 1;
        Ok(())
    }

    /// The levels.
    pub fn as_slice(&self) -> &[f32] {
        self.values.get(..usize::from(self.len)).unwrap_or(&[])
    }

    /// The number of levels.
    pub fn len(&self) -> usize {
        usize::from(self.len)
    }

    /// Whether there are no levels.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
}

impl PartialEq for Levels {
    fn eq(&self, other: &Self) -> bool {
        self.as_slice() == other.as_slice()
    }
}

impl Serialize for Levels {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut seq = serializer.serialize_seq(Some(self.len()))?;
        for level in self.as_slice() {
            seq.serialize_element(level)?;
        }
        seq.end()
    }
}

impl<'de> Deserialize<'de> for Levels {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct LevelsVisitor;
        impl<'de> Visitor<'de> for LevelsVisitor {
            type Value = Levels;
            fn expecting(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
                write!(f, "at most {MAX_LEVELS} f32 levels")
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Levels, A::Error> {
                let mut levels = Levels::new();
                while let Some(level) = seq.next_element::<f32>()? {
                    levels.push(level).map_err(|_| A::Error::invalid_length(MAX_LEVELS + 1, &self))?;
                }
                Ok(levels)
            }
        }
        deserializer.deserialize_seq(LevelsVisitor)
    }
}

/// One protocol message, either direction.
///
/// Postcard encodes the variant index as a varint (the number in each
/// variant's doc), then the fields in order: `u8` as one byte, `u16`/`u32`
/// as LEB128 varints, `f32` as 4 little-endian bytes, arrays element by
/// element with no length, `&[u8]` as a varint length then the bytes.
///
/// Host-to-MCU commands carry a `seq` that the MCU echoes in
/// [`Message::Ack`] or [`Message::Nack`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Message<'a> {
    /// 0, either direction: the sender's protocol and firmware version,
    /// and where the sequence numbers start.
    Hello {
        /// The sender's [`PROTOCOL_VERSION`](super::PROTOCOL_VERSION).
        protocol: u8,
        /// Major, minor, patch.
        firmware: [u8; 3],
        /// Host to MCU: the `seq` its first command will carry, so that the
        /// loss of any command, the first included, shows as a gap. MCU to
        /// host: the `seq` it expects next.
        seq: u16,
    },
    /// 1, MCU to host: what the MCU can take.
    Capabilities {
        /// The MCU's protocol version.
        protocol: u8,
        /// The most samples in one slice (`dims[0] * dims[1]` of the
        /// slicing axis).
        max_slice_samples: u32,
        /// Bit set of [`SampleType::bit`].
        sample_types: u8,
        /// The most points the display draws per refresh.
        display_points: u32,
    },
    /// 2, host to MCU: a volume transfer starts.
    BeginVolume {
        /// Sequence number.
        seq: u16,
        /// Samples along x, y, z.
        dims: [u16; 3],
        /// The type of the samples.
        sample_type: SampleType,
        /// Sample spacing along x, y, z.
        spacing: [f32; 3],
        /// Contour levels.
        levels: Levels,
        /// Bit set of [`AXIS_X`], [`AXIS_Y`], [`AXIS_Z`]: the slicing planes.
        axes: u8,
        /// Contour every `every`-th slice of each plane (slices `0, every,
        /// 2 * every, ...`); 1 (or 0) is every slice.
        every: u8,
    },
    /// 3, host to MCU: a chunk of one z slice.
    SliceData {
        /// Sequence number.
        seq: u16,
        /// The z index of the slice.
        slice: u16,
        /// Byte offset of this chunk within the slice.
        offset: u32,
        /// The sample bytes (little-endian samples), borrowed from the frame.
        #[serde(borrow)]
        data: &'a [u8],
    },
    /// 4, host to MCU: the volume transfer is complete.
    EndVolume {
        /// Sequence number.
        seq: u16,
    },
    /// 5, host to MCU: new contour levels for the current volume.
    SetLevels {
        /// Sequence number.
        seq: u16,
        /// Contour levels.
        levels: Levels,
    },
    /// 6, host to MCU: the view.
    SetView {
        /// Sequence number.
        seq: u16,
        /// Yaw, degrees.
        yaw: f32,
        /// Pitch, degrees.
        pitch: f32,
        /// Roll, degrees.
        roll: f32,
        /// Field of view in degrees; `0` is orthographic.
        fov_deg: f32,
        /// Spin about the vertical axis, degrees per second.
        spin_deg_per_s: f32,
    },
    /// 7, host to MCU: beam timing.
    SetBeam {
        /// Sequence number.
        seq: u16,
        /// DAC codes between points along a lit segment.
        lit_step: u16,
        /// Dwell per lit point, microseconds.
        dwell_us: u16,
        /// Settle time after a blanked move, microseconds.
        settle_us: u16,
    },
    /// 8, MCU to host: the command `seq` was accepted.
    Ack {
        /// The command's sequence number.
        seq: u16,
    },
    /// 9, MCU to host: the command `seq` was refused.
    Nack {
        /// The command's sequence number.
        seq: u16,
        /// Why.
        code: NackCode,
    },
    /// 10, MCU to host: state report.
    Status {
        /// The last sequence number accepted.
        seq: u16,
        /// What the MCU is doing.
        state: DeviceState,
        /// Slices of the current volume received.
        slices: u16,
        /// Points drawn per refresh.
        points: u32,
        /// Display refreshes per second, times 100.
        refresh_centi_hz: u16,
    },
}
