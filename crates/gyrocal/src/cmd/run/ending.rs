//! The ending of a run: the results of a complete run (analysed and written by its kind's
//! part of the report crate, [`gyrocal_report::end_of_run`]), the closing lines, where the
//! table was left, the exit code.

use super::*;

/// The command line that continues this run, with the options it was started with.
pub(super) fn resume_command(args: &RunArgs, dir: &Path) -> String {
    // the run's plan is in its manifest: the resume needs no plan file (one that was edited
    // since would be refused)
    let mut c = "gyrocal run".to_string();
    if args.simulate {
        c.push_str(" --simulate");
    }
    if let Some(x) = args.sim_time_scale {
        c.push_str(&format!(" --sim-time-scale {x}"));
    }
    if let Some(p) = &args.dmm_port {
        c.push_str(&format!(" --dmm-port {p}"));
    }
    if let Some(p) = &args.table_port {
        c.push_str(&format!(" --table-port {p}"));
    }
    if let Some(p) = &args.chamber_port {
        c.push_str(&format!(" --chamber-port {p}"));
    }
    c.push_str(&format!(" --resume {}", dir.display()));
    c
}

/// After the sequencer: fit, report, the closing summary; the exit code. The last line says
/// where the table was left whenever that is not "at rest, as the table reported".
pub(super) fn finish(
    args: &RunArgs,
    dir: &Path,
    summary: &RunSummary,
    mut run: RunDir,
    signal: Option<StopSignal>,
    doc: &mut serde_json::Value,
) -> anyhow::Result<u8> {
    // human text on stdout, or on stderr when stdout carries the JSON document
    let human = |text: String| {
        if args.json {
            say!("{text}");
        } else {
            out!("{text}");
        }
    };
    let resume = summary.resumable.then(|| resume_command(args, dir));
    let table = match &summary.table {
        TableRest::AtRest { rate_dps, waited } => serde_json::json!({
            "at_rest": true, "rate_dps": rate_dps, "waited_s": waited.as_secs_f64(),
        }),
        TableRest::NotConfirmed { reason } | TableRest::NeverReached { reason } => {
            serde_json::json!({ "at_rest": false, "reason": reason })
        }
        // nothing can be turning: at rest in the sense a script checks for
        TableRest::NoTable => serde_json::json!({ "at_rest": true, "none": true }),
    };
    let m = run.manifest();
    doc["run_dir"] = serde_json::json!(dir);
    doc["status"] = serde_json::json!(summary.status);
    doc["reason"] = serde_json::json!(summary.reason);
    doc["emergency_stop"] = serde_json::json!(summary.emergency_stop);
    doc["table"] = table;
    doc["chamber"] = serde_json::json!(summary.chamber.line());
    doc["steps_recorded_this_session"] = serde_json::json!(summary.steps_recorded);
    doc["steps_done"] = serde_json::json!(run.done_steps().len());
    doc["steps_total"] = serde_json::json!(run.schedule().len());
    doc["elapsed_s"] = serde_json::json!(summary.elapsed_s);
    doc["timing"] = serde_json::json!(summary.timing);
    doc["simulated"] = serde_json::json!(m.simulated);
    // the warm-up as watched online (plans with [warmup])
    doc["warmup"] = serde_json::json!(m.warmup);
    doc["resume_command"] = serde_json::json!(match summary.status {
        Status::Complete => None,
        _ => resume,
    });
    let code = finish_human(args, dir, summary, &mut run, signal, &human, doc);
    // the verdict the analysis found, into the live state's last write (and the bus)
    let verdict = run
        .manifest()
        .acceptance
        .as_ref()
        .map(|a| a.verdict.as_str().to_string());
    live::conclude(verdict.as_deref());
    catalog_close(dir, doc);
    let code = code?;
    if summary.status == Status::Complete && summary.table.nothing_turning() {
        let serial = run.manifest().dut.as_ref().and_then(|d| d.serial.clone());
        human(next_steps(dir, serial.as_deref(), doc));
    }
    doc["exit_code"] = serde_json::json!(code);
    Ok(code)
}

/// How long the end of a run waits for the catalog to take the run's last state.
pub(super) const CATALOG_CLOSE_TIMEOUT: Duration = Duration::from_secs(5);

/// Gives the catalog the run's final state and waits (bounded) for it; says so when the
/// catalog could not be updated: the run directory has everything, an import catches up.
pub(super) fn catalog_close(dir: &Path, doc: &mut serde_json::Value) {
    let Some((writer, _)) = CATALOG.lock().ok().and_then(|mut slot| slot.take()) else {
        return;
    };
    writer.finished(dir);
    let url = writer.url().to_string();
    let updated = writer.close(CATALOG_CLOSE_TIMEOUT);
    doc["catalog"] = serde_json::json!({ "url": url, "updated": updated });
    if !updated {
        say!(
            "gyrocal: warning: the catalog {url} could not be updated (see run.log); the run directory is complete: `gyrocal catalog import {}` brings the catalog up to date",
            dir.display()
        );
    }
}

/// The human side of [`finish`]: the closing lines, the fit and the report.
pub(super) fn finish_human(
    args: &RunArgs,
    dir: &Path,
    summary: &RunSummary,
    run: &mut RunDir,
    signal: Option<StopSignal>,
    human: &dyn Fn(String),
    doc: &mut serde_json::Value,
) -> anyhow::Result<u8> {
    let mut rest_line = match &summary.table {
        TableRest::AtRest { .. } => "the table is at rest".to_string(),
        other => rest_text(other),
    };
    // a temperature series: where the chamber was left, confirmed or plainly not
    if let Some(line) = summary.chamber.line() {
        rest_line = format!("{rest_line}\n  {line}");
    }
    // before a resume the operator re-arms what the emergency stop opened
    let rearm = if summary.emergency_stop {
        "\n  an EMERGENCY STOP was sent (it opens the table's interlock: servo off). Find out why \
         it was needed, make the table safe and re-arm the interlock at its controller before \
         resuming (the resume re-enables the servo and fails if the table refuses)"
    } else {
        ""
    };
    match summary.status {
        Status::Complete => {}
        Status::Aborted => {
            say!(
                "gyrocal: run aborted: {}\n  {} step(s) recorded this session (a step cut short \
                 is not recorded: it is measured afresh on resume); resume with: {}{rearm}\n  \
                 {rest_line}",
                summary.reason.as_deref().unwrap_or("stopped"),
                summary.steps_recorded,
                resume_command(args, dir)
            );
            return Ok(signal.map_or(EXIT_ABORTED, |s| s.exit_code));
        }
        Status::Failed | Status::Running => {
            let next = if summary.resumable {
                format!("resume with: {}", resume_command(args, dir))
            } else {
                // the plan must change, so the same run cannot go on
                "fix the plan and start a new run (a changed plan cannot resume this one)"
                    .to_string()
            };
            say!(
                "gyrocal: run failed: {}\n  {} step(s) recorded this session; {next}{rearm}\n  \
                 {rest_line}",
                summary.reason.as_deref().unwrap_or("unknown"),
                summary.steps_recorded,
            );
            return Ok(1);
        }
    }
    // one ending for every kind of complete run: its results, then the table's rest state
    // decides the last line and the exit code, whatever the analysis did (a failed fit must
    // not hide a table that could not be confirmed at rest)
    let ended = finish_complete(args, dir, summary, run, human, doc);
    if !summary.table.nothing_turning() {
        if let Err(e) = &ended {
            say!("gyrocal: error: {e:#}");
        }
        say!(
            "gyrocal: all steps recorded, but {}",
            rest_text(&summary.table)
        );
        return Ok(1);
    }
    if let Some(line) = summary.chamber.line() {
        if !summary.chamber.is_safe() {
            if let Err(e) = &ended {
                say!("gyrocal: error: {e:#}");
            }
            say!("gyrocal: all steps recorded, but {line}");
            return Ok(1);
        }
        human(line);
    }
    ended
}

/// The end of a complete run, whatever its kind: its analysis and page (the report crate's
/// one dispatch on the kind, [`gyrocal_report::end_of_run`]), the timing, where the files are.
pub(super) fn finish_complete(
    args: &RunArgs,
    dir: &Path,
    summary: &RunSummary,
    run: &mut RunDir,
    human: &dyn Fn(String),
    doc: &mut serde_json::Value,
) -> anyhow::Result<u8> {
    let ending = gyrocal_report::end_of_run(run, !args.no_report)
        .with_context(|| format!("analysing {}", dir.display()))?;
    for (key, value) in ending.json {
        doc[key] = value;
    }
    if !ending.results.is_empty() {
        human(ending.results);
    }
    if let Some(t) = &summary.timing {
        // which clock each figure is on, this session apart from the whole run (see clock)
        for line in timing_lines(t, summary.elapsed_s) {
            human(line);
        }
    }
    for w in &ending.warnings {
        say!("gyrocal: warning: {w}");
    }
    if let Some(line) = ending.page_line {
        human(line);
    }
    human(format!("run directory: {}", dir.display()));
    if let Some(result) = ending.result {
        human(result);
    }
    doc["page"] = serde_json::json!(ending.page);
    Ok(verdict_code(args, run, doc))
}

/// The exit code of a complete run at rest: 0, or [`EXIT_VERDICT`] when `--fail-on-verdict`
/// refuses its verdict (said on stderr, with the quantities that make it).
fn verdict_code(args: &RunArgs, run: &RunDir, doc: &mut serde_json::Value) -> u8 {
    let Some(level) = args.fail_on_verdict else {
        return 0;
    };
    match &run.manifest().acceptance {
        Some(a) if a.verdict >= level.verdict() => {
            say!(
                "gyrocal: {}; --fail-on-verdict {}: exit {EXIT_VERDICT}",
                gyrocal_report::text::verdict_line(a),
                level.verdict().as_str()
            );
            EXIT_VERDICT
        }
        Some(_) => 0,
        None => {
            doc["verdict_missing"] = serde_json::json!(true);
            say!(
                "gyrocal: --fail-on-verdict: the run has no verdict (its plan has no [acceptance]): exit {EXIT_VERDICT}"
            );
            EXIT_VERDICT
        }
    }
}

/// The last line of a complete run: where to look next (its page, the gyro's history when the
/// run was catalogued).
fn next_steps(dir: &Path, serial: Option<&str>, doc: &serde_json::Value) -> String {
    let page = doc["page"]
        .as_str()
        .map_or_else(|| dir.display().to_string(), str::to_string);
    let catalogued = doc["catalog"]["updated"].as_bool() == Some(true);
    match (serial, catalogued) {
        (Some(serial), true) => format!(
            "next: open {page}; catalogued in {}: `gyrocal history {serial}` shows this gyro's calibrations",
            doc["catalog"]["url"].as_str().unwrap_or("the catalog")
        ),
        (None, true) => format!(
            "next: open {page}; catalogued in {} (name the gyro with --dut-serial to follow it with `gyrocal history`)",
            doc["catalog"]["url"].as_str().unwrap_or("the catalog")
        ),
        (_, false) => format!("next: open {page}"),
    }
}
