//! Fitting a volume to a board: `--crop` (half-open voxel ranges),
//! `--downsample` (block means) and, for a volume a board cannot take, the
//! smallest uniform downsample that fits its slice memory. One
//! implementation for every command that puts a volume on a board (`send`,
//! and `render`, `stats`, `wav` with `--board`) or is asked to crop or
//! downsample (`contour` too).
//!
//! Samples keep their type, except that a volume whose every value a
//! smaller type holds exactly goes to a board in that type (`u16` values
//! up to 255 as `u8`, integral `f32` as an integer type): the contour
//! compares samples as `f32`, so the picture is the same, and a slice takes
//! fewer bytes. A block mean of integers is rounded to the nearest (half
//! away from zero) in the same type; of `f32`, kept as computed.

use crate::link::BoardInfo;
use crate::volume::{Dims, Dtype, LoadedVolume, Samples};
use anyhow::{Result, bail};
use isoscope_core::engine::{Board, Capacity};
use std::ops::Range;
use std::str::FromStr;

/// The most samples along an axis the wire protocol takes (`u16` extents).
pub const WIRE_MAX_EXTENT: usize = u16::MAX as usize;

/// Voxel ranges to keep along x, y and z, half-open, parsed from
/// `X0:X1,Y0:Y1,Z0:Z1`; a bound left out is the axis's start or end
/// (`:` keeps the whole axis).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Crop(pub [(Option<usize>, Option<usize>); 3]);

impl FromStr for Crop {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let bad =
            || format!("`{s}` is not X0:X1,Y0:Y1,Z0:Z1 (half-open voxel ranges, e.g. 20:180,0:220,10:170)");
        let parts: Vec<&str> = s.split(',').collect();
        if parts.len() != 3 {
            return Err(bad());
        }
        let mut out = [(None, None); 3];
        for (slot, part) in out.iter_mut().zip(&parts) {
            let (a, b) = part.split_once(':').ok_or_else(bad)?;
            let bound = |t: &str| -> Result<Option<usize>, String> {
                let t = t.trim();
                if t.is_empty() {
                    return Ok(None);
                }
                t.parse().map(Some).map_err(|_| bad())
            };
            *slot = (bound(a)?, bound(b)?);
        }
        Ok(Crop(out))
    }
}

impl std::fmt::Display for Crop {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let b = |x: Option<usize>| x.map(|v| v.to_string()).unwrap_or_default();
        let [x, y, z] = self.0;
        write!(f, "{}:{},{}:{},{}:{}", b(x.0), b(x.1), b(y.0), b(y.1), b(z.0), b(z.1))
    }
}

impl Crop {
    /// The ranges in a volume of `dims`.
    ///
    /// # Errors
    /// A range that ends past the volume or is empty.
    pub fn ranges(&self, dims: Dims) -> Result<[Range<usize>; 3]> {
        let n = [dims.0, dims.1, dims.2];
        let mut out = [0..0, 0..0, 0..0];
        for (i, ((a, b), slot)) in self.0.iter().zip(&mut out).enumerate() {
            let axis = AXES[i];
            let (a, b) = (a.unwrap_or(0), b.unwrap_or(n[i]));
            if b > n[i] {
                bail!(
                    "the {axis} range of --crop {self} ends at {b}, past the volume's {} samples along {axis}",
                    n[i]
                );
            }
            if a >= b {
                bail!("the {axis} range {a}:{b} of --crop {self} is empty (give START:END with START < END)");
            }
            *slot = a..b;
        }
        Ok(out)
    }
}

/// Block sizes along x, y and z, parsed from `N` (the same on every axis)
/// or `NX,NY,NZ`; each at least 1.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Factors(pub [usize; 3]);

impl FromStr for Factors {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let bad = || format!("`{s}` is not N or NX,NY,NZ (whole numbers of at least 1, e.g. 2 or 2,2,1)");
        let parts: Vec<usize> =
            s.split(',').map(|p| p.trim().parse::<usize>().map_err(|_| bad())).collect::<Result<_, _>>()?;
        let f = match parts[..] {
            [n] => [n; 3],
            [x, y, z] => [x, y, z],
            _ => return Err(bad()),
        };
        if f.contains(&0) {
            return Err(format!("`{s}`: a downsample factor must be at least 1"));
        }
        Ok(Factors(f))
    }
}

/// As given: `N` when uniform, else `NX,NY,NZ`.
impl std::fmt::Display for Factors {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.0 {
            [x, y, z] if x == y && y == z => write!(f, "{x}"),
            [x, y, z] => write!(f, "{x},{y},{z}"),
        }
    }
}

impl Factors {
    /// The block, `NXxNYxNZ`.
    pub fn block(&self) -> String {
        let [x, y, z] = self.0;
        format!("{x}x{y}x{z}")
    }
}

/// What a board takes of a volume: slices of at most `slice_bytes` bytes
/// and `extent` samples a side (the engine's [`Capacity`]), extents of at
/// most [`WIRE_MAX_EXTENT`], and at least 2x2 samples a slice.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Limits {
    /// Bytes of one slice buffer.
    pub slice_bytes: usize,
    /// The largest `nx` or `ny`.
    pub extent: usize,
    /// Who holds it, for notes ("the f407 board").
    pub holder: String,
}

impl Limits {
    /// The limits of memory `capacity`, held by `holder`.
    pub fn of_capacity(capacity: &Capacity, holder: String) -> Self {
        Self { slice_bytes: capacity.slice_bytes, extent: capacity.extent.min(WIRE_MAX_EXTENT), holder }
    }

    /// The limits of a board named in the core.
    pub fn of_board(board: &Board) -> Self {
        Self::of_capacity(&board.capacity, format!("the {} board", board.name))
    }

    /// The limits a connected board reported. Its capabilities give the
    /// slice bytes, not the longest row: that of the core's board with the
    /// same capabilities, else only the protocol's.
    pub fn of_info(info: &BoardInfo) -> Self {
        let slice_bytes = usize::try_from(info.max_slice_samples).unwrap_or(usize::MAX);
        match known_board(info) {
            Some(b) => {
                Self::of_capacity(&b.capacity, format!("the board (an {} by its capabilities)", b.name))
            }
            None => Self { slice_bytes, extent: WIRE_MAX_EXTENT, holder: "the board".into() },
        }
    }

    /// Whether a volume of `dims` with samples of `size` bytes fits.
    pub fn fits(&self, dims: Dims, size: usize) -> bool {
        let Dims(nx, ny, nz) = dims;
        let bytes = nx.checked_mul(ny).and_then(|n| n.checked_mul(size));
        nx >= 2
            && ny >= 2
            && (1..=WIRE_MAX_EXTENT).contains(&nz)
            && nx.max(ny) <= self.extent
            && bytes.is_some_and(|b| b <= self.slice_bytes)
    }

    /// The limits in words.
    pub fn describe(&self) -> String {
        format!(
            "{} takes slices of at most {} bytes and {} samples a side",
            self.holder, self.slice_bytes, self.extent
        )
    }
}

/// The board of the core's ([`Board::ALL`]) whose memory a connected
/// board reported: the same slice bytes and display points.
pub fn known_board(info: &BoardInfo) -> Option<Board> {
    let slice_bytes = usize::try_from(info.max_slice_samples).ok()?;
    Board::ALL.into_iter().find(|b| {
        b.capacity.slice_bytes == slice_bytes
            && u32::try_from(b.capacity.points).is_ok_and(|p| p == info.display_points)
    })
}

const AXES: [&str; 3] = ["x", "y", "z"];

/// The extents after block sizes `f` (whole blocks only).
pub fn downsampled_dims(dims: Dims, f: [usize; 3]) -> Dims {
    Dims(dims.0 / f[0].max(1), dims.1 / f[1].max(1), dims.2 / f[2].max(1))
}

/// The blocks of a uniform downsample by `f` of a volume of `dims`: `f`
/// along every axis, but no more than the volume's depth along z (a 2D
/// grid, or a volume thinner than `f`, keeps its slices).
pub fn uniform(dims: Dims, f: usize) -> Factors {
    Factors([f, f, f.min(dims.2).max(1)])
}

/// The smallest uniform block size ([`uniform`]) that makes a volume of
/// `dims` with samples of `size` bytes fit `limits`, if any does.
pub fn auto_factor(dims: Dims, size: usize, limits: &Limits) -> Option<usize> {
    // Past min(nx, ny) / 2 a slice has fewer than 2x2 samples.
    let most = dims.0.min(dims.1) / 2;
    (1..=most).find(|&f| limits.fits(downsampled_dims(dims, uniform(dims, f).0), size))
}

/// What a board draws of a volume: the slice stride it thinned the
/// surface to (every `every`-th slice of each plane) and whether it still
/// had to drop pieces at the coarsest stride.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Drawn {
    /// The stride drawn (at least the one asked for).
    pub every: usize,
    /// Pieces of the surface were dropped.
    pub dropped: bool,
}

/// A board's choice of uniform downsample ([`finest_on_board`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Choice {
    /// The uniform block size.
    pub factor: usize,
    /// What the board draws at that factor.
    pub drawn: Drawn,
}

impl Choice {
    /// How far apart the slices drawn lie, in voxels of the volume before
    /// the downsample.
    pub fn spacing(&self) -> usize {
        self.factor.saturating_mul(self.drawn.every)
    }
}

/// Fewest samples along x or y a downsample leaves ([`finest_on_board`]):
/// a coarser grid is hardly a picture of the volume.
pub const MIN_FIT_EXTENT: usize = 12;

/// Of the uniform downsamples of a volume of `dims` from `first` on, the
/// one a board draws most of: a board whose surface memory is short thins
/// the slices it draws (every 2nd, 4th, ... of each plane) and, at the
/// coarsest, drops pieces, while a smaller volume has fewer and shorter
/// contours, so a coarser grid may show more of the volume. Ranked by:
/// no pieces dropped, then the drawn slices closest together in the
/// volume's own voxels ([`Choice::spacing`]), then the smaller factor (the
/// finer grid). `draw(f)` puts the volume downsampled by `f` on the
/// board; factors are tried upwards while one could still rank better
/// (`f` times the stride `asked` is less than the best spacing) and the
/// grid keeps [`MIN_FIT_EXTENT`] samples along x and y. Returns the
/// board's picture at `first` and the best.
///
/// # Errors
/// `draw`'s first error.
pub fn finest_on_board(
    dims: Dims,
    first: usize,
    asked: usize,
    mut draw: impl FnMut(usize) -> Result<Drawn>,
) -> Result<(Choice, Choice)> {
    let first = first.max(1);
    let rank = |c: &Choice| (c.drawn.dropped, c.spacing(), c.factor);
    let at_first = Choice { factor: first, drawn: draw(first)? };
    let mut best = at_first;
    let mut f = first;
    loop {
        f += 1;
        let d = downsampled_dims(dims, uniform(dims, f).0);
        let none_better = !best.drawn.dropped && f.saturating_mul(asked.max(1)) >= best.spacing();
        if none_better || d.0.min(d.1) < MIN_FIT_EXTENT || f > dims.0.min(dims.1) {
            return Ok((at_first, best));
        }
        let c = Choice { factor: f, drawn: draw(f)? };
        if rank(&c) < rank(&best) {
            best = c;
        }
    }
}

/// The sample type of `samples`.
pub fn dtype_of(samples: &Samples) -> Dtype {
    match samples {
        Samples::U8(_) => Dtype::U8,
        Samples::U16(_) => Dtype::U16,
        Samples::I16(_) => Dtype::I16,
        Samples::F32(_) => Dtype::F32,
    }
}

/// The smallest type that holds every sample exactly, if smaller than
/// theirs.
pub fn narrower(samples: &Samples) -> Option<Dtype> {
    fn range<T: Copy + PartialOrd>(s: &[T]) -> Option<(T, T)> {
        let first = *s.first()?;
        Some(
            s.iter().fold((first, first), |(lo, hi), &v| {
                (if v < lo { v } else { lo }, if v > hi { v } else { hi })
            }),
        )
    }
    let ty = match samples {
        Samples::U8(_) => return None,
        Samples::U16(s) => range(s).filter(|&(_, hi)| hi <= 255).map(|_| Dtype::U8)?,
        Samples::I16(s) => range(s).filter(|&(lo, hi)| lo >= 0 && hi <= 255).map(|_| Dtype::U8)?,
        Samples::F32(s) => {
            if !s.iter().all(|v| v.is_finite() && v.fract() == 0.0) {
                return None;
            }
            let (lo, hi) = range(s)?;
            if lo >= 0.0 && hi <= 255.0 {
                Dtype::U8
            } else if lo >= f32::from(i16::MIN) && hi <= f32::from(i16::MAX) {
                Dtype::I16
            } else if lo >= 0.0 && hi <= f32::from(u16::MAX) {
                Dtype::U16
            } else {
                return None;
            }
        }
    };
    Some(ty)
}

/// `samples` in type `to` (values out of its range saturate; [`narrower`]
/// chooses a type that holds them all).
pub fn convert(samples: &Samples, to: Dtype) -> Samples {
    fn each<T: Copy>(s: &Samples, f: impl Fn(f64) -> T) -> Vec<T> {
        match s {
            Samples::U8(v) => v.iter().map(|&x| f(f64::from(x))).collect(),
            Samples::U16(v) => v.iter().map(|&x| f(f64::from(x))).collect(),
            Samples::I16(v) => v.iter().map(|&x| f(f64::from(x))).collect(),
            Samples::F32(v) => v.iter().map(|&x| f(f64::from(x))).collect(),
        }
    }
    match to {
        Dtype::U8 => Samples::U8(each(samples, |x| x as u8)),
        Dtype::U16 => Samples::U16(each(samples, |x| x as u16)),
        Dtype::I16 => Samples::I16(each(samples, |x| x as i16)),
        Dtype::F32 => Samples::F32(each(samples, |x| x as f32)),
    }
}

/// Check that `vol`'s samples are as many as its dims say.
fn check_len(vol: &LoadedVolume) -> Result<()> {
    let len = match &vol.samples {
        Samples::U8(s) => s.len(),
        Samples::U16(s) => s.len(),
        Samples::I16(s) => s.len(),
        Samples::F32(s) => s.len(),
    };
    let dims = vol.dims;
    if dims.count() != Some(len) {
        bail!("the volume holds {len} samples, not {}x{}x{}", dims.0, dims.1, dims.2);
    }
    Ok(())
}

/// The part of `vol` in `crop`'s ranges.
///
/// # Errors
/// A range outside the volume or empty.
pub fn crop(vol: &LoadedVolume, crop: &Crop) -> Result<LoadedVolume> {
    let [xr, yr, zr] = crop.ranges(vol.dims)?;
    let Dims(nx, ny, _) = vol.dims;
    fn cut<T: Copy>(s: &[T], nx: usize, ny: usize, r: &[Range<usize>; 3]) -> Vec<T> {
        let [xr, yr, zr] = r;
        let mut out = Vec::with_capacity(xr.len() * yr.len() * zr.len());
        for z in zr.clone() {
            for y in yr.clone() {
                let row = (z * ny + y) * nx;
                out.extend_from_slice(&s[row + xr.start..row + xr.end]);
            }
        }
        out
    }
    let r = [xr.clone(), yr.clone(), zr.clone()];
    check_len(vol)?;
    let samples = match &vol.samples {
        Samples::U8(s) => Samples::U8(cut(s, nx, ny, &r)),
        Samples::U16(s) => Samples::U16(cut(s, nx, ny, &r)),
        Samples::I16(s) => Samples::I16(cut(s, nx, ny, &r)),
        Samples::F32(s) => Samples::F32(cut(s, nx, ny, &r)),
    };
    Ok(LoadedVolume { dims: Dims(xr.len(), yr.len(), zr.len()), samples, spacing: vol.spacing })
}

/// `vol` with each block of `f` voxels replaced by their mean (integers
/// rounded to the nearest, half away from zero, in their type); samples
/// past the last whole block of an axis are left out. The spacing grows by
/// the factors.
///
/// # Errors
/// A factor of 0 or larger than its axis.
pub fn downsample(vol: &LoadedVolume, f: Factors) -> Result<LoadedVolume> {
    let n = [vol.dims.0, vol.dims.1, vol.dims.2];
    for i in 0..3 {
        if f.0[i] == 0 {
            bail!("a downsample factor must be at least 1");
        }
        if f.0[i] > n[i] {
            bail!(
                "--downsample {}: the factor {} is larger than the volume's {} samples along {}",
                f,
                f.0[i],
                n[i],
                AXES[i]
            );
        }
    }
    let out = downsampled_dims(vol.dims, f.0);
    fn mean<T: Copy>(
        s: &[T],
        n: [usize; 3],
        f: [usize; 3],
        out: Dims,
        to: impl Fn(T) -> f64,
        from: impl Fn(f64) -> T,
    ) -> Vec<T> {
        let [nx, ny, _] = n;
        let [fx, fy, fz] = f;
        let Dims(ox, oy, oz) = out;
        // At most the volume's sample count: no overflow.
        let per_block = (fx * fy * fz) as f64;
        let mut res = Vec::with_capacity(ox * oy * oz);
        let mut acc = vec![0f64; ox];
        for zo in 0..oz {
            for yo in 0..oy {
                acc.fill(0.0);
                for z in zo * fz..(zo + 1) * fz {
                    for y in yo * fy..(yo + 1) * fy {
                        let start = (z * ny + y) * nx;
                        let row = &s[start..start + ox * fx];
                        for (a, block) in acc.iter_mut().zip(row.chunks_exact(fx)) {
                            *a += block.iter().map(|&v| to(v)).sum::<f64>();
                        }
                    }
                }
                res.extend(acc.iter().map(|&a| from(a / per_block)));
            }
        }
        res
    }
    check_len(vol)?;
    let samples = match &vol.samples {
        Samples::U8(s) => Samples::U8(mean(s, n, f.0, out, f64::from, |m| m.round() as u8)),
        Samples::U16(s) => Samples::U16(mean(s, n, f.0, out, f64::from, |m| m.round() as u16)),
        Samples::I16(s) => Samples::I16(mean(s, n, f.0, out, f64::from, |m| m.round() as i16)),
        Samples::F32(s) => Samples::F32(mean(s, n, f.0, out, f64::from, |m| m as f32)),
    };
    let spacing = [0, 1, 2].map(|i| vol.spacing[i] * f.0[i] as f32);
    Ok(LoadedVolume { dims: out, samples, spacing })
}

/// How to fit a volume: the user's crop and downsample, if any.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FitOptions {
    /// `--crop`.
    pub crop: Option<Crop>,
    /// `--downsample`.
    pub downsample: Option<Factors>,
}

/// A fitted volume and what was done to it, as `note:` lines.
#[derive(Debug, Clone, PartialEq)]
pub struct Fitted {
    /// The volume to send or draw.
    pub volume: LoadedVolume,
    /// What was done, for the user (without the `isoscope-sim: ` prefix).
    pub notes: Vec<String>,
}

fn dims_text(d: Dims) -> String {
    format!("{}x{}x{}", d.0, d.1, d.2)
}

/// Fit `vol` as `opts` say and, when it goes to a board of `limits`, to
/// that board: samples in the smallest type that holds them exactly, and
/// with neither a crop nor a downsample given, the smallest uniform
/// downsample that fits ([`auto_factor`]), said in a note.
///
/// # Errors
/// A crop or downsample that does not apply to the volume (see [`crop`],
/// [`downsample`]), a volume no uniform downsample fits to the board, or
/// a crop or downsample after which it still does not fit.
pub fn fit(vol: LoadedVolume, opts: &FitOptions, limits: Option<&Limits>) -> Result<Fitted> {
    fit_drawing(vol, opts, limits, None)
}

/// [`fit`] for a board of `limits` whose picture the scene of `cfg` is
/// (the engine with the board's memory, [`crate::scene::build`]), at the
/// stride `every` gives for a volume's dims: with neither a crop nor a
/// downsample given, the uniform downsample the board draws most of
/// ([`finest_on_board`]: from the smallest that fits its slice memory on,
/// the one whose drawn slices lie closest together in the volume), said in
/// a note when it is not the smallest. What `send`, `render --board` and
/// the web page's board preset put on a board.
///
/// # Errors
/// As [`fit`], and a scene the board refuses.
pub fn fit_to_board_picture(
    vol: LoadedVolume,
    opts: &FitOptions,
    limits: &Limits,
    cfg: &crate::scene::SceneConfig,
    every: impl Fn(Dims) -> usize,
) -> Result<Fitted> {
    let mut draw = |v: &LoadedVolume| -> Result<Drawn> {
        let cfg = crate::scene::SceneConfig { every: every(v.dims), ..cfg.clone() };
        let loaded = crate::scene::build(&crate::link::WireVolume::from_loaded(v)?, &cfg)?.loaded;
        Ok(Drawn { every: usize::from(loaded.every), dropped: loaded.dropped > 0 || loaded.cut > 0 })
    };
    fit_drawing(vol, opts, Some(limits), Some(&mut draw))
}

/// Fit `vol` as `send` fits it to a board that said what it takes
/// (`info`): a board the core knows by its capabilities ([`known_board`])
/// as `--board` fits it, to the picture `picture` makes of it
/// ([`fit_to_board_picture`], at the stride `every` gives); any other to
/// its slices ([`fit`]). What `send` and the web page's *send to board*
/// put on a connected board.
///
/// # Errors
/// As [`fit_to_board_picture`] and [`fit`], and `picture`'s.
pub fn fit_to_connected(
    vol: LoadedVolume,
    opts: &FitOptions,
    info: &BoardInfo,
    picture: impl FnOnce(Board) -> Result<crate::scene::SceneConfig>,
    every: impl Fn(Dims) -> usize,
) -> Result<Fitted> {
    let limits = Limits::of_info(info);
    match known_board(info) {
        Some(board) => fit_to_board_picture(vol, opts, &limits, &picture(board)?, every),
        None => fit(vol, opts, Some(&limits)),
    }
}

/// The board's picture of a volume put on it ([`fit_to_board_picture`]).
type DrawOnBoard<'d> = &'d mut dyn FnMut(&LoadedVolume) -> Result<Drawn>;

/// [`fit`], and with `draw` [`fit_to_board_picture`].
fn fit_drawing(
    vol: LoadedVolume,
    opts: &FitOptions,
    limits: Option<&Limits>,
    draw: Option<DrawOnBoard<'_>>,
) -> Result<Fitted> {
    let mut notes = Vec::new();
    let mut vol = vol;
    let original = vol.dims;
    if let Some(c) = &opts.crop {
        vol = crop(&vol, c)?;
        notes.push(format!("--crop {c}: {} of {}", dims_text(vol.dims), dims_text(original)));
    }
    let Some(limits) = limits else {
        if let Some(f) = opts.downsample {
            let before = vol.dims;
            vol = downsample(&vol, f)?;
            notes.push(downsample_note(before, f, &vol, None, false));
        }
        return Ok(Fitted { volume: vol, notes });
    };
    let given = dtype_of(&vol.samples);
    if let Some(ty) = narrower(&vol.samples) {
        vol.samples = convert(&vol.samples, ty);
        notes.push(format!(
            "every sample fits {ty:?}: sent as {ty:?}, not {given:?} (the same picture, {}x fewer bytes)",
            given.size() / ty.size()
        ));
    }
    let ty = dtype_of(&vol.samples);
    let before = vol.dims;
    let fits = limits.fits(before, ty.size());
    let chosen = match opts.downsample {
        Some(f) => Some((f, false)),
        None if opts.crop.is_none() && !fits => {
            let Some(n) = auto_factor(before, ty.size(), limits) else {
                bail!(
                    "{}; no uniform downsample of a {} {ty:?} volume fits (--crop X0:X1,Y0:Y1,Z0:Z1 a part of it)",
                    limits.describe(),
                    dims_text(before)
                );
            };
            Some((uniform(before, n), true))
        }
        None => None,
    };
    // The board's picture at the smallest factor that fits, and at the
    // coarser ones while they may draw more.
    let mut thinned = None;
    let chosen = match (draw, chosen) {
        (Some(draw), None | Some((_, true))) if opts.crop.is_none() => {
            let first = chosen.map_or(1, |(f, _)| f.0[0]);
            // The stride asked for differs by factor (`every`): a bound of 1.
            let (at_first, best) = finest_on_board(before, first, 1, |f| {
                if f == 1 { draw(&vol) } else { draw(&downsample(&vol, uniform(before, f))?) }
            })?;
            if best.factor != first {
                thinned = Some((first, at_first.drawn, best));
            }
            (best.factor > 1).then(|| (uniform(before, best.factor), true))
        }
        (_, chosen) => chosen,
    };
    if let Some((f, auto)) = chosen {
        vol = downsample(&vol, f)?;
        let why = match thinned {
            _ if !auto => None,
            Some((first, at_first, best)) => Some(format!(
                "{} draws {} of a {} volume (slices {} voxels apart{}), and {} once downsampled by {} \
                 ({} voxels apart): ",
                limits.holder,
                crate::scene::stride(u16::try_from(at_first.every).unwrap_or(u16::MAX)),
                dims_text(downsampled_dims(before, uniform(before, first).0)),
                first.saturating_mul(at_first.every),
                if at_first.dropped { ", some pieces dropped" } else { "" },
                crate::scene::stride(u16::try_from(best.drawn.every).unwrap_or(u16::MAX)),
                best.factor,
                best.spacing(),
            )),
            None if fits => None,
            None => Some(format!(
                "{}, and a {}x{} slice of {ty:?} is {} bytes: ",
                limits.describe(),
                before.0,
                before.1,
                before.0.saturating_mul(before.1).saturating_mul(ty.size())
            )),
        };
        notes.push(downsample_note(before, f, &vol, why, thinned.is_some()));
    }
    if !limits.fits(vol.dims, ty.size()) {
        let hint = match auto_factor(vol.dims, ty.size(), limits) {
            Some(n) => {
                let more = uniform(vol.dims, n).0;
                let f = opts.downsample.map_or(more, |g| [0, 1, 2].map(|i| g.0[i].saturating_mul(more[i])));
                format!(" (--downsample {} fits)", Factors(f))
            }
            None => " (crop a smaller part)".into(),
        };
        bail!("{}; a {} {ty:?} volume does not fit{hint}", limits.describe(), dims_text(vol.dims));
    }
    Ok(Fitted { volume: vol, notes })
}

/// The note for a downsample of a `before` volume by `f` into `after`.
fn downsample_note(
    before: Dims,
    f: Factors,
    after: &LoadedVolume,
    why: Option<String>,
    drawn: bool,
) -> String {
    let ty = dtype_of(&after.samples);
    let n = [before.0, before.1, before.2];
    let left: Vec<String> = (0..3)
        .filter(|&i| !n[i].is_multiple_of(f.0[i]))
        .map(|i| format!("{} along {}", n[i] % f.0[i], AXES[i]))
        .collect();
    let rounded = if ty == Dtype::F32 { "" } else { ", rounded" };
    let mut s = match &why {
        Some(why) => format!(
            "{why}downsampling by {} ({}; --downsample or --crop to choose): \
             the mean of each {} block{rounded}, {} {ty:?}",
            f.0[0],
            if drawn {
                "the factor whose drawn slices lie closest together"
            } else {
                "the smallest factor that fits"
            },
            f.block(),
            dims_text(after.dims)
        ),
        None => format!(
            "downsampled: the mean of each {} block{rounded}, {} {ty:?}",
            f.block(),
            dims_text(after.dims)
        ),
    };
    if !left.is_empty() {
        s += &format!(" (left out, short of a whole block: the last {})", left.join(", "));
    }
    s
}
