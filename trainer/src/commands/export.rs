//! `hexacomp-trainer export`: the identified geometry for another tool (LinuxCNC's genhexkins).

use std::path::PathBuf;

use hexacomp_core::Geometry;
use hexacomp_measuring::linuxcnc::{genhexkins_hal, hal_files};

/// Export the geometry in use for LinuxCNC's hexapod kinematics.
///
/// Export the geometry in use (--geometry: the one `identify` wrote) for LinuxCNC's hexapod
/// kinematics, for users who want the geometric part of the calibration in the kinematics itself.
///
/// Writes the `setp genhexkins.base.N.x …` and `genhexkins.platform.N.…` lines of the geometry in
/// the units of the configuration --linuxcnc names, to replace that configuration's own. The leg
/// zero offsets are no genhexkins parameter: the file lists, as comments, the joints' HOME_OFFSET,
/// HOME, MIN_LIMIT and MAX_LIMIT moved by each offset, to set in the ini. A geometry whose joints
/// lie more than 25 mm from the configuration's is refused (another machine's).
#[derive(Debug, clap::Args)]
pub struct ExportArgs {
    /// The LinuxCNC ini file of the hexapod the geometry is for (its units and joint settings).
    #[arg(long, value_name = "INI")]
    linuxcnc: PathBuf,
    /// The HAL file to write.
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
}

impl ExportArgs {
    /// The files this command reads and writes.
    pub fn files(&self) -> super::Files<'_> {
        super::Files {
            inputs: vec![&self.linuxcnc],
            outputs: vec![&self.out],
        }
    }
}

pub fn run(
    geometry: &Geometry,
    source: Option<&std::path::Path>,
    args: &ExportArgs,
) -> anyhow::Result<()> {
    let source = source.map_or_else(
        || format!("the built-in geometry {}", geometry.name),
        |p| p.display().to_string(),
    );
    // The configuration's own HAL files hold more than the geometry: never replaced.
    let hal_files = hal_files(&args.linuxcnc)?;
    let hal_paths: Vec<&std::path::Path> = hal_files.iter().map(PathBuf::as_path).collect();
    hexacomp_formats::refuse_same_file(&args.out, &hal_paths)?;
    let text = genhexkins_hal(&args.linuxcnc, geometry, &source)?;
    super::write_bytes(&args.out, text.as_bytes())?;
    eprintln!(
        "wrote {} (genhexkins geometry for {})",
        args.out.display(),
        args.linuxcnc.display()
    );
    Ok(())
}
