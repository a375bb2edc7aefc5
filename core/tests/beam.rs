//! The beam scheduler drawn on the mock DAC, and its properties.
//!
//! ASCII pictures: a square (a closed polyline), a diamond and an octagon
//! (closed contours), a single point, a real contour of a grid, and where
//! the blanked beam goes.
//!
//! Properties over random command streams (NaN, infinities, huge values,
//! random mixes of `MoveTo / LineTo / Point`, empty streams) and random
//! configurations (valid ones, and garbage that the scheduler sanitizes):
//!
//! - a. nothing panics, the scheduler ends within a computable bound and
//!   stays ended, every code is in range, the last sample is blanked;
//! - b. an independent model of the documented semantics predicts the lit
//!   samples exactly: dwells at the right codes and counts, and each
//!   segment of length `L` in `ceil(L / lit_step)` samples on the segment,
//!   at most `lit_step + sqrt(2)` apart, ending on its end point; blanked
//!   samples only at targets;
//! - c. every point of every segment is within `lit_step / 2 + sqrt(2)/2`
//!   of a lit sample (the lines are covered, no gaps);
//! - d. the statistics match the input (lengths, counts, samples);
//! - e. the mock DAC takes exactly the in-range samples.

use isoscope_core::beam::replay::{Kept, Replay};
use isoscope_core::beam::{
    BeamConfig, FrameStats, MIN_LIT_STEP, Park, Scheduler, Spacing, fit_spacing, frame_stats, park_samples,
};
use isoscope_core::command::{Command, CommandSink, Point2};
use isoscope_core::contour::contour_grid;
use isoscope_core::contour::grid::Grid2;
use isoscope_core::contour::trace::Traversal;
use isoscope_core::output::mock::{MockDac, MockDacError};
use isoscope_core::output::{Beam, Dac, RunSink, Sample, SampleSource, Samples, Steps};
use isoscope_core::view::ScreenPoint;
use proptest::prelude::*;
use std::collections::HashMap;
use std::convert::Infallible;

type Cmd = Command<ScreenPoint>;

fn m(x: f32, y: f32) -> Cmd {
    Command::MoveTo(ScreenPoint::new(x, y))
}
fn l(x: f32, y: f32) -> Cmd {
    Command::LineTo(ScreenPoint::new(x, y))
}
fn p(x: f32, y: f32) -> Cmd {
    Command::Point(ScreenPoint::new(x, y))
}

/// 4-bit DAC, one LSB per lit step: on a 16 x 16 canvas every code is one
/// cell and lines are solid.
fn cfg4() -> BeamConfig {
    BeamConfig { bits: 4, lit_step: 1.0, ..BeamConfig::default() }
}

fn draw<const W: usize, const H: usize>(dac: &mut MockDac<W, H>, cmds: &[Cmd], cfg: &BeamConfig) {
    dac.write(Scheduler::new(cmds.iter().copied(), cfg)).unwrap();
    assert_eq!(dac.last_sample().map(|s| s.beam), Some(Beam::Off), "the frame must end blanked");
}

// ---------------------------------------------------------------------------
// Pictures

#[test]
fn square_closed_polyline() {
    let mut dac = MockDac::<16, 16>::new(4);
    draw(&mut dac, &[m(2.0, 2.0), l(13.0, 2.0), l(13.0, 13.0), l(2.0, 13.0), l(2.0, 2.0)], &cfg4());
    #[rustfmt::skip]
    dac.assert_eq(&[
        "",
        "",
        "  ############",
        "  #          #",
        "  #          #",
        "  #          #",
        "  #          #",
        "  #          #",
        "  #          #",
        "  #          #",
        "  #          #",
        "  #          #",
        "  #          #",
        "  ############",
        "",
        "",
    ]);
    // 4 x 11 LSB at 1 LSB a sample, 2 at the start, 3 corners, 1 at the end.
    assert_eq!(dac.lit_samples(), 44 + 2 + 3 + 1);
}

#[test]
fn diamond_closed_contour() {
    let mut dac = MockDac::<16, 16>::new(4);
    draw(&mut dac, &[m(8.0, 1.0), l(14.0, 7.0), l(8.0, 13.0), l(2.0, 7.0), l(8.0, 1.0)], &cfg4());
    #[rustfmt::skip]
    dac.assert_eq(&[
        "",
        "",
        "        #",
        "       # #",
        "      #   #",
        "     #     #",
        "    #       #",
        "   #         #",
        "  #           #",
        "   #         #",
        "    #       #",
        "     #     #",
        "      #   #",
        "       # #",
        "        #",
        "",
    ]);
}

#[test]
fn octagon_closed_contour_at_12_bits() {
    // A 12-bit DAC on a 32 x 16 canvas: 128 codes a column, 256 a row.
    let cfg = BeamConfig { lit_step: 8.0, ..BeamConfig::default() };
    // A regular octagon of radius 1700 around the centre, flat sides up,
    // down, left and right (vertices at 22.5 + 45 k degrees, rounded).
    let (a, b) = (1571.0f32, 651.0f32);
    let v = [(a, b), (b, a), (-b, a), (-a, b), (-a, -b), (-b, -a), (b, -a), (a, -b), (a, b)];
    let mut cmds: Vec<Cmd> = v.iter().map(|&(x, y)| l(2048.0 + x, 2048.0 + y)).collect();
    cmds[0] = m(2048.0 + a, 2048.0 + b);
    let mut dac = MockDac::<32, 16>::new(12);
    draw(&mut dac, &cmds, &cfg);
    #[rustfmt::skip]
    dac.assert_eq(&[
        "",
        "          ############",
        "        ###          ###",
        "      ###              ###",
        "    ###                  ###",
        "   ##                      ##",
        "   #                        #",
        "   #                        #",
        "   #                        #",
        "   #                        #",
        "   ##                      ##",
        "    ###                  ###",
        "      ###              ###",
        "        ###          ###",
        "          ############",
    ]);
    // With 45 degree turns and the default 60 degree threshold: one run
    // of steps 8 LSB apart along the whole outline, no corner dwell, only
    // the start and end dwells (per side, each would take ceil(1300.6 / 8)
    // = 163: 1304).
    let st = frame_stats(cmds.iter().copied(), &cfg);
    let length: f32 = cmds.windows(2).map(|w| w[0].point().distance(*w[1].point())).sum();
    let steps = (length / 8.0).ceil() as u64;
    assert_eq!(steps, 1302);
    assert_eq!(st.lit_samples, steps + 2 + 1);
    assert_eq!(st.polylines, 1);
}

#[test]
fn single_point() {
    let mut dac = MockDac::<16, 16>::new(4);
    draw(&mut dac, &[p(5.0, 10.0)], &cfg4());
    #[rustfmt::skip]
    dac.assert_eq(&[
        "",
        "",
        "",
        "",
        "",
        "     #",
    ]);
    // Jump there and back (both 11.2 LSB: 3 samples each), 4 lit.
    assert_eq!((dac.samples(), dac.lit_samples()), (3 + 4 + 3, 4));
    assert_eq!(cfg4().settle_samples(125f32.sqrt()), 3);
}

#[test]
fn blanked_beam_goes_only_to_targets_and_park() {
    // Blanked samples shown: the jumps land on the targets (no streaks), and
    // the frame returns to the park position.
    let cfg = BeamConfig { park: Park { x: 15, y: 0, return_at_end: true }, ..cfg4() };
    let mut dac = MockDac::<16, 8>::new(4).with_blank(true);
    draw(&mut dac, &[p(2.0, 14.0), m(4.0, 8.0), l(10.0, 8.0), m(12.0, 4.0), m(1.0, 1.0)], &cfg);
    #[rustfmt::skip]
    dac.assert_eq(&[
        "  #",
        "",
        "",
        "    #######",
        "",
        "",
        "",
        "               .",
    ]);
}

#[test]
fn contour_of_a_grid_drawn_through_the_scheduler() {
    // A bowl sampled on a 7 x 7 grid, contoured at one level: a closed ring
    // of fragments, two points per subgrid, straight from `contour_grid`.
    struct Screen(Vec<Cmd>);
    impl CommandSink<Point2> for Screen {
        type Error = Infallible;
        fn command(&mut self, _: usize, c: Command<Point2>) -> Result<(), Infallible> {
            self.0.push(c.map(|q| ScreenPoint::new(q.x * 5.0 + 1.0, q.y * 5.0 + 1.0)));
            Ok(())
        }
    }
    let samples: Vec<f32> =
        (0..49).map(|i| ((i % 7) as f32 - 3.0).powi(2) + ((i / 7) as f32 - 3.0).powi(2)).collect();
    let grid = Grid2::new(&samples, 7, 7).unwrap();
    let mut sink = Screen(Vec::new());
    contour_grid(&grid, &[6.5], Traversal::Corrected, Point2::new, &mut sink).unwrap();
    let mut dac = MockDac::<32, 32>::new(5);
    draw(&mut dac, &sink.0, &BeamConfig { bits: 5, lit_step: 1.0, ..BeamConfig::default() });
    #[rustfmt::skip]
    dac.assert_eq(&[
        "",
        "",
        "                #",
        "           ###########",
        "         ##           #",
        "        ##             ##",
        "       #                ##",
        "      ##                  #",
        "      #                    #",
        "     #                     #",
        "    ##                      #",
        "    #                       #",
        "    #                       #",
        "    #                       #",
        "    #                       #",
        "    #                       ##",
        "    #                       #",
        "    #                       #",
        "    #                       #",
        "    #                       #",
        "     #                      #",
        "     #                     #",
        "     ##                   #",
        "      #                  #",
        "       ##                #",
        "         #              #",
        "          ##         ###",
        "           ##########",
    ]);
}

#[test]
fn park_samples_idle_blanked() {
    let cfg = BeamConfig::default();
    let mut dac = MockDac::<8, 8>::new(12).with_blank(true);
    dac.write(park_samples(&cfg, 1000)).unwrap();
    assert_eq!((dac.samples(), dac.lit_samples()), (1000, 0));
    dac.assert_eq(&["", "", "", "", "", "", "", "."]);
}

#[test]
fn tiny_lit_step_at_16_bits_is_bounded() {
    // lit_step 1e-30 is sanitized to MIN_LIT_STEP: the full diagonal takes
    // ceil(92680 * 64) samples, not 10^35.
    let cfg = BeamConfig { bits: 16, lit_step: 1e-30, ..BeamConfig::default() };
    let st = frame_stats([p(f32::INFINITY, 1e9), m(0.0, 0.0), l(1e9, 1e9)], &cfg);
    let diag = ScreenPoint::new(0.0, 0.0).distance(ScreenPoint::new(65535.0, 65535.0));
    assert_eq!(st.skipped, 1);
    assert_eq!(st.lit_samples, 2 + (diag / MIN_LIT_STEP).ceil() as u64 + 1);
    assert_eq!(st.lit_samples, 5_931_554);
}

// ---------------------------------------------------------------------------
// Properties

/// 256 cases per property (`PROPTEST_CASES` overrides), no regression files.
fn config() -> ProptestConfig {
    let cases =
        if std::env::var_os("PROPTEST_CASES").is_some() { ProptestConfig::default().cases } else { 256 };
    ProptestConfig { cases, failure_persistence: None, ..ProptestConfig::default() }
}

/// Any coordinate: mostly in range, often whole, sometimes wild.
fn any_coord(max: f32) -> impl Strategy<Value = f32> + Clone {
    prop_oneof![
        6 => 0.0..=max,
        3 => (0..=max as u32).prop_map(|v| v as f32),
        1 => -1e6f32..1e6,
        1 => prop::sample::select(vec![
            f32::NAN, f32::INFINITY, f32::NEG_INFINITY, f32::MAX, f32::MIN, -0.0, 1e-40, max + 0.5, -0.5,
        ]),
        1 => any::<f32>(),
    ]
}

/// A coordinate in range: whole (repeats, axis-aligned lines) or not.
fn in_range_coord(max: f32) -> impl Strategy<Value = f32> + Clone {
    prop_oneof![(0..=max as u32).prop_map(|v| v as f32), 0.0..=max]
}

fn commands(coord: impl Strategy<Value = f32> + Clone, n: usize) -> impl Strategy<Value = Vec<Cmd>> {
    prop::collection::vec((0..6u8, coord.clone(), coord), 0..n).prop_map(|v| {
        v.into_iter()
            .map(|(op, x, y)| {
                let q = ScreenPoint::new(x, y);
                // LineTo more often than the others: longer polylines.
                match op {
                    0 => Command::MoveTo(q),
                    1 => Command::Point(q),
                    _ => Command::LineTo(q),
                }
            })
            .collect()
    })
}

/// A valid configuration, 4 to 12 bits.
fn valid_config() -> impl Strategy<Value = BeamConfig> {
    (
        (4u8..=12, 0.5f32..64.0, 0.0f32..8.0, 0.0f32..0.05, 0u16..40),
        (1u16..4, 0u16..4, 0u16..4, 0.0f32..=180.0, 1u16..6),
        (any::<u16>(), any::<u16>(), any::<bool>()),
    )
        .prop_map(|((bits, lit_step, settle_base, settle_per_lsb, settle_max), dw, (px, py, ret))| {
            let max = (1u32 << bits) as u16 - 1;
            let (dwell_start, dwell_end, corner_dwell, corner_angle_deg, point_dwell) = dw;
            BeamConfig {
                bits,
                lit_step,
                settle_base,
                settle_per_lsb,
                settle_max,
                dwell_start,
                dwell_end,
                corner_dwell,
                corner_angle_deg,
                point_dwell,
                park: Park { x: px % (max + 1), y: py % (max + 1), return_at_end: ret },
                spacing: Spacing::PerRun,
            }
        })
}

/// Anything, including invalid values the scheduler must sanitize.
fn garbage_config() -> impl Strategy<Value = BeamConfig> {
    let float = || {
        prop::sample::select(vec![
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            -1.0,
            0.0,
            -0.0,
            1e-30,
            0.01,
            0.7,
            3.0,
            16.0,
            1e30,
        ])
    };
    (
        (
            prop::sample::select(vec![0u8, 1, 2, 3, 8, 12, 16, 17, 255]),
            float(),
            float(),
            float(),
            prop::sample::select(vec![0u16, 1, 32, 1000, u16::MAX]),
        ),
        (0u16..3, 0u16..3, 0u16..3, float(), 0u16..3),
        (any::<u16>(), any::<u16>(), any::<bool>(), any::<bool>()),
    )
        .prop_map(
            |((bits, lit_step, settle_base, settle_per_lsb, settle_max), dw, (x, y, ret, constant))| {
                let (dwell_start, dwell_end, corner_dwell, corner_angle_deg, point_dwell) = dw;
                BeamConfig {
                    bits,
                    lit_step,
                    settle_base,
                    settle_per_lsb,
                    settle_max,
                    dwell_start,
                    dwell_end,
                    corner_dwell,
                    corner_angle_deg: corner_angle_deg * 50.0,
                    point_dwell,
                    park: Park { x, y, return_at_end: ret },
                    spacing: if constant { Spacing::Constant } else { Spacing::PerRun },
                }
            },
        )
}

/// The scheduler's frame of `cmds` recorded (as picture 9) into `mem` as it
/// plays in runs, `chunks` samples at a time: the samples played, the
/// frame's statistics, and the replay.
fn record<'m>(
    cmds: &[Command<ScreenPoint>],
    cfg: &BeamConfig,
    chunks: &[usize],
    mem: &'m mut [u8],
    kept: &'m mut Kept,
) -> (Vec<Sample>, FrameStats, Replay<'m>) {
    let mut replay = Replay::new(mem, kept);
    let mut sch = Scheduler::new(cmds.iter().copied(), cfg);
    let mut rec = replay.record(9).expect("memory");
    let mut got = Vec::new();
    for &n in chunks.iter().cycle() {
        if rec.fill_runs(&mut sch, n, &mut Expand(&mut got)) < n {
            break;
        }
    }
    rec.finish(sch.stats());
    (got, sch.stats(), replay)
}

/// A [`RunSink`] writing each run out as samples; a run of steps is lit.
struct Expand<'a>(&'a mut Vec<Sample>);

impl RunSink for Expand<'_> {
    fn repeat(&mut self, s: Sample, n: usize) {
        self.0.extend(std::iter::repeat_n(s, n));
    }

    fn steps<S: Steps>(&mut self, steps: &mut S, n: usize) {
        for _ in 0..n {
            let (x, y) = steps.step();
            self.0.push(Sample::new(x, y, Beam::On));
        }
    }
}

/// An upper bound on the samples of a frame of `n` commands.
fn sample_bound(n: usize, cfg: &BeamConfig) -> u64 {
    let c = cfg.sanitized();
    let per = u64::from(c.segment_cap())
        + u64::from(c.settle_max.max(1))
        + u64::from(c.dwell_start.max(c.point_dwell))
        + u64::from(c.dwell_end.max(c.corner_dwell))
        + 1;
    (n as u64 + 1) * per
}

fn code(v: f32, max: u16) -> u16 {
    v.round().clamp(0.0, f32::from(max)) as u16
}

/// Distance from `q` to the segment `a b`, in f64.
fn dist_to_segment(q: (f64, f64), a: ScreenPoint, b: ScreenPoint) -> f64 {
    let (ax, ay, bx, by) = (f64::from(a.x), f64::from(a.y), f64::from(b.x), f64::from(b.y));
    let (dx, dy) = (bx - ax, by - ay);
    let len2 = dx * dx + dy * dy;
    let t = if len2 > 0.0 { (((q.0 - ax) * dx + (q.1 - ay) * dy) / len2).clamp(0.0, 1.0) } else { 0.0 };
    let (px, py) = (ax + t * dx, ay + t * dy);
    ((q.0 - px).powi(2) + (q.1 - py).powi(2)).sqrt()
}

fn sxy(s: &Sample) -> (f64, f64) {
    (f64::from(s.x), f64::from(s.y))
}

/// What the documented semantics predict for the lit samples, in order.
#[derive(Debug, Clone, Copy)]
enum Lit {
    /// `n` samples at one code.
    Dwell { at: (u16, u16), n: u64 },
    /// One lit step at `at` (exact, before rounding), on the segment `a b`,
    /// the segment's `k`-th (from 0).
    Step { at: (f64, f64), a: ScreenPoint, b: ScreenPoint, k: u32 },
}

/// The model's prediction: lit groups in order, blanked targets, stats.
type Model = (Vec<Lit>, Vec<(u16, u16)>, FrameStats);

/// The model: the module docs' semantics, re-implemented plainly for finite
/// in-range input. Returns the lit groups, the blanked targets, the stats,
/// or `None` when a vertex turns within 0.1 degrees of the threshold (the
/// float rounding of the two computations may disagree there: the
/// scheduler compares cosines in `f32`, coarse near 0 and 180 degrees), or
/// a step falls within a few thousandths of an LSB of a vertex (the
/// scheduler measures the path in `f32` with a square root good to about
/// 1e-6, so the step may fall on either side of it there).
fn model(cmds: &[Cmd], cfg: &BeamConfig) -> Option<Model> {
    let max = cfg.max_code();
    let c = |q: ScreenPoint| (code(q.x, max), code(q.y, max));
    // Cleaning: zero-length lines dropped; a LineTo without a pen starts a
    // polyline. Each polyline: start + vertices.
    enum Item {
        Poly(Vec<ScreenPoint>),
        Dot(ScreenPoint),
    }
    let mut items: Vec<Item> = Vec::new();
    let mut open: Option<Vec<ScreenPoint>> = None;
    for cmd in cmds {
        match *cmd {
            Command::MoveTo(q) => {
                items.extend(open.take().map(Item::Poly));
                open = Some(vec![q]);
            }
            Command::LineTo(q) => match open.as_mut() {
                Some(v) if *v.last().unwrap() == q => {}
                Some(v) => v.push(q),
                None => open = Some(vec![q]),
            },
            Command::Point(q) => {
                items.extend(open.take().map(Item::Poly));
                items.push(Item::Dot(q));
            }
        }
    }
    items.extend(open.take().map(Item::Poly));

    let mut lit = Vec::new();
    let mut targets = vec![(cfg.park.x, cfg.park.y)];
    let mut st = FrameStats::default();
    let mut pos = ScreenPoint::new(f32::from(cfg.park.x), f32::from(cfg.park.y));
    for item in &items {
        match item {
            Item::Dot(q) => {
                st.points += 1;
                st.blank_length += pos.distance(*q);
                targets.push(c(*q));
                lit.push(Lit::Dwell { at: c(*q), n: u64::from(cfg.point_dwell) });
                pos = *q;
            }
            Item::Poly(v) if v.len() < 2 => {}
            Item::Poly(v) => {
                st.polylines += 1;
                st.blank_length += pos.distance(v[0]);
                targets.push(c(v[0]));
                lit.push(Lit::Dwell { at: c(v[0]), n: u64::from(cfg.dwell_start) });
                // Steps wherever the path since the last lit sample
                // reaches `lit_step`; a run ends at a corner or the end,
                // with a sample there.
                let step = f64::from(cfg.lit_step);
                let mut ahead = step;
                for i in 1..v.len() {
                    let (a, b) = (v[i - 1], v[i]);
                    let len = a.distance(b);
                    st.lit_length += len;
                    let (ax, ay) = (f64::from(a.x), f64::from(a.y));
                    let (dx, dy) = (f64::from(b.x) - ax, f64::from(b.y) - ay);
                    let l = (dx * dx + dy * dy).sqrt();
                    let extra = match v.get(i + 1) {
                        None => Some(cfg.dwell_end),
                        Some(&n) => {
                            let t1 = f64::from(b.y - a.y).atan2(f64::from(b.x - a.x));
                            let t2 = f64::from(n.y - b.y).atan2(f64::from(n.x - b.x));
                            let mut turn = (t2 - t1).to_degrees().abs();
                            if turn > 180.0 {
                                turn = 360.0 - turn;
                            }
                            if (turn - f64::from(cfg.corner_angle_deg)).abs() < 0.1 {
                                return None;
                            }
                            (turn > f64::from(cfg.corner_angle_deg)).then_some(cfg.corner_dwell)
                        }
                    };
                    let tolerance = 4e-3 + 2e-6 * (l + step);
                    let (mut t, mut k) = (ahead, 0);
                    while t <= l + tolerance {
                        if (t - l).abs() <= tolerance {
                            return None;
                        }
                        lit.push(Lit::Step { at: (ax + dx * t / l, ay + dy * t / l), a, b, k });
                        t += step;
                        k += 1;
                    }
                    ahead = t - l;
                    if let Some(dwell) = extra {
                        lit.push(Lit::Dwell { at: c(b), n: 1 + u64::from(dwell) });
                        ahead = step;
                    }
                }
                pos = *v.last().unwrap();
            }
        }
    }
    if cfg.park.return_at_end {
        st.blank_length += pos.distance(ScreenPoint::new(f32::from(cfg.park.x), f32::from(cfg.park.y)));
    } else {
        // Blanked in place.
        targets.push(c(pos));
    }
    Some((lit, targets, st))
}

/// Lit samples within this of an input segment: rounding both coordinates
/// moves a point by at most sqrt(2)/2.
const ON_SEGMENT: f64 = 0.7072;

proptest! {
    #![proptest_config(config())]

    /// a. Any configuration, any commands: no panic, bounded, in range,
    /// blanked at the end, fused.
    #[test]
    fn never_panics_and_ends_blanked(cfg in garbage_config(), cmds in commands(any_coord(70000.0), 24)) {
        let bound = sample_bound(cmds.len(), &cfg);
        prop_assume!(bound <= 2_000_000);
        let max = cfg.sanitized().max_code();
        let mut sch = Scheduler::new(cmds.iter().copied(), &cfg);
        let samples: Vec<Sample> = sch.by_ref().take(bound as usize + 1).collect();
        prop_assert!(samples.len() as u64 <= bound, "{} samples > bound {}", samples.len(), bound);
        prop_assert_eq!(sch.next(), None);
        prop_assert_eq!(sch.next(), None);
        for s in &samples {
            prop_assert!(s.x <= max && s.y <= max, "{:?} out of 0..={}", s, max);
        }
        if let Some(last) = samples.last() {
            prop_assert_eq!(last.beam, Beam::Off);
        }
        let st = sch.stats();
        prop_assert_eq!(st.samples, samples.len() as u64);
        prop_assert_eq!(st.lit_samples, samples.iter().filter(|s| s.beam == Beam::On).count() as u64);
        prop_assert!(st.lit_length.is_finite() && st.blank_length.is_finite());
        prop_assert_eq!(st, frame_stats(cmds.iter().copied(), &cfg));
        // The mock DAC at the same resolution takes all of them.
        let mut dac = MockDac::<16, 8>::new(cfg.sanitized().bits);
        prop_assert_eq!(dac.write(samples.iter().copied()), Ok(()));
    }

    /// A frame recorded as it plays (in runs, in chunks of any size) is
    /// the scheduler's frame, and so is every replay of it, in chunks too;
    /// a replay reports the recorded frame's statistics.
    #[test]
    fn a_recorded_frame_replays_exactly(
        cfg in garbage_config(),
        cmds in commands(any_coord(5000.0), 24),
        chunks in prop::collection::vec(1usize..70, 1..12),
    ) {
        let bound = sample_bound(cmds.len(), &cfg);
        prop_assume!(bound <= 200_000);
        let want: Vec<Sample> = Scheduler::new(cmds.iter().copied(), &cfg).collect();
        let mut mem = vec![0u8; 8 * want.len() + 8];
        let mut kept = Kept::new();
        let (got, stats, replay) = record(&cmds, &cfg, &chunks, &mut mem, &mut kept);
        prop_assert_eq!(&got, &want);
        for _ in 0..2 {
            let mut player = replay.play(9).expect("kept");
            prop_assert_eq!(player.stats(), stats);
            let mut again = Vec::new();
            for &n in chunks.iter().rev().cycle() {
                if player.fill_runs(n, &mut Expand(&mut again)) < n {
                    break;
                }
            }
            prop_assert_eq!(&again, &want);
        }
        // One byte short: played whole all the same, and not kept.
        let need = replay.len();
        if need == 0 {
            prop_assert!(want.is_empty());
            return Ok(());
        }
        let mut mem = vec![0u8; need - 1];
        let mut kept = Kept::new();
        let (got, _, replay) = record(&cmds, &cfg, &chunks, &mut mem, &mut kept);
        prop_assert_eq!(&got, &want);
        prop_assert!(replay.play(9).is_none());
        prop_assert!(replay.too_long(9));
        prop_assert!(replay.too_long(9));
    }

    /// Filling in runs (as the firmware refills its DMA halves, in chunks
    /// of any size, mixed with single `next`s) gives the iterator's
    /// samples, statistics and end, and so does `Samples` over any
    /// iterator.
    #[test]
    fn fill_equals_the_iterator(
        cfg in garbage_config(),
        cmds in commands(any_coord(5000.0), 24),
        chunks in prop::collection::vec(0usize..70, 1..12),
    ) {
        let bound = sample_bound(cmds.len(), &cfg);
        prop_assume!(bound <= 2_000_000);
        let want: Vec<Sample> = Scheduler::new(cmds.iter().copied(), &cfg).collect();
        let mut sch = Scheduler::new(cmds.iter().copied(), &cfg);
        let mut got = Vec::new();
        let mut buf = [Sample::default(); 70];
        for (i, &n) in chunks.iter().cycle().enumerate() {
            let ended = match i % 4 {
                3 => {
                    let before = got.len();
                    let k = sch.fill_runs(n, &mut Expand(&mut got));
                    prop_assert_eq!(got.len() - before, k);
                    prop_assert!(k <= n);
                    k < n
                }
                0 => {
                    let k = sch.fill(&mut buf[..n]);
                    got.extend_from_slice(&buf[..k]);
                    k < n
                }
                1 => {
                    let k = sch.fill_with(n, |s| got.push(s));
                    prop_assert!(k <= n);
                    k < n
                }
                _ => sch.next().map(|s| got.push(s)).is_none(),
            };
            if ended {
                break;
            }
            prop_assert!(got.len() <= want.len(), "{} samples, more than the iterator's {}", got.len(), want.len());
        }
        prop_assert_eq!(&got, &want);
        prop_assert_eq!(sch.fill_with(5, |_| ()), 0, "it stays ended");
        prop_assert_eq!(sch.next(), None);
        prop_assert_eq!(sch.stats(), frame_stats(cmds.iter().copied(), &cfg));
        // Skipping the rest after a few samples counts what it skipped.
        let mut skip = Scheduler::new(cmds.iter().copied(), &cfg);
        skip.fill_with(chunks[0], |_| ());
        skip.skip_to_end();
        prop_assert_eq!(skip.stats(), sch.stats());
        prop_assert_eq!(skip.next(), None);
        prop_assert_eq!(skip.position(), sch.position());
        let mut it = Samples(want.iter().copied());
        let mut again = Vec::new();
        while it.fill_with(7, |s| again.push(s)) == 7 {}
        prop_assert_eq!(again, want);
    }

    /// a. Valid configurations, wild coordinates: the same, plus only
    /// finite points are drawn.
    #[test]
    fn wild_coordinates(cfg in valid_config(), cmds in commands(any_coord(4095.0), 40)) {
        let max = cfg.max_code();
        let samples: Vec<Sample> = Scheduler::new(cmds.iter().copied(), &cfg).collect();
        prop_assert!(samples.len() as u64 <= sample_bound(cmds.len(), &cfg));
        prop_assert!(samples.iter().all(|s| s.x <= max && s.y <= max));
        prop_assert!(samples.last().is_none_or(|s| s.beam == Beam::Off));
        let st = frame_stats(cmds.iter().copied(), &cfg);
        let nonfinite = cmds.iter().filter(|c| !(c.point().x.is_finite() && c.point().y.is_finite())).count();
        prop_assert_eq!(st.skipped as usize, nonfinite);
        // Clamping first, the frame is the frame of the clamped finite
        // points with polylines broken at the skipped ones.
        let f = f32::from(max);
        let clamped: Vec<Cmd> = cmds
            .iter()
            .map(|c| {
                c.map(|q| {
                    if q.x.is_finite() && q.y.is_finite() {
                        ScreenPoint::new(q.x.clamp(0.0, f), q.y.clamp(0.0, f))
                    } else {
                        q
                    }
                })
            })
            .collect();
        let again: Vec<Sample> = Scheduler::new(clamped.iter().copied(), &cfg).collect();
        prop_assert_eq!(&samples, &again);
    }

    /// b, d. In-range input: the model predicts every lit sample.
    #[test]
    fn lit_samples_follow_the_model(cfg in valid_config(), cmds in commands(in_range_coord(4095.0), 40)) {
        let max = cfg.max_code();
        let f = f32::from(max);
        let cmds: Vec<Cmd> = cmds.into_iter().map(|c| c.map(|q| ScreenPoint::new(q.x.min(f), q.y.min(f)))).collect();
        let Some((groups, targets, want)) = model(&cmds, &cfg) else { return Err(TestCaseError::reject("ambiguous corner or step count")) };
        let samples: Vec<Sample> = Scheduler::new(cmds.iter().copied(), &cfg).collect();
        let lit: Vec<Sample> = samples.iter().copied().filter(|s| s.beam == Beam::On).collect();
        let mut it = lit.iter();
        let mut prev: Option<Sample> = None;
        for g in &groups {
            match *g {
                Lit::Dwell { at, n } => {
                    for _ in 0..n {
                        let s = it.next();
                        prop_assert_eq!(s.map(|s| (s.x, s.y)), Some(at), "dwell of {:?}", g);
                        prev = s.copied();
                    }
                }
                Lit::Step { at, a, b, k } => {
                    // Each step lags its exact place by under 1/32768 LSB a
                    // coordinate (the module docs).
                    let lag = f64::from(k + 1) * 2f64.sqrt() / 32768.0;
                    let from = prev.unwrap();
                    let s = *it.next().unwrap();
                    let off = ((f64::from(s.x) - at.0).powi(2) + (f64::from(s.y) - at.1).powi(2)).sqrt();
                    prop_assert!(off <= ON_SEGMENT + lag + 1e-3, "{:?} is {} from {:?}", s, off, g);
                    prop_assert!(dist_to_segment(sxy(&s), a, b) <= ON_SEGMENT + lag + 1e-3, "{:?} off {:?}", s, g);
                    let step = ((f64::from(s.x) - f64::from(from.x)).powi(2)
                        + (f64::from(s.y) - f64::from(from.y)).powi(2)).sqrt();
                    prop_assert!(step <= f64::from(cfg.lit_step) + 2f64.sqrt() + 1e-3,
                        "step {} > {} + sqrt 2 at {:?}", step, cfg.lit_step, g);
                    prev = Some(s);
                }
            }
        }
        prop_assert_eq!(it.next(), None, "more lit samples than the model");
        // Blanked samples only at targets.
        for s in samples.iter().filter(|s| s.beam == Beam::Off) {
            prop_assert!(targets.contains(&(s.x, s.y)), "blanked sample {:?} not at a target", s);
        }
        prop_assert!(samples.last().is_none_or(|s| s.beam == Beam::Off));
        // Statistics.
        let st = frame_stats(cmds.iter().copied(), &cfg);
        prop_assert_eq!((st.polylines, st.points, st.skipped), (want.polylines, want.points, 0));
        prop_assert!((st.lit_length - want.lit_length).abs() <= 1e-4 * want.lit_length.max(1.0),
            "lit_length {} vs {}", st.lit_length, want.lit_length);
        prop_assert!((st.blank_length - want.blank_length).abs() <= 1e-4 * want.blank_length.max(1.0),
            "blank_length {} vs {}", st.blank_length, want.blank_length);
        prop_assert_eq!(st.lit_samples, lit.len() as u64);
        prop_assert_eq!(st.samples, samples.len() as u64);
        let fps = st.fps(1e6);
        let want_fps = if st.samples == 0 { 0.0 } else { 1e6 / st.samples as f32 };
        prop_assert!((fps - want_fps).abs() <= 1e-3 * want_fps, "fps {} vs {}", fps, want_fps);
    }

    /// c. No gaps: every point of every input segment is near a lit sample.
    #[test]
    fn segments_are_covered(
        cfg in valid_config(),
        constant in any::<bool>(),
        cmds in commands(in_range_coord(4095.0), 30),
    ) {
        let cfg = if constant { BeamConfig { spacing: Spacing::Constant, ..cfg } } else { cfg };
        let f = f32::from(cfg.max_code());
        let cmds: Vec<Cmd> = cmds.into_iter().map(|c| c.map(|q| ScreenPoint::new(q.x.min(f), q.y.min(f)))).collect();
        let lit: Vec<Sample> =
            Scheduler::new(cmds.iter().copied(), &cfg).filter(|s| s.beam == Beam::On).collect();
        // Buckets at least `reach` wide: the neighbouring buckets suffice.
        let reach = f64::from(cfg.lit_step) / 2.0 + ON_SEGMENT;
        let bucket = (2.0 * reach).ceil().max(1.0) as i64;
        let mut grid: HashMap<(i64, i64), Vec<(f64, f64)>> = HashMap::new();
        for s in &lit {
            let q = sxy(s);
            grid.entry((q.0 as i64 / bucket, q.1 as i64 / bucket)).or_default().push(q);
        }
        let near = |q: (f64, f64)| {
            let (bx, by) = (q.0 as i64 / bucket, q.1 as i64 / bucket);
            (bx - 1..=bx + 1).any(|x| (by - 1..=by + 1).any(|y| {
                grid.get(&(x, y)).is_some_and(|v| v.iter().any(|s| ((s.0 - q.0).powi(2) + (s.1 - q.1).powi(2)).sqrt() <= reach + 1e-6))
            }))
        };
        let mut pen: Option<ScreenPoint> = None;
        for cmd in &cmds {
            match *cmd {
                Command::MoveTo(q) => pen = Some(q),
                Command::LineTo(b) => {
                    // A zero-length line draws nothing (module docs).
                    if let Some(a) = pen.filter(|&a| a != b) {
                        let len = f64::from(a.distance(b));
                        let steps = len.ceil() as usize + 1;
                        for i in 0..=steps {
                            let t = i as f64 / steps as f64;
                            let q = (f64::from(a.x) + t * f64::from(b.x - a.x), f64::from(a.y) + t * f64::from(b.y - a.y));
                            prop_assert!(near(q), "gap at {:?} on {:?} -> {:?}", q, a, b);
                        }
                    }
                    pen = Some(b);
                }
                Command::Point(q) => {
                    prop_assert!(near((f64::from(q.x), f64::from(q.y))), "point {:?} not drawn", q);
                    pen = None;
                }
            }
        }
    }

    /// f. Constant spacing: consecutive lit samples are at most `lit_step`
    /// (and rounding) apart unless a dwell repeats one; every polyline's
    /// start and end, and every dot, is drawn, in order; without corner
    /// dwells a frame takes its dwells and about its length over
    /// `lit_step` in lit samples (within one a polyline); `fit_spacing`
    /// finds a step that fits.
    #[test]
    fn constant_spacing(
        cfg in valid_config(),
        corner_dwell in 0u16..3,
        cmds in commands(in_range_coord(4095.0), 40),
        share in 0.05f64..1.0,
    ) {
        let cfg = BeamConfig { spacing: Spacing::Constant, corner_dwell, ..cfg };
        let max = cfg.max_code();
        let f = f32::from(max);
        let cmds: Vec<Cmd> = cmds.into_iter().map(|c| c.map(|q| ScreenPoint::new(q.x.min(f), q.y.min(f)))).collect();
        let samples: Vec<Sample> = Scheduler::new(cmds.iter().copied(), &cfg).collect();
        // Spacing, within runs of lit samples.
        for w in samples.windows(2) {
            if w[0].beam == Beam::On && w[1].beam == Beam::On {
                let d = ((f64::from(w[1].x) - f64::from(w[0].x)).powi(2) + (f64::from(w[1].y) - f64::from(w[0].y)).powi(2)).sqrt();
                prop_assert!(d <= f64::from(cfg.lit_step) + 2f64.sqrt() + 1e-3, "{:?} -> {:?}: {} apart", w[0], w[1], d);
            }
        }
        // Starts, ends and dots, in order: the cleaned polylines.
        let c = |q: ScreenPoint| (code(q.x, max), code(q.y, max));
        let mut want: Vec<(u16, u16)> = Vec::new();
        let (mut pen, mut start, mut drawn): (Option<ScreenPoint>, Option<ScreenPoint>, bool) = (None, None, false);
        let close = |want: &mut Vec<(u16, u16)>, start: Option<ScreenPoint>, pen: Option<ScreenPoint>, drawn: bool| {
            if let (true, Some(a), Some(b)) = (drawn, start, pen) {
                want.push(c(a));
                want.push(c(b));
            }
        };
        for cmd in &cmds {
            match *cmd {
                Command::MoveTo(q) => {
                    close(&mut want, start, pen, drawn);
                    (pen, start, drawn) = (Some(q), Some(q), false);
                }
                Command::LineTo(q) => match pen {
                    None => (pen, start, drawn) = (Some(q), Some(q), false),
                    Some(a) if a == q => {}
                    Some(_) => (pen, drawn) = (Some(q), true),
                },
                Command::Point(q) => {
                    close(&mut want, start, pen, drawn);
                    (pen, start, drawn) = (None, None, false);
                    want.push(c(q));
                }
            }
        }
        close(&mut want, start, pen, drawn);
        let mut lit = samples.iter().filter(|s| s.beam == Beam::On).map(|s| (s.x, s.y));
        for at in &want {
            prop_assert!(lit.any(|s| s == *at), "{:?} is not drawn (in order)", at);
        }
        // The count.
        let st = frame_stats(cmds.iter().copied(), &cfg);
        if corner_dwell == 0 {
            let dwells = u64::from(st.polylines) * u64::from(cfg.dwell_start + cfg.dwell_end)
                + u64::from(st.points) * u64::from(cfg.point_dwell);
            let steps = st.lit_samples as f64 - dwells as f64;
            let ideal = f64::from(st.lit_length) / f64::from(cfg.lit_step);
            prop_assert!((steps - ideal).abs() <= f64::from(st.polylines) + 1e-3 * ideal,
                "{} steps for {} LSB at {} a step over {} polylines", steps, st.lit_length, cfg.lit_step, st.polylines);
        }
        // Fitting a share of the samples.
        let budget = (st.samples as f64 * share) as u64;
        let fit = fit_spacing(cmds.iter().copied(), &cfg, budget);
        prop_assert!(fit.lit_step >= cfg.lit_step);
        let fitted = frame_stats(cmds.iter().copied(), &fit).samples;
        prop_assert!(fitted <= budget || fit.lit_step == (2.0 * (f + 1.0)).max(cfg.lit_step), "{} > {} at {}", fitted, budget, fit.lit_step);
    }

    /// e. The mock DAC takes exactly the samples in range, and stops at the
    /// first one out of range.
    #[test]
    fn mock_dac_range(bits in 1u8..=16, xs in prop::collection::vec((any::<u16>(), any::<u16>(), any::<bool>()), 0..50)) {
        let max = u16::MAX >> (16 - bits);
        let mut dac = MockDac::<20, 10>::new(bits).with_blank(true);
        let samples: Vec<Sample> =
            xs.iter().map(|&(x, y, on)| Sample::new(x, y, if on { Beam::On } else { Beam::Off })).collect();
        let first_bad = samples.iter().position(|s| s.x > max || s.y > max);
        let r = dac.write(samples.iter().copied());
        match first_bad {
            None => prop_assert_eq!(r, Ok(())),
            Some(i) => prop_assert_eq!(r, Err(MockDacError::OutOfRange { x: samples[i].x, y: samples[i].y })),
        }
        let played = first_bad.unwrap_or(samples.len());
        prop_assert_eq!(dac.samples(), played as u64);
        prop_assert_eq!(dac.lit_samples(), samples[..played].iter().filter(|s| s.beam == Beam::On).count() as u64);
        let marked = dac.picture().iter().flatten().filter(|&&b| b != b' ').count();
        prop_assert!(marked <= played && (played == 0) == (marked == 0));
    }
}
