//! One writer at a time: the OS lock on `.lock` (released even by a crash), taken only when
//! the file locked is still the one at the path. The holder writes who it is into the file
//! ([`LockHolder`]: host, PID, since when), so that a run whose process was killed (SIGKILL,
//! a power cut: its manifest still says `running`) can be told from one that is running:
//! `gyrocal runs` reads it with [`lock_holder`]. The OS lock decides who may write; the text
//! is only for people.
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
            write_holder(&file, &path);
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

/// Who holds (or last held) a run directory's lock, as the holder wrote it into `.lock`.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct LockHolder {
    /// The host name of the machine the holder ran on.
    pub host: String,
    /// Its process id.
    pub pid: u32,
    /// When it took the lock, RFC 3339 UTC.
    pub since_utc: String,
}

/// Whether the holder of a lock is alive, as far as this machine can tell.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HolderState {
    /// The process is alive on this host.
    Alive,
    /// The holder was on this host and its process is gone: the run was killed.
    Dead,
    /// The holder is on another host (or this one cannot list its processes): not checked.
    Unknown,
}

/// The most a `.lock` may hold to be read (a holder writes about 100 bytes).
const MAX_LOCK_BYTES: u64 = 4096;

impl LockHolder {
    /// This process, now.
    pub fn this_process() -> LockHolder {
        LockHolder {
            host: host_name(),
            pid: std::process::id(),
            since_utc: now_utc(),
        }
    }

    /// Whether the holder is alive: on this host, by its PID (`/proc/PID`); elsewhere unknown.
    /// A PID reused by another process reads as alive (the OS lock, not this, decides who may
    /// write).
    pub fn state(&self) -> HolderState {
        if self.host != host_name() || !Path::new("/proc/self").exists() {
            return HolderState::Unknown;
        }
        if Path::new("/proc").join(self.pid.to_string()).exists() {
            HolderState::Alive
        } else {
            HolderState::Dead
        }
    }
}

/// The holder written in `dir/.lock`: `Ok(None)` when there is no `.lock` (the run was closed,
/// or never started) or it holds no holder (an earlier gyrocal left it empty, or it was cut short);
/// an error only when the file exists and cannot be read. What the file says is untrusted:
/// read capped, parsed without panicking.
pub fn lock_holder(dir: &Path) -> Result<Option<LockHolder>, RunError> {
    let path = dir.join(LOCK_FILE);
    match fs::metadata(&path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(io(&path, "read")(e)),
        Ok(_) => {}
    }
    let bytes = read_capped(&path, MAX_LOCK_BYTES)?;
    Ok(serde_json::from_slice(&bytes).ok())
}

/// Writes this process into the lock file it holds (best effort: the lock holds without it).
fn write_holder(file: &File, path: &Path) {
    use std::io::Write as _;
    let Ok(mut text) = serde_json::to_vec(&LockHolder::this_process()) else {
        return;
    };
    text.push(b'\n');
    let mut f = file;
    let written = file
        .set_len(0)
        .and_then(|()| std::io::Seek::seek(&mut f, std::io::SeekFrom::Start(0)))
        .and_then(|_| f.write_all(&text));
    if let Err(e) = written {
        tracing::debug!(file = %path.display(), error = %e, "cannot write the lock holder");
    }
}

/// This machine's host name (`/proc/sys/kernel/hostname`, `/etc/hostname`, `$HOSTNAME`), or
/// `unknown`.
pub fn host_name() -> String {
    ["/proc/sys/kernel/hostname", "/etc/hostname"]
        .iter()
        .filter_map(|p| fs::read_to_string(p).ok())
        .chain(std::env::var("HOSTNAME").ok())
        .map(|s| s.trim().to_string())
        .find(|s| !s.is_empty() && s.len() < 256)
        .unwrap_or_else(|| "unknown".into())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_lock_names_its_holder_and_a_dead_one_reads_as_dead() {
        let tmp = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let dir = tmp.path();
        assert_eq!(lock_holder(dir).ok(), Some(None), "no .lock: no holder");
        let file = lock_dir(dir).unwrap_or_else(|e| panic!("{e}"));
        let holder = lock_holder(dir).ok().flatten().expect("the holder");
        assert_eq!(holder.pid, std::process::id());
        assert_eq!(holder.host, host_name());
        assert_eq!(holder.state(), HolderState::Alive);
        drop(file);
        // a process that is gone (PIDs stop far below u32::MAX), on this host and another
        let gone = LockHolder {
            pid: u32::MAX - 1,
            ..holder.clone()
        };
        assert_eq!(gone.state(), HolderState::Dead);
        let elsewhere = LockHolder {
            host: format!("{}-elsewhere", holder.host),
            ..gone
        };
        assert_eq!(elsewhere.state(), HolderState::Unknown);
        // what the file says is untrusted: garbage is no holder, a huge file an error
        fs::write(dir.join(LOCK_FILE), "\u{0}not json").unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(lock_holder(dir).ok(), Some(None));
        fs::write(dir.join(LOCK_FILE), vec![b'x'; 10_000]).unwrap_or_else(|e| panic!("{e}"));
        assert!(lock_holder(dir).is_err());
    }
}
