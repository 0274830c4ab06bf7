//! The model-based baseline: identification of the geometric parameters from point measurements.
//!
//! Parameters (42): the base joint centres `b_i` (18), the platform joint centres `a_i` (18) and
//! the leg zero offsets `o_i` (6). The targets are known in the platform frame and measured in the
//! base frame, which fixes both frames. For measured configuration `k` with commanded legs `q_k`,
//! the model's pose is the forward kinematics of the parameters, and its residual is
//! `r_k = r_Pm − r_Pc` (9 values). Differentiating the leg constraint
//! `|t + R·a_i − b_i| − o_i = q_i` with the legs held gives `Wᵀ·ξ = G·δθ` with row `i` of `G`
//! being `s_iᵀ` on `b_i`, `−(Rᵀs_i)ᵀ` on `a_i` and 1 on `o_i`; so `∂r_Pc/∂θ = P·T·G` (Eq. 3,
//! Eq. 4, and Eq. 5 with `ρ = G·δθ`).
//!
//! Gauss–Newton steps solve `J·δθ = r` by SVD, dropping directions whose singular value is below
//! a fraction of the largest: parameter combinations the measurements cannot see stay at their
//! nominal values. Compensation is then the identified geometry's inverse kinematics. With a
//! smoothness prior on the lead-screw curves ([`IdentifyOptions::smoothness`]) the steps solve
//! `J·δθ = r` stacked on the prior's rows (`√λ` times each curve's second differences, whose
//! residuals are those differences' negatives), and lower the sum of both squares.
//!
//! Optionally the model is shaped further like the machine ([`hexacomp_core::physical`]): a lead-screw
//! error curve per leg (`pitch_basis` B-spline coefficients each) and the legs' compliance under
//! the platform's weight (4 per leg). Both change the loaded leg length, as the offset does: a
//! pitch coefficient's column of `G` is its basis function at the leg's commanded length, a
//! compliance coefficient's is `−h_im` at the pose.

use hexacomp_core::records::MeasuredConfiguration;
use hexacomp_core::screw::{ActuationScrews, point_matrix};
use hexacomp_core::{ForwardOptions, Geometry, LEGS, Pose, forward_kinematics};
use nalgebra::{DMatrix, DVector, Dyn, SVD};

use crate::error::{Error, Result};
use hexacomp_core::physical::{COMPLIANCE_TERMS, PhysicalModel, PitchCurves};

/// Number of geometric parameters: 6 × (3 + 3 + 1).
pub const PARAMETERS: usize = 42;

/// The first of the legs' zero offsets among [`linearise`]'s columns (six, leg by leg, after
/// the base and the platform joints). An offset lengthens its leg one millimetre per
/// millimetre, so its column is how the targets move with that leg's length.
pub(crate) const LEG_OFFSET_COLUMNS: usize = 36;

/// Settings of the identification.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IdentifyOptions {
    /// Gauss–Newton iterations at most.
    pub max_iterations: usize,
    /// Stop when the largest parameter step is below this, mm.
    pub step_tolerance_mm: f64,
    /// Stop when an iteration lowers the root of what the steps lower (the residuals' squares
    /// and the smoothness prior's, per residual) by less than this fraction (noisy data never
    /// reaches the step tolerance: the fit stalls at the noise).
    pub stall_fraction: f64,
    /// Singular values below this fraction of the largest are treated as zero (unidentifiable).
    pub relative_cutoff: f64,
    /// B-spline coefficients of each leg's lead-screw error curve (0: no pitch errors
    /// identified).
    pub pitch_basis: usize,
    /// Identify the legs' compliance under the platform's weight.
    pub compliance: bool,
    /// Weight `λ` of the lead-screw curves' smoothness prior (dimensionless; 0: none): each
    /// second difference of a curve's coefficients, `c_(k−1) − 2c_k + c_(k+1)` (mm), enters the
    /// least squares beside the targets' residuals (mm) scaled by `√λ`, so a curve bends only
    /// as far as the measurements pay for. [`crate::pitch_resolution`] chooses it per machine.
    pub smoothness: f64,
}

impl IdentifyOptions {
    /// Identified coefficients per lead-screw curve: all but the middle one.
    fn pitch_columns(&self) -> usize {
        self.pitch_basis.saturating_sub(1)
    }

    /// The column of leg `leg`'s pitch coefficient `k` among the pitch columns, `None` for the
    /// middle one (held at 0).
    fn pitch_column(&self, leg: usize, k: usize) -> Option<usize> {
        let pinned = self.pitch_basis / 2;
        let within = match k.cmp(&pinned) {
            std::cmp::Ordering::Less => k,
            std::cmp::Ordering::Equal => return None,
            std::cmp::Ordering::Greater => k - 1,
        };
        Some(PARAMETERS + self.pitch_columns() * leg + within)
    }

    /// How many parameters are identified (a lead-screw curve's middle coefficient stays 0: the
    /// leg's offset carries its constant).
    pub fn parameters(&self) -> usize {
        PARAMETERS
            + LEGS * self.pitch_columns()
            + if self.compliance {
                LEGS * COMPLIANCE_TERMS
            } else {
                0
            }
    }
}

impl Default for IdentifyOptions {
    fn default() -> Self {
        Self {
            max_iterations: 30,
            step_tolerance_mm: 1e-10,
            stall_fraction: 1e-9,
            relative_cutoff: 1e-9,
            pitch_basis: 0,
            compliance: false,
            smoothness: 0.0,
        }
    }
}

/// The physical model's identification (the default of `calibrate` and `evaluate`): the
/// compliance, directions below 1e-6 of the largest singular value left alone (at 1e-9 the
/// weakly seen ends of the curves diverged), and eight B-spline coefficients per lead-screw
/// curve (a knot every 30 mm of the prototype's 150 mm stroke), the coarsest resolution
/// [`crate::pitch_resolution`] tries: it chooses a finer one for a machine whose
/// cross-validation asks for it (docs/accuracy.md).
pub const PHYSICAL: IdentifyOptions = IdentifyOptions {
    max_iterations: 30,
    step_tolerance_mm: 1e-10,
    stall_fraction: 1e-9,
    relative_cutoff: 1e-6,
    pitch_basis: 8,
    compliance: true,
    smoothness: 0.0,
};

impl IdentifyOptions {
    /// [`PHYSICAL`] with `pitch_basis` B-spline coefficients per lead-screw curve: the physical
    /// model's identification at another resolution.
    pub const fn physical(pitch_basis: usize) -> Self {
        Self {
            pitch_basis,
            ..PHYSICAL
        }
    }

    /// These options if a model can be identified with them: a lead-screw curve of none or at
    /// least four coefficients, and a smoothness prior's weight finite and ≥ 0.
    pub(crate) fn validate(&self) -> Result<()> {
        if (1..4).contains(&self.pitch_basis) {
            return Err(Error::OutOfRange {
                setting: "B-spline coefficients per lead-screw curve",
                value: self.pitch_basis as f64,
                valid: "must be 0 (none) or at least 4",
            });
        }
        if !(self.smoothness.is_finite() && self.smoothness >= 0.0) {
            return Err(Error::OutOfRange {
                setting: "the smoothness prior's weight",
                value: self.smoothness,
                valid: "must be finite and ≥ 0",
            });
        }
        Ok(())
    }

    /// These options with the lead-screw curves' smoothness prior of weight `smoothness`
    /// ([`Self::smoothness`]).
    pub const fn smoothed(self, smoothness: f64) -> Self {
        Self { smoothness, ..self }
    }
}

/// The identified geometry and how the identification went.
#[derive(Debug, Clone, PartialEq)]
pub struct Identification {
    /// The nominal geometry with identified joint centres and leg offsets.
    pub geometry: Geometry,
    /// The whole identified model: the geometry, and the pitch curves and compliance when they
    /// were identified (zero otherwise).
    pub model: PhysicalModel,
    /// Gauss–Newton iterations performed.
    pub iterations: usize,
    /// Parameter directions the measurements determine (≤ [`IdentifyOptions::parameters`]);
    /// with a smoothness prior, the measurements and the prior together.
    pub rank: usize,
    /// RMS of the target residuals with the nominal geometry, mm.
    pub rms_before_mm: f64,
    /// RMS of the target residuals with the identified geometry, mm.
    pub rms_after_mm: f64,
}

/// Identifies the geometric parameters of `nominal` from measured configurations.
pub fn identify(
    nominal: &Geometry,
    rows: &[MeasuredConfiguration],
    options: &IdentifyOptions,
) -> Result<Identification> {
    // 9 equations per configuration; 42 unknowns need at least 5 configurations, and far more
    // for a well-conditioned answer.
    if rows.len() < 5 {
        return Err(Error::TooFewConfigurations {
            task: "identification",
            needed: 5,
            got: rows.len(),
        });
    }
    options.validate()?;
    let mut model = PhysicalModel::geometric(nominal.clone());
    model.pitch = PitchCurves::zero(nominal.leg_range, options.pitch_basis);
    let parameters = options.parameters();
    let mut poses: Vec<Pose> = rows.iter().map(MeasuredConfiguration::pose).collect();
    let mut rms_before = None;
    let mut cost_previous = f64::INFINITY;
    let mut rank = 0;
    let mut iterations = 0;
    for _ in 0..options.max_iterations {
        let (jacobian, residual) = linearise(&model, options, rows, &mut poses)
            .map_err(|e| ill_conditioned(e, rank, parameters))?;
        let rms = (residual.norm_squared() / residual.len() as f64).sqrt();
        rms_before.get_or_insert(rms);
        // What the steps lower: the residuals' squares and the smoothness prior's.
        let prior = SmoothnessPrior::at(&model, options);
        let objective = residual.norm_squared() + prior.residual.norm_squared();
        let cost = (objective / residual.len() as f64).sqrt();
        if cost_previous.is_finite()
            && cost_previous - cost <= options.stall_fraction * cost_previous
        {
            break;
        }
        cost_previous = cost;
        let (step, kept) = scaled_step(jacobian, &residual, &prior, options)?;
        rank = kept;
        let (accepted, unreachable) =
            halved_until_lower(&model, options, rows, &poses, &step, objective);
        // None lowering it: the fit is done, unless no step could be taken at all because every
        // one left the reach of the geometry.
        let Some(accepted) = accepted else {
            match unreachable {
                Some(e) if iterations == 0 => return Err(ill_conditioned(e, rank, parameters)),
                _ => break,
            }
        };
        model = accepted.model;
        poses = accepted.poses;
        iterations += 1;
        if accepted.step.amax() < options.step_tolerance_mm {
            break;
        }
    }
    let (_, residual) = linearise(&model, options, rows, &mut poses)
        .map_err(|e| ill_conditioned(e, rank, parameters))?;
    Ok(Identification {
        geometry: model.geometry.clone(),
        model,
        iterations,
        rank,
        rms_before_mm: rms_before.unwrap_or(0.0),
        rms_after_mm: (residual.norm_squared() / residual.len() as f64).sqrt(),
    })
}

/// The least-squares step of the stacked residuals and smoothness prior (the SVD of the
/// column-scaled Jacobian, cut at the options' cutoff), in the parameters' units, and the
/// number of directions kept.
fn scaled_step(
    jacobian: DMatrix<f64>,
    residual: &DVector<f64>,
    prior: &SmoothnessPrior,
    options: &IdentifyOptions,
) -> Result<(DVector<f64>, usize)> {
    let ScaledSvd {
        svd,
        scales,
        cutoff,
        ..
    } = scaled_svd(jacobian, &prior.rows, options, true);
    let kept = svd.singular_values.iter().filter(|s| **s > cutoff).count();
    let stacked = DVector::from_iterator(
        residual.len() + prior.residual.len(),
        residual.iter().chain(prior.residual.iter()).copied(),
    );
    let step = svd
        .solve(&stacked, cutoff)
        .map_err(|cause| Error::IdentificationStep { cause })?
        .component_div(&scales);
    Ok((step, kept))
}

/// A step the identification took: the model and poses after it, and the step itself.
struct AcceptedStep {
    model: PhysicalModel,
    poses: Vec<Pose>,
    step: DVector<f64>,
}

/// `step` from `model`, halved (up to ten times) until it lowers `objective` (the residuals'
/// squares and the smoothness prior's) and keeps the legs within the geometry's reach: a
/// direction the data barely sees must not throw the model away. The model, poses and step
/// taken, if any; and the last error of a step that left the geometry's reach.
fn halved_until_lower(
    model: &PhysicalModel,
    options: &IdentifyOptions,
    rows: &[MeasuredConfiguration],
    poses: &[Pose],
    step: &DVector<f64>,
    objective: f64,
) -> (Option<AcceptedStep>, Option<Error>) {
    let mut unreachable = None;
    let accepted = (0..10).find_map(|halvings| {
        let step = step * 0.5f64.powi(halvings);
        let mut trial = model.clone();
        apply(&mut trial, options, &step);
        let mut trial_poses = poses.to_vec();
        match linearise(&trial, options, rows, &mut trial_poses) {
            Ok((_, r))
                if r.norm_squared()
                    + SmoothnessPrior::at(&trial, options).residual.norm_squared()
                    < objective =>
            {
                Some(AcceptedStep {
                    model: trial,
                    poses: trial_poses,
                    step,
                })
            }
            Ok(_) => None,
            Err(e) => {
                unreachable = Some(e);
                None
            }
        }
    });
    (accepted, unreachable)
}

/// The norm of `row`'s target residuals `r_Pm − r_Pc` at `geometry` (the targets seen, or the
/// geometry's targets at a measured pose), mm: how far the
/// targets that `geometry` (an identified one) predicts for the commanded legs are from the
/// measured ones. `None` when `geometry` cannot reach the commanded legs (forward kinematics
/// fails from the commanded pose).
pub fn target_distance(geometry: &Geometry, row: &MeasuredConfiguration) -> Option<f64> {
    let pose =
        forward_kinematics(geometry, &row.legs, &row.pose(), &ForwardOptions::default()).ok()?;
    Some(row.observed.misfit(geometry, &pose).norm())
}

/// The truncated SVD the identification steps with.
pub(crate) struct ScaledSvd {
    /// The SVD of the Jacobian stacked on the smoothness prior's rows, with its columns
    /// divided by `scales`.
    pub svd: SVD<f64, Dyn, Dyn>,
    /// The divisor of each column ([`column_scales`]).
    pub scales: DVector<f64>,
    /// Singular values at or below this are treated as zero (unidentifiable directions).
    pub cutoff: f64,
    /// The Jacobian's rows, the first of `svd`'s (the residuals'; the prior's follow).
    pub data_rows: usize,
}

/// The SVD of `jacobian` stacked on the smoothness prior's `prior_rows` (parameters' columns;
/// none without a prior, [`SmoothnessPrior`]), `U` only when `compute_u`, after the pitch and
/// compliance columns are scaled to the geometric columns' typical norm in `jacobian`, so that
/// `options`' relative cutoff judges what the data can see and not their units; the geometric
/// columns (mm per mm) keep the baseline's minimum-norm answer.
pub(crate) fn scaled_svd(
    jacobian: DMatrix<f64>,
    prior_rows: &DMatrix<f64>,
    options: &IdentifyOptions,
    compute_u: bool,
) -> ScaledSvd {
    let scales = column_scales(&jacobian);
    let data_rows = jacobian.nrows();
    let mut scaled = jacobian.resize_vertically(data_rows + prior_rows.nrows(), 0.0);
    scaled
        .rows_mut(data_rows, prior_rows.nrows())
        .copy_from(prior_rows);
    for (j, scale) in scales.iter().enumerate() {
        scaled.column_mut(j).unscale_mut(*scale);
    }
    let svd = scaled.svd(compute_u, true);
    let cutoff = options.relative_cutoff * svd.singular_values.max();
    ScaledSvd {
        svd,
        scales,
        cutoff,
        data_rows,
    }
}

/// The lead-screw curves' smoothness prior at a model ([`IdentifyOptions::smoothness`]): rows
/// appended to the identification's Jacobian, and their residuals appended to the targets'.
pub(crate) struct SmoothnessPrior {
    /// `√λ` times each second difference's change per unit of each parameter (rows × the
    /// parameters of [`linearise`]'s columns); no row without a prior.
    pub rows: DMatrix<f64>,
    /// `−√λ` times each second difference of the model's coefficients, mm (as the targets'
    /// residuals are measured minus modelled, with nothing measured).
    pub residual: DVector<f64>,
}

impl SmoothnessPrior {
    /// The prior of `options` at `model`'s lead-screw curves: `pitch_basis − 2` second
    /// differences per leg, none when the weight is 0 or no curve is identified. The middle
    /// coefficient, held at 0, enters its differences as the constant it is.
    pub(crate) fn at(model: &PhysicalModel, options: &IdentifyOptions) -> Self {
        let per_leg = options.pitch_basis.saturating_sub(2);
        let count = if options.smoothness > 0.0 {
            LEGS * per_leg
        } else {
            0
        };
        let mut rows = DMatrix::zeros(count, options.parameters());
        let mut residual = DVector::zeros(count);
        if count == 0 {
            return Self { rows, residual };
        }
        let root = options.smoothness.sqrt();
        for leg in 0..LEGS {
            let curve = &model.pitch.coefficients[leg];
            for k in 0..per_leg {
                let row = leg * per_leg + k;
                for (offset, weight) in [1.0, -2.0, 1.0].into_iter().enumerate() {
                    residual[row] -= root * weight * curve[k + offset];
                    if let Some(column) = options.pitch_column(leg, k + offset) {
                        rows[(row, column)] = root * weight;
                    }
                }
            }
        }
        Self { rows, residual }
    }
}

/// The divisor of each column of `jacobian` before the truncated SVD: 1 for the geometric
/// columns, and for the others their norm over the geometric columns' median norm (1 for a
/// column the data does not touch).
fn column_scales(jacobian: &DMatrix<f64>) -> DVector<f64> {
    let norms: Vec<f64> = jacobian.column_iter().map(|c| c.norm()).collect();
    let mut geometric = norms[..PARAMETERS].to_vec();
    geometric.sort_by(f64::total_cmp);
    let typical = geometric[PARAMETERS / 2];
    DVector::from_iterator(
        norms.len(),
        norms.iter().enumerate().map(|(j, n)| {
            if j < PARAMETERS || *n == 0.0 || typical == 0.0 {
                1.0
            } else {
                n / typical
            }
        }),
    )
}

/// `error` of an iterate, with the likely cause when the last step's data determined fewer
/// than all `parameters` combinations (`rank` of them): an ill-conditioned identification
/// drifts into geometries where forward kinematics fails.
fn ill_conditioned(error: Error, rank: usize, parameters: usize) -> Error {
    if rank == 0 || rank >= parameters {
        return error;
    }
    Error::IllConditioned {
        cause: Box::new(error),
        rank,
        parameters,
    }
}

/// The Jacobian `∂r_Pc/∂θ` (3 rows per measured point × the parameters of `options`; per
/// configuration `P·T·G`, Eq. 5 with `ρ = G·δθ`) and the residual `r_Pm − r_Pc` (the `ζ` of
/// Eq. 4) at the current parameters, over every configuration's
/// [`hexacomp_core::observation::Observation::points`] (a measured pose counts as its targets
/// placed at it); `poses` are updated to the model's poses (and seed the next call).
pub(crate) fn linearise(
    model: &PhysicalModel,
    options: &IdentifyOptions,
    rows: &[MeasuredConfiguration],
    poses: &mut [Pose],
) -> Result<(DMatrix<f64>, DVector<f64>)> {
    let geometry = &model.geometry;
    let parameters = options.parameters();
    let points: Vec<Vec<usize>> = rows
        .iter()
        .map(|row| {
            let points = row.observed.points(geometry);
            points.iter().map(|(j, _)| *j).collect()
        })
        .collect();
    let total = 3 * points.iter().map(Vec::len).sum::<usize>();
    let mut jacobian = DMatrix::zeros(total, parameters);
    let mut residual = DVector::zeros(total);
    let mut at = 0;
    for ((row, pose), which) in rows.iter().zip(poses.iter_mut()).zip(&points) {
        *pose = loaded_pose(model, &row.legs, pose).map_err(|cause| Error::Unreachable {
            configuration: row.id.clone(),
            cause: Box::new(cause),
        })?;
        let screws = ActuationScrews::at(geometry, pose);
        let t = screws
            .motion_jacobian()
            .ok_or_else(|| Error::SingularConfiguration {
                configuration: row.id.clone(),
            })?;
        let g = leg_sensitivities(model, options, &row.legs, pose, &screws);
        let t = DMatrix::from_column_slice(LEGS, LEGS, t.as_slice());
        let block = point_matrix(geometry, pose, which) * t * g;
        let height = 3 * which.len();
        jacobian
            .view_mut((at, 0), (height, parameters))
            .copy_from(&block);
        residual
            .rows_mut(at, height)
            .copy_from(&row.observed.misfit(geometry, pose));
        at += height;
    }
    Ok((jacobian, residual))
}

/// Passes at most of [`loaded_pose`]'s fixed point.
const LOADED_POSE_PASSES: usize = 8;

/// The loaded legs' lengths are taken as settled when a pass moves none by more than this, mm:
/// the forward kinematics' own tolerance on the legs (it returns its seed within it).
const LOADED_POSE_TOLERANCE_MM: f64 = 1e-9;

/// The pose `model`'s machine stands at with its legs commanded to `commanded` (mm), from
/// `seed`: the legs' loaded lengths depend on the pose through their sag under the weight, so
/// the two are solved together, each pass the geometry's forward kinematics of the lengths
/// loaded at the last pose (each shrinks the gap by the sag's slope, a small fraction). One
/// pass from a pose far off (a commanded one, 0.7 mm and 0.2° from where the machine stands)
/// left the identification's residuals' squares a quarter above their value: the answer must
/// not depend on where it starts. Why not, where the forward kinematics fails or the passes do
/// not settle (a model whose sag moves faster than the pose: a step the identification halves).
fn loaded_pose(model: &PhysicalModel, commanded: &[f64; LEGS], seed: &Pose) -> Result<Pose> {
    let fk = ForwardOptions::default();
    let kinematics = |lengths: &[f64; LEGS], seed: &Pose| {
        forward_kinematics(&model.geometry, lengths, seed, &fk)
            .map_err(|e| Error::from(e).of("forward kinematics of the identified geometry"))
    };
    let mut lengths = model.loaded_lengths(commanded, seed);
    let mut pose = kinematics(&lengths, seed)?;
    for _ in 0..LOADED_POSE_PASSES {
        let loaded = model.loaded_lengths(commanded, &pose);
        let moved = (0..LEGS).fold(0.0f64, |m, i| m.max((loaded[i] - lengths[i]).abs()));
        if moved <= LOADED_POSE_TOLERANCE_MM {
            return Ok(pose);
        }
        lengths = loaded;
        pose = kinematics(&lengths, &pose)?;
    }
    Err(Error::LoadedPoseUnsettled {
        passes: LOADED_POSE_PASSES,
    })
}

/// `G` at `pose` for legs commanded to `commanded` (mm): row `i` is how far leg `i`'s loaded
/// length (the length the geometry's forward kinematics places the platform with, mm) moves
/// per unit of each parameter (the order of [`linearise`]'s columns), the commanded legs held;
/// `screws` are the model geometry's at `pose`.
pub(crate) fn leg_sensitivities(
    model: &PhysicalModel,
    options: &IdentifyOptions,
    commanded: &[f64; LEGS],
    pose: &Pose,
    screws: &ActuationScrews,
) -> DMatrix<f64> {
    let compliance_columns = PARAMETERS + LEGS * options.pitch_columns();
    let rotation_t = pose.rotation().transpose();
    let mut g = DMatrix::<f64>::zeros(LEGS, options.parameters());
    for i in 0..LEGS {
        let s = screws.directions[i];
        let s_platform = rotation_t * s;
        for axis in 0..3 {
            g[(i, 3 * i + axis)] = s[axis];
            g[(i, 18 + 3 * i + axis)] = -s_platform[axis];
        }
        g[(i, LEG_OFFSET_COLUMNS + i)] = 1.0;
        // A pitch coefficient and a compliance coefficient lengthen the leg as its offset.
        // The middle basis function's coefficient stays 0: the functions sum to one, so
        // with it the curve and the offset could trade a constant.
        for (k, b) in model.pitch.basis_at(commanded[i]).iter().enumerate() {
            if let Some(column) = options.pitch_column(i, k) {
                g[(i, column)] = *b;
            }
        }
    }
    if options.compliance {
        let unloaded: [f64; LEGS] =
            std::array::from_fn(|i| commanded[i] + model.pitch.error(i, commanded[i]));
        let basis = model.compliance_basis(pose, &unloaded);
        for (i, terms) in basis.iter().enumerate() {
            for (m, h) in terms.iter().enumerate() {
                g[(i, compliance_columns + COMPLIANCE_TERMS * i + m)] = -h;
            }
        }
    }
    g
}

/// Adds a parameter step (the order of [`linearise`]'s columns) to the model.
fn apply(model: &mut PhysicalModel, options: &IdentifyOptions, step: &DVector<f64>) {
    let geometry = &mut model.geometry;
    for i in 0..LEGS {
        for axis in 0..3 {
            geometry.base_joints[i][axis] += step[3 * i + axis];
            geometry.platform_joints[i][axis] += step[18 + 3 * i + axis];
        }
        geometry.leg_offsets[i] += step[LEG_OFFSET_COLUMNS + i];
        for (k, c) in model.pitch.coefficients[i].iter_mut().enumerate() {
            if let Some(column) = options.pitch_column(i, k) {
                *c += step[column];
            }
        }
        if options.compliance {
            let first = PARAMETERS + LEGS * options.pitch_columns() + COMPLIANCE_TERMS * i;
            for (m, c) in model.compliance[i].iter_mut().enumerate() {
                *c += step[first + m];
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hexacomp_core::observation::Observation;
    use hexacomp_virtual::{ErrorModel, ErrorVariant, VirtualPlatform};

    /// `count` measurements of one and the same configuration: whatever their number, they
    /// determine only the six parameter combinations that move the platform at that pose.
    fn repeated_configuration(variant: ErrorVariant, count: usize) -> Vec<MeasuredConfiguration> {
        let g = Geometry::prototype();
        let mut platform = VirtualPlatform::new(&g, &ErrorModel::variant(variant), 18, 1).unwrap();
        let pose = Pose::from_mm_deg([10.0, -20.0, 300.0, 4.0, -3.0, 5.0]);
        (0..count)
            .map(|k| {
                let m = platform.measure(&pose).unwrap();
                MeasuredConfiguration {
                    id: (k + 1).to_string(),
                    pose_mm_deg: pose.to_mm_deg(),
                    legs: m.commanded_legs,
                    observed: Observation::Targets(m.targets.into_iter().map(Some).collect()),
                }
            })
            .collect()
    }

    /// The identified minus the nominal parameters, in the order of [`linearise`]'s columns.
    fn parameter_change(identified: &Geometry, nominal: &Geometry) -> DVector<f64> {
        let mut delta = DVector::zeros(PARAMETERS);
        for i in 0..LEGS {
            for axis in 0..3 {
                delta[3 * i + axis] =
                    identified.base_joints[i][axis] - nominal.base_joints[i][axis];
                delta[18 + 3 * i + axis] =
                    identified.platform_joints[i][axis] - nominal.platform_joints[i][axis];
            }
            delta[LEG_OFFSET_COLUMNS + i] = identified.leg_offsets[i] - nominal.leg_offsets[i];
        }
        delta
    }

    /// `count` configurations of the default plan (plan seed 3) measured on the virtual machine
    /// of `variant` (machine seed 1, noise seed 3).
    fn planned_and_measured(
        g: &Geometry,
        variant: ErrorVariant,
        count: usize,
    ) -> Vec<MeasuredConfiguration> {
        let mut platform = VirtualPlatform::new(g, &ErrorModel::variant(variant), 1, 3).unwrap();
        let poses = crate::plan::plan(
            g,
            &crate::plan::PlanOptions {
                count,
                seed: 3,
                ..Default::default()
            },
        )
        .unwrap();
        platform
            .measure_plan(&crate::plan::numbered_rows(&poses))
            .unwrap()
    }

    #[test]
    fn rank_deficient_data_moves_only_the_parameter_combinations_it_determines() {
        let g = Geometry::prototype();
        let rows = repeated_configuration(ErrorVariant::GeometricOnly, 8);
        let result = identify(&g, &rows, &IdentifyOptions::default()).unwrap();
        // Reported, not hidden: six of 42 directions are determined.
        assert_eq!(result.rank, 6, "{result:?}");
        // The measurements are explained (a rigid displacement of the targets)…
        assert!(result.rms_before_mm > 0.1, "{result:?}");
        assert!(result.rms_after_mm < 1e-6, "{result:?}");
        // …by the smallest parameter change that explains them: nothing moves along the 36
        // directions the data cannot see (the null space of ∂r_Pc/∂θ at the nominal geometry).
        let delta = parameter_change(&result.geometry, &g);
        let mut poses: Vec<Pose> = rows.iter().map(MeasuredConfiguration::pose).collect();
        let options = IdentifyOptions::default();
        let (jacobian, _) = linearise(
            &PhysicalModel::geometric(g.clone()),
            &options,
            &rows,
            &mut poses,
        )
        .unwrap();
        let svd = jacobian.svd(false, true);
        let v_t = svd.v_t.unwrap();
        let mut order: Vec<usize> = (0..PARAMETERS).collect();
        order.sort_by(|a, b| svd.singular_values[*b].total_cmp(&svd.singular_values[*a]));
        let unseen = order[6..]
            .iter()
            .map(|&k| v_t.row(k).transpose().dot(&delta).powi(2))
            .sum::<f64>()
            .sqrt();
        assert!(
            delta.norm() > 0.1 && unseen < 1e-4,
            "change {} mm, of which {unseen} mm along unseen directions",
            delta.norm()
        );
        result.geometry.validate().unwrap();
    }

    #[test]
    fn repeated_noisy_measurements_give_a_bounded_geometry_and_a_noise_level_residual() {
        let g = Geometry::prototype();
        let rows = repeated_configuration(ErrorVariant::Paper, 8);
        let result = identify(&g, &rows, &IdentifyOptions::default()).unwrap();
        assert_eq!(result.rank, 6, "{result:?}");
        // The machine's errors are a few tenths of a millimetre: so is the change.
        assert!(
            parameter_change(&result.geometry, &g).amax() < 1.0,
            "{result:?}"
        );
        // 8 readings of 9 coordinates, 6 fitted: what remains is the 12 µm device noise.
        assert!((0.003..0.02).contains(&result.rms_after_mm), "{result:?}");
    }

    #[test]
    fn the_smoothness_prior_is_each_curves_second_differences_and_their_derivative() {
        let options = IdentifyOptions::physical(8).smoothed(0.04);
        let mut model = PhysicalModel::geometric(Geometry::prototype());
        model.pitch = PitchCurves::zero(model.geometry.leg_range, 8);
        // Leg 0 a straight line through the held middle coefficient (k = 4): no curvature.
        // Leg 1 a parabola k² − 16 (0 at k = 4): each second difference 2 mm.
        model.pitch.coefficients[0] = (0..8).map(|k| 0.01 * (k as f64 - 4.0)).collect();
        model.pitch.coefficients[1] = (0..8).map(|k| (k * k) as f64 - 16.0).collect();
        let prior = SmoothnessPrior::at(&model, &options);
        assert_eq!(prior.rows.shape(), (LEGS * 6, options.parameters()));
        let leg = |i: usize| prior.residual.rows(6 * i, 6).into_owned();
        assert!(leg(0).amax() < 1e-15, "{}", leg(0));
        // −√λ · 2 = −0.4 mm, as a residual measured minus modelled.
        assert!(leg(1).iter().all(|r| (r + 0.4).abs() < 1e-12), "{}", leg(1));
        // The rows are the residuals' derivative: a step moves them by −rows · step (the prior is
        // linear in the coefficients), whatever the coefficients it starts from.
        let step = DVector::from_fn(options.parameters(), |j, _| {
            1e-3 * ((j * 7 % 13) as f64 - 6.0)
        });
        let mut stepped = model.clone();
        apply(&mut stepped, &options, &step);
        let moved = SmoothnessPrior::at(&stepped, &options).residual - &prior.residual;
        assert!((moved + &prior.rows * &step).amax() < 1e-12);
        // The geometry's and compliance's columns are not in it.
        assert_eq!(prior.rows.columns(0, PARAMETERS).amax(), 0.0);
        // No weight or no curves: no row.
        assert_eq!(
            SmoothnessPrior::at(&model, &IdentifyOptions::physical(8))
                .rows
                .nrows(),
            0
        );
        assert_eq!(
            SmoothnessPrior::at(&model, &IdentifyOptions::physical(0).smoothed(1.0))
                .rows
                .nrows(),
            0
        );
    }

    #[test]
    fn a_heavy_smoothness_prior_straightens_the_curves_and_a_bad_weight_is_refused() {
        let g = Geometry::prototype();
        let rows = planned_and_measured(&g, ErrorVariant::StrongPitch, 40);
        // The largest second difference of any leg's curve, mm.
        let bend = |smoothness: f64| {
            let options = IdentifyOptions::physical(12).smoothed(smoothness);
            let identified = identify(&g, &rows, &options).unwrap();
            identified
                .model
                .pitch
                .coefficients
                .iter()
                .flat_map(|c| c.windows(3).map(|w| (w[0] - 2.0 * w[1] + w[2]).abs()))
                .fold(0.0, f64::max)
        };
        let free = bend(0.0);
        let held = bend(1e6);
        // The strong robot's curves bend by tens of µm between knots; a prior a million times
        // a residual's weight leaves them straight to well under a µm.
        assert!(free > 0.01, "free curves bend by {free} mm");
        assert!(
            held < 1e-3 * free,
            "held curves bend by {held} mm (free {free} mm)"
        );
        // At a weight where the data and the prior both count, the identification lowers
        // what it is asked to: the targets' squares and the prior's, below where the curves
        // fitted without the prior put them, at a cost in the targets' alone.
        let options = IdentifyOptions::physical(12).smoothed(0.01);
        let objective = |smoothness: f64| {
            let model = identify(&g, &rows, &options.smoothed(smoothness))
                .unwrap()
                .model;
            let mut at: Vec<Pose> = rows.iter().map(MeasuredConfiguration::pose).collect();
            let (_, residual) = linearise(&model, &options, &rows, &mut at).unwrap();
            let prior = SmoothnessPrior::at(&model, &options)
                .residual
                .norm_squared();
            [residual.norm_squared(), prior]
        };
        let [fitted, fitted_bend] = objective(0.0);
        let [held, held_bend] = objective(0.01);
        assert!(
            held + held_bend < 0.9 * (fitted + fitted_bend) && held > fitted,
            "with the prior {held} + {held_bend} mm², without {fitted} + {fitted_bend} mm²"
        );
        for smoothness in [-1.0, f64::NAN, f64::INFINITY] {
            let e = identify(
                &g,
                &rows,
                &IdentifyOptions::physical(12).smoothed(smoothness),
            )
            .unwrap_err()
            .to_string();
            assert!(e.contains("smoothness prior"), "{e}");
        }
    }

    #[test]
    fn the_residuals_of_a_compliant_model_do_not_depend_on_the_pose_they_start_from() {
        let g = Geometry::prototype();
        let rows = planned_and_measured(&g, ErrorVariant::Unseen, 50);
        let options = IdentifyOptions::physical(12);
        let identified = identify(&g, &rows, &options).unwrap();
        // The identified model sags (else the sag cannot depend on the pose).
        assert!(
            identified
                .model
                .compliance
                .iter()
                .flatten()
                .any(|c| *c != 0.0),
            "{:?}",
            identified.model.compliance
        );
        // From the commanded poses (0.7 mm and more from where the machine stands, for this
        // robot), and again from the poses reached.
        let mut seeds: Vec<Pose> = rows.iter().map(MeasuredConfiguration::pose).collect();
        let (_, from_commanded) =
            linearise(&identified.model, &options, &rows, &mut seeds).unwrap();
        let (_, from_reached) = linearise(&identified.model, &options, &rows, &mut seeds).unwrap();
        let rms = |r: &DVector<f64>| (r.norm_squared() / r.len() as f64).sqrt();
        assert!(
            (&from_commanded - &from_reached).amax() < 1e-9,
            "the residuals' RMS is {} mm from the commanded poses, {} mm from the reached",
            rms(&from_commanded),
            rms(&from_reached)
        );
        // And the identification reports the same (to the forward kinematics' tolerance).
        assert!(
            (rms(&from_reached) - identified.rms_after_mm).abs() < 1e-9,
            "{} against {} mm",
            rms(&from_reached),
            identified.rms_after_mm
        );
    }
}
