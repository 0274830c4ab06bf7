//! The physical model carried into a model file: networks trained on the corrections it
//! commands at many poses (noise-free: the model is known everywhere), so that the service, the
//! C library and the HAL component evaluate it as they evaluate any model.
//!
//! The poses are the measured configurations' own and more drawn over the task workspace, kept
//! where every nominal leg lies within the range the measured configurations covered (the model
//! was identified there; beyond it its lead-screw curves are not seen), so the model file's
//! training range keeps its meaning: a point outside it is reported `outside_trained_range`, as
//! for networks trained on the measurements. The networks are the paper's decoupled ones (a lead-screw curve is a function
//! of its own leg; one network per leg learns it without the others' corrections in its loss).
//!
//! Units: mm.

use hexacomp_core::compensator::compensate_pose;
use hexacomp_core::model::{Model, NetworkInput};
use hexacomp_core::records::JointCorrection;
use hexacomp_core::sampling::{SamplerOptions, WorkspaceSampler};
use hexacomp_core::{Geometry, LEGS, Pose, inverse_kinematics};

use crate::error::{Error, Result};
use crate::physical::PhysicalModel;
use crate::train::{Architecture, TrainOptions, Trained, leg_range, train};

/// Settings of the distillation.
#[derive(Debug, Clone, PartialEq)]
pub struct DistillOptions {
    /// Poses drawn over the measured range the networks are trained on (the measured
    /// configurations' own poses are added to them).
    pub samples: usize,
    /// Seed of the poses.
    pub seed: u64,
    /// The networks' training (its holdout chooses the hidden nodes, as for measured data). Its
    /// input should be the equivalent legs: then the networks are trained at exactly the nominal
    /// legs they are evaluated at.
    pub train: TrainOptions,
}

impl Default for DistillOptions {
    /// 1000 poses; sizes 16, 20 and 24, one run of up to 300 iterations each (measured against
    /// smaller and larger settings in docs/accuracy.md).
    fn default() -> Self {
        Self {
            samples: 1000,
            seed: 1,
            train: TrainOptions {
                hidden_sizes: vec![16, 20, 24],
                restarts: 1,
                max_iterations: 300,
                relative_tolerance: 1e-7,
                validation_fraction: 0.2,
                input: NetworkInput::Equivalent,
                ..TrainOptions::default()
            },
        }
    }
}

/// The row of a pose the model puts the machine on: the model's command `c` is what the
/// machine is commanded with, and the pose it reaches has the nominal legs `q_nominal`, so
/// `Δq = c − q_nominal` and the equivalent legs `c − Δq` are exactly the nominal legs the
/// networks are evaluated at for that pose.
fn row(nominal: &Geometry, model: &PhysicalModel, pose: &Pose, id: String) -> JointCorrection {
    let legs = model.command(pose);
    let nominal_legs = inverse_kinematics(nominal, pose).lengths;
    JointCorrection {
        id,
        legs,
        corrections: std::array::from_fn(|i| legs[i] - nominal_legs[i]),
    }
}

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

/// Decoupled networks trained on the corrections `model` commands at the `measured` poses and
/// at `options.samples` poses drawn within their nominal legs' range, for `nominal`'s
/// fingerprint.
pub fn distill(
    nominal: &Geometry,
    model: &PhysicalModel,
    measured: &[Pose],
    options: &DistillOptions,
    progress: &(dyn Fn(u64) + Sync),
) -> Result<Trained> {
    let range = measured_range(nominal, measured);
    let drawn = draw(nominal, &range, options.samples, options.seed)?;
    let rows: Vec<JointCorrection> = measured
        .iter()
        .chain(&drawn)
        .enumerate()
        .map(|(k, pose)| row(nominal, model, pose, format!("d{}", k + 1)))
        .collect();
    train(
        &rows,
        Architecture::Decoupled,
        nominal.fingerprint(),
        &options.train,
        progress,
    )
}

/// How closely a distilled model commands what the physical model does, over poses it was not
/// trained on, mm of leg length.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fidelity {
    /// Poses compared.
    pub poses: usize,
    /// RMS over every leg of every pose of the difference between the two commands, mm.
    pub rms_mm: f64,
    /// The largest difference, mm.
    pub max_mm: f64,
}

/// Compares `distilled` with `model` on `poses` fresh poses within the `measured` poses' range
/// (drawn with a seed other than the training's).
pub fn fidelity(
    nominal: &Geometry,
    model: &PhysicalModel,
    distilled: &Model,
    measured: &[Pose],
    options: &DistillOptions,
    poses: usize,
) -> Result<Fidelity> {
    let range = measured_range(nominal, measured);
    let fresh = draw(nominal, &range, poses, options.seed.wrapping_add(0x5eed))?;
    let mut sum = 0.0;
    let mut max: f64 = 0.0;
    for pose in &fresh {
        let file = compensate_pose(nominal, Some(distilled), pose).legs;
        let wanted = model.command(pose);
        for (got, want) in file.iter().zip(wanted) {
            let difference = got - want;
            sum += difference * difference;
            max = max.max(difference.abs());
        }
    }
    Ok(Fidelity {
        poses: fresh.len(),
        rms_mm: (sum / (LEGS * fresh.len()).max(1) as f64).sqrt(),
        max_mm: max,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_rows_equivalent_legs_are_the_nominal_legs_of_its_pose() {
        let nominal = Geometry::prototype();
        let mut model = PhysicalModel::geometric(nominal.clone());
        model.geometry.leg_offsets = [0.3, -0.2, 0.1, 0.4, -0.5, 0.2];
        let pose = Pose::from_mm_deg([10.0, -5.0, 330.0, 2.0, -1.0, 3.0]);
        let row = row(&nominal, &model, &pose, "1".into());
        let nominal_legs = inverse_kinematics(&nominal, &pose).lengths;
        // The machine is commanded with the model's legs …
        assert_eq!(row.legs, model.command(&pose));
        for (i, nominal) in nominal_legs.iter().enumerate() {
            // … and the networks see the nominal legs of the pose it reaches.
            let equivalent = row.legs[i] - row.corrections[i];
            assert!((equivalent - nominal).abs() < 1e-12, "leg {i}");
            assert!(
                row.corrections[i].abs() > 0.05,
                "leg {i}: a correction to learn"
            );
        }
    }
}
