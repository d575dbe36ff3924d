//! A running `gyrocal sim` for the tests that drive the binary against it over its
//! pseudo-terminals: started with the caller's arguments, its first JSON line (the device
//! paths) read, SIGUSR1 for its chamber's panel reset, SIGINT for its final-state line (and
//! its exit status checked), killed when dropped.

use std::ffi::OsStr;
use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use serde_json::Value;

/// A running `gyrocal sim` (killed on drop if still running).
pub struct Sim {
    child: Child,
    lines: mpsc::Receiver<String>,
    info: Value,
}

impl Sim {
    /// `gyrocal sim ARGS`, once it has printed the JSON line with its device paths.
    pub fn start(args: &[&dyn AsRef<OsStr>]) -> Sim {
        let mut child = super::gyrocal()
            .arg("sim")
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .unwrap();
        let stdout = child.stdout.take().unwrap();
        let (tx, lines) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines() {
                let Ok(line) = line else { break };
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        let first = lines
            .recv_timeout(Duration::from_secs(10))
            .expect("the simulator's JSON line with the device paths");
        let info: Value = serde_json::from_str(&first).unwrap_or_else(|e| panic!("{e}: {first}"));
        Sim { child, lines, info }
    }

    /// The simulator's first line: its device paths and settings.
    pub fn info(&self) -> &Value {
        &self.info
    }

    /// The multimeter's pseudo-terminal.
    pub fn dmm(&self) -> &str {
        self.info["dmm"].as_str().unwrap()
    }

    /// The table's pseudo-terminal.
    pub fn table(&self) -> &str {
        self.info["table"].as_str().unwrap()
    }

    /// The chamber's pseudo-terminal or `tcp://` address (`--chamber`, `--chamber-tcp`).
    pub fn chamber(&self) -> &str {
        self.info["chamber"]
            .as_str()
            .unwrap_or_else(|| panic!("no chamber in {}", self.info))
    }

    fn signal(&self, signal: nix::sys::signal::Signal) {
        let pid = nix::unistd::Pid::from_raw(i32::try_from(self.child.id()).unwrap());
        nix::sys::signal::kill(pid, signal).unwrap();
    }

    /// SIGUSR1: the operator presses the alarm reset at the simulated chamber's panel; the
    /// simulator's line that says so (`{"chamber_panel": "alarms reset", "cleared": [...]}`).
    pub fn reset_chamber_alarms(&self) -> Value {
        self.signal(nix::sys::signal::Signal::SIGUSR1);
        let line = self
            .lines
            .recv_timeout(Duration::from_secs(10))
            .expect("the simulator's line for the panel's alarm reset");
        let v: Value = serde_json::from_str(&line).unwrap_or_else(|e| panic!("{e}: {line}"));
        assert_eq!(v["chamber_panel"], "alarms reset", "{v}");
        v
    }

    /// SIGINT; the simulator's final-state line, once it has exited with success.
    pub fn finish(mut self) -> Value {
        self.signal(nix::sys::signal::Signal::SIGINT);
        let last = self
            .lines
            .recv_timeout(Duration::from_secs(10))
            .expect("the simulator's final-state line");
        let status = self.child.wait().unwrap();
        assert!(status.success(), "gyrocal sim exited with {status:?}");
        serde_json::from_str(&last).unwrap_or_else(|e| panic!("{e}: {last}"))
    }
}

impl Drop for Sim {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// What a command run to its end with [`output_within`] gave.
#[derive(Debug)]
pub struct Ended {
    /// Its exit code (`None`: killed by a signal).
    pub code: Option<i32>,
    /// Its standard output.
    pub stdout: String,
    /// Its standard error.
    pub stderr: String,
}

/// Runs `cmd` to its end (stdin closed, both outputs captured), killing it and failing the
/// test with what it printed if it has not ended within `limit` (a generous bound: a run
/// against a paced simulator that hangs must fail the test with its own words, not hang it).
pub fn output_within(cmd: &mut Command, limit: Duration) -> Ended {
    use std::io::Read;
    let mut child = cmd
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let drain = |mut r: Box<dyn Read + Send>| {
        std::thread::spawn(move || {
            let mut buf = Vec::new();
            let _ = r.read_to_end(&mut buf);
            String::from_utf8_lossy(&buf).into_owned()
        })
    };
    let out = drain(Box::new(child.stdout.take().unwrap()));
    let err = drain(Box::new(child.stderr.take().unwrap()));
    let t0 = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if t0.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            panic!(
                "{cmd:?} did not end within {limit:?}; it printed:\n{}",
                err.join().unwrap_or_default()
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    Ended {
        code: status.code(),
        stdout: out.join().unwrap_or_default(),
        stderr: err.join().unwrap_or_default(),
    }
}
