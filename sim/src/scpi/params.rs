//! SCPI parameters as both simulated meters read them: a number (an optional `V` unit
//! suffix; anything else, or a number that is not finite, is -104 "Data type error") and a
//! boolean (`ON`/`OFF`/`1`/`0`, case-insensitive; anything else is -224 "Illegal parameter
//! value").

/// A SCPI error to queue: code and message.
pub(crate) type ScpiError = (i32, &'static str);

/// -104 "Data type error".
pub(crate) const DATA_TYPE_ERROR: ScpiError = (-104, "Data type error");
/// -224 "Illegal parameter value".
pub(crate) const ILLEGAL_PARAMETER: ScpiError = (-224, "Illegal parameter value");

/// A keyword parameter, trimmed and upper case.
pub(crate) fn keyword(s: &str) -> String {
    s.trim().to_ascii_uppercase()
}

/// A numeric parameter.
pub(crate) fn number(s: &str) -> Result<f64, ScpiError> {
    let t = s.trim();
    // both meters accept an optional unit suffix on voltages
    let t = t.strip_suffix(['V', 'v']).unwrap_or(t);
    match t.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(DATA_TYPE_ERROR),
    }
}

/// A boolean parameter.
pub(crate) fn boolean(s: &str) -> Result<bool, ScpiError> {
    match keyword(s).as_str() {
        "ON" | "1" => Ok(true),
        "OFF" | "0" => Ok(false),
        _ => Err(ILLEGAL_PARAMETER),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parameters() {
        assert_eq!(number(" 10 "), Ok(10.0));
        assert_eq!(number("0.5V"), Ok(0.5));
        assert_eq!(number("1e-3v"), Ok(1e-3));
        assert_eq!(number("inf"), Err(DATA_TYPE_ERROR));
        assert_eq!(number("ten"), Err(DATA_TYPE_ERROR));
        assert_eq!(boolean("on"), Ok(true));
        assert_eq!(boolean(" 0"), Ok(false));
        assert_eq!(boolean("yes"), Err(ILLEGAL_PARAMETER));
    }
}
