//! Truevolt driver errors: every message names the device (the link) and, where there was
//! one, the command being exchanged; [`gyrocal_meter::MeterError::kind`] tells generic code
//! what to do.

use gyrocal_link::{LinkError, show_bytes};
use gyrocal_meter::ErrorKind;

/// One entry of the SCPI error queue (`SYST:ERR?`), such as `-222,"Data out of range"`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct InstrumentError {
    /// The code (negative for standard SCPI errors).
    pub code: i32,
    /// The meter's message.
    pub message: String,
}

impl std::fmt::Display for InstrumentError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{},\"{}\"", self.code, self.message)
    }
}

/// Parses a `SYST:ERR?` reply (`+0,"No error"`, `-113,"Undefined header"`).
pub fn parse_error(reply: &str) -> Option<InstrumentError> {
    let (code, message) = reply.trim().split_once(',')?;
    let code: i32 = code.trim().trim_start_matches('+').parse().ok()?;
    let message = message.trim();
    let message = message
        .strip_prefix('"')
        .and_then(|m| m.strip_suffix('"'))
        .unwrap_or(message);
    Some(InstrumentError {
        code,
        message: message.to_string(),
    })
}

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

fn list(errors: &[InstrumentError]) -> String {
    errors
        .iter()
        .map(ToString::to_string)
        .collect::<Vec<_>>()
        .join("; ")
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

impl gyrocal_meter::MeterError for Error {
    fn kind(&self) -> ErrorKind {
        match self {
            Error::Link { source, .. } => match source.kind() {
                gyrocal_link::ErrorKind::Timeout => ErrorKind::Timeout,
                gyrocal_link::ErrorKind::Disconnected => ErrorKind::Disconnected,
                gyrocal_link::ErrorKind::Garbled => ErrorKind::Garbled,
                gyrocal_link::ErrorKind::Io => ErrorKind::Other,
            },
            Error::InvalidReply { .. } | Error::WrongCount { .. } => ErrorKind::Garbled,
            Error::Instrument { .. } => ErrorKind::Instrument,
            Error::ReadingsLost { .. } => ErrorKind::ReadingsLost,
            Error::NotBack { .. } => ErrorKind::Unreachable,
            // the meter already retried: not retryable again, whatever the last failure was
            Error::GaveUp { .. } => ErrorKind::Other,
            Error::Identity { .. } | Error::Config { .. } | Error::NotConfigured { .. } => {
                ErrorKind::Other
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn error_queue_entries() {
        assert_eq!(
            parse_error("-113,\"Undefined header\""),
            Some(InstrumentError {
                code: -113,
                message: "Undefined header".into()
            })
        );
        assert_eq!(parse_error("+0,\"No error\"").map(|e| e.code), Some(0));
        assert_eq!(parse_error("garbage"), None);
    }
}
