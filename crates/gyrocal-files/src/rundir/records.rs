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

/// A row of `steps.csv` as written: the sequencer's [`StepRecord`] with its step and pass
/// counted from 1 (see `columns`), its times converted to UTC by the run directory and its
/// computed numbers rounded (see [`crate::num`]). Built by `step_row`.
#[derive(Debug, Serialize)]
pub(super) struct StepRow<'a> {
    pub(super) step_no: u64,
    pub(super) pass_no: u64,
    pub(super) rate_dps: f64,
    pub(super) rate_meas_dps: Option<f64>,
    pub(super) rate_meas_std_dps: Option<f64>,
    pub(super) rate_meas_min_dps: Option<f64>,
    pub(super) rate_meas_max_dps: Option<f64>,
    pub(super) rate_samples: Option<u64>,
    pub(super) volts: f64,
    pub(super) volts_std: Option<f64>,
    pub(super) n: u64,
    pub(super) overloads: u64,
    pub(super) retries: u32,
    pub(super) t_start_s: f64,
    pub(super) t_end_s: f64,
    pub(super) t_start_utc: &'a str,
    pub(super) t_end_utc: &'a str,
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
        ..rec.clone()
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
    if !r.t_start_s.is_finite() || !r.t_end_s.is_finite() || r.t_end_s < r.t_start_s {
        return Some(format!(
            "t_start_s {} and t_end_s {} must be finite and ordered",
            r.t_start_s, r.t_end_s
        ));
    }
    None
}
