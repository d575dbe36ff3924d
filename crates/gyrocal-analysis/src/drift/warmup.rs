//! The warm-up (IEEE 1431 §12.6) of the analysed segment: consecutive window means, complete
//! when two agree within the tolerance (see the module docs of [`super`], *Warm-up*). One
//! criterion for both memory paths ([`detect_warmup_in`]), so their cuts are the same bits.

use super::{DEFAULT_WARMUP_SIGMAS, Warmup, WarmupOptions, WarmupSignificance, fmt_g};

/// Most points of the warm-up curve kept in the document.
const MAX_WARMUP_POINTS: usize = 2000;
/// Most window means kept for the significance test (32 MiB); a record with more windows is
/// tested on its first ones.
const MAX_MEANS_KEPT: usize = 1 << 22;
/// Pairs of settled windows needed to measure the record's own wander at the warm-up's span;
/// with fewer the cut found by the criterion is kept and the note says it was not tested.
pub(super) const MIN_WANDER_PAIRS: usize = 8;
/// A warm-up is cut only when the first window differs from the window where the criterion
/// settled by more than this many times the record's own wander over the same span.
pub(super) const WARMUP_SIGNIFICANCE: f64 = 3.0;

/// The warm-up of the segment `y`, held in memory.
pub(super) fn detect_warmup(
    y: &[f64],
    tau0: f64,
    t0: f64,
    factor: f64,
    opts: &WarmupOptions,
    notes: &mut Vec<String>,
) -> Option<Warmup> {
    let chunks = |r: std::ops::Range<usize>, f: &mut dyn FnMut(&[f64])| {
        f(y.get(r).unwrap_or(&[]));
        Ok(())
    };
    // reading a slice cannot fail
    detect_warmup_in(chunks, y.len(), tau0, t0, factor, opts, notes).unwrap_or(None)
}

/// The warm-up criterion over a segment of `n` samples handed over in chunks by `chunks(range,
/// f)` (a slice in memory; a file's buffers on the bounded path): one pass for the white-noise
/// σ when the tolerance is the default, one for the window means. Written once for both
/// paths, so their cuts are the same bits.
pub(super) fn detect_warmup_in<F>(
    mut chunks: F,
    n: usize,
    tau0: f64,
    t0: f64,
    factor: f64,
    opts: &WarmupOptions,
    notes: &mut Vec<String>,
) -> std::io::Result<Option<Warmup>>
where
    F: FnMut(std::ops::Range<usize>, &mut dyn FnMut(&[f64])) -> std::io::Result<()>,
{
    if !(opts.window_s.is_finite() && opts.window_s > 0.0) {
        return Ok(None);
    }
    let w = (opts.window_s / tau0).round().max(1.0) as usize;
    let n_means = n / w;
    if n_means < 2 {
        notes.push(format!(
            "no warm-up detection: the analysed segment is shorter than two {} s windows",
            fmt_g(w as f64 * tau0)
        ));
        return Ok(None);
    }
    let (tolerance, tolerance_source) = match opts.tolerance {
        Some(t) => (t * factor.abs(), "option".to_string()),
        None => {
            let mut ss = 0.0_f64;
            let mut prev: Option<f64> = None;
            chunks(0..n, &mut |c: &[f64]| {
                for &v in c {
                    if let Some(p) = prev {
                        ss += (v - p).powi(2);
                    }
                    prev = Some(v);
                }
            })?;
            let sigma_a = (ss / (2.0 * (n - 1) as f64)).sqrt();
            (
                DEFAULT_WARMUP_SIGMAS * sigma_a / (w as f64).sqrt(),
                "3 x white-noise sigma of a window mean (sigma_A(tau0)/sqrt(w))".to_string(),
            )
        }
    };
    let window_s = w as f64 * tau0;
    let step = n_means.div_ceil(MAX_WARMUP_POINTS).max(1);
    let mut curve = Vec::with_capacity(n_means.min(MAX_WARMUP_POINTS));
    let mut found = None;
    let mut prev_mean: Option<f64> = None;
    let mut means: Vec<f64> = Vec::with_capacity(n_means.min(MAX_MEANS_KEPT));
    let (mut i, mut in_window, mut acc) = (0usize, 0usize, 0.0_f64);
    chunks(0..n_means * w, &mut |c: &[f64]| {
        for &v in c {
            acc += v;
            in_window += 1;
            if in_window < w {
                continue;
            }
            let m = acc / w as f64;
            if found.is_none()
                && let Some(p) = prev_mean
                && (m - p).abs() < tolerance
            {
                found = Some((i - 1) as f64 * window_s);
            }
            if i % step == 0 {
                curve.push((t0 + (i as f64 + 0.5) * window_s, m));
            }
            if means.len() < MAX_MEANS_KEPT {
                means.push(m);
            }
            prev_mean = Some(m);
            i += 1;
            in_window = 0;
            acc = 0.0;
        }
    })?;
    // The criterion alone cuts noise: a record whose window means wander (rate random walk,
    // flicker) meets it late by chance. With the default tolerance, a cut stands only when the
    // start is off the settled level by more than the record wanders by itself.
    let significance = match found {
        Some(t) if opts.tolerance.is_none() => {
            significance(&means, (t / window_s).round() as usize, window_s)
        }
        _ => None,
    };
    let not_significant = significance.as_ref().is_some_and(|s| !s.significant);
    let (time_s, ended_by) = match (found, opts.max_s) {
        (Some(_), _) if not_significant => (0.0, "not_significant"),
        (Some(t), Some(m)) if t > m => (m, "max"),
        (Some(t), _) => (t, "criterion"),
        (None, Some(m)) => (m, "max"),
        (None, None) => {
            notes.push(
                "warm-up criterion never met (consecutive window means never agreed within the tolerance): nothing cut; give --warmup-max to cut"
                    .into(),
            );
            (0.0, "not_reached")
        }
    };
    Ok(Some(Warmup {
        window_s,
        tolerance,
        tolerance_source,
        max_s: opts.max_s,
        time_s,
        ended_by: ended_by.into(),
        significance,
        curve,
    }))
}

/// The test of the warm-up the criterion ended at window `cut` against the record's own
/// wander: the first window's mean against the mean at the cut, `|m₀ − m_c|`, beside the
/// spread of `|m_{k+c} − m_k|` over the settled windows (k ≥ c), the same span measured where
/// the gyro has settled. The spread is robust (median / 0.6745, a normal σ): a few outliers do
/// not widen it. `None` when nothing was cut (`cut` 0) or the means are missing.
fn significance(means: &[f64], cut: usize, window_s: f64) -> Option<WarmupSignificance> {
    if cut == 0 {
        return None;
    }
    let (first, at_cut) = (*means.first()?, *means.get(cut)?);
    let settled = means.get(cut..).unwrap_or(&[]);
    let mut diffs: Vec<f64> = settled
        .iter()
        .zip(settled.iter().skip(cut))
        .map(|(a, b)| (b - a).abs())
        .filter(|d| d.is_finite())
        .collect();
    let change = (first - at_cut).abs();
    let wander = (diffs.len() >= MIN_WANDER_PAIRS).then(|| {
        diffs.sort_by(f64::total_cmp);
        diffs.get(diffs.len() / 2).copied().unwrap_or(0.0) / 0.674_489_75
    });
    Some(WarmupSignificance {
        span_s: cut as f64 * window_s,
        change,
        wander,
        pairs: diffs.len(),
        significant: wander.is_none_or(|w| change > WARMUP_SIGNIFICANCE * w),
    })
}
