//! Running an ISO 9283 pose test ([`crate::pose_test`]): the machine driven through the test's
//! cycles, each attained pose measured (several readings combined as a campaign does), brought
//! into the base frame and fitted; then each pose's AP and RP.
//!
//! A pose whose every reading failed in a cycle, or whose targets do not fix the pose, is left
//! out of that pose's figures and listed ([`TestRun::missed`]): the figures say how many cycles
//! they rest on. Units: mm and degrees.

use hexacomp_core::{Geometry, Pose};

use crate::error::{Error, Result};
use crate::pose_test::{PoseCharacteristics, TestPose, characteristics};
use hexacomp_measuring::campaign::{
    CampaignOptions, Instrument, Machine, combine, read_configuration,
};

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
    /// The pose every cycle's first pose is approached from (ISO 9283 approaches P1 from P2):
    /// visited unmeasured before the first cycle and at the end of every cycle that does not
    /// end there.
    pub approach: Option<TestPose>,
}

impl PoseTest<'_> {
    /// Runs the cycles (each visiting the poses in the same order): drives to each pose, reads
    /// it as `options` says, brings the combined reading into the base frame and fits the
    /// attained pose, adding it to `run`. `progress()` is called after each pose. The machine's
    /// errors and an instrument that cannot work stop the test; what was measured before stays
    /// in `run`.
    pub fn run(
        &self,
        machine: &mut dyn Machine,
        instrument: &mut dyn Instrument,
        run: &mut TestRun,
        progress: &mut dyn FnMut(),
    ) -> Result<()> {
        let options = &self.options;
        if options.readings == 0 {
            return Err(Error::OutOfRange {
                setting: "readings",
                value: 0.0,
                valid: "must be ≥ 1",
            });
        }
        let approach = |machine: &mut dyn Machine, cycle: usize| -> Result<()> {
            match &self.approach {
                Some(from) => machine
                    .go_to(
                        &format!("approach/{cycle}"),
                        &Pose::from_mm_deg(from.commanded),
                    )
                    .map(|_| ())
                    .map_err(Error::from),
                None => Ok(()),
            }
        };
        approach(machine, 0)?;
        let ends_at_approach = self
            .approach
            .as_ref()
            .is_some_and(|a| self.poses.last().is_some_and(|p| p.name == a.name));
        for cycle in 1..=self.cycles {
            if cycle > 1 && !ends_at_approach {
                approach(machine, cycle - 1)?;
            }
            for pose in self.poses {
                let id = measurement_id(&pose.name, cycle);
                let arrival = machine.go_to(&id, &Pose::from_mm_deg(pose.commanded))?;
                if !options.settle.is_zero() {
                    std::thread::sleep(options.settle);
                }
                let readings =
                    read_configuration(instrument, options, &id, &pose.commanded, &arrival)?;
                let missed = |why: String| Missed {
                    cycle,
                    pose: pose.name.clone(),
                    why,
                };
                if readings.observations.is_empty() {
                    run.missed.push(missed(
                        readings.failure.unwrap_or_else(|| "no reading".into()),
                    ));
                } else {
                    let observed = combine(&readings.observations, options.outlier_factor)
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
        Ok(())
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
            characteristics(&pose.commanded, &at).map_err(|e| Error::AtPose {
                pose: pose.name.clone(),
                cause: Box::new(e),
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use hexacomp_core::observation::Observation;
    use hexacomp_measuring::campaign::{Arrival, ReadError};

    /// A machine that goes where it is told and remembers where it went.
    struct Logging(Vec<Pose>);

    impl Machine for Logging {
        fn go_to(&mut self, _id: &str, pose: &Pose) -> hexacomp_measuring::Result<Arrival> {
            self.0.push(*pose);
            Ok(Arrival {
                legs: [0.0; 6],
                drives: [0.0; 6],
                reached: None,
            })
        }
    }

    /// An instrument that reports the commanded pose as a probe would.
    struct Exact;

    impl Instrument for Exact {
        fn read(
            &mut self,
            _id: &str,
            _reading: usize,
            pose_mm_deg: &[f64; 6],
            _arrival: &hexacomp_measuring::campaign::Arrival,
        ) -> std::result::Result<Observation, ReadError> {
            Ok(Observation::Pose(*pose_mm_deg))
        }

        fn read_fiducial(
            &mut self,
            _name: &str,
            _reading: usize,
            nominal_mm: glam::DVec3,
        ) -> std::result::Result<glam::DVec3, ReadError> {
            Ok(nominal_mm)
        }
    }

    #[test]
    fn every_pose_p1_first_is_approached_from_the_same_pose_in_every_cycle() {
        let g = Geometry::prototype();
        let cube = crate::pose_test::test_cube(&g).unwrap();
        let options = crate::pose_test::TestPoseOptions {
            orientation: true,
            extra: 0,
            seed: 1,
        };
        let poses = crate::pose_test::cycle_poses(&g, &cube, &options).unwrap();
        let test = PoseTest {
            geometry: &g,
            poses: &poses,
            cycles: 3,
            instrument_frame: Pose::default(),
            options: CampaignOptions {
                readings: 1,
                ..CampaignOptions::default()
            },
            approach: crate::pose_test::approach_pose(&poses),
        };
        let mut machine = Logging(Vec::new());
        let mut run = TestRun::default();
        test.run(&mut machine, &mut Exact, &mut run, &mut || {})
            .unwrap();
        // Where the machine went, named by the test pose it is (approach moves included).
        let visited: Vec<String> = machine
            .0
            .iter()
            .map(|at| {
                let at = at.to_mm_deg();
                let pose = poses.iter().find(|p| {
                    p.commanded
                        .iter()
                        .zip(&at)
                        .all(|(c, a)| (c - a).abs() < 1e-9)
                });
                pose.expect("a test pose").name.clone()
            })
            .collect();
        for (k, pose) in visited.iter().enumerate().skip(1) {
            let before = &visited[k - 1];
            let expected = match pose.as_str() {
                "P1" => "P2",
                "P5" => "P1",
                "O1" => "P2",
                _ => continue,
            };
            assert_eq!(
                before, expected,
                "{pose} approached from {before}: {visited:?}"
            );
        }
        assert_eq!(
            visited[0], "P2",
            "the machine goes to P2 before the first cycle"
        );
        assert_eq!(run.attained.len(), 3 * poses.len());
        // The exact instrument: every attained pose is the commanded one.
        let c = characteristics_of(&poses, &run.attained).unwrap();
        assert!(c.iter().all(|c| c.ap_p_mm < 1e-9 && c.rp_l_mm < 1e-9));
    }
}
