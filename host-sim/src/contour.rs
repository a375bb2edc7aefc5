//! Parallel chicken-wire contouring on the host, and CSV export.
//!
//! Slices are independent (the algorithm is decomposable), so worker threads
//! take them one at a time from a shared counter; results are put back in
//! slice order so the output is the same for any thread count.

use crate::progress::Progress;
use anyhow::{Context, Result, anyhow};
use isoscope_core::command::{Command, Point3};
use isoscope_core::contour::Voxel;
use isoscope_core::contour::grid::{Plane, Planes, Volume};
use isoscope_core::contour::surface::{SliceId, SurfaceSink, contour_slab, contour_slice};
use isoscope_core::contour::trace::Traversal;
use isoscope_core::contour::{ContourError, ContourStats};
use std::convert::Infallible;
use std::io::Write;
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

/// The commands of one slice: `(level index, command)` in traversal order.
pub type SliceCommands = Vec<(u32, Command<Point3>)>;

/// The result of contouring a volume.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Contoured {
    /// Every slice with its commands (empty lists when commands were not kept).
    pub slices: Vec<(SliceId, SliceCommands)>,
    /// Totals over all slices.
    pub stats: ContourStats,
    /// Wall-clock seconds of the contouring alone.
    pub seconds: f64,
}

/// What to contour and how.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Job<'a> {
    /// Slicing planes, in output order.
    pub planes: &'a [Plane],
    /// Contour levels.
    pub levels: &'a [f32],
    /// Which traversal.
    pub traversal: Traversal,
    /// Worker threads (at least 1).
    pub threads: usize,
    /// Keep the commands (false: only count them).
    pub keep: bool,
    /// Contour only every `every`-th slice of each plane (1: all).
    pub every: usize,
}

/// Keeps every command with its slice and level.
struct Keep(Vec<(SliceId, u32, Command<Point3>)>);

impl SurfaceSink for Keep {
    type Error = Infallible;
    #[inline]
    fn command(&mut self, slice: SliceId, level: usize, c: Command<Point3>) -> Result<(), Infallible> {
        self.0.push((slice, level as u32, c));
        Ok(())
    }
}

/// Keeps nothing but a checksum of every point, so that timing without
/// output still computes every coordinate (a sink that ignored its input
/// would let the compiler skip that work).
struct Checksum(u32);

impl SurfaceSink for Checksum {
    type Error = Infallible;
    #[inline(always)]
    fn command(&mut self, _: SliceId, _: usize, c: Command<Point3>) -> Result<(), Infallible> {
        let p = c.point();
        self.0 = self.0.rotate_left(5)
            ^ p.x.to_bits()
            ^ p.y.to_bits().rotate_left(11)
            ^ p.z.to_bits().rotate_left(22);
        Ok(())
    }
}

/// One unit of parallel work: a slab of x-y slices and the cell rows
/// between them across every slice of the other planes, or one slice.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Band {
    Slab(std::ops::Range<usize>),
    Slice(SliceId),
}

/// Slices per slab: small enough to balance the threads, large enough that
/// a slab is worth a task.
fn bands<T: Voxel>(volume: &Volume<'_, T>, planes: &[Plane], threads: usize, every: usize) -> Vec<Band> {
    let mut out = vec![];
    if every > 1 {
        for &plane in planes {
            for index in (0..volume.slice_count(plane)).step_by(every) {
                out.push(Band::Slice(SliceId { plane, index }));
            }
        }
        return out;
    }
    let nz = volume.dims().2;
    let per = nz.div_ceil(8 * threads).max(1);
    let mut z = 0;
    while z < nz {
        out.push(Band::Slab(z..(z + per).min(nz)));
        z += per;
    }
    out
}

/// Contour one band into `sink`: each sink gets its own monomorphic copy,
/// so no command goes through a call by pointer.
fn run_band<T: Voxel, S: SurfaceSink<Error = Infallible>>(
    volume: &Volume<'_, T>,
    band: &Band,
    planes: Planes,
    levels: &[f32],
    traversal: Traversal,
    sink: &mut S,
) -> Result<ContourStats, ContourError<Infallible>> {
    match band {
        Band::Slice(slice) => contour_slice(volume, *slice, levels, traversal, sink),
        Band::Slab(zs) => contour_slab(volume, planes, zs.clone(), levels, traversal, sink),
    }
}

/// Contour every slice of the job's planes on `job.threads` threads. The
/// result is the same for any thread count: each slice's commands in
/// row-major cell order, slices in plane and index order.
pub fn contour_volume<T: Voxel + Sync>(
    volume: &Volume<'_, T>,
    job: &Job<'_>,
    progress: Option<&Progress>,
) -> Result<Contoured> {
    if let Some(i) = job.levels.iter().position(|l| !l.is_finite()) {
        return Err(anyhow!("contour level #{} ({}) is not a finite number", i + 1, job.levels[i]));
    }
    let threads = job.threads.max(1);
    let bands = bands(volume, job.planes, threads, job.every);
    let planes = job.planes.iter().fold(Planes::NONE, |p, &plane| p.with(plane));
    type BandResult = (Vec<(SliceId, u32, Command<Point3>)>, ContourStats);
    let results: Vec<Mutex<Option<BandResult>>> = bands.iter().map(|_| Mutex::new(None)).collect();
    let next = AtomicUsize::new(0);
    let start = Instant::now();
    let worker = || -> Result<()> {
        loop {
            let i = next.fetch_add(1, Ordering::Relaxed);
            let Some(band) = bands.get(i) else { return Ok(()) };
            let (levels, traversal) = (job.levels, job.traversal);
            let (cmds, stats) = if job.keep {
                let mut keep = Keep(Vec::new());
                let stats = run_band(volume, band, planes, levels, traversal, &mut keep);
                (keep.0, stats)
            } else {
                let mut sum = Checksum(0);
                let stats = run_band(volume, band, planes, levels, traversal, &mut sum);
                std::hint::black_box(sum.0);
                (Vec::new(), stats)
            };
            let stats = stats.map_err(|e| anyhow!("{band:?}: {e}"))?;
            *results[i].lock().map_err(|_| anyhow!("a worker thread panicked"))? = Some((cmds, stats));
            if let Some(p) = progress {
                p.inc();
            }
        }
    };
    std::thread::scope(|s| {
        let handles: Vec<_> = (0..threads.min(bands.len()).max(1)).map(|_| s.spawn(worker)).collect();
        handles
            .into_iter()
            .map(|h| h.join().map_err(|_| anyhow!("a worker thread panicked"))?)
            .collect::<Result<Vec<()>>>()
    })?;
    let seconds = start.elapsed().as_secs_f64();
    // Join each slice's commands band by band.
    let mut out = Contoured { seconds, ..Default::default() };
    let mut first_of_plane = std::collections::HashMap::new();
    for &plane in job.planes {
        first_of_plane.insert(plane, out.slices.len());
        for index in 0..volume.slice_count(plane) {
            out.slices.push((SliceId { plane, index }, Vec::new()));
        }
    }
    for r in results {
        let (cmds, stats) = r
            .into_inner()
            .map_err(|_| anyhow!("a worker thread panicked"))?
            .context("a band was not contoured")?;
        out.stats += stats;
        for (slice, level, c) in cmds {
            let at = first_of_plane.get(&slice.plane).copied().unwrap_or(0) + slice.index;
            if let Some((_, v)) = out.slices.get_mut(at) {
                v.push((level, c));
            }
        }
    }
    Ok(out)
}

/// The number of work units [`contour_volume`] splits a job into (for
/// progress reporting).
pub fn work_units<T: Voxel>(volume: &Volume<'_, T>, job: &Job<'_>) -> usize {
    bands(volume, job.planes, job.threads.max(1), job.every.max(1)).len()
}

/// Write commands as CSV: a header, then one command per line,
/// `level,axis,slice,op,x,y,z`, coordinates in voxel units with full `f32`
/// precision (shortest round-trip form).
pub fn write_csv(mut w: impl Write, contoured: &Contoured, levels: &[f32]) -> std::io::Result<()> {
    writeln!(w, "level,axis,slice,op,x,y,z")?;
    for (slice, cmds) in &contoured.slices {
        for (li, c) in cmds {
            let p = c.point();
            let level = levels.get(*li as usize).copied().unwrap_or(f32::NAN);
            writeln!(w, "{level},{},{},{},{},{},{}", slice.plane, slice.index, c.op(), p.x, p.y, p.z)?;
        }
    }
    w.flush()
}
