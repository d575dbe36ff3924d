//! The rows of the data files: a reading handed to the writer ([`Sample`]), a row of
//! `samples.csv` read back ([`SampleRow`]), a finished step ([`StepRecord`], a row of
//! `steps.csv`) and the checks of its numbers.
#[allow(unused_imports)]
use super::*;

/// One raw reading handed to [`RunDir::append_samples`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// 0-based, contiguous within the step (chunk after chunk).
    pub index: u64,
    /// Run clock, seconds.
    pub t_s: f64,
    /// The reading in volts; `None` for an overload (`9.9E+37`).
    pub volts: Option<f64>,
}

/// One row of `samples.csv`, as read back by [`load_samples`]: 0-based like the schedule,
/// whatever the file's counting (the file's `step_no` 4 and `sample_no` 1 are `step` 3 and
/// `index` 0 here; a file of format 2 or earlier has `step` and `index` as they are here).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SampleRow {
    /// Step index in the schedule (0-based; the file's `step_no` minus 1).
    pub step: usize,
    /// Reading index within the step (0-based; the file's `sample_no` minus 1).
    pub index: u64,
    /// Run clock, seconds.
    pub t_s: f64,
    /// Demanded rate, °/s.
    pub rate_dps: f64,
    /// Volts; empty (`None`) for an overload.
    pub volts: Option<f64>,
    /// 1 for an overload, else 0.
    pub overload: u8,
    /// `t_s` as UTC wall-clock time, RFC 3339 with milliseconds (see [`ClockAnchor`]); `None`
    /// in files written before the column existed.
    #[serde(default)]
    pub t_utc: Option<String>,
}

/// The columns of `steps.csv`, each named once: the row types written ([`StepRow`], and
/// [`PlainStepRow`] of a run that is not a series) and the headers ([`STEPS_HEADER`],
/// [`STEPS_HEADER_V4`]) are made from one list, the plain columns then the series' ones, so
/// a column added to one cannot be forgotten in another.
macro_rules! step_columns {
    (
        $(#[$plain_doc:meta])*
        plain { $($p:ident: $pt:ty,)* }
        $(#[$series_doc:meta])*
        series { $($s:ident: $st:ty,)* }
    ) => {
        /// A row of `steps.csv` as written: the sequencer's [`StepRecord`] with its step and
        /// pass counted from 1 (see `columns`), its times converted to UTC by the run
        /// directory and its computed numbers rounded (see [`crate::num`]). Built by
        /// `step_row`.
        #[derive(Debug, Serialize)]
        pub(super) struct StepRow<'a> {
            $(pub(super) $p: $pt,)*
            $(pub(super) $s: $st,)*
        }

        /// [`StepRow`] without the temperature series' columns: the row of every run that is
        /// not a series, in [`STEPS_HEADER_V4`]'s columns (a sweep's or a drift record's
        /// steps.csv is as it was before series existed, so a script reading it sees no new
        /// empty columns).
        #[derive(Debug, Serialize)]
        pub(super) struct PlainStepRow<'a> {
            $($p: $pt,)*
        }

        impl<'a> StepRow<'a> {
            /// The row without the series' columns.
            pub(super) fn plain(&self) -> PlainStepRow<'a> {
                PlainStepRow { $($p: self.$p,)* }
            }
        }

        $(#[$plain_doc])*
        pub const STEPS_HEADER_V4: [&str; [$(stringify!($p)),*].len()] = [$(stringify!($p)),*];

        $(#[$series_doc])*
        pub const STEPS_HEADER: [&str; [$(stringify!($p),)* $(stringify!($s)),*].len()] =
            [$(stringify!($p),)* $(stringify!($s)),*];
    };
}

step_columns! {
    /// Columns of `steps.csv` of every run that is not a temperature series (the format-4
    /// columns; `step_no` and `pass_no` counted from 1): the [`StepRecord`]'s fields
    /// (`step_no` and `pass_no` the record's `step` and `pass` plus one), then `t_start_utc`
    /// and `t_end_utc`, which the run directory computes from `t_start_s` and `t_end_s` (see
    /// the module docs, *Times*). A series' file has [`STEPS_HEADER`]; a file of an earlier
    /// release with these columns is a series-less run's, and a resume keeps them.
    plain {
        step_no: u64,
        pass_no: u64,
        rate_dps: f64,
        rate_meas_dps: Option<f64>,
        rate_meas_std_dps: Option<f64>,
        rate_meas_min_dps: Option<f64>,
        rate_meas_max_dps: Option<f64>,
        rate_samples: Option<u64>,
        volts: f64,
        volts_std: Option<f64>,
        n: u64,
        overloads: u64,
        retries: u32,
        t_start_s: f64,
        t_end_s: f64,
        t_start_utc: &'a str,
        t_end_utc: &'a str,
    }
    /// Columns of a temperature series' `steps.csv`, in order: [`STEPS_HEADER_V4`]'s, then
    /// the series' own: `series_point` (0-based index into `[series] temperatures_c`),
    /// `setpoint_c`, the gyro's temperature during the acquisition `temp_min_c`,
    /// `temp_mean_c`, `temp_max_c`, and `bias_record` (`1`: the bias record at that
    /// temperature, `0`: a step of its sweep). New columns go at the end, so a script that
    /// reads columns by position keeps working.
    series {
        series_point: Option<u32>,
        setpoint_c: Option<f64>,
        temp_min_c: Option<f64>,
        temp_mean_c: Option<f64>,
        temp_max_c: Option<f64>,
        bias_record: Option<u8>,
    }
}

/// `rec` with its computed numbers rounded once (the demanded rate, the plan's own number,
/// is kept bit for bit: a resume compares it with the schedule).
pub(super) fn rounded(rec: &StepRecord) -> StepRecord {
    StepRecord {
        rate_meas_dps: round_opt(rec.rate_meas_dps),
        rate_meas_std_dps: round_opt(rec.rate_meas_std_dps),
        rate_meas_min_dps: round_opt(rec.rate_meas_min_dps),
        rate_meas_max_dps: round_opt(rec.rate_meas_max_dps),
        volts: round_significant(rec.volts),
        volts_std: round_opt(rec.volts_std),
        t_start_s: round_significant(rec.t_start_s),
        t_end_s: round_significant(rec.t_end_s),
        series: rec.series.map(|c| SeriesCells {
            temp_min_c: round_opt(c.temp_min_c),
            temp_mean_c: round_opt(c.temp_mean_c),
            temp_max_c: round_opt(c.temp_max_c),
            ..c
        }),
        ..rec.clone()
    }
}

/// A step's place in a temperature series and the gyro's (product) temperature during its
/// acquisition: steps.csv's columns `series_point`, `setpoint_c`, `temp_min_c`,
/// `temp_mean_c`, `temp_max_c` and `bias_record`, empty on the rows of every other kind (and
/// absent from files written before they existed).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SeriesCells {
    /// 0-based index into the plan's `[series] temperatures_c`.
    pub series_point: u32,
    /// The chamber's setpoint, °C (the plan's number, kept bit for bit).
    pub setpoint_c: f64,
    /// The gyro's lowest temperature read during the acquisition, °C (`None`: no reading).
    pub temp_min_c: Option<f64>,
    /// Its mean, °C.
    pub temp_mean_c: Option<f64>,
    /// Its highest, °C.
    pub temp_max_c: Option<f64>,
    /// The row is the bias record at this temperature (0 °/s, `[series] bias_readings`
    /// readings), written `1`; a step of the sweep is `0`.
    pub bias_record: bool,
}

/// The series columns of a steps.csv row as read (every one optional).
#[derive(Debug, Default, Deserialize)]
pub(super) struct SeriesColumns {
    #[serde(default)]
    series_point: Option<u32>,
    #[serde(default)]
    setpoint_c: Option<f64>,
    #[serde(default)]
    temp_min_c: Option<f64>,
    #[serde(default)]
    temp_mean_c: Option<f64>,
    #[serde(default)]
    temp_max_c: Option<f64>,
    #[serde(default)]
    bias_record: Option<u8>,
}

impl SeriesColumns {
    /// The cells, when the row is a series step (`series_point` given); a row with some
    /// series cells but no `series_point` or `setpoint_c`, or a `bias_record` other than 0
    /// or 1, is an error.
    pub(super) fn cells(self) -> Result<Option<SeriesCells>, String> {
        let any = self.setpoint_c.is_some()
            || self.temp_min_c.is_some()
            || self.temp_mean_c.is_some()
            || self.temp_max_c.is_some()
            || self.bias_record.is_some();
        let Some(series_point) = self.series_point else {
            return if any {
                Err("has temperature cells but no series_point".into())
            } else {
                Ok(None)
            };
        };
        let Some(setpoint_c) = self.setpoint_c else {
            return Err("has a series_point but no setpoint_c".into());
        };
        let bias_record = match self.bias_record {
            None | Some(0) => false,
            Some(1) => true,
            Some(other) => return Err(format!("bias_record must be 0 or 1 (got {other})")),
        };
        Ok(Some(SeriesCells {
            series_point,
            setpoint_c,
            temp_min_c: self.temp_min_c,
            temp_mean_c: self.temp_mean_c,
            temp_max_c: self.temp_max_c,
            bias_record,
        }))
    }
}

/// One row of `steps.csv`: a finished step. The sequencer fills it; [`RunDir::append_step`]
/// checks it against the schedule and the samples written. 0-based like the schedule: the
/// file's `step_no` and `pass_no` are `step + 1` and `pass + 1` (see [`STEPS_HEADER`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StepRecord {
    /// Step index in the schedule (0-based).
    pub step: usize,
    /// Pass (0-based).
    pub pass: u32,
    /// Demanded rate, °/s (must equal the schedule's).
    pub rate_dps: f64,
    /// Mean measured table rate during the acquisition, °/s (empty if not measured).
    pub rate_meas_dps: Option<f64>,
    /// Std of the measured rate, °/s.
    pub rate_meas_std_dps: Option<f64>,
    /// Minimum measured rate, °/s.
    pub rate_meas_min_dps: Option<f64>,
    /// Maximum measured rate, °/s.
    pub rate_meas_max_dps: Option<f64>,
    /// Number of table rate samples taken during the acquisition (the basis of the
    /// `rate_meas_*` figures); empty when not recorded, and in files written before the column
    /// existed.
    #[serde(default)]
    pub rate_samples: Option<u64>,
    /// Mean of the valid readings, V.
    pub volts: f64,
    /// Sample standard deviation of the valid readings, V (empty when `n = 1`).
    pub volts_std: Option<f64>,
    /// Number of valid readings averaged (≥ 1).
    pub n: u64,
    /// Number of overload readings (written to samples.csv, excluded from the mean).
    pub overloads: u64,
    /// Retries during this step.
    pub retries: u32,
    /// Run clock at the start of the acquisition, s.
    pub t_start_s: f64,
    /// Run clock at the end of the acquisition, s.
    pub t_end_s: f64,
    /// On a temperature series: the step's temperature and the gyro's during it (the
    /// columns `series_point` … `bias_record`, see [`SeriesCells`]); `None` for every other
    /// kind.
    #[serde(skip)]
    pub series: Option<SeriesCells>,
}

/// Problems of a step record's numbers, if any.
pub(super) fn record_problem(r: &StepRecord) -> Option<String> {
    if !r.volts.is_finite() {
        return Some(format!("volts must be finite (got {})", r.volts));
    }
    let opts = [
        ("volts_std", r.volts_std),
        ("rate_meas_dps", r.rate_meas_dps),
        ("rate_meas_std_dps", r.rate_meas_std_dps),
        ("rate_meas_min_dps", r.rate_meas_min_dps),
        ("rate_meas_max_dps", r.rate_meas_max_dps),
    ];
    for (what, v) in opts {
        if v.is_some_and(|v| !v.is_finite()) {
            return Some(format!("{what} must be finite or empty (got {v:?})"));
        }
    }
    if let Some(c) = &r.series {
        if !c.setpoint_c.is_finite() {
            return Some(format!("setpoint_c must be finite (got {})", c.setpoint_c));
        }
        let temps = [
            ("temp_min_c", c.temp_min_c),
            ("temp_mean_c", c.temp_mean_c),
            ("temp_max_c", c.temp_max_c),
        ];
        for (what, v) in temps {
            if v.is_some_and(|v| !v.is_finite()) {
                return Some(format!("{what} must be finite or empty (got {v:?})"));
            }
        }
        if let (Some(lo), Some(mean), Some(hi)) = (c.temp_min_c, c.temp_mean_c, c.temp_max_c)
            && !(lo <= mean && mean <= hi)
        {
            return Some(format!(
                "temp_min_c {lo}, temp_mean_c {mean} and temp_max_c {hi} must be ordered"
            ));
        }
    }
    if !r.t_start_s.is_finite() || !r.t_end_s.is_finite() || r.t_end_s < r.t_start_s {
        return Some(format!(
            "t_start_s {} and t_end_s {} must be finite and ordered",
            r.t_start_s, r.t_end_s
        ));
    }
    None
}

/// Whether a row's series cells fit its schedule step: both without, or the same point,
/// setpoint (bit for bit: the plan's number) and kind of record. The message says what
/// differs.
pub(super) fn series_mismatch(r: &StepRecord, s: &Step) -> Option<String> {
    match (r.series, s.series) {
        (None, None) => None,
        (Some(c), Some(t))
            if c.series_point == t.point
                && c.setpoint_c.to_bits() == t.setpoint_c.to_bits()
                && c.bias_record == t.bias_record =>
        {
            None
        }
        (Some(c), Some(t)) => Some(format!(
            "series_point {} setpoint_c {} bias_record {} where the schedule has series_point {} setpoint_c {} bias_record {}",
            c.series_point,
            c.setpoint_c,
            u8::from(c.bias_record),
            t.point,
            t.setpoint_c,
            u8::from(t.bias_record)
        )),
        (None, Some(t)) => Some(format!(
            "has no series cells where the schedule measures at series_point {} ({} °C)",
            t.point, t.setpoint_c
        )),
        (Some(c), None) => Some(format!(
            "has series_point {} on a plan that is no temperature series",
            c.series_point
        )),
    }
}

#[cfg(test)]
#[path = "series_tests.rs"]
mod series_tests;
