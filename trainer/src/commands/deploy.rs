//! `hexacomp-trainer deploy`: hands a model to a running service (hot swap).

use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context;
use hexacomp_client::{Client, ClientOptions, DEFAULT_INSTANCE, DeployOutcome};

/// Hand a model file to the running hexacomp-service of an instance.
///
/// The service validates it off its serving thread (format, checksum, geometry fingerprint,
/// finite weights, corrections within bounds over the training range), persists it and switches
/// to it between two requests; a refused model leaves the old one serving. Prints "accepted as
/// generation N" or the reason.
#[derive(Debug, clap::Args)]
pub struct DeployArgs {
    /// The model file.
    #[arg(long, value_name = "FILE")]
    model: PathBuf,
    /// Instance name of the service.
    #[arg(long, default_value = DEFAULT_INSTANCE)]
    instance: String,
}

impl DeployArgs {
    /// The files this command reads and writes.
    pub fn files(&self) -> super::Files<'_> {
        super::Files {
            inputs: vec![&self.model],
            outputs: vec![],
        }
    }
}

pub fn run(args: &DeployArgs) -> anyhow::Result<()> {
    let bytes =
        std::fs::read(&args.model).with_context(|| format!("reading {}", args.model.display()))?;
    // The deploy itself waits at least a minute (`MIN_DEPLOY_DEADLINE`) for validation.
    let mut client = Client::connect(
        &args.instance,
        &ClientOptions {
            timeout: Duration::from_millis(500),
        },
    )?;
    match client.deploy(&bytes)? {
        DeployOutcome::Accepted {
            generation,
            warning,
        } => {
            println!("accepted as generation {generation}");
            if !warning.is_empty() {
                eprintln!("warning: {warning}");
            }
            Ok(())
        }
        DeployOutcome::Refused { reason, generation } => {
            anyhow::bail!("refused: {reason} (generation {generation} keeps serving)")
        }
    }
}
