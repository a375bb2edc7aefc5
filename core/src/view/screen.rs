//! Screen coordinates: points in DAC units, before quantisation.

/// A point on the screen in DAC units (0.0 ..= 2^bits - 1 on each axis,
/// x to the right, y up), kept as `f32` so that later stages (stitching,
/// collinear merging) work below one LSB; the beam scheduler rounds to
/// whole DAC codes.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ScreenPoint {
    /// Horizontal position in DAC units.
    pub x: f32,
    /// Vertical position in DAC units.
    pub y: f32,
}

impl ScreenPoint {
    /// A point from its coordinates.
    pub const fn new(x: f32, y: f32) -> Self {
        Self { x, y }
    }

    /// Euclidean distance to another point, in DAC units.
    #[inline]
    pub fn distance(self, o: ScreenPoint) -> f32 {
        let (dx, dy) = (o.x - self.x, o.y - self.y);
        libm::sqrtf(dx * dx + dy * dy)
    }
}
