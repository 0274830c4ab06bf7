//! Gross-error screening: which configurations are left out of training, why, and when a whole
//! input is refused.
//!
//! A check that finds a problem decides: the configuration is excluded (and listed with its
//! reason), or, when so much is excluded that the data as a whole must be wrong (a swapped
//! column, another machine's geometry, inches), the input is refused. The checks:
//!
//! - **Unsolvable, not converged, legs against the pose, correction bound** — per configuration
//!   ([`crate::corrections::Flag`]).
//! - **Fit residual.** Three targets give nine equations for the six leg corrections; what the
//!   corrections cannot explain is left in the residual `‖ζ‖`. Measurement noise of σ per
//!   coordinate leaves `‖ζ‖` distributed as σ·χ₃ (median 1.54σ, 1 − 10⁻⁴ quantile 4.6σ), so a
//!   residual above [`ScreeningOptions::residual_factor`] × the file's median residual (3 would be
//!   the 10⁻⁴ quantile of pure noise) is a gross error in a coordinate.
//! - **Consistency with the other configurations.** A typo along a direction the fit absorbs (a
//!   target's coordinate normal to the target plane is, to first order, a tilt of the platform)
//!   leaves a small residual but a correction unlike the others'. The one geometry that explains
//!   all configurations best is identified (the model-based baseline, [`crate::identify`]: 42
//!   joint and leg-zero parameters, least squares over all rows), and a configuration whose
//!   measured targets are further from that geometry's prediction than
//!   [`ScreeningOptions::identification_factor`] × the median distance (and
//!   [`ScreeningOptions::identification_floor_mm`]) is a gross error. The geometry is shared by
//!   all rows, so one row cannot pull it onto itself (its influence is about 1/rows), and the
//!   exact kinematics follow the corrections into every corner of the workspace, where a smooth
//!   fit over leg space did not (a quadratic fit flagged up to 4 clean rows of 110).
//!
//! Units: mm.

use hexacomp_core::Geometry;
use hexacomp_core::records::{JointCorrection, MeasuredConfiguration};

use crate::corrections::{Checks, Flag, Outcome};
use crate::error::{Error, Result};
use crate::identify::{IdentifyOptions, identify, target_distance};

/// Thresholds of the population checks and of the refusal.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScreeningOptions {
    /// Exclude a configuration whose fit residual `‖ζ‖` exceeds this many times the median
    /// residual of the file (dimensionless).
    pub residual_factor: f64,
    /// ... and exceeds this, mm: the residual limit never goes below it (noise-free data).
    pub residual_floor_mm: f64,
    /// Exclude a configuration whose measured targets are further from the identified
    /// geometry's prediction than this many times the median distance (dimensionless).
    pub identification_factor: f64,
    /// ... and further than this, mm.
    pub identification_floor_mm: f64,
    /// Refuse the whole input when more than this share of its configurations is excluded
    /// (0–1).
    pub max_excluded_share: f64,
}

impl Default for ScreeningOptions {
    fn default() -> Self {
        Self {
            residual_factor: 4.0,
            residual_floor_mm: 0.01,
            identification_factor: 3.0,
            identification_floor_mm: 0.05,
            max_excluded_share: 0.2,
        }
    }
}

impl ScreeningOptions {
    /// No population check and no refusal: only what cannot be trained on (unsolvable, not
    /// converged, legs against the pose) is excluded. For method comparisons that must train on
    /// everything a method produced, as the paper's ordinary compensator did.
    pub fn keep_all() -> Self {
        Self {
            residual_factor: f64::INFINITY,
            identification_factor: f64::INFINITY,
            max_excluded_share: 1.0,
            ..Self::default()
        }
    }

    /// Checks that every setting is usable (the factors may be infinite: check off).
    pub fn validate(&self) -> Result<()> {
        let positive = [
            ("residual-factor", self.residual_factor),
            ("residual-floor", self.residual_floor_mm),
            ("identification-factor", self.identification_factor),
            ("identification-floor", self.identification_floor_mm),
        ];
        for (name, value) in positive {
            if value.is_nan() || value <= 0.0 {
                return Err(Error::OutOfRange {
                    setting: name,
                    value,
                    valid: "must be a number > 0",
                });
            }
        }
        if !(0.0..=1.0).contains(&self.max_excluded_share) {
            return Err(Error::OutOfRange {
                setting: "max-excluded-share",
                value: self.max_excluded_share,
                valid: "must be between 0 and 1",
            });
        }
        Ok(())
    }
}

/// Why a configuration was excluded.
#[derive(Debug, Clone, PartialEq)]
pub enum Reason {
    /// What was measured does not determine the platform's pose (too few targets seen): the
    /// configuration cannot be used, but it is no gross error and does not count towards a
    /// refusal.
    Unmeasured(String),
    /// The joint-correction iteration failed (the message says why).
    Unsolvable(String),
    /// A per-configuration check of the solve failed.
    Flagged(Flag),
    /// The fit residual is a gross error.
    Residual {
        /// The residual `‖ζ‖`, mm.
        residual_mm: f64,
        /// The limit it exceeds, mm.
        limit_mm: f64,
    },
    /// The measurement is unlike the others': far from the geometry identified from the rows.
    Inconsistent {
        /// The distance of the measured targets from the identified geometry's, mm.
        deviation_mm: f64,
        /// The limit it exceeds, mm.
        limit_mm: f64,
    },
}

impl std::fmt::Display for Reason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Reason::Unmeasured(why) => write!(f, "cannot be used: {why}"),
            Reason::Unsolvable(why) => write!(f, "cannot be solved: {why}"),
            Reason::Flagged(flag) => write!(f, "{flag}"),
            Reason::Residual {
                residual_mm,
                limit_mm,
            } => write!(
                f,
                "fit residual {residual_mm:.4} mm above the limit {limit_mm:.4} mm (a wrong \
                 coordinate or a swapped target?)"
            ),
            Reason::Inconsistent {
                deviation_mm,
                limit_mm,
            } => write!(
                f,
                "the targets are {deviation_mm:.4} mm from where the geometry identified from \
                 the configurations puts them (limit {limit_mm:.4} mm; a wrong coordinate?)"
            ),
        }
    }
}

impl Reason {
    /// A short name of the kind of reason, for counts.
    pub fn kind(&self) -> &'static str {
        match self {
            Reason::Unmeasured(_) => "targets seen do not fix the pose",
            Reason::Unsolvable(_) => "cannot be solved",
            Reason::Flagged(Flag::NotConverged) => "did not converge",
            Reason::Flagged(Flag::LargeCorrection { .. }) => "correction above the bound",
            Reason::Flagged(Flag::LegsDisagreeWithPose { .. }) => "legs disagree with the pose",
            Reason::Residual { .. } => "fit residual",
            Reason::Inconsistent { .. } => "unlike the others",
        }
    }
}

/// The decision about every configuration of an input.
#[derive(Debug, Clone, PartialEq)]
pub struct Screening {
    /// The reasons for each configuration, in input order; empty for a kept one.
    pub reasons: Vec<Vec<Reason>>,
    /// The residual limit applied, mm (`None` for a corrections input, which has no residuals).
    pub residual_limit_mm: Option<f64>,
    /// What the user should know about the checks themselves (one left out, and why).
    pub notes: Vec<String>,
}

impl Screening {
    /// Whether configuration `index` is kept.
    pub fn kept(&self, index: usize) -> bool {
        self.reasons[index].is_empty()
    }

    /// The number of excluded configurations.
    pub fn excluded(&self) -> usize {
        self.reasons.iter().filter(|r| !r.is_empty()).count()
    }

    /// The number of configurations excluded as gross errors: excluded for a reason other than
    /// too few targets seen.
    pub fn gross_errors(&self) -> usize {
        self.reasons
            .iter()
            .filter(|r| {
                r.iter()
                    .any(|reason| !matches!(reason, Reason::Unmeasured(_)))
            })
            .count()
    }
}

/// Screens the solved configurations of a measurements file (`outcomes[k]` solved from
/// `measurements[k]` on `geometry`): per-configuration flags, the fit residual and consistency
/// with the other configurations. Refuses ([`Error::Refused`]) when more than
/// [`ScreeningOptions::max_excluded_share`] is excluded.
pub fn screen_measured(
    geometry: &Geometry,
    measurements: &[MeasuredConfiguration],
    outcomes: &[Outcome],
    options: &ScreeningOptions,
) -> Result<Screening> {
    options.validate()?;
    let mut reasons: Vec<Vec<Reason>> = outcomes
        .iter()
        .zip(measurements)
        .map(
            |(o, row)| match (&o.solution, row.observed.undetermined(geometry)) {
                (Err(_), Some(why)) => vec![Reason::Unmeasured(why)],
                (Err(why), None) => vec![Reason::Unsolvable(why.to_string())],
                (Ok(_), _) => o.flags.iter().cloned().map(Reason::Flagged).collect(),
            },
        )
        .collect();
    let residuals: Vec<f64> = outcomes
        .iter()
        .filter_map(|o| o.solution.as_ref().ok().map(|s| s.residual_mm))
        .collect();
    let residual_limit_mm = median(&residuals)
        .map(|median| (options.residual_factor * median).max(options.residual_floor_mm));
    if let Some(limit_mm) = residual_limit_mm {
        for (outcome, reasons) in outcomes.iter().zip(&mut reasons) {
            if let Ok(s) = &outcome.solution
                && s.residual_mm > limit_mm
            {
                reasons.push(Reason::Residual {
                    residual_mm: s.residual_mm,
                    limit_mm,
                });
            }
        }
    }
    let mut notes = Vec::new();
    if options.identification_factor.is_finite()
        && let Err(why) =
            check_against_identification(geometry, measurements, &mut reasons, options)
    {
        let why = match why {
            Error::TooFewConfigurations { needed, got, .. } => {
                format!("{got} configurations, it needs {needed}")
            }
            other => other.to_string(),
        };
        notes.push(format!(
            "the consistency check (against the identified geometry) was left out: {why}"
        ));
    }
    decide(
        Screening {
            reasons,
            residual_limit_mm,
            notes,
        },
        options,
    )
}

/// Screens the rows of a corrections file, which has no target points: the correction bound
/// `max_correction_mm` only. Refuses as [`screen_measured`] does.
pub fn screen_corrections(
    rows: &[JointCorrection],
    max_correction_mm: f64,
    options: &ScreeningOptions,
) -> Result<Screening> {
    options.validate()?;
    Checks {
        max_correction_mm,
        ..Checks::default()
    }
    .validate()?;
    let reasons: Vec<Vec<Reason>> = rows
        .iter()
        .map(|row| {
            let largest = row.corrections.iter().fold(0.0_f64, |m, d| m.max(d.abs()));
            if largest > max_correction_mm {
                vec![Reason::Flagged(Flag::LargeCorrection { max_mm: largest })]
            } else {
                Vec::new()
            }
        })
        .collect();
    decide(
        Screening {
            reasons,
            residual_limit_mm: None,
            notes: Vec::new(),
        },
        options,
    )
}

/// An input is refused only when more than this many configurations are excluded, whatever
/// their share.
pub const MIN_EXCLUDED_TO_REFUSE: usize = 2;

/// Refuses when too much is excluded; otherwise passes the screening on.
fn decide(screening: Screening, options: &ScreeningOptions) -> Result<Screening> {
    // Configurations with too few targets seen say nothing about the data's quality.
    let total = screening.reasons.len() - (screening.excluded() - screening.gross_errors());
    let excluded = screening.gross_errors();
    // A share of a tiny file is not evidence: one bad row of four is a bad row.
    if total == 0
        || excluded <= MIN_EXCLUDED_TO_REFUSE
        || (excluded as f64) <= options.max_excluded_share * total as f64
    {
        return Ok(screening);
    }
    let mut kinds: Vec<(&'static str, usize)> = Vec::new();
    let gross = screening
        .reasons
        .iter()
        .flatten()
        .filter(|reason| !matches!(reason, Reason::Unmeasured(_)));
    for reason in gross {
        match kinds.iter_mut().find(|(kind, _)| *kind == reason.kind()) {
            Some((_, count)) => *count += 1,
            None => kinds.push((reason.kind(), 1)),
        }
    }
    kinds.sort_by_key(|(_, count)| std::cmp::Reverse(*count));
    let counts: Vec<String> = kinds
        .iter()
        .map(|(kind, count)| format!("{kind}: {count}"))
        .collect();
    let reason = format!(
        "{excluded} of {total} configurations would be excluded as gross errors (more than {:.0} \
         %; {}): the data as a whole must be wrong — a swapped or misnamed column, another \
         machine's geometry file, inches instead of mm, targets measured in an instrument's own \
         frame (register it and give --registration)",
        100.0 * options.max_excluded_share,
        counts.join(", ")
    );
    Err(Error::Refused {
        reason,
        screening: Box::new(screening),
    })
}

/// Adds [`Reason::Inconsistent`] to every configuration (among those with no reason yet) whose
/// measured targets are far from where the geometry identified from the configurations within
/// the limit puts them.
///
/// A wrong row pulls the first identification towards itself, which can push clean rows over a
/// tight limit (on noise-free data); so the identification is repeated on the rows within the
/// limit, and every row judged again against it, until that set stops changing (at most
/// [`IDENTIFICATION_PASSES`] times; a later pass that cannot be made keeps the last decision).
/// A configuration the identified geometry cannot reach at all is excluded too. The check is
/// left out — and the returned error says why — when there are too few configurations
/// ([`MIN_ROWS_FOR_IDENTIFICATION`]) or the first identification fails.
fn check_against_identification(
    geometry: &Geometry,
    measurements: &[MeasuredConfiguration],
    reasons: &mut [Vec<Reason>],
    options: &ScreeningOptions,
) -> Result<()> {
    let indices: Vec<usize> = (0..measurements.len())
        .filter(|&i| reasons[i].is_empty())
        .collect();
    let candidates: Vec<MeasuredConfiguration> =
        indices.iter().map(|&i| measurements[i].clone()).collect();
    let mut within = vec![true; candidates.len()];
    let mut judged: Option<(Vec<f64>, f64)> = None;
    for _ in 0..IDENTIFICATION_PASSES {
        let fitted: Vec<MeasuredConfiguration> = candidates
            .iter()
            .zip(&within)
            .filter(|(_, w)| **w)
            .map(|(row, _)| row.clone())
            .collect();
        if fitted.len() < MIN_ROWS_FOR_IDENTIFICATION {
            if judged.is_none() {
                return Err(Error::TooFewConfigurations {
                    task: "the consistency check",
                    needed: MIN_ROWS_FOR_IDENTIFICATION,
                    got: fitted.len(),
                });
            }
            break;
        }
        let identified = match identify(geometry, &fitted, &IdentifyOptions::default()) {
            Ok(identified) => identified,
            Err(e) if judged.is_none() => return Err(e),
            Err(_) => break,
        };
        // Unreachable by the identified geometry: as far as can be.
        let distances: Vec<f64> = candidates
            .iter()
            .map(|row| target_distance(&identified.geometry, row).unwrap_or(f64::INFINITY))
            .collect();
        let fitted_distances: Vec<f64> = distances
            .iter()
            .zip(&within)
            .filter(|(_, w)| **w)
            .map(|(d, _)| *d)
            .collect();
        let median = median(&fitted_distances).unwrap_or(0.0);
        let limit_mm =
            (options.identification_factor * median).max(options.identification_floor_mm);
        // An unreachable row (infinite distance) is never within, even under an infinite limit.
        let next: Vec<bool> = distances
            .iter()
            .map(|d| d.is_finite() && *d <= limit_mm)
            .collect();
        let settled = next == within;
        within = next;
        judged = Some((distances, limit_mm));
        if settled {
            break;
        }
    }
    let (distances, limit_mm) = judged.expect("the first pass judged or returned");
    for ((&index, &deviation_mm), ok) in indices.iter().zip(&distances).zip(&within) {
        if !ok {
            reasons[index].push(Reason::Inconsistent {
                deviation_mm,
                limit_mm,
            });
        }
    }
    Ok(())
}

/// How many times the consistency check identifies the geometry at most.
const IDENTIFICATION_PASSES: usize = 4;

/// The consistency check identifies 42 parameters from 9 equations per configuration: it needs
/// at least this many configurations (4 equations per parameter); below it, it is off.
pub const MIN_ROWS_FOR_IDENTIFICATION: usize = 20;

/// The median of `values` (`None` when empty).
pub fn median(values: &[f64]) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    let middle = sorted.len() / 2;
    Some(if sorted.len().is_multiple_of(2) {
        0.5 * (sorted[middle - 1] + sorted[middle])
    } else {
        sorted[middle]
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use hexacomp_core::LEGS;

    fn corrections(wrong: &[usize]) -> Vec<JointCorrection> {
        (0..4)
            .map(|i| JointCorrection {
                id: (i + 1).to_string(),
                legs: [350.0; LEGS],
                corrections: if wrong.contains(&i) {
                    [9.0; LEGS]
                } else {
                    [0.1; LEGS]
                },
            })
            .collect()
    }

    #[test]
    fn one_bad_row_of_four_is_excluded_and_three_refuse_the_file() {
        let options = ScreeningOptions::default();
        let screening = screen_corrections(&corrections(&[2]), 5.0, &options).unwrap();
        assert_eq!(screening.excluded(), 1);
        assert!(!screening.kept(2));
        match screen_corrections(&corrections(&[0, 1, 2]), 5.0, &options) {
            Err(Error::Refused { screening, .. }) => assert_eq!(screening.excluded(), 3),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn unusable_thresholds_are_refused() {
        let rows = corrections(&[]);
        assert!(screen_corrections(&rows, f64::NAN, &ScreeningOptions::default()).is_err());
        let nan_factor = ScreeningOptions {
            residual_factor: f64::NAN,
            ..ScreeningOptions::default()
        };
        assert!(screen_corrections(&rows, 5.0, &nan_factor).is_err());
        assert!(screen_corrections(&rows, f64::INFINITY, &ScreeningOptions::keep_all()).is_ok());
    }
}
