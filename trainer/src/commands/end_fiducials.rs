//! The registration's fiducials measured again at the end of a campaign: the file they are
//! written to beside the record (a measured-fiducials file `register` reads), and the decision
//! whether the registration still holds.

use std::path::{Path, PathBuf};

use hexacomp_formats::{RegistrationFile, read_fiducials, write_fiducials_with};
use hexacomp_measuring::campaign::{CampaignOptions, Instrument};
use hexacomp_measuring::fiducial_check::{FiducialCheck, compare, remeasure};

/// The columns after `name,x,y,z`: the registration's weight, the movement since the
/// registration (mm), the readings' spread (mm) and the readings kept.
const COLUMNS: [&str; 4] = ["weight", "moved_mm", "spread_mm", "readings"];

/// The file of the record `out`: `out` with `.fiducials.csv` in place of its extension.
pub fn path(out: &Path) -> PathBuf {
    out.with_extension("fiducials.csv")
}

/// Refuses a file at `path` that a campaign did not write (its header lacks `moved_mm`): a
/// user's own fiducials file must not be replaced or removed.
pub fn refuse_foreign(path: &Path) -> anyhow::Result<()> {
    let text = match std::fs::read_to_string(path) {
        Ok(text) => text,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(e) => anyhow::bail!("{}: {e}", path.display()),
    };
    let header = text.lines().next().unwrap_or_default();
    anyhow::ensure!(
        header.split(',').any(|column| column.trim() == COLUMNS[1]),
        "{}: a file that a campaign did not write is where this campaign writes its fiducials \
         at the end: move it, or give --out another name",
        path.display()
    );
    Ok(())
}

/// Removes the file at `path` (a campaign's, [`refuse_foreign`]) before rows are recorded after
/// it: fiducials measured before them no longer check the end of the campaign.
pub fn forget(path: &Path) -> anyhow::Result<()> {
    match std::fs::remove_file(path) {
        Ok(()) => hexacomp_core::durable::sync_directory_of(path)
            .map_err(|e| anyhow::anyhow!("{}: {e}", path.display())),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => anyhow::bail!("{}: cannot remove it: {e}", path.display()),
    }
}

/// Measures the fiducials of `registration` with `instrument`, writes them to `path` (whole, and
/// only when there are enough to decide on: otherwise they stay owed to the next run), and
/// decides with `limit_mm` (`one_frame`: the record is in the instrument's frame as it stands):
/// the line to show when the registration holds, an error otherwise.
pub fn measure(
    instrument: &mut dyn Instrument,
    options: &CampaignOptions,
    registration: &RegistrationFile,
    path: &Path,
    limit_mm: f64,
    one_frame: bool,
) -> anyhow::Result<String> {
    let check = remeasure(instrument, options, registration)?;
    let shown = path.display().to_string();
    let Some(decision) = check.decide(limit_mm, &shown, one_frame) else {
        anyhow::bail!(
            "the fiducials could not be checked: {}; the registration is unchecked: run again to \
             measure them (or give --skip-fiducials)",
            check.undecided()
        );
    };
    write(path, &check)?;
    decision
        .map(|line| format!("{shown}: {line}"))
        .map_err(|why| anyhow::anyhow!("{shown}: {why}"))
}

/// Decides again from the file an earlier run wrote, against `registration` (that of this run:
/// a registration made from the file holds); `None` when the file cannot decide for this
/// registration (other fiducials, other weights): they are measured again.
pub fn recheck(
    registration: &RegistrationFile,
    path: &Path,
    limit_mm: f64,
    one_frame: bool,
) -> anyhow::Result<Option<String>> {
    let points = read_fiducials(path)?.into_items();
    let Ok(check) = compare(registration, &points) else {
        return Ok(None);
    };
    let shown = path.display().to_string();
    match check.decide(limit_mm, &shown, one_frame) {
        None => Ok(None),
        Some(Ok(line)) => Ok(Some(format!("{shown}: {line}"))),
        Some(Err(why)) => anyhow::bail!("{shown}: {why}"),
    }
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
