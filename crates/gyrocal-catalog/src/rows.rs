//! What the catalog's queries return, as plain data: built without the database driver, so a
//! renderer (the report crate's history page) takes them without an async runtime.

use crate::record::{CheckRow, Results, RunRow};

/// One line of `Catalog::runs`: the run and its headline results.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct RunSummary {
    /// The run.
    #[serde(flatten)]
    pub run: RunRow,
    /// Its results, when fitted.
    pub results: Option<Results>,
}

/// One calibration of a gyro, for its history.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Calibration {
    /// The run.
    #[serde(flatten)]
    pub run: RunRow,
    /// Its results.
    pub results: Option<Results>,
    /// Its acceptance checks (with their limits).
    pub checks: Vec<CheckRow>,
    /// The distinct rates its steps demanded, °/s, ascending: with the run's kind, what the
    /// history compares to tell plans apart ([`crate::history::plan_key`]); empty when the
    /// catalog holds no step of the run.
    pub rates_dps: Vec<f64>,
    /// A temperature series' sensitivities and points (its `series.json`), when the run is
    /// one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub series: Option<crate::series::SeriesRecord>,
}
