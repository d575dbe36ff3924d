//! `gyrocal serve` in a real browser (headless Chromium over WebDriver,
//! `tests/common/browser.rs`), next to simulated `gyrocal run`s: what a person watching the
//! lab's live view sees.
//!
//! - a paced run appears on the dashboard and its step count goes up there and on its page,
//!   and its plot gains points, without the page reloading (a marker set on the window
//!   survives); when it completes, its verdict shows on its page and under "finished today";
//! - a run whose process stops updating (SIGSTOP) is marked stale after `--stale-after`, and
//!   one whose process was killed (SIGKILL) is marked stale, its process named gone;
//! - at a phone's width (360 px) no page scrolls sideways;
//! - a temperature series' page draws its temperatures, a drift record's page its σ(τ), and a
//!   gyro's page (from a catalog) lists its runs.
//!
//! Without chromedriver and Chromium each test says so and passes (skips); `.ci/run` installs
//! them. With `GYROCAL_SHOTS=DIR` the tests save screenshots of what they looked at into DIR.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test helpers: a panic is a failed test

#[path = "common/browser.rs"]
mod browser;
mod common;

use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::{Duration, Instant};

use browser::{Browser, PATIENCE, Reap, Serve, Window};
use common::serve::{two_benches_and_a_view, uniq};
use common::{config, gyrocal, plans};

/// A sweep of seven rates with acceptance limits around the simulated K (0.3612 V/(°/s)):
/// a verdict once analysed.
fn sweep_plan(dir: &Path) -> PathBuf {
    sweep_plan_seeded(dir, 1)
}

/// [`sweep_plan`] with the simulated noise's `seed`.
fn sweep_plan_seeded(dir: &Path, seed: u32) -> PathBuf {
    let mut text = plans::config_with(
        "quick.toml",
        &[
            (
                "rates_dps = [0, 1, -1, 10, -10]",
                "rates_dps = [0, 1, -1, 5, -5, 10, -10]",
            ),
            (
                "name = \"Quick check (5 rates, 50 readings)\"",
                "name = \"Sweep of 7 rates, 50 readings\"",
            ),
            ("seed = 1", &format!("seed = {seed}")),
        ],
    );
    text.push_str("\n[acceptance]\n[acceptance.scale_factor]\nmin = 0.355\nmax = 0.367\n");
    let path = dir.join(format!("sweep-{seed}.toml"));
    std::fs::write(&path, text).unwrap();
    path
}

/// A temporary directory with an empty root of run directories in it (`runs`).
fn lab() -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().join("runs");
    std::fs::create_dir(&root).unwrap();
    (tmp, root)
}

/// `gyrocal run PLAN --simulate` into `out`, paced at `scale` × real time (`None`: as fast
/// as it goes), with `extra` arguments.
fn start_run(plan: &Path, out: &Path, scale: Option<f64>, extra: &[&str]) -> Reap {
    let mut c = gyrocal();
    c.arg("run")
        .arg(plan)
        .args(["--simulate", "--out"])
        .arg(out);
    if let Some(x) = scale {
        c.args(["--sim-time-scale", &x.to_string()]);
    }
    Reap(
        c.args(extra)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    )
}

/// `gyrocal run PLAN --simulate` into `out` to its end (virtual time), `extra` arguments.
fn run_to_end(plan: &Path, out: &Path, extra: &[&str]) {
    let o = gyrocal()
        .arg("run")
        .arg(plan)
        .args(["--simulate", "--out"])
        .arg(out)
        .args(extra)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// Waits for `live.json` in `dir` to record at least `steps` steps.
async fn wait_for_steps(dir: &Path, steps: u64) {
    let t0 = Instant::now();
    loop {
        let done = std::fs::read_to_string(dir.join("live.json"))
            .ok()
            .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
            .and_then(|d| d["steps_done"].as_u64())
            .unwrap_or(0);
        if done >= steps {
            return;
        }
        assert!(
            t0.elapsed() < PATIENCE * 2,
            "{}: {done} steps",
            dir.display()
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

/// Appends `v` to `seen` when it differs from the last value seen.
fn note<T: PartialEq>(seen: &mut Vec<T>, v: T) {
    if seen.last() != Some(&v) {
        seen.push(v);
    }
}

/// `n` of a step text `n/N`.
fn done_of(step: &str) -> u64 {
    step.trim()
        .split('/')
        .next()
        .and_then(|n| n.trim().parse().ok())
        .unwrap_or_else(|| panic!("a step count n/N, not {step:?}"))
}

/// Asserts `seen` holds at least three values, strictly increasing.
fn assert_grew(what: &str, seen: &[u64]) {
    assert!(seen.len() >= 3, "{what}: {seen:?}");
    assert!(seen.windows(2).all(|w| w[0] < w[1]), "{what}: {seen:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_dashboard_and_the_run_page_follow_a_paced_run_without_a_reload() {
    let (tmp, root) = lab();
    let plan = sweep_plan(tmp.path());
    let serve = Serve::start(&[&root], &[]);
    let Some(b) = Browser::start(Window::Desktop).await else {
        return;
    };

    // the dashboard, open before the run starts
    b.goto(&serve.at("/")).await;
    assert!(
        b.text("#live").await.unwrap().contains("No run is running"),
        "{:?}",
        b.text("body").await
    );
    b.set_marker().await;
    let dashboard = b.client.window().await.unwrap();

    let out = root.join("sweep-1");
    let mut run = start_run(&plan, &out, Some(1.0), &["--dut-serial", "SIM-42"]);
    let row = "#running tr.run[data-run='sweep-1']";

    // the run appears on the open dashboard by itself
    let t0 = Instant::now();
    while b.count(row).await == 0 {
        assert!(t0.elapsed() < PATIENCE, "{:?}", b.text("#live").await);
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    assert!(b.text(row).await.unwrap().contains("SIM-42"));

    // the run's page in a second window
    let page = b.client.new_window(false).await.unwrap().handle;
    b.client.switch_to_window(page.clone()).await.unwrap();
    b.goto(&serve.at("/run/0/sweep-1")).await;
    b.set_marker().await;

    let (mut dash_steps, mut page_steps, mut points, mut circles) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut shot_dashboard = Browser::shot("dashboard-running");
    let mut shot_page = Browser::shot("run-page-mid-run");
    let t0 = Instant::now();
    loop {
        assert!(
            t0.elapsed() < PATIENCE * 4,
            "the run did not complete: dashboard {dash_steps:?}, page {page_steps:?}, \
             points {points:?}"
        );
        b.client.switch_to_window(dashboard.clone()).await.unwrap();
        if let Some(step) = b.text(&format!("{row} td.step")).await {
            note(&mut dash_steps, done_of(&step));
            if dash_steps.len() >= 3 && shot_dashboard.is_some() {
                b.screenshot(shot_dashboard.take().as_deref()).await;
            }
        }
        b.client.switch_to_window(page.clone()).await.unwrap();
        if let Some(step) = b.text("#step").await {
            note(&mut page_steps, done_of(&step));
        }
        note(&mut points, b.data_points("plot-volts").await.unwrap_or(0));
        note(&mut circles, b.count("#plot-volts svg circle").await);
        if points.len() >= 4 && shot_page.is_some() {
            b.screenshot(shot_page.take().as_deref()).await;
        }
        if b.text("#status")
            .await
            .is_some_and(|s| s.starts_with("complete"))
        {
            break;
        }
        tokio::time::sleep(Duration::from_millis(150)).await;
    }
    let _ = run.0.wait();

    // it grew in front of the reader, and no page was reloaded to show it
    assert_grew("the dashboard's step count", &dash_steps);
    assert_grew("the run page's step count", &page_steps);
    assert_grew("the plot's points (data-points)", &points);
    assert_grew("the plot's drawn points (circles)", &circles);
    assert_eq!(points.last(), Some(&7), "{points:?}");
    assert!(b.marker_kept().await, "the run page was reloaded");

    // the verdict on the run page once the analysis wrote it (the page follows the manifest)
    let t0 = Instant::now();
    loop {
        let v = b.text("#verdict").await.unwrap_or_default();
        if v.contains("PASS") || v.contains("pass") {
            break;
        }
        assert!(t0.elapsed() < PATIENCE, "no verdict on the page: {v:?}");
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    assert!(b.count("#plot-residuals svg").await == 1, "the residuals");
    b.client
        .set_window_size(1280, 2200)
        .await
        .unwrap_or_else(|e| panic!("window size: {e}"));
    b.screenshot(Browser::shot("run-page-complete").as_deref())
        .await;
    assert!(b.marker_kept().await, "the run page was reloaded");

    // and on the dashboard: finished today, with its verdict; nothing running
    b.client.switch_to_window(dashboard.clone()).await.unwrap();
    let finished = "#finished tr.run[data-run='sweep-1']";
    let t0 = Instant::now();
    loop {
        let text = b.text(finished).await.unwrap_or_default();
        if text.contains("PASS") || text.contains("pass") {
            break;
        }
        assert!(
            t0.elapsed() < PATIENCE,
            "not finished with a verdict: {:?}",
            b.text("#live").await
        );
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    assert!(b.text("#live").await.unwrap().contains("Running now (0)"));
    assert!(b.marker_kept().await, "the dashboard was reloaded");
    b.close().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_run_whose_process_hangs_or_was_killed_is_marked_stale_without_a_reload() {
    use nix::sys::signal::{Signal, kill};
    use nix::unistd::Pid;

    let (tmp, root) = lab();
    let plan = sweep_plan(tmp.path());
    let serve = Serve::start(&[&root], &["--stale-after", "3"]);
    let Some(b) = Browser::start(Window::Desktop).await else {
        return;
    };
    let out = root.join("hung-1");
    let mut run = start_run(&plan, &out, Some(0.5), &[]);
    wait_for_steps(&out, 1).await;

    b.goto(&serve.at("/")).await;
    b.set_marker().await;
    let dashboard = b.client.window().await.unwrap();
    let page = b.client.new_window(false).await.unwrap().handle;
    b.client.switch_to_window(page.clone()).await.unwrap();
    b.goto(&serve.at("/run/0/hung-1")).await;
    b.set_marker().await;
    assert!(!b.text("#status").await.unwrap().contains("STALE"));

    // the process stops (as a hung one does): no update for 3 s is stale
    let pid = Pid::from_raw(i32::try_from(run.0.id()).unwrap());
    kill(pid, Signal::SIGSTOP).unwrap();
    let stale_seen = |what: &str| what.contains("STALE");
    let t0 = Instant::now();
    loop {
        b.client.switch_to_window(page.clone()).await.unwrap();
        let status = b.text("#status").await.unwrap_or_default();
        b.client.switch_to_window(dashboard.clone()).await.unwrap();
        let stale = b.text("#stale").await.unwrap_or_default();
        if stale_seen(&status) && stale.contains("hung-1") {
            assert!(status.contains("no update since"), "{status}");
            break;
        }
        assert!(
            t0.elapsed() < PATIENCE,
            "not stale: page {status:?}, dashboard {:?}",
            b.text("#live").await
        );
        tokio::time::sleep(Duration::from_millis(250)).await;
    }
    b.screenshot(Browser::shot("dashboard-stale").as_deref())
        .await;

    // killed: its process is named gone
    kill(pid, Signal::SIGKILL).unwrap();
    let _ = run.0.wait();
    let t0 = Instant::now();
    loop {
        b.client.switch_to_window(page.clone()).await.unwrap();
        let status = b.text("#status").await.unwrap_or_default();
        if status.contains("is gone") {
            assert!(status.contains(&pid.to_string()), "{status}");
            break;
        }
        assert!(t0.elapsed() < PATIENCE, "not gone: {status:?}");
        tokio::time::sleep(Duration::from_millis(250)).await;
    }
    b.client.switch_to_window(dashboard.clone()).await.unwrap();
    let t0 = Instant::now();
    while !b
        .text("#stale")
        .await
        .unwrap_or_default()
        .contains("is gone")
    {
        assert!(t0.elapsed() < PATIENCE, "{:?}", b.text("#live").await);
        tokio::time::sleep(Duration::from_millis(250)).await;
    }
    assert!(b.marker_kept().await, "the dashboard was reloaded");
    b.client.switch_to_window(page).await.unwrap();
    assert!(b.marker_kept().await, "the run page was reloaded");
    b.close().await;
}

/// The document's width against the window's, in CSS px: `(scrollWidth, innerWidth)`.
async fn widths(b: &Browser) -> (u64, u64) {
    let w = b
        .js(
            "return [document.documentElement.scrollWidth, window.innerWidth];",
            vec![],
        )
        .await;
    (w[0].as_u64().unwrap(), w[1].as_u64().unwrap())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn at_a_phones_width_no_page_scrolls_sideways() {
    let Some(b) = Browser::start(Window::Phone).await else {
        return;
    };
    let (tmp, root) = lab();
    let plan = sweep_plan(tmp.path());
    let catalog = format!("sqlite:{}", tmp.path().join("catalog.sqlite").display());
    // a finished run with a long name and a serial (in the catalog, for its gyro page, whose
    // table is the widest), and one running (paced)
    run_to_end(
        &plan,
        &root.join("sweep-with-a-rather-long-run-directory-name-2026-12-07T06-30-00Z"),
        &[
            "--dut-serial",
            "SIM-42-LONG-SERIAL-NUMBER",
            "--catalog",
            &catalog,
        ],
    );
    let running = start_run(&plan, &root.join("sweep-running"), Some(1.0), &[]);
    wait_for_steps(&root.join("sweep-running"), 1).await;
    let serve = Serve::start(&[&root], &[&format!("--catalog={catalog}")]);
    for (path, shot) in [
        (
            "/gyro/SIM-42-LONG-SERIAL-NUMBER?include_simulated=1",
            "phone-gyro",
        ),
        ("/", "phone-dashboard"),
        ("/run/0/sweep-running", "phone-run-page"),
        (
            "/run/0/sweep-with-a-rather-long-run-directory-name-2026-12-07T06-30-00Z",
            "phone-run-complete",
        ),
    ] {
        b.goto(&serve.at(path)).await;
        if path.starts_with("/gyro/") {
            // the page with its table, not a page saying there is none
            let text = b.js("return document.body.innerText;", vec![]).await;
            let text = text.as_str().unwrap_or_default();
            assert!(text.contains("1 complete calibration"), "{text}");
        }
        let (scroll, inner) = widths(&b).await;
        assert!(inner <= 360, "the window is a phone's: {inner} px");
        assert!(
            scroll <= 360,
            "{path}: the page is {scroll} px wide at a window of {inner} px"
        );
        b.screenshot(Browser::shot(shot).as_deref()).await;
    }
    // the plots fit the width too (scaled, not cut)
    let plot_w = b
        .js(
            "var s = document.querySelector('#plot-volts svg'); \
             return s ? s.getBoundingClientRect().width : 0;",
            vec![],
        )
        .await
        .as_f64()
        .unwrap();
    assert!(plot_w > 200.0 && plot_w <= 360.0, "{plot_w}");
    b.js(
        "document.getElementById('plot-volts').scrollIntoView(); return true;",
        vec![],
    )
    .await;
    b.screenshot(Browser::shot("phone-run-plots").as_deref())
        .await;
    b.close().await;
    drop(running);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_series_draws_its_temperatures_a_drift_record_its_allan_curve_and_a_gyro_its_runs() {
    let Some(b) = Browser::start(Window::Size(1280, 2000)).await else {
        return;
    };
    let (tmp, root) = lab();
    let catalog = format!("sqlite:{}", tmp.path().join("catalog.sqlite").display());
    for i in 1..=2 {
        run_to_end(
            &sweep_plan_seeded(tmp.path(), i),
            &root.join(format!("sweep-{i}")),
            &["--dut-serial", "SIM-7", "--catalog", &catalog],
        );
    }
    run_to_end(&config("series.toml"), &root.join("series-1"), &[]);
    // a drift record of 12 segments of 200 readings
    let drift = tmp.path().join("drift.toml");
    std::fs::write(
        &drift,
        plans::config_with(
            "drift.toml",
            &[
                ("samples_per_rate = 3000", "samples_per_rate = 200"),
                ("repeat = 167", "repeat = 12"),
            ],
        ),
    )
    .unwrap();
    run_to_end(&drift, &root.join("drift-1"), &[]);

    let serve = Serve::start(&[&root], &[&format!("--catalog={catalog}")]);

    b.goto(&serve.at("/run/0/series-1")).await;
    let temps = b
        .js(
            "var f = document.getElementById('plot-temps'); \
             return f ? [Number(f.getAttribute('data-points')), \
                         f.querySelectorAll('svg polyline, svg path').length, \
                         f.getBoundingClientRect().height] : null;",
            vec![],
        )
        .await;
    assert!(
        temps.is_array(),
        "no temperature plot: {:?}",
        b.text("#live").await
    );
    assert!(temps[0].as_u64().unwrap() >= 10, "{temps}");
    assert!(temps[1].as_u64().unwrap() >= 3, "three lines: {temps}");
    assert!(temps[2].as_f64().unwrap() > 200.0, "drawn: {temps}");
    assert!(
        b.text("#plot-temps figcaption")
            .await
            .unwrap()
            .contains("readings of the chamber")
    );
    b.screenshot(Browser::shot("series-run-page").as_deref())
        .await;

    b.goto(&serve.at("/run/0/drift-1")).await;
    let allan = b.data_points("plot-allan").await.unwrap_or(0);
    assert!(
        allan >= 3,
        "σ(τ) points: {allan}, {:?}",
        b.text("#live").await
    );
    b.screenshot(Browser::shot("drift-run-page").as_deref())
        .await;

    b.goto(&serve.at("/gyro/SIM-7?include_simulated=1")).await;
    let body = b.text("body").await.unwrap();
    assert!(body.contains("SIM-7"), "{body}");
    let rows = b.count("table tr").await;
    assert!(rows >= 3, "two runs listed: {rows} rows in\n{body}");
    b.screenshot(Browser::shot("gyro-page").as_deref()).await;
    b.close().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_benches_runs_on_one_postgres_catalog_show_on_a_third_processs_dashboard() {
    let Some(url) = common::postgres_url() else {
        return;
    };
    let Some(b) = Browser::start(Window::Desktop).await else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let plan = sweep_plan(tmp.path());
    let [root_a, root_b, view] = two_benches_and_a_view(tmp.path());
    // the view: the catalog only, no roots, in a directory without `runs`
    let serve = Serve::start_in(Some(&view), &[], &[&format!("--catalog={url}")]);
    b.goto(&serve.at("/")).await;
    b.set_marker().await;

    let names = [uniq("bench-a-sweep"), uniq("bench-b-sweep")];
    let mut runs: Vec<Reap> = [(&root_a, &names[0], "SIM-A"), (&root_b, &names[1], "SIM-B")]
        .into_iter()
        .map(|(root, name, serial)| {
            start_run(
                &plan,
                &root.join(name),
                Some(1.0),
                &["--catalog", &url, "--dut-serial", serial],
            )
        })
        .collect();

    // both grow on the open dashboard, then both are finished with a verdict
    let mut steps: [Vec<u64>; 2] = [Vec::new(), Vec::new()];
    let mut shot = Browser::shot("dashboard-two-benches");
    let t0 = Instant::now();
    loop {
        let mut finished = 0;
        for (i, name) in names.iter().enumerate() {
            let running = format!("#running tr.run[data-run='{name}'] td.step");
            if let Some(step) = b.text(&running).await {
                note(&mut steps[i], done_of(&step));
            }
            let ended = b
                .text(&format!("#finished tr.run[data-run='{name}']"))
                .await
                .unwrap_or_default();
            if ended.contains("PASS") || ended.contains("pass") {
                finished += 1;
            }
        }
        if steps.iter().all(|s| s.len() >= 2) && shot.is_some() {
            b.screenshot(shot.take().as_deref()).await;
        }
        if finished == 2 {
            break;
        }
        assert!(
            t0.elapsed() < PATIENCE * 4,
            "steps seen {steps:?}; the dashboard: {:?}",
            b.text("#live").await
        );
        tokio::time::sleep(Duration::from_millis(150)).await;
    }
    for r in &mut runs {
        assert!(r.0.wait().unwrap().success());
    }
    for (name, seen) in names.iter().zip(&steps) {
        assert_grew(&format!("{name}'s step count on the dashboard"), seen);
        let row = b
            .text(&format!("#finished tr.run[data-run='{name}']"))
            .await
            .unwrap();
        assert!(row.contains("7/7"), "{row}");
        // no longer running (other benches' runs on the same catalog may be)
        let running = format!("#running tr.run[data-run='{name}']");
        assert_eq!(b.count(&running).await, 0, "{:?}", b.text("#live").await);
    }
    assert!(b.marker_kept().await, "the dashboard was reloaded");

    // the run page of one, through its link on the dashboard: a run known through the catalog
    let href = b
        .js(
            "return document.querySelector(arguments[0]).getAttribute('href');",
            vec![serde_json::json!(format!(
                "#finished tr.run[data-run='{}'] a[href^='/live/']",
                names[0]
            ))],
        )
        .await;
    let href = href
        .as_str()
        .unwrap_or_else(|| panic!("no /live/ link: {href}"));
    assert!(href.ends_with(&format!("/{}", names[0])), "{href}");
    b.goto(&serve.at(href)).await;
    let body = b.text("body").await.unwrap_or_default();
    assert!(body.contains(&names[0]), "{body}");
    assert_eq!(b.count("#steps tr.steprow").await, 7, "{body}");
    assert!(
        b.text("#step").await.unwrap_or_default().contains("7/7"),
        "{body}"
    );
    b.screenshot(Browser::shot("live-run-page").as_deref())
        .await;
    b.close().await;
}
