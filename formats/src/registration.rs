//! The registration file (TOML): where an instrument stood in the machine's base frame, as
//! `hexacomp-trainer register` located it from fiducials, with the inputs, residuals and time
//! that prove it.

use std::path::Path;

use glam::DVec3;
use hexacomp_core::Pose;
use hexacomp_core::rigid_fit::{Locked, PARAMETER_NAMES};
use serde::{Deserialize, Serialize};

use crate::{Error, Result};

/// The format version this build writes and reads.
pub const REGISTRATION_FORMAT: u32 = 1;

/// The first line of every registration file.
pub const REGISTRATION_FIRST_LINE: &str =
    "# hexacomp registration: the instrument's frame located in the machine's base frame";

/// A registration: the instrument's pose in the base frame and the fit that found it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RegistrationFile {
    /// The format version ([`REGISTRATION_FORMAT`]).
    pub format: u32,
    /// When the registration was made, RFC 3339 UTC.
    pub created: String,
    /// The nominal fiducials file (base frame), as given.
    pub nominal: String,
    /// The measured fiducials file (instrument frame), as given.
    pub measured: String,
    /// The instrument's pose in the base frame `[x, y, z, a, b, c]`, mm and degrees, in the
    /// convention of every pose (`R = Rz(c)·Ry(b)·Rx(a)`): a point the instrument reports at
    /// `p` is at `t + R·p` in the base frame.
    pub instrument_pose: [f64; 6],
    /// The parameters held at zero in the fit (names of `instrument_pose`'s components).
    pub locked: Vec<String>,
    /// The largest residual the registration accepted, mm.
    pub tolerance_mm: f64,
    /// Root mean square of the residuals of the fiducials of positive weight, mm.
    pub rms_mm: f64,
    /// Largest residual of a fiducial of positive weight, mm.
    pub max_mm: f64,
    /// The instrument's stated accuracy `[A, B]`: MPE `A µm + B µm/m`, when the user gave it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub instrument_mpe_um: Option<[f64; 2]>,
    /// What the instrument and this registration can support at the platform: a measured target
    /// point in the base frame to within this, mm (2σ, 3D), when the MPE was given.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub supported_mm: Option<f64>,
    /// Every fiducial matched by name, in the nominal file's order.
    pub fiducials: Vec<RegisteredFiducial>,
}

/// One fiducial of a registration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RegisteredFiducial {
    /// Its name in both files.
    pub name: String,
    /// Nominal position, base frame, mm.
    pub nominal: [f64; 3],
    /// Measured position, instrument frame, mm.
    pub measured: [f64; 3],
    /// Its weight in the fit (0: reported, not used).
    pub weight: f64,
    /// The measured position brought into the base frame minus the nominal one, mm.
    pub residual: [f64; 3],
}

impl RegisteredFiducial {
    /// The length of the residual, mm.
    pub fn residual_mm(&self) -> f64 {
        DVec3::from_array(self.residual).length()
    }
}

impl RegistrationFile {
    /// The instrument's pose in the base frame (mm, rad).
    pub fn instrument_pose(&self) -> Pose {
        Pose::from_mm_deg(self.instrument_pose)
    }

    /// The locked parameters.
    pub fn locked(&self) -> Locked {
        Locked::from_names(self.locked.iter().map(String::as_str)).unwrap_or_default()
    }

    /// The file's text: a first comment line, then the TOML.
    pub fn to_toml_string(&self) -> String {
        let body = toml::to_string(self).expect("a registration always serialises to TOML");
        format!("{REGISTRATION_FIRST_LINE}\n{body}")
    }

    /// Checks what a file may hold: this format version, finite numbers, known locked names,
    /// fiducials named once with weights ≥ 0, three or more of them used, and residuals that are
    /// what `instrument_pose` gives (within 1e-6 mm): a pose edited by hand is refused.
    fn validate(&self) -> std::result::Result<(), RegistrationProblem> {
        if self.format != REGISTRATION_FORMAT {
            return Err(RegistrationProblem::Version { found: self.format });
        }
        if !self.instrument_pose.iter().all(|v| v.is_finite()) {
            return Err(RegistrationProblem::NotFinite {
                what: "instrument_pose has a number",
            });
        }
        if let Some(name) = self
            .locked
            .iter()
            .find(|name| !PARAMETER_NAMES.contains(&name.as_str()))
        {
            return Err(RegistrationProblem::UnknownLocked { name: name.clone() });
        }
        if self.fiducials.len() < 3 {
            return Err(RegistrationProblem::TooFewFiducials {
                count: self.fiducials.len(),
                of_positive_weight: false,
            });
        }
        let numbers = [self.tolerance_mm, self.rms_mm, self.max_mm]
            .into_iter()
            .chain(self.instrument_mpe_um.into_iter().flatten())
            .chain(self.supported_mm)
            .chain(self.fiducials.iter().flat_map(|f| {
                f.nominal
                    .into_iter()
                    .chain(f.measured)
                    .chain(f.residual)
                    .chain([f.weight])
            }));
        if numbers.into_iter().any(|v| !v.is_finite()) {
            return Err(RegistrationProblem::NotFinite { what: "a number" });
        }
        for (k, f) in self.fiducials.iter().enumerate() {
            if self.fiducials[..k].iter().any(|g| g.name == f.name) {
                return Err(RegistrationProblem::DuplicateFiducial {
                    name: f.name.clone(),
                });
            }
            if f.weight < 0.0 {
                return Err(RegistrationProblem::NegativeWeight {
                    name: f.name.clone(),
                    weight: f.weight,
                });
            }
        }
        let used = self.fiducials.iter().filter(|f| f.weight > 0.0).count();
        if used < 3 {
            return Err(RegistrationProblem::TooFewFiducials {
                count: used,
                of_positive_weight: true,
            });
        }
        let pose = self.instrument_pose();
        for f in &self.fiducials {
            let residual =
                pose.transform_point(DVec3::from_array(f.measured)) - DVec3::from_array(f.nominal);
            let gap = (residual - DVec3::from_array(f.residual)).length();
            if gap > 1e-6 {
                return Err(RegistrationProblem::ResidualMismatch {
                    name: f.name.clone(),
                    gap_mm: gap,
                });
            }
        }
        Ok(())
    }
}

/// What is wrong with a registration file's contents ([`RegistrationFile`]'s checks).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RegistrationProblem {
    /// Another format version than this build reads.
    #[error("format version {found}, this build reads version {REGISTRATION_FORMAT}")]
    Version {
        /// The version the file holds.
        found: u32,
    },
    /// A number that is not finite.
    #[error("{what} that is not finite")]
    NotFinite {
        /// Where ("instrument_pose has a number").
        what: &'static str,
    },
    /// A locked parameter name that is not one of the registration's.
    #[error("locked names {name:?}, not one of {}", PARAMETER_NAMES.join(", "))]
    UnknownLocked {
        /// The name.
        name: String,
    },
    /// Fewer than three fiducials (of positive weight, where so said).
    #[error(
        "{count} fiducials{}: a registration {} at least three",
        if *of_positive_weight { " of positive weight" } else { "" },
        if *of_positive_weight { "uses" } else { "has" }
    )]
    TooFewFiducials {
        /// How many there are.
        count: usize,
        /// Whether only those of positive weight were counted.
        of_positive_weight: bool,
    },
    /// A fiducial named twice.
    #[error("fiducial {name:?} appears twice")]
    DuplicateFiducial {
        /// Its name.
        name: String,
    },
    /// A negative weight.
    #[error("fiducial {name:?} has the negative weight {weight}")]
    NegativeWeight {
        /// The fiducial's name.
        name: String,
        /// Its weight.
        weight: f64,
    },
    /// `instrument_pose` does not give a fiducial's recorded residual: the file was edited.
    #[error(
        "instrument_pose does not give fiducial {name:?}'s residual (off by {gap_mm:.3e} mm): the \
         file was edited or damaged; register again"
    )]
    ResidualMismatch {
        /// The fiducial's name.
        name: String,
        /// How far the residual is off, mm.
        gap_mm: f64,
    },
}

/// Reads and checks a registration file; errors name the file (and, for TOML syntax, the line
/// and column).
pub fn read_registration(path: &Path) -> Result<RegistrationFile> {
    let fail = |message: String| Error::Format {
        file: path.display().to_string(),
        line: 0,
        column: None,
        message,
    };
    let text = std::fs::read_to_string(path).map_err(|e| fail(e.to_string()))?;
    let file: RegistrationFile = toml::from_str(&text).map_err(|e| {
        fail(format!(
            "not a registration file: {}",
            e.to_string().trim_end()
        ))
    })?;
    file.validate()
        .map_err(|problem| fail(format!("invalid registration: {problem}")))?;
    Ok(file)
}
