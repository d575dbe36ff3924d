//! A series run directory read into a [`SeriesInput`] (steps.csv's `series_point`,
//! `setpoint_c`, `temp_*_c` and `bias_record` columns), its analysis written as
//! `series.json` through the run directory, and the kind's [`Kind`] for the one dispatch.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use gyrocal_files::WriteResult;
use gyrocal_files::plan::Plan;
use gyrocal_files::rundir::{Manifest, RunData, RunDir, RunError, SERIES_JSON, STEPS_CSV, StepRecord};

use super::{
    BiasRecord, Options, PointInput, SeriesDocument, SeriesError, SeriesInput, TempcoLimits,
    analyse_input,
};
use crate::{AnalysisError, Figures, KindAnalysis};

/// The steps of one series point, in file order.
struct Gathered<'a> {
    setpoint_c: f64,
    sweep: Vec<&'a StepRecord>,
    bias: Vec<&'a StepRecord>,
}

/// The gyro's temperature over `rows`: (min, mean weighted by the readings, max); `None`
/// when no row has one.
fn temperatures(rows: &[&StepRecord]) -> Option<(f64, f64, f64)> {
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    let (mut sum, mut weight) = (0.0, 0.0);
    for r in rows {
        let Some(c) = r.series else { continue };
        if let Some(v) = c.temp_min_c.filter(|v| v.is_finite()) {
            lo = lo.min(v);
        }
        if let Some(v) = c.temp_max_c.filter(|v| v.is_finite()) {
            hi = hi.max(v);
        }
        if let Some(v) = c.temp_mean_c.filter(|v| v.is_finite()) {
            let w = r.n.max(1) as f64;
            sum += v * w;
            weight += w;
        }
    }
    (weight > 0.0 && lo.is_finite() && hi.is_finite()).then(|| (lo, sum / weight, hi))
}

/// The bias record of a point from its rows at 0 °/s: readings pooled (mean weighted by
/// count; the spread pooled within and between rows).
fn pooled_bias(rows: &[&StepRecord]) -> Option<BiasRecord> {
    let n: u64 = rows.iter().map(|r| r.n).sum();
    if n == 0 {
        return None;
    }
    let mean = rows.iter().map(|r| r.volts * r.n as f64).sum::<f64>() / n as f64;
    let ss: f64 = rows
        .iter()
        .map(|r| {
            let s = r.volts_std.unwrap_or(0.0);
            (r.n.saturating_sub(1)) as f64 * s * s + r.n as f64 * (r.volts - mean).powi(2)
        })
        .sum();
    let std_v = if n > 1 { (ss / (n - 1) as f64).sqrt() } else { 0.0 };
    Some(BiasRecord {
        mean_v: mean,
        std_v,
        n,
    })
}

/// The series as measured in a run directory read as `data` (`dir` names it in errors).
pub fn input_from_run(dir: &Path, data: &RunData) -> Result<SeriesInput, SeriesError> {
    let source = dir.join(STEPS_CSV).display().to_string();
    let mut points: BTreeMap<u32, Gathered<'_>> = BTreeMap::new();
    for s in &data.steps {
        let Some(c) = s.series else { continue };
        let g = points.entry(c.series_point).or_insert_with(|| Gathered {
            setpoint_c: c.setpoint_c,
            sweep: Vec::new(),
            bias: Vec::new(),
        });
        if c.bias_record {
            g.bias.push(s);
        } else {
            g.sweep.push(s);
        }
    }
    let mut out = Vec::with_capacity(points.len());
    for (sp, g) in points {
        let all: Vec<&StepRecord> = g.sweep.iter().chain(&g.bias).copied().collect();
        let Some((temp_min_c, temp_mean_c, temp_max_c)) = temperatures(&all) else {
            return Err(SeriesError::Point {
                source_name: source.clone(),
                series_point: sp as usize,
                setpoint_c: g.setpoint_c,
                message: "no gyro (product) temperature recorded during its tests (temp_min_c, temp_mean_c, temp_max_c empty)".into(),
            });
        };
        let sweep = (!g.sweep.is_empty()).then(|| {
            let owned: Vec<StepRecord> = g.sweep.iter().map(|s| (*s).clone()).collect();
            crate::sweep::dataset_from_steps(&owned, &source)
        });
        out.push(PointInput {
            series_point: sp as usize,
            setpoint_c: g.setpoint_c,
            temp_min_c,
            temp_mean_c,
            temp_max_c,
            sweep,
            bias: pooled_bias(&g.bias),
        });
    }
    // in the order measured: by the first step of each point
    out.sort_by_key(|p| {
        data.steps
            .iter()
            .position(|s| s.series.is_some_and(|c| c.series_point as usize == p.series_point))
            .unwrap_or(usize::MAX)
    });
    let (uncertainty, _missing) = crate::sweep::uncertainty_inputs(&data.manifest);
    let acc = data.manifest.plan.acceptance();
    Ok(SeriesInput {
        points: out,
        uncertainty,
        limits: TempcoLimits {
            k_tempco_ppm_per_c_max: acc.and_then(|a| a.k_tempco_ppm_per_c_max),
            bias_tempco_dph_per_c_max: acc.and_then(|a| a.bias_tempco_dph_per_c_max),
        },
    })
}

/// Analyses the series run in `dir` (read as `data`), writing nothing.
pub fn analyse_run_data(
    dir: &Path,
    data: &RunData,
    opts: &Options,
) -> Result<SeriesDocument, SeriesError> {
    let input = input_from_run(dir, data)?;
    let mut doc = analyse_input(&input, opts, &dir.display().to_string())?;
    let (_, missing) = crate::sweep::uncertainty_inputs(&data.manifest);
    doc.notes.extend(
        missing
            .into_iter()
            .map(|m| format!("not in each temperature's U: {m}")),
    );
    Ok(doc)
}

/// Writes `series.json` through the run directory (atomically, under its lock, its SHA-256
/// in the manifest); returns its path.
pub fn write_document(run: &mut dyn WriteResult, doc: &SeriesDocument) -> Result<PathBuf, RunError> {
    let json = serde_json::to_string_pretty(doc).map_err(|e| RunError::Protocol {
        path: run.dir().join(SERIES_JSON),
        message: format!("cannot serialise the series analysis: {e}"),
    })?;
    run.write_result(SERIES_JSON, json.as_bytes())?;
    Ok(run.dir().join(SERIES_JSON))
}

/// Reads a run's `series.json` back; `Ok(None)` when it has none.
pub fn load_document(dir: &Path) -> Result<Option<SeriesDocument>, SeriesError> {
    let path = dir.join(SERIES_JSON);
    let text = match std::fs::read_to_string(&path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => {
            return Err(SeriesError::Document {
                path,
                message: format!("cannot read: {e}"),
            });
        }
    };
    serde_json::from_str(&text)
        .map(Some)
        .map_err(|e| SeriesError::Document {
            path,
            message: format!("not a series analysis: {e}"),
        })
}

/// A temperature series' part of the one dispatch on the kind.
pub struct Kind;

impl KindAnalysis for Kind {
    type Output = SeriesDocument;
    type Options = Options;

    fn plan_warnings(plan: &Plan, path: &Path) -> Vec<String> {
        let mut out = Vec::new();
        let Some(s) = plan.series() else {
            return out;
        };
        let mut distinct = s.temperatures_c.clone();
        distinct.sort_by(f64::total_cmp);
        distinct.dedup();
        if distinct.len() < 2 {
            out.push(format!(
                "{}: [series] temperatures_c has {} distinct temperature{}: no model in temperature and no sensitivity can be computed (two at least; three for a quadratic)",
                path.display(),
                distinct.len(),
                if distinct.len() == 1 { "" } else { "s" }
            ));
        } else if distinct.len() == 2 {
            out.push(format!(
                "{}: [series] temperatures_c has 2 distinct temperatures: the sensitivities' U rests on the points' own U alone (no residual to check the line against)",
                path.display()
            ));
        }
        let mut rates = plan.rates_dps().to_vec();
        rates.sort_by(f64::total_cmp);
        rates.dedup();
        if s.measure.sweep() && rates.len() < 3 {
            out.push(format!(
                "{}: [plan] rates_dps has {} distinct rate{}: a line through fewer than 3 rates has no residual, so the sweep's K has no uncertainty at any temperature and the series gives no tempco with uncertainty: at least 3 rates per sweep are needed",
                path.display(),
                rates.len(),
                if rates.len() == 1 { "" } else { "s" }
            ));
        }
        if !s.measure.sweep() {
            out.push(format!(
                "{}: [series] measure = \"bias\": no sweep, so no scale factor at any temperature: the bias records stay in volts (no °/h, no bias sensitivity); measure = \"both\" gives them",
                path.display()
            ));
        }
        out
    }

    fn analyse(dir: &Path, data: &RunData, opts: &Options) -> Result<SeriesDocument, AnalysisError> {
        Ok(analyse_run_data(dir, data, opts)?)
    }

    fn analyse_run(run: &mut RunDir, opts: &Options) -> Result<SeriesDocument, AnalysisError> {
        let data = gyrocal_files::load(run.path())?;
        let doc = analyse_run_data(run.path(), &data, opts)?;
        write_document(run, &doc)?;
        Ok(doc)
    }

    fn figures(
        dir: &Path,
        _m: &Manifest,
        _fit: Option<&serde_json::Value>,
    ) -> Result<Option<Figures>, AnalysisError> {
        // the figures at the series' first temperature (the catalog keeps the whole series
        // from series.json's `catalog` member)
        let Some(doc) = load_document(dir)? else {
            return Ok(None);
        };
        let Some(p) = doc.points.first() else {
            return Ok(None);
        };
        Ok(Some(Figures {
            scale_factor: p.k,
            u_scale_factor: p.u_k,
            bias_dph: p.bias_dph,
            u_bias_dph: p.u_bias_dph,
            nonlinearity_ppm: p.nonlinearity_ppm,
            best_model: p.best_model.clone(),
            ..Figures::default()
        }))
    }
}
