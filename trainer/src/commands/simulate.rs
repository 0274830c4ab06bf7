//! `hexacomp-trainer simulate`: measures a plan on the virtual platform.

use std::path::PathBuf;

use anyhow::Context;
use hexacomp_core::Geometry;
use hexacomp_core::error::compact;
use hexacomp_core::pose::PoseConvention;
use hexacomp_core::records::{MeasuredConfiguration, NamedPoint, NamedPose};
use hexacomp_formats::{
    Records, read_fiducials, read_poses, write_fiducials, write_measurements_in,
};
use hexacomp_lab::acquire::{Reporting, as_reported};
use hexacomp_virtual::{
    DEFAULT_MACHINE_SEED, ErrorModel, ErrorVariant, VirtualPlatform, measure_fiducials,
};

use hexacomp_formats::write_file;

use super::register::geometry_fiducials;

/// Measure a plan on the built-in virtual platform, writing exactly what a measuring arm would
/// have produced.
///
/// The virtual machine differs from the geometry by joint-centre and leg-zero offsets, lead-screw
/// pitch errors, gravity compliance and repeatability noise; its device reads the geometry's
/// targets with 0.020 mm uncertainty (three readings averaged). Every pose is commanded with the
/// nominal inverse kinematics (uncompensated). Output: a measurements CSV,
/// `id,x,y,z,a,b,c,q1..q6,p1x,p1y,p1z,..,pNz` (mm, degrees; targets in the base frame).
///
/// With --instrument-pose the targets are written as a tracker standing there reports them, in
/// its own frame; --fiducials and --fiducials-out then write the fiducials on the base as that
/// tracker measures them, for `register`. --drop-rate leaves one target unseen in that share of
/// the configurations (empty cells); --probe writes the platform's pose (`mx..mc`) as a 6-DoF
/// probe reports it instead of the targets.
#[derive(Debug, clap::Args)]
pub struct SimulateArgs {
    /// Poses CSV to measure (`hexacomp-trainer plan`).
    #[arg(long, value_name = "FILE")]
    plan: PathBuf,
    /// Seed of the repeatability and measurement noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Seed that draws the virtual machine (its errors); 18 resembles the paper's prototype.
    #[arg(help_heading = "Virtual machine", long, default_value_t = DEFAULT_MACHINE_SEED)]
    machine_seed: u64,
    /// Error variant of the virtual machine.
    #[arg(help_heading = "Virtual machine", long, default_value_t = ErrorVariant::Paper, value_parser = super::named::<ErrorVariant>(ErrorVariant::ALL.map(ErrorVariant::name)))]
    error_variant: ErrorVariant,
    /// Output measurements CSV.
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
    /// Where the instrument stands: its pose `x,y,z,a,b,c` in the base frame (mm, degrees).
    ///
    /// R = Rz(c)·Ry(b)·Rx(a). The targets are then written in the instrument's frame.
    #[arg(
        help_heading = "Instrument",
        long,
        value_name = "X,Y,Z,A,B,C",
        value_delimiter = ',',
        allow_negative_numbers = true
    )]
    instrument_pose: Option<Vec<f64>>,
    /// Nominal fiducials on the machine base: CSV `name,x,y,z`, base frame, mm. Default: the
    /// `fiducials` of the geometry.
    #[arg(
        help_heading = "Instrument",
        long,
        value_name = "FILE",
        requires = "fiducials_out"
    )]
    fiducials: Option<PathBuf>,
    /// Output: the fiducials as the instrument measures them (`name,x,y,z`, its frame, mm).
    #[arg(help_heading = "Instrument", long, value_name = "FILE")]
    fiducials_out: Option<PathBuf>,
    /// Share of the configurations (0–1) in which one target, drawn at random, is not seen: its
    /// cells are left empty.
    #[arg(
        help_heading = "Instrument",
        long,
        default_value_t = 0.0,
        value_name = "SHARE",
        conflicts_with = "probe"
    )]
    drop_rate: f64,
    /// Report the platform's pose as a 6-DoF probe does, instead of the targets.
    ///
    /// Columns mx..mc, fitted to the measured targets.
    #[arg(help_heading = "Instrument", long)]
    probe: bool,
    /// Rotation convention of the measured poses written with --probe.
    ///
    /// linuxcnc: R = Rz(c)·Ry(b)·Rx(a); pi-uvw: R = Rx(U)·Ry(V)·Rz(W), rotations about the
    /// moving axes.
    #[arg(help_heading = "Instrument", long, default_value_t = PoseConvention::Linuxcnc, value_parser = super::named::<PoseConvention>(PoseConvention::ALL.map(PoseConvention::name)), value_name = "CONVENTION", requires = "probe")]
    pose_convention: PoseConvention,
    /// Noise of each fiducial coordinate the instrument measures, mm (1 σ).
    #[arg(
        help_heading = "Instrument",
        long,
        default_value_t = 0.010,
        value_name = "MM"
    )]
    fiducial_noise: f64,
}

impl SimulateArgs {
    /// The files this command reads and writes.
    pub fn files(&self) -> super::Files<'_> {
        super::Files {
            inputs: std::iter::once(self.plan.as_path())
                .chain(self.fiducials.as_deref())
                .collect(),
            outputs: std::iter::once(self.out.as_path())
                .chain(self.fiducials_out.as_deref())
                .collect(),
        }
    }
}

/// The seed of the fiducial readings, apart from the machine's moves and the target readings.
fn fiducial_seed(seed: u64) -> u64 {
    seed ^ 0x6669_6475_6369_616c
}

pub fn run(geometry: &Geometry, args: &SimulateArgs) -> anyhow::Result<()> {
    if let Some(fiducials_out) = &args.fiducials_out {
        anyhow::ensure!(
            fiducials_out != &args.out,
            "--fiducials-out and --out name the same file {}",
            args.out.display()
        );
        hexacomp_formats::refuse_same_file(fiducials_out, &[&args.out])?;
    }
    let instrument = super::instrument_pose(args.instrument_pose.as_deref())?;
    let plan = read_poses(&args.plan)?;
    let fiducials = nominal_fiducials(geometry, args)?;
    let model = ErrorModel::variant(args.error_variant);
    let mut platform = VirtualPlatform::new(geometry, &model, args.machine_seed, args.seed)?;
    let mut rows = measure(geometry, &mut platform, &plan)?;
    let reporting = Reporting {
        instrument,
        missed_share: args.drop_rate,
        probe: args.probe,
        seed: args.seed,
    };
    as_reported(geometry, &mut rows, &reporting)?;
    if let (Some((nominal, source)), Some(out)) = (&fiducials, &args.fiducials_out) {
        let measured = measure_fiducials(
            nominal,
            &instrument,
            args.fiducial_noise,
            fiducial_seed(args.seed),
        )?;
        write_file(out, |w| write_fiducials(w, &measured))?;
        eprintln!(
            "measured {} fiducials of {} from the instrument ({} mm noise) → {}",
            measured.len(),
            source,
            args.fiducial_noise,
            out.display()
        );
    }
    write_file(&args.out, |w| {
        write_measurements_in(w, &rows, args.pose_convention)
    })?;
    eprintln!(
        "measured {} configurations on virtual machine {} ({} errors) → {}",
        rows.len(),
        args.machine_seed,
        args.error_variant,
        args.out.display()
    );
    Ok(())
}

/// The fiducials' nominal positions (base frame, mm) to measure for --fiducials-out, and where
/// they come from: --fiducials, or the geometry's; `None` without --fiducials-out.
fn nominal_fiducials(
    geometry: &Geometry,
    args: &SimulateArgs,
) -> anyhow::Result<Option<(Vec<NamedPoint>, String)>> {
    Ok(match (&args.fiducials, &args.fiducials_out) {
        (Some(path), _) => Some((
            read_fiducials(path)?.into_items(),
            path.display().to_string(),
        )),
        (None, Some(_)) => Some((
            geometry_fiducials(geometry)?,
            format!("geometry {}", geometry.name),
        )),
        (None, None) => None,
    })
}

/// Measures every configuration of `plan` on the virtual machine `platform` (the targets in the
/// base frame), refusing a pose outside the geometry's stroke, naming its line.
fn measure(
    geometry: &Geometry,
    platform: &mut VirtualPlatform,
    plan: &Records<NamedPose>,
) -> anyhow::Result<Vec<MeasuredConfiguration>> {
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
        let [min, max] = geometry.leg_range;
        if let Some((leg, length)) = super::leg_outside_stroke(geometry, &row.pose()) {
            anyhow::bail!(
                "{}: the pose needs leg {leg} at {} mm, outside the geometry's stroke [{min}, \
                 {max}] mm",
                at(),
                compact(length, 3)
            );
        }
        let measured = platform
            .measure_plan(std::slice::from_ref(row))
            .with_context(|| format!("{}: cannot be measured on the virtual machine", at()))?;
        rows.extend(measured);
    }
    Ok(rows)
}
