//! The simulated Espec SH-641 text protocol (chamber.md; the commands of the open `sh641.py`
//! driver the gyrocal-chamber driver follows): one command a line, CR LF (a bare LF is
//! accepted too), one reply line, CR LF.
//!
//! | command | reply |
//! |---|---|
//! | `TYPE?` | the configured identity (`T,T,S2,160.0`) |
//! | `TEMP?` | `measured,setpoint,upper,lower`, 0.1 °C (measured: the air, with sensor noise; upper and lower: the configured range) |
//! | `TEMP,S<v>` | `OK:TEMP,S<v>` as sent; `NA:DATA OUT OF RANGE` outside the range, `NA:DATA NOT READY` when `<v>` is not a number |
//! | `MODE,CONSTANT` / `MODE,STANDBY` / `MODE,OFF` | `OK:` and the command; standby and off stop control (the air drifts back to the room) |
//! | `MODE?` | `CONSTANT`, `STANDBY`, `OFF`, or `RUN` while a profile of its own runs |
//! | `ALARM?` | `0`, or the count and the codes: `2,1,5` (over-temperature 1, door 5: sim's choice) |
//! | `ALARM,RESET` | `OK:ALARM,RESET`: clears the latched alarms (sim's; unconfirmed on a real one) |
//! | anything else | `NA:COMMAND ERR` |
//!
//! `MODE,CONSTANT` also ends a profile of the controller's own.

use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};

use super::{ChamberAlarm, ChamberHandle, SimMode, State};

/// The longest line accepted; a longer one is thrown away.
const MAX_LINE: usize = 256;

fn mode_word(m: SimMode) -> &'static str {
    match m {
        SimMode::Constant => "CONSTANT",
        SimMode::Profile => "RUN",
        SimMode::Standby => "STANDBY",
        SimMode::Off => "OFF",
    }
}

/// The reply to one command line.
fn execute(s: &mut State, line: &str) -> String {
    let upper = line.to_ascii_uppercase();
    let (lo, hi) = s.config.range_c;
    match upper.as_str() {
        "TYPE?" => s.config.espec_identity.clone(),
        "TEMP?" => {
            let air = s.sensed_air();
            format!("{air:.1},{:.1},{hi:.1},{lo:.1}", s.setpoint_c)
        }
        "MODE?" => mode_word(s.mode).to_string(),
        "ALARM?" => {
            let codes: Vec<String> = [ChamberAlarm::OverTemperature, ChamberAlarm::Door]
                .into_iter()
                .filter(|&a| s.alarm(a))
                .map(|a| a.espec_code().to_string())
                .collect();
            if codes.is_empty() {
                "0".into()
            } else {
                format!("{},{}", codes.len(), codes.join(","))
            }
        }
        "ALARM,RESET" => {
            s.set_alarm(ChamberAlarm::Door, false);
            s.set_alarm(ChamberAlarm::OverTemperature, false);
            format!("OK:{line}")
        }
        "MODE,CONSTANT" | "MODE,STANDBY" | "MODE,OFF" => {
            s.mode = match &upper[5..] {
                "CONSTANT" => SimMode::Constant,
                "STANDBY" => SimMode::Standby,
                _ => SimMode::Off,
            };
            s.retarget();
            format!("OK:{line}")
        }
        _ => match upper.strip_prefix("TEMP,S") {
            Some(v) => match v.trim().parse::<f64>() {
                Ok(c) if c.is_finite() && (lo..=hi).contains(&c) => {
                    s.setpoint_c = (c * 10.0).round() / 10.0;
                    s.retarget();
                    format!("OK:{line}")
                }
                Ok(_) => "NA:DATA OUT OF RANGE".into(),
                Err(_) => "NA:DATA NOT READY".into(),
            },
            None => "NA:COMMAND ERR".into(),
        },
    }
}

/// Whether `line` touches a register refused by [`ChamberHandle::exception_on_register`]
/// (100 for `TEMP?`'s measurement, 300 for the setpoint).
fn refused(s: &State, line: &str) -> bool {
    let upper = line.to_ascii_uppercase();
    (upper == "TEMP?" && s.wire.register_exception(100, 1).is_some())
        || (upper.starts_with("TEMP") && s.wire.register_exception(300, 1).is_some())
}

/// Replaces the first digit of `reply` (else its first character) by `#`.
fn garble(reply: &str) -> String {
    let at = reply
        .char_indices()
        .find(|(_, c)| c.is_ascii_digit())
        .map_or(0, |(i, _)| i);
    let mut out = String::with_capacity(reply.len());
    for (i, c) in reply.char_indices() {
        out.push(if i == at { '#' } else { c });
    }
    out
}

/// Serves the Espec text protocol on `stream` until it closes.
pub async fn serve<S>(chamber: ChamberHandle, mut stream: S)
where
    S: AsyncRead + AsyncWrite + Send + Unpin + 'static,
{
    let mut buf: Vec<u8> = Vec::new();
    let mut chunk = [0u8; 256];
    loop {
        let Some(end) = buf.iter().position(|&b| b == b'\n') else {
            if buf.len() > MAX_LINE {
                buf.clear();
            }
            match stream.read(&mut chunk).await {
                Ok(0) | Err(_) => return,
                Ok(n) => buf.extend_from_slice(&chunk[..n]),
            }
            continue;
        };
        let raw: Vec<u8> = buf.drain(..=end).collect();
        let line = String::from_utf8_lossy(&raw).trim().to_string();
        if line.is_empty() {
            continue;
        }
        let (reply, delay) = {
            let mut s = chamber.lock();
            let fate = s.begin_request();
            if fate.silent {
                continue;
            }
            let reply = if fate.refused || refused(&s, &line) {
                "NA:DEVICE FAULT".to_string()
            } else {
                execute(&mut s, &line)
            };
            let reply = if fate.corrupt { garble(&reply) } else { reply };
            (reply, fate.delay_s)
        };
        tokio::time::sleep(chamber.real(delay)).await;
        let bytes = format!("{reply}\r\n");
        if stream.write_all(bytes.as_bytes()).await.is_err() || stream.flush().await.is_err() {
            return;
        }
    }
}
