//! Compensating a whole file of points, streamed: rows are read in blocks, compensated and
//! written as they go, so memory does not grow with the file (a CAM post-processor compensating a
//! whole NC program sends files of hundreds of megabytes). The output is written whole or not at
//! all.

use std::path::Path;

use hexacomp_core::compensator::{Compensated, StatusCounts};
use hexacomp_core::durable::NewFile;

use crate::{
    Error, NamedCompensation, Rows, stream_joints, stream_poses, write_compensated_header,
    write_compensated_row,
};

/// A file of points to compensate.
#[derive(Debug, Clone, Copy)]
pub enum PointsFile<'a> {
    /// Poses (`id,x,y,z,a,b,c`, mm and degrees).
    Poses(&'a Path),
    /// Nominal leg lengths (`id,q1..q6`, mm).
    Joints(&'a Path),
}

impl PointsFile<'_> {
    /// The file's path.
    pub fn path(&self) -> &Path {
        match self {
            PointsFile::Poses(path) | PointsFile::Joints(path) => path,
        }
    }
}

/// The rows of either kind of points file, as (id, six numbers).
enum Points {
    Poses(Rows<crate::NamedPose>),
    Joints(Rows<crate::NamedLegs>),
}

impl Points {
    fn next(&mut self) -> Option<crate::Result<(String, [f64; 6])>> {
        match self {
            Points::Poses(rows) => rows
                .next()
                .map(|r| r.map(|(_, pose)| (pose.id, pose.pose_mm_deg))),
            Points::Joints(rows) => rows.next().map(|r| r.map(|(_, legs)| (legs.id, legs.legs))),
        }
    }

    fn bytes_read(&self) -> u64 {
        match self {
            Points::Poses(rows) => rows.bytes_read(),
            Points::Joints(rows) => rows.bytes_read(),
        }
    }
}

/// What [`compensate_file`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FileSummary {
    /// Points written.
    pub points: usize,
    /// Their statuses.
    pub statuses: StatusCounts,
}

/// Reads `input` in blocks of up to `block` rows, has `compensate` turn each block's points
/// (poses in mm and degrees, or legs in mm, as in the file) into one compensated point each, and
/// writes them to `output` as a compensated-output file — whole or not at all: a bad row, a
/// failed `compensate` or a full disk leaves an existing `output` as it was. `progress` is told
/// the bytes of `input` read so far after each block.
pub fn compensate_file<E: From<Error>>(
    input: PointsFile,
    output: &Path,
    block: usize,
    mut compensate: impl FnMut(&[[f64; 6]], &mut Vec<Compensated>) -> Result<(), E>,
    mut progress: impl FnMut(u64),
) -> Result<FileSummary, E> {
    let written = |e: std::io::Error| Error::write(output, e);
    let mut points = match input {
        PointsFile::Poses(path) => Points::Poses(stream_poses(path)?),
        PointsFile::Joints(path) => Points::Joints(stream_joints(path)?),
    };
    let mut file = NewFile::create(output).map_err(written)?;
    let mut csv = write_compensated_header(&mut file).map_err(written)?;
    let mut summary = FileSummary {
        points: 0,
        statuses: StatusCounts::default(),
    };
    let (mut ids, mut values, mut results) = (Vec::new(), Vec::new(), Vec::new());
    loop {
        ids.clear();
        values.clear();
        while ids.len() < block.max(1) {
            match points.next() {
                Some(row) => {
                    let (id, value) = row?;
                    ids.push(id);
                    values.push(value);
                }
                None => break,
            }
        }
        if ids.is_empty() {
            break;
        }
        results.clear();
        compensate(&values, &mut results)?;
        if results.len() != ids.len() {
            return Err(Error::Write {
                file: output.display().to_string(),
                message: format!(
                    "{} points compensated for {} read: nothing written",
                    results.len(),
                    ids.len()
                ),
            }
            .into());
        }
        for (id, point) in ids.drain(..).zip(&results) {
            summary.statuses.add(point.status);
            write_compensated_row(&mut csv, &NamedCompensation { id, point: *point })
                .map_err(written)?;
        }
        summary.points += results.len();
        progress(points.bytes_read());
    }
    csv.flush().map_err(written)?;
    drop(csv);
    file.commit().map_err(written)?;
    Ok(summary)
}

/// A progress bar over the bytes of the file at `path`, with rate and ETA, for
/// [`compensate_file`]'s `progress` (hidden when standard error is not a terminal).
pub fn bytes_progress(path: &Path) -> indicatif::ProgressBar {
    let total = std::fs::metadata(path).map_or(0, |m| m.len());
    let bar = indicatif::ProgressBar::new(total);
    if let Ok(style) = indicatif::ProgressStyle::with_template(
        "{msg} [{bar:30}] {bytes}/{total_bytes} ({bytes_per_sec}, ETA {eta})",
    ) {
        bar.set_style(style.progress_chars("=> "));
    }
    bar.set_message(path.display().to_string());
    bar
}
