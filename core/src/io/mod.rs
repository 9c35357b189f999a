//! Files: the output contract (`series.csv`, `summary.json`, `vtk/`) and the meshes read as input
//! (`gmsh`, `stl`).

pub mod checkpoint_file;
pub mod durable;
pub mod gmsh;
pub mod series;
pub mod stl;
pub mod vtk;
#[cfg(feature = "vtkhdf")]
pub mod vtkhdf;

pub use series::SeriesWriter;
pub use vtk::VtkWriter;

use crate::error::{GraniteError, Result};
use std::path::Path;

/// The bytes of an input file (a checkpoint, a mesh). Only a regular file is read, and one that
/// fits in memory: a FIFO would block the run before any stop request could be seen, a device
/// such as `/dev/urandom` would be read until memory runs out, and a regular file is read at the
/// disk's speed, so that a stop request is seen soon after.
pub fn read_input(path: &Path) -> Result<Vec<u8>> {
    read_input_until(path, &|| false)
}

/// Bytes read between two looks at the stop request: a second or less on a slow disk.
const READ_PIECE: usize = 16 << 20;

/// [`read_input`] that gives up between two pieces of the file once `stop()` says so (a signal
/// asking the run to stop while a checkpoint of gigabytes is read).
pub fn read_input_until(path: &Path, stop: &dyn Fn() -> bool) -> Result<Vec<u8>> {
    let meta = std::fs::metadata(path).map_err(|e| GraniteError::io(path, e))?;
    if !meta.is_file() {
        return Err(GraniteError::Setup(format!(
            "{} is {}, not a regular file: granite reads checkpoints and meshes from plain files",
            path.display(),
            file_kind(&meta.file_type())
        )));
    }
    // Read whole and then parsed: refused up front when it could not fit in memory twice.
    crate::memory::check(
        &format!("reading {}", path.display()),
        meta.len() as f64,
        "bytes",
        2.0,
        "is it the file you meant?",
    )?;
    use std::io::Read;
    let mut file = std::fs::File::open(path).map_err(|e| GraniteError::io(path, e))?;
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    loop {
        if stop() {
            return Err(GraniteError::Other(format!(
                "stopped while reading {} ({} of {} bytes read)",
                path.display(),
                bytes.len(),
                meta.len()
            )));
        }
        let read =
            (&mut file).take(READ_PIECE as u64).read_to_end(&mut bytes).map_err(|e| GraniteError::io(path, e))?;
        if read == 0 {
            return Ok(bytes);
        }
    }
}

/// [`read_input`] of a text file.
pub fn read_input_text(path: &Path) -> Result<String> {
    read_input_text_until(path, &|| false)
}

/// [`read_input_until`] of a text file.
pub fn read_input_text_until(path: &Path, stop: &dyn Fn() -> bool) -> Result<String> {
    String::from_utf8(read_input_until(path, stop)?)
        .map_err(|_| GraniteError::Setup(format!("{} is not a text file (it is not valid UTF-8)", path.display())))
}

/// What a file that is not a regular one is, in words.
fn file_kind(kind: &std::fs::FileType) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if kind.is_fifo() {
            return "a FIFO (named pipe)";
        }
        if kind.is_char_device() || kind.is_block_device() {
            return "a device";
        }
        if kind.is_socket() {
            return "a socket";
        }
    }
    if kind.is_dir() {
        "a folder"
    } else {
        "not a regular file"
    }
}

/// Whether `path` is a symbolic link (not followed).
fn is_link(path: &Path) -> bool {
    std::fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_symlink())
}

/// The error for a link found where a run writes.
fn link_refused(path: &Path) -> GraniteError {
    let to = std::fs::read_link(path).map(|t| format!(" (to {})", t.display())).unwrap_or_default();
    GraniteError::Setup(format!(
        "{} is a symbolic link{to}: granite does not write through links inside an output folder (a reused or \
         shared folder could send its files elsewhere); remove the link or choose another --out",
        path.display()
    ))
}

/// Makes the folders from `root` (an output folder, which may itself be a link) down to `dir`,
/// refusing any of them below `root` that is a symbolic link.
pub fn output_folder(root: &Path, dir: &Path) -> Result<()> {
    if let Ok(below) = dir.strip_prefix(root) {
        let mut at = root.to_path_buf();
        for part in below.components() {
            at.push(part);
            if is_link(&at) {
                return Err(link_refused(&at));
            }
        }
    }
    std::fs::create_dir_all(dir).map_err(|e| GraniteError::io(dir, e))
}

/// Creates `path` anew for writing. Whatever had its name (a symbolic link, a file) is removed
/// first and the file is made with `O_EXCL`, which never follows a link: the bytes land in the
/// folder, never where a link left there points.
pub fn create_in_folder(path: &Path) -> std::io::Result<std::fs::File> {
    if std::fs::symlink_metadata(path).is_ok_and(|m| !m.is_dir()) {
        std::fs::remove_file(path)?;
    }
    std::fs::OpenOptions::new().write(true).create_new(true).open(path)
}

/// Opens `path` to append to it, refusing a symbolic link of that name.
pub fn append_in_folder(path: &Path) -> Result<std::fs::File> {
    if is_link(path) {
        return Err(link_refused(path));
    }
    std::fs::OpenOptions::new().append(true).open(path).map_err(|e| GraniteError::io(path, e))
}

/// Writes `summary.json` (a flat object of named results, in insertion order), replacing the
/// file whole or not at all.
pub fn write_summary(path: &Path, values: &indexmap::IndexMap<String, serde_json::Value>) -> Result<()> {
    let text = serde_json::to_string_pretty(values).map_err(|e| GraniteError::Other(e.to_string()))?;
    durable::replace(path, (text + "\n").as_bytes(), durable::Flush::ToDisk)
}

#[cfg(all(test, unix))]
mod tests {
    use super::*;

    #[test]
    fn inputs_that_are_not_regular_files_are_refused_without_reading_them() {
        let dir = std::env::temp_dir().join(format!("granite-read-input-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let fifo = dir.join("ck.json");
        assert!(std::process::Command::new("mkfifo").arg(&fifo).status().unwrap().success());
        // Opening a FIFO with no writer would block this test for good: it must not be opened.
        for (path, kind) in
            [(fifo.as_path(), "a FIFO"), (Path::new("/dev/urandom"), "a device"), (dir.as_path(), "a folder")]
        {
            let e = read_input(path).unwrap_err().to_string();
            assert!(
                e.contains(kind) && e.contains("not a regular file") && e.contains(&path.display().to_string()),
                "{e}"
            );
        }
        let plain = dir.join("plain.json");
        std::fs::write(&plain, "{}").unwrap();
        assert_eq!(read_input_text(&plain).unwrap(), "{}");
        // A file of more than a piece, read whole, or given up between pieces once asked to stop.
        let big = dir.join("big.json");
        std::fs::write(&big, vec![b' '; READ_PIECE + 10]).unwrap();
        assert_eq!(read_input(&big).unwrap().len(), READ_PIECE + 10);
        let looks = std::cell::Cell::new(0);
        let stop_after_one = || {
            looks.set(looks.get() + 1);
            looks.get() > 1
        };
        let e = read_input_until(&big, &stop_after_one).unwrap_err().to_string();
        assert!(e.contains("stopped while reading") && e.contains(&format!("{READ_PIECE} of")), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
