//! Late replies and a table that answers slowly: what every dialect needs so that a reply is
//! never taken for another query's, written once.
//!
//! A line protocol without tags (ACL, the Aerosmith ASCII dialect) answers queries in order.
//! When a query's deadline passes, its reply is not gone: a controller busy with a profile, a
//! serial converter with a deep buffer or a network bridge delivers it later, and a driver that
//! only clears what has already arrived then reads it as the answer to its *next* query (a
//! `:Read:Rate?` answered `0,"No error"`, a `:Mode?` answered `-0.000092`). Two pieces stop
//! that:
//!
//! - [`Pending`] is the dialect's ledger of the queries whose replies are owed (sent, deadline
//!   passed or future cancelled, reply not read), oldest first. Before its next query a dialect
//!   gets back in step: ACL sends a *marker* query whose reply cannot be mistaken for any other
//!   (`*IDN?`) and reads up to its reply, every line before it being a late reply to an owed
//!   query, recognised and thrown away; the Aerosmith dialect reads the prompts it is owed.
//!   Each late reply tells how long the table took to answer.
//! - [`ReplyLatency`] keeps the slowest reply seen and adapts the deadlines to it, within a
//!   bound ([`ReplyLatency::limit`]): a table that is slow but alive keeps its run, the operator
//!   is told once that it answers slowly (and again when it gets markedly slower), and a table
//!   slower than the bound is treated as silent, as before.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use tokio::time::Instant;

/// The default bound of adapted reply deadlines: 5 s. A reply later than that is no reply (the
/// table is silent); a table whose replies take a few hundred milliseconds to 2 s, as a busy
/// controller or a serial-to-Ethernet bridge gives, keeps its run.
pub const DEFAULT_SLOW_REPLY_LIMIT: Duration = Duration::from_secs(5);

/// Replies faster than this are not taken as a sign of a slow table (a reply can be "late"
/// only for a deadline this short in a test script).
const SLOW: Duration = Duration::from_millis(50);

/// How many times the slowest latency a query's whole deadline adapts to: the marker exchange
/// that gets back in step and the query itself, each with a margin.
const DEADLINE_FACTOR: u32 = 6;

/// How many times the slowest latency one attempt gets at least: getting back in step (one
/// round trip) and the query (another), with margin.
const ATTEMPT_FACTOR: u32 = 3;

/// The table's observed reply latency, shared by the dialect and the retry policy
/// ([`crate::ask`]). Lock-free: read on every query.
#[derive(Debug)]
pub struct ReplyLatency {
    /// Slowest reply seen, in nanoseconds (0: none late yet).
    slowest_ns: AtomicU64,
    /// Slowest reply the operator was told about, in nanoseconds.
    told_ns: AtomicU64,
    limit: Duration,
}

impl ReplyLatency {
    /// No late reply seen yet; deadlines adapt up to `limit`.
    pub fn new(limit: Duration) -> Self {
        ReplyLatency {
            slowest_ns: AtomicU64::new(0),
            told_ns: AtomicU64::new(0),
            limit,
        }
    }

    /// The bound of adapted deadlines.
    pub fn limit(&self) -> Duration {
        self.limit
    }

    /// The slowest reply seen, if any came late.
    pub fn slowest(&self) -> Option<Duration> {
        match self.slowest_ns.load(Ordering::Relaxed) {
            0 => None,
            ns => Some(Duration::from_nanos(ns)),
        }
    }

    /// A query's whole deadline: `timeout`, or more for a table seen to answer slowly
    /// (six times its slowest reply), never more than the limit unless `timeout`
    /// itself is.
    pub fn deadline(&self, timeout: Duration) -> Duration {
        match self.slowest() {
            None => timeout,
            Some(slow) => timeout.max((slow * DEADLINE_FACTOR).min(self.limit)),
        }
    }

    /// The least time one attempt of a query gets (zero until a late reply was seen).
    pub fn attempt_floor(&self) -> Duration {
        self.slowest().map_or(Duration::ZERO, |slow| {
            (slow * ATTEMPT_FACTOR).min(self.limit)
        })
    }

    /// Records a reply that came `latency` after its query. Returns a sentence for the
    /// operator (and the run's manifest) the first time the table is seen to be slow and each
    /// time it gets half as slow again; `None` otherwise.
    pub fn observe(&self, latency: Duration, deadline: Option<Duration>) -> Option<String> {
        if latency < SLOW {
            // late for a deadline shorter than any a table is given: not a slow table
            return None;
        }
        let ns = u64::try_from(latency.as_nanos()).unwrap_or(u64::MAX).max(1);
        self.slowest_ns.fetch_max(ns, Ordering::Relaxed);
        let told = self.told_ns.load(Ordering::Relaxed);
        if told != 0 && ns < told.saturating_add(told / 2) {
            return None;
        }
        self.told_ns.fetch_max(ns, Ordering::Relaxed);
        let slow = Duration::from_nanos(ns);
        let beyond = slow > self.limit;
        let was = deadline
            .map(|d| format!(" (its deadline was {:.3} s)", d.as_secs_f64()))
            .unwrap_or_default();
        Some(if beyond {
            format!(
                "the table answers slowly: a reply came {:.3} s after its query{was}, more than \
                 the {:.1} s gyrocal waits at most; check the link (a busy controller, a serial \
                 converter's buffer, a network bridge)",
                slow.as_secs_f64(),
                self.limit.as_secs_f64()
            )
        } else {
            format!(
                "the table answers slowly: a reply came {:.3} s after its query{was}; reply \
                 deadlines now adapt to it (up to {:.3} s per query, at most {:.1} s); check \
                 the link (a busy controller, a serial converter's buffer, a network bridge)",
                slow.as_secs_f64(),
                (slow * DEADLINE_FACTOR).min(self.limit).as_secs_f64(),
                self.limit.as_secs_f64()
            )
        })
    }
}

impl Default for ReplyLatency {
    fn default() -> Self {
        ReplyLatency::new(DEFAULT_SLOW_REPLY_LIMIT)
    }
}

/// A query whose reply is owed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Owed {
    /// The query as sent.
    pub query: String,
    /// When it was sent.
    pub sent: Instant,
    /// A marker query sent to get back in step (its reply is recognised by its form).
    pub marker: bool,
}

/// The ledger of owed replies, oldest first (see the [module documentation](self)).
#[derive(Debug, Default)]
pub struct Pending {
    owed: VecDeque<Owed>,
}

/// What a line read while getting back in step was.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Late {
    /// The late reply to this query, which came this long after it was sent.
    Reply {
        /// The query it answers.
        query: String,
        /// How long after the query it came.
        latency: Duration,
    },
    /// A line no owed query accounts for (line noise, or a reply the table sent twice).
    Unexpected,
}

impl Pending {
    /// Owed replies.
    pub fn len(&self) -> usize {
        self.owed.len()
    }

    /// Nothing owed: the next reply is the next query's.
    pub fn is_empty(&self) -> bool {
        self.owed.is_empty()
    }

    /// A query is about to be sent: its reply is owed until [`Pending::answered`].
    pub fn sent(&mut self, query: &str, marker: bool) {
        self.owed.push_back(Owed {
            query: query.to_string(),
            sent: Instant::now(),
            marker,
        });
    }

    /// The newest query's reply was read in time.
    pub fn answered(&mut self) {
        self.owed.pop_back();
    }

    /// Markers still owed.
    pub fn markers(&self) -> usize {
        self.owed.iter().filter(|o| o.marker).count()
    }

    /// A line that is not a marker's reply arrived at `now`: the late reply to the oldest owed
    /// query that is not a marker (markers are answered in order after the queries before
    /// them, so a non-marker line belongs to the oldest non-marker).
    pub fn late_line(&mut self, now: Instant) -> Late {
        match self.owed.iter().position(|o| !o.marker) {
            Some(i) if self.owed.iter().take(i).all(|o| o.marker) => {
                let Some(o) = self.owed.remove(i) else {
                    return Late::Unexpected;
                };
                Late::Reply {
                    query: o.query,
                    latency: now.saturating_duration_since(o.sent),
                }
            }
            _ => Late::Unexpected,
        }
    }

    /// A marker's reply arrived at `now`: the oldest marker is answered, and every query owed
    /// before it got no reply (lost on the link, or thrown away with stale input). Returns
    /// those queries and the marker's latency.
    pub fn marker_line(&mut self, now: Instant) -> (Vec<String>, Option<Duration>) {
        let mut lost = Vec::new();
        while let Some(o) = self.owed.pop_front() {
            if o.marker {
                return (lost, Some(now.saturating_duration_since(o.sent)));
            }
            lost.push(o.query);
        }
        (lost, None)
    }

    /// Forgets what was owed longer than `limit` ago: such a reply is lost, not late. Returns
    /// how many were forgotten.
    pub fn forget_older_than(&mut self, limit: Duration, now: Instant) -> usize {
        let before = self.owed.len();
        self.owed
            .retain(|o| now.saturating_duration_since(o.sent) <= limit);
        before - self.owed.len()
    }

    /// Forgets everything owed (a fresh connection).
    pub fn clear(&mut self) {
        self.owed.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test(start_paused = true)]
    async fn late_lines_go_to_the_oldest_owed_query_and_a_marker_ends_the_ledger() {
        let mut p = Pending::default();
        p.sent(":Read:Rate? 1", false);
        tokio::time::advance(Duration::from_millis(300)).await;
        p.sent(":Mode? 1", false);
        p.sent("*IDN?", true);
        tokio::time::advance(Duration::from_millis(900)).await;
        assert_eq!(
            p.late_line(Instant::now()),
            Late::Reply {
                query: ":Read:Rate? 1".into(),
                latency: Duration::from_millis(1200)
            }
        );
        // the :Mode? reply was lost: the marker's reply says so
        let (lost, latency) = p.marker_line(Instant::now());
        assert_eq!(lost, vec![":Mode? 1".to_string()]);
        assert_eq!(latency, Some(Duration::from_millis(900)));
        assert!(p.is_empty());
        assert_eq!(p.late_line(Instant::now()), Late::Unexpected);
    }

    #[test]
    fn deadlines_adapt_to_a_slow_table_within_the_limit() {
        let l = ReplyLatency::new(Duration::from_secs(5));
        assert_eq!(l.deadline(Duration::from_secs(1)), Duration::from_secs(1));
        assert_eq!(l.attempt_floor(), Duration::ZERO);
        let note = l.observe(Duration::from_millis(600), Some(Duration::from_millis(333)));
        assert!(note.is_some_and(|n| n.contains("answers slowly") && n.contains("0.600 s")));
        assert_eq!(
            l.deadline(Duration::from_secs(1)),
            Duration::from_millis(3600)
        );
        assert_eq!(l.attempt_floor(), Duration::from_millis(1800));
        // slightly slower: not said again; half as slow again: said again
        assert!(l.observe(Duration::from_millis(700), None).is_none());
        assert!(l.observe(Duration::from_millis(2000), None).is_some());
        assert_eq!(l.deadline(Duration::from_secs(1)), Duration::from_secs(5));
        // a configured deadline above the limit is kept
        assert_eq!(l.deadline(Duration::from_secs(9)), Duration::from_secs(9));
    }
}
