//! Drawing commands and the sink trait that receives them.
//!
//! The paper's three drawing instructions map onto [`Command`]:
//! SETPOINT is [`Command::MoveTo`] (move with the beam off, then switch it on),
//! DRAWTO is [`Command::LineTo`] and DRAWPOINT is [`Command::Point`].

/// A 2D point in grid coordinates (x along the fast axis), in grid units.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Point2 {
    /// Coordinate along the grid's first (fast) axis.
    pub x: f32,
    /// Coordinate along the grid's second axis.
    pub y: f32,
}

/// A 3D point in voxel coordinates (x the fastest axis of the volume).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Point3 {
    /// Voxel x (fastest axis).
    pub x: f32,
    /// Voxel y.
    pub y: f32,
    /// Voxel z (slowest axis).
    pub z: f32,
}

impl Point2 {
    /// A point from its coordinates.
    pub const fn new(x: f32, y: f32) -> Self {
        Self { x, y }
    }
}

impl Point3 {
    /// A point from its coordinates.
    pub const fn new(x: f32, y: f32, z: f32) -> Self {
        Self { x, y, z }
    }
}

/// One drawing command.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Command<P> {
    /// SETPOINT: move with the beam off to the point; a polyline starts here.
    MoveTo(P),
    /// DRAWTO: draw a line from the current point to this one.
    LineTo(P),
    /// DRAWPOINT: the picture here is a single point.
    Point(P),
}

impl<P> Command<P> {
    /// The point the command names.
    pub fn point(&self) -> &P {
        match self {
            Command::MoveTo(p) | Command::LineTo(p) | Command::Point(p) => p,
        }
    }

    /// The command's op letter as written in CSV exports: `M`, `L` or `P`.
    pub fn op(&self) -> char {
        match self {
            Command::MoveTo(_) => 'M',
            Command::LineTo(_) => 'L',
            Command::Point(_) => 'P',
        }
    }

    /// The same command with its point mapped.
    pub fn map<Q>(self, f: impl FnOnce(P) -> Q) -> Command<Q> {
        match self {
            Command::MoveTo(p) => Command::MoveTo(f(p)),
            Command::LineTo(p) => Command::LineTo(f(p)),
            Command::Point(p) => Command::Point(f(p)),
        }
    }
}

/// Receives drawing commands from the contouring stages.
///
/// `level` is the index of the contour level in the slice of levels the
/// contouring call was given (0 for a single level). A sink that cannot take
/// more (a full buffer, a failed write) returns an error and contouring stops
/// with that error.
pub trait CommandSink<P> {
    /// Why the sink could not take a command.
    type Error;

    /// Take one command.
    ///
    /// # Errors
    /// Whatever the sink defines; contouring stops and hands it back.
    fn command(&mut self, level: usize, command: Command<P>) -> Result<(), Self::Error>;
}

impl<P, S: CommandSink<P> + ?Sized> CommandSink<P> for &mut S {
    type Error = S::Error;

    #[inline]
    fn command(&mut self, level: usize, command: Command<P>) -> Result<(), Self::Error> {
        (**self).command(level, command)
    }
}

/// A sink that only counts the commands it is given (for benchmarks and
/// statistics); it never fails.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CountingSink {
    /// `MoveTo` commands seen.
    pub moves: u64,
    /// `LineTo` commands seen.
    pub lines: u64,
    /// `Point` commands seen.
    pub points: u64,
}

impl CountingSink {
    /// All commands seen.
    pub fn total(&self) -> u64 {
        self.moves + self.lines + self.points
    }
}

impl<P> CommandSink<P> for CountingSink {
    type Error = core::convert::Infallible;

    #[inline]
    fn command(&mut self, _level: usize, command: Command<P>) -> Result<(), Self::Error> {
        match command {
            Command::MoveTo(_) => self.moves += 1,
            Command::LineTo(_) => self.lines += 1,
            Command::Point(_) => self.points += 1,
        }
        Ok(())
    }
}
