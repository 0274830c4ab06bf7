//! The "real" machine behind the virtual platform: one seeded draw of every error source.

use glam::DVec3;
use nalgebra::Vector6;
use rand::{Rng, RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use super::error_model::ErrorModel;
use hexacomp_core::error::Result;
use hexacomp_core::geometry::{Geometry, LEGS};
use hexacomp_core::kinematics::{ForwardOptions, forward_kinematics, inverse_kinematics};
use hexacomp_core::pose::Pose;
use hexacomp_core::screw::ActuationScrews;

/// Standard gravity, m/s².
const GRAVITY: f64 = 9.806_65;

/// How far the real legs may move beyond the nominal stroke, mm: the stroke limits the encoder
/// readings, while the real length also carries the machine's errors.
const TRUE_STROKE_SLACK_MM: f64 = 10.0;

/// The lead-screw error of one leg (see [`super::PitchErrors`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LeadScrew {
    /// Linear (scale) error, mm per mm.
    pub scale: f64,
    /// Quadratic term at the stroke ends, mm.
    pub curvature_mm: f64,
    /// Amplitude of the periodic term, mm.
    pub periodic_mm: f64,
    /// Phase of the periodic term, rad.
    pub phase: f64,
}

/// One drawn "real" machine: the true geometry and every non-geometric error, fixed by a seed.
#[derive(Debug, Clone, PartialEq)]
pub struct TrueMachine {
    /// The true geometry: the nominal joint centres plus drawn offsets, and drawn leg zero
    /// offsets (`leg_offsets`: real length minus encoder length); its stroke is the nominal one
    /// widened by a slack, since real lengths carry the errors.
    pub geometry: Geometry,
    /// Per-leg lead-screw errors.
    pub lead_screws: [LeadScrew; LEGS],
    /// Per-leg axial compliance at mid-stroke, mm/N.
    pub compliance_mm_per_n: [f64; LEGS],
    model: ErrorModel,
    stroke_mid_mm: f64,
    stroke_half_mm: f64,
}

impl TrueMachine {
    /// Draws a machine around `nominal` with the magnitudes of `model`; the same seed gives the
    /// same machine.
    pub fn draw(nominal: &Geometry, model: &ErrorModel, seed: u64) -> Result<Self> {
        model.validate()?;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut geometry = nominal.clone();
        geometry.name = format!("{} (virtual machine, seed {seed})", nominal.name);
        for joint in &mut geometry.base_joints {
            *joint += model.base_joint_sigma_mm * normal3(&mut rng);
        }
        for joint in &mut geometry.platform_joints {
            *joint += model.platform_joint_sigma_mm * normal3(&mut rng);
        }
        geometry.leg_range = [
            nominal.leg_range[0] - TRUE_STROKE_SLACK_MM,
            nominal.leg_range[1] + TRUE_STROKE_SLACK_MM,
        ];
        geometry.leg_offsets = std::array::from_fn(|_| model.leg_zero_sigma_mm * normal(&mut rng));
        let p = model.pitch;
        let lead_screws = std::array::from_fn(|_| LeadScrew {
            scale: p.scale_sigma * normal(&mut rng),
            curvature_mm: p.curvature_sigma_mm * normal(&mut rng),
            periodic_mm: p.periodic_sigma_mm * normal(&mut rng),
            phase: rng.random_range(0.0..std::f64::consts::TAU),
        });
        let c = model.compliance;
        let compliance_mm_per_n = std::array::from_fn(|_| {
            (c.compliance_mm_per_n * (1.0 + c.scatter * normal(&mut rng))).max(0.0)
        });
        Ok(Self {
            geometry,
            lead_screws,
            compliance_mm_per_n,
            model: *model,
            stroke_mid_mm: 0.5 * (nominal.leg_range[0] + nominal.leg_range[1]),
            stroke_half_mm: 0.5 * (nominal.leg_range[1] - nominal.leg_range[0]),
        })
    }

    /// The error model the machine was drawn from.
    pub fn model(&self) -> &ErrorModel {
        &self.model
    }

    /// Encoder-equivalent leg lengths (mm) for commanded encoder lengths `commanded` (mm), before
    /// gravity and noise: `q + lead-screw error(q)`. The true geometry's leg offsets turn these
    /// into real joint-to-joint lengths.
    pub fn unloaded_lengths(&self, commanded: &[f64; LEGS]) -> [f64; LEGS] {
        std::array::from_fn(|i| commanded[i] + self.pitch_error(i, commanded[i]))
    }

    /// The lead-screw error of leg `leg` (0-based) at encoder length `q`, mm.
    pub fn pitch_error(&self, leg: usize, q: f64) -> f64 {
        let s = &self.lead_screws[leg];
        let u = (q - self.stroke_mid_mm) / self.stroke_half_mm;
        let wavelength = self.model.pitch.periodic_wavelength_mm;
        s.scale * (q - self.stroke_mid_mm)
            + s.curvature_mm * u * u
            + s.periodic_mm * (std::f64::consts::TAU * q / wavelength + s.phase).sin()
    }

    /// Axial shortening of every leg under gravity at the real pose `pose`, mm (positive:
    /// shorter), for encoder-equivalent lengths `lengths`. Leg forces from static equilibrium
    /// `W·τ = −w_gravity` (Eq. 3's `W` of the true geometry), compliance growing linearly with
    /// leg length.
    pub fn gravity_shortening(&self, pose: &Pose, lengths: &[f64; LEGS]) -> [f64; LEGS] {
        let c = &self.model.compliance;
        if c.mass_kg == 0.0 {
            return [0.0; LEGS];
        }
        let force_n = DVec3::new(0.0, 0.0, -c.mass_kg * GRAVITY);
        let moment_nmm = (pose.rotation() * c.centre_of_mass_mm).cross(force_n);
        let wrench = Vector6::new(
            force_n.x,
            force_n.y,
            force_n.z,
            moment_nmm.x,
            moment_nmm.y,
            moment_nmm.z,
        );
        let w = ActuationScrews::at(&self.geometry, pose).force_jacobian();
        // Compression (legs pushing the platform away from the base) is positive.
        let Some(compression) = w.lu().solve(&(-wrench)) else {
            return [0.0; LEGS];
        };
        std::array::from_fn(|i| {
            compression[i] * self.compliance_mm_per_n[i] * lengths[i] / self.stroke_mid_mm
        })
    }

    /// The encoder leg lengths (mm) whose noiseless move reaches `pose` (base frame; mm, rad)
    /// exactly: the true geometry's inverse kinematics, the gravity sag at that pose added back,
    /// the lead-screw errors inverted. What a perfect compensation commands: driven with the
    /// machine's repeatability, it leaves the floor no method can go below.
    pub fn exact_command(&self, pose: &Pose) -> [f64; LEGS] {
        let loaded = inverse_kinematics(&self.geometry, pose).lengths;
        // The sag depends on the unloaded lengths only through the compliance growing with
        // length (relative change ~1e-4 per pass): a few fixed-point passes settle it.
        let mut unloaded = loaded;
        for _ in 0..4 {
            let sag = self.gravity_shortening(pose, &unloaded);
            unloaded = std::array::from_fn(|i| loaded[i] + sag[i]);
        }
        // q + pitch(q) = unloaded; the pitch error's slope is ~1e-3 (~2e-2 with the strong-pitch
        // variant's errors), so q ← unloaded − pitch(q) gains two to three digits a pass.
        std::array::from_fn(|i| {
            let mut q = unloaded[i];
            for _ in 0..8 {
                q = unloaded[i] - self.pitch_error(i, q);
            }
            q
        })
    }

    /// The real pose reached for encoder-equivalent unloaded leg lengths `unloaded` (mm),
    /// including gravity sag, by forward kinematics of the true geometry from `seed`.
    pub fn settle(&self, unloaded: &[f64; LEGS], seed: &Pose) -> Result<Pose> {
        let options = ForwardOptions::default();
        let mut pose = forward_kinematics(&self.geometry, unloaded, seed, &options)?;
        if self.model.compliance.mass_kg == 0.0 {
            return Ok(pose);
        }
        // The load changes little with the sag itself: three fixed-point passes settle it far
        // below a nanometre.
        for _ in 0..3 {
            let sag = self.gravity_shortening(&pose, unloaded);
            let loaded: [f64; LEGS] = std::array::from_fn(|i| unloaded[i] - sag[i]);
            pose = forward_kinematics(&self.geometry, &loaded, &pose, &options)?;
        }
        Ok(pose)
    }
}

pub(super) fn normal<R: Rng + ?Sized>(rng: &mut R) -> f64 {
    StandardNormal.sample(rng)
}

pub(super) fn normal3<R: Rng + ?Sized>(rng: &mut R) -> DVec3 {
    DVec3::new(normal(rng), normal(rng), normal(rng))
}
