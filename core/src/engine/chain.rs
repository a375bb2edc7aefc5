//! Stitching and ordering a received surface in 3D, in little memory.
//!
//! Two passes over the contour fragments (two or three points each, one per
//! subgrid), each from one [`Geometry`] into the other:
//!
//! 1. [`Pass::Stitch`]: what would be drawn twice is culled (the paper's
//!    section 4.1: an equal-valued edge on a border two subgrids share, a
//!    dot where a line is), then fragments are walked into maximal
//!    polylines: from the ends of open paths (points where an odd number of
//!    ends meet) first, then around closed loops, going on only through a
//!    fragment that starts exactly where the walk stands (crossings on
//!    shared edges are bit-identical), the straightest one first.
//! 2. [`Pass::Order`]: the loops that cross a polyline at one of its
//!    points are drawn inside it there (round and back: no jump to them
//!    or from them), so a chicken-wire surface, loops of three planes
//!    crossing at shared points, becomes one polyline a connected piece;
//!    the polylines that start a chain are toured: nearest neighbour (in
//!    space, on a grid of cells), then 2-opt and or-opt by a [`Metric`]
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
//! point for the drawn ones, about 6.7 bytes a point; in the stitch pass
//! two a fragment, about 5 bytes a point of 3.4-point pieces), all `u32`;
//! the stitch pass, when that is more than the scratch, keeps them in
//! `u16`s (surfaces under 32,767 points), half that. Drawn ends stay in
//! their lists and are passed over (the order pass takes them out of a
//! list as it searches it), so drawing a fragment costs no list walks.
//! Time: `O(n)` to build, and per fragment a search of the cells within
//! [`RINGS`] rings of the beam, else the next cell in scan order with an
//! end left (a cursor that only moves on, `O(cells)` in all).

use super::geometry::{Geometry, Kind, Packed, Source, pack};
use crate::command::Point3;
use crate::fastmath::sqrt;
use crate::view::ViewTransform;

/// No entry.
const NONE: u32 = u32::MAX;
/// The top bit of a fragment's start: drawn already.
const DRAWN: u32 = 1 << 31;
/// Rings of cells searched around the beam.
const RINGS: i32 = 8;
/// Steps a 2-opt move reverses at most (the tour is nearest-neighbour
/// already: the gains are local).
const WINDOW: usize = 48;
/// Dropped points remembered to check a merged chord against.
const MERGE_SPAN: usize = 8;
/// Closed loops drawn inside one another at most ([`Walk::emit_spliced`]):
/// a frame each on the stack, 24 bytes.
const SPLICE_DEPTH: usize = 16;

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

/// The index's words over a byte buffer (the scratch is lent as bytes):
/// `u32`s, or, where those would not fit, `u16`s ([`Words::narrow`]: for
/// the stitch pass, whose words are all point or end indices or [`NONE`],
/// when there are fewer than [`NARROW_LIMIT`] of each). One bounds check
/// and one load a word.
enum Words<'s> {
    Wide(&'s mut [[u8; 4]]),
    Narrow(&'s mut [[u8; 2]]),
}

/// Points (and ends) below which the stitch pass may keep its index in
/// `u16`s: the top bit is [`DRAWN`], all ones [`NONE`].
const NARROW_LIMIT: usize = 0x7FFF;

/// Bytes of scratch the stitch pass wants for `frags` fragments of
/// `points` points in all: its index in `u16` words where those fit (fewer
/// than [`NARROW_LIMIT`] points and ends), a start and two end links a
/// fragment and a list head for every four ends, so that a lookup walks a
/// few ends. With less it still stitches (fewer lists, longer walks) down
/// to three words a fragment, and below that copies the pieces unordered.
pub(crate) const fn stitch_reserve(frags: usize, points: usize) -> usize {
    let word = if points < NARROW_LIMIT && 2 * frags < NARROW_LIMIT { 2 } else { 4 };
    word * (3 * frags + frags / 2 + 1)
}

impl<'s> Words<'s> {
    fn wide(bytes: &'s mut [u8]) -> Self {
        Self::Wide(bytes.as_chunks_mut::<4>().0)
    }

    /// Half the size a word: only for values below [`NARROW_LIMIT`], with
    /// or without [`DRAWN`], and [`NONE`].
    fn narrow(bytes: &'s mut [u8]) -> Self {
        Self::Narrow(bytes.as_chunks_mut::<2>().0)
    }

    fn len(&self) -> usize {
        match self {
            Self::Wide(w) => w.len(),
            Self::Narrow(w) => w.len(),
        }
    }

    #[inline]
    fn get(&self, i: usize) -> u32 {
        match self {
            Self::Wide(w) => w.get(i).map_or(NONE, |b| u32::from_le_bytes(*b)),
            Self::Narrow(w) => match w.get(i).map(|b| u16::from_le_bytes(*b)) {
                None | Some(0xFFFF) => NONE,
                Some(v) => u32::from(v & 0x7FFF) | if v & 0x8000 != 0 { DRAWN } else { 0 },
            },
        }
    }

    #[inline]
    fn set(&mut self, i: usize, v: u32) {
        match self {
            Self::Wide(w) => {
                if let Some(b) = w.get_mut(i) {
                    *b = v.to_le_bytes();
                }
            }
            Self::Narrow(w) => {
                if let Some(b) = w.get_mut(i) {
                    let n = if v == NONE {
                        0xFFFF
                    } else {
                        (v & 0x7FFF) as u16 | if v & DRAWN != 0 { 0x8000 } else { 0 }
                    };
                    *b = n.to_le_bytes();
                }
            }
        }
    }
}

fn dist2(a: Packed, b: Packed) -> u64 {
    // Each square of a `u16` difference fits a `u32` (a 32-bit multiply on
    // the MCU), their sum may not.
    let sq = |a: u16, b: u16| {
        let d = u32::from(a.abs_diff(b));
        u64::from(d * d)
    };
    let ([ax, ay, az], [bx, by, bz]) = (a, b);
    sq(ax, bx) + sq(ay, by) + sq(az, bz)
}

/// [`dist2`] as an `f32` (rounded to nearest): summed in `u32` when it
/// fits, which the FPU converts (a `u64` takes a software call on the MCU).
/// The sum itself is in `u32` (each square of a `u16` difference fits):
/// taking the `u64` sum and converting it by way of `u32` when it fits was
/// folded by the compiler back into the `u64` conversion.
#[inline]
fn dist2f(a: Packed, b: Packed) -> f32 {
    let sq = |a: u16, b: u16| {
        let d = u32::from(a.abs_diff(b));
        d * d
    };
    let ([ax, ay, az], [bx, by, bz]) = (a, b);
    match sq(ax, bx).checked_add(sq(ay, by)).and_then(|s| s.checked_add(sq(az, bz))) {
        Some(s) => s as f32,
        None => dist2(a, b) as f32,
    }
}

/// The distance from `a` to `b`, in codes.
#[inline]
fn length(a: Packed, b: Packed) -> f32 {
    sqrt(dist2f(a, b))
}

/// How the order pass measures a jump when it improves its tour.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Metric {
    /// In voxel space (codes): any view then draws the tour with jumps no
    /// longer than these, scaled. For a spinning view.
    Space,
    /// On one view's screen (DAC units): the tour that view draws with the
    /// least blanked travel (a jump across the depth costs nothing there).
    /// Other views draw the same tour.
    Screen {
        /// The view.
        view: ViewTransform,
        /// The codes' fixed point shift.
        shift: u8,
        /// Where the beam starts, on the screen.
        park: [f32; 2],
    },
}

impl Metric {
    /// `q` on the screen (a point the view cannot project is far away).
    fn at(view: &ViewTransform, shift: u8, q: Packed) -> [f32; 2] {
        let k = f32::from_bits((127 - u32::from(shift.min(12))) << 23);
        let s = view.project_raw(Point3::new(f32::from(q[0]) * k, f32::from(q[1]) * k, f32::from(q[2]) * k));
        if s.x.is_finite() && s.y.is_finite() { [s.x, s.y] } else { [1e9, 1e9] }
    }

    /// The squared length of the jump from `a` to `b`.
    fn d2(&self, a: Packed, b: Packed) -> f32 {
        match self {
            Self::Space => dist2f(a, b),
            Self::Screen { view, shift, .. } => {
                let (p, q) = (Self::at(view, *shift, a), Self::at(view, *shift, b));
                let (dx, dy) = (p[0] - q[0], p[1] - q[1]);
                dx * dx + dy * dy
            }
        }
    }

    /// The length of the jump from `a` to `b`.
    fn d(&self, a: Packed, b: Packed) -> f32 {
        match self {
            Self::Space => length(a, b),
            Self::Screen { .. } => sqrt(self.d2(a, b)),
        }
    }

    /// The length of the jump from where the beam starts (`start` in
    /// space) to `b`.
    fn first_jump(&self, start: Packed, b: Packed) -> f32 {
        match self {
            Self::Space => length(start, b),
            Self::Screen { view, shift, park } => {
                let q = Self::at(view, *shift, b);
                let (dx, dy) = (park[0] - q[0], park[1] - q[1]);
                sqrt(dx * dx + dy * dy)
            }
        }
    }
}

/// 64 well-mixed bits of a point (for [`Index::odd`]).
fn point_hash([x, y, z]: Packed) -> u64 {
    let mix = |h: u32| {
        let h = (h ^ (h >> 16)).wrapping_mul(0x85EB_CA6B);
        let h = (h ^ (h >> 13)).wrapping_mul(0xC2B2_AE35);
        h ^ (h >> 16)
    };
    let (x, y, z) = (u32::from(x), u32::from(y), u32::from(z));
    let a = mix(x | (y << 16)) ^ mix(z ^ 0x9E37_79B9);
    let b = mix(y | (z << 16)) ^ mix(x ^ 0x7F4A_7C15);
    u64::from(a) << 32 | u64::from(b)
}

/// Cell coordinates of `q` in a grid of `n` cells of `2^bits` codes.
fn cell_coords(q: Packed, n: [u32; 3], bits: u32) -> [u32; 3] {
    let [x, y, z] = q;
    let [nx, ny, nz] = n;
    let c = |v: u16, n: u32| (u32::from(v) >> bits).min(n.saturating_sub(1));
    [c(x, nx), c(y, ny), c(z, nz)]
}

/// The fragments of a geometry and a grid of their ends: the first and
/// last point of an open fragment, the point of a dot, every vertex of a
/// closed loop (in the order pass). The lists hold slots: in the order
/// pass a slot is a point index (one link a point); in the stitch pass,
/// which links only first and last points, `2 f` and `2 f + 1` are the
/// ends of fragment `f` (two links a fragment: fewer than one a point, and
/// the fragment comes with the end).
struct Index<'s, 'g> {
    src: Source<'g>,
    w: Words<'s>,
    /// Cells along x, y, z; a cell is `2^bits` codes on a side.
    n: [u32; 3],
    bits: u32,
    /// Word offsets: fragment starts (`frags` of them), cell heads, one
    /// link a slot, and (the order pass, after its tour) a bit a point for
    /// the drawn ones.
    heads: usize,
    links: usize,
    dead: usize,
    frags: usize,
    /// Closed loops may be entered at any vertex.
    any_vertex: bool,
    /// The stitch pass: the hashes of the points of the ends not drawn
    /// ([`point_hash`], a dot's counting as nothing), xor-ed. They cancel
    /// in pairs, so this is zero when every point has an even number of
    /// ends (no open path is left to start), and all but surely not
    /// otherwise (were it zero then, the open paths left would be walked
    /// among the closed loops: drawn all the same, in more pieces). `None`
    /// once the open paths are walked: no longer kept up.
    odd: Option<u64>,
    /// The stitch pass only ever looks up ends at exact points: its lists
    /// are buckets of a hash of the point (this many), not cells of space,
    /// so that the ends of a surface, a sheet through few of its box's
    /// cells, spread over all of them. 0: the grid of cells (the order
    /// pass, which searches around a point).
    buckets: usize,
}

impl<'s, 'g> Index<'s, 'g> {
    fn build(src: Source<'g>, scratch: &'s mut [u8], any_vertex: bool, hashed: bool) -> Option<Self> {
        let points = src.len();
        let mut frags = 0usize;
        let mut top = [0u16; 3];
        src.for_each_kind(|i, kind| frags += usize::from(kind.starts() || i == 0));
        if !hashed {
            // The grid's extent (the stitch pass's buckets need none).
            for i in 0..points {
                for (t, v) in top.iter_mut().zip(src.point_at(i)?) {
                    *t = (*t).max(v);
                }
            }
        }
        // Words of `u32`, unless the stitch pass's index has less than a
        // word of lists an end that way and more in `u16`s.
        let ends = if any_vertex { points } else { 2 * frags };
        // A link a slot: a point, or an end.
        let slots = ends;
        let fixed = frags + slots;
        let narrow =
            !any_vertex && points < NARROW_LIMIT && slots < NARROW_LIMIT && scratch.len() / 4 < fixed + ends;
        let mut w = if narrow { Words::narrow(scratch) } else { Words::wide(scratch) };
        let words = w.len();
        if frags == 0 || points >= DRAWN as usize || words < fixed + 1 {
            return None;
        }
        // The finest grid with up to two cells an end (the surface, a 2D
        // sheet, passes through a few of the cells of its 3D box, so the
        // lists in those stay short) that the scratch holds beside the
        // fragments, the links and the tour: two ends a fragment, or every
        // point of the loops.
        let tour = if any_vertex { TOUR_WORDS * frags } else { 0 };
        // The order pass's drawn points, a bit each in (wide) words after
        // the tour.
        let dead_words = if any_vertex { points.div_ceil(32) } else { 0 };
        let spare = words.saturating_sub(fixed + tour + dead_words) as u64;
        let budget = spare.min((ends as u64 * 2).max(1)).max(1);
        let cells_at = |b: u32| -> u64 { top.iter().map(|&t| u64::from((u32::from(t) >> b) + 1)).product() };
        let mut bits = 0u32;
        while bits < 16 && cells_at(bits) > budget {
            bits += 1;
        }
        let n = top.map(|t| (u32::from(t) >> bits) + 1);
        let heads = frags;
        let buckets = if hashed { budget as usize } else { 0 };
        let cells = if hashed { buckets } else { n.iter().map(|&c| c as usize).product::<usize>() };
        let links = heads + cells;
        // The order pass keeps its tour ([`TOUR_WORDS`] a fragment) after
        // the links.
        if links + slots + tour + dead_words > words {
            return None;
        }
        let dead = links + slots + tour;
        for d in dead..dead + dead_words {
            w.set(d, 0);
        }
        let mut k = 0;
        src.for_each_kind(|i, kind| {
            if kind.starts() || i == 0 {
                w.set(k, i as u32);
                k += 1;
            }
        });
        for c in 0..cells {
            w.set(heads + c, NONE);
        }
        let mut index =
            Self { src, w, n, bits, heads, links, dead, frags, any_vertex, buckets, odd: Some(0) };
        if any_vertex {
            // The order pass links what it needs when it needs it
            // ([`Index::relink`]).
        } else {
            // The stitch pass: a fragment's span, end points and kind read
            // once for its two links and its share of `odd` (what
            // `each_slot`, `link` and `ends_hash` each read again).
            let mut odd = 0u64;
            for f in 0..frags {
                let (from, to) = index.span(f);
                let a = index.point(from);
                index.link_to(2 * f, a);
                let mut h = point_hash(a);
                if to - from > 1 {
                    let b = index.point(to - 1);
                    index.link_to(2 * f + 1, b);
                    h ^= point_hash(b);
                }
                if index.kind(from) != Kind::Dot {
                    odd ^= h;
                }
            }
            index.odd = Some(odd);
        }
        Some(index)
    }

    /// Where the order pass keeps its tour: after the links.
    fn tour_base(&self) -> usize {
        self.links + if self.any_vertex { self.src.len() } else { 2 * self.frags }
    }

    /// Call `act` with each slot of fragment `f`'s ends.
    #[inline]
    fn each_slot(&mut self, f: usize, mut act: impl FnMut(&mut Self, usize)) {
        let (from, to, every) = self.ends(f);
        if self.any_vertex {
            for i in from..to {
                if every || i == from || i + 1 == to {
                    act(self, i);
                }
            }
        } else {
            act(self, 2 * f);
            if to - from > 1 {
                act(self, 2 * f + 1);
            }
        }
    }

    /// The point of slot `s`.
    #[inline]
    fn end_point(&self, s: usize) -> usize {
        if self.any_vertex {
            return s;
        }
        if s & 1 == 0 {
            // A fragment's first point: its start alone (half the ends).
            return (self.w.get(s / 2) & !DRAWN) as usize;
        }
        self.span(s / 2).1 - 1
    }

    /// The fragment of slot `s`.
    #[inline]
    fn end_frag(&self, s: usize) -> usize {
        if self.any_vertex { self.frag_of(s) } else { s / 2 }
    }

    fn cells(&self) -> usize {
        if self.buckets > 0 { self.buckets } else { self.n.iter().map(|&n| n as usize).product() }
    }

    /// The list `q`'s ends are in: its bucket, or its cell.
    #[inline]
    fn cell(&self, q: Packed) -> usize {
        if self.buckets > 0 {
            let [x, y, z] = q.map(u32::from);
            let h = x.wrapping_mul(0x9E37_79B1) ^ y.wrapping_mul(0x85EB_CA77) ^ z.wrapping_mul(0xC2B2_AE3D);
            // Multiply-shift onto 0..buckets (no division).
            return ((u64::from(h) * self.buckets as u64) >> 32) as usize;
        }
        let [cx, cy, cz] = cell_coords(q, self.n, self.bits).map(|c| c as usize);
        let [nx, ny, _] = self.n.map(|n| n as usize);
        cx + nx * (cy + ny * cz)
    }

    #[inline]
    fn point(&self, i: usize) -> Packed {
        self.src.point_at(i).unwrap_or([0; 3])
    }

    #[inline]
    fn kind(&self, i: usize) -> Kind {
        self.src.kind(i).unwrap_or(Kind::Line)
    }

    fn drawn(&self, f: usize) -> bool {
        self.w.get(f) & DRAWN != 0
    }

    /// The point range of fragment `f`.
    fn span(&self, f: usize) -> (usize, usize) {
        let from = (self.w.get(f) & !DRAWN) as usize;
        let to = if f + 1 < self.frags { (self.w.get(f + 1) & !DRAWN) as usize } else { self.src.len() };
        (from, to.max(from + 1).min(self.src.len().max(from + 1)))
    }

    /// The fragment holding point `i`.
    fn frag_of(&self, i: usize) -> usize {
        let (mut lo, mut hi) = (0, self.frags);
        while hi - lo > 1 {
            let mid = (lo + hi) / 2;
            if (self.w.get(mid) & !DRAWN) as usize <= i {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        lo
    }

    fn is_loop(&self, f: usize) -> bool {
        self.kind(self.span(f).0) == Kind::Loop
    }

    fn is_dot(&self, f: usize) -> bool {
        self.kind(self.span(f).0) == Kind::Dot
    }

    /// The point range of fragment `f`, and whether every point of it is an
    /// end (a closed loop in the order pass); else its first and last are.
    #[inline]
    fn ends(&self, f: usize) -> (usize, usize, bool) {
        let (from, to) = self.span(f);
        (from, to, self.any_vertex && self.kind(from) == Kind::Loop)
    }

    fn link(&mut self, s: usize) {
        self.link_to(s, self.point(self.end_point(s)));
    }

    /// Put slot `s`, whose point is `q`, at the head of `q`'s list.
    #[inline]
    fn link_to(&mut self, s: usize, q: Packed) {
        let c = self.cell(q);
        let head = self.w.get(self.heads + c);
        self.w.set(self.links + s, head);
        self.w.set(self.heads + c, s as u32);
    }

    /// The order pass: whether point `s`'s fragment is drawn.
    #[inline]
    fn dead(&self, s: usize) -> bool {
        self.w.get(self.dead + s / 32) >> (s % 32) & 1 != 0
    }

    /// The order pass: take the drawn ends out of cell `c`'s list (each is
    /// passed over once, not looked for when its loop is drawn).
    fn prune(&mut self, c: usize) {
        let mut prev = NONE;
        let mut at = self.w.get(self.heads + c);
        while at != NONE {
            let next = self.w.get(self.links + at as usize);
            if self.dead(at as usize) {
                if prev == NONE {
                    self.w.set(self.heads + c, next);
                } else {
                    self.w.set(self.links + prev as usize, next);
                }
            } else {
                prev = at;
            }
            at = next;
        }
    }

    /// The order pass: mark points `from..to` drawn, a word at a time.
    fn kill(&mut self, from: usize, to: usize) {
        let mut s = from;
        while s < to {
            let bit = s % 32;
            let n = (32 - bit).min(to - s);
            let mask = if n == 32 { u32::MAX } else { ((1u32 << n) - 1) << bit };
            let at = self.dead + s / 32;
            let v = self.w.get(at);
            self.w.set(at, v | mask);
            s += n;
        }
    }

    /// The order pass: no point drawn, and the ends (every vertex of a
    /// loop) in lists: of the fragments not marked drawn, in the grid's
    /// cells, for the tour's searches around a point; or (`hashed`) of the
    /// loops, in buckets of a hash of the point, for the splices' exact
    /// lookups ([`Index::loop_at`]: a sheet crowds the cells it passes
    /// through, and a lookup at every point drawn walked them).
    fn relink(&mut self, hashed: bool) {
        // The buckets' heads: in the scratch past the drawn bits where that
        // holds more than the grid's (up to two a point: short lists), else
        // the grid's heads serve as as many.
        let grid: usize = self.n.iter().map(|&n| n as usize).product();
        let free = self.dead + self.src.len().div_ceil(32);
        let spare = self.w.len().saturating_sub(free);
        (self.heads, self.buckets) = match hashed {
            true if spare > grid => (free, spare.min(2 * self.src.len())),
            true => (self.frags, grid),
            false => (self.frags, 0),
        };
        for c in 0..self.cells() {
            self.w.set(self.heads + c, NONE);
        }
        for d in self.dead..self.dead + self.src.len().div_ceil(32) {
            self.w.set(d, 0);
        }
        for f in 0..self.frags {
            // The splices look up loops alone; the tour's searches the
            // polylines not marked drawn ([`mark_spliced`]).
            if if hashed { self.is_loop(f) } else { !self.drawn(f) } {
                self.each_slot(f, |x, s| x.link(s));
            }
        }
    }

    /// The order pass: whether fragment `f`'s points are drawn.
    fn emitted(&self, f: usize) -> bool {
        self.dead(self.span(f).0)
    }

    /// The order pass, its lists hashed ([`Index::relink`]): a vertex
    /// exactly at `q` of a closed loop not drawn yet.
    fn loop_at(&self, q: Packed) -> Option<usize> {
        let mut found = None;
        let raw = pack(q);
        self.each_end(self.cell(q), |s| {
            if self.src.is_at(s, &raw) {
                found = Some(s);
                return false;
            }
            true
        });
        found
    }

    /// Mark fragment `f` drawn. Its ends stay in their lists, passed over
    /// as drawn (in the stitch pass a list is the ends at a point or two;
    /// in the order pass a loop has an end a vertex, and finding each one's
    /// predecessor cost more than passing them).
    fn take(&mut self, f: usize) {
        if self.any_vertex {
            let (from, to) = self.span(f);
            self.kill(from, to);
        } else if let Some(h) = self.odd {
            self.odd = Some(h ^ self.ends_hash(f));
        }
        let s = self.w.get(f);
        self.w.set(f, s | DRAWN);
    }

    /// Fragment `f`'s share of [`Index::odd`] (none in the order pass).
    fn ends_hash(&self, f: usize) -> u64 {
        if self.any_vertex || self.is_dot(f) {
            return 0;
        }
        let (from, to) = self.span(f);
        let h = point_hash(self.point(from));
        if to - from > 1 { h ^ point_hash(self.point(to - 1)) } else { h }
    }

    /// The slots of the ends in cell `c` (any point) of fragments not yet
    /// drawn, by calling `visit` until it says stop.
    fn each_end(&self, c: usize, mut visit: impl FnMut(usize) -> bool) {
        let mut at = self.w.get(self.heads + c);
        while at != NONE {
            let s = at as usize;
            let live = if self.any_vertex { !self.dead(s) } else { !self.drawn(s / 2) };
            if live && !visit(s) {
                return;
            }
            at = self.w.get(self.links + s);
        }
    }

    /// How many fragment ends lie exactly at `q` (a dot counts twice: a
    /// path passes through it).
    fn degree(&self, q: Packed) -> usize {
        let mut n = 0;
        self.each_end(self.cell(q), |s| {
            let i = self.end_point(s);
            if self.point(i) == q {
                n += if self.kind(i) == Kind::Dot { 2 } else { 1 };
            }
            true
        });
        n
    }

    /// Of the ends exactly at `cur`, the one whose fragment goes on
    /// straightest from `prev -> cur`: its point and its fragment.
    fn straightest(&self, cur: Packed, prev: Option<Packed>) -> Option<(usize, usize)> {
        let v = |q: Packed| [f32::from(q[0]), f32::from(q[1]), f32::from(q[2])];
        let unit = |a: Packed, b: Packed| {
            let (a, b) = (v(a), v(b));
            let d = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
            let n = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
            if n > 0.0 { [d[0] / n, d[1] / n, d[2] / n] } else { [0.0; 3] }
        };
        // Scores are made only once a second end turns up (the first is
        // scored then): a lone end, as at a crossing's second visit, is
        // taken without a square root.
        let mut dir_in: Option<Option<[f32; 3]>> = None;
        let mut first: Option<(usize, usize, usize)> = None;
        let mut best: Option<(f32, (usize, usize))> = None;
        self.each_end(self.cell(cur), |s| {
            let f = self.end_frag(s);
            let (from, to) = self.span(f);
            // `end_point`, from the span already read.
            let i = if self.any_vertex {
                s
            } else if s & 1 == 0 {
                from
            } else {
                to - 1
            };
            // Only a fragment's first point may be a dot (the rest are lines).
            if self.point(i) == cur && (i != from || self.kind(i) != Kind::Dot) {
                let next = if i == from { (from + 1).min(to - 1) } else { i.saturating_sub(1).max(from) };
                if first.is_none() && best.is_none() {
                    first = Some((i, f, next));
                    return true;
                }
                let d = *dir_in.get_or_insert_with(|| prev.map(|p| unit(p, cur)));
                let score = |next: usize| {
                    d.map_or(0.0, |d| {
                        let u = unit(cur, self.point(next));
                        d[0] * u[0] + d[1] * u[1] + d[2] * u[2]
                    })
                };
                if let Some((i0, f0, next0)) = first.take() {
                    best = Some((score(next0), (i0, f0)));
                }
                let score = score(next);
                if best.is_none_or(|(b, _)| score > b) {
                    best = Some((score, (i, f)));
                }
            }
            true
        });
        best.map(|(_, end)| end).or(first.map(|(i, f, _)| (i, f)))
    }

    /// The end nearest `cur` within [`RINGS`] rings of cells.
    fn nearest(&mut self, cur: Packed) -> Option<usize> {
        let [cx, cy, cz] = cell_coords(cur, self.n, self.bits).map(|c| c as i32);
        let [nx, ny, nz] = self.n.map(|n| n as i32);
        let side = 1u64 << self.bits;
        let mut best: Option<(u64, usize)> = None;
        // The ends of one cell (its drawn ones taken out of the list
        // first): whether one lies at `cur` (then it is the nearest).
        let visit = |x: &mut Self, cell: i32, best: &mut Option<(u64, usize)>| {
            x.prune(cell as usize);
            x.each_end(cell as usize, |s| {
                let i = x.end_point(s);
                let d = dist2(cur, x.point(i));
                if best.is_none_or(|(bd, _)| d < bd) {
                    *best = Some((d, i));
                }
                d != 0
            });
            best.is_some_and(|(d, _)| d == 0)
        };
        for r in 0..=RINGS {
            // The shell of ring r inside the grid, in the order of z, y,
            // then x: inside its faces, just the two cells at x = cx - r
            // and x = cx + r.
            let (x0, x1) = ((cx - r).max(0), (cx + r).min(nx - 1));
            for z in (cz - r).max(0)..=(cz + r).min(nz - 1) {
                for y in (cy - r).max(0)..=(cy + r).min(ny - 1) {
                    let row = nx * (y + ny * z);
                    let face = (z - cz).abs() == r || (y - cy).abs() == r;
                    let found = if face || r == 0 {
                        (x0..=x1).any(|x| visit(self, row + x, &mut best))
                    } else {
                        (cx - r >= 0 && visit(self, row + cx - r, &mut best))
                            || (cx + r < nx && visit(self, row + cx + r, &mut best))
                    };
                    if found {
                        return best.map(|(_, i)| i);
                    }
                }
            }
            // Anything in the next ring is at least r cells away.
            if let Some((d, i)) = best {
                let reach = r as u64 * side;
                if d <= reach * reach {
                    return Some(i);
                }
            }
        }
        best.map(|(_, i)| i)
    }

    /// The first end not drawn at or after the cursor's cell (cells before
    /// it have none for good: ends are only ever drawn).
    fn first_from(&self, scan: &mut usize) -> Option<usize> {
        while *scan < self.cells() {
            let mut first = None;
            self.each_end(*scan, |s| {
                first = Some(s);
                false
            });
            if let Some(s) = first {
                return Some(self.end_point(s));
            }
            *scan += 1;
        }
        None
    }

    /// Take out what would be drawn twice: a one-segment fragment equal to
    /// another, and a dot where a line or another dot is.
    fn cull(&mut self, stats: &mut ChainStats) {
        for f in 0..self.frags {
            if self.drawn(f) {
                continue;
            }
            let (from, to) = self.span(f);
            let (a, b) = (self.point(from), self.point(to - 1));
            if self.is_dot(f) {
                // Its own end counts 2.
                if self.degree(a) > 2 {
                    self.take(f);
                    stats.culled_dots += 1;
                }
                continue;
            }
            if to - from != 2 || a == b {
                continue;
            }
            // Each round takes a twin for good: at most `frags` rounds.
            for _ in 0..self.frags {
                let mut twin = None;
                self.each_end(self.cell(a), |s| {
                    let (i, g) = (self.end_point(s), self.end_frag(s));
                    if g != f && self.point(i) == a && !self.is_dot(g) && !self.is_loop(g) {
                        let (f2, t2) = self.span(g);
                        let other = if i == f2 { self.point(t2 - 1) } else { self.point(f2) };
                        if t2 - f2 == 2 && other == b {
                            twin = Some(g);
                            return false;
                        }
                    }
                    true
                });
                let Some(g) = twin else { break };
                self.take(g);
                stats.duplicate_segments += 1;
            }
        }
    }
}

/// Chains `src` into `dst` (reset to `src`'s scale) as `pass` says; runs
/// of points within `tolerance` voxels of their chord are merged (0:
/// none). `start` is where the beam comes from. `scratch` should
/// hold about 7 bytes a point; with less, the fragments are copied as they
/// are.
pub(crate) fn chain(
    src: Source<'_>,
    dst: &mut Geometry<'_>,
    scratch: &mut [u8],
    start: Packed,
    tolerance: f32,
    pass: Pass,
) -> ChainStats {
    chain_on(src, dst, scratch, start, tolerance, pass, pass == Pass::Stitch)
}

/// [`chain`], with the stitch pass's ends in hashed buckets or (`hashed`
/// false, for the test that both stitch alike) in the grid of cells.
fn chain_on(
    src: Source<'_>,
    dst: &mut Geometry<'_>,
    scratch: &mut [u8],
    start: Packed,
    tolerance: f32,
    pass: Pass,
    hashed: bool,
) -> ChainStats {
    dst.reset(src.shift());
    let mut stats = ChainStats { points_in: src.len() as u32, ..ChainStats::default() };
    let Some(mut x) = Index::build(src, scratch, pass != Pass::Stitch, hashed && pass == Pass::Stitch) else {
        copy(src, dst, &mut stats);
        return stats;
    };
    stats.fragments = x.frags as u32;
    stats.ordered = true;
    let mut walk = Walk { out: Out::new(tolerance, src.shift()), cur: start, prev: None };
    match pass {
        Pass::Order(metric) => {
            // The tour: nearest neighbour, then 2-opt, then each loop entered
            // at its best vertex; drawn last.
            mark_spliced(&mut x);
            let mut tour = Tour { base: x.tour_base(), len: 0, metric };
            let mut scan = 0;
            let mut cur = start;
            for _ in 0..x.frags {
                let Some(end) = x.nearest(cur).or_else(|| x.first_from(&mut scan)) else { break };
                let f = x.frag_of(end);
                x.take(f);
                tour.push(&mut x, f, end);
                cur = x.point(exit(&x, f, end));
            }
            tour.improve(&mut x, start);
            // Drawn in the tour's order; a loop that passes exactly
            // through a point being drawn is drawn there, and the beam goes
            // on from where it came back (no jump to it, none from it).
            x.relink(true);
            for k in 0..tour.len {
                let (end, _) = tour.get(&x.w, k);
                let f = x.frag_of(end);
                if !x.emitted(f) {
                    walk.emit_spliced(&mut x, dst, f, end, &mut stats);
                }
            }
            // A loop the tour left to a splice that this drawing order
            // reached too deep (or not at all): drawn after the tour.
            for f in 0..x.frags {
                if !x.emitted(f) {
                    let end = x.span(f).0;
                    walk.emit_spliced(&mut x, dst, f, end, &mut stats);
                }
            }
        }
        Pass::Stitch => {
            x.cull(&mut stats);
            // Open paths first (from an end where an odd number meet), then
            // what is left: closed loops. (The first round ends when no odd
            // end is left: at once for a closed surface.)
            for odd in [true, false] {
                for f in 0..x.frags {
                    if odd && x.odd == Some(0) {
                        break;
                    }
                    if x.drawn(f) {
                        continue;
                    }
                    let (from, to) = x.span(f);
                    let last = to - 1;
                    let end = if !odd || x.degree(x.point(from)) % 2 == 1 {
                        from
                    } else if x.degree(x.point(last)) % 2 == 1 {
                        last
                    } else {
                        continue;
                    };
                    walk.take(&mut x, dst, (end, f), false, &mut stats);
                    // Each step takes a fragment for good: at most `frags`
                    // of them (a bound the walk keeps even if an end were
                    // ever left in its list).
                    let mut steps = 0;
                    while steps < x.frags
                        && let Some(next) = x.straightest(walk.cur, walk.prev)
                    {
                        walk.take(&mut x, dst, next, true, &mut stats);
                        steps += 1;
                    }
                    walk.out.finish(dst, &mut stats);
                }
                x.odd = None;
            }
        }
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

/// The point where the beam leaves fragment `f` entered at point `end`.
fn exit(x: &Index<'_, '_>, f: usize, end: usize) -> usize {
    let (from, to) = x.span(f);
    if x.is_loop(f) {
        end
    } else if end == from {
        to - 1
    } else {
        from
    }
}

/// The order pass's tour, in [`TOUR_WORDS`] words a step after the index's
/// links: the point a fragment is entered at, the point it is left at (the
/// same for a loop or a dot) and the length of the jump to the next step
/// (an `f32`'s bits, kept by [`Tour::two_opt`]).
struct Tour {
    base: usize,
    len: usize,
    metric: Metric,
}

/// Jumps the order pass's local search measures at most, all moves of
/// all passes: some 60 instructions each on the MCU, 1M is about 0.4 s at
/// 168 MHz, spent only on pictures of over a thousand polylines (a full
/// search of `n` polylines costs about `n^2` a pass).
const SEARCH_BUDGET: u64 = 1 << 20;

/// Words a tour step takes.
const TOUR_WORDS: usize = 3;

impl Tour {
    fn push(&mut self, x: &mut Index<'_, '_>, f: usize, end: usize) {
        let out = exit(x, f, end);
        self.set(&mut x.w, self.len, end, out);
        self.len += 1;
    }

    /// Step `k`'s entry and exit point indices.
    fn get(&self, w: &Words<'_>, k: usize) -> (usize, usize) {
        let at = self.base + TOUR_WORDS * k;
        (w.get(at) as usize, w.get(at + 1) as usize)
    }

    fn set(&self, w: &mut Words<'_>, k: usize, entry: usize, exit: usize) {
        let at = self.base + TOUR_WORDS * k;
        w.set(at, entry as u32);
        w.set(at + 1, exit as u32);
    }

    fn jump(&self, w: &Words<'_>, k: usize) -> f32 {
        f32::from_bits(w.get(self.base + TOUR_WORDS * k + 2))
    }

    fn set_jump(&self, w: &mut Words<'_>, k: usize, v: f32) {
        w.set(self.base + TOUR_WORDS * k + 2, v.to_bits());
    }

    /// Where step `k` is entered and left.
    fn ends(&self, x: &Index<'_, '_>, k: usize) -> (Packed, Packed) {
        let (entry, exit) = self.get(&x.w, k);
        (x.point(entry), x.point(exit))
    }

    /// Measure the jump from step `k` to step `k + 1`.
    fn measure(&self, x: &mut Index<'_, '_>, k: usize) {
        let jump = self.metric.d(self.ends(x, k).1, self.ends(x, k + 1).0);
        self.set_jump(&mut x.w, k, jump);
    }

    /// Improve the nearest-neighbour tour: 2-opt and or-opt in turn while
    /// either finds a move (and the budget lasts), then each loop entered
    /// at its best vertex.
    fn improve(&self, x: &mut Index<'_, '_>, start: Packed) {
        if let Some(mut near) = Near::build(x, self) {
            // Moves among screen neighbours: every step's, however long the
            // tour, until a pass finds none; the loops' entries chosen
            // again after each pass (and the neighbours found again).
            let mut budget = SEARCH_BUDGET;
            for _ in 0..16 {
                let a = self.two_opt_near(x, &near, &mut budget);
                let b = self.or_opt_near(x, &near, &mut budget);
                self.best_entries(x, start);
                if !(a || b) || budget == 0 {
                    break;
                }
                match Near::build(x, self) {
                    Some(n) => near = n,
                    None => break,
                }
            }
            return;
        }
        let n = self.len as u64;
        // Steps a 2-opt move reverses, and positions an or-opt move tries:
        // all of them while a pass costs no more than an eighth of the
        // budget, else as many as keep it so (at least WINDOW).
        let window = ((SEARCH_BUDGET / 8) / n.max(1)).max(WINDOW as u64).min(n) as usize;
        let mut budget = SEARCH_BUDGET;
        for _ in 0..8 {
            let a = self.two_opt(x, window, &mut budget);
            let b = self.or_opt(x, window, &mut budget);
            if !(a || b) || budget == 0 {
                break;
            }
        }
        self.best_entries(x, start);
    }

    /// Or-opt: take one step out and put it back, either way round, where
    /// that shortens the tour most, among the `window` positions on either
    /// side; a pass over every step. Returns whether it moved one.
    fn or_opt(&self, x: &mut Index<'_, '_>, window: usize, budget: &mut u64) -> bool {
        let n = self.len;
        if n < 4 {
            return false;
        }
        let m = self.metric;
        let mut moved = false;
        for i in 1..n {
            if *budget == 0 {
                break;
            }
            let (e, o) = self.ends(x, i);
            let prev = self.ends(x, i - 1).1;
            let next = (i + 1 < n).then(|| self.ends(x, i + 1).0);
            let gain = self.jump(&x.w, i - 1) + if i + 1 < n { self.jump(&x.w, i) } else { 0.0 }
                - next.map_or(0.0, |nx| m.d(prev, nx));
            if gain <= 1e-3 {
                continue;
            }
            // Between steps k and k + 1 (k + 1 == n: after the last).
            let mut best: Option<(f32, usize, bool)> = None;
            let lo = i.saturating_sub(window).max(1) - 1;
            let hi = (i + window).min(n - 1);
            for k in lo..=hi {
                if k == i || k + 1 == i {
                    continue;
                }
                *budget = budget.saturating_sub(1);
                let a = self.ends(x, k).1;
                let b = (k + 1 < n).then(|| self.ends(x, k + 1).0);
                let old = if k + 1 < n { self.jump(&x.w, k) } else { 0.0 };
                for flip in [false, true] {
                    let (ie, io) = if flip { (o, e) } else { (e, o) };
                    // The first new jump alone no shorter than the gain, less
                    // what the old jump gives back: no better (no root).
                    let bound = gain + old;
                    if m.d2(a, ie) * 0.999_99 >= bound * bound {
                        continue;
                    }
                    let add = m.d(a, ie) + b.map_or(0.0, |b| m.d(io, b)) - old;
                    if add + 1e-3 < gain && best.is_none_or(|(c, ..)| add < c) {
                        best = Some((add, k, flip));
                    }
                }
            }
            if let Some((_, k, flip)) = best {
                self.relocate(x, i, 1, k, flip);
                moved = true;
            }
        }
        moved
    }

    /// Or-opt among screen neighbours: each step tried just after a step
    /// that leaves it, or just before one that enters it, within the gain
    /// of taking it out of the tour. Returns whether it moved one.
    fn or_opt_near(&self, x: &mut Index<'_, '_>, near: &Near, budget: &mut u64) -> bool {
        let n = self.len;
        if n < 4 {
            return false;
        }
        let m = self.metric;
        let mut moved = false;
        for (len, i) in (1..=OR_CHAIN).flat_map(|len| (1..n.saturating_sub(len - 1)).map(move |i| (len, i))) {
            if *budget == 0 {
                break;
            }
            if i + len > n {
                continue;
            }
            // The run i .. i + len, entered at e and left at o.
            let last = i + len - 1;
            let (e, o) = (self.ends(x, i).0, self.ends(x, last).1);
            let (ei, oi) = (self.get(&x.w, i).0, self.get(&x.w, last).1);
            let prev = self.ends(x, i - 1).1;
            let next = (last + 1 < n).then(|| self.ends(x, last + 1).0);
            let gain = self.jump(&x.w, i - 1) + if last + 1 < n { self.jump(&x.w, last) } else { 0.0 }
                - next.map_or(0.0, |nx| m.d(prev, nx));
            if gain <= 1e-3 {
                continue;
            }
            let mut best: Option<(f32, usize, bool)> = None;
            let mut consider = |x: &Index<'_, '_>, k: usize, budget: &mut u64| {
                if (i - 1..=last).contains(&k) || k >= n {
                    return;
                }
                *budget = budget.saturating_sub(1);
                let a = self.ends(x, k).1;
                let b = (k + 1 < n).then(|| self.ends(x, k + 1).0);
                let old = if k + 1 < n { self.jump(&x.w, k) } else { 0.0 };
                for flip in [false, true] {
                    let (ie, io) = if flip { (o, e) } else { (e, o) };
                    let add = m.d(a, ie) + b.map_or(0.0, |b| m.d(io, b)) - old;
                    if add + 1e-3 < gain && best.is_none_or(|(c, ..)| add < c) {
                        best = Some((add, k, flip));
                    }
                }
            };
            for end in [ei, oi] {
                near.each_near(
                    x,
                    m,
                    x.point(end),
                    gain,
                    |x, c, budget| {
                        let j = near.pos(x, c);
                        let (ej, oj) = self.get(&x.w, j);
                        if oj == c {
                            consider(x, j, budget);
                        }
                        if ej == c && j > 0 {
                            consider(x, j - 1, budget);
                        }
                    },
                    budget,
                );
                if ei == oi {
                    break;
                }
            }
            if let Some((_, k, flip)) = best {
                let dest = self.relocate(x, i, len, k, flip);
                near.place(x, self, i.min(dest), last.max(dest + len - 1));
                moved = true;
            }
        }
        moved
    }

    /// 2-opt among screen neighbours: a run reversed where a step's exit
    /// is near the exit of a later one, or its entry near the entry of an
    /// earlier one, closer than the jump it leaves by. Returns whether it
    /// reversed one.
    fn two_opt_near(&self, x: &mut Index<'_, '_>, near: &Near, budget: &mut u64) -> bool {
        let n = self.len;
        if n < 3 {
            return false;
        }
        for k in 0..n - 1 {
            self.measure(x, k);
        }
        let m = self.metric;
        let mut any = false;
        for i in 0..n - 1 {
            if *budget == 0 {
                break;
            }
            // The jump out of step i, replaced by one to a later step's exit:
            // reverse i + 1 ..= j.
            let (_, oi) = self.get(&x.w, i);
            let mut found = None;
            near.each_near(
                x,
                m,
                x.point(oi),
                self.jump(&x.w, i),
                |x, c, budget| {
                    let j = near.pos(x, c);
                    if found.is_some() || j < i + 2 || self.get(&x.w, j).1 != c {
                        return;
                    }
                    *budget = budget.saturating_sub(1);
                    let old = self.jump(&x.w, i) + if j + 1 < n { self.jump(&x.w, j) } else { 0.0 };
                    let in_i1 = self.ends(x, i + 1).0;
                    let new = m.d(x.point(oi), x.point(c))
                        + if j + 1 < n { m.d(in_i1, self.ends(x, j + 1).0) } else { 0.0 };
                    if new + 1e-3 < old {
                        found = Some(j);
                    }
                },
                budget,
            );
            if let Some(j) = found {
                self.reverse(x, i + 1, j);
                self.measure(x, i);
                if j + 1 < n {
                    self.measure(x, j);
                }
                near.place(x, self, i + 1, j);
                any = true;
                continue;
            }
            // The jump into step i + 1, replaced by one from an earlier
            // step's entry: reverse l ..= i.
            if i == 0 {
                continue;
            }
            let (e1, _) = self.get(&x.w, i + 1);
            near.each_near(
                x,
                m,
                x.point(e1),
                self.jump(&x.w, i),
                |x, c, budget| {
                    let l = near.pos(x, c);
                    if found.is_some() || l == 0 || l >= i || self.get(&x.w, l).0 != c {
                        return;
                    }
                    *budget = budget.saturating_sub(1);
                    let old = self.jump(&x.w, l - 1) + self.jump(&x.w, i);
                    let new = m.d(self.ends(x, l - 1).1, self.ends(x, i).1) + m.d(x.point(c), x.point(e1));
                    if new + 1e-3 < old {
                        found = Some(l);
                    }
                },
                budget,
            );
            if let Some(l) = found {
                self.reverse(x, l, i);
                self.measure(x, l - 1);
                self.measure(x, i);
                near.place(x, self, l, i);
                any = true;
            }
        }
        any
    }

    /// Move the `len` steps from `i` (at most [`OR_CHAIN`]) to just after
    /// step `k` (counted before the move, outside the run), drawn the
    /// other way round if `flip`, and measure the jumps again. Returns
    /// where the run starts now.
    fn relocate(&self, x: &mut Index<'_, '_>, i: usize, len: usize, k: usize, flip: bool) -> usize {
        let len = len.clamp(1, OR_CHAIN);
        let mut run = [(0usize, 0usize); OR_CHAIN];
        for (d, slot) in run.iter_mut().take(len).enumerate() {
            *slot = self.get(&x.w, i + d);
        }
        if flip && let Some(r) = run.get_mut(..len) {
            {
                r.reverse();
                for s in r {
                    *s = (s.1, s.0);
                }
            }
        }
        let dest = if k < i {
            for j in (k + 1..i).rev() {
                let (a, b) = self.get(&x.w, j);
                self.set(&mut x.w, j + len, a, b);
            }
            k + 1
        } else {
            for j in i + len..=k {
                let (a, b) = self.get(&x.w, j);
                self.set(&mut x.w, j - len, a, b);
            }
            k + 1 - len
        };
        for (d, &(a, b)) in run.iter().take(len).enumerate() {
            self.set(&mut x.w, dest + d, a, b);
        }
        let lo = i.min(dest).saturating_sub(1);
        let hi = (i.max(dest) + len).min(self.len - 1);
        for j in lo..hi {
            self.measure(x, j);
        }
        dest
    }

    /// 2-opt: reverse a run of up to [`WINDOW`] steps (each drawn the other
    /// way) where that shortens the two jumps at its ends; first
    /// improvement, until a pass finds none (at most 8 passes).
    ///
    /// The jumps' lengths are kept with the steps (and mended after a
    /// reversal), and a candidate whose first new jump alone is surely no
    /// shorter than the two old ones is turned down without a square root:
    /// the same moves as measuring every jump afresh, at a fraction of the
    /// cost.
    fn two_opt(&self, x: &mut Index<'_, '_>, window: usize, budget: &mut u64) -> bool {
        let n = self.len;
        if n < 3 {
            return false;
        }
        for k in 0..n - 1 {
            self.measure(x, k);
        }
        let m = self.metric;
        let mut improved = true;
        let mut any = false;
        let mut passes = 0;
        while improved && *budget > 0 && passes < 8 {
            passes += 1;
            improved = false;
            for i in 0..n - 1 {
                // The jump into step i + 1 comes from step i's exit; step 0
                // is never moved, so the jump from the start stays.
                let out_i = self.ends(x, i).1;
                let in_i1 = self.ends(x, i + 1).0;
                let before = self.jump(&x.w, i);
                for j in i + 2..n.min(i + 2 + window) {
                    *budget = budget.saturating_sub(1);
                    let out_j = self.ends(x, j).1;
                    let old = before + if j + 1 < n { self.jump(&x.w, j) } else { 0.0 };
                    // `length` is within 1e-6 of the true root: a first new
                    // jump this long is no shorter than `old`, nor is `new`.
                    if m.d2(out_i, out_j) * 0.999_99 >= old * old {
                        continue;
                    }
                    let after = if j + 1 < n { Some(self.ends(x, j + 1).0) } else { None };
                    let new = m.d(out_i, out_j) + after.map_or(0.0, |a| m.d(in_i1, a));
                    if new + 1e-3 < old {
                        self.reverse(x, i + 1, j);
                        self.measure(x, i);
                        if j + 1 < n {
                            self.measure(x, j);
                        }
                        improved = true;
                        any = true;
                        break;
                    }
                }
                if *budget == 0 {
                    break;
                }
            }
        }
        any
    }

    /// Reverse steps `a..=b`, each drawn the other way (entry and exit
    /// swapped), and the jumps between them (a length reads the same both
    /// ways).
    fn reverse(&self, x: &mut Index<'_, '_>, a: usize, b: usize) {
        let (mut lo, mut hi) = (a, b);
        while lo <= hi {
            let (ea, xa) = self.get(&x.w, lo);
            let (eb, xb) = self.get(&x.w, hi);
            self.set(&mut x.w, lo, xb, eb);
            self.set(&mut x.w, hi, xa, ea);
            lo += 1;
            if hi == 0 {
                break;
            }
            hi -= 1;
        }
        let (mut lo, mut hi) = (a, b.saturating_sub(1));
        while lo < hi {
            let (ja, jb) = (self.jump(&x.w, lo), self.jump(&x.w, hi));
            self.set_jump(&mut x.w, lo, jb);
            self.set_jump(&mut x.w, hi, ja);
            lo += 1;
            hi -= 1;
        }
    }

    /// Enter each closed loop at the vertex nearest the jumps around it.
    fn best_entries(&self, x: &mut Index<'_, '_>, start: Packed) {
        let m = self.metric;
        let mut prev: Option<Packed> = None;
        for k in 0..self.len {
            let (end, _) = self.get(&x.w, k);
            let f = x.frag_of(end);
            if x.is_loop(f) {
                let next = if k + 1 < self.len { Some(self.ends(x, k + 1).0) } else { None };
                let into = |v: Packed| prev.map_or_else(|| m.first_jump(start, v), |p| m.d(p, v));
                let cost = |v: Packed| into(v) + next.map_or(0.0, |n| m.d(v, n));
                let (from, to) = x.span(f);
                let mut best = (cost(x.point(end)), end);
                for i in from..to {
                    let v = x.point(i);
                    // Either jump alone surely as long as the best (as in
                    // `two_opt`): no shorter, without a square root.
                    let bound = best.0 * best.0;
                    if prev.is_some_and(|p| m.d2(p, v) * 0.999_99 >= bound)
                        || next.is_some_and(|n| m.d2(v, n) * 0.999_99 >= bound)
                    {
                        continue;
                    }
                    let c = cost(v);
                    if c < best.0 {
                        best = (c, i);
                    }
                }
                self.set(&mut x.w, k, best.1, best.1);
            }
            prev = Some(self.ends(x, k).1);
        }
    }
}

/// Steps an or-opt move takes along at most (among screen neighbours).
const OR_CHAIN: usize = 3;

/// Rings of cells [`Near::each_near`] searches at most around a point.
const NEAR_RINGS: usize = 3;

/// The order pass's neighbours on the screen: the ends of the tour's steps
/// in a grid of cells on the metric's screen, and each step's position in
/// the tour by fragment. In the index's cell heads and links, idle from the
/// tour's nearest-neighbour search until the splices' [`Index::relink`]
/// (or, where the grid is small, in the words past the drawn bits): the
/// positions, the grid's heads after them, and a link a point.
struct Near {
    pos: usize,
    heads: usize,
    cells: [usize; 2],
    lo: [f32; 2],
    /// Cells per screen unit.
    scale: f32,
}

impl Near {
    /// The neighbours of `tour`'s steps, for a [`Metric::Screen`] tour
    /// with the room; `None` otherwise (the windowed search then serves).
    fn build(x: &mut Index<'_, '_>, tour: &Tour) -> Option<Near> {
        let Metric::Screen { view, shift, .. } = tour.metric else { return None };
        let n = tour.len;
        if n < 8 || x.buckets != 0 {
            return None;
        }
        // The positions and the heads: in the grid's heads, or else in the
        // words past the drawn bits.
        let grid: usize = x.n.iter().map(|&c| c as usize).product();
        let free = x.dead + x.src.len().div_ceil(32);
        let spare = x.w.len().saturating_sub(free);
        let (pos, room) = if grid >= spare {
            (x.frags, grid.checked_sub(x.frags + 16)? + 16)
        } else {
            (free, spare.checked_sub(x.frags + 16)? + 16)
        };
        let at = |q: Packed| Metric::at(&view, shift, q);
        let (mut lo, mut hi) = ([f32::MAX; 2], [f32::MIN; 2]);
        for k in 0..n {
            let (e, o) = tour.get(&x.w, k);
            for p in [e, o] {
                let s = at(x.point(p));
                for ((l, h), v) in lo.iter_mut().zip(hi.iter_mut()).zip(s) {
                    *l = l.min(v);
                    *h = h.max(v);
                }
            }
        }
        // About one end a cell.
        let want = room.min(2 * n).max(1) as f32;
        let (w, h) = ((hi[0] - lo[0]).max(1.0), (hi[1] - lo[1]).max(1.0));
        let mut scale = sqrt(want / (w * h));
        if !scale.is_finite() || scale <= 0.0 {
            return None;
        }
        let dim = |v: f32, scale: f32| ((v * scale) as usize + 1).clamp(1, 1 << 15);
        // Coarser until the cells fit (a thin strip rounds up).
        let mut cells = [dim(w, scale), dim(h, scale)];
        for _ in 0..64 {
            if cells[0] * cells[1] <= room {
                break;
            }
            scale *= 0.75;
            cells = [dim(w, scale), dim(h, scale)];
        }
        if cells[0] * cells[1] > room {
            return None;
        }
        let near = Near { pos, heads: pos + x.frags, cells, lo, scale };
        for c in 0..cells[0] * cells[1] {
            x.w.set(near.heads + c, NONE);
        }
        for k in 0..n {
            let (e, o) = tour.get(&x.w, k);
            for p in [e, o] {
                let c = near.cell_of(at(x.point(p)));
                let head = x.w.get(near.heads + c);
                x.w.set(x.links + p, head);
                x.w.set(near.heads + c, p as u32);
                if e == o {
                    break;
                }
            }
        }
        near.place(x, tour, 0, n - 1);
        Some(near)
    }

    fn coords(&self, s: [f32; 2]) -> [usize; 2] {
        let c = |v: f32, lo: f32, cells: usize| {
            let v = (v - lo) * self.scale;
            if v > 0.0 { (v as usize).min(cells - 1) } else { 0 }
        };
        [c(s[0], self.lo[0], self.cells[0]), c(s[1], self.lo[1], self.cells[1])]
    }

    fn cell_of(&self, s: [f32; 2]) -> usize {
        let [cx, cy] = self.coords(s);
        cx + self.cells[0] * cy
    }

    /// Record that steps `a ..= b` of the tour are where they are now.
    fn place(&self, x: &mut Index<'_, '_>, tour: &Tour, a: usize, b: usize) {
        for k in a..=b.min(tour.len.saturating_sub(1)) {
            let f = x.frag_of(tour.get(&x.w, k).0);
            x.w.set(self.pos + f, k as u32);
        }
    }

    /// The position in the tour of the step that point `p` ends.
    fn pos(&self, x: &Index<'_, '_>, p: usize) -> usize {
        x.w.get(self.pos + x.frag_of(p)) as usize
    }

    /// `visit` the ends in the cells within `r` of `q` on the screen (at
    /// most [`NEAR_RINGS`] rings of them), each counted against `budget`.
    fn each_near(
        &self,
        x: &mut Index<'_, '_>,
        m: Metric,
        q: Packed,
        r: f32,
        mut visit: impl FnMut(&mut Index<'_, '_>, usize, &mut u64),
        budget: &mut u64,
    ) {
        let Metric::Screen { view, shift, .. } = m else { return };
        let s = Metric::at(&view, shift, q);
        let [cx, cy] = self.coords(s);
        let reach = ((r * self.scale) as usize + 1).min(NEAR_RINGS);
        let (x0, x1) = (cx.saturating_sub(reach), (cx + reach).min(self.cells[0] - 1));
        let (y0, y1) = (cy.saturating_sub(reach), (cy + reach).min(self.cells[1] - 1));
        for y in y0..=y1 {
            for xx in x0..=x1 {
                let mut at = x.w.get(self.heads + xx + self.cells[0] * y);
                while at != NONE && *budget > 0 {
                    let p = at as usize;
                    at = x.w.get(x.links + p);
                    *budget = budget.saturating_sub(1);
                    visit(x, p, budget);
                }
            }
        }
    }
}

/// Where the beam is, and the chain being written.
struct Walk {
    out: Out,
    /// The last point drawn, and the one before it.
    cur: Packed,
    prev: Option<Packed>,
}

impl Walk {
    /// Take and draw fragment `f`, entering at its end `end`: a
    /// continuation of the chain when it starts where the chain ends (and
    /// `join` allows, or the ends meet exactly), else a new chain after a
    /// jump.
    fn take(
        &mut self,
        x: &mut Index<'_, '_>,
        dst: &mut Geometry<'_>,
        (end, f): (usize, usize),
        join: bool,
        stats: &mut ChainStats,
    ) {
        x.take(f);
        self.draw(x, dst, f, end, join, stats);
    }

    /// The order pass: draw fragment `f` entering at `end`, and at each
    /// point it passes, any closed loop not drawn yet that passes exactly
    /// there (entered and left at that point, so the beam goes on where it
    /// left off), and within that loop the same, up to [`SPLICE_DEPTH`]
    /// loops deep. A chicken-wire surface is loops crossing at shared
    /// points: so it is drawn in a few long polylines, one a connected
    /// piece, instead of a loop a slice and a jump between each two.
    fn emit_spliced(
        &mut self,
        x: &mut Index<'_, '_>,
        dst: &mut Geometry<'_>,
        f: usize,
        end: usize,
        stats: &mut ChainStats,
    ) {
        let (from, to) = x.span(f);
        x.kill(from, to);
        if x.is_dot(f) {
            self.draw(x, dst, f, end, false, stats);
            return;
        }
        let first = x.point(end);
        if first != self.cur || !self.out.open {
            self.out.finish(dst, stats);
            stats.travel += length(first, self.cur) / f32::from(1u16 << x.src.shift());
        }
        let spliced = splice_walk(x, f, end, false, |q| {
            self.out.point(dst, q, false, stats);
            if self.cur != q {
                self.prev = Some(self.cur);
                self.cur = q;
            }
        });
        stats.spliced += spliced;
    }

    fn draw(
        &mut self,
        x: &Index<'_, '_>,
        dst: &mut Geometry<'_>,
        f: usize,
        end: usize,
        join: bool,
        stats: &mut ChainStats,
    ) {
        let (from, to) = x.span(f);
        let first = x.point(end);
        if !(join || first == self.cur) || !self.out.open {
            self.out.finish(dst, stats);
            stats.travel += length(first, self.cur) / f32::from(1u16 << x.src.shift());
        }
        // Only a fragment's first point may be a dot (the rest are lines).
        let dot = x.kind(from) == Kind::Dot;
        let mut emit = |i: usize| {
            let q = x.point(i);
            self.out.point(dst, q, dot && i == from, stats);
            if self.cur != q {
                self.prev = Some(self.cur);
                self.cur = q;
            }
        };
        if x.is_loop(f) {
            // Entered at `end`: round to it again.
            (end..to).chain(from..=end).for_each(&mut emit);
        } else if end + 1 == to && end != from {
            (from..to).rev().for_each(&mut emit);
        } else {
            (from..to).for_each(&mut emit);
        }
    }
}

/// Walk fragment `f` from its point `end` as [`Walk::emit_spliced`] draws
/// it: `visit` each point in drawing order, with every closed loop not yet
/// drawn that passes exactly through one of them drawn there, round and
/// back (up to [`SPLICE_DEPTH`] deep). Marks the points drawn, and (`mark`)
/// the loops drawn inside ([`DRAWN`]). Returns how many were.
fn splice_walk(
    x: &mut Index<'_, '_>,
    f: usize,
    end: usize,
    mark: bool,
    mut visit: impl FnMut(Packed),
) -> u32 {
    let (from, to) = x.span(f);
    x.kill(from, to);
    let mut stack = [Splice::default(); SPLICE_DEPTH];
    stack[0] = Splice::new(from, to, end, x.is_loop(f));
    let mut depth: usize = 1;
    let mut spliced = 0;
    while let Some(top) = depth.checked_sub(1).and_then(|d| stack.get_mut(d)) {
        let Some(i) = top.next() else {
            depth -= 1;
            continue;
        };
        let q = x.point(i);
        visit(q);
        if depth < SPLICE_DEPTH
            && let Some(s) = x.loop_at(q)
            && let Some(slot) = stack.get_mut(depth)
        {
            let g = x.frag_of(s);
            let (gf, gt) = x.span(g);
            x.kill(gf, gt);
            if mark {
                let w = x.w.get(g);
                x.w.set(g, w | DRAWN);
            }
            // Its first vertex is `q`, just drawn.
            *slot = Splice::new(gf, gt, s, true);
            slot.next();
            depth += 1;
            spliced += 1;
        }
    }
    spliced
}

/// The order pass, before its tour: mark drawn ([`DRAWN`]) each closed
/// loop that the chains will draw inside another polyline, so that the
/// tour visits only the polylines that start a chain: open ones first (a
/// loop drawn inside an open path costs no chain of its own), then a loop
/// of each group of loops crossing one another. Leaves no point drawn and
/// the others' ends in the grid's lists.
fn mark_spliced(x: &mut Index<'_, '_>) {
    x.relink(true);
    for open in [true, false] {
        for f in 0..x.frags {
            let (from, _) = x.span(f);
            if x.is_loop(f) == open || x.dead(from) || x.is_dot(f) {
                continue;
            }
            splice_walk(x, f, from, true, |_| {});
        }
    }
    x.relink(false);
}

/// A fragment being drawn by [`Walk::emit_spliced`].
#[derive(Debug, Clone, Copy, Default)]
struct Splice {
    /// The fragment's points.
    from: usize,
    to: usize,
    /// The next point, and how many are left.
    at: usize,
    left: usize,
    /// Drawn from the last point to the first.
    back: bool,
}

impl Splice {
    /// Fragment `from..to` entered at point `entry`: a loop round from its
    /// entry back to it, an open fragment from the end it is entered at to
    /// the other.
    fn new(from: usize, to: usize, entry: usize, is_loop: bool) -> Self {
        let len = to.saturating_sub(from);
        if is_loop {
            let at = entry.clamp(from, to.saturating_sub(1).max(from));
            return Self { from, to, at, left: len + 1, back: false };
        }
        let back = entry + 1 == to && entry != from;
        Self { from, to, at: if back { entry } else { from }, left: len, back }
    }

    /// The next point to draw.
    fn next(&mut self) -> Option<usize> {
        self.left = self.left.checked_sub(1)?;
        let i = self.at;
        self.at = if self.back {
            i.saturating_sub(1)
        } else if i + 1 >= self.to {
            self.from
        } else {
            i + 1
        };
        Some(i)
    }
}

/// The chain being written: merges collinear runs, closes loops.
struct Out {
    open: bool,
    /// Index in `dst` of the chain's first point.
    first: usize,
    /// Merging: the last point kept for good, the last point written (it
    /// may yet be merged away), and the points merged away since `kept`.
    kept: Option<Packed>,
    last: Option<Packed>,
    dropped: [Packed; MERGE_SPAN],
    n_dropped: usize,
    tol2: f32,
}

impl Out {
    fn new(tolerance: f32, shift: u8) -> Self {
        let scale = f32::from(1u16 << shift);
        let t = tolerance.max(0.0) * scale;
        Self {
            open: false,
            first: 0,
            kept: None,
            last: None,
            dropped: [[0; 3]; MERGE_SPAN],
            n_dropped: 0,
            tol2: if t.is_finite() { t * t } else { 0.0 },
        }
    }

    /// Add a point to the chain (a dot is a chain of its own).
    fn point(&mut self, dst: &mut Geometry<'_>, q: Packed, dot: bool, stats: &mut ChainStats) {
        if dot {
            self.finish(dst, stats);
            if dst.push_raw(q, Kind::Dot) {
                stats.polylines += 1;
            }
            return;
        }
        if !self.open {
            self.open = true;
            self.first = dst.len();
            self.kept = None;
            self.n_dropped = 0;
            self.last = dst.push_raw(q, Kind::Move).then_some(q);
            stats.polylines += 1;
            return;
        }
        if self.last == Some(q) {
            return; // the joint of two fragments
        }
        // Merge: drop `last` if it, and every point dropped since the kept
        // one, lies within the tolerance of the chord kept -> q.
        if let (Some(kept), Some(last)) = (self.kept, self.last) {
            if self.tol2 > 0.0 && self.n_dropped < MERGE_SPAN {
                let near = |p: Packed| chord_dist2(kept, q, p) <= self.tol2;
                if near(last) && self.dropped.iter().take(self.n_dropped).all(|&p| near(p)) {
                    dst.pop();
                    if let Some(slot) = self.dropped.get_mut(self.n_dropped) {
                        *slot = last;
                    }
                    self.n_dropped += 1;
                    stats.merged += 1;
                    self.last = dst.push_raw(q, Kind::Line).then_some(q);
                    return;
                }
            }
            self.kept = Some(last);
        } else {
            self.kept = self.last;
        }
        self.n_dropped = 0;
        self.last = dst.push_raw(q, Kind::Line).then_some(q);
    }

    /// End the chain: a chain back at its first point is a closed loop.
    fn finish(&mut self, dst: &mut Geometry<'_>, stats: &mut ChainStats) {
        if !self.open {
            return;
        }
        self.open = false;
        let first = dst.get(self.first).map(|(q, _)| q);
        let n = dst.len().saturating_sub(self.first);
        if n == 1 {
            // All its points fell on one code: nothing to draw.
            dst.pop();
            stats.polylines = stats.polylines.saturating_sub(1);
            return;
        }
        if n >= 4 && first.is_some() && self.last == first {
            dst.pop();
            dst.close_at(self.first);
            stats.loops += 1;
        }
    }
}

/// Squared distance from `p` to the segment `a`-`b` (fixed point codes).
fn chord_dist2(a: Packed, b: Packed, p: Packed) -> f32 {
    let v = |q: Packed| [f32::from(q[0]), f32::from(q[1]), f32::from(q[2])];
    let (a, b, p) = (v(a), v(b), v(p));
    let ab = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let ap = [p[0] - a[0], p[1] - a[1], p[2] - a[2]];
    let len2 = ab[0] * ab[0] + ab[1] * ab[1] + ab[2] * ab[2];
    let t = if len2 > 0.0 {
        ((ap[0] * ab[0] + ap[1] * ab[1] + ap[2] * ab[2]) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let d = [ap[0] - t * ab[0], ap[1] - t * ab[1], ap[2] - t * ab[2]];
    d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::command::{Command, Point3};

    fn store(n: usize) -> Vec<u8> {
        vec![0; Geometry::bytes_for(n)]
    }

    /// Pieces on a small lattice, as the property tests draw them: shape 0
    /// a dot, 1 a three-point fragment (an elbow), else a segment.
    fn push_lattice(g: &mut Geometry<'_>, segs: &[(Packed, Packed, u8)]) {
        for &(a, b, shape) in segs {
            match shape {
                0 => {
                    g.push_raw(a, Kind::Dot);
                }
                1 => {
                    g.push_raw(a, Kind::Move);
                    g.push_raw([b[0], a[1], a[2]], Kind::Line);
                    g.push_raw(b, Kind::Line);
                }
                _ => {
                    g.push_raw(a, Kind::Move);
                    g.push_raw(b, Kind::Line);
                }
            }
        }
    }

    fn seg(g: &mut Geometry<'_>, a: [f32; 3], b: [f32; 3]) {
        g.push(Command::MoveTo(Point3::new(a[0], a[1], a[2]))).unwrap();
        g.push(Command::LineTo(Point3::new(b[0], b[1], b[2]))).unwrap();
    }

    /// 2-opt as it was before the lengths were kept: every jump measured
    /// afresh, every candidate's two new jumps computed. The oracle of
    /// `two_opt_keeps_lengths_without_changing_a_move`.
    fn two_opt_afresh(tour: &Tour, x: &mut Index<'_, '_>, window: usize, budget: &mut u64) {
        let n = tour.len;
        let length = |a: Packed, b: Packed| tour.metric.d(a, b);
        let (mut improved, mut passes) = (true, 0);
        while n >= 3 && improved && *budget > 0 && passes < 8 {
            passes += 1;
            improved = false;
            for i in 0..n - 1 {
                let out_i = tour.ends(x, i).1;
                let in_i1 = tour.ends(x, i + 1).0;
                let before = length(out_i, in_i1);
                for j in i + 2..n.min(i + 2 + window) {
                    *budget = budget.saturating_sub(1);
                    let out_j = tour.ends(x, j).1;
                    let after = if j + 1 < n { Some(tour.ends(x, j + 1).0) } else { None };
                    let old = before + after.map_or(0.0, |a| length(out_j, a));
                    let new = length(out_i, out_j) + after.map_or(0.0, |a| length(in_i1, a));
                    if new + 1e-3 < old {
                        tour.reverse(x, i + 1, j);
                        improved = true;
                        break;
                    }
                }
                if *budget == 0 {
                    break;
                }
            }
        }
    }

    /// Loop entries as they were chosen before the pruning: every vertex's
    /// two jumps measured. The oracle of
    /// `best_entries_prunes_without_changing_an_entry`.
    fn best_entries_afresh(tour: &Tour, x: &mut Index<'_, '_>, start: Packed) {
        let m = tour.metric;
        let mut prev: Option<Packed> = None;
        for k in 0..tour.len {
            let (end, _) = tour.get(&x.w, k);
            let f = x.frag_of(end);
            if x.is_loop(f) {
                let next = if k + 1 < tour.len { Some(tour.ends(x, k + 1).0) } else { None };
                let into = |v: Packed| prev.map_or_else(|| m.first_jump(start, v), |p| m.d(p, v));
                let cost = |v: Packed| into(v) + next.map_or(0.0, |n| m.d(v, n));
                let (from, to) = x.span(f);
                let mut best = (cost(x.point(end)), end);
                for i in from..to {
                    let c = cost(x.point(i));
                    if c < best.0 {
                        best = (c, i);
                    }
                }
                tour.set(&mut x.w, k, best.1, best.1);
            }
            prev = Some(tour.ends(x, k).1);
        }
    }

    /// The metrics the tour tests run with: space, and the screen of a
    /// view of the lattice they draw on.
    fn metrics() -> [Metric; 2] {
        let view = crate::view::View { spacing: [1.0; 3], ..crate::view::View::DEFAULT };
        let bounds = crate::view::Bounds::new(Point3::new(0.0, 0.0, 0.0), Point3::new(60.0, 60.0, 6.0));
        let t = ViewTransform::fit_sphere(&view, bounds).expect("a view");
        [Metric::Space, Metric::Screen { view: t, shift: 0, park: [0.0, 0.0] }]
    }

    #[test]
    fn dist2f_is_the_exact_square_rounded_once_at_the_extremes() {
        let far = [0u16, 65535, 37837, 37838, 46341, 46340, 1, 65534];
        for &a in &far {
            for &b in &far {
                for &c in &far {
                    let (p, q) = ([a, b, c], [0, 0, 0]);
                    assert_eq!(dist2f(p, q).to_bits(), (dist2(p, q) as f32).to_bits(), "{p:?}");
                    assert_eq!(dist2f(q, p).to_bits(), (dist2(p, q) as f32).to_bits(), "{p:?}");
                }
            }
        }
    }

    proptest::proptest! {
        #[test]
        fn dist2f_is_the_exact_square_rounded_once(a in proptest::array::uniform3(proptest::num::u16::ANY), b in proptest::array::uniform3(proptest::num::u16::ANY)) {
            proptest::prop_assert_eq!(dist2f(a, b).to_bits(), (dist2(a, b) as f32).to_bits());
        }
    }

    proptest::proptest! {
        #[test]
        fn frag_of_finds_the_fragment_of_every_point(
            lens in proptest::collection::vec(1usize..40, 1..120),
            long in proptest::option::of((0usize..120, 100usize..900)),
        ) {
            // Fragments of uneven lengths, one of them perhaps very long,
            // some taken (drawn: the flag shares the start's word).
            let mut lens = lens;
            if let Some((at, n)) = long {
                let at = at.min(lens.len() - 1);
                lens[at] = n;
            }
            let points: usize = lens.iter().sum();
            let mut p = store(points);
            let mut src = Geometry::new(&mut p);
            src.reset(0);
            let mut starts = Vec::new();
            for (f, &n) in lens.iter().enumerate() {
                starts.push(src.len());
                for j in 0..n {
                    let q = [f as u16, j as u16, 0];
                    src.push_raw(q, if j == 0 { if n == 1 { Kind::Dot } else { Kind::Move } } else { Kind::Line });
                }
            }
            let mut scratch = vec![0u8; 16 * points + 4096];
            let mut x = Index::build(Source::one(&src), &mut scratch, false, true).expect("room");
            for f in (0..lens.len()).step_by(3) {
                x.take(f);
            }
            for i in 0..points {
                let want = starts.partition_point(|&s| s <= i) - 1;
                proptest::prop_assert_eq!(x.frag_of(i), want, "point {}", i);
            }
        }
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(300))]
        #[test]
        fn two_opt_keeps_lengths_without_changing_a_move(
            frags in proptest::collection::vec(
                (proptest::collection::vec([0u16..400, 0u16..400, 0u16..40], 1..4), proptest::bool::ANY),
                3..60,
            ),
        ) {
            // Open polylines (some closed into loops, some single dots) in
            // the order given: a poor tour, so 2-opt has moves to make.
            let mut p = store(256);
            let mut src = Geometry::new(&mut p);
            src.reset(0);
            for (pts, closed) in &frags {
                let kind = match (pts.len(), closed) {
                    (1, _) => Kind::Dot,
                    (_, true) => Kind::Loop,
                    _ => Kind::Move,
                };
                for (n, &q) in pts.iter().enumerate() {
                    src.push_raw(q, if n == 0 { kind } else { Kind::Line });
                }
            }
            for metric in metrics() {
                let mut tours = Vec::new();
                for afresh in [false, true] {
                    let mut scratch = vec![0u8; 64 * 1024];
                    let mut x = Index::build(Source::one(&src), &mut scratch, true, false).expect("room");
                    let mut tour = Tour { base: x.tour_base(), len: 0, metric };
                    for f in 0..x.frags {
                        let end = x.span(f).0;
                        tour.push(&mut x, f, end);
                    }
                    let mut budget = 8 * WINDOW as u64 * tour.len as u64;
                    if afresh {
                        for k in 0..tour.len.saturating_sub(1) {
                            tour.measure(&mut x, k);
                        }
                        two_opt_afresh(&tour, &mut x, WINDOW, &mut budget)
                    } else {
                        tour.two_opt(&mut x, WINDOW, &mut budget);
                    }
                    tours.push((0..tour.len).map(|k| tour.get(&x.w, k)).collect::<Vec<_>>());
                }
                proptest::prop_assert_eq!(&tours[0], &tours[1]);
            }
        }
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(300))]
        #[test]
        fn best_entries_prunes_without_changing_an_entry(
            loops in proptest::collection::vec(
                (proptest::collection::vec([0u16..60, 0u16..60, 0u16..6], 3..14), 0usize..14),
                1..30,
            ),
            start in [0u16..60, 0u16..60, 0u16..6],
        ) {
            // Loops on a coarse lattice (ties between vertices are common),
            // each entered at some vertex, in the order given.
            let mut p = store(512);
            let mut src = Geometry::new(&mut p);
            src.reset(0);
            for (pts, _) in &loops {
                for (n, &q) in pts.iter().enumerate() {
                    src.push_raw(q, if n == 0 { Kind::Loop } else { Kind::Line });
                }
            }
            for metric in metrics() {
                let mut tours = Vec::new();
                for afresh in [false, true] {
                    let mut scratch = vec![0u8; 64 * 1024];
                    let mut x = Index::build(Source::one(&src), &mut scratch, true, false).expect("room");
                    let mut tour = Tour { base: x.tour_base(), len: 0, metric };
                    for (f, (_, at)) in loops.iter().enumerate() {
                        let (from, to) = x.span(f);
                        tour.push(&mut x, f, from + at % (to - from));
                    }
                    if afresh {
                        best_entries_afresh(&tour, &mut x, start)
                    } else {
                        tour.best_entries(&mut x, start)
                    }
                    tours.push((0..tour.len).map(|k| tour.get(&x.w, k)).collect::<Vec<_>>());
                }
                proptest::prop_assert_eq!(&tours[0], &tours[1]);
            }
        }
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(300))]
        #[test]
        fn stitching_in_hashed_buckets_or_u16_words_equals_stitching_in_cells(
            segs in proptest::collection::vec(([0u16..6, 0u16..6, 0u16..3], [0u16..6, 0u16..6, 0u16..3], 0u8..8), 1..120),
        ) {
            // Segments, dots and three-point fragments on a small lattice:
            // many ends meet, equal segments and dots on lines get culled.
            let mut p = store(512);
            let mut src = Geometry::new(&mut p);
            src.reset(0);
            push_lattice(&mut src, &segs);
            // Too little room for `u32` words and a list an end: `u16`s.
            let frags = (0..src.len()).filter(|&i| src.kind(i).is_some_and(Kind::starts)).count();
            // The starts, two links a fragment, a list for every other end.
            let tight = 2 * (frags + 2 * frags + frags);
            proptest::prop_assert!(matches!(
                Index::build(Source::one(&src), &mut vec![0u8; tight], false, true).map(|x| x.w),
                Some(Words::Narrow(_))
            ));
            let mut out = Vec::new();
            for (hashed, bytes) in [(true, 16 * 1024), (false, 16 * 1024), (true, tight)] {
                let mut p2 = store(512);
                let mut dst = Geometry::new(&mut p2);
                let mut scratch = vec![0u8; bytes];
                let st = chain_on(Source::one(&src), &mut dst, &mut scratch, [0; 3], 0.0, Pass::Stitch, hashed);
                proptest::prop_assert!(st.ordered);
                out.push((dst.commands().collect::<Vec<_>>(), st.polylines, st.culled_dots, st.duplicate_segments));
            }
            proptest::prop_assert_eq!(&out[0], &out[1]);
            proptest::prop_assert_eq!(&out[0], &out[2]);
        }
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(300))]
        #[test]
        fn open_paths_and_loops_cut_shuffled_and_turned_stitch_whole(
            shapes in proptest::collection::vec((2usize..9, proptest::bool::ANY), 1..12),
            cuts in proptest::collection::vec(1usize..4, 64),
            order in proptest::collection::vec(proptest::num::u32::ANY, 64),
        ) {
            // Open paths along x (at y = k, z = 5) and square loops (at
            // y = k, z in 0..=1), apart from each other: each must come out
            // as one polyline, whatever the fragments' order and direction.
            let mut frags: Vec<Vec<Packed>> = Vec::new();
            let mut cut = cuts.iter().cycle();
            for (k, &(n, closed)) in shapes.iter().enumerate() {
                let y = k as u16;
                let pts: Vec<Packed> = if closed {
                    vec![[0, y, 0], [1, y, 0], [1, y, 1], [0, y, 1], [0, y, 0]]
                } else {
                    (0..n as u16).map(|j| [j, y, 5]).collect()
                };
                let mut at = 0;
                while at + 1 < pts.len() {
                    let end = (at + cut.next().copied().unwrap_or(1)).min(pts.len() - 1);
                    frags.push(pts[at..=end].to_vec());
                    at = end;
                }
            }
            let mut keyed: Vec<(u32, Vec<Packed>)> =
                frags.into_iter().zip(order.iter().cycle()).map(|(f, &o)| (o, f)).collect();
            keyed.sort_by_key(|(o, _)| *o);
            let mut p = store(256);
            let mut src = Geometry::new(&mut p);
            src.reset(0);
            for (o, mut f) in keyed {
                if o % 2 == 1 {
                    f.reverse();
                }
                for (j, &q) in f.iter().enumerate() {
                    src.push_raw(q, if j == 0 { Kind::Move } else { Kind::Line });
                }
            }
            let mut p2 = store(256);
            let mut dst = Geometry::new(&mut p2);
            let mut scratch = vec![0u8; 16 * 1024];
            let st = chain(Source::one(&src), &mut dst, &mut scratch, [0; 3], 0.0, Pass::Stitch);
            let loops = shapes.iter().filter(|s| s.1).count() as u32;
            proptest::prop_assert_eq!((st.polylines, st.loops), (shapes.len() as u32, loops));
        }
    }

    /// The undirected segments (zero-length ones left out) and the dots a
    /// geometry draws, sorted.
    fn drawn(g: &Geometry<'_>) -> (Vec<[Packed; 2]>, Vec<Packed>) {
        let code = |p: Point3| [p.x as u16, p.y as u16, p.z as u16];
        let (mut segs, mut dots, mut pen) = (Vec::new(), Vec::new(), None);
        for c in g.commands() {
            match c {
                Command::MoveTo(p) => pen = Some(code(p)),
                Command::LineTo(p) => {
                    let q = code(p);
                    if let Some(a) = pen.filter(|&a| a != q) {
                        segs.push(if a < q { [a, q] } else { [q, a] });
                    }
                    pen = Some(q);
                }
                Command::Point(p) => {
                    dots.push(code(p));
                    pen = None;
                }
            }
        }
        segs.sort_unstable();
        dots.sort_unstable();
        (segs, dots)
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(300))]
        #[test]
        fn the_order_pass_draws_every_segment_and_dot_once(
            frags in proptest::collection::vec(
                (proptest::collection::vec([0u16..12, 0u16..12, 0u16..3], 1..7), 0u8..3),
                1..40,
            ),
            tight in proptest::bool::ANY,
        ) {
            // Dots, open polylines and closed loops on a small lattice, in
            // the order given: they touch, cross and repeat, so the tour
            // takes loops whose vertices other loops still list, and (with
            // a tight scratch: a coarse grid) searches crowded cells.
            let mut p = store(256);
            let mut src = Geometry::new(&mut p);
            src.reset(0);
            for (pts, kind) in &frags {
                let first = match (pts.len(), kind) {
                    (1, _) => Kind::Dot,
                    (2, _) | (_, 0) => Kind::Move,
                    _ => Kind::Loop,
                };
                for (n, &q) in pts.iter().enumerate() {
                    src.push_raw(q, if n == 0 { first } else { Kind::Line });
                }
            }
            let mut p2 = store(512);
            let mut dst = Geometry::new(&mut p2);
            let mut scratch = vec![0u8; if tight { 20 * src.len() + 32 } else { 64 * 1024 }];
            for metric in metrics() {
                let st = chain(Source::one(&src), &mut dst, &mut scratch, [0; 3], 0.0, Pass::Order(metric));
                proptest::prop_assert!(st.ordered);
                proptest::prop_assert_eq!(drawn(&dst), drawn(&src));
            }
        }
    }

    /// The tour's length by its metric: from the start, each jump.
    fn tour_length(tour: &Tour, x: &Index<'_, '_>, start: Packed) -> f32 {
        let m = tour.metric;
        let mut at: Option<Packed> = None;
        let mut sum = 0.0;
        for k in 0..tour.len {
            let (e, o) = tour.ends(x, k);
            sum += at.map_or_else(|| m.first_jump(start, e), |a| m.d(a, e));
            at = Some(o);
        }
        sum
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(200))]
        #[test]
        fn improving_the_tour_never_lengthens_it_and_keeps_every_step(
            frags in proptest::collection::vec(
                (proptest::collection::vec([0u16..60, 0u16..60, 0u16..6], 1..5), 0u8..3),
                8..60,
            ),
            start in [0u16..60, 0u16..60, 0u16..6],
        ) {
            // Dots, open polylines and loops scattered on a lattice, toured
            // in the order given: the neighbours' moves (and, in space, the
            // windowed ones) only shorten it, and every fragment stays once.
            let mut p = store(512);
            let mut src = Geometry::new(&mut p);
            src.reset(0);
            for (pts, kind) in &frags {
                let first = match (pts.len(), kind) {
                    (1, _) => Kind::Dot,
                    (2, _) | (_, 0) => Kind::Move,
                    _ => Kind::Loop,
                };
                for (n, &q) in pts.iter().enumerate() {
                    src.push_raw(q, if n == 0 { first } else { Kind::Line });
                }
            }
            for metric in metrics() {
                let mut scratch = vec![0u8; 64 * 1024];
                let mut x = Index::build(Source::one(&src), &mut scratch, true, false).expect("room");
                x.relink(false);
                let mut tour = Tour { base: x.tour_base(), len: 0, metric };
                for f in 0..x.frags {
                    let end = x.span(f).0;
                    tour.push(&mut x, f, end);
                }
                for k in 0..tour.len - 1 {
                    tour.measure(&mut x, k);
                }
                if matches!(metric, Metric::Screen { .. }) {
                    proptest::prop_assert!(Near::build(&mut x, &tour).is_some(), "no neighbours");
                }
                let before = tour_length(&tour, &x, start);
                tour.improve(&mut x, start);
                let after = tour_length(&tour, &x, start);
                proptest::prop_assert!(after <= before * 1.000_01 + 1e-3, "{after} > {before}");
                // Each kind of move alone only shortens.
                if let Some(near) = Near::build(&mut x, &tour) {
                    let mut budget = SEARCH_BUDGET;
                    tour.or_opt_near(&mut x, &near, &mut budget);
                    let l1 = tour_length(&tour, &x, start);
                    proptest::prop_assert!(l1 <= after * 1.000_01 + 1e-3, "or-opt: {l1} > {after}");
                    tour.two_opt_near(&mut x, &near, &mut budget);
                    let l2 = tour_length(&tour, &x, start);
                    proptest::prop_assert!(l2 <= l1 * 1.000_01 + 1e-3, "2-opt: {l2} > {l1}");
                }
                let after = tour_length(&tour, &x, start);
                // From a good tour too: a move is made only where it
                // shortens.
                tour.improve(&mut x, start);
                let again = tour_length(&tour, &x, start);
                proptest::prop_assert!(again <= after * 1.000_01 + 1e-3, "{again} > {after}");
                let mut seen: Vec<usize> = (0..tour.len).map(|k| x.frag_of(tour.get(&x.w, k).0)).collect();
                seen.sort_unstable();
                proptest::prop_assert_eq!(seen, (0..x.frags).collect::<Vec<_>>());
            }
        }
    }

    #[test]
    fn loops_that_cross_are_drawn_in_one_polyline() {
        // Square A in z = 0 and square B in x = 2 share two vertices (as
        // the slices of a chicken-wire surface do); C stands apart.
        let a = [[0, 0, 0], [2, 0, 0], [4, 0, 0], [4, 4, 0], [2, 4, 0], [0, 4, 0]];
        let b = [[2, 0, 0], [2, 0, 4], [2, 4, 4], [2, 4, 0]];
        let c = [[9, 9, 9], [11, 9, 9], [11, 11, 9]];
        let mut p = store(64);
        let mut src = Geometry::new(&mut p);
        src.reset(0);
        for l in [&a[..], &b[..], &c[..]] {
            for (n, &q) in l.iter().enumerate() {
                src.push_raw(q, if n == 0 { Kind::Loop } else { Kind::Line });
            }
        }
        for metric in metrics() {
            let mut p2 = store(64);
            let mut dst = Geometry::new(&mut p2);
            let mut scratch = vec![0u8; 4096];
            let st = chain(Source::one(&src), &mut dst, &mut scratch, [0; 3], 0.0, Pass::Order(metric));
            assert_eq!(drawn(&dst), drawn(&src));
            assert_eq!((st.polylines, st.spliced), (2, 1), "{st:?}");
            // One jump: from A and B to C (and none from the start, which
            // chain() does not count).
            assert!(st.travel > 0.0);
        }
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(300))]
        #[test]
        fn pieces_in_two_stores_chain_as_in_one(
            segs in proptest::collection::vec(([0u16..6, 0u16..6, 0u16..3], [0u16..6, 0u16..6, 0u16..3], 0u8..8), 1..120),
            cut in 0usize..400,
        ) {
            let mut p = store(512);
            let mut one = Geometry::new(&mut p);
            one.reset(3);
            push_lattice(&mut one, &segs);
            // The same points, the first `cut` in one store and the rest in
            // another (a polyline may straddle them).
            let cut = cut.min(one.len());
            let (mut p1, mut p2) = (store(512), store(512));
            let (mut head, mut tail) = (Geometry::new(&mut p1), Geometry::new(&mut p2));
            head.reset(3);
            tail.reset(3);
            for i in 0..one.len() {
                let (q, k) = one.get(i).unwrap();
                if i < cut { head.push_raw(q, k) } else { tail.push_raw(q, k) };
            }
            for pass in [Pass::Stitch, Pass::Order(Metric::Space)] {
                let mut out = Vec::new();
                for src in [Source::one(&one), Source::two(&head, &tail)] {
                    let mut q = store(512);
                    let mut dst = Geometry::new(&mut q);
                    let mut scratch = vec![0u8; 16 * 1024];
                    let st = chain(src, &mut dst, &mut scratch, [0; 3], 0.0, pass);
                    out.push((dst.commands().collect::<Vec<_>>(), st));
                }
                proptest::prop_assert_eq!(&out[0], &out[1]);
            }
        }
    }

    #[test]
    fn a_square_of_four_fragments_in_any_order_becomes_one_closed_loop() {
        let mut p = store(16);
        let mut src = Geometry::new(&mut p);
        src.reset(8);
        // Shuffled and with two fragments backwards.
        seg(&mut src, [1.0, 0.0, 0.0], [1.0, 1.0, 0.0]);
        seg(&mut src, [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]);
        seg(&mut src, [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]);
        seg(&mut src, [0.0, 0.0, 0.0], [1.0, 0.0, 0.0]);
        let mut p2 = store(16);
        let mut dst = Geometry::new(&mut p2);
        let mut scratch = [0u8; 256];
        let st = chain(Source::one(&src), &mut dst, &mut scratch, [0; 3], 0.0, Pass::Order(Metric::Space));
        assert!(st.ordered);
        assert_eq!((st.fragments, st.polylines, st.loops, st.points_out), (4, 1, 1, 4));
        assert_eq!(st.travel, 0.0);
        let cmds: Vec<_> = dst.commands().collect();
        assert_eq!(cmds.len(), 5);
        assert_eq!(cmds[0], Command::MoveTo(Point3::new(0.0, 0.0, 0.0)));
        assert_eq!(cmds[4], Command::LineTo(Point3::new(0.0, 0.0, 0.0)));
    }

    #[test]
    fn a_crossing_is_stitched_straight_through_in_any_order() {
        // Four arms from (2, 2, 0); every order and every direction of the
        // pieces must come out as the two straight lines through it.
        let arms = [[0.0, 2.0, 0.0], [4.0, 2.0, 0.0], [2.0, 0.0, 0.0], [2.0, 4.0, 0.0]];
        let c = [2.0, 2.0, 0.0];
        let mut orders: Vec<Vec<usize>> = vec![vec![]];
        for _ in 0..4 {
            let mut next = Vec::new();
            for o in &orders {
                for a in (0..4).filter(|a| !o.contains(a)) {
                    next.push([o.clone(), vec![a]].concat());
                }
            }
            orders = next;
        }
        assert_eq!(orders.len(), 24);
        for order in &orders {
            for flips in 0..16 {
                let mut p = store(16);
                let mut src = Geometry::new(&mut p);
                src.reset(8);
                for (k, &a) in order.iter().enumerate() {
                    if flips >> k & 1 == 0 { seg(&mut src, arms[a], c) } else { seg(&mut src, c, arms[a]) }
                }
                let mut p2 = store(16);
                let mut dst = Geometry::new(&mut p2);
                let mut scratch = [0u8; 512];
                let st = chain(Source::one(&src), &mut dst, &mut scratch, [0; 3], 0.0, Pass::Stitch);
                assert_eq!((st.polylines, st.points_out), (2, 6), "{order:?} {flips}");
                let cmds: Vec<_> = dst.commands().collect();
                for line in cmds.chunks(3) {
                    let [Command::MoveTo(a), Command::LineTo(m), Command::LineTo(b)] = line else {
                        panic!("{order:?} {flips}: {cmds:?}")
                    };
                    assert_eq!(*m, Point3::new(2.0, 2.0, 0.0), "{order:?} {flips}");
                    assert!(
                        a.x + b.x == 4.0 && a.y + b.y == 4.0,
                        "bent at the crossing: {order:?} {flips}: {cmds:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn collinear_points_merge_within_tolerance_only() {
        let mut p = store(16);
        let mut src = Geometry::new(&mut p);
        src.reset(8);
        seg(&mut src, [0.0, 0.0, 0.0], [1.0, 0.001, 0.0]);
        seg(&mut src, [1.0, 0.001, 0.0], [2.0, 0.0, 0.0]);
        seg(&mut src, [2.0, 0.0, 0.0], [2.0, 1.0, 0.0]);
        let mut p2 = store(16);
        let mut dst = Geometry::new(&mut p2);
        let mut scratch = [0u8; 256];
        let st = chain(Source::one(&src), &mut dst, &mut scratch, [0; 3], 0.01, Pass::Order(Metric::Space));
        assert_eq!((st.polylines, st.merged, st.points_out), (1, 1, 3));
        let st = chain(Source::one(&src), &mut dst, &mut scratch, [0; 3], 0.0, Pass::Order(Metric::Space));
        assert_eq!((st.merged, st.points_out), (0, 4));
    }

    #[test]
    fn too_little_scratch_copies_in_order() {
        let mut p = store(16);
        let mut src = Geometry::new(&mut p);
        src.reset(8);
        seg(&mut src, [5.0, 0.0, 0.0], [6.0, 0.0, 0.0]);
        seg(&mut src, [0.0, 0.0, 0.0], [1.0, 0.0, 0.0]);
        let mut p2 = store(16);
        let mut dst = Geometry::new(&mut p2);
        let st = chain(Source::one(&src), &mut dst, &mut [0u8; 8], [0; 3], 0.0, Pass::Order(Metric::Space));
        assert!(!st.ordered);
        let a: Vec<_> = src.commands().collect();
        let b: Vec<_> = dst.commands().collect();
        assert_eq!(a, b);
    }
}
