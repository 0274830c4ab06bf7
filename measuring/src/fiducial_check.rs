//! The fiducials measured again at the end of a campaign under a registration, compared with the
//! readings the registration was made from: whether the instrument still stands where it was
//! registered, so that the registration brings the record into the base frame.
//!
//! Each fiducial moves by its reading now minus its reading at the registration. The references
//! of the drift check compare the platform with the instrument; the fiducials compare the base
//! with the instrument, so they also catch a tracker that had moved before the campaign's
//! baseline was taken, or a registration file of another set-up.
//!
//! Units: mm, in the instrument's frame (a movement's length is the same in the base frame).

use glam::DVec3;
use hexacomp_core::records::NamedPoint;
use hexacomp_formats::RegistrationFile;

use crate::campaign::{CampaignOptions, Instrument, combine_points, read_repeatedly};
use crate::drift::Deviation;
use crate::error::{Error, Result};

/// The fewest fiducials of positive weight the check decides on: as many as locate the
/// instrument.
pub const MIN_FIDUCIALS: usize = 3;

/// A fiducial measured again.
#[derive(Debug, Clone, PartialEq)]
pub struct RemeasuredFiducial {
    /// Its name, position (the mean of the readings kept, the instrument's frame, mm) and its
    /// weight in the registration.
    pub point: NamedPoint,
    /// Its reading now minus its reading at the registration, mm.
    pub moved: DVec3,
    /// RMS distance of the readings kept from their mean, mm.
    pub spread_mm: f64,
    /// Readings kept (not outliers).
    pub kept: usize,
}

/// The fiducials of a registration measured again.
#[derive(Debug, Clone, PartialEq)]
pub struct FiducialCheck {
    /// Those measured, in the registration's order.
    pub measured: Vec<RemeasuredFiducial>,
    /// Those not measured (every attempt at every reading failed), with the last reason.
    pub lost: Vec<(String, String)>,
}

/// Measures every fiducial of `registration` with `instrument` (as many readings as a
/// configuration, outliers rejected alike); an instrument that cannot work is an error.
pub fn remeasure(
    instrument: &mut dyn Instrument,
    options: &CampaignOptions,
    registration: &RegistrationFile,
) -> Result<FiducialCheck> {
    let mut check = FiducialCheck {
        measured: Vec::new(),
        lost: Vec::new(),
    };
    for fiducial in &registration.fiducials {
        let nominal = DVec3::from_array(fiducial.nominal);
        let readings = read_repeatedly(options, &format!("fiducial {}", fiducial.name), |k| {
            instrument.read_fiducial(&fiducial.name, k, nominal)
        })?;
        if readings.observations.is_empty() {
            let why = readings.failure.unwrap_or_else(|| "no reading".into());
            check.lost.push((fiducial.name.clone(), why));
            continue;
        }
        let (mean, spread_mm, kept) =
            combine_points(&readings.observations, options.outlier_factor);
        check.measured.push(RemeasuredFiducial {
            point: NamedPoint {
                name: fiducial.name.clone(),
                position: mean,
                weight: fiducial.weight,
            },
            moved: mean - DVec3::from_array(fiducial.measured),
            spread_mm,
            kept: kept.iter().filter(|k| **k).count(),
        });
    }
    Ok(check)
}

/// The fiducials of `registration` as read before (`points`, the instrument's frame, mm), with
/// their movements from the registration's readings; fiducials the registration does not name
/// are refused.
pub fn compare(registration: &RegistrationFile, points: &[NamedPoint]) -> Result<FiducialCheck> {
    let measured = points
        .iter()
        .map(|point| {
            let at_registration = registration
                .fiducials
                .iter()
                .find(|f| f.name == point.name)
                .ok_or_else(|| Error::UnknownFiducial {
                    fiducial: point.name.clone(),
                })?;
            Ok(RemeasuredFiducial {
                point: NamedPoint {
                    weight: at_registration.weight,
                    ..point.clone()
                },
                moved: point.position - DVec3::from_array(at_registration.measured),
                spread_mm: 0.0,
                kept: 0,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(FiducialCheck {
        measured,
        lost: Vec::new(),
    })
}

impl FiducialCheck {
    /// How the fiducials of positive weight moved; `None` with fewer than [`MIN_FIDUCIALS`].
    pub fn deviation(&self) -> Option<Deviation> {
        let moves: Vec<DVec3> = self
            .measured
            .iter()
            .filter(|f| f.point.weight > 0.0)
            .map(|f| f.moved)
            .collect();
        (moves.len() >= MIN_FIDUCIALS)
            .then(|| Deviation::of_moves(&moves))
            .flatten()
    }

    /// The decision, `None` when fewer than [`MIN_FIDUCIALS`] of positive weight were measured
    /// (it cannot be told); otherwise `Ok` with a line that says the registration holds when
    /// every fiducial of positive weight moved at most `limit_mm`, or an error that says what
    /// moved and what to do (`written`: the file holding the fiducials as measured now;
    /// `one_frame`: the record is in the frame of the instrument as it stood all along, so a
    /// registration made from `written` is the record's).
    pub fn decide(&self, limit_mm: f64, written: &str, one_frame: bool) -> Option<Result<String>> {
        let deviation = self.deviation()?;
        Some(self.judge(&deviation, limit_mm, written, one_frame))
    }

    /// Why the check cannot decide: fewer than [`MIN_FIDUCIALS`] of positive weight measured,
    /// and those not measured with their reasons.
    pub fn undecided(&self) -> String {
        format!(
            "fewer than {MIN_FIDUCIALS} fiducials of positive weight were measured{}",
            self.lost_list()
        )
    }

    /// ` (not measured: NAME: why; …)`, or nothing.
    fn lost_list(&self) -> String {
        if self.lost.is_empty() {
            return String::new();
        }
        format!(
            " (not measured: {})",
            self.lost
                .iter()
                .map(|(name, why)| format!("{name}: {why}"))
                .collect::<Vec<_>>()
                .join("; ")
        )
    }

    /// The decision on the fiducials' `deviation`.
    fn judge(
        &self,
        deviation: &Deviation,
        limit_mm: f64,
        written: &str,
        one_frame: bool,
    ) -> Result<String> {
        let lost = self.lost_list();
        if deviation.largest_mm <= limit_mm {
            return Ok(format!(
                "the fiducials moved at most {:.4} mm since the registration (limit {limit_mm} \
                 mm): the registration holds{lost}",
                deviation.largest_mm
            ));
        }
        let worst = self
            .measured
            .iter()
            .filter(|f| f.point.weight > 0.0)
            .max_by(|a, b| a.moved.length().total_cmp(&b.moved.length()))
            .expect("a deviation has a fiducial");
        Err(Error::FiducialsMoved(Box::new(Movement {
            largest_mm: deviation.largest_mm,
            fiducial: worst.point.name.clone(),
            limit_mm,
            together: deviation.together().then_some(deviation.shift.to_array()),
            uneven_mm: deviation.uneven_mm,
            lost,
            written: written.to_string(),
            one_frame,
        })))
    }
}

/// How the registration's fiducials moved beyond the limit ([`Error::FiducialsMoved`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Movement {
    /// The largest movement of a fiducial of positive weight, mm.
    pub largest_mm: f64,
    /// The fiducial that moved the most.
    pub fiducial: String,
    /// The limit, mm.
    pub limit_mm: f64,
    /// The shift they moved by together (the instrument's frame, mm), if they did.
    pub together: Option<[f64; 3]>,
    /// How far apart from their mean movement they moved, mm.
    pub uneven_mm: f64,
    /// ` (not measured: …)`, or nothing.
    pub lost: String,
    /// The file holding the fiducials as measured now.
    pub written: String,
    /// Whether the record is in the frame of the instrument as it stood all along.
    pub one_frame: bool,
}

impl std::fmt::Display for Movement {
    /// What moved, how, and what to do.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let Movement {
            largest_mm,
            fiducial,
            limit_mm,
            together,
            uneven_mm,
            lost,
            written,
            one_frame,
        } = self;
        let shape = match together {
            Some([x, y, z]) => format!(
                "they moved together by ({x:.4}, {y:.4}, {z:.4}) mm in the instrument's frame: the \
                 tracker stands elsewhere than where it was registered"
            ),
            None => format!(
                "they moved differently (up to {uneven_mm:.4} mm apart from their mean movement): \
                 the tracker turned, or a fiducial's nest moved"
            ),
        };
        let advice = if *one_frame {
            format!(
                "The references held since the campaign began, so the tracker stood where it stands \
                 now all along: register again from the fiducials measured now (hexacomp-trainer \
                 register --measured {written} …) and give that registration to solve and calibrate \
                 with this record"
            )
        } else {
            format!(
                "The record's frame changed during the campaign (registered again, or a drift \
                 accepted): the rows recorded under this registration were brought into it through \
                 a registration that does not hold. Find them by the registration in the readings \
                 log (ix..ic), delete them from the record and measure them again under a new \
                 registration (register --measured {written} locates the tracker as it stands now)"
            )
        };
        write!(
            f,
            "the fiducials moved up to {largest_mm:.4} mm since the registration ({fiducial} \
             the most; limit {limit_mm} mm): {shape}{lost}. The registration does not bring \
             this run's readings into the base frame. {advice}. If something knocked a fiducial \
             only for the moment, delete {written} and run again to measure them again"
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hexacomp_formats::RegisteredFiducial;

    /// A registration of four fiducials read at `measured` (the instrument's frame, mm).
    fn registration(measured: [[f64; 3]; 4]) -> RegistrationFile {
        RegistrationFile {
            format: hexacomp_formats::REGISTRATION_FORMAT,
            created: "2026-11-24T00:00:00Z".into(),
            nominal: "nominal.csv".into(),
            measured: "measured.csv".into(),
            instrument_pose: [0.0; 6],
            locked: Vec::new(),
            tolerance_mm: 0.1,
            rms_mm: 0.0,
            max_mm: 0.0,
            instrument_mpe_um: None,
            supported_mm: None,
            fiducials: measured
                .iter()
                .enumerate()
                .map(|(k, m)| RegisteredFiducial {
                    name: format!("F{}", k + 1),
                    nominal: *m,
                    measured: *m,
                    weight: if k == 3 { 0.0 } else { 1.0 },
                    residual: [0.0; 3],
                })
                .collect(),
        }
    }

    /// The registration's fiducials read again, each moved by `moves[k]`.
    fn read_again(r: &RegistrationFile, moves: [[f64; 3]; 4]) -> Vec<NamedPoint> {
        r.fiducials
            .iter()
            .zip(moves)
            .map(|(f, m)| NamedPoint {
                name: f.name.clone(),
                position: DVec3::from_array(f.measured) + DVec3::from_array(m),
                weight: 1.0,
            })
            .collect()
    }

    const AT: [[f64; 3]; 4] = [
        [0.0, 0.0, 0.0],
        [500.0, 0.0, 0.0],
        [0.0, 500.0, 0.0],
        [0.0, 0.0, 500.0],
    ];

    #[test]
    fn fiducials_that_moved_less_than_the_limit_keep_the_registration() {
        let r = registration(AT);
        let check = compare(&r, &read_again(&r, [[0.01, 0.0, 0.0]; 4])).unwrap();
        let holds = check.decide(0.05, "f.csv", true).unwrap().unwrap();
        assert!(holds.contains("at most 0.0100 mm"), "{holds}");
    }

    #[test]
    fn a_tracker_that_moved_is_told_from_a_knocked_fiducial_and_one_of_weight_zero_is_ignored() {
        let r = registration(AT);
        // All three used fiducials moved 0.2 mm in x; F4 (weight 0) moved a metre.
        let check = compare(
            &r,
            &read_again(
                &r,
                [[0.2, 0.0, 0.0], [0.2, 0.0, 0.0], [0.2, 0.0, 0.0], [1e3; 3]],
            ),
        )
        .unwrap();
        let error = check
            .decide(0.05, "f.csv", true)
            .unwrap()
            .unwrap_err()
            .to_string();
        assert!(
            error.contains("up to 0.2000 mm")
                && error.contains("together by (0.2000, 0.0000, 0.0000) mm in the instrument's")
                && error.contains("--measured f.csv"),
            "{error}"
        );
        // F2 alone moved 0.1 mm.
        let check = compare(
            &r,
            &read_again(&r, [[0.0; 3], [0.0, 0.1, 0.0], [0.0; 3], [0.0; 3]]),
        )
        .unwrap();
        let error = check
            .decide(0.05, "f.csv", true)
            .unwrap()
            .unwrap_err()
            .to_string();
        assert!(
            error.contains("F2 the most") && error.contains("moved differently"),
            "{error}"
        );
        // A record whose frame changed: the file locates the tracker now, not the record.
        let error = check
            .decide(0.05, "f.csv", false)
            .unwrap()
            .unwrap_err()
            .to_string();
        assert!(
            error.contains("frame changed during the campaign")
                && !error.contains("give that registration to solve"),
            "{error}"
        );
    }

    #[test]
    fn too_few_fiducials_measured_leave_the_registration_unchecked() {
        let r = registration(AT);
        let mut points = read_again(&r, [[0.0; 3]; 4]);
        points.remove(1);
        let mut check = compare(&r, &points).unwrap();
        check.lost.push(("F2".into(), "not seen".into()));
        assert!(check.decide(0.05, "f.csv", true).is_none());
        let why = check.undecided();
        assert!(
            why.contains("fewer than 3") && why.contains("F2: not seen"),
            "{why}"
        );
        let stranger = NamedPoint {
            name: "X9".into(),
            position: DVec3::ZERO,
            weight: 1.0,
        };
        assert!(compare(&r, &[stranger]).is_err());
    }
}
