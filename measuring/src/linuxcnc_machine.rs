//! A running LinuxCNC as a campaign's machine, through LinuxCNC's own Python interface (the
//! `linuxcnc` and `hal` modules): a bridge script (`linuxcnc_bridge.py`, embedded here) runs
//! beside the campaign, checks that the machine is on and homed, switches to world coordinates
//! and MDI, and moves to each pose by `G0`, answering with the joint positions (the leg lengths
//! motion commands) and the drives' commands once the joints hold still.
//!
//! Units: mm and degrees (the bridge converts from the machine's units).

use std::io::{BufRead, Write};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::time::Duration;

use hexacomp_core::{Geometry, LEGS, Pose, inverse_kinematics};

use crate::campaign::{Arrival, Machine};
use crate::command_instrument::die_with_parent;
use crate::error::{Error, Result};

/// The bridge script run by `python3 -c`.
const BRIDGE: &str = include_str!("linuxcnc_bridge.py");

/// Largest difference between the legs LinuxCNC commands for a pose and the geometry's inverse
/// kinematics of it, mm, before the two are taken to describe different machines.
pub const LEGS_AGREE_MM: f64 = 1e-3;

/// How to reach LinuxCNC.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LinuxCncOptions {
    /// The Python interpreter that has LinuxCNC's modules (Debian's `/usr/bin/python3`).
    pub python: String,
    /// The HAL pins of the drives' commands, `#` standing for the joint number (the hexacomp
    /// component's `hexacomp.0.motor-out-#`).
    pub drive_pins: String,
    /// Whether the user named `drive_pins`: then pins that cannot be read are an error; the
    /// default falls back to motion's motor commands on a machine without the component.
    pub drive_pins_given: bool,
    /// Longest time a move may take.
    pub move_timeout: Duration,
}

/// LinuxCNC driven through the bridge.
pub struct LinuxCncMachine {
    geometry: Geometry,
    child: Child,
    stdin: Option<ChildStdin>,
    answers: Receiver<std::io::Result<String>>,
    timeout: Duration,
}

/// The bridge's answer to one request, parsed: its fields, or the error it reported.
fn parse(line: &str) -> Result<serde_json::Value> {
    let value: serde_json::Value = serde_json::from_str(line).map_err(|e| Error::BridgeAnswer {
        answer: line.to_string(),
        problem: e.to_string(),
    })?;
    match value.get("error").and_then(|e| e.as_str()) {
        Some(error) => Err(Error::LinuxCncRefused {
            message: error.to_string(),
        }),
        None => Ok(value),
    }
}

/// Six numbers of field `name` of an answer.
fn six(answer: &serde_json::Value, name: &str) -> Result<[f64; LEGS]> {
    let values: Vec<f64> = answer
        .get(name)
        .and_then(|v| v.as_array())
        .map(|a| a.iter().filter_map(|v| v.as_f64()).collect())
        .unwrap_or_default();
    <[f64; LEGS]>::try_from(values.as_slice()).map_err(|_| Error::BridgeAnswer {
        answer: answer.to_string(),
        problem: format!("not six numbers in {name:?}"),
    })
}

impl LinuxCncMachine {
    /// Starts the bridge and waits until LinuxCNC is ready (on, homed, in world mode and MDI);
    /// an error says what is missing (LinuxCNC not running, not homed, switched off).
    pub fn connect(geometry: &Geometry, options: &LinuxCncOptions) -> Result<Self> {
        let mut command = Command::new(&options.python);
        command
            .arg("-u")
            .arg("-c")
            .arg(BRIDGE)
            .arg(&options.drive_pins)
            .arg(if options.drive_pins_given {
                "given"
            } else {
                "default"
            })
            .arg(options.move_timeout.as_secs_f64().to_string())
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit());
        // SIGTERM: the bridge gives LinuxCNC's modes back and leaves HAL before it ends.
        die_with_parent(&mut command, libc::SIGTERM);
        let mut child = command.spawn().map_err(|e| Error::BridgeNotStarted {
            python: options.python.clone(),
            cause: e.to_string(),
        })?;
        let stdout = child.stdout.take().expect("stdout piped");
        let stdin = child.stdin.take();
        let (sender, answers) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            for line in std::io::BufReader::new(stdout).lines() {
                if sender.send(line).is_err() {
                    return;
                }
            }
        });
        let mut machine = Self {
            geometry: geometry.clone(),
            child,
            stdin,
            answers,
            timeout: options.move_timeout,
        };
        let ready = machine.answer(Duration::from_secs(180))?;
        let pins = ready.get("drive_pins").cloned().unwrap_or_default();
        eprintln!("LinuxCNC is ready; the drives' commands are read from {pins}");
        Ok(machine)
    }

    /// The bridge's next answer within `timeout`.
    fn answer(&mut self, timeout: Duration) -> Result<serde_json::Value> {
        match self.answers.recv_timeout(timeout) {
            Ok(Ok(line)) => parse(&line),
            Ok(Err(e)) => Err(Error::BridgeIo {
                what: "reading",
                cause: e.to_string(),
            }),
            Err(RecvTimeoutError::Timeout) => Err(Error::MachineTimeout { timeout }),
            Err(RecvTimeoutError::Disconnected) => {
                let status = self.child.wait().map(|s| s.to_string()).unwrap_or_default();
                Err(Error::BridgeEnded { status })
            }
        }
    }
}

impl Machine for LinuxCncMachine {
    fn go_to(&mut self, id: &str, pose: &Pose) -> Result<Arrival> {
        let request = serde_json::json!({ "move": pose.to_mm_deg() }).to_string() + "\n";
        let stdin = self.stdin.as_mut().ok_or_else(|| Error::BridgeIo {
            what: "writing to",
            cause: "it is closed".into(),
        })?;
        stdin
            .write_all(request.as_bytes())
            .and_then(|()| stdin.flush())
            .map_err(|e| Error::BridgeIo {
                what: "writing to",
                cause: e.to_string(),
            })?;
        let answer = self
            .answer(self.timeout)
            .map_err(|e| Error::AtConfiguration {
                configuration: id.to_string(),
                cause: Box::new(e),
            })?;
        let legs = six(&answer, "legs")?;
        let nominal = inverse_kinematics(&self.geometry, pose).lengths;
        if let Some(leg) = (0..LEGS).find(|&i| (legs[i] - nominal[i]).abs() > LEGS_AGREE_MM) {
            return Err(Error::GeometryNotThisMachine {
                configuration: id.to_string(),
                leg: leg + 1,
                linuxcnc_mm: legs[leg],
                geometry_mm: nominal[leg],
            });
        }
        Ok(Arrival {
            legs,
            drives: six(&answer, "drives")?,
            reached: None,
        })
    }
}

impl Drop for LinuxCncMachine {
    /// Closes the bridge's input (it restores the program units and ends), then waits for it a
    /// moment before killing it.
    fn drop(&mut self) {
        self.stdin = None;
        for _ in 0..100 {
            if let Ok(Some(_)) = self.child.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
