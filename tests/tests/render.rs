//! Golden images: what the scope shows for the standard scenes, compared
//! with checked-in references by a real image difference (not a hash), so
//! that a change in any stage (contouring, view, display list, ordering,
//! beam, phosphor) shows. `ISOSCOPE_BLESS=1` rewrites the references.

use isoscope_core::contour::grid::Plane;
use isoscope_core::demo::Demo;
use isoscope_sim::phosphor::PhosphorConfig;
use isoscope_sim::scene::{SceneConfig, build, render};
use isoscope_tests::{demo_wire, real_wire};
use std::path::PathBuf;

const SIZE: u32 = 256;

fn golden(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("golden").join(name)
}

fn decode(png_bytes: &[u8]) -> (u32, u32, Vec<u8>) {
    let mut r = png::Decoder::new(png_bytes).read_info().expect("a PNG");
    let mut buf = vec![0; r.output_buffer_size()];
    let info = r.next_frame(&mut buf).expect("a frame");
    buf.truncate(info.buffer_size());
    assert_eq!(info.color_type, png::ColorType::Rgb);
    (info.width, info.height, buf)
}

/// Compare with the reference: mean absolute difference per channel at
/// most 0.5 (of 255), and at most 0.1% of the channels off by more than 16.
fn check(name: &str, png_bytes: &[u8]) {
    let path = golden(name);
    if std::env::var_os("ISOSCOPE_BLESS").is_some() {
        std::fs::write(&path, png_bytes).unwrap();
        return;
    }
    let want = std::fs::read(&path)
        .unwrap_or_else(|e| panic!("{}: {e} (bless with ISOSCOPE_BLESS=1)", path.display()));
    let (w0, h0, a) = decode(&want);
    let (w1, h1, b) = decode(png_bytes);
    assert_eq!((w0, h0), (w1, h1));
    let diffs: Vec<u8> = a.iter().zip(&b).map(|(&x, &y)| x.abs_diff(y)).collect();
    let mean = diffs.iter().map(|&d| f64::from(d)).sum::<f64>() / diffs.len() as f64;
    let big = diffs.iter().filter(|&&d| d > 16).count();
    let out = std::env::temp_dir().join(format!("isoscope-actual-{name}"));
    let _ = std::fs::write(&out, png_bytes);
    assert!(
        mean <= 0.5 && big * 1000 <= diffs.len(),
        "{name}: mean difference {mean:.3}, {big} channels off by more than 16; actual picture in {}",
        out.display()
    );
}

fn picture(scene: &isoscope_sim::scene::Scene) -> Vec<u8> {
    let mut cfg = PhosphorConfig::with_size(SIZE, SIZE);
    cfg.bits = 12;
    render(scene, cfg, 1, None).unwrap().encode_png()
}

#[test]
fn hydrogen_32_looks_as_it_did() {
    let v = demo_wire(Demo::Hydrogen, 32);
    let scene = build(&v, &SceneConfig { levels: vec![0.1], ..SceneConfig::default() }).unwrap();
    check("hydrogen32.png", &picture(&scene));
}

#[test]
fn mri_head_looks_as_it_did() {
    let vol = real_wire("brainsmall.den");
    // Skin level, every 6th axial (x-y) and sagittal (y-z) slice, seen from
    // above and to the side: a chicken-wire head.
    let mut cfg = SceneConfig {
        levels: vec![30.0],
        every: 6,
        planes: vec![Plane::XY, Plane::YZ],
        ..SceneConfig::default()
    };
    cfg.view.pitch = 60.0;
    cfg.view.yaw = 20.0;
    let scene = build(&vol, &cfg).unwrap();
    check("brainsmall.png", &picture(&scene));
}

/// The comparison itself must fail on a real change: a picture from
/// another view differs from the reference.
#[test]
fn a_different_picture_fails_the_comparison() {
    let v = demo_wire(Demo::Hydrogen, 32);
    let mut cfg = SceneConfig { levels: vec![0.1], ..SceneConfig::default() };
    cfg.view.yaw += 20.0;
    let other = picture(&build(&v, &cfg).unwrap());
    if std::env::var_os("ISOSCOPE_BLESS").is_some() {
        return;
    }
    let r = std::panic::catch_unwind(|| check("hydrogen32.png", &other));
    assert!(r.is_err(), "a 20-degree turn passed the golden comparison");
}
