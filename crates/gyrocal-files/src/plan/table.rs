//! `[table]`: the rate table (its dialect, port, link and the client-side limits every move
//! is checked against), with its keys, defaults and checks.

use std::time::Duration;

use serde::{Deserialize, Serialize};

use super::error::PlanError;
use super::raw::{RawInt, S, Spans};
use super::schema::{IntRule, KeySchema, Kind};
use super::validate::Ctx;
use super::{BAUD_RATES, Port};

/// Hard ceiling for `[table] max_rate_dps`, in °/s. Laboratory single-axis rate tables reach a
/// few hundred to about 1000 °/s; a larger figure is a typo, and a dangerous one.
pub const HARD_MAX_RATE_DPS: f64 = 1000.0;

/// Hard ceiling for `[table] acceleration_dps2`, in °/s². Same reasoning as [`HARD_MAX_RATE_DPS`].
pub const HARD_MAX_ACCELERATION_DPS2: f64 = 1000.0;

/// `[table]` defaults: dialect, baud, "at rate" tolerance (°/s), stability window (s) and
/// timeout (s).
const DEFAULT_DIALECT: &str = "acl";
const DEFAULT_BAUD: i64 = 9600;
const DEFAULT_RATE_TOLERANCE_DPS: f64 = 0.001;
const DEFAULT_STABILITY_WINDOW_S: f64 = 2.0;
const DEFAULT_AT_RATE_TIMEOUT_S: f64 = 60.0;

/// The keys of `[table]`.
pub(super) const KEYS: &[KeySchema] = &[
    ("dialect", Kind::Text, false),
    ("port", Kind::Text, true),
    ("baud", Kind::Int(IntRule::OneOf(&BAUD_RATES)), false),
    ("max_rate_dps", Kind::Number, true),
    ("acceleration_dps2", Kind::Number, true),
    ("rate_tolerance_dps", Kind::Number, false),
    ("stability_window_s", Kind::Number, false),
    ("at_rate_timeout_s", Kind::Number, false),
];

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawTable {
    pub(super) dialect: Option<S<String>>,
    pub(super) port: S<String>,
    pub(super) baud: Option<S<RawInt>>,
    pub(super) max_rate_dps: S<f64>,
    pub(super) acceleration_dps2: S<f64>,
    pub(super) rate_tolerance_dps: Option<S<f64>>,
    pub(super) stability_window_s: Option<S<f64>>,
    pub(super) at_rate_timeout_s: Option<S<f64>>,
}

/// `[table]` as parsed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TableDoc {
    /// Command language, `acl`.
    pub dialect: String,
    /// Serial device path or `tcp://HOST:PORT`.
    pub port: String,
    /// Serial baud rate.
    pub baud: i64,
    /// Client-side rate limit, °/s.
    pub max_rate_dps: f64,
    /// Acceleration limit, °/s².
    pub acceleration_dps2: f64,
    /// "At rate" tolerance, °/s.
    pub rate_tolerance_dps: f64,
    /// "At rate" stability window, s.
    pub stability_window_s: f64,
    /// Time allowed to reach the rate, s.
    pub at_rate_timeout_s: f64,
}

impl TableDoc {
    /// `[table]` as written, defaults filled in, spans kept.
    pub(super) fn from_raw(
        t: RawTable,
        sp: &mut Spans,
    ) -> Result<TableDoc, (&'static str, String)> {
        Ok(TableDoc {
            dialect: sp.opt("table.dialect", t.dialect, DEFAULT_DIALECT.into()),
            port: sp.take("table.port", t.port),
            baud: sp.int("table.baud", t.baud, DEFAULT_BAUD)?,
            max_rate_dps: sp.take("table.max_rate_dps", t.max_rate_dps),
            acceleration_dps2: sp.take("table.acceleration_dps2", t.acceleration_dps2),
            rate_tolerance_dps: sp.opt(
                "table.rate_tolerance_dps",
                t.rate_tolerance_dps,
                DEFAULT_RATE_TOLERANCE_DPS,
            ),
            stability_window_s: sp.opt(
                "table.stability_window_s",
                t.stability_window_s,
                DEFAULT_STABILITY_WINDOW_S,
            ),
            at_rate_timeout_s: sp.opt(
                "table.at_rate_timeout_s",
                t.at_rate_timeout_s,
                DEFAULT_AT_RATE_TIMEOUT_S,
            ),
        })
    }

    /// The settings a plan without `[table]` holds (a drift record with `[drift] table =
    /// "none"`): never used to open or drive anything; the port names no device.
    pub(super) fn unused() -> TableDoc {
        TableDoc {
            dialect: DEFAULT_DIALECT.into(),
            port: "(no table)".into(),
            baud: DEFAULT_BAUD,
            max_rate_dps: 1.0,
            acceleration_dps2: 1.0,
            rate_tolerance_dps: DEFAULT_RATE_TOLERANCE_DPS,
            stability_window_s: DEFAULT_STABILITY_WINDOW_S,
            at_rate_timeout_s: DEFAULT_AT_RATE_TIMEOUT_S,
        }
    }
}

/// The rate table's command language.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TableDialect {
    /// Acutronic ACL (ACUTROL3000), the first dialect gyrocal speaks.
    Acl,
    /// Ideal Aerosmith three-letter ASCII commands (`JOG`, `ACL`, `STO`, `PVE`, ...):
    /// experimental, written from public scripts, no vendor manual (see gyrocal-table's
    /// `aerosmith` module for what a lab must verify first).
    Aerosmith,
}

impl TableDialect {
    /// The name used in plan files.
    pub fn as_str(self) -> &'static str {
        match self {
            TableDialect::Acl => "acl",
            TableDialect::Aerosmith => "aerosmith",
        }
    }
}

/// The validated `[table]` section.
#[derive(Debug, Clone, PartialEq)]
pub struct TableSettings {
    /// Command language.
    pub dialect: TableDialect,
    /// Where the table controller is connected.
    pub port: Port,
    /// Serial baud rate (one of [`BAUD_RATES`]).
    pub baud: u32,
    /// Client-side rate limit, °/s, in (0, [`HARD_MAX_RATE_DPS`]].
    pub max_rate_dps: f64,
    /// Acceleration limit, °/s², in (0, [`HARD_MAX_ACCELERATION_DPS2`]].
    pub acceleration_dps2: f64,
    /// "At rate" tolerance on the measured rate, °/s (> 0).
    pub rate_tolerance_dps: f64,
    /// The measured rate must stay within tolerance this long (> 0).
    pub stability_window: Duration,
    /// Reaching the rate takes longer than this: a fault (> the stability window).
    pub at_rate_timeout: Duration,
}

impl TableSettings {
    /// As the document writes it.
    pub(super) fn to_doc(&self) -> TableDoc {
        TableDoc {
            dialect: self.dialect.as_str().into(),
            port: self.port.to_string(),
            baud: self.baud.into(),
            max_rate_dps: self.max_rate_dps,
            acceleration_dps2: self.acceleration_dps2,
            rate_tolerance_dps: self.rate_tolerance_dps,
            stability_window_s: self.stability_window.as_secs_f64(),
            at_rate_timeout_s: self.at_rate_timeout.as_secs_f64(),
        }
    }
}

/// Checks `[table]` (`t`, absent when the file has none; `no_table`: `[drift] table = "none"`
/// allows that).
pub(super) fn validate(
    t: Option<TableDoc>,
    no_table: bool,
    cx: &Ctx<'_>,
) -> Result<TableSettings, PlanError> {
    let t = match t {
        Some(t) => t,
        None if no_table => TableDoc::unused(),
        None => {
            return Err(cx.err(
                "table.port",
                "the section [table] is missing (required): add a line [table] followed by port, max_rate_dps, acceleration_dps2 (or, for a drift record on a bench without a table, [drift] table = \"none\")"
                    .into(),
            ));
        }
    };
    let dialect = match t.dialect.to_ascii_lowercase().as_str() {
        "acl" => TableDialect::Acl,
        "aerosmith" => TableDialect::Aerosmith,
        _ => {
            return Err(cx.err(
                "table.dialect",
                format!(
                    "must be \"acl\" or \"aerosmith\" (experimental) (got {:?})",
                    t.dialect
                ),
            ));
        }
    };
    let table_port = cx.port("table.port", &t.port)?;
    let table_baud = cx.one_of_u32("table.baud", t.baud, &BAUD_RATES)?;
    let max_rate = cx.finite("table.max_rate_dps", t.max_rate_dps)?;
    if max_rate <= 0.0 || max_rate > HARD_MAX_RATE_DPS {
        return Err(cx.err(
            "table.max_rate_dps",
            format!("must be > 0 and <= {HARD_MAX_RATE_DPS} (got {max_rate})"),
        ));
    }
    let acc = cx.finite("table.acceleration_dps2", t.acceleration_dps2)?;
    if acc <= 0.0 {
        return Err(cx.err(
            "table.acceleration_dps2",
            format!("must be > 0 (got {acc})"),
        ));
    }
    if acc > HARD_MAX_ACCELERATION_DPS2 {
        return Err(cx.err(
            "table.acceleration_dps2",
            format!("must be <= {HARD_MAX_ACCELERATION_DPS2} (got {acc})"),
        ));
    }
    let tol = cx.finite("table.rate_tolerance_dps", t.rate_tolerance_dps)?;
    if tol <= 0.0 || tol > max_rate {
        return Err(cx.err(
            "table.rate_tolerance_dps",
            format!("must be > 0 and <= max_rate_dps {max_rate} (got {tol})"),
        ));
    }
    let window = cx.duration("table.stability_window_s", t.stability_window_s, true)?;
    let timeout = cx.duration("table.at_rate_timeout_s", t.at_rate_timeout_s, true)?;
    if timeout <= window {
        let key = if cx.has("table.at_rate_timeout_s") || !cx.has("table.stability_window_s") {
            "table.at_rate_timeout_s"
        } else {
            "table.stability_window_s"
        };
        let default = |k: &str| {
            if cx.src.is_none() || cx.has(k) {
                ""
            } else {
                " (the default)"
            }
        };
        let (timeout_s, window_s) = (t.at_rate_timeout_s, t.stability_window_s);
        let timeout_d = default("table.at_rate_timeout_s");
        let window_d = default("table.stability_window_s");
        let message = if key == "table.at_rate_timeout_s" {
            format!(
                "= {timeout_s}{timeout_d} must be greater than stability_window_s = \
                 {window_s}{window_d} (the rate must hold for the window before the timeout \
                 ends): raise at_rate_timeout_s or lower stability_window_s"
            )
        } else {
            format!(
                "= {window_s}{window_d} must be less than at_rate_timeout_s = \
                 {timeout_s}{timeout_d} (the rate must hold for the window before the timeout \
                 ends): lower stability_window_s or raise at_rate_timeout_s"
            )
        };
        return Err(cx.err(key, message));
    }
    Ok(TableSettings {
        dialect,
        port: table_port,
        baud: table_baud,
        max_rate_dps: max_rate,
        acceleration_dps2: acc,
        rate_tolerance_dps: tol,
        stability_window: window,
        at_rate_timeout: timeout,
    })
}
