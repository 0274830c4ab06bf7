//! `hexacomp-trainer simulate`: measures a plan on the virtual platform.

use std::path::PathBuf;

use anyhow::Context;
use hexacomp_core::error::compact;
use hexacomp_core::{Geometry, inverse_kinematics};
use hexacomp_formats::{read_poses, write_measurements};
use hexacomp_trainer::acquire::measure_plan;
use hexacomp_virtual::{DEFAULT_MACHINE_SEED, ErrorModel, ErrorVariant, VirtualPlatform};

use hexacomp_formats::write_file;

/// Measure a plan on the built-in virtual platform, writing exactly what a measuring arm would
/// have produced.
///
/// The virtual machine differs from the geometry by joint-centre and leg-zero offsets, lead-screw
/// pitch errors, gravity compliance and repeatability noise; its device reads the three targets
/// with 0.020 mm uncertainty (three readings averaged). Every pose is commanded with the nominal
/// inverse kinematics (uncompensated). Output: a measurements CSV,
/// `id,x,y,z,a,b,c,q1..q6,p1x,p1y,p1z,p2x,..,p3z` (mm, degrees; targets in the base frame).
#[derive(Debug, clap::Args)]
pub struct SimulateArgs {
    /// Poses CSV to measure (`hexacomp-trainer plan`).
    #[arg(long, value_name = "FILE")]
    plan: PathBuf,
    /// Seed of the repeatability and measurement noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Seed that draws the virtual machine (its errors); 18 resembles the paper's prototype.
    #[arg(long, default_value_t = DEFAULT_MACHINE_SEED)]
    machine_seed: u64,
    /// Error variant: paper, noise-free, geometric-only, strong-pitch.
    #[arg(long, default_value_t = ErrorVariant::Paper)]
    error_variant: ErrorVariant,
    /// Output measurements CSV.
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
}

impl SimulateArgs {
    /// The files this command reads and writes.
    pub fn files(&self) -> super::Files<'_> {
        super::Files {
            inputs: vec![&self.plan],
            outputs: vec![&self.out],
        }
    }
}

pub fn run(geometry: &Geometry, args: &SimulateArgs) -> anyhow::Result<()> {
    let plan = read_poses(&args.plan)?;
    let model = ErrorModel::variant(args.error_variant);
    let mut platform = VirtualPlatform::new(geometry, &model, args.machine_seed, args.seed)?;
    let mut rows = Vec::with_capacity(plan.len());
    for (index, row) in plan.iter().enumerate() {
        let at = || {
            format!(
                "{}:{}: configuration {}",
                plan.file,
                plan.line(index),
                row.id
            )
        };
        let legs = inverse_kinematics(geometry, &row.pose()).lengths;
        let [min, max] = geometry.leg_range;
        if let Some((leg, length)) = (1..).zip(legs).find(|(_, l)| !(min..=max).contains(l)) {
            anyhow::bail!(
                "{}: the pose needs leg {leg} at {} mm, outside the geometry's stroke [{min}, \
                 {max}] mm",
                at(),
                compact(length, 3)
            );
        }
        let measured = measure_plan(&mut platform, std::slice::from_ref(row))
            .with_context(|| format!("{}: cannot be measured on the virtual machine", at()))?;
        rows.extend(measured);
    }
    write_file(&args.out, |w| write_measurements(w, &rows))?;
    eprintln!(
        "measured {} configurations on virtual machine {} ({} errors) → {}",
        rows.len(),
        args.machine_seed,
        args.error_variant,
        args.out.display()
    );
    Ok(())
}
