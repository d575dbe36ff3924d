//! A real browser for the tests that look at what a person sees (`tests/serve_browser.rs`):
//! headless Chromium from the distribution (`/usr/bin/chromium`), driven over WebDriver by
//! Debian's `chromium-driver` (`/usr/bin/chromedriver`) with the `fantoccini` client, next to
//! `gyrocal serve` ([`Serve`]).
//!
//! - [`Browser::start`] starts chromedriver on a free loopback port in a process group of its
//!   own and opens a headless session (`--headless=new --no-sandbox --disable-gpu`) at a
//!   desktop or a phone's width; dropping the [`Browser`] (a failed assertion too) kills the
//!   whole group, chromedriver and every Chromium process it started.
//! - Chromium writes a profile, caches and crash reports under `HOME` and the XDG
//!   directories: chromedriver runs with all of them pointing into the browser's own
//!   temporary directory, so a test run writes nothing into a user's (or CI's sentinel) home.
//! - Without chromedriver or Chromium, [`Browser::start`] says so on stderr and returns
//!   `None`: the test skips (as the PostgreSQL tests do without a server). `.ci/run`
//!   installs both, so CI runs them. `GYROCAL_CHROMEDRIVER` and `GYROCAL_CHROMIUM` name other
//!   binaries.

#![allow(dead_code, clippy::unwrap_used, clippy::expect_used)] // each test uses a subset

use std::io::{BufRead as _, BufReader};
use std::net::{TcpListener, TcpStream};
use std::os::unix::process::CommandExt as _;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use fantoccini::{Client, ClientBuilder};
use nix::sys::signal::{Signal, killpg};
use nix::unistd::Pid;
use serde_json::Value;

/// Names another chromedriver binary.
pub const DRIVER_ENV: &str = "GYROCAL_CHROMEDRIVER";
/// Names another Chromium binary.
pub const CHROMIUM_ENV: &str = "GYROCAL_CHROMIUM";

/// The longest wall time any wait here takes (the machine may be loaded: generous).
pub const PATIENCE: Duration = Duration::from_secs(60);

/// The file the environment variable `env` names (`None` when it is not one), else the first
/// of `candidates` that is a file (a bare name: on `PATH`).
fn find(env: &str, candidates: &[&str]) -> Option<PathBuf> {
    if let Some(p) = std::env::var_os(env) {
        let p = PathBuf::from(p);
        return p.is_file().then_some(p);
    }
    let path = std::env::var_os("PATH").unwrap_or_default();
    for c in candidates {
        let p = Path::new(c);
        if p.is_absolute() {
            if p.is_file() {
                return Some(p.to_path_buf());
            }
        } else if let Some(found) = std::env::split_paths(&path)
            .map(|d| d.join(c))
            .find(|p| p.is_file())
        {
            return Some(found);
        }
    }
    None
}

/// How wide the window is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Window {
    /// 1280 × 1000 CSS px.
    Desktop,
    /// A phone held upright: 360 × 740 CSS px (emulated: Chromium's windows are at least
    /// 500 px wide).
    Phone,
    /// Any size (CSS px), for a screenshot of a long page.
    Size(u32, u32),
}

impl Window {
    fn size(self) -> (u32, u32) {
        match self {
            Window::Desktop => (1280, 1000),
            Window::Phone => (360, 740),
            Window::Size(w, h) => (w, h),
        }
    }
}

/// A headless Chromium session and its chromedriver, ended when dropped (see the module docs).
pub struct Browser {
    /// The WebDriver session.
    pub client: Client,
    driver: Child,
    dir: tempfile::TempDir,
}

impl Drop for Browser {
    fn drop(&mut self) {
        // chromedriver leads its own process group; Chromium's processes are in it too
        if let Ok(pid) = i32::try_from(self.driver.id()) {
            let _ = killpg(Pid::from_raw(pid), Signal::SIGKILL);
        }
        let _ = self.driver.kill();
        let _ = self.driver.wait();
    }
}

/// A free loopback port (bound, then let go: chromedriver takes it a moment later).
fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

impl Browser {
    /// Starts chromedriver and a headless session at `window`'s size, or says why it cannot
    /// on stderr and returns `None` (no chromedriver or no Chromium: the test skips).
    pub async fn start(window: Window) -> Option<Browser> {
        let Some(driver_bin) = find(DRIVER_ENV, &["/usr/bin/chromedriver", "chromedriver"]) else {
            eprintln!(
                "note: skipped: no chromedriver (apt-get install chromium chromium-driver, \
                 or ${DRIVER_ENV}); .ci/run installs it"
            );
            return None;
        };
        let Some(chromium) = find(
            CHROMIUM_ENV,
            &["/usr/bin/chromium", "chromium", "chromium-browser"],
        ) else {
            eprintln!("note: skipped: no Chromium (apt-get install chromium, or ${CHROMIUM_ENV})");
            return None;
        };
        let dir = tempfile::tempdir().unwrap();
        let home = dir.path().join("home");
        for sub in ["config", "cache", "data", "state", "profile"] {
            std::fs::create_dir_all(home.join(sub)).unwrap();
        }
        let log = std::fs::File::create(dir.path().join("chromedriver.log")).unwrap();
        let port = free_port();
        let mut cmd = Command::new(&driver_bin);
        cmd.arg(format!("--port={port}"))
            .arg("--allowed-ips=127.0.0.1")
            .env("HOME", &home)
            .env("XDG_CONFIG_HOME", home.join("config"))
            .env("XDG_CACHE_HOME", home.join("cache"))
            .env("XDG_DATA_HOME", home.join("data"))
            .env("XDG_STATE_HOME", home.join("state"))
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(log)
            .process_group(0);
        let driver = cmd
            .spawn()
            .unwrap_or_else(|e| panic!("{}: {e}", driver_bin.display()));
        let mut b = BrowserStart {
            driver: Some(driver),
        };
        // chromedriver listens a moment after it starts
        let t0 = Instant::now();
        while TcpStream::connect(("127.0.0.1", port)).is_err() {
            assert!(
                t0.elapsed() < PATIENCE,
                "chromedriver did not listen on port {port}: {}",
                std::fs::read_to_string(dir.path().join("chromedriver.log")).unwrap_or_default()
            );
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
        let (w, h) = window.size();
        let mut options = serde_json::json!({
            "binary": chromium,
            "args": [
                "--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                "--no-first-run", "--no-default-browser-check", "--hide-scrollbars",
                "--force-device-scale-factor=1",
                format!("--window-size={w},{h}"),
                format!("--user-data-dir={}", home.join("profile").display()),
            ],
        });
        if window == Window::Phone {
            // a window is at least 500 px wide, even headless: a phone is emulated (its
            // viewport, touch and `width=device-width` as a phone's browser reads it)
            options["mobileEmulation"] = serde_json::json!({
                "deviceMetrics": { "width": w, "height": h, "pixelRatio": 1.0, "touch": true }
            });
        }
        let mut caps = serde_json::Map::new();
        caps.insert("goog:chromeOptions".into(), options);
        let connector = hyper_util::client::legacy::connect::HttpConnector::new();
        let client = ClientBuilder::new(connector)
            .capabilities(caps)
            .connect(&format!("http://127.0.0.1:{port}"))
            .await
            .unwrap_or_else(|e| {
                panic!(
                    "a headless Chromium session: {e}\n{}",
                    std::fs::read_to_string(dir.path().join("chromedriver.log"))
                        .unwrap_or_default()
                )
            });
        Some(Browser {
            client,
            driver: b.driver.take().unwrap(),
            dir,
        })
    }

    /// Opens `url`.
    pub async fn goto(&self, url: &str) {
        self.client
            .goto(url)
            .await
            .unwrap_or_else(|e| panic!("{url}: {e}"));
    }

    /// Runs `script` (a function body: `return ...`) in the page with `args`.
    pub async fn js(&self, script: &str, args: Vec<Value>) -> Value {
        self.client
            .execute(script, args)
            .await
            .unwrap_or_else(|e| panic!("{script}: {e}"))
    }

    /// The visible text of the first element matching `css`, `None` when there is none.
    pub async fn text(&self, css: &str) -> Option<String> {
        self.js(
            "var e = document.querySelector(arguments[0]); return e ? e.innerText : null;",
            vec![Value::from(css)],
        )
        .await
        .as_str()
        .map(str::to_string)
    }

    /// How many elements match `css`.
    pub async fn count(&self, css: &str) -> u64 {
        self.js(
            "return document.querySelectorAll(arguments[0]).length;",
            vec![Value::from(css)],
        )
        .await
        .as_u64()
        .unwrap_or(0)
    }

    /// The `data-points` of the figure `id` (the points a plot draws), `None` without one.
    pub async fn data_points(&self, id: &str) -> Option<u64> {
        self.js(
            "var f = document.getElementById(arguments[0]); \
             return f ? Number(f.getAttribute('data-points')) : null;",
            vec![Value::from(id)],
        )
        .await
        .as_u64()
    }

    /// Sets a marker on the window: it survives the page's live updates and is gone after
    /// any navigation or reload ([`Browser::marker_kept`]).
    pub async fn set_marker(&self) {
        self.js(
            "window.__gyrocalMarker = 'not reloaded'; return true;",
            vec![],
        )
        .await;
    }

    /// Whether the marker [`Browser::set_marker`] set is still there (no reload since).
    pub async fn marker_kept(&self) -> bool {
        self.js("return window.__gyrocalMarker === 'not reloaded';", vec![])
            .await
            .as_bool()
            .unwrap_or(false)
    }

    /// Saves a screenshot of the window (PNG) to `path`, when `path` is given.
    pub async fn screenshot(&self, path: Option<&Path>) {
        let Some(path) = path else { return };
        let png = self.client.screenshot().await.unwrap();
        if let Some(d) = path.parent() {
            std::fs::create_dir_all(d).unwrap();
        }
        std::fs::write(path, png).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    }

    /// Where screenshots go: `$GYROCAL_SHOTS/NAME.png` when that variable is set (for a
    /// person to look at), else nowhere.
    pub fn shot(name: &str) -> Option<PathBuf> {
        std::env::var_os("GYROCAL_SHOTS").map(|d| PathBuf::from(d).join(format!("{name}.png")))
    }

    /// Ends the session cleanly (then chromedriver, as on drop).
    pub async fn close(self) {
        let _ = self.client.clone().close().await;
    }

    /// chromedriver's log (for a failure's message).
    pub fn log(&self) -> String {
        std::fs::read_to_string(self.dir.path().join("chromedriver.log")).unwrap_or_default()
    }
}

/// chromedriver while the session is being opened: killed with its group if that fails.
struct BrowserStart {
    driver: Option<Child>,
}

impl Drop for BrowserStart {
    fn drop(&mut self) {
        if let Some(mut d) = self.driver.take() {
            if let Ok(pid) = i32::try_from(d.id()) {
                let _ = killpg(Pid::from_raw(pid), Signal::SIGKILL);
            }
            let _ = d.kill();
            let _ = d.wait();
        }
    }
}

/// A child process of the test, killed and reaped when dropped, however the test ends.
pub struct Reap(pub Child);

impl Drop for Reap {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// `gyrocal serve` on a free loopback port over `roots`, with `extra` arguments (no catalog
/// unless `extra` names one); killed when dropped.
pub struct Serve {
    /// The server's process.
    pub process: Reap,
    /// Its base URL, `http://127.0.0.1:PORT`.
    pub url: String,
}

impl Serve {
    /// Starts it and reads the URL it prints first.
    pub fn start(roots: &[&Path], extra: &[&str]) -> Serve {
        Serve::start_in(None, roots, extra)
    }

    /// [`Serve::start`] in the working directory `cwd` (`None`: the test's): a view with no
    /// roots and a PostgreSQL catalog runs in a directory without `runs`.
    pub fn start_in(cwd: Option<&Path>, roots: &[&Path], extra: &[&str]) -> Serve {
        let mut cmd = crate::common::gyrocal();
        if let Some(dir) = cwd {
            cmd.current_dir(dir);
        }
        cmd.args(["serve", "--port", "0"]);
        for r in roots {
            cmd.arg("--root").arg(r);
        }
        cmd.args(extra);
        if !extra.iter().any(|a| a.starts_with("--catalog")) {
            cmd.arg("--no-catalog");
        }
        let mut process = Reap(
            cmd.stdout(Stdio::piped())
                .stderr(Stdio::null())
                .spawn()
                .unwrap(),
        );
        let mut line = String::new();
        BufReader::new(process.0.stdout.take().unwrap())
            .read_line(&mut line)
            .unwrap();
        let url = line
            .trim()
            .strip_prefix("gyrocal serve: ")
            .unwrap_or_else(|| panic!("gyrocal serve said {line:?}"))
            .trim_end_matches('/')
            .to_string();
        Serve { process, url }
    }

    /// The URL of `path` (`/`, `/run/0/NAME`).
    pub fn at(&self, path: &str) -> String {
        format!("{}{path}", self.url)
    }
}
