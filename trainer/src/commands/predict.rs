//! `hexacomp-trainer predict`: offline compensation, the numbers the service returns.

use std::path::PathBuf;

use hexacomp_core::Geometry;
use hexacomp_core::Pose;
use hexacomp_core::compensator::{Compensated, compensate_legs, compensate_pose};
use hexacomp_core::fused::FusedModel;
use hexacomp_core::model::Model;
use hexacomp_formats::{PointsFile, bytes_progress, compensate_file};

/// How one point of the input file (pose in mm and degrees, or legs in mm) is compensated.
type PointCompensation<'a> = dyn Fn(&[f64; 6]) -> Compensated + 'a;

/// Rows compensated between progress updates.
const BLOCK: usize = 4096;

/// Compensate poses (or nominal leg lengths) offline with a model: exactly the numbers the
/// service returns.
///
/// For each pose: nominal inverse kinematics q, correction Δq = N(q) clamped to the model's
/// bounds, output q + Δq. Output: a compensated CSV, `id,q1..q6` (legs to command, mm),
/// `dq1..dq6` (mm), `status` (ok, out_of_stroke, outside_trained_range, clamped, invalid_input).
#[derive(Debug, clap::Args)]
#[command(group(clap::ArgGroup::new("input").required(true).args(["poses", "joints"])))]
pub struct PredictArgs {
    /// The model file.
    #[arg(long, value_name = "FILE")]
    model: PathBuf,
    /// Poses CSV (`id,x,y,z,a,b,c`, mm and degrees).
    #[arg(long, value_name = "FILE")]
    poses: Option<PathBuf>,
    /// Nominal leg lengths CSV (`id,q1..q6`, mm) instead of poses.
    #[arg(long, value_name = "FILE")]
    joints: Option<PathBuf>,
    /// Output compensated CSV.
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
}

impl PredictArgs {
    /// The files this command reads and writes.
    pub fn files(&self) -> super::Files<'_> {
        super::Files {
            inputs: [&self.model]
                .into_iter()
                .chain(&self.poses)
                .chain(&self.joints)
                .map(PathBuf::as_path)
                .collect(),
            outputs: vec![&self.out],
        }
    }
}

pub fn run(geometry: &Geometry, args: &PredictArgs) -> anyhow::Result<()> {
    // The serving form: the numbers the service returns for the same points.
    let model = FusedModel::new(&Model::load(&args.model, geometry)?);
    let (input, compensate): (_, &PointCompensation) = match (&args.poses, &args.joints) {
        (Some(path), _) => (PointsFile::Poses(path), &|pose| {
            compensate_pose(geometry, Some(&model), &Pose::from_mm_deg(*pose))
        }),
        (None, Some(path)) => (PointsFile::Joints(path), &|legs| {
            compensate_legs(geometry, Some(&model), legs)
        }),
        (None, None) => anyhow::bail!("give --poses or --joints"),
    };
    let progress = bytes_progress(input.path());
    let summary = compensate_file::<hexacomp_formats::Error>(
        input,
        &args.out,
        BLOCK,
        |points, out| {
            out.extend(points.iter().map(compensate));
            Ok(())
        },
        |bytes| progress.set_position(bytes),
    )?;
    progress.finish_and_clear();
    eprintln!(
        "compensated {} points → {} ({})",
        summary.points,
        args.out.display(),
        summary.statuses
    );
    Ok(())
}
