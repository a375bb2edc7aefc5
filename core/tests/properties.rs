//! Property tests over random grids full of ties (samples from small integer
//! sets), with occasional NaN, infinities, `f32::MAX`/`f32::MIN`, subnormals
//! and large magnitudes, at levels drawn from the samples themselves and
//! from random finite floats.
//!
//! - a. nothing panics: `f32`, `u8`, `i16`, `u16` grids, strided views,
//!   volumes along all planes; non-finite levels are rejected up front.
//! - b. every emitted point lies on an edge of the subgrid that emitted it
//!   (border, spoke or node) and interpolates the edge to the level.
//! - c. subgrids touching NaN or infinity are skipped, counted, and silent.
//! - d. a crossing inside an edge shared by two subgrids (or by the slices
//!   of two planes of a volume) is emitted bit-identically by both.
//! - e. the command stream is tidy.
//!
//! Subgrids are identified by contouring each one separately with
//! `contour_subgrid` and `Placement::new(i, j)`; a separate property checks
//! that `contour_grid` emits exactly the concatenation of those, so the
//! per-subgrid properties hold for `contour_grid`'s output.

mod common;
use common::Log;
use isoscope_core::command::{Command, Point2, Point3};
use isoscope_core::contour::Voxel;
use isoscope_core::contour::grid::{Grid2, GridError, Plane, Planes, Volume};
use isoscope_core::contour::pen::Placement;
use isoscope_core::contour::subgrid::Subgrid;
use isoscope_core::contour::surface::{SliceId, SurfaceSink, contour_volume};
use isoscope_core::contour::trace::Traversal;
use isoscope_core::contour::{ContourError, ContourStats, contour_grid, contour_subgrid};
use proptest::prelude::*;
use proptest::sample::Index;
use std::collections::{BTreeMap, BTreeSet};
use std::convert::Infallible;

/// 256 cases per property (`PROPTEST_CASES` overrides, for longer runs), and
/// no regression files: this suite must not write into the source tree.
fn config() -> ProptestConfig {
    let cases =
        if std::env::var_os("PROPTEST_CASES").is_some() { ProptestConfig::default().cases } else { 256 };
    ProptestConfig { cases, failure_persistence: None, ..ProptestConfig::default() }
}

// ---------------------------------------------------------------------------
// Sinks

type Cmd = Command<Point2>;

#[derive(Default)]
struct VolLog(Vec<(SliceId, usize, Command<Point3>)>);

impl SurfaceSink for VolLog {
    type Error = Infallible;
    fn command(&mut self, slice: SliceId, level: usize, c: Command<Point3>) -> Result<(), Infallible> {
        self.0.push((slice, level, c));
        Ok(())
    }
}

/// A command with its point as f32 bits, for exact comparison.
fn bits(c: &Cmd) -> (char, u32, u32) {
    (c.op(), c.point().x.to_bits(), c.point().y.to_bits())
}

// ---------------------------------------------------------------------------
// Strategies

/// Special sample values: non-finite, extreme, subnormal, large, signed zero.
const SPECIALS: [f32; 16] = [
    f32::NAN,
    f32::INFINITY,
    f32::NEG_INFINITY,
    f32::MAX,
    f32::MIN,
    f32::from_bits(1),           // smallest subnormal
    -f32::from_bits(1),          // its negative
    f32::from_bits(0x007f_ffff), // largest subnormal
    f32::MIN_POSITIVE,
    1e30,
    -1e30,
    3e38,
    1e7,
    -65504.0,
    16_777_217.0,
    -0.0,
];

/// One sample. Mode 0: ties only; 1: ties and moderate floats; 2: ties,
/// moderate floats and specials.
fn f32_sample(mode: u8) -> BoxedStrategy<f32> {
    let ties = (0u8..4).prop_map(f32::from);
    let halves = (-2i8..10).prop_map(|k| f32::from(k) * 0.5);
    match mode {
        0 => prop_oneof![4 => ties, 1 => halves].boxed(),
        1 => prop_oneof![8 => ties, 1 => halves, 2 => -10.0f32..10.0].boxed(),
        _ => prop_oneof![
            12 => ties,
            1 => halves,
            2 => -10.0f32..10.0,
            2 => prop::sample::select(SPECIALS.to_vec()),
        ]
        .boxed(),
    }
}

fn f32_samples(n: usize) -> impl Strategy<Value = Vec<f32>> {
    (0u8..3).prop_flat_map(move |mode| prop::collection::vec(f32_sample(mode), n))
}

#[derive(Debug, Clone)]
enum Samples {
    F32(Vec<f32>),
    U8(Vec<u8>),
    I16(Vec<i16>),
    U16(Vec<u16>),
}

impl Samples {
    fn values(&self) -> Vec<f32> {
        match self {
            Samples::F32(v) => v.clone(),
            Samples::U8(v) => v.iter().map(|&s| s.to_f32()).collect(),
            Samples::I16(v) => v.iter().map(|&s| s.to_f32()).collect(),
            Samples::U16(v) => v.iter().map(|&s| s.to_f32()).collect(),
        }
    }
}

fn samples(n: usize) -> impl Strategy<Value = Samples> {
    use prop::collection::vec;
    prop_oneof![
        4 => f32_samples(n).prop_map(Samples::F32),
        1 => vec(prop_oneof![3 => 0u8..4, 1 => any::<u8>()], n).prop_map(Samples::U8),
        1 => vec(prop_oneof![3 => -2i16..3, 1 => any::<i16>()], n).prop_map(Samples::I16),
        1 => vec(prop_oneof![3 => 0u16..4, 1 => any::<u16>(), 1 => Just(u16::MAX)], n)
            .prop_map(Samples::U16),
    ]
}

/// Any finite `f32`, including subnormals and zeros.
fn finite_f32() -> impl Strategy<Value = f32> {
    use prop::num::f32::{NEGATIVE, NORMAL, POSITIVE, SUBNORMAL, ZERO};
    POSITIVE | NEGATIVE | NORMAL | SUBNORMAL | ZERO
}

#[derive(Debug, Clone)]
enum LevelSpec {
    /// The value of a sample (0.5 when that sample is not finite).
    Sample(Index),
    Value(f32),
}

fn level_spec() -> impl Strategy<Value = LevelSpec> {
    prop_oneof![
        4 => any::<Index>().prop_map(LevelSpec::Sample),
        2 => (-2i8..10).prop_map(|k| LevelSpec::Value(f32::from(k) * 0.5)),
        1 => (-20.0f32..20.0).prop_map(LevelSpec::Value),
        1 => finite_f32().prop_map(LevelSpec::Value),
    ]
}

fn resolve(specs: &[LevelSpec], vals: &[f32]) -> Vec<f32> {
    specs
        .iter()
        .map(|s| match s {
            LevelSpec::Sample(ix) if !vals.is_empty() => {
                let v = vals[ix.index(vals.len())];
                if v.is_finite() { v } else { 0.5 }
            }
            LevelSpec::Sample(_) => 0.5,
            LevelSpec::Value(v) => *v,
        })
        .collect()
}

#[derive(Debug, Clone)]
struct Case {
    nx: usize,
    ny: usize,
    samples: Samples,
    levels: Vec<LevelSpec>,
}

fn case(max: usize) -> impl Strategy<Value = Case> {
    (1..=max, 1..=max).prop_flat_map(|(nx, ny)| {
        (samples(nx * ny), prop::collection::vec(level_spec(), 1..=3))
            .prop_map(move |(samples, levels)| Case { nx, ny, samples, levels })
    })
}

// ---------------------------------------------------------------------------
// Running a case: the whole grid, and every subgrid on its own

#[derive(Debug)]
struct Cell {
    i: usize,
    j: usize,
    /// LL, LR, UR, UL.
    corners: [f32; 4],
    sub: Option<Subgrid>,
    out: Vec<(usize, Cmd)>,
}

#[derive(Debug)]
struct Run {
    nx: usize,
    ny: usize,
    vals: Vec<f32>,
    levels: Vec<f32>,
    log: Vec<(usize, Cmd)>,
    stats: ContourStats,
    cells: Vec<Cell>,
}

impl Run {
    fn val(&self, i: usize, j: usize) -> f32 {
        self.vals[j * self.nx + i]
    }

    fn cell(&self, i: usize, j: usize) -> &Cell {
        &self.cells[j * (self.nx - 1) + i]
    }
}

fn run_typed<T: Voxel>(data: &[T], nx: usize, ny: usize, levels: &[f32], traversal: Traversal) -> Run {
    let grid = Grid2::new(data, nx, ny).unwrap();
    let mut log = Log::default();
    let stats = contour_grid(&grid, levels, traversal, Point2::new, &mut log).unwrap();
    let vals: Vec<f32> = data.iter().map(|s| s.to_f32()).collect();
    let mut cells = vec![];
    for j in 0..ny - 1 {
        for i in 0..nx - 1 {
            let v = |i: usize, j: usize| vals[j * nx + i];
            let corners = [v(i, j), v(i + 1, j), v(i + 1, j + 1), v(i, j + 1)];
            let sub = Subgrid::new(corners[0], corners[1], corners[2], corners[3]).ok();
            let mut out = Log::default();
            if let Some(sub) = &sub {
                let sent =
                    contour_subgrid(sub, Placement::new(i, j), levels, traversal, &Point2::new, &mut out)
                        .unwrap();
                assert_eq!(sent, out.0.len() as u64);
            }
            cells.push(Cell { i, j, corners, sub, out: out.0 });
        }
    }
    Run { nx, ny, vals, levels: levels.to_vec(), log: log.0, stats, cells }
}

fn run_with(c: &Case, traversal: Traversal) -> Run {
    let levels = resolve(&c.levels, &c.samples.values());
    match &c.samples {
        Samples::F32(d) => run_typed(d, c.nx, c.ny, &levels, traversal),
        Samples::U8(d) => run_typed(d, c.nx, c.ny, &levels, traversal),
        Samples::I16(d) => run_typed(d, c.nx, c.ny, &levels, traversal),
        Samples::U16(d) => run_typed(d, c.nx, c.ny, &levels, traversal),
    }
}

fn run(c: &Case) -> Run {
    run_with(c, Traversal::Corrected)
}

// ---------------------------------------------------------------------------
// Geometry helpers

/// An edge's two ends in local cell coordinates and their node indices.
type EdgeGeom = ((f64, f64), (f64, f64), usize, usize);

/// The eight edges of a subgrid in local cell coordinates, with the node
/// indices (LL, LR, UR, UL, C) of their ends in canonical order.
const EDGES: [EdgeGeom; 8] = [
    ((0.0, 0.0), (1.0, 0.0), 0, 1), // B0
    ((1.0, 0.0), (1.0, 1.0), 1, 2), // B1
    ((0.0, 1.0), (1.0, 1.0), 3, 2), // B2
    ((0.0, 0.0), (0.0, 1.0), 0, 3), // B3
    ((0.0, 0.0), (0.5, 0.5), 0, 4), // S0
    ((1.0, 0.0), (0.5, 0.5), 1, 4), // S1
    ((1.0, 1.0), (0.5, 0.5), 2, 4), // S2
    ((0.0, 1.0), (0.5, 0.5), 3, 4), // S3
];

/// Geometric slack in grid units: coordinates up to 12 carry ~1e-6 of
/// rounding.
const GEOM_EPS: f64 = 1e-5;

/// Why the point `(u, v)` (local cell coordinates) is not a crossing of the
/// level on any edge of the subgrid with node values `vals`, or `None` when
/// it is one: within [`GEOM_EPS`] of the edge, where linear interpolation of
/// the edge's end values (in `f64`) is within 1e-4 of their range of the
/// level. The ends are the subgrid's own values, so the centre is the `f32`
/// mean the algorithm uses (checked against the exact mean separately).
/// This holds for all finite samples, not only moderate ones: the relative
/// tolerance absorbs the ~1e-6 grid-unit rounding of the placed point.
fn off_the_level(vals: [f32; 5], level: f32, u: f64, v: f64) -> Option<String> {
    let mut why = vec![];
    for (k, &((ax, ay), (bx, by), na, nb)) in EDGES.iter().enumerate() {
        let (dx, dy) = (bx - ax, by - ay);
        let len2 = dx * dx + dy * dy;
        let s = (((u - ax) * dx + (v - ay) * dy) / len2).clamp(0.0, 1.0);
        let (px, py) = (ax + s * dx, ay + s * dy);
        let dist = ((u - px).powi(2) + (v - py).powi(2)).sqrt();
        if dist > GEOM_EPS {
            continue;
        }
        let (va, vb) = (f64::from(vals[na]), f64::from(vals[nb]));
        let at = va + s * (vb - va);
        let tol = 1e-4 * (vb - va).abs();
        let err = (at - f64::from(level)).abs();
        if err <= tol {
            return None;
        }
        why.push(format!("edge #{k} at s={s}: value {at} (ends {va}, {vb}), |err| {err} > tol {tol}"));
    }
    Some(if why.is_empty() { "not on any edge".into() } else { why.join("; ") })
}

// ---------------------------------------------------------------------------
// a. Nothing panics

proptest! {
    #![proptest_config(config())]

    /// a. `contour_grid` over every sample type, both traversals, returns
    /// normally with consistent statistics.
    #[test]
    fn a_contour_grid_never_panics(c in case(12)) {
        for traversal in [Traversal::Corrected, Traversal::Literal] {
            let r = run_with(&c, traversal);
            prop_assert_eq!(r.stats.cells, ((r.nx - 1) * (r.ny - 1)) as u64);
            prop_assert_eq!(r.stats.commands, r.log.len() as u64);
            prop_assert!(r.stats.crossing_cells + r.stats.nonfinite_cells <= r.stats.cells);
        }
    }

    /// a. A strided view contours exactly as a contiguous copy of the same
    /// samples, and a view reaching past the data is refused.
    #[test]
    fn a_strided_views_match_copies(
        (nx, ny, sx, sy, offset, data) in (1usize..=8, 1usize..=8, 0usize..4, 0usize..14, 0usize..4, 0usize..3)
            .prop_flat_map(|(nx, ny, sx, sy, offset, extra)| {
                let need = offset + (nx - 1) * sx + (ny - 1) * sy + 1;
                (Just(nx), Just(ny), Just(sx), Just(sy), Just(offset), f32_samples(need + extra))
            }),
        specs in prop::collection::vec(level_spec(), 1..=3),
    ) {
        let levels = resolve(&specs, &data);
        let view = Grid2::strided(&data, offset, (nx, ny), (sx, sy)).unwrap();
        let copy: Vec<f32> = (0..ny)
            .flat_map(|j| (0..nx).map(move |i| (i, j)))
            .map(|(i, j)| view.get(i, j).unwrap())
            .collect();
        prop_assert_eq!(view.get(nx, 0), None);
        prop_assert_eq!(view.get(0, ny), None);
        let grid = Grid2::new(&copy, nx, ny).unwrap();
        let (mut a, mut b) = (Log::default(), Log::default());
        let sa = contour_grid(&view, &levels, Traversal::Corrected, Point2::new, &mut a).unwrap();
        let sb = contour_grid(&grid, &levels, Traversal::Corrected, Point2::new, &mut b).unwrap();
        prop_assert_eq!(sa, sb);
        let ka: Vec<_> = a.0.iter().map(|(l, c)| (*l, bits(c))).collect();
        let kb: Vec<_> = b.0.iter().map(|(l, c)| (*l, bits(c))).collect();
        prop_assert_eq!(ka, kb);

        let last = offset + (nx - 1) * sx + (ny - 1) * sy;
        let short = &data[..last];
        prop_assert_eq!(
            Grid2::strided(short, offset, (nx, ny), (sx, sy)),
            Err(GridError::OutOfBounds { last, len: last })
        );
    }

    /// a. Volumes along all three planes: no panic, points in voxel bounds
    /// on their slice, statistics consistent with an independent count.
    #[test]
    fn a_contour_volume_never_panics(
        (dims, samples) in (1usize..=6, 1usize..=6, 1usize..=6)
            .prop_flat_map(|d| (Just(d), samples(d.0 * d.1 * d.2))),
        specs in prop::collection::vec(level_spec(), 1..=2),
    ) {
        let levels = resolve(&specs, &samples.values());
        let (log, stats) = match &samples {
            Samples::F32(d) => run_volume(d, dims, &levels),
            Samples::U8(d) => run_volume(d, dims, &levels),
            Samples::I16(d) => run_volume(d, dims, &levels),
            Samples::U16(d) => run_volume(d, dims, &levels),
        };
        let (nx, ny, nz) = dims;
        let vals = samples.values();
        let v = |x: usize, y: usize, z: usize| vals[(z * ny + y) * nx + x];
        let (mut cells, mut nonfinite) = (0u64, 0u64);
        for plane in Plane::ALL {
            let (count, (nu, nv)) = match plane {
                Plane::XY => (nz, (nx, ny)),
                Plane::XZ => (ny, (nx, nz)),
                Plane::YZ => (nx, (ny, nz)),
            };
            for s in 0..count {
                for b in 0..nv.saturating_sub(1) {
                    for a in 0..nu.saturating_sub(1) {
                        cells += 1;
                        let at = |a: usize, b: usize| match plane {
                            Plane::XY => v(a, b, s),
                            Plane::XZ => v(a, s, b),
                            Plane::YZ => v(s, a, b),
                        };
                        let corners = [at(a, b), at(a + 1, b), at(a + 1, b + 1), at(a, b + 1)];
                        nonfinite += u64::from(!corners.iter().all(|c| c.is_finite()));
                    }
                }
            }
        }
        prop_assert_eq!(stats.cells, cells);
        prop_assert_eq!(stats.nonfinite_cells, nonfinite);
        prop_assert_eq!(stats.commands, log.len() as u64);
        for (slice, level, c) in &log {
            prop_assert!(*level < levels.len());
            let p = c.point();
            for (coord, n) in [(p.x, nx), (p.y, ny), (p.z, nz)] {
                prop_assert!(coord.is_finite() && coord >= 0.0 && coord <= (n - 1) as f32, "{:?} {:?}", slice, c);
            }
            let s = match slice.plane {
                Plane::XY => p.z,
                Plane::XZ => p.y,
                Plane::YZ => p.x,
            };
            prop_assert_eq!(s.to_bits(), (slice.index as f32).to_bits());
        }
    }

    /// a. A NaN or infinite level is refused before anything is drawn,
    /// naming the first bad level.
    #[test]
    fn a_nonfinite_levels_are_rejected(
        c in case(6),
        bad in prop::collection::vec(
            (any::<Index>(), prop::sample::select(vec![f32::NAN, f32::INFINITY, f32::NEG_INFINITY])),
            1..=2,
        ),
    ) {
        let mut levels = resolve(&c.levels, &c.samples.values());
        for (ix, b) in &bad {
            let at = ix.index(levels.len() + 1);
            levels.insert(at, *b);
        }
        let first = levels.iter().position(|l| !l.is_finite()).unwrap();
        let data = c.samples.values();
        let grid = Grid2::new(&data, c.nx, c.ny).unwrap();
        let mut log = Log::default();
        let got = contour_grid(&grid, &levels, Traversal::Corrected, Point2::new, &mut log);
        prop_assert_eq!(got, Err(ContourError::NonFiniteLevel { index: first }));
        prop_assert!(log.0.is_empty());

        let volume = Volume::new(&data, c.nx, c.ny, 1).unwrap();
        let mut vlog = VolLog::default();
        let got = contour_volume(&volume, Planes::ALL, &levels, Traversal::Corrected, &mut vlog);
        prop_assert_eq!(got, Err(ContourError::NonFiniteLevel { index: first }));
        prop_assert!(vlog.0.is_empty());
    }

    /// `contour_grid` emits, level by level, exactly the commands of its
    /// subgrids contoured one by one in row order, which ties the
    /// per-subgrid properties below to the whole-grid output.
    #[test]
    fn grid_output_is_the_concatenation_of_its_subgrids(c in case(12)) {
        let r = run(&c);
        for l in 0..r.levels.len() {
            let grid: Vec<_> = r.log.iter().filter(|(li, _)| *li == l).map(|(_, c)| bits(c)).collect();
            let cells: Vec<_> = r
                .cells
                .iter()
                .flat_map(|cell| cell.out.iter())
                .filter(|(li, _)| *li == l)
                .map(|(_, c)| bits(c))
                .collect();
            prop_assert_eq!(grid, cells, "level #{} = {}", l, r.levels[l]);
        }
    }

    /// b. Every emitted point lies on an edge of its subgrid (a border edge,
    /// a spoke or a node) and interpolates that edge to the level, for every
    /// finite subgrid (extreme and subnormal samples included). The centre
    /// node is the mean of the corners.
    #[test]
    fn b_points_lie_on_edges_at_the_level(c in case(12)) {
        let r = run(&c);
        for cell in &r.cells {
            let Some(sub) = &cell.sub else { continue };
            let vals = sub.values();
            let mean: f64 = cell.corners.iter().map(|&v| f64::from(v)).sum::<f64>() / 4.0;
            let scale = cell.corners.iter().fold(0.0f64, |m, &v| m.max(f64::from(v).abs()));
            let slack = 1e-6 * scale + 4.0 * f64::from(f32::from_bits(1));
            prop_assert!(
                (f64::from(vals[4]) - mean).abs() <= slack,
                "centre {} of {:?} is not their mean {}", vals[4], cell.corners, mean
            );
            for (l, cmd) in &cell.out {
                let level = r.levels[*l];
                let p = cmd.point();
                let (u, v) = (f64::from(p.x) - cell.i as f64, f64::from(p.y) - cell.j as f64);
                if let Some(why) = off_the_level(vals, level, u, v) {
                    prop_assert!(
                        false,
                        "cell ({}, {}) corners {:?} (centre {}) level {}: {:?} at local ({}, {}): {}",
                        cell.i, cell.j, cell.corners, vals[4], level, cmd, u, v, why
                    );
                }
            }
        }
    }

    /// c. Subgrids with a NaN or infinite corner are skipped, counted in
    /// `nonfinite_cells`, and draw nothing, also when contoured alone as a
    /// 2x2 strided view.
    #[test]
    fn c_nonfinite_cells_are_skipped_and_counted(c in case(12)) {
        let r = run(&c);
        let bad: Vec<&Cell> =
            r.cells.iter().filter(|cell| !cell.corners.iter().all(|v| v.is_finite())).collect();
        prop_assert_eq!(r.stats.nonfinite_cells, bad.len() as u64);
        prop_assert_eq!(r.stats.cells, r.cells.len() as u64);
        prop_assert_eq!(
            r.stats.crossing_cells,
            r.cells.iter().filter(|cell| !cell.out.is_empty()).count() as u64
        );
        let from_cells: usize = r.cells.iter().map(|cell| cell.out.len()).sum();
        prop_assert_eq!(r.stats.commands, from_cells as u64);
        for cell in bad {
            prop_assert!(cell.sub.is_none());
            let view = Grid2::strided(&r.vals, cell.j * r.nx + cell.i, (2, 2), (1, r.nx)).unwrap();
            let mut log = Log::default();
            let stats = contour_grid(&view, &r.levels, Traversal::Corrected, Point2::new, &mut log).unwrap();
            prop_assert!(log.0.is_empty());
            prop_assert_eq!(stats, ContourStats { cells: 1, nonfinite_cells: 1, ..ContourStats::default() });
        }
    }

    /// d. A crossing strictly inside an edge shared by two subgrids is emitted
    /// by both, bit-identically; a node at the level is emitted by every
    /// finite, non-constant subgrid around it.
    #[test]
    fn d_shared_edge_crossings_are_bit_identical(c in case(12)) {
        let r = run(&c);
        check_shared_edges(&r)?;
    }

    /// e. The command stream is tidy: a LineTo always continues a MoveTo or
    /// LineTo of the same subgrid and level, a MoveTo is always followed by
    /// a LineTo, and every point is finite and inside its subgrid (and the
    /// grid). Zero-length lines are checked separately below.
    #[test]
    fn e_command_stream_is_tidy(c in case(12)) {
        check_tidy(&run(&c), false)?;
    }

    /// e. No LineTo has zero length (it ends where the pen already is).
    ///
    /// Ignored: fails on a bug in core/src. `Pen::step` only drops a DRAWTO
    /// to the *same symbolic crossing*; distinct crossings whose placed
    /// coordinates round to the same `f32` point (a level within ~1e-7
    /// relative of a corner value, away from the grid origin) still come
    /// out as zero-length LineTo. See `e_zero_length_line_to_minimal_case`.
    #[test]
    fn e_no_zero_length_line_to(c in case(12)) {
        check_tidy(&run(&c), true)?;
    }

    /// d, for volumes: a crossing strictly inside a voxel edge is emitted
    /// bit-identically by the slices of both planes that contain the edge,
    /// so the chicken-wire x-y, x-z and y-z contours meet exactly.
    #[test]
    fn d_volume_slices_meet_exactly(
        (dims, data) in (2usize..=6, 2usize..=6, 2usize..=6)
            .prop_flat_map(|d| (Just(d), prop::collection::vec(f32_sample(1), d.0 * d.1 * d.2))),
        specs in prop::collection::vec(level_spec(), 1..=2),
    ) {
        let levels = resolve(&specs, &data);
        let (log, _) = run_volume(&data, dims, &levels);
        // Emitted point (bits) and level -> the planes that emitted it.
        let mut seen: BTreeMap<(usize, [u32; 3]), BTreeSet<Plane>> = BTreeMap::new();
        for (slice, level, cmd) in &log {
            let p = cmd.point();
            let xyz = [p.x, p.y, p.z];
            let integer: Vec<bool> = xyz.iter().map(|c| c.fract() == 0.0).collect();
            if integer.iter().filter(|&&b| b).count() != 2 {
                continue;
            }
            let axis = integer.iter().position(|&b| !b).unwrap();
            let f = f64::from(xyz[axis]);
            if (f - f.round()).abs() <= 1e-4 {
                continue; // too close to a voxel to tell a crossing from rounding
            }
            seen.entry((*level, xyz.map(f32::to_bits))).or_default().insert(slice.plane);
        }
        for ((level, xyz), planes) in &seen {
            let axis = (0..3).find(|&a| f32::from_bits(xyz[a]).fract() != 0.0).unwrap();
            let want: BTreeSet<Plane> = match axis {
                0 => [Plane::XY, Plane::XZ].into(),
                1 => [Plane::XY, Plane::YZ].into(),
                _ => [Plane::XZ, Plane::YZ].into(),
            };
            prop_assert_eq!(
                planes,
                &want,
                "level {} point {:?}",
                levels[*level],
                xyz.map(f32::from_bits)
            );
        }
    }
}

fn run_volume<T: Voxel>(
    data: &[T],
    (nx, ny, nz): (usize, usize, usize),
    levels: &[f32],
) -> (Vec<(SliceId, usize, Command<Point3>)>, ContourStats) {
    let volume = Volume::new(data, nx, ny, nz).unwrap();
    let mut log = VolLog::default();
    let stats = contour_volume(&volume, Planes::ALL, levels, Traversal::Corrected, &mut log).unwrap();
    (log.0, stats)
}

/// The tidiness rules of property e for one stream (one level of one grid
/// or subgrid), with the bounds its points must lie in.
fn tidy(stream: &[Cmd], (x0, x1): (f32, f32), (y0, y1): (f32, f32), zero_length: bool) -> Result<(), String> {
    let mut pen: Option<Point2> = None;
    for (k, c) in stream.iter().enumerate() {
        let p = *c.point();
        if !(p.x.is_finite() && p.y.is_finite() && x0 <= p.x && p.x <= x1 && y0 <= p.y && p.y <= y1) {
            return Err(format!("command #{k} {c:?} is outside [{x0}, {x1}] x [{y0}, {y1}]"));
        }
        match c {
            Command::MoveTo(_) => {
                if !matches!(stream.get(k + 1), Some(Command::LineTo(_))) {
                    return Err(format!("MoveTo #{k} is not followed by a LineTo: {stream:?}"));
                }
                pen = Some(p);
            }
            Command::LineTo(_) => {
                match pen {
                    None => return Err(format!("LineTo #{k} follows no MoveTo/LineTo: {stream:?}")),
                    Some(from) if zero_length && from.x == p.x && from.y == p.y => {
                        return Err(format!("LineTo #{k} has zero length: {stream:?}"));
                    }
                    Some(_) => {}
                }
                pen = Some(p);
            }
            Command::Point(_) => pen = None,
        }
    }
    Ok(())
}

/// Property e on one run: every level of the whole grid and of each
/// subgrid; `zero_length` also refuses zero-length LineTo.
fn check_tidy(r: &Run, zero_length: bool) -> Result<(), TestCaseError> {
    let (w, h) = ((r.nx - 1) as f32, (r.ny - 1) as f32);
    for l in 0..r.levels.len() {
        let stream: Vec<Cmd> = r.log.iter().filter(|(li, _)| *li == l).map(|(_, c)| *c).collect();
        tidy(&stream, (0.0, w), (0.0, h), zero_length)
            .map_err(|e| TestCaseError::fail(format!("grid, level {}: {e}", r.levels[l])))?;
        for cell in &r.cells {
            let stream: Vec<Cmd> = cell.out.iter().filter(|(li, _)| *li == l).map(|(_, c)| *c).collect();
            let (x0, y0) = (cell.i as f32, cell.j as f32);
            tidy(&stream, (x0, x0 + 1.0), (y0, y0 + 1.0), zero_length).map_err(|e| {
                TestCaseError::fail(format!(
                    "cell ({}, {}) corners {:?} level {}: {e}",
                    cell.i, cell.j, cell.corners, r.levels[l]
                ))
            })?;
        }
    }
    Ok(())
}

/// The smallest input found for the zero-length LineTo bug (see
/// `e_no_zero_length_line_to`): one 2x2 subgrid, UR = 0 and the other
/// corners 1, at level 1e-8. The crossings on B1, S2 and B2 all lie within
/// 1e-8 of UR = (1, 1) and are placed exactly there, so the stream is
/// `M(1,1) L(1,1) L(1,1)`; a single `P(1,1)` (or nothing) is expected.
#[test]
fn e_zero_length_line_to_minimal_case() {
    // Grid rows: (LL, LR), then (UL, UR).
    let data = [1.0f32, 1.0, 1.0, 0.0];
    let grid = Grid2::new(&data, 2, 2).unwrap();
    let mut log = Log::default();
    contour_grid(&grid, &[1e-8], Traversal::Corrected, Point2::new, &mut log).unwrap();
    let stream: Vec<Cmd> = log.0.iter().map(|(_, c)| *c).collect();
    tidy(&stream, (0.0, 1.0), (0.0, 1.0), true).unwrap();
}

/// Property d on one run.
fn check_shared_edges(r: &Run) -> Result<(), TestCaseError> {
    const NEAR_NODE: f64 = 1e-4;
    // The points of `cell` at `level` strictly inside (away from the ends
    // by more than NEAR_NODE) the grid edge from (x, y) along `axis`.
    let inside = |cell: &Cell, level: usize, (x, y): (usize, usize), axis: usize| -> BTreeSet<(u32, u32)> {
        let (fx, fy) = (x as f32, y as f32);
        cell.out
            .iter()
            .filter(|(l, _)| *l == level)
            .map(|(_, c)| *c.point())
            .filter(|p| {
                let (fixed, along, start) = if axis == 0 { (p.y == fy, p.x, x) } else { (p.x == fx, p.y, y) };
                let t = f64::from(along) - start as f64;
                fixed && t > NEAR_NODE && t < 1.0 - NEAR_NODE
            })
            .map(|p| (p.x.to_bits(), p.y.to_bits()))
            .collect()
    };
    for l in 0..r.levels.len() {
        let level = r.levels[l];
        // Interior vertical edges x = i (between cells i-1 and i), then
        // interior horizontal edges y = j (between cells j-1 and j).
        let mut shared = vec![];
        for j in 0..r.ny.saturating_sub(1) {
            for i in 1..r.nx.saturating_sub(1) {
                shared.push(((i, j), 1, r.cell(i - 1, j), r.cell(i, j)));
            }
        }
        for j in 1..r.ny.saturating_sub(1) {
            for i in 0..r.nx.saturating_sub(1) {
                shared.push(((i, j), 0, r.cell(i, j - 1), r.cell(i, j)));
            }
        }
        for ((x, y), axis, a, b) in shared {
            if a.sub.is_none() || b.sub.is_none() {
                continue;
            }
            let (pa, pb) = (inside(a, l, (x, y), axis), inside(b, l, (x, y), axis));
            let ctx = || {
                format!(
                    "level {level}, edge from ({x}, {y}) along {}: cell ({}, {}) {:?} emits {:?}, cell ({}, {}) {:?} emits {:?}",
                    if axis == 0 { 'x' } else { 'y' },
                    a.i,
                    a.j,
                    a.corners,
                    pa.iter().map(|&(x, y)| (f32::from_bits(x), f32::from_bits(y))).collect::<Vec<_>>(),
                    b.i,
                    b.j,
                    b.corners,
                    pb.iter().map(|&(x, y)| (f32::from_bits(x), f32::from_bits(y))).collect::<Vec<_>>(),
                )
            };
            prop_assert!(pa == pb, "{}", ctx());
            // One crossing when the edge straddles the level well inside.
            let (va, vb) =
                if axis == 0 { (r.val(x, y), r.val(x + 1, y)) } else { (r.val(x, y), r.val(x, y + 1)) };
            let (va, vb, k) = (f64::from(va), f64::from(vb), f64::from(level));
            let straddles = va.min(vb) < k && k < va.max(vb);
            let s = (k - va) / (vb - va);
            if !straddles {
                prop_assert!(pa.is_empty(), "{}", ctx());
            } else if s > 2.0 * NEAR_NODE && s < 1.0 - 2.0 * NEAR_NODE {
                prop_assert_eq!(pa.len(), 1, "{}", ctx());
            }
        }
        // Nodes at the level: every finite, non-constant subgrid around them
        // emits them.
        for cell in &r.cells {
            let Some(sub) = &cell.sub else { continue };
            if sub.is_constant() {
                continue;
            }
            for (k, (di, dj)) in [(0, 0), (1, 0), (1, 1), (0, 1)].into_iter().enumerate() {
                if cell.corners[k] != level {
                    continue;
                }
                let (nx, ny) = ((cell.i + di) as f32, (cell.j + dj) as f32);
                let hit = cell.out.iter().any(|(li, c)| {
                    *li == l && c.point().x.to_bits() == nx.to_bits() && c.point().y.to_bits() == ny.to_bits()
                });
                prop_assert!(
                    hit,
                    "cell ({}, {}) corners {:?} at level {} does not emit node ({}, {}): {:?}",
                    cell.i,
                    cell.j,
                    cell.corners,
                    level,
                    nx,
                    ny,
                    cell.out
                );
            }
        }
    }
    Ok(())
}

/// No subgrid yields more than [`MAX_COMMANDS_A_CELL`] commands at one
/// level, by any traversal: every subgrid of corners in `0..=6`, at every
/// level on a quarter step (so nodes at the level, centre included, and
/// levels between them). The engine sizes a row's room by it. Eight are
/// reached: the bound is the least that holds.
#[test]
fn no_subgrid_yields_more_than_max_commands_a_cell_at_a_level() {
    use isoscope_core::command::CountingSink;
    use isoscope_core::contour::MAX_COMMANDS_A_CELL;
    let mut most = 0;
    for t in [Traversal::Compiled, Traversal::Corrected, Traversal::Literal] {
        for code in 0..7u32.pow(4) {
            let c = |k: u32| ((code / 7u32.pow(k)) % 7) as f32;
            let sub = Subgrid::new(c(0), c(1), c(2), c(3)).unwrap();
            for q in 0..=24 {
                let mut n = CountingSink::default();
                contour_subgrid(&sub, Placement::new(0, 0), &[q as f32 / 4.0], t, &Point2::new, &mut n)
                    .unwrap();
                assert!(n.total() as usize <= MAX_COMMANDS_A_CELL, "{t:?} {code} {q}: {}", n.total());
                most = most.max(n.total() as usize);
            }
        }
    }
    assert_eq!(most, MAX_COMMANDS_A_CELL);
}
