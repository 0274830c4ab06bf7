//! The platform geometry: joint centres, stroke, home pose, measuring targets and task workspace.
//!
//! Read from and written to the geometry TOML of docs/formats.md. Numbers are kept exactly as the file
//! states them (mm and degrees), so that saving and reloading a geometry gives the same
//! [`Fingerprint`].

use std::fmt;
use std::path::Path;

use glam::DVec3;
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::kinematics::{LegStatus, inverse_kinematics};
use crate::pose::Pose;
use crate::screw::ActuationScrews;

/// Number of legs (actuated prismatic joints) of a Stewart platform.
pub const LEGS: usize = 6;
/// The fewest measured target points a geometry names (the paper's `P_1..P_3`); it may name
/// more.
pub const MIN_TARGETS: usize = 3;

/// The task workspace: a vertical cylinder for the position of `A`, a tilt cone and a yaw range.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Workspace {
    /// Cylinder radius of the position of `A` about the base z axis, mm.
    pub radius: f64,
    /// Absolute z range of `A` in the base frame, `[zmin, zmax]`, mm.
    pub z_range: [f64; 2],
    /// Largest angle between the platform normal and the base z axis, degrees.
    pub tilt_max: f64,
    /// Range of the yaw angle `c`, `[cmin, cmax]`, degrees.
    pub yaw_range: [f64; 2],
}

/// A Stewart platform's nominal geometry, as in the geometry TOML of docs/formats.md.
///
/// Leg `i` runs from base joint `B_i` (base frame, mm) to platform joint `A_i` (platform frame,
/// mm); its nominal length is `q_i = |t + R·a_i − b_i|`.
#[derive(Debug, Clone, PartialEq)]
pub struct Geometry {
    /// A human-readable name (not part of the fingerprint).
    pub name: String,
    /// Base joint centres `B_i` in `K_B`, mm.
    pub base_joints: [DVec3; LEGS],
    /// Platform joint centres `A_i` in `K_A`, mm.
    pub platform_joints: [DVec3; LEGS],
    /// Actuator stroke `[min, max]` of every leg, mm (limits of the commanded/encoder length).
    pub leg_range: [f64; 2],
    /// Leg zero offsets `o_i`: real joint-to-joint length minus commanded (encoder) length, mm.
    /// Optional in the TOML (`leg_offsets`, default all zero); a model-based calibration
    /// (`hexacomp-trainer identify`) writes them. Commanded length `q_i = |t + R·a_i − b_i| − o_i`.
    pub leg_offsets: [f64; LEGS],
    /// Home pose `[x, y, z, a, b, c]`, mm and degrees.
    pub home: [f64; 6],
    /// Measured target points `P_1..P_N` in `K_A`, mm; at least [`MIN_TARGETS`], not all on one
    /// line.
    pub targets: Vec<DVec3>,
    /// The task workspace.
    pub workspace: Workspace,
    /// Named fiducials on the machine base in `K_B` (mm), to register an instrument against;
    /// optional in the TOML, not part of the fingerprint (they do not change the kinematics).
    pub fiducials: Vec<Fiducial>,
}

/// A named fiducial on the machine base: a nest or reference point whose base-frame position is
/// known from the drawing or a CMM report.
#[derive(Debug, Clone, PartialEq)]
pub struct Fiducial {
    /// Its name, unique in the geometry; a measured fiducials file uses the same names.
    pub name: String,
    /// Its position in the base frame `K_B`, mm.
    pub position: DVec3,
}

/// One `[[fiducials]]` table of the TOML.
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct FiducialEntry {
    name: String,
    position: [f64; 3],
}

/// A stable 64-bit fingerprint of a geometry's numbers (CRC-64/XZ over their IEEE-754 bits in file
/// order); the name is not included. Models are bound to the fingerprint of their geometry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct Fingerprint(pub u64);

impl fmt::Display for Fingerprint {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:016x}", self.0)
    }
}

/// The TOML layout, with rows as vectors so that a wrong row count is reported by us, by name.
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct GeometryFile {
    name: String,
    base_joints: Vec<[f64; 3]>,
    platform_joints: Vec<[f64; 3]>,
    leg_range: [f64; 2],
    #[serde(default, skip_serializing_if = "all_zero")]
    leg_offsets: [f64; LEGS],
    home: [f64; 6],
    targets: Vec<[f64; 3]>,
    workspace: Workspace,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    fiducials: Vec<FiducialEntry>,
}

fn all_zero(v: &[f64; LEGS]) -> bool {
    v.iter().all(|x| *x == 0.0)
}

/// Parameters of a symmetric 6-6 platform: joints in pairs on two circles, base pairs centred at
/// 0°, 120°, 240°, platform pairs at 60°, 180°, 300°, each leg crossing to the neighbouring pair.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SymmetricLayout {
    /// Radius of the base joint circle, mm.
    pub base_radius: f64,
    /// Radius of the platform joint circle, mm.
    pub platform_radius: f64,
    /// Half the angle between the two joints of a base pair, degrees.
    pub base_half_separation: f64,
    /// Half the angle between the two joints of a platform pair, degrees.
    pub platform_half_separation: f64,
}

impl SymmetricLayout {
    /// Base joint centres `B_i` (z = 0) and platform joint centres `A_i` (z = 0), mm.
    pub fn joints(&self) -> ([DVec3; LEGS], [DVec3; LEGS]) {
        let on_circle = |radius: f64, deg: f64| {
            let (s, c) = deg.to_radians().sin_cos();
            DVec3::new(radius * c, radius * s, 0.0)
        };
        let mut base = [DVec3::ZERO; LEGS];
        let mut platform = [DVec3::ZERO; LEGS];
        for pair in 0..3 {
            let centre = 120.0 * pair as f64;
            let (bs, ps) = (self.base_half_separation, self.platform_half_separation);
            base[2 * pair] = on_circle(self.base_radius, centre - bs);
            base[2 * pair + 1] = on_circle(self.base_radius, centre + bs);
            platform[2 * pair] = on_circle(self.platform_radius, centre - 60.0 + ps);
            platform[2 * pair + 1] = on_circle(self.platform_radius, centre + 60.0 - ps);
        }
        (base, platform)
    }
}

impl Geometry {
    /// The built-in geometry `prototype`, resembling the paper's prototype (Sec. 4.1): base radius
    /// 370 mm, platform radius 250 mm, stroke 280–430 mm, task workspace a φ150 × 100 mm cylinder.
    ///
    /// The paper's ±30° tilt does not fit a 280–430 mm stroke with these radii (checked over pair
    /// separations and home heights), so the tilt limit is 15° and yaw ±10°; the workspace sampler
    /// additionally rejects poses whose legs come within a margin of the stroke ends.
    pub fn prototype() -> Self {
        let layout = SymmetricLayout {
            base_radius: 370.0,
            platform_radius: 250.0,
            base_half_separation: 15.0,
            platform_half_separation: 15.0,
        };
        let (base_joints, platform_joints) = layout.joints();
        let home_z = 280.0;
        let target_radius = 180.0;
        let target = |deg: f64| {
            let (s, c) = f64::to_radians(deg).sin_cos();
            DVec3::new(target_radius * c, target_radius * s, 25.0)
        };
        Self {
            name: "prototype".to_string(),
            base_joints,
            platform_joints,
            leg_range: [280.0, 430.0],
            leg_offsets: [0.0; LEGS],
            home: [0.0, 0.0, home_z, 0.0, 0.0, 0.0],
            targets: vec![target(90.0), target(210.0), target(330.0)],
            workspace: Workspace {
                radius: 75.0,
                z_range: [home_z - 50.0, home_z + 50.0],
                tilt_max: 15.0,
                yaw_range: [-10.0, 10.0],
            },
            // Six nests on a 450 mm circle around the base joints (coordinates as a drawing
            // gives them, to the micrometre), two of them on posts.
            fiducials: [
                [450.0, 0.0, 0.0],
                [225.0, 389.711, 0.0],
                [-225.0, 389.711, 20.0],
                [-450.0, 0.0, 0.0],
                [-225.0, -389.711, 40.0],
                [225.0, -389.711, 0.0],
            ]
            .into_iter()
            .enumerate()
            .map(|(k, position)| Fiducial {
                name: format!("F{}", k + 1),
                position: DVec3::from_array(position),
            })
            .collect(),
        }
    }

    /// Parses and validates a geometry from TOML text.
    pub fn from_toml_str(text: &str) -> Result<Self> {
        let file: GeometryFile =
            toml::from_str(text).map_err(|e| Error::GeometryParse(e.to_string()))?;
        let geometry = Self {
            name: file.name,
            base_joints: rows("base_joints", &file.base_joints)?,
            platform_joints: rows("platform_joints", &file.platform_joints)?,
            leg_range: file.leg_range,
            leg_offsets: file.leg_offsets,
            home: file.home,
            targets: target_rows(&file.targets)?,
            workspace: file.workspace,
            fiducials: file
                .fiducials
                .into_iter()
                .map(|f| Fiducial {
                    name: f.name,
                    position: DVec3::from_array(f.position),
                })
                .collect(),
        };
        geometry.validate()?;
        Ok(geometry)
    }

    /// Reads, parses and validates a geometry TOML file.
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::GeometryIo {
            path: path.display().to_string(),
            message: e.to_string(),
        })?;
        Self::from_toml_str(&text).map_err(|e| match e {
            Error::GeometryParse(m) => Error::GeometryParse(format!("{}: {m}", path.display())),
            Error::InvalidGeometry(m) => Error::InvalidGeometry(format!("{}: {m}", path.display())),
            other => other,
        })
    }

    /// The geometry as TOML text in the layout of docs/formats.md; numbers print exactly (shortest
    /// round-trip form), so [`Geometry::from_toml_str`] gives back an equal geometry.
    pub fn to_toml_string(&self) -> String {
        let to_rows = |v: &[DVec3]| v.iter().map(|p| p.to_array()).collect::<Vec<_>>();
        let file = GeometryFile {
            name: self.name.clone(),
            base_joints: to_rows(&self.base_joints),
            platform_joints: to_rows(&self.platform_joints),
            leg_range: self.leg_range,
            leg_offsets: self.leg_offsets,
            home: self.home,
            targets: to_rows(&self.targets),
            workspace: self.workspace,
            fiducials: self
                .fiducials
                .iter()
                .map(|f| FiducialEntry {
                    name: f.name.clone(),
                    position: f.position.to_array(),
                })
                .collect(),
        };
        toml::to_string(&file).expect("a geometry always serialises to TOML")
    }

    /// Writes the geometry as TOML to `path`, whole or not at all
    /// ([`crate::durable::replace_file`]).
    pub fn save(&self, path: &Path) -> Result<()> {
        crate::durable::replace_file(path, self.to_toml_string().as_bytes()).map_err(|e| {
            Error::GeometryIo {
                path: path.display().to_string(),
                message: e.to_string(),
            }
        })
    }

    /// The home pose (mm, rad).
    pub fn home_pose(&self) -> Pose {
        Pose::from_mm_deg(self.home)
    }

    /// The stable fingerprint of this geometry's numbers (leg offsets included only when any is
    /// non-zero, so files without them keep their fingerprint).
    pub fn fingerprint(&self) -> Fingerprint {
        const CRC: crc::Crc<u64> = crc::Crc::<u64>::new(&crc::CRC_64_XZ);
        let mut digest = CRC.digest();
        let mut put = |x: f64| digest.update(&x.to_le_bytes());
        for p in self.base_joints.iter().chain(&self.platform_joints) {
            p.to_array().into_iter().for_each(&mut put);
        }
        self.leg_range.into_iter().for_each(&mut put);
        // Absent offsets (all zero) leave the fingerprint of files without them unchanged.
        if !all_zero(&self.leg_offsets) {
            self.leg_offsets.into_iter().for_each(&mut put);
        }
        self.home.into_iter().for_each(&mut put);
        for p in &self.targets {
            p.to_array().into_iter().for_each(&mut put);
        }
        let w = &self.workspace;
        [w.radius, w.z_range[0], w.z_range[1], w.tilt_max]
            .into_iter()
            .chain(w.yaw_range)
            .for_each(&mut put);
        Fingerprint(digest.finalize())
    }

    /// Checks that the numbers describe a usable platform; the error names the first problem.
    pub fn validate(&self) -> Result<()> {
        let invalid = |m: String| Err(Error::InvalidGeometry(m));
        check_finite_rows("base_joints", &self.base_joints)?;
        check_finite_rows("platform_joints", &self.platform_joints)?;
        check_finite_rows("targets", &self.targets)?;
        check_finite("leg_range", &self.leg_range)?;
        check_finite("leg_offsets", &self.leg_offsets)?;
        check_finite("home", &self.home)?;
        let w = &self.workspace;
        check_finite("workspace.radius", &[w.radius])?;
        check_finite("workspace.z_range", &w.z_range)?;
        check_finite("workspace.tilt_max", &[w.tilt_max])?;
        check_finite("workspace.yaw_range", &w.yaw_range)?;

        let [min, max] = self.leg_range;
        if !(min > 0.0 && min < max) {
            return invalid(format!(
                "leg_range [{min}, {max}] must satisfy 0 < min < max (mm)"
            ));
        }
        check_legs_distinct(&self.base_joints, &self.platform_joints)?;
        check_targets_not_collinear(&self.targets)?;
        check_fiducials(&self.fiducials)?;
        if w.radius < 0.0 {
            return invalid(format!("workspace.radius {} mm is negative", w.radius));
        }
        if w.z_range[0] > w.z_range[1] {
            return invalid(format!(
                "workspace.z_range [{}, {}] is not ordered",
                w.z_range[0], w.z_range[1]
            ));
        }
        if !(0.0..90.0).contains(&w.tilt_max) {
            return invalid(format!(
                "workspace.tilt_max {}° must lie in [0°, 90°)",
                w.tilt_max
            ));
        }
        if w.yaw_range[0] > w.yaw_range[1] || w.yaw_range[1] - w.yaw_range[0] >= 360.0 {
            return invalid(format!(
                "workspace.yaw_range [{}, {}] must be ordered and narrower than 360°",
                w.yaw_range[0], w.yaw_range[1]
            ));
        }
        self.check_home()
    }

    fn check_home(&self) -> Result<()> {
        let legs = inverse_kinematics(self, &self.home_pose());
        let outside: Vec<String> = legs
            .status
            .iter()
            .enumerate()
            .filter(|(_, s)| **s != LegStatus::Ok)
            .map(|(i, _)| format!("leg {} = {:.3} mm", i + 1, legs.lengths[i]))
            .collect();
        if !outside.is_empty() {
            return Err(Error::InvalidGeometry(format!(
                "home pose {:?} puts legs outside the stroke [{}, {}] mm: {}",
                self.home,
                self.leg_range[0],
                self.leg_range[1],
                outside.join(", ")
            )));
        }
        let ratio = ActuationScrews::at(self, &self.home_pose()).singular_value_ratio();
        if ratio < 1e-6 {
            return Err(Error::InvalidGeometry(format!(
                "the platform is singular at the home pose (σ_min/σ_max of W = {ratio:.3e})"
            )));
        }
        Ok(())
    }
}

fn rows<const N: usize>(field: &str, v: &[[f64; 3]]) -> Result<[DVec3; N]> {
    if v.len() != N {
        return Err(Error::InvalidGeometry(format!(
            "{field} has {} rows, expected {N}",
            v.len()
        )));
    }
    Ok(std::array::from_fn(|i| DVec3::from_array(v[i])))
}

/// Fiducials need a name, unique, and finite coordinates.
fn check_fiducials(fiducials: &[Fiducial]) -> Result<()> {
    for (k, fiducial) in fiducials.iter().enumerate() {
        if fiducial.name.trim().is_empty() {
            return Err(Error::InvalidGeometry(format!(
                "fiducials[{k}] has an empty name"
            )));
        }
        if fiducials[..k].iter().any(|f| f.name == fiducial.name) {
            return Err(Error::InvalidGeometry(format!(
                "fiducial {:?} is named twice",
                fiducial.name
            )));
        }
        check_finite(
            &format!("fiducial {:?} position", fiducial.name),
            &fiducial.position.to_array(),
        )?;
    }
    Ok(())
}

/// The `targets` rows: at least [`MIN_TARGETS`].
fn target_rows(v: &[[f64; 3]]) -> Result<Vec<DVec3>> {
    if v.len() < MIN_TARGETS {
        return Err(Error::InvalidGeometry(format!(
            "targets has {} rows, at least {MIN_TARGETS} are needed",
            v.len()
        )));
    }
    Ok(v.iter().copied().map(DVec3::from_array).collect())
}

fn check_finite(field: &str, v: &[f64]) -> Result<()> {
    match v.iter().position(|x| !x.is_finite()) {
        Some(i) if v.len() > 1 => Err(Error::InvalidGeometry(format!(
            "{field}[{i}] is {}, expected a finite number",
            v[i]
        ))),
        Some(_) => Err(Error::InvalidGeometry(format!(
            "{field} is {}, expected a finite number",
            v[0]
        ))),
        None => Ok(()),
    }
}

fn check_finite_rows(field: &str, v: &[DVec3]) -> Result<()> {
    for (row, p) in v.iter().enumerate() {
        check_finite(&format!("{field}[{row}]"), &p.to_array())?;
    }
    Ok(())
}

/// Rejects two legs between the same pair of joint centres (closer than 1 nm). Legs may share one
/// joint centre: 3-3 and 6-3 platforms (LinuxCNC's hexapod sim among them) pair their legs so.
fn check_legs_distinct(base: &[DVec3; LEGS], platform: &[DVec3; LEGS]) -> Result<()> {
    for i in 0..LEGS {
        for j in i + 1..LEGS {
            if base[i].distance(base[j]) < 1e-6 && platform[i].distance(platform[j]) < 1e-6 {
                return Err(Error::InvalidGeometry(format!(
                    "legs {i} and {j} join the same base and platform joint centres"
                )));
            }
        }
    }
    Ok(())
}

/// Rejects targets that lie on one line: for some pair of targets `j, k`, the sine of the angle
/// at target 0 between `P_j − P_0` and `P_k − P_0` must exceed 1e-3 (collinear points leave the
/// orientation error unobservable, Eq. 4). With three targets this is the angle of their
/// triangle at target 0.
pub(crate) fn check_targets_not_collinear(t: &[DVec3]) -> Result<()> {
    let mut sine: f64 = 0.0;
    for j in 1..t.len() {
        for k in j + 1..t.len() {
            let (u, v) = (t[j] - t[0], t[k] - t[0]);
            let scale = u.length() * v.length();
            if scale > 0.0 {
                sine = sine.max(u.cross(v).length() / scale);
            }
        }
    }
    if sine < 1e-3 {
        return Err(Error::InvalidGeometry(format!(
            "targets are collinear or coincide (sine of the angle at target 0 is {sine:.2e}); \
             three non-collinear points are needed to observe orientation"
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prototype_is_valid_and_round_trips_through_toml() {
        let g = Geometry::prototype();
        g.validate().unwrap();
        let text = g.to_toml_string();
        let back = Geometry::from_toml_str(&text).unwrap();
        assert_eq!(back, g);
        assert_eq!(back.fingerprint(), g.fingerprint());
    }

    #[test]
    fn fingerprint_changes_with_any_number_but_not_the_name() {
        let g = Geometry::prototype();
        let mut renamed = g.clone();
        renamed.name = "other".into();
        assert_eq!(renamed.fingerprint(), g.fingerprint());
        let mut moved = g.clone();
        moved.platform_joints[3].z += 1e-9;
        assert_ne!(moved.fingerprint(), g.fingerprint());
        let mut tilted = g.clone();
        tilted.workspace.tilt_max = 14.0;
        assert_ne!(tilted.fingerprint(), g.fingerprint());
    }

    #[test]
    fn fingerprint_is_stable_across_releases() {
        // The fingerprint binds model files to geometries: it must never change for the same
        // numbers. This literal pins the algorithm (CRC-64/XZ over f64 LE bits, file order).
        assert_eq!(
            Geometry::prototype().fingerprint().to_string(),
            PROTOTYPE_FINGERPRINT
        );
    }

    #[test]
    fn legs_may_share_one_joint_centre_but_not_both() {
        let mut paired = Geometry::prototype();
        paired.leg_range = [100.0, 1000.0]; // room for the moved joint's leg at home
        paired.base_joints[1] = paired.base_joints[0];
        paired.validate().unwrap();
        paired.platform_joints[1] = paired.platform_joints[0];
        let message = paired.validate().unwrap_err().to_string();
        assert!(message.contains("legs 0 and 1"), "{message}");
    }

    const PROTOTYPE_FINGERPRINT: &str = "6dbc9d4c037e4df1";
}
