//! The chamber's thermal physics, in closed form so virtual time can jump hours exactly.
//!
//! Three temperatures, each °C (chamber.md, "Physics for the simulator"):
//!
//! * the **air** moves towards the controller's target (the setpoint while it controls, the
//!   room when it is in standby or off) in a straight line at the chamber's own maximum
//!   heating or cooling rate (`heat_c_per_min`, `cool_c_per_min`: a chamber is limited by its
//!   heater and compressor power, so a big step is a ramp), and holds once there;
//! * the gyro's **case** follows the air as a first-order lag, `dc/dt = (air − c)/case_tau_s`
//!   (a block of metal in moving air: tens of minutes);
//! * the gyro's **inside** (its resonator, what its scale factor and bias follow) follows the
//!   case as a second first-order lag, `di/dt = (c − i)/inside_tau_s`: later still.
//!
//! Between two changes of the target the air is piecewise linear (a ramp, then a hold), and a
//! chain of first-order lags driven by a linear input has an exact solution; [`Thermal`]
//! evaluates it at any instant without stepping, so a test can jump 10 hours of virtual time
//! and read the exact temperatures. The history of changes is kept, so an instant before the
//! latest change (a meter reading whose window began before the chamber was last written)
//! reads what it was then.

use serde::{Deserialize, Serialize};

/// The physics' settings, with their defaults.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ThermalConfig {
    /// The room around the chamber, °C: every temperature starts there, and the air returns
    /// to it when the controller stops controlling. Default 23.
    pub room_c: f64,
    /// The chamber's fastest heating, °C/min. Default 3 (a common bench-top chamber).
    pub heat_c_per_min: f64,
    /// The chamber's fastest cooling, °C/min. Default 2 (cooling is the slower direction on
    /// most mechanically refrigerated chambers).
    pub cool_c_per_min: f64,
    /// Time constant of the gyro's case following the air, s. Default 1200 (20 min: a small
    /// gyro's metal housing in forced air).
    pub case_tau_s: f64,
    /// Time constant of the gyro's inside following its case, s. Default 600 (10 min).
    pub inside_tau_s: f64,
    /// Standard deviation of the noise on each sensor reading the controller reports (air
    /// and product), °C. Default 0.05. The gyro itself sees the noise-free inside.
    pub sensor_noise_c: f64,
}

impl Default for ThermalConfig {
    fn default() -> Self {
        ThermalConfig {
            room_c: 23.0,
            heat_c_per_min: 3.0,
            cool_c_per_min: 2.0,
            case_tau_s: 1200.0,
            inside_tau_s: 600.0,
            sensor_noise_c: 0.05,
        }
    }
}

impl ThermalConfig {
    /// Checks the settings: a message naming the field when one is unusable.
    pub fn validate(&self) -> Result<(), String> {
        if !self.room_c.is_finite() || self.room_c.abs() > 200.0 {
            return Err(format!("room_c {} is not a room temperature", self.room_c));
        }
        for (name, v) in [
            ("heat_c_per_min", self.heat_c_per_min),
            ("cool_c_per_min", self.cool_c_per_min),
            ("case_tau_s", self.case_tau_s),
            ("inside_tau_s", self.inside_tau_s),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("{name} must be > 0 (got {v})"));
            }
        }
        if !(self.sensor_noise_c.is_finite() && self.sensor_noise_c >= 0.0) {
            return Err(format!(
                "sensor_noise_c must be >= 0 (got {})",
                self.sensor_noise_c
            ));
        }
        Ok(())
    }
}

/// The three temperatures at one instant, °C (noise-free).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Temperatures {
    /// The chamber's air.
    pub air_c: f64,
    /// The gyro's case (what a product thermocouple reads).
    pub case_c: f64,
    /// The gyro's inside (what its coefficients follow).
    pub inside_c: f64,
}

/// From one change of the target on: the state then and the target.
#[derive(Debug, Clone, Copy)]
struct Segment {
    t0: f64,
    at: Temperatures,
    target_c: f64,
}

/// The chamber's temperatures over sim time (seconds since the bench started).
#[derive(Debug, Clone)]
pub struct Thermal {
    heat_c_per_s: f64,
    cool_c_per_s: f64,
    tau_case: f64,
    tau_inside: f64,
    history: Vec<Segment>,
}

impl Thermal {
    /// Everything at the room's temperature at t = 0, the target the room.
    pub fn new(config: &ThermalConfig) -> Self {
        let room = config.room_c;
        Thermal {
            heat_c_per_s: config.heat_c_per_min / 60.0,
            cool_c_per_s: config.cool_c_per_min / 60.0,
            tau_case: config.case_tau_s,
            tau_inside: config.inside_tau_s,
            history: vec![Segment {
                t0: 0.0,
                at: Temperatures {
                    air_c: room,
                    case_c: room,
                    inside_c: room,
                },
                target_c: room,
            }],
        }
    }

    /// The target the air is moving towards now (the latest one set).
    pub fn target_c(&self) -> f64 {
        self.history.last().map_or(f64::NAN, |s| s.target_c)
    }

    /// The air's target changes at sim time `t` (clamped to the latest change: time does not
    /// go back).
    pub fn set_target(&mut self, t: f64, target_c: f64) {
        let Some(last) = self.history.last().copied() else {
            return;
        };
        if target_c == last.target_c {
            return;
        }
        let t = t.max(last.t0);
        let at = self.evaluate(&last, t);
        if t == last.t0 {
            // two changes at one instant: the later one wins
            self.history.pop();
        }
        self.history.push(Segment {
            t0: t,
            at,
            target_c,
        });
    }

    /// The temperatures at sim time `t`.
    pub fn at(&self, t: f64) -> Temperatures {
        let i = self.history.partition_point(|s| s.t0 <= t);
        let seg = &self.history[i.saturating_sub(1)];
        self.evaluate(seg, t.max(seg.t0))
    }

    fn evaluate(&self, seg: &Segment, t: f64) -> Temperatures {
        let dt = (t - seg.t0).max(0.0);
        let gap = seg.target_c - seg.at.air_c;
        let rate = if gap > 0.0 {
            self.heat_c_per_s
        } else {
            -self.cool_c_per_s
        };
        // how long the ramp lasts before the air holds at the target
        let ramp_s = if gap == 0.0 { 0.0 } else { gap / rate };
        if dt <= ramp_s {
            return self.lag(seg.at, rate, dt);
        }
        let mut end = self.lag(seg.at, rate, ramp_s);
        end.air_c = seg.target_c;
        self.lag(end, 0.0, dt - ramp_s)
    }

    /// The exact state `dt` seconds after `from`, the air ramping at `rate` °C/s meanwhile.
    ///
    /// With the air a(t) = a0 + r·t: the case c(t) = a(t) − r·τc + C1·e^(−t/τc), C1 = c0 − a0 +
    /// r·τc; the inside i(t) = a(t) − r·τc − r·τi + E(t) + C2·e^(−t/τi), where E is the
    /// response to C1·e^(−t/τc): C1·τc/(τc − τi)·e^(−t/τc), or C1·(t/τ)·e^(−t/τ) when the two
    /// time constants are equal.
    fn lag(&self, from: Temperatures, rate: f64, dt: f64) -> Temperatures {
        let (tc, ti) = (self.tau_case, self.tau_inside);
        let a = from.air_c + rate * dt;
        let c1 = from.case_c - from.air_c + rate * tc;
        let case = a - rate * tc + c1 * (-dt / tc).exp();
        let e_c = (-dt / tc).exp();
        let e_i = (-dt / ti).exp();
        // the transient the case's own transient drives in the inside, minus its value at 0
        // (which C2 carries), written as one difference so nearly equal constants stay exact
        let driven = if ((tc - ti) / tc).abs() < 1e-6 {
            c1 * (dt / tc) * e_c
        } else {
            c1 * tc * (e_c - e_i) / (tc - ti)
        };
        let steady0 = from.air_c - rate * tc - rate * ti;
        let inside = a - rate * tc - rate * ti + driven + (from.inside_c - steady0) * e_i;
        Temperatures {
            air_c: a,
            case_c: case,
            inside_c: inside,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn thermal() -> Thermal {
        Thermal::new(&ThermalConfig::default())
    }

    #[test]
    fn the_air_ramps_at_the_limited_rate_then_holds() {
        let mut th = thermal();
        th.set_target(0.0, 83.0);
        // 60 °C up at 3 °C/min: 20 min
        assert!((th.at(600.0).air_c - 53.0).abs() < 1e-9);
        assert!((th.at(1200.0).air_c - 83.0).abs() < 1e-9);
        assert!((th.at(5000.0).air_c - 83.0).abs() < 1e-9);
        th.set_target(5000.0, 63.0);
        // 20 °C down at 2 °C/min: 10 min
        assert!((th.at(5300.0).air_c - 73.0).abs() < 1e-9);
        assert!((th.at(5600.0).air_c - 63.0).abs() < 1e-9);
    }

    /// The closed form against a fine numerical integration of the two lags.
    #[test]
    fn the_closed_form_matches_an_integration() {
        for (tc, ti) in [(1200.0, 600.0), (600.0, 600.0), (300.0, 900.0)] {
            let config = ThermalConfig {
                case_tau_s: tc,
                inside_tau_s: ti,
                ..ThermalConfig::default()
            };
            let mut th = Thermal::new(&config);
            th.set_target(0.0, -37.0);
            th.set_target(2000.0, 60.0);
            let (mut c, mut i) = (23.0, 23.0);
            let h = 0.01;
            let mut t = 0.0;
            while t < 9000.0 {
                let a = th.at(t + h / 2.0).air_c;
                c += h * (a - c) / tc;
                i += h * (c - i) / ti;
                t += h;
            }
            let exact = th.at(t);
            assert!(
                (exact.case_c - c).abs() < 1e-3,
                "{tc}/{ti}: {exact:?} vs {c}"
            );
            assert!(
                (exact.inside_c - i).abs() < 1e-3,
                "{tc}/{ti}: {exact:?} vs {i}"
            );
        }
    }

    #[test]
    fn an_instant_before_the_latest_change_reads_what_it_was() {
        let mut th = thermal();
        th.set_target(0.0, 53.0);
        let before = th.at(300.0);
        th.set_target(600.0, 23.0);
        assert_eq!(th.at(300.0), before);
    }
}
