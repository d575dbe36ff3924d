//! The Espec SH-641 / SU series text protocol (experimental, like the Aerosmith table).
//!
//! Lines end CR LF both ways; 0.1 °C resolution; a 10 s read timeout is usual (from the open
//! driver `akaeba/ATWG`, `driver/espec/sh641.py`; see `docs/chamber.md`). Confirmed there:
//!
//! | sent | reply |
//! |---|---|
//! | `TYPE?` | identity, e.g. `T,T,S2,160.0` |
//! | `TEMP?` | `measured,setpoint,upper-alarm,lower-alarm`, e.g. `23.4,25.0,100.0,-40.0` |
//! | `TEMP,S25.0` | `OK:TEMP,S25.0`; refused: `NA:` and a reason |
//! | `MODE,CONSTANT` / `MODE,STANDBY` / `MODE,OFF` | `OK:` and the command |
//!
//! Not confirmed, so options, off by default ([`EspecConfig`]):
//! - `MODE?` (the mode read back: `CONSTANT`, `STANDBY`, `OFF`, `RUN…` for a program, `PAUSE…`).
//!   Off: a reading's mode is the last one this driver commanded (constant before any), an
//!   assumption the reading cannot check; a safe state is confirmed by the controller's `OK:`
//!   acknowledgement.
//! - `ALARM?` (`0`, or the count and the codes: `2,1,5`). Off: a reading has no alarms (the
//!   protocol gives none that is confirmed).
//!
//! No product input in this protocol: `product_c` is always `None` (a series on an Espec
//! soaks on the air, or reads the gyro's temperature elsewhere).
//!
//! At connect, the setpoint limits are narrowed to the controller's own upper and lower alarm
//! temperatures (the last two fields of `TEMP?`): a setpoint beyond them would raise its alarm.
//!
//! Queries (`TYPE?`, `TEMP?`, `MODE?`, `ALARM?`) are asked again after a lost or unparsable
//! reply (`1 + retries` attempts, each within the reply timeout); commands are sent once.
//! Stale input (a late reply) is thrown away before every line sent.

use std::time::Duration;

use gyrocal_link::{ErrorKind as LinkErrorKind, Link, LinkError, LinkOptions, Transport};

use crate::{
    Chamber, ChamberError, ChamberIdentity, ChamberMode, ChamberReading, ChamberTiming, SafeReport,
    SafeState,
};

/// The Espec driver's settings.
#[derive(Debug, Clone, PartialEq)]
pub struct EspecConfig {
    /// The lowest setpoint sent, °C (narrowed at connect by the controller's lower alarm
    /// temperature). Default −40.
    pub min_c: f64,
    /// The highest setpoint sent, °C (narrowed by the upper alarm temperature). Default 85.
    pub max_c: f64,
    /// How long a reply may take. Default 10 s.
    pub reply_timeout: Duration,
    /// How many times a query is asked again. Default 2.
    pub retries: u32,
    /// Read the mode back with `MODE?` (unconfirmed). Default false.
    pub mode_query: bool,
    /// Read the alarms with `ALARM?` (unconfirmed). Default false.
    pub alarm_query: bool,
    /// The serial line's baud rate (opening and the timing model). Default 9600.
    pub baud: u32,
    /// The controller's reply latency for the timing model. Default 200 ms (an assumption:
    /// no figure is published).
    pub reply_latency: Duration,
}

impl Default for EspecConfig {
    fn default() -> Self {
        EspecConfig {
            min_c: -40.0,
            max_c: 85.0,
            reply_timeout: Duration::from_secs(10),
            retries: 2,
            mode_query: false,
            alarm_query: false,
            baud: 9600,
            reply_latency: Duration::from_millis(200),
        }
    }
}

impl EspecConfig {
    fn validate(&self, device: &str) -> Result<(), ChamberError> {
        let bad = |what: String| {
            Err(ChamberError::Setup {
                device: device.to_string(),
                what,
            })
        };
        if !self.min_c.is_finite() || !self.max_c.is_finite() || self.min_c >= self.max_c {
            return bad(format!(
                "setpoint limits {} .. {} °C are not a range",
                self.min_c, self.max_c
            ));
        }
        if self.reply_timeout.is_zero() || self.reply_timeout > Duration::from_secs(60) {
            return bad(format!(
                "reply timeout {:?} is not within (0, 60 s]",
                self.reply_timeout
            ));
        }
        if self.retries > 10 {
            return bad(format!("{} retries is more than 10", self.retries));
        }
        Ok(())
    }
}

/// The fields of a `TEMP?` reply.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Temp {
    measured: f64,
    setpoint: f64,
    upper: f64,
    lower: f64,
}

fn parse_temp(reply: &str) -> Result<Temp, String> {
    let fields: Vec<&str> = reply.split(',').map(str::trim).collect();
    let [m, s, u, l] = fields.as_slice() else {
        return Err(format!("{} fields instead of 4", fields.len()));
    };
    let num = |name: &str, t: &str| match t.parse::<f64>() {
        Ok(v) if v.is_finite() && v.abs() < 1000.0 => Ok(v),
        _ => Err(format!("{name} {t:?} is not a temperature")),
    };
    Ok(Temp {
        measured: num("measured", m)?,
        setpoint: num("setpoint", s)?,
        upper: num("upper alarm", u)?,
        lower: num("lower alarm", l)?,
    })
}

fn parse_mode(reply: &str) -> Result<ChamberMode, String> {
    let word = reply.trim().to_ascii_uppercase();
    match word.as_str() {
        "CONSTANT" => Ok(ChamberMode::Constant),
        "STANDBY" => Ok(ChamberMode::Standby),
        "OFF" => Ok(ChamberMode::Off),
        w if w.starts_with("RUN") => Ok(ChamberMode::Profile),
        w if w.starts_with("PAUSE") => Ok(ChamberMode::Paused),
        _ => Err(format!("{reply:?} is not a mode")),
    }
}

fn parse_alarms(reply: &str) -> Result<Vec<String>, String> {
    let mut fields = reply.split(',').map(str::trim);
    let count: usize = fields
        .next()
        .and_then(|c| c.parse().ok())
        .filter(|&c| c <= 32)
        .ok_or_else(|| format!("{reply:?} does not start with an alarm count"))?;
    let codes: Vec<String> = fields
        .map(|c| match c.parse::<u16>() {
            Ok(n) => Ok(format!("alarm code {n}")),
            Err(_) => Err(format!("alarm code {c:?} is not a number")),
        })
        .collect::<Result<_, _>>()?;
    if codes.len() != count {
        return Err(format!(
            "{count} alarms announced, {} codes given",
            codes.len()
        ));
    }
    Ok(codes)
}

fn mode_word(mode: ChamberMode) -> &'static str {
    match mode {
        ChamberMode::Standby => "STANDBY",
        ChamberMode::Off => "OFF",
        _ => "CONSTANT",
    }
}

/// An Espec chamber controller over a line transport.
#[derive(Debug)]
pub struct Espec<T> {
    link: T,
    description: String,
    config: EspecConfig,
    limits: (f64, f64),
    /// The last mode commanded and acknowledged.
    last_mode: Option<ChamberMode>,
    retry_notes: Vec<String>,
}

impl Espec<Link> {
    /// Opens a port string (`/dev/ttyUSB2`, `tcp://host:port` for a serial-to-Ethernet
    /// converter) through gyrocal-link, at `config.baud` (the link's framing, 8N2: its second
    /// stop bit is idle time to a controller set to one).
    pub async fn open(port: &str, config: EspecConfig) -> Result<Self, ChamberError> {
        let options = LinkOptions {
            baud: config.baud,
            ..LinkOptions::default()
        };
        let link = gyrocal_link::open(port, &options)
            .await
            .map_err(|e| ChamberError::Link {
                device: format!("{port} (Espec)"),
                request: "opening".into(),
                detail: e.to_string(),
            })?;
        Self::over_transport(link, config)
    }
}

impl<T: Transport> Espec<T> {
    /// The driver over any line transport.
    pub fn over_transport(link: T, config: EspecConfig) -> Result<Self, ChamberError> {
        let description = format!("{} (Espec, text)", link.describe());
        config.validate(&description)?;
        Ok(Espec {
            limits: (config.min_c, config.max_c),
            link,
            description,
            config,
            last_mode: None,
            retry_notes: Vec::new(),
        })
    }

    /// The setpoint limits in force.
    pub fn limits(&self) -> (f64, f64) {
        self.limits
    }

    /// The transport (for a test's transcript).
    pub fn transport_mut(&mut self) -> &mut T {
        &mut self.link
    }

    fn link_error(&self, request: &str, e: &LinkError) -> ChamberError {
        ChamberError::Link {
            device: self.description.clone(),
            request: request.to_string(),
            detail: e.to_string(),
        }
    }

    /// Sends one line and reads one reply line; `NA:` is the controller's refusal.
    async fn exchange(&mut self, line: &str) -> Result<Result<String, LinkError>, ChamberError> {
        self.link
            .write_raw(format!("{line}\r\n").as_bytes())
            .await
            .map_err(|e| self.link_error(line, &e))?;
        let reply = self.link.read_line(Some(self.config.reply_timeout)).await;
        if let Ok(r) = &reply
            && let Some(reason) = r.strip_prefix("NA:")
        {
            return Err(ChamberError::Instrument {
                device: self.description.clone(),
                request: line.to_string(),
                reason: reason.trim().to_string(),
            });
        }
        Ok(reply)
    }

    /// An idempotent query, asked again after a lost or unparsable reply.
    async fn query<R>(
        &mut self,
        line: &str,
        parse: impl Fn(&str) -> Result<R, String>,
    ) -> Result<R, ChamberError> {
        let attempts = self.config.retries.saturating_add(1);
        let mut silent = true;
        let mut last = String::new();
        for attempt in 1..=attempts {
            if attempt > 1 {
                let note = format!(
                    "{}: {line}: {last}; asked again (attempt {attempt} of {attempts})",
                    self.description
                );
                tracing::warn!("{note}");
                self.retry_notes.push(note);
            }
            // A late reply to an earlier query is never read as this one's.
            if let Err(e) = self.link.discard_input().await {
                return Err(self.link_error(line, &e));
            }
            match self.exchange(line).await? {
                Ok(reply) => match parse(&reply) {
                    Ok(v) => return Ok(v),
                    Err(why) => {
                        silent = false;
                        last = format!("garbled reply {reply:?}: {why}");
                    }
                },
                Err(e) => match e.kind() {
                    LinkErrorKind::Timeout => {
                        last = format!(
                            "no reply within {} ms",
                            self.config.reply_timeout.as_millis()
                        );
                    }
                    LinkErrorKind::Garbled => {
                        silent = false;
                        last = e.to_string();
                    }
                    LinkErrorKind::Disconnected | LinkErrorKind::Io => {
                        return Err(self.link_error(line, &e));
                    }
                },
            }
        }
        Err(if silent {
            ChamberError::Timeout {
                device: self.description.clone(),
                request: format!("{line} (asked {attempts} times; the chamber is silent)"),
                timeout_ms: u64::try_from(self.config.reply_timeout.as_millis())
                    .unwrap_or(u64::MAX),
            }
        } else {
            ChamberError::Garbled {
                device: self.description.clone(),
                request: format!("{line} (asked {attempts} times)"),
                detail: last,
            }
        })
    }

    /// A command, sent once: the reply must be `OK:` and the command.
    async fn command(&mut self, line: &str) -> Result<(), ChamberError> {
        self.link
            .discard_input()
            .await
            .map_err(|e| self.link_error(line, &e))?;
        match self.exchange(line).await? {
            Ok(reply) if reply.trim() == format!("OK:{line}") => Ok(()),
            Ok(reply) => Err(ChamberError::Garbled {
                device: self.description.clone(),
                request: format!("{line}, not sent again"),
                detail: format!("reply {reply:?} is not OK:{line}"),
            }),
            Err(e) if e.kind() == LinkErrorKind::Timeout => Err(ChamberError::Timeout {
                device: self.description.clone(),
                request: format!("{line}, not sent again"),
                timeout_ms: u64::try_from(self.config.reply_timeout.as_millis())
                    .unwrap_or(u64::MAX),
            }),
            Err(e) if e.kind() == LinkErrorKind::Garbled => Err(ChamberError::Garbled {
                device: self.description.clone(),
                request: format!("{line}, not sent again"),
                detail: e.to_string(),
            }),
            Err(e) => Err(self.link_error(line, &e)),
        }
    }

    async fn set_mode(&mut self, mode: ChamberMode) -> Result<(), ChamberError> {
        self.command(&format!("MODE,{}", mode_word(mode))).await?;
        self.last_mode = Some(mode);
        Ok(())
    }

    async fn safe(&mut self, state: SafeState) -> Result<String, String> {
        match state {
            SafeState::Ambient { setpoint_c } => {
                self.last_mode = None; // MODE,CONSTANT is sent whatever was assumed
                self.set_setpoint(setpoint_c)
                    .await
                    .map_err(|e| e.to_string())?;
                let mode = self.mode_note(ChamberMode::Constant).await?;
                Ok(format!(
                    "setpoint {setpoint_c:.1} °C read back by TEMP?; {mode}"
                ))
            }
            SafeState::Standby | SafeState::Off => {
                let mode = if state == SafeState::Off {
                    ChamberMode::Off
                } else {
                    ChamberMode::Standby
                };
                self.set_mode(mode).await.map_err(|e| e.to_string())?;
                self.mode_note(mode).await
            }
        }
    }

    /// How the mode is known after commanding `mode`: read back when `MODE?` is on.
    async fn mode_note(&mut self, mode: ChamberMode) -> Result<String, String> {
        let word = mode_word(mode);
        if !self.config.mode_query {
            return Ok(format!(
                "mode acknowledged OK:MODE,{word} (not read back: mode_query is off)"
            ));
        }
        let read = self
            .query("MODE?", parse_mode)
            .await
            .map_err(|e| e.to_string())?;
        if read == mode {
            Ok(format!("mode {read} read back by MODE?"))
        } else {
            Err(format!("MODE,{word} acknowledged but MODE? reads {read}"))
        }
    }
}

impl<T: Transport> Chamber for Espec<T> {
    fn describe(&self) -> &str {
        &self.description
    }

    async fn connect(&mut self) -> Result<ChamberIdentity, ChamberError> {
        let identity = self
            .query("TYPE?", |r| {
                if r.trim().is_empty() {
                    Err("empty".to_string())
                } else {
                    Ok(r.trim().to_string())
                }
            })
            .await?;
        let temp = self.query("TEMP?", parse_temp).await?;
        let min_c = self.config.min_c.max(temp.lower);
        let max_c = self.config.max_c.min(temp.upper);
        if min_c >= max_c {
            return Err(ChamberError::Setup {
                device: self.description.clone(),
                what: format!(
                    "no setpoint is allowed: the limits {} .. {} °C and the controller's alarm \
                     temperatures {} .. {} °C do not overlap",
                    self.config.min_c, self.config.max_c, temp.lower, temp.upper
                ),
            });
        }
        self.limits = (min_c, max_c);
        Ok(ChamberIdentity {
            model: "Espec (SH-641/SU text protocol, experimental)".into(),
            detail: format!(
                "TYPE? {identity}; alarm temperatures {} .. {} °C; setpoint limits {min_c} .. \
                 {max_c} °C",
                temp.lower, temp.upper
            ),
        })
    }

    async fn set_setpoint(&mut self, setpoint_c: f64) -> Result<(), ChamberError> {
        let (lo, hi) = self.limits;
        if !setpoint_c.is_finite() || setpoint_c < lo || setpoint_c > hi {
            return Err(ChamberError::Limit {
                device: self.description.clone(),
                what: format!("setpoint {setpoint_c} °C is outside the limits {lo} .. {hi} °C"),
            });
        }
        let line = format!("TEMP,S{setpoint_c:.1}");
        self.command(&line).await?;
        if self.last_mode != Some(ChamberMode::Constant) {
            self.set_mode(ChamberMode::Constant).await?;
        }
        let temp = self.query("TEMP?", parse_temp).await?;
        if (temp.setpoint - setpoint_c).abs() > 0.051 {
            return Err(ChamberError::Instrument {
                device: self.description.clone(),
                request: line,
                reason: format!("TEMP? reads the setpoint {} °C instead", temp.setpoint),
            });
        }
        Ok(())
    }

    async fn read(&mut self) -> Result<ChamberReading, ChamberError> {
        let temp = self.query("TEMP?", parse_temp).await?;
        let mode = if self.config.mode_query {
            self.query("MODE?", parse_mode).await?
        } else {
            self.last_mode.unwrap_or(ChamberMode::Constant)
        };
        let alarms = if self.config.alarm_query {
            self.query("ALARM?", parse_alarms).await?
        } else {
            Vec::new()
        };
        Ok(ChamberReading {
            air_c: temp.measured,
            product_c: None,
            setpoint_c: temp.setpoint,
            mode,
            alarms,
        })
    }

    async fn reset_alarms(&mut self) -> Result<(), ChamberError> {
        Err(ChamberError::Unsupported {
            device: self.description.clone(),
            what: "resetting alarms (no confirmed command: reset them at the chamber's panel)"
                .into(),
        })
    }

    async fn go_safe(&mut self, state: SafeState) -> SafeReport {
        let (confirmed, detail) = match self.safe(state).await {
            Ok(d) => (true, d),
            Err(d) => (false, d),
        };
        SafeReport {
            state,
            confirmed,
            detail,
        }
    }

    fn timing(&self) -> ChamberTiming {
        // A query line and its reply: `TEMP?` CR LF (7) and about 24 characters back, 11 bits
        // each on the link's 8N2 framing, plus the latency.
        let char_s = 11.0 / f64::from(self.config.baud.max(1));
        let one = |chars: f64| Duration::from_secs_f64(chars * char_s) + self.config.reply_latency;
        let mut read = one(7.0 + 24.0);
        if self.config.mode_query {
            read += one(7.0 + 10.0);
        }
        if self.config.alarm_query {
            read += one(8.0 + 10.0);
        }
        ChamberTiming {
            read,
            reply_timeout: self.config.reply_timeout,
        }
    }

    fn take_retries(&mut self) -> Vec<String> {
        std::mem::take(&mut self.retry_notes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn replies_parse_or_say_why() {
        assert_eq!(
            parse_temp("23.4,25.0,100.0,-40.0"),
            Ok(Temp {
                measured: 23.4,
                setpoint: 25.0,
                upper: 100.0,
                lower: -40.0
            })
        );
        assert!(parse_temp("23.4,25.0").unwrap_err().contains("2 fields"));
        assert!(parse_temp("x,25.0,1,2").unwrap_err().contains("measured"));
        assert!(parse_temp("NaN,25.0,1,2").is_err());
        assert_eq!(parse_mode("RUN 3"), Ok(ChamberMode::Profile));
        assert!(parse_mode("DANCING").is_err());
        assert_eq!(parse_alarms("0"), Ok(vec![]));
        assert_eq!(
            parse_alarms("2,1,5"),
            Ok(vec!["alarm code 1".to_string(), "alarm code 5".to_string()])
        );
        assert!(parse_alarms("3,1").is_err());
        assert!(parse_alarms("99999").is_err());
    }
}
