//! The standard scenes of the one picture pipeline (the board's engine, in
//! process), with their figures held: the hydrogen 3d_xy orbital at 32^3
//! (the paper's Figure 1), a 48^3 gyroid, and the MRI head
//! `brainsmall.den` at level 40 with every 4th slice; default view and
//! beam, 1 MS/s, on the STM32F407's capacities (`--board f407`) and with the
//! host's room for the whole surface.
//!
//! Figures measured when written (docs/design.md, "Display pipeline"); each bound
//! leaves 2% of slack so that an ordering change which makes a scene worse
//! fails here. Issue 15's targets (blank travel at most 3.0%, 2% and 5% of
//! lit length) hold for hydrogen 32^3 on the f407 and for the gyroid 48^3
//! and the MRI head on the host's memory. The f407's 8,192-point picture
//! holds a tenth of those two: it thins them to whole slices (every 32nd
//! and 64th of each plane, from the middle), far apart, so their jumps are
//! long beside their lines; those figures are held as they are.

use isoscope_core::demo::Demo;
use isoscope_core::engine::Board;
use isoscope_sim::scene::{Memory, Scene, SceneConfig, build};
use isoscope_tests::{demo_wire, real_wire};

fn config(memory: Memory, levels: Vec<f32>) -> SceneConfig {
    match memory {
        Memory::Board(b) => SceneConfig::board(b, levels),
        Memory::Host => SceneConfig { levels, ..SceneConfig::default() },
    }
}

fn demo(d: Demo, n: usize, memory: Memory) -> Scene {
    build(&demo_wire(d, n), &config(memory, vec![d.default_level()])).unwrap()
}

fn brain(memory: Memory) -> Scene {
    build(&real_wire("brainsmall.den"), &SceneConfig { every: 4, ..config(memory, vec![40.0]) }).unwrap()
}

const F407: Memory = Memory::Board(Board::F407);

fn check(s: &Scene, max_ratio: f32) {
    assert!(s.blank_ratio() <= max_ratio * 1.02, "blank/lit {} > {max_ratio}", s.blank_ratio());
    // The samples are the frame counted.
    assert_eq!(s.samples.len() as u64, s.frame.samples);
}

#[test]
fn hydrogen_32_is_drawn_whole_on_the_board() {
    let (host, board) = (demo(Demo::Hydrogen, 32, Memory::Host), demo(Demo::Hydrogen, 32, F407));
    // The board stitches its pieces as they come, when its back fills:
    // what is left for the commit is 897 polylines and pieces.
    assert_eq!((host.chain.fragments, board.chain.fragments), (3728, 897));
    for s in [&host, &board] {
        assert!(s.loaded.whole(), "{:?}", s.loaded);
        assert!(s.remarks().is_empty(), "{:?}", s.remarks());
    }
    // The same lit picture: merging differs only where the board merges
    // while stitching (its pieces outnumber its picture's points).
    assert!((board.frame.lit_length / host.frame.lit_length - 1.0).abs() < 1e-3);
    // The slices' loops cross at shared points: drawn inside one another,
    // a polyline a lobe.
    assert_eq!(board.polylines, 4);
    check(&host, 0.0230);
    check(&board, 0.0253);
}

#[test]
fn gyroid_48_is_whole_on_the_host_and_thinned_on_the_board() {
    let host = demo(Demo::Gyroid, 48, Memory::Host);
    assert!(host.loaded.whole());
    check(&host, 0.0194);
    let board = demo(Demo::Gyroid, 48, F407);
    // The middle slice of each plane: nothing dropped, nothing cut, and
    // stitched and ordered.
    assert_eq!((board.loaded.asked, board.loaded.every), (1, 32), "{:?}", board.loaded);
    assert_eq!((board.loaded.dropped, board.loaded.cut), (0, 0), "{:?}", board.loaded);
    assert!(board.loaded.ordered, "{:?}", board.loaded);
    check(&board, 0.3114);
    assert!(board.points <= Board::F407.capacity.points);
    let note = board.remarks().join("\n");
    assert!(note.contains("note: the f407 board holds less than this surface"), "{note}");
    assert!(note.contains("every 32nd slice"), "{note}");
}

#[test]
fn brain_mri_holds_its_blank_figure() {
    let host = brain(Memory::Host);
    assert!(host.loaded.whole());
    check(&host, 0.0487);
    let board = brain(F407);
    // Thinned to its coarsest (every 64th slice from the middle), still a
    // little too large: the rest is dropped, and said to be.
    assert_eq!((board.loaded.asked, board.loaded.every), (4, 64), "{:?}", board.loaded);
    assert!(board.loaded.dropped > 0, "{:?}", board.loaded);
    assert!(board.loaded.ordered);
    check(&board, 0.2611);
    assert!(board.remarks().iter().any(|r| r.contains("pieces were dropped")));
}

/// Every standard scene, as the f407 draws it, keeps its frame in the
/// board's slice memory to replay at the full sample clock, and that
/// frame is short enough for a 55 Hz refresh at 1 MS/s.
#[test]
fn the_board_replays_every_standard_scene_at_55_hz() {
    let scenes = [
        ("hydrogen 32", demo(Demo::Hydrogen, 32, F407)),
        ("gyroid 32", demo(Demo::Gyroid, 32, F407)),
        ("torus 32", demo(Demo::Torus, 32, F407)),
        ("MRI head", brain(F407)),
    ];
    for (name, s) in &scenes {
        assert_eq!(s.replay_capacity(), 65_536, "{name}");
        assert!(
            s.replay_bytes > 0 && s.replay_bytes <= s.replay_capacity(),
            "{name}: {} bytes",
            s.replay_bytes
        );
        assert!(s.fps() >= 55.0, "{name}: {} Hz", s.fps());
        assert!(!s.remarks().iter().any(|r| r.contains("replay")), "{name}: {:?}", s.remarks());
    }
    // Hydrogen 32^3, the largest: two bytes a lit step, and a little more.
    let hydrogen = &scenes[0].1;
    assert!(hydrogen.replay_bytes < 2 * hydrogen.samples.len() + 1024, "{}", hydrogen.replay_bytes);
    // The host lends nothing.
    let host = demo(Demo::Torus, 16, Memory::Host);
    assert_eq!(host.replay_capacity(), 0);
    assert!(!host.report().contains("replay_bytes"));
    // A frame too long to keep is said to be.
    let long = Scene { replay_bytes: 70_000, ..demo(Demo::Torus, 16, F407) };
    let note = long.remarks().join("\n");
    assert!(
        note.contains("cannot keep this frame to replay it (70000 bytes, its slice memory holds 65536)"),
        "{note}"
    );
}
