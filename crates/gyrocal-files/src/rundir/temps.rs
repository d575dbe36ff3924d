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
