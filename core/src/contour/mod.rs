//! Contouring: Zyda's contouring trees, from one 2x2 subgrid to the
//! chicken-wire surface of a volume.
//!
//! Bottom up:
//!
//! - [`subgrid`]: the five nodes and eight downhill edges of a 2x2 subgrid.
//! - [`tree`]: the contouring trees of all 256 direction codes, built at
//!   compile time.
//! - [`trace`]: the paper's Figure 8 traversal (and its correction for nodes
//!   at the level).
//! - [`compiled`]: that traversal worked out at compile time for every
//!   subgrid with no node at the level: a lookup per crossing subgrid.
//!   Where the target has vectors, the crossing subgrids of a block at one
//!   level are worked out together (`batch`), the same numbers.
//! - [`pen`]: placement of crossings and tidy drawing commands.
//! - [`voxel`]: the sample types a grid may hold, the [`Voxel`] trait.
//! - [`grid`]: [`grid::Grid2`] and [`grid::Volume`] views with strides.
//! - this module: a whole 2D grid (below); its inner loop over blocks of
//!   cells is private (`sweep`).
//! - [`surface`]: every slice of a volume along any planes.
//!
//! # A whole 2D grid
//!
//! Every 2x2 subgrid, one or many levels.
//! Each subgrid's contouring trees are looked up once (they depend only on
//! its direction code) and traversed for every level, the paper's point.
//! Subgrids touching a NaN or infinite sample are skipped and counted.

mod batch;
pub mod compiled;
pub mod grid;
pub mod pen;
pub(crate) mod slab;
pub mod subgrid;
pub mod surface;
mod sweep;
pub mod trace;
pub mod tree;
pub mod voxel;

pub use voxel::Voxel;

use crate::command::{Command, CommandSink};
use core::ops::Range;
use grid::{Grid2, GridError};
use pen::{Pen, Placed, Placement};
use subgrid::Subgrid;
use sweep::{BLOCK, Scratch, Sweep, lane};
use trace::{Conn, Crossing, Traversal, visit};
use tree::Template;

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

/// The most commands one subgrid yields at one level, by any traversal
/// (eight crossings on its eight edges, or dots and lines through nodes at
/// the level): so a row of `n` cells at `l` levels yields at most
/// `n * l * MAX_COMMANDS_A_CELL`. The engine bounds a row's output with it
/// before contouring the row (`engine::stream`); checked exhaustively in
/// `core/tests/properties.rs`.
pub const MAX_COMMANDS_A_CELL: usize = 8;

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
    let code = sub.code();
    let (lo, hi) = sub.range();
    let mut sent = 0u64;
    for (li, &level) in levels.iter().enumerate() {
        if !(lo <= level && level <= hi) {
            continue;
        }
        let (below, on) = sub.below(level);
        if !on
            && traversal == Traversal::Compiled
            && let Some(program) = compiled::program(code, below)
        {
            draw_program(
                program,
                |e| Some(at.along(e, sub.crossing_inside(e, level))),
                |c| {
                    sent += 1;
                    sink.command(li, c.map(|(x, y)| place(x, y)))
                },
            )?;
            continue;
        }
        let mut placed = Placed::new();
        let mut send = |c: Command<(f32, f32)>| {
            sent += 1;
            sink.command(li, c.map(|(x, y)| place(x, y)))
        };
        let tpl = Template::for_code(code);
        let mut out = |c: Command<Crossing>| placed.step(c.map(|x| at.locate(sub, level, x)), &mut send);
        let mut err = None;
        if on {
            // Nodes at the level: the pen tidies repeated crossings,
            // equal-valued edges met twice and lone points.
            let mut pen = Pen::new();
            visit(sub, tpl, level, traversal, |conn, x| {
                if err.is_none()
                    && let Err(e) = pen.step(conn, x, &mut out)
                {
                    err = Some(e);
                }
            });
            if err.is_none() {
                pen.finish(&mut out)?;
            }
        } else {
            // No node at the level: every crossing lies inside an edge, each
            // tree edge is met once, and every SETPOINT is followed by a
            // DRAWTO (the exhaustive test checks all of this), so the
            // instructions map straight to commands.
            visit(sub, tpl, level, traversal, |conn, x| {
                if err.is_none() {
                    let c = match conn {
                        Conn::SetPoint => Command::MoveTo(x),
                        Conn::DrawTo => Command::LineTo(x),
                    };
                    if let Err(e) = out(c) {
                        err = Some(e);
                    }
                }
            });
        }
        if let Some(e) = err {
            return Err(e);
        }
        placed.finish(&mut send)?;
    }
    Ok(sent)
}

/// Draw a compiled traversal's `program` (every crossing inside an edge,
/// no node at the level): the point on each edge it names, `point(edge)`
/// in the cell's grid coordinates (worked out there, or by a batch
/// beforehand; `None` ends the drawing), tidied by [`Placed`] into
/// commands to `send`. Each caller passes closures of its own, so that
/// each is inlined where it is called.
///
/// # Errors
/// The error of `send`.
#[inline(always)]
pub(crate) fn draw_program<E>(
    program: compiled::Program,
    point: impl Fn(usize) -> Option<(f32, f32)>,
    mut send: impl FnMut(Command<(f32, f32)>) -> Result<(), E>,
) -> Result<(), E> {
    let mut placed = Placed::new();
    let mut steps = program.packed();
    for _ in 0..program.len() {
        let Some(p) = point(steps as usize & 7) else { break };
        placed.step(if steps & 8 != 0 { Command::LineTo(p) } else { Command::MoveTo(p) }, &mut send)?;
        steps >>= 4;
    }
    placed.finish(&mut send)
}

/// Contour every subgrid of `grid` at every level, in row order (`j`, then
/// `i`). Points are placed by `place(x, y)` from grid coordinates.
///
/// # Errors
/// [`ContourError::NonFiniteLevel`] before anything is drawn, or the sink's
/// error.
pub fn contour_grid<T: Voxel, P, S: CommandSink<P>>(
    grid: &Grid2<'_, T>,
    levels: &[f32],
    traversal: Traversal,
    place: impl Fn(f32, f32) -> P,
    sink: &mut S,
) -> Result<ContourStats, ContourError<S::Error>> {
    contour_rows(grid, 0..grid.ny() - 1, levels, traversal, place, sink)
}

/// As [`contour_grid`], for the cell rows `rows` only (row `j` holds the
/// subgrids between grid rows `j` and `j + 1`; rows past the end are
/// ignored).
///
/// # Errors
/// [`ContourError::NonFiniteLevel`] before anything is drawn, or the sink's
/// error.
pub fn contour_rows<T: Voxel, P, S: CommandSink<P>>(
    grid: &Grid2<'_, T>,
    rows: Range<usize>,
    levels: &[f32],
    traversal: Traversal,
    place: impl Fn(f32, f32) -> P,
    sink: &mut S,
) -> Result<ContourStats, ContourError<S::Error>> {
    check_levels(levels)?;
    let sweep = Sweep::new(levels, traversal);
    let mut stats = ContourStats::default();
    let mut scratch = Scratch::new();
    let (data, offset, sx, sy) = grid.layout();
    let (nx, ny) = (grid.nx(), grid.ny());
    let rows = rows.start..rows.end.min(ny - 1);
    for j in rows.clone() {
        let mut i0 = 0;
        while i0 + 1 < nx {
            let n = (nx - 1 - i0).min(BLOCK);
            let start = offset + j * sy + i0 * sx;
            let [b0, b1, ..] = &mut scratch.bufs;
            let [c0, c1, c2, ..] = &mut scratch.classes;
            let r0 = lane(data, start, sx, n + 1, b0);
            let r1 = lane(data, start + sy, sx, n + 1, b1);
            sweep
                .run_rows(
                    r0,
                    r1,
                    [c0, c1, c2],
                    &mut scratch.batch,
                    |k| Placement::new(i0 + k, j),
                    |_, x, y| place(x, y),
                    sink,
                    &mut stats,
                )
                .map_err(ContourError::Sink)?;
            i0 += n;
        }
    }
    stats.cells = ((nx - 1) * rows.len()) as u64;
    Ok(stats)
}
