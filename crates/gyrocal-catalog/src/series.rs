//! A temperature series as the catalog keeps it: the `catalog` member of a run's
//! `series.json` ([`SeriesRecord`], one per run, and its [`SeriesPointRecord`]s, one per
//! temperature), read typed from the run directory.
//!
//! Why a member of its own: `series.json` holds the whole analysis (the points with their
//! budgets, the models in T with their coefficients, the verdict), whose shape may grow with
//! the analysis; the catalog needs a small, stable part of it to follow a gyro's temperature
//! sensitivities over the years. The analysis crate writes exactly this shape under
//! `"catalog"` (its own structs, so neither crate's internals bind the other); the field
//! names here are the contract's, and a member that does not have this shape is refused with
//! the file and serde's words (a file from another program is untrusted).
//!
//! Units: K in `fit.json`'s unit (V/(°/s)), the bias in °/h (K0/K · 3600), temperatures in °C,
//! the sensitivities over the series' range (ppm/°C and °/h/°C; for a quadratic model, the
//! slope at the range's mid-temperature), hysteresis between the visits of a revisited
//! temperature (`null` when no temperature is revisited). Every `u_` is an expanded
//! uncertainty at k = 2.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::CatalogError;

/// The analysis file of a temperature series in its run directory.
pub const SERIES_JSON: &str = "series.json";

/// The member of [`SERIES_JSON`] the catalog reads.
pub const CATALOG_MEMBER: &str = "catalog";

/// One temperature of a series (a row of `series_points`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SeriesPointRecord {
    /// 0-based index into the plan's `temperatures_c` (a revisited temperature has its own).
    pub series_point: i64,
    /// The chamber's setpoint, °C.
    pub setpoint_c: f64,
    /// The gyro's lowest temperature during the point's measurement, °C.
    pub temp_min_c: Option<f64>,
    /// Its mean, °C: the temperature the point is plotted and modelled at.
    pub temp_mean_c: Option<f64>,
    /// Its highest, °C.
    pub temp_max_c: Option<f64>,
    /// Scale factor K at this temperature, in `fit.json`'s unit (V/(°/s)).
    pub k: Option<f64>,
    /// Its expanded uncertainty (k = 2).
    pub u_k: Option<f64>,
    /// Bias at this temperature, °/h.
    pub bias_dph: Option<f64>,
    /// Its expanded uncertainty (k = 2), °/h.
    pub u_bias_dph: Option<f64>,
    /// Nonlinearity of the sweep at this temperature, ppm.
    pub nonlinearity_ppm: Option<f64>,
}

/// The series of one run (a row of `series_results` and its points).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SeriesRecord {
    /// Each temperature, in the order of the plan.
    pub points: Vec<SeriesPointRecord>,
    /// K's temperature sensitivity, ppm/°C.
    pub k_tempco_ppm_per_c: Option<f64>,
    /// Its expanded uncertainty (k = 2), ppm/°C.
    pub u_k_tempco_ppm_per_c: Option<f64>,
    /// The bias's temperature sensitivity, °/h/°C.
    pub bias_tempco_dph_per_c: Option<f64>,
    /// Its expanded uncertainty (k = 2), °/h/°C.
    pub u_bias_tempco_dph_per_c: Option<f64>,
    /// The order of K's model in T chosen (1 linear, 2 quadratic).
    pub k_model_order: Option<i64>,
    /// The order of the bias's model in T chosen.
    pub bias_model_order: Option<i64>,
    /// K's largest difference between visits of one temperature, ppm (`None`: none revisited).
    pub hysteresis_k_ppm: Option<f64>,
    /// The bias's, °/h.
    pub hysteresis_bias_dph: Option<f64>,
    /// The lowest gyro temperature measured at, °C.
    pub t_min_c: Option<f64>,
    /// The highest, °C.
    pub t_max_c: Option<f64>,
}

impl SeriesRecord {
    /// A non-finite figure (a NaN written as a number by another program, or an overflow) is
    /// no figure: stored as NULL, never as a value a trend would plot.
    fn finite(mut self) -> SeriesRecord {
        let keep = |v: &mut Option<f64>| {
            if v.is_some_and(|x| !x.is_finite()) {
                *v = None;
            }
        };
        for v in [
            &mut self.k_tempco_ppm_per_c,
            &mut self.u_k_tempco_ppm_per_c,
            &mut self.bias_tempco_dph_per_c,
            &mut self.u_bias_tempco_dph_per_c,
            &mut self.hysteresis_k_ppm,
            &mut self.hysteresis_bias_dph,
            &mut self.t_min_c,
            &mut self.t_max_c,
        ] {
            keep(v);
        }
        for p in &mut self.points {
            for v in [
                &mut p.temp_min_c,
                &mut p.temp_mean_c,
                &mut p.temp_max_c,
                &mut p.k,
                &mut p.u_k,
                &mut p.bias_dph,
                &mut p.u_bias_dph,
                &mut p.nonlinearity_ppm,
            ] {
                keep(v);
            }
        }
        self
    }
}

/// The series of the run in `dir`: `Ok(None)` when it has no [`SERIES_JSON`] (every run that
/// is not a temperature series, and a series not analysed yet); an error naming the file when
/// the file is not JSON, has no `catalog` member, or the member has another shape (a unknown
/// field, a text where a number goes, two points with one `series_point`).
pub fn read_series(dir: &Path) -> Result<Option<SeriesRecord>, CatalogError> {
    let path = dir.join(SERIES_JSON);
    if !path.exists() {
        return Ok(None);
    }
    let bad = |message: String| CatalogError::NotARun {
        path: dir.to_path_buf(),
        message: format!("{SERIES_JSON}: {message}"),
    };
    let bytes = gyrocal_files::rundir::read_capped(&path, gyrocal_files::rundir::MAX_FIT_BYTES)
        .map_err(|e| bad(e.to_string()))?;
    let doc: serde_json::Value =
        serde_json::from_slice(&bytes).map_err(|e| bad(format!("not JSON: {e}")))?;
    let member = doc.get(CATALOG_MEMBER).ok_or_else(|| {
        bad(format!(
            "has no \"{CATALOG_MEMBER}\" member (the series' figures the catalog keeps); \
             analyse the run again with this gyrocal"
        ))
    })?;
    let record: SeriesRecord = serde_json::from_value(member.clone()).map_err(|e| {
        // serde's words name the type, not the key: say where it is
        let at = misplaced(member)
            .map(|k| format!(" at {k}"))
            .unwrap_or_default();
        bad(format!("\"{CATALOG_MEMBER}\"{at}: {e}"))
    })?;
    let mut seen = std::collections::HashSet::new();
    if let Some(p) = record.points.iter().find(|p| !seen.insert(p.series_point)) {
        return Err(bad(format!(
            "\"{CATALOG_MEMBER}\": series_point {} appears twice",
            p.series_point
        )));
    }
    Ok(Some(record.finite()))
}

/// How a member's value must look: `(name, integer, required)`.
type Field = (&'static str, bool, bool);

/// The series' own members besides `points`.
const SERIES_FIELDS: [Field; 10] = [
    ("k_tempco_ppm_per_c", false, false),
    ("u_k_tempco_ppm_per_c", false, false),
    ("bias_tempco_dph_per_c", false, false),
    ("u_bias_tempco_dph_per_c", false, false),
    ("k_model_order", true, false),
    ("bias_model_order", true, false),
    ("hysteresis_k_ppm", false, false),
    ("hysteresis_bias_dph", false, false),
    ("t_min_c", false, false),
    ("t_max_c", false, false),
];

/// A point's members.
const POINT_FIELDS: [Field; 10] = [
    ("series_point", true, true),
    ("setpoint_c", false, true),
    ("temp_min_c", false, false),
    ("temp_mean_c", false, false),
    ("temp_max_c", false, false),
    ("k", false, false),
    ("u_k", false, false),
    ("bias_dph", false, false),
    ("u_bias_dph", false, false),
    ("nonlinearity_ppm", false, false),
];

/// The first key of `member` that does not fit its field (`points[1].k`,
/// `k_model_order`), for the refusal's message.
fn misplaced(member: &serde_json::Value) -> Option<String> {
    use serde_json::Value;
    fn wrong(obj: &serde_json::Map<String, Value>, fields: &[Field], skip: &str) -> Option<String> {
        for (key, v) in obj {
            if key == skip {
                continue;
            }
            let Some((_, integer, required)) = fields.iter().find(|(n, _, _)| n == key) else {
                return Some(key.clone());
            };
            let fits = match v {
                Value::Null => !required,
                Value::Number(n) if *integer => n.as_i64().is_some(),
                Value::Number(_) => true,
                _ => false,
            };
            if !fits {
                return Some(key.clone());
            }
        }
        fields
            .iter()
            .find(|(n, _, required)| *required && !obj.contains_key(*n))
            .map(|(n, _, _)| n.to_string())
    }
    let obj = member.as_object()?;
    if let Some(k) = wrong(obj, &SERIES_FIELDS, "points") {
        return Some(k);
    }
    match obj.get("points") {
        None => Some("points".into()),
        Some(Value::Array(points)) => points.iter().enumerate().find_map(|(i, p)| match p {
            Value::Object(p) => wrong(p, &POINT_FIELDS, "").map(|k| format!("points[{i}].{k}")),
            _ => Some(format!("points[{i}]")),
        }),
        Some(_) => Some("points".into()),
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;

    const CONTRACT: &str = r#"{ "catalog": { "points": [ { "series_point": 0, "setpoint_c": 25.0,
        "temp_min_c": 24.8, "temp_mean_c": 25.0, "temp_max_c": 25.1, "k": 0.0123, "u_k": 1e-6,
        "bias_dph": 3.1, "u_bias_dph": 0.2, "nonlinearity_ppm": 120.0 },
        { "series_point": 1, "setpoint_c": -20.0, "temp_min_c": null, "temp_mean_c": null,
        "temp_max_c": null, "k": null, "u_k": null, "bias_dph": null, "u_bias_dph": null,
        "nonlinearity_ppm": null } ],
      "k_tempco_ppm_per_c": 30.1, "u_k_tempco_ppm_per_c": 4.0,
      "bias_tempco_dph_per_c": 1.5, "u_bias_tempco_dph_per_c": 0.3,
      "k_model_order": 1, "bias_model_order": 1,
      "hysteresis_k_ppm": null, "hysteresis_bias_dph": 0.1,
      "t_min_c": -20.1, "t_max_c": 60.2 }, "verdict": "pass" }"#;

    fn dir_with(text: &str) -> tempfile::TempDir {
        let d = tempfile::tempdir().unwrap();
        std::fs::write(d.path().join(SERIES_JSON), text).unwrap();
        d
    }

    #[test]
    fn the_contracts_shape_is_read_with_its_nulls() {
        let d = dir_with(CONTRACT);
        let s = read_series(d.path()).unwrap().unwrap();
        assert_eq!(s.points.len(), 2);
        assert_eq!(s.points[0].k, Some(0.0123));
        assert_eq!(s.points[1].k, None);
        assert_eq!(s.k_tempco_ppm_per_c, Some(30.1));
        assert_eq!(s.hysteresis_k_ppm, None);
        assert_eq!(s.t_max_c, Some(60.2));
        // and written back in the same shape
        let back = serde_json::to_value(&s).unwrap();
        let orig: serde_json::Value = serde_json::from_str(CONTRACT).unwrap();
        assert_eq!(back, orig["catalog"]);
    }

    #[test]
    fn no_series_json_is_no_series() {
        let d = tempfile::tempdir().unwrap();
        assert!(read_series(d.path()).unwrap().is_none());
    }

    #[test]
    fn another_shape_is_refused_naming_the_file_and_the_field() {
        for (text, says) in [
            ("{", "not JSON"),
            ("{\"verdict\": \"pass\"}", "no \"catalog\" member"),
            (
                &CONTRACT.replace("\"k_tempco_ppm_per_c\"", "\"k_tc\""),
                "k_tc",
            ),
            (
                &CONTRACT.replace("\"k_model_order\": 1", "\"k_model_order\": \"one\""),
                "at k_model_order: invalid type",
            ),
            (
                &CONTRACT.replace("\"u_k\": null", "\"u_k\": \"1e-6\""),
                "at points[1].u_k: invalid type",
            ),
            (
                &CONTRACT.replace("\"series_point\": 1", "\"series_point\": 0"),
                "series_point 0 appears twice",
            ),
        ] {
            let d = dir_with(text);
            let e = read_series(d.path()).unwrap_err();
            assert_eq!(e.kind(), crate::ErrorKind::NotARun);
            let m = e.to_string();
            assert!(m.contains("series.json") && m.contains(says), "{m}");
        }
    }
}
