//! Files a run rewrites (checkpoints, `summary.json`, `provenance.json`, `.pvd` indices) are
//! replaced whole or not at all: the new content goes to a file beside the target, is flushed to
//! the disk, then renamed over the target. A process killed at any moment, or a disk that fills
//! up, leaves the old file or the new one, never a cut one.
//!
//! Checkpoints also keep the one before (`ck.json` and `ck.prev.json`): should the newest be lost
//! all the same (a disk that lies about its flushes, a hand edit), [`read_newest`] falls back on
//! the previous one and says so.

use crate::error::{GraniteError, Result};
use std::io::Write;
use std::path::{Path, PathBuf};

/// Whether a replaced file is flushed to the disk before it takes the target's name.
#[derive(Clone, Copy, PartialEq, Eq)]
pub enum Flush {
    /// Checkpoints and records: they must survive a power cut, not only a killed process.
    ToDisk,
    /// VTK frames and their index: a killed process cannot cut them (the rename is atomic); a
    /// power cut may lose the last ones, which the next run writes again.
    ToSystem,
}

/// The file beside `path` its new content is written to first (one name per target: a killed
/// writer's leftover is overwritten by the next write, not piled up).
fn partial_path(path: &Path) -> PathBuf {
    let name = path.file_name().map(|n| n.to_string_lossy().to_string()).unwrap_or_default();
    path.with_file_name(format!(".{name}.partial"))
}

/// `ck.json` → `ck.prev.json`; `ck` → `ck.prev`: where the checkpoint before the newest is kept.
pub fn previous_path(path: &Path) -> PathBuf {
    let stem = path.file_stem().map(|n| n.to_string_lossy().to_string()).unwrap_or_default();
    match path.extension() {
        Some(ext) => path.with_file_name(format!("{stem}.prev.{}", ext.to_string_lossy())),
        None => path.with_file_name(format!("{stem}.prev")),
    }
}

/// Replaces `path` by `bytes`, whole or not at all. On failure the target is as it was, the
/// partial file is removed (on a full disk it would hold the space the next write needs) and the
/// error names the target and the cause.
pub fn replace(path: &Path, bytes: &[u8], flush: Flush) -> Result<()> {
    let partial = partial_path(path);
    let written = write_partial(&partial, bytes, flush).and_then(|()| std::fs::rename(&partial, path));
    if let Err(e) = written {
        let _ = std::fs::remove_file(&partial);
        return Err(GraniteError::io(path, e));
    }
    if flush == Flush::ToDisk {
        sync_folder(path);
    }
    Ok(())
}

/// [`replace`] for a checkpoint: the file it replaces becomes [`previous_path`] first, so that two
/// whole checkpoints exist from the second write on.
pub fn replace_keeping_previous(path: &Path, bytes: &[u8]) -> Result<()> {
    let partial = partial_path(path);
    if let Err(e) = write_partial(&partial, bytes, Flush::ToDisk) {
        let _ = std::fs::remove_file(&partial);
        return Err(GraniteError::io(path, e));
    }
    if path.is_file() {
        // A second name for the current file, renamed into place: `path` itself never goes
        // missing, and `prev` is always a whole file (the old one or the one before it).
        let prev = previous_path(path);
        let prev_partial = partial_path(&prev);
        let _ = std::fs::remove_file(&prev_partial);
        let linked =
            std::fs::hard_link(path, &prev_partial).or_else(|_| std::fs::copy(path, &prev_partial).map(|_| ()));
        match linked.and_then(|()| std::fs::rename(&prev_partial, &prev)) {
            Ok(()) => {}
            // No room for a copy (a file system without hard links, full): the new checkpoint
            // still replaces the old one; the previous file stays one generation older.
            Err(_) => {
                let _ = std::fs::remove_file(&prev_partial);
            }
        }
    }
    if let Err(e) = std::fs::rename(&partial, path) {
        let _ = std::fs::remove_file(&partial);
        return Err(GraniteError::io(path, e));
    }
    sync_folder(path);
    Ok(())
}

fn write_partial(partial: &Path, bytes: &[u8], flush: Flush) -> std::io::Result<()> {
    let mut file = super::create_in_folder(partial)?;
    file.write_all(bytes)?;
    if flush == Flush::ToDisk {
        file.sync_all()?;
    }
    Ok(())
}

/// Makes the renames in `path`'s folder durable (where the system allows opening a folder).
fn sync_folder(path: &Path) {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    if let Ok(d) = std::fs::File::open(dir) {
        let _ = d.sync_all();
    }
}

/// The text of the checkpoint at `path`, or of the one before it when `path` is missing or fails
/// `check` (cut, damaged); the path read, and what was wrong with the newer file if the older one
/// was taken. Both failing is an error naming both. Reading gives up once `stop()` says so.
pub fn read_newest(
    path: &Path,
    check: impl Fn(&Path, &str) -> Result<()>,
    stop: &dyn Fn() -> bool,
) -> Result<(PathBuf, String, Option<String>)> {
    let read = |p: &Path| -> Result<String> {
        let text = super::read_input_text_until(p, stop)?;
        check(p, &text)?;
        Ok(text)
    };
    let newest = match read(path) {
        Ok(text) => return Ok((path.to_path_buf(), text, None)),
        Err(e) => e,
    };
    let prev = previous_path(path);
    if !prev.is_file() {
        return Err(newest);
    }
    match read(&prev) {
        Ok(text) => {
            let why = format!(
                "{} could not be used ({newest}); the previous checkpoint {} was loaded instead",
                path.display(),
                prev.display()
            );
            Ok((prev, text, Some(why)))
        }
        Err(older) => {
            Err(GraniteError::Other(format!("{newest}; the previous checkpoint cannot be used either: {older}")))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn folder(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("granite-durable-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn a_checkpoint_keeps_the_one_before_and_a_damaged_newest_falls_back_on_it() {
        let dir = folder("prev");
        let ck = dir.join("ck.json");
        assert_eq!(previous_path(&ck), dir.join("ck.prev.json"));
        assert_eq!(previous_path(&dir.join("ck")), dir.join("ck.prev"));
        replace_keeping_previous(&ck, b"first").unwrap();
        assert!(!previous_path(&ck).exists(), "a first checkpoint has nothing before it");
        replace_keeping_previous(&ck, b"second").unwrap();
        replace_keeping_previous(&ck, b"third").unwrap();
        assert_eq!(std::fs::read_to_string(&ck).unwrap(), "third");
        assert_eq!(std::fs::read_to_string(previous_path(&ck)).unwrap(), "second");
        let whole = |p: &Path, t: &str| -> Result<()> {
            if t.starts_with('t') || t.starts_with('s') {
                Ok(())
            } else {
                Err(GraniteError::Other(format!("{} is cut", p.display())))
            }
        };
        let (read, text, note) = read_newest(&ck, whole, &|| false).unwrap();
        assert_eq!((read, text.as_str(), note), (ck.clone(), "third", None));
        std::fs::write(&ck, "").unwrap();
        let (read, text, note) = read_newest(&ck, whole, &|| false).unwrap();
        assert_eq!((read, text.as_str()), (previous_path(&ck), "second"));
        assert!(note.unwrap().contains("ck.json is cut"));
        std::fs::write(previous_path(&ck), "").unwrap();
        let e = read_newest(&ck, whole, &|| false).unwrap_err().to_string();
        assert!(e.contains("ck.json is cut") && e.contains("ck.prev.json is cut"), "{e}");
        let names: Vec<String> =
            std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().to_string()).collect();
        assert!(names.iter().all(|n| !n.ends_with(".partial")), "{names:?}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_failed_replacement_leaves_the_target_as_it_was() {
        let dir = folder("fail");
        let target = dir.join("summary.json");
        replace(&target, b"old", Flush::ToDisk).unwrap();
        // The partial file cannot be made where a folder of its name stands.
        std::fs::create_dir_all(partial_path(&target).join("x")).unwrap();
        let e = replace(&target, b"new", Flush::ToDisk).unwrap_err().to_string();
        assert!(e.contains("summary.json"), "{e}");
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "old");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
