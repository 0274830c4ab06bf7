//! Platform poses and the orientation convention.
//!
//! A pose places the platform frame `K_A` (origin: platform centre `A`) in the base frame `K_B`
//! (origin `B`: centre of the base joint plane, z up). Orientation is the roll–pitch–yaw sequence of
//! LinuxCNC's hexapod kinematics (genhexkins): `R = Rz(c)·Ry(b)·Rx(a)`.
//!
//! Units: millimetres for positions; radians inside the code, degrees only at the file/CLI boundary
//! ([`Pose::from_mm_deg`], [`Pose::to_mm_deg`]).

use glam::{DMat3, DVec3};

/// A platform pose: position of `A` in `K_B` (mm) and roll/pitch/yaw angles (rad).
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct Pose {
    /// Position of the platform centre `A` in the base frame, mm.
    pub position: DVec3,
    /// `(a, b, c)`: rotations about x, y, z in rad, composed as `Rz(c)·Ry(b)·Rx(a)`.
    pub angles: DVec3,
}

/// The small displacement that takes one pose to another, expressed about point `A` in axes
/// parallel to `K_B` (the paper's frame `K'_A`): the pose-error twist `ξ_t = (δ_A, ε)` of Eq. 2.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Twist {
    /// Translation of `A`, mm (`δ_A`).
    pub translation: DVec3,
    /// Rotation vector in base-frame axes, rad (`ε`): axis × angle.
    pub rotation: DVec3,
}

impl Twist {
    /// The twist as the 6-vector `(δ_A, ε)` used by the paper's matrices.
    pub fn to_array(&self) -> [f64; 6] {
        let (t, r) = (self.translation, self.rotation);
        [t.x, t.y, t.z, r.x, r.y, r.z]
    }

    /// Builds a twist from the 6-vector `(δ_A [mm], ε [rad])`.
    pub fn from_array(v: [f64; 6]) -> Self {
        Self {
            translation: DVec3::new(v[0], v[1], v[2]),
            rotation: DVec3::new(v[3], v[4], v[5]),
        }
    }
}

impl Pose {
    /// A pose from a position (mm) and roll/pitch/yaw angles (rad).
    pub const fn new(position: DVec3, angles: DVec3) -> Self {
        Self { position, angles }
    }

    /// A pose from the file/CLI convention `[x, y, z, a, b, c]` in mm and degrees.
    pub fn from_mm_deg(v: [f64; 6]) -> Self {
        Self {
            position: DVec3::new(v[0], v[1], v[2]),
            angles: DVec3::new(v[3].to_radians(), v[4].to_radians(), v[5].to_radians()),
        }
    }

    /// The pose as `[x, y, z, a, b, c]` in mm and degrees.
    pub fn to_mm_deg(&self) -> [f64; 6] {
        let (p, a) = (self.position, self.angles);
        [
            p.x,
            p.y,
            p.z,
            a.x.to_degrees(),
            a.y.to_degrees(),
            a.z.to_degrees(),
        ]
    }

    /// True when every component is finite.
    pub fn is_finite(&self) -> bool {
        self.position.is_finite() && self.angles.is_finite()
    }

    /// The rotation matrix `R = Rz(c)·Ry(b)·Rx(a)` taking platform-frame vectors to base-frame axes.
    #[inline]
    pub fn rotation(&self) -> DMat3 {
        DMat3::from_rotation_z(self.angles.z)
            * DMat3::from_rotation_y(self.angles.y)
            * DMat3::from_rotation_x(self.angles.x)
    }

    /// The pose with position `position` (mm) and orientation `rotation`, angles recovered in the
    /// branch `b ∈ [-90°, 90°]`, `a, c ∈ (-180°, 180°]`.
    pub fn from_rotation(position: DVec3, rotation: &DMat3) -> Self {
        // Element (row r, column k) of a column-major glam matrix is `col(k)[r]`.
        let r00 = rotation.x_axis.x;
        let r10 = rotation.x_axis.y;
        let r20 = rotation.x_axis.z;
        let r21 = rotation.y_axis.z;
        let r22 = rotation.z_axis.z;
        let b = (-r20).atan2((r00 * r00 + r10 * r10).sqrt());
        let a = r21.atan2(r22);
        let c = r10.atan2(r00);
        Self::new(position, DVec3::new(a, b, c))
    }

    /// A platform-frame point (mm) expressed in the base frame (mm): `t + R·p`.
    #[inline]
    pub fn transform_point(&self, platform_point: DVec3) -> DVec3 {
        self.position + self.rotation() * platform_point
    }

    /// The inverse transform: the pose of the base frame in this pose's frame, so that
    /// `inverse().transform_point(transform_point(p)) = p`.
    pub fn inverse(&self) -> Self {
        let rotation = self.rotation().transpose();
        Self::from_rotation(-(rotation * self.position), &rotation)
    }

    /// This pose displaced by a small twist: `t + δ_A`, `exp([ε×])·R` (rotation about `A` in
    /// base-frame axes).
    pub fn displaced(&self, twist: &Twist) -> Self {
        let rotation = rotation_from_vector(twist.rotation) * self.rotation();
        Self::from_rotation(self.position + twist.translation, &rotation)
    }

    /// The twist that takes `self` to `other` (the pose-error twist `ξ_t = (δ_A, ε)` of Eq. 2 when
    /// `other` is the reached pose): `δ_A = t_other − t_self`,
    /// `ε = log(R_other·R_selfᵀ)` in base-frame axes. Exact for any size, not only small ones.
    pub fn twist_to(&self, other: &Pose) -> Twist {
        let relative = other.rotation() * self.rotation().transpose();
        Twist {
            translation: other.position - self.position,
            rotation: rotation_vector(&relative),
        }
    }
}

/// The rotation matrix of a rotation vector (axis × angle, rad): Rodrigues' formula.
pub fn rotation_from_vector(v: DVec3) -> DMat3 {
    let angle = v.length();
    if angle < 1e-300 {
        return DMat3::IDENTITY;
    }
    DMat3::from_axis_angle(v / angle, angle)
}

/// The rotation vector (axis × angle, rad) of a rotation matrix, accurate for small angles too
/// (uses `atan2` of the antisymmetric and symmetric parts, not `acos` of the trace).
pub fn rotation_vector(r: &DMat3) -> DVec3 {
    // vee(R − Rᵀ)/2 = sin θ · axis
    let s = 0.5
        * DVec3::new(
            r.y_axis.z - r.z_axis.y,
            r.z_axis.x - r.x_axis.z,
            r.x_axis.y - r.y_axis.x,
        );
    let sin_angle = s.length();
    let cos_angle = 0.5 * (r.x_axis.x + r.y_axis.y + r.z_axis.z - 1.0);
    let angle = sin_angle.atan2(cos_angle);
    if sin_angle < 1e-12 {
        // θ/sin θ → 1 as θ → 0 (angles near π do not occur for pose errors).
        return s;
    }
    s * (angle / sin_angle)
}

/// How a file's three angles compose a rotation: the convention of the controller that wrote
/// it. Positions (mm) are the same in every convention; angles are degrees in files.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PoseConvention {
    /// LinuxCNC's hexapod kinematics (genhexkins), hexacomp's own: `R = Rz(c)·Ry(b)·Rx(a)`, roll
    /// about x, pitch about y, yaw about z, each about the fixed base axes.
    #[default]
    Linuxcnc,
    /// Physik Instrumente's hexapod controllers: `U` about x, then `V` about the moved y, then `W`
    /// about the moved z, `R = Rx(U)·Ry(V)·Rz(W)`.
    PiUvw,
}

impl PoseConvention {
    /// Every convention, in the order `--help` lists them.
    pub const ALL: [PoseConvention; 2] = [PoseConvention::Linuxcnc, PoseConvention::PiUvw];

    /// The name on the command line and in messages.
    pub fn name(self) -> &'static str {
        match self {
            PoseConvention::Linuxcnc => "linuxcnc",
            PoseConvention::PiUvw => "pi-uvw",
        }
    }

    /// The rotation of the angles `[α, β, γ]` (rad) in this convention.
    fn rotation(self, angles: DVec3) -> DMat3 {
        match self {
            PoseConvention::Linuxcnc => Pose::new(DVec3::ZERO, angles).rotation(),
            PoseConvention::PiUvw => {
                DMat3::from_rotation_x(angles.x)
                    * DMat3::from_rotation_y(angles.y)
                    * DMat3::from_rotation_z(angles.z)
            }
        }
    }

    /// The angles (rad) of `rotation` in this convention, the middle one in [-90°, 90°].
    fn angles(self, rotation: &DMat3) -> DVec3 {
        match self {
            PoseConvention::Linuxcnc => Pose::from_rotation(DVec3::ZERO, rotation).angles,
            PoseConvention::PiUvw => {
                // Element (row r, column k) of a column-major glam matrix is `col(k)[r]`.
                let (r00, r01, r02) = (rotation.x_axis.x, rotation.y_axis.x, rotation.z_axis.x);
                let (r12, r22) = (rotation.z_axis.y, rotation.z_axis.z);
                DVec3::new(
                    (-r12).atan2(r22),
                    r02.atan2((r00 * r00 + r01 * r01).sqrt()),
                    (-r01).atan2(r00),
                )
            }
        }
    }

    /// A pose `[x, y, z, α, β, γ]` (mm, degrees) written in this convention, in LinuxCNC's
    /// `[x, y, z, a, b, c]`; LinuxCNC's own values are returned unchanged.
    pub fn to_linuxcnc(self, values: [f64; 6]) -> [f64; 6] {
        self.convert(values, PoseConvention::Linuxcnc)
    }

    /// A pose in LinuxCNC's `[x, y, z, a, b, c]` (mm, degrees) written in this convention.
    pub fn from_linuxcnc(self, values: [f64; 6]) -> [f64; 6] {
        PoseConvention::Linuxcnc.convert(values, self)
    }

    /// `values` in this convention, expressed in `other`.
    fn convert(self, values: [f64; 6], other: PoseConvention) -> [f64; 6] {
        if self == other {
            return values;
        }
        let angles = DVec3::from_array([values[3], values[4], values[5]].map(f64::to_radians));
        let [a, b, c] = other
            .angles(&self.rotation(angles))
            .to_array()
            .map(f64::to_degrees);
        [values[0], values[1], values[2], a, b, c]
    }
}

impl std::fmt::Display for PoseConvention {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for PoseConvention {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, String> {
        Self::ALL
            .into_iter()
            .find(|c| c.name() == text)
            .ok_or_else(|| {
                let names: Vec<_> = Self::ALL.iter().map(|c| c.name()).collect();
                format!("{text:?} is not a pose convention ({})", names.join(", "))
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The rotation of a pose with angles `[a, b, c]` in degrees.
    fn rotation_deg(a: f64, b: f64, c: f64) -> DMat3 {
        Pose::from_mm_deg([0.0, 0.0, 0.0, a, b, c]).rotation()
    }

    fn assert_turns(r: DMat3, from: DVec3, to: DVec3, what: &str) {
        let got = r * from;
        assert!(
            (got - to).length() < 1e-15,
            "{what}: {from} turned to {got}, expected {to}"
        );
    }

    #[test]
    fn each_angle_turns_the_unit_vectors_right_handed_about_its_own_axis() {
        // Right-handed quarter turns: about x, y → z and z → −y; about y, z → x and x → −z;
        // about z, x → y and y → −x. The rotation axis itself stays put.
        let roll = rotation_deg(90.0, 0.0, 0.0);
        assert_turns(roll, DVec3::X, DVec3::X, "roll");
        assert_turns(roll, DVec3::Y, DVec3::Z, "roll");
        assert_turns(roll, DVec3::Z, -DVec3::Y, "roll");
        let pitch = rotation_deg(0.0, 90.0, 0.0);
        assert_turns(pitch, DVec3::Y, DVec3::Y, "pitch");
        assert_turns(pitch, DVec3::Z, DVec3::X, "pitch");
        assert_turns(pitch, DVec3::X, -DVec3::Z, "pitch");
        let yaw = rotation_deg(0.0, 0.0, 90.0);
        assert_turns(yaw, DVec3::Z, DVec3::Z, "yaw");
        assert_turns(yaw, DVec3::X, DVec3::Y, "yaw");
        assert_turns(yaw, DVec3::Y, -DVec3::X, "yaw");
        // A small angle: sin and cos, not only their values at 90°.
        let (s, c) = 30f64.to_radians().sin_cos();
        assert_turns(
            rotation_deg(30.0, 0.0, 0.0),
            DVec3::Y,
            DVec3::new(0.0, c, s),
            "roll 30°",
        );
        assert_turns(
            rotation_deg(0.0, -30.0, 0.0),
            DVec3::Z,
            DVec3::new(-s, 0.0, c),
            "pitch −30°",
        );
        assert_turns(
            rotation_deg(0.0, 0.0, 30.0),
            DVec3::X,
            DVec3::new(c, s, 0.0),
            "yaw 30°",
        );
    }

    #[test]
    fn roll_acts_first_then_pitch_then_yaw() {
        // R = Rz(c)·Ry(b)·Rx(a): a vector is rolled first, then pitched, then yawed, all about the
        // base axes. Each pair of quarter turns gives a different image in the other order.
        // Roll then yaw: y → z → z (yaw first: y → −x → −x).
        assert_turns(
            rotation_deg(90.0, 0.0, 90.0),
            DVec3::Y,
            DVec3::Z,
            "roll, yaw",
        );
        // Roll then pitch: y → z → x (pitch first: y → y → z).
        assert_turns(
            rotation_deg(90.0, 90.0, 0.0),
            DVec3::Y,
            DVec3::X,
            "roll, pitch",
        );
        // Pitch then yaw: z → x → y (yaw first: z → z → x).
        assert_turns(
            rotation_deg(0.0, 90.0, 90.0),
            DVec3::Z,
            DVec3::Y,
            "pitch, yaw",
        );
        // All three: x → x → −z → −z, and y → z → x → y.
        let all = rotation_deg(90.0, 90.0, 90.0);
        assert_turns(all, DVec3::X, -DVec3::Z, "roll, pitch, yaw");
        assert_turns(all, DVec3::Y, DVec3::Y, "roll, pitch, yaw");
        // And the platform frame's axes are the columns: a point on the platform's x axis
        // lands on R's first column, translated by the position.
        let pose = Pose::from_mm_deg([1.0, 2.0, 3.0, 90.0, 90.0, 90.0]);
        let moved = pose.transform_point(DVec3::new(10.0, 0.0, 0.0));
        assert!(
            (moved - DVec3::new(1.0, 2.0, -7.0)).length() < 1e-14,
            "{moved}"
        );
    }

    #[test]
    fn euler_extraction_round_trips() {
        for v in [
            [1.0, 2.0, 3.0, 12.0, -7.0, 9.5],
            [0.0, 0.0, 0.0, -170.0, 80.0, 179.0],
            [0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        ] {
            let p = Pose::from_mm_deg(v);
            let back = Pose::from_rotation(p.position, &p.rotation());
            assert!(
                (back.angles - p.angles).abs().max_element() < 1e-13,
                "{v:?}"
            );
        }
    }

    #[test]
    fn rotation_vector_inverts_rodrigues() {
        for v in [
            DVec3::new(1e-9, -2e-9, 3e-10),
            DVec3::new(0.1, -0.2, 0.3),
            DVec3::new(1.0, 0.5, -2.0),
        ] {
            let back = rotation_vector(&rotation_from_vector(v));
            assert!((back - v).length() < 1e-15 + 1e-13 * v.length(), "{v:?}");
        }
    }

    #[test]
    fn twist_to_and_displaced_are_inverse() {
        let a = Pose::from_mm_deg([1.0, -2.0, 300.0, 5.0, -3.0, 8.0]);
        let b = Pose::from_mm_deg([1.2, -2.1, 300.3, 5.1, -2.9, 7.7]);
        let back = a.displaced(&a.twist_to(&b));
        assert!((back.position - b.position).length() < 1e-12);
        assert!((back.angles - b.angles).abs().max_element() < 1e-14);
    }
}
