//! Training the joint-correction networks (Sec. 3.2).
//!
//! Each network is fitted by Levenberg–Marquardt on the mean squared error (Eq. 15): steps of
//! Eq. 16 with the analytic Jacobian `J`, updates of Eq. 17, an adaptive μ (÷10 after an
//! accepted step, ×10 after a rejected one), stopping when an accepted step changes the loss by
//! less than a relative tolerance, at an iteration cap, or when no step lowers the loss however
//! damped ([`FitStops`] counts which); several restarts from standard-normal weights (the paper's
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
use crate::parallel::in_parallel;
use crate::plan::rows_holding_leg_extremes;

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

/// How the Levenberg–Marquardt runs of a training ended: one run per restart of every fit (the
/// sweep's and the final refits).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FitStops {
    /// An accepted step lowered the loss by less than [`TrainOptions::relative_tolerance`].
    pub settled: usize,
    /// [`TrainOptions::max_iterations`] steps were taken.
    pub iteration_cap: usize,
    /// No step lowered the loss, however strongly damped.
    pub no_descent: usize,
}

impl FitStops {
    /// Every fit counted.
    pub fn total(&self) -> usize {
        self.settled + self.iteration_cap + self.no_descent
    }

    fn count(&mut self, stop: Stop) {
        match stop {
            Stop::Settled => self.settled += 1,
            Stop::IterationCap => self.iteration_cap += 1,
            Stop::NoDescent => self.no_descent += 1,
        }
    }

    fn add(mut self, other: FitStops) -> Self {
        self.settled += other.settled;
        self.iteration_cap += other.iteration_cap;
        self.no_descent += other.no_descent;
        self
    }
}

impl std::fmt::Display for FitStops {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} Levenberg–Marquardt runs: {} settled (loss change below the tolerance), {} at \
             the iteration cap, {} found no lower loss",
            self.total(),
            self.settled,
            self.iteration_cap,
            self.no_descent
        )
    }
}

/// Why one Levenberg–Marquardt fit ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Stop {
    Settled,
    IterationCap,
    NoDescent,
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
    /// How its fits ended.
    pub stops: FitStops,
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
pub fn leg_range(values: &[[f64; LEGS]], leg: usize) -> [f64; 2] {
    values
        .iter()
        .fold([f64::INFINITY, f64::NEG_INFINITY], |[lo, hi], v| {
            [lo.min(v[leg]), hi.max(v[leg])]
        })
}

/// The model's training range per leg, mm: the run-time input is the nominal legs, so it covers
/// both the commanded legs and the network-input legs of every row (they differ by the
/// corrections when the input is the equivalent legs), whether the row was held out or not.
pub(crate) fn training_range(
    inputs: &[[f64; LEGS]],
    commanded: &[[f64; LEGS]],
) -> [[f64; 2]; LEGS] {
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

/// The work of a training of `architecture` on `rows` configurations, in the units of [`train`]'s
/// progress, which reaches exactly this when the training ends. A unit is one entry of one
/// iteration's `JᵀJ` (residual rows × weights², what dominates an iteration's time), counted
/// for every iteration a fit may take; the final fit is counted at the largest hidden size,
/// since its size is chosen only after the sweep. Saturates at `u64::MAX`.
pub fn training_work(rows: usize, architecture: Architecture, options: &TrainOptions) -> u64 {
    let (networks, outputs) = match architecture {
        Architecture::Coupled => (1, LEGS),
        Architecture::Decoupled => (LEGS, 1),
    };
    let training = rows.saturating_sub(validation_count(rows, options.validation_fraction));
    let final_samples = if options.refit_on_all { rows } else { training };
    let largest = options.hidden_sizes.iter().copied().max().unwrap_or(0);
    let sweep = options
        .hidden_sizes
        .iter()
        .map(|&hidden| fit_work(training, outputs, hidden, options))
        .fold(0, u64::saturating_add);
    sweep
        .saturating_add(fit_work(final_samples, outputs, largest, options))
        .saturating_mul(networks as u64)
}

/// The work of one iteration of a fit of `hidden` nodes and `outputs` outputs on `samples`
/// samples (see [`training_work`]).
fn iteration_work(samples: usize, outputs: usize, hidden: usize) -> u64 {
    let weights = Network::weight_count(hidden, outputs) as u64;
    (samples as u64)
        .saturating_mul(outputs as u64)
        .saturating_mul(weights * weights)
}

/// The work of a whole fit, every restart and iteration it may take (see [`training_work`]).
fn fit_work(samples: usize, outputs: usize, hidden: usize, options: &TrainOptions) -> u64 {
    iteration_work(samples, outputs, hidden)
        .saturating_mul(options.max_iterations as u64)
        .saturating_mul(options.restarts as u64)
}

/// Folds of the cross-validation that compares one calibration's models (`calibrate`'s
/// candidates) and chooses the physical model's lead-screw resolution.
pub const CROSS_VALIDATION_FOLDS: usize = 5;

/// The fold (`0..folds`) that holds out each row in a `folds`-fold cross-validation, given each
/// row's commanded legs (mm); `None` for a row fitted in every fold. A row that holds a leg's
/// shortest or longest length among all the rows is never held out: held out, it would ask the
/// models fitted without it for a leg beyond the ones they saw, which no pose within the
/// measured legs asks (a plan starts with each leg's extremes; docs/accuracy.md). The other rows
/// in a seeded random order, dealt out in turn, so fold sizes differ by one at most.
pub fn folds(legs: &[[f64; LEGS]], folds: usize, seed: u64) -> Vec<Option<usize>> {
    let extreme = rows_holding_leg_extremes(legs);
    let mut fold = vec![None; legs.len()];
    let dealt = shuffled(legs.len(), seed)
        .into_iter()
        .filter(|&row| !extreme[row]);
    for (position, row) in dealt.enumerate() {
        fold[row] = Some(position % folds.max(1));
    }
    fold
}

/// The commanded legs of each row, mm (what [`folds`] and [`can_cross_validate`] take).
pub fn commanded_legs(rows: &[JointCorrection]) -> Vec<[f64; LEGS]> {
    rows.iter().map(|row| row.legs).collect()
}

/// Whether `folds` folds of the rows with commanded legs `legs` (mm) can cross-validate: two
/// folds or more, each holding out two rows or more (the legs' extremes are never held out).
pub fn can_cross_validate(legs: &[[f64; LEGS]], folds: usize) -> bool {
    let extremes = rows_holding_leg_extremes(legs)
        .iter()
        .filter(|&&e| e)
        .count();
    folds >= 2 && legs.len() - extremes >= 2 * folds
}

/// The error of networks of `architecture` and the hidden sizes `hidden` (one per network) on
/// configurations they were not fitted on: every fold of [`folds`] of the rows' commanded legs is
/// predicted by networks fitted on the others (and on the legs' extremes, never held out), and the
/// out-of-fold errors over every row held out give Eq. 21's `√Σ_i RMSE_i²`, mm. Comparable with
/// another model's cross-validated error on the same folds (the hidden sizes were chosen on a
/// holdout of these rows, and the inputs are normalised over every row: small advantages to the
/// networks).
pub fn cross_validated_rmse(
    rows: &[JointCorrection],
    architecture: Architecture,
    hidden: &[usize],
    options: &TrainOptions,
    fold_count: usize,
) -> Result<f64> {
    let networks = network_outputs(architecture);
    let legs = commanded_legs(rows);
    if !can_cross_validate(&legs, fold_count) || hidden.len() != networks.len() {
        return Err(Error::CrossValidationImpossible {
            what: format!(
                "{} networks ({} hidden sizes given)",
                networks.len(),
                hidden.len()
            ),
            folds: fold_count,
            rows: rows.len(),
            sizes_match: hidden.len() == networks.len(),
        });
    }
    let (inputs, targets) = samples(rows, options.input);
    let normalisation = Normalisation::of(&inputs)?;
    // The split's normalised samples; its own holdout is not used here.
    let split = Split::new(&inputs, &targets, &normalisation, options);
    let fold = folds(&legs, fold_count, options.seed);
    let held_out = fold.iter().flatten().count();
    let mut squared = 0.0;
    for f in 0..fold_count {
        let (held, fitted): (Vec<usize>, Vec<usize>) =
            (0..rows.len()).partition(|&k| fold[k] == Some(f));
        for (net, legs) in networks.iter().enumerate() {
            let seed = seed_for(options.seed ^ (f as u64) << 48, net as u64, hidden[net]);
            let fitted = split.data(&fitted, legs);
            let (network, _, _) = fit(&fitted, hidden[net], options, seed, &|_| {});
            squared += squared_error(&network, &split.data(&held, legs));
        }
    }
    Ok((squared / held_out as f64).sqrt())
}

/// The legs each network of `architecture` outputs.
fn network_outputs(architecture: Architecture) -> Vec<Vec<usize>> {
    match architecture {
        Architecture::Coupled => vec![(0..LEGS).collect()],
        Architecture::Decoupled => (0..LEGS).map(|leg| vec![leg]).collect(),
    }
}

/// How many of `count` configurations are held out for validation: `fraction` of them, rounded,
/// at least one and leaving at least one to train on.
fn validation_count(count: usize, fraction: f64) -> usize {
    ((count as f64 * fraction).round() as usize).clamp(1, count.saturating_sub(1).max(1))
}

/// Trains a model on corrections rows for the geometry with fingerprint `geometry`.
/// `progress(n)` reports `n` more units of the [`training_work`] done (for progress bars with an
/// estimated time left), from worker threads: once per iteration, and a fit that stops early
/// reports the iterations it did not need.
pub fn train(
    rows: &[JointCorrection],
    architecture: Architecture,
    geometry: Fingerprint,
    options: &TrainOptions,
    progress: &(dyn Fn(u64) + Sync),
) -> Result<Trained> {
    let start = Instant::now();
    if rows.len() < 6 {
        return Err(Error::TooFewConfigurations {
            task: "training",
            needed: 6,
            got: rows.len(),
        });
    }
    if options.hidden_sizes.is_empty() || options.restarts == 0 {
        return Err(Error::NothingToTrain);
    }
    let (inputs, targets) = samples(rows, options.input);
    let normalisation = Normalisation::of(&inputs)?;
    let split = Split::new(&inputs, &targets, &normalisation, options);
    let outputs = network_outputs(architecture);
    let mut networks = Vec::with_capacity(outputs.len());
    let mut selections = Vec::with_capacity(outputs.len());
    let mut stops = FitStops::default();
    for (net_index, legs) in outputs.iter().enumerate() {
        let (network, selection, net_stops) =
            select_and_fit(&split, legs, options, net_index, progress);
        networks.push(network);
        selections.push(selection);
        stops = stops.add(net_stops);
    }
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
        uncertainty: None,
    };
    model.validate()?;
    Ok(Trained {
        model,
        selections,
        validation_rmse_mm,
        seconds: start.elapsed().as_secs_f64(),
        stops,
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
        let validation_count = validation_count(inputs.len(), options.validation_fraction);
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
/// [`TrainOptions::refit_on_all`], else again on the training samples, as the sweep did).
fn select_and_fit(
    split: &Split,
    legs: &[usize],
    options: &TrainOptions,
    net_index: usize,
    progress: &(dyn Fn(u64) + Sync),
) -> (Network, Selection, FitStops) {
    let train_data = split.data(split.training(), legs);
    let validation_data = split.data(split.validation(), legs);
    let (sweep, sweep_stops) = sweep(
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
    let (network, _, final_stops) = fit(
        &final_data,
        chosen,
        options,
        seed_for(options.seed, net_index as u64, chosen),
        progress,
    );
    // The final fit was counted at the largest size: report what the chosen size did not need.
    let largest = options.hidden_sizes.iter().copied().max().unwrap_or(chosen);
    let samples = final_data.x.len();
    progress(
        fit_work(samples, legs.len(), largest, options)
            - fit_work(samples, legs.len(), chosen, options),
    );
    (
        network,
        Selection { sweep, chosen },
        sweep_stops.add(final_stops),
    )
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
    progress: &(dyn Fn(u64) + Sync),
) -> (Vec<SweepPoint>, FitStops) {
    let results = in_parallel(&options.hidden_sizes, |&hidden| {
        let seed = seed_for(options.seed, network, hidden);
        let (net, training_rmse_mm, stops) = fit(training, hidden, options, seed, progress);
        let point = SweepPoint {
            hidden,
            training_rmse_mm,
            validation_rmse_mm: rmse(&net, validation),
        };
        (point, stops)
    });
    let stops = results
        .iter()
        .fold(FitStops::default(), |total, (_, s)| total.add(*s));
    let mut points: Vec<SweepPoint> = results.into_iter().map(|(p, _)| p).collect();
    points.sort_by_key(|p| p.hidden);
    (points, stops)
}

/// RMSE of Eq. 18: `√(1/K Σ‖y − N(x)‖²)`, mm.
fn rmse(network: &Network, data: &Data) -> f64 {
    (squared_error(network, data) / data.x.len() as f64).sqrt()
}

/// `Σ‖y − N(x)‖²` over `data`'s samples, mm².
fn squared_error(network: &Network, data: &Data) -> f64 {
    let mut out = [0.0; LEGS];
    let o = data.outputs;
    data.x
        .iter()
        .enumerate()
        .map(|(k, x)| {
            network.evaluate(x, &mut out[..o]);
            (0..o)
                .map(|j| (data.y[k * o + j] - out[j]).powi(2))
                .sum::<f64>()
        })
        .sum()
}

/// The best of `options.restarts` LM fits of a `hidden`-node network; returns it, its training
/// RMSE (mm) and how the restarts ended.
fn fit(
    data: &Data,
    hidden: usize,
    options: &TrainOptions,
    seed: u64,
    progress: &(dyn Fn(u64) + Sync),
) -> (Network, f64, FitStops) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let count = Network::weight_count(hidden, data.outputs);
    let mut stops = FitStops::default();
    let (network, score) = (0..options.restarts)
        .map(|_| {
            let initial: Vec<f64> = (0..count)
                .map(|_| StandardNormal.sample(&mut rng))
                .collect();
            let (weights, stop) = levenberg_marquardt(data, hidden, initial, options, progress);
            stops.count(stop);
            let network = Network::from_weights(hidden, data.outputs, weights)
                .expect("LM keeps weights finite");
            let score = rmse(&network, data);
            (network, score)
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .expect("at least one restart");
    (network, score, stops)
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
/// (Eq. 17), kept only when it lowers the loss. Returns the weights and why it stopped;
/// reports [`TrainOptions::max_iterations`] iterations' work to `progress` in all.
fn levenberg_marquardt(
    data: &Data,
    hidden: usize,
    mut w: Vec<f64>,
    options: &TrainOptions,
    progress: &(dyn Fn(u64) + Sync),
) -> (Vec<f64>, Stop) {
    let n = w.len();
    let rows = data.x.len() * data.outputs;
    let mut jacobian = DMatrix::zeros(rows, n);
    let mut mu = 1e-3;
    let mut e = residuals_and_jacobian(data, hidden, &w, Some(&mut jacobian));
    let mut loss = e.norm_squared();
    let budget = options.max_iterations as u64;
    let work = iteration_work(data.x.len(), data.outputs, hidden);
    let stopped = |done: u64, stop: Stop| {
        progress(work.saturating_mul(budget - done));
        stop
    };
    for iteration in 0..budget {
        progress(work);
        let done = iteration + 1;
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
                    return (w, stopped(done, Stop::Settled));
                }
                e = residuals_and_jacobian(data, hidden, &w, Some(&mut jacobian));
                break;
            }
            mu *= 10.0;
        }
        if !accepted {
            return (w, stopped(done, Stop::NoDescent));
        }
    }
    (w, Stop::IterationCap)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Standard-normal weights of a `hidden`-node network with `outputs` outputs, from `seed`.
    fn random_weights(hidden: usize, outputs: usize, seed: u64) -> Vec<f64> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..Network::weight_count(hidden, outputs))
            .map(|_| StandardNormal.sample(&mut rng))
            .collect()
    }

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
        let (fitted, _) = levenberg_marquardt(&data, 6, initial, &options, &|_| {});
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
        let (fitted, _) =
            levenberg_marquardt(&data, hidden, initial, &TrainOptions::default(), &|_| {});
        let network = Network::from_weights(hidden, 1, fitted).unwrap();
        // Through the five points to far below a micrometre.
        assert!(rmse(&network, &data) < 1e-6, "{}", rmse(&network, &data));
    }

    #[test]
    fn the_fit_stops_at_the_first_accepted_step_that_gains_less_than_the_relative_tolerance() {
        let data = toy_data(2);
        let hidden = 4;
        let initial = random_weights(hidden, 2, 5);
        let run = |max_iterations, relative_tolerance| {
            let options = TrainOptions {
                max_iterations,
                relative_tolerance,
                ..TrainOptions::default()
            };
            levenberg_marquardt(&data, hidden, initial.clone(), &options, &|_| {}).0
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

    /// Runs one fit counting the progress it reports; returns why it stopped and that count.
    fn stop_and_progress(
        data: &Data,
        hidden: usize,
        initial: Vec<f64>,
        options: &TrainOptions,
    ) -> (Stop, u64) {
        let reported = std::sync::atomic::AtomicU64::new(0);
        let (_, stop) = levenberg_marquardt(data, hidden, initial, options, &|n| {
            reported.fetch_add(n, std::sync::atomic::Ordering::Relaxed);
        });
        (stop, reported.into_inner())
    }

    #[test]
    fn each_fit_says_why_it_stopped_and_reports_the_work_of_every_iteration_it_may_take() {
        let data = toy_data(2);
        let hidden = 4;
        let initial = random_weights(hidden, 2, 5);
        let options = |max_iterations, relative_tolerance| TrainOptions {
            max_iterations,
            relative_tolerance,
            ..TrainOptions::default()
        };
        // 40 samples × 2 outputs × (4·6 + 4 + 2·4 + 2 = 38 weights)².
        let work = 40 * 2 * 38 * 38;
        assert_eq!(iteration_work(40, 2, hidden), work);
        // No tolerance: every step gains something, so the cap ends it.
        assert_eq!(
            stop_and_progress(&data, hidden, initial.clone(), &options(7, 0.0)),
            (Stop::IterationCap, 7 * work)
        );
        // Every gain is below 100 %: the first accepted step settles it, and the 99 iterations
        // it did not need are reported at once.
        assert_eq!(
            stop_and_progress(&data, hidden, initial.clone(), &options(100, 1.0)),
            (Stop::Settled, 100 * work)
        );
        // Data a network reproduces exactly, fitted from that network's weights: the loss is
        // zero and no step can lower it.
        let (exact, _) = levenberg_marquardt(&data, hidden, initial, &options(100, 0.0), &|_| {});
        let network = Network::from_weights(hidden, 2, exact.clone()).unwrap();
        let mut reproduced = Data {
            x: data.x.clone(),
            y: Vec::new(),
            outputs: 2,
        };
        let mut out = [0.0; LEGS];
        for x in &data.x {
            network.evaluate(x, &mut out[..2]);
            reproduced.y.extend_from_slice(&out[..2]);
        }
        assert_eq!(
            stop_and_progress(&reproduced, hidden, exact, &options(100, 0.0)),
            (Stop::NoDescent, 100 * work)
        );
    }

    #[test]
    fn a_training_reports_exactly_its_work_and_counts_every_fit() {
        let rows: Vec<JointCorrection> = toy_data(LEGS)
            .x
            .iter()
            .enumerate()
            .map(|(k, x)| JointCorrection {
                id: k.to_string(),
                legs: x.map(|v| 400.0 + 50.0 * v),
                // One linear function of the legs for every leg: one node fits it, coupled or
                // not, so a size below the largest is chosen.
                corrections: [0.1 * x.iter().sum::<f64>(); LEGS],
            })
            .collect();
        for architecture in [Architecture::Coupled, Architecture::Decoupled] {
            // 8 nodes overfit 27 training samples: a smaller size is chosen.
            let options = TrainOptions {
                hidden_sizes: vec![1, 2, 8],
                restarts: 2,
                max_iterations: 20,
                ..TrainOptions::default()
            };
            let reported = std::sync::atomic::AtomicU64::new(0);
            let trained = train(&rows, architecture, Fingerprint(1), &options, &|n| {
                reported.fetch_add(n, std::sync::atomic::Ordering::Relaxed);
            })
            .unwrap();
            let work = training_work(rows.len(), architecture, &options);
            assert_eq!(reported.into_inner(), work, "{architecture:?}");
            // (3 sizes + the final fit) × 2 restarts per network.
            let (networks, outputs) = match architecture {
                Architecture::Coupled => (1, LEGS),
                Architecture::Decoupled => (LEGS, 1),
            };
            assert_eq!(trained.stops.total(), networks * 4 * 2, "{architecture:?}");
            // The final fit's surplus (counted at 8 nodes) is exercised.
            assert!(
                trained.selections.iter().any(|s| s.chosen < 8),
                "{:?}",
                trained.selections
            );
            // 40 rows: 13 held out, 27 to train on; the final fit on all 40 counted at 8 nodes.
            let by_hand: usize = [(27, 1), (27, 2), (27, 8), (40, 8)]
                .iter()
                .map(|&(samples, hidden)| {
                    let weights = hidden * LEGS + hidden + outputs * hidden + outputs;
                    samples * outputs * weights * weights * 20 * 2
                })
                .sum();
            assert_eq!(work, (networks * by_hand) as u64, "{architecture:?}");
            // Sizes that training refuses still have a work (and no overflow).
            for rows in [0, 1, 2] {
                assert!(training_work(rows, architecture, &options) < work);
            }
        }
    }
}
