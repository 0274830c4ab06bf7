//! Validation of a deployed model, off the serving thread: format, checksum, geometry
//! fingerprint, finite weights (the model file reader), then the model's outputs over its
//! training range.

use hexacomp_core::model::Model;
use hexacomp_core::{Geometry, LEGS};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Points sampled uniformly in the training-range box.
const SAMPLES: usize = 4096;
/// Samples checked between two yields of the core (about 20 µs of work).
const SAMPLES_PER_SLICE: usize = 64;
/// Largest fraction of box samples whose raw correction may exceed the bounds (corners of the
/// six-dimensional box are configurations the platform never reaches; the clamp covers them).
const OUT_OF_BOUNDS_FRACTION: f64 = 0.05;

/// Decodes and checks a model file's bytes for `geometry`; the error says why it is refused.
///
/// Yields the core every few dozen samples: with `--wait spin` on a small machine, the serving
/// thread and the NC's client may hold every core, and validation then takes only short slices
/// from them instead of a scheduler time slice of milliseconds.
pub fn validate(bytes: &[u8], geometry: &Geometry) -> Result<Model, String> {
    let model = Model::from_bytes(bytes).map_err(|p| p.to_string())?;
    if model.geometry != geometry.fingerprint() {
        return Err(format!(
            "trained for geometry {}, the service serves {} ({})",
            model.geometry,
            geometry.fingerprint(),
            geometry.name
        ));
    }
    let mut rng = ChaCha8Rng::seed_from_u64(0x6865_7861);
    let mut outside = 0usize;
    for sample in 0..SAMPLES {
        if sample % SAMPLES_PER_SLICE == 0 {
            std::thread::yield_now();
        }
        let q: [f64; LEGS] = std::array::from_fn(|i| {
            let [lo, hi] = model.training_range[i];
            lo + (hi - lo) * rng.random::<f64>()
        });
        let dq = model.raw_corrections(&q);
        if dq.iter().any(|d| !d.is_finite()) {
            return Err(format!("non-finite correction at legs {q:?}"));
        }
        let beyond = (0..LEGS).any(|i| {
            let [lo, hi] = model.correction_bounds[i];
            dq[i] < lo || dq[i] > hi
        });
        outside += usize::from(beyond);
    }
    let fraction = outside as f64 / SAMPLES as f64;
    if fraction > OUT_OF_BOUNDS_FRACTION {
        return Err(format!(
            "corrections exceed the model's own bounds at {:.1} % of its training range",
            100.0 * fraction
        ));
    }
    Ok(model)
}
