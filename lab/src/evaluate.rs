//! Evaluation on the virtual platform: the paper's Table 1, Table 2, Fig. 12 and Fig. 13.
//!
//! A plan of configurations is measured once on a virtual machine and solved by the robust and
//! the ordinary iteration. For each training size (a prefix of the plan, itself spread over the
//! workspace), the model-based baseline is identified and the networks are trained; every method
//! then drives the same machine to fresh validation poses that no training used. Each method's
//! errors are given in two protocols: the pose the machine actually reached (known only in
//! simulation), and the pose an instrument reports from the three measured targets, as the paper
//! evaluates (Sec. 4.2, Eq. 4), with the instrument's noise in it.

use hexacomp_core::compensator::compensate_pose;
use hexacomp_core::kinematics::pose_from_targets;
use hexacomp_core::model::{Model, NetworkInput};
use hexacomp_core::records::{JointCorrection, MeasuredConfiguration};
use hexacomp_core::sampling::{SamplerOptions, WorkspaceSampler};
use hexacomp_core::stats::{PoseErrorNorm, PoseErrorStats};
use hexacomp_core::{Geometry, Pose, inverse_kinematics};
use hexacomp_virtual::{ErrorModel, VirtualPlatform};

use crate::error::{Error, Result};
use hexacomp_calibration::corrections::{Checks, Outcome, SolverOptions};
use hexacomp_calibration::identify::{IdentifyOptions, PHYSICAL, identify};
use hexacomp_calibration::physical_candidate::with_uncertainty;
use hexacomp_calibration::pipeline::Pipeline;
use hexacomp_calibration::pitch_resolution::{ResolutionChoice, chosen_if_cross_validated};
use hexacomp_calibration::plan::PlanOptions;
use hexacomp_calibration::screening::ScreeningOptions;
use hexacomp_calibration::train::{Architecture, CROSS_VALIDATION_FOLDS, TrainOptions, Trained};
use hexacomp_calibration::uncertainty::{Coverage, Repeatability};
use hexacomp_core::physical::PhysicalModel;

/// A compensation method of the comparison.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Method {
    /// Nominal inverse kinematics, no compensation.
    Uncompensated,
    /// Inverse kinematics of the identified geometry (the paper's POE-based comparison).
    ModelBased,
    /// The identified physical model: geometry, a lead-screw curve per leg and the legs'
    /// compliance under the weight ([`hexacomp_core::physical`]), as its model file commands
    /// (what `calibrate` writes by default).
    Physical,
    /// The physical model, and decoupled networks trained on the robust corrections it leaves
    /// (each stage fitted on what the one before left).
    PhysicalResidual,
    /// Coupled network on corrections solved with λ = 0 (the paper's ordinary compensator).
    OrdinaryCoupled,
    /// Coupled network on robust corrections.
    RobustCoupled,
    /// Decoupled networks on robust corrections.
    RobustDecoupled,
    /// Decoupled networks on the exact corrections of the same configurations (the legs that
    /// put the noiseless machine on each commanded pose, known only in simulation): what the
    /// model class reaches without noise in its training data.
    ExactDecoupled,
    /// The exact legs of each pose, driven with the machine's repeatability: the floor no
    /// method can go below.
    Floor,
}

impl Method {
    /// Every method, in table order.
    pub const ALL: [Method; 9] = [
        Method::Uncompensated,
        Method::ModelBased,
        Method::Physical,
        Method::PhysicalResidual,
        Method::OrdinaryCoupled,
        Method::RobustCoupled,
        Method::RobustDecoupled,
        Method::ExactDecoupled,
        Method::Floor,
    ];

    /// A short label for tables and legends.
    pub fn label(self) -> &'static str {
        match self {
            Method::Uncompensated => "before",
            Method::ModelBased => "model-based",
            Method::Physical => "physical model",
            Method::PhysicalResidual => "physical + networks",
            Method::OrdinaryCoupled => "ordinary coupled",
            Method::RobustCoupled => "robust coupled",
            Method::RobustDecoupled => "robust decoupled",
            Method::ExactDecoupled => "decoupled, exact corrections",
            Method::Floor => "floor",
        }
    }
}

/// Settings of an evaluation.
#[derive(Debug, Clone)]
pub struct EvaluationOptions {
    /// Training sizes (configurations); the plan has as many as the largest.
    pub training_sizes: Vec<usize>,
    /// Fresh validation poses.
    pub validation_count: usize,
    /// Seed of the plan.
    pub plan_seed: u64,
    /// Start the plan with each leg's shortest and longest reach
    /// ([`PlanOptions::leg_extremes`]; `false`: best-candidate sampling alone, to compare).
    pub leg_extremes: bool,
    /// Seed of the validation poses.
    pub validation_seed: u64,
    /// The virtual machine's errors.
    pub error_model: ErrorModel,
    /// Seed of the virtual machine.
    pub machine_seed: u64,
    /// Seed of its repeatability and measuring noise while the plan is measured.
    pub noise_seed: u64,
    /// Seed of the instrument's noise at the validation poses (drawn apart from the machine's).
    pub instrument_seed: u64,
    /// Network training settings (the input is set per model).
    pub train: TrainOptions,
}

/// How a pose error at a validation pose is obtained.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Protocol {
    /// Against the pose the virtual machine really reached (known only in simulation).
    Reached,
    /// Against the pose fitted to the instrument's measured targets (Eq. 4), as the paper
    /// evaluates: the instrument's noise is in it.
    Measured,
}

/// One method's pose errors at the validation poses, in both protocols (same order as the
/// poses).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ValidationErrors {
    /// Commanded against reached poses.
    pub reached: Vec<PoseErrorNorm>,
    /// Commanded against measured poses.
    pub measured: Vec<PoseErrorNorm>,
}

impl ValidationErrors {
    /// The errors of `protocol`.
    pub fn of(&self, protocol: Protocol) -> &[PoseErrorNorm] {
        match protocol {
            Protocol::Reached => &self.reached,
            Protocol::Measured => &self.measured,
        }
    }
}

/// Errors of every method at every validation pose, for one training size.
#[derive(Debug, Clone)]
pub struct SizeResult {
    /// Training configurations.
    pub configurations: usize,
    /// Per method, the errors at each validation pose.
    pub errors: Vec<(Method, ValidationErrors)>,
    /// The trained robust coupled and decoupled models, for Table 1.
    pub coupled: Trained,
    /// See `coupled`.
    pub decoupled: Trained,
    /// The physical model's lead-screw resolution, chosen by cross-validation (`None`: too few
    /// configurations to cross-validate, eight coefficients).
    pub resolution: Option<ResolutionChoice>,
    /// How the physical model's uncertainty held on the validation poses (`None`:
    /// they carry none, too few configurations to fit it).
    pub uncertainty: Option<Coverage>,
}

/// The coverage of `model`'s uncertainty at `poses` against the position errors reached there
/// (same order). Points without an uncertainty count as 0 mm.
pub fn uncertainty_coverage(
    geometry: &Geometry,
    model: &hexacomp_core::model::Model,
    poses: &[Pose],
    errors: &[PoseErrorNorm],
) -> Coverage {
    let pairs: Vec<(f64, f64)> = poses
        .iter()
        .zip(errors)
        .map(|(pose, e)| {
            let sigma = compensate_pose(geometry, Some(model), pose).uncertainty_mm;
            (e.position_mm, sigma.unwrap_or(0.0))
        })
        .collect();
    Coverage::of(&pairs)
}

impl SizeResult {
    /// The errors of `method`.
    pub fn errors_of(&self, method: Method) -> &ValidationErrors {
        &self
            .errors
            .iter()
            .find(|(m, _)| *m == method)
            .expect("every method")
            .1
    }

    /// Table 2 statistics of `method` in `protocol`.
    pub fn stats(&self, method: Method, protocol: Protocol) -> PoseErrorStats {
        PoseErrorStats::of(self.errors_of(method).of(protocol))
    }
}

/// The whole evaluation.
#[derive(Debug, Clone)]
pub struct Evaluation {
    /// One result per training size, in the order given.
    pub sizes: Vec<SizeResult>,
    /// Configurations whose cond(PT) exceeded the threshold in the robust solve.
    pub above_threshold: usize,
    /// Input comparison at the largest size: decoupled networks with each input (reached).
    pub inputs: Vec<(NetworkInput, PoseErrorStats)>,
}

/// Runs the evaluation. `progress` receives a line per stage.
pub fn evaluate(
    geometry: &Geometry,
    options: &EvaluationOptions,
    progress: &dyn Fn(&str),
) -> Result<Evaluation> {
    let largest = *options
        .training_sizes
        .iter()
        .max()
        .ok_or(Error::NoTrainingSize)?;
    progress(&format!(
        "measuring {largest} configurations on the virtual machine"
    ));
    let campaign = Campaign::measured(geometry, options, largest)?;
    let mut sizes = Vec::new();
    let mut inputs = Vec::new();
    for &n in &options.training_sizes {
        progress(&format!(
            "{n} configurations: identifying the geometry and the physical model, carrying it \
             into networks, training five more"
        ));
        let models = campaign.models_at(n)?;
        let errors = campaign.drive_every_method(&models)?;
        if n == largest {
            inputs = campaign.input_comparison(n, &errors)?;
        }
        sizes.push(campaign.size_result(n, models, errors));
    }
    Ok(Evaluation {
        sizes,
        above_threshold: campaign.above_threshold(),
        inputs,
    })
}

/// The robust pipeline of the comparison: `options`' plan of `largest` configurations and
/// training, every solved correction trained on.
fn robust_pipeline(options: &EvaluationOptions, largest: usize) -> Pipeline {
    Pipeline {
        plan: PlanOptions {
            count: largest,
            seed: options.plan_seed,
            leg_extremes: options.leg_extremes,
            ..Default::default()
        },
        train: options.train.clone(),
        // The paper's comparison trains every method on every correction it solves (the virtual
        // platform makes no gross errors): the ordinary compensator's erratic corrections near
        // singular configurations are what it shows, and screening would hide them.
        checks: Checks {
            max_correction_mm: f64::INFINITY,
            ..Checks::default()
        },
        screening: ScreeningOptions::keep_all(),
        ..Default::default()
    }
}

/// The measured plan every size trains on, the machine and instrument every method meets, and
/// the validation poses.
struct Campaign<'a> {
    geometry: &'a Geometry,
    options: &'a EvaluationOptions,
    robust_pipeline: Pipeline,
    measurements: Vec<MeasuredConfiguration>,
    /// The machine after the plan was measured: each method drives a copy of it.
    platform: VirtualPlatform,
    /// The instrument measuring the validation poses, with noise drawn apart from the
    /// machine's moves (the reached errors do not depend on whether they are also measured).
    instrument: VirtualPlatform,
    /// Every configuration's robust (Fig. 2) and ordinary (λ = 0) outcome, in plan order.
    robust: Vec<Outcome>,
    ordinary: Vec<Outcome>,
    validation: Vec<Pose>,
}

/// Every method's model at one training size.
struct Models {
    identified: Geometry,
    physical: PhysicalModel,
    resolution: Option<ResolutionChoice>,
    /// The physical model's model file.
    served: Model,
    residual: Trained,
    ordinary_coupled: Trained,
    coupled: Trained,
    decoupled: Trained,
    exact_decoupled: Trained,
}

impl<'a> Campaign<'a> {
    /// Measures `largest` configurations of the plan on the virtual machine and solves them by
    /// the robust and the ordinary iteration.
    fn measured(
        geometry: &'a Geometry,
        options: &'a EvaluationOptions,
        largest: usize,
    ) -> Result<Self> {
        let robust_pipeline = robust_pipeline(options, largest);
        // The paper's ordinary compensator: the same pipeline with λ = 0.
        let ordinary_pipeline = Pipeline {
            solver: SolverOptions {
                robust: false,
                ..robust_pipeline.solver
            },
            ..robust_pipeline.clone()
        };
        let mut platform = VirtualPlatform::new(
            geometry,
            &options.error_model,
            options.machine_seed,
            options.noise_seed,
        )?;
        let (_, measurements) = crate::measure_virtual(&robust_pipeline.plan, &mut platform)?;
        let instrument = platform.reseeded(options.instrument_seed);
        let robust = robust_pipeline.solve(geometry, &measurements)?.outcomes;
        let ordinary = ordinary_pipeline.solve(geometry, &measurements)?.outcomes;
        let validation =
            WorkspaceSampler::new(geometry, options.validation_seed, SamplerOptions::default())?
                .samples(options.validation_count)?;
        Ok(Self {
            geometry,
            options,
            robust_pipeline,
            measurements,
            platform,
            instrument,
            robust,
            ordinary,
            validation,
        })
    }

    /// Configurations whose cond(PT) exceeded the threshold in the robust solve.
    fn above_threshold(&self) -> usize {
        self.robust
            .iter()
            .filter_map(|o| o.solution.as_ref().ok())
            .filter(|s| s.max_cond_pt > self.robust_pipeline.solver.cond_threshold)
            .count()
    }

    /// The correction rows of the first `n` configurations' solved `outcomes`.
    fn rows(outcomes: &[Outcome], n: usize) -> Vec<JointCorrection> {
        outcomes[..n]
            .iter()
            .filter_map(|o| o.joint_correction())
            .collect()
    }

    /// The exact corrections of the first `n` configurations: the machine commanded with the
    /// exact legs of a configuration's pose reaches it, so those legs are the row's commanded
    /// ones, and its equivalent legs the pose's nominal ones.
    fn exact_rows(&self, n: usize) -> Vec<JointCorrection> {
        let truth = self.platform.machine();
        self.measurements[..n]
            .iter()
            .map(|m| {
                let exact = truth.exact_command(&Pose::from_mm_deg(m.pose_mm_deg));
                JointCorrection {
                    id: m.id.clone(),
                    legs: exact,
                    corrections: std::array::from_fn(|i| exact[i] - m.legs[i]),
                }
            })
            .collect()
    }

    /// Networks of `architecture` on `corrections`, with `input`, trained as the options say.
    fn fit(
        &self,
        corrections: &[JointCorrection],
        architecture: Architecture,
        input: NetworkInput,
    ) -> Result<Trained> {
        let pipeline = Pipeline {
            train: TrainOptions {
                input,
                ..self.options.train.clone()
            },
            ..self.robust_pipeline.clone()
        };
        Ok(pipeline.train(self.geometry, corrections, architecture, &|_| {})?)
    }

    /// Every method's model from the first `n` configurations.
    fn models_at(&self, n: usize) -> Result<Models> {
        let geometry = self.geometry;
        let identified = identify(
            geometry,
            &self.measurements[..n],
            &IdentifyOptions::default(),
        )?
        .geometry;
        let robust_rows = Self::rows(&self.robust, n);
        let (physical, resolution, served, solved) = self.physical_at(n, &robust_rows)?;
        let left_by_physical = left_by(&physical, &robust_rows, &solved);
        let input = self.options.train.input;
        Ok(Models {
            identified,
            residual: self.fit(&left_by_physical, Architecture::Decoupled, input)?,
            ordinary_coupled: self.fit(
                &Self::rows(&self.ordinary, n),
                Architecture::Coupled,
                input,
            )?,
            coupled: self.fit(&robust_rows, Architecture::Coupled, input)?,
            decoupled: self.fit(&robust_rows, Architecture::Decoupled, input)?,
            exact_decoupled: self.fit(&self.exact_rows(n), Architecture::Decoupled, input)?,
            physical,
            resolution,
            served,
        })
    }

    /// The physical model as `calibrate` makes it from the first `n` configurations: its
    /// lead-screw resolution chosen by cross-validation on the configurations whose robust
    /// corrections were solved (eight with too few to cross-validate), on the folds of the
    /// training seed (the command's default, 1: `calibrate --seed 1`'s folds), and its model
    /// file. No resolution scored at a size ends the evaluation, naming the size. Also the
    /// solved configurations' measurements, in `robust_rows`' order.
    fn physical_at(
        &self,
        n: usize,
        robust_rows: &[JointCorrection],
    ) -> Result<(
        PhysicalModel,
        Option<ResolutionChoice>,
        Model,
        Vec<MeasuredConfiguration>,
    )> {
        let solved: Vec<MeasuredConfiguration> = robust_rows
            .iter()
            .map(|row| {
                self.measurements
                    .iter()
                    .find(|m| m.id == row.id)
                    .expect("a correction of a measured configuration")
                    .clone()
            })
            .collect();
        let resolution = chosen_if_cross_validated(
            self.geometry,
            &solved,
            robust_rows,
            self.options.train.seed,
            CROSS_VALIDATION_FOLDS,
            &|_| {},
        )
        .map_err(|cause| Error::AtSize {
            configurations: n,
            cause,
        })?;
        let identification = resolution.as_ref().map_or(PHYSICAL, |r| r.options);
        let physical = identify(self.geometry, &solved, &identification)?.model;
        let alternative_bases = resolution
            .as_ref()
            .map_or_else(Vec::new, ResolutionChoice::indistinguishable);
        let cross_validated_mm = resolution
            .as_ref()
            .map_or(f64::NAN, |r| r.chosen().cross_validated_rmse_mm);
        let served = with_uncertainty(
            self.geometry,
            (&physical, &identification),
            &alternative_bases,
            (&solved, cross_validated_mm),
            Repeatability::Known(self.options.error_model.repeatability_sigma_mm),
            self.options.train.seed,
        )?
        .model;
        Ok((physical, resolution, served, solved))
    }

    /// The legs `method` commands for `pose` with `models`.
    fn command(&self, method: Method, models: &Models, pose: &Pose) -> [f64; 6] {
        let geometry = self.geometry;
        let networks =
            |trained: &Trained| compensate_pose(geometry, Some(&trained.model), pose).legs;
        match method {
            Method::Uncompensated => inverse_kinematics(geometry, pose).lengths,
            Method::ModelBased => inverse_kinematics(&models.identified, pose).lengths,
            Method::Physical => compensate_pose(geometry, Some(&models.served), pose).legs,
            Method::PhysicalResidual => {
                let left = compensate_pose(geometry, Some(&models.residual.model), pose);
                let modelled = models.physical.command(pose);
                std::array::from_fn(|i| modelled[i] + left.corrections[i])
            }
            Method::OrdinaryCoupled => networks(&models.ordinary_coupled),
            Method::RobustCoupled => networks(&models.coupled),
            Method::RobustDecoupled => networks(&models.decoupled),
            Method::ExactDecoupled => networks(&models.exact_decoupled),
            Method::Floor => self.platform.machine().exact_command(pose),
        }
    }

    /// Every method's errors on the validation poses. Every method meets the same
    /// repeatability and instrument noise: each drives a copy of the machine in the same state,
    /// measured by a copy of the instrument in the same state.
    fn drive_every_method(&self, models: &Models) -> Result<Vec<(Method, ValidationErrors)>> {
        Method::ALL
            .into_iter()
            .map(|method| {
                let errors = drive(
                    &mut self.platform.clone(),
                    &mut self.instrument.clone(),
                    &self.validation,
                    |pose| self.command(method, models, pose),
                )?;
                Ok((method, errors))
            })
            .collect()
    }

    /// The decoupled networks trained on the first `n` configurations with each input (the one
    /// trained on, then the other), reached.
    fn input_comparison(
        &self,
        n: usize,
        errors: &[(Method, ValidationErrors)],
    ) -> Result<Vec<(NetworkInput, PoseErrorStats)>> {
        let input = self.options.train.input;
        let other = match input {
            NetworkInput::Equivalent => NetworkInput::Commanded,
            NetworkInput::Commanded => NetworkInput::Equivalent,
        };
        let alternative = self.fit(&Self::rows(&self.robust, n), Architecture::Decoupled, other)?;
        let own = errors
            .iter()
            .find(|(m, _)| *m == Method::RobustDecoupled)
            .expect("decoupled");
        let alt = drive(
            &mut self.platform.clone(),
            &mut self.instrument.clone(),
            &self.validation,
            |pose| compensate_pose(self.geometry, Some(&alternative.model), pose).legs,
        )?;
        Ok(vec![
            (input, PoseErrorStats::of(&own.1.reached)),
            (other, PoseErrorStats::of(&alt.reached)),
        ])
    }

    /// One size's result, with the coverage of the physical model's uncertainty where it
    /// carries one.
    fn size_result(
        &self,
        n: usize,
        models: Models,
        errors: Vec<(Method, ValidationErrors)>,
    ) -> SizeResult {
        let mut size = SizeResult {
            configurations: n,
            errors,
            coupled: models.coupled,
            decoupled: models.decoupled,
            resolution: models.resolution,
            uncertainty: None,
        };
        if models.served.uncertainty.is_some() {
            size.uncertainty = Some(uncertainty_coverage(
                self.geometry,
                &models.served,
                &self.validation,
                &size.errors_of(Method::Physical).reached,
            ));
        }
        size
    }
}

/// The robust corrections `rows` less what `physical` models of them, at the configurations
/// `solved` (in `rows`' order), mm.
fn left_by(
    physical: &PhysicalModel,
    rows: &[JointCorrection],
    solved: &[MeasuredConfiguration],
) -> Vec<JointCorrection> {
    rows.iter()
        .zip(solved)
        .map(|(row, measured)| {
            let modelled = physical.command(&measured.pose());
            JointCorrection {
                corrections: std::array::from_fn(|i| {
                    row.corrections[i] - (modelled[i] - row.legs[i])
                }),
                ..row.clone()
            }
        })
        .collect()
}

/// Drives the machine to every pose with the legs `command` gives, and measures each reached
/// pose's targets with `instrument` (its noise only: the targets are the nominal geometry's); the
/// errors in both protocols.
pub fn drive(
    platform: &mut VirtualPlatform,
    instrument: &mut VirtualPlatform,
    poses: &[Pose],
    command: impl Fn(&Pose) -> [f64; 6],
) -> Result<ValidationErrors> {
    let mut errors = ValidationErrors::default();
    for pose in poses {
        let reached = platform.move_legs(&command(pose), pose)?;
        let targets = instrument.measure_targets(&reached);
        let seen: Vec<_> = targets.into_iter().map(Some).collect();
        let measured = pose_from_targets(platform.nominal(), &seen)?;
        errors.reached.push(PoseErrorNorm::between(pose, &reached));
        errors
            .measured
            .push(PoseErrorNorm::between(pose, &measured));
    }
    Ok(errors)
}
