//! The standard scenes of the display pipeline, with their blank-travel
//! figures held (issue 3): the hydrogen 3d_xy orbital at 32^3 (the paper's
//! Figure 1), a 48^3 gyroid, and the MRI head `brainsmall.den` at level 40
//! with every 4th slice. Default view, default beam, 1 MS/s.
//!
//! Figures measured when written (README, "Display pipeline"); each bound
//! leaves 2% of slack so that an ordering change which makes a scene worse
//! fails here.

use isoscope_core::demo::Demo;
use isoscope_core::grid::Volume;
use isoscope_sim::scene::{Order, Scene, SceneConfig, build};
use isoscope_sim::volume::{LoadedVolume, Samples};
use isoscope_tests::{demo_samples, real_data};

fn demo(d: Demo, n: usize, order: Order) -> Scene {
    let data = demo_samples(d, n);
    let v = Volume::new(&data, n, n, n).unwrap();
    build(&v, &SceneConfig { levels: vec![d.default_level()], order, ..SceneConfig::default() }).unwrap()
}

fn brain(order: Order) -> Scene {
    let v = LoadedVolume::read_known(&real_data("brainsmall.den")).unwrap().unwrap();
    let Samples::U8(s) = &v.samples else { panic!("brainsmall.den is u8") };
    let vol = Volume::new(s, 128, 128, 84).unwrap();
    build(&vol, &SceneConfig { levels: vec![40.0], every: 4, order, ..SceneConfig::default() }).unwrap()
}

fn ratio(s: &Scene) -> f32 {
    s.frame.blank_length / s.frame.lit_length
}

/// The same lit picture in both orders, far less blanked travel optimised.
fn check(input: &Scene, opt: &Scene, max_ratio: f32, max_blank: f32) {
    assert_eq!(input.fragments, opt.fragments);
    // Merging collinear runs shortens lit length by far less than 1%.
    assert!((opt.frame.lit_length / input.frame.lit_length - 1.0).abs() < 0.01);
    assert!(ratio(opt) <= max_ratio, "blank/lit {} > {max_ratio}", ratio(opt));
    assert!(opt.frame.blank_length <= max_blank, "blank {} > {max_blank}", opt.frame.blank_length);
    assert!(opt.frame.blank_length * 50.0 < input.frame.blank_length);
    assert!(opt.frame.samples < input.frame.samples);
}

#[test]
fn hydrogen_32_meets_the_targets() {
    let (input, opt) = (demo(Demo::Hydrogen, 32, Order::Input), demo(Demo::Hydrogen, 32, Order::Optimized));
    assert_eq!((opt.fragments, opt.list.polyline_count()), (3728, 32));
    // Targets: blanked travel at most 5% of lit length; 50 frames/s at 1 MS/s.
    check(&input, &opt, 0.05, 5473.2 * 1.02);
    assert!(opt.frame.fps(1e6) >= 50.0, "{} fps", opt.frame.fps(1e6));
}

#[test]
fn gyroid_48_meets_the_blank_target() {
    let (input, opt) = (demo(Demo::Gyroid, 48, Order::Input), demo(Demo::Gyroid, 48, Order::Optimized));
    check(&input, &opt, 0.05, 50625.9 * 1.02);
}

#[test]
fn brain_mri_holds_its_blank_figure() {
    let (input, opt) = (brain(Order::Input), brain(Order::Optimized));
    // 4.9% measured: many tiny loops of MRI noise, each one jump away,
    // keep it the closest of the three to the 5% target.
    check(&input, &opt, 0.05, 40374.8 * 1.02);
}
