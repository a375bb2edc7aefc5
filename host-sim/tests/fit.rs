//! Any volume onto the board (issue 19): `--crop`, `--downsample` and the
//! automatic choice of `isoscope_sim::fit`, on hand-made volumes, on one of
//! the MNI152 template's size (197x233x189 u8, made here), sent to a
//! virtual f407 board, and on a real file too wide for the board.

mod common;
use common::real_data;
use isoscope_core::engine::Board;
use isoscope_sim::fit::{self, Crop, Factors, FitOptions, Limits};
use isoscope_sim::volume::{Dims, Dtype, LoadedVolume, Samples};
use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};

fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_isoscope-sim")
}

fn vol(dims: Dims, samples: Samples) -> LoadedVolume {
    LoadedVolume { dims, samples, spacing: [1.0, 2.0, 3.0] }
}

/// 4x4x2 u8, sample (x, y, z) = x + 4y + 16z; blocks of 2x2x2 hold
/// x0 + 4y0 + {0, 1, 4, 5, 16, 17, 20, 21}: mean x0 + 4y0 + 10.5.
fn ramp() -> LoadedVolume {
    vol(Dims(4, 4, 2), Samples::U8((0..32).collect()))
}

#[test]
fn block_mean_is_exact_and_rounds_in_the_type() {
    let d = fit::downsample(&ramp(), Factors([2; 3])).unwrap();
    assert_eq!(d.dims, Dims(2, 2, 1));
    // 10.5, 12.5, 18.5, 20.5 rounded half away from zero.
    assert_eq!(d.samples, Samples::U8(vec![11, 13, 19, 21]));
    assert_eq!(d.spacing, [2.0, 4.0, 6.0]);

    let neg = vol(Dims(2, 1, 1), Samples::I16(vec![-3, -4]));
    assert_eq!(fit::downsample(&neg, Factors([2, 1, 1])).unwrap().samples, Samples::I16(vec![-4]));
    let f = vol(Dims(3, 1, 1), Samples::F32(vec![0.25, 0.5, 9.0]));
    let d = fit::downsample(&f, Factors([2, 1, 1])).unwrap();
    // The last sample, short of a whole block, is left out.
    assert_eq!((d.dims, d.samples), (Dims(1, 1, 1), Samples::F32(vec![0.375])));
    let wide = vol(Dims(2, 1, 1), Samples::U16(vec![65535, 65534]));
    assert_eq!(fit::downsample(&wide, Factors([2, 1, 1])).unwrap().samples, Samples::U16(vec![65535]));
    // Per axis: along x only.
    let d = fit::downsample(&ramp(), Factors([2, 1, 1])).unwrap();
    assert_eq!(d.dims, Dims(2, 4, 2));
    let Samples::U8(s) = d.samples else { panic!() };
    assert_eq!(&s[..4], &[1, 3, 5, 7]); // (0+1)/2 = 0.5 -> 1, (2+3)/2 = 2.5 -> 3
}

#[test]
fn crop_takes_half_open_ranges_and_refuses_bad_ones() {
    let c: Crop = "1:3,2:,:1".parse().unwrap();
    let v = fit::crop(&ramp(), &c).unwrap();
    assert_eq!(v.dims, Dims(2, 2, 1));
    assert_eq!(v.samples, Samples::U8(vec![9, 10, 13, 14]));
    assert_eq!(v.spacing, ramp().spacing);
    let whole: Crop = ":,:,:".parse().unwrap();
    assert_eq!(fit::crop(&ramp(), &whole).unwrap(), ramp());

    let err = |s: &str| fit::crop(&ramp(), &s.parse().unwrap()).unwrap_err().to_string();
    assert!(err("0:5,:,:").contains("past the volume's 4 samples along x"), "{}", err("0:5,:,:"));
    assert!(err(":,:,2:2").contains("is empty"));
    assert!(err(":,3:1,:").contains("is empty"));
    for bad in ["1:2", "1:2,3:4", "a:b,:,:", "1-2,:,:", "-1:2,:,:"] {
        assert!(bad.parse::<Crop>().is_err(), "{bad}");
    }
    for bad in ["0", "2,0,2", "2,2", "", "x", "99999999999999999999999"] {
        assert!(bad.parse::<Factors>().is_err(), "{bad}");
    }
    assert_eq!("3".parse::<Factors>().unwrap(), Factors([3; 3]));
    let e = fit::downsample(&ramp(), Factors([1, 1, 3])).unwrap_err().to_string();
    assert!(e.contains("larger than the volume's 2 samples along z"), "{e}");
    // Factors as large as usize: refused, not overflowed.
    assert!(fit::downsample(&ramp(), Factors([usize::MAX; 3])).is_err());
}

/// A volume of the MNI152 template's size and type: an ellipsoid of
/// tissue (0 outside, up to 200 inside).
fn mni_like() -> LoadedVolume {
    let (nx, ny, nz) = (197usize, 233usize, 189usize);
    let mut s = Vec::with_capacity(nx * ny * nz);
    for z in 0..nz {
        for y in 0..ny {
            for x in 0..nx {
                let r = (((x as f32 - 98.0) / 80.0).powi(2)
                    + ((y as f32 - 116.0) / 100.0).powi(2)
                    + ((z as f32 - 94.0) / 80.0).powi(2))
                .sqrt();
                s.push((200.0 * (1.2 - r)).clamp(0.0, 255.0) as u8);
            }
        }
    }
    LoadedVolume { dims: Dims(nx, ny, nz), samples: Samples::U8(s), spacing: [1.0; 3] }
}

#[test]
fn an_mni152_sized_volume_gets_the_smallest_factor_that_fits_the_f407() {
    let limits = Limits::of_board(&Board::F407);
    let v = mni_like();
    assert!(!limits.fits(v.dims, 1));
    assert_eq!(fit::auto_factor(v.dims, 1, &limits), Some(2));
    let fitted = fit::fit(v, &FitOptions::default(), Some(&limits)).unwrap();
    assert_eq!(fitted.volume.dims, Dims(98, 116, 94));
    assert!(matches!(fitted.volume.samples, Samples::U8(_)), "u8 stays u8");
    assert!(limits.fits(fitted.volume.dims, 1));
    assert_eq!(fitted.notes.len(), 1, "{:?}", fitted.notes);
    let note = &fitted.notes[0];
    assert!(note.contains("downsampling by 2") && note.contains("98x116x94 U8"), "{note}");
    // Never silent: no fit, no note; a crop or downsample given is used as is.
    let small = fit::fit(ramp(), &FitOptions::default(), Some(&limits)).unwrap();
    assert_eq!((small.volume, small.notes.len()), (ramp(), 0));
    let opts = FitOptions { downsample: Some(Factors([1, 1, 2])), crop: None };
    let e = fit::fit(mni_like(), &opts, Some(&limits)).unwrap_err().to_string();
    assert!(e.contains("does not fit (--downsample 2,2,4 fits)"), "{e}");
    let opts = FitOptions { crop: Some("40:160,50:170,:".parse().unwrap()), downsample: None };
    assert_eq!(fit::fit(mni_like(), &opts, Some(&limits)).unwrap().volume.dims, Dims(120, 120, 189));
}

#[test]
fn samples_narrow_only_when_every_value_fits() {
    let limits = Limits::of_board(&Board::F407);
    let go = |s: Samples| fit::fit(vol(Dims(2, 2, 1), s), &FitOptions::default(), Some(&limits)).unwrap();
    assert_eq!(go(Samples::U16(vec![0, 1, 255, 7])).volume.samples, Samples::U8(vec![0, 1, 255, 7]));
    assert_eq!(go(Samples::U16(vec![0, 1, 256, 7])).volume.samples, Samples::U16(vec![0, 1, 256, 7]));
    assert_eq!(go(Samples::I16(vec![0, -1, 2, 3])).volume.samples, Samples::I16(vec![0, -1, 2, 3]));
    assert_eq!(
        go(Samples::F32(vec![-2.0, 0.0, 300.0, 1.0])).volume.samples,
        Samples::I16(vec![-2, 0, 300, 1])
    );
    assert_eq!(
        go(Samples::F32(vec![0.5, 0.0, 3.0, 1.0])).volume.samples,
        Samples::F32(vec![0.5, 0.0, 3.0, 1.0])
    );
    assert_eq!(fit::narrower(&Samples::F32(vec![f32::NAN, 1.0])), None);
    assert_eq!(fit::narrower(&Samples::F32(vec![70000.0])), None);
    assert_eq!(fit::narrower(&Samples::F32(vec![60000.0])), Some(Dtype::U16));
    // Without a board nothing is narrowed.
    let host = fit::fit(vol(Dims(2, 2, 1), Samples::U16(vec![1; 4])), &FitOptions::default(), None).unwrap();
    assert_eq!(host.volume.samples, Samples::U16(vec![1; 4]));
}

/// `send` of `input` (send's arguments) to a virtual f407 board: its
/// standard error and output, once the board has shown the volume.
fn send_to_a_virtual_board(input: &[&std::ffi::OsStr]) -> (String, String) {
    // A board that drops a client silent for two seconds, less than the
    // fits of the MNI-sized volumes take on a slow machine: `send` greets
    // it while it fits (it once fell silent, and lost the board).
    let mut board = Command::new(bin())
        .args(["device", "--tcp", "127.0.0.1:0", "--board", "f407", "--baud", "0", "--exit-after", "1"])
        .args(["--idle-timeout", "2"])
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut log = BufReader::new(board.stdout.take().unwrap());
    let mut addr = String::new();
    log.read_line(&mut addr).unwrap();
    std::thread::spawn(move || for _ in log.lines().map_while(Result::ok) {});
    let out = Command::new(bin())
        .arg("send")
        .args(input)
        .args(["--port", &format!("tcp:{}", addr.trim()), "--baud", "12000000"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    if !out.status.success() {
        let _ = board.kill();
    }
    let status = board.wait().unwrap();
    assert!(out.status.success(), "send failed: {err}");
    assert!(status.success());
    (err, String::from_utf8_lossy(&out.stdout).into_owned())
}

/// The board's own report of the points it shows.
fn board_points(text: &str) -> u64 {
    text.lines()
        .find_map(|l| l.strip_prefix("board_points=")?.parse().ok())
        .unwrap_or_else(|| panic!("no board_points= in {text}"))
}

/// `send` of an MNI152-sized volume to a virtual f407 board: downsampled
/// with a note (by 2 to fit its slices, by 3 for its picture: every 8th
/// slice asked, every 16th drawn at 2, every 8th at 3), sent, and the
/// board draws it.
#[test]
fn send_fits_an_mni152_sized_volume_to_the_virtual_board() {
    let dir = common::Scratch::new("fit");
    let raw = dir.0.join("mni.raw");
    let Samples::U8(bytes) = mni_like().samples else { unreachable!() };
    std::fs::write(&raw, &bytes).unwrap();
    let args = ["--dims", "197x233x189", "--dtype", "u8", "--level", "100", "--every", "8"];
    let mut input = vec![raw.as_os_str()];
    input.extend(args.iter().map(std::ffi::OsStr::new));
    let (err, text) = send_to_a_virtual_board(&input);
    assert!(err.contains("isoscope-sim: note: the board (an f407 by its capabilities)"), "{err}");
    assert!(
        err.contains("draws every 16th slice of a 98x116x94 volume (slices 32 voxels apart), and every 8th slice once downsampled by 3 (24 voxels apart)")
            && err.contains("sent 65x77x63 U8"),
        "{err}"
    );
    assert!(board_points(&text) > 100, "{text}");
}

/// The real MNI152 template (scripts/fetch-data), sent as a newcomer
/// sends it, with no option: oriented, fitted to the board's picture, and
/// shown whole (every slice drawn).
#[test]
fn send_puts_the_real_mni152_template_on_the_virtual_board() {
    let file = real_data("mni_icbm152_t1_tal_nlin_sym_09a_converted.nii.gz");
    let (err, text) = send_to_a_virtual_board(&[file.as_os_str()]);
    assert!(err.contains("downsampling by 9") && err.contains("sent 21x21x25 U8"), "{err}");
    assert!(text.contains("board_state=Showing"), "{text}");
    assert!(board_points(&text) > 1000, "{text}");
    // What the board was told it would draw: every slice, nothing dropped.
    let out = Command::new(bin()).arg("stats").arg(&file).args(["--board", "f407"]).output().unwrap();
    let stats = String::from_utf8_lossy(&out.stdout);
    assert!(stats.contains("\nevery=1\n") && stats.contains("pieces_dropped=0"), "{stats}");
    assert!(stats.contains(&format!("points={}", board_points(&text))), "{stats}\n{text}");
}

/// ITK's 221x257 proton density slice is wider than the f407's rows: the
/// board preset draws it downsampled by 2 in x and y (a 2D grid keeps its
/// one slice), with a note, and the picture is not empty.
#[test]
fn a_real_slice_too_wide_for_the_board_is_fitted() {
    let out = Command::new(bin())
        .arg("stats")
        .arg(real_data("BrainProtonDensitySliceBorder20.nhdr"))
        .args(["--board", "f407", "--level", "94"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(err.contains("2x2x1 block, rounded, 110x128x1 U8"), "{err}");
    let text = String::from_utf8_lossy(&out.stdout);
    let points: u64 = text.lines().find_map(|l| l.strip_prefix("points=")?.parse().ok()).unwrap();
    assert!(points > 100, "{text}");
}

/// A board that draws a volume of `n` samples a side every `stride(n)`-th
/// slice, dropping pieces above `drops` samples a side.
fn search(
    n: usize,
    asked: usize,
    stride: impl Fn(usize) -> usize,
    drops: usize,
) -> (fit::Choice, Vec<usize>) {
    let dims = Dims(n, n, n);
    let mut tried = Vec::new();
    let (_, c) = fit::finest_on_board(dims, 1, asked, |f| {
        tried.push(f);
        let side = n / f;
        Ok(fit::Drawn { every: stride(side).max(asked), dropped: side > drops })
    })
    .unwrap();
    (c, tried)
}

#[test]
fn the_board_fit_draws_the_slices_closest_together_in_the_volume() {
    // The MRI head's figures (`stats --board f407 --downsample F`,
    // 128x128x84 u8 at level 40): every 64th slice whole, 16th at 2, 4th
    // at 3, 2nd at 4, every slice at 6 (and, here, at 5).
    let mri = |side: usize| match side {
        128.. => 64,
        64.. => 16,
        42.. => 4,
        32.. => 2,
        _ => 1,
    };
    let (c, tried) = search(128, 1, mri, usize::MAX);
    assert_eq!((c.factor, c.drawn.every, c.spacing()), (5, 1, 5));
    // 6 and on could only draw slices 6 or more apart: not tried.
    assert_eq!(tried, [1, 2, 3, 4, 5]);

    // A volume the board draws whole stays as it is.
    let (c, tried) = search(64, 1, |_| 1, usize::MAX);
    assert_eq!((c.factor, tried), (1, vec![1]));
    // Asked for every 4th slice, drawn so: nothing gained downsampling.
    let (c, tried) = search(64, 4, |_| 1, usize::MAX);
    assert_eq!((c.factor, c.spacing(), tried), (1, 4, vec![1]));

    // Dropping pieces ranks below any picture that does not, however far
    // apart its slices.
    let (c, _) = search(128, 1, |side| if side > 20 { 2 } else { 8 }, 20);
    assert_eq!((c.factor, c.drawn.dropped), (7, false));
    // A tie in spacing: the finer grid.
    let (c, tried) = search(96, 1, |side| if side > 48 { 4 } else { 2 }, usize::MAX);
    assert_eq!((c.factor, c.spacing(), tried), (1, 4, vec![1, 2, 3]));
    // Never coarser than MIN_FIT_EXTENT samples a side, even dropping.
    let (c, tried) = search(40, 1, |_| 64, 0);
    assert!(tried.iter().all(|&f| 40 / f >= fit::MIN_FIT_EXTENT || f == 1), "{tried:?}");
    assert_eq!(c.factor, 1);
}
