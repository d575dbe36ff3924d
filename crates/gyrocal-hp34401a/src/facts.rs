//! The 34401A's facts (from its manual, `shared/docs/hp34401a.md`), with no I/O: built without
//! the `driver` feature too, so the synchronous plan crate checks a plan against them and
//! keeps no copy of its own.

/// The legal integration times in power-line cycles. The meter rejects anything else (-222).
pub const NPLC_VALUES: [f64; 5] = [0.02, 0.2, 1.0, 10.0, 100.0];

/// The DC voltage ranges, in volts.
pub const RANGES: [f64; 5] = [0.1, 1.0, 10.0, 100.0, 1000.0];

/// The power-line frequencies it integrates over, Hz.
pub const LINE_HZ: [u32; 2] = [50, 60];

/// The calibration period a DC voltage accuracy applies to (the manual's three columns).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SpecPeriod {
    /// 24 hours after calibration, 23 °C ± 1 °C.
    Hours24,
    /// 90 days after calibration, T_cal ± 5 °C.
    Days90,
    /// One year after calibration, T_cal ± 5 °C.
    Year1,
}

impl SpecPeriod {
    /// Every period, shortest first.
    pub const ALL: [SpecPeriod; 3] = [SpecPeriod::Hours24, SpecPeriod::Days90, SpecPeriod::Year1];

    /// The period in words (`24 hours`, `90 days`, `1 year`).
    pub fn name(self) -> &'static str {
        match self {
            SpecPeriod::Hours24 => "24 hours",
            SpecPeriod::Days90 => "90 days",
            SpecPeriod::Year1 => "1 year",
        }
    }
}

/// DC voltage accuracy `±(% of reading + % of range)` by range (V) and period, from the
/// 34401A User's Guide specifications (DC characteristics; 6½ digits, NPLC ≥ 10 (slow),
/// autozero on, after a one-hour warm-up). The 10 V row is also in
/// `shared/docs/records.md`; every row's full-scale sum equals the service guide's gain
/// verification limits (100 mV: ±6/7.5/8.5 µV; 1 V: ±26/37/47 µV; 10 V: ±190/250/400 µV;
/// 100 V: ±2.6/4.1/5.1 mV; 1000 V: ±26/45/55 mV), which the tests check.
const DCV_ACCURACY: [(f64, [(f64, f64); 3]); 5] = [
    (0.1, [(0.0030, 0.0030), (0.0040, 0.0035), (0.0050, 0.0035)]),
    (1.0, [(0.0020, 0.0006), (0.0030, 0.0007), (0.0040, 0.0007)]),
    (10.0, [(0.0015, 0.0004), (0.0020, 0.0005), (0.0035, 0.0005)]),
    (
        100.0,
        [(0.0020, 0.0006), (0.0035, 0.0006), (0.0045, 0.0006)],
    ),
    (
        1000.0,
        [(0.0020, 0.0006), (0.0035, 0.0010), (0.0045, 0.0010)],
    ),
];

/// The DC voltage accuracy on range `range_v` (one of [`RANGES`], V) for `period`, as
/// `(gain % of reading, offset % of range)`; `None` for any other range.
///
/// For an uncertainty budget the two terms act differently: the gain is a relative error of
/// every reading (so of a scale factor), the offset a constant error (so of a bias).
///
/// ```
/// use gyrocal_hp34401a::facts::{SpecPeriod, dcv_accuracy};
/// assert_eq!(dcv_accuracy(10.0, SpecPeriod::Year1), Some((0.0035, 0.0005)));
/// assert_eq!(dcv_accuracy(5.0, SpecPeriod::Year1), None);
/// ```
pub fn dcv_accuracy(range_v: f64, period: SpecPeriod) -> Option<(f64, f64)> {
    let column = match period {
        SpecPeriod::Hours24 => 0,
        SpecPeriod::Days90 => 1,
        SpecPeriod::Year1 => 2,
    };
    DCV_ACCURACY
        .iter()
        .find(|(r, _)| (range_v - r).abs() <= 1e-9 * r)
        .map(|(_, cols)| cols[column])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ten_volt_row_is_the_records_doc() {
        assert_eq!(
            dcv_accuracy(10.0, SpecPeriod::Hours24),
            Some((0.0015, 0.0004))
        );
        assert_eq!(
            dcv_accuracy(10.0, SpecPeriod::Days90),
            Some((0.0020, 0.0005))
        );
        assert_eq!(
            dcv_accuracy(10.0, SpecPeriod::Year1),
            Some((0.0035, 0.0005))
        );
    }

    #[test]
    fn full_scale_sums_are_the_service_guide_gain_verification_limits() {
        // Error from nominal at a full-scale input, volts: 24 h, 90 d, 1 y.
        let limits = [
            (0.1, [6e-6, 7.5e-6, 8.5e-6]),
            (1.0, [26e-6, 37e-6, 47e-6]),
            (10.0, [190e-6, 250e-6, 400e-6]),
            (100.0, [2.6e-3, 4.1e-3, 5.1e-3]),
            (1000.0, [26e-3, 45e-3, 55e-3]),
        ];
        for (range, volts) in limits {
            for (period, limit) in SpecPeriod::ALL.into_iter().zip(volts) {
                let Some((gain, offset)) = dcv_accuracy(range, period) else {
                    panic!("{range} V {}: no accuracy", period.name());
                };
                let sum = (gain + offset) / 100.0 * range;
                assert!(
                    (sum - limit).abs() <= 1e-9 * limit,
                    "{range} V {}: {sum} V vs {limit} V",
                    period.name()
                );
            }
        }
        assert_eq!(RANGES.len(), DCV_ACCURACY.len());
        for r in RANGES {
            assert!(dcv_accuracy(r, SpecPeriod::Year1).is_some());
        }
        assert_eq!(dcv_accuracy(3.0, SpecPeriod::Year1), None);
    }
}
