//! What a browser gets from the server, in-process (tower's `oneshot`, no socket): the
//! dashboard's running, stale and finished runs; path traversal refused whatever its form;
//! hostile text escaped; the catalog's password never shown; the token enforced.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test helpers: a panic is a failed test

use std::path::Path;
use std::time::{Duration, SystemTime};

use axum::body::Body;
use axum::http::{Request, StatusCode, header};
use gyrocal_run::live::{LIVE_JSON, LiveState, StepSummary, write_live};
use gyrocal_serve::{App, ServeConfig};
use http_body_util::BodyExt as _;
use tower::ServiceExt as _;

const SECRET: &str = "TOPSECRET-not-for-the-web";
const HOSTILE_SERIAL: &str = "<script>alert('serial')</script>";
const HOSTILE_PLAN: &str = "\"><img src=x onerror=alert(1)>";

fn now_utc() -> String {
    gyrocal_files::rfc3339_utc(SystemTime::now())
}

fn live(run_id: &str, serial: &str, plan: &str, steps_done: usize) -> LiveState {
    LiveState {
        format: 1,
        run_id: run_id.into(),
        station: Some("bench-2".into()),
        gyro_serial: Some(serial.into()),
        plan_name: plan.into(),
        plan_kind: "scale_factor".into(),
        phase: "acquiring".into(),
        step: steps_done + 1,
        steps: 19,
        steps_done,
        eta_s: Some(125.0),
        last_reading_v: Some(0.123_456_7),
        running_mean_v: Some(0.123_4),
        table: Some("settling at +10.0000 °/s (demand +10.0000 °/s)".into()),
        step_summaries: (0..steps_done)
            .map(|i| StepSummary {
                number: i + 1,
                rate_dps: 10.0 * i as f64 - 50.0,
                volts: 0.01 * (10.0 * i as f64 - 50.0) + 0.001,
                volts_std: Some(1e-5),
                n: 100,
                overloads: 0,
                t_end_s: 10.0 * i as f64,
            })
            .collect(),
        status: "running".into(),
        reason: None,
        verdict: None,
        chamber: None,
        adev_v: Vec::new(),
        started_utc: None,
        ended_utc: None,
        pid: std::process::id(),
        hostname: gyrocal_files::rundir::host_name(),
        updated_utc: now_utc(),
    }
}

fn manifest(dir: &Path, status: &str, serial: &str, plan: &str, verdict: Option<&str>) {
    let mut m = serde_json::json!({
        "status": status,
        "plan": { "name": plan, "kind": "scale_factor" },
        "dut": { "serial": serial },
        "started_utc": now_utc(),
        "updated_utc": now_utc(),
        "steps_total": 5,
        "steps_done": [0, 1, 2, 3, 4],
    });
    if status != "running" {
        m["ended_utc"] = now_utc().into();
    }
    if let Some(v) = verdict {
        m["acceptance"] = serde_json::json!({ "verdict": v, "rule": "simple" });
    }
    std::fs::write(dir.join("manifest.json"), m.to_string()).unwrap();
}

/// A pid that was a process and is not one any more.
fn dead_pid() -> u32 {
    let mut child = std::process::Command::new("true").spawn().unwrap();
    let pid = child.id();
    child.wait().unwrap();
    pid
}

/// root/: a running run, a finished one (pass), a stale one (its writer is gone), a hostile
/// one; outside the root: a secret file and a run directory reached by a symlink.
fn lab() -> (tempfile::TempDir, std::path::PathBuf) {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().join("runs");
    std::fs::create_dir(&root).unwrap();
    std::fs::write(tmp.path().join("secret.txt"), SECRET).unwrap();

    let running = root.join("paper-running");
    std::fs::create_dir(&running).unwrap();
    manifest(&running, "running", "G-100", "paper", None);
    write_live(
        &running.join(LIVE_JSON),
        &live("paper-running", "G-100", "paper", 7),
    )
    .unwrap();

    let done = root.join("paper-done");
    std::fs::create_dir(&done).unwrap();
    manifest(&done, "complete", "G-200", "paper", Some("pass"));
    std::fs::write(
        done.join("steps.csv"),
        "step_no,pass_no,rate_dps,volts,volts_std,n,overloads,t_end_s\n1,1,-10,-0.1,1e-5,100,0,5\n2,1,10,0.1,1e-5,100,0,10\n",
    )
    .unwrap();
    std::fs::write(
        done.join("report.html"),
        "<html><body>CERTIFICATE G-200</body></html>",
    )
    .unwrap();
    // a symlink inside a run directory pointing at the secret
    std::os::unix::fs::symlink(tmp.path().join("secret.txt"), done.join("leak.txt")).unwrap();

    let stale = root.join("drift-stale");
    std::fs::create_dir(&stale).unwrap();
    manifest(&stale, "running", "G-300", "drift", None);
    let mut l = live("drift-stale", "G-300", "drift", 3);
    l.pid = dead_pid();
    write_live(&stale.join(LIVE_JSON), &l).unwrap();

    let old = root.join("paper-silent");
    std::fs::create_dir(&old).unwrap();
    manifest(&old, "running", "G-400", "paper", None);
    let mut l = live("paper-silent", "G-400", "paper", 2);
    l.updated_utc = gyrocal_files::rfc3339_utc(SystemTime::now() - Duration::from_secs(3600));
    write_live(&old.join(LIVE_JSON), &l).unwrap();

    let hostile = root.join("hostile");
    std::fs::create_dir(&hostile).unwrap();
    manifest(&hostile, "running", HOSTILE_SERIAL, HOSTILE_PLAN, None);
    write_live(
        &hostile.join(LIVE_JSON),
        &live("hostile", HOSTILE_SERIAL, HOSTILE_PLAN, 1),
    )
    .unwrap();

    // a run directory outside the root, reached through a symlink in it
    let outside = tmp.path().join("outside-run");
    std::fs::create_dir(&outside).unwrap();
    manifest(&outside, "complete", "G-OUT", "outside", Some("pass"));
    std::fs::write(outside.join("report.html"), SECRET).unwrap();
    std::os::unix::fs::symlink(&outside, root.join("linked")).unwrap();
    (tmp, root)
}

fn app(root: &Path) -> axum::Router {
    App::new(ServeConfig {
        roots: vec![root.to_path_buf()],
        ..ServeConfig::default()
    })
    .router()
}

async fn get(app: &axum::Router, uri: &str) -> (StatusCode, String) {
    get_with(app, Request::get(uri).body(Body::empty()).unwrap()).await
}

async fn get_with(app: &axum::Router, req: Request<Body>) -> (StatusCode, String) {
    let res = app.clone().oneshot(req).await.unwrap();
    let status = res.status();
    let body = res.into_body().collect().await.unwrap().to_bytes();
    (status, String::from_utf8_lossy(&body).into_owned())
}

#[tokio::test]
async fn the_dashboard_shows_the_running_run_the_finished_one_with_its_verdict_and_the_stale_ones()
{
    let (_tmp, root) = lab();
    let app = app(&root);
    let (code, html) = get(&app, "/").await;
    assert_eq!(code, StatusCode::OK);
    // the running run: its phase, step n/N, ETA, last reading, table
    let running = html.split("<h2>Stale").next().unwrap();
    assert!(running.contains("paper-running"), "{html}");
    assert!(running.contains("acquiring"));
    assert!(running.contains(">7/19<"), "{running}");
    assert!(running.contains("0:02:05"), "ETA 125 s: {running}");
    assert!(running.contains("0.123457 V"));
    assert!(running.contains("settling at +10.0000"));
    // stale: the one whose process is gone, the one silent for an hour; not among the running
    assert!(!running.contains("drift-stale") && !running.contains("paper-silent"));
    let stale = html
        .split("<h2>Stale")
        .nth(1)
        .unwrap()
        .split("<h2>Finished")
        .next()
        .unwrap();
    assert!(
        stale.contains("drift-stale") && stale.contains("is gone"),
        "{stale}"
    );
    assert!(
        stale.contains("paper-silent") && stale.contains("no update since"),
        "{stale}"
    );
    // finished today, with its verdict
    let finished = html.split("<h2>Finished today").nth(1).unwrap();
    assert!(finished.contains("paper-done") && finished.contains("G-200"));
    assert!(finished.contains(">pass<"), "{finished}");
    // the page updates itself: its script over the event stream
    assert!(html.contains("/live.js") && html.contains("data-part=\"/part/dashboard\""));
    let (_, js) = get(&app, "/live.js").await;
    assert!(js.contains("EventSource('/api/events')"));

    // the API says the same
    let (code, json) = get(&app, "/api/runs").await;
    assert_eq!(code, StatusCode::OK);
    let doc: serde_json::Value = serde_json::from_str(&json).unwrap();
    let runs = doc["runs"].as_array().unwrap();
    let by = |name: &str| {
        runs.iter()
            .find(|r| r["key"]["name"] == name)
            .unwrap()
            .clone()
    };
    assert_eq!(by("paper-running")["steps_done"], 7);
    assert_eq!(by("paper-running")["stale"], false);
    assert_eq!(by("drift-stale")["stale"], true);
    assert_eq!(by("paper-done")["verdict"], "pass");
    // the symlinked run outside the root is not a run of this root
    assert!(runs.iter().all(|r| r["key"]["name"] != "linked"));
}

#[tokio::test]
async fn a_run_page_has_its_steps_its_plot_with_the_fit_line_and_its_report() {
    let (_tmp, root) = lab();
    let app = app(&root);
    let (code, html) = get(&app, "/run/0/paper-running").await;
    assert_eq!(code, StatusCode::OK);
    assert_eq!(html.matches("class=\"steprow\"").count(), 7);
    assert!(
        html.contains("id=\"plot-volts\" data-points=\"7\""),
        "{html}"
    );
    assert!(
        html.contains("least squares: K = "),
        "a fit line through 7 points"
    );
    assert!(html.contains("id=\"plot-residuals\" data-points=\"7\""));
    // a finished run without live.json: steps.csv's rows, and its own report
    let (_, html) = get(&app, "/run/0/paper-done").await;
    assert_eq!(html.matches("class=\"steprow\"").count(), 2, "{html}");
    assert!(html.contains("/run/0/paper-done/report.html"));
    let (code, report) = get(&app, "/run/0/paper-done/report.html").await;
    assert_eq!(code, StatusCode::OK);
    assert!(report.contains("CERTIFICATE G-200"));
    let (_, api) = get(&app, "/api/run/0/paper-running").await;
    let doc: serde_json::Value = serde_json::from_str(&api).unwrap();
    assert_eq!(doc["step_summaries"].as_array().unwrap().len(), 7);
}

#[tokio::test]
async fn path_traversal_in_every_form_is_refused_and_never_serves_the_file() {
    let (_tmp, root) = lab();
    let app = app(&root);
    for uri in [
        "/run/0/..",
        "/run/0/../files/secret.txt",
        "/run/0/%2e%2e/files/secret.txt",
        "/run/0/%2E%2E/report.html",
        "/run/0/paper-done/files/..%2f..%2fsecret.txt",
        "/run/0/paper-done/files/%2e%2e%2f%2e%2e%2fsecret.txt",
        "/run/0/%2Ftmp/files/secret.txt",
        "/run/0/paper-done/files/%2Fetc%2Fpasswd",
        "/run/0//etc/passwd",
        "/run/0/paper-done/files/leak.txt",
        "/run/0/linked",
        "/run/0/linked/report.html",
        "/api/run/0/linked",
        "/run/0/paper-done/files/.%2e",
        "/run/9/paper-done",
        "/run/0/paper-done%00/report.html",
        "/../../secret.txt",
        "/%2e%2e/%2e%2e/secret.txt",
    ] {
        let (code, body) = get(&app, uri).await;
        assert!(
            code == StatusCode::NOT_FOUND || code == StatusCode::BAD_REQUEST,
            "{uri}: {code}"
        );
        assert!(!body.contains(SECRET), "{uri} served the secret");
        assert!(!body.contains("root:"), "{uri} served /etc/passwd");
    }
    // a real file of a run is served, as text
    let (code, body) = get(&app, "/run/0/paper-done/files/steps.csv").await;
    assert_eq!(code, StatusCode::OK);
    assert!(body.starts_with("step_no,"));
}

#[tokio::test]
async fn a_hostile_serial_and_plan_name_are_shown_as_text_never_as_markup() {
    let (_tmp, root) = lab();
    let app = app(&root);
    for uri in [
        "/",
        "/part/dashboard",
        "/run/0/hostile",
        "/part/run/0/hostile",
    ] {
        let (code, html) = get(&app, uri).await;
        assert_eq!(code, StatusCode::OK, "{uri}");
        assert!(!html.contains("<script>alert"), "{uri}: {html}");
        assert!(!html.contains("<img src=x"), "{uri}");
        assert!(
            html.contains("&lt;script&gt;alert(&#39;serial&#39;)&lt;/script&gt;"),
            "{uri}"
        );
        assert!(
            html.contains("&quot;&gt;&lt;img src=x onerror=alert(1)&gt;"),
            "{uri}"
        );
    }
}

#[tokio::test]
async fn the_catalog_password_never_reaches_a_page_or_an_answer() {
    let (_tmp, root) = lab();
    let url =
        gyrocal_catalog::CatalogUrl::parse("postgres://lab:hunter2-pw@db.lab/gyrocal").unwrap();
    let app = App::new(ServeConfig {
        roots: vec![root.clone()],
        catalog_url: Some(url),
        ..ServeConfig::default()
    })
    .router();
    let (_, json) = get(&app, "/api/runs").await;
    assert!(json.contains("db.lab"), "the catalog is named: {json}");
    for uri in [
        "/",
        "/api/runs",
        "/part/dashboard",
        "/gyro/G-200",
        "/api/gyro/G-200",
    ] {
        let (_, body) = get(&app, uri).await;
        assert!(!body.contains("hunter2"), "{uri}: {body}");
    }
}

#[tokio::test]
async fn with_a_token_every_request_needs_it_as_a_header_or_the_login_cookie() {
    let (_tmp, root) = lab();
    let token = "a-long-enough-token-123";
    let app = App::new(ServeConfig {
        roots: vec![root.clone()],
        token: Some(token.into()),
        ..ServeConfig::default()
    })
    .router();
    for uri in [
        "/",
        "/api/runs",
        "/run/0/paper-done/report.html",
        "/api/events",
    ] {
        let (code, body) = get(&app, uri).await;
        assert_eq!(code, StatusCode::UNAUTHORIZED, "{uri}");
        assert!(
            !body.contains("paper-done") && !body.contains("CERTIFICATE"),
            "{uri}"
        );
    }
    let (code, _) = get(&app, "/login?token=wrong-token-xxxxxxx").await;
    assert_eq!(code, StatusCode::UNAUTHORIZED);
    let (code, html) = get_with(
        &app,
        Request::get("/")
            .header(header::AUTHORIZATION, format!("Bearer {token}"))
            .body(Body::empty())
            .unwrap(),
    )
    .await;
    assert_eq!(code, StatusCode::OK);
    assert!(html.contains("paper-running"));
    // the login link sets a cookie that then opens the pages
    let res = app
        .clone()
        .oneshot(
            Request::get(format!("/login?token={token}"))
                .body(Body::empty())
                .unwrap(),
        )
        .await
        .unwrap();
    assert!(res.status().is_redirection());
    let cookie = res.headers()[header::SET_COOKIE]
        .to_str()
        .unwrap()
        .to_string();
    assert!(cookie.contains("HttpOnly") && cookie.contains("SameSite=Strict"));
    let pair = cookie.split(';').next().unwrap().to_string();
    let (code, _) = get_with(
        &app,
        Request::get("/api/runs")
            .header(header::COOKIE, pair)
            .body(Body::empty())
            .unwrap(),
    )
    .await;
    assert_eq!(code, StatusCode::OK);
}

#[tokio::test]
async fn a_non_loopback_address_without_a_token_is_refused_at_start() {
    let public: std::net::SocketAddr = "0.0.0.0:0".parse().unwrap();
    let e = gyrocal_serve::bind(public, None).await.unwrap_err();
    assert_eq!(e.kind(), gyrocal_serve::ServeErrorKind::NoToken);
    assert!(e.to_string().contains("token"), "{e}");
    // a short token is no token
    assert!(gyrocal_serve::check_bind(&public, Some("short")).is_err());
    assert!(gyrocal_serve::check_bind(&public, Some("a-long-enough-token-123")).is_ok());
    let local: std::net::SocketAddr = "127.0.0.1:0".parse().unwrap();
    assert!(gyrocal_serve::bind(local, None).await.is_ok());
}

#[tokio::test]
async fn a_long_uri_and_a_post_are_refused() {
    let (_tmp, root) = lab();
    let app = app(&root);
    let long = format!("/run/0/{}", "a".repeat(5000));
    let (code, _) = get(&app, &long).await;
    assert_eq!(code, StatusCode::URI_TOO_LONG);
    let (code, _) = get_with(
        &app,
        Request::post("/api/runs")
            .body(Body::from(vec![b'x'; 100_000]))
            .unwrap(),
    )
    .await;
    assert!(code.is_client_error(), "{code}");
}
