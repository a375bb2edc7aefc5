//! The display list: polylines in DAC units, and the passes that make them
//! cheap to draw on a vector display.
//!
//! Contour fragments arrive one subgrid at a time (two or three points
//! each). [`DisplayStore::optimize`] turns them into what a beam should
//! trace:
//!
//! 1. **Cull** (the paper's section 4.1): identical points are one vertex;
//!    a segment drawn twice (an equal-valued edge on a border shared by two
//!    subgrids, or the same crossing reached from two slices) is kept once;
//!    a point already covered by a line, or drawn twice, is dropped.
//! 2. **Stitch**: the remaining segments form a graph; walks through it
//!    give maximal polylines (closed loops closed), preferring at each
//!    vertex the straightest continuation. Crossings on shared edges are
//!    bit-identical (see [`crate::pen`]), so fragments join exactly.
//! 3. **Merge**: runs of nearly collinear points (every dropped point within
//!    `tolerance` DAC units of the kept chord) become one segment.
//!
//! [`DisplayStore::order`] then orders the polylines to minimise blanked
//! travel around the refresh loop, the paper's "vector ordering problem"
//! (open polylines may be drawn either way, closed loops entered at any
//! vertex): nearest neighbour from the park position on a uniform grid,
//! then 2-opt and or-opt among near neighbours, then an iterated local
//! search.
//!
//! Everything runs in fixed memory: the list's own storage plus a
//! [`Scratch`] of the same capacity, `O(n log n)` time for culling and
//! stitching (sorting, in place).

use crate::command::Command;
use crate::screen::ScreenPoint;
use core::cell::Cell;

/// Vertex flag: a polyline starts here.
const START: u8 = 1;
/// Vertex flag (on a polyline's first vertex): the polyline is a single dot.
const DOT: u8 = 2;
/// Vertex flag (on a polyline's first vertex): the polyline is a closed
/// loop; its last vertex joins back to its first (not stored twice).
const CLOSED: u8 = 4;

/// Storage of a display list: `points` and per-point `flags`, of equal
/// capacity (the shorter one counts).
///
/// [`DisplayList`] is the fixed-capacity array form for the MCU; on the
/// host any `AsMut<[_]>` storage (e.g. `Vec`s) works the same way.
#[derive(Debug, Clone, PartialEq)]
pub struct DisplayStore<P, F> {
    points: P,
    flags: F,
    len: usize,
    dropped: u64,
    skipped: u64,
    open: bool,
}

/// A display list with room for `N` points, in two arrays (9 bytes a point).
///
/// `push` hands the command back when the list is full and counts it in
/// [`DisplayStore::dropped`]; nothing is allocated, ever.
pub type DisplayList<const N: usize> = DisplayStore<[ScreenPoint; N], [u8; N]>;

impl<const N: usize> DisplayList<N> {
    /// An empty list.
    pub const fn new() -> Self {
        DisplayStore {
            points: [ScreenPoint::new(0.0, 0.0); N],
            flags: [0; N],
            len: 0,
            dropped: 0,
            skipped: 0,
            open: false,
        }
    }
}

impl<const N: usize> Default for DisplayList<N> {
    fn default() -> Self {
        Self::new()
    }
}

/// One polyline of a display list.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Polyline<'a> {
    /// Its vertices (a closed loop does not repeat the first at the end).
    pub points: &'a [ScreenPoint],
    /// True for a closed loop.
    pub closed: bool,
    /// True for a single dot (a DRAWPOINT).
    pub dot: bool,
}

impl<'a> Polyline<'a> {
    /// Lit length in DAC units (a closed loop includes its closing segment).
    pub fn length(&self) -> f32 {
        let open: f32 = self.points.windows(2).map(seg_len).sum();
        match (self.closed, self.points.first(), self.points.last()) {
            (true, Some(&a), Some(&b)) => open + a.distance(b),
            _ => open,
        }
    }

    /// The drawing commands of this polyline: `MoveTo` the first vertex,
    /// `LineTo` the others (and back to the first for a closed loop), or a
    /// single `Point`.
    pub fn commands(self) -> impl Iterator<Item = Command<ScreenPoint>> + 'a {
        let first = self.points.first().copied();
        let dot = self.dot || self.points.len() == 1;
        let head = first.map(|p| if dot { Command::Point(p) } else { Command::MoveTo(p) });
        let body = self.points.iter().skip(1).filter(move |_| !dot).map(|&p| Command::LineTo(p));
        let close = first.filter(|_| self.closed && !dot && self.points.len() > 2).map(Command::LineTo);
        head.into_iter().chain(body).chain(close)
    }
}

fn seg_len(w: &[ScreenPoint]) -> f32 {
    match w {
        [a, b] => a.distance(*b),
        _ => 0.0,
    }
}

/// What [`DisplayStore::optimize`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct OptimizeStats {
    /// Polylines (fragments) before.
    pub fragments: usize,
    /// Polylines after.
    pub polylines: usize,
    /// Points before.
    pub points_in: usize,
    /// Points after.
    pub points_out: usize,
    /// Segments drawn twice and culled.
    pub duplicate_segments: usize,
    /// Dots culled (covered by a line, or repeated).
    pub culled_dots: usize,
    /// Vertices removed by merging collinear runs.
    pub merged_points: usize,
}

/// Scratch memory for [`DisplayStore::optimize`] and [`DisplayStore::order`]:
/// index arrays and a second point buffer, each of the list's capacity
/// (`N` points: 32 bytes a point).
#[derive(Debug, Clone, PartialEq)]
pub struct ScratchStore<U, W, P, F> {
    a: U,
    b: U,
    c: U,
    d: U,
    edges: W,
    back: P,
    back_flags: F,
}

/// Scratch for a [`DisplayList<N>`].
pub type Scratch<const N: usize> = ScratchStore<[u32; N], [u64; N], [ScreenPoint; N], [u8; N]>;

impl<const N: usize> Scratch<N> {
    /// Scratch for lists of capacity `N`.
    pub const fn new() -> Self {
        ScratchStore {
            a: [0; N],
            b: [0; N],
            c: [0; N],
            d: [0; N],
            edges: [0; N],
            back: [ScreenPoint::new(0.0, 0.0); N],
            back_flags: [0; N],
        }
    }
}

impl<const N: usize> Default for Scratch<N> {
    fn default() -> Self {
        Self::new()
    }
}

/// The parts of a scratch store, as slices.
struct Parts<'s> {
    a: &'s mut [u32],
    b: &'s mut [u32],
    c: &'s mut [u32],
    d: &'s mut [u32],
    edges: &'s mut [u64],
    back: &'s mut [ScreenPoint],
    back_flags: &'s mut [u8],
}

impl<U, W, P, F> ScratchStore<U, W, P, F>
where
    U: AsMut<[u32]>,
    W: AsMut<[u64]>,
    P: AsMut<[ScreenPoint]>,
    F: AsMut<[u8]>,
{
    /// Every part as a slice, or `None` when one holds fewer than `cap`
    /// entries (a scratch too small for the list).
    fn parts(&mut self, cap: usize) -> Option<Parts<'_>> {
        let p = Parts {
            a: self.a.as_mut(),
            b: self.b.as_mut(),
            c: self.c.as_mut(),
            d: self.d.as_mut(),
            edges: self.edges.as_mut(),
            back: self.back.as_mut(),
            back_flags: self.back_flags.as_mut(),
        };
        let lens =
            [p.a.len(), p.b.len(), p.c.len(), p.d.len(), p.edges.len(), p.back.len(), p.back_flags.len()];
        lens.iter().all(|&l| l >= cap).then_some(p)
    }

    /// Whether every part holds at least `capacity` entries: enough for a
    /// list of that capacity.
    pub fn fits(&mut self, capacity: usize) -> bool {
        self.parts(capacity).is_some()
    }

    /// Scratch over caller storage (each part at least the list's capacity).
    pub fn with_storage(a: U, b: U, c: U, d: U, edges: W, back: P, back_flags: F) -> Self {
        Self { a, b, c, d, edges, back, back_flags }
    }
}

/// Parameters of the optimisation passes.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct OptimizeConfig {
    /// Largest distance (DAC units) of a dropped vertex from the chord that
    /// replaces it when merging collinear runs; 0 disables merging.
    /// Default: half an LSB.
    pub tolerance: f32,
}

impl Default for OptimizeConfig {
    fn default() -> Self {
        Self { tolerance: 0.5 }
    }
}

/// Parameters of [`DisplayStore::order`].
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct OrderConfig {
    /// Where the beam starts (the park position), in DAC units.
    pub start: ScreenPoint,
    /// Local search: how many rings of grid cells (about two polyline ends
    /// a cell) around a polyline's end are searched for partners of a move.
    pub window: usize,
    /// Local search: most rounds over the polylines.
    pub passes: usize,
    /// Iterated local search: double-bridge kicks per 100 polylines (time
    /// grows with it).
    pub kicks: usize,
    /// Iterated local search: kicks however few the polylines (there are
    /// none below 8 polylines, or when this and `kicks` are 0).
    pub min_kicks: usize,
}

impl Default for OrderConfig {
    fn default() -> Self {
        Self { start: ScreenPoint::new(0.0, 0.0), window: 3, passes: 50, kicks: 25, min_kicks: 100 }
    }
}

/// Blanked travel of an ordering (DAC units): as a path from
/// [`OrderConfig::start`] ([`DisplayStore::blank_length`]) and around the
/// refresh loop ([`DisplayStore::cycle_blank_length`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct OrderStats {
    /// Path, in the order the list had before.
    pub blank_before: f32,
    /// Path, after nearest neighbour.
    pub blank_nearest: f32,
    /// Path, in the final order.
    pub blank_after: f32,
    /// Refresh loop, in the order the list had before.
    pub cycle_before: f32,
    /// Refresh loop, after nearest neighbour.
    pub cycle_nearest: f32,
    /// Refresh loop, in the final order.
    pub cycle_after: f32,
}

#[inline]
fn key(p: ScreenPoint) -> u64 {
    // +0.0 folds -0.0 into 0.0 so that equal points have equal keys.
    (u64::from((p.x + 0.0).to_bits()) << 32) | u64::from((p.y + 0.0).to_bits())
}

#[inline]
fn get<T: Copy + Default>(s: &[T], i: usize) -> T {
    s.get(i).copied().unwrap_or_default()
}

#[inline]
fn set<T>(s: &mut [T], i: usize, v: T) {
    if let Some(x) = s.get_mut(i) {
        *x = v;
    }
}

impl<P, F> DisplayStore<P, F>
where
    P: AsRef<[ScreenPoint]> + AsMut<[ScreenPoint]>,
    F: AsRef<[u8]> + AsMut<[u8]>,
{
    /// A list over caller storage; its capacity is the shorter of the two.
    pub fn with_storage(points: P, flags: F) -> Self {
        Self { points, flags, len: 0, dropped: 0, skipped: 0, open: false }
    }

    /// Point capacity.
    pub fn capacity(&self) -> usize {
        self.points.as_ref().len().min(self.flags.as_ref().len())
    }

    /// Points held.
    pub fn len(&self) -> usize {
        self.len
    }

    /// True when the list holds nothing.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Commands handed back because the list was full.
    pub fn dropped(&self) -> u64 {
        self.dropped
    }

    /// Commands ignored because their point was not finite.
    pub fn skipped(&self) -> u64 {
        self.skipped
    }

    /// Empty the list (keeps the counters of dropped and skipped commands
    /// until [`DisplayStore::reset_counters`]).
    pub fn clear(&mut self) {
        self.len = 0;
        self.open = false;
    }

    /// Zero the dropped and skipped counters.
    pub fn reset_counters(&mut self) {
        self.dropped = 0;
        self.skipped = 0;
    }

    /// Add a command. `MoveTo` starts a polyline, `LineTo` extends it (or
    /// starts one if none is open), `Point` adds a dot.
    ///
    /// # Errors
    /// The command is handed back when the list is full; it is counted in
    /// [`DisplayStore::dropped`], and later `LineTo`s of the same polyline
    /// are refused too until the next `MoveTo` or `Point` fits. A command
    /// whose point is not finite is ignored (counted in
    /// [`DisplayStore::skipped`]) and ends the open polyline.
    pub fn push(&mut self, command: Command<ScreenPoint>) -> Result<(), Command<ScreenPoint>> {
        let p = *command.point();
        if !(p.x.is_finite() && p.y.is_finite()) {
            self.skipped += 1;
            self.open = false;
            return Ok(());
        }
        let flag = match command {
            Command::MoveTo(_) => START,
            Command::LineTo(_) if self.open => 0,
            Command::LineTo(_) => START,
            Command::Point(_) => START | DOT,
        };
        if self.len >= self.capacity() {
            self.dropped += 1;
            self.open = false;
            return Err(command);
        }
        set(self.points.as_mut(), self.len, p);
        set(self.flags.as_mut(), self.len, flag);
        self.len += 1;
        self.open = flag & DOT == 0;
        Ok(())
    }

    /// The polylines, in list order.
    pub fn polylines(&self) -> impl Iterator<Item = Polyline<'_>> + '_ {
        let points = self.points.as_ref().get(..self.len).unwrap_or(&[]);
        let flags = self.flags.as_ref().get(..self.len).unwrap_or(&[]);
        let mut i = 0;
        core::iter::from_fn(move || {
            if i >= points.len() {
                return None;
            }
            let start = i;
            let f = get(flags, start);
            i += 1;
            while i < points.len() && get(flags, i) & START == 0 {
                i += 1;
            }
            Some(Polyline {
                points: points.get(start..i).unwrap_or(&[]),
                closed: f & CLOSED != 0,
                dot: f & DOT != 0,
            })
        })
    }

    /// Number of polylines (dots included).
    pub fn polyline_count(&self) -> usize {
        self.flags.as_ref().iter().take(self.len).filter(|&&f| f & START != 0).count()
    }

    /// All drawing commands in list order.
    pub fn commands(&self) -> impl Iterator<Item = Command<ScreenPoint>> + '_ {
        self.polylines().flat_map(Polyline::commands)
    }

    /// Total lit length in DAC units.
    pub fn lit_length(&self) -> f32 {
        self.polylines().map(|p| p.length()).sum()
    }

    /// Blanked travel in list order, starting at `start`, in DAC units.
    pub fn blank_length(&self, start: ScreenPoint) -> f32 {
        let mut at = start;
        let mut total = 0.0;
        for p in self.polylines() {
            let (Some(&first), Some(&last)) = (p.points.first(), p.points.last()) else { continue };
            total += at.distance(first);
            at = if p.closed { first } else { last };
        }
        total
    }
}

impl<P, F> DisplayStore<P, F>
where
    P: AsRef<[ScreenPoint]> + AsMut<[ScreenPoint]>,
    F: AsRef<[u8]> + AsMut<[u8]>,
{
    /// Cull duplicates, stitch fragments into maximal polylines and merge
    /// collinear runs (see the module docs). The list keeps its capacity;
    /// `scratch` must have at least that capacity in every part (a smaller
    /// scratch leaves the list as it is and reports nothing done).
    pub fn optimize<U, W, Q, G>(
        &mut self,
        scratch: &mut ScratchStore<U, W, Q, G>,
        cfg: &OptimizeConfig,
    ) -> OptimizeStats
    where
        U: AsMut<[u32]>,
        W: AsMut<[u64]>,
        Q: AsMut<[ScreenPoint]>,
        G: AsMut<[u8]>,
    {
        let n = self.len;
        let mut stats = OptimizeStats {
            fragments: self.polyline_count(),
            points_in: n,
            points_out: n,
            polylines: self.polyline_count(),
            ..Default::default()
        };
        let Some(Parts { a: vid, b: order, c: deg, d: adj, edges, back, back_flags }) =
            scratch.parts(self.capacity()).filter(|_| n > 0)
        else {
            return stats;
        };
        let points = self.points.as_ref();
        let flags = self.flags.as_ref();

        // 1. Vertices: equal points share the id of the first of them.
        for (i, o) in order.iter_mut().take(n).enumerate() {
            *o = i as u32;
        }
        if let Some(o) = order.get_mut(..n) {
            o.sort_unstable_by_key(|&i| (key(get(points, i as usize)), i));
        }
        let mut prev_key = None;
        let mut prev_id = 0u32;
        for k in 0..n {
            let i = get(order, k);
            let kk = key(get(points, i as usize));
            if prev_key != Some(kk) {
                prev_key = Some(kk);
                prev_id = i;
            }
            set(vid, i as usize, prev_id);
        }

        // 2. Segments as sorted, deduplicated vertex pairs.
        let mut m = 0usize;
        for i in 1..n {
            if get(flags, i) & START != 0 {
                continue;
            }
            let (u, v) = (get(vid, i - 1), get(vid, i));
            if u != v {
                let (lo, hi) = if u < v { (u, v) } else { (v, u) };
                set(edges, m, (u64::from(lo) << 32) | u64::from(hi));
                m += 1;
            }
        }
        // Closed loops already in the list keep their closing segment.
        let mut start = 0usize;
        for i in 0..=n {
            if i == n || get(flags, i) & START != 0 {
                if i > start + 2 && get(flags, start) & CLOSED != 0 && m < edges.len() {
                    let (u, v) = (get(vid, i - 1), get(vid, start));
                    if u != v {
                        let (lo, hi) = if u < v { (u, v) } else { (v, u) };
                        set(edges, m, (u64::from(lo) << 32) | u64::from(hi));
                        m += 1;
                    }
                }
                start = i;
            }
        }
        if let Some(e) = edges.get_mut(..m) {
            e.sort_unstable();
        }
        let mut unique = 0usize;
        for k in 0..m {
            let e = get(edges, k);
            if unique == 0 || get(edges, unique - 1) != e {
                set(edges, unique, e);
                unique += 1;
            }
        }
        stats.duplicate_segments = m - unique;
        let m = unique;

        // 3. Adjacency (compressed rows): `first[v]` is v's first slot; the
        // slots (two per segment) live in `d` and then in `b`, free by now.
        let first = deg;
        for x in first.iter_mut().take(n) {
            *x = 0;
        }
        for k in 0..m {
            let e = get(edges, k);
            for v in [(e >> 32) as usize, (e & 0xFFFF_FFFF) as usize] {
                set(first, v, get(first, v) + 1);
            }
        }
        let mut total = 0u32;
        for x in first.iter_mut().take(n) {
            total += *x;
            *x = total; // one past v's last slot, for now
        }
        let mut slots = Slots { lo: adj, hi: order };
        for k in 0..m {
            let e = get(edges, k);
            for v in [(e >> 32) as usize, (e & 0xFFFF_FFFF) as usize] {
                let slot = get(first, v) - 1;
                set(first, v, slot);
                slots.set(slot as usize, k as u32);
            }
        }
        let end_of = |first: &[u32], v: usize| if v + 1 < n { get(first, v + 1) } else { total };
        // 4. Walks: open paths from odd vertices first, then closed loops.
        let mut out = Builder {
            points: back,
            flags: back_flags,
            len: 0,
            tol: cfg.tolerance,
            start: 0,
            dropped: [ScreenPoint::new(0.0, 0.0); RUN],
            ndropped: 0,
        };
        let mut merged = 0usize;
        let other =
            |e: u64, v: u32| if (e >> 32) as u32 == v { (e & 0xFFFF_FFFF) as u32 } else { (e >> 32) as u32 };
        for pass in 0..2 {
            for v0 in 0..n as u32 {
                if get(vid, v0 as usize) != v0 {
                    continue;
                }
                loop {
                    let free = |v: u32, edges: &[u64]| {
                        let (s, e) = (get(first, v as usize), end_of(first, v as usize));
                        (s..e)
                            .filter(|&slot| get(edges, slots.get(slot as usize) as usize) >> 63 == 0)
                            .count()
                    };
                    let f = free(v0, edges);
                    if f == 0 || (pass == 0 && f % 2 == 0) {
                        break;
                    }
                    // Walk from v0, always taking the straightest free segment.
                    let mut v = v0;
                    let mut dir: Option<(f32, f32)> = None;
                    out.begin(get(points, v0 as usize));
                    loop {
                        let here = get(points, v as usize);
                        let (s, e) = (get(first, v as usize), end_of(first, v as usize));
                        let mut best: Option<(usize, f32)> = None;
                        for slot in s..e {
                            let k = slots.get(slot as usize) as usize;
                            let ek = get(edges, k);
                            if ek >> 63 != 0 {
                                continue;
                            }
                            let w = get(points, other(ek, v) as usize);
                            let (dx, dy) = (w.x - here.x, w.y - here.y);
                            let score = match dir {
                                // Cosine of the turn: larger is straighter.
                                Some((px, py)) => {
                                    let l = libm::sqrtf(dx * dx + dy * dy).max(f32::MIN_POSITIVE);
                                    (px * dx + py * dy) / l
                                }
                                None => 0.0,
                            };
                            if best.is_none_or(|(_, b)| score > b) {
                                best = Some((k, score));
                            }
                        }
                        let Some((k, _)) = best else { break };
                        let ek = get(edges, k);
                        set(edges, k, ek | (1 << 63));
                        let w = other(ek & !(1 << 63), v);
                        let (hp, wp) = (here, get(points, w as usize));
                        let l = hp.distance(wp).max(f32::MIN_POSITIVE);
                        dir = Some(((wp.x - hp.x) / l, (wp.y - hp.y) / l));
                        v = w;
                        merged += out.line_to(wp);
                    }
                    merged += out.end(v == v0);
                }
            }
        }
        // 5. Dots not covered by a line, once each.
        let mut culled = 0usize;
        let mut start = 0usize;
        for i in 0..=n {
            if i == n || get(flags, i) & START != 0 {
                if i > start && (get(flags, start) & DOT != 0 || i - start == 1) {
                    let v = get(vid, start);
                    let covered = end_of(first, v as usize) > get(first, v as usize);
                    // Mark a drawn dot by a self-loop slot: use vid's top bit.
                    let drawn = get(vid, v as usize) >> 31 != 0;
                    if covered || drawn {
                        culled += 1;
                    } else {
                        set(vid, v as usize, get(vid, v as usize) | (1 << 31));
                        out.dot(get(points, start));
                    }
                }
                start = i;
            }
        }
        stats.culled_dots = culled;
        stats.merged_points = merged;
        let len = out.len;
        // 6. The rebuilt list becomes the list.
        let (pts, fl) = (self.points.as_mut(), self.flags.as_mut());
        for i in 0..len {
            set(pts, i, get(back, i));
            set(fl, i, get(back_flags, i));
        }
        self.len = len;
        self.open = false;
        stats.points_out = len;
        stats.polylines = self.polyline_count();
        stats
    }
}

/// Adjacency slots over two scratch arrays (two slots per segment, and
/// there are fewer segments than points).
struct Slots<'s> {
    lo: &'s mut [u32],
    hi: &'s mut [u32],
}

impl Slots<'_> {
    fn get(&self, i: usize) -> u32 {
        match i.checked_sub(self.lo.len()) {
            None => get(self.lo, i),
            Some(j) => get(self.hi, j),
        }
    }

    fn set(&mut self, i: usize, v: u32) {
        match i.checked_sub(self.lo.len()) {
            None => set(self.lo, i, v),
            Some(j) => set(self.hi, j, v),
        }
    }
}

/// Longest run of vertices a collinear merge may replace by one chord.
const RUN: usize = 32;

/// Writes rebuilt polylines, merging collinear runs on the way.
struct Builder<'s> {
    points: &'s mut [ScreenPoint],
    flags: &'s mut [u8],
    len: usize,
    tol: f32,
    /// First vertex of the polyline being written.
    start: usize,
    /// Vertices dropped since the last kept one: all must stay within
    /// `tol` of the chord that replaces them.
    dropped: [ScreenPoint; RUN],
    ndropped: usize,
}

/// Distance from `p` to the segment `a`-`b`, and whether `p` projects
/// inside it.
fn chord_distance(p: ScreenPoint, a: ScreenPoint, b: ScreenPoint) -> (f32, bool) {
    let (vx, vy) = (b.x - a.x, b.y - a.y);
    let (wx, wy) = (p.x - a.x, p.y - a.y);
    let l2 = vx * vx + vy * vy;
    if l2 <= 0.0 {
        return (libm::sqrtf(wx * wx + wy * wy), false);
    }
    let t = (wx * vx + wy * vy) / l2;
    let cross = wx * vy - wy * vx;
    (libm::fabsf(cross) / libm::sqrtf(l2), (0.0..=1.0).contains(&t))
}

impl Builder<'_> {
    fn push(&mut self, p: ScreenPoint, flag: u8) {
        set(self.points, self.len, p);
        set(self.flags, self.len, flag);
        self.len += 1;
    }

    fn begin(&mut self, p: ScreenPoint) {
        self.start = self.len;
        self.ndropped = 0;
        self.push(p, START);
    }

    /// Append `q`; returns 1 when the previous vertex was merged away.
    fn line_to(&mut self, q: ScreenPoint) -> usize {
        if self.len >= self.start + 2 && self.tol > 0.0 && self.ndropped < RUN {
            let a = get(self.points, self.len - 2);
            let b = get(self.points, self.len - 1);
            let fits = |p: ScreenPoint| {
                let (d, inside) = chord_distance(p, a, q);
                d <= self.tol && inside
            };
            if fits(b) && self.dropped.iter().take(self.ndropped).all(|&p| fits(p)) {
                set(&mut self.dropped, self.ndropped, b);
                self.ndropped += 1;
                set(self.points, self.len - 1, q);
                return 1;
            }
        }
        self.ndropped = 0;
        self.push(q, 0);
        0
    }

    /// End the polyline; `returned` when the walk came back to its start.
    /// Returns 1 when the repeated start vertex was removed.
    fn end(&mut self, returned: bool) -> usize {
        if returned && self.len >= self.start + 4 {
            // The last vertex is the first again: close the loop instead.
            self.len -= 1;
            if let Some(f) = self.flags.get_mut(self.start) {
                *f |= CLOSED;
            }
            return 0;
        }
        0
    }

    fn dot(&mut self, p: ScreenPoint) {
        self.push(p, START | DOT);
    }
}

/// Orientation bit of an ordered polyline: drawn from its last vertex.
const REVERSED: u32 = 1 << 31;

/// Least gain (DAC units) for which an improving move is made.
const EPS: f32 = 1e-3;

/// The polylines of a list as the ordering sees them: polyline `p` starts
/// at vertex `starts[p]`.
struct Lines<'s> {
    points: &'s [ScreenPoint],
    flags: &'s [u8],
    starts: &'s [u32],
    n: usize,
}

impl Lines<'_> {
    fn count(&self) -> usize {
        self.starts.len()
    }

    fn range(&self, p: usize) -> (usize, usize) {
        let s = get(self.starts, p) as usize;
        let e = if p + 1 < self.count() { get(self.starts, p + 1) as usize } else { self.n };
        (s, e.max(s + 1))
    }

    fn closed(&self, p: usize) -> bool {
        get(self.flags, self.range(p).0) & CLOSED != 0
    }

    fn point(&self, v: usize) -> ScreenPoint {
        get(self.points, v)
    }

    /// Entry and exit vertices of `p` drawn as `h` (a closed loop is left
    /// where it was entered).
    fn ends_v(&self, p: usize, h: u32) -> (usize, usize) {
        let (s, e) = self.range(p);
        if self.closed(p) {
            let v = s + (h & !REVERSED) as usize;
            (v, v)
        } else if h & REVERSED != 0 {
            (e - 1, s)
        } else {
            (s, e - 1)
        }
    }

    /// Entry and exit points of `p` drawn as `h`.
    fn ends(&self, p: usize, h: u32) -> (ScreenPoint, ScreenPoint) {
        let (a, b) = self.ends_v(p, h);
        (self.point(a), self.point(b))
    }

    /// How to draw `p` to enter it at its door at `q`.
    fn entering_at(&self, p: usize, q: ScreenPoint) -> u32 {
        let (s, e) = self.range(p);
        if self.closed(p) {
            (s..e).find(|&v| self.point(v) == q).map_or(0, |v| (v - s) as u32)
        } else if self.point(s) == q || e - s < 2 {
            0
        } else {
            REVERSED
        }
    }

    /// Put the doors of every polyline into `items` (polyline) and `at`
    /// (point); returns how many.
    fn doors_into(&self, items: &mut [u32], at: &mut [ScreenPoint]) -> usize {
        let mut m = 0usize;
        for p in 0..self.count() {
            for v in self.doors(p) {
                set(items, m, p as u32);
                set(at, m, self.point(v));
                m += 1;
            }
        }
        m
    }

    /// The vertices where `p` may be entered or left: every vertex of a
    /// closed loop, the ends of anything else.
    fn doors(&self, p: usize) -> impl Iterator<Item = usize> {
        let (s, e) = self.range(p);
        let closed = self.closed(p);
        (s..e).filter(move |&v| closed || v == s || v + 1 == e)
    }

    /// How to draw `p` to enter it at its door `v`.
    fn entering(&self, p: usize, v: usize) -> u32 {
        let (s, e) = self.range(p);
        if self.closed(p) {
            (v - s) as u32
        } else if v == s || e - s < 2 {
            0
        } else {
            REVERSED
        }
    }

    /// `h` for `p` drawn the other way round (a closed loop stays as it is).
    fn flip(&self, p: usize, h: u32) -> u32 {
        if self.closed(p) { h } else { h ^ REVERSED }
    }
}

/// The cells of a uniform grid over the screen.
#[derive(Clone, Copy)]
struct Cells {
    gx: usize,
    gy: usize,
    x0: f32,
    y0: f32,
    cw: f32,
    ch: f32,
}

impl Cells {
    fn count(&self) -> usize {
        self.gx * self.gy
    }

    /// Column and row of the cell holding `q` (or nearest to it).
    fn xy(&self, q: ScreenPoint) -> (usize, usize) {
        // `as` saturates: negative and NaN become 0.
        let x = ((q.x - self.x0) / self.cw) as usize;
        let y = ((q.y - self.y0) / self.ch) as usize;
        (x.min(self.gx.saturating_sub(1)), y.min(self.gy.saturating_sub(1)))
    }

    fn index(&self, q: ScreenPoint) -> usize {
        let (x, y) = self.xy(q);
        y * self.gx + x
    }

    /// A lower bound on the distance from `q`, in or nearest to cell
    /// `(cx, cy)`, to anything in the cells `r` or more rings away from it
    /// (infinite when there are none).
    fn ring_bound(&self, q: ScreenPoint, cx: usize, cy: usize, r: usize) -> f32 {
        let (rf, xf, yf) = (r as f32, cx as f32, cy as f32);
        let mut bound = f32::INFINITY;
        if cx >= r {
            bound = bound.min(q.x - (self.x0 + (xf - rf + 1.0) * self.cw));
        }
        if cx + r < self.gx {
            bound = bound.min(self.x0 + (xf + rf) * self.cw - q.x);
        }
        if cy >= r {
            bound = bound.min(q.y - (self.y0 + (yf - rf + 1.0) * self.ch));
        }
        if cy + r < self.gy {
            bound = bound.min(self.y0 + (yf + rf) * self.ch - q.y);
        }
        bound
    }

    /// Visit the cells of ring `r` around `(cx, cy)`.
    fn ring(&self, cx: usize, cy: usize, r: usize, mut f: impl FnMut(usize)) {
        if r == 0 {
            f(cy * self.gx + cx);
            return;
        }
        let x_lo = cx.saturating_sub(r);
        let x_hi = (cx + r).min(self.gx.saturating_sub(1));
        for y in [cy.checked_sub(r), Some(cy + r).filter(|&y| y < self.gy)].into_iter().flatten() {
            for x in x_lo..=x_hi {
                f(y * self.gx + x);
            }
        }
        let y_lo = (cy + 1).saturating_sub(r);
        let y_hi = (cy + r - 1).min(self.gy.saturating_sub(1));
        for x in [cx.checked_sub(r), Some(cx + r).filter(|&x| x < self.gx)].into_iter().flatten() {
            for y in y_lo..=y_hi {
                f(y * self.gx + x);
            }
        }
    }
}

/// Most doors one neighbourhood search looks at (a bound on the time a
/// move search takes, however crowded the cells).
const NEAR: usize = 256;

/// A uniform grid over the doors of the polylines (about two a cell), in
/// scratch memory: the doors' polylines and points grouped by cell, and each
/// cell's first item.
struct Grid<'s> {
    items: &'s mut [u32],
    at: &'s mut [ScreenPoint],
    first: &'s mut [u32],
    m: usize,
    cells: Cells,
}

impl Grid<'_> {
    /// Items of cell `c`.
    fn span(&self, c: usize) -> (usize, usize) {
        let lo = get(self.first, c) as usize;
        let hi = if c + 1 < self.cells.count() { get(self.first, c + 1) as usize } else { self.m };
        (lo, hi)
    }

    /// Sort the doors `items[..m]`, `at[..m]` into a new grid fitted to
    /// them (a counting sort in place; `cursor` is scratch of a cell a slot).
    fn build(&mut self, m: usize, cursor: &mut [u32]) {
        self.m = m;
        let (mut lo, mut hi) = (ScreenPoint::new(f32::INFINITY, f32::INFINITY), ScreenPoint::new(0.0, 0.0));
        hi.x = f32::NEG_INFINITY;
        hi.y = f32::NEG_INFINITY;
        for k in 0..m {
            let q = get(self.at, k);
            lo = ScreenPoint::new(lo.x.min(q.x), lo.y.min(q.y));
            hi = ScreenPoint::new(hi.x.max(q.x), hi.y.max(q.y));
        }
        if m == 0 {
            (lo, hi) = (ScreenPoint::new(0.0, 0.0), ScreenPoint::new(0.0, 0.0));
        }
        let g = (m / 2).min(self.first.len()).min(cursor.len()).max(1);
        let (w, h) = (hi.x - lo.x, hi.y - lo.y);
        let (gx, gy) = if w > 0.0 && h > 0.0 {
            let side = libm::sqrtf(w * h / g as f32);
            let gx = ((w / side) as usize).clamp(1, g);
            (gx, (g / gx).max(1))
        } else if w > 0.0 {
            (g, 1)
        } else if h > 0.0 {
            (1, g)
        } else {
            (1, 1)
        };
        // A hair larger than the box, so that its far edge falls inside.
        let cw = (w / gx as f32 * 1.0001).max(1e-6);
        let ch = (h / gy as f32 * 1.0001).max(1e-6);
        let cells = Cells { gx, gy, x0: lo.x, y0: lo.y, cw, ch };
        self.cells = cells;
        let nc = cells.count();
        for c in 0..nc {
            set(self.first, c, 0);
        }
        for k in 0..m {
            let c = cells.index(get(self.at, k));
            set(self.first, c, get(self.first, c) + 1);
        }
        let mut total = 0u32;
        for c in 0..nc {
            let size = get(self.first, c);
            set(self.first, c, total);
            set(cursor, c, total);
            total += size;
        }
        // Each swap puts one item into its cell for good.
        for c in 0..nc {
            let end = if c + 1 < nc { get(self.first, c + 1) } else { m as u32 };
            loop {
                let k = get(cursor, c);
                if k >= end {
                    break;
                }
                let q = get(self.at, k as usize);
                let dc = cells.index(q);
                if dc == c {
                    set(cursor, c, k + 1);
                } else {
                    let t = get(cursor, dc);
                    if t as usize >= m {
                        break;
                    }
                    set(cursor, dc, t + 1);
                    let (v, vt) = (get(self.items, k as usize), get(self.items, t as usize));
                    set(self.items, k as usize, vt);
                    set(self.at, k as usize, get(self.at, t as usize));
                    set(self.items, t as usize, v);
                    set(self.at, t as usize, q);
                }
            }
        }
    }

    /// Every item live again: `live` gets each cell's item count.
    fn revive(&self, live: &mut [u32]) {
        for c in 0..self.cells.count() {
            let (lo, hi) = self.span(c);
            set(live, c, (hi - lo) as u32);
        }
    }

    /// The live item nearest `q` (each cell's live items come first).
    fn nearest_live(&self, q: ScreenPoint, live: &[u32]) -> Option<usize> {
        let cells = self.cells;
        let (cx, cy) = cells.xy(q);
        let mut best: Option<(usize, f32)> = None;
        for r in 0..=cells.gx.max(cells.gy) {
            if let Some((_, bd)) = best {
                let lb = cells.ring_bound(q, cx, cy, r);
                if lb > 0.0 && lb * lb >= bd {
                    break;
                }
            }
            cells.ring(cx, cy, r, |c| {
                let lo = get(self.first, c) as usize;
                for k in lo..lo + get(live, c) as usize {
                    let a = get(self.at, k);
                    let (dx, dy) = (a.x - q.x, a.y - q.y);
                    let d = dx * dx + dy * dy;
                    if best.is_none_or(|(_, b)| d < b) {
                        best = Some((k, d));
                    }
                }
            });
        }
        best.map(|(k, _)| k)
    }

    /// Take the door of polyline `v` at `q` out of the live items of its
    /// cell; false if it was not there.
    fn kill(&mut self, v: u32, q: ScreenPoint, live: &mut [u32]) -> bool {
        let c = self.cells.index(q);
        let lo = get(self.first, c) as usize;
        let n = get(live, c) as usize;
        for k in lo..lo + n {
            if get(self.items, k) == v && get(self.at, k) == q {
                let last = lo + n - 1;
                set(self.items, k, get(self.items, last));
                set(self.at, k, get(self.at, last));
                set(self.items, last, v);
                set(self.at, last, q);
                set(live, c, (n - 1) as u32);
                return true;
            }
        }
        false
    }

    /// Visit the doors within `radius` of `q` (polyline, point, distance),
    /// at most `rings` rings of cells away and [`NEAR`] doors looked at.
    fn near(&self, q: ScreenPoint, radius: f32, rings: usize, mut f: impl FnMut(usize, ScreenPoint, f32)) {
        let cells = self.cells;
        let (cx, cy) = cells.xy(q);
        let r2 = radius * radius;
        let mut budget = NEAR;
        for r in 0..=rings.min(cells.gx.max(cells.gy)) {
            if cells.ring_bound(q, cx, cy, r) >= radius || budget == 0 {
                break;
            }
            cells.ring(cx, cy, r, |c| {
                let (lo, hi) = self.span(c);
                let hi = hi.min(lo + budget);
                budget -= hi.saturating_sub(lo);
                for k in lo..hi {
                    let a = get(self.at, k);
                    let (dx, dy) = (a.x - q.x, a.y - q.y);
                    let d2 = dx * dx + dy * dy;
                    if d2 < r2 {
                        f(get(self.items, k) as usize, a, libm::sqrtf(d2));
                    }
                }
            });
        }
    }
}

/// A cyclic tour of the polylines: `seq[k]` is polyline and how it is drawn
/// (`how << 32 | polyline`), `pos` the inverse.
struct Tour<'s> {
    seq: &'s mut [u64],
    pos: &'s mut [u32],
    count: usize,
}

impl Tour<'_> {
    fn at(&self, k: usize) -> (usize, u32) {
        unpack(get(self.seq, k))
    }

    fn put(&mut self, k: usize, p: usize, h: u32) {
        set(self.seq, k, pack(p, h));
        set(self.pos, p, k as u32);
    }

    fn pos(&self, p: usize) -> usize {
        get(self.pos, p) as usize
    }

    fn add(&self, k: usize, d: usize) -> usize {
        if self.count == 0 { 0 } else { (k + d) % self.count }
    }

    fn next(&self, k: usize) -> usize {
        self.add(k, 1)
    }

    fn prev(&self, k: usize) -> usize {
        self.add(k, self.count.saturating_sub(1))
    }

    /// Steps forward from `a` to `b`.
    fn gap(&self, a: usize, b: usize) -> usize {
        self.add(b, self.count.saturating_sub(a % self.count.max(1)))
    }

    /// Reverse the polylines at `i..=j` (cyclically), or the rest of the
    /// cycle when that is shorter: the same cycle either way.
    fn reverse(&mut self, lines: &Lines<'_>, i: usize, j: usize) {
        let mut m = self.gap(i, j) + 1;
        let (mut i, mut j) = (i, j);
        if 2 * m > self.count {
            (i, j, m) = (self.next(j), self.prev(i), self.count - m);
        }
        for t in 0..m / 2 {
            let (a, b) = (self.add(i, t), self.add(j, self.count - t));
            let ((pa, ha), (pb, hb)) = (self.at(a), self.at(b));
            self.put(a, pb, hb);
            self.put(b, pa, ha);
        }
        for t in 0..m {
            let k = self.add(i, t);
            let (p, h) = self.at(k);
            self.put(k, p, lines.flip(p, h));
        }
    }

    /// Move the `len` (at most 3) polylines at `s0..` to just after position
    /// `t`, reversed if `rev`; a single closed loop is re-entered as `h`.
    /// The polylines between move the shorter way round (or as `forward`
    /// says: those after the chain, rather than those before it). Returns
    /// the move that undoes this one.
    #[allow(clippy::too_many_arguments)]
    fn shift(
        &mut self,
        lines: &Lines<'_>,
        s0: usize,
        len: usize,
        t: usize,
        rev: bool,
        h: Option<u32>,
        forward: Option<bool>,
    ) -> Undo {
        let mut buf = [(0usize, 0u32); 3];
        let len = len.clamp(1, 3);
        for (u, b) in buf.iter_mut().take(len).enumerate() {
            *b = self.at(self.add(s0, u));
        }
        let old_h = h.map(|_| get(&buf, 0).1);
        if let Some(seg) = buf.get_mut(..len) {
            if rev {
                seg.reverse();
                for (p, hh) in seg.iter_mut() {
                    *hh = lines.flip(*p, *hh);
                }
            }
            if let (Some(h), Some(first)) = (h, seg.first_mut()) {
                first.1 = h;
            }
        }
        let s1 = self.add(s0, len - 1);
        let f = self.gap(s1, t);
        let b = self.count.saturating_sub(len + f);
        let forward = forward.unwrap_or(f <= b);
        if forward {
            for u in 0..f {
                let (p, hh) = self.at(self.add(s1, 1 + u));
                self.put(self.add(s0, u), p, hh);
            }
            for (u, &(p, hh)) in buf.iter().take(len).enumerate() {
                self.put(self.add(s0, f + u), p, hh);
            }
        } else {
            for u in 0..b {
                let src = self.add(s0, self.count - 1 - u);
                let (p, hh) = self.at(src);
                self.put(self.add(src, len), p, hh);
            }
            for (u, &(p, hh)) in buf.iter().take(len).enumerate() {
                self.put(self.add(t, 1 + u), p, hh);
            }
        }
        if forward {
            Undo::Shift { s0: self.add(s0, f), len, t: self.prev(s0), rev, h: old_h, forward: false }
        } else {
            Undo::Shift { s0: self.add(t, 1), len, t: s1, rev, h: old_h, forward: true }
        }
    }

    /// Undo a move.
    fn undo(&mut self, lines: &Lines<'_>, u: Undo) {
        match u {
            Undo::Reverse { i, j } => self.reverse(lines, i, j),
            Undo::Shift { s0, len, t, rev, h, forward } => {
                self.shift(lines, s0, len, t, rev, h, Some(forward));
            }
            Undo::Enter { line, h } => self.put(self.pos(line), line, h),
            Undo::Nothing => {}
        }
    }
}

/// How to undo a change of a tour (see [`Tour::undo`]).
#[derive(Clone, Copy, Default)]
enum Undo {
    #[default]
    Nothing,
    Reverse {
        i: usize,
        j: usize,
    },
    Shift {
        s0: usize,
        len: usize,
        t: usize,
        rev: bool,
        h: Option<u32>,
        forward: bool,
    },
    Enter {
        line: usize,
        h: u32,
    },
}

/// An improving change of a tour; `enter` re-enters a closed loop
/// (polyline, at the door at that point) first.
#[derive(Clone, Copy)]
enum Move {
    /// Reverse positions `i..=j` (a closed loop alone stays as it is).
    Reverse { i: usize, j: usize, enter: Option<(usize, ScreenPoint)> },
    /// Move `len` polylines from `s0` to after `t` (see [`Tour::shift`]).
    Shift { s0: usize, len: usize, t: usize, rev: bool, h: Option<u32>, enter: Option<(usize, ScreenPoint)> },
}

/// A chain of polylines an or-opt move may take out: from position `s0`,
/// `len` of them, between exit `u` and entry `w`; entered at `e`, left at
/// `x`; taking it out shortens the tour by `gain`.
#[derive(Clone, Copy)]
struct Chain {
    s0: usize,
    len: usize,
    u: ScreenPoint,
    w: ScreenPoint,
    e: ScreenPoint,
    x: ScreenPoint,
    gain: f32,
}

/// Local search over a tour: 2-opt and or-opt moves between polylines whose
/// doors are near each other (found in the grid), loop entries re-chosen.
struct Search<'a, 'g, 't> {
    lines: &'a Lines<'a>,
    grid: &'a Grid<'g>,
    tour: Tour<'t>,
    /// Per polyline: nothing improved around it since it was last looked at.
    idle: &'t mut [u8],
    /// Rings of grid cells searched for partners.
    rings: usize,
    /// Most polylines a move may shift or reverse.
    max_work: usize,
}

impl Search<'_, '_, '_> {
    fn ends(&self, k: usize) -> (ScreenPoint, ScreenPoint) {
        let (p, h) = self.tour.at(k);
        self.lines.ends(p, h)
    }

    /// Blanked travel around the whole cycle.
    fn cycle(&self) -> f32 {
        let count = self.tour.count;
        let mut at = self.ends(count.saturating_sub(1)).1;
        let mut total = 0.0;
        for k in 0..count {
            let (e, x) = self.ends(k);
            total += at.distance(e);
            at = x;
        }
        total
    }

    /// The best improving move around polyline `p`, if any.
    fn best_move(&self, p: usize, nch: usize) -> Option<(f32, Move)> {
        let (lines, tour) = (self.lines, &self.tour);
        let count = tour.count;
        let i = tour.pos(p);
        let (ip, inx) = (tour.prev(i), tour.next(i));
        let (e_i, x_i) = self.ends(i);
        let x_prev = self.ends(ip).1;
        let e_next = self.ends(inx).0;
        let best: Cell<Option<(f32, Move)>> = Cell::new(None);
        let consider = |delta: f32, m: Move| {
            if delta < -EPS && best.get().is_none_or(|(b, _)| delta < b) {
                let work = match m {
                    Move::Reverse { i, j, .. } => {
                        let l = tour.gap(i, j) + 1;
                        l.min(count - l)
                    }
                    Move::Shift { s0, t, .. } => {
                        let l = tour.gap(s0, t);
                        l.min(count - l)
                    }
                };
                if work <= self.max_work {
                    best.set(Some((delta, m)));
                }
            }
        };
        let dist = |a: ScreenPoint, b: ScreenPoint| a.distance(b);

        // Enter a loop where it best serves both neighbours.
        if lines.closed(p) {
            let now = dist(x_prev, e_i) + dist(x_i, e_next);
            for v in lines.doors(p) {
                let q = lines.point(v);
                let m = Move::Reverse { i, j: i, enter: Some((p, q)) };
                consider(dist(x_prev, q) + dist(q, e_next) - now, m);
            }
        }
        if count < 3 {
            return best.get();
        }

        // Or-opt chains of 1 to 3 polylines that start or end at p: where
        // they start, their length, their neighbours' exit and entry, their
        // entry and exit, and what taking them out gains.
        let mut chains = [None; 5];
        for (c, (back, len)) in chains.iter_mut().zip([(0, 1), (0, 2), (0, 3), (1, 2), (2, 3)]).take(nch) {
            if len + 2 > count {
                continue;
            }
            let s0 = tour.add(i, count - back);
            let s1 = tour.add(s0, len - 1);
            let (u, w) = (self.ends(tour.prev(s0)).1, self.ends(tour.next(s1)).0);
            let (e, x) = (self.ends(s0).0, self.ends(s1).1);
            let gain = dist(u, e) + dist(x, w) - dist(u, w);
            if gain > EPS {
                *c = Some(Chain { s0, len, u, w, e, x, gain });
            }
        }
        // Where to look, and for what: 2-opt leaving p (bit 0) or entering
        // it (bit 1), and chain k next to a polyline found (bit 2 + k).
        let (g_out, g_in) = (dist(x_i, e_next), dist(x_prev, e_i));
        let chain = |k: usize| 4u32 << k;
        let centers = [
            (x_i, 1 | chain(0) | chain(3) | chain(4)),
            (e_i, 2 | chain(0) | chain(1) | chain(2)),
            (self.ends(tour.add(i, 1)).1, chain(1)),
            (self.ends(tour.add(i, 2)).1, chain(2)),
            (self.ends(tour.add(i, count - 1)).0, chain(3)),
            (self.ends(tour.add(i, count - 2)).0, chain(4)),
        ];
        let loop_alone = lines.closed(p);
        for (n, &(c, mut uses)) in centers.iter().enumerate() {
            if e_i == x_i && n == 0 {
                // Entered and left at the same point: look once.
                uses |= 2 | chain(1) | chain(2);
            } else if e_i == x_i && n == 1 {
                continue;
            }
            let mut radius = 0.0f32;
            if uses & 1 != 0 {
                radius = radius.max(g_out);
            }
            if uses & 2 != 0 {
                radius = radius.max(g_in);
            }
            for (k, ch) in chains.iter().enumerate() {
                match ch {
                    Some(ch) if uses & chain(k) != 0 => radius = radius.max(ch.gain),
                    _ => uses &= !chain(k),
                }
            }
            if radius <= EPS {
                continue;
            }
            self.grid.near(c, radius, self.rings, |line, q, d| {
                let j = tour.pos(line);
                let (ev, xv) = self.ends(j);
                let closed = lines.closed(line);
                // 2-opt, leaving p to the exit of the polyline at j: reverse
                // i+1..=j. A loop at j may be re-entered at the door found.
                if uses & 1 != 0 && d < g_out && j != i {
                    let e_after = self.ends(tour.next(j)).0;
                    let base = d + dist(e_next, e_after) - g_out;
                    if xv == q {
                        consider(base - dist(q, e_after), Move::Reverse { i: inx, j, enter: None });
                    } else if closed && j != inx {
                        // The loop's neighbours become x_i and the exit
                        // before it.
                        let x_before = self.ends(tour.prev(j)).1;
                        let delta = base + dist(q, x_before) - dist(x_before, ev) - dist(ev, e_after);
                        let enter = Some((line, q));
                        consider(delta, Move::Reverse { i: inx, j, enter });
                    }
                }
                // 2-opt, entering p from the entry of the polyline at j:
                // reverse j..=i-1.
                if uses & 2 != 0 && d < g_in && j != i {
                    let x_before = self.ends(tour.prev(j)).1;
                    let base = dist(x_before, x_prev) + d - g_in;
                    if ev == q {
                        consider(base - dist(x_before, q), Move::Reverse { i: j, j: ip, enter: None });
                    } else if closed && j != ip {
                        let e_after = self.ends(tour.next(j)).0;
                        let delta = base + dist(e_after, q) - dist(x_before, xv) - dist(xv, e_after);
                        let enter = Some((line, q));
                        consider(delta, Move::Reverse { i: j, j: ip, enter });
                    }
                }
                for (k, ch) in chains.iter().enumerate() {
                    let Some(ch) = ch else { continue };
                    if uses & chain(k) == 0 || d >= ch.gain || tour.gap(ch.s0, j) < ch.len {
                        continue;
                    }
                    self.chain_moves(ch, loop_alone && ch.len == 1, p, (q, line, j, ev, xv), &consider);
                }
            });
        }
        best.get()
    }

    /// Or-opt moves of `ch` next to the polyline `line` at `j` (not in the
    /// chain), found by its door at `q` (`ev`, `xv`: its entry and exit).
    /// `alone`: the chain is the single loop `p`.
    fn chain_moves(
        &self,
        ch: &Chain,
        alone: bool,
        p: usize,
        (q, line, j, ev, xv): (ScreenPoint, usize, usize, ScreenPoint, ScreenPoint),
        consider: &impl Fn(f32, Move),
    ) {
        let (lines, tour) = (self.lines, &self.tour);
        let dist = |a: ScreenPoint, b: ScreenPoint| a.distance(b);
        let Chain { s0, len, u, w, e, x, gain } = *ch;
        let s1 = tour.add(s0, len - 1);
        // The cheapest way to draw the chain from a to b: added length,
        // reversed, loop entry.
        let fit = |a: ScreenPoint, b: ScreenPoint| {
            if alone {
                let (mut hb, mut cb) = (0, f32::INFINITY);
                for dv in lines.doors(p) {
                    let dq = lines.point(dv);
                    let c = dist(a, dq) + dist(dq, b);
                    if c < cb {
                        (hb, cb) = (lines.entering(p, dv), c);
                    }
                }
                (cb, false, Some(hb))
            } else {
                let fwd = dist(a, e) + dist(x, b);
                let rev = dist(a, x) + dist(e, b);
                (fwd.min(rev), rev < fwd, None)
            }
        };
        let try_after = |t: usize| {
            if tour.gap(s0, t) < len || t == tour.prev(s0) {
                return;
            }
            let (a, b) = (self.ends(t).1, self.ends(tour.next(t)).0);
            let (c, rev, h) = fit(a, b);
            consider(c - dist(a, b) - gain, Move::Shift { s0, len, t, rev, h, enter: None });
        };
        if xv == q {
            try_after(j);
        }
        if ev == q {
            try_after(tour.prev(j));
        }
        if ev == q || xv == q || !lines.closed(line) {
            return;
        }
        // Next to a loop, re-entered at the door found: its neighbours once
        // the chain is out.
        let (jp, jn) = (tour.prev(j), tour.next(j));
        let a = if jp == s1 { u } else { self.ends(jp).1 };
        let b = if jn == s0 { w } else { self.ends(jn).0 };
        let old = dist(a, ev) + dist(ev, b) + gain;
        let enter = Some((line, q));
        if j != tour.prev(s0) {
            let (c, rev, h) = fit(q, b);
            consider(dist(a, q) + c - old, Move::Shift { s0, len, t: j, rev, h, enter });
        }
        if jp != s1 {
            let (c, rev, h) = fit(a, q);
            consider(c + dist(q, b) - old, Move::Shift { s0, len, t: jp, rev, h, enter });
        }
    }

    /// Make move `m`; returns the polylines around it (their jumps
    /// changed) and how to undo it.
    fn apply(&mut self, m: Move) -> ([usize; 10], [Option<Undo>; 2]) {
        let t = &self.tour;
        let (enter, wake) = match m {
            Move::Reverse { i, j, enter } => (enter, [t.prev(i), i, j, t.next(j), i, i, i]),
            Move::Shift { s0, len, t: at, enter, .. } => {
                let s1 = t.add(s0, len - 1);
                (enter, [t.prev(s0), s0, t.next(s0), s1, t.next(s1), at, t.next(at)])
            }
        };
        let mut lines = [usize::MAX; 10];
        for (l, k) in lines.iter_mut().zip(wake) {
            *l = t.at(k).0;
        }
        let mut undo_enter = None;
        if let Some((line, q)) = enter {
            let h = self.lines.entering_at(line, q);
            let k = t.pos(line);
            for (l, k) in lines.iter_mut().skip(7).zip([t.prev(k), k, t.next(k)]) {
                *l = t.at(k).0;
            }
            undo_enter = Some(Undo::Enter { line, h: t.at(k).1 });
            self.tour.put(k, line, h);
        }
        let undo_move = match m {
            Move::Reverse { i, j, .. } => {
                self.tour.reverse(self.lines, i, j);
                Undo::Reverse { i, j }
            }
            Move::Shift { s0, len, t, rev, h, .. } => self.tour.shift(self.lines, s0, len, t, rev, h, None),
        };
        (lines, [undo_enter, Some(undo_move)])
    }

    /// Improve until no move helps or `passes` rounds are done.
    fn run(&mut self, passes: usize) {
        let count = self.tour.count;
        for _ in 0..passes {
            let mut any = false;
            for p in 0..count {
                if get(self.idle, p) != 0 {
                    continue;
                }
                match self.best_move(p, 5) {
                    Some((_, m)) => {
                        for l in self.apply(m).0 {
                            set(self.idle, l, 0);
                        }
                        any = true;
                    }
                    None => set(self.idle, p, 1),
                }
            }
            if !any {
                break;
            }
        }
        for p in 0..count {
            set(self.idle, p, 1);
        }
    }

    /// Iterated local search: `kicks` times, swap two short runs of the
    /// tour (a double bridge, which 2-opt and or-opt cannot undo), improve
    /// around the change (2-opt and single-polyline or-opt, partners at
    /// most a ring of cells away, no move that shifts more than a quarter
    /// of a long tour), and keep the result only if the cycle got shorter.
    /// Expects every polyline idle.
    fn kick(&mut self, kicks: usize) {
        let count = self.tour.count;
        if count < 8 {
            return;
        }
        // Short enough that no reversal below is done the other way round.
        let span = KICK_SPAN.min(count / 4);
        // xorshift32, seeded by the size: the same list, the same order.
        let mut seed = 0x9E37_79B9u32 ^ count as u32;
        let mut rand = |m: usize| {
            seed ^= seed << 13;
            seed ^= seed >> 17;
            seed ^= seed << 5;
            seed as usize % m.max(1)
        };
        let dist = |a: ScreenPoint, b: ScreenPoint| a.distance(b);
        let (rings, max_work) = (self.rings, self.max_work);
        (self.rings, self.max_work) = (rings.min(1), (count / 4).max(256));
        let mut queue = Queue { items: [0; QUEUE], len: 0 };
        let mut log = [Undo::Nothing; LOG];
        for _ in 0..kicks {
            // A B C D becomes A C B D.
            let i = rand(count);
            let (lb, lc) = (1 + rand(span), 1 + rand(span));
            let (b0, b1) = (self.tour.add(i, 1), self.tour.add(i, lb));
            let (c0, c1) = (self.tour.add(b1, 1), self.tour.add(b1, lc));
            let d0 = self.tour.next(c1);
            let (xa, xb, xc) = (self.ends(i).1, self.ends(b1).1, self.ends(c1).1);
            let (eb, ec, ed) = (self.ends(b0).0, self.ends(c0).0, self.ends(d0).0);
            let mut total =
                dist(xa, ec) + dist(xc, eb) + dist(xb, ed) - dist(xa, eb) - dist(xb, ec) - dist(xc, ed);
            // Three reversals swap B and C.
            let cb = self.tour.add(i, lc);
            let mut logged = 0usize;
            for (r0, r1) in [(b0, c1), (b0, cb), (self.tour.next(cb), c1)] {
                self.tour.reverse(self.lines, r0, r1);
                set(&mut log, logged, Undo::Reverse { i: r0, j: r1 });
                logged += 1;
            }
            for k in [i, b0, cb, self.tour.next(cb), c1, d0] {
                queue.wake(self.tour.at(k).0, self.idle);
            }
            // Local search from the polylines around the change.
            while logged + 2 <= LOG {
                let Some(p) = queue.pop() else { break };
                set(self.idle, p, 1);
                if let Some((delta, m)) = self.best_move(p, 1) {
                    let (around, undo) = self.apply(m);
                    for u in undo.into_iter().flatten() {
                        set(&mut log, logged, u);
                        logged += 1;
                    }
                    total += delta;
                    for l in around {
                        queue.wake(l, self.idle);
                    }
                }
            }
            while let Some(p) = queue.pop() {
                set(self.idle, p, 1);
            }
            if total >= -EPS {
                for k in (0..logged).rev() {
                    self.tour.undo(self.lines, get(&log, k));
                }
            }
        }
        (self.rings, self.max_work) = (rings, max_work);
    }
}

/// Polylines waiting to be looked at (a stack; their idle flag is clear).
struct Queue {
    items: [usize; QUEUE],
    len: usize,
}

impl Queue {
    fn wake(&mut self, p: usize, idle: &mut [u8]) {
        if get(idle, p) != 0 && self.len < QUEUE {
            set(idle, p, 0);
            set(&mut self.items, self.len, p);
            self.len += 1;
        }
    }

    fn pop(&mut self) -> Option<usize> {
        self.len = self.len.checked_sub(1)?;
        Some(get(&self.items, self.len))
    }
}

/// Iterated local search: most polylines waiting to be looked at, most
/// changes kept for undoing, longest run of polylines a kick moves.
const QUEUE: usize = 48;
const LOG: usize = 40;
const KICK_SPAN: usize = 5;

/// A polyline and how it is drawn, in one word: `how << 32 | polyline`.
fn pack(p: usize, h: u32) -> u64 {
    (u64::from(h) << 32) | p as u64
}

/// See [`pack`].
fn unpack(w: u64) -> (usize, u32) {
    ((w & 0xFFFF_FFFF) as usize, (w >> 32) as u32)
}

/// Nearest neighbour from `start`, over the grid of doors: `seq` gets every
/// polyline once. `live` and `taken` are scratch of the list's capacity.
fn nearest_neighbour(
    lines: &Lines<'_>,
    grid: &mut Grid<'_>,
    seq: &mut [u64],
    live: &mut [u32],
    taken: &mut [u8],
    start: ScreenPoint,
) {
    let count = lines.count();
    for p in 0..count {
        set(taken, p, 0);
    }
    let m = lines.doors_into(grid.items, grid.at);
    grid.build(m, live);
    grid.revive(live);
    let (mut alive, mut built) = (m, m);
    let mut at = start;
    let mut k = 0usize;
    while k < count {
        if alive * 4 < built && built > 64 {
            // Few doors left: gather them into a grid of their own, so that
            // the search does not wade through empty cells.
            let mut w = 0usize;
            for c in 0..grid.cells.count() {
                let lo = get(grid.first, c) as usize;
                for t in lo..lo + get(live, c) as usize {
                    set(grid.items, w, get(grid.items, t));
                    set(grid.at, w, get(grid.at, t));
                    w += 1;
                }
            }
            grid.build(w, live);
            grid.revive(live);
            (alive, built) = (w, w);
        }
        let Some(best) = grid.nearest_live(at, live) else { break };
        let (p, q) = (get(grid.items, best) as usize, get(grid.at, best));
        if get(taken, p) == 0 {
            let h = lines.entering_at(p, q);
            set(seq, k, pack(p, h));
            set(taken, p, 1);
            k += 1;
            at = lines.ends(p, h).1;
            for u in lines.doors(p) {
                if grid.kill(p as u32, lines.point(u), live) {
                    alive -= 1;
                }
            }
        } else if grid.kill(p as u32, q, live) {
            alive -= 1;
        } else {
            break;
        }
    }
    // Whatever the search missed (nothing, unless the grid is broken).
    for p in 0..count {
        if k < count && get(taken, p) == 0 {
            set(seq, k, pack(p, 0));
            k += 1;
        }
    }
}

impl<P, F> DisplayStore<P, F>
where
    P: AsRef<[ScreenPoint]> + AsMut<[ScreenPoint]>,
    F: AsRef<[u8]> + AsMut<[u8]>,
{
    /// Blanked travel of the list drawn over and over (a refresh loop): as
    /// [`DisplayStore::blank_length`], but starting where the last polyline
    /// ends.
    pub fn cycle_blank_length(&self) -> f32 {
        let end = match self.polylines().last() {
            Some(p) if p.closed => p.points.first().copied(),
            Some(p) => p.points.last().copied(),
            None => None,
        };
        end.map_or(0.0, |e| self.blank_length(e))
    }

    /// Order the polylines to shorten blanked travel, for a refresh loop
    /// (the frame is drawn over and over, so the jump from the last polyline
    /// back to the first counts).
    ///
    /// Nearest neighbour from `cfg.start` (on a uniform grid of the
    /// polylines' doors: the ends of an open polyline, which may be drawn
    /// either way, and every vertex of a closed loop, which may be entered
    /// anywhere) builds a cycle. A local search then improves it, for at
    /// most `cfg.passes` rounds, with 2-opt moves and or-opt moves of chains
    /// of one to three polylines (either way round) among polylines whose
    /// doors are at most `cfg.window` grid cells apart; a closed loop is
    /// re-entered where it best serves both its neighbours, also as part of
    /// a move. An iterated local search follows: double-bridge kicks
    /// (`cfg.kicks` per 100 polylines, at least `cfg.min_kicks`), each
    /// repaired by the local search and kept only if the cycle got shorter.
    /// The cycle is finally cut where that makes the path from `cfg.start`
    /// shortest; should that path be longer than nearest neighbour's (rare:
    /// small lists), nearest neighbour's order is kept. The list is
    /// rewritten in the new order (closed loops rotated to start at their
    /// entry vertex). Deterministic; fixed memory (the scratch); a scratch
    /// smaller than the list's capacity leaves the order as it is.
    pub fn order<U, W, Q, G>(
        &mut self,
        scratch: &mut ScratchStore<U, W, Q, G>,
        cfg: &OrderConfig,
    ) -> OrderStats
    where
        U: AsMut<[u32]>,
        W: AsMut<[u64]>,
        Q: AsMut<[ScreenPoint]>,
        G: AsMut<[u8]>,
    {
        let before = self.blank_length(cfg.start);
        let cycle_before = self.cycle_blank_length();
        let mut stats = OrderStats {
            blank_before: before,
            blank_nearest: before,
            blank_after: before,
            cycle_before,
            cycle_nearest: cycle_before,
            cycle_after: cycle_before,
        };
        let n = self.len;
        let Some(Parts { a: starts, b: pos, c: items, d: first, edges: seq, back: at, back_flags: idle }) =
            scratch.parts(self.capacity()).filter(|_| n > 0)
        else {
            return stats;
        };
        let points = self.points.as_ref().get(..n).unwrap_or(&[]);
        let flags = self.flags.as_ref().get(..n).unwrap_or(&[]);
        let mut count = 0usize;
        for i in 0..n {
            if get(flags, i) & START != 0 || i == 0 {
                set(starts, count, i as u32);
                count += 1;
            }
        }
        let lines = Lines { points, flags, starts: starts.get(..count).unwrap_or(&[]), n };
        // Open travel from the start, drawing the cycle from position `k0`
        // forwards (or backwards, every polyline the other way round).
        let path = |seq: &[u64], k0: usize, backwards: bool| {
            let mut t = 0.0;
            let mut here = cfg.start;
            for r in 0..count {
                let (p, h) =
                    unpack(get(seq, if backwards { (k0 + count - r) % count } else { (k0 + r) % count }));
                let (e, x) = lines.ends(p, if backwards { lines.flip(p, h) } else { h });
                t += here.distance(e);
                here = x;
            }
            t
        };
        let mut grid = Grid {
            items,
            at,
            first,
            m: 0,
            cells: Cells { gx: 1, gy: 1, x0: 0.0, y0: 0.0, cw: 1.0, ch: 1.0 },
        };
        nearest_neighbour(&lines, &mut grid, seq, pos, idle, cfg.start);
        stats.blank_nearest = path(seq, 0, false);

        // Local search over the cycle, on a grid of all the doors.
        for p in 0..count {
            set(idle, p, 0);
        }
        let m = lines.doors_into(grid.items, grid.at);
        grid.build(m, pos);
        for k in 0..count {
            set(pos, unpack(get(seq, k)).0, k as u32);
        }
        let mut search = Search {
            lines: &lines,
            grid: &grid,
            tour: Tour { seq, pos, count },
            idle,
            rings: cfg.window,
            max_work: count,
        };
        stats.cycle_nearest = search.cycle();
        search.run(cfg.passes);
        search.kick((count.saturating_mul(cfg.kicks) / 100).max(cfg.min_kicks));

        // Cut the cycle where the path from the start is shortest.
        let mut cut = (0usize, false, f32::INFINITY);
        for k in 0..count {
            let (x, e) = (search.ends(k).1, search.ends(search.tour.next(k)).0);
            let jump = x.distance(e);
            for (c, back) in [(cfg.start.distance(e) - jump, false), (cfg.start.distance(x) - jump, true)] {
                if c < cut.2 {
                    cut = (if back { k } else { search.tour.next(k) }, back, c);
                }
            }
        }
        let Search { tour: Tour { seq, pos, .. }, idle, .. } = search;
        let (mut k0, mut backwards) = (cut.0, cut.1);
        if path(seq, k0, backwards) > stats.blank_nearest {
            nearest_neighbour(&lines, &mut grid, seq, pos, idle, cfg.start);
            (k0, backwards) = (0, false);
        }

        // Rewrite the list in the new order.
        let Grid { at: back, .. } = grid;
        let mut len = 0usize;
        for r in 0..count {
            let k = if backwards { (k0 + count - r) % count } else { (k0 + r) % count };
            let (p, h) = unpack(get(seq, k));
            let h = if backwards { lines.flip(p, h) } else { h };
            let (s, e) = lines.range(p);
            let f = get(flags, s);
            let m = e - s;
            for r in 0..m {
                let src = if f & CLOSED != 0 {
                    s + (r + (h & !REVERSED) as usize) % m
                } else if h & REVERSED != 0 {
                    e - 1 - r
                } else {
                    s + r
                };
                set(back, len, get(points, src));
                set(idle, len, if r == 0 { f | START } else { 0 });
                len += 1;
            }
        }
        let (pts, fl) = (self.points.as_mut(), self.flags.as_mut());
        for i in 0..len.min(n) {
            set(pts, i, get(back, i));
            set(fl, i, get(idle, i));
        }
        stats.blank_after = self.blank_length(cfg.start);
        stats.cycle_after = self.cycle_blank_length();
        stats
    }
}
