//! Gross errors in a measurements file: each kind is put into the virtual platform's
//! measurements, and the screening must exclude exactly the wrong row (or refuse a file that is
//! wrong as a whole), so that the model trained on what is kept is, blind on fresh poses of the
//! same machine, within 10 % of the model trained on the clean file.
//!
//! The fast tests run in CI on the default machine. The whole table of docs/commands.md ("Gross errors")
//! ("Gross errors": every kind on several virtual machines) is the ignored test
//! `the_gross_error_table`:
//! `cargo test --release -p hexacomp-trainer --test gross_errors -- --ignored --nocapture`.

mod common;

use hexacomp_calibration::Error;
use hexacomp_calibration::pipeline::Pipeline;
use hexacomp_calibration::screening::Reason;
use hexacomp_calibration::train::Architecture;
use hexacomp_core::Geometry;
use hexacomp_core::compensator::compensate_pose;
use hexacomp_core::records::MeasuredConfiguration;
use hexacomp_core::sampling::{SamplerOptions, WorkspaceSampler};
use hexacomp_core::stats::PoseErrorStats;
use hexacomp_lab::evaluate::drive;
use hexacomp_virtual::{DEFAULT_MACHINE_SEED, ErrorModel, ErrorVariant, VirtualPlatform};

/// The row each single-row gross error is put into (0-based; id 75 of 150).
const ROW: usize = 74;

/// A kind of gross error, as it happens with a laser tracker and a spreadsheet.
#[derive(Debug, Clone, Copy, PartialEq)]
enum GrossError {
    /// 30 mm added to one coordinate (a mistyped digit).
    CoordinateTypo,
    /// 1 mm added to a target's z, normal to the target plane: to first order the fit absorbs it
    /// as a tilt of the platform, so the residual stays small.
    TypoAlongTheNormal,
    /// 0.3 mm added to a target's z: at the edge of what the checks find (the limit scales with
    /// the machine's unmodelled errors); when it passes, what it costs is reported.
    SmallTypoAlongTheNormal,
    /// All three targets of one row 1 mm off in x (the instrument bumped for one reading): a
    /// rigid shift, which the leg corrections absorb entirely — the fit residual stays at the
    /// noise, and only the consistency with the other rows shows it.
    RowOffset,
    /// Targets 1 and 2 swapped in one row (reflectors mislabelled).
    SwappedTargets,
    /// One row's targets are the next row's (a reading recorded against the wrong
    /// configuration).
    RowShifted,
    /// A dropped decimal point in one coordinate: 123.456 read as 123456.
    DroppedDecimal,
    /// Leg columns q1 and q2 swapped in every row (a leg-numbering mix-up).
    SwappedLegColumns,
    /// Every target coordinate in inches.
    Inches,
}

impl GrossError {
    const ALL: [GrossError; 9] = [
        GrossError::CoordinateTypo,
        GrossError::TypoAlongTheNormal,
        GrossError::SmallTypoAlongTheNormal,
        GrossError::RowOffset,
        GrossError::SwappedTargets,
        GrossError::RowShifted,
        GrossError::DroppedDecimal,
        GrossError::SwappedLegColumns,
        GrossError::Inches,
    ];

    /// Whether the whole file is wrong (it must be refused) rather than one row (excluded).
    fn whole_file(self) -> bool {
        matches!(self, GrossError::SwappedLegColumns | GrossError::Inches)
    }

    /// Whether the error is too small for the checks to be required to find it.
    fn may_pass(self) -> bool {
        self == GrossError::SmallTypoAlongTheNormal
    }

    fn put_into(self, rows: &mut [MeasuredConfiguration]) {
        let next = common::seen_targets(&rows[ROW + 1]);
        let row = &mut rows[ROW];
        match self {
            GrossError::CoordinateTypo => common::edit_targets(row, |t| t[0].x += 30.0),
            GrossError::TypoAlongTheNormal => common::edit_targets(row, |t| t[0].z += 1.0),
            GrossError::SmallTypoAlongTheNormal => common::edit_targets(row, |t| t[0].z += 0.3),
            GrossError::RowOffset => {
                common::edit_targets(row, |t| t.iter_mut().for_each(|p| p.x += 1.0))
            }
            GrossError::SwappedTargets => common::edit_targets(row, |t| t.swap(0, 1)),
            GrossError::RowShifted => common::set_targets(row, next),
            GrossError::DroppedDecimal => {
                common::edit_targets(row, |t| t[1].y = (t[1].y * 1e3).round())
            }
            GrossError::SwappedLegColumns => rows.iter_mut().for_each(|r| r.legs.swap(0, 1)),
            GrossError::Inches => rows
                .iter_mut()
                .for_each(|r| common::edit_targets(r, |t| t.iter_mut().for_each(|p| *p /= 25.4))),
        }
    }
}

/// A virtual machine and its 150 measured configurations.
struct Machine {
    geometry: Geometry,
    platform: VirtualPlatform,
    measurements: Vec<MeasuredConfiguration>,
}

fn machine(variant: ErrorVariant, machine_seed: u64) -> Machine {
    let geometry = Geometry::prototype();
    let rows = common::plan_rows(&geometry, 150, 1);
    let (platform, measurements) = common::measure(
        &geometry,
        &ErrorModel::variant(variant),
        machine_seed,
        1,
        &rows,
    );
    Machine {
        geometry,
        platform,
        measurements,
    }
}

/// What the pipeline did with a file: refused it, or trained on what it kept.
enum Result {
    Refused(String),
    Trained {
        excluded: Vec<String>,
        /// Mean position error on fresh poses with the decoupled model, mm.
        mean_mm: f64,
    },
}

fn calibrate(machine: &Machine, measurements: &[MeasuredConfiguration]) -> Result {
    let pipeline = Pipeline::default();
    let solved = match pipeline.solve(&machine.geometry, measurements) {
        Ok(solved) => solved,
        Err(Error::Refused { reason, .. }) => return Result::Refused(reason),
        Err(e) => panic!("{e}"),
    };
    let excluded = solved
        .outcomes
        .iter()
        .enumerate()
        .filter(|(index, _)| !solved.screening.kept(*index))
        .map(|(_, o)| o.id.clone())
        .collect();
    let trained = pipeline
        .train(
            &machine.geometry,
            &solved.corrections,
            Architecture::Decoupled,
            &|_| {},
        )
        .unwrap();
    let poses = WorkspaceSampler::new(&machine.geometry, 1001, SamplerOptions::default())
        .unwrap()
        .samples(100)
        .unwrap();
    let errors = drive(
        &mut machine.platform.clone(),
        &mut machine.platform.reseeded(2),
        &poses,
        |p| compensate_pose(&machine.geometry, Some(&trained.model), p).legs,
    )
    .unwrap()
    .reached;
    Result::Trained {
        excluded,
        mean_mm: PoseErrorStats::of(&errors).position_mm.mean,
    }
}

/// Puts `kind` into the machine's measurements and checks the decision: refused when the file is
/// wrong as a whole, else exactly the wrong row excluded and the mean error within 10 % of
/// `clean_mm`. Returns the table cell.
fn check(machine: &Machine, kind: GrossError, clean_mm: f64) -> String {
    let mut rows = machine.measurements.clone();
    kind.put_into(&mut rows);
    match calibrate(machine, &rows) {
        Result::Refused(why) => {
            assert!(kind.whole_file(), "{kind:?}: refused: {why}");
            "refused".into()
        }
        Result::Trained { excluded, mean_mm } => {
            assert!(!kind.whole_file(), "{kind:?} was not refused");
            let cost = format!(
                "{mean_mm:.4} mm ({:+.0} %)",
                100.0 * (mean_mm / clean_mm - 1.0)
            );
            if excluded.is_empty() && kind.may_pass() {
                // Below what the checks are required to find: reported, not asserted (the
                // table of docs/commands.md gives what it costs).
                return format!("kept; {cost}");
            }
            assert_eq!(excluded, [rows[ROW].id.clone()], "{kind:?}");
            assert!(
                mean_mm <= 1.10 * clean_mm,
                "{kind:?}: mean {mean_mm:.4} mm against {clean_mm:.4} mm clean"
            );
            format!("excluded; {cost}")
        }
    }
}

fn clean_mean(machine: &Machine) -> f64 {
    match calibrate(machine, &machine.measurements) {
        Result::Trained { excluded, mean_mm } => {
            assert!(excluded.is_empty(), "clean rows excluded: {excluded:?}");
            mean_mm
        }
        Result::Refused(why) => panic!("the clean file was refused: {why}"),
    }
}

#[test]
fn every_kind_is_excluded_or_refused_on_the_default_machine() {
    let machine = machine(ErrorVariant::Paper, DEFAULT_MACHINE_SEED);
    let pipeline = Pipeline::default();
    for kind in GrossError::ALL {
        let mut rows = machine.measurements.clone();
        kind.put_into(&mut rows);
        match pipeline.solve(&machine.geometry, &rows) {
            Err(Error::Refused { reason, .. }) => assert!(kind.whole_file(), "{kind:?}: {reason}"),
            Err(e) => panic!("{kind:?}: {e}"),
            Ok(solved) => {
                assert!(!kind.whole_file(), "{kind:?} was not refused");
                let excluded: Vec<usize> = (0..rows.len())
                    .filter(|i| !solved.screening.kept(*i))
                    .collect();
                if !(excluded.is_empty() && kind.may_pass()) {
                    assert_eq!(
                        excluded,
                        [ROW],
                        "{kind:?}: {:?}",
                        solved.screening.reasons[ROW]
                    );
                }
                if kind == GrossError::RowOffset {
                    assert!(
                        matches!(
                            solved.screening.reasons[ROW].as_slice(),
                            [Reason::Inconsistent { .. }]
                        ),
                        "{:?}",
                        solved.screening.reasons[ROW]
                    );
                }
            }
        }
    }
}

#[test]
fn one_typo_in_150_rows_costs_at_most_a_tenth_of_the_accuracy() {
    let machine = machine(ErrorVariant::Paper, DEFAULT_MACHINE_SEED);
    let clean_mm = clean_mean(&machine);
    check(&machine, GrossError::CoordinateTypo, clean_mm);
}

/// The table of docs/commands.md ("Gross errors"): every kind on several virtual machines.
#[test]
#[ignore = "trains 10 models per machine (minutes); run for the docs table"]
fn the_gross_error_table() {
    let machines = [
        (ErrorVariant::Paper, DEFAULT_MACHINE_SEED),
        (ErrorVariant::Paper, 5),
        (ErrorVariant::StrongPitch, 77),
        (ErrorVariant::GeometricOnly, 5),
    ];
    for (variant, seed) in machines {
        let machine = machine(variant, seed);
        let clean_mm = clean_mean(&machine);
        println!("machine {variant} seed {seed}: clean {clean_mm:.4} mm");
        for kind in GrossError::ALL {
            println!("  {kind:?}: {}", check(&machine, kind, clean_mm));
        }
    }
}
