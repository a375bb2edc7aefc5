//! The host <-> MCU wire protocol: one [`Message`] type for both
//! directions, postcard-serialised, framed with a version byte, a CRC-32
//! and COBS.
//!
//! ```text
//! frame = COBS( version:u8 | postcard(Message) | crc32:u32 LE ) 0x00
//! ```
//!
//! The CRC is CRC-32/ISO-HDLC (the zlib / Ethernet CRC: reflected
//! polynomial `0xEDB88320`, init and final xor `0xFFFFFFFF`) over the version
//! byte and the postcard bytes. `docs/wire-format.md` is the normative
//! description, with a worked example.
//!
//! - [`encode`] writes a frame into the caller's buffer and returns the used
//!   part.
//! - [`FrameDecoder`] is a fixed-size accumulator: feed it bytes, one at a
//!   time ([`FrameDecoder::push`]) or a slice at a time
//!   ([`FrameDecoder::feed`]); it yields one decoded [`Message`] (borrowing
//!   its buffer) or one [`WireError`] per `0x00` delimiter, and starts afresh
//!   after every delimiter, so it resynchronises after garbage.
//!
//! No input makes the decoder panic, and it uses `N` bytes of memory, no
//! more.
//!
//! ```
//! use isoscope_core::wire::{encode, Feed, FrameDecoder, Message};
//!
//! let mut out = [0xAAu8; 64];
//! let frame = encode(&Message::Ack { seq: 7 }, &mut out).unwrap();
//! assert_eq!(frame, [0x08, 0x02, 0x08, 0x07, 0xD7, 0x12, 0x78, 0xAA, 0x00]);
//!
//! // The message borrows the decoder's buffer: use it before the next byte.
//! let mut decoder = FrameDecoder::<64>::new();
//! let Feed::Frame { result, remaining } = decoder.feed(frame) else { panic!() };
//! assert_eq!(result, Ok(Message::Ack { seq: 7 }));
//! assert!(remaining.is_empty());
//! ```

mod frame;
mod message;

pub use frame::{
    CRC_LEN, Feed, FrameDecoder, MIN_FRAME_LEN, cobs_decode_in_place, crc32, decode_frame, encode,
    max_frame_len,
};
pub use message::{AXIS_X, AXIS_Y, AXIS_Z, DeviceState, Levels, MAX_LEVELS, Message, NackCode, SampleType};

/// The most data bytes a sender puts in one [`Message::SliceData`] chunk.
/// Every receiver takes chunks this large.
pub const MAX_CHUNK: usize = 1024;

/// The longest frame a receiver must take, delimiter included: a
/// [`Message::SliceData`] of [`MAX_CHUNK`] bytes with the largest varints
/// (variant 1, seq 3, slice 3, offset 5, length 2 bytes).
pub const MAX_FRAME_LEN: usize = max_frame_len(1 + 3 + 3 + 5 + 2 + MAX_CHUNK);

/// A decoder that takes every frame of the protocol ([`MAX_FRAME_LEN`]
/// without the delimiter).
pub type ProtocolDecoder = FrameDecoder<{ MAX_FRAME_LEN - 1 }>;

/// The protocol version, the first byte of every frame (before COBS).
pub const PROTOCOL_VERSION: u8 = 2;

/// Why a frame could not be encoded or decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum WireError {
    /// The CRC-32 at the end of the frame does not match its contents.
    BadCrc,
    /// The decoded frame is shorter than [`MIN_FRAME_LEN`] bytes
    /// (version, one message byte, CRC).
    Truncated,
    /// The frame did not fit the decoder's buffer; its bytes up to the next
    /// `0x00` were dropped.
    Oversize,
    /// A COBS block runs past the end of the frame (typically a frame that
    /// lost bytes, cut inside a block).
    BadCobs,
    /// The CRC matched but postcard could not deserialise a [`Message`]
    /// (unknown variant, bad varint, too many levels, trailing bytes), or
    /// postcard failed to serialise for a reason other than space.
    UnknownMessage,
    /// The CRC matched but the version byte is not [`PROTOCOL_VERSION`].
    BadVersion {
        /// The version byte received.
        got: u8,
    },
    /// The output buffer given to [`encode`] is too small for the frame.
    BufferTooSmall,
}

impl core::fmt::Display for WireError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::BadCrc => f.write_str("frame CRC mismatch"),
            Self::Truncated => f.write_str("frame too short"),
            Self::Oversize => f.write_str("frame larger than the decoder buffer"),
            Self::BadCobs => f.write_str("malformed COBS encoding"),
            Self::UnknownMessage => f.write_str("message could not be (de)serialised"),
            Self::BadVersion { got } => write!(f, "protocol version {got}, expected {PROTOCOL_VERSION}"),
            Self::BufferTooSmall => f.write_str("output buffer too small for the frame"),
        }
    }
}

impl core::error::Error for WireError {}
