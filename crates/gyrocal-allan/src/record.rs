//! A rate record held as its cumulative sum (the phase), and parsing one from text.

use std::io::Read;

use crate::error::{Error, Result};
use crate::sum::{Neumaier, mean};

/// A rate (frequency-like) record `y[0..N]` at a fixed sample interval τ0, stored as the prefix
/// sums of `y − ȳ`: `P[0] = 0`, `P[k] = Σ_{i<k} (y[i] − ȳ)`, `k = 0..=N`.
///
/// `τ0·P` is exactly allantools' `frequency2phase(y)` (mean removed, cumsum, leading zero), so every
/// estimator is a difference of `P` values. The prefix sums are formed with a Neumaier-compensated
/// running sum after subtracting the (compensated) mean, so each `P[k]` is the correctly rounded
/// partial sum and a window sum `P[a+m] − P[a]` carries an absolute error of about ε·|P| ≈
/// ε·σ_y·√N, not ε·|ȳ|·N as a naive cumulative sum of the raw values would.
///
/// Memory: N+1 f64. [`Record::from_vec`] converts the caller's vector in place (no second copy),
/// which is how 10⁸ samples fit in well under 1 GiB.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Record {
    tau0_s: f64,
    mean: f64,
    #[serde(skip)]
    prefix: Vec<f64>,
}

pub(crate) fn check_tau0(tau0_s: f64) -> Result<()> {
    if !tau0_s.is_finite() || tau0_s <= 0.0 {
        return Err(Error::InvalidParameter {
            name: "sample interval tau0_s",
            value: tau0_s,
            why: "must be finite and > 0",
        });
    }
    Ok(())
}

fn check_values(values: &[f64]) -> Result<()> {
    if values.is_empty() {
        return Err(Error::Empty);
    }
    if let Some((index, &value)) = values.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(Error::NonFinite { index, value });
    }
    Ok(())
}

impl Record {
    /// A record from rate samples `values` taken every `tau0_s` seconds; the vector is turned into
    /// the prefix sums in place (one extra element is pushed).
    ///
    /// Errors: [`Error::Empty`], [`Error::NonFinite`] (with the index of the first bad sample),
    /// [`Error::InvalidParameter`] for τ0 ≤ 0 or non-finite.
    pub fn from_vec(mut values: Vec<f64>, tau0_s: f64) -> Result<Record> {
        check_tau0(tau0_s)?;
        check_values(&values)?;
        let mean = mean(&values);
        let mut acc = Neumaier::default();
        for v in values.iter_mut() {
            acc.add(*v - mean);
            *v = acc.value();
        }
        values.reserve_exact(1);
        values.insert(0, 0.0);
        Ok(Record {
            tau0_s,
            mean,
            prefix: values,
        })
    }

    /// A record from a slice of rate samples (copied once into the prefix sums).
    pub fn from_slice(values: &[f64], tau0_s: f64) -> Result<Record> {
        check_tau0(tau0_s)?;
        check_values(values)?;
        let mean = mean(values);
        let mut prefix = Vec::with_capacity(values.len() + 1);
        prefix.push(0.0);
        let mut acc = Neumaier::default();
        for &v in values {
            acc.add(v - mean);
            prefix.push(acc.value());
        }
        Ok(Record {
            tau0_s,
            mean,
            prefix,
        })
    }

    /// Parses a record from CSV-like text: one sample per line, either `value` or `time,value`
    /// (time in seconds; further columns are ignored). Separators: comma, semicolon, tab or
    /// spaces. Blank lines and lines starting with `#` are skipped; a first line that is not
    /// numeric is taken as a header. Lines are read by gyrocal's CSV reader's line layer
    /// (`gyrocal_csv::Lines`): at most 1 MiB a line (a longer one, or an input without
    /// newlines, is an [`Error::Parse`] naming the line after reading at most that much), a
    /// UTF-8 byte-order mark at the start skipped.
    ///
    /// With a time column, τ0 is the median time step and every step must lie within ±10 %
    /// of it (a gap or a jump is an [`Error::Parse`] naming the line: Allan variances need evenly
    /// spaced samples). Without a time column `tau0_s` must be given; when both are present the
    /// given `tau0_s` wins and the times are still checked against it.
    pub fn from_reader<R: Read>(reader: R, tau0_s: Option<f64>) -> Result<Record> {
        let mut lines = gyrocal_csv::Lines::new(reader, "record");
        let mut times: Vec<f64> = Vec::new();
        let mut values: Vec<f64> = Vec::new();
        let mut lines_of: Vec<usize> = Vec::new();
        let mut columns: Option<usize> = None;
        let mut seen_data_line = false;
        loop {
            let (lineno, bytes) = match lines.next_line() {
                Ok(Some(l)) => l,
                Ok(None) => break,
                Err(gyrocal_csv::Error::Read { source, .. }) => return Err(Error::Io(source)),
                Err(e) => {
                    return Err(Error::Parse {
                        line: e.line().unwrap_or(1) as usize,
                        msg: e.detail(),
                    });
                }
            };
            let lineno = lineno as usize;
            let line = std::str::from_utf8(bytes).map_err(|_| Error::Parse {
                line: lineno,
                msg: "not valid UTF-8".into(),
            })?;
            let t = line.trim();
            if t.is_empty() || t.starts_with('#') {
                continue;
            }
            // the first two numbers and how many there are, without a vector per line
            let (mut first, mut second, mut count, mut all_numbers) = (0.0, 0.0, 0usize, true);
            for f in t.split([',', ';', '\t', ' ']).filter(|f| !f.is_empty()) {
                match f.parse::<f64>() {
                    Ok(v) => {
                        match count {
                            0 => first = v,
                            1 => second = v,
                            _ => {}
                        }
                        count += 1;
                    }
                    Err(_) => {
                        all_numbers = false;
                        break;
                    }
                }
            }
            if !(all_numbers && count > 0) {
                if !seen_data_line {
                    seen_data_line = true; // header
                    continue;
                }
                return Err(Error::Parse {
                    line: lineno,
                    msg: format!("not a number in {t:?}"),
                });
            }
            seen_data_line = true;
            let cols = *columns.get_or_insert(count.min(2));
            if count < cols {
                return Err(Error::Parse {
                    line: lineno,
                    msg: format!("expected {cols} columns, found {count}"),
                });
            }
            let (time, value) = if cols == 1 {
                (None, first)
            } else {
                (Some(first), second)
            };
            if let Some(tv) = time {
                if !tv.is_finite() {
                    return Err(Error::Parse {
                        line: lineno,
                        msg: "time is not finite".into(),
                    });
                }
                times.push(tv);
            }
            if !value.is_finite() {
                return Err(Error::Parse {
                    line: lineno,
                    msg: format!("value is not finite ({value})"),
                });
            }
            values.push(value);
            lines_of.push(lineno);
        }
        if values.is_empty() {
            return Err(Error::Empty);
        }
        let tau0 = match (tau0_s, times.len()) {
            (Some(t), _) => t,
            (None, 0) => {
                return Err(Error::InvalidParameter {
                    name: "sample interval tau0_s",
                    value: f64::NAN,
                    why: "value-only input needs the sample interval",
                });
            }
            (None, n) if n < 2 => {
                return Err(Error::TooShort {
                    what: "deriving τ0 from a time column",
                    needed: 2,
                    got: n,
                });
            }
            (None, _) => {
                let mut steps: Vec<f64> = times.windows(2).map(|w| w[1] - w[0]).collect();
                steps.sort_by(f64::total_cmp);
                steps[steps.len() / 2]
            }
        };
        check_tau0(tau0)?;
        for (k, w) in times.windows(2).enumerate() {
            let dt = w[1] - w[0];
            if (dt - tau0).abs() > 0.1 * tau0 {
                return Err(Error::Parse {
                    line: lines_of[k + 1],
                    msg: format!(
                        "time step {dt} s differs from the sample interval {tau0} s by more than 10 % (gap or jump)"
                    ),
                });
            }
        }
        Record::from_vec(values, tau0)
    }

    /// Sample interval τ0 in seconds.
    pub fn tau0_s(&self) -> f64 {
        self.tau0_s
    }

    /// Number of rate samples N.
    pub fn len(&self) -> usize {
        self.prefix.len() - 1
    }

    /// Always false (a record holds at least one sample).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Mean of the rate samples (the bias, in the samples' unit).
    pub fn mean(&self) -> f64 {
        self.mean
    }

    /// Record length T = N·τ0 in seconds.
    pub fn duration_s(&self) -> f64 {
        self.len() as f64 * self.tau0_s
    }

    /// The prefix sums `P[0..=N]` of `y − ȳ` (phase divided by τ0).
    pub fn prefix(&self) -> &[f64] {
        &self.prefix
    }

    /// Means of consecutive non-overlapping windows of `window` samples (the last partial window
    /// is dropped), in the samples' unit.
    pub fn window_means(&self, window: usize) -> Vec<f64> {
        if window == 0 {
            return Vec::new();
        }
        let p = &self.prefix;
        (0..self.len() / window)
            .map(|k| (p[(k + 1) * window] - p[k * window]) / window as f64 + self.mean)
            .collect()
    }
}
