//! A running `gyrocal sim` for the tests that drive the binary against it over its
//! pseudo-terminals: started with the caller's arguments, its first JSON line (the device
//! paths) read, SIGINT for its final-state line, killed when dropped.

use std::ffi::OsStr;
use std::io::{BufRead, BufReader};
use std::process::{Child, Stdio};
use std::sync::mpsc;
use std::time::Duration;

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

    /// SIGINT; the simulator's final-state line.
    pub fn finish(mut self) -> Value {
        let pid = nix::unistd::Pid::from_raw(i32::try_from(self.child.id()).unwrap());
        nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGINT).unwrap();
        let last = self
            .lines
            .recv_timeout(Duration::from_secs(5))
            .expect("the simulator's final-state line");
        let _ = self.child.wait();
        serde_json::from_str(&last).unwrap()
    }
}

impl Drop for Sim {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
