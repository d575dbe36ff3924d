//! The calibration catalog: an index of gyrocal's run directories in a database, for listing
//! runs and following a gyro's calibrations over time.
//!
//! The run directories stay the source of truth; the catalog is rebuilt from them at any time
//! (`gyrocal catalog rebuild ROOT`). Two backends, one interface ([`Catalog`]):
//!
//! - **SQLite** (the default): a file in the user's data directory
//!   (`$XDG_DATA_HOME/gyrocal/catalog.sqlite`), in WAL mode with a busy timeout, so several
//!   gyrocal processes on one machine read and write it at once.
//! - **PostgreSQL**: a lab's shared catalog, `postgres://user@host/db`. The password comes
//!   from `PGPASSWORD` or `~/.pgpass` (libpq's conventions), and is never written to the
//!   catalog, a log or a message ([`CatalogUrl`] redacts it).
//!
//! Which one: [`Catalog::resolve`] (`--catalog URL`, then `GYROCAL_CATALOG`, then the
//! station file's `catalog` key, then the default file).
//!
//! Listing ([`Catalog::open_existing`], for `gyrocal runs` and `gyrocal history`) creates
//! nothing, and never reads a damaged SQLite file as a shorter history: SQLite reads a garbled
//! row as well as it can, and a filtering query can skip it without an error, so the tables a
//! listing reads are first checked against their indexes (`PRAGMA integrity_check(TABLE)`),
//! every row of a gyro is decoded, and any error is checked with `PRAGMA quick_check`; a
//! damaged file is [`CatalogError::Damaged`], whose message names the file and the repair. The
//! repair, `gyrocal catalog rebuild`, finds the damage ([`sqlite_damage`]), moves the file
//! aside ([`set_aside`], kept as `catalog.sqlite.damaged-<UTC time>`) and rebuilds from the run
//! directories. A PostgreSQL server that refuses the connection is said at once with its host
//! and port (one direct connection before the pool, whose own retries would only say "pool
//! timed out" after the connect timeout).
//!
//! The schema (versioned migrations, one folder for both backends, compiled in) is documented in
//! `SCHEMA.md`, included below. A running calibration updates the catalog through
//! [`CatalogWriter`], which never blocks or fails the run.
//!
//! Why sqlx: async like the rest of gyrocal; queries checked at run time (no database
//! needed to build) with bound parameters; one migration system for both backends; SQLite
//! compiled in (no system library).
#![doc = include_str!("../SCHEMA.md")]

#[cfg(feature = "db")]
mod bus;
#[cfg(feature = "db")]
mod db;
mod error;
#[cfg(feature = "db")]
mod health;
mod history;
mod live;
#[cfg(feature = "db")]
mod pg_probe;
mod record;
mod rows;
mod series;
#[cfg(feature = "db")]
mod url;
#[cfg(feature = "db")]
mod writer;

#[cfg(feature = "db")]
pub use bus::{LiveBus, LiveBusOptions, LiveBusStats};
#[cfg(feature = "db")]
pub use db::live::{LiveListener, LiveNews, MAX_LIVE_ROWS};
#[cfg(feature = "db")]
pub use db::{Catalog, OpenOptions, RunFilter};
pub use error::{CatalogError, ErrorKind};
#[cfg(feature = "db")]
pub use health::{set_aside, sqlite_damage};
pub use history::{
    Band, History, Limits, MIN_BAND_POINTS, PlanGroup, PlanKey, QUANTITIES, Quantity,
    Repeatability, Trend, TrendPoint, describe_plan, plan_key,
};
pub use live::{LIVE_CHANNEL, LIVE_KEEP_ENDED, LIVE_KEEP_SILENT, LiveRow, MAX_STATE_JSON};
pub use record::{
    CheckRow, InstrumentRow, KIND_SCALE_FACTOR, Results, RunRecord, RunRow, StepRow, find_run_dirs,
    host_name, is_run_dir, read_run,
};
pub use rows::{Calibration, RunSummary};
pub use series::{CATALOG_MEMBER, SERIES_JSON, SeriesPointRecord, SeriesRecord, read_series};
#[cfg(feature = "db")]
pub use url::{CATALOG_ENV, CatalogUrl, redact, resolve};
#[cfg(feature = "db")]
pub use writer::{CatalogWriter, WriterOptions, WriterStats};

#[cfg(feature = "db")]
impl Catalog {
    /// The history of the gyro `serial`: its complete calibrations (simulated ones only when
    /// `include_simulated`), repeatability, trends and control bands.
    pub async fn history(
        &self,
        serial: &str,
        include_simulated: bool,
    ) -> Result<History, CatalogError> {
        let calibrations = self.calibrations(serial, include_simulated).await?;
        Ok(History::of(serial, include_simulated, calibrations))
    }
}
