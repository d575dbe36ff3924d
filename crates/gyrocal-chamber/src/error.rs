//! Typed chamber errors. Every variant names the chamber (`device`), and
//! [`ChamberError::kind`] maps it to a small [`ChamberErrorKind`] so the run decides what to do
//! (ask again, stop, refuse the plan) without matching on a dialect's details.

/// What went wrong with a chamber, independent of the dialect.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ChamberErrorKind {
    /// A request outside the driver's limits (a setpoint beyond the controller's range or the
    /// plan's); nothing was sent.
    Limit,
    /// The controller refused a request (a Modbus exception reply, an Espec `NA:`).
    Instrument,
    /// The controller raised an alarm (over-temperature, door open, ...): the run must stop.
    Alarm,
    /// No reply within the deadline: the controller is silent.
    Timeout,
    /// A reply that is not a valid one (a Modbus CRC error, an unparsable line), after the
    /// retries of an idempotent query.
    Garbled,
    /// The link failed (disconnected, an I/O error).
    Link,
    /// The controller is set up in a way the driver will not guess about (°F, a unit that is
    /// not a temperature, a decimal-places value out of range).
    Setup,
    /// The dialect cannot do what was asked (a ramp rate on a controller without one).
    Unsupported,
    /// The request is not allowed now (asking [`crate::NoChamber`] for a temperature: a bug).
    State,
}

/// An error from a chamber driver.
#[derive(Debug, thiserror::Error)]
pub enum ChamberError {
    /// Refused before sending.
    #[error("{device}: refused before sending: {what}")]
    Limit {
        /// The chamber's link description.
        device: String,
        /// What was out of range, with the value and the limit.
        what: String,
    },
    /// The controller refused the request.
    #[error("{device}: the controller refused `{request}`: {reason}")]
    Instrument {
        /// The chamber's link description.
        device: String,
        /// The request (register write, command line).
        request: String,
        /// The controller's answer (the Modbus exception and its meaning, the `NA:` text).
        reason: String,
    },
    /// An alarm is active.
    #[error("{device}: chamber alarm: {alarms}")]
    Alarm {
        /// The chamber's link description.
        device: String,
        /// The active alarms, comma-separated.
        alarms: String,
    },
    /// No reply within the deadline.
    #[error("{device}: no answer to `{request}` within {timeout_ms} ms")]
    Timeout {
        /// The chamber's link description.
        device: String,
        /// The request that went unanswered.
        request: String,
        /// The deadline, ms.
        timeout_ms: u64,
    },
    /// Not a valid reply.
    #[error("{device}: garbled reply to `{request}`: {detail}")]
    Garbled {
        /// The chamber's link description.
        device: String,
        /// The request.
        request: String,
        /// What was wrong with the reply.
        detail: String,
    },
    /// The link failed.
    #[error("{device}: link failed during `{request}`: {detail}")]
    Link {
        /// The chamber's link description.
        device: String,
        /// The request in progress.
        request: String,
        /// The I/O error.
        detail: String,
    },
    /// The controller's setup is one the driver will not guess about.
    #[error("{device}: {what}")]
    Setup {
        /// The chamber's link description.
        device: String,
        /// What is wrong and what to change on the controller.
        what: String,
    },
    /// The dialect cannot do this.
    #[error("{device}: not supported by this controller: {what}")]
    Unsupported {
        /// The chamber's link description.
        device: String,
        /// What was asked.
        what: String,
    },
    /// Not allowed now.
    #[error("{device}: {what}")]
    State {
        /// The chamber's link description.
        device: String,
        /// What was asked, and why not.
        what: String,
    },
}

impl ChamberError {
    /// The kind of error, for the run's decisions.
    pub fn kind(&self) -> ChamberErrorKind {
        match self {
            ChamberError::Limit { .. } => ChamberErrorKind::Limit,
            ChamberError::Instrument { .. } => ChamberErrorKind::Instrument,
            ChamberError::Alarm { .. } => ChamberErrorKind::Alarm,
            ChamberError::Timeout { .. } => ChamberErrorKind::Timeout,
            ChamberError::Garbled { .. } => ChamberErrorKind::Garbled,
            ChamberError::Link { .. } => ChamberErrorKind::Link,
            ChamberError::Setup { .. } => ChamberErrorKind::Setup,
            ChamberError::Unsupported { .. } => ChamberErrorKind::Unsupported,
            ChamberError::State { .. } => ChamberErrorKind::State,
        }
    }
}
