//! The catalog itself: one interface, two backends (SQLite, PostgreSQL).
//!
//! Both backends run the same SQL text: `$N` placeholders (SQLite reads them as numbered
//! parameters), `INSERT ... ON CONFLICT ... DO UPDATE`, types both understand (`TEXT`,
//! `BIGINT`, `DOUBLE PRECISION`, `BOOLEAN`) and times as RFC 3339 UTC text (which sorts as
//! time). Every value reaches the database as a bound parameter, never inside the SQL text.

use std::borrow::Cow;
use std::path::Path;
use std::str::FromStr as _;
use std::time::Duration;

use sqlx::migrate::{Migration, MigrationSource, MigrationType, Migrator};
use sqlx::postgres::{PgConnectOptions, PgPool, PgPoolOptions};
use sqlx::sqlite::{
    SqliteConnectOptions, SqliteJournalMode, SqlitePool, SqlitePoolOptions, SqliteSynchronous,
};

use crate::error::CatalogError;
use crate::health;
use crate::url::CatalogUrl;

// The migrations: one folder (`migrations/`) for both backends, compiled in.
//
// Why the headers below: sqlx records each applied migration's checksum (SHA-384 of its SQL
// text) in `_sqlx_migrations` and refuses to open a database whose recorded checksum differs
// from the program's. Releases up to 0.1 kept one copy of version 1 per backend, identical but
// for a two-line comment naming the backend; a catalog they created recorded the checksum of
// that text. So version 1 is its shared body (`migrations/0001_catalog.sql`) behind the
// backend's original comment, byte for byte the text those releases ran, and such a catalog
// opens without a migration mismatch (tests/catalog.rs,
// `a_catalog_made_with_the_per_backend_migrations_opens`; the old files are kept in
// tests/fixtures/migrations-0.1). Versions 2 on were always the same text for both backends:
// no header. A new migration is one file in `migrations/`, listed once in `migrations()`.

/// The comment that opened version 1 of the SQLite migrations up to release 0.1 (part of the
/// checksum recorded in catalogs created by them).
const SQLITE_V1_HEADER: &str = "-- gyrocal catalog, schema version 1 (SQLite). Documented in SCHEMA.md; keep the PostgreSQL\n-- twin (migrations/postgres/0001_catalog.sql) in step.\n";
/// The same for PostgreSQL.
const POSTGRES_V1_HEADER: &str = "-- gyrocal catalog, schema version 1 (PostgreSQL). Documented in SCHEMA.md; keep the SQLite\n-- twin (migrations/sqlite/0001_catalog.sql) in step.\n";
/// Version 1's statements, shared by both backends.
const V1_CATALOG: &str = include_str!("../migrations/0001_catalog.sql");
/// Version 2: a drift test's figures.
const V2_DRIFT_RESULTS: &str = include_str!("../migrations/0002_drift_results.sql");
/// Version 3: a temperature series' sensitivities and points.
const V3_SERIES_RESULTS: &str = include_str!("../migrations/0003_series_results.sql");
/// Version 4: the live state of the runs going on (`live_runs`).
const V4_LIVE_RUNS: &str = include_str!("../migrations/0004_live_runs.sql");

/// Which backend a set of migrations is for (only version 1's leading comment differs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Backend {
    Sqlite,
    Postgres,
}

/// The migrations of `backend`, oldest first: (version, description, SQL text as checksummed).
fn migrations(backend: Backend) -> Vec<(i64, &'static str, Cow<'static, str>)> {
    let header = match backend {
        Backend::Sqlite => SQLITE_V1_HEADER,
        Backend::Postgres => POSTGRES_V1_HEADER,
    };
    vec![
        (1, "catalog", Cow::Owned(format!("{header}{V1_CATALOG}"))),
        (2, "drift results", Cow::Borrowed(V2_DRIFT_RESULTS)),
        (3, "series results", Cow::Borrowed(V3_SERIES_RESULTS)),
        (4, "live runs", Cow::Borrowed(V4_LIVE_RUNS)),
    ]
}

/// The migrations compiled into the program (no migration files at run time).
#[derive(Debug)]
struct Embedded(Backend);

impl<'s> MigrationSource<'s> for Embedded {
    fn resolve(
        self,
    ) -> std::pin::Pin<
        Box<
            dyn std::future::Future<Output = Result<Vec<Migration>, sqlx::error::BoxDynError>>
                + Send
                + 's,
        >,
    > {
        Box::pin(async move {
            Ok(migrations(self.0)
                .into_iter()
                .map(|(version, description, sql)| {
                    Migration::new(
                        version,
                        Cow::Borrowed(description),
                        MigrationType::Simple,
                        sql,
                        false,
                    )
                })
                .collect())
        })
    }
}

/// How to open a catalog.
#[derive(Debug, Clone)]
pub struct OpenOptions {
    /// The longest wait for a connection (PostgreSQL: connecting; SQLite: a free pooled
    /// connection). Short for the run hook, so an unreachable server costs seconds, not
    /// minutes.
    pub connect_timeout: Duration,
    /// The longest an SQLite statement waits for another process's write lock.
    pub busy_timeout: Duration,
    /// Connections in the pool.
    pub max_connections: u32,
    /// Create a missing SQLite file (and its directory). Off for the listing commands
    /// (`runs`, `history`), which create nothing: a missing file is
    /// [`CatalogError::NotFound`].
    pub create: bool,
}

impl Default for OpenOptions {
    fn default() -> Self {
        OpenOptions {
            connect_timeout: Duration::from_secs(5),
            busy_timeout: Duration::from_secs(10),
            max_connections: 4,
            create: true,
        }
    }
}

#[derive(Debug, Clone)]
enum Pool {
    Sqlite(SqlitePool),
    Postgres(PgPool),
}

/// Runs `$body` with `$p` bound to the concrete pool: the same code for both backends.
macro_rules! on_pool {
    ($self:expr, |$p:ident| $body:expr) => {
        match &$self.pool {
            Pool::Sqlite($p) => $body,
            Pool::Postgres($p) => $body,
        }
    };
}

// after `on_pool!`, which they use
pub(crate) mod live;
mod reads;
mod series;
mod write;

/// An open catalog.
#[derive(Debug, Clone)]
pub struct Catalog {
    url: CatalogUrl,
    pool: Pool,
}

/// Filters of [`Catalog::runs`] (all optional, combined with AND).
#[derive(Debug, Clone, Default)]
pub struct RunFilter {
    /// The gyro's serial.
    pub serial: Option<String>,
    /// The run's status (`complete`, `failed`, ...).
    pub status: Option<String>,
    /// Runs started at or after this (RFC 3339 or a date `YYYY-MM-DD`, UTC).
    pub since: Option<String>,
    /// The station's id.
    pub station: Option<String>,
    /// At most this many runs (newest first).
    pub limit: Option<i64>,
}

fn now_utc() -> String {
    gyrocal_files::rfc3339_utc(std::time::SystemTime::now())
}

impl Catalog {
    /// The catalog to use: see [`crate::resolve`] (`--catalog`, then `GYROCAL_CATALOG`, then
    /// the station file's `catalog` key, then the SQLite file in the user's data directory).
    pub fn resolve(
        flag: Option<&str>,
        station_catalog: Option<&str>,
    ) -> Result<CatalogUrl, CatalogError> {
        crate::url::resolve(flag, station_catalog)
    }

    /// Opens (creating an SQLite file and its directory when missing) and brings the schema
    /// up to date, with [`OpenOptions::default`].
    pub async fn open(url: &CatalogUrl) -> Result<Catalog, CatalogError> {
        Catalog::open_with(url, &OpenOptions::default()).await
    }

    /// Opens an existing catalog to list from it (`gyrocal runs`, `gyrocal history`):
    /// creates nothing (a missing SQLite file is [`CatalogError::NotFound`]) and reports a
    /// damaged one as [`CatalogError::Damaged`].
    pub async fn open_existing(url: &CatalogUrl) -> Result<Catalog, CatalogError> {
        let opts = OpenOptions {
            create: false,
            ..OpenOptions::default()
        };
        Catalog::open_with(url, &opts).await
    }

    /// [`Catalog::open`] with explicit timeouts.
    pub async fn open_with(url: &CatalogUrl, opts: &OpenOptions) -> Result<Catalog, CatalogError> {
        let pool = match url {
            CatalogUrl::Sqlite(path) if !opts.create => {
                match std::fs::metadata(path) {
                    Ok(m) if m.is_file() => {}
                    Ok(_) => {
                        return Err(CatalogError::Io {
                            path: path.clone(),
                            action: "open the catalog",
                            source: std::io::Error::other("not a regular file"),
                        });
                    }
                    Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                        return Err(CatalogError::NotFound { path: path.clone() });
                    }
                    Err(source) => {
                        return Err(CatalogError::Io {
                            path: path.clone(),
                            action: "open the catalog",
                            source,
                        });
                    }
                }
                Pool::Sqlite(sqlite_pool(url, path, opts).await?)
            }
            CatalogUrl::Sqlite(path) => {
                if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
                    std::fs::create_dir_all(parent).map_err(|source| CatalogError::Io {
                        path: parent.to_path_buf(),
                        action: "create the catalog's directory",
                        source,
                    })?;
                }
                Pool::Sqlite(sqlite_pool(url, path, opts).await?)
            }
            CatalogUrl::Postgres(text) => {
                // PGPASSWORD and ~/.pgpass (PGPASSFILE) are read by the driver when the URL
                // carries no password, as libpq does
                let options = PgConnectOptions::from_str(text)
                    .map_err(|e| CatalogError::BadUrl {
                        url: url.redacted(),
                        message: url.scrub(&e.to_string()),
                    })?
                    .application_name("gyrocal")
                    .options([("statement_timeout", "30s")]);
                crate::pg_probe::probe(url, &options, opts.connect_timeout).await?;
                let pool = PgPoolOptions::new()
                    .max_connections(opts.max_connections)
                    .acquire_timeout(opts.connect_timeout)
                    .connect_with(options)
                    .await
                    .map_err(|e| db_error(url, &e))?;
                Pool::Postgres(pool)
            }
        };
        let catalog = Catalog {
            url: url.clone(),
            pool,
        };
        if let Err(e) = catalog.migrate(opts.busy_timeout).await {
            // a damaged file fails the migrator's reads: say so, with the repair
            return Err(match (&catalog.pool, url) {
                (Pool::Sqlite(p), CatalogUrl::Sqlite(path)) => match health::quick_check(p).await {
                    Some(found) => CatalogError::Damaged {
                        path: path.clone(),
                        message: format!("{e}; {found}"),
                    },
                    None => e,
                },
                _ => e,
            });
        }
        Ok(catalog)
    }

    /// Runs the migrations; `busy` bounds how long a migration waits for another writer's
    /// lock on an SQLite file (SQLite reports a lock it will not wait for, such as a read
    /// transaction's upgrade to a write while another connection writes, at once).
    async fn migrate(&self, busy: Duration) -> Result<(), CatalogError> {
        let source = match self.pool {
            Pool::Sqlite(_) => Embedded(Backend::Sqlite),
            Pool::Postgres(_) => Embedded(Backend::Postgres),
        };
        let migrator = Migrator::new(source)
            .await
            .map_err(|e| self.migrate_error(&e))?;
        // PostgreSQL serialises concurrent migrations with an advisory lock; SQLite has no
        // such lock, so two processes opening a new file at once may race: the loser's
        // migration fails (the tables exist) and a second attempt finds them recorded.
        // A file another writer holds locked is waited for (up to `busy`, backing off), as
        // every other write waits through the busy timeout; any other failure is tried 3 times.
        let mut last = None;
        let deadline = tokio::time::Instant::now() + busy;
        let mut pause = Duration::from_millis(50);
        let mut attempt = 0;
        while attempt < 3 {
            let result = on_pool!(self, |p| migrator.run(p).await);
            match result {
                Ok(()) => return Ok(()),
                Err(e) => {
                    tracing::debug!(attempt, error = %self.url.scrub(&e.to_string()), "migration attempt failed");
                    if let sqlx::migrate::MigrateError::Execute(inner) = &e
                        && (is_unreachable(inner) || health::says_damaged(inner))
                    {
                        return Err(db_error(&self.url, inner));
                    }
                    let locked = e.to_string().contains("database is locked");
                    if !locked || tokio::time::Instant::now() + pause > deadline {
                        attempt += 1;
                    }
                    last = Some(e);
                    tokio::time::sleep(pause).await;
                    if locked {
                        pause = (pause * 2).min(Duration::from_millis(500));
                    }
                }
            }
        }
        match last {
            Some(e) => Err(self.migrate_error(&e)),
            None => Ok(()),
        }
    }

    fn migrate_error(&self, e: &sqlx::migrate::MigrateError) -> CatalogError {
        CatalogError::Migration {
            url: self.url.redacted(),
            message: self.url.scrub(&e.to_string()),
        }
    }

    fn err(&self, e: &sqlx::Error) -> CatalogError {
        db_error(&self.url, e)
    }

    /// Before a listing reads an SQLite catalog: SQLite's check of the tables it reads
    /// against their indexes, so that a garbled row is reported instead of silently left out
    /// (see [`crate::health`]). Nothing to do on PostgreSQL, which checksums and repairs its
    /// own pages.
    async fn check_listed_tables(&self) -> Result<(), CatalogError> {
        let (Pool::Sqlite(p), CatalogUrl::Sqlite(path)) = (&self.pool, &self.url) else {
            return Ok(());
        };
        match health::listed_tables_damage(p).await {
            Ok(None) => Ok(()),
            Ok(Some(found)) => Err(CatalogError::Damaged {
                path: path.clone(),
                message: found,
            }),
            Err(e) => Err(self.read_error(&e).await),
        }
    }

    /// A listing's read failed: on SQLite the file is checked (`PRAGMA quick_check`), and a
    /// damaged file is [`CatalogError::Damaged`]; any other SQLite error names the file and
    /// the rebuild all the same, since the listing cannot be trusted either way.
    async fn read_error(&self, e: &sqlx::Error) -> CatalogError {
        let (Pool::Sqlite(p), CatalogUrl::Sqlite(path)) = (&self.pool, &self.url) else {
            return self.err(e);
        };
        let said = e.to_string();
        match health::quick_check(p).await {
            Some(found) => CatalogError::Damaged {
                path: path.clone(),
                message: format!("{said}; {found}"),
            },
            None if health::says_damaged(e) => CatalogError::Damaged {
                path: path.clone(),
                message: said,
            },
            None => CatalogError::Database {
                url: self.url.redacted(),
                message: format!(
                    "{said}; nothing is listed (if the file is damaged, `gyrocal catalog rebuild ROOT` rebuilds it from the run directories)"
                ),
            },
        }
    }

    /// The catalog's URL.
    pub fn url(&self) -> &CatalogUrl {
        &self.url
    }

    /// Reads the run directory and writes its rows (see [`Catalog::upsert`]). Returns the
    /// run's id.
    pub async fn import_dir(&self, dir: &Path) -> Result<String, CatalogError> {
        let host = crate::record::host_name();
        let record = crate::record::read_run(dir, host.as_deref())?;
        self.upsert(&record).await?;
        Ok(record.run.id)
    }

    /// Closes the pool (waits for connections in use to come back). An SQLite catalog is
    /// checkpointed first, so that the file is whole on its own (its rows not left in the
    /// `-wal` file) for a copy or a backup; a checkpoint another process holds up is skipped.
    pub async fn close(&self) {
        if let Pool::Sqlite(p) = &self.pool {
            let checkpoint = async {
                let mut conn = p.acquire().await?;
                // a checkpoint waits for other processes' readers: briefly, at the end
                sqlx::query("PRAGMA busy_timeout = 200")
                    .execute(&mut *conn)
                    .await?;
                sqlx::query("PRAGMA wal_checkpoint(TRUNCATE)")
                    .execute(&mut *conn)
                    .await
            };
            if let Err(e) = checkpoint.await {
                tracing::debug!(error = %e, "no checkpoint at close");
            }
        }
        on_pool!(self, |p| p.close().await);
    }
}

fn is_unreachable(e: &sqlx::Error) -> bool {
    matches!(
        e,
        sqlx::Error::Io(_)
            | sqlx::Error::PoolTimedOut
            | sqlx::Error::PoolClosed
            | sqlx::Error::Tls(_)
            | sqlx::Error::WorkerCrashed
    )
}

/// The pool of an SQLite catalog (the file exists, or `opts.create` allows creating it).
async fn sqlite_pool(
    url: &CatalogUrl,
    path: &Path,
    opts: &OpenOptions,
) -> Result<SqlitePool, CatalogError> {
    let options = SqliteConnectOptions::new()
        .filename(path)
        .create_if_missing(opts.create)
        // several gyrocal processes on one machine: readers never block the writer, and a
        // writer waits for another's lock instead of failing
        .journal_mode(SqliteJournalMode::Wal)
        .synchronous(SqliteSynchronous::Normal)
        .busy_timeout(opts.busy_timeout)
        .foreign_keys(true);
    // Two processes creating or opening one file at once: switching it to WAL takes a lock
    // SQLite reports at once instead of waiting for; wait for it (backing off, up to the busy
    // timeout) as every other write waits.
    let deadline = tokio::time::Instant::now() + opts.busy_timeout;
    let mut pause = Duration::from_millis(20);
    loop {
        let result = SqlitePoolOptions::new()
            .max_connections(opts.max_connections)
            .acquire_timeout(opts.connect_timeout.max(opts.busy_timeout))
            .connect_with(options.clone())
            .await;
        match result {
            Err(e)
                if e.to_string().contains("database is locked")
                    && tokio::time::Instant::now() + pause < deadline =>
            {
                tracing::debug!(error = %e, "the catalog file is locked: waiting");
                tokio::time::sleep(pause).await;
                pause = (pause * 2).min(Duration::from_millis(500));
            }
            other => return other.map_err(|e| db_error(url, &e)),
        }
    }
}

/// A driver error as a [`CatalogError`], its message scrubbed of the URL's password. A
/// damaged SQLite file is [`CatalogError::Damaged`].
pub(crate) fn db_error(url: &CatalogUrl, e: &sqlx::Error) -> CatalogError {
    let message = url.scrub(&e.to_string());
    if let CatalogUrl::Sqlite(path) = url
        && health::says_damaged(e)
    {
        return CatalogError::Damaged {
            path: path.clone(),
            message,
        };
    }
    if is_unreachable(e) {
        CatalogError::Unreachable {
            url: url.redacted(),
            message,
        }
    } else {
        CatalogError::Database {
            url: url.redacted(),
            message,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{Backend, migrations};

    /// Each backend's migrations are, byte for byte, the text releases up to 0.1 ran from their
    /// per-backend folders (kept in tests/fixtures/migrations-0.1): so the checksums sqlx
    /// recorded in their catalogs match.
    #[test]
    fn each_backend_runs_the_text_the_per_backend_folders_held() {
        let old = |backend: Backend| -> [&str; 2] {
            match backend {
                Backend::Sqlite => [
                    include_str!("../tests/fixtures/migrations-0.1/sqlite/0001_catalog.sql"),
                    include_str!("../tests/fixtures/migrations-0.1/sqlite/0002_drift_results.sql"),
                ],
                Backend::Postgres => [
                    include_str!("../tests/fixtures/migrations-0.1/postgres/0001_catalog.sql"),
                    include_str!(
                        "../tests/fixtures/migrations-0.1/postgres/0002_drift_results.sql"
                    ),
                ],
            }
        };
        for backend in [Backend::Sqlite, Backend::Postgres] {
            let new = migrations(backend);
            // the versions that release had; the later ones (3: the series tables, 4: the live runs) are new
            assert_eq!(new.len(), 4, "{backend:?}");
            for (i, (version, _, sql)) in new.iter().take(2).enumerate() {
                assert_eq!(*version, i as i64 + 1);
                assert_eq!(
                    sql.as_ref(),
                    old(backend)[i],
                    "{backend:?} version {version}"
                );
            }
        }
    }
}
