//! An analysis judged against acceptance limits: which figure of the analysis each
//! [`Quantity`] is, with its expanded uncertainty, and the verdict.
//!
//! A limit applies to the figure the report presents as the result (ISO/IEC 17025 §7.8.6: the
//! statement of conformity is about the reported result):
//!
//! - K and K0 of the least-squares line and the bias as a rate, with U from the uncertainty
//!   budget ([`Analysis::uncertainty`]);
//! - the nonlinearity, with U by Monte Carlo over the points' noise ([`crate::nonlinearity`]);
//! - `asymmetry_ppm`: the **unbiased** asymmetry of one joint fit with a common K2
//!   ([`crate::AsymmetryCommonK2`], signed), with U twice its standard error (exact to first
//!   order: K+ and K− are linear in the data, their covariance included). The GJB two-line
//!   figure, which an even-order term biases (a K2 of 2e-5 V/(°/s)² on ±20 °/s makes about
//!   2000 ppm of it), is `asymmetry_gjb_ppm`, for a specification written to GJB 2426A;
//! - the repeatability over passes, with the exact 95 % chi-square interval of a standard
//!   deviation of `q` passes (skewed, so the guarded rule judges the interval itself:
//!   [`crate::uncertainty::repeatability_interval`]);
//! - K2 of the quadratic least-squares fit, with U twice its standard error.
//!
//! Every figure's U is looked up in the attached budget first, so a verdict uses the numbers
//! the certificate prints; without a budget the same figure is computed from the analysis. A
//! quantity without a U (a document written before it existed) is judged without one: the
//! guarded rule then says "indeterminate", with the reason.

use crate::acceptance::{Acceptance, AcceptanceSpec, Measured, Quantity, evaluate};
use crate::uncertainty::{COVERAGE_FACTOR, repeatability_interval};
use crate::{Analysis, Method, Model};

impl Analysis {
    /// The value of `q` in this analysis and its expanded uncertainty (k = 2), when known.
    pub fn measure(&self, q: Quantity) -> Measured {
        let m = &self.metrics;
        let common = m.asymmetry_common_k2.as_ref();
        let (value, key, fallback) = match q {
            Quantity::ScaleFactor => (Some(m.scale_factor), "scale_factor", None),
            Quantity::BiasV => (Some(m.bias_volts), "bias_v", None),
            Quantity::BiasDph => (Some(m.bias_dph), "bias_dph", None),
            Quantity::NonlinearityPpm => (
                Some(m.nonlinearity_ppm),
                "nonlinearity_ppm",
                m.nonlinearity_uncertainty
                    .as_ref()
                    .map(|u| u.expanded_uncertainty_ppm),
            ),
            Quantity::AsymmetryPpm => (
                common.map(|c| c.asymmetry_ppm),
                "asymmetry_common_k2",
                common.map(|c| COVERAGE_FACTOR * c.asymmetry_std_error_ppm),
            ),
            Quantity::AsymmetryGjbPpm => (m.asymmetry_ppm, "asymmetry_ppm", None),
            Quantity::RepeatabilityPpm => {
                let Some(r) = m.repeatability_ppm.filter(|r| r.is_finite()) else {
                    return Measured::NONE;
                };
                let interval = self
                    .uncertainty
                    .as_ref()
                    .and_then(|u| u.interval("repeatability_ppm"))
                    .or_else(|| {
                        m.repeatability_passes
                            .and_then(|q| repeatability_interval(r, q))
                    });
                return match interval {
                    Some([lo, hi]) => Measured::with_interval(r, lo, hi),
                    None => Measured::value(r),
                };
            }
            Quantity::K2 => {
                let quad = self.fit(Method::LeastSquares, Model::Quadratic);
                (
                    quad.and_then(|f| f.coefficients.k2),
                    "k2",
                    quad.and_then(|f| f.std_errors.k2)
                        .map(|se| COVERAGE_FACTOR * se),
                )
            }
        };
        Measured {
            value: value.filter(|v| v.is_finite()),
            expanded_uncertainty: self
                .expanded_uncertainty(key)
                .or(fallback)
                .filter(|u| u.is_finite() && *u >= 0.0),
            interval: None,
        }
    }

    /// The verdict of this analysis against `spec` (`None`: the spec limits nothing).
    pub fn evaluate_acceptance(&self, spec: &AcceptanceSpec) -> Option<Acceptance> {
        evaluate(spec, |q| self.measure(q))
    }
}
