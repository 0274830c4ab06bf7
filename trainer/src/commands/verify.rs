//! `hexacomp-trainer verify`: the ISO 9283 pose test on the machine — pose accuracy AP and pose
//! repeatability RP at the standard's five poses (and orientation and extra poses), with the raw
//! attained poses, a JSON report and a readable HTML page.

use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

use anyhow::Context;
use hexacomp_core::Geometry;
use hexacomp_iso9283::pose_test::{
    TestCube, TestPoseOptions, approach_pose, cycle_poses, test_cube,
};
use hexacomp_iso9283::verify::{PoseTest, TestRun, characteristics_of};
use hexacomp_iso9283::verify_report::{Conditions, VerifyReport, html, improvement, raw_csv};
use hexacomp_measuring::campaign::CampaignOptions;
use hexacomp_measuring::registration::InstrumentMpe;
use hexacomp_report::table::Table;

/// Test the machine's pose accuracy and repeatability as ISO 9283 defines them.
///
/// The test cube is the largest cube with edges parallel to the base axes inside the task
/// workspace (within the legs' stroke); P1 is its centre and P2–P5 lie on its diagonal plane at
/// 10 % of the diagonal from the corners. A hexapod is a six-axis machine, so six orientation
/// poses O1–O6 about P1 (± a, b, c) are added unless --no-orientation-poses; --extra-poses adds
/// poses drawn from the workspace. Each of the --cycles cycles visits P1, P5, P4, P3, P2, then
/// the others, each approached from the same pose every cycle; every attained pose is measured
/// (--readings combined as a campaign does), brought into the base frame (--registration) and
/// fitted.
///
/// Per pose: AP_P (the distance from the commanded position to the barycentre of the attained
/// ones), AP_a/b/c (the mean angle minus the commanded one), RP_l (the mean distance of the
/// attained positions from their barycentre plus three sample standard deviations of it) and
/// RP_a/b/c (three sample standard deviations of the angle). Writes --out (the raw attained
/// poses), --json (figures, conditions and attained poses) and --report (HTML, with a chart of
/// the attained points around each pose; --before sets a previous run's report beside it).
///
/// On the virtual machine --model is the compensation its controller applies; on a real machine
/// compensation is whatever the NC has active.
#[derive(Debug, clap::Args)]
pub struct VerifyArgs {
    /// The raw attained poses: CSV `cycle,pose,x,y,z,a,b,c` (mm, degrees, base frame).
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
    /// With the virtual machine: the model its controller applies (`calibrate` writes one).
    #[arg(long, value_name = "FILE")]
    model: Option<PathBuf>,
    /// The registration that brings the instrument's measurements into the base frame.
    ///
    /// Made by `hexacomp-trainer register`; without it they are taken to be in the base
    /// frame.
    #[arg(long, value_name = "FILE")]
    registration: Option<PathBuf>,
    /// Cycles, 2 to 10000 (ISO 9283 asks for 30).
    #[arg(long, default_value_t = 30, value_parser = clap::value_parser!(u16).range(2..=10000))]
    cycles: u16,
    #[command(flatten)]
    rig: super::rig::RigArgs,
    /// The report as JSON (default: --out with the extension .json).
    #[arg(help_heading = "Output", long, value_name = "FILE")]
    json: Option<PathBuf>,
    /// The readable report, HTML (default: --out with the extension .html).
    #[arg(help_heading = "Output", long, value_name = "FILE")]
    report: Option<PathBuf>,
    /// A previous run's JSON report (the same poses), set beside this one in the HTML report
    /// (before and after a calibration).
    #[arg(help_heading = "Output", long, value_name = "FILE")]
    before: Option<PathBuf>,
    /// Leave out the orientation poses O1–O6 (test ISO's five poses and any extra ones only).
    #[arg(help_heading = "Test poses", long)]
    no_orientation_poses: bool,
    /// Poses drawn from the task workspace (seeded by --seed) added to the test, E1….
    #[arg(help_heading = "Test poses", long, default_value_t = 0)]
    extra_poses: usize,
    /// The instrument's maximum permissible error `A+B` (µm + µm/m), stated in the report.
    #[arg(help_heading = "Conditions", long, value_name = "A+B")]
    instrument_mpe: Option<InstrumentMpe>,
    /// The air temperature during the test, °C, stated in the report.
    #[arg(
        help_heading = "Conditions",
        long,
        value_name = "CELSIUS",
        allow_negative_numbers = true
    )]
    air_temperature: Option<f64>,
    /// The machine's temperature during the test, °C, stated in the report.
    #[arg(
        help_heading = "Conditions",
        long,
        value_name = "CELSIUS",
        allow_negative_numbers = true
    )]
    machine_temperature: Option<f64>,
}

impl VerifyArgs {
    /// The JSON report's path.
    fn json_path(&self) -> PathBuf {
        self.json
            .clone()
            .unwrap_or_else(|| self.out.with_extension("json"))
    }

    /// The HTML report's path.
    fn report_path(&self) -> PathBuf {
        self.report
            .clone()
            .unwrap_or_else(|| self.out.with_extension("html"))
    }

    /// The files this command reads and writes.
    pub fn files(&self) -> super::Files<'_> {
        super::Files {
            inputs: [&self.model, &self.registration, &self.before]
                .into_iter()
                .flatten()
                .map(PathBuf::as_path)
                .chain(self.rig.instrument_file())
                .collect(),
            outputs: std::iter::once(&self.out)
                .chain(self.json.iter().chain(&self.report))
                .map(PathBuf::as_path)
                .collect(),
        }
    }
}

/// A temperature option, checked.
fn temperature(name: &str, value: Option<f64>) -> anyhow::Result<Option<f64>> {
    if let Some(t) = value {
        anyhow::ensure!(
            t.is_finite() && (-100.0..=200.0).contains(&t),
            "--{name} {t}: a temperature in °C between -100 and 200 is needed"
        );
    }
    Ok(value)
}

/// A previous run's report, read and checked.
fn read_before(path: &Path) -> anyhow::Result<VerifyReport> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    Ok(VerifyReport::from_json(&text, &path.display().to_string())?)
}

pub fn run(geometry: &Geometry, args: &VerifyArgs) -> anyhow::Result<()> {
    let (json_path, report_path) = (args.json_path(), args.report_path());
    refuse_shared_outputs(args, &json_path, &report_path)?;
    let air = temperature("air-temperature", args.air_temperature)?;
    let machine_temperature = temperature("machine-temperature", args.machine_temperature)?;
    let (compensation, instrument_frame) = args.rig.compensation_and_frame(
        geometry,
        args.model.as_deref(),
        args.registration.as_deref(),
    )?;
    let before = args.before.as_deref().map(read_before).transpose()?;
    let rig = args.rig.build(geometry, compensation)?;
    let cube = test_cube(geometry)?;
    let poses = cycle_poses(
        geometry,
        &cube,
        &TestPoseOptions {
            orientation: !args.no_orientation_poses,
            extra: args.extra_poses,
            seed: args.rig.seed,
        },
    )?;
    if let (Some(before), Some(path)) = (&before, &args.before) {
        before.check_same_poses(&poses, &path.display().to_string())?;
    }
    let cycles = usize::from(args.cycles);
    let options = rig.options;
    announce_test(&cube, poses.len(), cycles, &options);
    let test = PoseTest {
        geometry,
        poses: &poses,
        cycles,
        instrument_frame,
        options,
        approach: approach_pose(&poses),
    };
    let (run, outcome) = run_test(&test, rig, args);
    // The attained poses are kept whatever happens next (a machine that stops, a pose with too
    // few of them for its figures); with none, an earlier run's file is left as it is.
    if !run.attained.is_empty() {
        super::write_bytes(&args.out, raw_csv(&run.attained).as_bytes())?;
    }
    let kept = |e: anyhow::Error| {
        e.context(format!(
            "the {} attained poses measured are in {}",
            run.attained.len(),
            args.out.display()
        ))
    };
    outcome.map_err(|e| kept(e.into()))?;
    let figures = characteristics_of(&poses, &run.attained).map_err(|e| kept(e.into()))?;
    let report = VerifyReport::new(
        conditions(args, geometry, &options, cycles, air, machine_temperature),
        &cube,
        &poses
            .iter()
            .map(|p| (p.name.clone(), p.commanded))
            .collect::<Vec<_>>(),
        &figures,
        &run.attained,
        &run.missed,
        humantime::format_rfc3339_seconds(SystemTime::now()).to_string(),
    );
    print_figures(&report, before.as_ref());
    super::write_bytes(&json_path, report.to_json().as_bytes())?;
    super::write_bytes(&report_path, html(&report, before.as_ref())?.as_bytes())?;
    eprintln!(
        "wrote {}, {} and {}",
        args.out.display(),
        json_path.display(),
        report_path.display()
    );
    Ok(())
}

/// Refuses --out, --json and --report naming one file twice, and the derived reports naming an
/// input (--out's are checked with the inputs by main).
fn refuse_shared_outputs(
    args: &VerifyArgs,
    json_path: &Path,
    report_path: &Path,
) -> anyhow::Result<()> {
    let outputs = [args.out.as_path(), json_path, report_path];
    for (k, a) in outputs.iter().enumerate() {
        anyhow::ensure!(
            !outputs[k + 1..].contains(a),
            "{} is given for two outputs: give --out, --json and --report different files",
            a.display()
        );
    }
    let inputs = args.files().inputs;
    for derived in [json_path, report_path] {
        hexacomp_formats::refuse_same_file(derived, &inputs)?;
    }
    Ok(())
}

/// Says what the test measures: the cube (centre in the base frame, mm; side, mm), the poses
/// and cycles, and how long the dwelling alone takes.
fn announce_test(cube: &TestCube, poses: usize, cycles: usize, options: &CampaignOptions) {
    let measurements = cycles * poses;
    let dwelling = options.dwell.as_secs_f64() * (options.readings - 1) as f64;
    eprintln!(
        "test cube: centre {:?} mm, side {:.3} mm; {poses} poses × {cycles} cycles = \
         {measurements} attained poses, {} readings each{}",
        cube.centre.to_array(),
        cube.side_mm,
        options.readings,
        if dwelling > 0.0 {
            format!(
                ", about {} of dwelling alone",
                humantime::format_duration(Duration::from_secs(
                    (measurements as f64 * dwelling) as u64
                ))
            )
        } else {
            String::new()
        }
    );
}

/// Runs the test on the rig with a progress bar, and says which attained poses were not
/// measured: what was attained, and how the test ended.
fn run_test(
    test: &PoseTest<'_>,
    rig: super::rig::Rig,
    args: &VerifyArgs,
) -> (TestRun, hexacomp_iso9283::Result<()>) {
    let super::rig::Rig {
        mut machine,
        mut instrument,
        ..
    } = rig;
    let bar = args
        .rig
        .progress_bar(test.cycles * test.poses.len(), "attained poses");
    let mut run = TestRun::default();
    let outcome = test.run(machine.as_mut(), instrument.as_mut(), &mut run, &mut || {
        bar.inc(1)
    });
    bar.finish_and_clear();
    for missed in &run.missed {
        eprintln!(
            "{} in cycle {} was not measured ({}): left out of its figures",
            missed.pose, missed.cycle, missed.why
        );
    }
    (run, outcome)
}

/// The conditions of the test, as the report states them.
fn conditions(
    args: &VerifyArgs,
    geometry: &Geometry,
    options: &CampaignOptions,
    cycles: usize,
    air_temperature_c: Option<f64>,
    machine_temperature_c: Option<f64>,
) -> Conditions {
    Conditions {
        rig: args.rig.description(),
        instrument_mpe_um: args.instrument_mpe.map(|m| [m.constant_um, m.per_metre_um]),
        readings: options.readings,
        dwell_s: options.dwell.as_secs_f64(),
        cycles,
        air_temperature_c,
        machine_temperature_c,
        model: args.model.as_ref().map(|p| p.display().to_string()),
        registration: args.registration.as_ref().map(|p| p.display().to_string()),
        geometry: geometry.fingerprint().to_string(),
    }
}

/// Prints each pose's figures (µm and degrees), and the worst AP_P and RP_l beside `before`'s.
fn print_figures(report: &VerifyReport, before: Option<&VerifyReport>) {
    let mut table = Table::new([
        "pose", "n", "AP_P µm", "AP_a °", "AP_b °", "AP_c °", "RP_l µm", "RP_a °", "RP_b °",
        "RP_c °",
    ]);
    for pose in &report.poses {
        let f = &pose.figures;
        table.row([
            pose.name.clone(),
            f.cycles.to_string(),
            format!("{:.2}", f.ap_p_mm * 1000.0),
            format!("{:.5}", f.ap_a_deg),
            format!("{:.5}", f.ap_b_deg),
            format!("{:.5}", f.ap_c_deg),
            format!("{:.2}", f.rp_l_mm * 1000.0),
            format!("{:.5}", f.rp_a_deg),
            format!("{:.5}", f.rp_b_deg),
            format!("{:.5}", f.rp_c_deg),
        ]);
    }
    println!("{table}");
    match before {
        Some(before) => println!(
            "worst AP_P {:.2} µm (before {:.2} µm: {}); worst RP_l {:.2} µm (before {:.2} µm)",
            report.worst_ap_p_mm() * 1000.0,
            before.worst_ap_p_mm() * 1000.0,
            improvement(before.worst_ap_p_mm(), report.worst_ap_p_mm()),
            report.worst_rp_l_mm() * 1000.0,
            before.worst_rp_l_mm() * 1000.0
        ),
        None => println!(
            "worst AP_P {:.2} µm; worst RP_l {:.2} µm",
            report.worst_ap_p_mm() * 1000.0,
            report.worst_rp_l_mm() * 1000.0
        ),
    }
}
