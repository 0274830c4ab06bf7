//! `hexacomp-trainer register`: locates the instrument in the machine's base frame from
//! fiducials; `--registration` of `solve`, `identify` and `calibrate` uses the result.

use std::path::PathBuf;
use std::time::SystemTime;

use hexacomp_core::Geometry;
use hexacomp_core::kinematics::target_points;
use hexacomp_core::records::NamedPoint;
use hexacomp_core::rigid_fit::{Locked, PARAMETER_NAMES};
use hexacomp_formats::{RegistrationFile, read_fiducials};
use hexacomp_measuring::registration::{
    InstrumentMpe, RegistrationOptions, SupportedAccuracy, accuracy_from_residuals, register,
    supported_accuracy,
};
use hexacomp_report::table::Table;

use super::write_bytes;

/// Locate the instrument (laser tracker, measuring arm) in the machine's base frame from
/// fiducials on the base measured in both frames, and write the registration.
///
/// The least-squares rigid transform (rotation and translation, no scale) taking the measured
/// fiducials onto the nominal ones, matched by name, as "locate instrument" does in metrology
/// software. Prints every fiducial's residual, their RMS and maximum, and where the instrument
/// stands: its position in the base frame (mm) and its rotation as angles a, b, c (degrees,
/// R = Rz(c)·Ry(b)·Rx(a), the convention of every pose).
///
/// Refused, and no file written (an existing one is left as it was), when fewer than three
/// names are common to both files, a name is in one file only, the fiducials are nearly on one
/// line, or a residual exceeds --tolerance (the message names the worst fiducial and what the
/// data points to: two names swapped, inches, a fiducial knocked).
///
/// Then give the file to `solve`, `identify` or `calibrate` as --registration: their
/// measurements are in the instrument's frame and are brought into the base frame first.
#[derive(Debug, clap::Args)]
pub struct RegisterArgs {
    /// Nominal fiducials on the machine base: CSV `name,x,y,z`, base frame, mm.
    ///
    /// From the machine's drawing or an earlier CMM report. Default: the `fiducials` of the
    /// geometry.
    #[arg(long, value_name = "FILE")]
    nominal: Option<PathBuf>,
    /// The same fiducials as the instrument measured them: CSV `name,x,y,z`, instrument
    /// frame, mm.
    ///
    /// Any row order; an optional `weight` column (default 1; 0 reports a fiducial without
    /// using it).
    #[arg(long, value_name = "FILE")]
    measured: PathBuf,
    /// Output registration TOML.
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
    /// Refuse the registration when a fiducial's residual exceeds this, mm.
    #[arg(long, default_value_t = RegistrationOptions::default().tolerance_mm, value_name = "MM")]
    tolerance: f64,
    /// Parameters of the instrument's pose held at zero, comma-separated from x, y, z, a,
    /// b, c.
    ///
    /// `--lock a,b` keeps a levelled tracker's vertical (only a rotation about z is
    /// fitted).
    #[arg(long, value_delimiter = ',', value_name = "PARAMETERS", value_parser = parameter_name)]
    lock: Vec<String>,
    /// The instrument's stated accuracy, MPE = A µm + B µm/m of distance (e.g. 15+6).
    ///
    /// The registration then states what accuracy its measurements can support at the
    /// platform, and warns when the residuals or --tolerance disagree with it.
    #[arg(long, value_name = "A+B")]
    instrument_mpe: Option<InstrumentMpe>,
    /// The position accuracy (mm, 2σ) the calibration is to be proven to.
    ///
    /// With --instrument-mpe, a warning when the instrument set up like this cannot verify
    /// it.
    #[arg(long, value_name = "MM", requires = "instrument_mpe", value_parser = positive_mm)]
    goal: Option<f64>,
}

/// A finite length > 0, mm.
fn positive_mm(text: &str) -> Result<f64, String> {
    text.parse::<f64>()
        .ok()
        .filter(|v| v.is_finite() && *v > 0.0)
        .ok_or_else(|| format!("{text:?} is not a length > 0 (mm)"))
}

/// One of [`PARAMETER_NAMES`].
fn parameter_name(text: &str) -> Result<String, String> {
    if PARAMETER_NAMES.contains(&text) {
        Ok(text.to_string())
    } else {
        Err(format!(
            "{text:?} is not one of {}",
            PARAMETER_NAMES.join(", ")
        ))
    }
}

impl RegisterArgs {
    /// The files this command reads and writes.
    pub fn files(&self) -> super::Files<'_> {
        super::Files {
            inputs: self
                .nominal
                .iter()
                .map(PathBuf::as_path)
                .chain([self.measured.as_path()])
                .collect(),
            outputs: vec![&self.out],
        }
    }
}

pub fn run(geometry: &Geometry, args: &RegisterArgs) -> anyhow::Result<()> {
    let (nominal, nominal_source) = match &args.nominal {
        Some(path) => (
            read_fiducials(path)?.into_items(),
            path.display().to_string(),
        ),
        None => (
            geometry_fiducials(geometry)?,
            format!("the fiducials of geometry {}", geometry.name),
        ),
    };
    let measured = read_fiducials(&args.measured)?;
    let options = RegistrationOptions {
        tolerance_mm: args.tolerance,
        locked: Locked::from_names(args.lock.iter().map(String::as_str))
            .expect("clap checked the names"),
    };
    let registration = register(&nominal, &measured, &options).map_err(|e| {
        anyhow::anyhow!(
            "{} onto {nominal_source}: {e}\nno registration written",
            args.measured.display(),
        )
    })?;
    let created = humantime::format_rfc3339_seconds(SystemTime::now()).to_string();
    let mut file = registration.to_file(
        options.tolerance_mm,
        &nominal_source,
        &args.measured.display().to_string(),
        created,
    );
    let platform = target_points(geometry, &geometry.home_pose());
    let support = args.instrument_mpe.map(|mpe| {
        let support = supported_accuracy(&registration, &mpe, &platform);
        file.instrument_mpe_um = Some([mpe.constant_um, mpe.per_metre_um]);
        file.supported_mm = Some(2.0 * support.combined_mm);
        support
    });
    print_registration(&file);
    match support {
        Some(support) => report_support(&file, &support, args.goal),
        None => {
            // Without a stated accuracy, the residuals show the fiducials' noise: how far does
            // the registration itself move the platform's targets?
            let shown = accuracy_from_residuals(&registration);
            let support = supported_accuracy(&registration, &shown, &platform);
            println!(
                "the registration's own error at the platform, from the residuals: {:.4} mm (1σ); \
                 give --instrument-mpe for what the measurements support",
                support.registration_mm
            );
            if 2.0 * support.registration_mm > file.tolerance_mm {
                eprintln!(
                    "warning: the fiducials locate the instrument poorly for the platform: the \
                     registration alone may move a target there by {:.4} mm (2σ), more than the \
                     tolerance of {} mm; spread the fiducials wider and in height around the \
                     platform",
                    2.0 * support.registration_mm,
                    file.tolerance_mm
                );
            }
        }
    }
    write_bytes(&args.out, file.to_toml_string().as_bytes())?;
    eprintln!("wrote {}", args.out.display());
    Ok(())
}

/// Prints what the registration's measurements can support, and warns where the residuals, the
/// tolerance or the `goal` (mm, 2σ) ask for more than the instrument delivers.
fn report_support(file: &RegistrationFile, support: &SupportedAccuracy, goal: Option<f64>) {
    let [a, b] = file.instrument_mpe_um.unwrap_or_default();
    println!(
        "instrument MPE {a} µm + {b} µm/m: fiducials at {:.2}–{:.2} m, platform at {:.2} m",
        support.fiducial_distance_mm[0] / 1000.0,
        support.fiducial_distance_mm[1] / 1000.0,
        support.platform_distance_mm / 1000.0
    );
    println!(
        "  at the platform, a measured target is known to {:.4} mm (1σ, 3D): {:.4} mm from its \
         reading, {:.4} mm from this registration; {:.4} mm at 2σ",
        support.combined_mm,
        support.point_mm,
        support.registration_mm,
        2.0 * support.combined_mm
    );
    if support.residual_ratio > 1.0 {
        println!(
            "  the residuals (RMS {:.4} mm) are {:.1} times what the instrument explains ({:.4} \
             mm): the registration's error is scaled up by as much",
            file.rms_mm, support.residual_ratio, support.expected_rms_mm
        );
    }
    if support.residual_ratio > 3.0 {
        eprintln!(
            "warning: the residuals are {:.1} times what the instrument's accuracy explains: the \
             nominal positions or the fiducials themselves are off by more than the instrument's \
             error",
            support.residual_ratio
        );
    }
    if file.tolerance_mm < 2.0 * support.expected_rms_mm {
        eprintln!(
            "warning: --tolerance {} mm is tighter than the instrument holds at these distances \
             (residuals of about {:.4} mm are its noise): registrations will be refused for noise",
            file.tolerance_mm, support.expected_rms_mm
        );
    }
    if let Some(goal) = goal
        && 2.0 * support.combined_mm > goal
    {
        eprintln!(
            "warning: the goal of {goal} mm asks for more than this set-up can verify: a target \
             at the platform is known to {:.4} mm (2σ) only; move the instrument closer (it is \
             {:.2} m from the platform) or use a more accurate one",
            2.0 * support.combined_mm,
            support.platform_distance_mm / 1000.0
        );
    }
}

/// The fiducials the geometry names (weight 1); an error when it names none.
pub fn geometry_fiducials(geometry: &Geometry) -> anyhow::Result<Vec<NamedPoint>> {
    anyhow::ensure!(
        !geometry.fiducials.is_empty(),
        "geometry {} names no fiducials: give their nominal positions as a file (--nominal, or \
         --fiducials for simulate) or add [[fiducials]] to the geometry file",
        geometry.name
    );
    Ok(geometry
        .fiducials
        .iter()
        .map(|f| NamedPoint {
            name: f.name.clone(),
            position: f.position,
            weight: 1.0,
        })
        .collect())
}

/// Prints a registration as a metrologist reads it: the residual of every fiducial, RMS and
/// maximum, and the instrument's position and rotation in the base frame.
pub fn print_registration(file: &RegistrationFile) {
    let mut table = Table::new(["fiducial", "dx mm", "dy mm", "dz mm", "|r| mm", "weight"]);
    for f in &file.fiducials {
        table.row([
            f.name.clone(),
            format!("{:+.4}", f.residual[0]),
            format!("{:+.4}", f.residual[1]),
            format!("{:+.4}", f.residual[2]),
            format!("{:.4}", f.residual_mm()),
            if f.weight > 0.0 {
                format!("{}", f.weight)
            } else {
                "0 (not used)".into()
            },
        ]);
    }
    println!("residuals (measured brought into the base frame − nominal):\n{table}");
    let used = file.fiducials.iter().filter(|f| f.weight > 0.0).count();
    println!(
        "{used} fiducials used: RMS {:.4} mm, max {:.4} mm (tolerance {} mm)",
        file.rms_mm, file.max_mm, file.tolerance_mm
    );
    let [x, y, z, a, b, c] = file.instrument_pose;
    // The angle of the rotation from its trace (exact at 180° too).
    let r = file.instrument_pose().rotation();
    let angle = (0.5 * (r.x_axis.x + r.y_axis.y + r.z_axis.z - 1.0))
        .clamp(-1.0, 1.0)
        .acos()
        .to_degrees();
    println!("instrument in the base frame:");
    println!("  position   x {x:.4} mm, y {y:.4} mm, z {z:.4} mm");
    println!(
        "  rotation   a {a:.5}°, b {b:.5}°, c {c:.5}° (R = Rz(c)·Ry(b)·Rx(a)); {angle:.5}° in all"
    );
    if !file.locked.is_empty() {
        println!("  locked     {} (held at zero)", file.locked.join(", "));
    }
    if let (Some([a, b]), Some(supported)) = (file.instrument_mpe_um, file.supported_mm) {
        println!(
            "  supports   a target at the platform to {supported:.4} mm (2σ) with an instrument \
             of MPE {a} µm + {b} µm/m"
        );
    }
    println!(
        "made {} from {} (nominal) and {} (measured)",
        file.created, file.nominal, file.measured
    );
}
