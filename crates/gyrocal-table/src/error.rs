//! Typed rate-table errors. Every variant names the table (`device`), and [`TableError::kind`]
//! maps it to a small [`TableErrorKind`] so a sequencer can decide what to do (retry, stop,
//! abort the run) without matching on a dialect's details.

use gyrocal_link::{ErrorKind as LinkErrorKind, LinkError};

use crate::TableState;

/// What went wrong with a rate table, independent of the dialect.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum TableErrorKind {
    /// A request outside the client-side limits; nothing was sent to the table.
    Limit,
    /// The table refused a command and said why in its error queue.
    Table,
    /// The table latched a fault, or a run-level check failed (never settled): the run must end.
    Fault,
    /// The table stopped answering within a deadline (a reply timeout or a missed heartbeat).
    Timeout,
    /// The link failed (disconnected, I/O error) or the table sent bytes that are not a reply.
    Link,
    /// The request is not allowed in the driver's current state (for example a rate demand
    /// before `enable`, or after a latched fault that was not reset).
    State,
}

/// An error from a rate-table driver.
#[derive(Debug, thiserror::Error)]
pub enum TableError {
    /// A client-side limit refused the request before anything was sent.
    #[error("{device}: refused before sending: {what}")]
    Limit {
        /// The table's link description.
        device: String,
        /// What was out of range, with the value and the limit.
        what: String,
    },
    /// The table's error queue held an error after a command.
    #[error("{device}: table error after `{command}`: {code},\"{text}\"")]
    Table {
        /// The table's link description.
        device: String,
        /// The command (or commands) after which the queue was read.
        command: String,
        /// The table's error code.
        code: i32,
        /// The table's own error text.
        text: String,
    },
    /// A latched table fault or a failed run-level check (settling timeout).
    #[error("{device}: fault: {reason}")]
    Fault {
        /// The table's link description.
        device: String,
        /// The table's own message when it gave one, else the driver's.
        reason: String,
    },
    /// No reply within the deadline.
    #[error("{device}: no answer to `{command}` within the deadline ({source})")]
    Timeout {
        /// The table's link description.
        device: String,
        /// The query that went unanswered.
        command: String,
        /// The link's timeout error.
        #[source]
        source: LinkError,
    },
    /// The link failed.
    #[error("{device}: link failed during `{command}`: {source}")]
    Link {
        /// The table's link description.
        device: String,
        /// The command or query in progress.
        command: String,
        /// The link error.
        #[source]
        source: LinkError,
    },
    /// The table answered something that is not a valid reply to the query.
    #[error("{device}: unexpected reply to `{command}`: {reason} (bytes: {bytes})")]
    Reply {
        /// The table's link description.
        device: String,
        /// The query.
        command: String,
        /// Why the reply was rejected.
        reason: String,
        /// The reply, escaped for display.
        bytes: String,
    },
    /// The request is not allowed in the current state.
    #[error("{device}: cannot {action} while {state}")]
    State {
        /// The table's link description.
        device: String,
        /// What was asked.
        action: String,
        /// The driver's state at the time.
        state: TableState,
    },
}

impl TableError {
    /// The dialect-independent kind of this error.
    pub fn kind(&self) -> TableErrorKind {
        match self {
            TableError::Limit { .. } => TableErrorKind::Limit,
            TableError::Table { .. } => TableErrorKind::Table,
            TableError::Fault { .. } => TableErrorKind::Fault,
            TableError::Timeout { .. } => TableErrorKind::Timeout,
            TableError::Link { .. } | TableError::Reply { .. } => TableErrorKind::Link,
            TableError::State { .. } => TableErrorKind::State,
        }
    }

    /// Wraps a link error, sorting timeouts from other link failures.
    pub fn from_link(device: &str, command: &str, source: LinkError) -> Self {
        let (device, command) = (device.to_string(), command.to_string());
        match source.kind() {
            LinkErrorKind::Timeout => TableError::Timeout {
                device,
                command,
                source,
            },
            _ => TableError::Link {
                device,
                command,
                source,
            },
        }
    }

    /// True for errors after which the table's motion is unknown or unsafe, so the run must
    /// stop the table and end: faults, timeouts and link failures.
    pub fn ends_run(&self) -> bool {
        matches!(
            self.kind(),
            TableErrorKind::Fault | TableErrorKind::Timeout | TableErrorKind::Link
        )
    }
}
