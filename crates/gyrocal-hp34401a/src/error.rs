//! Driver errors, with the meter role's [`ErrorKind`] so the sequencer can decide what to do.
//! The error-queue entry ([`InstrumentError`]) and the kinds are the role's (`gyrocal-meter`),
//! shared with the Truevolt driver.

use gyrocal_link::{LinkError, show_bytes};
use gyrocal_meter::scpi::list;
pub use gyrocal_meter::{ErrorKind, InstrumentError};

/// An error from the driver.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The link failed (timeout, disconnect, garbled line, I/O).
    #[error(transparent)]
    Link(#[from] LinkError),
    /// `*IDN?` did not name a 34401A.
    #[error("{device}: not an HP 34401A: *IDN? answered {}", show_bytes(reply.as_bytes()))]
    NotA34401A {
        /// The link.
        device: String,
        /// What the device answered.
        reply: String,
    },
    /// An invalid configuration or request, refused before anything was sent.
    #[error("invalid configuration: {0}")]
    Config(String),
    /// The meter's error queue was not empty where it had to be.
    #[error("{device}: the meter reported {} after {context}", list(errors))]
    Instrument {
        /// The link.
        device: String,
        /// What the driver had just done.
        context: String,
        /// Every entry read from the queue, oldest first.
        errors: Vec<InstrumentError>,
    },
    /// A reply that is not what the protocol allows at this point.
    #[error("{device}: expected {expected}, got {}", show_bytes(bytes))]
    InvalidReply {
        /// The link.
        device: String,
        /// What was expected (`"a reading"`, `"1 from *OPC?"`...).
        expected: &'static str,
        /// The bytes received.
        bytes: Vec<u8>,
    },
    /// A reply line held a different number of readings than asked for.
    #[error("{device}: expected {expected} readings, the reply held {got}")]
    WrongCount {
        /// The link.
        device: String,
        /// Readings asked for.
        expected: usize,
        /// Readings received before the line ended (or before the surplus was noticed).
        got: usize,
    },
    /// An operation that needs `configure()` first.
    #[error("the meter is not configured: call configure() first")]
    NotConfigured,
    /// The meter stopped answering (or came back from a power cycle and still did not answer)
    /// and the driver gave up re-establishing the link after `waited`.
    #[error(
        "{device}: the multimeter did not come back within {}: is it powered and connected? \
         (last attempt: {last}){slow}",
        seconds(*waited)
    )]
    NotBack {
        /// The link.
        device: String,
        /// How long the driver kept trying (about [`crate::DriverOptions::reconnect_timeout`]).
        waited: std::time::Duration,
        /// Empty, or what the driver saw earlier of a meter that answers late (`; the meter
        /// answers slowly: ...`): replies later than the widened deadlines count as none.
        slow: String,
        /// The last attempt's error.
        #[source]
        last: Box<Error>,
    },
    /// [`crate::Hp34401a::fetch`] (or `wait_burst`) of a burst armed before the link was
    /// re-established: the meter's memory was cleared (it came back from a power cycle, or was
    /// found in LOCAL and reconfigured), so its readings are gone; the driver sends nothing.
    #[error(
        "{device}: the multimeter's memory was cleared since the burst of {count} readings was \
         armed ({cause}): the burst must be measured again"
    )]
    ReadingsLost {
        /// The link.
        device: String,
        /// Readings the lost burst held.
        count: usize,
        /// What cleared the memory: a power cycle, or gyrocal's own reconfiguration after the
        /// meter did not answer (see [`crate::LinkLoss::memory_cause`]).
        cause: String,
    },
    /// Recovery was tried `attempts - 1` times and the last attempt failed too.
    #[error("{device}: gave up after {attempts} attempts{slow}: {last}")]
    GaveUp {
        /// The link.
        device: String,
        /// Attempts made, the first included.
        attempts: u32,
        /// Empty, or what the driver saw of a meter that answers late (`; the meter answers
        /// slowly: ...`), so the message names the real cause.
        slow: String,
        /// The last attempt's error.
        #[source]
        last: Box<Error>,
    },
}

/// `30 s`, `2.5 s`.
fn seconds(d: std::time::Duration) -> String {
    let s = d.as_secs_f64();
    if (s - s.round()).abs() < 0.05 {
        format!("{:.0} s", s)
    } else {
        format!("{s:.1} s")
    }
}

impl Error {
    /// The kind of this error (for [`Error::GaveUp`], the kind of the last attempt's error),
    /// with the driver's detail: [`ErrorKind::Identity`], [`ErrorKind::Config`] and
    /// [`ErrorKind::Io`] are told apart here (the role reports them as
    /// [`ErrorKind::Other`]: [`gyrocal_meter::MeterError::kind`]).
    pub fn kind(&self) -> ErrorKind {
        match self {
            Error::Link(e) => match e.kind() {
                gyrocal_link::ErrorKind::Timeout => ErrorKind::Timeout,
                gyrocal_link::ErrorKind::Disconnected => ErrorKind::Disconnected,
                gyrocal_link::ErrorKind::Garbled => ErrorKind::Garbled,
                gyrocal_link::ErrorKind::Io => ErrorKind::Io,
            },
            Error::NotA34401A { .. } => ErrorKind::Identity,
            Error::Config(_) | Error::NotConfigured => ErrorKind::Config,
            Error::Instrument { .. } => ErrorKind::Instrument,
            Error::InvalidReply { .. } | Error::WrongCount { .. } => ErrorKind::Garbled,
            Error::GaveUp { last, .. } => last.kind(),
            Error::NotBack { .. } => ErrorKind::Unreachable,
            Error::ReadingsLost { .. } => ErrorKind::ReadingsLost,
        }
    }

    /// Whether a device clear and another attempt may help: timeouts and garbled replies.
    /// False for [`Error::GaveUp`] (the driver already retried), [`Error::NotBack`] (the
    /// driver already waited [`crate::DriverOptions::reconnect_timeout`]) and
    /// [`Error::ReadingsLost`] (fetching again cannot help: arm a new burst).
    pub fn is_retryable(&self) -> bool {
        !matches!(self, Error::GaveUp { .. })
            && matches!(self.kind(), ErrorKind::Timeout | ErrorKind::Garbled)
    }
}

impl gyrocal_meter::MeterError for Error {
    fn kind(&self) -> ErrorKind {
        match self {
            // the driver already retried: not retryable again, whatever the last failure was
            Error::GaveUp { .. } => ErrorKind::Other,
            _ => Error::kind(self).in_role(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use gyrocal_meter::MeterError;

    /// The driver's detail and the role's view of the same errors: identity, configuration
    /// and I/O are `Other` to a run, and a give-up is never retryable again.
    #[test]
    fn the_role_sees_the_drivers_kinds_coarser() {
        let identity = Error::NotA34401A {
            device: "sim".into(),
            reply: "X".into(),
        };
        assert_eq!(identity.kind(), ErrorKind::Identity);
        assert_eq!(MeterError::kind(&identity), ErrorKind::Other);
        let config = Error::Config("nplc".into());
        assert_eq!(config.kind(), ErrorKind::Config);
        assert_eq!(MeterError::kind(&config), ErrorKind::Other);
        let lost = Error::ReadingsLost {
            device: "sim".into(),
            count: 3,
            cause: "a power cycle".into(),
        };
        assert_eq!(MeterError::kind(&lost), ErrorKind::ReadingsLost);
        let gave_up = Error::GaveUp {
            device: "sim".into(),
            attempts: 3,
            slow: String::new(),
            last: Box::new(Error::WrongCount {
                device: "sim".into(),
                expected: 3,
                got: 2,
            }),
        };
        assert_eq!(gave_up.kind(), ErrorKind::Garbled);
        assert!(!gave_up.is_retryable());
        assert_eq!(MeterError::kind(&gave_up), ErrorKind::Other);
    }
}
