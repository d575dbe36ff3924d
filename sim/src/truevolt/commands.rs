//! The Truevolt's commands: headers made canonical (short forms, upper case, the optional
//! `[:SENSe]` and `[:DC]` nodes dropped) and what each command does to the instrument; a
//! command it does not know, or a parameter out of its range, queues the standard SCPI error.

use tokio::time::Instant;

use super::{Meter, Personality, Settings, Waiting};
use crate::scpi::{boolean, format_reading, number};

impl Meter {
    pub(super) fn run_command(
        &mut self,
        h: &str,
        p: &[&str],
        now: Instant,
    ) -> Result<(), (i32, &'static str)> {
        let first = p.first().copied().unwrap_or("");
        match h {
            "*IDN?" => {
                let text = match self.personality {
                    Personality::Hp34401a => "HEWLETT-PACKARD,34401A,0,11-5-2".to_string(),
                    Personality::Def => format!(
                        "Keysight Technologies,{},{},A.03.01-03.15-03.01-00.52-03-02",
                        self.cfg.model.name(),
                        self.cfg.serial
                    ),
                };
                self.reply(text, &[], now);
            }
            "*RST" => {
                self.set = Settings::default();
                self.config_changed();
            }
            "*CLS" => {
                self.errors.clear();
                self.esr.clear();
                self.ques = 0;
            }
            "*OPC?" => self.waiting = Some(Waiting::Opc),
            "*ESR?" => {
                let v = self.esr.read();
                self.reply(v, &[], now);
            }
            "SYST:ERR?" => {
                let entry = self.errors.next_reply();
                self.reply(entry, &[], now);
            }
            "SYST:IDEN" => {
                self.personality = match first.to_ascii_uppercase().as_str() {
                    "DEF" | "DEFAULT" => Personality::Def,
                    "HP34401A" => Personality::Hp34401a,
                    _ => return Err((-224, "Illegal parameter value")),
                };
            }
            "SYST:IDEN?" => {
                let text = match self.personality {
                    Personality::Def => "DEF",
                    Personality::Hp34401a => "HP34401A",
                };
                self.reply(text.into(), &[], now);
            }
            "CONF:VOLT" => {
                // CONFigure sets every measurement parameter to its default
                self.set = Settings::default();
                self.set.range = match first.to_ascii_uppercase().as_str() {
                    "" | "AUTO" | "DEF" => None,
                    r => Some(self.check_range(number(r)?)?),
                };
                self.config_changed();
            }
            "VOLT:RANG" => {
                self.set.range = Some(self.check_range(number(first)?)?);
                self.config_changed();
            }
            "VOLT:RANG:AUTO" => {
                if boolean(first)? {
                    self.set.range = None;
                }
                self.config_changed();
            }
            "VOLT:NPLC" => {
                let v = number(first)?;
                if !self.cfg.model.nplc_values().contains(&v) {
                    return Err((-222, "Data out of range"));
                }
                self.set.nplc = v;
                self.config_changed();
            }
            "VOLT:ZERO:AUTO" => {
                self.set.autozero = boolean(first)?;
                self.config_changed();
            }
            "TRIG:SOUR" => {
                if !matches!(first.to_ascii_uppercase().as_str(), "IMM" | "IMMEDIATE") {
                    return Err((-221, "Settings conflict"));
                }
            }
            "TRIG:DEL" => {
                let d = number(first)?;
                if !(0.0..=3600.0).contains(&d) {
                    return Err((-222, "Data out of range"));
                }
                self.set.trig_delay = Some(d);
                self.config_changed();
            }
            "TRIG:DEL:AUTO" => {
                if boolean(first)? {
                    self.set.trig_delay = None;
                }
                self.config_changed();
            }
            "TRIG:COUN" => {
                if number(first)? != 1.0 {
                    return Err((-221, "Settings conflict"));
                }
            }
            "SAMP:COUN" => {
                let n = number(first)?;
                if !(1.0..=1e6).contains(&n) || n.fract() != 0.0 {
                    return Err((-222, "Data out of range"));
                }
                #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                {
                    self.set.samp_count = n as usize;
                }
                self.config_changed();
            }
            "INIT" => {
                if self.meas.is_some() {
                    return Err((-213, "Init ignored"));
                }
                self.start_measurement(now);
            }
            "ABOR" => self.meas = None,
            "READ?" => {
                if self.meas.is_none() {
                    self.start_measurement(now);
                }
                self.waiting = Some(Waiting::Fetch);
            }
            "FETC?" => self.waiting = Some(Waiting::Fetch),
            "DATA:REM?" => {
                let n = number(first)?;
                let wait = p.get(1).is_some_and(|w| w.eq_ignore_ascii_case("WAIT"));
                if n < 1.0 || n.fract() != 0.0 || n > self.capacity() as f64 {
                    return Err((-222, "Data out of range"));
                }
                #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                let n = n as usize;
                if !wait && self.memory.len() < n {
                    return Err((-222, "Data out of range"));
                }
                self.waiting = Some(Waiting::Remove(n));
            }
            "R?" => {
                let max = if first.is_empty() {
                    self.memory.len()
                } else {
                    let m = number(first)?;
                    if m < 1.0 {
                        return Err((-222, "Data out of range"));
                    }
                    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                    {
                        (m as usize).min(self.memory.len())
                    }
                };
                let items: Vec<(f64, u64)> = self.memory.drain(..max).collect();
                let numbers: Vec<u64> = items.iter().map(|i| i.1).collect();
                let data = Self::readings_text(&items);
                let len = data.len().to_string();
                self.reply(format!("#{}{len}{data}", len.len()), &numbers, now);
            }
            "DATA:POIN?" => {
                let n = self.memory.len();
                self.reply(format!("{n:+}"), &[], now);
            }
            "DATA:LAST?" => match self.memory.back().copied() {
                Some((v, number)) => {
                    self.reply(format!("{} VDC", format_reading(v)), &[number], now)
                }
                None => self.reply("9.91000000E+37".into(), &[], now),
            },
            "STAT:QUES:COND?" => {
                let q = self.ques;
                self.reply(format!("{q:+}"), &[], now);
            }
            "STAT:QUES?" => {
                let q = self.ques;
                self.ques = 0;
                self.reply(format!("{q:+}"), &[], now);
            }
            _ => return Err((-113, "Undefined header")),
        }
        Ok(())
    }

    fn check_range(&self, r: f64) -> Result<f64, (i32, &'static str)> {
        gyrocal_truevolt::facts::RANGES_V
            .iter()
            .copied()
            .find(|&x| r <= x * 1.2 && r > 0.0)
            .ok_or((-222, "Data out of range"))
    }
}

/// Canonical header: short forms, upper case, optional nodes dropped.
pub(super) fn canonical(header: &str) -> String {
    const WORDS: [(&str, &str); 29] = [
        ("CONF", "CONFIGURE"),
        ("VOLT", "VOLTAGE"),
        ("RANG", "RANGE"),
        ("NPLC", "NPLCYCLES"),
        ("ZERO", "ZERO"),
        ("AUTO", "AUTO"),
        ("TRIG", "TRIGGER"),
        ("SOUR", "SOURCE"),
        ("DEL", "DELAY"),
        ("COUN", "COUNT"),
        ("SAMP", "SAMPLE"),
        ("INIT", "INITIATE"),
        ("ABOR", "ABORT"),
        ("READ", "READ"),
        ("FETC", "FETCH"),
        ("DATA", "DATA"),
        ("REM", "REMOVE"),
        ("POIN", "POINTS"),
        ("LAST", "LAST"),
        ("SYST", "SYSTEM"),
        ("ERR", "ERROR"),
        ("IDEN", "IDENTIFY"),
        ("STAT", "STATUS"),
        ("QUES", "QUESTIONABLE"),
        ("COND", "CONDITION"),
        ("EVEN", "EVENT"),
        ("NEXT", "NEXT"),
        ("SENS", "SENSE"),
        ("IMM", "IMMEDIATE"),
    ];
    let h = header.trim().trim_start_matches(':').to_ascii_uppercase();
    let (h, query) = match h.strip_suffix('?') {
        Some(h) => (h.to_string(), "?"),
        None => (h, ""),
    };
    if h.starts_with('*') {
        return format!("{h}{query}");
    }
    let mut out: Vec<String> = Vec::new();
    for seg in h.split(':') {
        let word = WORDS
            .iter()
            .find(|(s, l)| seg == *s || seg == *l)
            .map(|(s, _)| s.to_string())
            .unwrap_or_else(|| seg.to_string());
        let prev = out.last().map(String::as_str);
        let optional = (word == "SENS" && out.is_empty())
            || (word == "DC" && prev == Some("VOLT"))
            || (word == "NEXT" && prev == Some("ERR"))
            || (word == "EVEN" && prev == Some("QUES"))
            || (word == "IMM" && prev == Some("INIT"));
        if !optional {
            out.push(word);
        }
    }
    format!("{}{query}", out.join(":"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn headers_are_canonical() {
        assert_eq!(canonical(":SENSe:VOLTage:DC:NPLCycles"), "VOLT:NPLC");
        assert_eq!(canonical("volt:dc:nplc"), "VOLT:NPLC");
        assert_eq!(canonical("DATA:REMove?"), "DATA:REM?");
        assert_eq!(canonical("SYSTem:ERRor:NEXT?"), "SYST:ERR?");
        assert_eq!(canonical("*idn?"), "*IDN?");
        assert_eq!(canonical("CONF:VOLT:DC"), "CONF:VOLT");
        assert_eq!(canonical("STAT:QUES:EVEN?"), "STAT:QUES?");
    }
}
