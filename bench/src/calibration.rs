//! Calibrating the virtual platform for the benchmarks that need a model: the trainer's pipeline
//! on its defaults (plan, simulated measurement, robust joint corrections), then the model
//! `hexacomp-trainer calibrate` writes as model.hxm on the virtual platform at every size
//! measured (docs/accuracy.md): the physical model, with its position uncertainty.

use anyhow::Context;
use hexacomp_calibration::identify::{PHYSICAL, identify};
use hexacomp_calibration::physical_candidate::{ServedModel, with_uncertainty};
use hexacomp_calibration::pipeline::Pipeline;
use hexacomp_calibration::pitch_resolution::{
    ResolutionChoice, chosen_if_cross_validated, identifications,
};
use hexacomp_calibration::plan::PlanOptions;
use hexacomp_calibration::train::CROSS_VALIDATION_FOLDS;
use hexacomp_calibration::uncertainty::Repeatability;
use hexacomp_core::Geometry;
use hexacomp_core::model::Model;
use hexacomp_core::records::{JointCorrection, MeasuredConfiguration};
use hexacomp_virtual::{ErrorModel, ErrorVariant, VirtualPlatform};
use indicatif::{ProgressBar, ProgressStyle};

/// The virtual machine a benchmark drives: drawn from `machine_seed` with the paper's error
/// variant, noise from `seed`.
pub fn virtual_platform(
    geometry: &Geometry,
    machine_seed: u64,
    seed: u64,
) -> anyhow::Result<VirtualPlatform> {
    Ok(VirtualPlatform::new(
        geometry,
        &error_model(),
        machine_seed,
        seed,
    )?)
}

/// The errors of the benchmarks' virtual machine: the paper's variant.
fn error_model() -> ErrorModel {
    ErrorModel::variant(ErrorVariant::Paper)
}

/// What a calibration produced.
#[derive(Debug)]
pub struct Calibration {
    /// The physical model, with its uncertainty.
    pub model: Model,
    /// Configurations measured.
    pub configurations: usize,
    /// Seconds the whole calibration took.
    pub seconds: f64,
}

/// A progress bar on standard error of `total` units, with what it measures and the time left.
fn work_bar(total: u64, what: &str) -> ProgressBar {
    let bar = ProgressBar::new(total);
    bar.set_style(
        ProgressStyle::with_template(&format!(
            "{what} [{{bar:30}}] {{percent}}% ({{elapsed}}, about {{eta}} left)"
        ))
        .expect("valid template")
        .progress_chars("=> "),
    );
    bar
}

/// Calibrates `platform` on `configurations` planned poses and identifies the physical model,
/// with a progress bar on standard error.
pub fn calibrate(
    platform: &mut VirtualPlatform,
    configurations: usize,
    seed: u64,
) -> anyhow::Result<Calibration> {
    let start = std::time::Instant::now();
    let geometry = platform.nominal().clone();
    let pipeline = Pipeline {
        plan: PlanOptions {
            count: configurations,
            seed,
            ..Default::default()
        },
        ..Default::default()
    };
    let (_, measurements) = hexacomp_lab::measure_virtual(&pipeline.plan, platform)?;
    let solved = pipeline
        .solve(&geometry, &measurements)
        .context("solving the virtual platform's corrections")?;
    let kept = solved.kept_of(&measurements);
    let resolution = choose_resolution(&geometry, &kept, &solved.corrections, seed)?;
    for (basis, why) in resolution.iter().flat_map(|r| &r.failed) {
        eprintln!("{basis} lead-screw coefficients per leg left out: {why}");
    }
    let identification = resolution.as_ref().map_or(PHYSICAL, |r| r.options);
    let physical = identify(&geometry, &kept, &identification)
        .context("identifying the virtual platform's physical model")?
        .model;
    let alternative_bases = resolution
        .as_ref()
        .map_or_else(Vec::new, ResolutionChoice::indistinguishable);
    let cross_validated_mm = resolution
        .as_ref()
        .map_or(f64::NAN, |r| r.chosen().cross_validated_rmse_mm);
    let carried: ServedModel = with_uncertainty(
        &geometry,
        (&physical, &identification),
        &alternative_bases,
        (&kept, cross_validated_mm),
        Repeatability::Known(error_model().repeatability_sigma_mm),
        seed,
    )
    .context("the virtual platform's physical model")?;
    if let Err(e) = &carried.uncertainty {
        eprintln!("the model carries no uncertainty: {e}");
    }
    let mut model = carried.model;
    model.provenance.source = format!(
        "hexacomp-bench {} virtual calibration ({configurations} configurations): physical \
         model ({} lead-screw coefficients per leg)",
        env!("CARGO_PKG_VERSION"),
        identification.pitch_basis
    );
    Ok(Calibration {
        model,
        configurations,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// Cross-validates the lead-screw resolutions of the physical model on `kept` (with a progress
/// bar): the one chosen, or `None` where there are too few configurations to choose.
fn choose_resolution(
    geometry: &Geometry,
    kept: &[MeasuredConfiguration],
    corrections: &[JointCorrection],
    seed: u64,
) -> anyhow::Result<Option<ResolutionChoice>> {
    let choosing = work_bar(
        identifications(CROSS_VALIDATION_FOLDS),
        "choosing the physical model's lead-screw resolution",
    );
    let resolution = chosen_if_cross_validated(
        geometry,
        kept,
        corrections,
        seed,
        CROSS_VALIDATION_FOLDS,
        &|n| choosing.inc(n),
    );
    choosing.finish_and_clear();
    resolution.context("choosing the virtual platform's lead-screw resolution")
}
