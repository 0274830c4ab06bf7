//! Seeded, uniformly random poses over the task workspace.
//!
//! Position of `A`: uniform over the workspace cylinder. Orientation: the platform normal uniform
//! over the tilt cone (uniform on the spherical cap, not in the angle), yaw `c` uniform over the
//! yaw range. Poses whose legs come within [`SamplerOptions::stroke_margin_mm`] of a stroke end are
//! rejected, so the accepted poses are uniform over the reachable part of the workspace.

use glam::{DMat3, DVec3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::error::{Error, Result};
use crate::geometry::Geometry;
use crate::kinematics::inverse_kinematics;
use crate::pose::Pose;

/// Settings of the workspace sampler.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SamplerOptions {
    /// Reject poses with any leg closer than this to either stroke end, mm.
    pub stroke_margin_mm: f64,
    /// Give up with [`Error::WorkspaceUnreachable`] after this many rejections in a row.
    pub max_attempts: usize,
}

impl Default for SamplerOptions {
    fn default() -> Self {
        Self {
            stroke_margin_mm: 2.0,
            max_attempts: 10_000,
        }
    }
}

/// A reproducible stream of random workspace poses.
#[derive(Debug, Clone)]
pub struct WorkspaceSampler<'g> {
    geometry: &'g Geometry,
    options: SamplerOptions,
    rng: ChaCha8Rng,
}

impl<'g> WorkspaceSampler<'g> {
    /// A sampler over `geometry`'s workspace; the same seed gives the same poses.
    pub fn new(geometry: &'g Geometry, seed: u64, options: SamplerOptions) -> Result<Self> {
        let [min, max] = geometry.leg_range;
        if !(options.stroke_margin_mm >= 0.0 && 2.0 * options.stroke_margin_mm < max - min) {
            return Err(Error::InvalidSetting(format!(
                "stroke margin {} mm must be ≥ 0 and leave part of the {min}–{max} mm stroke",
                options.stroke_margin_mm
            )));
        }
        Ok(Self {
            geometry,
            options,
            rng: ChaCha8Rng::seed_from_u64(seed),
        })
    }

    /// The next accepted pose (mm, rad).
    pub fn sample(&mut self) -> Result<Pose> {
        for _ in 0..self.options.max_attempts {
            let candidate = self.candidate();
            if self.accepts(&candidate) {
                return Ok(candidate);
            }
        }
        Err(Error::WorkspaceUnreachable {
            attempts: self.options.max_attempts,
        })
    }

    /// `count` accepted poses.
    pub fn samples(&mut self, count: usize) -> Result<Vec<Pose>> {
        (0..count).map(|_| self.sample()).collect()
    }

    /// True when every leg of `pose` is at least the margin away from both stroke ends.
    pub fn accepts(&self, pose: &Pose) -> bool {
        let [min, max] = self.geometry.leg_range;
        let margin = self.options.stroke_margin_mm;
        inverse_kinematics(self.geometry, pose)
            .lengths
            .iter()
            .all(|&q| q >= min + margin && q <= max - margin)
    }

    /// A pose drawn uniformly from the workspace before the stroke check.
    fn candidate(&mut self) -> Pose {
        let w = &self.geometry.workspace;
        let radius = w.radius * self.rng.random::<f64>().sqrt();
        let azimuth = self.rng.random_range(0.0..std::f64::consts::TAU);
        let z = uniform(&mut self.rng, w.z_range);
        let position = DVec3::new(radius * azimuth.cos(), radius * azimuth.sin(), z);

        let cos_tilt_min = w.tilt_max.to_radians().cos();
        let cos_tilt = uniform(&mut self.rng, [cos_tilt_min, 1.0]);
        let sin_tilt = (1.0 - cos_tilt * cos_tilt).max(0.0).sqrt();
        let tilt_azimuth = self.rng.random_range(0.0..std::f64::consts::TAU);
        let normal = DVec3::new(
            sin_tilt * tilt_azimuth.cos(),
            sin_tilt * tilt_azimuth.sin(),
            cos_tilt,
        );
        let yaw = uniform(&mut self.rng, w.yaw_range).to_radians();
        Pose::new(position, angles_for_normal(normal, yaw))
    }
}

fn uniform(rng: &mut ChaCha8Rng, [lo, hi]: [f64; 2]) -> f64 {
    lo + (hi - lo) * rng.random::<f64>()
}

/// Roll and pitch `(a, b)` that, with yaw `c`, point the platform normal `R·e_z` along `normal`.
///
/// `R·e_z = Rz(c)·(cos a·sin b, −sin a, cos a·cos b)`, so with `n' = Rz(−c)·normal`:
/// `a = −asin(n'_y)`, `b = atan2(n'_x, n'_z)`.
fn angles_for_normal(normal: DVec3, yaw: f64) -> DVec3 {
    let n = DMat3::from_rotation_z(-yaw) * normal;
    DVec3::new(-n.y.clamp(-1.0, 1.0).asin(), n.x.atan2(n.z), yaw)
}

/// The angle between the platform normal `R·e_z` and the base z axis, rad.
pub fn tilt(pose: &Pose) -> f64 {
    (pose.rotation() * DVec3::Z).z.clamp(-1.0, 1.0).acos()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn samples_stay_inside_the_workspace_and_the_stroke_margin() {
        let g = Geometry::prototype();
        let opts = SamplerOptions::default();
        let mut sampler = WorkspaceSampler::new(&g, 7, opts).unwrap();
        let w = g.workspace;
        for pose in sampler.samples(2000).unwrap() {
            let p = pose.position;
            assert!(p.truncate().length() <= w.radius + 1e-9);
            assert!(p.z >= w.z_range[0] && p.z <= w.z_range[1]);
            assert!(tilt(&pose) <= w.tilt_max.to_radians() + 1e-12);
            let c = pose.angles.z.to_degrees();
            assert!(c >= w.yaw_range[0] - 1e-9 && c <= w.yaw_range[1] + 1e-9);
            for q in inverse_kinematics(&g, &pose).lengths {
                assert!(q >= g.leg_range[0] + opts.stroke_margin_mm);
                assert!(q <= g.leg_range[1] - opts.stroke_margin_mm);
            }
        }
    }

    #[test]
    fn same_seed_same_poses_other_seed_other_poses() {
        let g = Geometry::prototype();
        let draw = |seed| {
            WorkspaceSampler::new(&g, seed, SamplerOptions::default())
                .unwrap()
                .samples(20)
                .unwrap()
        };
        assert_eq!(draw(3), draw(3));
        assert_ne!(draw(3), draw(4));
    }

    #[test]
    fn normal_construction_gives_the_requested_tilt_direction() {
        let normal = DVec3::new(0.2, -0.1, 1.0).normalize();
        for yaw in [-0.2, 0.0, 0.15] {
            let pose = Pose::new(DVec3::ZERO, angles_for_normal(normal, yaw));
            assert!((pose.rotation() * DVec3::Z - normal).length() < 1e-14);
            assert_eq!(pose.angles.z, yaw);
        }
    }

    #[test]
    fn unreachable_workspace_is_an_error_not_a_hang() {
        let mut g = Geometry::prototype();
        g.workspace.z_range = [900.0, 950.0];
        let opts = SamplerOptions {
            max_attempts: 100,
            ..Default::default()
        };
        let err = WorkspaceSampler::new(&g, 1, opts)
            .unwrap()
            .sample()
            .unwrap_err();
        assert_eq!(err, Error::WorkspaceUnreachable { attempts: 100 });
    }
}
