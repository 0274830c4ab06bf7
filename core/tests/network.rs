//! Networks and models against hand computation: the three-layer network of Eq. 10, Eq. 11 and Eq. 12, the input
//! normalisation of Eq. 13 (and its refusals), which network a decoupled model uses for which
//! leg, and the checks a model must pass before it is used.

mod common;

use common::model;
use hexacomp_core::Geometry;
use hexacomp_core::error::Error;
use hexacomp_core::model::{Model, NetworkInput, Networks};
use hexacomp_core::network::{MAX_HIDDEN, Network, Normalisation};

/// The weights of a 2-hidden-node, 2-output network in the documented order: `w1` (2 × 6,
/// row-major), `b1`, `w2` (2 × 2, row-major), `b2`.
const W1: [[f64; 6]; 2] = [
    [0.5, -0.25, 0.0, 0.125, 1.0, -1.0],
    [-0.75, 0.0, 0.5, 0.25, 0.0, 2.0],
];
const B1: [f64; 2] = [0.1, -0.2];
const W2: [[f64; 2]; 2] = [[1.5, -2.0], [0.25, 3.5]];
const B2: [f64; 2] = [0.05, -0.5];

fn two_by_two() -> Network {
    let mut w: Vec<f64> = W1.iter().flatten().copied().collect();
    w.extend(B1);
    w.extend(W2.iter().flatten());
    w.extend(B2);
    Network::from_weights(2, 2, w).unwrap()
}

/// Eq. 10, Eq. 11 and Eq. 12 written out: `y_k = b2_k + Σ_j w2_kj · tanh(b1_j + Σ_i w1_ji · x_i)`.
fn by_hand(x: &[f64; 6]) -> ([f64; 2], [f64; 2]) {
    let hidden = [0, 1].map(|j| (B1[j] + (0..6).map(|i| W1[j][i] * x[i]).sum::<f64>()).tanh());
    let out = [0, 1].map(|k| B2[k] + W2[k][0] * hidden[0] + W2[k][1] * hidden[1]);
    (hidden, out)
}

#[test]
fn a_network_computes_eq_10_with_its_weights_in_the_documented_order() {
    let n = two_by_two();
    assert_eq!((n.hidden(), n.outputs()), (2, 2));
    assert_eq!(Network::weight_count(2, 2), 12 + 2 + 4 + 2);
    assert_eq!(n.weights().len(), 20);
    for x in [
        [0.0; 6],
        [0.3, -0.1, 0.2, 0.4, -0.5, 0.05],
        [-0.5, 0.5, -0.5, 0.5, -0.5, 0.5],
    ] {
        let (hidden, expected) = by_hand(&x);
        let mut out = [f64::NAN; 2];
        n.evaluate(&x, &mut out);
        for k in 0..2 {
            assert!(
                (out[k] - expected[k]).abs() < 1e-14,
                "{x:?}: {out:?} vs {expected:?}"
            );
        }
        let mut h = [f64::NAN; MAX_HIDDEN];
        n.hidden_layer(&x, &mut h);
        for j in 0..2 {
            assert!((h[j] - hidden[j]).abs() < 1e-15, "{x:?}: hidden {j}");
        }
        assert!(
            h[2..].iter().all(|v| v.is_nan()),
            "only the hidden nodes are written"
        );
    }
}

/// Each output's `Σ_j |w2_kj| · ‖w1_j ⊘ span‖`, from the weight vector in the documented order;
/// the documented bound is their maximum.
fn output_slopes(hidden: usize, outputs: usize, w: &[f64], span: &[f64; 6]) -> Vec<f64> {
    let w1 = |j: usize, i: usize| w[j * 6 + i];
    let w2 = |k: usize, j: usize| w[hidden * 6 + hidden + k * hidden + j];
    let gain = |j: usize| {
        (0..6)
            .map(|i| (w1(j, i) / span[i]).powi(2))
            .sum::<f64>()
            .sqrt()
    };
    (0..outputs)
        .map(|k| (0..hidden).map(|j| w2(k, j).abs() * gain(j)).sum::<f64>())
        .collect()
}

fn max_slope_by_hand(hidden: usize, outputs: usize, w: &[f64], span: &[f64; 6]) -> f64 {
    output_slopes(hidden, outputs, w, span)
        .into_iter()
        .fold(0.0, f64::max)
}

#[test]
fn max_slope_is_the_documented_bound_for_every_output_and_hidden_node() {
    let span = [10.0, 20.0, 40.0, 5.0, 10.0, 20.0];
    // The 2 × 2 network: the second output has the larger bound, so every output counts.
    let n = two_by_two();
    let slopes = output_slopes(2, 2, n.weights(), &span);
    assert!(slopes[1] > slopes[0], "{slopes:?}");
    assert!((n.max_slope(&span) - slopes[1]).abs() < 1e-15);
    // Networks of other shapes, with more outputs than hidden nodes and the reverse.
    for (hidden, outputs) in [(3, 5), (5, 3), (7, 1), (1, 6)] {
        let w: Vec<f64> = (0..Network::weight_count(hidden, outputs))
            .map(|i| (i as f64 * 0.83 + 0.2).sin())
            .collect();
        let n = Network::from_weights(hidden, outputs, w.clone()).unwrap();
        let expected = max_slope_by_hand(hidden, outputs, &w, &span);
        let slope = n.max_slope(&span);
        assert!(
            (slope - expected).abs() < 1e-14 * expected,
            "{hidden} × {outputs}: {slope} vs {expected}"
        );
    }
}

#[test]
fn normalisation_is_each_legs_mean_and_span() {
    let samples = [
        [300.0, 350.0, 400.0, 320.0, 330.0, 340.0],
        [310.0, 340.0, 380.0, 320.5, 330.0, 300.0],
        [305.0, 345.0, 390.0, 322.0, 336.0, 340.0],
        [301.0, 355.0, 410.0, 321.0, 330.0, 320.0],
    ];
    let n = Normalisation::of(&samples).unwrap();
    let mean = [304.0, 347.5, 395.0, 320.875, 331.5, 325.0];
    let span = [10.0, 15.0, 30.0, 2.0, 6.0, 40.0];
    for i in 0..6 {
        assert!((n.mean[i] - mean[i]).abs() < 1e-12, "mean of leg {}", i + 1);
        assert_eq!(n.span[i], span[i], "span of leg {}", i + 1);
    }
    // Eq. 13: (q − mean) / span.
    let q = [314.0, 347.5, 380.0, 321.875, 328.5, 345.0];
    let x = n.apply(&q);
    let expected = [1.0, 0.0, -0.5, 0.5, -0.5, 0.5];
    for i in 0..6 {
        assert!(
            (x[i] - expected[i]).abs() < 1e-12,
            "leg {}: {}",
            i + 1,
            x[i]
        );
    }
}

#[test]
fn normalisation_refuses_fewer_than_two_samples() {
    for samples in [&[][..], &[[350.0; 6]][..]] {
        match Normalisation::of(samples) {
            Err(Error::InvalidModel(m)) => assert!(m.contains("two samples"), "{m}"),
            other => panic!(
                "{} samples: expected a refusal, got {other:?}",
                samples.len()
            ),
        }
    }
    // Two samples that vary on every leg are enough.
    Normalisation::of(&[[350.0; 6], [351.0; 6]]).unwrap();
}

#[test]
fn normalisation_refuses_a_leg_that_never_varies() {
    for leg in 0..6 {
        let samples: Vec<[f64; 6]> = (0..5)
            .map(|s| {
                let mut q = [300.0 + s as f64; 6];
                q[leg] = 355.0;
                q
            })
            .collect();
        match Normalisation::of(&samples) {
            Err(Error::InvalidModel(m)) => {
                assert!(m.contains(&format!("leg {}", leg + 1)), "{m}");
                assert!(m.contains("does not vary"), "{m}");
            }
            other => panic!(
                "leg {} constant: expected a refusal, got {other:?}",
                leg + 1
            ),
        }
    }
}

#[test]
fn a_decoupled_model_uses_network_i_for_leg_i_on_normalised_legs() {
    let g = Geometry::prototype();
    let m = model(&g);
    let Networks::Decoupled(nets) = &m.networks else {
        panic!("the test model is decoupled")
    };
    let q = [300.0, 320.0, 340.0, 360.0, 380.0, 400.0];
    let x: [f64; 6] = std::array::from_fn(|i| (q[i] - 355.0) / 140.0);
    let raw = m.raw_corrections(&q);
    for (leg, n) in nets.iter().enumerate() {
        let mut out = [0.0];
        n.evaluate(&x, &mut out);
        assert_eq!(raw[leg], out[0], "leg {}", leg + 1);
    }
    // The networks differ, so a mix-up would show.
    assert!(raw.windows(2).all(|w| w[0] != w[1]), "{raw:?}");
    assert_eq!(m.hidden_nodes(), vec![3; 6]);
}

#[test]
fn a_coupled_model_gives_output_k_to_leg_k() {
    let g = Geometry::prototype();
    let count = Network::weight_count(5, 6);
    let w = (0..count).map(|i| (i as f64 * 0.61).cos() * 0.2).collect();
    let n = Network::from_weights(5, 6, w).unwrap();
    let m = Model {
        networks: Networks::Coupled(n.clone()),
        input: NetworkInput::Commanded,
        ..model(&g)
    };
    m.validate().unwrap();
    let q = [300.0, 320.0, 340.0, 360.0, 380.0, 400.0];
    let mut out = [0.0; 6];
    n.evaluate(&m.normalisation.apply(&q), &mut out);
    assert_eq!(m.raw_corrections(&q), out);
    assert_eq!(m.hidden_nodes(), vec![5]);
}

#[test]
fn network_input_names_are_the_command_line_words() {
    assert_eq!(NetworkInput::Commanded.name(), "commanded");
    assert_eq!(NetworkInput::Equivalent.name(), "equivalent");
}

#[test]
fn a_model_with_inconsistent_networks_or_normalisation_is_refused() {
    let g = Geometry::prototype();
    model(&g).validate().unwrap();
    let refused = |m: Model, what: &str| match m.validate() {
        Err(Error::InvalidModel(_)) => {}
        other => panic!("{what}: expected a refusal, got {other:?}"),
    };
    // A coupled network needs six outputs.
    let five = Network::from_weights(2, 5, vec![0.1; Network::weight_count(2, 5)]).unwrap();
    refused(
        Model {
            networks: Networks::Coupled(five),
            ..model(&g)
        },
        "coupled with five outputs",
    );
    // Decoupled: six networks of one output each.
    let one = Network::from_weights(2, 1, vec![0.1; Network::weight_count(2, 1)]).unwrap();
    let two = Network::from_weights(2, 2, vec![0.1; Network::weight_count(2, 2)]).unwrap();
    let mut nets = vec![one.clone(); 6];
    nets[4] = two;
    refused(
        Model {
            networks: Networks::Decoupled(nets),
            ..model(&g)
        },
        "decoupled with a two-output network",
    );
    refused(
        Model {
            networks: Networks::Decoupled(vec![one; 5]),
            ..model(&g)
        },
        "five decoupled networks",
    );
    // The normalisation: finite means, finite and positive spans, each checked on its own.
    for (field, leg, value) in [
        ("mean", 2, f64::NAN),
        ("mean", 5, f64::INFINITY),
        ("span", 0, f64::INFINITY),
        ("span", 3, 0.0),
        ("span", 1, -1.0),
    ] {
        let mut m = model(&g);
        match field {
            "mean" => m.normalisation.mean[leg] = value,
            _ => m.normalisation.span[leg] = value,
        }
        refused(m, &format!("{field}[{leg}] = {value}"));
    }
    // Ranges must be finite and ordered; an empty-width range is allowed.
    let mut m = model(&g);
    m.training_range[4] = [350.0, 350.0];
    m.correction_bounds[1] = [0.0, 0.0];
    m.validate().unwrap();
    let mut m = model(&g);
    m.training_range[4] = [351.0, 350.0];
    refused(m, "reversed training range");
    let mut m = model(&g);
    m.training_range[0] = [f64::NEG_INFINITY, 350.0];
    refused(m, "infinite training range");
    let mut m = model(&g);
    m.correction_bounds[5] = [-1.0, f64::NAN];
    refused(m, "NaN correction bound");
}
