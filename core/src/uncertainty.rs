//! The position uncertainty a model file carries for every compensated point: a function of the
//! point's nominal legs, cheap enough for the serving path (91 multiply-adds).
//!
//! `σ²(q) = constant + leverage · h(q)`, mm². `h` is the **leverage** of the nominal legs `q`
//! among the measured configurations' legs, over the features `φ(q) = [1, x_i, x_i²]`
//! (`x_i` leg `i` centred and scaled by the configurations' range): `h(q) = φᵀ M⁻¹ φ / 13` with
//! `M` the configurations' mean `φφᵀ`, so that `h` averages 1 over the configurations, stays
//! near it inside the measured range and grows with the fourth power of the distance outside
//! it — the shape of a least-squares prediction's variance. The trainer fits the two variances
//! to the uncertainty it propagates from its identification at poses over the measured range
//! (`hexacomp-trainer`'s `uncertainty` module).
//!
//! `σ` is a **one-dimensional equivalent**: the position error (a 3-D vector, anisotropic) lies
//! within `2σ` of zero with the probability a normal variable lies within two standard
//! deviations (95.45 %).

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::geometry::LEGS;

/// Features of the leverage: a constant, each leg and its square.
pub const FEATURES: usize = 1 + 2 * LEGS;

/// Entries of the packed lower-triangular whitening matrix.
pub const WHITENING_ENTRIES: usize = FEATURES * (FEATURES + 1) / 2;

/// How uncertain a model's compensated position is, as a function of the nominal legs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PositionUncertainty {
    /// The measured configurations' mid leg lengths, mm: `x_i = (q_i − centre_i) / half_span_i`.
    pub centre_mm: [f64; LEGS],
    /// Half of each leg's measured range, mm (positive).
    pub half_span_mm: [f64; LEGS],
    /// `L⁻¹ / √13`, `L` the Cholesky factor of the configurations' mean `φφᵀ`: lower
    /// triangular, packed by rows (row `r` holds columns `0..=r`), unitless.
    pub whitening: Vec<f64>,
    /// The variance every point has (the machine's repeatability, for networks their excess
    /// error over the physical model's, the model's own uncertainty at average leverage), mm².
    pub constant_variance_mm2: f64,
    /// The variance per unit of leverage (the model's uncertainty, growing where the
    /// configurations are sparse or absent), mm².
    pub leverage_variance_mm2: f64,
}

impl PositionUncertainty {
    /// The features `φ(q)` of nominal legs `q` (mm).
    pub fn features(&self, q: &[f64; LEGS]) -> [f64; FEATURES] {
        let mut phi = [1.0; FEATURES];
        for i in 0..LEGS {
            let x = (q[i] - self.centre_mm[i]) / self.half_span_mm[i];
            phi[1 + i] = x;
            phi[1 + LEGS + i] = x * x;
        }
        phi
    }

    /// The leverage `h(q)` of nominal legs `q` (mm): 1 on average over the measured
    /// configurations, growing outside them. Unitless.
    #[inline]
    pub fn leverage(&self, q: &[f64; LEGS]) -> f64 {
        let phi = self.features(q);
        let mut at = 0;
        let mut sum = 0.0;
        for r in 0..FEATURES {
            let row = &self.whitening[at..at + r + 1];
            let z: f64 = row.iter().zip(&phi[..=r]).map(|(w, p)| w * p).sum();
            sum += z * z;
            at += r + 1;
        }
        sum
    }

    /// The one-dimensional-equivalent 1-σ position uncertainty at nominal legs `q` (mm), mm.
    #[inline]
    pub fn sigma_mm(&self, q: &[f64; LEGS]) -> f64 {
        (self.constant_variance_mm2 + self.leverage_variance_mm2 * self.leverage(q)).sqrt()
    }

    /// Checks the shapes and that every number is finite, spans positive, variances
    /// non-negative.
    pub fn validate(&self) -> Result<()> {
        let invalid = |what: &str| Err(Error::InvalidModel(format!("uncertainty: {what}")));
        if self.whitening.len() != WHITENING_ENTRIES {
            return invalid(&format!(
                "{} whitening entries, {WHITENING_ENTRIES} expected",
                self.whitening.len()
            ));
        }
        if self
            .centre_mm
            .iter()
            .chain(&self.half_span_mm)
            .chain(&self.whitening)
            .any(|v| !v.is_finite())
        {
            return invalid("a number is not finite");
        }
        if self.half_span_mm.iter().any(|s| *s <= 0.0) {
            return invalid("a leg's span is not positive");
        }
        let variances = [self.constant_variance_mm2, self.leverage_variance_mm2];
        if variances.iter().any(|v| !(v.is_finite() && *v >= 0.0)) {
            return invalid("a variance is negative or not finite");
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Whitening of the identity moment matrix: `h = |φ|² / 13`.
    fn identity_whitened(constant: f64, leverage: f64) -> PositionUncertainty {
        let mut whitening = Vec::with_capacity(WHITENING_ENTRIES);
        for r in 0..FEATURES {
            for c in 0..=r {
                whitening.push(if r == c {
                    1.0 / (FEATURES as f64).sqrt()
                } else {
                    0.0
                });
            }
        }
        PositionUncertainty {
            centre_mm: [350.0; LEGS],
            half_span_mm: [50.0; LEGS],
            whitening,
            constant_variance_mm2: constant,
            leverage_variance_mm2: leverage,
        }
    }

    #[test]
    fn the_leverage_is_the_whitened_features_squared_norm() {
        let u = identity_whitened(1e-5, 4e-5);
        // At the centre only the constant feature is 1.
        assert!((u.leverage(&[350.0; LEGS]) - 1.0 / 13.0).abs() < 1e-15);
        // One leg at the range's end: x = 1 and x² = 1 add 2.
        let mut q = [350.0; LEGS];
        q[2] = 400.0;
        assert!((u.leverage(&q) - 3.0 / 13.0).abs() < 1e-15);
        let sigma = u.sigma_mm(&q);
        assert!((sigma * sigma - (1e-5 + 4e-5 * 3.0 / 13.0)).abs() < 1e-18);
        // Far outside, the fourth power of the distance.
        q[2] = 350.0 + 50.0 * 10.0;
        assert!((u.leverage(&q) - (1.0 + 100.0 + 10_000.0) / 13.0).abs() < 1e-9);
        u.validate().unwrap();
    }

    #[test]
    fn invalid_uncertainties_are_refused() {
        let mut short = identity_whitened(1e-5, 1e-5);
        short.whitening.pop();
        let mut negative = identity_whitened(1e-5, 1e-5);
        negative.leverage_variance_mm2 = -1e-9;
        let mut flat = identity_whitened(1e-5, 1e-5);
        flat.half_span_mm[4] = 0.0;
        let mut nan = identity_whitened(1e-5, 1e-5);
        nan.whitening[7] = f64::NAN;
        for (u, what) in [
            (short, "whitening entries"),
            (negative, "negative"),
            (flat, "span"),
            (nan, "not finite"),
        ] {
            let e = u.validate().unwrap_err().to_string();
            assert!(e.contains(what), "{e}");
        }
    }
}
