//! Test plans: TOML file -> raw serde structs -> validated [`Plan`] -> [`Step`] schedule.
//!
//! Parsing happens in two stages, ripgrep-style:
//!
//! 1. **Raw**: the file is parsed into `toml`'s spanned document and its shape checked against
//!    a small schema (sections, keys, the kind of each value): a missing key is reported under
//!    its own section at that section's header, an unknown section or key gets "did you mean
//!    \[table\]?" (edit distance), a value of the wrong kind is said in words ("write a whole
//!    number from 1 to 1000000"). Then private serde structs mirror the file (`[plan]`,
//!    `[table]`, `[dmm]`, `[simulation]`), reject unknown keys (`deny_unknown_fields`) and keep
//!    the byte span of every value ([`toml::Spanned`]). TOML syntax errors are reported from
//!    `toml`'s own spans.
//! 2. **Validated**: the raw values, with defaults filled in, become a [`PlanDoc`] (the plain,
//!    serialisable form with the file's key names) and are checked against the instruments'
//!    limits. Every semantic error points at the offending value through the span kept in
//!    stage 1, so a message reads `configs/bad.toml:7:21: [table] acceleration_dps2 must be > 0
//!    (got 0)`.
//!
//! A [`Plan`] serialises (serde) as its [`PlanDoc`], so the manifest holds the plan "as parsed":
//! the file's keys, every default made explicit. Deserialising a `Plan` (from a manifest)
//! runs the same validation, so nothing read back from disk is trusted.
//!
//! # The content hash
//!
//! [`Plan::hash`] is the SHA-256 (hex) of a canonical serialisation of the *validated* plan, not
//! of the file bytes: comments, whitespace, key order, `0` versus `0.0`, `-0` versus `0` and
//! spelled-out defaults do not change it; any change of a rate, a setting or the simulated truth
//! does. The canonical form is the compact JSON of the [`PlanDoc`] (fields in declaration
//! order, numbers in shortest round-trip form) prefixed with `gyrocal-plan-v1\n`, with the
//! two serial/TCP port fields left out: where an instrument is plugged in does not change the
//! measurement, and an operator who moved a USB adapter must still be able to resume.
//! The optional `[dut]` (the gyro under test) and `[acceptance]` (the specification and its
//! decision rule) sections are left out too: one plan serves many gyros, and limits can be
//! re-evaluated after the run (`gyrocal report RUN --acceptance FILE`), so neither changes the
//! method, the hash, or whether a run resumes. Both are kept in the [`PlanDoc`] (and so in
//! the manifest) when present.
//!
//! # Acceptance files
//!
//! [`load_acceptance`] reads a standalone file whose top level is what `[acceptance]` holds:
//! `decision_rule` and one table of limits per quantity
//! ([`gyrocal_fit::acceptance::Quantity`]); its errors name keys as a plan's would.

use std::collections::BTreeMap;
use std::fmt;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::time::Duration;

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use toml::Spanned;
use toml::de::{DeTable, DeValue};

use gyrocal_fit::acceptance::{AcceptanceSpec, Limits, Quantity, Rule};

/// Hard ceiling for `[table] max_rate_dps`, in °/s. Laboratory single-axis rate tables reach a
/// few hundred to about 1000 °/s; a larger figure is a typo, and a dangerous one.
pub const HARD_MAX_RATE_DPS: f64 = 1000.0;
/// Hard ceiling for `[table] acceleration_dps2`, in °/s². Same reasoning as [`HARD_MAX_RATE_DPS`].
pub const HARD_MAX_ACCELERATION_DPS2: f64 = 1000.0;
/// The largest plan file read: 1 MiB. A plan is a few kilobytes; anything larger (or an
/// endless file such as `/dev/zero`) is refused after reading at most this much.
pub const MAX_PLAN_BYTES: u64 = 1024 * 1024;
/// Upper bound for `[plan] samples_per_rate`: one million readings is about 11.5 hours at the
/// 34401A's 24 readings/s (NPLC 1, autozero on); more is certainly a typo.
pub const MAX_SAMPLES_PER_RATE: u32 = 1_000_000;
/// Upper bound for `[plan] repeat`.
pub const MAX_REPEAT: u32 = 1000;
/// Upper bound for `[plan] whole_revolutions`.
pub const MAX_WHOLE_REVOLUTIONS: u32 = 1000;
/// Upper bound for every duration key (`settle_s`, `stability_window_s`, `at_rate_timeout_s`):
/// one day.
pub const MAX_DURATION_S: f64 = 86_400.0;
// The instruments' facts are their crates' (one copy each, built without I/O for this
// synchronous crate); the plan checks against them.
/// Mains frequencies the meter integrates against: the 34401A's.
pub use gyrocal_hp34401a::facts::LINE_HZ;
/// Integration times (power-line cycles) the HP 34401A offers for DC volts: its driver's.
pub use gyrocal_hp34401a::facts::NPLC_VALUES;
/// DC voltage ranges, in volts: the 34401A's (the Truevolts' are the same; a test keeps it so).
pub use gyrocal_hp34401a::facts::RANGES as RANGES_V;
/// Baud rates the HP 34401A offers (also accepted for the table's serial link): the link's.
pub use gyrocal_link::facts::SUPPORTED_BAUDS as BAUD_RATES;
/// Every integration time some supported meter offers: the Truevolt 34465A/70A's list, which
/// holds the 34401A's and the 34460A/61A's (a test keeps it so). The plan refuses anything
/// else at once, with the line and column; which of these the named model offers is the
/// driver crate's fact, checked by the CLI (`gyrocal check`, `gyrocal run`) before anything
/// opens.
pub use gyrocal_truevolt::facts::NPLC_65_70 as KNOWN_NPLC_VALUES;

const HASH_DOMAIN: &str = "gyrocal-plan-v1\n";

// ---------------------------------------------------------------------------------------------
// Errors
// ---------------------------------------------------------------------------------------------

/// Where in a plan source an error is: the file (or another origin such as a manifest) and,
/// when known, the 1-based line and column.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Location {
    /// The file the plan came from (or a label such as `manifest.json`).
    pub file: PathBuf,
    /// 1-based line, when the error could be placed.
    pub line: Option<u32>,
    /// 1-based column (in characters), when the error could be placed.
    pub column: Option<u32>,
}

impl Location {
    /// The place of byte `offset` of `src`, the text of `file` (line and column 1-based;
    /// without an offset, the file alone).
    pub(crate) fn in_text(file: &Path, src: &str, offset: Option<usize>) -> Location {
        let (line, column) = match offset {
            Some(o) => {
                let (l, c) = line_col(src, o);
                (Some(l), Some(c))
            }
            None => (None, None),
        };
        Location {
            file: file.to_path_buf(),
            line,
            column,
        }
    }
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file.display())?;
        if let Some(line) = self.line {
            write!(f, ":{line}")?;
            if let Some(column) = self.column {
                write!(f, ":{column}")?;
            }
        }
        Ok(())
    }
}

/// Everything that can be wrong with a plan. Every variant names the file; the TOML variants
/// also the line, the column and the section or key.
#[derive(Debug, thiserror::Error)]
pub enum PlanError {
    /// The file could not be read (or is not UTF-8 text).
    #[error("{}: cannot read the {document}: {source}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// What the file was to be: `plan` or `acceptance file`.
        document: &'static str,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The file is larger than [`MAX_PLAN_BYTES`] (or endless).
    #[error(
        "{}: larger than the {} KiB limit for {} {document} ({} {document} is a few kilobytes); is it the right file?",
        path.display(),
        cap / 1024,
        article(document),
        article(document)
    )]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// What the file was to be: `plan` or `acceptance file`.
        document: &'static str,
        /// The limit, bytes.
        cap: u64,
    },
    /// TOML syntax error, unknown or missing section, unknown key (stage 1).
    #[error("{location}: {}{message}", section.as_ref().map(|s| format!("[{s}] ")).unwrap_or_default())]
    Syntax {
        /// Where.
        location: Location,
        /// The section (`plan`, `table`, `dmm`, `simulation`) the error is in, when known.
        section: Option<String>,
        /// What `toml`/serde said (names the key for unknown and missing keys).
        message: String,
    },
    /// A missing key or a value of the wrong kind (stage 1), or a value that parses but is not
    /// acceptable (stage 2).
    #[error("{location}: [{section}] {key} {message}")]
    Invalid {
        /// Where (the offending value, when the file had it).
        location: Location,
        /// The section (`plan`, `table`, `dmm`, `simulation`).
        section: String,
        /// The key, e.g. `acceleration_dps2` or `rates_dps[3]`.
        key: String,
        /// What is wrong, e.g. `must be > 0 (got 0)`.
        message: String,
    },
}

/// The kind of a [`PlanError`], for callers that act on it (exit codes, retries).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PlanErrorKind {
    /// The file could not be read ([`PlanError::Read`]).
    Read,
    /// The file is too large ([`PlanError::TooLarge`]).
    TooLarge,
    /// TOML syntax, an unknown or missing section or key ([`PlanError::Syntax`]).
    Syntax,
    /// A value that is not acceptable ([`PlanError::Invalid`]).
    Invalid,
}

/// `a` or `an` before a document's name.
fn article(word: &str) -> &'static str {
    if word.starts_with(['a', 'e', 'i', 'o', 'u']) {
        "an"
    } else {
        "a"
    }
}

/// The plan document's name in read errors.
const PLAN_DOCUMENT: &str = "plan";
/// A standalone acceptance file's name in read errors.
const ACCEPTANCE_DOCUMENT: &str = "acceptance file";

impl PlanError {
    /// What kind of error this is.
    pub fn kind(&self) -> PlanErrorKind {
        match self {
            PlanError::Read { .. } => PlanErrorKind::Read,
            PlanError::TooLarge { .. } => PlanErrorKind::TooLarge,
            PlanError::Syntax { .. } => PlanErrorKind::Syntax,
            PlanError::Invalid { .. } => PlanErrorKind::Invalid,
        }
    }

    /// The location of the error, when it has one (not for [`PlanError::Read`] and
    /// [`PlanError::TooLarge`]).
    pub fn location(&self) -> Option<&Location> {
        match self {
            PlanError::Read { .. } | PlanError::TooLarge { .. } => None,
            PlanError::Syntax { location, .. } | PlanError::Invalid { location, .. } => {
                Some(location)
            }
        }
    }
}

/// Converts a byte offset into a 1-based (line, column in characters).
pub(crate) fn line_col(src: &str, offset: usize) -> (u32, u32) {
    let offset = offset.min(src.len());
    let before = src.get(..offset).unwrap_or(src);
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    let column = before.get(line_start..).map_or(0, |s| s.chars().count()) + 1;
    (to_u32(line), to_u32(column))
}

fn to_u32(n: usize) -> u32 {
    u32::try_from(n).unwrap_or(u32::MAX)
}

/// The `[section]` header in force at a byte offset (a heuristic for error messages only).
fn section_at(src: &str, offset: usize) -> Option<String> {
    let before = src.get(..offset.min(src.len()))?;
    before.lines().rev().find_map(|line| {
        let t = line.trim();
        let inner = t.strip_prefix('[')?.split(']').next()?.trim();
        let is_header = !inner.is_empty()
            && inner
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.' | '"'));
        is_header.then(|| inner.to_string())
    })
}

/// Why [`read_capped_text`] failed.
pub(crate) enum ReadFailure {
    /// Opening or reading, or not UTF-8 text (as [`std::io::ErrorKind::InvalidData`]).
    Io(std::io::Error),
    /// Longer than the cap.
    TooLarge,
}

/// Reads a text file of at most `cap` bytes, reading no more than `cap + 1` of it (so an
/// endless file such as `/dev/zero` is refused quickly). Only a regular file is opened: a
/// named pipe would block the open until a writer comes (forever), a device may never end.
pub(crate) fn read_capped_text(path: &Path, cap: u64) -> Result<String, ReadFailure> {
    use std::io::Read as _;
    // stat first: opening a FIFO for reading blocks until someone writes to it
    let meta = std::fs::metadata(path).map_err(ReadFailure::Io)?;
    if !meta.is_file() {
        return Err(ReadFailure::Io(not_a_regular_file(&meta.file_type())));
    }
    let file = std::fs::File::open(path).map_err(ReadFailure::Io)?;
    // and again on what was opened, in case the path was replaced in between
    let meta = file.metadata().map_err(ReadFailure::Io)?;
    if !meta.is_file() {
        return Err(ReadFailure::Io(not_a_regular_file(&meta.file_type())));
    }
    let mut bytes = Vec::new();
    file.take(cap.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(ReadFailure::Io)?;
    if bytes.len() as u64 > cap {
        return Err(ReadFailure::TooLarge);
    }
    String::from_utf8(bytes).map_err(|e| {
        ReadFailure::Io(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("not UTF-8 text (byte {})", e.utf8_error().valid_up_to()),
        ))
    })
}

/// The error for a path that is not a regular file, saying what it is.
pub(crate) fn not_a_regular_file(t: &std::fs::FileType) -> std::io::Error {
    #[cfg(unix)]
    let what = {
        use std::os::unix::fs::FileTypeExt as _;
        if t.is_fifo() {
            "a named pipe (FIFO)"
        } else if t.is_char_device() || t.is_block_device() {
            "a device"
        } else if t.is_socket() {
            "a socket"
        } else if t.is_dir() {
            "a directory"
        } else {
            "not a regular file"
        }
    };
    #[cfg(not(unix))]
    let what = if t.is_dir() {
        "a directory"
    } else {
        "not a regular file"
    };
    std::io::Error::new(
        std::io::ErrorKind::InvalidInput,
        format!("{what}: gyrocal reads this file only from a regular file"),
    )
}

/// A plan or acceptance file's text, at most [`MAX_PLAN_BYTES`].
fn read_document(path: &Path, document: &'static str) -> Result<String, PlanError> {
    read_capped_text(path, MAX_PLAN_BYTES).map_err(|f| match f {
        ReadFailure::Io(source) => PlanError::Read {
            path: path.to_path_buf(),
            document,
            source,
        },
        ReadFailure::TooLarge => PlanError::TooLarge {
            path: path.to_path_buf(),
            document,
            cap: MAX_PLAN_BYTES,
        },
    })
}

// ---------------------------------------------------------------------------------------------
// Stage 1: raw structs
// ---------------------------------------------------------------------------------------------

type S<T> = Spanned<T>;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFile {
    plan: RawPlan,
    /// Absent only with `[drift] table = "none"` (the shape check says so otherwise).
    table: Option<RawTable>,
    dmm: RawDmm,
    simulation: Option<RawSimulation>,
    dut: Option<RawDut>,
    acceptance: Option<RawAcceptance>,
    drift: Option<RawDrift>,
    warmup: Option<RawWarmup>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDrift {
    table: Option<S<String>>,
    axis: Option<S<String>>,
    latitude_deg: Option<S<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawWarmup {
    window_s: Option<S<f64>>,
    tolerance_v: Option<S<f64>>,
    max_s: Option<S<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDut {
    serial: Option<S<String>>,
    model: Option<S<String>>,
    manufacturer: Option<S<String>>,
    condition: Option<S<String>>,
    notes: Option<S<String>>,
}

/// `[acceptance]` of a plan, or the whole of a standalone acceptance file. One field per
/// [`Quantity`] (a unit test keeps them in step with [`Quantity::ALL`]).
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawAcceptance {
    decision_rule: Option<S<String>>,
    scale_factor: Option<S<RawLimits>>,
    bias_v: Option<S<RawLimits>>,
    bias_dph: Option<S<RawLimits>>,
    nonlinearity_ppm: Option<S<RawLimits>>,
    asymmetry_ppm: Option<S<RawLimits>>,
    asymmetry_gjb_ppm: Option<S<RawLimits>>,
    repeatability_ppm: Option<S<RawLimits>>,
    k2: Option<S<RawLimits>>,
}

impl RawAcceptance {
    /// The limits tables, by quantity.
    fn into_limits(self) -> [(Quantity, Option<S<RawLimits>>); 8] {
        [
            (Quantity::ScaleFactor, self.scale_factor),
            (Quantity::BiasV, self.bias_v),
            (Quantity::BiasDph, self.bias_dph),
            (Quantity::NonlinearityPpm, self.nonlinearity_ppm),
            (Quantity::AsymmetryPpm, self.asymmetry_ppm),
            (Quantity::AsymmetryGjbPpm, self.asymmetry_gjb_ppm),
            (Quantity::RepeatabilityPpm, self.repeatability_ppm),
            (Quantity::K2, self.k2),
        ]
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLimits {
    min: Option<S<f64>>,
    max: Option<S<f64>>,
    marginal_min: Option<S<f64>>,
    marginal_max: Option<S<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPlan {
    kind: Option<S<String>>,
    name: Option<S<String>>,
    rates_dps: S<Vec<S<f64>>>,
    samples_per_rate: S<RawInt>,
    settle_s: Option<S<f64>>,
    repeat: Option<S<RawInt>>,
    whole_revolutions: Option<S<RawInt>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTable {
    dialect: Option<S<String>>,
    port: S<String>,
    baud: Option<S<RawInt>>,
    max_rate_dps: S<f64>,
    acceleration_dps2: S<f64>,
    rate_tolerance_dps: Option<S<f64>>,
    stability_window_s: Option<S<f64>>,
    at_rate_timeout_s: Option<S<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDmm {
    model: Option<S<String>>,
    port: S<String>,
    baud: Option<S<RawInt>>,
    framing: Option<S<String>>,
    range_v: Option<S<f64>>,
    nplc: Option<S<f64>>,
    autozero: Option<S<bool>>,
    line_hz: Option<S<RawInt>>,
    acquisition: Option<S<String>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSimulation {
    seed: Option<S<RawInt>>,
    scale_factor: Option<S<f64>>,
    bias: Option<S<f64>>,
    k2: Option<S<f64>>,
    k3: Option<S<f64>>,
    asymmetry: Option<S<f64>>,
    noise_v: Option<S<f64>>,
    bias_walk: Option<S<f64>>,
    latitude_deg: Option<S<f64>>,
    rate_noise_dps: Option<S<f64>>,
    ripple_dps: Option<S<f64>>,
    arw_deg_rt_h: Option<S<f64>>,
    bias_instability_dph: Option<S<f64>>,
    rrw_dph_rt_h: Option<S<f64>>,
    quantization_arcsec: Option<S<f64>>,
    warmup_dph: Option<S<f64>>,
    warmup_tau_s: Option<S<f64>>,
}

/// An integer key as written. Any TOML value is accepted at this stage, so that whatever was
/// written (an integer beyond 64 bits, a float, a string) is refused naming the key and the
/// allowed values, like an integer out of range, instead of as a serde type error.
enum RawInt {
    /// A 64-bit integer (range-checked by validation).
    Int(i64),
    /// Anything else, as it reads in an error message, and whether it is a whole number (an
    /// integer beyond 64 bits).
    Other(String, bool),
}

impl<'de> Deserialize<'de> for RawInt {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> serde::de::Visitor<'de> for V {
            type Value = RawInt;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("a whole number")
            }
            fn visit_i64<E>(self, v: i64) -> Result<RawInt, E> {
                Ok(RawInt::Int(v))
            }
            fn visit_u64<E>(self, v: u64) -> Result<RawInt, E> {
                Ok(i64::try_from(v)
                    .map_or_else(|_| RawInt::Other(v.to_string(), true), RawInt::Int))
            }
            fn visit_i128<E>(self, v: i128) -> Result<RawInt, E> {
                Ok(i64::try_from(v)
                    .map_or_else(|_| RawInt::Other(v.to_string(), true), RawInt::Int))
            }
            fn visit_u128<E>(self, v: u128) -> Result<RawInt, E> {
                Ok(i64::try_from(v)
                    .map_or_else(|_| RawInt::Other(v.to_string(), true), RawInt::Int))
            }
            fn visit_f64<E>(self, v: f64) -> Result<RawInt, E> {
                Ok(RawInt::Other(format!("{v:?}"), false))
            }
            fn visit_bool<E>(self, v: bool) -> Result<RawInt, E> {
                Ok(RawInt::Other(v.to_string(), false))
            }
            fn visit_str<E>(self, v: &str) -> Result<RawInt, E> {
                Ok(RawInt::Other(format!("{v:?}"), false))
            }
        }
        d.deserialize_any(V)
    }
}

/// The values an integer key allows.
enum IntRule {
    /// `lo..=hi`.
    Range(u64, u64),
    /// One of these.
    OneOf(&'static [u32]),
}

fn int_rule(key: &str) -> IntRule {
    match key {
        "plan.samples_per_rate" => IntRule::Range(1, MAX_SAMPLES_PER_RATE.into()),
        "plan.repeat" => IntRule::Range(1, MAX_REPEAT.into()),
        "plan.whole_revolutions" => IntRule::Range(0, MAX_WHOLE_REVOLUTIONS.into()),
        "table.baud" | "dmm.baud" => IntRule::OneOf(&BAUD_RATES),
        "dmm.line_hz" => IntRule::OneOf(&LINE_HZ),
        _ => IntRule::Range(0, i64::MAX.unsigned_abs()), // simulation.seed
    }
}

/// The message for an integer key whose value (`shown`, as written) is not allowed: the
/// allowed values in words and what to write.
fn int_error(key: &str, shown: &str, whole: bool) -> String {
    let words = int_words(key);
    if !whole {
        return format!("= {shown} is not a whole number: write {words}");
    }
    match int_rule(key) {
        IntRule::Range(..) => format!("= {shown} is out of range: write {words}"),
        IntRule::OneOf(_) => format!("= {shown} is not allowed: write {words}"),
    }
}

/// Spans of the values present in the file, keyed by `section.key` (`plan.rates_dps[2]`).
#[derive(Default)]
struct Spans(BTreeMap<String, Range<usize>>);

impl Spans {
    fn take<T>(&mut self, key: &str, v: S<T>) -> T {
        self.0.insert(key.to_string(), v.span());
        v.into_inner()
    }
    fn opt<T>(&mut self, key: &str, v: Option<S<T>>, default: T) -> T {
        match v {
            Some(v) => self.take(key, v),
            None => default,
        }
    }
    /// An integer key (`default` when absent); a value that is not a 64-bit integer is an
    /// error `(key, message)`.
    fn int(
        &mut self,
        key: &'static str,
        v: Option<S<RawInt>>,
        default: i64,
    ) -> Result<i64, (&'static str, String)> {
        match v.map(|v| self.take(key, v)) {
            None => Ok(default),
            Some(RawInt::Int(i)) => Ok(i),
            Some(RawInt::Other(shown, whole)) => Err((key, int_error(key, &shown, whole))),
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Stage 1a: the file's shape, checked before serde so errors name the right place in words
// ---------------------------------------------------------------------------------------------

/// What a key holds, in the words an operator reads in an error message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    /// A number (integer or float).
    Number,
    /// A whole number (the allowed values are [`int_rule`]'s).
    Int,
    /// Text in quotes.
    Text,
    /// `true` or `false`.
    Bool,
    /// A list of numbers.
    Numbers,
    /// A table of acceptance limits (`min`, `max`, `marginal_min`, `marginal_max`, numbers).
    Limits,
}

/// A section of the file: its name, whether it is required, and its keys (name, kind,
/// required). Kept in step with the `Raw*` structs by a unit test.
type SectionSchema = (&'static str, bool, &'static [(&'static str, Kind, bool)]);

const SCHEMA: &[SectionSchema] = &[
    (
        "plan",
        true,
        &[
            ("kind", Kind::Text, false),
            ("name", Kind::Text, false),
            ("rates_dps", Kind::Numbers, true),
            ("samples_per_rate", Kind::Int, true),
            ("settle_s", Kind::Number, false),
            ("repeat", Kind::Int, false),
            ("whole_revolutions", Kind::Int, false),
        ],
    ),
    (
        "table",
        true,
        &[
            ("dialect", Kind::Text, false),
            ("port", Kind::Text, true),
            ("baud", Kind::Int, false),
            ("max_rate_dps", Kind::Number, true),
            ("acceleration_dps2", Kind::Number, true),
            ("rate_tolerance_dps", Kind::Number, false),
            ("stability_window_s", Kind::Number, false),
            ("at_rate_timeout_s", Kind::Number, false),
        ],
    ),
    (
        "dmm",
        true,
        &[
            ("model", Kind::Text, false),
            ("port", Kind::Text, true),
            ("baud", Kind::Int, false),
            ("framing", Kind::Text, false),
            ("range_v", Kind::Number, false),
            ("nplc", Kind::Number, false),
            ("autozero", Kind::Bool, false),
            ("line_hz", Kind::Int, false),
            ("acquisition", Kind::Text, false),
        ],
    ),
    (
        "simulation",
        false,
        &[
            ("seed", Kind::Int, false),
            ("scale_factor", Kind::Number, false),
            ("bias", Kind::Number, false),
            ("k2", Kind::Number, false),
            ("k3", Kind::Number, false),
            ("asymmetry", Kind::Number, false),
            ("noise_v", Kind::Number, false),
            ("bias_walk", Kind::Number, false),
            ("latitude_deg", Kind::Number, false),
            ("rate_noise_dps", Kind::Number, false),
            ("ripple_dps", Kind::Number, false),
            ("arw_deg_rt_h", Kind::Number, false),
            ("bias_instability_dph", Kind::Number, false),
            ("rrw_dph_rt_h", Kind::Number, false),
            ("quantization_arcsec", Kind::Number, false),
            ("warmup_dph", Kind::Number, false),
            ("warmup_tau_s", Kind::Number, false),
        ],
    ),
    (
        "dut",
        false,
        &[
            ("serial", Kind::Text, false),
            ("model", Kind::Text, false),
            ("manufacturer", Kind::Text, false),
            ("condition", Kind::Text, false),
            ("notes", Kind::Text, false),
        ],
    ),
    ("acceptance", false, ACCEPTANCE_KEYS),
    (
        "drift",
        false,
        &[
            ("table", Kind::Text, false),
            ("axis", Kind::Text, false),
            ("latitude_deg", Kind::Number, false),
        ],
    ),
    (
        "warmup",
        false,
        &[
            ("window_s", Kind::Number, false),
            ("tolerance_v", Kind::Number, false),
            ("max_s", Kind::Number, false),
        ],
    ),
];

/// The keys of `[acceptance]` (and of a standalone acceptance file): the decision rule and a
/// table of limits per [`Quantity`] (a unit test keeps them in step with [`Quantity::ALL`]).
const ACCEPTANCE_KEYS: &[(&str, Kind, bool)] = &[
    ("decision_rule", Kind::Text, false),
    ("scale_factor", Kind::Limits, false),
    ("bias_v", Kind::Limits, false),
    ("bias_dph", Kind::Limits, false),
    ("nonlinearity_ppm", Kind::Limits, false),
    ("asymmetry_ppm", Kind::Limits, false),
    ("asymmetry_gjb_ppm", Kind::Limits, false),
    ("repeatability_ppm", Kind::Limits, false),
    ("k2", Kind::Limits, false),
];

/// An example line for a required key, for "add ..." hints.
fn example(section: &str, key: &str) -> &'static str {
    match (section, key) {
        ("plan", "rates_dps") => "rates_dps = [0, 5, -5]",
        ("plan", "samples_per_rate") => "samples_per_rate = 500",
        ("table", "port") => "port = \"/dev/ttyUSB1\"",
        ("dmm", "port") => "port = \"/dev/ttyUSB0\"",
        ("table", "max_rate_dps") => "max_rate_dps = 20",
        ("table", "acceleration_dps2") => "acceleration_dps2 = 10",
        _ => "",
    }
}

/// Optimal-string-alignment distance (Levenshtein plus adjacent transpositions), ASCII
/// case-insensitive.
fn edit_distance(a: &str, b: &str) -> usize {
    let a: Vec<char> = a.chars().map(|c| c.to_ascii_lowercase()).collect();
    let b: Vec<char> = b.chars().map(|c| c.to_ascii_lowercase()).collect();
    let w = b.len() + 1;
    let mut d = vec![0usize; (a.len() + 1) * w];
    for (i, row) in d.chunks_mut(w).enumerate() {
        if let Some(first) = row.first_mut() {
            *first = i;
        }
    }
    for (j, cell) in d.iter_mut().take(w).enumerate() {
        *cell = j;
    }
    for i in 1..=a.len() {
        for j in 1..=b.len() {
            let cost = usize::from(a[i - 1] != b[j - 1]);
            let mut best = (d[(i - 1) * w + j] + 1)
                .min(d[i * w + j - 1] + 1)
                .min(d[(i - 1) * w + j - 1] + cost);
            if i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1] {
                best = best.min(d[(i - 2) * w + j - 2] + 1);
            }
            d[i * w + j] = best;
        }
    }
    d[a.len() * w + b.len()]
}

/// The candidate closest to `name`, when it is close enough to be a likely misspelling (a
/// small edit distance, or one is a prefix of the other).
pub(crate) fn closest<'a>(
    name: &str,
    candidates: impl IntoIterator<Item = &'a str>,
) -> Option<&'a str> {
    let lower = name.to_ascii_lowercase();
    candidates
        .into_iter()
        .filter_map(|c| {
            let d = edit_distance(name, c);
            let prefix = lower.len() >= 3 && (c.starts_with(&lower) || lower.starts_with(c));
            let close = d <= 1 || d * 3 <= name.chars().count().max(c.len());
            (close || prefix).then_some((d, c))
        })
        .min_by_key(|&(d, _)| d)
        .map(|(_, c)| c)
}

/// `a, b or c`.
pub(crate) fn or_list<T: fmt::Display>(items: &[T]) -> String {
    word_list(items, "or")
}

/// `a, b and c`.
pub(crate) fn and_list<T: fmt::Display>(items: &[T]) -> String {
    word_list(items, "and")
}

fn word_list<T: fmt::Display>(items: &[T], conjunction: &str) -> String {
    let words: Vec<String> = items.iter().map(ToString::to_string).collect();
    match words.split_last() {
        None => String::new(),
        Some((last, [])) => last.clone(),
        Some((last, rest)) => format!("{} {conjunction} {last}", rest.join(", ")),
    }
}

/// A value as it reads in an error message, and what kind of thing it is, in words.
fn shown(v: &DeValue<'_>) -> (String, &'static str) {
    match v {
        DeValue::String(s) => (format!("{:?}", s.as_ref()), "text"),
        DeValue::Integer(i) => (i.as_str().to_string(), "a whole number"),
        DeValue::Float(f) => (f.as_str().to_string(), "a number with a fraction"),
        DeValue::Boolean(b) => (b.to_string(), "true/false"),
        DeValue::Datetime(d) => (d.to_string(), "a date/time"),
        DeValue::Array(_) => ("a list".into(), "a list"),
        DeValue::Table(_) => ("a table".into(), "a table"),
    }
}

/// What an integer key allows, in words: `a whole number from 1 to 1000000`, `one of 50 or 60`.
fn int_words(key: &str) -> String {
    match int_rule(key) {
        IntRule::Range(lo, hi) => format!("a whole number from {lo} to {hi}"),
        IntRule::OneOf(allowed) => format!("one of {}", or_list(allowed)),
    }
}

/// A stage-1 finding: where (byte offset, when known), section, key, message.
struct Finding {
    /// 0: a wrong key or value; 1: a missing key; 2: a missing section (reported in this order).
    rank: u8,
    offset: Option<usize>,
    section: Option<String>,
    key: Option<String>,
    message: String,
}

/// The message for a value of the wrong kind for `section.key`, or `None` when it fits.
fn wrong_kind(section: &str, key: &str, kind: Kind, v: &DeValue<'_>) -> Option<String> {
    let (shown, what) = shown(v);
    let quoted_number = v.as_str().is_some_and(|s| s.trim().parse::<f64>().is_ok());
    match kind {
        Kind::Number if v.is_integer() || v.is_float() => None,
        Kind::Number if quoted_number => Some(format!(
            "= {shown} is text, not a number: write the number without quotes"
        )),
        Kind::Number => Some(format!(
            "= {shown} is {what}: write a number, e.g. {key} = 10"
        )),
        Kind::Int if v.is_integer() => None,
        Kind::Int => {
            let words = int_words(&format!("{section}.{key}"));
            Some(if quoted_number {
                format!("= {shown} is text, not a number: write {words}, without quotes")
            } else if v.is_float() {
                format!("= {shown} is not a whole number: write {words}")
            } else {
                format!("= {shown} is {what}, not a number: write {words}")
            })
        }
        Kind::Text if v.is_str() => None,
        Kind::Text => Some(format!(
            "= {shown} is {what}: write text in quotes, e.g. {key} = \"{}\"",
            v.as_integer()
                .map(|i| i.as_str().to_string())
                .or_else(|| v.as_float().map(|f| f.as_str().to_string()))
                .unwrap_or_else(|| "...".into())
        )),
        Kind::Bool if v.is_bool() => None,
        Kind::Bool => Some(format!(
            "= {shown} is {what}: write true or false (no quotes)"
        )),
        Kind::Numbers if v.is_array() => None,
        Kind::Numbers => Some(format!(
            "= {shown} is {what}: write a list of numbers in brackets, e.g. {key} = [0, 5, -5]"
        )),
        Kind::Limits if v.is_table() => None,
        Kind::Limits => Some(format!(
            "= {shown} is {what}: write a table of limits, e.g. {key} = {{ min = 0.049, max = \
             0.051 }}, or a section [acceptance.{key}] with its keys"
        )),
    }
}

/// Checks the keys of one section (`table`, whose header is at byte `header` when known)
/// against its schema `keys`, adding every finding to `out`.
fn check_keys(
    sname: &str,
    keys: &[(&'static str, Kind, bool)],
    table: &DeTable<'_>,
    header: Option<usize>,
    out: &mut Vec<Finding>,
) {
    for (key, v) in table.iter() {
        let key_str: &str = key.get_ref().as_ref();
        let Some(&(kname, kind, _)) = keys.iter().find(|k| k.0 == key_str) else {
            let elsewhere: Vec<String> = SCHEMA
                .iter()
                .filter(|s| s.0 != sname && s.2.iter().any(|k| k.0 == key_str))
                .map(|s| format!("[{}]", s.0))
                .collect();
            let hint = if !elsewhere.is_empty() {
                format!("it belongs in {}", or_list(&elsewhere))
            } else if sname == "acceptance" {
                let all = format!(
                    "the keys of [acceptance] are decision_rule and the quantities {}",
                    Quantity::names()
                );
                match closest(key_str, keys.iter().map(|k| k.0)) {
                    Some(k) => format!("did you mean `{k}`? ({all})"),
                    None => all,
                }
            } else if let Some(k) = closest(key_str, keys.iter().map(|k| k.0)) {
                format!("did you mean `{k}`?")
            } else {
                format!(
                    "the keys of [{sname}] are {}",
                    and_list(&keys.iter().map(|k| k.0).collect::<Vec<_>>())
                )
            };
            out.push(Finding {
                rank: 0,
                offset: Some(key.span().start),
                section: Some(sname.to_string()),
                key: None,
                message: format!("unknown key `{key_str}`: {hint}"),
            });
            continue;
        };
        if let Some(message) = wrong_kind(sname, kname, kind, v.get_ref()) {
            out.push(Finding {
                rank: 0,
                offset: Some(v.span().start),
                section: Some(sname.to_string()),
                key: Some(kname.to_string()),
                message,
            });
        } else if let (Kind::Limits, Some(limits)) = (kind, v.get_ref().as_table()) {
            check_limits(&format!("{sname}.{kname}"), limits, out);
        } else if let (Kind::Numbers, Some(items)) = (kind, v.get_ref().as_array()) {
            for (i, item) in items.iter().enumerate() {
                if let Some(message) = wrong_kind(sname, kname, Kind::Number, item.get_ref()) {
                    out.push(Finding {
                        rank: 0,
                        offset: Some(item.span().start),
                        section: Some(sname.to_string()),
                        key: Some(format!("{kname}[{i}]")),
                        message,
                    });
                }
            }
        }
    }
    for &(kname, _, required) in keys.iter() {
        if required && !table.keys().any(|k| k.get_ref().as_ref() == kname) {
            let ex = example(sname, kname);
            let add = if ex.is_empty() {
                format!("add `{kname}` under [{sname}]")
            } else {
                format!("add a line such as {ex} under [{sname}]")
            };
            out.push(Finding {
                rank: 1,
                offset: header,
                section: Some(sname.to_string()),
                key: Some(kname.to_string()),
                message: format!("is missing (required): {add}"),
            });
        }
    }
}

/// Checks a table of acceptance limits (`section` is e.g. `acceptance.scale_factor`): only
/// `min`, `max`, `marginal_min` and `marginal_max`, each a number.
fn check_limits(section: &str, table: &DeTable<'_>, out: &mut Vec<Finding>) {
    for (key, v) in table.iter() {
        let key_str: &str = key.get_ref().as_ref();
        let Some(kname) = Limits::KEYS.into_iter().find(|k| *k == key_str) else {
            let all = "the keys of a quantity's limits are min, max, marginal_min and marginal_max";
            let hint = match closest(key_str, Limits::KEYS) {
                Some(k) => format!("did you mean `{k}`? ({all})"),
                None => all.to_string(),
            };
            out.push(Finding {
                rank: 0,
                offset: Some(key.span().start),
                section: Some(section.to_string()),
                key: None,
                message: format!("unknown key `{key_str}`: {hint}"),
            });
            continue;
        };
        if let Some(message) = wrong_kind(section, kname, Kind::Number, v.get_ref()) {
            out.push(Finding {
                rank: 0,
                offset: Some(v.span().start),
                section: Some(section.to_string()),
                key: Some(kname.to_string()),
                message,
            });
        }
    }
}

/// Checks the file's sections, keys and value kinds against [`SCHEMA`]; returns every finding.
fn check_shape(root: &DeTable<'_>) -> Vec<Finding> {
    let mut out = Vec::new();
    let section_names = || SCHEMA.iter().map(|s| s.0);
    for (name, value) in root.iter() {
        let name_str: &str = name.get_ref().as_ref();
        let Some((sname, _, keys)) = SCHEMA.iter().find(|s| s.0 == name_str) else {
            let all = and_list(
                &section_names()
                    .map(|s| format!("[{s}]"))
                    .collect::<Vec<_>>(),
            );
            let hint = match closest(name_str, section_names()) {
                Some(s) => format!("did you mean [{s}]? (the sections are {all})"),
                None => format!("the sections are {all}"),
            };
            let what = if value.get_ref().is_table() {
                format!("unknown section [{name_str}]")
            } else {
                format!("unknown key `{name_str}` outside any section")
            };
            out.push(Finding {
                rank: 0,
                offset: Some(name.span().start),
                section: None,
                key: None,
                message: format!("{what}: {hint}"),
            });
            continue;
        };
        let Some(table) = value.get_ref().as_table() else {
            out.push(Finding {
                rank: 0,
                offset: Some(name.span().start),
                section: None,
                key: None,
                message: format!(
                    "`{sname}` must be a section: write a line [{sname}] followed by its keys"
                ),
            });
            continue;
        };
        check_keys(sname, keys, table, Some(name.span().start), &mut out);
    }
    // a drift record on a bench without a table leaves [table] out
    let no_table = root
        .iter()
        .find(|(k, _)| k.get_ref().as_ref() == "drift")
        .and_then(|(_, v)| v.get_ref().as_table())
        .and_then(|d| {
            d.iter()
                .find(|(k, _)| k.get_ref().as_ref() == "table")
                .and_then(|(_, v)| v.get_ref().as_str().map(|s| s.trim() == "none"))
        })
        .unwrap_or(false);
    for &(sname, required, keys) in SCHEMA {
        if sname == "table" && no_table {
            continue;
        }
        if required && !root.keys().any(|k| k.get_ref().as_ref() == sname) {
            let needed: Vec<&str> = keys.iter().filter(|k| k.2).map(|k| k.0).collect();
            out.push(Finding {
                rank: 2,
                offset: None,
                section: None,
                key: None,
                message: format!(
                    "the section [{sname}] is missing (required): add a line [{sname}] followed \
                     by {}",
                    needed.join(", ")
                ),
            });
        }
    }
    out
}

/// Serde's type names, as words (for the rare serde message that gets past [`check_shape`]).
fn plain_words(message: &str) -> String {
    let mut m = message.to_string();
    for (jargon, words) in [
        ("u32", "a whole number"),
        ("u64", "a whole number"),
        ("i64", "a whole number"),
        ("f64", "a number"),
        ("a boolean", "true or false"),
        ("a string", "text in quotes"),
        ("a sequence", "a list"),
        ("struct ", ""),
    ] {
        m = m.replace(jargon, words);
    }
    m
}

// ---------------------------------------------------------------------------------------------
// The plain document (serialised form)
// ---------------------------------------------------------------------------------------------

/// The plan as parsed, with every default filled in: the same sections and key names as the
/// TOML file. This is what a [`Plan`] serialises to (in the manifest) and what the hash is
/// computed from. Building a [`Plan`] from it always goes through validation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlanDoc {
    /// `[plan]`
    pub plan: PlanSectionDoc,
    /// `[table]`
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub table: Option<TableDoc>,
    /// `[dmm]`
    pub dmm: DmmDoc,
    /// `[simulation]`
    pub simulation: Simulation,
    /// `[dut]` (absent: not named in the plan). Not part of the hash.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dut: Option<PlanDut>,
    /// `[acceptance]` (absent: no specification). Not part of the hash.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub acceptance: Option<AcceptanceSpec>,
    /// `[drift]` (a drift plan's table role and bench orientation; absent: the defaults).
    /// Part of the hash; absent from the documents of plans that have none, so their hashes
    /// stay what they were.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub drift: Option<DriftDoc>,
    /// `[warmup]` (absent: no warm-up). Part of the hash.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub warmup: Option<WarmupDoc>,
}

/// `[drift]` as parsed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DriftDoc {
    /// The table's role: `hold` or `servo_off`.
    pub table: String,
    /// Where the input axis points (`up`, `down`, `north`, `south`, `east`, `west`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub axis: Option<String>,
    /// The bench's latitude, degrees north.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub latitude_deg: Option<f64>,
}

/// `[warmup]` as parsed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WarmupDoc {
    /// Window of the rolling mean, s.
    pub window_s: f64,
    /// Largest change of consecutive window means that counts as settled, V (absent: 3 × the
    /// white-noise σ of a window mean, estimated from the readings so far).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tolerance_v: Option<f64>,
    /// The warm-up ends here at the latest, s.
    pub max_s: f64,
}

/// Default `[warmup] window_s`, s.
pub const DEFAULT_WARMUP_WINDOW_S: f64 = 60.0;
/// Default `[warmup] max_s`, s (IEEE 1431's HRG warm-up is tens of minutes).
pub const DEFAULT_WARMUP_MAX_S: f64 = 3600.0;
/// Default warm-up tolerance, in white-noise sigmas of a window mean (`sigma_A(tau0)/sqrt(w)`),
/// used when `[warmup] tolerance_v` is not given: three sigmas keep a settled gyro from being
/// called still warming up by noise alone (about 0.3 % of windows), and one value is shared by
/// the live monitor (gyrocal-run) and the report's warm-up curve so they agree on "settled".
pub const DEFAULT_WARMUP_SIGMAS: f64 = 3.0;

/// What the rate table does during a drift record (`[drift] table`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum TableRole {
    /// Servo on, holding 0 °/s; every segment is checked against the hold tolerance like a
    /// step of a sweep (the default: a table with its servo on is stiff against the gyro's
    /// cables and the floor).
    #[default]
    Hold,
    /// Brought to rest, then its servo switched off (ACL `:Interlock:Open`, the controller's
    /// orderly shutdown: an ABORT profile to zero, then servo off) for the whole record: no
    /// servo jitter on the input axis. The table's rate is still sampled; a segment during
    /// which it moved more than the hold tolerance is not recorded, and one during which it
    /// left OFF ends the run. ACL tables only (the aerosmith dialect has no servo-off command).
    ServoOff,
    /// No table at all (a gyro on a bench or a fixture): nothing is opened, moved or sampled
    /// on a table's port, and `[table]` may be left out.
    None,
}

impl TableRole {
    /// All roles.
    pub const ALL: [TableRole; 3] = [TableRole::Hold, TableRole::ServoOff, TableRole::None];

    /// As written in a plan.
    pub fn as_str(self) -> &'static str {
        match self {
            TableRole::Hold => "hold",
            TableRole::ServoOff => "servo_off",
            TableRole::None => "none",
        }
    }

    /// What the table does, in words for a reader (`gyrocal check`, the Allan page).
    pub fn describe(self) -> &'static str {
        match self {
            TableRole::Hold => "holding 0 °/s (servo on)",
            TableRole::ServoOff => "at rest, servo off",
            TableRole::None => "none (no table is opened)",
        }
    }
}

/// Earth's rotation rate, °/h (15.041 °/h: one turn per sidereal day).
pub const EARTH_RATE_DPH: f64 = 15.041;

/// Where a gyro's input axis points on the bench.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Axis {
    /// Local vertical, up: senses Ω·sin(latitude).
    Up,
    /// Down: −Ω·sin(latitude).
    Down,
    /// Horizontal, north: Ω·cos(latitude).
    North,
    /// Horizontal, south: −Ω·cos(latitude).
    South,
    /// Horizontal, east: no Earth rate.
    East,
    /// Horizontal, west: no Earth rate.
    West,
}

impl Axis {
    /// All directions.
    pub const ALL: [Axis; 6] = [
        Axis::Up,
        Axis::Down,
        Axis::North,
        Axis::South,
        Axis::East,
        Axis::West,
    ];

    /// As written in a plan and on the command line.
    pub fn as_str(self) -> &'static str {
        match self {
            Axis::Up => "up",
            Axis::Down => "down",
            Axis::North => "north",
            Axis::South => "south",
            Axis::East => "east",
            Axis::West => "west",
        }
    }

    /// The direction named `s` (ASCII case ignored).
    pub fn from_name(s: &str) -> Option<Axis> {
        Axis::ALL
            .into_iter()
            .find(|a| a.as_str().eq_ignore_ascii_case(s.trim()))
    }

    /// The Earth-rate component along the axis at `latitude_deg`, °/h.
    pub fn earth_rate_dph(self, latitude_deg: f64) -> f64 {
        let phi = latitude_deg.to_radians();
        match self {
            Axis::Up => EARTH_RATE_DPH * phi.sin(),
            Axis::Down => -EARTH_RATE_DPH * phi.sin(),
            Axis::North => EARTH_RATE_DPH * phi.cos(),
            Axis::South => -EARTH_RATE_DPH * phi.cos(),
            Axis::East | Axis::West => 0.0,
        }
    }
}

/// The validated `[drift]` section (defaults when the plan has none).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DriftSettings {
    /// What the table does during the record.
    pub table: TableRole,
    /// The input axis and the latitude, when given (both or neither): the Earth's rate along
    /// the axis is removed from the bias in the run's Allan analysis.
    pub earth: Option<(Axis, f64)>,
}

/// The validated `[warmup]` section.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WarmupSettings {
    /// Window of the rolling mean.
    pub window: Duration,
    /// Largest change of consecutive window means that counts as settled, V; `None`: 3 × the
    /// white-noise σ of a window mean.
    pub tolerance_v: Option<f64>,
    /// The warm-up ends here at the latest.
    pub max: Duration,
}

/// `[dut]`: the gyro under test, when the plan names it (a plan written for one gyro): the
/// run directory's own record ([`crate::rundir::Dut`]), every key optional text; the command
/// line overrides each key it gives ([`crate::rundir::Dut::overridden_by`]). Left out of the
/// plan's hash: one plan serves many gyros, and naming the gyro does not change the
/// measurement.
pub type PlanDut = crate::rundir::Dut;

fn default_kind() -> String {
    PlanKind::ScaleFactor.as_str().to_string()
}

fn is_scale_factor(kind: &str) -> bool {
    kind == PlanKind::ScaleFactor.as_str()
}

/// What a plan measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PlanKind {
    /// A sweep of rates for the scale factor (the paper's method).
    #[default]
    ScaleFactor,
    /// A static record at zero rate (IEEE 952 §6.6 drift test) in durable segments: every
    /// rate is 0, `samples_per_rate` readings make one segment (one step) and `repeat`
    /// segments the record; analysed by Allan deviation instead of a line.
    Drift,
}

impl PlanKind {
    /// All kinds.
    pub const ALL: [PlanKind; 2] = [PlanKind::ScaleFactor, PlanKind::Drift];

    /// `scale_factor` or `drift`, as written in a plan.
    pub fn as_str(self) -> &'static str {
        match self {
            PlanKind::ScaleFactor => "scale_factor",
            PlanKind::Drift => "drift",
        }
    }
}

/// `[plan]` as parsed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlanSectionDoc {
    /// What the plan measures: `scale_factor` (absent in documents of plans before drift
    /// plans existed, and never written for one, so their hashes stay) or `drift`.
    #[serde(default = "default_kind", skip_serializing_if = "is_scale_factor")]
    pub kind: String,
    /// Free-text name.
    pub name: String,
    /// Rates in the order applied, °/s.
    pub rates_dps: Vec<f64>,
    /// Readings per rate (integers are wide here, range-checked by validation).
    pub samples_per_rate: i64,
    /// Dwell after the table is at rate, s.
    pub settle_s: f64,
    /// Passes over the whole schedule.
    pub repeat: i64,
    /// Whole table turns to acquire over at each non-zero rate (0: off).
    pub whole_revolutions: i64,
}

impl TableDoc {
    /// The settings a plan without `[table]` holds (a drift record with `[drift] table =
    /// "none"`): never used to open or drive anything; the port names no device.
    fn unused() -> TableDoc {
        TableDoc {
            dialect: "acl".into(),
            port: "(no table)".into(),
            baud: 9600,
            max_rate_dps: 1.0,
            acceleration_dps2: 1.0,
            rate_tolerance_dps: 0.001,
            stability_window_s: 2.0,
            at_rate_timeout_s: 60.0,
        }
    }
}

/// `[table]` as parsed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TableDoc {
    /// Command language, `acl`.
    pub dialect: String,
    /// Serial device path or `tcp://HOST:PORT`.
    pub port: String,
    /// Serial baud rate.
    pub baud: i64,
    /// Client-side rate limit, °/s.
    pub max_rate_dps: f64,
    /// Acceleration limit, °/s².
    pub acceleration_dps2: f64,
    /// "At rate" tolerance, °/s.
    pub rate_tolerance_dps: f64,
    /// "At rate" stability window, s.
    pub stability_window_s: f64,
    /// Time allowed to reach the rate, s.
    pub at_rate_timeout_s: f64,
}

/// `[dmm]` as parsed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DmmDoc {
    /// `34401a` (the default), `34460a`, `34461a`, `34465a` or `34470a`. Left out of the
    /// serialised form when it is the default, so a 34401A plan's hash is what it was before
    /// the key existed.
    #[serde(default = "default_model", skip_serializing_if = "is_default_model")]
    pub model: String,
    /// Serial device path or `tcp://HOST:PORT`.
    pub port: String,
    /// Serial baud rate.
    pub baud: i64,
    /// `8N2`, `7E2` or `7O2`.
    pub framing: String,
    /// DC range, V.
    pub range_v: f64,
    /// Integration time, power-line cycles.
    pub nplc: f64,
    /// Autozero on or off.
    pub autozero: bool,
    /// Mains frequency, Hz.
    pub line_hz: i64,
    /// `auto`, `stream`, `memory` or `poll`.
    pub acquisition: String,
}

fn default_model() -> String {
    DmmModel::Hp34401a.as_str().into()
}

#[allow(clippy::ptr_arg)] // serde's skip_serializing_if passes a &String
fn is_default_model(m: &String) -> bool {
    m.eq_ignore_ascii_case(DmmModel::Hp34401a.as_str())
}

// ---------------------------------------------------------------------------------------------
// Validated types
// ---------------------------------------------------------------------------------------------

/// The multimeter model a plan names (`[dmm] model`). The plan knows the names only; each
/// model's facts (NPLC values, memory) are its driver crate's.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum DmmModel {
    /// HP 34401A on RS-232 or GPIB (the default).
    #[default]
    Hp34401a,
    /// Keysight Truevolt 34460A, over LAN.
    K34460a,
    /// Keysight Truevolt 34461A, over LAN.
    K34461a,
    /// Keysight Truevolt 34465A, over LAN.
    K34465a,
    /// Keysight Truevolt 34470A, over LAN.
    K34470a,
}

impl DmmModel {
    /// Every model.
    pub const ALL: [DmmModel; 5] = [
        DmmModel::Hp34401a,
        DmmModel::K34460a,
        DmmModel::K34461a,
        DmmModel::K34465a,
        DmmModel::K34470a,
    ];

    /// The name used in plan files.
    pub fn as_str(self) -> &'static str {
        match self {
            DmmModel::Hp34401a => "34401a",
            DmmModel::K34460a => "34460a",
            DmmModel::K34461a => "34461a",
            DmmModel::K34465a => "34465a",
            DmmModel::K34470a => "34470a",
        }
    }

    /// True for a Keysight Truevolt (reached over LAN).
    pub fn is_truevolt(self) -> bool {
        self != DmmModel::Hp34401a
    }
}

/// Where an instrument is connected.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Port {
    /// A serial device (`/dev/ttyUSB0`, `COM3`, a pseudo-terminal).
    Serial(PathBuf),
    /// A TCP endpoint (`tcp://HOST:PORT`), e.g. a serial-to-Ethernet converter or ACL's port 9878.
    Tcp {
        /// Host name or address (IPv6 without brackets).
        host: String,
        /// TCP port (1..=65535).
        port: u16,
    },
    /// GPIB through a Prologix controller: `prologix:/dev/ttyUSB0?addr=22` (GPIB-USB) or
    /// `prologix-tcp://HOST[:1234]?addr=22` (GPIB-Ethernet). Kept as written: the link layer
    /// (`gyrocal_link::parse_port`) owns the syntax and checks it when the port is opened or
    /// the plan checked (`gyrocal check`).
    Gpib(String),
}

impl Port {
    /// Parses `tcp://HOST:PORT` (IPv6 as `tcp://[::1]:9878`) or a serial device path.
    pub fn parse(s: &str) -> Result<Port, String> {
        if s.trim().is_empty() {
            return Err("must not be empty".into());
        }
        if s.chars().any(char::is_control) {
            return Err(format!("must not contain control characters (got {s:?})"));
        }
        if let Some(rest) = s.strip_prefix("tcp://") {
            let bad = || format!("must be tcp://HOST:PORT with PORT in 1..=65535 (got {s:?})");
            let (host, port) = if let Some(v6) = rest.strip_prefix('[') {
                let (host, after) = v6.split_once(']').ok_or_else(bad)?;
                (host, after.strip_prefix(':').ok_or_else(bad)?)
            } else {
                rest.rsplit_once(':').ok_or_else(bad)?
            };
            if host.is_empty()
                || host.contains(['/', ' '])
                || (host.contains(':') && !rest.starts_with('['))
            {
                return Err(bad());
            }
            let port: u16 = port.parse().map_err(|_| bad())?;
            if port == 0 {
                return Err(bad());
            }
            return Ok(Port::Tcp {
                host: host.to_string(),
                port,
            });
        }
        if s.starts_with("prologix:") || s.starts_with("prologix-tcp://") {
            return Ok(Port::Gpib(s.to_string()));
        }
        if s.contains("://") {
            return Err(format!(
                "unknown scheme: use a device path, tcp://HOST:PORT, prologix:DEVICE?addr=N or \
                 prologix-tcp://HOST?addr=N (got {s:?})"
            ));
        }
        Ok(Port::Serial(PathBuf::from(s)))
    }
}

impl fmt::Display for Port {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Port::Serial(p) => write!(f, "{}", p.display()),
            Port::Tcp { host, port } if host.contains(':') => write!(f, "tcp://[{host}]:{port}"),
            Port::Tcp { host, port } => write!(f, "tcp://{host}:{port}"),
            Port::Gpib(spec) => f.write_str(spec),
        }
    }
}

/// The rate table's command language.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TableDialect {
    /// Acutronic ACL (ACUTROL3000), the first dialect gyrocal speaks.
    Acl,
    /// Ideal Aerosmith three-letter ASCII commands (`JOG`, `ACL`, `STO`, `PVE`, ...):
    /// experimental, written from public scripts, no vendor manual (see gyrocal-table's
    /// `aerosmith` module for what a lab must verify first).
    Aerosmith,
}

impl TableDialect {
    /// The name used in plan files.
    pub fn as_str(self) -> &'static str {
        match self {
            TableDialect::Acl => "acl",
            TableDialect::Aerosmith => "aerosmith",
        }
    }
}

/// RS-232 character framing (`8N2`, `7E2`, `7O2`): the link's type, named in plans as it
/// displays.
pub use gyrocal_link::Framing;

/// How the multimeter acquires a step's readings (see `hp34401a.md`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Acquisition {
    /// Let the sequencer choose: stream when the wire keeps up, memory otherwise.
    Auto,
    /// `READ?` with a sample count: readings stream as they are taken.
    Stream,
    /// `INIT;*OPC?` then `FETC?` in bursts of at most 512 readings.
    Memory,
    /// One `READ?` per reading (the slow baseline).
    Poll,
}

impl Acquisition {
    /// The name used in plan files.
    pub fn as_str(self) -> &'static str {
        match self {
            Acquisition::Auto => "auto",
            Acquisition::Stream => "stream",
            Acquisition::Memory => "memory",
            Acquisition::Poll => "poll",
        }
    }
}

/// The validated `[table]` section.
#[derive(Debug, Clone, PartialEq)]
pub struct TableSettings {
    /// Command language.
    pub dialect: TableDialect,
    /// Where the table controller is connected.
    pub port: Port,
    /// Serial baud rate (one of [`BAUD_RATES`]).
    pub baud: u32,
    /// Client-side rate limit, °/s, in (0, [`HARD_MAX_RATE_DPS`]].
    pub max_rate_dps: f64,
    /// Acceleration limit, °/s², in (0, [`HARD_MAX_ACCELERATION_DPS2`]].
    pub acceleration_dps2: f64,
    /// "At rate" tolerance on the measured rate, °/s (> 0).
    pub rate_tolerance_dps: f64,
    /// The measured rate must stay within tolerance this long (> 0).
    pub stability_window: Duration,
    /// Reaching the rate takes longer than this: a fault (> the stability window).
    pub at_rate_timeout: Duration,
}

/// The validated `[dmm]` section.
#[derive(Debug, Clone, PartialEq)]
pub struct DmmSettings {
    /// The meter's model.
    pub model: DmmModel,
    /// Where the multimeter is connected.
    pub port: Port,
    /// Serial baud rate (one of [`BAUD_RATES`]).
    pub baud: u32,
    /// Character framing.
    pub framing: Framing,
    /// DC range, V (one of [`RANGES_V`]).
    pub range_v: f64,
    /// Integration time in power-line cycles (one of [`KNOWN_NPLC_VALUES`]; the model's own
    /// list is checked by its driver crate).
    pub nplc: f64,
    /// Autozero on (doubles each reading's time).
    pub autozero: bool,
    /// Mains frequency, 50 or 60 Hz.
    pub line_hz: u32,
    /// Acquisition strategy.
    pub acquisition: Acquisition,
}

/// `[simulation]`: the truth of the in-process simulated bench used by `--simulate`.
/// Every key is optional; the defaults resemble the paper's HRG.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Simulation {
    /// Seed of every random stream (default 1).
    pub seed: u64,
    /// Scale factor `Kn`, V/(°/s) (default 0.3612, the paper's result; non-zero).
    pub scale_factor: f64,
    /// Bias `K0`, V (default 0.0088, the paper's result).
    pub bias: f64,
    /// Second-order term, V/(°/s)² (default 2e-5: about 8 mV at 20 °/s, the even-order
    /// residual shape of the paper).
    pub k2: f64,
    /// Third-order term, V/(°/s)³ (default 0).
    pub k3: f64,
    /// Relative difference of the two directions' scale factors, `(K+ - K-)/Kbar` (default 0,
    /// |asymmetry| < 0.1).
    pub asymmetry: f64,
    /// Standard deviation of one reading's noise, V (default 0.002, ≥ 0).
    pub noise_v: f64,
    /// Bias random walk, V/√s (default 0, ≥ 0).
    pub bias_walk: f64,
    /// Latitude of the bench, degrees; the vertical Earth rate 15.041 °/h · sin(latitude) adds
    /// to every input (default 0, within ±90).
    pub latitude_deg: f64,
    /// Table rate noise std, °/s (default 0.0002, ≥ 0).
    pub rate_noise_dps: f64,
    /// Table once-per-revolution rate ripple amplitude, °/s (default 0.0005, ≥ 0).
    pub ripple_dps: f64,
    /// The gyro's angle random walk N (white rate noise), °/√h: an Allan deviation of the
    /// rate reads 60·N °/h at τ = 1 s (default 0 = off, 0 to 100). The rate-noise keys are
    /// left out of the serialised form (and so of the hash) when at their default, so an
    /// older plan's hash is what it was before they existed.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub arw_deg_rt_h: f64,
    /// The gyro's bias instability B (flicker rate noise), °/h: the Allan deviation's floor is
    /// 0.664·B (default 0 = off, 0 to 1000).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub bias_instability_dph: f64,
    /// The gyro's rate random walk K, °/h/√h: the Allan deviation reads K/60 °/h at τ = 3 s
    /// (default 0 = off, 0 to 1000).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub rrw_dph_rt_h: f64,
    /// The step of the gyro's quantized output angle, arcsec (IEEE 952's Q = step/√12;
    /// default 0 = off, 0 to 3600).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub quantization_arcsec: f64,
    /// Warm-up transient: the gyro's bias starts off by this much and decays with
    /// `warmup_tau_s`, °/h (default 0 = off, 0 to 36000).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub warmup_dph: f64,
    /// Time constant of the warm-up transient, s (default 600, > 0 and at most 86400).
    #[serde(
        default = "default_warmup_tau_s",
        skip_serializing_if = "is_default_warmup_tau_s"
    )]
    pub warmup_tau_s: f64,
}

/// `[simulation] warmup_tau_s` when the plan does not say, s.
const DEFAULT_WARMUP_TAU_S: f64 = 600.0;

fn default_warmup_tau_s() -> f64 {
    DEFAULT_WARMUP_TAU_S
}

#[allow(clippy::trivially_copy_pass_by_ref)] // serde's skip_serializing_if passes a &f64
fn is_default_warmup_tau_s(v: &f64) -> bool {
    *v == DEFAULT_WARMUP_TAU_S
}

#[allow(clippy::trivially_copy_pass_by_ref)] // serde's skip_serializing_if passes a &f64
fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

impl Default for Simulation {
    fn default() -> Self {
        Simulation {
            seed: 1,
            scale_factor: 0.3612,
            bias: 0.0088,
            k2: 2e-5,
            k3: 0.0,
            asymmetry: 0.0,
            noise_v: 0.002,
            bias_walk: 0.0,
            latitude_deg: 0.0,
            rate_noise_dps: 0.0002,
            ripple_dps: 0.0005,
            arw_deg_rt_h: 0.0,
            bias_instability_dph: 0.0,
            rrw_dph_rt_h: 0.0,
            quantization_arcsec: 0.0,
            warmup_dph: 0.0,
            warmup_tau_s: DEFAULT_WARMUP_TAU_S,
        }
    }
}

/// A validated test plan. Built only by [`Plan::from_toml_str`], [`Plan::from_file`] or
/// [`Plan::from_doc`], so its invariants hold; serialises (serde) as its [`PlanDoc`].
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    kind: PlanKind,
    name: String,
    rates_dps: Vec<f64>,
    samples_per_rate: u32,
    settle: Duration,
    repeat: u32,
    whole_revolutions: u32,
    table: TableSettings,
    dmm: DmmSettings,
    simulation: Simulation,
    dut: Option<PlanDut>,
    acceptance: Option<AcceptanceSpec>,
    drift: Option<DriftSettings>,
    warmup: Option<WarmupSettings>,
    /// The file had a `[table]` section (without one, `[drift] table = "none"`: `table` holds
    /// [`TableDoc::unused`]'s settings, which nothing reads).
    table_given: bool,
}

/// What a step acquires.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Acquire {
    /// A fixed number of readings (`samples_per_rate`; also zero-rate steps of a
    /// whole-revolution plan).
    Samples(u32),
    /// Readings spanning this long, a whole number of table turns
    /// (`whole_revolutions · 360 / |ω|`); see [`Step::sample_count`].
    Span {
        /// Required acquisition duration.
        duration: Duration,
        /// Number of whole turns it covers.
        revolutions: u32,
    },
}

/// One step of the schedule: one rate of one pass.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Step {
    /// 0-based position in the schedule; stable for a given plan (the run directory's `step`).
    pub index: usize,
    /// 0-based pass (`0..repeat`).
    pub pass: u32,
    /// Demanded rate, °/s.
    pub rate_dps: f64,
    /// What to acquire.
    pub acquire: Acquire,
}

impl Step {
    /// Readings to take given the meter's time per reading: `Samples(n)` gives `n`; `Span`
    /// gives `round(duration / reading_period)` (at least 1), the count whose total time is
    /// closest to the whole turns.
    pub fn sample_count(&self, reading_period: Duration) -> u64 {
        match self.acquire {
            Acquire::Samples(n) => u64::from(n),
            Acquire::Span { duration, .. } => {
                let p = reading_period.as_secs_f64();
                if p <= 0.0 || !p.is_finite() {
                    return 1;
                }
                let n = (duration.as_secs_f64() / p).round();
                // `as` saturates; the bound keeps a silly period from asking for billions.
                (n.max(1.0) as u64).min(u64::from(u32::MAX))
            }
        }
    }

    /// The required acquisition duration, for whole-revolution steps.
    pub fn span(&self) -> Option<Duration> {
        match self.acquire {
            Acquire::Samples(_) => None,
            Acquire::Span { duration, .. } => Some(duration),
        }
    }
}

impl Plan {
    /// Reads and validates a plan file; errors name `path`.
    /// A file larger than [`MAX_PLAN_BYTES`] is refused after reading at most that much.
    pub fn from_file(path: &Path) -> Result<Plan, PlanError> {
        let src = read_document(path, PLAN_DOCUMENT)?;
        Plan::from_toml_str(&src, path)
    }

    /// Parses and validates plan text; `origin` is the file name used in errors.
    pub fn from_toml_str(src: &str, origin: &Path) -> Result<Plan, PlanError> {
        let location = |offset: Option<usize>| Location::in_text(origin, src, offset);
        let syntax = |e: toml::de::Error| {
            let offset = e.span().map(|span| span.start);
            PlanError::Syntax {
                location: location(offset),
                section: offset.and_then(|o| section_at(src, o)),
                message: plain_words(e.message().trim()),
            }
        };
        // The shape first (sections, keys, kinds of value), so a missing key names its own
        // section and a wrong type is said in words; then serde, with the spans.
        let root = DeTable::parse(src).map_err(syntax)?;
        let mut findings = check_shape(root.get_ref());
        findings.sort_by_key(|f| (f.rank, f.offset.unwrap_or(usize::MAX)));
        if let Some(f) = findings.into_iter().next() {
            return Err(finding_error(f, location));
        }
        let raw: RawFile = toml::from_str(src).map_err(syntax)?;
        let mut spans = Spans::default();
        let doc = raw_to_doc(raw, &mut spans);
        let cx = Ctx {
            origin,
            src: Some(src),
            spans: &spans,
        };
        validate(doc.map_err(|(key, message)| cx.err(key, message))?, &cx)
    }

    /// Validates a plain document (e.g. read back from a manifest); errors carry `origin`
    /// without a line.
    pub fn from_doc(doc: PlanDoc, origin: &Path) -> Result<Plan, PlanError> {
        validate(
            doc,
            &Ctx {
                origin,
                src: None,
                spans: &Spans::default(),
            },
        )
    }

    /// The plan as parsed, defaults explicit (what the manifest stores).
    pub fn to_doc(&self) -> PlanDoc {
        PlanDoc {
            plan: PlanSectionDoc {
                kind: self.kind.as_str().to_string(),
                name: self.name.clone(),
                rates_dps: self.rates_dps.clone(),
                samples_per_rate: self.samples_per_rate.into(),
                settle_s: self.settle.as_secs_f64(),
                repeat: self.repeat.into(),
                whole_revolutions: self.whole_revolutions.into(),
            },
            table: self.table_given.then(|| TableDoc {
                dialect: self.table.dialect.as_str().into(),
                port: self.table.port.to_string(),
                baud: self.table.baud.into(),
                max_rate_dps: self.table.max_rate_dps,
                acceleration_dps2: self.table.acceleration_dps2,
                rate_tolerance_dps: self.table.rate_tolerance_dps,
                stability_window_s: self.table.stability_window.as_secs_f64(),
                at_rate_timeout_s: self.table.at_rate_timeout.as_secs_f64(),
            }),
            dmm: DmmDoc {
                model: self.dmm.model.as_str().into(),
                port: self.dmm.port.to_string(),
                baud: self.dmm.baud.into(),
                framing: self.dmm.framing.to_string(),
                range_v: self.dmm.range_v,
                nplc: self.dmm.nplc,
                autozero: self.dmm.autozero,
                line_hz: self.dmm.line_hz.into(),
                acquisition: self.dmm.acquisition.as_str().into(),
            },
            simulation: self.simulation.clone(),
            dut: self.dut.clone(),
            acceptance: self.acceptance.clone(),
            drift: self.drift.map(|d| DriftDoc {
                table: d.table.as_str().into(),
                axis: d.earth.map(|(a, _)| a.as_str().into()),
                latitude_deg: d.earth.map(|(_, l)| l),
            }),
            warmup: self.warmup.map(|w| WarmupDoc {
                window_s: w.window.as_secs_f64(),
                tolerance_v: w.tolerance_v,
                max_s: w.max.as_secs_f64(),
            }),
        }
    }

    /// SHA-256 (lower-case hex) of the canonical serialisation; see the module docs for what
    /// it covers (everything but the two port fields, `[dut]` and `[acceptance]`).
    pub fn hash(&self) -> String {
        let mut doc = self.to_doc();
        if let Some(t) = doc.table.as_mut() {
            t.port.clear();
        }
        doc.dmm.port.clear();
        // one plan serves many gyros, and limits can be re-evaluated: neither is the method
        doc.dut = None;
        doc.acceptance = None;
        let mut h = Sha256::new();
        h.update(HASH_DOMAIN.as_bytes());
        // Serialising plain structs of numbers, strings and bools to JSON cannot fail; an
        // empty body would still hash deterministically.
        h.update(serde_json::to_vec(&doc).unwrap_or_default());
        h.finalize().iter().map(|b| format!("{b:02x}")).collect()
    }

    /// The schedule: `repeat` passes over `rates_dps`, in order.
    pub fn schedule(&self) -> Vec<Step> {
        let mut steps = Vec::with_capacity(self.step_count());
        for pass in 0..self.repeat {
            for &rate_dps in &self.rates_dps {
                let acquire = if self.whole_revolutions > 0 && rate_dps != 0.0 {
                    let secs = f64::from(self.whole_revolutions) * 360.0 / rate_dps.abs();
                    // Validation bounds `secs` to MAX_DURATION_S; the fallback is unreachable.
                    let duration = Duration::try_from_secs_f64(secs)
                        .unwrap_or(Duration::from_secs_f64(MAX_DURATION_S));
                    Acquire::Span {
                        duration,
                        revolutions: self.whole_revolutions,
                    }
                } else {
                    Acquire::Samples(self.samples_per_rate)
                };
                steps.push(Step {
                    index: steps.len(),
                    pass,
                    rate_dps,
                    acquire,
                });
            }
        }
        steps
    }

    /// Number of steps (`repeat × rates`).
    pub fn step_count(&self) -> usize {
        self.rates_dps.len() * self.repeat as usize
    }

    /// Free-text name.
    pub fn name(&self) -> &str {
        &self.name
    }
    /// What the plan measures.
    pub fn kind(&self) -> PlanKind {
        self.kind
    }

    /// Rates of one pass, in the order applied, °/s.
    pub fn rates_dps(&self) -> &[f64] {
        &self.rates_dps
    }
    /// Readings per rate (for zero-rate and non-revolution steps).
    pub fn samples_per_rate(&self) -> u32 {
        self.samples_per_rate
    }
    /// Dwell after "at rate", before acquiring.
    pub fn settle(&self) -> Duration {
        self.settle
    }
    /// Passes over the schedule.
    pub fn repeat(&self) -> u32 {
        self.repeat
    }
    /// Whole turns per non-zero rate (0: off).
    pub fn whole_revolutions(&self) -> u32 {
        self.whole_revolutions
    }
    /// `[table]`.
    pub fn table(&self) -> &TableSettings {
        &self.table
    }
    /// `[dmm]`.
    pub fn dmm(&self) -> &DmmSettings {
        &self.dmm
    }
    /// Whether the run uses a rate table (every plan but a drift record with
    /// `[drift] table = "none"`).
    pub fn has_table(&self) -> bool {
        self.drift().table != TableRole::None
    }
    /// `[drift]`: the table's role and the bench's orientation (the defaults when the plan
    /// has no `[drift]`; only a drift plan may have one).
    pub fn drift(&self) -> DriftSettings {
        self.drift.unwrap_or_default()
    }
    /// `[warmup]`, when the plan asks for a warm-up.
    pub fn warmup(&self) -> Option<&WarmupSettings> {
        self.warmup.as_ref()
    }
    /// `[simulation]`.
    pub fn simulation(&self) -> &Simulation {
        &self.simulation
    }
    /// `[dut]`, when the plan names the gyro (a `[dut]` section without keys is `None`).
    pub fn dut(&self) -> Option<&PlanDut> {
        self.dut.as_ref()
    }
    /// `[acceptance]`, when the plan has a specification.
    pub fn acceptance(&self) -> Option<&AcceptanceSpec> {
        self.acceptance.as_ref()
    }
    /// Overrides the table's port (`--table-port`); ports are not part of the hash.
    pub fn set_table_port(&mut self, port: Port) {
        self.table.port = port;
    }
    /// Overrides the multimeter's port (`--dmm-port`); ports are not part of the hash.
    pub fn set_dmm_port(&mut self, port: Port) {
        self.dmm.port = port;
    }
}

impl Serialize for Plan {
    fn serialize<Ser: serde::Serializer>(&self, s: Ser) -> Result<Ser::Ok, Ser::Error> {
        self.to_doc().serialize(s)
    }
}

impl<'de> Deserialize<'de> for Plan {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let doc = PlanDoc::deserialize(d)?;
        Plan::from_doc(doc, Path::new("plan")).map_err(serde::de::Error::custom)
    }
}

// ---------------------------------------------------------------------------------------------
// Standalone acceptance files
// ---------------------------------------------------------------------------------------------

/// Reads a standalone acceptance file (`gyrocal report RUN --acceptance FILE`): its top level
/// is what a plan's `[acceptance]` section holds, `decision_rule` and one table per quantity:
///
/// ```toml
/// decision_rule = "guarded"
/// [scale_factor]
/// min = 0.049
/// max = 0.051
/// ```
///
/// Errors name the file, the line and the key as a plan's would (`[acceptance.scale_factor]
/// max ...`). A file larger than [`MAX_PLAN_BYTES`] is refused after reading at most that much.
pub fn load_acceptance(path: &Path) -> Result<AcceptanceSpec, PlanError> {
    let src = read_document(path, ACCEPTANCE_DOCUMENT)?;
    acceptance_from_toml_str(&src, path)
}

/// Parses and validates the text of a standalone acceptance file (see [`load_acceptance`]);
/// `document` is the file name used in errors.
pub fn acceptance_from_toml_str(src: &str, document: &Path) -> Result<AcceptanceSpec, PlanError> {
    let location = |offset: Option<usize>| Location::in_text(document, src, offset);
    let syntax = |e: toml::de::Error| {
        let offset = e.span().map(|span| span.start);
        PlanError::Syntax {
            location: location(offset),
            section: Some(
                offset
                    .and_then(|o| section_at(src, o))
                    .map_or_else(|| "acceptance".into(), |s| format!("acceptance.{s}")),
            ),
            message: plain_words(e.message().trim()),
        }
    };
    let root = DeTable::parse(src).map_err(syntax)?;
    let mut findings = Vec::new();
    check_keys(
        "acceptance",
        ACCEPTANCE_KEYS,
        root.get_ref(),
        None,
        &mut findings,
    );
    findings.sort_by_key(|f| (f.rank, f.offset.unwrap_or(usize::MAX)));
    if let Some(f) = findings.into_iter().next() {
        return Err(finding_error(f, location));
    }
    let raw: RawAcceptance = toml::from_str(src).map_err(syntax)?;
    let mut spans = Spans::default();
    let spec = raw_acceptance(raw, &mut spans);
    let cx = Ctx {
        origin: document,
        src: Some(src),
        spans: &spans,
    };
    let spec = spec.map_err(|(key, message)| cx.err(key, message))?;
    validate_acceptance(&spec, &cx)?;
    Ok(spec)
}

/// A stage-1 finding as the error it reports.
fn finding_error(f: Finding, location: impl Fn(Option<usize>) -> Location) -> PlanError {
    match (f.section, f.key) {
        (Some(section), Some(key)) => PlanError::Invalid {
            location: location(f.offset),
            section,
            key,
            message: f.message,
        },
        (section, _) => PlanError::Syntax {
            location: location(f.offset),
            section,
            message: f.message,
        },
    }
}

// ---------------------------------------------------------------------------------------------
// Stage 2: validation
// ---------------------------------------------------------------------------------------------

/// The raw file with defaults filled in. The one check here is the simulation seed's sign (the
/// seed is unsigned where the rest of the plan is validated); the error is `(key, message)`.
fn raw_to_doc(raw: RawFile, sp: &mut Spans) -> Result<PlanDoc, (&'static str, String)> {
    let d = Simulation::default();
    let p = raw.plan;
    let rates = sp.take("plan.rates_dps", p.rates_dps);
    let rates_dps = rates
        .into_iter()
        .enumerate()
        .map(|(i, r)| sp.take(&format!("plan.rates_dps[{i}]"), r))
        .collect();
    let t = raw.table;
    let m = raw.dmm;
    let plan = PlanSectionDoc {
        kind: sp.opt("plan.kind", p.kind, default_kind()),
        name: sp.opt("plan.name", p.name, String::new()),
        rates_dps,
        samples_per_rate: sp.int("plan.samples_per_rate", Some(p.samples_per_rate), 0)?,
        settle_s: sp.opt("plan.settle_s", p.settle_s, 10.0),
        repeat: sp.int("plan.repeat", p.repeat, 1)?,
        whole_revolutions: sp.int("plan.whole_revolutions", p.whole_revolutions, 0)?,
    };
    let table = match t {
        None => None,
        Some(t) => Some(TableDoc {
            dialect: sp.opt("table.dialect", t.dialect, "acl".into()),
            port: sp.take("table.port", t.port),
            baud: sp.int("table.baud", t.baud, 9600)?,
            max_rate_dps: sp.take("table.max_rate_dps", t.max_rate_dps),
            acceleration_dps2: sp.take("table.acceleration_dps2", t.acceleration_dps2),
            rate_tolerance_dps: sp.opt("table.rate_tolerance_dps", t.rate_tolerance_dps, 0.001),
            stability_window_s: sp.opt("table.stability_window_s", t.stability_window_s, 2.0),
            at_rate_timeout_s: sp.opt("table.at_rate_timeout_s", t.at_rate_timeout_s, 60.0),
        }),
    };
    let dmm = DmmDoc {
        model: sp.opt("dmm.model", m.model, default_model()),
        port: sp.take("dmm.port", m.port),
        baud: sp.int("dmm.baud", m.baud, 9600)?,
        framing: sp.opt("dmm.framing", m.framing, "8N2".into()),
        range_v: sp.opt("dmm.range_v", m.range_v, 10.0),
        nplc: sp.opt("dmm.nplc", m.nplc, 1.0),
        autozero: sp.opt("dmm.autozero", m.autozero, true),
        line_hz: sp.int("dmm.line_hz", m.line_hz, 50)?,
        acquisition: sp.opt("dmm.acquisition", m.acquisition, "auto".into()),
    };
    let simulation = match raw.simulation {
        None => d,
        Some(s) => Simulation {
            seed: {
                let seed = sp.int("simulation.seed", s.seed, 1)?;
                u64::try_from(seed).map_err(|_| {
                    (
                        "simulation.seed",
                        int_error("simulation.seed", &seed.to_string(), true),
                    )
                })?
            },
            scale_factor: sp.opt("simulation.scale_factor", s.scale_factor, d.scale_factor),
            bias: sp.opt("simulation.bias", s.bias, d.bias),
            k2: sp.opt("simulation.k2", s.k2, d.k2),
            k3: sp.opt("simulation.k3", s.k3, d.k3),
            asymmetry: sp.opt("simulation.asymmetry", s.asymmetry, d.asymmetry),
            noise_v: sp.opt("simulation.noise_v", s.noise_v, d.noise_v),
            bias_walk: sp.opt("simulation.bias_walk", s.bias_walk, d.bias_walk),
            latitude_deg: sp.opt("simulation.latitude_deg", s.latitude_deg, d.latitude_deg),
            rate_noise_dps: sp.opt(
                "simulation.rate_noise_dps",
                s.rate_noise_dps,
                d.rate_noise_dps,
            ),
            ripple_dps: sp.opt("simulation.ripple_dps", s.ripple_dps, d.ripple_dps),
            arw_deg_rt_h: sp.opt("simulation.arw_deg_rt_h", s.arw_deg_rt_h, d.arw_deg_rt_h),
            bias_instability_dph: sp.opt(
                "simulation.bias_instability_dph",
                s.bias_instability_dph,
                d.bias_instability_dph,
            ),
            rrw_dph_rt_h: sp.opt("simulation.rrw_dph_rt_h", s.rrw_dph_rt_h, d.rrw_dph_rt_h),
            quantization_arcsec: sp.opt(
                "simulation.quantization_arcsec",
                s.quantization_arcsec,
                d.quantization_arcsec,
            ),
            warmup_dph: sp.opt("simulation.warmup_dph", s.warmup_dph, d.warmup_dph),
            warmup_tau_s: sp.opt("simulation.warmup_tau_s", s.warmup_tau_s, d.warmup_tau_s),
        },
    };
    let dut = raw.dut.map(|d| PlanDut {
        serial: d.serial.map(|v| sp.take("dut.serial", v)),
        model: d.model.map(|v| sp.take("dut.model", v)),
        manufacturer: d.manufacturer.map(|v| sp.take("dut.manufacturer", v)),
        condition: d.condition.map(|v| sp.take("dut.condition", v)),
        notes: d.notes.map(|v| sp.take("dut.notes", v)),
    });
    let acceptance = match raw.acceptance {
        None => None,
        Some(a) => Some(raw_acceptance(a, sp)?),
    };
    let drift = raw.drift.map(|d| DriftDoc {
        table: sp.opt("drift.table", d.table, TableRole::Hold.as_str().into()),
        axis: d.axis.map(|v| sp.take("drift.axis", v)),
        latitude_deg: d.latitude_deg.map(|v| sp.take("drift.latitude_deg", v)),
    });
    let warmup = raw.warmup.map(|w| WarmupDoc {
        window_s: sp.opt("warmup.window_s", w.window_s, DEFAULT_WARMUP_WINDOW_S),
        tolerance_v: w.tolerance_v.map(|v| sp.take("warmup.tolerance_v", v)),
        max_s: sp.opt("warmup.max_s", w.max_s, DEFAULT_WARMUP_MAX_S),
    });
    Ok(PlanDoc {
        plan,
        table,
        dmm,
        simulation,
        dut,
        acceptance,
        drift,
        warmup,
    })
}

/// `[acceptance]` (or a standalone acceptance file) with its spans kept under
/// `acceptance.QUANTITY.KEY`; the decision rule is checked here, the limits by validation.
fn raw_acceptance(
    mut a: RawAcceptance,
    sp: &mut Spans,
) -> Result<AcceptanceSpec, (&'static str, String)> {
    let rule = match a.decision_rule.take() {
        None => Rule::default(),
        Some(r) => {
            let r = sp.take("acceptance.decision_rule", r);
            Rule::from_name(&r).ok_or((
                "acceptance.decision_rule",
                format!("= {r:?} is not a decision rule: write \"simple\" or \"guarded\""),
            ))?
        }
    };
    let mut limits = BTreeMap::new();
    for (q, raw) in a.into_limits() {
        let Some(raw) = raw else { continue };
        let at = format!("acceptance.{}", q.name());
        let raw = sp.take(&at, raw);
        let mut bound =
            |key: &str, v: Option<S<f64>>| v.map(|v| sp.take(&format!("{at}.{key}"), v));
        limits.insert(
            q,
            Limits {
                min: bound("min", raw.min),
                max: bound("max", raw.max),
                marginal_min: bound("marginal_min", raw.marginal_min),
                marginal_max: bound("marginal_max", raw.marginal_max),
            },
        );
    }
    Ok(AcceptanceSpec { rule, limits })
}

struct Ctx<'a> {
    origin: &'a Path,
    src: Option<&'a str>,
    spans: &'a Spans,
}

impl Ctx<'_> {
    /// An error at `path` (`section.key`), placed at the value's span when the file had it.
    fn err(&self, path: &str, message: String) -> PlanError {
        // `acceptance.scale_factor.min` is the key `min` of [acceptance.scale_factor]
        let (section, key) = path.rsplit_once('.').unwrap_or(("plan", path));
        let (line, column) = match (self.src, self.spans.0.get(path)) {
            (Some(src), Some(span)) => {
                let (l, c) = line_col(src, span.start);
                (Some(l), Some(c))
            }
            _ => (None, None),
        };
        PlanError::Invalid {
            location: Location {
                file: self.origin.to_path_buf(),
                line,
                column,
            },
            section: section.to_string(),
            key: key.to_string(),
            message,
        }
    }

    fn has(&self, path: &str) -> bool {
        self.spans.0.contains_key(path)
    }

    fn finite(&self, path: &str, v: f64) -> Result<f64, PlanError> {
        if v.is_finite() {
            Ok(v)
        } else {
            Err(self.err(path, format!("must be finite (got {v})")))
        }
    }

    fn one_of_f64(&self, path: &str, v: f64, allowed: &[f64]) -> Result<f64, PlanError> {
        // Exact comparison is intended: TOML `0.02` and the constant 0.02 are the same double.
        if allowed.contains(&v) {
            Ok(v)
        } else {
            Err(self.err(path, format!("must be one of {allowed:?} (got {v})")))
        }
    }

    fn one_of_u32(&self, path: &str, v: i64, allowed: &[u32]) -> Result<u32, PlanError> {
        match u32::try_from(v) {
            Ok(u) if allowed.contains(&u) => Ok(u),
            _ => Err(self.err(path, int_error(path, &v.to_string(), true))),
        }
    }

    /// An integer key: `v` must be in `lo..=hi` (both within `u32`).
    fn int_in(&self, path: &str, v: i64, lo: u32, hi: u32) -> Result<u32, PlanError> {
        match u32::try_from(v) {
            Ok(u) if (lo..=hi).contains(&u) => Ok(u),
            _ => Err(self.err(path, int_error(path, &v.to_string(), true))),
        }
    }

    fn duration(&self, path: &str, v: f64, min_exclusive: bool) -> Result<Duration, PlanError> {
        let v = self.finite(path, v)?;
        if v < 0.0 || (min_exclusive && v == 0.0) {
            let op = if min_exclusive { ">" } else { ">=" };
            return Err(self.err(path, format!("must be {op} 0 (got {v})")));
        }
        if v > MAX_DURATION_S {
            return Err(self.err(path, format!("must be <= {MAX_DURATION_S} s (got {v})")));
        }
        let d = Duration::from_secs_f64(v);
        // a positive duration below a nanosecond would be stored (and read back) as 0
        if min_exclusive && d.is_zero() {
            return Err(self.err(path, format!("must be at least 1e-9 s (got {v})")));
        }
        Ok(d)
    }

    fn port(&self, path: &str, v: &str) -> Result<Port, PlanError> {
        Port::parse(v).map_err(|m| self.err(path, m))
    }
}

fn validate_drift(d: &DriftDoc, cx: &Ctx<'_>) -> Result<DriftSettings, PlanError> {
    let table = TableRole::ALL
        .into_iter()
        .find(|r| r.as_str() == d.table.trim())
        .ok_or_else(|| {
            cx.err(
                "drift.table",
                format!(
                    "= {:?} is not a table role: write \"hold\" (servo on at 0 °/s), \"servo_off\" (stopped, servo off) or \"none\" (no table)",
                    d.table
                ),
            )
        })?;
    let axis = match &d.axis {
        None => None,
        Some(a) => Some(Axis::from_name(a).ok_or_else(|| {
            cx.err(
                "drift.axis",
                format!(
                    "= {a:?} is not a direction: write \"up\", \"down\", \"north\", \"south\", \"east\" or \"west\""
                ),
            )
        })?),
    };
    let latitude = match d.latitude_deg {
        None => None,
        Some(l) => {
            let l = cx.finite("drift.latitude_deg", l)?;
            if !(-90.0..=90.0).contains(&l) {
                return Err(cx.err(
                    "drift.latitude_deg",
                    format!("must be from -90 to 90 degrees (got {l})"),
                ));
            }
            Some(l)
        }
    };
    let earth = match (axis, latitude) {
        (Some(a), Some(l)) => Some((a, l)),
        (None, None) => None,
        (Some(_), None) => {
            return Err(cx.err(
                "drift.axis",
                "needs latitude_deg too: the Earth's rate along the axis depends on it".into(),
            ));
        }
        (None, Some(_)) => {
            return Err(cx.err(
                "drift.latitude_deg",
                "needs axis too: the Earth's rate seen depends on where the input axis points"
                    .into(),
            ));
        }
    };
    Ok(DriftSettings { table, earth })
}

fn validate_warmup(w: &WarmupDoc, cx: &Ctx<'_>) -> Result<WarmupSettings, PlanError> {
    let window = cx.duration("warmup.window_s", w.window_s, true)?;
    let max = cx.duration("warmup.max_s", w.max_s, true)?;
    if max < window * 2 {
        return Err(cx.err(
            "warmup.max_s",
            format!(
                "= {} s is shorter than two windows ({} s): the criterion compares consecutive window means",
                w.max_s,
                2.0 * w.window_s
            ),
        ));
    }
    let tolerance_v = match w.tolerance_v {
        None => None,
        Some(t) => {
            let t = cx.finite("warmup.tolerance_v", t)?;
            if t <= 0.0 {
                return Err(cx.err("warmup.tolerance_v", format!("must be > 0 V (got {t})")));
            }
            Some(t)
        }
    };
    Ok(WarmupSettings {
        window,
        tolerance_v,
        max,
    })
}

fn validate(doc: PlanDoc, cx: &Ctx<'_>) -> Result<Plan, PlanError> {
    let PlanDoc {
        plan: p,
        table: t_given,
        dmm: m,
        simulation: s,
        dut,
        acceptance,
        drift,
        warmup,
    } = doc;

    // [table] first: the rates are checked against its limits. A drift record without a
    // table (`[drift] table = "none"`) may leave the section out.
    let no_table = drift
        .as_ref()
        .is_some_and(|d| d.table.trim() == TableRole::None.as_str());
    let table_given = t_given.is_some();
    let t = match t_given {
        Some(t) => t,
        None if no_table => TableDoc::unused(),
        None => {
            return Err(cx.err(
                "table.port",
                "the section [table] is missing (required): add a line [table] followed by port, max_rate_dps, acceleration_dps2 (or, for a drift record on a bench without a table, [drift] table = \"none\")"
                    .into(),
            ));
        }
    };
    let dialect = match t.dialect.to_ascii_lowercase().as_str() {
        "acl" => TableDialect::Acl,
        "aerosmith" => TableDialect::Aerosmith,
        _ => {
            return Err(cx.err(
                "table.dialect",
                format!(
                    "must be \"acl\" or \"aerosmith\" (experimental) (got {:?})",
                    t.dialect
                ),
            ));
        }
    };
    let table_port = cx.port("table.port", &t.port)?;
    let table_baud = cx.one_of_u32("table.baud", t.baud, &BAUD_RATES)?;
    let max_rate = cx.finite("table.max_rate_dps", t.max_rate_dps)?;
    if max_rate <= 0.0 || max_rate > HARD_MAX_RATE_DPS {
        return Err(cx.err(
            "table.max_rate_dps",
            format!("must be > 0 and <= {HARD_MAX_RATE_DPS} (got {max_rate})"),
        ));
    }
    let acc = cx.finite("table.acceleration_dps2", t.acceleration_dps2)?;
    if acc <= 0.0 {
        return Err(cx.err(
            "table.acceleration_dps2",
            format!("must be > 0 (got {acc})"),
        ));
    }
    if acc > HARD_MAX_ACCELERATION_DPS2 {
        return Err(cx.err(
            "table.acceleration_dps2",
            format!("must be <= {HARD_MAX_ACCELERATION_DPS2} (got {acc})"),
        ));
    }
    let tol = cx.finite("table.rate_tolerance_dps", t.rate_tolerance_dps)?;
    if tol <= 0.0 || tol > max_rate {
        return Err(cx.err(
            "table.rate_tolerance_dps",
            format!("must be > 0 and <= max_rate_dps {max_rate} (got {tol})"),
        ));
    }
    let window = cx.duration("table.stability_window_s", t.stability_window_s, true)?;
    let timeout = cx.duration("table.at_rate_timeout_s", t.at_rate_timeout_s, true)?;
    if timeout <= window {
        let key = if cx.has("table.at_rate_timeout_s") || !cx.has("table.stability_window_s") {
            "table.at_rate_timeout_s"
        } else {
            "table.stability_window_s"
        };
        let default = |k: &str| {
            if cx.src.is_none() || cx.has(k) {
                ""
            } else {
                " (the default)"
            }
        };
        let (timeout_s, window_s) = (t.at_rate_timeout_s, t.stability_window_s);
        let timeout_d = default("table.at_rate_timeout_s");
        let window_d = default("table.stability_window_s");
        let message = if key == "table.at_rate_timeout_s" {
            format!(
                "= {timeout_s}{timeout_d} must be greater than stability_window_s = \
                 {window_s}{window_d} (the rate must hold for the window before the timeout \
                 ends): raise at_rate_timeout_s or lower stability_window_s"
            )
        } else {
            format!(
                "= {window_s}{window_d} must be less than at_rate_timeout_s = \
                 {timeout_s}{timeout_d} (the rate must hold for the window before the timeout \
                 ends): lower stability_window_s or raise at_rate_timeout_s"
            )
        };
        return Err(cx.err(key, message));
    }

    // [plan]
    let samples_per_rate = cx.int_in(
        "plan.samples_per_rate",
        p.samples_per_rate,
        1,
        MAX_SAMPLES_PER_RATE,
    )?;
    let repeat = cx.int_in("plan.repeat", p.repeat, 1, MAX_REPEAT)?;
    let whole_revolutions = cx.int_in(
        "plan.whole_revolutions",
        p.whole_revolutions,
        0,
        MAX_WHOLE_REVOLUTIONS,
    )?;
    let mut rates = Vec::with_capacity(p.rates_dps.len());
    for (i, &r) in p.rates_dps.iter().enumerate() {
        let key = format!("plan.rates_dps[{i}]");
        let r = cx.finite(&key, r)?;
        if r.abs() > max_rate {
            return Err(cx.err(
                &key,
                format!("|{r}| exceeds [table] max_rate_dps = {max_rate}"),
            ));
        }
        if whole_revolutions > 0 && r != 0.0 {
            let span = f64::from(whole_revolutions) * 360.0 / r.abs();
            if span > MAX_DURATION_S {
                return Err(cx.err(
                    &key,
                    format!(
                        "{r} deg/s needs {span:.0} s for {} whole revolution(s), over the \
                         {MAX_DURATION_S} s limit of one step",
                        whole_revolutions
                    ),
                ));
            }
        }
        rates.push(if r == 0.0 { 0.0 } else { r }); // -0 is 0
    }
    let kind = PlanKind::ALL
        .into_iter()
        .find(|k| k.as_str() == p.kind.trim())
        .ok_or_else(|| {
            cx.err(
                "plan.kind",
                format!(
                    "unknown kind {:?}: write \"scale_factor\" (a sweep of rates) or \"drift\" (a static record at zero rate)",
                    p.kind
                ),
            )
        })?;
    let mut distinct = rates.clone();
    distinct.sort_by(f64::total_cmp);
    distinct.dedup();
    if kind == PlanKind::Drift {
        // exactly one rate: each listed rate is one more record segment, so [0, 0] would
        // silently double the record
        if rates != [0.0] {
            return Err(cx.err(
                "plan.rates_dps",
                format!(
                    "a drift plan records once at rest: write exactly rates_dps = [0] (got {:?}; \
                     each listed rate would be one more record)",
                    p.rates_dps
                ),
            ));
        }
    } else if distinct.len() < 2 {
        return Err(cx.err(
            "plan.rates_dps",
            format!(
                "needs at least two distinct rates to fit a line (got {})",
                distinct.len()
            ),
        ));
    }
    let settle = cx.duration("plan.settle_s", p.settle_s, false)?;

    // [dmm]
    let model = DmmModel::ALL
        .into_iter()
        .find(|d| d.as_str().eq_ignore_ascii_case(m.model.trim()))
        .ok_or_else(|| {
            cx.err(
                "dmm.model",
                format!(
                    "must be \"34401a\", \"34460a\", \"34461a\", \"34465a\" or \"34470a\" (got {:?})",
                    m.model
                ),
            )
        })?;
    let dmm_port = cx.port("dmm.port", &m.port)?;
    if model.is_truevolt() && !matches!(dmm_port, Port::Tcp { .. }) {
        return Err(cx.err(
            "dmm.port",
            format!(
                "a {} is reached over LAN: use tcp://HOST:5025 (got {dmm_port})",
                model.as_str()
            ),
        ));
    }
    if dmm_port == table_port {
        return Err(cx.err(
            "dmm.port",
            format!("is the same as [table] port ({dmm_port})"),
        ));
    }
    let dmm_baud = cx.one_of_u32("dmm.baud", m.baud, &BAUD_RATES)?;
    let Ok(framing) = m.framing.parse::<Framing>() else {
        return Err(cx.err(
            "dmm.framing",
            format!("must be \"8N2\", \"7E2\" or \"7O2\" (got {:?})", m.framing),
        ));
    };
    let range_v = cx.one_of_f64("dmm.range_v", m.range_v, &RANGES_V)?;
    let nplc = cx.one_of_f64("dmm.nplc", m.nplc, &KNOWN_NPLC_VALUES)?;
    let line_hz = cx.one_of_u32("dmm.line_hz", m.line_hz, &LINE_HZ)?;
    let acquisition = match m.acquisition.to_ascii_lowercase().as_str() {
        "auto" => Acquisition::Auto,
        "stream" => Acquisition::Stream,
        "memory" => Acquisition::Memory,
        "poll" => Acquisition::Poll,
        _ => {
            return Err(cx.err(
                "dmm.acquisition",
                format!(
                    "must be auto, stream, memory or poll (got {:?})",
                    m.acquisition
                ),
            ));
        }
    };

    // [simulation]
    let scale_factor = cx.finite("simulation.scale_factor", s.scale_factor)?;
    if scale_factor == 0.0 {
        return Err(cx.err("simulation.scale_factor", "must be non-zero (got 0)".into()));
    }
    cx.finite("simulation.bias", s.bias)?;
    cx.finite("simulation.k2", s.k2)?;
    cx.finite("simulation.k3", s.k3)?;
    let asym = cx.finite("simulation.asymmetry", s.asymmetry)?;
    if asym.abs() >= 0.1 {
        return Err(cx.err(
            "simulation.asymmetry",
            format!("must be within ±0.1 (got {asym})"),
        ));
    }
    for (key, v) in [
        ("simulation.noise_v", s.noise_v),
        ("simulation.bias_walk", s.bias_walk),
        ("simulation.rate_noise_dps", s.rate_noise_dps),
        ("simulation.ripple_dps", s.ripple_dps),
    ] {
        let v = cx.finite(key, v)?;
        if v < 0.0 {
            return Err(cx.err(key, format!("must be >= 0 (got {v})")));
        }
    }
    let lat = cx.finite("simulation.latitude_deg", s.latitude_deg)?;
    if lat.abs() > 90.0 {
        return Err(cx.err(
            "simulation.latitude_deg",
            format!("must be within ±90 (got {lat})"),
        ));
    }
    // the gyro's rate-noise terms: finite, ≥ 0 (0 = off), below a bound no gyro comes near
    for (key, v, max, unit) in [
        ("simulation.arw_deg_rt_h", s.arw_deg_rt_h, 100.0, "°/√h"),
        (
            "simulation.bias_instability_dph",
            s.bias_instability_dph,
            1000.0,
            "°/h",
        ),
        ("simulation.rrw_dph_rt_h", s.rrw_dph_rt_h, 1000.0, "°/h/√h"),
        (
            "simulation.quantization_arcsec",
            s.quantization_arcsec,
            3600.0,
            "arcsec",
        ),
        ("simulation.warmup_dph", s.warmup_dph, 36000.0, "°/h"),
    ] {
        let v = cx.finite(key, v)?;
        if !(0.0..=max).contains(&v) {
            return Err(cx.err(key, format!("must be from 0 to {max} {unit} (got {v})")));
        }
    }
    let tau = cx.finite("simulation.warmup_tau_s", s.warmup_tau_s)?;
    if !(tau > 0.0 && tau <= 86400.0) {
        return Err(cx.err(
            "simulation.warmup_tau_s",
            format!("must be > 0 and at most 86400 s (got {tau})"),
        ));
    }

    // [dut]: text, none of it empty (an empty section is no [dut])
    if let Some(d) = &dut {
        for (key, v) in d.fields() {
            if v.as_ref().is_some_and(|v| v.trim().is_empty()) {
                return Err(cx.err(
                    &format!("dut.{key}"),
                    "must not be empty: leave the key out when it is not known".into(),
                ));
            }
        }
    }
    let dut = dut.filter(|d| !d.is_empty());

    // [acceptance]
    if let Some(a) = &acceptance {
        validate_acceptance(a, cx)?;
    }

    // [drift]: a drift plan's only
    let drift = match drift {
        None => None,
        Some(_) if kind != PlanKind::Drift => {
            return Err(cx.err(
                "drift.table",
                "[drift] belongs to a drift plan: add kind = \"drift\" to [plan], or remove [drift]"
                    .into(),
            ));
        }
        Some(d) => {
            let d = validate_drift(&d, cx)?;
            if d.table == TableRole::ServoOff && dialect == TableDialect::Aerosmith {
                return Err(cx.err(
                    "drift.table",
                    "= \"servo_off\" needs a table whose servo gyrocal can switch off: the ACL dialect (`:Interlock:Open`); the aerosmith dialect knows no servo-off command (`STO` only stops): write \"hold\" or \"none\""
                        .into(),
                ));
            }
            Some(d)
        }
    };

    // [warmup]
    let warmup = match warmup {
        None => None,
        Some(w) => Some(validate_warmup(&w, cx)?),
    };

    Ok(Plan {
        drift,
        warmup,
        table_given,
        kind,
        name: p.name,
        rates_dps: rates,
        samples_per_rate,
        settle,
        repeat,
        whole_revolutions,
        table: TableSettings {
            dialect,
            port: table_port,
            baud: table_baud,
            max_rate_dps: max_rate,
            acceleration_dps2: acc,
            rate_tolerance_dps: tol,
            stability_window: window,
            at_rate_timeout: timeout,
        },
        dmm: DmmSettings {
            model,
            port: dmm_port,
            baud: dmm_baud,
            framing,
            range_v,
            nplc,
            autozero: m.autozero,
            line_hz,
            acquisition,
        },
        simulation: s,
        dut,
        acceptance,
    })
}

/// Every quantity's limits; an error names `[acceptance.QUANTITY] KEY`, at the value.
fn validate_acceptance(a: &AcceptanceSpec, cx: &Ctx<'_>) -> Result<(), PlanError> {
    a.validate().map_err(|(q, e)| {
        let path = match e.key {
            Some(key) => format!("acceptance.{}.{key}", q.name()),
            None => format!("acceptance.{}", q.name()),
        };
        cx.err(&path, e.message)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sample value of each kind, as TOML.
    fn sample(kind: Kind) -> &'static str {
        match kind {
            Kind::Number => "1.5",
            Kind::Int => "1",
            Kind::Text => "\"x\"",
            Kind::Bool => "true",
            Kind::Numbers => "[0, 1]",
            Kind::Limits => "{ min = 0, max = 1 }",
        }
    }

    /// The schema and the raw structs name the same sections and keys: every schema key is one
    /// serde accepts, and a file without a key the schema calls required is one serde refuses.
    #[test]
    fn schema_matches_the_raw_structs() {
        let doc = |skip: Option<(&str, &str)>| {
            let mut text = String::new();
            for &(section, _, keys) in SCHEMA {
                text.push_str(&format!("[{section}]\n"));
                for &(key, kind, _) in keys {
                    if skip != Some((section, key)) {
                        text.push_str(&format!("{key} = {}\n", sample(kind)));
                    }
                }
            }
            text
        };
        let full = doc(None);
        assert!(toml::from_str::<RawFile>(&full).is_ok(), "{full}");
        for &(section, _, keys) in SCHEMA {
            for &(key, _, required) in keys {
                let text = doc(Some((section, key)));
                assert_eq!(
                    toml::from_str::<RawFile>(&text).is_err(),
                    required,
                    "[{section}] {key}"
                );
            }
        }
    }

    #[test]
    fn acceptance_keys_are_the_quantities() {
        let names: Vec<&str> = ACCEPTANCE_KEYS
            .iter()
            .filter(|k| k.1 == Kind::Limits)
            .map(|k| k.0)
            .collect();
        assert_eq!(names, Quantity::ALL.map(Quantity::name));
        let raw: RawAcceptance = toml::from_str(
            &names
                .iter()
                .map(|n| format!("{n} = {{ max = 1 }}\n"))
                .collect::<String>(),
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let quantities: Vec<Quantity> = raw
            .into_limits()
            .into_iter()
            .filter(|(_, l)| l.is_some())
            .map(|(q, _)| q)
            .collect();
        assert_eq!(quantities, Quantity::ALL);
    }

    #[test]
    fn misspellings_find_their_key() {
        assert_eq!(
            closest("tabel", ["plan", "table", "dmm", "simulation"]),
            Some("table")
        );
        assert_eq!(
            closest("sim", ["plan", "table", "dmm", "simulation"]),
            Some("simulation")
        );
        assert_eq!(
            closest("rate_dps", ["rates_dps", "settle_s"]),
            Some("rates_dps")
        );
        assert_eq!(
            closest("colour", ["plan", "table", "dmm", "simulation"]),
            None
        );
        assert_eq!(edit_distance("tabel", "table"), 1);
        assert_eq!(edit_distance("", "dmm"), 3);
    }
}
