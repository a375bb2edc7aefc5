//! A whole frame on the host: contour the chosen slices, project them,
//! build the display list, cull, stitch, merge, order, and schedule the beam.
//!
//! This is the pipeline the firmware runs, with `Vec` storage instead of
//! fixed arrays; it is single-threaded on purpose, so that its timing says
//! what one core (and, scaled, the MCU) would need.

use anyhow::{Context, Result, anyhow};
use isoscope_core::beam::{BeamConfig, FrameStats, Park, Scheduler, frame_stats};
use isoscope_core::command::{Command, Point3};
use isoscope_core::dac::Sample as DacSample;
use isoscope_core::display::{
    DisplayStore, OptimizeConfig, OptimizeStats, OrderConfig, OrderStats, ScratchStore,
};
use isoscope_core::grid::{Plane, Volume};
use isoscope_core::sample::Sample;
use isoscope_core::screen::ScreenPoint;
use isoscope_core::surface::{SliceId, SurfaceSink, contour_slice};
use isoscope_core::trace::Traversal;
use isoscope_core::view::{Bounds, View, ViewTransform};
use std::convert::Infallible;
use std::time::Instant;

/// How the polylines are ordered for the beam.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Order {
    /// Cull, stitch, merge and order (the default).
    #[default]
    Optimized,
    /// The contour fragments as they come, for comparison.
    Input,
}

/// How the view is scaled to the screen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ViewFit {
    /// The projected bounding box fills the screen ([`ViewTransform::fit`]):
    /// the largest picture for one still view (the default).
    #[default]
    Box,
    /// The bounding sphere fills the screen ([`ViewTransform::fit_sphere`]):
    /// the scale does not depend on the angles, so a spinning view does not
    /// breathe. For animation.
    Sphere,
}

/// What to put on the screen.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneConfig {
    /// Slicing planes.
    pub planes: Vec<Plane>,
    /// Contour levels.
    pub levels: Vec<f32>,
    /// Contour every `every`-th slice of each plane (1 = all).
    pub every: usize,
    /// The 3D view.
    pub view: View,
    /// The beam.
    pub beam: BeamConfig,
    /// Ordering.
    pub order: Order,
    /// Collinear merge tolerance, DAC units.
    pub tolerance: f32,
    /// How the view is scaled to the screen.
    pub fit: ViewFit,
}

impl Default for SceneConfig {
    fn default() -> Self {
        Self {
            planes: Plane::ALL.to_vec(),
            levels: vec![],
            every: 1,
            view: View::default(),
            beam: BeamConfig::default(),
            order: Order::Optimized,
            tolerance: OptimizeConfig::default().tolerance,
            fit: ViewFit::Box,
        }
    }
}

/// A host display list: the core's `DisplayStore` over `Vec`s.
pub type HostDisplayList = DisplayStore<Vec<ScreenPoint>, Vec<u8>>;

/// A frame and what it took.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    /// The display list, in drawing order.
    pub list: HostDisplayList,
    /// Contour fragments (polylines before stitching).
    pub fragments: usize,
    /// Culling and stitching.
    pub optimize: Option<OptimizeStats>,
    /// Ordering.
    pub ordering: Option<OrderStats>,
    /// The beam schedule of one frame in a refresh loop ([`refresh_stats`]).
    pub frame: FrameStats,
    /// Seconds: contouring with projection, optimisation, ordering.
    pub seconds: [f64; 3],
}

struct Project<'a> {
    view: &'a ViewTransform,
    out: &'a mut Vec<Command<ScreenPoint>>,
}

impl SurfaceSink for Project<'_> {
    type Error = Infallible;
    fn command(&mut self, _: SliceId, _: usize, c: Command<Point3>) -> Result<(), Infallible> {
        self.out.push(c.map(|p| self.view.project(p)));
        Ok(())
    }
}

/// Build one frame of `volume` as `cfg` says.
pub fn build<T: Sample>(volume: &Volume<'_, T>, cfg: &SceneConfig) -> Result<Scene> {
    check_contouring(cfg)?;
    cfg.beam.validate().context("invalid beam settings")?;
    let (nx, ny, nz) = volume.dims();
    let view = view_transform(cfg, Bounds::of_volume(nx, ny, nz)?)?;
    let t0 = Instant::now();
    let mut commands = Vec::new();
    for &plane in &cfg.planes {
        for index in (0..volume.slice_count(plane)).step_by(cfg.every) {
            let mut sink = Project { view: &view, out: &mut commands };
            contour_slice(volume, SliceId { plane, index }, &cfg.levels, Traversal::Corrected, &mut sink)
                .map_err(|e| anyhow!("contouring {plane} slice {index}: {e}"))?;
        }
    }
    finish(commands, cfg, t0)
}

/// The chicken-wire surface in voxel coordinates: contoured once, then
/// projected for any number of views ([`Surface::scene`]), as a spinning
/// view needs (the firmware keeps the same `Point3` commands and re-projects
/// them when the view changes).
#[derive(Debug, Clone, PartialEq)]
pub struct Surface {
    /// The contour commands of every slice, in [`build`]'s order.
    pub commands: Vec<Command<Point3>>,
    /// The volume's bounds, which the view fits to the screen.
    pub bounds: Bounds,
    /// Seconds the contouring took.
    pub seconds: f64,
}

struct Keep<'a>(&'a mut Vec<Command<Point3>>);

impl SurfaceSink for Keep<'_> {
    type Error = Infallible;
    fn command(&mut self, _: SliceId, _: usize, c: Command<Point3>) -> Result<(), Infallible> {
        self.0.push(c);
        Ok(())
    }
}

/// Contour the slices `cfg` chooses (its `planes`, `levels` and `every`;
/// the view, beam and ordering are not used here) into a [`Surface`].
///
/// # Errors
/// No level, a stride of 0, an empty volume, or a contouring error.
pub fn contour_surface<T: Sample>(volume: &Volume<'_, T>, cfg: &SceneConfig) -> Result<Surface> {
    check_contouring(cfg)?;
    let (nx, ny, nz) = volume.dims();
    let bounds = Bounds::of_volume(nx, ny, nz)?;
    let t0 = Instant::now();
    let mut commands = Vec::new();
    for &plane in &cfg.planes {
        for index in (0..volume.slice_count(plane)).step_by(cfg.every) {
            let mut sink = Keep(&mut commands);
            contour_slice(volume, SliceId { plane, index }, &cfg.levels, Traversal::Corrected, &mut sink)
                .map_err(|e| anyhow!("contouring {plane} slice {index}: {e}"))?;
        }
    }
    Ok(Surface { commands, bounds, seconds: t0.elapsed().as_secs_f64() })
}

impl Surface {
    /// The frame of this surface under `cfg`'s view, fit, beam and ordering
    /// (its `planes`, `levels` and `every` were used when contouring): the
    /// same display list and frame as [`build`] on the volume with the same
    /// `cfg`. The first of the scene's `seconds` is the projection alone.
    ///
    /// # Errors
    /// Invalid view or beam settings, or a display list too large.
    pub fn scene(&self, cfg: &SceneConfig) -> Result<Scene> {
        cfg.beam.validate().context("invalid beam settings")?;
        let view = view_transform(cfg, self.bounds)?;
        let t0 = Instant::now();
        let commands = self.commands.iter().map(|c| c.map(|p| view.project(p))).collect();
        finish(commands, cfg, t0)
    }
}

fn check_contouring(cfg: &SceneConfig) -> Result<()> {
    if cfg.levels.is_empty() {
        return Err(anyhow!("no contour level"));
    }
    if cfg.every == 0 {
        return Err(anyhow!("the slice stride must be at least 1"));
    }
    Ok(())
}

fn view_transform(cfg: &SceneConfig, bounds: Bounds) -> Result<ViewTransform> {
    match cfg.fit {
        ViewFit::Box => ViewTransform::fit(&cfg.view, bounds),
        ViewFit::Sphere => ViewTransform::fit_sphere(&cfg.view, bounds),
    }
    .context("invalid view")
}

/// The display list, its optimisation and ordering, and the frame
/// statistics of projected commands; `t0` is when they started coming.
fn finish(commands: Vec<Command<ScreenPoint>>, cfg: &SceneConfig, t0: Instant) -> Result<Scene> {
    let cap = commands.len().max(1);
    let mut list = DisplayStore::with_storage(vec![ScreenPoint::default(); cap], vec![0u8; cap]);
    for c in commands {
        list.push(c).map_err(|_| anyhow!("the display list is full"))?;
    }
    let fragments = list.polyline_count();
    let t1 = Instant::now();
    let (mut optimize, mut ordering) = (None, None);
    let mut t2 = t1;
    if cfg.order == Order::Optimized {
        let mut scratch = ScratchStore::with_storage(
            vec![0u32; cap],
            vec![0u32; cap],
            vec![0u32; cap],
            vec![0u32; cap],
            vec![0u64; cap],
            vec![ScreenPoint::default(); cap],
            vec![0u8; cap],
        );
        optimize = Some(list.optimize(&mut scratch, &OptimizeConfig { tolerance: cfg.tolerance }));
        t2 = Instant::now();
        let park = cfg.beam.park_sample();
        let start = ScreenPoint::new(f32::from(park.x), f32::from(park.y));
        ordering = Some(list.order(&mut scratch, &OrderConfig { start, ..OrderConfig::default() }));
    }
    let t3 = Instant::now();
    let frame = refresh_stats(&list, &cfg.beam);
    Ok(Scene {
        list,
        fragments,
        optimize,
        ordering,
        frame,
        seconds: [(t1 - t0).as_secs_f64(), (t2 - t1).as_secs_f64(), (t3 - t2).as_secs_f64()],
    })
}

/// The beam schedule of one frame in a refresh loop: the frame starts where
/// the same frame ended (no trip to the park position between frames; the
/// park position is for idle time), so the closing jump of the loop counts
/// as blanked travel.
pub fn refresh_stats(list: &HostDisplayList, beam: &BeamConfig) -> FrameStats {
    let Some(mut s) = refresh_scheduler(list, beam) else {
        return frame_stats(list.commands(), beam);
    };
    for _ in &mut s {}
    s.stats()
}

/// The samples of one frame in a refresh loop, as [`refresh_stats`] counts
/// them: the frame starts where it ends, so playing the samples over and
/// over is the refresh loop, seamless (the loop's closing jump is the
/// frame's first blanked jump). The last sample is blanked. Empty for an
/// empty list.
pub fn refresh_samples(list: &HostDisplayList, beam: &BeamConfig) -> Vec<DacSample> {
    refresh_scheduler(list, beam).map(Iterator::collect).unwrap_or_default()
}

/// The scheduler of one refresh-loop frame: no return to the park
/// position, starting where the last polyline ends; `None` for an empty
/// list.
fn refresh_scheduler<'a>(
    list: &'a HostDisplayList,
    beam: &BeamConfig,
) -> Option<Scheduler<impl Iterator<Item = Command<ScreenPoint>> + 'a>> {
    let last = list.polylines().last()?;
    let end = match (last.closed, last.points.first(), last.points.last()) {
        (true, Some(&p), _) | (false, _, Some(&p)) => p,
        _ => ScreenPoint::new(f32::NAN, f32::NAN),
    };
    let cfg = BeamConfig { park: Park { return_at_end: false, ..beam.park }, ..*beam };
    Some(Scheduler::with_start(list.commands(), &cfg, end))
}

impl Scene {
    /// The frame statistics as `key=value` lines.
    pub fn report(&self, sample_rate_hz: f32) -> String {
        let f = &self.frame;
        let mut s = String::new();
        let mut kv = |k: &str, v: String| {
            s.push_str(k);
            s.push('=');
            s.push_str(&v);
            s.push('\n');
        };
        kv("fragments", self.fragments.to_string());
        kv("polylines", self.list.polyline_count().to_string());
        kv("points", self.list.len().to_string());
        kv("dots", f.points.to_string());
        kv("lit_length", format!("{:.1}", f.lit_length));
        kv("blank_length", format!("{:.1}", f.blank_length));
        kv("blank_ratio", format!("{:.4}", f.blank_length / f.lit_length.max(f32::MIN_POSITIVE)));
        kv("samples", f.samples.to_string());
        kv("lit_samples", f.lit_samples.to_string());
        kv("fps_at_1msps", format!("{:.2}", f.fps(sample_rate_hz)));
        if let Some(o) = &self.optimize {
            kv("duplicate_segments", o.duplicate_segments.to_string());
            kv("merged_points", o.merged_points.to_string());
        }
        kv("contour_ms", format!("{:.3}", self.seconds[0] * 1e3));
        kv("optimize_ms", format!("{:.3}", self.seconds[1] * 1e3));
        kv("order_ms", format!("{:.3}", self.seconds[2] * 1e3));
        kv("pipeline_ms", format!("{:.3}", self.seconds.iter().sum::<f64>() * 1e3));
        s
    }
}

/// Draw `frames` refreshes of the scene's frame on a simulated phosphor,
/// through the beam scheduler, as the scope would show it.
///
/// # Errors
/// An invalid picture configuration.
pub fn render(
    scene: &Scene,
    beam: &BeamConfig,
    picture: crate::phosphor::PhosphorConfig,
    frames: u32,
    progress: Option<&crate::progress::Progress>,
) -> Result<crate::phosphor::Phosphor> {
    let mut screen = crate::phosphor::Phosphor::new(picture).context("invalid picture settings")?;
    for _ in 0..frames.max(1) {
        screen.decay();
        screen.deposit(Scheduler::new(scene.list.commands(), beam));
        if let Some(p) = progress {
            p.inc();
        }
    }
    Ok(screen)
}
