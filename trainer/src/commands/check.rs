//! `hexacomp-trainer check`: does the calibration still hold? The poses `verify` tested after
//! the calibration, measured once more with the compensation active, compared with what it
//! proved.

use std::path::PathBuf;

use anyhow::Context;
use hexacomp_core::Geometry;
use hexacomp_trainer::check::{CheckResult, promised_mm, verified_poses};
use hexacomp_trainer::verify::PoseTest;
use hexacomp_trainer::verify_report::{VerifyReport, raw_csv};

/// Check that the calibration still holds (monthly, or after a crash or a move of the machine).
///
/// Measures the poses of the ISO 9283 report of `verify` run after the calibration (--promise:
/// P1–P5 and, if it had them, the orientation and extra poses), once each, with the compensation
/// active (on the virtual machine: --model), and compares each position error |attained −
/// commanded| with what that test proved: one attained position lies within AP_P + RP_l of the
/// commanded one (the worst of each over the report's poses), times --tolerance. Prints one
/// line: "still good" (exit status 0) or "retrain" with the figures (exit status 1).
#[derive(Debug, clap::Args)]
pub struct CheckArgs {
    #[command(flatten)]
    rig: super::rig::RigArgs,
    /// The JSON report of `verify` after the calibration: what it was proven to.
    #[arg(long, value_name = "FILE")]
    promise: PathBuf,
    /// The error allowed, as a multiple of the promise.
    #[arg(long, default_value_t = 1.0)]
    tolerance: f64,
    /// With the virtual machine: the model its controller applies.
    #[arg(long, value_name = "FILE")]
    model: Option<PathBuf>,
    /// The registration that brings the instrument's measurements into the base frame.
    #[arg(long, value_name = "FILE")]
    registration: Option<PathBuf>,
    /// Write the attained poses here (CSV `cycle,pose,x,y,z,a,b,c`, mm, degrees, base frame).
    #[arg(long, value_name = "FILE")]
    out: Option<PathBuf>,
}

impl CheckArgs {
    /// The files this command reads and writes.
    pub fn files(&self) -> super::Files<'_> {
        super::Files {
            inputs: std::iter::once(&self.promise)
                .chain(self.model.iter().chain(&self.registration))
                .map(PathBuf::as_path)
                .collect(),
            outputs: self.out.iter().map(PathBuf::as_path).collect(),
        }
    }
}

pub fn run(geometry: &Geometry, args: &CheckArgs) -> anyhow::Result<()> {
    anyhow::ensure!(
        args.tolerance.is_finite() && args.tolerance > 0.0,
        "--tolerance {}: a factor > 0 is needed",
        args.tolerance
    );
    let text = std::fs::read_to_string(&args.promise)
        .with_context(|| format!("reading {}", args.promise.display()))?;
    let promise = VerifyReport::from_json(&text, &args.promise.display().to_string())?;
    anyhow::ensure!(
        promise.conditions.geometry == geometry.fingerprint().to_string(),
        "{}: it verified another geometry ({}; this one is {}): give the report of this \
         machine's calibration",
        args.promise.display(),
        promise.conditions.geometry,
        geometry.fingerprint()
    );
    let (compensation, instrument_frame) = args.rig.compensation_and_frame(
        geometry,
        args.model.as_deref(),
        args.registration.as_deref(),
    )?;
    let poses = verified_poses(&promise);
    let super::rig::Rig {
        mut machine,
        mut instrument,
        options,
        ..
    } = args.rig.build(geometry, compensation)?;
    let test = PoseTest {
        geometry,
        poses: &poses,
        cycles: 1,
        instrument_frame,
        options,
    };
    let run = test.run(machine.as_mut(), instrument.as_mut(), &mut || {})?;
    for missed in &run.missed {
        eprintln!(
            "{} was not measured ({}): left out",
            missed.pose, missed.why
        );
    }
    if let Some(out) = &args.out {
        super::write_bytes(out, raw_csv(&run.attained).as_bytes())?;
    }
    let promised = promised_mm(&promise);
    let result = CheckResult::new(&poses, &run.attained, promised * args.tolerance);
    let Some((pose, worst)) = result.worst() else {
        anyhow::bail!("no pose could be measured: check the instrument");
    };
    let figures = format!(
        "the largest position error {worst:.4} mm ({pose}; mean {:.4} mm over {} poses), the \
         calibration was verified to {promised:.4} mm ({}: worst AP_P {:.4} + worst RP_l {:.4} \
         mm){}",
        result.mean_mm(),
        result.errors_mm.len(),
        args.promise.display(),
        promise.worst_ap_p_mm(),
        promise.worst_rp_l_mm(),
        if args.tolerance == 1.0 {
            String::new()
        } else {
            format!(", × {} allowed", args.tolerance)
        }
    );
    if result.still_good() {
        println!("still good: {figures}");
        Ok(())
    } else {
        println!("retrain: {figures}");
        anyhow::bail!("the calibration no longer holds: measure and calibrate again")
    }
}
