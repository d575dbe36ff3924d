//! The one page every gyrocal HTML document is built on: the calibration report
//! (`report.html`), the drift (Allan) page and a gyro's history page.
//!
//! Why one module: the pages used to carry their own stylesheet (three copies that had
//! drifted: the report's, the drift page's, the history page's) and their own HTML escaper
//! (two, one of which did not escape `'`). A page now gets, from here only:
//!
//! * [`esc`], the escaper: every string that came from a file, a device, the operator or the
//!   catalog goes through it before it is written into element content or an attribute value;
//! * [`STYLESHEET`], the stylesheet (screen and print), holding the classes of every page;
//! * [`Page`], the skeleton: the document head (charset, viewport, title, the stylesheet plus a
//!   page's own extra rules, such as the certificate's `@page` header), the header block (the
//!   `<h1>` and the `.sub` line that names the run, the record or the gyro) and, with
//!   [`Page::close`], the footer and the closing tags.
//!
//! A page's own markup uses the classes listed on [`STYLESHEET`]; a class a new page needs
//! is added there, not in a second `<style>` block.
//!
//! ```
//! use gyrocal_report::page::{Page, esc};
//!
//! let serial = "A-0421 <lab>";
//! let mut html = String::new();
//! let title = format!("Calibration history of gyro {serial}");
//! Page::new(&title, &title).open(&mut html);
//! html.push_str(&format!("<p>{}</p>\n", esc(serial)));
//! Page::close(&mut html, None);
//! assert!(html.starts_with("<!DOCTYPE html>"));
//! assert!(html.contains("A-0421 &lt;lab&gt;") && html.ends_with("</html>\n"));
//! ```

use std::fmt::Write as _;

/// The stylesheet of every page (inline in each document: a report is one self-contained file).
///
/// Classes, by the page that needs them:
///
/// * all pages: `.sub` (the line under the title), `.banner` (red: must be seen before any
///   number), `.banner.simulated` / `.banner.caution` / `.banner.plans` (amber: a caution, not a
///   fault), `.note`, `td.num` (a right-aligned number), `.warn` (a warning inside a sentence or
///   a cell), `figure`/`figcaption` (a plot), `caption`;
/// * the calibration report and its certificate: `.dut`, `tr.best`, `table.cert`,
///   `table.signatures`, `.statement`, `.verdict` and `.verdict-*`, `td.v-pass`/`td.v-fail`,
///   `table.results`, `table.budget`, `#instruments-table`, `.end`, and the print rules that
///   start `#conditions`, `#uncertainty` and `#fit` on a new page;
/// * the drift (Allan) page: `tr.beyond` (curve points past the fitted range, greyed);
/// * the history page: `table.history` (smaller type and padding for its wide tables).
pub const STYLESHEET: &str = r#"
:root { color-scheme: light; }
body { font-family: system-ui, -apple-system, "Segoe UI", Roboto, Helvetica, Arial, sans-serif;
  color: #1a1a1a; background: #fff; margin: 0 auto; padding: 1rem 1.5rem 3rem; max-width: 64rem;
  line-height: 1.45; }
h1 { font-size: 1.6rem; margin: 0.5rem 0 0.25rem; }
h2 { font-size: 1.3rem; border-bottom: 1px solid #ccc; padding-bottom: 0.2rem; margin-top: 2rem; }
h3 { font-size: 1.1rem; margin-top: 1.5rem; }
.sub { color: #555; margin: 0 0 1rem; }
.banner { border: 2px solid #b00020; background: #fdecee; color: #6b0012; padding: 0.75rem 1rem;
  border-radius: 4px; font-weight: 600; margin: 1rem 0; }
.banner.simulated, .banner.caution { border-color: #7a4d00; background: #fff4d6; color: #4a2f00;
  font-weight: 400; }
.banner.simulated strong { font-size: 1.15rem; letter-spacing: 0.05em; }
.banner.plans { border-color: #7a4d00; background: #fff4d6; color: #4a2f00; }
.note { color: #444; font-size: 0.95rem; }
.warn { color: #b00020; font-weight: 600; }
table { border-collapse: collapse; margin: 0.5rem 0 1rem; font-size: 0.92rem; }
table.history { font-size: 0.85rem; }
table.history th, table.history td { padding: 0.2rem 0.4rem; }
/* a station id reads whole; the plan's words wrap instead (a wider column would push the
   verdict off a printed page) */
table.history td:nth-child(3) { white-space: nowrap; }
/* when a run started reads whole; a plan's name wraps in a column wide enough to read */
table.history td.when { white-space: nowrap; }
table.history td.plan { min-width: 9rem; }
/* on a narrow screen (a phone) a history table scrolls, not the page; a
   long serial in a heading wraps */
@media screen and (max-width: 48rem) {
  table.history { display: block; overflow-x: auto; max-width: 100%; }
}
h1, h2 { overflow-wrap: anywhere; }
/* a plot outside a figure (the history's trends) scales to the width too */
svg { max-width: 100%; height: auto; }
th, td { border: 1px solid #ccc; padding: 0.25rem 0.6rem; text-align: left; vertical-align: top; }
th { background: #f2f2f2; }
td.num { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
tr.best td { font-weight: 600; }
tr.beyond td { color: #888; }
figure { margin: 1rem 0 1.5rem; }
figure svg { display: block; width: 100%; max-width: 800px; height: auto; border: 1px solid #e3e3e3; }
figcaption { font-size: 0.92rem; color: #333; max-width: 800px; margin-top: 0.35rem; }
code { font-size: 0.9em; word-break: break-all; }
@media print {
  body { max-width: none; padding: 0; font-size: 10pt; }
  h2, h3, caption { break-after: avoid; }
  figure, table, .banner { break-inside: avoid; }
  figure svg { max-width: 100%; border: none; }
  .banner { background: #fff; color: #000; border: 3px solid #000; }
  th { background: #fff; }
  /* The budget starts a page; everything else flows, kept whole (a page of the acceptance
     table alone, or a summary alone before a forced break, was mostly empty paper). */
  #uncertainty { break-before: page; }
  /* a heading and its introductory paragraph stay with what they introduce */
  h2 + p, h3 + p, h2 + p.note, h3 + p.note { break-after: avoid; }
  .verdict { background: #fff; border-width: 3px; }
  table.cert td, table.cert th, table.results td { padding: 0.12rem 0.45rem; }
  h1 { margin-top: 0; }
  .signatures { break-inside: avoid; }
  table.history { font-size: 0.75rem; }
}
table.cert th { width: 11rem; background: #f7f7f7; }
#acceptance-table th, #instruments-table th, table.cert.results th { width: auto; }
#acceptance-table td:last-child { min-width: 14rem; }
table.signatures { width: 100%; margin-top: 2rem; }
table.signatures td { height: 2.2rem; min-width: 12rem; }
.statement { margin-top: 2rem; font-style: italic; }
.verdict { border: 2px solid #555; border-radius: 4px; padding: 0.6rem 1rem; margin: 1rem 0; }
.verdict-word { font-size: 1.25rem; font-weight: 700; letter-spacing: 0.04em; margin-right: 0.3rem; }
.verdict-fail { border-color: #b00020; background: #fdecee; }
.verdict-pass { border-color: #1b6e20; background: #eaf6ea; }
.verdict-marginal, .verdict-indeterminate { border-color: #7a4d00; background: #fff4d6; }
td.v-fail { color: #b00020; }
td.v-pass { color: #1b6e20; }
caption { text-align: left; font-weight: 600; padding: 0.2rem 0; }
table.results td.note { font-size: 0.85em; }
table.budget { font-size: 0.85em; width: 100%; }
table.budget td:first-child { min-width: 16rem; }
#instruments-table { font-size: 0.8rem; }
#instruments-table th, #instruments-table td { padding: 0.2rem 0.35rem; }
#instruments-table td { overflow-wrap: break-word; }
#instruments-table td:last-child { overflow-wrap: anywhere; }
/* ids and dates are read whole: SIM-34401A-0001 never on three lines */
#instruments-table td:nth-child(3), #instruments-table td:nth-child(4),
#instruments-table td:nth-child(6), #instruments-table td:nth-child(7) { white-space: nowrap; }
/* a table's first column names a quantity: no word broken there */
table.summary td:first-child, #acceptance-table td:first-child { min-width: 9rem; }
#acceptance-table td:nth-child(5), #acceptance-table td:nth-child(6) { white-space: nowrap; }
#bias-table th { white-space: nowrap; }
.end { text-align: center; margin-top: 2rem; font-weight: 600; letter-spacing: 0.05em; }
"#;

/// HTML-escapes text for element content and attribute values (`&`, `<`, `>`, `"` and `'`).
///
/// Everything that did not come from gyrocal's own source goes through it: names from a plan or
/// a manifest, a device's identification, a path, a catalog row, an error message.
pub fn esc(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            _ => out.push(c),
        }
    }
    out
}

/// The skeleton of one page: what goes before the page's own content.
///
/// [`Page::open`] writes the document head and the header block; the page then writes its
/// content; [`Page::close`] writes the footer and closes the document.
#[derive(Debug, Clone)]
pub struct Page<'a> {
    /// The document title (the browser tab, the printed header): plain text, escaped here.
    pub title: &'a str,
    /// The `<h1>` heading: plain text, escaped here.
    pub heading: &'a str,
    /// The `.sub` line under the heading naming what the page is about (the run, the record,
    /// the gyro): HTML, already escaped by the caller (it may hold `<code>`); none when `None`.
    pub sub: Option<String>,
    /// Rules appended to [`STYLESHEET`] for this document only (the certificate's `@page`
    /// header carrying the report id): CSS, not escaped.
    pub extra_css: String,
}

impl<'a> Page<'a> {
    /// A page with its title and heading, no `.sub` line and no extra CSS.
    pub fn new(title: &'a str, heading: &'a str) -> Self {
        Page {
            title,
            heading,
            sub: None,
            extra_css: String::new(),
        }
    }

    /// The `.sub` line (HTML, escaped by the caller).
    #[must_use]
    pub fn with_sub(mut self, html: String) -> Self {
        self.sub = Some(html);
        self
    }

    /// Extra CSS for this document only.
    #[must_use]
    pub fn with_css(mut self, css: String) -> Self {
        self.extra_css = css;
        self
    }

    /// Writes the document head and the header block: `<!DOCTYPE html>`, the head with the
    /// title and the stylesheet, `<body>`, the `<h1>` and the `.sub` line.
    pub fn open(&self, out: &mut String) {
        out.push_str("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n");
        let _ = write!(
            out,
            "<title>{}</title>\n<style>{STYLESHEET}{}</style>\n</head>\n<body>\n<h1>{}</h1>\n",
            esc(self.title),
            self.extra_css,
            esc(self.heading)
        );
        if let Some(sub) = &self.sub {
            let _ = writeln!(out, "<p class=\"sub\">{sub}</p>");
        }
    }

    /// Writes the footer (`footer`: HTML, escaped by the caller, such as "made by" or the
    /// deviation unit; none when `None`) and closes the document.
    pub fn close(out: &mut String, footer: Option<&str>) {
        if let Some(f) = footer {
            let _ = writeln!(out, "<footer class=\"note\">{f}</footer>");
        }
        out.push_str("</body>\n</html>\n");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn escapes_markup_and_both_quotes() {
        assert_eq!(
            esc(r#"<a href="x">Tom's & co</a>"#),
            "&lt;a href=&quot;x&quot;&gt;Tom&#39;s &amp; co&lt;/a&gt;"
        );
    }

    #[test]
    fn the_skeleton_escapes_title_and_heading_and_closes_the_document() {
        let mut html = String::new();
        Page::new("SIMULATED · <run>", "Report & co")
            .with_sub("<code>runs/r1</code>".into())
            .with_css("@page { size: A4; }".into())
            .open(&mut html);
        Page::close(&mut html, Some("made by gyrocal"));
        assert!(html.starts_with("<!DOCTYPE html>\n<html lang=\"en\">"));
        assert!(html.contains("<title>SIMULATED · &lt;run&gt;</title>"));
        assert!(html.contains("<h1>Report &amp; co</h1>"));
        assert!(html.contains("<p class=\"sub\"><code>runs/r1</code></p>"));
        assert!(html.contains("@page { size: A4; }</style>"));
        assert_eq!(html.matches("<style>").count(), 1, "one stylesheet");
        assert!(
            html.ends_with("<footer class=\"note\">made by gyrocal</footer>\n</body>\n</html>\n")
        );
    }
}
