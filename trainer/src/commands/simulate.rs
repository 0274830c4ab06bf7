//! `hexacomp-trainer simulate`: measures a plan on the virtual platform.

use std::path::PathBuf;

use hexacomp_core::Geometry;
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
    let rows = measure_plan(&mut platform, &plan)?;
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
