//! The [`Dialect`] trait: a rate table's wire protocol, and nothing else.
//!
//! Everything a careful driver does on top of the bytes (client-side limits, the state machine,
//! at-rate detection, waiting for rest, the heartbeat deadline, recording, fault latching, the
//! stop handle) is the same for every table, so it is written once, in [`Table`](crate::Table),
//! which implements [`RateTable`](crate::RateTable) over any dialect. A dialect only knows how
//! its table says "identify", "servo on", "turn at this rate with this acceleration", "what is
//! your rate, position, mode", "is a fault latched", "stop". This is how probe-rs writes JTAG
//! access once (`impl<P: AutoImplementJtagAccess> JtagAccess for P` over a small `RawJtagIo`
//! trait): the probe drivers implement the few raw operations, the shared code the rest.
//!
//! A dialect is shared between the task that owns the table and the [`StopHandle`]s
//! (`Send + Sync`, methods take `&self`): it keeps its link behind an async mutex, holds it for
//! one exchange at a time, and its [`Dialect::send_stop`] may run from any task while a query is
//! in flight.
//!
//! What belongs to the dialect and not to the policy:
//!
//! - which queries are idempotent and may be asked again after a lost or garbled reply, and the
//!   notes of those retries ([`Dialect::take_retries`]);
//! - how the table reports errors (an error queue, a `?` in a reply) and faults (a status bit,
//!   a text);
//! - what its stop commands are and whether they wait for a reply.
//!
//! A dialect tells the policy when the *link* failed ([`DialectError::link_failed`]): the
//! table's motion is then unknown and the policy faults the driver (after a best-effort
//! controlled stop). A reply that merely does not parse, or a command the table refused, is
//! returned without faulting.
//!
//! [`StopHandle`]: crate::StopHandle

use std::future::Future;
use std::time::Duration;

use tokio::time::Instant;

use crate::{Identity, Limits, StopKind, TableError, TableMode, TableStatus};

/// An error from a dialect operation.
#[derive(Debug)]
pub struct DialectError {
    /// The error, as the caller of the table sees it.
    pub error: TableError,
    /// The link lost or mangled the exchange and no attempt succeeded: the table's motion is
    /// unknown, so the policy faults the driver (unless it never identified the table).
    pub link_failed: bool,
}

impl DialectError {
    /// An error after which the link cannot be trusted.
    pub fn link(error: TableError) -> Self {
        DialectError {
            error,
            link_failed: true,
        }
    }
}

impl From<TableError> for DialectError {
    /// An error that leaves the link usable (a refused command, an unparseable reply).
    fn from(error: TableError) -> Self {
        DialectError {
            error,
            link_failed: false,
        }
    }
}

/// What [`Dialect::connect`] found.
#[derive(Debug, Clone, PartialEq)]
pub struct Connected {
    /// The table's identity.
    pub identity: Identity,
    /// The controller's mode at connection.
    pub mode: TableMode,
}

/// The outcome of [`Dialect::send_stop`].
#[derive(Debug)]
pub struct StopAttempt {
    /// The stop command was handed to the link (written, or its write failed or timed out
    /// part-way): the table may be stopping, so the driver's state becomes
    /// [`TableState::Stopping`](crate::TableState::Stopping). False when the link could not
    /// even be had.
    pub attempted: bool,
    /// Whether the command was written.
    pub result: Result<(), TableError>,
}

/// A rate table's wire protocol. See the [module documentation](self).
///
/// Timeouts are passed in by the policy: a monitoring sample uses the heartbeat deadline,
/// ordinary queries the reply timeout. A query's timeout bounds its retries too.
pub trait Dialect: Send + Sync + 'static {
    /// The dialect's short name, reported in [`Capabilities`](crate::Capabilities).
    const NAME: &'static str;

    /// Whether the table's position can be read back.
    const POSITION_READBACK: bool = true;

    /// The link's description, used in every error message.
    fn describe(&self) -> &str;

    /// Clears stale input, identifies the table (draining anything stale it reports) and reads
    /// its mode.
    fn connect(
        &self,
        timeout: Duration,
    ) -> impl Future<Output = Result<Connected, DialectError>> + Send;

    /// Clears latched faults and turns the servo on, ready for rate demands; `limits` are the
    /// client-side limits (a dialect may also set them on the table).
    fn enable(
        &self,
        limits: &Limits,
        timeout: Duration,
    ) -> impl Future<Output = Result<(), DialectError>> + Send;

    /// Demands `rate` (deg/s), entering rate mode if needed, first setting the acceleration
    /// limit to `acceleration` (deg/s²) when given (`None`: the table still has the one last
    /// sent, so nothing is spent on it), and checks that the table took it. Returns the instant
    /// the demand was written: the ramp starts there, and the policy's first at-rate sample
    /// is timed from it. The policy checked the limits and the state.
    fn demand_rate(
        &self,
        rate: f64,
        acceleration: Option<f64>,
        timeout: Duration,
    ) -> impl Future<Output = Result<Instant, DialectError>> + Send;

    /// The measured rate, deg/s.
    fn read_rate(
        &self,
        timeout: Duration,
    ) -> impl Future<Output = Result<f64, DialectError>> + Send;

    /// The measured position, degrees (the policy wraps it into `[0, 360)`).
    fn read_position(
        &self,
        timeout: Duration,
    ) -> impl Future<Output = Result<f64, DialectError>> + Send;

    /// The controller's mode. [`TableMode::Off`] must mean "not driven to turn": with a rate
    /// near zero it is rest.
    fn read_mode(
        &self,
        timeout: Duration,
    ) -> impl Future<Output = Result<TableMode, DialectError>> + Send;

    /// The controller's mode and status byte.
    fn status(
        &self,
        timeout: Duration,
    ) -> impl Future<Output = Result<TableStatus, DialectError>> + Send;

    /// Polls for a latched fault: `Some(reason)` (the table's own text when it gives one) is a
    /// fault the policy latches; an error the table reports that is not a fault is an `Err`.
    /// This is also the heartbeat.
    fn poll_faults(
        &self,
        timeout: Duration,
    ) -> impl Future<Output = Result<Option<String>, DialectError>> + Send;

    /// Sends a stop, whatever the state, without waiting for the motion (and, where the
    /// protocol allows, without waiting for a reply); `timeout` bounds getting and writing to
    /// the link. Called from the owning task and from [`StopHandle`](crate::StopHandle)s.
    fn send_stop(
        &self,
        kind: StopKind,
        timeout: Duration,
    ) -> impl Future<Output = StopAttempt> + Send;

    /// Takes the notes of the queries asked again since the last call (oldest first). The
    /// default (a dialect that never retries) has none.
    fn take_retries(&self) -> Vec<String> {
        Vec::new()
    }
}

/// A dialect built from its transport and its configuration, so that
/// [`Table::new`](crate::Table::new) builds the table of that dialect in one call
/// (`AclTable::new(link, AclConfig::default())`).
pub trait Build: Dialect + Sized {
    /// The link it talks over.
    type Transport;
    /// Its configuration (with the policy's settings in it).
    type Config;
    /// The dialect and the policy's settings for `config`.
    fn build(transport: Self::Transport, config: Self::Config) -> (Self, crate::PolicyConfig);
    /// The configuration in force.
    fn config(&self) -> &Self::Config;
}

/// The stop path every dialect shares, written once: get the link within `2 × timeout + ½ s`
/// (a query may hold it), log the command, write it within `timeout` with `write` (which gets
/// the link's guard, so the dialect can keep its link state), and say what happened. Never
/// waits for a reply: a stop must not depend on the table answering.
pub async fn send_stop_with<G, L, W, Fut>(
    device: &str,
    command: &str,
    timeout: Duration,
    lock: L,
    write: W,
) -> StopAttempt
where
    L: Future<Output = G>,
    W: FnOnce(G) -> Fut,
    Fut: Future<Output = Result<(), gyrocal_link::LinkError>>,
{
    let wait = timeout * 2 + Duration::from_millis(500);
    let Ok(guard) = tokio::time::timeout(wait, lock).await else {
        return StopAttempt {
            attempted: false,
            result: Err(TableError::Fault {
                device: device.to_string(),
                reason: format!("could not get the link within {wait:?} to send `{command}`"),
            }),
        };
    };
    tracing::info!(device = %device, "{command}");
    let result = match tokio::time::timeout(timeout, write(guard)).await {
        Ok(r) => r.map_err(|e| TableError::from_link(device, command, e)),
        Err(_) => Err(TableError::Fault {
            device: device.to_string(),
            reason: format!("`{command}` could not be written within {timeout:?}"),
        }),
    };
    StopAttempt {
        attempted: true,
        result,
    }
}
