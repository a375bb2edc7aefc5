//! # isoscope-core
//!
//! The heap-free, `no_std` core of isoscope: Zyda's *contouring trees*
//! ("A Decomposable Algorithm for Contour Surface Display Generation") for
//! 2x2 subgrids, zero-copy grid and volume views, and the chicken-wire
//! contour surface of a volume.
//!
//! - [`subgrid`]: the five nodes and eight downhill edges of a 2x2 subgrid.
//! - [`tree`]: the contouring trees of all 256 direction codes, built at
//!   compile time.
//! - [`trace`]: the paper's Figure 8 traversal (and its correction for nodes
//!   at the level).
//! - [`pen`]: placement of crossings and tidy drawing commands.
//! - [`grid`]: [`grid::Grid2`] and [`grid::Volume`] views with strides.
//! - [`contour`]: every subgrid of a grid, one or many levels.
//! - [`surface`]: every slice of a volume along any planes.
//! - [`command`]: `MoveTo / LineTo / Point` and the sink trait.
//! - [`demo`]: built-in volumes (hydrogen 3d_xy orbital, gyroid).
//!
//! No `alloc`, no `unsafe`, no panics on any input; all float maths goes
//! through `libm` so the host and the MCU compute the same numbers.
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

pub mod command;
pub mod contour;
pub mod demo;
pub mod grid;
pub mod pen;
pub mod sample;
pub mod subgrid;
pub mod surface;
mod sweep;
pub mod trace;
pub mod tree;
