//! Magnitudes of the simulated machine's error sources, and named presets.

use std::fmt;
use std::str::FromStr;

use glam::DVec3;

use hexacomp_core::error::{Error, Result};

/// Lead-screw errors of each leg: the difference between the length the encoder reports and the
/// real length, a nonlinear function of the leg length `q`. With `u = (q − q_mid)/(stroke/2)`:
/// `e(q) = scale·(q − q_mid) + curvature·u² + amplitude·sin(2π·q/wavelength + phase)`.
/// Per-leg coefficients are drawn as `N(0, σ)` (phase uniform).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PitchErrors {
    /// σ of the linear pitch (scale) error, mm per mm of travel.
    pub scale_sigma: f64,
    /// σ of the quadratic term's size at the stroke ends, mm.
    pub curvature_sigma_mm: f64,
    /// σ of the periodic term's amplitude, mm.
    pub periodic_sigma_mm: f64,
    /// Wavelength of the periodic term, mm of leg travel.
    pub periodic_wavelength_mm: f64,
}

/// Gravity-induced axial compliance of the legs: a payload of `mass_kg` at `centre_of_mass_mm`
/// (platform frame) loads the legs through static equilibrium, `W·τ = −w_gravity`; leg `i`
/// shortens by `τ_i·compliance_i·(L_i/L_mid)` (a screw's compliance grows with its free length).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Compliance {
    /// Moving mass (platform and payload), kg.
    pub mass_kg: f64,
    /// Centre of mass in the platform frame, mm.
    pub centre_of_mass_mm: DVec3,
    /// Mean axial compliance of a leg at mid-stroke, mm per newton.
    pub compliance_mm_per_n: f64,
    /// Relative σ of each leg's compliance around the mean (leg-to-leg scatter).
    pub scatter: f64,
}

/// The simulated point-measuring device (measuring arm or laser tracker).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeasuringDevice {
    /// Standard uncertainty of one reading, each coordinate, mm.
    pub sigma_mm: f64,
    /// Readings averaged per target (the paper averages three, Sec. 4.2).
    pub readings: usize,
}

/// The magnitudes of every error source of the virtual platform.
///
/// The defaults ([`ErrorVariant::Paper`]) are tuned so that, uncompensated, the pose errors over
/// random workspace poses resemble the paper's "before compensation" column of Table 2, with
/// enough non-geometric error that a purely geometric calibration is left clearly behind the
/// networks (as in the paper's Fig. 13).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ErrorModel {
    /// σ of each coordinate of each base joint centre's offset from nominal, mm.
    pub base_joint_sigma_mm: f64,
    /// σ of each coordinate of each platform joint centre's offset from nominal, mm.
    pub platform_joint_sigma_mm: f64,
    /// σ of each leg's zero (encoder reference) offset, mm.
    pub leg_zero_sigma_mm: f64,
    /// Lead-screw pitch errors.
    pub pitch: PitchErrors,
    /// Gravity-induced leg compliance.
    pub compliance: Compliance,
    /// σ of the random leg-length error of every move (repeatability), mm.
    pub repeatability_sigma_mm: f64,
    /// The point-measuring device.
    pub device: MeasuringDevice,
}

/// Named presets of [`ErrorModel`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ErrorVariant {
    /// Every error source at its default magnitude (resembles the paper's prototype).
    #[default]
    Paper,
    /// As `Paper`, without repeatability and measurement noise.
    NoiseFree,
    /// Only geometric errors (joint centres, leg zero offsets): no pitch, compliance or noise.
    GeometricOnly,
    /// As `Paper` with four times the pitch errors.
    StrongPitch,
    /// A robot the physical model's settings were not chosen on (added after they were, for
    /// blind figures): joint centres and leg zeros twice as far off as `Paper`'s, a lead-screw
    /// periodic error of 60 mm wavelength and twice the amplitude, and twice the moving mass
    /// with its centre of mass 40 mm further off the axis.
    Unseen,
}

impl ErrorVariant {
    /// Every variant, for listing in help texts.
    pub const ALL: [ErrorVariant; 5] = [
        ErrorVariant::Paper,
        ErrorVariant::NoiseFree,
        ErrorVariant::GeometricOnly,
        ErrorVariant::StrongPitch,
        ErrorVariant::Unseen,
    ];

    /// The variant's name as used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            ErrorVariant::Paper => "paper",
            ErrorVariant::NoiseFree => "noise-free",
            ErrorVariant::GeometricOnly => "geometric-only",
            ErrorVariant::StrongPitch => "strong-pitch",
            ErrorVariant::Unseen => "unseen",
        }
    }
}

impl fmt::Display for ErrorVariant {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for ErrorVariant {
    type Err = Error;

    fn from_str(s: &str) -> Result<Self> {
        Self::ALL
            .into_iter()
            .find(|v| v.name() == s)
            .ok_or_else(|| {
                let names: Vec<_> = Self::ALL.iter().map(|v| v.name()).collect();
                Error::InvalidSetting(format!(
                    "unknown error variant {s:?}; expected one of {}",
                    names.join(", ")
                ))
            })
    }
}

impl Default for ErrorModel {
    fn default() -> Self {
        Self {
            base_joint_sigma_mm: 0.10,
            platform_joint_sigma_mm: 0.20,
            leg_zero_sigma_mm: 0.45,
            pitch: PitchErrors {
                scale_sigma: 3e-4,
                curvature_sigma_mm: 0.04,
                periodic_sigma_mm: 0.025,
                periodic_wavelength_mm: 90.0,
            },
            compliance: Compliance {
                mass_kg: 80.0,
                centre_of_mass_mm: DVec3::new(15.0, -10.0, 60.0),
                compliance_mm_per_n: 4e-4,
                scatter: 0.2,
            },
            repeatability_sigma_mm: 0.004,
            device: MeasuringDevice {
                sigma_mm: 0.020,
                readings: 3,
            },
        }
    }
}

impl ErrorModel {
    /// The preset `variant`.
    pub fn variant(variant: ErrorVariant) -> Self {
        let paper = Self::default();
        match variant {
            ErrorVariant::Paper => paper,
            ErrorVariant::NoiseFree => paper.without_noise(),
            ErrorVariant::GeometricOnly => Self {
                pitch: PitchErrors {
                    scale_sigma: 0.0,
                    curvature_sigma_mm: 0.0,
                    periodic_sigma_mm: 0.0,
                    ..paper.pitch
                },
                compliance: Compliance {
                    mass_kg: 0.0,
                    ..paper.compliance
                },
                ..paper.without_noise()
            },
            ErrorVariant::StrongPitch => Self {
                pitch: PitchErrors {
                    scale_sigma: 4.0 * paper.pitch.scale_sigma,
                    curvature_sigma_mm: 4.0 * paper.pitch.curvature_sigma_mm,
                    periodic_sigma_mm: 4.0 * paper.pitch.periodic_sigma_mm,
                    ..paper.pitch
                },
                ..paper
            },
            ErrorVariant::Unseen => Self {
                base_joint_sigma_mm: 2.0 * paper.base_joint_sigma_mm,
                platform_joint_sigma_mm: 2.0 * paper.platform_joint_sigma_mm,
                leg_zero_sigma_mm: 2.0 * paper.leg_zero_sigma_mm,
                pitch: PitchErrors {
                    periodic_sigma_mm: 2.0 * paper.pitch.periodic_sigma_mm,
                    periodic_wavelength_mm: 60.0,
                    ..paper.pitch
                },
                compliance: Compliance {
                    mass_kg: 2.0 * paper.compliance.mass_kg,
                    centre_of_mass_mm: paper.compliance.centre_of_mass_mm
                        + DVec3::new(40.0, 0.0, 0.0),
                    ..paper.compliance
                },
                ..paper
            },
        }
    }

    /// This model with repeatability and measurement noise removed.
    pub fn without_noise(self) -> Self {
        Self {
            repeatability_sigma_mm: 0.0,
            device: MeasuringDevice {
                sigma_mm: 0.0,
                ..self.device
            },
            ..self
        }
    }

    /// Checks that every magnitude is finite and non-negative and the device takes ≥ 1 reading.
    pub fn validate(&self) -> Result<()> {
        let named = [
            ("base_joint_sigma_mm", self.base_joint_sigma_mm),
            ("platform_joint_sigma_mm", self.platform_joint_sigma_mm),
            ("leg_zero_sigma_mm", self.leg_zero_sigma_mm),
            ("pitch.scale_sigma", self.pitch.scale_sigma),
            ("pitch.curvature_sigma_mm", self.pitch.curvature_sigma_mm),
            ("pitch.periodic_sigma_mm", self.pitch.periodic_sigma_mm),
            ("compliance.mass_kg", self.compliance.mass_kg),
            (
                "compliance.compliance_mm_per_n",
                self.compliance.compliance_mm_per_n,
            ),
            ("compliance.scatter", self.compliance.scatter),
            ("repeatability_sigma_mm", self.repeatability_sigma_mm),
            ("device.sigma_mm", self.device.sigma_mm),
        ];
        for (name, value) in named {
            if !(value.is_finite() && value >= 0.0) {
                return Err(Error::InvalidSetting(format!(
                    "error model {name} = {value} must be finite and ≥ 0"
                )));
            }
        }
        if !(self.pitch.periodic_wavelength_mm.is_finite()
            && self.pitch.periodic_wavelength_mm > 0.0)
        {
            return Err(Error::InvalidSetting(format!(
                "error model pitch.periodic_wavelength_mm = {} must be > 0",
                self.pitch.periodic_wavelength_mm
            )));
        }
        if !self.compliance.centre_of_mass_mm.is_finite() {
            return Err(Error::InvalidSetting(
                "error model compliance.centre_of_mass_mm must be finite".into(),
            ));
        }
        if self.device.readings == 0 {
            return Err(Error::InvalidSetting(
                "the measuring device must take at least one reading per target".into(),
            ));
        }
        Ok(())
    }
}
