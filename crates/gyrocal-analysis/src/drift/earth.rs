//! The Earth's rate removed from the bias: the component of the Earth's rotation along the
//! gyro's input axis at the bench's latitude ([`super::Axis::earth_rate_dph`], the plan's one
//! Earth rate) subtracted from the measured mean rate, so the figure is the gyro's own bias.

use gyrocal_allan::BiasFigures;

use super::{Axis, EarthRateRemoved};

/// The bias without the Earth's rate when the axis and the latitude are known (`earth`) and the
/// record is a rate in °/h; a note when they are known but the record is not a rate.
pub(super) fn removed(
    earth: Option<(Axis, f64)>,
    is_rate: bool,
    bias: &BiasFigures,
    notes: &mut Vec<String>,
) -> Option<EarthRateRemoved> {
    match earth {
        Some((axis, latitude_deg)) if is_rate => {
            let component_dph = axis.earth_rate_dph(latitude_deg);
            Some(EarthRateRemoved {
                axis,
                latitude_deg,
                component_dph,
                bias_measured_dph: bias.bias.value,
                bias_dph: bias.bias.value - component_dph,
            })
        }
        Some(_) => {
            notes.push(
                "the Earth rate is not removed: the record is not a rate in °/h (give --scale-factor)"
                    .to_string(),
            );
            None
        }
        None => None,
    }
}
