//! The analytic rate profile: acceleration-limited (optionally jerk-limited) ramps without
//! overshoot, evaluated in closed form at any instant so virtual time stays exact and cheap.

/// One ramp from `w0` at sim time `t0` to `target`, then a hold at `target`.
///
/// Without a jerk limit the acceleration is a step (`a` during the ramp). With a jerk limit `j`
/// the acceleration rises at `j`, holds at `a` (or peaks lower on a short ramp) and falls at `j`:
/// an S-curve, point-symmetric about its middle, so the displacement over the whole ramp is
/// `|Δω|·T/2` exactly.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Segment {
    /// Sim time of the start, s.
    pub t0: f64,
    /// Unwrapped position at the start, degrees.
    pub p0: f64,
    /// Rate at the start, deg/s.
    pub w0: f64,
    /// Rate at the end, deg/s.
    pub target: f64,
    /// Acceleration limit, deg/s² (> 0).
    pub accel: f64,
    /// Jerk limit, deg/s³, if any.
    pub jerk: Option<f64>,
}

impl Segment {
    /// A hold at rate `w` from `t0`.
    pub fn hold(t0: f64, p0: f64, w: f64) -> Self {
        Segment {
            t0,
            p0,
            w0: w,
            target: w,
            accel: 1.0,
            jerk: None,
        }
    }

    fn delta(&self) -> f64 {
        (self.target - self.w0).abs()
    }

    fn sign(&self) -> f64 {
        if self.target >= self.w0 { 1.0 } else { -1.0 }
    }

    /// (jerk phase duration, constant-acceleration duration, peak acceleration).
    fn shape(&self) -> (f64, f64, f64) {
        let d = self.delta();
        let a = self.accel;
        match self.jerk {
            Some(j) if j > 0.0 && j.is_finite() => {
                if d >= a * a / j {
                    (a / j, d / a - a / j, a)
                } else {
                    let tj = (d / j).sqrt();
                    (tj, 0.0, j * tj)
                }
            }
            _ => (0.0, d / a, a),
        }
    }

    /// Ramp duration, s.
    pub fn duration(&self) -> f64 {
        let (tj, tc, _) = self.shape();
        2.0 * tj + tc
    }

    /// Sim time at which the ramp ends.
    pub fn end(&self) -> f64 {
        self.t0 + self.duration()
    }

    /// (rate gained, displacement beyond `w0·τ`) after `tau` seconds, both along `sign`.
    fn progress(&self, tau: f64) -> (f64, f64) {
        let d = self.delta();
        if d == 0.0 || tau <= 0.0 {
            return (0.0, 0.0);
        }
        let (tj, tc, ap) = self.shape();
        let total = 2.0 * tj + tc;
        if tau >= total {
            return (d, d * total / 2.0 + d * (tau - total));
        }
        let j = if tj > 0.0 { ap / tj } else { 0.0 };
        if tau < tj {
            (j * tau * tau / 2.0, j * tau.powi(3) / 6.0)
        } else if tau < tj + tc {
            let u = tau - tj;
            let r1 = j * tj * tj / 2.0;
            (
                r1 + ap * u,
                j * tj.powi(3) / 6.0 + r1 * u + ap * u * u / 2.0,
            )
        } else {
            let s = total - tau;
            (
                d - j * s * s / 2.0,
                d * total / 2.0 - (d * s - j * s.powi(3) / 6.0),
            )
        }
    }

    /// Profile rate at sim time `t`, deg/s.
    pub fn rate(&self, t: f64) -> f64 {
        self.w0 + self.sign() * self.progress(t - self.t0).0
    }

    /// Unwrapped position at sim time `t`, degrees.
    pub fn position(&self, t: f64) -> f64 {
        let tau = (t - self.t0).max(0.0);
        self.p0 + self.w0 * tau + self.sign() * self.progress(tau).1
    }

    /// The first sim time at which |rate| ≥ `threshold`, if the segment ever gets there.
    pub fn first_crossing(&self, threshold: f64) -> Option<f64> {
        if self.w0.abs() >= threshold {
            return Some(self.t0);
        }
        if self.target.abs() < threshold {
            return None;
        }
        // The rate is monotonic along the ramp; it leaves (−thr, thr) on the target's side.
        let level = threshold.copysign(self.target);
        let (mut lo, mut hi) = (0.0_f64, self.duration());
        for _ in 0..100 {
            let mid = 0.5 * (lo + hi);
            if (self.rate(self.t0 + mid) - level) * self.sign() >= 0.0 {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        Some(self.t0 + hi)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn numeric_position(s: &Segment, t: f64) -> f64 {
        let n = 20_000;
        let h = (t - s.t0) / n as f64;
        let mut acc = 0.0;
        for i in 0..n {
            acc += s.rate(s.t0 + (i as f64 + 0.5) * h) * h;
        }
        s.p0 + acc
    }

    #[test]
    fn table_profile_trapezoid_and_s_curve_integrate_exactly() {
        for jerk in [None, Some(20.0), Some(1.0)] {
            let s = Segment {
                t0: 1.0,
                p0: 10.0,
                w0: -5.0,
                target: 15.0,
                accel: 4.0,
                jerk,
            };
            assert!((s.rate(s.end()) - 15.0).abs() < 1e-9);
            assert_eq!(s.rate(0.0), -5.0);
            let mut prev = s.rate(s.t0);
            for i in 1..200 {
                let r = s.rate(s.t0 + i as f64 * s.duration() / 150.0);
                assert!(
                    r >= prev - 1e-12 && r <= 15.0 + 1e-12,
                    "monotonic, no overshoot"
                );
                prev = r;
            }
            for t in [1.5, 3.0, s.end(), s.end() + 2.0] {
                let exact = s.position(t);
                assert!(
                    (exact - numeric_position(&s, t)).abs() < 1e-4,
                    "{jerk:?} {t}"
                );
            }
            let tc = s.first_crossing(10.0).unwrap();
            assert!((s.rate(tc) - 10.0).abs() < 1e-9);
        }
        let plain = Segment {
            t0: 0.0,
            p0: 0.0,
            w0: 0.0,
            target: -20.0,
            accel: 5.0,
            jerk: None,
        };
        assert_eq!(plain.duration(), 4.0);
        assert!((plain.rate(2.0) + 10.0).abs() < 1e-12);
        assert!((plain.first_crossing(10.0).unwrap() - 2.0).abs() < 1e-9);
        assert_eq!(plain.first_crossing(25.0), None);
    }
}
