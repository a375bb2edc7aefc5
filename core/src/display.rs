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
//! travel, the paper's "vector ordering problem": nearest neighbour from the
//! park position (open polylines may be reversed, closed loops entered at
//! their nearest vertex), then a bounded 2-opt.
//!
//! Everything runs in fixed memory: the list's own storage plus a
//! [`Scratch`] of the same capacity, `O(n log n)` time for culling and
//! stitching (sorting, in place).

use crate::command::Command;
use crate::screen::ScreenPoint;

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

impl<U, W, P, F> ScratchStore<U, W, P, F>
where
    U: AsMut<[u32]>,
    W: AsMut<[u64]>,
    P: AsMut<[ScreenPoint]>,
    F: AsMut<[u8]>,
{
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
    /// 2-opt: largest span of polylines one move may reverse.
    pub window: usize,
    /// 2-opt: most passes over the sequence.
    pub passes: usize,
}

impl Default for OrderConfig {
    fn default() -> Self {
        Self { start: ScreenPoint::new(0.0, 0.0), window: 64, passes: 4 }
    }
}

/// Blanked travel of an ordering, and what 2-opt gained.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct OrderStats {
    /// Blanked travel (DAC units) in the order the list had before.
    pub blank_before: f32,
    /// After nearest neighbour.
    pub blank_nearest: f32,
    /// After 2-opt.
    pub blank_after: f32,
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
        let ScratchStore { a, b, c, d, edges, back, back_flags } = scratch;
        let (vid, order, deg, adj, edges, back, back_flags) = (
            a.as_mut(),
            b.as_mut(),
            c.as_mut(),
            d.as_mut(),
            edges.as_mut(),
            back.as_mut(),
            back_flags.as_mut(),
        );
        let cap = self.capacity();
        if [vid.len(), order.len(), deg.len(), adj.len(), edges.len(), back.len(), back_flags.len()]
            .iter()
            .any(|&l| l < cap)
            || n == 0
        {
            return stats;
        }
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

impl<P, F> DisplayStore<P, F>
where
    P: AsRef<[ScreenPoint]> + AsMut<[ScreenPoint]>,
    F: AsRef<[u8]> + AsMut<[u8]>,
{
    /// Order the polylines to shorten blanked travel: nearest neighbour from
    /// `cfg.start` (an open polyline may be drawn backwards, a closed loop is
    /// entered at its vertex nearest the beam), then 2-opt moves that
    /// reverse spans of at most `cfg.window` polylines, for at most
    /// `cfg.passes` passes. The list is rewritten in the new order (closed
    /// loops rotated to start at their entry vertex). A scratch smaller than
    /// the list's capacity leaves the order as it is.
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
        let mut stats = OrderStats { blank_before: before, blank_nearest: before, blank_after: before };
        let ScratchStore { a, b, c, d, back, back_flags, .. } = scratch;
        let (starts, taken, seq, how, back, back_flags) =
            (a.as_mut(), b.as_mut(), c.as_mut(), d.as_mut(), back.as_mut(), back_flags.as_mut());
        let cap = self.capacity();
        let n = self.len;
        if [starts.len(), taken.len(), seq.len(), how.len(), back.len(), back_flags.len()]
            .iter()
            .any(|&l| l < cap)
            || n == 0
        {
            return stats;
        }
        let points = self.points.as_ref();
        let flags = self.flags.as_ref();
        let mut count = 0usize;
        for i in 0..n {
            if get(flags, i) & START != 0 || i == 0 {
                set(starts, count, i as u32);
                set(taken, count, 0);
                count += 1;
            }
        }
        let range = |p: usize| {
            let s = get(starts, p) as usize;
            let e = if p + 1 < count { get(starts, p + 1) as usize } else { n };
            (s, e.max(s + 1))
        };
        let closed = |p: usize| get(flags, range(p).0) & CLOSED != 0;
        // Entry and exit points of polyline `p` drawn as `h`.
        let ends = |p: usize, h: u32| -> (ScreenPoint, ScreenPoint) {
            let (s, e) = range(p);
            if closed(p) {
                let v = get(points, s + (h & !REVERSED) as usize);
                (v, v)
            } else if h & REVERSED != 0 {
                (get(points, e - 1), get(points, s))
            } else {
                (get(points, s), get(points, e - 1))
            }
        };
        let d2 = |a: ScreenPoint, b: ScreenPoint| {
            let (dx, dy) = (a.x - b.x, a.y - b.y);
            dx * dx + dy * dy
        };

        // Nearest neighbour.
        let mut at = cfg.start;
        for k in 0..count {
            let mut best: Option<(usize, u32, f32)> = None;
            for p in 0..count {
                if get(taken, p) != 0 {
                    continue;
                }
                let (s, e) = range(p);
                if closed(p) {
                    for v in s..e {
                        let dd = d2(at, get(points, v));
                        if best.is_none_or(|(_, _, b)| dd < b) {
                            best = Some((p, (v - s) as u32, dd));
                        }
                    }
                } else {
                    for h in [0, REVERSED] {
                        let dd = d2(at, ends(p, h).0);
                        if best.is_none_or(|(_, _, b)| dd < b) {
                            best = Some((p, h, dd));
                        }
                    }
                }
            }
            let Some((p, h, _)) = best else { break };
            set(taken, p, 1);
            set(seq, k, p as u32);
            set(how, k, h);
            at = ends(p, h).1;
        }
        let travel = |seq: &[u32], how: &[u32]| {
            let mut at = cfg.start;
            let mut t = 0.0;
            for k in 0..count {
                let (en, ex) = ends(get(seq, k) as usize, get(how, k));
                t += at.distance(en);
                at = ex;
            }
            t
        };
        stats.blank_nearest = travel(seq, how);

        // Bounded 2-opt: reverse spans i..=j when that shortens the jumps at
        // both ends of the span.
        let dist = |a: ScreenPoint, b: ScreenPoint| a.distance(b);
        for _ in 0..cfg.passes {
            let mut improved = false;
            for i in 0..count {
                let before_i =
                    if i == 0 { cfg.start } else { ends(get(seq, i - 1) as usize, get(how, i - 1)).1 };
                let entry_i = ends(get(seq, i) as usize, get(how, i)).0;
                for j in i + 1..count.min(i + 1 + cfg.window) {
                    let exit_j = ends(get(seq, j) as usize, get(how, j)).1;
                    let after = (j + 1 < count).then(|| ends(get(seq, j + 1) as usize, get(how, j + 1)).0);
                    // Reversed, the span enters at j's exit and leaves at i's entry.
                    let old = dist(before_i, entry_i) + after.map_or(0.0, |a| dist(exit_j, a));
                    let new = dist(before_i, exit_j) + after.map_or(0.0, |a| dist(entry_i, a));
                    if new + 1e-3 < old {
                        if let (Some(s), Some(h)) = (seq.get_mut(i..=j), how.get_mut(i..=j)) {
                            s.reverse();
                            h.reverse();
                        }
                        for k in i..=j {
                            let p = get(seq, k) as usize;
                            if !closed(p) {
                                set(how, k, get(how, k) ^ REVERSED);
                            }
                        }
                        improved = true;
                        break;
                    }
                }
            }
            if !improved {
                break;
            }
        }
        // Or-opt: move single polylines (either way round) to where they
        // cost least, within the window.
        for _ in 0..cfg.passes {
            let mut improved = false;
            let mut i = 0;
            while i < count {
                let at = |k: usize| ends(get(seq, k) as usize, get(how, k));
                let prev = if i == 0 { cfg.start } else { at(i - 1).1 };
                let next = (i + 1 < count).then(|| at(i + 1).0);
                let (e, x) = at(i);
                let gain =
                    dist(prev, e) + next.map_or(0.0, |n| dist(x, n)) - next.map_or(0.0, |n| dist(prev, n));
                let p = get(seq, i) as usize;
                let h = get(how, i);
                let lo = i.saturating_sub(cfg.window);
                let hi = (i + cfg.window).min(count);
                // Insert after position j (j = usize::MAX: at the front).
                let mut best: Option<(usize, u32, f32)> = None;
                for j in lo..hi {
                    if j == i || j + 1 == i {
                        continue;
                    }
                    let a = at(j).1;
                    let b = (j + 1 < count).then(|| at(j + 1).0).filter(|_| j + 1 != i);
                    let b = if j + 1 == i { (i + 1 < count).then(|| at(i + 1).0) } else { b };
                    for hh in [h, h ^ REVERSED] {
                        if hh != h && closed(p) {
                            continue;
                        }
                        let (e2, x2) = ends(p, hh);
                        let cost =
                            dist(a, e2) + b.map_or(0.0, |b| dist(x2, b)) - b.map_or(0.0, |b| dist(a, b));
                        if cost + 1e-3 < gain && best.is_none_or(|(_, _, c)| cost < c) {
                            best = Some((j, hh, cost));
                        }
                    }
                }
                if let Some((j, hh, _)) = best {
                    let (sq, hw) = (get(seq, i), hh);
                    if j > i {
                        for k in i..j {
                            set(seq, k, get(seq, k + 1));
                            set(how, k, get(how, k + 1));
                        }
                        set(seq, j, sq);
                        set(how, j, hw);
                    } else {
                        for k in (j + 1..i).rev() {
                            set(seq, k + 1, get(seq, k));
                            set(how, k + 1, get(how, k));
                        }
                        set(seq, j + 1, sq);
                        set(how, j + 1, hw);
                    }
                    improved = true;
                }
                i += 1;
            }
            if !improved {
                break;
            }
        }

        // Enter each closed loop at the vertex that best serves both its
        // neighbours (nearest neighbour only looked back).
        for _ in 0..2 {
            for k in 0..count {
                let p = get(seq, k) as usize;
                if !closed(p) {
                    continue;
                }
                let prev = if k == 0 { cfg.start } else { ends(get(seq, k - 1) as usize, get(how, k - 1)).1 };
                let next = (k + 1 < count).then(|| ends(get(seq, k + 1) as usize, get(how, k + 1)).0);
                let (s, e) = range(p);
                let mut best = (get(how, k), f32::INFINITY);
                for v in s..e {
                    let q = get(points, v);
                    let c = dist(prev, q) + next.map_or(0.0, |nx| dist(q, nx));
                    if c < best.1 {
                        best = ((v - s) as u32, c);
                    }
                }
                set(how, k, best.0);
            }
        }
        stats.blank_after = travel(seq, how);

        // Rewrite the list in the new order.
        let mut len = 0usize;
        for k in 0..count {
            let p = get(seq, k) as usize;
            let h = get(how, k);
            let (s, e) = range(p);
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
                set(back_flags, len, if r == 0 { f | START } else { 0 });
                len += 1;
            }
        }
        let (pts, fl) = (self.points.as_mut(), self.flags.as_mut());
        for i in 0..len.min(n) {
            set(pts, i, get(back, i));
            set(fl, i, get(back_flags, i));
        }
        stats
    }
}
