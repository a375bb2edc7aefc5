//! Parallel chicken-wire contouring on the host, and CSV export.
//!
//! Slices are independent (the algorithm is decomposable), so worker threads
//! take them one at a time from a shared counter; results are put back in
//! slice order so the output is the same for any thread count.

use crate::progress::Progress;
use anyhow::{Result, anyhow};
use isoscope_core::command::{Command, Point3};
use isoscope_core::contour::ContourStats;
use isoscope_core::grid::{Plane, Volume};
use isoscope_core::sample::Sample;
use isoscope_core::surface::{SliceId, SurfaceSink, contour_slice};
use isoscope_core::trace::Traversal;
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
}

struct Keep<'v>(&'v mut SliceCommands);

impl SurfaceSink for Keep<'_> {
    type Error = Infallible;
    #[inline]
    fn command(&mut self, _: SliceId, level: usize, c: Command<Point3>) -> Result<(), Infallible> {
        self.0.push((level as u32, c));
        Ok(())
    }
}

struct Discard;

impl SurfaceSink for Discard {
    type Error = Infallible;
    #[inline(always)]
    fn command(&mut self, _: SliceId, _: usize, _: Command<Point3>) -> Result<(), Infallible> {
        Ok(())
    }
}

/// Contour every slice of the job's planes, on `job.threads` threads.
pub fn contour_volume<T: Sample + Sync>(
    volume: &Volume<'_, T>,
    job: &Job<'_>,
    progress: Option<&Progress>,
) -> Result<Contoured> {
    if let Some(i) = job.levels.iter().position(|l| !l.is_finite()) {
        return Err(anyhow!("contour level #{} ({}) is not a finite number", i + 1, job.levels[i]));
    }
    let slices: Vec<SliceId> = job
        .planes
        .iter()
        .flat_map(|&plane| (0..volume.slice_count(plane)).map(move |index| SliceId { plane, index }))
        .collect();
    let results: Vec<Mutex<Option<(SliceCommands, ContourStats)>>> =
        slices.iter().map(|_| Mutex::new(None)).collect();
    let next = AtomicUsize::new(0);
    let threads = job.threads.clamp(1, slices.len().max(1));
    let start = Instant::now();
    let worker = || -> Result<()> {
        loop {
            let i = next.fetch_add(1, Ordering::Relaxed);
            let Some(&slice) = slices.get(i) else { return Ok(()) };
            let mut cmds = SliceCommands::new();
            let stats = if job.keep {
                contour_slice(volume, slice, job.levels, job.traversal, &mut Keep(&mut cmds))
            } else {
                contour_slice(volume, slice, job.levels, job.traversal, &mut Discard)
            }
            .map_err(|e| anyhow!("slice {} {}: {e}", slice.plane, slice.index))?;
            *results[i].lock().map_err(|_| anyhow!("a worker thread panicked"))? = Some((cmds, stats));
            if let Some(p) = progress {
                p.inc();
            }
        }
    };
    std::thread::scope(|s| {
        let handles: Vec<_> = (0..threads).map(|_| s.spawn(worker)).collect();
        handles
            .into_iter()
            .map(|h| h.join().map_err(|_| anyhow!("a worker thread panicked"))?)
            .collect::<Result<Vec<()>>>()
    })?;
    let seconds = start.elapsed().as_secs_f64();
    let mut out = Contoured { seconds, ..Default::default() };
    for (slice, r) in slices.into_iter().zip(results) {
        let (cmds, stats) = r
            .into_inner()
            .map_err(|_| anyhow!("a worker thread panicked"))?
            .ok_or_else(|| anyhow!("slice {} {} was not contoured", slice.plane, slice.index))?;
        out.stats += stats;
        out.slices.push((slice, cmds));
    }
    Ok(out)
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
