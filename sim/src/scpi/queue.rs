//! The SCPI status a simulated meter keeps: its error queue (20 entries; -350 "Queue overflow"
//! replaces the last when it is full; `SYST:ERR?` answers the oldest, or `+0,"No error"`) and
//! the Standard Event register (only the Power On bit is modelled: `*ESR?` reads and clears
//! it, as does `*CLS`).

use std::collections::VecDeque;

/// Entries the error queue holds (both the 34401A and the Truevolts).
pub const ERROR_QUEUE_SIZE: usize = 20;

/// The Standard Event register's Power On bit.
pub const ESR_PON: u8 = 128;

/// A SCPI error queue.
#[derive(Debug, Clone, Default)]
pub(crate) struct ErrorQueue {
    entries: VecDeque<(i32, String)>,
}

impl ErrorQueue {
    /// Queues an entry; when the queue is full, the last entry becomes -350 "Queue overflow".
    pub(crate) fn raise(&mut self, code: i32, message: &str) {
        if self.entries.len() < ERROR_QUEUE_SIZE {
            self.entries.push_back((code, message.to_string()));
        } else if let Some(last) = self.entries.back_mut() {
            *last = (-350, "Queue overflow".to_string());
        }
    }

    /// The reply to `SYST:ERR?`: the oldest entry, taken off the queue (`-113,"Undefined
    /// header"`), or `+0,"No error"`.
    pub(crate) fn next_reply(&mut self) -> String {
        let (code, message) = self
            .entries
            .pop_front()
            .unwrap_or((0, "No error".to_string()));
        format!("{code:+},\"{message}\"")
    }

    /// Empties the queue (`*CLS`, power-on).
    pub(crate) fn clear(&mut self) {
        self.entries.clear();
    }

    /// The entries, oldest first (for [`crate::dmm::DmmStats::error_queue`]).
    pub(crate) fn snapshot(&self) -> Vec<(i32, String)> {
        self.entries.iter().cloned().collect()
    }
}

/// The Standard Event register, Power On bit only.
#[derive(Debug, Clone, Copy)]
pub(crate) struct EventStatus(u8);

impl EventStatus {
    /// As after power-on: the Power On bit set.
    pub(crate) fn powered_on() -> Self {
        EventStatus(ESR_PON)
    }

    /// Clears the register (`*CLS`).
    pub(crate) fn clear(&mut self) {
        self.0 = 0;
    }

    /// The reply to `*ESR?` (`+128`, `+0`); reading clears the register.
    pub(crate) fn read(&mut self) -> String {
        let v = std::mem::take(&mut self.0);
        format!("{v:+}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_queue_answers_oldest_first_then_no_error() {
        let mut q = ErrorQueue::default();
        q.raise(-113, "Undefined header");
        q.raise(-222, "Data out of range");
        assert_eq!(q.next_reply(), "-113,\"Undefined header\"");
        assert_eq!(q.next_reply(), "-222,\"Data out of range\"");
        assert_eq!(q.next_reply(), "+0,\"No error\"");
        q.raise(550, "Command not allowed in local");
        assert_eq!(q.next_reply(), "+550,\"Command not allowed in local\"");
    }

    #[test]
    fn a_full_queue_ends_in_queue_overflow() {
        let mut q = ErrorQueue::default();
        for _ in 0..ERROR_QUEUE_SIZE + 5 {
            q.raise(-222, "Data out of range");
        }
        let entries = q.snapshot();
        assert_eq!(entries.len(), ERROR_QUEUE_SIZE);
        assert_eq!(entries[ERROR_QUEUE_SIZE - 2].0, -222);
        assert_eq!(
            entries[ERROR_QUEUE_SIZE - 1],
            (-350, "Queue overflow".into())
        );
        q.clear();
        assert_eq!(q.next_reply(), "+0,\"No error\"");
    }

    #[test]
    fn the_power_on_bit_is_read_once() {
        let mut esr = EventStatus::powered_on();
        assert_eq!(esr.read(), "+128");
        assert_eq!(esr.read(), "+0");
        let mut esr = EventStatus::powered_on();
        esr.clear();
        assert_eq!(esr.read(), "+0");
    }
}
