//! The phosphor on a real frame: the hydrogen demo through the whole
//! pipeline (the board's engine in process, its beam scheduler) into a
//! [`Phosphor`] used as the DAC.

use isoscope_core::demo::Demo;
use isoscope_core::output::{Beam, Dac, Sample};
use isoscope_sim::link::WireVolume;
use isoscope_sim::phosphor::{Phosphor, PhosphorConfig};
use isoscope_sim::scene::{SceneConfig, build};
use isoscope_sim::volume::{Dims, Samples};

/// One scheduled frame of the hydrogen orbital at `n`^3, level 0.1.
fn hydrogen_frame(n: usize) -> Vec<Sample> {
    let mut data = vec![0.0f32; n * n * n];
    Demo::Hydrogen.fill(n, &mut data).unwrap();
    let volume = WireVolume::new(Dims(n, n, n), &Samples::F32(data), [1.0; 3]).unwrap();
    build(&volume, &SceneConfig { levels: vec![0.1], ..SceneConfig::default() }).unwrap().samples
}

#[test]
fn a_hydrogen_frame_keeps_its_energy_and_looks_green() {
    let samples = hydrogen_frame(16);
    let lit = samples.iter().filter(|s| s.beam == Beam::On).count();
    assert!(lit > 1000, "{lit} lit samples");
    let mut screen = Phosphor::new(PhosphorConfig::with_size(256, 256)).unwrap();
    screen.write(samples.iter().copied()).unwrap();
    // The view keeps a 5% margin: every lit sample's energy is on the image.
    let total = screen.total_energy();
    assert!((total - lit as f64).abs() < 0.01 * lit as f64, "{total} vs {lit}");
    // Nothing within 10 px of the edges (the margin is 12.8 px, the spot
    // reaches 2.6 px), not even at the parking corner: the beam is blanked
    // there.
    let e = screen.energy();
    for y in 0..256 {
        for x in 0..256 {
            if x.min(y).min(255 - x).min(255 - y) < 10 {
                assert_eq!(e[y * 256 + x], 0.0, "({x}, {y})");
            }
        }
    }
    // A green picture: lit pixels, none red or blue dominated, a black
    // background, and some saturated (whitish) ones where lines meet.
    let rgb = screen.to_rgb8();
    let pixels: Vec<&[u8]> = rgb.chunks_exact(3).collect();
    let lit_px = pixels.iter().filter(|p| p[1] > 60).count();
    assert!(lit_px > 256 * 256 / 50, "{lit_px} lit pixels");
    assert!(pixels.iter().all(|p| p[1] >= p[0] && p[1] >= p[2]));
    assert!(pixels.iter().filter(|p| p[1] == 0).count() > 256 * 256 / 2);
    assert!(pixels.iter().any(|p| p[0] > 150));
    // As a PNG.
    let png = screen.encode_png();
    let mut reader = png::Decoder::new(std::io::Cursor::new(png)).read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!((info.width, info.height), (256, 256));
    assert_eq!(&buf[..info.buffer_size()], &rgb[..]);
}

#[test]
fn a_refresh_loop_reaches_its_steady_state() {
    let samples = hydrogen_frame(12);
    let cfg = PhosphorConfig { persistence: 0.5, ..PhosphorConfig::with_size(128, 128) };
    let mut screen = Phosphor::new(cfg).unwrap();
    screen.deposit(samples.iter().copied());
    let one = screen.total_energy();
    // Frames back to back (each starts and ends at the park position),
    // decaying in between: the energy tends to one frame / (1 - 0.5).
    for _ in 0..30 {
        screen.decay();
        screen.deposit(samples.iter().copied());
    }
    let steady = screen.total_energy();
    assert!((steady - 2.0 * one).abs() < 1e-3 * one, "{steady} vs {}", 2.0 * one);
    // And the picture is brighter, never darker, than one frame alone.
    let mut single =
        Phosphor::new(PhosphorConfig { persistence: 0.5, ..PhosphorConfig::with_size(128, 128) }).unwrap();
    single.deposit(samples);
    let (a, b) = (single.to_rgb8(), screen.to_rgb8());
    assert!(a.iter().zip(&b).all(|(a, b)| b >= a));
    assert!(a.iter().zip(&b).any(|(a, b)| b > a));
}
