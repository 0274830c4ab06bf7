//! Training the joint-correction networks (Sec. 3.2).
//!
//! Each network is fitted by Levenberg–Marquardt on the mean squared error (Eq. 15): steps of
//! Eq. 16 with the analytic Jacobian `J`, updates of Eq. 17, an adaptive μ (÷10 after an
//! accepted step, ×10 after a rejected one), stopping when an accepted step changes the loss by
//! less than a relative tolerance; several restarts from standard-normal weights (the paper's
//! initialisation), keeping the one with the lowest training loss. The hidden-node count is
//! chosen by holdout validation (Eq. 18; Eq. 21 for the decoupled networks) over a sweep of
//! sizes: the smallest size whose validation RMSE is within 2 % of the best. The final model is
//! then refitted on all samples at that size unless asked not to.

use std::time::Instant;

use hexacomp_core::model::{Model, NetworkInput, Networks, Provenance};
use hexacomp_core::network::{Network, Normalisation};
use hexacomp_core::records::JointCorrection;
use hexacomp_core::{Fingerprint, LEGS};
use nalgebra::{DMatrix, DVector};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use crate::error::{Error, Result};

/// The two architectures of Fig. 3–4.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Architecture {
    /// One network, six outputs.
    Coupled,
    /// Six networks, one output each.
    Decoupled,
}

/// Settings of the training.
#[derive(Debug, Clone, PartialEq)]
pub struct TrainOptions {
    /// Hidden-node counts tried by the sweep.
    pub hidden_sizes: Vec<usize>,
    /// Restarts per fit; the best training loss is kept.
    pub restarts: usize,
    /// LM iterations per fit at most.
    pub max_iterations: usize,
    /// Stop when an accepted step lowers the loss by less than this fraction.
    pub relative_tolerance: f64,
    /// Fraction of the samples held out for choosing the hidden-node count.
    pub validation_fraction: f64,
    /// Refit on all samples at the chosen size (otherwise keep the holdout fit).
    pub refit_on_all: bool,
    /// The networks' input.
    pub input: NetworkInput,
    /// Seed of the split and the initial weights.
    pub seed: u64,
}

impl Default for TrainOptions {
    fn default() -> Self {
        Self {
            hidden_sizes: (1..=16).collect(),
            restarts: 3,
            max_iterations: 100,
            relative_tolerance: 1e-5,
            validation_fraction: 1.0 / 3.0,
            refit_on_all: true,
            input: NetworkInput::Equivalent,
            seed: 1,
        }
    }
}

/// Training and validation RMSE of one hidden-node count (a point of Fig. 10/11).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SweepPoint {
    /// Hidden nodes.
    pub hidden: usize,
    /// RMSE on the training subset, mm (Eq. 18).
    pub training_rmse_mm: f64,
    /// RMSE on the validation subset, mm (Eq. 18).
    pub validation_rmse_mm: f64,
}

/// The selection curve and choice for one network.
#[derive(Debug, Clone, PartialEq)]
pub struct Selection {
    /// Every size tried.
    pub sweep: Vec<SweepPoint>,
    /// The chosen hidden-node count.
    pub chosen: usize,
}

impl Selection {
    /// The sweep point of the chosen size.
    pub fn chosen_point(&self) -> SweepPoint {
        *self
            .sweep
            .iter()
            .find(|p| p.hidden == self.chosen)
            .expect("chosen size was swept")
    }
}

/// What training produced.
#[derive(Debug, Clone)]
pub struct Trained {
    /// The model, ready to save.
    pub model: Model,
    /// One selection per network (one for coupled, six for decoupled).
    pub selections: Vec<Selection>,
    /// Validation performance, mm: Eq. 18 for coupled, Eq. 21 (√Σ RMSE_i²) for decoupled.
    pub validation_rmse_mm: f64,
    /// Wall-clock seconds of the whole training.
    pub seconds: f64,
}

/// Inputs (network input legs, mm) and targets (corrections, mm) of training rows.
fn samples(rows: &[JointCorrection], input: NetworkInput) -> (Vec<[f64; LEGS]>, Vec<[f64; LEGS]>) {
    let x = rows
        .iter()
        .map(|r| match input {
            NetworkInput::Commanded => r.legs,
            NetworkInput::Equivalent => std::array::from_fn(|i| r.legs[i] - r.corrections[i]),
        })
        .collect();
    (x, rows.iter().map(|r| r.corrections).collect())
}

/// `0..count` in a seeded random order (Fisher–Yates): the first part is held out for
/// validation.
fn shuffled(count: usize, seed: u64) -> Vec<usize> {
    let mut order: Vec<usize> = (0..count).collect();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    for i in (1..order.len()).rev() {
        order.swap(i, rng.random_range(0..=i));
    }
    order
}

/// The smallest and largest value of leg `leg` over `values`, mm.
fn leg_range(values: &[[f64; LEGS]], leg: usize) -> [f64; 2] {
    values
        .iter()
        .fold([f64::INFINITY, f64::NEG_INFINITY], |[lo, hi], v| {
            [lo.min(v[leg]), hi.max(v[leg])]
        })
}

/// The model's training range per leg, mm: the run-time input is the nominal legs, so it covers
/// both the commanded legs and the network-input legs of every row (they differ by the
/// corrections when the input is the equivalent legs), whether the row was held out or not.
fn training_range(inputs: &[[f64; LEGS]], commanded: &[[f64; LEGS]]) -> [[f64; 2]; LEGS] {
    std::array::from_fn(|leg| {
        let ([a, b], [c, d]) = (leg_range(inputs, leg), leg_range(commanded, leg));
        [a.min(c), b.max(d)]
    })
}

/// The model's correction bounds per leg, mm: from the `k`-th smallest to the `k`-th largest of
/// the measured corrections, `k` = max(1, ⌈0.02·(n − 1)⌉) (the 2nd and 98th percentiles, and
/// never the extreme values of 3 or more), widened on each side by 3/4 of that spread plus
/// 0.01 mm (so that a leg whose corrections barely vary still has room for noise). Not the
/// minimum and maximum, so that one wrong correction left in the data cannot open the bounds (a
/// 1e308 mm row would make the run-time clamp do nothing). The clamp holds corrections inside
/// them. Without corrections, ±0.01 mm.
pub fn correction_bounds(targets: &[[f64; LEGS]]) -> [[f64; 2]; LEGS] {
    std::array::from_fn(|leg| {
        let mut values: Vec<f64> = targets.iter().map(|t| t[leg]).collect();
        values.sort_by(f64::total_cmp);
        let n = values.len();
        if n == 0 {
            return [-0.01, 0.01];
        }
        let k = if n >= 3 {
            ((0.02 * (n - 1) as f64).ceil() as usize).clamp(1, (n - 1) / 2)
        } else {
            0
        };
        let (lo, hi) = (values[k], values[n - 1 - k]);
        let margin = 0.75 * (hi - lo) + 0.01;
        [lo - margin, hi + margin]
    })
}

/// Trains a model on corrections rows for the geometry with fingerprint `geometry`.
/// `progress` is called once per fit of the sweep (for progress bars), from worker threads.
pub fn train(
    rows: &[JointCorrection],
    architecture: Architecture,
    geometry: Fingerprint,
    options: &TrainOptions,
    progress: &(dyn Fn() + Sync),
) -> Result<Trained> {
    let start = Instant::now();
    if rows.len() < 6 {
        return Err(Error::InsufficientData(format!(
            "training needs at least 6 configurations, got {}",
            rows.len()
        )));
    }
    if options.hidden_sizes.is_empty() || options.restarts == 0 {
        return Err(Error::InvalidSetting(
            "training needs at least one hidden size and one restart".into(),
        ));
    }
    let (inputs, targets) = samples(rows, options.input);
    let normalisation = Normalisation::of(&inputs)?;
    let split = Split::new(&inputs, &targets, &normalisation, options);
    let outputs: Vec<Vec<usize>> = match architecture {
        Architecture::Coupled => vec![(0..LEGS).collect()],
        Architecture::Decoupled => (0..LEGS).map(|leg| vec![leg]).collect(),
    };
    let (mut networks, selections): (Vec<Network>, Vec<Selection>) = outputs
        .iter()
        .enumerate()
        .map(|(net_index, legs)| select_and_fit(&split, legs, options, net_index, progress))
        .unzip();
    // Eq. 21 (for a coupled model, the one network's Eq. 18 validation RMSE).
    let validation_rmse_mm = selections
        .iter()
        .map(|s| s.chosen_point().validation_rmse_mm.powi(2))
        .sum::<f64>()
        .sqrt();
    let networks = match architecture {
        Architecture::Coupled => Networks::Coupled(networks.remove(0)),
        Architecture::Decoupled => Networks::Decoupled(networks),
    };
    let commanded: Vec<[f64; LEGS]> = rows.iter().map(|r| r.legs).collect();
    let training_range = training_range(&inputs, &commanded);
    let correction_bounds = correction_bounds(&targets);
    let created_unix_s = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let model = Model {
        networks,
        input: options.input,
        normalisation,
        training_range,
        correction_bounds,
        geometry,
        provenance: Provenance {
            created_unix_s,
            configurations: rows.len(),
            training_samples: if options.refit_on_all {
                rows.len()
            } else {
                split.training().len()
            },
            validation_samples: split.validation().len(),
            validation_rmse_mm,
            source: String::new(),
        },
    };
    model.validate()?;
    Ok(Trained {
        model,
        selections,
        validation_rmse_mm,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// Every configuration's normalised input and target, and their seeded split into validation
/// and training configurations.
struct Split<'a> {
    x: Vec<[f64; LEGS]>,
    targets: &'a [[f64; LEGS]],
    order: Vec<usize>,
    validation_count: usize,
}

impl<'a> Split<'a> {
    fn new(
        inputs: &[[f64; LEGS]],
        targets: &'a [[f64; LEGS]],
        normalisation: &Normalisation,
        options: &TrainOptions,
    ) -> Self {
        let order = shuffled(inputs.len(), options.seed);
        let validation_count = ((inputs.len() as f64 * options.validation_fraction).round()
            as usize)
            .clamp(1, inputs.len() - 1);
        Self {
            x: inputs.iter().map(|q| normalisation.apply(q)).collect(),
            targets,
            order,
            validation_count,
        }
    }

    fn validation(&self) -> &[usize] {
        &self.order[..self.validation_count]
    }

    fn training(&self) -> &[usize] {
        &self.order[self.validation_count..]
    }

    /// The samples `indices` for a network whose outputs are the corrections of `legs`.
    fn data(&self, indices: &[usize], legs: &[usize]) -> Data {
        Data {
            x: indices.iter().map(|&k| self.x[k]).collect(),
            y: indices
                .iter()
                .flat_map(|&k| legs.iter().map(move |&l| self.targets[k][l]))
                .collect(),
            outputs: legs.len(),
        }
    }
}

/// One network (outputs: the corrections of `legs`): sweeps the hidden sizes, chooses the
/// smallest whose validation RMSE is within 2 % of the best, and fits it (on all samples when
/// [`TrainOptions::refit_on_all`]).
fn select_and_fit(
    split: &Split,
    legs: &[usize],
    options: &TrainOptions,
    net_index: usize,
    progress: &(dyn Fn() + Sync),
) -> (Network, Selection) {
    let train_data = split.data(split.training(), legs);
    let validation_data = split.data(split.validation(), legs);
    let sweep = sweep(
        &train_data,
        &validation_data,
        options,
        net_index as u64,
        progress,
    );
    let best = sweep
        .iter()
        .map(|p| p.validation_rmse_mm)
        .fold(f64::INFINITY, f64::min);
    let chosen = sweep
        .iter()
        .find(|p| p.validation_rmse_mm <= 1.02 * best)
        .expect("non-empty sweep")
        .hidden;
    let final_data = if options.refit_on_all {
        split.data(&split.order, legs)
    } else {
        train_data
    };
    let (network, _) = fit(
        &final_data,
        chosen,
        options,
        seed_for(options.seed, net_index as u64, chosen),
    );
    (network, Selection { sweep, chosen })
}

/// Normalised inputs and row-major targets (`outputs` per sample) of one network.
struct Data {
    x: Vec<[f64; LEGS]>,
    y: Vec<f64>,
    outputs: usize,
}

fn seed_for(base: u64, network: u64, hidden: usize) -> u64 {
    base.wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ (network << 32) ^ hidden as u64
}

/// Fits every size on the training data and scores it on the validation data, spread over the
/// machine's cores.
fn sweep(
    training: &Data,
    validation: &Data,
    options: &TrainOptions,
    network: u64,
    progress: &(dyn Fn() + Sync),
) -> Vec<SweepPoint> {
    let workers = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .min(options.hidden_sizes.len());
    let mut points: Vec<SweepPoint> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..workers)
            .map(|w| {
                scope.spawn(move || {
                    options
                        .hidden_sizes
                        .iter()
                        .skip(w)
                        .step_by(workers)
                        .map(|&hidden| {
                            let seed = seed_for(options.seed, network, hidden);
                            let (net, training_rmse_mm) = fit(training, hidden, options, seed);
                            progress();
                            SweepPoint {
                                hidden,
                                training_rmse_mm,
                                validation_rmse_mm: rmse(&net, validation),
                            }
                        })
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().expect("sweep worker"))
            .collect()
    });
    points.sort_by_key(|p| p.hidden);
    points
}

/// RMSE of Eq. 18: `√(1/K Σ‖y − N(x)‖²)`, mm.
fn rmse(network: &Network, data: &Data) -> f64 {
    let mut out = [0.0; LEGS];
    let o = data.outputs;
    let sum: f64 = data
        .x
        .iter()
        .enumerate()
        .map(|(k, x)| {
            network.evaluate(x, &mut out[..o]);
            (0..o)
                .map(|j| (data.y[k * o + j] - out[j]).powi(2))
                .sum::<f64>()
        })
        .sum();
    (sum / data.x.len() as f64).sqrt()
}

/// The best of `options.restarts` LM fits of a `hidden`-node network; returns it and its
/// training RMSE (mm).
fn fit(data: &Data, hidden: usize, options: &TrainOptions, seed: u64) -> (Network, f64) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let count = Network::weight_count(hidden, data.outputs);
    (0..options.restarts)
        .map(|_| {
            let initial: Vec<f64> = (0..count)
                .map(|_| StandardNormal.sample(&mut rng))
                .collect();
            let weights = levenberg_marquardt(data, hidden, initial, options);
            let network = Network::from_weights(hidden, data.outputs, weights)
                .expect("LM keeps weights finite");
            let score = rmse(&network, data);
            (network, score)
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .expect("at least one restart")
}

/// Residuals `e = y − N(x)` and the Jacobian `J = ∂N/∂w` (rows: sample × output) of Eq. 16.
fn residuals_and_jacobian(
    data: &Data,
    hidden: usize,
    w: &[f64],
    jacobian: Option<&mut DMatrix<f64>>,
) -> DVector<f64> {
    let o = data.outputs;
    let network = Network::from_weights(hidden, o, w.to_vec());
    let mut e = DVector::zeros(data.x.len() * o);
    let Ok(network) = network else {
        e.fill(f64::INFINITY);
        return e;
    };
    let mut a = [0.0; hexacomp_core::network::MAX_HIDDEN];
    let mut out = [0.0; LEGS];
    let w2_start = hidden * LEGS + hidden;
    let b2_start = w2_start + o * hidden;
    let mut jacobian = jacobian;
    for (k, x) in data.x.iter().enumerate() {
        network.hidden_layer(x, &mut a);
        network.evaluate(x, &mut out[..o]);
        for j in 0..o {
            let row = k * o + j;
            e[row] = data.y[row] - out[j];
            if let Some(jac) = jacobian.as_deref_mut() {
                for h in 0..hidden {
                    let w2 = w[w2_start + j * hidden + h];
                    let d = w2 * (1.0 - a[h] * a[h]);
                    for (i, xi) in x.iter().enumerate() {
                        jac[(row, h * LEGS + i)] = d * xi;
                    }
                    jac[(row, hidden * LEGS + h)] = d;
                    jac[(row, w2_start + j * hidden + h)] = a[h];
                }
                jac[(row, b2_start + j)] = 1.0;
            }
        }
    }
    e
}

/// Levenberg–Marquardt on the sum of squared residuals `K·E(w)` (Eq. 15's loss times `K`: the
/// same minimiser): the step `Δw = (JᵀJ + μI)⁻¹Jᵀe` (Eq. 16) and the update `w ← w + Δw`
/// (Eq. 17), kept only when it lowers the loss.
fn levenberg_marquardt(
    data: &Data,
    hidden: usize,
    mut w: Vec<f64>,
    options: &TrainOptions,
) -> Vec<f64> {
    let n = w.len();
    let rows = data.x.len() * data.outputs;
    let mut jacobian = DMatrix::zeros(rows, n);
    let mut mu = 1e-3;
    let mut e = residuals_and_jacobian(data, hidden, &w, Some(&mut jacobian));
    let mut loss = e.norm_squared();
    for _ in 0..options.max_iterations {
        let jt = jacobian.transpose();
        let jtj = &jt * &jacobian;
        let jte = &jt * &e;
        let mut accepted = false;
        while mu < 1e10 {
            let mut system = jtj.clone();
            for d in 0..n {
                system[(d, d)] += mu;
            }
            let Some(step) = system.cholesky().map(|c| c.solve(&jte)) else {
                mu *= 10.0;
                continue;
            };
            let candidate: Vec<f64> = w.iter().zip(step.iter()).map(|(a, b)| a + b).collect();
            let candidate_e = residuals_and_jacobian(data, hidden, &candidate, None);
            let candidate_loss = candidate_e.norm_squared();
            if candidate_loss < loss {
                let improvement = (loss - candidate_loss) / loss.max(f64::MIN_POSITIVE);
                w = candidate;
                loss = candidate_loss;
                mu = (mu * 0.1).max(1e-12);
                accepted = true;
                if improvement < options.relative_tolerance {
                    return w;
                }
                e = residuals_and_jacobian(data, hidden, &w, Some(&mut jacobian));
                break;
            }
            mu *= 10.0;
        }
        if !accepted {
            break;
        }
    }
    w
}

#[cfg(test)]
mod tests {
    use super::*;

    fn toy_data(outputs: usize) -> Data {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let x: Vec<[f64; LEGS]> = (0..40)
            .map(|_| std::array::from_fn(|_| rng.random_range(-0.5..0.5)))
            .collect();
        let y = x
            .iter()
            .flat_map(|x| (0..outputs).map(move |j| (x[j] * 2.0).sin() + 0.3 * x[(j + 1) % LEGS]))
            .collect();
        Data { x, y, outputs }
    }

    #[test]
    fn analytic_jacobian_matches_finite_differences() {
        for outputs in [1, LEGS] {
            let data = toy_data(outputs);
            let hidden = 4;
            let mut rng = ChaCha8Rng::seed_from_u64(9);
            let w: Vec<f64> = (0..Network::weight_count(hidden, outputs))
                .map(|_| StandardNormal.sample(&mut rng))
                .collect();
            let mut jac = DMatrix::zeros(data.x.len() * outputs, w.len());
            residuals_and_jacobian(&data, hidden, &w, Some(&mut jac));
            let h = 1e-6;
            for p in 0..w.len() {
                let (mut plus, mut minus) = (w.clone(), w.clone());
                plus[p] += h;
                minus[p] -= h;
                // e = y − N, so ∂N/∂w = −∂e/∂w.
                let fd = (residuals_and_jacobian(&data, hidden, &minus, None)
                    - residuals_and_jacobian(&data, hidden, &plus, None))
                    / (2.0 * h);
                let worst = (fd - jac.column(p)).amax();
                assert!(worst < 1e-8, "outputs {outputs} weight {p}: {worst}");
            }
        }
    }

    #[test]
    fn levenberg_marquardt_fits_a_smooth_function_and_never_raises_the_loss() {
        let data = toy_data(2);
        let options = TrainOptions {
            restarts: 1,
            ..Default::default()
        };
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let initial: Vec<f64> = (0..Network::weight_count(6, 2))
            .map(|_| StandardNormal.sample(&mut rng))
            .collect();
        let before = residuals_and_jacobian(&data, 6, &initial, None).norm_squared();
        let fitted = levenberg_marquardt(&data, 6, initial, &options);
        let after = residuals_and_jacobian(&data, 6, &fitted, None).norm_squared();
        assert!(after <= before);
        let network = Network::from_weights(6, 2, fitted).unwrap();
        assert!(rmse(&network, &data) < 1e-3, "{}", rmse(&network, &data));
    }

    #[test]
    fn an_over_parameterised_fit_gets_past_failed_factorisations_and_interpolates() {
        // 5 residuals, 49 weights: JᵀJ is singular and its Cholesky factorisation fails at small
        // μ (as in a sweep's largest sizes on few configurations); raising μ gets past it.
        let mut data = toy_data(1);
        data.x.truncate(5);
        data.y.truncate(5);
        let hidden = 6;
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut initial: Vec<f64> = (0..Network::weight_count(hidden, 1))
            .map(|_| StandardNormal.sample(&mut rng))
            .collect();
        // Output weights 1e8 times too large: JᵀJ ~ 1e16, whose rounding swamps μ = 1e-3, so
        // the very first factorisations fail until μ is raised.
        let w2 = hidden * LEGS + hidden;
        for w in &mut initial[w2..w2 + hidden] {
            *w *= 1e8;
        }
        let fitted = levenberg_marquardt(&data, hidden, initial, &TrainOptions::default());
        let network = Network::from_weights(hidden, 1, fitted).unwrap();
        // Through the five points to far below a micrometre.
        assert!(rmse(&network, &data) < 1e-6, "{}", rmse(&network, &data));
    }

    #[test]
    fn the_fit_stops_at_the_first_accepted_step_that_gains_less_than_the_relative_tolerance() {
        let data = toy_data(2);
        let hidden = 4;
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let initial: Vec<f64> = (0..Network::weight_count(hidden, 2))
            .map(|_| StandardNormal.sample(&mut rng))
            .collect();
        let run = |max_iterations, relative_tolerance| {
            let options = TrainOptions {
                max_iterations,
                relative_tolerance,
                ..TrainOptions::default()
            };
            levenberg_marquardt(&data, hidden, initial.clone(), &options)
        };
        let loss = |w: &[f64]| residuals_and_jacobian(&data, hidden, w, None).norm_squared();
        // Without a tolerance, each iteration is one accepted step: the path of the fit.
        let path: Vec<Vec<f64>> = (0..=40).map(|k| run(k, 0.0)).collect();
        let tolerance = 0.02;
        let stop = (1..path.len())
            .find(|&k| {
                let (before, after) = (loss(&path[k - 1]), loss(&path[k]));
                (before - after) / before < tolerance
            })
            .expect("the gain falls below 2 % within 40 steps");
        assert!(stop >= 3, "the case discriminates: stop at step {stop}");
        assert_eq!(run(100, tolerance), path[stop]);
        // A tolerance of 1 (every gain is below 100 %) stops at the first accepted step.
        assert_eq!(run(100, 1.0), path[1]);
        assert!(loss(&path[1]) < loss(&initial));
    }
}
