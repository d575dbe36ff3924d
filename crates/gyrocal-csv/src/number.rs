//! Numbers straight from a cell's bytes.
//!
//! The fast path is `fast-float2` (Lemire's algorithm, the one the standard library's
//! `str::parse::<f64>` also uses, without the `&str` conversion and its UTF-8 check): on a
//! record's cells it is what makes reading a number cost about as much as finding it. Both
//! round correctly, so a value is the same bits either way. Whatever the fast parser does not
//! accept goes to the standard library's parser on the cell as text (any Unicode whitespace
//! trimmed), so the set of cells accepted is the standard library's, and the error message is
//! decided there, off the fast path.

use crate::Problem;

/// A finite number; `Empty`, `NotANumber` or `NotFinite` otherwise.
pub(crate) fn finite(cell: &[u8]) -> Result<f64, Problem> {
    let v = any_number(cell)?;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(Problem::NotFinite(v))
    }
}

/// A number, finite or not.
pub(crate) fn any_number(cell: &[u8]) -> Result<f64, Problem> {
    if cell.is_empty() {
        return Err(Problem::Empty);
    }
    match fast_float2::parse::<f64, _>(cell) {
        Ok(v) => Ok(v),
        Err(_) => slow(cell),
    }
}

/// The standard library's parser on the cell as text, trimmed of any Unicode whitespace (a
/// no-break space before a number pasted from a spreadsheet).
fn slow(cell: &[u8]) -> Result<f64, Problem> {
    let text = String::from_utf8_lossy(cell);
    let text = text.trim();
    if text.is_empty() {
        return Err(Problem::Empty);
    }
    text.parse::<f64>().map_err(|_| Problem::NotANumber)
}

/// A count: a whole number > 0 (`+` allowed, as `str::parse::<u64>`).
pub(crate) fn count(cell: &[u8]) -> Result<u64, Problem> {
    std::str::from_utf8(cell)
        .ok()
        .and_then(|t| t.parse::<u64>().ok())
        .filter(|&n| n > 0)
        .ok_or(Problem::NotACount)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use proptest::prelude::*;

    /// What the callers did before this reader: the standard library on the trimmed text.
    fn reference(cell: &[u8]) -> Result<f64, Problem> {
        let text = String::from_utf8_lossy(cell);
        let text = text.trim();
        if text.is_empty() {
            return Err(Problem::Empty);
        }
        text.parse::<f64>().map_err(|_| Problem::NotANumber)
    }

    fn same(cell: &[u8]) {
        match (any_number(cell), reference(cell)) {
            (Ok(a), Ok(b)) => assert!(
                a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()),
                "{:?}: {a} vs {b}",
                String::from_utf8_lossy(cell)
            ),
            (a, b) => assert_eq!(a, b, "{:?}", String::from_utf8_lossy(cell)),
        }
    }

    #[test]
    fn the_fast_parser_accepts_what_the_standard_library_accepts_bit_for_bit() {
        for cell in [
            "0",
            "-0",
            "+1",
            "1.",
            ".5",
            "+.5",
            "-.5e-3",
            "1e5",
            "1E+05",
            "1e",
            "e5",
            ".",
            "-",
            "+",
            "1.2.3",
            "0x10",
            "1_000",
            "inf",
            "-inf",
            "+Infinity",
            "NaN",
            "nan",
            "-nan",
            "1e999",
            "-1e-999",
            "4.9e-324",
            "2.2250738585072011e-308",
            "0.1",
            "0.30000000000000004",
            "123456789012345678901234567890",
            "1,5",
            " 1",
            "1 ",
            "\u{a0}2.5",
            "١",
            "∞",
            "0.012495622",
            "3.000000",
        ] {
            same(cell.as_bytes());
        }
        same(b"\xff1");
        assert_eq!(finite(b"1e999"), Err(Problem::NotFinite(f64::INFINITY)));
        assert_eq!(finite(b""), Err(Problem::Empty));
        assert_eq!(count(b"+5"), Ok(5));
        assert_eq!(count(b"0"), Err(Problem::NotACount));
        assert_eq!(count(b"1.0"), Err(Problem::NotACount));
    }

    proptest! {
        #[test]
        fn random_cells_parse_as_the_standard_library_parses_them(
            cell in "[-+0-9.eEinfatyINFATY ]{0,12}",
        ) {
            same(cell.trim_ascii().as_bytes());
        }

        #[test]
        fn random_decimals_are_the_same_bits(
            v in -1e6f64..1e6,
            decimals in 0usize..25,
            digits in "[0-9]{1,21}",
            dot in 0usize..22,
        ) {
            same(format!("{v:.decimals$}").as_bytes());
            let (a, b) = digits.split_at(dot.min(digits.len()));
            same(format!("{a}.{b}").as_bytes());
            same(format!("-{a}.{b}").as_bytes());
        }

        #[test]
        fn random_numbers_are_the_same_bits(v in any::<f64>(), digits in 1usize..20) {
            same(format!("{v:.digits$e}").as_bytes());
            same(format!("{v}").as_bytes());
        }
    }
}
