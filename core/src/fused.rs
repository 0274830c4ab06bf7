//! The serving form of a [`Model`]: its network(s) fused into one hidden layer evaluated
//! [`LANES`] hidden nodes at a time, with the vectorisable [`tanh_lanes`].
//!
//! A coupled network or six decoupled ones are the same computation once fused: every hidden
//! node `j` (of whichever network) has six input weights, a bias and one output weight per leg —
//! for a decoupled network's node, zero for the legs its network does not drive. The nodes are
//! laid out in blocks of [`LANES`] (the last one padded with nodes of zero weights, whose
//! activation is `tanh 0 = 0`), each block's weights stored lane by lane, so one block is a few
//! SIMD multiplies and adds, one vector `tanh`, and six more multiplies and adds.
//!
//! What it computes, against the reference [`Model::raw_corrections`]:
//! - the normalised input and every hidden node's sum `b1 + Σ w1·x` are the same operations in
//!   the same order, so the same bits;
//! - the activation is [`tanh_lanes`], within [`TANH_MAX_ERROR`] of the exact one;
//! - each output sums its hidden nodes in [`LANES`] partial sums, added pairwise at the end,
//!   instead of one after the other.
//!
//! [`FusedModel::error_bound_mm`] bounds the difference for every input, from the weights
//! (about 1e-14 mm for the models trained here; the property test sees 5.7e-14 mm at most in
//! the legs, one ulp of a 400 mm leg). A model whose bound would exceed [`MAX_ERROR_MM`] (1 nm),
//! and a physical model (nothing to fuse), are evaluated by the reference. The statuses are the reference's at every point: where a
//! fused correction lies within twice its bound of a correction bound or of a stroke end, or is
//! not finite, the compensation asks the reference (`compensator::compensate_legs`).
//!
//! The evaluation picks, once at construction, the AVX2 build of the same code when the CPU has
//! it (standard library detection, no nightly features); both builds compute each lane with the
//! same IEEE 754 operations and give the same bits (tested).

use crate::activation::{LANES, TANH_MAX_ERROR, tanh_lanes};
use crate::geometry::LEGS;
use crate::model::{Model, Networks};
use crate::network::Network;

/// Vector operations ([`LANES`] wide) one block costs: the hidden sums 12 (6 multiplies, 5 adds
/// and the bias), the activation 46 (absolute value: 1; cap: 2; `−2|z|`: 1; rounding to `n`: 3;
/// reduction: 4; Taylor polynomial by Estrin's scheme: 27; `2ⁿ` and its product: 3;
/// `(1 − e)/(1 + e)`: 3; sign: 2) and the six corrections 12 (6 multiplies, 6 adds). The
/// arithmetic floor of `hexacomp-bench compute` counts with it.
pub const OPERATIONS_PER_BLOCK: usize = 70;

/// [`LANES`] hidden nodes of the fused layer, stored lane by lane.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
struct Block {
    /// `w1[i][l]`: weight of normalised input `i` into the block's node `l`.
    input_weights: [[f64; LANES]; LEGS],
    /// `b1[l]`: the node's bias.
    biases: [f64; LANES],
    /// `w2[k][l]`: weight of the node's activation in correction `k` (mm).
    output_weights: [[f64; LANES]; LEGS],
}

/// Which build of the evaluation runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kernel {
    /// The baseline instruction set of the target (SSE2 on x86-64).
    Portable,
    /// AVX2 (x86-64 only, chosen when the CPU reports it).
    #[cfg(target_arch = "x86_64")]
    Avx2,
}

impl Kernel {
    /// The fastest build this CPU runs.
    fn detect() -> Self {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            return Kernel::Avx2;
        }
        Kernel::Portable
    }
}

/// A model's networks fused for serving, with the model itself (its ranges decide the statuses,
/// and its reference evaluation answers where the fused one could decide a status otherwise).
/// Built once when a model is loaded; evaluating it allocates nothing.
#[derive(Debug, Clone, PartialEq)]
pub struct FusedModel {
    blocks: Vec<Block>,
    /// `b2[k]`: the output bias of correction `k` (mm).
    output_biases: [f64; LEGS],
    kernel: Kernel,
    /// The model, evaluated by [`Model::raw_corrections`] where the fused form cannot stand in.
    reference: Model,
    /// The fused evaluation's bound against the reference, mm; `None` when it would exceed
    /// [`MAX_ERROR_MM`] and the reference is evaluated instead.
    error_bound_mm: Option<f64>,
}

/// The largest difference from the reference a fused model may have, mm: above it (`Σ|w2|` of
/// one correction above about 3e7 to 4e8, depending on the node count; training makes about 1)
/// the model is evaluated by the reference.
pub const MAX_ERROR_MM: f64 = 1e-6;

impl FusedModel {
    /// The serving form of `model`, which [`Model::validate`] has accepted (the model file's
    /// reader validates every model it returns).
    pub fn new(model: &Model) -> Self {
        debug_assert!(model.validate().is_ok(), "a fused form of an invalid model");
        let mut nodes = Vec::new();
        let mut output_biases = [0.0; LEGS];
        match &model.networks {
            Networks::Coupled(network) => {
                push_nodes(network, 0..LEGS, &mut nodes);
                output_biases = std::array::from_fn(|k| output_bias(network, k));
            }
            Networks::Decoupled(networks) => {
                for (leg, network) in networks.iter().enumerate() {
                    push_nodes(network, leg..leg + 1, &mut nodes);
                    output_biases[leg] = output_bias(network, 0);
                }
            }
            // Nothing to fuse: the reference evaluates it (`error_bound_mm` is `None`).
            Networks::Physical(_) => {}
        }
        let blocks: Vec<Block> = nodes
            .chunks(LANES)
            .map(|chunk| {
                let mut block = Block::default();
                for (l, node) in chunk.iter().enumerate() {
                    for i in 0..LEGS {
                        block.input_weights[i][l] = node.input_weights[i];
                        block.output_weights[i][l] = node.output_weights[i];
                    }
                    block.biases[l] = node.bias;
                }
                block
            })
            .collect();
        let bound = fused_error_bound(&blocks, &output_biases);
        Self {
            blocks,
            output_biases,
            kernel: Kernel::detect(),
            reference: model.clone(),
            error_bound_mm: Some(bound).filter(|b| *b <= MAX_ERROR_MM && !model.is_physical()),
        }
    }

    /// The raw corrections `Δq = N(q, w)` (mm) for network input legs `q` (mm), before
    /// clamping: [`Model::raw_corrections`] to within [`FusedModel::error_bound_mm`] where
    /// those are finite (a non-finite output of one decoupled network may make all six
    /// non-finite here; compensation then asks the reference). Allocation-free.
    #[inline]
    pub fn raw_corrections(&self, q: &[f64; LEGS]) -> [f64; LEGS] {
        let [corrections] = self.raw_corrections_of([q]);
        corrections
    }

    /// [`FusedModel::raw_corrections`] of several points at once: the blocks' weights are loaded
    /// once for all of them, and their activations overlap in the pipeline. Each point's
    /// corrections are the same bits as [`FusedModel::raw_corrections`] gives it alone.
    #[inline]
    pub fn raw_corrections_of<const N: usize>(&self, q: [&[f64; LEGS]; N]) -> [[f64; LEGS]; N] {
        if self.error_bound_mm.is_none() {
            return q.map(|q| self.reference.raw_corrections(q));
        }
        let x = q.map(|q| self.reference.normalisation.apply(q));
        let sums = match self.kernel {
            Kernel::Portable => hidden_sums(&self.blocks, &x),
            #[cfg(target_arch = "x86_64")]
            // SAFETY: `Kernel::Avx2` is only chosen when the CPU reports AVX2.
            Kernel::Avx2 => unsafe { hidden_sums_avx2(&self.blocks, &x) },
        };
        sums.map(|sums| {
            std::array::from_fn(|k| {
                let [a, b, c, d] = sums[k];
                self.output_biases[k] + ((a + b) + (c + d))
            })
        })
    }

    /// Blocks of [`LANES`] hidden nodes evaluated per point (the last one perhaps padded).
    pub fn blocks(&self) -> usize {
        self.blocks.len()
    }

    /// The instruction set the evaluation runs with: `"avx2"` or `"baseline"`.
    pub fn instruction_set(&self) -> &'static str {
        match self.kernel {
            Kernel::Portable => "baseline",
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx2 => "avx2",
        }
    }

    /// The model this is the serving form of.
    pub fn reference(&self) -> &Model {
        &self.reference
    }

    /// A bound, valid for every input, on how far each raw correction of this form lies from
    /// [`Model::raw_corrections`], mm; 0 when the model's weights are so large that the bound
    /// would exceed [`MAX_ERROR_MM`] and the reference is evaluated instead.
    pub fn error_bound_mm(&self) -> f64 {
        self.error_bound_mm.unwrap_or(0.0)
    }
}

/// The fused evaluation's bound against the reference, mm, of the layer `blocks` with output
/// biases `output_biases`. The hidden sums are the same bits in both; the activations differ by
/// at most `TANH_MAX_ERROR` (this form's, against the exact `tanh`) plus one ulp of 1 (the C
/// library's `tanh`), each weighted by `|w2|`; and each form's sum of `n` products and the bias
/// is within `γₙ·(Σ|w2| + |b2|)` of its exact value, `γₙ = n·u/(1 − n·u)`, `u = 2⁻⁵³`, in any
/// order of summation (the activations are at most 1 in magnitude). `n` counts this form's
/// padded nodes and the bias, at least the reference's.
fn fused_error_bound(blocks: &[Block], output_biases: &[f64; LEGS]) -> f64 {
    let unit = f64::EPSILON / 2.0;
    let n = (blocks.len() * LANES + 2) as f64;
    let gamma = n * unit / (1.0 - n * unit);
    (0..LEGS)
        .map(|k| {
            let weights: f64 = blocks
                .iter()
                .flat_map(|b| b.output_weights[k])
                .map(f64::abs)
                .sum();
            (TANH_MAX_ERROR + f64::EPSILON) * weights
                + 2.0 * gamma * (weights + output_biases[k].abs())
        })
        .fold(0.0, f64::max)
}

/// One hidden node of the fused layer.
struct Node {
    input_weights: [f64; LEGS],
    bias: f64,
    output_weights: [f64; LEGS],
}

/// Appends `network`'s hidden nodes, its outputs driving the corrections `legs`.
fn push_nodes(network: &Network, legs: std::ops::Range<usize>, nodes: &mut Vec<Node>) {
    let (h, o) = (network.hidden(), network.outputs());
    let w = network.weights();
    let (w1, rest) = w.split_at(h * LEGS);
    let (b1, w2) = (&rest[..h], &rest[h..h + o * h]);
    for j in 0..h {
        let mut output_weights = [0.0; LEGS];
        for (k, leg) in legs.clone().enumerate() {
            output_weights[leg] = w2[k * h + j];
        }
        nodes.push(Node {
            input_weights: std::array::from_fn(|i| w1[j * LEGS + i]),
            bias: b1[j],
            output_weights,
        });
    }
}

/// Output bias `b2[k]` of `network`.
fn output_bias(network: &Network, k: usize) -> f64 {
    let w = network.weights();
    w[w.len() - network.outputs() + k]
}

/// Each correction's [`LANES`] partial sums `Σ w2·tanh(b1 + Σ w1·x)` over the blocks, for
/// each of `N` normalised inputs `x`; a point's sums are the same bits whatever `N`.
#[inline(always)]
fn hidden_sums_inline<const N: usize>(
    blocks: &[Block],
    x: &[[f64; LEGS]; N],
) -> [[[f64; LANES]; LEGS]; N] {
    let mut sums = [[[0.0; LANES]; LEGS]; N];
    for block in blocks {
        for (sums, x) in sums.iter_mut().zip(x) {
            // Input 0 first, then 1…5: the reference's order, so `z` is the same bits.
            let mut z: [f64; LANES] = std::array::from_fn(|l| block.input_weights[0][l] * x[0]);
            for (weights, xi) in block.input_weights.iter().zip(x).skip(1) {
                z = std::array::from_fn(|l| z[l] + weights[l] * xi);
            }
            let activation = tanh_lanes(std::array::from_fn(|l| block.biases[l] + z[l]));
            for (sum, weights) in sums.iter_mut().zip(&block.output_weights) {
                *sum = std::array::from_fn(|l| sum[l] + weights[l] * activation[l]);
            }
        }
    }
    sums
}

/// [`hidden_sums_inline`] for the target's baseline instruction set.
fn hidden_sums<const N: usize>(
    blocks: &[Block],
    x: &[[f64; LEGS]; N],
) -> [[[f64; LANES]; LEGS]; N] {
    hidden_sums_inline(blocks, x)
}

/// [`hidden_sums_inline`] compiled for AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn hidden_sums_avx2<const N: usize>(
    blocks: &[Block],
    x: &[[f64; LEGS]; N],
) -> [[[f64; LANES]; LEGS]; N] {
    hidden_sums_inline(blocks, x)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{NetworkInput, Provenance};
    use crate::network::Normalisation;

    /// A decoupled model of irregular sizes (so blocks mix networks and the last is padded)
    /// with weights that drive the activations over their whole range.
    fn decoupled() -> Model {
        let sizes = [5, 2, 7, 1, 3, 4];
        let networks = sizes
            .iter()
            .enumerate()
            .map(|(leg, &h)| {
                let count = Network::weight_count(h, 1);
                let weights = (0..count)
                    .map(|i| ((i * 7 + leg * 13) as f64).sin() * 3.0)
                    .collect();
                Network::from_weights(h, 1, weights).unwrap()
            })
            .collect();
        Model {
            networks: Networks::Decoupled(networks),
            input: NetworkInput::Equivalent,
            normalisation: Normalisation {
                mean: [355.0; LEGS],
                span: [140.0; LEGS],
            },
            training_range: [[290.0, 420.0]; LEGS],
            correction_bounds: [[-1.0, 1.0]; LEGS],
            geometry: crate::Geometry::prototype().fingerprint(),
            provenance: Provenance::default(),
            uncertainty: None,
        }
    }

    fn legs(i: usize) -> [f64; LEGS] {
        std::array::from_fn(|k| 280.0 + ((i * 31 + k * 17) % 160) as f64 + (i as f64).cos())
    }

    #[test]
    fn fused_networks_compute_the_reference_corrections() {
        let model = decoupled();
        let fused = FusedModel::new(&model);
        assert_eq!(fused.blocks.len(), 6, "22 nodes in blocks of 4");
        for i in 0..10_000 {
            let q = legs(i);
            let (got, want) = (fused.raw_corrections(&q), model.raw_corrections(&q));
            for k in 0..LEGS {
                assert!(
                    (got[k] - want[k]).abs() < 1e-13,
                    "{q:?}: {got:?} vs {want:?}"
                );
            }
        }
    }

    /// `model` (decoupled) with network 3's output weights at `±magnitude`, alternating in sign.
    fn with_output_weights_of(model: &Model, magnitude: f64) -> Model {
        let mut changed = model.clone();
        if let Networks::Decoupled(networks) = &mut changed.networks {
            let h = networks[2].hidden();
            let mut w = networks[2].weights().to_vec();
            let count = w.len();
            for (j, v) in w[h * LEGS + h..count - 1].iter_mut().enumerate() {
                *v = if j % 2 == 0 { magnitude } else { -magnitude };
            }
            networks[2] = Network::from_weights(h, 1, w).unwrap();
        }
        changed
    }

    #[test]
    fn the_fused_forms_error_bound_covers_it_and_beyond_a_nanometre_the_reference_answers() {
        let model = decoupled();
        let fused = FusedModel::new(&model);
        let bound = fused.error_bound_mm();
        assert!(bound > 0.0 && bound < 1e-12, "{bound:e}");
        // Network 3's output weights at ±1e9, alternating in sign so that they largely cancel:
        // the fused sums could be far more than a nanometre off, so the reference answers.
        let large = with_output_weights_of(&model, 1e9);
        let fused_large = FusedModel::new(&large);
        assert_eq!(fused_large.error_bound_mm(), 0.0);
        // The same at ±1e6: the bound stays under a nanometre, the fused form answers, and its
        // cancelling sums (the summation term of the bound at work) stay within it.
        let cancelling = with_output_weights_of(&model, 1e6);
        let fused_cancelling = FusedModel::new(&cancelling);
        let cancelling_bound = fused_cancelling.error_bound_mm();
        assert!(
            cancelling_bound > 1e-9 && cancelling_bound < MAX_ERROR_MM,
            "{cancelling_bound:e}"
        );
        for i in 0..1000 {
            let q = legs(i);
            assert_eq!(fused_large.raw_corrections(&q), large.raw_corrections(&q));
            let (got, want) = (
                fused_cancelling.raw_corrections(&q),
                cancelling.raw_corrections(&q),
            );
            assert!((got[2] - want[2]).abs() <= cancelling_bound, "{q:?}");
            let (got, want) = (fused.raw_corrections(&q), model.raw_corrections(&q));
            for k in 0..LEGS {
                assert!((got[k] - want[k]).abs() <= bound, "{q:?}");
            }
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn the_avx2_and_portable_builds_give_the_same_bits() {
        if !std::arch::is_x86_feature_detected!("avx2") {
            eprintln!("no AVX2 on this CPU: only the portable build can run");
            return;
        }
        let fused = FusedModel::new(&decoupled());
        for i in 0..10_000 {
            // One point, and two together.
            let x = [fused.reference.normalisation.apply(&legs(i))];
            let portable = hidden_sums(&fused.blocks, &x);
            // SAFETY: AVX2 was detected above.
            let avx2 = unsafe { hidden_sums_avx2(&fused.blocks, &x) };
            assert_eq!(
                portable.map(|p| p.map(|s| s.map(f64::to_bits))),
                avx2.map(|p| p.map(|s| s.map(f64::to_bits)))
            );
            let x = [x[0], fused.reference.normalisation.apply(&legs(i + 1))];
            let portable = hidden_sums(&fused.blocks, &x);
            // SAFETY: AVX2 was detected above.
            let avx2 = unsafe { hidden_sums_avx2(&fused.blocks, &x) };
            assert_eq!(
                portable.map(|p| p.map(|s| s.map(f64::to_bits))),
                avx2.map(|p| p.map(|s| s.map(f64::to_bits)))
            );
        }
    }

    #[test]
    fn points_evaluated_together_get_the_bits_they_get_alone() {
        let model = decoupled();
        // The fused evaluation, and a model beyond the bound (the reference for every point).
        for fused in [
            FusedModel::new(&model),
            FusedModel::new(&with_output_weights_of(&model, 1e9)),
        ] {
            for i in 0..5_000 {
                let (a, b, c) = (legs(i), legs(i + 7919), legs(i + 104_729));
                let bits = |corrections: [f64; LEGS]| corrections.map(f64::to_bits);
                let alone = [a, b, c].map(|q| bits(fused.raw_corrections(&q)));
                assert_eq!(
                    fused.raw_corrections_of([&a, &b]).map(bits),
                    [alone[0], alone[1]]
                );
                assert_eq!(fused.raw_corrections_of([&a, &b, &c]).map(bits), alone);
            }
        }
    }
}
