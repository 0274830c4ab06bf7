//! `hexacomp-trainer evaluate`: the paper's comparison on the virtual platform.

use std::path::{Path, PathBuf};

use hexacomp_calibration::identify::PHYSICAL;
use hexacomp_calibration::pitch_resolution::{
    PITCH_RESOLUTIONS, ResolutionScore, SMOOTHNESS_WEIGHTS,
};
use hexacomp_calibration::train::{CROSS_VALIDATION_FOLDS, TrainOptions};
use hexacomp_core::Geometry;
use hexacomp_core::stats::{ErrorStats, PoseErrorStats};
use hexacomp_lab::evaluate::{
    Evaluation, EvaluationOptions, Method, Protocol, SizeResult, evaluate,
};
use hexacomp_report::chart::{Axis, Chart, Series};
use hexacomp_virtual::{DEFAULT_MACHINE_SEED, ErrorModel, ErrorVariant};

use super::ResultsFolder;
use super::train::InputArg;
use hexacomp_report::table::Table;

/// Compare the compensation methods on fresh poses of the virtual platform (the paper's tables
/// and figures).
///
/// Compare the compensation methods on the virtual platform, on fresh validation poses that no
/// training used: uncompensated, the model-based baseline (identified geometry), the physical
/// model (geometry, a lead-screw curve per leg, compliance under the weight) alone, with
/// decoupled networks on the corrections it leaves (the physical model as `calibrate` writes
/// it, model-physical.hxm), the ordinary
/// compensator (coupled network, λ = 0), the robust coupled and decoupled compensators, the
/// decoupled networks trained on the exact corrections (known only in simulation), and the
/// floor: the exact legs of each pose, driven with the machine's repeatability, which no method
/// can beat (docs/accuracy.md).
///
/// Prints the paper's Table 2 (max/mean/std of the position error ‖δ_A‖ in mm and the
/// orientation error ‖ε‖ in degrees) twice: measured as the paper does (the pose fitted to the
/// instrument's noisy target points, Eq. 4; the paper's own figures are comparable with this
/// one) and reached (the virtual machine's true pose). Then Fig. 13's numbers, every method
/// against the floor, Table 1 (hidden nodes, training time, validation RMSE) and the two network
/// inputs compared, and writes Fig. 12 (error reached per validation pose) and Fig. 13 (mean
/// error reached against the number of training configurations, ±1 std) as SVG to --out-dir.
#[derive(Debug, clap::Args)]
pub struct EvaluateArgs {
    /// Training sizes, comma-separated (the paper: 50, 100, 150).
    #[arg(long, value_delimiter = ',', default_value = "50,100,150")]
    sizes: Vec<usize>,
    /// Fresh validation poses.
    #[arg(long, default_value_t = 100)]
    validation: usize,
    /// Seed of the measuring plan and of the machine's noise while it is measured.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Plan without first taking each leg's shortest and longest reach.
    ///
    /// Every configuration by best-candidate sampling, as before, to compare with the
    /// default.
    #[arg(long)]
    no_leg_extremes: bool,
    /// Seed of the validation poses.
    #[arg(long, default_value_t = 1001)]
    validation_seed: u64,
    /// Seed of the instrument's noise at the validation poses (default: --seed + 1).
    #[arg(long)]
    instrument_seed: Option<u64>,
    /// Seed that draws the virtual machine.
    #[arg(long, default_value_t = DEFAULT_MACHINE_SEED)]
    machine_seed: u64,
    /// Error variant of the virtual machine.
    #[arg(long, default_value_t = ErrorVariant::Paper, value_parser = super::named::<ErrorVariant>(ErrorVariant::ALL.map(ErrorVariant::name)))]
    error_variant: ErrorVariant,
    /// Network input of the compensators (the other one is compared at the largest size).
    #[arg(long, value_enum, default_value_t = InputArg::Equivalent)]
    input: InputArg,
    /// Folder for the SVG figures.
    #[arg(long, value_name = "DIR", default_value = "evaluation")]
    out_dir: PathBuf,
}

pub fn run(geometry: &Geometry, args: &EvaluateArgs) -> anyhow::Result<()> {
    anyhow::ensure!(args.validation > 0, "--validation must be at least 1");
    let options = EvaluationOptions {
        training_sizes: args.sizes.clone(),
        validation_count: args.validation,
        plan_seed: args.seed,
        leg_extremes: !args.no_leg_extremes,
        validation_seed: args.validation_seed,
        error_model: ErrorModel::variant(args.error_variant),
        machine_seed: args.machine_seed,
        noise_seed: args.seed,
        instrument_seed: args
            .instrument_seed
            .unwrap_or_else(|| args.seed.wrapping_add(1)),
        train: TrainOptions {
            input: args.input.into(),
            ..Default::default()
        },
    };
    // Made first: a folder that cannot be replaced is refused before the evaluation's minutes.
    let folder = ResultsFolder::create(&args.out_dir, "evaluate", &FIGURES)?;
    let evaluation = evaluate(geometry, &options, &|stage| eprintln!("{stage}…"))?;
    print_evaluation(&evaluation, args.validation);
    write_figures(&evaluation, folder.path())?;
    folder.commit()?;
    eprintln!("figures → {}", args.out_dir.display());
    Ok(())
}

/// The methods compared.
const METHODS: usize = Method::ALL.len();

/// Every file `evaluate` writes into its folder.
const FIGURES: [&str; 4] = [
    "fig12_position.svg",
    "fig12_orientation.svg",
    "fig13_position.svg",
    "fig13_orientation.svg",
];

/// Prints Table 2 (largest size), Fig. 13's numbers, Table 1 and the input comparison.
fn print_evaluation(evaluation: &Evaluation, validation: usize) {
    // The largest size, wherever it is in the list: the input comparison is made there.
    let last = evaluation
        .sizes
        .iter()
        .max_by_key(|s| s.configurations)
        .expect("at least one size");
    print_table_2(last, validation);
    print_fig_13(evaluation);
    print_against_floor(evaluation);
    print_resolutions(evaluation);
    print_smoothness(evaluation);
    print_uncertainty(evaluation);
    print_table_1(evaluation, last);
    print_inputs(evaluation, last);
}

/// Prints Table 2 at `size` (`validation` fresh poses) in both protocols, with the paper's
/// figures between them.
fn print_table_2(size: &SizeResult, validation: usize) {
    println!(
        "Table 2: pose errors at {validation} fresh validation poses, {} training configurations",
        size.configurations
    );
    println!("{}", protocol_heading(Protocol::Measured));
    print!("{}", table_2(size, Protocol::Measured));
    println!(
        "The paper's Table 2, in its protocol on its prototype: mean ‖δ_A‖ 0.642 mm before, \
         0.076 mm coupled, 0.052 mm decoupled; mean ‖ε‖ 0.184°, 0.024°, 0.018°.\n"
    );
    println!("{}", protocol_heading(Protocol::Reached));
    println!("{}", table_2(size, Protocol::Reached));
}

/// Prints Fig. 13's numbers: every method's mean position error reached (mm) and mean
/// orientation error reached (deg) at every training size.
fn print_fig_13(evaluation: &Evaluation) {
    println!(
        "Fig. 13: mean position error (mm) / mean orientation error (deg) against training configurations, reached"
    );
    let mut header = vec!["configurations".to_string()];
    header.extend(Method::ALL.iter().map(|m| m.label().to_string()));
    let refs: Vec<&str> = header.iter().map(String::as_str).collect();
    let mut table = Table::<{ METHODS + 1 }>::new(refs.try_into().expect("a column per method"));
    for size in &evaluation.sizes {
        let mut row = vec![size.configurations.to_string()];
        row.extend(Method::ALL.iter().map(|m| {
            let s = size.stats(*m, Protocol::Reached);
            format!("{:.4} / {:.4}", s.position_mm.mean, s.orientation_deg.mean)
        }));
        table.row(row.try_into().expect("a cell per method"));
    }
    println!("{table}");
}

/// Prints every method's mean and max position error reached as multiples of the floor's, at
/// every training size.
fn print_against_floor(evaluation: &Evaluation) {
    println!(
        "Against the floor: mean / max position error reached, as multiples of the floor's mean \
         / max (the exact legs of each pose, driven with the machine's repeatability)"
    );
    let compared: Vec<Method> = Method::ALL
        .into_iter()
        .filter(|m| *m != Method::Floor)
        .collect();
    let mut header = vec!["configurations".to_string()];
    header.extend(compared.iter().map(|m| m.label().to_string()));
    let refs: Vec<&str> = header.iter().map(String::as_str).collect();
    let mut table = Table::<METHODS>::new(refs.try_into().expect("a column per method"));
    for size in &evaluation.sizes {
        let floor = size.stats(Method::Floor, Protocol::Reached).position_mm;
        let mut row = vec![size.configurations.to_string()];
        row.extend(compared.iter().map(|m| {
            let s = size.stats(*m, Protocol::Reached).position_mm;
            // A machine without noise has no floor to compare with.
            if floor.max > 0.0 {
                format!("{:.2} / {:.2}", s.mean / floor.mean, s.max / floor.max)
            } else {
                "—".to_string()
            }
        }));
        table.row(row.try_into().expect("a cell per method"));
    }
    println!("{table}");
}

/// Prints the physical model's lead-screw resolution chosen at every training size, with each
/// resolution's cross-validated error (mm), and the resolutions left out.
fn print_resolutions(evaluation: &Evaluation) {
    println!(
        "The physical model's lead-screw resolution: B-spline coefficients per leg, the fewest \
         whose {CROSS_VALIDATION_FOLDS}-fold cross-validated error (Eq. 21, mm, ± its standard \
         error) is within one standard error of the best (\"left out\": could not be \
         cross-validated)"
    );
    let mut header = vec!["configurations".to_string(), "chosen".to_string()];
    header.extend(PITCH_RESOLUTIONS.iter().map(|n| format!("{n} (mm)")));
    let refs: Vec<&str> = header.iter().map(String::as_str).collect();
    let mut table = Table::<{ PITCH_RESOLUTIONS.len() + 2 }>::new(
        refs.try_into().expect("a column per resolution"),
    );
    for size in &evaluation.sizes {
        let mut row = vec![size.configurations.to_string()];
        match &size.resolution {
            Some(resolution) => {
                row.push(resolution.options.pitch_basis.to_string());
                row.extend(
                    PITCH_RESOLUTIONS
                        .iter()
                        .map(|&basis| score_cell(resolution.outcome(basis))),
                );
            }
            None => {
                row.push(format!(
                    "{} (too few to cross-validate)",
                    PHYSICAL.pitch_basis
                ));
                row.extend(PITCH_RESOLUTIONS.iter().map(|_| "—".to_string()));
            }
        }
        table.row(row.try_into().expect("a cell per resolution"));
    }
    println!("{table}");
    for size in &evaluation.sizes {
        for (basis, why) in size.resolution.iter().flat_map(|r| &r.failed) {
            println!(
                "{} configurations: {basis} coefficients left out: {why}",
                size.configurations
            );
        }
    }
}

/// Prints the smoothness prior's weight chosen at every training size, with each weight's
/// cross-validated error (mm), and the weights left out.
fn print_smoothness(evaluation: &Evaluation) {
    println!(
        "The lead-screw curves' smoothness prior at the chosen resolution: the weight whose \
         cross-validated error (Eq. 21, mm, ± its standard error, on the same folds) is lowest"
    );
    let weights: Vec<f64> = std::iter::once(0.0).chain(SMOOTHNESS_WEIGHTS).collect();
    let mut header = vec!["configurations".to_string(), "chosen".to_string()];
    header.extend(weights.iter().map(|w| format!("λ = {w} (mm)")));
    let refs: Vec<&str> = header.iter().map(String::as_str).collect();
    let mut table = Table::<{ SMOOTHNESS_WEIGHTS.len() + 3 }>::new(
        refs.try_into().expect("a column per weight"),
    );
    for size in &evaluation.sizes {
        let Some(resolution) = &size.resolution else {
            let mut row = vec![
                size.configurations.to_string(),
                "0 (too few to cross-validate)".to_string(),
            ];
            row.extend(weights.iter().map(|_| "—".to_string()));
            table.row(row.try_into().expect("a cell per weight"));
            continue;
        };
        let mut row = vec![
            size.configurations.to_string(),
            resolution.options.smoothness.to_string(),
        ];
        row.extend(
            weights
                .iter()
                .map(|&weight| score_cell(resolution.smoothing_outcome(weight))),
        );
        table.row(row.try_into().expect("a cell per weight"));
    }
    println!("{table}");
    for size in &evaluation.sizes {
        for (weight, why) in size.resolution.iter().flat_map(|r| &r.smoothing_failed) {
            println!(
                "{} configurations: the smoothness prior of weight {weight} left out: {why}",
                size.configurations
            );
        }
    }
}

/// Prints how well the physical model states their uncertainty at every training
/// size: the share within 2σ, the mean σ (mm) and the floor's mean error (mm).
fn print_uncertainty(evaluation: &Evaluation) {
    println!(
        "Uncertainty of the physical model: the share of validation poses whose \
         position error reached is within 2σ (95.45 % when calibrated), and the mean σ"
    );
    let mut table = Table::new([
        "configurations",
        "within 2σ",
        "mean σ (mm)",
        "floor mean (mm)",
    ]);
    for size in &evaluation.sizes {
        let (within, mean) = size.uncertainty.map_or(("none".into(), "—".into()), |u| {
            (
                format!("{:.1} %", 100.0 * u.within_two_sigma),
                format!("{:.4}", u.mean_sigma_mm),
            )
        });
        table.row([
            size.configurations.to_string(),
            within,
            mean,
            format!(
                "{:.4}",
                size.stats(Method::Floor, Protocol::Reached)
                    .position_mm
                    .mean
            ),
        ]);
    }
    println!("{table}");
}

/// Prints Table 1 (the robust networks at `size`: hidden nodes, training time in s, validation
/// RMSE in mm) and how many training configurations were ill-conditioned.
fn print_table_1(evaluation: &Evaluation, size: &SizeResult) {
    println!(
        "Table 1: robust networks at {} configurations",
        size.configurations
    );
    let mut table = Table::new([
        "architecture",
        "hidden nodes",
        "average hidden nodes",
        "training time (s)",
        "validation RMSE (mm)",
    ]);
    for (name, trained) in [("coupled", &size.coupled), ("decoupled", &size.decoupled)] {
        let nodes = trained.model.hidden_nodes();
        table.row([
            name.into(),
            format!("{nodes:?}"),
            format!(
                "{:.1}",
                nodes.iter().sum::<usize>() as f64 / nodes.len() as f64
            ),
            format!("{:.2}", trained.seconds),
            format!("{:.4}", trained.validation_rmse_mm),
        ]);
    }
    println!("{table}");
    println!(
        "{} of the training configurations had cond(PT) above c = 1e3 (where none does, robust and ordinary corrections coincide)",
        evaluation.above_threshold
    );
}

/// Prints the two network inputs compared (robust decoupled at `size`, errors reached), when
/// they were.
fn print_inputs(evaluation: &Evaluation, size: &SizeResult) {
    if evaluation.inputs.is_empty() {
        return;
    }
    println!(
        "\nNetwork input, robust decoupled at {} configurations, reached:",
        size.configurations
    );
    let mut table = Table::new([
        "input",
        "mean ‖δ_A‖ (mm)",
        "max ‖δ_A‖ (mm)",
        "mean ‖ε‖ (deg)",
    ]);
    for (input, s) in &evaluation.inputs {
        table.row([
            format!("{} legs", input.name()),
            format!("{:.4}", s.position_mm.mean),
            format!("{:.4}", s.position_mm.max),
            format!("{:.4}", s.orientation_deg.mean),
        ]);
    }
    println!("{table}");
}

/// What a protocol's Table 2 shows, as its heading.
fn protocol_heading(protocol: Protocol) -> &'static str {
    match protocol {
        Protocol::Measured => {
            "measured, the paper's protocol (Sec. 4.2): the pose fitted to the instrument's \
             targets (Eq. 4), its noise included"
        }
        Protocol::Reached => {
            "reached: the pose the virtual machine really reached (known only in simulation)"
        }
    }
}

/// The paper's Table 2 of `size` in `protocol`: max, mean and std of the position and
/// orientation errors of every method.
fn table_2(size: &SizeResult, protocol: Protocol) -> Table<{ METHODS + 2 }> {
    let mut header = vec!["pose error", ""];
    header.extend(Method::ALL.iter().map(|m| m.label()));
    let mut table = Table::<{ METHODS + 2 }>::new(header.try_into().expect("a column per method"));
    let stats: Vec<PoseErrorStats> = Method::ALL
        .iter()
        .map(|m| size.stats(*m, protocol))
        .collect();
    for (name, pick) in [
        (
            "‖δ_A‖ (mm)",
            (|s: &PoseErrorStats| s.position_mm) as fn(&PoseErrorStats) -> ErrorStats,
        ),
        ("‖ε‖ (deg)", |s: &PoseErrorStats| s.orientation_deg),
    ] {
        for (label, value) in [
            ("max", (|e: ErrorStats| e.max) as fn(ErrorStats) -> f64),
            ("mean", |e| e.mean),
            ("std", |e| e.std),
        ] {
            let mut row = vec![name.to_string(), label.to_string()];
            row.extend(stats.iter().map(|s| format!("{:.4}", value(pick(s)))));
            table.row(row.try_into().expect("a cell per method"));
        }
    }
    table
}

/// Writes Fig. 12 and Fig. 13 (position and orientation each) as SVG into `dir`.
fn write_figures(evaluation: &Evaluation, dir: &Path) -> anyhow::Result<()> {
    let last = evaluation.sizes.last().expect("at least one size");
    for (file, title, unit, position) in [
        (
            "fig12_position.svg",
            "Position error reached per validation pose",
            "‖δ_A‖ (mm)",
            true,
        ),
        (
            "fig12_orientation.svg",
            "Orientation error reached per validation pose",
            "‖ε‖ (deg)",
            false,
        ),
    ] {
        let chart = Chart {
            title: format!("{title} ({} training configurations)", last.configurations),
            x: Axis::linear("validation pose"),
            y: Axis::linear(unit),
            series: fig_12_series(last, position),
        };
        write(dir, file, &chart)?;
    }
    for (file, title, unit, position) in [
        (
            "fig13_position.svg",
            "Mean position error reached against training configurations",
            "mean ‖δ_A‖ (mm), ±1 std",
            true,
        ),
        (
            "fig13_orientation.svg",
            "Mean orientation error reached against training configurations",
            "mean ‖ε‖ (deg), ±1 std",
            false,
        ),
    ] {
        write(
            dir,
            file,
            &Chart {
                title: title.into(),
                x: Axis::linear("training configurations"),
                y: Axis::linear(unit),
                series: fig_13_series(evaluation, position),
            },
        )?;
    }
    Ok(())
}

/// Fig. 12's lines at `size`: the error reached at each validation pose (position in mm, or
/// orientation in degrees) uncompensated and with the robust compensators.
fn fig_12_series(size: &SizeResult, position: bool) -> Vec<Series> {
    let shown = [
        Method::Uncompensated,
        Method::RobustCoupled,
        Method::RobustDecoupled,
    ];
    size.errors
        .iter()
        .filter(|(m, _)| shown.contains(m))
        .map(|(m, errors)| {
            Series::line(
                m.label(),
                errors
                    .reached
                    .iter()
                    .enumerate()
                    .map(|(i, e)| {
                        (
                            (i + 1) as f64,
                            if position {
                                e.position_mm
                            } else {
                                e.orientation_deg
                            },
                        )
                    })
                    .collect(),
            )
        })
        .collect()
}

/// Fig. 13's lines: every compensated method's mean error reached (position in mm, or
/// orientation in degrees) against the training size, with ±1 std bars.
fn fig_13_series(evaluation: &Evaluation, position: bool) -> Vec<Series> {
    Method::ALL
        .iter()
        .filter(|m| **m != Method::Uncompensated)
        .map(|m| {
            let stats: Vec<ErrorStats> = evaluation
                .sizes
                .iter()
                .map(|s| {
                    let stats = s.stats(*m, Protocol::Reached);
                    if position {
                        stats.position_mm
                    } else {
                        stats.orientation_deg
                    }
                })
                .collect();
            Series {
                label: m.label().into(),
                points: evaluation
                    .sizes
                    .iter()
                    .zip(&stats)
                    .map(|(s, e)| (s.configurations as f64, e.mean))
                    .collect(),
                error_bars: Some(stats.iter().map(|e| e.std).collect()),
                markers_only: false,
            }
        })
        .collect()
}

/// Writes `chart` as SVG into `dir` as `file`.
fn write(dir: &Path, file: &str, chart: &Chart) -> anyhow::Result<()> {
    let path = dir.join(file);
    Ok(super::write_bytes(&path, chart.to_svg()?.as_bytes())?)
}

/// A cross-validated score's cell: its error ± standard error (mm), "left out" where it could
/// not be scored, "—" where it was not tried.
fn score_cell(outcome: Option<Result<&ResolutionScore, &str>>) -> String {
    match outcome {
        Some(Ok(s)) => format!(
            "{:.4} ± {:.4}",
            s.cross_validated_rmse_mm, s.standard_error_mm
        ),
        Some(Err(_)) => "left out".to_string(),
        None => "—".to_string(),
    }
}
