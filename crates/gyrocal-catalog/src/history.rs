//! A gyro's calibration history: repeatability from day to day, trends, control bands.

use serde::Serialize;

use crate::record::Results;
use crate::rows::Calibration;

/// A quantity followed over the calibrations.
#[derive(Debug, Clone, Copy)]
pub struct Quantity {
    /// Name, as in acceptance checks and JSON (`scale_factor`, `bias_dph`, ...).
    pub name: &'static str,
    /// Label on plots.
    pub label: &'static str,
    /// Unit.
    pub unit: &'static str,
    value: fn(&Results) -> Option<f64>,
    uncertainty: fn(&Results) -> Option<f64>,
}

/// The quantities of a history, in the order shown.
pub const QUANTITIES: [Quantity; 14] = [
    Quantity {
        name: "scale_factor",
        label: "Scale factor K",
        unit: "V/(°/s)",
        value: |r| r.scale_factor,
        uncertainty: |r| r.u_scale_factor,
    },
    Quantity {
        name: "bias_dph",
        label: "Bias",
        unit: "°/h",
        value: |r| r.bias_dph,
        uncertainty: |r| r.u_bias_dph,
    },
    Quantity {
        name: "bias_v",
        label: "Bias K0",
        unit: "V",
        value: |r| r.bias_v,
        uncertainty: |r| r.u_bias_v,
    },
    Quantity {
        name: "k_pos",
        label: "Scale factor K+",
        unit: "V/(°/s)",
        value: |r| r.k_pos,
        uncertainty: |r| r.u_k_pos,
    },
    Quantity {
        name: "k_neg",
        label: "Scale factor K−",
        unit: "V/(°/s)",
        value: |r| r.k_neg,
        uncertainty: |r| r.u_k_neg,
    },
    Quantity {
        name: "k2",
        label: "Second-order coefficient K2",
        unit: "V/(°/s)²",
        value: |r| r.k2,
        uncertainty: |_| None,
    },
    Quantity {
        name: "nonlinearity_ppm",
        label: "Nonlinearity",
        unit: "ppm",
        value: |r| r.nonlinearity_ppm,
        uncertainty: |_| None,
    },
    Quantity {
        name: "asymmetry_ppm",
        label: "Asymmetry (GJB)",
        unit: "ppm",
        value: |r| r.asymmetry_ppm,
        uncertainty: |_| None,
    },
    Quantity {
        name: "asymmetry_common_k2_ppm",
        label: "Asymmetry (common K2)",
        unit: "ppm",
        value: |r| r.asymmetry_common_k2_ppm,
        uncertainty: |_| None,
    },
    Quantity {
        name: "repeatability_ppm",
        label: "Repeatability within a run",
        unit: "ppm",
        value: |r| r.repeatability_ppm,
        uncertainty: |_| None,
    },
    // a drift test's (IEEE 952 terms from its Allan analysis)
    Quantity {
        name: "arw_deg_rt_h",
        label: "Angle random walk N (drift test)",
        unit: "°/√h",
        value: |r| r.arw_deg_rt_h,
        uncertainty: |r| r.u_arw_deg_rt_h,
    },
    Quantity {
        name: "bias_instability_dph",
        label: "Bias instability B (drift test)",
        unit: "°/h",
        value: |r| r.bias_instability_dph,
        uncertainty: |r| r.u_bias_instability_dph,
    },
    Quantity {
        name: "rrw_dph_rt_h",
        label: "Rate random walk K (drift test)",
        unit: "°/h/√h",
        value: |r| r.rrw_dph_rt_h,
        uncertainty: |r| r.u_rrw_dph_rt_h,
    },
    Quantity {
        name: "drift_bias_dph",
        label: "Bias (drift test)",
        unit: "°/h",
        value: |r| r.drift_bias_dph,
        uncertainty: |r| r.u_drift_bias_dph,
    },
];

/// The acceptance check whose limits belong on a series. `asymmetry_ppm` limits the unbiased
/// common-K2 asymmetry (the figure a report presents as the result), and the GJB two-line figure,
/// stored as `asymmetry_ppm` in the catalog, has its own key, `asymmetry_gjb_ppm`; the other
/// quantities share their check's name. (A check recorded before the keys were split judged
/// the GJB figure: its limits then stand on the common-K2 series.)
fn limited_by(series: &str) -> &str {
    match series {
        "asymmetry_ppm" => "asymmetry_gjb_ppm",
        "asymmetry_common_k2_ppm" => "asymmetry_ppm",
        other => other,
    }
}

/// Day-to-day repeatability over the calibrations.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Repeatability {
    /// Calibrations with a scale factor.
    pub n: usize,
    /// Mean K, V/(°/s).
    pub scale_factor_mean: Option<f64>,
    /// `std(K_i, ddof = 1) / mean(K_i)`, ppm (two calibrations or more).
    pub scale_factor_ppm: Option<f64>,
    /// Mean bias, °/h.
    pub bias_dph_mean: Option<f64>,
    /// `std(bias_i, ddof = 1)`, °/h.
    pub bias_dph: Option<f64>,
}

/// One calibration's value of a quantity.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TrendPoint {
    /// The run.
    pub run_id: String,
    /// When it started.
    pub started_utc: String,
    /// The value.
    pub value: f64,
    /// Its expanded uncertainty, when known.
    pub expanded_uncertainty: Option<f64>,
}

/// Acceptance limits of a quantity (from the latest calibration that had them).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Limits {
    /// Lower limit.
    pub min: Option<f64>,
    /// Upper limit.
    pub max: Option<f64>,
}

/// The control band: mean ± 3σ of the calibrations before the latest.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Band {
    /// Calibrations it is computed from.
    pub n: usize,
    /// Their mean.
    pub mean: f64,
    /// Their standard deviation (ddof = 1).
    pub sigma: f64,
    /// mean − 3σ.
    pub low: f64,
    /// mean + 3σ.
    pub high: f64,
}

/// A quantity over time.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Trend {
    /// Name (`scale_factor`, ...).
    pub quantity: String,
    /// Label.
    pub label: String,
    /// Unit.
    pub unit: String,
    /// The values, oldest first.
    pub points: Vec<TrendPoint>,
    /// Acceptance limits, when a calibration had them.
    pub limits: Option<Limits>,
    /// Control band from the earlier calibrations (at least two before the latest).
    pub band: Option<Band>,
    /// Whether the latest value is outside the band.
    pub latest_outside_band: bool,
}

/// A gyro's history.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct History {
    /// The gyro's serial.
    pub serial: String,
    /// Whether simulated runs were included.
    pub include_simulated: bool,
    /// The complete calibrations, oldest first.
    pub calibrations: Vec<Calibration>,
    /// Day-to-day repeatability.
    pub repeatability: Repeatability,
    /// One trend per quantity that has values.
    pub trends: Vec<Trend>,
    /// Warnings (a latest value outside its control band).
    pub warnings: Vec<String>,
}

fn mean_std(v: &[f64]) -> Option<(f64, f64)> {
    if v.len() < 2 {
        return None;
    }
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
    Some((mean, var.sqrt()))
}

impl History {
    /// The history of `serial` from its calibrations (oldest first).
    pub fn of(serial: &str, include_simulated: bool, calibrations: Vec<Calibration>) -> History {
        let values = |f: fn(&Results) -> Option<f64>| -> Vec<f64> {
            calibrations
                .iter()
                .filter_map(|c| c.results.as_ref().and_then(f))
                .filter(|x| x.is_finite())
                .collect()
        };
        let ks = values(|r| r.scale_factor);
        let biases = values(|r| r.bias_dph);
        let k_stats = mean_std(&ks);
        let repeatability = Repeatability {
            n: ks.len(),
            scale_factor_mean: k_stats.map(|(m, _)| m).or_else(|| ks.first().copied()),
            scale_factor_ppm: k_stats
                .filter(|(m, _)| *m != 0.0)
                .map(|(m, s)| s / m.abs() * 1e6),
            bias_dph_mean: mean_std(&biases)
                .map(|(m, _)| m)
                .or_else(|| biases.first().copied()),
            bias_dph: mean_std(&biases).map(|(_, s)| s),
        };
        let mut trends = Vec::new();
        let mut warnings = Vec::new();
        for q in QUANTITIES {
            let points: Vec<TrendPoint> = calibrations
                .iter()
                .filter_map(|c| {
                    let r = c.results.as_ref()?;
                    let value = (q.value)(r).filter(|x| x.is_finite())?;
                    Some(TrendPoint {
                        run_id: c.run.id.clone(),
                        started_utc: c.run.started_utc.clone(),
                        value,
                        expanded_uncertainty: (q.uncertainty)(r),
                    })
                })
                .collect();
            if points.is_empty() {
                continue;
            }
            let limits = calibrations.iter().rev().find_map(|c| {
                let check = c.checks.iter().find(|k| k.quantity == limited_by(q.name))?;
                (check.min.is_some() || check.max.is_some()).then_some(Limits {
                    min: check.min,
                    max: check.max,
                })
            });
            let earlier: Vec<f64> = points[..points.len() - 1].iter().map(|p| p.value).collect();
            let band = mean_std(&earlier).map(|(mean, sigma)| Band {
                n: earlier.len(),
                mean,
                sigma,
                low: mean - 3.0 * sigma,
                high: mean + 3.0 * sigma,
            });
            let latest = points.last();
            let outside = match (&band, latest) {
                (Some(b), Some(p)) => p.value < b.low || p.value > b.high,
                _ => false,
            };
            if let (true, Some(b), Some(p)) = (outside, &band, latest) {
                warnings.push(format!(
                    "{serial}: the latest {} ({:.6e} {}, {}) is outside the control band \
                     {:.6e} .. {:.6e} (mean ± 3σ of the {} earlier calibrations)",
                    q.label, p.value, q.unit, p.started_utc, b.low, b.high, b.n
                ));
            }
            trends.push(Trend {
                quantity: q.name.to_string(),
                label: q.label.to_string(),
                unit: q.unit.to_string(),
                points,
                limits,
                band,
                latest_outside_band: outside,
            });
        }
        History {
            serial: serial.to_string(),
            include_simulated,
            calibrations,
            repeatability,
            trends,
            warnings,
        }
    }
}
