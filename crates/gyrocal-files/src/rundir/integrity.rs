//! The run directory's record of its own files, checked: `gyrocal verify` and the checks
//! `gyrocal report` makes before it uses a run's files.
//!
//! # What is recorded
//!
//! - `samples.csv` and `steps.csv`: their SHA-256 in the manifest's `checksums` when the run
//!   completes ([`super::RunDir::finish`]).
//! - `fit.json`: its SHA-256 in the manifest's `fit_summary` when it is written.
//! - Every later result file written through the run directory
//!   ([`super::RunDir::write_result`], [`super::RunResults::write_result`]): `allan.json` and
//!   `allan.html` of a drift record, in `checksums` beside the data files.
//!
//! # What is checked, and why so strictly
//!
//! A check that passes when the record is missing vouches for data nobody checked. So a
//! complete run whose manifest lacks the checksum of `samples.csv` or `steps.csv` fails
//! [`verify`] ("the checksums are missing"), and so does a result file on disk that the
//! manifest does not record. Every file is hashed only when it is a regular file
//! ([`crate::open::open_regular`]): a `samples.csv` replaced by a link to `/dev/zero` is
//! refused at once instead of being hashed forever.
//!
//! The manifest itself cannot hold its own digest. It is checked by what it says: its plan
//! must hash to its `plan_hash` (on every read), and every step it records as done must be in
//! `steps.csv` ([`check_files`]), so an emptied `steps.csv` is found in a run that has not
//! completed (and has no checksums yet) too.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use super::{
    ALLAN_HTML, ALLAN_JSON, FIT_JSON, MANIFEST_JSON, Manifest, RunError, SAMPLES_CSV, STEPS_CSV,
    Status, read_manifest,
};
use crate::open::{OpenError, OpenErrorKind, open_regular};

/// The result files a run may write after its data, each recorded with its SHA-256 when it
/// is written through the run directory. A file of this list on disk without a record fails
/// [`verify`].
pub const RESULT_FILES: [&str; 3] = [FIT_JSON, ALLAN_JSON, ALLAN_HTML];

/// The data files whose checksums a complete run must have.
pub const DATA_FILES: [&str; 2] = [SAMPLES_CSV, STEPS_CSV];

/// SHA-256 of `bytes`, lower-case hex.
pub fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::Digest as _;
    hex(&sha2::Sha256::digest(bytes))
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// SHA-256 of a file's bytes, lower-case hex, read in chunks (memory stays bounded whatever
/// the file's size). Only a regular file is read: a device, a FIFO or a directory (or a link
/// to one) is refused before a byte is read.
pub fn sha256_file(path: &Path) -> Result<String, OpenError> {
    use sha2::Digest as _;
    use std::io::Read as _;
    let mut file = open_regular(path)?;
    let mut hasher = sha2::Sha256::new();
    let mut buf = vec![0u8; 1 << 16];
    loop {
        let n = file.read(&mut buf).map_err(|source| OpenError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        if n == 0 {
            break;
        }
        hasher.update(buf.get(..n).unwrap_or_default());
    }
    Ok(hex(&hasher.finalize()))
}

/// How a file compares with the run's record of it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FileState {
    /// As recorded.
    Ok,
    /// Its bytes differ from the record: the SHA-256 it has now.
    Changed {
        /// SHA-256 of the file now.
        now: String,
    },
    /// Recorded, but not there.
    Missing,
    /// Not a regular file, or it could not be read: why.
    Unreadable(String),
    /// On disk (or required) without a record in the manifest.
    NotRecorded,
}

/// One file of a run checked against the run's record.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FileCheck {
    /// The file's name in the run directory.
    pub file: String,
    /// The SHA-256 the manifest recorded (`None`: none recorded).
    pub recorded: Option<String>,
    /// How the file compares.
    pub state: FileState,
}

impl FileCheck {
    /// The file is as it was recorded.
    pub fn ok(&self) -> bool {
        self.state == FileState::Ok
    }

    /// The check in words, starting with the file's name: `steps.csv ok`, `steps.csv CHANGED
    /// since the run recorded it (sha256 … recorded, … now)`.
    pub fn describe(&self) -> String {
        let file = &self.file;
        let recorded = self.recorded.as_deref().unwrap_or("none");
        match &self.state {
            FileState::Ok => format!("{file} ok"),
            FileState::Changed { now } => format!(
                "{file} CHANGED since the run recorded it (sha256 {recorded} recorded, {now} now)"
            ),
            FileState::Missing => {
                format!("{file} MISSING (the run recorded it with sha256 {recorded})")
            }
            FileState::Unreadable(why) => format!("{file} UNREADABLE: {why}"),
            FileState::NotRecorded if DATA_FILES.contains(&file.as_str()) => format!(
                "{file} NOT RECORDED: the manifest of this complete run holds no checksum of it \
                 (its `checksums` were removed or cut); the file cannot be verified"
            ),
            FileState::NotRecorded => format!(
                "{file} NOT RECORDED: the file is there but the manifest holds no checksum of \
                 it (written outside the run directory, by an earlier gyrocal, or its record was \
                 removed); it cannot be verified{}",
                if file == FIT_JSON {
                    ""
                } else {
                    " (`gyrocal report RUN_DIR` writes the Allan results again, recorded)"
                }
            ),
        }
    }
}

/// Every checksum the manifest records: `checksums` and `fit_summary`.
fn recorded(m: &Manifest) -> BTreeMap<String, String> {
    let mut out = m.checksums.clone();
    if let Some(f) = &m.fit_summary {
        out.insert(f.file.clone(), f.sha256.clone());
    }
    out
}

/// Compares one file with its record.
fn check_one(dir: &Path, file: &str, recorded: Option<&String>) -> FileCheck {
    let path = dir.join(file);
    let state = match (recorded, sha256_file(&path)) {
        (None, _) => FileState::NotRecorded,
        (Some(r), Ok(now)) if &now == r => FileState::Ok,
        (Some(_), Ok(now)) => FileState::Changed { now },
        (Some(_), Err(e)) if e.kind() == OpenErrorKind::NotFound => FileState::Missing,
        (Some(_), Err(e)) => FileState::Unreadable(e.to_string()),
    };
    FileCheck {
        file: file.to_string(),
        recorded: recorded.cloned(),
        state,
    }
}

/// True when something (a file, a link, a FIFO) is at `path`.
fn present(path: &Path) -> bool {
    std::fs::symlink_metadata(path).is_ok()
}

/// The outcome of [`verify`].
#[derive(Debug, Clone, PartialEq)]
pub struct Verification {
    /// The run's status in its manifest.
    pub status: Status,
    /// Every recorded file, every data file a complete run must have recorded, and every
    /// result file on disk, in that order.
    pub checks: Vec<FileCheck>,
    /// What makes the run unverifiable besides its files (a run that is not complete).
    pub problems: Vec<String>,
}

impl Verification {
    /// Every file is as recorded, and the run could be verified at all.
    pub fn ok(&self) -> bool {
        self.problems.is_empty() && !self.checks.is_empty() && self.checks.iter().all(FileCheck::ok)
    }
}

/// Re-checks the files of the run in `dir` against the checksums its manifest recorded
/// (see the module docs): every recorded file must be as recorded; a complete run must have
/// recorded `samples.csv` and `steps.csv`; a result file on disk (`fit.json`, `allan.json`,
/// `allan.html`) must be recorded; a run that is not complete has no checksums yet and cannot
/// be verified (a problem, not an error). An error only when the manifest cannot be read.
pub fn verify(dir: &Path) -> Result<Verification, RunError> {
    let path = dir.join(MANIFEST_JSON);
    if !present(&path) {
        return Err(RunError::NotARun {
            path: dir.to_path_buf(),
        });
    }
    let m = read_manifest(&path)?;
    let recorded = recorded(&m);
    let mut names: Vec<&str> = recorded.keys().map(String::as_str).collect();
    if m.status == Status::Complete {
        names.extend(DATA_FILES);
    }
    names.extend(RESULT_FILES.iter().filter(|f| present(&dir.join(f))));
    let mut seen = BTreeSet::new();
    let checks: Vec<FileCheck> = names
        .into_iter()
        .filter(|n| seen.insert(*n))
        .map(|n| check_one(dir, n, recorded.get(n)))
        .collect();
    let mut problems = Vec::new();
    if m.status != Status::Complete {
        problems.push(format!(
            "the run is not complete (status {}): its data files get their checksums when it \
             completes, so they cannot be verified",
            status_word(m.status)
        ));
    }
    Ok(Verification {
        status: m.status,
        checks,
        problems,
    })
}

fn status_word(s: Status) -> &'static str {
    match s {
        Status::Running => "running",
        Status::Complete => "complete",
        Status::Aborted => "aborted",
        Status::Failed => "failed",
    }
}

/// A file of a run that does not match the run's record, in words (for a refusal or a
/// banner).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Discrepancy {
    /// The file's name in the run directory.
    pub file: String,
    /// What is wrong, a sentence starting with the file's name.
    pub text: String,
    /// The file differs from the record (a reader refuses it): `false` when the file merely
    /// cannot be checked because the run recorded no checksum of it (a run written before
    /// gyrocal recorded checksums), which a reader says but does not refuse.
    pub differs: bool,
}

/// Checks the files of the run in `dir` that a reader is about to use (`files`, e.g.
/// `steps.csv` and `fit.json` for a certificate) against the run's record, and the manifest
/// against `steps.csv` when `steps.csv` is among them: the discrepancies, empty when
/// everything is as the run wrote it.
///
/// A file differs ([`Discrepancy::differs`]) when its bytes differ from its recorded SHA-256
/// or it is not a regular file; when `fit.json` was recorded and is gone (a reader would fit
/// the data itself, silently); when `fit.json` is on disk without a record (an Allan result
/// without one, left by an earlier gyrocal, is not: its reader writes it again, recorded);
/// and `steps.csv` when it lacks a step the manifest records as done (an emptied `steps.csv`
/// in a run that is not complete, or whose checksums were removed). A missing data file is left to
/// the reader, whose error names it. A complete run without a checksum of a data file read
/// gets a discrepancy that does not differ: runs written before gyrocal recorded checksums
/// have none, and their report says the files could not be checked. An error only when the
/// manifest or `steps.csv` cannot be read at all.
pub fn check_files(dir: &Path, files: &[&str]) -> Result<Vec<Discrepancy>, RunError> {
    let m = read_manifest(&dir.join(MANIFEST_JSON))?;
    let recorded = recorded(&m);
    let mut out = Vec::new();
    let mut unrecorded_data = Vec::new();
    for &file in files {
        let rec = recorded.get(file);
        let data = DATA_FILES.contains(&file);
        let result_on_disk = RESULT_FILES.contains(&file) && present(&dir.join(file));
        if rec.is_none() {
            if data && m.status == Status::Complete {
                unrecorded_data.push(file);
            }
            if !result_on_disk {
                continue;
            }
        }
        let c = check_one(dir, file, rec);
        let differs = match &c.state {
            FileState::Ok => false,
            // the reader's own error names a missing data file (exit 2); a recorded fit that
            // is gone would be replaced by the reader's own fit without a word
            FileState::Missing => file == FIT_JSON,
            FileState::Changed { .. } | FileState::Unreadable(_) => true,
            // a fit.json the run never recorded is not the run's; an Allan result left
            // unrecorded by an earlier gyrocal is replaced (and recorded) by its reader
            FileState::NotRecorded => file == FIT_JSON,
        };
        if differs {
            out.push(Discrepancy {
                file: file.to_string(),
                text: c.describe(),
                differs,
            });
        }
    }
    if !unrecorded_data.is_empty() {
        out.push(Discrepancy {
            file: unrecorded_data.join(", "),
            text: format!(
                "{MANIFEST_JSON} records no checksum of {} (a gyrocal before checksums wrote the \
                 run, or they were removed): these files cannot be checked against the run's record",
                unrecorded_data.join(" and ")
            ),
            differs: false,
        });
    }
    let steps_checked = out.iter().any(|d| d.differs && d.file == STEPS_CSV);
    if files.contains(&STEPS_CSV) && !steps_checked && present(&dir.join(STEPS_CSV)) {
        let data = super::load(dir)?;
        let have: BTreeSet<usize> = data.steps.iter().map(|s| s.step).collect();
        let lacking: Vec<usize> = m
            .steps_done
            .iter()
            .copied()
            .filter(|s| !have.contains(s))
            .collect();
        if !lacking.is_empty() {
            let shown: Vec<String> = lacking
                .iter()
                .take(8)
                .map(|s| (s + 1).to_string())
                .collect();
            out.push(Discrepancy {
                file: STEPS_CSV.to_string(),
                text: format!(
                    "{STEPS_CSV} lacks {} of the {} steps {} records as done (plan step{} {}{}): \
                     it was cut or emptied since the run wrote it",
                    lacking.len(),
                    m.steps_done.len(),
                    MANIFEST_JSON,
                    if lacking.len() == 1 { "" } else { "s" },
                    shown.join(", "),
                    if lacking.len() > shown.len() {
                        ", …"
                    } else {
                        ""
                    }
                ),
                differs: true,
            });
            tracing::warn!(dir = %dir.display(), lacking = lacking.len(), "steps.csv lacks finished steps");
        }
    }
    Ok(out)
}
