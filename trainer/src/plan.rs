//! Measuring plans: configurations spread over the task workspace.
//!
//! The paper picks its 150 configurations at random inside the task workspace (Fig. 8). Pure
//! random draws leave clumps and holes at this count; the plan uses best-candidate sampling
//! (Mitchell's algorithm): each new configuration is the one of several uniform random candidates
//! farthest from those already chosen, in coordinates normalised by the workspace's extent. The
//! result is still random and uniform in density, but evenly spread.

use hexacomp_core::records::NamedPose;
use hexacomp_core::sampling::{SamplerOptions, WorkspaceSampler};
use hexacomp_core::{Geometry, Pose};

use crate::error::{Error, Result};

/// Settings of a measuring plan.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanOptions {
    /// Number of configurations.
    pub count: usize,
    /// Seed of the random draws.
    pub seed: u64,
    /// Candidates drawn per configuration; 1 gives plain uniform random sampling.
    pub candidates: usize,
    /// The workspace sampler's settings (stroke margin).
    pub sampler: SamplerOptions,
}

impl Default for PlanOptions {
    fn default() -> Self {
        Self {
            count: 150,
            seed: 1,
            candidates: 10,
            sampler: SamplerOptions::default(),
        }
    }
}

/// `options.count` configurations over `geometry`'s workspace (mm, rad).
pub fn plan(geometry: &Geometry, options: &PlanOptions) -> Result<Vec<Pose>> {
    plan_with_progress(geometry, options, &|_| {})
}

/// The work of a plan, in the units [`plan_with_progress`] reports: a candidate drawn, or a
/// candidate weighed against one configuration chosen before it. Best-candidate sampling weighs
/// every candidate against every configuration already chosen, so the work grows with the square
/// of the count (`candidates · count · (count + 1) / 2`); plain random draws (one candidate) cost
/// one unit per configuration. Saturates at `u64::MAX`.
pub fn plan_work(options: &PlanOptions) -> u64 {
    let count = options.count as u128;
    let work = if options.candidates <= 1 {
        count
    } else {
        options.candidates as u128 * count * (count + 1) / 2
    };
    u64::try_from(work).unwrap_or(u64::MAX)
}

/// [`plan`], reporting `progress(n)` as `n` more units of [`plan_work`] are done (for a
/// progress bar with an estimated time left).
pub fn plan_with_progress(
    geometry: &Geometry,
    options: &PlanOptions,
    progress: &dyn Fn(u64),
) -> Result<Vec<Pose>> {
    if options.candidates == 0 {
        return Err(Error::InvalidSetting(
            "a plan needs at least one candidate per configuration".into(),
        ));
    }
    let mut sampler = WorkspaceSampler::new(geometry, options.seed, options.sampler)?;
    let scale = Normaliser::new(geometry);
    let mut chosen: Vec<Pose> = Vec::new();
    if options.candidates == 1 {
        // Nothing to weigh: plain uniform draws.
        for _ in 0..options.count {
            chosen.push(sampler.sample()?);
            progress(1);
        }
        return Ok(chosen);
    }
    let mut chosen_coords: Vec<[f64; 6]> = Vec::new();
    for k in 0..options.count {
        let mut best: Option<(f64, Pose, [f64; 6])> = None;
        for _ in 0..options.candidates {
            let candidate = sampler.sample()?;
            let coords = scale.coords(&candidate);
            let gap = chosen_coords
                .iter()
                .map(|c| distance_sq(c, &coords))
                .fold(f64::INFINITY, f64::min);
            if best.as_ref().is_none_or(|(g, _, _)| gap > *g) {
                best = Some((gap, candidate, coords));
            }
        }
        let (_, pose, coords) = best.expect("at least one candidate");
        chosen.push(pose);
        chosen_coords.push(coords);
        progress((options.candidates as u64).saturating_mul(k as u64 + 1));
    }
    Ok(chosen)
}

/// Poses as rows of a poses file, with ids 1, 2, … in order.
pub fn numbered_rows(poses: &[Pose]) -> Vec<NamedPose> {
    poses
        .iter()
        .enumerate()
        .map(|(i, pose)| NamedPose {
            id: (i + 1).to_string(),
            pose_mm_deg: pose.to_mm_deg(),
        })
        .collect()
}

/// Maps a pose to coordinates in which the workspace spans about [-1, 1] on every axis.
struct Normaliser {
    radius: f64,
    z_mid: f64,
    z_half: f64,
    tilt: f64,
    yaw_mid: f64,
    yaw_half: f64,
}

impl Normaliser {
    fn new(geometry: &Geometry) -> Self {
        let w = &geometry.workspace;
        let positive = |v: f64| if v > 1e-9 { v } else { 1.0 };
        Self {
            radius: positive(w.radius),
            z_mid: 0.5 * (w.z_range[0] + w.z_range[1]),
            z_half: positive(0.5 * (w.z_range[1] - w.z_range[0])),
            tilt: positive(w.tilt_max.to_radians()),
            yaw_mid: 0.5 * (w.yaw_range[0] + w.yaw_range[1]).to_radians(),
            yaw_half: positive(0.5 * (w.yaw_range[1] - w.yaw_range[0]).to_radians()),
        }
    }

    fn coords(&self, pose: &Pose) -> [f64; 6] {
        let (p, a) = (pose.position, pose.angles);
        [
            p.x / self.radius,
            p.y / self.radius,
            (p.z - self.z_mid) / self.z_half,
            a.x / self.tilt,
            a.y / self.tilt,
            (a.z - self.yaw_mid) / self.yaw_half,
        ]
    }
}

fn distance_sq(a: &[f64; 6], b: &[f64; 6]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn nearest_neighbour_mean(poses: &[Pose], geometry: &Geometry) -> f64 {
        let n = Normaliser::new(geometry);
        let coords: Vec<_> = poses.iter().map(|p| n.coords(p)).collect();
        let total: f64 = coords
            .iter()
            .enumerate()
            .map(|(i, c)| {
                coords
                    .iter()
                    .enumerate()
                    .filter(|(j, _)| *j != i)
                    .map(|(_, d)| distance_sq(c, d).sqrt())
                    .fold(f64::INFINITY, f64::min)
            })
            .sum();
        total / coords.len() as f64
    }

    #[test]
    fn best_candidate_plans_spread_wider_than_plain_random_draws() {
        let g = Geometry::prototype();
        let spread = plan(&g, &PlanOptions::default()).unwrap();
        let random = plan(
            &g,
            &PlanOptions {
                candidates: 1,
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(spread.len(), 150);
        let (s, r) = (
            nearest_neighbour_mean(&spread, &g),
            nearest_neighbour_mean(&random, &g),
        );
        assert!(
            s > 1.2 * r,
            "spread plan nearest-neighbour mean {s} vs random {r}"
        );
    }

    #[test]
    fn progress_adds_up_to_the_work_of_the_plan() {
        let g = Geometry::prototype();
        for candidates in [1, 10] {
            let options = PlanOptions {
                count: 20,
                candidates,
                ..Default::default()
            };
            let reported = std::cell::Cell::new(0);
            plan_with_progress(&g, &options, &|n| reported.set(reported.get() + n)).unwrap();
            assert_eq!(
                reported.get(),
                plan_work(&options),
                "{candidates} candidates"
            );
        }
        let huge = PlanOptions {
            count: 100_000_000,
            ..Default::default()
        };
        // 10 candidates × 1e8 × (1e8 + 1) / 2: quadratic, and still counted exactly.
        assert_eq!(plan_work(&huge), 50_000_000_500_000_000);
    }

    #[test]
    fn one_candidate_draws_exactly_the_samplers_poses() {
        let g = Geometry::prototype();
        let options = PlanOptions {
            count: 50,
            candidates: 1,
            seed: 4,
            ..Default::default()
        };
        let drawn = WorkspaceSampler::new(&g, 4, options.sampler)
            .unwrap()
            .samples(50)
            .unwrap();
        assert_eq!(plan(&g, &options).unwrap(), drawn);
    }

    #[test]
    fn plans_are_reproducible() {
        let g = Geometry::prototype();
        let options = PlanOptions {
            count: 20,
            ..Default::default()
        };
        assert_eq!(plan(&g, &options).unwrap(), plan(&g, &options).unwrap());
    }
}
