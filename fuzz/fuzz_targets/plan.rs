//! The plan parser on arbitrary text: errors, never panics.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    match gyrocal_run::Plan::from_toml_str(text, Path::new("fuzz.toml")) {
        Ok(plan) => {
            let _ = plan.schedule();
            let _ = plan.hash();
        }
        Err(e) => {
            let _ = e.to_string();
        }
    }
});
