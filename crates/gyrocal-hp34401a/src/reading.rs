//! Readings as the meter sends them: `SD.DDDDDDDDESDD`, e.g. `+1.00010310E+01`.

// The reading type is the multimeter role's: every meter hands the run the same readings.
pub use gyrocal_meter::{OVERLOAD, Reading};

/// Parses one reading. Accepts any exponent (`+0.00000000E-05` has been seen from real meters)
/// and the plain-number forms a sibling meter might send; rejects anything else with `None`.
pub fn parse_reading(text: &str) -> Option<Reading> {
    let t = text.trim_matches(' ');
    if t.is_empty()
        || t.len() > 24
        || !t
            .bytes()
            .all(|b| b.is_ascii_digit() || matches!(b, b'+' | b'-' | b'.' | b'E' | b'e'))
        || !t.bytes().any(|b| b.is_ascii_digit())
    {
        return None;
    }
    let v: f64 = t.parse().ok()?;
    if !v.is_finite() {
        return None;
    }
    if v.abs() >= OVERLOAD * 0.999_999 {
        return Some(Reading::Overload { positive: v > 0.0 });
    }
    Some(Reading::Volts(v))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formats_from_the_manual() {
        assert_eq!(
            parse_reading("+1.00010310E+01"),
            Some(Reading::Volts(10.001031))
        );
        assert_eq!(parse_reading("+0.00000000E-05"), Some(Reading::Volts(0.0)));
        assert_eq!(
            parse_reading("-1.23456789E-03"),
            Some(Reading::Volts(-1.23456789e-3))
        );
        assert_eq!(
            parse_reading("+9.90000000E+37"),
            Some(Reading::Overload { positive: true })
        );
        assert_eq!(
            parse_reading("-9.90000000E+37"),
            Some(Reading::Overload { positive: false })
        );
        for bad in [
            "",
            "1",
            "+1.0000?000E+00",
            "HEWLETT",
            "+1.0E+00;",
            "NaN",
            "inf",
            "1e999",
            "+.E",
        ] {
            if bad == "1" {
                assert!(parse_reading(bad).is_some());
            } else {
                assert_eq!(parse_reading(bad), None, "{bad}");
            }
        }
    }
}
