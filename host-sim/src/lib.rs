//! isoscope's host side: the same `isoscope-core` under `std`.
//!
//! - [`volume`]: volume sources (raw files, built-in demos) and sample types.
//! - [`orient`]: a file's orientation reduced to a rearrangement of its
//!   axes (the default view shows a head upright, facing the viewer).
//! - [`formats`]: volume file formats (NRRD, NIfTI-1, MRC/CCP4, Gaussian
//!   cube, VTK legacy), one module each.
//! - [`contour`]: parallel chicken-wire contouring of a volume into records,
//!   and their CSV export.
//! - [`fit`]: a volume fitted to a board: `--crop`, `--downsample` (block
//!   means), the smallest downsample a board takes, the narrowest exact
//!   sample type.
//! - [`info`]: a volume's summary, histogram and suggested levels.
//! - [`progress`]: progress lines on a terminal for long work.
//! - [`scene`]: a whole frame: contour, project, display list, cull,
//!   stitch, order, beam schedule.
//! - [`svg`]: the display list as SVG.
//! - [`virtual_dac`]: the host's DAC, recording samples with their clock.
//! - [`phosphor`]: the screen: DAC samples rasterised as a CRT in XY mode
//!   shows them (Gaussian spot, energy per sample, P31 green), to RGB and PNG.
//! - [`animate`]: the surface turning on the simulated screen, as a looping
//!   GIF or APNG.
//! - [`link`]: the host side of the UART link: open a port, stream a
//!   volume with a send window and retransmission, report the throughput.
//! - [`device`]: the virtual board: the core's device engine behind a
//!   pseudo-terminal or TCP port, at a real UART's line rate.
//! - [`ports`] (not on wasm32): the machine's serial ports, which look like
//!   a board, and the one `--port auto` picks.
//! - [`serve`] (not on wasm32): the web app's files over HTTP on a local
//!   port (`isoscope-sim serve`).
//! - `tty` (Unix only): the virtual board's pseudo-terminal.
//! - [`outfile`]: output files written whole or not at all.
//! - [`relay`]: a noisy line between a sender and a board, for testing
//!   links.
//! - [`wav`]: the sample stream as a WAV file (X, Y and the beam) for a
//!   DC-coupled sound card driving a real scope.

pub mod animate;
pub mod board;
pub mod contour;
pub mod device;
pub mod fit;
pub mod formats;
pub mod info;
pub mod link;
pub mod orient;
pub mod outfile;
pub mod phosphor;
#[cfg(not(target_arch = "wasm32"))]
pub mod ports;
pub mod progress;
pub mod relay;
pub mod scene;
#[cfg(not(target_arch = "wasm32"))]
pub mod serve;
pub mod svg;
#[cfg(unix)]
pub mod tty;
pub mod virtual_dac;
pub mod volume;
pub mod wav;
