//! Reopening an interrupted run ([`RunDir::open_for_resume`]): torn last lines dropped,
//! every row checked against the plan's schedule, the partial step's readings cut, older
//! headers upgraded; `samples.csv` is streamed, never held in memory.
#[allow(unused_imports)]
use super::*;

impl RunDir {
    /// Reopens an interrupted run to continue it with `plan`: refuses a different plan (by
    /// hash) or a complete run, keeps every finished step, drops the partial step's samples
    /// and torn last lines, records the resume and marks the run `running`.
    pub fn open_for_resume(path: &Path, plan: &Plan) -> Result<RunDir, RunError> {
        let mpath = path.join(MANIFEST_JSON);
        let manifest = read_manifest(&mpath)?;
        let finished = manifest.status != Status::Running;
        let mut lock = Some(lock_dir(path)?);
        let result = Self::resume_locked(path, plan, manifest, &mut lock);
        // A refused resume of a finished run leaves it as it was: without a `.lock` (removed
        // while still held, as `Drop` does).
        if result.is_err()
            && finished
            && let Some(file) = lock.take()
        {
            let lpath = path.join(LOCK_FILE);
            if let Err(e) = fs::remove_file(&lpath)
                && e.kind() != std::io::ErrorKind::NotFound
            {
                tracing::warn!(file = %lpath.display(), error = %e, "cannot remove the lock file");
            }
            drop(file);
        }
        result
    }

    /// [`RunDir::open_for_resume`] under the lock, which it takes from `lock` into the
    /// [`RunDir`] it returns (and leaves there on an error).
    pub(super) fn resume_locked(
        path: &Path,
        plan: &Plan,
        mut manifest: Manifest,
        lock: &mut Option<File>,
    ) -> Result<RunDir, RunError> {
        let mpath = path.join(MANIFEST_JSON);
        let plan_hash = plan.hash();
        if manifest.plan_hash != plan_hash {
            let changes = plan_changes(&manifest.plan, plan);
            return Err(RunError::PlanChanged {
                path: mpath,
                run_hash: manifest.plan_hash,
                plan_hash,
                changes,
            });
        }
        if manifest.status == Status::Complete {
            return Err(RunError::AlreadyComplete { path: mpath });
        }
        let schedule = plan.schedule();

        // steps.csv: repair the tail, then every row must fit the schedule.
        let spath = path.join(STEPS_CSV);
        let series_columns = super::writer::series_columns(plan);
        let (steps_bytes, torn_steps) = read_repaired(
            &spath,
            &super::writer::steps_headers_for(series_columns),
            MAX_STEPS_BYTES,
        )?;
        let records = parse_steps(&spath, &steps_bytes, &schedule)?;
        let done: BTreeSet<usize> = records.iter().map(|r| r.step).collect();
        let expected: BTreeMap<usize, u64> = records
            .iter()
            .map(|r| (r.step, r.n + r.overloads))
            .collect();

        // samples.csv: keep the finished steps' rows, drop everything from the first other row.
        let sapath = path.join(SAMPLES_CSV);
        let (samples_len, torn_samples, samples_columns) = repair_samples(&sapath)?;
        let (keep_len, dropped) = scan_samples(&sapath, samples_len, &schedule, &expected)?;
        truncate(&sapath, keep_len)?;
        truncate(&spath, steps_bytes.len() as u64)?;

        let samples = open_csv(&sapath, &SAMPLES_HEADER, false)?;
        let steps = open_csv(&spath, super::writer::steps_header(series_columns), false)?;
        let from_step = schedule.iter().map(|s| s.index).find(|i| !done.contains(i));
        manifest.resumes.push(Resume {
            at_utc: now_utc(),
            from_step,
            steps_done: done.len(),
            samples_dropped: dropped,
            torn_bytes_dropped: torn_steps + torn_samples,
            previous_status: manifest.status,
            previous_reason: manifest.reason.take(),
        });
        manifest.status = Status::Running;
        manifest.ended_utc = None;
        manifest.steps_done = done.iter().copied().collect();
        tracing::info!(
            dir = %path.display(),
            steps_done = done.len(),
            samples_dropped = dropped,
            from_step = ?from_step,
            "resuming run"
        );
        // the manifest is rewritten in this version's format (steps.csv was upgraded above)
        manifest.format_version = FORMAT_VERSION;
        // The run clock goes on from the last time on disk: the manifest's `elapsed_s`, or
        // the end of the last finished step when the process died after fsyncing that step
        // but before rewriting the manifest (else the resumed readings' t_s would run back
        // into the kept ones, and a drift record would overlap itself).
        // A temperature series logs the chamber between the steps (temps.csv, flushed at each
        // row, the manifest checkpointed only every few minutes of a soak): its last row
        // counts too, or a series killed mid-soak would log its resumed soak back in time.
        // (read from the file's end: only its last row's clock is wanted)
        let last_temp = temps::last_t_s(path).ok().flatten().unwrap_or(0.0);
        let last_step_end = records.iter().map(|r| r.t_end_s).fold(last_temp, f64::max);
        if last_step_end > manifest.elapsed_s {
            tracing::info!(
                manifest_elapsed_s = manifest.elapsed_s,
                last_step_end_s = last_step_end,
                "the run clock resumes from the last finished step"
            );
            manifest.elapsed_s = last_step_end;
        }
        // A virtual-time session's stamps ran ahead of the wall clock (`started_utc` plus the
        // run clock): the clock goes on from there when that is later than now, so the stamps
        // never run backwards from one session to the next. For a real-time run it is in the
        // past and changes nothing.
        let clock_floor = crate::parse_rfc3339_utc(&manifest.started_utc).map(|wall| ClockAnchor {
            wall,
            run_clock_s: 0.0,
        });
        let clock = ClockAnchor::now(manifest.elapsed_s).at_least(clock_floor);
        let Some(lock) = lock.take() else {
            return Err(RunError::Protocol {
                path: path.join(LOCK_FILE),
                message: "the run directory's lock was not held".into(),
            });
        };
        let mut rd = RunDir {
            dir: path.to_path_buf(),
            _lock: lock,
            schedule,
            manifest,
            samples,
            samples_columns,
            steps,
            done,
            current: None,
            clock,
            clock_floor,
            temps: temps::TempsWriter::default(),
            series_columns,
            durable_elapsed_s: 0.0,
        };
        rd.write_manifest()?;
        Ok(rd)
    }
}

/// Reads a CSV for resume: drops a torn last line; an empty file (or one with only a torn
/// header) gets its header back; a file with an older accepted header (`accepted[1..]`) is
/// rewritten, atomically, with the current one (`accepted[0]`), each old row getting an empty
/// cell in every column the old header lacks and its counted cells re-based (`step` 0 becomes
/// `step_no` 1; see `upgrade_steps`). Returns the repaired
/// content and the bytes dropped.
pub(super) fn read_repaired(
    path: &Path,
    accepted: &[&[&str]],
    cap: u64,
) -> Result<(Vec<u8>, u64), RunError> {
    let header = accepted.first().copied().unwrap_or_default();
    let bytes = read_capped(path, cap)?;
    let (keep, torn) = complete_lines(&bytes);
    if keep.is_empty() {
        let mut h = header.join(",").into_bytes();
        h.push(b'\n');
        fs::write(path, &h).map_err(io(path, "write"))?;
        return Ok((h, torn));
    }
    let which = check_header(path, keep, accepted)?;
    if torn > 0 {
        tracing::warn!(file = %path.display(), bytes = torn, "dropping a torn last line");
    }
    if which == 0 {
        return Ok((keep.to_vec(), torn));
    }
    let old = accepted.get(which).copied().unwrap_or_default();
    let upgraded = upgrade_steps(path, keep, old, header)?;
    let dir = path.parent().unwrap_or(Path::new("."));
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    write_atomic(dir, &name, &upgraded)?;
    tracing::info!(file = %path.display(), "rewrote an older header with the current columns");
    Ok((upgraded, torn))
}

/// Prepares samples.csv for a resume without reading it whole: finds the end of its last
/// complete line (a torn tail is dropped later by the truncation), checks the header, and
/// writes the header into an empty file. Returns (length of the complete lines, torn bytes,
/// the file's columns, which the resumed session's rows keep).
pub(super) fn repair_samples(path: &Path) -> Result<(u64, u64, SampleColumns), RunError> {
    use std::io::{Read as _, Seek as _, SeekFrom};
    let mut file = open_regular(path).map_err(opened)?;
    let meta = file.metadata().map_err(io(path, "read"))?;
    let len = meta.len();
    if len > MAX_SAMPLES_BYTES {
        return Err(RunError::TooLarge {
            path: path.to_path_buf(),
            cap: MAX_SAMPLES_BYTES,
        });
    }
    // The last newline, reading backwards in blocks.
    let mut keep = 0u64;
    let mut end = len;
    let mut block = vec![0u8; 64 * 1024];
    while end > 0 {
        let start = end.saturating_sub(block.len() as u64);
        let n = usize::try_from(end - start).unwrap_or(block.len());
        let buf = block.get_mut(..n).unwrap_or_default();
        file.seek(SeekFrom::Start(start))
            .map_err(io(path, "read"))?;
        file.read_exact(buf).map_err(io(path, "read"))?;
        if let Some(i) = buf.iter().rposition(|&b| b == b'\n') {
            keep = start + i as u64 + 1;
            break;
        }
        end = start;
    }
    let torn = len - keep;
    if keep == 0 {
        let mut h = SAMPLES_HEADER.join(",").into_bytes();
        h.push(b'\n');
        fs::write(path, &h).map_err(io(path, "write"))?;
        return Ok((h.len() as u64, torn, SampleColumns::CURRENT));
    }
    let mut first = Vec::new();
    file.seek(SeekFrom::Start(0)).map_err(io(path, "read"))?;
    (&mut file)
        .take(4096.min(keep))
        .read_to_end(&mut first)
        .map_err(io(path, "read"))?;
    let which = check_header(path, &first, SAMPLES_HEADERS)?;
    if torn > 0 {
        tracing::warn!(file = %path.display(), bytes = torn, "dropping a torn last line");
    }
    let header = SAMPLES_HEADERS
        .get(which)
        .copied()
        .unwrap_or(&SAMPLES_HEADER);
    let columns = SampleColumns::of_header(header);
    if which != 0 {
        tracing::info!(
            file = %path.display(),
            header = %header.join(","),
            "samples.csv was begun by an older gyrocal; its rows keep its columns"
        );
    }
    Ok((keep, torn, columns))
}

/// Checks the finished steps' rows in samples.csv and finds where the unfinished rows start.
/// Returns (bytes to keep, rows dropped).
///
/// Streams the first `len` bytes of the file (its complete lines, see [`repair_samples`]): a
/// long run's samples.csv is never held in memory.
pub(super) fn scan_samples(
    path: &Path,
    len: u64,
    schedule: &[Step],
    expected: &BTreeMap<usize, u64>,
) -> Result<(u64, u64), RunError> {
    use std::io::Read as _;
    let file = open_regular(path).map_err(opened)?;
    let mut rdr = csv::ReaderBuilder::new()
        .has_headers(true)
        .from_reader(std::io::BufReader::new(file.take(len)));
    let mut counts: BTreeMap<usize, u64> = BTreeMap::new();
    let mut cut: Option<u64> = None;
    let mut dropped = 0u64;
    let mut rec = csv::StringRecord::new();
    // The header's end, in case there is no row at all; rows are read by name (files written
    // before `t_utc` existed lack that column).
    let headers = rdr.headers().map_err(|e| csv_read(path, &e))?.clone();
    let counting = Counting::of_header(headers.iter());
    let fields = Counting::field_names(&headers);
    let step_no = |i: usize| counting.show("step", i as u64);
    let mut keep = rdr.position().byte();
    loop {
        match rdr.read_record(&mut rec) {
            Ok(false) => break,
            Ok(true) => {}
            Err(e) => return Err(csv_read(path, &e)),
        }
        // the record's own start: the reader's position before the first read is the header's
        let Some(pos) = rec.position().cloned() else {
            return Err(RunError::Csv {
                path: path.to_path_buf(),
                line: 0,
                message: "a row without a position".into(),
            });
        };
        let line = pos.line();
        let bad = |message: String| RunError::Csv {
            path: path.to_path_buf(),
            line,
            message,
        };
        if cut.is_some() {
            // Rows of the partial step: dropped, but a finished step's row here means the
            // file is not what this program writes.
            let step = rec
                .get(0)
                .and_then(|s| s.parse::<u64>().ok())
                .and_then(|s| counting.to_index("step", s).ok())
                .and_then(|s| usize::try_from(s).ok());
            if let Some(s) = step.filter(|s| expected.contains_key(s)) {
                return Err(bad(format!(
                    "a row of finished {} follows rows of an unfinished step",
                    step_no(s)
                )));
            }
            dropped += 1;
            continue;
        }
        let row = read_sample(&rec, &fields, counting).map_err(bad)?;
        if !expected.contains_key(&row.step) {
            cut = Some(pos.byte());
            dropped += 1;
            continue;
        }
        let Some(s) = schedule.get(row.step) else {
            return Err(bad(format!(
                "{} is not in the plan's schedule",
                step_no(row.step)
            )));
        };
        if row.rate_dps.to_bits() != s.rate_dps.to_bits() {
            return Err(bad(format!(
                "{} has rate {}, the schedule {}",
                step_no(row.step),
                row.rate_dps,
                s.rate_dps
            )));
        }
        let c = counts.entry(row.step).or_insert(0);
        if row.index != *c {
            return Err(bad(format!(
                "{}: {} where {} was due (duplicate or missing reading)",
                step_no(row.step),
                counting.show("index", row.index),
                counting.show("index", *c)
            )));
        }
        if row.volts.is_none() != (row.overload == 1) || row.overload > 1 {
            return Err(bad(format!(
                "{}: overload must be 1 exactly when volts is empty",
                step_no(row.step)
            )));
        }
        *c += 1;
        keep = rdr.position().byte();
    }
    for (step, want) in expected {
        let got = counts.get(step).copied().unwrap_or(0);
        if got != *want {
            return Err(RunError::Inconsistent {
                path: path.to_path_buf(),
                message: format!(
                    "plan step {}: steps.csv records {want} readings (n + overloads), samples.csv holds {got}",
                    step + 1
                ),
            });
        }
    }
    Ok((cut.unwrap_or(keep), dropped))
}

pub(super) fn truncate(path: &Path, len: u64) -> Result<(), RunError> {
    let f = OpenOptions::new()
        .write(true)
        .open(path)
        .map_err(io(path, "open"))?;
    let cur = f.metadata().map_err(io(path, "read the length of"))?.len();
    if cur != len {
        f.set_len(len).map_err(io(path, "truncate"))?;
        f.sync_all().map_err(io(path, "sync"))?;
    }
    Ok(())
}
