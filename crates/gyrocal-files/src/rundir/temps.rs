//! `temps.csv`: the chamber's temperatures all through a run with a chamber (a temperature
//! series), one row per reading of the chamber:
//! `t_s,setpoint_c,air_c,product_c,series_point,phase`.
//!
//! - `t_s`: the run clock, s (the same clock as samples.csv's `t_s`, so a reading of the gyro
//!   is joined with the temperature around it);
//! - `setpoint_c`: the setpoint the chamber reported (during a ramp, the run's intermediate
//!   setpoint, not the target);
//! - `air_c`: the chamber's air; `product_c`: the gyro's (product) temperature, empty when the
//!   chamber has no product sensor;
//! - `series_point`: 0-based index into `[series] temperatures_c` (empty at the teardown);
//! - `phase`: `ramp` (the setpoint moving towards the target), `soak` (waiting for the
//!   criterion), `measure` (during a step's acquisition) or `safe` (the teardown's reading
//!   after the chamber was put in its safe state).
//!
//! Why a file of its own and not columns of samples.csv: the chamber is read every `poll_s`
//! (seconds), the meter many times a second, and during a soak (hours) there are no readings
//! at all. Rows are appended and flushed to the OS one by one, like samples.csv (a crash of
//! the program loses nothing); the file is synced when the run closes and its SHA-256
//! recorded with the data files' when the run completes. A resume appends to it (a torn last
//! line dropped first): the temperatures are the run's history, every session's.

#[allow(unused_imports)]
use super::*;

/// Columns of `temps.csv`, in order.
pub const TEMPS_HEADER: [&str; 6] = [
    "t_s",
    "setpoint_c",
    "air_c",
    "product_c",
    "series_point",
    "phase",
];

/// The most bytes read from `temps.csv` (256 MiB: a reading every second for years).
pub const MAX_TEMPS_BYTES: u64 = 256 * 1024 * 1024;

/// What the run was doing when the chamber was read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Phase {
    /// The setpoint moving towards the target at the run's ramp.
    Ramp,
    /// Waiting for the soak criterion.
    Soak,
    /// During a step's acquisition.
    Measure,
    /// The teardown's reading, the chamber in its safe state.
    Safe,
}

impl Phase {
    /// As written in the file.
    pub fn as_str(self) -> &'static str {
        match self {
            Phase::Ramp => "ramp",
            Phase::Soak => "soak",
            Phase::Measure => "measure",
            Phase::Safe => "safe",
        }
    }
}

/// One row of `temps.csv`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TempRow {
    /// Run clock, s.
    pub t_s: f64,
    /// The chamber's setpoint, °C.
    pub setpoint_c: f64,
    /// The air, °C.
    pub air_c: f64,
    /// The gyro (product), °C; `None` without a product sensor.
    pub product_c: Option<f64>,
    /// 0-based index into `[series] temperatures_c`; `None` outside the series' points.
    pub series_point: Option<u32>,
    /// What the run was doing.
    pub phase: Phase,
}

fn row_problem(r: &TempRow) -> Option<String> {
    if !r.t_s.is_finite() || r.t_s < 0.0 {
        return Some(format!("t_s must be finite and >= 0 (got {})", r.t_s));
    }
    for (what, v) in [
        ("setpoint_c", Some(r.setpoint_c)),
        ("air_c", Some(r.air_c)),
        ("product_c", r.product_c),
    ] {
        if v.is_some_and(|v| !v.is_finite()) {
            return Some(format!("{what} must be finite (got {v:?})"));
        }
    }
    None
}

/// Reads every complete row of `DIR/temps.csv` (a torn last line is ignored): an empty list
/// when the run has no such file (a run without a chamber). A row that does not parse, or
/// whose numbers are not finite, is an error naming the file and its line.
pub fn read_temps(dir: &Path) -> Result<Vec<TempRow>, RunError> {
    let path = dir.join(TEMPS_CSV);
    match fs::symlink_metadata(&path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(io(&path, "read")(e)),
        Ok(_) => {}
    }
    let bytes = read_capped(&path, MAX_TEMPS_BYTES)?;
    let (bytes, _) = complete_lines(&bytes);
    check_header(&path, bytes, &[&TEMPS_HEADER])?;
    let mut rdr = csv::ReaderBuilder::new()
        .has_headers(true)
        .from_reader(bytes);
    let mut out = Vec::new();
    let mut rec = csv::StringRecord::new();
    loop {
        match rdr.read_record(&mut rec) {
            Ok(false) => break,
            Ok(true) => {}
            Err(e) => return Err(csv_read(&path, &e)),
        }
        let line = rec.position().map_or(0, csv::Position::line);
        let bad = |message: String| RunError::Csv {
            path: path.clone(),
            line,
            message,
        };
        let row: TempRow = rec.deserialize(None).map_err(|e| bad(e.to_string()))?;
        if let Some(m) = row_problem(&row) {
            return Err(bad(m));
        }
        out.push(row);
    }
    Ok(out)
}

/// How much of `temps.csv`'s end [`last_t_s`] reads first (a row is some 50 bytes); it
/// reads twice as much again while that holds no complete row.
const TAIL_BYTES: u64 = 16 * 1024;

/// The run clock (`t_s`) of the last complete row of `DIR/temps.csv`, read from the file's
/// end (a block of it, not the file: a series logs the chamber every few seconds for days,
/// and a resume wants only where its clock stopped). A torn last line (a crash mid-write) is
/// not a row. `None`: no file (a run without a chamber) or no row yet. A last row whose
/// `t_s` is not a number is an error naming the file.
pub fn last_t_s(dir: &Path) -> Result<Option<f64>, RunError> {
    use std::io::{Read as _, Seek as _, SeekFrom};
    let path = dir.join(TEMPS_CSV);
    let mut f = match open_regular(&path) {
        Ok(f) => f,
        Err(e) if e.kind() == crate::open::OpenErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(opened(e)),
    };
    let len = f.metadata().map_err(io(&path, "read"))?.len();
    let mut block = TAIL_BYTES;
    loop {
        let start = len.saturating_sub(block);
        f.seek(SeekFrom::Start(start)).map_err(io(&path, "read"))?;
        let mut buf = Vec::new();
        (&mut f)
            .take(len - start)
            .read_to_end(&mut buf)
            .map_err(io(&path, "read"))?;
        // the complete lines, without the newline that ends the last one
        let (complete, _) = complete_lines(&buf);
        let body = complete.strip_suffix(b"\n").unwrap_or(complete);
        let line = match body.iter().rposition(|&b| b == b'\n') {
            Some(i) => &body[i + 1..],
            // the block begins mid-line: the last complete line may begin before it
            None if start > 0 => {
                block = block.saturating_mul(2);
                continue;
            }
            // the file's only complete line: the header, no row yet
            None => return Ok(None),
        };
        let line = line.strip_suffix(b"\r").unwrap_or(line);
        let text = String::from_utf8_lossy(line);
        if line.is_empty() {
            return Ok(None);
        }
        let first = text.split(',').next().unwrap_or_default();
        return match first.trim().parse::<f64>() {
            Ok(t) if t.is_finite() && t >= 0.0 => Ok(Some(t)),
            _ => Err(RunError::Inconsistent {
                path,
                message: format!(
                    "its last row ({:?}) has no run clock (t_s) to resume from",
                    text.chars().take(80).collect::<String>()
                ),
            }),
        };
    }
}

/// The writer of `temps.csv`, opened on the first row (a run without a chamber has no file).
#[derive(Debug, Default)]
pub(super) struct TempsWriter {
    w: Option<csv::Writer<File>>,
}

impl TempsWriter {
    /// Appends one row and flushes it to the OS. The file is created with its header on the
    /// first row of a run; a resume first drops a torn last line.
    pub(super) fn append(&mut self, dir: &Path, row: &TempRow) -> Result<(), RunError> {
        let path = dir.join(TEMPS_CSV);
        if let Some(m) = row_problem(row) {
            return Err(RunError::Protocol { path, message: m });
        }
        if self.w.is_none() {
            self.w = Some(open_temps(&path)?);
        }
        let Some(w) = self.w.as_mut() else {
            return Ok(());
        };
        let rounded = TempRow {
            t_s: round_significant(row.t_s),
            ..*row
        };
        w.serialize((
            rounded.t_s,
            rounded.setpoint_c,
            rounded.air_c,
            rounded.product_c,
            rounded.series_point,
            rounded.phase.as_str(),
        ))
        .map_err(|e| csv_write(&path, e))?;
        w.flush().map_err(io(&path, "write"))
    }

    /// Syncs the file to disk, when there is one.
    pub(super) fn sync(&mut self, dir: &Path) -> Result<(), RunError> {
        let path = dir.join(TEMPS_CSV);
        if let Some(w) = self.w.as_mut() {
            w.flush().map_err(io(&path, "write"))?;
            w.get_ref().sync_data().map_err(io(&path, "sync"))?;
        }
        Ok(())
    }
}

/// Opens `temps.csv` for appending: created with its header when missing or empty; an
/// existing one (a resumed run) checked for its header and cut after its last complete line.
fn open_temps(path: &Path) -> Result<csv::Writer<File>, RunError> {
    let exists = match fs::symlink_metadata(path) {
        Ok(m) => m.len() > 0,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => false,
        Err(e) => return Err(io(path, "open")(e)),
    };
    if !exists {
        return open_csv(path, &TEMPS_HEADER, true);
    }
    let bytes = read_capped(path, MAX_TEMPS_BYTES)?;
    let (complete, _) = complete_lines(&bytes);
    check_header(path, complete, &[&TEMPS_HEADER])?;
    let keep = complete.len() as u64;
    if keep < bytes.len() as u64 {
        truncate(path, keep)?;
    }
    open_csv(path, &TEMPS_HEADER, false)
}

impl RunDir {
    /// Appends a reading of the chamber to `temps.csv` (created on the first), flushed to the
    /// OS. Numbers must be finite.
    pub fn append_temp(&mut self, row: &TempRow) -> Result<(), RunError> {
        let dir = self.dir.clone();
        self.temps.append(&dir, row)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn row(t_s: f64, phase: Phase) -> TempRow {
        TempRow {
            t_s,
            setpoint_c: -20.0,
            air_c: -19.5,
            product_c: Some(-18.25),
            series_point: Some(1),
            phase,
        }
    }

    #[test]
    fn rows_written_read_back_and_a_torn_line_is_ignored() {
        let dir = tempfile::tempdir().unwrap();
        let mut w = TempsWriter::default();
        w.append(dir.path(), &row(10.0, Phase::Ramp)).unwrap();
        w.append(
            dir.path(),
            &TempRow {
                product_c: None,
                series_point: None,
                ..row(20.0, Phase::Safe)
            },
        )
        .unwrap();
        w.sync(dir.path()).unwrap();
        let text = fs::read_to_string(dir.path().join(TEMPS_CSV)).unwrap();
        assert_eq!(
            text,
            "t_s,setpoint_c,air_c,product_c,series_point,phase\n10.0,-20.0,-19.5,-18.25,1,ramp\n20.0,-20.0,-19.5,,,safe\n"
        );
        // a torn last line (a crash mid-write) is ignored by the reader and cut by the next
        // writer
        fs::write(dir.path().join(TEMPS_CSV), format!("{text}30,-20,-1")).unwrap();
        let back = read_temps(dir.path()).unwrap();
        assert_eq!(back.len(), 2);
        assert_eq!(back[0], row(10.0, Phase::Ramp));
        assert_eq!(back[1].product_c, None);
        let mut again = TempsWriter::default();
        again
            .append(dir.path(), &row(40.0, Phase::Measure))
            .unwrap();
        let back = read_temps(dir.path()).unwrap();
        assert_eq!(
            back.iter().map(|r| r.t_s).collect::<Vec<_>>(),
            [10.0, 20.0, 40.0]
        );
    }

    #[test]
    fn a_run_without_a_chamber_has_no_temperatures() {
        let dir = tempfile::tempdir().unwrap();
        assert!(read_temps(dir.path()).unwrap().is_empty());
        assert_eq!(last_t_s(dir.path()).unwrap(), None);
        // the header alone, and the header with a torn first row: no row yet
        let header = format!("{}\n", TEMPS_HEADER.join(","));
        fs::write(dir.path().join(TEMPS_CSV), &header).unwrap();
        assert_eq!(last_t_s(dir.path()).unwrap(), None);
        fs::write(dir.path().join(TEMPS_CSV), format!("{header}12.5,2")).unwrap();
        assert_eq!(last_t_s(dir.path()).unwrap(), None);
    }

    #[test]
    fn the_last_row_s_clock_is_read_from_the_end_of_a_large_file() {
        let dir = tempfile::tempdir().unwrap();
        let mut w = TempsWriter::default();
        // some 2 MiB: a reading every 10 s for four days
        let rows = 36_000;
        for i in 0..rows {
            w.append(dir.path(), &row(f64::from(i) * 10.0, Phase::Soak))
                .unwrap();
        }
        w.sync(dir.path()).unwrap();
        let path = dir.path().join(TEMPS_CSV);
        assert!(fs::metadata(&path).unwrap().len() > 1024 * 1024);
        let last = f64::from(rows - 1) * 10.0;
        assert_eq!(last_t_s(dir.path()).unwrap(), Some(last));
        assert_eq!(read_temps(dir.path()).unwrap().last().unwrap().t_s, last);
        // a torn last line (a crash mid-write) is not a row: the one before it is the last
        let mut f = OpenOptions::new().append(true).open(&path).unwrap();
        std::io::Write::write_all(&mut f, b"999999.0,-20.0,-1").unwrap();
        assert_eq!(last_t_s(dir.path()).unwrap(), Some(last));
        // a last line longer than the first block read: read further back
        let long = format!("{}\n", "1".repeat(3 * TAIL_BYTES as usize));
        let mut f = OpenOptions::new().append(true).open(&path).unwrap();
        std::io::Write::write_all(
            &mut f,
            format!("\n12345.5,-20,-19.5,,1,soak{long}").as_bytes(),
        )
        .unwrap();
        assert_eq!(last_t_s(dir.path()).unwrap(), Some(12345.5));
        // a last row without a clock is an error naming the file
        let mut f = OpenOptions::new().append(true).open(&path).unwrap();
        std::io::Write::write_all(&mut f, b"noon,-20,-19.5,,1,soak\n").unwrap();
        let e = last_t_s(dir.path()).unwrap_err().to_string();
        assert!(e.contains("temps.csv") && e.contains("noon"), "{e}");
    }

    #[test]
    fn a_bad_row_names_the_file_and_line() {
        let dir = tempfile::tempdir().unwrap();
        fs::write(
            dir.path().join(TEMPS_CSV),
            "t_s,setpoint_c,air_c,product_c,series_point,phase\n1,25,25,25,0,soak\n2,25,x,25,0,soak\n",
        )
        .unwrap();
        let e = read_temps(dir.path()).unwrap_err().to_string();
        assert!(e.contains("temps.csv") && e.contains('3'), "{e}");
        fs::write(
            dir.path().join(TEMPS_CSV),
            "t_s,setpoint_c,air_c,product_c,series_point,phase\n1,25,25,25,0,boiling\n",
        )
        .unwrap();
        let e = read_temps(dir.path()).unwrap_err().to_string();
        assert!(e.contains("temps.csv"), "{e}");
        let mut w = TempsWriter::default();
        let e = w
            .append(
                dir.path(),
                &TempRow {
                    air_c: f64::NAN,
                    ..row(1.0, Phase::Soak)
                },
            )
            .unwrap_err()
            .to_string();
        assert!(e.contains("air_c"), "{e}");
    }
}
