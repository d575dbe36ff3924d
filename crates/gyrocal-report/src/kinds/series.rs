//! A temperature series' part of the report: NOT YET WRITTEN (a placeholder, so the kind
//! builds; helper "analysis" replaces this file). The end of a complete series says plainly
//! that nothing analysed it; no page.

use gyrocal_files::RunDir;

use super::{Ending, KindPages};
use crate::ReportError;

/// A temperature series: no analysis and no page yet.
pub(crate) static PAGES: KindPages = KindPages {
    ending: series_ending,
    own_page: None,
};

/// The end of a complete series: a warning that its analysis is not written.
fn series_ending(_run: &mut RunDir, _pages: bool) -> Result<Ending, ReportError> {
    let mut end = Ending::default();
    end.warnings.push(format!(
        "{}: the steps and temperatures are recorded, but no K(T) or bias(T) was computed",
        gyrocal_analysis::series::NOT_WRITTEN
    ));
    Ok(end)
}
