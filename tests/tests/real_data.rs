//! Real volumes nobody on the team made, fetched by package name and cached
//! by `scripts/fetch-data`.

use isoscope_sim::volume::{Dims, LoadedVolume, Samples};
use isoscope_tests::real_data;

#[test]
fn brainsmall_den_is_the_mri_head() {
    let path = real_data("brainsmall.den");
    let bytes = std::fs::read(&path).unwrap();
    assert_eq!(bytes.len(), 62 + 128 * 128 * 84);
    let v = LoadedVolume::read_known(&path).unwrap().expect("a .den is a known format");
    assert_eq!(v.dims, Dims(128, 128, 84));
    let Samples::U8(s) = &v.samples else { panic!("{:?}", v.samples) };
    // Known values of this file (checked independently with Python): the
    // first voxel, the maximum, and how many voxels lie above level 60.
    assert_eq!(s[0], bytes[62]);
    assert_eq!(s[0], 2);
    assert_eq!(*s.iter().max().unwrap(), 202);
    assert_eq!(s.iter().filter(|&&x| x > 60).count(), 112_197);
}

#[test]
fn truncated_and_corrupt_den_files_are_clear_errors() {
    let path = real_data("brainsmall.den");
    let bytes = std::fs::read(&path).unwrap();
    let err = |b: &[u8]| format!("{:#}", LoadedVolume::from_den(b).unwrap_err());
    assert!(err(&bytes[..40]).contains("62-byte header"), "{}", err(&bytes[..40]));
    assert!(err(&bytes[..bytes.len() - 1]).contains("truncated"));
    let mut bad = bytes.clone();
    bad[0] = 7;
    assert!(err(&bad).contains("not a VolPack .den file"));
    let mut bad = bytes.clone();
    bad[61] ^= 1; // sample count no longer matches the extents
    assert!(err(&bad).contains("inconsistent"));
    let mut bad = bytes;
    bad[50] = 0xff; // a negative extent
    bad[51] = 0xff;
    assert!(err(&bad).contains("positive") || err(&bad).contains("inconsistent"));
}
