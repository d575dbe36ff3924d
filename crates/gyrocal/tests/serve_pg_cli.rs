//! The live view across benches through the binary: runs publish their live state to the
//! PostgreSQL catalog (`live_runs`, `NOTIFY gyrocal_live`) and a `gyrocal serve --catalog`
//! with no roots shows them growing and ending with their verdicts (when
//! GYROCAL_TEST_POSTGRES_URL is set); a run against a catalog that never answers finishes in
//! the same virtual time with every step, the failure said once; `gyrocal run --serve` prints
//! its page and the page answers during the run; the station's `serve` key prints the lab
//! view's page of the run; a view whose connection to the catalog is cut mid-run listens
//! again and catches up; a view prunes the catalog's old live rows at its start; a view
//! started while its catalog does not answer serves at once and takes the catalog (the other
//! benches' runs, the gyro pages) once it answers.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test helpers: a panic is a failed test

mod common;

use std::collections::HashMap;
use std::io::{BufRead as _, BufReader};
use std::path::Path;
use std::process::Stdio;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use common::serve::{
    Events, Reap, Relay, api_runs, get, port_in, try_get, two_benches_and_a_view, uniq,
};
use common::{config, gyrocal, plans, stations};

/// The quick plan with acceptance limits, so its end has a verdict.
fn quick_with_acceptance(dir: &Path) -> std::path::PathBuf {
    let text = std::fs::read_to_string(config("quick.toml")).unwrap()
        + "\n[acceptance]\ndecision_rule = \"simple\"\n[acceptance.scale_factor]\nmin = -1000\nmax = 1000\n";
    plans::write(dir, "quick-acceptance.toml", &text)
}

/// The lines a child writes on stderr, collected by a thread of their own.
fn collect_stderr(child: &mut std::process::Child) -> Arc<Mutex<Vec<String>>> {
    let lines = Arc::new(Mutex::new(Vec::new()));
    let sink = lines.clone();
    let err = child.stderr.take().unwrap();
    std::thread::spawn(move || {
        for line in BufReader::new(err).lines() {
            let Ok(line) = line else { break };
            sink.lock().unwrap().push(line);
        }
    });
    lines
}

#[test]
fn serve_on_the_catalog_shows_two_benches_runs_growing_and_ending_with_their_verdicts() {
    let Some(url) = common::postgres_url() else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let plan = quick_with_acceptance(tmp.path());
    let [root_a, root_b, empty] = two_benches_and_a_view(tmp.path());
    let names = [uniq("bench-a-run"), uniq("bench-b-run")];

    // the view: the catalog only, no roots (its working directory has no `runs`)
    let mut view = gyrocal();
    view.current_dir(&empty)
        .args(["serve", "--catalog", &url, "--port", "0"]);
    let (_serve, _, port) = common::serve::start(view);
    let events = Events::start(port);
    // the listener is up once the view answers (it LISTENs before reading the rows)
    std::thread::sleep(Duration::from_millis(500));

    let runs: Vec<Reap> = [(&root_a, &names[0]), (&root_b, &names[1])]
        .into_iter()
        .map(|(root, name)| {
            Reap(
                gyrocal()
                    .arg("run")
                    .arg(&plan)
                    .args(["--simulate", "--sim-time-scale", "4", "--catalog", &url])
                    .arg("--out")
                    .arg(root.join(name))
                    .stdout(Stdio::null())
                    .stderr(Stdio::null())
                    .spawn()
                    .unwrap(),
            )
        })
        .collect();

    let mut seen: HashMap<String, Vec<u64>> = HashMap::new();
    let mut ended: HashMap<String, serde_json::Value> = HashMap::new();
    let t0 = Instant::now();
    while ended.len() < 2 {
        assert!(
            t0.elapsed() < Duration::from_secs(240),
            "seen {seen:?}, ended {ended:?}"
        );
        for r in api_runs(port) {
            let name = r["key"]["name"].as_str().unwrap_or("").to_string();
            if !names.contains(&name) {
                continue;
            }
            // a run known through the catalog: its host in the key, its page under /live
            assert!(r["key"]["host"].is_string(), "{r}");
            let n = r["steps_done"].as_u64().unwrap();
            let counts = seen.entry(name.clone()).or_default();
            if counts.last() != Some(&n) {
                counts.push(n);
            }
            if r["status"] == "complete" && !r["verdict"].is_null() {
                ended.insert(name, r);
            }
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    for name in &names {
        let counts = &seen[name];
        assert!(counts.len() >= 3, "{name}: {counts:?}");
        assert!(counts.windows(2).all(|w| w[0] < w[1]), "{name}: {counts:?}");
        let r = &ended[name];
        assert_eq!(
            (r["steps"].as_u64(), r["steps_done"].as_u64()),
            (Some(5), Some(5))
        );
        assert!(
            ["pass", "marginal", "indeterminate", "fail"].contains(&r["verdict"].as_str().unwrap()),
            "{r}"
        );
        // when it started and ended, from the run's state in the row (no directory here)
        let (started, end) = (
            r["started_utc"].as_str().unwrap(),
            r["ended_utc"].as_str().unwrap(),
        );
        assert!(started.ends_with('Z') && started <= end, "{r}");
        // its page, from the catalog's row
        let (status, html) = get(port, r["href"].as_str().unwrap());
        assert!(status.contains("200"), "{status}");
        assert!(html.contains(name.as_str()), "{html}");
        assert!(html.contains(started), "the start not on the page: {html}");
    }
    // the event stream carried each run's updates (a notification per update)
    let text = events.text();
    for name in &names {
        let n = text.matches(name.as_str()).count();
        assert!(n >= 3, "{name} in {n} events: {text}");
    }
    for mut r in runs {
        assert!(r.0.wait().unwrap().success());
    }
}

/// A "PostgreSQL" that accepts connections and never says a word.
fn silent_server() -> u16 {
    let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = l.local_addr().unwrap().port();
    std::thread::spawn(move || {
        let mut held = Vec::new();
        for c in l.incoming() {
            held.push(c);
        }
    });
    port
}

#[test]
fn a_run_against_a_catalog_that_never_answers_finishes_the_same_and_says_it_once() {
    let tmp = tempfile::tempdir().unwrap();
    let silent = format!("postgres://gyrocal@127.0.0.1:{}/lab", silent_server());
    let mut docs = Vec::new();
    for (name, catalog) in [("off", "off"), ("silent", silent.as_str())] {
        let out = tmp.path().join(name);
        let o = gyrocal()
            .arg("run")
            .arg(config("quick.toml"))
            .args(["--simulate", "--json", "--catalog", catalog, "--out"])
            .arg(&out)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let doc: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        docs.push((out, doc));
    }
    let (off, silent_doc) = (&docs[0].1, &docs[1].1);
    for doc in [off, silent_doc] {
        assert_eq!(doc["status"], "complete", "{doc}");
        assert_eq!(doc["steps_done"], 5, "{doc}");
        // a catalog that never answers keeps the run's safe end: the table confirmed at rest
        assert_eq!(doc["table"]["at_rest"], true, "{doc}");
    }
    // the run clock (virtual) is the same to the microsecond: the catalog cost it nothing
    let (a, b) = (
        off["elapsed_s"].as_f64().unwrap(),
        silent_doc["elapsed_s"].as_f64().unwrap(),
    );
    assert!(
        (a - b).abs() < 1e-6,
        "elapsed {a} s without a catalog, {b} s with a silent one"
    );
    // the live state's failure said once in the run's log, not at every step
    let log = std::fs::read_to_string(docs[1].0.join("run.log")).unwrap();
    let said = log
        .matches("the live state cannot reach the catalog")
        .count();
    assert_eq!(said, 1, "{log}");
}

#[test]
fn run_serve_prints_the_run_page_which_answers_during_the_run() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("runs").join("served-1");
    let mut run = Reap(
        gyrocal()
            .arg("run")
            .arg(config("quick.toml"))
            .args(["--simulate", "--sim-time-scale", "2", "--serve", "--out"])
            .arg(&out)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap(),
    );
    let lines = collect_stderr(&mut run.0);
    let t0 = Instant::now();
    let page_line = loop {
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "{:?}",
            lines.lock().unwrap()
        );
        if let Some(l) = lines
            .lock()
            .unwrap()
            .iter()
            .find(|l| l.starts_with("live view: "))
        {
            break l.clone();
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    assert!(
        page_line.starts_with("live view: http://127.0.0.1:")
            && page_line.ends_with("/run/0/served-1"),
        "{page_line}"
    );
    let port = port_in(&page_line);
    let path = &page_line[page_line.find("/run/").unwrap()..];
    // the page answers while the run goes on, and the run's state shows through it
    let mut statuses = Vec::new();
    loop {
        assert!(t0.elapsed() < Duration::from_secs(120), "{statuses:?}");
        // the server ends with the run: under load the run may end between two looks
        let Some((status, html)) = try_get(port, path) else {
            break;
        };
        assert!(status.contains("200"), "{status}");
        assert!(html.contains("served-1"), "{html}");
        let Some((_, api)) = try_get(port, "/api/run/0/served-1") else {
            break;
        };
        let doc: serde_json::Value = serde_json::from_str(&api).unwrap();
        let st = doc["status"].as_str().unwrap_or("").to_string();
        if statuses.last() != Some(&st) {
            statuses.push(st.clone());
        }
        if st == "complete" {
            break;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    assert_eq!(
        statuses.first().map(String::as_str),
        Some("running"),
        "{statuses:?}"
    );
    assert!(run.0.wait().unwrap().success());
    assert_eq!(common::manifest(&out)["status"], "complete");
    // the in-process view changes nothing of the run's end: the table is said to be at rest
    // (the reader thread may still be draining the pipe: give it a moment)
    let t1 = Instant::now();
    let said = loop {
        let said = lines.lock().unwrap().join("\n");
        if said.contains("at rest") || t1.elapsed() > Duration::from_secs(10) {
            break said;
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    assert!(said.contains("at rest"), "{said}");
}

#[test]
fn the_station_serve_key_prints_the_lab_views_page_of_the_run() {
    let tmp = tempfile::tempdir().unwrap();
    let station = tmp.path().join("station.toml");
    std::fs::write(
        &station,
        stations::bench_2("serve = \"http://lab-view:8737\"\n"),
    )
    .unwrap();
    let out = tmp.path().join("station-run-1");
    let o = gyrocal()
        .arg("run")
        .arg(config("quick.toml"))
        .args(["--simulate", "--station"])
        .arg(&station)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    let host = gyrocal_files::rundir::host_name();
    let expected = format!("live view: http://lab-view:8737/live/{host}/station-run-1");
    assert!(
        err.lines().any(|l| l.starts_with(&expected)),
        "{expected:?} not in:\n{err}"
    );
}

#[test]
fn run_serve_with_a_bad_address_is_refused_before_anything_starts() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("never");
    let o = gyrocal()
        .arg("run")
        .arg(config("quick.toml"))
        .args(["--simulate", "--serve", "0.0.0.0:0", "--out"])
        .arg(&out)
        .env_remove("GYROCAL_SERVE_TOKEN")
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("--serve") && err.contains("token"), "{err}");
    assert!(!out.exists());
}

/// The run named `name` in `/api/runs`, if shown.
fn run_named(port: u16, name: &str) -> Option<serde_json::Value> {
    api_runs(port)
        .into_iter()
        .find(|r| r["key"]["name"].as_str() == Some(name))
}

#[test]
fn a_view_whose_catalog_connection_is_cut_mid_run_listens_again_and_catches_up() {
    let Some(url) = common::postgres_url() else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let plan = quick_with_acceptance(tmp.path());
    let [root, _, empty] = two_benches_and_a_view(tmp.path());
    let name = uniq("cut-run");
    // the view reaches the catalog through a relay the test cuts; the run reaches it directly
    let relay = Relay::to(&url);
    let mut view = gyrocal();
    view.current_dir(&empty)
        .args(["serve", "--catalog", &relay.url, "--port", "0"]);
    let (_serve, _, port) = common::serve::start(view);
    let events = Events::start(port);
    std::thread::sleep(Duration::from_millis(500));
    let mut run = Reap(
        gyrocal()
            .arg("run")
            .arg(&plan)
            .args(["--simulate", "--sim-time-scale", "2", "--catalog", &url])
            .arg("--out")
            .arg(root.join(&name))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    // the view follows the run: a step recorded
    let t0 = Instant::now();
    let before = loop {
        assert!(
            t0.elapsed() < Duration::from_secs(120),
            "{:?}",
            run_named(port, &name)
        );
        if let Some(r) = run_named(port, &name).filter(|r| r["steps_done"].as_u64() >= Some(1)) {
            break r;
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    assert_eq!(before["status"], "running", "{before}");
    // the connection is lost (every socket shut, new ones refused) for 4 s: longer than the
    // view's wait before it tries again, while the run goes on
    relay.cut();
    let heard_at_cut = events.text().len();
    std::thread::sleep(Duration::from_secs(4));
    relay.restore();
    // the view listens again by itself: the run's newest state, its end and verdict, reach it
    let t0 = Instant::now();
    let end = loop {
        assert!(
            t0.elapsed() < Duration::from_secs(180),
            "before the cut {before}, now {:?}",
            run_named(port, &name)
        );
        if let Some(r) =
            run_named(port, &name).filter(|r| r["status"] == "complete" && !r["verdict"].is_null())
        {
            break r;
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    assert_eq!(
        (end["steps"].as_u64(), end["steps_done"].as_u64()),
        (Some(5), Some(5)),
        "{end}"
    );
    assert!(run.0.wait().unwrap().success());
    // after the cut the pages were told to read everything again (what was missed), and
    // the run's own updates came as events again
    let after = events.text()[heard_at_cut..].to_string();
    assert!(after.contains("{\"all\":true}"), "{after}");
    assert!(after.contains(name.as_str()), "{after}");
}

#[test]
fn a_view_prunes_the_catalogs_old_live_rows_at_its_start() {
    use gyrocal_catalog::{Catalog, CatalogUrl, LIVE_KEEP_ENDED, LIVE_KEEP_SILENT, LiveRow};
    let Some(url) = common::postgres_url() else {
        return;
    };
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let catalog = rt
        .block_on(Catalog::open(&CatalogUrl::parse(&url).unwrap()))
        .unwrap();
    let now = std::time::SystemTime::now();
    let day = Duration::from_secs(86_400);
    let row = |name: &str, status: &str, age: Duration| LiveRow {
        run_id: uniq(name),
        host: "old-bench".into(),
        station_id: None,
        dut_serial: Some("SIM-OLD".into()),
        plan_name: "quick".into(),
        kind: "scale_factor".into(),
        phase: "done".into(),
        step: 5,
        steps: 5,
        steps_done: 5,
        eta_s: None,
        last_reading_v: None,
        running_mean_v: None,
        table_state: None,
        status: status.into(),
        verdict: None,
        updated_utc: gyrocal_files::rfc3339_utc(now - age),
        state_json: "{}".into(),
    };
    let old = [
        row("ended-long-ago", "complete", LIVE_KEEP_ENDED + day),
        row("silent-for-a-week", "running", LIVE_KEEP_SILENT + day),
    ];
    let recent = row("ended-an-hour-ago", "complete", Duration::from_secs(3600));
    for r in old.iter().chain([&recent]) {
        rt.block_on(catalog.publish_live(r)).unwrap();
    }
    let rows_of = |r: &LiveRow| rt.block_on(catalog.live_runs(Some(&r.run_id))).unwrap();
    // no check that they are there before the view starts: another test's view (the same
    // binary) on the same database may prune them first, which shows the binary prunes too

    let tmp = tempfile::tempdir().unwrap();
    let mut view = gyrocal();
    view.current_dir(tmp.path())
        .args(["serve", "--catalog", &url, "--port", "0"]);
    let (_serve, _, port) = common::serve::start(view);
    let t0 = Instant::now();
    while old.iter().any(|r| !rows_of(r).is_empty()) {
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "not pruned: {:?}",
            old.iter().map(|r| rows_of(r).len()).collect::<Vec<_>>()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    assert_eq!(rows_of(&recent).len(), 1, "a recent row pruned");
    // and the view shows the recent one, not the pruned ones
    let t0 = Instant::now();
    while run_named(port, &recent.run_id).is_none() {
        assert!(
            t0.elapsed() < Duration::from_secs(30),
            "{:?}",
            api_runs(port)
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    for r in &old {
        assert!(run_named(port, &r.run_id).is_none(), "{} shown", r.run_id);
    }
}

/// `url` with `password` in it (`postgres://USER:PASSWORD@...`), unless it carries one.
fn with_password(url: &str, password: &str) -> String {
    let (scheme, rest) = url.split_once("://").unwrap();
    let (user, host) = rest.split_once('@').unwrap();
    if user.contains(':') {
        return url.to_string();
    }
    format!("{scheme}://{user}:{password}@{host}")
}

#[test]
fn a_view_started_before_its_catalog_answers_serves_at_once_and_takes_the_catalog_when_it_does() {
    use gyrocal_catalog::{Catalog, CatalogUrl};
    let Some(url) = common::postgres_url() else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let plan = quick_with_acceptance(tmp.path());
    let [root, _, empty] = two_benches_and_a_view(tmp.path());
    let name = uniq("late-catalog-run");
    let serial = uniq("G-LATE");
    // the view reaches the catalog through a relay that refuses until restored (PostgreSQL
    // not up yet at boot); its URL carries the password, which must show nowhere
    let relay = Relay::to(&url);
    relay.cut();
    let password = std::env::var("PGPASSWORD").ok().filter(|p| p.len() >= 6);
    let view_url = match &password {
        Some(pw) => with_password(&relay.url, pw),
        None => relay.url.clone(),
    };
    let mut view = Reap(
        gyrocal()
            .current_dir(&empty)
            .args(["serve", "--catalog", &view_url, "--port", "0"])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap(),
    );
    let said = collect_stderr(&mut view.0);
    let mut line = String::new();
    BufReader::new(view.0.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let port = port_in(&line);

    // a run publishes to the catalog itself meanwhile
    let mut run = Reap(
        gyrocal()
            .arg("run")
            .arg(&plan)
            .args(["--simulate", "--sim-time-scale", "4", "--catalog", &url])
            .args(["--dut-serial", &serial, "--out"])
            .arg(root.join(&name))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let catalog = rt
        .block_on(Catalog::open(&CatalogUrl::parse(&url).unwrap()))
        .unwrap();
    let t0 = Instant::now();
    while rt
        .block_on(catalog.live_runs(Some(&name)))
        .unwrap()
        .is_empty()
    {
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "the run never published"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    // the view answers, without the catalog: no run of it, and a gyro page that says why
    assert!(
        api_runs(port).iter().all(|r| !r["key"]["host"].is_string()),
        "{:?}",
        api_runs(port)
    );
    let (status, html) = get(port, &format!("/gyro/{serial}"));
    assert!(status.contains("503"), "{status}");
    assert!(html.contains("not reachable yet"), "{html}");
    let (_, dash) = get(port, "/");
    assert!(dash.contains("not reachable yet"), "{dash}");

    // the catalog answers: the run appears, and its gyro's page works
    relay.restore();
    let t0 = Instant::now();
    while run_named(port, &name).is_none() {
        assert!(
            t0.elapsed() < Duration::from_secs(150),
            "the run never appeared: {:?}; the view said {:?}",
            api_runs(port),
            said.lock().unwrap()
        );
        std::thread::sleep(Duration::from_millis(200));
    }
    let r = run_named(port, &name).unwrap();
    assert!(
        r["key"]["host"].is_string(),
        "known through the catalog: {r}"
    );
    let (status, html) = get(port, &format!("/gyro/{serial}"));
    assert!(status.contains("200"), "{status}: {html}");
    assert!(html.contains(serial.as_str()), "{html}");
    // and once the run has ended (indexed in the catalog), the gyro's page lists it
    assert!(run.0.wait().unwrap().success());
    let t0 = Instant::now();
    loop {
        let (status, html) = get(port, &format!("/gyro/{serial}?include_simulated=1"));
        assert!(status.contains("200"), "{status}");
        if html.contains("1 complete calibration") {
            break;
        }
        assert!(t0.elapsed() < Duration::from_secs(30), "{html}");
        std::thread::sleep(Duration::from_millis(200));
    }
    // said once each: not answering yet, then answering; never the password
    let text = said.lock().unwrap().join("\n");
    assert_eq!(text.matches("does not answer yet").count(), 1, "{text}");
    assert_eq!(text.matches("answers: gyro pages on").count(), 1, "{text}");
    if let Some(pw) = &password {
        assert!(!text.contains(pw.as_str()), "{text}");
        for path in ["/", "/api/runs", &format!("/gyro/{serial}")] {
            assert!(!get(port, path).1.contains(pw.as_str()), "{path}");
        }
    }
}
