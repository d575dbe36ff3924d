//! The chamber's faults: what can go wrong, when it happens, and the state of those that
//! have happened.
//!
//! | fault | effect | on the Watlow F4 | on the Espec |
//! |---|---|---|---|
//! | `door`, `overtemp` | an alarm latched until reset | register 1061 / 1063 reads 1 (0 when clear); a write of 0 resets it | `ALARM?` lists code 5 / 1 (sim's choice, unconfirmed) |
//! | `silent` | the controller answers nothing and executes nothing from then on | no reply | no reply |
//! | `exception` | the requests hit are refused | exception reply (code 4, server device failure; or the code given to [`super::ChamberHandle::exception_on_register`] for one register) | `NA:DEVICE FAULT` |
//! | `crc` | the replies hit are corrupted on the wire | RTU: the last CRC byte inverted; TCP: the protocol identifier 0x0001 | a digit of the reply becomes `#` |
//! | `slow` | replies leave late | held back `S` sim seconds | the same |
//!
//! A fault fires at its trigger: the N-th request the chamber sees (from 1, counting every
//! request addressed to it, whatever the dialect) or a sim time; it is checked at each
//! request, so a time trigger fires at the first request at or after its time (an alarm
//! also fires at that time for a reader of the handle).
//!
//! `gyrocal sim --fault chamber:...` specs ([`crate::faults`]'s grammar) are armed here
//! (`arm`), on the chamber itself.

use crate::faults::{FaultAction, FaultSpec, Trigger};

/// An alarm the simulated chamber can latch.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ChamberAlarm {
    /// The door was opened (Watlow register 1061, Espec code 5).
    Door,
    /// The over-temperature limit tripped (Watlow register 1063, Espec code 1).
    OverTemperature,
}

impl ChamberAlarm {
    /// The alarm's Watlow F4 holding register (sim's choice; the driver's `alarm_registers`
    /// must name it with `active = 1`).
    pub fn register(self) -> u16 {
        match self {
            ChamberAlarm::Door => super::REG_ALARM_DOOR,
            ChamberAlarm::OverTemperature => super::REG_ALARM_OVERTEMP,
        }
    }

    /// The alarm's Espec `ALARM?` code (sim's choice).
    pub fn espec_code(self) -> u16 {
        match self {
            ChamberAlarm::Door => 5,
            ChamberAlarm::OverTemperature => 1,
        }
    }

    /// Its name, for messages.
    pub fn name(self) -> &'static str {
        match self {
            ChamberAlarm::Door => "door open",
            ChamberAlarm::OverTemperature => "over-temperature",
        }
    }
}

/// What a chamber fault does.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ChamberFaultKind {
    /// Latches an alarm.
    Alarm(ChamberAlarm),
    /// The controller stops answering (and executing) for good.
    Silent,
    /// `count` requests are refused with an exception (code 4) / `NA:`.
    Exception,
    /// `count` replies are corrupted on the wire.
    Corrupt,
    /// Replies are held back this many sim seconds (`count` of them; 0: every one).
    Slow(f64),
}

/// When a chamber fault fires.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ChamberTrigger {
    /// At the N-th request the chamber sees (from 1).
    Request(u64),
    /// At this sim time (s since the bench started).
    Time(f64),
}

/// A fault armed on the chamber.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChamberFault {
    /// What happens.
    pub kind: ChamberFaultKind,
    /// When.
    pub trigger: ChamberTrigger,
    /// How many requests or replies it hits (exception, crc, slow; 0 for slow: every one).
    pub count: u32,
}

/// The faults in force on the wire now.
#[derive(Debug, Default)]
pub(crate) struct WireFaults {
    pub(crate) silent: bool,
    /// Requests still to refuse with exception 4.
    pub(crate) exceptions_left: u32,
    /// A register refused with an exception code, every time.
    pub(crate) register_exceptions: Vec<(u16, u8)>,
    /// Replies still to corrupt.
    pub(crate) corrupt_left: u32,
    /// The delay of slow replies (sim s) and how many are left (`None`: every one).
    pub(crate) slow: Option<(f64, Option<u32>)>,
}

/// What happens to one request's reply.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(crate) struct Fate {
    /// No reply at all, and nothing executed.
    pub(crate) silent: bool,
    /// Refused (exception 4, `NA:`).
    pub(crate) refused: bool,
    /// The reply corrupted.
    pub(crate) corrupt: bool,
    /// The reply held back, sim s.
    pub(crate) delay_s: f64,
}

impl WireFaults {
    /// The fate of the next request (using up the faults it takes).
    pub(crate) fn next(&mut self) -> Fate {
        if self.silent {
            return Fate {
                silent: true,
                ..Fate::default()
            };
        }
        let mut fate = Fate::default();
        if self.exceptions_left > 0 {
            self.exceptions_left -= 1;
            fate.refused = true;
        } else if self.corrupt_left > 0 {
            self.corrupt_left -= 1;
            fate.corrupt = true;
        }
        if let Some((delay, left)) = self.slow {
            fate.delay_s = delay;
            match left {
                Some(n) if n <= 1 => self.slow = None,
                Some(n) => self.slow = Some((delay, Some(n - 1))),
                None => {}
            }
        }
        fate
    }

    /// The exception code a register is refused with, if any.
    pub(crate) fn register_exception(&self, first: u16, count: u16) -> Option<u8> {
        let last = u32::from(first) + u32::from(count.max(1)) - 1;
        self.register_exceptions
            .iter()
            .find(|(r, _)| (u32::from(first)..=last).contains(&u32::from(*r)))
            .map(|&(_, c)| c)
    }
}

/// The chamber fault of a `chamber:` action of `gyrocal sim --fault` (`None` for the meter's
/// and the table's actions).
fn kind_of(action: FaultAction, delay_s: Option<f64>) -> Option<ChamberFaultKind> {
    Some(match action {
        FaultAction::ChamberDoor => ChamberFaultKind::Alarm(ChamberAlarm::Door),
        FaultAction::ChamberOvertemp => ChamberFaultKind::Alarm(ChamberAlarm::OverTemperature),
        FaultAction::ChamberSilent => ChamberFaultKind::Silent,
        FaultAction::ChamberException => ChamberFaultKind::Exception,
        FaultAction::ChamberCrc => ChamberFaultKind::Corrupt,
        FaultAction::ChamberSlow => ChamberFaultKind::Slow(delay_s.unwrap_or(0.0)),
        _ => return None,
    })
}

/// Arms a `chamber:` fault spec on the bench's chamber, exact at its request or time (see
/// [`crate::faults::schedule`]); a bench without a chamber ignores it. Returns whether `spec`
/// was the chamber's (the schedule handles the others).
/// What [`arm`] did with a spec.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Arming {
    /// Not a chamber fault: the caller schedules it.
    NotChamber,
    /// Armed on the chamber (at its request count or time), or ignored by a bench without one.
    Armed,
    /// A chamber fault at a crossed trigger (a meter reading, a table demand or stop): the
    /// supervisor arms it with [`arm_now`] once that trigger is reached.
    Crossed,
}

/// Arms a chamber spec on the bench's chamber.
pub(crate) fn arm(spec: &FaultSpec, bench: &crate::bench::BenchHandle) -> Arming {
    let Some(kind) = kind_of(spec.action, spec.delay_s) else {
        return Arming::NotChamber;
    };
    let trigger = match spec.trigger {
        Trigger::Request(n) => ChamberTrigger::Request(n),
        Trigger::Time(t) => ChamberTrigger::Time(t),
        _ => return Arming::Crossed,
    };
    if let Some(c) = &bench.chamber {
        c.arm(ChamberFault {
            kind,
            trigger,
            count: spec.count,
        });
    }
    Arming::Armed
}

/// Arms a chamber spec whose crossed trigger was just reached, due at the chamber's next
/// request (or a read of its alarms). False when the spec is not a chamber fault.
pub(crate) fn arm_now(spec: &FaultSpec, chamber: &super::ChamberHandle) -> bool {
    let Some(kind) = kind_of(spec.action, spec.delay_s) else {
        return false;
    };
    chamber.arm(ChamberFault {
        kind,
        trigger: ChamberTrigger::Time(0.0),
        count: spec.count,
    });
    true
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use crate::faults::schedule;
    use std::time::Duration;

    #[test]
    fn chamber_grammar() {
        let s: FaultSpec = "chamber:door@t=3600s".parse().unwrap();
        assert_eq!(
            (s.action, s.trigger),
            (FaultAction::ChamberDoor, Trigger::Time(3600.0))
        );
        let s: FaultSpec = "chamber:crc@request10x2".parse().unwrap();
        assert_eq!(
            (s.action, s.trigger, s.count),
            (FaultAction::ChamberCrc, Trigger::Request(10), 2)
        );
        assert_eq!(s.to_string(), "chamber:crc@request10x2");
        let s: FaultSpec = "chamber:slow@t=0s/0.5s".parse().unwrap();
        assert_eq!((s.delay_s, s.count), (Some(0.5), 0));
        assert_eq!(s.to_string(), "chamber:slow@t=0s/0.5s");
        // the crossed triggers: the meter's readings, the table's demands and stops
        for (text, trigger) in [
            ("chamber:door@reading3", Trigger::Reading(3)),
            ("chamber:silent@demand1", Trigger::Demand(1)),
            ("chamber:silent@stop2", Trigger::Stop(2)),
        ] {
            let s: FaultSpec = text.parse().unwrap();
            assert_eq!(s.trigger, trigger);
            assert_eq!(s.to_string(), text);
        }
        for bad in [
            "table:trip@request3",
            "chamber:door@request3x2",
            "chamber:slow@request3",
            "chamber:melt@t=1s",
        ] {
            let e = bad.parse::<FaultSpec>().unwrap_err();
            assert_eq!(e.spec, bad, "{e}");
        }
    }

    /// Chamber specs are armed on the chamber: an alarm at its time, a silent controller at
    /// its request, and the schedule's status says which fired.
    #[tokio::test(start_paused = true)]
    async fn chamber_faults_fire_on_the_chamber() {
        let mut bench = crate::bench::Bench::spawn(crate::bench::BenchConfig {
            chamber: Some(crate::chamber::ChamberSimConfig::default()),
            ..crate::bench::BenchConfig::default()
        });
        let specs: Vec<FaultSpec> = ["chamber:overtemp@t=60s", "chamber:silent@request2"]
            .iter()
            .map(|s| s.parse().unwrap())
            .collect();
        let schedule = schedule(&specs, &bench.handle, 1.0);
        let chamber = bench.handle.chamber.clone().unwrap();
        let mut link = bench.chamber_link().unwrap();
        assert!(chamber.alarms().is_empty());
        tokio::time::sleep(Duration::from_secs(61)).await;
        assert_eq!(
            chamber.alarms(),
            [crate::chamber::ChamberAlarm::OverTemperature]
        );
        use tokio::io::{AsyncReadExt, AsyncWriteExt};
        let read_901 = [0x01, 0x03, 0x03, 0x85, 0x00, 0x01, 0x95, 0xA7];
        let mut buf = [0u8; 64];
        link.write_all(&read_901).await.unwrap();
        let n = tokio::time::timeout(Duration::from_secs(1), link.read(&mut buf))
            .await
            .unwrap()
            .unwrap();
        assert_eq!(&buf[..n], [0x01, 0x03, 0x02, 0x00, 0x01, 0x79, 0x84]);
        link.write_all(&read_901).await.unwrap();
        assert!(
            tokio::time::timeout(Duration::from_secs(1), link.read(&mut buf))
                .await
                .is_err(),
            "silent from the second request"
        );
        let status = schedule.status(&bench.handle);
        assert!(status.iter().all(|s| s.fired), "{status:?}");
    }

    /// A chamber fault at a crossed trigger (here the table's second demand) is armed by the
    /// supervisor once the trigger is reached: no alarm before it, the alarm latched after it.
    #[tokio::test(start_paused = true)]
    async fn a_chamber_fault_at_a_table_demand_fires_after_that_demand() {
        use gyrocal_link::Transport;
        let mut bench = crate::bench::Bench::spawn(crate::bench::BenchConfig {
            chamber: Some(crate::chamber::ChamberSimConfig::default()),
            ..crate::bench::BenchConfig::default()
        });
        let specs: Vec<FaultSpec> = vec!["chamber:door@demand2".parse().unwrap()];
        let schedule = schedule(&specs, &bench.handle, 1.0);
        let chamber = bench.handle.chamber.clone().unwrap();
        let link = &mut bench.table;
        for c in [":Interlock:Close 1", ":Mode:Rate 1", ":Demand:Rate 5"] {
            link.send_line(c).await.unwrap();
        }
        tokio::time::sleep(Duration::from_secs(5)).await;
        assert!(chamber.alarms().is_empty(), "fired before its demand");
        assert!(!schedule.status(&bench.handle)[0].fired);
        link.send_line(":Demand:Rate 0").await.unwrap();
        tokio::time::sleep(Duration::from_millis(100)).await;
        assert_eq!(chamber.alarms(), [crate::chamber::ChamberAlarm::Door]);
        assert!(schedule.status(&bench.handle)[0].fired);
    }
}
