//! The operator as machine and instrument: the campaign shows each pose on standard error and
//! waits for the operator (or another controller) to confirm it on standard input; the operator
//! types or pastes each reading as the instrument's software shows it.
//!
//! Units: mm and degrees; readings in the instrument's frame.

use std::io::BufRead;

use glam::DVec3;

use hexacomp_core::observation::Observation;
use hexacomp_core::{Geometry, Pose, inverse_kinematics};

use crate::campaign::{Arrival, Instrument, Machine, ReadError};
use crate::command_instrument::{LineError, parse_point, parse_reading};
use crate::error::{Error, Result};

/// One line of standard input without its line end; `None` at the end of the input.
fn read_line() -> std::io::Result<Option<String>> {
    let mut line = String::new();
    let read = std::io::stdin().lock().read_line(&mut line)?;
    Ok((read > 0).then(|| line.trim_end_matches(['\n', '\r']).to_string()))
}

/// A machine moved by hand or by another controller: each pose is shown with its nominal legs,
/// and an empty line (Enter) confirms the machine is there and settled; `stop` stops the campaign.
#[derive(Debug, Clone)]
pub struct ManualMachine {
    /// The geometry whose inverse kinematics give the legs shown and recorded.
    pub geometry: Geometry,
}

impl Machine for ManualMachine {
    fn go_to(&mut self, id: &str, pose: &Pose) -> Result<Arrival> {
        let legs = inverse_kinematics(&self.geometry, pose).lengths;
        let shown = pose.to_mm_deg().map(|v| format!("{v:.4}")).join(" ");
        let lengths = legs.map(|q| format!("{q:.4}")).join(" ");
        eprintln!(
            "move to configuration {id}: x y z a b c = {shown} (legs {lengths} mm), then press \
             Enter (stop: end the campaign)"
        );
        loop {
            match read_line() {
                Ok(Some(line)) if line.trim().is_empty() => {
                    return Ok(Arrival {
                        legs,
                        drives: legs,
                        reached: None,
                    });
                }
                Ok(Some(line)) if line.trim() == "stop" => {
                    return Err(Error::StoppedByOperator);
                }
                // Asked again: a line typed here (a reading pasted too early) confirms nothing.
                Ok(Some(line)) => eprintln!(
                    "{line:?} is no confirmation: press Enter once the machine stands at \
                     configuration {id} (stop: end the campaign)"
                ),
                Ok(None) => {
                    return Err(Error::ConfirmationMissing {
                        configuration: id.to_string(),
                        problem: "the input ended".into(),
                    });
                }
                Err(e) => {
                    return Err(Error::ConfirmationMissing {
                        configuration: id.to_string(),
                        problem: format!("reading the confirmation failed ({e})"),
                    });
                }
            }
        }
    }
}

/// Asks the operator for a reading with `prompt` until a line `parse` accepts: a line it refuses
/// is named with its cause and asked again at no cost; an empty line is a failed reading;
/// `stop` or the end of the input stops the campaign.
fn ask_reading<T>(
    prompt: &str,
    parse: impl Fn(&str) -> std::result::Result<T, LineError>,
) -> std::result::Result<T, ReadError> {
    loop {
        eprintln!("{prompt}");
        match read_line() {
            Ok(Some(line)) if line.trim().is_empty() => {
                return Err(ReadError::Failed("no reading given".into()));
            }
            Ok(Some(line)) if line.trim() == "stop" => {
                return Err(ReadError::Broken("stopped by the operator".into()));
            }
            Ok(Some(line)) => match parse(line.trim()) {
                Ok(value) => return Ok(value),
                // Asked again: a typing mistake costs no attempt.
                Err(why) => eprintln!("not a reading: {why}"),
            },
            Ok(None) => return Err(ReadError::Broken("the input ended".into())),
            Err(e) => return Err(ReadError::Broken(format!("reading the input: {e}"))),
        }
    }
}

/// An instrument read by the operator: each reading is typed or pasted as one CSV line, the
/// targets `p1x..pNz` in the instrument's frame (three empty cells for a target not seen) or,
/// as a probe, the pose `x,y,z,a,b,c`. A line that does not parse is named with its cause and
/// asked again; an empty line is a failed reading (retried, then lost); `stop` or the end of the
/// input ends the campaign.
#[derive(Debug, Clone, Copy)]
pub struct ManualInstrument {
    /// How many targets the geometry names.
    pub targets: usize,
    /// The operator reads a pose instead of targets.
    pub probe: bool,
}

impl Instrument for ManualInstrument {
    fn read(
        &mut self,
        id: &str,
        reading: usize,
        _pose_mm_deg: &[f64; 6],
        _arrival: &Arrival,
    ) -> std::result::Result<Observation, ReadError> {
        let what = if self.probe {
            "the pose x,y,z,a,b,c (mm, degrees)".to_string()
        } else {
            format!("the targets p1x..p{}z (mm)", self.targets)
        };
        let prompt = format!(
            "configuration {id}, reading {}: type or paste {what} and press Enter (empty: no \
             reading; stop: end the campaign)",
            reading + 1
        );
        let (targets, probe) = (self.targets, self.probe);
        ask_reading(&prompt, |line| parse_reading(line, targets, probe))
    }

    fn read_fiducial(
        &mut self,
        name: &str,
        reading: usize,
        nominal_mm: DVec3,
    ) -> std::result::Result<DVec3, ReadError> {
        let [x, y, z] = nominal_mm.to_array().map(|v| format!("{v:.3}"));
        let prompt = format!(
            "fiducial {name} (nominal {x} {y} {z} mm on the base), reading {}: type or paste the \
             point x,y,z (mm, the instrument's frame) and press Enter (empty: no reading; stop: \
             end the campaign)",
            reading + 1
        );
        ask_reading(&prompt, parse_point)
    }
}
