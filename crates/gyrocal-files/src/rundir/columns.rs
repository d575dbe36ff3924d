//! The counted columns of the CSV files, across format versions: the one place where a
//! file's step, reading and pass numbers become the in-memory 0-based indices and back.
//!
//! Since format 3 the files count from 1, as the terminal and the report do ("step 3 of 19"
//! is `step_no` 3), and the counted columns say so by their `_no` suffix: `step_no`,
//! `sample_no` (samples.csv), `pass_no` (steps.csv). Why renamed and not only re-based: a
//! file whose `step` column silently changed its base would be misread by every script
//! written for the old one, and `index` and `pass` collide with pandas (`df.index` is the
//! DataFrame's index, `df.pass` a syntax error). Earlier files (`step`, `index`, `pass`,
//! counted from 0) still read with their values as before.
//!
//! Which base a file uses is told by its header, never guessed from its values:
//! [`Counting::of_header`]. In memory ([`StepRecord`], [`SampleRow`], the resume's
//! bookkeeping, the manifest's `steps_done`) everything stays 0-based, the schedule's index.
//! A serde `rename`/`alias` alone cannot do this (the base changes with the name), so a row
//! is read by the in-memory field names ([`Counting::field_names`]) and then re-based
//! ([`read_step`], [`read_sample`]); a row is written by [`step_row`] and [`write_sample`].
#[allow(unused_imports)]
use super::*;

/// Each counted column: its name since format 3 (counted from 1) and its name before (counted
/// from 0), which is also the in-memory field's name.
pub(super) const COUNTED: [(&str, &str); 3] = [
    ("step_no", "step"),
    ("sample_no", "index"),
    ("pass_no", "pass"),
];

/// How a CSV file counts its steps, readings and passes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Counting {
    /// `step_no`, `sample_no`, `pass_no`: from 1 (format 3 on).
    FromOne,
    /// `step`, `index`, `pass`: from 0 (files of formats 1 and 2).
    FromZero,
}

impl Counting {
    /// The counting of a file with these column names: from 1 when it has any `_no` column.
    pub(super) fn of_header<'a>(names: impl IntoIterator<Item = &'a str>) -> Counting {
        let mut names = names.into_iter();
        if names.any(|n| COUNTED.iter().any(|(new, _)| *new == n)) {
            Counting::FromOne
        } else {
            Counting::FromZero
        }
    }

    /// What the file's number of the 0-based index `i` is.
    pub(super) fn offset(self) -> u64 {
        match self {
            Counting::FromOne => 1,
            Counting::FromZero => 0,
        }
    }

    /// The header with every counted column named as the in-memory field it fills (`step_no`
    /// → `step`), for deserialising a row into [`StepRecord`] or [`SampleRow`].
    pub(super) fn field_names(headers: &csv::StringRecord) -> csv::StringRecord {
        headers
            .iter()
            .map(|h| {
                COUNTED
                    .iter()
                    .find(|(new, _)| *new == h)
                    .map_or(h, |(_, old)| *old)
            })
            .collect()
    }

    /// The column named as this counting names it (`field` is the in-memory name).
    pub(super) fn column(self, field: &'static str) -> &'static str {
        match self {
            Counting::FromZero => field,
            Counting::FromOne => COUNTED
                .iter()
                .find(|(_, old)| *old == field)
                .map_or(field, |(new, _)| *new),
        }
    }

    /// The file's value of column `field` as a 0-based index; a `_no` column's 0 is an error.
    pub(super) fn to_index(self, field: &'static str, value: u64) -> Result<u64, String> {
        value
            .checked_sub(self.offset())
            .ok_or_else(|| format!("{} is counted from 1 (got {value})", self.column(field)))
    }

    /// The 0-based index `i` as this counting writes it.
    pub(super) fn to_file(self, i: u64) -> u64 {
        i.saturating_add(self.offset())
    }

    /// `step_no 4` or `step 3`: a 0-based index named and numbered as the file has it, for
    /// messages about a row.
    pub(super) fn show(self, field: &'static str, i: u64) -> String {
        format!("{} {}", self.column(field), self.to_file(i))
    }
}

/// The columns of a `samples.csv` a writer appends to: its counting and whether it has `t_utc`.
/// A resume keeps appending rows of the file's own columns (it is never rewritten: it can hold
/// gigabytes), so a run an older gyrocal began keeps one format from its first row to its last.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct SampleColumns {
    pub(super) counting: Counting,
    pub(super) utc: bool,
}

impl SampleColumns {
    /// The current columns ([`SAMPLES_HEADER`]).
    pub(super) const CURRENT: SampleColumns = SampleColumns {
        counting: Counting::FromOne,
        utc: true,
    };

    /// The columns of an accepted header.
    pub(super) fn of_header(header: &[&str]) -> SampleColumns {
        SampleColumns {
            counting: Counting::of_header(header.iter().copied()),
            utc: header.contains(&"t_utc"),
        }
    }
}

/// A row of steps.csv as [`StepRecord`] (0-based). `fields` is the header through
/// [`Counting::field_names`].
pub(super) fn read_step(
    rec: &csv::StringRecord,
    fields: &csv::StringRecord,
    counting: Counting,
) -> Result<StepRecord, String> {
    let mut r: StepRecord = rec.deserialize(Some(fields)).map_err(|e| e.to_string())?;
    let series: SeriesColumns = rec.deserialize(Some(fields)).map_err(|e| e.to_string())?;
    r.series = series.cells()?;
    let step = counting.to_index("step", r.step as u64)?;
    let pass = counting.to_index("pass", u64::from(r.pass))?;
    r.step = usize::try_from(step).map_err(|e| e.to_string())?;
    r.pass = u32::try_from(pass).map_err(|e| e.to_string())?;
    Ok(r)
}

/// A row of samples.csv as [`SampleRow`] (0-based). `fields` is the header through
/// [`Counting::field_names`].
pub(super) fn read_sample(
    rec: &csv::StringRecord,
    fields: &csv::StringRecord,
    counting: Counting,
) -> Result<SampleRow, String> {
    let mut r: SampleRow = rec.deserialize(Some(fields)).map_err(|e| e.to_string())?;
    let step = counting.to_index("step", r.step as u64)?;
    r.step = usize::try_from(step).map_err(|e| e.to_string())?;
    r.index = counting.to_index("index", r.index)?;
    Ok(r)
}

/// The row of steps.csv for a (rounded) record, in the current columns ([`STEPS_HEADER`]:
/// steps.csv is always written in the current format, a resume converts an older one first).
pub(super) fn step_row<'a>(r: &StepRecord, start_utc: &'a str, end_utc: &'a str) -> StepRow<'a> {
    let c = Counting::FromOne;
    StepRow {
        step_no: c.to_file(r.step as u64),
        pass_no: c.to_file(u64::from(r.pass)),
        rate_dps: r.rate_dps,
        rate_meas_dps: r.rate_meas_dps,
        rate_meas_std_dps: r.rate_meas_std_dps,
        rate_meas_min_dps: r.rate_meas_min_dps,
        rate_meas_max_dps: r.rate_meas_max_dps,
        rate_samples: r.rate_samples,
        volts: r.volts,
        volts_std: r.volts_std,
        n: r.n,
        overloads: r.overloads,
        retries: r.retries,
        t_start_s: r.t_start_s,
        t_end_s: r.t_end_s,
        t_start_utc: start_utc,
        t_end_utc: end_utc,
        series_point: r.series.map(|c| c.series_point),
        setpoint_c: r.series.map(|c| c.setpoint_c),
        temp_min_c: r.series.and_then(|c| c.temp_min_c),
        temp_mean_c: r.series.and_then(|c| c.temp_mean_c),
        temp_max_c: r.series.and_then(|c| c.temp_max_c),
        bias_record: r.series.map(|c| u8::from(c.bias_record)),
    }
}

/// Writes one row of samples.csv in the file's own columns.
pub(super) fn write_sample(
    w: &mut csv::Writer<File>,
    row: &SampleRow,
    columns: SampleColumns,
) -> Result<(), csv::Error> {
    let step = columns.counting.to_file(row.step as u64);
    let index = columns.counting.to_file(row.index);
    let (t, rate, volts, overload) = (row.t_s, row.rate_dps, row.volts, row.overload);
    if columns.utc {
        w.serialize((step, index, t, rate, volts, overload, row.t_utc.as_deref()))
    } else {
        w.serialize((step, index, t, rate, volts, overload))
    }
}

/// Rewrites steps.csv rows written with the columns `old` for the columns `new` (which hold
/// every column of `old`, a counted one possibly renamed, see [`COUNTED`]): an empty cell for
/// each new column, and a counted column re-based when the counting changes (`step` 0 becomes
/// `step_no` 1). The rows are gyrocal's own (numbers, no quoting), so a row is one line and a
/// cell is between commas; a counted cell that is not a whole number is an error naming the
/// line.
pub(super) fn upgrade_steps(
    path: &Path,
    bytes: &[u8],
    old: &[&str],
    new: &[&str],
) -> Result<Vec<u8>, RunError> {
    let (from, to) = (
        Counting::of_header(old.iter().copied()),
        Counting::of_header(new.iter().copied()),
    );
    // for each new column: its position in the old header, and whether it is re-based
    let map: Vec<Option<(usize, bool)>> = new
        .iter()
        .map(|c| {
            let (name, counted) = match COUNTED.iter().find(|(n, o)| n == c || o == c) {
                Some(&(n, o)) => (if from == Counting::FromOne { n } else { o }, true),
                None => (*c, false),
            };
            old.iter().position(|o| *o == name).map(|i| (i, counted))
        })
        .collect();
    let mut out = new.join(",").into_bytes();
    out.push(b'\n');
    for (k, line) in bytes.split(|&b| b == b'\n').enumerate().skip(1) {
        let line = line.strip_suffix(b"\r").unwrap_or(line);
        if line.is_empty() {
            continue;
        }
        let cells: Vec<&[u8]> = line.split(|&b| b == b',').collect();
        for (j, m) in map.iter().enumerate() {
            if j > 0 {
                out.push(b',');
            }
            let Some((i, counted)) = *m else { continue };
            let Some(cell) = cells.get(i) else { continue };
            if !counted || from == to {
                out.extend_from_slice(cell);
                continue;
            }
            let column = old.get(i).copied().unwrap_or_default();
            let bad = |what: String| RunError::Csv {
                path: path.to_path_buf(),
                line: k as u64 + 1,
                message: format!("{column}: {what}"),
            };
            let v: u64 = std::str::from_utf8(cell)
                .ok()
                .and_then(|s| s.parse().ok())
                .ok_or_else(|| {
                    bad(format!(
                        "{:?} is not a whole number",
                        String::from_utf8_lossy(cell)
                    ))
                })?;
            let field = COUNTED
                .iter()
                .find(|(n, o)| *n == column || *o == column)
                .map_or("step", |(_, o)| *o);
            let i = from.to_index(field, v).map_err(bad)?;
            out.extend_from_slice(to.to_file(i).to_string().as_bytes());
        }
        out.push(b'\n');
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn the_header_tells_the_counting() {
        assert_eq!(
            Counting::of_header(SAMPLES_HEADER.iter().copied()),
            Counting::FromOne
        );
        assert_eq!(
            Counting::of_header(SAMPLES_HEADER_V2.iter().copied()),
            Counting::FromZero
        );
        assert_eq!(
            Counting::of_header(STEPS_HEADER.iter().copied()),
            Counting::FromOne
        );
        assert_eq!(
            Counting::of_header(STEPS_HEADER_V3.iter().copied()),
            Counting::FromZero
        );
        assert_eq!(Counting::FromOne.show("step", 3), "step_no 4");
        assert_eq!(Counting::FromZero.show("step", 3), "step 3");
        assert!(
            Counting::FromOne
                .to_index("pass", 0)
                .unwrap_err()
                .contains("pass_no is counted from 1")
        );
    }

    #[test]
    fn an_old_steps_file_is_upgraded_to_numbers_counted_from_one() {
        let old = b"step,pass,rate_dps,volts,n\n0,0,10,0.1,5\n4,1,-10,0.2,5\n";
        let new = [
            "step_no",
            "pass_no",
            "rate_dps",
            "rate_samples",
            "volts",
            "n",
        ];
        let up = upgrade_steps(
            Path::new("steps.csv"),
            old,
            &["step", "pass", "rate_dps", "volts", "n"],
            &new,
        )
        .unwrap();
        assert_eq!(
            String::from_utf8(up).unwrap(),
            "step_no,pass_no,rate_dps,rate_samples,volts,n\n1,1,10,,0.1,5\n5,2,-10,,0.2,5\n"
        );
        let e = upgrade_steps(
            Path::new("steps.csv"),
            b"step,pass\n0,x\n",
            &["step", "pass"],
            &["step_no", "pass_no"],
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("steps.csv:2: pass:"), "{e}");
    }
}
