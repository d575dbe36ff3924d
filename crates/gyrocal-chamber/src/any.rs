//! [`AnyChamber`]: the chamber a plan names, chosen at run time.
//!
//! The engine is generic over its instruments, and every type it is instantiated with is one
//! more copy of it. A chamber is polled every few seconds, so dispatching on an enum costs
//! nothing that matters, and keeps the engine's copies per meter or per table, not per
//! chamber as well. [`crate::Chamber`]'s methods return `impl Future`, so it cannot be a trait
//! object: this enum is the run-time choice instead.

use gyrocal_link::Link;

use crate::{
    Chamber, ChamberError, ChamberIdentity, ChamberReading, ChamberTiming, Espec, NoChamber,
    SafeReport, SafeState, WatlowF4,
};

/// One of the chambers this crate drives.
#[derive(Debug)]
pub enum AnyChamber {
    /// No chamber on this bench.
    None(NoChamber),
    /// A Watlow F4 (Modbus RTU or TCP).
    WatlowF4(Box<WatlowF4>),
    /// An Espec controller (text protocol, experimental) on any gyrocal-link link (a
    /// pipe or pseudo-terminal goes in as `Link::Stream(transport.boxed())`).
    Espec(Box<Espec<Link>>),
}

impl From<NoChamber> for AnyChamber {
    fn from(c: NoChamber) -> Self {
        AnyChamber::None(c)
    }
}

impl From<WatlowF4> for AnyChamber {
    fn from(c: WatlowF4) -> Self {
        AnyChamber::WatlowF4(Box::new(c))
    }
}

impl From<Espec<Link>> for AnyChamber {
    fn from(c: Espec<Link>) -> Self {
        AnyChamber::Espec(Box::new(c))
    }
}

macro_rules! each {
    ($self:ident, $c:ident => $e:expr) => {
        match $self {
            AnyChamber::None($c) => $e,
            AnyChamber::WatlowF4($c) => $e,
            AnyChamber::Espec($c) => $e,
        }
    };
}

impl Chamber for AnyChamber {
    fn describe(&self) -> &str {
        each!(self, c => c.describe())
    }

    fn present(&self) -> bool {
        each!(self, c => c.present())
    }

    async fn connect(&mut self) -> Result<ChamberIdentity, ChamberError> {
        each!(self, c => c.connect().await)
    }

    async fn set_setpoint(&mut self, setpoint_c: f64) -> Result<(), ChamberError> {
        each!(self, c => c.set_setpoint(setpoint_c).await)
    }

    async fn read(&mut self) -> Result<ChamberReading, ChamberError> {
        each!(self, c => c.read().await)
    }

    async fn reset_alarms(&mut self) -> Result<(), ChamberError> {
        each!(self, c => c.reset_alarms().await)
    }

    async fn go_safe(&mut self, state: SafeState) -> SafeReport {
        each!(self, c => c.go_safe(state).await)
    }

    fn timing(&self) -> ChamberTiming {
        each!(self, c => c.timing())
    }

    fn take_retries(&mut self) -> Vec<String> {
        each!(self, c => c.take_retries())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn the_enum_delegates() {
        let mut c = AnyChamber::from(NoChamber);
        assert!(!c.present());
        assert_eq!(c.describe(), crate::NO_CHAMBER);
        assert!(c.read().await.is_err());
        let (host, _device) = tokio::io::duplex(64);
        let f4 = WatlowF4::over_stream(host, "pipe", 9600, crate::WatlowConfig::default());
        let mut c = AnyChamber::from(f4.unwrap_or_else(|e| panic!("{e}")));
        assert!(c.present());
        assert!(c.describe().contains("Watlow F4"));
        // Standby on an F4 without a "chamber on" output: reported, nothing sent.
        assert!(!c.go_safe(SafeState::Standby).await.confirmed);
    }
}
