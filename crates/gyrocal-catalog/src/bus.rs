//! The publishing side of the live view's message bus: [`LiveBus`] hands a run's live state
//! to the catalog (`live_runs` and `NOTIFY gyrocal_live`, see [`crate::live`]) without the
//! run ever waiting on it.
//!
//! The run's side is [`LiveBus::publish`]: it puts the row in a one-slot mailbox (the newest
//! row replaces one not yet sent: latest wins, so the mailbox is bounded whatever the
//! catalog does) and wakes a thread of its own, with its own single-threaded runtime in real
//! time (a simulated run's virtual clock must not drive the catalog's timeouts). A few
//! microseconds, no I/O, no error. The thread connects (bounded by
//! [`LiveBusOptions::connect_timeout`]), upserts with a bound on each statement
//! ([`LiveBusOptions::statement_timeout`]), and after a failure says it once (a warning in
//! the log), drops the connection and tries again at the next row after a back-off (1 s
//! doubling to 30 s), so a catalog that is slow, stopped or unreachable costs the run
//! nothing and is caught up with by itself. [`LiveBus::close`] gives the last row a bounded
//! time.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use crate::db::{Catalog, OpenOptions};
use crate::live::LiveRow;
use crate::url::CatalogUrl;

/// The bus's settings.
#[derive(Debug, Clone)]
pub struct LiveBusOptions {
    /// The longest a connection attempt may take (default 2 s).
    pub connect_timeout: Duration,
    /// The longest one upsert may take before the catalog is taken as not answering
    /// (default 2 s).
    pub statement_timeout: Duration,
    /// The first wait after a failure before the next attempt (default 1 s; doubles up to
    /// 30 s). Rows that come meanwhile replace each other.
    pub retry: Duration,
}

impl Default for LiveBusOptions {
    fn default() -> Self {
        LiveBusOptions {
            connect_timeout: Duration::from_secs(2),
            statement_timeout: Duration::from_secs(2),
            retry: Duration::from_secs(1),
        }
    }
}

/// What the bus has done so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LiveBusStats {
    /// Rows handed to [`LiveBus::publish`].
    pub offered: u64,
    /// Rows in the catalog (each with its notification).
    pub published: u64,
    /// Rows replaced in the mailbox by a newer one before they were sent.
    pub superseded: u64,
    /// Failed attempts (connecting or upserting).
    pub failures: u64,
    /// Warnings given (at most one per outage: the first failure after a success).
    pub warnings: u64,
}

#[derive(Debug, Default)]
struct Shared {
    slot: Mutex<Option<LiveRow>>,
    notify: tokio::sync::Notify,
    closing: AtomicBool,
    /// The last attempt failed (the catalog is away): a close does not wait for it.
    failing: AtomicBool,
    offered: AtomicU64,
    published: AtomicU64,
    superseded: AtomicU64,
    failures: AtomicU64,
    warnings: AtomicU64,
}

impl Shared {
    fn slot(&self) -> MutexGuard<'_, Option<LiveRow>> {
        self.slot.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// The publisher of a run's live state to the catalog. See the module docs.
#[derive(Debug)]
pub struct LiveBus {
    shared: Arc<Shared>,
    /// The thread's end (`None`: it never started, or was waited for already).
    done: Mutex<Option<std::sync::mpsc::Receiver<()>>>,
    started: bool,
}

impl LiveBus {
    /// Starts the bus for `url` with [`LiveBusOptions::default`]. Never fails: when the
    /// thread cannot start, a warning is logged and the rows are dropped.
    pub fn spawn(url: CatalogUrl) -> LiveBus {
        LiveBus::spawn_with(url, LiveBusOptions::default())
    }

    /// [`LiveBus::spawn`] with explicit settings.
    pub fn spawn_with(url: CatalogUrl, options: LiveBusOptions) -> LiveBus {
        let shared = Arc::new(Shared::default());
        let (done_tx, done_rx) = std::sync::mpsc::channel();
        let worker_shared = Arc::clone(&shared);
        let spawned = std::thread::Builder::new()
            .name("gyrocal-live-bus".into())
            .spawn(move || {
                match tokio::runtime::Builder::new_current_thread()
                    .enable_all()
                    .build()
                {
                    Ok(rt) => rt.block_on(worker(url, options, worker_shared)),
                    Err(e) => tracing::warn!(error = %e, "the live bus cannot start its runtime; viewers of the catalog will not see this run live"),
                }
                let _ = done_tx.send(());
            });
        let done = match spawned {
            Ok(_) => Some(done_rx),
            Err(e) => {
                tracing::warn!(error = %e, "cannot start the live bus; viewers of the catalog will not see this run live");
                None
            }
        };
        LiveBus {
            shared,
            started: done.is_some(),
            done: Mutex::new(done),
        }
    }

    /// Hands the newest live state to the bus: never waits, never fails (see the module docs).
    pub fn publish(&self, row: LiveRow) {
        if !self.started {
            return;
        }
        self.shared.offered.fetch_add(1, Ordering::Relaxed);
        if self.shared.slot().replace(row).is_some() {
            self.shared.superseded.fetch_add(1, Ordering::Relaxed);
        }
        self.shared.notify.notify_one();
    }

    /// What the bus has done so far.
    pub fn stats(&self) -> LiveBusStats {
        let s = &self.shared;
        LiveBusStats {
            offered: s.offered.load(Ordering::Relaxed),
            published: s.published.load(Ordering::Relaxed),
            superseded: s.superseded.load(Ordering::Relaxed),
            failures: s.failures.load(Ordering::Relaxed),
            warnings: s.warnings.load(Ordering::Relaxed),
        }
    }

    /// Sends the row still waiting (one attempt) and ends the thread, waiting at most
    /// `timeout` (a blocking wait: call it when the run is over). True when nothing was left
    /// unsent. When the catalog is already known to be away (the last attempt failed), it
    /// does not wait at all: the thread makes its last attempt on its own.
    pub fn close(&self, timeout: Duration) -> bool {
        self.shared.closing.store(true, Ordering::SeqCst);
        self.shared.notify.notify_one();
        if self.shared.failing.load(Ordering::SeqCst) {
            return false;
        }
        let done = self.done.lock().unwrap_or_else(|e| e.into_inner()).take();
        let finished = match done {
            Some(rx) => rx.recv_timeout(timeout).is_ok(),
            None => true,
        };
        finished && self.shared.slot().is_none()
    }
}

impl Drop for LiveBus {
    fn drop(&mut self) {
        // without close(): the thread sends what is waiting (bounded) and ends
        self.shared.closing.store(true, Ordering::SeqCst);
        self.shared.notify.notify_one();
    }
}

async fn worker(url: CatalogUrl, options: LiveBusOptions, shared: Arc<Shared>) {
    let open = OpenOptions {
        connect_timeout: options.connect_timeout,
        busy_timeout: Duration::from_secs(5),
        max_connections: 1,
        create: false,
    };
    let mut catalog: Option<Catalog> = None;
    let mut failing = false;
    let mut backoff: Option<Duration> = None;
    loop {
        let closing = shared.closing.load(Ordering::SeqCst);
        let row = shared.slot().take();
        let Some(row) = row else {
            if closing {
                break;
            }
            shared.notify.notified().await;
            continue;
        };
        let attempt = async {
            if catalog.is_none() {
                catalog = Some(Catalog::open_with(&url, &open).await?);
            }
            match &catalog {
                Some(c) => {
                    match tokio::time::timeout(options.statement_timeout, c.publish_live(&row))
                        .await
                    {
                        Ok(r) => r,
                        Err(_) => Err(crate::CatalogError::Unreachable {
                            url: url.redacted(),
                            message: format!(
                                "no answer within {:?} to the live state's update",
                                options.statement_timeout
                            ),
                        }),
                    }
                }
                None => Ok(()),
            }
        };
        // the whole attempt is bounded too (a server that accepts and never answers)
        let bound = options.connect_timeout + options.statement_timeout;
        let result = match tokio::time::timeout(bound, attempt).await {
            Ok(r) => r,
            Err(_) => Err(crate::CatalogError::Unreachable {
                url: url.redacted(),
                message: format!("no answer within {bound:?}"),
            }),
        };
        match result {
            Ok(()) => {
                shared.published.fetch_add(1, Ordering::Relaxed);
                if failing {
                    tracing::warn!(catalog = %url.redacted(), "the catalog takes the live state again");
                }
                failing = false;
                shared.failing.store(false, Ordering::SeqCst);
                backoff = None;
            }
            Err(e) => {
                shared.failures.fetch_add(1, Ordering::Relaxed);
                if !failing {
                    shared.warnings.fetch_add(1, Ordering::Relaxed);
                    tracing::warn!(error = %e, "the live state cannot reach the catalog; the run goes on (its run directory is complete) and viewers of the catalog see it again once it answers");
                }
                failing = true;
                shared.failing.store(true, Ordering::SeqCst);
                if let Some(c) = catalog.take() {
                    // a pool that stopped answering is rebuilt at the next attempt; its
                    // close may hang on that server too: not waited for long
                    let _ = tokio::time::timeout(Duration::from_millis(200), c.close()).await;
                }
                // the newest row wins: this one goes back only when none came meanwhile
                {
                    let mut slot = shared.slot();
                    if slot.is_none() {
                        *slot = Some(row);
                    }
                }
                if closing {
                    break;
                }
                let wait = backoff.map_or(options.retry, |b| (b * 2).min(Duration::from_secs(30)));
                backoff = Some(wait);
                tokio::select! {
                    () = tokio::time::sleep(wait) => {}
                    () = async {
                        // a close ends the wait (one last attempt)
                        while !shared.closing.load(Ordering::SeqCst) {
                            shared.notify.notified().await;
                        }
                    } => {}
                }
            }
        }
    }
    if let Some(c) = catalog {
        let _ = tokio::time::timeout(Duration::from_secs(1), c.close()).await;
    }
}
