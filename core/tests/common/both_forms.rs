//! Compensation by both forms of a model, the reference ([`Model`]) and the serving one
//! ([`FusedModel`]): the tests that include this file check every point they compensate on both,
//! and that the two agree — the same status, legs and corrections within 1e-12 mm (the fused
//! form's documented difference is a few ulp plus `TANH_MAX_ERROR · Σ|w2|`). They return the
//! reference's answer, so the tests' own expectations are about the reference.

use hexacomp_core::compensator::{self, Compensated};
use hexacomp_core::fused::FusedModel;
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

/// [`compensator::compensate_legs`] by both forms of `model`.
pub fn compensate_legs(geometry: &Geometry, model: Option<&Model>, q: &[f64; 6]) -> Compensated {
    let fused = model.map(FusedModel::new);
    agree(
        compensator::compensate_legs(geometry, model, q),
        compensator::compensate_legs(geometry, fused.as_ref(), q),
        q,
    )
}

/// [`compensator::compensate_pose`] by both forms of `model`.
pub fn compensate_pose(geometry: &Geometry, model: Option<&Model>, pose: &Pose) -> Compensated {
    let fused = model.map(FusedModel::new);
    agree(
        compensator::compensate_pose(geometry, model, pose),
        compensator::compensate_pose(geometry, fused.as_ref(), pose),
        pose,
    )
}
