//! `[acceptance]` (the specification and its decision rule) of a plan, and standalone
//! acceptance files (`gyrocal report RUN --acceptance FILE`) whose top level is what the
//! section holds. Not part of the hash: limits can be re-evaluated after the run.
//!
//! [`load_acceptance`] reads a standalone file: `decision_rule` and one table of limits per
//! quantity ([`gyrocal_fit::acceptance::Quantity`]); its errors name keys as a plan's would.

use std::collections::BTreeMap;
use std::path::Path;

use serde::Deserialize;
use toml::de::DeTable;

use gyrocal_fit::acceptance::{AcceptanceSpec, Limits, Quantity, Rule};

use super::error::{ACCEPTANCE_DOCUMENT, Location, PlanError};
use super::raw::{S, Spans};
use super::schema::{KeySchema, Kind, check_keys, finding_error, plain_words};
use super::source::{read_document, section_at};
use super::validate::Ctx;

/// The keys of `[acceptance]` (and of a standalone acceptance file): the decision rule and a
/// table of limits per [`Quantity`] (a unit test keeps them in step with [`Quantity::ALL`]).
pub(super) const KEYS: &[KeySchema] = &[
    ("decision_rule", Kind::Text, false),
    ("scale_factor", Kind::Limits, false),
    ("bias_v", Kind::Limits, false),
    ("bias_dph", Kind::Limits, false),
    ("nonlinearity_ppm", Kind::Limits, false),
    ("asymmetry_ppm", Kind::Limits, false),
    ("asymmetry_gjb_ppm", Kind::Limits, false),
    ("repeatability_ppm", Kind::Limits, false),
    ("k2", Kind::Limits, false),
    // a temperature series' limits on its sensitivities (magnitudes), judged by its analysis
    ("k_tempco_ppm_per_c_max", Kind::Number, false),
    ("bias_tempco_dph_per_c_max", Kind::Number, false),
];

/// `[acceptance]` of a plan, or the whole of a standalone acceptance file. One field per
/// [`Quantity`] (a unit test keeps them in step with [`Quantity::ALL`]).
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawAcceptance {
    pub(super) decision_rule: Option<S<String>>,
    pub(super) scale_factor: Option<S<RawLimits>>,
    pub(super) bias_v: Option<S<RawLimits>>,
    pub(super) bias_dph: Option<S<RawLimits>>,
    pub(super) nonlinearity_ppm: Option<S<RawLimits>>,
    pub(super) asymmetry_ppm: Option<S<RawLimits>>,
    pub(super) asymmetry_gjb_ppm: Option<S<RawLimits>>,
    pub(super) repeatability_ppm: Option<S<RawLimits>>,
    pub(super) k2: Option<S<RawLimits>>,
    pub(super) k_tempco_ppm_per_c_max: Option<S<f64>>,
    pub(super) bias_tempco_dph_per_c_max: Option<S<f64>>,
}

impl RawAcceptance {
    /// The limits tables, by quantity.
    pub(super) fn into_limits(self) -> [(Quantity, Option<S<RawLimits>>); 8] {
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
pub(super) struct RawLimits {
    pub(super) min: Option<S<f64>>,
    pub(super) max: Option<S<f64>>,
    pub(super) marginal_min: Option<S<f64>>,
    pub(super) marginal_max: Option<S<f64>>,
}

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
/// max ...`). A file larger than [`MAX_PLAN_BYTES`](super::MAX_PLAN_BYTES) is refused after reading at most that much.
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
    check_keys("acceptance", KEYS, root.get_ref(), None, &mut findings);
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
    validate(&spec, &cx)?;
    Ok(spec)
}

/// `[acceptance]` (or a standalone acceptance file) with its spans kept under
/// `acceptance.QUANTITY.KEY`; the decision rule is checked here, the limits by validation.
pub(super) fn raw_acceptance(
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
    let mut tempco =
        |key: &'static str, v: Option<S<f64>>| -> Result<Option<f64>, (&'static str, String)> {
            let Some(v) = v else { return Ok(None) };
            let v = sp.take(key, v);
            if v.is_finite() && v > 0.0 {
                Ok(Some(v))
            } else {
                Err((
                    key,
                    format!("= {v} is not a positive number (a limit on a magnitude)"),
                ))
            }
        };
    let k_tempco_ppm_per_c_max = tempco(
        "acceptance.k_tempco_ppm_per_c_max",
        a.k_tempco_ppm_per_c_max.take(),
    )?;
    let bias_tempco_dph_per_c_max = tempco(
        "acceptance.bias_tempco_dph_per_c_max",
        a.bias_tempco_dph_per_c_max.take(),
    )?;
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
    Ok(AcceptanceSpec {
        rule,
        limits,
        k_tempco_ppm_per_c_max,
        bias_tempco_dph_per_c_max,
    })
}

/// Every quantity's limits; an error names `[acceptance.QUANTITY] KEY`, at the value.
pub(super) fn validate(a: &AcceptanceSpec, cx: &Ctx<'_>) -> Result<(), PlanError> {
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

    #[test]
    fn the_series_limits_are_read_and_a_non_positive_one_is_refused_naming_its_key() {
        let spec = acceptance_from_toml_str(
            "decision_rule = \"guarded\"\nk_tempco_ppm_per_c_max = 50\nbias_tempco_dph_per_c_max = 0.2\n",
            Path::new("acc.toml"),
        )
        .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(spec.k_tempco_ppm_per_c_max, Some(50.0));
        assert_eq!(spec.bias_tempco_dph_per_c_max, Some(0.2));
        // the manifest keeps them: serde round trip
        let json = serde_json::to_string(&spec).unwrap_or_default();
        let back: AcceptanceSpec = serde_json::from_str(&json).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(back, spec);
        let e = acceptance_from_toml_str("k_tempco_ppm_per_c_max = -1\n", Path::new("acc.toml"))
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(
            e.contains("k_tempco_ppm_per_c_max") && e.contains("positive"),
            "{e}"
        );
    }

    #[test]
    fn acceptance_keys_are_the_quantities() {
        let names: Vec<&str> = KEYS
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
}
