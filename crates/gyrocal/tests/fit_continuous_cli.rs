//! `gyrocal fit` on continuous-rate data (issue 24): a bounded `--json` document with rate-bin
//! summaries, `--residuals` for every point, and a human report that says what its rows are.

// Helpers outside #[test] functions may unwrap too: a panic there is a failed test.
#![allow(clippy::unwrap_used)]

mod common;

use common::gyrocal_output as gyrocal;

/// A CSV of `n` points with rates spread over ±20 °/s, written with 6 decimals as a table's
/// measured rate would be (nearly all distinct), and the (rate, volts) pairs as written.
fn continuous_csv(dir: &tempfile::TempDir, name: &str, n: usize) -> (String, Vec<(f64, f64)>) {
    let mut text = String::with_capacity(n * 24 + 16);
    text.push_str("rate_dps,volts\n");
    let mut pairs = Vec::with_capacity(n);
    for i in 0..n {
        let w = -20.0 + 40.0 * ((i as f64 * 0.754_877_666_2).fract());
        let noise = 1e-3 * ((i as f64 * 0.618_033_988_7).fract() - 0.5);
        let d = 0.0088 + 0.3612 * w + 2e-6 * w * w + noise;
        let line = format!("{w:.6},{d:.7}\n");
        let (a, b) = line.trim_end().split_once(',').unwrap();
        pairs.push((a.parse().unwrap(), b.parse().unwrap()));
        text.push_str(&line);
    }
    let path = dir.path().join(name);
    std::fs::write(&path, text).unwrap();
    (path.to_str().unwrap().to_string(), pairs)
}

/// Largest `--json` document accepted for continuous data, whatever the number of points:
/// five fits × 200 bins of summaries, the error surface and the neuron's pass errors.
const JSON_BYTES_MAX: usize = 1_000_000;

#[test]
fn json_on_200000_continuous_points_is_bounded_with_rate_bins_and_exact_figures() {
    let tmp = tempfile::tempdir().unwrap();
    let (path, pairs) = continuous_csv(&tmp, "continuous.csv", 200_000);
    let out = gyrocal(&["fit", "--json", &path]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        out.stdout.len() < JSON_BYTES_MAX,
        "{} bytes of JSON",
        out.stdout.len()
    );
    // one file: the first of `files` (fit --json has one shape for any number of files)
    let v = serde_json::from_slice::<serde_json::Value>(&out.stdout).unwrap()["files"][0].take();
    assert_eq!(v["points"], 200_000);
    assert!(v["distinct_rates"].as_u64().unwrap() > 190_000);
    assert_eq!(v["residual_detail"], "per-rate-bin");
    assert_eq!(v["rate_bins"]["bins"], 200);
    for f in v["fits"].as_array().unwrap() {
        assert_eq!(f["residuals"].as_array().unwrap().len(), 0);
        let rr = f["rate_residuals"].as_array().unwrap();
        assert!(!rr.is_empty() && rr.len() <= 200, "{}", rr.len());
        assert_eq!(
            rr.iter().map(|r| r["n"].as_u64().unwrap()).sum::<u64>(),
            200_000
        );
    }
    // The line and its SSE are those of every point (centred sums, computed here).
    let n = pairs.len() as f64;
    let mw = pairs.iter().map(|p| p.0).sum::<f64>() / n;
    let md = pairs.iter().map(|p| p.1).sum::<f64>() / n;
    let sxx: f64 = pairs.iter().map(|p| (p.0 - mw).powi(2)).sum();
    let sxy: f64 = pairs.iter().map(|p| (p.0 - mw) * (p.1 - md)).sum();
    let k = sxy / sxx;
    let k0 = md - k * mw;
    let sse: f64 = pairs.iter().map(|p| (p.1 - k0 - k * p.0).powi(2)).sum();
    let ls = &v["fits"][0];
    assert_eq!(ls["model"], "linear");
    let rel = |a: f64, b: f64| (a - b).abs() / b.abs();
    assert!(rel(ls["scale_factor"].as_f64().unwrap(), k) < 1e-12);
    assert!(rel(ls["bias"].as_f64().unwrap(), k0) < 1e-9);
    assert!(rel(ls["sse"].as_f64().unwrap(), sse) < 1e-9);
    let nn = &v["fits"][4];
    assert_eq!(nn["neuron"]["training_data"]["kind"], "rate-bins");
    assert!(rel(nn["sse"].as_f64().unwrap(), sse) < 1e-9);
}

#[test]
fn residuals_gives_every_point_of_every_fit_in_file_order() {
    let tmp = tempfile::tempdir().unwrap();
    let (path, pairs) = continuous_csv(&tmp, "continuous.csv", 30_000);
    let out = gyrocal(&["fit", "--json", "--residuals", &path]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // one file: the first of `files` (fit --json has one shape for any number of files)
    let v = serde_json::from_slice::<serde_json::Value>(&out.stdout).unwrap()["files"][0].take();
    assert_eq!(v["residual_detail"], "per-point");
    for f in v["fits"].as_array().unwrap() {
        assert!(f.get("rate_residuals").is_none());
        let r = f["residuals"].as_array().unwrap();
        assert_eq!(r.len(), 30_000);
        // (serde_json's default float parsing may be one unit in the last place off)
        let same = |a: f64, b: f64| (a - b).abs() <= 1e-15 * a.abs().max(b.abs()).max(1e-3);
        for i in [0, 1, 12_345, 29_999] {
            assert!(same(r[i]["rate_dps"].as_f64().unwrap(), pairs[i].0));
            assert!(same(r[i]["volts"].as_f64().unwrap(), pairs[i].1));
            let fitted = r[i]["fitted"].as_f64().unwrap();
            let residual = r[i]["residual"].as_f64().unwrap();
            assert!(
                (residual - (pairs[i].1 - fitted)).abs() <= 1e-14,
                "{}",
                r[i]
            );
        }
        // The figures are the same as without --residuals.
        let sse: f64 = r
            .iter()
            .map(|x| x["residual"].as_f64().unwrap().powi(2))
            .sum();
        let want = f["sse"].as_f64().unwrap();
        assert!((sse - want).abs() <= 1e-12 * want, "{sse} vs {want}");
    }

    // Two files: each file's fits carry their own points.
    let (other, _) = continuous_csv(&tmp, "other.csv", 12_000);
    let out = gyrocal(&["fit", "--json", "--residuals", &path, &other]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let files = v["files"].as_array().unwrap();
    assert_eq!(
        files[0]["fits"][0]["residuals"].as_array().unwrap().len(),
        30_000
    );
    assert_eq!(
        files[1]["fits"][0]["residuals"].as_array().unwrap().len(),
        12_000
    );
    assert!(v["repeatability_ppm"].as_f64().is_some());
}

#[test]
fn the_human_report_has_one_row_per_rate_bin_and_says_so() {
    let tmp = tempfile::tempdir().unwrap();
    let (path, _) = continuous_csv(&tmp, "continuous.csv", 20_000);
    let out = gyrocal(&["fit", &path]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains(
            "continuous rates (20000 distinct, more than 200): one row per rate bin, 200 bins"
        ),
        "{text}"
    );
    assert!(
        text.contains("online passes on the means of 200 rate bins"),
        "{text}"
    );
    assert!(text.lines().count() < 300, "{}", text.lines().count());
    // A bin's row: its mean rate to 4 decimals, its point count, its mean output.
    let row = text
        .lines()
        .find(|l| l.trim_start().starts_with("-19.9"))
        .unwrap_or_else(|| panic!("{text}"));
    let cells: Vec<&str> = row.split_whitespace().collect();
    assert_eq!(cells[0].split_once('.').unwrap().1.len(), 4, "{row}");
    assert!(cells[1].parse::<u64>().unwrap() > 0, "{row}");
}
