//! The volume format readers on real files nobody on the team made (fetched
//! by package name and cached by `scripts/fetch-data`), with known values,
//! and on truncated and corrupted copies of them.
//!
//! The known values were computed independently in Python: MRC/CCP4 with
//! `mrcfile` 1.5 and GridDataFormats 1.2.0 (both agree on every voxel,
//! after transposing by MAPC/MAPR/MAPS), NIfTI with `nibabel` 5.4,
//! NRRD with `pynrrd` 1.1, VTK with `meshio` 5.3, and the cube file with a
//! few lines of numpy (ASE's reader does not take two orbitals): text
//! split into numbers, reshaped (nx, ny, nz, orbitals) in C order. Points
//! are (x, y, z), x fastest, in the file's index order
//! ([`Orientation::Index`]; the readers put MRC maps and cube files x
//! fastest all the same); what the headers' orientation makes of them is
//! checked by `headers_orient_the_real_files`.

use isoscope_sim::formats::{self, Format, Loaded, Options, Orientation};
use isoscope_sim::orient::AxisMap;
use isoscope_sim::volume::{Dims, LoadedVolume, Samples};
use isoscope_tests::real_data;
use std::path::{Path, PathBuf};

/// The file's index order.
const INDEX: Options =
    Options { index: 0, max_bytes: formats::DEFAULT_MAX_BYTES, orientation: Orientation::Index };

fn load_index(name: &str, index: usize) -> Loaded {
    let path = real_data(name);
    formats::read(&path, &Options { index, ..INDEX })
        .unwrap_or_else(|e| panic!("{name}: {e:#}"))
        .unwrap_or_else(|| panic!("{name}: not a known format"))
}

fn load(name: &str) -> Loaded {
    let l = load_index(name, 0);
    // The command line's route, `read_known_with`, gives the same volume.
    let (known, _) =
        LoadedVolume::read_known_with(&real_data(name), &INDEX).unwrap().expect("a known format");
    assert_eq!(known, l.volume, "{name}: read_known differs");
    // The web page's route, the file's bytes, gives it too; a header whose
    // data are in another file is refused there.
    let bytes = std::fs::read(real_data(name)).unwrap();
    match LoadedVolume::read_known_bytes(name, &bytes, &INDEX) {
        Ok(Some((v, notes))) => {
            assert_eq!(v, l.volume, "{name}: read_known_bytes differs");
            assert_eq!(notes, l.notes, "{name}: read_known_bytes' notes differ");
        }
        Err(e) if name.ends_with(".nhdr") || name.ends_with(".hdr") => {
            let e = format!("{e:#}");
            assert!(e.contains("file"), "{name}: {e}");
        }
        r => panic!("{name}: read_known_bytes gives {:?}", r.map(|o| o.map(|(v, _)| v.dims))),
    }
    l
}

fn at(v: &LoadedVolume, x: usize, y: usize, z: usize) -> f64 {
    let Dims(nx, ny, nz) = v.dims;
    assert!(x < nx && y < ny && z < nz);
    let i = x + nx * (y + ny * z);
    match &v.samples {
        Samples::U8(s) => f64::from(s[i]),
        Samples::U16(s) => f64::from(s[i]),
        Samples::I16(s) => f64::from(s[i]),
        Samples::F32(s) => f64::from(s[i]),
    }
}

fn values(v: &LoadedVolume) -> Vec<f64> {
    match &v.samples {
        Samples::U8(s) => s.iter().map(|&x| f64::from(x)).collect(),
        Samples::U16(s) => s.iter().map(|&x| f64::from(x)).collect(),
        Samples::I16(s) => s.iter().map(|&x| f64::from(x)).collect(),
        Samples::F32(s) => s.iter().map(|&x| f64::from(x)).collect(),
    }
}

/// Minimum, maximum, their first positions (x, y, z), and the sum.
struct Summary {
    min: f64,
    max: f64,
    argmin: (usize, usize, usize),
    argmax: (usize, usize, usize),
    sum: f64,
}

fn summary(v: &LoadedVolume) -> Summary {
    let vals = values(v);
    let Dims(nx, ny, _) = v.dims;
    let pos = |i: usize| (i % nx, (i / nx) % ny, i / (nx * ny));
    // The first index in x-slowest order (numpy's argmax over [x, y, z]).
    let key = |i: usize| {
        let (x, y, z) = pos(i);
        (x, y, z)
    };
    let mut imin = 0;
    let mut imax = 0;
    for (i, &x) in vals.iter().enumerate() {
        if x < vals[imin] || (x == vals[imin] && key(i) < key(imin)) {
            imin = i;
        }
        if x > vals[imax] || (x == vals[imax] && key(i) < key(imax)) {
            imax = i;
        }
    }
    Summary { min: vals[imin], max: vals[imax], argmin: pos(imin), argmax: pos(imax), sum: vals.iter().sum() }
}

fn count_above(v: &LoadedVolume, level: f64) -> usize {
    values(v).into_iter().filter(|&x| x > level).count()
}

fn close(a: f64, b: f64, rel: f64) -> bool {
    (a - b).abs() <= rel * b.abs().max(1e-30)
}

fn assert_spacing(v: &LoadedVolume, want: [f64; 3]) {
    for i in 0..3 {
        assert!(close(f64::from(v.spacing[i]), want[i], 1e-6), "spacing {:?}, want {want:?}", v.spacing);
    }
}

#[test]
fn ccp4_1jzv_xray_density_is_transposed_by_its_axis_order() {
    let l = load("1jzv.ccp4");
    assert_eq!(l.format, Format::Mrc);
    let v = &l.volume;
    // MAPC, MAPR, MAPS = 2, 1, 3: 96 columns along y, 76 rows along x.
    assert_eq!(v.dims, Dims(76, 96, 70));
    assert!(matches!(v.samples, Samples::F32(_)));
    assert_spacing(v, [45.8 / 84.0, 45.8 / 84.0, 89.65 / 160.0]);
    assert_eq!(at(v, 0, 0, 0), f64::from(-0.083_348_93f32));
    assert_eq!(at(v, 1, 2, 3), f64::from(-0.081_816_13f32));
    assert_eq!(at(v, 10, 20, 30), f64::from(-0.315_487_24f32));
    assert_eq!(at(v, 75, 95, 69), f64::from(-0.093_887_86f32));
    let s = summary(v);
    assert_eq!((s.min, s.argmin), (f64::from(-0.993_094_2f32), (34, 69, 67)));
    assert_eq!((s.max, s.argmax), (f64::from(9.050_404f32), (29, 21, 10)));
    assert!(close(s.sum, -296.273_270_333_866_1, 1e-9), "{}", s.sum);
    assert_eq!(count_above(v, 1.0), 15_483);
    assert!(l.notes.iter().any(|n| n.contains("MAPC, MAPR, MAPS = 2, 1, 3")), "{:?}", l.notes);
}

#[test]
fn mrc_ispg_0_cryo_em_map() {
    let l = load("ispg_0.mrc");
    assert_eq!(l.format, Format::Mrc);
    let v = &l.volume;
    assert_eq!(v.dims, Dims(97, 97, 97));
    assert_spacing(v, [3.0; 3]);
    assert_eq!(at(v, 0, 0, 0), f64::from(-0.000_103_806_77f32));
    assert_eq!(at(v, 1, 2, 3), f64::from(-3.113_233_6e-6f32));
    assert_eq!(at(v, 10, 20, 30), f64::from(-2.161_054e-5f32));
    assert_eq!(at(v, 96, 96, 96), f64::from(2.477_246_9e-6f32));
    let s = summary(v);
    assert_eq!((s.min, s.argmin), (f64::from(-0.708_783_45f32), (53, 39, 44)));
    assert_eq!((s.max, s.argmax), (f64::from(2.163_535f32), (42, 56, 40)));
    assert!(close(s.sum, 829.925_229_480_894_5, 1e-9), "{}", s.sum);
    assert_eq!(count_above(v, 1.0), 1_039);
    assert!(l.notes.is_empty(), "{:?}", l.notes);
}

#[test]
fn cube_n2o_homo_and_lumo_are_transposed_to_x_fastest() {
    // (orbital, value at (0,0,0), (1,2,3), (0,0,1), (18,18,30), extreme, argmax, argmin, above 0.05)
    let cases = [
        (
            0,
            "11",
            [1.415_69e-4, 1.888_83e-3, 2.312_51e-4, 4.056_24e-5],
            0.574_763,
            (10, 9, 21),
            (8, 9, 21),
            515,
        ),
        (
            1,
            "12",
            [-3.888_36e-4, -4.943_42e-3, -6.280_73e-4, 2.838_94e-5],
            0.390_976,
            (8, 9, 15),
            (10, 9, 15),
            596,
        ),
    ];
    for (index, orbital, pts, extreme, argmax, argmin, above) in cases {
        let l = load_index("N2O_homo+lumo.cube.gz", index);
        assert_eq!(l.format, Format::Cube);
        let v = &l.volume;
        assert_eq!(v.dims, Dims(19, 19, 31));
        assert_spacing(v, [0.377_945; 3]);
        for (p, want) in [(0, 0, 0), (1, 2, 3), (0, 0, 1), (18, 18, 30)].into_iter().zip(pts) {
            assert!(
                close(at(v, p.0, p.1, p.2), want, 1e-6),
                "orbital {orbital} at {p:?}: {}",
                at(v, p.0, p.1, p.2)
            );
        }
        let s = summary(v);
        assert!(close(s.max, extreme, 1e-6) && close(s.min, -extreme, 1e-6), "{} {}", s.min, s.max);
        assert_eq!((s.argmax, s.argmin), (argmax, argmin), "orbital {orbital}");
        assert!(s.sum.abs() < 1e-9, "the orbitals are antisymmetric: sum {}", s.sum);
        assert_eq!(count_above(v, 0.05), above);
        assert!(
            l.notes.iter().any(|n| n.contains(&format!("orbitals 11, 12; loaded orbital {orbital}"))),
            "{:?}",
            l.notes
        );
        assert!(l.notes.iter().any(|n| n.contains("Bohr")));
    }
    let e = formats::read(&real_data("N2O_homo+lumo.cube.gz"), &Options { index: 2, ..Options::default() })
        .unwrap_err();
    assert!(format!("{e:#}").contains("2 value(s) per point; value 2 was asked for"), "{e:#}");
}

#[test]
fn nifti_big_endian_int16_anatomical() {
    let l = load("anatomical.nii");
    assert_eq!(l.format, Format::Nifti);
    let v = &l.volume;
    assert_eq!(v.dims, Dims(33, 41, 25));
    assert!(matches!(v.samples, Samples::I16(_)));
    assert_spacing(v, [2.0; 3]);
    assert_eq!(
        [at(v, 0, 0, 0), at(v, 1, 2, 3), at(v, 16, 20, 12), at(v, 32, 40, 24)],
        [10712.0, 9798.0, 11881.0, 2971.0]
    );
    let s = summary(v);
    assert_eq!((s.min, s.argmin, s.max, s.argmax), (-610.0, (24, 32, 14), 30393.0, (17, 23, 0)));
    assert_eq!(s.sum, 284_166_082.0);
}

#[test]
fn nifti_big_endian_float32() {
    let v = load("reoriented_anat_moved.nii").volume;
    assert_eq!(v.dims, Dims(21, 26, 22));
    assert!(matches!(v.samples, Samples::F32(_)));
    assert_spacing(&v, [4.0; 3]);
    assert_eq!(at(&v, 10, 13, 11), f64::from(8117.22f32));
    let s = summary(&v);
    assert_eq!((s.min, s.max, s.argmax), (0.0, f64::from(21199.936f32), (12, 15, 4)));
    assert!(close(s.sum, 32_739_769.449_157_715, 1e-9), "{}", s.sum);
}

#[test]
fn nifti_gzip_uint8_with_anisotropic_spacing() {
    let v = load("standard.nii.gz").volume;
    assert_eq!(v.dims, Dims(4, 5, 7));
    assert!(matches!(v.samples, Samples::U8(_)));
    assert_spacing(&v, [1.0, 3.0, 2.0]);
    assert_eq!(
        [at(&v, 0, 0, 0), at(&v, 1, 2, 3), at(&v, 2, 2, 3), at(&v, 3, 4, 6)],
        [0.0, 255.0, 0.0, 255.0]
    );
    let s = summary(&v);
    assert_eq!((s.min, s.max, s.argmax, s.sum), (0.0, 255.0, (0, 0, 1), 7650.0));
}

#[test]
fn nifti_4d_gives_each_time_point() {
    for (index, centre, max, sum) in [(0, 265.0, 1162.0, 50_994_397.0), (1, 266.0, 1140.0, 50_990_959.0)] {
        let l = load_index("example4d.nii.gz", index);
        let v = &l.volume;
        assert_eq!(v.dims, Dims(128, 96, 24));
        assert!(matches!(v.samples, Samples::I16(_)));
        assert_spacing(v, [2.0, 2.0, 2.199_999_094]);
        assert_eq!(at(v, 64, 48, 12), centre);
        let s = summary(v);
        assert_eq!((s.min, s.max, s.sum), (0.0, max, sum), "time point {index}");
        assert!(
            l.notes.iter().any(|n| n.contains(&format!("2 volumes (128x96x24x2); loaded volume {index}"))),
            "{:?}",
            l.notes
        );
    }
    assert_eq!(summary(&load("example4d.nii.gz").volume).argmax, (64, 49, 0));
    let e = formats::read(&real_data("example4d.nii.gz"), &Options { index: 2, ..Options::default() })
        .unwrap_err();
    assert!(format!("{e:#}").contains("holds 2 volume(s) of 128x96x24; volume 2 was asked for"), "{e:#}");
}

#[test]
fn nifti_itk_mri_head() {
    let v = load("KmeansTest_T1UCharRaw.nii.gz").volume;
    assert_eq!(v.dims, Dims(128, 128, 62));
    assert!(matches!(v.samples, Samples::I16(_)));
    assert_spacing(&v, [2.0, 2.0, 3.0]);
    assert_eq!(at(&v, 64, 64, 31), 97.0);
    let s = summary(&v);
    assert_eq!((s.min, s.max, s.argmax, s.sum), (0.0, 255.0, (30, 44, 47), 19_533_798.0));
}

#[test]
fn nrrd_detached_header_slice() {
    let l = load("BrainProtonDensitySliceBorder20.nhdr");
    assert_eq!(l.format, Format::Nrrd);
    let v = &l.volume;
    assert_eq!(v.dims, Dims(221, 257, 1));
    assert!(matches!(v.samples, Samples::U8(_)));
    assert_spacing(v, [1.0; 3]);
    assert_eq!(
        [at(v, 0, 0, 0), at(v, 1, 2, 0), at(v, 100, 100, 0), at(v, 220, 256, 0)],
        [1.0, 1.0, 171.0, 1.0]
    );
    let s = summary(v);
    assert_eq!((s.min, s.max, s.argmax, s.sum), (1.0, 249.0, (98, 136, 0), 4_861_905.0));
    assert_eq!(count_above(v, 40.0), 27_091);
}

/// Teem's own gzip, big-endian int16 NRRD of the MRI head holds exactly
/// the samples of the VolPack file it was made from.
#[test]
fn nrrd_gzip_big_endian_from_teem_matches_the_den() {
    let l = load("brainsmall_gz.nrrd");
    let v = &l.volume;
    assert_eq!(v.dims, Dims(128, 128, 84));
    assert_spacing(v, [1.0, 1.0, 1.5]);
    let Samples::I16(s) = &v.samples else { panic!("not int16") };
    let den = LoadedVolume::read_known(&real_data("brainsmall.den")).unwrap().unwrap();
    let Samples::U8(d) = &den.samples else { panic!() };
    assert!(s.iter().zip(d).all(|(&a, &b)| a == i16::from(b)) && s.len() == d.len());
    assert_eq!(at(v, 64, 64, 42), 65.0);
    let sm = summary(v);
    assert_eq!((sm.min, sm.max, sm.argmax, sm.sum), (0.0, 202.0, (70, 74, 29), 19_284_185.0));
    assert_eq!(count_above(v, 40.0), 211_180);
}

/// By default each file is laid out as its header says it lies in space:
/// the index-order volume rearranged (`x = -i` and so on, as each header
/// says; nibabel's `aff2axcodes` agrees: anatomical.nii is LAS,
/// reoriented_anat_moved.nii and standard.nii.gz RAS, example4d.nii.gz LAS
/// (oblique, 9° about x), KmeansTest_T1UCharRaw.nii.gz LSA by its sform,
/// brainsmall_gz.nrrd RAS), with a note; files whose headers say nothing
/// of it, flat ones and those already laid out so are as stored. The
/// command line's and web page's routes do the same.
#[test]
fn headers_orient_the_real_files() {
    // x = -i (left), y = k (superior), z = j (anterior), from RAS.
    let ras =
        (AxisMap::new([0, 2, 1], [true, false, false]), "x = -i (left), y = k (superior), z = j (anterior)");
    let las = (AxisMap::new([0, 2, 1], [false; 3]), "x = i (left), y = k (superior), z = j (anterior)");
    for (name, want, by) in [
        ("anatomical.nii", Some(las), "sform"),
        ("reoriented_anat_moved.nii", Some(ras), "sform"),
        ("standard.nii.gz", Some(ras), "sform"),
        ("example4d.nii.gz", Some(las), "sform"),
        ("brainsmall_gz.nrrd", Some(ras), "space directions"),
        ("KmeansTest_T1UCharRaw.nii.gz", None, ""),
        ("BrainProtonDensitySliceBorder20.nhdr", None, ""),
        ("N2O_homo+lumo.cube.gz", None, ""),
        ("1jzv.ccp4", None, ""),
        ("uniform.vtk", None, ""),
    ] {
        let index = load(name);
        let path = real_data(name);
        let file = formats::read(&path, &Options::default()).unwrap().unwrap();
        let (known, notes) = LoadedVolume::read_known_with(&path, &Options::default()).unwrap().unwrap();
        assert_eq!((&known, &notes), (&file.volume, &file.notes), "{name}: read_known_with differs");
        match want {
            None => assert_eq!((&file.volume, &file.notes), (&index.volume, &index.notes), "{name}"),
            Some((map, text)) => {
                let moved = index.volume.clone().reoriented(map.unwrap());
                assert_eq!((file.volume.dims, &file.volume.samples), (moved.dims, &moved.samples), "{name}");
                for (a, b) in file.volume.spacing.iter().zip(moved.spacing) {
                    assert!(close(f64::from(*a), f64::from(b), 1e-5), "{name}: {:?}", file.volume.spacing);
                }
                let note =
                    format!("oriented by the {by}: {text} (--orientation index keeps the file's order)");
                assert_eq!(file.notes.last(), Some(&note), "{name}");
            }
        }
    }
}

/// pyvista's example: double samples x * y * z on a 10^3 grid, after cell
/// data with a FIELD array that the reader must skip.
#[test]
fn vtk_binary_structured_points() {
    let l = load("uniform.vtk");
    assert_eq!(l.format, Format::Vtk);
    let v = &l.volume;
    assert_eq!(v.dims, Dims(10, 10, 10));
    assert_spacing(v, [1.0; 3]);
    for z in 0..10 {
        for y in 0..10 {
            for x in 0..10 {
                assert_eq!(at(v, x, y, z), (x * y * z) as f64);
            }
        }
    }
    assert_eq!(summary(v).sum, 91_125.0);
    assert_eq!(count_above(v, 500.0), 17);
    assert!(l.notes.iter().any(|n| n.contains("float64")), "{:?}", l.notes);
    assert!(l.notes.iter().any(|n| n.contains("`Spatial Point Data`")), "{:?}", l.notes);
}

/// A scratch folder, removed when dropped.
struct Scratch(PathBuf);

impl Scratch {
    fn new(name: &str) -> Self {
        let d = std::env::temp_dir().join(format!("isoscope-formats-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        Scratch(d)
    }

    /// Write a copy of real file `name`, changed by `f`, under the same name.
    fn copy(&self, name: &str, f: impl FnOnce(&mut Vec<u8>)) -> PathBuf {
        let mut b = std::fs::read(real_data(name)).unwrap();
        f(&mut b);
        let p = self.0.join(name);
        std::fs::write(&p, b).unwrap();
        p
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// The error `read_known` (the command line's route) gives, checked to
/// name the file and to say each of `what`.
fn error(path: &Path, what: &[&str]) {
    let e = match LoadedVolume::read_known(path) {
        Err(e) => format!("{e:#}"),
        Ok(v) => panic!("{} loaded: {:?}", path.display(), v.map(|v| v.dims)),
    };
    assert!(e.contains(&path.display().to_string()), "the error does not name the file: {e}");
    for w in what {
        assert!(e.contains(w), "`{w}` not in: {e}");
    }
}

fn set_word(b: &mut [u8], i: usize, v: i32) {
    b[4 * i..4 * i + 4].copy_from_slice(&v.to_le_bytes());
}

#[test]
fn broken_mrc_files_are_clear_errors() {
    let s = Scratch::new("mrc");
    let name = "1jzv.ccp4";
    error(
        &s.copy(name, |b| b.truncate(b.len() - 1)),
        &["cannot load", "as MRC/CCP4", "96x76x70", "(truncated?)"],
    );
    error(
        &s.copy(name, |b| b.truncate(500)),
        &["truncated: an MRC/CCP4 header is 1024 bytes, the file has 500"],
    );
    error(&s.copy(name, |b| b.truncate(1200)), &["extended header of 640 bytes"]);
    error(
        &s.copy(name, |b| b.extend_from_slice(&[0; 8])),
        &["2042880 bytes of data expected, and 8 more follow"],
    );
    error(&s.copy(name, |b| set_word(b, 3, 3)), &["mode 3 (complex samples) is not supported"]);
    error(&s.copy(name, |b| set_word(b, 16, 1)), &["MAPC, MAPR, MAPS = 1, 1, 3 is not a permutation"]);
    error(&s.copy(name, |b| set_word(b, 1, 77)), &["96x77x70", "need 2069760 bytes"]);
    error(&s.copy(name, |b| b[..12].fill(0xff)), &["not an MRC/CCP4 map"]);
    error(&s.copy("ispg_0.mrc", |b| set_word(b, 3, 9)), &["not an MRC/CCP4 map"]);
}

#[test]
fn broken_nifti_files_are_clear_errors() {
    let s = Scratch::new("nifti");
    let name = "anatomical.nii";
    error(&s.copy(name, |b| b.truncate(b.len() - 2)), &["as NIfTI-1", "33x41x25 of int16", "(truncated?)"]);
    error(&s.copy(name, |b| b.truncate(100)), &["a NIfTI-1 header is 348 bytes, the file has 100"]);
    // dim[1] 33 -> 34 (big-endian): the extents no longer match the size.
    error(&s.copy(name, |b| b[43] = 34), &["34x41x25", "truncated?"]);
    error(
        &s.copy(name, |b| b[70..72].copy_from_slice(&128i16.to_be_bytes())),
        &["Rgb24 (datatype 128) is not supported"],
    );
    error(
        &s.copy(name, |b| b[70..72].copy_from_slice(&99i16.to_be_bytes())),
        &["datatype 99 is not a NIfTI-1 data type"],
    );
    error(&s.copy(name, |b| b[0..4].copy_from_slice(&540i32.to_be_bytes())), &["NIfTI-2"]);
    error(&s.copy(name, |b| b[..4].fill(0)), &["not a NIfTI-1 file"]);
    // A gzip stream cut short.
    error(
        &s.copy("example4d.nii.gz", |b| b.truncate(b.len() / 2)),
        &["cannot gunzip", "corrupt or cut short"],
    );
    error(
        &s.copy("standard.nii.gz", |b| {
            let n = b.len();
            b[n - 6] ^= 0x55
        }),
        &["cannot gunzip"],
    );
}

#[test]
fn broken_nrrd_files_are_clear_errors() {
    let s = Scratch::new("nrrd");
    let name = "brainsmall_gz.nrrd";
    error(
        &s.copy(name, |b| b.truncate(b.len() - 1000)),
        &["as NRRD", "of gzip-encoded data: cannot gunzip: the gzip data are corrupt or cut short"],
    );
    let edit = |from: &'static str, to: &'static str| {
        move |b: &mut Vec<u8>| {
            let at = b.windows(from.len()).position(|w| w == from.as_bytes()).unwrap();
            b.splice(at..at + from.len(), to.bytes());
        }
    };
    error(
        &s.copy(name, edit("sizes: 128 128 84", "sizes: 128 128 85")),
        &["128x128x85 int16 samples need 2785280 bytes", "the data stop after 2752512 of 2785280 bytes"],
    );
    error(
        &s.copy(name, edit("sizes: 128 128 84", "sizes: 128 128 83")),
        &["2719744 bytes of data expected, more follow"],
    );
    error(&s.copy(name, edit("type: short", "type: quad")), &["`quad` is not a NRRD type"]);
    error(&s.copy(name, edit("encoding: gzip", "encoding: bz2")), &["bzip2-encoded data are not supported"]);
    error(&s.copy(name, edit("endian: big\n", "")), &["no `endian:` field, which int16 data need"]);
    // A detached header whose data file is cut short, or missing.
    let hdr = s.copy("BrainProtonDensitySliceBorder20.nhdr", |_| {});
    s.copy("BrainProtonDensitySliceBorder20.raw", |b| b.truncate(1000));
    error(&hdr, &["221x257x1 uint8 samples need 56797 bytes: the data stop after 1000 of 56797 bytes"]);
    std::fs::remove_file(s.0.join("BrainProtonDensitySliceBorder20.raw")).unwrap();
    error(&hdr, &["cannot read the header's data file", "BrainProtonDensitySliceBorder20.raw"]);
}

#[test]
fn broken_cube_and_vtk_files_are_clear_errors() {
    let s = Scratch::new("cube-vtk");
    error(
        &s.copy("N2O_homo+lumo.cube.gz", |b| b.truncate(b.len() - 100)),
        &["as Gaussian cube", "cut short"],
    );
    let name = "uniform.vtk";
    error(
        &s.copy(name, |b| b.truncate(b.len() - 9)),
        &["as VTK legacy", "truncated in SCALARS `Spatial Point Data`", "8000 bytes"],
    );
    error(&s.copy(name, |b| b.truncate(140)), &["truncated"]);
    let edit = |from: &'static str, to: &'static str| {
        move |b: &mut Vec<u8>| {
            let at = b.windows(from.len()).position(|w| w == from.as_bytes()).unwrap();
            b.splice(at..at + from.len(), to.bytes());
        }
    };
    error(
        &s.copy(name, edit("DIMENSIONS 10 10 10", "DIMENSIONS 10 10 11")),
        &["POINT_DATA 1000 does not match DIMENSIONS 10 10 11"],
    );
    error(
        &s.copy(name, edit("STRUCTURED_POINTS", "STRUCTURED_GRID")),
        &["STRUCTURED_GRID, which is not supported"],
    );
    error(&s.copy(name, edit("Data double", "Data quad")), &["`quad` is not a VTK numeric type"]);
}

/// Every prefix of each real file, and each file with a header byte
/// overwritten, is an error or a volume: never a panic.
#[test]
fn cut_and_corrupted_real_files_never_panic() {
    let nhdr_dir = real_data("BrainProtonDensitySliceBorder20.raw").parent().unwrap().to_path_buf();
    type Parse<'a> = &'a dyn Fn(&[u8]);
    let parsers: [(&str, usize, Parse); 5] = [
        ("1jzv.ccp4", 1024, &|b| drop(formats::mrc::parse(b, &Options::default()))),
        ("anatomical.nii", 352, &|b| drop(formats::nifti::parse(b, &Options::default()))),
        ("brainsmall_gz.nrrd", 300, &|b| drop(formats::nrrd::parse(b, None, &Options::default()))),
        ("BrainProtonDensitySliceBorder20.nhdr", 301, &|b| {
            drop(formats::nrrd::parse(b, Some(&nhdr_dir), &Options::default()))
        }),
        ("uniform.vtk", 200, &|b| drop(formats::vtk::parse(b, &Options::default()))),
    ];
    for (name, header, parse) in parsers {
        let bytes = std::fs::read(real_data(name)).unwrap();
        let n = bytes.len();
        let header = header.min(n);
        // Prefixes: through the header byte by byte, then on to the end.
        for cut in
            (0..header).step_by(2).chain((0..16).map(|k| header + k * (n - header) / 16)).chain(n - 8..n)
        {
            parse(&bytes[..cut]);
        }
        // Header bytes overwritten, the data cut to a sixteenth so that a
        // header that still reads well fails fast on the length.
        let short = &bytes[..header + (n - header) / 16];
        for at in 0..header {
            for v in [0u8, 0xff, b'9'] {
                let mut b = short.to_vec();
                b[at] = v;
                parse(&b);
            }
        }
    }
    // The gzip files through the file route.
    let s = Scratch::new("fuzz");
    for name in ["standard.nii.gz", "N2O_homo+lumo.cube.gz"] {
        let bytes = std::fs::read(real_data(name)).unwrap();
        let path = s.0.join(name);
        for cut in (0..16).map(|k| k * bytes.len() / 16) {
            std::fs::write(&path, &bytes[..cut]).unwrap();
            assert!(LoadedVolume::read_known(&path).is_err(), "{name} cut at {cut}");
        }
    }
}

/// Every reader checks `max_bytes` from its header before reading the
/// samples: each real file is refused with a limit one byte short of what
/// its volume takes (in the file's type or as loaded, whichever is more),
/// and loads at exactly that. A 4D NIfTI larger than the limit gives each
/// of its volumes, reading no further than the one taken.
#[test]
fn every_format_refuses_a_volume_over_the_limit() {
    for (name, bytes) in [
        ("1jzv.ccp4", 76 * 96 * 70 * 4),
        ("ispg_0.mrc", 97 * 97 * 97 * 4),
        ("N2O_homo+lumo.cube.gz", 19 * 19 * 31 * 4),
        ("anatomical.nii", 33 * 41 * 25 * 2),
        ("reoriented_anat_moved.nii", 21 * 26 * 22 * 4),
        ("standard.nii.gz", 4 * 5 * 7),
        ("example4d.nii.gz", 128 * 96 * 24 * 2),
        ("brainsmall_gz.nrrd", 128 * 128 * 84 * 2),
        ("BrainProtonDensitySliceBorder20.nhdr", 221 * 257),
        ("uniform.vtk", 10 * 10 * 10 * 8),
    ] {
        let path = real_data(name);
        let opts = |index, max_bytes| Options { index, max_bytes, ..INDEX };
        let e = format!("{:#}", formats::read(&path, &opts(0, bytes - 1)).unwrap_err());
        assert!(
            e.contains(&path.display().to_string())
                && e.contains(&format!("samples take {bytes} bytes"))
                && e.contains(&format!("more than the limit of {}", bytes - 1))
                && e.contains("--max-volume-mb raises it"),
            "{name}: {e}"
        );
        let l = formats::read(&path, &opts(0, bytes)).unwrap_or_else(|e| panic!("{name}: {e:#}")).unwrap();
        assert_eq!(l.volume, load(name).volume, "{name}");
    }
    let second =
        formats::read(&real_data("example4d.nii.gz"), &Options { index: 1, max_bytes: 589_824, ..INDEX });
    assert_eq!(second.unwrap().unwrap().volume, load_index("example4d.nii.gz", 1).volume);
}
