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

use sqlx::Row as _;
use sqlx::migrate::{Migration, MigrationSource, MigrationType, Migrator};
use sqlx::postgres::{PgConnectOptions, PgPool, PgPoolOptions};
use sqlx::sqlite::{
    SqliteConnectOptions, SqliteJournalMode, SqlitePool, SqlitePoolOptions, SqliteSynchronous,
};

use crate::error::CatalogError;
use crate::health;
use crate::record::{CheckRow, InstrumentRow, Results, RunRecord, RunRow, StepRow};
use crate::rows::{Calibration, RunSummary};
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

// after `on_pool!`, which it uses
mod series;

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

const RUN_COLUMNS: &str = "r.id, r.directory, r.host, r.station_id, r.plan_name, r.plan_hash, \
     r.kind, r.dut_serial, r.dut_model, r.operator, r.customer, r.status, r.reason, \
     r.started_utc, r.ended_utc, r.simulated, r.verdict, r.acceptance_rule, r.steps_total, \
     r.steps_done, r.ambient_c, r.humidity_pct, r.gyrocal_version";
const RESULT_COLUMNS: &str = "res.run_id AS res_run_id, res.scale_factor, \
     res.scale_factor_std_error, res.bias_v, res.bias_v_std_error, res.bias_dph, res.k_pos, \
     res.k_neg, res.k2, res.nonlinearity_ppm, res.asymmetry_ppm, res.asymmetry_common_k2_ppm, \
     res.repeatability_ppm, res.u_scale_factor, res.u_bias_v, res.u_bias_dph, res.u_k_pos, \
     res.u_k_neg, res.best_model, res.arw_deg_rt_h, res.u_arw_deg_rt_h, \
     res.bias_instability_dph, res.u_bias_instability_dph, res.rrw_dph_rt_h, res.u_rrw_dph_rt_h, \
     res.drift_bias_dph, res.u_drift_bias_dph, res.bias_stability_100s_dph, res.drift_duration_s";

const UPSERT_RUN: &str = "INSERT INTO runs (id, directory, host, station_id, plan_name, \
     plan_hash, kind, dut_serial, dut_model, operator, customer, status, reason, started_utc, \
     ended_utc, simulated, verdict, acceptance_rule, steps_total, steps_done, ambient_c, \
     humidity_pct, gyrocal_version, imported_utc) VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, \
     $10, $11, $12, $13, $14, $15, $16, $17, $18, $19, $20, $21, $22, $23, $24) \
     ON CONFLICT (id) DO UPDATE SET directory = excluded.directory, host = excluded.host, \
     station_id = excluded.station_id, plan_name = excluded.plan_name, \
     plan_hash = excluded.plan_hash, kind = excluded.kind, dut_serial = excluded.dut_serial, \
     dut_model = excluded.dut_model, operator = excluded.operator, \
     customer = excluded.customer, status = excluded.status, reason = excluded.reason, \
     started_utc = excluded.started_utc, ended_utc = excluded.ended_utc, \
     simulated = excluded.simulated, verdict = excluded.verdict, \
     acceptance_rule = excluded.acceptance_rule, steps_total = excluded.steps_total, \
     steps_done = excluded.steps_done, ambient_c = excluded.ambient_c, \
     humidity_pct = excluded.humidity_pct, gyrocal_version = excluded.gyrocal_version, \
     imported_utc = excluded.imported_utc";
const INSERT_RESULTS: &str = "INSERT INTO results (run_id, scale_factor, \
     scale_factor_std_error, bias_v, bias_v_std_error, bias_dph, k_pos, k_neg, k2, \
     nonlinearity_ppm, asymmetry_ppm, asymmetry_common_k2_ppm, repeatability_ppm, \
     u_scale_factor, u_bias_v, u_bias_dph, u_k_pos, u_k_neg, best_model, arw_deg_rt_h, \
     u_arw_deg_rt_h, bias_instability_dph, u_bias_instability_dph, rrw_dph_rt_h, u_rrw_dph_rt_h, \
     drift_bias_dph, u_drift_bias_dph, bias_stability_100s_dph, drift_duration_s) VALUES ($1, \
     $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12, $13, $14, $15, $16, $17, $18, $19, $20, $21, \
     $22, $23, $24, $25, $26, $27, $28, $29)";
const INSERT_STEP: &str = "INSERT INTO steps (run_id, step, pass, rate_dps, rate_meas_dps, \
     volts, volts_std, n, overloads) VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9)";
const INSERT_INSTRUMENT: &str = "INSERT INTO instruments (run_id, role, identity, model, \
     asset_id, serial, certificate, calibrated, due) VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9)";
const INSERT_CHECK: &str = "INSERT INTO checks (run_id, quantity, value, unit, \
     expanded_uncertainty, min, max, marginal_min, marginal_max, verdict) VALUES ($1, $2, $3, \
     $4, $5, $6, $7, $8, $9, $10)";
/// The child tables, deleted before a run's rows are written again.
const CHILD_TABLES: [&str; 6] = [
    "results",
    "steps",
    "instruments",
    "checks",
    "series_results",
    "series_points",
];

/// Reads a `runs` row selected with [`RUN_COLUMNS`].
macro_rules! run_row {
    ($r:expr) => {
        RunRow {
            id: $r.try_get("id")?,
            directory: $r.try_get("directory")?,
            host: $r.try_get("host")?,
            station_id: $r.try_get("station_id")?,
            plan_name: $r.try_get("plan_name")?,
            plan_hash: $r.try_get("plan_hash")?,
            kind: $r.try_get("kind")?,
            dut_serial: $r.try_get("dut_serial")?,
            dut_model: $r.try_get("dut_model")?,
            operator: $r.try_get("operator")?,
            customer: $r.try_get("customer")?,
            status: $r.try_get("status")?,
            reason: $r.try_get("reason")?,
            started_utc: $r.try_get("started_utc")?,
            ended_utc: $r.try_get("ended_utc")?,
            simulated: $r.try_get("simulated")?,
            verdict: $r.try_get("verdict")?,
            acceptance_rule: $r.try_get("acceptance_rule")?,
            steps_total: $r.try_get("steps_total")?,
            steps_done: $r.try_get("steps_done")?,
            ambient_c: $r.try_get("ambient_c")?,
            humidity_pct: $r.try_get("humidity_pct")?,
            gyrocal_version: $r.try_get("gyrocal_version")?,
        }
    };
}

/// Reads the `results` columns selected with [`RESULT_COLUMNS`] (`None` when the LEFT JOIN
/// found none).
macro_rules! results_row {
    ($r:expr) => {{
        let present: Option<String> = $r.try_get("res_run_id")?;
        match present {
            None => None,
            Some(_) => Some(Results {
                scale_factor: $r.try_get("scale_factor")?,
                scale_factor_std_error: $r.try_get("scale_factor_std_error")?,
                bias_v: $r.try_get("bias_v")?,
                bias_v_std_error: $r.try_get("bias_v_std_error")?,
                bias_dph: $r.try_get("bias_dph")?,
                k_pos: $r.try_get("k_pos")?,
                k_neg: $r.try_get("k_neg")?,
                k2: $r.try_get("k2")?,
                nonlinearity_ppm: $r.try_get("nonlinearity_ppm")?,
                asymmetry_ppm: $r.try_get("asymmetry_ppm")?,
                asymmetry_common_k2_ppm: $r.try_get("asymmetry_common_k2_ppm")?,
                repeatability_ppm: $r.try_get("repeatability_ppm")?,
                u_scale_factor: $r.try_get("u_scale_factor")?,
                u_bias_v: $r.try_get("u_bias_v")?,
                u_bias_dph: $r.try_get("u_bias_dph")?,
                u_k_pos: $r.try_get("u_k_pos")?,
                u_k_neg: $r.try_get("u_k_neg")?,
                best_model: $r.try_get("best_model")?,
                arw_deg_rt_h: $r.try_get("arw_deg_rt_h")?,
                u_arw_deg_rt_h: $r.try_get("u_arw_deg_rt_h")?,
                bias_instability_dph: $r.try_get("bias_instability_dph")?,
                u_bias_instability_dph: $r.try_get("u_bias_instability_dph")?,
                rrw_dph_rt_h: $r.try_get("rrw_dph_rt_h")?,
                u_rrw_dph_rt_h: $r.try_get("u_rrw_dph_rt_h")?,
                drift_bias_dph: $r.try_get("drift_bias_dph")?,
                u_drift_bias_dph: $r.try_get("u_drift_bias_dph")?,
                bias_stability_100s_dph: $r.try_get("bias_stability_100s_dph")?,
                drift_duration_s: $r.try_get("drift_duration_s")?,
            }),
        }
    }};
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

    /// Writes a run's rows, replacing what the catalog held for its id, in one transaction:
    /// importing the same run twice (or from two processes at once) leaves one copy.
    pub async fn upsert(&self, rec: &RunRecord) -> Result<(), CatalogError> {
        let imported = now_utc();
        let result: Result<(), sqlx::Error> = on_pool!(self, |p| {
            async {
                let mut tx = p.begin().await?;
                let r = &rec.run;
                sqlx::query(UPSERT_RUN)
                    .bind(&r.id)
                    .bind(&r.directory)
                    .bind(&r.host)
                    .bind(&r.station_id)
                    .bind(&r.plan_name)
                    .bind(&r.plan_hash)
                    .bind(&r.kind)
                    .bind(&r.dut_serial)
                    .bind(&r.dut_model)
                    .bind(&r.operator)
                    .bind(&r.customer)
                    .bind(&r.status)
                    .bind(&r.reason)
                    .bind(&r.started_utc)
                    .bind(&r.ended_utc)
                    .bind(r.simulated)
                    .bind(&r.verdict)
                    .bind(&r.acceptance_rule)
                    .bind(r.steps_total)
                    .bind(r.steps_done)
                    .bind(r.ambient_c)
                    .bind(r.humidity_pct)
                    .bind(&r.gyrocal_version)
                    .bind(&imported)
                    .execute(&mut *tx)
                    .await?;
                for table in CHILD_TABLES {
                    sqlx::query(&format!("DELETE FROM {table} WHERE run_id = $1"))
                        .bind(&r.id)
                        .execute(&mut *tx)
                        .await?;
                }
                if let Some(x) = &rec.results {
                    sqlx::query(INSERT_RESULTS)
                        .bind(&r.id)
                        .bind(x.scale_factor)
                        .bind(x.scale_factor_std_error)
                        .bind(x.bias_v)
                        .bind(x.bias_v_std_error)
                        .bind(x.bias_dph)
                        .bind(x.k_pos)
                        .bind(x.k_neg)
                        .bind(x.k2)
                        .bind(x.nonlinearity_ppm)
                        .bind(x.asymmetry_ppm)
                        .bind(x.asymmetry_common_k2_ppm)
                        .bind(x.repeatability_ppm)
                        .bind(x.u_scale_factor)
                        .bind(x.u_bias_v)
                        .bind(x.u_bias_dph)
                        .bind(x.u_k_pos)
                        .bind(x.u_k_neg)
                        .bind(&x.best_model)
                        .bind(x.arw_deg_rt_h)
                        .bind(x.u_arw_deg_rt_h)
                        .bind(x.bias_instability_dph)
                        .bind(x.u_bias_instability_dph)
                        .bind(x.rrw_dph_rt_h)
                        .bind(x.u_rrw_dph_rt_h)
                        .bind(x.drift_bias_dph)
                        .bind(x.u_drift_bias_dph)
                        .bind(x.bias_stability_100s_dph)
                        .bind(x.drift_duration_s)
                        .execute(&mut *tx)
                        .await?;
                }
                for s in &rec.steps {
                    sqlx::query(INSERT_STEP)
                        .bind(&r.id)
                        .bind(s.step)
                        .bind(s.pass)
                        .bind(s.rate_dps)
                        .bind(s.rate_meas_dps)
                        .bind(s.volts)
                        .bind(s.volts_std)
                        .bind(s.n)
                        .bind(s.overloads)
                        .execute(&mut *tx)
                        .await?;
                }
                for i in &rec.instruments {
                    sqlx::query(INSERT_INSTRUMENT)
                        .bind(&r.id)
                        .bind(&i.role)
                        .bind(&i.identity)
                        .bind(&i.model)
                        .bind(&i.asset_id)
                        .bind(&i.serial)
                        .bind(&i.certificate)
                        .bind(&i.calibrated)
                        .bind(&i.due)
                        .execute(&mut *tx)
                        .await?;
                }
                if let Some(x) = &rec.series {
                    series::insert_series!(tx, &r.id, x);
                }
                for c in &rec.checks {
                    sqlx::query(INSERT_CHECK)
                        .bind(&r.id)
                        .bind(&c.quantity)
                        .bind(c.value)
                        .bind(&c.unit)
                        .bind(c.expanded_uncertainty)
                        .bind(c.min)
                        .bind(c.max)
                        .bind(c.marginal_min)
                        .bind(c.marginal_max)
                        .bind(&c.verdict)
                        .execute(&mut *tx)
                        .await?;
                }
                tx.commit().await
            }
            .await
        });
        result.map_err(|e| self.err(&e))
    }

    /// Deletes every row (for `gyrocal catalog rebuild`), in one transaction.
    pub async fn clear(&self) -> Result<(), CatalogError> {
        let result: Result<(), sqlx::Error> = on_pool!(self, |p| {
            async {
                let mut tx = p.begin().await?;
                for table in CHILD_TABLES.iter().chain(["runs"].iter()) {
                    sqlx::query(&format!("DELETE FROM {table}"))
                        .execute(&mut *tx)
                        .await?;
                }
                tx.commit().await
            }
            .await
        });
        result.map_err(|e| self.err(&e))
    }

    /// The runs matching `filter`, newest first, with their results.
    pub async fn runs(&self, filter: &RunFilter) -> Result<Vec<RunSummary>, CatalogError> {
        let mut sql = format!(
            "SELECT {RUN_COLUMNS}, {RESULT_COLUMNS} FROM runs r \
             LEFT JOIN results res ON res.run_id = r.id WHERE 1 = 1"
        );
        let mut binds: Vec<String> = Vec::new();
        for (column, op, value) in [
            ("r.dut_serial", "=", &filter.serial),
            ("r.status", "=", &filter.status),
            ("r.started_utc", ">=", &filter.since),
            ("r.station_id", "=", &filter.station),
        ] {
            if let Some(v) = value {
                binds.push(v.clone());
                sql.push_str(&format!(" AND {column} {op} ${}", binds.len()));
            }
        }
        sql.push_str(" ORDER BY r.started_utc DESC, r.id DESC");
        if let Some(limit) = filter.limit {
            sql.push_str(&format!(" LIMIT {}", limit.max(0)));
        }
        self.check_listed_tables().await?;
        let result: Result<Vec<RunSummary>, sqlx::Error> = on_pool!(self, |p| {
            async {
                let mut q = sqlx::query(&sql);
                for b in &binds {
                    q = q.bind(b);
                }
                let rows = q.fetch_all(p).await?;
                let mut out = Vec::with_capacity(rows.len());
                for row in &rows {
                    out.push(RunSummary {
                        run: run_row!(row),
                        results: results_row!(row),
                    });
                }
                Ok(out)
            }
            .await
        });
        match result {
            Ok(out) => Ok(out),
            Err(e) => Err(self.read_error(&e).await),
        }
    }

    /// The complete calibrations of the gyro `serial`, oldest first, with results and
    /// acceptance checks; simulated runs only when `include_simulated`.
    pub async fn calibrations(
        &self,
        serial: &str,
        include_simulated: bool,
    ) -> Result<Vec<Calibration>, CatalogError> {
        // Every run of the serial is read and decoded, and the status and simulated filters
        // applied here rather than in SQL: a row garbled on disk then fails to decode (or
        // shows a status gyrocal never writes) instead of silently failing a WHERE clause
        // and leaving the history one calibration short.
        let sql = format!(
            "SELECT {RUN_COLUMNS}, {RESULT_COLUMNS} FROM runs r \
             LEFT JOIN results res ON res.run_id = r.id \
             WHERE r.dut_serial = $1 \
             ORDER BY r.started_utc, r.id"
        );
        let checks_sql = "SELECT c.run_id, c.quantity, c.value, c.unit, \
             c.expanded_uncertainty, c.min, c.max, c.marginal_min, c.marginal_max, c.verdict \
             FROM checks c JOIN runs r ON r.id = c.run_id WHERE r.dut_serial = $1";
        let rates_sql = "SELECT DISTINCT s.run_id, s.rate_dps FROM steps s \
             JOIN runs r ON r.id = s.run_id WHERE r.dut_serial = $1";
        self.check_listed_tables().await?;
        let result: Result<Vec<Calibration>, sqlx::Error> = on_pool!(self, |p| {
            async {
                let rows = sqlx::query(&sql).bind(serial).fetch_all(p).await?;
                let mut out = Vec::with_capacity(rows.len());
                for row in &rows {
                    let run: RunRow = run_row!(row);
                    let results = results_row!(row);
                    if !is_status_word(&run.status) {
                        return Err(sqlx::Error::Decode(
                            format!(
                                "run {} has the status {:?}, which gyrocal never writes",
                                run.id, run.status
                            )
                            .into(),
                        ));
                    }
                    if run.status != "complete" || (run.simulated && !include_simulated) {
                        continue;
                    }
                    out.push(Calibration {
                        run,
                        results,
                        checks: Vec::new(),
                        rates_dps: Vec::new(),
                        series: None,
                    });
                }
                let rows = sqlx::query(checks_sql).bind(serial).fetch_all(p).await?;
                let mut index = std::collections::HashMap::new();
                for (i, c) in out.iter().enumerate() {
                    index.insert(c.run.id.clone(), i);
                }
                for row in &rows {
                    let id: String = row.try_get("run_id")?;
                    let check = CheckRow {
                        quantity: row.try_get("quantity")?,
                        value: row.try_get("value")?,
                        unit: row.try_get("unit")?,
                        expanded_uncertainty: row.try_get("expanded_uncertainty")?,
                        min: row.try_get("min")?,
                        max: row.try_get("max")?,
                        marginal_min: row.try_get("marginal_min")?,
                        marginal_max: row.try_get("marginal_max")?,
                        verdict: row.try_get("verdict")?,
                    };
                    if let Some(&i) = index.get(&id) {
                        out[i].checks.push(check);
                    }
                }
                // the rates each run demanded: the history tells plans apart by them (a
                // different simulation seed is the same plan, a different rate list is not)
                let rows = sqlx::query(rates_sql).bind(serial).fetch_all(p).await?;
                for row in &rows {
                    let id: String = row.try_get("run_id")?;
                    let rate: f64 = row.try_get("rate_dps")?;
                    if let Some(&i) = index.get(&id) {
                        out[i].rates_dps.push(rate);
                    }
                }
                for c in &mut out {
                    c.rates_dps.sort_by(f64::total_cmp);
                    c.rates_dps.dedup();
                }
                Ok(out)
            }
            .await
        });
        let mut out = match result {
            Ok(out) => out,
            Err(e) => return Err(self.read_error(&e).await),
        };
        // a temperature series' sensitivities and points (schema version 3)
        let mut series = self.series_of_serial(serial).await?;
        for c in &mut out {
            c.series = series.remove(&c.run.id);
        }
        Ok(out)
    }

    /// The finished steps of a run, in order.
    pub async fn steps(&self, run_id: &str) -> Result<Vec<StepRow>, CatalogError> {
        let sql = "SELECT step, pass, rate_dps, rate_meas_dps, volts, volts_std, n, overloads \
                   FROM steps WHERE run_id = $1 ORDER BY step";
        let result: Result<Vec<StepRow>, sqlx::Error> = on_pool!(self, |p| {
            async {
                let rows = sqlx::query(sql).bind(run_id).fetch_all(p).await?;
                let mut out = Vec::with_capacity(rows.len());
                for row in &rows {
                    out.push(StepRow {
                        step: row.try_get("step")?,
                        pass: row.try_get("pass")?,
                        rate_dps: row.try_get("rate_dps")?,
                        rate_meas_dps: row.try_get("rate_meas_dps")?,
                        volts: row.try_get("volts")?,
                        volts_std: row.try_get("volts_std")?,
                        n: row.try_get("n")?,
                        overloads: row.try_get("overloads")?,
                    });
                }
                Ok(out)
            }
            .await
        });
        result.map_err(|e| self.err(&e))
    }

    /// The instruments of a run.
    pub async fn instruments(&self, run_id: &str) -> Result<Vec<InstrumentRow>, CatalogError> {
        let sql = "SELECT role, identity, model, asset_id, serial, certificate, calibrated, due \
                   FROM instruments WHERE run_id = $1 ORDER BY role";
        let result: Result<Vec<InstrumentRow>, sqlx::Error> = on_pool!(self, |p| {
            async {
                let rows = sqlx::query(sql).bind(run_id).fetch_all(p).await?;
                let mut out = Vec::with_capacity(rows.len());
                for row in &rows {
                    out.push(InstrumentRow {
                        role: row.try_get("role")?,
                        identity: row.try_get("identity")?,
                        model: row.try_get("model")?,
                        asset_id: row.try_get("asset_id")?,
                        serial: row.try_get("serial")?,
                        certificate: row.try_get("certificate")?,
                        calibrated: row.try_get("calibrated")?,
                        due: row.try_get("due")?,
                    });
                }
                Ok(out)
            }
            .await
        });
        result.map_err(|e| self.err(&e))
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

/// A run status as gyrocal writes it (`complete`, `failed`, ...): lower-case ASCII words.
fn is_status_word(status: &str) -> bool {
    !status.is_empty() && status.bytes().all(|b| b.is_ascii_lowercase() || b == b'_')
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
            // the versions that release had; the later ones (3: the series tables) are new
            assert_eq!(new.len(), 3, "{backend:?}");
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
