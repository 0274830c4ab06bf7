//! A model shaped like the machine: the identified geometry, one lead-screw error curve per leg
//! (a function of that leg's own encoder length, what LinuxCNC's joint compensation tables
//! hold) and the legs' compliance under the platform's weight — few parameters that mean
//! something, identified from the measured targets (`hexacomp_calibration::identify`).
//!
//! The legs: a commanded encoder length `q` moves the leg to `q + p_i(q)` unloaded (the pitch
//! curve `p_i`, a uniform cubic B-spline over the stroke), and the load shortens it by
//! `sag_i = Σ_m c_im · h_im(pose)`: `h_im` is leg `i`'s compression under the unit wrench `w_m`
//! (the weight's force, and its moment for a centre of mass along each platform axis) times
//! the leg's length over the stroke's middle — the compliance grows with length. The
//! coefficients `c_im` stand for the leg's compliance times the weight (times its centre of
//! mass). The loaded length is what the geometry's forward kinematics places the platform with.
//!
//! The model file carries it as it is ([`PhysicalCorrections`]): the service commands a pose
//! with the model's inverse, in closed form but for each lead-screw curve's inversion (a few
//! Newton steps), so no approximation of it stands between the identification and the machine.
//!
//! Units: mm, rad.

use glam::DVec3;
use nalgebra::Vector6;
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::geometry::{Geometry, LEGS, Workspace};
use crate::kinematics::inverse_kinematics;
use crate::pose::Pose;
use crate::screw::ActuationScrews;

/// Newton steps of a lead-screw curve's inversion ([`PitchCurves::inverse`]).
const NEWTON_STEPS: usize = 2;

/// Wrenches the compliance is modelled under: the weight's force and its moments.
pub const COMPLIANCE_TERMS: usize = 4;

/// One lead-screw error curve per leg: uniform cubic B-splines over the stroke.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
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

    /// The spacing of the knots, mm, and the offset of `q` (mm) in spacings from the first
    /// function's centre.
    fn position(&self, q: f64) -> (f64, f64) {
        let [min, max] = self.stroke;
        let spacing = (max - min) / (self.basis().max(4) - 3) as f64;
        (spacing, (q - min) / spacing + 1.0)
    }

    /// The functions that may be non-zero at offset `t` (in spacings, [`PitchCurves::position`]):
    /// the four whose support `[j − 2, j + 2]` holds it, within the curve's.
    fn supporting(&self, t: f64) -> std::ops::Range<usize> {
        let count = self.basis();
        if !t.is_finite() {
            return 0..count;
        }
        let first = (t.floor() - 2.0).clamp(0.0, count as f64) as usize;
        first..(first + 5).min(count)
    }

    /// Leg `leg`'s pitch error at encoder length `q`, mm: the same sum as over
    /// [`PitchCurves::basis_at`], over the functions non-zero at `q` alone. Allocation-free.
    #[inline]
    pub fn error(&self, leg: usize, q: f64) -> f64 {
        if self.basis() == 0 {
            return 0.0;
        }
        let (spacing, t) = self.position(q);
        let min = self.stroke[0];
        let coefficients = &self.coefficients[leg];
        // The argument as `basis_at` computes it, for the same bits.
        self.supporting(t)
            .map(|j| {
                cubic_b_spline((q - (min + (j as f64 - 1.0) * spacing)) / spacing) * coefficients[j]
            })
            .sum()
    }

    /// Leg `leg`'s pitch error (mm) and its slope (mm per mm) at encoder length `q`, from the
    /// four functions non-zero there in the uniform B-spline's matrix form (to rounding the
    /// same as [`PitchCurves::error`], and its derivative, with no division).
    /// Allocation-free.
    #[inline(always)]
    fn error_and_slope(&self, leg: usize, q: f64, inverse_spacing: f64) -> (f64, f64) {
        let coefficients = &self.coefficients[leg];
        let count = coefficients.len();
        if count == 0 {
            return (0.0, 0.0);
        }
        // Function j is centred on knot j − 1; between knots k − 1 and k the non-zero ones are
        // k − 1 … k + 2, weighted by the cubic pieces of the offset f past knot k − 1.
        let u = (q - self.stroke[0]) * inverse_spacing + 1.0;
        // `floor` by a cast (the baseline x86-64 target calls the C library's `floor`).
        let truncated = u as i64 as f64;
        let k = if truncated > u {
            truncated - 1.0
        } else {
            truncated
        };
        let f = u - k;
        // Coefficient k − 1 + d, zero beyond the curve's (a NaN or huge `q` reads none).
        let first = k - 1.0;
        let coefficient = |d: f64| {
            let j = first + d;
            if j >= 0.0 && j < count as f64 {
                coefficients[j as usize]
            } else {
                0.0
            }
        };
        let (c0, c1, c2, c3) = (
            coefficient(0.0),
            coefficient(1.0),
            coefficient(2.0),
            coefficient(3.0),
        );
        let (f2, f3) = (f * f, f * f * f);
        let g = 1.0 - f;
        // A sixth as a product: a division would be most of the evaluation's latency.
        const SIXTH: f64 = 1.0 / 6.0;
        let error = (g * g * g * c0
            + (3.0 * f3 - 6.0 * f2 + 4.0) * c1
            + (-3.0 * f3 + 3.0 * f2 + 3.0 * f + 1.0) * c2
            + f3 * c3)
            * SIXTH;
        let slope = (-0.5 * g * g * c0
            + (1.5 * f2 - 2.0 * f) * c1
            + (-1.5 * f2 + f + 0.5) * c2
            + 0.5 * f2 * c3)
            * inverse_spacing;
        (error, slope)
    }

    /// The encoder lengths `q` whose unloaded lengths `q_i + p_i(q_i)` are `unloaded`, mm, by
    /// Newton's method from `u − p(u) + p'(u)·p(u)` (the fixed point `q = u − p(q)` to second
    /// order, within about 1e-4 mm for lead-screw errors of tenths of a millimetre), the six
    /// legs in step so that their steps overlap in the pipeline. Each step squares the error,
    /// scaled by the curve's curvature over `2(1 + p')` (about 1e-3 per mm over knots 10–30 mm
    /// apart): two steps leave far below 1e-12 mm. Allocation-free.
    #[inline]
    pub fn inverse(&self, unloaded: &[f64; LEGS]) -> [f64; LEGS] {
        if self.basis() == 0 {
            return *unloaded;
        }
        let (spacing, _) = self.position(unloaded[0]);
        let inverse_spacing = 1.0 / spacing;
        let mut q = [0.0; LEGS];
        for (i, q) in q.iter_mut().enumerate() {
            let (error, slope) = self.error_and_slope(i, unloaded[i], inverse_spacing);
            *q = unloaded[i] - error + slope * error;
        }
        for _ in 0..NEWTON_STEPS {
            for (i, q) in q.iter_mut().enumerate() {
                let (error, slope) = self.error_and_slope(i, *q, inverse_spacing);
                *q -= (*q + error - unloaded[i]) / (1.0 + slope);
            }
        }
        q
    }

    /// Checks that the curves have the same number of coefficients (none, or four or more), all
    /// finite, over a finite stroke.
    fn validate(&self) -> Result<()> {
        let [min, max] = self.stroke;
        let basis = self.basis();
        if !(min.is_finite() && max.is_finite() && min < max) {
            return Err(Error::InvalidModel(format!(
                "lead-screw curves over the stroke [{min}, {max}] mm"
            )));
        }
        if basis != 0 && basis < 4 {
            return Err(Error::InvalidModel(format!(
                "lead-screw curves of {basis} coefficients (none, or 4 or more)"
            )));
        }
        for (leg, c) in self.coefficients.iter().enumerate() {
            if c.len() != basis || c.iter().any(|v| !v.is_finite()) {
                return Err(Error::InvalidModel(format!(
                    "leg {}'s lead-screw curve: {} coefficients, {basis} finite ones expected",
                    leg + 1,
                    c.len()
                )));
            }
        }
        Ok(())
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

/// Each leg's compression under each unit wrench `w_m` (mm per unit of the wrench's compliance
/// coefficient) for the force Jacobian `w` (by rows) at a pose of rotation `rotation`; zero at a
/// singular pose.
fn compressions(w: [[f64; LEGS]; LEGS], rotation: &glam::DMat3) -> [[f64; COMPLIANCE_TERMS]; LEGS] {
    // The weight pulls along −z; a centre of mass along platform axis m adds the moment
    // (R·e_m) × (−z). Column m is −w_m, solved for all four at once.
    let mut wrenches = [[0.0; COMPLIANCE_TERMS]; LEGS];
    wrenches[2][0] = 1.0;
    for (m, axis) in DVec3::AXES.iter().enumerate() {
        let arm = *rotation * *axis;
        wrenches[3][m + 1] = arm.y;
        wrenches[4][m + 1] = -arm.x;
    }
    solve_six(w, wrenches).unwrap_or([[0.0; COMPLIANCE_TERMS]; LEGS])
}

/// `X` with `A·X = B` for a 6 × 6 `A` (rows) and four right-hand sides, by Gaussian
/// elimination with partial pivoting (a sixth of nalgebra's generic LU's time here); `None`
/// where a pivot is zero or not finite (a singular pose). Allocation-free.
fn solve_six(
    mut a: [[f64; LEGS]; LEGS],
    mut b: [[f64; COMPLIANCE_TERMS]; LEGS],
) -> Option<[[f64; COMPLIANCE_TERMS]; LEGS]> {
    for col in 0..LEGS {
        let pivot = (col..LEGS).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        a.swap(col, pivot);
        b.swap(col, pivot);
        let p = a[col][col];
        if p == 0.0 || !p.is_finite() {
            return None;
        }
        let inverse_pivot = 1.0 / p;
        let (pivot_a, pivot_b) = (a[col], b[col]);
        for (a_row, b_row) in a.iter_mut().zip(b.iter_mut()).skip(col + 1) {
            let factor = a_row[col] * inverse_pivot;
            for (value, above) in a_row.iter_mut().zip(pivot_a).skip(col) {
                *value -= factor * above;
            }
            for (value, above) in b_row.iter_mut().zip(pivot_b) {
                *value -= factor * above;
            }
        }
    }
    let mut x = [[0.0; COMPLIANCE_TERMS]; LEGS];
    for row in (0..LEGS).rev() {
        let inverse_diagonal = 1.0 / a[row][row];
        for m in 0..COMPLIANCE_TERMS {
            let known: f64 = (row + 1..LEGS).map(|k| a[row][k] * x[k][m]).sum();
            x[row][m] = (b[row][m] - known) * inverse_diagonal;
        }
    }
    Some(x)
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
        let rotation = pose.rotation();
        let (_, w) = self.legs_at(pose, &rotation);
        let compressions = compressions(w, &rotation);
        let middle = 0.5 * (self.geometry.leg_range[0] + self.geometry.leg_range[1]);
        std::array::from_fn(|i| std::array::from_fn(|m| compressions[i][m] * unloaded[i] / middle))
    }

    /// The geometry's legs at `pose` (whose rotation matrix is `rotation`): each leg's length
    /// as [`inverse_kinematics`] gives it (mm), and the force Jacobian `W` by rows (Eq. 3:
    /// column `i` leg `i`'s unit wrench, the moment about `A` in mm), from the same leg
    /// vectors.
    fn legs_at(&self, pose: &Pose, rotation: &glam::DMat3) -> ([f64; LEGS], [[f64; LEGS]; LEGS]) {
        let g = &self.geometry;
        let mut lengths = [0.0; LEGS];
        let mut w = [[0.0; LEGS]; LEGS];
        for i in 0..LEGS {
            let lever = *rotation * g.platform_joints[i];
            let leg = pose.position + lever - g.base_joints[i];
            let length = leg.length();
            lengths[i] = length - g.leg_offsets[i];
            let s = leg / length;
            let m = lever.cross(s);
            for (row, value) in [s.x, s.y, s.z, m.x, m.y, m.z].into_iter().enumerate() {
                w[row][i] = value;
            }
        }
        (lengths, w)
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
    /// inverted. The sag is linear in the unloaded length (`sag_i = k_i · u_i` at a given
    /// pose), so the unloaded length is `loaded_i / (1 − k_i)`, in closed form. Allocation-free.
    pub fn command(&self, pose: &Pose) -> [f64; LEGS] {
        let rotation = pose.rotation();
        let (loaded, w) = self.legs_at(pose, &rotation);
        let unloaded: [f64; LEGS] = if self.compliant() {
            let compressions = compressions(w, &rotation);
            let middle = 0.5 * (self.geometry.leg_range[0] + self.geometry.leg_range[1]);
            std::array::from_fn(|i| {
                let k: f64 = (0..COMPLIANCE_TERMS)
                    .map(|m| self.compliance[i][m] * compressions[i][m])
                    .sum::<f64>()
                    / middle;
                loaded[i] / (1.0 - k)
            })
        } else {
            loaded
        };
        self.pitch.inverse(&unloaded)
    }

    /// Checks the curves and that every compliance coefficient is finite.
    pub fn validate(&self) -> Result<()> {
        self.pitch.validate()?;
        if self.compliance.iter().flatten().any(|c| !c.is_finite()) {
            return Err(Error::InvalidModel(
                "a compliance coefficient is not finite".into(),
            ));
        }
        Ok(())
    }
}

/// A physical model as the model file carries it: the identified machine and the nominal
/// geometry the NC commands with, its corrections `Δq = c(x) − q(x)` at every pose `x` (`c` the
/// model's [`PhysicalModel::command`], `q` the nominal inverse kinematics).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(from = "PhysicalFile", into = "PhysicalFile")]
pub struct PhysicalCorrections {
    /// The nominal geometry (its joints, offsets and stroke; the model's fingerprint is its).
    nominal: Geometry,
    /// The identified machine.
    machine: PhysicalModel,
}

/// Newton steps of the forward kinematics at most, and the leg residual they stop at, mm.
const FORWARD_STEPS: usize = 12;
const FORWARD_TOLERANCE_MM: f64 = 1e-10;

impl PhysicalCorrections {
    /// `machine`'s corrections for the NC's `nominal` geometry; refuses a machine whose curves
    /// or compliance are malformed.
    pub fn new(nominal: &Geometry, machine: PhysicalModel) -> Result<Self> {
        machine.validate()?;
        Ok(Self {
            nominal: legs_of(nominal),
            machine: PhysicalModel {
                geometry: legs_of(&machine.geometry),
                ..machine
            },
        })
    }

    /// Checks the machine's curves and compliance, and that both geometries' numbers are
    /// finite with a stroke (the model file's reader checks every model it returns).
    pub fn validate(&self) -> Result<()> {
        for geometry in [&self.nominal, &self.machine.geometry] {
            LegGeometry::of(geometry).check()?;
        }
        self.machine.validate()
    }

    /// The identified machine.
    pub fn machine(&self) -> &PhysicalModel {
        &self.machine
    }

    /// The fingerprint of the nominal geometry the corrections are for.
    pub fn nominal_fingerprint(&self) -> crate::geometry::Fingerprint {
        self.nominal.fingerprint()
    }

    /// An estimate of how fast a correction changes with the legs, mm per mm: the lead-screw
    /// curves' steepest slope bounded (a cubic B-spline's slope lies within its neighbouring
    /// coefficients' largest difference over the knot spacing), plus the identified joints'
    /// displacement from the nominal ones over the shortest leg, which is the order of how far
    /// the geometry tilts a leg's length against the nominal one (well under 1e-2 for a
    /// calibrated machine).
    pub fn max_slope(&self) -> f64 {
        let pitch = &self.machine.pitch;
        let spacing = (pitch.stroke[1] - pitch.stroke[0]) / (pitch.basis().max(4) - 3) as f64;
        let curves = pitch
            .coefficients
            .iter()
            .flat_map(|c| c.windows(2).map(|w| (w[1] - w[0]).abs()))
            .fold(0.0, f64::max)
            / spacing;
        let (nominal, machine) = (&self.nominal, &self.machine.geometry);
        let moved = (0..LEGS)
            .map(|i| {
                (machine.base_joints[i] - nominal.base_joints[i]).length()
                    + (machine.platform_joints[i] - nominal.platform_joints[i]).length()
            })
            .fold(0.0, f64::max);
        curves + moved / nominal.leg_range[0].max(1.0)
    }

    /// The corrections (mm) at `pose`, whose nominal legs are `nominal_legs` (mm).
    /// Allocation-free.
    #[inline]
    pub fn at_pose(&self, pose: &Pose, nominal_legs: &[f64; LEGS]) -> [f64; LEGS] {
        let command = self.machine.command(pose);
        std::array::from_fn(|i| command[i] - nominal_legs[i])
    }

    /// The corrections (mm) at nominal legs `q` (mm): the pose they place the nominal geometry
    /// at (Newton's method from the home pose), then [`PhysicalCorrections::at_pose`]. NaN
    /// where that pose cannot be found (singular, or no convergence). Allocation-free.
    pub fn at_legs(&self, q: &[f64; LEGS]) -> [f64; LEGS] {
        match self.nominal_pose(q) {
            Some(pose) => self.at_pose(&pose, q),
            None => [f64::NAN; LEGS],
        }
    }

    /// The pose whose nominal legs are `q` (mm), by Newton's method from the home pose.
    fn nominal_pose(&self, q: &[f64; LEGS]) -> Option<Pose> {
        let mut pose = self.nominal.home_pose();
        for _ in 0..FORWARD_STEPS {
            let current = inverse_kinematics(&self.nominal, &pose).lengths;
            let residual: [f64; LEGS] = std::array::from_fn(|i| q[i] - current[i]);
            if residual.iter().all(|r| r.abs() <= FORWARD_TOLERANCE_MM) {
                return Some(pose);
            }
            let w = ActuationScrews::at(&self.nominal, &pose).force_jacobian();
            let xi = w
                .transpose()
                .lu()
                .solve(&Vector6::from_column_slice(&residual))?;
            pose = pose.displaced(&crate::pose::Twist::from_array([
                xi[0], xi[1], xi[2], xi[3], xi[4], xi[5],
            ]));
            if !pose.is_finite() {
                return None;
            }
        }
        None
    }
}

/// `geometry` without its name and fiducials, what the model file stores of it (its
/// fingerprint is `geometry`'s).
fn legs_of(geometry: &Geometry) -> Geometry {
    Geometry {
        name: String::new(),
        fiducials: Vec::new(),
        ..geometry.clone()
    }
}

/// A geometry in the model file: all that its fingerprint covers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct LegGeometry {
    base_joints: [[f64; 3]; LEGS],
    platform_joints: [[f64; 3]; LEGS],
    leg_range: [f64; 2],
    leg_offsets: [f64; LEGS],
    home: [f64; 6],
    targets: Vec<[f64; 3]>,
    workspace: Workspace,
}

impl LegGeometry {
    fn of(geometry: &Geometry) -> Self {
        Self {
            base_joints: geometry.base_joints.map(|v| v.to_array()),
            platform_joints: geometry.platform_joints.map(|v| v.to_array()),
            leg_range: geometry.leg_range,
            leg_offsets: geometry.leg_offsets,
            home: geometry.home,
            targets: geometry.targets.iter().map(|p| p.to_array()).collect(),
            workspace: geometry.workspace,
        }
    }

    /// Checks that every number is finite and the stroke not empty.
    fn check(&self) -> Result<()> {
        let numbers = self
            .base_joints
            .iter()
            .chain(&self.platform_joints)
            .flatten()
            .chain(&self.leg_range)
            .chain(&self.leg_offsets)
            .chain(&self.home)
            .chain(self.targets.iter().flatten());
        if numbers.into_iter().any(|v| !v.is_finite()) || self.leg_range[0] >= self.leg_range[1] {
            return Err(Error::InvalidModel(
                "the physical model's geometry has a number that is not finite or an empty \
                 stroke"
                    .into(),
            ));
        }
        Ok(())
    }

    fn geometry(&self) -> Geometry {
        Geometry {
            name: String::new(),
            base_joints: self.base_joints.map(DVec3::from_array),
            platform_joints: self.platform_joints.map(DVec3::from_array),
            leg_range: self.leg_range,
            leg_offsets: self.leg_offsets,
            home: self.home,
            targets: self
                .targets
                .iter()
                .copied()
                .map(DVec3::from_array)
                .collect(),
            workspace: self.workspace,
            fiducials: Vec::new(),
        }
    }
}

/// [`PhysicalCorrections`] as the model file stores it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct PhysicalFile {
    nominal: LegGeometry,
    machine: LegGeometry,
    pitch: PitchCurves,
    compliance: [[f64; COMPLIANCE_TERMS]; LEGS],
}

impl From<PhysicalCorrections> for PhysicalFile {
    fn from(c: PhysicalCorrections) -> Self {
        Self {
            nominal: LegGeometry::of(&c.nominal),
            machine: LegGeometry::of(&c.machine.geometry),
            pitch: c.machine.pitch,
            compliance: c.machine.compliance,
        }
    }
}

impl From<PhysicalFile> for PhysicalCorrections {
    fn from(file: PhysicalFile) -> Self {
        Self {
            nominal: file.nominal.geometry(),
            machine: PhysicalModel {
                geometry: file.machine.geometry(),
                pitch: file.pitch,
                compliance: file.compliance,
            },
        }
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

    /// A machine like the virtual platform's: joints moved by tenths of a millimetre, curves of
    /// a few hundredths, compliance of its size.
    fn known_machine() -> (Geometry, PhysicalModel) {
        let nominal = Geometry::prototype();
        let mut machine = PhysicalModel::geometric(nominal.clone());
        for (i, joint) in machine.geometry.base_joints.iter_mut().enumerate() {
            *joint += DVec3::new(0.1, -0.05, 0.02) * (i as f64 - 2.5);
        }
        machine.geometry.leg_offsets = [0.3, -0.2, 0.1, 0.4, -0.5, 0.2];
        machine.pitch = PitchCurves::zero(nominal.leg_range, 12);
        for (i, c) in machine.pitch.coefficients.iter_mut().enumerate() {
            for (j, v) in c.iter_mut().enumerate() {
                *v = 0.05 * ((i * 12 + j) as f64).sin();
            }
        }
        machine.compliance = std::array::from_fn(|i| {
            let k = 0.3 * (1.0 + 0.1 * i as f64);
            [k, 15.0 * k, -10.0 * k, 60.0 * k]
        });
        (nominal, machine)
    }

    #[test]
    fn a_steep_curve_is_inverted_to_rounding() {
        // Half a millimetre of lead-screw error over 16 coefficients: a slope up to about 0.1.
        let (nominal, _) = known_machine();
        let mut curves = PitchCurves::zero(nominal.leg_range, 16);
        for (i, c) in curves.coefficients.iter_mut().enumerate() {
            for (j, v) in c.iter_mut().enumerate() {
                *v = 0.5 * ((i * 16 + j) as f64 * 1.7).sin();
            }
        }
        let [min, max] = nominal.leg_range;
        for k in 0..=600 {
            let u = min + (max - min) * k as f64 / 600.0;
            let q = curves.inverse(&[u; LEGS]);
            for (leg, q) in q.iter().enumerate() {
                assert!(
                    (q + curves.error(leg, *q) - u).abs() < 1e-11,
                    "leg {leg} at {u}"
                );
            }
        }
    }

    #[test]
    fn a_curves_error_is_its_whole_basis_sum_and_its_slope_and_inverse_hold() {
        let (nominal, machine) = known_machine();
        let curves = &machine.pitch;
        let [min, max] = nominal.leg_range;
        for k in -20..=320 {
            let q = min + (max - min) * k as f64 / 300.0;
            for leg in 0..LEGS {
                // The same bits as the sum over every basis function, inside the stroke and out.
                let whole: f64 = curves
                    .basis_at(q)
                    .iter()
                    .zip(&curves.coefficients[leg])
                    .map(|(b, c)| b * c)
                    .sum();
                assert_eq!(curves.error(leg, q), whole, "leg {leg} at {q}");
                // The serving evaluation: the same error to rounding, and its slope against a
                // central difference (step 1e-4 mm: truncation ~1e-10).
                let (spacing, _) = curves.position(q);
                let (error, slope) = curves.error_and_slope(leg, q, 1.0 / spacing);
                assert!(
                    (error - whole).abs() < 1e-15,
                    "leg {leg} at {q}: {error} {whole}"
                );
                let h = 1e-4;
                let difference = (curves.error(leg, q + h) - curves.error(leg, q - h)) / (2.0 * h);
                assert!(
                    (slope - difference).abs() < 1e-8,
                    "leg {leg} at {q}: {slope} against {difference}"
                );
                // The inverse lands on the unloaded length.
                let inverse = curves.inverse(&[q; LEGS])[leg];
                assert!(
                    (inverse + curves.error(leg, inverse) - q).abs() < 1e-11,
                    "leg {leg} at {q}"
                );
            }
        }
    }

    #[test]
    fn the_corrections_from_the_legs_are_those_from_the_pose() {
        let (nominal, machine) = known_machine();
        let corrections = PhysicalCorrections::new(&nominal, machine.clone()).unwrap();
        for pose in [
            nominal.home_pose(),
            Pose::from_mm_deg([12.0, -8.0, 330.0, 3.0, -2.0, 4.0]),
            Pose::from_mm_deg([-40.0, 30.0, 300.0, -5.0, 4.0, -10.0]),
        ] {
            let q = inverse_kinematics(&nominal, &pose).lengths;
            let from_pose = corrections.at_pose(&pose, &q);
            let from_legs = corrections.at_legs(&q);
            let command = machine.command(&pose);
            for i in 0..LEGS {
                assert_eq!(from_pose[i], command[i] - q[i]);
                assert!(
                    (from_legs[i] - from_pose[i]).abs() < 1e-9,
                    "leg {i}: {from_legs:?} {from_pose:?}"
                );
                assert!(from_pose[i].abs() > 0.01, "leg {i}: a correction");
            }
        }
        // Legs no pose of the nominal geometry has: no corrections rather than wrong ones.
        assert!(corrections.at_legs(&[1.0; LEGS]).iter().all(|c| c.is_nan()));
    }

    /// A physical model's model file.
    fn model_file(nominal: &Geometry, machine: PhysicalModel) -> crate::model::Model {
        let q = inverse_kinematics(nominal, &nominal.home_pose()).lengths;
        crate::model::Model {
            networks: crate::model::Networks::Physical(Box::new(
                PhysicalCorrections::new(nominal, machine).unwrap(),
            )),
            input: crate::model::NetworkInput::Equivalent,
            normalisation: crate::network::Normalisation::of(&[q, q.map(|v| v + 1.0)]).unwrap(),
            training_range: [nominal.leg_range; LEGS],
            correction_bounds: [[-1.0, 1.0]; LEGS],
            geometry: nominal.fingerprint(),
            provenance: Default::default(),
            uncertainty: None,
        }
    }

    #[test]
    fn a_physical_model_file_is_version_3_reads_back_whole_and_refuses_a_bad_model() {
        use crate::error::ModelFileProblem;
        use crate::model::Model;
        let (nominal, machine) = known_machine();
        let model = model_file(&nominal, machine.clone());
        assert_eq!(model.format_version(), 3);
        let bytes = model.to_bytes();
        assert_eq!(u16::from_le_bytes([bytes[8], bytes[9]]), 3);
        assert_eq!(Model::from_bytes(&bytes).unwrap(), model);
        // A coefficient that is not finite is refused by the reader.
        let mut bad = machine.clone();
        bad.pitch.coefficients[2][3] = f64::NAN;
        let mut file = model.clone();
        file.networks = crate::model::Networks::Physical(Box::new(PhysicalCorrections {
            nominal: legs_of(&nominal),
            machine: bad,
        }));
        assert!(matches!(
            Model::from_bytes(&file.to_bytes()),
            Err(ModelFileProblem::Corrupt(why)) if why.contains("lead-screw")
        ));
        // Bound to another geometry than its nominal one: refused.
        let mut other = model.clone();
        other.geometry = crate::geometry::Fingerprint(1);
        assert!(other.validate().is_err());
        // A physical model in a version-2 file (which earlier builds read as networks): refused.
        let mut relabelled = bytes.clone();
        relabelled[8..10].copy_from_slice(&2u16.to_le_bytes());
        let body = relabelled.len() - 8;
        let checksum = crc::Crc::<u64>::new(&crc::CRC_64_XZ).checksum(&relabelled[..body]);
        relabelled[body..].copy_from_slice(&checksum.to_le_bytes());
        assert!(Model::from_bytes(&relabelled).is_err());
    }
}
