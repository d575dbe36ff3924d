//! `[plan]`: what every kind of plan has (its kind, name, rates, readings per rate, dwell,
//! passes and whole-turn acquisition), with each key's schema entry, raw field, default and
//! checks. What a kind adds or restricts is its own module's ([`super::sweep`],
//! [`super::drift`]), reached through the one dispatch in [`super::kind`].

use std::time::Duration;

use serde::{Deserialize, Serialize};

use super::error::PlanError;
use super::kind::{self, PlanKind};
use super::raw::{RawInt, S, Spans};
use super::schema::{IntRule, KeySchema, Kind};
use super::validate::Ctx;
use super::{MAX_DURATION_S, Plan};

/// Upper bound for `[plan] samples_per_rate`: one million readings is about 11.5 hours at the
/// 34401A's 24 readings/s (NPLC 1, autozero on); more is certainly a typo.
pub const MAX_SAMPLES_PER_RATE: u32 = 1_000_000;

/// Upper bound for `[plan] repeat`.
pub const MAX_REPEAT: u32 = 1000;

/// Upper bound for `[plan] whole_revolutions`.
pub const MAX_WHOLE_REVOLUTIONS: u32 = 1000;

/// `[plan] settle_s` when the plan does not say, s.
const DEFAULT_SETTLE_S: f64 = 10.0;

/// The keys of `[plan]`.
pub(super) const KEYS: &[KeySchema] = &[
    ("kind", Kind::Text, false),
    ("name", Kind::Text, false),
    ("rates_dps", Kind::Numbers, true),
    (
        "samples_per_rate",
        Kind::Int(IntRule::Range(1, MAX_SAMPLES_PER_RATE as u64)),
        true,
    ),
    ("settle_s", Kind::Number, false),
    (
        "repeat",
        Kind::Int(IntRule::Range(1, MAX_REPEAT as u64)),
        false,
    ),
    (
        "whole_revolutions",
        Kind::Int(IntRule::Range(0, MAX_WHOLE_REVOLUTIONS as u64)),
        false,
    ),
];

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawPlan {
    pub(super) kind: Option<S<String>>,
    pub(super) name: Option<S<String>>,
    pub(super) rates_dps: S<Vec<S<f64>>>,
    pub(super) samples_per_rate: S<RawInt>,
    pub(super) settle_s: Option<S<f64>>,
    pub(super) repeat: Option<S<RawInt>>,
    pub(super) whole_revolutions: Option<S<RawInt>>,
}

/// `[plan]` as parsed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlanSectionDoc {
    /// What the plan measures: `scale_factor` (absent in documents of plans before drift
    /// plans existed, and never written for one, so their hashes stay) or `drift`.
    #[serde(
        default = "kind::default_kind",
        skip_serializing_if = "kind::is_scale_factor"
    )]
    pub kind: String,
    /// Free-text name.
    pub name: String,
    /// Rates in the order applied, °/s.
    pub rates_dps: Vec<f64>,
    /// Readings per rate (integers are wide here, range-checked by validation).
    pub samples_per_rate: i64,
    /// Dwell after the table is at rate, s.
    pub settle_s: f64,
    /// Passes over the whole schedule.
    pub repeat: i64,
    /// Whole table turns to acquire over at each non-zero rate (0: off).
    pub whole_revolutions: i64,
}

impl PlanSectionDoc {
    /// `[plan]` as written, defaults filled in, spans kept.
    pub(super) fn from_raw(p: RawPlan, sp: &mut Spans) -> Result<Self, (&'static str, String)> {
        let rates = sp.take("plan.rates_dps", p.rates_dps);
        let rates_dps = rates
            .into_iter()
            .enumerate()
            .map(|(i, r)| sp.take(&format!("plan.rates_dps[{i}]"), r))
            .collect();
        Ok(PlanSectionDoc {
            kind: sp.opt("plan.kind", p.kind, kind::default_kind()),
            name: sp.opt("plan.name", p.name, String::new()),
            rates_dps,
            samples_per_rate: sp.int("plan.samples_per_rate", Some(p.samples_per_rate), 0)?,
            settle_s: sp.opt("plan.settle_s", p.settle_s, DEFAULT_SETTLE_S),
            repeat: sp.int("plan.repeat", p.repeat, 1)?,
            whole_revolutions: sp.int("plan.whole_revolutions", p.whole_revolutions, 0)?,
        })
    }
}

/// The validated `[plan]` section.
pub(super) struct Section {
    pub(super) kind: PlanKind,
    pub(super) name: String,
    pub(super) rates_dps: Vec<f64>,
    pub(super) samples_per_rate: u32,
    pub(super) settle: Duration,
    pub(super) repeat: u32,
    pub(super) whole_revolutions: u32,
}

/// Checks `[plan]`; the rates against the table's `max_rate` (°/s), then the kind's own rule
/// on them.
pub(super) fn validate(
    p: PlanSectionDoc,
    max_rate: f64,
    cx: &Ctx<'_>,
) -> Result<Section, PlanError> {
    let samples_per_rate = cx.int_in(
        "plan.samples_per_rate",
        p.samples_per_rate,
        1,
        MAX_SAMPLES_PER_RATE,
    )?;
    let repeat = cx.int_in("plan.repeat", p.repeat, 1, MAX_REPEAT)?;
    let whole_revolutions = cx.int_in(
        "plan.whole_revolutions",
        p.whole_revolutions,
        0,
        MAX_WHOLE_REVOLUTIONS,
    )?;
    let mut rates = Vec::with_capacity(p.rates_dps.len());
    for (i, &r) in p.rates_dps.iter().enumerate() {
        let key = format!("plan.rates_dps[{i}]");
        let r = cx.finite(&key, r)?;
        if r.abs() > max_rate {
            return Err(cx.err(
                &key,
                format!("|{r}| exceeds [table] max_rate_dps = {max_rate}"),
            ));
        }
        if whole_revolutions > 0 && r != 0.0 {
            let span = f64::from(whole_revolutions) * 360.0 / r.abs();
            if span > MAX_DURATION_S {
                return Err(cx.err(
                    &key,
                    format!(
                        "{r} deg/s needs {span:.0} s for {} whole revolution(s), over the \
                         {MAX_DURATION_S} s limit of one step",
                        whole_revolutions
                    ),
                ));
            }
        }
        rates.push(if r == 0.0 { 0.0 } else { r }); // -0 is 0
    }
    let kind = kind::parse(&p.kind, cx)?;
    kind::check_rates(kind, &rates, &p.rates_dps, cx)?;
    let settle = cx.duration("plan.settle_s", p.settle_s, false)?;
    Ok(Section {
        kind,
        name: p.name,
        rates_dps: rates,
        samples_per_rate,
        settle,
        repeat,
        whole_revolutions,
    })
}

/// `[plan]` of a validated plan, as the document writes it.
pub(super) fn to_doc(plan: &Plan) -> PlanSectionDoc {
    PlanSectionDoc {
        kind: plan.kind.as_str().to_string(),
        name: plan.name.clone(),
        rates_dps: plan.rates_dps.clone(),
        samples_per_rate: plan.samples_per_rate.into(),
        settle_s: plan.settle.as_secs_f64(),
        repeat: plan.repeat.into(),
        whole_revolutions: plan.whole_revolutions.into(),
    }
}
