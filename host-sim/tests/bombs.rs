//! Decompression and size bombs, and streams without end: every volume
//! reader takes the header, then exactly the bytes it declares (inflating
//! gzip as it reads), so a small file that inflates to gigabytes, a header
//! asking for more than `--max-volume-mb`, or a data file that is
//! `/dev/zero` fails at once with a plain error.
//!
//! The binary runs under `ulimit -v` (address space, [`MEMORY_KB`]): a
//! reader that held a whole inflated stream, or read `/dev/zero` to its
//! end, could not allocate, and would not give the error these tests ask
//! for. A reader that read a stream without end and kept nothing would
//! never finish: the binary is stopped after [`HANG_SECONDS`] (a hang
//! guard, not a speed limit: the tests ask for an answer, not a time).

mod common;
use common::real_data;
use flate2::Compression;
use flate2::write::GzEncoder;
use std::io::Write;
use std::path::PathBuf;
use std::process::{Command, Output};

/// Address space the binary may take, in KiB: its own needs and a few
/// buffers, not a volume of the bombs.
const MEMORY_KB: u32 = 200_000;
/// Seconds after which the binary is stopped as hung (`timeout`'s exit
/// status 124): far past what any of these takes on a loaded machine (a
/// debug build refuses a bomb in well under a second, and summarises the
/// 96 MB file in a few), so a slow machine does not fail them.
const HANG_SECONDS: u32 = 600;

/// Run `isoscope-sim` with `args` under [`MEMORY_KB`] and the hang guard.
fn run_limited(args: &[&str]) -> Output {
    let out = Command::new("sh")
        .arg("-c")
        .arg(format!("ulimit -v {MEMORY_KB} && exec timeout {HANG_SECONDS} \"$0\" \"$@\""))
        .arg(env!("CARGO_BIN_EXE_isoscope-sim"))
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("cannot run isoscope-sim {args:?}: {e}"));
    assert_ne!(out.status.code(), Some(124), "isoscope-sim {args:?} did not finish in {HANG_SECONDS} s");
    out
}

/// Run `info` on `args` and expect a failure whose error names
/// every one of `causes`.
fn refused(args: &[&str], causes: &[&str]) {
    let mut all = vec!["info"];
    all.extend_from_slice(args);
    let out = run_limited(&all);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "isoscope-sim {all:?}: {}\n{stderr}", out.status);
    assert!(stderr.starts_with("isoscope-sim: error: "), "isoscope-sim {all:?}: {stderr}");
    for cause in causes {
        assert!(stderr.contains(cause), "isoscope-sim {all:?}: `{cause}` not in: {stderr}");
    }
}

/// Run `info` on `args` and expect a success; its report.
fn loaded(args: &[&str]) -> String {
    let mut all = vec!["info"];
    all.extend_from_slice(args);
    let out = run_limited(&all);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "isoscope-sim {all:?}: {}\n{stderr}", out.status);
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// A scratch folder, removed when dropped.
struct Scratch(PathBuf);

impl Scratch {
    fn new(name: &str) -> Self {
        let d = std::env::temp_dir().join(format!("isoscope-bombs-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        Scratch(d)
    }

    fn path(&self, name: &str) -> PathBuf {
        self.0.join(name)
    }

    /// Write `bytes` as `name`; its path as a string.
    fn file(&self, name: &str, bytes: &[u8]) -> String {
        let p = self.path(name);
        std::fs::write(&p, bytes).unwrap();
        p.to_str().unwrap().to_owned()
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn gzip(bytes: &[u8]) -> Vec<u8> {
    let mut z = GzEncoder::new(Vec::new(), Compression::best());
    z.write_all(bytes).unwrap();
    z.finish().unwrap()
}

/// Bytes of zeros a bomb inflates to: 2 GiB.
const BOMB: usize = 2 << 30;

/// A gzip file of `head`, then 2 GiB of zeros (about 2 MB): gzip members
/// of 8 MiB of zeros one after another, as gzip allows.
fn bomb(head: &[u8]) -> Vec<u8> {
    bomb_of(head, 0)
}

/// A gzip file of `head`, then 2 GiB of bytes `fill`.
fn bomb_of(head: &[u8], fill: u8) -> Vec<u8> {
    const MEMBER: usize = 8 << 20;
    let zeros = gzip(&vec![fill; MEMBER]);
    let mut f = gzip(head);
    for _ in 0..BOMB / MEMBER {
        f.extend_from_slice(&zeros);
    }
    assert!(f.len() < 4 << 20, "{} bytes", f.len());
    f
}

/// A NIfTI-1 header (352 bytes with the extension flag): `dims` of
/// `datatype`/`bitpix`, little-endian, data at byte 352; `magic` n+1 or
/// ni1 (a .hdr, data at byte 0 of its .img).
fn nifti(dims: &[i16], datatype: i16, bitpix: i16, magic: &[u8; 4]) -> Vec<u8> {
    let mut h = vec![0u8; 352];
    let mut put = |at: usize, b: &[u8]| h[at..at + b.len()].copy_from_slice(b);
    put(0, &348i32.to_le_bytes());
    put(40, &(dims.len() as i16).to_le_bytes());
    for (i, d) in dims.iter().enumerate() {
        put(42 + 2 * i, &d.to_le_bytes());
    }
    put(70, &datatype.to_le_bytes());
    put(72, &bitpix.to_le_bytes());
    for i in 0..4 {
        put(76 + 4 * i, &1f32.to_le_bytes());
    }
    let offset: f32 = if magic == b"ni1\0" { 0.0 } else { 352.0 };
    put(108, &offset.to_le_bytes());
    put(344, magic);
    h
}

/// An MRC header (mode 0, int8): `n` columns, rows, sections.
fn mrc(n: [i32; 3]) -> Vec<u8> {
    let mut h = vec![0u8; 1024];
    let mut put = |i: usize, v: [u8; 4]| h[4 * i..4 * i + 4].copy_from_slice(&v);
    for (i, &n) in n.iter().enumerate() {
        put(i, n.to_le_bytes());
        put(7 + i, n.to_le_bytes());
        put(10 + i, (n as f32).to_le_bytes());
        put(16 + i, (i as i32 + 1).to_le_bytes());
    }
    put(52, *b"MAP ");
    put(53, [0x44, 0x44, 0, 0]);
    h
}

const CUBE: &str = "title\ncomment\n    1 0.0 0.0 0.0\n    2 1.0 0.0 0.0\n    2 0.0 1.0 0.0\n\
                    2 0.0 0.0 1.0\n    1 1.0 0.0 0.0 0.0\n 1 2 3 4 5 6\n 7 8\n";

fn vtk(dims: [usize; 3]) -> String {
    format!(
        "# vtk DataFile Version 3.0\nbomb\nBINARY\nDATASET STRUCTURED_POINTS\nDIMENSIONS {} {} {}\n\
         POINT_DATA {}\nSCALARS s unsigned_char\nLOOKUP_TABLE default\n",
        dims[0],
        dims[1],
        dims[2],
        dims[0] * dims[1] * dims[2]
    )
}

#[test]
fn a_nifti_gzip_bomb_is_refused_after_its_volume() {
    let s = Scratch::new("nifti");
    let mut head = nifti(&[2, 2, 2], 2, 8, b"n+1\0");
    head.extend_from_slice(&[7; 8]);
    let path = s.file("bomb.nii.gz", &bomb(&head));
    refused(&[&path], &[&path, "as NIfTI-1", "2x2x2 of uint8", "8 bytes of data expected, more follow"]);
}

#[test]
fn an_mrc_gzip_bomb_is_refused_after_its_volume() {
    let s = Scratch::new("mrc");
    let mut head = mrc([2, 2, 2]);
    head.extend_from_slice(&[7; 8]);
    let path = s.file("bomb.mrc.gz", &bomb(&head));
    refused(&[&path], &[&path, "as MRC/CCP4", "8 bytes of data expected, more follow"]);
}

/// A cube file's values are text: after the 8 it declares, the reader
/// reads no more than a little text (2 GiB of blanks follow here), nor a
/// value longer than a number (2 GiB of NUL bytes).
#[test]
fn a_cube_gzip_bomb_ends_after_its_text() {
    let s = Scratch::new("cube");
    let path = s.file("bomb.cube.gz", &bomb_of(CUBE.as_bytes(), b' '));
    refused(&[&path], &[&path, "as Gaussian cube", "text runs on for more than", "more than 8 values take"]);
    let path = s.file("zeros.cube.gz", &bomb(CUBE.as_bytes()));
    refused(&[&path], &[&path, "a value of more than 256 characters in line 10: not text data"]);
    // The same values and nothing more load.
    let good = s.file("good.cube.gz", &gzip(CUBE.as_bytes()));
    assert!(loaded(&[&good]).contains("dims=2x2x2"));
}

/// A VTK file may hold more arrays after the one loaded: it is loaded
/// without reading on. A header asking for more than the limit is refused.
#[test]
fn a_vtk_gzip_bomb_is_not_read_past_its_volume_and_a_huge_one_is_refused() {
    let s = Scratch::new("vtk");
    let mut head = vtk([2, 2, 2]).into_bytes();
    head.extend_from_slice(&[7; 8]);
    let path = s.file("bomb.vtk.gz", &bomb(&head));
    assert!(loaded(&[&path]).contains("dims=2x2x2"));
    let path = s.file("huge.vtk.gz", &bomb(vtk([2048, 2048, 1024]).as_bytes()));
    refused(
        &[&path],
        &[
            &path,
            "as VTK legacy",
            "2048x2048x1024 uint8 samples take 4294967296 bytes (4096 MiB), more than the limit of 2048 MiB",
            "--max-volume-mb",
        ],
    );
}

/// NRRD declares its sizes, and gzip-encoded data inflate to exactly them:
/// a header asking for more than the limit is refused before inflating.
#[test]
fn a_nrrd_gzip_bomb_is_refused_by_its_sizes() {
    let s = Scratch::new("nrrd");
    let mut f = b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 1024 1024 4096\nencoding: gzip\n\n".to_vec();
    f.extend_from_slice(&bomb(&[]));
    let path = s.file("bomb.nrrd", &f);
    refused(
        &[&path],
        &[&path, "as NRRD", "take 4294967296 bytes (4096 MiB), more than the limit of 2048 MiB"],
    );
    // Sizes within the limit, and more data than they hold.
    let mut f = b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: gzip\n\n".to_vec();
    f.extend_from_slice(&bomb(&[]));
    let path = s.file("small.nrrd", &f);
    refused(&[&path], &[&path, "8 bytes of gzip-encoded data", "8 bytes of data expected, more follow"]);
}

#[test]
fn raw_dev_zero_stops_at_the_dims() {
    refused(
        &["/dev/zero", "--dims", "4x4x4", "--dtype", "u8"],
        &["/dev/zero", "64 bytes of data expected, more follow"],
    );
}

#[test]
#[cfg(unix)]
fn a_nifti_pair_whose_image_is_dev_zero_stops_at_the_header() {
    let s = Scratch::new("nifti-zero");
    let hdr = s.file("zero.hdr", &nifti(&[4, 4, 4], 2, 8, b"ni1\0"));
    std::os::unix::fs::symlink("/dev/zero", s.path("zero.img")).unwrap();
    refused(&[&hdr], &[&hdr, "in the image file", "zero.img", "64 bytes of data expected, more follow"]);
    // A .nii that is /dev/zero: its header is no header.
    let nii = s.path("zero.nii");
    std::os::unix::fs::symlink("/dev/zero", &nii).unwrap();
    refused(&[nii.to_str().unwrap()], &["zero.nii", "not a NIfTI-1 file: sizeof_hdr reads 0"]);
}

#[test]
fn a_detached_nrrd_on_dev_zero_stops_at_its_sizes() {
    let s = Scratch::new("nrrd-zero");
    let nhdr = s.file(
        "zero.nhdr",
        b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 4 4 4\nencoding: raw\ndata file: /dev/zero\n",
    );
    refused(
        &[&nhdr],
        &[&nhdr, "4x4x4 uint8 samples need 64 bytes", "64 bytes of data expected, more follow"],
    );
}

/// The limit is checked from the dims and type, before reading: 4 GiB of
/// f32 from /dev/zero is refused at once.
#[test]
fn a_volume_over_the_limit_is_refused_before_reading() {
    refused(
        &["/dev/zero", "--dims", "1024x1024x1024", "--dtype", "f32"],
        &["/dev/zero", "take 4294967296 bytes (4096 MiB), more than the limit of 2048 MiB (--max-volume-mb"],
    );
    refused(
        &["/dev/zero", "--dims", "1024x1024x1024", "--dtype", "u8", "--max-volume-mb", "1000"],
        &["take 1073741824 bytes (1024 MiB), more than the limit of 1000 MiB"],
    );
}

/// `--max-volume-mb` on every command that reads a volume: a real file
/// over it is refused, raising it lets the file through.
#[test]
fn max_volume_mb_refuses_and_admits_a_real_file() {
    // 128x128x84 int16: 2752512 bytes, 2.6 MiB.
    let path = real_data("brainsmall_gz.nrrd").to_string_lossy().into_owned();
    let over = ["the volume's 128x128x84 int16 samples take 2752512 bytes (2.6 MiB)", "limit of 2 MiB"];
    refused(&[&path, "--max-volume-mb", "2"], &[&[path.as_str()][..], &over[..]].concat());
    // Laid out as its `space: RAS` directions say: superior (k) up.
    assert!(loaded(&[&path, "--max-volume-mb", "3"]).contains("dims=128x84x128"));
    for cmd in [&["contour", "--format", "none", "--level", "60"][..], &["stats", "--level", "60"]] {
        let mut args = cmd.to_vec();
        args.extend_from_slice(&[&path, "--max-volume-mb", "2"]);
        let out = run_limited(&args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && stderr.contains(over[0]), "{args:?}: {stderr}");
    }
    // Raw files and .den files too.
    let den = real_data("brainsmall.den").to_string_lossy().into_owned();
    refused(
        &[&den, "--max-volume-mb", "1"],
        &[&den, "take 1376256 bytes (1.3 MiB), more than the limit of 1 MiB"],
    );
    assert!(loaded(&[&den, "--max-volume-mb", "2"]).contains("dims=128x128x84"));
    // Checked when parsed.
    let out = run_limited(&["info", &path, "--max-volume-mb", "0"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("`0` is out of range: give 1 to 16777216"), "{stderr}");
}

/// `info` on a volume near the limit works in the memory the volume takes:
/// its statistics read the samples in place (it copied them to `f32`
/// twice, 8 bytes a `u8` sample more). A 96 MB `u8` file runs in 200 MB;
/// a demo over `--max-volume-mb` is refused before it is made.
#[test]
fn info_summarises_in_place_and_demos_keep_to_the_limit() {
    let dir = Scratch::new("in-place");
    let raw = dir.path("big.raw");
    let f = std::fs::File::create(&raw).unwrap();
    f.set_len(512 * 512 * 384).unwrap();
    let report = loaded(&[raw.to_str().unwrap(), "--dims", "512x512x384", "--dtype", "u8"]);
    assert!(report.contains("samples=100663296\n") && report.contains("mean=0.000000\n"), "{report}");
    refused(
        &["--demo", "gyroid:300", "--max-volume-mb", "100"],
        &["the demo's 300^3 f32 samples take 103 MiB", "--max-volume-mb"],
    );
}
