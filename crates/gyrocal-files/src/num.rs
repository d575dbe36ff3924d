//! How the run directory writes computed numbers: rounded once to [`SIGNIFICANT_DIGITS`]
//! significant digits, then printed as the shortest text that reads back as the same `f64`
//! (what the `csv` and `serde_json` writers print).
//!
//! Why: a mean, a sum, a time interpolated between two others or a coefficient from least
//! squares carries the last bits of binary arithmetic, which the shortest round-trip printer
//! faithfully shows (`10.521512000000001`). Those digits are not information. Twelve
//! significant digits are far more than anything a bench measures (the 34401A resolves
//! 6½ digits; the mean of a million readings gains three more; the run clock is read to a
//! microsecond over eleven days), and few enough that arithmetic noise, some 1e-16 relative
//! per operation, never shows. The rule is relative, not a fixed number of decimals, so a
//! standard deviation of 3e-9 V keeps its digits as well as a rate of 500 °/s. Values that
//! come from a file as text (the plan's rates, a reading the meter sent) already have at
//! most the digits they were written with and come out unchanged.

/// Significant digits of every computed number written to a run directory.
pub const SIGNIFICANT_DIGITS: usize = 12;

/// `v` rounded to [`SIGNIFICANT_DIGITS`] significant digits (round half to even on the exact
/// decimal expansion of `v`, by Rust's float formatting). Zero, infinities and NaN are
/// returned as they are, and so is a value whose rounding would overflow.
pub fn round_significant(v: f64) -> f64 {
    if !v.is_finite() || v == 0.0 {
        return v;
    }
    let text = format!("{:.*e}", SIGNIFICANT_DIGITS - 1, v);
    match text.parse::<f64>() {
        Ok(r) if r.is_finite() => r,
        _ => v,
    }
}

/// [`round_significant`] of an optional value.
pub fn round_opt(v: Option<f64>) -> Option<f64> {
    v.map(round_significant)
}

/// Rounds every non-integer number of a JSON document (see [`round_significant`]); integers
/// (counts, indices) are left as they are.
pub fn round_json(v: &mut serde_json::Value) {
    match v {
        serde_json::Value::Number(n) if n.is_f64() => {
            if let Some(r) = n
                .as_f64()
                .map(round_significant)
                .and_then(serde_json::Number::from_f64)
            {
                *n = r;
            }
        }
        serde_json::Value::Array(items) => items.iter_mut().for_each(round_json),
        serde_json::Value::Object(map) => map.values_mut().for_each(round_json),
        _ => {}
    }
}

/// How a person reads a value with its uncertainty: the rule lives with the other display
/// rules in [`gyrocal_fit::display`] (re-exported here for the callers that found it here).
pub use gyrocal_fit::display::{significant, value_and_u};

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arithmetic_noise_goes_and_information_stays() {
        assert_eq!(round_significant(10.521512000000001), 10.521512);
        assert_eq!(round_significant(0.1 + 0.2), 0.3);
        assert_eq!(round_significant(3.000000000000004e-9), 3e-9);
        assert_eq!(round_significant(-609.8214999999999), -609.8215);
        // twelve digits survive
        assert_eq!(round_significant(1.23456789012), 1.23456789012);
        assert_eq!(round_significant(0.0), 0.0);
        assert!(round_significant(f64::NAN).is_nan());
        assert_eq!(round_significant(f64::MAX), 1.79769313486e308);
        let mut doc =
            serde_json::json!({"k": 0.30000000000000004, "n": 7, "a": [1.0000000000000002]});
        round_json(&mut doc);
        assert_eq!(doc.to_string(), r#"{"a":[1.0],"k":0.3,"n":7}"#);
    }
}
