//! A drift run's Allan results written through the run directory: what the operator is told
//! when the page cannot be written after the analysis was (a full disk).

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use gyrocal_files::{RunError, WriteResult};
use gyrocal_report::{ReportError, write_allan_into};

/// A run directory's result writer whose disk fills up before the page.
struct FullBeforePage {
    dir: PathBuf,
    written: Vec<String>,
}

impl WriteResult for FullBeforePage {
    fn dir(&self) -> &Path {
        &self.dir
    }

    fn write_result(&mut self, name: &str, bytes: &[u8]) -> Result<(), RunError> {
        if name == "allan.html" {
            return Err(RunError::Io {
                path: self.dir.join(".allan.html.tmp"),
                action: "write",
                source: std::io::Error::from_raw_os_error(28),
            });
        }
        std::fs::write(self.dir.join(name), bytes).unwrap();
        self.written.push(name.to_string());
        Ok(())
    }
}

/// A record at rest: white noise around 10 mV, 0.5 s apart.
fn samples(dir: &Path, n: usize) {
    let mut s = String::from("step,index,t_s,rate_dps,volts,overload,t_utc\n");
    let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
    for i in 0..n {
        x = x.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
        let u = (x >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
        let v = 0.01 + 1e-4 * u;
        let t = i as f64 * 0.5;
        let _ = writeln!(s, "0,{i},{t},0,{v:.9},0,2026-03-21T10:00:00.000Z");
    }
    std::fs::write(dir.join("samples.csv"), s).unwrap();
}

#[test]
fn a_page_that_cannot_be_written_is_told_apart_from_no_analysis() {
    let tmp = tempfile::tempdir().unwrap();
    samples(tmp.path(), 4000);
    let mut w = FullBeforePage {
        dir: tmp.path().to_path_buf(),
        written: Vec::new(),
    };
    let e = write_allan_into(&mut w, &Default::default(), &[]).unwrap_err();
    assert_eq!(w.written, ["allan.json"]);
    assert!(matches!(e, ReportError::PartlyWritten { .. }), "{e}");
    assert!(!e.is_input_error(), "a full disk is the environment's");
    let warning = e.allan_warning();
    assert!(
        warning.starts_with("the Allan analysis is in ") && warning.contains("allan.json"),
        "{warning}"
    );
    assert!(warning.contains("No space left on device"), "{warning}");
    assert!(!warning.contains("no Allan analysis"), "{warning}");
}
