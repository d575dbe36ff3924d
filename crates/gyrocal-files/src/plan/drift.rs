//! The drift record (`[plan] kind = "drift"`, IEEE 952 §6.6): a static record at zero rate in
//! durable segments, analysed by Allan deviation. Everything only a drift plan has is here:
//! its `[drift]` section (the table's role, the bench's orientation and latitude), the Earth
//! rate, and its rules (one rate, 0; `[drift]` on a drift plan only; servo off needs a table
//! that can switch its servo off).

use serde::{Deserialize, Serialize};
use toml::de::DeTable;

use super::Plan;
use super::error::PlanError;
use super::kind::PlanKind;
use super::raw::{S, Spans};
use super::schedule::Step;
use super::schema::{KeySchema, Kind};
use super::table::TableDialect;
use super::validate::Ctx;
use crate::steps::{Acquiring, Action, ChamberAction, Compiled, HoldCheck, Record, Setup, TableAction};

/// The keys of `[drift]`.
pub(super) const KEYS: &[KeySchema] = &[
    ("table", Kind::Text, false),
    ("axis", Kind::Text, false),
    ("latitude_deg", Kind::Number, false),
];

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawDrift {
    pub(super) table: Option<S<String>>,
    pub(super) axis: Option<S<String>>,
    pub(super) latitude_deg: Option<S<f64>>,
}

/// `[drift]` as parsed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DriftDoc {
    /// The table's role: `hold` or `servo_off`.
    pub table: String,
    /// Where the input axis points (`up`, `down`, `north`, `south`, `east`, `west`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub axis: Option<String>,
    /// The bench's latitude, degrees north.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub latitude_deg: Option<f64>,
}

impl DriftDoc {
    /// `[drift]` as written, defaults filled in, spans kept.
    pub(super) fn from_raw(d: RawDrift, sp: &mut Spans) -> DriftDoc {
        DriftDoc {
            table: sp.opt("drift.table", d.table, TableRole::Hold.as_str().into()),
            axis: d.axis.map(|v| sp.take("drift.axis", v)),
            latitude_deg: d.latitude_deg.map(|v| sp.take("drift.latitude_deg", v)),
        }
    }
}

/// What the rate table does during a drift record (`[drift] table`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum TableRole {
    /// Servo on, holding 0 °/s; every segment is checked against the hold tolerance like a
    /// step of a sweep (the default: a table with its servo on is stiff against the gyro's
    /// cables and the floor).
    #[default]
    Hold,
    /// Brought to rest, then its servo switched off (ACL `:Interlock:Open`, the controller's
    /// orderly shutdown: an ABORT profile to zero, then servo off) for the whole record: no
    /// servo jitter on the input axis. The table's rate is still sampled; a segment during
    /// which it moved more than the hold tolerance is not recorded, and one during which it
    /// left OFF ends the run. ACL tables only (the aerosmith dialect has no servo-off command).
    ServoOff,
    /// No table at all (a gyro on a bench or a fixture): nothing is opened, moved or sampled
    /// on a table's port, and `[table]` may be left out.
    None,
}

impl TableRole {
    /// All roles.
    pub const ALL: [TableRole; 3] = [TableRole::Hold, TableRole::ServoOff, TableRole::None];

    /// As written in a plan.
    pub fn as_str(self) -> &'static str {
        match self {
            TableRole::Hold => "hold",
            TableRole::ServoOff => "servo_off",
            TableRole::None => "none",
        }
    }

    /// What the table does, in words for a reader (`gyrocal check`, the Allan page).
    pub fn describe(self) -> &'static str {
        match self {
            TableRole::Hold => "holding 0 °/s (servo on)",
            TableRole::ServoOff => "at rest, servo off",
            TableRole::None => "none (no table is opened)",
        }
    }
}

/// Earth's rotation rate, °/h (15.041 °/h: one turn per sidereal day).
pub const EARTH_RATE_DPH: f64 = 15.041;

/// Where a gyro's input axis points on the bench.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Axis {
    /// Local vertical, up: senses Ω·sin(latitude).
    Up,
    /// Down: −Ω·sin(latitude).
    Down,
    /// Horizontal, north: Ω·cos(latitude).
    North,
    /// Horizontal, south: −Ω·cos(latitude).
    South,
    /// Horizontal, east: no Earth rate.
    East,
    /// Horizontal, west: no Earth rate.
    West,
}

impl Axis {
    /// All directions.
    pub const ALL: [Axis; 6] = [
        Axis::Up,
        Axis::Down,
        Axis::North,
        Axis::South,
        Axis::East,
        Axis::West,
    ];

    /// As written in a plan and on the command line.
    pub fn as_str(self) -> &'static str {
        match self {
            Axis::Up => "up",
            Axis::Down => "down",
            Axis::North => "north",
            Axis::South => "south",
            Axis::East => "east",
            Axis::West => "west",
        }
    }

    /// The direction named `s` (ASCII case ignored).
    pub fn from_name(s: &str) -> Option<Axis> {
        Axis::ALL
            .into_iter()
            .find(|a| a.as_str().eq_ignore_ascii_case(s.trim()))
    }

    /// The Earth-rate component along the axis at `latitude_deg`, °/h.
    pub fn earth_rate_dph(self, latitude_deg: f64) -> f64 {
        let phi = latitude_deg.to_radians();
        match self {
            Axis::Up => EARTH_RATE_DPH * phi.sin(),
            Axis::Down => -EARTH_RATE_DPH * phi.sin(),
            Axis::North => EARTH_RATE_DPH * phi.cos(),
            Axis::South => -EARTH_RATE_DPH * phi.cos(),
            Axis::East | Axis::West => 0.0,
        }
    }
}

/// The validated `[drift]` section (defaults when the plan has none).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DriftSettings {
    /// What the table does during the record.
    pub table: TableRole,
    /// The input axis and the latitude, when given (both or neither): the Earth's rate along
    /// the axis is removed from the bias in the run's Allan analysis.
    pub earth: Option<(Axis, f64)>,
}

impl DriftSettings {
    /// As the document writes it.
    pub(super) fn to_doc(self) -> DriftDoc {
        DriftDoc {
            table: self.table.as_str().into(),
            axis: self.earth.map(|(a, _)| a.as_str().into()),
            latitude_deg: self.earth.map(|(_, l)| l),
        }
    }
}

/// Whether `[drift]` says there is no table (`table = "none"`): then `[table]` may be left
/// out.
pub(super) fn has_no_table(d: Option<&DriftDoc>) -> bool {
    d.is_some_and(|d| d.table.trim() == TableRole::None.as_str())
}

/// The same, read off the file's shape before serde (`root`: the whole file), so the shape
/// check does not ask for a `[table]` the plan does not need.
pub(super) fn has_no_table_in(root: &DeTable<'_>) -> bool {
    root.iter()
        .find(|(k, _)| k.get_ref().as_ref() == "drift")
        .and_then(|(_, v)| v.get_ref().as_table())
        .and_then(|d| {
            d.iter()
                .find(|(k, _)| k.get_ref().as_ref() == "table")
                .and_then(|(_, v)| v.get_ref().as_str().map(|s| s.trim() == "none"))
        })
        .unwrap_or(false)
}

impl Plan {
    /// `[drift]`: the table's role and the bench's orientation (the defaults when the plan
    /// has no `[drift]`; only a drift plan may have one).
    pub fn drift(&self) -> DriftSettings {
        self.kind_sections.drift.unwrap_or_default()
    }
}

/// A drift plan records once at rest: exactly one rate, 0.
pub(super) fn check_rates(rates: &[f64], written: &[f64], cx: &Ctx<'_>) -> Result<(), PlanError> {
    // exactly one rate: each listed rate is one more record segment, so [0, 0] would
    // silently double the record
    if rates != [0.0] {
        return Err(cx.err(
            "plan.rates_dps",
            format!(
                "a drift plan records once at rest: write exactly rates_dps = [0] (got {written:?}; \
                 each listed rate would be one more record)"
            ),
        ));
    }
    Ok(())
}

/// `[drift]`: a drift plan's only; `servo_off` needs the ACL dialect.
pub(super) fn validate(
    drift: Option<DriftDoc>,
    kind: PlanKind,
    dialect: TableDialect,
    cx: &Ctx<'_>,
) -> Result<Option<DriftSettings>, PlanError> {
    Ok(match drift {
        None => None,
        Some(_) if kind != PlanKind::Drift => {
            return Err(cx.err(
                "drift.table",
                "[drift] belongs to a drift plan: add kind = \"drift\" to [plan], or remove [drift]"
                    .into(),
            ));
        }
        Some(d) => {
            let d = validate_drift(&d, cx)?;
            if d.table == TableRole::ServoOff && dialect == TableDialect::Aerosmith {
                return Err(cx.err(
                    "drift.table",
                    "= \"servo_off\" needs a table whose servo gyrocal can switch off: the ACL dialect (`:Interlock:Open`); the aerosmith dialect knows no servo-off command (`STO` only stops): write \"hold\" or \"none\""
                        .into(),
                ));
            }
            Some(d)
        }
    })
}

fn validate_drift(d: &DriftDoc, cx: &Ctx<'_>) -> Result<DriftSettings, PlanError> {
    let table = TableRole::ALL
        .into_iter()
        .find(|r| r.as_str() == d.table.trim())
        .ok_or_else(|| {
            cx.err(
                "drift.table",
                format!(
                    "= {:?} is not a table role: write \"hold\" (servo on at 0 °/s), \"servo_off\" (stopped, servo off) or \"none\" (no table)",
                    d.table
                ),
            )
        })?;
    let axis = match &d.axis {
        None => None,
        Some(a) => Some(Axis::from_name(a).ok_or_else(|| {
            cx.err(
                "drift.axis",
                format!(
                    "= {a:?} is not a direction: write \"up\", \"down\", \"north\", \"south\", \"east\" or \"west\""
                ),
            )
        })?),
    };
    let latitude = match d.latitude_deg {
        None => None,
        Some(l) => {
            let l = cx.finite("drift.latitude_deg", l)?;
            if !(-90.0..=90.0).contains(&l) {
                return Err(cx.err(
                    "drift.latitude_deg",
                    format!("must be from -90 to 90 degrees (got {l})"),
                ));
            }
            Some(l)
        }
    };
    let earth = match (axis, latitude) {
        (Some(a), Some(l)) => Some((a, l)),
        (None, None) => None,
        (Some(_), None) => {
            return Err(cx.err(
                "drift.axis",
                "needs latitude_deg too: the Earth's rate along the axis depends on it".into(),
            ));
        }
        (None, Some(_)) => {
            return Err(cx.err(
                "drift.latitude_deg",
                "needs axis too: the Earth's rate seen depends on where the input axis points"
                    .into(),
            ));
        }
    };
    Ok(DriftSettings { table, earth })
}

/// What `gyrocal check` says of a drift plan: the table's role and the Earth rate removed.
pub(super) fn summary(d: &DriftSettings) -> super::kind::KindSummary {
    super::kind::KindSummary {
        key: "drift",
        line: format!(
            "drift record: table {}{}",
            d.table.describe(),
            d.earth.map_or(String::new(), |(a, l)| format!(
                "; input axis {} at latitude {l}°: {:.3} °/h of Earth rate removed from the bias",
                a.as_str(),
                a.earth_rate_dph(l)
            ))
        ),
        json: serde_json::json!({
            "table": d.table.as_str(),
            "axis": d.earth.map(|(a, _)| a.as_str()),
            "latitude_deg": d.earth.map(|(_, l)| l),
        }),
    }
}

/// The drift record compiled to steps (see [`crate::steps`]): segment steps at zero rate, the
/// table's part set by `[drift] table` (hold 0 °/s with the servo on, at rest with the servo
/// off, or no table), the warm-up (when asked for) watched in the record's first segments.
pub(crate) fn compile(plan: &Plan, remaining: &[Step], warmup_done: bool) -> Compiled {
    let role = plan.drift().table;
    let tolerance_dps = plan.table().rate_tolerance_dps;
    let setup = match role {
        TableRole::Hold => Setup::EnableTable,
        TableRole::ServoOff => Setup::RestThenServoOff,
        TableRole::None => Setup::Nothing,
    };
    let steps = remaining
        .iter()
        .map(|step| {
            let (table, hold) = match role {
                TableRole::Hold => (
                    TableAction::Rate(step.rate_dps),
                    HoldCheck::Rate {
                        demand_dps: step.rate_dps,
                        tolerance_dps,
                    },
                ),
                TableRole::ServoOff => {
                    (TableAction::ServoOff, HoldCheck::ServoOff { tolerance_dps })
                }
                TableRole::None => (TableAction::Untouched, HoldCheck::None),
            };
            Action {
                table,
                dwell: plan.settle(),
                acquire: Acquiring::Readings(step.acquire),
                hold,
                record: Record::Segment(*step),
                chamber: ChamberAction::None,
            }
        })
        .collect();
    Compiled {
        setup,
        steps,
        warmup_in_record: plan.warmup().copied().filter(|_| !warmup_done),
        schedule_len: plan.step_count(),
        uses_table: role != TableRole::None,
        uses_chamber: false,
    }
}
