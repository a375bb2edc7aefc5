//! The order pass: loops spliced where they cross, the polylines that
//! start a chain toured (nearest neighbour, then 2-opt and or-opt by a
//! [`Metric`], among screen neighbours where the view is still) and drawn.

use super::ChainStats;
use super::index::{DRAWN, Index, NONE, Words, dist2f, length};
use super::merge::Walk;
use super::store::{Geometry, Packed};
use crate::command::Point3;
use crate::fastmath::sqrt;
use crate::view::ViewTransform;

/// Steps a 2-opt move reverses at most where the search is windowed (the
/// tour is nearest-neighbour already: the gains are local).
pub(super) const WINDOW: usize = 48;
/// Closed loops drawn inside one another at most ([`Walk::emit_spliced`]):
/// a frame each on the stack, 24 bytes. Sixteen left one of hydrogen
/// 32^3's loops unspliced (a fifth polyline, 2.96% blank travel for
/// 2.30%) once its pieces came in the slab's order: how deep the splices
/// nest follows the order the pieces come in.
pub(super) const SPLICE_DEPTH: usize = 32;

/// The order pass: the loops spliced, the rest toured and drawn (see the
/// [module docs](super)).
pub(super) fn order(
    x: &mut Index<'_, '_>,
    walk: &mut Walk,
    dst: &mut Geometry<'_>,
    start: Packed,
    metric: Metric,
    stats: &mut ChainStats,
) {
    // The tour: nearest neighbour, then 2-opt, then each loop entered
    // at its best vertex; drawn last.
    mark_spliced(x);
    let mut tour = Tour { base: x.tour_base(), len: 0, metric };
    let mut scan = 0;
    let mut cur = start;
    for _ in 0..x.frags {
        let Some(end) = x.nearest(cur).or_else(|| x.first_from(&mut scan)) else { break };
        let f = x.frag_of(end);
        x.take(f);
        tour.push(x, f, end);
        cur = x.point(exit(x, f, end));
        x.poll.tick(32);
    }
    tour.improve(x, start);
    // Drawn in the tour's order; a loop that passes exactly
    // through a point being drawn is drawn there, and the beam goes
    // on from where it came back (no jump to it, none from it).
    x.relink(true);
    for k in 0..tour.len {
        let (end, _) = tour.get(&x.w, k);
        let f = x.frag_of(end);
        if !x.emitted(f) {
            walk.emit_spliced(x, dst, f, end, stats);
        }
        x.poll.tick(32);
    }
    // A loop the tour left to a splice that this drawing order
    // reached too deep (or not at all): drawn after the tour.
    for f in 0..x.frags {
        if !x.emitted(f) {
            let end = x.span(f).0;
            walk.emit_spliced(x, dst, f, end, stats);
        }
    }
}

/// The point where the beam leaves fragment `f` entered at point `end`.
pub(super) fn exit(x: &Index<'_, '_>, f: usize, end: usize) -> usize {
    let (from, to) = x.span(f);
    if x.is_loop(f) {
        end
    } else if end == from {
        to - 1
    } else {
        from
    }
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
    pub(super) fn at(view: &ViewTransform, shift: u8, q: Packed) -> [f32; 2] {
        let k = f32::from_bits((127 - u32::from(shift.min(12))) << 23);
        let s = view.project_raw(Point3::new(f32::from(q[0]) * k, f32::from(q[1]) * k, f32::from(q[2]) * k));
        if s.x.is_finite() && s.y.is_finite() { [s.x, s.y] } else { [1e9, 1e9] }
    }

    /// The squared length of the jump from `a` to `b`.
    pub(super) fn d2(&self, a: Packed, b: Packed) -> f32 {
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
    pub(super) fn d(&self, a: Packed, b: Packed) -> f32 {
        match self {
            Self::Space => length(a, b),
            Self::Screen { .. } => sqrt(self.d2(a, b)),
        }
    }

    /// The length of the jump from where the beam starts (`start` in
    /// space) to `b`.
    pub(super) fn first_jump(&self, start: Packed, b: Packed) -> f32 {
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

/// The order pass's tour, in [`Words::tour_step`] words a step after the
/// index's links: the point a fragment is entered at, the point it is left
/// at (the same for a loop or a dot) and the length of the jump to the next
/// step (an `f32`'s bits, one wide word or two narrow ones, kept by
/// [`Tour::two_opt`]).
pub(super) struct Tour {
    pub(super) base: usize,
    pub(super) len: usize,
    pub(super) metric: Metric,
}

/// Jumps the order pass's local search measures at most, all moves of
/// all passes: some 60 instructions each on the MCU, 1M is about 0.4 s at
/// 168 MHz, spent only on pictures of over a thousand polylines (a full
/// search of `n` polylines costs about `n^2` a pass).
pub(super) const SEARCH_BUDGET: u64 = 1 << 20;

impl Tour {
    pub(super) fn push(&mut self, x: &mut Index<'_, '_>, f: usize, end: usize) {
        let out = exit(x, f, end);
        self.set(&mut x.w, self.len, end, out);
        self.len += 1;
    }

    /// Step `k`'s entry and exit point indices.
    pub(super) fn get(&self, w: &Words<'_>, k: usize) -> (usize, usize) {
        let at = self.base + w.tour_step() * k;
        (w.get(at) as usize, w.get(at + 1) as usize)
    }

    pub(super) fn set(&self, w: &mut Words<'_>, k: usize, entry: usize, exit: usize) {
        let at = self.base + w.tour_step() * k;
        w.set(at, entry as u32);
        w.set(at + 1, exit as u32);
    }

    pub(super) fn jump(&self, w: &Words<'_>, k: usize) -> f32 {
        f32::from_bits(w.get32(self.base + w.tour_step() * k + 2))
    }

    pub(super) fn set_jump(&self, w: &mut Words<'_>, k: usize, v: f32) {
        w.set32(self.base + w.tour_step() * k + 2, v.to_bits());
    }

    /// Where step `k` is entered and left.
    pub(super) fn ends(&self, x: &Index<'_, '_>, k: usize) -> (Packed, Packed) {
        let (entry, exit) = self.get(&x.w, k);
        (x.point(entry), x.point(exit))
    }

    /// Measure every jump, kept with the steps.
    pub(super) fn measure_all(&self, x: &mut Index<'_, '_>) {
        for k in 0..self.len.saturating_sub(1) {
            self.measure(x, k);
            x.poll.tick(1);
        }
    }

    /// Measure the jump from step `k` to step `k + 1`.
    pub(super) fn measure(&self, x: &mut Index<'_, '_>, k: usize) {
        let jump = self.metric.d(self.ends(x, k).1, self.ends(x, k + 1).0);
        self.set_jump(&mut x.w, k, jump);
    }

    /// Improve the nearest-neighbour tour: 2-opt and or-opt in turn while
    /// either finds a move (and the budget lasts), then each loop entered
    /// at its best vertex.
    pub(super) fn improve(&self, x: &mut Index<'_, '_>, start: Packed) {
        if let Some(mut near) = Near::build(x, self) {
            // The tour made again by nearest neighbour on the screen (the
            // one in space leaves ends far apart on the screen that are near
            // in depth), then moves among screen neighbours: every step's,
            // however long the tour, until a pass finds none; the loops'
            // entries chosen again after each pass (and the neighbours found
            // again).
            let mut budget = SEARCH_BUDGET;
            if self.nearest_on_screen(x, &near, &mut budget) {
                self.measure_all(x);
                match Near::build(x, self) {
                    Some(n) => near = n,
                    None => return self.best_entries(x, start),
                }
            }
            for _ in 0..16 {
                let a = self.two_opt(x, Some(&near), 0, &mut budget);
                let b = self.or_opt(x, Some(&near), 0, &mut budget);
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
            let a = self.two_opt(x, None, window, &mut budget);
            let b = self.or_opt(x, None, window, &mut budget);
            if !(a || b) || budget == 0 {
                break;
            }
        }
        self.best_entries(x, start);
    }

    /// Or-opt: a run of up to [`OR_CHAIN`] steps taken out and put back,
    /// either way round, where that shortens the tour most; a pass over
    /// every run. The places tried: with `near`, just after a step that
    /// leaves, or just before one that enters, near the run's ends on the
    /// screen (within the gain of taking it out); without, the `window`
    /// places on either side in the tour (runs of one step). Returns
    /// whether it moved one.
    pub(super) fn or_opt(
        &self,
        x: &mut Index<'_, '_>,
        near: Option<&Near>,
        window: usize,
        budget: &mut u64,
    ) -> bool {
        let n = self.len;
        if n < 4 {
            return false;
        }
        let m = self.metric;
        let chain = if near.is_some() { OR_CHAIN } else { 1 };
        let mut moved = false;
        for (len, i) in (1..=chain).flat_map(|len| (1..n.saturating_sub(len - 1)).map(move |i| (len, i))) {
            x.poll.tick(8);
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
            // Between steps k and k + 1 (k + 1 == n: after the last).
            let mut best: Option<(f32, usize, bool)> = None;
            let mut consider = |x: &Index<'_, '_>, k: usize, budget: &mut u64| {
                if (i - 1..=last).contains(&k) || k >= n {
                    return;
                }
                *budget = budget.saturating_sub(1);
                x.poll.tick(8);
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
            };
            match near {
                Some(near) => {
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
                }
                None => {
                    let lo = i.saturating_sub(window).max(1) - 1;
                    for k in lo..=(i + window).min(n - 1) {
                        consider(x, k, budget);
                    }
                }
            }
            if let Some((_, k, flip)) = best {
                let dest = self.relocate(x, i, len, k, flip);
                // The steps shifted (and placed again) count too.
                *budget = budget.saturating_sub(i.abs_diff(dest) as u64 + len as u64);
                if let Some(near) = near {
                    near.place(x, self, i.min(dest), last.max(dest + len - 1));
                }
                moved = true;
            }
        }
        moved
    }

    /// The tour made again on the screen: from the start, the step with the
    /// end nearest the last exit next, entered there; the nearest found in
    /// rings of cells around it, the steps already placed taken out of the
    /// lists as they are passed. Returns false when the budget runs out
    /// first: the tour is then a permutation still (part made again), its
    /// jumps not measured, and the screen grid's lists are spent.
    fn nearest_on_screen(&self, x: &mut Index<'_, '_>, near: &Near, budget: &mut u64) -> bool {
        let Metric::Screen { view, shift, park } = self.metric else { return false };
        let n = self.len;
        let [gx, gy] = near.cells;
        let mut here = park;
        for k in 0..n {
            x.poll.tick(32);
            let [cx, cy] = near.coords(here);
            let mut best: Option<(f32, usize)> = None;
            let side = 1.0 / near.scale;
            for r in 0..gx.max(gy) {
                // Anything in ring r is at least (r - 1) cells away.
                if best.is_some_and(|(d, _)| d <= (r as f32 - 1.0).max(0.0) * side) {
                    break;
                }
                let (x0, x1) = (cx.saturating_sub(r), (cx + r).min(gx - 1));
                let (y0, y1) = (cy.saturating_sub(r), (cy + r).min(gy - 1));
                for yy in y0..=y1 {
                    let edge = yy + r == cy || yy == cy + r;
                    let mut xx = x0;
                    while xx <= x1 {
                        *budget = budget.saturating_sub(1);
                        x.poll.tick(1);
                        let c = near.heads + xx + gx * yy;
                        // Walk the cell's list, unlinking the placed ends.
                        let (mut prev, mut at) = (NONE, x.w.get(c));
                        while at != NONE {
                            *budget = budget.saturating_sub(1);
                            x.poll.tick(4);
                            let p = at as usize;
                            let next = x.w.get(x.links + p);
                            if near.pos(x, p) < k {
                                if prev == NONE {
                                    x.w.set(c, next);
                                } else {
                                    x.w.set(x.links + prev as usize, next);
                                }
                            } else {
                                let s = Metric::at(&view, shift, x.point(p));
                                let d = sqrt(
                                    (s[0] - here[0]) * (s[0] - here[0]) + (s[1] - here[1]) * (s[1] - here[1]),
                                );
                                if best.is_none_or(|(b, _)| d < b) {
                                    best = Some((d, p));
                                }
                                prev = at;
                            }
                            at = next;
                        }
                        // Inside the ring's square only its two side cells.
                        xx = if edge || r == 0 || xx != x0 { xx + 1 } else { x1.max(xx + 1) };
                    }
                }
            }
            if *budget == 0 {
                return false;
            }
            let Some((_, p)) = best else { return false };
            let j = near.pos(x, p);
            let (ek, ok) = self.get(&x.w, k);
            let (ej, oj) = self.get(&x.w, j);
            // Step j comes to k, entered at p; step k goes where j was.
            let (e, o) = if p == ej { (ej, oj) } else { (oj, ej) };
            self.set(&mut x.w, k, e, o);
            self.set(&mut x.w, j, ek, ok);
            near.place(x, self, k, k);
            near.place(x, self, j, j);
            here = Metric::at(&view, shift, x.point(o));
        }
        true
    }

    /// Move the `len` steps from `i` (at most [`OR_CHAIN`]) to just after
    /// step `k` (counted before the move, outside the run), drawn the
    /// other way round if `flip`, and measure the jumps again. Returns
    /// where the run starts now.
    pub(super) fn relocate(
        &self,
        x: &mut Index<'_, '_>,
        i: usize,
        len: usize,
        k: usize,
        flip: bool,
    ) -> usize {
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

    /// 2-opt, one pass: for each step, a run after it reversed (each step
    /// drawn the other way) where that shortens the two jumps at the run's
    /// ends; first improvement. The runs tried: with `near`, those ending at
    /// a step whose exit is near this step's exit on the screen (closer
    /// than the jump it leaves by), and those starting at a step whose
    /// entry is near the next step's entry; without, the runs of up to
    /// `window` steps. Returns whether it reversed one.
    ///
    /// The jumps' lengths are kept with the steps (and mended after a
    /// reversal), and a candidate whose first new jump alone is surely no
    /// shorter than the two old ones is turned down without a square root:
    /// the same moves as measuring every jump afresh, at a fraction of the
    /// cost.
    pub(super) fn two_opt(
        &self,
        x: &mut Index<'_, '_>,
        near: Option<&Near>,
        window: usize,
        budget: &mut u64,
    ) -> bool {
        let n = self.len;
        if n < 3 {
            return false;
        }
        self.measure_all(x);
        let m = self.metric;
        // Whether the jumps `a -> b` and `c -> d` (none past the last step)
        // are longer than `a -> c` and `b -> d`: reversing the run between
        // them draws the latter.
        let better = |old: f32, a: Packed, c: Packed, bd: Option<(Packed, Packed)>| {
            // `length` is within 1e-6 of the true root: a first new jump
            // this long is no shorter than `old`, nor is the new pair.
            if m.d2(a, c) * 0.999_99 >= old * old {
                return false;
            }
            m.d(a, c) + bd.map_or(0.0, |(b, d)| m.d(b, d)) + 1e-3 < old
        };
        let mut any = false;
        for i in 0..n - 1 {
            x.poll.tick(8);
            if *budget == 0 {
                break;
            }
            // The jump out of step i, replaced by one to a later step j's
            // exit: reverse i + 1 ..= j.
            let out_i = self.ends(x, i).1;
            let in_i1 = self.ends(x, i + 1).0;
            let before = self.jump(&x.w, i);
            let try_j = |x: &Index<'_, '_>, j: usize| {
                let old = before + if j + 1 < n { self.jump(&x.w, j) } else { 0.0 };
                let after = (j + 1 < n).then(|| (in_i1, self.ends(x, j + 1).0));
                better(old, out_i, self.ends(x, j).1, after)
            };
            let mut found = match near {
                Some(near) => {
                    let mut found = None;
                    near.each_near(
                        x,
                        m,
                        out_i,
                        before,
                        |x, c, budget| {
                            let j = near.pos(x, c);
                            if found.is_some() || j < i + 2 || self.get(&x.w, j).1 != c {
                                return;
                            }
                            *budget = budget.saturating_sub(1);
                            x.poll.tick(8);
                            if try_j(x, j) {
                                found = Some(j);
                            }
                        },
                        budget,
                    );
                    found
                }
                None => (i + 2..n.min(i + 2 + window)).find(|&j| {
                    *budget = budget.saturating_sub(1);
                    x.poll.tick(8);
                    try_j(x, j)
                }),
            };
            if let Some(j) = found {
                self.reverse_measured(x, near, i + 1, j, budget);
                any = true;
                continue;
            }
            // With neighbours: the jump into step i + 1, replaced by one
            // from an earlier step l's entry: reverse l ..= i. (In a window
            // that move is the one above from step l - 1.)
            let (Some(near), true) = (near, i > 0) else { continue };
            let (e1, _) = self.get(&x.w, i + 1);
            near.each_near(
                x,
                m,
                x.point(e1),
                before,
                |x, c, budget| {
                    let l = near.pos(x, c);
                    if found.is_some() || l == 0 || l >= i || self.get(&x.w, l).0 != c {
                        return;
                    }
                    *budget = budget.saturating_sub(1);
                    x.poll.tick(8);
                    let old = self.jump(&x.w, l - 1) + before;
                    let out_l1 = self.ends(x, l - 1).1;
                    if better(old, out_l1, out_i, Some((x.point(c), x.point(e1)))) {
                        found = Some(l);
                    }
                },
                budget,
            );
            if let Some(l) = found {
                self.reverse_measured(x, Some(near), l, i, budget);
                any = true;
            }
        }
        any
    }

    /// Reverse steps `a..=b` (costing the budget their count), measure the
    /// two jumps at their ends again, and tell `near` where they are now.
    fn reverse_measured(
        &self,
        x: &mut Index<'_, '_>,
        near: Option<&Near>,
        a: usize,
        b: usize,
        budget: &mut u64,
    ) {
        self.reverse(x, a, b);
        *budget = budget.saturating_sub((b - a + 1) as u64);
        if a > 0 {
            self.measure(x, a - 1);
        }
        if b + 1 < self.len {
            self.measure(x, b);
        }
        if let Some(near) = near {
            near.place(x, self, a, b);
        }
    }

    /// Reverse steps `a..=b`, each drawn the other way (entry and exit
    /// swapped), and the jumps between them (a length reads the same both
    /// ways).
    pub(super) fn reverse(&self, x: &mut Index<'_, '_>, a: usize, b: usize) {
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
    pub(super) fn best_entries(&self, x: &mut Index<'_, '_>, start: Packed) {
        let m = self.metric;
        let mut prev: Option<Packed> = None;
        for k in 0..self.len {
            let (end, _) = self.get(&x.w, k);
            let f = x.frag_of(end);
            x.poll.tick(2);
            if x.is_loop(f) {
                let next = if k + 1 < self.len { Some(self.ends(x, k + 1).0) } else { None };
                let into = |v: Packed| prev.map_or_else(|| m.first_jump(start, v), |p| m.d(p, v));
                let cost = |v: Packed| into(v) + next.map_or(0.0, |n| m.d(v, n));
                let (from, to) = x.span(f);
                let mut best = (cost(x.point(end)), end);
                for i in from..to {
                    x.poll.tick(2);
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
                if best.1 != end {
                    self.set(&mut x.w, k, best.1, best.1);
                    // The jumps into and out of it, kept with the steps.
                    if k > 0 {
                        self.measure(x, k - 1);
                    }
                    if k + 1 < self.len {
                        self.measure(x, k);
                    }
                }
            }
            prev = Some(self.ends(x, k).1);
        }
    }
}

/// Steps an or-opt move takes along at most (among screen neighbours).
pub(super) const OR_CHAIN: usize = 3;

/// Rings of cells [`Near::each_near`] searches at most around a point.
pub(super) const NEAR_RINGS: usize = 3;

/// The order pass's neighbours on the screen: the ends of the tour's steps
/// in a grid of cells on the metric's screen, and each step's position in
/// the tour by fragment. In the index's cell heads and links, idle from the
/// tour's nearest-neighbour search until the splices' [`Index::relink`]
/// (or, where the grid is small, in the words past the drawn bits): the
/// positions, the grid's heads after them, and a link a point.
pub(super) struct Near {
    pub(super) pos: usize,
    pub(super) heads: usize,
    pub(super) cells: [usize; 2],
    pub(super) lo: [f32; 2],
    /// Cells per screen unit.
    pub(super) scale: f32,
}

impl Near {
    /// The neighbours of `tour`'s steps, for a [`Metric::Screen`] tour
    /// with the room; `None` otherwise (the windowed search then serves).
    pub(super) fn build(x: &mut Index<'_, '_>, tour: &Tour) -> Option<Near> {
        let Metric::Screen { view, shift, .. } = tour.metric else { return None };
        let n = tour.len;
        if n < 8 || x.buckets != 0 {
            return None;
        }
        // The positions and the heads: in the grid's heads, or else in the
        // words past the drawn bits.
        let grid: usize = x.n.iter().map(|&c| c as usize).product();
        let free = x.past_dead();
        let spare = x.w.len().saturating_sub(free);
        let (pos, room) = if grid >= spare {
            (x.frags, grid.checked_sub(x.frags + 16)? + 16)
        } else {
            (free, spare.checked_sub(x.frags + 16)? + 16)
        };
        let at = |q: Packed| Metric::at(&view, shift, q);
        let (mut lo, mut hi) = ([f32::MAX; 2], [f32::MIN; 2]);
        for k in 0..n {
            x.poll.tick(1);
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
            x.poll.tick(1);
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

    pub(super) fn coords(&self, s: [f32; 2]) -> [usize; 2] {
        let c = |v: f32, lo: f32, cells: usize| {
            let v = (v - lo) * self.scale;
            if v > 0.0 { (v as usize).min(cells - 1) } else { 0 }
        };
        [c(s[0], self.lo[0], self.cells[0]), c(s[1], self.lo[1], self.cells[1])]
    }

    pub(super) fn cell_of(&self, s: [f32; 2]) -> usize {
        let [cx, cy] = self.coords(s);
        cx + self.cells[0] * cy
    }

    /// Record that steps `a ..= b` of the tour are where they are now.
    pub(super) fn place(&self, x: &mut Index<'_, '_>, tour: &Tour, a: usize, b: usize) {
        for k in a..=b.min(tour.len.saturating_sub(1)) {
            let f = x.frag_of(tour.get(&x.w, k).0);
            x.w.set(self.pos + f, k as u32);
        }
    }

    /// The position in the tour of the step that point `p` ends.
    pub(super) fn pos(&self, x: &Index<'_, '_>, p: usize) -> usize {
        x.w.get(self.pos + x.frag_of(p)) as usize
    }

    /// `visit` the ends in the cells within `r` of `q` on the screen (at
    /// most [`NEAR_RINGS`] rings of them), each counted against `budget`.
    pub(super) fn each_near(
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
                    x.poll.tick(2);
                    visit(x, p, budget);
                }
            }
        }
    }
}

impl Walk {
    /// The order pass: draw fragment `f` entering at `end`, and at each
    /// point it passes, any closed loop not drawn yet that passes exactly
    /// there (entered and left at that point, so the beam goes on where it
    /// left off), and within that loop the same, up to [`SPLICE_DEPTH`]
    /// loops deep. A chicken-wire surface is loops crossing at shared
    /// points: so it is drawn in a few long polylines, one a connected
    /// piece, instead of a loop a slice and a jump between each two.
    pub(super) fn emit_spliced(
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
}

/// Walk fragment `f` from its point `end` as [`Walk::emit_spliced`] draws
/// it: `visit` each point in drawing order, with every closed loop not yet
/// drawn that passes exactly through one of them drawn there, round and
/// back (up to [`SPLICE_DEPTH`] deep). Marks the points drawn, and (`mark`)
/// the loops drawn inside ([`DRAWN`]). Returns how many were.
pub(super) fn splice_walk(
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
        x.poll.tick(2);
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
pub(super) fn mark_spliced(x: &mut Index<'_, '_>) {
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
pub(super) struct Splice {
    /// The fragment's points.
    pub(super) from: usize,
    pub(super) to: usize,
    /// The next point, and how many are left.
    pub(super) at: usize,
    pub(super) left: usize,
    /// Drawn from the last point to the first.
    pub(super) back: bool,
}

impl Splice {
    /// Fragment `from..to` entered at point `entry`: a loop round from its
    /// entry back to it, an open fragment from the end it is entered at to
    /// the other.
    pub(super) fn new(from: usize, to: usize, entry: usize, is_loop: bool) -> Self {
        let len = to.saturating_sub(from);
        if is_loop {
            let at = entry.clamp(from, to.saturating_sub(1).max(from));
            return Self { from, to, at, left: len + 1, back: false };
        }
        let back = entry + 1 == to && entry != from;
        Self { from, to, at: if back { entry } else { from }, left: len, back }
    }

    /// The next point to draw.
    pub(super) fn next(&mut self) -> Option<usize> {
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
