//! NRRD (`.nrrd`, or a `.nhdr` header with a detached `data file`): raw,
//! gzip or ASCII encodings, either byte order, 1 to 3 dimensions (more when
//! the extra axes have one sample).
//!
//! The fastest axis comes first in `sizes`, so the data are x fastest
//! already. Types: `uchar` loads as `u8`, `signed char` and `short` as
//! `i16`, `ushort` as `u16`, `float` as `f32`; `int`, `uint`, `longlong`,
//! `ulonglong` and `double` as `f32` with a note (every NRRD spelling of
//! them is understood); `block` is refused. Spacing per axis: the length of
//! its `space directions` vector, else its `spacings` entry, else 1. An axis
//! whose `kinds` entry is not spatial (a vector or colour axis) is refused
//! unless it has one sample. `line skip` and `byte skip` (including
//! `byte skip: -1` for raw data in an uncompressed file) are honoured;
//! `bzip2`, `hex` and the multi-file `data file` forms are refused with a
//! clear error.
//!
//! Orientation ([`super::Orientation::File`], the default): with `space
//! directions` in an anatomical `space` (`RAS`, `LAS`, `LPS`) the volume is
//! rearranged so that a head is upright and faces the viewer, in a plain
//! one (`scanner-xyz`, `3D-right-handed`, `3D-left-handed`, or only `space
//! dimension: 3`) so that its x, y and z are the display's
//! ([`crate::orient`]); the spacing is then the length of each direction.
//!
//! The header is read, then exactly the bytes of data it declares (raw, or
//! gzip inflated as it is read), and nothing may follow; ASCII data are read
//! value by value, at most 64 bytes of text a value.

use super::{
    Elem, Endian, Format, Input, Loaded, Options, TEXT_PER_VALUE, TEXT_SLACK, check_size, decode, oriented,
    parse_text, single_volume, text, voxel_size,
};
use crate::orient::{Directions, Space};
use crate::volume::{Dims, LoadedVolume};
use anyhow::{Context, Result, bail};
use std::collections::HashMap;
use std::path::Path;

/// Read a `.nrrd` (`.nrrd.gz`) or a `.nhdr` (and its data file, relative to
/// its folder).
pub fn read(path: &Path, opts: &Options) -> Result<Loaded> {
    read_from(Input::open(path)?, path.parent(), opts)
}

/// The header: its fields by lower-case name, and whether a blank line
/// ended it (attached data follow).
struct Header {
    fields: HashMap<String, String>,
    has_data: bool,
}

fn header(input: &mut Input<'_>) -> Result<Header> {
    let head = input.peek(64)?;
    let magic = text(head.split(|&c| c == b'\n').next().unwrap_or_default());
    if !(magic.len() == 8 && magic.starts_with("NRRD000") && magic.as_bytes()[7].is_ascii_digit()) {
        bail!(
            "not a NRRD file: it starts with `{}`, not `NRRD0001` to `NRRD0005`",
            magic.chars().take(40).collect::<String>()
        );
    }
    input.line()?;
    let mut fields = HashMap::new();
    let mut line_no = 1;
    while let Some(raw) = input.line()? {
        line_no += 1;
        let line = String::from_utf8_lossy(&raw).into_owned();
        if line.trim().is_empty() {
            // The blank line ends the header; the data follow.
            return Ok(Header { fields, has_data: true });
        }
        let key_value = line.find(":=").is_some_and(|kv| line.find(": ").is_none_or(|f| kv < f));
        if line.starts_with('#') || key_value {
            continue; // a comment, or a key/value pair
        }
        let Some((k, v)) = line.split_once(':') else {
            bail!(
                "header line {line_no}, `{}`, is not `field: value`",
                line.chars().take(60).collect::<String>()
            );
        };
        fields.insert(k.trim().to_ascii_lowercase(), v.trim().to_string());
    }
    Ok(Header { fields, has_data: false })
}

/// The sample type of a NRRD `type:` value.
fn elem(t: &str) -> Result<Elem> {
    let t = t.split_ascii_whitespace().collect::<Vec<_>>().join(" ");
    Ok(match t.as_str() {
        "signed char" | "int8" | "int8_t" => Elem::I8,
        "uchar" | "unsigned char" | "uint8" | "uint8_t" => Elem::U8,
        "short" | "short int" | "signed short" | "signed short int" | "int16" | "int16_t" => Elem::I16,
        "ushort" | "unsigned short" | "unsigned short int" | "uint16" | "uint16_t" => Elem::U16,
        "int" | "signed int" | "int32" | "int32_t" => Elem::I32,
        "uint" | "unsigned int" | "uint32" | "uint32_t" => Elem::U32,
        "longlong"
        | "long long"
        | "long long int"
        | "signed long long"
        | "signed long long int"
        | "int64"
        | "int64_t" => Elem::I64,
        "ulonglong" | "unsigned long long" | "unsigned long long int" | "uint64" | "uint64_t" => Elem::U64,
        "float" => Elem::F32,
        "double" => Elem::F64,
        "block" => bail!("the type `block` is not supported: only numeric types"),
        other => bail!("the type `{other}` is not a NRRD type"),
    })
}

/// Kinds of axis along which samples are positions, not components.
fn spatial_kind(kind: &str) -> bool {
    matches!(kind.to_ascii_lowercase().as_str(), "domain" | "space" | "time" | "???" | "none")
}

/// The vectors of `space directions`: `(x,y,z)` each, or `none`.
fn directions(v: &str) -> Result<Vec<Option<Vec<f64>>>> {
    let mut out = Vec::new();
    let mut rest = v.trim();
    while !rest.is_empty() {
        if let Some(r) = rest.strip_prefix("none") {
            out.push(None);
            rest = r.trim_start();
        } else if let Some(r) = rest.strip_prefix('(') {
            let close =
                r.find(')').with_context(|| format!("`space directions: {v}`: a `(` is not closed"))?;
            let nums: Option<Vec<f64>> = r[..close].split(',').map(|s| s.trim().parse().ok()).collect();
            out.push(Some(
                nums.with_context(|| {
                    format!("`space directions: {v}`: `({})` is not a vector", &r[..close])
                })?,
            ));
            rest = r[close + 1..].trim_start();
        } else {
            bail!("`space directions: {v}` should be vectors like (1,0,0) or `none`");
        }
    }
    Ok(out)
}

/// Decode a NRRD file; a detached data file is looked for in `dir`.
pub fn parse(bytes: &[u8], dir: Option<&Path>, opts: &Options) -> Result<Loaded> {
    read_from(Input::from_slice(bytes), dir, opts)
}

pub(crate) fn read_from(mut input: Input<'_>, dir: Option<&Path>, opts: &Options) -> Result<Loaded> {
    single_volume(opts)?;
    let h = header(&mut input)?;
    let get = |k: &str| h.fields.get(k).map(String::as_str);
    let need_field = |k: &str| get(k).with_context(|| format!("the header has no `{k}:` field"));
    let elem = elem(need_field("type")?)?;
    let dim: usize = need_field("dimension")?
        .parse()
        .with_context(|| format!("`dimension: {}` is not a count", get("dimension").unwrap_or_default()))?;
    if dim == 0 {
        bail!("`dimension: 0`: a volume needs at least one axis");
    }
    let sizes: Vec<usize> = need_field("sizes")?
        .split_ascii_whitespace()
        .map(str::parse)
        .collect::<Result<_, _>>()
        .with_context(|| format!("`sizes: {}` are not counts", get("sizes").unwrap_or_default()))?;
    if sizes.len() != dim {
        bail!(
            "`sizes: {}` has {} entries but `dimension: {dim}`",
            get("sizes").unwrap_or_default(),
            sizes.len()
        );
    }
    if sizes.contains(&0) {
        bail!("`sizes: {}`: every size must be at least 1", get("sizes").unwrap_or_default());
    }
    let kinds: Vec<&str> = get("kinds").map(|k| k.split_ascii_whitespace().collect()).unwrap_or_default();
    if let Some(i) = (0..dim).find(|&i| sizes[i] > 1 && kinds.get(i).is_some_and(|k| !spatial_kind(k))) {
        bail!(
            "axis {i} is of kind `{}` with {} samples, not a spatial axis: only scalar volumes are supported",
            kinds[i],
            sizes[i]
        );
    }
    if dim > 3 && sizes[3..].iter().any(|&s| s > 1) {
        bail!(
            "`sizes: {}`: a {dim}-dimensional NRRD is not a volume (only 1 to 3 axes with more than one sample)",
            get("sizes").unwrap_or_default()
        );
    }
    let n = [0, 1, 2].map(|i| sizes.get(i).copied().unwrap_or(1));

    let mut spacing = [1.0f32; 3];
    let mut axes = None;
    if let Some(d) = get("space directions") {
        let dirs = directions(d)?;
        if dirs.len() != dim {
            bail!("`space directions: {d}` has {} entries but `dimension: {dim}`", dirs.len());
        }
        for (s, v) in spacing.iter_mut().zip(&dirs) {
            if let Some(v) = v {
                *s = voxel_size(v.iter().map(|x| x * x).sum::<f64>().sqrt());
            }
        }
        axes = space(get("space"), get("space dimension")).and_then(|sp| orientation(sp, &dirs));
    } else if let Some(sp) = get("spacings") {
        for (s, v) in spacing.iter_mut().zip(sp.split_ascii_whitespace()) {
            *s = voxel_size(v.parse().unwrap_or(f64::NAN));
        }
    }

    let encoding = need_field("encoding")?.to_ascii_lowercase();
    let encoding = match encoding.as_str() {
        "raw" => Encoding::Raw,
        "gzip" | "gz" => Encoding::Gzip,
        "ascii" | "text" | "txt" => Encoding::Ascii,
        "bzip2" | "bz2" => {
            bail!("bzip2-encoded data are not supported: use raw or gzip (`unu save -e gzip`)")
        }
        e => bail!("the encoding `{e}` is not supported: only raw, gzip and ascii"),
    };
    let endian = match get("endian").map(str::to_ascii_lowercase).as_deref() {
        Some("little") => Endian::Little,
        Some("big") => Endian::Big,
        Some(e) => bail!("`endian: {e}` should be `little` or `big`"),
        None if elem.size() == 1 || encoding == Encoding::Ascii => Endian::Little,
        None => bail!("the header has no `endian:` field, which {} data need", elem.name()),
    };
    let line_skip: usize = match get("line skip").or(get("lineskip")) {
        Some(v) => v.parse().with_context(|| format!("`line skip: {v}` is not a count"))?,
        None => 0,
    };
    let byte_skip: i64 = match get("byte skip").or(get("byteskip")) {
        Some(v) => v.parse().with_context(|| format!("`byte skip: {v}` is not a whole number"))?,
        None => 0,
    };
    if byte_skip < -1 {
        bail!("`byte skip: {byte_skip}`: only -1 (data at the end) or a count is allowed");
    }
    if byte_skip == -1 && encoding != Encoding::Raw {
        bail!("`byte skip: -1` is only allowed with raw encoding");
    }
    if usize::try_from(byte_skip).is_ok_and(|b| b > opts.max_bytes) {
        bail!("`byte skip: {byte_skip}` is more than the limit of {} bytes", opts.max_bytes);
    }
    let need = check_size(&n, elem, opts.max_bytes)?;

    // The data: attached after the blank line, or in a detached file.
    let mut data = match get("data file").or(get("datafile")) {
        Some(name) => {
            if name.starts_with("LIST") || name.split_ascii_whitespace().count() > 1 {
                bail!("`data file: {name}`: data in several files are not supported");
            }
            let dir = dir.context("the data are in a detached file, but the header's folder is not known")?;
            Input::open_plain(&dir.join(name)).context("cannot read the header's data file")?
        }
        None if !h.has_data => bail!(
            "the file has no data: the header is not followed by a blank line and data, nor has a `data file:`"
        ),
        None => input,
    };
    for i in 0..line_skip {
        if data.line()?.is_none() {
            bail!("the data are truncated: `line skip: {line_skip}` but only {i} lines");
        }
    }
    let shape = n.map(|v| v.to_string()).join("x");
    let what = format!("{shape} {} samples", elem.name());
    let samples = match encoding {
        Encoding::Raw | Encoding::Gzip => {
            if encoding == Encoding::Gzip {
                data = data.gunzip_rest();
            }
            let skip = match usize::try_from(byte_skip) {
                Ok(b) => b,
                // -1: the data are the last bytes of the file.
                Err(_) => usize::try_from(data.remaining().context(
                    "`byte skip: -1` needs to know where the data file ends, and this one is not a regular file",
                )?)
                .unwrap_or(usize::MAX)
                .saturating_sub(need),
            };
            let mut bytes = data.data(skip.saturating_add(need));
            let body = bytes
                .skip(skip as u64)
                .and_then(|()| bytes.take(need))
                .and_then(|b| bytes.finish().map(|()| b))
                .with_context(|| {
                    format!(
                        "{what} need {need} bytes{}{}",
                        if encoding == Encoding::Gzip { " of gzip-encoded data" } else { "" },
                        if skip > 0 { format!(" after a byte skip of {skip}") } else { String::new() },
                    )
                })?;
            decode(body, elem, endian)
        }
        Encoding::Ascii => {
            let count = n[0] * n[1] * n[2];
            data.allow_text(
                (count as u64).saturating_mul(TEXT_PER_VALUE).saturating_add(TEXT_SLACK),
                format!("{count} values take"),
            );
            let s = parse_text(&mut data, true, count, (0, 1), elem, &format!("data ({what})"))?;
            if data.token(&mut String::new(), true)? {
                bail!("the ASCII data hold more values than {what}");
            }
            s
        }
    };
    let loaded = Loaded {
        volume: LoadedVolume { dims: Dims(n[0], n[1], n[2]), samples, spacing },
        format: Format::Nrrd,
        notes: elem.note().into_iter().collect(),
    };
    Ok(oriented(loaded, axes.map(|a| (a, "space directions")), opts))
}

/// A NRRD space of three dimensions: anatomical (`RAS`, `LAS`, `LPS`, or
/// spelt out, in any case), with the signs that take its coordinates to
/// RAS+; or plain (`scanner-xyz`, `3D-right-handed`, `3D-left-handed`, or
/// no `space` but `space dimension: 3`). `None` for any other (the spaces
/// with time have four dimensions).
fn space(space: Option<&str>, dimension: Option<&str>) -> Option<(Space, [f64; 3])> {
    let Some(name) = space else {
        return (dimension.map(str::trim) == Some("3")).then_some((Space::Xyz, [1.0; 3]));
    };
    Some(match name.trim().to_ascii_lowercase().as_str() {
        "ras" | "right-anterior-superior" => (Space::Ras, [1.0, 1.0, 1.0]),
        "las" | "left-anterior-superior" => (Space::Ras, [-1.0, 1.0, 1.0]),
        "lps" | "left-posterior-superior" => (Space::Ras, [-1.0, -1.0, 1.0]),
        "scanner-xyz" | "3d-right-handed" | "3d-left-handed" => (Space::Xyz, [1.0; 3]),
        _ => return None,
    })
}

/// The directions of the first three axes in `space`, when each is a
/// vector of three components (a `none`, another count, or fewer than
/// three axes: no orientation).
fn orientation((space, sign): (Space, [f64; 3]), dirs: &[Option<Vec<f64>>]) -> Option<Directions> {
    let mut columns = [[0f64; 3]; 3];
    for (col, d) in columns.iter_mut().zip(dirs.get(..3)?) {
        let v: [f64; 3] = d.as_deref()?.try_into().ok()?;
        *col = [v[0] * sign[0], v[1] * sign[1], v[2] * sign[2]];
    }
    Some(Directions { space, columns })
}

/// How the data are stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Encoding {
    Raw,
    Gzip,
    Ascii,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::volume::Samples;
    use std::io::Write;

    fn nrrd(fields: &str, data: &[u8]) -> Vec<u8> {
        let mut f = format!("NRRD0004\n# a comment\n{fields}\n").into_bytes();
        f.extend_from_slice(data);
        f
    }

    fn load(bytes: &[u8]) -> Loaded {
        parse(bytes, None, &Options::default()).unwrap()
    }

    fn err(bytes: &[u8]) -> String {
        format!("{:#}", parse(bytes, None, &Options::default()).unwrap_err())
    }

    fn gz(data: &[u8]) -> Vec<u8> {
        let mut z = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
        z.write_all(data).unwrap();
        z.finish().unwrap()
    }

    const U8: &str = "type: uchar\ndimension: 3\nsizes: 2 3 4\nencoding: raw\n";

    #[test]
    fn raw_u8_fastest_axis_first() {
        let data: Vec<u8> = (0..24).collect();
        let l = load(&nrrd(&format!("{U8}spacings: 0.5 1 -2\nkey:=value: x\ncontent: a:=b\n"), &data));
        assert_eq!(l.format, Format::Nrrd);
        assert_eq!(l.volume.dims, Dims(2, 3, 4));
        assert_eq!(l.volume.spacing, [0.5, 1.0, 2.0]);
        assert_eq!(l.volume.samples, Samples::U8(data));
        assert!(l.notes.is_empty());
    }

    #[test]
    fn gzip_big_endian_int16_with_space_directions() {
        let v = [-1i16, 2, 300, -400, 5, 6];
        let be: Vec<u8> = v.iter().flat_map(|x| x.to_be_bytes()).collect();
        let f = nrrd(
            "type: short\ndimension: 3\nspace: RAS\nsizes: 3 2 1\nspace directions: (0,0.5,0) (3,4,0) (0,0,1.5)\n\
             endian: big\nencoding: gzip\nspace origin: (0,0,0)\n",
            &gz(&be),
        );
        let l = load(&f);
        assert_eq!(l.volume.dims, Dims(3, 2, 1));
        assert_eq!(l.volume.spacing, [0.5, 5.0, 1.5]);
        assert_eq!(l.volume.samples, Samples::I16(v.to_vec()));
    }

    #[test]
    fn every_type_spelling() {
        for (t, bytes, want) in [
            ("signed char", vec![0xff], Samples::I16(vec![-1])),
            ("int8_t", vec![0x80], Samples::I16(vec![-128])),
            ("unsigned char", vec![200], Samples::U8(vec![200])),
            ("unsigned short int", vec![1, 2], Samples::U16(vec![0x0201])),
            ("int16", vec![0, 0x80], Samples::I16(vec![i16::MIN])),
            ("float", 2.5f32.to_le_bytes().to_vec(), Samples::F32(vec![2.5])),
            ("int", (-5i32).to_le_bytes().to_vec(), Samples::F32(vec![-5.0])),
            ("unsigned   int", 5u32.to_le_bytes().to_vec(), Samples::F32(vec![5.0])),
            ("long long", (-6i64).to_le_bytes().to_vec(), Samples::F32(vec![-6.0])),
            ("ulonglong", 6u64.to_le_bytes().to_vec(), Samples::F32(vec![6.0])),
            ("double", 0.5f64.to_le_bytes().to_vec(), Samples::F32(vec![0.5])),
        ] {
            let f =
                nrrd(&format!("type: {t}\ndimension: 1\nsizes: 1\nendian: little\nencoding: raw\n"), &bytes);
            let l = load(&f);
            assert_eq!(l.volume.samples, want, "{t}");
            assert_eq!(l.volume.dims, Dims(1, 1, 1));
            assert_eq!(
                !l.notes.is_empty(),
                matches!(t, "int" | "unsigned   int" | "long long" | "ulonglong" | "double"),
                "{t}"
            );
        }
    }

    #[test]
    fn ascii_skips_and_trailing_unit_axes() {
        let f = nrrd(
            "type: float\ndimension: 4\nsizes: 2 2 1 1\nencoding: ascii\nkinds: space space space time\n",
            b"1 2\n3, 4.5\n",
        );
        let l = load(&f);
        assert_eq!(l.volume.dims, Dims(2, 2, 1));
        assert_eq!(l.volume.samples, Samples::F32(vec![1.0, 2.0, 3.0, 4.5]));
        // line skip and byte skip, raw.
        let f = nrrd(
            "type: uchar\ndimension: 2\nsizes: 2 1\nencoding: raw\nline skip: 1\nbyte skip: 2\n",
            b"junk\nxx\x07\x08",
        );
        assert_eq!(load(&f).volume.samples, Samples::U8(vec![7, 8]));
        // byte skip -1: the data are the last bytes.
        let f = nrrd(
            "type: uchar\ndimension: 2\nsizes: 2 1\nencoding: raw\nbyte skip: -1\n",
            b"whatever\x07\x08",
        );
        assert_eq!(load(&f).volume.samples, Samples::U8(vec![7, 8]));
        // byte skip after gzip inflation.
        let f =
            nrrd("type: uchar\ndimension: 1\nsizes: 2\nencoding: gz\nbyte skip: 3\n", &gz(b"abc\x01\x02"));
        assert_eq!(load(&f).volume.samples, Samples::U8(vec![1, 2]));
    }

    #[test]
    fn detached_header_from_disk() {
        let dir = std::env::temp_dir().join(format!("isoscope-nrrd-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("v.raw"), [1u8, 2, 3, 4]).unwrap();
        let hdr = dir.join("v.nhdr");
        std::fs::write(
            &hdr,
            "NRRD0004\ntype: uchar\ndimension: 2\nsizes: 2 2\nencoding: raw\ndata file: v.raw\n",
        )
        .unwrap();
        let l = read(&hdr, &Options::default()).unwrap();
        assert_eq!((l.volume.dims, l.volume.samples), (Dims(2, 2, 1), Samples::U8(vec![1, 2, 3, 4])));
        std::fs::write(dir.join("v.raw"), [1u8, 2, 3]).unwrap();
        let e = format!("{:#}", read(&hdr, &Options::default()).unwrap_err());
        assert!(e.contains("need 4 bytes: the data stop after 3 of 4 bytes (truncated?)"), "{e}");
        std::fs::remove_file(dir.join("v.raw")).unwrap();
        let e = format!("{:#}", read(&hdr, &Options::default()).unwrap_err());
        assert!(e.contains("cannot read the header's data file") && e.contains("v.raw"), "{e}");
        let e = format!("{:#}", parse(&std::fs::read(&hdr).unwrap(), None, &Options::default()).unwrap_err());
        assert!(e.contains("folder is not known"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// The data are read to the header's sizes and no further: text data
    /// with blanks without end stop, skips are bounded, and a whole
    /// gzip-compressed file is inflated as it is read.
    #[test]
    fn data_are_read_to_their_sizes_and_no_further() {
        let mut f = nrrd("type: float\ndimension: 1\nsizes: 2\nencoding: ascii\n", b"1 2");
        f.extend_from_slice(&vec![b' '; 200_000]);
        let e = err(&f);
        assert!(e.contains("text runs on for more than") && e.contains("more than 2 values take"), "{e}");
        let f = nrrd("type: uchar\ndimension: 1\nsizes: 2\nencoding: raw\nbyte skip: 100\n", &[0; 102]);
        let e = format!(
            "{:#}",
            parse(&f, None, &Options { index: 0, max_bytes: 10, ..Options::default() }).unwrap_err()
        );
        assert!(e.contains("`byte skip: 100` is more than the limit of 10 bytes"), "{e}");
        let e = format!(
            "{:#}",
            parse(&nrrd(U8, &[0; 24]), None, &Options { index: 0, max_bytes: 23, ..Options::default() })
                .unwrap_err()
        );
        assert!(e.contains("2x3x4 uint8 samples take 24 bytes, more than the limit of 23 bytes"), "{e}");
        // A header without end.
        let mut f = b"NRRD0004\n".to_vec();
        f.extend_from_slice(&b"# a comment\n".repeat(400_000));
        assert!(err(&f).contains("more than a header takes"), "{}", err(&f));
        // A .nrrd.gz; `byte skip: -1` needs the length, which gzip does not give.
        let dir = std::env::temp_dir().join(format!("isoscope-nrrd-gz-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("v.nrrd.gz");
        std::fs::write(&path, gz(&nrrd(U8, &[9; 24]))).unwrap();
        assert_eq!(read(&path, &Options::default()).unwrap().volume.samples, Samples::U8(vec![9; 24]));
        let skip = nrrd("type: uchar\ndimension: 1\nsizes: 2\nencoding: raw\nbyte skip: -1\n", b"xx\x01\x02");
        std::fs::write(&path, gz(&skip)).unwrap();
        let e = format!("{:#}", read(&path, &Options::default()).unwrap_err());
        assert!(e.contains("`byte skip: -1` needs to know where the data file ends"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn bad_files_are_clear_errors() {
        let data = [0u8; 24];
        let good = nrrd(U8, &data);
        assert!(
            err(&good[..good.len() - 1]).contains(
                "2x3x4 uint8 samples need 24 bytes: the data stop after 23 of 24 bytes (truncated?)"
            )
        );
        let mut long = good.clone();
        long.push(0);
        assert!(err(&long).contains("24 bytes of data expected, and 1 more follow"), "{}", err(&long));
        assert!(err(b"P5\n").contains("not a NRRD file: it starts with `P5`"));
        assert!(
            err(&nrrd("type: uchar\ndimension: 3\nencoding: raw\n", &data)).contains("no `sizes:` field")
        );
        assert!(
            err(&nrrd("type: quad\ndimension: 1\nsizes: 1\nencoding: raw\n", &data))
                .contains("`quad` is not a NRRD type")
        );
        assert!(
            err(&nrrd("type: block\ndimension: 1\nsizes: 1\nencoding: raw\n", &data))
                .contains("`block` is not supported")
        );
        assert!(
            err(&nrrd("type: short\ndimension: 1\nsizes: 1\nencoding: raw\n", &data))
                .contains("no `endian:` field")
        );
        assert!(
            err(&nrrd("type: uchar\ndimension: 2\nsizes: 2 3 4\nencoding: raw\n", &data))
                .contains("3 entries but `dimension: 2`")
        );
        assert!(
            err(&nrrd("type: uchar\ndimension: 3\nsizes: 2 0 4\nencoding: raw\n", &data))
                .contains("at least 1")
        );
        assert!(
            err(&nrrd("type: uchar\ndimension: 3\nsizes: 2 x 4\nencoding: raw\n", &data))
                .contains("are not counts")
        );
        assert!(
            err(&nrrd(&format!("{U8}kinds: RGB-color space space\n"), &data))
                .contains("axis 0 is of kind `RGB-color`")
        );
        assert!(
            err(&nrrd("type: uchar\ndimension: 4\nsizes: 2 3 2 2\nencoding: raw\n", &data))
                .contains("4-dimensional")
        );
        assert!(
            err(&nrrd("type: uchar\ndimension: 3\nsizes: 2 3 4\nencoding: bzip2\n", &data))
                .contains("bzip2-encoded data are not supported")
        );
        assert!(
            err(&nrrd("type: uchar\ndimension: 3\nsizes: 2 3 4\nencoding: hex\n", &data))
                .contains("`hex` is not supported")
        );
        assert!(
            err(&nrrd("type: uchar\ndimension: 3\nsizes: 2 3 4\nencoding: gzip\n", &data))
                .contains("cannot gunzip: the gzip data are corrupt or cut short")
        );
        let z = gz(&data);
        assert!(
            err(&nrrd("type: uchar\ndimension: 3\nsizes: 2 3 4\nencoding: gzip\n", &z[..z.len() - 9]))
                .contains("cannot gunzip: the gzip data are corrupt or cut short")
        );
        let e = err(&nrrd("type: uchar\ndimension: 3\nsizes: 2 3 5\nencoding: gzip\n", &z));
        assert!(
            e.contains(
                "2x3x5 uint8 samples need 30 bytes of gzip-encoded data: the data stop after 24 of 30"
            ),
            "{e}"
        );
        assert!(err(&nrrd(&format!("{U8}space directions: (1,0,0) (0,1,0)\n"), &data)).contains("2 entries"));
        assert!(
            err(&nrrd(&format!("{U8}space directions: (1,0,0) (0,1 none\n"), &data)).contains("not closed")
        );
        assert!(
            err(&nrrd(&format!("{U8}space directions: (1,0,0) (0,a,0) none\n"), &data))
                .contains("not a vector")
        );
        assert!(err(&nrrd(&format!("{U8}data file: LIST\n"), &data)).contains("several files"));
        let e = format!("{:#}", parse(&good, None, &Options { index: 1, ..Options::default() }).unwrap_err());
        assert!(e.contains("holds one volume; volume 1 was asked for"), "{e}");
        assert!(
            err(&nrrd("type: float\ndimension: 1\nsizes: 3\nencoding: ascii\n", b"1 2"))
                .contains("truncated: 2 of 3")
        );
        assert!(
            err(&nrrd("type: float\ndimension: 1\nsizes: 1\nencoding: ascii\n", b"1 2"))
                .contains("more values")
        );
        assert!(err(b"NRRD0004\ntype: uchar\nsizes 3\n\n").contains("`sizes 3`, is not `field: value`"));
        assert!(
            err(b"NRRD0004\ntype: uchar\ndimension: 1\nsizes: 3\nencoding: raw\n").contains("has no data")
        );
        // Huge sizes: an error, not an allocation.
        let e = err(&nrrd(
            "type: double\ndimension: 3\nsizes: 100000 100000 100000\nendian: little\nencoding: gzip\n",
            &z,
        ));
        assert!(
            e.contains("take 8000000000000000 bytes (7629394531.2 MiB), more than the limit of 2048 MiB"),
            "{e}"
        );
        assert!(err(&nrrd("type: double\ndimension: 3\nsizes: 10000000000 10000000000 10000000000\nendian: big\nencoding: raw\n", &z)).contains("overflow"));
    }

    /// A 2x3x4 volume in RAS order (i right, j anterior, k superior) given
    /// in LPS, RAS and in a plain space along permuted axes: the anatomical
    /// ones load upright and facing the viewer (x = -i, y = k, z = j), the
    /// plain one with its x, y, z along the display's; `Index` and spaces
    /// the reader does not know keep the file's order.
    #[test]
    fn space_directions_orient_the_volume() {
        let data: Vec<u8> = (0..24).collect();
        let head = |space: &str, dirs: &str| nrrd(&format!("{U8}{space}space directions: {dirs}\n"), &data);
        let mut face = Vec::new();
        for z in 0..3 {
            for y in 0..4 {
                for x in 0..2 {
                    face.push((1 - x) + 2 * (z + 3 * y) as u8);
                }
            }
        }
        let face = LoadedVolume { dims: Dims(2, 4, 3), samples: Samples::U8(face), spacing: [0.5, 3.0, 2.0] };
        for f in [
            head("space: RAS\n", "(0.5,0,0) (0,2,0) (0,0,3)"),
            head("space: left-posterior-superior\n", "(-0.5,0,0) (0,-2,0) (0,0,3)"),
            head("space: LAS\n", "(-0.5,0,0) (0,2,0) (0,0,3)"),
        ] {
            let l = load(&f);
            assert_eq!(l.volume, face);
            assert_eq!(
                l.notes,
                ["oriented by the space directions: x = -i (left), y = k (superior), z = j (anterior) \
                  (--orientation index keeps the file's order)"]
            );
        }
        // Plain space: i along y, j along z, k along x.
        let l = load(&head("space: scanner-xyz\n", "(0,1,0) (0,0,1) (1,0,0)"));
        assert_eq!((l.volume.dims, l.volume.spacing), (Dims(4, 2, 3), [1.0; 3]));
        let Samples::U8(v) = &l.volume.samples else { panic!() };
        // Display (x, y, z) is file (y, z, x).
        assert_eq!((v[0], v[1], v[4 * 2]), (0, 6, 2), "{v:?}");
        assert!(l.notes[0].contains("x = k (+x), y = i (+y), z = j (+z)"), "{:?}", l.notes);
        let l = load(&head("space dimension: 3\n", "(0,1,0) (0,0,1) (1,0,0)"));
        assert_eq!(l.volume.dims, Dims(4, 2, 3));
        // Index order, an unknown space, time, or a missing vector: as stored.
        let index = Options { orientation: super::super::Orientation::Index, ..Options::default() };
        let f = head("space: RAS\n", "(0.5,0,0) (0,2,0) (0,0,3)");
        assert_eq!(parse(&f, None, &index).unwrap().volume.dims, Dims(2, 3, 4));
        for f in [
            head("space: RAST\n", "(1,0,0,0) (0,1,0,0) (0,0,1,0)"),
            head("space: nowhere\n", "(0,1,0) (0,0,1) (1,0,0)"),
            head("", "(0,1,0) (0,0,1) (1,0,0)"),
            head("space dimension: 2\n", "(0,1) (1,0) (1,1)"),
        ] {
            let l = load(&f);
            assert_eq!(l.volume.dims, Dims(2, 3, 4));
            assert!(l.notes.is_empty(), "{:?}", l.notes);
        }
        // Coplanar directions: the file's order, and why.
        let l = load(&head("space: LPS\n", "(1,0,0) (0,1,0) (1,1,0)"));
        assert_eq!(l.volume.dims, Dims(2, 3, 4));
        assert!(
            l.notes[0].contains("not oriented by the space directions") && l.notes[0].contains("coplanar")
        );
    }
}
