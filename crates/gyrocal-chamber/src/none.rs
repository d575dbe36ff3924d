//! The chamber of a bench that has none.

use std::time::Duration;

use crate::{
    Chamber, ChamberError, ChamberIdentity, ChamberReading, ChamberTiming, SafeReport, SafeState,
};

/// What [`NoChamber`] describes itself as.
pub const NO_CHAMBER: &str = "no chamber";

/// A bench without a chamber: every run that is not a temperature series. Asking it for a
/// temperature is a bug in the caller (an error of kind [`crate::ChamberErrorKind::State`], never a
/// made-up reading); leaving it safe is trivially confirmed (there is nothing to leave).
#[derive(Debug, Clone, Copy, Default)]
pub struct NoChamber;

fn absent(what: &str) -> ChamberError {
    ChamberError::State {
        device: NO_CHAMBER.into(),
        what: format!("{what}: this bench has no chamber"),
    }
}

impl Chamber for NoChamber {
    fn describe(&self) -> &str {
        NO_CHAMBER
    }

    fn present(&self) -> bool {
        false
    }

    async fn connect(&mut self) -> Result<ChamberIdentity, ChamberError> {
        Err(absent("connect"))
    }

    async fn set_setpoint(&mut self, _c: f64) -> Result<(), ChamberError> {
        Err(absent("set a setpoint"))
    }

    async fn read(&mut self) -> Result<ChamberReading, ChamberError> {
        Err(absent("read"))
    }

    async fn reset_alarms(&mut self) -> Result<(), ChamberError> {
        Err(absent("reset alarms"))
    }

    async fn go_safe(&mut self, state: SafeState) -> SafeReport {
        SafeReport {
            state,
            confirmed: true,
            detail: "no chamber on this bench".into(),
        }
    }

    fn timing(&self) -> ChamberTiming {
        ChamberTiming {
            read: Duration::ZERO,
            reply_timeout: Duration::ZERO,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ChamberErrorKind;

    #[tokio::test]
    async fn no_chamber_refuses_to_make_up_a_temperature() {
        let mut c = NoChamber;
        let e = c.read().await.unwrap_err();
        assert_eq!(e.kind(), ChamberErrorKind::State);
        assert!(e.to_string().contains("no chamber"), "{e}");
        assert!(c.go_safe(SafeState::default()).await.confirmed);
    }
}
