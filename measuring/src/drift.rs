//! Drift during a campaign: the reference configuration measured again at the start, every few
//! configurations and at the end, compared with its baseline; what moved, by how much, and what
//! was decided. A warm-up gate measures it until two measurements in a row agree.
//!
//! Units: mm, in the record's frame (the instrument's, or the first registration's after a
//! re-registration).

use std::time::Duration;

use glam::DVec3;
use hexacomp_core::Geometry;
use hexacomp_core::observation::Observation;

/// How far the reference moved between two measurements of it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Deviation {
    /// The largest movement of a point (a target seen in both, or a target placed by a probe's
    /// pose), mm.
    pub largest_mm: f64,
    /// The mean movement of the points, mm.
    pub shift: DVec3,
    /// The largest distance of a point's movement from the mean movement, mm: small when
    /// everything moved together (the tracker or the whole machine moved), large when the
    /// points moved differently (a rotation, the machine's geometry changed).
    pub uneven_mm: f64,
}

/// The movement of the points of `now` from those of `before` (common targets only); `None`
/// when they share no point.
pub fn deviation(
    geometry: &Geometry,
    now: &Observation,
    before: &Observation,
) -> Option<Deviation> {
    let before_points = before.points(geometry);
    let moves: Vec<DVec3> = now
        .points(geometry)
        .iter()
        .filter_map(|(j, p)| {
            before_points
                .iter()
                .find(|(k, _)| k == j)
                .map(|(_, q)| *p - *q)
        })
        .collect();
    Deviation::of_moves(&moves)
}

impl Deviation {
    /// The deviation of points that moved by `moves` (mm); `None` without any.
    pub fn of_moves(moves: &[DVec3]) -> Option<Self> {
        if moves.is_empty() {
            return None;
        }
        let shift = moves.iter().copied().sum::<DVec3>() / moves.len() as f64;
        Some(Self {
            largest_mm: moves.iter().map(|m| m.length()).fold(0.0, f64::max),
            shift,
            uneven_mm: moves
                .iter()
                .map(|m| (*m - shift).length())
                .fold(0.0, f64::max),
        })
    }

    /// Whether the points moved together (the largest distance of a point's movement from the
    /// mean movement is at most 30 % of the largest movement).
    pub fn together(&self) -> bool {
        self.uneven_mm <= 0.3 * self.largest_mm
    }

    /// What the movement looks like and what to do about it, for the message that stops a
    /// campaign (`limit_mm`: the threshold it exceeded).
    pub fn explain(&self, limit_mm: f64) -> String {
        let shape = if self.together() {
            format!(
                "the targets moved together by ({:.4}, {:.4}, {:.4}) mm: the tracker or the whole \
                 machine moved (a bumped tracker, the floor, thermal growth of the base)",
                self.shift.x, self.shift.y, self.shift.z
            )
        } else {
            format!(
                "the targets moved differently (mean ({:.4}, {:.4}, {:.4}) mm, up to {:.4} mm \
                 apart from it): the machine's geometry changed (warm-up, a crash) or the tracker \
                 turned",
                self.shift.x, self.shift.y, self.shift.z, self.uneven_mm
            )
        };
        format!(
            "the reference configuration moved {:.4} mm since its baseline (limit {limit_mm} mm); \
             {shape}",
            self.largest_mm
        )
    }
}

/// Why the reference was measured.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReferenceEvent {
    /// Waiting for the machine and the instrument to settle before the first configuration.
    WarmUp,
    /// At the start of a run.
    Start,
    /// After every few configurations.
    Periodic,
    /// After the last configuration of a run.
    End,
}

impl ReferenceEvent {
    /// The name the drift log writes.
    pub fn name(self) -> &'static str {
        match self {
            ReferenceEvent::WarmUp => "warm-up",
            ReferenceEvent::Start => "start",
            ReferenceEvent::Periodic => "reference",
            ReferenceEvent::End => "end",
        }
    }
}

/// What was decided about a measurement of the reference.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Decision {
    /// The first measurement: what later ones are compared with.
    Baseline,
    /// Within the limit: the campaign goes on.
    Ok,
    /// Beyond the limit: the campaign stops.
    Stopped,
    /// Beyond the limit, accepted by the user (`--accept-drift`): the new baseline.
    Accepted,
    /// Warm-up: still changing.
    Warming,
    /// Warm-up: agrees with the measurement before it; the campaign starts.
    Stable,
}

impl Decision {
    /// The name the drift log writes.
    pub fn name(self) -> &'static str {
        match self {
            Decision::Baseline => "baseline",
            Decision::Ok => "ok",
            Decision::Stopped => "stopped",
            Decision::Accepted => "accepted",
            Decision::Warming => "warming",
            Decision::Stable => "stable",
        }
    }
}

/// The warm-up gate: the reference measured every `interval` until two measurements in a row
/// agree within `limit_mm`, at most `max_measurements` times.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WarmUp {
    /// Largest movement between two measurements in a row that counts as settled, mm.
    pub limit_mm: f64,
    /// Time between two measurements.
    pub interval: Duration,
    /// Measurements before the campaign gives up.
    pub max_measurements: usize,
}

/// How a campaign watches its reference configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct DriftCheck {
    /// The reference configuration's commanded pose, mm and degrees.
    pub pose_mm_deg: [f64; 6],
    /// Configurations between two measurements of the reference (besides the start and the end).
    pub every: usize,
    /// Largest movement from the baseline before the campaign stops, mm.
    pub limit_mm: f64,
    /// At this run's start, take a reference beyond the limit as the new baseline.
    pub accept: bool,
    /// The warm-up gate, if any.
    pub warm_up: Option<WarmUp>,
    /// The baseline of earlier runs (`None`: this run's first measurement becomes it).
    pub baseline: Option<Observation>,
    /// The number of this run's first measurement of the reference (`R1`, `R2`… in the log).
    pub first_number: usize,
    /// A note for the log's first row of this run (a re-registration, rows kept under an
    /// accepted drift), if any.
    pub note: Option<String>,
    /// The configurations recorded since the last good measurement of the reference (a run
    /// killed before its next one): named if this run's start finds drift.
    pub suspects: Vec<String>,
    /// The record holds rows measured after the last measurement of the reference (a run killed
    /// after its last row, before its end measurement): measure it even when nothing is left to
    /// measure.
    pub end_pending: bool,
    /// The rows a stop on drift found suspect are kept (`accept`): measure the start reference
    /// (and log the decision) even when nothing is left to measure.
    pub start_pending: bool,
}

/// One measurement of the reference, for the drift log.
#[derive(Debug, Clone, PartialEq)]
pub struct ReferenceMeasurement {
    /// `R<n>`.
    pub id: String,
    /// The commanded legs, mm.
    pub legs: [f64; 6],
    /// What was measured, in the record's frame.
    pub observed: Observation,
    /// Why it was measured.
    pub event: ReferenceEvent,
    /// The configurations the record held.
    pub configurations: usize,
    /// The movement from the baseline (or, in the warm-up, from the measurement before).
    pub deviation: Option<Deviation>,
    /// What was decided.
    pub decision: Decision,
    /// A note (a re-registration), or empty.
    pub note: String,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_shift_of_every_target_is_told_from_an_uneven_movement() {
        let g = Geometry::prototype();
        let points = |moves: [DVec3; 3]| {
            Observation::Targets(
                (0..3)
                    .map(|j| Some(DVec3::new(100.0 * j as f64, 50.0, 300.0) + moves[j]))
                    .collect(),
            )
        };
        let base = points([DVec3::ZERO; 3]);
        let shifted = points([DVec3::new(0.1, 0.0, 0.0); 3]);
        let d = deviation(&g, &shifted, &base).unwrap();
        assert!((d.largest_mm - 0.1).abs() < 1e-12 && d.uneven_mm < 1e-12);
        assert!(
            d.explain(0.05)
                .contains("moved together by (0.1000, 0.0000, 0.0000)")
        );
        let uneven = points([DVec3::ZERO, DVec3::ZERO, DVec3::new(0.0, 0.0, 0.09)]);
        let d = deviation(&g, &uneven, &base).unwrap();
        assert!((d.largest_mm - 0.09).abs() < 1e-12);
        assert!((d.uneven_mm - 0.06).abs() < 1e-12, "{d:?}");
        assert!(d.explain(0.05).contains("moved differently"));
        // Only the targets seen in both count.
        let one_missing =
            Observation::Targets(vec![None, Some(DVec3::new(100.0, 50.0, 300.1)), None]);
        let d = deviation(&g, &one_missing, &base).unwrap();
        assert!((d.largest_mm - 0.1).abs() < 1e-9);
        assert!(deviation(&g, &Observation::Targets(vec![None; 3]), &base).is_none());
    }
}
