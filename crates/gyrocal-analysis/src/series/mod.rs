//! The analysis of a temperature series: each temperature's sweep fitted with the sweep's own
//! fit (`gyrocal-fit`: K, K0, the nonlinearity, their U from the budget), each bias record's
//! mean as a rate, then K and the bias modelled in the gyro's measured temperature
//! ([`crate::tempco`]), the sensitivities over the range, the hysteresis where a setpoint is
//! revisited, the temperature's min/mean/max during each test, and the verdict against the
//! limits on the sensitivities. [`analyse_input`] is the pure part, on a [`SeriesInput`];
//! `series.json` ([`SeriesDocument`]) is what it returns.

mod document;
mod run;
#[cfg(test)]
mod tests;

pub use run::{Kind, analyse_run_data, input_from_run, load_document, write_document};

pub use document::{
    CatalogPoint, CatalogSeries, SERIES_FORMAT, Sensitivity, SeriesDocument, SeriesPoint,
    TempcoVerdict,
};

use crate::tempco::{self, Hysteresis, TempFit, TempPoint};

/// The bias record at one temperature: readings at 0 °/s.
#[derive(Debug, Clone, PartialEq)]
pub struct BiasRecord {
    /// Mean output, V.
    pub mean_v: f64,
    /// Standard deviation of the readings, V.
    pub std_v: f64,
    /// Number of readings.
    pub n: u64,
}

/// What was measured at one temperature.
#[derive(Debug, Clone, PartialEq)]
pub struct PointInput {
    /// 0-based index into `temperatures_c`.
    pub series_point: usize,
    /// The setpoint, °C.
    pub setpoint_c: f64,
    /// The gyro's temperature during the point's tests: min, mean, max, °C.
    pub temp_min_c: f64,
    /// Mean, °C.
    pub temp_mean_c: f64,
    /// Max, °C.
    pub temp_max_c: f64,
    /// The sweep's steps (rate, mean volts, spread, count), when a sweep was run.
    pub sweep: Option<gyrocal_fit::Dataset>,
    /// The bias record, when one was run.
    pub bias: Option<BiasRecord>,
}

/// Limits on the sensitivities (the plan's `[acceptance]` keys of the same names).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct TempcoLimits {
    /// Largest |K's sensitivity|, ppm/°C.
    pub k_tempco_ppm_per_c_max: Option<f64>,
    /// Largest |bias sensitivity|, °/h/°C.
    pub bias_tempco_dph_per_c_max: Option<f64>,
}

/// A whole series, as measured.
#[derive(Debug, Clone, PartialEq)]
pub struct SeriesInput {
    /// Every temperature in the order measured.
    pub points: Vec<PointInput>,
    /// The instruments' accuracies for each sweep's uncertainty budget.
    pub uncertainty: gyrocal_fit::UncertaintyInputs,
    /// The limits on the sensitivities.
    pub limits: TempcoLimits,
}

/// How to analyse a series.
#[derive(Debug, Clone, Default)]
pub struct Options {
    /// The fit of each temperature's sweep (the sweep's defaults).
    pub fit: gyrocal_fit::Options,
    /// The temperature K is referred to for ppm/°C; the first point's setpoint when absent.
    pub reference_c: Option<f64>,
}

/// Why a series could not be analysed.
#[derive(Debug, thiserror::Error)]
pub enum SeriesError {
    /// No temperature was measured.
    #[error("{source_name}: the series has no measured temperature")]
    Empty {
        /// The run or file, for the message.
        source_name: String,
    },
    /// A temperature's figures are not numbers.
    #[error("{source_name}: series point {series_point} ({setpoint_c} °C): {message}")]
    Point {
        /// The run or file.
        source_name: String,
        /// The point.
        series_point: usize,
        /// Its setpoint.
        setpoint_c: f64,
        /// What is wrong.
        message: String,
    },
    /// `series.json` could not be read back.
    #[error("{}: {message}", path.display())]
    Document {
        /// The file.
        path: std::path::PathBuf,
        /// What is wrong.
        message: String,
    },
}

impl SeriesError {
    /// Whose fault it is: always the input's (the data or the file cannot be analysed).
    pub fn kind(&self) -> crate::ErrorKind {
        crate::ErrorKind::Input
    }
}

/// One temperature's sweep and bias figures.
fn analyse_point(p: &PointInput, input: &SeriesInput, opts: &Options) -> SeriesPoint {
    let mut out = SeriesPoint {
        series_point: p.series_point,
        setpoint_c: p.setpoint_c,
        temp_min_c: p.temp_min_c,
        temp_mean_c: p.temp_mean_c,
        temp_max_c: p.temp_max_c,
        k: None,
        u_k: None,
        u_k_weight: None,
        bias_dph: None,
        u_bias_dph: None,
        bias_from: None,
        nonlinearity_ppm: None,
        u_nonlinearity_ppm: None,
        best_model: None,
        notes: Vec::new(),
    };
    if let Some(data) = &p.sweep {
        match gyrocal_fit::analyze(data, &opts.fit) {
            Ok(mut a) => {
                a.attach_uncertainty(&input.uncertainty);
                let m = &a.metrics;
                let finite = |v: f64| v.is_finite().then_some(v);
                // a U of zero is no U (a line through two rates has no residual, and the
                // budget then says 0): kept as none, so no model weighs the point as exact
                let u = |key: &str| usable_u(a.expanded_uncertainty(key));
                out.k = finite(m.scale_factor);
                out.u_k = u("scale_factor");
                out.u_k_weight = a
                    .fit(gyrocal_fit::Method::LeastSquares, gyrocal_fit::Model::Linear)
                    .and_then(|f| prior_u_k(f, a.points))
                    .or(out.u_k);
                out.bias_dph = finite(m.bias_dph);
                out.u_bias_dph = u("bias_dph");
                out.bias_from = out.bias_dph.map(|_| "sweep".to_string());
                out.nonlinearity_ppm = finite(m.nonlinearity_ppm);
                out.u_nonlinearity_ppm = u("nonlinearity_ppm").or_else(|| {
                    usable_u(
                        m.nonlinearity_uncertainty
                            .as_ref()
                            .map(|u| u.expanded_uncertainty_ppm),
                    )
                });
                if out.k.is_some() && out.u_k.is_none() {
                    out.notes.push(format!(
                        "K has no uncertainty: a sweep of {} distinct rate{} leaves the line no \
                         residual (at least 3 rates are needed for a tempco with uncertainty)",
                        distinct_rates(data),
                        if distinct_rates(data) == 1 { "" } else { "s" }
                    ));
                }
                out.best_model = a.best_model.map(|m| m.to_string());
            }
            Err(e) => out.notes.push(format!("sweep not fitted: {e}")),
        }
    }
    if let Some(b) = &p.bias {
        match bias_from_record(b, out.k, out.u_k) {
            Ok((v, u)) => {
                out.bias_dph = Some(v);
                out.u_bias_dph = Some(u);
                out.bias_from = Some("bias record".to_string());
            }
            Err(why) => out.notes.push(why),
        }
    }
    out
}

/// An uncertainty that can weigh a point: finite and positive.
fn usable_u(u: Option<f64>) -> Option<f64> {
    u.filter(|u| u.is_finite() && *u > 0.0)
}

/// The distinct rates of a sweep.
fn distinct_rates(data: &gyrocal_fit::Dataset) -> usize {
    let mut rates: Vec<f64> = data.points.iter().map(|p| p.rate_dps).collect();
    rates.sort_by(f64::total_cmp);
    rates.dedup();
    rates.len()
}

/// K's U (k = 2) from a weighted line's covariance before its scaling by the residual
/// scatter: `se(K)·√(ν/χ²)`; `None` for an unweighted fit or one without residual freedom.
fn prior_u_k(f: &gyrocal_fit::Fit, points: usize) -> Option<f64> {
    let se = f.std_errors.k1?;
    let chi2 = f.chi_squared.filter(|c| f.weighted && c.is_finite() && *c > 0.0)?;
    let dof = points.checked_sub(2).filter(|d| *d > 0)?;
    let u = 2.0 * se * (dof as f64 / chi2).sqrt();
    (u.is_finite() && u > 0.0).then_some(u)
}

/// The bias record's mean as a rate, `V̄/K·3600` °/h, with U from the mean's standard error
/// and K's U (k = 2). Needs the K of the same temperature (a sweep there).
fn bias_from_record(
    b: &BiasRecord,
    k: Option<f64>,
    u_k: Option<f64>,
) -> Result<(f64, f64), String> {
    let Some(k) = k.filter(|k| *k != 0.0) else {
        return Err(
            "bias record not turned into °/h: no scale factor at this temperature (measure = \"both\" gives one)"
                .to_string(),
        );
    };
    if !(b.mean_v.is_finite() && b.std_v.is_finite()) || b.n < 2 {
        return Err(format!(
            "bias record unusable: mean {} V, std {} V over {} readings",
            b.mean_v, b.std_v, b.n
        ));
    }
    let bias = b.mean_v / k * 3600.0;
    let u_mean = b.std_v / (b.n as f64).sqrt();
    let u_k_std = u_k.unwrap_or(0.0) / 2.0;
    let rel = ((u_mean / b.mean_v).powi(2) + (u_k_std / k).powi(2)).sqrt();
    let u_std = if b.mean_v == 0.0 {
        u_mean / k.abs() * 3600.0
    } else {
        bias.abs() * rel
    };
    Ok((bias, 2.0 * u_std))
}

fn temp_points(
    points: &[SeriesPoint],
    y: impl Fn(&SeriesPoint) -> Option<(f64, f64)>,
) -> Vec<(f64, TempPoint)> {
    points
        .iter()
        .filter_map(|p| {
            let (y, u) = y(p)?;
            (y.is_finite() && u.is_finite() && u > 0.0).then_some((
                p.setpoint_c,
                TempPoint {
                    t_c: p.temp_mean_c,
                    y,
                    u,
                },
            ))
        })
        .collect()
}

fn model(
    visits: &[(f64, TempPoint)],
    what: &str,
    points: &[SeriesPoint],
    notes: &mut Vec<String>,
) -> Option<TempFit> {
    let pts: Vec<TempPoint> = visits.iter().map(|v| v.1).collect();
    match tempco::fit(&pts) {
        Ok(f) => Some(f),
        Err(e) => {
            let why = match (&e, without_u(points, what)) {
                (tempco::TempcoError::TooFewTemperatures(_), n) if n > 0 => format!(
                    "{n} of {} temperatures have {what} without an uncertainty, which a model \
                     weighs by: a sweep needs at least 3 distinct rates for a tempco with \
                     uncertainty (a line through 2 rates has no residual, so its K has no U)",
                    points.len()
                ),
                _ => e.to_string(),
            };
            notes.push(format!("no model of {what} in temperature: {why}"));
            None
        }
    }
}

/// How many points have the figure `what` (`K`, `the bias`) but no U: a model in temperature
/// leaves them out, and its own error ("at least two distinct temperatures, 0 given") would
/// not say why (a series measured at four temperatures with sweeps of two rates).
fn without_u(points: &[SeriesPoint], what: &str) -> usize {
    points
        .iter()
        .filter(|p| match what {
            "K" => p.k.is_some() && p.u_k.is_none(),
            _ => p.bias_dph.is_some() && p.u_bias_dph.is_none(),
        })
        .count()
}

fn distinct(visits: &[(f64, TempPoint)]) -> usize {
    let pts: Vec<TempPoint> = visits.iter().map(|v| v.1).collect();
    tempco::temperatures_apart(&pts)
}

fn judge(key: &str, max: f64, s: Option<&Sensitivity>) -> TempcoVerdict {
    let verdict = match s {
        Some(s) if s.value.abs() + s.u <= max => "pass",
        Some(s) if s.value.abs() - s.u > max => "fail",
        _ => "indeterminate",
    };
    TempcoVerdict {
        limit_key: key.to_string(),
        max,
        value: s.map(|s| s.value.abs()),
        u: s.map(|s| s.u),
        verdict: verdict.to_string(),
    }
}

fn largest(h: &[Hysteresis]) -> Option<f64> {
    h.iter()
        .map(|h| h.difference)
        .max_by(|a, b| a.abs().total_cmp(&b.abs()))
}

/// Analyses a series (see the module's notes). `source_name` names the run in errors.
pub fn analyse_input(
    input: &SeriesInput,
    opts: &Options,
    source_name: &str,
) -> Result<SeriesDocument, SeriesError> {
    let Some(first) = input.points.first() else {
        return Err(SeriesError::Empty {
            source_name: source_name.to_string(),
        });
    };
    for p in &input.points {
        let ts = [p.temp_min_c, p.temp_mean_c, p.temp_max_c];
        if ts.iter().any(|t| !t.is_finite()) || !p.setpoint_c.is_finite() {
            return Err(SeriesError::Point {
                source_name: source_name.to_string(),
                series_point: p.series_point,
                setpoint_c: p.setpoint_c,
                message: "its temperatures are not numbers".to_string(),
            });
        }
    }
    let reference_c = opts.reference_c.unwrap_or(first.setpoint_c);
    let points: Vec<SeriesPoint> = input
        .points
        .iter()
        .map(|p| analyse_point(p, input, opts))
        .collect();
    let mut notes = Vec::new();
    // K weighted by its prior U (see `SeriesPoint::u_k_weight`); the hysteresis compares
    // two visits with their stated U
    let k_weighted = temp_points(&points, |p| Some((p.k?, p.u_k_weight.or(p.u_k)?)));
    let k_visits = temp_points(&points, |p| Some((p.k?, p.u_k?)));
    let b_visits = temp_points(&points, |p| Some((p.bias_dph?, p.u_bias_dph?)));
    // with two temperatures the model has no residual to scale by: the stated U then
    let k_model = if k_weighted.len() == k_visits.len() && distinct(&k_visits) > 2 {
        model(&k_weighted, "K", &points, &mut notes)
    } else {
        model(&k_visits, "K", &points, &mut notes)
    };
    let bias_model = model(&b_visits, "the bias", &points, &mut notes);
    let k_tempco = k_model.as_ref().and_then(|f| {
        let m = f.chosen();
        let (v, u) = m.relative_sensitivity_ppm(reference_c)?;
        Some(Sensitivity {
            value: v,
            u,
            coverage_factor: m.coverage_factor,
            unit: "ppm/°C".to_string(),
            model_order: m.order,
        })
    });
    let bias_tempco = bias_model.as_ref().map(|f| {
        let m = f.chosen();
        let (v, u) = m.sensitivity();
        Sensitivity {
            value: v,
            u,
            coverage_factor: m.coverage_factor,
            unit: "°/h/°C".to_string(),
            model_order: m.order,
        }
    });
    // K's hysteresis in ppm of the first visit's K
    let hysteresis_k_ppm: Vec<Hysteresis> =
        tempco::hysteresis(&k_visits, k_model.as_ref().map(TempFit::chosen))
            .into_iter()
            .map(|mut h| {
                let k1 = k_visits[h.first].1.y;
                h.difference *= 1e6 / k1;
                h.u *= 1e6 / k1.abs();
                h
            })
            .collect();
    let hysteresis_bias_dph =
        tempco::hysteresis(&b_visits, bias_model.as_ref().map(TempFit::chosen));
    let mut acceptance = Vec::new();
    if let Some(max) = input.limits.k_tempco_ppm_per_c_max {
        acceptance.push(judge("k_tempco_ppm_per_c_max", max, k_tempco.as_ref()));
    }
    if let Some(max) = input.limits.bias_tempco_dph_per_c_max {
        acceptance.push(judge(
            "bias_tempco_dph_per_c_max",
            max,
            bias_tempco.as_ref(),
        ));
    }
    let verdict = (!acceptance.is_empty()).then(|| {
        ["fail", "indeterminate"]
            .into_iter()
            .find(|v| acceptance.iter().any(|a| a.verdict == *v))
            .unwrap_or("pass")
            .to_string()
    });
    let catalog = CatalogSeries {
        points: points
            .iter()
            .map(|p| CatalogPoint {
                series_point: p.series_point,
                setpoint_c: p.setpoint_c,
                temp_min_c: p.temp_min_c,
                temp_mean_c: p.temp_mean_c,
                temp_max_c: p.temp_max_c,
                k: p.k,
                u_k: p.u_k,
                bias_dph: p.bias_dph,
                u_bias_dph: p.u_bias_dph,
                nonlinearity_ppm: p.nonlinearity_ppm,
            })
            .collect(),
        k_tempco_ppm_per_c: k_tempco.as_ref().map(|s| s.value),
        u_k_tempco_ppm_per_c: k_tempco.as_ref().map(|s| s.u),
        bias_tempco_dph_per_c: bias_tempco.as_ref().map(|s| s.value),
        u_bias_tempco_dph_per_c: bias_tempco.as_ref().map(|s| s.u),
        k_model_order: k_model.as_ref().map(|f| f.chosen().order),
        bias_model_order: bias_model.as_ref().map(|f| f.chosen().order),
        hysteresis_k_ppm: largest(&hysteresis_k_ppm),
        hysteresis_bias_dph: largest(&hysteresis_bias_dph),
        t_min_c: points.iter().map(|p| p.temp_min_c).reduce(f64::min),
        t_max_c: points.iter().map(|p| p.temp_max_c).reduce(f64::max),
    };
    Ok(SeriesDocument {
        format: SERIES_FORMAT,
        reference_c,
        points,
        k_model,
        bias_model,
        k_tempco_ppm_per_c: k_tempco,
        bias_tempco_dph_per_c: bias_tempco,
        hysteresis_k_ppm,
        hysteresis_bias_dph,
        acceptance,
        verdict,
        notes,
        catalog,
    })
}
