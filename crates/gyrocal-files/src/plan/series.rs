//! The temperature series (`[plan] kind = "temperature_series"`, IEEE 1431 §12.8, IEEE 952
//! §6.6.8–6.6.9): the chamber set to each temperature of `[series] temperatures_c` in turn,
//! a soak until the gyro's own temperature has settled, then the sweep of `rates_dps` (as a
//! sweep plan runs it), a bias record at 0 °/s, or both. Everything only a series has is
//! here: its `[series]` section (keys, defaults, rules), what `gyrocal check` says of it, its
//! schedule and its compile to steps; the chamber's own section is `[chamber]` (module
//! `chamber`).
//!
//! Why the soak criterion watches the gyro (the product input) and not the air: the air
//! follows the setpoint in minutes, the inside of a gyro in tens of minutes; a sweep started
//! when the air arrived measures a gyro still changing temperature (chamber.md).
//!
//! # The schedule
//!
//! For each temperature (its `series_point`, 0-based), in the order written: `repeat` passes
//! over `rates_dps` when `measure` is `sweep` or `both`, then one step of `bias_readings`
//! readings at 0 °/s when it is `bias` or `both` (the bias record, marked `bias_record = 1`
//! in steps.csv). Step indices run on through the whole series, so a resume key is a step as
//! for any plan.
//!
//! # The compiled steps
//!
//! Before the first step of each temperature the session has to measure, a soak action
//! ([`crate::steps::ChamberAction::Soak`]); a resumed session soaks again at the temperature
//! of its first remaining step, since the chamber may have drifted or gone safe meanwhile.
//! Every measuring step watches the chamber ([`crate::steps::ChamberAction::Watch`]): a step
//! during which the gyro's temperature left the band is measured again.

use std::time::Duration;

use serde::{Deserialize, Serialize};

use super::Plan;
use super::chamber::ChamberSettings;
use super::error::PlanError;
use super::kind::PlanKind;
use super::raw::{RawInt, S, Spans};
use super::schedule::{Acquire, SeriesStep, Step};
use super::schema::{IntRule, KeySchema, Kind};
use super::validate::Ctx;
use crate::steps::{
    Acquiring, Action, ChamberAction, Compiled, HoldCheck, Record, Setup, Soak, TableAction,
    Watch,
};

/// The keys of `[series]`.
pub(super) const KEYS: &[KeySchema] = &[
    ("temperatures_c", Kind::Numbers, true),
    ("measure", Kind::Text, false),
    ("band_c", Kind::Number, false),
    ("stability_c_per_min", Kind::Number, false),
    ("soak_min", Kind::Number, false),
    ("max_wait_min", Kind::Number, false),
    ("poll_s", Kind::Number, false),
    ("bias_readings", Kind::Int(IntRule::Range(1, 1_000_000)), false),
];

/// The most temperatures a series takes (a series is hours per temperature).
pub const MAX_TEMPERATURES: usize = 100;
/// Default `[series] band_c`, °C.
pub const DEFAULT_BAND_C: f64 = 0.5;
/// Default `[series] stability_c_per_min`, °C/min.
pub const DEFAULT_STABILITY_C_PER_MIN: f64 = 0.05;
/// Default `[series] soak_min`, min.
pub const DEFAULT_SOAK_MIN: f64 = 30.0;
/// Default `[series] max_wait_min`, min.
pub const DEFAULT_MAX_WAIT_MIN: f64 = 240.0;
/// Default `[series] poll_s`, s.
pub const DEFAULT_POLL_S: f64 = 10.0;
/// Default `[series] bias_readings`.
pub const DEFAULT_BIAS_READINGS: u32 = 500;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawSeries {
    temperatures_c: S<Vec<S<f64>>>,
    measure: Option<S<String>>,
    band_c: Option<S<f64>>,
    stability_c_per_min: Option<S<f64>>,
    soak_min: Option<S<f64>>,
    max_wait_min: Option<S<f64>>,
    poll_s: Option<S<f64>>,
    bias_readings: Option<S<RawInt>>,
}

/// `[series]` as parsed (defaults filled in).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SeriesDoc {
    /// The temperatures, °C, in the order run.
    pub temperatures_c: Vec<f64>,
    /// `sweep`, `bias` or `both`.
    pub measure: String,
    /// Soak band on the gyro's temperature, ± °C.
    pub band_c: f64,
    /// Soak stability, °C/min.
    pub stability_c_per_min: f64,
    /// Soak time, min.
    pub soak_min: f64,
    /// The longest wait for a soak, min.
    pub max_wait_min: f64,
    /// Chamber poll interval, s.
    pub poll_s: f64,
    /// Readings of the bias record.
    pub bias_readings: i64,
}

impl SeriesDoc {
    /// `[series]` as written, defaults filled in, spans kept.
    pub(super) fn from_raw(
        s: RawSeries,
        sp: &mut Spans,
    ) -> Result<SeriesDoc, (&'static str, String)> {
        let list = sp.take("series.temperatures_c", s.temperatures_c);
        let temperatures_c = list
            .into_iter()
            .enumerate()
            .map(|(i, t)| sp.take(&format!("series.temperatures_c[{i}]"), t))
            .collect();
        Ok(SeriesDoc {
            temperatures_c,
            measure: sp.opt("series.measure", s.measure, Measure::Sweep.as_str().into()),
            band_c: sp.opt("series.band_c", s.band_c, DEFAULT_BAND_C),
            stability_c_per_min: sp.opt(
                "series.stability_c_per_min",
                s.stability_c_per_min,
                DEFAULT_STABILITY_C_PER_MIN,
            ),
            soak_min: sp.opt("series.soak_min", s.soak_min, DEFAULT_SOAK_MIN),
            max_wait_min: sp.opt("series.max_wait_min", s.max_wait_min, DEFAULT_MAX_WAIT_MIN),
            poll_s: sp.opt("series.poll_s", s.poll_s, DEFAULT_POLL_S),
            bias_readings: sp.int(
                "series.bias_readings",
                s.bias_readings,
                i64::from(DEFAULT_BIAS_READINGS),
            )?,
        })
    }
}

/// What is measured at each temperature (`[series] measure`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Measure {
    /// The sweep of `rates_dps` (scale factor, bias and nonlinearity at each temperature).
    Sweep,
    /// A record at 0 °/s of `bias_readings` readings.
    Bias,
    /// The sweep, then the bias record.
    Both,
}

impl Measure {
    /// All choices.
    pub const ALL: [Measure; 3] = [Measure::Sweep, Measure::Bias, Measure::Both];

    /// As written in a plan.
    pub fn as_str(self) -> &'static str {
        match self {
            Measure::Sweep => "sweep",
            Measure::Bias => "bias",
            Measure::Both => "both",
        }
    }

    /// Whether the sweep is run at each temperature.
    pub fn sweep(self) -> bool {
        matches!(self, Measure::Sweep | Measure::Both)
    }

    /// Whether the bias record is taken at each temperature.
    pub fn bias(self) -> bool {
        matches!(self, Measure::Bias | Measure::Both)
    }
}

/// The validated `[series]` section (public fields named like the keys).
#[derive(Debug, Clone, PartialEq)]
pub struct SeriesSettings {
    /// The temperatures, °C, in the order run (each within the chamber's limits).
    pub temperatures_c: Vec<f64>,
    /// What is measured at each.
    pub measure: Measure,
    /// Soaked when the gyro's temperature is within ± this of the setpoint, °C (> 0).
    pub band_c: f64,
    /// ... changing slower than this, °C/min (> 0) ...
    pub stability_c_per_min: f64,
    /// ... for this long, min (≥ 0).
    pub soak_min: f64,
    /// The run fails if not soaked after this long, min (> `soak_min`).
    pub max_wait_min: f64,
    /// The chamber is read at this interval, s (> 0).
    pub poll_s: f64,
    /// Readings of the bias record.
    pub bias_readings: u32,
}

impl SeriesSettings {
    /// As the document writes it.
    pub(super) fn to_doc(&self) -> SeriesDoc {
        SeriesDoc {
            temperatures_c: self.temperatures_c.clone(),
            measure: self.measure.as_str().into(),
            band_c: self.band_c,
            stability_c_per_min: self.stability_c_per_min,
            soak_min: self.soak_min,
            max_wait_min: self.max_wait_min,
            poll_s: self.poll_s,
            bias_readings: i64::from(self.bias_readings),
        }
    }

    /// The soak time.
    pub fn soak(&self) -> Duration {
        Duration::from_secs_f64(self.soak_min * 60.0)
    }

    /// The longest wait for a soak.
    pub fn max_wait(&self) -> Duration {
        Duration::from_secs_f64(self.max_wait_min * 60.0)
    }

    /// The chamber's poll interval.
    pub fn poll(&self) -> Duration {
        Duration::from_secs_f64(self.poll_s)
    }

    /// Whether the temperature at `point` was already visited earlier in the series (within
    /// the band): its measurement then says the hysteresis.
    pub fn revisits(&self, point: usize) -> bool {
        let Some(t) = self.temperatures_c.get(point) else {
            return false;
        };
        self.temperatures_c[..point]
            .iter()
            .any(|u| (u - t).abs() <= self.band_c)
    }
}

impl Plan {
    /// `[series]`, on a temperature series plan.
    pub fn series(&self) -> Option<&SeriesSettings> {
        self.kind_sections.series.as_ref()
    }

    /// `[chamber]`, on a plan that drives a chamber (a temperature series).
    pub fn chamber(&self) -> Option<&ChamberSettings> {
        self.kind_sections.chamber.as_ref()
    }

    /// Overrides the chamber's port (`--chamber-port`), on a plan that has one; ports are not
    /// part of the hash. Recorded in the run's manifest like the meter's and the table's, so a
    /// bare `--resume DIR` reaches the same chamber.
    pub fn set_chamber_port(&mut self, port: gyrocal_link::PortSpec) {
        if let Some(c) = self.kind_sections.chamber.as_mut() {
            c.port = port;
        }
    }
}

/// The rates of a series: its sweep's, so the sweep's rule (two distinct rates at least),
/// unless only the bias is measured (then the rates are not used); checked by [`validate`],
/// which knows `measure`.
pub(super) fn check_rates(
    measure: Measure,
    rates: &[f64],
    cx: &Ctx<'_>,
) -> Result<(), PlanError> {
    if measure.sweep() {
        super::sweep::check_rates(rates, cx)
    } else {
        Ok(())
    }
}

/// `[series]` and `[chamber]`: a temperature series needs both, no other kind has either;
/// every temperature within the chamber's limits.
pub(super) fn validate(
    series: Option<SeriesDoc>,
    chamber: Option<super::chamber::ChamberDoc>,
    kind: PlanKind,
    rates: &[f64],
    cx: &Ctx<'_>,
) -> Result<(Option<SeriesSettings>, Option<ChamberSettings>), PlanError> {
    let is_series = kind == PlanKind::Series;
    match (&series, &chamber, is_series) {
        (None, _, true) => {
            return Err(cx.err(
                "series.temperatures_c",
                "a temperature series needs a [series] section: add [series] with temperatures_c = [25, -20, 60, 25]".into(),
            ));
        }
        (_, None, true) => {
            return Err(cx.err(
                "chamber.model",
                "a temperature series needs a [chamber] section: add [chamber] with model and port".into(),
            ));
        }
        (Some(_), _, false) => {
            return Err(cx.err(
                "series.temperatures_c",
                "[series] belongs to a temperature series: add kind = \"temperature_series\" to [plan], or remove [series]".into(),
            ));
        }
        (_, Some(_), false) => {
            return Err(cx.err(
                "chamber.model",
                "[chamber] is driven by a temperature series only: add kind = \"temperature_series\" to [plan], or remove [chamber]".into(),
            ));
        }
        _ => {}
    }
    let (Some(s), Some(c)) = (series, chamber) else {
        return Ok((None, None));
    };
    let chamber = super::chamber::validate(&c, cx)?;
    let settings = validate_series(&s, &chamber, cx)?;
    check_rates(settings.measure, rates, cx)?;
    Ok((Some(settings), Some(chamber)))
}

fn positive(cx: &Ctx<'_>, key: &str, v: f64, unit: &str) -> Result<f64, PlanError> {
    let v = cx.finite(key, v)?;
    if v <= 0.0 {
        return Err(cx.err(key, format!("must be > 0 {unit} (got {v})")));
    }
    Ok(v)
}

fn validate_series(
    s: &SeriesDoc,
    chamber: &ChamberSettings,
    cx: &Ctx<'_>,
) -> Result<SeriesSettings, PlanError> {
    if s.temperatures_c.is_empty() {
        return Err(cx.err(
            "series.temperatures_c",
            "is empty: list the temperatures to measure at, e.g. temperatures_c = [25, -20, 60, 25]"
                .into(),
        ));
    }
    if s.temperatures_c.len() > MAX_TEMPERATURES {
        return Err(cx.err(
            "series.temperatures_c",
            format!(
                "lists {} temperatures: at most {MAX_TEMPERATURES}",
                s.temperatures_c.len()
            ),
        ));
    }
    for (i, &t) in s.temperatures_c.iter().enumerate() {
        let key = format!("series.temperatures_c[{i}]");
        let key = if cx.has(&key) {
            key
        } else {
            "series.temperatures_c".to_string()
        };
        let t = cx.finite(&key, t)?;
        if !(chamber.min_c..=chamber.max_c).contains(&t) {
            return Err(cx.err(
                &key,
                format!(
                    "= {t} °C is outside the chamber's limits [{}, {}] °C ([chamber] min_c, max_c): the setpoint is refused",
                    chamber.min_c, chamber.max_c
                ),
            ));
        }
    }
    let measure = Measure::ALL
        .into_iter()
        .find(|m| m.as_str() == s.measure.trim())
        .ok_or_else(|| {
            cx.err(
                "series.measure",
                format!(
                    "= {:?} is not a measurement: write \"sweep\" (the sweep of rates_dps), \"bias\" (a record at 0 °/s) or \"both\"",
                    s.measure
                ),
            )
        })?;
    let band_c = positive(cx, "series.band_c", s.band_c, "°C")?;
    let stability = positive(
        cx,
        "series.stability_c_per_min",
        s.stability_c_per_min,
        "°C/min",
    )?;
    let soak_min = cx.finite("series.soak_min", s.soak_min)?;
    if !(0.0..=MAX_SOAK_MIN).contains(&soak_min) {
        return Err(cx.err(
            "series.soak_min",
            format!("must be from 0 to {MAX_SOAK_MIN} min (got {soak_min})"),
        ));
    }
    let max_wait_min = positive(cx, "series.max_wait_min", s.max_wait_min, "min")?;
    if max_wait_min > MAX_SOAK_MIN {
        return Err(cx.err(
            "series.max_wait_min",
            format!("must be <= {MAX_SOAK_MIN} min (got {max_wait_min})"),
        ));
    }
    if max_wait_min <= soak_min {
        return Err(cx.err(
            "series.max_wait_min",
            format!(
                "= {max_wait_min} min must be longer than soak_min = {soak_min} min: the soak alone takes that long"
            ),
        ));
    }
    let poll_s = positive(cx, "series.poll_s", s.poll_s, "s")?;
    if !(0.1..=3600.0).contains(&poll_s) {
        return Err(cx.err(
            "series.poll_s",
            format!("must be from 0.1 to 3600 s (got {poll_s})"),
        ));
    }
    if soak_min > 0.0 && poll_s > soak_min * 60.0 {
        return Err(cx.err(
            "series.poll_s",
            format!(
                "= {poll_s} s is longer than the soak ({soak_min} min): the criterion would never be read during it"
            ),
        ));
    }
    let bias_readings = cx.int_in("series.bias_readings", s.bias_readings, 1, 1_000_000)?;
    Ok(SeriesSettings {
        temperatures_c: s.temperatures_c.clone(),
        measure,
        band_c,
        stability_c_per_min: stability,
        soak_min,
        max_wait_min,
        poll_s,
        bias_readings,
    })
}

/// The longest soak or wait, min (a week).
pub const MAX_SOAK_MIN: f64 = 10_080.0;

/// The time the chamber's ramps and the soaks take at least (from ambient to the first
/// temperature, then from one to the next, at the run's ramp; a soak of `soak_min` at each
/// temperature): the measurements' own time is the schedule's estimate on top.
pub fn ramps_and_soaks(series: &SeriesSettings, chamber: &ChamberSettings) -> (Duration, Duration) {
    let mut from = chamber.ambient_c;
    let mut ramp_min = 0.0;
    for &t in &series.temperatures_c {
        ramp_min += (t - from).abs() / chamber.ramp_c_per_min;
        from = t;
    }
    let soak_min = series.soak_min * series.temperatures_c.len() as f64;
    (
        Duration::from_secs_f64(ramp_min * 60.0),
        Duration::from_secs_f64(soak_min * 60.0),
    )
}

fn hours(d: Duration) -> String {
    let h = d.as_secs_f64() / 3600.0;
    if h >= 1.0 {
        format!("{h:.1} h")
    } else {
        format!("{:.0} min", d.as_secs_f64() / 60.0)
    }
}

/// What `gyrocal check` says of a series: the temperatures in order, what is measured, the
/// soak criterion, the chamber, and the time its ramps and soaks take at least.
pub(super) fn summary(plan: &Plan) -> Option<super::kind::KindSummary> {
    let (s, c) = (plan.series()?, plan.chamber()?);
    let temps: Vec<String> = s
        .temperatures_c
        .iter()
        .map(|t| format!("{t}"))
        .collect();
    let (ramps, soaks) = ramps_and_soaks(s, c);
    let revisited: Vec<usize> = (0..s.temperatures_c.len())
        .filter(|&i| s.revisits(i))
        .collect();
    let what = match s.measure {
        Measure::Sweep => "the sweep".to_string(),
        Measure::Bias => format!("a bias record of {} readings at 0 °/s", s.bias_readings),
        Measure::Both => format!(
            "the sweep and a bias record of {} readings at 0 °/s",
            s.bias_readings
        ),
    };
    let line = format!(
        "temperature series: {} °C ({} at each{}); soaked when the gyro is within ±{} °C, \
         changing < {} °C/min, for {} min (at most {} min, else the run fails); chamber {} on \
         {}, ramp {} °C/min, safe state {}; the chamber's ramps take {} and the soaks at least \
         {}: {} before the measurements' own time",
        temps.join(" → "),
        what,
        if revisited.is_empty() {
            String::new()
        } else {
            "; a revisited temperature measures the hysteresis".to_string()
        },
        s.band_c,
        s.stability_c_per_min,
        s.soak_min,
        s.max_wait_min,
        c.model.as_str(),
        c.port,
        c.ramp_c_per_min,
        c.describe_safe_state(),
        hours(ramps),
        hours(soaks),
        hours(ramps + soaks),
    );
    Some(super::kind::KindSummary {
        key: "series",
        line,
        json: serde_json::json!({
            "temperatures_c": s.temperatures_c,
            "measure": s.measure.as_str(),
            "band_c": s.band_c,
            "stability_c_per_min": s.stability_c_per_min,
            "soak_min": s.soak_min,
            "max_wait_min": s.max_wait_min,
            "poll_s": s.poll_s,
            "bias_readings": s.bias_readings,
            "revisited_points": revisited,
            "chamber": {
                "model": c.model.as_str(),
                "port": c.port.to_string(),
                "ramp_c_per_min": c.ramp_c_per_min,
                "min_c": c.min_c,
                "max_c": c.max_c,
                "safe_state": c.safe_state.as_str(),
                "ambient_c": c.ambient_c,
            },
            "ramps_s": ramps.as_secs_f64(),
            "soaks_min_s": soaks.as_secs_f64(),
        }),
    })
}

/// The series' schedule (see the module docs): at each temperature its sweep's passes, then
/// its bias record.
pub(super) fn schedule(plan: &Plan) -> Vec<Step> {
    let Some(s) = plan.series() else {
        return plan.passes_schedule(0, None);
    };
    let mut steps: Vec<Step> = Vec::new();
    for (point, &setpoint_c) in s.temperatures_c.iter().enumerate() {
        let point = u32::try_from(point).unwrap_or(u32::MAX);
        if s.measure.sweep() {
            let series = SeriesStep {
                point,
                setpoint_c,
                bias_record: false,
            };
            steps.extend(plan.passes_schedule(steps.len(), Some(series)));
        }
        if s.measure.bias() {
            steps.push(Step {
                index: steps.len(),
                pass: 0,
                rate_dps: 0.0,
                acquire: Acquire::Samples(s.bias_readings),
                series: Some(SeriesStep {
                    point,
                    setpoint_c,
                    bias_record: true,
                }),
            });
        }
    }
    steps
}

/// Steps in a series' schedule.
pub(super) fn step_count(plan: &Plan) -> usize {
    let Some(s) = plan.series() else {
        return plan.passes_count();
    };
    let per_point =
        usize::from(s.measure.sweep()) * plan.passes_count() + usize::from(s.measure.bias());
    per_point * s.temperatures_c.len()
}

/// The series compiled to steps (see [`crate::steps`]): the table enabled, an optional
/// warm-up at 0 °/s first, then for each temperature a soak and its remaining steps, each
/// watching the chamber.
pub(crate) fn compile(plan: &Plan, remaining: &[Step], warmup_done: bool) -> Compiled {
    let tolerance_dps = plan.table().rate_tolerance_dps;
    let mut steps: Vec<Action> = plan
        .warmup()
        .filter(|_| !warmup_done)
        .map(|settings| Action {
            table: TableAction::Rate(0.0),
            dwell: Duration::ZERO,
            acquire: Acquiring::UntilSettled(*settings),
            hold: HoldCheck::None,
            record: Record::Warmup,
            chamber: ChamberAction::None,
        })
        .into_iter()
        .collect();
    let (Some(s), Some(c)) = (plan.series(), plan.chamber()) else {
        // validation makes a series plan hold both sections; nothing to run without them
        return Compiled {
            setup: Setup::EnableTable,
            steps,
            warmup_in_record: None,
            schedule_len: plan.step_count(),
            uses_table: true,
            uses_chamber: false,
        };
    };
    let mut soaked: Option<u32> = None;
    for step in remaining {
        let Some(at) = step.series else { continue };
        if soaked != Some(at.point) {
            soaked = Some(at.point);
            steps.push(Action {
                // the table holds still while the chamber moves: no readings, no row
                table: TableAction::Rate(0.0),
                dwell: Duration::ZERO,
                acquire: Acquiring::Nothing,
                hold: HoldCheck::None,
                record: Record::Soak,
                chamber: ChamberAction::Soak(Soak {
                    point: at.point,
                    setpoint_c: at.setpoint_c,
                    ramp_c_per_min: c.ramp_c_per_min,
                    band_c: s.band_c,
                    stability_c_per_min: s.stability_c_per_min,
                    soak: s.soak(),
                    max_wait: s.max_wait(),
                    poll: s.poll(),
                }),
            });
        }
        steps.push(Action {
            table: TableAction::Rate(step.rate_dps),
            dwell: plan.settle(),
            acquire: Acquiring::Readings(step.acquire),
            hold: HoldCheck::Rate {
                demand_dps: step.rate_dps,
                tolerance_dps,
            },
            record: Record::Row(*step),
            chamber: ChamberAction::Watch(Watch {
                point: at.point,
                setpoint_c: at.setpoint_c,
                band_c: s.band_c,
                poll: s.poll(),
            }),
        });
    }
    Compiled {
        setup: Setup::EnableTable,
        steps,
        warmup_in_record: None,
        schedule_len: plan.step_count(),
        uses_table: true,
        uses_chamber: true,
    }
}

#[cfg(test)]
#[path = "series_tests.rs"]
mod tests;
