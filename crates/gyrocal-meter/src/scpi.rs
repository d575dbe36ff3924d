//! SCPI basics every SCPI meter shares: an entry of the instrument's error queue, its parser,
//! and reading the queue until it is empty.
//!
//! Why here: the error queue (`SYST:ERR?` answered oldest first, until `+0,"No error"`) is
//! IEEE 488.2 / SCPI, not a model's; the 34401A and the Truevolt drivers each had a copy of the
//! entry type, the parser and the loop. The reading is written without I/O ([`ErrorQueue`]
//! says what to send and takes each reply), so this crate stays free of an async runtime and
//! each driver keeps its own exchange (its timeouts, its deadlines widened after late replies,
//! its error type naming the link).

use std::fmt;

/// The query that reads one entry of the error queue.
pub const ERROR_QUERY: &str = "SYST:ERR?";

/// The most `SYST:ERR?` queries one reading of the queue sends: a SCPI meter's queue holds 20
/// entries (the last replaced by -350 "Queue overflow" when full), and a few more may arrive
/// while it is read. A meter that never says "No error" cannot keep the driver asking forever.
pub const ERROR_QUEUE_READS: usize = 24;

/// One entry of the meter's error queue (`SYST:ERR?`), such as `-222,"Data out of range"`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct InstrumentError {
    /// The SCPI or device-specific code (negative for standard SCPI errors; 0 for "No error").
    pub code: i32,
    /// The meter's message.
    pub message: String,
}

impl fmt::Display for InstrumentError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{},\"{}\"", self.code, self.message)
    }
}

/// Parses an error-queue entry such as `-222,"Data out of range"` or `+0,"No error"`: a
/// signed integer code, a comma, and the message (the enclosing double quotes removed). `None`
/// for anything else (the reply is untrusted: no code, a code beyond `i32`, no comma).
pub fn parse_error(reply: &str) -> Option<InstrumentError> {
    let (code, message) = reply.trim().split_once(',')?;
    let code: i32 = code.trim().trim_start_matches('+').parse().ok()?;
    let message = message.trim();
    let message = message
        .strip_prefix('"')
        .and_then(|m| m.strip_suffix('"'))
        .unwrap_or(message);
    Some(InstrumentError {
        code,
        message: message.to_string(),
    })
}

/// A reply to `SYST:ERR?` that is not an error-queue entry (the driver names the device and
/// the bytes in its own error).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NotAnEntry(pub String);

impl NotAnEntry {
    /// What the driver expected, for its message.
    pub const EXPECTED: &'static str = "an error-queue entry";
}

/// Reading the error queue, oldest entry first, until `+0,"No error"`, at most
/// [`ERROR_QUEUE_READS`] queries, without I/O: the driver sends [`ErrorQueue::next_query`]
/// while it gives one, and hands each reply to [`ErrorQueue::accept`].
///
/// ```
/// use gyrocal_meter::scpi::ErrorQueue;
/// let mut queue = ErrorQueue::new();
/// let mut replies = ["-113,\"Undefined header\"", "+0,\"No error\""].into_iter();
/// while let Some(query) = queue.next_query() {
///     assert_eq!(query, "SYST:ERR?");
///     queue.accept(replies.next().unwrap()).unwrap();
/// }
/// let entries = queue.into_entries();
/// assert_eq!(entries.len(), 1);
/// assert_eq!(entries[0].code, -113);
/// ```
#[derive(Debug, Clone, Default)]
pub struct ErrorQueue {
    entries: Vec<InstrumentError>,
    asked: usize,
    empty: bool,
}

impl ErrorQueue {
    /// Nothing read yet.
    pub fn new() -> Self {
        ErrorQueue::default()
    }

    /// The query to send next, or `None` once the meter said "No error" (or the bound is
    /// reached).
    pub fn next_query(&mut self) -> Option<&'static str> {
        if self.empty || self.asked >= ERROR_QUEUE_READS {
            return None;
        }
        self.asked += 1;
        Some(ERROR_QUERY)
    }

    /// Takes the reply to the last query: an entry is kept, code 0 ends the reading.
    pub fn accept(&mut self, reply: &str) -> Result<(), NotAnEntry> {
        let entry = parse_error(reply).ok_or_else(|| NotAnEntry(reply.to_string()))?;
        if entry.code == 0 {
            self.empty = true;
        } else {
            self.entries.push(entry);
        }
        Ok(())
    }

    /// The entries read, oldest first.
    pub fn into_entries(self) -> Vec<InstrumentError> {
        self.entries
    }
}

/// `-113,"Undefined header"; -222,"Data out of range"`: entries as a driver's message lists
/// them.
pub fn list(errors: &[InstrumentError]) -> String {
    errors
        .iter()
        .map(ToString::to_string)
        .collect::<Vec<_>>()
        .join("; ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn error_queue_entries() {
        assert_eq!(
            parse_error("-113,\"Undefined header\""),
            Some(InstrumentError {
                code: -113,
                message: "Undefined header".into()
            })
        );
        assert_eq!(parse_error("+0,\"No error\"").map(|e| e.code), Some(0));
        assert_eq!(
            parse_error("  -222,\"Data out of range\"\r").map(|e| e.code),
            Some(-222)
        );
        assert_eq!(parse_error("garbage"), None);
        assert_eq!(parse_error("99999999999,\"too big\""), None);
    }

    #[test]
    fn an_entry_prints_as_the_meter_sent_it() {
        let e = parse_error("-350,\"Queue overflow\"");
        assert_eq!(
            e.map(|e| e.to_string()).as_deref(),
            Some("-350,\"Queue overflow\"")
        );
    }

    #[test]
    fn the_queue_is_read_until_no_error() {
        let mut q = ErrorQueue::new();
        let mut sent = 0;
        let replies = [
            "-113,\"Undefined header\"",
            "-222,\"Data out of range\"",
            "+0,\"No error\"",
        ];
        while let Some(query) = q.next_query() {
            assert_eq!(query, "SYST:ERR?");
            assert!(q.accept(replies[sent]).is_ok());
            sent += 1;
        }
        assert_eq!(sent, 3);
        let entries = q.into_entries();
        assert_eq!(
            list(&entries),
            "-113,\"Undefined header\"; -222,\"Data out of range\""
        );
    }

    #[test]
    fn a_meter_that_never_says_no_error_is_asked_a_bounded_number_of_times() {
        let mut q = ErrorQueue::new();
        let mut sent = 0;
        while q.next_query().is_some() {
            assert!(q.accept("-350,\"Queue overflow\"").is_ok());
            sent += 1;
        }
        assert_eq!(sent, ERROR_QUEUE_READS);
        assert_eq!(q.into_entries().len(), ERROR_QUEUE_READS);
    }

    #[test]
    fn a_garbled_entry_is_refused_with_its_text() {
        let mut q = ErrorQueue::new();
        assert!(q.next_query().is_some());
        assert_eq!(
            q.accept("#0,\"No error\""),
            Err(NotAnEntry("#0,\"No error\"".into()))
        );
    }
}
