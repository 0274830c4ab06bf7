//! The simulated instrument's set-up: where it stands in the base frame, and the fiducials on the
//! machine base as it measures them there.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use hexacomp_core::error::{Error, Result};
use hexacomp_core::pose::Pose;
use hexacomp_core::records::NamedPoint;

use crate::machine::normal3;

/// The `nominal` fiducials (base frame, mm) as the instrument at `instrument` measures them: in
/// its frame, each coordinate with independent Gaussian noise of `sigma_mm`, drawn from
/// `seed` (the same seed gives the same readings). Weights are 1.
pub fn measure_fiducials(
    nominal: &[NamedPoint],
    instrument: &Pose,
    sigma_mm: f64,
    seed: u64,
) -> Result<Vec<NamedPoint>> {
    if !(sigma_mm.is_finite() && sigma_mm >= 0.0) {
        return Err(Error::InvalidSetting(format!(
            "fiducial noise {sigma_mm} mm: a finite number ≥ 0 is needed"
        )));
    }
    if !instrument.is_finite() {
        return Err(Error::NonFinite("instrument pose"));
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let into_instrument = instrument.inverse();
    Ok(nominal
        .iter()
        .map(|point| NamedPoint {
            name: point.name.clone(),
            position: into_instrument
                .transform_point(point.position + sigma_mm * normal3(&mut rng)),
            weight: 1.0,
        })
        .collect())
}
