//! An analysis judged against acceptance limits: which figure of the analysis each
//! [`Quantity`] is, with its expanded uncertainty, and the verdict.
//!
//! The values are the ones the report's results table shows: K and K0 of the least-squares
//! line, the bias as a rate, the nonlinearity and the GJB asymmetry of [`crate::Metrics`]
//! (the unbiased common-K2 asymmetry is reported beside it, but a specification written to
//! GJB/IEEE means the simple definition), the repeatability over passes, and K2 of the
//! quadratic least-squares fit. Their uncertainties come from [`Analysis::uncertainty`]
//! where the budget has them, else (K2, the common-K2 asymmetry) twice the fit's standard
//! error; a quantity without one is judged without it (the guarded rule then says
//! "indeterminate").

use crate::acceptance::{Acceptance, AcceptanceSpec, Measured, Quantity, evaluate};
use crate::{Analysis, Method, Model};

impl Analysis {
    /// The value of `q` in this analysis and its expanded uncertainty (k = 2), when known.
    pub fn measure(&self, q: Quantity) -> Measured {
        let m = &self.metrics;
        let (value, key) = match q {
            Quantity::ScaleFactor => (Some(m.scale_factor), Some("scale_factor")),
            Quantity::BiasV => (Some(m.bias_volts), Some("bias_v")),
            Quantity::BiasDph => (Some(m.bias_dph), Some("bias_dph")),
            Quantity::NonlinearityPpm => (Some(m.nonlinearity_ppm), Some("nonlinearity_ppm")),
            Quantity::AsymmetryPpm => (m.asymmetry_ppm, Some("asymmetry_ppm")),
            Quantity::RepeatabilityPpm => (m.repeatability_ppm, Some("repeatability_ppm")),
            Quantity::K2 => {
                let quad = self.fit(Method::LeastSquares, Model::Quadratic);
                return Measured {
                    value: quad.and_then(|f| f.coefficients.k2),
                    expanded_uncertainty: quad.and_then(|f| f.std_errors.k2).map(|se| 2.0 * se),
                };
            }
        };
        Measured {
            value: value.filter(|v| v.is_finite()),
            expanded_uncertainty: key
                .and_then(|k| self.expanded_uncertainty(k))
                .filter(|u| u.is_finite() && *u >= 0.0),
        }
    }

    /// The verdict of this analysis against `spec` (`None`: the spec limits nothing).
    pub fn evaluate_acceptance(&self, spec: &AcceptanceSpec) -> Option<Acceptance> {
        evaluate(spec, |q| self.measure(q))
    }
}
