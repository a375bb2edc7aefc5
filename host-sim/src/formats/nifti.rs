//! NIfTI-1: a `.nii` file (header, extensions, data at `vox_offset`), gzip
//! compressed or not, or a `.hdr` + `.img` pair; either byte order.
//!
//! The 348-byte header is parsed by the `nifti` crate; the byte order is
//! the one in which `sizeof_hdr` reads 348. Data types: `uint8` loads as
//! `u8`, `int8` and `int16` as `i16`, `uint16` as `u16`, `float32` as `f32`;
//! `int32`, `uint32`, `int64`, `uint64` and `float64` as `f32` with a note;
//! complex, RGB and 128-bit types are refused. A non-trivial `scl_slope` /
//! `scl_inter` (slope neither 0 nor 1, or an intercept) is applied, giving
//! `f32` samples. Spacing: `|pixdim[1..=3]|`. Dims: `dim[1..=3]`, missing
//! ones 1; a file with more dimensions (`dim[4..]`, time and so on) holds
//! several volumes, and [`Options::index`] picks one (default the first).
//!
//! Orientation ([`super::Orientation::File`], the default): the sform if
//! `sform_code > 0`, else the qform (quaternion, `pixdim`, `qfac`) if
//! `qform_code > 0`, else none; the volume is then rearranged so that a head
//! is upright and faces the viewer ([`crate::orient`]), and the spacing is
//! the length of each axis's direction. With [`super::Orientation::Index`],
//! x is the file's first axis.

use super::{
    Data, Elem, Endian, Format, Input, Loaded, Options, byte_len, check_size, decode, oriented, to_f32,
    voxel_size,
};
use crate::orient::{Directions, Space, qform_directions};
use crate::volume::{Dims, LoadedVolume, Samples};
use anyhow::{Context, Result, anyhow, bail};
use nifti::{NiftiError, NiftiHeader, NiftiType};
use std::path::{Path, PathBuf};

/// Size of a NIfTI-1 header.
pub const HEADER: usize = 348;

/// The byte order in which a header's `sizeof_hdr` reads 348, if either.
pub fn sizeof_hdr_endian(bytes: &[u8]) -> Option<Endian> {
    let w: [u8; 4] = bytes.get(..4)?.try_into().ok()?;
    if i32::from_le_bytes(w) == HEADER as i32 {
        Some(Endian::Little)
    } else if i32::from_be_bytes(w) == HEADER as i32 {
        Some(Endian::Big)
    } else {
        None
    }
}

/// Read a `.nii` or `.nii.gz` file, or a `.hdr` (`.hdr.gz`) whose data are
/// in the `.img` (`.img.gz`) beside it: the header, then the data it
/// declares, streamed (a gzip file is inflated as it is read).
pub fn read(path: &Path, opts: &Options) -> Result<Loaded> {
    read_from(Input::open(path)?, Some(path), opts)
}

/// Read a NIfTI-1 file from `input`: a `.nii`, or the `.hdr` at `path`
/// whose data are in the `.img` beside it (none without a `path`).
pub(crate) fn read_from(mut input: Input<'_>, path: Option<&Path>, opts: &Options) -> Result<Loaded> {
    let h = header(&mut input)?;
    if &h.magic == b"ni1\0" {
        let Some(path) = path else {
            bail!("the header's magic `ni1` says the data are in a separate .img file, which is not here");
        };
        let img = image_path(path).with_context(|| {
            format!(
                "the header's magic `ni1` says the data are in a separate .img file, and no {} is there",
                {
                    let mut p = path.to_path_buf();
                    p.set_extension("img");
                    p.display().to_string()
                }
            )
        })?;
        return Input::open(&img)
            .and_then(|mut data| volume(&h, &mut data, 0, opts))
            .with_context(|| format!("in the image file {}", img.display()));
    }
    volume(&h, &mut input, HEADER + 4, opts)
}

/// Decode a single-file NIfTI-1 (`.nii`, already gunzipped).
pub fn parse(bytes: &[u8], opts: &Options) -> Result<Loaded> {
    let mut input = Input::from_slice(bytes);
    let h = header(&mut input)?;
    if &h.magic == b"ni1\0" {
        bail!(
            "the header's magic `ni1` says the data are in a separate .img file; open the .hdr file instead"
        );
    }
    volume(&h, &mut input, HEADER + 4, opts)
}

/// The `.img` or `.img.gz` beside a `.hdr` or `.hdr.gz`, if there is one.
fn image_path(hdr: &Path) -> Option<PathBuf> {
    let name = hdr.file_name()?.to_str()?;
    let lower = name.to_ascii_lowercase();
    let stem = if lower.ends_with(".hdr.gz") {
        &name[..name.len() - 7]
    } else if lower.ends_with(".hdr") {
        &name[..name.len() - 4]
    } else {
        name
    };
    ["img", "img.gz", "IMG", "IMG.GZ"]
        .iter()
        .map(|e| hdr.with_file_name(format!("{stem}.{e}")))
        .find(|p| p.exists())
}

/// Read, parse and check the 348-byte header.
fn header(input: &mut Input<'_>) -> Result<NiftiHeader> {
    let bytes = input.head(HEADER)?;
    if bytes.len() < HEADER {
        bail!("the file is truncated: a NIfTI-1 header is {HEADER} bytes, the file has {}", bytes.len());
    }
    let Some(order) = sizeof_hdr_endian(&bytes) else {
        let w = [bytes[0], bytes[1], bytes[2], bytes[3]];
        let (le, be) = (i32::from_le_bytes(w), i32::from_be_bytes(w));
        if le == 540 || be == 540 {
            bail!("this is a NIfTI-2 file (sizeof_hdr 540), which is not supported; only NIfTI-1");
        }
        bail!("not a NIfTI-1 file: sizeof_hdr reads {le} (little-endian) or {be} (big-endian), not {HEADER}");
    };
    let h = NiftiHeader::from_reader(&bytes[..]).map_err(|e| match e {
        NiftiError::InvalidFormat => anyhow!(
            "not a NIfTI-1 file: the magic at byte 344 is {:?}, not \"n+1\" or \"ni1\" (an Analyze 7.5 header?)",
            String::from_utf8_lossy(&bytes[344..348])
        ),
        e => anyhow!("cannot parse the NIfTI-1 header: {e}"),
    })?;
    // The crate tells the byte order by dim[0]; sizeof_hdr must agree.
    let crate_order = if h.endianness == nifti::Endianness::Little { Endian::Little } else { Endian::Big };
    if crate_order != order {
        let d = [bytes[40], bytes[41]];
        let d0 = if order == Endian::Little { i16::from_le_bytes(d) } else { i16::from_be_bytes(d) };
        bail!("the header's dim[0] is {d0}; it must be 1 to 7");
    }
    let n = usize::from(h.dim[0]);
    if !(1..=7).contains(&n) {
        bail!("the header's dim[0] is {}; it must be 1 to 7", h.dim[0] as i16);
    }
    if let Some(i) = (1..=n).find(|&i| h.dim[i] == 0 || h.dim[i] > i16::MAX as u16) {
        bail!("the header's dim[{i}] is {}; every extent must be positive", h.dim[i] as i16);
    }
    Ok(h)
}

/// Where the data start: `vox_offset`, at least `min` (the end of the
/// header and extension flag, in a single file), at most `max_bytes` past
/// it (extensions larger than a volume are refused, not read through).
fn offset(h: &NiftiHeader, min: usize, max_bytes: usize) -> Result<usize> {
    let v = h.vox_offset;
    if !v.is_finite() || v < 0.0 || v.fract() != 0.0 {
        bail!("the header's vox_offset {v} is not a byte offset");
    }
    let at = (v as usize).max(min);
    if at - min > max_bytes {
        bail!(
            "the header's vox_offset {v} puts the data more than the limit of {max_bytes} bytes past the header"
        );
    }
    Ok(at)
}

/// The sample type of a NIfTI data type.
fn elem(t: NiftiType) -> Result<Elem> {
    Ok(match t {
        NiftiType::Uint8 => Elem::U8,
        NiftiType::Int8 => Elem::I8,
        NiftiType::Int16 => Elem::I16,
        NiftiType::Uint16 => Elem::U16,
        NiftiType::Int32 => Elem::I32,
        NiftiType::Uint32 => Elem::U32,
        NiftiType::Int64 => Elem::I64,
        NiftiType::Uint64 => Elem::U64,
        NiftiType::Float32 => Elem::F32,
        NiftiType::Float64 => Elem::F64,
        t => bail!(
            "the data type {t:?} (datatype {}) is not supported: only real scalar types (uint8, int8, int16, \
             uint16, int32, uint32, int64, uint64, float32, float64)",
            t as i16
        ),
    })
}

/// Read volume `opts.index` from `input`, which has given the header and
/// holds the data from byte `vox_offset` (at least `min`). The volumes
/// before it are passed over; those after it too, and then nothing may
/// follow, when all the data fit within [`Options::max_bytes`]; otherwise
/// they are left unread.
fn volume(h: &NiftiHeader, input: &mut Input<'_>, min: usize, opts: &Options) -> Result<Loaded> {
    let t = h
        .data_type()
        .map_err(|_| anyhow!("the header's datatype {} is not a NIfTI-1 data type", h.datatype))?;
    let elem = elem(t)?;
    let n = usize::from(h.dim[0]);
    let ext = |i: usize| if i <= n { usize::from(h.dim[i]) } else { 1 };
    let (nx, ny, nz) = (ext(1), ext(2), ext(3));
    let all: Vec<usize> = (1..=n).map(ext).collect();
    let need = byte_len(&all, elem)?;
    // No overflow: `need` did not.
    let frames: usize = (4..=7).map(ext).product();
    let shape = all.iter().map(|d| d.to_string()).collect::<Vec<_>>().join("x");
    if opts.index >= frames {
        bail!("the file holds {frames} volume(s) of {nx}x{ny}x{nz}; volume {} was asked for", opts.index);
    }
    let (slope, inter) = (h.scl_slope, h.scl_inter);
    let scaled = slope.is_finite() && slope != 0.0 && (slope != 1.0 || (inter.is_finite() && inter != 0.0));
    let one = check_size(&[nx, ny, nz], elem, opts.max_bytes)?;
    if scaled {
        check_size(&[nx, ny, nz], Elem::F32, opts.max_bytes)?;
    }
    let offset = offset(h, min, opts.max_bytes)?;
    let gap = offset.saturating_sub(usize::try_from(input.pos()).unwrap_or(usize::MAX));
    input
        .data(gap)
        .skip(gap as u64)
        .with_context(|| format!("the header's vox_offset {} is past the end of the file", h.vox_offset))?;
    let mut data = input.data(need);
    let bytes = take_volume(&mut data, opts.index, one, need <= opts.max_bytes).with_context(|| {
        format!(
            "the header's extents {shape} of {} need {need} bytes of data from byte {offset}",
            elem.name()
        )
    })?;
    let endian = if h.endianness == nifti::Endianness::Little { Endian::Little } else { Endian::Big };
    let mut samples = decode(bytes, elem, endian);
    let mut notes: Vec<String> = elem.note().into_iter().collect();
    if frames > 1 {
        notes.push(format!("the file holds {frames} volumes ({shape}); loaded volume {}", opts.index));
    }
    if scaled {
        let inter = if inter.is_finite() { inter } else { 0.0 };
        samples = Samples::F32(to_f32(samples).into_iter().map(|v| v * slope + inter).collect());
        notes.push(format!("scaled by scl_slope {slope} and scl_inter {inter} into f32"));
    }
    let spacing = [1, 2, 3].map(|i| if i <= n { voxel_size(f64::from(h.pixdim[i])) } else { 1.0 });
    let loaded = Loaded {
        volume: LoadedVolume { dims: Dims(nx, ny, nz), samples, spacing },
        format: Format::Nifti,
        notes,
    };
    Ok(oriented(loaded, directions(h), opts))
}

/// The directions of the index axes in RAS+ space: the sform's if its code
/// is positive, else the qform's if its code is, else none (the index axes;
/// nifti1.h's method 1).
fn directions(h: &NiftiHeader) -> Option<(Directions, &'static str)> {
    if h.sform_code > 0 {
        let rows = [h.srow_x, h.srow_y, h.srow_z].map(|r| r.map(f64::from));
        let columns = [0, 1, 2].map(|i| [rows[0][i], rows[1][i], rows[2][i]]);
        Some((Directions { space: Space::Ras, columns }, "sform"))
    } else if h.qform_code > 0 {
        let q = [h.quatern_b, h.quatern_c, h.quatern_d].map(f64::from);
        let pixdim = [h.pixdim[0], h.pixdim[1], h.pixdim[2], h.pixdim[3]].map(f64::from);
        Some((qform_directions(q, pixdim), "qform"))
    } else {
        None
    }
}

/// Volume `index` of `one` bytes from `data`; then, if `whole`, the rest
/// passed over and checked to be all.
fn take_volume(data: &mut Data<'_, '_>, index: usize, one: usize, whole: bool) -> Result<Vec<u8>> {
    // No overflow: index < frames, and frames * one did not.
    data.skip((index * one) as u64)?;
    let bytes = data.take(one)?;
    if whole {
        data.finish()?;
    }
    Ok(bytes)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A NIfTI-1 header built field by field at the offsets of nifti1.h
    /// (independently of the `nifti` crate), then `data`.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn file(
        dims: &[i16],
        datatype: i16,
        bitpix: i16,
        pixdim: [f32; 3],
        slope_inter: (f32, f32),
        magic: &[u8; 4],
        big: bool,
        data: &[u8],
    ) -> Vec<u8> {
        let mut h = vec![0u8; 352];
        let mut put = |at: usize, b: &[u8]| h[at..at + b.len()].copy_from_slice(b);
        let i16b = |v: i16| if big { v.to_be_bytes() } else { v.to_le_bytes() };
        let i32b = |v: i32| if big { v.to_be_bytes() } else { v.to_le_bytes() };
        let f32b = |v: f32| if big { v.to_be_bytes() } else { v.to_le_bytes() };
        put(0, &i32b(348));
        put(40, &i16b(dims.len() as i16));
        for (i, &d) in dims.iter().enumerate() {
            put(42 + 2 * i, &i16b(d));
        }
        put(70, &i16b(datatype));
        put(72, &i16b(bitpix));
        put(76, &f32b(1.0));
        for (i, &p) in pixdim.iter().enumerate() {
            put(80 + 4 * i, &f32b(p));
        }
        put(108, &f32b(352.0));
        put(112, &f32b(slope_inter.0));
        put(116, &f32b(slope_inter.1));
        put(344, magic);
        h.extend_from_slice(data);
        h
    }

    fn le16(v: &[i16]) -> Vec<u8> {
        v.iter().flat_map(|x| x.to_le_bytes()).collect()
    }

    fn err(bytes: &[u8]) -> String {
        format!("{:#}", parse(bytes, &Options::default()).unwrap_err())
    }

    #[test]
    fn little_endian_u8_with_spacing() {
        let data: Vec<u8> = (0..24).collect();
        let f = file(&[2, 3, 4], 2, 8, [0.5, 2.0, -3.0], (0.0, 0.0), b"n+1\0", false, &data);
        let l = parse(&f, &Options::default()).unwrap();
        assert_eq!(l.format, Format::Nifti);
        assert_eq!(l.volume.dims, Dims(2, 3, 4));
        assert_eq!(l.volume.spacing, [0.5, 2.0, 3.0]);
        assert_eq!(l.volume.samples, Samples::U8(data));
        assert!(l.notes.is_empty(), "{:?}", l.notes);
    }

    #[test]
    fn big_endian_int16_and_int8() {
        let v = [-300i16, 0, 7, i16::MAX];
        let be: Vec<u8> = v.iter().flat_map(|x| x.to_be_bytes()).collect();
        let f = file(&[2, 2], 4, 16, [1.0, 1.0, 0.0], (1.0, 0.0), b"n+1\0", true, &be);
        let l = parse(&f, &Options::default()).unwrap();
        assert_eq!(l.volume.dims, Dims(2, 2, 1));
        assert_eq!(l.volume.spacing, [1.0, 1.0, 1.0]);
        assert_eq!(l.volume.samples, Samples::I16(v.to_vec()));
        let f = file(&[3, 1, 1], 256, 8, [1.0; 3], (0.0, 0.0), b"n+1\0", true, &[0x80, 0xff, 0x7f]);
        assert_eq!(parse(&f, &Options::default()).unwrap().volume.samples, Samples::I16(vec![-128, -1, 127]));
    }

    #[test]
    fn uint16_float64_and_scaling() {
        let f = file(&[2, 1, 1], 512, 16, [1.0; 3], (0.0, 0.0), b"n+1\0", false, &[1, 0, 0xff, 0xff]);
        assert_eq!(parse(&f, &Options::default()).unwrap().volume.samples, Samples::U16(vec![1, 65535]));
        let d: Vec<u8> = [0.25f64, -1e300].iter().flat_map(|x| x.to_le_bytes()).collect();
        let f = file(&[2, 1, 1], 64, 64, [1.0; 3], (0.0, 0.0), b"n+1\0", false, &d);
        let l = parse(&f, &Options::default()).unwrap();
        assert_eq!(l.volume.samples, Samples::F32(vec![0.25, f32::NEG_INFINITY]));
        assert!(l.notes[0].contains("float64 samples are loaded as f32"), "{:?}", l.notes);
        // int16 with slope 0.5, intercept -10: f32.
        let f = file(&[3, 1, 1], 4, 16, [1.0; 3], (0.5, -10.0), b"n+1\0", false, &le16(&[0, 4, -6]));
        let l = parse(&f, &Options::default()).unwrap();
        assert_eq!(l.volume.samples, Samples::F32(vec![-10.0, -8.0, -13.0]));
        assert!(l.notes.iter().any(|n| n.contains("scl_slope 0.5")), "{:?}", l.notes);
        // Slope 1 with an intercept scales too; slope 0 or 1 alone does not.
        let f = file(&[1, 1, 1], 4, 16, [1.0; 3], (1.0, 3.0), b"n+1\0", false, &le16(&[4]));
        assert_eq!(parse(&f, &Options::default()).unwrap().volume.samples, Samples::F32(vec![7.0]));
        let f = file(&[1, 1, 1], 4, 16, [1.0; 3], (0.0, 3.0), b"n+1\0", false, &le16(&[4]));
        assert_eq!(parse(&f, &Options::default()).unwrap().volume.samples, Samples::I16(vec![4]));
    }

    #[test]
    fn four_dimensions_pick_a_volume() {
        let f = file(&[2, 1, 1, 3], 4, 16, [1.0; 3], (0.0, 0.0), b"n+1\0", false, &le16(&[1, 2, 3, 4, 5, 6]));
        let l = parse(&f, &Options::default()).unwrap();
        assert_eq!(l.volume.samples, Samples::I16(vec![1, 2]));
        assert!(l.notes.iter().any(|n| n.contains("3 volumes")), "{:?}", l.notes);
        let l = parse(&f, &Options { index: 2, ..Options::default() }).unwrap();
        assert_eq!(l.volume.samples, Samples::I16(vec![5, 6]));
        let e = format!("{:#}", parse(&f, &Options { index: 3, ..Options::default() }).unwrap_err());
        assert!(e.contains("holds 3 volume(s) of 2x1x1; volume 3 was asked for"), "{e}");
    }

    /// A 4D file larger than the limit: its volumes load one at a time,
    /// and the volumes after the one taken are not read (here, they are
    /// cut short); within the limit, the whole file is checked.
    #[test]
    fn four_dimensions_over_the_limit_read_only_the_volume_taken() {
        let v = le16(&[1, 2, 3, 4, 5, 6]);
        let f = file(&[2, 1, 1, 3], 4, 16, [1.0; 3], (0.0, 0.0), b"n+1\0", false, &v[..9]);
        let small = |index| Options { index, max_bytes: 4, ..Options::default() };
        assert_eq!(parse(&f, &small(0)).unwrap().volume.samples, Samples::I16(vec![1, 2]));
        assert_eq!(parse(&f, &small(1)).unwrap().volume.samples, Samples::I16(vec![3, 4]));
        let e = format!("{:#}", parse(&f, &small(2)).unwrap_err());
        assert!(e.contains("the data stop after 9 of 12 bytes (truncated?)"), "{e}");
        let e = format!("{:#}", parse(&f, &Options::default()).unwrap_err());
        assert!(e.contains("the data stop after 9 of 12 bytes (truncated?)"), "{e}");
        let e = format!(
            "{:#}",
            parse(&f, &Options { index: 0, max_bytes: 3, ..Options::default() }).unwrap_err()
        );
        assert!(e.contains("2x1x1 int16 samples take 4 bytes, more than the limit of 3 bytes"), "{e}");
        // Scaled to f32: the loaded size counts.
        let f = file(&[2, 1, 1], 4, 16, [1.0; 3], (2.0, 0.0), b"n+1\0", false, &v[..4]);
        let e = format!(
            "{:#}",
            parse(&f, &Options { index: 0, max_bytes: 7, ..Options::default() }).unwrap_err()
        );
        assert!(e.contains("2x1x1 float32 samples take 8 bytes"), "{e}");
        // Extensions larger than the limit before the data are not read through.
        let mut f = file(&[2, 1, 1], 4, 16, [1.0; 3], (0.0, 0.0), b"n+1\0", false, &v[..4]);
        f[108..112].copy_from_slice(&1e6f32.to_le_bytes());
        let e = format!(
            "{:#}",
            parse(&f, &Options { index: 0, max_bytes: 1000, ..Options::default() }).unwrap_err()
        );
        assert!(e.contains("vox_offset 1000000 puts the data more than the limit of 1000 bytes"), "{e}");
    }

    #[test]
    fn bad_files_are_clear_errors() {
        let good = file(&[2, 2, 2], 4, 16, [1.0; 3], (0.0, 0.0), b"n+1\0", false, &le16(&[0; 8]));
        assert!(err(&good[..200]).contains("truncated: a NIfTI-1 header is 348 bytes, the file has 200"));
        let e = err(&good[..good.len() - 1]);
        assert!(
            e.contains(
                "2x2x2 of int16 need 16 bytes of data from byte 352: the data stop after 15 of 16 bytes \
                 (truncated?)"
            ),
            "{e}"
        );
        let mut long = good.clone();
        long.push(0);
        assert!(err(&long).contains("16 bytes of data expected, and 1 more follow"), "{}", err(&long));
        let mut bad = good.clone();
        bad[0] = 7;
        assert!(err(&bad).contains("not a NIfTI-1 file: sizeof_hdr reads"), "{}", err(&bad));
        let mut bad = good.clone();
        bad[..4].copy_from_slice(&540i32.to_le_bytes());
        assert!(err(&bad).contains("NIfTI-2"), "{}", err(&bad));
        let mut bad = good.clone();
        bad[344..348].copy_from_slice(b"\0\0\0\0");
        assert!(err(&bad).contains("Analyze"), "{}", err(&bad));
        let mut bad = good.clone();
        bad[344..348].copy_from_slice(b"ni1\0");
        assert!(err(&bad).contains("separate .img"), "{}", err(&bad));
        let mut bad = good.clone();
        bad[70..72].copy_from_slice(&32i16.to_le_bytes()); // complex64
        assert!(err(&bad).contains("Complex64 (datatype 32) is not supported"), "{}", err(&bad));
        let mut bad = good.clone();
        bad[70..72].copy_from_slice(&3i16.to_le_bytes());
        assert!(err(&bad).contains("datatype 3 is not a NIfTI-1 data type"), "{}", err(&bad));
        let mut bad = good.clone();
        bad[44..46].copy_from_slice(&0i16.to_le_bytes());
        assert!(err(&bad).contains("dim[2] is 0"), "{}", err(&bad));
        let mut bad = good.clone();
        bad[44..46].copy_from_slice(&(-5i16).to_le_bytes());
        assert!(err(&bad).contains("dim[2] is -5"), "{}", err(&bad));
        let mut bad = good.clone();
        bad[40..42].copy_from_slice(&0i16.to_le_bytes());
        assert!(err(&bad).contains("dim[0] is 0"), "{}", err(&bad));
        // dim[0] 9 reads as a byte-swapped header to the crate; sizeof_hdr says otherwise.
        let mut bad = good.clone();
        bad[40..42].copy_from_slice(&9i16.to_le_bytes());
        assert!(err(&bad).contains("dim[0] is 9; it must be 1 to 7"), "{}", err(&bad));
        let mut bad = good.clone();
        bad[108..112].copy_from_slice(&f32::NAN.to_le_bytes());
        assert!(err(&bad).contains("vox_offset NaN"), "{}", err(&bad));
        let mut bad = good;
        bad[108..112].copy_from_slice(&1e9f32.to_le_bytes());
        assert!(err(&bad).contains("vox_offset 1000000000"), "{}", err(&bad));
    }

    #[test]
    fn huge_extents_do_not_allocate() {
        let f = file(
            &[32767, 32767, 32767, 32767, 32767, 32767, 32767],
            64,
            64,
            [1.0; 3],
            (0.0, 0.0),
            b"n+1\0",
            false,
            &[],
        );
        let e = err(&f);
        assert!(e.contains("overflow") || e.contains("need"), "{e}");
    }

    #[test]
    fn gzip_and_header_pairs_from_disk() {
        use std::io::Write;
        let dir = std::env::temp_dir().join(format!("isoscope-nifti-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = file(&[2, 1, 1], 2, 8, [1.0; 3], (0.0, 0.0), b"n+1\0", false, &[5, 6]);
        let mut z = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
        z.write_all(&f).unwrap();
        let gz = dir.join("a.nii.gz");
        std::fs::write(&gz, z.finish().unwrap()).unwrap();
        assert_eq!(read(&gz, &Options::default()).unwrap().volume.samples, Samples::U8(vec![5, 6]));
        // A pair: the header (352 bytes, magic ni1, vox_offset 0) and the image.
        let mut hdr = file(&[2, 1, 1], 2, 8, [1.0; 3], (0.0, 0.0), b"ni1\0", false, &[]);
        hdr[108..112].copy_from_slice(&0f32.to_le_bytes());
        std::fs::write(dir.join("b.hdr"), &hdr).unwrap();
        let e = format!("{:#}", read(&dir.join("b.hdr"), &Options::default()).unwrap_err());
        assert!(e.contains("b.img"), "{e}");
        std::fs::write(dir.join("b.img"), [9u8, 8]).unwrap();
        assert_eq!(
            read(&dir.join("b.hdr"), &Options::default()).unwrap().volume.samples,
            Samples::U8(vec![9, 8])
        );
        std::fs::write(dir.join("b.img"), [9u8]).unwrap();
        let e = format!("{:#}", read(&dir.join("b.hdr"), &Options::default()).unwrap_err());
        assert!(e.contains("truncated") && e.contains("b.img"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Set a little-endian header's sform (rows `srow`, code `code`).
    fn set_sform(f: &mut [u8], code: i16, srow: [[f32; 4]; 3]) {
        f[254..256].copy_from_slice(&code.to_le_bytes());
        for (r, row) in srow.iter().enumerate() {
            for (c, v) in row.iter().enumerate() {
                let at = 280 + 16 * r + 4 * c;
                f[at..at + 4].copy_from_slice(&v.to_le_bytes());
            }
        }
    }

    /// Set a little-endian header's qform (quaternion b, c, d; code 1).
    fn set_qform(f: &mut [u8], q: [f32; 3]) {
        f[252..254].copy_from_slice(&1i16.to_le_bytes());
        for (i, v) in q.iter().enumerate() {
            f[256 + 4 * i..260 + 4 * i].copy_from_slice(&v.to_le_bytes());
        }
    }

    /// The reference volume in RAS order, 3x4x5 (i right, j anterior, k
    /// superior), voxels 1 x 2 x 3 mm: value i + 3 (j + 4 k) at (i, j, k).
    fn ras_value(i: usize, j: usize, k: usize) -> u8 {
        (i + 3 * (j + 4 * k)) as u8
    }

    /// The reference stored along other axes: i' posterior (reversed j),
    /// j' superior (k), k' left (reversed i): 4x5x3.
    fn permuted_data() -> Vec<u8> {
        let mut v = Vec::new();
        for c in 0..3 {
            for b in 0..5 {
                for a in 0..4 {
                    v.push(ras_value(2 - c, 3 - a, b));
                }
            }
        }
        v
    }

    /// Shown as a face: x left (reversed i), y superior (k), z anterior (j).
    fn shown_as_a_face() -> LoadedVolume {
        let mut v = Vec::new();
        for z in 0..4 {
            for y in 0..5 {
                for x in 0..3 {
                    v.push(ras_value(2 - x, z, y));
                }
            }
        }
        LoadedVolume { dims: Dims(3, 5, 4), samples: Samples::U8(v), spacing: [1.0, 3.0, 2.0] }
    }

    /// The same head stored in RAS order with an sform, along permuted and
    /// reversed axes with an sform, and so with a qform only: each loads as
    /// the same volume, upright and facing the viewer; `Index` keeps the
    /// file's order.
    #[test]
    fn permuted_and_flipped_forms_load_as_the_ras_reference() {
        let ras: Vec<u8> = (0..60).collect();
        let mut reference = file(&[3, 4, 5], 2, 8, [1.0, 2.0, 3.0], (0.0, 0.0), b"n+1\0", false, &ras);
        set_sform(&mut reference, 2, [[1.0, 0.0, 0.0, -1.0], [0.0, 2.0, 0.0, -3.0], [0.0, 0.0, 3.0, -6.0]]);
        let mut by_sform =
            file(&[4, 5, 3], 2, 8, [2.0, 3.0, 1.0], (0.0, 0.0), b"n+1\0", false, &permuted_data());
        let mut by_qform = by_sform.clone();
        set_sform(&mut by_sform, 1, [[0.0, 0.0, -1.0, 1.0], [-2.0, 0.0, 0.0, 3.0], [0.0, 3.0, 0.0, -6.0]]);
        // The rotation taking i' to -y, j' to z, k' to -x: a = 1/2, (b, c, d) = (1/2, -1/2, -1/2).
        set_qform(&mut by_qform, [0.5, -0.5, -0.5]);
        let want = shown_as_a_face();
        for (name, f, what) in
            [("reference", &reference, "sform"), ("sform", &by_sform, "sform"), ("qform", &by_qform, "qform")]
        {
            let l = parse(f, &Options::default()).unwrap();
            assert_eq!(l.volume, want, "{name}");
            assert!(
                l.notes.iter().any(|n| n.starts_with(&format!("oriented by the {what}: x = "))),
                "{name}: {:?}",
                l.notes
            );
        }
        let index = Options { orientation: super::super::Orientation::Index, ..Options::default() };
        let l = parse(&by_sform, &index).unwrap();
        assert_eq!((l.volume.dims, l.volume.spacing), (Dims(4, 5, 3), [2.0, 3.0, 1.0]));
        assert_eq!(l.volume.samples, Samples::U8(permuted_data()));
        assert!(l.notes.is_empty(), "{:?}", l.notes);
        // Without either form: the index axes.
        let plain = file(&[4, 5, 3], 2, 8, [2.0, 3.0, 1.0], (0.0, 0.0), b"n+1\0", false, &permuted_data());
        assert_eq!(parse(&plain, &Options::default()).unwrap().volume, l.volume);
        // An sform wins over a qform.
        let mut both = by_qform.clone();
        set_sform(&mut both, 1, [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]]);
        assert_eq!(parse(&both, &Options::default()).unwrap().volume.dims, Dims(4, 3, 5));
    }

    /// NaN, zero, huge or coplanar forms leave the file's order, with a
    /// note saying why, and never panic; so does a flat volume.
    #[test]
    fn hostile_forms_keep_the_index_order() {
        let data: Vec<u8> = (0..60).collect();
        let good = file(&[3, 4, 5], 2, 8, [1.0, 2.0, 3.0], (0.0, 0.0), b"n+1\0", false, &data);
        let nan = f32::NAN;
        for (srow, why) in [
            (
                [[nan, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]],
                "index axis i is not finite",
            ),
            ([[0.0; 4], [0.0; 4], [0.0; 4]], "index axis i is zero"),
            ([[1.0, 0.0, 0.0, 0.0], [0.0, 3e38, 0.0, 0.0], [0.0, 3e38, 1.0, 0.0]], "index axis j is 4.24"),
            ([[1.0, 1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]], "coplanar"),
            ([[f32::INFINITY; 4], [0.0; 4], [0.0; 4]], "not finite"),
        ] {
            let mut f = good.clone();
            set_sform(&mut f, 1, srow);
            let l = parse(&f, &Options::default()).unwrap();
            assert_eq!((l.volume.dims, l.volume.spacing), (Dims(3, 4, 5), [1.0, 2.0, 3.0]), "{why}");
            assert_eq!(l.volume.samples, Samples::U8(data.clone()));
            let note = l.notes.join("; ");
            assert!(note.contains("not oriented by the sform") && note.contains(why), "{why}: {note}");
            assert!(note.contains("shown in the file's index order"), "{note}");
        }
        let mut f = good.clone();
        set_qform(&mut f, [nan, 0.0, 0.0]);
        let note = parse(&f, &Options::default()).unwrap().notes.join("; ");
        assert!(note.contains("not oriented by the qform"), "{note}");
        // A flat volume (one slice) keeps its order, face on.
        let mut flat = file(&[3, 4, 1], 2, 8, [1.0; 3], (0.0, 0.0), b"n+1\0", false, &data[..12]);
        set_sform(&mut flat, 1, [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]]);
        let l = parse(&flat, &Options::default()).unwrap();
        assert_eq!((l.volume.dims, l.volume.samples), (Dims(3, 4, 1), Samples::U8(data[..12].to_vec())));
        assert!(
            l.notes.iter().any(|n| n.contains("a flat volume keeps the file's index order")),
            "{:?}",
            l.notes
        );
    }
}
