//! Fault schedules for a running bench, from a small text grammar (`gyrocal sim --fault`).
//!
//! ```text
//! spec    = device ":" action "@" trigger [ "x" count ] [ "/" S ["s"] ]
//! device  = "dmm" | "table" | "chamber"
//! action  = dmm:   "timeout" | "garble" | "truncate" | "overload" | "disconnect" | "powercycle"
//!                  | "slow"
//!           table: "trip" | "fault" | "silent" | "interlock" | "drop" | "garble" | "noise"
//!                  | "slow"
//!           chamber: "door" | "overtemp" | "silent" | "exception" | "crc" | "slow"
//! trigger = "reading" N        the N-th reading the meter takes (N >= 1)
//!         | "request" N        the N-th request the chamber sees (N >= 1)
//!         | "demand" N         the N-th `:Demand:Rate` the table sees (N >= 1)
//!         | "stop" N           the N-th stop command the table sees (ACL `:Mode:Off` or
//!                              `:Interlock:Open`, Aerosmith `STO`; N >= 1)
//!         | "t=" S ["s"]       S sim seconds after the bench started (S >= 0)
//! count   = N >= 1, default 1: for overload the number of overload readings, for timeout,
//!           garble and truncate the number of consecutive replies (readings) hit; for the
//!           table's drop, garble and noise the number of consecutive query replies hit; not
//!           allowed for disconnect, powercycle and the other table actions; for slow the
//!           number of replies held back (without it: every reply from the trigger on)
//! "/" S   powercycle: the off time in sim seconds (default the meter's `power_off_s`, 5);
//!         slow (required): how long each reply is held back, sim seconds
//! ```
//!
//! Examples: `dmm:timeout@reading100` (the reply carrying reading 100 never comes),
//! `dmm:garble@reading100`, `dmm:overload@reading50x5` (readings 50 to 54 are overloads),
//! `dmm:disconnect@reading300` (the meter drops its link for good instead of taking reading
//! 300), `dmm:powercycle@reading250/8s` (the meter is switched off for 8 sim seconds instead
//! of taking reading 250, and comes back in LOCAL with its power-on settings and an empty
//! memory), `table:trip@demand4` (a rate trip latched halfway through the 4th demand's ramp),
//! `table:fault@t=12s`, `table:silent@demand3` (the table ignores the 3rd demand and everything
//! after it), `table:interlock@demand2` (the door opens halfway through the 2nd demand's ramp),
//! `table:drop@t=5s` (the next reply the table sends after 5 s is lost),
//! `table:garble@demand3x2`, `table:noise@reading40`, `table:silent@stop1` (the table ignores
//! the first stop it is sent and everything after it: it keeps turning, or holding, as it was),
//! `dmm:slow@reading40/2.5s` (every reply
//! from the one carrying reading 40 on leaves 2.5 sim seconds late), `dmm:slow@t=10sx3/4s`
//! (the next three replies after 10 s are 4 s late), `table:slow@demand2/0.5s`.
//!
//! `slow` is a reply that comes, but late: a controller busy with something else, a serial
//! converter with a deep buffer, a network bridge. The instrument is alive and obeys; its
//! bytes reach the host `S` seconds after it sent them. On the 34401A (RS-232 or GPIB) the
//! held-back bytes are already on their way (in the converter): a device clear does not
//! recall them, so a driver that gave up on a reply must recognise it when it comes late. On
//! a Truevolt's socket the instrument sends its reply `S` seconds late on the connection the
//! query came on; a reconnect (the socket's device clear) drops what the old connection was
//! owed. The table executes every command when it arrives and sends its replies `S` seconds
//! late, in order ([`crate::table::TableHandle::hold_replies`]).
//!
//! What the actions do: `timeout` loses a reply (the meter says nothing), `garble` replaces a
//! digit of a reply by `#`, `truncate` cuts a reply halfway without its terminator, `overload`
//! makes readings ±9.9E37, `disconnect` closes the meter's end of its link and stops it,
//! `powercycle` switches the meter off and on ([`crate::dmm::Fault::PowerCycle`]); `trip`
//! latches a rate trip (error 210), `fault` an injected fault (error 220), `silent` makes the
//! table stop answering and executing anything (it keeps turning as it was); `interlock` opens
//! the interlock as a door or a hardware interlock would (abort profile to zero, servo off,
//! mode ABORT then OFF, bit 0 of `*STB?` set, error 201 `"Interlock open"` queued, latched until
//! `:Interlock:Reset`); the table's link faults hit the next query replies, after the query was
//! executed: `drop` sends no reply line, `garble` replaces one character (the first digit, else
//! the first character) by `#`, `noise` writes the byte 0xFF just before the reply (a glitch on
//! a serial line; the reply then reads with a junk prefix and is not valid text). Commands have
//! no reply and never use up a link fault. These are the faults a driver must retry (ask again)
//! rather than give up on, so they do not end a run that retries.
//!
//! How they fire: a meter action on a `reading` trigger and a table action on a `demand`
//! trigger are armed on the instrument itself and fire exactly there
//! ([`crate::dmm::DmmHandle::inject_at_reading`], [`crate::table::TableHandle::arm_at_demand`]).
//! Time triggers and the crossed ones (a meter action at a table demand, a table action at a
//! meter reading) fire from a supervisor task within a few milliseconds of their moment: a
//! meter action then hits the next reply (or the next readings), a table trip, fault or
//! interlock opening latches at once, whatever the rate, and a table link fault hits the next
//! replies. At `demandN` a table trip, fault or interlock opening latches halfway through that
//! demand's ramp, and a link fault hits the replies that follow the demand (typically the
//! driver's error-queue check).
//!
//! Chamber faults ([`crate::chamber::faults`]) are armed on the chamber itself and fire at
//! the first request at or after their trigger (`requestN` or `t=Ss`; at a crossed trigger,
//! `readingN`, `demandN` or `stopN`, the supervisor arms them for the chamber's next request
//! once the trigger is reached, so a test can place a chamber fault in a given step of a
//! run whatever the wall time the run took to get there): `door` and `overtemp`
//! latch an alarm until reset, `silent` stops the controller for good, `exception` refuses
//! COUNT requests (Modbus exception 4, Espec `NA:`), `crc` corrupts COUNT replies, `slow`
//! holds replies back by `/Ss`. Examples: `chamber:door@t=3600s`, `chamber:silent@request40`,
//! `chamber:crc@request10x2`, `chamber:slow@t=0s/0.5s`, `chamber:door@reading50` (the door
//! opens once the meter has taken its 50th reading), `chamber:silent@stop1`. A bench without
//! a chamber ignores them.

use std::fmt;
use std::str::FromStr;
use std::time::Duration;

use tokio::task::JoinHandle;
use tokio::time::Instant;

use crate::bench::BenchHandle;
use crate::dmm::Fault;
use crate::table::{DemandFault, ReplyFault};

/// The grammar, for command-line help.
pub const GRAMMAR: &str = "\
SPEC = DEVICE:ACTION@TRIGGER[xCOUNT][/Ss]
  dmm actions:   timeout (a reply never comes), garble (a digit of a reply becomes #),
                 truncate (a reply stops halfway), overload (readings are +-9.9E37),
                 disconnect (the meter closes its link and is gone for good),
                 powercycle (the meter is off for 5 s, or /Ss, then back in LOCAL
                 with power-on settings and an empty memory),
                 slow (every reply is held back by /Ss, which is required: the
                 meter answers, late; a device clear does not recall bytes on
                 their way)
  table actions: trip (rate trip, error 210), fault (injected fault, error 220),
                 silent (the table answers and executes nothing more),
                 interlock (the interlock opens: abort to zero, servo off, error 201),
                 drop (a query reply is lost), garble (a character of a reply
                 becomes #), noise (a 0xFF byte comes just before a reply),
                 slow (every reply held back by /Ss, which is required: the
                 table executes commands at once and answers late, in order)
  chamber actions: door, overtemp (an alarm latched until reset), silent (the
                 controller answers nothing more), exception (COUNT requests
                 refused: Modbus exception 4 / Espec NA:), crc (COUNT replies
                 corrupted), slow (replies held back by /Ss, required)
  triggers:      readingN (the N-th reading the meter takes), demandN (the N-th
                 :Demand:Rate the table sees), stopN (the N-th stop command the
                 table sees: table:silent@stop1 ignores the first stop), requestN
                 (the N-th request the chamber sees), t=Ss (S sim seconds after start);
                 a chamber action at readingN, demandN or stopN hits the chamber's
                 next request after it (chamber:door@reading50)
  xCOUNT:        overload: that many readings; timeout/garble/truncate: that many
                 consecutive replies (readings); table drop/garble/noise: that many
                 consecutive query replies; slow: that many replies held back
                 (without xCOUNT: every reply from the trigger on)
  /Ss:           powercycle: off for S sim seconds (default 5); slow: each reply
                 held back by S sim seconds (required)
  examples: dmm:garble@reading100  dmm:overload@reading50x5  dmm:disconnect@reading300
            dmm:powercycle@reading250  dmm:powercycle@t=30s/10s
            dmm:slow@reading40/2.5s  dmm:slow@t=10sx3/4s  table:slow@demand2/0.5s
            table:trip@demand4  table:fault@t=12s  table:silent@demand3
            table:interlock@demand2  table:drop@t=5s  table:garble@demand3x2";

/// What a fault does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum FaultAction {
    /// The meter loses a reply.
    DmmTimeout,
    /// A digit of a meter reply becomes `#`.
    DmmGarble,
    /// A meter reply stops halfway, without its terminator.
    DmmTruncate,
    /// Meter readings are overloads.
    DmmOverload,
    /// The meter closes its link and stops for good.
    DmmDisconnect,
    /// The meter is switched off and on again.
    DmmPowerCycle,
    /// The meter's replies are held back (they come, late).
    DmmSlow,
    /// The table latches a rate trip.
    TableTrip,
    /// The table latches an injected fault.
    TableFault,
    /// The table stops answering and executing.
    TableSilent,
    /// The table's interlock opens (door, hardware interlock).
    TableInterlock,
    /// Table query replies are lost.
    TableDrop,
    /// A character of table query replies becomes `#`.
    TableGarble,
    /// A noise byte (0xFF) comes just before table query replies.
    TableNoise,
    /// The table's replies are held back (they come, late, in order).
    TableSlow,
    /// The chamber latches a door-open alarm.
    ChamberDoor,
    /// The chamber latches an over-temperature alarm.
    ChamberOvertemp,
    /// The chamber's controller stops answering.
    ChamberSilent,
    /// Chamber requests are refused with an exception.
    ChamberException,
    /// Chamber replies are corrupted.
    ChamberCrc,
    /// Chamber replies are held back.
    ChamberSlow,
}

impl FaultAction {
    /// The `device:action` text.
    pub fn as_str(self) -> &'static str {
        match self {
            FaultAction::DmmTimeout => "dmm:timeout",
            FaultAction::DmmGarble => "dmm:garble",
            FaultAction::DmmTruncate => "dmm:truncate",
            FaultAction::DmmOverload => "dmm:overload",
            FaultAction::DmmDisconnect => "dmm:disconnect",
            FaultAction::DmmPowerCycle => "dmm:powercycle",
            FaultAction::DmmSlow => "dmm:slow",
            FaultAction::TableTrip => "table:trip",
            FaultAction::TableFault => "table:fault",
            FaultAction::TableSilent => "table:silent",
            FaultAction::TableInterlock => "table:interlock",
            FaultAction::TableDrop => "table:drop",
            FaultAction::TableGarble => "table:garble",
            FaultAction::TableNoise => "table:noise",
            FaultAction::TableSlow => "table:slow",
            FaultAction::ChamberDoor => "chamber:door",
            FaultAction::ChamberOvertemp => "chamber:overtemp",
            FaultAction::ChamberSilent => "chamber:silent",
            FaultAction::ChamberException => "chamber:exception",
            FaultAction::ChamberCrc => "chamber:crc",
            FaultAction::ChamberSlow => "chamber:slow",
        }
    }

    /// Whether the simulator implements the action; the grammar is defined for more (a
    /// spec naming one that is not is refused with this message).
    pub fn implemented(self) -> Result<(), &'static str> {
        Ok(())
    }

    /// Whether the action takes `/Ss` (and whether it must).
    fn takes_seconds(self) -> (bool, bool) {
        match self {
            FaultAction::DmmPowerCycle => (true, false),
            FaultAction::DmmSlow | FaultAction::TableSlow | FaultAction::ChamberSlow => {
                (true, true)
            }
            _ => (false, false),
        }
    }

    fn takes_count(self) -> bool {
        matches!(
            self,
            FaultAction::DmmTimeout
                | FaultAction::DmmGarble
                | FaultAction::DmmTruncate
                | FaultAction::DmmOverload
                | FaultAction::TableDrop
                | FaultAction::TableGarble
                | FaultAction::TableNoise
                | FaultAction::DmmSlow
                | FaultAction::TableSlow
                | FaultAction::ChamberException
                | FaultAction::ChamberCrc
                | FaultAction::ChamberSlow
        )
    }

    fn is_chamber(self) -> bool {
        self.as_str().starts_with("chamber:")
    }

    fn is_dmm(self) -> bool {
        self.as_str().starts_with("dmm:")
    }

    /// The meter faults a spec injects (`count` of them, or one overload of `count`; `off_s`
    /// for a power cycle; one slow fault for `count` replies, every one when `count` is 0).
    fn dmm_faults(self, count: u32, off_s: Option<f64>, delay_s: Option<f64>) -> Vec<Fault> {
        let one = match self {
            FaultAction::DmmSlow => {
                return vec![Fault::Slow {
                    delay_s: delay_s.unwrap_or(0.0),
                    replies: (count > 0).then_some(count),
                }];
            }
            FaultAction::DmmTimeout => Fault::NoReply,
            FaultAction::DmmGarble => Fault::Garble,
            FaultAction::DmmTruncate => Fault::Truncate,
            FaultAction::DmmOverload => return vec![Fault::Overload { readings: count }],
            FaultAction::DmmDisconnect => return vec![Fault::Disconnect],
            FaultAction::DmmPowerCycle => return vec![Fault::PowerCycle { off_s }],
            _ => return Vec::new(),
        };
        vec![one; usize::try_from(count).unwrap_or(1)]
    }

    /// The reply fault of a table link action.
    fn reply_fault(self) -> Option<ReplyFault> {
        match self {
            FaultAction::TableDrop => Some(ReplyFault::Drop),
            FaultAction::TableGarble => Some(ReplyFault::Garble),
            FaultAction::TableNoise => Some(ReplyFault::Noise),
            _ => None,
        }
    }

    fn demand_fault(self, count: u32) -> Option<DemandFault> {
        match self {
            FaultAction::TableTrip => Some(DemandFault::Trip),
            FaultAction::TableFault => Some(DemandFault::Fault),
            FaultAction::TableSilent => Some(DemandFault::Silent),
            FaultAction::TableInterlock => Some(DemandFault::Interlock),
            a => a.reply_fault().map(|f| DemandFault::Reply(f, count)),
        }
    }
}

/// When a fault fires.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Trigger {
    /// At the N-th reading the meter takes (from 1).
    Reading(u64),
    /// At the N-th `:Demand:Rate` the table sees (from 1).
    Demand(u64),
    /// At the N-th stop command the table sees (from 1).
    Stop(u64),
    /// At the N-th request the chamber sees (from 1).
    Request(u64),
    /// This many sim seconds after the bench started.
    Time(f64),
}

impl fmt::Display for Trigger {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Trigger::Reading(n) => write!(f, "reading{n}"),
            Trigger::Demand(n) => write!(f, "demand{n}"),
            Trigger::Stop(n) => write!(f, "stop{n}"),
            Trigger::Request(n) => write!(f, "request{n}"),
            Trigger::Time(s) => write!(f, "t={s}s"),
        }
    }
}

/// One parsed fault spec, such as `dmm:overload@reading50x5`.
#[derive(Debug, Clone, PartialEq)]
pub struct FaultSpec {
    /// What happens.
    pub action: FaultAction,
    /// When.
    pub trigger: Trigger,
    /// How many (see the grammar); 1 unless given, except for `slow`: 0 unless given (every
    /// reply from the trigger on).
    pub count: u32,
    /// `dmm:powercycle` only: the off time in sim seconds (`/Ss`); `None` is the meter's
    /// configured `power_off_s`.
    pub off_s: Option<f64>,
    /// `slow` only: how long each reply is held back, sim seconds (`/Ss`, required).
    pub delay_s: Option<f64>,
}

impl fmt::Display for FaultSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}@{}", self.action.as_str(), self.trigger)?;
        let slow = matches!(
            self.action,
            FaultAction::DmmSlow | FaultAction::TableSlow | FaultAction::ChamberSlow
        );
        if (slow && self.count != 0) || (!slow && self.count != 1) {
            write!(f, "x{}", self.count)?;
        }
        if let Some(s) = self.off_s.or(self.delay_s) {
            write!(f, "/{s}s")?;
        }
        Ok(())
    }
}

/// A spec that does not follow the grammar; the message names the spec.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("fault spec `{spec}`: {reason}")]
pub struct FaultSpecError {
    /// The spec as given.
    pub spec: String,
    /// What is wrong with it.
    pub reason: String,
}

fn positive(text: &str, what: &str) -> Result<u64, String> {
    match text.parse::<u64>() {
        Ok(n) if n >= 1 => Ok(n),
        _ => Err(format!("{what} must be a whole number >= 1, not `{text}`")),
    }
}

impl FromStr for FaultSpec {
    type Err = FaultSpecError;

    fn from_str(spec: &str) -> Result<Self, Self::Err> {
        let err = |reason: String| FaultSpecError {
            spec: spec.to_string(),
            reason,
        };
        let text = spec.trim().to_ascii_lowercase();
        let (what, when) = text.split_once('@').ok_or_else(|| {
            err("expected DEVICE:ACTION@TRIGGER, such as dmm:garble@reading100".into())
        })?;
        let action = match what.trim() {
            "dmm:timeout" => FaultAction::DmmTimeout,
            "dmm:garble" => FaultAction::DmmGarble,
            "dmm:truncate" => FaultAction::DmmTruncate,
            "dmm:overload" => FaultAction::DmmOverload,
            "dmm:disconnect" => FaultAction::DmmDisconnect,
            "dmm:powercycle" => FaultAction::DmmPowerCycle,
            "dmm:slow" => FaultAction::DmmSlow,
            "table:trip" => FaultAction::TableTrip,
            "table:fault" => FaultAction::TableFault,
            "table:silent" => FaultAction::TableSilent,
            "table:interlock" => FaultAction::TableInterlock,
            "table:drop" => FaultAction::TableDrop,
            "table:garble" => FaultAction::TableGarble,
            "table:noise" => FaultAction::TableNoise,
            "table:slow" => FaultAction::TableSlow,
            "chamber:door" => FaultAction::ChamberDoor,
            "chamber:overtemp" => FaultAction::ChamberOvertemp,
            "chamber:silent" => FaultAction::ChamberSilent,
            "chamber:exception" => FaultAction::ChamberException,
            "chamber:crc" => FaultAction::ChamberCrc,
            "chamber:slow" => FaultAction::ChamberSlow,
            other => {
                return Err(err(format!(
                    "unknown action `{other}` (dmm: timeout, garble, truncate, overload, \
                     disconnect, powercycle, slow; table: trip, fault, silent, interlock, \
                     drop, garble, noise, slow; chamber: door, overtemp, silent, exception, \
                     crc, slow)"
                )));
            }
        };
        let (takes_seconds, needs_seconds) = action.takes_seconds();
        let what_seconds = if action == FaultAction::DmmPowerCycle {
            "the off time"
        } else {
            "the delay"
        };
        let (when, seconds) = match when.trim().rsplit_once('/') {
            Some(_) if !takes_seconds => {
                return Err(err(format!(
                    "{} takes no time (/Ss is for dmm:powercycle and slow)",
                    action.as_str()
                )));
            }
            Some((w, s)) => match s.strip_suffix('s').unwrap_or(s).parse::<f64>() {
                Ok(v) if (0.0..1e6).contains(&v) && !(needs_seconds && v == 0.0) => (w, Some(v)),
                _ => {
                    return Err(err(format!(
                        "{what_seconds} must be sim seconds {}, such as /8s, not `/{s}`",
                        if needs_seconds { "> 0" } else { ">= 0" }
                    )));
                }
            },
            None if needs_seconds => {
                return Err(err(format!(
                    "{} needs the delay of each reply, such as {}@{}/2.5s",
                    action.as_str(),
                    action.as_str(),
                    when.trim()
                )));
            }
            None => (when.trim(), None),
        };
        let (off_s, delay_s) = if action == FaultAction::DmmPowerCycle {
            (seconds, None)
        } else {
            (None, seconds)
        };
        let (trigger_text, count) = match when.rsplit_once('x') {
            Some((t, c)) => (t, Some(positive(c, "the count").map_err(err)?)),
            None => (when, None),
        };
        let trigger = if let Some(n) = trigger_text.strip_prefix("reading") {
            Trigger::Reading(positive(n, "the reading number").map_err(err)?)
        } else if let Some(n) = trigger_text.strip_prefix("demand") {
            Trigger::Demand(positive(n, "the demand number").map_err(err)?)
        } else if let Some(n) = trigger_text.strip_prefix("stop") {
            Trigger::Stop(positive(n, "the stop number").map_err(err)?)
        } else if let Some(n) = trigger_text.strip_prefix("request") {
            Trigger::Request(positive(n, "the request number").map_err(err)?)
        } else if let Some(s) = trigger_text.strip_prefix("t=") {
            let s = s.strip_suffix('s').unwrap_or(s);
            match s.parse::<f64>() {
                Ok(v) if (0.0..1e9).contains(&v) => Trigger::Time(v),
                _ => {
                    return Err(err(format!(
                        "the time must be sim seconds >= 0, such as t=12s, not `{trigger_text}`"
                    )));
                }
            }
        } else {
            return Err(err(format!(
                "unknown trigger `{trigger_text}` (readingN, demandN, stopN, requestN or t=Ss)"
            )));
        };
        let count = match count {
            None if takes_seconds && needs_seconds => 0,
            None => 1,
            Some(_) if !action.takes_count() => {
                return Err(err(format!("{} takes no count", action.as_str())));
            }
            Some(c) => u32::try_from(c)
                .ok()
                .filter(|&c| c <= 100_000)
                .ok_or_else(|| err(format!("count {c} is above 100000")))?,
        };
        action.implemented().map_err(|why| err(why.to_string()))?;
        // a chamber action may fire at any trigger (the crossed ones through the supervisor);
        // the chamber's request count is its own
        if !action.is_chamber() && matches!(trigger, Trigger::Request(_)) {
            return Err(err("requestN is a chamber trigger".to_string()));
        }
        Ok(FaultSpec {
            action,
            trigger,
            count,
            off_s,
            delay_s,
        })
    }
}

/// Whether each spec of a schedule has been triggered, for reports.
#[derive(Debug, Clone, PartialEq)]
pub struct FaultStatus {
    /// The spec, in its canonical form.
    pub spec: String,
    /// Whether its trigger has been reached.
    pub fired: bool,
}

/// A schedule armed on a bench: see [`schedule`].
#[derive(Debug)]
pub struct FaultSchedule {
    specs: Vec<FaultSpec>,
    started: Instant,
    time_scale: f64,
    supervisor: Option<JoinHandle<()>>,
}

impl FaultSchedule {
    /// Where each spec stands now.
    pub fn status(&self, bench: &BenchHandle) -> Vec<FaultStatus> {
        let readings = bench.dmm.readings_taken();
        let demands = bench.table.demands_seen();
        let stops = bench.table.stops_seen();
        let requests = bench.chamber.as_ref().map_or(0, |c| c.requests_seen());
        let sim_s = self.started.elapsed().as_secs_f64() * self.time_scale;
        let dmm_gone = bench.dmm.is_finished();
        let dmm_stats = bench.dmm.stats();
        let power_cycling = dmm_stats.power_cycles > 0 || !dmm_stats.powered;
        self.specs
            .iter()
            .map(|s| {
                let fired = match s.trigger {
                    Trigger::Reading(n) => {
                        readings >= n
                            || (s.action == FaultAction::DmmDisconnect
                                && dmm_gone
                                && readings + 1 >= n)
                            || (s.action == FaultAction::DmmPowerCycle
                                && power_cycling
                                && readings + 1 >= n)
                    }
                    Trigger::Demand(n) => demands >= n,
                    Trigger::Stop(n) => stops >= n,
                    Trigger::Request(n) => requests >= n,
                    Trigger::Time(t) => sim_s >= t,
                };
                FaultStatus {
                    spec: s.to_string(),
                    fired,
                }
            })
            .collect()
    }

    /// Stops the supervisor (faults not yet fired by it never fire).
    pub fn stop(&mut self) {
        if let Some(t) = self.supervisor.take() {
            t.abort();
        }
    }
}

impl Drop for FaultSchedule {
    fn drop(&mut self) {
        self.stop();
    }
}

/// How often the supervisor looks at the counters for crossed triggers.
const POLL: Duration = Duration::from_millis(2);

/// Arms `specs` on a bench that started just now, whose instruments run `time_scale` sim
/// seconds per real second. Exact triggers are armed on the instruments; the others are
/// watched by a supervisor task (spawned only if needed; inside a tokio runtime).
pub fn schedule(specs: &[FaultSpec], bench: &BenchHandle, time_scale: f64) -> FaultSchedule {
    let time_scale = if time_scale.is_finite() && time_scale > 0.0 {
        time_scale
    } else {
        1.0
    };
    let started = Instant::now();
    let mut pending: Vec<FaultSpec> = Vec::new();
    for s in specs {
        // armed on the chamber itself, exact at its request or time; at a meter reading, a
        // table demand or stop, armed by the supervisor once that trigger is reached
        match crate::chamber::faults::arm(s, bench) {
            crate::chamber::faults::Arming::NotChamber => {}
            crate::chamber::faults::Arming::Armed => continue,
            crate::chamber::faults::Arming::Crossed => {
                pending.push(s.clone());
                continue;
            }
        }
        match (s.trigger, s.action.is_dmm()) {
            (Trigger::Reading(n), true) => {
                for (i, f) in s
                    .action
                    .dmm_faults(s.count, s.off_s, s.delay_s)
                    .into_iter()
                    .enumerate()
                {
                    let offset = if matches!(f, Fault::Overload { .. }) {
                        0
                    } else {
                        i as u64
                    };
                    bench.dmm.inject_at_reading(n + offset, f);
                }
            }
            (Trigger::Demand(n), false) if s.action.demand_fault(s.count).is_some() => {
                if let Some(f) = s.action.demand_fault(s.count) {
                    bench.table.arm_at_demand(n, f);
                }
            }
            (Trigger::Stop(n), false) if s.action == FaultAction::TableSilent => {
                bench.table.arm_silent_at_stop(n);
            }
            _ => pending.push(s.clone()),
        }
    }
    let supervisor = (!pending.is_empty()).then(|| {
        let dmm_faults = bench.dmm.injector();
        let table = bench.table.clone();
        let chamber = bench.chamber.clone();
        let message = table.config().faults.message;
        tokio::spawn(async move {
            let mut left = pending;
            while !left.is_empty() {
                let sim_s = started.elapsed().as_secs_f64() * time_scale;
                let readings = dmm_faults.readings_taken();
                let demands = table.demands_seen();
                let stops = table.stops_seen();
                left.retain(|s| {
                    let due = match s.trigger {
                        Trigger::Reading(n) => readings >= n,
                        Trigger::Demand(n) => demands >= n,
                        Trigger::Stop(n) => stops >= n,
                        // chamber specs never reach the supervisor
                        Trigger::Request(_) => false,
                        Trigger::Time(t) => sim_s >= t,
                    };
                    if !due {
                        return true;
                    }
                    tracing::info!(spec = %s, "fault fires");
                    if let Some(c) = &chamber
                        && crate::chamber::faults::arm_now(s, c)
                    {
                        return false;
                    }
                    match s.action {
                        FaultAction::TableTrip => table.trip(),
                        FaultAction::TableFault => table.inject_fault(&message),
                        FaultAction::TableSilent => table.set_silent(true),
                        FaultAction::TableInterlock => table.open_interlock(),
                        FaultAction::TableSlow => table.hold_replies(
                            table.sim_duration(s.delay_s.unwrap_or(0.0)),
                            (s.count > 0).then_some(s.count),
                        ),
                        a => {
                            if let Some(f) = a.reply_fault() {
                                table.inject_reply_faults(f, s.count);
                            }
                            for f in a.dmm_faults(s.count, s.off_s, s.delay_s) {
                                dmm_faults.inject(f);
                            }
                        }
                    }
                    false
                });
                tokio::time::sleep(POLL).await;
            }
        })
    });
    FaultSchedule {
        specs: specs.to_vec(),
        started,
        time_scale,
        supervisor,
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn grammar() {
        let s: FaultSpec = "dmm:overload@reading50x5".parse().unwrap();
        assert_eq!(s.action, FaultAction::DmmOverload);
        assert_eq!(s.trigger, Trigger::Reading(50));
        assert_eq!(s.count, 5);
        assert_eq!(s.to_string(), "dmm:overload@reading50x5");
        let s: FaultSpec = " Table:Fault@t=12s ".parse().unwrap();
        assert_eq!(s.trigger, Trigger::Time(12.0));
        assert_eq!(s.to_string(), "table:fault@t=12s");
        let s: FaultSpec = "table:silent@demand3".parse().unwrap();
        assert_eq!(
            (s.action, s.trigger),
            (FaultAction::TableSilent, Trigger::Demand(3))
        );
        assert_eq!(
            "dmm:timeout@t=0.5".parse::<FaultSpec>().unwrap().trigger,
            Trigger::Time(0.5)
        );
        let s: FaultSpec = "dmm:powercycle@reading250".parse().unwrap();
        assert_eq!(
            (s.action, s.trigger, s.count, s.off_s),
            (FaultAction::DmmPowerCycle, Trigger::Reading(250), 1, None)
        );
        assert_eq!(s.to_string(), "dmm:powercycle@reading250");
        let s: FaultSpec = "DMM:PowerCycle@t=30s/7.5s".parse().unwrap();
        assert_eq!((s.trigger, s.off_s), (Trigger::Time(30.0), Some(7.5)));
        assert_eq!(s.to_string(), "dmm:powercycle@t=30s/7.5s");
        assert_eq!(
            s.action.dmm_faults(1, s.off_s, None),
            [Fault::PowerCycle { off_s: Some(7.5) }]
        );
        assert_eq!(
            "dmm:powercycle@demand3/0"
                .parse::<FaultSpec>()
                .unwrap()
                .off_s,
            Some(0.0)
        );
        for bad in [
            "",
            "dmm:garble",
            "dmm:melt@reading1",
            "dmm:garble@reading0",
            "dmm:garble@reading-1",
            "dmm:garble@step3",
            "table:trip@demand4x2",
            "dmm:disconnect@reading3x2",
            "dmm:overload@reading3x0",
            "dmm:powercycle@reading3x2",
            "dmm:powercycle@reading3/-1s",
            "dmm:powercycle@reading3/soon",
            "dmm:timeout@reading3/5s",
            "dmm:timeout@t=-1s",
            "dmm:timeout@t=nan",
            "dmm:timeout@t=infs",
        ] {
            let e = bad.parse::<FaultSpec>().unwrap_err();
            assert_eq!(e.spec, bad);
            assert!(e.to_string().contains(&format!("`{bad}`")), "{e}");
        }
    }

    #[test]
    fn table_link_and_interlock_specs() {
        for (text, action, trigger, count) in [
            (
                "table:interlock@demand2",
                FaultAction::TableInterlock,
                Trigger::Demand(2),
                1,
            ),
            (
                "table:interlock@t=3s",
                FaultAction::TableInterlock,
                Trigger::Time(3.0),
                1,
            ),
            (
                "table:drop@reading40",
                FaultAction::TableDrop,
                Trigger::Reading(40),
                1,
            ),
            (
                "table:drop@t=5sx3",
                FaultAction::TableDrop,
                Trigger::Time(5.0),
                3,
            ),
            (
                "table:garble@demand3x2",
                FaultAction::TableGarble,
                Trigger::Demand(3),
                2,
            ),
            (
                "TABLE:NOISE@demand1",
                FaultAction::TableNoise,
                Trigger::Demand(1),
                1,
            ),
        ] {
            let s: FaultSpec = text.parse().unwrap();
            assert_eq!(
                (s.action, s.trigger, s.count),
                (action, trigger, count),
                "{text}"
            );
            // the canonical form parses back to the same spec
            assert_eq!(s.to_string().parse::<FaultSpec>().unwrap(), s);
        }
        assert_eq!(
            "table:garble@demand3x2"
                .parse::<FaultSpec>()
                .unwrap()
                .to_string(),
            "table:garble@demand3x2"
        );
        for (bad, names) in [
            (
                "table:interlock@demand2x2",
                "table:interlock takes no count",
            ),
            (
                "table:drop@demand0",
                "the demand number must be a whole number >= 1",
            ),
            (
                "table:noise@demand1x0",
                "the count must be a whole number >= 1",
            ),
            (
                "table:garble@demand1x200000",
                "count 200000 is above 100000",
            ),
            ("table:jam@demand1", "unknown action `table:jam`"),
            ("table:drop", "expected DEVICE:ACTION@TRIGGER"),
            ("table:drop@step2", "unknown trigger `step2`"),
        ] {
            let e = bad.parse::<FaultSpec>().unwrap_err();
            let msg = e.to_string();
            assert!(msg.contains(&format!("`{bad}`")), "{msg}");
            assert!(msg.contains(names), "{bad}: {msg}");
        }
        // the help lists every table action
        for a in ["interlock", "drop", "garble", "noise"] {
            assert!(GRAMMAR.contains(a), "{a}");
        }
    }

    #[test]
    fn slow_specs() {
        let s: FaultSpec = "dmm:slow@reading40/2.5s".parse().unwrap();
        assert_eq!(
            (s.action, s.trigger, s.count, s.delay_s, s.off_s),
            (
                FaultAction::DmmSlow,
                Trigger::Reading(40),
                0,
                Some(2.5),
                None
            )
        );
        assert_eq!(s.to_string(), "dmm:slow@reading40/2.5s");
        assert_eq!(
            s.action.dmm_faults(s.count, s.off_s, s.delay_s),
            [Fault::Slow {
                delay_s: 2.5,
                replies: None
            }]
        );
        let s: FaultSpec = "DMM:Slow@t=10sx3/4".parse().unwrap();
        assert_eq!(
            (s.trigger, s.count, s.delay_s),
            (Trigger::Time(10.0), 3, Some(4.0))
        );
        assert_eq!(s.to_string(), "dmm:slow@t=10sx3/4s");
        assert_eq!(s.to_string().parse::<FaultSpec>().unwrap(), s);
        assert_eq!(
            s.action.dmm_faults(s.count, s.off_s, s.delay_s),
            [Fault::Slow {
                delay_s: 4.0,
                replies: Some(3)
            }]
        );
        let s: FaultSpec = "dmm:slow@demand2x1/0.5s".parse().unwrap();
        assert_eq!(s.to_string(), "dmm:slow@demand2x1/0.5s");
        for (bad, names) in [
            (
                "dmm:slow@reading40",
                "dmm:slow needs the delay of each reply",
            ),
            ("dmm:slow@reading40/0s", "the delay must be sim seconds > 0"),
            (
                "dmm:slow@reading40/-1s",
                "the delay must be sim seconds > 0",
            ),
            (
                "dmm:slow@reading40x0/1s",
                "the count must be a whole number >= 1",
            ),
            ("table:slow@demand2", "table:slow needs the delay"),
            ("dmm:garble@reading4/1s", "dmm:garble takes no time"),
        ] {
            let e = bad.parse::<FaultSpec>().unwrap_err();
            let msg = e.to_string();
            assert!(msg.contains(&format!("`{bad}`")), "{msg}");
            assert!(msg.contains(names), "{bad}: {msg}");
        }
        assert!(GRAMMAR.contains("slow (every reply is held back by /Ss"));
        assert!(GRAMMAR.contains("dmm:slow@reading40/2.5s"));
    }

    #[tokio::test(start_paused = true)]
    async fn table_faults_fire_from_the_schedule() {
        use crate::bench::{Bench, BenchConfig};
        use crate::table::SimMode;
        use gyrocal_link::Transport;

        let mut bench = Bench::spawn(BenchConfig::default());
        let specs: Vec<FaultSpec> = ["table:drop@t=1sx2", "table:interlock@t=2s"]
            .iter()
            .map(|s| s.parse().unwrap())
            .collect();
        let mut schedule = schedule(&specs, &bench.handle, 1.0);
        let link = &mut bench.table;
        for c in [":Interlock:Close 1", ":Mode:Rate 1"] {
            link.send_line(c).await.unwrap();
        }
        let t = Some(Duration::from_millis(100));
        link.send_line("*STB?").await.unwrap();
        assert_eq!(link.read_line(t).await.unwrap(), "0");
        tokio::time::sleep(Duration::from_millis(1100)).await;
        let status = schedule.status(&bench.handle);
        assert!(status[0].fired && !status[1].fired, "{status:?}");
        for q in ["*STB?", ":Mode? 1"] {
            link.send_line(q).await.unwrap();
            assert!(link.read_line(t).await.is_err(), "{q} answered");
        }
        link.send_line(":Mode? 1").await.unwrap();
        assert_eq!(link.read_line(t).await.unwrap(), "RATE");
        tokio::time::sleep(Duration::from_secs(1)).await;
        assert!(schedule.status(&bench.handle).iter().all(|s| s.fired));
        assert!(!bench.handle.table.interlock_closed());
        assert_eq!(bench.handle.table.mode(), SimMode::Off);
        link.send_line(":System:Error?").await.unwrap();
        assert_eq!(link.read_line(t).await.unwrap(), "201,\"Interlock open\"");
        schedule.stop();
    }
}
