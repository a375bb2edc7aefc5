//! VTK legacy files (`.vtk`, gzip compressed or not) holding a
//! `STRUCTURED_POINTS` dataset, ASCII or binary (big-endian), versions 1 to
//! 5.1.
//!
//! `DIMENSIONS`, `SPACING` (or `ASPECT_RATIO`) and `ORIGIN` give the grid;
//! the data are x fastest already. The volume is a one-component array of
//! the `POINT_DATA` section: a `SCALARS` array or a `FIELD` array with one
//! value per point, the first by default, [`Options::index`] to pick
//! another. Every other section (cell data, lookup tables, vectors, normals,
//! tensors, texture coordinates, field data, metadata) is skipped. Types:
//! `unsigned_char` loads as `u8`, `char` and `short` as `i16`,
//! `unsigned_short` as `u16`, `float` as `f32`; `int`, `unsigned_int`,
//! `long`, `unsigned_long`, `vtktypeint64`, `vtktypeuint64`, `vtkIdType`
//! (written as 4-byte int) and `double` as `f32` with a note.

//!
//! The file is read in order, keyword lines, then each array's data, up to
//! the chosen array and no further (the arrays after it are left unread);
//! ASCII data at most 64 bytes of text a value.

use super::{
    Elem, Endian, Format, HEADER_TEXT, Input, Loaded, Options, TEXT_PER_VALUE, check_size, decode,
    parse_text, text, voxel_size,
};
use crate::volume::{Dims, LoadedVolume, Samples};
use anyhow::{Context, Result, bail};
use std::path::Path;

/// Read a VTK legacy file (gzip compressed or not).
pub fn read(path: &Path, opts: &Options) -> Result<Loaded> {
    read_from(&mut Input::open(path)?, opts)
}

/// Arrays not taken that an error lists, at most.
const LISTED: usize = 32;

/// A VTK data type: a sample type, or packed bits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Ty {
    Elem(Elem),
    Bit,
}

fn data_type(name: &str) -> Result<Ty> {
    Ok(Ty::Elem(match name.to_ascii_lowercase().as_str() {
        "bit" => return Ok(Ty::Bit),
        "unsigned_char" => Elem::U8,
        "char" | "signed_char" => Elem::I8,
        "unsigned_short" => Elem::U16,
        "short" => Elem::I16,
        "unsigned_int" => Elem::U32,
        "int" | "vtkidtype" => Elem::I32,
        "unsigned_long" | "vtktypeuint64" => Elem::U64,
        "long" | "vtktypeint64" => Elem::I64,
        "float" => Elem::F32,
        "double" => Elem::F64,
        other => bail!("the data type `{other}` is not a VTK numeric type"),
    }))
}

/// A name as VTK writes it (`%20` for a space), decoded.
fn unescape(name: &str) -> String {
    let b = name.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%'
            && let Some(v) =
                b.get(i + 1..i + 3).and_then(|h| u8::from_str_radix(std::str::from_utf8(h).ok()?, 16).ok())
        {
            out.push(v);
            i += 3;
            continue;
        }
        out.push(b[i]);
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// Which attribute section the keywords are in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Section {
    None,
    Point(usize),
    Cell(usize),
}

/// One data array met in the file.
struct Array {
    name: String,
    comps: usize,
    ty: Ty,
    total: usize,
    what: String,
}

/// The point arrays that could be the volume, the other arrays (for the
/// error message), and the one chosen (the `index`-th candidate).
struct Arrays {
    index: usize,
    candidates: Vec<String>,
    others: Vec<String>,
    found: Option<(String, Elem, Samples)>,
}

impl Arrays {
    /// Take `a` if it is the chosen candidate (`usable` gives its element
    /// type and the grid when it is a one-component point array),
    /// otherwise skip its data.
    fn offer(
        &mut self,
        r: &mut Reader<'_, '_>,
        section: Section,
        a: Array,
        usable: Option<(Elem, [usize; 3])>,
    ) -> Result<()> {
        match usable {
            Some((e, dims)) => {
                if self.candidates.len() == self.index {
                    check_size(&dims, e, r.max_bytes)?;
                    self.found = Some((a.name.clone(), e, r.values(dims.iter().product(), e, &a.what)?));
                } else {
                    r.skip(a.total, a.ty, &a.what)?;
                }
                self.candidates.push(a.name);
            }
            None => {
                self.other(describe(section, &a.name, a.comps));
                r.skip(a.total, a.ty, &a.what)?;
            }
        }
        Ok(())
    }

    /// Note an array that is not a candidate.
    fn other(&mut self, what: String) {
        if self.others.len() < LISTED {
            self.others.push(what);
        }
    }
}

struct Reader<'i, 'a> {
    input: &'i mut Input<'a>,
    binary: bool,
    max_bytes: usize,
}

impl Reader<'_, '_> {
    /// The next line that is not blank, trimmed.
    fn keyword_line(&mut self) -> Result<Option<String>> {
        while let Some(l) = self.input.line()? {
            let l = text(&l);
            if !l.is_empty() {
                return Ok(Some(l));
            }
        }
        Ok(None)
    }

    /// Whether the next line that is not blank starts with LOOKUP_TABLE
    /// (without taking it: if not, the data start there).
    fn lookup_table_follows(&mut self) -> Result<bool> {
        const KEY: &[u8] = b"LOOKUP_TABLE";
        let head = self.input.peek(256)?;
        let Some(at) = head.iter().position(|c| !c.is_ascii_whitespace()) else { return Ok(false) };
        Ok(head.get(at..at + KEY.len()).is_some_and(|w| w.eq_ignore_ascii_case(KEY))
            && head.get(at + KEY.len()).is_none_or(|c| c.is_ascii_whitespace()))
    }

    /// Allow the text of `count` values (ASCII), and a header's worth of
    /// keyword lines after them.
    fn allow(&mut self, count: usize) {
        let values = if self.binary { 0 } else { count as u64 };
        self.input.allow_text(
            values.saturating_mul(TEXT_PER_VALUE).saturating_add(HEADER_TEXT),
            format!("{values} values and keyword lines take"),
        );
    }

    /// Skip `count` values of type `ty` (what names them in errors).
    fn skip(&mut self, count: usize, ty: Ty, what: &str) -> Result<()> {
        self.allow(count);
        if self.binary {
            let n = match ty {
                Ty::Bit => count.div_ceil(8),
                Ty::Elem(e) => count.checked_mul(e.size()).context("the extents overflow")?,
            };
            let at = self.input.pos();
            self.input.data(n).skip(n as u64).with_context(|| truncated(what, n, at))?;
        } else {
            let mut tok = String::new();
            for i in 0..count {
                if !self.input.token(&mut tok, false)? {
                    bail!("the file is truncated in {what}: {i} of {count} values");
                }
            }
        }
        Ok(())
    }

    /// Read `count` values of `elem`.
    fn values(&mut self, count: usize, elem: Elem, what: &str) -> Result<Samples> {
        self.allow(count);
        if self.binary {
            let n = count.checked_mul(elem.size()).context("the extents overflow")?;
            let at = self.input.pos();
            let bytes = self.input.data(n).take(n).with_context(|| truncated(what, n, at))?;
            Ok(decode(bytes, elem, Endian::Big))
        } else {
            parse_text(self.input, false, count, (0, 1), elem, what)
        }
    }

    /// Skip a `METADATA` block: lines up to a blank one.
    fn skip_metadata(&mut self) -> Result<()> {
        while let Some(l) = self.input.line()? {
            if text(&l).is_empty() {
                break;
            }
        }
        Ok(())
    }
}

/// The error context of binary data cut short.
fn truncated(what: &str, n: usize, at: u64) -> String {
    format!("the file is truncated in {what}: {n} bytes of binary data from byte {at}")
}

/// Words of a keyword line, checked for a count.
fn words<'l>(line: &'l str, min: usize, form: &str) -> Result<Vec<&'l str>> {
    let w: Vec<&str> = line.split_ascii_whitespace().collect();
    if w.len() < min {
        bail!("`{line}` should read `{form}`");
    }
    Ok(w)
}

fn count(word: &str, line: &str) -> Result<usize> {
    word.parse().with_context(|| format!("`{word}` in `{line}` is not a count"))
}

/// Decode a VTK legacy file (already gunzipped).
pub fn parse(bytes: &[u8], opts: &Options) -> Result<Loaded> {
    read_from(&mut Input::from_slice(bytes), opts)
}

pub(crate) fn read_from(input: &mut Input<'_>, opts: &Options) -> Result<Loaded> {
    let head = input.peek(256)?;
    let first = text(head.split(|&c| c == b'\n').next().unwrap_or_default());
    if !first.starts_with("# vtk DataFile Version") {
        bail!(
            "not a VTK legacy file: the first line is `{}`, not `# vtk DataFile Version ...`",
            first.chars().take(60).collect::<String>()
        );
    }
    input.line()?;
    let _title = input.line()?.context("the file is truncated after its first line")?;
    let mut r = Reader { input, binary: false, max_bytes: opts.max_bytes };
    let mode = r.keyword_line()?.context("the file is truncated: no ASCII or BINARY line")?;
    r.binary = match mode.to_ascii_uppercase().as_str() {
        "ASCII" => false,
        "BINARY" => true,
        _ => bail!("line 3 should be ASCII or BINARY, not `{mode}`"),
    };
    let binary = r.binary;
    let dataset = r.keyword_line()?.context("the file is truncated: no DATASET line")?;
    let ds = words(&dataset, 2, "DATASET STRUCTURED_POINTS")?;
    if !ds[0].eq_ignore_ascii_case("DATASET") {
        bail!("expected `DATASET STRUCTURED_POINTS`, found `{dataset}`");
    }
    if !ds[1].eq_ignore_ascii_case("STRUCTURED_POINTS") {
        bail!("the dataset is {}, which is not supported: only STRUCTURED_POINTS", ds[1]);
    }
    let mut dims: Option<[usize; 3]> = None;
    let mut spacing = [1.0f32; 3];
    let mut section = Section::None;
    let mut seen = Arrays { index: opts.index, candidates: Vec::new(), others: Vec::new(), found: None };
    let points = |dims: Option<[usize; 3]>| dims.map(|d| d[0] * d[1] * d[2]);
    while seen.found.is_none() {
        let Some(line) = r.keyword_line()? else { break };
        let at = r.input.line_no() - 1;
        let w = words(&line, 1, "a keyword")?;
        let n_here = match section {
            Section::Point(n) | Section::Cell(n) => n,
            Section::None => 0,
        };
        // A keyword line that the end of the file cuts short is a truncation.
        let cut = r.input.line_was_cut();
        let mut step = || -> Result<()> {
            match w[0].to_ascii_uppercase().as_str() {
                "DIMENSIONS" => {
                    let w = words(&line, 4, "DIMENSIONS NX NY NZ")?;
                    let d = [count(w[1], &line)?, count(w[2], &line)?, count(w[3], &line)?];
                    if d.contains(&0) {
                        bail!("line {at}: `{line}`: every dimension must be at least 1");
                    }
                    d[0].checked_mul(d[1])
                        .and_then(|v| v.checked_mul(d[2]))
                        .context("the DIMENSIONS overflow")?;
                    dims = Some(d);
                }
                "SPACING" | "ASPECT_RATIO" => {
                    let w = words(&line, 4, "SPACING SX SY SZ")?;
                    for i in 0..3 {
                        let v: f64 =
                            w[i + 1].parse().with_context(|| format!("line {at}: `{line}`: not a number"))?;
                        spacing[i] = voxel_size(v);
                    }
                }
                "ORIGIN" => {}
                "POINT_DATA" | "CELL_DATA" => {
                    let w = words(&line, 2, "POINT_DATA N")?;
                    let n = count(w[1], &line)?;
                    if w[0].eq_ignore_ascii_case("POINT_DATA") {
                        let p = points(dims)
                            .with_context(|| format!("line {at}: POINT_DATA comes before DIMENSIONS"))?;
                        if n != p {
                            let d = dims.unwrap_or([0; 3]);
                            bail!(
                                "line {at}: POINT_DATA {n} does not match DIMENSIONS {} {} {} ({p} points)",
                                d[0],
                                d[1],
                                d[2]
                            );
                        }
                        section = Section::Point(n);
                    } else {
                        section = Section::Cell(n);
                    }
                }
                "SCALARS" => {
                    let w = words(&line, 3, "SCALARS NAME TYPE [COMPONENTS]")?;
                    let ty = data_type(w[2]).with_context(|| format!("line {at}"))?;
                    let comps = match w.get(3) {
                        Some(v) => count(v, &line)?,
                        None => 1,
                    };
                    let name = unescape(w[1]);
                    // An optional LOOKUP_TABLE line follows.
                    if r.lookup_table_follows()? {
                        r.keyword_line()?;
                    }
                    let what = format!("SCALARS `{name}` (line {at})");
                    let total = n_here.checked_mul(comps).context("the extents overflow")?;
                    if section == Section::None {
                        bail!("line {at}: SCALARS outside POINT_DATA or CELL_DATA");
                    }
                    let usable = match (section, ty, dims) {
                        (Section::Point(_), Ty::Elem(e), Some(d)) if comps == 1 => Some((e, d)),
                        _ => None,
                    };
                    seen.offer(&mut r, section, Array { name, comps, ty, total, what }, usable)?;
                }
                "FIELD" => {
                    let w = words(&line, 3, "FIELD NAME ARRAYS")?;
                    let arrays = count(w[2], &line)?;
                    let mut i = 0;
                    while i < arrays && seen.found.is_none() {
                        let l = r
                            .keyword_line()?
                            .with_context(|| format!("the file is truncated in FIELD `{}`", w[1]))?;
                        if l.eq_ignore_ascii_case("METADATA") {
                            r.skip_metadata()?;
                            continue;
                        }
                        let a = words(&l, 4, "NAME COMPONENTS TUPLES TYPE")?;
                        let (comps, tuples) = (count(a[1], &l)?, count(a[2], &l)?);
                        let ty = data_type(a[3]).with_context(|| format!("FIELD array `{l}`"))?;
                        let name = unescape(a[0]);
                        let what = format!("FIELD array `{name}`");
                        let total = comps.checked_mul(tuples).context("the extents overflow")?;
                        let usable = match (section, ty, dims) {
                            (Section::Point(n), Ty::Elem(e), Some(d)) if comps == 1 && tuples == n => {
                                Some((e, d))
                            }
                            _ => None,
                        };
                        seen.offer(&mut r, section, Array { name, comps, ty, total, what }, usable)?;
                        i += 1;
                    }
                }
                "METADATA" => r.skip_metadata()?,
                "LOOKUP_TABLE" => {
                    let w = words(&line, 3, "LOOKUP_TABLE NAME SIZE")?;
                    let size = count(w[2], &line)?;
                    let n = size.checked_mul(4).context("the extents overflow")?;
                    r.skip(
                        n,
                        if binary { Ty::Elem(Elem::U8) } else { Ty::Elem(Elem::F32) },
                        "a LOOKUP_TABLE",
                    )?;
                }
                "COLOR_SCALARS" => {
                    let w = words(&line, 3, "COLOR_SCALARS NAME COMPONENTS")?;
                    let n = n_here.checked_mul(count(w[2], &line)?).context("the extents overflow")?;
                    r.skip(
                        n,
                        if binary { Ty::Elem(Elem::U8) } else { Ty::Elem(Elem::F32) },
                        "COLOR_SCALARS",
                    )?;
                }
                k @ ("VECTORS" | "NORMALS" | "TENSORS" | "TENSORS6" | "TEXTURE_COORDINATES") => {
                    let (per, ty_word) = match k {
                        "TEXTURE_COORDINATES" => {
                            let w = words(&line, 4, "TEXTURE_COORDINATES NAME DIM TYPE")?;
                            (count(w[2], &line)?, w[3])
                        }
                        _ => {
                            let w = words(&line, 3, "VECTORS NAME TYPE")?;
                            (
                                match k {
                                    "TENSORS" => 9,
                                    "TENSORS6" => 6,
                                    _ => 3,
                                },
                                w[2],
                            )
                        }
                    };
                    let ty = data_type(ty_word).with_context(|| format!("line {at}"))?;
                    seen.other(describe(section, &unescape(w.get(1).copied().unwrap_or("")), per));
                    let n = n_here.checked_mul(per).context("the extents overflow")?;
                    r.skip(n, ty, &format!("{k} (line {at})"))?;
                }
                _ => bail!("line {at}: unexpected `{line}` in a STRUCTURED_POINTS file"),
            }
            Ok(())
        };
        if let Err(e) = step() {
            return Err(if cut { e.context(format!("the file ends in line {at} (truncated?)")) } else { e });
        }
    }
    let d = dims.context("the file has no DIMENSIONS line")?;
    let Arrays { candidates, others, found, .. } = seen;
    let Some((name, elem, samples)) = found else {
        if candidates.is_empty() {
            bail!(
                "the file holds no one-component POINT_DATA array to load{}",
                if others.is_empty() { String::new() } else { format!(" (it holds {})", others.join(", ")) }
            );
        }
        bail!(
            "the file holds {} one-component POINT_DATA array(s) ({}); array {} was asked for",
            candidates.len(),
            candidates.join(", "),
            opts.index
        );
    };
    let mut notes: Vec<String> = elem.note().into_iter().collect();
    notes.push(format!("loaded point data `{name}`"));
    Ok(Loaded {
        volume: LoadedVolume { dims: Dims(d[0], d[1], d[2]), samples, spacing },
        format: Format::Vtk,
        notes,
    })
}

fn describe(section: Section, name: &str, comps: usize) -> String {
    let s = match section {
        Section::Point(_) => "point",
        Section::Cell(_) => "cell",
        Section::None => "field",
    };
    format!("{s} data `{name}` of {comps} component(s)")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn err(bytes: &[u8]) -> String {
        format!("{:#}", parse(bytes, &Options::default()).unwrap_err())
    }

    const ASCII: &str = "# vtk DataFile Version 3.0
a test
ASCII
DATASET STRUCTURED_POINTS
DIMENSIONS 3 2 2
ORIGIN 0 0 0
SPACING 0.5 -2 1e0
CELL_DATA 2
SCALARS cells float
LOOKUP_TABLE default
1.5 2.5
POINT_DATA 12
VECTORS v float
0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0
0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0
SCALARS rgb unsigned_char 3
0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0
0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0
SCALARS density short
LOOKUP_TABLE default
0 1 2 10 11 12
100 101 102 110 111 -112
FIELD FieldData 2
extra 1 12 double
0 0 0 0 0 0 0 0 0 0 0 .5
ignored 2 1 int
7 8
";

    #[test]
    fn ascii_skips_to_the_first_point_scalars() {
        let l = parse(ASCII.as_bytes(), &Options::default()).unwrap();
        assert_eq!(l.format, Format::Vtk);
        assert_eq!(l.volume.dims, Dims(3, 2, 2));
        assert_eq!(l.volume.spacing, [0.5, 2.0, 1.0]);
        assert_eq!(l.volume.samples, Samples::I16(vec![0, 1, 2, 10, 11, 12, 100, 101, 102, 110, 111, -112]));
        assert_eq!(l.notes, ["loaded point data `density`"]);
        // The second one-component point array is the FIELD's `extra`.
        let l = parse(ASCII.as_bytes(), &Options { index: 1, ..Options::default() }).unwrap();
        let Samples::F32(v) = &l.volume.samples else { panic!() };
        assert_eq!(v[11], 0.5);
        assert!(l.notes[0].contains("float64"));
        let e = format!(
            "{:#}",
            parse(ASCII.as_bytes(), &Options { index: 2, ..Options::default() }).unwrap_err()
        );
        assert!(e.contains("holds 2 one-component POINT_DATA array(s) (density, extra); array 2"), "{e}");
    }

    /// A binary file as VTK writes one: big-endian, data right after
    /// their keyword line, a newline after them.
    fn binary(ty: &str, data: &[u8], n: usize) -> Vec<u8> {
        let mut f = b"# vtk DataFile Version 4.2\nvtk output\nBINARY\nDATASET STRUCTURED_POINTS\n".to_vec();
        f.extend_from_slice(format!("DIMENSIONS {n} 1 1\nSPACING 1 1 1\nORIGIN 0 0 0\n").as_bytes());
        f.extend_from_slice(b"FIELD FieldData 1\nTime 1 1 double\n");
        f.extend_from_slice(&10.0f64.to_be_bytes());
        f.extend_from_slice(
            format!("\nCELL_DATA {}\nFIELD FieldData 1\nc%20d 1 {} float\n", n - 1, n - 1).as_bytes(),
        );
        f.extend_from_slice(&vec![0x0a; 4 * (n - 1)]); // newline bytes as data: must not confuse the reader
        f.extend_from_slice(
            format!("\nPOINT_DATA {n}\nSCALARS my%20scalars {ty}\nLOOKUP_TABLE default\n").as_bytes(),
        );
        f.extend_from_slice(data);
        f.push(b'\n');
        f
    }

    #[test]
    fn binary_is_big_endian_for_every_type() {
        let l = parse(&binary("unsigned_char", &[0, 10, 255], 3), &Options::default()).unwrap();
        assert_eq!(l.volume.samples, Samples::U8(vec![0, 10, 255]));
        assert_eq!(l.notes, ["loaded point data `my scalars`"]);
        let d: Vec<u8> = [1i16, -2, 0x1234].iter().flat_map(|v| v.to_be_bytes()).collect();
        assert_eq!(
            parse(&binary("short", &d, 3), &Options::default()).unwrap().volume.samples,
            Samples::I16(vec![1, -2, 0x1234])
        );
        let d: Vec<u8> = [1u16, 65535].iter().flat_map(|v| v.to_be_bytes()).collect();
        assert_eq!(
            parse(&binary("unsigned_short", &d, 2), &Options::default()).unwrap().volume.samples,
            Samples::U16(vec![1, 65535])
        );
        assert_eq!(
            parse(&binary("char", &[0xff, 1], 2), &Options::default()).unwrap().volume.samples,
            Samples::I16(vec![-1, 1])
        );
        let d: Vec<u8> = [1.5f32, -0.25].iter().flat_map(|v| v.to_be_bytes()).collect();
        assert_eq!(
            parse(&binary("float", &d, 2), &Options::default()).unwrap().volume.samples,
            Samples::F32(vec![1.5, -0.25])
        );
        let d: Vec<u8> = [7i32, -9].iter().flat_map(|v| v.to_be_bytes()).collect();
        let l = parse(&binary("int", &d, 2), &Options::default()).unwrap();
        assert_eq!(l.volume.samples, Samples::F32(vec![7.0, -9.0]));
        assert!(l.notes[0].contains("int32 samples are loaded as f32"));
        let d: Vec<u8> = [3.25f64, 1e-3].iter().flat_map(|v| v.to_be_bytes()).collect();
        assert_eq!(
            parse(&binary("double", &d, 2), &Options::default()).unwrap().volume.samples,
            Samples::F32(vec![3.25, 1e-3])
        );
    }

    /// Only what is needed is read: arrays after the one taken are not,
    /// text stops at what the arrays declare, and the limit is checked
    /// before the chosen array is read.
    #[test]
    fn reads_up_to_the_array_taken() {
        // After `density`: a FIELD array cut short, never read.
        let cut = &ASCII[..ASCII.find("0 0 0 0 0 0 0 0 0 0 0 .5").unwrap() + 5];
        assert!(parse(cut.as_bytes(), &Options::default()).is_ok());
        // Blanks without end in ASCII data (an array's values and a
        // header's worth of keyword lines may follow).
        let blanks = ASCII.replace("0 1 2 10 11 12", &format!("0 1 2 10 11{} 12", " ".repeat(5 << 20)));
        let e = err(blanks.as_bytes());
        assert!(
            e.contains("text runs on for more than")
                && e.contains("more than 12 values and keyword lines take"),
            "{e}"
        );
        let e = format!(
            "{:#}",
            parse(ASCII.as_bytes(), &Options { index: 0, max_bytes: 23, ..Options::default() }).unwrap_err()
        );
        assert!(e.contains("3x2x2 int16 samples take 24 bytes, more than the limit of 23 bytes"), "{e}");
        assert!(parse(ASCII.as_bytes(), &Options { index: 0, max_bytes: 24, ..Options::default() }).is_ok());
        // Binary data right after SCALARS, without a LOOKUP_TABLE line.
        let f = binary("unsigned_char", b"LOO", 3);
        let no_table = String::from_utf8_lossy(&f).replace("LOOKUP_TABLE default\n", "");
        let l = parse(no_table.as_bytes(), &Options::default()).unwrap();
        assert_eq!(l.volume.samples, Samples::U8(b"LOO".to_vec()));
    }

    #[test]
    fn bad_files_are_clear_errors() {
        assert!(err(b"hello\n").contains("not a VTK legacy file: the first line is `hello`"));
        assert!(err(b"# vtk DataFile Version 3.0\nt\nUTF8\n").contains("ASCII or BINARY, not `UTF8`"));
        assert!(
            err(ASCII.replace("STRUCTURED_POINTS", "RECTILINEAR_GRID").as_bytes())
                .contains("RECTILINEAR_GRID, which is not supported")
        );
        assert!(
            err(ASCII.replace("POINT_DATA 12", "POINT_DATA 13").as_bytes())
                .contains("POINT_DATA 13 does not match DIMENSIONS 3 2 2 (12 points)")
        );
        assert!(err(ASCII.replace("DIMENSIONS 3 2 2", "DIMENSIONS 3 0 2").as_bytes()).contains("at least 1"));
        assert!(
            err(ASCII.replace("density short", "density quad").as_bytes())
                .contains("`quad` is not a VTK numeric type")
        );
        assert!(
            err(ASCII.replace("110 111 -112", "110 1x1 -112").as_bytes())
                .contains("value 11 of the SCALARS `density`")
        );
        let cut = &ASCII[..ASCII.find("111 -112").unwrap()];
        assert!(err(cut.as_bytes()).contains("truncated: 10 of 12 values"), "{}", err(cut.as_bytes()));
        assert!(
            err(ASCII.replace("DIMENSIONS 3 2 2\n", "").as_bytes())
                .contains("POINT_DATA comes before DIMENSIONS")
        );
        let no_scalars = "# vtk DataFile Version 2.0\nt\nASCII\nDATASET STRUCTURED_POINTS\nDIMENSIONS 2 1 1\n\
                          POINT_DATA 2\nNORMALS n float\n0 0 1 0 0 1\nSCALARS two float 2\n1 2 3 4\n";
        let e = err(no_scalars.as_bytes());
        assert!(e.contains("no one-component POINT_DATA array to load (it holds point data `n` of 3 component(s), point data `two` of 2"), "{e}");
        assert!(err(ASCII.replace("ORIGIN", "WHATEVER").as_bytes()).contains("unexpected `WHATEVER 0 0 0`"));
        let full = binary("float", &[0; 12], 3);
        let e = err(&full[..full.len() - 3]);
        assert!(
            e.contains("truncated in SCALARS `my scalars`") && e.contains("12 bytes of binary data"),
            "{e}"
        );
        let e = err(&full[..120]);
        assert!(e.contains("truncated"), "{e}");
    }
}
