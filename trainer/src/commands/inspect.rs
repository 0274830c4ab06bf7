//! `hexacomp-trainer inspect`: prints what a model file holds.

use std::path::PathBuf;
use std::time::{Duration, UNIX_EPOCH};

use anyhow::Context;
use hexacomp_core::Geometry;
use hexacomp_core::error::Error;
use hexacomp_core::model::{Model, Networks};

/// Print a model file or a registration file.
///
/// Print a model file: architecture, hidden nodes, input, the geometry it is bound to, training
/// joint ranges, correction bounds and provenance; or a registration file (`register`): the
/// instrument's pose, every fiducial's residual, the inputs and the time. Refuses truncated,
/// corrupted or foreign files with the reason.
#[derive(Debug, clap::Args)]
pub struct InspectArgs {
    /// The model file (`.hxm`) or registration file (`.toml`).
    #[arg(value_name = "FILE")]
    model: PathBuf,
}

impl InspectArgs {
    /// The files this command reads and writes.
    pub fn files(&self) -> super::Files<'_> {
        super::Files {
            inputs: vec![&self.model],
            outputs: vec![],
        }
    }
}

/// True for a registration file: named `.toml`, or starting with a registration's first line.
fn is_registration(path: &std::path::Path, bytes: &[u8]) -> bool {
    path.extension().is_some_and(|e| e == "toml")
        || bytes.starts_with(hexacomp_formats::REGISTRATION_FIRST_LINE.as_bytes())
}

pub fn run(geometry: &Geometry, args: &InspectArgs) -> anyhow::Result<()> {
    let bytes =
        std::fs::read(&args.model).with_context(|| format!("reading {}", args.model.display()))?;
    if is_registration(&args.model, &bytes) {
        let registration = hexacomp_formats::read_registration(&args.model)?;
        println!(
            "registration file {} (format version {})",
            args.model.display(),
            registration.format
        );
        super::register::print_registration(&registration);
        return Ok(());
    }
    let model = Model::from_bytes(&bytes).map_err(|problem| Error::ModelFile {
        path: args.model.display().to_string(),
        problem,
    })?;
    let p = &model.provenance;
    let created =
        humantime::format_rfc3339_seconds(UNIX_EPOCH + Duration::from_secs(p.created_unix_s));
    let architecture = match &model.networks {
        Networks::Coupled(_) => "coupled (one network, six outputs)".to_string(),
        Networks::Decoupled(_) => "decoupled (six single-output networks)".to_string(),
        Networks::Physical(physical) => format!(
            "physical model (the identified geometry, lead-screw curves of {} coefficients per \
             leg, compliance under the weight)",
            physical.machine().pitch.basis()
        ),
    };
    let bound = if model.geometry == geometry.fingerprint() {
        format!("matches geometry {}", geometry.name)
    } else {
        format!(
            "does NOT match geometry {} ({})",
            geometry.name,
            geometry.fingerprint()
        )
    };
    println!(
        "model file     {} ({} bytes, format version {}, checksum ok)",
        args.model.display(),
        bytes.len(),
        model.format_version()
    );
    println!("architecture   {architecture}");
    if model.is_physical() {
        println!("geometry       {} ({bound})", model.geometry);
        println!("created        {created}");
        println!("identified on  {} configurations", p.configurations);
        if p.validation_rmse_mm.is_finite() {
            println!(
                "accuracy       {:.4} mm cross-validated (Eq. 21, against the measurements)",
                p.validation_rmse_mm
            );
        } else {
            println!("accuracy       not cross-validated (too few configurations)");
        }
    } else {
        println!("hidden nodes   {:?}", model.hidden_nodes());
        println!("network input  {} legs", model.input.name());
        println!("geometry       {} ({bound})", model.geometry);
        println!("created        {created}");
        println!(
            "trained on     {} configurations ({} in the final fit, {} held out to choose the \
             size)",
            p.configurations, p.training_samples, p.validation_samples
        );
        println!("validation     RMSE {:.4} mm", p.validation_rmse_mm);
    }
    println!("source         {}", p.source);
    match &model.uncertainty {
        Some(u) => println!(
            "uncertainty    1-σ position {:.4} mm RMS over the measured configurations \
             ({:.3e} mm² + {:.3e} mm² per unit of leverage)",
            (u.constant_variance_mm2 + u.leverage_variance_mm2).sqrt(),
            u.constant_variance_mm2,
            u.leverage_variance_mm2
        ),
        None => println!("uncertainty    none (points are answered without one)"),
    }
    println!("leg   trained range (mm)         correction bounds (mm)");
    for leg in 0..6 {
        let [lo, hi] = model.training_range[leg];
        let [clo, chi] = model.correction_bounds[leg];
        println!(
            "{:>3}   {lo:>9.3} – {hi:>9.3}       {clo:>8.4} – {chi:>8.4}",
            leg + 1
        );
    }
    Ok(())
}
