//! Output files written whole or not at all.
//!
//! Every file a command writes (a PNG, an animation, an SVG or CSV, a WAV,
//! a samples list, the virtual board's snapshot) goes through
//! [`write_whole`]: into a temporary file beside it, renamed over it only
//! once all of it is written. A command that fails half-way, or refuses
//! its arguments, leaves an existing file as it was, and a viewer watching
//! a snapshot never reads half a picture.

use anyhow::{Context, Result};
use std::fs::{File, OpenOptions};
use std::io::{BufWriter, Write};
use std::path::Path;

/// What [`write_whole`] hands its writer: buffered, and seekable (a WAV
/// header is written last).
pub type Out<'a> = BufWriter<&'a mut File>;

/// Write `path` with `write`, whole or not at all: into a temporary file
/// in the same directory, renamed over `path` when `write` and the flush
/// succeed, removed otherwise. A path that exists and is not a regular
/// file (`/dev/null`, a pipe, a terminal) is written in place: a rename
/// would replace it.
///
/// # Errors
/// `write`'s error, or the file cannot be created, written or renamed;
/// each names the path.
pub fn write_whole<T>(path: &Path, write: impl FnOnce(&mut Out<'_>) -> Result<T>) -> Result<T> {
    let name = path.display();
    if std::fs::metadata(path).is_ok_and(|m| !m.is_file()) {
        let mut f =
            OpenOptions::new().write(true).open(path).with_context(|| format!("cannot open {name}"))?;
        let mut w = BufWriter::new(&mut f);
        let t = write(&mut w)?;
        w.flush().with_context(|| format!("cannot write {name}"))?;
        return Ok(t);
    }
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    // Created as `File::create` would (0666 less the umask), not 0600; by
    // our own opener, whose error is the system's alone (`tempfile_in`
    // adds the temporary file's path, a second name for the same fault).
    let open = |tmp: &Path| {
        let mut options = OpenOptions::new();
        options.read(true).write(true).create_new(true);
        #[cfg(unix)]
        std::os::unix::fs::OpenOptionsExt::mode(&mut options, 0o666);
        options.open(tmp)
    };
    let mut tmp = tempfile::Builder::new()
        .prefix(".isoscope-")
        .suffix(".part")
        .make_in(dir, open)
        .with_context(|| format!("cannot create {name}"))?;
    let t = {
        let mut w = BufWriter::new(tmp.as_file_mut());
        let t = write(&mut w)?;
        w.flush().with_context(|| format!("cannot write {name}"))?;
        t
    };
    tmp.persist(path).map_err(|e| e.error).with_context(|| format!("cannot write {name}"))?;
    Ok(t)
}

/// A warning for an output at `path` that is written as `format` ("a
/// PNG") whatever its name, when the name ends in an extension other than
/// `extensions` (compared in any case; the first is the usual one):
/// `x.jpg` for a PNG. `None` for a name with one of them, or with none
/// (`/dev/stdout`). Every command whose output's format is fixed (not
/// chosen by the name, as `--animate`'s is) warns with it, and writes.
pub fn misnamed(path: &Path, format: &str, extensions: &[&str]) -> Option<String> {
    let ext = path.extension()?.to_str().unwrap_or("?");
    if extensions.iter().any(|e| e.eq_ignore_ascii_case(ext)) {
        return None;
    }
    let usual = extensions.first().map_or(String::new(), |e| format!("; name it .{e}"));
    Some(format!("{}: written as {format}, whatever its .{ext} says{usual}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failed_write_leaves_the_old_file_and_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("k.gif");
        std::fs::write(&path, b"the old picture").unwrap();
        let e = write_whole::<()>(&path, |w| {
            w.write_all(b"half of a new")?;
            anyhow::bail!("the encoder failed")
        })
        .unwrap_err();
        assert_eq!(format!("{e:#}"), "the encoder failed");
        assert_eq!(std::fs::read(&path).unwrap(), b"the old picture");
        let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names, [std::ffi::OsString::from("k.gif")]);
        // A good write replaces it, with the usual permissions.
        let n = write_whole(&path, |w| Ok(w.write(b"new")?)).unwrap();
        assert_eq!(n, 3);
        assert_eq!(std::fs::read(&path).unwrap(), b"new");
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = std::fs::metadata(&path).unwrap().permissions().mode();
            assert_ne!(mode & 0o044, 0, "readable by others as File::create makes it: {mode:o}");
        }
    }

    #[test]
    fn devices_are_written_in_place_and_missing_directories_named() {
        write_whole(Path::new("/dev/null"), |w| Ok(w.write_all(b"gone")?)).unwrap();
        #[cfg(unix)]
        {
            use std::os::unix::fs::FileTypeExt;
            assert!(std::fs::metadata("/dev/null").unwrap().file_type().is_char_device());
        }
        let e = write_whole(Path::new("/nonexistent-dir/x.png"), |_| Ok(())).unwrap_err();
        assert!(format!("{e:#}").starts_with("cannot create /nonexistent-dir/x.png"), "{e:#}");
    }

    #[test]
    fn a_name_that_says_another_format_is_named() {
        let w = misnamed(Path::new("out/x.jpg"), "a PNG", &["png"]).unwrap();
        assert_eq!(w, "out/x.jpg: written as a PNG, whatever its .jpg says; name it .png");
        for ok in ["x.png", "X.PNG", "x", "/dev/stdout", ".png"] {
            assert_eq!(misnamed(Path::new(ok), "a PNG", &["png"]), None, "{ok}");
        }
        assert!(misnamed(Path::new("x.svg"), "CSV", &["csv", "txt"]).is_some());
        assert_eq!(misnamed(Path::new("x.TXT"), "CSV", &["csv", "txt"]), None);
    }
}
