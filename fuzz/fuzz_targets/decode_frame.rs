//! `decode_frame` (and `cobs_decode_in_place`, `crc32`) on arbitrary bytes.
//!
//! Checks: no panic; the COBS decoding and the CRC match independent
//! implementations; the error is the one the documented order of checks
//! gives (`reference_precheck`); a decoded message re-encodes to a frame that
//! decodes back to the same message (`check_message`).
#![no_main]

use isoscope_core::wire::{WireError, cobs_decode_in_place, crc32, decode_frame};
use isoscope_fuzz::{outcome, reference_cobs_decode, reference_crc32, reference_precheck};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    assert_eq!(crc32(data), reference_crc32(data), "crc32");

    let mut buf = data.to_vec();
    let cobs = cobs_decode_in_place(&mut buf).ok().map(|n| buf[..n].to_vec());
    assert_eq!(cobs, reference_cobs_decode(data), "cobs_decode_in_place");

    let mut frame = data.to_vec();
    let got = decode_frame(&mut frame);
    match reference_precheck(data) {
        Err(want) => assert_eq!(got, Err(want), "decode_frame error"),
        Ok(()) => assert!(matches!(got, Ok(_) | Err(WireError::UnknownMessage)), "decode_frame: {got:?}"),
    }
    let _ = outcome(got, data.len());
});
