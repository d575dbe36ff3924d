//! Truevolt driver errors: every message names the device (the link) and, where there was
//! one, the command being exchanged; [`gyrocal_meter::MeterError::kind`] tells generic code
//! what to do.

use gyrocal_link::{LinkError, show_bytes};
use gyrocal_meter::ErrorKind;
use gyrocal_meter::scpi::list;
/// The SCPI error-queue entry and its parser are the meter role's (one copy for every SCPI
/// meter).
pub use gyrocal_meter::{InstrumentError, parse_error};

/// An error from the Truevolt driver.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The link failed during `command`.
    #[error("{source} (during {command})")]
    Link {
        /// The command being exchanged (`DATA:REM? 12,WAIT`).
        command: String,
        /// The link's error (it names the device).
        #[source]
        source: LinkError,
    },
    /// The instrument is not the model the plan names.
    #[error("{device}: {message}")]
    Identity {
        /// The link.
        device: String,
        /// What answered and why it is refused.
        message: String,
    },
    /// Settings the model does not offer, refused before anything was sent.
    #[error("invalid configuration for the {model}: {message}")]
    Config {
        /// The model.
        model: String,
        /// What is wrong, with the allowed values.
        message: String,
    },
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
    /// A reply the protocol does not allow.
    #[error("{device}: {command}: expected {expected}, got {}", show_bytes(bytes))]
    InvalidReply {
        /// The link.
        device: String,
        /// The query.
        command: String,
        /// What was expected.
        expected: &'static str,
        /// The bytes received.
        bytes: Vec<u8>,
    },
    /// A reply with another number of readings than asked for.
    #[error("{device}: {command}: expected {expected} readings, the reply held {got}")]
    WrongCount {
        /// The link.
        device: String,
        /// The query.
        command: String,
        /// Readings asked for.
        expected: usize,
        /// Readings received.
        got: usize,
    },
    /// An acquisition before `configure()`.
    #[error("{device}: the meter is not configured: call configure() first")]
    NotConfigured {
        /// The link.
        device: String,
    },
    /// Readings still in the meter were lost (the link was re-established since they were
    /// taken: a power cycle clears the memory, and so does gyrocal's own reconfiguration).
    #[error(
        "{device}: the multimeter's memory was cleared since {count} readings were taken \
         ({cause}): they must be measured again"
    )]
    ReadingsLost {
        /// The link.
        device: String,
        /// Readings lost.
        count: usize,
        /// What cleared the memory: a power cycle, or gyrocal's reconfiguration after the
        /// meter did not answer or the connection was lost.
        cause: String,
    },
    /// The meter did not come back within the reconnect timeout.
    #[error("{device}: the multimeter did not come back within {:.0} s: is it powered and on the network? (last attempt: {last}){slow}", waited.as_secs_f64())]
    NotBack {
        /// The link.
        device: String,
        /// How long the driver kept trying.
        waited: std::time::Duration,
        /// Empty, or what the driver saw earlier of a meter that answers late (`; the meter
        /// answers slowly: ...`): replies later than the widened deadlines count as none.
        slow: String,
        /// The last attempt's error.
        #[source]
        last: Box<Error>,
    },
    /// The retry budget was spent; the last failure.
    #[error("{device}: gave up after {attempts} attempts{slow}: {last}")]
    GaveUp {
        /// The link.
        device: String,
        /// Attempts made, the first included.
        attempts: u32,
        /// Empty, or what the driver saw of a meter that answers late (`; the meter answers
        /// slowly: ...`), so the message names the real cause.
        slow: String,
        /// The last failure.
        #[source]
        last: Box<Error>,
    },
}

impl Error {
    /// Whether a recovery (reconnect, `ABOR`) and another attempt may help: timeouts,
    /// garbled replies, and a socket that went away (reconnecting is the recovery).
    pub fn is_retryable(&self) -> bool {
        matches!(
            gyrocal_meter::MeterError::kind(self),
            ErrorKind::Timeout | ErrorKind::Garbled | ErrorKind::Disconnected
        )
    }
}

impl Error {
    /// The kind of this error with the driver's detail (identity, configuration and I/O told
    /// apart); for [`Error::GaveUp`], the kind of the last failure.
    fn detailed_kind(&self) -> ErrorKind {
        match self {
            Error::Link { source, .. } => match source.kind() {
                gyrocal_link::ErrorKind::Timeout => ErrorKind::Timeout,
                gyrocal_link::ErrorKind::Disconnected => ErrorKind::Disconnected,
                gyrocal_link::ErrorKind::Garbled => ErrorKind::Garbled,
                gyrocal_link::ErrorKind::Io => ErrorKind::Io,
            },
            Error::InvalidReply { .. } | Error::WrongCount { .. } => ErrorKind::Garbled,
            Error::Instrument { .. } => ErrorKind::Instrument,
            Error::ReadingsLost { .. } => ErrorKind::ReadingsLost,
            Error::NotBack { .. } => ErrorKind::Unreachable,
            Error::GaveUp { last, .. } => last.detailed_kind(),
            Error::Identity { .. } => ErrorKind::Identity,
            Error::Config { .. } | Error::NotConfigured { .. } => ErrorKind::Config,
        }
    }
}

impl gyrocal_meter::MeterError for Error {
    fn kind(&self) -> ErrorKind {
        match self {
            // the meter already retried: not retryable again, whatever the last failure was
            Error::GaveUp { .. } => ErrorKind::Other,
            _ => self.detailed_kind().in_role(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use gyrocal_meter::MeterError;

    /// Both meter drivers classify onto the role's one `ErrorKind` alike: identity and
    /// configuration are `Other` to a run, a give-up is never retryable again.
    #[test]
    fn kinds_as_the_role_reports_them() {
        let identity = Error::Identity {
            device: "tcp://lab-dmm:5025".into(),
            message: "a 34401A answered".into(),
        };
        assert_eq!(identity.detailed_kind(), ErrorKind::Identity);
        assert_eq!(identity.kind(), ErrorKind::Other);
        let config = Error::NotConfigured {
            device: "tcp://lab-dmm:5025".into(),
        };
        assert_eq!(config.detailed_kind(), ErrorKind::Config);
        assert_eq!(config.kind(), ErrorKind::Other);
        let garbled = Error::WrongCount {
            device: "tcp://lab-dmm:5025".into(),
            command: "FETC?".into(),
            expected: 3,
            got: 2,
        };
        assert_eq!(garbled.kind(), ErrorKind::Garbled);
        assert!(garbled.is_retryable());
        let gave_up = Error::GaveUp {
            device: "tcp://lab-dmm:5025".into(),
            attempts: 3,
            slow: String::new(),
            last: Box::new(garbled),
        };
        assert_eq!(gave_up.detailed_kind(), ErrorKind::Garbled);
        assert_eq!(gave_up.kind(), ErrorKind::Other);
        assert!(!gave_up.is_retryable());
    }
}
