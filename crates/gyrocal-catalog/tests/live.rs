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
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let rows = rt.block_on(async {
        let c = Catalog::open(&url).await.unwrap();
        c.live_runs(Some(&id)).await.unwrap()
    });
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
