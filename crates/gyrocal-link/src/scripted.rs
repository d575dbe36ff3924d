//! [`ScriptedTransport`]: a transcript test double in the manner of embedded-hal-mock.
//!
//! A test lists what the driver must write, byte for byte, and what the device answers. Any
//! write that differs from the next expected one, a read when the script expects a write, or a
//! script not used up when the transport is dropped fails the test with the whole transcript so
//! far. A read when the script says [`ScriptStep::Silence`] returns a timeout at once, so the
//! recovery paths of a driver can be checked byte for byte too.

use std::collections::VecDeque;
use std::time::Duration;

use crate::{Field, LinkError, Transport};

/// One step of a transcript.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ScriptStep {
    /// The driver must write exactly these bytes in one `write_raw`/`send_line` call.
    Write(Vec<u8>),
    /// The device answers this line (the terminator is implied).
    Reply(String),
    /// The device says nothing: the next read times out.
    Silence,
    /// The device goes away: the next read or write reports a disconnect.
    Disconnect,
}

/// A transport that replays a transcript and checks the driver's bytes against it.
#[derive(Debug)]
pub struct ScriptedTransport {
    name: String,
    steps: VecDeque<ScriptStep>,
    log: Vec<String>,
    checked: bool,
}

impl ScriptedTransport {
    /// An empty script.
    pub fn new(name: impl Into<String>) -> Self {
        ScriptedTransport {
            name: name.into(),
            steps: VecDeque::new(),
            log: Vec::new(),
            checked: false,
        }
    }

    /// Expects the driver to send `line` followed by LF.
    pub fn expect_line(mut self, line: &str) -> Self {
        self.steps
            .push_back(ScriptStep::Write(format!("{line}\n").into_bytes()));
        self
    }

    /// Expects the driver to write exactly `bytes`.
    pub fn expect_raw(mut self, bytes: &[u8]) -> Self {
        self.steps.push_back(ScriptStep::Write(bytes.to_vec()));
        self
    }

    /// The device answers `line`.
    pub fn reply(mut self, line: &str) -> Self {
        self.steps.push_back(ScriptStep::Reply(line.to_string()));
        self
    }

    /// Expects the query `line` and answers `reply`.
    pub fn query(self, line: &str, reply: &str) -> Self {
        self.expect_line(line).reply(reply)
    }

    /// The device stays silent for the next read.
    pub fn silence(mut self) -> Self {
        self.steps.push_back(ScriptStep::Silence);
        self
    }

    /// The device disconnects.
    pub fn disconnect(mut self) -> Self {
        self.steps.push_back(ScriptStep::Disconnect);
        self
    }

    /// Appends steps.
    pub fn steps(mut self, steps: impl IntoIterator<Item = ScriptStep>) -> Self {
        self.steps.extend(steps);
        self
    }

    /// What happened so far, one entry per call, for failure messages.
    pub fn transcript(&self) -> &[String] {
        &self.log
    }

    /// Steps not yet used.
    pub fn remaining(&self) -> usize {
        self.steps.len()
    }

    /// Asserts that every step was used. Called by `Drop` too, unless already checked.
    ///
    /// # Panics
    /// If steps remain: this is a test assertion.
    pub fn done(&mut self) {
        self.checked = true;
        assert!(
            self.steps.is_empty(),
            "{}: script not finished, next expected {:?}\ntranscript:\n{}",
            self.name,
            self.steps.front(),
            self.log.join("\n")
        );
    }

    fn fail(&mut self, what: String) -> ! {
        self.checked = true;
        panic!(
            "{}: {what}\ntranscript:\n{}",
            self.name,
            self.log.join("\n")
        );
    }
}

impl Drop for ScriptedTransport {
    fn drop(&mut self) {
        if !self.checked && !std::thread::panicking() {
            self.done();
        }
    }
}

impl Transport for ScriptedTransport {
    fn describe(&self) -> &str {
        &self.name
    }

    async fn write_raw(&mut self, bytes: &[u8]) -> Result<(), LinkError> {
        let shown = crate::show_bytes(bytes);
        match self.steps.pop_front() {
            Some(ScriptStep::Write(expected)) if expected == bytes => {
                self.log.push(format!("> {shown}"));
                Ok(())
            }
            Some(ScriptStep::Disconnect) => {
                self.log.push(format!("> {shown} (disconnected)"));
                Err(LinkError::Disconnected {
                    device: self.name.clone(),
                    partial: Vec::new(),
                })
            }
            Some(ScriptStep::Write(expected)) => self.fail(format!(
                "driver wrote {shown}, script expected {}",
                crate::show_bytes(&expected)
            )),
            other => self.fail(format!("driver wrote {shown}, script expected {other:?}")),
        }
    }

    async fn read_line(&mut self, timeout: Option<Duration>) -> Result<String, LinkError> {
        match self.steps.front() {
            Some(ScriptStep::Reply(_)) => {
                let Some(ScriptStep::Reply(line)) = self.steps.pop_front() else {
                    unreachable!("front was a reply")
                };
                self.log.push(format!("< {line:?}"));
                Ok(line)
            }
            Some(ScriptStep::Silence) => {
                self.steps.pop_front();
                self.log.push("< (silence)".into());
                Err(LinkError::Timeout {
                    device: self.name.clone(),
                    timeout: timeout.unwrap_or_default(),
                    partial: Vec::new(),
                })
            }
            Some(ScriptStep::Disconnect) => {
                self.steps.pop_front();
                self.log.push("< (disconnected)".into());
                Err(LinkError::Disconnected {
                    device: self.name.clone(),
                    partial: Vec::new(),
                })
            }
            Some(ScriptStep::Write(w)) => {
                let w = crate::show_bytes(w);
                self.fail(format!(
                    "driver read a reply, script expected it to write {w}"
                ))
            }
            None => self.fail("driver read a reply after the end of the script".into()),
        }
    }

    async fn discard_input(&mut self) -> Result<usize, LinkError> {
        self.log.push("(discard input)".into());
        Ok(0)
    }

    /// Reads replies up to the byte `delimiter`: a reply step that holds it is split there (the
    /// rest stays in the script as the next reply); a reply step without it is taken whole with
    /// its implied LF and the next step continues the read.
    async fn read_until(
        &mut self,
        delimiter: u8,
        timeout: Option<Duration>,
    ) -> Result<String, LinkError> {
        let mut text = String::new();
        loop {
            if let Some(ScriptStep::Reply(line)) = self.steps.front_mut()
                && let Some(pos) = line.bytes().position(|b| b == delimiter)
            {
                let rest = line.split_off(pos + 1);
                line.pop();
                let piece = std::mem::replace(line, rest);
                if line.is_empty() {
                    self.steps.pop_front();
                }
                self.log
                    .push(format!("< {piece:?} (up to {:?})", char::from(delimiter)));
                text.push_str(&piece);
                return Ok(text);
            }
            text.push_str(&self.read_line(timeout).await?);
            text.push('\n');
        }
    }

    /// Splits the next reply at `sep`: the rest stays in the script as the next reply piece.
    async fn read_field(&mut self, sep: u8, timeout: Option<Duration>) -> Result<Field, LinkError> {
        if let Some(ScriptStep::Reply(line)) = self.steps.front_mut()
            && let Some(pos) = line.bytes().position(|b| b == sep)
        {
            let rest = line.split_off(pos + 1);
            line.pop();
            let text = std::mem::replace(line, rest);
            self.log.push(format!("< {text:?} (piece)"));
            return Ok(Field {
                text,
                end_of_line: false,
            });
        }
        let text = self.read_line(timeout).await?;
        Ok(Field {
            text,
            end_of_line: true,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ErrorKind;

    #[tokio::test]
    async fn replays_and_checks() {
        let mut t = ScriptedTransport::new("dmm")
            .query("*IDN?", "HP")
            .silence()
            .expect_raw(&[3]);
        t.send_line("*IDN?").await.unwrap();
        assert_eq!(t.read_line(None).await.unwrap(), "HP");
        assert_eq!(
            t.read_line(None).await.unwrap_err().kind(),
            ErrorKind::Timeout
        );
        t.write_raw(&[3]).await.unwrap();
        t.done();
    }

    #[tokio::test]
    async fn fields_are_split_from_replies() {
        let mut t = ScriptedTransport::new("dmm").query("FETC?", "+1,+2,+3");
        t.send_line("FETC?").await.unwrap();
        let mut got = Vec::new();
        loop {
            let f = t.read_field(b',', None).await.unwrap();
            got.push(f.text);
            if f.end_of_line {
                break;
            }
        }
        assert_eq!(got, ["+1", "+2", "+3"]);
    }

    #[tokio::test]
    async fn read_until_splits_and_joins_replies() {
        let mut t = ScriptedTransport::new("table")
            .expect_raw(b"PVE\r")
            .reply("10.0\r")
            .reply(">")
            .reply("\r\n>");
        t.write_raw(b"PVE\r").await.unwrap();
        assert_eq!(t.read_until(b'>', None).await.unwrap(), "10.0\r\n");
        assert_eq!(t.read_until(b'>', None).await.unwrap(), "\r\n");
        t.done();
    }

    #[tokio::test]
    #[should_panic(expected = "script expected")]
    async fn wrong_bytes_fail() {
        let mut t = ScriptedTransport::new("dmm").expect_line("SYST:REM");
        let _ = t.send_line("SYST:LOC").await;
    }

    #[test]
    #[should_panic(expected = "script not finished")]
    fn unused_steps_fail_on_drop() {
        let _t = ScriptedTransport::new("dmm").expect_line("SYST:REM");
    }
}
