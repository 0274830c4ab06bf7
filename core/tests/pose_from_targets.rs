//! The pose an instrument reports from measured targets (`pose_from_targets`): exact targets give
//! the pose back; noisy targets give the least-squares rigid fit, checked against this file's
//! own closed-form solution of that problem (Kabsch/Horn: centroids and the SVD of the
//! cross-covariance); a target not seen is left out of the fit; fewer than three are refused.

use glam::{DMat3, DVec3};
use hexacomp_core::kinematics::{pose_from_targets, target_points};
use hexacomp_core::pose::rotation_vector;
use hexacomp_core::sampling::{SamplerOptions, WorkspaceSampler};
use hexacomp_core::{Error, Geometry, Pose};
use nalgebra::Matrix3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

fn workspace_poses(count: usize, seed: u64) -> Vec<Pose> {
    WorkspaceSampler::new(&Geometry::prototype(), seed, SamplerOptions::default())
        .expect("sampler")
        .samples(count)
        .expect("poses")
}

/// `points` with independent `noise` on every coordinate.
fn with_noise(points: Vec<DVec3>, noise: &Normal<f64>, rng: &mut ChaCha8Rng) -> Vec<DVec3> {
    points
        .into_iter()
        .map(|p| p + DVec3::new(noise.sample(rng), noise.sample(rng), noise.sample(rng)))
        .collect()
}

/// Every point seen.
fn seen(points: &[DVec3]) -> Vec<Option<DVec3>> {
    points.iter().copied().map(Some).collect()
}

/// The angle between two rotations, rad.
fn rotation_gap(a: &DMat3, b: &DMat3) -> f64 {
    rotation_vector(&(*a * b.transpose())).length()
}

/// The least-squares rigid transform platform → base taking the targets `platform` onto
/// `measured`, in closed form (Kabsch).
fn kabsch(platform: &[DVec3], measured: &[DVec3]) -> (DMat3, DVec3) {
    let mean = |points: &[DVec3]| points.iter().copied().sum::<DVec3>() / points.len() as f64;
    let (p_mean, m_mean) = (mean(platform), mean(measured));
    let mut h = Matrix3::zeros();
    for (p, m) in platform.iter().zip(measured) {
        let (p, m) = (*p - p_mean, *m - m_mean);
        h += nalgebra::Vector3::new(p.x, p.y, p.z)
            * nalgebra::Vector3::new(m.x, m.y, m.z).transpose();
    }
    let svd = h.svd(true, true);
    let (u, v) = (svd.u.expect("U"), svd.v_t.expect("Vᵀ").transpose());
    let d = (v * u.transpose()).determinant().signum();
    let r = v * Matrix3::from_diagonal(&nalgebra::Vector3::new(1.0, 1.0, d)) * u.transpose();
    let rotation = DMat3::from_cols_array(&[
        r[(0, 0)],
        r[(1, 0)],
        r[(2, 0)],
        r[(0, 1)],
        r[(1, 1)],
        r[(2, 1)],
        r[(0, 2)],
        r[(1, 2)],
        r[(2, 2)],
    ]);
    (rotation, m_mean - rotation * p_mean)
}

#[test]
fn exact_targets_give_the_pose_back() {
    let g = Geometry::prototype();
    let poses = workspace_poses(300, 7);
    let mut worst = (0.0_f64, 0.0_f64);
    for pose in &poses {
        let fitted = pose_from_targets(&g, &seen(&target_points(&g, pose))).expect("fit");
        worst.0 = worst.0.max((fitted.position - pose.position).length());
        worst.1 = worst
            .1
            .max(rotation_gap(&fitted.rotation(), &pose.rotation()));
    }
    assert!(worst.0 < 1e-9, "position off by {:e} mm", worst.0);
    assert!(worst.1 < 1e-12, "rotation off by {:e} rad", worst.1);
}

#[test]
fn noisy_targets_give_the_least_squares_rigid_fit() {
    let g = Geometry::prototype();
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    // 0.05 mm: ten times a laser tracker's noise, so the fit's residual is far from zero.
    let noise = Normal::new(0.0, 0.05).expect("normal");
    let mut worst = (0.0_f64, 0.0_f64, 0.0_f64);
    for pose in workspace_poses(300, 8) {
        let measured = with_noise(target_points(&g, &pose), &noise, &mut rng);
        let fitted = pose_from_targets(&g, &seen(&measured)).expect("fit");
        let (rotation, position) = kabsch(&g.targets, &measured);
        worst.0 = worst.0.max((fitted.position - position).length());
        worst.1 = worst.1.max(rotation_gap(&fitted.rotation(), &rotation));
        // The noise moved the fit away from the true pose: the comparison is not trivial.
        worst.2 = worst.2.max((fitted.position - pose.position).length());
    }
    assert!(
        worst.0 < 1e-9,
        "position off the closed form by {:e} mm",
        worst.0
    );
    assert!(
        worst.1 < 1e-12,
        "rotation off the closed form by {:e} rad",
        worst.1
    );
    assert!(
        worst.2 > 0.02,
        "the noise moved the fit by {:e} mm only",
        worst.2
    );
}

#[test]
fn a_non_finite_target_is_refused() {
    let g = Geometry::prototype();
    let pose = g.home_pose();
    let mut measured = target_points(&g, &pose);
    measured[1].y = f64::NAN;
    assert!(matches!(
        pose_from_targets(&g, &seen(&measured)),
        Err(Error::NonFinite(_))
    ));
}

#[test]
fn collinear_targets_are_refused_with_their_cause() {
    let mut g = Geometry::prototype();
    for (j, x) in [-50.0, 0.0, 50.0].into_iter().enumerate() {
        g.targets[j] = DVec3::new(x, 0.0, 25.0);
    }
    let pose = g.home_pose();
    let error = pose_from_targets(&g, &seen(&target_points(&g, &pose))).unwrap_err();
    assert!(error.to_string().contains("collinear"), "{error}");
}

#[test]
fn a_pose_far_from_the_origin_is_fitted_where_rounding_is_coarser() {
    // Points in a site's survey frame, 10 km from its origin: coordinates near 1e7 mm, whose
    // rounding step is 1.9e-9 mm.
    let g = Geometry::prototype();
    let mut rng = ChaCha8Rng::seed_from_u64(12);
    let noise = Normal::new(0.0, 0.05).expect("normal");
    for pose in workspace_poses(50, 9) {
        let far = Pose::new(pose.position + DVec3::new(1e7, -1e7, 1e7), pose.angles);
        let measured = with_noise(target_points(&g, &far), &noise, &mut rng);
        let fitted = pose_from_targets(&g, &seen(&measured)).expect("fit");
        let (rotation, position) = kabsch(&g.targets, &measured);
        // Rounding of the coordinates themselves limits both fits to about 1e-8 mm here.
        assert!((fitted.position - position).length() < 1e-7);
        assert!(rotation_gap(&fitted.rotation(), &rotation) < 1e-9);
    }
}

/// The prototype with a fourth target, 40 mm above the platform centre.
fn four_targets() -> Geometry {
    let mut g = Geometry::prototype();
    g.targets.push(DVec3::new(0.0, 0.0, 40.0));
    g.validate().expect("four targets");
    g
}

#[test]
fn a_target_not_seen_is_left_out_of_the_fit() {
    let g = four_targets();
    let mut rng = ChaCha8Rng::seed_from_u64(13);
    let noise = Normal::new(0.0, 0.05).expect("normal");
    for (k, pose) in workspace_poses(100, 11).iter().enumerate() {
        let measured = with_noise(target_points(&g, pose), &noise, &mut rng);
        let missing = k % 4;
        let mut observed = seen(&measured);
        observed[missing] = None;
        let fitted = pose_from_targets(&g, &observed).expect("fit");
        let kept = |points: &[DVec3]| -> Vec<DVec3> {
            (0..4)
                .filter(|&j| j != missing)
                .map(|j| points[j])
                .collect()
        };
        let (rotation, position) = kabsch(&kept(&g.targets), &kept(&measured));
        assert!((fitted.position - position).length() < 1e-9);
        assert!(rotation_gap(&fitted.rotation(), &rotation) < 1e-12);
    }
}

#[test]
fn fewer_than_three_targets_or_another_count_are_refused() {
    let g = Geometry::prototype();
    let pose = g.home_pose();
    let mut observed = seen(&target_points(&g, &pose));
    observed[2] = None;
    let error = pose_from_targets(&g, &observed).unwrap_err().to_string();
    assert!(error.contains("2 of 3 targets seen"), "{error}");
    let error = pose_from_targets(&four_targets(), &observed)
        .unwrap_err()
        .to_string();
    assert!(
        error.contains("3 measured targets, the geometry has 4"),
        "{error}"
    );
}
