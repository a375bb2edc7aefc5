//! Contouring a whole 2D grid: every 2x2 subgrid, one or many levels.
//!
//! Each subgrid's contouring trees are looked up once (they depend only on
//! its direction code) and traversed for every level, the paper's point.
//! Subgrids touching a NaN or infinite sample are skipped and counted.

use crate::command::{Command, CommandSink};
use crate::grid::{Grid2, GridError};
use crate::pen::{Pen, Placement};
use crate::sample::Sample;
use crate::subgrid::Subgrid;
use crate::trace::{Traversal, visit};
use crate::tree::Template;

/// Why contouring stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ContourError<E> {
    /// A contour level is NaN or infinite.
    NonFiniteLevel {
        /// Index of the level in the slice given.
        index: usize,
    },
    /// The grid or slice could not be viewed.
    Grid(GridError),
    /// The sink refused a command.
    Sink(E),
}

impl<E: core::fmt::Display> core::fmt::Display for ContourError<E> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            ContourError::NonFiniteLevel { index } => {
                write!(f, "contour level #{index} is NaN or infinite")
            }
            ContourError::Grid(e) => write!(f, "{e}"),
            ContourError::Sink(e) => write!(f, "the command sink failed: {e}"),
        }
    }
}

impl<E: core::fmt::Debug + core::fmt::Display> core::error::Error for ContourError<E> {}

/// What one contouring run did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ContourStats {
    /// Subgrids visited.
    pub cells: u64,
    /// Subgrids skipped because a corner is NaN or infinite.
    pub nonfinite_cells: u64,
    /// Subgrids that emitted at least one command (at any level).
    pub crossing_cells: u64,
    /// Commands emitted.
    pub commands: u64,
}

impl core::ops::AddAssign for ContourStats {
    fn add_assign(&mut self, o: Self) {
        self.cells += o.cells;
        self.nonfinite_cells += o.nonfinite_cells;
        self.crossing_cells += o.crossing_cells;
        self.commands += o.commands;
    }
}

impl core::ops::Add for ContourStats {
    type Output = Self;
    fn add(mut self, o: Self) -> Self {
        self += o;
        self
    }
}

/// Check that every level is finite.
///
/// # Errors
/// [`ContourError::NonFiniteLevel`] naming the first bad level.
pub fn check_levels<E>(levels: &[f32]) -> Result<(), ContourError<E>> {
    match levels.iter().position(|l| !l.is_finite()) {
        Some(index) => Err(ContourError::NonFiniteLevel { index }),
        None => Ok(()),
    }
}

/// Contour one subgrid at every level and send its commands, placed by
/// `place(x, y)`, to `sink`. Returns the number of commands sent.
///
/// # Errors
/// The sink's error.
#[inline]
pub fn contour_subgrid<P, S: CommandSink<P>>(
    sub: &Subgrid,
    at: Placement,
    levels: &[f32],
    traversal: Traversal,
    place: &impl Fn(f32, f32) -> P,
    sink: &mut S,
) -> Result<u64, S::Error> {
    let tpl = Template::for_code(sub.code());
    let mut sent = 0u64;
    for (li, &level) in levels.iter().enumerate() {
        let mut pen = Pen::new();
        let mut err = None;
        let mut out = |c: Command<_>| {
            let c = c.map(|x| {
                let (u, v) = at.locate(sub, level, x);
                place(u, v)
            });
            sent += 1;
            sink.command(li, c)
        };
        visit(sub, tpl, level, traversal, |conn, x| {
            if err.is_none() {
                if let Err(e) = pen.step(conn, x, &mut out) {
                    err = Some(e);
                }
            }
        });
        if let Some(e) = err {
            return Err(e);
        }
        pen.finish(&mut out)?;
    }
    Ok(sent)
}

/// Contour every subgrid of `grid` at every level, in row order (`j`, then
/// `i`). Points are placed by `place(x, y)` from grid coordinates.
///
/// # Errors
/// [`ContourError::NonFiniteLevel`] before anything is drawn, or the sink's
/// error.
pub fn contour_grid<T: Sample, P, S: CommandSink<P>>(
    grid: &Grid2<'_, T>,
    levels: &[f32],
    traversal: Traversal,
    place: impl Fn(f32, f32) -> P,
    sink: &mut S,
) -> Result<ContourStats, ContourError<S::Error>> {
    check_levels(levels)?;
    let mut stats = ContourStats::default();
    let (lo_level, hi_level) =
        levels.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &l| (a.min(l), b.max(l)));
    let (nx, ny) = (grid.nx(), grid.ny());
    for j in 0..ny - 1 {
        let mut a = grid.value(0, j);
        let mut d = grid.value(0, j + 1);
        for i in 0..nx - 1 {
            let b = grid.value(i + 1, j);
            let c = grid.value(i + 1, j + 1);
            let (ll, ul) = (a, d);
            a = b;
            d = c;
            if !(ll.is_finite() & b.is_finite() & c.is_finite() & ul.is_finite()) {
                stats.nonfinite_cells += 1;
                continue;
            }
            let lo = ll.min(b).min(c.min(ul));
            let hi = ll.max(b).max(c.max(ul));
            // No level can meet this subgrid; a constant one draws nothing.
            if hi_level < lo || lo_level > hi || lo == hi {
                continue;
            }
            let sub = Subgrid::from_finite(ll, b, c, ul);
            let sent = contour_subgrid(&sub, Placement::new(i, j), levels, traversal, &place, sink)
                .map_err(ContourError::Sink)?;
            stats.crossing_cells += u64::from(sent > 0);
            stats.commands += sent;
        }
    }
    stats.cells = grid.cells() as u64;
    Ok(stats)
}
