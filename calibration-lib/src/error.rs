//! The one error type of the calibration numerics.

use thiserror::Error;

/// Everything the calibration numerics can fail with.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum Error {
    /// An error of the core numerics.
    #[error(transparent)]
    Core(#[from] hexacomp_core::Error),

    /// A setting is outside its valid range.
    #[error("invalid setting: {setting} = {value} {valid}")]
    OutOfRange {
        /// The setting, as its option is named.
        setting: &'static str,
        /// The value given.
        value: f64,
        /// What is valid ("must be a number > 0").
        valid: &'static str,
    },

    /// Network training was asked for without a hidden size or without a restart.
    #[error("invalid setting: training needs at least one hidden size and one restart")]
    NothingToTrain,

    /// Too few configurations for the computation.
    #[error("insufficient data: {task} needs at least {needed} configurations, got {got}")]
    TooFewConfigurations {
        /// What needs them ("identification", "training").
        task: &'static str,
        /// How many it needs.
        needed: usize,
        /// How many there are.
        got: usize,
    },

    /// Cross-validation is impossible with these folds and rows: at least 2 folds and two rows
    /// per fold to hold out besides the legs' extremes are needed (and, for networks, one
    /// hidden size per network).
    #[error(
        "invalid setting: cross-validating {what} needs at least 2 folds ({folds} given) and \
         two configurations per fold to hold out besides the legs' extremes ({rows} \
         configurations){}",
        if *sizes_match { "" } else { ", and one hidden size per network" }
    )]
    CrossValidationImpossible {
        /// What is cross-validated ("the physical model", "6 networks").
        what: String,
        /// The folds asked for.
        folds: usize,
        /// The configurations.
        rows: usize,
        /// Whether the hidden sizes given match the networks (always for the physical model).
        sizes_match: bool,
    },

    /// The robust corrections are not one per measured configuration, in the same order.
    #[error(
        "invalid setting: the physical model needs one robust correction per measured \
         configuration, in the same order ({measurements} configurations, {corrections} \
         corrections)"
    )]
    CorrectionsMismatch {
        /// The measured configurations.
        measurements: usize,
        /// The corrections given.
        corrections: usize,
    },

    /// The measurements do not fit the geometry (another number of targets, numbers that are not
    /// finite).
    #[error(
        "the measurements do not fit the geometry: {}{problem}",
        configuration_prefix(configuration)
    )]
    MeasurementsMismatch {
        /// The configuration at fault, where one is.
        configuration: Option<String>,
        /// What does not fit.
        problem: hexacomp_core::observation::Mismatch,
    },

    /// A measured configuration does not determine the six leg corrections (too few targets
    /// seen).
    #[error("insufficient data: {reason}")]
    Undetermined {
        /// Why, as the observation says.
        reason: String,
    },

    /// The normal equations of a correction step (`(PT)ᵀ(PT) + λI`, Eq. 7) cannot be solved: the
    /// measured target points do not determine the six leg corrections at this configuration.
    #[error(
        "the normal equations (PT)ᵀ(PT) + λI of the correction step are singular (cond(PT) = \
         {cond_pt:.3e}, λ = {lambda:e}): the targets cannot determine six leg corrections here \
         (targets on one line? enable the robust solve to regularise)"
    )]
    SingularNormalEquations {
        /// `cond(PT)` at the iterate, as computed (infinite when `PT` is rank-deficient).
        cond_pt: f64,
        /// The regularisation `λ` applied at the iterate (0: none).
        lambda: f64,
    },

    /// The input as a whole was refused: so much of it is a gross error that the data must be
    /// wrong (the message says what was found and the likely causes).
    #[error("refused: {reason}")]
    Refused {
        /// What was found and the likely causes.
        reason: String,
        /// The decision about every configuration, so that a caller can list them.
        screening: Box<crate::screening::Screening>,
    },

    /// The model cannot reach a measured configuration's commanded legs.
    #[error("insufficient data: configuration {configuration}: {cause}")]
    Unreachable {
        /// The configuration's id.
        configuration: String,
        /// Why (forward kinematics failed, the loaded pose did not settle).
        cause: Box<Error>,
    },

    /// The legs' sag under the payload and the pose did not settle together.
    #[error("the legs' sag and the pose did not settle together in {passes} passes")]
    LoadedPoseUnsettled {
        /// The passes tried.
        passes: usize,
    },

    /// A measured configuration is singular: its actuation screws do not span the motions.
    #[error("insufficient data: configuration {configuration} is singular")]
    SingularConfiguration {
        /// The configuration's id.
        configuration: String,
    },

    /// An identification step could not be solved.
    #[error("insufficient data: identification step: {cause}")]
    IdentificationStep {
        /// The solver's reason.
        cause: &'static str,
    },

    /// An identification failed where its data determined fewer than all its parameters: it
    /// drifted into geometries where forward kinematics fails.
    #[error(
        "{cause}; the configurations determine only {rank} of the {parameters} parameter \
         combinations (ill-conditioned: measure configurations spread over the whole workspace)"
    )]
    IllConditioned {
        /// The error of the iterate.
        cause: Box<Error>,
        /// The parameter combinations the data determined.
        rank: usize,
        /// The parameters identified.
        parameters: usize,
    },

    /// No lead-screw resolution of the physical model could be cross-validated.
    #[error(
        "insufficient data: no lead-screw resolution of the physical model could be \
         cross-validated ({})",
        reasons.iter().map(|(basis, why)| format!("{basis} coefficients: {why}")).collect::<Vec<_>>().join("; ")
    )]
    NoResolutionCrossValidated {
        /// Each resolution tried (coefficients per leg) and why it has no score.
        reasons: Vec<(usize, String)>,
    },

    /// A cross-validated error or its standard error is not finite.
    #[error("cross-validated to {rmse_mm} ± {standard_error_mm} mm")]
    ScoreUnbounded {
        /// The cross-validated RMSE, mm.
        rmse_mm: f64,
        /// Its standard error, mm.
        standard_error_mm: f64,
    },

    /// A fold of a cross-validation failed.
    #[error("identified without fold {fold}: {cause}")]
    FoldFailed {
        /// The fold, from 1.
        fold: usize,
        /// Why.
        cause: Box<Error>,
    },

    /// Too few poses drawn over the workspace lie within the measured legs' range to fit the
    /// physical model's uncertainty at.
    #[error(
        "insufficient data: only {drawn} of {attempts} workspace poses lie within the measured \
         legs' range; the physical model's uncertainty needs {needed} to be fitted at"
    )]
    TooFewPosesInRange {
        /// The poses drawn within the range.
        drawn: usize,
        /// The poses tried.
        attempts: usize,
        /// The poses needed.
        needed: usize,
    },

    /// The physical model's cross-validated error is not a finite number.
    #[error("invalid setting: the physical model's cross-validated error is {score_mm} mm")]
    ScoreNotFinite {
        /// The cross-validated RMSE, mm.
        score_mm: f64,
    },

    /// A model and the identification options it is propagated with have other lead-screw
    /// resolutions.
    #[error(
        "invalid setting: the model's lead-screw curves have {model} coefficients, the \
         identification's options {options}"
    )]
    ResolutionMismatch {
        /// The model's coefficients per leg.
        model: usize,
        /// The options' coefficients per leg.
        options: usize,
    },

    /// A known repeatability would give the identification's residuals more than twice the
    /// variance they hold: it is not the machine's.
    #[error(
        "invalid setting: the machine's repeatability of {repeatability_mm} mm would give the \
         identification's residuals more than twice the variance they hold (all of it is a \
         repeatability of {all_of_it_um:.3} µm with a noiseless instrument)"
    )]
    RepeatabilityTooLarge {
        /// The repeatability given, mm (1 σ).
        repeatability_mm: f64,
        /// The repeatability that would be all the residuals hold, µm.
        all_of_it_um: f64,
    },

    /// No residual is left to estimate the noise from.
    #[error(
        "insufficient data: {residuals} residuals for {kept} identified parameter combinations \
         leave {freedom:.2} degrees of freedom: no residual is left to estimate the noise from"
    )]
    NoDegreesOfFreedom {
        /// The residuals.
        residuals: usize,
        /// The parameter combinations identified.
        kept: usize,
        /// The degrees of freedom left.
        freedom: f64,
    },

    /// The smoothness prior's bias is measured against another identification than the same
    /// one without the prior, from the same rows.
    #[error(
        "invalid setting: a prior's bias is measured against the same identification without \
         it, from the same rows: this model has {} coefficients, a prior of {} and {} \
         residuals, the other {} coefficients, a prior of {} and {} residuals",
        model.0, model.1, model.2, reference.0, reference.1, reference.2
    )]
    PriorReferenceMismatch {
        /// The model's coefficients per leg, smoothness weight and residuals.
        model: (usize, f64, usize),
        /// The reference's.
        reference: (usize, f64, usize),
    },

    /// The uncertainty of a model with a smoothness prior needs the same resolution identified
    /// without the prior, which bounds the prior's bias.
    #[error(
        "invalid setting: the uncertainty of a model with a smoothness prior of {smoothness} \
         needs the same resolution identified without the prior, which bounds the prior's \
         bias; none was given"
    )]
    PriorReferenceMissing {
        /// The prior's weight.
        smoothness: f64,
    },

    /// The uncertainty could be fitted at too few poses over the measured range.
    #[error(
        "insufficient data: the uncertainty is fitted at poses over the measured range; \
         {usable} of {drawn} could be used"
    )]
    TooFewUncertaintyPoses {
        /// The poses it could be propagated to.
        usable: usize,
        /// The poses drawn.
        drawn: usize,
    },

    /// A leg has the same length in every configuration: no range to place the uncertainty in.
    #[error(
        "insufficient data: leg {leg} has the same length in every configuration: no range to \
         place the uncertainty in"
    )]
    LegWithoutRange {
        /// The leg, from 1.
        leg: usize,
    },

    /// The configurations' leg moments are not positive definite (the legs' lengths are
    /// linearly dependent over the configurations).
    #[error("insufficient data: the configurations' leg moments are not positive definite")]
    LegMomentsSingular,

    /// An error of one of several computations, naming which.
    #[error("{what}: {cause}")]
    Of {
        /// The computation ("the alternative of 16 lead-screw coefficients per leg").
        what: String,
        /// Its error.
        cause: Box<Error>,
    },
}

/// "configuration ID: " where there is one.
fn configuration_prefix(configuration: &Option<String>) -> String {
    configuration
        .as_ref()
        .map_or_else(String::new, |id| format!("configuration {id}: "))
}

impl Error {
    /// This error of the computation `what`, its message naming it.
    pub fn of(self, what: impl Into<String>) -> Self {
        Error::Of {
            what: what.into(),
            cause: Box::new(self),
        }
    }
}

/// `Result` with the calibration's [`enum@Error`].
pub type Result<T> = std::result::Result<T, Error>;
