//! Writing a run's result files after its data: the Allan analysis of a drift record
//! (`allan.json`, `allan.html`), written at the end of the run by the process that ran it (its
//! [`RunDir`] still open) or later by `gyrocal report` (a [`RunResults`]).
//!
//! Either way a result goes through the run directory: atomically (temporary file, fsync,
//! rename, fsync of the directory; the temporary file removed on any failure), under the
//! run's lock (so two writers never interleave their manifest updates), and with its SHA-256
//! recorded in the manifest's `checksums`, which `gyrocal verify` checks.

use std::fs::File;
use std::path::{Path, PathBuf};

use super::{
    FIT_JSON, LOCK_FILE, MANIFEST_JSON, Manifest, RunDir, RunError, SAMPLES_CSV, STEPS_CSV, Status,
    lock_dir, read_manifest, sha256_hex, store_manifest, write_atomic,
};

/// A writer of a run's result files: an open [`RunDir`] (the run that just ended) or a
/// [`RunResults`] (a finished run opened again).
pub trait WriteResult {
    /// The run directory.
    fn dir(&self) -> &Path;
    /// Writes the result `name` atomically and records its SHA-256 in the manifest.
    fn write_result(&mut self, name: &str, bytes: &[u8]) -> Result<(), RunError>;
}

impl WriteResult for RunDir {
    fn dir(&self) -> &Path {
        self.path()
    }

    fn write_result(&mut self, name: &str, bytes: &[u8]) -> Result<(), RunError> {
        RunDir::write_result(self, name, bytes)
    }
}

/// A run directory opened to write result files (not data): its lock held while this value
/// lives. Released like a [`RunDir`]'s: a run that is not `running` is left without `.lock`.
#[derive(Debug)]
pub struct RunResults {
    dir: PathBuf,
    _lock: File,
    manifest: Manifest,
}

impl RunResults {
    /// Opens the run in `dir` for its results: takes the run's lock (refused while another
    /// process writes the run: [`RunError::Locked`]) and reads its manifest under it.
    pub fn open(dir: &Path) -> Result<RunResults, RunError> {
        let mpath = dir.join(MANIFEST_JSON);
        if std::fs::symlink_metadata(&mpath).is_err() {
            return Err(RunError::NotARun {
                path: dir.to_path_buf(),
            });
        }
        let lock = lock_dir(dir)?;
        let manifest = match read_manifest(&mpath) {
            Ok(m) => m,
            Err(e) => {
                // a refused opening leaves a finished run as it was: without `.lock`
                remove_lock(dir);
                return Err(e);
            }
        };
        Ok(RunResults {
            dir: dir.to_path_buf(),
            _lock: lock,
            manifest,
        })
    }

    /// The run's manifest as last written.
    pub fn manifest(&self) -> &Manifest {
        &self.manifest
    }
}

impl WriteResult for RunResults {
    fn dir(&self) -> &Path {
        &self.dir
    }

    fn write_result(&mut self, name: &str, bytes: &[u8]) -> Result<(), RunError> {
        record_result(&self.dir, &mut self.manifest, name, bytes)
    }
}

fn remove_lock(dir: &Path) {
    if cfg!(not(unix)) {
        return;
    }
    let path = dir.join(LOCK_FILE);
    match std::fs::remove_file(&path) {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => tracing::warn!(file = %path.display(), error = %e, "cannot remove the lock file"),
    }
}

/// As [`RunDir`]'s: a run that is not `running` keeps no `.lock` (removed while still held).
impl Drop for RunResults {
    fn drop(&mut self) {
        if self.manifest.status != Status::Running {
            remove_lock(&self.dir);
        }
    }
}

/// The files a result may not replace: the data, the record, the fit (which has its own
/// record), the lock and the log.
pub(super) const NOT_RESULTS: [&str; 6] = [
    SAMPLES_CSV,
    STEPS_CSV,
    MANIFEST_JSON,
    FIT_JSON,
    LOCK_FILE,
    "run.log",
];

/// Writes the result `name` into `dir` atomically, then records its SHA-256 in `m` and
/// stores the manifest (the caller holds the run's lock). If the manifest cannot be stored,
/// the result file is on disk without a record (`gyrocal verify` then says so).
pub(super) fn record_result(
    dir: &Path,
    m: &mut Manifest,
    name: &str,
    bytes: &[u8],
) -> Result<(), RunError> {
    if name.contains(['/', '\\'])
        || name.starts_with('.')
        || name.is_empty()
        || NOT_RESULTS.contains(&name)
    {
        return Err(RunError::Protocol {
            path: dir.join(name),
            message: "a result file name must be a plain, non-hidden name other than the run's data, manifest, fit, lock and log".into(),
        });
    }
    write_atomic(dir, name, bytes)?;
    m.checksums.insert(name.to_string(), sha256_hex(bytes));
    store_manifest(dir, m)?;
    tracing::info!(file = %dir.join(name).display(), "result written and recorded");
    Ok(())
}
