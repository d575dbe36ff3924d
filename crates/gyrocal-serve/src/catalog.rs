//! The catalog as the server holds it: it may come after the server.
//!
//! A lab starts its view at boot, often before its PostgreSQL is up, or during a network
//! blip. The view must not wait for the catalog, nor do without it for its whole life: it
//! serves its roots' runs at once, and a catalog that does not answer at the start
//! ([`CatalogSource::Later`]) is tried again in the background after [`RETRY_FIRST`],
//! doubling to at most [`RETRY_MAX`] between tries ([`retry`]), until it opens. Meanwhile the
//! gyro pages answer 503 saying the catalog is not reachable yet ([`CatalogNow::Waiting`]);
//! once it opens they work, and with PostgreSQL the other benches' live runs appear (the
//! server starts to `LISTEN`, see [`crate::bus`]).
//!
//! Every failure to open is tried again, not only a refused connection: an SQLite file that
//! is missing (the first run creates it), unreadable (its permissions fixed) or damaged
//! (`gyrocal catalog rebuild` replaces it) comes the same way once it opens. Only a URL that
//! does not parse is refused, by the caller, before the server starts: waiting cannot mend it.
//!
//! The caller says the state to its user ([`crate::App::catalog_now`]): the pages never
//! carry the catalog's URL other than redacted.

use std::future::Future;
use std::time::Duration;

use gyrocal_catalog::{Catalog, CatalogUrl};

/// The wait before the first try again of a catalog that did not answer at the start.
pub const RETRY_FIRST: Duration = Duration::from_secs(2);
/// The longest wait between two tries (the wait doubles from [`RETRY_FIRST`] up to it).
pub const RETRY_MAX: Duration = Duration::from_secs(60);

/// Where the server's catalog comes from.
#[derive(Debug, Clone, Default)]
pub enum CatalogSource {
    /// No catalog: no gyro pages, no other benches' runs.
    #[default]
    None,
    /// A catalog already open.
    Open(Catalog),
    /// A catalog that did not answer when the server started: opened in the background,
    /// tried again until it answers (see the module docs).
    Later(CatalogUrl),
}

/// The catalog now.
#[derive(Debug, Clone)]
pub enum CatalogNow {
    /// No catalog.
    None,
    /// Not reachable yet: tried again in the background.
    Waiting,
    /// Open.
    Open(Catalog),
}

impl CatalogNow {
    /// The state a server with `source` starts in.
    pub fn at_start(source: &CatalogSource) -> CatalogNow {
        match source {
            CatalogSource::None => CatalogNow::None,
            CatalogSource::Open(c) => CatalogNow::Open(c.clone()),
            CatalogSource::Later(_) => CatalogNow::Waiting,
        }
    }
}

/// The wait before try number `n` (0: the first try again): [`RETRY_FIRST`] doubled `n`
/// times, at most [`RETRY_MAX`].
pub fn backoff(n: u32) -> Duration {
    RETRY_FIRST
        .saturating_mul(2u32.saturating_pow(n.min(16)))
        .min(RETRY_MAX)
}

/// Calls `open` after [`backoff`]`(0)`, then again after each next backoff, until it
/// succeeds; its value. Each failure is given to `failed` (to be logged: the first is said
/// by the caller before the server starts).
pub async fn retry<T, E, F, Fut>(mut open: F, mut failed: impl FnMut(&E)) -> T
where
    F: FnMut() -> Fut,
    Fut: Future<Output = Result<T, E>>,
{
    let mut n = 0;
    loop {
        tokio::time::sleep(backoff(n)).await;
        match open().await {
            Ok(v) => return v,
            Err(e) => failed(&e),
        }
        n = n.saturating_add(1);
    }
}

/// Opens the existing catalog at `url` once it answers (see [`retry`]).
pub async fn open_when_it_answers(url: &CatalogUrl) -> Catalog {
    retry(
        || Catalog::open_existing(url),
        |e| tracing::debug!("the catalog does not answer yet: {e}"),
    )
    .await
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // a panic is a failed test

    use std::cell::RefCell;

    use tokio::time::Instant;

    use super::*;

    #[test]
    fn the_wait_doubles_from_two_seconds_to_a_minute_and_stays_there() {
        let waits: Vec<u64> = (0..8).map(|n| backoff(n).as_secs()).collect();
        assert_eq!(waits, [2, 4, 8, 16, 32, 60, 60, 60]);
        assert_eq!(backoff(u32::MAX), RETRY_MAX);
    }

    #[tokio::test(start_paused = true)]
    async fn a_catalog_that_answers_at_the_seventh_try_is_open_after_the_waits_and_no_sooner() {
        let t0 = Instant::now();
        let tries = RefCell::new(Vec::new());
        let failures = RefCell::new(0);
        let got = retry(
            || {
                tries.borrow_mut().push(t0.elapsed().as_secs());
                let n = tries.borrow().len();
                async move { if n < 7 { Err("refused") } else { Ok(n) } }
            },
            |_: &&str| *failures.borrow_mut() += 1,
        )
        .await;
        assert_eq!(got, 7);
        assert_eq!(*failures.borrow(), 6);
        // virtual seconds since the start: 2, then +4, +8, +16, +32, +60, +60
        assert_eq!(*tries.borrow(), [2, 6, 14, 30, 62, 122, 182]);
    }
}
