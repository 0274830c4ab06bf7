//! Run-time compensation: known answers and a status for every kind of point.

use hexacomp_core::compensator::{PointStatus, compensate_legs, compensate_pose};
use hexacomp_core::model::{Model, NetworkInput, Networks, Provenance};
use hexacomp_core::network::{Network, Normalisation};
use hexacomp_core::{Geometry, Pose, inverse_kinematics};

/// A coupled network whose output is `offsets` everywhere: zero output weights, biases = offsets.
fn constant_model(geometry: &Geometry, offsets: [f64; 6], bounds: [f64; 2]) -> Model {
    let hidden = 2;
    let mut weights = vec![0.3; Network::weight_count(hidden, 6)];
    let w2 = hidden * 6 + hidden;
    for w in &mut weights[w2..w2 + 6 * hidden] {
        *w = 0.0;
    }
    weights[w2 + 6 * hidden..].copy_from_slice(&offsets);
    Model {
        networks: Networks::Coupled(Network::from_weights(hidden, 6, weights).unwrap()),
        input: NetworkInput::Commanded,
        normalisation: Normalisation {
            mean: [355.0; 6],
            span: [140.0; 6],
        },
        training_range: [[300.0, 400.0]; 6],
        correction_bounds: [bounds; 6],
        geometry: geometry.fingerprint(),
        provenance: Provenance::default(),
    }
}

#[test]
fn a_constant_network_adds_its_constant_to_the_nominal_legs() {
    let g = Geometry::prototype();
    let offsets = [0.1, -0.2, 0.3, -0.4, 0.5, -0.6];
    let m = constant_model(&g, offsets, [-1.0, 1.0]);
    let pose = g.home_pose();
    let nominal = inverse_kinematics(&g, &pose).lengths;
    let c = compensate_pose(&g, Some(&m), &pose);
    assert_eq!(c.status, PointStatus::Ok);
    for i in 0..6 {
        assert!((c.corrections[i] - offsets[i]).abs() < 1e-15);
        assert_eq!(c.legs[i], nominal[i] + c.corrections[i]);
    }
}

#[test]
fn every_kind_of_point_gets_its_status() {
    let g = Geometry::prototype();
    let m = constant_model(&g, [0.1, -0.2, 0.3, -0.4, 0.5, 2.0], [-1.0, 1.0]);
    let home = inverse_kinematics(&g, &g.home_pose()).lengths;

    let clamped = compensate_legs(&g, Some(&m), &home);
    assert_eq!(clamped.status, PointStatus::Clamped);
    assert_eq!(
        clamped.corrections[5], 1.0,
        "clamped to the bound, never beyond"
    );

    let ok = constant_model(&g, [0.1; 6], [-1.0, 1.0]);
    assert_eq!(
        compensate_legs(&g, None, &home).status,
        PointStatus::NoModel
    );
    assert_eq!(compensate_legs(&g, None, &home).legs, home);
    let mut nan = home;
    nan[2] = f64::NAN;
    let invalid = compensate_legs(&g, Some(&ok), &nan);
    assert_eq!(invalid.status, PointStatus::InvalidInput);
    assert_eq!(invalid.corrections, [0.0; 6]);
    let mut long = home;
    long[0] = 431.0;
    assert_eq!(
        compensate_legs(&g, Some(&ok), &long).status,
        PointStatus::OutOfStroke
    );
    let mut untrained = home;
    untrained[3] = 290.0; // inside the stroke, below the trained 300 mm
    assert_eq!(
        compensate_legs(&g, Some(&ok), &untrained).status,
        PointStatus::OutsideTrainedRange
    );
    let mut near_top = home;
    near_top[1] = 429.95; // inside the stroke, but the correction would push it out
    assert_eq!(
        compensate_legs(&g, Some(&ok), &near_top).status,
        PointStatus::OutOfStroke
    );
    let bad_pose = Pose::from_mm_deg([f64::INFINITY, 0.0, 280.0, 0.0, 0.0, 0.0]);
    assert_eq!(
        compensate_pose(&g, Some(&ok), &bad_pose).status,
        PointStatus::InvalidInput
    );
}

#[test]
fn statuses_round_trip_through_their_wire_values() {
    for status in PointStatus::ALL {
        assert_eq!(PointStatus::from_u8(status as u8), Some(status));
    }
    assert_eq!(PointStatus::from_u8(6), None);
}
