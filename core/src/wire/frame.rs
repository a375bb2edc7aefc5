//! Framing: version byte, postcard, CRC-32, COBS, `0x00` delimiter.

use postcard::ser_flavors::Flavor;

use super::{Message, PROTOCOL_VERSION, WireError};

/// Length of the CRC at the end of a decoded frame.
pub const CRC_LEN: usize = 4;

/// The shortest decoded frame: version byte, one message byte, CRC.
/// Anything shorter is [`WireError::Truncated`].
pub const MIN_FRAME_LEN: usize = 1 + 1 + CRC_LEN;

/// The most bytes [`encode`] writes for a message whose postcard encoding
/// is `message_len` bytes: version, message, CRC, COBS overhead, delimiter.
pub const fn max_frame_len(message_len: usize) -> usize {
    let decoded = 1 + message_len + CRC_LEN;
    decoded + decoded / 254 + 1 + 1
}

const CRC32_POLY: u32 = 0xEDB8_8320;

/// The CRC of each byte value alone, built at compile time (1 KB of
/// flash): a byte costs a look-up, a shift and two XORs instead of eight
/// shift-and-XOR steps. The link moves whole volumes through it at both
/// ends.
#[allow(clippy::indexing_slicing)]
const CRC32_TABLE: [u32; 256] = {
    let mut t = [0u32; 256];
    let mut b = 0;
    while b < 256 {
        let mut crc = b as u32;
        let mut k = 0;
        while k < 8 {
            crc = if crc & 1 == 1 { (crc >> 1) ^ CRC32_POLY } else { crc >> 1 };
            k += 1;
        }
        t[b] = crc;
        b += 1;
    }
    t
};

#[inline(always)]
// A byte indexes the 256 entries: the compiler drops the bounds check.
#[allow(clippy::indexing_slicing)]
fn crc32_update(crc: u32, byte: u8) -> u32 {
    (crc >> 8) ^ CRC32_TABLE[usize::from(crc as u8 ^ byte)]
}

/// CRC-32/ISO-HDLC (zlib, Ethernet) of `data`: reflected polynomial
/// `0xEDB88320`, init and final xor `0xFFFFFFFF`, a table look-up a byte.
pub fn crc32(data: &[u8]) -> u32 {
    !data.iter().fold(!0, |crc, &b| crc32_update(crc, b))
}

/// A postcard flavor that CRCs and COBS-encodes on the fly into a slice.
struct CobsCrc<'b> {
    buf: &'b mut [u8],
    /// Where the current block's code byte goes.
    code_at: usize,
    /// The next free byte.
    pos: usize,
    crc: u32,
}

impl<'b> CobsCrc<'b> {
    fn new(buf: &'b mut [u8]) -> Self {
        Self { buf, code_at: 0, pos: 1, crc: !0 }
    }

    fn put(&mut self, at: usize, byte: u8) -> postcard::Result<()> {
        let slot = self.buf.get_mut(at).ok_or(postcard::Error::SerializeBufferFull)?;
        *slot = byte;
        Ok(())
    }

    fn close_block(&mut self) -> postcard::Result<()> {
        let code = u8::try_from(self.pos - self.code_at).map_err(|_| postcard::Error::SerializeBufferFull)?;
        self.put(self.code_at, code)
    }

    /// COBS-encodes one byte, without touching the CRC.
    fn cobs_push(&mut self, byte: u8) -> postcard::Result<()> {
        if byte == 0 {
            self.close_block()?;
            self.code_at = self.pos;
            self.pos += 1;
        } else {
            self.put(self.pos, byte)?;
            self.pos += 1;
            if self.pos - self.code_at == 0xFF {
                self.close_block()?;
                self.code_at = self.pos;
                self.pos += 1;
            }
        }
        Ok(())
    }

    /// Appends the CRC, closes the last block, writes the delimiter.
    fn finish(mut self) -> postcard::Result<&'b [u8]> {
        for b in (!self.crc).to_le_bytes() {
            self.cobs_push(b)?;
        }
        self.close_block()?;
        self.put(self.pos, 0)?;
        let len = self.pos + 1;
        let buf: &'b [u8] = self.buf;
        buf.get(..len).ok_or(postcard::Error::SerializeBufferFull)
    }
}

impl Flavor for CobsCrc<'_> {
    type Output = Self;

    fn try_push(&mut self, data: u8) -> postcard::Result<()> {
        self.crc = crc32_update(self.crc, data);
        self.cobs_push(data)
    }

    fn finalize(self) -> postcard::Result<Self> {
        Ok(self)
    }
}

fn ser_error(e: postcard::Error) -> WireError {
    match e {
        postcard::Error::SerializeBufferFull => WireError::BufferTooSmall,
        _ => WireError::UnknownMessage,
    }
}

/// Encodes `msg` as one frame, delimiter included, into `buf`; returns the
/// used part. Bytes of `buf` past the frame are left as they were.
///
/// [`max_frame_len`] bounds the length.
///
/// # Errors
///
/// [`WireError::BufferTooSmall`] when the frame does not fit `buf`.
pub fn encode<'b>(msg: &Message<'_>, buf: &'b mut [u8]) -> Result<&'b [u8], WireError> {
    let mut flavor = CobsCrc::new(buf);
    flavor.try_push(PROTOCOL_VERSION).map_err(ser_error)?;
    let flavor = postcard::serialize_with_flavor(msg, flavor).map_err(ser_error)?;
    flavor.finish().map_err(ser_error)
}

/// Decodes COBS in place: `buf` is one frame without its `0x00`
/// delimiter. Returns the decoded length; the decoded bytes are at the
/// start of `buf`.
///
/// # Errors
///
/// [`WireError::BadCobs`] when a block runs past the end of `buf`, or any
/// byte (code or data) is `0`: an encoded frame holds none.
pub fn cobs_decode_in_place(buf: &mut [u8]) -> Result<usize, WireError> {
    let n = buf.len();
    let mut read = 0;
    let mut write = 0;
    while read < n {
        let code = usize::from(*buf.get(read).ok_or(WireError::BadCobs)?);
        if code == 0 {
            return Err(WireError::BadCobs);
        }
        read += 1;
        let end = read + code - 1;
        if end > n {
            return Err(WireError::BadCobs);
        }
        while read < end {
            let b = *buf.get(read).ok_or(WireError::BadCobs)?;
            if b == 0 {
                return Err(WireError::BadCobs);
            }
            *buf.get_mut(write).ok_or(WireError::BadCobs)? = b;
            read += 1;
            write += 1;
        }
        if code < 0xFF && read < n {
            *buf.get_mut(write).ok_or(WireError::BadCobs)? = 0;
            write += 1;
        }
    }
    Ok(write)
}

/// Decodes one frame in place: `frame` is the COBS bytes without the `0x00`
/// delimiter. The message borrows `frame`.
///
/// Checks, in order: COBS ([`WireError::BadCobs`]), length
/// ([`WireError::Truncated`]), CRC ([`WireError::BadCrc`]), version
/// ([`WireError::BadVersion`]), postcard ([`WireError::UnknownMessage`],
/// also for trailing bytes after the message).
///
/// # Errors
///
/// As above.
pub fn decode_frame(frame: &mut [u8]) -> Result<Message<'_>, WireError> {
    let len = cobs_decode_in_place(frame)?;
    let frame: &[u8] = frame;
    let data = frame.get(..len).ok_or(WireError::BadCobs)?;
    if len < MIN_FRAME_LEN {
        return Err(WireError::Truncated);
    }
    let (body, crc) = data.split_at_checked(len - CRC_LEN).ok_or(WireError::Truncated)?;
    let crc: [u8; CRC_LEN] = crc.try_into().map_err(|_| WireError::Truncated)?;
    if crc32(body) != u32::from_le_bytes(crc) {
        return Err(WireError::BadCrc);
    }
    let (&version, payload) = body.split_first().ok_or(WireError::Truncated)?;
    if version != PROTOCOL_VERSION {
        return Err(WireError::BadVersion { got: version });
    }
    match postcard::take_from_bytes::<Message<'_>>(payload) {
        Ok((msg, [])) => Ok(msg),
        _ => Err(WireError::UnknownMessage),
    }
}

/// What [`FrameDecoder::feed`] found.
#[derive(Debug, PartialEq)]
pub enum Feed<'d, 's> {
    /// All input was taken; no frame ended in it.
    Consumed,
    /// A frame ended (its delimiter was taken).
    Frame {
        /// The message, borrowing the decoder, or why the frame was bad.
        result: Result<Message<'d>, WireError>,
        /// The input after the delimiter; feed it next.
        remaining: &'s [u8],
    },
}

/// A fixed-size frame accumulator: `N` bytes hold one COBS-encoded frame
/// (without its delimiter). Longer frames are dropped and reported as
/// [`WireError::Oversize`] at their delimiter.
///
/// Every `0x00` ends a frame, good or bad, and the next byte starts a new
/// one, so the decoder resynchronises after garbage at the first `0x00`.
/// Empty frames (consecutive `0x00`s) are skipped silently, so a sender may
/// send a lone `0x00` to flush a receiver's partial frame.
#[derive(Debug, Clone)]
pub struct FrameDecoder<const N: usize> {
    buf: [u8; N],
    len: usize,
    overflow: bool,
}

impl<const N: usize> Default for FrameDecoder<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> FrameDecoder<N> {
    /// An empty decoder.
    pub const fn new() -> Self {
        Self { buf: [0; N], len: 0, overflow: false }
    }

    /// Drops any partial frame.
    pub fn reset(&mut self) {
        self.len = 0;
        self.overflow = false;
    }

    /// Bytes of a partial frame held (0 when between frames).
    pub fn buffered(&self) -> usize {
        self.len
    }

    /// Takes one byte; true when it ends a non-empty frame.
    fn accept(&mut self, byte: u8) -> bool {
        if byte == 0 {
            return self.len > 0 || self.overflow;
        }
        match self.buf.get_mut(self.len) {
            Some(slot) => {
                *slot = byte;
                self.len += 1;
            }
            None => self.overflow = true,
        }
        false
    }

    /// Decodes the held frame and starts afresh.
    fn take(&mut self) -> Result<Message<'_>, WireError> {
        let len = core::mem::replace(&mut self.len, 0);
        if core::mem::replace(&mut self.overflow, false) {
            return Err(WireError::Oversize);
        }
        let frame = self.buf.get_mut(..len).ok_or(WireError::Oversize)?;
        decode_frame(frame)
    }

    /// Takes one byte. Returns `Some` when the byte is a delimiter ending a
    /// non-empty frame: the message (borrowing the decoder until the next
    /// call) or the frame's error.
    pub fn push(&mut self, byte: u8) -> Option<Result<Message<'_>, WireError>> {
        if self.accept(byte) { Some(self.take()) } else { None }
    }

    /// Takes bytes up to and including the first delimiter that ends a
    /// non-empty frame, and returns its result with the rest of `input`.
    pub fn feed<'s>(&mut self, input: &'s [u8]) -> Feed<'_, 's> {
        let mut rest = input;
        while let Some((&b, tail)) = rest.split_first() {
            rest = tail;
            if self.accept(b) {
                return Feed::Frame { result: self.take(), remaining: rest };
            }
        }
        Feed::Consumed
    }
}
