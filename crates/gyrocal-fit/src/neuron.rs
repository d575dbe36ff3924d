//! The paper's estimator: one linear neuron trained by gradient descent with momentum.
//!
//! The neuron's input is the applied rate, its weight the scale factor, its threshold the bias:
//! `y_out = w·ω + θ`. Each presentation of a point has the error `e = D − y_out` and the cost
//! `E = e²/2`, and the paper's equation (5) updates
//!
//! ```text
//! w(k) = w(k−1) − η·∂E/∂w + α·(w(k−1) − w(k−2))     (same rule for θ)
//! ```
//!
//! once per point per pass (online training).
//!
//! # What this implementation adds, and why
//!
//! * **Normalisation.** Training runs on `x = (ω − ω̄)/s_ω` and `y = (D − D̄)/s_D` (weighted means,
//!   `s` the largest absolute deviation), so `|x|, |y| ≤ 1` and one default η works for rates to
//!   20 °/s and outputs to 7 V. The weight and threshold are mapped back:
//!   `K = w·s_D/s_ω`, `K0 = D̄ + s_D·θ − K·ω̄`. The initial weight and threshold are drawn
//!   uniformly from ±0.1 in these normalised units (seeded), and reported in volts.
//! * **A stopping rule that can fire.** The paper stops when the error falls below ε, which never
//!   happens on real data (the smallest error is the least-squares residual). The online phase
//!   here stops when the *change* of the pass error is at most `epsilon` times the pass error,
//!   or after `max_online_passes` (the decayed step may crawl on strongly weighted data).
//! * **Real convergence.** With a fixed step, online updates circle the minimum at a distance
//!   proportional to η, because each point pulls the weights its own way. So the step decays
//!   over the online passes, `η_p = η / (1 + p/eta_decay_passes)`, and training then *finishes
//!   with full-batch passes* (the same momentum rule on the gradient of the whole pass, step
//!   `1/(1 + max x²)`, which is stable for any data, and momentum 0.5) until the gradient norm in
//!   normalised units is below `gradient_tolerance`. That reaches the least-squares solution to
//!   about 1e-9 relative. Setting `batch_finish = false` gives the online-only behaviour, which
//!   stops near, not at, the minimum.
//! * **Weights.** When the points carry standard deviations the neuron minimises the same
//!   weighted error as least squares (each presentation's cost multiplied by its normalised
//!   weight), so the two are comparable.
//! * **Failure is a status.** A non-finite pass error, or one above 1000 times the error of the
//!   initial weights, stops training as [`NeuronStatus::Diverged`] and keeps the last finite
//!   weights; reaching `max_passes` is [`NeuronStatus::MaxPasses`]. No NaN is returned.

use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use serde::{Deserialize, Serialize};

use crate::data::{RateGroups, RateIndex};
use crate::model::TrainingData;
use crate::surface::SseForm;

/// Above this many points the online passes present each distinct rate's mean output (weighted
/// by the points it averages) instead of every point: see [`TrainingData::RateMeans`]. The
/// batch passes and the pass errors still cover every point, through the sufficient statistics
/// of the data, so their cost does not grow with the number of points. At or below it (a
/// calibration's step means, tens of points) training is per point, as before.
pub const RATE_MEANS_ABOVE_POINTS: usize = 10_000;

/// Most presentations (rates × online passes) in the online phase of training on rate means:
/// with very many distinct rates the online-pass limit is lowered to
/// `max(1, ONLINE_PRESENTATIONS_MAX / rates)` (reported in the trace); the batch finish then
/// converges as usual.
pub const ONLINE_PRESENTATIONS_MAX: u64 = 20_000_000;

/// Settings of the neuron.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct NeuronOptions {
    /// Learning rate η of the online phase (normalised units).
    pub eta: f64,
    /// Momentum α of the online phase.
    pub alpha: f64,
    /// Tolerance ε on the relative change of the pass error that ends the online phase.
    pub epsilon: f64,
    /// Maximum number of passes (online and batch together).
    pub max_passes: u64,
    /// Most online passes before the batch finish starts even if the online stopping rule has
    /// not fired. With strongly unequal weights (a whole-turn plan has 60 times more readings
    /// at 0.3 °/s than at 20 °/s) the decayed online step can crawl for ever with a relative
    /// change just above `epsilon`; the batch finish converges regardless.
    pub max_online_passes: u64,
    /// Seed of the small random initial weight and threshold.
    pub seed: u64,
    /// The online step is `η / (1 + p / eta_decay_passes)` at pass `p` (0 or infinity: no
    /// decay).
    pub eta_decay_passes: f64,
    /// Finish with full-batch gradient passes (see the module docs).
    pub batch_finish: bool,
    /// Batch phase stops when the gradient norm (normalised units, mean over points) is below
    /// this.
    pub gradient_tolerance: f64,
}

impl Default for NeuronOptions {
    fn default() -> Self {
        Self {
            eta: 0.01,
            alpha: 0.9,
            epsilon: 1e-6,
            max_passes: 100_000,
            max_online_passes: 5_000,
            seed: 1,
            eta_decay_passes: 50.0,
            batch_finish: true,
            gradient_tolerance: 1e-13,
        }
    }
}

/// How training ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", tag = "status")]
pub enum NeuronStatus {
    /// The stopping rule fired.
    Converged,
    /// `max_passes` were used up before the stopping rule fired.
    MaxPasses,
    /// The error became non-finite or grew past 1000 times its initial value at this pass.
    Diverged {
        /// The pass (1-based) at which divergence was detected.
        pass: u64,
    },
}

/// The trained neuron, in original units.
#[derive(Debug, Clone, PartialEq)]
pub struct Trained {
    /// Weight: the scale factor, V/(°/s).
    pub weight: f64,
    /// Threshold: the bias, V.
    pub threshold: f64,
    /// How training ended.
    pub status: NeuronStatus,
    /// Online passes run.
    pub online_passes: u64,
    /// Batch passes run.
    pub batch_passes: u64,
    /// Unweighted sum of squared residuals after every pass, V².
    pub pass_errors: Vec<f64>,
    /// Initial weight, V/(°/s).
    pub initial_weight: f64,
    /// Initial threshold, V.
    pub initial_threshold: f64,
    /// What the online passes presented.
    pub training_data: TrainingData,
    /// The online-pass limit, when lowered below `max_online_passes` to bound the cost.
    pub online_pass_limit: Option<u64>,
}

/// Trains the neuron on `(rates, volts)` with optional per-point σ (weights `1/σ²`).
///
/// The slices must have the same, non-zero length and at least two distinct rates (checked by
/// the callers in this crate; otherwise the result is a zero-weight neuron with status
/// `MaxPasses`).
pub fn train(
    rates: &[f64],
    volts: &[f64],
    sigmas: Option<&[f64]>,
    opts: &NeuronOptions,
) -> Trained {
    let n = rates.len().min(volts.len());
    // Normalised weights u_i with mean 1.
    let mut u: Vec<f64> = match sigmas {
        Some(s) => s.iter().take(n).map(|s| 1.0 / (s * s)).collect(),
        None => vec![1.0; n],
    };
    let usum: f64 = u.iter().sum();
    for ui in &mut u {
        *ui *= n as f64 / usum;
    }
    let nf = n as f64;
    let mx = rates.iter().zip(&u).map(|(w, u)| w * u).sum::<f64>() / nf;
    let my = volts.iter().zip(&u).map(|(d, u)| d * u).sum::<f64>() / nf;
    let sx = rates.iter().fold(0.0_f64, |m, w| m.max((w - mx).abs()));
    let sy = volts.iter().fold(0.0_f64, |m, d| m.max((d - my).abs()));
    let sx = if sx > 0.0 { sx } else { 1.0 };
    let sy = if sy > 0.0 { sy } else { 1.0 };
    let x: Vec<f64> = rates.iter().map(|w| (w - mx) / sx).collect();
    let y: Vec<f64> = volts.iter().map(|d| (d - my) / sy).collect();

    let to_original = |w: f64, t: f64| {
        let k = w * sy / sx;
        (k, my + sy * t - k * mx)
    };
    // Unweighted SSE in V² (comparable with least squares' `sse`).
    let sse_volts = |w: f64, t: f64| -> f64 {
        x.iter()
            .zip(&y)
            .map(|(x, y)| (y - (w * x + t)).powi(2))
            .sum::<f64>()
            * sy
            * sy
    };
    // Weighted cost in normalised units (what training minimises).
    let cost = |w: f64, t: f64| -> f64 {
        x.iter()
            .zip(&y)
            .zip(&u)
            .map(|((x, y), u)| u * (y - (w * x + t)).powi(2))
            .sum::<f64>()
            / 2.0
    };

    let max_x2 = x.iter().fold(0.0_f64, |m, x| m.max(x * x));
    let grad = |w: f64, t: f64| -> (f64, f64) {
        let (mut gw, mut gt) = (0.0, 0.0);
        for i in 0..n {
            let e = y[i] - (w * x[i] + t);
            gw -= u[i] * e * x[i];
            gt -= u[i] * e;
        }
        (gw / nf, gt / nf)
    };
    let problem = Problem {
        x: &x,
        y: &y,
        u: &u,
        max_x2,
        online_limit: opts.max_online_passes,
    };
    let mut t = run(&problem, opts, &to_original, &cost, &sse_volts, &grad);
    t.training_data = TrainingData::Points;
    t
}

/// Trains on the per-rate means of a large data set ([`TrainingData::RateMeans`]), or on
/// continuous data on the per-bin means ([`TrainingData::RateBins`]: each bin presented at its
/// points' weighted mean rate): the same
/// normalisation, initial weights, update rules and stopping rules as [`train`], the online
/// passes over the distinct rates' weighted mean outputs (each weighted by the summed
/// normalised weights of its points), the batch gradient, cost and pass errors from the
/// sufficient statistics of every point ([`SseForm`]). At the minimum this is the per-point
/// problem's minimum: `Σ_i u_i (y_i − ŷ)²` differs from `Σ_g U_g (ȳ_g − ŷ_g)²` by a constant.
pub(crate) fn train_rate_means(
    rates: &[f64],
    volts: &[f64],
    sigmas: Option<&[f64]>,
    index: &RateIndex,
    opts: &NeuronOptions,
) -> Trained {
    let n = rates.len().min(volts.len());
    let nf = n as f64;
    let raw = |i: usize| sigmas.map_or(1.0, |s| 1.0 / (s[i] * s[i]));
    let usum: f64 = (0..n).map(raw).sum();
    let norm = nf / usum;
    let groups = index.group_count();
    let binned = index.bins();
    let mut gu = vec![0.0_f64; groups];
    let mut guy = vec![0.0_f64; groups];
    // Binned: Σ u·ω per bin, for the bin's weighted mean rate.
    let mut gux = vec![0.0_f64; if binned.is_some() { groups } else { 0 }];
    let (mut swx, mut swy) = (0.0_f64, 0.0_f64);
    let (mut dmin, mut dmax) = (f64::INFINITY, f64::NEG_INFINITY);
    for i in 0..n {
        let u = raw(i) * norm;
        swx += rates[i] * u;
        swy += volts[i] * u;
        let g = index.group(rates[i]);
        gu[g] += u;
        guy[g] += u * volts[i];
        if binned.is_some() {
            gux[g] += u * rates[i];
        }
        dmin = dmin.min(volts[i]);
        dmax = dmax.max(volts[i]);
    }
    let mx = swx / nf;
    let my = swy / nf;
    let sx = match &index.groups {
        RateGroups::Rates { rates, .. } => rates.iter().fold(0.0_f64, |m, w| m.max((w - mx).abs())),
        // The largest deviation is at one end of the range, as over the points.
        RateGroups::Bins { bins, .. } => (bins.hi_dps - mx).abs().max((bins.lo_dps - mx).abs()),
    };
    let sy = if n > 0 {
        (dmax - my).abs().max((dmin - my).abs())
    } else {
        0.0
    };
    let sx = if sx > 0.0 { sx } else { 1.0 };
    let sy = if sy > 0.0 { sy } else { 1.0 };
    // The groups with points (every distinct rate has some; a bin may have none).
    let present: Vec<usize> = (0..groups).filter(|&g| index.counts()[g] > 0).collect();
    let presented = present.len();
    let xg: Vec<f64> = match &index.groups {
        RateGroups::Rates { rates, .. } => present.iter().map(|&g| (rates[g] - mx) / sx).collect(),
        RateGroups::Bins { .. } => present
            .iter()
            .map(|&g| (gux[g] / gu[g] - mx) / sx)
            .collect(),
    };
    let yg: Vec<f64> = present
        .iter()
        .map(|&g| (guy[g] / gu[g] - my) / sy)
        .collect();
    let gu: Vec<f64> = present.iter().map(|&g| gu[g]).collect();
    // Mean 1 over the presented means, as the per-point weights have mean 1 over the points.
    let ug: Vec<f64> = gu.iter().map(|u| u * presented as f64 / nf).collect();
    // The weighted least-squares line in normalised units, from the rate means (exact: the
    // within-rate scatter does not move it), as the reference of the sufficient statistics.
    let (mut s1, mut sx1, mut sxx, mut sy1, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for g in 0..presented {
        s1 += gu[g];
        sx1 += gu[g] * xg[g];
        sxx += gu[g] * xg[g] * xg[g];
        sy1 += gu[g] * yg[g];
        sxy += gu[g] * xg[g] * yg[g];
    }
    let det = s1 * sxx - sx1 * sx1;
    let w0 = if det > 0.0 {
        (s1 * sxy - sx1 * sy1) / det
    } else {
        0.0
    };
    let t0 = if s1 > 0.0 { (sy1 - w0 * sx1) / s1 } else { 0.0 };
    let mut weighted = SseForm::new(&[], &[], None, w0, t0);
    let mut unweighted = weighted;
    for i in 0..n {
        let x = (rates[i] - mx) / sx;
        let y = (volts[i] - my) / sy;
        weighted.add(x, y, raw(i) * norm);
        unweighted.add(x, y, 1.0);
    }
    let to_original = |w: f64, t: f64| {
        let k = w * sy / sx;
        (k, my + sy * t - k * mx)
    };
    let sse_volts = |w: f64, t: f64| unweighted.at(w, t) * sy * sy;
    let cost = |w: f64, t: f64| weighted.at(w, t) / 2.0;
    let grad = |w: f64, t: f64| {
        let (gw, gt) = weighted.half_gradient(w, t);
        (gw / nf, gt / nf)
    };
    let max_x2 = xg.iter().fold(0.0_f64, |m, x| m.max(x * x));
    let budget = (ONLINE_PRESENTATIONS_MAX / presented.max(1) as u64).max(1);
    let online_limit = opts.max_online_passes.min(budget);
    let problem = Problem {
        x: &xg,
        y: &yg,
        u: &ug,
        max_x2,
        online_limit,
    };
    let mut t = run(&problem, opts, &to_original, &cost, &sse_volts, &grad);
    t.training_data = if binned.is_some() {
        TrainingData::RateBins {
            bins: presented,
            points: n,
        }
    } else {
        TrainingData::RateMeans {
            rates: presented,
            points: n,
        }
    };
    t.online_pass_limit = (online_limit < opts.max_online_passes).then_some(online_limit);
    t
}

/// What the online passes present, in normalised units.
struct Problem<'a> {
    x: &'a [f64],
    y: &'a [f64],
    u: &'a [f64],
    max_x2: f64,
    online_limit: u64,
}

/// The training loop shared by [`train`] and [`train_rate_means`].
fn run(
    problem: &Problem<'_>,
    opts: &NeuronOptions,
    to_original: &dyn Fn(f64, f64) -> (f64, f64),
    cost: &dyn Fn(f64, f64) -> f64,
    sse_volts: &dyn Fn(f64, f64) -> f64,
    grad: &dyn Fn(f64, f64) -> (f64, f64),
) -> Trained {
    let (x, y, u) = (problem.x, problem.y, problem.u);
    let n = x.len().min(y.len()).min(u.len());
    let mut rng = StdRng::seed_from_u64(opts.seed);
    let mut w: f64 = rng.random_range(-0.1..0.1);
    let mut t: f64 = rng.random_range(-0.1..0.1);
    let (initial_weight, initial_threshold) = to_original(w, t);
    let e0 = cost(w, t);
    let mut prev_e = e0;
    let (mut dw, mut dt) = (0.0_f64, 0.0_f64);
    let mut pass_errors = Vec::new();
    let mut online_passes = 0_u64;
    let mut batch_passes = 0_u64;
    let mut online = true;
    let mut status = NeuronStatus::MaxPasses;
    let batch_eta = 1.0 / (1.0 + problem.max_x2);
    let batch_alpha = 0.5;

    for pass in 1..=opts.max_passes {
        let (w_before, t_before) = (w, t);
        if online {
            online_passes += 1;
            let decay = if opts.eta_decay_passes > 0.0 && opts.eta_decay_passes.is_finite() {
                1.0 + (online_passes - 1) as f64 / opts.eta_decay_passes
            } else {
                1.0
            };
            let eta = opts.eta / decay;
            for i in 0..n {
                let e = y[i] - (w * x[i] + t);
                // ∂E/∂w = −u·e·x, ∂E/∂θ = −u·e
                let gw = -u[i] * e * x[i];
                let gt = -u[i] * e;
                dw = -eta * gw + opts.alpha * dw;
                dt = -eta * gt + opts.alpha * dt;
                w += dw;
                t += dt;
            }
        } else {
            batch_passes += 1;
            let (gw, gt) = grad(w, t);
            if (gw * gw + gt * gt).sqrt() <= opts.gradient_tolerance {
                batch_passes -= 1;
                status = NeuronStatus::Converged;
                break;
            }
            dw = -batch_eta * gw + batch_alpha * dw;
            dt = -batch_eta * gt + batch_alpha * dt;
            w += dw;
            t += dt;
        }
        let e = cost(w, t);
        if !e.is_finite()
            || !w.is_finite()
            || !t.is_finite()
            || e > 1000.0 * e0.max(f64::MIN_POSITIVE)
        {
            // Keep the last finite weights; the pass that blew up is not recorded.
            w = w_before;
            t = t_before;
            if online {
                online_passes -= 1;
            } else {
                batch_passes -= 1;
            }
            status = NeuronStatus::Diverged { pass };
            break;
        }
        pass_errors.push(sse_volts(w, t));
        let change = (prev_e - e).abs();
        prev_e = e;
        let settled = change <= opts.epsilon * e;
        if online && (settled || online_passes >= problem.online_limit) {
            if opts.batch_finish {
                online = false;
                // Start the batch phase without the online phase's momentum.
                dw = 0.0;
                dt = 0.0;
            } else {
                // online only: the pass limit is not convergence
                status = if settled {
                    NeuronStatus::Converged
                } else {
                    NeuronStatus::MaxPasses
                };
                break;
            }
        }
    }
    let (weight, threshold) = to_original(w, t);
    Trained {
        weight,
        threshold,
        status,
        online_passes,
        batch_passes,
        pass_errors,
        initial_weight,
        initial_threshold,
        training_data: TrainingData::Points,
        online_pass_limit: None,
    }
}
