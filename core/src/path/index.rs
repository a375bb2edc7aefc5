//! The index of a surface's fragments and of their ends: the ends in
//! linked lists of a grid of cells (searches around a point) or of hashed
//! buckets (lookups at a point), in words of caller scratch.

use super::store::{Kind, Packed, Source, pack};
use super::{ChainStats, Poll};
use crate::fastmath::sqrt;

/// No entry.
pub(super) const NONE: u32 = u32::MAX;
/// The top bit of a fragment's start: drawn already (the top bit of a
/// `u16` word in [`Words::Narrow`]).
pub(super) const DRAWN: u32 = 1 << 31;
/// Rings of cells searched around the beam.
pub(super) const RINGS: i32 = 8;

/// The index's words over a byte buffer (the scratch is lent as bytes):
/// `u32`s, or, where those would not fit, `u16`s ([`Words::narrow`]: the
/// words are point, end, fragment or tour indices or [`NONE`], so either
/// pass may narrow them when there are fewer than [`NARROW_LIMIT`] of
/// each). Besides indices, the order pass keeps bits (a point's drawn
/// bit, [`Words::bits`] a word) and `f32`s (the tour's jumps,
/// [`Words::get32`]: one wide word or two narrow ones). One bounds check
/// and one load a word.
pub(super) enum Words<'s> {
    Wide(&'s mut [[u8; 4]]),
    Narrow(&'s mut [[u8; 2]]),
}

/// Points (and ends) below which a pass may keep its index in `u16`s: the
/// top bit is [`DRAWN`], all ones [`NONE`].
pub(super) const NARROW_LIMIT: usize = 0x7FFF;

/// Which words [`Index::build`] takes: `u16`s where they fit and the
/// scratch is short for `u32`s (what the passes use), or (for the tests
/// that both order alike) one or the other.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(not(test), expect(dead_code, reason = "only the tests force a width"))]
pub(super) enum Width {
    Fit,
    Wide,
    Narrow,
}

/// Bytes of scratch the stitch pass wants for `frags` fragments of
/// `points` points in all: its index in `u16` words where those fit (fewer
/// than [`NARROW_LIMIT`] points and ends), a start and two end links a
/// fragment and a list head for every four ends, so that a lookup walks a
/// few ends. With less it still stitches (fewer lists, longer walks) down
/// to three words a fragment, and below that copies the pieces unordered.
pub(crate) const fn stitch_reserve(frags: usize, points: usize) -> usize {
    stitch_word(frags, points) * (3 * frags + frags / 2 + 1)
}

/// The least scratch worth giving the stitch pass of `frags` fragments of
/// `points` points when [`stitch_reserve`] is not to be had: its starts
/// and two end links a fragment, and a list for every sixteen ends, so
/// that a lookup walks some four times the ends it walks in the reserve.
/// In any room from three words a fragment up (one list for all the ends)
/// it makes the same polylines as in the reserve or more: its lists hold
/// the ends of a point in the same order however many lists there are.
pub(crate) const fn stitch_least(frags: usize, points: usize) -> usize {
    stitch_word(frags, points) * (3 * frags + frags / 8 + 1)
}

/// The stitch pass's word: `u16` where its points and ends fit.
const fn stitch_word(frags: usize, points: usize) -> usize {
    if points < NARROW_LIMIT && 2 * frags < NARROW_LIMIT { 2 } else { 4 }
}

/// Bytes of scratch the order pass wants for `frags` polylines of
/// `points` points in all: its index in `u16` words where those fit (fewer
/// than [`NARROW_LIMIT`] points), a start and a tour step a polyline (four
/// words narrow, three wide: an `f32` jump is two `u16`s), a link and a
/// drawn bit a point, and a cell of the grid for every four points. With
/// less it still orders (a coarser grid: the nearest ends are searched
/// among more) down to one cell, and below that copies the polylines
/// unordered.
#[cfg_attr(not(test), expect(dead_code, reason = "for the engine's fixed tail, the step after this"))]
pub(crate) const fn order_reserve(frags: usize, points: usize) -> usize {
    let (word, bits, step) = if points < NARROW_LIMIT { (2, 16, 4) } else { (4, 32, 3) };
    word * ((1 + step) * frags + points + points.div_ceil(bits) + points / 4 + 1)
}

impl<'s> Words<'s> {
    pub(super) fn wide(bytes: &'s mut [u8]) -> Self {
        Self::Wide(bytes.as_chunks_mut::<4>().0)
    }

    /// Half the size a word: only for values below [`NARROW_LIMIT`], with
    /// or without [`DRAWN`], and [`NONE`].
    pub(super) fn narrow(bytes: &'s mut [u8]) -> Self {
        Self::Narrow(bytes.as_chunks_mut::<2>().0)
    }

    pub(super) fn len(&self) -> usize {
        match self {
            Self::Wide(w) => w.len(),
            Self::Narrow(w) => w.len(),
        }
    }

    /// Bits a word: 32 or 16.
    #[inline]
    pub(super) fn bits(&self) -> usize {
        match self {
            Self::Wide(_) => 32,
            Self::Narrow(_) => 16,
        }
    }

    /// Words a step of the order pass's tour takes (`order::Tour`): its
    /// entry, its exit and the `f32` jump to the next ([`Words::get32`]).
    #[inline]
    pub(super) fn tour_step(&self) -> usize {
        match self {
            Self::Wide(_) => 3,
            Self::Narrow(_) => 4,
        }
    }

    /// Bit `b` of the bits kept from word `at` on (a word's own
    /// [`Words::bits`], its raw value: no [`NONE`] or [`DRAWN`]).
    #[inline]
    pub(super) fn bit(&self, at: usize, b: usize) -> bool {
        match self {
            Self::Wide(w) => w.get(at + b / 32).is_some_and(|v| u32::from_le_bytes(*v) >> (b % 32) & 1 != 0),
            Self::Narrow(w) => {
                w.get(at + b / 16).is_some_and(|v| u16::from_le_bytes(*v) >> (b % 16) & 1 != 0)
            }
        }
    }

    /// Set bits `from..to` of the bits kept from word `at` on, a word at
    /// a time.
    pub(super) fn set_bits(&mut self, at: usize, from: usize, to: usize) {
        let bits = self.bits();
        let mut s = from;
        while s < to {
            let bit = s % bits;
            let n = (bits - bit).min(to - s);
            let mask = if n == 32 { u32::MAX } else { ((1u32 << n) - 1) << bit };
            let i = at + s / bits;
            match self {
                Self::Wide(w) => {
                    if let Some(b) = w.get_mut(i) {
                        *b = (u32::from_le_bytes(*b) | mask).to_le_bytes();
                    }
                }
                Self::Narrow(w) => {
                    if let Some(b) = w.get_mut(i) {
                        *b = (u16::from_le_bytes(*b) | mask as u16).to_le_bytes();
                    }
                }
            }
            s += n;
        }
    }

    /// Clear `n` bits from word `at` on (whole words).
    pub(super) fn clear_bits(&mut self, at: usize, n: usize) {
        let words = n.div_ceil(self.bits());
        match self {
            Self::Wide(w) => w.iter_mut().skip(at).take(words).for_each(|b| *b = [0; 4]),
            Self::Narrow(w) => w.iter_mut().skip(at).take(words).for_each(|b| *b = [0; 2]),
        }
    }

    /// Words that `n` bits take.
    #[inline]
    pub(super) fn words_for_bits(&self, n: usize) -> usize {
        n.div_ceil(self.bits())
    }

    /// The 32 bits at word `at`: that word, or it (low half) and the next.
    #[inline]
    pub(super) fn get32(&self, at: usize) -> u32 {
        match self {
            Self::Wide(w) => w.get(at).map_or(0, |b| u32::from_le_bytes(*b)),
            Self::Narrow(w) => {
                let half = |i: usize| w.get(i).map_or(0, |b| u32::from(u16::from_le_bytes(*b)));
                half(at) | half(at + 1) << 16
            }
        }
    }

    /// Set the 32 bits at word `at` ([`Words::get32`]).
    #[inline]
    pub(super) fn set32(&mut self, at: usize, v: u32) {
        match self {
            Self::Wide(w) => {
                if let Some(b) = w.get_mut(at) {
                    *b = v.to_le_bytes();
                }
            }
            Self::Narrow(w) => {
                for (i, half) in [(at, v as u16), (at + 1, (v >> 16) as u16)] {
                    if let Some(b) = w.get_mut(i) {
                        *b = half.to_le_bytes();
                    }
                }
            }
        }
    }

    #[inline]
    pub(super) fn get(&self, i: usize) -> u32 {
        match self {
            Self::Wide(w) => w.get(i).map_or(NONE, |b| u32::from_le_bytes(*b)),
            Self::Narrow(w) => match w.get(i).map(|b| u16::from_le_bytes(*b)) {
                None | Some(0xFFFF) => NONE,
                Some(v) => u32::from(v & 0x7FFF) | u32::from(v & 0x8000) << 16,
            },
        }
    }

    #[inline]
    pub(super) fn set(&mut self, i: usize, v: u32) {
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

pub(super) fn dist2(a: Packed, b: Packed) -> u64 {
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
pub(super) fn dist2f(a: Packed, b: Packed) -> f32 {
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
pub(super) fn length(a: Packed, b: Packed) -> f32 {
    sqrt(dist2f(a, b))
}

/// 64 well-mixed bits of a point (for [`Index::odd`]).
pub(super) fn point_hash([x, y, z]: Packed) -> u64 {
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
pub(super) fn cell_coords(q: Packed, n: [u32; 3], bits: u32) -> [u32; 3] {
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
pub(super) struct Index<'s, 'g> {
    pub(super) src: Source<'g>,
    pub(super) w: Words<'s>,
    /// Cells along x, y, z; a cell is `2^bits` codes on a side.
    pub(super) n: [u32; 3],
    pub(super) bits: u32,
    /// Word offsets: fragment starts (`frags` of them), cell heads, one
    /// link a slot, and (the order pass, after its tour) a bit a point for
    /// the drawn ones.
    pub(super) heads: usize,
    pub(super) links: usize,
    pub(super) dead: usize,
    pub(super) frags: usize,
    /// Closed loops may be entered at any vertex.
    pub(super) any_vertex: bool,
    /// The stitch pass: the hashes of the points of the ends not drawn
    /// ([`point_hash`], a dot's counting as nothing), xor-ed. They cancel
    /// in pairs, so this is zero when every point has an even number of
    /// ends (no open path is left to start), and all but surely not
    /// otherwise (were it zero then, the open paths left would be walked
    /// among the closed loops: drawn all the same, in more pieces). `None`
    /// once the open paths are walked: no longer kept up.
    pub(super) odd: Option<u64>,
    /// The stitch pass only ever looks up ends at exact points: its lists
    /// are buckets of a hash of the point (this many), not cells of space,
    /// so that the ends of a surface, a sheet through few of its box's
    /// cells, spread over all of them. 0: the grid of cells (the order
    /// pass, which searches around a point).
    pub(super) buckets: usize,
    /// Called as the work goes on ([`super::chain`]).
    pub(super) poll: Poll<'s>,
}

impl<'s, 'g> Index<'s, 'g> {
    pub(super) fn build(
        src: Source<'g>,
        scratch: &'s mut [u8],
        any_vertex: bool,
        hashed: bool,
        width: Width,
        poll: Poll<'s>,
    ) -> Option<Self> {
        let points = src.len();
        let mut frags = 0usize;
        let mut top = [0u16; 3];
        src.for_each_kind(|i, kind| {
            frags += usize::from(kind.starts() || i == 0);
            if i.is_multiple_of(64) {
                poll.tick(16);
            }
        });
        if !hashed {
            // The grid's extent (the stitch pass's buckets need none).
            for i in 0..points {
                for (t, v) in top.iter_mut().zip(src.point_at(i)?) {
                    *t = (*t).max(v);
                }
                poll.tick(1);
            }
        }
        // Words of `u32`, unless `u16`s fit and the scratch is short: the
        // stitch pass's index then has less than a word of lists an end;
        // the order pass's no room for a single cell beside its starts,
        // links, tour (three words a step) and drawn bits. (Its picture
        // depends on its grid, the nearest end searched within rings of
        // cells, ties in the lists' order: so one that it orders in `u32`s
        // stays the same. In `u16`s the grid is as fine as that room
        // allows.)
        let ends = if any_vertex { points } else { 2 * frags };
        // A link a slot: a point, or an end.
        let slots = ends;
        let fixed = frags + slots;
        let wide_need = if any_vertex { fixed + 3 * frags + points.div_ceil(32) + 1 } else { fixed + ends };
        let fits = points < NARROW_LIMIT && slots < NARROW_LIMIT;
        let narrow = match width {
            Width::Fit => fits && scratch.len() / 4 < wide_need,
            Width::Wide => false,
            Width::Narrow if fits => true,
            Width::Narrow => return None,
        };
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
        let tour = if any_vertex { w.tour_step() * frags } else { 0 };
        // The order pass's drawn points, a bit each in words after the
        // tour.
        let dead_words = if any_vertex { w.words_for_bits(points) } else { 0 };
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
        // The order pass keeps its tour ([`Words::tour_step`] a fragment)
        // after the links.
        if links + slots + tour + dead_words > words {
            return None;
        }
        let dead = links + slots + tour;
        w.clear_bits(dead, if any_vertex { points } else { 0 });
        let mut k = 0;
        src.for_each_kind(|i, kind| {
            if kind.starts() || i == 0 {
                w.set(k, i as u32);
                k += 1;
            }
            if i.is_multiple_of(64) {
                poll.tick(16);
            }
        });
        for c in 0..cells {
            w.set(heads + c, NONE);
            if c.is_multiple_of(256) {
                poll.tick(16);
            }
        }
        let mut index =
            Self { src, w, n, bits, heads, links, dead, frags, any_vertex, buckets, odd: Some(0), poll };
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
                index.poll.tick(2);
            }
            index.odd = Some(odd);
        }
        Some(index)
    }

    /// Where the order pass keeps its tour: after the links.
    pub(super) fn tour_base(&self) -> usize {
        self.links + if self.any_vertex { self.src.len() } else { 2 * self.frags }
    }

    /// Call `act` with each slot of fragment `f`'s ends.
    #[inline]
    pub(super) fn each_slot(&mut self, f: usize, mut act: impl FnMut(&mut Self, usize)) {
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
    pub(super) fn end_point(&self, s: usize) -> usize {
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
    pub(super) fn end_frag(&self, s: usize) -> usize {
        if self.any_vertex { self.frag_of(s) } else { s / 2 }
    }

    pub(super) fn cells(&self) -> usize {
        if self.buckets > 0 { self.buckets } else { self.n.iter().map(|&n| n as usize).product() }
    }

    /// The list `q`'s ends are in: its bucket, or its cell.
    #[inline]
    pub(super) fn cell(&self, q: Packed) -> usize {
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
    pub(super) fn point(&self, i: usize) -> Packed {
        self.src.point_at(i).unwrap_or([0; 3])
    }

    #[inline]
    pub(super) fn kind(&self, i: usize) -> Kind {
        self.src.kind(i).unwrap_or(Kind::Line)
    }

    pub(super) fn drawn(&self, f: usize) -> bool {
        self.w.get(f) & DRAWN != 0
    }

    /// The point range of fragment `f`.
    pub(super) fn span(&self, f: usize) -> (usize, usize) {
        let from = (self.w.get(f) & !DRAWN) as usize;
        let to = if f + 1 < self.frags { (self.w.get(f + 1) & !DRAWN) as usize } else { self.src.len() };
        (from, to.max(from + 1).min(self.src.len().max(from + 1)))
    }

    /// The fragment holding point `i`: the last whose first point is at
    /// or before it (the first fragment for none). A binary search whose
    /// step is a select, not a branch: the order pass asks it some
    /// quarter of a million times for a 124,000-point surface, at random.
    pub(super) fn frag_of(&self, i: usize) -> usize {
        let (mut base, mut size) = (0, self.frags);
        while size > 1 {
            let half = size / 2;
            let mid = base + half;
            base = if (self.w.get(mid) & !DRAWN) as usize <= i { mid } else { base };
            size -= half;
        }
        base
    }

    pub(super) fn is_loop(&self, f: usize) -> bool {
        self.kind(self.span(f).0) == Kind::Loop
    }

    pub(super) fn is_dot(&self, f: usize) -> bool {
        self.kind(self.span(f).0) == Kind::Dot
    }

    /// The point range of fragment `f`, and whether every point of it is an
    /// end (a closed loop in the order pass); else its first and last are.
    #[inline]
    pub(super) fn ends(&self, f: usize) -> (usize, usize, bool) {
        let (from, to) = self.span(f);
        (from, to, self.any_vertex && self.kind(from) == Kind::Loop)
    }

    pub(super) fn link(&mut self, s: usize) {
        self.link_to(s, self.point(self.end_point(s)));
    }

    /// Put slot `s`, whose point is `q`, at the head of `q`'s list.
    #[inline]
    pub(super) fn link_to(&mut self, s: usize, q: Packed) {
        let c = self.cell(q);
        let head = self.w.get(self.heads + c);
        self.w.set(self.links + s, head);
        self.w.set(self.heads + c, s as u32);
    }

    /// The order pass: whether point `s`'s fragment is drawn.
    #[inline]
    pub(super) fn dead(&self, s: usize) -> bool {
        self.w.bit(self.dead, s)
    }

    /// The order pass: the first word past the drawn bits.
    pub(super) fn past_dead(&self) -> usize {
        self.dead + self.w.words_for_bits(self.src.len())
    }

    /// The order pass: take the drawn ends out of cell `c`'s list (each is
    /// passed over once, not looked for when its loop is drawn).
    pub(super) fn prune(&mut self, c: usize) {
        let mut prev = NONE;
        let mut at = self.w.get(self.heads + c);
        while at != NONE {
            self.poll.tick(1);
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
    pub(super) fn kill(&mut self, from: usize, to: usize) {
        self.w.set_bits(self.dead, from, to);
    }

    /// The order pass: no point drawn, and the ends (every vertex of a
    /// loop) in lists: of the fragments not marked drawn, in the grid's
    /// cells, for the tour's searches around a point; or (`hashed`) of the
    /// loops, in buckets of a hash of the point, for the splices' exact
    /// lookups ([`Index::loop_at`]: a sheet crowds the cells it passes
    /// through, and a lookup at every point drawn walked them).
    pub(super) fn relink(&mut self, hashed: bool) {
        // The buckets' heads: in the scratch past the drawn bits where that
        // holds more than the grid's (up to two a point: short lists), else
        // the grid's heads serve as as many.
        let grid: usize = self.n.iter().map(|&n| n as usize).product();
        let free = self.past_dead();
        let spare = self.w.len().saturating_sub(free);
        (self.heads, self.buckets) = match hashed {
            true if spare > grid => (free, spare.min(2 * self.src.len())),
            true => (self.frags, grid),
            false => (self.frags, 0),
        };
        for c in 0..self.cells() {
            self.w.set(self.heads + c, NONE);
            if c.is_multiple_of(64) {
                self.poll.tick(4);
            }
        }
        self.w.clear_bits(self.dead, self.src.len());
        for f in 0..self.frags {
            // The splices look up loops alone; the tour's searches the
            // polylines not marked drawn ([`mark_spliced`]).
            if if hashed { self.is_loop(f) } else { !self.drawn(f) } {
                self.each_slot(f, |x, s| x.link(s));
            }
            let (from, to) = self.span(f);
            self.poll.tick(2 + (to - from) as u32);
        }
    }

    /// The order pass: whether fragment `f`'s points are drawn.
    pub(super) fn emitted(&self, f: usize) -> bool {
        self.dead(self.span(f).0)
    }

    /// The order pass, its lists hashed ([`Index::relink`]): a vertex
    /// exactly at `q` of a closed loop not drawn yet.
    pub(super) fn loop_at(&self, q: Packed) -> Option<usize> {
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
    pub(super) fn take(&mut self, f: usize) {
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
    pub(super) fn ends_hash(&self, f: usize) -> u64 {
        if self.any_vertex || self.is_dot(f) {
            return 0;
        }
        let (from, to) = self.span(f);
        let h = point_hash(self.point(from));
        if to - from > 1 { h ^ point_hash(self.point(to - 1)) } else { h }
    }

    /// The slots of the ends in cell `c` (any point) of fragments not yet
    /// drawn, by calling `visit` until it says stop.
    pub(super) fn each_end(&self, c: usize, mut visit: impl FnMut(usize) -> bool) {
        let mut at = self.w.get(self.heads + c);
        while at != NONE {
            self.poll.tick(1);
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
    pub(super) fn degree(&self, q: Packed) -> usize {
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
    pub(super) fn straightest(&self, cur: Packed, prev: Option<Packed>) -> Option<(usize, usize)> {
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
    pub(super) fn nearest(&mut self, cur: Packed) -> Option<usize> {
        let [cx, cy, cz] = cell_coords(cur, self.n, self.bits).map(|c| c as i32);
        let [nx, ny, nz] = self.n.map(|n| n as i32);
        let side = 1u64 << self.bits;
        let mut best: Option<(u64, usize)> = None;
        // The ends of one cell (its drawn ones taken out of the list
        // first): whether one lies at `cur` (then it is the nearest).
        let visit = |x: &mut Self, cell: i32, best: &mut Option<(u64, usize)>| {
            x.poll.tick(1);
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
    pub(super) fn first_from(&self, scan: &mut usize) -> Option<usize> {
        while *scan < self.cells() {
            self.poll.tick(1);
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
    pub(super) fn cull(&mut self, stats: &mut ChainStats) {
        for f in 0..self.frags {
            self.poll.tick(4);
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
