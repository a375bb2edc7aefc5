//! The one path pipeline: a received surface culled, stitched, merged,
//! spliced and ordered, in 3D, in little memory. [`store`] keeps surfaces
//! compactly ([`Geometry`]); `index` finds ends around a point or at one;
//! `stitch` walks maximal polylines; `order` splices and tours them;
//! `merge` writes the chains, merging collinear runs. The board's engine
//! ([`crate::engine`]) runs it when a volume is complete, and so does every
//! host command that draws a picture.
//!
//! Two passes over the contour fragments (two or three points each, one per
//! subgrid), each from one [`Geometry`] into the other:
//!
//! 1. The stitch pass (`stitch`): what would be drawn twice is culled (the paper's
//!    section 4.1: an equal-valued edge on a border two subgrids share, a
//!    dot where a line is), then fragments are walked into maximal
//!    polylines: from the ends of open paths (points where an odd number of
//!    ends meet) first, then around closed loops, going on only through a
//!    fragment that starts exactly where the walk stands (crossings on
//!    shared edges are bit-identical), the straightest one first.
//! 2. The order pass (`order`): the loops that cross a polyline at one of its
//!    points are drawn inside it there (round and back: no jump to them
//!    or from them), so a chicken-wire surface, loops of three planes
//!    crossing at shared points, becomes one polyline a connected piece;
//!    the polylines that start a chain are toured: nearest neighbour (in
//!    space, on a grid of cells), then 2-opt and or-opt by a metric
//!    (in space, or on the screen of the view in force, where a jump across
//!    the depth costs nothing), each loop entered at its best vertex.
//!
//! Either pass merges runs of nearly collinear points on the way, as told
//! (the engine merges in one of them: see `Engine::commit`).
//!
//! The order is made once per volume: a new or spinning view needs no
//! re-ordering. Made in space, any view draws it with no more blanked
//! travel than the 3D tour, scaled (a projection never lengthens a jump);
//! made on one view's screen, that view draws it shortest and the others
//! draw the same tour.
//!
//! Memory, in caller scratch (the engine lends the slice buffers, idle
//! between volumes): the fragment starts and a grid of ends (a singly
//! linked list per cell: in the order pass one link a point and a bit a
//! point for the drawn ones, about 6.7 bytes a point, and a tour step a
//! polyline; in the stitch pass two a fragment, about 5 bytes a point of
//! 3.4-point pieces), all `u32`; in `u16`s (surfaces under 32,767 points),
//! about half that, where the scratch is short: for the stitch pass when
//! it holds less than a list an end in `u32`s, for the order pass when it
//! holds no grid at all in `u32`s (its picture depends on its grid: one it
//! orders in `u32`s stays the same). The order pass's tour steps then take
//! four `u16`s, not three `u32`s (a jump's `f32` is two of them). Either
//! width orders alike where the grid comes out the same. Drawn ends stay in
//! their lists and are passed over (the order pass takes them out of a
//! list as it searches it), so drawing a fragment costs no list walks.
//! Time: `O(n)` to build, and per fragment a search of the cells within
//! eight rings of the beam, else the next cell in scan order with an
//! end left (a cursor that only moves on, `O(cells)` in all).

mod index;
mod merge;
mod order;
mod stitch;
pub mod store;
#[cfg(test)]
mod tests;
pub mod thin;

use core::cell::Cell;
use index::{Index, Width};
pub(crate) use index::{stitch_least, stitch_reserve};
use merge::{Out, Walk};
pub(crate) use order::Metric;
pub use store::{Commands, Geometry, Kind, Packed};
pub(crate) use store::{Held, Source};
pub use thin::Stride;
pub(crate) use thin::thin;

/// What stitching and ordering (`chain`) did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ChainStats {
    /// Fragments in.
    pub fragments: u32,
    /// Polylines (and dots) out.
    pub polylines: u32,
    /// Points in.
    pub points_in: u32,
    /// Points out.
    pub points_out: u32,
    /// Closed loops among the polylines.
    pub loops: u32,
    /// Points removed by merging collinear runs.
    pub merged: u32,
    /// One-segment fragments drawn twice, culled.
    pub duplicate_segments: u32,
    /// Dots culled (on a line, or drawn twice).
    pub culled_dots: u32,
    /// Blanked travel between polylines, in voxels.
    pub travel: f32,
    /// False when the scratch was too small: the fragments were copied in
    /// the order they came.
    pub ordered: bool,
    /// Points the output had no room for: the picture is cut short.
    pub cut: u32,
    /// Closed loops drawn inside another polyline where they cross it, no
    /// jump to them or from them.
    pub spliced: u32,
}

/// How [`chain`] picks the next fragment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Pass {
    /// Cull, then walk maximal polylines.
    Stitch,
    /// Short jumps by the metric, merging collinear runs.
    Order(Metric),
}

/// Chains `src` into `dst` (reset to `src`'s scale) as `pass` says; runs
/// of points within `tolerance` voxels of their chord are merged (0:
/// none). `start` is where the beam comes from. `scratch` should
/// hold about 7 bytes a point; with less, the fragments are copied as they
/// are. `poll` is called every [`POLL_WORK`] units of work or so (a unit
/// is about a point passed over, some tens of cycles): so that a board
/// keeps its output fed from elsewhere while a pass runs. What the pass
/// makes does not depend on it.
pub(crate) fn chain(
    src: Source<'_>,
    dst: &mut Geometry<'_>,
    scratch: &mut [u8],
    start: Packed,
    tolerance: f32,
    pass: Pass,
    poll: &mut dyn FnMut(),
) -> ChainStats {
    chain_on(src, dst, scratch, start, tolerance, pass, pass == Pass::Stitch, Width::Fit, poll)
}

/// Units of work ([`chain`]) between two polls.
pub(crate) const POLL_WORK: u32 = 256;

/// A poll called as work is done ([`chain`]). Ticked through a
/// shared reference, so that a search that only reads (the walk of a list
/// of ends) counts its work too.
pub(crate) struct Poll<'p> {
    f: Cell<Option<&'p mut dyn FnMut()>>,
    work: Cell<u32>,
}

impl<'p> Poll<'p> {
    pub(crate) fn new(f: &'p mut dyn FnMut()) -> Self {
        Self { f: Cell::new(Some(f)), work: Cell::new(0) }
    }

    /// No poll.
    #[cfg(test)]
    pub(crate) fn none() -> Self {
        Self { f: Cell::new(None), work: Cell::new(0) }
    }

    /// `units` of work done: poll if [`POLL_WORK`] are done since the last.
    #[inline(always)]
    pub(crate) fn tick(&self, units: u32) {
        let work = self.work.get().wrapping_add(units);
        if work >= POLL_WORK {
            self.fire();
        } else {
            self.work.set(work);
        }
    }

    #[cold]
    #[inline(never)]
    fn fire(&self) {
        self.work.set(0);
        if let Some(f) = self.f.take() {
            f();
            self.f.set(Some(f));
        }
    }
}

impl core::fmt::Debug for Poll<'_> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Poll").field("work", &self.work.get()).finish_non_exhaustive()
    }
}

/// [`chain`], with the stitch pass's ends in hashed buckets or (`hashed`
/// false, for the test that both stitch alike) in the grid of cells, and
/// the index in the words `width` says (for the tests that both widths
/// chain alike).
#[expect(clippy::too_many_arguments, reason = "the tests' two knobs and the poll beside chain's own")]
fn chain_on(
    src: Source<'_>,
    dst: &mut Geometry<'_>,
    scratch: &mut [u8],
    start: Packed,
    tolerance: f32,
    pass: Pass,
    hashed: bool,
    width: Width,
    poll: &mut dyn FnMut(),
) -> ChainStats {
    dst.reset(src.shift());
    let mut stats = ChainStats { points_in: src.len() as u32, ..ChainStats::default() };
    let any_vertex = pass != Pass::Stitch;
    let poll = Poll::new(poll);
    let Some(mut x) = Index::build(src, scratch, any_vertex, hashed && pass == Pass::Stitch, width, poll)
    else {
        copy(src, dst, &mut stats);
        // Nothing to stitch or order is in order (not "no room for it").
        stats.ordered = src.len() == 0;
        return stats;
    };
    stats.fragments = x.frags as u32;
    stats.ordered = true;
    let mut walk = Walk { out: Out::new(tolerance, src.shift()), cur: start, prev: None };
    match pass {
        Pass::Order(metric) => order::order(&mut x, &mut walk, dst, start, metric, &mut stats),
        Pass::Stitch => stitch::stitch(&mut x, &mut walk, dst, &mut stats),
    }
    walk.out.finish(dst, &mut stats);
    stats.points_out = dst.len() as u32;
    stats.cut = dst.dropped();
    stats
}

/// Copy `src` as it is.
fn copy(src: Source<'_>, dst: &mut Geometry<'_>, stats: &mut ChainStats) {
    for i in 0..src.len() {
        if let Some((q, kind)) = src.get(i) {
            dst.push_raw(q, kind);
            stats.polylines += u32::from(kind.starts());
        }
    }
    stats.points_out = dst.len() as u32;
    stats.cut = dst.dropped();
}
