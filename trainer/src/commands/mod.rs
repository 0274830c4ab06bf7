//! One module per subcommand.

pub mod calibrate;
pub mod campaign;
pub mod check;
pub mod deploy;
pub mod drift_log;
pub mod end_fiducials;
pub mod evaluate;
pub mod export;
pub mod geometry;
pub mod identify;
pub mod inspect;
pub mod measurements_input;
pub mod plan;
pub mod predict;
pub mod readings_log;
pub mod register;
pub mod rig;
pub mod simulate;
pub mod solve;
pub mod survey;
pub mod train;
pub mod verify;

use std::io::Write;
use std::path::Path;

/// The instrument's pose in the base frame from `--instrument-pose x,y,z,a,b,c` (mm, degrees);
/// the identity (the base frame itself) when the option is not given.
pub fn instrument_pose(values: Option<&[f64]>) -> anyhow::Result<hexacomp_core::Pose> {
    let Some(values) = values else {
        return Ok(hexacomp_core::Pose::default());
    };
    let values: [f64; 6] = values
        .try_into()
        .map_err(|_| anyhow::anyhow!("--instrument-pose needs six numbers x,y,z,a,b,c"))?;
    anyhow::ensure!(
        values.iter().all(|v| v.is_finite()),
        "--instrument-pose {values:?}: every number must be finite"
    );
    Ok(hexacomp_core::Pose::from_mm_deg(values))
}

/// The value parser of an option that takes one of `names` (parsed by the type's `FromStr`):
/// `--help` lists the names, and a value not among them is refused with the list.
pub fn named<T>(
    names: impl IntoIterator<Item = &'static str>,
) -> impl clap::builder::TypedValueParser<Value = T>
where
    T: std::str::FromStr + Clone + Send + Sync + 'static,
    T::Err: std::fmt::Debug,
{
    use clap::builder::TypedValueParser;
    clap::builder::PossibleValuesParser::new(names)
        .map(|name| name.parse().expect("a listed name parses"))
}

/// The first leg (1–6) whose commanded length at `pose` lies outside the geometry's stroke, and
/// that length (mm); `None` when every leg is inside.
pub fn leg_outside_stroke(
    geometry: &hexacomp_core::Geometry,
    pose: &hexacomp_core::Pose,
) -> Option<(usize, f64)> {
    let [min, max] = geometry.leg_range;
    let legs = hexacomp_core::inverse_kinematics(geometry, pose).lengths;
    (1..).zip(legs).find(|(_, l)| !(min..=max).contains(l))
}

/// A number as a campaign log writes it (every digit), or an empty cell for none.
pub fn optional_cell(value: Option<f64>) -> String {
    value.map_or(String::new(), |v| v.to_string())
}

/// The cells `ix..ic` of a campaign log: the instrument's pose of the run's registration (mm,
/// degrees), or six empty cells without one.
pub fn registration_cells(pose: Option<[f64; 6]>) -> impl Iterator<Item = String> {
    (0..6).map(move |k| optional_cell(pose.map(|p| p[k])))
}

/// Writes `bytes` to the file at `path`, whole or not at all ([`hexacomp_formats::write_file`]).
pub fn write_bytes(path: &Path, bytes: &[u8]) -> hexacomp_formats::Result<()> {
    hexacomp_formats::write_file(path, |file| file.write_all(bytes))
}

/// The files a command reads and the files it writes (folders it replaces as a whole are not
/// listed: they are checked where they are written).
#[derive(Default)]
pub struct Files<'a> {
    /// Files read.
    pub inputs: Vec<&'a Path>,
    /// Files written.
    pub outputs: Vec<&'a Path>,
}

impl Files<'_> {
    /// Refuses, before anything is written, an output that is one of the inputs or the geometry
    /// file `geometry` (when one was given).
    pub fn refuse_overwriting_inputs(
        &self,
        geometry: Option<&Path>,
    ) -> hexacomp_formats::Result<()> {
        let inputs: Vec<&Path> = self.inputs.iter().copied().chain(geometry).collect();
        self.outputs
            .iter()
            .try_for_each(|output| hexacomp_formats::refuse_same_file(output, &inputs))
    }
}

/// A folder of results being written: replaced as a unit when complete
/// ([`hexacomp_core::durable::NewDirectory`]). An existing folder holding anything but the
/// command's own files is refused rather than replaced (its other files would be lost).
pub struct ResultsFolder {
    folder: hexacomp_core::durable::NewDirectory,
    target: std::path::PathBuf,
}

impl ResultsFolder {
    /// Starts the folder `dir` of `command`, which writes only files named in `own`.
    pub fn create(dir: &Path, command: &str, own: &[&str]) -> anyhow::Result<Self> {
        use anyhow::Context;
        refuse_foreign_files(dir, command, own)?;
        if let Some(parent) = dir.parent().filter(|p| !p.as_os_str().is_empty()) {
            std::fs::create_dir_all(parent)
                .with_context(|| format!("creating {}", parent.display()))?;
        }
        let folder = hexacomp_core::durable::NewDirectory::create(dir)
            .with_context(|| format!("{}: cannot make its replacement", dir.display()))?;
        Ok(Self {
            folder,
            target: dir.to_path_buf(),
        })
    }

    /// Where to write the files.
    pub fn path(&self) -> &Path {
        self.folder.path()
    }

    /// Puts the folder in place of the old one (a cleanup that fails afterwards is a warning).
    pub fn commit(self) -> anyhow::Result<()> {
        use anyhow::Context;
        let warning = self
            .folder
            .commit()
            .with_context(|| format!("replacing {}", self.target.display()))?;
        if let Some(warning) = warning {
            eprintln!(
                "warning: {} was replaced, but {warning}",
                self.target.display()
            );
        }
        Ok(())
    }
}

/// Refuses an existing `dir` that holds anything `command` does not write (`own`).
fn refuse_foreign_files(dir: &Path, command: &str, own: &[&str]) -> anyhow::Result<()> {
    use anyhow::Context;
    let entries = match std::fs::read_dir(dir) {
        Ok(entries) => entries,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(e) => return Err(e).with_context(|| format!("reading {}", dir.display())),
    };
    let mut foreign = Vec::new();
    for entry in entries {
        let name = entry
            .with_context(|| format!("reading {}", dir.display()))?
            .file_name();
        if !own.iter().any(|known| name == *known) {
            foreign.push(name.to_string_lossy().into_owned());
        }
    }
    foreign.sort();
    anyhow::ensure!(
        foreign.is_empty(),
        "{} is replaced as a whole by {command}, but holds files {command} did not write ({}): \
         give another folder",
        dir.display(),
        foreign.join(", ")
    );
    Ok(())
}
