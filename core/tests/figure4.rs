//! The ten crossing cases of the paper's Figure 4, one test each (the saddle
//! twice, once per resolution by the centre value), with the exact command
//! lists the corrected traversal emits for one 2x2 subgrid.
//!
//! Corner values are small integers and levels are chosen so that every
//! crossing is a dyadic rational, exact in `f32`; points are written with
//! `f32`'s shortest round-trip `Display` (`0.375`, `1`), so the comparison is
//! exact. Commands are `M` (SETPOINT / MoveTo), `L` (DRAWTO / LineTo) and `P`
//! (DRAWPOINT / Point), in grid coordinates with LL at (0,0), LR at (1,0), UR
//! at (1,1), UL at (0,1) and the centre node C at (0.5,0.5) holding the mean of
//! the corners. Each expectation is the level set of the piecewise-linear
//! surface on the four triangles (corner, next corner, C); the derivation is
//! given in each test.
//!
//! In the pictures below `+` marks a crossing, `*` a corner at the level, `o`
//! the centre at the level, `=` and `#` a border edge drawn along its length;
//! the drawn contour runs between them.

mod common;
use common::Log;
use isoscope_core::command::{Command, Point2};
use isoscope_core::contour::grid::Grid2;
use isoscope_core::contour::trace::Traversal;
use isoscope_core::contour::{ContourStats, contour_grid};

fn show(c: &Command<Point2>) -> String {
    let p = c.point();
    format!("{}({},{})", c.op(), p.x, p.y)
}

/// Contour the single 2x2 subgrid laid out as it is drawn, top row first:
/// `[[UL, UR], [LL, LR]]`, at the given levels.
fn contour_levels(rows: [[f32; 2]; 2], levels: &[f32]) -> (Vec<(usize, String)>, ContourStats) {
    let [[ul, ur], [ll, lr]] = rows;
    // Grid rows: (LL, LR), then (UL, UR).
    let data = [ll, lr, ul, ur];
    let grid = Grid2::new(&data, 2, 2).unwrap();
    let mut log = Log::default();
    let stats = contour_grid(&grid, levels, Traversal::Corrected, Point2::new, &mut log).unwrap();
    (log.0.iter().map(|(l, c)| (*l, show(c))).collect(), stats)
}

/// As [`contour_levels`] at one level, commands only.
fn contour(rows: [[f32; 2]; 2], level: f32) -> Vec<String> {
    let (cmds, stats) = contour_levels(rows, &[level]);
    assert_eq!(stats.cells, 1);
    assert_eq!(stats.nonfinite_cells, 0);
    assert_eq!(stats.commands, cmds.len() as u64);
    assert_eq!(stats.crossing_cells, u64::from(!cmds.is_empty()));
    cmds.into_iter().map(|(_, c)| c).collect()
}

/// Figure 4, "contour through adjacent edges": one corner cut off.
///
/// ```text
///  UL=4 --------- UR=4
///    |             |
///    |     C=3     |
///    +_            |
///    | \           |
///  LL=0 -+------- LR=4     level 1.5
/// ```
#[test]
fn contour_through_adjacent_edges() {
    // C = 3. B0 (LL->LR): t = 1.5/4 = 0.375; S0 (LL->C): t = 1.5/3 = 0.5,
    // at (0.25, 0.25); B3 (LL->UL): t = 0.375. Triangles (LL,LR,C) and
    // (UL,LL,C) each hold one segment through the S0 crossing.
    assert_eq!(contour([[4.0, 4.0], [0.0, 4.0]], 1.5), ["M(0,0.375)", "L(0.25,0.25)", "L(0.375,0)"]);
}

/// Figure 4, "contour across the 2x2": one contour from the left edge to
/// the right edge.
///
/// ```text
///  UL=4 --------- UR=4
///    |             |
///    |     C=2     |
///    +-------------+
///  LL=0 --------- LR=0     level 1
/// ```
#[test]
fn contour_across_the_2x2() {
    // C = 2. B3 and B1: t = 1/4, at (0, 0.25) and (1, 0.25); S0 and S1:
    // t = 1/2, at (0.25, 0.25) and (0.75, 0.25). The top triangle is above
    // the level, the bottom one below it.
    assert_eq!(
        contour([[4.0, 4.0], [0.0, 0.0]], 1.0),
        ["M(0,0.25)", "L(0.25,0.25)", "L(0.75,0.25)", "L(1,0.25)"]
    );
}

/// Figure 4, "contour tangent to the 2x2": the level touches one corner
/// only, a single DRAWPOINT there (at the minimum and at the maximum).
///
/// ```text
///  UL=2 --------- UR=2
///    |             |
///    |     C=1.5   |
///    |             |
///  LL=0*--------- LR=2     level 0
/// ```
#[test]
fn contour_tangent_to_the_2x2() {
    // Only LL equals the level; every other node is above it.
    assert_eq!(contour([[2.0, 2.0], [0.0, 2.0]], 0.0), ["P(0,0)"]);
    // Only UR equals the level; every other node is below it.
    assert_eq!(contour([[0.0, 4.0], [0.0, 0.0]], 4.0), ["P(1,1)"]);
}

/// Figure 4, "contour through one corner": it enters at a corner and leaves
/// through an edge not touching that corner.
///
/// ```text
///  UL=3 --------- UR=4
///    |             |
///    |     C=2     |
///    |          ___+
///    |    ___---   |
///  LL=1*--------- LR=0     level 1
/// ```
#[test]
fn contour_through_one_corner() {
    // C = 2. Triangle (LL,LR,C): LL at the level, LR below, C above, so a
    // segment from LL to S1 (LR->C, t = 1/2, at (0.75, 0.25)). Triangle
    // (LR,UR,C): S1 to B1 (LR->UR, t = 1/4, at (1, 0.25)). Triangle (UL,LL,C)
    // only touches LL; (UR,UL,C) is above the level.
    assert_eq!(contour([[3.0, 4.0], [1.0, 0.0]], 1.0), ["M(0,0)", "L(0.75,0.25)", "L(1,0.25)"]);
}

/// Figure 4, "two contours through adjacent edges" (the saddle), resolved
/// by a centre above the level: the two low corners are cut off.
///
/// ```text
///  UL=4 ------+-- UR=0
///    |        |    |
///    |        +----+
///    |     C=2     |
///    +----+        |
///    |    |        |
///  LL=0 --+------- LR=4     level 1
/// ```
#[test]
fn two_contours_through_adjacent_edges_centre_above() {
    // C = 2 > 1. Around LL: B0 (t = 1/4, (0.25, 0)), S0 (t = 1/2,
    // (0.25, 0.25)), B3 ((0, 0.25)). Around UR: B1 (LR->UR, t = 3/4,
    // (1, 0.75)), S2 (UR->C, t = 1/2, (0.75, 0.75)), B2 (UL->UR, t = 3/4,
    // (0.75, 1)). The tree traversal draws each contour as two pieces that
    // meet at the spoke crossing.
    assert_eq!(
        contour([[4.0, 0.0], [0.0, 4.0]], 1.0),
        [
            "M(1,0.75)",
            "L(0.75,0.75)",
            "M(0.25,0.25)",
            "L(0.25,0)",
            "M(0,0.25)",
            "L(0.25,0.25)",
            "M(0.75,0.75)",
            "L(0.75,1)",
        ]
    );
}

/// Figure 4, "two contours through adjacent edges" (the saddle), resolved
/// by a centre below the level: the two high corners are cut off.
///
/// ```text
///  UL=4 --+------- UR=0
///    |    |        |
///    +----+        |
///    |     C=2     |
///    |        +----+
///    |        |    |
///  LL=0 ------+-- LR=4     level 3
/// ```
#[test]
fn two_contours_through_adjacent_edges_centre_below() {
    // C = 2 < 3. Around LR: B1 (t = 1/4, (1, 0.25)), S1 (LR->C, t = 1/2,
    // (0.75, 0.25)), B0 (t = 3/4, (0.75, 0)). Around UL: B3 (t = 3/4,
    // (0, 0.75)), S3 (UL->C, t = 1/2, (0.25, 0.75)), B2 (t = 1/4, (0.25, 1)).
    assert_eq!(
        contour([[4.0, 0.0], [0.0, 4.0]], 3.0),
        ["M(1,0.25)", "L(0.75,0.25)", "L(0.75,0)", "M(0,0.75)", "L(0.25,0.75)", "L(0.25,1)"]
    );
}

/// Figure 4, "two contours tangent to the 2x2": the level equals two
/// opposite corners and the other two are on the same side, two DRAWPOINTs.
///
/// ```text
///  UL=4 --------- UR=0*
///    |             |
///    |     C=2     |
///    |             |
///  LL=0*--------- LR=4     level 0 (and mirrored: level 4, the others 0)
/// ```
#[test]
fn two_contours_tangent_to_the_2x2() {
    // C = 2: every node but LL and UR is above the level 0.
    assert_eq!(contour([[4.0, 0.0], [0.0, 4.0]], 0.0), ["P(0,0)", "P(1,1)"]);
    // The same with the two other corners below the level 4.
    assert_eq!(contour([[0.0, 4.0], [4.0, 0.0]], 4.0), ["P(0,0)", "P(1,1)"]);
}

/// Figure 4, "contour across the diagonal": two opposite corners at the
/// level, the other two on opposite sides of it, so the centre equals the
/// level too and the contour is the diagonal through the centre.
///
/// ```text
///  UL=4 --------- UR=2*
///    |          /  |
///    |     o       |
///    |   /         |
///  LL=2*--------- LR=0     level 2
/// ```
#[test]
fn contour_across_the_diagonal() {
    // C = 2 = level. Each triangle has two nodes at the level (a corner and
    // C) and its third node off the level: segments LL-C and C-UR. The
    // traversal draws them as two SETPOINT/DRAWTO pairs; the second SETPOINT
    // is where the beam already is, so the pen continues the polyline.
    assert_eq!(contour([[4.0, 2.0], [2.0, 0.0]], 2.0), ["M(0,0)", "L(0.5,0.5)", "L(1,1)"]);
}

/// Figure 4, "contour along one edge": an equal-valued border edge at the
/// level is drawn in its entirety, exactly once.
///
/// ```text
///  UL=4 --------- UR=4
///    |             |
///    |     C=2     |
///    |             |
///  LL=0*=========* LR=0     level 0 (and mirrored: the top edge)
/// ```
#[test]
fn contour_along_one_edge() {
    // C = 2. Triangle (LL,LR,C) has LL and LR at the level: segment B0. The
    // triangles beside it only touch LL or LR.
    assert_eq!(contour([[4.0, 4.0], [0.0, 0.0]], 0.0), ["M(0,0)", "L(1,0)"]);
    // The top edge, the other corners above the level.
    assert_eq!(contour([[0.0, 0.0], [4.0, 4.0]], 0.0), ["M(1,1)", "L(0,1)"]);
}

/// Figure 4, "contours along two edges": three corners at the level, the
/// two equal-valued border edges they span are drawn.
///
/// ```text
///  UL=0*--------- UR=4
///    #             |
///    #     C=1     |
///    #             |
///  LL=0*=========* LR=0     level 0
/// ```
#[test]
fn contours_along_two_edges() {
    // C = 1. Triangles (LL,LR,C) and (UL,LL,C) hold segments B0 and B3; the
    // other two only touch LR or UL. Each equal-valued edge comes from the
    // traversal as its own SETPOINT/DRAWTO pair; the second SETPOINT is where
    // the beam already is, so the pen continues the polyline.
    assert_eq!(contour([[0.0, 4.0], [0.0, 0.0]], 0.0), ["M(0,1)", "L(0,0)", "L(1,0)"]);
}

/// Figure 4, "constant 2x2": by convention nothing is drawn, neither at its
/// own value nor at any other level.
///
/// ```text
///  UL=2 --------- UR=2
///    |             |
///    |     C=2     |
///    |             |
///  LL=2 --------- LR=2     level 2 (and 1, 3)
/// ```
#[test]
fn constant_2x2() {
    let flat = [[2.0, 2.0], [2.0, 2.0]];
    for level in [2.0, 1.0, 3.0, 0.0, -2.0] {
        assert!(contour(flat, level).is_empty(), "level {level}");
    }
    let (cmds, stats) = contour_levels(flat, &[1.0, 2.0, 3.0]);
    assert!(cmds.is_empty());
    assert_eq!(stats, ContourStats { cells: 1, ..ContourStats::default() });
}
