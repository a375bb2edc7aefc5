//! The README's picture and links. `docs/img/hydrogen.png` is what
//! `scripts/readme-picture` renders (`isoscope-sim render --demo hydrogen:32
//! --size 512`); this test renders the same scene through the same library
//! calls and fails when a single pixel of the committed picture differs, so
//! the README never shows a picture the tool no longer draws.
//! `ISOSCOPE_BLESS=1` rewrites the picture (as `scripts/readme-picture` does).

use isoscope_core::demo::Demo;
use isoscope_sim::phosphor::PhosphorConfig;
use isoscope_sim::scene::{SceneConfig, build, render};
use isoscope_tests::demo_wire;
use std::path::{Path, PathBuf};

/// The picture's width and height (`--size 512`).
const SIZE: u32 = 512;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn decode(png_bytes: &[u8]) -> (u32, u32, png::ColorType, Vec<u8>) {
    let mut r = png::Decoder::new(png_bytes).read_info().expect("a PNG");
    let mut buf = vec![0; r.output_buffer_size()];
    let info = r.next_frame(&mut buf).expect("a frame");
    buf.truncate(info.buffer_size());
    (info.width, info.height, info.color_type, buf)
}

/// `render --demo hydrogen:32 --size 512`: the demo's own level (0.1), the
/// default view, beam and memory, one frame, blanked moves hidden.
fn hydrogen_picture() -> Vec<u8> {
    let v = demo_wire(Demo::Hydrogen, 32);
    let cfg = SceneConfig { levels: vec![Demo::Hydrogen.default_level()], ..SceneConfig::default() };
    let scene = build(&v, &cfg).expect("the hydrogen scene");
    let mut picture = PhosphorConfig::with_size(SIZE, SIZE);
    picture.bits = cfg.view.bits;
    render(&scene, picture, 1, None).expect("a picture").encode_png()
}

#[test]
fn readme_picture_is_what_the_tool_draws() {
    let path = root().join("docs/img/hydrogen.png");
    let png_bytes = hydrogen_picture();
    if std::env::var_os("ISOSCOPE_BLESS").is_some() {
        std::fs::write(&path, &png_bytes).unwrap();
        return;
    }
    let want = std::fs::read(&path)
        .unwrap_or_else(|e| panic!("{}: {e} (run scripts/readme-picture)", path.display()));
    let (w0, h0, c0, a) = decode(&want);
    let (w1, h1, c1, b) = decode(&png_bytes);
    assert_eq!((w0, h0, c0), (w1, h1, c1), "size or colour type of {}", path.display());
    let differing = a.iter().zip(&b).filter(|(x, y)| x != y).count();
    let out = std::env::temp_dir().join("isoscope-actual-readme-hydrogen.png");
    let _ = std::fs::write(&out, &png_bytes);
    assert!(
        differing == 0,
        "{}: {differing} channels differ from what the tool draws now (actual picture in {}); \
         run scripts/readme-picture if the change is meant",
        path.display(),
        out.display()
    );
}

/// Every relative link and image of the README names a file that exists.
#[test]
fn readme_links_resolve() {
    let readme = std::fs::read_to_string(root().join("README.md")).unwrap();
    let mut missing = Vec::new();
    let mut rest = readme.as_str();
    while let Some(i) = rest.find("](") {
        rest = &rest[i + 2..];
        let Some(end) = rest.find(')') else { break };
        let target = &rest[..end];
        let file = target.split('#').next().unwrap_or_default();
        if !file.is_empty() && !file.contains("://") && !root().join(file).exists() {
            missing.push(target.to_string());
        }
    }
    assert!(missing.is_empty(), "README.md links to files that do not exist: {missing:?}");
}
