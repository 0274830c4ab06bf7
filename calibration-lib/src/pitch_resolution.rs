//! How finely the physical model's lead-screw curves are resolved, chosen per machine by
//! cross-validation.
//!
//! A curve of few B-spline coefficients cannot follow a short lead-screw period; one of many
//! fits the noise of few configurations (docs/accuracy.md: on the paper's robot eight do best,
//! on a robot with a 60 mm period twelve). Each resolution of [`PITCH_RESOLUTIONS`] is
//! identified without each fold, and predicts the fold's robust corrections where they are
//! exact (Eq. 21's `√Σ_i RMSE_i²`, mm). The machine's resolution is the coarsest whose error is
//! within one standard error of the lowest (the one-standard-error rule of cross-validation:
//! a finer curve has to beat the coarser by more than the estimate's own noise). Its score is
//! on the folds the networks are scored on, so the physical model stays comparable with them.

use hexacomp_core::records::{JointCorrection, MeasuredConfiguration};
use hexacomp_core::{ForwardOptions, Geometry, LEGS, forward_kinematics};

use crate::error::{Error, Result};
use crate::identify::{IdentifyOptions, identify};
use crate::parallel::in_parallel;
use crate::train::{can_cross_validate, commanded_legs, folds};
use hexacomp_core::physical::PhysicalModel;

/// The lead-screw resolutions tried: B-spline coefficients per leg's curve (a knot every 30,
/// 16.7 and 11.5 mm of the prototype's 150 mm stroke: the stroke over `n − 3` spacings).
pub const PITCH_RESOLUTIONS: [usize; 3] = [8, 12, 16];

/// The smoothness priors' weights tried at the chosen resolution besides none
/// ([`IdentifyOptions::smoothness`]): on the blind robot at 50 configurations these three
/// cross-validated in the order of their blind errors (docs/accuracy.md).
pub const SMOOTHNESS_WEIGHTS: [f64; 3] = [0.003, 0.01, 0.03];

/// How one resolution predicted the configurations held out of its identification.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ResolutionScore {
    /// B-spline coefficients per leg's lead-screw curve.
    pub pitch_basis: usize,
    /// The weight of the curves' smoothness prior ([`IdentifyOptions::smoothness`]).
    pub smoothness: f64,
    /// Eq. 21's `√Σ_i RMSE_i²` over every configuration, each predicted by the model identified
    /// without its fold, mm.
    pub cross_validated_rmse_mm: f64,
    /// The standard error of that estimate over the configurations (of the mean squared miss,
    /// carried to the RMSE to first order: `SE(m)/(2·RMSE)`), mm.
    pub standard_error_mm: f64,
}

/// The resolution chosen for a machine, and how every one tried scored.
#[derive(Debug, Clone, PartialEq)]
pub struct ResolutionChoice {
    /// [`crate::identify::PHYSICAL`] with the chosen resolution and smoothness prior: the
    /// physical model's identification.
    pub options: IdentifyOptions,
    /// Every resolution that could be cross-validated without a smoothness prior, in the order
    /// of [`PITCH_RESOLUTIONS`].
    pub scores: Vec<ResolutionScore>,
    /// Every resolution that could not (an identification without a fold failed, or its
    /// error is not finite), with why: left out of the choice.
    pub failed: Vec<(usize, String)>,
    /// The resolution chosen among `scores`, with each smoothness prior of
    /// [`SMOOTHNESS_WEIGHTS`] that could be cross-validated, in that order.
    pub smoothed: Vec<ResolutionScore>,
    /// Every weight that could not, with why.
    pub smoothing_failed: Vec<(f64, String)>,
}

impl ResolutionChoice {
    /// What resolution `pitch_basis` gave: its score, or why it has none. `None` for one not
    /// tried.
    pub fn outcome(
        &self,
        pitch_basis: usize,
    ) -> Option<std::result::Result<&ResolutionScore, &str>> {
        outcome_in(&self.scores, |s| s.pitch_basis, &self.failed, pitch_basis)
    }

    /// What the chosen resolution gave with the smoothness prior of weight `smoothness` (0:
    /// none): its score, or why it has none. `None` for a weight not tried.
    pub fn smoothing_outcome(
        &self,
        smoothness: f64,
    ) -> Option<std::result::Result<&ResolutionScore, &str>> {
        if smoothness == 0.0 {
            return self.outcome(self.options.pitch_basis);
        }
        outcome_in(
            &self.smoothed,
            |s| s.smoothness,
            &self.smoothing_failed,
            smoothness,
        )
    }

    /// The chosen resolution's score without a smoothness prior.
    pub fn chosen_without_prior(&self) -> &ResolutionScore {
        self.smoothing_outcome(0.0)
            .and_then(std::result::Result::ok)
            .expect("the chosen resolution was scored")
    }

    /// The chosen resolution's and smoothness prior's score.
    pub fn chosen(&self) -> &ResolutionScore {
        self.smoothing_outcome(self.options.smoothness)
            .and_then(std::result::Result::ok)
            .expect("the chosen resolution and prior were scored")
    }

    /// The resolutions besides the chosen one that the cross-validation could not tell from
    /// the best without a smoothness prior (within one standard error of the lowest error),
    /// coarsest first: the uncertainty's alternatives ([`identified_on_every_configuration`] as
    /// they were scored).
    pub fn indistinguishable(&self) -> Vec<usize> {
        within_one_standard_error(&self.scores)
            .map(|s| s.pitch_basis)
            .filter(|&basis| basis != self.options.pitch_basis)
            .collect()
    }
}

/// The score among `scores` whose `key` is `wanted`, or why it has none among `failed`; `None`
/// where it is in neither.
fn outcome_in<'a, K: PartialEq>(
    scores: &'a [ResolutionScore],
    key: impl Fn(&ResolutionScore) -> K,
    failed: &'a [(K, String)],
    wanted: K,
) -> Option<std::result::Result<&'a ResolutionScore, &'a str>> {
    scores
        .iter()
        .find(|s| key(s) == wanted)
        .map(Ok)
        .or_else(|| {
            failed
                .iter()
                .find(|(k, _)| *k == wanted)
                .map(|(_, why)| Err(why.as_str()))
        })
}

/// The physical models identified with each of `forms` on every configuration of
/// `measurements`, in the order of `forms`: such as the chosen resolution without its
/// smoothness prior, which bounds the prior's bias
/// ([`crate::uncertainty::Propagation::with_prior_bias`]), and the resolutions the
/// cross-validation could not tell from the chosen one ([`ResolutionChoice::indistinguishable`],
/// each with [`IdentifyOptions::physical`], as it was scored); an error naming the first that
/// could not be (by its resolution and prior). The identifications run on the machine's cores.
pub fn identified_on_every_configuration(
    nominal: &Geometry,
    measurements: &[MeasuredConfiguration],
    forms: &[IdentifyOptions],
) -> Result<Vec<PhysicalModel>> {
    in_parallel(forms, |options| {
        identify(nominal, measurements, options)
            .map(|identified| identified.model)
            .map_err(|e| {
                let prior = if options.smoothness > 0.0 {
                    format!("with a smoothness prior of {}", options.smoothness)
                } else {
                    "without a smoothness prior".to_string()
                };
                e.of(format!(
                    "the physical model of {} lead-screw coefficients per leg {prior}, \
                     identified on every configuration",
                    options.pitch_basis
                ))
            })
    })
    .into_iter()
    .collect()
}

/// Chooses the lead-screw resolution of the physical model of the kept `measurements` and their
/// robust `corrections` (one row per measurement, in the same order) on the folds
/// [`folds`] of the corrections' commanded legs (the legs' extremes never held out): the
/// coarsest whose model, identified without each fold, predicts the fold's corrections within
/// one standard error of the best; then, at that resolution, the smoothness prior among none
/// and [`SMOOTHNESS_WEIGHTS`] whose model predicts them best. The
/// identifications run on the machine's cores; `progress(1)` reports each one done (of
/// [`identifications`]).
pub fn chosen_resolution(
    nominal: &Geometry,
    measurements: &[MeasuredConfiguration],
    corrections: &[JointCorrection],
    seed: u64,
    fold_count: usize,
    progress: &(dyn Fn(u64) + Sync),
) -> Result<ResolutionChoice> {
    if measurements.len() != corrections.len()
        || measurements
            .iter()
            .zip(corrections)
            .any(|(m, c)| m.id != c.id)
    {
        return Err(Error::CorrectionsMismatch {
            measurements: measurements.len(),
            corrections: corrections.len(),
        });
    }
    let legs = commanded_legs(corrections);
    if !can_cross_validate(&legs, fold_count) {
        return Err(Error::CrossValidationImpossible {
            what: "the physical model".into(),
            folds: fold_count,
            rows: measurements.len(),
            sizes_match: true,
        });
    }
    let fold = folds(&legs, fold_count, seed);
    // Each of `candidates` identified without each fold, on the machine's cores: every job's
    // misses, each candidate's folds in order.
    let misses = |candidates: Vec<IdentifyOptions>| {
        let jobs: Vec<(IdentifyOptions, usize)> = candidates
            .into_iter()
            .flat_map(|options| (0..fold_count).map(move |f| (options, f)))
            .collect();
        in_parallel(&jobs, |(options, f)| {
            let missed = fold_miss(nominal, measurements, corrections, &fold, *f, options);
            progress(1);
            missed
        })
    };
    let missed = misses(PITCH_RESOLUTIONS.map(IdentifyOptions::physical).to_vec());
    let choice = choice_of(measurements.len(), fold_count, missed)?;
    let missed = misses(
        SMOOTHNESS_WEIGHTS
            .map(|w| choice.options.smoothed(w))
            .to_vec(),
    );
    Ok(choice.smoothed_by(measurements.len(), fold_count, missed))
}

/// The score of each of `candidates`, or why it has none, from every job's misses (each
/// candidate's `fold_count` folds in order) over `configurations` configurations.
fn scores_of(
    candidates: impl IntoIterator<Item = IdentifyOptions>,
    configurations: usize,
    fold_count: usize,
    missed: Vec<Result<Vec<(usize, f64)>>>,
) -> Vec<Result<ResolutionScore>> {
    let mut missed = missed.into_iter();
    candidates
        .into_iter()
        .map(|options| {
            let fold_results: Vec<_> = missed.by_ref().take(fold_count).collect();
            scored(&options, configurations, fold_results)
        })
        .collect()
}

impl ResolutionChoice {
    /// This choice, its resolution then scored with each weight of [`SMOOTHNESS_WEIGHTS`]
    /// from every job's result (each weight's folds in order) over `configurations`
    /// configurations, and identified with the prior that scored lowest (none if none did
    /// better); weights that could not be scored left out and named.
    fn smoothed_by(
        mut self,
        configurations: usize,
        fold_count: usize,
        missed: Vec<Result<Vec<(usize, f64)>>>,
    ) -> Self {
        let candidates = SMOOTHNESS_WEIGHTS.map(|weight| self.options.smoothed(weight));
        for (weight, score) in SMOOTHNESS_WEIGHTS.into_iter().zip(scores_of(
            candidates,
            configurations,
            fold_count,
            missed,
        )) {
            match score {
                Ok(score) => self.smoothed.push(score),
                Err(why) => self.smoothing_failed.push((weight, why.to_string())),
            }
        }
        let best = std::iter::once(self.chosen_without_prior())
            .chain(&self.smoothed)
            .min_by(|a, b| {
                a.cross_validated_rmse_mm
                    .total_cmp(&b.cross_validated_rmse_mm)
            })
            .expect("the resolution was scored")
            .smoothness;
        self.options = self.options.smoothed(best);
        self
    }
}

/// The choice from every job's result (each resolution of [`PITCH_RESOLUTIONS`] in turn, its
/// folds in order) over `configurations` configurations: the resolutions that could not be
/// scored left out and named; an error when none could.
fn choice_of(
    configurations: usize,
    fold_count: usize,
    missed: Vec<Result<Vec<(usize, f64)>>>,
) -> Result<ResolutionChoice> {
    let mut scores = Vec::with_capacity(PITCH_RESOLUTIONS.len());
    let mut failed = Vec::new();
    let candidates = PITCH_RESOLUTIONS.map(IdentifyOptions::physical);
    for (basis, score) in
        PITCH_RESOLUTIONS
            .into_iter()
            .zip(scores_of(candidates, configurations, fold_count, missed))
    {
        match score {
            Ok(score) => scores.push(score),
            Err(why) => failed.push((basis, why.to_string())),
        }
    }
    if scores.is_empty() {
        return Err(Error::NoResolutionCrossValidated { reasons: failed });
    }
    Ok(ResolutionChoice {
        options: IdentifyOptions::physical(coarsest_within_one_standard_error(&scores).pitch_basis),
        scores,
        failed,
        smoothed: Vec::new(),
        smoothing_failed: Vec::new(),
    })
}

/// The score of the identification `options` from its folds' misses (in fold order), or why
/// it has none.
fn scored(
    options: &IdentifyOptions,
    configurations: usize,
    folds: Vec<Result<Vec<(usize, f64)>>>,
) -> Result<ResolutionScore> {
    // Each held-out configuration's squared miss in the plan's order: the score does not
    // depend on which core ran which fold.
    let mut squared = vec![None; configurations];
    for (f, result) in folds.into_iter().enumerate() {
        let misses = result.map_err(|e| Error::FoldFailed {
            fold: f + 1,
            cause: Box::new(e),
        })?;
        for (k, miss) in misses {
            squared[k] = Some(miss);
        }
    }
    let squared: Vec<f64> = squared.into_iter().flatten().collect();
    let score = score_of(options, &squared);
    if !(score.cross_validated_rmse_mm.is_finite() && score.standard_error_mm.is_finite()) {
        return Err(Error::ScoreUnbounded {
            rmse_mm: score.cross_validated_rmse_mm,
            standard_error_mm: score.standard_error_mm,
        });
    }
    Ok(score)
}

/// The identifications [`chosen_resolution`] runs on `fold_count` folds: each resolution, and
/// each smoothness prior at the chosen one, without each fold.
pub fn identifications(fold_count: usize) -> u64 {
    ((PITCH_RESOLUTIONS.len() + SMOOTHNESS_WEIGHTS.len()) * fold_count) as u64
}

/// [`chosen_resolution`] when every fold has two configurations or more to hold out besides the
/// legs' extremes ([`can_cross_validate`]), `None` with fewer (then the physical model is
/// identified with [`crate::identify::PHYSICAL`]'s eight coefficients).
pub fn chosen_if_cross_validated(
    nominal: &Geometry,
    measurements: &[MeasuredConfiguration],
    corrections: &[JointCorrection],
    seed: u64,
    fold_count: usize,
    progress: &(dyn Fn(u64) + Sync),
) -> Result<Option<ResolutionChoice>> {
    if !can_cross_validate(&commanded_legs(corrections), fold_count) {
        return Ok(None);
    }
    chosen_resolution(
        nominal,
        measurements,
        corrections,
        seed,
        fold_count,
        progress,
    )
    .map(Some)
}

/// The score with the fewest coefficients whose error is within one standard error of the
/// lowest error's.
fn coarsest_within_one_standard_error(scores: &[ResolutionScore]) -> &ResolutionScore {
    within_one_standard_error(scores)
        .min_by_key(|s| s.pitch_basis)
        .expect("the best is within its own standard error")
}

/// The scores whose error is within one standard error of the lowest error's (that one
/// included), in the order of `scores`.
fn within_one_standard_error(scores: &[ResolutionScore]) -> impl Iterator<Item = &ResolutionScore> {
    let best = scores
        .iter()
        .min_by(|a, b| {
            a.cross_validated_rmse_mm
                .total_cmp(&b.cross_validated_rmse_mm)
        })
        .expect("resolutions are tried");
    let within = best.cross_validated_rmse_mm + best.standard_error_mm;
    scores
        .iter()
        .filter(move |s| s.cross_validated_rmse_mm <= within)
}

/// The score of the identification `options` from each configuration's squared miss (summed
/// over the legs, mm²).
fn score_of(options: &IdentifyOptions, squared: &[f64]) -> ResolutionScore {
    let n = squared.len() as f64;
    let mean = squared.iter().sum::<f64>() / n;
    let variance = squared.iter().map(|s| (s - mean).powi(2)).sum::<f64>() / (n - 1.0);
    let rmse = mean.sqrt();
    ResolutionScore {
        pitch_basis: options.pitch_basis,
        smoothness: options.smoothness,
        cross_validated_rmse_mm: rmse,
        // No miss at all: nothing to be uncertain about.
        standard_error_mm: if rmse > 0.0 {
            (variance / n).sqrt() / (2.0 * rmse)
        } else {
            0.0
        },
    }
}

/// The squared miss, summed over the legs, of each of fold `f`'s configurations (by index) by
/// the model identified with `options` on the other folds.
fn fold_miss(
    nominal: &Geometry,
    measurements: &[MeasuredConfiguration],
    corrections: &[JointCorrection],
    fold: &[Option<usize>],
    f: usize,
    options: &IdentifyOptions,
) -> Result<Vec<(usize, f64)>> {
    let fitted: Vec<MeasuredConfiguration> = measurements
        .iter()
        .zip(fold)
        .filter(|(_, of)| **of != Some(f))
        .map(|(m, _)| m.clone())
        .collect();
    let model = identify(nominal, &fitted, options)?.model;
    fold.iter()
        .enumerate()
        .filter(|(_, of)| **of == Some(f))
        .map(|(k, _)| {
            Ok((
                k,
                squared_miss(nominal, &model, &measurements[k], &corrections[k])?,
            ))
        })
        .collect()
}

/// The squared difference, summed over the legs, between `row`'s robust correction and the one
/// `model` predicts where it is exact: at the pose the machine reached, whose nominal legs are
/// the equivalent legs `q − Δq`; there the machine needed the commanded legs `q`, and the model
/// commands `q_model`, so the predicted correction is `Δq + (q_model − q)`.
fn squared_miss(
    nominal: &Geometry,
    model: &PhysicalModel,
    measured: &MeasuredConfiguration,
    row: &JointCorrection,
) -> Result<f64> {
    let equivalent: [f64; LEGS] = std::array::from_fn(|i| row.legs[i] - row.corrections[i]);
    let reached = forward_kinematics(
        nominal,
        &equivalent,
        &measured.pose(),
        &ForwardOptions::default(),
    )?;
    let modelled = model.command(&reached);
    Ok((0..LEGS).map(|i| (modelled[i] - row.legs[i]).powi(2)).sum())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::identify::PHYSICAL;

    fn score(pitch_basis: usize, rmse: f64, se: f64) -> ResolutionScore {
        ResolutionScore {
            pitch_basis,
            smoothness: 0.0,
            cross_validated_rmse_mm: rmse,
            standard_error_mm: se,
        }
    }

    #[test]
    fn a_finer_curve_must_beat_the_coarser_by_more_than_one_standard_error() {
        // The default robot at 150 configurations: twelve is lower by less than the noise.
        let level = [
            score(8, 0.0366, 0.0010),
            score(12, 0.0365, 0.0009),
            score(16, 0.0378, 0.0010),
        ];
        assert_eq!(coarsest_within_one_standard_error(&level).pitch_basis, 8);
        // A short lead-screw period: eight misses by far more.
        let short = [
            score(8, 0.0475, 0.0012),
            score(12, 0.0367, 0.0009),
            score(16, 0.0377, 0.0010),
        ];
        assert_eq!(coarsest_within_one_standard_error(&short).pitch_basis, 12);
        // Only the finest within reach of itself.
        let finest = [
            score(8, 0.0475, 0.0012),
            score(12, 0.0420, 0.0011),
            score(16, 0.0377, 0.0010),
        ];
        assert_eq!(coarsest_within_one_standard_error(&finest).pitch_basis, 16);
    }

    #[test]
    fn the_alternatives_are_the_other_resolutions_within_one_standard_error_of_the_best() {
        let choice = |scores: Vec<ResolutionScore>| ResolutionChoice {
            options: IdentifyOptions::physical(
                coarsest_within_one_standard_error(&scores).pitch_basis,
            ),
            scores,
            failed: Vec::new(),
            smoothed: Vec::new(),
            smoothing_failed: Vec::new(),
        };
        // The strong lead-screw robot at 100 configurations: twelve lowest, eight chosen, both
        // others within the noise.
        let level = choice(vec![
            score(8, 0.0378, 0.0012),
            score(12, 0.0370, 0.0012),
            score(16, 0.0374, 0.0012),
        ]);
        assert_eq!(level.options.pitch_basis, 8);
        assert_eq!(level.indistinguishable(), [12, 16]);
        // Twelve chosen, sixteen within its noise, eight far off.
        let short = choice(vec![
            score(8, 0.0475, 0.0012),
            score(12, 0.0367, 0.0009),
            score(16, 0.0370, 0.0010),
        ]);
        assert_eq!(short.indistinguishable(), [16]);
        // The best alone within its standard error: no alternative.
        let clear = choice(vec![
            score(8, 0.0475, 0.0012),
            score(12, 0.0367, 0.0009),
            score(16, 0.0477, 0.0010),
        ]);
        assert_eq!(clear.indistinguishable(), [0usize; 0]);
    }

    #[test]
    fn a_resolution_whose_fold_fails_or_misses_without_bound_is_left_out_and_says_why() {
        let fold = |misses: &[(usize, f64)]| Ok(misses.to_vec());
        let good = scored(
            &IdentifyOptions::physical(8),
            4,
            vec![fold(&[(0, 1.0), (2, 4.0)]), fold(&[(1, 1.0), (3, 4.0)])],
        );
        assert_eq!(
            good,
            Ok(score_of(
                &IdentifyOptions::physical(8),
                &[1.0, 1.0, 4.0, 4.0]
            ))
        );
        let failed = scored(
            &IdentifyOptions::physical(12),
            4,
            vec![
                fold(&[(0, 1.0), (2, 4.0)]),
                Err(Error::SingularConfiguration {
                    configuration: "3".into(),
                }),
            ],
        );
        assert_eq!(
            failed.unwrap_err().to_string(),
            "identified without fold 2: insufficient data: configuration 3 is singular"
        );
        let unbounded = scored(
            &IdentifyOptions::physical(16),
            2,
            vec![fold(&[(0, f64::INFINITY)]), fold(&[(1, 1.0)])],
        );
        assert!(
            unbounded
                .unwrap_err()
                .to_string()
                .contains("cross-validated to inf ±")
        );
        // Nothing missed: a zero error with a zero standard error, not an undefined one.
        assert_eq!(
            score_of(&IdentifyOptions::physical(8), &[0.0, 0.0]).standard_error_mm,
            0.0
        );
    }

    #[test]
    fn the_score_is_the_rmse_over_configurations_with_its_standard_error() {
        // Squared misses 1, 1, 4, 4 mm²: mean 2.5, sample variance 3, so SE(mean) = √(3/4)
        // and the RMSE's √2.5 carries SE(mean)/(2√2.5).
        let s = score_of(&IdentifyOptions::physical(12), &[1.0, 1.0, 4.0, 4.0]);
        assert_eq!(s.pitch_basis, 12);
        assert!((s.cross_validated_rmse_mm - 2.5_f64.sqrt()).abs() < 1e-15);
        let expected = (0.75_f64).sqrt() / (2.0 * 2.5_f64.sqrt());
        assert!((s.standard_error_mm - expected).abs() < 1e-15);
    }

    #[test]
    fn configurations_never_held_out_are_not_scored() {
        // Six configurations, the last two a leg's extremes (never held out): the two folds
        // miss the other four by 1 and 4 mm². The score is theirs alone.
        let folds = vec![Ok(vec![(0, 1.0), (2, 4.0)]), Ok(vec![(1, 1.0), (3, 4.0)])];
        let s = scored(&IdentifyOptions::physical(8), 6, folds).unwrap();
        assert_eq!(
            s,
            score_of(&IdentifyOptions::physical(8), &[1.0, 1.0, 4.0, 4.0])
        );
        assert!((s.cross_validated_rmse_mm - 2.5_f64.sqrt()).abs() < 1e-15);
    }

    /// Two folds of four configurations: resolution `basis` misses each by `miss` (mm² over
    /// the legs), or its second fold fails.
    fn folds_of(miss: Option<f64>) -> Vec<Result<Vec<(usize, f64)>>> {
        match miss {
            Some(m) => vec![Ok(vec![(0, m), (2, m)]), Ok(vec![(1, m), (3, m)])],
            None => vec![
                Ok(vec![(0, 1.0), (2, 1.0)]),
                Err(Error::SingularConfiguration {
                    configuration: "3".into(),
                }),
            ],
        }
    }

    #[test]
    fn the_choice_leaves_out_resolutions_that_failed_and_refuses_when_all_did() {
        // Eight fails; twelve and sixteen are scored in their own folds, twelve the coarser of
        // the two within reach.
        let missed = [folds_of(None), folds_of(Some(1.0)), folds_of(Some(1.0))].concat();
        let choice = choice_of(4, 2, missed).unwrap();
        assert_eq!(choice.options.pitch_basis, 12);
        assert_eq!(
            choice.options,
            IdentifyOptions {
                pitch_basis: 12,
                ..PHYSICAL
            }
        );
        assert_eq!(choice.scores.len(), 2);
        assert_eq!(choice.failed.len(), 1);
        assert!(matches!(choice.outcome(8), Some(Err(why)) if why.contains("fold 2")));
        assert!(matches!(choice.outcome(16), Some(Ok(s)) if s.cross_validated_rmse_mm == 1.0));
        assert!(choice.outcome(10).is_none());
        // Each resolution's folds are its own: sixteen far worse than twelve, twelve chosen.
        let choice = twelve_chosen();
        assert_eq!(choice.options.pitch_basis, 12);
        assert!(choice.failed.is_empty());
        let errors: Vec<f64> = choice
            .scores
            .iter()
            .map(|s| s.cross_validated_rmse_mm)
            .collect();
        assert_eq!(errors, [2.0, 1.0, 3.0]);
        // None scored: refused, each named.
        let missed = [folds_of(None), folds_of(None), folds_of(None)].concat();
        let e = choice_of(4, 2, missed).unwrap_err().to_string();
        for basis in ["8 coefficients", "12 coefficients", "16 coefficients"] {
            assert!(e.contains(basis), "{e}");
        }
    }

    /// The choice when eight, twelve and sixteen miss their two folds' configurations by 4, 1
    /// and 9 mm²: twelve.
    fn twelve_chosen() -> ResolutionChoice {
        let missed = [
            folds_of(Some(4.0)),
            folds_of(Some(1.0)),
            folds_of(Some(9.0)),
        ]
        .concat();
        choice_of(4, 2, missed).unwrap()
    }

    #[test]
    fn the_smoothness_prior_scoring_lowest_at_the_chosen_resolution_is_taken() {
        // Twelve chosen (misses of 1 mm² over its two folds); the three weights then miss by
        // `misses` in turn (`None`: a fold failed).
        let smoothed = |misses: [Option<f64>; 3]| {
            let choice = twelve_chosen();
            assert_eq!(choice.options.pitch_basis, 12);
            let missed = misses.into_iter().flat_map(folds_of).collect();
            choice.smoothed_by(4, 2, missed)
        };
        let middle = smoothed([Some(0.81), Some(0.64), Some(0.72)]);
        assert_eq!(middle.options, IdentifyOptions::physical(12).smoothed(0.01));
        assert_eq!(middle.chosen().cross_validated_rmse_mm, 0.8);
        assert_eq!(middle.chosen_without_prior().cross_validated_rmse_mm, 1.0);
        assert_eq!(middle.smoothed.len(), 3);
        assert!(middle.smoothed.iter().all(|s| s.pitch_basis == 12));
        assert!(
            matches!(middle.smoothing_outcome(0.03), Some(Ok(s)) if s.cross_validated_rmse_mm == 0.72_f64.sqrt())
        );
        assert!(matches!(middle.smoothing_outcome(0.0), Some(Ok(s)) if s.smoothness == 0.0));
        // None better than no prior: none taken.
        let none = smoothed([Some(1.21), Some(1.44), Some(4.0)]);
        assert_eq!(none.options, IdentifyOptions::physical(12));
        // A weight whose fold failed is left out and named; the best of the others taken.
        let failed = smoothed([None, Some(0.9), Some(0.64)]);
        assert_eq!(failed.options.smoothness, 0.03);
        assert_eq!(failed.smoothed.len(), 2);
        assert!(
            matches!(failed.smoothing_outcome(0.003), Some(Err(why)) if why.contains("fold 2"))
        );
        assert!(failed.smoothing_outcome(0.5).is_none());
    }
}
