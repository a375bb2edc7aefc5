//! Volume file formats: [`nrrd`], [`nifti`] (NIfTI-1), [`mrc`] (MRC/CCP4),
//! [`cube`] (Gaussian cube) and [`vtk`] (VTK legacy `STRUCTURED_POINTS`),
//! one module each, and what they share: gzip, byte order, sample types and
//! axis order.
//!
//! Every reader returns a [`LoadedVolume`] in the one layout the core wants:
//! dims `(nx, ny, nz)`, samples x fastest, and the voxel spacing the file
//! gives (`[1, 1, 1]` when it gives none). A file's sample type is loaded as
//! the closest of the four the core takes ([`Elem::loads_as`]): `uint8` as
//! `u8`; `int8` and `int16` as `i16`; `uint16` as `u16`; `float16` and
//! `float32` as `f32`; `int32`, `uint32`, `int64`, `uint64` and `float64` as
//! `f32` too, which rounds (the reader then says so in [`Loaded::notes`]).
//!
//! [`read`] picks the reader from the file name, or else from the first
//! bytes; [`crate::volume::LoadedVolume::read_known`] calls it. Errors name
//! the file and what is wrong with it (truncated data, more data than the
//! header declares, an unsupported type), and never panic.
//!
//! Every reader (and the raw one) reads through one bounded `Input`: the
//! header first, then exactly the bytes it declares (gzip inflated as it
//! is read), then whether more follow; never a whole file or gzip stream
//! before the header has said what it holds, so a stream without end
//! (`/dev/zero`, a FIFO) stops where the header's sizes do. A volume whose
//! samples would take more than [`Options::max_bytes`] (default 2 GiB) is
//! refused from its header before anything is allocated for it
//! (`check_size`), and text data stop at 64 bytes of text a
//! value the header declares.

use crate::orient::{AxisMap, Directions, reduce};
use crate::volume::{Dims, Dtype, LoadedVolume, Samples};
use anyhow::{Context, Result, bail};
use std::io::Read;
use std::path::Path;

pub mod cube;
pub mod mrc;
pub mod nifti;
pub mod nrrd;
pub mod vtk;

/// A volume file format.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Format {
    /// NRRD (`.nrrd`, or a detached `.nhdr` header), raw, gzip or ASCII encoded.
    Nrrd,
    /// NIfTI-1 (`.nii`, `.nii.gz`, or a `.hdr` + `.img` pair).
    Nifti,
    /// MRC (cryo-EM) or CCP4 (crystallography) map.
    Mrc,
    /// Gaussian cube.
    Cube,
    /// VTK legacy `STRUCTURED_POINTS`, ASCII or binary.
    Vtk,
}

impl Format {
    /// Every format.
    pub const ALL: [Format; 5] = [Format::Nrrd, Format::Nifti, Format::Mrc, Format::Cube, Format::Vtk];

    /// Its usual name.
    pub fn name(self) -> &'static str {
        match self {
            Format::Nrrd => "NRRD",
            Format::Nifti => "NIfTI-1",
            Format::Mrc => "MRC/CCP4",
            Format::Cube => "Gaussian cube",
            Format::Vtk => "VTK legacy",
        }
    }

    /// The file name endings it is known by (lower case, without the dot,
    /// before any `.gz`), the usual ones first.
    pub fn extensions(self) -> &'static [&'static str] {
        match self {
            Format::Nrrd => &["nrrd", "nhdr"],
            Format::Nifti => &["nii", "hdr"],
            Format::Mrc => &["mrc", "map", "ccp4", "mrcs", "rec"],
            Format::Cube => &["cube", "cub"],
            Format::Vtk => &["vtk"],
        }
    }

    /// The format a file name tells (case-insensitive; any of these may end
    /// in `.gz`): one of its [`Format::extensions`].
    pub fn from_name(path: &Path) -> Option<Format> {
        let ext = extension(path)?;
        Format::ALL.into_iter().find(|f| f.extensions().contains(&ext.as_str()))
    }

    /// The format the first bytes of a file show (gunzipped already), if
    /// they have a signature: `NRRD000`, `# vtk DataFile`, NIfTI-1's `n+1`
    /// at byte 344, MRC/CCP4's `MAP ` at byte 208. (A cube file has none.)
    pub fn sniff(head: &[u8]) -> Option<Format> {
        if head.starts_with(b"NRRD000") {
            Some(Format::Nrrd)
        } else if head.starts_with(b"# vtk DataFile") {
            Some(Format::Vtk)
        } else if head.get(344..348) == Some(b"n+1\0") && nifti::sizeof_hdr_endian(head).is_some() {
            Some(Format::Nifti)
        } else if head.get(208..212) == Some(b"MAP ") && head.len() >= 1024 {
            Some(Format::Mrc)
        } else {
            None
        }
    }
}

/// A file name's extension, lower case, before any `.gz`: `nii` for
/// `Head.NII.gz`.
pub fn extension(path: &Path) -> Option<String> {
    let name = path.file_name()?.to_str()?.to_ascii_lowercase();
    let name = name.strip_suffix(".gz").unwrap_or(&name);
    Some(name.rsplit_once('.')?.1.to_owned())
}

/// Default of [`Options::max_bytes`]: 2 GiB.
pub const DEFAULT_MAX_BYTES: usize = 2 << 30;

/// How a volume's axes are laid out when it is loaded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Orientation {
    /// As the file's header says the volume lies in space (`oriented`):
    /// a NIfTI file's sform, else its qform; a NRRD file's `space` and
    /// `space directions`; a cube file's axis vectors. A head is then shown
    /// upright and facing the viewer ([`crate::orient`]). A file that says
    /// nothing keeps its index order.
    #[default]
    File,
    /// The file's index axes as they are: x its first (fastest) axis, then
    /// y, then z (an MRC map's and a cube file's are still put x fastest).
    Index,
}

impl std::str::FromStr for Orientation {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "file" => Ok(Orientation::File),
            "index" => Ok(Orientation::Index),
            _ => Err(format!("unknown orientation `{s}` (expected file or index)")),
        }
    }
}

/// Which volume to take from a file that holds several, how large a
/// volume may be, and how to lay out its axes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Options {
    /// Index from 0 of the volume to load: a NIfTI's time point (the 4th
    /// dimension and on, flattened), a cube's orbital (or value per point),
    /// a VTK file's point scalar array (in file order). Default: the first.
    pub index: usize,
    /// The most bytes a volume's samples may take, in the file's sample
    /// type or as loaded, whichever is more: a header asking for more is
    /// refused before anything is allocated or read for the samples
    /// (`check_size`). Default [`DEFAULT_MAX_BYTES`], 2 GiB; the command
    /// line's `--max-volume-mb` sets it.
    pub max_bytes: usize,
    /// The file's orientation, or its index order. Default
    /// [`Orientation::File`]; the command line's `--orientation` sets it.
    pub orientation: Orientation,
}

impl Default for Options {
    fn default() -> Self {
        Options { index: 0, max_bytes: DEFAULT_MAX_BYTES, orientation: Orientation::File }
    }
}

/// A volume read from a file, and what the reader has to say about it.
#[derive(Debug, Clone, PartialEq)]
pub struct Loaded {
    /// The volume.
    pub volume: LoadedVolume,
    /// Its file's format.
    pub format: Format,
    /// Remarks for the user: samples converted with rounding, one of several
    /// volumes taken, a skew ignored, a unit.
    pub notes: Vec<String>,
}

/// A reader's volume, in the file's index order, laid out as `opts` say:
/// with [`Orientation::File`] and the file's `directions` of its index
/// axes (`what` names them for the notes: "sform", "space directions"),
/// rearranged by [`crate::orient::reduce`] with [`LoadedVolume::reoriented`]
/// and given the spacing the directions have. Directions that cannot
/// orient it (not finite, zero, coplanar) leave it in index order, with a
/// note saying why; so does a flat volume (an extent of 1), which is shown
/// as a 2D grid, face on.
pub(crate) fn oriented(mut loaded: Loaded, directions: Option<(Directions, &str)>, opts: &Options) -> Loaded {
    let Some((d, what)) = directions else { return loaded };
    if opts.orientation == Orientation::Index {
        return loaded;
    }
    let o = match reduce(&d) {
        Ok(o) => o,
        Err(e) => {
            loaded.notes.push(format!("not oriented by the {what} ({e}): shown in the file's index order"));
            return loaded;
        }
    };
    let Dims(nx, ny, nz) = loaded.volume.dims;
    if nx == 1 || ny == 1 || nz == 1 {
        if !o.map.is_identity() {
            loaded
                .notes
                .push(format!("a flat volume keeps the file's index order (not oriented by its {what})"));
        }
        return loaded;
    }
    loaded.volume.spacing = o.spacing;
    if !o.map.is_identity() {
        loaded.volume = loaded.volume.reoriented(o.map);
        loaded.notes.push(format!(
            "oriented by the {what}: {} (--orientation index keeps the file's order)",
            o.describe()
        ));
    }
    loaded
}

/// Read `path` if its name or (failing that) its first bytes tell one of
/// these formats; `Ok(None)` if they tell none, or the file cannot be opened
/// to look (the caller's raw reader then reports that).
pub fn read(path: &Path, opts: &Options) -> Result<Option<Loaded>> {
    let format = match Format::from_name(path).or_else(|| sniff_file(path)) {
        Some(f) => f,
        None => return Ok(None),
    };
    read_as(path, format, opts).map(Some)
}

/// Read `path` as `format`.
pub fn read_as(path: &Path, format: Format, opts: &Options) -> Result<Loaded> {
    Input::open(path)
        .and_then(|input| read_input(input, format, Some(path), opts))
        .with_context(|| format!("cannot load {} as {}", path.display(), format.name()))
}

/// Read a file's bytes, already in memory (a file dropped on a web page):
/// gzip is inflated as it is read, and `name` or (failing that) the first
/// bytes tell the format, as [`read`] does; `Ok(None)` if they tell none.
/// A detached NRRD header or a NIfTI `.hdr` is refused: its data are in
/// another file.
pub fn read_bytes(name: &str, bytes: &[u8], opts: &Options) -> Result<Option<Loaded>> {
    let mut input = Input::from_slice(bytes);
    if is_gzip(bytes) {
        input = input.gunzip_rest();
    }
    let format = match Format::from_name(Path::new(name)).or_else(|| sniff(&mut input)) {
        Some(f) => f,
        None => return Ok(None),
    };
    read_input(input, format, None, opts)
        .with_context(|| format!("cannot load {name} as {}", format.name()))
        .map(Some)
}

/// Read `input` as `format`; `path` is the file's, where a header may name
/// a data file beside it (none for bytes in memory).
fn read_input(mut input: Input<'_>, format: Format, path: Option<&Path>, opts: &Options) -> Result<Loaded> {
    match format {
        Format::Nrrd => nrrd::read_from(input, path.and_then(Path::parent), opts),
        Format::Nifti => nifti::read_from(input, path, opts),
        Format::Mrc => mrc::read_from(&mut input, opts),
        Format::Cube => cube::read_from(&mut input, opts),
        Format::Vtk => vtk::read_from(&mut input, opts),
    }
}

/// Check that `opts` asks for the one volume of a single-volume format.
pub(crate) fn single_volume(opts: &Options) -> Result<()> {
    if opts.index > 0 {
        bail!("the file holds one volume; volume {} was asked for", opts.index);
    }
    Ok(())
}

/// Check, from a header's extents `dims` and sample type, that the samples
/// fit within `max_bytes` ([`Options::max_bytes`]) in the file's type and
/// as loaded; their bytes in the file's type. Call it before allocating or
/// reading anything for them.
pub(crate) fn check_size(dims: &[usize], elem: Elem, max_bytes: usize) -> Result<usize> {
    let stored = byte_len(dims, elem)?;
    let count = dims.iter().try_fold(1usize, |a, &d| a.checked_mul(d));
    let loaded = count.and_then(|c| c.checked_mul(elem.loads_as().size()));
    let need = loaded.with_context(|| format!("the extents {dims:?} overflow"))?.max(stored);
    if need > max_bytes {
        let shape = dims.iter().map(ToString::to_string).collect::<Vec<_>>().join("x");
        bail!(
            "the volume's {shape} {} samples take {}, more than the limit of {} (--max-volume-mb raises it)",
            elem.name(),
            amount(need, false),
            amount(max_bytes, true)
        );
    }
    Ok(stored)
}

/// Bytes for messages: `2752512 bytes (2.6 MiB)`, `24 bytes`, or (if
/// `whole` and they are) `2048 MiB`.
fn amount(bytes: usize, whole: bool) -> String {
    const MIB: usize = 1 << 20;
    match (bytes / MIB, bytes % MIB) {
        (m, 0) if whole && m > 0 => format!("{m} MiB"),
        (0, _) => format!("{bytes} bytes"),
        (m, 0) => format!("{bytes} bytes ({m} MiB)"),
        _ => format!("{bytes} bytes ({:.1} MiB)", bytes as f64 / MIB as f64),
    }
}

/// Bytes of text a header may run to (its fields, comments, atom lines):
/// a stream that never ends its header stops here.
pub(crate) const HEADER_TEXT: u64 = 4 << 20;
/// Bytes of text a value in text data may take with its separators; text
/// data stop at this many bytes a value the header declares (plus
/// [`TEXT_SLACK`]), so a gigantic or endless text stream ends.
pub(crate) const TEXT_PER_VALUE: u64 = 64;
/// Bytes of text allowed beyond [`TEXT_PER_VALUE`] per value: line ends,
/// blank lines, a comment at the end.
pub(crate) const TEXT_SLACK: u64 = 64 << 10;
/// Longest token of text data: a number is far shorter.
const LONGEST_TOKEN: usize = 256;
/// Bytes the input buffers.
const BUFFER: usize = 64 << 10;

/// A volume file, or a part of one, as a stream of bytes that a reader
/// takes in order, never more than it asks for: a header's first bytes
/// ([`Input::head`]) or text lines ([`Input::line`]), then the data the
/// header declares ([`Input::data`]: exactly that many bytes, and whether
/// more follow), or text values ([`Input::token`]), at most
/// [`Input::allow_text`] bytes of them. Nothing is read ahead beyond a
/// small buffer, so a file is never held whole before its header has said
/// what it holds, and a stream without end (`/dev/zero`, a FIFO) stops
/// where the header's sizes do. A gzip file is inflated as it is read.
pub(crate) struct Input<'a> {
    src: Box<dyn Read + 'a>,
    /// Bytes read from `src` are `buf[..end]`, those before `at` taken
    /// already.
    buf: Box<[u8]>,
    at: usize,
    end: usize,
    /// Bytes taken so far.
    pos: u64,
    /// Whether `src` inflates gzip (for error messages).
    gzip: bool,
    /// Bytes in all, when known (a regular file, a slice; not gzip).
    size: Option<u64>,
    /// Bytes taken as text, how many may be, and the last allowance.
    text: u64,
    text_cap: u64,
    text_allowed: u64,
    text_why: String,
    /// Line ends taken as text.
    lines: usize,
    /// Whether the last line ended at the end of the stream, not in `\n`.
    cut: bool,
}

impl<'a> Input<'a> {
    fn new(src: Box<dyn Read + 'a>, gzip: bool, size: Option<u64>) -> Self {
        Input {
            src,
            buf: vec![0; BUFFER].into_boxed_slice(),
            at: 0,
            end: 0,
            pos: 0,
            gzip,
            size,
            text: 0,
            text_cap: HEADER_TEXT,
            text_allowed: HEADER_TEXT,
            text_why: "a header takes".to_string(),
            lines: 0,
            cut: false,
        }
    }

    /// Open `path`, inflating it as it is read if it starts like gzip.
    pub(crate) fn open(path: &Path) -> Result<Input<'static>> {
        Self::open_as(path, true)
    }

    /// Open `path` as it is (a raw file whose first bytes happen to look
    /// like gzip is still raw).
    pub(crate) fn open_plain(path: &Path) -> Result<Input<'static>> {
        Self::open_as(path, false)
    }

    fn open_as(path: &Path, gunzip: bool) -> Result<Input<'static>> {
        let cannot = || format!("cannot read {}", path.display());
        let file = std::fs::File::open(path).with_context(cannot)?;
        let size = file.metadata().ok().filter(|m| m.is_file()).map(|m| m.len());
        let mut r = std::io::BufReader::new(file);
        if gunzip && is_gzip(std::io::BufRead::fill_buf(&mut r).with_context(cannot)?) {
            return Ok(Input::new(Box::new(flate2::bufread::MultiGzDecoder::new(r)), true, None));
        }
        Ok(Input::new(Box::new(r), false, size))
    }

    /// Bytes in memory, taken as they are.
    pub(crate) fn from_slice(bytes: &'a [u8]) -> Self {
        Input::new(Box::new(bytes), false, Some(bytes.len() as u64))
    }

    /// The rest of the stream, inflated as gzip (positions and text
    /// allowance start again from 0).
    pub(crate) fn gunzip_rest(self) -> Input<'a> {
        let rest = self.avail().to_vec();
        let src = std::io::BufReader::new(std::io::Cursor::new(rest).chain(self.src));
        Input::new(Box::new(flate2::bufread::MultiGzDecoder::new(src)), true, None)
    }

    /// Bytes taken so far.
    pub(crate) fn pos(&self) -> u64 {
        self.pos
    }

    /// Bytes left, when the stream's length is known (an uncompressed
    /// regular file, a slice).
    pub(crate) fn remaining(&self) -> Option<u64> {
        self.size.map(|s| s.saturating_sub(self.pos))
    }

    /// The number of the line that text reads are in, from 1.
    pub(crate) fn line_no(&self) -> usize {
        self.lines + 1
    }

    /// Whether the last [`Input::line`] ended at the end of the stream
    /// rather than in a line end.
    pub(crate) fn line_was_cut(&self) -> bool {
        self.cut
    }

    fn read_error(&self, e: std::io::Error) -> anyhow::Error {
        if self.gzip {
            anyhow::anyhow!("cannot gunzip: the gzip data are corrupt or cut short ({e})")
        } else {
            anyhow::anyhow!("read error ({e})")
        }
    }

    /// Buffered bytes not yet taken.
    fn avail(&self) -> &[u8] {
        self.buf.get(self.at..self.end).unwrap_or_default()
    }

    /// Read more into the buffer; `false` at the end of the stream.
    fn fill(&mut self) -> Result<bool> {
        if self.at > 0 {
            self.buf.copy_within(self.at..self.end, 0);
            self.end -= self.at;
            self.at = 0;
        }
        if self.end >= self.buf.len() {
            return Ok(true);
        }
        loop {
            match self.src.read(self.buf.get_mut(self.end..).unwrap_or_default()) {
                Ok(n) => {
                    self.end += n;
                    return Ok(n > 0);
                }
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(self.read_error(e)),
            }
        }
    }

    fn consume(&mut self, n: usize) {
        let n = n.min(self.avail().len());
        self.at += n;
        self.pos += n as u64;
    }

    /// The next bytes without taking them: `n` of them (at most 64 KiB),
    /// fewer only at the end of the stream.
    pub(crate) fn peek(&mut self, n: usize) -> Result<&[u8]> {
        let n = n.min(BUFFER);
        while self.avail().len() < n && self.fill()? {}
        Ok(self.avail().get(..n).unwrap_or(self.avail()))
    }

    /// Take up to `n` bytes: fewer only at the end of the stream. Memory
    /// grows with the bytes that come, not with `n`.
    pub(crate) fn head(&mut self, n: usize) -> Result<Vec<u8>> {
        let mut out: Vec<u8> = Vec::new();
        while out.len() < n {
            if self.avail().is_empty() && !self.fill()? {
                break;
            }
            let k = self.avail().len().min(n - out.len());
            if out.capacity() - out.len() < k {
                // Double, but never past `n`.
                let more = (n - out.len()).min(out.capacity().max(BUFFER));
                out.try_reserve_exact(more)
                    .map_err(|e| anyhow::anyhow!("cannot allocate {n} bytes ({e})"))?;
            }
            out.extend_from_slice(self.avail().get(..k).unwrap_or_default());
            self.consume(k);
        }
        Ok(out)
    }

    /// Pass over up to `n` bytes without keeping them; how many there were.
    fn skip(&mut self, n: u64) -> Result<u64> {
        let mut done = 0;
        while done < n {
            if self.avail().is_empty() && !self.fill()? {
                break;
            }
            let k = self.avail().len().min(usize::try_from(n - done).unwrap_or(usize::MAX));
            self.consume(k);
            done += k as u64;
        }
        Ok(done)
    }

    /// The data the header declares: exactly `len` bytes from here.
    pub(crate) fn data(&mut self, len: usize) -> Data<'_, 'a> {
        let start = self.pos;
        Data { input: self, start, len: len as u64 }
    }

    /// The next `len` bytes, the last of the input: short data and data
    /// after them are both errors ([`Data::take`], [`Data::finish`]).
    pub(crate) fn exactly(&mut self, len: usize) -> Result<Vec<u8>> {
        let mut data = self.data(len);
        let bytes = data.take(len)?;
        data.finish()?;
        Ok(bytes)
    }

    /// Allow `bytes` more bytes of text from here on ([`Input::line`],
    /// [`Input::token`]) for `why` (as in "12 values take"), instead of what
    /// was allowed before. At first a header's worth, [`HEADER_TEXT`].
    pub(crate) fn allow_text(&mut self, bytes: u64, why: impl Into<String>) {
        self.text_cap = self.text.saturating_add(bytes);
        self.text_allowed = bytes;
        self.text_why = why.into();
    }

    /// Take `n` buffered bytes as text, holding `newlines` line ends.
    fn take_text(&mut self, n: usize, newlines: usize) -> Result<()> {
        if self.text.saturating_add(n as u64) > self.text_cap {
            bail!(
                "the text runs on for more than {} bytes, more than {} (a gigantic or endless file?)",
                self.text_allowed,
                self.text_why
            );
        }
        self.text += n as u64;
        self.lines += newlines;
        self.consume(n);
        Ok(())
    }

    /// The next line of text, without its `\n` (or `\r\n`); `None` at the
    /// end of the stream.
    pub(crate) fn line(&mut self) -> Result<Option<Vec<u8>>> {
        let mut line = Vec::new();
        loop {
            if self.avail().is_empty() && !self.fill()? {
                self.cut = !line.is_empty();
                return Ok((!line.is_empty()).then_some(line));
            }
            let a = self.avail();
            let (k, end) = match a.iter().position(|&c| c == b'\n') {
                Some(i) => (i + 1, true),
                None => (a.len(), false),
            };
            line.extend_from_slice(a.get(..k).unwrap_or_default());
            self.take_text(k, usize::from(end))?;
            if end {
                line.pop();
                if line.last() == Some(&b'\r') {
                    line.pop();
                }
                self.cut = false;
                return Ok(Some(line));
            }
        }
    }

    /// The next value of text data into `tok`: a run of bytes between
    /// white space (and commas, if `comma`); `false` at the end of the
    /// stream. Bytes that are not UTF-8 become U+FFFD (and the value then
    /// fails to parse).
    pub(crate) fn token(&mut self, tok: &mut String, comma: bool) -> Result<bool> {
        let sep = |c: u8| c.is_ascii_whitespace() || (comma && c == b',');
        loop {
            if self.avail().is_empty() && !self.fill()? {
                return Ok(false);
            }
            let a = self.avail();
            let k = a.iter().position(|&c| !sep(c)).unwrap_or(a.len());
            let newlines = a.get(..k).unwrap_or_default().iter().filter(|&&c| c == b'\n').count();
            let more = k == a.len();
            self.take_text(k, newlines)?;
            if !more {
                break;
            }
        }
        let mut bytes = Vec::new();
        loop {
            if self.avail().is_empty() && !self.fill()? {
                break;
            }
            let a = self.avail();
            let k = a.iter().position(|&c| sep(c)).unwrap_or(a.len());
            if bytes.len() + k > LONGEST_TOKEN {
                bail!(
                    "a value of more than {LONGEST_TOKEN} characters in line {}: not text data",
                    self.line_no()
                );
            }
            bytes.extend_from_slice(a.get(..k).unwrap_or_default());
            let more = k == a.len();
            self.take_text(k, 0)?;
            if !more {
                break;
            }
        }
        tok.clear();
        tok.push_str(&String::from_utf8_lossy(&bytes));
        Ok(true)
    }
}

/// The data a header declares, [`Input::data`]: parts taken or passed over
/// in order, then [`Data::finish`] checks that no more follow.
pub(crate) struct Data<'i, 'a> {
    input: &'i mut Input<'a>,
    start: u64,
    len: u64,
}

impl Data<'_, '_> {
    /// Bytes of the data taken or passed over so far.
    fn done(&self) -> u64 {
        self.input.pos - self.start
    }

    fn short(&self) -> anyhow::Error {
        anyhow::anyhow!("the data stop after {} of {} bytes (truncated?)", self.done(), self.len)
    }

    fn room(&self, n: u64) -> Result<()> {
        if n > self.len.saturating_sub(self.done()) {
            bail!("internal: {n} bytes asked for past the {} bytes of data", self.len);
        }
        Ok(())
    }

    /// Take the next `n` bytes of the data.
    pub(crate) fn take(&mut self, n: usize) -> Result<Vec<u8>> {
        self.room(n as u64)?;
        let v = self.input.head(n)?;
        if v.len() < n {
            return Err(self.short());
        }
        Ok(v)
    }

    /// Pass over the next `n` bytes of the data.
    pub(crate) fn skip(&mut self, n: u64) -> Result<()> {
        self.room(n)?;
        if self.input.skip(n)? < n {
            return Err(self.short());
        }
        Ok(())
    }

    /// Pass over what is left of the data, and check that nothing follows.
    pub(crate) fn finish(&mut self) -> Result<()> {
        self.skip(self.len.saturating_sub(self.done()))?;
        if !self.input.peek(1)?.is_empty() {
            bail!(
                "{} bytes of data expected, {} follow",
                self.len,
                match self.input.remaining() {
                    Some(k) => format!("and {k} more"),
                    None => "more".to_string(),
                }
            );
        }
        Ok(())
    }
}

/// The format the first KiB of the file (gunzipped if need be) shows.
fn sniff_file(path: &Path) -> Option<Format> {
    sniff(&mut Input::open(path).ok()?)
}

/// The format the first KiB of `input` shows, leaving them unread.
fn sniff(input: &mut Input<'_>) -> Option<Format> {
    // A read error (a short or corrupt stream) still leaves what came.
    let _ = input.peek(1024);
    Format::sniff(input.avail())
}

/// Whether `bytes` start like a gzip stream.
pub(crate) fn is_gzip(bytes: &[u8]) -> bool {
    bytes.starts_with(&[0x1f, 0x8b])
}

/// Byte order of binary samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Endian {
    /// Least significant byte first.
    Little,
    /// Most significant byte first.
    Big,
}

/// A sample type as a file stores it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Elem {
    /// Signed 8-bit.
    I8,
    /// Unsigned 8-bit.
    U8,
    /// Signed 16-bit.
    I16,
    /// Unsigned 16-bit.
    U16,
    /// Signed 32-bit.
    I32,
    /// Unsigned 32-bit.
    U32,
    /// Signed 64-bit.
    I64,
    /// Unsigned 64-bit.
    U64,
    /// IEEE 754 half.
    F16,
    /// IEEE 754 single.
    F32,
    /// IEEE 754 double.
    F64,
}

impl Elem {
    /// Bytes per sample.
    pub fn size(self) -> usize {
        match self {
            Elem::I8 | Elem::U8 => 1,
            Elem::I16 | Elem::U16 | Elem::F16 => 2,
            Elem::I32 | Elem::U32 | Elem::F32 => 4,
            Elem::I64 | Elem::U64 | Elem::F64 => 8,
        }
    }

    /// Its name, as in `int16`.
    pub fn name(self) -> &'static str {
        match self {
            Elem::I8 => "int8",
            Elem::U8 => "uint8",
            Elem::I16 => "int16",
            Elem::U16 => "uint16",
            Elem::I32 => "int32",
            Elem::U32 => "uint32",
            Elem::I64 => "int64",
            Elem::U64 => "uint64",
            Elem::F16 => "float16",
            Elem::F32 => "float32",
            Elem::F64 => "float64",
        }
    }

    /// The sample type it loads as.
    pub fn loads_as(self) -> Dtype {
        match self {
            Elem::U8 => Dtype::U8,
            Elem::I8 | Elem::I16 => Dtype::I16,
            Elem::U16 => Dtype::U16,
            _ => Dtype::F32,
        }
    }

    /// Whether loading it as [`Elem::loads_as`] may round.
    pub fn rounds(self) -> bool {
        matches!(self, Elem::I32 | Elem::U32 | Elem::I64 | Elem::U64 | Elem::F64)
    }

    /// A note for [`Loaded::notes`] when loading it rounds.
    pub(crate) fn note(self) -> Option<String> {
        self.rounds().then(|| {
            format!(
                "{} samples are loaded as f32 ({})",
                self.name(),
                if self == Elem::F64 {
                    "rounded to single precision"
                } else {
                    "exact up to 2^24 in magnitude"
                }
            )
        })
    }
}

impl From<Dtype> for Elem {
    fn from(d: Dtype) -> Elem {
        match d {
            Dtype::U8 => Elem::U8,
            Dtype::U16 => Elem::U16,
            Dtype::I16 => Elem::I16,
            Dtype::F32 => Elem::F32,
        }
    }
}

impl From<crate::volume::Endian> for Endian {
    fn from(e: crate::volume::Endian) -> Endian {
        match e {
            crate::volume::Endian::Little => Endian::Little,
            crate::volume::Endian::Big => Endian::Big,
        }
    }
}

/// Bytes of `dims` samples of `elem`, or an error if that overflows.
pub(crate) fn byte_len(dims: &[usize], elem: Elem) -> Result<usize> {
    dims.iter()
        .try_fold(elem.size(), |a, &d| a.checked_mul(d))
        .with_context(|| format!("the extents {dims:?} overflow"))
}

/// Decode binary samples; `bytes.len()` is a multiple of `elem.size()`
/// (anything past the last whole sample is ignored). `u8` samples keep
/// the bytes' memory.
pub(crate) fn decode(bytes: Vec<u8>, elem: Elem, endian: Endian) -> Samples {
    fn words<const N: usize, T>(
        bytes: &[u8],
        endian: Endian,
        le: fn([u8; N]) -> T,
        be: fn([u8; N]) -> T,
    ) -> Vec<T> {
        let f = if endian == Endian::Little { le } else { be };
        bytes.chunks_exact(N).map(|c| f(c.try_into().unwrap_or([0; N]))).collect()
    }
    let b = &bytes[..];
    match elem {
        Elem::U8 => Samples::U8(bytes),
        Elem::I8 => Samples::I16(b.iter().map(|&b| i16::from(b as i8)).collect()),
        Elem::I16 => Samples::I16(words(b, endian, i16::from_le_bytes, i16::from_be_bytes)),
        Elem::U16 => Samples::U16(words(b, endian, u16::from_le_bytes, u16::from_be_bytes)),
        Elem::F16 => Samples::F32(
            words(b, endian, u16::from_le_bytes, u16::from_be_bytes).into_iter().map(f16_to_f32).collect(),
        ),
        Elem::F32 => Samples::F32(words(b, endian, f32::from_le_bytes, f32::from_be_bytes)),
        Elem::I32 => Samples::F32(
            words(b, endian, i32::from_le_bytes, i32::from_be_bytes).into_iter().map(|v| v as f32).collect(),
        ),
        Elem::U32 => Samples::F32(
            words(b, endian, u32::from_le_bytes, u32::from_be_bytes).into_iter().map(|v| v as f32).collect(),
        ),
        Elem::I64 => Samples::F32(
            words(b, endian, i64::from_le_bytes, i64::from_be_bytes).into_iter().map(|v| v as f32).collect(),
        ),
        Elem::U64 => Samples::F32(
            words(b, endian, u64::from_le_bytes, u64::from_be_bytes).into_iter().map(|v| v as f32).collect(),
        ),
        Elem::F64 => Samples::F32(
            words(b, endian, f64::from_le_bytes, f64::from_be_bytes).into_iter().map(|v| v as f32).collect(),
        ),
    }
}

/// Samples as `f32` (exact for the integer types).
pub(crate) fn to_f32(samples: Samples) -> Vec<f32> {
    match samples {
        Samples::U8(v) => v.into_iter().map(f32::from).collect(),
        Samples::U16(v) => v.into_iter().map(f32::from).collect(),
        Samples::I16(v) => v.into_iter().map(f32::from).collect(),
        Samples::F32(v) => v,
    }
}

/// An IEEE 754 half as a single (exact).
pub(crate) fn f16_to_f32(h: u16) -> f32 {
    let sign = u32::from(h >> 15) << 31;
    let exp = u32::from((h >> 10) & 0x1f);
    let man = u32::from(h & 0x3ff);
    let bits = match (exp, man) {
        (0, 0) => sign,
        (0, m) => {
            // Subnormal: m * 2^-24.
            let v = m as f32 * (1.0 / 16_777_216.0);
            return if sign != 0 { -v } else { v };
        }
        (0x1f, m) => sign | 0x7f80_0000 | (m << 13),
        (e, m) => sign | ((e + 112) << 23) | (m << 13),
    };
    f32::from_bits(bits)
}

/// Samples from numbers in text data: exactly `count` values taken from
/// `input` ([`Input::token`], commas separating too if `comma`), parsed as
/// `elem` (integers must be whole and in range), of which those at `keep.0`,
/// `keep.0 + keep.1`, ... are kept (several values to a point: one of them).
/// `what` names the values in errors. The caller has allowed the text
/// ([`Input::allow_text`]).
pub(crate) fn parse_text(
    input: &mut Input<'_>,
    comma: bool,
    count: usize,
    keep: (usize, usize),
    elem: Elem,
    what: &str,
) -> Result<Samples> {
    fn take<T>(
        input: &mut Input<'_>,
        (comma, count, keep): (bool, usize, (usize, usize)),
        what: &str,
        elem: Elem,
        conv: impl Fn(f64) -> Option<T>,
    ) -> Result<Vec<T>> {
        let step = keep.1.max(1);
        // Grow as values come: the count is the file's word, not yet its data.
        let mut out = Vec::with_capacity((count / step).min(1 << 20));
        let mut tok = String::new();
        for i in 0..count {
            if !input.token(&mut tok, comma)? {
                bail!("the {what} are truncated: {i} of {count} values");
            }
            let v = parse_number(&tok).and_then(&conv).with_context(|| {
                format!("value {} of the {what}, `{tok}`, is not a valid {}", i + 1, elem.name())
            })?;
            if i % step == keep.0 {
                out.push(v);
            }
        }
        Ok(out)
    }
    fn int<T: TryFrom<i64>>(v: f64) -> Option<T> {
        if v.fract() != 0.0 || !(-9.3e18..9.3e18).contains(&v) {
            return None;
        }
        T::try_from(v as i64).ok()
    }
    let how = (comma, count, keep);
    Ok(match elem {
        Elem::U8 => Samples::U8(take(input, how, what, elem, int::<u8>)?),
        Elem::I8 => Samples::I16(take(input, how, what, elem, |v| int::<i8>(v).map(i16::from))?),
        Elem::I16 => Samples::I16(take(input, how, what, elem, int::<i16>)?),
        Elem::U16 => Samples::U16(take(input, how, what, elem, int::<u16>)?),
        _ => Samples::F32(take(input, how, what, elem, |v| Some(v as f32))?),
    })
}

/// A number in text: decimal, `nan`, `inf`, or with a Fortran `D` exponent.
pub(crate) fn parse_number(tok: &str) -> Option<f64> {
    tok.parse().ok().or_else(|| tok.replace(['D', 'd'], "E").parse().ok())
}

/// Reorder samples stored with file axes of extents `n` (fastest first),
/// file axis `i` running along space axis `axis[i]` (0 = x, 1 = y, 2 = z),
/// into x-fastest order ([`crate::volume::remap`]). Returns them with
/// `(nx, ny, nz)`.
///
/// # Errors
/// `axis` is not a permutation of 0, 1, 2.
pub(crate) fn permute(samples: Samples, n: [usize; 3], axis: [usize; 3]) -> Result<(Samples, Dims)> {
    let map =
        AxisMap::placing(axis).with_context(|| format!("internal: axes {axis:?} are no permutation"))?;
    Ok(crate::volume::remap(samples, n, map))
}

/// A usable voxel size from a file's word: its magnitude when finite and
/// non-zero, else 1.
pub(crate) fn voxel_size(v: f64) -> f32 {
    let a = v.abs() as f32;
    if a.is_finite() && a > 0.0 { a } else { 1.0 }
}

/// A text line's bytes as a trimmed `str` (lossy: header lines are ASCII).
pub(crate) fn text(line: &[u8]) -> String {
    String::from_utf8_lossy(line).trim().to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_tell_formats() {
        for (name, f) in [
            ("a.nrrd", Format::Nrrd),
            ("a.NHDR", Format::Nrrd),
            ("a.nii", Format::Nifti),
            ("a.nii.gz", Format::Nifti),
            ("a.hdr", Format::Nifti),
            ("emd_3001.map.gz", Format::Mrc),
            ("x.ccp4", Format::Mrc),
            ("x.mrcs", Format::Mrc),
            ("N2O_homo+lumo.cube.gz", Format::Cube),
            ("a.cub", Format::Cube),
            ("a.vtk", Format::Vtk),
        ] {
            assert_eq!(Format::from_name(Path::new(name)), Some(f), "{name}");
        }
        for name in ["a.raw", "a.den", "a", "a.gz", "nii"] {
            assert_eq!(Format::from_name(Path::new(name)), None, "{name}");
        }
    }

    #[test]
    fn first_bytes_tell_formats_without_a_known_name() {
        let nii = nifti::tests::file(&[2, 1, 1], 2, 8, [1.0; 3], (0.0, 0.0), b"n+1\0", false, &[3, 4]);
        let mut mrc = vec![0u8; 1024];
        mrc[208..212].copy_from_slice(b"MAP ");
        assert_eq!(Format::sniff(b"NRRD0005\ntype: uchar"), Some(Format::Nrrd));
        assert_eq!(Format::sniff(b"# vtk DataFile Version 2.0\n"), Some(Format::Vtk));
        assert_eq!(Format::sniff(&nii), Some(Format::Nifti));
        assert_eq!(Format::sniff(&mrc), Some(Format::Mrc));
        assert_eq!(Format::sniff(&mrc[..1000]), None);
        assert_eq!(Format::sniff(&[0u8; 2048]), None);
        let dir = std::env::temp_dir().join(format!("isoscope-sniff-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("scan.bin");
        std::fs::write(&path, &nii).unwrap();
        let l = read(&path, &Options::default()).unwrap().unwrap();
        assert_eq!((l.format, l.volume.samples), (Format::Nifti, Samples::U8(vec![3, 4])));
        // Gzip compressed, still sniffed.
        let mut z = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
        std::io::Write::write_all(&mut z, &nii).unwrap();
        std::fs::write(&path, z.finish().unwrap()).unwrap();
        assert_eq!(read(&path, &Options::default()).unwrap().unwrap().format, Format::Nifti);
        // Raw samples, and a missing file: not this module's (the raw reader reports).
        std::fs::write(&path, [0u8; 400]).unwrap();
        assert!(read(&path, &Options::default()).unwrap().is_none());
        assert!(read(&dir.join("missing.raw"), &Options::default()).unwrap().is_none());
        // A known name whose file is missing: an error naming it.
        let e = format!("{:#}", read(&dir.join("missing.nrrd"), &Options::default()).unwrap_err());
        assert!(e.contains("cannot load") && e.contains("missing.nrrd") && e.contains("as NRRD"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn decode_every_type_both_orders() {
        let le = |v: &[u8]| decode(v.to_vec(), Elem::I16, Endian::Little);
        assert_eq!(le(&[0x34, 0x12, 0xff, 0xff]), Samples::I16(vec![0x1234, -1]));
        assert_eq!(decode([0x12, 0x34].to_vec(), Elem::U16, Endian::Big), Samples::U16(vec![0x1234]));
        assert_eq!(decode([0x80, 0x7f].to_vec(), Elem::I8, Endian::Big), Samples::I16(vec![-128, 127]));
        assert_eq!(decode(1.5f32.to_be_bytes().to_vec(), Elem::F32, Endian::Big), Samples::F32(vec![1.5]));
        assert_eq!(
            decode((-7i32).to_le_bytes().to_vec(), Elem::I32, Endian::Little),
            Samples::F32(vec![-7.0])
        );
        assert_eq!(
            decode(u32::MAX.to_be_bytes().to_vec(), Elem::U32, Endian::Big),
            Samples::F32(vec![4294967296.0])
        );
        assert_eq!(decode((-3i64).to_be_bytes().to_vec(), Elem::I64, Endian::Big), Samples::F32(vec![-3.0]));
        assert_eq!(decode(9u64.to_le_bytes().to_vec(), Elem::U64, Endian::Little), Samples::F32(vec![9.0]));
        assert_eq!(decode(0.1f64.to_be_bytes().to_vec(), Elem::F64, Endian::Big), Samples::F32(vec![0.1]));
        assert_eq!(decode([0x3c, 0x00].to_vec(), Elem::F16, Endian::Big), Samples::F32(vec![1.0]));
    }

    #[test]
    fn halves() {
        assert_eq!(f16_to_f32(0x3c00), 1.0);
        assert_eq!(f16_to_f32(0xc000), -2.0);
        assert_eq!(f16_to_f32(0x7bff), 65504.0);
        assert_eq!(f16_to_f32(0x0001), 2f32.powi(-24));
        assert_eq!(f16_to_f32(0x8001), -(2f32.powi(-24)));
        assert_eq!(f16_to_f32(0x3555), 0.333_251_95);
        assert_eq!(f16_to_f32(0x7c00), f32::INFINITY);
        assert!(f16_to_f32(0x7e00).is_nan());
        assert_eq!(f16_to_f32(0x8000).to_bits(), (-0.0f32).to_bits());
    }

    #[test]
    fn permute_puts_x_fastest() {
        // File order z fastest (a cube file): value = 100 x + 10 y + z.
        let (nx, ny, nz) = (2, 3, 4);
        let mut file = Vec::new();
        for x in 0..nx {
            for y in 0..ny {
                for z in 0..nz {
                    file.push((100 * x + 10 * y + z) as f32);
                }
            }
        }
        let (s, d) = permute(Samples::F32(file), [nz, ny, nx], [2, 1, 0]).unwrap();
        assert_eq!(d, Dims(nx, ny, nz));
        let Samples::F32(v) = s else { panic!() };
        for z in 0..nz {
            for y in 0..ny {
                for x in 0..nx {
                    assert_eq!(v[x + nx * (y + ny * z)], (100 * x + 10 * y + z) as f32);
                }
            }
        }
        // Identity leaves it alone.
        let (s, d) = permute(Samples::U8(vec![1, 2, 3]), [3, 1, 1], [0, 1, 2]).unwrap();
        assert_eq!((s, d), (Samples::U8(vec![1, 2, 3]), Dims(3, 1, 1)));
        assert!(permute(Samples::U8(vec![1]), [1, 1, 1], [0, 0, 1]).is_err());
    }

    #[test]
    fn text_numbers() {
        let parse = |s: &str, count, elem| {
            parse_text(&mut Input::from_slice(s.as_bytes()), false, count, (0, 1), elem, "data")
        };
        let Samples::F32(v) = parse("1 2.5e1 -3.0D-01 nan", 4, Elem::F64).unwrap() else { panic!() };
        assert_eq!(&v[..3], [1.0, 25.0, -0.3]);
        assert!(v[3].is_nan());
        let e = |s: &str, elem| format!("{:#}", parse(s, 3, elem).unwrap_err());
        assert!(e("1 2", Elem::U8).contains("truncated: 2 of 3"), "{}", e("1 2", Elem::U8));
        assert!(e("1 256 3", Elem::U8).contains("value 2 of the data, `256`, is not a valid uint8"));
        assert!(e("1 2.5 3", Elem::I16).contains("`2.5`"));
        assert!(e("1 x 3", Elem::F32).contains("`x`"));
        assert_eq!(parse("-128\n127", 2, Elem::I8).unwrap(), Samples::I16(vec![-128, 127]));
        // Commas separate too if asked; every other value kept.
        let mut input = Input::from_slice(b"1,2, 3 ,4");
        assert_eq!(parse_text(&mut input, true, 4, (1, 2), Elem::U8, "d").unwrap(), Samples::U8(vec![2, 4]));
    }

    fn error<T: std::fmt::Debug>(r: Result<T>) -> String {
        format!("{:#}", r.unwrap_err())
    }

    #[test]
    fn input_takes_exactly_the_data_declared() {
        let mut input = Input::from_slice(b"headDATAmore");
        assert_eq!(input.peek(2).unwrap(), b"he");
        assert_eq!(input.head(4).unwrap(), b"head");
        let mut data = input.data(4);
        assert_eq!(data.take(4).unwrap(), b"DATA");
        assert_eq!(error(data.finish()), "4 bytes of data expected, and 4 more follow");
        let mut input = Input::from_slice(b"abc");
        let mut data = input.data(5);
        data.skip(1).unwrap();
        assert_eq!(error(data.take(4)), "the data stop after 3 of 5 bytes (truncated?)");
        let mut input = Input::from_slice(b"abcd");
        let mut data = input.data(3);
        assert!(error(data.take(4)).contains("internal"));
        data.skip(1).unwrap();
        assert_eq!(data.take(2).unwrap(), b"bc");
        assert!(error(data.finish()).contains("and 1 more follow"));
        // A head asks for at most: fewer at the end.
        let mut input = Input::from_slice(b"ab");
        assert_eq!(input.head(1 << 40).unwrap(), b"ab");
        assert_eq!(input.head(8).unwrap(), b"");
        assert_eq!(input.data(0).finish().unwrap(), ());
    }

    #[test]
    fn input_inflates_gzip_as_it_reads_and_stops_at_the_data() {
        use std::io::Write;
        let dir = std::env::temp_dir().join(format!("isoscope-input-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut z = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
        z.write_all(&[5u8; 1 << 20]).unwrap();
        let gz = z.finish().unwrap();
        let path = dir.join("a.gz");
        std::fs::write(&path, &gz).unwrap();
        let mut input = Input::open(&path).unwrap();
        let mut data = input.data(10);
        assert_eq!(data.take(10).unwrap(), [5; 10]);
        // The stream's length is not known: it says only that more follow.
        assert_eq!(error(data.finish()), "10 bytes of data expected, more follow");
        // Not inflated when opened as it is.
        assert_eq!(Input::open_plain(&path).unwrap().head(2).unwrap(), [0x1f, 0x8b]);
        assert_eq!(Input::open_plain(&path).unwrap().remaining(), Some(gz.len() as u64));
        // Cut short, or corrupt: the gzip error.
        std::fs::write(&path, &gz[..gz.len() / 2]).unwrap();
        let e = error(Input::open(&path).unwrap().data(1 << 20).take(1 << 20));
        assert!(e.contains("cannot gunzip: the gzip data are corrupt or cut short"), "{e}");
        let mut bad = gz.clone();
        let n = bad.len();
        bad[n - 6] ^= 0x55; // the CRC: found when the end is checked
        std::fs::write(&path, &bad).unwrap();
        let mut input = Input::open(&path).unwrap();
        let mut data = input.data(1 << 20);
        data.take(1 << 20).unwrap();
        assert!(error(data.finish()).contains("corrupt"));
        // The rest of a stream after a text header, inflated.
        let mut f = b"header\n".to_vec();
        f.extend_from_slice(&gz);
        let mut input = Input::from_slice(&f);
        assert_eq!(input.line().unwrap().unwrap(), b"header");
        let mut rest = input.gunzip_rest();
        let mut data = rest.data(1 << 20);
        assert_eq!(data.take(1 << 20).unwrap(), vec![5; 1 << 20]);
        data.finish().unwrap();
        assert!(error(Input::open(&dir.join("missing")).map(|_| ())).contains("cannot read"));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn text_reads_are_bounded() {
        let mut input = Input::from_slice(b"one\r\n\ntwo\nthree");
        assert_eq!(input.line().unwrap().unwrap(), b"one");
        assert_eq!(input.line().unwrap().unwrap(), b"");
        assert_eq!(input.line_no(), 3);
        assert_eq!(input.line().unwrap().unwrap(), b"two");
        assert!(!input.line_was_cut());
        assert_eq!(input.line().unwrap().unwrap(), b"three");
        assert!(input.line_was_cut());
        assert_eq!(input.line().unwrap(), None);
        // Blanks without end stop at the allowance.
        let blanks = format!("1{}2", " ".repeat(100_000));
        let mut input = Input::from_slice(blanks.as_bytes());
        input.allow_text(1000, "2 values take");
        let mut tok = String::new();
        assert!(input.token(&mut tok, false).unwrap() && tok == "1");
        let e = error(input.token(&mut tok, false));
        assert_eq!(
            e,
            "the text runs on for more than 1000 bytes, more than 2 values take (a gigantic or endless file?)"
        );
        // So does a line without end, even at first (a header's worth).
        let endless = vec![b'x'; (HEADER_TEXT + 1) as usize];
        assert!(error(Input::from_slice(&endless).line()).contains("more than a header takes"));
        // A value longer than a number is no value.
        let long = format!("1 {} 2", "9".repeat(300));
        let mut input = Input::from_slice(long.as_bytes());
        input.token(&mut tok, false).unwrap();
        assert!(
            error(input.token(&mut tok, false)).contains("a value of more than 256 characters in line 1")
        );
        // Commas, line ends, and the end.
        let mut input = Input::from_slice(b" a,b\n\nc ");
        let mut all = Vec::new();
        while input.token(&mut tok, true).unwrap() {
            all.push(tok.clone());
        }
        assert_eq!((all, input.line_no()), (vec!["a".to_string(), "b".into(), "c".into()], 3));
    }

    #[test]
    fn the_limit_counts_the_larger_of_the_file_and_loaded_types() {
        const GIB: usize = 1 << 30;
        assert_eq!(check_size(&[1024, 1024, 1024], Elem::U8, GIB).unwrap(), GIB);
        // int8 loads as i16: twice its bytes.
        assert_eq!(check_size(&[512, 1024, 1024], Elem::I8, GIB).unwrap(), GIB / 2);
        let e = error(check_size(&[1024, 1024, 1024], Elem::I8, GIB));
        assert_eq!(
            e,
            "the volume's 1024x1024x1024 int8 samples take 2147483648 bytes (2048 MiB), more than the limit \
             of 1024 MiB (--max-volume-mb raises it)"
        );
        // float64 loads as f32: its own bytes.
        assert!(
            error(check_size(&[256, 1024, 1024], Elem::F64, GIB * 2 - 1))
                .contains("limit of 2147483647 bytes (2048.0 MiB)")
        );
        assert!(error(check_size(&[usize::MAX, 2, 1], Elem::U8, GIB)).contains("overflow"));
        assert_eq!(Options::default().max_bytes, 2 * GIB);
    }
}
