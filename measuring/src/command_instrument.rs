//! A user's program as a campaign's instrument: the hook for a tracker's SDK.
//!
//! The contract: for every reading the program is run as
//! `PROGRAM [ARGS…] ID X Y Z A B C READING` — the configuration's id (`R1`, `R2`… for the
//! reference configuration the campaign watches for drift), its commanded pose (mm,
//! degrees, `R = Rz(C)·Ry(B)·Rx(A)`) and the reading's number from 1 — and prints one line on
//! standard output: the measured target points `p1x,p1y,p1z,…,pNx,pNy,pNz` in the instrument's
//! frame (mm; a target not seen as three empty cells), or the platform's pose `x,y,z,a,b,c` from
//! a 6-DoF probe. At the end of a campaign under a registration, each fiducial is read as
//! `PROGRAM [ARGS…] --fiducial NAME X Y Z READING` (its nominal position in the base frame, mm),
//! and the program prints the point `x,y,z` it measured there (the instrument's frame, mm).
//! Exit status 0; anything else, no line, a line of another width, a cell that is
//! not a number (or beyond 1e9 mm), or no answer within the timeout is a failed reading (retried
//! by the campaign); a program that cannot be started stops the campaign. Lines after the first
//! are ignored, standard error is shown. The program runs in its own process group, killed whole
//! on a timeout, and is killed when the campaign dies.

use std::io::Read;
use std::os::unix::process::CommandExt;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use glam::DVec3;
use hexacomp_core::observation::Observation;

use crate::campaign::{Arrival, Instrument, ReadError};

/// A user's program that reads the instrument.
#[derive(Debug, Clone)]
pub struct CommandInstrument {
    /// The program and its fixed arguments.
    pub program: Vec<String>,
    /// How many targets the geometry names (a line has three cells per target).
    pub targets: usize,
    /// The program reports a pose (six cells) instead of targets.
    pub probe: bool,
    /// How long one reading may take before the program is killed.
    pub timeout: Duration,
}

/// Why an instrument's line is not a reading.
#[derive(Debug, Clone, PartialEq)]
pub enum LineError {
    /// Another number of cells than the reading has.
    Width {
        /// The line.
        line: String,
        /// Its cells.
        cells: usize,
        /// The cells expected.
        expected: usize,
        /// What they hold ("a pose x,y,z,a,b,c", "3 targets × x,y,z").
        holding: String,
    },
    /// A cell that is not a finite number of at most 10⁹ mm (1000 km) in size.
    NotANumber {
        /// The cell.
        cell: String,
        /// The line.
        line: String,
    },
    /// A probe's pose with empty cells.
    PoseCellsEmpty {
        /// The line.
        line: String,
    },
    /// A target measured in part: a target is measured whole or left empty.
    TargetPartlyEmpty {
        /// The target, from 1.
        target: usize,
        /// The line.
        line: String,
    },
    /// A fiducial's line that is empty: the fiducial was not seen.
    FiducialNotSeen {
        /// The line.
        line: String,
    },
}

impl std::fmt::Display for LineError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Width {
                line,
                cells,
                expected,
                holding,
            } => write!(
                f,
                "the line {line:?} has {cells} cells, expected {expected} ({holding})"
            ),
            Self::NotANumber { cell, line } => write!(
                f,
                "{cell:?} in the line {line:?} is not a number of at most {MAX_COORDINATE_MM:e} \
                 in size"
            ),
            Self::PoseCellsEmpty { line } => write!(f, "the pose line {line:?} has empty cells"),
            Self::TargetPartlyEmpty { target, line } => write!(
                f,
                "target {target} of the line {line:?} is partly empty: a target is measured \
                 whole or left empty"
            ),
            Self::FiducialNotSeen { line } => {
                write!(f, "the line {line:?} is empty: the fiducial was not seen")
            }
        }
    }
}

impl From<LineError> for ReadError {
    /// A line that is not a reading is a failed reading: retried.
    fn from(e: LineError) -> Self {
        ReadError::Failed(e.to_string())
    }
}

/// Parses an instrument's line (a program's or an operator's): `targets` points `p1x..pNz` in the
/// instrument's frame (three empty cells for a target not seen), or with `probe` a pose
/// `x,y,z,a,b,c` (mm, degrees); numbers beyond [`MAX_COORDINATE_MM`] are refused.
pub(crate) fn parse_reading(
    line: &str,
    targets: usize,
    probe: bool,
) -> Result<Observation, LineError> {
    let cells: Vec<&str> = line.split(',').map(str::trim).collect();
    let expected = if probe { 6 } else { 3 * targets };
    if cells.len() != expected {
        return Err(LineError::Width {
            line: line.to_string(),
            cells: cells.len(),
            expected,
            holding: if probe {
                "a pose x,y,z,a,b,c".to_string()
            } else {
                format!("{targets} targets × x,y,z")
            },
        });
    }
    let number = |text: &str| -> Result<Option<f64>, LineError> {
        if text.is_empty() {
            return Ok(None);
        }
        text.parse::<f64>()
            .ok()
            .filter(|v| v.is_finite() && v.abs() <= MAX_COORDINATE_MM)
            .map(Some)
            .ok_or_else(|| LineError::NotANumber {
                cell: text.to_string(),
                line: line.to_string(),
            })
    };
    let values: Vec<Option<f64>> = cells.iter().map(|c| number(c)).collect::<Result<_, _>>()?;
    if probe {
        let pose: Option<Vec<f64>> = values.into_iter().collect();
        let pose = pose.ok_or_else(|| LineError::PoseCellsEmpty {
            line: line.to_string(),
        })?;
        return Ok(Observation::Pose(std::array::from_fn(|k| pose[k])));
    }
    let targets = values
        .chunks(3)
        .enumerate()
        .map(|(j, xyz)| match (xyz[0], xyz[1], xyz[2]) {
            (Some(x), Some(y), Some(z)) => Ok(Some(DVec3::new(x, y, z))),
            (None, None, None) => Ok(None),
            _ => Err(LineError::TargetPartlyEmpty {
                target: j + 1,
                line: line.to_string(),
            }),
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok(Observation::Targets(targets))
}

/// Has the kernel send `signal` to the program `command` starts when this process dies (any
/// death: Ctrl-C, SIGKILL, a crash), so that no instrument or machine bridge outlives the
/// campaign. A parent that died before the request took effect is caught too: the program then
/// has another parent, and fails to start.
pub(crate) fn die_with_parent(command: &mut Command, signal: libc::c_int) {
    // SAFETY: getpid(2) is async-signal-safe; called before the fork, in the parent.
    let parent = unsafe { libc::getpid() };
    // SAFETY: between fork and exec the closure only calls prctl(2) and getppid(2), which are
    // async-signal-safe.
    unsafe {
        command.pre_exec(move || {
            if libc::prctl(libc::PR_SET_PDEATHSIG, signal) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            if libc::getppid() != parent {
                return Err(std::io::Error::other(
                    "the campaign ended before it started",
                ));
            }
            Ok(())
        });
    }
}

/// Kills the process group `child` leads (its own, from `process_group(0)`).
fn kill_group(child: &Child) {
    if let Ok(group) = libc::pid_t::try_from(child.id()) {
        // SAFETY: killpg(2) on the group our child leads; the child has not been reaped (the
        // caller still holds it), so its pid, and the group id, cannot have been reused.
        unsafe {
            libc::killpg(group, libc::SIGKILL);
        }
    }
}

/// The most a program may print for one reading; the rest is read and dropped.
const MAX_OUTPUT_BYTES: u64 = 1 << 20;

/// The largest magnitude a coordinate may have, mm (1000 km): beyond it, a sentinel or garbage.
const MAX_COORDINATE_MM: f64 = 1e9;

impl Instrument for CommandInstrument {
    fn read(
        &mut self,
        id: &str,
        reading: usize,
        pose_mm_deg: &[f64; 6],
        _arrival: &Arrival,
    ) -> Result<Observation, ReadError> {
        let arguments: Vec<String> = std::iter::once(id.to_string())
            .chain(pose_mm_deg.map(|v| v.to_string()))
            .chain([(reading + 1).to_string()])
            .collect();
        let line = first_line(&self.program, &arguments, self.timeout)?;
        parse_reading(&line, self.targets, self.probe).map_err(ReadError::from)
    }

    fn read_fiducial(
        &mut self,
        name: &str,
        reading: usize,
        nominal_mm: DVec3,
    ) -> Result<DVec3, ReadError> {
        let arguments: Vec<String> = ["--fiducial".to_string(), name.to_string()]
            .into_iter()
            .chain(nominal_mm.to_array().map(|v| v.to_string()))
            .chain([(reading + 1).to_string()])
            .collect();
        let line = first_line(&self.program, &arguments, self.timeout)?;
        parse_point(&line).map_err(ReadError::from)
    }
}

/// Parses a fiducial's reading `x,y,z` (mm, the instrument's frame).
pub(crate) fn parse_point(line: &str) -> Result<DVec3, LineError> {
    match parse_reading(line, 1, false)? {
        Observation::Targets(points) => match points.as_slice() {
            [Some(point)] => Ok(*point),
            _ => Err(LineError::FiducialNotSeen {
                line: line.to_string(),
            }),
        },
        // A reading of one target without the probe is targets.
        _ => unreachable!("parse_reading without the probe gives targets"),
    }
}

/// Runs `program` (the program and its fixed arguments) with `arguments` and returns the first
/// line it prints, within `timeout`. The program runs in its own process group, killed whole on
/// a timeout, and is killed when this process dies; at most 1 MiB of its output is read; its
/// standard error is shown. A program that cannot be started is [`ReadError::Broken`]; a
/// timeout, an exit status other than 0, no line or a line that is not text is
/// [`ReadError::Failed`].
pub fn first_line(
    program: &[String],
    arguments: &[String],
    timeout: Duration,
) -> Result<String, ReadError> {
    let (program, fixed) = program
        .split_first()
        .ok_or_else(|| ReadError::Broken("no program given".into()))?;
    let mut command = Command::new(program);
    // Its own process group: on a timeout the program and whatever it started are killed
    // together (a child left behind would hold our standard error open).
    command
        .process_group(0)
        .args(fixed)
        .args(arguments)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit());
    // Killed when the campaign dies (Ctrl-C, SIGKILL), so it does not keep the tracker busy.
    die_with_parent(&mut command, libc::SIGKILL);
    let mut child = command.spawn().map_err(|e| {
        ReadError::Broken(format!(
            "cannot run {program}: {e} (is the path right, the file executable, with a \
                 #! line?)"
        ))
    })?;
    let stdout = child.stdout.take().expect("stdout piped");
    let (sender, receiver) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let mut bytes = Vec::new();
        let mut limited = stdout.take(MAX_OUTPUT_BYTES);
        let result = limited.read_to_end(&mut bytes).map(|_| bytes);
        // Whatever is printed beyond the limit is read and dropped.
        let _ = std::io::copy(&mut limited.into_inner(), &mut std::io::sink());
        let _ = sender.send(result);
    });
    let deadline = Instant::now() + timeout;
    let timed_out = |child: &mut Child| {
        kill_group(child);
        let _ = child.wait();
        ReadError::Failed(format!(
            "{program} did not answer within {timeout:?} (killed with what it started)"
        ))
    };
    let status = loop {
        match child.try_wait() {
            Ok(Some(status)) => break status,
            Ok(None) if Instant::now() < deadline => {
                std::thread::sleep(Duration::from_millis(5));
            }
            Ok(None) => return Err(timed_out(&mut child)),
            Err(e) => {
                kill_group(&child);
                let _ = child.wait();
                return Err(ReadError::Failed(format!("waiting for {program}: {e}")));
            }
        }
    };
    // A program that exited but left something holding its output open gets the rest of
    // the time, then its group is killed.
    let left = deadline.saturating_duration_since(Instant::now());
    let bytes = match receiver.recv_timeout(left) {
        Ok(result) => {
            result.map_err(|e| ReadError::Failed(format!("reading {program}'s output: {e}")))?
        }
        Err(_) => return Err(timed_out(&mut child)),
    };
    if !status.success() {
        return Err(ReadError::Failed(format!("{program} exited with {status}")));
    }
    if bytes.is_empty() {
        return Err(ReadError::Failed(format!("{program} printed no line")));
    }
    let first = bytes.split(|b| *b == b'\n').next().unwrap_or_default();
    let line = std::str::from_utf8(first)
        .map_err(|_| ReadError::Failed(format!("{program}'s first line is not UTF-8 text")))?
        .trim_end_matches('\r');
    Ok(line.to_string())
}
