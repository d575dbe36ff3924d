//! The live view's message bus on the catalog (schema version 4, `live_runs`): a run's live
//! state upserted and announced with NOTIFY on PostgreSQL (when GYROCAL_TEST_POSTGRES_URL is
//! set), the table present but unused on SQLite, and the run's publisher ([`LiveBus`]) that
//! never waits on a catalog that is unreachable or does not answer, and says so once.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::time::{Duration, Instant};

use gyrocal_catalog::{
    Catalog, CatalogUrl, LiveBus, LiveBusOptions, LiveNews, LiveRow, MAX_STATE_JSON,
};

fn row(run_id: &str, steps_done: i64) -> LiveRow {
    LiveRow {
        run_id: run_id.into(),
        host: "bench-host".into(),
        station_id: Some("bench-2".into()),
        dut_serial: Some("SN-1".into()),
        plan_name: "paper".into(),
        kind: "scale_factor".into(),
        phase: "acquiring".into(),
        step: steps_done + 1,
        steps: 19,
        steps_done,
        eta_s: Some(100.0),
        last_reading_v: Some(0.25),
        running_mean_v: Some(0.2499),
        table_state: Some("at rate".into()),
        status: "running".into(),
        verdict: None,
        updated_utc: gyrocal_files::rfc3339_utc(std::time::SystemTime::now()),
        state_json: format!("{{\"run_id\":\"{run_id}\",\"steps_done\":{steps_done}}}"),
    }
}

/// A run id no other test (or earlier run on the same database) uses.
fn uniq(name: &str) -> String {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos();
    format!("{name}-{}-{nanos}", std::process::id())
}

/// The rows of run `id` in the catalog at `url` (from a synchronous test).
fn rows_of(url: &CatalogUrl, id: &str) -> Vec<LiveRow> {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    rt.block_on(async {
        let c = Catalog::open(url).await.unwrap();
        c.live_runs(Some(id)).await.unwrap()
    })
}

fn postgres_url() -> Option<CatalogUrl> {
    let Ok(url) = std::env::var("GYROCAL_TEST_POSTGRES_URL") else {
        eprintln!("note: GYROCAL_TEST_POSTGRES_URL is not set; PostgreSQL test skipped");
        return None;
    };
    Some(CatalogUrl::parse(&url).unwrap())
}

#[tokio::test]
async fn postgres_upserts_one_row_per_run_and_notifies_each_update() {
    let Some(url) = postgres_url() else { return };
    let catalog = Catalog::open(&url).await.unwrap();
    assert!(catalog.carries_live());
    let mut listener = catalog
        .listen_live(Duration::from_secs(10))
        .await
        .unwrap()
        .expect("PostgreSQL listens");
    let id = uniq("live-run");
    for done in 0..3 {
        catalog.publish_live(&row(&id, done)).await.unwrap();
    }
    // three notifications naming the run (other tests' runs may come between)
    let mut heard = 0;
    let deadline = Instant::now() + Duration::from_secs(30);
    while heard < 3 {
        assert!(
            Instant::now() < deadline,
            "heard {heard} of 3 notifications"
        );
        let news = tokio::time::timeout(Duration::from_secs(30), listener.recv())
            .await
            .expect("a notification within 30 s")
            .unwrap();
        if news == LiveNews::Changed(id.clone()) {
            heard += 1;
        }
    }
    // one row, the last state
    let rows = catalog.live_runs(Some(&id)).await.unwrap();
    assert_eq!(rows.len(), 1, "{rows:?}");
    assert_eq!(rows[0].steps_done, 2);
    let expected = LiveRow {
        updated_utc: rows[0].updated_utc.clone(),
        ..row(&id, 2)
    };
    assert_eq!(rows[0], expected);
    assert!(
        catalog
            .live_runs(None)
            .await
            .unwrap()
            .iter()
            .any(|r| r.run_id == id)
    );
    // a state above the cap is refused, not stored cut
    let mut big = row(&id, 3);
    big.state_json = "x".repeat(MAX_STATE_JSON + 1);
    assert!(catalog.publish_live(&big).await.is_err());
    assert_eq!(catalog.live_runs(Some(&id)).await.unwrap()[0].steps_done, 2);
}

#[tokio::test]
async fn sqlite_has_the_table_and_no_listener() {
    let dir = tempfile::tempdir().unwrap();
    let catalog = Catalog::open(&CatalogUrl::Sqlite(dir.path().join("c.sqlite")))
        .await
        .unwrap();
    assert!(!catalog.carries_live());
    assert!(
        catalog
            .listen_live(Duration::from_secs(1))
            .await
            .unwrap()
            .is_none()
    );
    assert!(catalog.live_runs(None).await.unwrap().is_empty());
}

/// The bus against PostgreSQL: the newest state offered is the one in the table, and a
/// burst of states never waits for the catalog (the mailbox keeps the newest).
#[test]
fn the_bus_leaves_the_newest_state_in_the_catalog() {
    let Some(url) = postgres_url() else { return };
    let id = uniq("bus-run");
    let bus = LiveBus::spawn(url.clone());
    let t0 = Instant::now();
    for done in 0..200 {
        bus.publish(row(&id, done));
    }
    let offered_in = t0.elapsed();
    assert!(
        offered_in < Duration::from_secs(1),
        "200 states took {offered_in:?} to hand over"
    );
    assert!(bus.close(Duration::from_secs(30)), "{:?}", bus.stats());
    let stats = bus.stats();
    assert_eq!(stats.offered, 200);
    assert_eq!(stats.warnings, 0, "{stats:?}");
    assert!(
        stats.published >= 1 && stats.published + stats.superseded >= 200,
        "{stats:?}"
    );
    let rows = rows_of(&url, &id);
    assert_eq!(rows.len(), 1);
    assert_eq!(rows[0].steps_done, 199);
}

/// A "PostgreSQL" that accepts connections and never answers, and one that refuses them:
/// handing a state over stays immediate, the failure is warned once (not per state), and
/// closing is bounded.
#[test]
fn a_catalog_that_never_answers_costs_the_publisher_nothing_and_is_said_once() {
    let silent = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let silent_port = silent.local_addr().unwrap().port();
    // hold the accepted connections open without a word
    std::thread::spawn(move || {
        let mut held = Vec::new();
        for c in silent.incoming() {
            held.push(c);
        }
    });
    let refused_port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    for port in [silent_port, refused_port] {
        let url = CatalogUrl::parse(&format!("postgres://gyrocal@127.0.0.1:{port}/lab")).unwrap();
        let bus = LiveBus::spawn_with(
            url,
            LiveBusOptions {
                connect_timeout: Duration::from_millis(300),
                statement_timeout: Duration::from_millis(300),
                retry: Duration::from_millis(100),
            },
        );
        let mut slowest = Duration::ZERO;
        for done in 0..50 {
            let t = Instant::now();
            bus.publish(row("r", done));
            slowest = slowest.max(t.elapsed());
            std::thread::sleep(Duration::from_millis(40));
        }
        assert!(
            slowest < Duration::from_millis(50),
            "port {port}: a hand-over took {slowest:?}"
        );
        let t = Instant::now();
        assert!(
            !bus.close(Duration::from_secs(5)),
            "port {port}: nothing could be sent"
        );
        assert!(
            t.elapsed() < Duration::from_secs(6),
            "close took {:?}",
            t.elapsed()
        );
        let stats = bus.stats();
        assert!(stats.failures >= 2, "port {port}: {stats:?}");
        assert_eq!(stats.warnings, 1, "port {port}: said once: {stats:?}");
        assert_eq!(stats.published, 0);
    }
}

/// A TCP relay to the test's PostgreSQL that can be frozen (it stops passing bytes either way
/// and keeps the connections open: a server that stops answering) and thawed.
struct Relay {
    port: u16,
    frozen: std::sync::Arc<std::sync::atomic::AtomicBool>,
}

impl Relay {
    fn to(target: String) -> Relay {
        use std::io::{Read as _, Write as _};
        use std::sync::atomic::Ordering;
        let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let port = l.local_addr().unwrap().port();
        let frozen = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let f = frozen.clone();
        std::thread::spawn(move || {
            for client in l.incoming() {
                let Ok(client) = client else { continue };
                let Ok(server) = std::net::TcpStream::connect(&target) else {
                    continue;
                };
                for (mut from, mut to) in [
                    (client.try_clone().unwrap(), server.try_clone().unwrap()),
                    (server, client),
                ] {
                    let f = f.clone();
                    std::thread::spawn(move || {
                        from.set_read_timeout(Some(Duration::from_millis(20)))
                            .unwrap();
                        let mut buf = [0u8; 16384];
                        loop {
                            if f.load(Ordering::SeqCst) {
                                std::thread::sleep(Duration::from_millis(20));
                                continue;
                            }
                            match from.read(&mut buf) {
                                Ok(0) => break,
                                Ok(n) => {
                                    if to.write_all(&buf[..n]).is_err() {
                                        break;
                                    }
                                }
                                Err(e)
                                    if matches!(
                                        e.kind(),
                                        std::io::ErrorKind::WouldBlock
                                            | std::io::ErrorKind::TimedOut
                                    ) => {}
                                Err(_) => break,
                            }
                        }
                    });
                }
            }
        });
        Relay { port, frozen }
    }

    fn freeze(&self, on: bool) {
        self.frozen.store(on, std::sync::atomic::Ordering::SeqCst);
    }
}

/// PostgreSQL stops answering in the middle of a run and comes back: every hand-over stays
/// immediate, the outage is warned once, and the bus catches up by itself with the newest
/// state.
#[test]
fn a_catalog_that_stops_answering_mid_run_is_said_once_and_caught_up_with() {
    let Some(url) = postgres_url() else { return };
    let text = std::env::var("GYROCAL_TEST_POSTGRES_URL").unwrap();
    // postgres://USER[:PASS]@HOST:PORT/DB: the relay in place of HOST:PORT
    let at = text.rfind('@').unwrap() + 1;
    let slash = at + text[at..].find('/').unwrap();
    let relay = Relay::to(text[at..slash].to_string());
    let relayed = CatalogUrl::parse(&format!(
        "{}127.0.0.1:{}{}",
        &text[..at],
        relay.port,
        &text[slash..]
    ))
    .unwrap();
    let id = uniq("frozen-run");
    let bus = LiveBus::spawn_with(
        relayed,
        LiveBusOptions {
            connect_timeout: Duration::from_millis(500),
            statement_timeout: Duration::from_millis(500),
            retry: Duration::from_millis(100),
        },
    );
    let wait_for = |what: &str, f: &dyn Fn() -> bool| {
        let t = Instant::now();
        while !f() {
            assert!(
                t.elapsed() < Duration::from_secs(30),
                "{what}: {:?}",
                bus.stats()
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    };
    bus.publish(row(&id, 0));
    wait_for("the first state", &|| bus.stats().published >= 1);
    relay.freeze(true);
    let mut slowest = Duration::ZERO;
    for done in 1..40 {
        let t = Instant::now();
        bus.publish(row(&id, done));
        slowest = slowest.max(t.elapsed());
        std::thread::sleep(Duration::from_millis(40));
    }
    assert!(
        slowest < Duration::from_millis(50),
        "a hand-over took {slowest:?}"
    );
    wait_for("the outage noticed", &|| bus.stats().failures >= 1);
    assert_eq!(bus.stats().warnings, 1, "{:?}", bus.stats());
    relay.freeze(false);
    let before = bus.stats().published;
    bus.publish(row(&id, 40));
    wait_for("caught up", &|| bus.stats().published > before);
    assert!(bus.close(Duration::from_secs(10)), "{:?}", bus.stats());
    // one warning for the one outage (the catalog answered again in between)
    assert_eq!(bus.stats().warnings, 1, "{:?}", bus.stats());
    let rows = rows_of(&url, &id);
    assert_eq!(rows[0].steps_done, 40, "the newest state is in the catalog");
}

/// The prune's policy on `catalog` as of now: an ended run's row goes 30 days after its last
/// update, a `running` one silent for 7 days goes; younger rows stay. Returns how many rows
/// the prune said it deleted.
async fn prune_keeps_what_a_view_needs(catalog: &Catalog) -> u64 {
    use gyrocal_catalog::{LIVE_KEEP_ENDED, LIVE_KEEP_SILENT};
    let now = std::time::SystemTime::now();
    let day = Duration::from_secs(86_400);
    let aged = |name: &str, status: &str, age: Duration| LiveRow {
        status: status.into(),
        updated_utc: gyrocal_files::rfc3339_utc(now - age),
        ..row(&uniq(name), 3)
    };
    let gone = [
        aged("ended-31d", "complete", LIVE_KEEP_ENDED + day),
        aged("aborted-31d", "aborted", LIVE_KEEP_ENDED + day),
        aged("silent-8d", "running", LIVE_KEEP_SILENT + day),
    ];
    let kept = [
        aged("ended-29d", "complete", LIVE_KEEP_ENDED - day),
        aged("silent-6d", "running", LIVE_KEEP_SILENT - day),
        aged("running-now", "running", Duration::from_secs(5)),
    ];
    for r in gone.iter().chain(&kept) {
        catalog.publish_live(r).await.unwrap();
    }
    let deleted = catalog.prune_live(now).await.unwrap();
    for r in &gone {
        let left = catalog.live_runs(Some(&r.run_id)).await.unwrap();
        assert!(left.is_empty(), "{} ({}) kept", r.run_id, r.updated_utc);
    }
    for r in &kept {
        let left = catalog.live_runs(Some(&r.run_id)).await.unwrap();
        assert_eq!(left.len(), 1, "{} ({}) pruned", r.run_id, r.updated_utc);
    }
    deleted
}

#[tokio::test]
async fn prune_deletes_ended_rows_after_30_days_and_silent_running_ones_after_7_sqlite() {
    let dir = tempfile::tempdir().unwrap();
    let catalog = Catalog::open(&CatalogUrl::Sqlite(dir.path().join("c.sqlite")))
        .await
        .unwrap();
    assert_eq!(prune_keeps_what_a_view_needs(&catalog).await, 3);
    assert_eq!(catalog.live_runs(None).await.unwrap().len(), 3);
    // nothing more to prune at once
    let now = std::time::SystemTime::now();
    assert_eq!(catalog.prune_live(now).await.unwrap(), 0);
}

#[tokio::test]
async fn prune_deletes_ended_rows_after_30_days_and_silent_running_ones_after_7_postgres() {
    let Some(url) = postgres_url() else { return };
    let catalog = Catalog::open(&url).await.unwrap();
    // the count is not checked: another test's server may prune the same rows first
    prune_keeps_what_a_view_needs(&catalog).await;
}
