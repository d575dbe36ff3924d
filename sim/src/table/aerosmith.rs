//! The simulated table speaking the Ideal Aerosmith three-letter ASCII dialect (experimental,
//! `shared/docs/instruments.md`), with the same motion model as the ACL simulator: the same
//! [`State`](super) (profile segments, limits, fault latching, rate noise and ripple) behind a
//! different wire. A [`TableHandle`] served this way keeps all its truth and fault-injection
//! methods ([`TableHandle::trip`], [`TableHandle::inject_fault`],
//! [`TableHandle::inject_reply_faults`], [`TableHandle::arm_at_demand`] counting `JOG`s, ...).
//!
//! The wire, as gyrocal's experimental driver assumes it (every point a lab must verify on its
//! table is an [`AerosmithWire`] option):
//!
//! - a command ends with the configured line ending ([`Terminator`]; default CR). The simulator
//!   is strict: with CR, an LF that follows is the start of the next command (which then is
//!   not a known mnemonic, `?`); with CR LF, a command without its CR is refused (`?`);
//! - every command is answered, then the prompt `>` without a line ending: a query with its
//!   value line (`10.000000` + line ending), a command with the prompt alone, an unknown or
//!   refused command with `?` + line ending;
//! - `SRV` servo on (clears a latched fault; refused while an abort profile runs);
//!   `ACL<deg/s²>` acceleration (0 < a ≤ the table's maximum); `JOG<rate>` continuous rate
//!   (servo on and an acceleration set first; |rate| ≤ the table's maximum rate); `STO`
//!   controlled stop; `PVE` measured rate; `PPO` position in `[0, 360)`; `STA` status word
//!   (decimal: servo on `0x01`, jogging `0x02`, fault latched `0x04`); `MCO<tol>` motion
//!   complete (the profile reached its target and the actual rate is within `tol` of it);
//! - JOG and PVE in deg/s or deg/min ([`AerosmithWire::per_minute`]);
//! - a fault (rate trip, injected fault, an interlock that opens) latches as in ACL: abort
//!   profile at the table's maximum acceleration, servo off, fault bit set until `SRV`.
//!
//! Reply faults ([`ReplyFault`]) hit query replies only (the value and its prompt).

use serde::{Deserialize, Serialize};
use tokio::io::{AsyncBufReadExt, AsyncRead, AsyncWrite, BufReader};
use tokio::time::Instant;

use super::profile::Segment;
use super::{ReplyFault, SimMode, SimTable, State, TableConfig, TableHandle, faulty_reply_ending};
use rand::RngExt;
use rand_distr::StandardNormal;

/// Status word bit: servo on.
pub const STA_SERVO: u32 = 0x01;
/// Status word bit: jogging (a continuous-rate command in force).
pub const STA_JOG: u32 = 0x02;
/// Status word bit: a fault is latched.
pub const STA_FAULT: u32 = 0x04;

/// The line ending that ends a command (and the simulator's reply lines).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Terminator {
    /// CR (default).
    #[default]
    Cr,
    /// CR LF.
    CrLf,
}

impl Terminator {
    fn bytes(self) -> &'static [u8] {
        match self {
            Terminator::Cr => b"\r",
            Terminator::CrLf => b"\r\n",
        }
    }
}

/// The points of the Aerosmith wire the public scripts disagree on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AerosmithWire {
    /// Command line ending. Default CR.
    pub terminator: Terminator,
    /// `JOG` and `PVE` in deg/min instead of deg/s. Default false.
    pub per_minute: bool,
    /// `MCO` answers `0` (not `1`) when the motion is complete. Default false.
    pub mco_zero_is_complete: bool,
}

impl SimTable {
    /// Serves the Aerosmith dialect on `stream` as a tokio task, like [`SimTable::spawn`] for
    /// ACL (the [`TableConfig`]'s identity is unused: the dialect has no identification).
    pub fn spawn_aerosmith<S>(
        stream: S,
        config: TableConfig,
        wire: AerosmithWire,
        seed: u64,
    ) -> TableHandle
    where
        S: AsyncRead + AsyncWrite + Send + Unpin + 'static,
    {
        let handle = TableHandle::new(config, seed);
        handle.serve_aerosmith(stream, wire);
        handle
    }
}

impl TableHandle {
    /// Serves the Aerosmith dialect on one more `stream` against this table, as a tokio task,
    /// until the stream closes or [`TableHandle::shutdown`].
    pub fn serve_aerosmith<S>(&self, stream: S, wire: AerosmithWire) -> tokio::task::JoinHandle<()>
    where
        S: AsyncRead + AsyncWrite + Send + Unpin + 'static,
    {
        let task = self.clone();
        tokio::spawn(async move { task.serve_aerosmith_on(stream, wire).await })
    }

    async fn serve_aerosmith_on<S>(self, stream: S, wire: AerosmithWire)
    where
        S: AsyncRead + AsyncWrite + Send + Unpin + 'static,
    {
        let (read, write) = tokio::io::split(stream);
        let write = super::spawn_reply_writer(write);
        let mut read = BufReader::new(read);
        let mut stop = self.shutdown.subscribe();
        let end = match wire.terminator {
            Terminator::Cr => b'\r',
            Terminator::CrLf => b'\n',
        };
        let mut line = Vec::new();
        loop {
            line.clear();
            let n = tokio::select! {
                _ = stop.wait_for(|s| *s) => break,
                n = read.read_until(end, &mut line) => n,
            };
            match n {
                Ok(0) | Err(_) => break,
                Ok(_) => {}
            }
            let now = Instant::now();
            let Some(bytes) = self.aerosmith_reply(&line, wire, now) else {
                continue;
            };
            let delay = self.lock().take_reply_delay();
            if write.send((now + delay, bytes)).is_err() {
                return;
            }
        }
        tracing::debug!("sim aerosmith table stopped");
    }

    /// Executes one received command (terminator included) at `now`; the bytes to answer, or
    /// `None` when silent.
    fn aerosmith_reply(&self, raw: &[u8], wire: AerosmithWire, now: Instant) -> Option<Vec<u8>> {
        let (mut st, t) = self.at(now);
        if st.silent {
            return None;
        }
        let eol = wire.terminator.bytes();
        let complete = raw.ends_with(eol);
        let text =
            String::from_utf8_lossy(&raw[..raw.len() - if complete { eol.len() } else { 0 }])
                .into_owned();
        let reply = if complete {
            execute(&mut st, t, &text, wire)
        } else {
            Err(())
        };
        if st.silent {
            return None;
        }
        let mut bytes = Vec::new();
        match reply {
            Ok(Some(value)) => {
                let fault = st.reply_faults.pop_front();
                if let Some(f) = fault {
                    tracing::info!("sim aerosmith reply fault {f:?} on {value:?}");
                }
                if fault == Some(ReplyFault::Drop) {
                    return Some(bytes);
                }
                bytes.extend(faulty_reply_ending(&value, fault, eol));
                bytes.push(b'>');
            }
            Ok(None) => bytes.push(b'>'),
            Err(()) => {
                tracing::debug!("sim aerosmith table refused {text:?}");
                bytes.extend_from_slice(b"?");
                bytes.extend_from_slice(eol);
                bytes.push(b'>');
            }
        }
        Some(bytes)
    }
}

fn number(arg: &str) -> Result<f64, ()> {
    match arg.trim().parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(()),
    }
}

/// One command: `Ok(Some(value))` for a query, `Ok(None)` for a command, `Err` for `?`.
fn execute(st: &mut State, t: f64, text: &str, wire: AerosmithWire) -> Result<Option<String>, ()> {
    let units = if wire.per_minute { 60.0 } else { 1.0 };
    if text.len() < 3 || !text.is_char_boundary(3) {
        return Err(());
    }
    let (mnemonic, arg) = text.split_at(3);
    let no_arg = |v: Option<String>| if arg.is_empty() { Ok(v) } else { Err(()) };
    match mnemonic.to_ascii_uppercase().as_str() {
        "SRV" => {
            if st.mode == SimMode::Abort {
                return Err(());
            }
            st.fault = None;
            st.interlock_event = false;
            if !st.interlock_closed {
                st.interlock_closed = true;
                st.mode = SimMode::Off;
                st.demand = 0.0;
                st.seg = Segment::hold(t, st.seg.position(t), 0.0);
            }
            no_arg(None)
        }
        "ACL" => {
            let a = number(arg)?;
            if a <= 0.0 || a > st.config.max_acceleration {
                return Err(());
            }
            st.accel_limit = a;
            Ok(None)
        }
        "JOG" => {
            let v = number(arg)? / units;
            let armed = st.count_demand().ok_or(())?;
            let refused = !st.interlock_closed || st.accel_limit <= 0.0 || v.abs() > st.rate_limit;
            if !refused {
                st.mode = SimMode::Rate;
                let (accel, jerk) = (st.accel_limit, st.config.jerk);
                st.ramp_to(t, v, accel, jerk);
                st.demand = v;
                st.advance(t);
            }
            st.arm_demand_faults(t, armed);
            if refused { Err(()) } else { Ok(None) }
        }
        "STO" => {
            if st.count_stop() {
                return Ok(None);
            }
            st.controlled_stop(t);
            no_arg(None)
        }
        "PVE" => {
            let noise: f64 = st.rng.sample(StandardNormal);
            let v = st.actual(t) + st.config.rate_noise_std * noise;
            no_arg(Some(format!("{:.6}", v * units)))
        }
        "PPO" => no_arg(Some(format!("{:.6}", st.seg.position(t).rem_euclid(360.0)))),
        "STA" => {
            let word = if st.servo_on() { STA_SERVO } else { 0 }
                | if st.mode == SimMode::Rate { STA_JOG } else { 0 }
                | if st.fault.is_some() { STA_FAULT } else { 0 };
            no_arg(Some(word.to_string()))
        }
        "MCO" => {
            let tol = number(arg)? / units;
            let done = st.mode != SimMode::Abort
                && t >= st.seg.end()
                && (st.actual(t) - st.seg.target).abs() <= tol;
            let one = done != wire.mco_zero_is_complete;
            Ok(Some(if one { "1" } else { "0" }.to_string()))
        }
        _ => Err(()),
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use tokio::io::{AsyncReadExt, AsyncWriteExt, DuplexStream};

    use super::*;

    fn quiet() -> TableConfig {
        TableConfig {
            rate_noise_std: 0.0,
            ripple_amplitude: 0.0,
            ..TableConfig::default()
        }
    }

    /// Sends `command` + the wire's terminator and reads the reply up to its prompt.
    async fn ask(link: &mut DuplexStream, command: &str, wire: AerosmithWire) -> String {
        let mut bytes = command.as_bytes().to_vec();
        bytes.extend_from_slice(wire.terminator.bytes());
        link.write_all(&bytes).await.unwrap();
        let mut got = Vec::new();
        let mut b = [0u8; 1];
        while got.last() != Some(&b'>') {
            let n = tokio::time::timeout(Duration::from_secs(1), link.read(&mut b))
                .await
                .expect("a reply up to the prompt")
                .unwrap();
            assert_eq!(n, 1, "closed");
            got.push(b[0]);
        }
        String::from_utf8(got).unwrap()
    }

    #[tokio::test(start_paused = true)]
    async fn jog_ramps_reports_and_stops_with_prompts() {
        let wire = AerosmithWire::default();
        let (mut link, device) = tokio::io::duplex(4096);
        let sim = SimTable::spawn_aerosmith(device, quiet(), wire, 1);
        assert_eq!(ask(&mut link, "STA", wire).await, "0\r>");
        assert_eq!(ask(&mut link, "JOG10", wire).await, "?\r>", "servo off");
        assert_eq!(ask(&mut link, "SRV", wire).await, ">");
        assert_eq!(
            ask(&mut link, "JOG10", wire).await,
            "?\r>",
            "no acceleration yet"
        );
        assert_eq!(ask(&mut link, "ACL0", wire).await, "?\r>");
        assert_eq!(ask(&mut link, "ACL5", wire).await, ">");
        assert_eq!(ask(&mut link, "JOG10", wire).await, ">");
        assert_eq!(ask(&mut link, "STA", wire).await, "3\r>");
        assert_eq!(ask(&mut link, "MCO0.01", wire).await, "0\r>");
        tokio::time::sleep(Duration::from_secs(1)).await;
        assert_eq!(ask(&mut link, "PVE", wire).await, "5.000000\r>");
        tokio::time::sleep(Duration::from_secs(2)).await;
        assert_eq!(ask(&mut link, "PVE", wire).await, "10.000000\r>");
        assert_eq!(ask(&mut link, "MCO0.01", wire).await, "1\r>");
        assert_eq!(ask(&mut link, "STO", wire).await, ">");
        assert_eq!(ask(&mut link, "STA", wire).await, "1\r>");
        assert_eq!(ask(&mut link, "MCO0.01", wire).await, "0\r>");
        tokio::time::sleep(Duration::from_secs(2)).await;
        assert_eq!(ask(&mut link, "MCO0.01", wire).await, "1\r>");
        assert_eq!(ask(&mut link, "PVE", wire).await, "0.000000\r>");
        assert!(sim.is_stopped());
        assert_eq!(ask(&mut link, "XYZ", wire).await, "?\r>");
        assert_eq!(sim.demands_seen(), 3);
    }

    #[tokio::test(start_paused = true)]
    async fn options_per_minute_crlf_and_mco_polarity() {
        let wire = AerosmithWire {
            terminator: Terminator::CrLf,
            per_minute: true,
            mco_zero_is_complete: true,
        };
        let (mut link, device) = tokio::io::duplex(4096);
        let sim = SimTable::spawn_aerosmith(device, quiet(), wire, 1);
        assert_eq!(ask(&mut link, "SRV", wire).await, ">");
        assert_eq!(ask(&mut link, "ACL10", wire).await, ">");
        // 600 deg/min is 10 deg/s
        assert_eq!(ask(&mut link, "JOG600", wire).await, ">");
        tokio::time::sleep(Duration::from_secs(2)).await;
        assert!((sim.actual_rate(Instant::now()) - 10.0).abs() < 1e-9);
        assert_eq!(ask(&mut link, "PVE", wire).await, "600.000000\r\n>");
        assert_eq!(ask(&mut link, "MCO0.6", wire).await, "0\r\n>");
        // a command without its CR is refused
        link.write_all(b"STO\n").await.unwrap();
        let mut got = [0u8; 4];
        link.read_exact(&mut got).await.unwrap();
        assert_eq!(&got, b"?\r\n>");
    }

    #[tokio::test(start_paused = true)]
    async fn a_wrong_line_ending_is_refused_with_cr() {
        let wire = AerosmithWire::default();
        let (mut link, device) = tokio::io::duplex(4096);
        let _sim = SimTable::spawn_aerosmith(device, quiet(), wire, 1);
        // CR LF to a CR table: the LF starts the next command
        assert_eq!(ask(&mut link, "STA", wire).await, "0\r>");
        link.write_all(b"\nSTA\r").await.unwrap();
        let mut got = [0u8; 3];
        link.read_exact(&mut got).await.unwrap();
        assert_eq!(&got, b"?\r>");
    }

    #[tokio::test(start_paused = true)]
    async fn a_fault_latches_the_fault_bit_until_srv() {
        let wire = AerosmithWire::default();
        let (mut link, device) = tokio::io::duplex(4096);
        let sim = SimTable::spawn_aerosmith(device, quiet(), wire, 1);
        ask(&mut link, "SRV", wire).await;
        ask(&mut link, "ACL10", wire).await;
        ask(&mut link, "JOG20", wire).await;
        tokio::time::sleep(Duration::from_secs(3)).await;
        sim.inject_fault("Tracking error limit exceeded");
        // abort profile: servo on, not jogging, fault
        assert_eq!(ask(&mut link, "STA", wire).await, "5\r>");
        assert_eq!(ask(&mut link, "SRV", wire).await, "?\r>", "moving");
        tokio::time::sleep(Duration::from_secs(2)).await;
        assert_eq!(ask(&mut link, "STA", wire).await, "4\r>");
        assert_eq!(ask(&mut link, "JOG1", wire).await, "?\r>");
        assert_eq!(ask(&mut link, "SRV", wire).await, ">");
        assert_eq!(ask(&mut link, "STA", wire).await, "1\r>");
        assert!(sim.fault().is_none());
    }

    #[tokio::test(start_paused = true)]
    async fn reply_faults_hit_query_replies() {
        let wire = AerosmithWire::default();
        let (mut link, device) = tokio::io::duplex(4096);
        let sim = SimTable::spawn_aerosmith(device, quiet(), wire, 1);
        sim.inject_reply_faults(ReplyFault::Garble, 1);
        assert_eq!(ask(&mut link, "STA", wire).await, "#\r>");
        sim.inject_reply_faults(ReplyFault::Drop, 1);
        link.write_all(b"STA\r").await.unwrap();
        tokio::time::sleep(Duration::from_millis(10)).await;
        assert_eq!(ask(&mut link, "STA", wire).await, "0\r>");
        sim.set_silent(true);
        link.write_all(b"STA\r").await.unwrap();
        let mut b = [0u8; 1];
        assert!(
            tokio::time::timeout(Duration::from_secs(1), link.read(&mut b))
                .await
                .is_err()
        );
    }
}
