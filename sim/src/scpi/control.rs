//! Controlling a running simulated SCPI meter, whichever it is: the faults it takes
//! ([`Fault`], the grammar of `dmm:` fault specs), the control messages, the handle a test or
//! the bench holds ([`DmmHandle`], [`DmmInjector`]) and the counters it reads ([`DmmStats`]).
//! The 34401A and the Truevolt simulators are driven by the same messages, so fault specs and
//! counters work for every meter.

use std::sync::{Arc, Mutex};

use serde::{Deserialize, Serialize};
use tokio::sync::mpsc;
use tokio::task::JoinHandle;

/// A fault to inject.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "kind", deny_unknown_fields)]
pub enum Fault {
    /// The next reply (the output of the next line that produces any) is never sent.
    NoReply,
    /// The next reply has a character replaced by `#`.
    Garble,
    /// The next reply stops halfway, without its terminator (the rest of that line's output,
    /// readings included, is lost).
    Truncate,
    /// The meter drops the connection: the simulator closes its end and stops.
    Disconnect,
    /// The next `readings` readings are overloads.
    Overload {
        /// How many.
        readings: u32,
    },
    /// The meter is switched off and on again: dead (deaf and mute) for `off_s` sim seconds
    /// (`None`: [`crate::dmm::DmmConfig::power_off_s`]), then back in LOCAL with the power-on state (see
    /// [`crate::dmm`]; the Truevolt's in [`crate::truevolt`]). Armed at a reading, the meter dies instead of taking it.
    PowerCycle {
        /// Off time in sim seconds; default [`crate::dmm::DmmConfig::power_off_s`].
        #[serde(default)]
        off_s: Option<f64>,
    },
    /// Replies held back: every byte the meter sends from now on reaches the host `delay_s`
    /// sim seconds after it was sent, for the next `replies` replies (lines), or for good.
    /// The meter itself is alive and obeys at once. On the 34401A the held bytes are already
    /// on their way (a serial converter's deep buffer, a network bridge): a device clear does
    /// not recall them. On a Truevolt the reply is sent late on the connection its query came
    /// on, and a reconnect drops it (see [`crate::truevolt`]).
    Slow {
        /// How late each reply is, sim seconds.
        delay_s: f64,
        /// Replies held back; `None`: every reply from now on.
        #[serde(default)]
        replies: Option<u32>,
    },
    /// An entry pushed into the error queue.
    PushError {
        /// The code.
        code: i32,
        /// The message.
        message: String,
    },
}

/// Counters and state a test can read through [`DmmHandle::stats`].
#[derive(Debug, Clone, Default, PartialEq)]
pub struct DmmStats {
    /// Readings taken (to memory or to the output).
    pub readings_taken: u64,
    /// Commands (program message units) seen, refused ones included.
    pub commands_seen: u64,
    /// Lines seen.
    pub lines_seen: u64,
    /// Queries answered.
    pub queries_answered: u64,
    /// Device clears (Ctrl-C) received.
    pub device_clears: u64,
    /// Errors raised into the queue (also those lost to an overflow).
    pub errors_raised: u64,
    /// Largest number of characters waiting in the input at once (the real meter's input
    /// buffer holds about 100).
    pub max_input_backlog: usize,
    /// Whether the meter is in remote.
    pub remote: bool,
    /// Power cycles so far ([`Fault::PowerCycle`]).
    pub power_cycles: u64,
    /// Whether the meter is switched on (false during a power cycle's off time).
    pub powered: bool,
    /// The integration time now in force (`VOLT:DC:NPLC`), for tests that check a
    /// reconfiguration.
    pub nplc: f64,
    /// Readings in the internal memory now.
    pub memory_points: usize,
    /// The error queue now, oldest first.
    pub error_queue: Vec<(i32, String)>,
    /// True once the simulator has stopped (stop, disconnect, or the host closed the link).
    pub stopped: bool,
    /// Replies held back by a [`Fault::Slow`] (sent late).
    pub late_replies: u64,
}

/// What a handle tells a running simulated meter.
pub(crate) enum Ctl {
    Fault(Fault),
    AtReading(u64, Fault),
    Stop,
}

/// Controls a running simulated meter.
pub struct DmmHandle {
    ctl: mpsc::UnboundedSender<Ctl>,
    stats: Arc<Mutex<DmmStats>>,
    task: JoinHandle<()>,
}

impl DmmHandle {
    /// A handle on a simulated meter's task, driven through `ctl`, its counters in `stats`.
    pub(crate) fn from_parts(
        ctl: mpsc::UnboundedSender<Ctl>,
        stats: Arc<Mutex<DmmStats>>,
        task: JoinHandle<()>,
    ) -> Self {
        DmmHandle { ctl, stats, task }
    }

    /// Injects a fault now.
    pub fn inject(&self, fault: Fault) {
        let _ = self.ctl.send(Ctl::Fault(fault));
    }

    /// A snapshot of the counters.
    pub fn stats(&self) -> DmmStats {
        self.stats
            .lock()
            .map(|s| s.clone())
            .unwrap_or_else(|e| e.into_inner().clone())
    }

    /// Arms `fault` for the `n`-th reading the meter takes (counted from 1 since the start,
    /// like [`DmmStats::readings_taken`]); injected just before that reading is taken, so:
    ///
    /// - a reply fault (no reply, garble, truncate) hits the reply that carries reading `n`:
    ///   when readings stream (`READ?`) the reply it is part of, from that reading on (a garble
    ///   lands in reading `n`'s own characters); when they go to memory, the `FETC?` reply
    ///   (a garble lands in reading `n`'s characters there);
    /// - an overload makes reading `n` (and the following ones, as many as asked) overloads;
    /// - a disconnect drops the link instead of taking reading `n`.
    ///
    /// A reading number already passed fires at the next reading.
    pub fn inject_at_reading(&self, n: u64, fault: Fault) {
        let _ = self.ctl.send(Ctl::AtReading(n, fault));
    }

    /// Readings taken so far.
    pub fn readings_taken(&self) -> u64 {
        self.stats().readings_taken
    }

    /// Commands seen so far.
    pub fn commands_seen(&self) -> u64 {
        self.stats().commands_seen
    }

    /// A cloneable handle that injects faults and reads the counters (for other tasks).
    pub fn injector(&self) -> DmmInjector {
        DmmInjector {
            ctl: self.ctl.clone(),
            stats: self.stats.clone(),
        }
    }

    /// Whether the simulator task has ended.
    pub fn is_finished(&self) -> bool {
        self.task.is_finished()
    }

    /// Stops the simulator (its end of the stream is closed) and waits for it.
    pub async fn stop(self) {
        let _ = self.ctl.send(Ctl::Stop);
        let _ = self.task.await;
    }
}

/// A cloneable part of a [`DmmHandle`]: fault injection and counters, without the task.
#[derive(Clone)]
pub struct DmmInjector {
    ctl: mpsc::UnboundedSender<Ctl>,
    stats: Arc<Mutex<DmmStats>>,
}

impl std::fmt::Debug for DmmInjector {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DmmInjector").finish_non_exhaustive()
    }
}

impl DmmInjector {
    /// See [`DmmHandle::inject`].
    pub fn inject(&self, fault: Fault) {
        let _ = self.ctl.send(Ctl::Fault(fault));
    }

    /// See [`DmmHandle::inject_at_reading`].
    pub fn inject_at_reading(&self, n: u64, fault: Fault) {
        let _ = self.ctl.send(Ctl::AtReading(n, fault));
    }

    /// A snapshot of the counters.
    pub fn stats(&self) -> DmmStats {
        self.stats
            .lock()
            .map(|s| s.clone())
            .unwrap_or_else(|e| e.into_inner().clone())
    }

    /// Readings taken so far.
    pub fn readings_taken(&self) -> u64 {
        self.stats().readings_taken
    }
}

/// Faults armed for a reading number ([`DmmHandle::inject_at_reading`]), in the order they
/// were armed.
#[derive(Debug, Default)]
pub(crate) struct ArmedFaults(Vec<(u64, Fault)>);

impl ArmedFaults {
    /// Arms `fault` for reading `n`.
    pub(crate) fn arm(&mut self, n: u64, fault: Fault) {
        self.0.push((n, fault));
    }

    /// Disarms and returns the faults due at reading `number` (armed for it or for a reading
    /// already passed), in the order armed.
    pub(crate) fn due(&mut self, number: u64) -> Vec<Fault> {
        let mut due = Vec::new();
        self.0.retain(|(n, f)| {
            if *n <= number {
                due.push(f.clone());
                false
            } else {
                true
            }
        });
        due
    }

    /// Arms again, first and due at reading `number`, faults [`ArmedFaults::due`] returned
    /// that did not fire (the reading was not taken).
    pub(crate) fn put_back(&mut self, number: u64, faults: impl IntoIterator<Item = Fault>) {
        let rest: Vec<(u64, Fault)> = faults.into_iter().map(|f| (number, f)).collect();
        self.0.splice(0..0, rest);
    }

    /// Faults still armed.
    #[cfg(test)]
    pub(crate) fn len(&self) -> usize {
        self.0.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn armed_faults_fire_in_order_once_their_reading_comes() {
        let mut armed = ArmedFaults::default();
        armed.arm(5, Fault::Garble);
        armed.arm(3, Fault::NoReply);
        armed.arm(3, Fault::Truncate);
        assert!(armed.due(2).is_empty());
        assert_eq!(armed.due(4), vec![Fault::NoReply, Fault::Truncate]);
        armed.put_back(4, [Fault::Truncate]);
        assert_eq!(armed.due(4), vec![Fault::Truncate]);
        assert_eq!(armed.len(), 1);
        assert_eq!(armed.due(9), vec![Fault::Garble]);
        assert_eq!(armed.len(), 0);
    }
}
