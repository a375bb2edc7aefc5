//! A heap-free mock DAC that draws samples as ASCII art, for tests.
//!
//! [`MockDac<W, H>`] is a [`Dac`] with a `W` x `H` character canvas in
//! place of an oscilloscope, in the spirit of embedded-graphics'
//! `MockDisplay`: lit samples mark their cell `#`; blanked ones, if
//! [enabled](MockDac::with_blank), mark `.` (a `#` is never overwritten by a
//! `.`); untouched cells are spaces.
//!
//! **Mapping.** With `bits` of resolution (codes `0 ..= 2^bits - 1`), code
//! `x` falls in column `floor(x * W / 2^bits)` and code `y` in row
//! `H - 1 - floor(y * H / 2^bits)`: x grows to the right and y upwards, so
//! row 0 of the picture is its top (the highest codes). With `2^bits == W`
//! each code is one column.
//!
//! ```
//! use isoscope_core::output::{Beam, Dac, Sample};
//! use isoscope_core::output::mock::MockDac;
//!
//! let mut dac = MockDac::<4, 2>::new(2); // codes 0..=3: one column each, two codes a row
//! dac.write([Sample::new(0, 0, Beam::On), Sample::new(3, 3, Beam::On)]).unwrap();
//! dac.assert_eq(&[
//!     "   #",
//!     "#",
//! ]);
//! ```

use super::{Beam, Dac, Sample};

/// Why the [`MockDac`] refused a sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum MockDacError {
    /// A code is above `2^bits - 1`; the sample was not drawn, nor any after
    /// it in the same write.
    OutOfRange {
        /// X code of the sample.
        x: u16,
        /// Y code of the sample.
        y: u16,
    },
}

impl core::fmt::Display for MockDacError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            MockDacError::OutOfRange { x, y } => write!(f, "sample ({x}, {y}) is outside the DAC range"),
        }
    }
}

impl core::error::Error for MockDacError {}

/// Cell of a lit sample.
const LIT: u8 = b'#';
/// Cell of a blanked sample (when enabled).
const BLANK: u8 = b'.';
/// Untouched cell.
const EMPTY: u8 = b' ';

/// A mock DAC drawing on a `W` columns x `H` rows character canvas
/// (`W * H` bytes, no heap). See the [module docs](self) for the mapping.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MockDac<const W: usize, const H: usize> {
    canvas: [[u8; W]; H],
    bits: u8,
    show_blank: bool,
    samples: u64,
    lit: u64,
    last: Option<Sample>,
}

impl<const W: usize, const H: usize> Default for MockDac<W, H> {
    /// A 12-bit mock DAC, blanked samples not shown.
    fn default() -> Self {
        Self::new(12)
    }
}

impl<const W: usize, const H: usize> MockDac<W, H> {
    /// An empty canvas for a DAC of `bits` resolution (clamped into
    /// `1 ..= 16`); blanked samples are not shown.
    pub const fn new(bits: u8) -> Self {
        let bits = if bits < 1 {
            1
        } else if bits > 16 {
            16
        } else {
            bits
        };
        Self { canvas: [[EMPTY; W]; H], bits, show_blank: false, samples: 0, lit: 0, last: None }
    }

    /// The same DAC, marking cells visited by blanked samples `.` (or not).
    pub const fn with_blank(mut self, show: bool) -> Self {
        self.show_blank = show;
        self
    }

    /// The resolution in bits.
    pub fn bits(&self) -> u8 {
        self.bits
    }

    /// The largest code accepted, `2^bits - 1`.
    pub fn max_code(&self) -> u16 {
        u16::MAX >> (16 - self.bits.clamp(1, 16))
    }

    /// The cell `(column, row)` of a sample's codes (row 0 at the top), or
    /// `None` for a code out of range.
    pub fn cell(&self, x: u16, y: u16) -> Option<(usize, usize)> {
        let max = self.max_code();
        if x > max || y > max {
            return None;
        }
        let span = u64::from(max) + 1;
        let col = u64::from(x) * W as u64 / span;
        let up = u64::from(y) * H as u64 / span;
        let col = usize::try_from(col).ok()?;
        let up = usize::try_from(up).ok()?;
        Some((col, H.checked_sub(1)?.checked_sub(up)?))
    }

    /// Draw one sample.
    ///
    /// # Errors
    /// [`MockDacError::OutOfRange`] for a code above `2^bits - 1`; nothing is
    /// drawn or counted then.
    pub fn draw(&mut self, sample: Sample) -> Result<(), MockDacError> {
        let (col, row) =
            self.cell(sample.x, sample.y).ok_or(MockDacError::OutOfRange { x: sample.x, y: sample.y })?;
        self.samples += 1;
        self.last = Some(sample);
        let lit = sample.beam == Beam::On;
        if lit {
            self.lit += 1;
        }
        if let Some(cell) = self.canvas.get_mut(row).and_then(|r| r.get_mut(col)) {
            if lit {
                *cell = LIT;
            } else if self.show_blank && *cell != LIT {
                *cell = BLANK;
            }
        }
        Ok(())
    }

    /// The canvas: `H` rows of `W` bytes, row 0 at the top, each `#`, `.`
    /// or a space.
    pub fn picture(&self) -> &[[u8; W]; H] {
        &self.canvas
    }

    /// The canvas rows as text, top first.
    pub fn rows(&self) -> impl Iterator<Item = &str> + '_ {
        // The canvas only ever holds ASCII.
        self.canvas.iter().map(|r| core::str::from_utf8(r).unwrap_or(""))
    }

    /// Samples drawn since the last [`clear`](MockDac::clear).
    pub fn samples(&self) -> u64 {
        self.samples
    }

    /// Lit samples drawn since the last [`clear`](MockDac::clear).
    pub fn lit_samples(&self) -> u64 {
        self.lit
    }

    /// The last sample drawn since the last [`clear`](MockDac::clear).
    pub fn last_sample(&self) -> Option<Sample> {
        self.last
    }

    /// Empty the canvas and zero the counts (the resolution and the
    /// blank-marking setting stay).
    pub fn clear(&mut self) {
        self.canvas = [[EMPTY; W]; H];
        self.samples = 0;
        self.lit = 0;
        self.last = None;
    }

    /// Whether the canvas matches an ASCII-art picture: one string a row,
    /// top first, `#` lit, `.` blanked (if enabled), space empty. Rows may
    /// be shorter than `W` and fewer than `H` (the rest is empty); anything
    /// but a space beyond the canvas is a mismatch.
    pub fn matches(&self, pattern: &[&str]) -> bool {
        let rows = H.max(pattern.len());
        let cols = W.max(pattern.iter().map(|r| r.len()).max().unwrap_or(0));
        (0..rows).all(|r| (0..cols).all(|c| self.at(c, r) == pattern_at(pattern, c, r)))
    }

    /// Assert that the canvas matches an ASCII-art picture (see
    /// [`matches`](MockDac::matches)).
    ///
    /// # Panics
    /// On a mismatch (that is its job, in tests), printing the canvas, the
    /// pattern and the differing cells side by side.
    #[track_caller]
    #[allow(clippy::panic)] // an assertion: panicking is what it is for
    pub fn assert_eq(&self, pattern: &[&str]) {
        if !self.matches(pattern) {
            panic!("{}", Mismatch { dac: self, pattern });
        }
    }

    /// The canvas cell at column `c`, row `r`; a space outside.
    fn at(&self, c: usize, r: usize) -> u8 {
        self.canvas.get(r).and_then(|row| row.get(c)).copied().unwrap_or(EMPTY)
    }
}

/// The pattern's cell at column `c`, row `r`; a space outside.
fn pattern_at(pattern: &[&str], c: usize, r: usize) -> u8 {
    pattern.get(r).and_then(|row| row.as_bytes().get(c)).copied().unwrap_or(EMPTY)
}

impl<const W: usize, const H: usize> Dac for MockDac<W, H> {
    type Error = MockDacError;

    fn write<I>(&mut self, samples: I) -> Result<(), MockDacError>
    where
        I: IntoIterator<Item = Sample>,
    {
        samples.into_iter().try_for_each(|s| self.draw(s))
    }
}

/// The panic message of [`MockDac::assert_eq`]: canvas, pattern and diff
/// side by side, framed.
struct Mismatch<'a, const W: usize, const H: usize> {
    dac: &'a MockDac<W, H>,
    pattern: &'a [&'a str],
}

impl<const W: usize, const H: usize> core::fmt::Display for Mismatch<'_, W, H> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let rows = H.max(self.pattern.len());
        let cols = W.max(self.pattern.iter().map(|r| r.len()).max().unwrap_or(0));
        let bar = |f: &mut core::fmt::Formatter<'_>| -> core::fmt::Result {
            for i in 0..3 {
                f.write_str(if i == 0 { "+" } else { " +" })?;
                for _ in 0..cols {
                    f.write_str("-")?;
                }
                f.write_str("+")?;
            }
            f.write_str("\n")
        };
        writeln!(f, "MockDac<{W}, {H}> picture differs from the pattern (row 0 is the top, the highest y)")?;
        writeln!(f, "{:<w$} {:<w$} diff (X)", "canvas", "pattern", w = cols + 2)?;
        bar(f)?;
        for r in 0..rows {
            let mut line = |first: bool, cell: &dyn Fn(usize) -> u8| -> core::fmt::Result {
                f.write_str(if first { "|" } else { " |" })?;
                for c in 0..cols {
                    let b = cell(c);
                    // Non-ASCII pattern bytes show as '?'.
                    let ch = if b.is_ascii_graphic() || b == b' ' { char::from(b) } else { '?' };
                    write!(f, "{ch}")?;
                }
                f.write_str("|")
            };
            line(true, &|c| self.dac.at(c, r))?;
            line(false, &|c| pattern_at(self.pattern, c, r))?;
            line(false, &|c| if self.dac.at(c, r) == pattern_at(self.pattern, c, r) { b' ' } else { b'X' })?;
            f.write_str("\n")?;
        }
        bar(f)?;
        writeln!(f, "samples: {}, lit: {}", self.dac.samples, self.dac.lit)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::string::ToString;

    #[test]
    fn mapping_floor_and_y_up() {
        let dac = MockDac::<16, 8>::new(12);
        assert_eq!(dac.cell(0, 0), Some((0, 7)));
        assert_eq!(dac.cell(255, 511), Some((0, 7)));
        assert_eq!(dac.cell(256, 512), Some((1, 6)));
        assert_eq!(dac.cell(4095, 4095), Some((15, 0)));
        assert_eq!(dac.cell(4096, 0), None);
        assert_eq!(dac.cell(0, u16::MAX), None);
        let wide = MockDac::<20, 10>::new(16);
        assert_eq!(wide.cell(u16::MAX, u16::MAX), Some((19, 0)));
        assert_eq!(wide.cell(32768, 32767), Some((10, 5)));
        // Degenerate canvases never panic.
        let mut none = MockDac::<0, 0>::new(4);
        assert_eq!(none.cell(3, 3), None);
        assert_eq!(none.draw(Sample::new(3, 3, Beam::On)), Err(MockDacError::OutOfRange { x: 3, y: 3 }));
        none.assert_eq(&[]);
        assert_eq!(MockDac::<4, 4>::new(0).bits(), 1);
        assert_eq!(MockDac::<4, 4>::new(99).max_code(), u16::MAX);
    }

    #[test]
    fn draws_counts_and_clears() {
        let mut dac = MockDac::<4, 4>::new(2).with_blank(true);
        let s = [
            Sample::new(0, 0, Beam::Off),
            Sample::new(1, 1, Beam::On),
            Sample::new(1, 1, Beam::Off), // a '.' never hides a '#'
            Sample::new(3, 3, Beam::Off),
        ];
        dac.write(s).unwrap();
        dac.assert_eq(&["   .", "", " #", "."]);
        assert_eq!((dac.samples(), dac.lit_samples()), (4, 1));
        assert_eq!(dac.last_sample(), Some(Sample::new(3, 3, Beam::Off)));
        assert_eq!(dac.rows().collect::<std::vec::Vec<_>>(), ["   .", "    ", " #  ", ".   "]);
        assert_eq!(dac.picture()[2], *b" #  ");
        // Out of range: stops there.
        let err = dac.write([
            Sample::new(2, 2, Beam::On),
            Sample::new(4, 0, Beam::On),
            Sample::new(0, 3, Beam::On),
        ]);
        assert_eq!(err, Err(MockDacError::OutOfRange { x: 4, y: 0 }));
        assert_eq!(err.unwrap_err().to_string(), "sample (4, 0) is outside the DAC range");
        dac.assert_eq(&["   .", "  #", " #", "."]);
        assert_eq!(dac.samples(), 5);
        dac.clear();
        dac.assert_eq(&[]);
        assert_eq!((dac.samples(), dac.lit_samples(), dac.last_sample()), (0, 0, None));
        // Blanked samples are invisible by default.
        let mut dark = MockDac::<4, 4>::new(2);
        dark.write([Sample::new(1, 1, Beam::Off)]).unwrap();
        dark.assert_eq(&["", "", "", ""]);
        assert_eq!(dark, MockDac::<4, 4>::new(2).tap_draw(Sample::new(1, 1, Beam::Off)));
    }

    impl<const W: usize, const H: usize> MockDac<W, H> {
        fn tap_draw(mut self, s: Sample) -> Self {
            self.draw(s).unwrap();
            self
        }
    }

    #[test]
    fn matches_pads_and_rejects_extra() {
        let mut dac = MockDac::<3, 2>::new(8);
        dac.draw(Sample::new(0, 255, Beam::On)).unwrap();
        assert!(dac.matches(&["#"]));
        assert!(dac.matches(&["#  ", "   ", "   "]));
        assert!(!dac.matches(&["#", "", "#"]));
        assert!(!dac.matches(&["#  #"]));
        assert!(!dac.matches(&[" #"]));
    }

    #[test]
    fn mismatch_shows_both_pictures_side_by_side() {
        let mut dac = MockDac::<3, 2>::new(2);
        dac.draw(Sample::new(0, 3, Beam::On)).unwrap();
        let msg = Mismatch { dac: &dac, pattern: &["  #"] }.to_string();
        let want = "\
MockDac<3, 2> picture differs from the pattern (row 0 is the top, the highest y)
canvas pattern diff (X)
+---+ +---+ +---+
|#  | |  #| |X X|
|   | |   | |   |
+---+ +---+ +---+
samples: 1, lit: 1
";
        assert_eq!(msg, want);
    }

    #[test]
    #[should_panic(expected = "picture differs")]
    fn assert_eq_panics_on_mismatch() {
        MockDac::<3, 2>::new(2).assert_eq(&["#"]);
    }
}
