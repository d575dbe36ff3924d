//! Stage 1, the raw form: private serde structs mirror the file (one per section, each in its
//! section's module), reject unknown keys (`deny_unknown_fields`) and keep the byte span of
//! every value ([`toml::Spanned`]); [`raw_to_doc`] fills in the defaults and records every
//! value's span in [`Spans`], so validation can point at it.

use std::collections::BTreeMap;
use std::fmt;
use std::ops::Range;

use serde::Deserialize;
use toml::Spanned;

use super::acceptance::{RawAcceptance, raw_acceptance};
use super::dmm::{DmmDoc, RawDmm};
use super::doc::PlanDoc;
use super::dut::RawDut;
use super::schema::int_error;
use super::section::{PlanSectionDoc, RawPlan};
use super::simulation::{RawSimulation, Simulation};
use super::table::{RawTable, TableDoc};
use super::warmup::{RawWarmup, WarmupDoc};

pub(super) type S<T> = Spanned<T>;

/// The file's common sections. A test kind's own section (`[drift]`) is not here: the kind's
/// module reads it from the same text ([`super::kind::raw_sections`]), so a new kind does not
/// touch this struct. Unknown sections were refused by the shape check before serde runs.
#[derive(Deserialize)]
pub(super) struct RawFile {
    pub(super) plan: RawPlan,
    /// Absent only with `[drift] table = "none"` (the shape check says so otherwise).
    pub(super) table: Option<RawTable>,
    pub(super) dmm: RawDmm,
    pub(super) simulation: Option<RawSimulation>,
    pub(super) dut: Option<RawDut>,
    pub(super) acceptance: Option<RawAcceptance>,
    pub(super) warmup: Option<RawWarmup>,
}

/// An integer key as written. Any TOML value is accepted at this stage, so that whatever was
/// written (an integer beyond 64 bits, a float, a string) is refused naming the key and the
/// allowed values, like an integer out of range, instead of as a serde type error.
pub(super) enum RawInt {
    /// A 64-bit integer (range-checked by validation).
    Int(i64),
    /// Anything else, as it reads in an error message, and whether it is a whole number (an
    /// integer beyond 64 bits).
    Other(String, bool),
}

impl<'de> Deserialize<'de> for RawInt {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> serde::de::Visitor<'de> for V {
            type Value = RawInt;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("a whole number")
            }
            fn visit_i64<E>(self, v: i64) -> Result<RawInt, E> {
                Ok(RawInt::Int(v))
            }
            fn visit_u64<E>(self, v: u64) -> Result<RawInt, E> {
                Ok(i64::try_from(v)
                    .map_or_else(|_| RawInt::Other(v.to_string(), true), RawInt::Int))
            }
            fn visit_i128<E>(self, v: i128) -> Result<RawInt, E> {
                Ok(i64::try_from(v)
                    .map_or_else(|_| RawInt::Other(v.to_string(), true), RawInt::Int))
            }
            fn visit_u128<E>(self, v: u128) -> Result<RawInt, E> {
                Ok(i64::try_from(v)
                    .map_or_else(|_| RawInt::Other(v.to_string(), true), RawInt::Int))
            }
            fn visit_f64<E>(self, v: f64) -> Result<RawInt, E> {
                Ok(RawInt::Other(format!("{v:?}"), false))
            }
            fn visit_bool<E>(self, v: bool) -> Result<RawInt, E> {
                Ok(RawInt::Other(v.to_string(), false))
            }
            fn visit_str<E>(self, v: &str) -> Result<RawInt, E> {
                Ok(RawInt::Other(format!("{v:?}"), false))
            }
        }
        d.deserialize_any(V)
    }
}

/// Spans of the values present in the file, keyed by `section.key` (`plan.rates_dps[2]`).
#[derive(Default)]
pub(super) struct Spans(pub(super) BTreeMap<String, Range<usize>>);

impl Spans {
    pub(super) fn take<T>(&mut self, key: &str, v: S<T>) -> T {
        self.0.insert(key.to_string(), v.span());
        v.into_inner()
    }
    pub(super) fn opt<T>(&mut self, key: &str, v: Option<S<T>>, default: T) -> T {
        match v {
            Some(v) => self.take(key, v),
            None => default,
        }
    }
    /// An integer key (`default` when absent); a value that is not a 64-bit integer is an
    /// error `(key, message)`.
    pub(super) fn int(
        &mut self,
        key: &'static str,
        v: Option<S<RawInt>>,
        default: i64,
    ) -> Result<i64, (&'static str, String)> {
        match v.map(|v| self.take(key, v)) {
            None => Ok(default),
            Some(RawInt::Int(i)) => Ok(i),
            Some(RawInt::Other(shown, whole)) => Err((key, int_error(key, &shown, whole))),
        }
    }
}

/// The raw file with defaults filled in, each section by its own module. The one check here
/// is the simulation seed's sign (the seed is unsigned where the rest of the plan is
/// validated); the error is `(key, message)`.
pub(super) fn raw_to_doc(
    raw: RawFile,
    kinds: super::kind::KindSectionsDoc,
    sp: &mut Spans,
) -> Result<PlanDoc, (&'static str, String)> {
    Ok(PlanDoc {
        plan: PlanSectionDoc::from_raw(raw.plan, sp)?,
        table: raw.table.map(|t| TableDoc::from_raw(t, sp)).transpose()?,
        dmm: DmmDoc::from_raw(raw.dmm, sp)?,
        simulation: raw.simulation.map_or_else(
            || Ok(Simulation::default()),
            |s| Simulation::from_raw(s, sp),
        )?,
        dut: raw.dut.map(|d| super::dut::from_raw(d, sp)),
        acceptance: raw.acceptance.map(|a| raw_acceptance(a, sp)).transpose()?,
        kinds,
        warmup: raw.warmup.map(|w| WarmupDoc::from_raw(w, sp)),
    })
}
