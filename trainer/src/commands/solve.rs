//! `hexacomp-trainer solve`: joint corrections by the paper's robust Levenberg–Marquardt
//! iteration (Fig. 2).

use std::path::{Path, PathBuf};
use std::time::Instant;

use hexacomp_calibration::corrections::{Checks, Outcome, Solution, SolverOptions};
use hexacomp_calibration::pipeline::{Pipeline, Solved};
use hexacomp_calibration::screening::{Screening, ScreeningOptions, screen_corrections};
use hexacomp_core::Geometry;
use hexacomp_core::records::JointCorrection;
use hexacomp_core::records::MeasuredConfiguration;
use hexacomp_formats::{Records, write_corrections};

use hexacomp_formats::write_file;

use super::measurements_input::MeasurementsInput;

/// Solve the joint corrections Δq of every measured configuration (paper Fig. 2: Eq. 5, Eq. 6,
/// Eq. 7, Eq. 8, Eq. 9).
///
/// From the commanded legs q⁽⁰⁾, iterate: ζ = measured − computed target points, P and T at the
/// iterate, λ = λ0 when cond(PT) > c else 0, ρ = ((PT)ᵀPT + λI)⁻¹(PT)ᵀζ, q += ρ, until ‖ρ‖ < κ;
/// then Δq = q⁽⁰⁾ − q⁽ᴸ⁾. Output: a corrections CSV, `id,q1..q6,dq1..dq6` (mm), then the
/// diagnostics `cond_pt` (largest over the iterates), `iterations`, `converged`, `residual_mm`
/// (‖ζ‖ at q⁽ᴸ⁾).
///
/// Gross errors are excluded, each listed with its line, id and reason: a configuration that
/// cannot be solved or does not converge, whose commanded legs disagree with the pose, whose
/// correction exceeds --max-correction, whose fit residual is more than --residual-factor × the
/// median, or whose targets are far from the geometry identified from the configurations
/// (docs/commands.md, "Gross errors").
/// When more than --max-excluded-share of the file would be excluded, the file is refused and
/// nothing is written: the data as a whole must be wrong. An existing output is replaced only by
/// a complete new one.
#[derive(Debug, clap::Args)]
pub struct SolveArgs {
    /// Measurements CSV (from a measuring arm or laser tracker, or `hexacomp-trainer simulate`).
    #[arg(long, value_name = "FILE")]
    measurements: PathBuf,
    /// Output corrections CSV.
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
    /// Regularisation λ0 applied when cond(PT) > c (paper: 0.05).
    #[arg(long, default_value_t = SolverOptions::default().lambda0)]
    lambda0: f64,
    /// Condition-number threshold c of PT (paper: 1e3).
    #[arg(long, default_value_t = SolverOptions::default().cond_threshold)]
    cond_threshold: f64,
    /// Convergence threshold κ on ‖ρ‖, mm (paper: √6 × 0.002 mm encoder resolution).
    #[arg(long, default_value_t = SolverOptions::default().kappa_mm)]
    kappa: f64,
    /// Iteration limit per configuration.
    #[arg(long, default_value_t = SolverOptions::default().max_iterations)]
    max_iterations: usize,
    /// The paper's ordinary compensator: λ = 0 always, for comparison.
    #[arg(long)]
    ordinary: bool,
    #[command(flatten)]
    reading: MeasurementsInput,
    #[command(flatten)]
    screening: MeasuredScreeningArgs,
}

impl SolveArgs {
    /// The files this command reads and writes.
    pub fn files(&self) -> super::Files<'_> {
        super::Files {
            inputs: std::iter::once(self.measurements.as_path())
                .chain(self.reading.registration_path())
                .collect(),
            outputs: vec![&self.out],
        }
    }
}

pub fn run(geometry: &Geometry, args: &SolveArgs) -> anyhow::Result<()> {
    let rows = args.reading.read(&args.measurements, geometry)?;
    anyhow::ensure!(
        !rows.is_empty(),
        "{}: no configurations",
        args.measurements.display()
    );
    let pipeline = Pipeline {
        solver: SolverOptions {
            lambda0: args.lambda0,
            cond_threshold: args.cond_threshold,
            kappa_mm: args.kappa,
            max_iterations: args.max_iterations,
            robust: !args.ordinary,
        },
        checks: args.screening.checks(),
        screening: args.screening.options(),
        ..Default::default()
    };
    let start = Instant::now();
    let solved = solve_screened(&pipeline, geometry, &rows)?;
    let elapsed = start.elapsed();
    let kept = solved.kept();
    anyhow::ensure!(
        !kept.is_empty(),
        "no configuration of {} could be used; nothing written",
        args.measurements.display()
    );
    let written = write_outcomes(&args.out, &kept)?;
    report(&kept, &pipeline.solver, elapsed.as_secs_f64());
    eprintln!("wrote {written} rows → {}", args.out.display());
    Ok(())
}

/// The solver's figures over the configurations kept.
fn report(kept: &[&Outcome], options: &SolverOptions, seconds: f64) {
    let solved: Vec<&Solution> = kept
        .iter()
        .filter_map(|o| o.solution.as_ref().ok())
        .collect();
    let regularised = solved.iter().filter(|s| s.regularised).count();
    let above = solved
        .iter()
        .filter(|s| s.max_cond_pt > options.cond_threshold)
        .count();
    let max_cond = solved.iter().map(|s| s.max_cond_pt).fold(0.0, f64::max);
    let max_iterations = solved.iter().map(|s| s.iterations).max().unwrap_or(0);
    let mean_residual =
        solved.iter().map(|s| s.residual_mm).sum::<f64>() / solved.len().max(1) as f64;
    eprintln!(
        "{} compensator: {} configurations in {:.1} ms; cond(PT) ≤ {:.3e} ({above} above c = \
         {:.0e}, {regularised} regularised); iterations ≤ {max_iterations}; mean residual {:.4} mm",
        if options.robust { "robust" } else { "ordinary" },
        solved.len(),
        1e3 * seconds,
        max_cond,
        options.cond_threshold,
        mean_residual,
    );
}

/// Writes the corrections file of `outcomes` that have a solution: the columns of docs/formats.md and the
/// diagnostics. Returns the rows written.
pub fn write_outcomes(path: &Path, outcomes: &[&Outcome]) -> anyhow::Result<usize> {
    let solved: Vec<(&Outcome, &Solution)> = outcomes
        .iter()
        .filter_map(|o| o.solution.as_ref().ok().map(|s| (*o, s)))
        .collect();
    let corrections: Vec<_> = solved
        .iter()
        .filter_map(|(o, _)| o.joint_correction())
        .collect();
    let diagnostics: Vec<Vec<String>> = solved
        .iter()
        .map(|(_, s)| {
            vec![
                s.max_cond_pt.to_string(),
                s.iterations.to_string(),
                s.converged.to_string(),
                s.residual_mm.to_string(),
            ]
        })
        .collect();
    write_file(path, |w| {
        write_corrections(
            w,
            &corrections,
            &["cond_pt", "iterations", "converged", "residual_mm"],
            &diagnostics,
        )
    })?;
    Ok(corrections.len())
}

/// Prints every excluded configuration of `records` with its file, line and id and reasons,
/// then how many were kept and excluded, and any note on the checks.
fn print_exclusions<T>(screening: &Screening, records: &Records<T>, id: impl Fn(&T) -> &str) {
    for (index, reasons) in screening.reasons.iter().enumerate() {
        for reason in reasons {
            eprintln!(
                "excluded: configuration {} ({}:{}): {reason}",
                id(&records[index]),
                records.file,
                records.line(index)
            );
        }
    }
    for note in &screening.notes {
        eprintln!("note: {note}");
    }
    let total = screening.reasons.len();
    let unmeasured = screening.excluded() - screening.gross_errors();
    eprintln!(
        "{} of {total} configurations kept, {} excluded as gross errors{}{}",
        total - screening.excluded(),
        screening.gross_errors(),
        if unmeasured > 0 {
            format!(", {unmeasured} whose targets seen do not fix the pose")
        } else {
            String::new()
        },
        screening
            .residual_limit_mm
            .map(|limit| format!(" (residual limit {limit:.4} mm)"))
            .unwrap_or_default()
    );
}

/// Prints the screening of `records` (every excluded row, the counts), and turns a refusal into
/// an error that names the file, after listing its rows.
fn decided<T, R>(
    result: hexacomp_calibration::Result<R>,
    screening_of: impl Fn(&R) -> &Screening,
    records: &Records<T>,
    id: impl Fn(&T) -> &str,
) -> anyhow::Result<R> {
    match result {
        Ok(value) => {
            print_exclusions(screening_of(&value), records, id);
            Ok(value)
        }
        Err(hexacomp_calibration::Error::Refused { reason, screening }) => {
            print_exclusions(&screening, records, id);
            anyhow::bail!("{}: refused: {reason}", records.file)
        }
        Err(e) => Err(e.into()),
    }
}

/// Solves and screens `measurements` with `pipeline`, printing the exclusions; a refused file is
/// an error naming it, after its rows are listed.
pub fn solve_screened(
    pipeline: &Pipeline,
    geometry: &Geometry,
    measurements: &Records<MeasuredConfiguration>,
) -> anyhow::Result<Solved> {
    decided(
        pipeline.solve(geometry, measurements),
        |solved| &solved.screening,
        measurements,
        |row| &row.id,
    )
}

/// Screens the rows of a corrections file (the bound of `args`), printing the exclusions; a
/// refused file is an error naming it, after its rows are listed.
pub fn screen_corrections_file(
    rows: &Records<JointCorrection>,
    args: &ScreeningArgs,
) -> anyhow::Result<Screening> {
    decided(
        screen_corrections(rows, args.max_correction_mm(), &args.options()),
        |screening| screening,
        rows,
        |row| &row.id,
    )
}

/// How gross errors among corrections are found and decided (the options of `train`; with
/// [`MeasuredScreeningArgs`], of `solve`, `calibrate` and `identify`).
#[derive(Debug, clap::Args)]
pub struct ScreeningArgs {
    /// Exclude a configuration with a correction larger than this, mm (no real leg is that far
    /// off).
    #[arg(help_heading = "Screening", long, default_value_t = Checks::default().max_correction_mm, value_name = "MM")]
    max_correction: f64,
    /// Refuse the input when more than this share of its configurations is excluded.
    #[arg(help_heading = "Screening", long, default_value_t = ScreeningOptions::default().max_excluded_share, value_name = "SHARE")]
    max_excluded_share: f64,
}

impl ScreeningArgs {
    /// The largest plausible correction, mm.
    pub fn max_correction_mm(&self) -> f64 {
        self.max_correction
    }

    /// The population checks and the refusal.
    pub fn options(&self) -> ScreeningOptions {
        ScreeningOptions {
            max_excluded_share: self.max_excluded_share,
            ..ScreeningOptions::default()
        }
    }
}

/// How gross errors among measurements are found and decided.
#[derive(Debug, clap::Args)]
pub struct MeasuredScreeningArgs {
    #[command(flatten)]
    corrections: ScreeningArgs,
    /// Exclude a configuration whose fit residual exceeds this many times the file's
    /// median.
    ///
    /// Pure noise exceeds 3× once in 10 000.
    #[arg(help_heading = "Screening", long, default_value_t = ScreeningOptions::default().residual_factor)]
    residual_factor: f64,
    /// Exclude a configuration this many times the median distance from the identified
    /// geometry.
    ///
    /// Its targets are further from the geometry identified from the configurations
    /// (repeated without those beyond the limit) than this many times the median distance.
    #[arg(help_heading = "Screening", long, default_value_t = ScreeningOptions::default().identification_factor)]
    identification_factor: f64,
    /// Exclude a configuration whose commanded legs differ from its pose's by more than
    /// this, mm.
    ///
    /// The legs are compared with the inverse kinematics of its commanded pose: a wrong
    /// geometry file, swapped leg columns; files must give poses and legs to enough
    /// decimals to meet it.
    #[arg(help_heading = "Screening", long, default_value_t = Checks::default().legs_tolerance_mm, value_name = "MM")]
    legs_tolerance: f64,
}

impl MeasuredScreeningArgs {
    /// The per-configuration checks of the solve.
    pub fn checks(&self) -> Checks {
        Checks {
            max_correction_mm: self.corrections.max_correction_mm(),
            legs_tolerance_mm: self.legs_tolerance,
        }
    }

    /// The population checks and the refusal.
    pub fn options(&self) -> ScreeningOptions {
        ScreeningOptions {
            residual_factor: self.residual_factor,
            identification_factor: self.identification_factor,
            ..self.corrections.options()
        }
    }
}
