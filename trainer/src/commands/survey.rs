//! `hexacomp-trainer survey`: the virtual platform's uncompensated pose errors, beside the
//! paper's "before compensation" column (Table 2).

use hexacomp_core::Geometry;
use hexacomp_core::sampling::{SamplerOptions, WorkspaceSampler};
use hexacomp_core::stats::{ErrorStats, PoseErrorStats};
use hexacomp_virtual::{
    DEFAULT_MACHINE_SEED, DEFAULT_NOISE_SEED, ErrorModel, ErrorVariant, VirtualPlatform,
};

use hexacomp_report::table::Table;

/// Report the uncompensated virtual platform's pose errors at random workspace poses.
///
/// Drive the virtual platform uncompensated to random workspace poses and report its pose
/// errors (max/mean/std of the position error ‖δ_A‖ in mm and the orientation error ‖ε‖ in
/// degrees), next to the paper's prototype before compensation.
#[derive(Debug, clap::Args)]
pub struct SurveyArgs {
    /// Number of random workspace poses.
    #[arg(long, default_value_t = 1000)]
    poses: usize,
    /// Seed of the random poses.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Error variant of the virtual machine: paper, noise-free, geometric-only, strong-pitch,
    /// unseen.
    #[arg(long, default_value_t = ErrorVariant::Paper, value_parser = super::named::<ErrorVariant>(ErrorVariant::ALL.map(ErrorVariant::name)))]
    error_variant: ErrorVariant,
    /// Seed that draws the virtual machine's errors (joint offsets, pitch, compliance).
    #[arg(long, default_value_t = DEFAULT_MACHINE_SEED)]
    machine_seed: u64,
    /// Seed of the repeatability and measurement noise.
    #[arg(long, default_value_t = DEFAULT_NOISE_SEED)]
    noise_seed: u64,
}

/// The paper's Table 2, "before compensation": max, mean, std of ‖δ_A‖ (mm) and ‖ε‖ (deg).
const PAPER_BEFORE: PoseErrorStats = PoseErrorStats {
    position_mm: ErrorStats {
        max: 1.225,
        mean: 0.642,
        std: 0.163,
        count: 150,
    },
    orientation_deg: ErrorStats {
        max: 0.290,
        mean: 0.184,
        std: 0.041,
        count: 150,
    },
};

pub fn run(geometry: &Geometry, args: &SurveyArgs) -> anyhow::Result<()> {
    anyhow::ensure!(args.poses > 0, "--poses must be at least 1");
    let poses = WorkspaceSampler::new(geometry, args.seed, SamplerOptions::default())?
        .samples(args.poses)?;
    let model = ErrorModel::variant(args.error_variant);
    let mut platform = VirtualPlatform::new(geometry, &model, args.machine_seed, args.noise_seed)?;
    let stats = PoseErrorStats::of(&platform.uncompensated_errors(&poses)?);

    println!(
        "Virtual platform, uncompensated: geometry {} (fingerprint {}), error variant {}, \
         machine seed {}, {} workspace poses (seed {})",
        geometry.name,
        geometry.fingerprint(),
        args.error_variant,
        args.machine_seed,
        args.poses,
        args.seed
    );
    let mut table = Table::new(["pose error", "", "this machine", "paper, before"]);
    let rows = [
        ("‖δ_A‖ (mm)", stats.position_mm, PAPER_BEFORE.position_mm),
        (
            "‖ε‖ (deg)",
            stats.orientation_deg,
            PAPER_BEFORE.orientation_deg,
        ),
    ];
    for (name, ours, paper) in rows {
        for (label, a, b) in [
            ("max", ours.max, paper.max),
            ("mean", ours.mean, paper.mean),
            ("std", ours.std, paper.std),
        ] {
            table.row([
                name.to_string(),
                label.into(),
                format!("{a:.3}"),
                format!("{b:.3}"),
            ]);
        }
    }
    print!("{table}");
    Ok(())
}
