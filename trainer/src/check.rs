//! The drift check a user runs monthly or after a crash: the poses an ISO 9283 test verified
//! after the calibration (`verify`), each measured once more with the compensation active,
//! their position errors compared with what that test proved.
//!
//! The promise: at a verified pose the barycentre lies within AP_P of the commanded position and
//! an attained position within RP_l of the barycentre, so one attained position lies within
//! `AP_P + RP_l` of the commanded one. The worst of both over the verified poses is allowed at
//! every one of them. Units: mm, base frame.

use crate::iso9283::TestPose;
use crate::verify::Attained;
use crate::verify_report::VerifyReport;
use glam::DVec3;

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

/// The largest single-pose position error a verified calibration promises: the worst AP_P plus
/// the worst RP_l of `report`, mm.
pub fn promised_mm(report: &VerifyReport) -> f64 {
    report.worst_ap_p_mm() + report.worst_rp_l_mm()
}

/// What a check found.
#[derive(Debug, Clone, PartialEq)]
pub struct CheckResult {
    /// Each measured pose's position error `|attained − commanded|`, mm, in the order of the
    /// poses (a pose not measured is left out).
    pub errors_mm: Vec<(String, f64)>,
    /// The largest error allowed (the promise times the tolerance), mm.
    pub allowed_mm: f64,
}

impl CheckResult {
    /// The errors of `attained` at `poses` against `allowed_mm`.
    pub fn new(poses: &[TestPose], attained: &[Attained], allowed_mm: f64) -> Self {
        let errors_mm = attained
            .iter()
            .filter_map(|a| {
                let pose = poses.iter().find(|p| p.name == a.pose)?;
                let at = DVec3::from_slice(&a.pose_mm_deg[..3]);
                let commanded = DVec3::from_slice(&pose.commanded[..3]);
                Some((a.pose.clone(), at.distance(commanded)))
            })
            .collect();
        Self {
            errors_mm,
            allowed_mm,
        }
    }

    /// The largest error and its pose, if any pose was measured.
    pub fn worst(&self) -> Option<(&str, f64)> {
        self.errors_mm
            .iter()
            .map(|(name, e)| (name.as_str(), *e))
            .max_by(|a, b| a.1.total_cmp(&b.1))
    }

    /// The mean error, mm (0 when nothing was measured).
    pub fn mean_mm(&self) -> f64 {
        if self.errors_mm.is_empty() {
            return 0.0;
        }
        self.errors_mm.iter().map(|(_, e)| e).sum::<f64>() / self.errors_mm.len() as f64
    }

    /// Whether the machine still keeps the promise: every measured pose within the allowed
    /// error (and at least one measured).
    pub fn still_good(&self) -> bool {
        self.worst().is_some_and(|(_, e)| e <= self.allowed_mm)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_verdict_is_the_worst_error_against_the_allowed_one() {
        let poses = vec![
            TestPose {
                name: "C1".into(),
                commanded: [0.0, 0.0, 300.0, 0.0, 0.0, 0.0],
            },
            TestPose {
                name: "C2".into(),
                commanded: [10.0, 0.0, 300.0, 0.0, 0.0, 0.0],
            },
        ];
        let at = |pose: &str, x: f64, z: f64| Attained {
            cycle: 1,
            pose: pose.into(),
            pose_mm_deg: [x, 0.0, z, 0.0, 0.0, 0.0],
        };
        let result = CheckResult::new(
            &poses,
            &[at("C1", 0.03, 300.04), at("C2", 10.0, 300.01)],
            0.06,
        );
        let (name, worst) = result.worst().unwrap();
        assert!(
            name == "C1" && (worst - 0.05).abs() < 1e-12,
            "{name} {worst}"
        );
        assert!((result.mean_mm() - 0.03).abs() < 1e-12);
        assert!(result.still_good());
        assert!(!CheckResult::new(&poses, &[at("C1", 0.0, 300.07)], 0.06).still_good());
        // Nothing measured keeps no promise.
        assert!(!CheckResult::new(&poses, &[], 0.06).still_good());
    }
}
