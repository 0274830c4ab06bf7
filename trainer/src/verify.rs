//! Running an ISO 9283 pose test ([`crate::iso9283`]): the machine driven through the test's
//! cycles, each attained pose measured (several readings combined as a campaign does), brought
//! into the base frame and fitted; then each pose's AP and RP.
//!
//! A pose whose every reading failed in a cycle, or whose targets do not fix the pose, is left
//! out of that pose's figures and listed ([`TestRun::missed`]): the figures say how many cycles
//! they rest on. Units: mm and degrees.

use hexacomp_core::{Geometry, Pose};

use crate::campaign::{CampaignOptions, Instrument, Machine, combine, read_configuration};
use crate::error::{Error, Result};
use crate::iso9283::{PoseCharacteristics, TestPose, characteristics};

/// One attained pose.
#[derive(Debug, Clone, PartialEq)]
pub struct Attained {
    /// The cycle, from 1.
    pub cycle: usize,
    /// The test pose's name.
    pub pose: String,
    /// The attained pose `x, y, z, a, b, c` as measured, mm and degrees, base frame.
    pub pose_mm_deg: [f64; 6],
}

/// A pose not measured in a cycle.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Missed {
    /// The cycle, from 1.
    pub cycle: usize,
    /// The test pose's name.
    pub pose: String,
    /// Why.
    pub why: String,
}

/// What a test measured.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TestRun {
    /// Every attained pose, in the order measured.
    pub attained: Vec<Attained>,
    /// The poses not measured.
    pub missed: Vec<Missed>,
}

/// The identifier of a pose's measurement in a cycle (`P3/12`): the machine's and the virtual
/// instrument's noise is keyed on it.
pub fn measurement_id(pose: &str, cycle: usize) -> String {
    format!("{pose}/{cycle}")
}

/// An ISO 9283 test to run: what to visit, how often, how to read and where the instrument
/// stands.
#[derive(Debug, Clone)]
pub struct PoseTest<'a> {
    /// The geometry (its targets fit the attained pose).
    pub geometry: &'a Geometry,
    /// The poses, in the order a cycle visits them.
    pub poses: &'a [TestPose],
    /// Cycles to run.
    pub cycles: usize,
    /// The instrument's pose in the base frame (from its registration; the identity when it
    /// measures in the base frame).
    pub instrument_frame: Pose,
    /// How each attained pose is read.
    pub options: CampaignOptions,
}

impl PoseTest<'_> {
    /// Runs the cycles (each visiting the poses in the same order): drives to each pose, reads
    /// it as `options` says, brings the combined reading into the base frame and fits the
    /// attained pose. `progress()` is called after each pose. The machine's errors and an
    /// instrument that cannot work stop the test.
    pub fn run(
        &self,
        machine: &mut dyn Machine,
        instrument: &mut dyn Instrument,
        progress: &mut dyn FnMut(),
    ) -> Result<TestRun> {
        let options = &self.options;
        if options.readings == 0 {
            return Err(Error::InvalidSetting("readings must be ≥ 1".into()));
        }
        let mut run = TestRun::default();
        for cycle in 1..=self.cycles {
            for pose in self.poses {
                let id = measurement_id(&pose.name, cycle);
                let arrival = machine.go_to(&id, &Pose::from_mm_deg(pose.commanded))?;
                if !options.settle.is_zero() {
                    std::thread::sleep(options.settle);
                }
                let (readings, _lost, failure) =
                    read_configuration(instrument, options, &id, &pose.commanded, &arrival)?;
                let missed = |why: String| Missed {
                    cycle,
                    pose: pose.name.clone(),
                    why,
                };
                if readings.is_empty() {
                    run.missed
                        .push(missed(failure.unwrap_or_else(|| "no reading".into())));
                } else {
                    let observed = combine(&readings, options.outlier_factor)
                        .observed
                        .in_frame(&self.instrument_frame);
                    match observed.undetermined(self.geometry) {
                        Some(why) => run.missed.push(missed(why)),
                        None => run.attained.push(Attained {
                            cycle,
                            pose: pose.name.clone(),
                            pose_mm_deg: observed.fitted_pose(self.geometry)?.to_mm_deg(),
                        }),
                    }
                }
                progress();
            }
        }
        Ok(run)
    }
}

/// Each pose's characteristics from the attained poses of `run` (in the order of `poses`); a
/// pose with fewer than two attained poses is an error that names it.
pub fn characteristics_of(
    poses: &[TestPose],
    attained: &[Attained],
) -> Result<Vec<PoseCharacteristics>> {
    poses
        .iter()
        .map(|pose| {
            let at: Vec<[f64; 6]> = attained
                .iter()
                .filter(|a| a.pose == pose.name)
                .map(|a| a.pose_mm_deg)
                .collect();
            characteristics(&pose.commanded, &at)
                .map_err(|e| Error::InsufficientData(format!("pose {}: {e}", pose.name)))
        })
        .collect()
}
