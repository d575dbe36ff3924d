//! Reading a run directory back (the report, `gyrocal fit`, the catalog): [`load`],
//! [`load_fit`], [`load_samples`], each file read with a size cap ([`read_capped`]); the plan a
//! run was started with ([`run_plan`]) and how another plan differs from it
//! ([`plan_changes`]).
#[allow(unused_imports)]
use super::*;

/// Reads a run directory (for the report and `gyrocal fit`): the manifest and the finished
/// steps. Read-only: a torn last line of steps.csv is ignored, not repaired.
pub fn load(dir: &Path) -> Result<RunData, RunError> {
    let manifest = read_manifest(&dir.join(MANIFEST_JSON))?;
    let spath = dir.join(STEPS_CSV);
    let bytes = read_capped(&spath, MAX_STEPS_BYTES)?;
    let (bytes, _) = complete_lines(&bytes);
    check_header(&spath, bytes, STEPS_HEADERS)?;
    let schedule = manifest.plan.schedule();
    let steps = parse_steps(&spath, bytes, &schedule)?;
    Ok(RunData { manifest, steps })
}

/// Reads a run directory's `fit.json` (what `gyrocal_analysis::sweep::fit_run` wrote): `Ok(None)` when the run
/// has none (not fitted yet, or written before fit.json existed: see
/// [`Manifest::legacy_fit`]). A file that does not parse is an error naming it, its line and
/// column.
pub fn load_fit(dir: &Path) -> Result<Option<gyrocal_fit::Analysis>, RunError> {
    let path = dir.join(FIT_JSON);
    match fs::symlink_metadata(&path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(io(&path, "read")(e)),
        Ok(_) => {}
    }
    let bytes = read_capped(&path, MAX_FIT_BYTES)?;
    serde_json::from_slice(&bytes)
        .map(Some)
        .map_err(|e| RunError::Json {
            path: path.clone(),
            line: e.line(),
            column: e.column(),
            message: e.to_string(),
        })
}

/// Reads every complete row of samples.csv (a torn last line is ignored), 0-based whatever the
/// file's counting (see [`SampleRow`]).
pub fn load_samples(dir: &Path) -> Result<Vec<SampleRow>, RunError> {
    let path = dir.join(SAMPLES_CSV);
    let bytes = read_capped(&path, MAX_SAMPLES_BYTES)?;
    let (bytes, _) = complete_lines(&bytes);
    check_header(&path, bytes, SAMPLES_HEADERS)?;
    let mut rdr = csv::ReaderBuilder::new()
        .has_headers(true)
        .from_reader(bytes);
    // by name: files written before `t_utc` existed lack that column; the counted columns by
    // their in-memory names, re-based by the header's counting
    let headers = rdr.headers().map_err(|e| csv_read(&path, &e))?.clone();
    let counting = Counting::of_header(headers.iter());
    let fields = Counting::field_names(&headers);
    let mut out = Vec::new();
    let mut rec = csv::StringRecord::new();
    loop {
        match rdr.read_record(&mut rec) {
            Ok(false) => break,
            Ok(true) => {}
            Err(e) => return Err(csv_read(&path, &e)),
        }
        let row = read_sample(&rec, &fields, counting).map_err(|message| RunError::Csv {
            path: path.clone(),
            line: rec.position().map_or(0, csv::Position::line),
            message,
        })?;
        out.push(row);
    }
    Ok(out)
}

/// Reads a file of a run directory whole, refusing anything but a regular file and more than
/// `cap` bytes (checked from the size first, then by reading at most `cap + 1` bytes, so a file
/// that grows or never ends costs at most `cap` bytes of memory).
pub fn read_capped(path: &Path, cap: u64) -> Result<Vec<u8>, RunError> {
    use std::io::Read as _;
    let file = open_regular(path).map_err(opened)?;
    let meta = file.metadata().map_err(io(path, "read"))?;
    let too_large = || RunError::TooLarge {
        path: path.to_path_buf(),
        cap,
    };
    if meta.len() > cap {
        return Err(too_large());
    }
    let mut bytes = Vec::with_capacity(usize::try_from(meta.len()).unwrap_or(0));
    file.take(cap.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(io(path, "read"))?;
    if bytes.len() as u64 > cap {
        return Err(too_large());
    }
    Ok(bytes)
}

/// The plan a run was started with, from its manifest: `gyrocal run --resume DIR` needs no
/// plan file. A directory without a manifest is said to be no run directory.
pub fn run_plan(dir: &Path) -> Result<Plan, RunError> {
    let path = dir.join(MANIFEST_JSON);
    if !path.exists() {
        return Err(RunError::NotARun {
            path: dir.to_path_buf(),
        });
    }
    read_manifest(&path).map(|m| m.plan)
}

/// The keys whose values differ between the plan of a run and another plan, as
/// `[section] key: run's value (run) vs other value (this plan)`, in the plan file's order.
pub fn plan_changes(run: &Plan, other: &Plan) -> Vec<String> {
    let (Ok(a), Ok(b)) = (
        serde_json::to_value(run.to_doc()),
        serde_json::to_value(other.to_doc()),
    ) else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for section in ["plan", "table", "dmm", "simulation"] {
        let empty = serde_json::Map::new();
        let sa = a.get(section).and_then(|v| v.as_object()).unwrap_or(&empty);
        let sb = b.get(section).and_then(|v| v.as_object()).unwrap_or(&empty);
        let mut keys: Vec<&String> = sa.keys().chain(sb.keys()).collect();
        keys.dedup();
        let mut seen = std::collections::BTreeSet::new();
        for key in keys {
            if !seen.insert(key) {
                continue;
            }
            let (va, vb) = (sa.get(key), sb.get(key));
            if va != vb {
                let show =
                    |v: Option<&serde_json::Value>| v.map_or("(none)".into(), |v| v.to_string());
                out.push(format!(
                    "[{section}] {key}: {} (run) vs {} (this plan)",
                    show(va),
                    show(vb)
                ));
            }
        }
    }
    out
}
