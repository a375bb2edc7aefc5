//! `FrameDecoder<N>` on arbitrary bytes, for N = 64 and N = 1200, fed one
//! byte at a time (`push`), as one slice and in uneven slices (`feed`).
//!
//! Checks: no panic; `buffered() <= N` after every byte; all three ways give
//! exactly the results the specification gives (`expected_frames`: split at
//! `0x00`, `Oversize` past N, else `decode_frame`); every message re-encodes
//! to a frame that decodes back to the same message (`check_message`).
#![no_main]

use isoscope_core::wire::{Feed, FrameDecoder};
use isoscope_fuzz::{Outcome, expected_frames, outcome};
use libfuzzer_sys::fuzz_target;

/// Slice lengths for the uneven `feed`, used in turn.
const CHUNKS: [usize; 7] = [1, 7, 3, 64, 2, 255, 1300];

fn by_push<const N: usize>(input: &[u8]) -> (Vec<Outcome>, usize) {
    let mut dec = FrameDecoder::<N>::new();
    let mut out = Vec::new();
    for &b in input {
        let held = dec.buffered();
        if let Some(r) = dec.push(b) {
            out.push(outcome(r, held));
            assert_eq!(dec.buffered(), 0, "bytes held after a frame ended");
        }
        assert!(dec.buffered() <= N, "buffered() = {} > N = {N}", dec.buffered());
    }
    (out, dec.buffered())
}

fn by_feed<const N: usize>(input: &[u8], chunks: &[usize]) -> (Vec<Outcome>, usize) {
    let mut dec = FrameDecoder::<N>::new();
    let mut out = Vec::new();
    let mut rest = input;
    for &size in chunks.iter().cycle() {
        if rest.is_empty() {
            break;
        }
        let (mut chunk, after) = rest.split_at(size.min(rest.len()));
        rest = after;
        loop {
            let held = dec.buffered();
            match dec.feed(chunk) {
                Feed::Consumed => break,
                Feed::Frame { result, remaining } => {
                    // `remaining` is what follows the delimiter in `chunk`.
                    let taken = chunk.len() - remaining.len();
                    assert!(taken >= 1 && chunk[taken - 1] == 0, "Frame without a delimiter");
                    assert!(std::ptr::eq(remaining, &chunk[taken..]), "remaining is not a suffix");
                    out.push(outcome(result, held + taken));
                    assert_eq!(dec.buffered(), 0, "bytes held after a frame ended");
                    chunk = remaining;
                }
            }
            assert!(dec.buffered() <= N, "buffered() = {} > N = {N}", dec.buffered());
        }
    }
    (out, dec.buffered())
}

fn check<const N: usize>(input: &[u8]) {
    let (want, tail) = expected_frames(input, N);
    let (pushed, held) = by_push::<N>(input);
    assert_eq!(pushed, want, "push, N = {N}");
    if tail <= N {
        assert_eq!(held, tail, "push: partial frame length, N = {N}");
    }
    assert_eq!(by_feed::<N>(input, &[usize::MAX]), (pushed.clone(), held), "feed whole, N = {N}");
    assert_eq!(by_feed::<N>(input, &CHUNKS), (pushed, held), "feed in chunks, N = {N}");
}

fuzz_target!(|data: &[u8]| {
    check::<64>(data);
    check::<1200>(data);
});
