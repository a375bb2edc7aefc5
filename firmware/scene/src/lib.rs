//! The firmware's built-in scene, in code that both the firmware and the
//! host compile: the hydrogen 3d_xy orbital (the paper's Figure 1) at 12^3,
//! contoured, projected, culled, stitched, ordered and played through the
//! beam scheduler in a refresh loop.
//!
//! `no_std`, no `alloc`, no `unsafe`: fixed-size [`Buffers`] (89 KB, a
//! `static` on the MCU) and the core's `libm` maths, so that the MCU and
//! the host compute bit-identical samples. The QEMU end-to-end test relies
//! on this: the firmware's DAC writes under QEMU must equal
//! [`qemu_sequence`] computed on the host, sample for sample.
//!
//! The pipeline mirrors the simulator's (`host-sim/src/scene.rs`): every
//! slice of every plane contoured in turn (`contour_slice`), projected with
//! [`ViewTransform::fit`] of the default view, optimised and ordered with
//! the default settings from the park position, then played as the
//! simulator's refresh loop (each frame starts where the last one ended,
//! without a trip to the park position).
#![no_std]
#![forbid(unsafe_code)]
#![warn(missing_docs)]
#![deny(clippy::panic, clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]

use isoscope_core::beam::{BeamConfig, Park, Scheduler, frame_stats};
use isoscope_core::command::{Command, Point3};
use isoscope_core::dac::Sample;
use isoscope_core::demo::Demo;
use isoscope_core::display::{DisplayList, OptimizeConfig, OptimizeStats, OrderConfig, OrderStats, Scratch};
use isoscope_core::grid::{GridError, Plane, Volume};
use isoscope_core::screen::ScreenPoint;
use isoscope_core::surface::{SliceId, SurfaceSink, contour_slice};
use isoscope_core::trace::Traversal;
use isoscope_core::view::{Bounds, View, ViewError, ViewTransform};

/// The built-in volume.
pub const DEMO: Demo = Demo::Hydrogen;
/// Its side, in samples (`SIDE`^3 voxels).
pub const SIDE: usize = 12;
/// Voxels of the volume.
pub const VOXELS: usize = SIDE * SIDE * SIDE;
/// Display list capacity, in points: the scene's 368 contour fragments have
/// 1,416 points before culling and stitching (898 after), checked by the
/// host-side test. (At 16^3 they would have 2,824: a list of 3,072 points
/// needs 96 KB of scratch, more than fits beside it in the 128 KB SRAM.)
pub const CAPACITY: usize = 2048;
/// Frames the firmware plays under QEMU before it exits.
pub const QEMU_FRAMES: usize = 2;

/// The display list of the scene.
pub type List = DisplayList<CAPACITY>;

/// Everything the scene needs, in fixed memory: the volume (6.9 KB), the
/// display list (18 KB) and its scratch (64 KB).
pub struct Buffers {
    /// The sampled volume, x fastest.
    pub volume: [f32; VOXELS],
    /// The display list, in drawing order once [`build`] has run.
    pub list: List,
    /// Scratch for optimising and ordering the list.
    pub scratch: Scratch<CAPACITY>,
}

impl Buffers {
    /// Zeroed buffers (a `const fn`, so they can be a `static`).
    pub const fn new() -> Self {
        Self { volume: [0.0; VOXELS], list: List::new(), scratch: Scratch::new() }
    }
}

impl Default for Buffers {
    fn default() -> Self {
        Self::new()
    }
}

/// Why the scene could not be built.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SceneError {
    /// Sampling the volume failed.
    Grid(GridError),
    /// The view could not be fitted.
    View(ViewError),
    /// Contouring a slice failed (a non-finite level or a bad slice index).
    Contour,
}

/// What building the scene did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Built {
    /// Contour fragments (polylines before stitching).
    pub fragments: usize,
    /// Points before culling and stitching.
    pub points_in: usize,
    /// Commands that did not fit in the display list (0 for the built-in
    /// scene).
    pub dropped: u64,
    /// Culling, stitching and merging.
    pub optimize: OptimizeStats,
    /// Ordering.
    pub order: OrderStats,
    /// Samples of one refresh-loop frame ([`refresh`]).
    pub frame_samples: u64,
    /// Lit samples of one frame.
    pub lit_samples: u64,
}

/// The beam settings: the core's defaults (12-bit DAC at 1 MS/s, park at
/// the corner `(0, 0)`).
pub fn beam_config() -> BeamConfig {
    BeamConfig::default()
}

/// The view: the core's default (yaw 30, pitch 20, orthographic, 5% margin,
/// 12 bits).
pub fn view() -> View {
    View::DEFAULT
}

struct Project<'a> {
    view: &'a ViewTransform,
    list: &'a mut List,
}

impl SurfaceSink for Project<'_> {
    type Error = core::convert::Infallible;
    fn command(&mut self, _: SliceId, _: usize, c: Command<Point3>) -> Result<(), Self::Error> {
        // A full list counts the command (`List::dropped`) and refuses the
        // rest of its polyline; the scene is drawn without it.
        let _ = self.list.push(c.map(|p| self.view.project(p)));
        Ok(())
    }
}

/// Build the scene into `buf.list`: sample the volume, contour every slice
/// of every plane at the demo's level, project, optimise and order.
///
/// # Errors
/// Only if the core rejects the built-in settings (never, in practice).
pub fn build(buf: &mut Buffers) -> Result<Built, SceneError> {
    DEMO.fill(SIDE, &mut buf.volume).map_err(SceneError::Grid)?;
    let volume = Volume::new(&buf.volume[..], SIDE, SIDE, SIDE).map_err(SceneError::Grid)?;
    let bounds = Bounds::of_volume(SIDE, SIDE, SIDE).map_err(SceneError::View)?;
    let transform = ViewTransform::fit(&view(), bounds).map_err(SceneError::View)?;
    let levels = [DEMO.default_level()];
    buf.list.clear();
    buf.list.reset_counters();
    for plane in Plane::ALL {
        for index in 0..volume.slice_count(plane) {
            let mut sink = Project { view: &transform, list: &mut buf.list };
            contour_slice(&volume, SliceId { plane, index }, &levels, Traversal::Corrected, &mut sink)
                .map_err(|_| SceneError::Contour)?;
        }
    }
    let fragments = buf.list.polyline_count();
    let points_in = buf.list.len();
    let optimize = buf.list.optimize(&mut buf.scratch, &OptimizeConfig::default());
    let park = beam_config().park_sample();
    let start = ScreenPoint::new(f32::from(park.x), f32::from(park.y));
    let order = buf.list.order(&mut buf.scratch, &OrderConfig { start, ..OrderConfig::default() });
    let stats = match frame(&buf.list, &beam_config()) {
        Some(mut s) => {
            s.by_ref().for_each(drop);
            s.stats()
        }
        None => frame_stats(core::iter::empty(), &beam_config()),
    };
    Ok(Built {
        fragments,
        points_in,
        dropped: buf.list.dropped(),
        optimize,
        order,
        frame_samples: stats.samples,
        lit_samples: stats.lit_samples,
    })
}

/// The scheduler of one refresh-loop frame, as the simulator plays it: no
/// return to the park position, starting (blanked and settled) where the
/// last polyline ends, so that playing frames back to back is seamless.
/// `None` for an empty list.
pub fn frame<'a>(
    list: &'a List,
    beam: &BeamConfig,
) -> Option<Scheduler<impl Iterator<Item = Command<ScreenPoint>> + use<'a>>> {
    let last = list.polylines().last()?;
    let end = match (last.closed, last.points.first(), last.points.last()) {
        (true, Some(&p), _) | (false, _, Some(&p)) => p,
        _ => ScreenPoint::new(f32::NAN, f32::NAN),
    };
    let cfg = BeamConfig { park: Park { return_at_end: false, ..beam.park }, ..*beam };
    Some(Scheduler::with_start(list.commands(), &cfg, end))
}

/// The endless sample stream of the refresh loop: frame after frame of
/// [`frame`]. An empty scene (or one whose frame has no samples) plays the
/// blanked park sample instead, so the beam is never left lit and the
/// stream never stalls.
pub fn refresh<'a>(list: &'a List, beam: &BeamConfig) -> impl Iterator<Item = Sample> + use<'a> {
    let beam = *beam;
    let park = beam.park_sample();
    let mut current = frame(list, &beam);
    core::iter::from_fn(move || {
        loop {
            let scheduler = current.as_mut()?;
            if let Some(s) = scheduler.next() {
                return Some(s);
            }
            if scheduler.stats().samples == 0 {
                current = None;
            } else {
                current = frame(list, &beam);
            }
        }
    })
    .chain(core::iter::repeat(park))
}

/// What the firmware plays under QEMU, in order: one park sample (at
/// boot, before the scene is built), [`QEMU_FRAMES`] frames of the refresh
/// loop, one park sample (idle), then it exits.
pub fn qemu_sequence<'a>(
    list: &'a List,
    beam: &BeamConfig,
    built: &Built,
) -> impl Iterator<Item = Sample> + use<'a> {
    let park = beam.park_sample();
    let n = usize::try_from(built.frame_samples).unwrap_or(0).saturating_mul(QEMU_FRAMES);
    core::iter::once(park).chain(refresh(list, beam).take(n)).chain(core::iter::once(park))
}
