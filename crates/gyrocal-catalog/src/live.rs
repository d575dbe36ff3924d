//! The live state of a run going on, as the catalog holds it (`live_runs`, schema version 4):
//! what `gyrocal run` publishes when its catalog is PostgreSQL, and what `gyrocal serve`
//! shows beside the runs under its own roots. See [`crate::LiveBus`] for the publishing side
//! and `Catalog::listen_live` for the listening one.
//!
//! Why the catalog: a lab's benches already share its PostgreSQL server, and `LISTEN`/`NOTIFY`
//! tells every listener "run X changed" without a service of its own. The row is a copy of the
//! run's `live.json` (the run directory stays the truth), its JSON capped at
//! [`MAX_STATE_JSON`].

use serde::{Deserialize, Serialize};

/// The channel of the notifications (`NOTIFY gyrocal_live, 'RUN_ID'`).
pub const LIVE_CHANNEL: &str = "gyrocal_live";

/// The most bytes of a live state's JSON kept in a row (a state with more step summaries is
/// trimmed by the publisher, oldest steps first).
pub const MAX_STATE_JSON: usize = 64 * 1024;

/// How long the row of an ended run (`complete`, `aborted`, `failed`) stays in `live_runs`
/// after its last update (see `Catalog::prune_live`): 30 days, long past the dashboard's
/// "finished today"; the run directory and the `runs` table keep the results.
pub const LIVE_KEEP_ENDED: std::time::Duration = std::time::Duration::from_secs(30 * 86_400);

/// How long a `running` row that is no longer updated stays in `live_runs` (see
/// `Catalog::prune_live`): 7 days. A run updates its row at every step; one silent for a
/// week was killed or lost its host, and the view has shown it stale all that time.
pub const LIVE_KEEP_SILENT: std::time::Duration = std::time::Duration::from_secs(7 * 86_400);

/// The RFC 3339 UTC text of `keep` before `now` (the epoch when that is earlier): rows last
/// updated before it are older than `keep`.
pub(crate) fn cutoff(now: std::time::SystemTime, keep: std::time::Duration) -> String {
    gyrocal_files::rfc3339_utc(now.checked_sub(keep).unwrap_or(std::time::UNIX_EPOCH))
}

/// One row of `live_runs`: a run going on (or just ended) on a host.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LiveRow {
    /// The run's id (its directory's name).
    pub run_id: String,
    /// The host the run runs on.
    pub host: String,
    /// The station's id.
    pub station_id: Option<String>,
    /// The gyro's serial.
    pub dut_serial: Option<String>,
    /// The plan's name.
    pub plan_name: String,
    /// The plan's kind.
    pub kind: String,
    /// The phase (`ramping`, `acquiring`, `soaking`, `done`, ...).
    pub phase: String,
    /// The step under way (1-based).
    pub step: i64,
    /// Steps in the plan.
    pub steps: i64,
    /// Steps recorded.
    pub steps_done: i64,
    /// Estimated time to the end, s.
    pub eta_s: Option<f64>,
    /// The last reading, V.
    pub last_reading_v: Option<f64>,
    /// The running mean, V.
    pub running_mean_v: Option<f64>,
    /// The table's state.
    pub table_state: Option<String>,
    /// `running`, `complete`, `aborted`, `failed`.
    pub status: String,
    /// The verdict, once the analysis knows it.
    pub verdict: Option<String>,
    /// When the run wrote this state, RFC 3339 UTC.
    pub updated_utc: String,
    /// The live state itself (`live.json`'s text), at most [`MAX_STATE_JSON`] bytes.
    pub state_json: String,
}

impl LiveRow {
    /// Whether the prune of `live_runs` as of `now` deletes this row (an ended run's after
    /// [`LIVE_KEEP_ENDED`], a silent `running` one's after [`LIVE_KEEP_SILENT`]): the same
    /// rule as `Catalog::prune_live`, for the rows a view keeps in memory.
    pub fn prunable(&self, now: std::time::SystemTime) -> bool {
        let keep = if self.status == "running" {
            LIVE_KEEP_SILENT
        } else {
            LIVE_KEEP_ENDED
        };
        self.updated_utc < cutoff(now, keep)
    }
}
