//! The stability of the analysed stretch: the curve (the chosen estimator over the τ set, with
//! EDF and chi-squared intervals), the bias and the GJB 2426A bias stability, and the IEEE 952
//! noise terms read from the curve. The numerics are `gyrocal-allan`'s; this module picks the
//! memory path's record and says when a figure cannot be given.

use std::ops::Range;
use std::path::Path;

use gyrocal_allan::{
    BiasFigures, Curve, DiskRecord, NoiseTerms, Record, bias_figures, bias_figures_in,
    compute_record, noise_terms,
};

use super::AllanOptions;
use super::bounded::{self, Samples};
use super::input::data_err;
use crate::DriftError;

/// The curve and the bias figures of `range` of the record's `samples`.
pub(super) fn curve_and_bias(
    samples: Samples,
    range: Range<usize>,
    tau0: f64,
    unit: &str,
    opts: &AllanOptions,
    file: &Path,
    temp_dir: &Path,
) -> Result<(Curve, BiasFigures), DriftError> {
    let allan_err = |e: gyrocal_allan::Error| match e {
        gyrocal_allan::Error::Io(e) => bounded::temp_err(temp_dir, e),
        e => data_err(file, None, e.to_string()),
    };
    Ok(match samples {
        Samples::Memory(mut values) => {
            values.truncate(range.end);
            values.drain(..range.start);
            let rec = Record::from_vec(values, tau0).map_err(allan_err)?;
            let curve = compute_record(&rec, opts.estimator, &opts.taus).map_err(allan_err)?;
            (curve, bias_figures(&rec, unit))
        }
        Samples::Disk(values) => {
            let prefix = bounded::temp_file(temp_dir)?;
            let rec = DiskRecord::from_samples(&values, range, prefix, tau0).map_err(allan_err)?;
            drop(values);
            let curve = compute_record(&rec, opts.estimator, &opts.taus).map_err(allan_err)?;
            (curve, bias_figures_in(&rec, unit).map_err(allan_err)?)
        }
    })
}

/// The IEEE 952 noise terms of `curve` when it is a rate in °/h; otherwise `None` and a note.
pub(super) fn noise_terms_of(
    curve: &Curve,
    is_rate: bool,
    unit: &str,
    notes: &mut Vec<String>,
) -> Option<NoiseTerms> {
    if is_rate {
        Some(noise_terms(curve))
    } else {
        notes.push(format!(
            "the curve is in {unit}: the noise terms need a rate in °/h (give --scale-factor K in V/(°/s))"
        ));
        None
    }
}
