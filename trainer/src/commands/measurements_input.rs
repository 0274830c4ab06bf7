//! How `solve`, `identify` and `calibrate` read a measurements file: the frame it was measured
//! in (`--registration`) and the rotation convention of its measured poses
//! (`--pose-convention`).

use std::path::Path;
use std::path::PathBuf;

use hexacomp_core::Geometry;
use hexacomp_core::observation::Observation;
use hexacomp_core::pose::PoseConvention;
use hexacomp_core::records::MeasuredConfiguration;
use hexacomp_formats::{Records, RegistrationFile, read_measurements_in, read_registration};
use hexacomp_measuring::registration::into_base_frame;

/// The options that say how a measurements file is to be read.
#[derive(Debug, clap::Args)]
pub struct MeasurementsInput {
    /// Registration TOML (`hexacomp-trainer register`) of the instrument that measured.
    ///
    /// The measured target points (or poses) are in that instrument's frame and are brought
    /// into the base frame before solving. Without it they are in the base frame.
    #[arg(long, value_name = "FILE", requires = "measurements")]
    registration: Option<PathBuf>,
    /// Rotation convention of the measured poses of a 6-DoF probe (columns mx..mc).
    ///
    /// linuxcnc: R = Rz(c)·Ry(b)·Rx(a), as every pose in hexacomp; pi-uvw: R =
    /// Rx(U)·Ry(V)·Rz(W), rotations about the moving axes, as PI's hexapod controllers
    /// write them.
    #[arg(help_heading = "Measurements", long, default_value_t = PoseConvention::Linuxcnc, value_parser = super::named::<PoseConvention>(PoseConvention::ALL.map(PoseConvention::name)), value_name = "CONVENTION")]
    pose_convention: PoseConvention,
}

impl MeasurementsInput {
    /// The registration file, when one is given.
    pub fn registration_path(&self) -> Option<&Path> {
        self.registration.as_deref()
    }

    /// Reads the registration, when one is given.
    pub fn registration(&self) -> anyhow::Result<Option<RegistrationFile>> {
        Ok(self
            .registration_path()
            .map(read_registration)
            .transpose()?)
    }

    /// Reads the measurements file at `path` in the pose convention given, without bringing it
    /// into the base frame; refuses, naming the line, a row that does not fit `geometry` (another
    /// number of targets). Warns when --pose-convention is given for a file without poses.
    pub fn read_file(
        &self,
        path: &Path,
        geometry: &Geometry,
    ) -> anyhow::Result<Records<MeasuredConfiguration>> {
        let rows = read_measurements_in(path, self.pose_convention)?;
        for (index, row) in rows.iter().enumerate() {
            if let Err(why) = row.observed.check(geometry) {
                anyhow::bail!(
                    "{}:{}: configuration {}: {why}",
                    rows.file,
                    rows.line(index),
                    row.id
                );
            }
        }
        let has_poses = rows
            .iter()
            .any(|row| matches!(row.observed, Observation::Pose(_) | Observation::PoseMissed));
        if self.pose_convention != PoseConvention::Linuxcnc && !has_poses {
            eprintln!(
                "warning: --pose-convention {} has no effect: {} holds no measured poses \
                 (mx..mc); its commanded poses are read in LinuxCNC's convention",
                self.pose_convention, rows.file
            );
        }
        Ok(rows)
    }

    /// Brings `rows` into the base frame through `registration`, saying so.
    pub fn apply(
        &self,
        registration: Option<&RegistrationFile>,
        rows: &mut Records<MeasuredConfiguration>,
    ) {
        let (Some(path), Some(registration)) = (self.registration_path(), registration) else {
            return;
        };
        into_base_frame(rows, &registration.instrument_pose());
        eprintln!(
            "{}: measured in the instrument frame of {} (registered {}, RMS {:.4} mm), brought \
             into the base frame",
            rows.file,
            path.display(),
            registration.created,
            registration.rms_mm
        );
    }

    /// Reads `path`'s measurements for `geometry` and brings them into the base frame when a
    /// registration is given.
    pub fn read(
        &self,
        path: &Path,
        geometry: &Geometry,
    ) -> anyhow::Result<Records<MeasuredConfiguration>> {
        let registration = self.registration()?;
        let mut rows = self.read_file(path, geometry)?;
        self.apply(registration.as_ref(), &mut rows);
        Ok(rows)
    }
}
