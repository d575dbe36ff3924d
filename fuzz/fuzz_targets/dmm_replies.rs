//! The HP 34401A reply parsers on arbitrary bytes: none may panic, and what they accept must
//! be what the meter could have meant.
#![no_main]

use gyrocal_hp34401a::{Identity, Reading, parse_error, parse_reading};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    for piece in text.split([',', ';', '\n']) {
        if let Some(r) = parse_reading(piece) {
            if let Reading::Volts(v) = r {
                assert!(v.is_finite());
            }
        }
    }
    let _ = parse_reading(&text);
    if let Some(e) = parse_error(&text) {
        let _ = e.to_string();
    }
    if let Some(id) = Identity::parse(&text) {
        assert!(id.model.eq_ignore_ascii_case("34401A"));
        assert_eq!(id.raw, text);
    }
});
