//! What a picture draws, as a set of segments: shared by the engine tests
//! here and the link tests of `host-sim` (which include this file by path).

use isoscope_core::command::{Command, Point3};
use isoscope_core::engine::{Geometry, Packed};
use std::collections::HashSet;

/// A drawn segment, undirected (a dot is a segment from a point to itself),
/// in the engine's fixed point.
pub type Seg = (Packed, Packed);

/// The segments commands draw, each once, sorted: zero-length lines left
/// out (the quantisation can join two crossings a hair apart; the engine
/// then draws one point, not a line), duplicates and dots on lines culled.
pub fn segments(cmds: impl Iterator<Item = Command<Point3>>, shift: u8) -> Vec<Seg> {
    let mut out = Vec::new();
    let mut at = None;
    for c in cmds {
        let p = Geometry::quantise_with(shift, *c.point());
        match c {
            Command::MoveTo(_) => at = Some(p),
            Command::Point(_) => {
                out.push((p, p));
                at = None;
            }
            Command::LineTo(_) => {
                if let Some(a) = at.filter(|&a| a != p) {
                    out.push(if a < p { (a, p) } else { (p, a) });
                }
                at = Some(p);
            }
        }
    }
    out.sort();
    out.dedup();
    let on_line: HashSet<Packed> = out.iter().filter(|(a, b)| a != b).flat_map(|&(a, b)| [a, b]).collect();
    out.retain(|(a, b)| a != b || !on_line.contains(a));
    out
}
