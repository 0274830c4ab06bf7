//! `hexacomp-trainer plan`: measuring configurations spread over the task workspace.

use std::path::PathBuf;

use hexacomp_calibration::plan::{PlanOptions, numbered_rows, plan_with_progress, plan_work};
use hexacomp_core::Geometry;
use hexacomp_core::sampling::SamplerOptions;
use hexacomp_formats::write_poses;
use indicatif::{ProgressBar, ProgressStyle};

use hexacomp_formats::write_file;

/// Plan N measuring configurations spread over the task workspace (like the paper's Fig. 8).
///
/// The plan starts with each leg's shortest and longest reach over the workspace (12
/// configurations, the extremes among 2000 random poses; with --count below 12, only the first
/// legs' extremes), so that the model is rarely asked beyond the leg lengths it was measured at,
/// and then by a fraction of a millimetre. Each further configuration is the best of several
/// uniform random candidates (the one farthest from those already chosen), so the plan is
/// random but evenly spread; poses whose legs come within the stroke margin of a stroke end are
/// never chosen. The time this takes grows with the square of the count (a progress bar shows
/// the time left); with --candidates 1 it grows linearly.
/// Output: a poses CSV, `id,x,y,z,a,b,c` (mm, degrees), ids 1..N.
#[derive(Debug, clap::Args)]
pub struct PlanArgs {
    /// Number of configurations (the paper measured 150: 100 for training, 50 for validation).
    #[arg(long, default_value_t = 150)]
    count: usize,
    /// Seed of the random draws; the same seed gives the same plan.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Candidates drawn per configuration (1: plain uniform random draws).
    #[arg(long, default_value_t = 10)]
    candidates: usize,
    /// Keep every leg at least this far from both stroke ends, mm.
    #[arg(long, default_value_t = 2.0)]
    stroke_margin: f64,
    /// Do not start with each leg's shortest and longest reach.
    ///
    /// Every configuration by best-candidate sampling (with --candidates 1, plain uniform
    /// draws as in the paper's Fig. 8).
    #[arg(long)]
    no_leg_extremes: bool,
    /// Output poses CSV.
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
}

impl PlanArgs {
    /// The files this command reads and writes.
    pub fn files(&self) -> super::Files<'_> {
        super::Files {
            inputs: vec![],
            outputs: vec![&self.out],
        }
    }
}

pub fn run(geometry: &Geometry, args: &PlanArgs) -> anyhow::Result<()> {
    anyhow::ensure!(args.count > 0, "--count must be at least 1");
    let options = PlanOptions {
        count: args.count,
        seed: args.seed,
        candidates: args.candidates,
        sampler: SamplerOptions {
            stroke_margin_mm: args.stroke_margin,
            ..Default::default()
        },
        leg_extremes: !args.no_leg_extremes,
    };
    let bar = ProgressBar::new(plan_work(&options));
    bar.set_style(
        ProgressStyle::with_template(
            "planning {msg} configurations [{bar:30}] {percent_precise}% ({elapsed}, about {eta} left)",
        )
        .expect("valid template")
        .progress_chars("=> "),
    );
    bar.set_message(args.count.to_string());
    let poses = plan_with_progress(geometry, &options, &|n| bar.inc(n));
    bar.finish_and_clear();
    let rows = numbered_rows(&poses?);
    write_file(&args.out, |w| write_poses(w, &rows))?;
    eprintln!(
        "planned {} configurations over the workspace of {} → {}",
        rows.len(),
        geometry.name,
        args.out.display()
    );
    Ok(())
}
