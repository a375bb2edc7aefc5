//! `isoscope-sim`: the isoscope core on the host.

use anyhow::{Context, Result, bail};
use clap::{Args, CommandFactory, Parser, Subcommand, ValueEnum};
use isoscope_core::beam::BeamConfig;
use isoscope_core::contour::Voxel;
use isoscope_core::contour::grid::{Plane, Volume};
use isoscope_core::contour::trace::Traversal;
use isoscope_core::engine::Board;
use isoscope_core::view::{Projection, View};
use isoscope_sim::animate::{AnimConfig, AnimFormat, animate_board};
use isoscope_sim::board::frames_for;
use isoscope_sim::contour::{Job, contour_volume, work_units, write_csv};
use isoscope_sim::link::WireVolume;
use isoscope_sim::outfile::write_whole;
use isoscope_sim::phosphor::PhosphorConfig;
use isoscope_sim::progress::Progress;
use isoscope_sim::scene::{self, Scene, SceneConfig, write_samples};
use isoscope_sim::volume::{DemoSpec, Dims, Dtype, Endian, LoadedVolume, Samples};
use isoscope_sim::wav::{
    WavChannels, WavConfig, WavFormat, audio_beam, audio_frame, sample_frames, write_wav_file_counted,
};
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser, Debug)]
#[command(
    name = "isoscope-sim",
    version,
    about = "The isoscope core on the host: contour volumes, build display frames, see what the scope shows",
    after_help = "Examples:
  isoscope-sim render --demo hydrogen:32 -o hydrogen.png      the paper's Figure 1, as the scope shows it
  isoscope-sim info head.den                                  dims, range, histogram, suggested levels
  isoscope-sim render head.den --level 38 --every 4 --pitch 60 -o head.png
  isoscope-sim stats --demo gyroid:48                         frame statistics (fps at 1 MS/s, blank travel)
  isoscope-sim contour --demo torus:32 --format svg -o torus.svg
  isoscope-sim contour data.raw --dims 256x256x128 --dtype i16 --level 300 -o ct.csv

Volumes: NIfTI-1 (.nii, .hdr), NRRD (.nrrd, .nhdr), MRC/CCP4 (.mrc, .map, .ccp4, .mrcs, .rec),
Gaussian cube (.cube, .cub), VTK legacy (.vtk), VolPack (.den) (any may end in .gz), a raw file
(--dims NXxNYxNZ --dtype u8|u16|i16|f32, x fastest), or --demo hydrogen:N | gyroid:N | sphere:N |
torus:N. Levels: --level L (repeatable); a demo has a default. A volume too large for a board
(send, --board) is downsampled to fit, with a note; --downsample N and --crop X0:X1,Y0:Y1,Z0:Z1
choose.
'isoscope-sim COMMAND --help' lists every flag."
)]
struct Cli {
    #[command(subcommand)]
    command: Cmd,
}

#[derive(Subcommand, Debug)]
enum Cmd {
    /// Contour every slice of a volume (a chicken-wire surface) and export the
    /// drawing commands as CSV: level,axis,slice,op,x,y,z.
    Contour(ContourArgs),
    /// Build one frame as the board does (contour, cull, stitch, order,
    /// project, schedule the beam) and print its statistics as key=value
    /// lines.
    Stats(StatsArgs),
    /// Describe a volume: dims, type, spacing, value range, a histogram and
    /// suggested contour levels.
    Info(InfoArgs),
    /// Write the beam's sample stream as a WAV file (left = X, right = Y,
    /// optional third channel = beam): drive a real scope from a DC-coupled
    /// sound card, no microcontroller needed.
    Wav(WavArgs),
    /// Render what the oscilloscope shows to a PNG: the frame's samples on a
    /// simulated P31 phosphor (beam spot, brightness from beam speed, glow).
    Render(RenderArgs),
    /// Stream a volume to the board over a serial line (or to the virtual
    /// board), slice by slice, with retransmission; print throughput and
    /// payload efficiency as key=value lines.
    Send(SendArgs),
    /// Run the virtual board: the firmware's engine behind a pseudo-terminal
    /// (or TCP port) at a real UART's line rate, one line per event, and a
    /// PNG of the screen whenever it changes.
    Device(DeviceArgs),
    /// A noisy line for testing links: relay TCP clients to a board (e.g.
    /// `device --tcp`), flipping, dropping and doubling bytes and frames
    /// both ways at the rates given, from a seed; one line a client says
    /// what was done.
    Relay(RelayArgs),
    /// List the serial ports, one a line: the name, USB vendor:product ids,
    /// manufacturer and product when known, and which look like a board (an
    /// ST-LINK's virtual COM port, an FTDI, CP210x, CH340 or Prolific
    /// USB-UART): the one `send --port auto` picks.
    Ports,
    /// Serve the web app (built by `scripts/web-build` into target/web) on a
    /// local port, e.g. open http://127.0.0.1:8000/?demo=hydrogen:32.
    Serve(ServeArgs),
    /// Print a completion script for SHELL to standard output, e.g.
    /// `isoscope-sim completions bash > ~/.local/share/bash-completion/completions/isoscope-sim`.
    Completions(CompletionsArgs),
    /// Write the manual page (roff) to standard output or to -o FILE, e.g.
    /// `isoscope-sim manpage -o isoscope-sim.1; man ./isoscope-sim.1`.
    #[command(visible_alias = "man")]
    Manpage(ManpageArgs),
}

#[derive(Args, Debug)]
struct CompletionsArgs {
    /// The shell to write completions for.
    #[arg(value_enum)]
    shell: clap_complete::Shell,
}

#[derive(Args, Debug)]
struct ServeArgs {
    /// The folder to serve: the built web app.
    #[arg(long, default_value = "target/web")]
    dir: PathBuf,
    /// Address to listen on (127.0.0.1:0 picks a free port).
    #[arg(long, default_value = "127.0.0.1:8000")]
    listen: String,
}

#[derive(Args, Debug)]
struct ManpageArgs {
    /// Output file (default: standard output).
    #[arg(short, long)]
    output: Option<PathBuf>,
}

#[derive(Args, Debug)]
struct RelayArgs {
    /// Address to listen on (127.0.0.1:0 picks a free port); the address is
    /// the first line printed.
    #[arg(long, value_name = "ADDR", default_value = "127.0.0.1:0")]
    listen: String,
    /// The board's TCP address (`device --tcp` prints it).
    #[arg(long, value_name = "HOST:PORT")]
    to: String,
    /// Probability that a byte has a bit flipped, 0 to 1.
    #[arg(long, default_value_t = 0.0, value_parser = parse_probability)]
    flip: f64,
    /// Probability that a byte is lost.
    #[arg(long, default_value_t = 0.0, value_parser = parse_probability)]
    drop: f64,
    /// Probability that a byte arrives twice.
    #[arg(long, default_value_t = 0.0, value_parser = parse_probability)]
    dup: f64,
    /// Probability that a whole frame (up to a 0x00 delimiter) is lost.
    #[arg(long, default_value_t = 0.0, value_parser = parse_probability)]
    drop_frame: f64,
    /// Probability that a whole frame arrives twice.
    #[arg(long, default_value_t = 0.0, value_parser = parse_probability)]
    dup_frame: f64,
    /// Lose the N-th frame towards the board (from 0, on each connection);
    /// repeatable.
    #[arg(long, value_name = "N")]
    lose_frame: Vec<u64>,
    /// Seed of the damage (the n-th client gets seed + n).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Exit after this many clients.
    #[arg(long, value_name = "N", value_parser = in_range::<1, 4_294_967_295, u64>)]
    exit_after: Option<u64>,
}

#[derive(Args, Debug)]
struct SendArgs {
    #[command(flatten)]
    input: InputArgs,
    /// The board's port: a serial device (/dev/ttyUSB0, COM3), the
    /// pseudo-terminal `device --pty` printed, tcp:HOST:PORT (`device
    /// --tcp`, QEMU), or auto: the one serial port that looks like a board
    /// (see `isoscope-sim ports`).
    #[arg(long)]
    port: String,
    /// Line rate in bit/s (8N1), 300 to 12,000,000.
    #[arg(long, default_value_t = 921_600, value_parser = in_range::<300, 12_000_000, u32>)]
    baud: u32,
    /// Contour every N-th slice of each plane (the board does; 1 = all).
    #[arg(long, value_name = "N", default_value_t = 1)]
    every: u8,
    /// Frames in flight before waiting for acknowledgements, 1 to 32 (the
    /// board remembers the answers to its last 32).
    #[arg(long, default_value_t = 8, value_parser = in_range::<1, 32, usize>)]
    window: usize,
    /// Data bytes per chunk, 1 to 1024.
    #[arg(long, default_value_t = isoscope_core::wire::MAX_CHUNK, value_parser = in_range::<1, 1024, usize>)]
    chunk: usize,
    /// Timeouts in a row (each about half a second, more on a slow line)
    /// before the board is given up on, 1 to 1000: more for a board that
    /// is slowed down (under a debugger, or an emulator that logs).
    #[arg(long, value_name = "N", default_value_t = isoscope_sim::link::MAX_TIMEOUTS, value_parser = in_range::<1, 1000, u32>)]
    patience: u32,
    /// Set the view first: yaw in degrees (the other angles default to the
    /// default view's).
    #[arg(long, allow_hyphen_values = true)]
    yaw: Option<f32>,
    /// Set the view first: pitch in degrees.
    #[arg(long, allow_hyphen_values = true)]
    pitch: Option<f32>,
    /// Set the view first: roll in degrees.
    #[arg(long, allow_hyphen_values = true)]
    roll: Option<f32>,
    /// Set the view first: perspective with this field of view.
    #[arg(long, value_name = "FOV")]
    perspective: Option<f32>,
    /// Set the view first: spin about the vertical axis, degrees per second.
    #[arg(long, allow_hyphen_values = true)]
    spin: Option<f32>,
    /// The board's kind (f407: the firmware's STM32F407): before sending,
    /// say what it will show of this volume, and refuse a volume it cannot
    /// take, without a round trip.
    #[arg(long, value_name = "NAME", value_parser = parse_board)]
    board: Option<Board>,
}

#[derive(Args, Debug)]
struct DeviceArgs {
    /// Serve on a new pseudo-terminal (Unix only); its path is the first
    /// line printed.
    #[arg(long, conflicts_with = "tcp", required_unless_present = "tcp")]
    pty: bool,
    /// Serve on a TCP address instead (127.0.0.1:0 picks a free port); the
    /// address is the first line printed.
    #[arg(long, value_name = "ADDR")]
    tcp: Option<String>,
    /// The UART's line rate (bit/s, 8N1): bytes are taken no faster; 0 takes
    /// them as fast as they come; at most 12,000,000.
    #[arg(long, default_value_t = 921_600, value_parser = in_range::<0, 12_000_000, u32>)]
    baud: u32,
    /// Rewrite this PNG whenever the picture changes.
    #[arg(long, value_name = "FILE.png")]
    snapshot: Option<PathBuf>,
    /// Snapshot width and height in pixels, 16 to 8192.
    #[arg(long, default_value_t = 512, value_parser = in_range::<16, 8192, u32>)]
    size: u32,
    /// Write one frame's DAC samples (`x y beam` lines) to this file
    /// whenever a new volume is shown.
    #[arg(long, value_name = "FILE")]
    samples: Option<PathBuf>,
    /// Exit after this many volumes are shown (at least 1).
    #[arg(long, value_name = "N", value_parser = in_range::<1, 4_294_967_295, u32>)]
    exit_after: Option<u32>,
    /// With --tcp: drop a client that sends no whole frame for this many
    /// seconds (so an idle or trickling one cannot keep others out).
    #[arg(long, value_name = "SECONDS", default_value_t = 10.0, value_parser = parse_timeout)]
    idle_timeout: f64,
    /// Be this board: its capacities and sample clock (f407: the
    /// firmware's STM32F407). Without it, the sizes below.
    #[arg(long, value_name = "NAME", value_parser = parse_board, conflicts_with_all = ["max_slice_bytes", "points"])]
    board: Option<Board>,
    /// Largest slice the board takes, in bytes (nx * ny * sample size), 64
    /// to 2^30.
    #[arg(long, default_value_t = 1 << 20, value_parser = in_range::<64, 1_073_741_824, usize>)]
    max_slice_bytes: usize,
    /// Points each of the engine's two surfaces holds (it also gets the
    /// scratch to stitch and order them, 8 bytes a point), 16 to 2^26.
    #[arg(long, default_value_t = 1 << 19, value_parser = in_range::<16, 67_108_864, usize>)]
    points: usize,
}

#[derive(Args, Debug)]
struct InfoArgs {
    #[command(flatten)]
    source: Source,
    /// Histogram bins, 1 to 4096.
    #[arg(long, default_value_t = 32, value_parser = in_range::<1, 4096, usize>)]
    bins: usize,
}

#[derive(Args, Debug)]
struct RenderArgs {
    #[command(flatten)]
    scene: StatsArgs,
    /// Output PNG.
    #[arg(short, long, default_value = "isoscope.png")]
    output: PathBuf,
    /// Image width and height in pixels.
    #[arg(long, default_value_t = 1024)]
    size: u32,
    /// Brightness of blanked moves: 0 hides them (a scope with a Z input),
    /// 0.05 shows them faintly (a scope without one).
    #[arg(long, default_value_t = 0.0)]
    show_blanked: f32,
    /// Refresh the frame this many times on the phosphor (persistence), 1
    /// to 10,000.
    #[arg(long, default_value_t = 1, value_parser = in_range::<1, 10_000, u32>)]
    frames: u32,
    /// Also write an animation of the surface slowly turning (yaw) to this
    /// file: .gif, or .png for an animated PNG. (The still picture is not
    /// written then.)
    #[arg(long, value_name = "FILE")]
    animate: Option<PathBuf>,
    /// Animation frames.
    #[arg(long, default_value_t = 72,
          value_parser = in_range::<1, { isoscope_sim::animate::MAX_FRAMES as u64 }, u32>)]
    anim_frames: u32,
    /// Degrees the animation turns in all (360: one full turn, looping).
    #[arg(long, default_value_t = 360.0, allow_hyphen_values = true)]
    turn: f32,
}

#[derive(Args, Debug)]
struct WavArgs {
    #[command(flatten)]
    input: InputArgs,
    #[command(flatten)]
    view: ViewArgs,
    /// Output WAV file.
    #[arg(short, long, default_value = "isoscope.wav")]
    output: PathBuf,
    /// Audio sample rate in Hz (48000, 96000, 192000...).
    #[arg(long, default_value_t = 48_000)]
    audio_rate: u32,
    /// Seconds of audio (the frame repeats).
    #[arg(long, default_value_t = 5.0)]
    seconds: f64,
    /// Refreshes a second to space the samples for: the samples are spread
    /// evenly along the picture's path, as far apart as it takes for the
    /// frame to play this many times a second at --audio-rate (or as fast
    /// as its jumps and dwells let it), and no closer than a full-scale
    /// line a millisecond. Below about 20 a scope's picture flickers; a
    /// long picture at a low rate is drawn coarser instead.
    #[arg(long, default_value_t = isoscope_sim::wav::AUDIO_FPS, value_parser = parse_fps,
          conflicts_with_all = ["lit_step", "scope_beam"])]
    fps: f32,
    /// Samples this far apart along the path, in DAC LSB, whatever the
    /// refresh rate (instead of --fps; default: one full-scale line a
    /// millisecond at the audio rate, or wider for --fps).
    #[arg(long)]
    lit_step: Option<f32>,
    /// Add a third channel with the beam for a Z input: +1 blanked, -1 lit
    /// (Z high blanks, as on the firmware's blank pin).
    #[arg(long)]
    beam_channel: bool,
    /// The beam channel blanks low: -1 blanked, +1 lit (for a Z input that
    /// blanks on a negative voltage; as the firmware's feature
    /// blank-active-low).
    #[arg(long, requires = "beam_channel")]
    blank_active_low: bool,
    /// 32-bit float samples instead of 16-bit PCM.
    #[arg(long)]
    float: bool,
    /// Draw with the scope beam of `render` and the board (and so the
    /// board's very samples, played at the audio rate: slower, dimmer
    /// where the beam moves fast) instead of one made for audio rates.
    #[arg(long)]
    scope_beam: bool,
    #[command(flatten)]
    board: BoardArgs,
}

/// What to contour: a volume, its levels and its slicing planes.
#[derive(Args, Debug, Clone)]
struct InputArgs {
    #[command(flatten)]
    source: Source,
    /// Contour level (repeatable). Default for a demo: its characteristic level.
    #[arg(long = "level", value_name = "L", allow_hyphen_values = true, value_parser = parse_level)]
    levels: Vec<f32>,
    /// Slicing planes, comma-separated: xy, xz, yz.
    #[arg(long, default_value = "xy,xz,yz", value_delimiter = ',')]
    axes: Vec<String>,
    #[command(flatten)]
    fit: FitArgs,
}

/// How to make a volume smaller, for a board or by choice.
#[derive(Args, Debug, Clone, Copy)]
struct FitArgs {
    /// Replace each block of N x N x N voxels (or NX x NY x NZ: `2,2,1`)
    /// by its mean (integers rounded, in their type); samples short of a
    /// whole block at an axis's end are left out. Without it (and
    /// --crop), a volume a board cannot take (send, or --board) is
    /// downsampled by the smallest factor that fits, with a note.
    #[arg(long, value_name = "N|NX,NY,NZ")]
    downsample: Option<isoscope_sim::fit::Factors>,
    /// Keep only these half-open voxel ranges, from 0 (a bound left out is
    /// the axis's start or end: `:,:,40:`); applied before --downsample.
    #[arg(long, value_name = "X0:X1,Y0:Y1,Z0:Z1")]
    crop: Option<isoscope_sim::fit::Crop>,
}

impl FitArgs {
    fn options(&self) -> isoscope_sim::fit::FitOptions {
        isoscope_sim::fit::FitOptions { crop: self.crop, downsample: self.downsample }
    }
}

/// Fit `vol` as `args` say, and to `limits` when it goes to a board; the
/// notes on standard error.
fn fit_volume(
    vol: LoadedVolume,
    args: &FitArgs,
    limits: Option<&isoscope_sim::fit::Limits>,
) -> Result<LoadedVolume> {
    Ok(noted(isoscope_sim::fit::fit(vol, &args.options(), limits)?))
}

/// Fit `vol` as `args` say to a board of `limits`, whose picture `cfg`
/// makes (the stride `every` gives for a volume's dims)
/// ([`isoscope_sim::fit::fit_to_board_picture`]); the notes on standard
/// error.
fn fit_board_volume(
    vol: LoadedVolume,
    args: &FitArgs,
    limits: &isoscope_sim::fit::Limits,
    cfg: &SceneConfig,
    every: impl Fn(isoscope_sim::volume::Dims) -> usize,
) -> Result<LoadedVolume> {
    Ok(noted(isoscope_sim::fit::fit_to_board_picture(vol, &args.options(), limits, cfg, every)?))
}

/// The fitted volume, its notes said on standard error.
fn noted(fitted: isoscope_sim::fit::Fitted) -> LoadedVolume {
    for n in &fitted.notes {
        eprintln!("isoscope-sim: note: {n}");
    }
    fitted.volume
}

#[derive(Args, Debug, Clone, Copy)]
struct ViewArgs {
    /// Rotation about the vertical screen axis, degrees.
    #[arg(long, default_value_t = View::DEFAULT.yaw, allow_hyphen_values = true)]
    yaw: f32,
    /// Rotation about the horizontal screen axis, degrees.
    #[arg(long, default_value_t = View::DEFAULT.pitch, allow_hyphen_values = true)]
    pitch: f32,
    /// Rotation about the view axis, degrees.
    #[arg(long, default_value_t = View::DEFAULT.roll, allow_hyphen_values = true)]
    roll: f32,
    /// Perspective projection with this field of view in degrees (default:
    /// orthographic).
    #[arg(long, value_name = "FOV")]
    perspective: Option<f32>,
    /// Fraction of the screen left free on each side.
    #[arg(long, default_value_t = View::DEFAULT.margin, allow_hyphen_values = true)]
    margin: f32,
    /// DAC resolution in bits.
    #[arg(long, default_value_t = 12)]
    bits: u8,
    /// Contour every N-th slice of each plane (default 1; `render` picks
    /// one that keeps a large volume from blurring into a blob: the longest
    /// axis / 32, rounded up).
    #[arg(long, value_name = "N")]
    every: Option<usize>,
}

#[derive(Args, Debug)]
struct BeamArgs {
    /// Largest step per sample while the beam is lit, in DAC LSB (sets the
    /// beam speed and so the brightness).
    #[arg(long, default_value_t = BeamConfig::default().lit_step)]
    lit_step: f32,
    /// DAC sample rate in samples per second, for frames per second
    /// (default: the board's, else 1 MS/s).
    #[arg(long)]
    rate: Option<f32>,
}

/// Whose memory draws the picture, and where its samples go.
#[derive(Args, Debug, Clone)]
struct BoardArgs {
    /// Draw as this board draws: its capacities (a surface it cannot hold is
    /// cut as on the board, and a note says how much) and its sample clock.
    /// f407: the firmware's STM32F407. Default: room for the whole surface.
    #[arg(long, value_name = "NAME", value_parser = parse_board)]
    board: Option<Board>,
    /// Write one frame's DAC samples to this file, `x y beam` a line (the
    /// format of `device --samples`).
    #[arg(long, value_name = "FILE")]
    samples: Option<PathBuf>,
}

#[derive(Args, Debug)]
struct StatsArgs {
    #[command(flatten)]
    input: InputArgs,
    #[command(flatten)]
    view: ViewArgs,
    #[command(flatten)]
    beam: BeamArgs,
    #[command(flatten)]
    board: BoardArgs,
}

#[derive(Args, Debug, Clone)]
struct Source {
    /// Volume file: NIfTI-1 (.nii, .hdr), NRRD (.nrrd, .nhdr), MRC/CCP4
    /// (.mrc, .map, .ccp4, .mrcs, .rec), Gaussian cube (.cube, .cub), VTK
    /// legacy (.vtk), VolPack (.den) (any may end in .gz), or raw samples,
    /// x fastest (a raw file needs --dims and --dtype).
    #[arg(conflicts_with = "demo")]
    input: Option<PathBuf>,
    /// Volume extents NXxNYxNZ (a 2D grid has NZ = 1).
    #[arg(long, requires = "input")]
    dims: Option<Dims>,
    /// Sample type of the raw file: u8, u16, i16 or f32.
    #[arg(long, requires = "input")]
    dtype: Option<Dtype>,
    /// Byte order of the raw file: little (default) or big.
    #[arg(long, requires = "input")]
    endian: Option<Endian>,
    /// Which volume of a file that holds several (a NIfTI time point, a cube
    /// orbital, a VTK array), from 0.
    #[arg(long = "volume", value_name = "N", default_value_t = 0, requires = "input")]
    volume_index: usize,
    /// The most memory a volume's samples may take, in MiB (2^20 bytes), in
    /// the file's sample type or as loaded: a file whose header (or
    /// --dims and --dtype) asks for more, or a larger demo, is refused
    /// before its samples are read or made. 1 to 16777216 (the default,
    /// 2048, is 2 GiB).
    #[arg(long, value_name = "MB",
          default_value_t = isoscope_sim::formats::DEFAULT_MAX_BYTES >> 20,
          value_parser = in_range::<1, 16_777_216, usize>)]
    max_volume_mb: usize,
    /// file: lay the volume out as its header says it lies in space (a
    /// NIfTI sform or qform, NRRD space directions, a cube's axis vectors),
    /// so that a head is upright and faces the viewer; index: the file's
    /// index axes as they are, x its first.
    #[arg(long, value_name = "file|index", default_value = "file")]
    orientation: isoscope_sim::formats::Orientation,
    /// A built-in volume instead of a file: hydrogen:N (the paper's Figure 1,
    /// 3d_xy orbital), gyroid:N, sphere:N or torus:N.
    #[arg(long, value_name = "NAME:N")]
    demo: Option<DemoSpec>,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum Format {
    /// One command per line.
    Csv,
    /// The display list after culling, stitching and ordering, seen through
    /// the view (view flags apply), as SVG.
    Svg,
    /// Write nothing (for timing with --stats).
    None,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum TraversalArg {
    /// The corrected traversal compiled into a table at build time (the same commands, faster).
    Compiled,
    /// The paper's Figure 8 with the pen restored after equal-valued edges, walking the trees.
    Corrected,
    /// Figure 8 exactly as printed (wrong for ~1% of subgrids with nodes at the level).
    Literal,
}

#[derive(Args, Debug)]
struct ContourArgs {
    #[command(flatten)]
    input: InputArgs,
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Output format.
    #[arg(long, value_enum, default_value = "csv")]
    format: Format,
    /// Output file (default: standard output).
    #[arg(short, long)]
    output: Option<PathBuf>,
    /// Print cells, crossing cells, commands, seconds and Mcells/s of the
    /// contouring alone to standard error.
    #[arg(long)]
    stats: bool,
    /// Which traversal of the contouring trees.
    #[arg(long, value_enum, default_value = "compiled")]
    traversal: TraversalArg,
    /// View settings (for --format svg).
    #[command(flatten)]
    view: ViewArgs,
}

/// Warn when `path`'s name says another format than the `format` it is
/// written as ([`isoscope_sim::outfile::misnamed`]).
fn warn_misnamed(path: &std::path::Path, format: &str, extensions: &[&str]) {
    if let Some(w) = isoscope_sim::outfile::misnamed(path, format, extensions) {
        eprintln!("isoscope-sim: warning: {w}");
    }
}

/// Write `text` to standard output. A reader that went away (`| head`)
/// is not an error: the output is simply not wanted any more.
fn print_out(text: &str) -> Result<()> {
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        r => r.context("cannot write to standard output"),
    }
}

/// A whole number in `MIN ..= MAX`, for size and count options: checked
/// where the option is parsed, before anything is allocated.
fn in_range<const MIN: u64, const MAX: u64, T: TryFrom<u64>>(s: &str) -> Result<T, String> {
    let v: u64 = s.trim().parse().map_err(|_| format!("`{s}` is not a whole number"))?;
    if !(MIN..=MAX).contains(&v) {
        return Err(format!("`{s}` is out of range: give {MIN} to {MAX}"));
    }
    T::try_from(v).map_err(|_| format!("`{s}` is too large for this machine"))
}

/// A timeout in seconds: finite, 0.1 to one day.
fn parse_timeout(s: &str) -> Result<f64, String> {
    let x: f64 = s.trim().parse().map_err(|_| format!("`{s}` is not a number of seconds"))?;
    if !(0.1..=86_400.0).contains(&x) {
        return Err(format!("`{s}`: give 0.1 to 86400 seconds"));
    }
    Ok(x)
}

/// A board named in the core ([`Board::ALL`]).
fn parse_board(s: &str) -> Result<Board, String> {
    Board::named(s.trim()).ok_or_else(|| {
        let names: Vec<&str> = Board::ALL.iter().map(|b| b.name).collect();
        format!("unknown board `{s}` (known: {})", names.join(", "))
    })
}

/// A contour level: a finite number within the `f32` range.
fn parse_level(s: &str) -> Result<f32, String> {
    let x: f64 = s.trim().parse().map_err(|_| format!("`{s}` is not a number"))?;
    if !x.is_finite() {
        return Err(format!("`{s}` is not a finite number"));
    }
    if x.abs() > f64::from(f32::MAX) {
        return Err(format!("`{s}` is outside the range of f32 samples"));
    }
    Ok(x as f32)
}

fn load(source: &Source) -> Result<(LoadedVolume, Option<DemoSpec>)> {
    // No overflow below 16 TiB on a 64-bit machine; a 32-bit one cannot
    // hold more than `usize::MAX` anyway.
    let max_bytes = source.max_volume_mb.saturating_mul(1 << 20);
    match (&source.input, source.demo) {
        (Some(path), None) => {
            if source.dims.is_none() && source.dtype.is_none() {
                let opts = isoscope_sim::formats::Options {
                    index: source.volume_index,
                    max_bytes,
                    orientation: source.orientation,
                };
                if let Some((v, notes)) = LoadedVolume::read_known_with(path, &opts)? {
                    for n in &notes {
                        eprintln!("isoscope-sim: note: {}: {n}", path.display());
                    }
                    return Ok((v, None));
                }
                // A file that cannot be opened to look at says why; one
                // that can names no format that loads.
                std::fs::File::open(path).with_context(|| format!("cannot read {}", path.display()))?;
                return Err(isoscope_sim::volume::LoadError::UnknownFormat(path.clone()).into());
            }
            let dims = source.dims.context("a raw volume file needs --dims NXxNYxNZ (and --dtype)")?;
            let dtype = source.dtype.context("a raw volume file needs --dtype u8|u16|i16|f32")?;
            let endian = source.endian.unwrap_or_default();
            if source.volume_index > 0 {
                bail!("a raw file holds one volume; --volume {} asks for another", source.volume_index);
            }
            Ok((LoadedVolume::read_raw_endian(path, dims, dtype, endian, max_bytes)?, None))
        }
        (None, Some(_)) if source.volume_index > 0 => {
            bail!("a demo is one volume; --volume {} asks for another", source.volume_index)
        }
        (None, Some(spec)) => {
            let bytes = spec.n.saturating_pow(3).saturating_mul(4);
            if bytes > max_bytes {
                bail!(
                    "the demo's {n}^3 f32 samples take {} MiB, more than the limit of {} MiB \
                     (--max-volume-mb raises it)",
                    bytes.div_ceil(1 << 20),
                    max_bytes >> 20,
                    n = spec.n
                );
            }
            Ok((LoadedVolume::demo(spec)?, Some(spec)))
        }
        _ => bail!("give a volume file (with --dims and --dtype) or --demo NAME:N"),
    }
}

fn planes(axes: &[String]) -> Result<Vec<Plane>> {
    let mut out = Vec::new();
    for a in axes {
        if a.trim().is_empty() {
            bail!("--axes has an empty plane name (expected a comma-separated list of xy, xz, yz)");
        }
        let p = Plane::from_name(a.trim())
            .with_context(|| format!("unknown axes `{a}` (expected xy, xz or yz)"))?;
        if !out.contains(&p) {
            out.push(p);
        }
    }
    if out.is_empty() {
        bail!("--axes names no plane");
    }
    Ok(out)
}

fn contour_svg(args: &ContourArgs) -> Result<()> {
    let scene_args = StatsArgs {
        input: args.input.clone(),
        view: ViewArgs { ..args.view },
        beam: BeamArgs { lit_step: BeamConfig::default().lit_step, rate: None },
        board: BoardArgs { board: None, samples: None },
    };
    let scene = build_scene(&scene_args, false)?;
    let bits = args.view.bits;
    match &args.output {
        Some(path) => write_whole(path, |w| {
            isoscope_sim::svg::write_svg(w, &scene.commands, bits)
                .with_context(|| format!("cannot write {}", path.display()))
        }),
        None => match isoscope_sim::svg::write_svg(std::io::stdout().lock(), &scene.commands, bits) {
            Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => {
                Err(e).context("cannot write to standard output")
            }
            _ => Ok(()),
        },
    }
}

fn contour(args: &ContourArgs) -> Result<()> {
    if let Some(path) = &args.output {
        match args.format {
            Format::Csv => warn_misnamed(path, "CSV", &["csv", "txt"]),
            Format::Svg => warn_misnamed(path, "SVG", &["svg"]),
            Format::None => {}
        }
    }
    if let Format::Svg = args.format {
        return contour_svg(args);
    }
    let (vol, demo) = load(&args.input.source)?;
    // An export says its levels: no suggested level for a file.
    let levels = levels_for(&args.input.levels, demo, None)?;
    let vol = fit_volume(vol, &args.input.fit, None)?;
    let planes = planes(&args.input.axes)?;
    let threads = match args.threads {
        Some(0) => bail!("--threads must be at least 1"),
        Some(n) => n,
        None => std::thread::available_parallelism().map_or(1, |n| n.get()),
    };
    let traversal = match args.traversal {
        TraversalArg::Compiled => Traversal::Compiled,
        TraversalArg::Corrected => Traversal::Corrected,
        TraversalArg::Literal => Traversal::Literal,
    };
    let job = Job {
        planes: &planes,
        levels: &levels,
        traversal,
        threads,
        keep: matches!(args.format, Format::Csv),
        every: args.view.every.unwrap_or(1),
    };
    if args.view.every == Some(0) {
        bail!("--every must be at least 1");
    }
    let Dims(nx, ny, nz) = vol.dims;
    fn run<T: Voxel + Sync>(
        data: &[T],
        d: (usize, usize, usize),
        job: &Job<'_>,
    ) -> Result<isoscope_sim::contour::Contoured> {
        let v = Volume::new(data, d.0, d.1, d.2)?;
        let progress = Progress::new("contouring", work_units(&v, job));
        contour_volume(&v, job, Some(&progress))
    }
    let d = (nx, ny, nz);
    let result = match &vol.samples {
        Samples::U8(s) => run(s, d, &job),
        Samples::U16(s) => run(s, d, &job),
        Samples::I16(s) => run(s, d, &job),
        Samples::F32(s) => run(s, d, &job),
    }?;
    if result.stats.cells == 0 {
        eprintln!(
            "isoscope-sim: warning: the volume is {nx}x{ny}x{nz}: its {} slices have no 2x2 cells to contour",
            planes.iter().map(|p| p.name()).collect::<Vec<_>>().join(", ")
        );
    } else if result.stats.commands == 0 {
        let values = isoscope_sim::info::summarize(&vol, isoscope_sim::info::LEVEL_BINS);
        eprintln!("isoscope-sim: {}", scene::nothing_drawn("the export", &levels, Some(&values)));
    }
    if let Format::Csv = args.format {
        match &args.output {
            Some(path) => write_whole(path, |w| {
                write_csv(w, &result, &levels).with_context(|| format!("cannot write {}", path.display()))
            })?,
            None => {
                let out = std::io::stdout().lock();
                if let Err(e) = write_csv(std::io::BufWriter::new(out), &result, &levels)
                    && e.kind() != std::io::ErrorKind::BrokenPipe
                {
                    return Err(e).context("cannot write to standard output");
                }
            }
        }
    }
    if args.stats {
        let s = result.stats;
        let mcells = s.cells as f64 / result.seconds.max(1e-9) / 1e6;
        let mut e = std::io::stderr().lock();
        writeln!(e, "cells={}", s.cells)?;
        writeln!(e, "crossing_cells={}", s.crossing_cells)?;
        writeln!(e, "nonfinite_cells={}", s.nonfinite_cells)?;
        writeln!(e, "commands={}", s.commands)?;
        writeln!(e, "levels={}", levels.len())?;
        writeln!(e, "threads={}", threads)?;
        writeln!(e, "seconds={:.6}", result.seconds)?;
        writeln!(e, "mcells_per_s={mcells:.1}")?;
    }
    Ok(())
}

/// The levels to draw: those given, else the demo's own, else (when
/// `suggest` gives the volume) the first level `info` suggests for it
/// (Otsu's threshold), with a note.
fn levels_for(given: &[f32], demo: Option<DemoSpec>, suggest: Option<&LoadedVolume>) -> Result<Vec<f32>> {
    if !given.is_empty() {
        return Ok(given.to_vec());
    }
    if let Some(d) = demo {
        return Ok(vec![d.demo.default_level()]);
    }
    let Some(vol) = suggest else { bail!("give at least one --level for a volume file") };
    match isoscope_sim::info::default_level(vol) {
        Some(l) => {
            eprintln!(
                "isoscope-sim: note: no --level given; drawing level {l} (Otsu's threshold, see `info`)"
            );
            Ok(vec![l])
        }
        None => {
            bail!("give at least one --level: the volume's values suggest none (it is constant or empty)")
        }
    }
}

fn render(args: &RenderArgs) -> Result<()> {
    if let Some(path) = &args.animate {
        return render_animation(args, path);
    }
    if args.frames == 0 {
        bail!("--frames must be at least 1");
    }
    warn_misnamed(&args.output, "a PNG", &["png"]);
    let scene = build_scene(&args.scene, true)?;
    let mut cfg = PhosphorConfig::with_size(args.size, args.size);
    cfg.bits = args.scene.view.bits;
    cfg.show_blanked = args.show_blanked;
    let progress = Progress::new("rendering frames", args.frames as usize);
    let screen = scene::render(&scene, cfg, args.frames, Some(&progress))?;
    screen.write_png(&args.output)?;
    eprintln!(
        "isoscope-sim: wrote {} ({}x{}; {} polylines, {} samples, {:.1} frames/s at {} samples/s)",
        args.output.display(),
        args.size,
        args.size,
        scene.polylines,
        scene.frame.samples,
        scene.fps(),
        scene.sample_rate_hz
    );
    Ok(())
}

fn render_animation(args: &RenderArgs, path: &std::path::Path) -> Result<()> {
    let format = AnimFormat::from_path(path)
        .with_context(|| format!("{}: an animation is a .gif or an (animated) .png", path.display()))?;
    if args.scene.board.samples.is_some() {
        bail!("--samples writes one frame: give it to a still render, not with --animate");
    }
    let (volume, cfg) = prepare(
        &args.scene.input,
        &args.scene.view,
        &args.scene.board,
        scene_beam(&args.scene),
        args.scene.beam.rate,
        true,
    )?;
    let mut picture = PhosphorConfig::with_size(args.size, args.size);
    picture.bits = args.scene.view.bits;
    picture.show_blanked = args.show_blanked;
    let anim = AnimConfig { frames: args.anim_frames, turn_deg: args.turn, format, ..AnimConfig::default() };
    anim.validate()?;
    let contouring = contouring_progress(&volume, &cfg)?;
    let progress = Progress::new("animating", anim.frames as usize);
    let st = write_whole(path, |w| {
        scene::with_board(&volume, &cfg, Some(&contouring), |board, capacity| {
            // What the still picture has to say (the board's memory, an
            // empty picture, a flickering one) holds for every frame.
            print_remarks(&scene::scene_of(board, &volume, capacity, &cfg));
            animate_board(board, &cfg, picture, &anim, w, Some(&progress))
        })
        .with_context(|| format!("cannot write {}", path.display()))
    })?;
    eprintln!(
        "isoscope-sim: wrote {} ({} frames, {}x{}, {:.1} degrees a frame, {} bytes)",
        path.display(),
        st.frames,
        st.width,
        st.height,
        st.step_deg,
        st.bytes
    );
    Ok(())
}

fn scene_beam(args: &StatsArgs) -> BeamConfig {
    BeamConfig { bits: args.view.bits, lit_step: args.beam.lit_step, ..BeamConfig::default() }
}

/// Load the volume and make the scene configuration: everything a frame,
/// an animation or a WAV needs.
fn prepare(
    input: &InputArgs,
    v: &ViewArgs,
    board: &BoardArgs,
    beam: BeamConfig,
    rate: Option<f32>,
    auto_every: bool,
) -> Result<(WireVolume, SceneConfig)> {
    let (vol, demo) = load(&input.source)?;
    let levels = levels_for(&input.levels, demo, Some(&vol))?;
    let planes = planes(&input.axes)?;
    if v.every == Some(0) {
        bail!("--every must be at least 1");
    }
    let every_for = |dims| match v.every {
        Some(n) => n,
        None if auto_every => scene::auto_every(dims),
        None => 1,
    };
    let vol = match board.board {
        Some(b) => {
            let cfg = SceneConfig { planes: planes.clone(), ..SceneConfig::board(b, levels.clone()) };
            fit_board_volume(vol, &input.fit, &isoscope_sim::fit::Limits::of_board(&b), &cfg, every_for)?
        }
        None => fit_volume(vol, &input.fit, None)?,
    };
    let every = every_for(vol.dims);
    if every > 1 && v.every.is_none() {
        let stride = scene::stride(u16::try_from(every).unwrap_or(u16::MAX));
        eprintln!("isoscope-sim: note: drawing {stride} (--every to choose)");
    }
    let view = View {
        yaw: v.yaw,
        pitch: v.pitch,
        roll: v.roll,
        projection: match v.perspective {
            Some(fov_deg) => Projection::Perspective { fov_deg },
            None => Projection::Orthographic,
        },
        margin: v.margin,
        bits: v.bits,
        spacing: vol.spacing,
    };
    let base = match board.board {
        Some(b) => SceneConfig::board(b, levels),
        None => SceneConfig { levels, ..SceneConfig::default() },
    };
    let sample_rate_hz = match rate {
        Some(r) if !(r.is_finite() && r >= 1.0 && r <= u32::MAX as f32) => {
            bail!("--rate must be a sample rate of at least 1 sample a second")
        }
        Some(r) => r as u32,
        None => base.sample_rate_hz,
    };
    let cfg = SceneConfig { planes, every, view, beam, sample_rate_hz, ..base };
    let wire = WireVolume::from_loaded(&vol)?;
    Ok((wire, cfg))
}

/// One frame; `auto_every` lets a large volume default to every n-th
/// slice. Says what the board could not hold, writes `--samples`.
fn build_scene(args: &StatsArgs, auto_every: bool) -> Result<Scene> {
    let (volume, cfg) =
        prepare(&args.input, &args.view, &args.board, scene_beam(args), args.beam.rate, auto_every)?;
    let scene = draw(&volume, &cfg)?;
    finish_scene(&scene, &args.board)?;
    Ok(scene)
}

/// The frame of `volume` with `cfg`, with progress as the board is fed.
fn draw(volume: &WireVolume, cfg: &SceneConfig) -> Result<Scene> {
    let progress = contouring_progress(volume, cfg)?;
    scene::with_board(volume, cfg, Some(&progress), |board, capacity| {
        Ok(scene::scene_of(board, volume, capacity, cfg))
    })
}

/// Progress over the frames that feed `volume` to the board with `cfg`.
fn contouring_progress(volume: &WireVolume, cfg: &SceneConfig) -> Result<Progress> {
    Ok(Progress::new("contouring (frames fed to the board)", frames_for(volume, &cfg.send()?)))
}

/// The scene's remarks on standard error.
fn print_remarks(scene: &Scene) {
    for r in scene.remarks() {
        eprintln!("isoscope-sim: {r}");
    }
}

/// The scene's remarks on standard error, its samples to `--samples`.
fn finish_scene(scene: &Scene, board: &BoardArgs) -> Result<()> {
    print_remarks(scene);
    if let Some(path) = &board.samples {
        write_samples(&scene.samples, path)?;
    }
    Ok(())
}

fn wav(args: &WavArgs) -> Result<()> {
    // Spaced for --fps unless the spacing or the scope's beam is given.
    let fit = !(args.scope_beam || args.lit_step.is_some());
    let mut beam = if args.scope_beam {
        BeamConfig { bits: args.view.bits, ..BeamConfig::default() }
    } else {
        audio_beam(args.audio_rate, args.view.bits)
    };
    if let Some(step) = args.lit_step {
        beam.lit_step = step;
    }
    if args.audio_rate == 0 {
        bail!("--audio-rate must be at least 1 Hz");
    }
    warn_misnamed(&args.output, "a WAV file", &["wav"]);
    let (volume, mut cfg) = prepare(&args.input, &args.view, &args.board, beam, None, true)?;
    // The frame plays at the audio rate: its refresh rate is counted at it.
    cfg.sample_rate_hz = args.audio_rate;
    let mut scene = draw(&volume, &cfg)?;
    if fit {
        let frame = audio_frame(&scene.commands, &cfg.beam, args.audio_rate, Some(args.fps));
        (scene.samples, scene.frame, beam) = (frame.samples, frame.stats, frame.beam);
    }
    finish_scene(&scene, &args.board)?;
    let wcfg = WavConfig {
        rate_hz: args.audio_rate,
        channels: if args.beam_channel { WavChannels::WithBeam } else { WavChannels::Stereo },
        format: if args.float { WavFormat::Float32 } else { WavFormat::Pcm16 },
        seconds: args.seconds,
        bits: args.view.bits,
        blank_active_low: args.blank_active_low,
        ..WavConfig::default()
    };
    let length = sample_frames(&wcfg, scene.samples.len())?;
    let writing =
        Progress::new("writing audio (sample frames)", usize::try_from(length).unwrap_or(usize::MAX));
    let st = write_wav_file_counted(&args.output, &scene.samples, &wcfg, Some(&writing))?;
    eprintln!(
        "isoscope-sim: wrote {} ({:.2} s at {} Hz, {} channels; one frame is {} samples, {:.1} LSB apart: \
         {:.1} frames/s)",
        args.output.display(),
        st.seconds,
        args.audio_rate,
        if args.beam_channel { 3 } else { 2 },
        st.frame_samples,
        beam.lit_step,
        st.refresh_hz
    );
    let span = f32::from(beam.max_code()) + 1.0;
    if !fit && st.refresh_hz < f64::from(isoscope_sim::scene::FLICKER_HZ) && scene.frame.lit_samples > 0 {
        eprintln!(
            "isoscope-sim: warning: {:.1} frames/s: drop {} to space the samples for {} frames/s (--fps)",
            st.refresh_hz,
            if args.scope_beam { "--scope-beam" } else { "--lit-step" },
            isoscope_sim::wav::AUDIO_FPS
        );
    } else if fit && beam.lit_step > span / 32.0 {
        eprintln!(
            "isoscope-sim: note: at {:.0} frames/s the samples are {:.0} LSB apart ({:.1}% of the screen), a \
             coarse picture: a higher --audio-rate, a lower --fps or fewer slices (--every) draw it finer",
            st.refresh_hz,
            beam.lit_step,
            100.0 * beam.lit_step / span
        );
    }
    if st.clipped > 0 {
        eprintln!("isoscope-sim: warning: {} samples were outside the DAC range and clipped", st.clipped);
    }
    Ok(())
}

fn send(args: &SendArgs) -> Result<()> {
    use isoscope_sim::fit::Limits;
    use isoscope_sim::link::{SendConfig, ViewSetting, WireVolume, connect, open_port};
    let (vol, demo) = load(&args.input.source)?;
    let levels = levels_for(&args.input.levels, demo, Some(&vol))?;
    let axes = scene::axes(&planes(&args.input.axes)?);
    let any_view = args.yaw.or(args.pitch).or(args.roll).or(args.perspective).or(args.spin).is_some();
    let view = any_view.then(|| ViewSetting {
        angles: [
            args.yaw.unwrap_or(View::DEFAULT.yaw),
            args.pitch.unwrap_or(View::DEFAULT.pitch),
            args.roll.unwrap_or(View::DEFAULT.roll),
        ],
        fov_deg: args.perspective.unwrap_or(0.0),
        spin_deg_per_s: args.spin.unwrap_or(0.0),
    });
    // The picture `board` draws of the volume, as it will be sent.
    let board_picture = |board: Board| -> Result<SceneConfig> {
        let mut cfg = SceneConfig::board(board, levels.clone());
        cfg.planes = planes(&args.input.axes)?;
        cfg.every = usize::from(args.every);
        Ok(cfg)
    };
    // With --board the volume is fitted to that board and previewed before
    // the port is opened; without, to what the board says it takes.
    let mut vol = Some(vol);
    let mut fitted = None;
    if let Some(board) = args.board
        && let Some(vol) = vol.take()
    {
        // The settings first, so that their errors say what they are.
        let mut preview = board_picture(board)?;
        preview.send()?;
        let every = preview.every;
        let limits = Limits::of_board(&board);
        let wire =
            WireVolume::from_loaded(&fit_board_volume(vol, &args.input.fit, &limits, &preview, |_| every)?)?;
        // What that board will show: the same engine with its memory.
        if let Some(v) = view {
            let [yaw, pitch, roll] = v.angles;
            let projection = match v.perspective() {
                Some(fov_deg) => Projection::Perspective { fov_deg },
                None => Projection::Orthographic,
            };
            preview.view = View { yaw, pitch, roll, projection, ..preview.view };
        }
        let scene = scene::build(&wire, &preview)
            .with_context(|| format!("the {} board cannot take this volume", board.name))?;
        print_remarks(&scene);
        eprintln!(
            "isoscope-sim: the {} board will show {} polylines, {} points, at {:.1} frames/s",
            board.name,
            scene.polylines,
            scene.points,
            scene.fps()
        );
        fitted = Some(wire);
    }
    let cfg = SendConfig {
        levels: levels.clone(),
        axes,
        every: args.every,
        window: args.window,
        chunk: args.chunk,
        baud: args.baud,
        view,
        max_timeouts: args.patience,
    };
    // The settings before the port: a bad one is refused here, not by the
    // board after the volume.
    cfg.check()?;
    let port = if args.port == "auto" {
        let ports = isoscope_sim::ports::available()?;
        let chosen = isoscope_sim::ports::choose_auto(&ports)?;
        eprintln!("isoscope-sim: --port auto: {}", chosen.line());
        chosen.name.clone()
    } else {
        args.port.clone()
    };
    let (reader, writer) = open_port(&port, args.baud)?;
    let mut link = connect(reader, writer)?;
    let wire = match fitted {
        Some(w) => w,
        None => {
            let vol = vol.context("the volume was fitted already")?;
            let every = usize::from(args.every);
            let (opts, board) = (args.input.fit.options(), *link.board());
            // The fit runs the board's own engine and can take seconds, in
            // which a board may drop a silent client (the virtual board's
            // --idle-timeout): the board is greeted meanwhile.
            let fitted = std::thread::scope(|s| -> Result<_> {
                let fit = s.spawn(|| {
                    isoscope_sim::fit::fit_to_connected(vol, &opts, &board, board_picture, |_| every)
                });
                let mut greeted = std::time::Instant::now();
                while !fit.is_finished() {
                    std::thread::sleep(std::time::Duration::from_millis(10));
                    if greeted.elapsed() >= KEEP_ALIVE {
                        link.greet()?;
                        greeted = std::time::Instant::now();
                    }
                }
                fit.join().unwrap_or_else(|panic| std::panic::resume_unwind(panic))
            })?;
            let takes = |b: &isoscope_sim::link::BoardInfo| {
                (b.firmware, b.max_slice_samples, b.sample_types, b.display_points)
            };
            if takes(link.board()) != takes(&board) {
                bail!("the board on {port} changed while the volume was fitted to it: send again");
            }
            WireVolume::from_loaded(&noted(fitted))?
        }
    };
    let chunks_per_slice = wire.slice_bytes().div_ceil(cfg.chunk.max(1));
    let total = 2 + chunks_per_slice * usize::from(wire.dims[2]) + usize::from(view.is_some());
    let progress = Progress::new("sending frames", total);
    let report = link.send(&wire, &cfg, Some(&progress))?;
    eprintln!(
        "isoscope-sim: sent {}x{}x{} {:?} to {} ({:.1} KB/s, {:.1}% of the line rate)",
        wire.dims[0],
        wire.dims[1],
        wire.dims[2],
        wire.sample_type,
        port,
        report.throughput() / 1e3,
        report.efficiency(args.baud) * 100.0
    );
    print_out(&report.report(args.baud))?;
    Ok(())
}

/// How often `send` greets the board while it fits a volume to it: well
/// inside the virtual board's shortest `--idle-timeout` (and its default
/// 10 s).
const KEEP_ALIVE: std::time::Duration = std::time::Duration::from_millis(500);

fn device(args: &DeviceArgs) -> Result<()> {
    use isoscope_sim::board::{HostBuffers, host_capacity};
    use isoscope_sim::device::{Board as VirtualBoard, DeviceOptions};
    if let Some(path) = &args.snapshot {
        warn_misnamed(path, "a PNG", &["png"]);
    }
    let mut opts = DeviceOptions {
        baud: args.baud,
        snapshot: args.snapshot.clone(),
        size: args.size,
        samples: args.samples.clone(),
        exit_after: args.exit_after,
        slice_bytes: args.max_slice_bytes,
        points: args.points,
        ..DeviceOptions::default()
    };
    let capacity = match args.board {
        Some(b) => {
            opts.engine = b.engine_config();
            b.capacity
        }
        None => host_capacity(opts.slice_bytes, isoscope_sim::fit::WIRE_MAX_EXTENT, opts.points),
    };
    let mut mem = HostBuffers::new(&capacity);
    let mut board = VirtualBoard::new(&mut mem, &opts)?;
    let stdout = std::io::stdout();
    let mut log = stdout.lock();
    if let Some(addr) = &args.tcp {
        let listener =
            std::net::TcpListener::bind(addr).with_context(|| format!("cannot listen on {addr}"))?;
        writeln!(log, "{}", listener.local_addr()?)?;
        log.flush()?;
        opts.idle_timeout = Some(std::time::Duration::from_secs_f64(args.idle_timeout));
        return isoscope_sim::device::serve_tcp(&mut board, listener, &opts, &mut log);
    }
    #[cfg(unix)]
    {
        let pty = isoscope_sim::tty::open_pty()?;
        writeln!(log, "{}", pty.path.display())?;
        log.flush()?;
        let mut master = &pty.master;
        board.serve(&mut master, &opts, &mut log)?;
        Ok(())
    }
    #[cfg(not(unix))]
    bail!("--pty needs a Unix system (pseudo-terminals); serve on TCP with --tcp 127.0.0.1:0")
}

fn relay(args: &RelayArgs) -> Result<()> {
    use isoscope_sim::relay::{Noise, serve};
    // Frames towards the board are lost as named; the answers only by rate.
    let noise = Noise {
        flip: args.flip,
        drop: args.drop,
        dup: args.dup,
        drop_frame: args.drop_frame,
        dup_frame: args.dup_frame,
        lose: args.lose_frame.clone(),
    };
    let listener = std::net::TcpListener::bind(&args.listen)
        .with_context(|| format!("cannot listen on {}", args.listen))?;
    print_out(&format!("{}\n", listener.local_addr()?))?;
    let mut clients = 0u64;
    serve(&listener, &args.to, &noise, args.seed, |damage| {
        clients += 1;
        let _ = print_out(&format!("client={clients} {}\n", damage.report()));
        args.exit_after.is_none_or(|n| clients < n)
    })
}

/// A probability: a number from 0 to 1.
fn parse_fps(s: &str) -> Result<f32, String> {
    let f: f32 = s.trim().parse().map_err(|_| format!("`{s}` is not a number"))?;
    if !(f.is_finite() && f > 0.0) {
        return Err(format!("`{s}` is not a refresh rate: give a positive number of frames a second"));
    }
    Ok(f)
}

fn parse_probability(s: &str) -> Result<f64, String> {
    let p: f64 = s.trim().parse().map_err(|_| format!("`{s}` is not a number"))?;
    if !(0.0..=1.0).contains(&p) {
        return Err(format!("`{s}` is not a probability: give 0 to 1"));
    }
    Ok(p)
}

/// A completion script for `args.shell`, generated from the same clap
/// declarations that parse the command line, so it cannot drift from them.
fn serve(args: &ServeArgs) -> Result<()> {
    if !args.dir.join("index.html").is_file() {
        bail!("{} holds no web app (no index.html): build it with scripts/web-build", args.dir.display());
    }
    let listener = std::net::TcpListener::bind(&args.listen)
        .with_context(|| format!("cannot listen on {}", args.listen))?;
    let addr = listener.local_addr()?;
    println!("http://{addr}/?demo=hydrogen:32");
    eprintln!("isoscope-sim: serving {} at http://{addr}/ (Ctrl-C stops)", args.dir.display());
    std::io::stdout().flush()?;
    isoscope_sim::serve::serve(&listener, &args.dir)
}

fn completions(args: &CompletionsArgs) -> Result<()> {
    let mut script = Vec::new();
    clap_complete::generate(args.shell, &mut Cli::command(), "isoscope-sim", &mut script);
    print_out(&String::from_utf8(script).context("the completion script is not UTF-8")?)
}

/// The manual page, in roff: one page for the whole tool, so that
/// `man isoscope-sim` shows every subcommand's synopsis, description and
/// options (not a list of pages that do not exist), then the examples.
fn manpage(args: &ManpageArgs) -> Result<()> {
    let page = manual_page().context("cannot render the manual page")?;
    match &args.output {
        Some(path) => write_whole(path, |w| {
            w.write_all(page.as_bytes()).with_context(|| format!("cannot write {}", path.display()))
        }),
        None => print_out(&page),
    }
}

/// The page, from the clap declarations that parse the command line.
/// `clap_mangen` renders a section at a time; each rendering starts with the
/// same two lines of set-up for apostrophes, kept once at the top.
fn manual_page() -> Result<String> {
    type Render = fn(&clap_mangen::Man, &mut dyn Write) -> std::io::Result<()>;
    fn part(man: &clap_mangen::Man, render: Render, heading: Option<&str>) -> Result<String> {
        let mut buf = Vec::new();
        render(man, &mut buf)?;
        let text = String::from_utf8(buf).context("the manual page is not UTF-8")?;
        let mut body: String = text
            .lines()
            .filter(|l| !l.starts_with(".ie \\n(.g .ds Aq") && !l.starts_with(".el .ds Aq"))
            .map(|l| format!("{l}\n"))
            .collect();
        if let Some(heading) = heading {
            body = body.strip_prefix(heading).map(str::to_owned).unwrap_or(body);
        }
        Ok(body)
    }
    use clap_mangen::Man;
    let mut cmd = Cli::command();
    cmd.build();
    let man = Man::new(cmd.clone());
    let mut title = Vec::new();
    man.render_title(&mut title)?;
    let mut page = String::from_utf8(title).context("the manual page is not UTF-8")?;
    for render in [Man::render_name_section, Man::render_synopsis_section, Man::render_description_section] {
        page += &part(&man, render, None)?;
    }
    page += ".SH COMMANDS\n";
    for sub in cmd.get_subcommands().filter(|s| s.get_name() != "help") {
        let sub_man = Man::new(sub.clone());
        page += &format!(".SS \"isoscope\\-sim {}\"\n", sub.get_name());
        page += &part(&sub_man, Man::render_synopsis_section, Some(".SH SYNOPSIS\n"))?;
        page += ".PP\n";
        page += &part(&sub_man, Man::render_description_section, Some(".SH DESCRIPTION\n"))?;
        page += &part(&sub_man, Man::render_options_section, Some(".SH OPTIONS\n"))?;
    }
    // The examples and the volume syntax as laid out in --help: no filling.
    page += ".SH NOTES\n.nf\n";
    page += &part(&man, Man::render_extra_section, Some(".SH EXTRA\n"))?;
    page += ".fi\n";
    page += &part(&man, Man::render_version_section, None)?;
    Ok(page)
}

fn stats(args: &StatsArgs) -> Result<()> {
    let scene = build_scene(args, false)?;
    print_out(&scene.report())?;
    Ok(())
}

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            use clap::error::ErrorKind;
            if matches!(
                e.kind(),
                ErrorKind::DisplayHelp
                    | ErrorKind::DisplayVersion
                    | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand
            ) {
                e.exit();
            }
            // Usage errors: clap's message under our prefix, exit code 2.
            eprint!("isoscope-sim: {}", e.render());
            return ExitCode::from(2);
        }
    };
    let r = match &cli.command {
        Cmd::Contour(a) => contour(a),
        Cmd::Stats(a) => stats(a),
        Cmd::Render(a) => render(a),
        Cmd::Wav(a) => wav(a),
        Cmd::Send(a) => send(a),
        Cmd::Device(a) => device(a),
        Cmd::Relay(a) => relay(a),
        Cmd::Ports => {
            isoscope_sim::ports::available().and_then(|p| print_out(&isoscope_sim::ports::listing(&p)))
        }
        Cmd::Serve(a) => serve(a),
        Cmd::Completions(a) => completions(a),
        Cmd::Manpage(a) => manpage(a),
        Cmd::Info(a) => {
            load(&a.source).and_then(|(v, _)| print_out(&isoscope_sim::info::summarize(&v, a.bins).report()))
        }
    };
    match r {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("isoscope-sim: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
