//! A gyro's calibration history: repeatability from day to day, trends, control bands.
//!
//! **Plans told apart.** A repeatability or a control band compares calibrations of one plan;
//! calibrations of another plan (19 rates against 5) differ by more than drift, and mixing them
//! raises false alarms. Two calibrations follow the same plan here when they measured the same
//! kind of thing at the same demanded rates ([`plan_key`]): the plan hash is not the test,
//! because it covers the `[simulation]` section, so a different simulation seed (or simulated
//! gyro) would count as a different plan. A run whose steps the catalog does not hold is told
//! apart by its plan hash. The repeatability and every control band use the calibrations of
//! the latest calibration's plan only; the others stay in the tables and plots, and
//! [`History::warnings`] says how many were left out and why.
//!
//! **Control bands need [`MIN_BAND_POINTS`] earlier calibrations.** See there why.

use gyrocal_files::num::significant;
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
    value: fn(&Calibration) -> Option<f64>,
    uncertainty: fn(&Calibration) -> Option<f64>,
}

/// The quantities of a history, in the order shown.
pub const QUANTITIES: [Quantity; 18] = [
    Quantity {
        name: "scale_factor",
        label: "Scale factor K",
        unit: "V/(°/s)",
        value: |c| c.results.as_ref()?.scale_factor,
        uncertainty: |c| c.results.as_ref()?.u_scale_factor,
    },
    Quantity {
        name: "bias_dph",
        label: "Bias",
        unit: "°/h",
        value: |c| c.results.as_ref()?.bias_dph,
        uncertainty: |c| c.results.as_ref()?.u_bias_dph,
    },
    Quantity {
        name: "bias_v",
        label: "Bias K0",
        unit: "V",
        value: |c| c.results.as_ref()?.bias_v,
        uncertainty: |c| c.results.as_ref()?.u_bias_v,
    },
    Quantity {
        name: "k_pos",
        label: "Scale factor K+",
        unit: "V/(°/s)",
        value: |c| c.results.as_ref()?.k_pos,
        uncertainty: |c| c.results.as_ref()?.u_k_pos,
    },
    Quantity {
        name: "k_neg",
        label: "Scale factor K−",
        unit: "V/(°/s)",
        value: |c| c.results.as_ref()?.k_neg,
        uncertainty: |c| c.results.as_ref()?.u_k_neg,
    },
    Quantity {
        name: "k2",
        label: "Second-order coefficient K2",
        unit: "V/(°/s)²",
        value: |c| c.results.as_ref()?.k2,
        uncertainty: |_| None,
    },
    Quantity {
        name: "nonlinearity_ppm",
        label: "Nonlinearity",
        unit: "ppm",
        value: |c| c.results.as_ref()?.nonlinearity_ppm,
        uncertainty: |_| None,
    },
    Quantity {
        name: "asymmetry_ppm",
        label: "Asymmetry (GJB)",
        unit: "ppm",
        value: |c| c.results.as_ref()?.asymmetry_ppm,
        uncertainty: |_| None,
    },
    Quantity {
        name: "asymmetry_common_k2_ppm",
        label: "Asymmetry (common K2)",
        unit: "ppm",
        value: |c| c.results.as_ref()?.asymmetry_common_k2_ppm,
        uncertainty: |_| None,
    },
    Quantity {
        name: "repeatability_ppm",
        label: "Repeatability within a run",
        unit: "ppm",
        value: |c| c.results.as_ref()?.repeatability_ppm,
        uncertainty: |_| None,
    },
    // a drift test's (IEEE 952 terms from its Allan analysis)
    Quantity {
        name: "arw_deg_rt_h",
        label: "Angle random walk N (drift test)",
        unit: "°/√h",
        value: |c| c.results.as_ref()?.arw_deg_rt_h,
        uncertainty: |c| c.results.as_ref()?.u_arw_deg_rt_h,
    },
    Quantity {
        name: "bias_instability_dph",
        label: "Bias instability B (drift test)",
        unit: "°/h",
        value: |c| c.results.as_ref()?.bias_instability_dph,
        uncertainty: |c| c.results.as_ref()?.u_bias_instability_dph,
    },
    Quantity {
        name: "rrw_dph_rt_h",
        label: "Rate random walk K (drift test)",
        unit: "°/h/√h",
        value: |c| c.results.as_ref()?.rrw_dph_rt_h,
        uncertainty: |c| c.results.as_ref()?.u_rrw_dph_rt_h,
    },
    Quantity {
        name: "drift_bias_dph",
        label: "Bias (drift test)",
        unit: "°/h",
        value: |c| c.results.as_ref()?.drift_bias_dph,
        uncertainty: |c| c.results.as_ref()?.u_drift_bias_dph,
    },
    // a temperature series' (its series.json's `catalog` member): the sensitivities over the
    // series' range with their U, and the hysteresis where a temperature was revisited
    Quantity {
        name: "k_tempco_ppm_per_c",
        label: "Temperature sensitivity of K (series)",
        unit: "ppm/°C",
        value: |c| c.series.as_ref()?.k_tempco_ppm_per_c,
        uncertainty: |c| c.series.as_ref()?.u_k_tempco_ppm_per_c,
    },
    Quantity {
        name: "bias_tempco_dph_per_c",
        label: "Temperature sensitivity of the bias (series)",
        unit: "°/h/°C",
        value: |c| c.series.as_ref()?.bias_tempco_dph_per_c,
        uncertainty: |c| c.series.as_ref()?.u_bias_tempco_dph_per_c,
    },
    Quantity {
        name: "hysteresis_k_ppm",
        label: "Thermal hysteresis of K (series)",
        unit: "ppm",
        value: |c| c.series.as_ref()?.hysteresis_k_ppm,
        uncertainty: |_| None,
    },
    Quantity {
        name: "hysteresis_bias_dph",
        label: "Thermal hysteresis of the bias (series)",
        unit: "°/h",
        value: |c| c.series.as_ref()?.hysteresis_bias_dph,
        uncertainty: |_| None,
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

/// Earlier calibrations (of the same plan) a control band needs: with fewer, none is drawn or
/// judged.
///
/// Why 5: a band of mean ± 3σ is meant to flag about 3 in 1000 calibrations of a gyro that has
/// not changed, but σ estimated from n earlier values is itself uncertain, and a new value of
/// an unchanged gyro falls outside mean ± 3s with the probability of a Student t with n − 1
/// degrees of freedom beyond 3/√(1 + 1/n): 25 % with 2 earlier calibrations (the false alarms
/// the issue saw), 12 % with 3, 7.5 % with 4, 5.2 % with 5, 2.5 % with 8. From 5 on a warning
/// is rare enough to be worth reading; a lab that wants fewer false alarms waits for more.
pub const MIN_BAND_POINTS: usize = 5;

/// A plan as the history compares them (see the module docs): the kind of test and the rates
/// it demanded, rounded to a nano-degree per second.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum PlanKey {
    /// By kind and demanded rates.
    Rates(String, Vec<i64>),
    /// By plan hash (no steps in the catalog).
    Hash(String),
}

/// The plan a calibration followed, as the history compares them.
pub fn plan_key(c: &Calibration) -> PlanKey {
    if c.rates_dps.is_empty() {
        return PlanKey::Hash(c.run.plan_hash.clone());
    }
    let mut rates: Vec<i64> = c
        .rates_dps
        .iter()
        .map(|r| (r * 1e9).round() as i64)
        .collect();
    rates.sort_unstable();
    rates.dedup();
    PlanKey::Rates(c.run.kind.clone(), rates)
}

/// One of the plans in a history.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PlanGroup {
    /// The plan's name (of its latest calibration).
    pub name: String,
    /// The kind of test.
    pub kind: String,
    /// The demanded rates, °/s, ascending (empty: not in the catalog).
    pub rates_dps: Vec<f64>,
    /// Its calibrations in the history.
    pub calibrations: usize,
}

/// Day-to-day repeatability over the calibrations.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Repeatability {
    /// Calibrations with a scale factor (of the latest sweep's plan).
    pub n: usize,
    /// The plan they follow (index in [`History::plans`]).
    pub plan: Option<usize>,
    /// Sweeps with a scale factor left out because they follow other plans.
    pub other_plans: usize,
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
    /// The plan it followed (index in [`History::plans`]).
    pub plan: usize,
}

/// Acceptance limits of a quantity (from the latest calibration that had them).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Limits {
    /// Lower limit.
    pub min: Option<f64>,
    /// Upper limit.
    pub max: Option<f64>,
    /// Lower limit of the non-marginal band (a value between it and `min` is marginal).
    pub marginal_min: Option<f64>,
    /// Upper limit of the non-marginal band.
    pub marginal_max: Option<f64>,
}

/// The control band: mean ± 3σ of the calibrations before the latest, of its plan.
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
    /// Control band from the earlier calibrations of the latest one's plan (at least
    /// [`MIN_BAND_POINTS`] of them).
    pub band: Option<Band>,
    /// Earlier calibrations of the latest one's plan (the band's; below [`MIN_BAND_POINTS`],
    /// no band).
    pub band_candidates: usize,
    /// The plan of the latest calibration (index in [`History::plans`]).
    pub plan: usize,
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
    /// The plans they follow, in the order of their first calibration.
    pub plans: Vec<PlanGroup>,
    /// Each calibration's plan (index in `plans`), in the order of `calibrations`.
    pub plan_of: Vec<usize>,
    /// Day-to-day repeatability.
    pub repeatability: Repeatability,
    /// One trend per quantity that has values.
    pub trends: Vec<Trend>,
    /// Warnings (a latest value outside its control band; calibrations of other plans left
    /// out of the repeatability and the bands).
    pub warnings: Vec<String>,
}

/// `v` to 6 significant digits without trailing zeros (`0.362`, `-20`, `1.5e-9`).
fn short(v: f64) -> String {
    let s = significant(v, 6);
    if s.contains('e') || !s.contains('.') {
        return s;
    }
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// `"NAME" (KIND, N rates −20..20 °/s, M calibrations)`.
pub fn describe_plan(p: &PlanGroup) -> String {
    let rates = match (p.rates_dps.first(), p.rates_dps.last()) {
        (Some(a), Some(b)) if p.rates_dps.len() > 1 => format!(
            "{} rates {}..{} °/s",
            p.rates_dps.len(),
            short(*a),
            short(*b)
        ),
        (Some(a), _) => format!("at {} °/s", short(*a)),
        _ => "rates not in the catalog".to_string(),
    };
    format!(
        "\"{}\" ({}, {rates}, {} calibration{})",
        p.name,
        p.kind,
        p.calibrations,
        if p.calibrations == 1 { "" } else { "s" }
    )
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
        let mut keys: Vec<PlanKey> = Vec::new();
        let mut plans: Vec<PlanGroup> = Vec::new();
        let mut plan_of = Vec::with_capacity(calibrations.len());
        for c in &calibrations {
            let key = plan_key(c);
            let i = match keys.iter().position(|k| *k == key) {
                Some(i) => i,
                None => {
                    keys.push(key);
                    plans.push(PlanGroup {
                        name: String::new(),
                        kind: c.run.kind.clone(),
                        rates_dps: c.rates_dps.clone(),
                        calibrations: 0,
                    });
                    plans.len() - 1
                }
            };
            plans[i].name = c.run.plan_name.clone();
            plans[i].calibrations += 1;
            plan_of.push(i);
        }
        // the repeatability: the sweeps of the latest sweep's plan
        let with_k: Vec<(usize, &Calibration)> = calibrations
            .iter()
            .enumerate()
            .filter(|(_, c)| {
                c.results
                    .as_ref()
                    .and_then(|r| r.scale_factor)
                    .is_some_and(f64::is_finite)
            })
            .collect();
        let rep_plan = with_k.last().map(|(i, _)| plan_of[*i]);
        let values = |f: fn(&Results) -> Option<f64>| -> Vec<f64> {
            calibrations
                .iter()
                .zip(&plan_of)
                .filter(|(_, p)| Some(**p) == rep_plan)
                .filter_map(|(c, _)| c.results.as_ref().and_then(f))
                .filter(|x| x.is_finite())
                .collect()
        };
        let ks = values(|r| r.scale_factor);
        let biases = values(|r| r.bias_dph);
        let k_stats = mean_std(&ks);
        let repeatability = Repeatability {
            n: ks.len(),
            plan: rep_plan,
            other_plans: with_k.len() - ks.len(),
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
                .zip(&plan_of)
                .filter_map(|(c, &plan)| {
                    let value = (q.value)(c).filter(|x| x.is_finite())?;
                    Some(TrendPoint {
                        run_id: c.run.id.clone(),
                        started_utc: c.run.started_utc.clone(),
                        value,
                        expanded_uncertainty: (q.uncertainty)(c).filter(|x| x.is_finite()),
                        plan,
                    })
                })
                .collect();
            let Some(latest) = points.last() else {
                continue;
            };
            let plan = latest.plan;
            let limits = calibrations.iter().rev().find_map(|c| {
                let check = c.checks.iter().find(|k| k.quantity == limited_by(q.name))?;
                (check.min.is_some() || check.max.is_some()).then_some(Limits {
                    min: check.min,
                    max: check.max,
                    marginal_min: check.marginal_min,
                    marginal_max: check.marginal_max,
                })
            });
            let earlier: Vec<f64> = points[..points.len() - 1]
                .iter()
                .filter(|p| p.plan == plan)
                .map(|p| p.value)
                .collect();
            let band = mean_std(&earlier)
                .filter(|_| earlier.len() >= MIN_BAND_POINTS)
                .map(|(mean, sigma)| Band {
                    n: earlier.len(),
                    mean,
                    sigma,
                    low: mean - 3.0 * sigma,
                    high: mean + 3.0 * sigma,
                });
            let outside = band
                .as_ref()
                .is_some_and(|b| latest.value < b.low || latest.value > b.high);
            if let (true, Some(b)) = (outside, &band) {
                warnings.push(format!(
                    "{serial}: the latest {} ({} {}, {}) is outside the control band \
                     {} .. {} (mean ± 3σ of the {} earlier calibrations of its plan)",
                    q.label,
                    short(latest.value),
                    q.unit,
                    latest.started_utc,
                    short(b.low),
                    short(b.high),
                    b.n
                ));
            }
            let band_candidates = earlier.len();
            trends.push(Trend {
                quantity: q.name.to_string(),
                label: q.label.to_string(),
                unit: q.unit.to_string(),
                points,
                limits,
                band,
                band_candidates,
                plan,
                latest_outside_band: outside,
            });
        }
        // a drift test and a sweep are never compared: only several plans of one kind are
        if plans
            .iter()
            .any(|p| plans.iter().filter(|q| q.kind == p.kind).count() > 1)
        {
            let names: Vec<String> = plans.iter().map(describe_plan).collect();
            warnings.insert(
                0,
                format!(
                    "{serial}: the calibrations follow {} plans ({}); the repeatability and the \
                     control bands use only the calibrations of the latest one's plan, the \
                     others are shown but not compared",
                    plans.len(),
                    names.join("; ")
                ),
            );
        }
        History {
            serial: serial.to_string(),
            include_simulated,
            calibrations,
            plans,
            plan_of,
            repeatability,
            trends,
            warnings,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::record::RunRow;

    const FIVE: [f64; 5] = [0.0, 1.0, -1.0, 10.0, -10.0];

    fn cal(day: u32, k: f64, hash: &str, rates: &[f64]) -> Calibration {
        let mut rates_dps = rates.to_vec();
        rates_dps.sort_by(f64::total_cmp);
        Calibration {
            run: RunRow {
                id: format!("run-{day:02}"),
                directory: format!("/runs/{day}"),
                host: None,
                station_id: None,
                plan_name: format!("plan {}", rates.len()),
                plan_hash: hash.to_string(),
                kind: "scale_factor".into(),
                dut_serial: Some("G-1".into()),
                dut_model: None,
                operator: None,
                customer: None,
                status: "complete".into(),
                reason: None,
                started_utc: format!("2026-01-{day:02}T10:00:00Z"),
                ended_utc: None,
                simulated: true,
                verdict: None,
                acceptance_rule: None,
                steps_total: rates.len() as i64,
                steps_done: rates.len() as i64,
                ambient_c: None,
                humidity_pct: None,
                gyrocal_version: None,
            },
            results: Some(Results {
                scale_factor: Some(k),
                bias_dph: Some(10.0),
                ..Results::default()
            }),
            checks: Vec::new(),
            rates_dps,
            series: None,
        }
    }

    fn k_trend(h: &History) -> &Trend {
        h.trends
            .iter()
            .find(|t| t.quantity == "scale_factor")
            .expect("a K trend")
    }

    #[test]
    fn a_different_seed_is_not_a_different_plan() {
        // the plan hash covers [simulation]: each seed hashes differently
        let h = History::of(
            "G-1",
            true,
            vec![
                cal(1, 0.3610, "seed1", &FIVE),
                cal(2, 0.3611, "seed2", &FIVE),
                cal(3, 0.3612, "seed3", &FIVE),
            ],
        );
        assert_eq!(h.plans.len(), 1, "{:?}", h.plans);
        assert_eq!(h.repeatability.n, 3);
        assert_eq!(h.repeatability.other_plans, 0);
        assert!(h.warnings.is_empty(), "{:?}", h.warnings);
    }

    #[test]
    fn a_different_rate_list_is_a_different_plan_and_is_not_mixed() {
        let nineteen: Vec<f64> = (-9..=9).map(f64::from).collect();
        let mut cals: Vec<Calibration> = (1..=6)
            .map(|d| cal(d, 0.3610 + f64::from(d) * 1e-6, "a", &FIVE))
            .collect();
        // two calibrations of a 19-rate plan in between (their K differs by the plan)
        cals.insert(2, cal(20, 0.3700, "b", &nineteen));
        cals.insert(4, cal(21, 0.3700, "b", &nineteen));
        let h = History::of("G-1", true, cals);
        assert_eq!(h.plans.len(), 2);
        assert_eq!(h.plans[0].calibrations, 6);
        assert_eq!(h.plans[1].rates_dps.len(), 19);
        // the repeatability is the 5-rate plan's (the latest's): 6 values 1e-6 apart, not the
        // 9e-3 jump between the plans
        assert_eq!(h.repeatability.n, 6);
        assert_eq!(h.repeatability.other_plans, 2);
        let ppm = h.repeatability.scale_factor_ppm.expect("ppm");
        assert!(ppm < 10.0, "{ppm}");
        // the band: the 5 earlier calibrations of the 5-rate plan, the latest inside it
        let k = k_trend(&h);
        assert_eq!(k.band_candidates, 5);
        assert_eq!(k.band.as_ref().map(|b| b.n), Some(5));
        assert!(!k.latest_outside_band);
        assert_eq!(h.warnings.len(), 1, "{:?}", h.warnings);
        assert!(
            h.warnings[0].contains("2 plans") && h.warnings[0].contains("19 rates"),
            "{}",
            h.warnings[0]
        );
        // each point knows its plan
        assert_eq!(k.points.iter().filter(|p| p.plan == 1).count(), 2);
    }

    #[test]
    fn no_band_below_the_minimum_of_earlier_calibrations() {
        // 2 earlier calibrations and a latest far off: the false alarm
        let few = vec![
            cal(1, 0.36100, "a", &FIVE),
            cal(2, 0.36101, "a", &FIVE),
            cal(3, 0.36110, "a", &FIVE),
        ];
        let h = History::of("G-1", true, few);
        let k = k_trend(&h);
        assert!(k.band.is_none());
        assert_eq!(k.band_candidates, 2);
        assert!(!k.latest_outside_band);
        assert!(h.warnings.is_empty(), "{:?}", h.warnings);
        // one short of the minimum: still none
        let four: Vec<Calibration> = (1..=MIN_BAND_POINTS as u32)
            .map(|d| cal(d, 0.3610 + f64::from(d % 2) * 1e-5, "a", &FIVE))
            .collect();
        let k = k_trend(&History::of("G-1", true, four)).clone();
        assert_eq!(k.band_candidates, MIN_BAND_POINTS - 1);
        assert!(k.band.is_none());
        // with the minimum, a band, and a latest outside it is warned
        let mut enough: Vec<Calibration> = (1..=MIN_BAND_POINTS as u32)
            .map(|d| cal(d, 0.3610 + f64::from(d % 2) * 1e-5, "a", &FIVE))
            .collect();
        enough.push(cal(30, 0.3620, "a", &FIVE));
        let h = History::of("G-1", true, enough);
        let k = k_trend(&h);
        assert_eq!(k.band.as_ref().map(|b| b.n), Some(MIN_BAND_POINTS));
        assert!(k.latest_outside_band);
        assert_eq!(h.warnings.len(), 1);
        assert!(h.warnings[0].contains("0.362 V/(°/s)"), "{}", h.warnings[0]);
    }

    #[test]
    fn a_drift_test_beside_the_sweeps_is_no_mixing_of_plans() {
        let mut drift = cal(4, 0.0, "d", &[0.0]);
        drift.run.kind = "drift".into();
        drift.results = Some(Results {
            arw_deg_rt_h: Some(0.01),
            ..Results::default()
        });
        let h = History::of(
            "G-1",
            true,
            vec![cal(1, 0.361, "a", &FIVE), cal(2, 0.361, "b", &FIVE), drift],
        );
        assert_eq!(h.plans.len(), 2);
        assert!(h.warnings.is_empty(), "{:?}", h.warnings);
        assert_eq!(
            h.repeatability.n, 2,
            "the sweeps' plan, though a drift test is the latest"
        );
    }

    #[test]
    fn runs_without_steps_in_the_catalog_are_told_apart_by_hash() {
        let h = History::of(
            "G-1",
            true,
            vec![cal(1, 0.361, "a", &[]), cal(2, 0.361, "b", &[])],
        );
        assert_eq!(h.plans.len(), 2);
        assert!(describe_plan(&h.plans[0]).contains("rates not in the catalog"));
    }

    #[test]
    fn a_series_sensitivities_trend_with_their_u_and_a_sweep_has_none() {
        let series = |day: u32, tc: f64| {
            let mut c = cal(day, 0.361, "s", &FIVE);
            c.run.kind = "temperature_series".into();
            c.series = Some(crate::series::SeriesRecord {
                points: Vec::new(),
                k_tempco_ppm_per_c: Some(tc),
                u_k_tempco_ppm_per_c: Some(4.0),
                bias_tempco_dph_per_c: Some(1.5),
                u_bias_tempco_dph_per_c: Some(0.3),
                k_model_order: Some(1),
                bias_model_order: Some(1),
                hysteresis_k_ppm: None,
                hysteresis_bias_dph: Some(0.1),
                t_min_c: Some(-20.0),
                t_max_c: Some(60.0),
            });
            c
        };
        let h = History::of(
            "G-1",
            true,
            vec![series(1, 30.0), cal(2, 0.361, "a", &FIVE), series(3, 33.0)],
        );
        let t = h
            .trends
            .iter()
            .find(|t| t.quantity == "k_tempco_ppm_per_c")
            .expect("a K tempco trend");
        let values: Vec<_> = t
            .points
            .iter()
            .map(|p| (p.value, p.expanded_uncertainty))
            .collect();
        assert_eq!(values, vec![(30.0, Some(4.0)), (33.0, Some(4.0))]);
        assert_eq!(t.unit, "ppm/°C");
        // the series' own plan (another kind than the sweep), not the sweep's
        assert_eq!(t.plan, h.plan_of[2]);
        assert_ne!(h.plan_of[1], h.plan_of[2]);
        assert!(h.trends.iter().any(|t| t.quantity == "hysteresis_bias_dph"));
        // no revisited temperature: no hysteresis of K to follow
        assert!(!h.trends.iter().any(|t| t.quantity == "hysteresis_k_ppm"));
    }
}
