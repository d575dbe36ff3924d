//! Figures, not assertions (ignored by default; run with
//! `cargo test -p gyrocal-catalog --test bench -- --ignored --nocapture`): a gyro's history
//! among 10 000 calibrations (target < 100 ms) and the import of 1 000 run directories
//! (target < 10 s), on SQLite and, when GYROCAL_TEST_POSTGRES_URL is set, on PostgreSQL.

#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::time::Instant;

use common::{Spec, clone_run};
use gyrocal_catalog::{Catalog, CatalogUrl, RunFilter};

async fn catalogs(tmp: &std::path::Path) -> Vec<(String, Catalog)> {
    let mut out = vec![(
        "sqlite".to_string(),
        Catalog::open(&CatalogUrl::Sqlite(tmp.join("bench.sqlite")))
            .await
            .unwrap(),
    )];
    match std::env::var("GYROCAL_TEST_POSTGRES_URL") {
        Ok(url) => out.push((
            "postgres".to_string(),
            Catalog::open(&CatalogUrl::parse(&url).unwrap())
                .await
                .unwrap(),
        )),
        Err(_) => eprintln!("note: GYROCAL_TEST_POSTGRES_URL is not set; SQLite only"),
    }
    out
}

#[tokio::test]
#[ignore = "benchmark: prints figures"]
async fn history_among_10000_calibrations() {
    let tmp = tempfile::tempdir().unwrap();
    let template = clone_run(&tmp.path().join("t"), &Spec::new("T", 1, 0.36));
    let base = gyrocal_catalog::read_run(&template, Some("bench")).unwrap();
    let tag = std::process::id();
    for (name, catalog) in catalogs(tmp.path()).await {
        let t0 = Instant::now();
        for i in 0..10_000u32 {
            let mut rec = base.clone();
            rec.run.id = format!("bench-{tag}-{i}");
            rec.run.dut_serial = Some(format!("S{tag}-{}", i % 100));
            rec.run.started_utc = format!(
                "20{:02}-{:02}-{:02}T10:00:00.000Z",
                10 + i / 1000,
                1 + (i / 28) % 12,
                1 + i % 28
            );
            if let Some(r) = rec.results.as_mut() {
                r.scale_factor = Some(0.36 + 1e-6 * f64::from(i % 7));
            }
            catalog.upsert(&rec).await.unwrap();
        }
        let fill = t0.elapsed();
        let serial = format!("S{tag}-42");
        let mut times = Vec::new();
        for _ in 0..5 {
            let t = Instant::now();
            let h = catalog.history(&serial, true).await.unwrap();
            times.push(t.elapsed());
            assert_eq!(h.calibrations.len(), 100);
        }
        let t = Instant::now();
        let runs = catalog
            .runs(&RunFilter {
                limit: Some(50),
                ..RunFilter::default()
            })
            .await
            .unwrap();
        let list = t.elapsed();
        assert_eq!(runs.len(), 50);
        times.sort();
        println!(
            "{name}: 10 000 calibrations written in {fill:.2?}; history of one serial (100 \
             calibrations): median {:.2?}, worst {:.2?}; newest 50 runs: {list:.2?}",
            times[2], times[4]
        );
    }
}

#[tokio::test]
#[ignore = "benchmark: prints figures"]
async fn import_1000_run_directories() {
    let tmp = tempfile::tempdir().unwrap();
    let tag = std::process::id();
    let dirs: Vec<_> = (0..1000u32)
        .map(|i| {
            clone_run(
                &tmp.path().join(format!("runs/r{i}")),
                &Spec::new(&format!("I{tag}-{}", i % 50), i % 300, 0.36),
            )
        })
        .collect();
    for (name, catalog) in catalogs(tmp.path()).await {
        let t0 = Instant::now();
        for d in &dirs {
            catalog.import_dir(d).await.unwrap();
        }
        println!(
            "{name}: imported 1 000 run directories in {:.2?}",
            t0.elapsed()
        );
    }
}
