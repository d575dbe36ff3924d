//! The writer: [`RunDir`] creates a run directory, appends each chunk of readings to
//! `samples.csv` and each finished step to `steps.csv` (samples synced first), keeps the
//! manifest current and finishes the run (see the module docs of [`super`], *Durability
//! rules*). Reopening an interrupted run is `resume`'s.
#[allow(unused_imports)]
use super::*;

/// The temporary file of an atomic manifest replacement.
pub(super) const MANIFEST_TMP: &str = ".manifest.json.tmp";

/// Removes what a failed [`RunDir::create`] may have written (its fixed file names only;
/// missing ones are fine). The lock file goes last.
pub(super) fn remove_skeleton(dir: &Path) {
    for name in [
        MANIFEST_JSON,
        MANIFEST_TMP,
        SAMPLES_CSV,
        STEPS_CSV,
        LOCK_FILE,
    ] {
        let f = dir.join(name);
        match fs::remove_file(&f) {
            Ok(()) => tracing::debug!(file = %f.display(), "removed a file of a failed creation"),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => tracing::warn!(file = %f.display(), error = %e, "cannot remove"),
        }
    }
}

/// True when the file is empty or holds only a (possibly torn) header line of one of `headers`.
pub(super) fn holds_at_most_header(path: &Path, headers: &[&[&str]]) -> bool {
    let longest = headers
        .iter()
        .map(|h| h.join(",").len() + 2)
        .max()
        .unwrap_or(0);
    let Ok(bytes) = read_capped(path, longest as u64) else {
        return false;
    };
    headers.iter().any(|h| {
        let full = format!("{}\n", h.join(","));
        let crlf = format!("{}\r\n", h.join(","));
        full.as_bytes().starts_with(&bytes) || crlf.as_bytes().starts_with(&bytes)
    })
}

/// The step whose samples are being written.
#[derive(Debug, Clone, Copy)]
pub(super) struct Current {
    pub(super) step: usize,
    /// Length of samples.csv before this step's first row.
    pub(super) start_len: u64,
    /// Rows written so far.
    pub(super) count: u64,
}

/// An open run directory, for writing. See the module docs for the protocol.
#[derive(Debug)]
pub struct RunDir {
    pub(super) dir: PathBuf,
    /// An exclusive advisory lock on `DIR/.lock`, held while this value lives: a second
    /// process (or a second `RunDir`) writing the same run directory is refused. The operating
    /// system drops the lock when the process dies, even by SIGKILL, so a resume is never
    /// blocked by a crashed run.
    pub(super) _lock: File,
    pub(super) schedule: Vec<Step>,
    pub(super) manifest: Manifest,
    pub(super) samples: csv::Writer<File>,
    /// The columns of samples.csv: the current ones, or the older ones of a file an older
    /// gyrocal began, whose rows a resume keeps appending in that file's format.
    pub(super) samples_columns: SampleColumns,
    pub(super) steps: csv::Writer<File>,
    pub(super) done: BTreeSet<usize>,
    pub(super) current: Option<Current>,
    /// Converts the run clock to UTC for the `t_utc` columns.
    pub(super) clock: ClockAnchor,
    /// A resumed virtual-time run's earlier stamps: `started_utc` plus the run clock, ahead of
    /// the wall clock. The clock is never anchored earlier than this, so the stamps of the
    /// sessions after it go on from there instead of falling back to the wall clock (`None`
    /// for a new run, and harmless for a real-time one, whose earlier stamps are all past).
    pub(super) clock_floor: Option<ClockAnchor>,
    /// `temps.csv`, opened on its first row (a run with a chamber).
    pub(super) temps: temps::TempsWriter,
    /// steps.csv has the temperature series' columns ([`STEPS_HEADER`]; a series run) or
    /// not ([`STEPS_HEADER_V4`]; every other run).
    pub(super) series_columns: bool,
    /// The run clock the manifest on disk holds (see [`RunDir::checkpoint`]).
    pub(super) durable_elapsed_s: f64,
}

/// A finished run (complete, failed or aborted) leaves no `.lock` behind: the file is removed
/// while the lock is still held (the lock itself goes with the file handle, right after).
/// A run still `running` keeps it: its process died or failed to close the manifest, and the
/// next resume takes the lock as usual (an OS lock dies with its process, so a stale `.lock`
/// never blocks). Not on Windows, where an open file cannot be removed.
impl Drop for RunDir {
    fn drop(&mut self) {
        if self.manifest.status == Status::Running || cfg!(not(unix)) {
            return;
        }
        let path = self.dir.join(LOCK_FILE);
        match fs::remove_file(&path) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => {
                tracing::warn!(file = %path.display(), error = %e, "cannot remove the lock file")
            }
        }
    }
}

impl RunDir {
    /// Creates a new run directory (or fills an existing empty one) for `plan`, writes both CSV
    /// headers and a `running` manifest. Refuses a directory that holds anything but what an
    /// interrupted creation leaves ([`RunDir::is_half_created`]), which it reuses.
    ///
    /// Creation is all or nothing: when a step fails (disk full, permissions), the files this
    /// call created are removed again, and so are the directories it created (the run directory
    /// and missing parents, when empty); a directory that existed before is left in place,
    /// empty. The error names the file that could not be written.
    pub fn create(path: &Path, plan: &Plan, meta: RunMeta) -> Result<RunDir, RunError> {
        if path.exists() && !Self::is_half_created(path)? {
            return Err(RunError::NotEmpty {
                path: path.to_path_buf(),
            });
        }
        // The directories this call creates, deepest first, for the cleanup.
        let mut created_dirs = Vec::new();
        let mut p = path;
        while !p.as_os_str().is_empty() && fs::symlink_metadata(p).is_err() {
            created_dirs.push(p.to_path_buf());
            match p.parent() {
                Some(parent) => p = parent,
                None => break,
            }
        }
        let remove_dirs = |dirs: &[PathBuf]| {
            for d in dirs {
                // only empty ones: what someone else put there meanwhile stays
                if fs::remove_dir(d).is_ok() {
                    tracing::debug!(dir = %d.display(), "removed a directory of a failed creation");
                }
            }
        };
        if let Err(e) = fs::create_dir_all(path) {
            remove_dirs(&created_dirs);
            return Err(io(path, "create the directory")(e));
        }
        let lock = match lock_dir(path) {
            Ok(lock) => lock,
            // Another process holds the lock: it is creating or writing this run; touch nothing.
            Err(e @ RunError::Locked { .. }) => return Err(e),
            Err(e) => {
                // Without the lock, only a directory this call created is cleaned.
                if !created_dirs.is_empty() {
                    remove_skeleton(path);
                }
                remove_dirs(&created_dirs);
                return Err(e);
            }
        };
        // Under the lock, the directory must still be empty or half created (another process
        // may have finished creating it between the check above and the lock).
        let result = match Self::is_half_created(path) {
            Ok(true) => Self::create_locked(path, plan, meta, lock),
            Ok(false) => {
                return Err(RunError::NotEmpty {
                    path: path.to_path_buf(),
                });
            }
            Err(e) => Err(e),
        };
        match result {
            Ok(rd) => Ok(rd),
            Err(e) => {
                tracing::warn!(dir = %path.display(), error = %e, "run directory creation failed; removing what it created");
                remove_skeleton(path);
                remove_dirs(&created_dirs);
                Err(e)
            }
        }
    }

    /// True when `path` is a directory that is empty or holds only what an interrupted
    /// [`RunDir::create`] leaves (a crash, a kill or a power cut between its first file and its
    /// manifest): no `manifest.json` (so no run ever started in it and no reading was ever
    /// taken), and nothing but `.lock`, `.manifest.json.tmp` and `samples.csv` / `steps.csv`
    /// holding at most their header. `gyrocal run --out DIR` and `--resume DIR` start the run
    /// in such a directory instead of refusing it. Errors only when the directory cannot be
    /// read.
    pub fn is_half_created(path: &Path) -> Result<bool, RunError> {
        if !path.is_dir() {
            return Ok(false);
        }
        let entries = fs::read_dir(path).map_err(io(path, "read the directory"))?;
        for entry in entries {
            let entry = entry.map_err(io(path, "read the directory"))?;
            let name = entry.file_name();
            let Some(name) = name.to_str() else {
                return Ok(false);
            };
            let file = entry.path();
            let regular = fs::symlink_metadata(&file).is_ok_and(|m| m.is_file());
            let ok = match name {
                LOCK_FILE | MANIFEST_TMP => regular,
                SAMPLES_CSV => regular && holds_at_most_header(&file, SAMPLES_HEADERS),
                STEPS_CSV => regular && holds_at_most_header(&file, STEPS_HEADERS),
                _ => false,
            };
            if !ok {
                return Ok(false);
            }
        }
        Ok(true)
    }

    pub(super) fn create_locked(
        path: &Path,
        plan: &Plan,
        meta: RunMeta,
        lock: File,
    ) -> Result<RunDir, RunError> {
        // A half-created directory's CSVs start again from nothing.
        for name in [SAMPLES_CSV, STEPS_CSV] {
            let f = path.join(name);
            match fs::remove_file(&f) {
                Ok(()) => {}
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(e) => return Err(io(&f, "remove")(e)),
            }
        }
        let samples = open_csv(&path.join(SAMPLES_CSV), &SAMPLES_HEADER, true)?;
        let series_columns = series_columns(plan);
        let steps = open_csv(&path.join(STEPS_CSV), steps_header(series_columns), true)?;
        let now = now_utc();
        let manifest = Manifest {
            format_version: FORMAT_VERSION,
            status: Status::Running,
            reason: None,
            gyrocal_version: meta.gyrocal_version,
            plan_hash: plan.hash(),
            plan: plan.clone(),
            simulated: meta.simulated,
            simulated_by: None,
            checksums: BTreeMap::new(),
            dut: meta.dut,
            context: meta.context,
            station: meta.station,
            virtual_time: meta.virtual_time,
            instruments: meta.instruments,
            deviations: Vec::new(),
            started_utc: now.clone(),
            ended_utc: None,
            updated_utc: now,
            elapsed_s: 0.0,
            steps_total: plan.step_count(),
            steps_done: Vec::new(),
            resumes: Vec::new(),
            retries: Vec::new(),
            timing: None,
            fit_summary: None,
            warmup: None,
            chamber: None,
            acceptance: None,
            legacy_fit: None,
        };
        let mut rd = RunDir {
            dir: path.to_path_buf(),
            _lock: lock,
            schedule: plan.schedule(),
            manifest,
            samples,
            samples_columns: SampleColumns::CURRENT,
            steps,
            done: BTreeSet::new(),
            current: None,
            clock: ClockAnchor::now(0.0),
            clock_floor: None,
            temps: temps::TempsWriter::default(),
            series_columns,
            durable_elapsed_s: 0.0,
        };
        sync_dir(path)?;
        rd.write_manifest()?;
        tracing::info!(dir = %path.display(), hash = %rd.manifest.plan_hash, "run directory created");
        Ok(rd)
    }

    /// The run directory.
    pub fn path(&self) -> &Path {
        &self.dir
    }

    /// The manifest as last written.
    pub fn manifest(&self) -> &Manifest {
        &self.manifest
    }

    /// Tells the run directory that the run clock reads `run_clock_s` now, so that the `t_utc`
    /// columns are the wall-clock times of the run clock's `t_s`. [`RunDir::create`] and
    /// [`RunDir::open_for_resume`] set this (run clock 0, or the manifest's `elapsed_s`), which
    /// is right to the few milliseconds between opening the directory and starting the clock;
    /// a writer whose clock starts later calls this when it starts it. A non-finite or
    /// negative value is ignored.
    pub fn anchor_clock(&mut self, run_clock_s: f64) {
        if run_clock_s.is_finite() && run_clock_s >= 0.0 {
            self.clock = ClockAnchor::now(run_clock_s).at_least(self.clock_floor);
        }
    }

    /// The wall-clock anchor of the run clock (see [`RunDir::anchor_clock`]).
    pub fn clock_anchor(&self) -> ClockAnchor {
        self.clock
    }

    /// Records that this session runs in virtual time ([`Manifest::virtual_time`]; a
    /// [`RunMeta`] says so for a new run).
    pub fn set_virtual_time(&mut self) -> Result<(), RunError> {
        if self.manifest.virtual_time {
            return Ok(());
        }
        self.manifest.virtual_time = true;
        self.write_manifest()
    }

    /// The schedule of the plan this run follows.
    pub fn schedule(&self) -> &[Step] {
        &self.schedule
    }

    /// Indices of the finished steps.
    pub fn done_steps(&self) -> &BTreeSet<usize> {
        &self.done
    }

    /// The steps still to run, in schedule order.
    pub fn remaining_steps(&self) -> Vec<Step> {
        self.schedule
            .iter()
            .filter(|s| !self.done.contains(&s.index))
            .copied()
            .collect()
    }

    /// Appends a chunk of raw readings of `step` to samples.csv and flushes it. Indices must
    /// continue the step's previous chunks (0, 1, 2, ...); only one step may be in progress.
    pub fn append_samples(&mut self, step: usize, samples: &[Sample]) -> Result<(), RunError> {
        let path = self.dir.join(SAMPLES_CSV);
        let proto = |message: String| RunError::Protocol {
            path: path.clone(),
            message,
        };
        let Some(s) = self.schedule.get(step).copied() else {
            return Err(proto(format!("step {step} is not in the schedule")));
        };
        if self.done.contains(&step) {
            return Err(proto(format!("step {step} is already recorded")));
        }
        let mut cur = match self.current {
            Some(c) if c.step == step => c,
            Some(c) => {
                return Err(proto(format!(
                    "step {} is in progress; record or restart it before step {step}",
                    c.step
                )));
            }
            None => {
                let start_len = self
                    .samples
                    .get_ref()
                    .metadata()
                    .map_err(io(&path, "read the length of"))?
                    .len();
                Current {
                    step,
                    start_len,
                    count: 0,
                }
            }
        };
        for (k, smp) in samples.iter().enumerate() {
            let want = cur.count + k as u64;
            if smp.index != want {
                return Err(proto(format!(
                    "step {step}: sample index {} where {want} was due",
                    smp.index
                )));
            }
            if !smp.t_s.is_finite() || smp.volts.is_some_and(|v| !v.is_finite()) {
                return Err(proto(format!(
                    "step {step}: sample {} is not finite (t_s {}, volts {:?}); an overload is volts = None",
                    smp.index, smp.t_s, smp.volts
                )));
            }
        }
        for smp in samples {
            let row = SampleRow {
                step,
                index: smp.index,
                t_s: round_significant(smp.t_s),
                rate_dps: s.rate_dps,
                volts: round_opt(smp.volts),
                overload: u8::from(smp.volts.is_none()),
                t_utc: self.samples_columns.utc.then(|| self.clock.utc(smp.t_s)),
            };
            let written = write_sample(&mut self.samples, &row, self.samples_columns);
            written.map_err(|e| csv_write(&path, e))?;
        }
        self.samples.flush().map_err(io(&path, "write"))?;
        cur.count += samples.len() as u64;
        self.current = Some(cur);
        Ok(())
    }

    /// Drops the samples written so far for `step` (e.g. before re-acquiring it after a
    /// failure), so the step starts again at index 0. A no-op for a step with no samples.
    pub fn restart_step(&mut self, step: usize) -> Result<(), RunError> {
        let path = self.dir.join(SAMPLES_CSV);
        if self.done.contains(&step) {
            return Err(RunError::Protocol {
                path,
                message: format!("step {step} is already recorded and cannot be restarted"),
            });
        }
        if let Some(c) = self.current.filter(|c| c.step == step) {
            self.samples.flush().map_err(io(&path, "write"))?;
            let f = self.samples.get_ref();
            f.set_len(c.start_len).map_err(io(&path, "truncate"))?;
            f.sync_data().map_err(io(&path, "sync"))?;
            self.current = None;
            tracing::debug!(step, dropped = c.count, "step restarted");
        }
        Ok(())
    }

    /// Records a finished step: syncs samples.csv, appends the row to steps.csv, flushes and
    /// fsyncs it, then updates the manifest. The record must match the schedule (step, pass,
    /// rate) and the samples written (`n + overloads`), with `n ≥ 1` and a finite mean.
    pub fn append_step(&mut self, rec: StepRecord) -> Result<(), RunError> {
        let spath = self.dir.join(STEPS_CSV);
        let proto = |message: String| RunError::Protocol {
            path: spath.clone(),
            message,
        };
        let Some(s) = self.schedule.get(rec.step).copied() else {
            return Err(proto(format!("step {} is not in the schedule", rec.step)));
        };
        if self.done.contains(&rec.step) {
            return Err(proto(format!("step {} is already recorded", rec.step)));
        }
        if rec.pass != s.pass || rec.rate_dps.to_bits() != s.rate_dps.to_bits() {
            return Err(proto(format!(
                "step {}: pass {} rate {} where the schedule has pass {} rate {}",
                rec.step, rec.pass, rec.rate_dps, s.pass, s.rate_dps
            )));
        }
        if let Some(m) = series_mismatch(&rec, &s) {
            return Err(proto(format!("step {}: {m}", rec.step)));
        }
        let written = self
            .current
            .filter(|c| c.step == rec.step)
            .map_or(0, |c| c.count);
        if rec.n == 0 || rec.n.checked_add(rec.overloads) != Some(written) {
            return Err(proto(format!(
                "step {}: n {} + overloads {} must equal the {written} samples written, with n >= 1",
                rec.step, rec.n, rec.overloads
            )));
        }
        if let Some(msg) = record_problem(&rec) {
            return Err(proto(format!("step {}: {msg}", rec.step)));
        }
        let sapath = self.dir.join(SAMPLES_CSV);
        self.samples.flush().map_err(io(&sapath, "write"))?;
        self.samples
            .get_ref()
            .sync_data()
            .map_err(io(&sapath, "sync"))?;
        let start_utc = self.clock.utc(rec.t_start_s);
        let end_utc = self.clock.utc(rec.t_end_s);
        let r = rounded(&rec);
        let row = step_row(&r, &start_utc, &end_utc);
        if self.series_columns {
            self.steps.serialize(&row)
        } else {
            self.steps.serialize(row.plain())
        }
        .map_err(|e| csv_write(&spath, e))?;
        self.steps.flush().map_err(io(&spath, "write"))?;
        self.steps
            .get_ref()
            .sync_data()
            .map_err(io(&spath, "sync"))?;
        self.done.insert(rec.step);
        self.current = None;
        self.manifest.steps_done = self.done.iter().copied().collect();
        tracing::debug!(
            step = rec.step,
            rate_dps = rec.rate_dps,
            n = rec.n,
            "step recorded"
        );
        self.write_manifest()
    }

    /// Marks the run simulated because `by` says so (instruments that identify as
    /// simulators); a run started with `--simulate` is already.
    pub fn mark_simulated(&mut self, by: &str) -> Result<(), RunError> {
        if self.manifest.simulated {
            return Ok(());
        }
        self.manifest.simulated = true;
        self.manifest.simulated_by = Some(by.to_string());
        self.write_manifest()
    }

    /// Records the chamber's identity (a run with a chamber).
    pub fn set_chamber_identity(&mut self, identity: &str) -> Result<(), RunError> {
        let c = self
            .manifest
            .chamber
            .get_or_insert_with(ChamberRecord::default);
        c.identity = Some(identity.to_string());
        self.write_manifest()
    }

    /// Records where the session left the chamber: its safe state in words, whether it was
    /// confirmed, and what was read back (or why nothing could be).
    pub fn set_chamber_safe(
        &mut self,
        state: &str,
        confirmed: bool,
        detail: &str,
    ) -> Result<(), RunError> {
        let c = self
            .manifest
            .chamber
            .get_or_insert_with(ChamberRecord::default);
        c.safe_state = Some(state.to_string());
        c.safe_confirmed = Some(confirmed);
        c.safe_detail = Some(detail.to_string());
        self.write_manifest()
    }

    /// Sets the instruments' identities.
    pub fn set_instruments(&mut self, instruments: Instruments) -> Result<(), RunError> {
        self.manifest.instruments = instruments;
        self.write_manifest()
    }

    /// Records the warm-up's state (written at every window, so a crash keeps the curve).
    pub fn set_warmup(&mut self, warmup: WarmupRecord) -> Result<(), RunError> {
        self.manifest.warmup = Some(warmup);
        self.write_manifest()
    }

    /// Records a departure from the method (see [`Deviation`]).
    pub fn add_deviation(&mut self, kind: &str, text: &str) -> Result<(), RunError> {
        self.manifest.deviations.push(Deviation {
            kind: kind.to_string(),
            text: text.to_string(),
            at_utc: now_utc(),
        });
        self.write_manifest()
    }

    /// Sets the elapsed run-clock time, s (the caller's figure; finite, ≥ 0).
    pub fn set_elapsed(&mut self, elapsed_s: f64) -> Result<(), RunError> {
        self.check_finite("elapsed_s", elapsed_s)?;
        self.manifest.elapsed_s = round_significant(elapsed_s);
        self.write_manifest()
    }

    /// The run clock at a point where the run writes nothing else (a soak's poll of the
    /// chamber, a warm-up's chunk), s: held in the manifest at once, but written to disk only
    /// when it is [`CHECKPOINT_INTERVAL_S`] or more ahead of the manifest on disk; every other
    /// write of the manifest (a step recorded, a retry, the end) writes it too. Returns
    /// whether the manifest was written.
    ///
    /// Why the policy is here, once, and not in each caller: a write of the manifest is an
    /// atomic rewrite with two fsyncs, and a caller that checkpoints at every poll (a soak
    /// polled every 10 s through a day-long series) made thousands of them: 56 s of wall time
    /// for an 8 h 52 min simulated series instead of 2 s. What a crash can lose is at most
    /// that much of the run clock's account, never a reading: a resume goes on from the last
    /// finished step's end or `temps.csv`'s last row when they are later.
    pub fn checkpoint(&mut self, elapsed_s: f64) -> Result<bool, RunError> {
        self.check_finite("elapsed_s", elapsed_s)?;
        self.manifest.elapsed_s = round_significant(elapsed_s);
        if self.manifest.elapsed_s - self.durable_elapsed_s < CHECKPOINT_INTERVAL_S {
            return Ok(false);
        }
        self.write_manifest()?;
        Ok(true)
    }

    /// Logs a retry.
    pub fn log_retry(&mut self, retry: Retry) -> Result<(), RunError> {
        self.check_finite("retry t_s", retry.t_s)?;
        self.manifest.retries.push(Retry {
            t_s: round_significant(retry.t_s),
            ..retry
        });
        self.write_manifest()
    }

    /// Records bound versus elapsed.
    pub fn set_timing(&mut self, timing: Timing) -> Result<(), RunError> {
        for (what, v) in [
            ("bound_s", timing.bound_s),
            ("elapsed_s", timing.elapsed_s),
            ("ratio", timing.ratio),
        ] {
            self.check_finite(what, v)?;
        }
        self.manifest.timing = Some(Timing {
            bound_s: round_significant(timing.bound_s),
            elapsed_s: round_significant(timing.elapsed_s),
            ratio: round_significant(timing.ratio),
            ..timing
        });
        self.write_manifest()
    }

    /// Stores the fit document: writes `fit.json` atomically (every computed number rounded
    /// once, see [`crate::num`]) and references it from the manifest ([`FitSummary`]: its
    /// name, the SHA-256 of its bytes, the headline figures).
    pub fn set_fit(&mut self, fit: gyrocal_fit::Analysis) -> Result<(), RunError> {
        let path = self.dir.join(FIT_JSON);
        let cannot = |e: serde_json::Error| RunError::Protocol {
            path: path.clone(),
            message: format!("cannot serialise the fit: {e}"),
        };
        let mut doc = serde_json::to_value(&fit).map_err(cannot)?;
        round_json(&mut doc);
        let mut bytes = serde_json::to_vec_pretty(&doc).map_err(cannot)?;
        bytes.push(b'\n');
        write_atomic(&self.dir, FIT_JSON, &bytes)?;
        self.manifest.fit_summary = Some(FitSummary::of(&fit, sha256_hex(&bytes)));
        // the verdict as fit.json holds it (rounded alike), so the two documents agree
        self.manifest.acceptance = serde_json::from_value(doc["acceptance"].clone()).ok();
        self.manifest.legacy_fit = None;
        self.write_manifest()
    }

    /// Closes the run with `status` (not `running`) and its reason, the run-clock elapsed
    /// time and the end (`ended_utc`: the wall clock now; in virtual time, the run clock's
    /// `elapsed_s` on the clock of the `t_utc` stamps). `complete` is refused while steps
    /// remain.
    pub fn finish(
        &mut self,
        status: Status,
        reason: Option<String>,
        elapsed_s: f64,
    ) -> Result<(), RunError> {
        self.check_finite("elapsed_s", elapsed_s)?;
        let path = self.dir.join(MANIFEST_JSON);
        if status == Status::Running {
            return Err(RunError::Protocol {
                path,
                message: "finish with status running".into(),
            });
        }
        if status == Status::Complete && self.done.len() != self.schedule.len() {
            return Err(RunError::Protocol {
                path,
                message: format!(
                    "cannot mark complete: {} of {} steps done",
                    self.done.len(),
                    self.schedule.len()
                ),
            });
        }
        // Best effort to get everything on disk before the final word.
        let sapath = self.dir.join(SAMPLES_CSV);
        self.samples.flush().map_err(io(&sapath, "write"))?;
        self.samples
            .get_ref()
            .sync_data()
            .map_err(io(&sapath, "sync"))?;
        let dir = self.dir.clone();
        self.temps.sync(&dir)?;
        if status == Status::Complete {
            for name in [SAMPLES_CSV, STEPS_CSV] {
                let path = self.dir.join(name);
                let sum = sha256_file(&path).map_err(opened)?;
                self.manifest.checksums.insert(name.to_string(), sum);
            }
            // the temperatures of a run with a chamber, checked by `verify` like the data
            let tpath = self.dir.join(TEMPS_CSV);
            if tpath.is_file() {
                let sum = sha256_file(&tpath).map_err(opened)?;
                self.manifest.checksums.insert(TEMPS_CSV.to_string(), sum);
            }
        }
        self.manifest.status = status;
        self.manifest.reason = reason;
        self.manifest.elapsed_s = round_significant(elapsed_s);
        // one clock for the stamps and the end: in virtual time the run clock runs ahead of
        // the wall clock, and `t_utc` is the anchor plus the run clock (see "Times"), so the
        // end is too; otherwise the wall clock now (the same to a few milliseconds)
        self.manifest.ended_utc = Some(if self.manifest.virtual_time {
            self.clock.utc(elapsed_s)
        } else {
            now_utc()
        });
        self.write_manifest()
    }

    /// Writes another file of the run (e.g. `report.html`) atomically.
    pub fn write_file(&self, name: &str, bytes: &[u8]) -> Result<(), RunError> {
        if name.contains(['/', '\\']) || name.starts_with('.') || name.is_empty() {
            return Err(RunError::Protocol {
                path: self.dir.join(name),
                message: "a run file name must be a plain, non-hidden name".into(),
            });
        }
        write_atomic(&self.dir, name, bytes)
    }

    pub(super) fn check_finite(&self, what: &str, v: f64) -> Result<(), RunError> {
        if v.is_finite() && v >= 0.0 || (what == "ratio" && v.is_finite()) {
            Ok(())
        } else {
            Err(RunError::Protocol {
                path: self.dir.join(MANIFEST_JSON),
                message: format!("{what} must be finite and >= 0 (got {v})"),
            })
        }
    }

    pub(super) fn write_manifest(&mut self) -> Result<(), RunError> {
        store_manifest(&self.dir, &mut self.manifest)?;
        self.durable_elapsed_s = self.manifest.elapsed_s;
        Ok(())
    }

    /// Writes a result file of the run (`allan.json`, `allan.html`, any later one) atomically
    /// and records its SHA-256 in the manifest's `checksums`, so `gyrocal verify` checks it
    /// and `gyrocal report` refuses it edited. Not for the data files, the manifest or
    /// `fit.json` (see [`RunDir::set_fit`]).
    pub fn write_result(&mut self, name: &str, bytes: &[u8]) -> Result<(), RunError> {
        record_result(&self.dir, &mut self.manifest, name, bytes)
    }
}

/// Whether a run of `plan` writes the temperature series' columns in steps.csv.
pub(super) fn series_columns(plan: &Plan) -> bool {
    plan.kind() == crate::PlanKind::Series
}

/// The steps.csv columns a run writes ([`STEPS_HEADER`] with the series' columns).
pub(super) fn steps_header(series_columns: bool) -> &'static [&'static str] {
    if series_columns {
        &STEPS_HEADER
    } else {
        &STEPS_HEADER_V4
    }
}

/// The steps.csv headers a resume accepts, the one it writes first (an older one is
/// rewritten to it).
pub(super) fn steps_headers_for(series_columns: bool) -> Vec<&'static [&'static str]> {
    let first = steps_header(series_columns);
    std::iter::once(first)
        .chain(STEPS_HEADERS.iter().copied().filter(|h| *h != first))
        .collect()
}
