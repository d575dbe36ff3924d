//! The rate table of a plan that has none: a drift record on a bench without a table
//! (`[drift] table = "none"`).
//!
//! The sequencer still owns a [`RateTable`], so the run's code has one shape; this one turns
//! nothing and says so. It identifies as "no rate table", accepts a demand of 0 °/s (the drift
//! record's only rate) and refuses any other, and runs an acquisition without sampling a rate
//! (the step's table statistics are empty: a rate that was never measured is never reported as
//! rest). Its stops succeed at once: nothing turns. Everything that would read a table (rate,
//! position, status, the wait for rest) is refused, so a run that asked it by mistake fails
//! loudly instead of reporting a table that is not there; the sequencer does not ask it.

use std::future::Future;
use std::pin::Pin;
use std::sync::Arc;
use std::time::Duration;

use crate::{
    Capabilities, Identity, RateStats, RateTable, RestReport, SettleCriteria, SettleReport,
    StopHandle, StopKind, StopPath, TableError, TableState, TableStatus,
};

/// How a table that is not there describes itself.
pub const NO_TABLE: &str = "no rate table";

/// A bench without a rate table (see the module docs).
#[derive(Debug, Clone)]
pub struct NoTable {
    handle: StopHandle,
}

impl Default for NoTable {
    fn default() -> Self {
        NoTable::new()
    }
}

impl NoTable {
    /// The table of a plan that has none.
    pub fn new() -> Self {
        NoTable {
            handle: StopHandle::new(Arc::new(NoStop)),
        }
    }

    fn refuse(action: &str) -> TableError {
        TableError::State {
            device: NO_TABLE.into(),
            action: format!("{action} (the plan has no rate table)"),
            state: TableState::Connected,
        }
    }
}

struct NoStop;

impl StopPath for NoStop {
    fn describe(&self) -> &str {
        NO_TABLE
    }

    fn send_stop(
        &self,
        _kind: StopKind,
    ) -> Pin<Box<dyn Future<Output = Result<(), TableError>> + Send + '_>> {
        // nothing turns
        Box::pin(async { Ok(()) })
    }
}

impl RateTable for NoTable {
    fn describe(&self) -> &str {
        NO_TABLE
    }

    fn state(&self) -> TableState {
        TableState::Connected
    }

    fn capabilities(&self) -> Capabilities {
        Capabilities {
            dialect: "none",
            axes: 0,
            max_rate: 0.0,
            max_acceleration: 1.0,
            position_readback: false,
        }
    }

    async fn connect(&mut self) -> Result<Identity, TableError> {
        Ok(Identity {
            manufacturer: "none".into(),
            model: NO_TABLE.into(),
            serial: "-".into(),
            version: "-".into(),
        })
    }

    async fn enable(&mut self) -> Result<(), TableError> {
        Ok(())
    }

    async fn set_rate(&mut self, rate: f64, _acceleration: f64) -> Result<(), TableError> {
        if rate == 0.0 {
            Ok(())
        } else {
            Err(TableError::Limit {
                device: NO_TABLE.into(),
                what: format!("a rate of {rate} °/s: the plan has no rate table"),
            })
        }
    }

    async fn read_rate(&mut self) -> Result<f64, TableError> {
        Err(NoTable::refuse("read a rate"))
    }

    async fn read_position(&mut self) -> Result<f64, TableError> {
        Err(NoTable::refuse("read a position"))
    }

    async fn status(&mut self) -> Result<TableStatus, TableError> {
        Err(NoTable::refuse("read a status"))
    }

    async fn sample(&mut self) -> Result<f64, TableError> {
        Err(NoTable::refuse("sample a rate"))
    }

    async fn wait_at_rate(
        &mut self,
        _criteria: &SettleCriteria,
    ) -> Result<SettleReport, TableError> {
        Err(NoTable::refuse("wait for a rate"))
    }

    fn start_recording(&mut self) {}

    fn stop_recording(&mut self) -> RateStats {
        RateStats::from_samples(&[])
    }

    async fn record_while<F>(
        &mut self,
        _interval: Duration,
        acquisition: F,
    ) -> Result<(F::Output, RateStats), TableError>
    where
        F: Future + Send,
        F::Output: Send,
        Self: Sized,
    {
        Ok((acquisition.await, RateStats::from_samples(&[])))
    }

    async fn heartbeat(&mut self) -> Result<(), TableError> {
        Ok(())
    }

    async fn stop(&mut self) -> Result<(), TableError> {
        Ok(())
    }

    async fn emergency_stop(&mut self) -> Result<(), TableError> {
        Ok(())
    }

    async fn wait_stopped(&mut self, _timeout: Duration) -> Result<RestReport, TableError> {
        Err(NoTable::refuse("confirm rest"))
    }

    fn stop_handle(&self) -> StopHandle {
        self.handle.clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn it_turns_nothing_and_reads_nothing() {
        let mut t = NoTable::new();
        assert_eq!(t.connect().await.unwrap().model, NO_TABLE);
        t.set_rate(0.0, 10.0).await.unwrap();
        let e = t.set_rate(1.0, 10.0).await.unwrap_err();
        assert!(e.to_string().contains("no rate table"), "{e}");
        // an acquisition runs without a rate: empty statistics, never "at rest"
        let (out, stats) = t
            .record_while(Duration::from_millis(1), async { 7 })
            .await
            .unwrap();
        assert_eq!(out, 7);
        assert_eq!(stats.count, 0);
        // nothing to read, nothing to confirm; stops succeed at once
        assert!(t.read_rate().await.is_err());
        assert!(t.wait_stopped(Duration::from_secs(1)).await.is_err());
        t.stop_handle().emergency_stop().await.unwrap();
    }
}
