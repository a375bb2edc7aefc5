//! Contouring trees (Zyda, section 5), built for all 256 direction codes at
//! compile time.
//!
//! The subgrid graph has five nodes and eight downhill edges. Its roots are
//! the nodes of in-degree 0: none for a constant subgrid (which draws nothing),
//! one, or two for a saddle. Each root gets its own tree, built with the other
//! root and its edges removed. A node of in-degree n > 1 is duplicated so that
//! each incoming edge has its own copy; the copy met first in pre-order keeps
//! the node's outgoing edges, the others are leaves. So each tree holds every
//! graph edge it can reach exactly once, as the paper's completeness proof
//! counts them (three edges fixed by the root, five more placed below).
//!
//! Children are ordered counterclockwise, starting just past the direction
//! back to the parent; a root corner starts from the direction pointing away
//! from the centre. With this order the traversal reproduces the paper's
//! Figures 5b and 7b exactly.
//!
//! A tree depends only on the [`DirectionCode`], never on the level, so the
//! [`TEMPLATES`] table is computed once by `const fn` and lives in flash on the
//! MCU (see [`TEMPLATE_TABLE_BYTES`]). Traversal is in
//! [`crate::contour::trace`].

use super::subgrid::{DirectionCode, Edge, Node};
use super::trace::Crossing;

/// Most trees in one subgrid (two, for a saddle).
pub const MAX_TREES: usize = 2;

/// Most entries in one template: each tree holds its root plus at most the
/// eight graph edges.
pub const MAX_ENTRIES: usize = MAX_TREES * 9;

/// One node copy in a flattened, pre-order contouring tree.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Entry {
    node: u8,
    parent: u8,
    /// [`Crossing`] key of the tree edge (the node's own key for a root).
    crossing: u8,
    end: u8,
    /// bit 0: first copy of a sink node in its tree; bits 3..8: nodes met
    /// earlier in the tree's pre-order.
    flags: u8,
}

impl Entry {
    const EMPTY: Entry = Entry { node: 0, parent: 0, crossing: 0, end: 0, flags: 0 };

    /// The grid node this entry is a copy of.
    #[inline(always)]
    pub const fn node(&self) -> Node {
        node_of(self.node)
    }

    /// The node of the tree parent (the upper end of the tree edge that
    /// leads here); the node itself for a root.
    #[inline(always)]
    pub const fn parent(&self) -> Node {
        node_of(self.parent)
    }

    /// Index of [`Entry::node`] (0..5).
    #[inline(always)]
    pub(crate) const fn node_index(&self) -> usize {
        self.node as usize
    }

    /// True for a tree's root.
    #[inline(always)]
    pub const fn is_root(&self) -> bool {
        self.node == self.parent
    }

    /// The tree edge from the parent, `None` for a root.
    #[inline(always)]
    pub const fn edge(&self) -> Option<Edge> {
        Edge::between(self.parent(), self.node())
    }

    /// The crossing of the tree edge from the parent when the level lies
    /// strictly inside it (the node itself for a root).
    #[inline(always)]
    pub const fn crossing(&self) -> Crossing {
        match Crossing::from_index(self.crossing as usize) {
            Some(x) => x,
            None => Crossing::node(Node::C),
        }
    }

    /// Index one past this entry's subtree in the template's entry array.
    #[inline(always)]
    pub const fn subtree_end(&self) -> usize {
        self.end as usize
    }

    /// True when this is the first copy of a sink node (out-degree 0) in the
    /// tree's pre-order: the paper places a SETPOINT there.
    #[inline(always)]
    pub const fn is_first_sink(&self) -> bool {
        self.flags & 1 != 0
    }

    /// Bit mask (bit `Node::index()`) of the nodes met before this entry in
    /// its tree's pre-order; the entry is a "new lowest value" when its value
    /// is below all of them.
    #[inline(always)]
    pub const fn earlier(&self) -> u8 {
        self.flags >> 3
    }
}

/// Element `i` of `s`, if there is one: `<[T]>::get` for `const fn`s.
#[inline(always)]
pub(crate) const fn get<T>(s: &[T], i: usize) -> Option<&T> {
    match s.split_at_checked(i) {
        Some((_, rest)) => rest.first(),
        None => None,
    }
}

#[inline(always)]
const fn node_of(i: u8) -> Node {
    match i {
        0 => Node::LL,
        1 => Node::LR,
        2 => Node::UR,
        3 => Node::UL,
        _ => Node::C,
    }
}

/// The contouring trees of one direction code, flattened in pre-order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Template {
    entries: [Entry; MAX_ENTRIES],
    /// Tree `t` spans entries `[start(t), tree_end[t])`.
    tree_end: [u8; MAX_TREES],
    trees: u8,
    /// Bit `i` of `node_at[n]` is set when entry `i` is a copy of node `n`.
    node_at: [u32; 5],
    /// Bit `i` of `parent_at[n]` is set when entry `i` hangs below node `n`
    /// (roots excluded).
    parent_at: [u32; 5],
}

impl Template {
    /// The precomputed template for a direction code.
    #[inline(always)]
    pub const fn for_code(code: DirectionCode) -> &'static Template {
        match get(&TEMPLATES, code.0 as usize) {
            Some(t) => t,
            None => &EMPTY,
        }
    }

    /// How many trees (roots): 0, 1 or 2.
    #[inline(always)]
    pub const fn tree_count(&self) -> usize {
        self.trees as usize
    }

    /// All entries of all trees.
    #[inline(always)]
    pub const fn entries(&self) -> &[Entry] {
        let n = match get(&self.tree_end, self.tree_count().wrapping_sub(1)) {
            Some(&n) => n as usize,
            None => 0,
        };
        match self.entries.split_at_checked(n) {
            Some((entries, _)) => entries,
            None => &[],
        }
    }

    /// The entries whose tree edge contains the level, as a bit set over
    /// entry indices, given the nodes at or below the level (`below`, bit
    /// `n` for node `n`). Roots are not included.
    #[inline(always)]
    pub const fn crossing_entries(&self, below: u8) -> u32 {
        let mut nodes = 0;
        let mut parents = 0;
        let [a0, a1, a2, a3, a4] = self.node_at;
        let [p0, p1, p2, p3, p4] = self.parent_at;
        let (a, p) = ([a0, a1, a2, a3, a4], [p0, p1, p2, p3, p4]);
        let mut n = 0;
        while n < 5 {
            let is_below = 0u32.wrapping_sub((below >> n) as u32 & 1);
            if let (Some(&a), Some(&p)) = (get(&a, n), get(&p, n)) {
                nodes |= a & is_below;
                parents |= p & !is_below;
            }
            n += 1;
        }
        nodes & parents
    }

    /// Index one past the last entry of the first tree.
    #[inline(always)]
    pub(crate) const fn first_tree_end(&self) -> usize {
        self.tree_end[0] as usize
    }

    /// The entry index range of tree `t` (empty past the last tree).
    #[inline(always)]
    pub const fn tree_range(&self, t: usize) -> core::ops::Range<usize> {
        if t >= self.tree_count() {
            return 0..0;
        }
        let end = match get(&self.tree_end, t) {
            Some(&e) => e as usize,
            None => 0,
        };
        let start = match get(&self.tree_end, t.wrapping_sub(1)) {
            Some(&e) if t > 0 => e as usize,
            _ => 0,
        };
        start..end
    }
}

static EMPTY: Template = Template {
    entries: [Entry::EMPTY; MAX_ENTRIES],
    tree_end: [0; MAX_TREES],
    trees: 0,
    node_at: [0; 5],
    parent_at: [0; 5],
};

// The builder below runs at compile time only (for `TEMPLATES`): an index out
// of range there is a build error, never a run-time panic.

/// Direction from one node to another as an octant (0 = east,
/// counterclockwise in steps of 45 degrees).
const fn octant(from: u8, to: u8) -> u8 {
    let (ax, ay) = pos2(from);
    let (bx, by) = pos2(to);
    let dx = (bx - ax).signum();
    let dy = (by - ay).signum();
    match (dx, dy) {
        (1, 0) => 0,
        (1, 1) => 1,
        (0, 1) => 2,
        (-1, 1) => 3,
        (-1, 0) => 4,
        (-1, -1) => 5,
        (0, -1) => 6,
        _ => 7,
    }
}

const fn pos2(n: u8) -> (i8, i8) {
    match n {
        0 => (0, 0),
        1 => (2, 0),
        2 => (2, 2),
        3 => (0, 2),
        _ => (1, 1),
    }
}

/// Out-neighbour masks of the five nodes under a direction code.
#[allow(clippy::indexing_slicing)]
const fn out_masks(code: u8) -> [u8; 5] {
    let mut out = [0u8; 5];
    let mut e = 0;
    while e < 8 {
        let (from, to) = DirectionCode(code).directed(Edge::ALL[e]);
        out[from as usize] |= 1 << (to as u8);
        e += 1;
    }
    out
}

struct Builder {
    entries: [Entry; MAX_ENTRIES],
    len: usize,
    expanded: u8,
}

#[allow(clippy::indexing_slicing)]
const fn dfs(b: &mut Builder, out: &[u8; 5], removed: u8, node: u8, parent: u8) {
    let idx = b.len;
    let crossing = match (Node::from_index(parent as usize), Node::from_index(node as usize)) {
        (Some(p), Some(n)) => match Edge::between(p, n) {
            Some(e) => Crossing::edge(e).index() as u8,
            None => node,
        },
        _ => node,
    };
    b.entries[idx] = Entry { node, parent, crossing, end: 0, flags: 0 };
    b.len += 1;
    if b.expanded & (1 << node) == 0 {
        b.expanded |= 1 << node;
        let start = if node != parent {
            (octant(node, parent) + 1) & 7
        } else if node == 4 {
            0 // a centre root cannot come from real values; any order will do
        } else {
            octant(4, node) // away from the centre
        };
        let mut k = 0;
        while k < 8 {
            let dir = (start + k) & 7;
            let mut c = 0;
            while c < 5 {
                let bit = 1u8 << c;
                if out[node as usize] & bit != 0 && removed & bit == 0 && octant(node, c) == dir {
                    dfs(b, out, removed, c, node);
                }
                c += 1;
            }
            k += 1;
        }
    }
    b.entries[idx].end = b.len as u8;
}

#[allow(clippy::indexing_slicing)]
const fn build(code: u8) -> Template {
    let out = out_masks(code);
    let mut indeg = [0u8; 5];
    let mut n = 0;
    while n < 5 {
        let mut m = 0;
        while m < 5 {
            if out[m] & (1 << n) != 0 {
                indeg[n] += 1;
            }
            m += 1;
        }
        n += 1;
    }
    let mut roots = 0u8;
    n = 0;
    while n < 5 {
        if indeg[n] == 0 {
            roots |= 1 << n;
        }
        n += 1;
    }
    let mut b = Builder { entries: [Entry::EMPTY; MAX_ENTRIES], len: 0, expanded: 0 };
    let mut tree_end = [0u8; MAX_TREES];
    let mut trees = 0usize;
    let mut r = 0u8;
    while r < 5 {
        if roots & (1 << r) != 0 {
            let start = b.len;
            b.expanded = 0;
            dfs(&mut b, &out, roots & !(1 << r), r, r);
            // Drawing-command placement: nodes met earlier, first sink copies.
            let mut seen = 0u8;
            let mut i = start;
            while i < b.len {
                let node = b.entries[i].node;
                let first_sink = out[node as usize] == 0 && seen & (1 << node) == 0;
                b.entries[i].flags = (seen << 3) | first_sink as u8;
                seen |= 1 << node;
                i += 1;
            }
            tree_end[trees] = b.len as u8;
            trees += 1;
        }
        r += 1;
    }
    let mut node_at = [0u32; 5];
    let mut parent_at = [0u32; 5];
    let mut i = 0;
    while i < b.len {
        let e = b.entries[i];
        node_at[e.node as usize] |= 1 << i;
        if e.node != e.parent {
            parent_at[e.parent as usize] |= 1 << i;
        }
        i += 1;
    }
    Template { entries: b.entries, tree_end, trees: trees as u8, node_at, parent_at }
}

#[allow(clippy::indexing_slicing)]
const fn build_all() -> [Template; 256] {
    let mut all = [EMPTY; 256];
    let mut code = 0;
    while code < 256 {
        all[code] = build(code as u8);
        code += 1;
    }
    all
}

/// The contouring-tree templates of all 256 direction codes, built at compile
/// time by the construction above.
pub static TEMPLATES: [Template; 256] = build_all();

/// Bytes the template table occupies (in flash on the MCU).
pub const TEMPLATE_TABLE_BYTES: usize = core::mem::size_of::<[Template; 256]>();

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contour::subgrid::Subgrid;
    use std::collections::BTreeSet;

    /// The construction written again, independently: angles by `atan2`,
    /// recursion over a `Vec`, the other root removed by filtering.
    fn reference(code: u8) -> Vec<Vec<(usize, usize, bool, u8)>> {
        let pos =
            |n: usize| -> (f64, f64) { [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0), (0.5, 0.5)][n] };
        let angle = |a: usize, b: usize| {
            let (pa, pb) = (pos(a), pos(b));
            (pb.1 - pa.1).atan2(pb.0 - pa.0).rem_euclid(std::f64::consts::TAU)
        };
        let mut edges = vec![];
        for e in Edge::ALL {
            let (f, t) = DirectionCode(code).directed(e);
            edges.push((f.index(), t.index()));
        }
        let indeg = |n: usize| edges.iter().filter(|e| e.1 == n).count();
        let roots: Vec<usize> = (0..5).filter(|&n| indeg(n) == 0).collect();
        let mut trees = vec![];
        for &r in &roots {
            let mut out = vec![];
            let mut expanded = BTreeSet::new();
            #[allow(clippy::too_many_arguments)]
            fn go(
                n: usize,
                p: usize,
                start: f64,
                edges: &[(usize, usize)],
                removed: &[usize],
                angle: &dyn Fn(usize, usize) -> f64,
                expanded: &mut BTreeSet<usize>,
                out: &mut Vec<(usize, usize)>,
            ) {
                out.push((n, p));
                if !expanded.insert(n) {
                    return;
                }
                let mut kids: Vec<usize> =
                    edges.iter().filter(|e| e.0 == n && !removed.contains(&e.1)).map(|e| e.1).collect();
                // Counterclockwise from just past `start`.
                kids.sort_by(|&a, &b| {
                    let ka = (angle(n, a) - start - 1e-9).rem_euclid(std::f64::consts::TAU);
                    let kb = (angle(n, b) - start - 1e-9).rem_euclid(std::f64::consts::TAU);
                    ka.total_cmp(&kb)
                });
                for k in kids {
                    go(k, n, angle(k, n), edges, removed, angle, expanded, out);
                }
            }
            let removed: Vec<usize> = roots.iter().copied().filter(|&x| x != r).collect();
            let start = if r == 4 { -1e-6 } else { angle(4, r) - 1e-6 };
            let mut seq = vec![];
            go(r, r, start, &edges, &removed, &angle, &mut expanded, &mut seq);
            let sinks: BTreeSet<usize> = (0..5).filter(|&n| !edges.iter().any(|e| e.0 == n)).collect();
            let mut seen = 0u8;
            for (n, p) in seq {
                let first_sink = sinks.contains(&n) && seen & (1 << n) == 0;
                out.push((n, p, first_sink, seen));
                seen |= 1 << n;
            }
            trees.push(out);
        }
        trees
    }

    #[test]
    fn table_matches_an_independent_construction_for_all_256_codes() {
        for code in 0..=255u8 {
            let t = Template::for_code(DirectionCode(code));
            let want = reference(code);
            assert_eq!(t.tree_count(), want.len(), "code {code:#010b}");
            for (ti, tree) in want.iter().enumerate() {
                let got: Vec<_> = t.entries()[t.tree_range(ti)]
                    .iter()
                    .map(|e| (e.node().index(), e.parent().index(), e.is_first_sink(), e.earlier()))
                    .collect();
                assert_eq!(&got, tree, "code {code:#010b} tree {ti}");
            }
            // Subtree ends nest properly and each tree edge is a graph edge.
            for r in 0..t.tree_count() {
                let range = t.tree_range(r);
                for i in range.clone() {
                    let e = t.entries()[i];
                    assert!(e.subtree_end() > i && e.subtree_end() <= range.end);
                    if !e.is_root() {
                        let edge = Edge::between(e.parent(), e.node()).unwrap();
                        assert_eq!(DirectionCode(code).directed(edge), (e.parent(), e.node()));
                        assert_eq!(e.crossing().as_edge(), Some(edge));
                    }
                }
            }
        }
    }

    /// Over every subgrid with corners in {0..6}^4 (all orderings and ties):
    /// which codes occur, how many trees and entries they need.
    #[test]
    fn realizable_codes_have_one_or_two_trees_of_at_most_nine_entries() {
        let mut codes = BTreeSet::new();
        for i in 0..7u32.pow(4) {
            let c = [i % 7, i / 7 % 7, i / 49 % 7, i / 343 % 7].map(|x| x as f32);
            let sub = Subgrid::new(c[0], c[1], c[2], c[3]).unwrap();
            let t = Template::for_code(sub.code());
            if sub.is_constant() {
                assert_eq!(t.tree_count(), 0);
                continue;
            }
            assert!((1..=2).contains(&t.tree_count()), "{c:?}");
            for r in 0..t.tree_count() {
                // Root plus at most the eight edges.
                assert!(t.tree_range(r).len() <= 9);
            }
            codes.insert(sub.code().0);
        }
        // Measured: only 50 of the 256 codes come from real values (plus the
        // constant subgrid's 0xFF); random reals and {0..12}^4 find no more.
        assert_eq!(codes.len(), 50);
    }

    #[test]
    fn table_size_is_as_documented() {
        assert_eq!(TEMPLATE_TABLE_BYTES, 256 * core::mem::size_of::<Template>());
        assert_eq!(core::mem::size_of::<Template>(), 136);
    }
}
