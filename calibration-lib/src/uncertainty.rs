//! The position uncertainty of a compensated point, propagated from the physical model's
//! identification, and its cheap form for the model file ([`PositionUncertainty`]).
//!
//! **Propagation.** The identification's parameters `θ` move with its residuals as
//! `δθ = B r`, `B = D⁻¹ V_r S_r⁻¹ U_rᵀ` (the truncated SVD of the column-scaled Jacobian
//! `J D⁻¹ = U S Vᵀ` it steps with, stacked on the lead-screw curves' smoothness prior when it
//! has one, `r` the directions it keeps, `U_r` their residuals' rows), and have the covariance
//! `C = B Ω Bᵀ`: `Ω` the residuals', the instrument's noise on every coordinate and the
//! machine's repeatability shared by the targets of a configuration ([`Propagation::of`]).
//! A parameter error `δθ` moves each loaded leg by `G(x)·δθ` at a
//! pose `x` commanded with the model's legs ([`crate::identify`]'s `G`), and the platform by the
//! twist `T·G·δθ` (`T` the motion Jacobian, Eq. 3). Every move adds the leg errors `ε`
//! (variance `w` each: the machine's repeatability, what the model's form misses where the
//! residuals' shape shows it, [`crate::residual_noise`], and for networks their excess error
//! over the model's): the pose-error twist has the covariance `T (G C Gᵀ + w I) Tᵀ`, and the position
//! error its upper-left 3 × 3 block `Σ`.
//!
//! Two approximations: `J` holds the pose while a parameter moves the legs, not the sag's
//! change with the pose it moves to (a slope of about 1e-2: `B` about 1 % off); and with a
//! smoothness prior, the curvature the prior takes off the curves stays in the penalised fit's
//! residuals and is counted as noise in its `Ω` (`σ²`, and `v` where the repeatability is
//! assumed, a little high: `C` errs wide, and so does `N` below, which shrinks the prior's
//! bias more: that side errs narrow); the leg variance at a fresh move is the unpenalised
//! fit's.
//!
//! **The smoothness prior's bias.** The prior holds the curves' noise back and bends them
//! toward straight lines: a bias `C` does not hold. The same resolution identified without
//! the prior has none; were the machine as it says, this model's commands would miss by `d`,
//! of which the two fits' noise explains a part. That miss, shrunk as the alternatives' is,
//! takes this model's own place among the forms (whole where there is no alternative), and
//! the legs' variance at a fresh move is the unpenalised fit's, whose residuals do not hold
//! the curvature the prior took off ([`Propagation::with_prior_bias`]).
//!
//! **The resolutions the data cannot tell apart.** The covariance holds the parameters' noise,
//! not the model's form: where the cross-validation could not tell other lead-screw
//! resolutions from the chosen one (each identified on every configuration,
//! [`crate::pitch_resolution::identified_on_every_configuration`]), each is taken equally
//! likely, and the spread of the legs' errors a machine of its form would make under the
//! chosen model's commands, shrunk by what the two fits' own noise explains, is added
//! ([`Propagation::position_covariances`]): `d dᵀ` of each miss `d`, scaled by `(1 − p/s)₊`, `s`
//! its squared Mahalanobis length over the `p` directions of that noise.
//!
//! **One σ.** `Σ` is anisotropic; the uncertainty reported is the one-dimensional equivalent
//! `σ` with `P(‖δ‖ ≤ 2σ) = 95.45 %` (what `2σ` covers in one dimension): `‖δ‖²` is a weighted
//! sum of χ²₁ variables, approximated by a scaled χ² with the same mean and variance (Patnaik),
//! whose quantile the Wilson–Hilferty transformation gives.
//!
//! **Cheap form.** `σ²` is computed at poses over the measured range and fitted as
//! `a + b · h(q)`, `h` the leverage of the nominal legs among the configurations'
//! ([`hexacomp_core::uncertainty`]): inside the measured range the propagation decides the
//! level, outside it the leverage's growth (where the truncated covariance cannot: directions
//! the data does not see carry no variance in it).
//!
//! Units: mm.

use hexacomp_core::observation::Observation;
use hexacomp_core::records::MeasuredConfiguration;
use hexacomp_core::screw::ActuationScrews;
use hexacomp_core::uncertainty::{FEATURES, PositionUncertainty, WHITENING_ENTRIES};
use hexacomp_core::{Geometry, LEGS, Pose};
use nalgebra::{DMatrix, Matrix3, SMatrix};

use crate::error::{Error, Result};
use crate::identify::{
    IdentifyOptions, LEG_OFFSET_COLUMNS, ScaledSvd, SmoothnessPrior, leg_sensitivities, linearise,
    scaled_svd,
};
use crate::measured_range::{draw, measured_range};
use crate::residual_noise::{ResidualNoise, ShapeSplit, expected_squares, split_by_shape};
use hexacomp_core::physical::PhysicalModel;

/// A repeatability is refused when its expected share of the residuals' variance is more than
/// this many times what they hold: far beyond their own scatter (of 40 draws of a machine
/// repeating within 0.02 mm, 40 configurations each, one held 0.98 of it, a repeatability of
/// 0.0198 mm: `tests::the_propagated_covariances_…`, which fails if the share is refused at
/// once).
const REPEATABILITY_EXCESS_REFUSED: f64 = 2.0;

/// The machine's repeatability the uncertainty is propagated with: σ of one leg's length error
/// at every move, mm, and whether it is the machine's.
///
/// Where the residuals' shape shows the platform moving by more than it
/// ([`crate::residual_noise`]), the excess is either what the model's form misses or a
/// repeatability the machine does not reach, and no data tells the two apart. A misfit moves the
/// identified parameters little (the model's columns cannot fit it), a repeatability as much as
/// any noise does: a known repeatability makes the excess the misfit, an assumed one is not
/// trusted over the residuals, and the excess moves the parameters too.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Repeatability {
    /// The machine's, given by its user (or the virtual machine's own), mm.
    Known(f64),
    /// Assumed for want of the machine's (a default), mm.
    Assumed(f64),
}

impl Repeatability {
    /// σ of one leg's length error at every move, mm.
    pub fn sigma_mm(self) -> f64 {
        match self {
            Self::Known(mm) | Self::Assumed(mm) => mm,
        }
    }
}

/// Poses drawn over the measured range that the uncertainty is fitted at (the configurations'
/// own are added).
pub const FIT_POSES: usize = 300;

/// The normal quantile of 95.45 % (`Φ⁻¹(0.9545)`): `2σ` covers that share in one dimension.
const NORMAL_QUANTILE: f64 = 1.690_6;

/// The identified physical model with its parameters' covariance.
#[derive(Debug, Clone)]
pub struct Propagation {
    model: PhysicalModel,
    options: IdentifyOptions,
    /// `B = F U_rᵀ` (`U_r` the residuals' rows): the parameters' change per mm of each
    /// residual (the identification's columns × its residuals).
    estimator: DMatrix<f64>,
    /// The residuals' covariance `Ω`.
    noise: ResidualNoise,
    /// `w`, the variance of each leg's length at a fresh move: the repeatability, and what the
    /// model's form misses, where the residuals' shape shows more than the repeatability
    /// ([`crate::residual_noise`]), mm².
    leg_variance_mm2: f64,
    /// The repeatability's variance taken (an assumed one no more than all the residuals
    /// hold), mm².
    repeatability_variance_mm2: f64,
    /// The residuals' variance told apart by shape, where it can be.
    split: Option<ShapeSplit>,
    /// `C = B Ω Bᵀ`, mm² per unit² of the parameters.
    covariance: DMatrix<f64>,
    /// The same resolution identified from the same rows without the smoothness prior, where
    /// this model has one ([`Self::with_prior_bias`]): its miss beyond the two fits' noise is
    /// the prior's bias.
    unpenalised: Option<Box<Propagation>>,
}

/// The residuals' variances a [`Propagation`] takes, mm².
#[derive(Debug, Clone, Copy, PartialEq)]
struct Variances {
    /// `v` of the repeatability, per leg and move: what the other two are taken against.
    repeatability: f64,
    /// `σ²` of `Ω`, per coordinate.
    instrument: f64,
    /// `v` of `Ω`, per leg and configuration: what moved the platform and the parameters with it.
    moving_parameters: f64,
    /// `w`, per leg at a fresh move.
    fresh_move: f64,
}

/// Refuses a repeatability that is not a finite σ ≥ 0 (mm), options out of range, and options
/// of another lead-screw resolution than `model`'s.
fn check_propagation_inputs(
    model: &PhysicalModel,
    options: &IdentifyOptions,
    repeatability: Repeatability,
) -> Result<()> {
    let repeatability_mm = repeatability.sigma_mm();
    if !(repeatability_mm.is_finite() && repeatability_mm >= 0.0) {
        return Err(Error::OutOfRange {
            setting: "the machine's repeatability (1 σ, mm)",
            value: repeatability_mm,
            valid: "must be finite and ≥ 0",
        });
    }
    options.validate()?;
    if options.pitch_basis != model.pitch.basis() {
        return Err(Error::ResolutionMismatch {
            model: model.pitch.basis(),
            options: options.pitch_basis,
        });
    }
    Ok(())
}

/// The identification's Jacobian factorised for the propagation.
struct Factorised {
    /// The residuals' rows of `U_r` (the kept directions): the hat matrix is `U_r U_rᵀ` of
    /// them, a projection without a smoothness prior (then `Uᵀ U = I`), not with one.
    u: DMatrix<f64>,
    /// `F = D⁻¹ V_r S_r⁻¹`: the parameters' change per unit of each kept direction.
    factor: DMatrix<f64>,
    /// How many directions are kept (above the SVD's cutoff).
    kept: usize,
}

/// The scaled SVD of `jacobian` stacked on the smoothness prior's `prior_rows`, cut as the
/// identification cuts it.
fn factorised(
    jacobian: DMatrix<f64>,
    prior_rows: &DMatrix<f64>,
    options: &IdentifyOptions,
) -> Factorised {
    let ScaledSvd {
        svd,
        scales,
        cutoff,
        data_rows,
    } = scaled_svd(jacobian, prior_rows, options, true);
    let kept: Vec<usize> = (0..svd.singular_values.len())
        .filter(|k| svd.singular_values[*k] > cutoff)
        .collect();
    let u = svd
        .u
        .expect("U was asked for")
        .rows(0, data_rows)
        .select_columns(&kept);
    let v_t = svd.v_t.expect("V was asked for");
    let mut factor = DMatrix::zeros(scales.len(), kept.len());
    for (column, &k) in kept.iter().enumerate() {
        let inverse = 1.0 / svd.singular_values[k];
        for j in 0..scales.len() {
            factor[(j, column)] = v_t[(k, j)] * inverse / scales[j];
        }
    }
    Factorised {
        u,
        factor,
        kept: kept.len(),
    }
}

/// Each configuration's block of residual rows: (first row, height), three rows per target
/// point it holds.
fn target_blocks(rows: &[MeasuredConfiguration], geometry: &Geometry) -> Vec<(usize, usize)> {
    let mut blocks = Vec::with_capacity(rows.len());
    let mut at = 0;
    for row in rows {
        let height = 3 * row.observed.points(geometry).len();
        blocks.push((at, height));
        at += height;
    }
    blocks
}

/// The repeatability the propagation takes, and its variance (mm²), from the residuals'
/// squares `held` and their expected squares per unit of the repeatability's variance `share`.
/// An assumed repeatability is not trusted over the residuals: at most all they hold. A known
/// one whose share is more than twice what they hold is refused, naming the one that would be
/// all of it.
fn repeatability_taken(
    repeatability: Repeatability,
    held: f64,
    share: f64,
) -> Result<(Repeatability, f64)> {
    let repeatability_mm = repeatability.sigma_mm();
    let (machine, variance) = match repeatability {
        Repeatability::Known(_) => (repeatability, repeatability_mm.powi(2)),
        Repeatability::Assumed(_) => {
            let taken = repeatability_mm.powi(2).min(held / share);
            (Repeatability::Assumed(taken.sqrt()), taken)
        }
    };
    if variance * share > REPEATABILITY_EXCESS_REFUSED * held {
        return Err(Error::RepeatabilityTooLarge {
            repeatability_mm,
            all_of_it_um: 1e3 * (held / share).sqrt(),
        });
    }
    Ok((machine, variance))
}

/// The variances of residuals whose shape split them as `split` (where it could), on a machine
/// of `repeatability`: `all_platform_mm2` is the platform's variance per leg that all of the
/// residuals would be (`‖r‖² / tr((I − H) K Kᵀ (I − H))`), `unsplit_mm2` the instrument's that
/// all they hold beyond the repeatability's share would be ([`Propagation::of`]).
fn variances(
    split: Option<ShapeSplit>,
    repeatability: Repeatability,
    all_platform_mm2: f64,
    unsplit_mm2: f64,
) -> Variances {
    let given = repeatability.sigma_mm().powi(2);
    let (instrument, platform) = match split {
        // A negative instrument's variance: all of the residuals are the platform's, as far as
        // they hold more than the repeatability's share (the limit of a split whose
        // instrument's variance falls to zero).
        Some(split) if split.instrument_variance_mm2 < 0.0 => (0.0, all_platform_mm2.max(given)),
        Some(split) if split.platform_variance_mm2 > given => {
            (split.instrument_variance_mm2, split.platform_variance_mm2)
        }
        _ => (unsplit_mm2, given),
    };
    Variances {
        repeatability: given,
        instrument,
        // Beyond a known repeatability, the form's misfit; beyond an assumed one, maybe the
        // machine's own repeatability, which moves the parameters.
        moving_parameters: match repeatability {
            Repeatability::Known(_) => given,
            Repeatability::Assumed(_) => platform,
        },
        fresh_move: platform,
    }
}

impl Propagation {
    /// The covariance of `model`, identified from `rows` with `options`, at its parameters, on
    /// a machine whose legs repeat within `repeatability` (1 σ of each leg's length at every
    /// move, mm).
    ///
    /// The residuals are not independent: a configuration's repeatability moves the platform,
    /// and so every target measured there, together (`K_c ε`, `K_c` how the targets move per mm
    /// of each leg: the leg offsets' columns, `LEG_OFFSET_COLUMNS`). Their covariance is
    /// `Ω = σ² I + v Σ_c K_c K_cᵀ` (`v` the repeatability's variance, `σ²` the rest per
    /// coordinate: the instrument's noise, and what the model's form misses unless split
    /// below), and the
    /// estimate's change `δθ = B r` (`B = F U_rᵀ`, `F = D⁻¹ V_r S_r⁻¹`; with a smoothness prior
    /// the SVD is of the Jacobian stacked on the prior's rows, `U_r` the residuals' rows of its
    /// kept directions, and the hat matrix `H = U_r U_rᵀ` no projection) has the covariance
    /// `B Ω Bᵀ`. `σ²` is what the residuals hold beyond the repeatability's
    /// expected share: `E‖r‖² = σ² tr((I − H)²) + v tr((I − H) K Kᵀ (I − H))`
    /// (`tr((I − H)²) = m − r` without a prior), and 0 where the
    /// residuals hold less than that share, as their noise lets them when the instrument's is
    /// small. A known repeatability whose share is more than twice what they hold is refused
    /// (it is not the machine's), naming the one that would be all of it; an assumed one is
    /// taken as no more than all of it.
    ///
    /// Where the residuals' shape shows the platform moved by more than the repeatability
    /// ([`crate::residual_noise`]: a variance `w > v` per leg and configuration, beside the
    /// instrument's `σ²` per coordinate), `σ²` is the instrument's alone and `w` the legs'
    /// variance at a fresh move. Beyond a [`Repeatability::Known`] the rest is what the
    /// model's form misses at the configurations, and stays out of `Ω`: it is what the
    /// model's columns cannot fit, which moves its parameters little, not noise that moves
    /// them. Beyond a [`Repeatability::Assumed`] it may be the machine's own repeatability,
    /// and `Ω` holds `w` in `v`'s place. A split whose instrument's variance comes out negative
    /// is taken at its limit: no instrument's noise, all of the residuals the platform's.
    pub fn of(
        model: &PhysicalModel,
        options: &IdentifyOptions,
        rows: &[MeasuredConfiguration],
        repeatability: Repeatability,
    ) -> Result<Self> {
        check_propagation_inputs(model, options, repeatability)?;
        let mut poses: Vec<Pose> = rows.iter().map(MeasuredConfiguration::pose).collect();
        let (jacobian, residual) = linearise(model, options, rows, &mut poses)?;
        let moves = jacobian.columns(LEG_OFFSET_COLUMNS, LEGS).into_owned();
        let prior = SmoothnessPrior::at(model, options);
        let Factorised { u, factor, kept } = factorised(jacobian, &prior.rows, options);
        let blocks = target_blocks(rows, &model.geometry);
        // The residuals' expected squares per unit of σ² (tr((I − H)²): m − r without a prior)
        // and of the repeatability's variance.
        let [freedom, share] = expected_squares(&u, &moves, &blocks);
        // (Half a degree: without a prior the count is whole, to rounding. With one, the prior
        // may see directions the residuals do not: as many residuals as directions are refused
        // all the same.)
        if freedom < 0.5 || residual.len() <= kept {
            return Err(Error::NoDegreesOfFreedom {
                residuals: residual.len(),
                kept,
                freedom,
            });
        }
        let held = residual.norm_squared();
        let (machine, repeatability) = repeatability_taken(repeatability, held, share)?;
        // What the residuals hold beyond the repeatability's share, all taken as the
        // instrument's where their shape cannot tell more.
        let unsplit = ((held - repeatability * share) / freedom).max(0.0);
        // A pose measured places its targets with its noise in the platform's directions.
        let targets_measured = rows
            .iter()
            .all(|row| matches!(row.observed, Observation::Targets(_)));
        let split = targets_measured
            .then(|| split_by_shape(&residual, &u, &moves, &blocks))
            .flatten();
        // (The flags of `UncertaintySource` compare with the repeatability these were chosen
        // against, not with `repeatability`: an assumed one's σ squared again may differ in
        // the last bit.)
        let Variances {
            repeatability: repeatability_variance_mm2,
            instrument,
            moving_parameters,
            fresh_move: leg_variance_mm2,
        } = variances(split, machine, held / share, unsplit);
        let noise = ResidualNoise {
            instrument_variance_mm2: instrument,
            repeatability_variance_mm2: moving_parameters,
            moves,
            blocks,
        };
        let estimator = factor * u.transpose();
        Ok(Self {
            leg_variance_mm2,
            repeatability_variance_mm2,
            split,
            model: model.clone(),
            options: *options,
            covariance: noise.sandwich(&estimator),
            estimator,
            noise,
            unpenalised: None,
        })
    }

    /// This propagation, of a model identified with a smoothness prior, with `unpenalised`:
    /// the same resolution identified from the same rows with the same options but the prior.
    /// The prior trades the curves' noise for a bias toward straight curves, which `C` does
    /// not hold; the unpenalised estimate has none, so were the machine as it says, the legs
    /// this model commands would stand off by its miss `d` ([`Self::position_covariances`]),
    /// less the two fits' own noise. That miss beyond the noise takes this model's own place
    /// among the forms the alternatives' spread weighs (where the machine has this model's
    /// form, it is the error its commands make), and whole where there is no alternative.
    /// Refused for a model without a prior, or an `unpenalised` whose options are not these
    /// without it, or identified from other rows (another count of residuals).
    pub fn with_prior_bias(self, unpenalised: Propagation) -> Result<Self> {
        if self.options.smoothness <= 0.0
            || unpenalised.options != self.options.smoothed(0.0)
            || unpenalised.residuals() != self.residuals()
        {
            return Err(Error::PriorReferenceMismatch {
                model: (
                    self.options.pitch_basis,
                    self.options.smoothness,
                    self.residuals(),
                ),
                reference: (
                    unpenalised.options.pitch_basis,
                    unpenalised.options.smoothness,
                    unpenalised.residuals(),
                ),
            });
        }
        Ok(Self {
            unpenalised: Some(Box::new(unpenalised)),
            ..self
        })
    }

    /// The covariance of the position error (mm², base-frame axes) at `pose` commanded with
    /// the model's legs, in two parts: what the parameters' uncertainty and the choice among
    /// `alternatives` give, and what one mm² of independent leg variance at every move gives
    /// (mm² per mm²); `Σ` is the first plus the leg variance times the second. `None` at a
    /// singular pose.
    ///
    /// `alternatives` are models identified from the same configurations that the data could
    /// not tell from this one (other lead-screw resolutions within the cross-validation's
    /// noise): had the machine been alternative `k`'s, the legs commanded by this model would
    /// stand loaded at `L_k(q)` where the pose needs `l_k` (its geometry's inverse
    /// kinematics), off by `d_k = L_k(q) − l_k`. Part of `d_k` is the two fits' own noise, not
    /// the choice: the difference of their estimates' moves, `A_k = G_k B_k − G B`, has the
    /// covariance `N_k = A_k Ω A_kᵀ`. `d_k d_kᵀ` shrunk by that noise (by `(1 − p/s)₊`,
    /// `s = d_kᵀ N_k⁻¹ d_k`, `p` the directions `N_k` holds: `s − p` estimates `s`'s share
    /// beyond the noise),
    /// over the `K` alternatives and this model taken as equally likely (`/ (K + 1)`), is
    /// added to the legs' covariance. Where the model has a smoothness prior, its own form's
    /// share is not zero but the miss to the same resolution without the prior, so shrunk:
    /// the prior's bias ([`Self::with_prior_bias`]).
    pub fn position_covariances(
        &self,
        pose: &Pose,
        alternatives: &[Propagation],
    ) -> Option<(Matrix3<f64>, Matrix3<f64>)> {
        let geometry = &self.model.geometry;
        let commanded = self.model.command(pose);
        let screws = ActuationScrews::at(geometry, pose);
        let t = screws.motion_jacobian()?;
        let g = leg_sensitivities(&self.model, &self.options, &commanded, pose, &screws);
        let legs = &g * &self.covariance * g.transpose();
        let mut legs = SMatrix::<f64, LEGS, LEGS>::from_iterator(legs.iter().copied());
        let choices = (alternatives.len() + 1) as f64;
        if !alternatives.is_empty() || self.unpenalised.is_some() {
            let own = &g * &self.estimator;
            // Each alternative's miss holds the prior's bias too: it is measured under this
            // model's commands. Its own form's share is the bias alone.
            for form in self.unpenalised.as_deref().into_iter().chain(alternatives) {
                let (d, fits) = self.miss_of(form, pose, &commanded, &own);
                legs += beyond_noise(&d, &fits) / choices;
            }
        }
        let position = |m: SMatrix<f64, LEGS, LEGS>| {
            (t * m * t.transpose())
                .fixed_view::<3, 3>(0, 0)
                .into_owned()
        };
        Some((position(legs), position(SMatrix::identity())))
    }

    /// `d_k` and `N_k` of `alternative` (another resolution, or this one without the prior) at
    /// `pose` (mm, mm²; [`Self::position_covariances`]):
    /// legs `commanded` by this model, whose estimate moves them there by `own = G B` per mm
    /// of each residual.
    fn miss_of(
        &self,
        alternative: &Propagation,
        pose: &Pose,
        commanded: &[f64; LEGS],
        own: &DMatrix<f64>,
    ) -> (SMatrix<f64, LEGS, 1>, SMatrix<f64, LEGS, LEGS>) {
        let model = &alternative.model;
        let loaded = model.loaded_lengths(commanded, pose);
        let needed = hexacomp_core::inverse_kinematics(&model.geometry, pose).lengths;
        let d = SMatrix::<f64, LEGS, 1>::from_fn(|i, _| loaded[i] - needed[i]);
        let screws = ActuationScrews::at(&model.geometry, pose);
        let g_k = leg_sensitivities(model, &alternative.options, commanded, pose, &screws);
        let fits = self.noise.sandwich(&(g_k * &alternative.estimator - own));
        (d, SMatrix::from_iterator(fits.iter().copied()))
    }

    /// The fit that stands for this model's form: the same identification without the
    /// smoothness prior where it has one ([`Self::with_prior_bias`]), else this one.
    fn own_form(&self) -> &Propagation {
        self.unpenalised.as_deref().unwrap_or(self)
    }

    /// The number of residuals the model was identified from (three per measured point).
    fn residuals(&self) -> usize {
        self.estimator.ncols()
    }
}

/// Eigenvalues of a noise covariance below this share of its largest are directions it does
/// not hold: they are counted at this share, so a miss along them is not noise.
const NOISE_RANK_TOLERANCE: f64 = 1e-12;

/// What of a miss `d` (mm, one per leg) is beyond `noise`, the covariance of the part of it
/// that is noise (mm²): `d dᵀ (1 − p/s)₊`, `s = dᵀ N⁻¹ d` the miss's squared Mahalanobis length
/// and `p` the directions the noise holds. Were `d = δ + e`, `e ~ N(0, N)`, `s` would average
/// `p + δᵀN⁻¹δ`: the estimate keeps `s − p` of it (the signal's share in the noise's metric),
/// along `d`, and nothing where the noise explains the whole miss. A miss along directions the
/// noise does not hold is kept, and without noise (`p = 0`) all of `d dᵀ`. NaN where the
/// noise is not finite. (Taking `N` away from `d dᵀ` and keeping the positive part instead
/// keeps about five of the six a pure noise miss holds in that metric: `d dᵀ` is of rank
/// one, `N` spreads over six directions.)
fn beyond_noise(
    d: &SMatrix<f64, LEGS, 1>,
    noise: &SMatrix<f64, LEGS, LEGS>,
) -> SMatrix<f64, LEGS, LEGS> {
    if !noise.iter().all(|v| v.is_finite()) {
        // nalgebra's eigendecomposition does not return on a NaN.
        return SMatrix::from_element(f64::NAN);
    }
    let eigen = noise.symmetric_eigen();
    let floor = NOISE_RANK_TOLERANCE * eigen.eigenvalues.max();
    let directions = eigen.eigenvalues.iter().filter(|&&v| v > floor).count();
    let kept = if directions == 0 {
        1.0
    } else {
        let squared: f64 = eigen
            .eigenvalues
            .iter()
            .enumerate()
            .map(|(k, &variance)| eigen.eigenvectors.column(k).dot(d).powi(2) / variance.max(floor))
            .sum();
        (1.0 - directions as f64 / squared).max(0.0)
    };
    d * d.transpose() * kept
}

/// The one-dimensional-equivalent σ of a zero-mean normal position error with covariance
/// `sigma` (mm²): `P(‖δ‖ ≤ 2σ) ≈ 95.45 %`, mm. 0 for a zero covariance, NaN for one that is
/// not finite.
pub fn one_sigma_mm(sigma: &Matrix3<f64>) -> f64 {
    // The eigen-decomposition does not end on a matrix that is not finite.
    if !sigma.iter().all(|v| v.is_finite()) {
        return f64::NAN;
    }
    let eigen = sigma.symmetric_eigen().eigenvalues.map(|l| l.max(0.0));
    let sum = eigen.sum();
    let squares = eigen.norm_squared();
    if sum <= 0.0 {
        return 0.0;
    }
    // ‖δ‖² ≈ a · χ²_ν with the same mean (Σλ) and variance (2Σλ²).
    let scale = squares / sum;
    let freedom = sum * sum / squares;
    let w = 2.0 / (9.0 * freedom);
    let quantile = freedom * (1.0 - w + NORMAL_QUANTILE * w.sqrt()).powi(3);
    (scale * quantile).sqrt() / 2.0
}

/// Where the platform's variance the residuals' shape shows beyond the repeatability was taken
/// ([`Propagation::of`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BeyondRepeatability {
    /// The model's or an alternative's residuals moved the platform by more than the
    /// repeatability: every fresh move takes it. (The model's own: those of its fit without
    /// the smoothness prior, where it has one, as in the leg variance.)
    pub at_fresh_moves: bool,
    /// The model's excess moved its identified parameters too (`Ω`): the repeatability was
    /// assumed, and the excess may be the machine's own. (The model's own fit, with its prior:
    /// the parameters' covariance is its.)
    pub moving_parameters: bool,
}

/// What a model file's uncertainty is fitted from: a physical model's [`Propagation`] at the
/// configurations it was identified from and at poses over their legs' range, and the leverage
/// among the configurations' nominal legs.
#[derive(Debug, Clone)]
pub struct UncertaintySource {
    /// `w` of the model's [`Propagation`] (of its fit without the smoothness prior, where it
    /// has one) and its alternatives', averaged (each form taken as equally likely), mm².
    leg_variance_mm2: f64,
    /// The model's residuals' variance told apart by shape, where it can be (of its fit
    /// without the smoothness prior, where it has one, as the leg variance).
    split: Option<ShapeSplit>,
    /// What the leg variance holds beyond the repeatability, and where.
    beyond: BeyondRepeatability,
    /// The smoothness prior's bias is in the covariances ([`Propagation::with_prior_bias`]).
    prior_bias: bool,
    /// The leverage's normalisation and whitening (variances zero).
    leverage: PositionUncertainty,
    /// At each pose the propagation is defined at: its leverage, and the position covariance's
    /// two parts ([`Propagation::position_covariances`]).
    samples: Vec<(f64, Matrix3<f64>, Matrix3<f64>)>,
    /// The poses: the configurations' and [`FIT_POSES`] more.
    poses: usize,
}

/// `propagation` with the smoothness prior's bias bounded by `without_prior`, the same
/// resolution identified from `rows` without the prior ([`Propagation::with_prior_bias`]):
/// refused missing beside `options` with a prior, and given beside options without one.
fn with_prior_bounded(
    propagation: Propagation,
    without_prior: Option<&PhysicalModel>,
    options: &IdentifyOptions,
    rows: &[MeasuredConfiguration],
    repeatability: Repeatability,
) -> Result<Propagation> {
    match without_prior {
        // `with_prior_bias` refuses it beside a model without a prior.
        Some(unpenalised) => {
            let of = Propagation::of(unpenalised, &options.smoothed(0.0), rows, repeatability)
                .map_err(|e| {
                    e.of("the model without its smoothness prior, which bounds the prior's bias")
                })?;
            propagation.with_prior_bias(of)
        }
        None if options.smoothness > 0.0 => Err(Error::PriorReferenceMissing {
            smoothness: options.smoothness,
        }),
        None => Ok(propagation),
    }
}

/// The propagation of each of `alternatives`, identified from `rows` at its own resolution
/// ([`IdentifyOptions::physical`]); an error names the alternative.
fn alternatives_propagated(
    alternatives: &[PhysicalModel],
    rows: &[MeasuredConfiguration],
    repeatability: Repeatability,
) -> Result<Vec<Propagation>> {
    alternatives
        .iter()
        .map(|alternative| {
            let options = IdentifyOptions::physical(alternative.pitch.basis());
            Propagation::of(alternative, &options, rows, repeatability).map_err(|e| {
                e.of(format!(
                    "the alternative of {} lead-screw coefficients per leg",
                    options.pitch_basis
                ))
            })
        })
        .collect()
}

impl UncertaintySource {
    /// The source of `model`, identified from `rows` with `options` on `nominal` whose legs
    /// repeat within `repeatability` ([`Propagation::of`]), beside `alternatives` identified
    /// from the same rows, which they could not tell from it (each with
    /// [`IdentifyOptions::physical`] at its own resolution, as the cross-validation scored them,
    /// [`Propagation::position_covariances`]), and `without_prior`, the same resolution
    /// identified from the same rows without the smoothness prior, which bounds the prior's
    /// bias ([`Propagation::with_prior_bias`]): given exactly where `options` have a prior,
    /// refused otherwise. The poses over the measured range are drawn with `seed`.
    ///
    /// `without_prior` is trusted to be that identification (as
    /// [`crate::pitch_resolution::identified_on_every_configuration`] makes it with
    /// `options.smoothed(0.0)`): its resolution is checked, but another model of the same
    /// resolution, the penalised one itself included, is not told from it, and would leave
    /// the prior's bias out.
    pub fn new(
        nominal: &Geometry,
        (model, options): (&PhysicalModel, &IdentifyOptions),
        without_prior: Option<&PhysicalModel>,
        alternatives: &[PhysicalModel],
        rows: &[MeasuredConfiguration],
        repeatability: Repeatability,
        seed: u64,
    ) -> Result<Self> {
        let propagation = Propagation::of(model, options, rows, repeatability)?;
        let propagation =
            with_prior_bounded(propagation, without_prior, options, rows, repeatability)?;
        let alternatives = alternatives_propagated(alternatives, rows, repeatability)?;
        // The same rows, each with as many targets whatever the geometry.
        debug_assert!(
            alternatives
                .iter()
                .all(|of| of.residuals() == propagation.residuals())
        );
        let measured: Vec<Pose> = rows.iter().map(MeasuredConfiguration::pose).collect();
        let nominal_legs = |pose: &Pose| hexacomp_core::inverse_kinematics(nominal, pose).lengths;
        let configurations: Vec<[f64; LEGS]> = measured.iter().map(nominal_legs).collect();
        let leverage = leverage_of(&configurations)?;
        let range = measured_range(nominal, &measured);
        let mut poses = measured;
        poses.extend(draw(nominal, &range, FIT_POSES, seed)?);
        let samples = poses
            .iter()
            .filter_map(|pose| {
                let (parameters, legs) = propagation.position_covariances(pose, &alternatives)?;
                Some((leverage.leverage(&nominal_legs(pose)), parameters, legs))
            })
            .collect();
        // Each form taken as equally likely, as in the spread between them: had the machine
        // been alternative k's, what the form misses would be k's. The model's own form is
        // its fit without the prior where it has one (whose residuals do not hold the
        // curvature the prior took off: that is its bias, in the spread's own share).
        let forms = || std::iter::once(propagation.own_form()).chain(&alternatives);
        let leg_variance_mm2 = forms().map(|form| form.leg_variance_mm2).sum::<f64>()
            / (alternatives.len() + 1) as f64;
        let beyond = BeyondRepeatability {
            at_fresh_moves: forms().any(|of| of.leg_variance_mm2 > of.repeatability_variance_mm2),
            moving_parameters: propagation.noise.repeatability_variance_mm2
                > propagation.repeatability_variance_mm2,
        };
        Ok(Self {
            leg_variance_mm2,
            split: propagation.own_form().split,
            beyond,
            prior_bias: propagation.unpenalised.is_some(),
            leverage,
            samples,
            poses: poses.len(),
        })
    }

    /// The variance of each leg's length at a fresh move the uncertainty is fitted with: `w`
    /// of the model's [`Propagation`] (of its fit without the smoothness prior, where it has
    /// one) and of its alternatives', averaged, mm².
    pub fn leg_variance_mm2(&self) -> f64 {
        self.leg_variance_mm2
    }

    /// The model's residuals' variance told apart by shape (of its fit without the smoothness
    /// prior, where it has one): the instrument's per coordinate,
    /// the platform's per leg and configuration ([`crate::residual_noise`]);
    /// `None` where the measurements cannot tell them apart.
    pub fn shape_split(&self) -> Option<ShapeSplit> {
        self.split
    }

    /// What [`Self::leg_variance_mm2`] holds beyond the repeatability, and where.
    pub fn beyond_repeatability(&self) -> BeyondRepeatability {
        self.beyond
    }

    /// Whether the covariances hold the model's smoothness prior's bias (a model identified
    /// with a prior, [`Propagation::with_prior_bias`]).
    pub fn holds_prior_bias(&self) -> bool {
        self.prior_bias
    }

    /// The model file's uncertainty for networks that depart from the model by independent
    /// leg errors of variance `departure_variance_mm2` (mm²) at every move, beside the model's
    /// own `w` ([`Propagation`]): the leverage among the configurations' nominal legs, its two
    /// variances fitted, relative to the fit (`relative_fit`), to the propagated `σ²` at the
    /// poses.
    pub fn fitted(&self, departure_variance_mm2: f64) -> Result<PositionUncertainty> {
        let leg_variance_mm2 = self.leg_variance_mm2 + departure_variance_mm2;
        let samples: Vec<(f64, f64)> = self
            .samples
            .iter()
            .map(|(h, parameters, legs)| {
                (*h, one_sigma_mm(&(parameters + legs * leg_variance_mm2)))
            })
            .filter(|(_, s)| *s > 0.0)
            .map(|(h, s)| (h, s * s))
            .collect();
        if samples.len() < 2 {
            return Err(Error::TooFewUncertaintyPoses {
                usable: samples.len(),
                drawn: self.poses,
            });
        }
        let [constant, leverage] = relative_fit(&samples);
        let uncertainty = PositionUncertainty {
            constant_variance_mm2: constant,
            leverage_variance_mm2: leverage,
            ..self.leverage.clone()
        };
        uncertainty.validate()?;
        Ok(uncertainty)
    }
}

/// A 1-σ position uncertainty against the position errors reached where it was given.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Coverage {
    /// The share of points whose error is within `2σ` (95.45 % for a calibrated uncertainty).
    pub within_two_sigma: f64,
    /// The mean `σ`, mm.
    pub mean_sigma_mm: f64,
}

impl Coverage {
    /// The coverage of `(error, σ)` pairs (mm); 0 and 0 without pairs.
    pub fn of(pairs: &[(f64, f64)]) -> Self {
        let count = pairs.len().max(1) as f64;
        let within = pairs.iter().filter(|(e, s)| *e <= 2.0 * s).count();
        Self {
            within_two_sigma: within as f64 / count,
            mean_sigma_mm: pairs.iter().map(|(_, s)| s).sum::<f64>() / count,
        }
    }
}

/// Iterations of [`relative_fit`]'s reweighting at most.
const REWEIGHTINGS: usize = 50;

/// [`relative_fit`] stops when no variance moves by more than this fraction.
const SETTLED: f64 = 1e-12;

/// `[a, b] ≥ 0` fitting `a + b·h` to samples `(h, y)`, `y > 0`, in relative terms **to the
/// fit**: the solution of `Σ (y − μ) / μ² · (1, h) = 0`, `μ = a + b·h` (the maximum likelihood
/// of variances `y` scattered as a gamma distribution about `μ`), by least squares reweighted
/// with `1/μ²`. Relative to the samples instead (`Σ ((μ − y) / y)²`) the fit leans to the small
/// ones and falls short of the variances' mean: by 12 % on a model of 50 configurations.
fn relative_fit(samples: &[(f64, f64)]) -> [f64; 2] {
    let mut fit = weighted_least_squares(samples, |_, y| y);
    for _ in 0..REWEIGHTINGS {
        let [a, b] = fit;
        // μ > 0 wherever some y is: a fit of zero at a sample is weighted by the sample.
        fit = weighted_least_squares(samples, |h, y| {
            let mu = a + b * h;
            if mu > 0.0 { mu } else { y }
        });
        let moved = |new: f64, old: f64| (new - old).abs() > SETTLED * new.abs().max(old.abs());
        if !moved(fit[0], a) && !moved(fit[1], b) {
            break;
        }
    }
    fit
}

/// `[a, b] ≥ 0` minimising `Σ ((a + b·h − y) / s)²` over samples `(h, y)`, `s = scale(h, y)`
/// positive.
fn weighted_least_squares(samples: &[(f64, f64)], scale: impl Fn(f64, f64) -> f64) -> [f64; 2] {
    // Normal equations of the rows (1/s, h/s) against y/s.
    let (mut s11, mut s12, mut s22, mut r1, mut r2) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for &(h, y) in samples {
        let s = scale(h, y);
        let (u, v, t) = (1.0 / s, h / s, y / s);
        s11 += u * u;
        s12 += u * v;
        s22 += v * v;
        r1 += u * t;
        r2 += v * t;
    }
    let determinant = s11 * s22 - s12 * s12;
    let (a, b) = if determinant > 0.0 {
        (
            (r1 * s22 - r2 * s12) / determinant,
            (r2 * s11 - r1 * s12) / determinant,
        )
    } else {
        (-1.0, -1.0)
    };
    if a >= 0.0 && b >= 0.0 {
        return [a, b];
    }
    // The best with one of them zero.
    let only_a = [r1 / s11, 0.0];
    let only_b = [0.0, r2 / s22];
    let cost = |[a, b]: [f64; 2]| {
        samples
            .iter()
            .map(|&(h, y)| ((a + b * h - y) / scale(h, y)).powi(2))
            .sum::<f64>()
    };
    if cost(only_a) <= cost(only_b) {
        only_a
    } else {
        only_b
    }
}

/// The leverage's normalisation and whitening over the nominal legs of `configurations` (mm),
/// variances zero.
fn leverage_of(configurations: &[[f64; LEGS]]) -> Result<PositionUncertainty> {
    if configurations.len() < FEATURES {
        return Err(Error::TooFewConfigurations {
            task: "the uncertainty's leverage",
            needed: FEATURES,
            got: configurations.len(),
        });
    }
    let mut centre_mm = [0.0; LEGS];
    let mut half_span_mm = [0.0; LEGS];
    for leg in 0..LEGS {
        let [lo, hi] = crate::train::leg_range(configurations, leg);
        centre_mm[leg] = 0.5 * (lo + hi);
        half_span_mm[leg] = 0.5 * (hi - lo);
        if half_span_mm[leg].is_nan() || half_span_mm[leg] <= 0.0 {
            return Err(Error::LegWithoutRange { leg: leg + 1 });
        }
    }
    let mut uncertainty = PositionUncertainty {
        centre_mm,
        half_span_mm,
        whitening: vec![0.0; WHITENING_ENTRIES],
        constant_variance_mm2: 0.0,
        leverage_variance_mm2: 0.0,
    };
    let mut moments = DMatrix::<f64>::zeros(FEATURES, FEATURES);
    for q in configurations {
        let phi = nalgebra::DVector::from_row_slice(&uncertainty.features(q));
        moments += &phi * phi.transpose();
    }
    moments /= configurations.len() as f64;
    // A ridge of 1e-9 of the mean diagonal keeps the factor finite where the features are
    // (nearly) dependent over the configurations, as a leg's square is on its length when the
    // leg takes two lengths only.
    let ridge = 1e-9 * moments.trace() / FEATURES as f64;
    for k in 0..FEATURES {
        moments[(k, k)] += ridge;
    }
    let cholesky = moments.cholesky().ok_or(Error::LegMomentsSingular)?;
    let inverse = cholesky
        .l()
        .solve_lower_triangular(&DMatrix::identity(FEATURES, FEATURES))
        .ok_or(Error::LegMomentsSingular)?;
    let norm = 1.0 / (FEATURES as f64).sqrt();
    let mut at = 0;
    for r in 0..FEATURES {
        for c in 0..=r {
            uncertainty.whitening[at] = inverse[(r, c)] * norm;
            at += 1;
        }
    }
    Ok(uncertainty)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, StandardNormal};

    /// The share of draws of `N(0, Σ)` within `2σ`.
    fn coverage(sigma: &Matrix3<f64>, draws: usize, seed: u64) -> f64 {
        let s = one_sigma_mm(sigma);
        let l = sigma.cholesky().unwrap().l();
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let within = (0..draws)
            .filter(|_| {
                let z = nalgebra::Vector3::from_fn(|_, _| StandardNormal.sample(&mut rng));
                (l * z).norm() <= 2.0 * s
            })
            .count();
        within as f64 / draws as f64
    }

    #[test]
    fn two_sigma_covers_what_it_covers_in_one_dimension() {
        // Isotropic, flattened, nearly one-dimensional, and a rotated anisotropic covariance.
        let rotation = nalgebra::Rotation3::from_euler_angles(0.3, -0.7, 1.1);
        let cases = [
            Matrix3::from_diagonal(&nalgebra::Vector3::new(1.0, 1.0, 1.0)),
            Matrix3::from_diagonal(&nalgebra::Vector3::new(1.0, 1.0, 0.01)),
            Matrix3::from_diagonal(&nalgebra::Vector3::new(1.0, 1e-4, 1e-4)),
            rotation
                * Matrix3::from_diagonal(&nalgebra::Vector3::new(4.0, 1.0, 0.2))
                * rotation.transpose(),
        ];
        for (k, sigma) in cases.iter().enumerate() {
            let share = coverage(&(sigma * 1e-5), 200_000, k as u64);
            // 95.45 % within the approximation (measured 95.19–95.33 %: the one-dimensional case
            // is the worst, its χ²₁ quantile 3.91 by Wilson–Hilferty against 4) and 0.1 % of
            // sampling noise; the 95 % quantile would give 94.8–95.0 %.
            assert!((0.9505..0.958).contains(&share), "case {k}: {share}");
        }
        assert_eq!(one_sigma_mm(&Matrix3::zeros()), 0.0);
        assert!(one_sigma_mm(&Matrix3::from_element(f64::INFINITY)).is_nan());
    }

    /// Where a machine that `alternative` describes exactly reaches when commanded with the legs
    /// `model` gives for `pose`, minus `pose`'s position (mm): Newton steps on the
    /// alternative's commands, differentiated by central differences.
    fn reached_off(
        model: &PhysicalModel,
        alternative: &PhysicalModel,
        pose: &Pose,
    ) -> nalgebra::Vector3<f64> {
        let target = model.command(pose);
        let start = pose.to_mm_deg();
        let mut at = start;
        for _ in 0..3 {
            let commanded = alternative.command(&Pose::from_mm_deg(at));
            let mut jacobian = SMatrix::<f64, LEGS, LEGS>::zeros();
            for k in 0..LEGS {
                let step = if k < 3 { 1e-3 } else { 1e-4 };
                let (mut up, mut down) = (at, at);
                up[k] += step;
                down[k] -= step;
                let (up, down) = (
                    alternative.command(&Pose::from_mm_deg(up)),
                    alternative.command(&Pose::from_mm_deg(down)),
                );
                for i in 0..LEGS {
                    jacobian[(i, k)] = (up[i] - down[i]) / (2.0 * step);
                }
            }
            let miss = SMatrix::<f64, LEGS, 1>::from_fn(|i, _| target[i] - commanded[i]);
            let step = jacobian.lu().solve(&miss).expect("a regular pose");
            for k in 0..LEGS {
                at[k] += step[k];
            }
        }
        nalgebra::Vector3::from_fn(|k, _| at[k] - start[k])
    }

    /// Plan poses of the default robot's 40 configurations (plan seed 3).
    fn forty_poses(g: &Geometry) -> Vec<Pose> {
        crate::plan::plan(
            g,
            &crate::plan::PlanOptions {
                count: 40,
                seed: 3,
                ..Default::default()
            },
        )
        .unwrap()
    }

    /// `poses` measured on the virtual machine of `errors` (machine seed 1) with the noise of
    /// `noise_seed`.
    fn measured(
        g: &Geometry,
        poses: &[Pose],
        errors: &hexacomp_virtual::ErrorModel,
        noise_seed: u64,
    ) -> Vec<MeasuredConfiguration> {
        let mut platform =
            hexacomp_virtual::VirtualPlatform::new(g, errors, 1, noise_seed).unwrap();
        platform
            .measure_plan(&crate::plan::numbered_rows(poses))
            .unwrap()
    }

    /// `poses` measured as [`measured`], and the physical models of eight and twelve lead-screw
    /// coefficients identified from them, with their propagations for `errors`' repeatability.
    fn eight_and_twelve(
        g: &Geometry,
        poses: &[Pose],
        errors: &hexacomp_virtual::ErrorModel,
        noise_seed: u64,
    ) -> [Propagation; 2] {
        eight_and_twelve_of(g, &measured(g, poses, errors, noise_seed), errors)
    }

    /// The physical models of eight and twelve lead-screw coefficients identified from `rows`,
    /// with their propagations for `errors`' repeatability.
    fn eight_and_twelve_of(
        g: &Geometry,
        rows: &[MeasuredConfiguration],
        errors: &hexacomp_virtual::ErrorModel,
    ) -> [Propagation; 2] {
        [8, 12].map(|basis| {
            let options = IdentifyOptions::physical(basis);
            let model = crate::identify::identify(g, rows, &options).unwrap().model;
            Propagation::of(
                &model,
                &options,
                rows,
                Repeatability::Known(errors.repeatability_sigma_mm),
            )
            .unwrap()
        })
    }

    #[test]
    fn an_alternative_adds_its_share_of_where_its_machine_would_reach() {
        // The physical model of the default robot's 40 configurations with eight and with
        // twelve lead-screw coefficients: the second is the alternative.
        let g = Geometry::prototype();
        let poses = forty_poses(&g);
        let [mut propagation, alternative] =
            eight_and_twelve(&g, &poses, &hexacomp_virtual::ErrorModel::default(), 1);
        // Without the fits' noise to take away, all of the miss is the choice's.
        propagation.noise.instrument_variance_mm2 = 0.0;
        propagation.noise.repeatability_variance_mm2 = 0.0;
        let mut largest = 0.0f64;
        for pose in &poses[20..26] {
            let (alone, legs_alone) = propagation.position_covariances(pose, &[]).unwrap();
            let (beside, legs_beside) = propagation
                .position_covariances(pose, std::slice::from_ref(&alternative))
                .unwrap();
            assert_eq!(
                legs_alone, legs_beside,
                "the leg variance's part is unchanged"
            );
            // Two models the data cannot tell apart: half the outer product of the miss, to
            // within what the propagation's linear map leaves out (it holds the sag under the
            // weight fixed while the pose moves: 0.5 % here).
            let off = reached_off(&propagation.model, &alternative.model, pose);
            let expected = off * off.transpose() / 2.0;
            let added = beside - alone;
            largest = largest.max(off.norm());
            assert!(
                (added - expected).norm() <= 1e-2 * expected.norm(),
                "pose {pose:?}: added {added} against {expected}"
            );
        }
        // The models differ by micrometres: the check is about something.
        assert!(largest > 5e-4, "the models differ by {largest} mm at most");
    }

    /// The default virtual machine with legs repeating within 0.02 mm, measured by an
    /// instrument of 0.002 mm a reading (three averaged).
    fn repeating_machine() -> hexacomp_virtual::ErrorModel {
        let paper = hexacomp_virtual::ErrorModel::default();
        hexacomp_virtual::ErrorModel {
            repeatability_sigma_mm: 0.02,
            device: hexacomp_virtual::MeasuringDevice {
                sigma_mm: 0.002,
                ..paper.device
            },
            ..paper
        }
    }

    /// Per draw of the noise, the share of `validation` poses within 2σ: of the σ the
    /// physical model of eight coefficients identified on `configurations` of a default robot
    /// (machine seed 1) gives, and of the true σ (what the errors of the other draws at the pose scatter by,
    /// their bias included). Each draw's errors share its model's: one draw is one sample.
    fn coverage_over_draws(
        g: &Geometry,
        configurations: &[Pose],
        validation: &[Pose],
        draws: u64,
    ) -> (Vec<f64>, Vec<f64>) {
        let errors = hexacomp_virtual::ErrorModel::default();
        let options = IdentifyOptions::physical(8);
        let repeatability = Repeatability::Known(errors.repeatability_sigma_mm);
        let nominal_legs = |pose: &Pose| hexacomp_core::inverse_kinematics(g, pose).lengths;
        let (reached, sigmas): (Vec<Vec<nalgebra::Vector3<f64>>>, Vec<Vec<f64>>) = (1..=draws)
            .map(|seed| {
                let mut platform =
                    hexacomp_virtual::VirtualPlatform::new(g, &errors, 1, seed).unwrap();
                let rows = platform
                    .measure_plan(&crate::plan::numbered_rows(configurations))
                    .unwrap();
                let model = crate::identify::identify(g, &rows, &options).unwrap().model;
                let uncertainty = UncertaintySource::new(
                    g,
                    (&model, &options),
                    None,
                    &[],
                    &rows,
                    repeatability,
                    1,
                )
                .and_then(|source| source.fitted(0.0))
                .unwrap();
                validation
                    .iter()
                    .map(|pose| {
                        // The machine goes on moving with its repeatability after the
                        // configurations: a fresh move.
                        let at = platform.move_legs(&model.command(pose), pose).unwrap();
                        let off = at.position - pose.position;
                        let off = nalgebra::Vector3::new(off.x, off.y, off.z);
                        (off, uncertainty.sigma_mm(&nominal_legs(pose)))
                    })
                    .unzip()
            })
            .unzip();
        let share = |inside: usize| 100.0 * inside as f64 / validation.len() as f64;
        (0..reached.len())
            .map(|draw| {
                let (mut true_inside, mut inside) = (0, 0);
                for pose in 0..validation.len() {
                    let others = (0..reached.len()).filter(|&other| other != draw);
                    let second_moment = others
                        .map(|other| reached[other][pose] * reached[other][pose].transpose())
                        .sum::<Matrix3<f64>>()
                        / (reached.len() - 1) as f64;
                    let error = reached[draw][pose].norm();
                    true_inside += usize::from(error <= 2.0 * one_sigma_mm(&second_moment));
                    inside += usize::from(error <= 2.0 * sigmas[draw][pose]);
                }
                (share(inside), share(true_inside))
            })
            .unzip()
    }

    #[test]
    fn over_draws_of_the_noise_the_coverage_is_the_true_sigmas() {
        // A default robot (machine seed 1), 50 and 150 configurations of one plan, forty draws
        // of the noise:
        // the coverage of the propagated σ averages what the true σ's does (95.45 % for a
        // covariance known), and scatters from draw to draw not much more than the true σ's,
        // which scatters too: every pose of a draw meets the same model's error. (Eight
        // coefficients, no prior and no alternative: the propagation, the residuals' split
        // and the file's form alone.)
        let g = Geometry::prototype();
        let plan = crate::plan::plan(&g, &crate::plan::PlanOptions::default()).unwrap();
        let validation = hexacomp_core::sampling::WorkspaceSampler::new(&g, 7, Default::default())
            .unwrap()
            .samples(200)
            .unwrap();
        let statistics = |shares: &[f64]| {
            let mean = shares.iter().sum::<f64>() / shares.len() as f64;
            let variance =
                shares.iter().map(|s| (s - mean).powi(2)).sum::<f64>() / (shares.len() - 1) as f64;
            let outside = shares
                .iter()
                .filter(|s| !(90.0..=98.0).contains(*s))
                .count();
            (mean, variance.sqrt(), outside)
        };
        for count in [50, 150] {
            let (ours, truth) = coverage_over_draws(&g, &plan[..count], &validation, 40);
            let (mean, deviation, outside) = statistics(&ours);
            let (true_mean, true_deviation, true_outside) = statistics(&truth);
            eprintln!(
                "{count} configurations, 40 draws: within 2σ {mean:.2} % on average, {deviation:.2} \
                 from draw to draw, {outside} outside 90-98 %; with the true σ {true_mean:.2} %, \
                 {true_deviation:.2}, {true_outside}"
            );
            // The true σ's share is what a covariance known gives, within what forty draws
            // scattering by 2-3.5 points tell (and the χ² approximation's 0.2 points, and the
            // leave-one-out second moment of 39 draws, a few tenths narrow).
            assert!((94.0..=97.0).contains(&true_mean), "{true_mean}");
            assert!((93.5..=97.5).contains(&mean), "{mean}");
            assert!(
                deviation <= 1.8 * true_deviation,
                "{deviation} against {true_deviation}"
            );
        }
    }

    #[test]
    fn the_propagated_covariances_hold_what_fits_of_other_draws_scatter_by() {
        // A machine whose legs repeat within 0.02 mm, measured by an instrument of 0.002 mm a
        // reading (three averaged):
        // the residuals' noise is mostly the configurations' own moves, shared by their
        // targets. Forty draws of the noise, each identified with eight and twelve coefficients,
        // and eight's propagation with the repeatability assumed as 0.004 mm, as `calibrate
        // --measurements` does for want of the machine's: the platform's variance its
        // residuals' shape shows then moves the parameters instead. And twelve with a
        // smoothness prior (weight 0.01), whose estimate the prior holds back.
        let g = Geometry::prototype();
        let poses = forty_poses(&g);
        let errors = repeating_machine();
        let smoothed = IdentifyOptions::physical(12).smoothed(0.01);
        let draws: Vec<([Propagation; 2], Propagation, Propagation)> = (1..=40)
            .map(|seed| {
                let rows = measured(&g, &poses, &errors, seed);
                let [eight, twelve] = eight_and_twelve_of(&g, &rows, &errors);
                let assumed = Propagation::of(
                    &eight.model,
                    &eight.options,
                    &rows,
                    Repeatability::Assumed(0.004),
                )
                .unwrap();
                let model = crate::identify::identify(&g, &rows, &smoothed)
                    .unwrap()
                    .model;
                let repeatability = Repeatability::Known(errors.repeatability_sigma_mm);
                let held = Propagation::of(&model, &smoothed, &rows, repeatability).unwrap();
                ([eight, twelve], assumed, held)
            })
            .collect();
        let first = &draws[0].0[0];
        let (mut model_predicted, mut model_scattered) = (0.0, 0.0);
        let mut assumed_predicted = 0.0;
        let (mut miss_predicted, mut miss_scattered) = (0.0, 0.0);
        let (mut held_predicted, mut held_scattered) = (0.0, 0.0);
        let (mut free_predicted, mut free_scattered) = (0.0, 0.0);
        for pose in &poses[20..24] {
            // Where the legs commanded by the first draw's model stand loaded against where
            // the pose needs them, under each draw's model: their scatter is G C Gᵀ's.
            let commanded = first.model.command(pose);
            let off = |model: &PhysicalModel| {
                let loaded = model.loaded_lengths(&commanded, pose);
                let needed = hexacomp_core::inverse_kinematics(&model.geometry, pose);
                SMatrix::<f64, LEGS, 1>::from_fn(|i, _| loaded[i] - needed.lengths[i])
            };
            let predicted = |of: &Propagation| {
                let commanded = of.model.command(pose);
                let screws = ActuationScrews::at(&of.model.geometry, pose);
                let g = leg_sensitivities(&of.model, &of.options, &commanded, pose, &screws);
                (&g * &of.covariance * g.transpose()).trace() / 40.0
            };
            let scattered_of =
                |which: fn(&([Propagation; 2], Propagation, Propagation)) -> &PhysicalModel| {
                    let off: Vec<_> = draws.iter().map(|draw| off(which(draw))).collect();
                    scatter(&off)
                };
            model_scattered += scattered_of(|([eight, _], _, _)| &eight.model);
            held_scattered += scattered_of(|(_, _, held)| &held.model);
            free_scattered += scattered_of(|([_, twelve], _, _)| &twelve.model);
            // Twelve's miss under eight's commands, in each draw: its scatter is N's. The
            // predictions are averaged over the draws.
            let mut misses = Vec::with_capacity(draws.len());
            for ([eight, twelve], assumed, held) in &draws {
                model_predicted += predicted(eight);
                assumed_predicted += predicted(assumed);
                free_predicted += predicted(twelve);
                held_predicted += predicted(held);
                let commanded = eight.model.command(pose);
                let screws = ActuationScrews::at(&eight.model.geometry, pose);
                let g = leg_sensitivities(&eight.model, &eight.options, &commanded, pose, &screws);
                let own = &g * &eight.estimator;
                let (miss, fits) = eight.miss_of(twelve, pose, &commanded, &own);
                misses.push(miss);
                miss_predicted += fits.trace() / 40.0;
            }
            miss_scattered += scatter(&misses);
        }
        // Forty draws (39 degrees of freedom) estimate one direction's variance within 23 % (1 σ,
        // √(2/39)), a sum over several directions within less: 1.01, 0.99 and 0.98 measured
        // (the repeatability assumed: 0.004 mm's would be some 25 times short).
        for (what, predicted, scattered) in [
            ("the model's", model_predicted, model_scattered),
            ("the miss's", miss_predicted, miss_scattered),
            (
                "the model's, the repeatability assumed,",
                assumed_predicted,
                model_scattered,
            ),
            ("twelve's", free_predicted, free_scattered),
            (
                "twelve's, with a smoothness prior,",
                held_predicted,
                held_scattered,
            ),
        ] {
            let ratio = scattered / predicted;
            assert!(
                (0.7..1.4).contains(&ratio),
                "{what} scatter over draws is {ratio} times the propagated \
                 ({scattered} against {predicted} mm²)"
            );
        }
        // What the prior takes off the scatter is what it takes off the propagation: on the
        // same draws the two ratios share their sampling error (0.79 and 0.81 measured; a
        // propagation that ignored the prior would read 1.0).
        let (scatter_kept, propagation_kept) = (
            held_scattered / free_scattered,
            held_predicted / free_predicted,
        );
        assert!(
            scatter_kept < 0.9 && (0.93..1.07).contains(&(scatter_kept / propagation_kept)),
            "the prior keeps {scatter_kept} of the scatter and {propagation_kept} of the \
             propagated variance"
        );
    }

    /// An anisotropic noise covariance of the legs' miss (mm²): variances 1–16 µm² along
    /// randomly rotated directions.
    fn anisotropic_noise() -> SMatrix<f64, LEGS, LEGS> {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let rotation = SMatrix::<f64, LEGS, LEGS>::from_fn(|_, _| StandardNormal.sample(&mut rng))
            .qr()
            .q();
        let spread = SMatrix::<f64, LEGS, 1>::from_fn(|i, _| 1e-6 * (1.0 + 3.0 * i as f64));
        rotation * SMatrix::from_diagonal(&spread) * rotation.transpose()
    }

    /// The means of `tr(N⁻¹ R)` and of `tr R / tr N`, `R = beyond_noise(d, N)`, over `draws`
    /// misses `d = δ + e`, `e ~ N(0, N)`.
    fn kept_over_draws(
        signal: &SMatrix<f64, LEGS, 1>,
        noise: &SMatrix<f64, LEGS, LEGS>,
        draws: usize,
    ) -> (f64, f64) {
        let root = noise.cholesky().unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let (mut mahalanobis, mut euclidean) = (0.0, 0.0);
        for _ in 0..draws {
            let z = SMatrix::<f64, LEGS, 1>::from_fn(|_, _| StandardNormal.sample(&mut rng));
            let kept = beyond_noise(&(signal + root.l() * z), noise);
            mahalanobis += root.solve(&kept).trace();
            euclidean += kept.trace() / noise.trace();
        }
        (mahalanobis / draws as f64, euclidean / draws as f64)
    }

    #[test]
    fn the_miss_is_shrunk_by_what_the_noise_explains() {
        let noise = anisotropic_noise();
        // A miss of noise alone: tr(N⁻¹R) = (s − 6)₊, s ~ χ²₆, whose mean is
        // 6·P(χ²₈ > 6) − 6·P(χ²₆ > 6) = 6·e⁻³·(13 − 8.5) = 1.344: against 6 for the whole
        // miss, and about 5 for the positive part of `d dᵀ − N`. In mm², as the position's
        // covariance takes it: d's direction is uniform in N's metric and independent of s, so
        // tr R averages tr N · 1.344 / 6 = 0.224 tr N (the positive part about 0.8). 20 000
        // draws estimate the first within 0.02 (1 σ), the second within 0.004.
        let (mahalanobis, euclidean) = kept_over_draws(&SMatrix::zeros(), &noise, 20_000);
        let expected = 6.0 * (-3.0f64).exp() * (13.0 - 8.5);
        assert!(
            (mahalanobis - expected).abs() < 0.1,
            "{mahalanobis} against {expected}"
        );
        assert!(
            (euclidean - expected / 6.0).abs() < 0.02,
            "{euclidean} against {expected}/6"
        );
        // A signal of Mahalanobis length² 100 beside the noise: `s − 6` is kept, which
        // averages it in the noise's metric (s < 6 on a vanishing share of draws; 1 σ of the
        // mean √(2·206/20 000) = 0.14).
        let unit = SMatrix::<f64, LEGS, 1>::from_fn(|i, _| i as f64 - 2.5).normalize();
        let signal = noise.cholesky().unwrap().l() * unit * 10.0;
        let (mahalanobis, _) = kept_over_draws(&signal, &noise, 20_000);
        assert!(
            (mahalanobis - 100.0).abs() < 0.7,
            "{mahalanobis} against 100"
        );
    }

    #[test]
    fn a_platform_moving_beyond_the_given_repeatability_is_told_from_the_instrument() {
        // A machine repeating within 0.02 mm, measured by an instrument of 0.002 mm a reading
        // (three averaged: 1.33e-6 mm² per coordinate), its repeatability given as 0.004 mm:
        // the residuals' shape shows the platform's 4e-4 mm², and the instrument's variance is
        // the split's, not what the residuals hold beyond 0.004 mm's share (about 7e-5 mm²).
        let propagation = of_the_repeating_machine(Repeatability::Known(0.004));
        let split = propagation.split.expect("three targets a configuration");
        // Forty configurations estimate w within about 15 % (1 σ).
        let w = propagation.leg_variance_mm2;
        assert!((2.6e-4..6e-4).contains(&w), "{w} mm² against 4e-4");
        assert_eq!(w, split.platform_variance_mm2);
        let instrument = propagation.noise.instrument_variance_mm2;
        assert_eq!(instrument, split.instrument_variance_mm2);
        assert!((0.6e-6..2.2e-6).contains(&instrument), "{instrument} mm²");
        // Ω keeps the given repeatability: the misfit is not noise that moves the parameters.
        assert_eq!(propagation.noise.repeatability_variance_mm2, 0.004 * 0.004);
    }

    /// The [`repeating_machine`]'s forty configurations (noise seed 1) and the physical model
    /// of eight coefficients identified from them.
    fn the_repeating_machine_identified() -> (
        Geometry,
        Vec<MeasuredConfiguration>,
        IdentifyOptions,
        PhysicalModel,
    ) {
        let g = Geometry::prototype();
        let rows = measured(&g, &forty_poses(&g), &repeating_machine(), 1);
        let options = IdentifyOptions::physical(8);
        let model = crate::identify::identify(&g, &rows, &options)
            .unwrap()
            .model;
        (g, rows, options, model)
    }

    /// The propagation of [`the_repeating_machine_identified`]'s model for `repeatability`.
    fn of_the_repeating_machine(repeatability: Repeatability) -> Propagation {
        let (_, rows, options, model) = the_repeating_machine_identified();
        Propagation::of(&model, &options, &rows, repeatability).unwrap()
    }

    /// The trace of the parameters' covariance `propagation`'s estimator gives residuals whose
    /// platform moves by `platform_mm2` per leg and configuration, the instrument's noise as
    /// its own.
    fn covariance_trace_with(propagation: &Propagation, platform_mm2: f64) -> f64 {
        let mut noise = propagation.noise.clone();
        noise.repeatability_variance_mm2 = platform_mm2;
        noise.sandwich(&propagation.estimator).trace()
    }

    #[test]
    fn an_assumed_repeatability_lets_what_the_platform_shows_move_the_parameters() {
        // The machine above, repeating within 0.02 mm, its repeatability assumed as 0.004 mm
        // for want of its own: the platform's variance the residuals' shape shows may be the
        // machine's repeatability, and moves the parameters as that would.
        let assumed = of_the_repeating_machine(Repeatability::Assumed(0.004));
        let w = assumed
            .split
            .expect("three targets a configuration")
            .platform_variance_mm2;
        assert_eq!(assumed.noise.repeatability_variance_mm2, w);
        assert_eq!(assumed.leg_variance_mm2, w);
        // The covariance the machine's own repeatability gives, within the split's estimate of
        // it (about 15 %, 1 σ); the assumed one's would be a twenty-fifth of it.
        let ratio = assumed.covariance.trace() / covariance_trace_with(&assumed, 0.02 * 0.02);
        assert!((0.65..1.5).contains(&ratio), "{ratio}");
    }

    #[test]
    fn the_excess_moves_the_parameters_beyond_an_assumed_repeatability_alone() {
        // Residuals whose shape shows the platform moving by 3e-4 mm² per leg, the instrument's
        // noise 1e-6 mm² per coordinate.
        let split = ShapeSplit {
            instrument_variance_mm2: 1e-6,
            platform_variance_mm2: 3e-4,
            platform_error_mm2: 4e-5,
        };
        // (all of the residuals would be 4e-4 mm² of the platform's; beyond the repeatability's
        // share they hold 2e-6 mm² per coordinate)
        let of = |split, machine| variances(Some(split), machine, 4e-4, 2e-6);
        // Beyond a known repeatability, the form's misfit: at a fresh move alone.
        assert_eq!(
            of(split, Repeatability::Known(0.01)),
            Variances {
                repeatability: 1e-4,
                instrument: 1e-6,
                moving_parameters: 1e-4,
                fresh_move: 3e-4,
            }
        );
        // Beyond an assumed one, maybe the machine's own: the parameters too.
        assert_eq!(
            of(split, Repeatability::Assumed(0.01)),
            Variances {
                repeatability: 1e-4,
                instrument: 1e-6,
                moving_parameters: 3e-4,
                fresh_move: 3e-4,
            }
        );
        // Within the repeatability, the residuals' rest is the instrument's.
        assert_eq!(
            of(split, Repeatability::Known(0.02)),
            Variances {
                repeatability: 4e-4,
                instrument: 2e-6,
                moving_parameters: 4e-4,
                fresh_move: 4e-4,
            }
        );
        // A split whose instrument's variance falls to zero and below (a noiseless instrument,
        // all of the residuals the platform's) is taken at its limit on either side, with the
        // same rule: no jump where the sign turns.
        for machine in [Repeatability::Known(0.0), Repeatability::Assumed(0.0)] {
            let [above, below] = [1e-15, -1e-15].map(|instrument| {
                of(
                    ShapeSplit {
                        instrument_variance_mm2: instrument,
                        platform_variance_mm2: 4e-4,
                        ..split
                    },
                    machine,
                )
            });
            assert!((above.instrument - below.instrument).abs() <= 1e-15);
            assert_eq!(above.moving_parameters, below.moving_parameters);
            assert_eq!(above.fresh_move, below.fresh_move);
            let moving = match machine {
                Repeatability::Known(_) => 0.0,
                Repeatability::Assumed(_) => 4e-4,
            };
            assert_eq!(below.moving_parameters, moving);
            assert_eq!(below.fresh_move, 4e-4);
        }
    }

    #[test]
    fn the_source_says_where_the_platforms_excess_went() {
        // The machine above, repeating within 0.02 mm (its residuals show 2.6e-4 to 6e-4 mm²):
        // beyond 0.004 mm known, at fresh moves alone; beyond 0.004 mm assumed, in the
        // parameters too; within 0.025 mm known, nowhere.
        let (g, rows, options, model) = the_repeating_machine_identified();
        for (machine, at_fresh_moves, moving_parameters) in [
            (Repeatability::Known(0.004), true, false),
            (Repeatability::Assumed(0.004), true, true),
            (Repeatability::Known(0.025), false, false),
            // More than all the residuals hold, assumed: all of them taken, nothing beyond.
            (Repeatability::Assumed(0.1), false, false),
        ] {
            let source =
                UncertaintySource::new(&g, (&model, &options), None, &[], &rows, machine, 1)
                    .unwrap();
            assert_eq!(
                source.beyond_repeatability(),
                BeyondRepeatability {
                    at_fresh_moves,
                    moving_parameters
                },
                "{machine:?}"
            );
        }
    }

    #[test]
    fn poses_measured_are_not_split_by_shape() {
        // The same measurements as a 6-DoF probe would report them: each configuration's
        // targets placed by one pose, the instrument's noise in the platform's directions.
        let g = Geometry::prototype();
        let errors = hexacomp_virtual::ErrorModel::default();
        let rows = measured(&g, &forty_poses(&g), &errors, 1);
        let as_poses: Vec<MeasuredConfiguration> = rows
            .iter()
            .map(|row| MeasuredConfiguration {
                observed: Observation::Pose(row.observed.fitted_pose(&g).unwrap().to_mm_deg()),
                ..row.clone()
            })
            .collect();
        let options = IdentifyOptions::physical(8);
        let model = crate::identify::identify(&g, &as_poses, &options)
            .unwrap()
            .model;
        let v = errors.repeatability_sigma_mm;
        let propagation =
            Propagation::of(&model, &options, &as_poses, Repeatability::Known(v)).unwrap();
        assert!(propagation.split.is_none());
        assert_eq!(propagation.leg_variance_mm2, v * v);
    }

    #[test]
    fn a_smoothness_priors_bias_is_added_as_far_as_the_machine_shows_it() {
        // A noiseless default robot, whose lead-screw curves twelve and sixteen coefficients
        // follow: the models of twelve and of sixteen without a prior reach every pose (within
        // 0.1 µm here), so the model of twelve with a prior misses by the prior's bias alone,
        // and its uncertainty must add that miss — against where the machine really goes.
        // (A weight of 1, above the ones calibrate tries, for a bias of 5–22 µm, well above
        // twelve's own miss.) Beside sixteen as an alternative, whose form describes the
        // machine as well, the two forms' shares together are still that one miss: each
        // alternative's miss holds the prior's bias too.
        let g = Geometry::prototype();
        let errors = hexacomp_virtual::ErrorModel::default().without_noise();
        let rows = measured(&g, &forty_poses(&g), &errors, 1);
        let repeatability = Repeatability::Known(0.0);
        let propagated = |options: &IdentifyOptions| {
            let model = crate::identify::identify(&g, &rows, options).unwrap().model;
            Propagation::of(&model, options, &rows, repeatability).unwrap()
        };
        let smoothed = IdentifyOptions::physical(12).smoothed(1.0);
        let alone = propagated(&smoothed);
        let without = propagated(&IdentifyOptions::physical(12));
        let sixteen = propagated(&IdentifyOptions::physical(16));
        let with_bias = alone.clone().with_prior_bias(without.clone()).unwrap();
        let machine = hexacomp_virtual::VirtualPlatform::new(&g, &errors, 1, 1)
            .unwrap()
            .machine()
            .clone();
        let fresh = crate::plan::plan(
            &g,
            &crate::plan::PlanOptions {
                count: 8,
                seed: 9,
                ..Default::default()
            },
        )
        .unwrap();
        let mut largest = 0.0f64;
        for pose in &fresh {
            let reached = machine
                .settle(&machine.unloaded_lengths(&alone.model.command(pose)), pose)
                .unwrap();
            let off = reached.position - pose.position;
            let off = nalgebra::Vector3::new(off.x, off.y, off.z);
            let expected = off * off.transpose();
            largest = largest.max(off.norm());
            let before = alone.position_covariances(pose, &[]).unwrap().0;
            for alternatives in [&[][..], std::slice::from_ref(&sixteen)] {
                let after = with_bias
                    .position_covariances(pose, alternatives)
                    .unwrap()
                    .0;
                // Within what the linear map leaves out (the sag held while the pose moves)
                // and what the unpenalised models miss of the machine's curves: 1.5 % of the
                // trace measured.
                assert!(
                    (after - before - expected).norm() <= 3e-2 * expected.norm(),
                    "pose {pose:?}, {} alternatives: added {} against {expected}",
                    alternatives.len(),
                    after - before
                );
            }
        }
        // The prior moves the poses by micrometres: the check is about something.
        assert!(largest > 1e-3, "the prior's bias is {largest} mm at most");
        // The reference must be this identification without the prior, from the same rows,
        // and this model must have one.
        let physical = IdentifyOptions::physical(12);
        let other_rows =
            Propagation::of(&without.model, &physical, &rows[1..], repeatability).unwrap();
        let other_options = [
            IdentifyOptions {
                compliance: false,
                ..physical
            },
            IdentifyOptions {
                relative_cutoff: 10.0 * physical.relative_cutoff,
                ..physical
            },
        ]
        .map(|options| Propagation::of(&without.model, &options, &rows, repeatability).unwrap());
        let references = [&alone, &sixteen, &other_rows]
            .into_iter()
            .chain(&other_options)
            .map(|reference| (&alone, reference))
            .chain([(&without, &without)]);
        for (model, reference) in references {
            assert!(
                matches!(
                    model.clone().with_prior_bias(reference.clone()),
                    Err(Error::PriorReferenceMismatch { .. })
                ),
                "{:?} with {} residuals taken as {:?}'s without its prior",
                reference.options,
                reference.residuals(),
                model.options
            );
        }
    }

    #[test]
    fn a_priors_model_takes_its_leg_variance_from_its_fit_without_the_prior() {
        // The machine repeating within 0.02 mm, its repeatability given as 0.004 mm: the
        // excess (the machine's own repeatability here, read as the form's misfit, as a given
        // repeatability makes it) is taken at fresh moves, and the prior's own curvature must
        // not count in it — the fit without the prior stands for the model's form.
        let (g, rows, physical, without) = the_repeating_machine_identified();
        let smoothed = physical.smoothed(1.0);
        let model = crate::identify::identify(&g, &rows, &smoothed)
            .unwrap()
            .model;
        let repeatability = Repeatability::Known(0.004);
        let penalised = Propagation::of(&model, &smoothed, &rows, repeatability).unwrap();
        let unpenalised = Propagation::of(&without, &physical, &rows, repeatability).unwrap();
        let source = UncertaintySource::new(
            &g,
            (&model, &smoothed),
            Some(&without),
            &[],
            &rows,
            repeatability,
            1,
        )
        .unwrap();
        assert_eq!(source.leg_variance_mm2(), unpenalised.leg_variance_mm2);
        assert_eq!(source.shape_split(), unpenalised.split);
        assert!(source.holds_prior_bias());
        // The two fits' leg variances differ: the check is about something.
        assert!(
            penalised.leg_variance_mm2 > 1.1 * unpenalised.leg_variance_mm2,
            "{} against {}",
            penalised.leg_variance_mm2,
            unpenalised.leg_variance_mm2
        );
        // The fit without the prior is given exactly where the model has one.
        // Missing beside a prior: refused as missing; given beside none: refused by
        // `with_prior_bias` as another identification than the model's without its prior.
        for (options, without_prior) in [(&smoothed, None), (&physical, Some(&without))] {
            let model = if options.smoothness > 0.0 {
                &model
            } else {
                &without
            };
            assert!(matches!(
                UncertaintySource::new(
                    &g,
                    (model, options),
                    without_prior,
                    &[],
                    &rows,
                    repeatability,
                    1
                ),
                Err(Error::PriorReferenceMissing { .. } | Error::PriorReferenceMismatch { .. })
            ));
        }
    }

    #[test]
    fn a_miss_the_noise_cannot_make_is_kept_whole() {
        let d = SMatrix::<f64, LEGS, 1>::from_fn(|i, _| 1e-3 * (i as f64 + 1.0));
        assert_eq!(beyond_noise(&d, &SMatrix::zeros()), d * d.transpose());
        assert_eq!(
            beyond_noise(&SMatrix::zeros(), &anisotropic_noise()),
            SMatrix::<f64, LEGS, LEGS>::zeros()
        );
        // Noise in five directions, the miss along the sixth.
        let mut spread = SMatrix::<f64, LEGS, 1>::from_element(1e-6);
        spread[5] = 0.0;
        let along = SMatrix::<f64, LEGS, 1>::from_fn(|i, _| if i == 5 { 1e-3 } else { 0.0 });
        let kept = beyond_noise(&along, &SMatrix::from_diagonal(&spread));
        // (Counted at 1e-12 of the largest variance: 1 − 5·10⁻¹² of it kept.)
        assert!(
            (kept - along * along.transpose()).norm() < 1e-10 * kept.norm(),
            "{kept}"
        );
        // Noise that is not a number gives no number, and returns.
        let broken = SMatrix::<f64, LEGS, LEGS>::from_element(f64::NAN);
        assert!(beyond_noise(&d, &broken).iter().all(|v| v.is_nan()));
    }

    #[test]
    fn the_propagation_refuses_a_repeatability_not_a_finite_sigma_or_beyond_the_residuals() {
        let g = Geometry::prototype();
        let rows = measured(
            &g,
            &forty_poses(&g),
            &hexacomp_virtual::ErrorModel::default(),
            1,
        );
        let options = IdentifyOptions::physical(8);
        let model = crate::identify::identify(&g, &rows, &options)
            .unwrap()
            .model;
        for bad in [-0.004, f64::NAN, f64::INFINITY] {
            let e =
                Propagation::of(&model, &options, &rows, Repeatability::Known(bad)).unwrap_err();
            assert!(e.to_string().contains("repeatability"), "{e}");
        }
        // A repeatability the residuals cannot hold: refused, naming the one that is all of
        // them (to 1 nm). Up to √2 times that, within the residuals' own scatter, accepted.
        let e = Propagation::of(&model, &options, &rows, Repeatability::Known(0.1)).unwrap_err();
        let largest: f64 = e
            .to_string()
            .split("repeatability of ")
            .nth(2)
            .and_then(|rest| rest.split(' ').next()?.parse::<f64>().ok())
            .map(|micrometres| micrometres * 1e-3)
            .unwrap_or_else(|| panic!("no largest repeatability in {e}"));
        assert!((0.004..0.1).contains(&largest), "{e}");
        assert!(
            Propagation::of(
                &model,
                &options,
                &rows,
                Repeatability::Known(largest * 1.35)
            )
            .is_ok()
        );
        assert!(
            Propagation::of(&model, &options, &rows, Repeatability::Known(largest * 1.5)).is_err()
        );
        // Assumed, it is not trusted over the residuals: no more than all they hold is taken.
        let assumed =
            Propagation::of(&model, &options, &rows, Repeatability::Assumed(0.1)).unwrap();
        let taken = assumed.repeatability_variance_mm2.sqrt();
        assert!(
            (taken - largest).abs() < 1e-6,
            "{taken} mm against {largest}"
        );
        assert_eq!(assumed.noise.instrument_variance_mm2, 0.0);
        // Options that are not the model's identification: refused, not propagated.
        let known = Repeatability::Known(0.004);
        for (other, says) in [
            (IdentifyOptions::physical(12), "coefficients"),
            (options.smoothed(f64::NAN), "smoothness prior"),
            (options.smoothed(-0.01), "smoothness prior"),
        ] {
            let e = Propagation::of(&model, &other, &rows, known).unwrap_err();
            assert!(e.to_string().contains(says), "{e}");
        }
    }

    /// The trace of the sample covariance of `values`, mm².
    fn scatter(values: &[SMatrix<f64, LEGS, 1>]) -> f64 {
        let n = values.len() as f64;
        let mean = values.iter().sum::<SMatrix<f64, LEGS, 1>>() / n;
        values
            .iter()
            .map(|v| (v - mean).norm_squared())
            .sum::<f64>()
            / (n - 1.0)
    }

    #[test]
    fn the_leverage_averages_one_over_the_configurations_and_grows_outside_them() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let configurations: Vec<[f64; LEGS]> = (0..60)
            .map(|_| std::array::from_fn(|_| rng.random_range(300.0..400.0)))
            .collect();
        let u = leverage_of(&configurations).unwrap();
        let mean = configurations.iter().map(|q| u.leverage(q)).sum::<f64>() / 60.0;
        assert!((mean - 1.0).abs() < 1e-6, "{mean}");
        let centre = [350.0; LEGS];
        let mut outside = centre;
        outside[2] = 500.0;
        assert!(u.leverage(&outside) > 10.0 * u.leverage(&centre));
        // Too few configurations, or a leg that never moves, are refused.
        assert!(leverage_of(&configurations[..12]).is_err());
        let mut still = configurations.clone();
        for q in &mut still {
            q[4] = 350.0;
        }
        let e = leverage_of(&still).unwrap_err().to_string();
        assert!(e.contains("leg 5"), "{e}");
    }

    #[test]
    fn the_relative_fit_recovers_known_variances_and_stays_non_negative() {
        let samples: Vec<(f64, f64)> = (0..50)
            .map(|k| {
                let h = 0.2 + 0.1 * k as f64;
                (h, 2e-5 + 3e-5 * h)
            })
            .collect();
        let [a, b] = relative_fit(&samples);
        assert!(
            (a - 2e-5).abs() < 1e-12 && (b - 3e-5).abs() < 1e-12,
            "{a} {b}"
        );
        // Falling with the leverage: a constant, not a negative slope.
        let falling: Vec<(f64, f64)> = (0..50)
            .map(|k| {
                let h = 0.2 + 0.1 * k as f64;
                (h, 1e-4 - 1e-5 * h)
            })
            .collect();
        let [a, b] = relative_fit(&falling);
        assert!(a > 0.0 && b == 0.0, "{a} {b}");
    }

    #[test]
    fn the_relative_fit_is_relative_to_the_fit_not_to_the_scattered_samples() {
        // Each leverage twice, at half and at one and a half times the variance: the variances'
        // mean at every leverage is exactly 2e-5 + 3e-5·h. Relative to the samples, the fit
        // leans to the halves (a constant would come out at 0.6 of the mean).
        let scattered: Vec<(f64, f64)> = (0..50)
            .flat_map(|k| {
                let h = 0.2 + 0.1 * k as f64;
                let variance = 2e-5 + 3e-5 * h;
                [(h, 0.5 * variance), (h, 1.5 * variance)]
            })
            .collect();
        let [a, b] = relative_fit(&scattered);
        assert!(
            (a / 2e-5 - 1.0).abs() < 1e-6 && (b / 3e-5 - 1.0).abs() < 1e-6,
            "{a} {b}"
        );
    }
}
