//! `hexacomp-trainer solve`: joint corrections by the paper's robust Levenberg–Marquardt
//! iteration (Fig. 2).

use std::path::{Path, PathBuf};
use std::time::Instant;

use hexacomp_core::Geometry;
use hexacomp_core::records::MeasuredConfiguration;
use hexacomp_formats::{Records, read_measurements, write_corrections};
use hexacomp_trainer::corrections::{Checks, Outcome, Solution, SolverOptions, solve_all};

use super::write_file;

/// Solve the joint corrections Δq of every measured configuration (paper Fig. 2: Eq. 5, Eq. 6,
/// Eq. 7, Eq. 8, Eq. 9).
///
/// From the commanded legs q⁽⁰⁾, iterate: ζ = measured − computed target points, P and T at the
/// iterate, λ = λ0 when cond(PT) > c else 0, ρ = ((PT)ᵀPT + λI)⁻¹(PT)ᵀζ, q += ρ, until ‖ρ‖ < κ;
/// then Δq = q⁽⁰⁾ − q⁽ᴸ⁾. Output: a corrections CSV, `id,q1..q6,dq1..dq6` (mm), then the
/// diagnostics `cond_pt` (largest over the iterates), `iterations`, `converged`, `residual_mm`
/// (‖ζ‖ at q⁽ᴸ⁾).
///
/// Configurations that did not converge, whose residual is far above the measurement noise, whose
/// correction is implausibly large, or whose commanded legs disagree with the geometry are listed
/// by id; they stay in the output unless --exclude-flagged is given. Configurations that cannot be
/// solved at all (a leg leaves the stroke, a singular iterate) cannot have a row and are listed as
/// errors.
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
    /// Flag configurations whose residual ‖ζ‖ exceeds this, mm (noise alone leaves about
    /// √3 × the device's per-coordinate uncertainty).
    #[arg(long, default_value_t = Checks::default().max_residual_mm)]
    max_residual: f64,
    /// Flag configurations with a correction larger than this, mm.
    #[arg(long, default_value_t = Checks::default().max_correction_mm)]
    max_correction: f64,
    /// Leave flagged configurations out of the output.
    #[arg(long)]
    exclude_flagged: bool,
}

pub fn run(geometry: &Geometry, args: &SolveArgs) -> anyhow::Result<()> {
    let rows = read_measurements(&args.measurements)?;
    anyhow::ensure!(
        !rows.is_empty(),
        "{}: no configurations",
        args.measurements.display()
    );
    let options = SolverOptions {
        lambda0: args.lambda0,
        cond_threshold: args.cond_threshold,
        kappa_mm: args.kappa,
        max_iterations: args.max_iterations,
        robust: !args.ordinary,
    };
    let checks = Checks {
        max_residual_mm: args.max_residual,
        max_correction_mm: args.max_correction,
        ..Checks::default()
    };
    let start = Instant::now();
    let outcomes = solve_all(geometry, &rows, &options, &checks)?;
    let elapsed = start.elapsed();

    let kept: Vec<&Outcome> = outcomes
        .iter()
        .filter(|o| o.solution.is_ok() && (o.flags.is_empty() || !args.exclude_flagged))
        .collect();
    let written = write_outcomes(&args.out, &kept)?;
    report(
        &outcomes,
        &rows,
        &options,
        elapsed.as_secs_f64(),
        written,
        args,
    );
    anyhow::ensure!(
        written > 0,
        "no configuration could be solved; nothing to train on"
    );
    Ok(())
}

fn report(
    outcomes: &[Outcome],
    measurements: &Records<MeasuredConfiguration>,
    options: &SolverOptions,
    seconds: f64,
    written: usize,
    args: &SolveArgs,
) {
    let solved: Vec<_> = outcomes
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
        "{} compensator: solved {}/{} configurations in {:.1} ms; cond(PT) ≤ {:.3e} \
         ({above} above c = {:.0e}, {regularised} regularised); iterations ≤ {max_iterations}; \
         mean residual {:.4} mm",
        if options.robust { "robust" } else { "ordinary" },
        solved.len(),
        outcomes.len(),
        1e3 * seconds,
        max_cond,
        options.cond_threshold,
        mean_residual,
    );
    print_problems(outcomes, measurements, "");
    let flagged = outcomes.iter().filter(|o| !o.flags.is_empty()).count();
    if flagged > 0 {
        eprintln!(
            "{flagged} configurations flagged; {}",
            if args.exclude_flagged {
                "excluded from the output (--exclude-flagged)"
            } else {
                "kept in the output (use --exclude-flagged to leave them out of training)"
            }
        );
    }
    eprintln!("wrote {written} rows → {}", args.out.display());
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

/// Prints every configuration that could not be solved (as an error) or was flagged (as a
/// warning, followed by `flag_note`), with its line in `measurements` (the file the outcomes,
/// in the same order, were solved from).
pub fn print_problems(
    outcomes: &[Outcome],
    measurements: &Records<MeasuredConfiguration>,
    flag_note: &str,
) {
    for (index, o) in outcomes.iter().enumerate() {
        let line = measurements.line(index);
        if let Err(e) = &o.solution {
            eprintln!(
                "error: configuration {} (line {line}): cannot be solved: {e}",
                o.id
            );
        }
        for flag in &o.flags {
            eprintln!(
                "warning: configuration {} (line {line}): {flag}{flag_note}",
                o.id
            );
        }
    }
}
