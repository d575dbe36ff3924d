//! The 34401A's commands: what each program message unit does to the meter (the common
//! commands, `SYSTem`, `CONFigure`/`MEASure` settings, triggering, `INIT`/`READ?`/`FETCh?`),
//! and the parameter rules (numbers with a unit, booleans, counts, ranges, resolution to NPLC)
//! whose violations queue the standard SCPI errors.

use tokio::time::Instant;

use super::parse::{Cmd, Unit};
use super::{Dest, MEMORY_SIZE, Meter, Settings, TrigSource, Zero};
use crate::scpi::{ReplyFault, boolean, format_nr3, format_reading, garbled, keyword, number};

impl Meter {
    pub(super) fn command(
        &mut self,
        cmd: Cmd,
        u: &Unit,
        now: Instant,
    ) -> Result<(), (i32, &'static str)> {
        let q = u.query;
        let p = &u.params;
        let no_params = || {
            if p.is_empty() {
                Ok(())
            } else {
                Err((-108, "Parameter not allowed"))
            }
        };
        let one = || match p.as_slice() {
            [x] => Ok(x.as_str()),
            [] => Err((-109, "Missing parameter")),
            _ => Err((-108, "Parameter not allowed")),
        };
        match (cmd, q) {
            (Cmd::Idn, true) => {
                no_params()?;
                let id = self.cfg.identity.clone();
                self.reply(&id);
            }
            (Cmd::Rst, false) => {
                no_params()?;
                self.set = Settings::default();
                self.memory.clear();
                self.memory_fault = None;
            }
            (Cmd::Cls, false) => {
                no_params()?;
                self.errors.clear();
                self.esr.clear();
            }
            (Cmd::Opc, true) => self.reply("1"),
            (Cmd::Opc | Cmd::Ese | Cmd::Sre, false) => {}
            (Cmd::Esr, true) => {
                let v = self.esr.read();
                self.reply(&v);
            }
            (Cmd::Stb | Cmd::Ese | Cmd::Sre | Cmd::Tst, true) => self.reply("+0"),
            (Cmd::Trg, false) => return Err((-211, "Trigger ignored")),
            (Cmd::Remote, false) => self.remote = true,
            (Cmd::Rwlock, false) => self.remote = true,
            (Cmd::Local, false) => self.remote = false,
            (Cmd::Error, true) => {
                let entry = self.errors.next_reply();
                self.reply(&entry);
            }
            (Cmd::Version, true) => self.reply("1992.0"),
            (Cmd::Configure, false) => self.configure(p)?,
            (Cmd::Configure, true) => {
                let r = self.set.range.unwrap_or(10.0);
                let res = r * resolution_ratio(self.set.nplc);
                self.reply(&format!("\"VOLT {},{}\"", format_nr3(r), format_nr3(res)));
            }
            (Cmd::Measure, true) => {
                self.configure(p)?;
                self.start_read(now);
            }
            (Cmd::Function, false) => {
                let f = one()?.trim_matches(['"', '\'']).to_ascii_uppercase();
                if !matches!(f.as_str(), "VOLT" | "VOLT:DC" | "VOLTAGE" | "VOLTAGE:DC") {
                    return Err((-224, "Illegal parameter value"));
                }
            }
            (Cmd::Function, true) => self.reply("\"VOLT\""),
            (Cmd::Range, false) => {
                self.set.range = Some(match keyword(one()?).as_str() {
                    "MIN" => 0.1,
                    "MAX" => 1000.0,
                    "DEF" => 10.0,
                    _ => pick_range(number(one()?)?)?,
                });
            }
            (Cmd::Range, true) => {
                let r = self.set.range.unwrap_or(10.0);
                self.reply(&format_nr3(r));
            }
            (Cmd::RangeAuto, false) => {
                if boolean(one()?)? {
                    self.set.range = None;
                } else if self.set.range.is_none() {
                    self.set.range = Some(10.0);
                }
            }
            (Cmd::RangeAuto, true) => self.reply(bool01(self.set.range.is_none())),
            (Cmd::Nplc, false) => {
                let v = match keyword(one()?).as_str() {
                    "MIN" => 0.02,
                    "MAX" => 100.0,
                    "DEF" => 10.0,
                    _ => number(one()?)?,
                };
                if ![0.02, 0.2, 1.0, 10.0, 100.0].contains(&v) {
                    return Err((-222, "Data out of range"));
                }
                self.set.nplc = v;
            }
            (Cmd::Nplc, true) => {
                let v = self.set.nplc;
                self.reply(&format_nr3(v));
            }
            (Cmd::Resolution, false) => {
                let r = number(one()?)?;
                self.set.nplc = nplc_for_resolution(r / self.set.range.unwrap_or(10.0));
            }
            (Cmd::Resolution, true) => {
                let r = self.set.range.unwrap_or(10.0) * resolution_ratio(self.set.nplc);
                self.reply(&format_nr3(r));
            }
            (Cmd::ZeroAuto, false) => {
                self.set.zero = match keyword(one()?).as_str() {
                    "ON" | "1" => Zero::On,
                    "OFF" | "0" => Zero::Off,
                    "ONCE" => Zero::Once,
                    _ => return Err((-224, "Illegal parameter value")),
                };
            }
            (Cmd::ZeroAuto, true) => self.reply(bool01(self.set.zero == Zero::On)),
            (Cmd::ImpedanceAuto, false) => self.set.imp_auto = boolean(one()?)?,
            (Cmd::ImpedanceAuto, true) => self.reply(bool01(self.set.imp_auto)),
            (Cmd::TrigSource, false) => {
                self.set.trig_source = match keyword(one()?).as_str() {
                    "IMM" | "IMMEDIATE" => TrigSource::Imm,
                    "BUS" => TrigSource::Bus,
                    "EXT" | "EXTERNAL" => TrigSource::Ext,
                    _ => return Err((-224, "Illegal parameter value")),
                };
            }
            (Cmd::TrigSource, true) => {
                let s = match self.set.trig_source {
                    TrigSource::Imm => "IMM",
                    TrigSource::Bus => "BUS",
                    TrigSource::Ext => "EXT",
                };
                self.reply(s);
            }
            (Cmd::TrigDelay, false) => {
                let d = match keyword(one()?).as_str() {
                    "MIN" => 0.0,
                    "MAX" => 3600.0,
                    _ => number(one()?)?,
                };
                if !(0.0..=3600.0).contains(&d) {
                    return Err((-222, "Data out of range"));
                }
                self.set.trig_delay = Some(d);
            }
            (Cmd::TrigDelay, true) => {
                let d = self
                    .trigger_delay()
                    .mul_f64(self.cfg.time_scale)
                    .as_secs_f64();
                self.reply(&format_nr3(d));
            }
            (Cmd::TrigDelayAuto, false) => {
                if boolean(one()?)? {
                    self.set.trig_delay = None;
                } else if self.set.trig_delay.is_none() {
                    let d = self
                        .trigger_delay()
                        .mul_f64(self.cfg.time_scale)
                        .as_secs_f64();
                    self.set.trig_delay = Some(d);
                }
            }
            (Cmd::TrigDelayAuto, true) => self.reply(bool01(self.set.trig_delay.is_none())),
            (Cmd::TrigCount, false) => self.set.trig_count = count(one()?)?,
            (Cmd::TrigCount, true) => self.reply(&format!("{:+}", self.set.trig_count)),
            (Cmd::SampleCount, false) => self.set.samp_count = count(one()?)?,
            (Cmd::SampleCount, true) => self.reply(&format!("{:+}", self.set.samp_count)),
            (Cmd::Init, false) => {
                no_params()?;
                let total = u64::from(self.set.samp_count) * u64::from(self.set.trig_count);
                if total > MEMORY_SIZE as u64 {
                    return Err((531, "Insufficient memory"));
                }
                self.begin_measurement(Dest::Memory, now);
            }
            (Cmd::Read, true) => {
                no_params()?;
                self.start_read(now);
            }
            (Cmd::Fetch, true) => {
                no_params()?;
                if self.memory.is_empty() {
                    return Err((-230, "Data stale"));
                }
                let mut fields: Vec<String> =
                    self.memory.iter().map(|&v| format_reading(v)).collect();
                match self.memory_fault.take() {
                    Some((i, ReplyFault::Garble)) => {
                        if let Some(f) = fields.get_mut(i) {
                            *f = garbled(f.as_bytes());
                        }
                    }
                    Some((_, other)) if !self.exec.as_ref().is_some_and(|e| e.has_output) => {
                        self.pending_reply_fault.push_front(other);
                    }
                    Some(_) | None => {}
                }
                self.reply(&fields.join(","));
            }
            (Cmd::DataPoints, true) => {
                let n = self.memory.len();
                self.reply(&format!("{n:+}"));
            }
            (Cmd::Display, false) => self.set.display = boolean(one()?)?,
            (Cmd::Display, true) => self.reply(bool01(self.set.display)),
            (Cmd::DisplayText, false) => {
                let t = one()?.trim_matches(['"', '\'']);
                if t.len() > 12 {
                    return Err((-223, "Too much data"));
                }
            }
            (Cmd::DisplayText, true) => self.reply("\"\""),
            (Cmd::DisplayTextClear, false) => {}
            _ => return Err((-113, "Undefined header")),
        }
        Ok(())
    }

    fn start_read(&mut self, now: Instant) {
        self.counters.queries_answered += 1;
        self.begin_measurement(Dest::Output, now);
    }

    /// `CONFigure:VOLTage:DC [range[,resolution]]` and its presets.
    fn configure(&mut self, p: &[String]) -> Result<(), (i32, &'static str)> {
        if p.len() > 2 {
            return Err((-108, "Parameter not allowed"));
        }
        let range = match p.first().map(|s| keyword(s)) {
            None => None,
            Some(k) if k == "DEF" || k == "AUTO" => None,
            Some(k) if k == "MIN" => Some(0.1),
            Some(k) if k == "MAX" => Some(1000.0),
            Some(_) => Some(pick_range(number(&p[0])?)?),
        };
        let nplc = match p.get(1).map(|s| keyword(s)) {
            None => 10.0,
            Some(k) if k == "DEF" => 10.0,
            Some(k) if k == "MIN" => 100.0,
            Some(k) if k == "MAX" => 0.02,
            Some(_) => nplc_for_resolution(number(&p[1])? / range.unwrap_or(10.0)),
        };
        self.set.range = range;
        self.set.nplc = nplc;
        self.set.samp_count = 1;
        self.set.trig_count = 1;
        self.set.trig_source = TrigSource::Imm;
        self.set.trig_delay = None;
        self.set.zero = if nplc >= 1.0 { Zero::On } else { Zero::Off };
        self.set.imp_auto = false;
        Ok(())
    }
}

fn count(s: &str) -> Result<u32, (i32, &'static str)> {
    let k = keyword(s);
    let v = match k.as_str() {
        "MIN" => 1.0,
        "MAX" => 50_000.0,
        _ => number(s)?,
    };
    if !(1.0..=50_000.0).contains(&v) || v.fract() != 0.0 {
        return Err((-222, "Data out of range"));
    }
    Ok(v as u32)
}

fn bool01(b: bool) -> &'static str {
    if b { "1" } else { "0" }
}

/// The smallest range that holds `v` volts.
fn pick_range(v: f64) -> Result<f64, (i32, &'static str)> {
    let v = v.abs();
    [0.1, 1.0, 10.0, 100.0, 1000.0]
        .into_iter()
        .find(|&r| v <= r * 1.2)
        .ok_or((-222, "Data out of range"))
}

/// Resolution as a fraction of the range for each NPLC (User's Guide, resolution table).
fn resolution_ratio(nplc: f64) -> f64 {
    match nplc {
        n if n <= 0.02 => 1e-4,
        n if n <= 0.2 => 1e-5,
        n if n <= 1.0 => 3e-6,
        n if n <= 10.0 => 1e-6,
        _ => 3e-7,
    }
}

fn nplc_for_resolution(ratio: f64) -> f64 {
    [(1e-4, 0.02), (1e-5, 0.2), (3e-6, 1.0), (1e-6, 10.0)]
        .into_iter()
        .find(|&(r, _)| ratio >= r * 0.999)
        .map_or(100.0, |(_, n)| n)
}
