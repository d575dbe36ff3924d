//! The run hook: keeps the catalog up to date while a run writes its directory, without ever
//! slowing or failing the run.
//!
//! [`CatalogWriter::spawn`] starts one OS thread with its own single-threaded tokio runtime
//! (real time: the caller may be a simulated run in paused, virtual time, whose clock must
//! not drive the catalog's timeouts, and whose runtime must not wait on the catalog).
//! [`CatalogWriter::register`], [`CatalogWriter::step_done`] and
//! [`CatalogWriter::finished`] only note the directory in a small map (one entry per run
//! directory, later events replacing earlier ones: each re-imports the whole directory, so
//! nothing is lost by coalescing) and wake the thread: a few microseconds, no I/O, no error.
//!
//! The thread re-imports each noted directory (an idempotent upsert by run id). When the
//! catalog is unreachable it logs one warning, keeps the directories noted, and tries again
//! at the next event or after a back-off (5 s doubling to 60 s), so it catches up by itself;
//! a connection attempt is bounded by [`WriterOptions::connect_timeout`].
//! [`CatalogWriter::close`] gives it a bounded time to finish.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use crate::db::{Catalog, OpenOptions};
use crate::error::{CatalogError, ErrorKind};
use crate::url::CatalogUrl;

/// Which event noted a directory (for the log only: every event re-imports the directory).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Event {
    Register,
    StepDone,
    Finished,
}

/// The writer's settings.
#[derive(Debug, Clone)]
pub struct WriterOptions {
    /// The longest a connection attempt may take (default 2 s).
    pub connect_timeout: Duration,
    /// First wait before retrying an unreachable catalog without a new event (default 5 s;
    /// doubles up to 60 s).
    pub retry: Duration,
}

impl Default for WriterOptions {
    fn default() -> Self {
        WriterOptions {
            connect_timeout: Duration::from_secs(2),
            retry: Duration::from_secs(5),
        }
    }
}

/// What the writer has done so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct WriterStats {
    /// Successful imports.
    pub imported: u64,
    /// Failed attempts (unreachable catalog, unreadable directory, database errors).
    pub failures: u64,
    /// Directories waiting to be imported.
    pub pending: u64,
}

#[derive(Debug, Default)]
struct Shared {
    pending: Mutex<BTreeMap<PathBuf, Event>>,
    notify: tokio::sync::Notify,
    closing: AtomicBool,
    imported: AtomicU64,
    failures: AtomicU64,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, BTreeMap<PathBuf, Event>> {
        // a panic elsewhere while holding the lock leaves a valid map: go on with it
        self.pending.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// The catalog's run hook. See the module docs.
#[derive(Debug)]
pub struct CatalogWriter {
    shared: Arc<Shared>,
    done: Option<std::sync::mpsc::Receiver<()>>,
    url: String,
}

impl CatalogWriter {
    /// Starts the writer for `url` with [`WriterOptions::default`]. Never fails: when the
    /// thread cannot start, a warning is logged and the events are ignored.
    pub fn spawn(url: CatalogUrl) -> CatalogWriter {
        CatalogWriter::spawn_with(url, WriterOptions::default())
    }

    /// [`CatalogWriter::spawn`] with explicit settings.
    pub fn spawn_with(url: CatalogUrl, options: WriterOptions) -> CatalogWriter {
        let shared = Arc::new(Shared::default());
        let (done_tx, done_rx) = std::sync::mpsc::channel();
        let redacted = url.redacted();
        let worker_shared = Arc::clone(&shared);
        let spawned = std::thread::Builder::new()
            .name("gyrocal-catalog".into())
            .spawn(move || {
                match tokio::runtime::Builder::new_current_thread()
                    .enable_all()
                    .build()
                {
                    Ok(rt) => rt.block_on(worker(url, options, worker_shared)),
                    Err(e) => tracing::warn!(error = %e, "the catalog writer cannot start its runtime; the catalog will not be updated by this run"),
                }
                let _ = done_tx.send(());
            });
        let done = match spawned {
            Ok(_) => Some(done_rx),
            Err(e) => {
                tracing::warn!(error = %e, "cannot start the catalog writer; the catalog will not be updated by this run");
                None
            }
        };
        CatalogWriter {
            shared,
            done,
            url: redacted,
        }
    }

    fn note(&self, dir: &Path, event: Event) {
        if self.done.is_none() {
            return;
        }
        self.shared.lock().insert(dir.to_path_buf(), event);
        self.shared.notify.notify_one();
    }

    /// The catalog's URL, its password redacted (for messages).
    pub fn url(&self) -> &str {
        &self.url
    }

    /// A run directory was created (its manifest exists).
    pub fn register(&self, run_dir: &Path) {
        self.note(run_dir, Event::Register);
    }

    /// A step of the run finished.
    pub fn step_done(&self, run_dir: &Path) {
        self.note(run_dir, Event::StepDone);
    }

    /// The run ended (complete, failed or aborted; fitted when it could be).
    pub fn finished(&self, run_dir: &Path) {
        self.note(run_dir, Event::Finished);
    }

    /// What the writer has done so far.
    pub fn stats(&self) -> WriterStats {
        WriterStats {
            imported: self.shared.imported.load(Ordering::Relaxed),
            failures: self.shared.failures.load(Ordering::Relaxed),
            pending: self.shared.lock().len() as u64,
        }
    }

    /// Lets the writer import what is pending, waiting at most `timeout` (a blocking wait:
    /// call it when the run is over). Returns true when everything noted is in the catalog;
    /// false (with a warning naming the catalog) when the time ran out or the catalog could
    /// not be reached: the run directories stay the source of truth, and
    /// `gyrocal catalog import DIR` adds them later.
    pub fn close(mut self, timeout: Duration) -> bool {
        self.shared.closing.store(true, Ordering::SeqCst);
        self.shared.notify.notify_one();
        let finished = match self.done.take() {
            Some(rx) => rx.recv_timeout(timeout).is_ok(),
            None => true,
        };
        let pending = self.shared.lock().len();
        if pending > 0 || !finished {
            tracing::warn!(catalog = %self.url, pending, "the catalog was not brought up to date; add the run later with `gyrocal catalog import DIR`");
            false
        } else {
            true
        }
    }
}

impl Drop for CatalogWriter {
    fn drop(&mut self) {
        // without close(): the thread finishes what is pending in the background
        self.shared.closing.store(true, Ordering::SeqCst);
        self.shared.notify.notify_one();
    }
}

async fn worker(url: CatalogUrl, options: WriterOptions, shared: Arc<Shared>) {
    let open = OpenOptions {
        connect_timeout: options.connect_timeout,
        busy_timeout: Duration::from_secs(5),
        max_connections: 1,
        create: true,
    };
    let mut catalog: Option<Catalog> = None;
    let mut unreachable_warned = false;
    let mut backoff: Option<Duration> = None;
    let mut warned_dirs: std::collections::BTreeSet<PathBuf> = Default::default();
    loop {
        let closing = shared.closing.load(Ordering::SeqCst);
        let batch: BTreeMap<PathBuf, Event> = std::mem::take(&mut *shared.lock());
        if batch.is_empty() && closing {
            break;
        }
        if !batch.is_empty() {
            let mut retry_later: Vec<(PathBuf, Event)> = Vec::new();
            if catalog.is_none() {
                match Catalog::open_with(&url, &open).await {
                    Ok(c) => {
                        if unreachable_warned {
                            tracing::warn!(catalog = %url, "the catalog is reachable again; catching up");
                        }
                        unreachable_warned = false;
                        catalog = Some(c);
                    }
                    Err(e) => {
                        shared.failures.fetch_add(1, Ordering::Relaxed);
                        if !unreachable_warned {
                            tracing::warn!(error = %e, "cannot reach the catalog; the run goes on and the catalog catches up later");
                            unreachable_warned = true;
                        }
                        retry_later.extend(batch.clone());
                    }
                }
            }
            if let Some(c) = &catalog {
                for (dir, event) in batch {
                    match import(c, &dir).await {
                        Ok(id) => {
                            shared.imported.fetch_add(1, Ordering::Relaxed);
                            tracing::debug!(dir = %dir.display(), ?event, run = %id, "catalog updated");
                        }
                        Err(e) if e.kind() == ErrorKind::Unreachable => {
                            shared.failures.fetch_add(1, Ordering::Relaxed);
                            if !unreachable_warned {
                                tracing::warn!(error = %e, "lost the catalog; the run goes on and the catalog catches up later");
                                unreachable_warned = true;
                            }
                            retry_later.push((dir, event));
                        }
                        Err(e) => {
                            shared.failures.fetch_add(1, Ordering::Relaxed);
                            if warned_dirs.insert(dir.clone()) {
                                tracing::warn!(error = %e, "cannot add the run to the catalog");
                            }
                            // a database error may pass (a lock, a restart): once more later
                            if e.kind() == ErrorKind::Database {
                                retry_later.push((dir, event));
                            }
                        }
                    }
                }
                if !retry_later.is_empty() {
                    // a broken pool is rebuilt at the next attempt
                    if let Some(c) = catalog.take() {
                        c.close().await;
                    }
                }
            }
            if retry_later.is_empty() {
                backoff = None;
            } else {
                let mut pending = shared.lock();
                for (dir, event) in retry_later {
                    // a newer event for the same directory wins
                    pending.entry(dir).or_insert(event);
                }
                drop(pending);
                if closing {
                    // one last attempt was made; close() reports what is left
                    break;
                }
                backoff = Some(
                    backoff
                        .map_or(options.retry, |b| b * 2)
                        .min(Duration::from_secs(60)),
                );
            }
        }
        if shared.closing.load(Ordering::SeqCst) && shared.lock().is_empty() {
            break;
        }
        match backoff {
            Some(wait) => {
                tokio::select! {
                    () = shared.notify.notified() => {}
                    () = tokio::time::sleep(wait) => {}
                }
            }
            None => shared.notify.notified().await,
        }
    }
    if let Some(c) = catalog {
        c.close().await;
    }
}

async fn import(catalog: &Catalog, dir: &Path) -> Result<String, CatalogError> {
    catalog.import_dir(dir).await
}
