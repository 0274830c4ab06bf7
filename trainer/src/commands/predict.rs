//! `hexacomp-trainer predict`: offline compensation, the numbers the service returns.

use std::path::PathBuf;

use hexacomp_core::Geometry;
use hexacomp_core::compensator::{StatusCounts, compensate_legs, compensate_pose};
use hexacomp_core::model::Model;
use hexacomp_core::records::NamedCompensation;
use hexacomp_formats::{read_joints, read_poses, write_compensated};

use hexacomp_formats::write_file;

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
    let model = Model::load(&args.model, geometry)?;
    let rows: Vec<NamedCompensation> = match (&args.poses, &args.joints) {
        (Some(path), _) => read_poses(path)?
            .into_iter()
            .map(|r| NamedCompensation {
                point: compensate_pose(geometry, Some(&model), &r.pose()),
                id: r.id,
            })
            .collect(),
        (None, Some(path)) => read_joints(path)?
            .into_iter()
            .map(|r| NamedCompensation {
                point: compensate_legs(geometry, Some(&model), &r.legs),
                id: r.id,
            })
            .collect(),
        (None, None) => anyhow::bail!("give --poses or --joints"),
    };
    write_file(&args.out, |w| write_compensated(w, &rows))?;
    let counts: StatusCounts = rows.iter().map(|r| r.point.status).collect();
    eprintln!(
        "compensated {} points → {} ({counts})",
        rows.len(),
        args.out.display()
    );
    Ok(())
}
