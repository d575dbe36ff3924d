//! `gyrocal serve` through the binary, next to a paced simulated `gyrocal run`: the run's
//! `live.json` grows step by step, the server's `/api/runs` shows the run and its step count
//! growing, its event stream delivers a change; a public address without a token, and a
//! catalog URL that does not parse, are refused before anything listens.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test helpers: a panic is a failed test

mod common;

use std::io::{Read as _, Write as _};
use std::net::TcpStream;
use std::process::Stdio;
use std::time::{Duration, Instant};

use common::serve::{Reap, get};
use common::{config, gyrocal};

/// The run `name`'s entry in `/api/runs`.
fn run_in_api(port: u16, name: &str) -> Option<serde_json::Value> {
    let (status, body) = get(port, "/api/runs");
    assert!(status.contains("200"), "{status}");
    let doc: serde_json::Value = serde_json::from_str(&body).ok()?;
    doc["runs"]
        .as_array()?
        .iter()
        .find(|r| r["key"]["name"] == name)
        .cloned()
}

#[test]
fn serve_shows_a_paced_run_growing_and_its_event_stream_says_so() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().join("runs");
    std::fs::create_dir(&root).unwrap();
    let out = root.join("quick-1");

    // the server first, on any free port; its first line names the URL
    let mut view = gyrocal();
    view.args(["serve", "--no-catalog", "--port", "0", "--root"])
        .arg(&root);
    let (_serve, line, port) = common::serve::start(view);
    assert!(
        line.starts_with("gyrocal serve: http://127.0.0.1:"),
        "{line}"
    );

    // a listener on the event stream before the run starts
    let mut events = TcpStream::connect(("127.0.0.1", port)).unwrap();
    events
        .set_read_timeout(Some(Duration::from_secs(60)))
        .unwrap();
    write!(
        events,
        "GET /api/events HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n"
    )
    .unwrap();

    let _run = Reap(
        gyrocal()
            .arg("run")
            .arg(config("quick.toml"))
            .args(["--simulate", "--sim-time-scale", "4", "--out"])
            .arg(&out)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );

    // the run's live.json and the server's answer both grow, step by step
    let t0 = Instant::now();
    let mut seen_file = Vec::new();
    let mut seen_api = Vec::new();
    loop {
        assert!(
            t0.elapsed() < Duration::from_secs(120),
            "live.json {seen_file:?}, /api/runs {seen_api:?}"
        );
        if let Ok(text) = std::fs::read_to_string(out.join("live.json"))
            && let Ok(doc) = serde_json::from_str::<serde_json::Value>(&text)
        {
            let n = doc["steps_done"].as_u64().unwrap();
            if seen_file.last() != Some(&n) {
                seen_file.push(n);
            }
        }
        if let Some(r) = run_in_api(port, "quick-1") {
            let n = r["steps_done"].as_u64().unwrap();
            if seen_api.last() != Some(&n) {
                seen_api.push(n);
            }
            if r["status"] == "complete" {
                assert_eq!(r["steps"], 5);
                assert_eq!(n, 5);
                break;
            }
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    // seen growing: at least three different counts, in increasing order, while it ran
    for seen in [&seen_file, &seen_api] {
        assert!(seen.len() >= 3, "{seen:?}");
        assert!(seen.windows(2).all(|w| w[0] < w[1]), "{seen:?}");
    }
    // the run page has the steps
    let (status, html) = get(port, "/run/0/quick-1");
    assert!(status.contains("200"), "{status}");
    assert_eq!(html.matches("class=\"steprow\"").count(), 5);

    // the event stream delivered the run's change
    let mut got = String::new();
    let mut buf = [0u8; 4096];
    while !got.contains("event: run") || !got.contains("quick-1") {
        let n = events.read(&mut buf).unwrap();
        assert!(n > 0, "the event stream closed: {got}");
        got.push_str(&String::from_utf8_lossy(&buf[..n]));
    }
    assert!(got.contains("text/event-stream"), "{got}");
}

#[test]
fn serve_on_a_public_address_without_a_token_is_refused() {
    let o = gyrocal()
        .args(["serve", "--no-catalog", "--bind", "0.0.0.0", "--port", "0"])
        .env_remove("GYROCAL_SERVE_TOKEN")
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("token"), "{err}");
    assert!(o.stdout.is_empty(), "nothing was served");
}

#[test]
fn a_catalog_url_that_does_not_parse_is_refused_at_once_naming_where_it_came_from() {
    // waiting cannot mend a bad URL: refused before anything listens, unlike a catalog that
    // does not answer (tried again in the background)
    let by_flag = gyrocal()
        .args([
            "serve",
            "--port",
            "0",
            "--catalog",
            "mysql://lab:hunter2@db/gyro",
        ])
        .output()
        .unwrap();
    let by_env = gyrocal()
        .args(["serve", "--port", "0"])
        .env("GYROCAL_CATALOG", "pg://lab:hunter2@db/gyro")
        .output()
        .unwrap();
    for (o, names) in [(by_flag, "--catalog"), (by_env, "$GYROCAL_CATALOG")] {
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{err}");
        assert!(err.contains(names), "{err}");
        assert!(!err.contains("hunter2"), "{err}");
        assert!(o.stdout.is_empty(), "nothing was served");
    }
}
