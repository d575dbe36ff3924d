//! The quantities an acceptance specification can limit: their names in plan files and JSON,
//! their units, and which figure of an analysis each one is ([`Quantity::figure`]).

use std::fmt;

use serde::{Deserialize, Serialize};

/// A quantity a specification can limit, named as in plan files and JSON.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Quantity {
    /// The scale factor `K`, V/(°/s).
    ScaleFactor,
    /// The bias `K0` as a voltage, V.
    BiasV,
    /// The bias as an equivalent rate, °/h.
    BiasDph,
    /// The nonlinearity, ppm (of full scale, as the analysis reports it).
    NonlinearityPpm,
    /// The asymmetry of the two directions' scale factors, ppm, signed: the figure the
    /// report presents as the result, from one joint fit with a common K2
    /// ([`crate::AsymmetryCommonK2`]), free of the even-order bias. Plans written before
    /// `asymmetry_gjb_ppm` existed limited the GJB figure under this key; the key now means
    /// the unbiased figure (configs/README.md, "Acceptance limits").
    AsymmetryPpm,
    /// The GJB 2426A asymmetry of two separate lines, `|K+ − K−| / ((K+ + K−)/2)`, ppm
    /// (unsigned): biased by an even-order term (K2), for a specification written to it.
    AsymmetryGjbPpm,
    /// The repeatability of the scale factor over the passes, ppm.
    RepeatabilityPpm,
    /// The second-order coefficient of the quadratic model, V/(°/s)².
    K2,
}

impl Quantity {
    /// Every quantity, in the order checks are listed.
    pub const ALL: [Quantity; 8] = [
        Quantity::ScaleFactor,
        Quantity::BiasV,
        Quantity::BiasDph,
        Quantity::NonlinearityPpm,
        Quantity::AsymmetryPpm,
        Quantity::AsymmetryGjbPpm,
        Quantity::RepeatabilityPpm,
        Quantity::K2,
    ];

    /// The name used in plan files and JSON (`scale_factor`, `bias_v`, ...).
    pub fn name(self) -> &'static str {
        match self {
            Quantity::ScaleFactor => "scale_factor",
            Quantity::BiasV => "bias_v",
            Quantity::BiasDph => "bias_dph",
            Quantity::NonlinearityPpm => "nonlinearity_ppm",
            Quantity::AsymmetryPpm => "asymmetry_ppm",
            Quantity::AsymmetryGjbPpm => "asymmetry_gjb_ppm",
            Quantity::RepeatabilityPpm => "repeatability_ppm",
            Quantity::K2 => "k2",
        }
    }

    /// Which figure of an analysis the quantity is, and where its expanded uncertainty comes
    /// from, in words (recorded in each [`crate::acceptance::Check`], so a verdict says what it judged).
    pub fn figure(self) -> &'static str {
        match self {
            Quantity::ScaleFactor => {
                "metrics.scale_factor: K of the least-squares line; U from the uncertainty budget"
            }
            Quantity::BiasV => {
                "metrics.bias_volts: K0 of the least-squares line; U from the uncertainty budget"
            }
            Quantity::BiasDph => "metrics.bias_dph: K0/K·3600; U from the uncertainty budget",
            Quantity::NonlinearityPpm => {
                "metrics.nonlinearity_ppm; U by Monte Carlo over the points' noise \
                 (metrics.nonlinearity_uncertainty)"
            }
            Quantity::AsymmetryPpm => {
                "metrics.asymmetry_common_k2.asymmetry_ppm: the joint fit \
                 K0 + K+·ω⁺ + K−·ω⁻ + K2·ω², signed, unbiased by K2; U = 2 × its standard error"
            }
            Quantity::AsymmetryGjbPpm => {
                "metrics.asymmetry_ppm: the GJB two-line figure |K+ − K−|/((K+ + K−)/2), \
                 biased by K2; U = 2 × its standard error"
            }
            Quantity::RepeatabilityPpm => {
                "metrics.repeatability_ppm: std(K per pass)/mean; the exact 95 % chi-square \
                 interval of a standard deviation of q passes"
            }
            Quantity::K2 => "K2 of the quadratic least-squares fit; U = 2 × its standard error",
        }
    }

    /// The quantity in words (`scale factor K`), from the one table of display names
    /// ([`crate::display::QUANTITIES`]): what a person reads on the terminal and the pages.
    pub fn title(self) -> String {
        crate::display::quantity_words(self.name()).0
    }

    /// The unit of the quantity's value (and of its limits).
    pub fn unit(self) -> &'static str {
        match self {
            Quantity::ScaleFactor => "V/(°/s)",
            Quantity::BiasV => "V",
            Quantity::BiasDph => "°/h",
            Quantity::NonlinearityPpm
            | Quantity::AsymmetryPpm
            | Quantity::AsymmetryGjbPpm
            | Quantity::RepeatabilityPpm => "ppm",
            Quantity::K2 => "V/(°/s)²",
        }
    }

    /// The quantity named `name` (exactly as [`Quantity::name`] spells it).
    pub fn from_name(name: &str) -> Option<Quantity> {
        Quantity::ALL.into_iter().find(|q| q.name() == name)
    }

    /// Every name, `scale_factor, bias_v, ...`, for error messages.
    pub fn names() -> String {
        Quantity::ALL.map(Quantity::name).join(", ")
    }

    /// Why a quantity can be missing from an analysis, for the `not measured: ...` reason.
    pub(crate) fn missing_because(self) -> &'static str {
        match self {
            Quantity::RepeatabilityPpm => {
                "the repeatability needs a line per pass of a plan with repeat >= 2"
            }
            Quantity::AsymmetryPpm => {
                "the asymmetry (common K2) needs both turning directions and at least 4 \
                 distinct rates (the joint fit K0 + K+·ω⁺ + K−·ω⁻ + K2·ω²)"
            }
            Quantity::AsymmetryGjbPpm => {
                "the GJB asymmetry needs two distinct rates on each side of zero (the split \
                 model)"
            }
            Quantity::K2 => "k2 needs the quadratic model (three distinct rates)",
            Quantity::NonlinearityPpm => "the analysis has no nonlinearity",
            Quantity::ScaleFactor => "the analysis has no scale factor",
            Quantity::BiasV => "the analysis has no bias",
            Quantity::BiasDph => "the bias as a rate needs the bias and a non-zero scale factor",
        }
    }
}

impl fmt::Display for Quantity {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}
