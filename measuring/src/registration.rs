//! Locating the instrument in the machine's base frame from fiducials measured in both frames
//! (`hexacomp-trainer register`), and bringing measurements made in the instrument's frame into
//! the base frame.
//!
//! The fiducials are matched by name; the least-squares rigid transform instrument → base
//! ([`fit_rigid_transform`]) is accepted only when every fiducial of positive weight lies within
//! the tolerance of its nominal position. A refusal names its cause and, where the data shows
//! it, the likely mistake: two names swapped, inches for millimetres, one fiducial knocked.

use glam::DVec3;
use hexacomp_core::Pose;
use hexacomp_core::records::{MeasuredConfiguration, NamedPoint};
use hexacomp_core::rigid_fit::{Locked, fit_rigid_transform};
use hexacomp_formats::{RegisteredFiducial, RegistrationFile};

use crate::error::{Error, Result};

/// How a registration is made and accepted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RegistrationOptions {
    /// The largest residual accepted on a fiducial of positive weight, mm.
    pub tolerance_mm: f64,
    /// Parameters of the instrument's pose held at zero.
    pub locked: Locked,
}

impl Default for RegistrationOptions {
    fn default() -> Self {
        Self {
            tolerance_mm: 0.05,
            locked: Locked::default(),
        }
    }
}

/// An accepted registration: the instrument's pose in the base frame and every fiducial's
/// residual.
#[derive(Debug, Clone, PartialEq)]
pub struct Registration {
    /// The instrument's pose in the base frame (mm, rad), exactly as written to the file (its
    /// angles have been through degrees).
    pub instrument: Pose,
    /// The fiducials in the nominal file's order, with their residuals (base frame, mm).
    pub fiducials: Vec<RegisteredFiducial>,
    /// RMS of the residuals of the fiducials of positive weight, mm.
    pub rms_mm: f64,
    /// Largest residual of a fiducial of positive weight, mm.
    pub max_mm: f64,
    /// The parameters held at zero in the fit.
    pub locked: Locked,
}

impl Registration {
    /// The registration file of this registration, accepted under `tolerance_mm`, made at
    /// `created` (RFC 3339) from the files named `nominal` and `measured`.
    pub fn to_file(
        &self,
        tolerance_mm: f64,
        nominal: &str,
        measured: &str,
        created: String,
    ) -> RegistrationFile {
        RegistrationFile {
            format: hexacomp_formats::REGISTRATION_FORMAT,
            created,
            nominal: nominal.to_string(),
            measured: measured.to_string(),
            instrument_pose: self.instrument.to_mm_deg(),
            locked: self
                .locked
                .names()
                .into_iter()
                .map(str::to_string)
                .collect(),
            tolerance_mm,
            rms_mm: self.rms_mm,
            max_mm: self.max_mm,
            instrument_mpe_um: None,
            supported_mm: None,
            fiducials: self.fiducials.clone(),
        }
    }
}

/// The fiducials of both files paired by name, in the nominal file's order; refuses names on
/// one side only (listing them) and fewer than three common names.
fn pair_by_name<'a>(
    nominal: &'a [NamedPoint],
    measured: &'a [NamedPoint],
) -> Result<Vec<(&'a NamedPoint, &'a NamedPoint)>> {
    let pairs: Vec<_> = nominal
        .iter()
        .filter_map(|n| named(measured, &n.name).map(|m| (n, m)))
        .collect();
    let only = |set: &[NamedPoint], other: &[NamedPoint]| -> Vec<String> {
        set.iter()
            .filter(|p| named(other, &p.name).is_none())
            .map(|p| p.name.clone())
            .collect()
    };
    let (nominal_only, measured_only) = (only(nominal, measured), only(measured, nominal));
    let mut problems = Vec::new();
    if pairs.len() < 3 {
        problems.push(format!(
            "{} fiducial names are common to both files: at least three are needed",
            pairs.len()
        ));
    }
    if !nominal_only.is_empty() {
        problems.push(format!(
            "names only in the nominal file: {} (measure them too, or give --nominal with only \
             the fiducials measured)",
            nominal_only.join(", ")
        ));
    }
    if !measured_only.is_empty() {
        problems.push(format!(
            "names only in the measured file: {}",
            measured_only.join(", ")
        ));
    }
    if problems.is_empty() {
        Ok(pairs)
    } else {
        Err(Error::FiducialNamesUnmatched { problems })
    }
}

/// The point of `set` named `name`.
fn named<'a>(set: &'a [NamedPoint], name: &str) -> Option<&'a NamedPoint> {
    set.iter().find(|p| p.name == name)
}

/// The fit of `measured` onto `nominal` and the residuals, the pose's angles rounded through
/// degrees as the file keeps them.
fn fit(
    nominal: &[DVec3],
    measured: &[DVec3],
    weights: &[f64],
    locked: Locked,
) -> Result<(Pose, Vec<DVec3>)> {
    let pose = fit_rigid_transform(measured, nominal, weights, locked)?;
    let pose = Pose::from_mm_deg(pose.to_mm_deg());
    let residuals = measured
        .iter()
        .zip(nominal)
        .map(|(m, n)| pose.transform_point(*m) - *n)
        .collect();
    Ok((pose, residuals))
}

/// The largest residual among the fiducials of positive weight, and its index.
fn worst(residuals: &[DVec3], weights: &[f64]) -> (usize, f64) {
    residuals
        .iter()
        .zip(weights)
        .enumerate()
        .filter(|(_, (_, w))| **w > 0.0)
        .map(|(k, (r, _))| (k, r.length()))
        .fold(
            (0, -1.0),
            |best, next| if next.1 > best.1 { next } else { best },
        )
}

/// Locates the instrument from `nominal` fiducials (base frame, mm) and the same fiducials
/// `measured` in its frame (mm, weights from the measured file), matched by name.
///
/// Refused, with the cause ([`Error::FiducialNamesUnmatched`], [`Error::FiducialsDoNotLocate`],
/// [`Error::FiducialBeyondTolerance`]): names on one side only, fewer than
/// three common names or of positive weight, nearly collinear fiducials, a residual above the
/// tolerance (naming the worst fiducial and, where the data shows it, two swapped names, inches,
/// or the one fiducial whose removal makes the rest fit).
pub fn register(
    nominal: &[NamedPoint],
    measured: &[NamedPoint],
    options: &RegistrationOptions,
) -> Result<Registration> {
    if !(options.tolerance_mm.is_finite() && options.tolerance_mm > 0.0) {
        return Err(Error::OutOfRange {
            setting: "registration tolerance (mm)",
            value: options.tolerance_mm,
            valid: "must be a positive number",
        });
    }
    let pairs = pair_by_name(nominal, measured)?;
    let names: Vec<&str> = pairs.iter().map(|(n, _)| n.name.as_str()).collect();
    let nominal_points: Vec<DVec3> = pairs.iter().map(|(n, _)| n.position).collect();
    let measured_points: Vec<DVec3> = pairs.iter().map(|(_, m)| m.position).collect();
    let weights: Vec<f64> = pairs.iter().map(|(_, m)| m.weight).collect();
    let (instrument, residuals) = fit(&nominal_points, &measured_points, &weights, options.locked)
        .map_err(|e| match e {
            Error::Core(cause) => Error::FiducialsDoNotLocate { cause },
            other => other,
        })?;
    let (worst_index, max_mm) = worst(&residuals, &weights);
    if max_mm > options.tolerance_mm {
        return Err(Error::FiducialBeyondTolerance {
            fiducial: names[worst_index].to_string(),
            distance_mm: max_mm,
            tolerance_mm: options.tolerance_mm,
            diagnosis: diagnose(&names, &nominal_points, &measured_points, &weights, options),
        });
    }
    let used: Vec<f64> = residuals
        .iter()
        .zip(&weights)
        .filter(|(_, w)| **w > 0.0)
        .map(|(r, _)| r.length_squared())
        .collect();
    let rms_mm = (used.iter().sum::<f64>() / used.len() as f64).sqrt();
    let fiducials = pairs
        .iter()
        .zip(&residuals)
        .map(|((n, m), r)| RegisteredFiducial {
            name: n.name.clone(),
            nominal: n.position.to_array(),
            measured: m.position.to_array(),
            weight: m.weight,
            residual: r.to_array(),
        })
        .collect();
    Ok(Registration {
        instrument,
        fiducials,
        rms_mm,
        max_mm,
        locked: options.locked,
    })
}

/// What the data says about a registration that does not fit.
#[derive(Debug, Clone, PartialEq)]
pub enum Diagnosis {
    /// With nothing locked every fiducial fits within `max_mm`: the instrument does not meet
    /// the `locked` parameters.
    LockedParametersMissed {
        /// The largest residual with nothing locked, mm.
        max_mm: f64,
        /// The locked parameters' names.
        locked: Vec<&'static str>,
    },
    /// One file's coordinates look like inches: the nominal fiducials are spread `ratio` times
    /// as wide as the measured ones (25.4 or 1/25.4).
    Inches {
        /// Which file: "measured" or "nominal".
        file: &'static str,
        /// The nominal spread over the measured one.
        ratio: f64,
    },
    /// Two names look swapped in the measured file: exchanged, every fiducial fits within
    /// `max_mm`.
    SwappedNames {
        /// The two names.
        names: [String; 2],
        /// The largest residual with them exchanged, mm.
        max_mm: f64,
    },
    /// Without `fiducial` the others fit within `max_mm`.
    OneFiducialOff {
        /// The fiducial that probably moved.
        fiducial: String,
        /// The largest residual of the others, mm.
        max_mm: f64,
    },
    /// Without any one of `candidates` the others fit: the layout cannot tell which moved.
    OneOfSeveralOff {
        /// The fiducials any of which may have moved.
        candidates: Vec<String>,
    },
    /// The nominal fiducials are spread `ratio` times as wide as the measured ones.
    Scale {
        /// The nominal spread over the measured one.
        ratio: f64,
    },
    /// Nothing in the data points to one cause.
    Unknown,
}

/// The typical causes of a registration that does not fit.
const TYPICAL: &str = "Typical causes: two fiducial names swapped, inches instead of \
                       millimetres, a fiducial knocked or its nest moved, a reflector not \
                       seated.";

impl std::fmt::Display for Diagnosis {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::LockedParametersMissed { max_mm, locked } => write!(
                f,
                "With nothing locked every fiducial fits within {max_mm:.4} mm: the instrument \
                 does not meet the locked parameters ({}); level it again, or register without \
                 locking them.",
                locked.join(", ")
            ),
            Self::Inches { file, ratio } => write!(
                f,
                "the {file} coordinates look like inches: the nominal fiducials are spread \
                 {ratio:.3} times as wide as the measured ones (25.4 mm to the inch); give both \
                 files in millimetres."
            ),
            Self::SwappedNames { names, max_mm } => write!(
                f,
                "The names {} and {} look swapped in the measured file: exchanged, every \
                 fiducial fits within {max_mm:.4} mm.",
                names[0], names[1]
            ),
            Self::OneFiducialOff { fiducial, max_mm } => write!(
                f,
                "Without {fiducial} the others fit within {max_mm:.4} mm: it was probably \
                 knocked, mis-measured or its nominal position is wrong (measure it again, or \
                 give it weight 0 in the measured file to register without it)."
            ),
            Self::OneOfSeveralOff { candidates } => write!(
                f,
                "Without any one of {} the others fit: these fiducials cannot tell which of \
                 them moved; measure them again, or add fiducials.",
                candidates.join(", ")
            ),
            Self::Scale { ratio } => write!(
                f,
                "The nominal fiducials are spread {ratio:.4} times as wide as the measured ones: \
                 a scale or unit error? {TYPICAL}"
            ),
            Self::Unknown => f.write_str(TYPICAL),
        }
    }
}

/// A registration's fiducials, as the diagnosis refits them.
struct Fiducials<'a> {
    names: &'a [&'a str],
    nominal: &'a [DVec3],
    measured: &'a [DVec3],
    weights: &'a [f64],
    options: &'a RegistrationOptions,
}

impl Fiducials<'_> {
    /// The largest residual of the fit of `measured` with `weights` (the options' locks), when
    /// it is within the tolerance.
    fn fits(&self, measured: &[DVec3], weights: &[f64]) -> Option<f64> {
        fit(self.nominal, measured, weights, self.options.locked)
            .ok()
            .map(|(_, residuals)| worst(&residuals, weights).1)
            .filter(|max| *max <= self.options.tolerance_mm)
    }

    /// Every fiducial fits with nothing locked, where something is.
    fn locked_parameters_missed(&self) -> Option<Diagnosis> {
        let options = self.options;
        if options.locked == Locked::default() {
            return None;
        }
        let (_, residuals) =
            fit(self.nominal, self.measured, self.weights, Locked::default()).ok()?;
        let max_mm = worst(&residuals, self.weights).1;
        (max_mm <= options.tolerance_mm).then(|| Diagnosis::LockedParametersMissed {
            max_mm,
            locked: options.locked.names(),
        })
    }

    /// One file's coordinates 25.4 times the other's, within 2 %.
    fn inches(&self, ratio: f64) -> Option<Diagnosis> {
        [(25.4, "measured"), (1.0 / 25.4, "nominal")]
            .into_iter()
            .find(|(factor, _)| (ratio / factor - 1.0).abs() < 0.02)
            .map(|(_, file)| Diagnosis::Inches { file, ratio })
    }

    /// Two names whose measured points, exchanged, make every fiducial fit (tried up to 64
    /// fiducials).
    fn swapped_names(&self) -> Option<Diagnosis> {
        const MAX_PAIRS_TRIED: usize = 64;
        let names = self.names;
        if names.len() > MAX_PAIRS_TRIED {
            return None;
        }
        for i in 0..names.len() {
            for j in i + 1..names.len() {
                let mut swapped = self.measured.to_vec();
                swapped.swap(i, j);
                let mut swapped_weights = self.weights.to_vec();
                swapped_weights.swap(i, j);
                if let Some(max_mm) = self.fits(&swapped, &swapped_weights) {
                    return Some(Diagnosis::SwappedNames {
                        names: [names[i].to_string(), names[j].to_string()],
                        max_mm,
                    });
                }
            }
        }
        None
    }

    /// One fiducial off: the others fit without it. When several removals fit, the layout
    /// cannot tell which one moved (with four nearly coplanar fiducials any three fit).
    fn one_fiducial_off(&self) -> Option<Diagnosis> {
        let weights = self.weights;
        if weights.iter().filter(|w| **w > 0.0).count() <= 3 {
            return None;
        }
        let fitting: Vec<(usize, f64)> = (0..self.names.len())
            .filter(|&k| weights[k] > 0.0)
            .filter_map(|k| {
                let mut without = weights.to_vec();
                without[k] = 0.0;
                self.fits(self.measured, &without).map(|max| (k, max))
            })
            .collect();
        match fitting.as_slice() {
            [(k, max_mm)] => Some(Diagnosis::OneFiducialOff {
                fiducial: self.names[*k].to_string(),
                max_mm: *max_mm,
            }),
            [_, _, ..] => Some(Diagnosis::OneOfSeveralOff {
                candidates: fitting
                    .iter()
                    .map(|(k, _)| self.names[*k].to_string())
                    .collect(),
            }),
            [] => None,
        }
    }
}

/// What the data says about a registration that does not fit: locked parameters the
/// instrument does not meet, inches, two swapped names, one fiducial off, a scale; otherwise
/// the typical causes.
fn diagnose(
    names: &[&str],
    nominal: &[DVec3],
    measured: &[DVec3],
    weights: &[f64],
    options: &RegistrationOptions,
) -> Diagnosis {
    let fiducials = Fiducials {
        names,
        nominal,
        measured,
        weights,
        options,
    };
    let ratio = spread(nominal, weights) / spread(measured, weights);
    fiducials
        .locked_parameters_missed()
        .or_else(|| fiducials.inches(ratio))
        .or_else(|| fiducials.swapped_names())
        .or_else(|| fiducials.one_fiducial_off())
        .unwrap_or(if (ratio - 1.0).abs() > 0.001 {
            Diagnosis::Scale { ratio }
        } else {
            Diagnosis::Unknown
        })
}

/// The weighted RMS distance of `points` from their weighted centroid, mm.
fn spread(points: &[DVec3], weights: &[f64]) -> f64 {
    let total: f64 = weights.iter().sum();
    let centre = points
        .iter()
        .zip(weights)
        .fold(DVec3::ZERO, |s, (p, w)| s + *p * *w)
        / total;
    (points
        .iter()
        .zip(weights)
        .map(|(p, w)| w * (*p - centre).length_squared())
        .sum::<f64>()
        / total)
        .sqrt()
}

/// `rows` with what was measured (targets or a pose) brought from the instrument's frame into
/// the base frame through the `instrument`'s pose in the base frame (a point `p` to `t + R·p`).
pub fn into_base_frame(rows: &mut [MeasuredConfiguration], instrument: &Pose) {
    for row in rows {
        row.observed = row.observed.in_frame(instrument);
    }
}

/// An instrument's stated accuracy: the maximum permissible error of a point, `A + B·d` (µm, d
/// the distance from the instrument in metres), as trackers and arms are specified (e.g.
/// 15 µm + 6 µm/m). Taken as a 2σ bound: one coordinate of a point is read with a standard
/// deviation of half the MPE.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InstrumentMpe {
    /// The constant part `A`, µm.
    pub constant_um: f64,
    /// The part per metre of distance `B`, µm/m.
    pub per_metre_um: f64,
}

impl InstrumentMpe {
    /// The standard deviation of one coordinate of a point at `distance_mm` from the
    /// instrument, mm.
    pub fn sigma_mm(&self, distance_mm: f64) -> f64 {
        0.5 * (self.constant_um + self.per_metre_um * distance_mm / 1000.0) / 1000.0
    }
}

impl std::str::FromStr for InstrumentMpe {
    type Err = String;

    /// Parses `A+B` (µm and µm/m, e.g. `15+6`).
    fn from_str(text: &str) -> std::result::Result<Self, String> {
        let (a, b) = text
            .split_once('+')
            .ok_or_else(|| format!("{text:?}: give the MPE as A+B (µm + µm/m, e.g. 15+6)"))?;
        let number = |part: &str| {
            part.trim()
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite() && *v >= 0.0)
                .ok_or_else(|| format!("{part:?} in {text:?} is not a number ≥ 0"))
        };
        Ok(Self {
            constant_um: number(a)?,
            per_metre_um: number(b)?,
        })
    }
}

/// What accuracy measurements made under a registration can support (all 3D, 1σ, mm).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SupportedAccuracy {
    /// Distances from the instrument to the nearest and farthest fiducial used, mm.
    pub fiducial_distance_mm: [f64; 2],
    /// Distance from the instrument to the platform's targets at the home pose, mm.
    pub platform_distance_mm: f64,
    /// The RMS residual (3D) the instrument's accuracy alone explains, mm.
    pub expected_rms_mm: f64,
    /// A target point read at the platform, mm.
    pub point_mm: f64,
    /// The registration's own error at the platform (the fiducials' noise through the fit), mm.
    pub registration_mm: f64,
    /// The residuals' RMS over what the instrument's accuracy explains ([`Self::expected_rms_mm`]).
    pub residual_ratio: f64,
    /// A target point at the platform in the base frame: its reading and the registration's
    /// error, the latter scaled up by [`Self::residual_ratio`] when the fiducials fit worse than
    /// the instrument explains, mm.
    pub combined_mm: f64,
}

/// The accuracy `registration` and an instrument of `mpe` can support at the `platform`
/// points (base frame, mm: the geometry's targets at its home pose): each target point's
/// reading, and the registration's error there from the fiducials' readings propagated through
/// the least-squares fit (its covariance `σ²(JᵀWJ)⁻¹`, `J` the fit's Jacobian in a twist about
/// the base origin).
pub fn supported_accuracy(
    registration: &Registration,
    mpe: &InstrumentMpe,
    platform: &[DVec3],
) -> SupportedAccuracy {
    let at = registration.instrument.position;
    let used: Vec<&RegisteredFiducial> = registration
        .fiducials
        .iter()
        .filter(|f| f.weight > 0.0)
        .collect();
    let distance = |p: DVec3| (p - at).length();
    let fiducial_distances: Vec<f64> = used
        .iter()
        .map(|f| distance(DVec3::from_array(f.nominal)))
        .collect();
    // Each fiducial's coordinates with σ from its distance; the fit weighted them by w, so its
    // covariance is the sandwich A⁻¹·B·A⁻¹, A = Σ w·JᵀJ, B = Σ w²σ²·JᵀJ. Locked parameters do
    // not move (their columns are left out: exact for locked translations and for a rotation
    // about z only).
    let free = |mut jacobian: nalgebra::SMatrix<f64, 3, 6>| {
        for k in (0..6).filter(|&k| registration.locked.is_locked(k)) {
            jacobian.column_mut(k).fill(0.0);
        }
        jacobian
    };
    let (mut a, mut b) = (
        nalgebra::Matrix6::<f64>::zeros(),
        nalgebra::Matrix6::<f64>::zeros(),
    );
    let mut expected_square = 0.0;
    for (f, d) in used.iter().zip(&fiducial_distances) {
        let sigma = mpe.sigma_mm(*d);
        let jacobian = free(twist_jacobian(DVec3::from_array(f.nominal)));
        let jtj = jacobian.transpose() * jacobian;
        a += jtj * f.weight;
        b += jtj * (f.weight * f.weight * sigma * sigma);
        expected_square += 3.0 * sigma * sigma;
    }
    let free_parameters = (0..6)
        .filter(|&k| !registration.locked.is_locked(k))
        .count();
    let dof = (3 * used.len()).saturating_sub(free_parameters) as f64 / (3 * used.len()) as f64;
    let a_inverse = a
        .pseudo_inverse(1e-12 * a.norm())
        .unwrap_or_else(|_| nalgebra::Matrix6::from_element(f64::INFINITY));
    let covariance = a_inverse * b * a_inverse;
    let centre = platform.iter().copied().sum::<DVec3>() / platform.len() as f64;
    let platform_distance_mm = distance(centre);
    let registration_mm = platform
        .iter()
        .map(|p| {
            let j = twist_jacobian(*p);
            (j * covariance * j.transpose()).trace()
        })
        .fold(0.0, f64::max)
        .sqrt();
    let point_mm = 3f64.sqrt() * mpe.sigma_mm(platform_distance_mm);
    let expected_rms_mm = (expected_square / used.len() as f64 * dof).sqrt();
    SupportedAccuracy {
        fiducial_distance_mm: [
            fiducial_distances
                .iter()
                .copied()
                .fold(f64::INFINITY, f64::min),
            fiducial_distances.iter().copied().fold(0.0, f64::max),
        ],
        platform_distance_mm,
        expected_rms_mm,
        point_mm,
        registration_mm,
        residual_ratio: registration.rms_mm / expected_rms_mm,
        combined_mm: point_mm
            .hypot(registration_mm * (registration.rms_mm / expected_rms_mm).max(1.0)),
    }
}

/// The instrument accuracy the residuals of `registration` show: one σ per coordinate, the
/// same for every fiducial, from their sum of squares over the fit's degrees of freedom; for a
/// registration made without a stated MPE.
pub fn accuracy_from_residuals(registration: &Registration) -> InstrumentMpe {
    let used: Vec<&RegisteredFiducial> = registration
        .fiducials
        .iter()
        .filter(|f| f.weight > 0.0)
        .collect();
    let free = (0..6)
        .filter(|&k| !registration.locked.is_locked(k))
        .count();
    let square: f64 = used.iter().map(|f| f.residual_mm().powi(2)).sum();
    let dof = (3 * used.len()).saturating_sub(free).max(1) as f64;
    InstrumentMpe {
        constant_um: 2.0 * 1000.0 * (square / dof).sqrt(),
        per_metre_um: 0.0,
    }
}

/// `∂p/∂(δt, ω)` of a point `p` moved by a small twist about the base origin: `[I  −[p×]]`.
fn twist_jacobian(p: DVec3) -> nalgebra::SMatrix<f64, 3, 6> {
    nalgebra::SMatrix::<f64, 3, 6>::from_row_slice(&[
        1.0, 0.0, 0.0, 0.0, p.z, -p.y, //
        0.0, 1.0, 0.0, -p.z, 0.0, p.x, //
        0.0, 0.0, 1.0, p.y, -p.x, 0.0,
    ])
}
