//! Helpers shared by core's integration tests.

use hexacomp_core::Geometry;
use hexacomp_core::model::{Model, NetworkInput, Networks, Provenance};
use hexacomp_core::network::{Network, Normalisation};

/// A small decoupled model for `geometry`: three hidden nodes per leg, weights within ±0.1,
/// corrections well inside its ±1.5 mm bounds.
pub fn model(geometry: &Geometry) -> Model {
    let network = |seed: f64| {
        let count = Network::weight_count(3, 1);
        Network::from_weights(
            3,
            1,
            (0..count)
                .map(|i| (i as f64 * 0.37 + seed).sin() * 0.1)
                .collect(),
        )
        .unwrap()
    };
    Model {
        networks: Networks::Decoupled((0..6).map(|i| network(i as f64)).collect()),
        input: NetworkInput::Equivalent,
        normalisation: Normalisation {
            mean: [355.0; 6],
            span: [140.0; 6],
        },
        training_range: [[282.0, 428.0]; 6],
        correction_bounds: [[-1.5, 1.5]; 6],
        geometry: geometry.fingerprint(),
        provenance: Provenance {
            created_unix_s: 1_790_000_000,
            configurations: 150,
            training_samples: 150,
            validation_samples: 50,
            validation_rmse_mm: 0.0462,
            source: "test".into(),
        },
    }
}
