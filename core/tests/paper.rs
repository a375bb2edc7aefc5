//! The paper's Figures 5b and 7b, reproduced to the printed four decimals.
//! Grid values come from the printed coordinates (1-based, as in the paper).

mod common;
use common::Log;
use isoscope_core::command::{Command, Point2};
use isoscope_core::contour::contour_grid;
use isoscope_core::contour::grid::Grid2;
use isoscope_core::contour::trace::Traversal;

/// Contour a single 2x2 subgrid whose lower-left grid point is `origin`
/// (1-based) and render the commands as `S(x,y)` / `D(x,y)` / `P(x,y)`.
fn subgrid(origin: (f32, f32), ll: f32, lr: f32, ur: f32, ul: f32, level: f32) -> Vec<String> {
    let data = [ll, lr, ul, ur];
    let grid = Grid2::new(&data, 2, 2).unwrap();
    let mut log = Log::default();
    contour_grid(
        &grid,
        &[level],
        Traversal::Corrected,
        |x, y| Point2::new(x + origin.0, y + origin.1),
        &mut log,
    )
    .unwrap();
    log.0
        .iter()
        .map(|(_, c)| {
            let p = c.point();
            let op = match c {
                Command::MoveTo(_) => 'S',
                Command::LineTo(_) => 'D',
                Command::Point(_) => 'P',
            };
            format!("{op}({:.4},{:.4})", p.x, p.y)
        })
        .collect()
}

#[test]
fn figure_5b_level_50() {
    assert_eq!(
        subgrid((2.0, 2.0), 150.0, 40.0, 60.0, 30.0, 50.0),
        [
            "S(2.9091,2.0000)",
            "D(2.8333,2.1667)",
            "D(3.0000,2.5000)",
            "S(2.6667,3.0000)",
            "D(2.2500,2.7500)",
            "D(2.0000,2.8333)"
        ]
    );
}

#[test]
fn figure_5b_level_100() {
    assert_eq!(
        subgrid((2.0, 2.0), 150.0, 40.0, 60.0, 30.0, 100.0),
        ["S(2.4545,2.0000)", "D(2.3125,2.3125)", "D(2.0000,2.4167)"]
    );
}

#[test]
fn figure_7b_level_100() {
    assert_eq!(
        subgrid((2.0, 1.0), 50.0, 90.0, 40.0, 150.0, 100.0),
        ["S(2.0000,1.5000)", "D(2.3704,1.6296)", "D(2.4545,2.0000)"]
    );
}
