//! The least-squares rigid transform (`fit_rigid_transform`) against its definition: exact
//! points give any transform back; with noise the fit is a minimum of the weighted sum of squares
//! (no free parameter moved by a small step lowers it) and its residuals do not depend on where
//! the instrument stood; locked parameters stay at zero; degenerate inputs are refused.

use glam::DVec3;
use hexacomp_core::pose::rotation_vector;
use hexacomp_core::rigid_fit::{Locked, fit_rigid_transform};
use hexacomp_core::{Error, Pose};
use proptest::prelude::*;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// Six fiducials on a machine base about 600 mm across, at different heights (mm).
fn fiducials() -> Vec<DVec3> {
    vec![
        DVec3::new(310.0, 12.0, 0.0),
        DVec3::new(-140.0, 260.0, 35.0),
        DVec3::new(-150.0, -255.0, 0.0),
        DVec3::new(20.0, 0.0, 180.0),
        DVec3::new(260.0, -180.0, 95.0),
        DVec3::new(-300.0, 40.0, 140.0),
    ]
}

/// `points` with independent normal noise of `sigma` mm on every coordinate.
fn noisy(points: &[DVec3], sigma: f64, seed: u64) -> Vec<DVec3> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let normal = Normal::new(0.0, sigma).expect("sigma");
    points
        .iter()
        .map(|p| {
            *p + DVec3::new(
                normal.sample(&mut rng),
                normal.sample(&mut rng),
                normal.sample(&mut rng),
            )
        })
        .collect()
}

/// Where the instrument sees base-frame `points` when it stands at `instrument` (its pose in
/// the base frame).
fn seen_from(instrument: &Pose, points: &[DVec3]) -> Vec<DVec3> {
    let rotation = instrument.rotation();
    points
        .iter()
        .map(|p| rotation.transpose() * (*p - instrument.position))
        .collect()
}

fn residuals(pose: &Pose, from: &[DVec3], to: &[DVec3]) -> Vec<DVec3> {
    from.iter()
        .zip(to)
        .map(|(f, t)| pose.transform_point(*f) - *t)
        .collect()
}

fn cost(pose: &Pose, from: &[DVec3], to: &[DVec3], weights: &[f64]) -> f64 {
    residuals(pose, from, to)
        .iter()
        .zip(weights)
        .map(|(r, w)| w * r.length_squared())
        .sum()
}

/// Asserts that no free parameter of `pose`, moved by ±`step` (mm, or rad), lowers the cost by
/// more than rounding: the fit is a (local) minimum of its problem.
fn assert_minimum(pose: &Pose, from: &[DVec3], to: &[DVec3], weights: &[f64], locked: Locked) {
    let at = cost(pose, from, to, weights);
    for k in (0..6).filter(|&k| !locked.is_locked(k)) {
        for step in [1e-4_f64, -1e-4] {
            let mut moved = pose.to_mm_deg();
            moved[k] += if k < 3 { step } else { step.to_degrees() };
            let moved = Pose::from_mm_deg(moved);
            let there = cost(&moved, from, to, weights);
            assert!(
                there >= at - 1e-9 * at.max(1e-12),
                "parameter {k} moved by {step} lowers the cost from {at:e} to {there:e}"
            );
        }
    }
}

fn any_instrument() -> impl Strategy<Value = Pose> {
    (
        prop::array::uniform3(-5000.0..5000.0_f64),
        prop::array::uniform3(-179.0..179.0_f64),
    )
        .prop_map(|(p, a)| {
            // b within ±85°: the angles of a pose are unique there.
            Pose::from_mm_deg([p[0], p[1], p[2], a[0], a[1] * 85.0 / 179.0, a[2]])
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    /// Exact measurements give the instrument's pose back, whatever it is.
    #[test]
    fn random_transforms_are_recovered(instrument in any_instrument()) {
        let nominal = fiducials();
        let measured = seen_from(&instrument, &nominal);
        let fitted = fit_rigid_transform(&measured, &nominal, &[1.0; 6], Locked::default())
            .expect("fit");
        prop_assert!((fitted.position - instrument.position).length() < 1e-8);
        let gap = rotation_vector(&(fitted.rotation() * instrument.rotation().transpose()));
        prop_assert!(gap.length() < 1e-12, "rotation off by {} rad", gap.length());
    }

    /// The residuals of a noisy registration are the same wherever the instrument stood.
    #[test]
    fn residuals_do_not_depend_on_the_instrument_pose(
        first in any_instrument(),
        second in any_instrument(),
        seed in 0..1000_u64,
    ) {
        let nominal = fiducials();
        // The same noisy fiducials in the base frame, seen from two places.
        let noisy_base = noisy(&nominal, 0.01, seed);
        let weights = [1.0, 2.0, 1.0, 0.5, 1.0, 1.0];
        let mut fitted_residuals = Vec::new();
        for instrument in [first, second] {
            let measured = seen_from(&instrument, &noisy_base);
            let fitted = fit_rigid_transform(&measured, &nominal, &weights, Locked::default())
                .expect("fit");
            fitted_residuals.push(residuals(&fitted, &measured, &nominal));
        }
        for (a, b) in fitted_residuals[0].iter().zip(&fitted_residuals[1]) {
            prop_assert!((*a - *b).length() < 1e-8, "{a} vs {b}");
        }
    }
}

#[test]
fn a_weighted_fit_is_a_minimum_of_its_weighted_sum_of_squares() {
    let nominal = fiducials();
    let instrument = Pose::from_mm_deg([2500.0, -1200.0, -900.0, 3.0, -2.0, 140.0]);
    let measured = seen_from(&instrument, &noisy(&nominal, 0.05, 7));
    let weights = [1.0, 4.0, 0.25, 1.0, 2.0, 1.0];
    let fitted =
        fit_rigid_transform(&measured, &nominal, &weights, Locked::default()).expect("fit");
    assert_minimum(&fitted, &measured, &nominal, &weights, Locked::default());
}

#[test]
fn a_fiducial_of_weight_zero_does_not_move_the_fit() {
    let nominal = fiducials();
    let instrument = Pose::from_mm_deg([1000.0, 500.0, -300.0, 0.0, 0.0, 30.0]);
    let mut measured = seen_from(&instrument, &noisy(&nominal, 0.01, 3));
    measured[4] += DVec3::new(3.0, -2.0, 1.0); // knocked
    let zero = fit_rigid_transform(
        &measured,
        &nominal,
        &[1.0, 1.0, 1.0, 1.0, 0.0, 1.0],
        Locked::default(),
    )
    .expect("fit");
    let (mut kept_m, mut kept_n) = (measured.clone(), nominal.clone());
    kept_m.remove(4);
    kept_n.remove(4);
    let without = fit_rigid_transform(&kept_m, &kept_n, &[1.0; 5], Locked::default()).expect("fit");
    assert!((zero.position - without.position).length() < 1e-9);
    assert!((zero.angles - without.angles).length() < 1e-12);
}

#[test]
fn a_levelled_instrument_keeps_its_vertical_and_fits_the_rest_best() {
    let nominal = fiducials();
    // The tracker is levelled to 0.002°: locking a and b is what the user wants.
    let instrument = Pose::from_mm_deg([1800.0, 2200.0, -650.0, 0.002, -0.001, -127.0]);
    let measured = seen_from(&instrument, &noisy(&nominal, 0.01, 11));
    let locked = Locked::from_names(["a", "b"]).expect("names");
    let fitted = fit_rigid_transform(&measured, &nominal, &[1.0; 6], locked).expect("fit");
    assert_eq!((fitted.angles.x, fitted.angles.y), (0.0, 0.0));
    assert!((fitted.angles.z.to_degrees() - -127.0).abs() < 1e-3);
    assert_minimum(&fitted, &measured, &nominal, &[1.0; 6], locked);
}

#[test]
fn locked_translations_and_a_single_locked_angle_are_held_and_the_rest_is_optimal() {
    let nominal = fiducials();
    let instrument = Pose::from_mm_deg([0.03, 900.0, 0.02, 0.5, 1.0, 60.0]);
    let measured = seen_from(&instrument, &noisy(&nominal, 0.01, 5));
    for names in [
        &["x", "z"][..],
        &["a"][..],
        &["x", "c"][..],
        &["b", "y"][..],
    ] {
        let locked = Locked::from_names(names.iter().copied()).expect("names");
        let fitted = fit_rigid_transform(&measured, &nominal, &[1.0; 6], locked).expect("fit");
        let values = fitted.to_mm_deg();
        for k in (0..6).filter(|&k| locked.is_locked(k)) {
            assert_eq!(values[k], 0.0, "{names:?}: parameter {k} moved");
        }
        assert_minimum(&fitted, &measured, &nominal, &[1.0; 6], locked);
    }
}

#[test]
fn degenerate_inputs_are_refused_with_their_cause() {
    let line: Vec<DVec3> = (0..5)
        .map(|k| DVec3::new(100.0 * k as f64, 0.0, 0.001 * (k % 2) as f64))
        .collect();
    let message = fit_rigid_transform(&line, &line, &[1.0; 5], Locked::default())
        .expect_err("collinear")
        .to_string();
    assert!(message.contains("nearly collinear"), "{message}");

    let nominal = fiducials();
    let message = fit_rigid_transform(
        &nominal,
        &nominal,
        &[1.0, 1.0, 0.0, 0.0, 0.0, 0.0],
        Locked::default(),
    )
    .expect_err("two used")
    .to_string();
    assert!(message.contains("2 points of positive weight"), "{message}");

    let message = fit_rigid_transform(
        &nominal,
        &nominal,
        &[1.0, 1.0, -1.0, 1.0, 1.0, 1.0],
        Locked::default(),
    )
    .expect_err("negative weight")
    .to_string();
    assert!(message.contains("weight -1"), "{message}");

    let mut huge = nominal.clone();
    huge[1].x = 1e160;
    let message = fit_rigid_transform(&huge, &nominal, &[1.0; 6], Locked::default())
        .expect_err("huge")
        .to_string();
    assert!(message.contains("lies beyond 1e12 mm"), "{message}");
    let message = fit_rigid_transform(&nominal, &nominal, &[1e300; 6], Locked::default())
        .expect_err("huge weights")
        .to_string();
    assert!(message.contains("weight 1e300 is above"), "{message}");

    let mut bad = nominal.clone();
    bad[2].y = f64::NAN;
    assert_eq!(
        fit_rigid_transform(&bad, &nominal, &[1.0; 6], Locked::default()),
        Err(Error::NonFinite("point of a rigid fit"))
    );
}
