//! A drift record's part of the report ([`super`]): the end of a complete record (its Allan
//! analysis and page written through the run directory) and its own page for `gyrocal
//! report`. The page itself is [`crate::allan`]'s, which `gyrocal allan` also renders for any
//! record.

use std::path::{Path, PathBuf};

use super::{Ending, KindPages, OwnPage};
use crate::ReportError;

/// A drift record's part of the one dispatch: its ending and its own page.
pub(crate) static PAGES: KindPages = KindPages {
    ending,
    own_page: Some(OwnPage {
        kind: "drift",
        files_read: &crate::allan::DRIFT_FILES_READ,
        what: "a drift record: the Allan analysis",
        alone,
        write: write_own_page,
    }),
};

/// Why a drift record's report takes no other inputs, `--out` or `--acceptance`.
fn alone(dir: &Path) -> String {
    format!(
        "{} is a drift record: its report is its Allan page, written alone into the run directory by `gyrocal report {0}` (or anywhere by `gyrocal allan {0} -o FILE`); --out, --acceptance and other inputs do not apply",
        dir.display()
    )
}

fn write_own_page(dir: &Path, notes: &[String]) -> Result<Vec<PathBuf>, ReportError> {
    crate::allan::write_run_allan_noted(dir, &Default::default(), notes).map(|(_, files)| files)
}

/// The end of a complete drift record: the record is analysed by Allan deviation, not
/// fitted; `allan.json` and `allan.html` are written through the run directory still open
/// (recorded in the manifest with their SHA-256, under the run's lock). Without `pages` the
/// record is left for `gyrocal allan`. The analysis finds the scale factor itself (the run's
/// fit.json, or the simulated gyro's); without one the record stays in volts.
fn ending(
    run: &mut gyrocal_files::RunDir,
    pages: bool,
) -> Result<Ending, ReportError> {
    let dir = run.path().to_path_buf();
    let mut end = Ending::default();
    if !pages {
        end.results = format!(
            "drift record complete: analyse it with `gyrocal allan {}` (--scale-factor K for °/h)",
            dir.display()
        );
        return Ok(end);
    }
    match crate::allan::write_allan_into(run, &Default::default(), &[]) {
        Ok((a, files)) => {
            end.result = Some(result_line(&a, &dir));
            end.page = files
                .iter()
                .find(|f| f.extension().is_some_and(|e| e == "html"))
                .cloned();
            end.json.insert(
                "allan".into(),
                serde_json::json!({
                    "files": files,
                    "unit": a.unit,
                    "scale_factor": a.scale_factor,
                    "noise_terms": a.noise_terms,
                    "bias": a.bias,
                    "warmup": a.warmup,
                }),
            );
            // short lines (the run directory is printed beside them): the files by name
            end.results = format!(
                "drift record complete: its Allan analysis is {} in the run directory\n{}",
                files
                    .iter()
                    .filter_map(|f| f.file_name().map(|n| n.to_string_lossy().into_owned()))
                    .collect::<Vec<_>>()
                    .join(" and "),
                match &a.scale_factor {
                    Some(k) => format!(
                        "  in °/h with K = {} V/(°/s): {}",
                        k.v_per_dps, k.source
                    ),
                    None => format!(
                        "  in volts: `gyrocal allan {} --scale-factor K` for °/h",
                        dir.display()
                    ),
                }
            );
            if let Some(s) = a.join_gaps_hint_s {
                end.results.push_str(&format!(
                    "\nnote: the record has short gaps (a resume?) and only its longest segment was analysed: `gyrocal allan {} --join-gaps-below {s:.0}` analyses it whole, the gaps as dead time (if the gyro was left untouched across them)",
                    dir.display(),
                ));
            }
        }
        Err(e) => end.warnings.push(format!(
            "{} (the record is complete: `gyrocal report {}` writes the analysis again)",
            e.allan_warning(),
            dir.display()
        )),
    }
    Ok(end)
}


/// "result: N = … ± … °/√h, B = … ± … °/h, K = … ± … °/h/√h (k = 2)": the noise terms of the
/// five-term fit, as the certificate prints a value with its U; a record left in volts says
/// how to get them.
fn result_line(doc: &gyrocal_analysis::drift::AllanDocument, dir: &Path) -> String {
    let f = gyrocal_analysis::drift::DriftFigures::of(doc).figures();
    let term = |name: &str, v: Option<f64>, u: Option<f64>, unit: &str| {
        v.map(|v| format!("{name} = {}", gyrocal_fit::display::value_pm_u(v, u, unit)))
    };
    let terms: Vec<String> = [
        term("N", f.arw_deg_rt_h, f.u_arw_deg_rt_h, "°/√h"),
        term("B", f.bias_instability_dph, f.u_bias_instability_dph, "°/h"),
        term("K", f.rrw_dph_rt_h, f.u_rrw_dph_rt_h, "°/h/√h"),
    ]
    .into_iter()
    .flatten()
    .collect();
    if terms.is_empty() {
        format!(
            "result: the record is in volts (no scale factor known): `gyrocal allan {} --scale-factor K` gives its noise terms in °/h",
            dir.display()
        )
    } else {
        format!("result: {} (k = 2)", terms.join(", "))
    }
}
