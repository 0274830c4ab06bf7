//! The fused serving form of a model against the reference evaluation, over the whole workspace
//! and at its edges: random coupled and decoupled models of every size the trainer makes, with
//! training ranges and correction bounds narrow enough that every status occurs. Each point's
//! legs and corrections must agree within 1 nm (the bound; the differences seen are
//! about 1e-15 mm) and its status must be the same.
//!
//! Deeper runs: `PROPTEST_CASES=2000 cargo test --release -p hexacomp-core --test fused`.

use std::cell::RefCell;

use hexacomp_core::compensator::{self, Compensated, Corrections, PointStatus, compensate_pose};
use hexacomp_core::fused::{FusedModel, MAX_ERROR_MM};
use hexacomp_core::model::{Model, NetworkInput, Networks, Provenance};
use hexacomp_core::network::{Network, Normalisation};
use hexacomp_core::sampling::{SamplerOptions, WorkspaceSampler};
use hexacomp_core::{Geometry, Pose, inverse_kinematics};
use proptest::prelude::*;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// The bound the fast path must keep, mm (1 nm).
const AGREEMENT_MM: f64 = 1e-6;

/// A network of `hidden` nodes and `outputs` outputs: input weights of scale `input_scale`
/// (large scales saturate the activations), output weights within ±0.05 mm.
fn network(rng: &mut ChaCha8Rng, hidden: usize, outputs: usize, input_scale: f64) -> Network {
    let mut weights = Vec::with_capacity(Network::weight_count(hidden, outputs));
    for _ in 0..hidden * 6 + hidden {
        weights.push(input_scale * rng.random_range(-1.0..1.0));
    }
    for _ in 0..outputs * hidden + outputs {
        weights.push(rng.random_range(-0.05..0.05));
    }
    Network::from_weights(hidden, outputs, weights).unwrap()
}

/// A random model for `geometry`: coupled or decoupled, 1–64 hidden nodes per network, trained
/// over the legs 300–410 mm of the 280–430 mm stroke, corrections bounded to ±0.08 mm.
fn random_model(geometry: &Geometry, seed: u64, coupled: bool, input_scale: f64) -> Model {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let networks = if coupled {
        let hidden = rng.random_range(1..=64);
        Networks::Coupled(network(&mut rng, hidden, 6, input_scale))
    } else {
        Networks::Decoupled(
            (0..6)
                .map(|_| {
                    let hidden = rng.random_range(1..=24);
                    network(&mut rng, hidden, 1, input_scale)
                })
                .collect(),
        )
    };
    let model = Model {
        networks,
        input: NetworkInput::Equivalent,
        normalisation: Normalisation {
            mean: std::array::from_fn(|_| rng.random_range(340.0..370.0)),
            span: std::array::from_fn(|_| rng.random_range(80.0..150.0)),
        },
        training_range: [[300.0, 410.0]; 6],
        correction_bounds: [[-0.08, 0.08]; 6],
        geometry: geometry.fingerprint(),
        provenance: Provenance::default(),
        uncertainty: None,
    };
    model.validate().unwrap();
    model
}

/// Poses on the workspace's edge: from the home pose towards `pose` and beyond, the last pose
/// (to the bisection's resolution, about 1e-15 of the way) whose legs are all in the stroke, and
/// the first whose legs are not.
fn edge_poses(geometry: &Geometry, pose: &Pose) -> [Pose; 2] {
    let home = geometry.home_pose().to_mm_deg();
    let target = pose.to_mm_deg();
    let along =
        |t: f64| Pose::from_mm_deg(std::array::from_fn(|i| home[i] + t * (target[i] - home[i])));
    let inside = |t: f64| hexacomp_core::inverse_kinematics(geometry, &along(t)).all_in_stroke();
    let (mut lo, mut hi) = (0.0, 1.0);
    while inside(hi) {
        (lo, hi) = (hi, 2.0 * hi);
    }
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if mid == lo || mid == hi {
            break;
        }
        if inside(mid) { lo = mid } else { hi = mid }
    }
    [along(lo), along(hi)]
}

/// The largest difference seen between the two forms, and how many points had each status.
#[derive(Default)]
struct Seen {
    largest_mm: f64,
    statuses: [usize; 6],
}

/// Checks one point: the same status, corrections within the fused form's own error `bound`
/// (its legs too, but for the rounding of `q + Δq`), and both within 1 nm.
fn check(
    seen: &RefCell<Seen>,
    reference: &Compensated,
    fused: &Compensated,
    bound: f64,
    pose: &Pose,
) {
    assert_eq!(reference.status, fused.status, "at {pose:?}");
    let mut seen = seen.borrow_mut();
    for (a, b, allowed) in [
        (reference.legs, fused.legs, bound + 1e-12),
        (reference.corrections, fused.corrections, bound),
    ] {
        for (x, y) in a.iter().zip(b) {
            let difference = if x.to_bits() == y.to_bits() {
                0.0
            } else {
                (x - y).abs()
            };
            assert!(
                difference <= allowed && difference <= AGREEMENT_MM,
                "{a:?} and {b:?} at {pose:?} (bound {bound:e} mm)"
            );
            seen.largest_mm = seen.largest_mm.max(difference);
        }
    }
    seen.statuses[reference.status as usize] += 1;
}

#[test]
fn the_fused_form_agrees_with_the_reference_over_the_workspace_and_at_its_edges() {
    let g = Geometry::prototype();
    let seen = RefCell::new(Seen::default());
    proptest!(ProptestConfig::with_cases(64), |(
        model_seed in any::<u64>(),
        pose_seed in any::<u64>(),
        coupled in any::<bool>(),
        input_scale in prop::sample::select(vec![0.3, 2.0, 20.0]),
    )| {
        let model = random_model(&g, model_seed, coupled, input_scale);
        let fused = FusedModel::new(&model);
        let poses = WorkspaceSampler::new(&g, pose_seed, SamplerOptions { stroke_margin_mm: 0.0, ..SamplerOptions::default() })
            .unwrap()
            .samples(50)
            .unwrap();
        for pose in &poses {
            for p in std::iter::once(*pose).chain(edge_poses(&g, pose)) {
                check(
                    &seen,
                    &compensate_pose(&g, Some(&model), &p),
                    &compensate_pose(&g, Some(&fused), &p),
                    fused.error_bound_mm(),
                    &p,
                );
            }
        }
    });
    let seen = seen.into_inner();
    eprintln!(
        "largest difference {:e} mm; statuses {:?}",
        seen.largest_mm, seen.statuses
    );
    // The scenario happened: points of every status a model decides were compared.
    for status in [
        PointStatus::Ok,
        PointStatus::Clamped,
        PointStatus::OutsideTrainedRange,
        PointStatus::OutOfStroke,
    ] {
        assert!(
            seen.statuses[status as usize] > 0,
            "no point was {status:?}"
        );
    }
}

#[test]
fn at_a_correction_bound_the_reference_decides_the_status() {
    // A correction bound placed exactly on the reference's answer: the fused value lies up to
    // its error bound on either side of it (it differs from the reference in the last bit at
    // about four points in ten), so without the reference deciding there, many of these points
    // would be clamped in one form and not in the other.
    let g = Geometry::prototype();
    let mut decided_by_the_model = 0;
    for seed in 0..24 {
        let mut model = random_model(&g, seed, seed % 2 == 0, 2.0);
        model.correction_bounds = [[-1.0, 1.0]; 6];
        let poses = WorkspaceSampler::new(&g, seed, SamplerOptions::default())
            .unwrap()
            .samples(20)
            .unwrap();
        for pose in &poses {
            let q = inverse_kinematics(&g, pose).lengths;
            for (k, c) in model.raw_corrections(&q).into_iter().enumerate() {
                let mut at_bound = model.clone();
                at_bound.correction_bounds[k] = [c - 0.5, c];
                let fused = FusedModel::new(&at_bound);
                let (a, b) = (
                    compensate_pose(&g, Some(&at_bound), pose),
                    compensate_pose(&g, Some(&fused), pose),
                );
                assert_eq!(a.status, b.status, "at {pose:?}, leg {}", k + 1);
                assert_eq!(a.legs, b.legs, "at {pose:?}, leg {}", k + 1);
                decided_by_the_model += usize::from(a.status == PointStatus::Ok);
            }
        }
    }
    // The scenario happened: the points reached the model and were not clamped.
    assert!(decided_by_the_model > 500, "{decided_by_the_model}");
}

#[test]
fn at_a_stroke_end_the_reference_decides_the_status() {
    // Where the two forms' corrections, a last bit apart, round to different corrected legs
    // (rare: a few in ten thousand), a stroke end placed on the lower of the two sends the other
    // out of stroke, unless the reference decides there.
    let g = Geometry::prototype();
    let mut found = 0;
    for seed in 0..1000 {
        let model = random_model(&g, seed, seed % 2 == 0, 2.0);
        let fused = FusedModel::new(&model);
        let poses = WorkspaceSampler::new(&g, seed, SamplerOptions::default())
            .unwrap()
            .samples(100)
            .unwrap();
        for pose in &poses {
            let q = inverse_kinematics(&g, pose).lengths;
            let (raw, fused_raw) = (model.raw_corrections(&q), fused.raw_corrections(&q));
            for k in 0..6 {
                let (a, b) = (q[k] + raw[k], q[k] + fused_raw[k]);
                let end = a.min(b);
                // Only where leg k alone decides: its correction not clamped (bounds ±0.08 mm),
                // every other leg below the end, nominal and corrected, in both forms.
                let others_below = (0..6)
                    .filter(|&j| j != k)
                    .all(|j| q[j] < end && q[j] + raw[j] < end && q[j] + fused_raw[j] < end);
                if a == b || raw[k].abs() >= 0.08 || !others_below {
                    continue;
                }
                let mut at_stroke_end = g.clone();
                at_stroke_end.leg_range[1] = end;
                let (r, f) = (
                    compensate_pose(&at_stroke_end, Some(&model), pose),
                    compensate_pose(&at_stroke_end, Some(&fused), pose),
                );
                assert_eq!(r.status, f.status, "at {pose:?}, leg {}", k + 1);
                assert_eq!(r.legs, f.legs, "at {pose:?}, leg {}", k + 1);
                found += 1;
            }
        }
    }
    // The scenario happened: points whose corrected legs differ between the forms, decided at
    // the stroke end by that leg alone.
    assert!(found >= 3, "{found}");
}

#[test]
fn through_the_compensators_trait_the_reference_has_no_error_and_the_fused_form_its_bound() {
    // `Corrections::error_bound_mm` is how far a form's corrections may lie from the reference's
    // (0: it is the reference). The reference lies exactly 0 mm from itself; the fused form's
    // bound covers its differences seen at workspace points and stays within 1 nm, above which
    // the reference answers instead (bound 0, the same bits as the reference).
    let g = Geometry::prototype();
    for seed in 0..8 {
        let model = random_model(&g, seed, seed % 2 == 0, 2.0);
        assert_eq!(Corrections::error_bound_mm(&model), 0.0, "seed {seed}");
        let fused = FusedModel::new(&model);
        let bound = Corrections::error_bound_mm(&fused);
        assert_eq!(bound, fused.error_bound_mm(), "seed {seed}");
        assert!(
            bound > 0.0 && bound <= MAX_ERROR_MM,
            "seed {seed}: {bound:e}"
        );
        let poses = WorkspaceSampler::new(&g, seed, SamplerOptions::default())
            .unwrap()
            .samples(50)
            .unwrap();
        for pose in &poses {
            let q = inverse_kinematics(&g, pose).lengths;
            let (fast, reference) = (fused.raw_corrections(&q), model.raw_corrections(&q));
            for k in 0..6 {
                assert!(
                    (fast[k] - reference[k]).abs() <= bound,
                    "{q:?}, leg {}",
                    k + 1
                );
            }
        }
    }
    // Output weights scaled by 1e11 (up to 5e9 mm): a bound far beyond 1 nm, so the fused form
    // leaves every point to the reference and has none of its own.
    let mut large = random_model(&g, 1, true, 2.0);
    if let Networks::Coupled(network) = &large.networks {
        let mut weights = network.weights().to_vec();
        let w2 = network.hidden() * 6 + network.hidden();
        for w in &mut weights[w2..w2 + 6 * network.hidden()] {
            *w *= 1e11;
        }
        large.networks =
            Networks::Coupled(Network::from_weights(network.hidden(), 6, weights).unwrap());
    }
    large.validate().unwrap();
    let fused_large = FusedModel::new(&large);
    assert_eq!(Corrections::error_bound_mm(&fused_large), 0.0);
}

#[test]
fn away_from_every_threshold_the_fused_form_serves_its_own_corrections() {
    // The reference is asked only where a fused correction lies within twice the bound of a
    // correction bound or of a stroke end (module doc of `fused`). Elsewhere the compensated
    // point carries the fused evaluation's own bits, which differ from the reference's in the
    // last bit at many points: there the answer shows which of the two computed it.
    let g = Geometry::prototype();
    let mut told_apart = 0;
    for seed in 0..24 {
        let model = random_model(&g, seed, seed % 2 == 0, 2.0);
        let fused = FusedModel::new(&model);
        let [lo, hi] = g.leg_range;
        let poses = WorkspaceSampler::new(&g, seed, SamplerOptions::default())
            .unwrap()
            .samples(50)
            .unwrap();
        for pose in &poses {
            let q = inverse_kinematics(&g, pose).lengths;
            let own = fused.raw_corrections(&q);
            // Far (1e-9 mm, a thousand times the bound and more) from every threshold.
            let far = (0..6).all(|k| {
                let [cl, ch] = model.correction_bounds[k];
                let leg = q[k] + own[k];
                own[k] - cl > 1e-9 && ch - own[k] > 1e-9 && leg - lo > 1e-9 && hi - leg > 1e-9
            });
            if !far {
                continue;
            }
            let home = inverse_kinematics(&g, &g.home_pose()).lengths;
            let alone = compensator::compensate_legs(&g, Some(&fused), &q);
            let paired = compensator::compensate_legs_pair(&g, Some(&fused), [&q, &home])[0];
            for c in [alone, paired] {
                assert_eq!(
                    c.corrections.map(f64::to_bits),
                    own.map(f64::to_bits),
                    "{q:?}"
                );
                assert_eq!(c.legs, std::array::from_fn(|k| q[k] + own[k]), "{q:?}");
            }
            told_apart += usize::from(own != model.raw_corrections(&q));
        }
    }
    eprintln!("{told_apart} points where the two forms' corrections differ");
    // The scenario happened: points where the two forms' corrections differ.
    assert!(told_apart > 50, "{told_apart}");
}
