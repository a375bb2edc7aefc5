//! Streaming contouring: a volume arrives one z slice at a time, and only
//! two slices (the previous and the current) are ever held.
//!
//! When slice `z` is complete, the engine contours the slab between slices
//! `z - 1` and `z` ([`crate::contour::slab`]): the x-y slice `z - 1`, and
//! one row of subgrids of every x-z slice (one per `y`) and every y-z
//! slice (one per `x`); the last slice adds its own x-y slice. Together
//! these are all the subgrids of the whole chicken-wire surface, with the
//! very commands, in the very order, of contouring the whole volume at once
//! ([`crate::contour::surface::contour_volume`]): the same code, fed from
//! the two slices held.
//!
//! That work is a [`Job`] of slab rows (`n` for an `n x n` slice, each
//! with the cells of all three planes), done at once when the slice
//! completes or, deferred, a few rows at a time ([`Stream::work`], by
//! cells) so that the caller can keep its display refreshed in between;
//! the next slice's data then waits for the job (the caller stops
//! feeding), or finishes it first if it comes anyway.

use super::{QUIET_ROWS, RowMemory};
use crate::command::{Command, Point3};
use crate::contour::slab::{self, Cut, Every, Lane, Rows, Slab};
use crate::contour::surface::{SliceId, SurfaceSink};
use crate::contour::trace::Traversal;
use crate::contour::{ContourStats, MAX_COMMANDS_A_CELL};
use crate::path::{self, Geometry, Held, Stride};
use crate::wire::{AXIS_X, AXIS_Y, AXIS_Z, Levels, NackCode, SampleType};
use core::convert::Infallible;
use core::ops::Range;

/// A volume as `BeginVolume` announced it, checked.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct VolumeSpec {
    /// Samples along x, y, z (x, y at least 2; z at least 1).
    pub dims: [u16; 3],
    /// The type of the samples.
    pub sample_type: SampleType,
    /// Voxel spacing along x, y, z (finite, positive).
    pub spacing: [f32; 3],
    /// Contour levels (at least one, all finite).
    pub levels: Levels,
    /// Slicing planes: a set of [`AXIS_X`] (y-z slices), [`AXIS_Y`] (x-z
    /// slices) and [`AXIS_Z`] (x-y slices).
    pub axes: u8,
    /// Contour every `every`-th slice of each plane (at least 1).
    pub every: u8,
}

impl VolumeSpec {
    /// Bytes in one z slice.
    pub fn slice_bytes(&self) -> usize {
        usize::from(self.dims[0]) * usize::from(self.dims[1]) * self.sample_type.size()
    }

    /// Check a volume against the buffers: `Invalid` for contents that no
    /// device takes, `DimsOverCapacity` for a slice that does not fit.
    pub(crate) fn check(&self, slice_capacity: usize) -> Result<(), NackCode> {
        let [nx, ny, nz] = self.dims.map(usize::from);
        let levels_ok = !self.levels.is_empty() && self.levels.as_slice().iter().all(|l| l.is_finite());
        let spacing_ok = self.spacing.iter().all(|s| s.is_finite() && *s > 0.0);
        let axes_ok = self.axes != 0 && self.axes & !(AXIS_X | AXIS_Y | AXIS_Z) == 0;
        if nx < 2 || ny < 2 || nz < 1 || !levels_ok || !spacing_ok || !axes_ok {
            return Err(NackCode::Invalid);
        }
        if self.slice_bytes() > slice_capacity {
            return Err(NackCode::DimsOverCapacity);
        }
        Ok(())
    }
}

/// A transfer in progress.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Transfer {
    pub spec: VolumeSpec,
    /// The slice being received.
    pub z: u16,
    /// Bytes of slice `z` received.
    pub offset: u32,
    /// When the last whole command came (ms): accepted, or out of order
    /// or sent again (the sender is still at it).
    pub last_ms: u32,
    /// Contouring so far.
    pub stats: ContourStats,
    /// What the last completed slice still has to contour.
    pub job: Option<Job>,
    /// Fragments of the surface kept so far.
    pub frags: u32,
    /// The slices in force: `spec.every` apart, twice as many each time
    /// the surface outgrew the memory ([`path::thin`]).
    pub stride: Stride,
}

/// The contouring a completed slice `z` owes: the rows of the slab
/// between slices `z - 1` and `z`, then, after the last slice, those of
/// the slab of slice `z` alone (its x-y cells); where it stands. A step
/// is a row's planes from `plane` on, as many as the back has room for
/// all they may yield (the bound the memory is checked against before
/// each plane; all of them once the spill has begun). A transfer's job
/// always stands at a step with something to do under the transfer's
/// stride ([`Stream::ahead`] is called wherever one is made or moved).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub(crate) struct Job {
    /// The slice.
    z: u16,
    /// The slot holding slice `z` (the other holds `z - 1`).
    slot: usize,
    /// The lower slice of the slab at hand (`z - 1`, or `z`).
    lower: u16,
    /// The next row (`y`).
    next: u32,
    /// The next plane of that row: 0 x-y, 1 x-z, 2 y-z.
    plane: u8,
}

impl Job {
    /// Move past the planes of the row before `end` (all of them at 3 or
    /// more: on to the next row).
    fn past(&mut self, end: u8) {
        if end < 3 {
            self.plane = end;
        } else {
            self.plane = 0;
            self.next += 1;
        }
    }
}

/// The two slices, the decoded rows and the transfer state.
///
/// The slice memory holds a transfer's two slices at its start, each
/// `nx * ny * sample size` bytes; what they leave free holds the part of
/// the surface that does not fit the back (the spill: a [`Geometry`] lent
/// those bytes), from the first slice until the engine commits the
/// volume. So a volume of small slices may have a larger surface: of
/// 32 x 32 `f32` (8 KB), the 64 KB of the firmware leave room for 9,000
/// more points.
///
/// The slice memory itself is the engine's, lent to each call as `slots`:
/// all of it, or (while the replay of the picture on screen keeps its
/// tail) its head. With the head alone, a row is contoured only when the
/// back has room for all it can yield, so nothing is ever kept in the
/// spill then: what a transfer keeps does not depend on which was lent.
/// When the back is short of that room, the row waits and the stream asks
/// for all of the memory ([`Stream::wants_all`]).
#[derive(Debug)]
pub(crate) struct Stream<'a> {
    /// Bytes of the whole slice memory.
    capacity: usize,
    /// What contouring keeps from one step of a job to the next (the
    /// rows' samples and classes).
    rows: &'a mut RowMemory,
    /// A row waited for the whole slice memory.
    wants_all: bool,
    /// A row waits for the engine to fold the back into the front
    /// ([`Stream::fold`]).
    wants_fold: bool,
    /// The front was folded into this transfer: the picture on screen is
    /// gone from it (the engine clears this when it commits).
    pub(crate) front_taken: bool,
    /// Points the back held after its last fold (0 before the first).
    folded_len: usize,
    /// Points the front holds, which a fold's output may not outgrow.
    front_points: usize,
    /// The slot receiving slice `z`; the other holds slice `z - 1`.
    cur: usize,
    pub transfer: Option<Transfer>,
    /// The spill of the last transfer: where in `slots` its store starts,
    /// and what it holds.
    spill: Option<(usize, Held)>,
}

/// Keeps every command of the slices in force: in the back while it has
/// room, then in the spill; the store that refuses one counts it. The
/// spill stops short of its room by the scratch the stitch pass will want
/// for all the pieces kept ([`path::stitch_reserve`]), in the slice
/// memory, which the spill then shares with it.
///
/// When both are full it thins the surface ([`path::thin`]): the stride
/// doubles, the pieces of the slices it no longer takes go, and the
/// command is tried again; so a surface larger than the board holds is
/// drawn whole at a coarser stride, not cut. Only when one slice of each
/// plane is left is it cut, and what is kept is still stitched and
/// ordered.
struct Keep<'g, 'a, 's> {
    /// Called as a long thinning goes on (a board refills its output).
    poll: &'g mut dyn FnMut(),
    back: &'g mut Geometry<'a>,
    spill: &'g mut Geometry<'s>,
    /// Fragments kept so far (back and spill).
    frags: &'g mut u32,
    /// Bytes of the whole slice memory.
    memory: usize,
    /// The slices in force.
    stride: Stride,
    /// The slice the last command came from: its axis (0 x for a y-z
    /// slice, 1 y for an x-z, 2 z for an x-y) and index.
    slice: (usize, u16),
    /// Whether `stride` keeps that slice (asked when the slice changes,
    /// not each command).
    live: bool,
    /// Commands taken since `poll` was last called.
    since_poll: u8,
}

/// Commands kept between two polls of a board's output (some 200 cycles
/// each, with their contouring).
const KEEP_POLL: u8 = 48;

impl Keep<'_, '_, '_> {
    /// The commands that follow come from slice `index` along `axis`.
    fn enter_slice(&mut self, axis: usize, index: u16) {
        self.slice = (axis, index);
        self.live = self.stride.keeps(axis, index);
    }

    /// Whether the spill has room for `c` beside the scratch the stitch
    /// pass will want for all the pieces kept.
    #[cold]
    fn spill_fits(&self, c: &Command<Point3>) -> bool {
        let frags = *self.frags as usize + usize::from(!matches!(c, Command::LineTo(_)));
        let points = self.back.len() + self.spill.len() + 1;
        let need = Geometry::bytes_for(self.spill.len() + 1) + path::stitch_reserve(frags, points);
        need <= self.memory && self.spill.len() < self.spill.capacity()
    }

    /// Thin the surface to the next coarser stride, if there is one;
    /// whether there was.
    #[cold]
    fn thin(&mut self) -> bool {
        let Some(coarser) = self.stride.coarser() else { return false };
        self.stride = coarser;
        self.live = coarser.keeps(self.slice.0, self.slice.1);
        *self.frags = path::thin(self.back, self.spill, &self.stride, self.poll);
        true
    }
}

impl SurfaceSink for Keep<'_, '_, '_> {
    type Error = Infallible;
    #[inline(always)]
    fn command(&mut self, slice: SliceId, _level: usize, c: Command<Point3>) -> Result<(), Infallible> {
        let (axis, index) = (slice.plane.axis(), slice.index as u16);
        if (axis, index) != self.slice {
            self.enter_slice(axis, index);
        }
        // A row of a large slice at several levels yields hundreds of
        // commands: a board refills its output between some of them.
        self.since_poll = self.since_poll.wrapping_add(1);
        if self.since_poll >= KEEP_POLL {
            self.since_poll = 0;
            (self.poll)();
        }
        if !self.live {
            // A slice thinned away (while it was being contoured).
            return Ok(());
        }
        let starts = !matches!(c, Command::LineTo(_));
        // Nearly always: nothing spilled yet, and the back has room for
        // this command and one after it (what `keep` would find first).
        if self.spill.is_empty() && self.back.len() + 1 < self.back.capacity() {
            if self.back.push(c).is_ok() && starts {
                *self.frags = self.frags.saturating_add(1);
            }
            return Ok(());
        }
        self.keep(c, starts);
        Ok(())
    }
}

impl Keep<'_, '_, '_> {
    /// [`SurfaceSink::command`] once the back is nearly full: into the
    /// back's last slot, the spill, or (thinning first) either.
    #[inline(never)]
    fn keep(&mut self, c: Command<Point3>, starts: bool) {
        let kept = loop {
            let room = self.back.capacity().saturating_sub(self.back.len());
            // The back until the spill takes its first command (in order:
            // the spill's points come after all of the back's). A polyline
            // may go on from the back into the spill, but does not start in
            // the back's last slot (were the spill full, that `MoveTo` would
            // be left alone).
            let back = self.spill.capacity() == 0
                || (self.spill.is_empty() && (room > 1 || (room == 1 && !matches!(c, Command::MoveTo(_)))));
            if back && room > 0 {
                break self.back.push(c).is_ok();
            }
            if !back && self.spill_fits(&c) {
                break self.spill.push_within(c, usize::MAX).is_ok();
            }
            // Full: thin and try again, or (at the coarsest stride) refuse
            // it, counted.
            if !self.thin() {
                break if back { self.back.push(c).is_ok() } else { self.spill.push_within(c, 0).is_ok() };
            }
            if !self.live {
                return;
            }
        };
        if kept && starts {
            *self.frags = self.frags.saturating_add(1);
        }
    }
}

/// Samples `start, start + 1, ...` of a slice of little-endian samples,
/// widened to `f32` into all of `out` (NaN past the end).
fn decode(ty: SampleType, bytes: &[u8], start: usize, out: &mut [f32]) {
    // One loop per type (the type is not asked again per sample).
    match ty {
        SampleType::U8 => widen::<1>(bytes, start, out, |b| f32::from(b[0])),
        SampleType::U16 => widen::<2>(bytes, start, out, |b| f32::from(u16::from_le_bytes(b))),
        SampleType::I16 => widen::<2>(bytes, start, out, |b| f32::from(i16::from_le_bytes(b))),
        SampleType::F32 => widen::<4>(bytes, start, out, f32::from_le_bytes),
    }
}

/// [`decode`] for samples of `N` bytes, four a step: four loads and four
/// stores a step are not a copy to LLVM, where the plain loop of `f32`s
/// was (a call to `compiler_builtins`' `memcpy`, some 320 instructions
/// for a row of 32 samples on the board).
#[inline(always)]
fn widen<const N: usize>(bytes: &[u8], start: usize, out: &mut [f32], from: impl Fn([u8; N]) -> f32) {
    let samples = bytes.as_chunks::<N>().0.get(start..).unwrap_or(&[]);
    let n = out.len().min(samples.len());
    let (Some(head), Some(samples)) = (out.get_mut(..n), samples.get(..n)) else { return };
    let (quads, rest) = head.as_chunks_mut::<4>();
    let (squads, srest) = samples.as_chunks::<4>();
    for (o, &[a, b, c, d]) in quads.iter_mut().zip(squads) {
        o[0] = from(a);
        o[1] = from(b);
        o[2] = from(c);
        o[3] = from(d);
    }
    // The last one to three, spelled out (a loop would be a copy again).
    match (rest, srest) {
        ([o0], &[s0]) => *o0 = from(s0),
        ([o0, o1], &[s0, s1]) => (*o0, *o1) = (from(s0), from(s1)),
        ([o0, o1, o2], &[s0, s1, s2]) => (*o0, *o1, *o2) = (from(s0), from(s1), from(s2)),
        _ => {}
    }
    if let Some(past) = out.get_mut(n..) {
        past.fill(f32::NAN);
    }
}

/// A slab row's samples in the two slices held: rows `y` and `y + 1` of
/// the lower slice's bytes and of the upper's (empty for the last slice's
/// own slab), decoded block by block.
struct SliceRows<'s> {
    ty: SampleType,
    nx: usize,
    y: usize,
    lower: &'s [u8],
    upper: &'s [u8],
}

impl Rows for SliceRows<'_> {
    const KEEPS: bool = true;

    #[inline(always)]
    fn lanes<'b>(
        &'b self,
        x0: usize,
        n: usize,
        need: [bool; 4],
        fill: [bool; 4],
        [b0, b1, b2, b3]: [&'b mut Lane; 4],
    ) -> [&'b [f32]; 4] {
        let (ty, nx, n) = (self.ty, self.nx, n.min(slab::LANE));
        let row = move |k: usize, bytes: &[u8], y: usize, buf: &'b mut Lane| -> &'b [f32] {
            let on = need.get(k) == Some(&true);
            let out = buf.get_mut(..if on { n } else { 0 }).unwrap_or_default();
            if fill.get(k) == Some(&true) {
                decode(ty, bytes, y * nx + x0, out);
            }
            out
        };
        let (y, lo, up) = (self.y, self.lower, self.upper);
        [row(0, lo, y, b0), row(1, lo, y + 1, b1), row(2, up, y, b2), row(3, up, y + 1, b3)]
    }
}

/// The sizes whether the back may be folded is decided on: points the
/// back held after its last fold, points the front holds, and bytes of
/// the head of the slice memory.
#[derive(Debug, Clone, Copy)]
struct FoldRule {
    folded_len: usize,
    front_points: usize,
    head: usize,
}

impl FoldRule {
    /// Whether the back, about to outgrow its room, may be folded into
    /// the front now: nothing spilled yet, a quarter of it new since the
    /// last fold (each fold then gains), the front holds it, and the
    /// stitch pass's scratch fits what the head of the slice memory leaves
    /// beside the two slices from `at` on. Decided on these sizes alone,
    /// never on whether the front or the whole memory is at hand, so that
    /// every board folds at the same command.
    fn allows(self, back: &Geometry<'_>, frags: u32, spilled: usize, at: usize) -> bool {
        let fresh = back.len().saturating_sub(self.folded_len);
        spilled == 0
            && fresh >= back.capacity() / 4
            && back.len() <= self.front_points
            && path::stitch_reserve(frags as usize, back.len()) <= self.head.saturating_sub(at)
    }
}

impl<'a> Stream<'a> {
    /// A stream over a slice memory of `capacity` bytes.
    pub(crate) fn new(capacity: usize, rows: &'a mut RowMemory, front_points: usize) -> Self {
        Self {
            capacity,
            rows,
            wants_all: false,
            wants_fold: false,
            front_taken: false,
            folded_len: 0,
            front_points,
            cur: 0,
            transfer: None,
            spill: None,
        }
    }

    /// Bytes one slice may hold.
    pub(crate) fn slice_capacity(&self) -> usize {
        self.capacity / 2
    }

    /// Whether nothing needs the slice memory: no transfer, no spill
    /// waiting for its commit.
    pub(crate) fn idle(&self) -> bool {
        self.transfer.is_none() && self.spill.is_none()
    }

    /// Whether a row waits for the whole slice memory (it had the head
    /// alone); cleared by `take`.
    pub(crate) fn wants_all(&mut self, take: bool) -> bool {
        let w = self.wants_all;
        if take {
            self.wants_all = false;
        }
        w
    }

    /// Where a spill that starts at byte `at` of the slice memory ends: at
    /// the end of the head (the memory less [`super::replay_tail`]), so
    /// that a recording in the tail outlives the transfer and its commit;
    /// at the end of the memory for slices the head cannot hold. Fixed by
    /// the sizes alone, so every board thins alike.
    fn spill_end(&self, at: usize) -> usize {
        let head = self.head();
        if at <= head { head } else { self.capacity }
    }

    /// Bytes of the head of the slice memory: all of it less the tail a
    /// recording may keep ([`super::replay_tail`]).
    fn head(&self) -> usize {
        self.capacity.saturating_sub(super::replay_tail(self.capacity))
    }

    /// Whether a row waits for the engine (the whole memory, or a fold).
    pub(crate) fn waits(&self) -> bool {
        self.busy() && (self.wants_all || self.wants_fold)
    }

    /// Whether a row waits for the back to be folded
    /// ([`Stream::fold`]) by the engine, which has the front.
    pub(crate) fn wants_fold(&self) -> bool {
        self.wants_fold
    }

    /// The sizes whether the back may be folded is decided on
    /// ([`FoldRule::allows`]).
    fn fold_rule(&self) -> FoldRule {
        FoldRule { folded_len: self.folded_len, front_points: self.front_points, head: self.head() }
    }

    /// Stitch the back's pieces into maximal polylines (no merging: each
    /// segment stays in its slice, so thinning still finds it,
    /// [`path::thin`]) in the front, which then becomes the back: a
    /// volume's pieces stitched take a third less room or so, and its rows
    /// go on into the room freed ([`Stream::wants_fold`]). The picture on
    /// screen is gone from the front after it (`front_taken`): a board
    /// plays it on from its recording. The stitch pass's scratch is the
    /// stream's part of the slice memory, `slots`, past the two slices;
    /// `poll` is called as it goes on.
    pub(crate) fn fold<'g>(
        &mut self,
        slots: &mut [u8],
        back: &mut Geometry<'g>,
        front: &mut Geometry<'g>,
        poll: &mut dyn FnMut(),
    ) {
        self.wants_fold = false;
        let at = self.spill.map_or(slots.len(), |(at, _)| at);
        let Some(t) = self.transfer.as_mut() else { return };
        let scratch = slots.get_mut(at..).unwrap_or_default();
        let stitched =
            path::chain(path::Source::one(back), front, scratch, [0; 3], 0.0, path::Pass::Stitch, poll);
        core::mem::swap(back, front);
        front.reset(front.shift());
        t.frags = stitched.polylines;
        self.folded_len = back.len();
        self.front_taken = true;
    }

    /// Whether a transfer under way needs no more than the head of the
    /// slice memory (`head` bytes): its two slices fit there (its spill
    /// then stays there too, [`Stream::spill_end`]).
    pub(crate) fn fits_head(&self, head: usize) -> bool {
        self.transfer.is_some_and(|t| 2 * t.spec.slice_bytes() <= head)
    }

    /// Whether the last transfer's spill lies in the head of the slice
    /// memory (it began there, [`Stream::spill_end`]), or holds nothing.
    pub(crate) fn spill_in_head(&self) -> bool {
        self.spill.is_none_or(|(at, h)| at <= self.head() || (h.len() == 0 && h.dropped() == 0))
    }

    /// Between transfers: move a spill that began past the head (its
    /// slices took all of the slice memory, `slots`) into the head, laid
    /// out as one that began at its start; returns whether it lies in the
    /// head now. The slices it began after are done with.
    pub(crate) fn spill_into_head(&mut self, slots: &mut [u8]) -> bool {
        let head = self.head();
        let Some((at, held)) = self.spill else { return true };
        if self.spill_in_head() {
            return true;
        }
        let end = self.spill_end(at);
        if self.transfer.is_some() || end > slots.len() || Geometry::bytes_for(held.len()) > head {
            return false;
        }
        let moved = Geometry::move_down(slots.get_mut(..end).unwrap_or_default(), at, held, head);
        if moved.len() != held.len() {
            return false;
        }
        self.spill = Some((0, moved));
        true
    }

    /// What the last transfer spilled (counted with the back's).
    pub(crate) fn spilled(&self) -> Held {
        self.spill.map_or_else(Held::default, |(_, h)| h)
    }

    /// Between transfers: the last transfer's spill, moved to the start of
    /// the slice memory, and the rest of that memory as scratch. The spill
    /// is forgotten: once the volume is committed the memory is all
    /// scratch again ([`Stream::idle_scratch`]).
    pub(crate) fn take_spill<'s>(&mut self, slots: &'s mut [u8]) -> (Geometry<'s>, &'s mut [u8]) {
        let (at, held) = match (self.transfer, self.spill.take()) {
            (None, Some(spill)) => spill,
            _ => (0, Held::default()),
        };
        let end = self.spill_end(at).min(slots.len());
        let held = Geometry::move_to_front(slots.get_mut(..end).unwrap_or_default(), at, held);
        let (store, rest) = slots.split_at_mut(Geometry::bytes_for(held.len()).min(slots.len()));
        (Geometry::lent(store, held), rest)
    }

    /// Bytes of one slot: the transfer's slice, else the most a slice may
    /// hold.
    fn slot_bytes(&self) -> usize {
        self.transfer.map_or(usize::MAX, |t| t.spec.slice_bytes()).min(self.slice_capacity())
    }

    /// The two slots of `slots`: (current, previous).
    fn halves<'s>(&self, slots: &'s mut [u8]) -> (&'s mut [u8], &'s mut [u8]) {
        let n = self.slot_bytes().min(slots.len());
        let (a, rest) = slots.split_at_mut(n);
        let b = rest.get_mut(..n).unwrap_or(&mut []);
        if self.cur == 0 { (a, b) } else { (b, a) }
    }

    /// Start receiving a checked volume (its surface at `shift`).
    pub(crate) fn begin(&mut self, spec: VolumeSpec, now_ms: u32, shift: u8) {
        self.cur = 0;
        self.rows.0.forget();
        self.transfer = Some(Transfer {
            spec,
            z: 0,
            offset: 0,
            last_ms: now_ms,
            stats: ContourStats::default(),
            job: None,
            frags: 0,
            stride: Stride::new(spec.dims, spec.every),
        });
        // The spill starts after the transfer's two slots.
        self.spill = Some((2 * self.slot_bytes(), Held::empty(shift)));
        self.folded_len = 0;
        self.wants_fold = false;
    }

    /// Whether a completed slice still has contouring to do.
    pub(crate) fn busy(&self) -> bool {
        self.transfer.is_some_and(|t| t.job.is_some())
    }

    /// Take a chunk of slice `slice` at byte `offset`; when it completes the
    /// slice, contour what the slice completes into `geometry`, at once or,
    /// with `defer`, later ([`Stream::work`]). A job still pending from the
    /// slice before is finished first.
    ///
    /// `Busy` (not taken) if that job waits for the whole slice memory.
    #[expect(clippy::too_many_arguments, reason = "a chunk, its clock, and the memory it goes to")]
    pub(crate) fn chunk(
        &mut self,
        slots: &mut [u8],
        slice: u16,
        offset: u32,
        data: &[u8],
        now_ms: u32,
        geometry: &mut Geometry<'_>,
        defer: bool,
    ) -> Result<(), NackCode> {
        if !self.finish(slots, geometry) {
            return Err(NackCode::Busy);
        }
        let t = self.transfer.ok_or(NackCode::Aborted)?;
        let slice_bytes = t.spec.slice_bytes();
        if slice >= t.spec.dims[2] {
            return Err(NackCode::Invalid);
        }
        if (slice, offset) < (t.z, t.offset) {
            return Err(NackCode::Duplicate);
        }
        if (slice, offset) > (t.z, t.offset) {
            return Err(NackCode::OutOfOrder);
        }
        let start = offset as usize;
        let end = start + data.len();
        if data.is_empty() || end > slice_bytes {
            return Err(NackCode::Invalid);
        }
        let (slot, _) = self.halves(slots);
        slot.get_mut(start..end).ok_or(NackCode::DimsOverCapacity)?.copy_from_slice(data);
        let complete = end == slice_bytes;
        if let Some(t) = self.transfer.as_mut() {
            t.last_ms = now_ms;
            if complete {
                let mut job = Job { z: t.z, slot: self.cur, lower: t.z.saturating_sub(1), next: 0, plane: 0 };
                t.job = Self::ahead(&t.spec, &t.stride, &mut job).then_some(job);
                t.z += 1;
                t.offset = 0;
            } else {
                t.offset = end as u32;
            }
        }
        if complete {
            self.cur = 1 - self.cur;
            if !defer {
                // (Not deferred, the whole memory is lent: it never waits.)
                self.finish(slots, geometry);
            }
        }
        Ok(())
    }

    /// Finish the pending job, if any; false if it waits for the whole
    /// slice memory ([`Stream::wants_all`]).
    pub(crate) fn finish(&mut self, slots: &mut [u8], geometry: &mut Geometry<'_>) -> bool {
        while self.work(slots, geometry, usize::MAX) {
            if self.wants_all || self.wants_fold {
                return false;
            }
        }
        true
    }

    /// Contour whole rows of subgrids of the pending job into `geometry`,
    /// at least one and until `cells` cells are done. Returns whether some
    /// are left.
    pub(crate) fn work(&mut self, slots: &mut [u8], geometry: &mut Geometry<'_>, cells: usize) -> bool {
        self.work_while(slots, geometry, |done| done < cells, &mut || {})
    }

    /// Contour whole rows of subgrids of the pending job into `geometry`:
    /// one, then more while `more(cells done)` says so. Returns whether
    /// some are left. A row waits (none is done) when the back may not
    /// have room for it and may be folded ([`Stream::wants_fold`]: the
    /// engine folds it at the next update), or, with the head of the slice
    /// memory alone, when it may not be (the stream asks for the whole
    /// memory, [`Stream::wants_all`]). `poll` is called as a thinning of
    /// the surface goes on (it passes over all of it).
    pub(crate) fn work_while(
        &mut self,
        slots: &mut [u8],
        geometry: &mut Geometry<'_>,
        mut more: impl FnMut(usize) -> bool,
        poll: &mut dyn FnMut(),
    ) -> bool {
        let Some(mut t) = self.transfer else { return false };
        let Some(mut job) = t.job else { return false };
        let mut stats = ContourStats::default();
        let mut left = true;
        let n = self.slot_bytes();
        let (at, held) = self.spill.unwrap_or((2 * n, Held::empty(geometry.shift())));
        let end = self.spill_end(at);
        // With the head alone lent, all the spill may have (else the row
        // waits for the whole memory: slices the head cannot hold).
        let short = slots.len() < end;
        let (slots, rest) = slots.split_at_mut(at.min(slots.len()));
        let rest = rest.get_mut(..end.saturating_sub(at)).unwrap_or_default();
        let mut spill = Geometry::lent(rest, held);
        let fold = self.fold_rule();
        let mut slab = Slab::new(t.spec.levels.as_slice(), Traversal::Compiled, &mut self.rows.0);
        let mut done = 0usize;
        let bound = Self::row_bound(&t.spec);
        let mut sink = Keep {
            poll,
            back: geometry,
            spill: &mut spill,
            frags: &mut t.frags,
            memory: self.capacity,
            stride: t.stride,
            slice: (2, 0),
            live: true,
            since_poll: 0,
        };
        let (s0, s1) = slots.split_at(n.min(slots.len()));
        let slots = [s0, s1];
        loop {
            // More than a row can yield, and one: the back keeps the
            // row's every command, and never at its last slot, as it
            // does with the whole memory lent (see `Keep`).
            let room = sink.back.capacity().saturating_sub(sink.back.len());
            if room <= bound {
                if fold.allows(sink.back, *sink.frags, sink.spill.len(), at) {
                    self.wants_fold = true;
                    break;
                }
                if short {
                    self.wants_all = true;
                    break;
                }
            }
            // As many planes of the row at once as the checks above, made
            // before each plane, would let through (fewer, longer steps):
            // all that the back has room for, and the whole row once the
            // spill has begun (a fold needs an empty spill, and a row with
            // the head alone never spills; a thinning that empties the
            // spill within the row is checked at the next row).
            let planes = if !sink.spill.is_empty() && !short {
                3
            } else {
                (room.saturating_sub(1) / bound.max(1)).clamp(1, 3) as u8
            };
            done = done.saturating_add(Self::row(
                &t.spec, &mut job, planes, &mut slab, slots, &mut sink, &mut stats,
            ));
            // On to the next step with something to do; done as soon as
            // the last row is: no empty call after it.
            if !Self::ahead(&t.spec, &sink.stride, &mut job) {
                left = false;
                break;
            }
            if !more(done) {
                break;
            }
        }
        t.stride = sink.stride;
        self.spill = Some((at, spill.held()));
        t.stats += stats;
        t.job = left.then_some(job);
        self.transfer = Some(t);
        left
    }

    /// The most commands a row of one plane may yield: at most `nx` cells
    /// ([`MAX_COMMANDS_A_CELL`] a cell and level).
    fn row_bound(spec: &VolumeSpec) -> usize {
        usize::from(spec.dims[0]) * spec.levels.len() * MAX_COMMANDS_A_CELL
    }

    /// What the planes `planes` (0 x-y, 1 x-z, 2 y-z) of row `y` of the
    /// slab on slice `lower` contour under `stride`: those asked for, in
    /// the slices kept.
    fn cut(spec: &VolumeSpec, stride: &Stride, lower: u16, y: usize, planes: Range<u8>) -> Cut {
        Cut {
            xy: planes.contains(&0) && spec.axes & AXIS_Z != 0 && stride.keeps(2, lower),
            xz: planes.contains(&1) && spec.axes & AXIS_Y != 0 && stride.keeps(1, y as u16),
            yz: if planes.contains(&2) && spec.axes & AXIS_X != 0 {
                Every { first: stride.next(0, 0), step: usize::from(stride.every.max(1)) }
            } else {
                Every::NONE
            },
        }
    }

    /// Move `job` past the steps with nothing to do (under `stride`, which
    /// may have grown since the last step) and past the slabs done;
    /// whether a step is left.
    fn ahead(spec: &VolumeSpec, stride: &Stride, job: &mut Job) -> bool {
        let ny = usize::from(spec.dims[1]);
        let last = job.z + 1 == spec.dims[2];
        loop {
            // The slab between `lower` and `z`, then the last slice's own.
            let up = job.lower < job.z;
            if !(up || (job.lower == job.z && last)) {
                return false;
            }
            let y = job.next as usize;
            if y >= ny {
                job.lower += 1;
                job.next = 0;
                job.plane = 0;
                continue;
            }
            let cut = Self::cut(spec, stride, job.lower, y, job.plane..job.plane + 1);
            if !cut.within(y + 1 < ny, up).is_empty() {
                return true;
            }
            job.past(job.plane + 1);
        }
    }

    /// Contour the step `job` stands at (one with something to do, see
    /// [`Job`]), up to `planes` planes of its row, and move past it;
    /// returns its cells.
    fn row(
        spec: &VolumeSpec,
        job: &mut Job,
        planes: u8,
        slab: &mut Slab<'_, '_, 1, QUIET_ROWS>,
        [s0, s1]: [&[u8]; 2],
        sink: &mut Keep<'_, '_, '_>,
        stats: &mut ContourStats,
    ) -> usize {
        let [nx, ny] = [usize::from(spec.dims[0]), usize::from(spec.dims[1])];
        let y = job.next as usize;
        let (cur, prev): (&[u8], &[u8]) = if job.slot == 0 { (s0, s1) } else { (s1, s0) };
        let up = job.lower < job.z;
        let (lower, upper) = if up { (prev, cur) } else { (cur, &[][..]) };
        let rows = SliceRows { ty: spec.sample_type, nx, y, lower, upper };
        let end = (job.plane + planes).min(3);
        let cut = Self::cut(spec, &sink.stride, job.lower, y, job.plane..end);
        let before = stats.cells;
        let _ = slab.row(&rows, [nx, ny], y, usize::from(job.lower), up, cut, sink, stats);
        job.past(end);
        (stats.cells - before).max(1) as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contour::grid::{Plane, Planes, Volume};
    use crate::path::{Kind, Source};

    /// `cmds` kept in a back of `back` points and a spill of `spill`: how
    /// many points each holds, and all of them in order (x, kind).
    fn keep_all(back: usize, spill: usize, cmds: &[Command<Point3>]) -> ([usize; 2], Vec<(u16, Kind)>) {
        let (mut b, mut s) = (vec![0u8; Geometry::bytes_for(back)], vec![0u8; Geometry::bytes_for(spill)]);
        let (mut back, mut spill) = (Geometry::new(&mut b), Geometry::new(&mut s));
        let mut frags = 0;
        let mut keep = Keep {
            poll: &mut || {},
            back: &mut back,
            spill: &mut spill,
            frags: &mut frags,
            memory: usize::MAX,
            stride: Stride::new([2; 3], 1),
            slice: (2, 0),
            live: true,
            since_poll: 0,
        };
        for &c in cmds {
            let _ = keep.command(SliceId { plane: Plane::XY, index: 0 }, 0, c);
        }
        let src = Source::two(&back, &spill);
        let got = (0..src.len()).filter_map(|i| src.get(i)).map(|(q, k)| (q[0], k)).collect();
        ([back.len(), spill.len()], got)
    }

    #[test]
    fn pieces_go_on_in_the_spill_in_order() {
        let p = |x: f32| Point3::new(x, 0.0, 0.0);
        let (m, l, d) = (Kind::Move, Kind::Line, Kind::Dot);
        // A back of 3 points: a polyline does not start in its last slot,
        // and once the spill has a point, everything after goes there too.
        let cmds = [
            Command::MoveTo(p(1.0)),
            Command::LineTo(p(2.0)),
            Command::MoveTo(p(3.0)),
            Command::LineTo(p(4.0)),
            Command::Point(p(5.0)),
            Command::MoveTo(p(6.0)),
            Command::LineTo(p(7.0)),
        ];
        let (lens, got) = keep_all(3, 10, &cmds);
        assert_eq!(lens, [2, 5]);
        assert_eq!(got, [(1, m), (2, l), (3, m), (4, l), (5, d), (6, m), (7, l)]);
        // A line that reaches the back's end goes on in the spill.
        let (lens, got) =
            keep_all(2, 4, &[Command::MoveTo(p(1.0)), Command::LineTo(p(2.0)), Command::LineTo(p(3.0))]);
        assert_eq!(got, [(1, m), (2, l), (3, l)]);
        assert_eq!(lens, [2, 1]);
    }

    /// A volume received slice by slice keeps the very commands of
    /// contouring it whole, in the very order (rows of one block, as the
    /// board's; each sample type; a NaN, samples at a level, every plane
    /// and a stride of two).
    #[test]
    fn a_stream_keeps_whole_volume_contouring_in_order() {
        let (nx, ny, nz) = (13usize, 9usize, 7usize);
        let mut values: Vec<f32> = (0..nx * ny * nz)
            .map(|k| {
                let (x, y, z) = ((k % nx) as f32, (k / nx % ny) as f32, (k / (nx * ny)) as f32);
                ((x * 0.7).sin() * 40.0 + (y * 0.5).cos() * 30.0 + (z * 0.9).sin() * 20.0 + 100.0).round()
            })
            .collect();
        values[3 * nx * ny + 2 * nx + 5] = f32::NAN;
        let dims = [nx as u16, ny as u16, nz as u16];
        let levels = [100.0f32, 131.5];
        for ty in SampleType::ALL {
            for (axes, every) in [
                (AXIS_X | AXIS_Y | AXIS_Z, 1),
                (AXIS_X | AXIS_Z, 1),
                (AXIS_Y, 1),
                (AXIS_X | AXIS_Y | AXIS_Z, 2),
            ] {
                let vals: Vec<f32> = values
                    .iter()
                    .map(|&v| if ty == SampleType::F32 || v.is_finite() { v } else { 0.0 })
                    .collect();
                let shift = Geometry::shift_for(dims);
                let (mut wb, mut gb) =
                    (vec![0u8; Geometry::bytes_for(20_000)], vec![0u8; Geometry::bytes_for(20_000)]);
                let mut want = Geometry::new(&mut wb);
                want.reset(shift);
                // The whole volume, slab by slab as contour_slab goes, the
                // slices `every` apart.
                let volume = Volume::new(&vals, nx, ny, nz).unwrap();
                let stride = Stride::new(dims, every);
                let planes = [(AXIS_Z, Plane::XY), (AXIS_Y, Plane::XZ), (AXIS_X, Plane::YZ)];
                let set = planes.iter().filter(|p| axes & p.0 != 0).fold(Planes::NONE, |s, p| s.with(p.1));
                let mut all = Vec::new();
                {
                    struct Tagged<'v>(&'v mut Vec<(SliceId, Command<Point3>)>);
                    impl SurfaceSink for Tagged<'_> {
                        type Error = Infallible;
                        fn command(
                            &mut self,
                            s: SliceId,
                            _: usize,
                            c: Command<Point3>,
                        ) -> Result<(), Infallible> {
                            self.0.push((s, c));
                            Ok(())
                        }
                    }
                    crate::contour::surface::contour_volume(
                        &volume,
                        set,
                        &levels,
                        Traversal::Compiled,
                        &mut Tagged(&mut all),
                    )
                    .unwrap();
                }
                for (_, c) in all.iter().filter(|(s, _)| stride.keeps(s.plane.axis(), s.index as u16)) {
                    let _ = want.push(*c);
                }
                // The stream, fed whole slices.
                let spec = VolumeSpec {
                    dims,
                    sample_type: ty,
                    spacing: [1.0; 3],
                    levels: Levels::from_slice(&levels).unwrap(),
                    axes,
                    every,
                };
                let mut rows = RowMemory::new();
                let mut slots = vec![0u8; 2 * spec.slice_bytes()];
                let mut stream = Stream::new(slots.len(), &mut rows, 20_000);
                let mut got = Geometry::new(&mut gb);
                got.reset(shift);
                stream.begin(spec, 0, shift);
                for z in 0..nz {
                    let bytes: Vec<u8> = vals[z * nx * ny..(z + 1) * nx * ny]
                        .iter()
                        .flat_map(|&v| match ty {
                            SampleType::U8 => vec![v as u8],
                            SampleType::U16 => (v as u16).to_le_bytes().to_vec(),
                            SampleType::I16 => (v as i16).to_le_bytes().to_vec(),
                            SampleType::F32 => v.to_le_bytes().to_vec(),
                        })
                        .collect();
                    stream.chunk(&mut slots, z as u16, 0, &bytes, 0, &mut got, false).unwrap();
                }
                let (got, want) = (got.commands().collect::<Vec<_>>(), want.commands().collect::<Vec<_>>());
                assert!(want.len() > 100, "{ty:?} {axes} {every}: {}", want.len());
                assert_eq!(got, want, "{ty:?} axes {axes} every {every}");
            }
        }
    }

    #[test]
    fn decode_little_endian_types() {
        let mut out = [0.0f32; 3];
        decode(SampleType::U8, &[1, 2, 3, 4, 5, 6], 1, &mut out);
        assert_eq!(out, [2.0, 3.0, 4.0]);
        decode(SampleType::U16, &[0x34, 0x12, 0xFF, 0xFF], 0, &mut out);
        assert_eq!(out[..2], [4660.0, 65535.0]);
        assert!(out[2].is_nan(), "past the end is NaN");
        decode(SampleType::I16, &[0xFE, 0xFF, 0x00, 0x80], 0, &mut out[..2]);
        assert_eq!(out[..2], [-2.0, -32768.0]);
        decode(SampleType::F32, &1.5f32.to_le_bytes(), 0, &mut out[..1]);
        assert_eq!(out[0], 1.5);
    }

    proptest::proptest! {
        #[test]
        fn decode_takes_each_sample_and_nan_past_the_end(
            bytes in proptest::collection::vec(proptest::num::u8::ANY, 0..200),
            start in 0usize..60,
            n in 0usize..50,
        ) {
            for ty in SampleType::ALL {
                let size = ty.size();
                let mut out = vec![0.0f32; n];
                decode(ty, &bytes, start, &mut out);
                for (k, &got) in out.iter().enumerate() {
                    let at = (start + k) * size;
                    let want = bytes.get(at..at + size).map_or(f32::NAN, |b| match ty {
                        SampleType::U8 => f32::from(b[0]),
                        SampleType::U16 => f32::from(u16::from_le_bytes([b[0], b[1]])),
                        SampleType::I16 => f32::from(i16::from_le_bytes([b[0], b[1]])),
                        SampleType::F32 => f32::from_le_bytes([b[0], b[1], b[2], b[3]]),
                    });
                    proptest::prop_assert_eq!(got.to_bits(), want.to_bits(), "{:?} sample {}", ty, k);
                }
            }
        }
    }
}
