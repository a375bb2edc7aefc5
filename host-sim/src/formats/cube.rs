//! Gaussian cube files (`.cube`, `.cub`, gzip compressed or not): two
//! comment lines; `NATOMS X0 Y0 Z0 [NVAL]`; three lines `N_i` and the axis
//! vector `i`; one line per atom; when `NATOMS < 0`, a line with the number
//! of orbitals and their numbers; then the values, the innermost loop over
//! the third axis (and, innermost of all, over the values at a point).
//!
//! The values load as `f32`, transposed so that x (the first axis) runs
//! fastest, dims `(N_1, N_2, N_3)`. When a point holds several values (the
//! orbitals of `NATOMS < 0`, or `NVAL`), [`Options::index`] picks one
//! (default the first). Spacing: the lengths of the axis vectors, in Bohr
//! when `N_i > 0` and in Å when negative; a skew between non-orthogonal
//! axes is not kept (the reader says so). Orientation
//! ([`super::Orientation::File`], the default): the axes are rearranged
//! (and reversed) to run along the x, y, z their vectors lie nearest
//! ([`crate::orient`]); vectors that cannot orient it leave the file's
//! order, with a note.
//!
//! The text is read line by line, then value by value, up to the values
//! the header declares: at most 64 bytes of text a value, so a gigantic or
//! endless file ends with an error.

use super::{
    Elem, Format, HEADER_TEXT, Input, Loaded, Options, TEXT_PER_VALUE, TEXT_SLACK, check_size, oriented,
    parse_number, parse_text, permute, voxel_size,
};
use crate::orient::{Directions, Space};
use crate::volume::{LoadedVolume, Samples};
use anyhow::{Context, Result, anyhow, bail};
use std::path::Path;

/// Text a line of an atom may take.
const ATOM_TEXT: u64 = 256;

/// Read a cube file (gzip compressed or not).
pub fn read(path: &Path, opts: &Options) -> Result<Loaded> {
    read_from(&mut Input::open(path)?, opts)
}

/// The next line, which must be text.
fn line(input: &mut Input<'_>) -> Result<Option<String>> {
    let no = input.line_no();
    input
        .line()?
        .map(|l| String::from_utf8(l).map_err(|_| anyhow!("not a text file: line {no} is not UTF-8")))
        .transpose()
}

/// Numbers of a header line, with its line number for errors.
fn numbers(line: Option<String>, no: usize, what: &str, min: usize) -> Result<Vec<f64>> {
    let line = line.with_context(|| format!("the file is truncated: it ends before line {no} ({what})"))?;
    let v: Option<Vec<f64>> = line.split_ascii_whitespace().map(parse_number).collect();
    match v {
        Some(v) if v.len() >= min => Ok(v),
        _ => bail!("line {no} should be {what}, but it is `{}`", line.trim()),
    }
}

/// A whole number of the header.
fn whole(v: f64, no: usize, what: &str) -> Result<i64> {
    if v.fract() != 0.0 || v.abs() > 1e15 {
        bail!("line {no}: {what} is {v}, not a whole number");
    }
    Ok(v as i64)
}

/// Decode a cube file (already gunzipped).
pub fn parse(bytes: &[u8], opts: &Options) -> Result<Loaded> {
    read_from(&mut Input::from_slice(bytes), opts)
}

pub(crate) fn read_from(input: &mut Input<'_>, opts: &Options) -> Result<Loaded> {
    let mut no = 2;
    if line(input)?.is_none() || line(input)?.is_none() {
        bail!("the file is truncated: a cube file starts with two comment lines and five header lines");
    }
    no += 1;
    let head = numbers(line(input)?, no, "`NATOMS X0 Y0 Z0 [NVAL]`", 4)?;
    let natoms = whole(head[0], no, "NATOMS")?;
    let nval = match head.get(4) {
        Some(&v) => whole(v, no, "NVAL")?,
        None => 1,
    };
    let mut n = [0usize; 3];
    let mut vec = [[0f64; 3]; 3];
    let mut angstrom = false;
    for i in 0..3 {
        no += 1;
        let v = numbers(line(input)?, no, &format!("`N{} and axis vector {}`", i + 1, i + 1), 4)?;
        let count = whole(v[0], no, &format!("N{}", i + 1))?;
        if count == 0 || count.unsigned_abs() > 1 << 24 {
            bail!("line {no}: N{} is {count}; an axis needs 1 to 2^24 points", i + 1);
        }
        angstrom |= count < 0;
        n[i] = count.unsigned_abs() as usize;
        vec[i] = [v[1], v[2], v[3]];
    }
    if natoms.unsigned_abs() > 1 << 24 {
        bail!("line 3: NATOMS is {natoms}, implausibly many");
    }
    check_size(&n, Elem::F32, opts.max_bytes)?;
    input.allow_text(
        HEADER_TEXT + natoms.unsigned_abs() * ATOM_TEXT,
        format!("a header of {} atoms takes", natoms.unsigned_abs()),
    );
    for a in 0..natoms.unsigned_abs() {
        no += 1;
        numbers(line(input)?, no, &format!("atom {} (`Z CHARGE X Y Z`)", a + 1), 5)?;
    }
    let mut tok = String::new();
    let (per_point, orbitals) = if natoms < 0 {
        let what = "the orbital list after the atoms (NATOMS < 0)";
        let m = input
            .token(&mut tok, false)?
            .then(|| parse_number(&tok))
            .flatten()
            .with_context(|| format!("the file ends or is garbled at {what}"))?;
        let m = whole(m, no + 1, "the number of orbitals")?;
        if !(1..=1 << 16).contains(&m) {
            bail!("{what} gives {m} orbitals");
        }
        let mut list = Vec::new();
        while (list.len() as i64) < m && input.token(&mut tok, false)? {
            list.push(tok.clone());
        }
        if list.len() as i64 != m {
            bail!("the file is truncated in {what}");
        }
        (m as usize, Some(list))
    } else {
        if !(1..=1 << 16).contains(&nval) {
            bail!("line 3: NVAL is {nval}; it must be at least 1");
        }
        (nval as usize, None)
    };
    if opts.index >= per_point {
        bail!("the file holds {per_point} value(s) per point; value {} was asked for", opts.index);
    }
    let points = n[0].checked_mul(n[1]).and_then(|p| p.checked_mul(n[2])).context("the extents overflow")?;
    let count = points.checked_mul(per_point).context("the extents overflow")?;
    let what = format!("{}x{}x{} points of {per_point} value(s)", n[0], n[1], n[2]);
    input.allow_text(
        (count as u64).saturating_mul(TEXT_PER_VALUE).saturating_add(TEXT_SLACK),
        format!("{count} values take"),
    );
    let values = format!("values ({what})");
    let Samples::F32(picked) = parse_text(input, false, count, (opts.index, per_point), Elem::F32, &values)?
    else {
        bail!("internal: f32 text samples");
    };
    if input.token(&mut tok, false)? {
        bail!("the file holds more values than {what}");
    }
    // File order: the third axis fastest, the first slowest.
    let (samples, dims) = permute(Samples::F32(picked), [n[2], n[1], n[0]], [2, 1, 0])?;
    let len = |v: [f64; 3]| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    let spacing = vec.map(|v| voxel_size(len(v)));
    let mut notes = vec![format!("voxel spacing in {}", if angstrom { "Å" } else { "Bohr" })];
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    if [(0, 1), (0, 2), (1, 2)]
        .iter()
        .any(|&(i, j)| dot(vec[i], vec[j]).abs() > 1e-6 * len(vec[i]) * len(vec[j]))
    {
        notes.push("the axes are not orthogonal; only their lengths are kept as spacing".to_string());
    }
    if per_point > 1 {
        let which = match &orbitals {
            Some(list) => format!("orbitals {}; loaded orbital {}", list.join(", "), list[opts.index]),
            None => format!("values; loaded value {}", opts.index),
        };
        notes.push(format!("the file holds {per_point} {which} (index {})", opts.index));
    }
    let loaded = Loaded { volume: LoadedVolume { dims, samples, spacing }, format: Format::Cube, notes };
    let axes = Directions { space: Space::Xyz, columns: vec };
    Ok(oriented(loaded, Some((axes, "axis vectors")), opts))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::volume::Dims;

    /// A cube file of `n` points whose value(s) at (x, y, z) are `f(x, y,
    /// z, k)` for orbital k, written z fastest, 6 values a line.
    fn cube(n: [i64; 3], orbitals: &[u32], f: impl Fn(usize, usize, usize, usize) -> f64) -> String {
        let natoms: i64 = if orbitals.is_empty() { 2 } else { -2 };
        let mut s = format!("title\ncomment\n{natoms:5} -1.0 -2.0 -3.0\n");
        s += &format!("{:5} 0.5 0.0 0.0\n{:5} 0.0 0.25 0.0\n{:5} 0.0 0.0 2.0\n", n[0], n[1], n[2]);
        s += "    7    7.000000     .000000     .000000   -2.262147\n";
        s += "    8    8.000000     .000000     .000000    2.144908\n";
        if !orbitals.is_empty() {
            s += &format!("{:5}", orbitals.len());
            for o in orbitals {
                s += &format!("{o:5}");
            }
            s += "\n";
        }
        let per = orbitals.len().max(1);
        let [nx, ny, nz] = n.map(|v| v.unsigned_abs() as usize);
        for x in 0..nx {
            for y in 0..ny {
                let mut k = 0;
                for z in 0..nz {
                    for o in 0..per {
                        s += &format!(" {:12.5E}", f(x, y, z, o));
                        k += 1;
                        if k % 6 == 0 {
                            s += "\n";
                        }
                    }
                }
                s += "\n";
            }
        }
        s
    }

    fn value(x: usize, y: usize, z: usize, o: usize) -> f64 {
        (100 * x + 10 * y + z) as f64 * if o == 0 { 1.0 } else { -1.0 }
    }

    #[test]
    fn z_fastest_file_loads_x_fastest() {
        let text = cube([2, 3, 4], &[], value);
        let l = parse(text.as_bytes(), &Options::default()).unwrap();
        assert_eq!(l.format, Format::Cube);
        assert_eq!(l.volume.dims, Dims(2, 3, 4));
        assert_eq!(l.volume.spacing, [0.5, 0.25, 2.0]);
        let Samples::F32(v) = &l.volume.samples else { panic!() };
        for z in 0..4 {
            for y in 0..3 {
                for x in 0..2 {
                    assert_eq!(v[x + 2 * (y + 3 * z)], value(x, y, z, 0) as f32);
                }
            }
        }
        assert_eq!(l.notes, ["voxel spacing in Bohr"]);
    }

    #[test]
    fn orbitals_are_picked_by_index() {
        let text = cube([3, 2, 5], &[11, 12], value);
        for (index, sign) in [(0, 1.0), (1, -1.0)] {
            let l = parse(text.as_bytes(), &Options { index, ..Options::default() }).unwrap();
            let Samples::F32(v) = &l.volume.samples else { panic!() };
            assert_eq!(v[1 + 3 * (1 + 2 * 4)], sign * 114.0);
            let orbital = ["11", "12"][index];
            assert!(
                l.notes.iter().any(|n| n.contains(&format!("loaded orbital {orbital}"))),
                "{:?}",
                l.notes
            );
        }
        let e =
            format!("{:#}", parse(text.as_bytes(), &Options { index: 2, ..Options::default() }).unwrap_err());
        assert!(e.contains("holds 2 value(s) per point; value 2 was asked for"), "{e}");
    }

    #[test]
    fn angstrom_units_and_skew_are_noted() {
        let text = cube([-2, -2, -2], &[], value).replace(" 0.0 0.25 0.0", " 0.25 0.25 0.0");
        let l = parse(text.as_bytes(), &Options::default()).unwrap();
        assert_eq!(l.volume.dims, Dims(2, 2, 2));
        assert_eq!(l.volume.spacing[1], (0.125f64).sqrt() as f32);
        assert_eq!(l.notes[0], "voxel spacing in Å");
        assert!(l.notes[1].contains("not orthogonal"));
    }

    /// Axis vectors along other axes: the first axis along -z, the third
    /// along +x: x = k, y = j, z = -i; `Index` keeps the file's order.
    #[test]
    fn axis_vectors_orient_the_grid() {
        let text = cube([2, 3, 4], &[], value)
            .replace(" 0.5 0.0 0.0\n", " 0.0 0.0 -0.5\n")
            .replace(" 0.0 0.0 2.0\n", " 2.0 0.0 0.0\n");
        let l = parse(text.as_bytes(), &Options::default()).unwrap();
        assert_eq!((l.volume.dims, l.volume.spacing), (Dims(4, 3, 2), [2.0, 0.25, 0.5]));
        let Samples::F32(v) = &l.volume.samples else { panic!() };
        for z in 0..2 {
            for y in 0..3 {
                for x in 0..4 {
                    assert_eq!(v[x + 4 * (y + 3 * z)], value(1 - z, y, x, 0) as f32, "({x},{y},{z})");
                }
            }
        }
        assert!(l.notes[1].contains("oriented by the axis vectors: x = k (+x), y = j (+y), z = -i (+z)"));
        let index = Options { orientation: super::super::Orientation::Index, ..Options::default() };
        assert_eq!(parse(text.as_bytes(), &index).unwrap().volume.dims, Dims(2, 3, 4));
        // Zero vectors: the file's order, and why.
        let text = cube([2, 3, 4], &[], value).replace(" 0.5 0.0 0.0\n", " 0.0 0.0 0.0\n");
        let l = parse(text.as_bytes(), &Options::default()).unwrap();
        assert_eq!(l.volume.dims, Dims(2, 3, 4));
        assert!(l.notes.iter().any(|n| n.contains("not oriented by the axis vectors")), "{:?}", l.notes);
    }

    #[test]
    fn nval_on_line_3() {
        let text = cube([2, 2, 2], &[11, 12], value);
        // The same values, declared by NVAL = 2 with a positive NATOMS.
        let text = text.replacen("   -2 -1.0 -2.0 -3.0", "    2 -1.0 -2.0 -3.0 2", 1).replacen(
            "    2   11   12\n",
            "",
            1,
        );
        let l = parse(text.as_bytes(), &Options { index: 1, ..Options::default() }).unwrap();
        let Samples::F32(v) = &l.volume.samples else { panic!() };
        assert_eq!(v[7], -111.0);
        assert!(l.notes.iter().any(|n| n.contains("2 values; loaded value 1")), "{:?}", l.notes);
    }

    #[test]
    fn bad_files_are_clear_errors() {
        let good = cube([2, 2, 3], &[], value);
        let err = |s: &str| format!("{:#}", parse(s.as_bytes(), &Options::default()).unwrap_err());
        assert!(err("title\n").contains("truncated"));
        let cut = &good[..good.len() - 20];
        assert!(err(cut).contains("are truncated: 11 of 12 values"), "{}", err(cut));
        assert!(err(&format!("{good} 1.0\n")).contains("more values than 2x2x3 points"));
        assert!(
            err(&good.replacen("-1.0 -2.0 -3.0", "-1.0 -2.0", 1))
                .contains("line 3 should be `NATOMS X0 Y0 Z0")
        );
        assert!(err(&good.replacen("    2 0.0 0.25", "    0 0.0 0.25", 1)).contains("line 5: N2 is 0"));
        assert!(
            err(&good.replacen("    2 0.0 0.25", "  2.5 0.0 0.25", 1))
                .contains("N2 is 2.5, not a whole number")
        );
        assert!(
            err(&good.replacen("    8    8.000000", "    8", 1)).contains("line 8 should be atom 2"),
            "{}",
            err(&good.replacen("    8    8.000000", "    8", 1))
        );
        let garbled = good.replacen(" 1.00000E0", " 1.0000QE0", 1);
        assert!(
            err(&garbled).contains("value 2 of the values (2x2x3 points of 1 value(s)), `1.0000QE0`"),
            "{}",
            err(&garbled)
        );
        assert!(
            format!("{:#}", parse(&[0xff, 0xfe, 0], &Options::default()).unwrap_err())
                .contains("not a text file")
        );
        let lines: Vec<&str> = good.lines().collect();
        assert!(err(&lines[..5].join("\n")).contains("ends before line 6"));
        let mo = cube([2, 2, 2], &[11, 12], value);
        assert!(err(&mo.replacen("    2   11   12\n", "    3   11   12\n", 1)).contains("value"));
    }
}
