//! What an operator sees of a run, through the binary: a drift record's display (a few short
//! lines a minute, not two long ones per segment, in °/h), one clock said (the run clock
//! labelled, a time-scaled simulator's impossible ratio not shown, the stamps and the manifest
//! on one clock, a resumed session told apart from the whole run), `run.log` following the
//! steps, and `gyrocal runs` (aligned columns, a killed run told from a running one).

#![allow(clippy::unwrap_used, clippy::expect_used)] // test helpers: a panic is a failed test

mod common;

use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::{Duration, Instant};

use common::sim::Sim;
use common::{RunOutput, config, gyrocal, manifest, run_json, steps_done};

/// `H:MM:SS` or `M:SS` to seconds.
fn clock_s(text: &str) -> f64 {
    text.split(':')
        .map(|p| p.parse::<f64>().unwrap_or_else(|_| panic!("{text:?}")))
        .fold(0.0, |acc, v| acc * 60.0 + v)
}

/// A 3-hour drift plan (configs/drift.toml, its 167 segments of about 65 s) at 10 NPLC with 300
/// readings a segment: the same record's length and segments with a tenth of the readings, so
/// the virtual-time run takes seconds.
fn three_hour_drift(dir: &Path) -> PathBuf {
    let text = common::plans::config_with(
        "drift.toml",
        &[
            ("samples_per_rate = 3000", "samples_per_rate = 300"),
            ("nplc = 1", "nplc = 10"),
        ],
    );
    common::plans::write(dir, "drift3h.toml", &text)
}

/// The lines the run printed while it ran: up to the closing lines that name files (the
/// ending is the report's, and its paths are as long as the temporary directory), without the
/// plan's warnings (`gyrocal check`'s, said again before the instruments move).
fn display_lines(stderr: &str) -> Vec<&str> {
    stderr
        .lines()
        .take_while(|l| !l.starts_with("simulated table at the end"))
        .filter(|l| !l.starts_with("gyrocal: warning: "))
        .collect()
}

/// The requirement: a drift record's display is a few lines a minute of run clock, not one
/// or two per segment. Rule checked: at most one progress line per 20 s of run clock (plus the
/// header and the ending), every line under 100 columns, "segment" (never "step") for a
/// segment, the running ADEV and the bias in °/h (the simulated gyro's K is known), and the
/// noise terms at the end.
#[test]
fn a_three_hour_drift_record_prints_a_few_short_lines_a_minute_in_degrees_per_hour() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = three_hour_drift(tmp.path());
    let out = tmp.path().join("run");
    let RunOutput { code, doc, stderr } = run_json(&[&plan, &"--simulate", &"--out", &out]);
    assert_eq!(code, Some(0), "{stderr}");
    assert_eq!(doc["status"], "complete");
    let m = manifest(&out);
    let run_clock = m["elapsed_s"].as_f64().unwrap();
    assert!(run_clock > 2.5 * 3600.0, "a 3-hour record: {run_clock} s");

    let shown = display_lines(&stderr);
    let progress: Vec<&str> = shown
        .iter()
        .copied()
        .filter(|l| l.starts_with("segment "))
        .collect();
    // at most one per 20 s of run clock (the last segment's line may come sooner)
    let allowed = (run_clock / 20.0).floor() as usize + 1;
    assert!(
        progress.len() <= allowed,
        "{} progress lines for {run_clock} s of run clock (at most {allowed})",
        progress.len()
    );
    // and not per segment: 167 segments of ~65 s give one line each at most, the record
    // shows each, as its 20 s rule allows, and nothing else per segment
    let header_and_ending = 12;
    assert!(
        shown.len() <= progress.len() + header_and_ending,
        "{} lines in the display, {} of them progress:\n{}",
        shown.len(),
        progress.len(),
        shown.join("\n")
    );
    // the run clock of successive lines is 20 s apart or more
    let times: Vec<f64> = progress
        .iter()
        .map(|l| {
            let at = l.split(" at ").nth(1).unwrap();
            clock_s(at.split([',', ' ']).next().unwrap())
        })
        .collect();
    for w in times.windows(2).take(times.len().saturating_sub(2)) {
        assert!(w[1] - w[0] >= 19.5, "{} then {}", w[0], w[1]);
    }
    for l in &shown {
        assert!(
            l.chars().count() < 100,
            "{} columns: {l}",
            l.chars().count()
        );
        // one word for a segment: no "step N" in a drift record's display
        assert!(
            !l.split_whitespace()
                .collect::<Vec<_>>()
                .windows(2)
                .any(|w| w[0] == "step" && w[1].starts_with(|c: char| c.is_ascii_digit())),
            "{l}"
        );
    }
    // the running deviation and the bias in °/h, the unit said once in the header
    let late = progress[progress.len() / 2];
    assert!(
        late.contains(" · bias ") && late.contains(" · ADEV ") && late.ends_with("°/h"),
        "{late}"
    );
    assert!(
        shown.iter().any(|l| l.contains("in °/h with K = 0.3612")),
        "{}",
        shown.join("\n")
    );
    // it ends with its noise terms
    assert!(stderr.contains("result: N = "), "{stderr}");
}

/// A sweep keeps a line per step, short, with the time left on the run clock, which the run
/// says is the simulated bench's virtual time.
#[test]
fn a_sweep_prints_a_short_line_per_step_on_the_run_clock_it_names() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("run");
    let RunOutput { code, stderr, .. } =
        run_json(&[&config("quick.toml"), &"--simulate", &"--out", &out]);
    assert_eq!(code, Some(0), "{stderr}");
    let shown = display_lines(&stderr);
    for n in 1..=5 {
        let start = shown
            .iter()
            .find(|l| l.starts_with(&format!("step {n}/5 ")))
            .unwrap_or_else(|| panic!("step {n}/5 in:\n{stderr}"));
        assert!(start.ends_with("left on the run clock)"), "{start}");
        assert!(
            shown
                .iter()
                .any(|l| l.starts_with(&format!("  step {n} done: "))),
            "{stderr}"
        );
    }
    for l in &shown {
        assert!(
            l.chars().count() < 100,
            "{} columns: {l}",
            l.chars().count()
        );
    }
    assert!(
        stderr.contains("times are on the run clock: the simulated bench's virtual time"),
        "{stderr}"
    );
    assert!(
        stderr.contains("the run clock was virtual (the simulated bench, as fast as possible)"),
        "{stderr}"
    );
}

/// The `t_utc` stamps of a virtual-time run and the manifest's start and end are on one
/// clock: the stamps lie between `started_utc` and `ended_utc`, and the end follows the last
/// stamp by the stop's seconds, not by minutes either way.
#[test]
fn the_stamps_of_a_virtual_time_run_lie_within_its_manifests_start_and_end() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("run");
    // the paper plan: about 10 minutes of run clock in a few seconds
    let RunOutput { code, stderr, .. } =
        run_json(&[&config("paper.toml"), &"--simulate", &"--out", &out]);
    assert_eq!(code, Some(0), "{stderr}");
    let m = manifest(&out);
    let utc = |s: &str| gyrocal_files::parse_rfc3339_utc(s).unwrap_or_else(|| panic!("{s}"));
    let started = utc(m["started_utc"].as_str().unwrap());
    let ended = utc(m["ended_utc"].as_str().unwrap());
    let mut r = csv::Reader::from_path(out.join("samples.csv")).unwrap();
    let col = r
        .headers()
        .unwrap()
        .iter()
        .position(|c| c == "t_utc")
        .unwrap();
    let stamps: Vec<_> = r.records().map(|rec| utc(&rec.unwrap()[col])).collect();
    let (first, last) = (stamps[0], *stamps.last().unwrap());
    assert!(first >= started, "first stamp before started_utc");
    assert!(last <= ended, "last stamp after ended_utc: {m}");
    let tail = ended.duration_since(last).unwrap();
    assert!(
        tail < Duration::from_secs(60),
        "{tail:?} from the last stamp to the end"
    );
    // the end is the run clock's: started + elapsed (to the stamps' millisecond)
    let elapsed = m["elapsed_s"].as_f64().unwrap();
    let span = ended.duration_since(started).unwrap().as_secs_f64();
    assert!(
        (span - elapsed).abs() < 5.0,
        "{span} s from start to end, {elapsed} s of run clock"
    );
}

/// A resumed run's closing lines tell this session's schedule from the whole run's run clock.
#[test]
fn a_resume_tells_this_session_from_the_whole_run() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let o = gyrocal()
        .arg("run")
        .arg(config("quick.toml"))
        .args(["--simulate", "--sim-fault", "table:trip@demand3", "-o"])
        .arg(&dir)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    let first = manifest(&dir)["elapsed_s"].as_f64().unwrap();
    let o = gyrocal()
        .args(["run", "--simulate", "--resume"])
        .arg(&dir)
        .output()
        .unwrap();
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&o.stderr),
        String::from_utf8_lossy(&o.stdout)
    );
    assert!(o.status.success(), "{text}");
    let resuming = text.lines().find(|l| l.starts_with("resuming ")).unwrap();
    assert!(
        resuming.contains("the run clock goes on from"),
        "{resuming}"
    );
    assert!(text.contains("timing, this session: schedule "), "{text}");
    let whole = text
        .lines()
        .find(|l| l.contains("the whole run: "))
        .unwrap_or_else(|| panic!("no whole-run line in:\n{text}"));
    assert!(whole.contains("over 2 sessions"), "{whole}");
    let total = manifest(&dir)["elapsed_s"].as_f64().unwrap();
    assert!(total > first);
    // the stamps go on from the first session's (virtual, ahead of the wall clock): they never
    // run backwards at the resume, and they stay within the manifest's start and end
    let m = manifest(&dir);
    let utc = |s: &str| gyrocal_files::parse_rfc3339_utc(s).unwrap_or_else(|| panic!("{s}"));
    let (started, ended) = (
        utc(m["started_utc"].as_str().unwrap()),
        utc(m["ended_utc"].as_str().unwrap()),
    );
    let mut r = csv::Reader::from_path(dir.join("samples.csv")).unwrap();
    let col = r
        .headers()
        .unwrap()
        .iter()
        .position(|c| c == "t_utc")
        .unwrap();
    let stamps: Vec<_> = r.records().map(|rec| utc(&rec.unwrap()[col])).collect();
    assert!(
        stamps.windows(2).all(|w| w[0] <= w[1]),
        "t_utc runs backwards across the resume"
    );
    assert!(
        stamps[0] >= started && *stamps.last().unwrap() <= ended,
        "{m}"
    );
}

/// `tail -f run.log` follows the run: each recorded step with its number (steps.csv's
/// `step_no`, the same count) and its figures; a drift record's say "segment".
#[test]
fn run_log_records_each_step_and_segment() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("run");
    let RunOutput { code, stderr, .. } =
        run_json(&[&config("quick.toml"), &"--simulate", &"--out", &out]);
    assert_eq!(code, Some(0), "{stderr}");
    let log = std::fs::read_to_string(out.join("run.log")).unwrap();
    for n in 1..=5 {
        let line = log
            .lines()
            .find(|l| l.contains(&format!("step {n}/5 recorded")))
            .unwrap_or_else(|| panic!("step {n}/5 in:\n{log}"));
        assert!(
            line.contains(&format!("step {n}/5 recorded in steps.csv:")) && line.contains(" V"),
            "{line}"
        );
    }
    let plan = common::plans::write(tmp.path(), "drift.toml", &common::plans::drift(3, 200));
    let out = tmp.path().join("drift");
    let RunOutput { code, stderr, .. } = run_json(&[&plan, &"--simulate", &"--out", &out]);
    assert_eq!(code, Some(0), "{stderr}");
    let log = std::fs::read_to_string(out.join("run.log")).unwrap();
    for n in 1..=3 {
        assert!(log.contains(&format!("segment {n}/3 recorded")), "{log}");
    }
}

fn start_sim(plan: &Path, time_scale: &str) -> Sim {
    Sim::start(&[&"--config", &plan, &"--time-scale", &time_scale])
}

/// Against `gyrocal sim --time-scale 20` the schedule beats the instruments' physical bound:
/// the run does not print that impossible ratio, and says why.
#[test]
fn a_time_scaled_simulator_shows_no_ratio_below_one() {
    let tmp = tempfile::tempdir().unwrap();
    let sim = start_sim(&config("quick.toml"), "20");
    let out = tmp.path().join("run");
    let o = gyrocal()
        .arg("run")
        .arg(config("quick.toml"))
        .args(["--dmm-port", sim.info()["dmm_port"].as_str().unwrap()])
        .args(["--table-port", sim.info()["table"].as_str().unwrap()])
        .args(["--no-report", "--json", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(0), "{stderr}");
    let ratio = manifest(&out)["timing"]["ratio"].as_f64().unwrap();
    assert!(ratio < 1.0, "the simulator ran 20 times faster: {ratio}");
    assert!(!stderr.contains("ratio 0."), "{stderr}");
    assert!(
        stderr.contains("a time-scaled simulator? (no ratio shown)"),
        "{stderr}"
    );
    // (the ETA at the observed pace is shown exactly in virtual time by the display's own
    // test, `the_eta_follows_the_pace_the_run_keeps`: here the pace is the machine's)
}

/// The station file of bench 2 named `id`.
fn station(dir: &Path, id: &str) -> PathBuf {
    let text = common::stations::bench_2("").replace("id = \"bench-2\"", &format!("id = \"{id}\""));
    common::plans::write(dir, &format!("{id}.toml"), &text)
}

/// `gyrocal runs` lines up its columns whatever the length of a station's name.
#[test]
fn gyrocal_runs_aligns_its_columns_with_a_long_station_name() {
    let tmp = tempfile::tempdir().unwrap();
    let catalog = format!("sqlite:{}", tmp.path().join("catalog.sqlite").display());
    for (i, id) in ["b2", "the-long-named-bench-in-the-north-lab-42"]
        .iter()
        .enumerate()
    {
        let out = tmp.path().join(format!("run{i}"));
        let o = gyrocal()
            .arg("run")
            .arg(config("quick.toml"))
            .args([
                "--simulate",
                "--no-report",
                "--catalog",
                &catalog,
                "--station",
            ])
            .arg(station(tmp.path(), id))
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    let o = gyrocal()
        .args(["runs", "--catalog", &catalog])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{text}");
    let lines: Vec<&str> = text.lines().collect();
    let column = |l: &str, word: &str| l.find(word).map(|b| l[..b].chars().count());
    let sim_at = column(lines[0], "SIM").unwrap();
    let dir_at = column(lines[0], "DIRECTORY").unwrap();
    for l in &lines[1..3] {
        assert_eq!(column(l, "yes"), Some(sim_at), "{text}");
        assert_eq!(
            column(l, tmp.path().to_str().unwrap()),
            Some(dir_at),
            "{text}"
        );
    }
}

/// A run killed with SIGKILL leaves its lock: `gyrocal runs` says it is stale, naming the dead
/// process, where a live run shows its host, PID and start.
#[test]
fn gyrocal_runs_tells_a_killed_run_from_a_running_one() {
    let tmp = tempfile::tempdir().unwrap();
    let catalog = format!("sqlite:{}", tmp.path().join("catalog.sqlite").display());
    let out = tmp.path().join("run");
    // paced at 4 simulated seconds a second: about 6 s of wall time for the plan
    let mut child = gyrocal()
        .arg("run")
        .arg(config("quick.toml"))
        .args([
            "--simulate",
            "--sim-time-scale",
            "4",
            "--catalog",
            &catalog,
            "--out",
        ])
        .arg(&out)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let pid = child.id();
    let runs = || {
        let o = gyrocal()
            .args(["runs", "--catalog", &catalog])
            .output()
            .unwrap();
        String::from_utf8_lossy(&o.stdout).into_owned()
    };
    let t0 = Instant::now();
    while steps_done(&out) < 1 || !runs().contains("running") {
        assert!(t0.elapsed() < Duration::from_secs(60), "no step recorded");
        assert!(child.try_wait().unwrap().is_none(), "the run ended early");
        std::thread::sleep(Duration::from_millis(20));
    }
    let live = runs();
    assert!(
        live.contains(&format!(
            "running (host {}, pid {pid}, since ",
            gyrocal_files::rundir::host_name()
        )),
        "{live}"
    );
    child.kill().unwrap();
    child.wait().unwrap();
    let dead = runs();
    assert!(
        dead.contains(&format!("stale (process {pid} not alive on this host")),
        "{dead}"
    );
    let row = dead.lines().nth(1).unwrap();
    assert!(row.contains(" stale "), "{dead}");
}
