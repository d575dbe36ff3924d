//! The station file: the bench a run is made on, and its instruments' calibration records.
//!
//! A calibration certificate names the laboratory and its address, the conditions of the
//! measurement, and how traceability is achieved: every instrument used, with its serial, the
//! date it was calibrated and until when the calibration is valid (ISO/IEC 17025:2017 §7.8.2.1,
//! §7.8.4). None of that belongs in a plan (one plan serves many benches), so it lives in a
//! station file, one per bench:
//!
//! ```toml
//! id = "bench-2"
//! lab = "Inertial Sensors Lab"
//! address = "1 Example Road, Springfield"
//! ambient_c = 23.0          # optional, typical conditions
//! humidity_pct = 45         # optional
//!
//! [multimeter]
//! model = "HP 34401A"
//! asset_id = "DMM-07"
//! serial = "3146A12345"
//! certificate = "CAL-2025-0412"
//! calibrated = 2025-04-12
//! due = 2026-04-12
//! accuracy = "1y"           # the DC V specification period: "24h", "90d" or "1y"
//!
//! [table]
//! model = "Acutronic AC1120S"
//! asset_id = "RT-01"
//! serial = "1120-0031"
//! certificate = "CAL-2024-1107"
//! calibrated = 2024-11-07
//! due = 2026-11-07
//! rate_accuracy_ppm = 10
//!
//! [chamber]                 # the thermal chamber of a temperature series
//! model = "Thermotron SE-600 (Watlow F4)"
//! asset_id = "TC-03"
//! serial = "SE600-1187"
//! certificate = "CAL-2025-0930"
//! calibrated = 2025-09-30
//! due = 2026-09-30
//! ```
//!
//! Dates are TOML dates (`2026-04-12`) or the same as text (`"2026-04-12"`). Every key of an
//! instrument is required except `accuracy`, `gain_pct`/`offset_pct` (multimeter only, given
//! together: an explicit accuracy that overrides the period) and `rate_accuracy_ppm` (table
//! only); a `[chamber]` has the six common keys only (the temperatures a series uses are the
//! gyro's own sensor's, read through the controller: no accuracy is taken from the chamber's
//! record). `catalog` is reserved for the address of a lab's instrument catalog (a later
//! version may read the records from it); it is kept and shown, never fetched. `serve` is the
//! address of the lab's live view (`serve = "http://lab-view:8737"`, a `gyrocal serve` on the
//! shared catalog): `gyrocal run` prints the run's page there and starts nothing. Unknown keys are
//! refused, naming the file, the line and the key.
//!
//! Where it is found ([`Station::resolve`]): the `--station` flag, else the
//! [`STATION_ENV`] variable, else [`Station::default_path`] when that file exists. A path given
//! by the flag or the variable must exist.
//!
//! A calibration is valid through its due date: an instrument is overdue the day after
//! ([`Station::overdue`]). A `calibrated` date after today is refused, naming the instrument:
//! it is a typing error (or a wrong clock), and a certificate would otherwise claim a
//! calibration that had not happened yet. The file must be a regular file: a named pipe or a
//! device is refused before it is opened (opening a pipe would wait for a writer forever).
//! A station without a `[multimeter]` (or, for a plan with a table, a `[table]`; for a
//! temperature series, a `[chamber]`) section is accepted, and `gyrocal run` and `gyrocal
//! check` say at the terminal what is missing ([`Station::missing_sections`], with the plan's
//! [`Needs`]); an overdue instrument the plan uses refuses the run ([`Station::overdue_for`]).
//!
//! The serials are checked against the instruments ([`Station::check_serials`], in
//! `serials`): once the instruments have identified themselves, a serial that differs from
//! the record is a warning and a recorded deviation, since the certificate would otherwise
//! name another instrument's calibration. A chamber's controller identifies itself by model
//! only: [`Station::check_chamber`] (in `chamber`) compares the record's model with it.
//! Where the file is found and the simulated bench's station are in `resolve`.

mod chamber;
mod resolve;
mod serials;

pub use chamber::{Needs, SERIES_KIND};
pub use serials::{SERIAL_MISMATCH, SerialCheck, reported_serial};

use std::fmt;
use std::ops::Range;
use std::path::{Path, PathBuf};

use jiff::civil::Date;
use serde::{Deserialize, Serialize};
use toml::de::{DeTable, DeValue};

use crate::plan::{Location, ReadFailure, and_list, closest, read_capped_text};

/// The environment variable naming the station file (after `--station`, before the default
/// path).
pub const STATION_ENV: &str = "GYROCAL_STATION";
/// The largest station file read: 1 MiB (a station file is a few hundred bytes).
pub const MAX_STATION_BYTES: u64 = 1024 * 1024;

// ---------------------------------------------------------------------------------------------
// Types
// ---------------------------------------------------------------------------------------------

/// The period of a multimeter's accuracy specification since its calibration (the HP 34401A's
/// DC V table has 24-hour, 90-day and 1-year columns). `24h`, `90d` or `1y` in files.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum SpecPeriod {
    /// 24 hours (`24h`).
    #[serde(rename = "24h")]
    Hours24,
    /// 90 days (`90d`).
    #[serde(rename = "90d")]
    Days90,
    /// One year (`1y`).
    #[serde(rename = "1y")]
    Year1,
}

impl SpecPeriod {
    /// Every period, shortest first.
    pub const ALL: [SpecPeriod; 3] = [SpecPeriod::Hours24, SpecPeriod::Days90, SpecPeriod::Year1];

    /// `24h`, `90d` or `1y`.
    pub fn as_str(self) -> &'static str {
        match self {
            SpecPeriod::Hours24 => "24h",
            SpecPeriod::Days90 => "90d",
            SpecPeriod::Year1 => "1y",
        }
    }

    /// The period named `name` (as [`SpecPeriod::as_str`], ASCII case-insensitive).
    pub fn from_name(name: &str) -> Option<SpecPeriod> {
        SpecPeriod::ALL
            .into_iter()
            .find(|p| p.as_str().eq_ignore_ascii_case(name.trim()))
    }
}

impl fmt::Display for SpecPeriod {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// The multimeter's accuracy, as the station states it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MeterAccuracySpec {
    /// `gain_pct` (% of reading) and `offset_pct` (% of range), given explicitly.
    Explicit {
        /// % of reading.
        gain_pct: f64,
        /// % of range.
        offset_pct: f64,
    },
    /// The model's specification for this period since calibration.
    Period(SpecPeriod),
}

/// One instrument's identity and calibration record.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InstrumentRecord {
    /// Make and model, e.g. `HP 34401A`.
    pub model: String,
    /// The lab's asset number.
    pub asset_id: String,
    /// The maker's serial number.
    pub serial: String,
    /// The calibration certificate's number.
    pub certificate: String,
    /// When it was calibrated (`YYYY-MM-DD`).
    #[serde(with = "date_text")]
    pub calibrated: Date,
    /// The last day the calibration is valid (`YYYY-MM-DD`).
    #[serde(with = "date_text")]
    pub due: Date,
    /// Multimeter only: the DC V specification period the uncertainty budget uses.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub accuracy: Option<SpecPeriod>,
    /// Multimeter only: explicit accuracy, % of reading (overrides `accuracy`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gain_pct: Option<f64>,
    /// Multimeter only: explicit accuracy, % of range (given with `gain_pct`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub offset_pct: Option<f64>,
    /// Table only: rate accuracy, ppm of rate (datasheet or calibration).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rate_accuracy_ppm: Option<f64>,
}

/// The bench: laboratory, conditions and instruments. See the module docs for the file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Station {
    /// The bench's name, e.g. `bench-2`.
    pub id: String,
    /// The laboratory's name.
    pub lab: String,
    /// The laboratory's address.
    pub address: String,
    /// Typical ambient temperature, °C.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ambient_c: Option<f64>,
    /// Typical relative humidity, %.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub humidity_pct: Option<f64>,
    /// Reserved: the address of the lab's instrument catalog (kept and shown, never fetched).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub catalog: Option<String>,
    /// The lab's live view (`http://` or `https://`, a `gyrocal serve`): `gyrocal run` prints
    /// the run's page on it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub serve: Option<String>,
    /// `[multimeter]`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub multimeter: Option<InstrumentRecord>,
    /// `[table]`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub table: Option<InstrumentRecord>,
    /// `[chamber]`: the thermal chamber of a temperature series.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub chamber: Option<InstrumentRecord>,
}

/// An instrument whose calibration has expired.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Overdue {
    /// `multimeter`, `table` or `chamber`.
    pub role: &'static str,
    /// Its asset number.
    pub asset_id: String,
    /// The last day its calibration was valid.
    #[serde(with = "date_text")]
    pub due: Date,
}

impl fmt::Display for Overdue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "the {} {} was due for calibration on {}",
            self.role, self.asset_id, self.due
        )
    }
}

/// Dates as `YYYY-MM-DD` text in JSON.
mod date_text {
    use jiff::civil::Date;
    use serde::{Deserialize as _, Deserializer, Serializer};

    pub(super) fn serialize<S: Serializer>(d: &Date, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(d)
    }

    pub(super) fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Date, D::Error> {
        let text = String::deserialize(d)?;
        super::parse_date_text(&text).map_err(serde::de::Error::custom)
    }
}

/// `YYYY-MM-DD`, exactly.
fn parse_date_text(text: &str) -> Result<Date, String> {
    let b = text.as_bytes();
    let shaped = b.len() == 10
        && b.iter().enumerate().all(|(i, c)| {
            if i == 4 || i == 7 {
                *c == b'-'
            } else {
                c.is_ascii_digit()
            }
        });
    if !shaped {
        return Err(format!(
            "{text:?} is not a date: write YYYY-MM-DD, e.g. 2026-04-12"
        ));
    }
    text.parse::<Date>()
        .map_err(|e| format!("{text:?} is not a date: {e}"))
}

// ---------------------------------------------------------------------------------------------
// Errors
// ---------------------------------------------------------------------------------------------

/// The kind of a [`StationError`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum StationErrorKind {
    /// The file could not be read.
    Read,
    /// The file is larger than [`MAX_STATION_BYTES`].
    TooLarge,
    /// A path given by `--station` or [`STATION_ENV`] does not exist.
    NotFound,
    /// TOML syntax.
    Syntax,
    /// An unknown, missing or unacceptable key.
    Invalid,
}

/// Everything that can be wrong with a station file; every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum StationError {
    /// The file could not be read (or is not UTF-8 text).
    #[error("{}: cannot read the station file: {source}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// Larger than [`MAX_STATION_BYTES`] (or endless).
    #[error(
        "{}: larger than the {} KiB limit for a station file (a station file is a few hundred bytes); is it the right file?",
        path.display(),
        cap / 1024
    )]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// The limit, bytes.
        cap: u64,
    },
    /// A station file named by `--station` or [`STATION_ENV`] that does not exist.
    #[error("{}: no such station file (given by {origin})", path.display())]
    NotFound {
        /// The path given.
        path: PathBuf,
        /// `--station` or `GYROCAL_STATION`.
        origin: &'static str,
    },
    /// TOML syntax error.
    #[error("{location}: {message}")]
    Syntax {
        /// Where.
        location: Location,
        /// What `toml` said.
        message: String,
    },
    /// An unknown, missing or unacceptable key.
    #[error(
        "{location}: {}{key} {message}",
        section.as_ref().map(|s| format!("[{s}] ")).unwrap_or_default()
    )]
    Invalid {
        /// Where (the value, the key, or the section's header).
        location: Location,
        /// `multimeter`, `table` or `chamber`; `None` for a top-level key.
        section: Option<String>,
        /// The key.
        key: String,
        /// What is wrong.
        message: String,
    },
}

impl StationError {
    /// What kind of error this is.
    pub fn kind(&self) -> StationErrorKind {
        match self {
            StationError::Read { .. } => StationErrorKind::Read,
            StationError::TooLarge { .. } => StationErrorKind::TooLarge,
            StationError::NotFound { .. } => StationErrorKind::NotFound,
            StationError::Syntax { .. } => StationErrorKind::Syntax,
            StationError::Invalid { .. } => StationErrorKind::Invalid,
        }
    }

    /// Where in the file, for the syntax and key errors.
    pub fn location(&self) -> Option<&Location> {
        match self {
            StationError::Syntax { location, .. } | StationError::Invalid { location, .. } => {
                Some(location)
            }
            _ => None,
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Parsing
// ---------------------------------------------------------------------------------------------

/// The top-level keys, in file order.
const TOP_KEYS: [&str; 10] = [
    "id",
    "lab",
    "address",
    "ambient_c",
    "humidity_pct",
    "catalog",
    "serve",
    "multimeter",
    "table",
    "chamber",
];
/// The keys of an instrument table.
const INSTRUMENT_KEYS: [&str; 10] = [
    "model",
    "asset_id",
    "serial",
    "certificate",
    "calibrated",
    "due",
    "accuracy",
    "gain_pct",
    "offset_pct",
    "rate_accuracy_ppm",
];
/// The largest explicit meter accuracy term, %: more is a typo.
const MAX_METER_PCT: f64 = 10.0;
/// The largest table rate accuracy, ppm (100 %).
const MAX_RATE_PPM: f64 = 1_000_000.0;

/// One problem found while walking the file: where (byte offset), the section, the key.
struct Problem {
    /// 0: a wrong key or value; 1: a missing key (reported after every wrong one, as a
    /// misspelt key is also a missing one).
    rank: u8,
    offset: Option<usize>,
    section: Option<&'static str>,
    key: String,
    message: String,
}

/// Walks a parsed station file, keeping every problem; the first in the file is reported.
struct Walker {
    problems: Vec<Problem>,
    /// The calendar day a `calibrated` date may not be after.
    today: Date,
}

type Entry<'a, 'i> = (
    &'a toml::Spanned<toml::de::DeString<'i>>,
    &'a toml::Spanned<DeValue<'i>>,
);

impl Walker {
    fn problem(
        &mut self,
        offset: Option<usize>,
        section: Option<&'static str>,
        key: &str,
        message: String,
    ) {
        self.problems.push(Problem {
            rank: 0,
            offset,
            section,
            key: key.to_string(),
            message,
        });
    }

    /// The value of `key` in `table`, with its span.
    fn get<'a, 'i>(table: &'a DeTable<'i>, key: &str) -> Option<&'a toml::Spanned<DeValue<'i>>> {
        table
            .iter()
            .find(|(k, _)| k.get_ref().as_ref() == key)
            .map(|(_, v)| v)
    }

    /// Refuses keys not in `known`.
    fn unknown_keys(&mut self, table: &DeTable<'_>, section: Option<&'static str>, known: &[&str]) {
        for (k, v) in table.iter() {
            let name: &str = k.get_ref().as_ref();
            if known.contains(&name) {
                continue;
            }
            let where_ = section.map_or_else(|| "a station file".to_string(), |s| format!("[{s}]"));
            let all = format!("the keys of {where_} are {}", and_list(known));
            let hint = match closest(name, known.iter().copied()) {
                Some(c) => format!("did you mean `{c}`? ({all})"),
                None => all,
            };
            let what = if section.is_none() && v.get_ref().is_table() {
                "unknown section"
            } else {
                "unknown key"
            };
            self.problem(
                Some(k.span().start),
                section,
                name,
                format!("is an {what}: {hint}"),
            );
        }
    }

    /// A text value (not empty).
    fn text(
        &mut self,
        section: Option<&'static str>,
        key: &str,
        v: Option<&toml::Spanned<DeValue<'_>>>,
        header: Option<usize>,
    ) -> Option<String> {
        let v = self.required(section, key, v, header)?;
        match v.get_ref() {
            DeValue::String(s) if !s.trim().is_empty() => Some(s.to_string()),
            DeValue::String(_) => {
                self.problem(
                    Some(v.span().start),
                    section,
                    key,
                    "must not be empty".into(),
                );
                None
            }
            other => {
                self.problem(
                    Some(v.span().start),
                    section,
                    key,
                    format!(
                        "= {} is {}: write text in quotes",
                        shown(other),
                        other.type_str()
                    ),
                );
                None
            }
        }
    }

    /// Like [`Walker::problem`], for a missing key.
    fn missing(
        &mut self,
        offset: Option<usize>,
        section: Option<&'static str>,
        key: &str,
        message: String,
    ) {
        self.problems.push(Problem {
            rank: 1,
            offset,
            section,
            key: key.to_string(),
            message,
        });
    }

    fn required<'a, 'i>(
        &mut self,
        section: Option<&'static str>,
        key: &str,
        v: Option<&'a toml::Spanned<DeValue<'i>>>,
        header: Option<usize>,
    ) -> Option<&'a toml::Spanned<DeValue<'i>>> {
        if v.is_none() {
            let under = section.map_or_else(
                || "at the top of the file".to_string(),
                |s| format!("under [{s}]"),
            );
            self.missing(
                header,
                section,
                key,
                format!("is missing (required): add `{key} = ...` {under}"),
            );
        }
        v
    }

    /// An optional number within `lo..=hi`.
    fn number(
        &mut self,
        section: Option<&'static str>,
        key: &str,
        v: Option<&toml::Spanned<DeValue<'_>>>,
        lo: f64,
        hi: f64,
    ) -> Option<f64> {
        let v = v?;
        let n = match v.get_ref() {
            DeValue::Integer(i) => i64::from_str_radix(i.as_str(), i.radix())
                .ok()
                .map(|n| n as f64),
            DeValue::Float(f) => f.as_str().parse::<f64>().ok(),
            DeValue::String(s) if s.trim().parse::<f64>().is_ok() => {
                self.problem(
                    Some(v.span().start),
                    section,
                    key,
                    format!("= {s:?} is text, not a number: write the number without quotes"),
                );
                return None;
            }
            other => {
                self.problem(
                    Some(v.span().start),
                    section,
                    key,
                    format!("= {} is {}: write a number", shown(other), other.type_str()),
                );
                return None;
            }
        };
        match n {
            Some(n) if n.is_finite() && (lo..=hi).contains(&n) => Some(n),
            _ => {
                self.problem(
                    Some(v.span().start),
                    section,
                    key,
                    format!(
                        "= {} is out of range: write a number from {lo} to {hi}",
                        shown(v.get_ref())
                    ),
                );
                None
            }
        }
    }

    /// A required date: a TOML date or `YYYY-MM-DD` text.
    fn date(
        &mut self,
        section: Option<&'static str>,
        key: &str,
        v: Option<&toml::Spanned<DeValue<'_>>>,
        header: Option<usize>,
    ) -> Option<Date> {
        let v = self.required(section, key, v, header)?;
        let at = Some(v.span().start);
        let parsed = match v.get_ref() {
            DeValue::Datetime(dt) => match (dt.date, dt.time, dt.offset) {
                (Some(d), None, None) => {
                    match (
                        i16::try_from(d.year),
                        i8::try_from(d.month),
                        i8::try_from(d.day),
                    ) {
                        (Ok(y), Ok(m), Ok(dd)) => {
                            Date::new(y, m, dd).map_err(|e| format!("= {dt} is not a date: {e}"))
                        }
                        _ => Err(format!("= {dt} is not a date this program handles")),
                    }
                }
                _ => Err(format!(
                    "= {dt} has a time of day: write the date only, e.g. {key} = 2026-04-12"
                )),
            },
            DeValue::String(s) => parse_date_text(s).map_err(|e| format!("= {e}")),
            other => Err(format!(
                "= {} is {}: write a date, e.g. {key} = 2026-04-12",
                shown(other),
                other.type_str()
            )),
        };
        match parsed {
            Ok(d) => Some(d),
            Err(message) => {
                self.problem(at, section, key, message);
                None
            }
        }
    }

    /// An instrument table.
    fn instrument(&mut self, role: &'static str, entry: Entry<'_, '_>) -> Option<InstrumentRecord> {
        let (name, value) = entry;
        let header = Some(name.span().start);
        let Some(t) = value.get_ref().as_table() else {
            self.problem(
                header,
                None,
                role,
                format!("must be a section: write a line [{role}] followed by its keys"),
            );
            return None;
        };
        let s = Some(role);
        self.unknown_keys(t, s, &INSTRUMENT_KEYS);
        let g = |k: &str| Walker::get(t, k);
        let model = self.text(s, "model", g("model"), header);
        let asset_id = self.text(s, "asset_id", g("asset_id"), header);
        let serial = self.text(s, "serial", g("serial"), header);
        let certificate = self.text(s, "certificate", g("certificate"), header);
        let calibrated = self.date(s, "calibrated", g("calibrated"), header);
        let due = self.date(s, "due", g("due"), header);
        // a calibration in the future is a typing error (or a wrong clock): the certificate
        // would state a traceability that did not exist on the day of the measurement
        if let (Some(c), Some(v)) = (calibrated, g("calibrated"))
            && c > self.today
        {
            let instrument = asset_id
                .as_deref()
                .map_or_else(|| format!("the {role}"), |id| format!("the {role} {id}"));
            self.problem(
                Some(v.span().start),
                s,
                "calibrated",
                format!(
                    "= {c} is after today ({}): {instrument} cannot have been calibrated in \
                     the future; correct the date (or the computer's clock)",
                    self.today
                ),
            );
        }
        if let (Some(c), Some(d), Some(v)) = (calibrated, due, g("due"))
            && d < c
        {
            self.problem(
                Some(v.span().start),
                s,
                "due",
                format!("= {d} is before calibrated = {c}"),
            );
        }
        let meter_only = |w: &mut Walker, key: &str, other: &str| {
            if let Some(v) = g(key) {
                w.problem(
                    Some(v.span().start),
                    s,
                    key,
                    format!("belongs to the multimeter; the table's accuracy is {other}"),
                );
            }
        };
        let mut accuracy = None;
        let (mut gain_pct, mut offset_pct, mut rate_accuracy_ppm) = (None, None, None);
        if role == "multimeter" {
            if let Some(v) = g("accuracy") {
                match v.get_ref().as_str().and_then(SpecPeriod::from_name) {
                    Some(p) => accuracy = Some(p),
                    None => self.problem(
                        Some(v.span().start),
                        s,
                        "accuracy",
                        format!(
                            "= {} is not a specification period: write \"24h\", \"90d\" or \"1y\"",
                            shown(v.get_ref())
                        ),
                    ),
                }
            }
            gain_pct = self.number(s, "gain_pct", g("gain_pct"), 0.0, MAX_METER_PCT);
            offset_pct = self.number(s, "offset_pct", g("offset_pct"), 0.0, MAX_METER_PCT);
            match (g("gain_pct"), g("offset_pct")) {
                (Some(_), None) => self.missing(header, s, "offset_pct", "is missing: gain_pct and offset_pct go together (write offset_pct = 0 for none)".into()),
                (None, Some(v)) => self.problem(Some(v.span().start), s, "gain_pct", "is missing: gain_pct and offset_pct go together".into()),
                _ => {}
            }
            if let Some(v) = g("rate_accuracy_ppm") {
                self.problem(
                    Some(v.span().start),
                    s,
                    "rate_accuracy_ppm",
                    "belongs to the table; the multimeter's accuracy is accuracy, or gain_pct and offset_pct".into(),
                );
            }
        } else if role == "chamber" {
            // the chamber's record states no accuracy: name whose key it is
            for (key, owner) in [
                ("accuracy", "the multimeter"),
                ("gain_pct", "the multimeter"),
                ("offset_pct", "the multimeter"),
                ("rate_accuracy_ppm", "the table"),
            ] {
                if let Some(v) = g(key) {
                    self.problem(
                        Some(v.span().start),
                        s,
                        key,
                        format!(
                            "belongs to {owner}; a [chamber] has model, asset_id, serial, \
                             certificate, calibrated and due only"
                        ),
                    );
                }
            }
        } else {
            meter_only(self, "accuracy", "rate_accuracy_ppm");
            meter_only(self, "gain_pct", "rate_accuracy_ppm");
            meter_only(self, "offset_pct", "rate_accuracy_ppm");
            rate_accuracy_ppm = self.number(
                s,
                "rate_accuracy_ppm",
                g("rate_accuracy_ppm"),
                0.0,
                MAX_RATE_PPM,
            );
        }
        Some(InstrumentRecord {
            model: model?,
            asset_id: asset_id?,
            serial: serial?,
            certificate: certificate?,
            calibrated: calibrated?,
            due: due?,
            accuracy,
            gain_pct,
            offset_pct,
            rate_accuracy_ppm,
        })
    }
}

/// A value as it reads in an error message.
fn shown(v: &DeValue<'_>) -> String {
    match v {
        DeValue::String(s) => format!("{:?}", s.as_ref()),
        DeValue::Integer(i) => i.to_string(),
        DeValue::Float(f) => f.to_string(),
        DeValue::Boolean(b) => b.to_string(),
        DeValue::Datetime(d) => d.to_string(),
        DeValue::Array(_) => "a list".into(),
        DeValue::Table(_) => "a table".into(),
    }
}

impl Station {
    /// Reads and validates a station file (at most [`MAX_STATION_BYTES`], a regular file only:
    /// a named pipe or a device is refused before it is opened); errors name `path`. A
    /// `calibrated` date after today (the local calendar day) is refused.
    pub fn from_file(path: &Path) -> Result<Station, StationError> {
        Station::from_file_on(path, jiff::Zoned::now().date())
    }

    /// [`Station::from_file`] with `today` given.
    pub fn from_file_on(path: &Path, today: Date) -> Result<Station, StationError> {
        let src = read_capped_text(path, MAX_STATION_BYTES).map_err(|f| match f {
            ReadFailure::Io(source) => StationError::Read {
                path: path.to_path_buf(),
                source,
            },
            ReadFailure::TooLarge => StationError::TooLarge {
                path: path.to_path_buf(),
                cap: MAX_STATION_BYTES,
            },
        })?;
        Station::from_toml_str_on(&src, path, today)
    }

    /// Parses and validates station text; `name` is the file name used in errors. A
    /// `calibrated` date after today (the local calendar day) is refused.
    pub fn from_toml_str(src: &str, name: &Path) -> Result<Station, StationError> {
        Station::from_toml_str_on(src, name, jiff::Zoned::now().date())
    }

    /// [`Station::from_toml_str`] with `today` given.
    pub fn from_toml_str_on(src: &str, name: &Path, today: Date) -> Result<Station, StationError> {
        let location = |offset: Option<usize>| Location::in_text(name, src, offset);
        let root = DeTable::parse(src).map_err(|e| StationError::Syntax {
            location: location(e.span().map(|s: Range<usize>| s.start)),
            message: e.message().trim().to_string(),
        })?;
        let root = root.get_ref();
        let mut w = Walker {
            problems: Vec::new(),
            today,
        };
        w.unknown_keys(root, None, &TOP_KEYS);
        let g = |k: &str| Walker::get(root, k);
        let id = w.text(None, "id", g("id"), None);
        let lab = w.text(None, "lab", g("lab"), None);
        let address = w.text(None, "address", g("address"), None);
        let ambient_c = w.number(None, "ambient_c", g("ambient_c"), -50.0, 100.0);
        let humidity_pct = w.number(None, "humidity_pct", g("humidity_pct"), 0.0, 100.0);
        let catalog = g("catalog").and_then(|v| w.text(None, "catalog", Some(v), None));
        let serve = g("serve").and_then(|v| {
            let text = w.text(None, "serve", Some(v), None)?;
            let t = text.trim().trim_end_matches('/');
            let rest = t
                .strip_prefix("http://")
                .or_else(|| t.strip_prefix("https://"));
            if rest.is_some_and(|r| !r.is_empty() && !r.contains(char::is_whitespace)) {
                Some(t.to_string())
            } else {
                w.problem(
                    Some(v.span().start),
                    None,
                    "serve",
                    format!(
                        "= {text:?} is not the address of a web view: write \"http://HOST:PORT\" \
                         (a gyrocal serve)"
                    ),
                );
                None
            }
        });
        let entry = |k: &str| root.iter().find(|(n, _)| n.get_ref().as_ref() == k);
        let multimeter = entry("multimeter").and_then(|e| w.instrument("multimeter", e));
        let table = entry("table").and_then(|e| w.instrument("table", e));
        let chamber = entry("chamber").and_then(|e| w.instrument("chamber", e));
        // the first problem in the file (a missing top-level key, placed nowhere, last)
        if let Some(p) = w
            .problems
            .into_iter()
            .min_by_key(|p| (p.rank, p.offset.unwrap_or(usize::MAX)))
        {
            return Err(StationError::Invalid {
                location: location(p.offset),
                section: p.section.map(str::to_string),
                key: p.key,
                message: p.message,
            });
        }
        match (id, lab, address) {
            (Some(id), Some(lab), Some(address)) => Ok(Station {
                id,
                lab,
                address,
                ambient_c,
                humidity_pct,
                catalog,
                serve,
                multimeter,
                table,
                chamber,
            }),
            // every None above recorded a problem
            _ => Err(StationError::Syntax {
                location: location(None),
                message: "incomplete station file".into(),
            }),
        }
    }

    /// The instruments recorded, as `(role, record)`: `multimeter`, `table`, then `chamber`.
    pub fn instruments(&self) -> Vec<(&'static str, &InstrumentRecord)> {
        self.instruments_slots()
            .into_iter()
            .filter_map(|(role, r)| r.map(|r| (role, r)))
            .collect()
    }

    /// The sections a run would need and the file lacks: `multimeter` always, `table` and
    /// `chamber` when the plan `needs` them ([`Needs::of_plan`]). A station without them is
    /// accepted (a bench may record only some instruments) but the certificate cannot name
    /// what is missing, so the CLI says so at the terminal.
    pub fn missing_sections(&self, needs: Needs) -> Vec<&'static str> {
        self.instruments_slots()
            .into_iter()
            .filter(|(role, r)| needs.uses(role) && r.is_none())
            .map(|(role, _)| role)
            .collect()
    }

    /// Every role with its record or none, in the order of [`Station::instruments`].
    fn instruments_slots(&self) -> [(&'static str, Option<&InstrumentRecord>); 3] {
        [
            ("multimeter", self.multimeter.as_ref()),
            ("table", self.table.as_ref()),
            ("chamber", self.chamber.as_ref()),
        ]
    }

    /// The instruments whose calibration has expired on `today`: due before today. A
    /// calibration is valid through its due date, so `due == today` is not overdue.
    pub fn overdue(&self, today: Date) -> Vec<Overdue> {
        self.instruments()
            .into_iter()
            .filter(|(_, r)| r.due < today)
            .map(|(role, r)| Overdue {
                role,
                asset_id: r.asset_id.clone(),
                due: r.due,
            })
            .collect()
    }

    /// The table's rate accuracy, ppm of rate, when recorded.
    pub fn table_rate_accuracy_ppm(&self) -> Option<f64> {
        self.table.as_ref().and_then(|t| t.rate_accuracy_ppm)
    }

    /// The multimeter's accuracy: explicit `gain_pct`/`offset_pct` when given, else the
    /// specification period `accuracy`; `None` when the station states neither (the caller
    /// chooses its default).
    pub fn meter_accuracy(&self) -> Option<MeterAccuracySpec> {
        let m = self.multimeter.as_ref()?;
        match (m.gain_pct, m.offset_pct, m.accuracy) {
            (Some(gain_pct), Some(offset_pct), _) => Some(MeterAccuracySpec::Explicit {
                gain_pct,
                offset_pct,
            }),
            (_, _, Some(p)) => Some(MeterAccuracySpec::Period(p)),
            _ => None,
        }
    }
}
