//! Per-point residuals written as they are computed: the document of an analysis with every
//! point's residual in every fit, without holding them.
//!
//! Per-point residuals of five fits take 32 bytes a point each in memory (1.6 GB at 10^7
//! points) and about 850 bytes a point in pretty JSON (844 MB at 10^6 points).
//! [`crate::analyze_columns`] therefore keeps them only up to
//! [`crate::Options::point_residuals_max`] points and summarises the rest per rate or per
//! rate bin; [`WithPointResiduals`] is the explicit way to every point
//! (`gyrocal fit --json --residuals`): it serializes an analysis made with summaries as the
//! document the same analysis would be with per-point residuals (byte for byte: the same
//! keys, in the same order, `residual_detail: "per-point"`, no `rate_residuals`), computing
//! each fit's residuals from the data and the fit's coefficients while it is written. Memory
//! is the data's columns, whatever the size of the document.

use serde::ser::{SerializeSeq, SerializeStruct};
use serde::{Serialize, Serializer};

use crate::analysis::{Analysis, MultiAnalysis, ResidualDetail};
use crate::data::Columns;
use crate::model::{Fit, Residual, predict};

/// An [`Analysis`] with every point's residual in every fit, computed while it is written
/// (see the module docs). The columns must be those the analysis was made from.
#[derive(Debug, Clone, Copy)]
pub struct WithPointResiduals<'a> {
    analysis: &'a Analysis,
    data: &'a Columns,
}

impl<'a> WithPointResiduals<'a> {
    /// `analysis` of `data`, to be written with per-point residuals.
    pub fn new(analysis: &'a Analysis, data: &'a Columns) -> Self {
        Self { analysis, data }
    }
}

/// A [`MultiAnalysis`] with every point's residual in every fit of every file
/// ([`WithPointResiduals`]); `data[i]` are the columns of `multi.files[i]`.
#[derive(Debug, Clone, Copy)]
pub struct MultiWithPointResiduals<'a> {
    multi: &'a MultiAnalysis,
    data: &'a [Columns],
}

impl<'a> MultiWithPointResiduals<'a> {
    /// `multi`, whose files were made from `data` in order, to be written with per-point
    /// residuals.
    pub fn new(multi: &'a MultiAnalysis, data: &'a [Columns]) -> Self {
        Self { multi, data }
    }
}

impl Fit {
    /// The residual of the point `(rate_dps, volts)` under this fit, exactly as the fit's
    /// own `residuals` hold it.
    pub fn residual_at(&self, rate_dps: f64, volts: f64) -> Residual {
        let fitted = predict(self.model, &self.coefficients, rate_dps);
        Residual {
            rate_dps,
            volts,
            fitted,
            residual: volts - fitted,
        }
    }
}

/// Field counts of the structs mirrored, for `serialize_struct` (a hint; serde_json writes
/// `{}` at once for 0, so it must not be 0).
const ANALYSIS_FIELDS: usize = 13;
const MULTI_FIELDS: usize = 3;
const FIT_FIELDS: usize = 18;

impl Serialize for WithPointResiduals<'_> {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let a = self.analysis;
        // Already per point: the analysis as it is.
        if a.residual_detail == ResidualDetail::PerPoint {
            return a.serialize(serializer);
        }
        // The fields of `Analysis`, in its order, with its skip rules.
        let mut s = serializer.serialize_struct("Analysis", ANALYSIS_FIELDS)?;
        if let Some(v) = &a.source {
            s.serialize_field("source", v)?;
        }
        s.serialize_field("points", &a.points)?;
        if let Some(v) = &a.distinct_rates {
            s.serialize_field("distinct_rates", v)?;
        }
        s.serialize_field("residual_detail", &ResidualDetail::PerPoint)?;
        if let Some(v) = &a.rate_bins {
            s.serialize_field("rate_bins", v)?;
        }
        let fits: Vec<FitPoints<'_>> = a
            .fits
            .iter()
            .map(|fit| FitPoints {
                fit,
                data: self.data,
            })
            .collect();
        s.serialize_field("fits", &fits)?;
        s.serialize_field("skipped", &a.skipped)?;
        if let Some(v) = &a.best_model {
            s.serialize_field("best_model", v)?;
        }
        if let Some(v) = &a.model_selection {
            s.serialize_field("model_selection", v)?;
        }
        s.serialize_field("metrics", &a.metrics)?;
        if let Some(v) = &a.error_surface {
            s.serialize_field("error_surface", v)?;
        }
        if let Some(v) = &a.uncertainty {
            s.serialize_field("uncertainty", v)?;
        }
        if let Some(v) = &a.acceptance {
            s.serialize_field("acceptance", v)?;
        }
        s.end()
    }
}

impl Serialize for MultiWithPointResiduals<'_> {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let m = self.multi;
        let files: Vec<WithPointResiduals<'_>> = m
            .files
            .iter()
            .zip(self.data)
            .map(|(analysis, data)| WithPointResiduals { analysis, data })
            .collect();
        let mut s = serializer.serialize_struct("MultiAnalysis", MULTI_FIELDS)?;
        s.serialize_field("files", &files)?;
        s.serialize_field("scale_factors", &m.scale_factors)?;
        s.serialize_field("repeatability_ppm", &m.repeatability_ppm)?;
        s.end()
    }
}

/// One fit with its per-point residuals computed from the data.
struct FitPoints<'a> {
    fit: &'a Fit,
    data: &'a Columns,
}

impl Serialize for FitPoints<'_> {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let f = self.fit;
        // The fields of `Fit`, in its order, with its skip rules; `rate_residuals` is empty
        // in a per-point document, so skipped.
        let mut s = serializer.serialize_struct("Fit", FIT_FIELDS)?;
        s.serialize_field("method", &f.method)?;
        s.serialize_field("model", &f.model)?;
        s.serialize_field("scale_factor", &f.scale_factor)?;
        s.serialize_field("bias", &f.bias)?;
        s.serialize_field("coefficients", &f.coefficients)?;
        s.serialize_field("std_errors", &f.std_errors)?;
        s.serialize_field("weighted", &f.weighted)?;
        s.serialize_field("sse", &f.sse)?;
        if let Some(v) = &f.chi_squared {
            s.serialize_field("chi_squared", v)?;
        }
        s.serialize_field("rms_residual", &f.rms_residual)?;
        if let Some(v) = &f.residual_std_error {
            s.serialize_field("residual_std_error", v)?;
        }
        s.serialize_field("max_abs_residual", &f.max_abs_residual)?;
        s.serialize_field("r_squared", &f.r_squared)?;
        s.serialize_field(
            "residuals",
            &Points {
                fit: f,
                data: self.data,
            },
        )?;
        if let Some(v) = &f.passes {
            s.serialize_field("passes", v)?;
        }
        s.serialize_field("converged", &f.converged)?;
        if let Some(v) = &f.neuron {
            s.serialize_field("neuron", v)?;
        }
        s.end()
    }
}

/// The residuals of one fit at every point of the data, in data order.
struct Points<'a> {
    fit: &'a Fit,
    data: &'a Columns,
}

impl Serialize for Points<'_> {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let n = self.data.len();
        let mut seq = serializer.serialize_seq(Some(n))?;
        for (&w, &d) in self.data.rates[..n].iter().zip(&self.data.volts[..n]) {
            seq.serialize_element(&self.fit.residual_at(w, d))?;
        }
        seq.end()
    }
}
