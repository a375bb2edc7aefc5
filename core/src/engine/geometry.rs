//! The chicken-wire surface of one volume in voxel coordinates: contour
//! commands kept so that a new view re-projects them without the volume.

use crate::command::{Command, Point3};

/// Command kinds, one byte each beside the points.
const MOVE: u8 = 0;
const LINE: u8 = 1;
const DOT: u8 = 2;

/// Contour commands in voxel coordinates over caller storage (13 bytes a
/// command: a [`Point3`] and its kind). The capacity is the shorter of the
/// two slices.
///
/// `push` hands the command back when full and counts it; a polyline cut
/// short by the capacity keeps the part that fitted, and a lone trailing
/// `MoveTo` is taken back, so the store always holds whole drawing
/// commands.
#[derive(Debug, PartialEq)]
pub struct Geometry<'a> {
    points: &'a mut [Point3],
    kinds: &'a mut [u8],
    len: usize,
    dropped: u32,
    /// A command of the open polyline was refused: its later `LineTo`s are
    /// refused too, until the next `MoveTo` or `Point`.
    broken: bool,
}

impl<'a> Geometry<'a> {
    /// An empty store over `points` and `kinds`.
    pub fn new(points: &'a mut [Point3], kinds: &'a mut [u8]) -> Self {
        Self { points, kinds, len: 0, dropped: 0, broken: false }
    }

    /// The most commands it holds.
    pub fn capacity(&self) -> usize {
        self.points.len().min(self.kinds.len())
    }

    /// Commands held.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether no command is held.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Commands refused since the last [`Geometry::clear`].
    pub fn dropped(&self) -> u32 {
        self.dropped
    }

    /// Forget every command.
    pub fn clear(&mut self) {
        self.len = 0;
        self.dropped = 0;
        self.broken = false;
    }

    /// Append a command.
    ///
    /// # Errors
    /// The command, when the store is full.
    pub fn push(&mut self, command: Command<Point3>) -> Result<(), Command<Point3>> {
        match command {
            Command::LineTo(_) if self.broken => {
                self.dropped = self.dropped.saturating_add(1);
                return Err(command);
            }
            Command::LineTo(_) => {}
            Command::MoveTo(_) | Command::Point(_) => self.broken = false,
        }
        if self.len >= self.capacity() {
            self.broken = true;
            self.dropped = self.dropped.saturating_add(1);
            // A MoveTo whose line did not fit would draw nothing: take it back.
            if self.len > 0 && self.kinds.get(self.len - 1) == Some(&MOVE) {
                self.len -= 1;
                self.dropped = self.dropped.saturating_add(1);
            }
            return Err(command);
        }
        let (p, kind) = match command {
            Command::MoveTo(p) => (p, MOVE),
            Command::LineTo(p) => (p, LINE),
            Command::Point(p) => (p, DOT),
        };
        if let (Some(slot), Some(k)) = (self.points.get_mut(self.len), self.kinds.get_mut(self.len)) {
            *slot = p;
            *k = kind;
            self.len += 1;
        }
        Ok(())
    }

    /// The commands, in the order they came.
    pub fn commands(&self) -> impl Iterator<Item = Command<Point3>> + '_ {
        let n = self.len;
        self.points.iter().zip(self.kinds.iter()).take(n).map(|(&p, &k)| match k {
            MOVE => Command::MoveTo(p),
            DOT => Command::Point(p),
            _ => Command::LineTo(p),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(x: f32) -> Point3 {
        Point3::new(x, 0.0, 0.0)
    }

    #[test]
    fn push_hands_back_when_full_and_takes_back_a_lone_move() {
        let (mut pts, mut kinds) = ([Point3::default(); 3], [0u8; 3]);
        let mut g = Geometry::new(&mut pts, &mut kinds);
        assert_eq!(g.push(Command::MoveTo(p(0.0))), Ok(()));
        assert_eq!(g.push(Command::LineTo(p(1.0))), Ok(()));
        assert_eq!(g.push(Command::MoveTo(p(2.0))), Ok(()));
        assert_eq!(g.push(Command::LineTo(p(3.0))), Err(Command::LineTo(p(3.0))));
        // The MoveTo at 2 lost its line: it is gone too, and both count.
        assert_eq!(g.len(), 2);
        assert_eq!(g.dropped(), 2);
        // The rest of that polyline is refused although a slot is free now.
        assert_eq!(g.push(Command::LineTo(p(4.0))), Err(Command::LineTo(p(4.0))));
        assert_eq!(g.dropped(), 3);
        let got: Vec<_> = g.commands().collect();
        assert_eq!(got, [Command::MoveTo(p(0.0)), Command::LineTo(p(1.0))]);
        assert_eq!(g.push(Command::Point(p(5.0))), Ok(()));
        assert_eq!(g.commands().last(), Some(Command::Point(p(5.0))));
        g.clear();
        assert!(g.is_empty());
        assert_eq!(g.dropped(), 0);
    }
}
