//! The registration's fiducials measured again at the end of a campaign: the file they are
//! written to beside the record (a measured-fiducials file `register` reads), and the decision
//! whether the registration still holds.

use std::path::{Path, PathBuf};

use hexacomp_formats::{RegistrationFile, read_fiducials, write_fiducials_with};
use hexacomp_trainer::campaign::{CampaignOptions, Instrument};
use hexacomp_trainer::fiducial_check::{FiducialCheck, compare, remeasure};

/// The columns after `name,x,y,z`: the registration's weight, the movement since the
/// registration (mm), the readings' spread (mm) and the readings kept.
const COLUMNS: [&str; 4] = ["weight", "moved_mm", "spread_mm", "readings"];

/// The file of the record `out`: `out` with `.fiducials.csv` in place of its extension.
pub fn path(out: &Path) -> PathBuf {
    out.with_extension("fiducials.csv")
}

/// Measures the fiducials of `registration` with `instrument`, writes them to `path` (whole, and
/// only when there are enough to decide on: otherwise they stay owed to the next run), and
/// decides with `limit_mm`: the line to show when the registration holds, an error otherwise.
pub fn measure(
    instrument: &mut dyn Instrument,
    options: &CampaignOptions,
    registration: &RegistrationFile,
    path: &Path,
    limit_mm: f64,
) -> anyhow::Result<String> {
    let check = remeasure(instrument, options, registration)?;
    if check.deviation().is_some() {
        write(path, &check)?;
    }
    decide(&check, path, limit_mm)
}

/// Decides again from the file an earlier run wrote, against `registration` (that of this run:
/// a registration made from the file holds).
pub fn recheck(
    registration: &RegistrationFile,
    path: &Path,
    limit_mm: f64,
) -> anyhow::Result<String> {
    let points = read_fiducials(path)?.into_items();
    let check = compare(registration, &points)
        .map_err(|e| anyhow::anyhow!("{}: {e}: it belongs to another set-up", path.display()))?;
    decide(&check, path, limit_mm)
}

/// The decision, naming the file.
fn decide(check: &FiducialCheck, path: &Path, limit_mm: f64) -> anyhow::Result<String> {
    let shown = path.display().to_string();
    check
        .decide(limit_mm, &shown)
        .map(|line| format!("{shown}: {line}"))
        .map_err(|why| anyhow::anyhow!("{shown}: {why}"))
}

/// Writes the fiducials measured (the instrument's frame, mm) with their figures.
fn write(path: &Path, check: &FiducialCheck) -> anyhow::Result<()> {
    let points: Vec<_> = check.measured.iter().map(|f| f.point.clone()).collect();
    let cells: Vec<Vec<String>> = check
        .measured
        .iter()
        .map(|f| {
            vec![
                f.point.weight.to_string(),
                f.moved.length().to_string(),
                f.spread_mm.to_string(),
                f.kept.to_string(),
            ]
        })
        .collect();
    hexacomp_formats::write_file(path, |file| {
        write_fiducials_with(file, &points, &COLUMNS, &cells)
    })?;
    Ok(())
}
