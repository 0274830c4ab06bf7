//! The virtual platform as a campaign's machine and instrument: each configuration's noise keyed
//! on the seed and the configuration's id, so a resumed campaign records exactly what an
//! uninterrupted one does.
//!
//! Units: mm and degrees in records; poses in the base frame, measurements in the instrument's.

use glam::DVec3;
use hexacomp_core::compensator::{PointStatus, compensate_legs};
use hexacomp_core::fused::FusedModel;
use hexacomp_core::observation::Observation;
use hexacomp_core::records::NamedPoint;
use hexacomp_core::{Pose, inverse_kinematics};
use hexacomp_measuring::campaign::{
    Arrival, Instrument, Machine, ReadError, as_instrument_reports,
};
use hexacomp_measuring::{Error, Result};
use hexacomp_virtual::{VirtualPlatform, measure_fiducials};

/// A stable 64-bit key of `seed`, a configuration id and a number (FNV-1a): the virtual
/// platform's noise for that configuration, the same in every run.
pub fn noise_key(seed: u64, id: &str, number: u64) -> u64 {
    let mut hash: u64 = 0xcbf2_9ce4_8422_2325;
    for byte in seed
        .to_le_bytes()
        .iter()
        .chain(id.as_bytes())
        .chain(&number.to_le_bytes())
    {
        hash ^= u64::from(*byte);
        hash = hash.wrapping_mul(0x0000_0100_0000_01b3);
    }
    hash
}

/// The virtual platform as a campaign's machine: each configuration moves with the
/// repeatability noise of its own key, so a resumed campaign reaches what an uninterrupted one
/// does.
#[derive(Debug, Clone)]
pub struct VirtualMachine {
    /// The platform (its noise stream is replaced per configuration).
    pub platform: VirtualPlatform,
    /// The seed the keys are drawn from.
    pub seed: u64,
    /// The compensation active in the machine's controller, whose corrections are added to the
    /// nominal legs (`verify --model`), in the serving form the service computes with; none for
    /// a calibration campaign, which measures the machine as it is.
    pub compensation: Option<FusedModel>,
}

impl Machine for VirtualMachine {
    fn go_to(&mut self, id: &str, pose: &Pose) -> Result<Arrival> {
        let geometry = self.platform.nominal().clone();
        let nominal = inverse_kinematics(&geometry, pose);
        if !nominal.all_in_stroke() {
            return Err(Error::OutsideStroke {
                configuration: id.to_string(),
            });
        }
        let drives = match &self.compensation {
            None => nominal.lengths,
            Some(model) => {
                let compensated = compensate_legs(&geometry, Some(model), &nominal.lengths);
                match compensated.status {
                    PointStatus::Ok | PointStatus::Clamped | PointStatus::OutsideTrainedRange => {
                        compensated.legs
                    }
                    status => {
                        return Err(Error::NotCompensated {
                            configuration: id.to_string(),
                            status: status.name(),
                        });
                    }
                }
            }
        };
        self.platform = self.platform.reseeded(noise_key(self.seed, id, 0));
        let reached = self.platform.move_legs(&drives, pose)?;
        Ok(Arrival {
            legs: nominal.lengths,
            drives,
            reached: Some(reached),
        })
    }
}

/// A real controller (LinuxCNC) driving the virtual platform's hardware: the platform moves to
/// what the controller commands its drives, with the repeatability noise of the configuration's
/// own key, so that the virtual instrument measures what such a machine would reach.
pub struct VirtualHardware {
    /// The controller.
    pub controller: Box<dyn Machine>,
    /// The platform (its noise stream is replaced per configuration).
    pub platform: VirtualPlatform,
    /// The seed the keys are drawn from.
    pub seed: u64,
}

impl Machine for VirtualHardware {
    fn go_to(&mut self, id: &str, pose: &Pose) -> Result<Arrival> {
        let mut arrival = self.controller.go_to(id, pose)?;
        self.platform = self.platform.reseeded(noise_key(self.seed, id, 0));
        arrival.reached = Some(self.platform.move_legs(&arrival.drives, pose)?);
        Ok(arrival)
    }
}

/// The virtual platform's tracker as a campaign's instrument: it reads the targets (or, as a
/// probe, the pose fitted to them) of the pose the virtual machine reached, in its own frame
/// (`instrument`: its pose in the base frame), each reading with the noise of its own key.
#[derive(Debug, Clone)]
pub struct VirtualInstrument {
    /// The platform whose device reads.
    pub platform: VirtualPlatform,
    /// Where the instrument stands in the base frame.
    pub instrument: Pose,
    /// Report the pose instead of the targets.
    pub probe: bool,
    /// The seed the keys are drawn from.
    pub seed: u64,
}

impl Instrument for VirtualInstrument {
    fn read(
        &mut self,
        id: &str,
        reading: usize,
        _pose_mm_deg: &[f64; 6],
        arrival: &Arrival,
    ) -> std::result::Result<Observation, ReadError> {
        let reached = arrival.reached.ok_or_else(|| {
            ReadError::Broken("the virtual instrument measures the virtual machine only".into())
        })?;
        let mut device = self
            .platform
            .reseeded(noise_key(self.seed, id, 1 + reading as u64));
        let targets: Vec<Option<DVec3>> = device
            .measure_targets(&reached)
            .into_iter()
            .map(Some)
            .collect();
        as_instrument_reports(
            self.platform.nominal(),
            &Observation::Targets(targets),
            &self.instrument.inverse(),
            self.probe,
        )
        .map_err(|e| ReadError::Failed(e.to_string()))
    }

    /// The fiducial seen from where the instrument stands, with the device's noise (keyed on
    /// the seed, the fiducial's name and the reading's number).
    fn read_fiducial(
        &mut self,
        name: &str,
        reading: usize,
        nominal_mm: DVec3,
    ) -> std::result::Result<DVec3, ReadError> {
        let point = NamedPoint {
            name: name.to_string(),
            position: nominal_mm,
            weight: 1.0,
        };
        // Each reading is the mean of the device's own readings, as for the targets.
        let device = self.platform.machine().model().device;
        let sigma_mm = device.sigma_mm / (device.readings.max(1) as f64).sqrt();
        let key = noise_key(self.seed, &format!("fiducial {name}"), reading as u64);
        measure_fiducials(&[point], &self.instrument, sigma_mm, key)
            .map(|seen| seen[0].position)
            .map_err(|e| ReadError::Broken(e.to_string()))
    }
}

#[cfg(test)]
mod tests {
    use std::collections::HashSet;

    use hexacomp_core::Geometry;
    use hexacomp_measuring::campaign::{Campaign, CampaignOptions};

    use super::*;

    /// A controller whose drives get a correction on top of the nominal legs.
    struct Compensating(VirtualMachine);

    impl Machine for Compensating {
        fn go_to(&mut self, id: &str, pose: &Pose) -> Result<Arrival> {
            let mut arrival = self.0.go_to(id, pose)?;
            arrival.drives[2] += 0.01;
            Ok(arrival)
        }
    }

    #[test]
    fn a_campaign_refuses_a_machine_whose_compensation_is_active() {
        let g = Geometry::prototype();
        let platform = VirtualPlatform::new(
            &g,
            &hexacomp_virtual::ErrorModel::variant(hexacomp_virtual::ErrorVariant::Paper),
            18,
            1,
        )
        .unwrap();
        let plan = hexacomp_calibration::plan::numbered_rows(&[g.home_pose()]);
        let done = HashSet::new();
        let campaign = Campaign {
            geometry: &g,
            plan: &plan,
            order: &[0],
            done: &done,
            nothing_seen: Observation::Targets(vec![None; 3]),
            options: CampaignOptions::default(),
            into_record_frame: Vec::new(),
            drift: None,
        };
        let mut instrument = VirtualInstrument {
            platform: platform.clone(),
            instrument: Pose::default(),
            probe: false,
            seed: 1,
        };
        let mut recorded = 0;
        let error = campaign
            .run(
                &mut Compensating(VirtualMachine {
                    platform,
                    seed: 1,
                    compensation: None,
                }),
                &mut instrument,
                &mut |_, _| {
                    recorded += 1;
                    Ok(())
                },
                &mut |_| Ok(()),
                &mut || {},
            )
            .unwrap_err();
        assert!(
            error.to_string().contains("compensation is active"),
            "{error}"
        );
        assert_eq!(recorded, 0);
    }

    #[test]
    fn noise_keys_differ_by_seed_id_and_number_and_are_stable() {
        assert_eq!(noise_key(1, "17", 0), noise_key(1, "17", 0));
        assert_ne!(noise_key(1, "17", 0), noise_key(2, "17", 0));
        assert_ne!(noise_key(1, "17", 0), noise_key(1, "18", 0));
        assert_ne!(noise_key(1, "17", 0), noise_key(1, "17", 1));
        // FNV-1a is fixed: the same key in every build (a resumed campaign depends on it).
        // Known answer: FNV-1a of sixteen zero bytes, computed apart from this code.
        assert_eq!(noise_key(0, "", 0), 0x8820_1fb9_60ff_6465);
    }
}
