//! What the service's tests share.

use hexacomp_core::Geometry;
use hexacomp_core::model::{Model, NetworkInput, Networks, Provenance};
use hexacomp_core::network::{Network, Normalisation};
use hexacomp_service::Generation;

/// A decoupled model for `geometry` served as generation `number`: one hidden node per leg,
/// weights `sin(i · number) · 0.01` (so models of different numbers answer differently),
/// corrections within ±1 mm, trained range 280–430 mm on every leg.
pub fn generation(geometry: &Geometry, number: u64) -> Box<Generation> {
    let network = |o: usize| {
        let n = Network::weight_count(6, o);
        Network::from_weights(
            6,
            o,
            (0..n)
                .map(|i| ((i as u64 * number) as f64).sin() * 0.01)
                .collect(),
        )
        .unwrap()
    };
    let model = Model {
        networks: Networks::Decoupled((0..6).map(|_| network(1)).collect()),
        input: NetworkInput::Equivalent,
        normalisation: Normalisation {
            mean: [355.0; 6],
            span: [140.0; 6],
        },
        training_range: [[280.0, 430.0]; 6],
        correction_bounds: [[-1.0, 1.0]; 6],
        geometry: geometry.fingerprint(),
        provenance: Provenance::default(),
        uncertainty: None,
    };
    Box::new(Generation::new(&model, number))
}
