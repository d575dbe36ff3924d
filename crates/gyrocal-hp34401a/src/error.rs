//! Driver errors, with a small [`ErrorKind`] so the sequencer can decide what to do.

use gyrocal_link::{LinkError, show_bytes};

/// One entry of the meter's error queue (`SYST:ERR?`), such as `-222,"Data out of range"`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct InstrumentError {
    /// The SCPI or device-specific code (negative for standard SCPI errors).
    pub code: i32,
    /// The meter's message.
    pub message: String,
}

impl std::fmt::Display for InstrumentError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{},\"{}\"", self.code, self.message)
    }
}

/// What went wrong, independent of the details.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ErrorKind {
    /// No (complete) reply in time. Retryable.
    Timeout,
    /// The link went away. Not retryable without reopening it.
    Disconnected,
    /// A reply that is not what the protocol allows (bad reading, wrong count). Retryable.
    Garbled,
    /// An operating-system error on the link.
    Io,
    /// The meter reported errors in its queue.
    Instrument,
    /// The device is not an HP 34401A.
    Identity,
    /// The configuration or the request is invalid (nothing was sent).
    Config,
    /// The meter stopped answering and did not come back within
    /// [`crate::DriverOptions::reconnect_timeout`]. Not retryable.
    Unreachable,
    /// The readings of a memory burst were lost with the meter's memory (a power cycle, or the
    /// link re-established since the burst was armed): the burst must be measured again.
    ReadingsLost,
}

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

fn list(errors: &[InstrumentError]) -> String {
    errors
        .iter()
        .map(ToString::to_string)
        .collect::<Vec<_>>()
        .join("; ")
}

impl Error {
    /// The kind of this error (for [`Error::GaveUp`], the kind of the last attempt's error).
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
    fn kind(&self) -> gyrocal_meter::ErrorKind {
        use gyrocal_meter::ErrorKind as K;
        match self {
            // the driver already retried: not retryable again, whatever the last failure was
            Error::GaveUp { .. } => K::Other,
            _ => match Error::kind(self) {
                ErrorKind::Timeout => K::Timeout,
                ErrorKind::Disconnected => K::Disconnected,
                ErrorKind::Garbled => K::Garbled,
                ErrorKind::Instrument => K::Instrument,
                ErrorKind::Unreachable => K::Unreachable,
                ErrorKind::ReadingsLost => K::ReadingsLost,
                ErrorKind::Io | ErrorKind::Identity | ErrorKind::Config => K::Other,
            },
        }
    }
}
