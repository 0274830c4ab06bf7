//! `hexacomp-trainer calibrate`: the whole pipeline in one command.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use hexacomp_calibration::identify::{IdentifyOptions, identify};
use hexacomp_calibration::physical_candidate::{
    NetworksUncertainty, PhysicalCandidate, physical_candidate,
};
use hexacomp_calibration::pipeline::{Pipeline, Solved};
use hexacomp_calibration::pitch_resolution::{
    ResolutionChoice, ResolutionScore, chosen_resolution, identifications,
};
use hexacomp_calibration::plan::PlanOptions;
use hexacomp_calibration::residual_noise::ShapeSplit;
use hexacomp_calibration::train::{
    Architecture, CROSS_VALIDATION_FOLDS, TrainOptions, can_cross_validate, commanded_legs,
    cross_validated_rmse,
};
use hexacomp_calibration::uncertainty::{Coverage, Repeatability};
use hexacomp_core::compensator::compensate_pose;
use hexacomp_core::model::Model;
use hexacomp_core::records::MeasuredConfiguration;
use hexacomp_core::sampling::{SamplerOptions, WorkspaceSampler};
use hexacomp_core::stats::PoseErrorStats;
use hexacomp_core::{Geometry, inverse_kinematics};
use hexacomp_formats::{
    Records, read_measurements, read_registration, write_measurements, write_poses,
};
use hexacomp_lab::evaluate::{drive, uncertainty_coverage};
use hexacomp_virtual::{DEFAULT_MACHINE_SEED, ErrorModel, ErrorVariant, VirtualPlatform};

use super::solve::{MeasuredScreeningArgs, solve_screened, write_outcomes};
use super::train::{
    InputArg, arch_name, print_selection, train_with_progress, work_bar, write_selection_plot,
};
use hexacomp_formats::write_file;

use super::measurements_input::MeasurementsInput;
use super::{ResultsFolder, write_bytes};
use hexacomp_report::table::Table;

/// Calibrate in one command: measure, solve, identify (or train), evaluate, write the models.
///
/// Plan → measure (the virtual platform, or --measurements from a real
/// device) → solve the robust joint corrections → identify the physical model (geometry, a
/// lead-screw curve per leg, compliance under the weight), and with --arch train the paper's
/// coupled or decoupled networks with hidden-node selection → evaluate → write the models.
///
/// Writes into --out-dir: poses.csv, measurements.csv, corrections.csv, model-physical.hxm
/// (with --arch also model-coupled.hxm, model-decoupled.hxm and their selection curves, SVG),
/// and model.hxm, the one of them that predicts best the configurations it was not fitted on
/// (5-fold cross-validation on the same folds). On the virtual platform the models are also
/// checked on fresh poses against the uncompensated machine, the model-based baseline and the
/// floor (the machine's exact legs, driven with its repeatability). Ends with a summary and the
/// time each stage took.
#[derive(Debug, clap::Args)]
pub struct CalibrateArgs {
    /// Measurements CSV from a real device; without it the virtual platform is measured.
    #[arg(long, value_name = "FILE")]
    measurements: Option<PathBuf>,
    /// Configurations to plan and measure on the virtual platform.
    #[arg(long, default_value_t = 150, conflicts_with = "measurements")]
    count: usize,
    /// Seed of the plan, the noise and the training.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Seed that draws the virtual machine.
    #[arg(help_heading = "Virtual machine", long, default_value_t = DEFAULT_MACHINE_SEED, conflicts_with = "measurements")]
    machine_seed: u64,
    /// Error variant of the virtual machine.
    #[arg(help_heading = "Virtual machine", long, default_value_t = ErrorVariant::Paper, value_parser = super::named::<ErrorVariant>(ErrorVariant::ALL.map(ErrorVariant::name)), conflicts_with = "measurements")]
    error_variant: ErrorVariant,
    /// Fresh poses for the final check on the virtual platform.
    #[arg(
        help_heading = "Virtual machine",
        long,
        default_value_t = 100,
        conflicts_with = "measurements"
    )]
    validation: usize,
    /// The models to fit and compare, comma-separated: the physical model, and the paper's
    /// coupled and decoupled networks (`--arch physical,coupled,decoupled` compares all three;
    /// the networks take some seconds each).
    #[arg(long, value_enum, value_delimiter = ',', default_value = "physical")]
    arch: Vec<Method>,
    /// Network input of the coupled and decoupled networks (see `train --help`).
    #[arg(help_heading = "Advanced", long, value_enum, default_value_t = InputArg::Equivalent)]
    input: InputArg,
    /// The machine's repeatability, mm: σ of one leg's length error at every move.
    ///
    /// σ is one standard deviation. It enters each point's position uncertainty, and
    /// decides how much of the measurements' scatter is the instrument's (the rest the
    /// legs', shared by the targets of a configuration); one that would give the scatter
    /// more than twice the variance it has is refused, and the models are written without
    /// an uncertainty.
    ///
    /// Not ISO 9283's RP, which is a position figure of the mean plus three standard
    /// deviations: a leg's σ is of the order of RP / 3 divided by the leg-to-tool gain of
    /// the pose.
    ///
    /// Default: the virtual machine's (0.004 mm for the built-in variants with noise); with
    /// --measurements 0.004 mm is assumed, which calibrate says: where the residuals' shape
    /// shows the legs moving by more (three targets or more a configuration), that is taken
    /// as the machine's instead, and where the residuals hold less than its share, no more
    /// than all they hold (a repeatability given is refused there; beyond one given, the
    /// excess is what the model's form misses).
    #[arg(long, value_name = "MM", value_parser = repeatability)]
    repeatability_mm: Option<f64>,
    /// Output folder, replaced as a whole when the calibration succeeds (a failed one leaves it
    /// as it was).
    #[arg(long, value_name = "DIR", default_value = "calibration")]
    out_dir: PathBuf,
    #[command(flatten)]
    reading: MeasurementsInput,
    #[command(flatten)]
    screening: MeasuredScreeningArgs,
}

/// A model `calibrate` can fit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum Method {
    /// The physical model: geometry, a lead-screw curve per leg, compliance (the default).
    Physical,
    /// The paper's coupled network (one network, six outputs).
    Coupled,
    /// The paper's decoupled networks (one per leg).
    Decoupled,
}

impl CalibrateArgs {
    /// Whether --arch asks for `method`.
    fn wants(&self, method: Method) -> bool {
        self.arch.contains(&method)
    }

    /// The files this command reads and writes.
    pub fn files(&self) -> super::Files<'_> {
        super::Files {
            inputs: self
                .measurements
                .iter()
                .map(PathBuf::as_path)
                .chain(self.reading.registration_path())
                .collect(),
            outputs: vec![],
        }
    }
}

/// Parses a repeatability: a finite number of millimetres, not negative.
fn repeatability(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(mm) if mm.is_finite() && mm >= 0.0 => Ok(mm),
        _ => Err(format!(
            "{text:?} is not a repeatability in mm (a number, 0 or more)"
        )),
    }
}

/// How long each stage took, seconds, in the order they ran.
#[derive(Default)]
struct Stages(Vec<(&'static str, f64)>);

impl Stages {
    /// Records that the stage `name` begun at `start` has ended.
    fn record(&mut self, name: &'static str, start: Instant) {
        self.0.push((name, start.elapsed().as_secs_f64()));
    }

    /// Prints the time in all since `total` and each stage's, seconds.
    fn print(&self, total: Instant) {
        let breakdown: Vec<String> = self
            .0
            .iter()
            .map(|(n, s)| format!("{n} {s:.2} s"))
            .collect();
        println!(
            "time: {:.2} s in all ({})",
            total.elapsed().as_secs_f64(),
            breakdown.join(", ")
        );
    }
}

/// Every file `calibrate` writes into its folder.
const CALIBRATION_FILES: [&str; 10] = [
    "poses.csv",
    "measurements.csv",
    "registration.toml",
    "corrections.csv",
    "model-coupled.hxm",
    "model-coupled.selection.svg",
    "model-decoupled.hxm",
    "model-decoupled.selection.svg",
    "model-physical.hxm",
    "model.hxm",
];

pub fn run(geometry: &Geometry, args: &CalibrateArgs) -> anyhow::Result<()> {
    let total = Instant::now();
    let mut stages = Stages::default();
    // Everything is written into a new folder that replaces --out-dir as a unit at the end: a
    // calibration that fails leaves the previous folder whole.
    let folder = ResultsFolder::create(&args.out_dir, "calibrate", &CALIBRATION_FILES)?;
    let dir = folder.path();
    let error_model = ErrorModel::variant(args.error_variant);
    let repeatability = machine_repeatability(args, &error_model);
    let mut platform = VirtualPlatform::new(geometry, &error_model, args.machine_seed, args.seed)?;
    let pipeline = pipeline(args);

    let start = Instant::now();
    let measurements = acquire(args, &pipeline, &mut platform, dir)?;
    stages.record(
        if args.measurements.is_some() {
            "read measurements"
        } else {
            "plan + measure (virtual)"
        },
        start,
    );

    let start = Instant::now();
    let solved = solve_screened(&pipeline, geometry, &measurements)?;
    let kept = solved.kept();
    write_outcomes(&dir.join("corrections.csv"), &kept)?;
    stages.record("solve corrections", start);

    let physical_possible = cross_validated(&solved);
    let networks = networks_to_train(args, physical_possible);
    let mut candidates = train_networks(
        geometry,
        &pipeline,
        &solved,
        (measurements.len(), &networks),
        dir,
        &mut stages,
    )?;
    let fresh_move = if !args.wants(Method::Physical) {
        println!(
            "the networks carry no uncertainty: it is propagated from the physical model's \
             identification (add physical to --arch)"
        );
        None
    } else if physical_possible {
        let start = Instant::now();
        let fresh_move = add_physical(
            geometry,
            &pipeline,
            &solved,
            &measurements,
            repeatability,
            &mut candidates,
        );
        stages.record("physical model", start);
        fresh_move
    } else {
        say_too_few_for_physical(&solved);
        None
    };
    if candidates.is_empty() {
        println!("training the paper's networks instead");
        let both = [Architecture::Coupled, Architecture::Decoupled];
        let source = (measurements.len(), &both[..]);
        candidates = train_networks(geometry, &pipeline, &solved, source, dir, &mut stages)?;
    }
    let best = save_models(&candidates, dir)?;

    let check = if args.measurements.is_none() {
        let start = Instant::now();
        let kept = solved.kept_of(&measurements);
        let table = check_on_fresh_poses(geometry, &platform, &kept, &candidates, args)?;
        stages.record("evaluate on fresh poses", start);
        Some(table)
    } else {
        None
    };
    print_summary(args, measurements.len(), &candidates, check);
    folder.commit()?;
    println!(
        "model.hxm = the {} model (lowest error on configurations it was not fitted on); files \
         in {}",
        best.name,
        args.out_dir.display()
    );
    if let Some(u) = &best.model.uncertainty {
        print_uncertainty(u, repeatability, fresh_move);
    }
    stages.print(total);
    Ok(())
}

/// The machine's repeatability (σ of a leg's length at every move, mm): --repeatability-mm,
/// the virtual machine's, or with --measurements an assumed one (which is said).
fn machine_repeatability(args: &CalibrateArgs, error_model: &ErrorModel) -> Repeatability {
    match (args.repeatability_mm, &args.measurements) {
        (Some(given), _) => Repeatability::Known(given),
        (None, None) => Repeatability::Known(error_model.repeatability_sigma_mm),
        (None, Some(_)) => {
            let assumed = ErrorModel::default().repeatability_sigma_mm;
            println!(
                "uncertainty: the machine's repeatability is taken as {assumed} mm per leg and \
                 move (the virtual platform's), or as what the residuals' shape shows where it \
                 shows more; give --repeatability-mm for this machine's"
            );
            Repeatability::Assumed(assumed)
        }
    }
}

/// The pipeline's settings from the options: the plan, the training and the screening.
fn pipeline(args: &CalibrateArgs) -> Pipeline {
    Pipeline {
        plan: PlanOptions {
            count: args.count,
            seed: args.seed,
            ..Default::default()
        },
        train: TrainOptions {
            input: args.input.into(),
            seed: args.seed,
            ..Default::default()
        },
        checks: args.screening.checks(),
        screening: args.screening.options(),
        ..Default::default()
    }
}

/// The networks to train: those --arch asks for, and both where the physical model is asked
/// for alone but cannot be cross-validated (then there would be no model).
fn networks_to_train(args: &CalibrateArgs, physical_possible: bool) -> Vec<Architecture> {
    let only_physical = !args.wants(Method::Coupled) && !args.wants(Method::Decoupled);
    [
        (Method::Coupled, Architecture::Coupled),
        (Method::Decoupled, Architecture::Decoupled),
    ]
    .into_iter()
    .filter(|(method, _)| args.wants(*method) || (only_physical && !physical_possible))
    .map(|(_, architecture)| architecture)
    .collect()
}

/// Adds the physical model to the `candidates` and gives the networks its uncertainty; a
/// physical model that cannot be identified leaves the choice to the
/// networks, and says why. Returns σ of each leg's length at a fresh move the uncertainty takes
/// (mm), and whether it holds more than the repeatability.
fn add_physical(
    geometry: &Geometry,
    pipeline: &Pipeline,
    solved: &Solved,
    measurements: &[MeasuredConfiguration],
    repeatability: Repeatability,
    candidates: &mut Vec<Candidate>,
) -> Option<(f64, bool)> {
    match physical(geometry, pipeline, solved, measurements, repeatability) {
        Ok((candidate, Ok(uncertainty))) => {
            let source = &uncertainty.source;
            let fresh_move = (
                source.leg_variance_mm2().sqrt(),
                source.beyond_repeatability().at_fresh_moves,
            );
            for network in candidates.iter_mut() {
                match uncertainty.of_networks(network.score_mm) {
                    Ok(u) => network.model.uncertainty = Some(u),
                    Err(e) => {
                        println!("the {} networks carry no uncertainty: {e}", network.name)
                    }
                }
            }
            candidates.push(candidate);
            Some(fresh_move)
        }
        Ok((candidate, Err(e))) => {
            println!("no model carries an uncertainty: {e}");
            candidates.push(candidate);
            None
        }
        Err(e) => {
            println!("physical model left out: {e:#}; without it the models carry no uncertainty");
            None
        }
    }
}

/// Says that the physical model is left out: too few configurations to cross-validate it.
fn say_too_few_for_physical(solved: &Solved) {
    println!(
        "physical model left out: {} configurations are too few to cross-validate it on \
         {CROSS_VALIDATION_FOLDS} folds (two per fold to hold out besides those holding a leg's \
         shortest or longest length, never held out); without another model asked for, the \
         paper's networks are trained instead, compared by their holdout validation RMSE",
        solved.corrections.len()
    );
}

/// Saves every candidate as model-NAME.hxm and the best (lowest score) as model.hxm into
/// `dir`; returns the best.
fn save_models<'a>(candidates: &'a [Candidate], dir: &Path) -> anyhow::Result<&'a Candidate> {
    for candidate in candidates {
        candidate
            .model
            .save(&dir.join(format!("model-{}.hxm", candidate.name)))?;
    }
    let best = candidates
        .iter()
        .min_by(|a, b| a.score_mm.total_cmp(&b.score_mm))
        .expect("a model is fitted: the physical one, or networks where it cannot be");
    best.model.save(&dir.join("model.hxm"))?;
    Ok(best)
}

/// Prints the calibration's summary (a line per candidate) and the check on fresh poses, if
/// made.
fn print_summary(
    args: &CalibrateArgs,
    configurations: usize,
    candidates: &[Candidate],
    check: Option<Table<8>>,
) {
    println!(
        "\nCalibration summary ({configurations} configurations, {})",
        if args.measurements.is_some() {
            "measured"
        } else {
            "virtual platform"
        }
    );
    for candidate in candidates {
        println!("  {:<9} {}", candidate.name, candidate.summary);
    }
    if let Some(table) = check {
        println!(
            "\nOn {} fresh poses of the virtual machine; reached: the machine's true pose; \
             measured: the pose fitted to the instrument's targets (Eq. 4), the paper's \
             protocol, with the instrument's noise:\n{table}",
            args.validation.max(1)
        );
    }
}

/// Prints the best model's 1-σ position uncertainty (mm RMS over the measured configurations)
/// and the legs' repeatability it takes: `fresh_move`, σ of a leg at a fresh move (mm) and
/// whether it holds more than the repeatability, when the physical model gave it.
fn print_uncertainty(
    u: &hexacomp_core::uncertainty::PositionUncertainty,
    repeatability: Repeatability,
    fresh_move: Option<(f64, bool)>,
) {
    let mm = repeatability.sigma_mm();
    let assumed = matches!(repeatability, Repeatability::Assumed(_));
    let legs = match fresh_move {
        Some((fresh_mm, beyond)) => format!(
            "legs moving by {:.1} µm at a fresh move: the repeatability {}{}",
            1e3 * fresh_mm,
            if assumed {
                format!("assumed, {mm} mm,")
            } else {
                format!("of {mm} mm")
            },
            match (beyond, assumed) {
                (true, _) => " and what the residuals show beyond it",
                (false, true) => " no more than all the residuals hold",
                (false, false) => "",
            }
        ),
        None => format!("legs repeating within {mm} mm"),
    };
    println!(
        "its 1-σ position uncertainty: {:.4} mm RMS over the measured configurations, growing \
         outside them ({legs}; `predict` and the service give it per point)",
        (u.constant_variance_mm2 + u.leverage_variance_mm2).sqrt()
    );
}

/// The measurements: read from --measurements (and copied byte for byte into `dir`, as is the
/// --registration they are brought into the base frame with), or the plan
/// measured on the virtual platform (both written to `dir`, and the measurements read back from
/// it, so that what is solved is what the folder holds).
fn acquire(
    args: &CalibrateArgs,
    pipeline: &Pipeline,
    platform: &mut VirtualPlatform,
    dir: &Path,
) -> anyhow::Result<Records<MeasuredConfiguration>> {
    let written = dir.join("measurements.csv");
    if let Some(path) = &args.measurements {
        // The copy is what is solved: a file the instrument is still appending to cannot
        // differ between the two.
        let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
        write_bytes(&written, &bytes)?;
        let geometry = platform.nominal();
        let mut records = match args.reading.read_file(&written, geometry) {
            Ok(records) => records,
            // The same bytes fail the same way when read from the user's file, whose name the
            // message should carry (not the staging folder's).
            Err(e) => return Err(args.reading.read_file(path, geometry).err().unwrap_or(e)),
        };
        records.file = path.display().to_string();
        let registration = match args.reading.registration_path() {
            Some(given) => {
                let bytes =
                    std::fs::read(given).with_context(|| format!("reading {}", given.display()))?;
                write_bytes(&dir.join("registration.toml"), &bytes)?;
                Some(
                    read_registration(&dir.join("registration.toml"))
                        .map_err(|e| read_registration(given).err().unwrap_or(e))?,
                )
            }
            None => None,
        };
        args.reading.apply(registration.as_ref(), &mut records);
        return Ok(records);
    }
    let (poses, measured) = hexacomp_lab::measure_virtual(&pipeline.plan, platform)?;
    write_file(&dir.join("poses.csv"), |w| write_poses(w, &poses))?;
    write_file(&written, |w| write_measurements(w, &measured))?;
    let mut records = read_measurements(&written)?;
    // Messages name the file where it will be, not the folder it is staged in.
    records.file = args.out_dir.join("measurements.csv").display().to_string();
    Ok(records)
}

/// A model `calibrate` may write as model.hxm.
struct Candidate {
    /// Its name in model-NAME.hxm and in the summary.
    name: &'static str,
    /// Its row in the check on fresh poses.
    label: &'static str,
    /// The model.
    model: Model,
    /// Its error on configurations it was not fitted on ([`CROSS_VALIDATION_FOLDS`]-fold cross-validation,
    /// Eq. 21; the holdout validation RMSE when there are too few to cross-validate), mm: what
    /// the candidates are compared by.
    score_mm: f64,
    /// What the summary says of it.
    summary: String,
}

/// Whether the candidates are compared by cross-validation: with two configurations per fold
/// or more to hold out besides the legs' extremes (otherwise the networks by their holdout,
/// without the physical model).
fn cross_validated(solved: &Solved) -> bool {
    can_cross_validate(&commanded_legs(&solved.corrections), CROSS_VALIDATION_FOLDS)
}

/// The model's source line in its file.
fn source(configurations: usize) -> String {
    format!(
        "hexacomp-trainer {} calibrate ({configurations} configurations)",
        env!("CARGO_PKG_VERSION"),
    )
}

/// Trains the networks of `architectures` on the solved corrections of `configurations`,
/// writing each model's selection curve into `dir`.
fn train_networks(
    geometry: &Geometry,
    pipeline: &Pipeline,
    solved: &Solved,
    (configurations, architectures): (usize, &[Architecture]),
    dir: &Path,
    stages: &mut Stages,
) -> anyhow::Result<Vec<Candidate>> {
    let mut candidates = Vec::new();
    for &architecture in architectures {
        let start = Instant::now();
        let t = train_with_progress(
            &solved.corrections,
            architecture,
            geometry,
            pipeline,
            source(configurations),
        )?;
        let name = arch_name(architecture);
        write_selection_plot(
            &t,
            architecture,
            &dir.join(format!("model-{name}.selection.svg")),
        )?;
        print_selection(&t, architecture);
        stages.record(
            if architecture == Architecture::Coupled {
                "train coupled"
            } else {
                "train decoupled"
            },
            start,
        );
        let (score_mm, scored) = if cross_validated(solved) {
            let score_mm = cross_validated_rmse(
                &solved.corrections,
                architecture,
                &t.model.hidden_nodes(),
                &pipeline.train,
                CROSS_VALIDATION_FOLDS,
            )
            .with_context(|| format!("cross-validating the {name} networks"))?;
            (score_mm, format!(", cross-validated {score_mm:.4} mm"))
        } else {
            (t.validation_rmse_mm, String::new())
        };
        candidates.push(Candidate {
            name,
            label: if architecture == Architecture::Coupled {
                "robust coupled"
            } else {
                "robust decoupled"
            },
            summary: format!(
                "hidden nodes {:?}, holdout validation RMSE {:.4} mm{scored}, trained in {:.2} s; \
                 {}",
                t.model.hidden_nodes(),
                t.validation_rmse_mm,
                t.seconds,
                t.stops
            ),
            score_mm,
            model: t.model,
        });
    }
    Ok(candidates)
}

/// Identifies the physical model on the kept configurations, cross-validates it on the folds
/// the networks are, and gives it its uncertainty (for model-physical.hxm).
fn physical(
    geometry: &Geometry,
    pipeline: &Pipeline,
    solved: &Solved,
    measurements: &[MeasuredConfiguration],
    repeatability: Repeatability,
) -> anyhow::Result<(Candidate, hexacomp_calibration::Result<NetworksUncertainty>)> {
    let kept = solved.kept_of(measurements);
    let choosing = Instant::now();
    let resolution = choose_resolution(geometry, pipeline, solved, &kept)?;
    let choosing = choosing.elapsed().as_secs_f64();
    let mut candidate = physical_candidate(
        geometry,
        &kept,
        resolution,
        repeatability,
        pipeline.train.seed,
    )?;
    candidate.model.provenance.source = format!(
        "{}: physical model ({} lead-screw coefficients per leg, smoothness {}), \
         cross-validated {:.4} mm",
        source(measurements.len()),
        candidate.resolution.options.pitch_basis,
        candidate.resolution.options.smoothness,
        candidate.cross_validated_rmse_mm
    );
    print_resolution(&candidate);
    if let Ok(uncertainty) = &candidate.networks_uncertainty
        && let Some(split) = uncertainty.source.shape_split()
    {
        print_residual_split(uncertainty, split, repeatability);
    }
    println!(
        "physical model: {:.4} mm cross-validated (each configuration predicted by the model \
         identified without its fold); the model file holds the model itself",
        candidate.cross_validated_rmse_mm,
    );
    let candidate_of_physical = Candidate {
        name: "physical",
        label: "physical model",
        summary: format!(
            "cross-validated {:.4} mm; identified and cross-validated in {:.2} s",
            candidate.cross_validated_rmse_mm,
            choosing + candidate.seconds,
        ),
        score_mm: candidate.cross_validated_rmse_mm,
        model: candidate.model,
    };
    Ok((candidate_of_physical, candidate.networks_uncertainty))
}

/// Chooses the physical model's lead-screw resolution and smoothness prior on the kept
/// configurations `kept` by cross-validation (each identified without each fold), with a
/// progress bar.
fn choose_resolution(
    geometry: &Geometry,
    pipeline: &Pipeline,
    solved: &Solved,
    kept: &[MeasuredConfiguration],
) -> hexacomp_calibration::Result<ResolutionChoice> {
    let bar = work_bar(
        identifications(CROSS_VALIDATION_FOLDS),
        "choosing the physical model's lead-screw resolution (each without each fold)".into(),
    );
    let resolution = chosen_resolution(
        geometry,
        kept,
        &solved.corrections,
        pipeline.train.seed,
        CROSS_VALIDATION_FOLDS,
        &|n| bar.inc(n),
    );
    bar.finish_and_clear();
    resolution
}

/// A resolution's score as `calibrate` prints it: its label (the coefficients per leg, or the
/// prior's weight), its cross-validated error ± standard error, mm.
fn score_text(label: impl std::fmt::Display, score: &ResolutionScore) -> String {
    format!(
        "{label}: {:.4} ± {:.4} mm",
        score.cross_validated_rmse_mm, score.standard_error_mm
    )
}

/// Prints the physical model's resolution chosen (coefficients per leg and smoothness prior),
/// every one tried with its cross-validated error, those left out, and what its uncertainty
/// holds of the choice.
fn print_resolution(candidate: &PhysicalCandidate) {
    let resolution = &candidate.resolution;
    let tried: Vec<String> = resolution
        .scores
        .iter()
        .map(|s| score_text(s.pitch_basis, s))
        .collect();
    println!(
        "physical model: lead-screw curves of {} B-spline coefficients per leg, the fewest \
         cross-validated within one standard error of the best ({})",
        resolution.options.pitch_basis,
        tried.join(", ")
    );
    for (basis, why) in &resolution.failed {
        println!("physical model: {basis} lead-screw coefficients per leg left out: {why}");
    }
    let smoothed: Vec<String> = std::iter::once(resolution.chosen_without_prior())
        .chain(&resolution.smoothed)
        .map(|s| score_text(s.smoothness, s))
        .collect();
    println!(
        "physical model: the curves' smoothness prior of weight {}, the lowest cross-validated \
         at {} coefficients ({})",
        resolution.options.smoothness,
        resolution.options.pitch_basis,
        smoothed.join(", ")
    );
    for (weight, why) in &resolution.smoothing_failed {
        println!("physical model: the smoothness prior of weight {weight} left out: {why}");
    }
    let alternatives = resolution.indistinguishable();
    if !alternatives.is_empty() && candidate.networks_uncertainty.is_ok() {
        println!(
            "physical model: its uncertainty holds the spread to the models of {alternatives:?} \
             coefficients per leg, which the cross-validation could not tell from it"
        );
    }
    if candidate
        .networks_uncertainty
        .as_ref()
        .is_ok_and(|u| u.source.holds_prior_bias())
    {
        println!(
            "physical model: its uncertainty holds the smoothness prior's bias, its miss to the \
             same resolution identified without the prior beyond the two fits' noise"
        );
    }
}

/// Prints how the physical model's residuals split between the instrument's noise and the
/// platform's moves (µm, µm²), and the σ per leg at a fresh move every point's uncertainty
/// takes, with why.
fn print_residual_split(
    uncertainty: &NetworksUncertainty,
    split: ShapeSplit,
    repeatability: Repeatability,
) {
    // A variance the split finds negative is printed as it is, not as its root.
    let deviation = |variance: f64| {
        if variance >= 0.0 {
            format!("{:.1} µm", 1e3 * variance.sqrt())
        } else {
            "nothing".to_string()
        }
    };
    let legs = uncertainty.source.leg_variance_mm2();
    println!(
        "physical model: its residuals hold {} per coordinate of the instrument's noise (a \
         variance of {:.1} µm²), and move the platform by {} per leg and configuration (a \
         variance of {:.1} ± {:.1} µm²); every point's uncertainty takes {:.1} µm per leg at \
         a fresh move ({})",
        deviation(split.instrument_variance_mm2),
        1e6 * split.instrument_variance_mm2,
        deviation(split.platform_variance_mm2),
        1e6 * split.platform_variance_mm2,
        1e6 * split.platform_error_mm2,
        1e3 * legs.sqrt(),
        fresh_move_source(uncertainty, repeatability),
    );
}

/// What the σ per leg at a fresh move stands for: the repeatability, and what the model's form
/// misses beyond it.
fn fresh_move_source(uncertainty: &NetworksUncertainty, repeatability: Repeatability) -> String {
    let repeatability_mm = repeatability.sigma_mm();
    let beyond = uncertainty.source.beyond_repeatability();
    let why = match (beyond.at_fresh_moves, repeatability) {
        (false, Repeatability::Known(_)) => {
            format!("the repeatability of {repeatability_mm} mm")
        }
        (false, Repeatability::Assumed(_)) => format!(
            "the repeatability assumed, {repeatability_mm} mm, no more than all the residuals \
             hold"
        ),
        (true, Repeatability::Known(_)) => format!(
            "the repeatability of {repeatability_mm} mm and what the model's form misses beyond \
             it, over the resolutions kept"
        ),
        (true, Repeatability::Assumed(_)) => format!(
            "more than the repeatability assumed, {repeatability_mm} mm: the machine's own \
             repeatability or what the model's form misses, over the resolutions kept"
        ),
    };
    if beyond.moving_parameters {
        format!("{why}; the model's excess moves its identified parameters too")
    } else {
        why
    }
}

/// On fresh poses of the virtual machine: the pose errors uncompensated, with the identified
/// geometry (the model-based baseline), with each candidate model and at the floor (the legs
/// that put the noiseless machine exactly on the pose); reached (the machine's true
/// pose) and measured (the pose fitted to the instrument's noisy targets, Eq. 4: the paper's
/// protocol).
fn check_on_fresh_poses(
    geometry: &Geometry,
    platform: &VirtualPlatform,
    measurements: &[MeasuredConfiguration],
    candidates: &[Candidate],
    args: &CalibrateArgs,
) -> anyhow::Result<Table<8>> {
    let poses = WorkspaceSampler::new(
        geometry,
        args.seed.wrapping_add(1000),
        SamplerOptions::default(),
    )?
    .samples(args.validation.max(1))?;
    let identified = identify(geometry, measurements, &IdentifyOptions::default())?.geometry;
    // The instrument draws its noise apart from the machine's moves; every method meets the same
    // machine and instrument states.
    let instrument = platform.reseeded(args.seed.wrapping_add(1));
    let errors = |command: &dyn Fn(&hexacomp_core::Pose) -> [f64; 6]| {
        drive(
            &mut platform.clone(),
            &mut instrument.clone(),
            &poses,
            command,
        )
    };
    let stats = |command: &dyn Fn(&hexacomp_core::Pose) -> [f64; 6]| {
        errors(command).map(|e| {
            (
                PoseErrorStats::of(&e.reached),
                PoseErrorStats::of(&e.measured),
                None,
            )
        })
    };
    let mut rows = vec![
        (
            "uncompensated".to_string(),
            stats(&|p| inverse_kinematics(geometry, p).lengths)?,
        ),
        (
            "model-based (identified geometry)".to_string(),
            stats(&|p| inverse_kinematics(&identified, p).lengths)?,
        ),
    ];
    for candidate in candidates {
        let model = &candidate.model;
        let e = errors(&|p| compensate_pose(geometry, Some(model), p).legs)?;
        let uncertainty = model
            .uncertainty
            .is_some()
            .then(|| uncertainty_coverage(geometry, model, &poses, &e.reached));
        rows.push((
            candidate.label.to_string(),
            (
                PoseErrorStats::of(&e.reached),
                PoseErrorStats::of(&e.measured),
                uncertainty,
            ),
        ));
    }
    let truth = platform.machine();
    rows.push((
        "floor (exact legs, with the machine's repeatability)".to_string(),
        stats(&|p| truth.exact_command(p))?,
    ));
    Ok(fresh_pose_table(rows))
}

/// One method's errors on the fresh poses: reached, measured, and how its uncertainty covers
/// the errors reached (for a model that states one).
type FreshPoseErrors = (PoseErrorStats, PoseErrorStats, Option<Coverage>);

/// The table of the check on fresh poses: a row per method (mm, degrees).
fn fresh_pose_table(rows: Vec<(String, FreshPoseErrors)>) -> Table<8> {
    let mut table = Table::new([
        "method",
        "reached mean ‖δ_A‖ (mm)",
        "reached max ‖δ_A‖ (mm)",
        "reached mean ‖ε‖ (deg)",
        "measured mean ‖δ_A‖ (mm)",
        "measured mean ‖ε‖ (deg)",
        "mean σ (mm)",
        "reached within 2σ",
    ]);
    for (name, (reached, measured, uncertainty)) in rows {
        table.row([
            name,
            format!("{:.4}", reached.position_mm.mean),
            format!("{:.4}", reached.position_mm.max),
            format!("{:.4}", reached.orientation_deg.mean),
            format!("{:.4}", measured.position_mm.mean),
            format!("{:.4}", measured.orientation_deg.mean),
            uncertainty.map_or("—".into(), |u| format!("{:.4}", u.mean_sigma_mm)),
            uncertainty.map_or("—".into(), |u| {
                format!("{:.1} %", 100.0 * u.within_two_sigma)
            }),
        ]);
    }
    table
}
