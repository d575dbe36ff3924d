//! Atomic replacement of a file: a temporary file beside it (`.NAME.tmp`), written and
//! fsynced, renamed over the destination, then the directory fsynced. A reader sees the old
//! content or the new, never a mix, and a crash leaves one of the two.
//!
//! Why the temporary file is removed on every failure: a disk that fills up (ENOSPC) while
//! the page of an analysis is written must not leave a `.allan.html.tmp` behind, which the
//! operator would have to find and delete, and which makes a run directory look half written.

use std::fs::{self, File};
use std::io::Write as _;
use std::path::{Path, PathBuf};

/// An atomic write that failed; the temporary file is gone.
#[derive(Debug, thiserror::Error)]
#[error("{}: cannot {action}: {source}", path.display())]
pub struct AtomicError {
    /// The file concerned (the temporary file while writing it, the destination when
    /// replacing it, the directory when syncing it).
    pub path: PathBuf,
    /// What was being done (`create`, `write`, `sync`, `replace`, `sync the directory`).
    pub action: &'static str,
    /// The I/O error.
    pub source: std::io::Error,
}

/// The temporary file of an atomic write of `path`: `.NAME.tmp` in the same directory (so the
/// rename is within one file system).
pub fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "file".to_string());
    path.with_file_name(format!(".{name}.tmp"))
}

/// Replaces `path` with `bytes` atomically (see the module docs). On any failure the
/// temporary file is removed and the destination is left as it was.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), AtomicError> {
    write_atomic_with(path, bytes, |f, b| f.write_all(b))
}

/// [`write_atomic`] with the writing of the bytes into the temporary file given: a test makes
/// it fail as a full disk does.
pub(crate) fn write_atomic_with(
    path: &Path,
    bytes: &[u8],
    write: impl FnOnce(&mut File, &[u8]) -> std::io::Result<()>,
) -> Result<(), AtomicError> {
    let tmp = temp_path(path);
    let fail = |path: &Path, action: &'static str| {
        let path = path.to_path_buf();
        move |source| AtomicError {
            path,
            action,
            source,
        }
    };
    let written = (|| {
        let mut f = File::create(&tmp).map_err(fail(&tmp, "create"))?;
        write(&mut f, bytes).map_err(fail(&tmp, "write"))?;
        f.sync_all().map_err(fail(&tmp, "sync"))?;
        drop(f);
        fs::rename(&tmp, path).map_err(fail(path, "replace"))
    })();
    if let Err(e) = written {
        remove_temp(&tmp);
        return Err(e);
    }
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    sync_dir(dir).map_err(fail(dir, "sync the directory"))
}

/// Removes a temporary file after a failed write (a missing one is fine).
fn remove_temp(tmp: &Path) {
    match fs::remove_file(tmp) {
        Ok(()) => {
            tracing::debug!(file = %tmp.display(), "removed the temporary file of a failed write")
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => {
            tracing::warn!(file = %tmp.display(), error = %e, "cannot remove the temporary file of a failed write")
        }
    }
}

/// Fsyncs a directory, so a rename in it survives a power cut (a no-op where directories
/// cannot be opened).
pub fn sync_dir(dir: &Path) -> std::io::Result<()> {
    #[cfg(unix)]
    {
        File::open(dir).and_then(|d| d.sync_all())
    }
    #[cfg(not(unix))]
    {
        let _ = dir;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use std::io::Write as _;

    use super::*;

    #[test]
    fn a_full_disk_leaves_the_old_file_and_no_temporary_file() {
        let tmp = tempfile::tempdir().unwrap();
        let path = tmp.path().join("allan.html");
        fs::write(&path, "old").unwrap();
        let err = write_atomic_with(&path, b"new page", |f, b| {
            // half the bytes land, then the disk is full
            f.write_all(&b[..4])?;
            Err(std::io::Error::from_raw_os_error(28))
        })
        .unwrap_err();
        assert_eq!(err.action, "write");
        assert_eq!(err.source.kind(), std::io::ErrorKind::StorageFull);
        assert!(err.to_string().contains(".allan.html.tmp"), "{err}");
        assert_eq!(fs::read_to_string(&path).unwrap(), "old");
        let names: Vec<_> = fs::read_dir(tmp.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        assert_eq!(names, ["allan.html"]);
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn a_write_into_dev_full_fails_and_cleans_up() {
        // a stale temporary file that is a link to /dev/full: every write fails with ENOSPC
        let tmp = tempfile::tempdir().unwrap();
        let path = tmp.path().join("fit.json");
        std::os::unix::fs::symlink("/dev/full", temp_path(&path)).unwrap();
        let err = write_atomic(&path, &[b'x'; 100_000]).unwrap_err();
        assert_eq!(err.source.kind(), std::io::ErrorKind::StorageFull);
        assert!(!path.exists());
        assert!(fs::symlink_metadata(temp_path(&path)).is_err());
    }

    #[test]
    fn a_write_replaces_the_file() {
        let tmp = tempfile::tempdir().unwrap();
        let path = tmp.path().join("x.json");
        write_atomic(&path, b"1").unwrap();
        write_atomic(&path, b"22").unwrap();
        assert_eq!(fs::read_to_string(&path).unwrap(), "22");
        assert!(!temp_path(&path).exists());
    }
}
