//! A temperature series' part of the report ([`super`]): the end of a complete series (its
//! analysis `series.json` and its page `series.html` written through the run directory, the
//! sensitivities with U said) and its own page for `gyrocal report`. The page itself is
//! [`crate::series_page`]'s.

use std::path::{Path, PathBuf};

use gyrocal_files::RunDir;

use super::{Ending, KindPages, OwnPage};
use crate::ReportError;

/// A temperature series' part of the one dispatch: its ending and its own page.
pub(crate) static PAGES: KindPages = KindPages {
    ending,
    own_page: Some(OwnPage {
        kind: "temperature_series",
        files_read: &crate::series_page::SERIES_FILES_READ,
        what: "a temperature series: K and the bias against temperature",
        alone,
        write: write_own_page,
    }),
};

/// Why a series' report takes no other inputs, `--out` or `--acceptance`.
fn alone(dir: &Path) -> String {
    format!(
        "{} is a temperature series: its report is its series page, written alone into the run directory by `gyrocal report {0}` (the limits on the sensitivities are the plan's [acceptance]); --out, --acceptance and other inputs do not apply",
        dir.display()
    )
}

fn write_own_page(dir: &Path, notes: &[String]) -> Result<Vec<PathBuf>, ReportError> {
    let mut run = gyrocal_files::RunResults::open(dir)?;
    crate::series_page::write_series_into(&mut run, notes).map(|(_, files)| files)
}

/// The end of a complete series: `series.json` and (with `pages`) `series.html` written
/// through the run directory still open; the sensitivities with their U said.
fn ending(run: &mut RunDir, pages: bool) -> Result<Ending, ReportError> {
    let dir = run.path().to_path_buf();
    let mut end = Ending::default();
    let written = if pages {
        crate::series_page::write_series_into(run, &[])
    } else {
        crate::series_page::write_analysis_into(run)
    };
    match written {
        Ok((doc, files)) => {
            let line = crate::series_page::result_line(&doc);
            end.results = format!(
                "temperature series complete: {} in the run directory\n  {line}",
                files
                    .iter()
                    .filter_map(|f| f.file_name().map(|n| n.to_string_lossy().into_owned()))
                    .collect::<Vec<_>>()
                    .join(" and ")
            );
            for n in &doc.notes {
                end.results.push_str(&format!("\n  note: {n}"));
            }
            end.result = Some(line);
            end.page = files
                .iter()
                .find(|f| f.extension().is_some_and(|e| e == "html"))
                .cloned();
            end.json.insert(
                "series".into(),
                serde_json::json!({
                    "files": files,
                    "k_tempco_ppm_per_c": doc.k_tempco_ppm_per_c,
                    "bias_tempco_dph_per_c": doc.bias_tempco_dph_per_c,
                    "verdict": doc.verdict,
                }),
            );
        }
        Err(e) => end.warnings.push(format!(
            "no series analysis: {e} (the run is complete: `gyrocal report {}` writes it again)",
            dir.display()
        )),
    }
    Ok(end)
}
