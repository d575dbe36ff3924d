//! Typed transport errors with a small common [`ErrorKind`], so a caller can decide to retry on a
//! timeout without knowing which backend produced it (the embedded-hal pattern).

use std::time::Duration;

/// What went wrong on a link, independent of the backend.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ErrorKind {
    /// No complete reply arrived within the deadline.
    Timeout,
    /// The other end went away (EOF, hang-up, port unplugged).
    Disconnected,
    /// Bytes arrived that do not form a valid line or reply.
    Garbled,
    /// Any other operating-system I/O failure (open, configure, write).
    Io,
}

/// An error on a link. Every variant names the link (`device`) so messages point at the port.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    /// No complete line within the timeout. `partial` holds what had arrived (it is not a line).
    #[error("{device}: no reply within {timeout:?}{}", partial_note(.partial))]
    Timeout {
        /// The link's description (port path, address).
        device: String,
        /// The timeout that expired.
        timeout: Duration,
        /// Bytes received without a terminator before the deadline, if any.
        partial: Vec<u8>,
    },
    /// The peer closed the link.
    #[error("{device}: disconnected{}", partial_note(.partial))]
    Disconnected {
        /// The link's description.
        device: String,
        /// Bytes received without a terminator before the end, if any.
        partial: Vec<u8>,
    },
    /// A line that cannot be a reply (not UTF-8, too long, control bytes).
    #[error("{device}: garbled reply: {reason} (bytes: {})", show_bytes(.bytes))]
    Garbled {
        /// The link's description.
        device: String,
        /// Why the bytes were rejected.
        reason: String,
        /// The offending bytes, for the message and the log.
        bytes: Vec<u8>,
    },
    /// An operating-system error while opening, configuring, reading or writing.
    #[error("{device}: {context}: {source}")]
    Io {
        /// The link's description.
        device: String,
        /// What the link was doing.
        context: String,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
}

impl LinkError {
    /// The backend-independent kind of this error.
    pub fn kind(&self) -> ErrorKind {
        match self {
            LinkError::Timeout { .. } => ErrorKind::Timeout,
            LinkError::Disconnected { .. } => ErrorKind::Disconnected,
            LinkError::Garbled { .. } => ErrorKind::Garbled,
            LinkError::Io { .. } => ErrorKind::Io,
        }
    }

    /// Builds an [`LinkError::Io`] with context.
    pub fn io(
        device: impl Into<String>,
        context: impl Into<String>,
        source: std::io::Error,
    ) -> Self {
        LinkError::Io {
            device: device.into(),
            context: context.into(),
            source,
        }
    }
}

fn partial_note(partial: &[u8]) -> String {
    if partial.is_empty() {
        String::new()
    } else {
        format!(" (partial, unterminated: {})", show_bytes(partial))
    }
}

/// Renders bytes for an error message: printable ASCII as is, everything else escaped, and
/// long inputs shortened so one garbled burst does not flood a log line.
pub fn show_bytes(bytes: &[u8]) -> String {
    const MAX: usize = 80;
    let mut out = String::from("\"");
    for &b in bytes.iter().take(MAX) {
        out.extend(std::ascii::escape_default(b).map(char::from));
    }
    out.push('"');
    if bytes.len() > MAX {
        out.push_str(&format!("… ({} bytes)", bytes.len()));
    }
    out
}
