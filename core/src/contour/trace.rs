//! Traversal of contouring trees (Zyda, Figure 8) for one level.

use super::subgrid::{Edge, Node, Subgrid};
use super::tree::{Entry, Template};

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
pub fn conn(sub: &Subgrid, e: &Entry) -> Conn {
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
    #[default]
    Corrected,
}

/// Traverse the subgrid's contouring trees at `level` and hand every emitted
/// point to `emit` with its drawing instruction.
///
/// Pre-order over each tree; an entry whose tree edge contains the level
/// (`lower <= level < upper`, or a root equal to the level) emits its
/// crossing with its drawing instruction, then its subtree is searched for
/// equal-valued edges at the level (VISIT_SUBTREE), and is not traversed
/// further.
#[inline]
pub fn visit(
    sub: &Subgrid,
    tpl: &Template,
    level: f32,
    traversal: Traversal,
    mut emit: impl FnMut(Conn, Crossing),
) {
    let entries = tpl.entries();
    let mut below = 0u8;
    for n in 0..5 {
        below |= u8::from(sub.at(n) <= level) << n;
    }
    // Entries whose tree edge contains the level, plus roots at the level.
    let mut todo = tpl.crossing_entries(below);
    for t in 0..tpl.tree_count() {
        let root = tpl.tree_range(t).start;
        if entries.get(root).is_some_and(|e| sub.at(e.node_index()) == level) {
            todo |= 1 << root;
        }
    }
    let second_tree = tpl.first_tree_end();
    // The pen is away from the last main emission (VISIT_SUBTREE moved it).
    let mut restore: Option<Crossing> = None;
    while todo != 0 {
        let i = todo.trailing_zeros() as usize;
        let Some(e) = entries.get(i) else { break };
        if i == second_tree {
            restore = None;
        }
        let vn = sub.at(e.node_index());
        let at = if vn == level { Crossing::node(e.node()) } else { e.crossing() };
        let c = conn(sub, e);
        if let (Conn::DrawTo, Some(back), Traversal::Corrected) = (c, restore, traversal) {
            emit(Conn::SetPoint, back);
        }
        emit(c, at);
        restore = None;
        let end = e.subtree_end().max(i + 1);
        if vn == level {
            for d in entries.get(i + 1..end).unwrap_or(&[]) {
                if sub.at(d.node_index()) == level {
                    emit(Conn::SetPoint, Crossing::node(d.parent()));
                    emit(Conn::DrawTo, Crossing::node(d.node()));
                    restore = Some(at);
                }
            }
        }
        // The subtree below an emitting entry is not traversed further.
        todo &= u32::MAX.checked_shl(end as u32).unwrap_or(0);
    }
}
