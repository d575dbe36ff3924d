//! The `live_runs` table (schema version 4, see [`crate::live`]): a run's live state upserted
//! with a `NOTIFY gyrocal_live, 'RUN_ID'` in the same transaction (PostgreSQL delivers it at
//! the commit, so a listener that re-reads finds the new row), the rows read back, and the
//! listener of `gyrocal serve`.

use std::time::Duration;

use sqlx::Row as _;
use sqlx::postgres::PgListener;

use super::{Catalog, Pool};
use crate::error::CatalogError;
use crate::live::{LIVE_CHANNEL, LIVE_KEEP_ENDED, LIVE_KEEP_SILENT, LiveRow, MAX_STATE_JSON};

const UPSERT_LIVE: &str = "INSERT INTO live_runs (run_id, host, station_id, dut_serial, \
     plan_name, kind, phase, step, steps, steps_done, eta_s, last_reading_v, running_mean_v, \
     table_state, status, verdict, updated_utc, state_json) VALUES ($1, $2, $3, $4, $5, $6, \
     $7, $8, $9, $10, $11, $12, $13, $14, $15, $16, $17, $18) \
     ON CONFLICT (run_id, host) DO UPDATE SET station_id = excluded.station_id, \
     dut_serial = excluded.dut_serial, plan_name = excluded.plan_name, kind = excluded.kind, \
     phase = excluded.phase, step = excluded.step, steps = excluded.steps, \
     steps_done = excluded.steps_done, eta_s = excluded.eta_s, \
     last_reading_v = excluded.last_reading_v, running_mean_v = excluded.running_mean_v, \
     table_state = excluded.table_state, status = excluded.status, verdict = excluded.verdict, \
     updated_utc = excluded.updated_utc, state_json = excluded.state_json";

const LIVE_COLUMNS: &str = "run_id, host, station_id, dut_serial, plan_name, kind, phase, \
     step, steps, steps_done, eta_s, last_reading_v, running_mean_v, table_state, status, \
     verdict, updated_utc, state_json";

/// The most rows [`Catalog::live_runs`] returns (newest first): bounded work per request.
pub const MAX_LIVE_ROWS: i64 = 1000;

macro_rules! live_row {
    ($r:expr) => {
        LiveRow {
            run_id: $r.try_get("run_id")?,
            host: $r.try_get("host")?,
            station_id: $r.try_get("station_id")?,
            dut_serial: $r.try_get("dut_serial")?,
            plan_name: $r.try_get("plan_name")?,
            kind: $r.try_get("kind")?,
            phase: $r.try_get("phase")?,
            step: $r.try_get("step")?,
            steps: $r.try_get("steps")?,
            steps_done: $r.try_get("steps_done")?,
            eta_s: $r.try_get("eta_s")?,
            last_reading_v: $r.try_get("last_reading_v")?,
            running_mean_v: $r.try_get("running_mean_v")?,
            table_state: $r.try_get("table_state")?,
            status: $r.try_get("status")?,
            verdict: $r.try_get("verdict")?,
            updated_utc: $r.try_get("updated_utc")?,
            state_json: $r.try_get("state_json")?,
        }
    };
}

/// What a listener heard.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LiveNews {
    /// The run with this id changed (re-read its rows).
    Changed(String),
    /// The connection was lost and made again: notifications may have been missed (re-read
    /// every row).
    Reconnected,
}

/// A `LISTEN gyrocal_live` connection (PostgreSQL only), see [`Catalog::listen_live`].
pub struct LiveListener {
    inner: PgListener,
    url: crate::url::CatalogUrl,
}

impl std::fmt::Debug for LiveListener {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("LiveListener")
    }
}

impl LiveListener {
    /// The next notification; [`LiveNews::Reconnected`] after the connection was lost (it is
    /// made again at the next call). An error when the server cannot be reached: the caller
    /// waits and calls again.
    pub async fn recv(&mut self) -> Result<LiveNews, CatalogError> {
        match self.inner.try_recv().await {
            Ok(Some(n)) => Ok(LiveNews::Changed(n.payload().to_string())),
            Ok(None) => Ok(LiveNews::Reconnected),
            Err(e) => Err(super::db_error(&self.url, &e)),
        }
    }
}

impl Catalog {
    /// Whether this catalog can carry live states (PostgreSQL: a shared server with
    /// `LISTEN`/`NOTIFY`; an SQLite file cannot notify another process).
    pub fn carries_live(&self) -> bool {
        matches!(self.pool, Pool::Postgres(_))
    }

    /// Upserts a run's live state and, on PostgreSQL, notifies `gyrocal_live` with its id in
    /// the same transaction. A state longer than [`MAX_STATE_JSON`] is refused (the
    /// publisher trims it first).
    pub async fn publish_live(&self, row: &LiveRow) -> Result<(), CatalogError> {
        if row.state_json.len() > MAX_STATE_JSON {
            return Err(CatalogError::Database {
                url: self.url.redacted(),
                message: format!(
                    "the live state of {} is {} bytes, more than {MAX_STATE_JSON}",
                    row.run_id,
                    row.state_json.len()
                ),
            });
        }
        let notify = self.carries_live();
        let result: Result<(), sqlx::Error> = on_pool!(self, |p| {
            async {
                let mut tx = p.begin().await?;
                sqlx::query(UPSERT_LIVE)
                    .bind(&row.run_id)
                    .bind(&row.host)
                    .bind(&row.station_id)
                    .bind(&row.dut_serial)
                    .bind(&row.plan_name)
                    .bind(&row.kind)
                    .bind(&row.phase)
                    .bind(row.step)
                    .bind(row.steps)
                    .bind(row.steps_done)
                    .bind(row.eta_s)
                    .bind(row.last_reading_v)
                    .bind(row.running_mean_v)
                    .bind(&row.table_state)
                    .bind(&row.status)
                    .bind(&row.verdict)
                    .bind(&row.updated_utc)
                    .bind(&row.state_json)
                    .execute(&mut *tx)
                    .await?;
                if notify {
                    sqlx::query("SELECT pg_notify($1, $2)")
                        .bind(LIVE_CHANNEL)
                        .bind(&row.run_id)
                        .execute(&mut *tx)
                        .await?;
                }
                tx.commit().await
            }
            .await
        });
        result.map_err(|e| self.err(&e))
    }

    /// The live rows, newest update first, at most [`MAX_LIVE_ROWS`]; only the run `run_id`'s
    /// when given.
    pub async fn live_runs(&self, run_id: Option<&str>) -> Result<Vec<LiveRow>, CatalogError> {
        let sql = match run_id {
            Some(_) => format!(
                "SELECT {LIVE_COLUMNS} FROM live_runs WHERE run_id = $1 \
                 ORDER BY updated_utc DESC LIMIT {MAX_LIVE_ROWS}"
            ),
            None => format!(
                "SELECT {LIVE_COLUMNS} FROM live_runs ORDER BY updated_utc DESC \
                 LIMIT {MAX_LIVE_ROWS}"
            ),
        };
        let result: Result<Vec<LiveRow>, sqlx::Error> = on_pool!(self, |p| {
            async {
                let mut q = sqlx::query(&sql);
                if let Some(id) = run_id {
                    q = q.bind(id);
                }
                let rows = q.fetch_all(p).await?;
                let mut out = Vec::with_capacity(rows.len());
                for row in &rows {
                    out.push(live_row!(row));
                }
                Ok(out)
            }
            .await
        });
        result.map_err(|e| self.err(&e))
    }

    /// Deletes the rows of `live_runs` that no view needs any more, as of `now`: an ended
    /// run's row last updated more than [`LIVE_KEEP_ENDED`] ago, and a `running` row not
    /// updated for [`LIVE_KEEP_SILENT`] (its run was killed or its host lost). Without this
    /// the table grows by a row per run forever (`gyrocal serve` calls it at its start and
    /// hourly; [`LiveRow::prunable`] says the same of a row in memory). Returns the number of rows
    /// deleted.
    pub async fn prune_live(&self, now: std::time::SystemTime) -> Result<u64, CatalogError> {
        let (ended, silent) = (
            crate::live::cutoff(now, LIVE_KEEP_ENDED),
            crate::live::cutoff(now, LIVE_KEEP_SILENT),
        );
        let result: Result<u64, sqlx::Error> = on_pool!(self, |p| {
            sqlx::query(
                "DELETE FROM live_runs WHERE (status <> 'running' AND updated_utc < $1) \
                 OR (status = 'running' AND updated_utc < $2)",
            )
            .bind(&ended)
            .bind(&silent)
            .execute(p)
            .await
            .map(|r| r.rows_affected())
        });
        result.map_err(|e| self.err(&e))
    }

    /// `LISTEN gyrocal_live` on a connection of its own (PostgreSQL only: `None` for SQLite),
    /// bounded by `timeout` to connect.
    pub async fn listen_live(
        &self,
        timeout: Duration,
    ) -> Result<Option<LiveListener>, CatalogError> {
        let Pool::Postgres(p) = &self.pool else {
            return Ok(None);
        };
        let listen = async {
            let mut l = PgListener::connect_with(p).await?;
            l.listen(LIVE_CHANNEL).await?;
            Ok::<_, sqlx::Error>(l)
        };
        match tokio::time::timeout(timeout, listen).await {
            Ok(Ok(inner)) => Ok(Some(LiveListener {
                inner,
                url: self.url.clone(),
            })),
            Ok(Err(e)) => Err(self.err(&e)),
            Err(_) => Err(CatalogError::Unreachable {
                url: self.url.redacted(),
                message: format!("no answer to LISTEN within {timeout:?}"),
            }),
        }
    }
}
