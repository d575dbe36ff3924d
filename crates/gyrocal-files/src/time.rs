//! Wall-clock timestamps, formatted and parsed by hand (RFC 3339, UTC) to avoid a date crate:
//! the manifest's times, and the `t_utc` columns of the CSV files, which are the run clock's
//! `t_s` converted through the wall-clock time at which that clock was read (see
//! [`ClockAnchor`]).

use std::time::{Duration, SystemTime, UNIX_EPOCH};

/// Formats a wall-clock time as RFC 3339 UTC with milliseconds, e.g.
/// `2026-03-21T10:22:33.123Z`. Times before 1970 are clamped to the epoch.
pub fn rfc3339_utc(t: SystemTime) -> String {
    let d = t.duration_since(UNIX_EPOCH).unwrap_or_default();
    let secs = d.as_secs();
    let millis = d.subsec_millis();
    let days = i64::try_from(secs / 86_400).unwrap_or(i64::MAX / 2);
    let rem = secs % 86_400;
    let (y, m, day) = civil_from_days(days);
    format!(
        "{y:04}-{m:02}-{day:02}T{:02}:{:02}:{:02}.{millis:03}Z",
        rem / 3600,
        (rem % 3600) / 60,
        rem % 60
    )
}

/// The current wall-clock time, RFC 3339 UTC.
pub(crate) fn now_utc() -> String {
    rfc3339_utc(SystemTime::now())
}

/// Parses what [`rfc3339_utc`] writes (`YYYY-MM-DDTHH:MM:SS[.fff…]Z`, UTC only). `None` for
/// anything else: the caller decides what an unreadable time means (the report leaves out
/// the figure it would have computed).
pub fn parse_rfc3339_utc(s: &str) -> Option<SystemTime> {
    let b = s.as_bytes();
    if b.len() < 20 || b.last() != Some(&b'Z') {
        return None;
    }
    let num = |r: std::ops::Range<usize>| -> Option<u64> {
        let t = s.get(r)?;
        if t.bytes().all(|c| c.is_ascii_digit()) {
            t.parse().ok()
        } else {
            None
        }
    };
    let sep = |i: usize, c: u8| b.get(i) == Some(&c);
    if !(sep(4, b'-') && sep(7, b'-') && sep(10, b'T') && sep(13, b':') && sep(16, b':')) {
        return None;
    }
    let (y, mo, d) = (num(0..4)?, num(5..7)?, num(8..10)?);
    let (h, mi, se) = (num(11..13)?, num(14..16)?, num(17..19)?);
    if !(1..=12).contains(&mo) || !(1..=31).contains(&d) || h > 23 || mi > 59 || se > 60 {
        return None;
    }
    let frac = s.get(19..s.len() - 1)?;
    let nanos = if frac.is_empty() {
        0
    } else {
        let digits = frac.strip_prefix('.')?;
        if digits.is_empty() || digits.len() > 9 || !digits.bytes().all(|c| c.is_ascii_digit()) {
            return None;
        }
        let v: u32 = digits.parse().ok()?;
        v * 10u32.pow(9 - digits.len() as u32)
    };
    let days = days_from_civil(i64::try_from(y).ok()?, mo as u32, d as u32);
    let secs = u64::try_from(days).ok()? * 86_400 + h * 3600 + mi * 60 + se;
    UNIX_EPOCH.checked_add(Duration::new(secs, nanos))
}

/// The wall-clock time at which the run clock read `run_clock_s`: converts the run clock's
/// `t_s` (seconds, the time base of every row) to UTC as `wall + (t_s − run_clock_s)`.
///
/// A run directory sets its anchor when it is created (run clock 0) or reopened for a resume
/// (the run clock where the previous session stopped), and the sequencer may set it again when
/// it starts its clock ([`crate::RunDir::anchor_clock`]), which removes the few milliseconds
/// between opening the directory and the first reading. In a simulated run in virtual time
/// the run clock runs ahead of the wall clock, and so do the converted times: they say when a
/// real bench would have taken each reading.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClockAnchor {
    /// The wall-clock time of the reading.
    pub wall: SystemTime,
    /// The run clock at that moment, s.
    pub run_clock_s: f64,
}

impl ClockAnchor {
    /// The run clock reads `run_clock_s` now.
    pub fn now(run_clock_s: f64) -> ClockAnchor {
        ClockAnchor {
            wall: SystemTime::now(),
            run_clock_s,
        }
    }

    /// This anchor, or `floor` when `floor` puts this anchor's run clock at a later wall time:
    /// of two mappings of the run clock to UTC, the later one.
    pub fn at_least(self, floor: Option<ClockAnchor>) -> ClockAnchor {
        match floor.and_then(|f| f.wall_at(self.run_clock_s)) {
            Some(w) if w > self.wall => ClockAnchor {
                wall: w,
                run_clock_s: self.run_clock_s,
            },
            _ => self,
        }
    }

    /// The wall-clock time of `t_s` on the run clock (`None` when it does not fit a
    /// `SystemTime`, or `t_s` is not finite).
    fn wall_at(&self, t_s: f64) -> Option<SystemTime> {
        let d = t_s - self.run_clock_s;
        if d >= 0.0 {
            Duration::try_from_secs_f64(d)
                .ok()
                .and_then(|d| self.wall.checked_add(d))
        } else {
            Duration::try_from_secs_f64(-d)
                .ok()
                .and_then(|d| self.wall.checked_sub(d))
        }
    }

    /// `t_s` on the run clock as RFC 3339 UTC with milliseconds. A non-finite `t_s` (never
    /// written: the writers refuse it) gives the anchor's own time.
    pub fn utc(&self, t_s: f64) -> String {
        rfc3339_utc(self.wall_at(t_s).unwrap_or(self.wall))
    }
}

/// (year, month, day) to days since 1970-01-01 (Howard Hinnant's `days_from_civil`).
fn days_from_civil(y: i64, m: u32, d: u32) -> i64 {
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y.rem_euclid(400);
    let m = i64::from(m);
    let mp = if m > 2 { m - 3 } else { m + 9 };
    let doy = (153 * mp + 2) / 5 + i64::from(d) - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

/// Days since 1970-01-01 to (year, month, day) in the proleptic Gregorian calendar
/// (Howard Hinnant's `civil_from_days`).
fn civil_from_days(z: i64) -> (i64, u32, u32) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let y = yoe + era * 400;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = if m <= 2 { y + 1 } else { y };
    // d is in 1..=31 and m in 1..=12 by construction.
    (y, m as u32, d as u32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formats_known_instants() {
        assert_eq!(rfc3339_utc(UNIX_EPOCH), "1970-01-01T00:00:00.000Z");
        // 2000-02-29T12:34:56.789Z = 951827696.789
        let t = UNIX_EPOCH + Duration::from_millis(951_827_696_789);
        assert_eq!(rfc3339_utc(t), "2000-02-29T12:34:56.789Z");
        // 2024-12-31T23:59:59Z = 1735689599
        let t = UNIX_EPOCH + Duration::from_secs(1_735_689_599);
        assert_eq!(rfc3339_utc(t), "2024-12-31T23:59:59.000Z");
    }

    #[test]
    fn parses_what_it_writes() {
        for ms in [0u64, 951_827_696_789, 1_735_689_599_000, 1_774_088_553_123] {
            let t = UNIX_EPOCH + Duration::from_millis(ms);
            assert_eq!(parse_rfc3339_utc(&rfc3339_utc(t)), Some(t));
        }
        assert_eq!(
            parse_rfc3339_utc("2024-12-31T23:59:59Z"),
            Some(UNIX_EPOCH + Duration::from_secs(1_735_689_599))
        );
        for bad in [
            "",
            "2024-12-31 23:59:59Z",
            "2024-13-01T00:00:00Z",
            "2024-12-31T23:59:59+01:00",
            "2024-12-31T23:59:59.Z",
        ] {
            assert_eq!(parse_rfc3339_utc(bad), None, "{bad}");
        }
    }

    #[test]
    fn an_anchor_converts_the_run_clock() {
        let a = ClockAnchor {
            wall: UNIX_EPOCH + Duration::from_millis(951_827_696_789),
            run_clock_s: 100.0,
        };
        assert_eq!(a.utc(100.0), "2000-02-29T12:34:56.789Z");
        assert_eq!(a.utc(101.5), "2000-02-29T12:34:58.289Z");
        assert_eq!(a.utc(99.0), "2000-02-29T12:34:55.789Z");
    }
}
