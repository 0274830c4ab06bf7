//! The drift check a user runs monthly or after a crash: the poses an ISO 9283 test verified
//! after the calibration (`verify`), each measured once more with the compensation active,
//! their errors compared with what that test proved.
//!
//! The promise: at a verified pose the barycentre lies within AP_P of the commanded position and
//! an attained position within RP_l of the barycentre, so one attained position lies within
//! `AP_P + RP_l` of the commanded one; an angle within `|AP_a| + RP_a` of the commanded angle
//! (and so for b and c). The worst of each over the verified poses is allowed at every one of
//! them. Units: mm and degrees, base frame.

use glam::DVec3;

use crate::pose_test::{TestPose, angle_difference};
use crate::verify::{Attained, Missed};
use crate::verify_report::VerifyReport;

/// The poses `report` verified, in its order.
pub fn verified_poses(report: &VerifyReport) -> Vec<TestPose> {
    report
        .poses
        .iter()
        .map(|p| TestPose {
            name: p.name.clone(),
            commanded: p.commanded,
        })
        .collect()
}

/// The largest errors of one attained pose a verified calibration allows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Allowed {
    /// Position error, mm.
    pub position_mm: f64,
    /// Errors of the angles `a, b, c`, degrees.
    pub angles_deg: [f64; 3],
}

/// What `report` promises (the worst AP_P + the worst RP_l, the worst |AP_a| + the worst RP_a,
/// …), times `tolerance`.
pub fn promised(report: &VerifyReport, tolerance: f64) -> Allowed {
    let worst = |value: fn(&crate::pose_test::PoseCharacteristics) -> f64| {
        report
            .poses
            .iter()
            .map(|p| value(&p.figures).abs())
            .fold(0.0, f64::max)
    };
    Allowed {
        position_mm: tolerance * (report.worst_ap_p_mm() + report.worst_rp_l_mm()),
        angles_deg: [
            tolerance * (worst(|f| f.ap_a_deg) + worst(|f| f.rp_a_deg)),
            tolerance * (worst(|f| f.ap_b_deg) + worst(|f| f.rp_b_deg)),
            tolerance * (worst(|f| f.ap_c_deg) + worst(|f| f.rp_c_deg)),
        ],
    }
}

/// One attained pose's errors.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseError {
    /// The pose's name.
    pub name: String,
    /// `|attained − commanded|` of the position, mm.
    pub position_mm: f64,
    /// `attained − commanded` of the angles `a, b, c`, degrees (wrapped into (−180°, 180°]).
    pub angles_deg: [f64; 3],
}

/// What a check found.
#[derive(Debug, Clone, PartialEq)]
pub struct CheckResult {
    /// Each measured pose's errors, in the order measured.
    pub errors: Vec<PoseError>,
    /// The poses not measured, with why.
    pub missed: Vec<(String, String)>,
    /// What is allowed.
    pub allowed: Allowed,
}

/// The answer of a check.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// Every pose measured and within what is allowed.
    StillGood,
    /// A pose beyond what is allowed.
    Retrain,
    /// Some pose was not measured: no answer.
    Inconclusive,
}

impl CheckResult {
    /// The errors of `attained` at `poses` against `allowed`; `missed`: the poses not measured.
    pub fn new(
        poses: &[TestPose],
        attained: &[Attained],
        missed: &[Missed],
        allowed: Allowed,
    ) -> Self {
        let errors = attained
            .iter()
            .filter_map(|a| {
                let pose = poses.iter().find(|p| p.name == a.pose)?;
                let at = DVec3::from_slice(&a.pose_mm_deg[..3]);
                let commanded = DVec3::from_slice(&pose.commanded[..3]);
                Some(PoseError {
                    name: a.pose.clone(),
                    position_mm: at.distance(commanded),
                    angles_deg: std::array::from_fn(|k| {
                        angle_difference(a.pose_mm_deg[3 + k], pose.commanded[3 + k])
                    }),
                })
            })
            .collect();
        Self {
            errors,
            missed: missed
                .iter()
                .map(|m| (m.pose.clone(), m.why.clone()))
                .collect(),
            allowed,
        }
    }

    /// The largest position error and its pose, if any pose was measured.
    pub fn worst_position(&self) -> Option<(&str, f64)> {
        self.errors
            .iter()
            .map(|e| (e.name.as_str(), e.position_mm))
            .max_by(|a, b| a.1.total_cmp(&b.1))
    }

    /// The largest angle error as a share of what is allowed, its pose and axis (`a`, `b`, `c`).
    pub fn worst_angle_share(&self) -> Option<(&str, char, f64)> {
        self.errors
            .iter()
            .flat_map(|e| {
                (0..3).map(move |k| {
                    let allowed = self.allowed.angles_deg[k];
                    let share = if allowed > 0.0 {
                        e.angles_deg[k].abs() / allowed
                    } else if e.angles_deg[k] == 0.0 {
                        0.0
                    } else {
                        f64::INFINITY
                    };
                    (e.name.as_str(), ['a', 'b', 'c'][k], share)
                })
            })
            .max_by(|a, b| a.2.total_cmp(&b.2))
    }

    /// The mean position error, mm (0 when nothing was measured).
    pub fn mean_position_mm(&self) -> f64 {
        if self.errors.is_empty() {
            return 0.0;
        }
        self.errors.iter().map(|e| e.position_mm).sum::<f64>() / self.errors.len() as f64
    }

    /// The answer: retrain when a measured pose is beyond what is allowed (whatever was not
    /// measured); otherwise inconclusive when a pose was not measured, still good when all were.
    pub fn verdict(&self) -> Verdict {
        let positions = self
            .worst_position()
            .is_none_or(|(_, e)| e <= self.allowed.position_mm);
        let angles = self.worst_angle_share().is_none_or(|(_, _, s)| s <= 1.0);
        if !(positions && angles) {
            Verdict::Retrain
        } else if !self.missed.is_empty() || self.errors.is_empty() {
            Verdict::Inconclusive
        } else {
            Verdict::StillGood
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_verdict_weighs_positions_and_angles_against_the_promise_and_wants_every_pose() {
        let poses = vec![
            TestPose {
                name: "C1".into(),
                commanded: [0.0, 0.0, 300.0, 0.0, 0.0, 180.0],
            },
            TestPose {
                name: "C2".into(),
                commanded: [10.0, 0.0, 300.0, 0.0, 0.0, 0.0],
            },
        ];
        let at = |pose: &str, x: f64, z: f64, c: f64| Attained {
            cycle: 1,
            pose: pose.into(),
            pose_mm_deg: [x, 0.0, z, 0.0, 0.0, c],
        };
        let allowed = Allowed {
            position_mm: 0.06,
            angles_deg: [0.01; 3],
        };
        let good = [
            at("C1", 0.03, 300.04, -179.995),
            at("C2", 10.0, 300.01, 0.0),
        ];
        let result = CheckResult::new(&poses, &good, &[], allowed);
        let (name, worst) = result.worst_position().unwrap();
        assert!(
            name == "C1" && (worst - 0.05).abs() < 1e-12,
            "{name} {worst}"
        );
        assert!((result.mean_position_mm() - 0.03).abs() < 1e-12);
        // −179.995° is 0.005° from 180°, not 359.995°.
        let (_, axis, share) = result.worst_angle_share().unwrap();
        assert!(axis == 'c' && (share - 0.5).abs() < 1e-6, "{share}");
        assert_eq!(result.verdict(), Verdict::StillGood);
        let far = [at("C1", 0.0, 300.07, 180.0), at("C2", 10.0, 300.0, 0.0)];
        assert_eq!(
            CheckResult::new(&poses, &far, &[], allowed).verdict(),
            Verdict::Retrain
        );
        let turned = [at("C1", 0.0, 300.0, 179.98), at("C2", 10.0, 300.0, 0.0)];
        assert_eq!(
            CheckResult::new(&poses, &turned, &[], allowed).verdict(),
            Verdict::Retrain
        );
        let missed = [Missed {
            cycle: 1,
            pose: "C2".into(),
            why: "no reading".into(),
        }];
        assert_eq!(
            CheckResult::new(&poses, &good[..1], &missed, allowed).verdict(),
            Verdict::Inconclusive
        );
        // A problem found decides, whatever was not measured.
        assert_eq!(
            CheckResult::new(&poses, &far[..1], &missed, allowed).verdict(),
            Verdict::Retrain
        );
    }
}
