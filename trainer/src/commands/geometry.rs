//! `hexacomp-trainer geometry`: prints or writes the geometry in use, with its fingerprint.

use std::path::PathBuf;

use anyhow::Context;
use hexacomp_core::Geometry;

/// Print the geometry in use (the built-in `prototype` unless --geometry is given) as TOML.
///
/// Use it to start a geometry file of your own machine from the prototype, or to see the
/// fingerprint that model files are bound to.
#[derive(Debug, clap::Args)]
pub struct GeometryArgs {
    /// Write the TOML to this file instead of standard output.
    #[arg(long, value_name = "FILE")]
    out: Option<PathBuf>,
}

pub fn run(geometry: &Geometry, args: &GeometryArgs) -> anyhow::Result<()> {
    let text = format!(
        "# hexacomp geometry; fingerprint {}\n{}",
        geometry.fingerprint(),
        geometry.to_toml_string()
    );
    match &args.out {
        Some(path) => {
            std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))?
        }
        None => print!("{text}"),
    }
    Ok(())
}
