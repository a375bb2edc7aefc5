//! Write a built-in demo volume as a raw file: little-endian f32, x fastest,
//! exactly the samples `isoscope-sim ... --demo NAME:N` contours. Other tools
//! can then read the same bytes (`scripts/bench-peers` does), and
//! `isoscope-sim contour FILE --dims NxNxN --dtype f32` contours the file.
//!
//! ```text
//! cargo run --release -p isoscope-sim --example write_demo -- gyroid:256 gyroid256.raw
//! ```

use anyhow::{Context, Result, anyhow, bail};
use isoscope_sim::outfile::write_whole;
use isoscope_sim::volume::{DemoSpec, LoadedVolume, Samples};
use std::io::Write;
use std::path::PathBuf;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [spec, out] = args.as_slice() else {
        bail!("usage: write_demo NAME:N OUT.raw   (e.g. gyroid:256 gyroid256.raw)");
    };
    let spec: DemoSpec = spec.parse().map_err(|e: String| anyhow!(e))?;
    let vol = LoadedVolume::demo(spec)?;
    let Samples::F32(samples) = &vol.samples else { bail!("a demo volume is f32") };
    let bytes: Vec<u8> = samples.iter().flat_map(|v| v.to_le_bytes()).collect();
    let out = PathBuf::from(out);
    write_whole(&out, |w| w.write_all(&bytes).with_context(|| format!("cannot write {}", out.display())))?;
    Ok(())
}
