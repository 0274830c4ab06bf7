//! `hexacomp-bench`: per-point latency along interpolated paths and the one-command demo. This
//! first version measures the compute floor only: nominal inverse kinematics along random
//! workspace poses, in process.

use std::hint::black_box;
use std::time::Instant;

use clap::Parser;
use hexacomp_core::sampling::{SamplerOptions, WorkspaceSampler};
use hexacomp_core::{Geometry, inverse_kinematics};

/// Measure the in-process cost of nominal inverse kinematics (pose → six leg lengths), the floor
/// under every compensation request.
#[derive(Debug, Parser)]
#[command(name = "hexacomp-bench", version)]
struct Args {
    /// Number of poses per round.
    #[arg(long, default_value_t = 100_000)]
    points: usize,
    /// Rounds; the median round is reported.
    #[arg(long, default_value_t = 7)]
    rounds: usize,
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    anyhow::ensure!(
        args.points > 0 && args.rounds > 0,
        "--points and --rounds must be ≥ 1"
    );
    let geometry = Geometry::prototype();
    let poses = WorkspaceSampler::new(&geometry, 1, SamplerOptions::default())?
        .samples(args.points.min(10_000))?;
    let mut per_point_ns: Vec<f64> = (0..args.rounds)
        .map(|_| {
            let start = Instant::now();
            for i in 0..args.points {
                black_box(inverse_kinematics(
                    &geometry,
                    black_box(&poses[i % poses.len()]),
                ));
            }
            start.elapsed().as_nanos() as f64 / args.points as f64
        })
        .collect();
    per_point_ns.sort_by(f64::total_cmp);
    let median = per_point_ns[per_point_ns.len() / 2];
    println!(
        "inverse kinematics, in process: median {median:.1} ns per point over {} rounds of {} \
         points ({:.2} M points/s)",
        args.rounds,
        args.points,
        1e3 / median
    );
    Ok(())
}
