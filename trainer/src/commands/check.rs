//! `hexacomp-trainer check`: does the calibration still hold? The poses `verify` tested after
//! the calibration, measured once more with the compensation active, compared with what it
//! proved.

use std::path::{Path, PathBuf};

use anyhow::Context;
use hexacomp_core::Geometry;
use hexacomp_iso9283::check::{Allowed, CheckResult, Verdict, promised, verified_poses};
use hexacomp_iso9283::pose_test::approach_pose;
use hexacomp_iso9283::verify::{PoseTest, TestRun};
use hexacomp_iso9283::verify_report::{VerifyReport, raw_csv};

/// Check that the calibration still holds (monthly, or after a crash or a move of the machine).
///
/// Measures the poses of the ISO 9283 report of `verify` run after the calibration (--promise:
/// P1–P5 and, if it had them, the orientation and extra poses), once each, with the compensation
/// active (on the virtual machine: --model), and compares each position error |attained −
/// commanded| with what that test proved: one attained position lies within AP_P + RP_l of the
/// commanded one, an angle within |AP_a| + RP_a (the worst of each over the report's poses),
/// times --tolerance. Prints one line: "still good" (exit status 0), or "retrain" with the
/// figures, or "inconclusive" when a pose could not be measured (exit status 1).
#[derive(Debug, clap::Args)]
pub struct CheckArgs {
    /// The JSON report of `verify` after the calibration: what it was proven to.
    #[arg(long, value_name = "FILE")]
    promise: PathBuf,
    /// With the virtual machine: the model its controller applies.
    #[arg(long, value_name = "FILE")]
    model: Option<PathBuf>,
    /// The registration that brings the instrument's measurements into the base frame.
    #[arg(long, value_name = "FILE")]
    registration: Option<PathBuf>,
    /// The error allowed, as a multiple of the promise.
    #[arg(long, default_value_t = 1.0)]
    tolerance: f64,
    #[command(flatten)]
    rig: super::rig::RigArgs,
    /// Write the attained poses here (CSV `cycle,pose,x,y,z,a,b,c`, mm, degrees, base frame).
    #[arg(help_heading = "Output", long, value_name = "FILE")]
    out: Option<PathBuf>,
}

impl CheckArgs {
    /// The files this command reads and writes.
    pub fn files(&self) -> super::Files<'_> {
        super::Files {
            inputs: std::iter::once(&self.promise)
                .chain(self.model.iter().chain(&self.registration))
                .map(PathBuf::as_path)
                .chain(self.rig.instrument_file())
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
    let promise = read_promise(&args.promise, geometry)?;
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
        // Approached as verify did: P1 from P2.
        approach: approach_pose(&poses),
    };
    let mut run = TestRun::default();
    test.run(machine.as_mut(), instrument.as_mut(), &mut run, &mut || {})?;
    for missed in &run.missed {
        eprintln!(
            "{} was not measured ({}): left out",
            missed.pose, missed.why
        );
    }
    if let Some(out) = &args.out {
        super::write_bytes(out, raw_csv(&run.attained).as_bytes())?;
    }
    let allowed = promised(&promise, args.tolerance);
    let result = CheckResult::new(&poses, &run.attained, &run.missed, allowed);
    let figures = format!(
        "{}; promised by {} (worst AP_P {:.4} + worst RP_l {:.4} mm{})",
        errors_found(&result, &allowed),
        args.promise.display(),
        promise.worst_ap_p_mm(),
        promise.worst_rp_l_mm(),
        if args.tolerance == 1.0 {
            String::new()
        } else {
            format!(", × {}", args.tolerance)
        }
    );
    print_verdict(&result, &figures)
}

/// The JSON report of `verify` at `path`, refused when it verified another geometry.
fn read_promise(path: &Path, geometry: &Geometry) -> anyhow::Result<VerifyReport> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let promise = VerifyReport::from_json(&text, &path.display().to_string())?;
    anyhow::ensure!(
        promise.conditions.geometry == geometry.fingerprint().to_string(),
        "{}: it verified another geometry ({}; this one is {}): give the report of this \
         machine's calibration",
        path.display(),
        promise.conditions.geometry,
        geometry.fingerprint()
    );
    Ok(promise)
}

/// The largest position error found (mm, with the mean over the poses) against the `allowed`,
/// and the largest angle error as a share of its allowed.
fn errors_found(result: &CheckResult, allowed: &Allowed) -> String {
    let position = result
        .worst_position()
        .map_or("no pose measured".to_string(), |(pose, e)| {
            format!(
                "the largest position error {e:.4} mm ({pose}; mean {:.4} mm over {} poses) of \
                 {:.4} mm allowed",
                result.mean_position_mm(),
                result.errors.len(),
                allowed.position_mm
            )
        });
    let angle = result
        .worst_angle_share()
        .map_or(String::new(), |(pose, axis, share)| {
            format!(
                ", the largest angle error {:.0} % of the allowed ({pose}, {axis})",
                100.0 * share
            )
        });
    format!("{position}{angle}")
}

/// Prints the verdict with its `figures`: "still good" (Ok), or "retrain" or "inconclusive"
/// (an error saying what to do).
fn print_verdict(result: &CheckResult, figures: &str) -> anyhow::Result<()> {
    match result.verdict() {
        Verdict::StillGood => {
            println!("still good: {figures}");
            Ok(())
        }
        Verdict::Retrain => {
            println!("retrain: {figures}");
            anyhow::bail!("the calibration no longer holds: measure and calibrate again")
        }
        Verdict::Inconclusive => {
            let missed: Vec<String> = result
                .missed
                .iter()
                .map(|(pose, why)| format!("{pose} ({why})"))
                .collect();
            println!(
                "inconclusive: not measured: {}; {figures}",
                missed.join(", ")
            );
            anyhow::bail!("the check is incomplete: check the instrument and run it again")
        }
    }
}
