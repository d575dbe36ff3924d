//! A catalog that does not open when the server starts (`CatalogSource::Later`): the server
//! answers meanwhile, its gyro pages saying plainly the catalog is not reachable yet (503,
//! not an error page), and they work once it opens, without a restart. No PostgreSQL: an
//! SQLite catalog file that does not exist yet, created while the server runs (the first
//! run on a new machine does that).

#![allow(clippy::unwrap_used, clippy::expect_used)] // test helpers: a panic is a failed test

use std::time::Duration;

use axum::body::Body;
use axum::http::{Request, StatusCode};
use gyrocal_catalog::{Catalog, CatalogUrl};
use gyrocal_serve::{App, CatalogNow, CatalogSource, ServeConfig};
use http_body_util::BodyExt as _;
use tower::ServiceExt as _;

async fn get(app: &axum::Router, uri: &str) -> (StatusCode, String) {
    let req = Request::get(uri).body(Body::empty()).unwrap();
    let res = app.clone().oneshot(req).await.unwrap();
    let status = res.status();
    let body = res.into_body().collect().await.unwrap().to_bytes();
    (status, String::from_utf8_lossy(&body).into_owned())
}

#[tokio::test]
async fn a_gyro_page_says_the_catalog_is_not_reachable_yet_and_works_once_it_opens() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().join("runs");
    std::fs::create_dir(&root).unwrap();
    let url = CatalogUrl::Sqlite(tmp.path().join("later").join("catalog.sqlite"));
    let app = App::new(ServeConfig {
        roots: vec![root],
        catalog: CatalogSource::Later(url.clone()),
        catalog_url: Some(url.clone()),
        ..ServeConfig::default()
    });
    let router = app.router();
    let mut now = app.catalog_now();
    let follow = tokio::spawn(async move { app.follow_catalog().await });

    let (code, html) = get(&router, "/gyro/G-1").await;
    assert_eq!(code, StatusCode::SERVICE_UNAVAILABLE, "{html}");
    assert!(html.contains("not reachable yet"), "{html}");
    let (code, json) = get(&router, "/api/gyro/G-1").await;
    assert_eq!(code, StatusCode::SERVICE_UNAVAILABLE, "{json}");
    let doc: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert!(
        doc["error"].as_str().unwrap().contains("not reachable yet"),
        "{doc}"
    );
    let (code, dash) = get(&router, "/").await;
    assert_eq!(code, StatusCode::OK);
    assert!(dash.contains("not reachable yet"), "{dash}");

    // the catalog comes (created by a run); the server takes it at its next try
    Catalog::open(&url).await.unwrap();
    tokio::time::timeout(
        Duration::from_secs(60),
        now.wait_for(|s| matches!(s, CatalogNow::Open(_))),
    )
    .await
    .expect("the catalog was not taken within 60 s")
    .unwrap();
    let (code, html) = get(&router, "/gyro/G-1").await;
    assert_eq!(code, StatusCode::OK, "{html}");
    assert!(html.contains("Calibration history of gyro G-1"), "{html}");
    let (_, dash) = get(&router, "/").await;
    assert!(!dash.contains("not reachable yet"), "{dash}");
    // an SQLite catalog carries no other benches' runs: nothing more to follow
    tokio::time::timeout(Duration::from_secs(10), follow)
        .await
        .expect("still following an SQLite catalog")
        .unwrap();
}
