//! Errors of the fitting functions.

use crate::model::Model;

/// Why a data set cannot be fitted.
///
/// These are properties of the data (too few points, rates that cannot determine the model),
/// never numerical accidents: the solvers check rank before they divide.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FitError {
    /// Fewer points than the model has coefficients.
    #[error("the {model} model has {needed} coefficients but the data has only {points} points")]
    TooFewPoints {
        /// The model that was asked for.
        model: Model,
        /// Number of points in the data.
        points: usize,
        /// Number of coefficients the model needs.
        needed: usize,
    },
    /// Fewer than two distinct rates: no line can be fitted.
    #[error(
        "the data has {distinct} distinct rate(s); at least 2 are needed to fit a scale factor"
    )]
    TooFewDistinctRates {
        /// Number of distinct rates in the data.
        distinct: usize,
    },
    /// The rates cannot determine the model's coefficients (e.g. a cubic on 3 distinct rates).
    #[error(
        "the {model} model has {needed} coefficients and needs at least {needed} distinct rates; the data have {distinct}"
    )]
    RankDeficient {
        /// The model that was asked for.
        model: Model,
        /// Distinct rates needed.
        needed: usize,
        /// Distinct rates present.
        distinct: usize,
    },
    /// The split model needs at least two distinct rates on each side of zero (zero counts on
    /// both sides).
    #[error(
        "the split model needs both turning directions: the {side} side (rates {side_sign} 0) has {distinct} distinct rate(s), at least 2 are needed"
    )]
    SplitNeedsBothSigns {
        /// `"positive"` or `"negative"`.
        side: &'static str,
        /// `">="` or `"<="`.
        side_sign: &'static str,
        /// Distinct rates on that side, zero included.
        distinct: usize,
    },
    /// A value in the data set is NaN or infinite (parsed input never contains one; this guards
    /// data sets built in code).
    #[error("point {index} has a non-finite value")]
    NonFinite {
        /// Index of the point in the data set.
        index: usize,
    },
    /// The options ask for nothing that can be computed, e.g. the neuron on a quadratic model.
    #[error("{0}")]
    Unsupported(String),
}
