//! Helpers shared by core's integration tests.

use hexacomp_core::Geometry;
use hexacomp_core::model::{Model, NetworkInput, Networks, Provenance};
use hexacomp_core::network::{Network, Normalisation};

/// A small decoupled model for `geometry`: three hidden nodes per leg, weights within ±0.1,
/// corrections well inside its ±1.5 mm bounds.
#[allow(dead_code)]
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
        uncertainty: None,
    }
}

/// An uncertainty whose leverage is the features' squared norm over 13 (the identity moment
/// matrix), centred on the prototype's mid stroke: σ² = 2e-5 + 3e-5 · h mm².
#[allow(dead_code)]
pub fn uncertainty() -> hexacomp_core::uncertainty::PositionUncertainty {
    use hexacomp_core::uncertainty::{FEATURES, PositionUncertainty};
    let scale = 1.0 / (FEATURES as f64).sqrt();
    let whitening = (0..FEATURES)
        .flat_map(|r| (0..=r).map(move |c| if r == c { scale } else { 0.0 }))
        .collect();
    PositionUncertainty {
        centre_mm: [355.0; 6],
        half_span_mm: [60.0; 6],
        whitening,
        constant_variance_mm2: 2e-5,
        leverage_variance_mm2: 3e-5,
    }
}
