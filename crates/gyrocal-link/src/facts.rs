//! Facts of the links, with no I/O: available without the `io` feature, so the plan crate
//! (synchronous) validates a plan against them and nothing else keeps a copy.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

/// The baud rates the supported instruments offer (HP 34401A: 300 to 9600).
pub const SUPPORTED_BAUDS: [u32; 6] = [300, 600, 1200, 2400, 4800, 9600];

/// Character framing: parity and data bits are tied, always one start and two stop bits, so every
/// character is 11 bits on the wire.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
pub enum Framing {
    /// 8 data bits, no parity, 2 stop bits (`8N2`).
    #[default]
    #[serde(rename = "8N2")]
    EightNone,
    /// 7 data bits, even parity, 2 stop bits (`7E2`).
    #[serde(rename = "7E2")]
    SevenEven,
    /// 7 data bits, odd parity, 2 stop bits (`7O2`).
    #[serde(rename = "7O2")]
    SevenOdd,
}

impl Framing {
    /// Bits on the wire per character: 1 start + 7 or 8 data + parity + 2 stop = 11.
    pub const BITS_PER_CHAR: u32 = 11;
}

impl fmt::Display for Framing {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Framing::EightNone => "8N2",
            Framing::SevenEven => "7E2",
            Framing::SevenOdd => "7O2",
        })
    }
}

impl FromStr for Framing {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_uppercase().as_str() {
            "8N2" => Ok(Framing::EightNone),
            "7E2" => Ok(Framing::SevenEven),
            "7O2" => Ok(Framing::SevenOdd),
            other => Err(format!(
                "unsupported framing {other:?} (use 8N2, 7E2 or 7O2)"
            )),
        }
    }
}

/// The Ctrl-C byte: on the HP 34401A's RS-232 port it is the device clear (aborts a measurement,
/// clears the input and output buffers, keeps the configuration and the error queue).
pub const DEVICE_CLEAR: u8 = 0x03;
