//! # isoscope-core
//!
//! The heap-free, `no_std` core of isoscope: Zyda's *contouring trees*
//! ("A Decomposable Algorithm for Contour Surface Display Generation") for
//! 2x2 subgrids, zero-copy grid and volume views, and the chicken-wire
//! contour surface of a volume.
//!
//! The modules follow the pipeline, volume to DAC: each folder of `src/`
//! is one stage ([`contour`], [`path`], [`engine`], [`view`], [`beam`], [`output`])
//! or the UART protocol ([`wire`]); [`command`] and [`demo`] stand alone.
//!
//! - [`contour`]: the contouring, bottom up:
//!   - [`contour::subgrid`]: the five nodes and eight downhill edges of a
//!     2x2 subgrid.
//!   - [`contour::tree`]: the contouring trees of all 256 direction codes,
//!     built at compile time.
//!   - [`contour::trace`]: the paper's Figure 8 traversal (and its
//!     correction for nodes at the level).
//!   - [`contour::pen`]: placement of crossings and tidy drawing commands.
//!   - [`contour::voxel`]: the sample types a grid may hold
//!     ([`contour::Voxel`]).
//!   - [`contour::grid`]: [`contour::grid::Grid2`] and
//!     [`contour::grid::Volume`] views with strides.
//!   - [`contour`] itself: every subgrid of a grid, one or many levels.
//!   - [`contour::surface`]: every slice of a volume along any planes.
//! - [`command`]: `MoveTo / LineTo / Point` and the sink trait.
//! - [`demo`]: built-in volumes (hydrogen 3d_xy orbital, gyroid, sphere,
//!   torus).
//! - [`view`]: 3D view, projection and auto-fit to the DAC range
//!   ([`view::ViewTransform`]), onto points in DAC units
//!   ([`view::ScreenPoint`]).
//! - [`beam`]: the beam scheduler (display list to DAC samples,
//!   [`beam::Scheduler`]) and frame statistics ([`beam::FrameStats`]);
//!   [`beam::pace`]: slowing the sample clock to what the refill keeps up
//!   with.
//! - [`output`]: the DAC samples and the [`output::Dac`] trait every DAC
//!   implements:
//!   - [`output::mock`]: a heap-free mock with ASCII art;
//!   - `output::mcp4922` (feature `embedded-hal`): the MCP4922 SPI DAC.
//! - [`path`]: the one path pipeline: surfaces stored compactly
//!   ([`path::Geometry`]), culled, stitched, merged, spliced and ordered in
//!   bounded memory.
//! - [`engine`]: the device engine behind the UART, which every board and
//!   every host command that draws a picture runs: streaming volumes slice
//!   by slice, the path pipeline once a volume is complete, a
//!   double-buffered picture, view changes without the volume;
//!   [`engine::Board`] names a board's capacities.
//! - [`wire`]: the UART frame protocol shared by host and device (postcard,
//!   CRC-32, COBS; see `docs/wire-format.md`).
//!
//! No `alloc`, no `unsafe`, no panics on any input; all float maths goes
//! through `libm` so the host and the MCU compute the same numbers.
//!
//! ```
//! use isoscope_core::command::{Command, CommandSink, Point2};
//! use isoscope_core::contour::contour_grid;
//! use isoscope_core::contour::grid::Grid2;
//! use isoscope_core::contour::trace::Traversal;
//!
//! /// A heap-free sink: the first 16 commands.
//! struct First16 { cmds: [Option<Command<Point2>>; 16], n: usize }
//! impl CommandSink<Point2> for First16 {
//!     type Error = Command<Point2>; // hands the command back when full
//!     fn command(&mut self, _level: usize, c: Command<Point2>) -> Result<(), Self::Error> {
//!         let slot = self.cmds.get_mut(self.n).ok_or(c)?;
//!         *slot = Some(c);
//!         self.n += 1;
//!         Ok(())
//!     }
//! }
//!
//! // The paper's Figure 5 subgrid: rows (LL, LR), (UL, UR).
//! let samples = [150u8, 40, 30, 60];
//! let grid = Grid2::new(&samples, 2, 2).unwrap();
//! let mut sink = First16 { cmds: [None; 16], n: 0 };
//! let stats = contour_grid(&grid, &[100.0], Traversal::Corrected, Point2::new, &mut sink).unwrap();
//! assert_eq!(stats.commands, 3);
//! assert!(matches!(sink.cmds[0], Some(Command::MoveTo(p)) if (p.x - 0.4545).abs() < 1e-4 && p.y == 0.0));
//! ```
#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]
#![warn(missing_docs)]
#![cfg_attr(
    not(test),
    deny(
        clippy::panic,
        clippy::unwrap_used,
        clippy::expect_used,
        clippy::indexing_slicing,
        clippy::unreachable
    )
)]

pub mod beam;
pub mod command;
pub mod contour;
pub mod demo;
pub mod engine;
mod fastmath;
pub mod output;
pub mod path;
pub mod view;
pub mod wire;
