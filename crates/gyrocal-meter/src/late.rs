//! A meter seen answering late: how much every reply deadline is widened by, and what the
//! operator is told. The same for every meter driver, so written once.
//!
//! A driver that gave up on a reply waits a little longer for it (its own
//! `late_reply_wait`); when it comes, the meter is alive but slow, and [`LateReplies::saw`]
//! widens every later deadline by twice what came on top of the deadline already missed (which
//! held the driver's slack and the widening so far), at most the driver's `max_reply_delay`.

use std::time::Duration;

/// The widening of a meter's reply deadlines after late replies.
#[derive(Debug, Clone)]
pub struct LateReplies {
    /// Added to every reply deadline.
    reply_delay: Duration,
    /// The latest a late reply came after its deadline, if one did.
    latest_seen: Option<Duration>,
    /// The most the deadlines are widened by.
    max: Duration,
    /// The driver's slack on every deadline.
    slack: Duration,
    /// The option that sets `max`, named in messages (`DriverOptions::max_reply_delay`).
    max_option: &'static str,
}

impl LateReplies {
    /// No late reply seen yet.
    pub fn new(max: Duration, slack: Duration, max_option: &'static str) -> Self {
        LateReplies {
            reply_delay: Duration::ZERO,
            latest_seen: None,
            max,
            slack,
            max_option,
        }
    }

    /// What every reply deadline is widened by (zero for a meter that answers in time).
    pub fn reply_delay(&self) -> Duration {
        self.reply_delay
    }

    /// A late reply came `late` after its deadline: widens the deadlines and returns the
    /// sentence for the operator and the run's manifest.
    pub fn saw(&mut self, late: Duration) -> String {
        self.latest_seen = Some(self.latest_seen.map_or(late, |l| l.max(late)));
        let widened = ((self.reply_delay + late + self.slack) * 2).min(self.max);
        self.reply_delay = self.reply_delay.max(widened);
        format!(
            "the meter answers slowly: the reply came {:.1} s after its deadline and was thrown \
             away; reply deadlines widened by {:.1} s",
            late.as_secs_f64(),
            self.reply_delay.as_secs_f64()
        )
    }

    /// For an error that gives up: what was seen of a slow meter, or nothing.
    pub fn note(&self) -> String {
        match self.latest_seen {
            Some(late) => format!(
                "; the meter answers slowly: a reply came {:.1} s after its deadline, and \
                 deadlines were widened by {:.1} s (at most {:.1} s, {})",
                late.as_secs_f64(),
                self.reply_delay.as_secs_f64(),
                self.max.as_secs_f64(),
                self.max_option
            ),
            None => String::new(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn deadlines_widen_by_twice_the_lateness_within_the_bound() {
        let mut l = LateReplies::new(
            Duration::from_secs(5),
            Duration::from_millis(100),
            "Options::max_reply_delay",
        );
        assert!(l.note().is_empty());
        let said = l.saw(Duration::from_millis(900));
        assert_eq!(l.reply_delay(), Duration::from_secs(2));
        assert!(
            said.contains("0.9 s after its deadline") && said.contains("2.0 s"),
            "{said}"
        );
        // a second late reply on top of the widening: capped at the bound
        l.saw(Duration::from_secs(1));
        assert_eq!(l.reply_delay(), Duration::from_secs(5));
        assert!(l.note().contains("at most 5.0 s, Options::max_reply_delay"));
    }
}
