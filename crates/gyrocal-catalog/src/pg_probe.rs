//! One connection attempt before a PostgreSQL pool is built, so that a server that is not
//! there is said at once, with its host and port.
//!
//! Why: sqlx's pool takes "connection refused" for a server that is still starting and
//! retries it until its acquire timeout (5 s), then reports only "pool timed out while
//! waiting for an open connection", which names neither the cause nor the place. One direct
//! connection first gives the real cause in the time the refusal takes (milliseconds):
//! "connection refused by db.lab:5432"; a server that does not answer at all is given the
//! connect timeout, then named the same way.

use std::time::Duration;

use sqlx::Connection as _;
use sqlx::postgres::{PgConnectOptions, PgConnection};

use crate::error::CatalogError;
use crate::url::CatalogUrl;

/// Connects once to the server of `options` (then closes): `Ok` when it answers, else the
/// error naming the host and port (or socket) and the cause.
pub(crate) async fn probe(
    url: &CatalogUrl,
    options: &PgConnectOptions,
    timeout: Duration,
) -> Result<(), CatalogError> {
    let place = match options.get_socket() {
        Some(dir) => format!("the socket in {}", dir.display()),
        None => format!("{}:{}", options.get_host(), options.get_port()),
    };
    let unreachable = |message: String| CatalogError::Unreachable {
        url: url.redacted(),
        message: url.scrub(&message),
    };
    match tokio::time::timeout(timeout, PgConnection::connect_with(options)).await {
        Ok(Ok(conn)) => {
            // the pool makes its own connections; this one only proved the server is there
            let _ = conn.close().await;
            Ok(())
        }
        Ok(Err(sqlx::Error::Io(e))) if e.kind() == std::io::ErrorKind::ConnectionRefused => {
            Err(unreachable(format!(
                "connection refused by {place} (is PostgreSQL running and listening there?)"
            )))
        }
        Ok(Err(sqlx::Error::Io(e))) => Err(unreachable(format!("{place}: {e}"))),
        Ok(Err(e)) => Err(crate::db::db_error(url, &e)),
        Err(_) => Err(unreachable(format!(
            "no answer from {place} within {} s",
            timeout.as_secs_f64()
        ))),
    }
}
