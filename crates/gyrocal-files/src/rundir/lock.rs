//! One writer at a time: the OS lock on `.lock` (released even by a crash), taken only when
//! the file locked is still the one at the path.
#[allow(unused_imports)]
use super::*;

/// The lock file inside a run directory (see [`RunDir`]).
pub const LOCK_FILE: &str = ".lock";

/// Takes the run directory's exclusive lock.
///
/// A finished run's writer removes `.lock` (see [`RunDir`]'s `Drop`), so the file may vanish
/// between this process opening it and locking it: the lock would then be on a file nobody
/// else can find, while another process creates and locks a new `.lock`. So the lock counts
/// only when the file locked is still the one at the path (same device and inode); otherwise
/// it is taken again.
pub(super) fn lock_dir(dir: &Path) -> Result<File, RunError> {
    let path = dir.join(LOCK_FILE);
    for _ in 0..8 {
        let file = fs::OpenOptions::new()
            .create(true)
            .truncate(false)
            .write(true)
            .open(&path)
            .map_err(io(&path, "open the lock file"))?;
        match file.try_lock() {
            Ok(()) => {}
            Err(std::fs::TryLockError::WouldBlock) => {
                return Err(RunError::Locked {
                    path: dir.to_path_buf(),
                });
            }
            Err(std::fs::TryLockError::Error(e)) => return Err(io(&path, "lock")(e)),
        }
        if still_at_path(&file, &path) {
            return Ok(file);
        }
        tracing::debug!(file = %path.display(), "the lock file was replaced meanwhile; locking again");
    }
    // the file keeps being replaced under us: another process is busy with this directory
    Err(RunError::Locked {
        path: dir.to_path_buf(),
    })
}

/// True when `file` is the file at `path` (same device and inode).
#[cfg(unix)]
pub(super) fn still_at_path(file: &File, path: &Path) -> bool {
    use std::os::unix::fs::MetadataExt as _;
    match (file.metadata(), fs::metadata(path)) {
        (Ok(a), Ok(b)) => a.dev() == b.dev() && a.ino() == b.ino(),
        _ => false,
    }
}

/// Elsewhere the lock file is never removed (see `Drop for RunDir`), so it cannot be replaced.
#[cfg(not(unix))]
pub(super) fn still_at_path(_file: &File, _path: &Path) -> bool {
    true
}
