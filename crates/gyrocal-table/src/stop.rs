//! Stopping the table from anywhere: a cloneable [`StopHandle`] and a [`StopGuard`].
//!
//! The task that owns the driver may be in the middle of a query, cancelled, or unwinding from a
//! panic when the table must stop. The handle shares the driver's link (behind an async mutex
//! held only for one exchange, so a stop waits at most one reply timeout) and sends the stop
//! command without waiting for any reply, so it works on a table in any state.

use std::future::Future;
use std::pin::Pin;
use std::sync::Arc;

use crate::TableError;

/// Which stop to send.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum StopKind {
    /// Smooth deceleration to zero-rate hold, servo stays on (ACL `:Mode:Off 1`).
    Controlled,
    /// Abort profile to zero, then servo off (ACL `:Interlock:Open 1`).
    Emergency,
}

/// A dialect's stop path, object-safe so [`StopHandle`] does not depend on the transport type.
pub trait StopPath: Send + Sync {
    /// The table's link description.
    fn describe(&self) -> &str;
    /// Sends the stop command and records the stop in the driver's state.
    fn send_stop(
        &self,
        kind: StopKind,
    ) -> Pin<Box<dyn Future<Output = Result<(), TableError>> + Send + '_>>;
}

/// A cloneable, `Send + Sync` handle that stops the table from any task.
#[derive(Clone)]
pub struct StopHandle {
    path: Arc<dyn StopPath>,
}

impl std::fmt::Debug for StopHandle {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("StopHandle")
            .field("device", &self.path.describe())
            .finish()
    }
}

impl StopHandle {
    /// Wraps a dialect's stop path.
    pub fn new(path: Arc<dyn StopPath>) -> Self {
        StopHandle { path }
    }

    /// The table's link description.
    pub fn describe(&self) -> &str {
        self.path.describe()
    }

    /// Controlled stop. Idempotent: a second call sends the same harmless command again.
    pub async fn stop(&self) -> Result<(), TableError> {
        self.path.send_stop(StopKind::Controlled).await
    }

    /// Emergency stop. Idempotent.
    pub async fn emergency_stop(&self) -> Result<(), TableError> {
        self.path.send_stop(StopKind::Emergency).await
    }

    /// A guard that sends a controlled stop when dropped without [`StopGuard::disarm`]: put one
    /// in a scope that moves the table so an early return, a cancelled future or a panic still
    /// stops it. The stop is spawned on the current tokio runtime (if any) because `Drop` cannot
    /// wait.
    pub fn guard(&self) -> StopGuard {
        StopGuard {
            handle: Some(self.clone()),
        }
    }
}

/// Sends a controlled stop on drop unless disarmed. See [`StopHandle::guard`].
#[derive(Debug)]
#[must_use = "a guard stops the table when dropped"]
pub struct StopGuard {
    handle: Option<StopHandle>,
}

impl StopGuard {
    /// The scope ended normally and the caller takes over stopping: do nothing on drop.
    pub fn disarm(mut self) {
        self.handle = None;
    }
}

impl Drop for StopGuard {
    fn drop(&mut self) {
        let Some(handle) = self.handle.take() else {
            return;
        };
        match tokio::runtime::Handle::try_current() {
            Ok(rt) => {
                tracing::warn!(
                    device = handle.describe(),
                    "stop guard dropped: stopping the table"
                );
                rt.spawn(async move {
                    if let Err(e) = handle.stop().await {
                        tracing::error!("stop guard could not stop the table: {e}");
                    }
                });
            }
            Err(_) => tracing::error!(
                device = handle.describe(),
                "stop guard dropped outside a tokio runtime: the table was NOT stopped"
            ),
        }
    }
}
