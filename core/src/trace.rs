//! Traversal of contouring trees (Zyda, Figure 8) for one level.

use crate::subgrid::{Edge, Node, Subgrid};
use crate::tree::{Entry, Template};

/// The paper's drawing instruction on a tree node.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Conn {
    /// SETPOINT: start a new polyline here.
    SetPoint,
    /// DRAWTO: continue the current polyline to here.
    DrawTo,
}

/// Where an emitted point lies, symbolically: at a node (its value equals the
/// level) or strictly inside an edge.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Crossing {
    /// Exactly at a node.
    Node(Node),
    /// Strictly inside an edge.
    Edge(Edge),
}

/// The drawing instruction of a tree entry: SETPOINT on a root, on the first
/// copy of a sink node, or on a node whose value is a new lowest value of the
/// tree in pre-order; DRAWTO otherwise.
#[inline]
pub fn conn(sub: &Subgrid, e: &Entry) -> Conn {
    if e.is_root() || e.is_first_sink() {
        return Conn::SetPoint;
    }
    let v = sub.value(e.node());
    let earlier = e.earlier();
    let lower_or_equal_before =
        sub.values().iter().enumerate().any(|(n, &u)| earlier & (1 << n) != 0 && u <= v);
    if lower_or_equal_before { Conn::DrawTo } else { Conn::SetPoint }
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
    for t in 0..tpl.tree_count() {
        let range = tpl.tree_range(t);
        // The pen is away from the last main emission (VISIT_SUBTREE moved it).
        let mut restore: Option<Crossing> = None;
        let mut i = range.start;
        while i < range.end {
            let Some(e) = entries.get(i) else { break };
            let vn = sub.value(e.node());
            let contains =
                if e.is_root() { vn == level } else { vn <= level && level < sub.value(e.parent()) };
            if !contains {
                i += 1;
                continue;
            }
            let at = if vn == level {
                Crossing::Node(e.node())
            } else {
                match e.edge() {
                    Some(edge) => Crossing::Edge(edge),
                    None => Crossing::Node(e.node()),
                }
            };
            let c = conn(sub, e);
            if let (Conn::DrawTo, Some(back), Traversal::Corrected) = (c, restore, traversal) {
                emit(Conn::SetPoint, back);
            }
            emit(c, at);
            restore = None;
            if vn == level {
                for d in entries.get(i + 1..e.subtree_end()).unwrap_or(&[]) {
                    if sub.value(d.node()) == level {
                        emit(Conn::SetPoint, Crossing::Node(d.parent()));
                        emit(Conn::DrawTo, Crossing::Node(d.node()));
                        restore = Some(at);
                    }
                }
            }
            i = e.subtree_end().max(i + 1);
        }
    }
}
