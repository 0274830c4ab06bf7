//! The one error type of measuring a machine.

use thiserror::Error;

/// Everything measuring a machine can fail with.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum Error {
    /// An error of the calibration numerics (a plan, a solve, an identification).
    #[error(transparent)]
    Calibration(#[from] hexacomp_calibration::Error),

    /// An error of the core numerics.
    #[error(transparent)]
    Core(#[from] hexacomp_core::Error),

    /// A CSV file could not be read or written, or one of its rows is invalid.
    #[error(transparent)]
    Format(#[from] hexacomp_formats::Error),

    /// A setting is outside its valid range.
    #[error("invalid setting: {setting} = {value} {valid}")]
    OutOfRange {
        /// The setting, as its option is named.
        setting: &'static str,
        /// The value given.
        value: f64,
        /// What is valid ("must be ≥ 1").
        valid: &'static str,
    },

    /// A fiducial measured again is not one of the registration's.
    #[error("invalid setting: fiducial {fiducial} is not one of the registration's")]
    UnknownFiducial {
        /// The fiducial's name.
        fiducial: String,
    },

    /// A LinuxCNC configuration's joint limits are no leg stroke.
    #[error(
        "invalid setting: the joint limits [{min_mm}, {max_mm}] mm are no leg stroke (set \
         MIN_LIMIT/MAX_LIMIT of the joints to the actuators' travel, or give the stroke: \
         --leg-range MIN,MAX)"
    )]
    NoLegStroke {
        /// The largest lower joint limit, mm.
        min_mm: f64,
        /// The smallest upper joint limit, mm.
        max_mm: f64,
    },

    /// The machine's compensation is active during a calibration campaign, which measures the
    /// machine as it is.
    #[error(
        "the machine: configuration {configuration}: the drives are commanded {offset_mm:.4} mm \
         away from the nominal legs: compensation is active. A calibration measures the \
         machine as it is: switch it off (halcmd setp hexacomp.0.enable 0) and run again"
    )]
    CompensationActive {
        /// The configuration driven to.
        configuration: String,
        /// The largest difference between a drive and its nominal leg, mm.
        offset_mm: f64,
    },

    /// A configuration's pose needs legs outside the stroke.
    #[error(
        "the machine: configuration {configuration}: the pose needs legs outside the stroke (a \
         pose outside the workspace?)"
    )]
    OutsideStroke {
        /// The configuration driven to.
        configuration: String,
    },

    /// The machine's compensation model does not compensate a configuration's pose.
    #[error(
        "the machine: configuration {configuration}: the model does not compensate the pose ({status})"
    )]
    NotCompensated {
        /// The configuration driven to.
        configuration: String,
        /// The point status the model gave.
        status: &'static str,
    },

    /// An error of the machine at one configuration.
    #[error("configuration {configuration}: {cause}")]
    AtConfiguration {
        /// The configuration driven to.
        configuration: String,
        /// What went wrong.
        cause: Box<Error>,
    },

    /// LinuxCNC (through its bridge) reported an error: not homed, not running, a move
    /// refused.
    #[error("the machine: {message}")]
    LinuxCncRefused {
        /// LinuxCNC's or the bridge's own message.
        message: String,
    },

    /// The LinuxCNC bridge's Python could not be started.
    #[error(
        "the machine: cannot run {python} for LinuxCNC's Python interface: {cause} (give \
         --linuxcnc-python)"
    )]
    BridgeNotStarted {
        /// The Python interpreter.
        python: String,
        /// Why.
        cause: String,
    },

    /// The LinuxCNC bridge answered what is not one of its answers.
    #[error("the machine: the LinuxCNC bridge answered {answer:?} ({problem})")]
    BridgeAnswer {
        /// The answer.
        answer: String,
        /// What is wrong with it.
        problem: String,
    },

    /// Talking to the LinuxCNC bridge failed, or it ended.
    #[error("the machine: {what} the LinuxCNC bridge: {cause}")]
    BridgeIo {
        /// "reading", "writing to".
        what: &'static str,
        /// Why.
        cause: String,
    },

    /// The LinuxCNC bridge ended: its messages are above (on standard error).
    #[error("the machine: the LinuxCNC bridge ended ({status}); its messages are above")]
    BridgeEnded {
        /// Its exit status.
        status: String,
    },

    /// LinuxCNC did not answer in time.
    #[error("the machine: LinuxCNC did not answer within {timeout:?}")]
    MachineTimeout {
        /// How long it was given.
        timeout: std::time::Duration,
    },

    /// LinuxCNC commands legs the geometry's inverse kinematics does not: the geometry is
    /// another machine's.
    #[error(
        "the machine: configuration {configuration}: LinuxCNC commands leg {leg} at {linuxcnc_mm} \
         mm where the geometry's inverse kinematics gives {geometry_mm} mm: --geometry is not \
         this machine's (convert it with hexacomp-trainer geometry --from-linuxcnc)"
    )]
    GeometryNotThisMachine {
        /// The configuration driven to.
        configuration: String,
        /// The leg, from 1.
        leg: usize,
        /// The length LinuxCNC commands, mm.
        linuxcnc_mm: f64,
        /// The length of the geometry's inverse kinematics, mm.
        geometry_mm: f64,
    },

    /// The operator stopped a manual campaign.
    #[error("the machine: stopped by the operator; run again to continue")]
    StoppedByOperator,

    /// The operator's input ended or could not be read before a move was confirmed.
    #[error("the machine: configuration {configuration}: {problem} before the move was confirmed")]
    ConfirmationMissing {
        /// The configuration driven to.
        configuration: String,
        /// "the input ended", or the read error.
        problem: String,
    },

    /// The instrument cannot work at all: measuring stops before a configuration.
    #[error("the instrument: {cause}; measuring stops before {before}")]
    InstrumentBroken {
        /// The instrument's reason.
        cause: String,
        /// What was to be measured ("configuration 17").
        before: String,
    },

    /// The reference configuration could not be measured.
    #[error(
        "the instrument: the reference configuration ({reference}) could not be measured \
         ({reason}); the campaign stops: check the instrument and run again to continue"
    )]
    ReferenceUnmeasured {
        /// The reference measurement's id.
        reference: String,
        /// Why.
        reason: String,
    },

    /// The reference configuration did not settle in the warm-up.
    #[error(
        "drift: the reference configuration did not settle in {measurements} measurements{}: \
         the machine or the instrument is still warming up; run again to go on waiting \
         (nothing was recorded)",
        last_change_mm.map_or(String::new(), |d| format!(" (the last two {d:.4} mm apart, limit {limit_mm} mm)"))
    )]
    NotWarmedUp {
        /// The measurements of the warm-up.
        measurements: usize,
        /// How far the last two were apart, mm.
        last_change_mm: Option<f64>,
        /// The limit, mm.
        limit_mm: f64,
    },

    /// The reference configuration moved beyond the limit: the campaign stopped.
    #[error(
        "drift: {reference}: {what}. The campaign stops (logged). If the tracker moved, \
         register it again (hexacomp-trainer register) and run again with --registration NEW; \
         if the drift is real and acceptable, run again with --accept-drift.{}",
        suspects_sentence(suspects)
    )]
    Drifted {
        /// The reference measurement's id.
        reference: String,
        /// What moved, by how much.
        what: String,
        /// The configurations recorded since the last good measurement of the reference.
        suspects: Vec<String>,
    },

    /// A LinuxCNC configuration cannot be read as a genhexkins hexapod.
    #[error("LinuxCNC configuration {}: {problem}", path.display())]
    LinuxCncConfig {
        /// The ini or HAL file at fault.
        path: std::path::PathBuf,
        /// What is wrong with it.
        problem: crate::linuxcnc::ConfigProblem,
    },

    /// A registration was refused: the fiducials are not named the same in both files, or
    /// fewer than three are common to them.
    #[error(
        "registration refused: {} (every fiducial must be named the same in both files)",
        problems.join("; ")
    )]
    FiducialNamesUnmatched {
        /// Each problem: too few common names, names on one side only.
        problems: Vec<String>,
    },

    /// A registration was refused: the fiducials cannot locate the instrument (too few of
    /// positive weight, nearly collinear).
    #[error("registration refused: the fiducials: {cause}")]
    FiducialsDoNotLocate {
        /// The fit's own error.
        cause: hexacomp_core::Error,
    },

    /// A registration was refused: after the best fit a fiducial lies beyond the tolerance;
    /// the diagnosis names the likely mistake where the data shows it.
    #[error(
        "registration refused: fiducial {fiducial} is {distance_mm:.4} mm from its nominal \
         position after the best fit, more than the tolerance of {tolerance_mm} mm. {diagnosis}"
    )]
    FiducialBeyondTolerance {
        /// The fiducial farthest from its nominal position.
        fiducial: String,
        /// Its distance after the best fit, mm.
        distance_mm: f64,
        /// The registration's tolerance, mm.
        tolerance_mm: f64,
        /// What the data says of the cause.
        diagnosis: crate::registration::Diagnosis,
    },

    /// So many configurations in a row gave no reading that the campaign stopped; what was
    /// recorded stays.
    #[error(
        "the instrument: {count} configurations in a row gave no reading (the last: \
         {last_reason}); the campaign stops: check the instrument and run again to continue"
    )]
    GapsInARow {
        /// How many configurations in a row gave no reading.
        count: usize,
        /// Why the last one gave none.
        last_reason: String,
    },

    /// The registration's fiducials, measured again, moved beyond the limit: the registration
    /// does not bring the run's readings into the base frame.
    #[error("{0}")]
    FiducialsMoved(Box<crate::fiducial_check::Movement>),

    /// A campaign's record or one of its logs could not be written; the rows before it are on
    /// disk and the campaign stops.
    #[error(
        "{}: cannot {what}: {message} ({}; run again to continue)",
        path.display(),
        if *rows_kept { "the rows before it are on disk" } else { "the campaign stops" }
    )]
    RecordNotWritten {
        /// The record or log file.
        path: std::path::PathBuf,
        /// What was being written ("record configuration 17", "log the reference R3").
        what: String,
        /// Why it could not be written.
        message: String,
        /// Whether the record's rows before it are on disk (a configuration's row or readings;
        /// not said of a reference's log line).
        rows_kept: bool,
    },
}

/// The sentence naming the configurations that may hold a drift ("" when none).
fn suspects_sentence(suspects: &[String]) -> String {
    if suspects.is_empty() {
        return String::new();
    }
    format!(
        " The configurations recorded since the last good measurement of the reference ({}) \
         may hold the drift: delete their lines from the record to measure them again.",
        suspects.join(", ")
    )
}

/// `Result` with this crate's [`enum@Error`].
pub type Result<T> = std::result::Result<T, Error>;
