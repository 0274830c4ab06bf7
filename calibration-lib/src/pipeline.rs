//! The calibration pipeline as one type: plan → acquire → solve → train. The `calibrate`,
//! `train` and `evaluate` commands, the evaluation library, the bench and the multi-process
//! tests run its stages through [`Pipeline`], so that they cannot drift apart between them (the
//! single-stage commands `plan`, `simulate` and `solve`, and tests that check one stage against
//! an independent value, call that stage's function directly).
//!
//! Units: mm and degrees in the rows (as in the files), mm in the corrections.

use hexacomp_core::Geometry;
use hexacomp_core::records::{JointCorrection, MeasuredConfiguration};

use crate::corrections::{Checks, Outcome, SolverOptions, solve_all};
use crate::error::Result;
use crate::plan::PlanOptions;
use crate::screening::{Screening, ScreeningOptions, screen_measured};
use crate::train::{Architecture, TrainOptions, Trained, train};

/// The settings of every stage of a calibration.
#[derive(Debug, Clone, Default)]
pub struct Pipeline {
    /// The measuring plan (configurations, seed), for a calibration on the virtual platform
    /// (`hexacomp_lab::measure_virtual`).
    pub plan: PlanOptions,
    /// The joint-correction solve (robust by default, Fig. 2).
    pub solver: SolverOptions,
    /// The per-configuration checks of the solve.
    pub checks: Checks,
    /// Which configurations are gross errors, and when an input is refused.
    pub screening: ScreeningOptions,
    /// Network training and hidden-node selection.
    pub train: TrainOptions,
}

/// What the solve stage produced.
#[derive(Debug, Clone)]
pub struct Solved {
    /// Every configuration's outcome, in the measurements' order (solution or error, flags).
    pub outcomes: Vec<Outcome>,
    /// Which configurations are excluded and why, in the same order.
    pub screening: Screening,
    /// The correction rows of the kept configurations: the training data.
    pub corrections: Vec<JointCorrection>,
}

impl Solved {
    /// The items of `rows` (one per configuration, in the measurements' order, such as the
    /// measurements themselves) of the kept configurations.
    pub fn kept_of<T: Clone>(&self, rows: &[T]) -> Vec<T> {
        rows.iter()
            .enumerate()
            .filter(|(index, _)| self.screening.kept(*index))
            .map(|(_, row)| row.clone())
            .collect()
    }

    /// The outcomes of the kept configurations, in the measurements' order.
    pub fn kept(&self) -> Vec<&Outcome> {
        self.outcomes
            .iter()
            .enumerate()
            .filter(|(index, _)| self.screening.kept(*index))
            .map(|(_, o)| o)
            .collect()
    }
}

/// What a whole calibration produced.
#[derive(Debug, Clone)]
pub struct Calibration {
    /// The solve stage.
    pub solved: Solved,
    /// One trained model per architecture asked for, in that order.
    pub models: Vec<(Architecture, Trained)>,
}

impl Pipeline {
    /// Solves the joint corrections of every measured configuration and screens them for gross
    /// errors: the excluded configurations are not trained on, and an input with too many of
    /// them is refused ([`crate::Error::Refused`]).
    pub fn solve(
        &self,
        geometry: &Geometry,
        measurements: &[MeasuredConfiguration],
    ) -> Result<Solved> {
        let outcomes = solve_all(geometry, measurements, &self.solver, &self.checks)?;
        let screening = screen_measured(geometry, measurements, &outcomes, &self.screening)?;
        let corrections = outcomes
            .iter()
            .enumerate()
            .filter(|(index, _)| screening.kept(*index))
            .filter_map(|(_, o)| o.joint_correction())
            .collect();
        Ok(Solved {
            outcomes,
            screening,
            corrections,
        })
    }

    /// Trains networks of `architecture` on `corrections` for `geometry`; `progress(n)` reports
    /// `n` more units of [`crate::train::training_work`] done (for progress bars).
    pub fn train(
        &self,
        geometry: &Geometry,
        corrections: &[JointCorrection],
        architecture: Architecture,
        progress: &(dyn Fn(u64) + Sync),
    ) -> Result<Trained> {
        train(
            corrections,
            architecture,
            geometry.fingerprint(),
            &self.train,
            progress,
        )
    }

    /// Solves `measurements` and trains each of `architectures` on the corrections;
    /// `progress(architecture, n)` as [`Pipeline::train`] reports it.
    pub fn calibrate(
        &self,
        geometry: &Geometry,
        measurements: &[MeasuredConfiguration],
        architectures: &[Architecture],
        progress: &(dyn Fn(Architecture, u64) + Sync),
    ) -> Result<Calibration> {
        let solved = self.solve(geometry, measurements)?;
        let models = architectures
            .iter()
            .map(|&architecture| {
                let done = |n| progress(architecture, n);
                self.train(geometry, &solved.corrections, architecture, &done)
                    .map(|trained| (architecture, trained))
            })
            .collect::<Result<_>>()?;
        Ok(Calibration { solved, models })
    }
}
