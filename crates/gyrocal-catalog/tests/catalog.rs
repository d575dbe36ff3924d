//! The catalog on SQLite (always) and PostgreSQL (when GYROCAL_TEST_POSTGRES_URL is set):
//! import, idempotency, run lists, history, concurrent writers, and the run hook with an
//! unreachable catalog.

#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::path::PathBuf;
use std::time::{Duration, Instant};

use common::{Spec, clone_run};
use gyrocal_catalog::{Catalog, CatalogUrl, CatalogWriter, ErrorKind, RunFilter, WriterOptions};

fn sqlite_url(dir: &tempfile::TempDir) -> CatalogUrl {
    CatalogUrl::Sqlite(dir.path().join("data/gyrocal/catalog.sqlite"))
}

/// The PostgreSQL catalog of the test environment, or None (with a note).
async fn postgres() -> Option<Catalog> {
    let Ok(url) = std::env::var("GYROCAL_TEST_POSTGRES_URL") else {
        eprintln!("note: GYROCAL_TEST_POSTGRES_URL is not set; PostgreSQL test skipped");
        return None;
    };
    let catalog = Catalog::open(&CatalogUrl::parse(&url).unwrap())
        .await
        .unwrap();
    Some(catalog)
}

/// A serial number no other test (or earlier run of the tests on the same PostgreSQL
/// database) uses: tests run in parallel processes and never empty the shared catalog.
fn uniq(serial: &str) -> String {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos();
    format!("{serial}-{}-{nanos}", std::process::id())
}

async fn import_and_query(catalog: &Catalog, root: &std::path::Path) {
    let a = uniq("A-0421");
    let a = a.as_str();
    let b = uniq("B-7");
    let a1 = clone_run(&root.join("a1"), &Spec::new(a, 1, 0.3600));
    let mut s = Spec::new(a, 5, 0.3601);
    s.extras = true;
    let a2 = clone_run(&root.join("a2"), &s);
    let b1 = clone_run(&root.join("b1"), &Spec::new(&b, 3, 0.3500));
    let mut sim = Spec::new(a, 7, 0.3602);
    sim.simulated = true;
    let a3 = clone_run(&root.join("a3"), &sim);
    for d in [&a1, &a2, &b1, &a3] {
        catalog.import_dir(d).await.unwrap();
    }
    // idempotent
    let id = catalog.import_dir(&a2).await.unwrap();
    catalog.import_dir(&a2).await.unwrap();

    let all = catalog
        .runs(&RunFilter {
            serial: Some(a.into()),
            ..RunFilter::default()
        })
        .await
        .unwrap();
    assert_eq!(all.len(), 3);
    // newest first
    assert_eq!(all[0].run.started_utc, "2026-01-08T10:00:00.000Z");
    assert!(all[0].run.simulated);
    let since = catalog
        .runs(&RunFilter {
            serial: Some(a.into()),
            since: Some("2026-01-04".into()),
            ..RunFilter::default()
        })
        .await
        .unwrap();
    assert_eq!(since.len(), 2, "{since:?}");

    let steps = catalog.steps(&id).await.unwrap();
    assert_eq!(steps.len(), 5);
    assert_eq!(steps[3].rate_dps, 10.0);
    let instruments = catalog.instruments(&id).await.unwrap();
    assert_eq!(instruments.len(), 2);
    assert_eq!(instruments[0].role, "multimeter");
    assert_eq!(instruments[0].model.as_deref(), Some("34401A"));
    assert_eq!(instruments[0].serial.as_deref(), Some("3146A12345"));

    let h = catalog.history(a, false).await.unwrap();
    assert_eq!(h.calibrations.len(), 2, "simulated runs are left out");
    let r = h.calibrations[1].results.as_ref().unwrap();
    assert_eq!(r.scale_factor, Some(0.3601));
    assert_eq!(r.u_scale_factor, Some(3.6e-5));
    assert_eq!(r.asymmetry_common_k2_ppm, Some(12.5));
    assert_eq!(r.k2, Some(1.1e-5));
    assert_eq!(h.calibrations[1].run.verdict.as_deref(), Some("pass"));
    assert_eq!(h.calibrations[1].checks.len(), 1);
    let ppm = h.repeatability.scale_factor_ppm.unwrap();
    let expected = (0.0001f64 / 2f64.sqrt()) / 0.36005 * 1e6;
    assert!(
        (ppm - expected).abs() < 1e-6 * expected,
        "{ppm} vs {expected}"
    );
    let k = h
        .trends
        .iter()
        .find(|t| t.quantity == "scale_factor")
        .unwrap();
    assert_eq!(k.limits.as_ref().unwrap().max, Some(0.365));
    let with_sim = catalog.history(a, true).await.unwrap();
    assert_eq!(with_sim.calibrations.len(), 3);
    // the page of this history is rendered by gyrocal-report (its test
    // `history_page_has_the_trend_plots_and_names_the_gyro`, moved from here with the renderer)
}

#[tokio::test]
async fn sqlite_imports_lists_and_tells_the_history() {
    let tmp = tempfile::tempdir().unwrap();
    let catalog = Catalog::open(&sqlite_url(&tmp)).await.unwrap();
    import_and_query(&catalog, tmp.path()).await;
    // a directory that is not a run
    let err = catalog.import_dir(tmp.path()).await.unwrap_err();
    assert_eq!(err.kind(), ErrorKind::NotARun);
}

#[tokio::test]
async fn postgres_imports_lists_and_tells_the_history() {
    let Some(catalog) = postgres().await else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    import_and_query(&catalog, tmp.path()).await;
}

#[tokio::test]
async fn the_latest_outside_its_control_band_is_warned() {
    let tmp = tempfile::tempdir().unwrap();
    let catalog = Catalog::open(&sqlite_url(&tmp)).await.unwrap();
    // five earlier calibrations: a band needs MIN_BAND_POINTS (issue 25: not from fewer)
    for (i, k) in [0.3600, 0.36001, 0.35999, 0.36002, 0.36000, 0.3700]
        .iter()
        .enumerate()
    {
        let d = clone_run(
            &tmp.path().join(format!("r{i}")),
            &Spec::new("C-1", i as u32, *k),
        );
        catalog.import_dir(&d).await.unwrap();
    }
    let h = catalog.history("C-1", false).await.unwrap();
    let k = h
        .trends
        .iter()
        .find(|t| t.quantity == "scale_factor")
        .unwrap();
    assert!(k.latest_outside_band);
    assert_eq!(k.band.as_ref().unwrap().n, 5);
    assert_eq!(h.warnings.len(), 1, "{:?}", h.warnings);
    assert!(h.warnings[0].contains("Scale factor K"));
}

/// `writers` catalogs (separate pools, as separate processes would have) import overlapping
/// sets of runs at once: every run appears once, with all its steps.
async fn concurrent_writers(url: &CatalogUrl, writers: usize, root: &std::path::Path) {
    let serial = uniq("D-9");
    let dirs: Vec<PathBuf> = (0..24)
        .map(|i| clone_run(&root.join(format!("c{i}")), &Spec::new(&serial, i, 0.36)))
        .collect();
    let mut tasks = Vec::new();
    for w in 0..writers {
        let url = url.clone();
        let dirs = dirs.clone();
        tasks.push(tokio::spawn(async move {
            let catalog = Catalog::open(&url).await.unwrap();
            // each writer goes through the runs in its own order, twice
            for round in 0..2 {
                for i in 0..dirs.len() {
                    let d = &dirs[(i * (w + 1) + round) % dirs.len()];
                    catalog.import_dir(d).await.unwrap();
                }
            }
            catalog.close().await;
        }));
    }
    for t in tasks {
        t.await.unwrap();
    }
    let catalog = Catalog::open(url).await.unwrap();
    let runs = catalog
        .runs(&RunFilter {
            serial: Some(serial.clone()),
            ..RunFilter::default()
        })
        .await
        .unwrap();
    assert_eq!(runs.len(), dirs.len());
    for r in &runs {
        assert_eq!(catalog.steps(&r.run.id).await.unwrap().len(), 5);
        assert!(r.results.is_some());
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_writers_share_one_sqlite_catalog() {
    let tmp = tempfile::tempdir().unwrap();
    concurrent_writers(&sqlite_url(&tmp), 2, tmp.path()).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn four_writers_share_one_postgres_catalog() {
    let Some(catalog) = postgres().await else {
        return;
    };
    let url = catalog.url().clone();
    catalog.close().await;
    let tmp = tempfile::tempdir().unwrap();
    concurrent_writers(&url, 4, tmp.path()).await;
}

#[test]
fn an_unreachable_catalog_neither_blocks_nor_fails_the_run() {
    // a port nobody listens on (bound, then released)
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let url = CatalogUrl::parse(&format!(
        "postgres://gyrocal:pw-never-shown@127.0.0.1:{port}/lab"
    ))
    .unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let dir = clone_run(&tmp.path().join("r"), &Spec::new("E-1", 1, 0.36));
    let writer = CatalogWriter::spawn_with(
        url,
        WriterOptions {
            connect_timeout: Duration::from_millis(500),
            retry: Duration::from_millis(100),
        },
    );
    let t0 = Instant::now();
    writer.register(&dir);
    for _ in 0..100 {
        writer.step_done(&dir);
    }
    writer.finished(&dir);
    assert!(
        t0.elapsed() < Duration::from_millis(50),
        "{:?}",
        t0.elapsed()
    );
    let t1 = Instant::now();
    assert!(!writer.close(Duration::from_secs(3)));
    assert!(t1.elapsed() < Duration::from_secs(4), "{:?}", t1.elapsed());
}

#[test]
fn the_writer_brings_the_catalog_up_to_date() {
    let tmp = tempfile::tempdir().unwrap();
    let url = sqlite_url(&tmp);
    let dir = clone_run(&tmp.path().join("r"), &Spec::new("F-1", 1, 0.36));
    let writer = CatalogWriter::spawn(url.clone());
    writer.register(&dir);
    writer.step_done(&dir);
    writer.finished(&dir);
    assert!(writer.close(Duration::from_secs(20)));
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    rt.block_on(async {
        let catalog = Catalog::open(&url).await.unwrap();
        let runs = catalog.runs(&RunFilter::default()).await.unwrap();
        assert_eq!(runs.len(), 1);
        assert_eq!(runs[0].run.dut_serial.as_deref(), Some("F-1"));
    });
}

#[tokio::test]
async fn connection_errors_never_show_the_password() {
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let url =
        CatalogUrl::parse(&format!("postgres://gyrocal:hunter2@127.0.0.1:{port}/lab")).unwrap();
    let err = Catalog::open_with(
        &url,
        &gyrocal_catalog::OpenOptions {
            connect_timeout: Duration::from_millis(500),
            ..Default::default()
        },
    )
    .await
    .unwrap_err();
    assert_eq!(err.kind(), ErrorKind::Unreachable);
    let text = format!("{err} {err:?}");
    assert!(!text.contains("hunter2"), "{text}");
    assert!(text.contains("gyrocal:***@127.0.0.1"), "{text}");
}

/// A lab's catalog created by the first schema (before drift results) is migrated when a newer
/// gyrocal opens it: its calibrations stay, and new ones carry the new columns.
#[tokio::test]
async fn a_version_1_sqlite_catalog_is_migrated_and_keeps_its_calibrations() {
    let tmp = tempfile::tempdir().unwrap();
    let file = tmp.path().join("lab.sqlite");
    // schema version 1 exactly as an earlier gyrocal applied it (sqlx's own bookkeeping)
    let only_v1 = tmp.path().join("v1");
    std::fs::create_dir_all(&only_v1).unwrap();
    std::fs::copy(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/fixtures/migrations-0.1/sqlite/0001_catalog.sql"),
        only_v1.join("0001_catalog.sql"),
    )
    .unwrap();
    let opts = sqlx::sqlite::SqliteConnectOptions::new()
        .filename(&file)
        .create_if_missing(true);
    let pool = sqlx::SqlitePool::connect_with(opts).await.unwrap();
    sqlx::migrate::Migrator::new(only_v1.as_path())
        .await
        .unwrap()
        .run(&pool)
        .await
        .unwrap();
    // a calibration written under version 1
    sqlx::query(
        "INSERT INTO runs (id, directory, plan_name, plan_hash, kind, dut_serial, status, \
         started_utc, simulated, steps_total, steps_done, imported_utc) VALUES ('r1', '/runs/r1', \
         'paper', 'abc', 'scale_factor', 'OLD-1', 'complete', '2026-01-02T03:04:05Z', false, 19, \
         19, '2026-01-02T04:00:00Z')",
    )
    .execute(&pool)
    .await
    .unwrap();
    sqlx::query(
        "INSERT INTO results (run_id, scale_factor, u_scale_factor) VALUES ('r1', 0.05, 1e-5)",
    )
    .execute(&pool)
    .await
    .unwrap();
    pool.close().await;
    // a newer gyrocal opens it: migrated, the calibration still there, the new columns empty
    let url = CatalogUrl::Sqlite(file.clone());
    let catalog = Catalog::open(&url).await.unwrap();
    let cals = catalog.calibrations("OLD-1", true).await.unwrap();
    assert_eq!(cals.len(), 1);
    let r = cals[0].results.as_ref().unwrap();
    assert_eq!(r.scale_factor, Some(0.05));
    assert_eq!(r.u_scale_factor, Some(1e-5));
    assert!(r.arw_deg_rt_h.is_none());
    // and new calibrations go in beside it
    let new_run = clone_run(&tmp.path().join("new"), &Spec::new("OLD-1", 3, 0.0501));
    catalog.import_dir(&new_run).await.unwrap();
    assert_eq!(catalog.calibrations("OLD-1", true).await.unwrap().len(), 2);
    let applied: i64 = {
        let pool = sqlx::SqlitePool::connect_with(
            sqlx::sqlite::SqliteConnectOptions::new().filename(&file),
        )
        .await
        .unwrap();
        let n = sqlx::query_scalar("SELECT MAX(version) FROM _sqlx_migrations")
            .fetch_one(&pool)
            .await
            .unwrap();
        pool.close().await;
        n
    };
    assert_eq!(
        applied, 4,
        "migrated to version 4 (the series tables, then the live runs)"
    );
}

/// A catalog created by a release that kept one migrations folder per backend (up to 0.1: its
/// files are kept in tests/fixtures/migrations-0.1) opens with the one shared folder: the
/// checksums sqlx recorded then still match (no "migration was previously applied but has been
/// modified"), nothing is re-applied (the later versions are added), and its calibrations are
/// listed.
#[tokio::test]
async fn a_catalog_made_with_the_per_backend_migrations_opens() {
    let tmp = tempfile::tempdir().unwrap();
    let file = tmp.path().join("lab.sqlite");
    let old_layout = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/migrations-0.1/sqlite");
    let opts = sqlx::sqlite::SqliteConnectOptions::new()
        .filename(&file)
        .create_if_missing(true);
    let pool = sqlx::SqlitePool::connect_with(opts).await.unwrap();
    // both versions exactly as that release applied them (sqlx's own bookkeeping)
    sqlx::migrate::Migrator::new(old_layout.as_path())
        .await
        .unwrap()
        .run(&pool)
        .await
        .unwrap();
    let recorded = |pool: sqlx::SqlitePool| async move {
        let rows: Vec<(i64, Vec<u8>)> =
            sqlx::query_as("SELECT version, checksum FROM _sqlx_migrations ORDER BY version")
                .fetch_all(&pool)
                .await
                .unwrap();
        pool.close().await;
        rows
    };
    let before = recorded(pool).await;
    assert_eq!(before.len(), 2, "the old layout has versions 1 and 2");
    let old_run = clone_run(&tmp.path().join("old"), &Spec::new("LAYOUT-1", 1, 0.36));

    let url = CatalogUrl::Sqlite(file.clone());
    let catalog = Catalog::open(&url).await.unwrap();
    catalog.import_dir(&old_run).await.unwrap();
    assert_eq!(
        catalog.calibrations("LAYOUT-1", true).await.unwrap().len(),
        1
    );
    catalog.close().await;
    // opened again (listing opens existing catalogs only): no mismatch either
    let catalog = Catalog::open_existing(&url).await.unwrap();
    assert_eq!(
        catalog.calibrations("LAYOUT-1", true).await.unwrap().len(),
        1
    );
    catalog.close().await;
    let pool =
        sqlx::SqlitePool::connect_with(sqlx::sqlite::SqliteConnectOptions::new().filename(&file))
            .await
            .unwrap();
    let after = recorded(pool).await;
    assert_eq!(
        after[..before.len()],
        before[..],
        "the record of the earlier migrations is untouched"
    );
    assert_eq!(
        after.iter().map(|(v, _)| *v).collect::<Vec<_>>(),
        vec![1, 2, 3, 4],
        "only the later versions (3, the series tables; 4, the live runs) are added"
    );
}
