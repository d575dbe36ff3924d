//! Asking an idempotent query again: the retry policy every dialect shares, written once.
//!
//! A lost, garbled or noisy reply to a query that changes nothing (`:Read:Rate?`, `PVE`,
//! `*STB?`, ...) is asked again, at most `1 + retries` times within the query's own deadline
//! (each attempt gets the time left divided by the attempts left, so a silent table still
//! fails within the heartbeat deadline). A dead link fails at once. Every retry is noted for
//! the run's manifest. A link that lost or mangled a reply and never gave a usable one is a
//! link failure (the policy faults the table); a table that answered every time with something
//! unusable is a reply error only.
//!
//! The reply of an attempt whose time ran out is still owed: the dialect keeps it in its
//! [`crate::latency::Pending`] ledger and gets back in step before its next exchange, so a late
//! reply is never read as another query's. A table seen to answer late gets longer deadlines
//! ([`crate::latency::ReplyLatency`]): the query's whole deadline is recomputed before every
//! attempt (a late reply seen during this very query counts), and each attempt gets at least
//! twice the slowest reply seen, within the dialect's bound.

use std::future::Future;
use std::sync::Mutex;
use std::time::Duration;

use gyrocal_link::{ErrorKind as LinkErrorKind, LinkError, show_bytes};
use tokio::time::Instant;

use crate::TableError;
use crate::dialect::DialectError;
use crate::latency::ReplyLatency;

/// The retry notes a dialect keeps for the run's manifest until
/// [`crate::RateTable::take_retries`] collects them.
#[derive(Debug, Default)]
pub struct RetryNotes(Mutex<Vec<String>>);

impl RetryNotes {
    /// Logs `note` and keeps it.
    pub fn push(&self, device: &str, note: String) {
        tracing::warn!(device = %device, "{note}");
        self.0
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .push(note);
    }

    /// The notes since the last call.
    pub fn take(&self) -> Vec<String> {
        std::mem::take(
            &mut *self
                .0
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner),
        )
    }
}

/// How one attempt went.
pub enum Attempt<R> {
    /// A usable value.
    Value(R),
    /// A reply line came back that the parser refused.
    Unusable {
        /// The reply.
        reply: String,
        /// Why it is refused.
        reason: &'static str,
    },
    /// The link failed (retried when [`retryable`]).
    Link(LinkError),
    /// A definite answer that asking again cannot change (a table error reply).
    Final(DialectError),
}

/// What the shared policy needs from a dialect.
pub trait Asking: Sync {
    /// The link's description.
    fn device(&self) -> &str;
    /// Retries after the first attempt.
    fn retries(&self) -> u32;
    /// Where the retry notes go.
    fn retry_notes(&self) -> &RetryNotes;
    /// The next exchange must clear stale input first.
    fn mark_dirty(&self) -> impl Future<Output = ()> + Send;
    /// The table's observed reply latency, which deadlines adapt to.
    fn latency(&self) -> &ReplyLatency;
    /// Something to add to a retry note of `line` (an error-queue entry that may be lost).
    fn retry_caveat(&self, line: &str) -> Option<&'static str> {
        let _ = line;
        None
    }
}

/// Asks `line` through `attempt` (one exchange and its parse, given the time it may take)
/// under the shared retry policy.
pub async fn ask<D, R, F, Fut>(
    dialect: &D,
    line: &str,
    timeout: Duration,
    mut attempt: F,
) -> Result<R, DialectError>
where
    D: Asking,
    F: FnMut(Duration) -> Fut,
    Fut: Future<Output = Attempt<R>>,
{
    let attempts = dialect.retries().saturating_add(1);
    let start = Instant::now();
    let mut deadline = start + dialect.latency().deadline(timeout);
    let mut first: Option<Miss> = None;
    let mut last = String::new();
    let mut link_missed = false;
    for n in 1..=attempts {
        // a late reply seen since (in this query's own attempts too) lengthens the deadline
        deadline = deadline.max(start + dialect.latency().deadline(timeout));
        let left_attempts = attempts - n + 1;
        let left = deadline.saturating_duration_since(Instant::now());
        let budget = (left / left_attempts)
            .max(dialect.latency().attempt_floor())
            .min(left);
        let miss = match attempt(budget).await {
            Attempt::Value(v) => return Ok(v),
            Attempt::Unusable { reply, reason } => Miss::Reply { reply, reason },
            Attempt::Link(e) if retryable(&e) => Miss::Link(e),
            Attempt::Link(e) => {
                return Err(DialectError::link(TableError::from_link(
                    dialect.device(),
                    line,
                    e,
                )));
            }
            Attempt::Final(e) => return Err(e),
        };
        last = miss.describe();
        link_missed |= matches!(miss, Miss::Link(_));
        if n < attempts {
            let mut note = format!(
                "`{line}`: {last}; asked again (retry {n} of {})",
                attempts - 1
            );
            if let Some(caveat) = dialect.retry_caveat(line) {
                note.push_str(caveat);
            }
            dialect.retry_notes().push(dialect.device(), note);
            // the reply may have been late or followed by more junk: clear it first
            dialect.mark_dirty().await;
        }
        first.get_or_insert(miss);
    }
    let error = match first {
        Some(Miss::Reply { reply, reason }) => TableError::Reply {
            device: dialect.device().to_string(),
            command: line.to_string(),
            reason: if attempts > 1 {
                format!("{reason}; no usable reply in {attempts} attempts")
            } else {
                reason.to_string()
            },
            bytes: show_bytes(reply.as_bytes()),
        },
        Some(Miss::Link(e)) => TableError::from_link(dialect.device(), line, e),
        None => TableError::Reply {
            device: dialect.device().to_string(),
            command: line.to_string(),
            reason: "no attempt was made".into(),
            bytes: String::new(),
        },
    };
    if attempts > 1 {
        dialect.retry_notes().push(
            dialect.device(),
            format!("`{line}`: {last}; no usable reply in {attempts} attempts, gave up"),
        );
    }
    Err(DialectError {
        error,
        link_failed: link_missed,
    })
}

/// One failed attempt at a query.
pub enum Miss {
    /// Nothing (or not a line of text) came back.
    Link(LinkError),
    /// A line came back that is not a valid reply.
    Reply {
        /// The reply.
        reply: String,
        /// Why it is refused.
        reason: &'static str,
    },
}

impl Miss {
    /// What went wrong, for a retry note.
    pub fn describe(&self) -> String {
        match self {
            Miss::Link(LinkError::Timeout {
                timeout, partial, ..
            }) if partial.is_empty() => {
                format!("no reply within {:.3} s", timeout.as_secs_f64())
            }
            Miss::Link(LinkError::Timeout {
                timeout, partial, ..
            }) => format!(
                "no complete reply within {:.3} s (got {})",
                timeout.as_secs_f64(),
                show_bytes(partial)
            ),
            Miss::Link(LinkError::Garbled { reason, bytes, .. }) => {
                format!("garbled reply {} ({reason})", show_bytes(bytes))
            }
            Miss::Link(e) => e.to_string(),
            Miss::Reply { reply, reason } => {
                format!("unusable reply {} ({reason})", show_bytes(reply.as_bytes()))
            }
        }
    }
}

/// Whether asking again can help: a lost or corrupted reply can, a dead link cannot.
pub fn retryable(e: &LinkError) -> bool {
    matches!(e.kind(), LinkErrorKind::Timeout | LinkErrorKind::Garbled)
}
