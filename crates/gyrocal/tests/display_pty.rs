//! The interactive display, seen through a pseudo-terminal 80 columns wide as an operator's
//! terminal would show it: a bar that names the step in the plan's numbering (`step 3/5`),
//! counts time on the run clock (said so) and the time left, fits 80 columns without
//! wrapping, and ends with the table's state.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test helpers: a panic is a failed test

mod common;

use std::io::Read;
use std::os::fd::{AsRawFd, OwnedFd};
use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::{Duration, Instant};

fn config(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../configs")
        .join(name)
}

/// Removes ANSI escape sequences (CSI ... letter, and two-byte ESC x): colours vanish, and a
/// cursor movement or erase ends the frame before it (it is where the terminal's line ends).
fn strip_ansi(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    let mut chars = s.chars().peekable();
    while let Some(c) = chars.next() {
        if c != '\u{1b}' {
            out.push(c);
            continue;
        }
        if chars.next() == Some('[') {
            for c in chars.by_ref() {
                if c.is_ascii_alphabetic() {
                    if c != 'm' {
                        out.push('\n');
                    }
                    break;
                }
            }
        }
    }
    out
}

#[test]
fn the_run_display_fits_80_columns_names_the_plan_step_and_counts_time() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let size = nix::pty::Winsize {
        ws_row: 24,
        ws_col: 80,
        ws_xpixel: 0,
        ws_ypixel: 0,
    };
    let pty = nix::pty::openpty(Some(&size), None).unwrap();
    let slave: OwnedFd = pty.slave;
    let mut child = common::gyrocal()
        .env("GYROCAL_CATALOG", "off")
        .arg("run")
        .arg(config("quick.toml"))
        .args(["--simulate", "--out"])
        .arg(&dir)
        .env("TERM", "xterm")
        .env_remove("NO_COLOR")
        .stdin(Stdio::null())
        .stdout(Stdio::from(slave.try_clone().unwrap()))
        .stderr(Stdio::from(slave.try_clone().unwrap()))
        .spawn()
        .unwrap();
    drop(slave);
    let master = std::fs::File::from(pty.master);
    let fd = master.as_raw_fd();
    assert!(fd >= 0);
    let reader = std::thread::spawn(move || {
        let mut master = master;
        let mut all = Vec::new();
        let mut buf = [0u8; 4096];
        // EIO once the child closed the terminal
        while let Ok(n) = master.read(&mut buf) {
            if n == 0 {
                break;
            }
            all.extend_from_slice(&buf[..n]);
        }
        all
    });
    let t0 = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        assert!(t0.elapsed() < Duration::from_secs(120), "run did not end");
        std::thread::sleep(Duration::from_millis(20));
    };
    let raw = reader.join().unwrap();
    let raw = String::from_utf8_lossy(&raw).into_owned();
    assert!(status.success(), "{raw}");
    // indicatif redraws the bar after `ESC [2K` (erase the line); lines printed above it are
    // padded to the terminal's width, so the bar is what follows the last step label before
    // the run clock. A bar wider than 80 columns wraps, and the next erase clears only its
    // last row: the old lines pile up. Each bar frame must fit.
    let mut bars = Vec::new();
    for segment in raw.split("\u{1b}[2K") {
        let frame = strip_ansi(segment).replace(['\r', '\n'], "");
        let Some(at) = frame.rfind("] at ") else {
            continue;
        };
        let start = frame[..at]
            .rfind("step ")
            .filter(|s| at - s < 50)
            .unwrap_or(at.saturating_sub(1));
        let bar = frame[start..].to_string();
        assert!(
            bar.chars().count() <= 80,
            "a bar frame wider than the terminal ({} columns): {bar:?}",
            bar.chars().count()
        );
        bars.push(bar);
    }
    let text = strip_ansi(&raw);
    // the bar: the plan's step numbering, the run clock (no wall-clock elapsed time beside a
    // run-clock ETA: the run said which clock its times are on), the time left on it, the
    // phase
    let bar = bars
        .iter()
        .find(|f| f.starts_with("step ") && f.contains(" left · ") && f.contains('['))
        .unwrap_or_else(|| panic!("no progress bar frame in:\n{text}"));
    assert!(
        text.contains("times are on the run clock"),
        "the run says which clock: {text}"
    );
    assert!(bar.contains("/5 "), "{bar}");
    assert!(
        bars.iter().any(|b| b.contains("waiting for at-rate (")),
        "the at-rate wait is shown: {bars:#?}"
    );
    assert!(
        bars.iter()
            .any(|b| b.contains("/50: ") && b.contains("mean")),
        "the latest reading and the running mean are shown: {bars:#?}"
    );
    for n in 1..=5 {
        assert!(
            text.contains(&format!("step {n} done")),
            "step {n} done in:\n{text}"
        );
    }
    assert!(text.contains("table at rest"), "{text}");
}
