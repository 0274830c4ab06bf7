//! Calibrating the virtual platform for the benchmarks that need a model: the trainer's pipeline
//! (plan, simulated measurement, robust joint corrections, decoupled networks with hidden-node
//! selection) on its defaults.

use anyhow::Context;
use hexacomp_core::Geometry;
use hexacomp_core::model::Model;
use hexacomp_trainer::pipeline::Pipeline;
use hexacomp_trainer::plan::PlanOptions;
use hexacomp_trainer::train::{Architecture, TrainOptions, training_work};
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
        &ErrorModel::variant(ErrorVariant::Paper),
        machine_seed,
        seed,
    )?)
}

/// What a calibration produced.
#[derive(Debug)]
pub struct Calibration {
    /// The decoupled model.
    pub model: Model,
    /// Configurations measured.
    pub configurations: usize,
    /// Holdout validation RMSE of the corrections, mm.
    pub validation_rmse_mm: f64,
    /// Seconds the whole calibration took.
    pub seconds: f64,
}

/// Calibrates `platform` on `configurations` planned poses and trains the decoupled model, with
/// a progress bar on standard error.
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
        train: TrainOptions {
            seed,
            ..Default::default()
        },
        ..Default::default()
    };
    let (_, measurements) = pipeline.measure_virtual(platform)?;
    let solved = pipeline
        .solve(&geometry, &measurements)
        .context("solving the virtual platform's corrections")?;
    let bar = ProgressBar::new(training_work(
        solved.corrections.len(),
        Architecture::Decoupled,
        &pipeline.train,
    ));
    bar.set_style(
        ProgressStyle::with_template(
            "training decoupled networks [{bar:30}] {percent}% ({elapsed}, about {eta} left)",
        )
        .expect("valid template")
        .progress_chars("=> "),
    );
    let mut trained = pipeline
        .train(
            &geometry,
            &solved.corrections,
            Architecture::Decoupled,
            &|n| bar.inc(n),
        )
        .context("training the virtual platform's model")?;
    bar.finish_and_clear();
    trained.model.provenance.source = format!(
        "hexacomp-bench {} virtual calibration ({configurations} configurations)",
        env!("CARGO_PKG_VERSION")
    );
    Ok(Calibration {
        model: trained.model,
        configurations,
        validation_rmse_mm: trained.validation_rmse_mm,
        seconds: start.elapsed().as_secs_f64(),
    })
}
