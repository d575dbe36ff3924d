//! The CSV files' lines, headers and rows: torn last lines, accepted headers (a column named
//! twice named with both positions), `steps.csv` parsed against the schedule, and the
//! `csv` crate's errors naming the file and the line.
#[allow(unused_imports)]
use super::*;

/// Splits off a torn last line: returns the bytes up to and including the last newline, and
/// how many bytes followed it.
pub(super) fn complete_lines(bytes: &[u8]) -> (&[u8], u64) {
    let keep = bytes.iter().rposition(|&b| b == b'\n').map_or(0, |i| i + 1);
    (
        bytes.get(..keep).unwrap_or_default(),
        (bytes.len() - keep) as u64,
    )
}

/// Checks the first line against the accepted headers (current first); returns the index of
/// the one found. A column name that appears twice is named with both positions.
pub(super) fn check_header(
    path: &Path,
    bytes: &[u8],
    accepted: &[&[&str]],
) -> Result<usize, RunError> {
    let first = bytes.split(|&b| b == b'\n').next().unwrap_or_default();
    let first = first.strip_suffix(b"\r").unwrap_or(first);
    let text = String::from_utf8_lossy(first);
    let names: Vec<&str> = text.split(',').collect();
    for (j, name) in names.iter().enumerate() {
        if let Some(i) = names.iter().take(j).position(|n| n == name) {
            return Err(RunError::Csv {
                path: path.to_path_buf(),
                line: 1,
                message: format!(
                    "the header names column `{name}` twice (columns {} and {})",
                    i + 1,
                    j + 1
                ),
            });
        }
    }
    if let Some(k) = accepted
        .iter()
        .position(|h| h.len() == names.len() && h.iter().zip(&names).all(|(a, b)| a == b))
    {
        return Ok(k);
    }
    Err(RunError::Csv {
        path: path.to_path_buf(),
        line: 1,
        message: format!(
            "header is {text:?}, expected {:?}",
            accepted.first().map(|h| h.join(",")).unwrap_or_default()
        ),
    })
}

pub(super) fn parse_steps(
    path: &Path,
    bytes: &[u8],
    schedule: &[Step],
) -> Result<Vec<StepRecord>, RunError> {
    let mut rdr = csv::ReaderBuilder::new()
        .has_headers(true)
        .from_reader(bytes);
    let mut seen = BTreeSet::new();
    let mut out = Vec::new();
    let mut rec = csv::StringRecord::new();
    // by name: files written before `rate_samples` existed lack that column; the counted
    // columns by their in-memory names, re-based by the header's counting
    let headers = rdr.headers().map_err(|e| csv_read(path, &e))?.clone();
    let counting = Counting::of_header(headers.iter());
    let fields = Counting::field_names(&headers);
    let step_no = |i: usize| counting.show("step", i as u64);
    loop {
        match rdr.read_record(&mut rec) {
            Ok(false) => break,
            Ok(true) => {}
            Err(e) => return Err(csv_read(path, &e)),
        }
        // the record's own position: taken before the first read, the reader's position
        // would still point at the header
        let line = rec.position().map_or(0, csv::Position::line);
        let bad = |message: String| RunError::Csv {
            path: path.to_path_buf(),
            line,
            message,
        };
        let r = read_step(&rec, &fields, counting).map_err(bad)?;
        let Some(s) = schedule.get(r.step) else {
            return Err(bad(format!(
                "{} is not in the plan's schedule ({} steps)",
                step_no(r.step),
                schedule.len()
            )));
        };
        if r.pass != s.pass || r.rate_dps.to_bits() != s.rate_dps.to_bits() {
            return Err(bad(format!(
                "{} has {} rate {}, the schedule {} rate {}",
                step_no(r.step),
                counting.show("pass", u64::from(r.pass)),
                r.rate_dps,
                counting.show("pass", u64::from(s.pass)),
                s.rate_dps
            )));
        }
        if let Some(m) = series_mismatch(&r, s) {
            return Err(bad(format!("{} {m}", step_no(r.step))));
        }
        if !seen.insert(r.step) {
            return Err(bad(format!("{} appears twice", step_no(r.step))));
        }
        if r.n == 0 || r.n.checked_add(r.overloads).is_none() {
            return Err(bad(format!(
                "{}: n must be >= 1 (got {})",
                step_no(r.step),
                r.n
            )));
        }
        if let Some(msg) = record_problem(&r) {
            return Err(bad(format!("{}: {msg}", step_no(r.step))));
        }
        out.push(r);
    }
    Ok(out)
}

pub(super) fn csv_read(path: &Path, e: &csv::Error) -> RunError {
    RunError::Csv {
        path: path.to_path_buf(),
        line: e.position().map_or(0, csv::Position::line),
        message: e.to_string(),
    }
}

pub(super) fn csv_write(path: &Path, e: csv::Error) -> RunError {
    match e.into_kind() {
        csv::ErrorKind::Io(source) => RunError::Io {
            path: path.to_path_buf(),
            action: "write",
            source,
        },
        other => RunError::Protocol {
            path: path.to_path_buf(),
            message: format!("{other:?}"),
        },
    }
}

/// Opens a CSV for appending; `new` writes (and syncs) the header into an empty file.
pub(super) fn open_csv(
    path: &Path,
    header: &[&str],
    new: bool,
) -> Result<csv::Writer<File>, RunError> {
    let file = OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)
        .map_err(io(path, "open"))?;
    let mut w = csv::WriterBuilder::new()
        .has_headers(false)
        .from_writer(file);
    if new {
        w.write_record(header).map_err(|e| csv_write(path, e))?;
        w.flush().map_err(io(path, "write"))?;
        w.get_ref().sync_all().map_err(io(path, "sync"))?;
    }
    Ok(w)
}
