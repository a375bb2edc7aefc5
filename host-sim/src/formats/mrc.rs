//! MRC (cryo-EM, MRC2014) and CCP4 (crystallography) maps: a 1024-byte
//! header of 4-byte words, an extended header of `NSYMBT` bytes (CCP4
//! symmetry records, or MRC2014 metadata), then the data; gzip compressed
//! or not.
//!
//! Byte order: the machine stamp (`0x44` little-endian, `0x11` big-endian)
//! if the header reads sensibly that way, else whichever order gives
//! sensible extents, mode and axis words. Modes: 0 (`int8`) and 1 (`int16`)
//! load as `i16`, 2 (`float32`) and 12 (`float16`) as `f32`, 6 (`uint16`) as
//! `u16`; the complex modes 3 and 4 and the packed 4-bit mode 101 are
//! refused. The data run columns fastest, then rows, then sections, along
//! the space axes `MAPC`, `MAPR`, `MAPS` (1 = x); they are transposed so
//! that x runs fastest, with dims `(nx, ny, nz)`. Spacing: cell dimensions
//! over sampling, `(a / MX, b / MY, c / MZ)`, in the file's unit (Å).
//! The origin and start indices are not used.

use super::{
    Elem, Endian, Format, Input, Loaded, Options, check_size, decode, permute, single_volume, voxel_size,
};
use crate::volume::LoadedVolume;
use anyhow::{Context, Result, bail};
use std::path::Path;

/// Size of the main header.
pub const HEADER: usize = 1024;

/// Read an MRC or CCP4 map (gzip compressed or not): the header, then
/// exactly the data it declares, streamed.
pub fn read(path: &Path, opts: &Options) -> Result<Loaded> {
    read_from(&mut Input::open(path)?, opts)
}

/// A 4-byte word of the header.
fn word(bytes: &[u8], i: usize, e: Endian) -> i32 {
    let w = [bytes[4 * i], bytes[4 * i + 1], bytes[4 * i + 2], bytes[4 * i + 3]];
    if e == Endian::Little { i32::from_le_bytes(w) } else { i32::from_be_bytes(w) }
}

/// A 4-byte real of the header.
fn real(bytes: &[u8], i: usize, e: Endian) -> f32 {
    f32::from_bits(word(bytes, i, e) as u32)
}

/// Whether the header reads sensibly in byte order `e`.
fn plausible(bytes: &[u8], e: Endian) -> bool {
    let ok_n = (0..3).all(|i| (1..=1 << 24).contains(&word(bytes, i, e)));
    let ok_mode = matches!(word(bytes, 3, e), 0..=4 | 6 | 12 | 101);
    let ok_map = (16..19).all(|i| (0..=3).contains(&word(bytes, i, e)));
    ok_n && ok_mode && ok_map
}

/// The header's byte order.
fn byte_order(bytes: &[u8]) -> Result<Endian> {
    let stamp = match bytes[212] {
        0x44 | 0x41 => Some(Endian::Little),
        0x11 => Some(Endian::Big),
        _ => None,
    };
    if let Some(e) = stamp.filter(|&e| plausible(bytes, e)) {
        return Ok(e);
    }
    match (plausible(bytes, Endian::Little), plausible(bytes, Endian::Big)) {
        (true, _) => Ok(Endian::Little),
        (false, true) => Ok(Endian::Big),
        (false, false) => {
            let w = |i| word(bytes, i, Endian::Little);
            bail!(
                "not an MRC/CCP4 map: the header makes no sense in either byte order (little-endian: NC, NR, NS = \
                 {}, {}, {}, MODE {}, MAPC, MAPR, MAPS = {}, {}, {})",
                w(0),
                w(1),
                w(2),
                w(3),
                w(16),
                w(17),
                w(18)
            )
        }
    }
}

/// Decode an MRC or CCP4 map (already gunzipped).
pub fn parse(bytes: &[u8], opts: &Options) -> Result<Loaded> {
    read_from(&mut Input::from_slice(bytes), opts)
}

pub(crate) fn read_from(input: &mut Input<'_>, opts: &Options) -> Result<Loaded> {
    single_volume(opts)?;
    let bytes = input.head(HEADER)?;
    if bytes.len() < HEADER {
        bail!("the file is truncated: an MRC/CCP4 header is {HEADER} bytes, the file has {}", bytes.len());
    }
    let bytes = &bytes[..];
    let e = byte_order(bytes)?;
    let w = |i| word(bytes, i, e);
    let n = [w(0), w(1), w(2)];
    let mode = w(3);
    let map = [w(16), w(17), w(18)];
    let nsymbt = w(23);
    let elem = match mode {
        0 => Elem::I8,
        1 => Elem::I16,
        2 => Elem::F32,
        6 => Elem::U16,
        12 => Elem::F16,
        3 | 4 => bail!("mode {mode} (complex samples) is not supported: only modes 0, 1, 2, 6 and 12"),
        101 => bail!("mode 101 (packed 4-bit samples) is not supported: only modes 0, 1, 2, 6 and 12"),
        m => bail!("mode {m} is not an MRC mode (0, 1, 2, 6 and 12 are supported)"),
    };
    let axis = match map {
        [0, 0, 0] => [0, 1, 2],
        [c, r, s]
            if {
                let mut v = [c, r, s];
                v.sort_unstable();
                v == [1, 2, 3]
            } =>
        {
            [c as usize - 1, r as usize - 1, s as usize - 1]
        }
        _ => bail!("MAPC, MAPR, MAPS = {}, {}, {} is not a permutation of 1, 2, 3", map[0], map[1], map[2]),
    };
    // `plausible` has checked the extents are 1 ..= 2^24.
    let n = n.map(|v| v as usize);
    let ext = usize::try_from(nsymbt)
        .with_context(|| format!("the extended header size NSYMBT is {nsymbt}; it must not be negative"))?;
    if ext > opts.max_bytes {
        bail!("the extended header size NSYMBT is {nsymbt}, more than the limit of {} bytes", opts.max_bytes);
    }
    let need = check_size(&n, elem, opts.max_bytes)?;
    input.data(ext).skip(ext as u64).with_context(|| {
        format!("the file is truncated: its extended header of {nsymbt} bytes (NSYMBT) ends past the end of the file")
    })?;
    let offset = HEADER + ext;
    let body = input.exactly(need).with_context(|| {
        format!(
            "the header's extents {}x{}x{} of mode {mode} ({}) need {need} bytes of data from byte {offset}",
            n[0],
            n[1],
            n[2],
            elem.name()
        )
    })?;
    let (samples, dims) = permute(decode(body, elem, e), n, axis)?;
    let m = [w(7), w(8), w(9)];
    let spacing = [0, 1, 2].map(|i| {
        let cell = f64::from(real(bytes, 10 + i, e));
        if m[i] > 0 { voxel_size(cell / f64::from(m[i])) } else { 1.0 }
    });
    let mut notes = Vec::new();
    if mode == 0 {
        notes.push("mode 0 samples are read as signed int8 (MRC2014), loaded as i16".to_string());
    }
    if axis != [0, 1, 2] {
        notes.push(format!(
            "the data run along MAPC, MAPR, MAPS = {}, {}, {}; transposed to x fastest",
            map[0], map[1], map[2]
        ));
    }
    Ok(Loaded { volume: LoadedVolume { dims, samples, spacing }, format: Format::Mrc, notes })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::volume::{Dims, Samples};

    /// A header built word by word (MRC2014 layout), then `data`.
    #[allow(clippy::too_many_arguments)]
    fn file(
        n: [i32; 3],
        mode: i32,
        m: [i32; 3],
        cell: [f32; 3],
        map: [i32; 3],
        ext: &[u8],
        stamp: u8,
        big: bool,
        data: &[u8],
    ) -> Vec<u8> {
        let mut h = vec![0u8; HEADER];
        let mut put = |i: usize, b: [u8; 4]| h[4 * i..4 * i + 4].copy_from_slice(&b);
        let wi = |v: i32| if big { v.to_be_bytes() } else { v.to_le_bytes() };
        let wf = |v: f32| if big { v.to_be_bytes() } else { v.to_le_bytes() };
        for i in 0..3 {
            put(i, wi(n[i]));
            put(7 + i, wi(m[i]));
            put(10 + i, wf(cell[i]));
            put(13 + i, wf(90.0));
            put(16 + i, wi(map[i]));
        }
        put(3, wi(mode));
        put(23, wi(ext.len() as i32));
        put(52, *b"MAP ");
        put(53, [stamp, stamp, 0, 0]);
        h.extend_from_slice(ext);
        h.extend_from_slice(data);
        h
    }

    fn f32s(v: &[f32], big: bool) -> Vec<u8> {
        v.iter().flat_map(|x| if big { x.to_be_bytes() } else { x.to_le_bytes() }).collect()
    }

    fn err(bytes: &[u8]) -> String {
        format!("{:#}", parse(bytes, &Options::default()).unwrap_err())
    }

    #[test]
    fn float32_little_endian_with_spacing() {
        let v: Vec<f32> = (0..24).map(|i| i as f32 * 0.5).collect();
        let f = file([2, 3, 4], 2, [4, 3, 8], [2.0, 3.0, 4.0], [1, 2, 3], &[], 0x44, false, &f32s(&v, false));
        let l = parse(&f, &Options::default()).unwrap();
        assert_eq!(l.format, Format::Mrc);
        assert_eq!(l.volume.dims, Dims(2, 3, 4));
        assert_eq!(l.volume.spacing, [0.5, 1.0, 0.5]);
        assert_eq!(l.volume.samples, Samples::F32(v));
        assert!(l.notes.is_empty());
    }

    #[test]
    fn big_endian_by_stamp_or_by_sense() {
        let v = [1i16, -2, 300, -400];
        let be: Vec<u8> = v.iter().flat_map(|x| x.to_be_bytes()).collect();
        for stamp in [0x11, 0x00, 0x44] {
            let f = file([2, 2, 1], 1, [2, 2, 1], [2.0, 2.0, 1.0], [1, 2, 3], &[], stamp, true, &be);
            let l = parse(&f, &Options::default()).unwrap();
            assert_eq!(l.volume.samples, Samples::I16(v.to_vec()), "stamp {stamp:#x}");
            assert_eq!(l.volume.spacing, [1.0; 3]);
        }
    }

    #[test]
    fn modes_0_6_and_12() {
        let f = file([3, 1, 1], 0, [0; 3], [0.0; 3], [0; 3], &[], 0x44, false, &[0xff, 0x7f, 0x80]);
        let l = parse(&f, &Options::default()).unwrap();
        assert_eq!(l.volume.samples, Samples::I16(vec![-1, 127, -128]));
        assert_eq!(l.volume.spacing, [1.0; 3], "no sampling: unit spacing");
        assert!(l.notes[0].contains("signed int8"));
        let f = file([2, 1, 1], 6, [1; 3], [1.0; 3], [1, 2, 3], &[], 0x44, false, &[0xff, 0xff, 1, 0]);
        assert_eq!(parse(&f, &Options::default()).unwrap().volume.samples, Samples::U16(vec![65535, 1]));
        let f = file([2, 1, 1], 12, [1; 3], [1.0; 3], [1, 2, 3], &[], 0x44, false, &[0x00, 0x3c, 0x00, 0xc0]);
        assert_eq!(parse(&f, &Options::default()).unwrap().volume.samples, Samples::F32(vec![1.0, -2.0]));
    }

    /// Data stored along permuted axes come out x fastest: value 100 x +
    /// 10 y + z at every point, for every axis order.
    #[test]
    fn axis_permutations_are_transposed() {
        let (nx, ny, nz) = (2usize, 3usize, 4usize);
        let size = [nx, ny, nz];
        for map in [[1, 2, 3], [2, 1, 3], [3, 1, 2], [3, 2, 1], [1, 3, 2], [2, 3, 1]] {
            let ax = map.map(|a| a as usize - 1);
            let n = ax.map(|a| size[a]);
            let mut data = Vec::new();
            for s in 0..n[2] {
                for r in 0..n[1] {
                    for c in 0..n[0] {
                        let mut p = [0; 3];
                        p[ax[0]] = c;
                        p[ax[1]] = r;
                        p[ax[2]] = s;
                        data.push((100 * p[0] + 10 * p[1] + p[2]) as f32);
                    }
                }
            }
            let ni = n.map(|v| v as i32);
            let f =
                file(ni, 2, [4, 6, 16], [2.0, 3.0, 4.0], map, b"symmetry", 0x44, false, &f32s(&data, false));
            let l = parse(&f, &Options::default()).unwrap();
            assert_eq!(l.volume.dims, Dims(nx, ny, nz), "{map:?}");
            assert_eq!(l.volume.spacing, [0.5, 0.5, 0.25], "{map:?}: spacing follows space axes");
            let Samples::F32(v) = &l.volume.samples else { panic!() };
            for z in 0..nz {
                for y in 0..ny {
                    for x in 0..nx {
                        assert_eq!(v[x + nx * (y + ny * z)], (100 * x + 10 * y + z) as f32, "{map:?}");
                    }
                }
            }
            assert_eq!(l.notes.is_empty(), map == [1, 2, 3]);
        }
    }

    #[test]
    fn bad_files_are_clear_errors() {
        let good = file([2, 2, 2], 2, [2; 3], [2.0; 3], [1, 2, 3], &[0; 80], 0x44, false, &[0; 32]);
        assert!(parse(&good, &Options::default()).is_ok());
        let e = format!("{:#}", parse(&good, &Options { index: 1, ..Options::default() }).unwrap_err());
        assert!(e.contains("holds one volume; volume 1 was asked for"), "{e}");
        assert!(err(&good[..500]).contains("truncated: an MRC/CCP4 header is 1024 bytes, the file has 500"));
        let e = err(&good[..good.len() - 3]);
        assert!(
            e.contains(
                "2x2x2 of mode 2 (float32) need 32 bytes of data from byte 1104: the data stop after 29 of 32 \
                 bytes (truncated?)"
            ),
            "{e}"
        );
        let mut long = good.clone();
        long.extend_from_slice(&[0; 4]);
        assert!(err(&long).contains("32 bytes of data expected, and 4 more follow"), "{}", err(&long));
        assert!(err(&good[..1050]).contains("extended header of 80 bytes"), "{}", err(&good[..1050]));
        let with = |i: usize, v: i32| {
            let mut b = good.clone();
            b[4 * i..4 * i + 4].copy_from_slice(&v.to_le_bytes());
            err(&b)
        };
        assert!(with(3, 4).contains("mode 4 (complex samples) is not supported"));
        assert!(with(3, 101).contains("mode 101 (packed 4-bit"));
        assert!(with(3, 7).contains("not an MRC/CCP4 map"), "{}", with(3, 7));
        assert!(with(16, 2).contains("MAPC, MAPR, MAPS = 2, 2, 3 is not a permutation"), "{}", with(16, 2));
        assert!(with(0, 0).contains("not an MRC/CCP4 map"));
        assert!(with(1, -5).contains("NC, NR, NS = 2, -5, 2"));
        assert!(with(23, -1).contains("NSYMBT is -1"));
        assert!(with(23, i32::MAX).contains("truncated"));
        // Large but plausible extents: an error, not an allocation.
        let e = with(0, 1 << 24);
        assert!(e.contains("need"), "{e}");
    }
}
