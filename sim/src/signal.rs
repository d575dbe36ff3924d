//! The seam between the simulated multimeter and whatever it measures.
//!
//! The multimeter asks for the mean input voltage over each reading's integration window; a
//! constant, a function of time, or the simulated gyro on the simulated table answers.

use std::time::Duration;

use tokio::time::Instant;

/// The voltage at the simulated multimeter's input terminals.
pub trait SignalSource: Send + 'static {
    /// Mean input voltage over `[start, start + window]`: one reading's integration window
    /// (an integrating A/D converter averages the input over it).
    fn volts(&mut self, start: Instant, window: Duration) -> f64;
}

/// A constant voltage.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Constant(pub f64);

impl SignalSource for Constant {
    fn volts(&mut self, _start: Instant, _window: Duration) -> f64 {
        self.0
    }
}

/// A voltage given as a function of the time since the source was created, sampled at the middle
/// of the integration window.
pub struct FnOfTime<F> {
    origin: Instant,
    f: F,
}

impl<F: FnMut(f64) -> f64 + Send + 'static> FnOfTime<F> {
    /// `f` maps seconds since now to volts.
    pub fn new(f: F) -> Self {
        FnOfTime {
            origin: Instant::now(),
            f,
        }
    }
}

impl<F: FnMut(f64) -> f64 + Send + 'static> SignalSource for FnOfTime<F> {
    fn volts(&mut self, start: Instant, window: Duration) -> f64 {
        let mid = start.saturating_duration_since(self.origin) + window / 2;
        (self.f)(mid.as_secs_f64())
    }
}

impl<S: SignalSource + ?Sized> SignalSource for Box<S> {
    fn volts(&mut self, start: Instant, window: Duration) -> f64 {
        (**self).volts(start, window)
    }
}
