//! The wire protocol: golden frames, round trips, every error, resync.
//!
//! The golden frames were computed independently of this crate, by a short
//! Python script: postcard's rules by hand (LEB128 varints, `f32` as 4 LE
//! bytes, variant index as a varint), `binascii.crc32` for the CRC and a
//! textbook COBS encoder.

use isoscope_core::wire::{
    AXIS_X, AXIS_Z, DeviceState, Feed, FrameDecoder, Levels, Message, NackCode, SampleType, WireError, crc32,
    decode_frame, encode, max_frame_len,
};
use proptest::prelude::*;

#[path = "common/cobs.rs"]
mod cobs;
use cobs::cobs;

fn hex(s: &str) -> Vec<u8> {
    (0..s.len()).step_by(2).map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap()).collect()
}

const SLICE: [u8; 5] = [0, 1, 2, 0xFF, 0];

fn golden() -> Vec<(&'static str, Message<'static>, &'static str)> {
    vec![
        (
            "hello",
            Message::Hello { protocol: 1, firmware: [0, 3, 2], seq: 300 },
            "02020201090302ac02f8e2d61100",
        ),
        (
            "capabilities",
            Message::Capabilities {
                protocol: 1,
                max_slice_samples: 65536,
                sample_types: 0x0F,
                display_points: 4000,
            },
            "0e0201018080040fa01f3ef245aa00",
        ),
        (
            "begin_volume",
            Message::BeginVolume {
                seq: 1,
                dims: [64, 64, 300],
                sample_type: SampleType::I16,
                spacing: [1.0, 1.0, 2.5],
                levels: Levels::from_slice(&[100.0, 1000.0]).unwrap(),
                axes: AXIS_X | AXIS_Z,
                every: 4,
            },
            "090202014040ac02020103803f0103803f01042040020103c84201097a440504c670e99200",
        ),
        (
            "slice_data",
            Message::SliceData { seq: 2, slice: 17, offset: 300, data: &SLICE },
            "0802030211ac0205040102ff05de84eea300",
        ),
        ("end_volume", Message::EndVolume { seq: 130 }, "09020482011475f6f200"),
        (
            "set_levels",
            Message::SetLevels { seq: 3, levels: Levels::from_slice(&[0.5]).unwrap() },
            "05020503010101063f9081ad7800",
        ),
        (
            "set_view",
            Message::SetView {
                seq: 4,
                yaw: 30.0,
                pitch: -15.0,
                roll: 0.0,
                fov_deg: 0.0,
                spin_deg_per_s: 10.0,
            },
            "040206040103f041010370c101010101010101010107204130fe9cfc00",
        ),
        (
            "set_beam",
            Message::SetBeam { seq: 5, lit_step: 64, dwell_us: 2, settle_us: 20 },
            "0b020705400214b517822100",
        ),
        ("ack", Message::Ack { seq: 7 }, "08020807d71278aa00"),
        ("nack", Message::Nack { seq: 8, code: NackCode::OutOfOrder }, "0902090806250326a500"),
        (
            "status",
            Message::Status {
                seq: 9,
                state: DeviceState::Showing,
                slices: 300,
                points: 4000,
                refresh_centi_hz: 5000,
            },
            "0f020a0902ac02a01f882742e0dee200",
        ),
    ]
}

/// Feeds `bytes` and collects every result, messages as owned debug text.
fn decode_all<const N: usize>(dec: &mut FrameDecoder<N>, bytes: &[u8]) -> Vec<Result<String, WireError>> {
    let mut out = Vec::new();
    for &b in bytes {
        if let Some(r) = dec.push(b) {
            out.push(r.map(|m| format!("{m:?}")));
        }
    }
    out
}

fn ok(m: &Message<'_>) -> Result<String, WireError> {
    Ok(format!("{m:?}"))
}

#[test]
fn golden_emit_into_junk() {
    for (name, msg, want) in golden() {
        let want = hex(want);
        let mut buf = [0xAAu8; 128];
        let frame = encode(&msg, &mut buf).unwrap();
        assert_eq!(frame, &want[..], "{name}");
    }
}

#[test]
fn golden_parse_back() {
    for (name, msg, want) in golden() {
        let mut dec = FrameDecoder::<64>::new();
        assert_eq!(decode_all(&mut dec, &hex(want)), vec![ok(&msg)], "{name}");
        assert_eq!(dec.buffered(), 0);
    }
}

#[test]
fn all_golden_frames_back_to_back_with_feed() {
    let stream: Vec<u8> = golden().iter().flat_map(|g| hex(g.2)).collect();
    let mut dec = FrameDecoder::<64>::new();
    let mut rest = &stream[..];
    let mut got = Vec::new();
    while let Feed::Frame { result, remaining } = dec.feed(rest) {
        got.push(result.map(|m| format!("{m:?}")));
        rest = remaining;
    }
    let want: Vec<_> = golden().iter().map(|g| ok(&g.1)).collect();
    assert_eq!(got, want);
}

#[test]
fn worked_example_by_hand() {
    // Ack { seq: 7 }: version 02, variant 8 (varint 08), seq 7 (varint 07).
    let body = [0x02, 0x08, 0x07];
    assert_eq!(crc32(&body), 0xAA78_12D7);
    assert_eq!(crc32(b"123456789"), 0xCBF4_3926); // the CRC-32 check value
    // No zeros: one COBS block of 7 bytes, code 0x08, then the delimiter.
    assert_eq!(hex("08020807d71278aa00"), [8, 2, 8, 7, 0xD7, 0x12, 0x78, 0xAA, 0]);
    assert_eq!(encode(&Message::Ack { seq: 7 }, &mut [0u8; 16]).unwrap(), hex("08020807d71278aa00"));
}

#[test]
fn buffer_too_small_for_every_shorter_buffer() {
    for (name, msg, want) in golden() {
        let need = hex(want).len();
        for len in 0..need {
            let mut buf = vec![0xAA; len];
            assert_eq!(encode(&msg, &mut buf), Err(WireError::BufferTooSmall), "{name} {len}");
        }
    }
}

#[test]
fn corrupt_crc_is_bad_crc() {
    let mut frame = hex("08020807d71278aa00");
    frame[5] ^= 0x01;
    assert_eq!(decode_all(&mut FrameDecoder::<64>::new(), &frame), vec![Err(WireError::BadCrc)]);
    // A flipped payload bit also fails the CRC.
    let mut frame = hex("08020807d71278aa00");
    frame[3] ^= 0x10;
    assert_eq!(decode_all(&mut FrameDecoder::<64>::new(), &frame), vec![Err(WireError::BadCrc)]);
}

#[test]
fn truncated_frames() {
    // Cut inside a COBS block: the block runs past the delimiter.
    let frame = hex("08020807d71278aa00");
    let mut cut = frame[..5].to_vec();
    cut.push(0);
    assert_eq!(decode_all(&mut FrameDecoder::<64>::new(), &cut), vec![Err(WireError::BadCobs)]);
    // Fewer than 6 decoded bytes.
    assert_eq!(
        decode_all(&mut FrameDecoder::<64>::new(), &[0x03, 0x01, 0x08, 0x00]),
        vec![Err(WireError::Truncated)]
    );
    // Cut on a block boundary: decodes, but the CRC is wrong.
    let frame = hex("040206040103f041010370c101010101010101010107204130fe9cfc00");
    let mut cut = frame[..12].to_vec();
    cut.push(0);
    assert_eq!(decode_all(&mut FrameDecoder::<64>::new(), &cut), vec![Err(WireError::BadCrc)]);
    // Every prefix of every golden frame is an error, never a message.
    for (name, _, want) in golden() {
        let frame = hex(want);
        for n in 1..frame.len() - 1 {
            let mut cut = frame[..n].to_vec();
            cut.push(0);
            let got = decode_all(&mut FrameDecoder::<64>::new(), &cut);
            assert_eq!(got.len(), 1, "{name} {n}");
            assert!(
                matches!(got[0], Err(WireError::BadCobs | WireError::Truncated | WireError::BadCrc)),
                "{name} {n}: {got:?}"
            );
        }
    }
}

#[test]
fn oversize_frame_then_recovery() {
    let big = hex(golden()[2].2); // begin_volume: 36 bytes
    let ack = hex("08020807d71278aa00");
    let mut dec = FrameDecoder::<16>::new();
    let stream: Vec<u8> = [&big[..], &ack[..], &big[..], &ack[..]].concat();
    assert_eq!(
        decode_all(&mut dec, &stream),
        vec![
            Err(WireError::Oversize),
            ok(&Message::Ack { seq: 7 }),
            Err(WireError::Oversize),
            ok(&Message::Ack { seq: 7 })
        ]
    );
    // Exactly N bytes fit.
    let mut dec = FrameDecoder::<8>::new();
    assert_eq!(decode_all(&mut dec, &ack), vec![ok(&Message::Ack { seq: 7 })]);
    let mut dec = FrameDecoder::<7>::new();
    assert_eq!(decode_all(&mut dec, &ack), vec![Err(WireError::Oversize)]);
}

#[test]
fn garbage_between_frames_is_skipped() {
    let ack = hex("08020807d71278aa00");
    let end = hex("09020482011475f6f200");
    let stream: Vec<u8> = [&b"\x00\x00noise"[..], &[0], &ack, &[0, 0, 0], b"more junk\x00", &end].concat();
    let got = decode_all(&mut FrameDecoder::<64>::new(), &stream);
    let msgs: Vec<_> = got.iter().filter(|r| r.is_ok()).cloned().collect();
    assert_eq!(msgs, vec![ok(&Message::Ack { seq: 7 }), ok(&Message::EndVolume { seq: 130 })]);
    // Each garbage run is one error, reported, not dropped.
    assert_eq!(got.len(), 4);
    // Garbage with no delimiter before a frame: that frame is lost (one
    // error), the next one decodes.
    let stream: Vec<u8> = [&b"junk"[..], &ack, &end].concat();
    let got = decode_all(&mut FrameDecoder::<64>::new(), &stream);
    assert_eq!(got.len(), 2);
    assert!(got[0].is_err());
    assert_eq!(got[1], ok(&Message::EndVolume { seq: 130 }));
}

#[test]
fn wrong_version_is_bad_version() {
    assert_eq!(
        // Ack { seq: 7 } of protocol version 1.
        decode_all(&mut FrameDecoder::<64>::new(), &hex("080108078eac3ea800")),
        vec![Err(WireError::BadVersion { got: 1 })]
    );
}

#[test]
fn unknown_messages() {
    for frame in [
        // SetLevels with 9 levels.
        "05020503090103803f0103803f0103803f0103803f0103803f0103803f0103803f0103803f0107803f969b099600",
        // Variant 11.
        "08020b030d85388600",
        // Ack with a trailing byte.
        "09020807017ee018bd00",
    ] {
        assert_eq!(
            decode_all(&mut FrameDecoder::<64>::new(), &hex(frame)),
            vec![Err(WireError::UnknownMessage)],
            "{frame}"
        );
    }
}

struct XorShift(u64);
impl XorShift {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
}

#[test]
fn one_megabyte_of_noise_then_a_frame() {
    let mut rng = XorShift(0x9E37_79B9_7F4A_7C15);
    let noise: Vec<u8> = (0..1 << 20).map(|_| rng.next() as u8).collect();
    let ack = hex("08020807d71278aa00");
    let end = hex("09020482011475f6f200");
    // With the documented flush byte: the first frame after the noise decodes.
    let mut dec = FrameDecoder::<256>::new();
    let mut got = decode_all(&mut dec, &noise);
    assert!(got.len() > 1000);
    // The flush byte reports the noise tail (if any) as one error.
    got = decode_all(&mut dec, &[&[0][..], &ack].concat());
    assert!(got.len() <= 2 && got[..got.len() - 1].iter().all(Result::is_err));
    assert_eq!(got.last(), Some(&ok(&Message::Ack { seq: 7 })));
    // Without it: the noise tail swallows the first frame; the next decodes.
    let mut dec = FrameDecoder::<256>::new();
    decode_all(&mut dec, &noise);
    let got = decode_all(&mut dec, &[&ack[..], &end].concat());
    assert_eq!(got.last(), Some(&ok(&Message::EndVolume { seq: 130 })));
}

fn levels() -> impl Strategy<Value = Levels> {
    prop::collection::vec(any::<f32>().prop_filter("not NaN", |f| !f.is_nan()), 0..=8)
        .prop_map(|v| Levels::from_slice(&v).unwrap())
}

fn finite() -> impl Strategy<Value = f32> {
    any::<f32>().prop_filter("not NaN", |f| !f.is_nan())
}

fn sample_type() -> impl Strategy<Value = SampleType> {
    prop::sample::select(SampleType::ALL.to_vec())
}

/// A message whose `SliceData` borrows `data`.
#[allow(clippy::too_many_arguments)] // one argument per proptest input
fn message(
    data: &[u8],
    pick: u8,
    a: u16,
    b: u32,
    c: u8,
    f: [f32; 5],
    st: SampleType,
    lv: Levels,
) -> Message<'_> {
    match pick % 11 {
        0 => Message::Hello { protocol: c, firmware: [c, a as u8, b as u8], seq: a },
        1 => Message::Capabilities {
            protocol: c,
            max_slice_samples: b,
            sample_types: c,
            display_points: b ^ 0xFFFF,
        },
        2 => Message::BeginVolume {
            seq: a,
            dims: [a, a.wrapping_mul(3), b as u16],
            sample_type: st,
            spacing: [f[0], f[1], f[2]],
            levels: lv,
            axes: c,
            every: c,
        },
        3 => Message::SliceData { seq: a, slice: b as u16, offset: b, data },
        4 => Message::EndVolume { seq: a },
        5 => Message::SetLevels { seq: a, levels: lv },
        6 => Message::SetView {
            seq: a,
            yaw: f[0],
            pitch: f[1],
            roll: f[2],
            fov_deg: f[3],
            spin_deg_per_s: f[4],
        },
        7 => Message::SetBeam { seq: a, lit_step: b as u16, dwell_us: a, settle_us: c.into() },
        8 => Message::Ack { seq: a },
        9 => Message::Nack { seq: a, code: NackCode::Busy },
        _ => Message::Status {
            seq: a,
            state: DeviceState::Receiving,
            slices: b as u16,
            points: b,
            refresh_centi_hz: a,
        },
    }
}

proptest! {
    #[test]
    fn round_trip_random_messages(
        data in prop::collection::vec(any::<u8>(), 0..700),
        pick in any::<u8>(), a in any::<u16>(), b in any::<u32>(), c in any::<u8>(),
        f in [finite(), finite(), finite(), finite(), finite()],
        st in sample_type(), lv in levels(),
    ) {
        let msg = message(&data, pick, a, b, c, f, st, lv);
        let mut buf = [0xAAu8; 1024];
        let frame = encode(&msg, &mut buf).unwrap();
        prop_assert_eq!(frame.last(), Some(&0));
        if let Message::SliceData { .. } = msg {
            // Header at most 1 + 3 + 3 + 5 + 3 (length) bytes.
            prop_assert!(frame.len() <= max_frame_len(data.len() + 15));
        }
        prop_assert!(!frame[..frame.len() - 1].contains(&0));
        let mut dec = FrameDecoder::<1024>::new();
        let got = decode_all(&mut dec, frame);
        prop_assert_eq!(got, vec![ok(&msg)]);
    }

    #[test]
    fn decoder_never_panics(bytes in prop::collection::vec(any::<u8>(), 0..4096)) {
        let mut small = FrameDecoder::<16>::new();
        let mut big = FrameDecoder::<512>::new();
        let _ = decode_all(&mut small, &bytes);
        let _ = decode_all(&mut big, &bytes);
        let mut rest = &bytes[..];
        while let Feed::Frame { remaining, .. } = big.feed(rest) {
            rest = remaining;
        }
    }

    #[test]
    fn mostly_nonzero_noise_never_panics(bytes in prop::collection::vec(prop::sample::select(vec![0u8, 1, 2, 3, 0x7F, 0xFE, 0xFF]), 0..2048)) {
        let _ = decode_all(&mut FrameDecoder::<300>::new(), &bytes);
    }
}

#[test]
fn a_zero_inside_a_cobs_block_is_bad_cobs() {
    // `Hello { protocol: 0, firmware: [1, 2, 3] }` with a valid CRC, but its
    // zero byte sent raw inside an 11-byte block instead of COBS-encoded.
    let mut frame = hex("0b010000010203092b63d0");
    assert_eq!(decode_frame(&mut frame), Err(WireError::BadCobs));
    assert_eq!(isoscope_core::wire::cobs_decode_in_place(&mut hex("0301000a")), Err(WireError::BadCobs));
}

/// CRC-32/ISO-HDLC bit by bit, as the specification gives it.
fn crc32_bitwise(data: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in data {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 == 1 { (crc >> 1) ^ 0xEDB8_8320 } else { crc >> 1 };
        }
    }
    !crc
}

#[test]
fn crc32_is_the_standard_check_value_and_the_bitwise_crc_of_every_byte_pair() {
    assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
    assert_eq!(crc32(&[]), 0);
    for a in 0..=255u8 {
        for b in 0..=255u8 {
            assert_eq!(crc32(&[a, b]), crc32_bitwise(&[a, b]), "{a:#04x} {b:#04x}");
        }
    }
}

proptest! {
    #[test]
    fn crc32_is_the_bitwise_crc(data in prop::collection::vec(any::<u8>(), 0..600)) {
        prop_assert_eq!(crc32(&data), crc32_bitwise(&data));
    }
}

/// LEB128, as postcard writes an unsigned integer.
fn varint(mut v: u64, out: &mut Vec<u8>) {
    loop {
        let b = (v & 0x7F) as u8;
        v >>= 7;
        if v == 0 {
            out.push(b);
            return;
        }
        out.push(b | 0x80);
    }
}

proptest! {
    /// A slice's bytes go to the framing whole (postcard bytes, CRC and
    /// COBS over runs): the frame is the one built byte by byte by hand,
    /// for data with zeros anywhere and non-zero runs past a COBS block.
    #[test]
    fn slice_data_frames_are_built_by_the_book(
        data in prop::collection::vec(prop_oneof![3 => any::<u8>(), 1 => Just(0u8), 1 => Just(0xFFu8)], 0..1100),
        ones in 0..600usize,
        seq in any::<u16>(),
        slice in any::<u16>(),
        offset in any::<u32>(),
    ) {
        // Some long runs without a zero, too.
        let mut data = data;
        data.extend(std::iter::repeat_n(7u8, ones));
        let mut body = vec![isoscope_core::wire::PROTOCOL_VERSION, 3];
        varint(u64::from(seq), &mut body);
        varint(u64::from(slice), &mut body);
        varint(u64::from(offset), &mut body);
        varint(data.len() as u64, &mut body);
        body.extend_from_slice(&data);
        body.extend_from_slice(&crc32_bitwise(&body).to_le_bytes());
        let mut buf = vec![0u8; max_frame_len(data.len() + 16)];
        let frame = encode(&Message::SliceData { seq, slice, offset, data: &data }, &mut buf).unwrap();
        prop_assert_eq!(frame, &cobs(&body)[..]);
    }
}
