//! # hexacomp-point-status
//!
//! The status of one compensated point: what the compensator (`hexacomp-core`) computes and what
//! travels on the wire (`hexacomp-protocol`'s `PointResponse::status`, as `u8`). One definition
//! for both, in a crate without dependencies, so that neither of the two needs the other.

#![no_std]
#![warn(missing_docs)]

/// How a point was compensated. The numeric values are the wire values: a service sends
/// `status as u8`, a client reads it back with [`PointStatus::from_u8`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum PointStatus {
    /// Compensated inside the trained range.
    Ok = 0,
    /// A nominal or corrected leg is outside the stroke: the legs returned are uncorrected.
    OutOfStroke = 1,
    /// Compensated, but the legs lie outside the range the model was trained on.
    OutsideTrainedRange = 2,
    /// A correction exceeded the model's bounds and was clamped to them.
    Clamped = 3,
    /// A non-finite input, or a non-finite output of the model: no correction applied, the legs
    /// returned are the input (for a non-finite pose, its non-finite inverse kinematics).
    InvalidInput = 4,
    /// No model loaded: the legs returned are the nominal ones.
    NoModel = 5,
}

impl PointStatus {
    /// Every status, in numeric order.
    pub const ALL: [PointStatus; 6] = [
        PointStatus::Ok,
        PointStatus::OutOfStroke,
        PointStatus::OutsideTrainedRange,
        PointStatus::Clamped,
        PointStatus::InvalidInput,
        PointStatus::NoModel,
    ];

    /// The status's name, as in the `status` column of compensated-point files.
    pub fn name(self) -> &'static str {
        match self {
            PointStatus::Ok => "ok",
            PointStatus::OutOfStroke => "out_of_stroke",
            PointStatus::OutsideTrainedRange => "outside_trained_range",
            PointStatus::Clamped => "clamped",
            PointStatus::InvalidInput => "invalid_input",
            PointStatus::NoModel => "no_model",
        }
    }

    /// The status of a wire value, if it is one.
    pub fn from_u8(value: u8) -> Option<Self> {
        Self::ALL.get(value as usize).copied()
    }
}

/// How many points had each status: a summary for a user, printed as the statuses other than
/// `ok` with their counts (`3 clamped, 1 outside_trained_range`), or `all ok`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct StatusCounts([usize; PointStatus::ALL.len()]);

impl StatusCounts {
    /// Counts one more point of `status`.
    pub fn add(&mut self, status: PointStatus) {
        self.0[status as usize] += 1;
    }

    /// The points counted with `status`.
    pub fn count(&self, status: PointStatus) -> usize {
        self.0[status as usize]
    }
}

impl FromIterator<PointStatus> for StatusCounts {
    fn from_iter<I: IntoIterator<Item = PointStatus>>(statuses: I) -> Self {
        let mut counts = Self::default();
        statuses.into_iter().for_each(|s| counts.add(s));
        counts
    }
}

impl core::fmt::Display for StatusCounts {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let mut first = true;
        for status in PointStatus::ALL {
            let count = self.count(status);
            if status == PointStatus::Ok || count == 0 {
                continue;
            }
            if !first {
                f.write_str(", ")?;
            }
            write!(f, "{count} {}", status.name())?;
            first = false;
        }
        if first {
            f.write_str("all ok")?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    extern crate std;
    use std::string::ToString;

    #[test]
    fn counts_print_the_statuses_that_are_not_ok() {
        let counts: StatusCounts = [
            PointStatus::Ok,
            PointStatus::Clamped,
            PointStatus::NoModel,
            PointStatus::Clamped,
        ]
        .into_iter()
        .collect();
        assert_eq!(counts.count(PointStatus::Clamped), 2);
        assert_eq!(counts.to_string(), "2 clamped, 1 no_model");
        let all_ok: StatusCounts = [PointStatus::Ok; 3].into_iter().collect();
        assert_eq!(all_ok.to_string(), "all ok");
    }

    #[test]
    fn wire_values_round_trip_and_unknown_values_are_none() {
        for (value, status) in PointStatus::ALL.iter().enumerate() {
            assert_eq!(*status as u8 as usize, value);
            assert_eq!(PointStatus::from_u8(value as u8), Some(*status));
        }
        assert_eq!(PointStatus::from_u8(6), None);
        assert_eq!(PointStatus::from_u8(u8::MAX), None);
    }
}
