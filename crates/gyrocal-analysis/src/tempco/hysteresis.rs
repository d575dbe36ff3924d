//! Hysteresis: where a series returns to a setpoint, the difference between the later visit
//! and the first, corrected to the first visit's measured temperature by the model's slope
//! (a gyro that came back to 25.3 °C instead of 25.0 °C is compared at the same temperature).

use serde::{Deserialize, Serialize};

use super::{COVERAGE_FACTOR, TempModel, TempPoint};

/// One revisit of a setpoint.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Hysteresis {
    /// The setpoint revisited, °C.
    pub setpoint_c: f64,
    /// Index (into the points given) of the first visit.
    pub first: usize,
    /// Index of the later visit.
    pub later: usize,
    /// `y_later − y_first − slope·(T_later − T_first)`, in the figure's unit.
    pub difference: f64,
    /// Its expanded uncertainty (k = 2): the two points' U and the slope's part.
    pub u: f64,
}

/// Every later visit of a setpoint against its first visit. `visits` are the points with
/// their setpoints, in the order measured; `model` supplies the slope for the small
/// temperature correction (none when absent).
pub fn hysteresis(visits: &[(f64, TempPoint)], model: Option<&TempModel>) -> Vec<Hysteresis> {
    let mut out = Vec::new();
    for (later, (sp, p2)) in visits.iter().enumerate() {
        let Some(first) = visits[..later]
            .iter()
            .position(|(s, _)| (s - sp).abs() < 1e-6)
        else {
            continue;
        };
        let p1 = visits[first].1;
        let dt = p2.t_c - p1.t_c;
        let (slope, u_slope) = model.map_or((0.0, 0.0), |m| {
            let t = 0.5 * (p1.t_c + p2.t_c);
            (m.slope(t), m.slope_std_u(t))
        });
        let difference = p2.y - p1.y - slope * dt;
        let var_std = (p1.u / COVERAGE_FACTOR).powi(2)
            + (p2.u / COVERAGE_FACTOR).powi(2)
            + (dt * u_slope).powi(2);
        out.push(Hysteresis {
            setpoint_c: *sp,
            first,
            later,
            difference,
            u: COVERAGE_FACTOR * var_std.sqrt(),
        });
    }
    out
}
