//! The ACL dialect (gyrocal's serial dialect of an ACUTROL, `shared/docs/rate-table.md`) over
//! the table's motion model: serving a link line by line, with the reply faults and held
//! replies in force, and what each command does (interlock, modes, rate demands and limits,
//! the error queue and `*STB?`).

use rand::RngExt;
use rand_distr::StandardNormal;
use tokio::io::{AsyncBufReadExt, AsyncRead, AsyncWrite, BufReader};
use tokio::time::Instant;

use super::profile::Segment;
use super::{SimMode, State, TableHandle, faulty_reply, spawn_reply_writer};

impl TableHandle {
    pub(super) async fn serve<S>(self, stream: S)
    where
        S: AsyncRead + AsyncWrite + Send + Unpin + 'static,
    {
        let (read, write) = tokio::io::split(stream);
        let write = spawn_reply_writer(write);
        let mut read = BufReader::new(read);
        let mut stop = self.shutdown.subscribe();
        let mut line = Vec::new();
        loop {
            line.clear();
            let n = tokio::select! {
                _ = stop.wait_for(|s| *s) => break,
                n = read.read_until(b'\n', &mut line) => n,
            };
            match n {
                Ok(0) | Err(_) => break,
                Ok(_) => {}
            }
            let text = String::from_utf8_lossy(&line);
            let text = text.trim_end_matches(['\n', '\r']);
            let now = Instant::now();
            let replies = self.execute(text, now);
            let mut st = self.lock();
            for r in &replies {
                let fault = st.reply_faults.pop_front();
                if let Some(f) = fault {
                    tracing::info!("sim table reply fault {f:?} on {r:?}");
                }
                let delay = st.take_reply_delay();
                if !delay.is_zero() {
                    tracing::debug!("sim table holds the reply {r:?} back by {delay:?}");
                }
                if write.send((now + delay, faulty_reply(r, fault))).is_err() {
                    return;
                }
            }
        }
        tracing::debug!("sim table stopped");
    }

    /// Executes one input line at `now`; returns the reply lines.
    pub(super) fn execute(&self, line: &str, now: Instant) -> Vec<String> {
        let (mut st, t) = self.at(now);
        if st.silent {
            return Vec::new();
        }
        let mut replies = Vec::new();
        let mut base: Vec<String> = Vec::new();
        for part in line.split(';') {
            if st.silent {
                break;
            }
            let part = part.trim();
            if part.is_empty() {
                continue;
            }
            let (header, args) = match part.split_once(char::is_whitespace) {
                Some((h, a)) => (h, a.trim()),
                None => (part, ""),
            };
            let header = header.to_ascii_uppercase();
            let (query, header) = match header.strip_suffix('?') {
                Some(h) => (true, h.to_string()),
                None => (false, header),
            };
            let nodes: Vec<String> = if header.starts_with('*') {
                vec![header.clone()]
            } else if let Some(abs) = header.strip_prefix(':') {
                abs.split(':').map(str::to_string).collect()
            } else {
                base.iter()
                    .cloned()
                    .chain(header.split(':').map(str::to_string))
                    .collect()
            };
            if nodes.len() > 1 {
                base = nodes[..nodes.len() - 1].to_vec();
            }
            let args: Vec<&str> = if args.is_empty() {
                Vec::new()
            } else {
                args.split(',').map(str::trim).collect()
            };
            if let Some(r) = command(&mut st, t, &nodes, query, &args) {
                replies.push(r);
            }
        }
        replies
    }
}

/// Whether a header node matches a mixed-case name in long form or short form (its capitals).
fn node_is(node: &str, name: &str) -> bool {
    let short: String = name.chars().filter(char::is_ascii_uppercase).collect();
    node == name.to_ascii_uppercase() || node == short
}

fn path_is(nodes: &[String], names: &[&str]) -> bool {
    nodes.len() == names.len() && nodes.iter().zip(names).all(|(n, m)| node_is(n, m))
}

fn parse_axis(st: &mut State, arg: Option<&&str>) -> Option<()> {
    match arg {
        None => {
            st.push_error(-109, "Missing parameter");
            None
        }
        Some(a) if a.parse::<u32>() == Ok(1) => Some(()),
        Some(_) => {
            st.push_error(-222, "Data out of range");
            None
        }
    }
}

fn parse_value(st: &mut State, arg: Option<&&str>) -> Option<f64> {
    match arg.map(|a| a.parse::<f64>()) {
        None => {
            st.push_error(-109, "Missing parameter");
            None
        }
        Some(Ok(v)) if v.is_finite() => Some(v),
        Some(_) => {
            st.push_error(-104, "Data type error");
            None
        }
    }
}

/// `R,<axis>,<value>` of the `:Limit` commands.
fn parse_limit(st: &mut State, args: &[&str]) -> Option<f64> {
    match args.first() {
        Some(m) if m.eq_ignore_ascii_case("R") => {}
        Some(_) => {
            st.push_error(-224, "Illegal parameter value");
            return None;
        }
        None => {
            st.push_error(-109, "Missing parameter");
            return None;
        }
    }
    parse_axis(st, args.get(1))?;
    parse_value(st, args.get(2))
}

fn num(v: f64) -> String {
    format!("{v:.6}")
}

fn command(st: &mut State, t: f64, nodes: &[String], query: bool, args: &[&str]) -> Option<String> {
    if query {
        if path_is(nodes, &["*IDN"]) {
            return Some(st.config.identity.clone());
        }
        if path_is(nodes, &["*STB"]) {
            return Some(st.status_byte().to_string());
        }
        if path_is(nodes, &["System", "Error"]) {
            return Some(match st.errors.pop_front() {
                Some((code, text)) => format!("{code},\"{text}\""),
                None => "0,\"No error\"".into(),
            });
        }
        if path_is(nodes, &["Mode"]) {
            parse_axis(st, args.first())?;
            return Some(st.mode.reply().into());
        }
        if path_is(nodes, &["Read", "Rate"]) {
            parse_axis(st, args.first())?;
            let noise: f64 = st.rng.sample(StandardNormal);
            let v = st.actual(t) + st.config.rate_noise_std * noise;
            return Some(num(v));
        }
        if path_is(nodes, &["Read", "Position"]) {
            parse_axis(st, args.first())?;
            return Some(num(st.seg.position(t).rem_euclid(360.0)));
        }
        st.push_error(-113, "Undefined header");
        return None;
    }
    if path_is(nodes, &["*CLS"]) {
        st.errors.clear();
    } else if path_is(nodes, &["Interlock", "Reset"]) {
        st.fault = None;
        st.interlock_event = false;
    } else if path_is(nodes, &["Interlock", "Close"]) {
        parse_axis(st, args.first())?;
        if let Some(f) = st.fault.clone() {
            st.push_error(203, format!("Fault latched: {f}"));
        } else if st.mode == SimMode::Abort {
            st.push_error(204, "Axis moving");
        } else if !st.interlock_closed {
            st.interlock_closed = true;
            st.mode = SimMode::Off;
            st.demand = 0.0;
            st.seg = Segment::hold(t, st.seg.position(t), 0.0);
        }
    } else if path_is(nodes, &["Interlock", "Open"]) {
        parse_axis(st, args.first())?;
        if st.count_stop() {
            return None;
        }
        if st.interlock_closed {
            st.interlock_event = true;
            st.abort(t);
        }
    } else if path_is(nodes, &["Mode", "Rate"]) {
        parse_axis(st, args.first())?;
        if !st.interlock_closed {
            st.push_error(201, "Interlock open");
        } else if st.mode != SimMode::Rate {
            st.mode = SimMode::Rate;
            st.demand = st.seg.target;
        }
    } else if path_is(nodes, &["Mode", "Off"]) {
        parse_axis(st, args.first())?;
        if st.count_stop() {
            return None;
        }
        st.controlled_stop(t);
    } else if path_is(nodes, &["Mode", "Position"]) {
        parse_axis(st, args.first())?;
        st.push_error(205, "Mode not available");
    } else if path_is(nodes, &["Limit", "Acceleration"]) {
        let v = parse_limit(st, args)?;
        if v <= 0.0 {
            st.push_error(202, "Acceleration limit must be positive");
        } else if v > st.config.max_acceleration {
            st.push_error(-222, "Data out of range");
        } else {
            st.accel_limit = v;
        }
    } else if path_is(nodes, &["Limit", "Rate"]) {
        let v = parse_limit(st, args)?;
        if v <= 0.0 || v > st.config.max_rate {
            st.push_error(-222, "Data out of range");
        } else {
            st.rate_limit = v;
        }
    } else if path_is(nodes, &["Demand", "Rate"]) {
        let armed = st.count_demand()?;
        demand_rate(st, t, args);
        st.arm_demand_faults(t, armed);
    } else {
        st.push_error(-113, "Undefined header");
    }
    None
}

/// `:Demand:Rate <axis>,<rate>`: checks, then a ramp to the new demand.
fn demand_rate(st: &mut State, t: f64, args: &[&str]) -> Option<()> {
    {
        parse_axis(st, args.first())?;
        let v = parse_value(st, args.get(1))?;
        if !st.interlock_closed {
            st.push_error(201, "Interlock open");
        } else if st.mode != SimMode::Rate {
            st.push_error(-221, "Settings conflict");
        } else if st.accel_limit <= 0.0 {
            st.push_error(202, "Acceleration limit must be positive");
        } else if v.abs() > st.rate_limit {
            st.push_error(-222, "Data out of range");
        } else {
            let (accel, jerk) = (st.accel_limit, st.config.jerk);
            st.ramp_to(t, v, accel, jerk);
            st.demand = v;
            // a fault injected at a rate may now be reached on this ramp
            st.advance(t);
        }
    }
    Some(())
}
