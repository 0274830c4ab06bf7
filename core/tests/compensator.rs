//! Run-time compensation, by both forms of a model (the reference and the fused serving one,
//! which must agree): known answers, a status for every kind of point, which status wins
//! when several apply, and the exact meaning of the model's trained range, its correction bounds
//! and the stroke ends (inclusive, per leg).

#[path = "common/both_forms.rs"]
mod both_forms;
mod common;

use both_forms::{compensate_legs, compensate_pose};
use hexacomp_core::compensator::{self, Compensated, Corrections, PointStatus};
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
        uncertainty: None,
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
fn a_corrected_point_carries_the_models_uncertainty_at_its_nominal_legs_and_others_none() {
    let g = Geometry::prototype();
    let uncertainty = common::uncertainty();
    let m = Model {
        uncertainty: Some(uncertainty.clone()),
        ..constant_model(&g, [0.1; 6], [-1.0, 1.0])
    };
    let home = inverse_kinematics(&g, &g.home_pose()).lengths;
    let at_home = compensate_pose(&g, Some(&m), &g.home_pose());
    assert_eq!(at_home.status, PointStatus::Ok);
    // At the nominal legs, not the corrected ones.
    assert_eq!(at_home.uncertainty_mm, Some(uncertainty.sigma_mm(&home)));
    assert_ne!(
        at_home.uncertainty_mm,
        Some(uncertainty.sigma_mm(&at_home.legs))
    );
    // Outside the trained range it is still given, and larger.
    let mut untrained = home;
    untrained[3] = 290.0;
    let outside = compensate_legs(&g, Some(&m), &untrained);
    assert_eq!(outside.status, PointStatus::OutsideTrainedRange);
    assert!(outside.uncertainty_mm.unwrap() > at_home.uncertainty_mm.unwrap());
    // Points the model did not correct, or not as it wanted, have none.
    let clamped = compensate_legs(
        &g,
        Some(&Model {
            uncertainty: Some(uncertainty.clone()),
            ..constant_model(&g, [0.1, -0.2, 0.3, -0.4, 0.5, 2.0], [-1.0, 1.0])
        }),
        &home,
    );
    assert_eq!(clamped.status, PointStatus::Clamped);
    assert_eq!(clamped.uncertainty_mm, None);
    let mut long = home;
    long[0] = 431.0;
    let mut nan = home;
    nan[2] = f64::NAN;
    for (point, status) in [
        (
            compensate_legs(&g, Some(&m), &long),
            PointStatus::OutOfStroke,
        ),
        (
            compensate_legs(&g, Some(&m), &nan),
            PointStatus::InvalidInput,
        ),
        (compensate_legs(&g, None, &home), PointStatus::NoModel),
    ] {
        assert_eq!(point.status, status);
        assert_eq!(point.uncertainty_mm, None, "{status:?}");
    }
    // A model without one gives none.
    let plain = constant_model(&g, [0.1; 6], [-1.0, 1.0]);
    assert_eq!(
        compensate_legs(&g, Some(&plain), &home).uncertainty_mm,
        None
    );
}

#[test]
fn statuses_round_trip_through_their_wire_values() {
    for status in PointStatus::ALL {
        assert_eq!(PointStatus::from_u8(status as u8), Some(status));
    }
    assert_eq!(PointStatus::from_u8(6), None);
}

/// A coupled network with `hidden` nodes, input weights 0 and hidden biases 50: every hidden
/// activation is tanh(50) = 1 exactly, whatever the legs, so output `k` is
/// `b2[k] + hidden · w2[k]` (summed in floating point, so it can overflow).
fn saturated_model(geometry: &Geometry, hidden: usize, w2: [f64; 6], b2: [f64; 6]) -> Model {
    let mut weights = vec![0.0; Network::weight_count(hidden, 6)];
    let b1 = hidden * 6;
    weights[b1..b1 + hidden].fill(50.0);
    for k in 0..6 {
        for j in 0..hidden {
            weights[b1 + hidden + k * hidden + j] = w2[k];
        }
    }
    weights[b1 + hidden + 6 * hidden..].copy_from_slice(&b2);
    Model {
        networks: Networks::Coupled(Network::from_weights(hidden, 6, weights).unwrap()),
        ..constant_model(geometry, [0.0; 6], [-1.0, 1.0])
    }
}

fn assert_unchanged(c: &Compensated, q: &[f64; 6], status: PointStatus) {
    assert_eq!(c.status, status);
    assert_eq!(c.corrections, [0.0; 6]);
    assert_eq!(c.legs, *q);
}

#[test]
fn a_model_output_that_is_not_finite_makes_the_point_invalid_input() {
    let g = Geometry::prototype();
    let home = inverse_kinematics(&g, &g.home_pose()).lengths;
    for leg in 0..6 {
        for sign in [1.0, -1.0] {
            // Two saturated hidden nodes of weight ±1e308 each overflow to ±∞ on one output;
            // every finite weight passes the model's validation.
            let mut w2 = [0.0; 6];
            w2[leg] = sign * 1e308;
            let mut b2 = [0.0; 6];
            b2[leg] = sign * 1e308;
            // Leg 1's correction is also beyond its bound (unless leg 1 is the non-finite one):
            // the non-finite output still makes the point invalid, not clamped.
            b2[0] += 5.0;
            let m = saturated_model(&g, 2, w2, b2);
            m.validate().unwrap();
            assert!(!m.raw_corrections(&home)[leg].is_finite());
            assert_unchanged(
                &compensate_legs(&g, Some(&m), &home),
                &home,
                PointStatus::InvalidInput,
            );
        }
    }
    // NaN: a valid but subnormal span overflows the normalised input to ±∞, and its zero input
    // weight times ∞ is NaN.
    let mut m = saturated_model(&g, 1, [0.0; 6], [0.1; 6]);
    m.normalisation.span[3] = 1e-310;
    m.validate().unwrap();
    assert!(m.raw_corrections(&home).iter().all(|c| c.is_nan()));
    assert_unchanged(
        &compensate_legs(&g, Some(&m), &home),
        &home,
        PointStatus::InvalidInput,
    );
    let c = compensate_pose(&g, Some(&m), &g.home_pose());
    assert_unchanged(&c, &home, PointStatus::InvalidInput);
}

#[test]
fn clamped_takes_precedence_over_outside_trained_range() {
    // Both apply: a leg below the trained 300 mm and a correction beyond ±1 mm. A point has one
    // status; whichever leg comes first, it is clamped (the legs returned are not the model's
    // output), and the correction is the bound.
    let g = Geometry::prototype();
    let home = inverse_kinematics(&g, &g.home_pose()).lengths;
    for (untrained_leg, clamped_leg) in [(0, 5), (5, 0), (2, 2)] {
        let mut offsets = [0.1; 6];
        offsets[clamped_leg] = -2.0;
        let m = constant_model(&g, offsets, [-1.0, 1.0]);
        let mut q = home;
        q[untrained_leg] = 290.0;
        let c = compensate_legs(&g, Some(&m), &q);
        assert_eq!(
            c.status,
            PointStatus::Clamped,
            "legs {untrained_leg}, {clamped_leg}"
        );
        assert_eq!(c.corrections[clamped_leg], -1.0);
        assert_eq!(c.legs[clamped_leg], q[clamped_leg] - 1.0);
    }
}

#[test]
fn the_trained_range_includes_its_ends_and_a_nanometre_beyond_them() {
    // Leg i is trained on [300 + i, 400 − i] mm. At the ends, and up to 1e-6 mm (the tolerance
    // for rounding in the nominal legs) beyond them, a point is inside; one ulp further it is
    // outside. Only the leg that leaves its own range matters.
    let g = Geometry::prototype();
    let mut m = constant_model(&g, [0.1; 6], [-1.0, 1.0]);
    m.training_range = std::array::from_fn(|i| [300.0 + i as f64, 400.0 - i as f64]);
    let tolerance = 1e-6;
    for leg in 0..6 {
        let [lo, hi] = m.training_range[leg];
        let inside = [lo, hi, lo - tolerance, hi + tolerance, lo - 1e-9, hi + 1e-9];
        let outside = [
            (lo - tolerance).next_down(),
            (hi + tolerance).next_up(),
            lo - 1e-3,
            hi + 1e-3,
        ];
        for (values, status) in [
            (&inside[..], PointStatus::Ok),
            (&outside[..], PointStatus::OutsideTrainedRange),
        ] {
            for &v in values {
                let mut q = [350.0; 6];
                q[leg] = v;
                let c = compensate_legs(&g, Some(&m), &q);
                assert_eq!(c.status, status, "leg {} at {v} in [{lo}, {hi}]", leg + 1);
                // Outside the trained range the point is still compensated.
                assert_eq!(c.corrections, [0.1; 6]);
            }
        }
        // Another leg's range does not apply: leg `leg` at the edge of the widest range [300,
        // 400] is outside only for legs with a narrower one.
        let mut q = [350.0; 6];
        q[leg] = 300.5;
        let expected = if leg == 0 {
            PointStatus::Ok
        } else {
            PointStatus::OutsideTrainedRange
        };
        assert_eq!(
            compensate_legs(&g, Some(&m), &q).status,
            expected,
            "leg {}",
            leg + 1
        );
    }
}

#[test]
fn corrections_at_their_bounds_are_kept_and_beyond_them_clamped_per_leg() {
    // Leg i may be corrected by [−0.1 (i + 1), 0.2 (i + 1)] mm.
    let g = Geometry::prototype();
    let bounds: [[f64; 2]; 6] =
        std::array::from_fn(|i| [-0.1 * (i + 1) as f64, 0.2 * (i + 1) as f64]);
    let q = [350.0; 6];
    let with = |offsets| Model {
        correction_bounds: bounds,
        ..constant_model(&g, offsets, [-1.0, 1.0])
    };
    for end in 0..2 {
        let at_bounds = bounds.map(|b| b[end]);
        let c = compensate_legs(&g, Some(&with(at_bounds)), &q);
        assert_eq!(
            c.status,
            PointStatus::Ok,
            "corrections at the bounds {at_bounds:?}"
        );
        assert_eq!(c.corrections, at_bounds);
        for leg in 0..6 {
            let mut beyond = at_bounds;
            beyond[leg] = if end == 0 {
                at_bounds[leg].next_down()
            } else {
                at_bounds[leg].next_up()
            };
            let c = compensate_legs(&g, Some(&with(beyond)), &q);
            assert_eq!(
                c.status,
                PointStatus::Clamped,
                "leg {} beyond {beyond:?}",
                leg + 1
            );
            assert_eq!(
                c.corrections, at_bounds,
                "clamped to the bound, never beyond"
            );
            assert_eq!(c.legs, std::array::from_fn(|i| q[i] + at_bounds[i]));
        }
    }
}

#[test]
fn stroke_ends_bound_nominal_and_corrected_legs_inclusively() {
    let g = Geometry::prototype();
    let mut m = constant_model(&g, [0.0; 6], [-1.0, 1.0]);
    m.training_range = [[280.0, 430.0]; 6];
    // Nominal legs at the stroke ends are compensated; one ulp outside they are refused.
    let ends = [280.0, 430.0, 280.0, 430.0, 280.0, 430.0];
    let c = compensate_legs(&g, Some(&m), &ends);
    assert_eq!((c.status, c.legs), (PointStatus::Ok, ends));
    for leg in 0..6 {
        let mut q = ends;
        q[leg] = if leg % 2 == 0 {
            q[leg].next_down()
        } else {
            q[leg].next_up()
        };
        assert_unchanged(
            &compensate_legs(&g, Some(&m), &q),
            &q,
            PointStatus::OutOfStroke,
        );
        assert_unchanged(&compensate_legs(&g, None, &q), &q, PointStatus::OutOfStroke);
    }
    // Corrected legs landing exactly on the stroke ends are kept; past them, refused.
    let q = [280.5, 429.5, 280.5, 429.5, 280.5, 429.5];
    let onto_ends = Model {
        training_range: [[280.0, 430.0]; 6],
        ..constant_model(&g, [-0.5, 0.5, -0.5, 0.5, -0.5, 0.5], [-1.0, 1.0])
    };
    let c = compensate_legs(&g, Some(&onto_ends), &q);
    assert_eq!((c.status, c.legs), (PointStatus::Ok, ends));
    for leg in 0..6 {
        let mut offsets = [-0.5, 0.5, -0.5, 0.5, -0.5, 0.5];
        offsets[leg] *= 1.001;
        let past = constant_model(&g, offsets, [-1.0, 1.0]);
        assert_unchanged(
            &compensate_legs(&g, Some(&past), &q),
            &q,
            PointStatus::OutOfStroke,
        );
    }
}

#[test]
fn status_names_are_the_documented_file_words() {
    // README (`predict`): the `status` column's words, in numeric order.
    let names = [
        "ok",
        "out_of_stroke",
        "outside_trained_range",
        "clamped",
        "invalid_input",
        "no_model",
    ];
    for (status, name) in PointStatus::ALL.into_iter().zip(names) {
        assert_eq!(status.name(), name, "{status:?}");
    }
}

/// A form of `reference` whose corrections lie `shift` mm from the reference's, within its
/// declared error `bound` (a serving form's, as `Corrections` allows), but for leg `nan_leg`,
/// whose correction it cannot compute (not finite, as a fused form's may be where the
/// reference's is). Where the compensator trusts it, a point's unclamped corrections are its
/// bits; where a status is too close to call, the reference's.
struct Shifted {
    reference: Model,
    shift: f64,
    bound: f64,
    nan_leg: Option<usize>,
}

impl Corrections for Shifted {
    fn raw_corrections(&self, q: &[f64; 6]) -> [f64; 6] {
        let mut c = self.reference.raw_corrections(q).map(|c| c + self.shift);
        if let Some(leg) = self.nan_leg {
            c[leg] = f64::NAN;
        }
        c
    }
    fn error_bound_mm(&self) -> f64 {
        self.bound
    }
    fn reference(&self) -> &Model {
        &self.reference
    }
}

/// Who answered a point: the reference (`true`) or the shifted form (`false`), told by the
/// correction of a leg other than `leg`, left unclamped and away from the stroke ends.
fn answered_by_reference(c: &Compensated, leg: usize, reference: f64, shifted: f64) -> bool {
    let other = (leg + 1) % 6;
    assert_ne!(reference.to_bits(), shifted.to_bits());
    let corrected = [
        PointStatus::Ok,
        PointStatus::Clamped,
        PointStatus::OutsideTrainedRange,
    ];
    assert!(corrected.contains(&c.status), "{c:?}");
    match c.corrections[other] {
        v if v.to_bits() == reference.to_bits() => true,
        v if v.to_bits() == shifted.to_bits() => false,
        v => panic!("correction {v} is neither form's"),
    }
}

#[test]
fn within_twice_the_error_bound_of_a_correction_bound_the_reference_decides() {
    // Corrections 0.1 mm on every leg (the reference's, exactly: a constant network), the
    // served form's 0.1 + 5e-10 mm with an error bound of 1e-9 mm. One leg's correction bound
    // is placed 0.9 or 1.1 times twice the error bound from the served correction, above or
    // below it, on either side (the correction inside its bounds or beyond one).
    let g = Geometry::prototype();
    let (bound, shift) = (1e-9, 5e-10);
    let q = [350.0; 6];
    let served = 0.1 + shift;
    for leg in 0..6 {
        for (factor, by_reference) in [(0.9, true), (1.1, false)] {
            let d = factor * 2.0 * bound;
            for (end, at) in [
                (0, served - d),
                (0, served + d),
                (1, served + d),
                (1, served - d),
            ] {
                let mut reference = constant_model(&g, [0.1; 6], [-1.0, 1.0]);
                reference.correction_bounds[leg][end] = at;
                let form = Shifted {
                    reference,
                    shift,
                    bound,
                    nan_leg: None,
                };
                let c = compensator::compensate_legs(&g, Some(&form), &q);
                assert_eq!(
                    answered_by_reference(&c, leg, 0.1, served),
                    by_reference,
                    "leg {}, bound {end} at {at} ({factor} × 2 × error bound): {c:?}",
                    leg + 1
                );
            }
        }
    }
}

#[test]
fn within_twice_the_error_bound_and_four_ulp_of_a_stroke_end_the_reference_decides() {
    // One leg, corrected by ±0.1 mm (served: + `shift`) towards a stroke end placed beyond the
    // corrected leg by 0.9 or 1.1 times twice the error bound (1e-9 mm), or, with an error
    // bound of 1e-15 mm, by four or eight ulp of the leg (the rounding of q + Δq the
    // compensator allows for).
    let g = Geometry::prototype();
    for (bound, shift) in [(1e-9, 5e-10), (1e-15, 5e-16)] {
        for leg in 0..6 {
            for top in [false, true] {
                let mut q: [f64; 6] = [350.0; 6];
                q[leg] = if top { 429.5 } else { 280.5 };
                let mut offsets = [0.1; 6];
                offsets[leg] = if top { 0.1 } else { -0.1 };
                let corrected = q[leg] + (offsets[leg] + shift);
                let ulp = corrected.next_up() - corrected;
                let distances = if bound > 1e-12 {
                    [(1.8 * bound, true), (2.2 * bound, false)]
                } else {
                    [(4.0 * ulp, true), (8.0 * ulp, false)]
                };
                for (d, by_reference) in distances {
                    let mut narrow = g.clone();
                    if top {
                        narrow.leg_range[1] = corrected + d;
                    } else {
                        narrow.leg_range[0] = corrected - d;
                    }
                    let form = Shifted {
                        reference: constant_model(&g, offsets, [-1.0, 1.0]),
                        shift,
                        bound,
                        nan_leg: None,
                    };
                    let c = compensator::compensate_legs(&narrow, Some(&form), &q);
                    assert_eq!(
                        answered_by_reference(&c, leg, 0.1, 0.1 + shift),
                        by_reference,
                        "leg {} at {corrected}, stroke {:?}, error bound {bound:e}: {c:?}",
                        leg + 1,
                        narrow.leg_range
                    );
                }
            }
        }
    }
}

#[test]
fn a_clamped_correction_is_judged_by_its_clamped_leg_against_the_stroke_ends() {
    // One leg's correction, ±0.1 mm (served: + 5e-10 mm), is clamped to a bound ±0.05 mm
    // (towards the nominal leg): the leg that would be commanded is `q ± 0.05`, and a stroke
    // end 1e-9 mm (within twice the error bound) beyond it leaves the decision to the reference.
    // A stroke end on the unclamped leg, 0.05 mm further, is not close: the served form answers.
    let g = Geometry::prototype();
    let (bound, shift) = (1e-9, 5e-10);
    for leg in 0..6 {
        for top in [false, true] {
            let mut q: [f64; 6] = [350.0; 6];
            q[leg] = if top { 429.5 } else { 280.5 };
            let (raw, limit) = if top { (0.1, 0.05) } else { (-0.1, -0.05) };
            let mut offsets = [0.1; 6];
            offsets[leg] = raw;
            let served = raw + shift;
            let clamped_leg = q[leg] + limit;
            for (end, by_reference) in [(1e-9, true), ((served - limit).abs(), false)] {
                let mut narrow = g.clone();
                let mut reference = constant_model(&g, offsets, [-1.0, 1.0]);
                if top {
                    reference.correction_bounds[leg][1] = limit;
                    narrow.leg_range[1] = clamped_leg + end;
                } else {
                    reference.correction_bounds[leg][0] = limit;
                    narrow.leg_range[0] = clamped_leg - end;
                }
                let form = Shifted {
                    reference,
                    shift,
                    bound,
                    nan_leg: None,
                };
                let c = compensator::compensate_legs(&narrow, Some(&form), &q);
                assert_eq!(c.status, PointStatus::Clamped, "{c:?}");
                assert_eq!(c.corrections[leg], limit);
                assert_eq!(
                    answered_by_reference(&c, leg, 0.1, 0.1 + shift),
                    by_reference,
                    "leg {} clamped to {clamped_leg}, stroke {:?}: {c:?}",
                    leg + 1,
                    narrow.leg_range
                );
            }
        }
    }
}

#[test]
fn a_served_correction_that_is_not_finite_leaves_the_point_to_the_reference() {
    // The reference's corrections are finite there: the point is compensated by them, not
    // refused as invalid input. A form that is the reference (error bound 0) is not asked again.
    let g = Geometry::prototype();
    let q = [350.0; 6];
    for leg in 0..6 {
        let form = Shifted {
            reference: constant_model(&g, [0.1; 6], [-1.0, 1.0]),
            shift: 5e-10,
            bound: 1e-9,
            nan_leg: Some(leg),
        };
        let c = compensator::compensate_legs(&g, Some(&form), &q);
        assert_eq!(c.status, PointStatus::Ok, "leg {}", leg + 1);
        assert_eq!(c.corrections, [0.1; 6]);
    }
}

#[test]
fn poses_are_compensated_into_as_many_slots_as_the_shorter_side_has() {
    // Odd and even counts, more slots than poses and fewer: slot i is compensate_pose of pose i,
    // and a slot without a pose is left as it was.
    let g = Geometry::prototype();
    let m = constant_model(&g, [0.1, -0.2, 0.3, -0.4, 0.5, 2.0], [-1.0, 1.0]);
    let poses: Vec<Pose> = (0..5)
        .map(|i| {
            let i = i as f64;
            Pose::from_mm_deg([10.0 * i, -5.0 * i, 280.0 + 8.0 * i, i, -0.5 * i, 2.0 * i])
        })
        .collect();
    // Never an answer: corrections are finite or zero.
    let untouched = Compensated {
        legs: [-1.0; 6],
        corrections: [f64::INFINITY; 6],
        status: PointStatus::NoModel,
        uncertainty_mm: None,
    };
    for (pose_count, slots) in [(5, 5), (5, 3), (4, 6), (1, 1), (2, 2)] {
        let mut out = vec![untouched; slots];
        compensator::compensate_poses(&g, Some(&m), &poses[..pose_count], &mut out);
        for (i, got) in out.iter().enumerate() {
            let expected = if i < pose_count {
                compensator::compensate_pose(&g, Some(&m), &poses[i])
            } else {
                untouched
            };
            assert_eq!(
                got, &expected,
                "{pose_count} poses, {slots} slots, slot {i}"
            );
        }
    }
}
