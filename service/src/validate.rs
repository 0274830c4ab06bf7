//! Validation of a deployed model, off the serving thread: format, checksum, geometry
//! fingerprint, finite weights (the model file reader), no jumps between neighbouring points
//! (a bound valid everywhere), then the model's outputs over the configurations the platform
//! reaches.

use hexacomp_core::model::Model;

use crate::Refusal;
use hexacomp_core::sampling::{SamplerOptions, WorkspaceSampler};
use hexacomp_core::{Geometry, LEGS, inverse_kinematics};

/// Poses sampled uniformly over the geometry's workspace.
const SAMPLES: usize = 4096;
/// Samples checked between two yields of the core (about 20 µs of work).
const SAMPLES_PER_SLICE: usize = 64;
/// Largest fraction of sampled configurations whose raw correction may exceed the bounds (the
/// bounds are the training data's extremes with a margin, the clamp covers the rest).
const OUT_OF_BOUNDS_FRACTION: f64 = 0.05;
/// Neighbouring points: leg vectors this far apart (Euclidean), mm. At a 1 kHz servo period, a
/// leg moving 100 mm/s travels this far between two commands.
pub const NEIGHBOUR_MM: f64 = 0.1;
/// Largest change of any correction between neighbouring points, mm. The models trained here
/// stay below a fifth of it (`max_slope` 0.026–0.092 mm/mm, i.e. 0.003–0.009 mm per 0.1 mm).
pub const MAX_JUMP_MM: f64 = 0.05;

/// Decodes and checks a model file's bytes for `geometry`; the error says why it is refused.
///
/// Yields the core every few dozen samples: with `--wait spin` on a small machine, the serving
/// thread and the NC's client may hold every core, and validation then takes only short slices
/// from them instead of a scheduler time slice of milliseconds.
pub fn validate(bytes: &[u8], geometry: &Geometry) -> Result<Model, Refusal> {
    let model = Model::from_bytes(bytes).map_err(Refusal::File)?;
    if model.geometry != geometry.fingerprint() {
        return Err(Refusal::OtherGeometry {
            model: model.geometry.to_string(),
            served: geometry.fingerprint().to_string(),
            name: geometry.name.clone(),
        });
    }
    let jump = model.max_slope() * NEIGHBOUR_MM;
    if jump.is_nan() || jump > MAX_JUMP_MM {
        return Err(Refusal::Jumps {
            jump_mm: jump,
            neighbour_mm: NEIGHBOUR_MM,
            max_jump_mm: MAX_JUMP_MM,
        });
    }
    // The legs of workspace poses, not the training-range box: most of the six-dimensional box
    // is leg combinations no pose has, where a network extrapolates freely and is never asked.
    let mut poses = WorkspaceSampler::new(geometry, 0x6865_7861, SamplerOptions::default())
        .map_err(Refusal::Unsampleable)?;
    let mut outside = 0usize;
    let mut checked = 0usize;
    for sample in 0..SAMPLES {
        if sample % SAMPLES_PER_SLICE == 0 {
            std::thread::yield_now();
        }
        let pose = poses.sample().map_err(Refusal::Unsampleable)?;
        let q = inverse_kinematics(geometry, &pose).lengths;
        let trained = (0..LEGS).all(|i| {
            let [lo, hi] = model.training_range[i];
            (lo..=hi).contains(&q[i])
        });
        if !trained {
            continue; // answered "outside trained range", never computed
        }
        checked += 1;
        let dq = model.raw_corrections(&q);
        if dq.iter().any(|d| !d.is_finite()) {
            return Err(Refusal::NonFinite { legs_mm: q });
        }
        let beyond = (0..LEGS).any(|i| {
            let [lo, hi] = model.correction_bounds[i];
            dq[i] < lo || dq[i] > hi
        });
        outside += usize::from(beyond);
    }
    let fraction = outside as f64 / checked.max(1) as f64;
    if fraction > OUT_OF_BOUNDS_FRACTION {
        return Err(Refusal::BeyondBounds {
            percent: 100.0 * fraction,
        });
    }
    Ok(model)
}

#[cfg(test)]
mod tests {
    use super::*;
    use hexacomp_core::model::{NetworkInput, Networks, Provenance};
    use hexacomp_core::network::{Network, Normalisation};

    /// A decoupled model whose six networks have one hidden node with weights `w`.
    fn one_node_model(geometry: &Geometry, w: [f64; 9]) -> Model {
        Model {
            networks: Networks::Decoupled(
                (0..LEGS)
                    .map(|_| Network::from_weights(1, 1, w.to_vec()).unwrap())
                    .collect(),
            ),
            input: NetworkInput::Equivalent,
            normalisation: Normalisation {
                mean: [355.0; LEGS],
                span: [140.0; LEGS],
            },
            training_range: [[290.0, 420.0]; LEGS],
            correction_bounds: [[-1.0, 1.0]; LEGS],
            geometry: geometry.fingerprint(),
            provenance: Provenance::default(),
            uncertainty: None,
        }
    }

    #[test]
    fn a_smooth_model_is_accepted() {
        let g = Geometry::prototype();
        let model = one_node_model(&g, [1.0, 0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.3, 0.0]);
        assert!(validate(&model.to_bytes(), &g).is_ok());
    }

    #[test]
    fn a_step_inside_the_range_is_refused_even_where_no_sample_lands() {
        let g = Geometry::prototype();
        // tanh(5000 · x) steps by 0.6 mm within ±0.03 mm of leg 1's mid-range, and stays
        // inside the correction bounds everywhere: only the jump bound can see it.
        let model = one_node_model(&g, [5000.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.3, 0.0]);
        let why = validate(&model.to_bytes(), &g).unwrap_err();
        assert!(matches!(why, Refusal::Jumps { .. }), "{why}");
    }

    #[test]
    fn a_model_whose_output_overflows_is_refused() {
        let g = Geometry::prototype();
        // Finite weights, flat (no slope), but b2 + w2 · tanh(10) overflows to infinity.
        let model = one_node_model(&g, [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 10.0, f64::MAX, f64::MAX]);
        let why = validate(&model.to_bytes(), &g).unwrap_err();
        assert!(matches!(why, Refusal::NonFinite { .. }), "{why}");
    }

    #[test]
    fn a_model_beyond_its_own_bounds_over_its_range_is_refused() {
        let g = Geometry::prototype();
        let model = one_node_model(&g, [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 2.0]);
        let why = validate(&model.to_bytes(), &g).unwrap_err();
        assert!(matches!(why, Refusal::BeyondBounds { .. }), "{why}");
    }
}
