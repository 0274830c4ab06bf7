//! `hexacomp-service`: the compensation daemon for one hexapod.

use std::process::ExitCode;

use clap::Parser;
use hexacomp_service::cli::{Args, init_logging, run};

fn main() -> ExitCode {
    init_logging();
    match run(Args::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
