//! `hexacomp-service`: the compensation daemon. This first version checks its configuration
//! (geometry, instance name) and reports what it would serve; the iceoryx2 serving path arrives
//! with the service issue.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use hexacomp_client::{DEFAULT_INSTANCE, Endpoint, service_name};
use hexacomp_core::Geometry;

/// Serve joint compensation for one hexapod over iceoryx2 (not yet: this build only validates
/// its configuration and exits with status 2).
#[derive(Debug, Parser)]
#[command(name = "hexacomp-service", version)]
struct Args {
    /// Instance name: one service per machine tool.
    #[arg(long, default_value = DEFAULT_INSTANCE)]
    instance: String,
    /// Geometry TOML (DESIGN.md layout). Default: the built-in `prototype`.
    #[arg(long, value_name = "FILE")]
    geometry: Option<PathBuf>,
}

fn main() -> ExitCode {
    let args = Args::parse();
    let checked = (|| -> anyhow::Result<(Geometry, String)> {
        let geometry = match &args.geometry {
            Some(path) => Geometry::load(path)?,
            None => Geometry::prototype(),
        };
        Ok((
            geometry,
            service_name(&args.instance, Endpoint::Compensate)?,
        ))
    })();
    match checked {
        Ok((geometry, name)) => {
            eprintln!(
                "configuration valid: geometry {} (fingerprint {}), service {name}; \
                 serving is not implemented in this build",
                geometry.name,
                geometry.fingerprint()
            );
            ExitCode::from(2)
        }
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
