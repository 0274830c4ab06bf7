//! Compensation by both forms of a model, the reference ([`Model`]) and the serving one
//! ([`FusedModel`]): the tests that include this file check every point they compensate on both,
//! and that the two agree — the same status, legs and corrections within 1e-12 mm (the fused
//! form's documented difference is a few ulp plus `TANH_MAX_ERROR · Σ|w2|`). They return the
//! reference's answer, so the tests' own expectations are about the reference. Each form's
//! answer is also checked to be the same bits when the point is computed in a pair
//! (`compensate_legs_pair`, `compensate_pose_pair`, `compensate_poses`), beside the home pose
//! and beside itself.

use hexacomp_core::compensator::{self, Compensated, Corrections};
use hexacomp_core::fused::FusedModel;
use hexacomp_core::kinematics::inverse_kinematics;
use hexacomp_core::model::Model;
use hexacomp_core::{Geometry, Pose};

/// Largest difference allowed between the two forms' legs or corrections, mm.
const AGREEMENT_MM: f64 = 1e-12;

fn agree(reference: Compensated, fused: Compensated, input: &dyn std::fmt::Debug) -> Compensated {
    assert_eq!(
        reference.status, fused.status,
        "statuses differ at {input:?}"
    );
    for (a, b) in [
        (reference.legs, fused.legs),
        (reference.corrections, fused.corrections),
    ] {
        for (x, y) in a.iter().zip(b) {
            let same = x.to_bits() == y.to_bits() || (x - y).abs() <= AGREEMENT_MM;
            assert!(same, "{a:?} and {b:?} differ at {input:?}");
        }
    }
    reference
}

/// Whether `a` and `b` are the same bits (NaN legs included).
fn same_bits(a: &Compensated, b: &Compensated) -> bool {
    let bits = |c: &Compensated| {
        (
            c.legs.map(f64::to_bits),
            c.corrections.map(f64::to_bits),
            c.status,
        )
    };
    bits(a) == bits(b)
}

/// `alone`, checked to be what `q` gets in a pair, beside the home legs and beside itself.
fn as_in_pairs<M: Corrections>(
    geometry: &Geometry,
    model: Option<&M>,
    q: &[f64; 6],
    alone: Compensated,
) -> Compensated {
    let home = inverse_kinematics(geometry, &geometry.home_pose()).lengths;
    for (pair, at) in [([q, &home], 0), ([&home, q], 1), ([q, q], 1)] {
        let paired = compensator::compensate_legs_pair(geometry, model, pair)[at];
        assert!(
            same_bits(&paired, &alone),
            "{q:?} in a pair: {paired:?}, alone {alone:?}"
        );
    }
    alone
}

/// `alone`, checked to be what `pose` gets in a pair and in a batch of three.
fn as_in_pairs_of_poses<M: Corrections>(
    geometry: &Geometry,
    model: Option<&M>,
    pose: &Pose,
    alone: Compensated,
) -> Compensated {
    let home = geometry.home_pose();
    for (pair, at) in [([pose, &home], 0), ([&home, pose], 1), ([pose, pose], 0)] {
        let paired = compensator::compensate_pose_pair(geometry, model, pair)[at];
        assert!(
            same_bits(&paired, &alone),
            "{pose:?} in a pair: {paired:?}, alone {alone:?}"
        );
    }
    // Filled with what is never an answer (corrections are finite or zero), so that a slot
    // left as it was is seen.
    let mut batch = [Compensated {
        legs: [-1.0; 6],
        corrections: [f64::INFINITY; 6],
        ..alone
    }; 3];
    compensator::compensate_poses(geometry, model, &[home, *pose, *pose], &mut batch);
    for got in &batch[1..] {
        assert!(
            same_bits(got, &alone),
            "{pose:?} in a batch: {got:?}, alone {alone:?}"
        );
    }
    alone
}

/// [`compensator::compensate_legs`] by both forms of `model`, alone and in pairs.
pub fn compensate_legs(geometry: &Geometry, model: Option<&Model>, q: &[f64; 6]) -> Compensated {
    let fused = model.map(FusedModel::new);
    let reference = compensator::compensate_legs(geometry, model, q);
    let served = compensator::compensate_legs(geometry, fused.as_ref(), q);
    agree(
        as_in_pairs(geometry, model, q, reference),
        as_in_pairs(geometry, fused.as_ref(), q, served),
        q,
    )
}

/// [`compensator::compensate_pose`] by both forms of `model`, alone, in pairs and in a batch.
pub fn compensate_pose(geometry: &Geometry, model: Option<&Model>, pose: &Pose) -> Compensated {
    let fused = model.map(FusedModel::new);
    let reference = compensator::compensate_pose(geometry, model, pose);
    let served = compensator::compensate_pose(geometry, fused.as_ref(), pose);
    agree(
        as_in_pairs_of_poses(geometry, model, pose, reference),
        as_in_pairs_of_poses(geometry, fused.as_ref(), pose, served),
        pose,
    )
}
