//! `hexacomp-bench compute`: what compensating a pose costs in this process, by the model's
//! reference evaluation and by its fused serving form, one point at a time and in batches,
//! beside the arithmetic floor of the fused networks on this core.

use std::hint::black_box;
use std::path::PathBuf;
use std::time::Instant;

use hdrhistogram::Histogram;
use hexacomp_core::compensator::{
    Compensated, Corrections, PointStatus, compensate_pose, compensate_poses,
};
use hexacomp_core::fused::{FusedModel, OPERATIONS_PER_BLOCK};
use hexacomp_core::{Geometry, Pose, inverse_kinematics};
use serde::Serialize;

use crate::path::interpolate;
use crate::report::write_json;
use crate::roofline::{networks_floor_ns, peak_operations_per_ns};
use crate::session::{PathArgs, Session, SetupArgs};
use crate::stream::new_histogram;

/// Batch sizes measured.
const BATCHES: [usize; 5] = [1, 16, 64, 256, 1024];
/// Largest difference allowed between the two forms along the path, mm (1 nm).
const AGREEMENT_MM: f64 = 1e-6;

/// Compensate the path's poses in this process, no server involved, with the model's reference
/// evaluation (what training and evaluation use) and its fused serving form (what the service
/// and `predict` use): each point timed alone (p50), batches of 1 to 1024 points (points per
/// second), the networks and the nominal inverse kinematics alone (mean), and the arithmetic
/// floor of the fused networks at this core's measured peak of vector multiplies and adds.
/// Checks first that the two forms agree on every pose (same status, within 1 nm).
///
/// The service's options (`--instance`, `--wait`, the CPU and real-time settings) do not apply:
/// nothing is started.
#[derive(Debug, clap::Args)]
pub struct ComputeCommand {
    #[command(flatten)]
    setup: SetupArgs,
    #[command(flatten)]
    path: PathArgs,
    /// Poses of the path, each measurement.
    #[arg(long, default_value_t = 100_000)]
    points: usize,
    /// Write the figures here as JSON (see docs/serving.md).
    #[arg(long, value_name = "FILE")]
    json: Option<PathBuf>,
}

/// One form's figures.
#[derive(Debug, Clone, Serialize)]
struct FormFigures {
    /// One point timed alone (two clock reads included), median, ns.
    single_p50_ns: u64,
    /// Points per second in batches of each of [`BATCHES`] points.
    batch_points_per_second: Vec<f64>,
    /// The networks alone on the path's nominal legs, mean per point, ns.
    networks_mean_ns: f64,
}

/// What `--json` writes.
#[derive(Debug, Serialize)]
struct ComputeReport {
    points: usize,
    hidden_nodes: Vec<usize>,
    fused_blocks: usize,
    instruction_set: &'static str,
    batch_sizes: Vec<usize>,
    reference: FormFigures,
    fused: FormFigures,
    inverse_kinematics_mean_ns: f64,
    clock_pair_p50_ns: u64,
    peak_vector_operations_per_ns: f64,
    operations_per_block: usize,
    networks_floor_ns: f64,
    largest_difference_mm: f64,
}

pub fn run(command: &ComputeCommand) -> anyhow::Result<()> {
    anyhow::ensure!(command.points > 0, "--points must be ≥ 1");
    let session = Session::prepare(&command.setup)?;
    let geometry = &session.geometry;
    let duration = command.points as f64 / command.path.rate;
    let poses: Vec<Pose> = interpolate(geometry, &command.path.spec(duration))?
        .poses
        .iter()
        .map(|p| Pose::from_mm_deg(*p))
        .collect();
    let reference = &session.model;
    let fused = FusedModel::new(reference);
    let largest_difference_mm = agreement(geometry, reference, &fused, &poses)?;
    let legs: Vec<[f64; 6]> = poses
        .iter()
        .map(|p| inverse_kinematics(geometry, p).lengths)
        .collect();

    let figures = |model: &dyn Fn(&Pose) -> Compensated,
                   batch: &dyn Fn(&[Pose], &mut [Compensated]),
                   networks: &dyn Fn(&[f64; 6]) -> f64| FormFigures {
        single_p50_ns: single_p50_ns(&poses, model),
        batch_points_per_second: BATCHES
            .iter()
            .map(|&size| points_per_second(&poses, size, batch))
            .collect(),
        networks_mean_ns: mean_ns(&legs, networks),
    };
    let reference_figures = figures(
        &|p| compensate_pose(geometry, Some(reference), p),
        &|poses, out| compensate_poses(geometry, Some(reference), poses, out),
        &|q| Corrections::raw_corrections(reference, q)[0],
    );
    let fused_figures = figures(
        &|p| compensate_pose(geometry, Some(&fused), p),
        &|poses, out| compensate_poses(geometry, Some(&fused), poses, out),
        &|q| fused.raw_corrections(q)[0],
    );
    let inverse_kinematics_mean_ns =
        mean_ns(&poses, &|p| inverse_kinematics(geometry, p).lengths[0]);
    let peak = peak_operations_per_ns(&fused);
    let report = ComputeReport {
        points: poses.len(),
        hidden_nodes: reference.hidden_nodes(),
        fused_blocks: fused.blocks(),
        instruction_set: fused.instruction_set(),
        batch_sizes: BATCHES.to_vec(),
        reference: reference_figures,
        fused: fused_figures,
        inverse_kinematics_mean_ns,
        clock_pair_p50_ns: clock_pair_p50_ns(poses.len()),
        peak_vector_operations_per_ns: peak,
        operations_per_block: OPERATIONS_PER_BLOCK,
        networks_floor_ns: networks_floor_ns(&fused, peak),
        largest_difference_mm,
    };
    print(&report);
    if let Some(file) = &command.json {
        write_json(file, &report)?;
        println!("wrote {}", file.display());
    }
    Ok(())
}

/// The largest difference between the two forms' legs and corrections over `poses`, mm; an
/// error naming the pose where their statuses differ or they are more than 1 nm apart.
fn agreement(
    geometry: &Geometry,
    reference: &hexacomp_core::model::Model,
    fused: &FusedModel,
    poses: &[Pose],
) -> anyhow::Result<f64> {
    let mut largest: f64 = 0.0;
    for pose in poses {
        let (a, b) = (
            compensate_pose(geometry, Some(reference), pose),
            compensate_pose(geometry, Some(fused), pose),
        );
        let difference = a
            .legs
            .iter()
            .chain(&a.corrections)
            .zip(b.legs.iter().chain(&b.corrections))
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max);
        anyhow::ensure!(
            a.status == b.status && difference <= AGREEMENT_MM,
            "the fused form does not agree with the reference at {:?} (mm, degrees): statuses \
             {} and {}, legs {:?} and {:?}",
            pose.to_mm_deg(),
            a.status.name(),
            b.status.name(),
            a.legs,
            b.legs
        );
        largest = largest.max(difference);
    }
    Ok(largest)
}

/// The median time of compensating one pose, each timed alone, ns.
fn single_p50_ns(poses: &[Pose], compensate: &dyn Fn(&Pose) -> Compensated) -> u64 {
    let mut histogram: Histogram<u64> = new_histogram();
    for pose in poses {
        let start = Instant::now();
        black_box(compensate(black_box(pose)));
        let _ = histogram.record(start.elapsed().as_nanos() as u64);
    }
    histogram.value_at_quantile(0.5)
}

/// Points per second compensating `poses` in batches of `batch` (by `compensate`, which fills
/// one result per pose), each batch timed.
fn points_per_second(
    poses: &[Pose],
    batch: usize,
    compensate: &dyn Fn(&[Pose], &mut [Compensated]),
) -> f64 {
    let unset = Compensated {
        legs: [f64::NAN; 6],
        corrections: [f64::NAN; 6],
        status: PointStatus::InvalidInput,
        uncertainty_mm: None,
    };
    let mut out = vec![unset; batch];
    let mut nanoseconds = 0u128;
    for chunk in poses.chunks(batch) {
        let start = Instant::now();
        compensate(chunk, &mut out[..chunk.len()]);
        nanoseconds += start.elapsed().as_nanos();
        black_box(&out);
    }
    poses.len() as f64 / (nanoseconds.max(1) as f64 * 1e-9)
}

/// The mean time of `f` over `inputs`, timed as a whole, ns; every result is kept (through
/// `black_box`), so no part of it can be left uncomputed.
fn mean_ns<T, R>(inputs: &[T], f: &dyn Fn(&T) -> R) -> f64 {
    let start = Instant::now();
    for input in inputs {
        black_box(f(black_box(input)));
    }
    start.elapsed().as_nanos() as f64 / inputs.len() as f64
}

/// The median time between two clock reads with nothing between them, ns: what each timed
/// single point includes besides its computation.
fn clock_pair_p50_ns(samples: usize) -> u64 {
    let mut histogram: Histogram<u64> = new_histogram();
    for _ in 0..samples {
        let start = Instant::now();
        let _ = histogram.record(start.elapsed().as_nanos() as u64);
    }
    histogram.value_at_quantile(0.5)
}

fn print(report: &ComputeReport) {
    let mut table =
        hexacomp_report::table::Table::new(["per point", "reference", "fused", "fused speed-up"]);
    let (r, f) = (&report.reference, &report.fused);
    table.row([
        "one point alone, p50 (ns)".into(),
        r.single_p50_ns.to_string(),
        f.single_p50_ns.to_string(),
        format!("{:.2}", r.single_p50_ns as f64 / f.single_p50_ns as f64),
    ]);
    for (i, batch) in report.batch_sizes.iter().enumerate() {
        let (a, b) = (r.batch_points_per_second[i], f.batch_points_per_second[i]);
        table.row([
            format!("batches of {batch} (M points/s)"),
            format!("{:.2}", a / 1e6),
            format!("{:.2}", b / 1e6),
            format!("{:.2}", b / a),
        ]);
    }
    table.row([
        "networks alone, mean (ns)".into(),
        format!("{:.1}", r.networks_mean_ns),
        format!("{:.1}", f.networks_mean_ns),
        format!("{:.2}", r.networks_mean_ns / f.networks_mean_ns),
    ]);
    println!(
        "\ncompensating {} poses of the path in this process; hidden nodes {:?}, {} blocks of 4 in \
         the fused form ({}):\n{table}",
        report.points, report.hidden_nodes, report.fused_blocks, report.instruction_set
    );
    println!(
        "nominal inverse kinematics (the same code for both): {:.1} ns mean; two clock reads: {} \
         ns p50 (included in \"one point alone\")",
        report.inverse_kinematics_mean_ns, report.clock_pair_p50_ns
    );
    println!(
        "arithmetic floor of the fused networks: {} blocks × {} vector operations at this core's \
         peak of {:.2} per ns ({}) = {:.1} ns per point; measured {:.1} ns, {:.1}× the floor",
        report.fused_blocks,
        report.operations_per_block,
        report.peak_vector_operations_per_ns,
        report.instruction_set,
        report.networks_floor_ns,
        f.networks_mean_ns,
        f.networks_mean_ns / report.networks_floor_ns
    );
    println!(
        "the two forms agree on every pose: same statuses, largest difference {:.1e} mm",
        report.largest_difference_mm
    );
}
