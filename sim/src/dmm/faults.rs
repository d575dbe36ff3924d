//! Faults on the simulated 34401A: a fault injected now or at a reading (reply faults land on
//! the reply that carries the reading), the scheduled ones, and the power cycle (off for the
//! off time, back in LOCAL with the power-on state).

use std::time::Duration;

use tokio::time::Instant;

use super::{Dest, Meter, Settings, scaled};
use crate::scpi::{EventStatus, Fault, ReplyFault, slow_delay};

impl Meter {
    pub(super) fn inject(&mut self, f: Fault) {
        tracing::debug!(fault = ?f, "simulated 34401A: fault injected");
        if let Some(reply_fault) = ReplyFault::of(&f) {
            self.pending_reply_fault.push_back(reply_fault);
            return;
        }
        match f {
            Fault::NoReply | Fault::Garble | Fault::Truncate => {}
            Fault::Disconnect => self.disconnect = true,
            Fault::PowerCycle { off_s } => self.power_off(off_s),
            Fault::Overload { readings } => self.overloads_left += readings,
            Fault::PushError { code, message } => self.raise(code, &message),
            Fault::Slow { delay_s, replies } => {
                self.slow
                    .set(scaled(&self.cfg, slow_delay(delay_s)), replies);
            }
        }
    }

    /// Switches the meter off for `off_s` sim seconds (default `power_off_s`): the
    /// measurement, the line being executed, everything buffered in and out is lost.
    pub(super) fn power_off(&mut self, off_s: Option<f64>) {
        let off = off_s
            .filter(|s| s.is_finite() && *s >= 0.0)
            .unwrap_or(self.cfg.power_off_s);
        let now = Instant::now().max(self.clock);
        let until = now + scaled(&self.cfg, Duration::from_secs_f64(off.min(1e9)));
        tracing::debug!(off_s = off, "simulated 34401A: power off");
        // a power cycle while off restarts the off time
        self.off_until = Some(self.off_until.map_or(until, |u| u.max(until)));
        self.meas = None;
        self.exec = None;
        self.out.clear();
        self.tx = None;
        self.lines.clear();
        self.inbuf.clear();
    }

    /// Back on at `t`, as after power-on: LOCAL (unless `strict_remote` is off), the `*RST`
    /// settings, memory, buffers and error queue empty, the Power On event bit set.
    pub(super) fn power_on(&mut self, t: Instant) {
        tracing::debug!("simulated 34401A: power on");
        self.off_until = None;
        self.counters.power_cycles += 1;
        self.remote = !self.cfg.strict_remote || self.gpib();
        self.talk = false;
        self.talk_check = false;
        self.set = Settings::default();
        self.errors.clear();
        self.memory.clear();
        self.memory_fault = None;
        self.esr = EventStatus::powered_on();
        self.meas = None;
        self.exec = None;
        self.out.clear();
        self.tx = None;
        self.lines.clear();
        self.inbuf.clear();
        self.clock = self.clock.max(t);
        self.in_wire_free = t;
        self.out_wire_free = t;
        self.out_time = t;
    }

    /// Fires the faults armed for the reading about to be taken; true when the meter
    /// disconnected or was switched off instead.
    pub(super) fn reading_faults(&mut self, dest: Dest) -> bool {
        let next = self.counters.readings_taken + 1;
        for f in self.at_reading.due(next) {
            tracing::debug!(fault = ?f, reading = next, "simulated 34401A: fault at reading");
            let Some(reply_fault) = ReplyFault::of(&f) else {
                self.inject(f);
                continue;
            };
            if self.off_until.is_some() {
                continue;
            }
            match dest {
                Dest::Memory => self.memory_fault = Some((self.memory.len(), reply_fault)),
                Dest::Output => match self.exec.as_mut() {
                    // the reply has begun: the fault lands on this reading's characters
                    Some(e) if e.has_output && !e.muted => e.fault = Some(reply_fault),
                    // the reply begins with this reading
                    _ => self.pending_reply_fault.push_front(reply_fault),
                },
            }
        }
        self.disconnect || self.off_until.is_some()
    }

    pub(super) fn scheduled_faults(&mut self) {
        while self
            .faults
            .last()
            .is_some_and(|f| f.after_commands <= self.counters.commands_seen)
        {
            if let Some(f) = self.faults.pop() {
                self.inject(f.fault);
            }
        }
    }
}
