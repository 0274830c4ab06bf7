//! Three-layer feed-forward networks (Sec. 3.2): nodes as in Eq. 10, tanh hidden layer (Eq. 11:
//! `σ_H(z) = (1 − e^(−2z))/(1 + e^(−2z)) = tanh z`), linear output (Eq. 12 with k = 1), inputs
//! normalised by Eq. 13; the network as a whole is the `N(q, w)` of Eq. 14.
//!
//! Inference is allocation-free: the hidden activations live in a stack buffer of
//! [`MAX_HIDDEN`] values.

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::geometry::LEGS;

/// Largest hidden layer a network may have.
pub const MAX_HIDDEN: usize = 64;

/// A network with 6 inputs (normalised leg lengths), `hidden` tanh nodes and `outputs` linear
/// outputs (joint corrections, mm).
///
/// All weights live in one vector, in the order `w1` (hidden × 6, row-major), `b1` (hidden),
/// `w2` (outputs × hidden, row-major), `b2` (outputs): the weight vector `w` of Eq. 14.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Network {
    hidden: usize,
    outputs: usize,
    weights: Vec<f64>,
}

impl Network {
    /// Number of weights of a network with `hidden` nodes and `outputs` outputs.
    pub const fn weight_count(hidden: usize, outputs: usize) -> usize {
        hidden * LEGS + hidden + outputs * hidden + outputs
    }

    /// A network from its weight vector (see the type's documentation for the order).
    pub fn from_weights(hidden: usize, outputs: usize, weights: Vec<f64>) -> Result<Self> {
        let network = Self {
            hidden,
            outputs,
            weights,
        };
        network.validate()?;
        Ok(network)
    }

    /// Checks sizes and that every weight is finite.
    pub fn validate(&self) -> Result<()> {
        if !(1..=MAX_HIDDEN).contains(&self.hidden) || !(1..=LEGS).contains(&self.outputs) {
            return Err(Error::InvalidModel(format!(
                "network of {} hidden nodes and {} outputs (allowed: 1–{MAX_HIDDEN}, 1–{LEGS})",
                self.hidden, self.outputs
            )));
        }
        let expected = Self::weight_count(self.hidden, self.outputs);
        if self.weights.len() != expected {
            return Err(Error::InvalidModel(format!(
                "network has {} weights, expected {expected}",
                self.weights.len()
            )));
        }
        if let Some(i) = self.weights.iter().position(|w| !w.is_finite()) {
            return Err(Error::InvalidModel(format!(
                "network weight {i} is not finite"
            )));
        }
        Ok(())
    }

    /// Hidden nodes.
    pub fn hidden(&self) -> usize {
        self.hidden
    }

    /// Outputs.
    pub fn outputs(&self) -> usize {
        self.outputs
    }

    /// The weight vector.
    pub fn weights(&self) -> &[f64] {
        &self.weights
    }

    /// Evaluates the network at normalised input `x`, writing `outputs` values to `out`: Eq. 10
    /// for both layers, with Eq. 11 (tanh) on the hidden layer and Eq. 12 (`k = 1`) on the output.
    /// Allocation-free; each hidden activation is consumed as it is computed, so no buffer of
    /// activations is set up per call.
    #[inline]
    pub fn evaluate(&self, x: &[f64; LEGS], out: &mut [f64]) {
        let (h, o) = (self.hidden, self.outputs);
        let (w1, rest) = self.weights.split_at(h * LEGS);
        let (b1, rest) = rest.split_at(h);
        let (w2, b2) = rest.split_at(o * h);
        let mut sums = [0.0; LEGS];
        for (j, row) in w1.chunks_exact(LEGS).enumerate() {
            let z = b1[j] + row.iter().zip(x).map(|(w, x)| w * x).sum::<f64>();
            let a = z.tanh();
            for (k, sum) in sums.iter_mut().enumerate().take(o) {
                *sum += w2[k * h + j] * a;
            }
        }
        for (k, value) in out.iter_mut().enumerate().take(o) {
            *value = b2[k] + sums[k];
        }
    }

    /// An upper bound, valid for every input, on how fast any output changes with the legs:
    /// `max_k Σ_j |w2_kj| · ‖w1_j ⊘ span‖` (mm of output per mm of leg travel, Euclidean norm of
    /// the leg change), from `|tanh'| ≤ 1`. `span` is the input normalisation's (mm).
    pub fn max_slope(&self, span: &[f64; LEGS]) -> f64 {
        let (h, o) = (self.hidden, self.outputs);
        let (w1, rest) = self.weights.split_at(h * LEGS);
        let w2 = &rest[h..h + o * h];
        let gains: [f64; MAX_HIDDEN] = std::array::from_fn(|j| {
            if j < h {
                let row = &w1[j * LEGS..(j + 1) * LEGS];
                row.iter()
                    .zip(span)
                    .map(|(w, s)| (w / s).powi(2))
                    .sum::<f64>()
                    .sqrt()
            } else {
                0.0
            }
        });
        (0..o)
            .map(|k| (0..h).map(|j| w2[k * h + j].abs() * gains[j]).sum::<f64>())
            .fold(0.0, f64::max)
    }

    /// The hidden activations `tanh(w1·x + b1)` (Eq. 10, Eq. 11) into `hidden[..self.hidden()]`.
    #[inline]
    pub fn hidden_layer(&self, x: &[f64; LEGS], hidden: &mut [f64; MAX_HIDDEN]) {
        let h = self.hidden;
        let (w1, rest) = self.weights.split_at(h * LEGS);
        let b1 = &rest[..h];
        for (j, a) in hidden.iter_mut().enumerate().take(h) {
            let row = &w1[j * LEGS..(j + 1) * LEGS];
            let z = b1[j] + row.iter().zip(x).map(|(w, x)| w * x).sum::<f64>();
            *a = z.tanh();
        }
    }
}

/// The input normalisation of Eq. 13: `(q_i − mean_i) / (max_i − min_i)` over the training
/// joint ranges.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Normalisation {
    /// `q_i,mean`, mm.
    pub mean: [f64; LEGS],
    /// `q_i,max − q_i,min`, mm.
    pub span: [f64; LEGS],
}

impl Normalisation {
    /// The normalisation of a set of leg-length vectors (mm): Eq. 13's `q_i,mean` is the samples'
    /// mean of leg `i` and `q_i,max − q_i,min` the range the samples span.
    pub fn of(samples: &[[f64; LEGS]]) -> Result<Self> {
        if samples.len() < 2 {
            return Err(Error::InvalidModel(
                "normalisation needs at least two samples".into(),
            ));
        }
        let mut mean = [0.0; LEGS];
        let mut span = [0.0; LEGS];
        for i in 0..LEGS {
            let (lo, hi) = samples
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), q| {
                    (lo.min(q[i]), hi.max(q[i]))
                });
            mean[i] = samples.iter().map(|q| q[i]).sum::<f64>() / samples.len() as f64;
            span[i] = hi - lo;
            if span[i].is_nan() || span[i] <= 0.0 {
                return Err(Error::InvalidModel(format!(
                    "leg {} does not vary over the samples: nothing to normalise",
                    i + 1
                )));
            }
        }
        Ok(Self { mean, span })
    }

    /// The normalised input of leg lengths `q` (mm): `(q_i − q_i,mean)/(q_i,max − q_i,min)`
    /// (Eq. 13).
    #[inline]
    pub fn apply(&self, q: &[f64; LEGS]) -> [f64; LEGS] {
        std::array::from_fn(|i| (q[i] - self.mean[i]) / self.span[i])
    }
}
