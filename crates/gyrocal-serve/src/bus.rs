//! The listening side of the live view's message bus: with a PostgreSQL catalog the server
//! `LISTEN`s on `gyrocal_live` and keeps the rows of `live_runs` (the runs of every bench that
//! publishes there, see `gyrocal_catalog::LiveBus`) in memory, for the dashboard and the run
//! pages to show beside the roots' runs.
//!
//! Each notification names a run: its rows are read again and one `run` event goes to the
//! event streams. When the connection is lost, notifications sent meanwhile are gone: once it
//! is made again every row is read again and an `{"all":true}` event tells the pages to
//! reload. A catalog that cannot be reached is said once in the log and tried again every
//! [`RELISTEN`]; the pages meanwhile show the last rows known (marked stale once old, as a
//! local run whose writer stopped).
//!
//! The server also keeps `live_runs` from growing without bound ([`prune`]): at its start and
//! every [`PRUNE_EVERY`] it deletes the rows of runs ended 30 days ago and of `running` ones
//! silent for 7 days (`Catalog::prune_live`), and forgets them in memory too.

use std::collections::HashMap;
use std::sync::RwLock;
use std::time::Duration;

use gyrocal_catalog::{Catalog, LiveNews, LiveRow};
use tokio::sync::broadcast;

/// How long a `LISTEN` may take to be set up, and the wait before trying again after a
/// failure.
pub const RELISTEN: Duration = Duration::from_secs(2);

/// How often the server prunes `live_runs` (and once at its start).
pub const PRUNE_EVERY: Duration = Duration::from_secs(3600);

/// The longest run id a notification may name (a directory's name).
const MAX_ID: usize = 255;

/// The runs known through the catalog, by host and run id.
#[derive(Debug, Default)]
pub struct LiveRuns {
    rows: RwLock<HashMap<(String, String), LiveRow>>,
}

impl LiveRuns {
    fn read(&self) -> std::sync::RwLockReadGuard<'_, HashMap<(String, String), LiveRow>> {
        self.rows.read().unwrap_or_else(|e| e.into_inner())
    }

    fn write(&self) -> std::sync::RwLockWriteGuard<'_, HashMap<(String, String), LiveRow>> {
        self.rows.write().unwrap_or_else(|e| e.into_inner())
    }

    /// Every row, newest update first, except those the prune would delete now
    /// ([`LiveRow::prunable`]): a reload that read the table just before a prune (the two run
    /// side by side, at the start) must not bring back the rows it deleted for an hour.
    pub fn rows(&self) -> Vec<LiveRow> {
        let now = std::time::SystemTime::now();
        let mut out: Vec<LiveRow> = self
            .read()
            .values()
            .filter(|r| !r.prunable(now))
            .cloned()
            .collect();
        out.sort_by(|a, b| b.updated_utc.cmp(&a.updated_utc));
        out
    }

    /// The row of run `run_id` on `host`, unless the prune would delete it now (as [`Self::rows`]).
    pub fn get(&self, host: &str, run_id: &str) -> Option<LiveRow> {
        self.read()
            .get(&(host.to_string(), run_id.to_string()))
            .filter(|r| !r.prunable(std::time::SystemTime::now()))
            .cloned()
    }

    /// Every row, replaced by `rows`.
    pub fn replace_all(&self, rows: Vec<LiveRow>) {
        let mut map = self.write();
        map.clear();
        for r in rows {
            map.insert((r.host.clone(), r.run_id.clone()), r);
        }
    }

    /// The rows of run `run_id`, replaced by `rows`.
    pub fn update(&self, run_id: &str, rows: Vec<LiveRow>) {
        let mut map = self.write();
        map.retain(|(_, id), _| id != run_id);
        for r in rows {
            map.insert((r.host.clone(), r.run_id.clone()), r);
        }
    }

    /// Forgets the rows the prune as of `now` deletes ([`LiveRow::prunable`]); how many.
    pub fn forget_prunable(&self, now: std::time::SystemTime) -> usize {
        let mut map = self.write();
        let before = map.len();
        map.retain(|_, r| !r.prunable(now));
        before - map.len()
    }
}

fn event_of(row: &LiveRow) -> String {
    let key = crate::runs::RunKey {
        root: 0,
        name: row.run_id.clone(),
        host: Some(row.host.clone()),
    };
    serde_json::json!({ "name": row.run_id, "host": row.host, "href": key.href() }).to_string()
}

/// Reads every row again; false when the catalog could not be read.
async fn reload(catalog: &Catalog, live: &LiveRuns, events: &broadcast::Sender<String>) -> bool {
    match catalog.live_runs(None).await {
        Ok(rows) => {
            live.replace_all(rows);
            let _ = events.send("{\"all\":true}".to_string());
            true
        }
        Err(e) => {
            tracing::warn!("the catalog's live runs cannot be read: {e}");
            false
        }
    }
}

/// Listens forever (see the module docs).
pub async fn listen(catalog: &Catalog, live: &LiveRuns, events: &broadcast::Sender<String>) {
    let mut warned = false;
    loop {
        match catalog
            .listen_live(RELISTEN.max(Duration::from_secs(5)))
            .await
        {
            Ok(Some(mut listener)) => {
                if warned {
                    tracing::warn!("listening to the catalog's live runs again");
                }
                warned = false;
                reload(catalog, live, events).await;
                loop {
                    match listener.recv().await {
                        Ok(LiveNews::Changed(id)) if !id.is_empty() && id.len() <= MAX_ID => {
                            match catalog.live_runs(Some(&id)).await {
                                Ok(rows) => {
                                    for r in &rows {
                                        let _ = events.send(event_of(r));
                                    }
                                    live.update(&id, rows);
                                }
                                Err(e) => tracing::warn!("the live run {id} cannot be read: {e}"),
                            }
                        }
                        Ok(LiveNews::Changed(_)) => {}
                        Ok(LiveNews::Reconnected) => {
                            reload(catalog, live, events).await;
                        }
                        Err(e) => {
                            if !std::mem::replace(&mut warned, true) {
                                tracing::warn!(
                                    "lost the catalog's notifications ({e}); the live runs of other benches are not updated until it answers"
                                );
                            }
                            break;
                        }
                    }
                }
            }
            Ok(None) => return,
            Err(e) => {
                if !std::mem::replace(&mut warned, true) {
                    tracing::warn!(
                        "cannot listen to the catalog ({e}); the live runs of other benches are not shown until it answers"
                    );
                }
            }
        }
        tokio::time::sleep(RELISTEN).await;
    }
}

/// Prunes `live_runs` now and every [`PRUNE_EVERY`], forever (see the module docs): the rows
/// deleted are forgotten in `live` too. A failure is said in the log and tried again at the
/// next hour.
pub async fn prune(catalog: &Catalog, live: &LiveRuns) {
    prune_every(catalog, live, PRUNE_EVERY).await;
}

/// [`prune`] every `every`.
async fn prune_every(catalog: &Catalog, live: &LiveRuns, every: Duration) {
    loop {
        let now = std::time::SystemTime::now();
        match catalog.prune_live(now).await {
            Ok(n) => {
                live.forget_prunable(now);
                if n > 0 {
                    tracing::info!("pruned {n} old rows of the catalog's live runs");
                }
            }
            Err(e) => tracing::warn!("the catalog's old live runs cannot be pruned: {e}"),
        }
        tokio::time::sleep(every).await;
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)] // a panic is a failed test

    use std::sync::Arc;
    use std::time::{Instant, SystemTime};

    use gyrocal_catalog::{CatalogUrl, LIVE_KEEP_ENDED, LIVE_KEEP_SILENT};

    use super::*;

    const DAY: Duration = Duration::from_secs(86_400);

    fn row(run_id: &str, status: &str, age: Duration) -> LiveRow {
        LiveRow {
            run_id: run_id.into(),
            host: "bench".into(),
            station_id: None,
            dut_serial: None,
            plan_name: "quick".into(),
            kind: "scale_factor".into(),
            phase: "acquiring".into(),
            step: 1,
            steps: 5,
            steps_done: 1,
            eta_s: None,
            last_reading_v: None,
            running_mean_v: None,
            table_state: None,
            status: status.into(),
            verdict: None,
            updated_utc: gyrocal_files::rfc3339_utc(SystemTime::now() - age),
            state_json: "{}".into(),
        }
    }

    #[test]
    fn the_view_forgets_the_rows_the_prune_deletes() {
        let live = LiveRuns::default();
        live.replace_all(vec![
            row("ended-31d", "complete", LIVE_KEEP_ENDED + DAY),
            row("ended-29d", "failed", LIVE_KEEP_ENDED - DAY),
            row("silent-8d", "running", LIVE_KEEP_SILENT + DAY),
            row("silent-6d", "running", LIVE_KEEP_SILENT - DAY),
        ]);
        assert_eq!(live.forget_prunable(SystemTime::now()), 2);
        assert_eq!(live.read().len(), 2, "still held in memory");
        let mut left: Vec<String> = live.rows().into_iter().map(|r| r.run_id).collect();
        left.sort();
        assert_eq!(left, ["ended-29d", "silent-6d"]);
    }

    #[test]
    fn rows_read_just_before_a_prune_are_never_shown() {
        // the start's reload and the start's prune run side by side: the reload may read the
        // old rows before the prune deletes them and store them after it forgot them
        let live = LiveRuns::default();
        live.replace_all(vec![
            row("ended-31d", "complete", LIVE_KEEP_ENDED + DAY),
            row("silent-8d", "running", LIVE_KEEP_SILENT + DAY),
            row("ended-1h", "complete", Duration::from_secs(3600)),
        ]);
        let shown: Vec<String> = live.rows().into_iter().map(|r| r.run_id).collect();
        assert_eq!(shown, ["ended-1h"]);
        assert!(live.get("bench", "ended-31d").is_none());
        assert!(live.get("bench", "silent-8d").is_none());
        assert!(live.get("bench", "ended-1h").is_some());
    }

    /// Waits (wall time, generous) until run `id` has no row in `catalog`.
    async fn gone(catalog: &Catalog, id: &str) -> bool {
        let t0 = Instant::now();
        while t0.elapsed() < Duration::from_secs(30) {
            if catalog.live_runs(Some(id)).await.unwrap().is_empty() {
                return true;
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        false
    }

    #[tokio::test]
    async fn the_prune_runs_at_the_start_and_again_at_each_period() {
        let dir = tempfile::tempdir().unwrap();
        let catalog = Catalog::open(&CatalogUrl::Sqlite(dir.path().join("c.sqlite")))
            .await
            .unwrap();
        let old = row("old-at-start", "complete", LIVE_KEEP_ENDED + DAY);
        catalog.publish_live(&old).await.unwrap();
        let live = Arc::new(LiveRuns::default());
        live.replace_all(vec![old.clone()]);
        let (c, l) = (catalog.clone(), live.clone());
        let task = tokio::spawn(async move {
            prune_every(&c, &l, Duration::from_millis(300)).await;
        });
        assert!(gone(&catalog, &old.run_id).await, "not pruned at the start");
        assert!(live.read().is_empty(), "kept in memory: {:?}", live.read());
        // a row that turns up old later goes at a later period
        let later = row("old-later", "running", LIVE_KEEP_SILENT + DAY);
        catalog.publish_live(&later).await.unwrap();
        assert!(gone(&catalog, &later.run_id).await, "not pruned again");
        task.abort();
    }
}
