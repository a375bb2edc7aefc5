//! Orientation from the file: the MNI152 head (fetched by
//! `scripts/fetch-data`) loads upright and facing the viewer, a small head
//! stored along permuted and reversed axes draws exactly as the same head
//! stored in RAS order (on the board too), and `--orientation index`
//! (on every command that loads a volume) keeps the file's order.

mod common;
use common::{Scratch, real_data};
use isoscope_sim::formats::{Options, Orientation};
use isoscope_sim::volume::{Dims, LoadedVolume, Samples};
use std::io::{BufRead, BufReader};
use std::process::{Command, Output, Stdio};

const MNI: &str = "mni_icbm152_t1_tal_nlin_sym_09a_converted.nii.gz";

fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_isoscope-sim")
}

fn run(args: &[&str]) -> Output {
    Command::new(bin())
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("cannot run isoscope-sim {args:?}: {e}"))
}

fn index_order() -> Options {
    Options { orientation: Orientation::Index, ..Options::default() }
}

/// The MNI152 (ICBM 2009a symmetric) T1 template, 197x233x189 u8 in RAS
/// order (sform code 2, 1 mm voxels), is shown with the person's left to
/// the right (x = -i), superior up (y = k) and anterior towards the viewer
/// (z = j): the brainstem leaves the box at the bottom, there is air above
/// the crown, and the brainstem and cerebellum lie behind the middle, the
/// face side towards the viewer.
#[test]
fn mni152_loads_upright_and_facing_the_viewer() {
    let path = real_data(MNI);
    let file = LoadedVolume::read_known(&path).unwrap().expect("a NIfTI file");
    let (index, notes) = LoadedVolume::read_known_with(&path, &index_order()).unwrap().unwrap();
    assert!(notes.is_empty(), "{notes:?}");
    assert_eq!(index.dims, Dims(197, 233, 189));
    assert_eq!(file.dims, Dims(197, 189, 233));
    assert_eq!((file.spacing, index.spacing), ([1.0; 3], [1.0; 3]));
    let (Samples::U8(f), Samples::U8(ix)) = (&file.samples, &index.samples) else {
        panic!("not u8: {:?}", std::mem::discriminant(&file.samples))
    };
    assert_eq!((f.iter().min(), f.iter().max()), (Some(&0), Some(&255)));
    // Known independently (Python, on the gunzipped file): the sum of all
    // samples, and how many exceed 50.
    assert_eq!(f.iter().map(|&v| u64::from(v)).sum::<u64>(), 333_468_829);
    assert_eq!(f.iter().filter(|&&v| v > 50).count(), 1_883_244);
    // Display (x, y, z) is file (196 - x, z, y), voxel for voxel.
    let (nx, ny, nz) = (197, 189, 233);
    let at = |v: &[u8], d: (usize, usize), x: usize, y: usize, z: usize| v[x + d.0 * (y + d.1 * z)];
    for z in (0..nz).step_by(7) {
        for y in (0..ny).step_by(5) {
            for x in (0..nx).step_by(3) {
                assert_eq!(at(f, (nx, ny), x, y, z), at(ix, (197, 233), 196 - x, z, y), "({x},{y},{z})");
            }
        }
    }
    // Tissue (> 50) per display slice along y, and its mean z there.
    let mut count = vec![0usize; ny];
    let mut sum_z = vec![0usize; ny];
    for z in 0..nz {
        for y in 0..ny {
            let row = &f[nx * (y + ny * z)..][..nx];
            let c = row.iter().filter(|&&v| v > 50).count();
            count[y] += c;
            sum_z[y] += c * z;
        }
    }
    let bottom: usize = count[..10].iter().sum();
    let top: usize = count[ny - 20..].iter().sum();
    assert!(bottom > 1000 && top == 0, "superior is not up: {bottom} voxels at the bottom, {top} at the top");
    let low = count[..20].iter().sum::<usize>();
    let low_z = sum_z[..20].iter().sum::<usize>() as f64 / low as f64;
    let centre = (nz - 1) as f64 / 2.0;
    assert!(
        low_z < centre - 15.0,
        "the brainstem is not behind the middle (the face not towards the viewer): mean z {low_z:.1}, centre {centre}"
    );
}

/// `info` says how the file was oriented, `--orientation index` keeps its
/// order, and a wrong value is a usage error.
#[test]
fn info_reports_the_orientation_and_the_flag_keeps_the_index_order() {
    let path = real_data(MNI).to_string_lossy().into_owned();
    let out = run(&["info", &path, "--bins", "4"]);
    let (stdout, stderr) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "{stderr}");
    assert!(stdout.contains("dims=197x189x233\n"), "{stdout}");
    assert!(
        stderr.contains(
            "oriented by the sform: x = -i (left), y = k (superior), z = j (anterior) (--orientation index keeps \
             the file's order)"
        ),
        "{stderr}"
    );
    let out = run(&["info", &path, "--bins", "4", "--orientation", "index"]);
    let (stdout, stderr) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success() && stdout.contains("dims=197x233x189\n"), "{stdout}{stderr}");
    assert!(!stderr.contains("oriented"), "{stderr}");
    let out = run(&["info", &path, "--orientation", "sideways"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("unknown orientation `sideways` (expected file or index)"), "{stderr}");
}

/// Every command that loads a volume takes the flag.
#[test]
fn every_command_that_loads_a_volume_takes_the_flag() {
    for cmd in ["info", "contour", "stats", "render", "wav", "send"] {
        let out = run(&[cmd, "--help"]);
        let help = String::from_utf8_lossy(&out.stdout);
        assert!(out.status.success() && help.contains("--orientation <file|index>"), "{cmd}: {help}");
    }
}

/// A little-endian NIfTI-1 file of u8 samples with an sform (code 1),
/// written field by field at the offsets of nifti1.h.
fn nifti(dims: [usize; 3], srow: [[f32; 4]; 3], data: &[u8]) -> Vec<u8> {
    let mut h = vec![0u8; 352];
    let mut put = |at: usize, b: &[u8]| h[at..at + b.len()].copy_from_slice(b);
    put(0, &348i32.to_le_bytes());
    put(40, &3i16.to_le_bytes());
    for (i, &d) in dims.iter().enumerate() {
        put(42 + 2 * i, &(d as i16).to_le_bytes());
    }
    put(70, &2i16.to_le_bytes()); // uint8
    put(72, &8i16.to_le_bytes());
    for i in 0..4 {
        put(76 + 4 * i, &1f32.to_le_bytes());
    }
    put(108, &352f32.to_le_bytes());
    put(254, &1i16.to_le_bytes());
    for (r, row) in srow.iter().enumerate() {
        for (c, v) in row.iter().enumerate() {
            put(280 + 16 * r + 4 * c, &v.to_le_bytes());
        }
    }
    put(344, b"n+1\0");
    h.extend_from_slice(data);
    h
}

/// A small head in RAS order (i right, j anterior, k superior), 14x16x18:
/// an ellipsoid skull with a nose in front, lower than the middle, and the
/// same head stored along other axes: i' posterior, j' superior, k' left.
fn heads(s: &Scratch) -> (String, String) {
    let (ni, nj, nk) = (14, 16, 18);
    let value = |i: usize, j: usize, k: usize| -> u8 {
        let (x, y, z) = (i as f32 - 6.5, j as f32 - 7.0, k as f32 - 8.5);
        let skull = (x / 6.0).powi(2) + (y / 6.0).powi(2) + (z / 8.0).powi(2) < 1.0;
        let nose = x.abs() < 1.5 && (5.0..7.5).contains(&y) && (-3.0..0.0).contains(&z);
        if skull || nose { 200 } else { 0 }
    };
    let mut ras = Vec::new();
    for k in 0..nk {
        for j in 0..nj {
            for i in 0..ni {
                ras.push(value(i, j, k));
            }
        }
    }
    let mut turned = Vec::new();
    for c in 0..ni {
        for b in 0..nk {
            for a in 0..nj {
                turned.push(value(ni - 1 - c, nj - 1 - a, b));
            }
        }
    }
    let eye = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]];
    let moved = [[0.0, 0.0, -1.0, 13.0], [-1.0, 0.0, 0.0, 15.0], [0.0, 1.0, 0.0, 0.0]];
    let (a, b) = (s.path("ras.nii"), s.path("turned.nii"));
    std::fs::write(&a, nifti([ni, nj, nk], eye, &ras)).unwrap();
    std::fs::write(&b, nifti([nj, nk, ni], moved, &turned)).unwrap();
    (a, b)
}

/// One frame's DAC samples as `stats --samples` writes them.
fn frame(args: &[&str], out: &str) -> Vec<u8> {
    let mut all = vec!["stats", "--level", "100", "--board", "f407", "--samples", out];
    all.extend_from_slice(args);
    let r = run(&all);
    assert!(r.status.success(), "{all:?}: {}", String::from_utf8_lossy(&r.stderr));
    std::fs::read(out).unwrap()
}

/// The head stored along other axes draws the very samples of the head in
/// RAS order; with `--orientation index` it does not.
#[test]
fn a_turned_head_draws_as_the_ras_head() {
    let s = Scratch::new("orientation-draw");
    let (ras, turned) = heads(&s);
    let out = s.path("frame.txt");
    let want = frame(&[&ras], &out);
    assert!(want.len() > 1000);
    assert!(frame(&[&turned], &out) == want, "the turned head draws differently");
    assert!(frame(&[&turned, "--orientation", "index"], &out) != want);
}

/// `send` lays the volume out as the other commands do: the virtual board
/// shows the turned head exactly as `render --board` draws the RAS one.
#[test]
fn send_gives_the_board_the_oriented_volume() {
    let s = Scratch::new("orientation-send");
    let (ras, turned) = heads(&s);
    let board_samples = s.path("board.txt");
    let mut device = Command::new(bin())
        .args(["device", "--pty", "--board", "f407", "--exit-after", "1", "--baud", "0", "--samples"])
        .arg(&board_samples)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // The device exits once it shows the volume.
    let watchdog = common::Watchdog::new(device.id());
    let mut lines = BufReader::new(device.stdout.take().unwrap()).lines();
    let pty = lines.next().unwrap().unwrap();
    let sent = Command::new(bin())
        .args(["send", &turned, "--level", "100", "--port", &pty])
        .stdin(Stdio::null())
        .output()
        .unwrap();
    assert!(sent.status.success(), "send failed: {}", String::from_utf8_lossy(&sent.stderr));
    for _ in lines.by_ref() {}
    let status = device.wait().unwrap();
    assert!(!watchdog.stopped_it(), "the device did not exit after showing the volume");
    assert!(status.success());
    let want = frame(&[&ras], &s.path("render.txt"));
    assert!(std::fs::read(&board_samples).unwrap() == want, "the board's samples differ from the RAS head's");
}
