//! The guaranteed teardown: whatever way a run ends (every step recorded, an error, a stop
//! request, a failed consumer, a panic in the steps), the table is brought to rest and
//! waited for until it says so, the multimeter is returned to its front panel, the chamber
//! of a temperature series goes to its safe state (after the table: the table is the
//! dangerous one) and is read back, and the consumers (the run directory first) are told how
//! the run ended (OpenHTF's teardown phase group, which always runs). The operator is never
//! told "stopped" or "safe" unless the machine said so.

use gyrocal_table::RateTable;
use tokio::sync::watch;
use tokio::time::Instant;

use super::{
    ChamberRest, Engine, Event, RunSummary, SequenceError, SequenceErrorKind, StopRequest,
    TableRest,
};
use crate::bench::Bench;
use crate::sink::Finish;
use gyrocal_files::rundir::{Status, Timing as RunTiming};
use gyrocal_meter::Multimeter;

impl<B: Bench> Engine<B> {
    /// The teardown after every step was recorded.
    pub(super) async fn finish_ok(
        &mut self,
        timing: RunTiming,
        stop: &mut watch::Receiver<StopRequest>,
    ) -> RunSummary {
        // the steps sent the controlled stop; the run ends when the table says it is at rest
        let table = self.bring_to_rest(stop, false).await;
        self.release_meter(false).await;
        let chamber = self.chamber_safe_and_recorded().await;
        let elapsed_s = self.now_s();
        // The data are complete whatever the table does now; a table that did not confirm
        // rest is said in the manifest and by the caller, but does not void the calibration.
        let mut notes: Vec<String> = Vec::new();
        match &table {
            TableRest::AtRest { .. } | TableRest::NoTable => {}
            TableRest::NotConfirmed { reason } | TableRest::NeverReached { reason } => {
                notes.push(format!(
                    "all steps recorded, but the table could NOT be confirmed at rest: {reason}"
                ))
            }
        }
        if let ChamberRest::NotConfirmed { state, reason } = &chamber {
            notes.push(format!(
                "all steps recorded, but the chamber's safe state ({state}) could NOT be confirmed: {reason}"
            ));
        }
        let note = (!notes.is_empty()).then(|| notes.join("; "));
        let mut summary = RunSummary {
            status: Status::Complete,
            reason: note.clone(),
            steps_recorded: self.recorded,
            timing: Some(timing.clone()),
            elapsed_s,
            table,
            chamber,
            resumable: false,
            emergency_stop: self.emergency_sent,
        };
        let result = self.log_table_retries(None).and_then(|()| {
            Ok(self.sinks.finish(&Finish {
                status: Status::Complete,
                reason: note,
                elapsed_s,
                timing: Some(timing),
            })?)
        });
        if let Err(e) = result {
            tracing::error!(error = %e, "could not close the run directory");
            summary.status = Status::Failed;
            summary.reason = Some(e.to_string());
        }
        summary
    }

    /// The teardown after an error or a stop request.
    pub(super) async fn finish_err(
        &mut self,
        error: SequenceError,
        emergency: bool,
        stop: &mut watch::Receiver<StopRequest>,
    ) -> RunSummary {
        let status = match error {
            SequenceError::Stopped(_) => Status::Aborted,
            _ => Status::Failed,
        };
        let reason = error.to_string();
        // a changed plan (or bench) is another run
        let resumable = error.kind() != SequenceErrorKind::Plan;
        tracing::warn!(%reason, ?status, "run stopping");
        // Table first: it is the dangerous one. A table that faulted or stopped answering gets
        // the emergency path too (rate-table.md: "for a second interrupt or a fault"): a
        // controlled stop that was written may still not have been heard.
        let table_fault = matches!(&error, SequenceError::Table(e) if e.ends_run());
        let stopped = if emergency {
            self.stop_handle.emergency_stop().await
        } else {
            self.stop_handle.stop().await
        };
        if let Err(e) = &stopped {
            tracing::error!(error = %e, "stop command failed; trying the emergency stop");
        }
        let mut emergency_sent = emergency;
        if !emergency && (table_fault || stopped.is_err()) {
            tracing::warn!("table fault: emergency stop (interlock open)");
            emergency_sent = true;
            if let Err(e) = self.stop_handle.emergency_stop().await {
                tracing::error!(error = %e, "emergency stop failed: STOP THE TABLE BY HAND");
            }
        }
        self.emergency_sent |= emergency_sent;
        let table = self.bring_to_rest(stop, emergency_sent).await;
        self.release_meter(true).await;
        let chamber = self.chamber_safe_and_recorded().await;
        let elapsed_s = self.now_s();
        // the record says an emergency stop when one was sent, whatever the first request was
        let reason = if self.emergency_sent && !reason.contains("emergency stop") {
            format!("{reason}; then an emergency stop (interlock open)")
        } else {
            reason
        };
        if let Err(e) = self.log_table_retries(None).and_then(|()| {
            Ok(self.sinks.finish(&Finish {
                status,
                reason: Some(reason.clone()),
                elapsed_s,
                timing: None,
            })?)
        }) {
            tracing::error!(error = %e, "could not write the final manifest");
        }
        RunSummary {
            status,
            reason: Some(reason),
            steps_recorded: self.recorded,
            timing: None,
            elapsed_s,
            table,
            chamber,
            resumable,
            emergency_stop: self.emergency_sent,
        }
    }

    /// The chamber to its safe state ([`Engine::chamber_to_safety`]), said in the manifest;
    /// a manifest that cannot be written is logged (the ending says it anyway).
    async fn chamber_safe_and_recorded(&mut self) -> ChamberRest {
        let chamber = self.chamber_to_safety().await;
        let record = match &chamber {
            ChamberRest::NoChamber => None,
            ChamberRest::Confirmed { state, detail } => Some((state.clone(), true, detail.clone())),
            ChamberRest::NotConfirmed { state, reason } => {
                Some((state.clone(), false, reason.clone()))
            }
        };
        if let Some((state, confirmed, detail)) = record
            && let Err(e) = self.sinks.run.set_chamber_safe(&state, confirmed, &detail)
        {
            tracing::error!(error = %e, "could not record the chamber's state in the manifest");
        }
        chamber
    }

    /// An event during the teardown: a consumer that fails now cannot change the ending, so
    /// its error is logged.
    fn tell(&mut self, event: Event) {
        if let Err(e) = self.emit(event) {
            tracing::error!(error = %e, "a consumer failed during the teardown");
        }
    }

    /// After a stop was sent: waits until the table reports rest (|rate| within its stop
    /// tolerance, mode OFF), at most the time a stop from the measured rate at the plan's
    /// acceleration can take plus a margin. An emergency request arriving meanwhile sends the
    /// emergency stop at once (from a task of its own: the wait may hold the table's link).
    /// A run without a table ([`gyrocal_files::steps::Compiled::uses_table`]) has nothing to
    /// bring to rest. Says honestly what it found; never fails.
    pub(super) async fn bring_to_rest(
        &mut self,
        stop: &mut watch::Receiver<StopRequest>,
        emergency_sent: bool,
    ) -> TableRest {
        if !self.program.uses_table {
            tracing::info!("no rate table in this run: nothing to bring to rest");
            self.tell(Event::Rest(TableRest::NoTable));
            return TableRest::NoTable;
        }
        let limit = self.options.cleanup_timeout;
        let from = match tokio::time::timeout(limit, self.bench.table().read_rate()).await {
            Ok(Ok(r)) => Some(r),
            Ok(Err(e)) => {
                tracing::warn!(error = %e, "could not read the table's rate after the stop");
                None
            }
            Err(_) => None,
        };
        let worst = from.map_or(self.plan.table().max_rate_dps, f64::abs);
        let deadline = self.bench.table().stop_deadline(worst);
        self.tell(Event::Stopping {
            from_dps: from,
            emergency: emergency_sent,
            deadline,
        });
        tracing::info!(from_dps = ?from, ?deadline, "waiting for the table to come to rest");
        let started = Instant::now();
        let stop_handle = self.stop_handle.clone();
        let mut emergency_during = false;
        let mut watching = !emergency_sent;
        let result = {
            let mut wait = std::pin::pin!(self.bench.table().wait_stopped(deadline));
            loop {
                tokio::select! {
                    r = &mut wait => break r,
                    changed = stop.changed(), if watching => {
                        if changed.is_err() {
                            watching = false;
                        } else if matches!(*stop.borrow_and_update(), StopRequest::Emergency(_)) {
                            watching = false;
                            emergency_during = true;
                            tracing::warn!("emergency stop requested while the table decelerates");
                            let handle = stop_handle.clone();
                            tokio::spawn(async move {
                                if let Err(e) = handle.emergency_stop().await {
                                    tracing::error!(error = %e, "emergency stop failed: STOP THE TABLE BY HAND");
                                }
                            });
                        }
                    }
                }
            }
        };
        self.emergency_sent |= emergency_during;
        let rest = match result {
            Ok(report) => TableRest::AtRest {
                rate_dps: report.rate_dps,
                waited: started.elapsed(),
            },
            Err(e) if !self.table_reached && !self.moved => TableRest::NeverReached {
                reason: format!("the table did not answer ({e}); this session did not move it"),
            },
            Err(e) => TableRest::NotConfirmed {
                reason: e.to_string(),
            },
        };
        match &rest {
            TableRest::AtRest { .. } => tracing::info!("table at rest"),
            TableRest::NoTable => tracing::info!("no rate table: nothing turning"),
            TableRest::NotConfirmed { reason } | TableRest::NeverReached { reason } => {
                tracing::error!(%reason, "the table could NOT be confirmed at rest: stop it by hand")
            }
        }
        self.tell(Event::Rest(rest.clone()));
        rest
    }

    /// Recovery (after an interrupted exchange), then back to the front panel; bounded in
    /// time, errors logged (the run's outcome is already decided). Once only.
    pub(super) async fn release_meter(&mut self, after_error: bool) {
        if self.meter_released {
            return;
        }
        self.meter_released = true;
        let dmm = self.bench.meter();
        let limit = self.options.cleanup_timeout;
        if after_error {
            match tokio::time::timeout(limit, dmm.recover()).await {
                Ok(Ok(note)) => tracing::info!(%note, "multimeter recovered at the stop"),
                Ok(Err(e)) => tracing::warn!(error = %e, "multimeter clear failed"),
                Err(_) => tracing::warn!("multimeter clear timed out"),
            }
        }
        match tokio::time::timeout(limit, dmm.release()).await {
            Ok(Ok(())) => {}
            Ok(Err(e)) => tracing::warn!(error = %e, "multimeter did not go back to local"),
            Err(_) => tracing::warn!("multimeter did not go back to local in time"),
        }
    }
}
