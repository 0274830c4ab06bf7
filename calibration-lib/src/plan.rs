//! Measuring plans: configurations spread over the task workspace.
//!
//! The paper picks its 150 configurations at random inside the task workspace (Fig. 8). Pure
//! random draws leave clumps and holes at this count; the plan uses best-candidate sampling
//! (Mitchell's algorithm): each new configuration is the one of several uniform random candidates
//! farthest from those already chosen, in coordinates normalised by the workspace's extent. The
//! result is still random and uniform in density, but evenly spread.
//!
//! **Each leg's extremes first.** Evenly spread poses still leave each leg's shortest and longest
//! reach to chance: with 50 configurations, 29 of 200 fresh poses of the blind robot put a leg
//! up to 11 mm beyond the lengths measured, where the lead-screw curves extrapolate
//! (docs/accuracy.md). A plan therefore starts with [`EXTREMES`] configurations: for each leg in
//! turn, its shortest and its longest among [`EXTREMES_POOL`] uniform draws over the workspace
//! (each not already chosen); the rest follow by best-candidate sampling, spread away from them
//! too. Every prefix of twelve or more configurations of the plan then spans the legs'
//! workspace range, and a campaign measures those twelve first (`campaign::tour`).

use hexacomp_core::records::NamedPose;
use hexacomp_core::sampling::{SamplerOptions, WorkspaceSampler};
use hexacomp_core::{Geometry, LEGS, Pose, inverse_kinematics};

use crate::error::{Error, Result};

/// Configurations a plan starts with when it covers the legs' extremes: each leg's shortest and
/// longest reach.
pub const EXTREMES: usize = 2 * LEGS;

/// Uniform draws over the workspace the legs' extremes are chosen among.
pub const EXTREMES_POOL: usize = 2000;

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
    /// Start with each leg's shortest and longest reach ([`EXTREMES`] configurations, fewer
    /// when the count is smaller); `false`: every configuration by best-candidate sampling.
    pub leg_extremes: bool,
}

impl Default for PlanOptions {
    fn default() -> Self {
        Self {
            count: 150,
            seed: 1,
            candidates: 10,
            sampler: SamplerOptions::default(),
            leg_extremes: true,
        }
    }
}

/// `options.count` configurations over `geometry`'s workspace (mm, rad).
pub fn plan(geometry: &Geometry, options: &PlanOptions) -> Result<Vec<Pose>> {
    plan_with_progress(geometry, options, &|_| {})
}

/// The work of a plan, in the units [`plan_with_progress`] reports: a pose drawn, or a
/// candidate weighed against one configuration chosen before it. The legs' extremes cost their
/// pool ([`EXTREMES_POOL`] draws). Best-candidate sampling weighs every candidate against every
/// configuration already chosen, so the rest grows with the square of the count (configuration
/// `k`, counted from 0, costs `candidates · (k + 1)`); plain random draws (one candidate) cost
/// one unit per configuration. Saturates at `u64::MAX`.
pub fn plan_work(options: &PlanOptions) -> u64 {
    let count = options.count as u128;
    let extremes = extremes_of(options) as u128;
    let pool = if options.leg_extremes {
        EXTREMES_POOL as u128
    } else {
        0
    };
    let drawn = if options.candidates <= 1 {
        count - extremes
    } else {
        let triangle = |n: u128| n * (n + 1) / 2;
        options.candidates as u128 * (triangle(count) - triangle(extremes))
    };
    u64::try_from(pool + drawn).unwrap_or(u64::MAX)
}

/// How many configurations of the plan are legs' extremes.
fn extremes_of(options: &PlanOptions) -> usize {
    if options.leg_extremes {
        EXTREMES.min(options.count)
    } else {
        0
    }
}

/// [`plan`], reporting `progress(n)` as `n` more units of [`plan_work`] are done (for a
/// progress bar with an estimated time left).
pub fn plan_with_progress(
    geometry: &Geometry,
    options: &PlanOptions,
    progress: &dyn Fn(u64),
) -> Result<Vec<Pose>> {
    if options.candidates == 0 {
        return Err(Error::OutOfRange {
            setting: "candidates per configuration",
            value: 0.0,
            valid: "must be ≥ 1",
        });
    }
    let mut sampler = WorkspaceSampler::new(geometry, options.seed, options.sampler)?;
    let scale = Normaliser::new(geometry);
    let mut chosen: Vec<Pose> = Vec::new();
    if options.leg_extremes {
        let pool = sampler.samples(EXTREMES_POOL)?;
        progress(EXTREMES_POOL as u64);
        chosen = legs_extremes(geometry, &pool, extremes_of(options));
    }
    if options.candidates == 1 {
        // Nothing to weigh: plain uniform draws.
        for _ in chosen.len()..options.count {
            chosen.push(sampler.sample()?);
            progress(1);
        }
        return Ok(chosen);
    }
    let mut chosen_coords: Vec<[f64; 6]> = chosen.iter().map(|p| scale.coords(p)).collect();
    for k in chosen.len()..options.count {
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

/// The first `count` of: leg 1's shortest and longest reach among `pool`, leg 2's, … (each the
/// extreme among the poses not already taken).
fn legs_extremes(geometry: &Geometry, pool: &[Pose], count: usize) -> Vec<Pose> {
    let legs: Vec<[f64; LEGS]> = pool
        .iter()
        .map(|pose| inverse_kinematics(geometry, pose).lengths)
        .collect();
    let mut taken = vec![false; pool.len()];
    let mut chosen = Vec::with_capacity(count);
    for (leg, longest) in (0..LEGS).flat_map(|leg| [(leg, false), (leg, true)]) {
        if chosen.len() == count {
            break;
        }
        let extreme = (0..pool.len()).filter(|&k| !taken[k]).min_by(|&a, &b| {
            let order = legs[a][leg].total_cmp(&legs[b][leg]);
            if longest { order.reverse() } else { order }
        });
        if let Some(k) = extreme {
            taken[k] = true;
            chosen.push(pool[k]);
        }
    }
    chosen
}

/// Which of the rows of legs `legs` (mm) hold a leg's shortest or longest length among them
/// (the first such row where several tie).
pub fn rows_holding_leg_extremes(legs: &[[f64; LEGS]]) -> Vec<bool> {
    let mut extreme = vec![false; legs.len()];
    for leg in 0..LEGS {
        let by_leg = |a: &usize, b: &usize| legs[*a][leg].total_cmp(&legs[*b][leg]);
        let indices = 0..legs.len();
        let longest = indices.clone().min_by(|a, b| by_leg(a, b).reverse());
        for row in [indices.min_by(by_leg), longest].into_iter().flatten() {
            extreme[row] = true;
        }
    }
    extreme
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
        for (candidates, count, leg_extremes) in [
            (1, 20, false),
            (10, 20, false),
            (1, 20, true),
            (10, 20, true),
            (10, 5, true),
        ] {
            let options = PlanOptions {
                count,
                candidates,
                leg_extremes,
                ..Default::default()
            };
            let reported = std::cell::Cell::new(0);
            let planned =
                plan_with_progress(&g, &options, &|n| reported.set(reported.get() + n)).unwrap();
            assert_eq!(planned.len(), count);
            assert_eq!(
                reported.get(),
                plan_work(&options),
                "{candidates} candidates, {count} configurations, extremes {leg_extremes}"
            );
        }
        let huge = PlanOptions {
            count: 100_000_000,
            ..Default::default()
        };
        // The pool, then 10 candidates × (1e8 × (1e8 + 1) − 12 × 13) / 2: quadratic, and still
        // counted exactly.
        assert_eq!(plan_work(&huge), 2000 + 50_000_000_500_000_000 - 780);
    }

    #[test]
    fn one_candidate_draws_exactly_the_samplers_poses() {
        let g = Geometry::prototype();
        let options = PlanOptions {
            count: 50,
            candidates: 1,
            seed: 4,
            leg_extremes: false,
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

    /// How far (mm) the legs of `poses` reach beyond those of `plan`, at most over the legs.
    fn reach_beyond(g: &Geometry, plan: &[Pose], poses: &[Pose]) -> f64 {
        let legs = |p: &Pose| inverse_kinematics(g, p).lengths;
        let planned: Vec<[f64; LEGS]> = plan.iter().map(legs).collect();
        let range: [[f64; 2]; LEGS] = std::array::from_fn(|i| crate::train::leg_range(&planned, i));
        poses
            .iter()
            .map(legs)
            .flat_map(|q| (0..LEGS).map(move |i| (range[i][0] - q[i]).max(q[i] - range[i][1])))
            .fold(0.0, f64::max)
    }

    #[test]
    fn a_plan_of_fifty_reaches_every_legs_extremes_over_the_workspace() {
        let g = Geometry::prototype();
        let fresh = WorkspaceSampler::new(&g, 99, SamplerOptions::default())
            .unwrap()
            .samples(500)
            .unwrap();
        let plan_of = |leg_extremes| {
            plan(
                &g,
                &PlanOptions {
                    count: 50,
                    leg_extremes,
                    ..Default::default()
                },
            )
            .unwrap()
        };
        let spanning = plan_of(true);
        let beyond = reach_beyond(&g, &spanning, &fresh);
        assert!(beyond < 0.5, "fresh legs {beyond} mm beyond the plan's");
        for (k, pose) in spanning.iter().enumerate() {
            assert!(!spanning[..k].contains(pose), "configuration {k} repeated");
        }
        // Spread in pose space alone leaves legs several mm beyond.
        let spread = reach_beyond(&g, &plan_of(false), &fresh);
        assert!(spread > 4.0, "without the extremes: {spread} mm beyond");
        eprintln!("fresh legs beyond a plan of 50: {beyond:.3} mm; without extremes {spread:.3}");
    }

    #[test]
    fn a_pose_extreme_for_several_legs_is_taken_once() {
        let g = Geometry::prototype();
        let pool = WorkspaceSampler::new(&g, 5, SamplerOptions::default())
            .unwrap()
            .samples(3)
            .unwrap();
        // Three poses hold all twelve extremes between them: each is taken once.
        let chosen = legs_extremes(&g, &pool, EXTREMES);
        assert_eq!(chosen.len(), 3);
        for pose in &pool {
            assert_eq!(chosen.iter().filter(|c| *c == pose).count(), 1);
        }
        assert_eq!(legs_extremes(&g, &pool, 2).len(), 2);
    }
}
