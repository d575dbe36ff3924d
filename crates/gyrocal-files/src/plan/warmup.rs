//! `[warmup]`: wait until the gyro's output settles before measuring (a rolling window mean
//! whose consecutive values change less than a tolerance), with its keys, defaults and
//! checks. The defaults are the ones the live monitor (gyrocal-run) and the analysis use too.

use std::time::Duration;

use serde::{Deserialize, Serialize};

use super::error::PlanError;
use super::raw::{S, Spans};
use super::schema::{KeySchema, Kind};
use super::validate::Ctx;

/// The keys of `[warmup]`.
pub(super) const KEYS: &[KeySchema] = &[
    ("window_s", Kind::Number, false),
    ("tolerance_v", Kind::Number, false),
    ("max_s", Kind::Number, false),
];

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawWarmup {
    pub(super) window_s: Option<S<f64>>,
    pub(super) tolerance_v: Option<S<f64>>,
    pub(super) max_s: Option<S<f64>>,
}

/// `[warmup]` as parsed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WarmupDoc {
    /// Window of the rolling mean, s.
    pub window_s: f64,
    /// Largest change of consecutive window means that counts as settled, V (absent: 3 × the
    /// white-noise σ of a window mean, estimated from the readings so far).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tolerance_v: Option<f64>,
    /// The warm-up ends here at the latest, s.
    pub max_s: f64,
}

/// Default `[warmup] window_s`, s.
pub const DEFAULT_WARMUP_WINDOW_S: f64 = 60.0;

/// Default `[warmup] max_s`, s (IEEE 1431's HRG warm-up is tens of minutes).
pub const DEFAULT_WARMUP_MAX_S: f64 = 3600.0;

/// Default warm-up tolerance, in white-noise sigmas of a window mean (`sigma_A(tau0)/sqrt(w)`),
/// used when `[warmup] tolerance_v` is not given: three sigmas keep a settled gyro from being
/// called still warming up by noise alone (about 0.3 % of windows), and one value is shared by
/// the live monitor (gyrocal-run) and the report's warm-up curve so they agree on "settled".
pub const DEFAULT_WARMUP_SIGMAS: f64 = 3.0;

impl WarmupDoc {
    /// `[warmup]` as written, defaults filled in, spans kept.
    pub(super) fn from_raw(w: RawWarmup, sp: &mut Spans) -> WarmupDoc {
        WarmupDoc {
            window_s: sp.opt("warmup.window_s", w.window_s, DEFAULT_WARMUP_WINDOW_S),
            tolerance_v: w.tolerance_v.map(|v| sp.take("warmup.tolerance_v", v)),
            max_s: sp.opt("warmup.max_s", w.max_s, DEFAULT_WARMUP_MAX_S),
        }
    }
}

/// The validated `[warmup]` section.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WarmupSettings {
    /// Window of the rolling mean.
    pub window: Duration,
    /// Largest change of consecutive window means that counts as settled, V; `None`: 3 × the
    /// white-noise σ of a window mean.
    pub tolerance_v: Option<f64>,
    /// The warm-up ends here at the latest.
    pub max: Duration,
}

impl WarmupSettings {
    /// As the document writes it.
    pub(super) fn to_doc(self) -> WarmupDoc {
        WarmupDoc {
            window_s: self.window.as_secs_f64(),
            tolerance_v: self.tolerance_v,
            max_s: self.max.as_secs_f64(),
        }
    }
}

pub(super) fn validate(w: &WarmupDoc, cx: &Ctx<'_>) -> Result<WarmupSettings, PlanError> {
    let window = cx.duration("warmup.window_s", w.window_s, true)?;
    let max = cx.duration("warmup.max_s", w.max_s, true)?;
    if max < window * 2 {
        return Err(cx.err(
            "warmup.max_s",
            format!(
                "= {} s is shorter than two windows ({} s): the criterion compares consecutive window means",
                w.max_s,
                2.0 * w.window_s
            ),
        ));
    }
    let tolerance_v = match w.tolerance_v {
        None => None,
        Some(t) => {
            let t = cx.finite("warmup.tolerance_v", t)?;
            if t <= 0.0 {
                return Err(cx.err("warmup.tolerance_v", format!("must be > 0 V (got {t})")));
            }
            Some(t)
        }
    };
    Ok(WarmupSettings {
        window,
        tolerance_v,
        max,
    })
}
