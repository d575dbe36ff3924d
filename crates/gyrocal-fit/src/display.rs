//! How a person reads a figure: one rule for a value with its uncertainty, one table of the
//! quantities' names in words with their units, one spelling of each unit. The terminal
//! (`gyrocal fit`, `allan`, `history`, `check`, the end of a run), the certificate and the
//! pages all print through here, so the same quantity reads the same everywhere.
//!
//! Why one rule: before it, the same nonlinearity read "9.3134121e2 ppm" in a verdict line,
//! "931.3412" in its reason and "931.3" in the metrics, and a scale factor "3.6119660e-1"
//! beside "0.361197". A reader comparing figures should compare digits, not formats.
//!
//! Files are not formatted here: JSON and CSV keep every computed digit
//! (`gyrocal_files::num::round_significant`) and their keys (`scale_factor`, `bias_v`, ...).

/// Values whose magnitude lies in this range are written in plain decimals; smaller or larger
/// ones as a mantissa times a power of ten, `(2.0797 ± 0.0033) × 10⁻⁵`, never `2.0797e-5`.
const PLAIN: std::ops::Range<f64> = 1e-3..1e6;

/// `10ⁿ` with superscript digits (`10⁻⁵`), as a certificate prints a power of ten.
pub fn power_of_ten(n: i32) -> String {
    const SUP: [char; 10] = ['⁰', '¹', '²', '³', '⁴', '⁵', '⁶', '⁷', '⁸', '⁹'];
    let mut s = String::from("10");
    if n < 0 {
        s.push('⁻');
    }
    for d in n.unsigned_abs().to_string().chars() {
        if let Some(i) = d.to_digit(10) {
            s.push(SUP[i as usize]);
        }
    }
    s
}

fn decade(v: f64) -> i32 {
    v.abs().log10().floor() as i32
}

/// A value and its uncertainty in the certificate's rule, as text in a common scale:
/// the mantissas and the power of ten they share (`None`: plain decimals).
struct Scaled {
    value: String,
    u: String,
    exponent: Option<i32>,
}

/// The rule: U to two significant digits, the value to one decimal beyond U's last digit
/// (GUM 7.2.6 rounds to U's digits; the extra digit keeps the rounding error well under U).
/// Both in the same scale, so the value and U line up digit for digit.
fn scaled(v: f64, u: f64) -> Scaled {
    let av = v.abs();
    let exponent = (av != 0.0 && !PLAIN.contains(&av)).then(|| decade(v));
    let (v, u) = match exponent {
        Some(e) => (v / 10f64.powi(e), u / 10f64.powi(e)),
        None => (v, u),
    };
    // U to two significant digits first (0.0996 is 0.10: its decade is the rounded one's)
    let u = format!("{u:.1e}").parse::<f64>().unwrap_or(u);
    let eu = decade(u);
    // above 100 the digits to drop are before the point: U = 131 is 130, and a value beside
    // U = 1300 is rounded to tens
    let (v, u) = if eu >= 2 {
        let to = |x: f64, e: i32| (x / 10f64.powi(e)).round() * 10f64.powi(e);
        (if eu >= 3 { to(v, eu - 2) } else { v }, to(u, eu - 1))
    } else {
        (v, u)
    };
    let decimals = (2 - eu).clamp(0, 15) as usize;
    let u_decimals = (1 - eu).clamp(0, 15) as usize;
    Scaled {
        value: format!("{v:.decimals$}"),
        u: format!("{u:.u_decimals$}"),
        exponent,
    }
}

/// A value and its uncertainty as two columns (a table's "Value" and "U"): the rule of
/// [`value_pm_u`], each with its power of ten when one is needed (`2.0797 × 10⁻⁵`,
/// `0.0033 × 10⁻⁵`). Without a usable U (missing, zero, not finite) the value to 7
/// significant digits and "—".
pub fn value_and_u(v: f64, u: Option<f64>) -> (String, String) {
    let Some(u) = u.filter(|u| u.is_finite() && *u > 0.0 && v.is_finite()) else {
        return (significant(v, 7), "—".to_string());
    };
    let s = scaled(v, u);
    match s.exponent {
        Some(e) => {
            let p = power_of_ten(e);
            (format!("{} × {p}", s.value), format!("{} × {p}", s.u))
        }
        None => (s.value, s.u),
    }
}

/// A value with its uncertainty and unit on one line, the one way every `±` is printed:
/// `0.361197 ± 0.00015 V/(°/s)`, `2098 ± 300 ppm`, `(2.0797 ± 0.0033) × 10⁻⁵ V/(°/s)²`.
/// Without a usable U the value alone ([`significant`], 7 digits). `unit` may be empty.
pub fn value_pm_u(v: f64, u: Option<f64>, unit: &str) -> String {
    let unit = display_unit(unit);
    let sep = if unit.is_empty() { "" } else { " " };
    let Some(u) = u.filter(|u| u.is_finite() && *u > 0.0 && v.is_finite()) else {
        return format!("{}{sep}{unit}", significant(v, 7));
    };
    let s = scaled(v, u);
    match s.exponent {
        Some(e) => format!("({} ± {}) × {}{sep}{unit}", s.value, s.u, power_of_ten(e)),
        None => format!("{} ± {}{sep}{unit}", s.value, s.u),
    }
}

/// The value alone, rounded as [`value_pm_u`] would round it beside `u` (the same decimals),
/// for a figure written next to its value ± U elsewhere on the same page or screen.
pub fn value_as_with_u(v: f64, u: Option<f64>) -> String {
    value_and_u(v, u).0
}

/// `v` to `n` significant digits; outside 0.001 .. 10⁶ as a mantissa times a power of ten
/// (`2.079674 × 10⁻⁵`). Not finite: "—".
pub fn significant(v: f64, n: i32) -> String {
    if !v.is_finite() {
        return "—".to_string();
    }
    let av = v.abs();
    let digits = |x: f64| {
        let e = if x == 0.0 { 0 } else { decade(x) };
        (n - 1 - e).clamp(0, 15) as usize
    };
    if av != 0.0 && !PLAIN.contains(&av) {
        let e = decade(v);
        let m = v / 10f64.powi(e);
        let d = digits(m);
        return format!("{m:.d$} × {}", power_of_ten(e));
    }
    let d = digits(v);
    format!("{v:.d$}")
}

/// [`significant`] without the trailing zeros (`0.3616`, `20`, `1.5 × 10⁻⁹`): for axis
/// labels and plan descriptions, where the digits are not a claim of precision.
pub fn trimmed(v: f64, n: i32) -> String {
    let s = significant(v, n);
    let (mantissa, rest) = match s.find(" × ") {
        Some(i) => s.split_at(i),
        None => (s.as_str(), ""),
    };
    let mantissa = if mantissa.contains('.') {
        mantissa.trim_end_matches('0').trim_end_matches('.')
    } else {
        mantissa
    };
    format!("{mantissa}{rest}")
}

/// A number written in a file or by a person (a limit, a rate of the plan), in its shortest
/// form, with a power of ten outside 0.001 .. 10⁶ (`1 × 10⁻⁵` for `1e-5`): no trailing zeros
/// it did not have.
pub fn plain(v: f64) -> String {
    if !v.is_finite() {
        return v.to_string();
    }
    let av = v.abs();
    if av != 0.0 && !PLAIN.contains(&av) {
        let e = decade(v);
        // the shortest mantissa that reads back as the value
        let text = format!("{v:e}");
        let mantissa = text.split('e').next().unwrap_or(&text).to_string();
        return format!("{mantissa} × {}", power_of_ten(e));
    }
    format!("{v}")
}

/// One spelling of each unit on human-facing output: the files' ASCII spellings (`deg/h`,
/// `deg/sqrt(h)`, kept in JSON) become the symbols the pages use (`°/h`, `°/√h`). Any other
/// unit is returned as it is.
pub fn display_unit(unit: &str) -> &str {
    match unit {
        "deg/s" => "°/s",
        "deg/h" => "°/h",
        "deg/sqrt(h)" => "°/√h",
        "deg/h/sqrt(h)" => "°/h/√h",
        "deg/h^2" | "deg/h/h" => "°/h²",
        "deg" => "°",
        "V/(deg/s)" => "V/(°/s)",
        "V/(deg/s)^2" => "V/(°/s)²",
        other => other,
    }
}

/// The quantities a person reads, by the key files and JSON use: (name in words, unit).
/// The one table of display names: the terminal, the certificate's results, acceptance and
/// budget tables, and the history pages take their words from it.
pub const QUANTITIES: [(&str, &str, &str); 10] = [
    ("scale_factor", "scale factor K", "V/(°/s)"),
    ("bias_v", "bias K0", "V"),
    ("bias_dph", "bias (as a rate)", "°/h"),
    ("k_pos", "scale factor K+ (ω ≥ 0)", "V/(°/s)"),
    ("k_neg", "scale factor K− (ω ≤ 0)", "V/(°/s)"),
    ("nonlinearity_ppm", "nonlinearity", "ppm"),
    ("asymmetry_ppm", "asymmetry (common K2, unbiased)", "ppm"),
    (
        "asymmetry_gjb_ppm",
        "asymmetry (GJB two lines, biased by K2)",
        "ppm",
    ),
    ("repeatability_ppm", "repeatability", "ppm"),
    ("k2", "second-order coefficient K2", "V/(°/s)²"),
];

/// The name in words and the unit of the quantity a file calls `key` (`scale_factor` →
/// "scale factor K", "V/(°/s)"); a key not in [`QUANTITIES`] (written by a later gyrocal)
/// comes back with its underscores as spaces and no unit.
pub fn quantity_words(key: &str) -> (String, &'static str) {
    match QUANTITIES.iter().find(|(k, _, _)| *k == key) {
        Some((_, name, unit)) => ((*name).to_string(), unit),
        None => (key.replace('_', " "), ""),
    }
}

/// The name in words and unit of a metric of the uncertainty budget's metrics table
/// (`uncertainty.metrics.entries[].metric`): those keys follow [`crate::Metrics`], where
/// `asymmetry_ppm` is the GJB two-line figure and `asymmetry_common_k2` the unbiased one
/// (an acceptance specification's `asymmetry_ppm` is the unbiased one: [`quantity_words`]).
pub fn metric_words(key: &str) -> (String, &'static str) {
    match key {
        "asymmetry_ppm" => quantity_words("asymmetry_gjb_ppm"),
        "asymmetry_common_k2" => quantity_words("asymmetry_ppm"),
        other => quantity_words(other),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_value_is_shown_to_a_digit_beyond_its_uncertainty() {
        assert_eq!(
            value_and_u(0.3611966, Some(1.452e-4)),
            ("0.361197".to_string(), "0.00015".to_string())
        );
        assert_eq!(
            value_and_u(116.91155, Some(13.2)),
            ("116.9".to_string(), "13".to_string())
        );
        assert_eq!(
            value_and_u(1.5, None),
            ("1.500000".to_string(), "—".to_string())
        );
        assert_eq!(significant(931.3412055, 7), "931.3412");
    }

    #[test]
    fn small_values_share_a_power_of_ten_with_their_uncertainty() {
        assert_eq!(
            value_and_u(2.0797e-5, Some(3.3e-7)),
            ("2.0797 × 10⁻⁵".to_string(), "0.033 × 10⁻⁵".to_string())
        );
        assert_eq!(
            value_pm_u(2.0796736e-5, Some(3.32e-7), "V/(°/s)²"),
            "(2.0797 ± 0.033) × 10⁻⁵ V/(°/s)²"
        );
        assert_eq!(
            value_pm_u(2.5e7, Some(1.2e5), "Hz"),
            "(2.5000 ± 0.012) × 10⁷ Hz"
        );
        assert_eq!(significant(2.0796736e-5, 4), "2.080 × 10⁻⁵");
        assert_eq!(plain(1e-5), "1 × 10⁻⁵");
        assert_eq!(trimmed(1.5e-9, 6), "1.5 × 10⁻⁹");
        assert_eq!(trimmed(0.36160, 6), "0.3616");
        assert_eq!(trimmed(-20.0, 6), "-20");
        assert_eq!(plain(36.0), "36");
        assert_eq!(plain(0.051), "0.051");
    }

    #[test]
    fn the_one_line_form_matches_the_columns() {
        // the verdict line of the issue: one form, the value to a digit beyond U
        assert_eq!(value_pm_u(2098.3722, Some(300.0), "ppm"), "2098 ± 300 ppm");
        assert_eq!(value_pm_u(931.34121, Some(21.1), "ppm"), "931.3 ± 21 ppm");
        assert_eq!(
            value_pm_u(0.3611966, Some(1.45e-4), "V/(°/s)"),
            "0.361197 ± 0.00015 V/(°/s)"
        );
        assert_eq!(
            value_pm_u(0.0195, Some(4.2e-4), "deg/sqrt(h)"),
            "0.019500 ± 0.00042 °/√h"
        );
        assert_eq!(value_pm_u(1.5, None, ""), "1.500000");
        assert_eq!(value_pm_u(1.5, Some(f64::NAN), "V"), "1.500000 V");
        for (v, u) in [
            (3.6e-1, 7.2e-5),
            (2.0e-5, 1.7e-7),
            (1.2e3, 13.0),
            (4.7, 0.68),
        ] {
            let s = value_pm_u(v, Some(u), "V");
            assert!(!s.contains("e-") && !s.contains("e3"), "{s}");
        }
    }

    #[test]
    fn every_key_has_words_and_units_are_spelled_once() {
        for (key, name, unit) in QUANTITIES {
            assert!(!name.contains('_'), "{key}: {name}");
            assert_eq!(quantity_words(key), (name.to_string(), unit));
        }
        assert_eq!(quantity_words("some_new_key").0, "some new key");
        assert!(metric_words("asymmetry_ppm").0.contains("GJB"));
        assert!(metric_words("asymmetry_common_k2").0.contains("unbiased"));
        assert_eq!(display_unit("deg/sqrt(h)"), "°/√h");
        assert_eq!(display_unit("deg/h/sqrt(h)"), "°/h/√h");
        assert_eq!(display_unit("ppm"), "ppm");
        assert_eq!(power_of_ten(-12), "10⁻¹²");
        assert_eq!(power_of_ten(7), "10⁷");
    }
}
