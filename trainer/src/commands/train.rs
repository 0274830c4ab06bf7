//! `hexacomp-trainer train`: fits the joint-correction networks and writes a model file.

use std::path::{Path, PathBuf};

use anyhow::Context;
use hexacomp_calibration::pipeline::Pipeline;
use hexacomp_core::Geometry;
use hexacomp_core::model::NetworkInput;
use hexacomp_core::records::JointCorrection;
use hexacomp_formats::read_corrections;

use super::solve::{ScreeningArgs, screen_corrections_file};
use hexacomp_calibration::train::{Architecture, Selection, TrainOptions, Trained, training_work};
use hexacomp_report::chart::{Axis, Chart, Series};
use indicatif::{ProgressBar, ProgressStyle};

use hexacomp_report::table::Table;

/// Fit the joint-correction function Δq = N(q) with three-layer networks (tanh hidden layer,
/// linear output, inputs normalised by Eq. 13) and write a model file.
///
/// Training: Levenberg–Marquardt on the mean squared error (Eq. 15, Eq. 16, Eq. 17) with an
/// analytic Jacobian, several seeded restarts keeping the best. The hidden-node count is chosen
/// by holdout validation: a third of the configurations is held out, every size of the sweep is
/// fitted on the rest, and the smallest size within 2 % of the best validation RMSE (Eq. 18;
/// Eq. 21 for decoupled) wins. The final networks are then refitted on all configurations at the
/// chosen size (--no-refit keeps the holdout fit). The selection curve (like the paper's
/// Fig. 10/11) is printed and written as SVG beside the model.
#[derive(Debug, clap::Args)]
pub struct TrainArgs {
    /// Corrections CSV (`hexacomp-trainer solve`).
    #[arg(long, value_name = "FILE")]
    corrections: PathBuf,
    /// coupled: one network with six outputs; decoupled: six single-output networks.
    #[arg(long, value_enum, default_value_t = ArchitectureArg::Decoupled)]
    arch: ArchitectureArg,
    /// Network input: the equivalent legs, or the commanded legs (the paper).
    ///
    /// `equivalent` legs q⁽ᴸ⁾ = q⁽⁰⁾ − Δq (N inverts the machine's map, so q + N(q) is
    /// right at the corrected point), or `commanded` legs q⁽⁰⁾ (the paper).
    #[arg(long, value_enum, default_value_t = InputArg::Equivalent)]
    input: InputArg,
    /// Largest hidden-node count of the sweep (it tries 1..=N).
    #[arg(long, default_value_t = 16)]
    hidden_max: usize,
    /// Restarts per fit.
    #[arg(long, default_value_t = TrainOptions::default().restarts)]
    restarts: usize,
    /// Seed of the holdout split and the initial weights.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Keep the networks fitted on the training part instead of refitting on all configurations.
    #[arg(long)]
    no_refit: bool,
    /// Output model file.
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
    #[command(flatten)]
    screening: ScreeningArgs,
}

impl TrainArgs {
    /// The files this command reads and writes.
    pub fn files(&self) -> super::Files<'_> {
        super::Files {
            inputs: vec![&self.corrections],
            outputs: vec![&self.out],
        }
    }
}

/// The architecture on the command line.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum ArchitectureArg {
    /// One network, six outputs.
    Coupled,
    /// Six networks, one output each.
    Decoupled,
}

impl From<ArchitectureArg> for Architecture {
    fn from(a: ArchitectureArg) -> Self {
        match a {
            ArchitectureArg::Coupled => Architecture::Coupled,
            ArchitectureArg::Decoupled => Architecture::Decoupled,
        }
    }
}

/// The network input on the command line.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum InputArg {
    /// Equivalent legs q⁽ᴸ⁾.
    Equivalent,
    /// Commanded legs q⁽⁰⁾.
    Commanded,
}

impl From<InputArg> for NetworkInput {
    fn from(i: InputArg) -> Self {
        match i {
            InputArg::Equivalent => NetworkInput::Equivalent,
            InputArg::Commanded => NetworkInput::Commanded,
        }
    }
}

pub fn run(geometry: &Geometry, args: &TrainArgs) -> anyhow::Result<()> {
    anyhow::ensure!(args.hidden_max >= 1, "--hidden-max must be at least 1");
    let file = read_corrections(&args.corrections)?;
    let screening = screen_corrections_file(&file, &args.screening)?;
    let rows: Vec<JointCorrection> = file
        .iter()
        .enumerate()
        .filter(|(index, _)| screening.kept(*index))
        .map(|(_, row)| row.clone())
        .collect();
    let options = TrainOptions {
        hidden_sizes: (1..=args.hidden_max.min(hexacomp_core::network::MAX_HIDDEN)).collect(),
        restarts: args.restarts,
        refit_on_all: !args.no_refit,
        input: args.input.into(),
        seed: args.seed,
        ..Default::default()
    };
    let source = format!(
        "hexacomp-trainer {} train --corrections {}",
        env!("CARGO_PKG_VERSION"),
        args.corrections.display()
    );
    let pipeline = Pipeline {
        train: options,
        ..Default::default()
    };
    let trained = train_with_progress(&rows, args.arch.into(), geometry, &pipeline, source)?;
    trained.model.save(&args.out)?;
    let plot = args.out.with_extension("selection.svg");
    print_selection(&trained, args.arch.into());
    write_selection_plot(&trained, args.arch.into(), &plot)?;
    eprintln!(
        "trained {} model (hidden nodes {:?}, validation RMSE {:.4} mm) in {:.2} s → {} (selection curve: {})\n{}",
        arch_name(args.arch.into()),
        trained.model.hidden_nodes(),
        trained.validation_rmse_mm,
        trained.seconds,
        args.out.display(),
        plot.display(),
        trained.stops
    );
    Ok(())
}

/// Trains with a progress bar (share of the iteration budget done, time left), recording
/// `source` in the provenance.
pub fn train_with_progress(
    rows: &[JointCorrection],
    architecture: Architecture,
    geometry: &Geometry,
    pipeline: &Pipeline,
    source: String,
) -> anyhow::Result<Trained> {
    // The bar counts the work of Levenberg–Marquardt iterations, so it moves within a fit on
    // large inputs; fits that settle early skip ahead, so the real time left is often shorter.
    let bar = work_bar(
        training_work(rows.len(), architecture, &pipeline.train),
        format!("training {} networks", arch_name(architecture)),
    );
    let mut trained = pipeline
        .train(geometry, rows, architecture, &|n| bar.inc(n))
        .context("training")?;
    bar.finish_and_clear();
    trained.model.provenance.source = source;
    Ok(trained)
}

/// A progress bar over `total` units of training work, with the time left.
pub fn work_bar(total: u64, message: String) -> ProgressBar {
    let bar = ProgressBar::new(total);
    bar.set_style(
        ProgressStyle::with_template(
            "{msg} [{bar:30}] {percent_precise}% ({elapsed}, about {eta} left)",
        )
        .expect("valid template")
        .progress_chars("=> "),
    );
    bar.set_message(message);
    bar
}

pub fn arch_name(architecture: Architecture) -> &'static str {
    match architecture {
        Architecture::Coupled => "coupled",
        Architecture::Decoupled => "decoupled",
    }
}

/// Prints the selection curve: training and validation RMSE per hidden-node count.
pub fn print_selection(trained: &Trained, architecture: Architecture) {
    let sizes: Vec<usize> = trained.selections[0]
        .sweep
        .iter()
        .map(|p| p.hidden)
        .collect();
    match architecture {
        Architecture::Coupled => {
            let s = &trained.selections[0];
            let mut table = Table::new([
                "hidden nodes",
                "training RMSE (mm)",
                "validation RMSE (mm)",
                "",
            ]);
            for p in &s.sweep {
                table.row([
                    p.hidden.to_string(),
                    format!("{:.4}", p.training_rmse_mm),
                    format!("{:.4}", p.validation_rmse_mm),
                    if p.hidden == s.chosen {
                        "← chosen".into()
                    } else {
                        String::new()
                    },
                ]);
            }
            println!("Selection of hidden nodes, coupled network (Eq. 18):\n{table}");
        }
        Architecture::Decoupled => {
            let mut table = Table::new([
                "hidden",
                "leg 1",
                "leg 2",
                "leg 3",
                "leg 4",
                "leg 5",
                "leg 6",
                "Perf (Eq. 21)",
            ]);
            for (row, hidden) in sizes.iter().enumerate() {
                let cells: Vec<String> = trained
                    .selections
                    .iter()
                    .map(|s| {
                        let p = s.sweep[row];
                        let mark = if s.chosen == *hidden { "*" } else { "" };
                        format!(
                            "{:.4}/{:.4}{mark}",
                            p.training_rmse_mm, p.validation_rmse_mm
                        )
                    })
                    .collect();
                let perf = composite(&trained.selections, row, |p| p.validation_rmse_mm);
                table.row([
                    hidden.to_string(),
                    cells[0].clone(),
                    cells[1].clone(),
                    cells[2].clone(),
                    cells[3].clone(),
                    cells[4].clone(),
                    cells[5].clone(),
                    format!("{perf:.4}"),
                ]);
            }
            println!(
                "Selection of hidden nodes, decoupled networks: training/validation RMSE (mm), * chosen:\n{table}"
            );
        }
    }
}

/// √Σ_i RMSE_i² over the networks at sweep row `row` (Eq. 21).
fn composite(
    selections: &[Selection],
    row: usize,
    pick: impl Fn(&hexacomp_calibration::train::SweepPoint) -> f64,
) -> f64 {
    selections
        .iter()
        .map(|s| pick(&s.sweep[row]).powi(2))
        .sum::<f64>()
        .sqrt()
}

/// Writes the selection curve as SVG (Fig. 10 for coupled, Fig. 11 for decoupled).
pub fn write_selection_plot(
    trained: &Trained,
    architecture: Architecture,
    path: &Path,
) -> anyhow::Result<()> {
    let s = &trained.selections;
    let sizes: Vec<f64> = s[0].sweep.iter().map(|p| p.hidden as f64).collect();
    let curve =
        |pick: &dyn Fn(&hexacomp_calibration::train::SweepPoint) -> f64| -> Vec<(f64, f64)> {
            sizes
                .iter()
                .enumerate()
                .map(|(row, &h)| (h, composite(s, row, pick)))
                .collect()
        };
    let mut series = vec![
        Series::line("training", curve(&|p| p.training_rmse_mm)),
        Series::line("validation", curve(&|p| p.validation_rmse_mm)),
    ];
    if architecture == Architecture::Decoupled {
        for (leg, sel) in s.iter().enumerate() {
            series.push(Series::line(
                format!("validation, leg {}", leg + 1),
                sel.sweep
                    .iter()
                    .map(|p| (p.hidden as f64, p.validation_rmse_mm))
                    .collect(),
            ));
        }
    }
    let chart = Chart {
        title: format!(
            "Selection of hidden nodes, {} ({})",
            arch_name(architecture),
            match architecture {
                Architecture::Coupled => "Eq. 18",
                Architecture::Decoupled => "Eq. 21 for the totals",
            }
        ),
        x: Axis::linear("hidden nodes"),
        y: Axis::linear("RMSE (mm)"),
        series,
    };
    Ok(super::write_bytes(path, chart.to_svg()?.as_bytes())?)
}
