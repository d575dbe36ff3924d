//! Stage 2, validation: a [`PlanDoc`] (defaults filled in) becomes a [`Plan`], one section at
//! a time by the section's own module, in the order below (the table first: the rates are
//! checked against its limits). Every error points at the offending value through the span
//! kept in stage 1 ([`Ctx`]), so a message reads `configs/bad.toml:7:21: [table]
//! acceleration_dps2 must be > 0 (got 0)`.

use std::path::Path;
use std::time::Duration;

use gyrocal_link::PortErrorKind;

use super::doc::PlanDoc;
use super::error::{Location, PlanError};
use super::raw::Spans;
use super::schema::int_error;
use super::source::line_col;
use super::{MAX_DURATION_S, Plan, Port};
use super::{acceptance, dmm, dut, section, simulation, table, warmup};

/// Where a plan came from, to place its errors.
pub(super) struct Ctx<'a> {
    /// The file (or label) errors name.
    pub(super) origin: &'a Path,
    /// The file's text, when the plan came from one (errors then carry line and column).
    pub(super) src: Option<&'a str>,
    /// Where each value was in `src`.
    pub(super) spans: &'a Spans,
}

impl Ctx<'_> {
    /// An error at `path` (`section.key`), placed at the value's span when the file had it.
    pub(super) fn err(&self, path: &str, message: String) -> PlanError {
        // `acceptance.scale_factor.min` is the key `min` of [acceptance.scale_factor]
        let (section, key) = path.rsplit_once('.').unwrap_or(("plan", path));
        let (line, column) = match (self.src, self.spans.0.get(path)) {
            (Some(src), Some(span)) => {
                let (l, c) = line_col(src, span.start);
                (Some(l), Some(c))
            }
            _ => (None, None),
        };
        PlanError::Invalid {
            location: Location {
                file: self.origin.to_path_buf(),
                line,
                column,
            },
            section: section.to_string(),
            key: key.to_string(),
            message,
        }
    }

    pub(super) fn has(&self, path: &str) -> bool {
        self.spans.0.contains_key(path)
    }

    pub(super) fn finite(&self, path: &str, v: f64) -> Result<f64, PlanError> {
        if v.is_finite() {
            Ok(v)
        } else {
            Err(self.err(path, format!("must be finite (got {v})")))
        }
    }

    pub(super) fn one_of_f64(&self, path: &str, v: f64, allowed: &[f64]) -> Result<f64, PlanError> {
        // Exact comparison is intended: TOML `0.02` and the constant 0.02 are the same double.
        if allowed.contains(&v) {
            Ok(v)
        } else {
            Err(self.err(path, format!("must be one of {allowed:?} (got {v})")))
        }
    }

    pub(super) fn one_of_u32(&self, path: &str, v: i64, allowed: &[u32]) -> Result<u32, PlanError> {
        match u32::try_from(v) {
            Ok(u) if allowed.contains(&u) => Ok(u),
            _ => Err(self.err(path, int_error(path, &v.to_string(), true))),
        }
    }

    /// An integer key: `v` must be in `lo..=hi` (both within `u32`).
    pub(super) fn int_in(&self, path: &str, v: i64, lo: u32, hi: u32) -> Result<u32, PlanError> {
        match u32::try_from(v) {
            Ok(u) if (lo..=hi).contains(&u) => Ok(u),
            _ => Err(self.err(path, int_error(path, &v.to_string(), true))),
        }
    }

    pub(super) fn duration(
        &self,
        path: &str,
        v: f64,
        min_exclusive: bool,
    ) -> Result<Duration, PlanError> {
        let v = self.finite(path, v)?;
        if v < 0.0 || (min_exclusive && v == 0.0) {
            let op = if min_exclusive { ">" } else { ">=" };
            return Err(self.err(path, format!("must be {op} 0 (got {v})")));
        }
        if v > MAX_DURATION_S {
            return Err(self.err(path, format!("must be <= {MAX_DURATION_S} s (got {v})")));
        }
        let d = Duration::from_secs_f64(v);
        // a positive duration below a nanosecond would be stored (and read back) as 0
        if min_exclusive && d.is_zero() {
            return Err(self.err(path, format!("must be at least 1e-9 s (got {v})")));
        }
        Ok(d)
    }

    /// A port, parsed into the link's type. A wrong part of a GPIB port string is said with
    /// what to write, naming the key as `section.key` (the way `gyrocal check` said it when the
    /// link layer checked it after the plan).
    pub(super) fn port(&self, path: &str, v: &str) -> Result<Port, PlanError> {
        Port::parse(v).map_err(|e| {
            let message = match e.kind() {
                PortErrorKind::Gpib => format!(
                    "= {v:?} is not a GPIB port: {e}; write {path} as prologix:DEVICE?addr=N or \
                     prologix-tcp://HOST[:PORT]?addr=N"
                ),
                _ => e.to_string(),
            };
            self.err(path, message)
        })
    }
}

/// Validates a whole plan, section by section.
pub(super) fn validate(doc: PlanDoc, cx: &Ctx<'_>) -> Result<Plan, PlanError> {
    let PlanDoc {
        plan,
        table,
        dmm,
        simulation,
        dut,
        acceptance,
        kinds,
        warmup,
    } = doc;
    // [table] first: the rates are checked against its limits. A drift record without a
    // table (`[drift] table = "none"`) may leave the section out.
    let table_given = table.is_some();
    let table = table::validate(table, !kinds.uses_table(), cx)?;
    let section = section::validate(plan, table.max_rate_dps, cx)?;
    let dmm = dmm::validate(dmm, &table.port, cx)?;
    simulation::validate(&simulation, cx)?;
    let dut = dut::validate(dut, cx)?;
    if let Some(a) = &acceptance {
        acceptance::validate(a, cx)?;
    }
    let kind_sections = kinds.validate(section.kind, table.dialect, &section.rates_dps, cx)?;
    let warmup = warmup.map(|w| warmup::validate(&w, cx)).transpose()?;
    Ok(Plan {
        kind_sections,
        warmup,
        table_given,
        kind: section.kind,
        name: section.name,
        rates_dps: section.rates_dps,
        samples_per_rate: section.samples_per_rate,
        settle: section.settle,
        repeat: section.repeat,
        whole_revolutions: section.whole_revolutions,
        table,
        dmm,
        simulation,
        dut,
        acceptance,
    })
}
