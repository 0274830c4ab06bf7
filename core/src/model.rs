//! The trained compensation model and its file (docs/formats.md, "Model file").
//!
//! File layout: 8 magic bytes `HXCMODEL`, the format version (u16, little-endian), the payload
//! length (u32 LE), the payload, and a CRC-64/XZ (u64 LE) of everything before it. The payload
//! is the postcard-encoded [`Model`] without its uncertainty (version 1), followed in version 2
//! by the postcard-encoded [`PositionUncertainty`], in version 3 by an optional one (postcard's
//! `Option`). Networks without an uncertainty are written as version 1 and with one as version
//! 2, so that builds that read only those keep reading them; a physical model
//! ([`Networks::Physical`], which no earlier build knows) as version 3. A model binds itself to
//! the fingerprint of the geometry it was trained for.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::{Error, ModelFileProblem, Result};
use crate::geometry::{Fingerprint, Geometry, LEGS};
use crate::network::{Network, Normalisation};
use crate::physical::PhysicalCorrections;
use crate::pose::Pose;
use crate::uncertainty::PositionUncertainty;

/// Magic bytes at the start of every model file.
pub const MAGIC: &[u8; 8] = b"HXCMODEL";
/// The newest model-file format version, which this build writes for a physical model; it
/// reads it and every earlier one.
pub const FORMAT_VERSION: u16 = 3;
/// The format version of networks with an uncertainty.
const FORMAT_WITH_UNCERTAINTY: u16 = 2;
/// The format version of networks without an uncertainty (the first).
const FORMAT_WITHOUT_UNCERTAINTY: u16 = 1;
const HEADER: usize = 8 + 2 + 4;
const CHECKSUM: crc::Crc<u64> = crc::Crc::<u64>::new(&crc::CRC_64_XZ);

/// What computes the joint corrections: the paper's networks (Sec. 3.2, Fig. 3–4), or the
/// physical model itself.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Networks {
    /// One network with six outputs.
    Coupled(Network),
    /// Six single-output networks, one per leg.
    Decoupled(Vec<Network>),
    /// The identified physical model, evaluated as it is (format version 3; its model's
    /// `input` and `normalisation` are not used).
    Physical(Box<PhysicalCorrections>),
}

/// Which leg lengths the networks take as input.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum NetworkInput {
    /// The commanded nominal legs `q⁽⁰⁾` (the paper): `Δq = N(q⁽⁰⁾)`.
    Commanded,
    /// The equivalent legs `q⁽ᴸ⁾ = q⁽⁰⁾ − Δq`: `N` inverts the machine's map, so `q + N(q)` is
    /// right at the corrected point rather than only at `q⁽⁰⁾`.
    Equivalent,
}

impl NetworkInput {
    /// The name used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            NetworkInput::Commanded => "commanded",
            NetworkInput::Equivalent => "equivalent",
        }
    }
}

/// Where a model came from.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Provenance {
    /// Creation time, seconds since the Unix epoch (UTC).
    pub created_unix_s: u64,
    /// Configurations the corrections came from.
    pub configurations: usize,
    /// Samples in the final fit.
    pub training_samples: usize,
    /// Samples held out to choose the hidden-node count.
    pub validation_samples: usize,
    /// Holdout validation RMSE of the chosen size (Eq. 18, or Eq. 21 for decoupled), mm. For a
    /// physical model: its cross-validated error against the measurements (Eq. 21's units;
    /// files of earlier builds, whose physical model was carried into networks: the networks'
    /// error against the model's corrections).
    pub validation_rmse_mm: f64,
    /// Free text: the tool, its version, the source files.
    pub source: String,
}

/// A trained compensation model: `Δq = N(normalise(q))`, clamped to the correction bounds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Model {
    /// The network(s).
    pub networks: Networks,
    /// The networks' input.
    pub input: NetworkInput,
    /// Input normalisation (Eq. 13).
    pub normalisation: Normalisation,
    /// `[min, max]` of each nominal leg the model answers for without the status
    /// `outside_trained_range`, mm: for a trained model, every configuration's commanded and
    /// network-input legs (held-out ones included).
    pub training_range: [[f64; 2]; LEGS],
    /// `[min, max]` of each correction the model may return, mm.
    pub correction_bounds: [[f64; 2]; LEGS],
    /// Fingerprint of the geometry the model was trained for.
    pub geometry: Fingerprint,
    /// Where the model came from.
    pub provenance: Provenance,
    /// The 1-σ position uncertainty of each compensated point (format version 2; `None` in a
    /// version-1 file).
    #[serde(skip)]
    pub uncertainty: Option<PositionUncertainty>,
}

impl Model {
    /// The raw network output `Δq = N(q, w)` (Eq. 14; mm) for network input legs `q` (mm),
    /// normalised by Eq. 13, before clamping. Allocation-free.
    #[inline]
    pub fn raw_corrections(&self, q: &[f64; LEGS]) -> [f64; LEGS] {
        let x = self.normalisation.apply(q);
        let mut out = [0.0; LEGS];
        match &self.networks {
            Networks::Coupled(n) => n.evaluate(&x, &mut out),
            Networks::Decoupled(nets) => {
                for (leg, n) in nets.iter().enumerate() {
                    n.evaluate(&x, &mut out[leg..=leg]);
                }
            }
            Networks::Physical(physical) => out = physical.at_legs(q),
        }
        out
    }

    /// [`Model::raw_corrections`] at the nominal legs `q` (mm) of `pose` (mm, rad): a physical
    /// model takes the pose rather than finding it from the legs (the same corrections to
    /// rounding, without the forward kinematics). Allocation-free.
    #[inline]
    pub fn raw_corrections_at_pose(&self, q: &[f64; LEGS], pose: &Pose) -> [f64; LEGS] {
        match &self.networks {
            Networks::Physical(physical) => physical.at_pose(pose, q),
            _ => self.raw_corrections(q),
        }
    }

    /// Whether the corrections are the physical model's ([`Networks::Physical`]).
    pub fn is_physical(&self) -> bool {
        matches!(self.networks, Networks::Physical(_))
    }

    /// An upper bound, valid for every input, on how fast any raw correction changes with the
    /// legs (mm per mm of leg travel, Euclidean norm): corrections at legs `d` mm apart differ
    /// by at most `max_slope() · d` mm. See [`Network::max_slope`]; for a physical model an
    /// estimate, not a bound ([`PhysicalCorrections::max_slope`]).
    pub fn max_slope(&self) -> f64 {
        let span = &self.normalisation.span;
        match &self.networks {
            Networks::Coupled(n) => n.max_slope(span),
            Networks::Decoupled(nets) => nets.iter().map(|n| n.max_slope(span)).fold(0.0, f64::max),
            Networks::Physical(physical) => physical.max_slope(),
        }
    }

    /// Hidden nodes of each network (none for a physical model).
    pub fn hidden_nodes(&self) -> Vec<usize> {
        match &self.networks {
            Networks::Coupled(n) => vec![n.hidden()],
            Networks::Decoupled(nets) => nets.iter().map(Network::hidden).collect(),
            Networks::Physical(_) => Vec::new(),
        }
    }

    /// Checks the networks' shapes, that every number is finite and ranges are ordered.
    pub fn validate(&self) -> Result<()> {
        match &self.networks {
            Networks::Coupled(n) => {
                n.validate()?;
                if n.outputs() != LEGS {
                    return Err(Error::InvalidModel(format!(
                        "a coupled network needs {LEGS} outputs, has {}",
                        n.outputs()
                    )));
                }
            }
            Networks::Decoupled(nets) => {
                if nets.len() != LEGS || nets.iter().any(|n| n.outputs() != 1) {
                    return Err(Error::InvalidModel(format!(
                        "decoupled models need {LEGS} single-output networks"
                    )));
                }
                nets.iter().try_for_each(Network::validate)?;
            }
            Networks::Physical(physical) => {
                physical.validate()?;
                if physical.nominal_fingerprint() != self.geometry {
                    return Err(Error::InvalidModel(format!(
                        "the physical model's nominal geometry is {}, the model's {}",
                        physical.nominal_fingerprint(),
                        self.geometry
                    )));
                }
            }
        }
        let n = &self.normalisation;
        if n.mean.iter().chain(&n.span).any(|v| !v.is_finite()) || n.span.iter().any(|s| *s <= 0.0)
        {
            return Err(Error::InvalidModel(
                "normalisation must be finite with positive spans".into(),
            ));
        }
        for (name, ranges) in [
            ("training range", &self.training_range),
            ("correction bounds", &self.correction_bounds),
        ] {
            for (leg, [lo, hi]) in ranges.iter().enumerate() {
                if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
                    return Err(Error::InvalidModel(format!(
                        "{name} of leg {} is [{lo}, {hi}]",
                        leg + 1
                    )));
                }
            }
        }
        if let Some(uncertainty) = &self.uncertainty {
            uncertainty.validate()?;
        }
        Ok(())
    }

    /// The format version the model's file has: [`FORMAT_VERSION`] for a physical model; for
    /// networks 2 with an uncertainty, 1 without (what a file read with or without one had).
    pub fn format_version(&self) -> u16 {
        if self.is_physical() {
            FORMAT_VERSION
        } else if self.uncertainty.is_some() {
            FORMAT_WITH_UNCERTAINTY
        } else {
            FORMAT_WITHOUT_UNCERTAINTY
        }
    }

    /// The model-file bytes, in [`Model::format_version`].
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut payload = postcard::to_stdvec(self).expect("a model always serialises");
        let version = self.format_version();
        let uncertainty = match version {
            FORMAT_VERSION => postcard::to_stdvec(&self.uncertainty),
            _ => self
                .uncertainty
                .as_ref()
                .map_or(Ok(Vec::new()), postcard::to_stdvec),
        };
        payload.extend(uncertainty.expect("an uncertainty always serialises"));
        let mut bytes = Vec::with_capacity(HEADER + payload.len() + 8);
        bytes.extend_from_slice(MAGIC);
        bytes.extend_from_slice(&version.to_le_bytes());
        bytes.extend_from_slice(&(payload.len() as u32).to_le_bytes());
        bytes.extend_from_slice(&payload);
        let checksum = CHECKSUM.checksum(&bytes);
        bytes.extend_from_slice(&checksum.to_le_bytes());
        bytes
    }

    /// Decodes and validates model-file bytes.
    pub fn from_bytes(bytes: &[u8]) -> std::result::Result<Self, ModelFileProblem> {
        if bytes.len() < MAGIC.len() || &bytes[..MAGIC.len()] != MAGIC {
            return Err(ModelFileProblem::NotAModel);
        }
        if bytes.len() < HEADER {
            return Err(ModelFileProblem::Truncated {
                actual: bytes.len(),
                expected: HEADER,
            });
        }
        let version = u16::from_le_bytes([bytes[8], bytes[9]]);
        if !(FORMAT_WITHOUT_UNCERTAINTY..=FORMAT_VERSION).contains(&version) {
            return Err(ModelFileProblem::Version {
                found: version,
                supported: FORMAT_VERSION,
            });
        }
        let length = u32::from_le_bytes([bytes[10], bytes[11], bytes[12], bytes[13]]) as usize;
        let expected = HEADER + length + 8;
        if bytes.len() < expected {
            return Err(ModelFileProblem::Truncated {
                actual: bytes.len(),
                expected,
            });
        }
        if bytes.len() > expected {
            return Err(ModelFileProblem::Corrupt(format!(
                "{} bytes after the checksum",
                bytes.len() - expected
            )));
        }
        let (body, tail) = bytes.split_at(HEADER + length);
        let stored = u64::from_le_bytes(tail.try_into().expect("8 checksum bytes"));
        if CHECKSUM.checksum(body) != stored {
            return Err(ModelFileProblem::Checksum);
        }
        let corrupt = |e: postcard::Error| ModelFileProblem::Corrupt(e.to_string());
        let (mut model, rest): (Model, _) =
            postcard::take_from_bytes(&body[HEADER..]).map_err(corrupt)?;
        let rest = match version {
            FORMAT_VERSION => {
                let (uncertainty, rest) = postcard::take_from_bytes(rest).map_err(corrupt)?;
                model.uncertainty = uncertainty;
                rest
            }
            FORMAT_WITH_UNCERTAINTY => {
                let (uncertainty, rest) = postcard::take_from_bytes(rest).map_err(corrupt)?;
                model.uncertainty = Some(uncertainty);
                rest
            }
            _ => rest,
        };
        if model.is_physical() != (version == FORMAT_VERSION) {
            return Err(ModelFileProblem::Corrupt(format!(
                "format version {version} with {}",
                if model.is_physical() {
                    "a physical model (version 3 only)"
                } else {
                    "networks (versions 1 and 2 only)"
                }
            )));
        }
        if !rest.is_empty() {
            return Err(ModelFileProblem::Corrupt(format!(
                "{} bytes after the format version {version} payload",
                rest.len()
            )));
        }
        model
            .validate()
            .map_err(|e| ModelFileProblem::Corrupt(e.to_string()))?;
        Ok(model)
    }

    /// Reads a model file and checks that it was trained for `geometry`.
    pub fn load(path: &Path, geometry: &Geometry) -> Result<Self> {
        let fail = |problem| Error::ModelFile {
            path: path.display().to_string(),
            problem,
        };
        let bytes = std::fs::read(path).map_err(|e| fail(ModelFileProblem::Io(e.to_string())))?;
        let model = Self::from_bytes(&bytes).map_err(fail)?;
        if model.geometry != geometry.fingerprint() {
            return Err(fail(ModelFileProblem::Geometry {
                model: model.geometry.to_string(),
                geometry: geometry.fingerprint().to_string(),
            }));
        }
        Ok(model)
    }

    /// Writes the model file whole or not at all, durable once this returns
    /// ([`crate::durable::replace_file`]), so a crash or power loss never leaves a half-written
    /// model nor brings the previous one back.
    pub fn save(&self, path: &Path) -> Result<()> {
        crate::durable::replace_file(path, &self.to_bytes()).map_err(|e| Error::ModelFile {
            path: path.display().to_string(),
            problem: ModelFileProblem::Io(e.to_string()),
        })
    }
}
