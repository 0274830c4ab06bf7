//! A user's program as a campaign's instrument: the hook for a tracker's SDK.
//!
//! The contract: for every reading the program is run as
//! `PROGRAM [ARGS…] ID X Y Z A B C READING` — the configuration's id, its commanded pose (mm,
//! degrees, `R = Rz(C)·Ry(B)·Rx(A)`) and the reading's number from 1 — and prints one line on
//! standard output: the measured target points `p1x,p1y,p1z,…,pNx,pNy,pNz` in the instrument's
//! frame (mm; a target not seen as three empty cells), or the platform's pose `x,y,z,a,b,c` from
//! a 6-DoF probe. Exit status 0; anything else, no line, a line of another width, a cell that is
//! not a finite number, or no answer within the timeout is a failed reading (retried by the
//! campaign). Lines after the first and standard error are ignored (standard error is shown).

use std::io::Read;
use std::os::unix::process::CommandExt;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use glam::DVec3;
use hexacomp_core::Pose;
use hexacomp_core::observation::Observation;

use crate::campaign::{Arrival, Instrument};

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

impl CommandInstrument {
    /// Parses the program's line into an observation.
    fn parse(&self, line: &str) -> Result<Observation, String> {
        let cells: Vec<&str> = line.split(',').map(str::trim).collect();
        let expected = if self.probe { 6 } else { 3 * self.targets };
        if cells.len() != expected {
            return Err(format!(
                "the line {line:?} has {} cells, expected {expected} ({})",
                cells.len(),
                if self.probe {
                    "a pose x,y,z,a,b,c".to_string()
                } else {
                    format!("{} targets × x,y,z", self.targets)
                }
            ));
        }
        let number = |text: &str| -> Result<Option<f64>, String> {
            if text.is_empty() {
                return Ok(None);
            }
            text.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .map(Some)
                .ok_or_else(|| format!("{text:?} in the line {line:?} is not a finite number"))
        };
        let values: Vec<Option<f64>> = cells.iter().map(|c| number(c)).collect::<Result<_, _>>()?;
        if self.probe {
            let pose: Option<Vec<f64>> = values.into_iter().collect();
            let pose = pose.ok_or_else(|| format!("the pose line {line:?} has empty cells"))?;
            return Ok(Observation::Pose(std::array::from_fn(|k| pose[k])));
        }
        let targets = values
            .chunks(3)
            .enumerate()
            .map(|(j, xyz)| match (xyz[0], xyz[1], xyz[2]) {
                (Some(x), Some(y), Some(z)) => Ok(Some(DVec3::new(x, y, z))),
                (None, None, None) => Ok(None),
                _ => Err(format!(
                    "target {} of the line {line:?} is partly empty: a target is measured whole \
                     or left empty",
                    j + 1
                )),
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Observation::Targets(targets))
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

impl Instrument for CommandInstrument {
    fn read(
        &mut self,
        id: &str,
        reading: usize,
        pose: &Pose,
        _arrival: &Arrival,
    ) -> Result<Observation, String> {
        let (program, fixed) = self.program.split_first().ok_or("no program given")?;
        // Its own process group: on a timeout the program and whatever it started are killed
        // together (a child left behind would hold our standard error open).
        let mut child = Command::new(program)
            .process_group(0)
            .args(fixed)
            .arg(id)
            .args(pose.to_mm_deg().map(|v| v.to_string()))
            .arg((reading + 1).to_string())
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .map_err(|e| format!("cannot run {program}: {e}"))?;
        let mut stdout = child.stdout.take().expect("stdout piped");
        let reader = std::thread::spawn(move || {
            let mut text = String::new();
            stdout.read_to_string(&mut text).map(|_| text)
        });
        let start = Instant::now();
        let status = loop {
            match child.try_wait() {
                Ok(Some(status)) => break status,
                Ok(None) if start.elapsed() < self.timeout => {
                    std::thread::sleep(Duration::from_millis(5));
                }
                Ok(None) => {
                    kill_group(&child);
                    let _ = child.wait();
                    return Err(format!(
                        "{program} did not answer within {:?} (killed)",
                        self.timeout
                    ));
                }
                Err(e) => return Err(format!("waiting for {program}: {e}")),
            }
        };
        let text = reader
            .join()
            .map_err(|_| format!("reading {program}'s output failed"))?
            .map_err(|e| format!("reading {program}'s output: {e}"))?;
        if !status.success() {
            return Err(format!("{program} exited with {status}"));
        }
        let line = text
            .lines()
            .next()
            .ok_or_else(|| format!("{program} printed no line"))?;
        self.parse(line)
    }
}
