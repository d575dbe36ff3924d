//! The whole analysis of a data set: the document `gyrocal fit --json` prints.

use serde::{Deserialize, Serialize};

use crate::data::{Columns, Dataset, RateBins, Weighting};
use crate::error::FitError;
use crate::lsq::{Prepared, assemble, check, check_rates, fit_prepared};
use crate::metrics::{Metrics, repeatability_ppm};
use crate::model::{Coefficients, Fit, Method, Model, NeuronTrace};
use crate::neuron::{NeuronOptions, RATE_MEANS_ABOVE_POINTS, train, train_rate_means};
use crate::selection::{ModelSelection, select};
use crate::surface::ErrorSurface;
use crate::uncertainty::Uncertainty;

/// Default of [`Options::point_residuals_max`]: data sets of up to 10 000 points carry
/// per-point residuals in every fit; larger ones per-rate summaries
/// ([`crate::Fit::rate_residuals`]) unless asked (`gyrocal fit --residuals`).
pub const POINT_RESIDUALS_MAX: usize = 10_000;

/// How the fits of an analysis record their residuals.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ResidualDetail {
    /// Every fit's `residuals` has one entry per point, in data order.
    #[default]
    PerPoint,
    /// Every fit's `residuals` is empty and `rate_residuals` has one entry per distinct rate
    /// (more points than [`Options::point_residuals_max`], a schedule: at most
    /// [`crate::RATE_GROUPS_MAX`] distinct rates).
    PerRate,
    /// Every fit's `residuals` is empty and `rate_residuals` has one entry per non-empty rate
    /// bin ([`Analysis::rate_bins`]): more points than [`Options::point_residuals_max`] and
    /// continuous rates (more than [`crate::RATE_GROUPS_MAX`] distinct).
    PerRateBin,
}

/// What to compute.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Options {
    /// Models to fit (default: all four).
    pub models: Vec<Model>,
    /// Methods to use (default: least squares and the neuron). Least squares fits every model;
    /// the neuron fits the linear model only, and only when `models` contains it.
    pub methods: Vec<Method>,
    /// Neuron settings.
    pub neuron: NeuronOptions,
    /// Point weighting.
    pub weighting: Weighting,
    /// Side of the error-surface grid (0: no surface).
    pub surface_size: usize,
    /// What to do with a requested model the data cannot determine (too few distinct rates,
    /// one turning direction only): `true` (the default) skips it and records why in
    /// [`Analysis::skipped`]; `false` makes it an error (for models the user asked for by
    /// name). The linear model underlies the metrics: data that cannot determine it is an
    /// error either way.
    pub skip_unsupported: bool,
    /// Most points for which fits carry per-point residuals; above it they carry per-rate
    /// summaries instead ([`ResidualDetail::PerRate`]). Default [`POINT_RESIDUALS_MAX`];
    /// `usize::MAX` keeps them always.
    pub point_residuals_max: usize,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            models: Model::ALL.to_vec(),
            methods: vec![Method::LeastSquares, Method::Neuron],
            neuron: NeuronOptions::default(),
            weighting: Weighting::Auto,
            surface_size: 41,
            skip_unsupported: true,
            point_residuals_max: POINT_RESIDUALS_MAX,
        }
    }
}

/// The analysis of one data set.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Analysis {
    /// Where the data came from.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source: Option<String>,
    /// Number of points.
    pub points: usize,
    /// Distinct rates in the data (absent in documents written before this field existed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub distinct_rates: Option<usize>,
    /// Whether the fits carry per-point or per-rate residuals (absent in documents written
    /// before this field existed: per point).
    #[serde(default)]
    pub residual_detail: ResidualDetail,
    /// The rate bins of continuous data (more than [`crate::RATE_GROUPS_MAX`] distinct rates):
    /// what the per-bin summaries ([`ResidualDetail::PerRateBin`]) and, above
    /// [`RATE_MEANS_ABOVE_POINTS`] points, the neuron's online passes
    /// ([`crate::TrainingData::RateBins`]) are over. Absent for a schedule and for documents
    /// written before this field existed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rate_bins: Option<RateBins>,
    /// The fits, least squares first (in model order), then the neuron.
    pub fits: Vec<Fit>,
    /// The requested models that were not fitted because the data cannot determine them, with
    /// the reason, in model order (empty when every requested model was fitted). Absent in
    /// documents written before this field existed.
    #[serde(default)]
    pub skipped: Vec<Skipped>,
    /// The model the data support: [`ModelSelection::chosen`], by nested F-tests at
    /// [`crate::MODEL_SELECTION_LEVEL`] up the chain linear → quadratic → cubic among the
    /// least-squares fits made (see [`Analysis::model_selection`]). When no polynomial model
    /// was fitted, the split model if it was. Documents written before the F-test existed
    /// chose by the smallest residual standard error.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub best_model: Option<Model>,
    /// How `best_model` was chosen: the nested F-tests, their statistics and where the climb
    /// stopped. Absent when no polynomial model was fitted, and in documents written before
    /// this field existed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model_selection: Option<ModelSelection>,
    /// Metrics from least-squares fits.
    pub metrics: Metrics,
    /// SSE of the linear model over (weight, threshold) around the least-squares optimum.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error_surface: Option<ErrorSurface>,
    /// The uncertainty budget (k = 2), when one was attached
    /// ([`Analysis::attach_uncertainty`]); [`analyze`] leaves it absent, as do documents
    /// written before this field existed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uncertainty: Option<Uncertainty>,
    /// The verdict against acceptance limits ([`Analysis::evaluate_acceptance`]), when the
    /// run had limits; [`analyze`] leaves it absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub acceptance: Option<crate::acceptance::Acceptance>,
}

impl Analysis {
    /// The fit of `model` by `method`, if it was computed.
    pub fn fit(&self, method: Method, model: Model) -> Option<&Fit> {
        self.fits
            .iter()
            .find(|f| f.method == method && f.model == model)
    }
}

/// A requested model that was not fitted, and why (e.g. `cubic`: "the cubic model has 4
/// coefficients and needs at least 4 distinct rates; the data have 3"). In JSON:
/// `{"model": "cubic", "reason": "..."}`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Skipped {
    /// The model (by every method: the neuron fits only the linear model, which is never
    /// skipped).
    pub model: Model,
    /// Why the data cannot determine it, in words.
    pub reason: String,
}

/// Which of `models` data measured at `rates` cannot determine, with the reasons: the models
/// [`analyze`] will skip (by the same rule, [`check_rates`]). For a plan checker: pass the
/// schedule's rates, one per step.
///
/// ```
/// use gyrocal_fit::{Model, unsupported_models};
/// let skipped = unsupported_models(&[0.0, 10.0, -10.0], &Model::ALL);
/// assert_eq!(skipped.len(), 1);
/// assert_eq!(skipped[0].model, Model::Cubic);
/// ```
pub fn unsupported_models(rates: &[f64], models: &[Model]) -> Vec<Skipped> {
    let mut models = models.to_vec();
    models.sort();
    models.dedup();
    models
        .into_iter()
        .filter_map(|model| {
            check_rates(rates, model).err().map(|e| Skipped {
                model,
                reason: e.to_string(),
            })
        })
        .collect()
}

/// The analyses of several data sets (runs of the same gyro) and the repeatability across them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MultiAnalysis {
    /// One analysis per data set, in the order given; each one's `metrics.repeatability_ppm`
    /// holds the repeatability across the set.
    pub files: Vec<Analysis>,
    /// The least-squares linear scale factor of each data set, V/(°/s).
    pub scale_factors: Vec<f64>,
    /// `std(K_i, ddof=1)/mean(K_i)`, ppm; null for one data set.
    pub repeatability_ppm: Option<f64>,
}

/// Fits the requested models by the requested methods and computes the metrics.
///
/// A requested model the data cannot determine (too few distinct rates, split model without
/// both directions) is skipped and listed in [`Analysis::skipped`] with the reason, unless
/// `opts.skip_unsupported` is off, which makes it an error. Errors when the data cannot
/// determine even the linear model (fewer than two distinct rates, a non-finite value), or
/// when the options select nothing (e.g. only the neuron, which fits the linear model, with
/// only the quadratic model).
pub fn analyze(data: &Dataset, opts: &Options) -> Result<Analysis, FitError> {
    analyze_columns(&Columns::from_dataset(data), opts)
}

/// [`analyze`] on column arrays (what `gyrocal fit` reads a file into).
///
/// The cost is a few passes over the data whatever its size: one sort of the rates (the
/// distinct rates are counted once), one blocked QR and one residual pass per fit, one pass
/// for the error surface (then the grid in closed form), and for the neuron above
/// [`RATE_MEANS_ABOVE_POINTS`] points two passes (then training on the rate means).
pub fn analyze_columns(data: &Columns, opts: &Options) -> Result<Analysis, FitError> {
    let _span =
        tracing::debug_span!("analyze", source = ?data.source, points = data.len()).entered();
    let mut models = opts.models.clone();
    models.sort();
    models.dedup();
    let ls = opts.methods.contains(&Method::LeastSquares);
    let neuron = opts.methods.contains(&Method::Neuron) && models.contains(&Model::Linear);
    if !ls && !neuron {
        return Err(FitError::Unsupported(
            "nothing to fit: the neuron fits only the linear model; add --model linear or --method least-squares"
                .to_string(),
        ));
    }
    let point_residuals = data.len() <= opts.point_residuals_max;
    // Finite values, then the distinct rates, counted once for every check below.
    let prep = Prepared::new(data, opts.weighting, point_residuals)?;
    // The linear model underlies the metrics, so the data must support it in any case.
    prep.check(Model::Linear)?;
    let mut fits = Vec::new();
    let mut skipped = Vec::new();
    let mut split_error = None;
    if ls {
        for &m in &models {
            // The rule first (the reason a user can act on), then the solver, whose rank
            // check may still refuse nearly coincident rates.
            match prep.check(m).and_then(|()| fit_prepared(&prep, m)) {
                Ok(fit) => fits.push(fit),
                Err(e) if opts.skip_unsupported && m != Model::Linear => {
                    tracing::info!(model = %m, reason = %e, "model skipped");
                    skipped.push(Skipped {
                        model: m,
                        reason: e.to_string(),
                    });
                    if m == Model::Split {
                        split_error = Some(e);
                    }
                }
                Err(e) => return Err(e),
            }
        }
    }
    if neuron {
        fits.push(neuron_prepared(&prep, &opts.neuron));
    }
    let model_selection = select(&fits, prep.len(), rounding_floor(&prep));
    let best_model = match &model_selection {
        Some(s) => Some(s.chosen),
        None => fits
            .iter()
            .find(|f| f.method == Method::LeastSquares && f.model == Model::Split)
            .map(|f| f.model),
    };
    // The metrics reuse the least-squares fits already made (the same weighting).
    let find = |m: Model| {
        fits.iter()
            .find(|f| f.method == Method::LeastSquares && f.model == m)
    };
    let line_own;
    let line = match find(Model::Linear) {
        Some(f) => f,
        None => {
            line_own = fit_prepared(&prep, Model::Linear)?;
            &line_own
        }
    };
    let split_own;
    let split = match (find(Model::Split), split_error) {
        (Some(f), _) => Ok(f),
        (None, Some(e)) => Err(e),
        (None, None) => {
            split_own = prep
                .check(Model::Split)
                .and_then(|()| fit_prepared(&prep, Model::Split));
            split_own.as_ref().map_err(Clone::clone)
        }
    };
    let mut metrics = Metrics::from_fits(&prep, line, split.as_ref().map(|f| *f));
    // The nonlinearity's uncertainty: the chosen polynomial model is the noise-free reference
    // (the split model's kink is not a curve to take the bias from: the line then).
    let reference = best_model
        .filter(|m| *m != Model::Split)
        .and_then(find)
        .unwrap_or(line);
    match crate::nonlinearity::monte_carlo(&prep, reference) {
        Ok(u) => metrics.nonlinearity_uncertainty = Some(u),
        Err(reason) => {
            tracing::info!(%reason, "no uncertainty of the nonlinearity");
            metrics.not_computed.push(crate::NotComputed {
                metric: "nonlinearity_uncertainty".to_string(),
                reason,
            });
        }
    }
    let error_surface = (opts.surface_size > 0).then(|| {
        ErrorSurface::around_columns(
            prep.rates(),
            prep.volts(),
            metrics.scale_factor,
            metrics.bias_volts,
            opts.surface_size,
        )
    });
    for f in &fits {
        tracing::debug!(method = %f.method, model = %f.model, k = f.scale_factor, k0 = f.bias, sse = f.sse, "fit");
    }
    Ok(Analysis {
        source: data.source.clone(),
        points: data.len(),
        distinct_rates: Some(prep.index.distinct),
        residual_detail: match (point_residuals, prep.index.bins()) {
            (true, _) => ResidualDetail::PerPoint,
            (false, None) => ResidualDetail::PerRate,
            (false, Some(_)) => ResidualDetail::PerRateBin,
        },
        rate_bins: prep.index.bins().cloned(),
        fits,
        skipped,
        best_model,
        model_selection,
        metrics,
        error_surface,
        uncertainty: None,
        acceptance: None,
    })
}

/// The (weighted) SSE below which a fit counts as exact for the model selection: rounding
/// noise of about `1000·ε` relative to the outputs, `(1000·ε)²·Σ (D_i/σ_i)²`.
fn rounding_floor(prep: &Prepared<'_>) -> f64 {
    let sum: f64 = match prep.sigmas {
        Some(s) => prep
            .volts()
            .iter()
            .zip(s)
            .map(|(d, s)| (d / s) * (d / s))
            .sum(),
        None => prep.volts().iter().map(|d| d * d).sum(),
    };
    (1e3 * f64::EPSILON).powi(2) * sum
}

/// Fits the linear model with the paper's neuron (see [`crate::neuron`]).
pub fn fit_neuron(
    data: &Dataset,
    opts: &NeuronOptions,
    weighting: Weighting,
) -> Result<Fit, FitError> {
    check(data, Model::Linear)?;
    let cols = Columns::from_dataset(data);
    let prep = Prepared::new(&cols, weighting, true)?;
    Ok(neuron_prepared(&prep, opts))
}

/// The neuron's fit of prepared data (checked for the linear model): per point up to
/// [`RATE_MEANS_ABOVE_POINTS`] points, on the rate means above.
fn neuron_prepared(prep: &Prepared<'_>, opts: &NeuronOptions) -> Fit {
    let t = if prep.len() > RATE_MEANS_ABOVE_POINTS {
        train_rate_means(prep.rates(), prep.volts(), prep.sigmas, &prep.index, opts)
    } else {
        train(prep.rates(), prep.volts(), prep.sigmas, opts)
    };
    match t.status {
        crate::neuron::NeuronStatus::Converged => {}
        status => tracing::warn!(
            ?status,
            passes = t.online_passes + t.batch_passes,
            "neuron did not converge"
        ),
    }
    let coefficients = Coefficients {
        k0: Some(t.threshold),
        k1: Some(t.weight),
        ..Coefficients::default()
    };
    let trace = NeuronTrace {
        status: t.status,
        online_passes: t.online_passes,
        batch_passes: t.batch_passes,
        pass_errors: t.pass_errors,
        eta: opts.eta,
        alpha: opts.alpha,
        seed: opts.seed,
        initial_weight: t.initial_weight,
        initial_threshold: t.initial_threshold,
        training_data: t.training_data,
        online_pass_limit: t.online_pass_limit,
    };
    assemble(
        prep,
        Method::Neuron,
        Model::Linear,
        coefficients,
        Coefficients::default(),
        Some(trace),
    )
}

/// Analyses several data sets and adds the repeatability of the least-squares linear scale
/// factor across them (also copied into each analysis's metrics).
pub fn analyze_many(data: &[Dataset], opts: &Options) -> Result<MultiAnalysis, FitError> {
    let files = data
        .iter()
        .map(|d| analyze(d, opts))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(MultiAnalysis::from_analyses(files))
}

impl MultiAnalysis {
    /// Combines analyses made one by one (e.g. to report which file failed) and adds the
    /// repeatability across them.
    pub fn from_analyses(mut files: Vec<Analysis>) -> Self {
        let scale_factors: Vec<f64> = files.iter().map(|a| a.metrics.scale_factor).collect();
        let repeatability = repeatability_ppm(&scale_factors);
        for a in &mut files {
            a.metrics.set_repeatability(&scale_factors);
        }
        MultiAnalysis {
            files,
            scale_factors,
            repeatability_ppm: repeatability,
        }
    }
}
