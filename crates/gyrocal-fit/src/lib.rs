//! Pure numerics for calibrating a gyroscope's scale factor on a rate table.
//!
//! A rate table turns the gyro at known rates `ω` (°/s) and a multimeter records the mean output
//! `D` (V) at each rate. This crate turns those pairs into the numbers a lab reports: the scale
//! factor `K` (V/(°/s)), the bias `K0` (V), their uncertainties, how well the model fits, and the
//! standard metrics (nonlinearity, asymmetry, bias as a rate, repeatability).
//!
//! # Why it is shaped this way
//!
//! * **Least squares is the reference.** The paper this project follows (Li, Liu, Zhang, *The
//!   Identification Method of HRG Scale Factor Based on Neural Network*) fits a straight line two
//!   ways, least squares and a single neuron trained by gradient descent with momentum, and claims
//!   the neuron is better. A linear neuron trained to the minimum of the squared error converges
//!   to the least-squares line, by construction. So [`neuron`] implements the paper's update rule
//!   faithfully (online, with momentum), but finishes with full-batch gradient passes so it really
//!   reaches the minimum, and every report shows both estimators with the same figures
//!   (SSE, RMS, max |residual|, per-rate residuals) so neither can be presented as better than it
//!   is.
//! * **Better models, not a different optimiser.** Residuals positive at both ends and negative
//!   in the middle are an even-order nonlinearity; [`Model::Quadratic`], [`Model::Cubic`] and
//!   [`Model::Split`] (separate scale factors for the two turning directions) capture it.
//! * **Numerically sound.** Least squares is solved by a Householder QR of the column-scaled
//!   design matrix (`ω/ω_max`), never by inverting `AᵀA`; the coefficient covariance comes from
//!   the triangular factor, `(RᵀR)⁻¹ = R⁻¹R⁻ᵀ`. The neuron normalises its inputs and outputs.
//!   Nothing here returns NaN: bad data is an error ([`FitError`]), a diverging neuron is a
//!   status ([`NeuronStatus::Diverged`]).
//! * **No I/O.** [`input`] parses CSV from any [`std::io::Read`]; opening files is the caller's
//!   job. Every result type is `Serialize + Deserialize`, so the run sequencer can write
//!   `fit.json` and the report can read it back with these same types.
//!
//! # Entry points
//!
//! * [`input::parse_csv`] reads a data set.
//! * [`analyze`] fits the requested models and methods and computes the metrics; the result is
//!   the JSON document `gyrocal fit --json` prints. Models the data cannot determine are
//!   skipped and listed with the reason ([`Analysis::skipped`]); [`check_rates`] is that rule,
//!   and [`unsupported_models`] applies it to a plan's schedule before a run. [`analyze_many`] does the same for several
//!   data sets and adds the repeatability.
//! * [`fit_least_squares`] and [`neuron::train`] are the individual estimators;
//!   [`Fit::compensate`] turns an output voltage back into a rate.
//! * [`Analysis::best_model`] is chosen by nested F-tests ([`selection`],
//!   [`Analysis::model_selection`]); [`Metrics::asymmetry_common_k2`] is the asymmetry from
//!   one joint fit with a common `K2`, free of the even-order bias of the GJB figure.
//! * [`Analysis::attach_uncertainty`] adds the expanded uncertainty (k = 2) budget
//!   ([`uncertainty`]) from the instruments' stated accuracies, and the metrics' own
//!   uncertainties (the nonlinearity's by Monte Carlo, [`nonlinearity`]).
//! * [`analyze_columns`] is the same on column arrays of any size (`gyrocal fit`): above
//!   [`POINT_RESIDUALS_MAX`] points the fits carry residual summaries per distinct rate for a
//!   schedule (at most [`RATE_GROUPS_MAX`] distinct rates) and per rate bin ([`RateBins`],
//!   [`RATE_BINS`] of equal width) for continuous rates, every figure over the points staying
//!   exact; [`WithPointResiduals`] writes every point's residuals anyway, computed as they are
//!   written.
//! * [`Analysis::evaluate_acceptance`] judges an analysis against acceptance limits
//!   ([`acceptance`]): every limit applies to the figure the report presents as the result,
//!   with its uncertainty, so the guarded rule decides on evidence.

#![deny(missing_docs)]

pub mod acceptance;
mod analysis;
mod asymmetry;
mod data;
pub mod display;
mod error;
pub mod input;
mod lsq;
pub mod metrics;
mod model;
pub mod neuron;
pub mod nonlinearity;
mod quantity;
pub mod selection;
mod stream;
mod surface;
pub mod uncertainty;
mod verdict;

pub use analysis::{
    Analysis, MultiAnalysis, Options, POINT_RESIDUALS_MAX, ResidualDetail, Skipped, analyze,
    analyze_columns, analyze_many, fit_neuron, unsupported_models,
};
pub use asymmetry::{ASYMMETRY_COMMON_K2_MODEL, ASYMMETRY_COMMON_K2_UNITS, AsymmetryCommonK2};
pub use data::{
    Columns, Dataset, Point, RATE_BINS, RATE_BINS_RULE, RATE_GROUPS_MAX, RateBins, Weighting,
};
pub use error::FitError;
pub use lsq::{check_rates, fit_least_squares, fit_least_squares_columns};
pub use metrics::{Metrics, NONLINEARITY_NORMALISATION, NotComputed, repeatability_ppm};
pub use model::{
    Coefficients, Fit, Method, Model, NeuronTrace, RateResidual, Residual, TrainingData,
};
pub use neuron::{NeuronOptions, NeuronStatus};
pub use selection::{MODEL_SELECTION_LEVEL, ModelSelection, NestedTest};
pub use stream::{MultiWithPointResiduals, WithPointResiduals};
pub use surface::ErrorSurface;
pub use uncertainty::{MeterAccuracy, TableRateAccuracy, Uncertainty, UncertaintyInputs};
