//! The meter's retry loops are bounded as a whole, in virtual time against the simulated
//! bench: a meter that loses a step's readings at every attempt (what a 34461A whose replies
//! come too late for its recovery did: every reconfiguration cleared its memory, and steps 3
//! and 4 were measured in turn until Ctrl-C) ends the run after
//! `SequencerOptions::lost_retries` re-measurements of that step, with the meter's own words
//! for what cleared its memory, and the table at rest.

#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)] // test helpers

mod common;

use std::sync::Arc;
use std::sync::atomic::{AtomicU32, Ordering};

use common::{config, plans, table_config};
use gyrocal_acl::AclTable;
use gyrocal_files::{Plan, RunDir, RunMeta, Status};
use gyrocal_hp34401a::Error as DmmError;
use gyrocal_meter::{Acquired, DcVolts, Identity, Measured, Multimeter, ProgressFn, TimingModel};
use gyrocal_run::{Sequencer, SequencerOptions, StopRequest, TableRest};
use gyrocal_sim::bench::Bench;
use gyrocal_sim::from_plan::bench_config;
use gyrocal_sim::table::SimMode;
use tokio::sync::watch;

/// quick.toml in memory mode (every step but the last leaves its readings in the meter, to
/// be fetched during the next ramp).
fn memory_plan() -> Plan {
    let text = plans::config_with(
        "quick.toml",
        &[("acquisition = \"auto\"", "acquisition = \"memory\"")],
    );
    assert!(text.contains("acquisition = \"memory\""));
    Plan::from_toml_str(&text, &config("quick.toml")).unwrap()
}

/// What a meter whose recovery reconfigures it at every transfer says: the readings left in
/// its memory are gone, and gyrocal's own reconfiguration cleared them.
const CAUSE: &str = "gyrocal configured the meter again after it did not answer, which clears \
                     its memory; no power cycle was seen: its replies may be too late or lost";

/// The real 34401A driver, whose every deferred transfer finds the memory cleared.
struct LosesEveryTransfer<M> {
    inner: M,
    collects: Arc<AtomicU32>,
}

impl<M: Multimeter<Error = DmmError>> Multimeter for LosesEveryTransfer<M> {
    type Error = DmmError;
    type Pending = M::Pending;

    fn describe(&self) -> &str {
        self.inner.describe()
    }
    async fn connect(&mut self) -> Result<Identity, DmmError> {
        self.inner.connect().await
    }
    async fn configure(&mut self, settings: &DcVolts) -> Result<(), DmmError> {
        self.inner.configure(settings).await
    }
    fn timing(&self) -> Option<Box<dyn TimingModel>> {
        self.inner.timing()
    }
    async fn measure(
        &mut self,
        n: usize,
        may_defer: bool,
    ) -> Result<Measured<M::Pending>, DmmError> {
        self.inner.measure(n, may_defer).await
    }
    async fn collect(&mut self, pending: M::Pending) -> Result<Acquired, DmmError> {
        drop(pending);
        self.collects.fetch_add(1, Ordering::SeqCst);
        Err(DmmError::ReadingsLost {
            device: self.inner.describe().to_string(),
            count: 50,
            cause: CAUSE.into(),
        })
    }
    async fn recover(&mut self) -> Result<String, DmmError> {
        self.inner.recover().await
    }
    async fn release(&mut self) -> Result<(), DmmError> {
        self.inner.release().await
    }
    fn set_progress(&mut self, progress: Option<ProgressFn>) {
        self.inner.set_progress(progress);
    }
}

#[tokio::test(start_paused = true)]
async fn a_meter_that_loses_every_steps_readings_ends_the_run_after_the_documented_attempts() {
    let plan = memory_plan();
    let tmp = tempfile::tempdir().unwrap();
    let bench = Bench::spawn(bench_config(&plan));
    let collects = Arc::new(AtomicU32::new(0));
    let dmm = LosesEveryTransfer {
        inner: common::hp34401a(bench.dmm, &plan),
        collects: collects.clone(),
    };
    let table = AclTable::new(bench.table, table_config(&plan));
    let meta = RunMeta {
        gyrocal_version: "test".into(),
        simulated: true,
        ..RunMeta::default()
    };
    let run = RunDir::create(tmp.path(), &plan, meta).unwrap();
    let options = SequencerOptions::default();
    assert_eq!(options.lost_retries, 2, "the documented default");
    let mut seq = Sequencer::new(plan.clone(), dmm, table, run, options);
    let (_stop_tx, stop_rx) = watch::channel(StopRequest::None);
    // it ends (before the bound, the sequencer measured steps 1 and 2 in turn for ever)
    let summary = tokio::time::timeout(std::time::Duration::from_secs(3600), seq.run(stop_rx))
        .await
        .expect("the run never ended");
    drop(seq);
    assert_eq!(summary.status, Status::Failed, "{summary:?}");
    let reason = summary.reason.clone().unwrap();
    assert!(
        reason.contains("step 1 at 0 °/s not recorded")
            && reason.contains("lost its readings at all 3 attempts, the most allowed"),
        "{reason}"
    );
    // the real cause, not a power cycle
    assert!(reason.contains(CAUSE), "{reason}");
    assert!(!reason.contains("power cycle?"), "{reason}");
    // step 1's three transfers and those of the step measured in between, no more
    let n = collects.load(Ordering::SeqCst);
    assert!((3..=6).contains(&n), "{n} transfers");
    // nothing of the lost steps was recorded
    assert_eq!(summary.steps_recorded, 0, "{summary:?}");
    // the table ends at rest
    assert!(
        matches!(summary.table, TableRest::AtRest { .. }),
        "{:?}",
        summary.table
    );
    let t = &bench.handle.table;
    assert_eq!(t.mode(), SimMode::Off);
    let now = tokio::time::Instant::now();
    assert!(t.is_stopped());
    assert!(t.actual_rate(now).abs() < 0.01, "{}", t.actual_rate(now));
}
