//! The report's head matter before any number: the gyro under test and who ran it, and the
//! banners a reader must see first (a simulated run, an incomplete run, runs of different
//! plans).

use std::fmt::Write as _;

use gyrocal_files::Status;

use super::{esc, suffix};
use crate::input::Input;

/// "Gyro under test: serial …, model …; operator …, customer …; ambient … °C, … % RH", as
/// the operator entered them (a run that names no gyro says so).
pub(super) fn identification(html: &mut String, input: &Input, which: Option<usize>) {
    let Some(m) = &input.manifest else {
        return;
    };
    let prefix = which.map_or(String::new(), |n| format!("Run {n}: "));
    let mut parts = Vec::new();
    match &m.dut {
        Some(d) => {
            if let Some(s) = &d.serial {
                parts.push(format!("serial <strong>{}</strong>", esc(s)));
            }
            if let Some(s) = &d.model {
                parts.push(format!("model {}", esc(s)));
            }
        }
        None => parts.push("not named (no --dut-serial)".into()),
    }
    let mut who = Vec::new();
    if let Some(c) = &m.context {
        if let Some(o) = &c.operator {
            who.push(format!("operator {}", esc(o)));
        }
        if let Some(o) = &c.customer {
            who.push(format!("customer {}", esc(o)));
        }
        if let Some(t) = c.ambient_c {
            who.push(format!("ambient {t} °C"));
        }
        if let Some(h) = c.humidity_pct {
            who.push(format!("{h} % RH"));
        }
    }
    let who = if who.is_empty() {
        String::new()
    } else {
        format!("; {}", who.join(", "))
    };
    let _ = writeln!(
        html,
        "<p class=\"dut\">{prefix}Gyro under test: {}{who}</p>",
        parts.join(", ")
    );
}

/// Runs of different plans given to one report.
pub(crate) struct PlansDiffer {
    /// Each run's plan hash (`None`: a bare CSV, plan unknown), in input order.
    hashes: Vec<Option<String>>,
}

impl PlansDiffer {
    fn distinct(&self) -> usize {
        let mut known: Vec<&str> = self.hashes.iter().flatten().map(String::as_str).collect();
        known.sort_unstable();
        known.dedup();
        known.len()
    }

    /// The sentence for stderr and the report.
    pub(crate) fn warning(&self) -> String {
        let runs: Vec<String> = self
            .hashes
            .iter()
            .enumerate()
            .map(|(i, h)| match h {
                Some(h) => format!("run {} plan {}", i + 1, h.get(..12).unwrap_or(h)),
                None => format!("run {} plan unknown (a CSV file)", i + 1),
            })
            .collect();
        format!(
            "the runs come from {} different plans ({}): the spread of their scale factors is \
             not the repeatability of one plan (different rates, readings or settings change K \
             as well as drift does)",
            self.distinct().max(2),
            runs.join(", ")
        )
    }
}

/// `Some` when the inputs do not all follow one plan (by [`method_hash`]: a different
/// simulation seed is the same plan). A bare CSV has no plan: it differs only from nothing,
/// and is named as unknown when run directories disagree. The warning names each run's plan
/// hash, as its manifest has it.
pub(super) fn plans_differ(inputs: &[Input]) -> Option<PlansDiffer> {
    let methods: Vec<Option<String>> = inputs
        .iter()
        .map(|i| i.manifest.as_ref().map(|m| method_hash(&m.plan)))
        .collect();
    if (PlansDiffer { hashes: methods }).distinct() <= 1 {
        return None;
    }
    let hashes = inputs
        .iter()
        .map(|i| i.manifest.as_ref().map(|m| m.plan_hash.clone()))
        .collect();
    Some(PlansDiffer { hashes })
}

/// What makes two runs' plans the same method: the plan's hash without its `[simulation]`
/// section (the simulated bench's seed and gyro are not how the gyro was measured; the plan
/// hash covers them, so two seeds of one plan hash differently). Ports, `[dut]` and
/// `[acceptance]` are left out as in the plan hash.
pub(crate) fn method_hash(plan: &gyrocal_files::Plan) -> String {
    let mut doc = plan.to_doc();
    if let Some(t) = doc.table.as_mut() {
        t.port.clear();
    }
    doc.dmm.port.clear();
    doc.dut = None;
    doc.acceptance = None;
    doc.simulation = gyrocal_files::plan::Simulation::default();
    // serialising plain structs cannot fail; an empty body would still compare equal only to
    // itself
    gyrocal_files::rundir::sha256_hex(&serde_json::to_vec(&doc).unwrap_or_default())
}

/// The banner of a simulated run: it comes first, so that simulated numbers are never
/// mistaken for a calibration. In virtual time it explains why the run clock and the wall
/// clock disagree.
pub(super) fn simulated_banner(html: &mut String, input: &Input, run: Option<usize>) {
    let Some(m) = &input.manifest else { return };
    if !m.simulated {
        return;
    }
    let which = run.map_or_else(String::new, |r| format!("Run {r}: "));
    let mut text = format!(
        "<strong>SIMULATED.</strong> {which}These data come from gyrocal's simulated bench (a \
         simulated rate table and multimeter with a modelled gyroscope), not from an instrument: \
         they calibrate nothing."
    );
    if m.virtual_time {
        // `ended_utc` of a virtual-time run is on the run clock (like the t_utc stamps); the
        // wall clock of its last write is `updated_utc`
        let wall = match (
            gyrocal_files::parse_rfc3339_utc(&m.started_utc),
            gyrocal_files::parse_rfc3339_utc(&m.updated_utc),
        ) {
            (Some(a), Some(b)) => b
                .duration_since(a)
                .ok()
                .map(|d| format!("{:.1} s", d.as_secs_f64())),
            _ => None,
        };
        let _ = write!(
            text,
            " It ran in <em>virtual time</em>: every time in it (each <code>t_s</code>, the \
             <code>t_utc</code> times derived from it, the elapsed {:.1} s and the schedule) is \
             on the simulated bench's clock, paced or as fast as the computer allows, counting \
             what a real bench would have taken, not the wall clock; the simulation itself took \
             {} of wall-clock time (from its start to its last write{}).",
            m.elapsed_s,
            wall.as_deref().unwrap_or("a fraction of that"),
            match m.resumes.len() {
                0 => String::new(),
                n => format!(", including the pauses between its {} sessions", n + 1),
            }
        );
    }
    let _ = writeln!(
        html,
        "<div class=\"banner simulated\" role=\"note\" id=\"simulated{}\">{text}</div>",
        suffix(run)
    );
}

pub(super) fn banner(html: &mut String, input: &Input, run: Option<usize>) {
    let Some(m) = &input.manifest else { return };
    if m.status == Status::Complete {
        return;
    }
    let status = match m.status {
        Status::Running => "running (or the program stopped without closing the run)",
        Status::Complete => "complete",
        Status::Aborted => "aborted",
        Status::Failed => "failed",
    };
    let which = run.map_or_else(String::new, |r| format!("Run {r}: "));
    let _ = writeln!(
        html,
        "<div class=\"banner\" role=\"alert\" id=\"banner{}\">{which}INCOMPLETE RUN: status {status}{}. {} of {} steps done; every figure and number below uses only the finished steps.</div>",
        suffix(run),
        m.reason
            .as_deref()
            .map_or_else(String::new, |r| format!(": {}", esc(r))),
        m.steps_done.len(),
        m.steps_total,
    );
}
