//! Any `Message` (built with `arbitrary` from a local mirror of the enum):
//! encode, decode, compare (`check_message`), and the frame through a
//! `FrameDecoder` too, alone and after a flush byte.
#![no_main]

use arbitrary::{Arbitrary, Unstructured};
use isoscope_core::wire::{DeviceState, FrameDecoder, Levels, MAX_LEVELS, Message, NackCode, SampleType};
use isoscope_fuzz::{check_message, outcome};
use libfuzzer_sys::fuzz_target;

/// The largest SliceData payload tried: a frame just over the 1200-byte
/// decoder used below, so both sides of its limit are reached.
const MAX_DATA: usize = 1200;

/// `Message`, field for field, with `arbitrary`-friendly field types.
#[derive(Debug, Arbitrary)]
enum Arb<'a> {
    Hello {
        protocol: u8,
        firmware: [u8; 3],
        seq: u16,
    },
    Capabilities {
        protocol: u8,
        max_slice_samples: u32,
        sample_types: u8,
        display_points: u32,
    },
    BeginVolume {
        seq: u16,
        dims: [u16; 3],
        sample_type: u8,
        spacing: [f32; 3],
        levels: Vec<f32>,
        axes: u8,
        every: u8,
    },
    SliceData {
        seq: u16,
        slice: u16,
        offset: u32,
        data: &'a [u8],
    },
    EndVolume {
        seq: u16,
    },
    SetLevels {
        seq: u16,
        levels: Vec<f32>,
    },
    SetView {
        seq: u16,
        yaw: f32,
        pitch: f32,
        roll: f32,
        fov_deg: f32,
        spin_deg_per_s: f32,
    },
    SetBeam {
        seq: u16,
        lit_step: u16,
        dwell_us: u16,
        settle_us: u16,
    },
    Ack {
        seq: u16,
    },
    Nack {
        seq: u16,
        code: u8,
    },
    Status {
        seq: u16,
        state: u8,
        slices: u16,
        points: u32,
        refresh_centi_hz: u16,
    },
}

const NACK_CODES: [NackCode; 12] = [
    NackCode::BadCrc,
    NackCode::Truncated,
    NackCode::Oversize,
    NackCode::UnknownMessage,
    NackCode::BadVersion,
    NackCode::DimsOverCapacity,
    NackCode::OutOfOrder,
    NackCode::Duplicate,
    NackCode::Missing,
    NackCode::Aborted,
    NackCode::Busy,
    NackCode::Invalid,
];
const STATES: [DeviceState; 3] = [DeviceState::Idle, DeviceState::Receiving, DeviceState::Showing];

fn levels(v: &[f32]) -> Levels {
    Levels::from_slice(&v[..v.len().min(MAX_LEVELS)]).expect("at most MAX_LEVELS")
}

fn pick<T: Copy>(all: &[T], i: u8) -> T {
    all[usize::from(i) % all.len()]
}

impl<'a> Arb<'a> {
    fn message(&self) -> Message<'a> {
        match *self {
            Arb::Hello { protocol, firmware, seq } => Message::Hello { protocol, firmware, seq },
            Arb::Capabilities { protocol, max_slice_samples, sample_types, display_points } => {
                Message::Capabilities { protocol, max_slice_samples, sample_types, display_points }
            }
            Arb::BeginVolume { seq, dims, sample_type, spacing, ref levels, axes, every } => {
                Message::BeginVolume {
                    seq,
                    dims,
                    sample_type: pick(&SampleType::ALL, sample_type),
                    spacing,
                    levels: self::levels(levels),
                    axes,
                    every,
                }
            }
            Arb::SliceData { seq, slice, offset, data } => {
                Message::SliceData { seq, slice, offset, data: &data[..data.len().min(MAX_DATA)] }
            }
            Arb::EndVolume { seq } => Message::EndVolume { seq },
            Arb::SetLevels { seq, ref levels } => Message::SetLevels { seq, levels: self::levels(levels) },
            Arb::SetView { seq, yaw, pitch, roll, fov_deg, spin_deg_per_s } => {
                Message::SetView { seq, yaw, pitch, roll, fov_deg, spin_deg_per_s }
            }
            Arb::SetBeam { seq, lit_step, dwell_us, settle_us } => {
                Message::SetBeam { seq, lit_step, dwell_us, settle_us }
            }
            Arb::Ack { seq } => Message::Ack { seq },
            Arb::Nack { seq, code } => Message::Nack { seq, code: pick(&NACK_CODES, code) },
            Arb::Status { seq, state, slices, points, refresh_centi_hz } => {
                Message::Status { seq, state: pick(&STATES, state), slices, points, refresh_centi_hz }
            }
        }
    }
}

/// Feeds `bytes` to a 1200-byte decoder; the outcomes, in order.
fn decode_all(bytes: &[u8]) -> Vec<isoscope_fuzz::Outcome> {
    let mut dec = FrameDecoder::<1200>::new();
    let mut out = Vec::new();
    for &b in bytes {
        let held = dec.buffered();
        if let Some(r) = dec.push(b) {
            out.push(outcome(r, held));
        }
    }
    out
}

fuzz_target!(|data: &[u8]| {
    let Ok(arb) = Arb::arbitrary_take_rest(Unstructured::new(data)) else { return };
    let msg = arb.message();
    // Postcard length bound: 5 varint bytes per field is generous, plus the data.
    let data_len = if let Message::SliceData { data, .. } = msg { data.len() } else { 0 };
    let frame = check_message(&msg, 64 + data_len);

    // Through the stream decoder: alone, after a flush byte, twice in a row.
    let want = if frame.len() - 1 <= 1200 {
        Ok(frame.clone())
    } else {
        Err(isoscope_core::wire::WireError::Oversize)
    };
    assert_eq!(decode_all(&frame), vec![want.clone()]);
    let stream = [&[0u8][..], &frame, &frame].concat();
    assert_eq!(decode_all(&stream), vec![want.clone(), want]);
});
