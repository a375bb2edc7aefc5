//! Checks shared by the fuzz targets in `fuzz_targets/`.
//!
//! Everything here panics (so libFuzzer reports a crash) when an invariant
//! of `isoscope_core::wire` does not hold; see `docs/wire-format.md`.

use isoscope_core::wire::{
    CRC_LEN, MIN_FRAME_LEN, Message, PROTOCOL_VERSION, WireError, cobs_decode_in_place, decode_frame, encode,
    max_frame_len,
};

/// A decoded frame's outcome, owned: the message as its canonical frame
/// (from [`check_message`]), or the error. Frames compare bit for bit, so
/// NaN fields compare equal to themselves.
pub type Outcome = Result<Vec<u8>, WireError>;

/// Encodes `msg` and checks everything `encode` promises, then decodes the
/// frame and checks that it gives the same message back. Returns the frame
/// (delimiter included).
///
/// `postcard_bound` is an upper bound on the postcard length of `msg` (for a
/// message decoded from a frame, the decoded length minus version and CRC).
pub fn check_message(msg: &Message<'_>, postcard_bound: usize) -> Vec<u8> {
    const JUNK: u8 = 0xAA;
    let cap = max_frame_len(postcard_bound);
    let mut buf = vec![JUNK; cap + 16];
    let frame = match encode(msg, &mut buf) {
        Ok(f) => f.to_vec(),
        Err(e) => panic!("encode failed with {e:?} into {cap}+16 bytes for {msg:?}"),
    };
    assert!(frame.len() <= cap, "frame of {} bytes > max_frame_len({postcard_bound}) = {cap}", frame.len());
    // Bytes past the frame are left as they were.
    assert!(buf[frame.len()..].iter().all(|&b| b == JUNK), "encode wrote past its frame");
    // One delimiter, at the end.
    let (&last, body) = frame.split_last().expect("empty frame");
    assert_eq!(last, 0, "frame does not end with 0x00");
    assert!(!body.contains(&0), "0x00 inside a frame: {frame:02x?}");

    // The exact length fits; one byte less is BufferTooSmall.
    let mut exact = vec![JUNK; frame.len()];
    assert_eq!(encode(msg, &mut exact).map(<[u8]>::to_vec), Ok(frame.clone()), "exact-size buffer");
    let mut short = vec![JUNK; frame.len() - 1];
    assert_eq!(encode(msg, &mut short), Err(WireError::BufferTooSmall), "one byte short");

    // The decoded frame: version, postcard, CRC; max_frame_len bounds it.
    let mut decoded = body.to_vec();
    let dlen = cobs_decode_in_place(&mut decoded).expect("encode wrote bad COBS");
    assert!(dlen >= MIN_FRAME_LEN);
    assert_eq!(decoded[0], PROTOCOL_VERSION);
    assert!(frame.len() <= max_frame_len(dlen - 1 - CRC_LEN), "max_frame_len does not bound the frame");
    assert_eq!(reference_crc32(&decoded[..dlen - CRC_LEN]).to_le_bytes(), decoded[dlen - CRC_LEN..dlen]);

    // Decoding gives the message back.
    let mut copy = body.to_vec();
    let back = match decode_frame(&mut copy) {
        Ok(m) => m,
        Err(e) => panic!("own frame of {msg:?} does not decode: {e:?} ({frame:02x?})"),
    };
    // Same bits (re-encoding is deterministic)...
    let mut again = vec![JUNK; frame.len()];
    assert_eq!(encode(&back, &mut again).ok(), Some(&frame[..]), "{msg:?} came back as {back:?}");
    // ...and equal unless a float is NaN (then `msg != msg`).
    #[allow(clippy::eq_op)]
    let reflexive = msg == msg;
    assert!(!reflexive || back == *msg, "{msg:?} came back as {back:?}");
    frame
}

/// The outcome of a decode, checked with [`check_message`] when it is a
/// message. `frame_len` is the COBS length the message was decoded from.
pub fn outcome(result: Result<Message<'_>, WireError>, frame_len: usize) -> Outcome {
    result.map(|m| check_message(&m, frame_len.saturating_sub(1 + CRC_LEN)))
}

/// What a [`FrameDecoder<N>`](isoscope_core::wire::FrameDecoder) must
/// report for `input`, from the specification: split at every `0x00`; each
/// non-empty piece before a delimiter is `Oversize` if longer than `n`, else
/// `decode_frame` of it. Also returns the length of the trailing piece (the
/// partial frame after the last delimiter).
pub fn expected_frames(input: &[u8], n: usize) -> (Vec<Outcome>, usize) {
    let mut pieces: Vec<&[u8]> = input.split(|&b| b == 0).collect();
    let tail = pieces.pop().map_or(0, <[u8]>::len);
    let out = pieces
        .into_iter()
        .filter(|p| !p.is_empty())
        .map(|p| {
            if p.len() > n {
                Err(WireError::Oversize)
            } else {
                let mut frame = p.to_vec();
                outcome(decode_frame(&mut frame), p.len())
            }
        })
        .collect();
    (out, tail)
}

/// CRC-32/ISO-HDLC, table-driven (the core's is bitwise): an independent
/// implementation to check it against.
pub fn reference_crc32(data: &[u8]) -> u32 {
    static TABLE: std::sync::OnceLock<[u32; 256]> = std::sync::OnceLock::new();
    let table = TABLE.get_or_init(|| {
        let mut t = [0u32; 256];
        for (i, e) in t.iter_mut().enumerate() {
            let mut c = i as u32;
            for _ in 0..8 {
                c = if c & 1 != 0 { 0xEDB8_8320 ^ (c >> 1) } else { c >> 1 };
            }
            *e = c;
        }
        t
    });
    !data.iter().fold(!0u32, |c, &b| table[((c ^ u32::from(b)) & 0xFF) as usize] ^ (c >> 8))
}

/// Textbook COBS decoding of a frame without its delimiter, into a new
/// vector: `None` for a code byte `0` or a block running past the end.
pub fn reference_cobs_decode(frame: &[u8]) -> Option<Vec<u8>> {
    let mut out = Vec::with_capacity(frame.len());
    let mut i = 0;
    while i < frame.len() {
        let code = usize::from(frame[i]);
        if code == 0 {
            return None;
        }
        let block = frame.get(i + 1..i + code)?;
        if block.contains(&0) {
            return None;
        }
        out.extend_from_slice(block);
        i += code;
        if code < 0xFF && i < frame.len() {
            out.push(0);
        }
    }
    Some(out)
}

/// The checks `decode_frame` makes before postcard, in the documented
/// order: `Err` with the error it must return, or `Ok` when only postcard
/// is left (then it returns a message or `UnknownMessage`).
pub fn reference_precheck(frame: &[u8]) -> Result<(), WireError> {
    let decoded = reference_cobs_decode(frame).ok_or(WireError::BadCobs)?;
    if decoded.len() < MIN_FRAME_LEN {
        return Err(WireError::Truncated);
    }
    let (body, crc) = decoded.split_at(decoded.len() - CRC_LEN);
    if reference_crc32(body).to_le_bytes() != crc {
        return Err(WireError::BadCrc);
    }
    if body[0] != PROTOCOL_VERSION {
        return Err(WireError::BadVersion { got: body[0] });
    }
    Ok(())
}

/// Engine memory for the `engine` target: slices of 1 KB, rows of 32, 4096
/// points in each surface (no extra scratch: the slices are it, as on the
/// MCU).
pub type EngineMem =
    isoscope_core::engine::StaticBuffers<1024, { isoscope_core::engine::Geometry::bytes_for(4096) }>;
