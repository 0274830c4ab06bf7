//! Measurements files: per configuration the commanded pose and legs, then what the instrument
//! measured — the target points `p1x..pNz` (any number N ≥ 3; a target not seen has its three
//! cells empty), or the platform's pose `mx,my,mz,ma,mb,mc` from a 6-DoF probe.

use std::collections::HashMap;
use std::io::Write;
use std::path::Path;

use glam::DVec3;
use hexacomp_core::MIN_TARGETS;
use hexacomp_core::observation::Observation;
use hexacomp_core::pose::PoseConvention;
use hexacomp_core::records::MeasuredConfiguration;

use crate::{
    Error, JournalKind, LEG_COLUMNS, POSE_COLUMNS, Records, Result, Row, Rows, cells, header,
    write_rows,
};

/// The measured-pose columns of a 6-DoF probe: position (mm) and angles (degrees).
pub const MEASURED_POSE_COLUMNS: [&str; 6] = ["mx", "my", "mz", "ma", "mb", "mc"];

/// The three columns of target `j` (1-based): `pjx, pjy, pjz`.
pub fn target_columns(j: usize) -> [String; 3] {
    ["x", "y", "z"].map(|axis| format!("p{j}{axis}"))
}

/// How many targets a header names: N when `p1x..pNz` are all present and `p(N+1)x` is not.
fn targets_named(columns: &HashMap<String, usize>) -> usize {
    (1..)
        .take_while(|&j| columns.contains_key(&format!("p{j}x")))
        .count()
}

/// The kind of `observed`, as a file's measured columns hold it (a missed pose is a pose).
pub(crate) fn kind_of(observed: &Observation) -> JournalKind {
    match observed {
        Observation::Targets(targets) => JournalKind::Targets(targets.len()),
        Observation::Pose(_) | Observation::PoseMissed => JournalKind::Pose,
    }
}

/// The measured columns of a file of `kind`: `p1x..pNz` or `mx..mc`.
pub(crate) fn measured_columns(kind: JournalKind) -> Vec<String> {
    match kind {
        JournalKind::Targets(count) => (1..=count).flat_map(target_columns).collect(),
        JournalKind::Pose => MEASURED_POSE_COLUMNS.map(str::to_string).to_vec(),
    }
}

/// The cells of `row`: id, commanded pose, legs, then what was measured (a target not seen or a
/// missed pose as empty cells; a pose in `convention`).
pub(crate) fn row_cells(row: &MeasuredConfiguration, convention: PoseConvention) -> Vec<String> {
    let measured: Vec<String> = match &row.observed {
        Observation::Targets(targets) => targets
            .iter()
            .flat_map(|p| match p {
                Some(p) => cells(&p.to_array()).collect::<Vec<_>>(),
                None => vec![String::new(); 3],
            })
            .collect(),
        Observation::Pose(values) => cells(&convention.from_linuxcnc(*values)).collect(),
        Observation::PoseMissed => vec![String::new(); 6],
    };
    std::iter::once(row.id.clone())
        .chain(cells(&row.pose_mm_deg))
        .chain(cells(&row.legs))
        .chain(measured)
        .collect()
}

/// Reads a measurements file (`id,x,y,z,a,b,c,q1..q6`, then `p1x..pNz` or `mx..mc`), its
/// measured poses in `convention` (converted to LinuxCNC's; the commanded pose is read as
/// written).
///
/// A target whose three cells are all empty was not seen, a measured pose whose six cells are all
/// empty was not taken ([`Observation::PoseMissed`]); a target or pose with only some cells empty
/// is refused.
pub fn read_measurements_in(
    path: &Path,
    convention: PoseConvention,
) -> Result<Records<MeasuredConfiguration>> {
    let rows = Rows::open(path, &[&POSE_COLUMNS, &LEG_COLUMNS], |row| {
        Ok(MeasuredConfiguration {
            id: row.id.to_string(),
            pose_mm_deg: row.numbers(POSE_COLUMNS)?,
            legs: row.numbers(LEG_COLUMNS)?,
            observed: observation(row)?,
        })
    })?;
    check_measured_columns(&rows)?;
    let mut records = rows.collect()?;
    if convention != PoseConvention::Linuxcnc {
        for record in records.iter_mut() {
            if let Observation::Pose(values) = &mut record.observed {
                *values = convention.to_linuxcnc(*values);
            }
        }
    }
    Ok(records)
}

/// Reads a measurements file whose measured poses (if any) are in LinuxCNC's convention.
pub fn read_measurements(path: &Path) -> Result<Records<MeasuredConfiguration>> {
    read_measurements_in(path, PoseConvention::Linuxcnc)
}

/// One row of a campaign's drift log: a measurement of the reference configuration and what
/// was decided about it (the columns [`crate::DRIFT_COLUMNS`]).
#[derive(Debug, Clone, PartialEq)]
pub struct DriftEntry {
    /// The reference configuration as measured (its id numbers the measurements: `R1`, `R2`…),
    /// in the record's frame.
    pub reference: MeasuredConfiguration,
    /// `warm-up`, `start`, `reference` or `end`.
    pub event: String,
    /// The configurations the record held when it was measured.
    pub configurations: usize,
    /// `baseline`, `ok`, `stopped`, `accepted`, `warming` or `stable`.
    pub decision: String,
    /// The instrument's pose in the base frame of the run's registration (mm, degrees), when the
    /// run had one.
    pub instrument_pose: Option<[f64; 6]>,
}

/// The instrument-pose columns of a drift log.
const INSTRUMENT_POSE_COLUMNS: [&str; 6] = ["ix", "iy", "iz", "ia", "ib", "ic"];

/// The events a drift log names.
pub const DRIFT_EVENTS: [&str; 4] = ["warm-up", "start", "reference", "end"];
/// The decisions a drift log names.
pub const DRIFT_DECISIONS: [&str; 6] =
    ["baseline", "ok", "stopped", "accepted", "warming", "stable"];

/// Reads a campaign's drift log (a measurements file with [`crate::DRIFT_COLUMNS`] after the
/// measured ones); an event or a decision it does not know is an error naming its line.
pub fn read_drift_log(path: &Path) -> Result<Records<DriftEntry>> {
    let rows = Rows::open(
        path,
        &[&POSE_COLUMNS, &LEG_COLUMNS, &crate::DRIFT_COLUMNS],
        |row| {
            let configurations = row.text("configurations").parse().map_err(|_| {
                row.error(
                    Some("configurations"),
                    format!(
                        "{} is not a count",
                        crate::quote(row.text("configurations"))
                    ),
                )
            })?;
            let instrument_pose = if INSTRUMENT_POSE_COLUMNS
                .iter()
                .all(|c| row.text(c).is_empty())
            {
                None
            } else {
                Some(row.numbers(INSTRUMENT_POSE_COLUMNS)?)
            };
            for (column, known) in [
                ("event", &DRIFT_EVENTS[..]),
                ("decision", &DRIFT_DECISIONS[..]),
            ] {
                if !known.contains(&row.text(column)) {
                    return Err(row.error(
                        Some(column),
                        format!(
                            "{} is not one of {}",
                            crate::quote(row.text(column)),
                            known.join(", ")
                        ),
                    ));
                }
            }
            Ok(DriftEntry {
                reference: MeasuredConfiguration {
                    id: row.id.to_string(),
                    pose_mm_deg: row.numbers(POSE_COLUMNS)?,
                    legs: row.numbers(LEG_COLUMNS)?,
                    observed: observation(row)?,
                },
                event: row.text("event").to_string(),
                configurations,
                decision: row.text("decision").to_string(),
                instrument_pose,
            })
        },
    )?;
    check_measured_columns(&rows)?;
    rows.collect()
}

/// Refuses a header with neither targets nor a measured pose, both, or fewer than three
/// targets, or a target with one of its three columns missing.
fn check_measured_columns<T>(rows: &Rows<T>) -> Result<()> {
    let columns = &rows.header.columns;
    let fail = |column: String, message: String| Error::Format {
        file: rows.file().to_string(),
        line: rows.header.line,
        column: Some(column),
        message,
    };
    let has_pose = MEASURED_POSE_COLUMNS
        .iter()
        .any(|c| columns.contains_key(*c));
    let named = targets_named(columns);
    if has_pose {
        if named > 0 {
            return Err(fail(
                "p1x".into(),
                "a measurements file holds target points or a measured pose (mx..mc), not both"
                    .into(),
            ));
        }
        if let Some(missing) = MEASURED_POSE_COLUMNS
            .iter()
            .find(|c| !columns.contains_key(**c))
        {
            return Err(fail(
                missing.to_string(),
                "required column is missing from the header".into(),
            ));
        }
        return Ok(());
    }
    for j in 1..=named.max(MIN_TARGETS) {
        if let Some(missing) = target_columns(j)
            .into_iter()
            .find(|c| !columns.contains_key(c))
        {
            return Err(fail(
                missing,
                "required column is missing from the header".into(),
            ));
        }
    }
    Ok(())
}

/// The observation of one row: its targets (empty cells: not seen) or its measured pose.
fn observation(row: &Row) -> Result<Observation> {
    if row.header.columns.contains_key("mx") {
        let empty = MEASURED_POSE_COLUMNS
            .iter()
            .all(|c| row.record[row.header.columns[*c]].trim().is_empty());
        if empty {
            return Ok(Observation::PoseMissed);
        }
        return Ok(Observation::Pose(row.numbers(MEASURED_POSE_COLUMNS)?));
    }
    let targets = (1..=targets_named(&row.header.columns))
        .map(|j| {
            let columns = target_columns(j);
            let texts = columns
                .each_ref()
                .map(|c| row.record[row.header.columns[c.as_str()]].trim());
            if texts.iter().all(|t| t.is_empty()) {
                return Ok(None);
            }
            if let Some(k) = texts.iter().position(|t| t.is_empty()) {
                return Err(row.error(
                    Some(&columns[k]),
                    format!(
                        "empty, but target {j}'s other coordinates are given: a target is either \
                         measured whole or left empty (not seen)"
                    ),
                ));
            }
            let [x, y, z] = row.numbers(columns.each_ref().map(String::as_str))?;
            Ok(Some(DVec3::new(x, y, z)))
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(Observation::Targets(targets))
}

/// Writes a measurements file, its measured poses (if any) in `convention`. Every row holds the
/// same kind of observation (targets, as many in each row, or a pose); a target not seen is
/// written as three empty cells.
pub fn write_measurements_in<W: Write>(
    writer: W,
    rows: &[MeasuredConfiguration],
    convention: PoseConvention,
) -> std::io::Result<()> {
    let first = rows
        .first()
        .map_or(JournalKind::Targets(MIN_TARGETS), |r| kind_of(&r.observed));
    if let Some(row) = rows.iter().find(|r| kind_of(&r.observed) != first) {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!(
                "configuration {} measured otherwise than the first (targets or a pose, as many \
                 targets): one file holds one kind",
                row.id
            ),
        ));
    }
    let measured = measured_columns(first);
    let mut head = header(&[&POSE_COLUMNS, &LEG_COLUMNS]);
    head.extend(measured.iter().map(String::as_str));
    write_rows(writer, &head, rows.iter().map(|r| row_cells(r, convention)))
}

/// Writes a measurements file, measured poses (if any) in LinuxCNC's convention.
pub fn write_measurements<W: Write>(
    writer: W,
    rows: &[MeasuredConfiguration],
) -> std::io::Result<()> {
    write_measurements_in(writer, rows, PoseConvention::Linuxcnc)
}
