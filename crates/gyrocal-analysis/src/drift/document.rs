//! The result of a drift record's analysis: [`AllanDocument`], what `allan.json` holds, what
//! `gyrocal allan --json` prints and what the report crate's drift page renders. Its JSON
//! form is a file format (`allan.json`, read back typed by the catalog): fields are added
//! with `#[serde(default)]`, never renamed.

use std::path::{Path, PathBuf};

use gyrocal_allan::{BiasFigures, Curve, NoiseTerms};
use gyrocal_files::rundir::{ALLAN_JSON, MAX_FIT_BYTES, RunError, WriteResult, read_capped};
use serde::{Deserialize, Serialize};

use super::Axis;
use super::bounded::MemoryUse;

/// What a run directory's record is and whose: the head of the page, as on a certificate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunHeader {
    /// The plan's name.
    pub plan_name: String,
    /// The plan's hash.
    pub plan_hash: String,
    /// `complete`, `aborted`, `failed` or `running`.
    pub status: String,
    /// The record was taken on the simulated bench.
    pub simulated: bool,
    /// The gyro's serial number and model, when named.
    pub dut_serial: Option<String>,
    /// The gyro's model.
    pub dut_model: Option<String>,
    /// The station's id and lab.
    pub station: Option<String>,
    /// Who ran it.
    pub operator: Option<String>,
    /// When the record started and ended, UTC.
    pub started_utc: String,
    /// When it ended (absent while running).
    pub ended_utc: Option<String>,
    /// The multimeter's identity.
    pub multimeter: Option<String>,
    /// The table's identity, and its role during the record.
    pub table: String,
    /// Departures from the method (`kind: text`).
    pub deviations: Vec<String>,
}

impl RunHeader {
    /// The head of the run whose manifest is `m`.
    pub fn of(m: &gyrocal_files::Manifest) -> RunHeader {
        let d = m.plan.drift();
        let role = d.table.describe();
        RunHeader {
            plan_name: m.plan.name().to_string(),
            plan_hash: m.plan_hash.clone(),
            status: serde_json::to_value(m.status)
                .ok()
                .and_then(|v| v.as_str().map(str::to_string))
                .unwrap_or_default(),
            simulated: m.simulated,
            dut_serial: m.dut.as_ref().and_then(|d| d.serial.clone()),
            dut_model: m.dut.as_ref().and_then(|d| d.model.clone()),
            station: m.station.as_ref().map(|s| format!("{} — {}", s.id, s.lab)),
            operator: m.context.as_ref().and_then(|c| c.operator.clone()),
            started_utc: m.started_utc.clone(),
            ended_utc: m.ended_utc.clone(),
            multimeter: m.instruments.dmm.clone(),
            table: match (&m.instruments.table, d.table) {
                (_, gyrocal_files::plan::TableRole::None) => "none (the plan has no table)".into(),
                (Some(id), _) => format!("{id} ({role})"),
                (None, _) => format!("({role})"),
            },
            deviations: m
                .deviations
                .iter()
                .map(|x| format!("{}: {}", x.kind, x.text))
                .collect(),
        }
    }
}

/// The bias with the Earth rate removed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EarthRateRemoved {
    /// Input axis direction.
    pub axis: Axis,
    /// Latitude, degrees (north positive).
    pub latitude_deg: f64,
    /// Earth-rate component along the axis, °/h.
    pub component_dph: f64,
    /// The measured mean rate, °/h.
    pub bias_measured_dph: f64,
    /// The gyro's own bias: measured minus the component, °/h.
    pub bias_dph: f64,
}

/// The scale factor used and where it came from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ScaleFactorUsed {
    /// K, V/(°/s).
    pub v_per_dps: f64,
    /// `option` (given) or the path of the fit.json it was read from.
    pub source: String,
}

/// A gap-free stretch of the record.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Segment {
    /// 1-based line of its first and last row in the file.
    pub lines: (u64, u64),
    /// Time of its first and last sample, s (τ0-spaced indices without a time column).
    pub t_s: (f64, f64),
    /// Number of samples.
    pub samples: usize,
    /// This is the segment analysed.
    pub analysed: bool,
}

/// What was analysed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Analysed {
    /// Index into [`AllanDocument::segments`].
    pub segment: usize,
    /// Time of the first sample analysed (after the warm-up) and of the last, s.
    pub t_s: (f64, f64),
    /// Samples analysed (after the warm-up).
    pub samples: usize,
    /// Their duration N·τ0, s.
    pub duration_s: f64,
    /// Samples of the segment left out as warm-up.
    pub warmup_samples: usize,
}

/// The warm-up found on the analysed segment.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Warmup {
    /// Window of the rolling mean, s (a whole number of samples).
    pub window_s: f64,
    /// Tolerance on the change of consecutive window means, in [`AllanDocument::unit`].
    pub tolerance: f64,
    /// `option` or `3 x white-noise sigma of a window mean (sigma_A(tau0)/sqrt(w))`.
    pub tolerance_source: String,
    /// The cap given, s.
    pub max_s: Option<f64>,
    /// Warm-up time from the start of the segment, s.
    pub time_s: f64,
    /// How it ended: `criterion`, `max` (capped), `not_reached` (never settled: nothing cut),
    /// `not_significant` (the criterion settled late, but the start was within the record's own
    /// wander: nothing cut).
    pub ended_by: String,
    /// The test that what the criterion found is more than the record's own wander (with the
    /// default tolerance, when it found a warm-up); absent in documents of earlier gyrocal.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub significance: Option<WarmupSignificance>,
    /// Window means: (time of the window's centre, s; mean in [`AllanDocument::unit`]), at most
    /// 2000 points (evenly decimated).
    pub curve: Vec<(f64, f64)>,
}

/// Whether a warm-up found by the criterion is more than the record's own wander: the start's
/// change against the spread of the same span's changes where the gyro has settled.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WarmupSignificance {
    /// The span tested: the warm-up the criterion found, s.
    pub span_s: f64,
    /// |first window mean − window mean at the end of the span|, in [`AllanDocument::unit`].
    pub change: f64,
    /// Robust σ of the change of window means over the same span in the settled record
    /// (median |Δ| / 0.6745), in [`AllanDocument::unit`]; `None` when the settled record had
    /// too few pairs of windows to measure it (the cut then stands).
    pub wander: Option<f64>,
    /// Pairs of settled windows the wander was measured on.
    pub pairs: usize,
    /// Whether the warm-up stands: the change is more than 3 × the wander (or the wander could
    /// not be measured).
    pub significant: bool,
}

/// Everything `gyrocal allan` found: what `--json` prints and the page shows.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AllanDocument {
    /// The input given.
    pub input: PathBuf,
    /// The file read (the run's samples.csv for a run directory).
    pub file: PathBuf,
    /// The value column.
    pub value_column: String,
    /// The time column, if any.
    pub time_column: Option<String>,
    /// Unit of the deviations and the bias: `deg/h`, or the input's (`V`, `unit of <column>`).
    pub unit: String,
    /// The scale factor used to convert volts to °/h.
    pub scale_factor: Option<ScaleFactorUsed>,
    /// Data rows read (including overloads).
    pub rows: u64,
    /// Rows skipped because overload = 1.
    pub overloads_skipped: u64,
    /// Sample interval, s.
    pub tau0_s: f64,
    /// `median interval of <column>` or `option`.
    pub tau0_source: String,
    /// Intervals within segments differing from τ0 by more than 10 %.
    pub irregular_intervals: u64,
    /// Line of the first irregular interval.
    pub first_irregular_line: Option<u64>,
    /// The gap-free segments, in file order.
    pub segments: Vec<Segment>,
    /// What was analysed.
    pub analysed: Analysed,
    /// The warm-up (`None` when off or the segment is shorter than two windows).
    pub warmup: Option<Warmup>,
    /// The stability curve.
    pub curve: Curve,
    /// The IEEE 952 noise terms (`None` without a rate in °/h).
    pub noise_terms: Option<NoiseTerms>,
    /// Bias and GJB bias stability over 10 s and 100 s, in [`AllanDocument::unit`].
    pub bias: BiasFigures,
    /// The bias with the Earth's rate along the input axis removed, when the axis and the
    /// latitude were given and the record is a rate in °/h.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub earth_rate: Option<EarthRateRemoved>,
    /// The run the record belongs to (a run directory's input; `None` for a CSV file).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub run: Option<RunHeader>,
    /// What the reader must be told (gaps, irregular sampling, skipped rows, units, warm-up).
    pub notes: Vec<String>,
    /// When the record has gaps short beside it (a resume's, a meter's re-arming) and only its
    /// longest segment was analysed: the `--join-gaps-below` value, s, that would analyse it
    /// whole (the gaps then count as dead time). Said in [`Self::notes`] too.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub join_gaps_hint_s: Option<f64>,
    /// Which path analysed the record (in memory or bounded) and why.
    #[serde(default)]
    pub memory: MemoryUse,
}

impl AllanDocument {
    /// The document as `allan.json` holds it (and `gyrocal allan --json` prints it): pretty
    /// JSON. Non-finite numbers (an interval that cannot be computed) are written `null`.
    pub fn to_json(&self) -> String {
        // a derived Serialize of plain data into a String cannot fail
        serde_json::to_string_pretty(self).unwrap_or_default()
    }
}

/// Writes `doc` as the run's `allan.json` through the run directory (atomically, under the
/// run's lock, its SHA-256 recorded in the manifest's `checksums`, so `gyrocal verify` checks
/// it). Returns the path written.
pub fn write_document(run: &mut dyn WriteResult, doc: &AllanDocument) -> Result<PathBuf, RunError> {
    run.write_result(ALLAN_JSON, doc.to_json().as_bytes())?;
    Ok(run.dir().join(ALLAN_JSON))
}

/// The headline figures of a drift record's analysis: what an index of runs (the catalog)
/// keeps of `allan.json`. Read back typed ([`DriftFigures::load`]) but leniently: every figure
/// is optional, so an `allan.json` written by an earlier gyrocal, or one whose interval came
/// out `null`, still gives the figures it has. In °/h only: a record left in volts gives the
/// duration alone.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct DriftFigures {
    /// The unit of the record analysed (`deg/h` for a rate).
    pub unit: Option<String>,
    /// The analysed duration, s.
    pub duration_s: Option<f64>,
    /// Angle random walk N of the five-term fit, °/√h.
    pub arw: Figure,
    /// Bias instability B of the five-term fit, °/h.
    pub bias_instability: Figure,
    /// Rate random walk K of the five-term fit, °/h/√h.
    pub rrw: Figure,
    /// The bias, °/h: the Earth's rate removed when the axis and latitude were known, else the
    /// measured mean; its uncertainty is the measured mean's.
    pub bias: Figure,
    /// The GJB 2426A bias stability over 100 s windows, °/h.
    pub bias_stability_100s: Option<f64>,
}

/// A figure and its standard (1σ) uncertainty, each as `allan.json` has it (or not).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Figure {
    /// The value.
    pub value: Option<f64>,
    /// Its standard uncertainty (k = 1).
    pub uncertainty: Option<f64>,
}

/// The parts of `allan.json` [`DriftFigures`] reads; every one optional.
mod view {
    use serde::Deserialize;

    #[derive(Deserialize, Default)]
    #[serde(default)]
    pub(super) struct Doc {
        pub unit: Option<String>,
        pub analysed: Option<Analysed>,
        pub noise_terms: Option<Terms>,
        pub bias: Option<Bias>,
        pub earth_rate: Option<Earth>,
    }
    #[derive(Deserialize, Default)]
    #[serde(default)]
    pub(super) struct Analysed {
        pub duration_s: Option<f64>,
    }
    #[derive(Deserialize, Default)]
    #[serde(default)]
    pub(super) struct Terms {
        pub fit: Option<Fit>,
    }
    #[derive(Deserialize, Default)]
    #[serde(default)]
    pub(super) struct Fit {
        pub terms: Vec<Term>,
    }
    #[derive(Deserialize, Default)]
    #[serde(default)]
    pub(super) struct Term {
        pub term: Option<String>,
        pub value: Option<Quantity>,
    }
    #[derive(Deserialize, Default)]
    #[serde(default)]
    pub(super) struct Quantity {
        pub value: Option<f64>,
        pub uncertainty: Option<f64>,
    }
    #[derive(Deserialize, Default)]
    #[serde(default)]
    pub(super) struct Bias {
        pub bias: Option<Quantity>,
        pub stability_100s: Option<Stability>,
    }
    #[derive(Deserialize, Default)]
    #[serde(default)]
    pub(super) struct Stability {
        pub stability: Option<Quantity>,
    }
    #[derive(Deserialize, Default)]
    #[serde(default)]
    pub(super) struct Earth {
        pub bias_dph: Option<f64>,
    }
}

impl DriftFigures {
    /// The figures of `doc`, as [`DriftFigures::load`] reads them back from its `allan.json`.
    pub fn of(doc: &AllanDocument) -> DriftFigures {
        // through the file's form, so the figures of a document and of its file are one reading
        serde_json::from_str::<view::Doc>(&doc.to_json())
            .map(DriftFigures::from_view)
            .unwrap_or_default()
    }

    /// Reads the figures of the run's `allan.json` in `dir`: `Ok(None)` when the run has
    /// none; an error naming the file when it cannot be read (not a regular file, larger than
    /// [`MAX_FIT_BYTES`]) or is not JSON.
    pub fn load(dir: &Path) -> Result<Option<DriftFigures>, RunError> {
        let path = dir.join(ALLAN_JSON);
        if std::fs::symlink_metadata(&path).is_err() {
            return Ok(None);
        }
        let bytes = read_capped(&path, MAX_FIT_BYTES)?;
        let view: view::Doc = serde_json::from_slice(&bytes).map_err(|e| RunError::Json {
            path: path.clone(),
            line: e.line(),
            column: e.column(),
            message: e.to_string(),
        })?;
        Ok(Some(DriftFigures::from_view(view)))
    }

    /// The run's headline figures ([`crate::Figures`]): N, B and K of the five-term fit, the
    /// bias (the Earth rate removed when known) and the 100 s bias stability, uncertainties
    /// expanded to k = 2. In °/h only: a record left in volts has the duration alone.
    pub fn figures(&self) -> crate::Figures {
        let k2 = |u: Option<f64>| u.map(|u| 2.0 * u);
        crate::Figures {
            arw_deg_rt_h: self.arw.value,
            u_arw_deg_rt_h: k2(self.arw.uncertainty),
            bias_instability_dph: self.bias_instability.value,
            u_bias_instability_dph: k2(self.bias_instability.uncertainty),
            rrw_dph_rt_h: self.rrw.value,
            u_rrw_dph_rt_h: k2(self.rrw.uncertainty),
            drift_bias_dph: self.bias.value,
            u_drift_bias_dph: k2(self.bias.uncertainty),
            bias_stability_100s_dph: self.bias_stability_100s,
            drift_duration_s: self.duration_s,
            ..crate::Figures::default()
        }
    }

    fn from_view(v: view::Doc) -> DriftFigures {
        let duration_s = v.analysed.and_then(|a| a.duration_s);
        if v.unit.as_deref() != Some("deg/h") {
            return DriftFigures {
                unit: v.unit,
                duration_s,
                ..DriftFigures::default()
            };
        }
        let figure = |q: Option<&view::Quantity>| Figure {
            value: q.and_then(|q| q.value),
            uncertainty: q.and_then(|q| q.uncertainty),
        };
        let terms = v
            .noise_terms
            .and_then(|t| t.fit)
            .map(|f| f.terms)
            .unwrap_or_default();
        let term = |name: &str| {
            figure(
                terms
                    .iter()
                    .find(|t| t.term.as_deref() == Some(name))
                    .and_then(|t| t.value.as_ref()),
            )
        };
        let (measured, stability) = match v.bias {
            Some(b) => (figure(b.bias.as_ref()), b.stability_100s),
            None => (Figure::default(), None),
        };
        DriftFigures {
            unit: v.unit,
            duration_s,
            arw: term("angle_random_walk"),
            bias_instability: term("bias_instability"),
            rrw: term("rate_random_walk"),
            bias: Figure {
                value: v.earth_rate.and_then(|e| e.bias_dph).or(measured.value),
                uncertainty: measured.uncertainty,
            },
            bias_stability_100s: stability.and_then(|s| s.stability).and_then(|s| s.value),
        }
    }
}
