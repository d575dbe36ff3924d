//! The file's shape, checked before serde so errors name the right place in words: the
//! sections and their keys ([`schema`], assembled from each section's own module, where the
//! key's raw field, default and checks live beside its entry), what kind of value each key
//! holds, and the findings (unknown section or key with a did-you-mean, a missing key, a
//! value of the wrong kind) reported before the values are validated.

use toml::de::{DeTable, DeValue};

use gyrocal_fit::acceptance::{Limits, Quantity};

use super::error::{Location, PlanError};
use super::words::{and_list, closest, or_list};
use super::{acceptance, dmm, dut, section, simulation, table, warmup};

/// One key of a section: its name, the kind of value it holds, and whether it is required.
pub(super) type KeySchema = (&'static str, Kind, bool);

/// A section of the file: its name, whether it is required, and its keys. Kept in step with
/// the `Raw*` structs by a unit test.
pub(super) type SectionSchema = (&'static str, bool, &'static [KeySchema]);

/// The common sections before the test kinds' own ones, in the order the file documents them.
const COMMON: &[SectionSchema] = &[
    ("plan", true, section::KEYS),
    ("table", true, table::KEYS),
    ("dmm", true, dmm::KEYS),
    ("simulation", false, simulation::KEYS),
    ("dut", false, dut::KEYS),
    ("acceptance", false, acceptance::KEYS),
];

/// The common sections after the test kinds' own ones.
const LAST: &[SectionSchema] = &[("warmup", false, warmup::KEYS)];

/// Every section, in the order the file documents them: the common ones, with the test
/// kinds' own sections ([`super::kind::SECTIONS`], written by each kind's module) between
/// `[acceptance]` and `[warmup]`.
pub(super) fn schema() -> impl Iterator<Item = &'static SectionSchema> + Clone {
    COMMON.iter().chain(super::kind::SECTIONS).chain(LAST)
}

/// What a key holds, in the words an operator reads in an error message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Kind {
    /// A number (integer or float).
    Number,
    /// A whole number, and the values it allows (written with the key, in its section's
    /// module).
    Int(IntRule),
    /// Text in quotes.
    Text,
    /// `true` or `false`.
    Bool,
    /// A list of numbers.
    Numbers,
    /// A table of acceptance limits (`min`, `max`, `marginal_min`, `marginal_max`, numbers).
    Limits,
    /// A list of inline tables (`[chamber] alarm_registers`); their keys are checked by
    /// serde (unknown keys refused, with their place).
    Tables,
}

/// An example line for a required key, for "add ..." hints.
fn example(section: &str, key: &str) -> &'static str {
    match (section, key) {
        ("plan", "rates_dps") => "rates_dps = [0, 5, -5]",
        ("plan", "samples_per_rate") => "samples_per_rate = 500",
        ("table", "port") => "port = \"/dev/ttyUSB1\"",
        ("dmm", "port") => "port = \"/dev/ttyUSB0\"",
        ("table", "max_rate_dps") => "max_rate_dps = 20",
        ("table", "acceleration_dps2") => "acceleration_dps2 = 10",
        ("series", "temperatures_c") => "temperatures_c = [25, -20, 60, 25]",
        ("chamber", "model") => "model = \"watlow_f4\"",
        ("chamber", "port") => "port = \"/dev/ttyUSB2\"",
        _ => "",
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

/// The values an integer key allows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum IntRule {
    /// `lo..=hi`.
    Range(u64, u64),
    /// One of these.
    OneOf(&'static [u32]),
}

impl IntRule {
    /// Any whole number from 0 that fits a signed 64-bit integer (`simulation.seed`).
    pub(super) const NON_NEGATIVE: IntRule = IntRule::Range(0, i64::MAX.unsigned_abs());
}

/// The values the integer key `section.key` allows: its schema entry's.
pub(super) fn int_rule(key: &str) -> IntRule {
    let (section, name) = key.split_once('.').unwrap_or(("", key));
    schema()
        .filter(|s| s.0 == section)
        .flat_map(|s| s.2.iter())
        .find_map(|&(k, kind, _)| match kind {
            Kind::Int(rule) if k == name => Some(rule),
            _ => None,
        })
        .unwrap_or(IntRule::NON_NEGATIVE)
}

/// The message for an integer key whose value (`shown`, as written) is not allowed: the
/// allowed values in words and what to write.
pub(super) fn int_error(key: &str, shown: &str, whole: bool) -> String {
    let words = int_words(key);
    if !whole {
        return format!("= {shown} is not a whole number: write {words}");
    }
    match int_rule(key) {
        IntRule::Range(..) => format!("= {shown} is out of range: write {words}"),
        IntRule::OneOf(_) => format!("= {shown} is not allowed: write {words}"),
    }
}

/// What an integer key allows, in words: `a whole number from 1 to 1000000`, `one of 50 or 60`.
pub(super) fn int_words(key: &str) -> String {
    match int_rule(key) {
        IntRule::Range(lo, hi) => format!("a whole number from {lo} to {hi}"),
        IntRule::OneOf(allowed) => format!("one of {}", or_list(allowed)),
    }
}

/// A stage-1 finding: where (byte offset, when known), section, key, message.
pub(super) struct Finding {
    /// 0: a wrong key or value; 1: a missing key; 2: a missing section (reported in this order).
    pub(super) rank: u8,
    pub(super) offset: Option<usize>,
    pub(super) section: Option<String>,
    pub(super) key: Option<String>,
    pub(super) message: String,
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
        Kind::Int(_) if v.is_integer() => None,
        Kind::Int(_) => {
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
        Kind::Tables
            if v.as_array()
                .is_some_and(|a| a.iter().all(|t| t.get_ref().is_table())) =>
        {
            None
        }
        Kind::Tables => Some(format!(
            "= {shown} is not a list of tables: write e.g. {key} = [{{ register = 1061, name = \"door open\" }}]"
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
pub(super) fn check_keys(
    sname: &str,
    keys: &[KeySchema],
    table: &DeTable<'_>,
    header: Option<usize>,
    out: &mut Vec<Finding>,
) {
    for (key, v) in table.iter() {
        let key_str: &str = key.get_ref().as_ref();
        let Some(&(kname, kind, _)) = keys.iter().find(|k| k.0 == key_str) else {
            let elsewhere: Vec<String> = schema()
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

/// Checks the file's sections, keys and value kinds against [`schema`]; returns every finding.
pub(super) fn check_shape(root: &DeTable<'_>) -> Vec<Finding> {
    let mut out = Vec::new();
    let section_names = || schema().map(|s| s.0);
    for (name, value) in root.iter() {
        let name_str: &str = name.get_ref().as_ref();
        let Some((sname, _, keys)) = schema().find(|s| s.0 == name_str) else {
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
    // a plan whose kind needs no table (a drift record with `[drift] table = "none"`) may
    // leave [table] out
    let no_table = super::kind::table_optional_in(root);
    for &(sname, required, keys) in schema() {
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
pub(super) fn plain_words(message: &str) -> String {
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

/// A stage-1 finding as the error it reports.
pub(super) fn finding_error(f: Finding, location: impl Fn(Option<usize>) -> Location) -> PlanError {
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

#[cfg(test)]
mod tests {
    use super::super::raw::RawFile;
    use super::*;

    /// A sample value of each kind, as TOML.
    fn sample(kind: Kind) -> &'static str {
        match kind {
            Kind::Number => "1.5",
            Kind::Int(_) => "1",
            Kind::Text => "\"x\"",
            Kind::Bool => "true",
            Kind::Numbers => "[0, 1]",
            Kind::Limits => "{ min = 0, max = 1 }",
            Kind::Tables => "[{ register = 1, name = \"x\" }]",
        }
    }

    /// The schema and the raw structs name the same sections and keys: every schema key is one
    /// serde accepts, and a file without a key the schema calls required is one serde refuses.
    #[test]
    fn schema_matches_the_raw_structs() {
        let doc = |skip: Option<(&str, &str)>| {
            let mut text = String::new();
            for &(section, _, keys) in schema() {
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
        // the common sections are RawFile's; the kinds' own are read by their modules
        let parse = |text: &str| {
            toml::from_str::<RawFile>(text).and_then(|_| {
                super::super::kind::raw_sections(text, &mut super::super::raw::Spans::default())
            })
        };
        assert!(parse(&full).is_ok(), "{full}");
        for &(section, _, keys) in schema() {
            for &(key, _, required) in keys {
                let text = doc(Some((section, key)));
                assert_eq!(parse(&text).is_err(), required, "[{section}] {key}");
            }
        }
    }

    /// An integer key's allowed values are read from its own schema entry.
    #[test]
    fn integer_rules_come_from_the_keys_own_entries() {
        assert_eq!(int_rule("plan.repeat"), IntRule::Range(1, 1000));
        assert_eq!(
            int_rule("plan.samples_per_rate"),
            IntRule::Range(1, 1_000_000)
        );
        assert_eq!(int_rule("dmm.line_hz"), IntRule::OneOf(&[50, 60]));
        assert_eq!(int_rule("table.baud"), int_rule("dmm.baud"));
        assert_eq!(int_rule("simulation.seed"), IntRule::NON_NEGATIVE);
        assert_eq!(
            int_error("plan.repeat", "0", true),
            "= 0 is out of range: write a whole number from 1 to 1000"
        );
    }
}
