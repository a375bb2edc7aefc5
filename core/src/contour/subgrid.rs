//! One 2x2 subgrid: its five nodes, eight edges and their downhill directions.
//!
//! Corners are numbered counterclockwise with x to the right and y up:
//!
//! ```text
//!  UL(3) ---- B2 ---- UR(2)
//!    |  \            /  |
//!    B3  S3        S2   B1
//!    |      \ C(4) /    |
//!    |      /      \    |
//!    |  S0            S1|
//!  LL(0) ---- B0 ---- LR(1)
//! ```
//!
//! Border edge `Bi` joins corner `i` and corner `i+1`; spoke `Si` joins corner
//! `i` and the centre node `C`, whose value is the mean of the four corners.
//! Every edge is directed downhill. An equal-valued border edge points
//! counterclockwise (`i -> i+1`); an equal-valued spoke points toward the
//! centre. The eight directions form the subgrid's [`DirectionCode`].

/// A node of the subgrid graph.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum Node {
    /// Lower-left corner, grid point (i, j).
    LL = 0,
    /// Lower-right corner, grid point (i+1, j).
    LR = 1,
    /// Upper-right corner, grid point (i+1, j+1).
    UR = 2,
    /// Upper-left corner, grid point (i, j+1).
    UL = 3,
    /// Centre node at (i+0.5, j+0.5), the mean of the corners.
    C = 4,
}

impl Node {
    /// All nodes in index order.
    pub const ALL: [Node; 5] = [Node::LL, Node::LR, Node::UR, Node::UL, Node::C];

    /// The node with this index (0..5), or `None`.
    pub const fn from_index(i: usize) -> Option<Node> {
        match i {
            0 => Some(Node::LL),
            1 => Some(Node::LR),
            2 => Some(Node::UR),
            3 => Some(Node::UL),
            4 => Some(Node::C),
            _ => None,
        }
    }

    /// The node's index (0..5).
    pub const fn index(self) -> usize {
        self as usize
    }

    /// Position in doubled cell units: corners at 0 or 2, the centre at 1.
    pub(crate) const fn pos2(self) -> (i8, i8) {
        match self {
            Node::LL => (0, 0),
            Node::LR => (2, 0),
            Node::UR => (2, 2),
            Node::UL => (0, 2),
            Node::C => (1, 1),
        }
    }

    /// Position within the cell in cell units (0.0, 0.5 or 1.0 per axis).
    pub fn offset(self) -> (f32, f32) {
        let (x, y) = self.pos2();
        (f32::from(x) * 0.5, f32::from(y) * 0.5)
    }
}

/// One of the eight edges of the subgrid graph.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum Edge {
    /// Border LL-LR (bottom).
    B0 = 0,
    /// Border LR-UR (right).
    B1 = 1,
    /// Border UR-UL (top).
    B2 = 2,
    /// Border UL-LL (left).
    B3 = 3,
    /// Spoke LL-C.
    S0 = 4,
    /// Spoke LR-C.
    S1 = 5,
    /// Spoke UR-C.
    S2 = 6,
    /// Spoke UL-C.
    S3 = 7,
}

impl Edge {
    /// All edges in index order (the bit order of a [`DirectionCode`]).
    pub const ALL: [Edge; 8] =
        [Edge::B0, Edge::B1, Edge::B2, Edge::B3, Edge::S0, Edge::S1, Edge::S2, Edge::S3];

    /// The edge's index (0..8).
    pub const fn index(self) -> usize {
        self as usize
    }

    /// The edge with this index (0..8), or `None`.
    pub const fn from_index(i: usize) -> Option<Edge> {
        match i {
            0 => Some(Edge::B0),
            1 => Some(Edge::B1),
            2 => Some(Edge::B2),
            3 => Some(Edge::B3),
            4 => Some(Edge::S0),
            5 => Some(Edge::S1),
            6 => Some(Edge::S2),
            7 => Some(Edge::S3),
            _ => None,
        }
    }

    /// The edge's two nodes in its canonical interpolation order.
    ///
    /// Border edges run from the grid point with the smaller coordinates to
    /// the larger one, so the two subgrids sharing an edge compute
    /// bit-identical crossings. Spokes run from the corner to the centre.
    pub const fn canonical(self) -> (Node, Node) {
        match self {
            Edge::B0 => (Node::LL, Node::LR),
            Edge::B1 => (Node::LR, Node::UR),
            Edge::B2 => (Node::UL, Node::UR),
            Edge::B3 => (Node::LL, Node::UL),
            Edge::S0 => (Node::LL, Node::C),
            Edge::S1 => (Node::LR, Node::C),
            Edge::S2 => (Node::UR, Node::C),
            Edge::S3 => (Node::UL, Node::C),
        }
    }

    /// The edge joining two nodes, if they are adjacent.
    pub const fn between(a: Node, b: Node) -> Option<Edge> {
        let (a, b) = if (a as u8) < (b as u8) { (a, b) } else { (b, a) };
        match (a, b) {
            (Node::LL, Node::LR) => Some(Edge::B0),
            (Node::LR, Node::UR) => Some(Edge::B1),
            (Node::UR, Node::UL) => Some(Edge::B2),
            (Node::LL, Node::UL) => Some(Edge::B3),
            (Node::LL, Node::C) => Some(Edge::S0),
            (Node::LR, Node::C) => Some(Edge::S1),
            (Node::UR, Node::C) => Some(Edge::S2),
            (Node::UL, Node::C) => Some(Edge::S3),
            _ => None,
        }
    }
}

/// The downhill directions of the eight edges, one bit per edge
/// (bit `i` for [`Edge`] index `i`).
///
/// For a border edge `Bi` the bit is set when it points counterclockwise,
/// `i -> i+1` (value at `i` >= value at `i+1`); for a spoke `Si` it is set when
/// it points toward the centre (corner value >= centre value).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DirectionCode(pub u8);

impl DirectionCode {
    /// The edge's `(from, to)` nodes under this code: the edge points
    /// downhill from `from` to `to`.
    pub const fn directed(self, edge: Edge) -> (Node, Node) {
        let set = self.0 & (1 << edge as u8) != 0;
        match edge {
            Edge::S0 | Edge::S1 | Edge::S2 | Edge::S3 => {
                let corner = edge.canonical().0;
                if set { (corner, Node::C) } else { (Node::C, corner) }
            }
            _ => {
                // Counterclockwise order along the border: corner i -> i+1.
                let i = edge as usize;
                let (a, b) = match (Node::from_index(i), Node::from_index((i + 1) % 4)) {
                    (Some(a), Some(b)) => (a, b),
                    _ => (Node::LL, Node::LL), // unreachable: i < 4
                };
                if set { (a, b) } else { (b, a) }
            }
        }
    }
}

/// The smaller of two finite values.
#[inline(always)]
const fn min2(a: f32, b: f32) -> f32 {
    if a < b { a } else { b }
}

/// The larger of two finite values.
#[inline(always)]
const fn max2(a: f32, b: f32) -> f32 {
    if a > b { a } else { b }
}

/// The five node values of one subgrid, all finite.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Subgrid {
    /// LL, LR, UR, UL, C, then the smallest and largest corner, padded to
    /// eight so that a masked index needs no bounds check.
    values: [f32; 8],
}

/// Why a subgrid could not be formed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SubgridError {
    /// A corner is NaN or infinite.
    NonFinite,
}

impl core::fmt::Display for SubgridError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            SubgridError::NonFinite => f.write_str("a subgrid corner is NaN or infinite"),
        }
    }
}

impl core::error::Error for SubgridError {}

impl Subgrid {
    /// A subgrid from its corner values in counterclockwise order
    /// (LL, LR, UR, UL). The centre is their mean.
    ///
    /// # Errors
    /// [`SubgridError::NonFinite`] when a corner is NaN or infinite.
    #[inline]
    pub fn new(ll: f32, lr: f32, ur: f32, ul: f32) -> Result<Self, SubgridError> {
        if ll.is_finite() & lr.is_finite() & ur.is_finite() & ul.is_finite() {
            Ok(Self::from_finite(ll, lr, ur, ul))
        } else {
            Err(SubgridError::NonFinite)
        }
    }

    /// As [`Subgrid::new`] for corners already known to be finite.
    ///
    /// The mean is formed from quarters so that it cannot overflow; it always
    /// lies between the smallest and the largest corner.
    #[inline(always)]
    pub(crate) const fn from_finite(ll: f32, lr: f32, ur: f32, ul: f32) -> Self {
        let c = (ll * 0.25 + lr * 0.25) + (ur * 0.25 + ul * 0.25);
        // Finite inputs: plain comparisons suffice (no NaN to propagate).
        let lo = min2(min2(ll, lr), min2(ur, ul));
        let hi = max2(max2(ll, lr), max2(ur, ul));
        Self { values: [ll, lr, ur, ul, min2(max2(c, lo), hi), lo, hi, 0.0] }
    }

    /// The value at a node.
    #[inline(always)]
    pub const fn value(&self, node: Node) -> f32 {
        self.at(node as usize)
    }

    /// The value at node index `i` (0..5).
    #[inline(always)]
    pub(crate) const fn at(&self, i: usize) -> f32 {
        match crate::contour::tree::get(&self.values, i & 7) {
            Some(&v) => v,
            None => f32::NAN,
        }
    }

    /// All five values, indexed by [`Node::index`].
    pub const fn values(&self) -> [f32; 5] {
        let [ll, lr, ur, ul, c, ..] = self.values;
        [ll, lr, ur, ul, c]
    }

    /// The smallest and the largest value (the centre lies between them).
    #[inline(always)]
    pub const fn range(&self) -> (f32, f32) {
        (self.at(5), self.at(6))
    }

    /// True when all four corners are equal (the paper draws nothing then).
    pub fn is_constant(&self) -> bool {
        let v = &self.values;
        v[0] == v[1] && v[1] == v[2] && v[2] == v[3]
    }

    /// Which nodes lie at or below `level` (bit `n` for node index `n`),
    /// and whether one of them equals it.
    #[inline(always)]
    pub const fn below(&self, level: f32) -> (u8, bool) {
        let (mut below, mut on) = (0u8, false);
        let mut n = 0;
        while n < 5 {
            let v = self.at(n);
            below |= ((v <= level) as u8) << n;
            on |= v == level;
            n += 1;
        }
        (below, on)
    }

    /// The downhill direction of every edge.
    #[inline(always)]
    pub const fn code(&self) -> DirectionCode {
        let v = &self.values;
        let c = v[4];
        let b = ((v[0] >= v[1]) as u8)
            | (((v[1] >= v[2]) as u8) << 1)
            | (((v[2] >= v[3]) as u8) << 2)
            | (((v[3] >= v[0]) as u8) << 3)
            | (((v[0] >= c) as u8) << 4)
            | (((v[1] >= c) as u8) << 5)
            | (((v[2] >= c) as u8) << 6)
            | (((v[3] >= c) as u8) << 7);
        DirectionCode(b)
    }

    /// Where the level crosses `edge`, as a fraction along its canonical
    /// direction (0.0 at the first node, 1.0 at the second), clamped to
    /// [0, 1]. A crossing at a node is exact (0.0 or 1.0).
    #[inline(always)]
    pub fn crossing(&self, edge: Edge, level: f32) -> f32 {
        let (a, b) = edge.canonical();
        if self.value(a) == level {
            return 0.0;
        }
        if self.value(b) == level {
            return 1.0;
        }
        self.crossing_inside(edge as usize, level)
    }

    /// [`Subgrid::crossing`] of the edge with index `edge` (`0..8`) when
    /// neither of its nodes is at the level: the compiled traversal's case,
    /// where the nodes come from a table instead of a match.
    #[inline(always)]
    pub(crate) fn crossing_inside(&self, edge: usize, level: f32) -> f32 {
        let [a, b] = match crate::contour::tree::get(&ENDS, edge & 7) {
            Some(&ends) => ends,
            None => [0, 0],
        };
        let (va, vb) = (self.at(usize::from(a)), self.at(usize::from(b)));
        // Nearly always strictly inside: then both differences were finite
        // (an infinite one gives an infinite, zero or NaN quotient), and
        // the quotient is what the full form below gives, without its
        // finiteness tests on every crossing.
        let t = (level - va) / (vb - va);
        if t > 0.0 && t < 1.0 {
            return t;
        }
        crossing_between(va, vb, level)
    }
}

/// The fraction of the way from `va` to `vb` where `level` lies, clamped
/// to [0, 1] (0.0 for NaN: a zero-length range never contains a
/// crossing); differences too large for `f32` are taken at half scale.
#[inline(never)]
fn crossing_between(va: f32, vb: f32, level: f32) -> f32 {
    let mut num = level - va;
    let mut den = vb - va;
    if !(num.is_finite() && den.is_finite()) {
        // Extreme values: halve everything so the differences fit.
        num = level * 0.5 - va * 0.5;
        den = vb * 0.5 - va * 0.5;
    }
    let t = num / den;
    let t = if t >= 0.0 { t } else { 0.0 };
    if t <= 1.0 { t } else { 1.0 }
}

/// Each edge's nodes in [`Edge::canonical`] order, as node indices (built
/// at compile time: an index out of range there is a build error).
#[allow(clippy::indexing_slicing)]
const ENDS: [[u8; 2]; 8] = {
    let mut t = [[0u8; 2]; 8];
    let mut e = 0;
    while e < 8 {
        t[e] = match Edge::from_index(e) {
            Some(edge) => [edge.canonical().0 as u8, edge.canonical().1 as u8],
            None => [0, 0],
        };
        e += 1;
    }
    t
};
