//! Acceptance limits and verdicts: does a calibrated gyro meet its specification?
//!
//! The model is OpenHTF's `InRange(min, max, marginal_min, marginal_max)` measurement, with
//! the decision rules of ISO/IEC 17025:2017 §7.8.6 (a statement of conformity names the
//! specification and the decision rule):
//!
//! - [`Rule::Simple`] (simple acceptance, the measured value alone): a value below `min` or
//!   above `max` fails; a value inside the limits but outside `[marginal_min, marginal_max]` is
//!   marginal; anything else passes. The limits themselves pass: `value == max` passes.
//! - [`Rule::Guarded`] (guarded acceptance, ILAC-G8): the interval `[value − U, value + U]`, with
//!   `U` the expanded uncertainty (k = 2), decides. It passes when the whole interval lies inside
//!   the limits (and inside the marginal band; inside the limits but not the band is marginal),
//!   fails when it lies wholly outside (`value − U > max` or `value + U < min`), and is
//!   indeterminate otherwise: the value is within `U` of a limit, so the measurement cannot
//!   tell. Without a known `U` the guarded rule cannot decide: indeterminate, with the reason.
//!
//! A quantity the analysis did not compute (the repeatability of a single pass, the asymmetry
//! without two rates on each side of zero) is indeterminate under either rule, with the reason
//! `not measured: ...`. The run's verdict is its worst check ([`Verdict`] is ordered by
//! severity: pass < marginal < indeterminate < fail).
//!
//! Pure and serialisable: [`AcceptanceSpec`] reads and writes the shape of a plan's
//! `[acceptance]` table (`decision_rule` and one table of limits per quantity), [`Acceptance`]
//! is the result a report prints and `fit.json`-like documents carry.

use std::collections::BTreeMap;
use std::fmt;

use crate::display;

use serde::de::{MapAccess, Visitor};
use serde::ser::SerializeMap;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

pub use crate::quantity::Quantity;

/// The limits of one quantity, in the quantity's unit. Every bound is optional (a one-sided
/// specification has only `min` or only `max`), at least one must be set, and those present
/// satisfy `min <= marginal_min <= marginal_max <= max` ([`Limits::validate`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Limits {
    /// Below this fails.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min: Option<f64>,
    /// Above this fails.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max: Option<f64>,
    /// Below this (but not below `min`) is marginal.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub marginal_min: Option<f64>,
    /// Above this (but not above `max`) is marginal.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub marginal_max: Option<f64>,
}

/// What is wrong with a [`Limits`]: the key at fault (`None` when none is set) and what is
/// wrong with it. Displays as `max = 0.04 must be >= min = 0.049 (...)`: the key, then the
/// message (which leaves the key out, so that a plan's error can name it in its own way).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{}{message}", key.map(|k| format!("{k} ")).unwrap_or_default())]
pub struct LimitsError {
    /// `min`, `max`, `marginal_min` or `marginal_max`; `None` when no bound is set.
    pub key: Option<&'static str>,
    /// What is wrong, without the key: `= 0.04 must be >= min = 0.049 (...)`,
    /// `must be a finite number (got NaN)`, `sets no limit: ...`.
    pub message: String,
}

impl Limits {
    /// The keys of a limits table, in order.
    pub const KEYS: [&'static str; 4] = ["min", "marginal_min", "marginal_max", "max"];

    /// The bounds as `(key, value)`, in the order they must ascend.
    fn ordered(&self) -> [(&'static str, Option<f64>); 4] {
        [
            ("min", self.min),
            ("marginal_min", self.marginal_min),
            ("marginal_max", self.marginal_max),
            ("max", self.max),
        ]
    }

    /// Checks that at least one bound is set, every bound is finite, and those present ascend:
    /// `min <= marginal_min <= marginal_max <= max`.
    pub fn validate(&self) -> Result<(), LimitsError> {
        let bounds = self.ordered();
        if bounds.iter().all(|(_, v)| v.is_none()) {
            return Err(LimitsError {
                key: None,
                message: "sets no limit: give min, max, or both (marginal_min and marginal_max \
                          are optional)"
                    .into(),
            });
        }
        for (key, v) in bounds {
            if let Some(v) = v
                && !v.is_finite()
            {
                return Err(LimitsError {
                    key: Some(key),
                    message: format!("must be a finite number (got {v})"),
                });
            }
        }
        const ASCEND: &str = "(the limits ascend: min <= marginal_min <= marginal_max <= max)";
        for (j, &(later, b)) in bounds.iter().enumerate() {
            let Some(b) = b else { continue };
            for &(earlier, a) in bounds.iter().take(j) {
                let Some(a) = a else { continue };
                if a <= b {
                    continue;
                }
                // The limits are the specification, the marginal band lies inside them: when
                // a band's end crosses a limit, the band's end is at fault.
                let blame_earlier = later == "max" && earlier.starts_with("marginal");
                return Err(if blame_earlier {
                    LimitsError {
                        key: Some(earlier),
                        message: format!("= {a} must be <= {later} = {b} {ASCEND}"),
                    }
                } else {
                    LimitsError {
                        key: Some(later),
                        message: format!("= {b} must be >= {earlier} = {a} {ASCEND}"),
                    }
                });
            }
        }
        Ok(())
    }
}

/// The decision rule of a statement of conformity (ISO/IEC 17025 §7.8.6).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Rule {
    /// Simple acceptance: the measured value against the limits.
    #[default]
    Simple,
    /// Guarded acceptance: the value ± its expanded uncertainty against the limits.
    Guarded,
}

impl Rule {
    /// `simple` or `guarded`, as in plan files and JSON.
    pub fn as_str(self) -> &'static str {
        match self {
            Rule::Simple => "simple",
            Rule::Guarded => "guarded",
        }
    }

    /// The rule named `name` (`simple` or `guarded`, ASCII case-insensitive).
    pub fn from_name(name: &str) -> Option<Rule> {
        [Rule::Simple, Rule::Guarded]
            .into_iter()
            .find(|r| r.as_str().eq_ignore_ascii_case(name.trim()))
    }

    /// What the rule means, for a report's statement of conformity.
    pub fn description(self) -> &'static str {
        match self {
            Rule::Simple => {
                "simple acceptance: a value inside the limits passes, outside fails; the \
                 measurement uncertainty is not taken into account"
            }
            Rule::Guarded => {
                "guarded acceptance (ILAC-G8): passes when the value ± its expanded uncertainty \
                 (k = 2) lies inside the limits, fails when it lies wholly outside, and is \
                 indeterminate otherwise"
            }
        }
    }
}

impl fmt::Display for Rule {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// The outcome of one check, or of a run (its worst check). Ordered by severity:
/// `Pass < Marginal < Indeterminate < Fail`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Verdict {
    /// Inside the limits (and the marginal band).
    Pass,
    /// Inside the limits, outside the marginal band.
    Marginal,
    /// Cannot be decided: not measured, or (guarded rule) within the uncertainty of a limit or
    /// the uncertainty unknown.
    Indeterminate,
    /// Outside the limits.
    Fail,
}

impl Verdict {
    /// `pass`, `marginal`, `indeterminate` or `fail`, as in JSON.
    pub fn as_str(self) -> &'static str {
        match self {
            Verdict::Pass => "pass",
            Verdict::Marginal => "marginal",
            Verdict::Indeterminate => "indeterminate",
            Verdict::Fail => "fail",
        }
    }

    /// `PASS`, `MARGINAL`, `INDETERMINATE` or `FAIL`, for reports (also [`fmt::Display`]).
    pub fn label(self) -> &'static str {
        match self {
            Verdict::Pass => "PASS",
            Verdict::Marginal => "MARGINAL",
            Verdict::Indeterminate => "INDETERMINATE",
            Verdict::Fail => "FAIL",
        }
    }
}

impl fmt::Display for Verdict {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.label())
    }
}

/// A specification: the decision rule and the limits of each quantity it constrains.
///
/// Serialises as the `[acceptance]` table of a plan: `decision_rule` (`simple` when absent on
/// reading) and one table of [`Limits`] per quantity, keyed by [`Quantity::name`]:
/// `{"decision_rule":"guarded","scale_factor":{"min":0.049,"max":0.051}}`. Reading refuses an
/// unknown key (naming the valid ones) and invalid limits ([`Limits::validate`]).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct AcceptanceSpec {
    /// The decision rule.
    pub rule: Rule,
    /// The limits, by quantity.
    pub limits: BTreeMap<Quantity, Limits>,
    /// A temperature series' limit on |K's sensitivity|, ppm/°C (`k_tempco_ppm_per_c_max`):
    /// judged by the series analysis (its sensitivities are not figures of one sweep).
    pub k_tempco_ppm_per_c_max: Option<f64>,
    /// A temperature series' limit on |the bias's sensitivity|, °/h/°C
    /// (`bias_tempco_dph_per_c_max`).
    pub bias_tempco_dph_per_c_max: Option<f64>,
}

/// The keys of the temperature series' limits in `[acceptance]` (plain numbers, not tables of
/// limits: a sensitivity is limited in magnitude).
pub const TEMPCO_KEYS: [&str; 2] = ["k_tempco_ppm_per_c_max", "bias_tempco_dph_per_c_max"];

impl AcceptanceSpec {
    /// Validates every quantity's limits; the error names the quantity.
    pub fn validate(&self) -> Result<(), (Quantity, LimitsError)> {
        for (q, l) in &self.limits {
            l.validate().map_err(|e| (*q, e))?;
        }
        Ok(())
    }
}

impl Serialize for AcceptanceSpec {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut map = s.serialize_map(None)?;
        map.serialize_entry("decision_rule", &self.rule)?;
        for (q, l) in &self.limits {
            map.serialize_entry(q.name(), l)?;
        }
        let tempco = [self.k_tempco_ppm_per_c_max, self.bias_tempco_dph_per_c_max];
        for (key, v) in TEMPCO_KEYS.iter().zip(tempco) {
            if let Some(v) = v {
                map.serialize_entry(key, &v)?;
            }
        }
        map.end()
    }
}

/// A series' limit as read: a positive number.
fn tempco_limit<E: serde::de::Error>(key: &str, v: f64) -> Result<f64, E> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(E::custom(format!(
            "[acceptance] {key} = {v} is not a positive number"
        )))
    }
}

impl<'de> Deserialize<'de> for AcceptanceSpec {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = AcceptanceSpec;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("an acceptance table: decision_rule and limits per quantity")
            }
            fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<AcceptanceSpec, A::Error> {
                use serde::de::Error as _;
                let mut spec = AcceptanceSpec::default();
                let mut rule_seen = false;
                while let Some(key) = map.next_key::<String>()? {
                    if key == "decision_rule" {
                        if rule_seen {
                            return Err(A::Error::duplicate_field("decision_rule"));
                        }
                        rule_seen = true;
                        spec.rule = map.next_value()?;
                    } else if key == TEMPCO_KEYS[0] {
                        spec.k_tempco_ppm_per_c_max = Some(tempco_limit(&key, map.next_value()?)?);
                    } else if key == TEMPCO_KEYS[1] {
                        spec.bias_tempco_dph_per_c_max =
                            Some(tempco_limit(&key, map.next_value()?)?);
                    } else if let Some(q) = Quantity::from_name(&key) {
                        let limits: Limits = map.next_value()?;
                        limits
                            .validate()
                            .map_err(|e| A::Error::custom(format!("[acceptance.{q}] {e}")))?;
                        if spec.limits.insert(q, limits).is_some() {
                            return Err(A::Error::custom(format!("duplicate quantity `{q}`")));
                        }
                    } else {
                        return Err(A::Error::custom(format!(
                            "unknown acceptance key `{key}`: the keys are decision_rule, the \
                             quantities {} and the series' {}",
                            Quantity::names(),
                            TEMPCO_KEYS.join(", ")
                        )));
                    }
                }
                Ok(spec)
            }
        }
        d.deserialize_map(V)
    }
}

/// A quantity as measured: its value and expanded uncertainty (k = 2), each when known.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Measured {
    /// The value, in the quantity's unit; `None` when not computed.
    pub value: Option<f64>,
    /// The expanded uncertainty `U` (k = 2), same unit; `None` when not known.
    pub expanded_uncertainty: Option<f64>,
    /// The coverage interval `[low, high]` (about 95 %) when it is not `value ± U` (a skewed
    /// distribution); the guarded rule then judges this interval.
    pub interval: Option<[f64; 2]>,
}

impl Measured {
    /// Not measured.
    pub const NONE: Measured = Measured {
        value: None,
        expanded_uncertainty: None,
        interval: None,
    };

    /// A value with its expanded uncertainty.
    pub fn new(value: f64, expanded_uncertainty: f64) -> Measured {
        Measured {
            value: Some(value),
            expanded_uncertainty: Some(expanded_uncertainty),
            interval: None,
        }
    }

    /// A value with a coverage interval that is not symmetric about it; its expanded
    /// uncertainty is the wider half.
    pub fn with_interval(value: f64, low: f64, high: f64) -> Measured {
        Measured {
            value: Some(value),
            expanded_uncertainty: Some((high - value).max(value - low)),
            interval: Some([low, high]),
        }
    }

    /// A value whose uncertainty is not known.
    pub fn value(value: f64) -> Measured {
        Measured {
            value: Some(value),
            expanded_uncertainty: None,
            interval: None,
        }
    }
}

/// One quantity checked against its limits.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Check {
    /// The quantity.
    pub quantity: Quantity,
    /// The measured value (`null`: not measured).
    pub value: Option<f64>,
    /// The unit of value, uncertainty and limits ([`Quantity::unit`]).
    pub unit: String,
    /// The expanded uncertainty (k = 2), when known.
    pub expanded_uncertainty: Option<f64>,
    /// The coverage interval judged by the guarded rule when it is not `value ± U`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub interval: Option<[f64; 2]>,
    /// Lower limit.
    pub min: Option<f64>,
    /// Upper limit.
    pub max: Option<f64>,
    /// Lower end of the marginal band.
    pub marginal_min: Option<f64>,
    /// Upper end of the marginal band.
    pub marginal_max: Option<f64>,
    /// The outcome.
    pub verdict: Verdict,
    /// Why the outcome is not a plain pass (which limit, not measured, ...).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    /// Which figure of the analysis was judged and where its U comes from
    /// ([`Quantity::figure`]). Absent in checks recorded before this field existed: their
    /// `asymmetry_ppm` judged the GJB two-line figure.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub figure: Option<String>,
}

/// The result of checking a run against a specification.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Acceptance {
    /// The worst verdict of the checks.
    pub verdict: Verdict,
    /// The decision rule applied.
    pub rule: Rule,
    /// One check per limited quantity, in [`Quantity::ALL`] order.
    pub checks: Vec<Check>,
}

impl Acceptance {
    /// The checks that make the verdict: those with the run's (worst) verdict, none when it
    /// passes.
    pub fn deciding(&self) -> impl Iterator<Item = &Check> {
        self.checks
            .iter()
            .filter(move |c| c.verdict == self.verdict && c.verdict != Verdict::Pass)
    }
}

/// Checks every quantity `spec` limits against `measured(quantity)`. `None` when the
/// specification limits nothing (no checks, no verdict).
pub fn evaluate(
    spec: &AcceptanceSpec,
    measured: impl Fn(Quantity) -> Measured,
) -> Option<Acceptance> {
    let checks: Vec<Check> = spec
        .limits
        .iter()
        .map(|(&q, limits)| check(spec.rule, q, limits, measured(q)))
        .collect();
    let verdict = checks.iter().map(|c| c.verdict).max()?;
    Some(Acceptance {
        verdict,
        rule: spec.rule,
        checks,
    })
}

/// One quantity against its limits under `rule`.
pub fn check(rule: Rule, quantity: Quantity, limits: &Limits, measured: Measured) -> Check {
    let (verdict, reason) = decide(rule, quantity, limits, measured);
    Check {
        quantity,
        value: measured.value,
        unit: quantity.unit().to_string(),
        expanded_uncertainty: measured.expanded_uncertainty,
        interval: measured.interval,
        min: limits.min,
        max: limits.max,
        marginal_min: limits.marginal_min,
        marginal_max: limits.marginal_max,
        verdict,
        reason,
        figure: Some(quantity.figure().to_string()),
    }
}

fn decide(rule: Rule, quantity: Quantity, l: &Limits, m: Measured) -> (Verdict, Option<String>) {
    let unit = quantity.unit();
    let Some(v) = m.value else {
        return (
            Verdict::Indeterminate,
            Some(format!("not measured: {}", quantity.missing_because())),
        );
    };
    if !v.is_finite() {
        return (
            Verdict::Indeterminate,
            Some(format!("not measured: the value is not finite ({v})")),
        );
    }
    // The value as a person reads it everywhere else: rounded by the one rule beside its U
    // (`931.3 ± 21 ppm`), never to another number of digits (crate::display).
    let vs = display::value_as_with_u(v, m.expanded_uncertainty);
    let lim = |x: f64| format!("{} {unit}", display::plain(x));
    match rule {
        Rule::Simple => {
            if let Some(min) = l.min
                && v < min
            {
                return (
                    Verdict::Fail,
                    Some(format!("{vs} {unit} is below min {}", lim(min))),
                );
            }
            if let Some(max) = l.max
                && v > max
            {
                return (
                    Verdict::Fail,
                    Some(format!("{vs} {unit} is above max {}", lim(max))),
                );
            }
            if let Some(mmin) = l.marginal_min
                && v < mmin
            {
                return (
                    Verdict::Marginal,
                    Some(format!("{vs} {unit} is below marginal_min {}", lim(mmin))),
                );
            }
            if let Some(mmax) = l.marginal_max
                && v > mmax
            {
                return (
                    Verdict::Marginal,
                    Some(format!("{vs} {unit} is above marginal_max {}", lim(mmax))),
                );
            }
            (Verdict::Pass, None)
        }
        Rule::Guarded => {
            if let Some([lo, hi]) = m.interval {
                if lo.is_finite() && hi.is_finite() && lo <= v && v <= hi {
                    let interval = format!(
                        "{vs} {unit} (95 % interval {} .. {})",
                        display::significant(lo, 3),
                        display::significant(hi, 3)
                    );
                    return guarded(l, lo, hi, &interval, unit);
                }
                return (
                    Verdict::Indeterminate,
                    Some(format!(
                        "the guarded rule needs a finite coverage interval about the value \
                         (got {lo} .. {hi})"
                    )),
                );
            }
            let u = match m.expanded_uncertainty {
                Some(u) if u.is_finite() && u >= 0.0 => u,
                Some(u) => {
                    return (
                        Verdict::Indeterminate,
                        Some(format!(
                            "the guarded rule needs a finite, non-negative expanded \
                             uncertainty (got {u})"
                        )),
                    );
                }
                None => {
                    return (
                        Verdict::Indeterminate,
                        Some(format!(
                            "the guarded rule needs the expanded uncertainty of {quantity}, \
                             which is not known"
                        )),
                    );
                }
            };
            let interval = display::value_pm_u(v, Some(u), unit);
            guarded(l, v - u, v + u, &interval, unit)
        }
    }
}

/// The guarded rule on the interval `[lo, hi]` (`interval` in words, for the reasons).
fn guarded(l: &Limits, lo: f64, hi: f64, interval: &str, unit: &str) -> (Verdict, Option<String>) {
    let lim = |x: f64| format!("{} {unit}", display::plain(x));
    if let Some(max) = l.max
        && lo > max
    {
        return (
            Verdict::Fail,
            Some(format!("{interval} lies wholly above max {}", lim(max))),
        );
    }
    if let Some(min) = l.min
        && hi < min
    {
        return (
            Verdict::Fail,
            Some(format!("{interval} lies wholly below min {}", lim(min))),
        );
    }
    if let Some(min) = l.min
        && lo < min
    {
        return (
            Verdict::Indeterminate,
            Some(format!(
                "{interval} straddles min {}: within the uncertainty of the limit",
                lim(min)
            )),
        );
    }
    if let Some(max) = l.max
        && hi > max
    {
        return (
            Verdict::Indeterminate,
            Some(format!(
                "{interval} straddles max {}: within the uncertainty of the limit",
                lim(max)
            )),
        );
    }
    if let Some(mmin) = l.marginal_min
        && lo < mmin
    {
        return (
            Verdict::Marginal,
            Some(format!(
                "{interval} reaches below marginal_min {}",
                lim(mmin)
            )),
        );
    }
    if let Some(mmax) = l.marginal_max
        && hi > mmax
    {
        return (
            Verdict::Marginal,
            Some(format!(
                "{interval} reaches above marginal_max {}",
                lim(mmax)
            )),
        );
    }
    (Verdict::Pass, None)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;

    fn limits(min: f64, max: f64) -> Limits {
        Limits {
            min: Some(min),
            max: Some(max),
            ..Limits::default()
        }
    }

    fn banded() -> Limits {
        Limits {
            min: Some(0.049),
            max: Some(0.051),
            marginal_min: Some(0.0495),
            marginal_max: Some(0.0505),
        }
    }

    fn simple(l: &Limits, v: f64) -> Verdict {
        check(Rule::Simple, Quantity::ScaleFactor, l, Measured::value(v)).verdict
    }

    fn guarded(l: &Limits, v: f64, u: f64) -> Check {
        check(Rule::Guarded, Quantity::ScaleFactor, l, Measured::new(v, u))
    }

    #[test]
    fn names_units_and_serde_agree() {
        for q in Quantity::ALL {
            assert_eq!(Quantity::from_name(q.name()), Some(q));
            let json = serde_json::to_string(&q).unwrap();
            assert_eq!(json, format!("\"{}\"", q.name()));
            assert!(!q.unit().is_empty());
        }
        assert_eq!(Quantity::from_name("scale"), None);
        assert_eq!(Quantity::ScaleFactor.unit(), "V/(°/s)");
        assert_eq!(Quantity::BiasDph.unit(), "°/h");
        assert_eq!(Quantity::K2.unit(), "V/(°/s)²");
    }

    #[test]
    fn verdicts_are_ordered_by_severity() {
        assert!(Verdict::Pass < Verdict::Marginal);
        assert!(Verdict::Marginal < Verdict::Indeterminate);
        assert!(Verdict::Indeterminate < Verdict::Fail);
        assert_eq!(serde_json::to_string(&Verdict::Fail).unwrap(), "\"fail\"");
        assert_eq!(Verdict::Marginal.to_string(), "MARGINAL");
        assert_eq!(Verdict::Indeterminate.as_str(), "indeterminate");
    }

    #[test]
    fn limits_validate() {
        assert!(banded().validate().is_ok());
        assert!(limits(1.0, 1.0).validate().is_ok());
        assert!(
            Limits {
                max: Some(5.0),
                ..Limits::default()
            }
            .validate()
            .is_ok()
        );
        let none = Limits::default().validate().unwrap_err();
        assert_eq!(none.key, None);
        assert!(none.message.contains("no limit"), "{}", none.message);
        let e = limits(2.0, 1.0).validate().unwrap_err();
        assert_eq!(e.key, Some("max"));
        assert!(
            e.to_string().starts_with("max = 1 must be >= min = 2"),
            "{}",
            e.message
        );
        let e = Limits {
            marginal_min: Some(0.048),
            ..banded()
        }
        .validate()
        .unwrap_err();
        assert_eq!(e.key, Some("marginal_min"));
        let e = Limits {
            marginal_max: Some(0.0494),
            ..banded()
        }
        .validate()
        .unwrap_err();
        assert_eq!(e.key, Some("marginal_max"));
        let e = Limits {
            min: Some(f64::NAN),
            ..Limits::default()
        }
        .validate()
        .unwrap_err();
        assert_eq!(e.key, Some("min"));
        assert_eq!(e.to_string(), "min must be a finite number (got NaN)");
    }

    #[test]
    fn simple_rule() {
        let l = banded();
        assert_eq!(simple(&l, 0.05), Verdict::Pass);
        // the limits themselves pass, the band's ends are not marginal
        assert_eq!(simple(&l, 0.051), Verdict::Marginal);
        assert_eq!(simple(&limits(0.049, 0.051), 0.051), Verdict::Pass);
        assert_eq!(simple(&limits(0.049, 0.051), 0.049), Verdict::Pass);
        assert_eq!(simple(&l, 0.0505), Verdict::Pass);
        assert_eq!(simple(&l, 0.0495), Verdict::Pass);
        assert_eq!(simple(&l, 0.0506), Verdict::Marginal);
        assert_eq!(simple(&l, 0.0494), Verdict::Marginal);
        assert_eq!(simple(&l, 0.0511), Verdict::Fail);
        assert_eq!(simple(&l, 0.0489), Verdict::Fail);
        let c = check(
            Rule::Simple,
            Quantity::ScaleFactor,
            &l,
            Measured::value(0.06),
        );
        assert!(c.reason.unwrap().contains("above max 0.051"));
        // one-sided
        let max_only = Limits {
            max: Some(100.0),
            ..Limits::default()
        };
        assert_eq!(simple(&max_only, -1e9), Verdict::Pass);
        assert_eq!(simple(&max_only, 100.0), Verdict::Pass);
        assert_eq!(simple(&max_only, 100.1), Verdict::Fail);
        // the uncertainty does not matter under the simple rule
        let c = check(
            Rule::Simple,
            Quantity::ScaleFactor,
            &l,
            Measured::new(0.051, 1.0),
        );
        assert_eq!(c.verdict, Verdict::Marginal);
    }

    #[test]
    fn guarded_rule() {
        // binary-exact numbers, so "touching a limit" is exact
        let l = limits(-4.0, 4.0);
        assert_eq!(guarded(&l, 0.0, 1.0).verdict, Verdict::Pass);
        // the interval touching a limit is inside
        assert_eq!(guarded(&l, 3.0, 1.0).verdict, Verdict::Pass);
        assert_eq!(guarded(&l, -3.0, 1.0).verdict, Verdict::Pass);
        // within U of a limit: indeterminate, on either side of it
        let c = guarded(&l, 3.5, 1.0);
        assert_eq!(c.verdict, Verdict::Indeterminate);
        assert!(c.reason.unwrap().contains("straddles max"));
        assert_eq!(guarded(&l, 4.5, 1.0).verdict, Verdict::Indeterminate);
        assert_eq!(guarded(&l, -3.5, 1.0).verdict, Verdict::Indeterminate);
        assert_eq!(guarded(&l, -4.5, 1.0).verdict, Verdict::Indeterminate);
        // value - U exactly at max (value + U at min): not wholly outside
        assert_eq!(guarded(&l, 5.0, 1.0).verdict, Verdict::Indeterminate);
        assert_eq!(guarded(&l, -5.0, 1.0).verdict, Verdict::Indeterminate);
        // wholly outside
        let c = guarded(&l, 5.5, 1.0);
        assert_eq!(c.verdict, Verdict::Fail);
        assert!(c.reason.unwrap().contains("wholly above max"));
        let c = guarded(&l, -5.5, 1.0);
        assert_eq!(c.verdict, Verdict::Fail);
        assert!(c.reason.unwrap().contains("wholly below min"));
        // marginal band: inside the limits but not the band
        let b = Limits {
            marginal_min: Some(-2.0),
            marginal_max: Some(2.0),
            ..l
        };
        assert_eq!(guarded(&b, 0.0, 1.0).verdict, Verdict::Pass);
        assert_eq!(guarded(&b, 1.0, 1.0).verdict, Verdict::Pass);
        assert_eq!(guarded(&b, 1.5, 1.0).verdict, Verdict::Marginal);
        assert_eq!(guarded(&b, -1.5, 1.0).verdict, Verdict::Marginal);
        assert_eq!(guarded(&b, 3.5, 1.0).verdict, Verdict::Indeterminate);
        // U unknown
        let c = check(
            Rule::Guarded,
            Quantity::ScaleFactor,
            &l,
            Measured::value(0.0),
        );
        assert_eq!(c.verdict, Verdict::Indeterminate);
        assert!(c.reason.unwrap().contains("expanded uncertainty"));
        assert_eq!(guarded(&l, 0.0, f64::NAN).verdict, Verdict::Indeterminate);
        assert_eq!(guarded(&l, 0.0, -1.0).verdict, Verdict::Indeterminate);
        // U = 0 is the simple rule
        assert_eq!(guarded(&l, 4.0, 0.0).verdict, Verdict::Pass);
        assert_eq!(guarded(&l, 4.25, 0.0).verdict, Verdict::Fail);
        // a realistic scale factor within U of its limit
        let k = limits(0.049, 0.051);
        assert_eq!(guarded(&k, 0.05, 0.0005).verdict, Verdict::Pass);
        assert_eq!(guarded(&k, 0.0508, 0.0005).verdict, Verdict::Indeterminate);
        assert_eq!(guarded(&k, 0.0516, 0.0005).verdict, Verdict::Fail);
    }

    #[test]
    fn not_measured_is_indeterminate() {
        for rule in [Rule::Simple, Rule::Guarded] {
            let c = check(
                rule,
                Quantity::RepeatabilityPpm,
                &limits(0.0, 50.0),
                Measured::NONE,
            );
            assert_eq!(c.verdict, Verdict::Indeterminate);
            assert!(c.reason.unwrap().starts_with("not measured: "));
            let c = check(
                rule,
                Quantity::K2,
                &limits(0.0, 1.0),
                Measured::value(f64::NAN),
            );
            assert_eq!(c.verdict, Verdict::Indeterminate);
        }
    }

    #[test]
    fn the_run_gets_its_worst_check() {
        let mut spec = AcceptanceSpec {
            rule: Rule::Guarded,
            k_tempco_ppm_per_c_max: None,
            bias_tempco_dph_per_c_max: None,
            limits: BTreeMap::new(),
        };
        assert_eq!(evaluate(&spec, |_| Measured::NONE), None);
        spec.limits.insert(Quantity::ScaleFactor, banded());
        spec.limits.insert(Quantity::BiasV, limits(-0.02, 0.02));
        spec.limits
            .insert(Quantity::RepeatabilityPpm, limits(0.0, 100.0));
        let a = evaluate(&spec, |q| match q {
            Quantity::ScaleFactor => Measured::new(0.05, 0.0001),
            Quantity::BiasV => Measured::new(0.0, 0.001),
            _ => Measured::NONE,
        })
        .unwrap();
        assert_eq!(a.verdict, Verdict::Indeterminate);
        assert_eq!(a.checks.len(), 3);
        assert_eq!(a.checks[0].quantity, Quantity::ScaleFactor);
        assert_eq!(a.checks[0].verdict, Verdict::Pass);
        let a = evaluate(&spec, |q| match q {
            Quantity::BiasV => Measured::new(0.5, 0.001),
            _ => Measured::new(0.05, 0.0),
        })
        .unwrap();
        assert_eq!(a.verdict, Verdict::Fail);
    }

    #[test]
    fn acceptance_json_shape() {
        let spec = AcceptanceSpec {
            rule: Rule::Guarded,
            k_tempco_ppm_per_c_max: None,
            bias_tempco_dph_per_c_max: None,
            limits: [(Quantity::ScaleFactor, banded())].into_iter().collect(),
        };
        let a = evaluate(&spec, |_| Measured::new(0.06, 0.001)).unwrap();
        let json = serde_json::to_string(&a).unwrap();
        assert_eq!(
            json,
            "{\"verdict\":\"fail\",\"rule\":\"guarded\",\"checks\":[{\"quantity\":\"scale_factor\",\
             \"value\":0.06,\"unit\":\"V/(°/s)\",\"expanded_uncertainty\":0.001,\"min\":0.049,\
             \"max\":0.051,\"marginal_min\":0.0495,\"marginal_max\":0.0505,\"verdict\":\"fail\",\
             \"reason\":\"0.06000 ± 0.0010 V/(°/s) lies wholly above max 0.051 V/(°/s)\",\
             \"figure\":\"metrics.scale_factor: K of the least-squares line; U from the \
             uncertainty budget\"}]}"
        );
        let back: Acceptance = serde_json::from_str(&json).unwrap();
        assert_eq!(back, a);
        // a check recorded before `figure` existed still reads (its figure unknown)
        let old = json.replace(
            ",\"figure\":\"metrics.scale_factor: K of the least-squares line; U from the \
             uncertainty budget\"",
            "",
        );
        let back: Acceptance = serde_json::from_str(&old).unwrap();
        assert_eq!(back.checks[0].figure, None);
        let pass = evaluate(&spec, |_| Measured::new(0.05, 0.0)).unwrap();
        let json = serde_json::to_string(&pass).unwrap();
        assert!(!json.contains("reason"), "{json}");
    }

    #[test]
    fn spec_serde_is_the_acceptance_table() {
        let spec = AcceptanceSpec {
            rule: Rule::Guarded,
            k_tempco_ppm_per_c_max: None,
            bias_tempco_dph_per_c_max: None,
            limits: [
                (Quantity::ScaleFactor, banded()),
                (
                    Quantity::NonlinearityPpm,
                    Limits {
                        max: Some(200.0),
                        ..Limits::default()
                    },
                ),
            ]
            .into_iter()
            .collect(),
        };
        let json = serde_json::to_string(&spec).unwrap();
        assert_eq!(
            json,
            "{\"decision_rule\":\"guarded\",\"scale_factor\":{\"min\":0.049,\"max\":0.051,\
             \"marginal_min\":0.0495,\"marginal_max\":0.0505},\"nonlinearity_ppm\":{\"max\":200.0}}"
        );
        let back: AcceptanceSpec = serde_json::from_str(&json).unwrap();
        assert_eq!(back, spec);
        let default_rule: AcceptanceSpec = serde_json::from_str("{\"k2\":{\"max\":1e-4}}").unwrap();
        assert_eq!(default_rule.rule, Rule::Simple);
        let e = serde_json::from_str::<AcceptanceSpec>("{\"scale\":{\"max\":1}}").unwrap_err();
        assert!(e.to_string().contains("scale_factor, bias_v"), "{e}");
        let e =
            serde_json::from_str::<AcceptanceSpec>("{\"k2\":{\"min\":2,\"max\":1}}").unwrap_err();
        assert!(e.to_string().contains("max = 1 must be >= min = 2"), "{e}");
        let e = serde_json::from_str::<AcceptanceSpec>("{\"k2\":{\"mx\":1}}").unwrap_err();
        assert!(e.to_string().contains("mx"), "{e}");
    }
}
