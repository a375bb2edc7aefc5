//! Volume sources: raw little-endian files and the built-in demos.

use crate::formats::{self, Input};
use crate::orient::AxisMap;
use anyhow::{Context, Result, bail};
use isoscope_core::demo::Demo;
use std::path::Path;

/// A sample type of a raw volume file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Dtype {
    /// Unsigned 8-bit (MRI).
    U8,
    /// Unsigned 16-bit little-endian.
    U16,
    /// Signed 16-bit little-endian (CT).
    I16,
    /// IEEE 754 single little-endian (simulation, EM).
    F32,
}

impl Dtype {
    /// Bytes per sample.
    pub fn size(self) -> usize {
        match self {
            Dtype::U8 => 1,
            Dtype::U16 | Dtype::I16 => 2,
            Dtype::F32 => 4,
        }
    }
}

impl std::str::FromStr for Dtype {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "u8" => Ok(Dtype::U8),
            "u16" => Ok(Dtype::U16),
            "i16" => Ok(Dtype::I16),
            "f32" => Ok(Dtype::F32),
            _ => Err(format!("unknown sample type `{s}` (expected u8, u16, i16 or f32)")),
        }
    }
}

/// Byte order of a raw volume file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Endian {
    /// Least significant byte first (x86, ARM).
    #[default]
    Little,
    /// Most significant byte first.
    Big,
}

impl std::str::FromStr for Endian {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "little" | "le" => Ok(Endian::Little),
            "big" | "be" => Ok(Endian::Big),
            _ => Err(format!("unknown byte order `{s}` (expected little or big)")),
        }
    }
}

/// Volume extents parsed from `NXxNYxNZ`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Dims(pub usize, pub usize, pub usize);

impl Dims {
    /// Samples in the volume.
    pub fn count(self) -> Option<usize> {
        self.0.checked_mul(self.1)?.checked_mul(self.2)
    }
}

impl std::str::FromStr for Dims {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let parts: Vec<&str> = s.split(['x', 'X']).collect();
        let bad = || format!("`{s}` is not NXxNYxNZ (e.g. 128x128x84)");
        if parts.len() != 3 {
            return Err(bad());
        }
        let mut n = [0usize; 3];
        for (slot, p) in n.iter_mut().zip(&parts) {
            let p = p.trim();
            *slot = p.parse().map_err(|_| {
                if !p.is_empty() && p.bytes().all(|b| b.is_ascii_digit()) {
                    format!("`{s}`: the extent {p} is too large")
                } else {
                    bad()
                }
            })?;
            if *slot == 0 {
                return Err(format!("`{s}`: every extent must be at least 1"));
            }
        }
        Ok(Dims(n[0], n[1], n[2]))
    }
}

/// A built-in demo and its size, parsed from `NAME:N`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct DemoSpec {
    /// Which demo.
    pub demo: Demo,
    /// Samples per axis.
    pub n: usize,
}

/// Largest demo edge: 1024^3 f32 is 4 GiB.
pub const MAX_DEMO_N: usize = 1024;

impl std::str::FromStr for DemoSpec {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let names = Demo::ALL.map(|d| d.name()).join(", ");
        let (name, n) = s.split_once(':').unwrap_or((s, "32"));
        let demo = Demo::from_name(name)
            .ok_or_else(|| format!("unknown demo `{name}` (expected one of: {names})"))?;
        let n: usize = n
            .parse()
            .map_err(|_| format!("`{s}`: the size after `:` must be a whole number, e.g. {name}:32"))?;
        if !(2..=MAX_DEMO_N).contains(&n) {
            return Err(format!("`{s}`: the size must be between 2 and {MAX_DEMO_N}"));
        }
        Ok(DemoSpec { demo, n })
    }
}

/// The samples of a loaded volume, in their own type.
#[derive(Debug, Clone, PartialEq)]
pub enum Samples {
    /// u8 samples.
    U8(Vec<u8>),
    /// u16 samples.
    U16(Vec<u16>),
    /// i16 samples.
    I16(Vec<i16>),
    /// f32 samples.
    F32(Vec<f32>),
}

/// A loaded volume.
#[derive(Debug, Clone, PartialEq)]
pub struct LoadedVolume {
    /// Extents.
    pub dims: Dims,
    /// Samples, x fastest.
    pub samples: Samples,
    /// Physical size of a voxel along x, y, z (any unit; `[1, 1, 1]` when
    /// the format does not say), honoured by the 3D view.
    pub spacing: [f32; 3],
}

/// Voxel spacing when a format gives none.
pub const UNIT_SPACING: [f32; 3] = [1.0, 1.0, 1.0];

/// The volume files that load by their name or first bytes, with their
/// name endings: every [`formats::Format`], then VolPack `.den`.
pub fn known_formats() -> String {
    let mut names: Vec<String> = formats::Format::ALL
        .iter()
        .map(|f| {
            let ext: Vec<String> = f.extensions().iter().map(|e| format!(".{e}")).collect();
            format!("{} ({})", f.name(), ext.join(", "))
        })
        .collect();
    names.push("VolPack (.den)".into());
    names.join(", ")
}

/// Why a volume file was not loaded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LoadError {
    /// Neither the file's name nor its first bytes tell a format that
    /// loads, and no `--dims` and `--dtype` say how to read it raw.
    UnknownFormat(std::path::PathBuf),
}

impl std::fmt::Display for LoadError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LoadError::UnknownFormat(path) => write!(
                f,
                "{}: neither its name nor its first bytes tell a volume format; volumes load from {} \
                 files, any of them gzipped (.gz), and from raw samples with --dims NXxNYxNZ and \
                 --dtype u8|u16|i16|f32",
                path.display(),
                known_formats()
            ),
        }
    }
}

impl std::error::Error for LoadError {}

impl LoadedVolume {
    /// Compute a built-in demo.
    pub fn demo(spec: DemoSpec) -> Result<Self> {
        let n = spec.n;
        let mut data = vec![0f32; n * n * n];
        spec.demo.fill(n, &mut data)?;
        Ok(Self { dims: Dims(n, n, n), samples: Samples::F32(data), spacing: UNIT_SPACING })
    }

    /// The volume with its axes rearranged by `map`: axis `d` of the result
    /// runs along axis `map.from()[d]` of this one, reversed where
    /// `map.flip()[d]`; the extents and spacing follow. (A file's
    /// orientation is applied so, [`crate::formats::Orientation`]: a
    /// permutation of the samples, so that the board, sent the slices,
    /// holds the same volume.)
    #[must_use]
    pub fn reoriented(self, map: AxisMap) -> Self {
        let Dims(nx, ny, nz) = self.dims;
        let (samples, dims) = remap(self.samples, [nx, ny, nz], map);
        let spacing = map.from().map(|a| self.spacing.get(a).copied().unwrap_or(1.0));
        Self { dims, samples, spacing }
    }

    /// Decode raw little-endian samples.
    pub fn from_bytes(bytes: &[u8], dims: Dims, dtype: Dtype) -> Result<Self> {
        Self::from_bytes_endian(bytes, dims, dtype, Endian::Little)
    }

    /// Decode raw samples in the given byte order.
    pub fn from_bytes_endian(bytes: &[u8], dims: Dims, dtype: Dtype, endian: Endian) -> Result<Self> {
        let count = dims.count().context("the volume extents overflow")?;
        let expected = count.checked_mul(dtype.size()).context("the volume extents overflow")?;
        if bytes.len() != expected {
            bail!(
                "the file holds {} bytes but {}x{}x{} {:?} samples need {} bytes{}",
                bytes.len(),
                dims.0,
                dims.1,
                dims.2,
                dtype,
                expected,
                if bytes.len() < expected {
                    " (truncated, or wrong --dims/--dtype?)"
                } else {
                    " (wrong --dims/--dtype?)"
                }
            );
        }
        Ok(Self::decoded(bytes.to_vec(), dims, dtype, endian))
    }

    /// Decode exactly the bytes of `dims` samples of `dtype`.
    fn decoded(bytes: Vec<u8>, dims: Dims, dtype: Dtype, endian: Endian) -> Self {
        let samples = formats::decode(bytes, dtype.into(), endian.into());
        Self { dims, samples, spacing: UNIT_SPACING }
    }

    /// Decode a VolPack density file (`.den`): a 62-byte header (version 1,
    /// in either byte order; original, extracted and map extents; warps;
    /// sample count), then exactly that many `u8` samples, x fastest.
    pub fn from_den(bytes: &[u8]) -> Result<Self> {
        Self::read_den(&mut Input::from_slice(bytes), usize::MAX)
    }

    /// Read a `.den` file from `input`, refusing one whose samples take
    /// more than `max_bytes`.
    fn read_den(input: &mut Input<'_>, max_bytes: usize) -> Result<Self> {
        const HEADER: usize = 62;
        let header = input.head(HEADER)?;
        if header.len() < HEADER {
            bail!("a .den file starts with a {HEADER}-byte header; this one has only {} bytes", header.len());
        }
        let swap = match [header[0], header[1]] {
            [0, 1] => false,
            [1, 0] => true,
            v => bail!("not a VolPack .den file (version bytes {v:02x?}, expected 00 01 or 01 00)"),
        };
        let short = |i: usize| {
            let b = [header[2 * i], header[2 * i + 1]];
            if swap { i16::from_le_bytes(b) } else { i16::from_be_bytes(b) }
        };
        // Shorts: version, orig_min[3], orig_max[3], orig_len[3], extr_min[3],
        // extr_max[3], extr_len[3], map_min[3], map_max[3], map_len[3], warps.
        let len = [short(25), short(26), short(27)];
        let w = [header[58], header[59], header[60], header[61]];
        let count = if swap { i32::from_le_bytes(w) } else { i32::from_be_bytes(w) };
        if len.iter().any(|&l| l <= 0) {
            bail!("the .den header gives extents {len:?}; every extent must be positive");
        }
        let dims = Dims(len[0] as usize, len[1] as usize, len[2] as usize);
        if i64::from(count) != (len[0] as i64) * (len[1] as i64) * (len[2] as i64) {
            bail!("the .den header is inconsistent: {count} samples for extents {len:?}");
        }
        let need = formats::check_size(&[dims.0, dims.1, dims.2], formats::Elem::U8, max_bytes)?;
        let body = input.exactly(need).with_context(|| {
            format!(
                "the .den header's {}x{}x{} samples need {need} bytes after the header",
                dims.0, dims.1, dims.2
            )
        })?;
        Ok(Self { dims, samples: Samples::U8(body), spacing: UNIT_SPACING })
    }

    /// Read a volume file whose format its name tells (`.den`, and those of
    /// [`crate::formats::Format::from_name`]) or, failing that, its first
    /// bytes ([`crate::formats::Format::sniff`]); `Ok(None)` for any other
    /// file (a raw one). A file holding several volumes gives its first.
    pub fn read_known(path: &Path) -> Result<Option<Self>> {
        Ok(Self::read_known_with(path, &formats::Options::default())?.map(|(v, _)| v))
    }

    /// As [`LoadedVolume::read_known`], choosing among several volumes with
    /// `opts` (which also bound the volume's size), and with the reader's
    /// remarks for the user (conversions, units, which volume was taken).
    pub fn read_known_with(path: &Path, opts: &formats::Options) -> Result<Option<(Self, Vec<String>)>> {
        match formats::extension(path).as_deref() {
            Some("den") => {
                let v = Input::open(path)
                    .and_then(|mut input| Self::read_den(&mut input, opts.max_bytes))
                    .with_context(|| format!("cannot load {}", path.display()))?;
                Ok(Some((v, Vec::new())))
            }
            _ => Ok(formats::read(path, opts)?.map(|l| (l.volume, l.notes))),
        }
    }

    /// As [`LoadedVolume::read_known_with`], for a file's bytes already in
    /// memory, named `name` ([`formats::read_bytes`]).
    ///
    /// # Errors
    /// The bytes are not a volume of the format their name or first bytes
    /// tell, or it is larger than `opts` allows.
    pub fn read_known_bytes(
        name: &str,
        bytes: &[u8],
        opts: &formats::Options,
    ) -> Result<Option<(Self, Vec<String>)>> {
        if formats::extension(Path::new(name)).as_deref() == Some("den") {
            let mut input = Input::from_slice(bytes);
            if formats::is_gzip(bytes) {
                input = input.gunzip_rest();
            }
            let v =
                Self::read_den(&mut input, opts.max_bytes).with_context(|| format!("cannot load {name}"))?;
            return Ok(Some((v, Vec::new())));
        }
        Ok(formats::read_bytes(name, bytes, opts)?.map(|l| (l.volume, l.notes)))
    }

    /// Read a raw volume file in the given byte order: exactly the bytes
    /// of `dims` samples of `dtype`, refusing a file with fewer or more
    /// (it stops reading there: a stream without end is refused too), and
    /// refusing samples that take more than `max_bytes` before reading any
    /// ([`formats::Options::max_bytes`]).
    pub fn read_raw_endian(
        path: &Path,
        dims: Dims,
        dtype: Dtype,
        endian: Endian,
        max_bytes: usize,
    ) -> Result<Self> {
        let load = || -> Result<Self> {
            let need = formats::check_size(&[dims.0, dims.1, dims.2], dtype.into(), max_bytes)?;
            let mut input = Input::open_plain(path)?;
            let bytes = input.exactly(need).with_context(|| {
                format!(
                    "{}x{}x{} {dtype:?} samples need {need} bytes (wrong --dims/--dtype?)",
                    dims.0, dims.1, dims.2
                )
            })?;
            Ok(Self::decoded(bytes, dims, dtype, endian))
        };
        load().with_context(|| format!("cannot load {}", path.display()))
    }

    /// Read a raw little-endian volume file (of at most the default
    /// [`formats::DEFAULT_MAX_BYTES`]).
    pub fn read_raw(path: &Path, dims: Dims, dtype: Dtype) -> Result<Self> {
        Self::read_raw_endian(path, dims, dtype, Endian::Little, formats::DEFAULT_MAX_BYTES)
    }
}

/// Samples of extents `n` (x fastest) rearranged by `map` (axis `d` of the
/// result runs along axis `map.from()[d]` of `samples`, reversed where
/// `map.flip()[d]`), with the new extents: the one implementation of
/// transposing and flipping a volume's axes ([`LoadedVolume::reoriented`],
/// and the readers of files stored along other axes).
pub fn remap(samples: Samples, n: [usize; 3], map: AxisMap) -> (Samples, Dims) {
    let (from, flip) = (map.from(), map.flip());
    let out = from.map(|a| n.get(a).copied().unwrap_or(1));
    let dims = Dims(out[0], out[1], out[2]);
    if map.is_identity() {
        return (samples, dims);
    }
    let stride = [1, n[0], n[0].saturating_mul(n[1])];
    // offsets[d][t]: where coordinate t along output axis d starts in the input.
    let offsets: [Vec<usize>; 3] = [0, 1, 2].map(|d| {
        let (len, s) = (out[d], stride.get(from[d]).copied().unwrap_or(0));
        (0..len).map(|t| (if flip[d] { len - 1 - t } else { t }) * s).collect()
    });
    fn go<T: Copy + Default>(v: &[T], o: &[Vec<usize>; 3]) -> Vec<T> {
        let mut out = Vec::with_capacity(v.len());
        for &z in &o[2] {
            for &y in &o[1] {
                let base = z + y;
                out.extend(o[0].iter().map(|&x| v.get(base + x).copied().unwrap_or_default()));
            }
        }
        out
    }
    let samples = match samples {
        Samples::U8(v) => Samples::U8(go(&v, &offsets)),
        Samples::U16(v) => Samples::U16(go(&v, &offsets)),
        Samples::I16(v) => Samples::I16(go(&v, &offsets)),
        Samples::F32(v) => Samples::F32(go(&v, &offsets)),
    };
    (samples, dims)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Value 100 x + 10 y + z at (x, y, z) of a 2x3x4 volume, x fastest.
    fn coded() -> LoadedVolume {
        let (nx, ny, nz) = (2, 3, 4);
        let mut v = Vec::new();
        for z in 0..nz {
            for y in 0..ny {
                for x in 0..nx {
                    v.push((100 * x + 10 * y + z) as f32);
                }
            }
        }
        LoadedVolume { dims: Dims(nx, ny, nz), samples: Samples::F32(v), spacing: [1.0, 2.0, 3.0] }
    }

    fn at(v: &LoadedVolume, x: usize, y: usize, z: usize) -> f32 {
        let Dims(nx, ny, _) = v.dims;
        let Samples::F32(s) = &v.samples else { panic!() };
        s[x + nx * (y + ny * z)]
    }

    #[test]
    fn reoriented_permutes_and_flips_samples_extents_and_spacing() {
        // x = -k, y = i, z = j.
        let map = AxisMap::new([2, 0, 1], [true, false, false]).unwrap();
        let r = coded().reoriented(map);
        assert_eq!(r.dims, Dims(4, 2, 3));
        assert_eq!(r.spacing, [3.0, 1.0, 2.0]);
        for x in 0..4 {
            for y in 0..2 {
                for z in 0..3 {
                    // Original (i, j, k) = (y, z, 3 - x).
                    assert_eq!(at(&r, x, y, z), (100 * y + 10 * z + (3 - x)) as f32, "({x},{y},{z})");
                }
            }
        }
        // Flips alone keep the extents; twice is the identity.
        let flip = AxisMap::new([0, 1, 2], [true, true, true]).unwrap();
        let f = coded().reoriented(flip);
        assert_eq!((f.dims, at(&f, 0, 0, 0), at(&f, 1, 2, 3)), (Dims(2, 3, 4), 123.0, 0.0));
        assert_eq!(f.reoriented(flip), coded());
        assert_eq!(coded().reoriented(AxisMap::IDENTITY), coded());
        // Every type; an empty volume.
        let u8s =
            LoadedVolume { dims: Dims(3, 1, 1), samples: Samples::U8(vec![1, 2, 3]), spacing: [1.0; 3] };
        assert_eq!(u8s.reoriented(flip).samples, Samples::U8(vec![3, 2, 1]));
        let (s, d) = remap(Samples::I16(vec![]), [0, 2, 2], map);
        assert_eq!((s, d), (Samples::I16(vec![]), Dims(2, 0, 2)));
    }
}
