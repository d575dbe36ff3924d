//! Helpers shared by gyrocal-report' tests (`mod common;`): the plans written once for every
//! crate's tests (`tests/support/plans.rs`, see there).

#![allow(dead_code)] // each test file uses a subset

#[path = "../../../../tests/support/plans.rs"]
pub mod plans;
