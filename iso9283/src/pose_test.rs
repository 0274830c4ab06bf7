//! ISO 9283 (1998) pose characteristics: the test poses on the diagonal plane of the test cube
//! (§ 6.2), and the pose accuracy AP and pose repeatability RP of the attained poses (§ 7.2).
//!
//! - The **test cube** is the largest cube with edges parallel to the base axes inside the task
//!   workspace (the cylinder of `Workspace::radius` about the base z axis, `Workspace::z_range`),
//!   at the home orientation, shrunk until every pose on its faces is within the legs' stroke.
//! - The **test plane** is a diagonal plane of the cube through two opposite edges (ISO's
//!   C1–C2–C7–C8): here the edge `y = −h, z = −h` and the edge `y = +h, z = +h` (`h` half the
//!   side). **P1** is the cube's centre; **P2–P5** lie on the plane's diagonals at 10 % of the
//!   diagonal's length from its ends, i.e. at 80 % of the way from the centre to the corners.
//!   Every test pose has the home orientation.
//! - **Orientation poses** O1–O6 (a hexapod is a six-axis machine; ISO's five poses test its
//!   position only): P1 rotated by ± 80 % of the workspace's tilt about x and y, and by ± 80 % of
//!   the half yaw range about z (less where the stroke does not allow it).
//! - A **cycle** visits P1, P5, P4, P3, P2 (ISO § 7.2.1), then the orientation and extra poses,
//!   and the machine returns to P2 unmeasured (it also goes there before the first cycle), so
//!   that every pose, P1 included, is approached from the same pose every cycle, P1 from P2 as
//!   ISO's cycle P1 → P5 → P4 → P3 → P2 → P1 does ([`crate::verify::PoseTest::approach`]).
//!
//! The characteristics, per pose, of `n` attained poses `(x_j, y_j, z_j, a_j, b_j, c_j)` against
//! the commanded `(x_c, …, c_c)` (mm and degrees, base frame):
//!
//! - `AP_P = √((x̄ − x_c)² + (ȳ − y_c)² + (z̄ − z_c)²)`, `AP_a = ā − a_c`, `AP_b = b̄ − b_c`,
//!   `AP_c = c̄ − c_c`, with `x̄ = (1/n) Σ x_j` and so on;
//! - `RP_l = l̄ + 3 S_l`, `l_j = √((x_j − x̄)² + (y_j − ȳ)² + (z_j − z̄)²)`, `l̄ = (1/n) Σ l_j`,
//!   `S_l = √(Σ (l_j − l̄)² / (n − 1))`;
//! - `RP_a = ±3 S_a`, `S_a = √(Σ (a_j − ā)² / (n − 1))`, and so for `b` and `c` (reported as
//!   the positive `3 S`).
//!
//! Angles are taken as their difference from the commanded angle wrapped into (−180°, 180°], so a
//! pose commanded at 180° is not averaged across the wrap.

use glam::DVec3;
use hexacomp_core::sampling::{SamplerOptions, WorkspaceSampler};
use hexacomp_core::{Geometry, Pose, inverse_kinematics};

use crate::error::{Error, Result};

/// The test cube: axis-parallel, in the base frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TestCube {
    /// The cube's centre (P1's position), mm, base frame.
    pub centre: DVec3,
    /// The length of its edges, mm.
    pub side_mm: f64,
}

impl TestCube {
    /// The four corners of the test plane (near P2, P3, P4, P5), mm, base frame.
    pub fn plane_corners(&self) -> [DVec3; 4] {
        let h = self.side_mm / 2.0;
        [
            DVec3::new(-h, -h, -h),
            DVec3::new(h, -h, -h),
            DVec3::new(h, h, h),
            DVec3::new(-h, h, h),
        ]
        .map(|offset| self.centre + offset)
    }
}

/// A pose of the test, named as ISO does (P1–P5) or as its additions (O1–O6, E1…).
#[derive(Debug, Clone, PartialEq)]
pub struct TestPose {
    /// P1…P5, O1…O6, E1…
    pub name: String,
    /// The commanded pose `x, y, z, a, b, c`, mm and degrees, base frame.
    pub commanded: [f64; 6],
}

/// Which poses a test holds besides ISO's five.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct TestPoseOptions {
    /// Add the orientation poses O1–O6.
    pub orientation: bool,
    /// Add this many poses drawn from the task workspace (E1…).
    pub extra: usize,
    /// The seed the extra poses are drawn with.
    pub seed: u64,
}

/// Share of the largest rotation the workspace allows that the orientation poses use.
const ORIENTATION_SHARE: f64 = 0.8;
/// Poses per face edge checked against the stroke when the cube is sized.
const FACE_GRID: usize = 7;

/// Whether every pose on the faces of the cube (a grid of [`FACE_GRID`]² per face) at the
/// orientation `abc_deg` is within the stroke.
fn cube_in_stroke(geometry: &Geometry, cube: &TestCube, abc_deg: [f64; 3]) -> bool {
    let h = cube.side_mm / 2.0;
    let steps: Vec<f64> = (0..FACE_GRID)
        .map(|k| -h + cube.side_mm * k as f64 / (FACE_GRID - 1) as f64)
        .collect();
    let mut points = Vec::new();
    for &u in &steps {
        for &v in &steps {
            for side in [-h, h] {
                points.push(DVec3::new(side, u, v));
                points.push(DVec3::new(u, side, v));
                points.push(DVec3::new(u, v, side));
            }
        }
    }
    points.iter().all(|offset| {
        let p = cube.centre + *offset;
        let pose = Pose::from_mm_deg([p.x, p.y, p.z, abc_deg[0], abc_deg[1], abc_deg[2]]);
        inverse_kinematics(geometry, &pose).all_in_stroke()
    })
}

/// The largest axis-parallel cube in the task workspace whose faces are within the stroke at
/// the home orientation: centred on the workspace cylinder's axis half way up its z range, its
/// side at most `radius·√2` and the z range, then shrunk by bisection (to 0.1 %) until it fits
/// the stroke. An error when not even a 1 mm cube fits.
pub fn test_cube(geometry: &Geometry) -> Result<TestCube> {
    let w = &geometry.workspace;
    let centre = DVec3::new(0.0, 0.0, (w.z_range[0] + w.z_range[1]) / 2.0);
    let largest = (w.radius * std::f64::consts::SQRT_2).min(w.z_range[1] - w.z_range[0]);
    let home = geometry.home;
    let abc = [home[3], home[4], home[5]];
    let fits = |side_mm: f64| cube_in_stroke(geometry, &TestCube { centre, side_mm }, abc);
    if fits(largest) {
        return Ok(TestCube {
            centre,
            side_mm: largest,
        });
    }
    if !(largest >= 1.0 && fits(1.0)) {
        return Err(Error::NoTestCube {
            centre_z_mm: centre.z,
        });
    }
    let (mut inside, mut outside) = (1.0, largest);
    while outside - inside > 1e-3 * inside {
        let middle = (inside + outside) / 2.0;
        if fits(middle) {
            inside = middle;
        } else {
            outside = middle;
        }
    }
    Ok(TestCube {
        centre,
        side_mm: inside,
    })
}

/// ISO's five poses P1–P5 of `cube` at the home orientation, in the order of their names.
pub fn iso_poses(geometry: &Geometry, cube: &TestCube) -> Vec<TestPose> {
    let home = geometry.home;
    let at = |name: String, p: DVec3| TestPose {
        name,
        commanded: [p.x, p.y, p.z, home[3], home[4], home[5]],
    };
    let mut poses = vec![at("P1".into(), cube.centre)];
    for (k, corner) in cube.plane_corners().iter().enumerate() {
        let point = cube.centre + 0.8 * (*corner - cube.centre);
        poses.push(at(format!("P{}", k + 2), point));
    }
    poses
}

/// The orientation poses O1–O6 about P1: `a`, `b` and `c` turned by ± [`ORIENTATION_SHARE`] of
/// what the workspace allows, halved until the legs are within the stroke.
fn orientation_poses(geometry: &Geometry, p1: &[f64; 6]) -> Result<Vec<TestPose>> {
    let w = &geometry.workspace;
    let half_yaw = (w.yaw_range[1] - w.yaw_range[0]) / 2.0;
    let turns = [
        (3, w.tilt_max),
        (3, -w.tilt_max),
        (4, w.tilt_max),
        (4, -w.tilt_max),
        (5, half_yaw),
        (5, -half_yaw),
    ];
    turns
        .iter()
        .enumerate()
        .map(|(k, &(axis, range))| {
            let mut turn = ORIENTATION_SHARE * range;
            for _ in 0..30 {
                let mut commanded = *p1;
                commanded[axis] += turn;
                if inverse_kinematics(geometry, &Pose::from_mm_deg(commanded)).all_in_stroke() {
                    return Ok(TestPose {
                        name: format!("O{}", k + 1),
                        commanded,
                    });
                }
                turn /= 2.0;
            }
            Err(Error::NoOrientationPose { pose: k + 1 })
        })
        .collect()
}

/// The poses of a test in the order a cycle visits them: P1, P5, P4, P3, P2 (ISO § 7.2.1), then
/// O1–O6 and E1… as `options` asks.
pub fn cycle_poses(
    geometry: &Geometry,
    cube: &TestCube,
    options: &TestPoseOptions,
) -> Result<Vec<TestPose>> {
    let iso = iso_poses(geometry, cube);
    let mut poses: Vec<TestPose> = [0, 4, 3, 2, 1].iter().map(|&k| iso[k].clone()).collect();
    if options.orientation {
        poses.extend(orientation_poses(geometry, &iso[0].commanded)?);
    }
    if let Some(outside) = poses
        .iter()
        .find(|p| !inverse_kinematics(geometry, &Pose::from_mm_deg(p.commanded)).all_in_stroke())
    {
        return Err(Error::PoseOutsideStroke {
            pose: outside.name.clone(),
            commanded: outside.commanded,
        });
    }
    if options.extra > 0 {
        let mut sampler = WorkspaceSampler::new(geometry, options.seed, SamplerOptions::default())?;
        for k in 0..options.extra {
            poses.push(TestPose {
                name: format!("E{}", k + 1),
                commanded: sampler.sample()?.to_mm_deg(),
            });
        }
    }
    Ok(poses)
}

/// The pose every cycle's first pose is approached from: P2, as in ISO's cycle
/// P1 → P5 → P4 → P3 → P2 → P1 (none when `poses` has no P2).
pub fn approach_pose(poses: &[TestPose]) -> Option<TestPose> {
    poses.iter().find(|p| p.name == "P2").cloned()
}

/// One pose's ISO 9283 characteristics (mm and degrees).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PoseCharacteristics {
    /// Attained poses the figures are computed from.
    pub cycles: usize,
    /// The barycentre of the attained poses `x̄, ȳ, z̄, ā, b̄, c̄`, mm and degrees.
    pub barycentre: [f64; 6],
    /// Position accuracy `AP_P`, mm.
    pub ap_p_mm: f64,
    /// Orientation accuracy `AP_a = ā − a_c`, degrees (signed).
    pub ap_a_deg: f64,
    /// Orientation accuracy `AP_b`, degrees (signed).
    pub ap_b_deg: f64,
    /// Orientation accuracy `AP_c`, degrees (signed).
    pub ap_c_deg: f64,
    /// Position repeatability `RP_l = l̄ + 3 S_l`, mm.
    pub rp_l_mm: f64,
    /// Orientation repeatability `3 S_a`, degrees.
    pub rp_a_deg: f64,
    /// Orientation repeatability `3 S_b`, degrees.
    pub rp_b_deg: f64,
    /// Orientation repeatability `3 S_c`, degrees.
    pub rp_c_deg: f64,
}

/// `angle − reference` wrapped into (−180°, 180°].
pub(crate) fn angle_difference(angle: f64, reference: f64) -> f64 {
    let d = (angle - reference).rem_euclid(360.0);
    if d > 180.0 { d - 360.0 } else { d }
}

/// The sample standard deviation of `values` about `mean` (`n − 1` in the denominator).
fn sample_deviation(values: impl Iterator<Item = f64>, mean: f64, n: usize) -> f64 {
    (values.map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt()
}

/// The ISO 9283 characteristics of the poses `attained` at the pose `commanded` (mm and
/// degrees, base frame); at least two attained poses are needed.
pub fn characteristics(commanded: &[f64; 6], attained: &[[f64; 6]]) -> Result<PoseCharacteristics> {
    let n = attained.len();
    if n < 2 {
        return Err(Error::TooFewAttained { given: n });
    }
    let mean = |k: usize| attained.iter().map(|p| p[k]).sum::<f64>() / n as f64;
    let position = DVec3::new(mean(0), mean(1), mean(2));
    let commanded_position = DVec3::new(commanded[0], commanded[1], commanded[2]);
    // Angles as deviations from the commanded angle, so the mean does not cross ±180°.
    let deviations = |k: usize| -> Vec<f64> {
        attained
            .iter()
            .map(|p| angle_difference(p[k], commanded[k]))
            .collect()
    };
    let angle_terms: [(f64, f64); 3] = std::array::from_fn(|i| {
        let d = deviations(3 + i);
        let ap = d.iter().sum::<f64>() / n as f64;
        (ap, 3.0 * sample_deviation(d.iter().copied(), ap, n))
    });
    let l: Vec<f64> = attained
        .iter()
        .map(|p| DVec3::new(p[0], p[1], p[2]).distance(position))
        .collect();
    let l_mean = l.iter().sum::<f64>() / n as f64;
    let s_l = sample_deviation(l.iter().copied(), l_mean, n);
    Ok(PoseCharacteristics {
        cycles: n,
        barycentre: [
            position.x,
            position.y,
            position.z,
            commanded[3] + angle_terms[0].0,
            commanded[4] + angle_terms[1].0,
            commanded[5] + angle_terms[2].0,
        ],
        ap_p_mm: position.distance(commanded_position),
        ap_a_deg: angle_terms[0].0,
        ap_b_deg: angle_terms[1].0,
        ap_c_deg: angle_terms[2].0,
        rp_l_mm: l_mean + 3.0 * s_l,
        rp_a_deg: angle_terms[0].1,
        rp_b_deg: angle_terms[1].1,
        rp_c_deg: angle_terms[2].1,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_answer_ap_and_rp_as_iso_defines_them() {
        let commanded = [100.0, 0.0, 300.0, 0.0, 0.0, 180.0];
        // Four positions one mm around (110, 0, 300): l_j = 1 each, so RP_l = 1 + 3·0.
        let attained = [
            [111.0, 0.0, 300.0, 0.1, 0.0, 179.9],
            [109.0, 0.0, 300.0, -0.1, 0.0, -179.9],
            [110.0, 1.0, 300.0, 0.3, 0.0, 179.9],
            [110.0, -1.0, 300.0, -0.1, 0.0, -179.9],
        ];
        let c = characteristics(&commanded, &attained).unwrap();
        assert_eq!(c.cycles, 4);
        assert!((c.ap_p_mm - 10.0).abs() < 1e-12, "{c:?}");
        assert!((c.rp_l_mm - 1.0).abs() < 1e-12, "{c:?}");
        // a: mean 0.05°; deviations 0.05, −0.15, 0.25, −0.15; S_a = √(0.11 / 3).
        assert!((c.ap_a_deg - 0.05).abs() < 1e-12);
        assert!((c.rp_a_deg - 3.0 * (0.11_f64 / 3.0).sqrt()).abs() < 1e-12);
        assert_eq!((c.ap_b_deg, c.rp_b_deg), (0.0, 0.0));
        // c across ±180°: the mean is 180°, not 0°; S_c = √(4·0.01 / 3).
        assert!(c.ap_c_deg.abs() < 1e-9, "{c:?}");
        assert!((c.rp_c_deg - 3.0 * (0.04_f64 / 3.0).sqrt()).abs() < 1e-9);
        assert!((c.barycentre[0] - 110.0).abs() < 1e-12);
    }

    #[test]
    fn rp_l_adds_three_sample_deviations_of_the_distances() {
        let commanded = [0.0; 6];
        // Along x: 0, 0, 0, 4 → barycentre 1; l = 1, 1, 1, 3; l̄ = 1.5; S_l = √(3·0.25 + 2.25)/√3 = 1.
        let attained = [
            [0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            [0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            [0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            [4.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        ];
        let c = characteristics(&commanded, &attained).unwrap();
        assert!((c.ap_p_mm - 1.0).abs() < 1e-12);
        assert!((c.rp_l_mm - (1.5 + 3.0)).abs() < 1e-12, "{c:?}");
        assert!(characteristics(&commanded, &attained[..1]).is_err());
    }

    #[test]
    fn the_test_poses_lie_where_iso_puts_them_in_the_largest_cube_that_fits() {
        let g = Geometry::prototype();
        let cube = test_cube(&g).unwrap();
        let w = &g.workspace;
        let h = cube.side_mm / 2.0;
        // Inside the task workspace: the square's corners within the radius, the z range held.
        assert!((2.0 * h * h).sqrt() <= w.radius * (1.0 + 1e-12));
        assert!(
            cube.centre.z - h >= w.z_range[0] - 1e-9 && cube.centre.z + h <= w.z_range[1] + 1e-9
        );
        let abc = [g.home[3], g.home[4], g.home[5]];
        assert!(cube_in_stroke(&g, &cube, abc));
        // The largest: either the workspace's bound or a cube 0.2 % larger leaves the stroke.
        let largest = (w.radius * std::f64::consts::SQRT_2).min(w.z_range[1] - w.z_range[0]);
        let bigger = TestCube {
            side_mm: cube.side_mm * 1.002,
            ..cube
        };
        assert!(
            cube.side_mm == largest || !cube_in_stroke(&g, &bigger, abc),
            "{cube:?}"
        );

        let poses = iso_poses(&g, &cube);
        let position = |p: &TestPose| DVec3::new(p.commanded[0], p.commanded[1], p.commanded[2]);
        assert_eq!(position(&poses[0]), cube.centre);
        let corners = cube.plane_corners();
        let diagonal = corners[0].distance(corners[2]);
        assert!((diagonal - cube.side_mm * 3f64.sqrt()).abs() < 1e-9);
        let normal = (corners[1] - corners[0])
            .cross(corners[3] - corners[0])
            .normalize();
        for (k, pose) in poses[1..].iter().enumerate() {
            // 10 % of the diagonal from its end, on the diagonal, in the plane.
            let p = position(pose);
            assert!(
                (p.distance(corners[k]) - 0.1 * diagonal).abs() < 1e-9,
                "{pose:?}"
            );
            assert!((p.distance(cube.centre) - 0.4 * diagonal).abs() < 1e-9);
            assert!((p - corners[0]).dot(normal).abs() < 1e-9);
            assert_eq!(pose.commanded[3..], g.home[3..]);
        }
        // Opposite corners of the plane are opposite corners of the cube.
        assert!((corners[0] + corners[2] - 2.0 * cube.centre).length() < 1e-9);
        assert!((corners[1] + corners[3] - 2.0 * cube.centre).length() < 1e-9);

        let options = TestPoseOptions {
            orientation: true,
            extra: 2,
            seed: 1,
        };
        let cycle = cycle_poses(&g, &cube, &options).unwrap();
        let names: Vec<&str> = cycle.iter().map(|p| p.name.as_str()).collect();
        assert_eq!(
            names,
            [
                "P1", "P5", "P4", "P3", "P2", "O1", "O2", "O3", "O4", "O5", "O6", "E1", "E2"
            ]
        );
        for pose in &cycle {
            assert!(inverse_kinematics(&g, &Pose::from_mm_deg(pose.commanded)).all_in_stroke());
        }
        // O1 turns a, O6 turns c the other way; both about P1.
        assert!(cycle[5].commanded[3] > g.home[3] && cycle[10].commanded[5] < g.home[5]);
        assert_eq!(cycle[5].commanded[..3], cycle[0].commanded[..3]);
    }
}
