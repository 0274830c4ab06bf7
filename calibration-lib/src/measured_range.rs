//! The range of nominal legs the measured configurations cover, and poses drawn within it:
//! where the physical model was identified (beyond it its lead-screw curves are not seen), and
//! where its uncertainty is fitted ([`crate::uncertainty`]).
//!
//! Units: mm.

use hexacomp_core::sampling::{SamplerOptions, WorkspaceSampler};
use hexacomp_core::{Geometry, LEGS, Pose, inverse_kinematics};

use crate::error::{Error, Result};
use crate::train::leg_range;

/// The smallest and largest nominal length of each leg over `poses`, mm.
pub fn measured_range(nominal: &Geometry, poses: &[Pose]) -> [[f64; 2]; LEGS] {
    let legs: Vec<[f64; LEGS]> = poses
        .iter()
        .map(|pose| inverse_kinematics(nominal, pose).lengths)
        .collect();
    std::array::from_fn(|leg| leg_range(&legs, leg))
}

/// `count` poses drawn over the workspace with `seed` whose nominal legs lie within `range`
/// (per leg `[min, max]`, mm).
pub(crate) fn draw(
    nominal: &Geometry,
    range: &[[f64; 2]; LEGS],
    count: usize,
    seed: u64,
) -> Result<Vec<Pose>> {
    let mut sampler = WorkspaceSampler::new(nominal, seed, SamplerOptions::default())?;
    let inside = |pose: &Pose| {
        inverse_kinematics(nominal, pose)
            .lengths
            .iter()
            .zip(range)
            .all(|(q, [lo, hi])| (lo..=hi).contains(&q))
    };
    let mut drawn = Vec::with_capacity(count);
    // The measured range is most of the workspace's in a planned campaign; a campaign confined
    // to a corner makes most draws miss it.
    let attempts = 50 * count.max(1);
    for _ in 0..attempts {
        if drawn.len() == count {
            break;
        }
        let pose = sampler.sample()?;
        if inside(&pose) {
            drawn.push(pose);
        }
    }
    if drawn.len() < count {
        return Err(Error::TooFewPosesInRange {
            drawn: drawn.len(),
            attempts,
            needed: count,
        });
    }
    Ok(drawn)
}
