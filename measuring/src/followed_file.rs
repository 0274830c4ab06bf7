//! A file that the tracker's software appends its readings to, followed as a campaign's
//! instrument: each reading is the next complete line appended after the machine arrived.
//!
//! The lines are those of the command instrument ([`crate::command_instrument`]): the targets
//! `p1x..pNz` (three empty cells for a target not seen) or a probe's pose `x,y,z,a,b,c` in the
//! instrument's frame (mm, degrees), and a fiducial's point `x,y,z`. Empty lines and lines
//! beginning with `#` are skipped. Lines appended before the machine stood at a configuration
//! (while it moved) belong to no reading of it and are skipped, and said so.
//!
//! Units: mm and degrees, the instrument's frame.

use std::io::{Read, Seek, SeekFrom};
use std::path::PathBuf;
use std::time::{Duration, Instant};

use glam::DVec3;
use hexacomp_core::observation::Observation;
use hexacomp_formats::file_identity;

use crate::campaign::{Arrival, Instrument, ReadError};
use crate::command_instrument::{LineError, parse_point, parse_reading};

/// How often the file is looked at while waiting for a line.
const POLL: Duration = Duration::from_millis(50);

/// The longest line accepted, bytes: beyond it the file is not a readings export.
const MAX_LINE_BYTES: u64 = 1 << 16;

/// A file followed for readings.
#[derive(Debug)]
pub struct FollowedFile {
    /// The file the tracker's software appends to.
    path: PathBuf,
    /// How many targets the geometry names (a line has three cells per target).
    targets: usize,
    /// The lines are a probe's poses instead of targets.
    probe: bool,
    /// How long one reading may take to appear.
    timeout: Duration,
    /// Bytes of the file consumed: the next reading starts here.
    offset: u64,
    /// Lines of the file consumed (the next line's number is one more).
    lines: u64,
    /// The file's device and inode once it exists: another file in its place is refused.
    identity: Option<(u64, u64)>,
    /// What the last reading was of (a configuration's id, a fiducial's name).
    last_subject: Option<String>,
    /// A line was being written when the readings of a subject began: once whole, it is
    /// skipped (it was measured before).
    skip_partial: bool,
}

impl FollowedFile {
    /// Follows `path` from its current end (lines already in it are no readings of this run; a
    /// file that does not exist yet is followed from its first line once it appears).
    pub fn open(
        path: PathBuf,
        targets: usize,
        probe: bool,
        timeout: Duration,
    ) -> std::io::Result<Self> {
        let mut followed = Self {
            path,
            targets,
            probe,
            timeout,
            offset: 0,
            lines: 0,
            identity: None,
            last_subject: None,
            skip_partial: false,
        };
        if let Some(file) = followed.current()? {
            followed.identity = Some(file_identity(&file.metadata()?));
            let skipped = followed.skip_to_end(file)?;
            if skipped > 0 {
                eprintln!(
                    "{}: skipped the {skipped} lines already in it (readings of an earlier \
                     session)",
                    followed.path.display()
                );
            }
        }
        Ok(followed)
    }

    /// An error reading the file: the campaign cannot go on following it.
    fn broken(&self, e: std::io::Error) -> ReadError {
        ReadError::Broken(format!("following {}: {e}", self.path.display()))
    }

    /// The file as it is now, `None` while it does not exist.
    fn current(&self) -> std::io::Result<Option<std::fs::File>> {
        match std::fs::File::open(&self.path) {
            Ok(file) => Ok(Some(file)),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(e) => Err(e),
        }
    }

    /// Consumes every complete line appended so far, and marks a line still being written to be
    /// skipped once whole; returns how many complete lines were not empty.
    fn skip_to_end(&mut self, mut file: std::fs::File) -> std::io::Result<u64> {
        file.seek(SeekFrom::Start(self.offset))?;
        let mut rest = Vec::new();
        file.read_to_end(&mut rest)?;
        let complete = rest.iter().rposition(|b| *b == b'\n').map_or(0, |k| k + 1);
        self.skip_partial = complete < rest.len();
        let skipped = rest[..complete]
            .split(|b| *b == b'\n')
            .filter(|line| !line.trim_ascii().is_empty())
            .count() as u64;
        self.lines += rest[..complete].iter().filter(|b| **b == b'\n').count() as u64;
        self.offset += complete as u64;
        Ok(skipped)
    }

    /// The file, refused when another file took its place or it was cut shorter than what was
    /// consumed (the readings already taken could not be told from new ones).
    fn checked(&mut self) -> Result<Option<std::fs::File>, ReadError> {
        let Some(file) = self.current().map_err(|e| self.broken(e))? else {
            return match self.identity {
                Some(_) => Err(ReadError::Broken(format!(
                    "{} was removed while it was followed",
                    self.path.display()
                ))),
                None => Ok(None),
            };
        };
        let metadata = file.metadata().map_err(|e| self.broken(e))?;
        let now = file_identity(&metadata);
        if *self.identity.get_or_insert(now) != now || metadata.len() < self.offset {
            return Err(ReadError::Broken(format!(
                "{} was replaced or cut short while it was followed (its software must append \
                 to it): the readings taken cannot be told from new ones; start the run again",
                self.path.display()
            )));
        }
        Ok(Some(file))
    }

    /// Starts the readings of `subject` (a configuration, a fiducial): lines appended before it
    /// are skipped, and said so.
    fn begin(&mut self, subject: &str) -> Result<(), ReadError> {
        if self.last_subject.as_deref() == Some(subject) {
            return Ok(());
        }
        self.last_subject = Some(subject.to_string());
        if let Some(file) = self.checked()? {
            let skipped = self.skip_to_end(file).map_err(|e| self.broken(e))?;
            if skipped > 0 {
                eprintln!(
                    "{}: skipped {skipped} line{} appended before {subject} stood still",
                    self.path.display(),
                    if skipped == 1 { "" } else { "s" }
                );
            }
        }
        Ok(())
    }

    /// The next complete line that is not empty or a comment, and its number; a failed reading
    /// when none comes within the timeout.
    fn next_line(&mut self) -> Result<(u64, String), ReadError> {
        let deadline = Instant::now() + self.timeout;
        loop {
            if let Some(mut file) = self.checked()? {
                file.seek(SeekFrom::Start(self.offset))
                    .map_err(|e| self.broken(e))?;
                let mut rest = Vec::new();
                file.take(MAX_LINE_BYTES)
                    .read_to_end(&mut rest)
                    .map_err(|e| self.broken(e))?;
                match rest.iter().position(|b| *b == b'\n') {
                    Some(end) => {
                        self.offset += end as u64 + 1;
                        self.lines += 1;
                        let line = std::str::from_utf8(&rest[..end])
                            .map_err(|_| {
                                ReadError::Failed(format!(
                                    "{}:{}: the line is not UTF-8 text",
                                    self.path.display(),
                                    self.lines
                                ))
                            })?
                            .trim();
                        if std::mem::take(&mut self.skip_partial) {
                            eprintln!(
                                "{}:{}: skipped, being written before the readings began",
                                self.path.display(),
                                self.lines
                            );
                            continue;
                        }
                        if line.is_empty() || line.starts_with('#') {
                            continue;
                        }
                        return Ok((self.lines, line.to_string()));
                    }
                    None if rest.len() as u64 >= MAX_LINE_BYTES => {
                        return Err(ReadError::Broken(format!(
                            "{}:{}: a line longer than {MAX_LINE_BYTES} bytes: not a readings \
                             file",
                            self.path.display(),
                            self.lines + 1
                        )));
                    }
                    None => {}
                }
            }
            if Instant::now() >= deadline {
                return Err(ReadError::Failed(format!(
                    "no line was appended to {} within {:?}",
                    self.path.display(),
                    self.timeout
                )));
            }
            std::thread::sleep(POLL);
        }
    }

    /// Waits for the next line of `subject`'s reading number `reading` (0-based), announcing it,
    /// and parses it with `parse`.
    fn take<T>(
        &mut self,
        subject: &str,
        reading: usize,
        what: &str,
        parse: impl Fn(&str) -> Result<T, LineError>,
    ) -> Result<T, ReadError> {
        self.begin(subject)?;
        eprintln!(
            "{subject}, reading {}: measure {what}; waiting up to {:?} for its line in {}",
            reading + 1,
            self.timeout,
            self.path.display()
        );
        let (number, line) = self.next_line()?;
        parse(&line)
            .map_err(|why| ReadError::Failed(format!("{}:{number}: {why}", self.path.display())))
    }
}

impl Instrument for FollowedFile {
    fn read(
        &mut self,
        id: &str,
        reading: usize,
        _pose_mm_deg: &[f64; 6],
        _arrival: &Arrival,
    ) -> Result<Observation, ReadError> {
        let what = if self.probe {
            "the pose".to_string()
        } else {
            format!("the {} targets", self.targets)
        };
        let (targets, probe) = (self.targets, self.probe);
        self.take(&format!("configuration {id}"), reading, &what, |line| {
            parse_reading(line, targets, probe)
        })
    }

    fn read_fiducial(
        &mut self,
        name: &str,
        reading: usize,
        _nominal_mm: DVec3,
    ) -> Result<DVec3, ReadError> {
        self.take(
            &format!("fiducial {name}"),
            reading,
            "the point",
            parse_point,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    fn append(path: &std::path::Path, text: &str) {
        std::fs::OpenOptions::new()
            .append(true)
            .create(true)
            .open(path)
            .unwrap()
            .write_all(text.as_bytes())
            .unwrap();
    }

    #[test]
    fn a_file_cut_short_or_replaced_while_followed_is_refused_and_a_missing_line_fails_the_reading()
    {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("export.txt");
        // Not there yet: followed from its first line once it appears.
        let mut followed = FollowedFile::open(path.clone(), 1, false, POLL).unwrap();
        // Lines appended once the fiducial's readings began are its readings.
        followed.begin("fiducial F1").unwrap();
        append(&path, "# the software's header\n1,2,3\n");
        assert_eq!(
            followed.read_fiducial("F1", 0, DVec3::ZERO),
            Ok(DVec3::new(1.0, 2.0, 3.0))
        );
        let missing = followed.read_fiducial("F1", 1, DVec3::ZERO);
        assert!(
            matches!(&missing, Err(ReadError::Failed(why)) if why.contains("no line was appended")),
            "{missing:?}"
        );
        // Cut short: the readings taken could no longer be told from new ones.
        std::fs::write(&path, "").unwrap();
        let cut = followed.read_fiducial("F1", 1, DVec3::ZERO);
        assert!(
            matches!(&cut, Err(ReadError::Broken(why)) if why.contains("cut short")),
            "{cut:?}"
        );
        // Replaced by another file, even a longer one.
        let mut followed = FollowedFile::open(path.clone(), 1, false, POLL).unwrap();
        let other = dir.path().join("other.txt");
        std::fs::write(&other, "4,5,6\n7,8,9\n").unwrap();
        std::fs::rename(&other, &path).unwrap();
        let replaced = followed.read_fiducial("F2", 0, DVec3::ZERO);
        assert!(
            matches!(&replaced, Err(ReadError::Broken(why)) if why.contains("replaced")),
            "{replaced:?}"
        );
    }
}
