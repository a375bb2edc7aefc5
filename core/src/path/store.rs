//! The chicken-wire surface of one volume in voxel coordinates, compact:
//! kept so that any view re-projects it without the volume.
//!
//! A point is three `u16` in fixed point (`1 / 2^shift` voxel, the shift
//! chosen per volume so that its largest extent fills the `u16` range), and
//! its command kind takes 2 bits: 6.25 bytes a point, in one byte buffer
//! (no alignment asked: any bytes the caller has spare can hold a surface).
//! The quantisation step
//! is about 1/16 LSB of a 12-bit screen whatever the volume's size, and a
//! crossing shared by two subgrids or slices stays bit-identical (the same
//! `f32` quantises to the same code).

use crate::command::{Command, Point3};

/// A point in fixed point voxel coordinates.
pub type Packed = [u16; 3];

/// What a stored point starts or continues.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Kind {
    /// Continues the polyline (DRAWTO).
    Line,
    /// Starts an open polyline (SETPOINT).
    Move,
    /// A dot (DRAWPOINT).
    Dot,
    /// Starts a closed loop: its last point joins back to this one.
    Loop,
}

impl Kind {
    const fn bits(self) -> u8 {
        match self {
            Kind::Line => 0,
            Kind::Move => 1,
            Kind::Dot => 2,
            Kind::Loop => 3,
        }
    }

    const fn from_bits(b: u8) -> Kind {
        match b & 3 {
            0 => Kind::Line,
            1 => Kind::Move,
            2 => Kind::Dot,
            _ => Kind::Loop,
        }
    }

    /// Whether a polyline (or dot) starts here.
    pub const fn starts(self) -> bool {
        !matches!(self, Kind::Line)
    }
}

/// Contour commands in voxel coordinates over caller bytes: the points (6
/// bytes each, little-endian `u16`s), then their kinds (4 a byte). Bytes
/// for `n` points: [`Geometry::bytes_for`].
///
/// `push` hands the command back when full and counts it; a polyline cut
/// short by the capacity keeps the part that fitted, and a lone trailing
/// `MoveTo` is taken back, so the store always holds whole drawing
/// commands.
#[derive(Debug, PartialEq)]
pub struct Geometry<'a> {
    points: &'a mut [[u8; 6]],
    kinds: &'a mut [u8],
    /// Everything but the bytes.
    held: Held,
}

impl<'a> Geometry<'a> {
    /// An empty store over `bytes`, at the finest scale: as many points
    /// as they hold ([`Geometry::bytes_for`]).
    pub fn new(bytes: &'a mut [u8]) -> Self {
        let n = Self::points_in(bytes.len());
        let (points, kinds) = bytes.split_at_mut(6 * n);
        let points = points.as_chunks_mut::<6>().0;
        Self { points, kinds, held: Held::default() }
    }

    /// Bytes that hold `points` points: 6 each, and their kinds (2 bits
    /// each, rounded up to a byte).
    pub const fn bytes_for(points: usize) -> usize {
        6 * points + points.div_ceil(4)
    }

    /// Points that `bytes` bytes hold: the most `n` with
    /// `bytes_for(n) <= bytes`.
    pub const fn points_in(bytes: usize) -> usize {
        // 6.25 bytes a point, less the rounding of the last kind byte.
        let n = bytes / 25 * 4;
        let rest = bytes % 25;
        // In the last 25 bytes: up to 3 more points (6 bytes each, and
        // their kinds' one byte).
        n + if rest >= 19 {
            3
        } else if rest >= 13 {
            2
        } else if rest >= 7 {
            1
        } else {
            0
        }
    }

    /// The fixed point shift for a volume of `dims` samples: the largest
    /// with `(max extent - 1) * 2^shift <= 65535`, at most 12.
    pub fn shift_for(dims: [u16; 3]) -> u8 {
        let top = dims.iter().map(|&d| u32::from(d.max(2)) - 1).max().unwrap_or(1);
        let mut shift = 0u8;
        while shift < 12 && (top << (shift + 1)) <= 0xFFFF {
            shift += 1;
        }
        shift
    }

    /// The most points it holds: every point slot has its kind's bits
    /// (`new` takes `points_in(bytes)` slots, whose kinds fit after them).
    #[inline]
    pub fn capacity(&self) -> usize {
        self.points.len()
    }

    /// Points held.
    pub fn len(&self) -> usize {
        self.held.len
    }

    /// Whether no point is held.
    pub fn is_empty(&self) -> bool {
        self.held.len == 0
    }

    /// Commands refused since the last [`Geometry::reset`].
    pub fn dropped(&self) -> u32 {
        self.held.dropped
    }

    /// The fixed point shift.
    pub fn shift(&self) -> u8 {
        self.held.shift
    }

    /// Forget every point and take a new scale.
    pub fn reset(&mut self, shift: u8) {
        self.held = Held::empty(shift);
    }

    /// `p` in this store's fixed point (clamped to the `u16` range).
    pub fn quantise(&self, p: Point3) -> Packed {
        // The shift is at most 12 (`Held::empty`): no clamp for every point.
        quantise_by(scale(self.held.shift), p)
    }

    /// `p` in the fixed point of `shift` (clamped to the `u16` range).
    pub fn quantise_with(shift: u8, p: Point3) -> Packed {
        quantise_by(scale(shift.min(12)), p)
    }

    /// A fixed point code back in voxel coordinates (exact).
    pub fn point(&self, q: Packed) -> Point3 {
        // 2^-shift, exactly: built from its exponent bits, not a division
        // (a 14-cycle VDIV on the M4, for every point of every frame).
        let k = f32::from_bits((127 - u32::from(self.held.shift)) << 23);
        Point3::new(f32::from(q[0]) * k, f32::from(q[1]) * k, f32::from(q[2]) * k)
    }

    /// Point `i` and its kind.
    pub fn get(&self, i: usize) -> Option<(Packed, Kind)> {
        if i >= self.held.len {
            return None;
        }
        Some((unpack(self.points.get(i)?), kind_in(self.kinds, i)?))
    }

    /// The held points' bytes, and the kinds' bytes.
    pub(crate) fn held_parts(&self) -> (&[[u8; 6]], &[u8]) {
        (self.points.get(..self.held.len).unwrap_or(&[]), self.kinds)
    }

    /// The kind of point `i` alone.
    #[inline]
    pub(crate) fn kind(&self, i: usize) -> Option<Kind> {
        if i >= self.held.len {
            return None;
        }
        kind_in(self.kinds, i)
    }

    fn set_kind(&mut self, i: usize, kind: Kind) {
        if let Some(byte) = self.kinds.get_mut(i / 4) {
            let s = 2 * (i % 4);
            *byte = (*byte & !(3 << s)) | (kind.bits() << s);
        }
    }

    /// Write slot `i` (held or not).
    pub(crate) fn put(&mut self, i: usize, q: Packed, kind: Kind) {
        if let Some(slot) = self.points.get_mut(i) {
            pack_into(slot, q);
        }
        self.set_kind(i, kind);
    }

    /// Append a point of `kind`; false when full (counted).
    #[inline(always)]
    pub(crate) fn push_raw(&mut self, q: Packed, kind: Kind) -> bool {
        let i = self.held.len;
        // Both lookups fail together (`capacity`), past the last slot.
        let (Some(slot), Some(byte)) = (self.points.get_mut(i), self.kinds.get_mut(i / 4)) else {
            self.held.dropped = self.held.dropped.saturating_add(1);
            return false;
        };
        pack_into(slot, q);
        let s = 2 * (i % 4);
        *byte = (*byte & !(3 << s)) | (kind.bits() << s);
        self.held.len = i + 1;
        true
    }

    /// Hold the first `len` points written (at most the capacity).
    pub(crate) fn set_len(&mut self, len: usize) {
        self.held.len = len.min(self.capacity());
    }

    /// Drop the last point.
    pub(crate) fn pop(&mut self) {
        self.held.len = self.held.len.saturating_sub(1);
    }

    /// Mark point `i` (a polyline's first) as the start of a closed loop.
    pub(crate) fn close_at(&mut self, i: usize) {
        if i < self.held.len {
            self.set_kind(i, Kind::Loop);
        }
    }

    /// Append a command.
    ///
    /// # Errors
    /// The command, when the store is full.
    pub fn push(&mut self, command: Command<Point3>) -> Result<(), Command<Point3>> {
        self.push_within(command, usize::MAX)
    }

    /// [`Geometry::push`], as if the store held at most `cap` points.
    #[inline(always)]
    pub(crate) fn push_within(
        &mut self,
        command: Command<Point3>,
        cap: usize,
    ) -> Result<(), Command<Point3>> {
        let kind = match command {
            Command::LineTo(_) if self.held.broken => return Err(self.refuse(command, false)),
            Command::LineTo(_) => Kind::Line,
            Command::MoveTo(_) => Kind::Move,
            Command::Point(_) => Kind::Dot,
        };
        if self.held.len < cap && self.push_raw(self.quantise(*command.point()), kind) {
            if kind.starts() {
                self.held.broken = false;
            }
            return Ok(());
        }
        Err(self.refuse(command, self.held.len < cap))
    }

    /// Count `command` refused (unless `push_raw` has), and break the
    /// open polyline: its later `LineTo`s are refused too, and a `MoveTo`
    /// left without its line is taken back (it would draw nothing).
    #[cold]
    #[inline(never)]
    fn refuse(&mut self, command: Command<Point3>, counted: bool) -> Command<Point3> {
        if !counted {
            self.held.dropped = self.held.dropped.saturating_add(1);
        }
        if matches!(command, Command::LineTo(_)) && self.held.broken {
            return command;
        }
        self.held.broken = true;
        if matches!(self.get(self.held.len.wrapping_sub(1)), Some((_, Kind::Move))) {
            self.pop();
            self.held.dropped = self.held.dropped.saturating_add(1);
        }
        command
    }

    /// The drawing commands, in order; a closed loop ends with the `LineTo`
    /// back to its first point.
    pub fn commands(&self) -> Commands<'_, 'a> {
        Commands { g: self, i: 0, first: None, close: None }
    }

    /// Polylines and dots held.
    pub fn polylines(&self) -> usize {
        (0..self.held.len).filter(|&i| self.get(i).is_some_and(|(_, k)| k.starts())).count()
    }
}

/// What a [`Geometry`] holds besides its bytes: to lend a store the same
/// bytes again later ([`Geometry::held`], [`Geometry::lent`]), as the
/// stream does with the part of a surface that spills into the idle slice
/// memory.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub(crate) struct Held {
    len: usize,
    dropped: u32,
    /// A command of the open polyline was refused: its later `LineTo`s are
    /// refused too, until the next `MoveTo` or `Point`.
    broken: bool,
    /// Fixed point: `1 / 2^shift` voxel per code; at most 12 ([`Held::empty`]).
    shift: u8,
}

/// `2^shift` exactly, from its exponent bits (`shift` at most 12): no
/// integer-to-float conversion for every point stored.
#[inline(always)]
fn scale(shift: u8) -> f32 {
    f32::from_bits((127 + u32::from(shift)) << 23)
}

/// `p` times `k`, each coordinate rounded to the `u16` range.
#[inline(always)]
fn quantise_by(k: f32, p: Point3) -> Packed {
    let q = |v: f32| crate::fastmath::round_u16(v * k);
    [q(p.x), q(p.y), q(p.z)]
}

impl Held {
    /// An empty store at `shift`.
    pub(crate) fn empty(shift: u8) -> Self {
        Self { shift: shift.min(12), ..Self::default() }
    }

    /// Points held.
    pub(crate) fn len(&self) -> usize {
        self.len
    }

    /// Commands refused.
    pub(crate) fn dropped(&self) -> u32 {
        self.dropped
    }
}

impl<'a> Geometry<'a> {
    /// What it holds, to lend its bytes again with [`Geometry::lent`].
    pub(crate) fn held(&self) -> Held {
        self.held
    }

    /// The store `held` describes, over the same bytes it was taken from
    /// (or a copy of them: [`Geometry::move_to_front`]).
    pub(crate) fn lent(bytes: &'a mut [u8], held: Held) -> Self {
        let mut g = Self::new(bytes);
        g.held = Held { len: held.len.min(g.capacity()), shift: held.shift.min(12), ..held };
        g
    }

    /// Move the store lent `bytes[at..]` and holding `held` to the start
    /// of `bytes`, in as few bytes as it needs: it is then
    /// `Geometry::lent(&mut bytes[..Geometry::bytes_for(held.len())], held)`
    /// and the rest of `bytes` is free.
    pub(crate) fn move_to_front(bytes: &mut [u8], at: usize, held: Held) -> Held {
        let n = Self::points_in(bytes.len().saturating_sub(at));
        Self::move_down(bytes, at, held, Self::bytes_for(held.len.min(n)))
    }

    /// Move the store lent `bytes[at..]` and holding `held` to be the
    /// store lent `bytes[..to]`: it is then `Geometry::lent(&mut
    /// bytes[..to], held)`. Empty if `to` is past the end of `bytes`, or
    /// if `bytes[..to]` holds fewer points than `held`.
    pub(crate) fn move_down(bytes: &mut [u8], at: usize, held: Held, to: usize) -> Held {
        let n = Self::points_in(bytes.len().saturating_sub(at));
        let len = held.len.min(n);
        let kinds = at + 6 * n;
        let to_kinds = 6 * Self::points_in(to);
        // Points first: they move down to the start, past nothing the
        // kinds still need (those lie after all `n` points, and the
        // kinds' new place after all the points moved).
        if kinds + len.div_ceil(4) > bytes.len() || len > Self::points_in(to) || to > bytes.len() {
            return Held::empty(held.shift);
        }
        bytes.copy_within(at..at + 6 * len, 0);
        bytes.copy_within(kinds..kinds + len.div_ceil(4), to_kinds);
        Held { len, ..held }
    }
}

/// The points of a surface in one or two stores, as one sequence: all of
/// the first, then all of the second (the part that spilled). It keeps
/// the stores' held points and kinds as slices: a lookup is one compare
/// and one bounds check (the stitcher's hottest path).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Source<'g> {
    points: [&'g [[u8; 6]]; 2],
    kinds: [&'g [u8]; 2],
    /// The fixed point shift (the first store's: both have the volume's).
    shift: u8,
}

impl<'g> Source<'g> {
    /// One store.
    pub(crate) fn one(g: &'g Geometry<'g>) -> Self {
        let (points, kinds) = g.held_parts();
        Self { points: [points, &[]], kinds: [kinds, &[]], shift: g.shift() }
    }

    /// `head`'s points, then `tail`'s.
    pub(crate) fn two(head: &'g Geometry<'g>, tail: &'g Geometry<'g>) -> Self {
        let ((p0, k0), (p1, k1)) = (head.held_parts(), tail.held_parts());
        Self { points: [p0, p1], kinds: [k0, k1], shift: head.shift() }
    }

    /// Points in all.
    pub(crate) fn len(&self) -> usize {
        self.points[0].len() + self.points[1].len()
    }

    /// The smallest box of codes holding every point (lowest, highest
    /// corner); `None` with no points.
    /// `poll` is called every 1,024 points (for a board that keeps its
    /// output fed meanwhile).
    pub(crate) fn extent(&self, poll: &mut dyn FnMut()) -> Option<[Packed; 2]> {
        let mut box_: Option<[Packed; 2]> = None;
        for points in self.points {
            for chunk in points.chunks(1024) {
                for q in chunk.iter().map(unpack) {
                    let [lo, hi] = box_.get_or_insert([q, q]);
                    *lo = [lo[0].min(q[0]), lo[1].min(q[1]), lo[2].min(q[2])];
                    *hi = [hi[0].max(q[0]), hi[1].max(q[1]), hi[2].max(q[2])];
                }
                poll();
            }
        }
        box_
    }

    /// The fixed point shift.
    pub(crate) fn shift(&self) -> u8 {
        self.shift
    }

    /// Point `i` and its kind.
    #[inline]
    pub(crate) fn get(&self, i: usize) -> Option<(Packed, Kind)> {
        Some((self.point_at(i)?, self.kind(i)?))
    }

    /// `f(i, kind)` for every point in order: four kinds a byte read,
    /// not a lookup a point.
    #[inline]
    pub(crate) fn for_each_kind(&self, mut f: impl FnMut(usize, Kind)) {
        let mut i = 0;
        for (points, kinds) in self.points.iter().zip(self.kinds) {
            let mut left = points.len();
            for &byte in kinds {
                if left == 0 {
                    break;
                }
                for k in 0..left.min(4) {
                    f(i, Kind::from_bits(byte >> (2 * k)));
                    i += 1;
                }
                left = left.saturating_sub(4);
            }
        }
    }

    /// Whether point `i` is exactly `q` ([`pack`]ed): its stored bytes
    /// compared, not unpacked.
    #[inline]
    pub(crate) fn is_at(&self, i: usize, q: &[u8; 6]) -> bool {
        let [head, tail] = self.points;
        let p = if i < head.len() { head.get(i) } else { tail.get(i - head.len()) };
        p == Some(q)
    }

    /// Point `i` alone.
    #[inline]
    pub(crate) fn point_at(&self, i: usize) -> Option<Packed> {
        let [head, tail] = self.points;
        if i < head.len() { head.get(i) } else { tail.get(i - head.len()) }.map(unpack)
    }

    /// The kind of point `i` alone.
    #[inline]
    pub(crate) fn kind(&self, i: usize) -> Option<Kind> {
        let [head, tail] = self.points;
        let (kinds, j) = if i < head.len() {
            (self.kinds[0], i)
        } else if i - head.len() < tail.len() {
            (self.kinds[1], i - head.len())
        } else {
            return None;
        };
        kind_in(kinds, j)
    }
}

/// The kind of point `i` in kind bytes (four a byte).
#[inline]
fn kind_in(kinds: &[u8], i: usize) -> Option<Kind> {
    let byte = *kinds.get(i / 4)?;
    Some(Kind::from_bits(byte >> (2 * (i % 4))))
}

/// A point as its 6 stored bytes.
#[inline]
pub(crate) fn pack([x, y, z]: Packed) -> [u8; 6] {
    let ([a, b], [c, d], [e, f]) = (x.to_le_bytes(), y.to_le_bytes(), z.to_le_bytes());
    [a, b, c, d, e, f]
}

/// [`pack`] into `slot`, as a word and a halfword: the M4 stores each in
/// one instruction (it takes them unaligned), where the six bytes of
/// `pack` are six stores.
#[inline(always)]
fn pack_into(slot: &mut [u8; 6], [x, y, z]: Packed) {
    if let Some((word, half)) = slot.split_first_chunk_mut::<4>()
        && let Some(half) = half.first_chunk_mut::<2>()
    {
        *word = (u32::from(x) | u32::from(y) << 16).to_le_bytes();
        *half = z.to_le_bytes();
    }
}

/// A point from its 6 stored bytes.
#[inline]
fn unpack(b: &[u8; 6]) -> Packed {
    let [a, b0, c, d, e, f] = *b;
    [u16::from_le_bytes([a, b0]), u16::from_le_bytes([c, d]), u16::from_le_bytes([e, f])]
}

/// The commands of a [`Geometry`] ([`Geometry::commands`]).
#[derive(Debug, Clone)]
pub struct Commands<'g, 'a> {
    g: &'g Geometry<'a>,
    i: usize,
    /// The first point of the loop being drawn.
    first: Option<Packed>,
    /// The closing `LineTo` due before the next point.
    close: Option<Packed>,
}

impl Commands<'_, '_> {
    /// The next command with its point as stored, in `1 / 2^shift` voxel
    /// ([`Geometry::shift`]): for a reader that folds the scale into its
    /// own arithmetic (the engine's projection).
    pub fn next_packed(&mut self) -> Option<Command<Packed>> {
        if let Some(q) = self.close.take() {
            return Some(Command::LineTo(q));
        }
        let (q, kind) = self.g.get(self.i)?;
        self.i += 1;
        // The loop ends here if the next point starts something (or none).
        let ends = self.g.kind(self.i).is_none_or(Kind::starts);
        let command = match kind {
            Kind::Line => Command::LineTo(q),
            Kind::Move => {
                self.first = None;
                Command::MoveTo(q)
            }
            Kind::Dot => {
                self.first = None;
                Command::Point(q)
            }
            Kind::Loop => {
                self.first = Some(q);
                Command::MoveTo(q)
            }
        };
        if ends {
            self.close = self.first.take();
        }
        Some(command)
    }
}

impl Iterator for Commands<'_, '_> {
    type Item = Command<Point3>;

    fn next(&mut self) -> Option<Command<Point3>> {
        let command = self.next_packed()?;
        Some(command.map(|q| self.g.point(q)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(x: f32) -> Point3 {
        Point3::new(x, 0.0, 0.0)
    }

    fn store(n: usize) -> Vec<u8> {
        vec![0; Geometry::bytes_for(n)]
    }

    #[test]
    fn bytes_hold_the_points_they_say() {
        for n in 0..200 {
            let b = Geometry::bytes_for(n);
            assert_eq!(Geometry::points_in(b), n, "{n}");
            assert_eq!(Geometry::points_in(b - usize::from(n > 0)), n.saturating_sub(1), "{n}");
            assert_eq!(Geometry::new(&mut vec![0; b]).capacity(), n);
        }
        for bytes in 0..300 {
            let n = Geometry::points_in(bytes);
            assert!(Geometry::bytes_for(n) <= bytes && Geometry::bytes_for(n + 1) > bytes, "{bytes}");
        }
    }

    #[test]
    fn points_read_back_as_written_at_any_alignment() {
        let mut bytes = vec![0u8; Geometry::bytes_for(3) + 1];
        let mut g = Geometry::new(&mut bytes[1..]);
        let q = [[0, 0xFFFF, 0x1234], [0x8001, 7, 0xFF00], [1, 2, 3]];
        for (i, &p) in q.iter().enumerate() {
            assert!(g.push_raw(p, if i == 0 { Kind::Move } else { Kind::Line }));
        }
        assert!(!g.push_raw([9; 3], Kind::Line));
        assert_eq!((0..3).map(|i| g.get(i).unwrap().0).collect::<Vec<_>>(), q);
        let s = Source::one(&g);
        assert_eq!((0..3).map(|i| s.point_at(i).unwrap()).collect::<Vec<_>>(), q);
        assert_eq!(s.point_at(3), None);
        assert_eq!(bytes[1..3], [0, 0]);
        assert_eq!(bytes[3..5], [0xFF, 0xFF]);
    }

    #[test]
    fn push_hands_back_when_full_and_takes_back_a_lone_move() {
        let mut bytes = store(3);
        let mut g = Geometry::new(&mut bytes);
        g.reset(4);
        assert_eq!(g.push(Command::MoveTo(p(0.0))), Ok(()));
        assert_eq!(g.push(Command::LineTo(p(1.0))), Ok(()));
        assert_eq!(g.push(Command::MoveTo(p(2.0))), Ok(()));
        assert_eq!(g.push(Command::LineTo(p(3.0))), Err(Command::LineTo(p(3.0))));
        // The MoveTo at 2 lost its line: it is gone too, and both count.
        assert_eq!(g.len(), 2);
        assert_eq!(g.dropped(), 2);
        // The rest of that polyline is refused although a slot is free now.
        assert_eq!(g.push(Command::LineTo(p(4.0))), Err(Command::LineTo(p(4.0))));
        assert_eq!(g.dropped(), 3);
        let got: Vec<_> = g.commands().collect();
        assert_eq!(got, [Command::MoveTo(p(0.0)), Command::LineTo(p(1.0))]);
        assert_eq!(g.push(Command::Point(p(5.0))), Ok(()));
        assert_eq!(g.commands().last(), Some(Command::Point(p(5.0))));
        g.reset(4);
        assert!(g.is_empty());
        assert_eq!(g.dropped(), 0);
    }

    /// A stored point and its kind, as [`Geometry::get`] reads it.
    type Stored = Option<([u16; 3], Kind)>;

    /// 200 bytes with a store of `n` points (of five kinds) lent from byte
    /// `at`: the bytes, what it holds, and its points.
    fn lent_at(at: usize, n: usize) -> (Vec<u8>, Held, Vec<Stored>) {
        let kinds = [Kind::Move, Kind::Line, Kind::Dot, Kind::Loop, Kind::Line];
        let mut bytes: Vec<u8> = (0..200u8).collect();
        let mut g = Geometry::lent(&mut bytes[at..], Held::empty(5));
        for (i, &k) in kinds.iter().take(n).enumerate() {
            assert!(g.push_raw([i as u16, 1000 + i as u16, 0xFFFF - i as u16], k));
        }
        let points = (0..n).map(|i| g.get(i)).collect();
        let held = g.held();
        (bytes, held, points)
    }

    #[test]
    fn a_store_moved_to_the_front_holds_what_it_held() {
        for at in [0, 1, 37, 60] {
            for n in 0..=5 {
                let (mut bytes, held, want) = lent_at(at, n);
                let held = Geometry::move_to_front(&mut bytes, at, held);
                assert_eq!(held, Held { len: n, dropped: 0, broken: false, shift: 5 });
                let g = Geometry::lent(&mut bytes[..Geometry::bytes_for(n)], held);
                assert_eq!((0..n).map(|i| g.get(i)).collect::<Vec<_>>(), want, "at {at}, {n} points");
                assert_eq!(g.shift(), 5);
            }
        }
        // A store that cannot be where it is said to be holds nothing.
        let mut bytes = [0u8; 10];
        assert_eq!(Geometry::move_to_front(&mut bytes, 20, Held { len: 3, ..Held::empty(2) }).len(), 0);
    }

    #[test]
    fn a_store_moved_down_is_the_store_lent_its_new_bytes() {
        for at in [0, 1, 37, 60, 150] {
            for n in 0..=5 {
                for to in 0..=200 {
                    let (mut bytes, held, want) = lent_at(at, n);
                    let held = Geometry::move_down(&mut bytes, at, held, to);
                    if Geometry::points_in(to) < n {
                        assert_eq!(held.len(), 0, "{n} points do not fit {to} bytes");
                        continue;
                    }
                    assert_eq!(held, Held { len: n, dropped: 0, broken: false, shift: 5 });
                    let g = Geometry::lent(&mut bytes[..to], held);
                    assert_eq!(
                        (0..n).map(|i| g.get(i)).collect::<Vec<_>>(),
                        want,
                        "at {at} to {to}, {n} points"
                    );
                }
            }
        }
    }

    #[test]
    fn every_kind_in_order_over_two_stores_of_any_length() {
        let cycle = [Kind::Move, Kind::Line, Kind::Dot, Kind::Loop, Kind::Line, Kind::Line, Kind::Move];
        for n in 0..11 {
            for m in 0..11 {
                let (mut a, mut b) = (store(12), store(12));
                let (mut g, mut h) = (Geometry::new(&mut a), Geometry::new(&mut b));
                for i in 0..n + m {
                    let store = if i < n { &mut g } else { &mut h };
                    assert!(store.push_raw([i as u16; 3], cycle[i % cycle.len()]));
                }
                let s = Source::two(&g, &h);
                let mut got = Vec::new();
                s.for_each_kind(|i, k| got.push((i, k)));
                let want: Vec<_> = (0..n + m).map(|i| (i, cycle[i % cycle.len()])).collect();
                assert_eq!(got, want, "{n} + {m} points");
            }
        }
    }

    #[test]
    fn two_stores_read_as_one() {
        let (mut a, mut b) = (store(2), store(3));
        let (mut g, mut h) = (Geometry::new(&mut a), Geometry::new(&mut b));
        assert!(g.push_raw([1; 3], Kind::Move) && g.push_raw([2; 3], Kind::Line));
        assert!(h.push_raw([3; 3], Kind::Line) && h.push_raw([4; 3], Kind::Dot));
        let s = Source::two(&g, &h);
        assert_eq!(s.len(), 4);
        let got: Vec<_> = (0..5).map(|i| (s.get(i), s.point_at(i), s.kind(i))).collect();
        assert_eq!(got[1], (Some(([2; 3], Kind::Line)), Some([2; 3]), Some(Kind::Line)));
        assert_eq!(got[2], (Some(([3; 3], Kind::Line)), Some([3; 3]), Some(Kind::Line)));
        assert_eq!(got[3], (Some(([4; 3], Kind::Dot)), Some([4; 3]), Some(Kind::Dot)));
        assert_eq!(got[4], (None, None, None));
        assert_eq!(Source::one(&g).len(), 2);
        assert_eq!(Source::one(&g).get(2), None);
    }

    #[test]
    fn shift_fills_the_u16_range() {
        assert_eq!(Geometry::shift_for([128, 128, 84]), 9); // 127 * 512 = 65024
        assert_eq!(Geometry::shift_for([2, 2, 2]), 12);
        assert_eq!(Geometry::shift_for([256, 3, 3]), 8);
        assert_eq!(Geometry::shift_for([257, 3, 3]), 7); // 256 * 256 = 65536 > 65535
        assert_eq!(Geometry::shift_for([65535, 2, 2]), 0);
        assert_eq!(Geometry::shift_for([0, 0, 0]), 12);
    }

    #[test]
    fn quantisation_is_exact_on_the_grid_and_within_half_a_step() {
        let mut bytes = store(1);
        let mut g = Geometry::new(&mut bytes);
        g.reset(Geometry::shift_for([128, 128, 84]));
        let step = 1.0 / 512.0;
        for v in [0.0f32, 1.0, 63.5, 127.0, 0.3333, 101.12345, 126.999] {
            let back = g.point(g.quantise(Point3::new(v, v, v)));
            assert!((back.x - v).abs() <= step / 2.0, "{v} -> {}", back.x);
        }
        assert_eq!(g.point(g.quantise(Point3::new(17.0, 3.5, 0.25))), Point3::new(17.0, 3.5, 0.25));
        assert_eq!(g.quantise(Point3::new(-1.0, 1e9, f32::NAN)), [0, 0xFFFF, 0]);
    }

    #[test]
    fn scale_is_two_to_the_shift() {
        for shift in 0..=12u8 {
            assert_eq!(scale(shift), f32::from(1u16 << shift), "shift {shift}");
        }
    }

    #[test]
    fn kinds_pack_four_a_byte_and_loops_close() {
        let mut bytes = store(9);
        let mut g = Geometry::new(&mut bytes);
        g.reset(0);
        let q = |x: u16| [x, 0, 0];
        for (x, k) in [
            (1, Kind::Move),
            (2, Kind::Line),
            (3, Kind::Line),
            (4, Kind::Dot),
            (5, Kind::Move),
            (6, Kind::Line),
        ] {
            assert!(g.push_raw(q(x), k));
        }
        g.close_at(0);
        let pt = |x: f32| Point3::new(x, 0.0, 0.0);
        let got: Vec<_> = g.commands().collect();
        assert_eq!(
            got,
            [
                Command::MoveTo(pt(1.0)),
                Command::LineTo(pt(2.0)),
                Command::LineTo(pt(3.0)),
                Command::LineTo(pt(1.0)),
                Command::Point(pt(4.0)),
                Command::MoveTo(pt(5.0)),
                Command::LineTo(pt(6.0)),
            ]
        );
        assert_eq!(g.polylines(), 3);
        assert_eq!(g.get(3), Some((q(4), Kind::Dot)));
        assert_eq!(g.get(6), None);
    }
}
