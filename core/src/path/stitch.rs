//! The stitch pass: what would be drawn twice culled, then fragments walked
//! into maximal polylines, open paths first, the straightest way on.

use super::ChainStats;
use super::index::Index;
use super::merge::Walk;
use super::store::Geometry;

/// The stitch pass: culled, then walked into maximal polylines (see the
/// [module docs](super)).
pub(super) fn stitch(x: &mut Index<'_, '_>, walk: &mut Walk, dst: &mut Geometry<'_>, stats: &mut ChainStats) {
    x.cull(stats);
    // Open paths first (from an end where an odd number meet), then
    // what is left: closed loops. (The first round ends when no odd
    // end is left: at once for a closed surface.)
    for odd in [true, false] {
        for f in 0..x.frags {
            if odd && x.odd == Some(0) {
                break;
            }
            x.poll.tick(1);
            if x.drawn(f) {
                continue;
            }
            let (from, to) = x.span(f);
            let last = to - 1;
            let end = if !odd || x.degree(x.point(from)) % 2 == 1 {
                from
            } else if x.degree(x.point(last)) % 2 == 1 {
                last
            } else {
                continue;
            };
            walk.take(x, dst, (end, f), false, stats);
            // Each step takes a fragment for good: at most `frags`
            // of them (a bound the walk keeps even if an end were
            // ever left in its list).
            let mut steps = 0;
            while steps < x.frags
                && let Some(next) = x.straightest(walk.cur, walk.prev)
            {
                walk.take(x, dst, next, true, stats);
                steps += 1;
                x.poll.tick(16);
            }
            walk.out.finish(dst, stats);
        }
        x.odd = None;
    }
}
