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
    write_rows(
        writer,
        &["name", "x", "y", "z"],
        points.iter().map(|p| {
            std::iter::once(p.name.clone())
                .chain(p.position.to_array().iter().map(|v| v.to_string()))
                .collect()
        }),
    )
}
