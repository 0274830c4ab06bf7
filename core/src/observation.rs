//! What an instrument measured of one configuration: target points (any number, some perhaps
//! not seen), or the platform's pose from a 6-DoF probe; and the paper's linearisation of it
//! (Eq. 4) at a pose.
//!
//! Frames: measured points and poses are in the base frame `K_B` (mm; poses in mm and degrees
//! as in files, `R = Rz(c)·Ry(b)·Rx(a)`). Measurements made in an instrument's own frame are
//! brought into the base frame first ([`Observation::in_frame`]).

use glam::DVec3;
use nalgebra::{DMatrix, DVector};

use crate::error::{Error, Result};
use crate::geometry::Geometry;
use crate::kinematics::{pose_from_targets, target_points};
use crate::pose::Pose;
use crate::screw::point_matrix;

/// What was measured of one configuration.
#[derive(Debug, Clone, PartialEq)]
pub enum Observation {
    /// The target points `P_1..P_N` of the geometry, measured in the base frame (mm), in the
    /// geometry's order; `None` for a target not seen in this configuration (a blocked beam).
    Targets(Vec<Option<DVec3>>),
    /// The pose of the platform frame measured directly by a 6-DoF probe: `[x, y, z, a, b, c]`,
    /// mm and degrees, base frame, the convention of the commanded pose.
    Pose([f64; 6]),
    /// A 6-DoF probe's row without a pose (its six cells empty): nothing was measured.
    PoseMissed,
}

/// Why an observation does not belong to a geometry ([`Observation::check`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Mismatch {
    /// Another number of targets than the geometry names.
    #[error(
        "{measured} measured targets, but geometry {geometry} names {named} (is it the geometry \
         the campaign was measured with?)"
    )]
    TargetCount {
        /// The targets measured (seen or not).
        measured: usize,
        /// The geometry's name.
        geometry: String,
        /// The targets it names.
        named: usize,
    },
    /// A number that is not finite.
    #[error("{what} is not finite")]
    NotFinite {
        /// What holds it ("the measured pose").
        what: &'static str,
    },
}

impl Observation {
    /// The measured pose of a [`Observation::Pose`] (mm, rad).
    fn measured_pose(values: &[f64; 6]) -> Pose {
        Pose::from_mm_deg(*values)
    }

    /// How many targets were seen (for a pose: none).
    pub fn targets_seen(&self) -> usize {
        match self {
            Observation::Targets(targets) => targets.iter().flatten().count(),
            Observation::Pose(_) | Observation::PoseMissed => 0,
        }
    }

    /// Checks that the observation belongs to `geometry` (as many targets as it names) and that
    /// its numbers are finite; the error says what does not fit.
    pub fn check(&self, geometry: &Geometry) -> std::result::Result<(), Mismatch> {
        match self {
            Observation::Targets(targets) => {
                if targets.len() != geometry.targets.len() {
                    return Err(Mismatch::TargetCount {
                        measured: targets.len(),
                        geometry: geometry.name.clone(),
                        named: geometry.targets.len(),
                    });
                }
                if !targets.iter().flatten().all(|p| p.is_finite()) {
                    return Err(Mismatch::NotFinite {
                        what: "a measured target point",
                    });
                }
            }
            Observation::Pose(values) => {
                if !values.iter().all(|v| v.is_finite()) {
                    return Err(Mismatch::NotFinite {
                        what: "the measured pose",
                    });
                }
            }
            Observation::PoseMissed => {}
        }
        Ok(())
    }

    /// Why the observation does not determine the platform's pose, or `None` when it does (a
    /// measured pose; three or more seen targets not on one line). Two targets leave the
    /// rotation about the line through them unmeasured.
    pub fn undetermined(&self, geometry: &Geometry) -> Option<String> {
        let targets = match self {
            Observation::Targets(targets) => targets,
            Observation::Pose(_) => return None,
            Observation::PoseMissed => return Some("the probe gave no pose".into()),
        };
        let seen: Vec<DVec3> = geometry
            .targets
            .iter()
            .zip(targets)
            .filter(|(_, m)| m.is_some())
            .map(|(p, _)| *p)
            .collect();
        let missing: Vec<String> = (1..)
            .zip(targets)
            .filter(|(_, m)| m.is_none())
            .map(|(j, _)| format!("P{j}"))
            .collect();
        if seen.len() < 3 {
            return Some(format!(
                "{} of {} targets seen ({} not seen): fewer than three leave the platform's pose \
                 undetermined",
                seen.len(),
                targets.len(),
                missing.join(", ")
            ));
        }
        if crate::geometry::check_targets_not_collinear(&seen).is_err() {
            return Some(format!(
                "the targets seen lie on one line ({} not seen): the rotation about it is \
                 undetermined",
                missing.join(", ")
            ));
        }
        None
    }

    /// The measured points in the base frame (mm) with the index of the geometry's target each
    /// is: the seen targets, or for a measured pose every target placed at that pose. These are
    /// what [`Observation::misfit`] compares.
    pub fn points(&self, geometry: &Geometry) -> Vec<(usize, DVec3)> {
        match self {
            Observation::Targets(targets) => targets
                .iter()
                .enumerate()
                .filter_map(|(j, m)| m.map(|m| (j, m)))
                .collect(),
            Observation::Pose(values) => target_points(geometry, &Self::measured_pose(values))
                .into_iter()
                .enumerate()
                .collect(),
            Observation::PoseMissed => Vec::new(),
        }
    }

    /// `ζ = r_Pm − r_Pc` (Eq. 4) over [`Observation::points`]: the measured points minus those of
    /// `geometry` at `pose` (base frame, mm), stacked point by point as `(x₁, y₁, z₁, x₂, …)`.
    pub fn misfit(&self, geometry: &Geometry, pose: &Pose) -> DVector<f64> {
        let rotation = pose.rotation();
        let points = self.points(geometry);
        DVector::from_iterator(
            3 * points.len(),
            points.iter().flat_map(|(j, measured)| {
                (*measured - (pose.position + rotation * geometry.targets[*j])).to_array()
            }),
        )
    }

    /// The paper's linear model of the observation at `pose`: `(ζ, P)` with `ζ ≈ P·ξ_t` for a
    /// small pose-error twist `ξ_t` about `A` (Eq. 4), over [`Observation::points`]: `ζ` is the
    /// misfit of the seen targets (mm) and `P` their rows of the point matrix. A measured pose
    /// enters through the targets it places: its pose error `ξ_t` moves them by `P·ξ_t`, so `ζ`
    /// and `cond(PT)` keep the units and meaning they have with targets (`P = I` would mix mm
    /// and rad in `ζ`, and `cond(T)` is hundreds where `cond(PT)` is single digits).
    pub fn linearised(&self, geometry: &Geometry, pose: &Pose) -> (DVector<f64>, DMatrix<f64>) {
        let which: Vec<usize> = self.points(geometry).iter().map(|(j, _)| *j).collect();
        (
            self.misfit(geometry, pose),
            point_matrix(geometry, pose, &which),
        )
    }

    /// The pose the observation gives (mm, rad): the least-squares fit of the seen targets
    /// ([`pose_from_targets`]), or the measured pose.
    pub fn fitted_pose(&self, geometry: &Geometry) -> Result<Pose> {
        match self {
            Observation::Targets(targets) => pose_from_targets(geometry, targets),
            Observation::Pose(values) => Ok(Self::measured_pose(values)),
            Observation::PoseMissed => Err(Error::RigidFit("the probe gave no pose".into())),
        }
    }

    /// The observation made in an instrument's frame, expressed in the base frame: `frame` is the
    /// instrument's pose in the base frame. A point `p` becomes `t + R·p`; a measured pose is
    /// composed with the frame.
    pub fn in_frame(&self, frame: &Pose) -> Observation {
        match self {
            Observation::Targets(targets) => Observation::Targets(
                targets
                    .iter()
                    .map(|m| m.map(|p| frame.transform_point(p)))
                    .collect(),
            ),
            Observation::Pose(values) => {
                let local = Self::measured_pose(values);
                let rotation = frame.rotation() * local.rotation();
                let pose = Pose::from_rotation(frame.transform_point(local.position), &rotation);
                Observation::Pose(pose.to_mm_deg())
            }
            Observation::PoseMissed => Observation::PoseMissed,
        }
    }
}
