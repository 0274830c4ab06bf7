//! `hexacomp-trainer geometry`: prints or writes the geometry in use, with its fingerprint, or
//! converts the geometry of a LinuxCNC hexapod configuration.

use std::path::PathBuf;

use hexacomp_core::{Geometry, Workspace};
use hexacomp_measuring::linuxcnc::{ConversionOptions, LinuxCncHexapod};

/// Print the geometry in use (the built-in `prototype` unless --geometry is given) as TOML, or
/// convert a LinuxCNC hexapod configuration (--from-linuxcnc).
///
/// Use it to start a geometry file of your own machine from the prototype, or to see the
/// fingerprint that model files are bound to.
///
/// With --from-linuxcnc the joint centres come from the genhexkins `setp` lines of the HAL files
/// the ini names, the units from [TRAJ]LINEAR_UNITS, the home pose from [TRAJ]HOME and the leg
/// stroke from the joints' MIN_LIMIT/MAX_LIMIT; everything is converted to mm. LinuxCNC does not
/// know the task workspace or the measured targets: the workspace defaults to a cylinder of a
/// tenth of the base radius about home (tilt 10°, yaw ±10°), the targets to the midpoints of the
/// platform joint pairs. Check both before calibrating.
#[derive(Debug, clap::Args)]
pub struct GeometryArgs {
    /// Write the TOML to this file instead of standard output.
    #[arg(long, value_name = "FILE")]
    out: Option<PathBuf>,

    /// Convert the hexapod (genhexkins) of this LinuxCNC ini file instead.
    #[arg(long, value_name = "INI")]
    from_linuxcnc: Option<PathBuf>,

    /// With --from-linuxcnc: leg stroke MIN,MAX in mm (default: the ini's joint limits).
    #[arg(long, value_name = "MIN,MAX", value_parser = parse_pair, requires = "from_linuxcnc", allow_hyphen_values = true)]
    leg_range: Option<[f64; 2]>,

    /// With --from-linuxcnc: workspace radius, mm (with --z-range, --tilt-max, --yaw-range).
    #[arg(long, value_name = "MM", requires_all = ["from_linuxcnc", "z_range", "tilt_max", "yaw_range"])]
    workspace_radius: Option<f64>,

    /// With --from-linuxcnc: workspace height range ZMIN,ZMAX of the platform origin, mm.
    #[arg(long, value_name = "ZMIN,ZMAX", value_parser = parse_pair, requires = "workspace_radius", allow_hyphen_values = true)]
    z_range: Option<[f64; 2]>,

    /// With --from-linuxcnc: largest tilt of the platform, degrees.
    #[arg(long, value_name = "DEG", requires = "workspace_radius")]
    tilt_max: Option<f64>,

    /// With --from-linuxcnc: yaw range CMIN,CMAX, degrees.
    #[arg(long, value_name = "CMIN,CMAX", value_parser = parse_pair, requires = "workspace_radius", allow_hyphen_values = true)]
    yaw_range: Option<[f64; 2]>,
}

impl GeometryArgs {
    /// The files this command reads and writes.
    pub fn files(&self) -> super::Files<'_> {
        super::Files {
            inputs: self.from_linuxcnc.iter().map(PathBuf::as_path).collect(),
            outputs: self.out.iter().map(PathBuf::as_path).collect(),
        }
    }
}

pub fn run(geometry: &Geometry, args: &GeometryArgs) -> anyhow::Result<()> {
    let converted;
    let geometry = match &args.from_linuxcnc {
        Some(ini) => {
            let hexapod = LinuxCncHexapod::read(ini)?;
            converted = hexapod.to_geometry(&conversion_options(args))?;
            &converted
        }
        None => geometry,
    };
    let text = format!(
        "# hexacomp geometry; fingerprint {}\n{}",
        geometry.fingerprint(),
        geometry.to_toml_string()
    );
    match &args.out {
        Some(path) => super::write_bytes(path, text.as_bytes())?,
        None => print!("{text}"),
    }
    Ok(())
}

fn conversion_options(args: &GeometryArgs) -> ConversionOptions {
    ConversionOptions {
        leg_range: args.leg_range,
        workspace: args.workspace_radius.map(|radius| Workspace {
            radius,
            z_range: args.z_range.expect("clap requires --z-range"),
            tilt_max: args.tilt_max.expect("clap requires --tilt-max"),
            yaw_range: args.yaw_range.expect("clap requires --yaw-range"),
        }),
    }
}

/// Parses `A,B` into two numbers.
fn parse_pair(text: &str) -> Result<[f64; 2], String> {
    let numbers: Vec<f64> = text
        .split(',')
        .map(|word| {
            word.trim()
                .parse::<f64>()
                .map_err(|e| format!("`{word}`: {e}"))
        })
        .collect::<Result<_, _>>()?;
    numbers
        .try_into()
        .map_err(|_| format!("`{text}`: two numbers separated by a comma"))
}
