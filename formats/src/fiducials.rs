//! Fiducial files: `name,x,y,z` (mm), optionally `weight`, one fiducial per row.

use std::io::Write;
use std::path::Path;

use glam::DVec3;
use hexacomp_core::records::NamedPoint;

use crate::{Records, Result, Rows, write_rows};

/// The coordinate columns of a fiducials file, mm.
pub const FIDUCIAL_COLUMNS: [&str; 3] = ["x", "y", "z"];

/// Reads a fiducials file: `name,x,y,z` (mm, in the frame the file is in), and an optional
/// `weight` column (a finite number ≥ 0; 1 when absent). Names are unique and not empty.
pub fn read_fiducials(path: &Path) -> Result<Records<NamedPoint>> {
    Rows::open_keyed(path, "name", &[&FIDUCIAL_COLUMNS], |row| {
        let [x, y, z] = row.numbers(FIDUCIAL_COLUMNS)?;
        let weight = row.optional_number("weight")?.unwrap_or(1.0);
        if weight < 0.0 {
            return Err(row.error(
                Some("weight"),
                format!("weight {weight} is negative (0 reports a fiducial without using it)"),
            ));
        }
        Ok(NamedPoint {
            name: row.id.to_string(),
            position: DVec3::new(x, y, z),
            weight,
        })
    })?
    .collect()
}

/// Writes a fiducials file: `name,x,y,z` (weights are not written).
pub fn write_fiducials<W: Write>(writer: W, points: &[NamedPoint]) -> std::io::Result<()> {
    write_fiducials_with(writer, points, &[], &[])
}

/// Writes a fiducials file `name,x,y,z` with more columns after them: `columns` named, and
/// `cells[k]` the cells of point `k` (read_fiducials reads the file as any other, `weight`
/// included when it is one of them).
pub fn write_fiducials_with<W: Write>(
    writer: W,
    points: &[NamedPoint],
    columns: &[&str],
    cells: &[Vec<String>],
) -> std::io::Result<()> {
    let head: Vec<&str> = ["name", "x", "y", "z"]
        .into_iter()
        .chain(columns.iter().copied())
        .collect();
    write_rows(
        writer,
        &head,
        points.iter().enumerate().map(|(k, p)| {
            std::iter::once(p.name.clone())
                .chain(p.position.to_array().iter().map(|v| v.to_string()))
                .chain(cells.get(k).into_iter().flatten().cloned())
                .collect()
        }),
    )
}
