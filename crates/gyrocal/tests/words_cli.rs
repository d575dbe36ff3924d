//! Numbers and words as a person reads them (issue 25, item 7): every value with an
//! uncertainty printed one way (`gyrocal_fit::display::value_pm_u`: U to two significant
//! digits, the value to one decimal beyond, never `3.6119660e-1`), quantities named in words
//! with their units (no `scale_factor`, `bias_v`, `k_pos` on the terminal), one spelling of a
//! unit (`°/√h`, not `deg/sqrt(h)`), and `gyrocal fit --json` of one shape for one file or
//! several. Through the binary, on a full simulated run with acceptance limits (the run's
//! ending, `fit`, the report), a short drift record (`allan` and its page) and `history`.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test helpers: a panic is a failed test

mod common;

use std::path::{Path, PathBuf};

use common::{config, gyrocal, gyrocal_with_data_home};

/// The code keys of the files and JSON: never on a person's screen.
const CODE_KEYS: [&str; 9] = [
    "scale_factor",
    "bias_v",
    "bias_dph",
    "k_pos",
    "k_neg",
    "nonlinearity_ppm",
    "asymmetry_ppm",
    "asymmetry_gjb_ppm",
    "repeatability_ppm",
];

/// The paper's plan with guarded acceptance limits that the simulated gyro fails on some
/// quantities, cannot be judged on one (the repeatability of a single pass) and passes on
/// others: every kind of verdict line.
fn plan_with_limits(dir: &Path) -> PathBuf {
    let text = std::fs::read_to_string(config("paper.toml")).unwrap()
        + "\n[acceptance]\ndecision_rule = \"guarded\"\n\
           [acceptance.scale_factor]\nmin = 0.3\nmax = 0.4\n\
           [acceptance.bias_dph]\nmin = -36\nmax = 36\n\
           [acceptance.nonlinearity_ppm]\nmax = 300\n\
           [acceptance.asymmetry_gjb_ppm]\nmax = 3000\n\
           [acceptance.repeatability_ppm]\nmax = 100\n\
           [acceptance.k2]\nmax = 1e-5\n";
    let path = dir.join("limited.toml");
    std::fs::write(&path, text).unwrap();
    path
}

/// configs/drift.toml, three segments of 2000 readings (enough for noise terms).
fn short_drift(dir: &Path) -> PathBuf {
    let text = std::fs::read_to_string(config("drift.toml"))
        .unwrap()
        .replace("samples_per_rate = 3000", "samples_per_rate = 2000")
        .replace("repeat = 167", "repeat = 3");
    let path = dir.join("drift.toml");
    std::fs::write(&path, text).unwrap();
    path
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// A number as the rule writes it: optional sign, digits, optional decimals; its count of
/// decimals. `None` for anything else (a word, `1σ`, `3.6e-1`).
fn decimals(token: &str) -> Option<usize> {
    let t = token.strip_prefix('-').unwrap_or(token);
    let (int, frac) = t.split_once('.').unwrap_or((t, ""));
    let digits = |s: &str| s.chars().all(|c| c.is_ascii_digit());
    (!int.is_empty() && digits(int) && digits(frac)).then_some(frac.len())
}

/// A whole token written in e-notation (`3.6e-1`, `-2E5`), not one that merely holds `…1e4`
/// (a run id such as `3bbac4b781e4`).
fn scientific(token: &str) -> bool {
    let t = token.trim_start_matches(['+', '-']);
    let Some((mantissa, exponent)) = t.split_once(['e', 'E']) else {
        return false;
    };
    let exponent = exponent.trim_start_matches(['+', '-']);
    decimals(mantissa).is_some()
        && !exponent.is_empty()
        && exponent.chars().all(|c| c.is_ascii_digit())
}

/// Every `A ± B` of `out` whose A is a number is in the one form: B a plain number of at
/// most two significant digits, A to one decimal beyond B (or both whole), no exponent
/// (`e-5`); a power of ten only as `(A ± B) × 10ⁿ`. Returns how many were checked.
fn assert_one_form(what: &str, out: &str) -> usize {
    let mut checked = 0;
    for line in out.lines() {
        if line.contains('±') {
            assert!(
                !line
                    .split(|c: char| !(c.is_ascii_alphanumeric() || "._+-".contains(c)))
                    .any(scientific),
                "{what}: scientific notation in a value ± U line: {line:?}"
            );
        }
        let mut rest = line;
        while let Some(i) = rest.find(" ± ") {
            let before = rest[..i].rsplit([' ', '>', '=']).next().unwrap_or("");
            let after = &rest[i + " ± ".len()..];
            rest = after;
            let a = before.trim_start_matches('(');
            let Some(da) = decimals(a) else { continue };
            let b_token = after
                .split([' ', '<', ','])
                .next()
                .unwrap_or("")
                .trim_end_matches(')');
            let db = decimals(b_token).unwrap_or_else(|| {
                panic!("{what}: {a} ± {b_token:?} is not a plain number: {line:?}")
            });
            if before.starts_with('(') {
                assert!(
                    after.contains(") × 10"),
                    "{what}: a bracketed value ± U without its power of ten: {line:?}"
                );
            }
            let significant = b_token
                .trim_start_matches(['0', '.'])
                .trim_end_matches('0')
                .replace('.', "");
            assert!(
                significant.len() <= 2,
                "{what}: U {b_token} has more than two significant digits: {line:?}"
            );
            assert!(
                da == db + 1 || (db == 0 && da <= 1),
                "{what}: {a} ± {b_token}: the value is not to one decimal beyond U: {line:?}"
            );
            checked += 1;
        }
    }
    checked
}

fn assert_no_code_keys(what: &str, out: &str) {
    for line in out.lines() {
        // a path or file name may contain anything; the words around it may not
        if line.starts_with("report: ") || line.starts_with("run directory: ") {
            continue;
        }
        for key in CODE_KEYS {
            assert!(
                !line.contains(key),
                "{what}: the code key {key} on a person's screen: {line:?}"
            );
        }
    }
}

/// The text of an HTML page without its markup (tags, scripts and styles out), with the
/// entities people write in these pages decoded.
fn page_text(html: &str) -> String {
    let mut out = String::new();
    let mut in_tag = false;
    for c in html.chars() {
        match c {
            '<' => {
                in_tag = true;
                out.push(' ');
            }
            '>' => in_tag = false,
            c if !in_tag => out.push(c),
            _ => {}
        }
    }
    out.replace("&amp;", "&")
        .replace("&lt;", "<")
        .replace("&gt;", ">")
}

#[test]
fn a_full_run_fit_allan_and_history_print_every_value_with_its_u_one_way() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    let run = tmp.path().join("run");
    let plan = plan_with_limits(tmp.path());
    let o = gyrocal_with_data_home(&data)
        .args(["run", "--simulate", "--dut-serial", "WORDS-1", "--out"])
        .arg(&run)
        .arg(&plan)
        .output()
        .unwrap();
    let ending = text(&o.stdout) + &text(&o.stderr);
    assert_eq!(o.status.code(), Some(0), "{ending}");

    // the run's ending: the verdict lines in words, each with its value ± U
    let verdicts = ending
        .lines()
        .skip_while(|l| !l.starts_with("verdict: "))
        .take_while(|l| !l.trim().is_empty())
        .collect::<Vec<_>>();
    assert!(verdicts.len() >= 7, "{ending}");
    assert!(verdicts[0].contains("FAIL"), "{}", verdicts[0]);
    let nonlinearity = verdicts
        .iter()
        .find(|l| l.trim_start().starts_with("nonlinearity "))
        .unwrap_or_else(|| panic!("no nonlinearity verdict: {verdicts:?}"));
    assert!(
        nonlinearity.contains(" ± ") && nonlinearity.contains("lies wholly above max 300 ppm"),
        "{nonlinearity}"
    );
    let k2 = verdicts
        .iter()
        .find(|l| l.trim_start().starts_with("second-order coefficient K2"))
        .unwrap();
    assert!(k2.contains("× 10⁻⁵ V/(°/s)²"), "K2 with its unit: {k2}");
    assert!(!ending.contains("not measured: not measured"), "{ending}");
    assert!(
        ending.contains("repeatability") && ending.contains("INDETERMINATE"),
        "{ending}"
    );
    assert_no_code_keys("the run's ending", &ending);
    let n = assert_one_form("the run's ending", &ending);
    assert!(n >= 20, "only {n} values ± U checked in {ending}");

    // the same quantity with the same decimals: the nonlinearity of the metrics is the value
    // of its value ± U
    let metric = ending
        .lines()
        .find(|l| l.starts_with("  nonlinearity ") && l.contains("ppm of F_m"))
        .unwrap();
    let value = metric.split_whitespace().nth(1).unwrap();
    assert!(
        nonlinearity.contains(&format!("{value} ± ")),
        "{value} in the metrics, {nonlinearity} in the verdict"
    );

    // gyrocal fit on the run directory: the same words and the same form
    let o = gyrocal().arg("fit").arg(&run).output().unwrap();
    let fit = text(&o.stdout);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o.stderr));
    assert_no_code_keys("gyrocal fit", &fit);
    assert!(
        assert_one_form("gyrocal fit", &fit) >= 12,
        "too few values ± U in {fit}"
    );
    assert!(fit.contains("K2 in V/(°/s)²"), "the fits' heading: {fit}");

    // the report: every value ± U in the same form, budget headings in words
    let html = std::fs::read_to_string(run.join("report.html")).unwrap();
    let page = page_text(&html);
    assert!(assert_one_form("report.html", &page) >= 5);
    for caption in html.split("<caption>").skip(1) {
        let caption = &caption[..caption.find("</caption>").unwrap()];
        for key in CODE_KEYS {
            assert!(
                !caption.starts_with(key),
                "a budget heading by its code key: {caption}"
            );
        }
    }
    assert!(
        html.contains("<caption>Scale factor K = 0.3"),
        "budget heading"
    );

    // gyrocal history: the calibration's K ± U in the same form
    let o = gyrocal_with_data_home(&data)
        .args(["history", "WORDS-1", "--include-simulated", "-o"])
        .arg(tmp.path().join("history.html"))
        .output()
        .unwrap();
    let history = text(&o.stdout);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o.stderr));
    assert!(
        assert_one_form("gyrocal history", &history) >= 2,
        "{history}"
    );
    let history_page =
        page_text(&std::fs::read_to_string(tmp.path().join("history.html")).unwrap());
    assert!(assert_one_form("history.html", &history_page) >= 2);
}

#[test]
fn allan_speaks_in_words_and_one_spelling_of_units() {
    let tmp = tempfile::tempdir().unwrap();
    let run = tmp.path().join("drift");
    let o = gyrocal()
        .args(["run", "--simulate", "--out"])
        .arg(&run)
        .arg(short_drift(tmp.path()))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", text(&o.stderr));
    let page_path = tmp.path().join("allan.html");
    let o = gyrocal()
        .arg("allan")
        .arg(&run)
        .arg("-o")
        .arg(&page_path)
        .output()
        .unwrap();
    let out = text(&o.stdout);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o.stderr));
    for (what, s) in [
        ("gyrocal allan", out.clone()),
        (
            "allan.html",
            page_text(&std::fs::read_to_string(&page_path).unwrap()),
        ),
    ] {
        assert!(!s.contains("deg/sqrt(h)"), "{what}: {s}");
        assert!(!s.contains("deg/h"), "{what}: {s}");
        for code in [
            "RateRamp",
            "Quantization:",
            "AngleRandomWalk",
            "RateRandomWalk",
        ] {
            assert!(!s.contains(code), "{what}: {code} in {s}");
        }
        assert!(assert_one_form(what, &s) >= 3, "{what}: {s}");
    }
    assert!(out.contains("°/√h"), "{out}");
}

#[test]
fn fit_json_has_one_shape_for_one_file_and_for_several() {
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/paper-shaped.csv");
    let one = gyrocal()
        .args(["fit", "--json"])
        .arg(&data)
        .output()
        .unwrap();
    assert_eq!(one.status.code(), Some(0), "{}", text(&one.stderr));
    let two = gyrocal()
        .args(["fit", "--json"])
        .arg(&data)
        .arg(&data)
        .output()
        .unwrap();
    assert_eq!(two.status.code(), Some(0), "{}", text(&two.stderr));
    let one: serde_json::Value = serde_json::from_slice(&one.stdout).unwrap();
    let two: serde_json::Value = serde_json::from_slice(&two.stdout).unwrap();
    let keys = |v: &serde_json::Value| {
        let mut k: Vec<String> = v.as_object().unwrap().keys().cloned().collect();
        k.sort();
        k
    };
    assert_eq!(keys(&one), keys(&two), "the same top-level keys");
    assert_eq!(one["files"].as_array().unwrap().len(), 1);
    assert_eq!(two["files"].as_array().unwrap().len(), 2);
    assert_eq!(
        keys(&one["files"][0]),
        keys(&two["files"][1]),
        "each file an analysis of the same shape"
    );
    assert!(one["files"][0]["metrics"]["scale_factor"].is_number());
    assert!(one["repeatability_ppm"].is_null());
    assert!(two["repeatability_ppm"].is_number());
    // the shape is documented where a script writer looks
    let help = gyrocal().args(["fit", "--help"]).output().unwrap();
    assert!(
        text(&help.stdout).contains(".files[0]"),
        "{}",
        text(&help.stdout)
    );
}

#[test]
fn check_prints_the_acceptance_limits_in_words() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = plan_with_limits(tmp.path());
    let o = gyrocal().arg("check").arg(&plan).output().unwrap();
    let out = text(&o.stdout);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o.stderr));
    let k2 = out
        .lines()
        .find(|l| l.contains("second-order coefficient K2"))
        .unwrap_or_else(|| panic!("{out}"));
    assert!(k2.contains("— to 1 × 10⁻⁵ V/(°/s)²"), "{k2}");
    assert!(
        out.lines()
            .any(|l| l.contains("bias (as a rate)") && l.contains("-36 to 36 °/h")),
        "{out}"
    );
}
