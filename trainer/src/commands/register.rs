//! `hexacomp-trainer register`: locates the instrument in the machine's base frame from
//! fiducials; `--registration` of `solve`, `identify` and `calibrate` uses the result.

use std::path::PathBuf;
use std::time::SystemTime;

use hexacomp_core::pose::rotation_vector;
use hexacomp_core::rigid_fit::{Locked, PARAMETER_NAMES};
use hexacomp_formats::{RegistrationFile, read_fiducials};
use hexacomp_trainer::registration::{RegistrationOptions, register};
use hexacomp_trainer::table::Table;

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
    /// Nominal fiducials on the machine base: CSV `name,x,y,z`, base frame, mm (from the
    /// machine's drawing or an earlier CMM report).
    #[arg(long, value_name = "FILE")]
    nominal: PathBuf,
    /// The same fiducials as the instrument measured them: CSV `name,x,y,z`, instrument frame,
    /// mm, any row order; an optional `weight` column (default 1; 0 reports a fiducial without
    /// using it).
    #[arg(long, value_name = "FILE")]
    measured: PathBuf,
    /// Output registration TOML.
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
    /// Refuse the registration when a fiducial's residual exceeds this, mm.
    #[arg(long, default_value_t = RegistrationOptions::default().tolerance_mm, value_name = "MM")]
    tolerance: f64,
    /// Parameters of the instrument's pose held at zero, comma-separated from x, y, z, a, b, c:
    /// `--lock a,b` keeps a levelled tracker's vertical (only a rotation about z is fitted).
    #[arg(long, value_delimiter = ',', value_name = "PARAMETERS", value_parser = parameter_name)]
    lock: Vec<String>,
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
            inputs: vec![&self.nominal, &self.measured],
            outputs: vec![&self.out],
        }
    }
}

pub fn run(args: &RegisterArgs) -> anyhow::Result<()> {
    let nominal = read_fiducials(&args.nominal)?;
    let measured = read_fiducials(&args.measured)?;
    let options = RegistrationOptions {
        tolerance_mm: args.tolerance,
        locked: Locked::from_names(args.lock.iter().map(String::as_str))
            .expect("clap checked the names"),
    };
    let registration = register(&nominal, &measured, &options).map_err(|e| {
        anyhow::anyhow!(
            "{} onto {}: {e}\nno registration written",
            args.measured.display(),
            args.nominal.display()
        )
    })?;
    let created = humantime::format_rfc3339_seconds(SystemTime::now()).to_string();
    let file = registration.to_file(
        &options,
        &args.nominal.display().to_string(),
        &args.measured.display().to_string(),
        created,
    );
    print_registration(&file);
    write_bytes(&args.out, file.to_toml_string().as_bytes())?;
    eprintln!("wrote {}", args.out.display());
    Ok(())
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
    let angle = rotation_vector(&file.instrument_pose().rotation())
        .length()
        .to_degrees();
    println!("instrument in the base frame:");
    println!("  position   x {x:.4} mm, y {y:.4} mm, z {z:.4} mm");
    println!(
        "  rotation   a {a:.5}°, b {b:.5}°, c {c:.5}° (R = Rz(c)·Ry(b)·Rx(a)); {angle:.5}° in all"
    );
    if !file.locked.is_empty() {
        println!("  locked     {} (held at zero)", file.locked.join(", "));
    }
    println!(
        "made {} from {} (nominal) and {} (measured)",
        file.created, file.nominal, file.measured
    );
}
