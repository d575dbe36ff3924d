//! A damaged SQLite catalog: finding it out before trusting a listing, and setting the file
//! aside for `gyrocal catalog rebuild`.
//!
//! Why a listing checks first: SQLite reads a damaged page as well as it can. A full scan
//! stops with "database disk image is malformed" or yields a value that is not text, but a
//! query that filters (a gyro's history: its serial, `complete`) can step over a garbled row
//! without an error, and the history is then one calibration short, its repeatability
//! computed on the rest. Random bytes in a page of the `runs` table did exactly that. What
//! gives such a row away is SQLite's own cross-check of a table against its indexes
//! (`PRAGMA integrity_check(TABLE)`: the garbled row no longer matches its index entries),
//! so a listing runs it on the tables it reads before it reads them and reports a damaged
//! file as [`CatalogError::Damaged`], naming the file and the repair, instead of a shorter
//! list. The price, measured with the crate's `bench` test on a catalog of 10 000 runs on a
//! shared 2-core machine: a history took 44–80 ms (median) instead of 5 ms, a listing of the
//! newest 50 runs 43–57 ms instead of 1 ms; a person waiting for one command does not notice,
//! and a history that hides a calibration is worse than a slow one.
//! Any error while reading is checked the same way (`PRAGMA quick_check` of the whole file).
//!
//! The repair: the run directories hold every run, so the catalog is rebuilt from them.
//! [`set_aside`] renames the damaged file to `catalog.sqlite.damaged-<UTC time>` (kept for
//! whoever wants to look at it, never deleted) and the rebuild starts from a new file.

use std::path::{Path, PathBuf};

use sqlx::Row as _;
use sqlx::sqlite::{SqliteConnectOptions, SqlitePool};
use sqlx::{ConnectOptions as _, Connection as _};

use crate::error::CatalogError;

/// The tables a listing (`runs`, `history`) reads: checked before they are read.
pub(crate) const LISTED_TABLES: [&str; 5] = [
    "runs",
    "results",
    "checks",
    "series_results",
    "series_points",
];

/// At most this many of SQLite's findings are quoted in a message.
const QUOTED: usize = 3;

/// SQLite's primary result codes for a damaged file: SQLITE_CORRUPT and SQLITE_NOTADB.
const CORRUPT_CODES: [i64; 2] = [11, 26];

/// True when the driver's error says the file is damaged: SQLite's corruption codes, or a
/// value that does not decode (gyrocal only writes what it reads back, so a row whose text
/// is not UTF-8 or whose number is text was garbled on disk).
pub(crate) fn says_damaged(e: &sqlx::Error) -> bool {
    match e {
        sqlx::Error::Database(db) => {
            db.try_downcast_ref::<sqlx::sqlite::SqliteError>().is_some()
                && db
                    .code()
                    .and_then(|c| c.parse::<i64>().ok())
                    .is_some_and(|c| CORRUPT_CODES.contains(&(c & 0xff)))
        }
        sqlx::Error::ColumnDecode { .. } | sqlx::Error::Decode(_) => true,
        _ => false,
    }
}

/// The findings of `sql` (an integrity pragma), without the `ok` that means none.
async fn findings(pool: &SqlitePool, sql: &str) -> Result<Vec<String>, sqlx::Error> {
    let rows = sqlx::query(sql).fetch_all(pool).await?;
    let mut out = Vec::new();
    for row in &rows {
        let line: String = row.try_get(0)?;
        if line != "ok" {
            out.push(line);
        }
    }
    Ok(out)
}

/// `findings` as one line for a message: the first few, and how many more.
fn summarise(findings: &[String]) -> String {
    let mut text = findings
        .iter()
        .take(QUOTED)
        .cloned()
        .collect::<Vec<_>>()
        .join("; ");
    if findings.len() > QUOTED {
        text.push_str(&format!(" (and {} more)", findings.len() - QUOTED));
    }
    text
}

/// What is wrong with the tables a listing reads (`PRAGMA integrity_check(TABLE)` on each of
/// [`LISTED_TABLES`]), as a message, or `None` when they are sound. An error of the check
/// itself is returned as it is (the caller classifies it).
pub(crate) async fn listed_tables_damage(pool: &SqlitePool) -> Result<Option<String>, sqlx::Error> {
    let mut all = Vec::new();
    for table in LISTED_TABLES {
        // the table names are this crate's constants, never input
        all.extend(findings(pool, &format!("PRAGMA integrity_check({table})")).await?);
    }
    Ok((!all.is_empty()).then(|| format!("integrity_check: {}", summarise(&all))))
}

/// What `PRAGMA quick_check` finds wrong with the whole file, as a message, or `None` when it
/// finds nothing (or cannot run: the caller has an error to report already).
pub(crate) async fn quick_check(pool: &SqlitePool) -> Option<String> {
    match findings(pool, "PRAGMA quick_check").await {
        Ok(f) if f.is_empty() => None,
        Ok(f) => Some(format!("quick_check: {}", summarise(&f))),
        Err(e) if says_damaged(&e) => Some(format!("quick_check: {e}")),
        Err(_) => None,
    }
}

/// Whether the SQLite file at `path` is damaged: opens it (creating nothing) on one
/// connection and runs `PRAGMA integrity_check` on the whole file. `Ok(Some(what))` when
/// SQLite finds damage or cannot read the file as a database, `Ok(None)` when it is sound or
/// missing; an error that says nothing about the file's state (permissions, a lock held past
/// the busy timeout) is returned as an error, and the file is left alone.
pub async fn sqlite_damage(path: &Path) -> Result<Option<String>, CatalogError> {
    if !path.exists() {
        return Ok(None);
    }
    let url = crate::CatalogUrl::Sqlite(path.to_path_buf());
    let fail = |e: &sqlx::Error| {
        if says_damaged(e) {
            Ok(Some(e.to_string()))
        } else {
            Err(CatalogError::Database {
                url: url.redacted(),
                message: e.to_string(),
            })
        }
    };
    let options = SqliteConnectOptions::new()
        .filename(path)
        .create_if_missing(false)
        .busy_timeout(std::time::Duration::from_secs(10));
    let mut conn = match options.connect().await {
        Ok(c) => c,
        Err(e) => return fail(&e),
    };
    let rows = sqlx::query("PRAGMA integrity_check")
        .fetch_all(&mut conn)
        .await;
    let _ = conn.close().await;
    let rows = match rows {
        Ok(r) => r,
        Err(e) => return fail(&e),
    };
    let mut found = Vec::new();
    for row in &rows {
        match row.try_get::<String, _>(0) {
            Ok(line) if line == "ok" => {}
            Ok(line) => found.push(line),
            Err(e) => return fail(&e),
        }
    }
    Ok((!found.is_empty()).then(|| format!("integrity_check: {}", summarise(&found))))
}

/// Renames the damaged catalog `path` (and its `-wal` and `-shm` companions, which belong to
/// it) to `PATH.damaged-YYYYMMDDTHHMMSSZ` (with `-2`, `-3`, ... when that name is taken), and
/// returns the new name. Nothing is deleted.
pub fn set_aside(path: &Path) -> Result<PathBuf, CatalogError> {
    let stamp: String = gyrocal_files::rfc3339_utc(std::time::SystemTime::now())
        .chars()
        .take(19)
        .filter(|c| !matches!(c, '-' | ':'))
        .collect();
    let with = |suffix: &str| {
        let mut name = path.as_os_str().to_os_string();
        name.push(suffix);
        PathBuf::from(name)
    };
    let mut target = with(&format!(".damaged-{stamp}Z"));
    let mut n = 2;
    while target.exists() {
        target = with(&format!(".damaged-{stamp}Z-{n}"));
        n += 1;
    }
    std::fs::rename(path, &target).map_err(|source| CatalogError::Io {
        path: path.to_path_buf(),
        action: "move the damaged catalog aside",
        source,
    })?;
    for companion in ["-wal", "-shm"] {
        let from = with(companion);
        if from.exists() {
            let mut to = target.as_os_str().to_os_string();
            to.push(companion);
            std::fs::rename(&from, &to).map_err(|source| CatalogError::Io {
                path: from.clone(),
                action: "move the damaged catalog's companion file aside",
                source,
            })?;
        }
    }
    Ok(target)
}
