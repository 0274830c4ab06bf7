//! A model shaped like the machine: the identified geometry, one lead-screw error curve per leg
//! (a function of that leg's own encoder length, what LinuxCNC's joint compensation tables
//! hold) and the legs' compliance under the platform's weight — few parameters that mean
//! something, identified from the measured targets ([`crate::identify`]).
//!
//! The legs: a commanded encoder length `q` moves the leg to `q + p_i(q)` unloaded (the pitch
//! curve `p_i`, a uniform cubic B-spline over the stroke), and the load shortens it by
//! `sag_i = Σ_m c_im · h_im(pose)`: `h_im` is leg `i`'s compression under the unit wrench `w_m`
//! (the weight's force, and its moment for a centre of mass along each platform axis) times
//! the leg's length over the stroke's middle — the compliance grows with length. The
//! coefficients `c_im` stand for the leg's compliance times the weight (times its centre of
//! mass). The loaded length is what the geometry's forward kinematics places the platform with.
//!
//! Units: mm, rad.

use glam::DVec3;
use hexacomp_core::screw::ActuationScrews;
use hexacomp_core::{Geometry, LEGS, Pose, inverse_kinematics};
use nalgebra::Vector6;

/// Wrenches the compliance is modelled under: the weight's force and its moments.
pub const COMPLIANCE_TERMS: usize = 4;

/// One lead-screw error curve per leg: uniform cubic B-splines over the stroke.
#[derive(Debug, Clone, PartialEq)]
pub struct PitchCurves {
    /// The encoder stroke `[min, max]` the knots span, mm.
    pub stroke: [f64; 2],
    /// The coefficients of each leg's basis functions, mm (as many per leg as basis functions;
    /// none: no pitch error modelled).
    pub coefficients: [Vec<f64>; LEGS],
}

impl PitchCurves {
    /// Curves of `basis` functions per leg over `stroke`, all zero.
    pub fn zero(stroke: [f64; 2], basis: usize) -> Self {
        Self {
            stroke,
            coefficients: std::array::from_fn(|_| vec![0.0; basis]),
        }
    }

    /// Basis functions per leg.
    pub fn basis(&self) -> usize {
        self.coefficients[0].len()
    }

    /// The values of the basis functions (unitless, summing to 1 over the stroke) at encoder
    /// length `q` (mm); empty without curves. Needs four or more functions to be a partition of
    /// unity (the identification refuses fewer).
    pub fn basis_at(&self, q: f64) -> Vec<f64> {
        let count = self.basis();
        if count == 0 {
            return Vec::new();
        }
        let [min, max] = self.stroke;
        // Centres one spacing beyond each end, so the stroke lies where the functions sum to 1.
        let spacing = (max - min) / (count.max(4) - 3) as f64;
        (0..count)
            .map(|j| cubic_b_spline((q - (min + (j as f64 - 1.0) * spacing)) / spacing))
            .collect()
    }

    /// Leg `leg`'s pitch error at encoder length `q`, mm.
    pub fn error(&self, leg: usize, q: f64) -> f64 {
        self.basis_at(q)
            .iter()
            .zip(&self.coefficients[leg])
            .map(|(b, c)| b * c)
            .sum()
    }
}

/// The uniform cubic B-spline kernel, support `[−2, 2]`.
fn cubic_b_spline(t: f64) -> f64 {
    let t = t.abs();
    if t < 1.0 {
        2.0 / 3.0 - t * t + 0.5 * t * t * t
    } else if t < 2.0 {
        (2.0 - t).powi(3) / 6.0
    } else {
        0.0
    }
}

/// The identified machine.
#[derive(Debug, Clone, PartialEq)]
pub struct PhysicalModel {
    /// The geometry (joint centres, leg zero offsets).
    pub geometry: Geometry,
    /// The lead-screw error curves.
    pub pitch: PitchCurves,
    /// The compliance coefficients `c_im` of each leg, mm per unit of `h_im` (all zero: none
    /// modelled).
    pub compliance: [[f64; COMPLIANCE_TERMS]; LEGS],
}

impl PhysicalModel {
    /// The geometry alone (no pitch, no compliance).
    pub fn geometric(geometry: Geometry) -> Self {
        let stroke = geometry.leg_range;
        Self {
            geometry,
            pitch: PitchCurves::zero(stroke, 0),
            compliance: [[0.0; COMPLIANCE_TERMS]; LEGS],
        }
    }

    /// `h_im` at `pose` for unloaded lengths `unloaded` (mm): leg `i`'s compression under the
    /// unit wrench `w_m`, times its length over the stroke's middle. Zero at a singular pose.
    pub fn compliance_basis(
        &self,
        pose: &Pose,
        unloaded: &[f64; LEGS],
    ) -> [[f64; COMPLIANCE_TERMS]; LEGS] {
        let w = ActuationScrews::at(&self.geometry, pose).force_jacobian();
        let lu = w.lu();
        let rotation = pose.rotation();
        let middle = 0.5 * (self.geometry.leg_range[0] + self.geometry.leg_range[1]);
        let mut basis = [[0.0; COMPLIANCE_TERMS]; LEGS];
        for m in 0..COMPLIANCE_TERMS {
            // The columns of `basis` are filled one wrench at a time.
            // The weight pulls along −z; a centre of mass along platform axis m adds the moment
            // (R·e_m) × (−z).
            let wrench = if m == 0 {
                Vector6::new(0.0, 0.0, -1.0, 0.0, 0.0, 0.0)
            } else {
                let arm = rotation * DVec3::AXES[m - 1];
                Vector6::new(0.0, 0.0, 0.0, -arm.y, arm.x, 0.0)
            };
            let Some(compression) = lu.solve(&(-wrench)) else {
                return [[0.0; COMPLIANCE_TERMS]; LEGS];
            };
            for (i, terms) in basis.iter_mut().enumerate() {
                terms[m] = compression[i] * unloaded[i] / middle;
            }
        }
        basis
    }

    /// The sag of every leg at `pose` for unloaded lengths `unloaded`, mm.
    fn sag(&self, pose: &Pose, unloaded: &[f64; LEGS]) -> [f64; LEGS] {
        let basis = self.compliance_basis(pose, unloaded);
        std::array::from_fn(|i| {
            (0..COMPLIANCE_TERMS)
                .map(|m| self.compliance[i][m] * basis[i][m])
                .sum()
        })
    }

    /// Whether the model has compliance terms other than zero.
    fn compliant(&self) -> bool {
        self.compliance.iter().flatten().any(|c| *c != 0.0)
    }

    /// The loaded encoder-equivalent lengths for commanded encoder lengths `commanded` at
    /// (about) `pose`, mm: what the geometry's forward kinematics takes.
    pub fn loaded_lengths(&self, commanded: &[f64; LEGS], pose: &Pose) -> [f64; LEGS] {
        let unloaded: [f64; LEGS] =
            std::array::from_fn(|i| commanded[i] + self.pitch.error(i, commanded[i]));
        if !self.compliant() {
            return unloaded;
        }
        let sag = self.sag(pose, &unloaded);
        std::array::from_fn(|i| unloaded[i] - sag[i])
    }

    /// The encoder lengths to command so that the modelled machine stands at `pose`, mm: the
    /// geometry's inverse kinematics, the sag at that pose added back, the pitch curves
    /// inverted.
    pub fn command(&self, pose: &Pose) -> [f64; LEGS] {
        let loaded = inverse_kinematics(&self.geometry, pose).lengths;
        let mut unloaded = loaded;
        if self.compliant() {
            for _ in 0..4 {
                let sag = self.sag(pose, &unloaded);
                unloaded = std::array::from_fn(|i| loaded[i] + sag[i]);
            }
        }
        // q + p(q) = unloaded: each pass shrinks the error by the curve's slope (below 0.03 for
        // lead-screw errors of a few tenths of a millimetre over the stroke): eight passes
        // leave it below 1e-12 of the curve's size.
        std::array::from_fn(|i| {
            let mut q = unloaded[i];
            for _ in 0..8 {
                q = unloaded[i] - self.pitch.error(i, q);
            }
            q
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_pitch_basis_sums_to_one_over_the_stroke_and_is_smooth() {
        let curves = PitchCurves::zero([280.0, 430.0], 12);
        for k in 0..=300 {
            let q = 280.0 + 150.0 * k as f64 / 300.0;
            let sum: f64 = curves.basis_at(q).iter().sum();
            assert!((sum - 1.0).abs() < 1e-12, "{q}: {sum}");
        }
        // Continuous with a continuous slope at a knot: the one-sided slopes agree.
        let f = |q: f64| curves.basis_at(q)[5];
        let knot = 280.0 + 4.0 * 150.0 / 9.0;
        let h = 1e-4;
        let left = (f(knot) - f(knot - h)) / h;
        let right = (f(knot + h) - f(knot)) / h;
        assert!((left - right).abs() < 1e-3, "{left} {right}");
    }

    #[test]
    fn the_command_lands_the_model_on_the_pose() {
        let g = Geometry::prototype();
        let mut model = PhysicalModel::geometric(g.clone());
        model.pitch = PitchCurves::zero(g.leg_range, 10);
        for (i, c) in model.pitch.coefficients.iter_mut().enumerate() {
            for (j, v) in c.iter_mut().enumerate() {
                *v = 0.03 * ((i * 10 + j) as f64).sin();
            }
        }
        // Of the virtual machine's size: compliance 4e-4 mm/N times 785 N of weight, times a
        // centre of mass some 10–60 mm from the platform's origin.
        model.compliance = std::array::from_fn(|i| {
            let k = 0.3 * (1.0 + 0.1 * i as f64);
            [k, 15.0 * k, -10.0 * k, 60.0 * k]
        });
        let pose = Pose::from_mm_deg([12.0, -8.0, 330.0, 3.0, -2.0, 4.0]);
        let command = model.command(&pose);
        let loaded = model.loaded_lengths(&command, &pose);
        let exact = inverse_kinematics(&g, &pose).lengths;
        for i in 0..LEGS {
            assert!((loaded[i] - exact[i]).abs() < 1e-9, "leg {i}");
        }
        assert!((0..LEGS).any(|i| (command[i] - exact[i]).abs() > 0.01));
    }
}
