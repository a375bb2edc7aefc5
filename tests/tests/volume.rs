//! Raw volume decoding: little-endian round trips for every sample type,
//! length errors, and the `--dims`/`--dtype`/`--demo` parsers.

use isoscope_core::demo::Demo;
use isoscope_sim::volume::{DemoSpec, Dims, Dtype, LoadedVolume, MAX_DEMO_N, Samples, UNIT_SPACING};

const DIMS: Dims = Dims(3, 2, 1);

#[test]
fn u8_round_trip() {
    let v = [0u8, 1, 127, 128, 254, 255];
    let l = LoadedVolume::from_bytes(&v, DIMS, Dtype::U8).unwrap();
    assert_eq!(l, LoadedVolume { dims: DIMS, samples: Samples::U8(v.to_vec()), spacing: UNIT_SPACING });
}

#[test]
fn u16_round_trip() {
    let v = [0u16, 1, 0x00ff, 0x0100, 0x1234, u16::MAX];
    let bytes: Vec<u8> = v.iter().flat_map(|x| x.to_le_bytes()).collect();
    assert_eq!(&bytes[8..10], [0x34, 0x12], "little-endian");
    let l = LoadedVolume::from_bytes(&bytes, DIMS, Dtype::U16).unwrap();
    assert_eq!(l, LoadedVolume { dims: DIMS, samples: Samples::U16(v.to_vec()), spacing: UNIT_SPACING });
}

#[test]
fn i16_round_trip() {
    let v = [i16::MIN, -1000, -1, 0, 1, i16::MAX];
    let bytes: Vec<u8> = v.iter().flat_map(|x| x.to_le_bytes()).collect();
    let l = LoadedVolume::from_bytes(&bytes, DIMS, Dtype::I16).unwrap();
    assert_eq!(l, LoadedVolume { dims: DIMS, samples: Samples::I16(v.to_vec()), spacing: UNIT_SPACING });
}

#[test]
fn f32_round_trip_bit_for_bit() {
    let v = [0.0f32, -0.0, 1.5, -3.25e-7, f32::MAX, f32::MIN_POSITIVE / 2.0, f32::INFINITY, f32::NAN];
    let dims = Dims(2, 2, 2);
    let bytes: Vec<u8> = v.iter().flat_map(|x| x.to_le_bytes()).collect();
    let l = LoadedVolume::from_bytes(&bytes, dims, Dtype::F32).unwrap();
    assert_eq!(l.dims, dims);
    let Samples::F32(got) = l.samples else { panic!("not f32: {:?}", l.samples) };
    let bits = |s: &[f32]| s.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&got), bits(&v));
}

#[test]
fn wrong_lengths_are_errors() {
    for dtype in [Dtype::U8, Dtype::U16, Dtype::I16, Dtype::F32] {
        let need = 6 * dtype.size();
        let short = vec![0u8; need - 1];
        let e = format!("{:#}", LoadedVolume::from_bytes(&short, DIMS, dtype).unwrap_err());
        assert!(e.contains("truncated"), "{dtype:?}: {e}");
        assert!(e.contains(&format!("{} bytes", need - 1)) && e.contains(&format!("{need} bytes")), "{e}");
        let long = vec![0u8; need + 1];
        let e = format!("{:#}", LoadedVolume::from_bytes(&long, DIMS, dtype).unwrap_err());
        assert!(!e.contains("truncated"), "{dtype:?}: {e}");
        assert!(e.contains(&format!("{} bytes", need + 1)) && e.contains(&format!("{need} bytes")), "{e}");
        assert!(LoadedVolume::from_bytes(&[], DIMS, dtype).is_err());
        assert!(LoadedVolume::from_bytes(&vec![0u8; need], DIMS, dtype).is_ok());
    }
    let e = LoadedVolume::from_bytes(&[0; 4], Dims(usize::MAX, 2, 1), Dtype::U8).unwrap_err();
    assert!(format!("{e:#}").contains("overflow"), "{e:#}");
    let e = LoadedVolume::from_bytes(&[0; 4], Dims(usize::MAX / 2, 1, 1), Dtype::F32).unwrap_err();
    assert!(format!("{e:#}").contains("overflow"), "{e:#}");
}

#[test]
fn read_raw_names_the_file() {
    let dir = std::env::temp_dir().join(format!("isoscope-tests-volume-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("v.i16");
    std::fs::write(&path, [0xffu8, 0xff, 0x00, 0x80]).unwrap();
    let ok = LoadedVolume::read_raw(&path, Dims(2, 1, 1), Dtype::I16);
    let short = LoadedVolume::read_raw(&path, Dims(3, 1, 1), Dtype::I16);
    let missing = LoadedVolume::read_raw(&dir.join("none"), Dims(2, 1, 1), Dtype::I16);
    let _ = std::fs::remove_dir_all(&dir);
    assert_eq!(ok.unwrap().samples, Samples::I16(vec![-1, i16::MIN]));
    let e = format!("{:#}", short.unwrap_err());
    assert!(e.contains("v.i16") && e.contains("truncated"), "{e}");
    let e = format!("{:#}", missing.unwrap_err());
    assert!(e.contains("none"), "{e}");
}

#[test]
fn demo_volumes_are_the_core_demos() {
    let spec: DemoSpec = "hydrogen:5".parse().unwrap();
    let l = LoadedVolume::demo(spec).unwrap();
    assert_eq!(l.dims, Dims(5, 5, 5));
    let Samples::F32(s) = l.samples else { panic!("demo is not f32") };
    assert_eq!(s.len(), 125);
    assert_eq!(s[(3 * 5 + 2) * 5 + 1].to_bits(), Demo::Hydrogen.sample(5, 1, 2, 3).to_bits());
}

#[test]
fn parsers() {
    assert_eq!("128x128x84".parse::<Dims>(), Ok(Dims(128, 128, 84)));
    assert_eq!("2X3x1".parse::<Dims>(), Ok(Dims(2, 3, 1)));
    for bad in ["12x12", "0x2x2", "axbxc", "1x2x3x4", "", "-1x2x2"] {
        assert!(bad.parse::<Dims>().is_err(), "{bad}");
    }
    for (s, d) in [("u8", Dtype::U8), ("u16", Dtype::U16), ("i16", Dtype::I16), ("f32", Dtype::F32)] {
        assert_eq!(s.parse::<Dtype>(), Ok(d));
    }
    assert!("u32".parse::<Dtype>().unwrap_err().contains("u32"));
    assert_eq!("gyroid:7".parse::<DemoSpec>(), Ok(DemoSpec { demo: Demo::Gyroid, n: 7 }));
    assert_eq!("hydrogen".parse::<DemoSpec>(), Ok(DemoSpec { demo: Demo::Hydrogen, n: 32 }));
    assert!("gyroid:1".parse::<DemoSpec>().is_err());
    assert!(format!("gyroid:{}", MAX_DEMO_N + 1).parse::<DemoSpec>().is_err());
    assert!("nosuch:8".parse::<DemoSpec>().unwrap_err().contains("nosuch"));
}
