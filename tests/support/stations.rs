//! The station file the CLI tests write (`--station`): bench 2 of an example lab, with a
//! calibrated multimeter and rate table due far in the future, so a report shows the full
//! traceability block and no test fails on the day the calibration would expire.
//!
//! Included, not a crate, like `plans.rs` (`#[path = "../../../../tests/support/stations.rs"]`
//! in `crates/gyrocal/tests/common`); it needs only `std`.

#![allow(dead_code)] // each test binary uses a subset

/// The room's conditions some tests record in the station file (top-level keys).
pub const CONDITIONS: &str = "ambient_c = 22.5\nhumidity_pct = 41\n";

/// The station file of `bench-2` with `conditions` (top-level keys such as
/// [`CONDITIONS`], `""` for none) after its address: an HP 34401A `DMM-0042` and an
/// ACUTRONIC AC1120S table `TBL-0007`, both due in 2099.
pub fn bench_2(conditions: &str) -> String {
    format!(
        r#"
id = "bench-2"
lab = "Inertial Lab, Example Institute"
address = "1 Test Road, Example City"
{conditions}
[multimeter]
model = "HP 34401A"
asset_id = "DMM-0042"
serial = "3146A12345"
certificate = "CAL-2026-0815"
calibrated = "2026-08-15"
due = "2099-08-15"
accuracy = "1y"

[table]
model = "ACUTRONIC AC1120S"
asset_id = "TBL-0007"
serial = "AC-1120-77"
certificate = "CAL-2026-0901"
calibrated = "2026-09-01"
due = "2099-09-01"
rate_accuracy_ppm = 10
"#
    )
}
