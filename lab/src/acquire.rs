//! How the virtual instrument reports a simulated campaign: in its own frame, as a 6-DoF probe
//! or as targets, some of them missed.

use hexacomp_core::observation::Observation;
use hexacomp_core::records::MeasuredConfiguration;
use hexacomp_core::{Geometry, Pose};
use hexacomp_measuring::campaign::as_instrument_reports;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::error::{Error, Result};

/// How the virtual instrument reports a campaign, beyond its noise.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Reporting {
    /// Where the instrument stands: its pose in the base frame; what it reports is in its own
    /// frame (the identity: the base frame).
    pub instrument: Pose,
    /// The share of configurations in which one target, drawn at random, is not seen (0–1).
    pub missed_share: f64,
    /// A 6-DoF probe: the platform's pose is reported (fitted to the measured targets) instead of
    /// the targets.
    pub probe: bool,
    /// Seed of the missed targets.
    pub seed: u64,
}

/// `rows` (measured in the base frame) as the instrument of `reporting` reports them: a probe's
/// pose instead of the targets, in the instrument's frame, with targets missed.
pub fn as_reported(
    geometry: &Geometry,
    rows: &mut [MeasuredConfiguration],
    reporting: &Reporting,
) -> Result<()> {
    if !(0.0..=1.0).contains(&reporting.missed_share) {
        return Err(Error::OutOfRange {
            setting: "share of configurations with a target missed",
            value: reporting.missed_share,
            valid: "must be a number in [0, 1]",
        });
    }
    let into_instrument = reporting.instrument.inverse();
    let mut rng = ChaCha8Rng::seed_from_u64(reporting.seed ^ 0x6d69_7373_6564);
    for row in rows {
        row.observed =
            as_instrument_reports(geometry, &row.observed, &into_instrument, reporting.probe)?;
        let missed = rng.random_bool(reporting.missed_share);
        if let Observation::Targets(targets) = &mut row.observed
            && missed
        {
            let index = rng.random_range(0..targets.len());
            targets[index] = None;
        }
    }
    Ok(())
}
