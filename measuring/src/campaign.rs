//! A measuring campaign: the machine driven to every planned configuration, each measured with
//! several readings (outliers rejected, the mean and spread kept) and handed to the caller to
//! record before the next move, in a short tour; configurations already recorded are skipped,
//! so a campaign killed at any moment continues where it stopped.
//!
//! The machine and the instrument are traits: the virtual platform implements both here (its
//! noise keyed on the seed and the configuration's id, so a resumed campaign records exactly
//! what an uninterrupted one does); a user's program is an instrument
//! ([`crate::command_instrument`]).
//!
//! Units: mm and degrees in records; poses in the base frame, measurements in the instrument's.

use std::collections::HashSet;
use std::time::Duration;

use glam::DVec3;

use hexacomp_core::observation::Observation;
use hexacomp_core::pose::{rotation_from_vector, rotation_vector};
use hexacomp_core::records::{MeasuredConfiguration, NamedPose};
use hexacomp_core::{Geometry, LEGS, Pose, inverse_kinematics};

use crate::drift::{Decision, DriftCheck, ReferenceEvent, ReferenceMeasurement, deviation};
use crate::error::{Error, Result};
use hexacomp_calibration::plan::rows_holding_leg_extremes;

/// Where the machine went for a configuration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Arrival {
    /// The leg lengths the controller commands for the pose (its nominal inverse kinematics),
    /// mm: what a campaign records.
    pub legs: [f64; LEGS],
    /// What the drives are commanded, mm: the legs plus the corrections of the compensation
    /// active in the machine, if any.
    pub drives: [f64; LEGS],
    /// The pose really reached, when the machine knows it (the virtual one does).
    pub reached: Option<Pose>,
}

/// A machine a campaign drives.
pub trait Machine {
    /// Moves to `pose` (the configuration `id`), waits until in position and settled.
    fn go_to(&mut self, id: &str, pose: &Pose) -> Result<Arrival>;
}

/// Why a reading failed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ReadError {
    /// This reading failed (no answer in time, a line of the wrong width, a beam lost): retried,
    /// then the configuration is a gap.
    #[error("{0}")]
    Failed(String),
    /// The instrument cannot work at all (its program cannot be started): the campaign stops
    /// before recording anything for the configuration.
    #[error("{0}")]
    Broken(String),
}

/// An instrument a campaign reads.
pub trait Instrument {
    /// Reading number `reading` (0-based) of configuration `id`, commanded to `pose_mm_deg` (the
    /// plan's numbers, mm and degrees): the targets or the pose the instrument reports, in its
    /// frame.
    fn read(
        &mut self,
        id: &str,
        reading: usize,
        pose_mm_deg: &[f64; 6],
        arrival: &Arrival,
    ) -> std::result::Result<Observation, ReadError>;

    /// Reading number `reading` (0-based) of the fiducial `name`, a fixed point on the machine's
    /// base whose nominal position is `nominal_mm` (base frame, mm): where the instrument sees
    /// it, in its frame, mm. A probe's instrument measures it as a point too.
    fn read_fiducial(
        &mut self,
        name: &str,
        reading: usize,
        nominal_mm: DVec3,
    ) -> std::result::Result<DVec3, ReadError>;
}

/// How each configuration is measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CampaignOptions {
    /// Readings per configuration.
    pub readings: usize,
    /// Pause between two readings (a tracker needs about 2 s per point for its stated accuracy).
    pub dwell: Duration,
    /// Attempts at a reading that fails before the configuration is recorded as a gap.
    pub retries: usize,
    /// With at least [`MIN_READINGS_TO_REJECT`] readings, a reading farther from their median
    /// than this many times their median distance from it (and than 1 µm, or 1e-5 rad for a
    /// probe's rotation) is rejected as an outlier.
    pub outlier_factor: f64,
    /// The campaign stops after this many configurations in a row recorded as gaps (the
    /// instrument is not answering).
    pub max_consecutive_gaps: usize,
    /// Time to wait once the machine is in position, before the first reading (the structure
    /// and the drives settle).
    pub settle: Duration,
}

/// The largest difference between the drives' commands and the nominal legs a campaign accepts,
/// mm: more means a compensation is active, and the record would pair nominal legs with a
/// machine that moved elsewhere.
pub const COMPENSATION_OFF_MM: f64 = 1e-3;

/// The fewest readings outliers are rejected among: with fewer the median distance is too
/// unsteady (with three readings of pure Gaussian noise and a factor of 5, 3 % of points would
/// lose a good reading; with four, 0.5 %; two are always equally far from their median).
pub const MIN_READINGS_TO_REJECT: usize = 4;

impl Default for CampaignOptions {
    fn default() -> Self {
        Self {
            readings: 5,
            dwell: Duration::ZERO,
            retries: 2,
            outlier_factor: 5.0,
            max_consecutive_gaps: 3,
            settle: Duration::ZERO,
        }
    }
}

/// One configuration's readings combined.
#[derive(Debug, Clone, PartialEq)]
pub struct Combined {
    /// The mean of the readings kept (a target seen in fewer than half the readings is not
    /// seen).
    pub observed: Observation,
    /// Readings kept.
    pub kept: usize,
    /// Readings rejected as outliers.
    pub rejected: usize,
    /// RMS distance of the kept readings from their mean, worst target, mm.
    pub spread_mm: f64,
    /// Readings lost (every attempt at them failed), and the last failure's reason.
    pub lost: (usize, Option<String>),
    /// Whether each reading that succeeded (in the order taken) was kept (not an outlier).
    pub kept_readings: Vec<bool>,
    /// Every attempt at a reading, as the instrument answered it (its frame).
    pub attempts: Vec<Attempt>,
}

/// One attempt at a reading (of a configuration, or of a fiducial's point).
#[derive(Debug, Clone, PartialEq)]
pub struct Attempt<T = Observation> {
    /// The reading's number, from 1.
    pub reading: usize,
    /// The attempt's number for that reading, from 1.
    pub attempt: usize,
    /// What the instrument reported (its frame), or why it failed.
    pub outcome: std::result::Result<T, ReadError>,
}

/// The readings of one configuration (or of one fiducial's point).
#[derive(Debug, Clone, PartialEq)]
pub struct Readings<T = Observation> {
    /// The readings that succeeded, in the order taken.
    pub observations: Vec<T>,
    /// Every attempt.
    pub attempts: Vec<Attempt<T>>,
    /// Readings lost (every attempt failed).
    pub lost: usize,
    /// The last failure's reason, if any.
    pub failure: Option<String>,
}

impl<T> Default for Readings<T> {
    fn default() -> Self {
        Self {
            observations: Vec::new(),
            attempts: Vec::new(),
            lost: 0,
            failure: None,
        }
    }
}

/// The median of `values` (not empty).
fn median(values: &[f64]) -> f64 {
    hexacomp_calibration::screening::median(values).unwrap_or(f64::NAN)
}

/// Which of `points` are outliers: farther from their coordinate-wise median than
/// `outlier_factor` times their median distance from it and than `floor`; none with fewer than
/// [`MIN_READINGS_TO_REJECT`] points.
fn outliers(points: &[DVec3], outlier_factor: f64, floor: f64) -> Vec<bool> {
    if points.len() < MIN_READINGS_TO_REJECT {
        return vec![false; points.len()];
    }
    let centre = DVec3::new(
        median(&points.iter().map(|p| p.x).collect::<Vec<_>>()),
        median(&points.iter().map(|p| p.y).collect::<Vec<_>>()),
        median(&points.iter().map(|p| p.z).collect::<Vec<_>>()),
    );
    let distances: Vec<f64> = points.iter().map(|p| p.distance(centre)).collect();
    let limit = (outlier_factor * median(&distances)).max(floor);
    distances.iter().map(|d| *d > limit).collect()
}

/// The readings of one point combined (not empty): outliers rejected against the coordinate-wise median,
/// the mean of the rest, their RMS distance from it, and which readings were kept.
pub fn combine_points(points: &[DVec3], outlier_factor: f64) -> (DVec3, f64, Vec<bool>) {
    let kept: Vec<bool> = outliers(points, outlier_factor, 1e-3)
        .iter()
        .map(|o| !o)
        .collect();
    let chosen: Vec<DVec3> = points
        .iter()
        .zip(&kept)
        .filter(|(_, k)| **k)
        .map(|(p, _)| *p)
        .collect();
    let mean = chosen.iter().copied().sum::<DVec3>() / chosen.len() as f64;
    let spread =
        (chosen.iter().map(|p| p.distance_squared(mean)).sum::<f64>() / chosen.len() as f64).sqrt();
    (mean, spread, kept)
}

/// Combines a configuration's readings (all of one kind): per target, or for the pose's
/// position, outliers rejected and the rest averaged; a reading rejected for any point counts
/// as rejected.
pub fn combine(readings: &[Observation], outlier_factor: f64) -> Combined {
    let count = readings.len();
    let mut rejected_reading = vec![false; count];
    let (observed, spread_mm) = match readings.first() {
        Some(Observation::Targets(first)) => {
            combine_targets(readings, first.len(), outlier_factor, &mut rejected_reading)
        }
        Some(Observation::Pose(first)) => {
            combine_poses(readings, first, outlier_factor, &mut rejected_reading)
        }
        Some(Observation::PoseMissed) | None => (Observation::PoseMissed, 0.0),
    };
    let rejected = rejected_reading.iter().filter(|r| **r).count();
    Combined {
        observed,
        kept: count - rejected,
        rejected,
        spread_mm,
        lost: (0, None),
        kept_readings: rejected_reading.iter().map(|r| !r).collect(),
        attempts: Vec::new(),
    }
}

/// Each of `targets` targets combined over the readings that saw it (none where fewer than
/// half did), marking in `rejected_reading` every reading rejected for a point; and the largest
/// spread of a point, mm.
fn combine_targets(
    readings: &[Observation],
    targets: usize,
    outlier_factor: f64,
    rejected_reading: &mut [bool],
) -> (Observation, f64) {
    let mut spread_mm: f64 = 0.0;
    let targets = (0..targets)
        .map(|j| {
            let seen: Vec<(usize, DVec3)> = readings
                .iter()
                .enumerate()
                .filter_map(|(k, r)| match r {
                    Observation::Targets(t) => t.get(j).copied().flatten().map(|p| (k, p)),
                    _ => None,
                })
                .collect();
            if 2 * seen.len() < readings.len() || seen.is_empty() {
                return None;
            }
            let points: Vec<DVec3> = seen.iter().map(|(_, p)| *p).collect();
            let (mean, spread, kept) = combine_points(&points, outlier_factor);
            for ((k, _), keep) in seen.iter().zip(kept) {
                rejected_reading[*k] |= !keep;
            }
            spread_mm = spread_mm.max(spread);
            Some(mean)
        })
        .collect();
    (Observation::Targets(targets), spread_mm)
}

/// The poses of `readings` combined: positions and rotations judged for outliers apart (the
/// rotations as rotation vectors relative to `first`, averaged and judged without the ±180°
/// wrap of the angles), marking in `rejected_reading` every reading rejected; and the
/// positions' spread, mm.
fn combine_poses(
    readings: &[Observation],
    first: &[f64; 6],
    outlier_factor: f64,
    rejected_reading: &mut [bool],
) -> (Observation, f64) {
    let poses: Vec<(usize, Pose)> = readings
        .iter()
        .enumerate()
        .filter_map(|(k, r)| match r {
            Observation::Pose(values) => Some((k, Pose::from_mm_deg(*values))),
            _ => None,
        })
        .collect();
    let reference = Pose::from_mm_deg(*first).rotation();
    let turns: Vec<DVec3> = poses
        .iter()
        .map(|(_, p)| rotation_vector(&(p.rotation() * reference.transpose())))
        .collect();
    let positions: Vec<DVec3> = poses.iter().map(|(_, p)| p.position).collect();
    let (_, spread, kept_position) = combine_points(&positions, outlier_factor);
    let odd_turn = outliers(&turns, outlier_factor, 1e-5);
    let kept: Vec<bool> = kept_position
        .iter()
        .zip(&odd_turn)
        .map(|(k, odd)| *k && !odd)
        .collect();
    for ((k, _), keep) in poses.iter().zip(&kept) {
        rejected_reading[*k] |= !keep;
    }
    let count = kept.iter().filter(|k| **k).count() as f64;
    let mean_of = |values: &[DVec3]| {
        values
            .iter()
            .zip(&kept)
            .filter(|(_, k)| **k)
            .map(|(v, _)| *v)
            .sum::<DVec3>()
            / count
    };
    let rotation = rotation_from_vector(mean_of(&turns)) * reference;
    let mean = Pose::from_rotation(mean_of(&positions), &rotation).to_mm_deg();
    (Observation::Pose(mean), spread)
}

/// The order to visit `plan` in (the indices into `plan`; each once): first the configurations
/// holding a leg's shortest or longest length among the plan's, so that a campaign cut short
/// has still measured the legs' whole range; then the others. Each part is a nearest-neighbour
/// tour in leg space, from `start` and then from where the first ended, so that consecutive
/// moves are short.
pub fn tour(geometry: &Geometry, plan: &[NamedPose], start: &Pose) -> Vec<usize> {
    let legs: Vec<[f64; LEGS]> = plan
        .iter()
        .map(|row| inverse_kinematics(geometry, &row.pose()).lengths)
        .collect();
    let extreme = rows_holding_leg_extremes(&legs);
    let (extremes, others): (Vec<usize>, Vec<usize>) = (0..plan.len()).partition(|&k| extreme[k]);
    let mut at = inverse_kinematics(geometry, start).lengths;
    let mut order = Vec::with_capacity(plan.len());
    for mut left in [extremes, others] {
        while !left.is_empty() {
            let travel = |k: usize| {
                (0..LEGS)
                    .map(|i| (legs[k][i] - at[i]).abs())
                    .fold(0.0, f64::max)
            };
            let (slot, _) = left
                .iter()
                .enumerate()
                .min_by(|(_, a), (_, b)| travel(**a).total_cmp(&travel(**b)))
                .expect("not empty");
            let next = left.swap_remove(slot);
            at = legs[next];
            order.push(next);
        }
    }
    order
}

/// What a campaign did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CampaignSummary {
    /// Configurations measured in this run.
    pub measured: usize,
    /// Configurations recorded before this run (skipped).
    pub already: usize,
    /// Configurations recorded as gaps (every attempt at a reading failed), with the reason.
    pub gaps: Vec<(String, String)>,
}

/// A campaign over a plan: what to measure, in which order, what is already recorded.
#[derive(Debug, Clone)]
pub struct Campaign<'a> {
    /// The geometry (its targets compare measurements of the reference).
    pub geometry: &'a Geometry,
    /// The planned configurations.
    pub plan: &'a [NamedPose],
    /// The order to visit them in (indices into `plan`, each once; [`tour`]).
    pub order: &'a [usize],
    /// The ids already recorded: skipped.
    pub done: &'a HashSet<String>,
    /// What stands for nothing measured in the record (every target unseen, or no pose).
    pub nothing_seen: Observation,
    /// How each configuration is measured.
    pub options: CampaignOptions,
    /// Brings a combined reading into the record's frame: the poses applied in turn with
    /// [`Observation::in_frame`] (after a re-registration: the instrument's pose now, then the
    /// inverse of its pose when the record began); none when the instrument has not moved.
    pub into_record_frame: Vec<Pose>,
    /// The reference configuration watched for drift, if any.
    pub drift: Option<DriftCheck>,
}

/// A campaign's state while it runs: the reference's baseline and numbering, and what was
/// recorded since the last good measurement of it.
struct Watch {
    baseline: Option<Observation>,
    number: usize,
    recorded: usize,
    since_reference: Vec<String>,
    note: Option<String>,
}

impl Watch {
    /// The watch as a campaign starts: the drift check's baseline, numbering, suspects and
    /// note (none without a check), with `recorded` configurations already in the record.
    fn at_start(drift: Option<&DriftCheck>, recorded: usize) -> Self {
        Self {
            baseline: drift.and_then(|d| d.baseline.clone()),
            number: drift.map_or(1, |d| d.first_number),
            recorded,
            since_reference: drift.map(|d| d.suspects.clone()).unwrap_or_default(),
            note: drift.and_then(|d| d.note.clone()),
        }
    }
}

impl Campaign<'_> {
    /// Runs the campaign: each configuration not yet recorded is driven to, read
    /// `options.readings` times (each reading retried up to `options.retries` times), combined,
    /// brought into the record's frame and passed to `record` with its [`Combined`] figures
    /// before the next move; `progress()` is called after each. A configuration whose readings
    /// all fail is recorded as a gap (`nothing_seen`) and listed in the summary; after
    /// `options.max_consecutive_gaps` gaps in a row the campaign stops ([`Error::GapsInARow`]).
    /// An instrument that cannot work ([`ReadError::Broken`]), an error of the machine or of
    /// `record` stop it at once; what was recorded stays.
    ///
    /// With `drift`, the reference configuration is measured (each measurement passed to
    /// `log` before the campaign goes on): until it settles (the warm-up gate), at the start,
    /// after every `every` configurations and after the last; a movement from its baseline
    /// beyond the limit stops the campaign ([`Error::Drifted`], naming what moved and the
    /// configurations recorded since the last good measurement) unless accepted at the start.
    pub fn run(
        &self,
        machine: &mut dyn Machine,
        instrument: &mut dyn Instrument,
        record: &mut dyn FnMut(MeasuredConfiguration, &Combined) -> Result<()>,
        log: &mut dyn FnMut(&ReferenceMeasurement) -> Result<()>,
        progress: &mut dyn FnMut(),
    ) -> Result<CampaignSummary> {
        let options = &self.options;
        if options.readings == 0 {
            return Err(Error::OutOfRange {
                setting: "readings",
                value: 0.0,
                valid: "must be ≥ 1",
            });
        }
        let mut watch = Watch::at_start(self.drift.as_ref(), self.done.len());
        let left = self
            .order
            .iter()
            .filter(|&&k| !self.done.contains(&self.plan[k].id))
            .count();
        let start_pending = self.drift.as_ref().is_some_and(|d| d.start_pending);
        if left > 0 || start_pending {
            self.warm_up(machine, instrument, log, &mut watch)?;
            self.check_reference(ReferenceEvent::Start, machine, instrument, log, &mut watch)?;
        }
        let mut summary = CampaignSummary::default();
        let mut gaps_in_a_row = 0;
        for &index in self.order {
            let row = &self.plan[index];
            if self.done.contains(&row.id) {
                summary.already += 1;
                continue;
            }
            let gap = self.record_one(row, machine, instrument, record, &mut summary)?;
            gaps_in_a_row = if gap { gaps_in_a_row + 1 } else { 0 };
            watch.recorded += 1;
            watch.since_reference.push(row.id.clone());
            progress();
            if gaps_in_a_row >= options.max_consecutive_gaps {
                let (_, last_reason) = summary.gaps.last().cloned().unwrap_or_default();
                return Err(Error::GapsInARow {
                    count: gaps_in_a_row,
                    last_reason,
                });
            }
            let every = self.drift.as_ref().map_or(0, |d| d.every);
            let last = summary.measured == left;
            if every > 0 && watch.since_reference.len() >= every && !last {
                self.check_reference(
                    ReferenceEvent::Periodic,
                    machine,
                    instrument,
                    log,
                    &mut watch,
                )?;
            }
        }
        let end_pending = self.drift.as_ref().is_some_and(|d| d.end_pending);
        if summary.measured > 0 || end_pending {
            self.check_reference(ReferenceEvent::End, machine, instrument, log, &mut watch)?;
        }
        Ok(summary)
    }

    /// Measures the configuration `row` and passes it to `record` (every reading failed: as a
    /// gap, `nothing_seen`, listed in `summary` with the reason); whether it was a gap.
    fn record_one(
        &self,
        row: &NamedPose,
        machine: &mut dyn Machine,
        instrument: &mut dyn Instrument,
        record: &mut dyn FnMut(MeasuredConfiguration, &Combined) -> Result<()>,
        summary: &mut CampaignSummary,
    ) -> Result<bool> {
        let (arrival, mut combined) =
            self.measure(machine, instrument, &row.id, &row.pose_mm_deg)?;
        let gap = combined.kept == 0;
        if gap {
            let why = combined
                .lost
                .1
                .clone()
                .unwrap_or_else(|| "no reading".into());
            summary.gaps.push((row.id.clone(), why));
            combined.observed = self.nothing_seen.clone();
        }
        record(
            MeasuredConfiguration {
                id: row.id.clone(),
                pose_mm_deg: row.pose_mm_deg,
                legs: arrival.legs,
                observed: combined.observed.clone(),
            },
            &combined,
        )?;
        summary.measured += 1;
        Ok(gap)
    }

    /// Drives to `pose_mm_deg` (the configuration `id`), settles, reads and combines the
    /// readings in the record's frame; `kept` is 0 when every reading failed (`lost` says why).
    fn measure(
        &self,
        machine: &mut dyn Machine,
        instrument: &mut dyn Instrument,
        id: &str,
        pose_mm_deg: &[f64; 6],
    ) -> Result<(Arrival, Combined)> {
        let arrival = machine.go_to(id, &Pose::from_mm_deg(*pose_mm_deg))?;
        let compensated = (0..LEGS)
            .map(|i| (arrival.drives[i] - arrival.legs[i]).abs())
            .fold(0.0, f64::max);
        if compensated > COMPENSATION_OFF_MM {
            return Err(Error::CompensationActive {
                configuration: id.to_string(),
                offset_mm: compensated,
            });
        }
        if !self.options.settle.is_zero() {
            std::thread::sleep(self.options.settle);
        }
        let readings = read_configuration(instrument, &self.options, id, pose_mm_deg, &arrival)?;
        let mut combined = if readings.observations.is_empty() {
            Combined {
                observed: self.nothing_seen.clone(),
                kept: 0,
                rejected: 0,
                spread_mm: 0.0,
                lost: (0, None),
                kept_readings: Vec::new(),
                attempts: Vec::new(),
            }
        } else {
            combine(&readings.observations, self.options.outlier_factor)
        };
        combined.lost = (readings.lost, readings.failure);
        combined.attempts = readings.attempts;
        combined.observed = self
            .into_record_frame
            .iter()
            .fold(combined.observed, |o, frame| o.in_frame(frame));
        Ok((arrival, combined))
    }

    /// Measures the reference configuration as `R<n>` (a failure to measure it stops the
    /// campaign).
    fn measure_reference(
        &self,
        machine: &mut dyn Machine,
        instrument: &mut dyn Instrument,
        watch: &mut Watch,
    ) -> Result<(String, Arrival, Observation)> {
        let check = self.drift.as_ref().expect("a reference to measure");
        let id = format!("R{}", watch.number);
        watch.number += 1;
        let (arrival, combined) = self.measure(machine, instrument, &id, &check.pose_mm_deg)?;
        if combined.kept == 0 {
            return Err(Error::ReferenceUnmeasured {
                reference: id,
                reason: combined.lost.1.unwrap_or_else(|| "no reading".into()),
            });
        }
        Ok((id, arrival, combined.observed))
    }

    /// The warm-up gate: the reference measured every `interval` until two measurements in a
    /// row agree within the limit; an error after `max_measurements`.
    fn warm_up(
        &self,
        machine: &mut dyn Machine,
        instrument: &mut dyn Instrument,
        log: &mut dyn FnMut(&ReferenceMeasurement) -> Result<()>,
        watch: &mut Watch,
    ) -> Result<()> {
        let Some(gate) = self.drift.as_ref().and_then(|d| d.warm_up) else {
            return Ok(());
        };
        let mut previous: Option<Observation> = None;
        let mut last_change = None;
        for k in 0..gate.max_measurements {
            if k > 0 && !gate.interval.is_zero() {
                std::thread::sleep(gate.interval);
            }
            let (id, arrival, observed) = self.measure_reference(machine, instrument, watch)?;
            let change = previous
                .as_ref()
                .and_then(|p| deviation(self.geometry, &observed, p));
            let stable = change.is_some_and(|d| d.largest_mm <= gate.limit_mm);
            log(&ReferenceMeasurement {
                id,
                legs: arrival.legs,
                observed: observed.clone(),
                event: ReferenceEvent::WarmUp,
                configurations: watch.recorded,
                deviation: change,
                decision: if stable {
                    Decision::Stable
                } else {
                    Decision::Warming
                },
                note: watch.note.take().unwrap_or_default(),
            })?;
            if stable {
                return Ok(());
            }
            last_change = change;
            previous = Some(observed);
        }
        Err(Error::NotWarmedUp {
            measurements: gate.max_measurements,
            last_change_mm: last_change.map(|d| d.largest_mm),
            limit_mm: gate.limit_mm,
        })
    }

    /// Measures the reference and compares it with the baseline: the first becomes the
    /// baseline; beyond the limit the campaign stops, unless this is the start of a run whose
    /// user accepts the drift (the new baseline).
    fn check_reference(
        &self,
        event: ReferenceEvent,
        machine: &mut dyn Machine,
        instrument: &mut dyn Instrument,
        log: &mut dyn FnMut(&ReferenceMeasurement) -> Result<()>,
        watch: &mut Watch,
    ) -> Result<()> {
        let Some(check) = self.drift.as_ref() else {
            return Ok(());
        };
        let (id, arrival, observed) = self.measure_reference(machine, instrument, watch)?;
        let moved = watch
            .baseline
            .as_ref()
            .and_then(|b| deviation(self.geometry, &observed, b));
        let decision = match (&watch.baseline, moved) {
            (None, _) => Decision::Baseline,
            (Some(_), Some(d)) if d.largest_mm > check.limit_mm => {
                if event == ReferenceEvent::Start && check.accept {
                    Decision::Accepted
                } else {
                    Decision::Stopped
                }
            }
            (Some(_), Some(_)) => Decision::Ok,
            (Some(_), None) => Decision::Stopped,
        };
        let mut note = watch.note.take().unwrap_or_default();
        if decision == Decision::Accepted && !watch.since_reference.is_empty() {
            // Rows recorded before this drift was found (a run killed before its next
            // reference) are kept with it: said in the log.
            let kept = format!(
                "kept {} measured before this drift was found",
                watch.since_reference.join(", ")
            );
            note = if note.is_empty() {
                kept
            } else {
                format!("{note}; {kept}")
            };
        }
        log(&ReferenceMeasurement {
            id: id.clone(),
            legs: arrival.legs,
            observed: observed.clone(),
            event,
            configurations: watch.recorded,
            deviation: moved,
            decision,
            note,
        })?;
        if decision == Decision::Stopped {
            let what = moved.map_or_else(
                || "the reference shares no target with its baseline".to_string(),
                |d| d.explain(check.limit_mm),
            );
            return Err(Error::Drifted {
                reference: id,
                what,
                suspects: watch.since_reference.clone(),
            });
        }
        if matches!(decision, Decision::Baseline | Decision::Accepted) {
            watch.baseline = Some(observed);
        }
        watch.since_reference.clear();
        Ok(())
    }
}

/// The readings of configuration `id` (each reading retried up to `options.retries` times,
/// `options.dwell` apart): those that succeeded, every attempt, how many were lost and the last
/// failure's reason; an instrument that cannot work is an error.
pub fn read_configuration(
    instrument: &mut dyn Instrument,
    options: &CampaignOptions,
    id: &str,
    pose_mm_deg: &[f64; 6],
    arrival: &Arrival,
) -> Result<Readings> {
    read_repeatedly(options, &format!("configuration {id}"), |reading| {
        instrument.read(id, reading, pose_mm_deg, arrival)
    })
}

/// `options.readings` readings of `what` by `read` (given the reading's number from 0), each
/// retried up to `options.retries` times, `options.dwell` apart: those that succeeded, every
/// attempt, how many were lost and the last failure's reason; an instrument that cannot work
/// ([`ReadError::Broken`]) is an error.
pub fn read_repeatedly<T: Clone>(
    options: &CampaignOptions,
    what: &str,
    mut read: impl FnMut(usize) -> std::result::Result<T, ReadError>,
) -> Result<Readings<T>> {
    let mut readings = Readings::default();
    for reading in 0..options.readings {
        if reading > 0 && !options.dwell.is_zero() {
            std::thread::sleep(options.dwell);
        }
        let mut read_one = false;
        for attempt in 0..=options.retries {
            let outcome = match read(reading) {
                Ok(value) => {
                    readings.observations.push(value.clone());
                    read_one = true;
                    Ok(value)
                }
                Err(ReadError::Failed(why)) => {
                    readings.failure = Some(why.clone());
                    Err(ReadError::Failed(why))
                }
                Err(ReadError::Broken(why)) => {
                    return Err(Error::InstrumentBroken {
                        cause: why,
                        before: what.to_string(),
                    });
                }
            };
            readings.attempts.push(Attempt {
                reading: reading + 1,
                attempt: attempt + 1,
                outcome,
            });
            if read_one {
                break;
            }
        }
        readings.lost += usize::from(!read_one);
    }
    Ok(readings)
}

/// Targets measured in the base frame as an instrument reports them: in its frame
/// (`into_instrument`: the base frame's pose in the instrument's), and as a 6-DoF probe's pose
/// fitted to them when `probe`.
pub fn as_instrument_reports(
    geometry: &Geometry,
    observed: &Observation,
    into_instrument: &Pose,
    probe: bool,
) -> Result<Observation> {
    let observed = if probe {
        Observation::Pose(observed.fitted_pose(geometry)?.to_mm_deg())
    } else {
        observed.clone()
    };
    Ok(observed.in_frame(into_instrument))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn targets(points: &[Option<DVec3>]) -> Observation {
        Observation::Targets(points.to_vec())
    }

    #[test]
    fn an_outlier_is_rejected_and_the_rest_averaged() {
        let p = |x: f64| Some(DVec3::new(x, 0.0, 100.0));
        let readings = [
            targets(&[p(1.000), p(5.0)]),
            targets(&[p(1.002), p(5.0)]),
            targets(&[p(0.998), p(5.0)]),
            targets(&[p(1.250), p(5.0)]), // knocked during the reading
            targets(&[p(1.000), None]),
        ];
        let combined = combine(&readings, 5.0);
        assert_eq!((combined.kept, combined.rejected), (4, 1));
        let Observation::Targets(mean) = &combined.observed else {
            panic!("targets")
        };
        assert!((mean[0].unwrap().x - 1.0).abs() < 1e-12);
        // Seen in four readings of five: seen, averaged over those.
        assert_eq!(mean[1], p(5.0));
        assert!((combined.spread_mm - (0.000002_f64).sqrt()).abs() < 1e-9);
        // Seen in two readings of five: not seen.
        let rare = [
            targets(&[p(1.0)]),
            targets(&[p(1.0)]),
            targets(&[None]),
            targets(&[None]),
            targets(&[None]),
        ];
        assert_eq!(combine(&rare, 5.0).observed, targets(&[None]));
    }

    #[test]
    fn probe_poses_across_180_degrees_average_to_180_not_0_and_odd_turns_are_rejected() {
        let pose = |c: f64, x: f64| Observation::Pose([x, 0.0, 300.0, 0.0, 0.0, c]);
        let readings = [
            pose(179.99, 1.0),
            pose(-179.99, 1.0),
            pose(179.995, 1.0),
            pose(-179.995, 1.0),
            pose(170.0, 1.0), // the probe's orientation read wrong
        ];
        let combined = combine(&readings, 5.0);
        assert_eq!((combined.kept, combined.rejected), (4, 1));
        let Observation::Pose(mean) = combined.observed else {
            panic!("a pose")
        };
        assert!((mean[5].abs() - 180.0).abs() < 1e-9, "{mean:?}");
        assert!((mean[0] - 1.0).abs() < 1e-12);
        // Fewer than four readings: nothing is rejected.
        assert_eq!(combine(&readings[2..], 5.0).rejected, 0);
    }

    #[test]
    fn the_tour_visits_the_legs_extremes_first_and_every_configuration_once_in_less_travel() {
        let g = Geometry::prototype();
        let plan = hexacomp_calibration::plan::numbered_rows(
            &hexacomp_calibration::plan::plan(
                &g,
                &hexacomp_calibration::plan::PlanOptions {
                    count: 60,
                    seed: 3,
                    ..Default::default()
                },
            )
            .unwrap(),
        );
        let order = tour(&g, &plan, &g.home_pose());
        let mut sorted = order.clone();
        sorted.sort_unstable();
        assert_eq!(sorted, (0..60).collect::<Vec<_>>());
        let travel = |order: &[usize]| -> f64 {
            order
                .windows(2)
                .map(|w| {
                    let a = inverse_kinematics(&g, &plan[w[0]].pose()).lengths;
                    let b = inverse_kinematics(&g, &plan[w[1]].pose()).lengths;
                    (0..LEGS).map(|i| (a[i] - b[i]).abs()).fold(0.0, f64::max)
                })
                .sum()
        };
        let planned: Vec<usize> = (0..60).collect();
        assert!(
            travel(&order) < 0.6 * travel(&planned),
            "{} vs {}",
            travel(&order),
            travel(&planned)
        );
        // The legs' extremes first: the first configurations measured span every leg's range
        // over the plan, so a campaign cut short has measured it.
        let legs: Vec<[f64; LEGS]> = plan
            .iter()
            .map(|row| inverse_kinematics(&g, &row.pose()).lengths)
            .collect();
        let range = |rows: &[usize], leg: usize| {
            let of_rows: Vec<[f64; LEGS]> = rows.iter().map(|&k| legs[k]).collect();
            hexacomp_calibration::train::leg_range(&of_rows, leg)
        };
        let spanning = (1..=60)
            .find(|&n| (0..LEGS).all(|i| range(&order[..n], i) == range(&planned, i)))
            .expect("the whole tour spans the plan");
        assert!(
            spanning <= hexacomp_calibration::plan::EXTREMES,
            "the legs' range spanned after {spanning} configurations"
        );
    }
}
