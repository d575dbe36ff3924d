//! The README's commands, run as a newcomer would type them, and the EXAMPLES section of every
//! `--help` and man page.
//!
//! The rule: every command a user should type is in a ```sh block of README.md or
//! configs/README.md (inline code spans in the prose are references, such as `gyrocal run
//! --resume DIR`; of those only the subcommand is checked). Each line of a ```sh block (a
//! trailing `\` joins lines, `&&` separates commands, comment lines are skipped) is one
//! command, and each command is either
//!
//! - in [`EXPECTED`], by its exact text: it is run in README order, in one temporary directory
//!   holding a copy of `configs/`, by `sh` with a temporary `HOME` and none of the user's
//!   gyrocal variables, `gyrocal` being this build's binary; its exit code, words and files are
//!   checked. A command naming the real ports `/dev/ttyUSB0` (the meter) and `/dev/ttyUSB1`
//!   (the table) gets the pseudo-terminals of a `gyrocal sim` instead, never a real port;
//! - a `cargo` command, which CI runs anyway (`.ci/run`); `cargo run … -p gyrocal -- ARGS` is
//!   run here as `gyrocal ARGS`, and so is a path to a built binary (`target/…/gyrocal ARGS`);
//! - or in [`NOT_RUN`], the small allowlist, with the reason.
//!
//! A command in a README that none of these covers fails the test, naming the file and line;
//! so does an entry of [`EXPECTED`] or [`NOT_RUN`] that no README uses any more.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a panic is a failed test

mod common;

use std::io::{BufRead as _, BufReader, Read as _};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use serde_json::Value;

/// How a README command is checked.
#[derive(Debug, Clone, Copy)]
enum Check {
    /// Runs to its end: this exit code, these words in stdout or stderr, these files (relative
    /// to the working directory; `~/` is the temporary home).
    Ends {
        code: i32,
        says: &'static [&'static str],
        creates: &'static [&'static str],
    },
    /// A run on the instruments: interrupted (SIGINT, as Ctrl-C) once its first step has
    /// started; it must exit 130 saying the table is at rest.
    CtrlCAfterFirstStep,
    /// A server that runs until Ctrl-C (`gyrocal sim`): its first line is the JSON with the
    /// ports; after SIGINT it exits 0 and its last line says the table is stopped.
    ServesUntilCtrlC,
}

const fn ends(code: i32, says: &'static [&'static str], creates: &'static [&'static str]) -> Check {
    Check::Ends {
        code,
        says,
        creates,
    }
}

/// Every command the READMEs give (after the rewrite of `cargo run … --` and built-binary
/// paths to `gyrocal …`), with what it must do. Words checked are ones that stay true when the
/// wording of a message is improved: instruments' identities, file names, "at rest".
const EXPECTED: &[(&str, Check)] = &[
    // README: the first screen
    (
        "gyrocal run configs/paper.toml --simulate",
        ends(0, &["at rest"], &[]),
    ),
    // README: first calibration on real instruments
    (
        "mkdir -p ~/.local/share/bash-completion/completions",
        ends(0, &[], &["~/.local/share/bash-completion/completions"]),
    ),
    (
        "gyrocal completions bash > ~/.local/share/bash-completion/completions/gyrocal",
        ends(
            0,
            &[],
            &["~/.local/share/bash-completion/completions/gyrocal"],
        ),
    ),
    (
        "gyrocal man -o ~/.local/share/man/man1",
        ends(
            0,
            &[],
            &[
                "~/.local/share/man/man1/gyrocal.1",
                "~/.local/share/man/man1/gyrocal-run.1",
            ],
        ),
    ),
    (
        "cp configs/paper.toml my-gyro.toml",
        ends(0, &[], &["my-gyro.toml"]),
    ),
    ("gyrocal check my-gyro.toml", ends(0, &["19 steps"], &[])),
    (
        "gyrocal check my-gyro.toml --probe --dmm-port /dev/ttyUSB0 --table-port /dev/ttyUSB1",
        ends(0, &["34401A", "ACUTROL"], &[]),
    ),
    (
        "gyrocal run my-gyro.toml --simulate --dut-serial HRG-0042 -o runs/rehearsal",
        ends(
            0,
            &["at rest"],
            &["runs/rehearsal/report.html", "runs/rehearsal/fit.json"],
        ),
    ),
    (
        "gyrocal run my-gyro.toml --simulate --sim-fault table:trip@demand3 -o runs/tripped",
        ends(
            1,
            &["--resume runs/tripped", "at rest"],
            &["runs/tripped/manifest.json"],
        ),
    ),
    (
        "gyrocal run --resume runs/tripped --simulate",
        ends(0, &["at rest"], &["runs/tripped/report.html"]),
    ),
    (
        "gyrocal run my-gyro.toml --dmm-port /dev/ttyUSB0 --table-port /dev/ttyUSB1 --dut-serial HRG-0042",
        Check::CtrlCAfterFirstStep,
    ),
    (
        "gyrocal report runs/rehearsal runs/tripped -o both.html",
        ends(0, &[], &["both.html"]),
    ),
    // README: plans
    (
        "gyrocal check configs/ieee.toml",
        ends(0, &["12 steps"], &[]),
    ),
    // README: instruments
    (
        "gyrocal sim --time-scale 50 --seed 7",
        Check::ServesUntilCtrlC,
    ),
    // README: drift and Allan
    (
        "gyrocal run configs/drift.toml --simulate -o runs/drift",
        ends(
            0,
            &["at rest"],
            &["runs/drift/allan.json", "runs/drift/allan.html"],
        ),
    ),
    (
        "gyrocal allan runs/drift --estimator mdev --taus decade -o mdev.html",
        ends(0, &[], &["mdev.html"]),
    ),
    // README: temperature series
    (
        "gyrocal check configs/series.toml",
        ends(0, &["temperature"], &[]),
    ),
    (
        "gyrocal run configs/series.toml --simulate -o runs/series",
        ends(
            0,
            &["in control: confirmed", "at rest"],
            &[
                "runs/series/series.json",
                "runs/series/series.html",
                "runs/series/temps.csv",
            ],
        ),
    ),
    // README: records and catalog
    (
        "gyrocal verify runs/rehearsal runs/drift",
        ends(0, &["samples.csv", "allan.json"], &[]),
    ),
    (
        "gyrocal report runs/rehearsal --acceptance configs/acceptance.example.toml -o judged.html",
        ends(0, &[], &["judged.html"]),
    ),
    (
        "gyrocal catalog rebuild runs",
        ends(0, &[], &["~/.local/share/gyrocal/catalog.sqlite"]),
    ),
    (
        "gyrocal runs --serial HRG-0042",
        ends(0, &["HRG-0042"], &[]),
    ),
    (
        "gyrocal history HRG-0042 --include-simulated -o history.html",
        ends(0, &[], &["history.html"]),
    ),
    // README: other commands
    (
        "gyrocal fit runs/rehearsal/steps.csv --model linear,quadratic",
        ends(0, &["quadratic"], &[]),
    ),
];

/// Commands not run here, and why.
const NOT_RUN: &[(&str, &str)] = &[(
    "sudo usermod -aG dialout $USER",
    "changes the system's groups (needs root); nothing of gyrocal runs",
)];

/// One command of a ```sh block.
#[derive(Debug, Clone)]
struct Line {
    /// `README.md:42`
    place: String,
    text: String,
}

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The commands of every ```sh block of `file` (relative to the repository).
fn sh_commands(file: &str) -> Vec<Line> {
    let text = std::fs::read_to_string(repo().join(file)).unwrap();
    let mut out = Vec::new();
    let mut in_sh = false;
    let mut pending: Option<(usize, String)> = None;
    for (i, raw) in text.lines().enumerate() {
        let trimmed = raw.trim();
        if trimmed.starts_with("```") {
            in_sh = !in_sh && trimmed == "```sh";
            continue;
        }
        if !in_sh {
            continue;
        }
        let (start, mut joined) = pending.take().unwrap_or((i + 1, String::new()));
        let code = strip_comment(trimmed);
        if let Some(head) = code.strip_suffix('\\') {
            joined.push_str(head.trim_end());
            joined.push(' ');
            pending = Some((start, joined));
            continue;
        }
        joined.push_str(code);
        for part in joined.split("&&") {
            let part = part.trim();
            if !part.is_empty() {
                out.push(Line {
                    place: format!("{file}:{start}"),
                    text: part.to_string(),
                });
            }
        }
    }
    out
}

/// The line without a trailing `# comment` (a `#` at the start of a word, outside quotes).
fn strip_comment(line: &str) -> &str {
    let mut quote = None;
    let mut prev = ' ';
    for (i, c) in line.char_indices() {
        match (quote, c) {
            (None, '\'' | '"') => quote = Some(c),
            (Some(q), _) if c == q => quote = None,
            (None, '#') if prev.is_whitespace() => return line[..i].trim_end(),
            _ => {}
        }
        prev = c;
    }
    line.trim_end()
}

/// A command as this test runs it: `cargo run … -- ARGS` and `path/to/gyrocal ARGS` become
/// `gyrocal ARGS`; `None` for the other `cargo` commands (CI runs them).
fn as_run(text: &str) -> Option<String> {
    let words: Vec<&str> = text.split_whitespace().collect();
    match words.first() {
        Some(&"cargo") => {
            let is_run = words.get(1) == Some(&"run");
            let dashes = words.iter().position(|w| *w == "--");
            match (is_run, dashes) {
                (true, Some(at)) => Some(format!("gyrocal {}", words[at + 1..].join(" "))),
                _ => None,
            }
        }
        Some(program) if program.ends_with("/gyrocal") => {
            Some(format!("gyrocal {}", words[1..].join(" ")))
        }
        _ => Some(words.join(" ")),
    }
}

/// A `gyrocal sim` standing in for the instruments on `/dev/ttyUSB0` and `/dev/ttyUSB1`.
struct Bench {
    child: Child,
    lines: mpsc::Receiver<String>,
    dmm: String,
    table: String,
}

impl Bench {
    fn start() -> Bench {
        let mut child = common::gyrocal()
            .args(["sim", "--time-scale", "50", "--seed", "7"])
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let lines = line_channel(child.stdout.take().unwrap());
        let first = lines
            .recv_timeout(Duration::from_secs(20))
            .expect("gyrocal sim's line with its ports");
        let info: Value = serde_json::from_str(&first).unwrap();
        let path = |key: &str| info[key].as_str().unwrap().to_string();
        Bench {
            dmm: path("dmm"),
            table: path("table"),
            child,
            lines,
        }
    }

    /// Ctrl-C; the simulator's last line (the instruments' final state).
    fn stop(mut self) -> Value {
        interrupt(&self.child);
        let last = self
            .lines
            .recv_timeout(Duration::from_secs(10))
            .expect("gyrocal sim's final line");
        let status = self.child.wait().unwrap();
        assert!(status.success(), "gyrocal sim: {status}");
        serde_json::from_str(&last).unwrap()
    }
}

impl Drop for Bench {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn line_channel(stream: impl std::io::Read + Send + 'static) -> mpsc::Receiver<String> {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stream).lines() {
            let Ok(line) = line else { break };
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    rx
}

fn interrupt(child: &Child) {
    let pid = nix::unistd::Pid::from_raw(i32::try_from(child.id()).unwrap());
    nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGINT).unwrap();
}

/// Where the README's commands run: a working directory with `configs/`, a home, and a
/// directory holding `gyrocal` (this build's binary) for `PATH`.
struct Place {
    _tmp: tempfile::TempDir,
    work: PathBuf,
    home: PathBuf,
    bin: PathBuf,
}

impl Place {
    fn new() -> Place {
        let tmp = tempfile::tempdir().unwrap();
        let work = tmp.path().join("work");
        let home = tmp.path().join("home");
        let bin = tmp.path().join("bin");
        for d in [&work, &home, &bin] {
            std::fs::create_dir_all(d).unwrap();
        }
        common::copy_dir(&repo().join("configs"), &work.join("configs"));
        std::os::unix::fs::symlink(env!("CARGO_BIN_EXE_gyrocal"), bin.join("gyrocal")).unwrap();
        Place {
            _tmp: tmp,
            work,
            home,
            bin,
        }
    }

    /// `sh -c 'exec TEXT'` here, with none of the user's files (see `common::isolated`).
    fn shell(&self, text: &str) -> Command {
        let mut c = Command::new("sh");
        common::remove_users_own(&mut c);
        let path = std::env::var("PATH").unwrap_or_default();
        c.env("HOME", &self.home)
            .env("PATH", format!("{}:{path}", self.bin.display()))
            .env("NO_COLOR", "1")
            .current_dir(&self.work)
            .arg("-c")
            .arg(format!("exec {text}"))
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped());
        c
    }

    fn file(&self, name: &str) -> PathBuf {
        match name.strip_prefix("~/") {
            Some(rest) => self.home.join(rest),
            None => self.work.join(name),
        }
    }
}

/// Waits for `child` at most `limit`; its status, stdout and stderr (killed and failed when
/// late, naming `what`).
fn finish(mut child: Child, limit: Duration, what: &str) -> (ExitStatus, String, String) {
    let mut out = child.stdout.take().unwrap();
    let mut err = child.stderr.take().unwrap();
    let o = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = out.read_to_string(&mut s);
        s
    });
    let e = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = err.read_to_string(&mut s);
        s
    });
    let status = wait_for(&mut child, limit, what);
    (status, o.join().unwrap(), e.join().unwrap())
}

/// Waits for `child` at most `limit` (killed and failed when late, naming `what`).
fn wait_for(child: &mut Child, limit: Duration, what: &str) -> ExitStatus {
    let start = Instant::now();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            return status;
        }
        if start.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            panic!("`{what}` still running after {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Runs one README command as [`EXPECTED`] says; its combined output.
fn run_one(
    place: &Place,
    bench: &mut Option<Bench>,
    line: &Line,
    text: &str,
    check: Check,
) -> String {
    let mut shell_text = text.to_string();
    if text.contains("/dev/ttyUSB") {
        let b = bench.get_or_insert_with(Bench::start);
        shell_text = shell_text
            .replace("/dev/ttyUSB0", &b.dmm)
            .replace("/dev/ttyUSB1", &b.table);
    }
    let what = format!("{} ({})", text, line.place);
    match check {
        Check::Ends {
            code,
            says,
            creates,
        } => {
            let child = place.shell(&shell_text).spawn().unwrap();
            let (status, out, err) = finish(child, Duration::from_secs(60), &what);
            let all = format!("{out}\n{err}");
            assert_eq!(
                status.code(),
                Some(code),
                "`{what}` exited {status}, the README's expectation is {code}:\n{all}"
            );
            for word in says {
                assert!(all.contains(word), "`{what}` does not say {word:?}:\n{all}");
            }
            for file in creates {
                assert!(
                    place.file(file).exists(),
                    "`{what}` did not create {file}:\n{all}"
                );
            }
            all
        }
        Check::CtrlCAfterFirstStep => {
            let mut child = place.shell(&shell_text).spawn().unwrap();
            let lines = line_channel(child.stderr.take().unwrap());
            let mut seen = String::new();
            let deadline = Instant::now() + Duration::from_secs(30);
            // "step 1/19 …": the first step has started (any wording that numbers it)
            while !seen.to_lowercase().contains("step 1") {
                let left = deadline.saturating_duration_since(Instant::now());
                match lines.recv_timeout(left) {
                    Ok(l) => {
                        seen.push_str(&l);
                        seen.push('\n');
                    }
                    Err(_) => {
                        let _ = child.kill();
                        panic!("`{what}` never started its first step:\n{seen}");
                    }
                }
            }
            interrupt(&child);
            let status = wait_for(&mut child, Duration::from_secs(30), &what);
            while let Ok(l) = lines.recv_timeout(Duration::from_secs(2)) {
                seen.push_str(&l);
                seen.push('\n');
            }
            assert_eq!(
                status.code(),
                Some(130),
                "`{what}` after Ctrl-C: {status}\n{seen}"
            );
            assert!(
                seen.contains("at rest"),
                "`{what}`: the table is said at rest:\n{seen}"
            );
            seen
        }
        Check::ServesUntilCtrlC => {
            let mut child = place
                .shell(&shell_text)
                .stderr(Stdio::null())
                .spawn()
                .unwrap();
            let lines = line_channel(child.stdout.take().unwrap());
            let first = lines
                .recv_timeout(Duration::from_secs(20))
                .unwrap_or_else(|_| panic!("`{what}` printed no line"));
            let info: Value = serde_json::from_str(&first)
                .unwrap_or_else(|e| panic!("`{what}`'s first line is not JSON ({e}): {first}"));
            assert!(
                info["dmm"].is_string() && info["table"].is_string(),
                "{first}"
            );
            interrupt(&child);
            let last = lines
                .recv_timeout(Duration::from_secs(10))
                .unwrap_or_else(|_| panic!("`{what}` printed no final line"));
            let status = wait_for(&mut child, Duration::from_secs(10), &what);
            assert!(status.success(), "`{what}` after Ctrl-C: {status}");
            let end: Value = serde_json::from_str(&last).unwrap();
            assert_eq!(end["table"]["stopped"], Value::Bool(true), "{last}");
            format!("{first}\n{last}")
        }
    }
}

/// The labels (`result:`, `report:`, ...) of the terminal sample on the README's first screen
/// (its first ```text block): the lines whose text before the first `:` is lower-case words.
fn sample_labels() -> Vec<String> {
    let text = std::fs::read_to_string(repo().join("README.md")).unwrap();
    let start = text
        .find("```text\n")
        .expect("README.md has a terminal sample")
        + 8;
    let block = &text[start..start + text[start..].find("```").unwrap()];
    block
        .lines()
        .filter_map(|l| l.split_once(':').map(|(label, _)| label))
        .filter(|label| {
            !label.is_empty()
                && !label.starts_with(' ')
                && label.chars().all(|c| c.is_ascii_lowercase() || c == ' ')
        })
        .map(str::to_string)
        .collect()
}

/// Every command in a ```sh block of README.md and configs/README.md is run as the rule at
/// the top of this file says (or allowlisted with its reason); the terminal sample on the
/// first screen has the labels the run really prints; and the simulated instruments that
/// stood in for the real ports end at rest.
#[test]
fn every_readme_command_runs_as_the_readme_says() {
    let lines: Vec<Line> = ["README.md", "configs/README.md"]
        .iter()
        .flat_map(|f| sh_commands(f))
        .collect();
    assert!(
        lines.len() >= 20,
        "only {} commands found: {lines:?}",
        lines.len()
    );

    // coverage first: a command nobody checks fails before anything runs
    let mut uncovered = Vec::new();
    let mut plan = Vec::new();
    for line in &lines {
        let Some(text) = as_run(&line.text) else {
            continue; // cargo: CI builds and tests
        };
        if NOT_RUN.iter().any(|(t, _)| *t == text) {
            continue;
        }
        match EXPECTED.iter().find(|(t, _)| *t == text) {
            Some((_, check)) => plan.push((line.clone(), text, *check)),
            None => uncovered.push(format!("{}: {}", line.place, line.text)),
        }
    }
    assert!(
        uncovered.is_empty(),
        "README commands no test runs (add each to EXPECTED in tests/readme_cli.rs, or to \
         NOT_RUN with the reason):\n{}",
        uncovered.join("\n")
    );
    let used: Vec<String> = lines.iter().filter_map(|l| as_run(&l.text)).collect();
    let checked = EXPECTED.iter().map(|(t, _)| *t);
    for t in checked.chain(NOT_RUN.iter().map(|(t, _)| *t)) {
        assert!(
            used.iter().any(|u| u == t),
            "tests/readme_cli.rs expects `{t}`, which no README gives any more"
        );
    }

    let place = Place::new();
    let mut bench = None;
    let mut first_run = None;
    for (line, text, check) in &plan {
        let output = run_one(&place, &mut bench, line, text, *check);
        if first_run.is_none() && text.starts_with("gyrocal run ") {
            first_run = Some(output);
        }
    }

    // the sample on the first screen: its labels are the run's
    let output = first_run.expect("the README runs a calibration");
    let labels = sample_labels();
    assert!(labels.len() >= 3, "labels of the sample: {labels:?}");
    for label in labels {
        assert!(
            output
                .lines()
                .any(|l| l.trim_start().starts_with(&format!("{label}:"))),
            "the README's terminal sample shows a line `{label}: …` that the run does not print:\n{output}"
        );
    }

    // the simulated instruments behind /dev/ttyUSB0 and /dev/ttyUSB1: the table at rest
    if let Some(bench) = bench {
        let end = bench.stop();
        assert_eq!(end["table"]["stopped"], Value::Bool(true), "{end}");
        let rate = end["table"]["actual_rate"].as_f64().unwrap();
        assert!(rate.abs() < 0.01, "the table ended at {rate} °/s: {end}");
    }
}

/// An inline `gyrocal SUBCOMMAND …` in the READMEs' prose names a subcommand that exists.
#[test]
fn inline_commands_name_real_subcommands() {
    let mut subs = std::collections::BTreeSet::new();
    for file in ["README.md", "configs/README.md"] {
        let text = std::fs::read_to_string(repo().join(file)).unwrap();
        // the prose only: fenced blocks left out, so that their ``` do not shift the spans
        let prose: String = text.split("```").step_by(2).collect::<Vec<_>>().join("\n");
        for span in prose.split('`').skip(1).step_by(2) {
            let sub = span
                .strip_prefix("gyrocal ")
                .and_then(|rest| rest.split_whitespace().next())
                .unwrap_or("");
            if !sub.is_empty() && sub.chars().all(|c| c.is_ascii_lowercase()) {
                subs.insert(sub.to_string());
            }
        }
    }
    assert!(subs.len() >= 8, "inline subcommands found: {subs:?}");
    for sub in subs {
        let out = common::gyrocal().args([&sub, "--help"]).output().unwrap();
        assert!(
            out.status.success(),
            "the README names `gyrocal {sub}`, which is not a subcommand:\n{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
}

/// The subcommands `gyrocal --help` lists (without `help`).
fn subcommands() -> Vec<String> {
    let out = common::gyrocal().arg("--help").output().unwrap();
    let text = String::from_utf8(out.stdout).unwrap();
    let list = &text[text.find("Commands:").unwrap()..];
    let list = &list[..list.find("\n\n").unwrap_or(list.len())];
    list.lines()
        .skip(1)
        .filter_map(|l| l.split_whitespace().next())
        .filter(|name| *name != "help")
        .map(str::to_string)
        .collect()
}

/// The examples of a help text: the command lines after its `Examples:` heading.
fn examples_in(help: &str) -> Vec<String> {
    let Some(at) = help.find("Examples:") else {
        return Vec::new();
    };
    help[at..]
        .lines()
        .map(str::trim)
        .filter(|l| l.starts_with("gyrocal "))
        .map(str::to_string)
        .collect()
}

/// `gyrocal SUB --help` ends with an EXAMPLES section of 2 to 4 invocations of SUB (each
/// parsed with the real definitions by `src/examples.rs`'s unit tests), the short `-h` stays
/// short, and every man page carries the same section.
#[test]
fn every_help_and_man_page_ends_with_examples_of_its_own_command() {
    let subs = subcommands();
    assert!(subs.len() >= 12, "{subs:?}");
    let mut paths: Vec<Vec<String>> = subs.iter().map(|s| vec![s.clone()]).collect();
    paths.push(vec!["catalog".into(), "import".into()]);
    paths.push(vec!["catalog".into(), "rebuild".into()]);
    let man = tempfile::tempdir().unwrap();
    let out = common::gyrocal()
        .args(["man", "-o"])
        .arg(man.path())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for path in paths {
        let name = path.join(" ");
        let out = common::gyrocal()
            .args(&path)
            .arg("--help")
            .output()
            .unwrap();
        let help = String::from_utf8(out.stdout).unwrap();
        let examples = examples_in(&help);
        assert!(
            (2..=4).contains(&examples.len()),
            "`gyrocal {name} --help` has {} examples:\n{help}",
            examples.len()
        );
        for e in &examples {
            assert!(
                e.starts_with(&format!("gyrocal {name}")),
                "`gyrocal {name} --help` shows an example of another command: {e}"
            );
        }
        let tail = &help[help.find("Examples:").unwrap()..];
        assert!(
            !tail.contains("Options:") && !tail.contains("Usage:"),
            "the examples end the help of `gyrocal {name}`:\n{help}"
        );
        let short = common::gyrocal().args(&path).arg("-h").output().unwrap();
        assert!(
            !String::from_utf8_lossy(&short.stdout).contains("Examples:"),
            "`gyrocal {name} -h` stays short"
        );
        let page = man.path().join(format!("gyrocal-{}.1", path.join("-")));
        let roff = std::fs::read_to_string(&page)
            .unwrap_or_else(|e| panic!("{}: {e}", page.display()))
            .replace("\\-", "-");
        assert!(
            roff.contains("Examples:") && roff.contains(&examples[0]),
            "{} lacks the examples:\n{roff}",
            page.display()
        );
    }
}
