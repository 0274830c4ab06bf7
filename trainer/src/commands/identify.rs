//! `hexacomp-trainer identify`: the model-based baseline (geometric calibration).

use std::path::PathBuf;

use anyhow::Context;
use hexacomp_calibration::identify::{IdentifyOptions, PARAMETERS, identify};
use hexacomp_calibration::pipeline::Pipeline;
use hexacomp_core::{Geometry, LEGS};

use super::measurements_input::MeasurementsInput;
use super::solve::{MeasuredScreeningArgs, solve_screened};

/// Identify the platform's geometric parameters from point measurements (the paper's model-based
/// comparison method) and write them as a geometry file.
///
/// Parameters: the 12 joint centres and the 6 leg zero offsets (42 in all), fitted by iterative
/// (Gauss–Newton) least squares to the measured target points; parameter directions the
/// measurements cannot determine are dropped by SVD and keep their nominal values. Compensating
/// with this baseline means commanding the identified geometry's inverse kinematics: the output
/// is a geometry TOML (leg zero offsets in `leg_offsets`) usable on its own as --geometry.
///
/// Configurations that are gross errors (as `solve` screens them) are excluded and listed first.
#[derive(Debug, clap::Args)]
pub struct IdentifyArgs {
    /// Measurements CSV.
    #[arg(long, value_name = "FILE")]
    measurements: PathBuf,
    /// Output geometry TOML.
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
    /// Gauss–Newton iterations at most.
    #[arg(long, default_value_t = IdentifyOptions::default().max_iterations)]
    max_iterations: usize,
    #[command(flatten)]
    reading: MeasurementsInput,
    #[command(flatten)]
    screening: MeasuredScreeningArgs,
}

impl IdentifyArgs {
    /// The files this command reads and writes.
    pub fn files(&self) -> super::Files<'_> {
        super::Files {
            inputs: std::iter::once(self.measurements.as_path())
                .chain(self.reading.registration_path())
                .collect(),
            outputs: vec![&self.out],
        }
    }
}

pub fn run(geometry: &Geometry, args: &IdentifyArgs) -> anyhow::Result<()> {
    let file = args.reading.read(&args.measurements, geometry)?;
    // The configurations the joint-correction solve screens out as gross errors are left out
    // of the identification too: one wrong coordinate would move the identified joints.
    let pipeline = Pipeline {
        checks: args.screening.checks(),
        screening: args.screening.options(),
        ..Default::default()
    };
    let solved = solve_screened(&pipeline, geometry, &file)?;
    let rows = solved.kept_of(&file);
    let options = IdentifyOptions {
        max_iterations: args.max_iterations,
        ..Default::default()
    };
    let result = identify(geometry, &rows, &options)?;
    let mut identified = result.geometry.clone();
    identified.name = format!("{} (identified)", geometry.name);
    identified
        .validate()
        .context("the identified geometry is not a valid platform")?;
    let header = format!(
        "# identified by hexacomp-trainer from {} configurations of {}\n\
         # rank {}/{PARAMETERS}; target residual RMS {:.4} mm before, {:.4} mm after\n",
        rows.len(),
        args.measurements.display(),
        result.rank,
        result.rms_before_mm,
        result.rms_after_mm,
    );
    super::write_bytes(
        &args.out,
        (header + &identified.to_toml_string()).as_bytes(),
    )?;

    let largest = |pick: &dyn Fn(usize) -> f64| (0..LEGS).map(pick).fold(0.0_f64, f64::max);
    eprintln!(
        "identified {}/{PARAMETERS} parameter directions from {} configurations in {} \
         iterations: target residual RMS {:.4} → {:.4} mm",
        result.rank,
        rows.len(),
        result.iterations,
        result.rms_before_mm,
        result.rms_after_mm
    );
    eprintln!(
        "largest changes: base joint {:.4} mm, platform joint {:.4} mm, leg offset {:.4} mm → {}",
        largest(&|i| identified.base_joints[i].distance(geometry.base_joints[i])),
        largest(&|i| identified.platform_joints[i].distance(geometry.platform_joints[i])),
        largest(&|i| (identified.leg_offsets[i] - geometry.leg_offsets[i]).abs()),
        args.out.display()
    );
    Ok(())
}
