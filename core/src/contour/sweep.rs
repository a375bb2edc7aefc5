//! The inner loop: sweep rows of cells in blocks, skipping the cells no
//! level meets.
//!
//! Each sample is classed once a row ([`Sweep::classify`]): finite and
//! above every level, finite and below every level, or neither (a level
//! may pass it, or it is not finite), as two bits of a byte. A cell no
//! level meets has its four corners in one class: the AND of their bytes
//! is not zero. Both passes are branch-free loops over bytes that
//! vectorise; the few cells left (a few percent in a real volume,
//! [`each_busy`] finds them eight at a time) build a subgrid and run their
//! traversal, and those touching a non-finite sample are skipped there and
//! counted.
//!
//! The whole grid ([`crate::contour::contour_rows`]) and the engine's
//! streaming rows ([`Sweep::run_rows`]) take cells between two rows of
//! samples; a volume's slab of all three planes at once
//! ([`crate::contour::surface::contour_slab`]) takes the four rows around
//! a cell row of every plane.

use super::batch::Batch;
use super::pen::Placement;
use super::subgrid::Node;
use super::subgrid::Subgrid;
use super::trace::Traversal;
use super::voxel::Voxel;
use super::{ContourStats, compiled, contour_subgrid, draw_program};
use crate::command::CommandSink;

/// Cells per block. The scratch space is about 17 bytes per cell (2.2 KiB
/// of stack).
pub(crate) const BLOCK: usize = 128;

/// `n` samples, `stride` apart from `start`, as `f32`: borrowed from
/// `data` when they are contiguous `f32`s, otherwise converted into `buf`
/// (NaN past the end of `data`; the callers' views are checked, so that does
/// not happen).
#[inline(always)]
pub(crate) fn lane<'a, T: Voxel>(
    data: &'a [T],
    start: usize,
    stride: usize,
    n: usize,
    buf: &'a mut [f32; BLOCK + 1],
) -> &'a [f32] {
    let n = n.min(BLOCK + 1);
    if stride == 1
        && let Some(src) = data.get(start..start.saturating_add(n))
    {
        if let Some(f) = T::as_f32s(src) {
            return f;
        }
        for (o, s) in buf.iter_mut().zip(src) {
            *o = s.to_f32();
        }
        return buf.get(..n).unwrap_or(&[]);
    }
    for (k, o) in buf.iter_mut().take(n).enumerate() {
        *o = data.get(start.wrapping_add(k.wrapping_mul(stride))).map_or(f32::NAN, |s| s.to_f32());
    }
    buf.get(..n).unwrap_or(&[])
}

/// A float's bits as an integer in the same order (`-0.0` just below
/// `+0.0`, NaNs beyond the infinities): an integer compare instead of a
/// float compare and a move of the flags on the MCU.
#[inline(always)]
fn key(v: f32) -> i32 {
    let b = v.to_bits() as i32;
    b ^ ((b >> 31) & 0x7FFF_FFFF)
}

/// Keys strictly between `lo` and `hi` (`lo < hi`): one subtraction and
/// one unsigned compare, as a borrow.
#[derive(Debug, Clone, Copy)]
struct Between {
    /// `lo + 1`.
    from: i32,
    /// Keys from `from` on that are in.
    span: u32,
}

impl Between {
    fn new(lo: i32, hi: i32) -> Self {
        Self { from: lo.wrapping_add(1), span: (hi.wrapping_sub(lo) as u32).wrapping_sub(1) }
    }

    /// All ones when `k` is in, else 0: [`Between::mask_borrow`] on the
    /// MCU, [`Between::mask_compare`] where rows are classed by SIMD.
    #[inline(always)]
    fn mask(self, k: i32) -> u32 {
        #[cfg(target_arch = "arm")]
        return self.mask_borrow(k);
        #[cfg(not(target_arch = "arm"))]
        return self.mask_compare(k);
    }

    /// [`Between::mask`] as the borrow of `k - from` less `span`, a 64-bit
    /// subtraction's high word: a subtraction and a subtraction with carry
    /// on the M4, where a compare makes its flag a value with a conditional
    /// move.
    #[inline(always)]
    #[cfg_attr(not(any(test, target_arch = "arm")), allow(dead_code))]
    fn mask_borrow(self, k: i32) -> u32 {
        (u64::from(k.wrapping_sub(self.from) as u32).wrapping_sub(u64::from(self.span)) >> 32) as u32
    }

    /// [`Between::mask`] as an unsigned compare: four lanes a 128-bit
    /// vector (a biased signed compare on SSE2), where the 64-bit borrow
    /// takes two a vector and a shuffle to pack them (the x86-64 skip path
    /// ran some 1.3 times slower with it).
    #[inline(always)]
    #[cfg_attr(target_arch = "arm", allow(dead_code))]
    fn mask_compare(self, k: i32) -> u32 {
        u32::from((k.wrapping_sub(self.from) as u32) < self.span).wrapping_neg()
    }
}

/// A sample's class against the levels: [`ABOVE`] when it is finite and
/// above every level, [`BELOW`] when finite and below every level, 0
/// otherwise (a level may pass it, or it is not finite). A cell no level
/// meets is one whose four corners share a class bit: the AND of their
/// classes is not zero.
pub(crate) const ABOVE: u8 = 1;
/// See [`ABOVE`].
pub(crate) const BELOW: u8 = 2;

/// Class bytes of up to `BLOCK + 1` samples, rounded up to whole words of
/// eight (a scan reads whole words and masks the bytes past its end). The
/// passes touch only the bytes of the row at hand: a board's rows are
/// short.
pub(crate) type Classes = [u8; BLOCK + 9];

impl Sweep<'_> {
    /// The classes of `row` into `out` (see [`ABOVE`]); the bytes past the
    /// row are set quiet. Branch-free: it vectorises. Not inlined: a slab
    /// row classes up to six rows in as many places, and inlined each copy
    /// held the levels' bounds in registers that the whole row, called
    /// once a row of the volume, then spilled and set up on every call.
    /// In WebAssembly it is built with SIMD (`simd128`), as the page's
    /// painter is, though the module as a whole is not (docs/web.md): the
    /// classes are integer operations alone, four samples a step.
    #[inline(never)]
    #[cfg_attr(target_arch = "wasm32", target_feature(enable = "simd128"))]
    pub(crate) fn classify(&self, row: &[f32], out: &mut Classes) {
        let (above, below) = (self.above, self.below);
        let class = |v: f32| {
            let k = key(v);
            ((above.mask(k) & u32::from(ABOVE)) | (below.mask(k) & u32::from(BELOW))) as u8
        };
        #[cfg(target_arch = "arm")]
        class_quads(row, out, class);
        #[cfg(not(target_arch = "arm"))]
        class_each(row, out, class);
    }
}

/// `class` of each sample of `row` into `out`, four samples a step: the MCU
/// does not vectorise, and a step costs its loop's count and branch once.
#[inline(always)]
#[cfg_attr(not(any(test, target_arch = "arm")), allow(dead_code))]
fn class_quads(row: &[f32], out: &mut Classes, class: impl Fn(f32) -> u8) {
    let (quads, rest) = row.as_chunks::<4>();
    let (outs, _) = out.as_chunks_mut::<4>();
    for (o, &[a, b, c, d]) in outs.iter_mut().zip(quads) {
        *o = [class(a), class(b), class(c), class(d)];
    }
    let tail = outs.get_mut(quads.len()..).unwrap_or_default().as_flattened_mut();
    for (o, &v) in tail.iter_mut().zip(rest) {
        *o = class(v);
    }
}

/// [`class_quads`] one sample a step, a loop the compiler vectorises as
/// wide as the target allows (sixteen samples a step on x86-64, where four
/// a step packed each quad's bytes apart: the skip path ran some 1.3 times
/// slower).
#[inline(always)]
#[cfg_attr(target_arch = "arm", allow(dead_code))]
fn class_each(row: &[f32], out: &mut Classes, class: impl Fn(f32) -> u8) {
    for (o, &v) in out.iter_mut().zip(row) {
        *o = class(v);
    }
}

impl Sweep<'_> {}

/// `m[k]` for the `n` cells between two rows of classes: the AND of the
/// classes of samples `k` and `k + 1` of both. Eight cells a word (the
/// bytes of `m` past `n` are left undefined: [`each_busy`] masks them).
#[inline(always)]
pub(crate) fn and_along(m: &mut Classes, a: &Classes, b: &Classes, n: usize) {
    let (aw, _) = a.as_chunks::<8>();
    let (bw, _) = b.as_chunks::<8>();
    let (mw, _) = m.as_chunks_mut::<8>();
    // Both rows' classes of eight samples, ANDed.
    let both = |w: usize| match (aw.get(w), bw.get(w)) {
        (Some(a), Some(b)) => u64::from_le_bytes(*a) & u64::from_le_bytes(*b),
        _ => 0,
    };
    let mut next = both(0);
    for (w, o) in mw.iter_mut().enumerate().take(n.div_ceil(8)) {
        let cur = next;
        next = both(w + 1);
        // Sample `k + 1` of each byte `k`: the next word's first byte
        // comes in at the top.
        *o = (cur & ((cur >> 8) | (next << 56))).to_le_bytes();
    }
}

/// `m[k]` for `n` samples of four rows of classes: the AND of sample `k`'s.
#[inline(always)]
pub(crate) fn and_across(m: &mut Classes, [a, b, c, d]: [&Classes; 4], n: usize) {
    let m = m.get_mut(..n).unwrap_or(&mut []);
    for ((((o, &a), &b), &c), &d) in m.iter_mut().zip(a).zip(b).zip(c).zip(d) {
        *o = a & b & c & d;
    }
}

/// The class bits that all of the first `n` samples of `c` share (0: some
/// level may meet a cell among them): whole words, the bytes past `n`
/// counted as sharing every bit.
#[inline(always)]
pub(crate) fn quiet_bits(c: &Classes, n: usize) -> u8 {
    let (words, _) = c.as_chunks::<8>();
    let full = n / 8;
    let mut all = !0u64;
    for bytes in words.iter().take(full) {
        all &= u64::from_le_bytes(*bytes);
    }
    if !n.is_multiple_of(8)
        && let Some(bytes) = words.get(full)
    {
        all &= u64::from_le_bytes(*bytes) | (!0u64 << (8 * (n % 8)));
    }
    let all = all & (all >> 32);
    let all = all & (all >> 16);
    (all & (all >> 8)) as u8 & (ABOVE | BELOW)
}

/// Hand `f` the index of every zero byte of `m[..n]`, in order: the cells
/// some level may meet (`m` holds the AND of their corners' classes). Eight
/// bytes at a time: a word with no zero byte, the common case, costs one
/// test.
#[inline(always)]
pub(crate) fn each_busy<E>(
    m: &Classes,
    n: usize,
    mut f: impl FnMut(usize) -> Result<(), E>,
) -> Result<(), E> {
    const LOW7: u64 = 0x7F7F_7F7F_7F7F_7F7F;
    let (words, _) = m.as_chunks::<8>();
    for (w, bytes) in words.iter().enumerate() {
        let first = 8 * w;
        if first >= n {
            break;
        }
        let v = u64::from_le_bytes(*bytes);
        // The top bit of each zero byte, exactly (no borrow between bytes).
        let mut zero = !(((v & LOW7) + LOW7) | v) & !LOW7;
        if n - first < 8 {
            zero &= (1u64 << (8 * (n - first))) - 1;
        }
        while zero != 0 {
            f(first + zero.trailing_zeros() as usize / 8)?;
            zero &= zero - 1;
        }
    }
    Ok(())
}

/// Scratch space for one block: lane buffers for samples that need
/// converting, the classes of four rows and the cells' AND of them.
#[derive(Debug)]
pub(crate) struct Scratch {
    pub bufs: [[f32; BLOCK + 1]; 4],
    pub classes: [Classes; 5],
    pub batch: Batch,
}

impl Scratch {
    pub(crate) const fn new() -> Self {
        Self { bufs: [[0.0; BLOCK + 1]; 4], classes: [[0; BLOCK + 9]; 5], batch: Batch::new() }
    }
}

/// Levels and traversal of one contouring run.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Sweep<'l> {
    pub levels: &'l [f32],
    pub traversal: Traversal,
    /// Finite samples above every level, and below every level.
    above: Between,
    below: Between,
}

impl<'l> Sweep<'l> {
    /// A sweep over finite `levels` (checked by the caller).
    pub(crate) fn new(levels: &'l [f32], traversal: Traversal) -> Self {
        let (klo, khi) =
            levels.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &l| (a.min(l), b.max(l)));
        // Above `khi` in the float order (`-0.0` is not above `0.0`) and
        // below `klo` (`0.0` is not below `-0.0`), and finite.
        let above = Between::new(key(khi + 0.0), key(f32::INFINITY));
        let below = Between::new(key(f32::NEG_INFINITY), key(if klo == 0.0 { -0.0 } else { klo }));
        Self { levels, traversal, above, below }
    }

    /// Contour the cells between two rows of samples: cell `k` has corners
    /// `lower[k], lower[k + 1], upper[k + 1], upper[k]` (the shorter row,
    /// up to `BLOCK + 1` samples, sets the cells), sits at `at(k)` in its
    /// grid, and its points are placed by `place(k, x, y)`. `scratch` holds
    /// the rows' classes.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn run_rows<P, S: CommandSink<P>>(
        &self,
        lower: &[f32],
        upper: &[f32],
        [lo, up, m]: [&mut Classes; 3],
        batch: &mut Batch,
        at: impl Fn(usize) -> Placement,
        place: impl Fn(usize, f32, f32) -> P,
        sink: &mut S,
        stats: &mut ContourStats,
    ) -> Result<(), S::Error> {
        let samples = lower.len().min(upper.len()).min(BLOCK + 1);
        let (lower, upper) = (lower.get(..samples).unwrap_or(&[]), upper.get(..samples).unwrap_or(&[]));
        self.classify(lower, lo);
        self.classify(upper, up);
        self.run_classed(lower, upper, [lo, up], m, batch, at, place, sink, stats)
    }

    /// [`Sweep::run_rows`] for rows whose classes `lo` and `up` are already
    /// known (a slab classes a row once for several planes); `m` is
    /// scratch.
    #[inline(never)]
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn run_classed<P, S: CommandSink<P>>(
        &self,
        lower: &[f32],
        upper: &[f32],
        [lo, up]: [&Classes; 2],
        m: &mut Classes,
        batch: &mut Batch,
        at: impl Fn(usize) -> Placement,
        place: impl Fn(usize, f32, f32) -> P,
        sink: &mut S,
        stats: &mut ContourStats,
    ) -> Result<(), S::Error> {
        let cells = lower.len().min(upper.len()).min(BLOCK + 1).saturating_sub(1);
        and_along(m, lo, up, cells);
        let corners = |k: usize| match (lower.get(k), lower.get(k + 1), upper.get(k + 1), upper.get(k)) {
            (Some(&a), Some(&b), Some(&c), Some(&d)) => Some([a, b, c, d]),
            _ => None,
        };
        if self.batched() {
            batch.gather(m, cells, self.level(), |k| Some((corners(k)?, at(k))));
            return batch.each(|i, k, corners, program| match program {
                Some(p) => batch.draw(i, p, &|x, y| place(k, x, y), sink, stats),
                None => self.cell_aside(corners, at(k), &|x, y| place(k, x, y), sink, stats),
            });
        }
        let classes = |k: usize| match (lo.get(k), lo.get(k + 1), up.get(k + 1), up.get(k)) {
            (Some(&a), Some(&b), Some(&c), Some(&d)) => [a, b, c, d],
            _ => [0; 4],
        };
        // The classes help at one level only: the loop is chosen once.
        if self.classed() {
            return each_busy(m, cells, |k| match corners(k) {
                Some(c) => self.cell_classed(c, classes(k), at(k), &|x, y| place(k, x, y), sink, stats),
                None => Ok(()),
            });
        }
        each_busy(m, cells, |k| match corners(k) {
            Some(c) => self.cell(c, at(k), &|x, y| place(k, x, y), sink, stats),
            None => Ok(()),
        })
    }

    /// Whether [`Sweep::cell_classed`] draws some cells from their classes:
    /// one level, the compiled traversal.
    #[inline(always)]
    pub(crate) fn classed(&self) -> bool {
        self.levels.len() == 1 && self.traversal == Traversal::Compiled
    }

    /// [`Sweep::cell`] for a cell whose corners' classes are known, in
    /// the same order (LL, LR, UR, UL). At one level a corner of class
    /// [`ABOVE`] or [`BELOW`] is finite and off the level, on the side the
    /// class says: when all four are, the cell is finite, crosses the
    /// level (it is busy: its corners lie on both sides) and has no
    /// corner at it, so only the centre is compared before its compiled
    /// program is drawn. Others take [`Sweep::cell`]: the same commands.
    #[inline(always)]
    pub(crate) fn cell_classed<P, S: CommandSink<P>>(
        &self,
        corners: [f32; 4],
        [ca, cb, cc, cd]: [u8; 4],
        at: Placement,
        place: &impl Fn(f32, f32) -> P,
        sink: &mut S,
        stats: &mut ContourStats,
    ) -> Result<(), S::Error> {
        if let &[level] = self.levels
            && self.classed()
            && (ca != 0) & (cb != 0) & (cc != 0) & (cd != 0)
        {
            let [a, b, c, d] = corners;
            let sub = Subgrid::from_finite(a, b, c, d);
            let m = sub.value(Node::C);
            // Corner `n` lies below the level when its class is BELOW
            // (bit 1): bit `n` of the nodes below, as `Subgrid::below`.
            let below = ((ca & BELOW) >> 1)
                | (cb & BELOW)
                | ((cc & BELOW) << 1)
                | ((cd & BELOW) << 2)
                | (u8::from(m <= level) << 4);
            if m != level
                && let Some(program) = compiled::program(sub.code(), below)
            {
                let mut sent = 0u32;
                draw_program(
                    program,
                    |e| Some(at.along(e, sub.crossing_inside(e, level))),
                    |c| {
                        sent += 1;
                        sink.command(0, c.map(|(x, y)| place(x, y)))
                    },
                )?;
                stats.crossing_cells += u64::from(sent > 0);
                stats.commands += u64::from(sent);
                return Ok(());
            }
        }
        self.cell(corners, at, place, sink, stats)
    }

    /// [`Sweep::cell`] as a call: for the few cells the batch leaves
    /// (a node at the level, a non-finite corner), so that the batch's
    /// loop stays small.
    #[inline(never)]
    #[cold]
    pub(crate) fn cell_aside<P, S: CommandSink<P>>(
        &self,
        corners: [f32; 4],
        at: Placement,
        place: &impl Fn(f32, f32) -> P,
        sink: &mut S,
        stats: &mut ContourStats,
    ) -> Result<(), S::Error> {
        self.cell(corners, at, place, sink, stats)
    }

    /// Contour one cell that the classes did not skip.
    #[inline(always)]
    pub(crate) fn cell<P, S: CommandSink<P>>(
        &self,
        [a, b, c, d]: [f32; 4],
        at: Placement,
        place: &impl Fn(f32, f32) -> P,
        sink: &mut S,
        stats: &mut ContourStats,
    ) -> Result<(), S::Error> {
        if !(a.is_finite() & b.is_finite() & c.is_finite() & d.is_finite()) {
            stats.nonfinite_cells += 1;
            return Ok(());
        }
        let sub = Subgrid::from_finite(a, b, c, d);
        let (lo, hi) = sub.range();
        // A constant subgrid draws nothing; with several levels, none may
        // meet the cell even though the marking kept it.
        if lo == hi || (self.levels.len() > 1 && !self.levels.iter().any(|&l| lo <= l && l <= hi)) {
            return Ok(());
        }
        let sent = contour_subgrid(&sub, at, self.levels, self.traversal, place, sink)?;
        stats.crossing_cells += u64::from(sent > 0);
        stats.commands += sent;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::command::Command;
    use proptest::prelude::*;

    /// A cell's index and a point.
    type Placed = (usize, f32, f32);

    #[test]
    fn between_masks_the_signed_compare() {
        let edges = [i32::MIN, i32::MIN + 1, -2, -1, 0, 1, 2, 0x7F80_0000, i32::MAX - 1, i32::MAX];
        for &lo in &edges {
            for &hi in &edges {
                if lo >= hi {
                    continue;
                }
                let b = Between::new(lo, hi);
                for &k in &edges {
                    let want = if lo < k && k < hi { !0 } else { 0 };
                    assert_eq!(b.mask_borrow(k), want, "borrow: lo, hi, k = {:?}", (lo, hi, k));
                    assert_eq!(b.mask_compare(k), want, "compare: lo, hi, k = {:?}", (lo, hi, k));
                }
            }
        }
    }

    proptest! {
        #[test]
        fn between_masks_the_signed_compare_anywhere(lo in any::<i32>(), hi in any::<i32>(), k in any::<i32>()) {
            prop_assume!(lo < hi);
            let b = Between::new(lo, hi);
            let want = if lo < k && k < hi { !0 } else { 0 };
            prop_assert_eq!(b.mask_borrow(k), want);
            prop_assert_eq!(b.mask_compare(k), want);
        }
    }

    proptest! {
        #[test]
        fn a_row_is_classed_the_same_four_a_step_or_one(
            row in prop::collection::vec(any::<u32>().prop_map(f32::from_bits), 0..=BLOCK + 1),
            levels in prop::collection::vec(-1e3f32..1e3, 1..4),
        ) {
            let sweep = Sweep::new(&levels, Traversal::default());
            let class = |v: f32| {
                let k = key(v);
                ((sweep.above.mask(k) & u32::from(ABOVE)) | (sweep.below.mask(k) & u32::from(BELOW))) as u8
            };
            let (mut quads, mut each): (Classes, Classes) = ([0xEE; BLOCK + 9], [0xEE; BLOCK + 9]);
            class_quads(&row, &mut quads, class);
            class_each(&row, &mut each, class);
            prop_assert_eq!(&quads[..], &each[..]);
            let mut classed: Classes = [0xEE; BLOCK + 9];
            sweep.classify(&row, &mut classed);
            prop_assert_eq!(&classed[..], &each[..]);
        }
    }

    proptest! {
        #[test]
        fn quiet_bits_are_the_and_of_the_first_n_classes(
            bytes in prop::collection::vec(prop::sample::select(vec![0u8, ABOVE, BELOW, ABOVE | BELOW]), BLOCK + 9),
            n in 0..=BLOCK + 1,
        ) {
            let mut c: Classes = [0; BLOCK + 9];
            c.copy_from_slice(&bytes);
            let want = bytes[..n].iter().fold(ABOVE | BELOW, |a, &b| a & b);
            prop_assert_eq!(quiet_bits(&c, n), want);
        }
    }

    proptest! {
        #[test]
        fn and_along_is_the_and_of_each_cells_four_corners(
            a in prop::collection::vec(any::<u8>(), BLOCK + 9),
            b in prop::collection::vec(any::<u8>(), BLOCK + 9),
            n in 0..=BLOCK,
        ) {
            let (mut ca, mut cb, mut m): (Classes, Classes, Classes) = ([0; BLOCK + 9], [0; BLOCK + 9], [0; BLOCK + 9]);
            ca.copy_from_slice(&a);
            cb.copy_from_slice(&b);
            and_along(&mut m, &ca, &cb, n);
            let want: Vec<u8> = (0..n).map(|k| a[k] & a[k + 1] & b[k] & b[k + 1]).collect();
            prop_assert_eq!(&m[..n], &want[..]);
        }
    }

    /// Records every command with its level.
    struct Record(Vec<(usize, Command<Placed>)>);

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(2000))]
        /// A cell given its corners' classes draws, bit for bit, what it
        /// draws without them, and counts the same: at one level (the
        /// board's path, which the host's batch otherwise takes) and at
        /// several, with corners at the levels, non-finite and huge.
        #[test]
        fn a_cell_draws_the_same_with_its_classes(
            corners in prop::array::uniform4(sample()),
            levels in prop::collection::vec(prop::sample::select(vec![0.0f32, -0.0, 0.5, 1.0, -1.0, 2.5]), 1..3),
            compiled in any::<bool>(),
        ) {
            let traversal = if compiled { Traversal::Compiled } else { Traversal::Corrected };
            let sweep = Sweep::new(&levels, traversal);
            let mut classes: Classes = [0; BLOCK + 9];
            sweep.classify(&corners, &mut classes);
            let [a, b, c, d] = [classes[0], classes[1], classes[2], classes[3]];
            // Only busy cells are drawn: the AND of the classes is 0.
            prop_assume!(a & b & c & d == 0);
            let at = Placement::new(3, 7);
            let place = |x: f32, y: f32| (0usize, x, y);
            let (mut with, mut without) = (Record(Vec::new()), Record(Vec::new()));
            let (mut with_stats, mut without_stats) = (ContourStats::default(), ContourStats::default());
            let _ = sweep.cell_classed(corners, [a, b, c, d], at, &place, &mut with, &mut with_stats);
            let _ = sweep.cell(corners, at, &place, &mut without, &mut without_stats);
            let bits = |r: &Record| r.0.iter().map(|(l, c)| (*l, c.map(|(k, x, y)| (k, x.to_bits(), y.to_bits())))).collect::<Vec<_>>();
            prop_assert_eq!(bits(&with), bits(&without));
            prop_assert_eq!(with_stats, without_stats);
        }
    }

    impl CommandSink<Placed> for Record {
        type Error = core::convert::Infallible;
        fn command(&mut self, level: usize, c: Command<Placed>) -> Result<(), Self::Error> {
            self.0.push((level, c));
            Ok(())
        }
    }

    /// Samples where the two ways of finding quiet cells could part: the
    /// levels themselves, signed zeros, non-finite and huge values.
    fn sample() -> impl Strategy<Value = f32> {
        prop_oneof![
            2 => -3.0f32..3.0,
            1 => prop::sample::select(vec![
                0.0f32, -0.0, 1.0, -1.0, 0.5, f32::NAN, f32::INFINITY, f32::NEG_INFINITY, f32::MAX, -f32::MAX,
                f32::MIN_POSITIVE, -1e-45,
            ]),
        ]
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(400))]
        #[test]
        fn rows_skip_exactly_the_cells_no_level_meets(
            lower in prop::collection::vec(sample(), 0..=BLOCK + 1),
            upper in prop::collection::vec(sample(), 0..=BLOCK + 1),
            levels in prop::collection::vec(prop::sample::select(vec![0.0f32, -0.0, 0.5, 1.0, -1.0, 2.5]), 1..3),
            compiled in any::<bool>(),
        ) {
            // The compiled traversal at one level takes the batch: it
            // must draw what each cell drawn alone draws, bit for bit.
            let traversal = if compiled { Traversal::Compiled } else { Traversal::Corrected };
            let sweep = Sweep::new(&levels, traversal);
            let place = |k: usize, x: f32, y: f32| (k, x, y);
            let at = |k: usize| Placement::new(k, 7);
            let (mut rows, mut every) = (Record(Vec::new()), Record(Vec::new()));
            let (mut rows_stats, mut every_stats) = (ContourStats::default(), ContourStats::default());
            let mut scratch = [[0u8; BLOCK + 9]; 3];
            let [c0, c1, c2] = &mut scratch;
            let mut batch = Batch::new();
            let _ = sweep.run_rows(&lower, &upper, [c0, c1, c2], &mut batch, at, place, &mut rows, &mut rows_stats);
            // The reference: every cell, none skipped.
            let n = lower.len().min(upper.len()).min(BLOCK + 1);
            let (r0, r1) = (&lower[..n], &upper[..n]);
            for k in 0..n.saturating_sub(1) {
                let _ = sweep.cell([r0[k], r0[k + 1], r1[k + 1], r1[k]], at(k), &|x, y| place(k, x, y), &mut every, &mut every_stats);
            }
            let bits = |r: &Record| r.0.iter().map(|(l, c)| (*l, c.map(|(k, x, y)| (k, x.to_bits(), y.to_bits())))).collect::<Vec<_>>();
            prop_assert_eq!(bits(&rows), bits(&every));
            prop_assert_eq!(rows_stats, every_stats);
            // And exactly the quiet cells are found quiet (a busy cell
            // taken for quiet is lost; the converse only costs time).
            let (klo, khi) = levels.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &l| (a.min(l), b.max(l)));
            let [lo, up, m] = &mut scratch;
            sweep.classify(r0, lo);
            sweep.classify(r1, up);
            and_along(m, lo, up, n.saturating_sub(1));
            let mut busy = vec![];
            let _ = each_busy::<()>(m, n.saturating_sub(1), |k| { busy.push(k); Ok(()) });
            for k in 0..n.saturating_sub(1) {
                let corners = [r0[k], r0[k + 1], r1[k + 1], r1[k]];
                let all = |f: &dyn Fn(f32) -> bool| corners.iter().all(|&v| v.is_finite() && f(v));
                let quiet = all(&|v| v > khi) || all(&|v| v < klo);
                prop_assert_eq!(busy.contains(&k), !quiet, "cell {}", k);
            }
        }
    }
}
