//! The report of a run directory: sections, SVG validity, numbers equal to fit.json, banner of
//! an incomplete run, errors naming the file.

// Test helpers outside #[test] functions may unwrap too: a panic is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::fs;
use std::path::{Path, PathBuf};

use gyrocal_files::rundir::{FIT_JSON, STEPS_CSV};
use gyrocal_files::{Instruments, Plan, RunDir, RunMeta, Sample, Status, StepRecord};
use gyrocal_fit::{Analysis, Options, analyze};
use gyrocal_report::{ReportError, load_input, render_many, render_steps_csv, write_run_report};

const RATES: [f64; 19] = [
    0.0, 0.1, -0.1, 0.3, -0.3, 0.7, -0.7, 1.0, -1.0, 3.0, -3.0, 7.0, -7.0, 10.0, -10.0, 15.0,
    -15.0, 20.0, -20.0,
];
const N: u64 = 50;

fn plan(name: &str) -> Plan {
    let toml = common::plans::sweep(name, &RATES, N);
    Plan::from_toml_str(&toml, Path::new("test.toml")).unwrap()
}

/// Seeded Gaussian noise (xorshift64* and Box–Muller): no dependency, same numbers every time.
struct Noise(u64);

impl Noise {
    fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let x = self.0.wrapping_mul(0x2545_F491_4F6C_DD1D);
        ((x >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }
    fn gauss(&mut self) -> f64 {
        let (u, v) = (self.uniform(), self.uniform());
        (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
    }
}

struct RunSpec<'a> {
    name: &'a str,
    steps: usize,
    status: Status,
    reason: Option<&'a str>,
    with_fit: bool,
    seed: u64,
}

impl Default for RunSpec<'_> {
    fn default() -> Self {
        Self {
            name: "paper schedule (test)",
            steps: RATES.len(),
            status: Status::Complete,
            reason: None,
            with_fit: true,
            seed: 7,
        }
    }
}

/// A run directory like the sequencer writes: D = 0.3612·ω + 0.0088 + 2e-5·ω² + noise.
fn make_run(dir: &Path, spec: &RunSpec<'_>) {
    let plan = plan(spec.name);
    let meta = RunMeta {
        gyrocal_version: "0.1.0-test".into(),
        instruments: Instruments {
            dmm: Some("HEWLETT-PACKARD,34401A,0,11-5-2 (simulated)".into()),
            table: Some("ACUTRONIC ACUTROL <sim>".into()),
        },
        simulated: true,
        virtual_time: false,
        ..RunMeta::default()
    };
    let mut rd = RunDir::create(dir, &plan, meta).unwrap();
    let mut noise = Noise(0x9E37_79B9_7F4A_7C15 ^ spec.seed);
    let k = 0.3612 * (1.0 + 2e-5 * noise.gauss());
    let schedule = rd.schedule().to_vec();
    for (i, s) in schedule.iter().take(spec.steps).enumerate() {
        let w = s.rate_dps;
        let truth = 0.0088 + k * w + 2e-5 * w * w;
        let samples: Vec<Sample> = (0..N)
            .map(|j| Sample {
                index: j,
                t_s: i as f64 * 40.0 + j as f64 * 0.04,
                volts: Some(truth + 0.002 * (1.0 + 0.02 * w.abs()) * noise.gauss()),
            })
            .collect();
        rd.append_samples(s.index, &samples).unwrap();
        let v: Vec<f64> = samples.iter().filter_map(|s| s.volts).collect();
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (v.len() - 1) as f64;
        let rate_err = 2e-5 * noise.gauss() + 1e-5 * w.signum();
        rd.append_step(StepRecord {
            step: s.index,
            pass: s.pass,
            rate_dps: w,
            rate_meas_dps: Some(w + rate_err),
            rate_meas_std_dps: Some(2e-4),
            rate_meas_min_dps: Some(w + rate_err - 5e-4),
            rate_meas_max_dps: Some(w + rate_err + 5e-4),
            rate_samples: Some(20),
            volts: mean,
            volts_std: Some(var.sqrt()),
            n: N,
            overloads: 0,
            retries: 0,
            t_start_s: i as f64 * 40.0,
            t_end_s: i as f64 * 40.0 + 2.0,
            series: None,
        })
        .unwrap();
    }
    if spec.with_fit {
        let run = gyrocal_files::load(dir).unwrap();
        let data =
            gyrocal_analysis::sweep::dataset_from_steps(&run.steps, &dir.display().to_string());
        let a = analyze(&data, &Options::default()).unwrap();
        rd.set_fit(a.clone()).unwrap();
    }
    rd.finish(
        spec.status,
        spec.reason.map(str::to_string),
        spec.steps as f64 * 40.0,
    )
    .unwrap();
}

/// With `GYROCAL_REPORT_KEEP=DIR`, copies a test's report files to `DIR/NAME` to look at them
/// (e.g. in a browser); otherwise does nothing.
fn keep(dir: &Path, name: &str) {
    let Some(base) = std::env::var_os("GYROCAL_REPORT_KEEP") else {
        return;
    };
    let out = Path::new(&base).join(name);
    fs::create_dir_all(&out).unwrap();
    for e in fs::read_dir(dir).unwrap() {
        let e = e.unwrap();
        if e.path().is_file() {
            fs::copy(e.path(), out.join(e.file_name())).unwrap();
        }
    }
}

fn complete_run() -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    make_run(&dir, &RunSpec::default());
    (tmp, dir)
}

/// The text of the element with `id="..."` (up to the next `<`).
fn cell(html: &str, id: &str) -> Option<String> {
    let pat = format!("id=\"{id}\">");
    let start = html.find(&pat)? + pat.len();
    let end = html[start..].find('<')? + start;
    Some(html[start..end].to_string())
}

/// Half a unit in the last printed digit of `text` (fixed or exponent notation).
fn half_ulp(text: &str) -> f64 {
    let (mantissa, exp) = match text.split_once('e') {
        Some((m, e)) => (m, e.parse::<i32>().unwrap()),
        None => (text, 0),
    };
    let decimals = mantissa.split_once('.').map_or(0, |(_, d)| d.len()) as i32;
    0.5 * 10f64.powi(exp - decimals)
}

fn assert_printed(html: &str, id: &str, value: f64) {
    let text = cell(html, id).unwrap_or_else(|| panic!("no cell {id}"));
    let printed: f64 = text
        .trim()
        .parse()
        .unwrap_or_else(|e| panic!("cell {id} = {text:?}: {e}"));
    let tol = half_ulp(text.trim()) * (1.0 + 1e-9);
    assert!(
        (printed - value).abs() <= tol,
        "{id}: printed {text}, fit.json {value} (tolerance {tol})"
    );
}

const SECTIONS: [&str; 9] = [
    "summary",
    "fit",
    "residuals",
    "residual-table",
    "estimators",
    "training",
    "surface",
    "noise",
    "metadata",
];

const PLOTS: [(&str, &[&str]); 6] = [
    ("fit.svg", &["input rate ω (°/s)", "gyro output D (V)"]),
    (
        "residuals.svg",
        &[
            "input rate ω (°/s)",
            "residual (mV)",
            "residual / K (m°/s equivalent)",
        ],
    ),
    (
        "training.svg",
        &["training pass", "sum of squared residuals (V²)"],
    ),
    (
        "surface.svg",
        &["scale factor K (V/(°/s))", "bias K0 (V)", "SSE (V²), from"],
    ),
    (
        "noise.svg",
        &["input rate ω (°/s)", "std of the readings (mV)"],
    ),
    (
        "rate-error.svg",
        &["demanded rate ω (°/s)", "rate error (µ°/s)"],
    ),
];

#[test]
fn run_report_has_every_section_and_plot() {
    let (_tmp, dir) = complete_run();
    let path = write_run_report(&dir).unwrap();
    assert_eq!(path, dir.join("report.html"));
    let html = fs::read_to_string(&path).unwrap();
    for s in SECTIONS {
        assert!(html.contains(&format!("id=\"{s}\"")), "section {s} missing");
    }
    for (file, _) in PLOTS {
        let stem = file.trim_end_matches(".svg");
        assert!(
            html.contains(&format!("id=\"fig-{stem}\"")),
            "figure {stem} missing"
        );
        assert!(dir.join(file).is_file(), "{file} not written");
    }
    assert!(
        !html.contains("class=\"banner\""),
        "a complete run has no banner"
    );
    // Self-contained: no script, no external resource.
    assert!(!html.contains("<script"));
    assert!(!html.contains("src="));
    assert!(!html.contains("href="));
    assert!(!html.contains("@import"));
    let without_ns = html.replace("http://www.w3.org/2000/svg", "");
    assert!(!without_ns.contains("http://") && !without_ns.contains("https://"));
    // Metadata from the manifest, escaped.
    assert!(html.contains("paper schedule (test)"));
    assert!(html.contains("ACUTRONIC ACUTROL &lt;sim&gt;"));
    assert!(html.contains("0.1.0-test"));
    let manifest = gyrocal_files::load(&dir).unwrap().manifest;
    assert!(html.contains(&manifest.plan_hash));
    // The paper's table: one row per rate.
    let table_start = html.find("class=\"residuals\"").unwrap();
    let table = &html[table_start..table_start + html[table_start..].find("</table>").unwrap()];
    assert_eq!(table.matches("<tr>").count(), 1 + RATES.len());
    keep(&dir, "complete");
}

#[test]
fn every_svg_parses_and_has_its_axis_labels() {
    let (_tmp, dir) = complete_run();
    write_run_report(&dir).unwrap();
    let html = fs::read_to_string(dir.join("report.html")).unwrap();
    for (file, labels) in PLOTS {
        let text = fs::read_to_string(dir.join(file)).unwrap();
        let doc =
            roxmltree::Document::parse(&text).unwrap_or_else(|e| panic!("{file} is not XML: {e}"));
        assert_eq!(doc.root_element().tag_name().name(), "svg");
        let texts: Vec<String> = doc
            .descendants()
            .filter(|n| n.has_tag_name("text"))
            .map(|n| n.text().unwrap_or_default().trim().to_string())
            .collect();
        for label in labels {
            assert!(
                texts.iter().any(|t| t == label),
                "{file}: no axis label {label:?} in {texts:?}"
            );
        }
        // The same SVG is inlined in the HTML.
        let body = text.trim_start_matches("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n");
        assert!(html.contains(body), "{file} is not inlined verbatim");
    }
}

#[test]
fn summary_numbers_equal_fit_json() {
    let (_tmp, dir) = complete_run();
    write_run_report(&dir).unwrap();
    let html = fs::read_to_string(dir.join("report.html")).unwrap();
    let a: Analysis = serde_json::from_slice(&fs::read(dir.join(FIT_JSON)).unwrap()).unwrap();
    let m = &a.metrics;
    let ls = a
        .fit(
            gyrocal_fit::Method::LeastSquares,
            gyrocal_fit::Model::Linear,
        )
        .unwrap();
    assert_printed(&html, "sum-k", m.scale_factor);
    assert_printed(&html, "sum-k-se", ls.std_errors.k1.unwrap());
    assert_printed(&html, "sum-k0", m.bias_volts);
    assert_printed(&html, "sum-k0-se", ls.std_errors.k0.unwrap());
    assert_printed(&html, "sum-nonlinearity", m.nonlinearity_ppm);
    assert_printed(&html, "sum-asymmetry", m.asymmetry_ppm.unwrap());
    assert_printed(&html, "sum-k-pos", m.scale_factor_positive.unwrap());
    assert_printed(&html, "sum-k-neg", m.scale_factor_negative.unwrap());
    assert_printed(&html, "sum-bias-dps", m.bias_dps);
    assert_printed(&html, "sum-bias-dph", m.bias_dph);
    assert_eq!(cell(&html, "sum-repeatability").unwrap(), "—");
    assert_eq!(
        cell(&html, "sum-best-model").unwrap(),
        a.best_model.unwrap().to_string()
    );
    // The data's bowl is found: the quadratic model is the best one.
    assert_eq!(a.best_model, Some(gyrocal_fit::Model::Quadratic));
    assert!((m.scale_factor - 0.3612).abs() < 1e-3);
    assert!(html.contains(&format!(
        "read from <code>{}</code>",
        dir.join(FIT_JSON).display()
    )));
}

#[test]
fn verdict_never_calls_the_neuron_better() {
    let (_tmp, dir) = complete_run();
    write_run_report(&dir).unwrap();
    let html = fs::read_to_string(dir.join("report.html")).unwrap();
    let verdict = cell(&html, "verdict").unwrap();
    assert!(
        verdict.contains("not better, only equal") || verdict.starts_with("The neuron's SSE is "),
        "{verdict}"
    );
    assert!(!html.to_lowercase().contains("neuron is better"));
}

#[test]
fn incomplete_run_shows_the_banner_with_the_reason() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    make_run(
        &dir,
        &RunSpec {
            steps: 7,
            status: Status::Failed,
            reason: Some("table <fault> & timeout"),
            with_fit: false,
            ..RunSpec::default()
        },
    );
    write_run_report(&dir).unwrap();
    let html = fs::read_to_string(dir.join("report.html")).unwrap();
    let banner_at = html.find("class=\"banner\"").expect("banner");
    assert!(
        banner_at < html.find("id=\"summary\"").unwrap(),
        "banner before the numbers"
    );
    let banner = cell(&html, "banner").unwrap();
    assert!(banner.contains("INCOMPLETE RUN: status failed"), "{banner}");
    assert!(html.contains("table &lt;fault&gt; &amp; timeout"));
    assert!(banner.contains("7 of 19 steps done"), "{banner}");
    // No fit.json: the report fits the finished steps itself.
    assert!(html.contains("computed by the report"));
    assert!(html.contains("id=\"fig-fit\""));
    keep(&dir, "incomplete");
}

#[test]
fn run_with_one_step_still_reports_why_there_is_no_fit() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    make_run(
        &dir,
        &RunSpec {
            steps: 1,
            status: Status::Aborted,
            reason: Some("operator stop"),
            with_fit: false,
            ..RunSpec::default()
        },
    );
    write_run_report(&dir).unwrap();
    let html = fs::read_to_string(dir.join("report.html")).unwrap();
    assert!(html.contains("INCOMPLETE RUN: status aborted: operator stop"));
    assert!(html.contains("No fit: "));
    assert!(html.contains("id=\"metadata\""));
}

#[test]
fn strings_from_files_are_escaped() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    make_run(
        &dir,
        &RunSpec {
            name: "HRG <script>alert(1)</script> & co",
            ..RunSpec::default()
        },
    );
    write_run_report(&dir).unwrap();
    let html = fs::read_to_string(dir.join("report.html")).unwrap();
    assert!(!html.contains("<script"));
    assert!(html.contains("HRG &lt;script&gt;alert(1)&lt;/script&gt; &amp; co"));
}

#[test]
fn bare_steps_csv_gives_a_report_without_run_metadata() {
    let (_tmp, dir) = complete_run();
    let report = render_steps_csv(&dir.join(STEPS_CSV)).unwrap();
    assert!(report.html.contains("none: a bare CSV data set"));
    let names: Vec<&str> = report.svgs.iter().map(|s| s.0.as_str()).collect();
    assert_eq!(
        names,
        [
            "fit.svg",
            "residuals.svg",
            "training.svg",
            "surface.svg",
            "noise.svg",
            "rate-error.svg"
        ]
    );
}

#[test]
fn several_runs_give_the_repeatability() {
    let tmp = tempfile::tempdir().unwrap();
    let dirs: Vec<PathBuf> = (0..3)
        .map(|i| {
            let d = tmp.path().join(format!("run{i}"));
            make_run(
                &d,
                &RunSpec {
                    seed: 100 + i,
                    ..RunSpec::default()
                },
            );
            d
        })
        .collect();
    let report = render_many(&dirs).unwrap();
    report.write(&tmp.path().join("report.html")).unwrap();
    keep(tmp.path(), "several");
    assert!(report.html.contains("id=\"repeatability\""));
    let ks: Vec<f64> = dirs
        .iter()
        .map(|d| {
            let a: Analysis = serde_json::from_slice(&fs::read(d.join(FIT_JSON)).unwrap()).unwrap();
            a.metrics.scale_factor
        })
        .collect();
    let kr = gyrocal_fit::repeatability_ppm(&ks).unwrap();
    assert_printed(&report.html, "sum-repeatability", kr);
    assert!(report.svgs.iter().any(|s| s.0 == "repeatability.svg"));
    assert!(report.svgs.iter().any(|s| s.0 == "run3-fit.svg"));
    roxmltree::Document::parse(
        &report
            .svgs
            .iter()
            .find(|s| s.0 == "repeatability.svg")
            .unwrap()
            .1,
    )
    .unwrap();
}

#[test]
fn missing_manifest_is_an_error_naming_the_file() {
    let (_tmp, dir) = complete_run();
    fs::remove_file(dir.join("manifest.json")).unwrap();
    let err = write_run_report(&dir).unwrap_err();
    assert!(err.is_input_error());
    assert!(err.to_string().contains("manifest.json"), "{err}");
}

#[test]
fn missing_path_is_an_error_naming_it() {
    let err = load_input(Path::new("/nonexistent/run-42")).unwrap_err();
    assert!(matches!(err, ReportError::NotFound { .. }));
    assert!(err.to_string().contains("/nonexistent/run-42"), "{err}");
}

#[test]
fn malformed_steps_csv_is_an_error_naming_the_file_and_line() {
    let (_tmp, dir) = complete_run();
    // In a run directory.
    let steps = dir.join(STEPS_CSV);
    let text = fs::read_to_string(&steps).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let volts = lines[0].split(',').position(|c| c == "volts").unwrap();
    let mut fields: Vec<&str> = lines[1].split(',').collect();
    fields[volts] = "1.2.3";
    lines[1] = fields.join(",");
    fs::write(&steps, lines.join("\n") + "\n").unwrap();
    let err = write_run_report(&dir).unwrap_err();
    assert!(err.is_input_error());
    let msg = err.to_string();
    // (gyrocal-run reports the record's line inside its message.)
    assert!(
        msg.contains("steps.csv") && (msg.contains(":2:") || msg.contains("line: 2")),
        "{msg}"
    );
    // As a bare CSV.
    let err = render_steps_csv(&steps).unwrap_err();
    let msg = err.to_string();
    assert!(msg.contains("steps.csv") && msg.contains("line 2"), "{msg}");
    // A malformed fit.json.
    let (_tmp2, dir2) = complete_run();
    fs::write(dir2.join(FIT_JSON), "{\"points\": 3").unwrap();
    let err = write_run_report(&dir2).unwrap_err();
    assert!(err.to_string().contains("fit.json"), "{err}");
}

/// A single run's report is a certificate: a report id on the first page, in the print
/// margins beside "page x of y" and in the end-of-report mark; the test conditions; the
/// statement and the signature lines. The same run gives the same id.
#[test]
fn a_run_report_is_a_certificate_with_an_id_on_every_page_and_an_end() {
    let (_tmp, dir) = complete_run();
    let html = fs::read_to_string(write_run_report(&dir).unwrap()).unwrap();
    let id = cell(&html, "report-id").expect("report id");
    let id = id.trim_start_matches("<strong id=\"report-id\">");
    let start = html.find("id=\"report-id\">").unwrap() + "id=\"report-id\">".len();
    let id_text = &html[start..start + html[start..].find('<').unwrap()];
    assert!(id.contains(id_text));
    assert!(
        id_text.len() == 15
            && id_text.starts_with("GC-")
            && id_text[3..].chars().all(|c| c.is_ascii_hexdigit()),
        "report id {id_text}"
    );
    assert!(html.contains(&format!(
        "@top-left {{ content: \"Calibration report {id_text}\""
    )));
    assert!(html.contains("counter(page) \" of \" counter(pages)"));
    assert!(html.contains(&format!("End of report {id_text}")));
    assert!(html.find("id=\"end-of-report\"").unwrap() > html.find("id=\"metadata\"").unwrap());
    assert!(html.contains("The results relate only to the item calibrated"));
    assert!(html.contains("Prepared by") && html.contains("Approved by"));
    // the test conditions: every plan setting that affects the measurement
    let conditions = &html[html.find("id=\"conditions-table\"").unwrap()..];
    let conditions = &conditions[..conditions.find("</table>").unwrap()];
    for needle in [
        "NPLC",
        "V range",
        "autozero",
        "acceleration",
        "Readings per rate",
        "Settle",
    ] {
        assert!(
            conditions.contains(needle),
            "conditions lack {needle}: {conditions}"
        );
    }
    // the same run, the same id
    let again = fs::read_to_string(write_run_report(&dir).unwrap()).unwrap();
    assert!(again.contains(&format!("End of report {id_text}")));
}

/// The report is on the shared page: the one stylesheet (the page module's, once, with the
/// certificate's `@page` header after it), its title and heading, and the document closed.
#[test]
fn report_is_on_the_shared_page_with_one_stylesheet() {
    let (_tmp, dir) = complete_run();
    let html = fs::read_to_string(write_run_report(&dir).unwrap()).unwrap();
    assert!(html.starts_with("<!DOCTYPE html>"));
    assert_eq!(html.matches("<style>").count(), 1, "one stylesheet");
    assert!(html.contains(gyrocal_report::page::STYLESHEET));
    let style = &html[html.find("<style>").unwrap()..html.find("</style>").unwrap()];
    assert!(style.contains("@page"), "the certificate's page header");
    assert!(html.contains("<h1>Gyro scale-factor calibration report</h1>"));
    assert!(html.ends_with("</body>\n</html>\n"));
}

/// A run directory of `toml`'s plan without steps or fit (enough to compare plans).
fn bare_run(dir: &Path, toml: &str) {
    let plan = Plan::from_toml_str(toml, Path::new("test.toml")).unwrap();
    let mut rd = RunDir::create(dir, &plan, RunMeta::default()).unwrap();
    rd.finish(Status::Aborted, Some("stopped at once".into()), 1.0)
        .unwrap();
}

#[test]
fn a_different_simulation_seed_is_not_a_different_plan() {
    let tmp = tempfile::tempdir().unwrap();
    let base = common::plans::sweep("seeds", &RATES, N);
    let (a, b, c) = (
        tmp.path().join("a"),
        tmp.path().join("b"),
        tmp.path().join("c"),
    );
    bare_run(&a, &format!("{base}\n[simulation]\nseed = 1\n"));
    bare_run(&b, &format!("{base}\n[simulation]\nseed = 2\n"));
    // the plan hashes differ ([simulation] is hashed), the method does not
    let ha = gyrocal_files::load(&a).unwrap().manifest.plan_hash;
    let hb = gyrocal_files::load(&b).unwrap().manifest.plan_hash;
    assert_ne!(ha, hb);
    let same = render_many(&[a.clone(), b]).unwrap();
    assert!(
        !same.warnings.iter().any(|w| w.contains("different plans")),
        "{:?}",
        same.warnings
    );
    // another rate list is another plan
    bare_run(&c, &common::plans::sweep("seeds", &RATES[..5], N));
    let mixed = render_many(&[a, c]).unwrap();
    assert!(
        mixed.warnings.iter().any(|w| w.contains("different plans")),
        "{:?}",
        mixed.warnings
    );
}
