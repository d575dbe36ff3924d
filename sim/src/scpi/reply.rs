//! Replies a simulated meter sends: the reply faults ([`ReplyFault`]: never sent, garbled,
//! cut short), a reply held back by a slow meter ([`SlowReplies`]), and readings as the meters
//! format them.

use std::time::Duration;

use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, Normal};

use super::control::Fault;

/// The value the meters send for an overload (±9.9E37).
pub const OVERLOAD: f64 = 9.9e37;

/// A fault that hits a reply.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum ReplyFault {
    /// The reply is never sent.
    NoReply,
    /// A character is replaced by `#` ([`garbled`]).
    Garble,
    /// The reply stops halfway, without its terminator.
    Truncate,
}

impl ReplyFault {
    /// The reply fault `fault` is, if it is one.
    pub(crate) fn of(fault: &Fault) -> Option<ReplyFault> {
        match fault {
            Fault::NoReply => Some(ReplyFault::NoReply),
            Fault::Garble => Some(ReplyFault::Garble),
            Fault::Truncate => Some(ReplyFault::Truncate),
            _ => None,
        }
    }

    /// `bytes` as they leave the meter with this fault, and whether the rest of the reply is
    /// lost with it (nothing more of it may be sent).
    pub(crate) fn apply(self, bytes: &[u8]) -> (Vec<u8>, bool) {
        match self {
            ReplyFault::NoReply => (Vec::new(), true),
            ReplyFault::Garble => (garbled(bytes).into_bytes(), false),
            ReplyFault::Truncate => (bytes[..bytes.len().div_ceil(2)].to_vec(), true),
        }
    }
}

/// `bytes` with the second digit (or the first, or the first byte) replaced by `#`.
pub(crate) fn garbled(bytes: &[u8]) -> String {
    let mut b = bytes.to_vec();
    let mut digits = b
        .iter()
        .enumerate()
        .filter(|(_, c)| c.is_ascii_digit())
        .map(|(i, _)| i);
    let first = digits.next();
    let i = digits.next().or(first).unwrap_or(0);
    if let Some(c) = b.get_mut(i) {
        *c = b'#';
    }
    String::from_utf8_lossy(&b).into_owned()
}

/// A [`Fault::Slow`] in force: how late replies are, and how many more it holds back
/// (`None`: every one).
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct SlowReplies(Option<(Duration, Option<u32>)>);

impl SlowReplies {
    /// Holds back the next `replies` replies (`None`: every one; `Some(0)`: none) by `delay`
    /// (already scaled to the simulator's time).
    pub(crate) fn set(&mut self, delay: Duration, replies: Option<u32>) {
        self.0 = (replies != Some(0)).then_some((delay, replies));
    }

    /// Whether replies are held back now.
    pub(crate) fn is_active(&self) -> bool {
        self.0.is_some()
    }

    /// Counts `replies` replies held back, and returns the delay they get (`None` when the
    /// fault is not in force).
    pub(crate) fn hold(&mut self, replies: u64) -> Option<Duration> {
        let (delay, left) = self.0.as_mut()?;
        let delay = *delay;
        if let Some(n) = left {
            *n = n.saturating_sub(u32::try_from(replies).unwrap_or(u32::MAX));
            if *n == 0 {
                self.0 = None;
            }
        }
        Some(delay)
    }
}

/// The delay of a [`Fault::Slow`], sim seconds bounded to what a `Duration` holds.
pub(crate) fn slow_delay(delay_s: f64) -> Duration {
    Duration::from_secs_f64(delay_s.clamp(0.0, 1e6))
}

/// The input a meter reads: the signal plus seeded gaussian noise, clipped to overloads.
pub(crate) struct Noise {
    rng: StdRng,
    normal: Option<Normal<f64>>,
}

impl Noise {
    /// Noise of standard deviation `sigma_v` (none when 0), seeded.
    pub(crate) fn new(sigma_v: f64, seed: u64) -> Self {
        Noise {
            rng: StdRng::seed_from_u64(seed),
            normal: (sigma_v > 0.0)
                .then(|| Normal::new(0.0, sigma_v).ok())
                .flatten(),
        }
    }

    /// `v` plus one sample of the noise.
    pub(crate) fn add(&mut self, v: f64) -> f64 {
        match &self.normal {
            Some(n) => v + n.sample(&mut self.rng),
            None => v,
        }
    }
}

/// The reading a meter on `range` (`None`: autorange, up to 1000 V) makes of `v` volts: an
/// overload (±9.9E37) beyond 1.2 × the range, or when `forced` (a [`Fault::Overload`]), or
/// for anything not finite.
pub(crate) fn clip(v: f64, range: Option<f64>, forced: bool) -> f64 {
    let limit = 1.2 * range.unwrap_or(1000.0);
    if forced || !v.is_finite() || v.abs() > limit {
        if v < 0.0 { -OVERLOAD } else { OVERLOAD }
    } else {
        v
    }
}

/// Formats a reading the way the meters send it: `SD.DDDDDDDDESDD` (15 characters),
/// overloads `+9.90000000E+37` (or negative).
pub fn format_reading(v: f64) -> String {
    if !v.is_finite() || v.abs() >= OVERLOAD {
        return if v < 0.0 {
            "-9.90000000E+37".into()
        } else {
            "+9.90000000E+37".into()
        };
    }
    format_nr3(v)
}

/// NR3 with 8 decimals and a signed two-digit exponent: `+1.00010310E+01`.
pub(crate) fn format_nr3(v: f64) -> String {
    let s = format!("{:.8E}", v.abs());
    let (mant, exp) = s.split_once('E').unwrap_or((s.as_str(), "0"));
    let exp: i32 = exp.parse().unwrap_or(0);
    let sign = if v.is_sign_negative() && v != 0.0 {
        '-'
    } else {
        '+'
    };
    let esign = if exp < 0 { '-' } else { '+' };
    format!("{sign}{mant}E{esign}{:02}", exp.abs())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reply_faults_as_the_host_sees_them() {
        let reply = b"+1.00010310E+01\r\n";
        assert_eq!(ReplyFault::NoReply.apply(reply), (Vec::new(), true));
        let (garbled, muted) = ReplyFault::Garble.apply(reply);
        assert_eq!(garbled, b"+1.#0010310E+01\r\n");
        assert!(!muted);
        let (cut, muted) = ReplyFault::Truncate.apply(reply);
        assert_eq!(cut, b"+1.000103");
        assert!(muted);
        assert_eq!(ReplyFault::of(&Fault::Disconnect), None);
    }

    #[test]
    fn a_slow_fault_holds_back_the_replies_it_was_given() {
        let mut slow = SlowReplies::default();
        assert_eq!(slow.hold(1), None);
        slow.set(Duration::from_secs(2), Some(2));
        assert_eq!(slow.hold(1), Some(Duration::from_secs(2)));
        assert!(slow.is_active());
        assert_eq!(slow.hold(1), Some(Duration::from_secs(2)));
        assert!(!slow.is_active());
        slow.set(Duration::from_secs(2), Some(0));
        assert!(!slow.is_active());
        slow.set(Duration::from_secs(1), None);
        for _ in 0..100 {
            assert_eq!(slow.hold(3), Some(Duration::from_secs(1)));
        }
    }

    #[test]
    fn overloads() {
        assert_eq!(clip(12.5, Some(10.0), false), OVERLOAD);
        assert_eq!(clip(-12.5, Some(10.0), false), -OVERLOAD);
        assert_eq!(clip(11.9, Some(10.0), false), 11.9);
        assert_eq!(clip(-0.5, Some(10.0), true), -OVERLOAD);
        assert_eq!(clip(f64::NAN, None, false), OVERLOAD);
        assert_eq!(clip(999.0, None, false), 999.0);
    }

    /// Moved from the 34401A simulator: both meters format readings with it.
    #[test]
    fn reading_format() {
        assert_eq!(format_reading(10.001031), "+1.00010310E+01");
        assert_eq!(format_reading(0.0), "+0.00000000E+00");
        assert_eq!(format_reading(-1.5e-3), "-1.50000000E-03");
        assert_eq!(format_reading(OVERLOAD), "+9.90000000E+37");
        assert_eq!(format_reading(-OVERLOAD), "-9.90000000E+37");
        for v in [1.0, -123.456, 9.99999999e-9, 1000.0] {
            assert_eq!(format_reading(v).len(), 15, "{v}");
        }
        assert_eq!(format_reading(f64::INFINITY), "+9.90000000E+37");
    }

    #[test]
    fn seeded_noise_repeats() {
        let mut a = Noise::new(1e-6, 7);
        let mut b = Noise::new(1e-6, 7);
        let xa: Vec<f64> = (0..5).map(|_| a.add(1.0)).collect();
        let xb: Vec<f64> = (0..5).map(|_| b.add(1.0)).collect();
        assert_eq!(xa, xb);
        assert!(xa.iter().all(|x| (x - 1.0).abs() < 1e-5 && *x != 1.0));
        assert_eq!(Noise::new(0.0, 7).add(1.0), 1.0);
    }
}
