//! The records the trainer and the client work with — planned poses, measured configurations,
//! joint corrections, leg lengths, compensated points — each with its id, independent of the
//! file format they are stored in (`hexacomp-formats` reads and writes them as CSV).
//!
//! Units: mm and degrees for the poses as planned or commanded (kept exactly as given, so a
//! record written and read back is bit-identical); the `pose()` methods convert to [`Pose`]
//! (mm, radians). Points are in the base frame unless a record says otherwise.

use glam::DVec3;

use crate::compensator::Compensated;
use crate::geometry::LEGS;
use crate::observation::Observation;
use crate::pose::Pose;

/// A pose with an id: one planned configuration, or one point to compensate.
#[derive(Debug, Clone, PartialEq)]
pub struct NamedPose {
    /// The configuration's id, unique in its set.
    pub id: String,
    /// The pose `[x, y, z, a, b, c]`, mm and degrees.
    pub pose_mm_deg: [f64; 6],
}

impl NamedPose {
    /// The pose (mm, rad).
    pub fn pose(&self) -> Pose {
        Pose::from_mm_deg(self.pose_mm_deg)
    }
}

/// One measured configuration: the commanded pose, the nominal legs commanded for it, and what
/// the instrument measured (target points or the platform's pose) in the base frame.
#[derive(Debug, Clone, PartialEq)]
pub struct MeasuredConfiguration {
    /// The configuration's id, unique in its set.
    pub id: String,
    /// The commanded pose `[x, y, z, a, b, c]`, mm and degrees.
    pub pose_mm_deg: [f64; 6],
    /// The nominal leg lengths that were commanded, mm.
    pub legs: [f64; LEGS],
    /// What was measured: the target points `P_1..P_N` (some perhaps not seen) or the pose.
    pub observed: Observation,
}

impl MeasuredConfiguration {
    /// The commanded pose (mm, rad).
    pub fn pose(&self) -> Pose {
        Pose::from_mm_deg(self.pose_mm_deg)
    }
}

/// The joint corrections of one configuration: nominal legs `q` and corrections `Δq` (mm).
#[derive(Debug, Clone, PartialEq)]
pub struct JointCorrection {
    /// The configuration's id.
    pub id: String,
    /// Nominal (commanded) leg lengths `q⁽⁰⁾`, mm.
    pub legs: [f64; LEGS],
    /// Joint corrections `Δq = q⁽⁰⁾ − q⁽ᴸ⁾` (Eq. 9), mm.
    pub corrections: [f64; LEGS],
}

/// Nominal leg lengths with an id: one point to compensate in joint space.
#[derive(Debug, Clone, PartialEq)]
pub struct NamedLegs {
    /// The point's id.
    pub id: String,
    /// Nominal leg lengths, mm.
    pub legs: [f64; LEGS],
}

/// A compensated point with the id of the pose or legs it was computed for.
#[derive(Debug, Clone, PartialEq)]
pub struct NamedCompensation {
    /// The point's id.
    pub id: String,
    /// The compensated point: legs to command, corrections (mm) and status.
    pub point: Compensated,
}

/// A named point: a fiducial on the machine base, in the base frame (nominal) or as an
/// instrument measured it (in the instrument's frame).
#[derive(Debug, Clone, PartialEq)]
pub struct NamedPoint {
    /// The point's name, unique in its set.
    pub name: String,
    /// Its coordinates, mm, in the frame of its file.
    pub position: DVec3,
    /// Its weight in a registration (≥ 0; 1 when the file gives none; 0: reported, not used).
    pub weight: f64,
}
