//! The volume readers on arbitrary files: the first byte picks the format
//! (and so the file name's extension), the rest is the file, written to a
//! scratch file and read as a user's would be (`formats::read_as`), with a
//! memory limit of 64 MiB of samples.
//!
//! Checks: no panic; a volume read holds exactly the samples its extents
//! say, within the limit. Run under `-rss_limit_mb` (scripts/fuzz gives
//! 512): a reader that inflated or read more than a header declares, or
//! allocated past the limit, is a crash.
#![no_main]

use isoscope_sim::formats::{Format, Options, read_as};
use isoscope_sim::volume::Samples;
use libfuzzer_sys::fuzz_target;
use std::path::PathBuf;

/// Samples a volume may take (the readers' limit, small here).
const MAX_BYTES: usize = 64 << 20;

/// Formats and the names a file of each is given.
const FORMATS: [(Format, &str); 6] = [
    (Format::Nrrd, "v.nrrd"),
    (Format::Nifti, "v.nii"),
    (Format::Mrc, "v.mrc"),
    (Format::Cube, "v.cube"),
    (Format::Vtk, "v.vtk"),
    (Format::Nifti, "v.hdr"),
];

fn scratch(name: &str) -> PathBuf {
    let shm = std::path::Path::new("/dev/shm");
    let base = if shm.is_dir() { shm.to_path_buf() } else { std::env::temp_dir() };
    let dir = base.join(format!("isoscope-fuzz-readers-{}", std::process::id()));
    let _ = std::fs::create_dir_all(&dir);
    dir.join(name)
}

fuzz_target!(|data: &[u8]| {
    let Some((&pick, file)) = data.split_first() else { return };
    let (format, name) = FORMATS[usize::from(pick) % FORMATS.len()];
    let path = scratch(name);
    if std::fs::write(&path, file).is_err() {
        return;
    }
    let opts = Options { index: usize::from(pick / 8 % 3), max_bytes: MAX_BYTES, ..Options::default() };
    if let Ok(loaded) = read_as(&path, format, &opts) {
        let v = &loaded.volume;
        let count = v.dims.count().expect("extents that were read overflow");
        let (len, size) = match &v.samples {
            Samples::U8(s) => (s.len(), 1),
            Samples::U16(s) => (s.len(), 2),
            Samples::I16(s) => (s.len(), 2),
            Samples::F32(s) => (s.len(), 4),
        };
        assert_eq!(len, count, "samples for {:?}", v.dims);
        assert!(len * size <= MAX_BYTES, "{len} samples of {size} bytes: past the limit of {MAX_BYTES}");
    }
});
