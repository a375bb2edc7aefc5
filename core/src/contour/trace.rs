//! Traversal of contouring trees (Zyda, Figure 8) for one level.

use super::subgrid::{Edge, Node, Subgrid};
use super::tree::{Entry, MAX_ENTRIES, Template, get};

/// The paper's drawing instruction on a tree node.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Conn {
    /// SETPOINT: start a new polyline here.
    SetPoint,
    /// DRAWTO: continue the current polyline to here.
    DrawTo,
}

/// Where an emitted point lies, symbolically: exactly at a node (its value
/// equals the level) or strictly inside an edge. A compact key, 0..5 for the
/// nodes and 5..13 for the edges.
#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Crossing(u8);

impl Crossing {
    /// Number of distinct crossings (five nodes, eight edges).
    pub const COUNT: usize = 13;

    /// The crossing exactly at a node.
    #[inline(always)]
    pub const fn node(n: Node) -> Self {
        Crossing(n as u8)
    }

    /// The crossing strictly inside an edge.
    #[inline(always)]
    pub const fn edge(e: Edge) -> Self {
        Crossing(5 + e as u8)
    }

    /// The key, 0..13.
    #[inline(always)]
    pub const fn index(self) -> usize {
        self.0 as usize
    }

    /// The crossing with this key, if it is below [`Crossing::COUNT`].
    pub const fn from_index(i: usize) -> Option<Self> {
        if i < Self::COUNT { Some(Crossing(i as u8)) } else { None }
    }

    /// The node, when the crossing is at one.
    #[inline(always)]
    pub const fn as_node(self) -> Option<Node> {
        Node::from_index(self.0 as usize)
    }

    /// The edge, when the crossing is strictly inside one.
    #[inline(always)]
    pub const fn as_edge(self) -> Option<Edge> {
        if self.0 >= 5 { Edge::from_index(self.0 as usize - 5) } else { None }
    }
}

impl core::fmt::Debug for Crossing {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match (self.as_node(), self.as_edge()) {
            (Some(n), _) => write!(f, "Node({n:?})"),
            (_, Some(e)) => write!(f, "Edge({e:?})"),
            _ => write!(f, "Crossing({})", self.0),
        }
    }
}

/// The drawing instruction of a tree entry: SETPOINT on a root, on the first
/// copy of a sink node, or on a node whose value is a new lowest value of the
/// tree in pre-order; DRAWTO otherwise.
#[inline(always)]
pub const fn conn(sub: &Subgrid, e: &Entry) -> Conn {
    if e.is_root() || e.is_first_sink() {
        return Conn::SetPoint;
    }
    let v = sub.at(e.node_index());
    let mut earlier = e.earlier();
    while earlier != 0 {
        if sub.at(earlier.trailing_zeros() as usize) <= v {
            return Conn::DrawTo;
        }
        earlier &= earlier - 1;
    }
    Conn::SetPoint
}

/// Which traversal to run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Traversal {
    /// Figure 8 exactly as printed. Correct whenever no node equals the
    /// level; with nodes at the level it draws about 1% of subgrids wrongly
    /// (see [`Traversal::Corrected`]).
    Literal,
    /// Figure 8 with the pen restored after VISIT_SUBTREE: the equal-valued
    /// edges it draws (`SETPOINT parent, DRAWTO child`) move the pen away from
    /// the node that was just emitted, so the next DRAWTO of the main
    /// traversal drew from the wrong place (a spurious diagonal, or a line to
    /// the far end of the equal-valued edge). The corrected traversal issues a
    /// SETPOINT back at that node before such a DRAWTO. The exhaustive
    /// completeness test shows this is the only defect.
    Corrected,
    /// [`Traversal::Corrected`], compiled: a subgrid with no node at the
    /// level draws its instructions from a table built at compile time by
    /// the corrected traversal itself ([`crate::contour::compiled`]); the
    /// others walk the trees. The same commands, bit for bit, faster.
    #[default]
    Compiled,
}

/// Most instructions one traversal emits: an entry emits at most two, its
/// own and a SETPOINT that restores the pen before it, or two as an
/// equal-valued edge below an emitting entry (whose subtree is then not
/// traversed further, so no entry does both).
pub const MAX_TRACE: usize = 2 * MAX_ENTRIES;

/// The instructions one traversal emits, in order (at most [`MAX_TRACE`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Trace {
    items: [(Conn, Crossing); MAX_TRACE],
    len: u8,
}

impl Trace {
    const EMPTY: Trace = Trace { items: [(Conn::SetPoint, Crossing(0)); MAX_TRACE], len: 0 };

    /// One more instruction; [`MAX_TRACE`] bounds them (see there), so none
    /// is ever refused.
    #[inline(always)]
    const fn push(&mut self, conn: Conn, at: Crossing) {
        if let Some(slot) = get_mut(&mut self.items, self.len as usize) {
            *slot = (conn, at);
            self.len += 1;
        }
    }

    /// The instructions, in order.
    #[inline(always)]
    pub const fn as_slice(&self) -> &[(Conn, Crossing)] {
        match self.items.split_at_checked(self.len as usize) {
            Some((items, _)) => items,
            None => &self.items,
        }
    }
}

/// Element `i` of `s`, if there is one: `<[T]>::get_mut` for `const fn`s.
#[inline(always)]
const fn get_mut<T>(s: &mut [T], i: usize) -> Option<&mut T> {
    match s.split_at_mut_checked(i) {
        Some((_, rest)) => rest.first_mut(),
        None => None,
    }
}

/// Traverse the subgrid's contouring trees at `level` and hand every emitted
/// point to `emit` with its drawing instruction (see [`trace`]).
#[inline]
pub fn visit(
    sub: &Subgrid,
    tpl: &Template,
    level: f32,
    traversal: Traversal,
    mut emit: impl FnMut(Conn, Crossing),
) {
    for &(conn, at) in trace(sub, tpl, level, traversal).as_slice() {
        emit(conn, at);
    }
}

/// The traversal of the subgrid's contouring trees at `level`: every
/// emitted point with its drawing instruction.
///
/// Pre-order over each tree; an entry whose tree edge contains the level
/// (`lower <= level < upper`, or a root equal to the level) emits its
/// crossing with its drawing instruction, then its subtree is searched for
/// equal-valued edges at the level (VISIT_SUBTREE), and is not traversed
/// further. A `const fn`: [`crate::contour::compiled`] runs it at compile
/// time to build its table.
#[inline]
pub const fn trace(sub: &Subgrid, tpl: &Template, level: f32, traversal: Traversal) -> Trace {
    let mut out = Trace::EMPTY;
    let entries = tpl.entries();
    let (below, _) = sub.below(level);
    // Entries whose tree edge contains the level, plus roots at the level.
    let mut todo = tpl.crossing_entries(below);
    let mut t = 0;
    while t < tpl.tree_count() {
        let root = tpl.tree_range(t).start;
        if let Some(e) = get(entries, root)
            && sub.at(e.node_index()) == level
        {
            todo |= 1 << root;
        }
        t += 1;
    }
    let second_tree = tpl.first_tree_end();
    // The pen is away from the last main emission (VISIT_SUBTREE moved it).
    let mut restore: Option<Crossing> = None;
    while todo != 0 {
        let i = todo.trailing_zeros() as usize;
        let Some(e) = get(entries, i) else { break };
        if i == second_tree {
            restore = None;
        }
        let vn = sub.at(e.node_index());
        let at = if vn == level { Crossing::node(e.node()) } else { e.crossing() };
        let c = conn(sub, e);
        if let (Conn::DrawTo, Some(back), Traversal::Corrected | Traversal::Compiled) =
            (c, restore, traversal)
        {
            out.push(Conn::SetPoint, back);
        }
        out.push(c, at);
        restore = None;
        let end = if e.subtree_end() > i + 1 { e.subtree_end() } else { i + 1 };
        if vn == level {
            let mut k = i + 1;
            while k < end {
                if let Some(d) = get(entries, k)
                    && sub.at(d.node_index()) == level
                {
                    out.push(Conn::SetPoint, Crossing::node(d.parent()));
                    out.push(Conn::DrawTo, Crossing::node(d.node()));
                    restore = Some(at);
                }
                k += 1;
            }
        }
        // The subtree below an emitting entry is not traversed further.
        todo &= match u32::MAX.checked_shl(end as u32) {
            Some(m) => m,
            None => 0,
        };
    }
    out
}
