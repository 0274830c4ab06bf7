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

use std::path::Path;

use anyhow::Context;

/// Writes a file through `write`, reporting the path on failure.
pub fn write_file(
    path: &Path,
    write: impl FnOnce(std::io::BufWriter<std::fs::File>) -> hexacomp_formats::Result<()>,
) -> anyhow::Result<()> {
    let file = hexacomp_formats::create_file(path)?;
    write(file).with_context(|| format!("writing {}", path.display()))
}
