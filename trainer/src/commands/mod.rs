//! One module per subcommand.

pub mod calibrate;
pub mod deploy;
pub mod evaluate;
pub mod geometry;
pub mod identify;
pub mod inspect;
pub mod plan;
pub mod predict;
pub mod simulate;
pub mod solve;
pub mod survey;
pub mod train;

use std::io::Write;
use std::path::Path;

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
