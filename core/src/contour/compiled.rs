//! The traversal of the contouring trees, compiled: a crossing subgrid as a
//! table lookup and the interpolations it names.
//!
//! When no node of a subgrid equals the level, what the traversal
//! ([`trace`]) emits depends on nothing but the subgrid's direction code and
//! which of its five nodes lie below the level: the trees are the code's,
//! the emitting entries are those whose tree edge has one node above and
//! one below, and every drawing instruction follows from comparisons those
//! two facts settle. So the instructions are worked out once, here, at
//! compile time, by running the tree traversal itself on representative
//! subgrids (corners `0..=6`, every level between two node values: every
//! direction code that real values give, with every set of nodes below),
//! and kept as a [`Program`] for each (code, nodes below). Tests check that
//! the key settles the instructions: the table against the traversal over
//! every subgrid of a larger grid of values, random reals, and the demo
//! volumes' slices.
//!
//! A subgrid with a node at the level takes the trees ([`trace`]): its
//! instructions need the pen's tidying ([`super::pen::Pen`]) and depend on
//! ties the key does not record. They are rare in real data (a sample
//! exactly at the level).

use super::subgrid::{DirectionCode, Edge, Subgrid};
use super::trace::{Conn, Traversal, trace};
use super::tree::{Template, get};

/// Most instructions in a program: a subgrid with no node at the level
/// crosses each of its eight edges at most once.
pub const MAX_STEPS: usize = 8;

/// The instructions of one crossing subgrid with no node at the level:
/// up to [`MAX_STEPS`] steps of four bits (the edge whose crossing is
/// drawn, bit 3 for DRAWTO against SETPOINT), then their count in bits 32
/// to 35.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Program(u64);

impl Program {
    /// How many instructions.
    #[inline(always)]
    pub const fn len(self) -> usize {
        (self.0 >> 32) as usize & 15
    }

    /// True for a program with no instruction (none is stored).
    #[inline(always)]
    pub const fn is_empty(self) -> bool {
        self.len() == 0
    }

    /// The instructions packed four bits each, the first lowest: the
    /// edge's index in bits 0 to 2, bit 3 for DRAWTO (what
    /// [`Program::steps`] decodes).
    #[inline(always)]
    pub(crate) const fn packed(self) -> u32 {
        self.0 as u32
    }

    /// The instructions in order: the drawing instruction and the edge
    /// whose crossing it goes to.
    #[inline(always)]
    pub fn steps(self) -> impl Iterator<Item = (Conn, Edge)> {
        let bits = self.0 as u32;
        (0..self.len().min(MAX_STEPS)).filter_map(move |k| {
            let s = bits >> (4 * k);
            let conn = if s & 8 != 0 { Conn::DrawTo } else { Conn::SetPoint };
            Edge::from_index(s as usize & 7).map(|e| (conn, e))
        })
    }
}

/// The program of a subgrid with direction code `code` whose nodes at or
/// below the level are `below` (bit `n` for node index `n`), when no node
/// equals the level. `None` for a key no real subgrid has.
#[inline(always)]
pub fn program(code: DirectionCode, below: u8) -> Option<Program> {
    let row = *ROW.get(usize::from(code.0))?;
    let at = *PROGRAMS.get(usize::from(row))?.get(usize::from(below & 31))?;
    match at {
        0 => None,
        _ => POOL.get(usize::from(at)).map(|&bits| Program(bits)),
    }
}

/// The program of `sub` at `level`, when no node equals the level; for a
/// subgrid the table does not hold, or with a node at the level, `None`.
#[inline(always)]
pub fn program_for(sub: &Subgrid, level: f32) -> Option<Program> {
    let (below, on) = sub.below(level);
    if on { None } else { program(sub.code(), below) }
}

// The builder below runs at compile time only (for the statics): an index out
// of range or a panic there is a build error, never a run-time one.

/// The table as built, with room to spare; trimmed into the statics.
struct Built {
    /// Code -> its row of `programs` (0: none).
    row: [u8; 256],
    rows: usize,
    /// (row, nodes below) -> index into `pool` (0: none).
    programs: [[u8; 32]; 64],
    pool: [u64; 256],
    pooled: usize,
}

/// The program the tree traversal gives `sub` at `level` (no node at it).
#[allow(clippy::panic)]
const fn compile(sub: &Subgrid, level: f32) -> u64 {
    let t = trace(sub, Template::for_code(sub.code()), level, Traversal::Corrected);
    let steps = t.as_slice();
    if steps.len() > MAX_STEPS {
        panic!("a subgrid with no node at the level emitted more than MAX_STEPS instructions");
    }
    let mut bits = 0u64;
    let mut k = 0;
    while k < steps.len() {
        let Some(&(conn, at)) = get(steps, k) else { break };
        let Some(edge) = at.as_edge() else {
            panic!("a subgrid with no node at the level emitted a crossing at a node");
        };
        let drawto = matches!(conn, Conn::DrawTo) as u64;
        bits |= ((edge as u64) | (drawto << 3)) << (4 * k);
        k += 1;
    }
    bits | ((steps.len() as u64) << 32)
}

#[allow(clippy::indexing_slicing)]
const fn build() -> Built {
    let mut b = Built { row: [0; 256], rows: 1, programs: [[0; 32]; 64], pool: [0; 256], pooled: 1 };
    let mut i = 0;
    while i < 7 * 7 * 7 * 7 {
        let c = [i % 7, i / 7 % 7, i / 49 % 7, i / 343];
        i += 1;
        let sub = Subgrid::from_finite(c[0] as f32, c[1] as f32, c[2] as f32, c[3] as f32);
        let code = sub.code().0 as usize;
        // The node values in order, and a level between each two.
        let mut v = sub.values();
        let mut a = 1;
        while a < 5 {
            let mut k = a;
            while k > 0 && v[k - 1] > v[k] {
                let t = v[k];
                v[k] = v[k - 1];
                v[k - 1] = t;
                k -= 1;
            }
            a += 1;
        }
        let mut g = 0;
        while g < 4 {
            let (lo, hi) = (v[g], v[g + 1]);
            g += 1;
            if lo == hi {
                continue;
            }
            let level = (lo + hi) * 0.5;
            let below = sub.below(level).0 as usize;
            if b.row[code] == 0 {
                b.row[code] = b.rows as u8;
                b.rows += 1;
            }
            let row = b.row[code] as usize;
            if b.programs[row][below] != 0 {
                continue;
            }
            let program = compile(&sub, level);
            let mut p = 1;
            while p < b.pooled && b.pool[p] != program {
                p += 1;
            }
            if p == b.pooled {
                b.pool[p] = program;
                b.pooled += 1;
            }
            b.programs[row][below] = p as u8;
        }
    }
    b
}

const BUILT: Built = build();

/// Rows of [`PROGRAMS`]: one per direction code real values give, and the
/// empty row 0.
pub const ROWS: usize = BUILT.rows;

/// Distinct programs in [`POOL`], with the unused entry 0.
pub const POOLED: usize = BUILT.pooled;

/// Bytes the compiled traversal takes (in flash on the MCU).
pub const TABLE_BYTES: usize = 256 + ROWS * 32 + POOLED * 8;

#[allow(clippy::indexing_slicing)]
const fn trim<T: Copy, const N: usize>(all: &[T], fill: T) -> [T; N] {
    let mut out = [fill; N];
    let mut k = 0;
    while k < N {
        out[k] = all[k];
        k += 1;
    }
    out
}

/// Direction code -> its row of [`PROGRAMS`] (0: no real subgrid has it).
static ROW: [u8; 256] = BUILT.row;

/// (row, nodes below) -> index of the program in [`POOL`] (0: none).
static PROGRAMS: [[u8; 32]; ROWS] = trim(&BUILT.programs, [0; 32]);

/// The distinct programs (encoded as [`Program`]).
static POOL: [u64; POOLED] = trim(&BUILT.pool, 0);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contour::trace::visit;

    /// The tree traversal's instructions for `sub` at `level`.
    fn by_trees(sub: &Subgrid, level: f32) -> Vec<(Conn, Edge)> {
        let mut out = vec![];
        visit(sub, Template::for_code(sub.code()), level, Traversal::Corrected, |c, x| {
            out.push((c, x.as_edge().expect("no node at the level: every crossing is inside an edge")))
        });
        out
    }

    #[test]
    fn the_table_is_small() {
        // Measured: 51 rows (50 codes from real values and the empty row),
        // 220 keys, 40 distinct programs (and the unused entry 0).
        assert_eq!((ROWS, POOLED), (51, 41));
        let keys = PROGRAMS.iter().flatten().filter(|&&p| p != 0).count();
        assert_eq!(keys, 220);
        assert_eq!(TABLE_BYTES, 2216);
    }

    /// Over every subgrid with corners in {0..12}^4 and every level between
    /// two of its node values: the table has the key, and its program is
    /// the traversal's.
    #[test]
    fn programs_equal_the_tree_traversal_on_a_grid_of_values() {
        let k = 13u32;
        let mut checked = 0u64;
        for i in 0..k.pow(4) {
            let c = [i % k, i / k % k, i / (k * k) % k, i / (k * k * k)].map(|x| x as f32);
            let sub = Subgrid::new(c[0], c[1], c[2], c[3]).unwrap();
            let mut v = sub.values();
            v.sort_by(f32::total_cmp);
            for w in v.windows(2) {
                if w[0] == w[1] {
                    continue;
                }
                let level = (w[0] + w[1]) / 2.0;
                let p = program_for(&sub, level).unwrap_or_else(|| panic!("no program for {c:?} at {level}"));
                assert_eq!(p.steps().collect::<Vec<_>>(), by_trees(&sub, level), "{c:?} at {level}");
                checked += 1;
            }
        }
        assert!(checked > 50_000, "{checked}");
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(20_000))]
        #[test]
        fn programs_equal_the_tree_traversal_on_random_reals(
            c in proptest::array::uniform4(-1.0e3f32..1.0e3),
            t in 0.0f32..=1.0,
        ) {
            let sub = Subgrid::new(c[0], c[1], c[2], c[3]).unwrap();
            let (lo, hi) = sub.range();
            let level = lo + (hi - lo) * t;
            match program_for(&sub, level) {
                Some(p) => proptest::prop_assert_eq!(p.steps().collect::<Vec<_>>(), by_trees(&sub, level)),
                // Only a node at the level (or a constant subgrid) goes
                // without a program.
                None => proptest::prop_assert!(sub.values().contains(&level) || lo == hi),
            }
        }
    }
}
