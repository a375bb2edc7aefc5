//! The pen: turns the traversal's drawing instructions into clean commands.
//!
//! The traversal of one subgrid emits SETPOINT/DRAWTO instructions at
//! symbolic [`Crossing`]s. The pen places them in grid coordinates and tidies
//! what a display should not see twice: a DRAWTO to where the pen already is
//! (duplicated tree nodes reach the same crossing more than once) is dropped,
//! a SETPOINT that no DRAWTO follows becomes a DRAWPOINT, and such a point is
//! dropped when a line of the same subgrid already passes through it, or when
//! it was already drawn.

use super::subgrid::{Edge, Node, Subgrid};
use super::trace::{Conn, Crossing};
use crate::command::Command;

/// Bit of a crossing in a 13-bit mask.
#[inline(always)]
fn bit(x: Crossing) -> u16 {
    1 << (x.index() & 15)
}

/// Bit index of each unordered pair of crossings in a 78-bit mask (built at
/// compile time; an index out of range there is a build error).
#[allow(clippy::indexing_slicing)]
const PAIRS: [[u8; Crossing::COUNT]; Crossing::COUNT] = {
    let mut t = [[0u8; Crossing::COUNT]; Crossing::COUNT];
    let mut next = 0u8;
    let mut a = 0;
    while a < Crossing::COUNT {
        let mut b = a + 1;
        while b < Crossing::COUNT {
            t[a][b] = next;
            t[b][a] = next;
            next += 1;
            b += 1;
        }
        a += 1;
    }
    t
};

/// Bit of the segment between two crossings in a 78-bit mask.
#[inline(always)]
fn pair_bit(a: Crossing, b: Crossing) -> u128 {
    let i = PAIRS.get(a.index()).and_then(|r| r.get(b.index())).copied().unwrap_or(127);
    1u128 << (i & 127)
}

/// Where a subgrid sits in its grid, to place crossings in grid coordinates.
///
/// Coordinates are formed as `i + t` (or `j + t`) along each edge's canonical
/// direction, so the two subgrids sharing an edge produce bit-identical
/// crossings on it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placement {
    /// `x0, x1`: the cell's two grid columns.
    x: [f32; 2],
    /// `y0, y1`: its two grid rows.
    y: [f32; 2],
}

impl Placement {
    /// The placement of the subgrid whose lower-left corner is grid point
    /// `(i, j)`.
    #[inline(always)]
    pub fn new(i: usize, j: usize) -> Self {
        Self { x: [i as f32, (i + 1) as f32], y: [j as f32, (j + 1) as f32] }
    }

    /// The grid coordinates of a crossing at `level`.
    #[inline(always)]
    pub fn locate(&self, sub: &Subgrid, level: f32, at: Crossing) -> (f32, f32) {
        let ([x0, x1], [y0, y1]) = (self.x, self.y);
        let xc = x0 + 0.5;
        let yc = y0 + 0.5;
        match (at.as_node(), at.as_edge()) {
            (Some(n), _) => match n {
                Node::LL => (x0, y0),
                Node::LR => (x1, y0),
                Node::UR => (x1, y1),
                Node::UL => (x0, y1),
                Node::C => (xc, yc),
            },
            (None, None) => (xc, yc),
            (None, Some(e)) => self.locate_edge(sub, level, e),
        }
    }

    /// The grid coordinates of the level's crossing strictly inside `e`.
    #[inline(always)]
    pub fn locate_edge(&self, sub: &Subgrid, level: f32, e: Edge) -> (f32, f32) {
        self.along(e as usize, sub.crossing(e, level))
    }

    /// The point a fraction `t` (in `[0, 1]`) along the edge with index
    /// `edge` (`0..8`) in its canonical direction: a corner's coordinate
    /// plus `t` times 0, 1 or +-0.5 per axis, from a table instead of a
    /// match (no jump on the edge). Bit-identical to the plain forms
    /// (`x0 + t`, `x1 - 0.5 * t`, `y0`): `1.0 * t` is `t`, `a + (-0.5) * t`
    /// is `a - 0.5 * t`, and `a + 0.0 * t` is `a` for `t >= 0` and `a >= 0`.
    #[inline(always)]
    pub(crate) fn along(&self, edge: usize, t: f32) -> (f32, f32) {
        along_in(self.x, self.y, edge, t)
    }

    /// The cell's two grid columns and two grid rows.
    #[inline(always)]
    pub(crate) const fn sides(&self) -> ([f32; 2], [f32; 2]) {
        (self.x, self.y)
    }
}

/// [`Placement::along`] of the cell with columns `xs` and rows `ys` (a
/// batch of cells works out their points apart from their placements).
#[inline(always)]
pub(crate) fn along_in(xs: [f32; 2], ys: [f32; 2], edge: usize, t: f32) -> (f32, f32) {
    let e = edge & 7;
    let x = xs.get((FROM_X1 >> e) & 1).copied().unwrap_or(0.0);
    let y = ys.get((FROM_Y1 >> e) & 1).copied().unwrap_or(0.0);
    let (kx, ky) = (ALONG_X.get(e).copied().unwrap_or(0.0), ALONG_Y.get(e).copied().unwrap_or(0.0));
    (x + kx * t, y + ky * t)
}

// Per edge index (B0..B3, S0..S3): whether the edge starts at `x1` rather
// than `x0` (a bit each), the factor of the crossing's fraction along x,
// and the same for y. B0: (x0 + t, y0); B1: (x1, y0 + t); B2: (x0 + t,
// y1); B3: (x0, y0 + t); S0: (x0 + t/2, y0 + t/2); S1: (x1 - t/2, y0 +
// t/2); S2: (x1 - t/2, y1 - t/2); S3: (x0 + t/2, y1 - t/2).
const FROM_X1: usize = 0b0110_0010;
const FROM_Y1: usize = 0b1100_0100;
const ALONG_X: [f32; 8] = [1.0, 0.0, 1.0, 0.0, 0.5, -0.5, -0.5, 0.5];
const ALONG_Y: [f32; 8] = [0.0, 1.0, 0.0, 1.0, 0.5, 0.5, -0.5, -0.5];

/// Pen state for one subgrid at one level.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Pen {
    at: Option<Crossing>,
    pending: Option<Crossing>,
    lone: u16,
    lined: u16,
    segments: u128,
}

impl Pen {
    /// A pen that has drawn nothing.
    pub const fn new() -> Self {
        Self { at: None, pending: None, lone: 0, lined: 0, segments: 0 }
    }

    /// Take one instruction; `out` receives the commands it yields, with the
    /// crossing they are at.
    #[inline(always)]
    pub fn step<E>(
        &mut self,
        conn: Conn,
        x: Crossing,
        mut out: impl FnMut(Command<Crossing>) -> Result<(), E>,
    ) -> Result<(), E> {
        match (conn, self.at) {
            (Conn::DrawTo, Some(at)) if at == x => {}
            (Conn::DrawTo, Some(at)) if self.segments & pair_bit(at, x) != 0 => {
                // Already drawn: move there with the beam off instead.
                if let Some(p) = self.pending.replace(x) {
                    self.lone |= bit(p);
                }
                self.at = Some(x);
            }
            (Conn::DrawTo, Some(at)) => {
                self.segments |= pair_bit(at, x);
                if let Some(p) = self.pending.take() {
                    out(Command::MoveTo(p))?;
                    self.lined |= bit(p);
                }
                out(Command::LineTo(x))?;
                self.lined |= bit(x);
                self.at = Some(x);
            }
            // A SETPOINT, or a DRAWTO with no pen down (treated as a SETPOINT).
            _ => {
                if let Some(p) = self.pending.replace(x) {
                    self.lone |= bit(p);
                }
                self.at = Some(x);
            }
        }
        Ok(())
    }

    /// End of the subgrid: emit the points that no line covers.
    #[inline(always)]
    pub fn finish<E>(&mut self, mut out: impl FnMut(Command<Crossing>) -> Result<(), E>) -> Result<(), E> {
        if let Some(p) = self.pending.take() {
            self.lone |= bit(p);
        }
        let mut points = self.lone & !self.lined;
        while points != 0 {
            let i = points.trailing_zeros();
            if let Some(x) = Crossing::from_index(i as usize) {
                out(Command::Point(x))?;
            }
            points &= points - 1;
        }
        self.lone = 0;
        Ok(())
    }
}

/// The second, placed stage of the pen: it sees commands with their grid
/// coordinates. Distinct crossings within about one ULP of a node round to
/// the same `f32` point, so a line can still have zero length once placed; it
/// is dropped, and a polyline that collapses entirely becomes a point. A
/// SETPOINT to where the beam already is continues the polyline instead of
/// starting a new one.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Placed {
    /// Where the beam is (valid when `has_at`).
    at: (f32, f32),
    /// A SETPOINT not yet sent (valid when `has_held`): it is sent with the
    /// first line of non-zero length that follows it.
    held: (f32, f32),
    has_at: bool,
    has_held: bool,
}

impl Placed {
    /// Nothing drawn yet.
    pub const fn new() -> Self {
        Self { at: (0.0, 0.0), held: (0.0, 0.0), has_at: false, has_held: false }
    }

    /// Take one placed command; `out` receives what should be drawn.
    #[inline(always)]
    pub fn step<E>(
        &mut self,
        c: Command<(f32, f32)>,
        mut out: impl FnMut(Command<(f32, f32)>) -> Result<(), E>,
    ) -> Result<(), E> {
        match c {
            Command::MoveTo(p) => {
                if self.has_held || !(self.has_at && self.at == p) {
                    self.collapse(&mut out)?;
                    self.held = p;
                    self.has_held = true;
                }
                self.at = p;
                self.has_at = true;
            }
            Command::LineTo(p) => {
                if !(self.has_at && self.at == p) {
                    if self.has_held {
                        self.has_held = false;
                        out(Command::MoveTo(self.held))?;
                        out(Command::LineTo(p))?;
                    } else if self.has_at {
                        out(Command::LineTo(p))?;
                    } else {
                        // A line with no start: hold its end as a SETPOINT.
                        self.held = p;
                        self.has_held = true;
                    }
                    self.at = p;
                    self.has_at = true;
                }
            }
            Command::Point(p) => {
                self.collapse(&mut out)?;
                out(Command::Point(p))?;
                self.has_at = false;
            }
        }
        Ok(())
    }

    /// End of the subgrid.
    #[inline(always)]
    pub fn finish<E>(&mut self, mut out: impl FnMut(Command<(f32, f32)>) -> Result<(), E>) -> Result<(), E> {
        self.collapse(&mut out)?;
        self.has_at = false;
        Ok(())
    }

    /// A held SETPOINT whose lines all had zero length is a point.
    #[inline(always)]
    fn collapse<E>(&mut self, out: &mut impl FnMut(Command<(f32, f32)>) -> Result<(), E>) -> Result<(), E> {
        if self.has_held {
            self.has_held = false;
            self.has_at = false;
            out(Command::Point(self.held))?;
        }
        Ok(())
    }
}
