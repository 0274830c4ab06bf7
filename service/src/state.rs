//! The state directory: the last accepted model and its generation, written atomically so that a
//! crash mid-write never leaves a broken file.

use std::path::{Path, PathBuf};

use hexacomp_core::Geometry;
use hexacomp_core::durable::replace_file;
use hexacomp_core::model::Model;

use crate::Error;

/// The accepted model's file in a state directory.
pub fn model_path(dir: &Path) -> PathBuf {
    dir.join("model.hxm")
}

fn generation_path(dir: &Path) -> PathBuf {
    dir.join("generation")
}

/// Creates the state directory, readable and writable by its owner only.
pub fn prepare(dir: &Path) -> Result<(), Error> {
    use std::os::unix::fs::PermissionsExt;
    std::fs::create_dir_all(dir)
        .and_then(|()| std::fs::set_permissions(dir, std::fs::Permissions::from_mode(0o700)))
        .map_err(|cause| Error::StateDir {
            path: dir.to_path_buf(),
            cause,
        })
}

/// Persists an accepted model file (its bytes) and its generation, each file replaced whole and
/// durably ([`hexacomp_core::durable::replace_file`]).
pub fn persist(dir: &Path, model_file: &[u8], generation: u64) -> Result<(), Error> {
    let replace = |path: PathBuf, bytes: &[u8]| {
        replace_file(&path, bytes).map_err(|cause| Error::Persist { path, cause })
    };
    replace(model_path(dir), model_file)?;
    replace(generation_path(dir), generation.to_string().as_bytes())
}

/// The persisted model and generation, if any, for `geometry`. A file for another geometry or a
/// damaged one is reported and ignored.
pub fn restore(dir: &Path, geometry: &Geometry) -> Option<(Model, u64)> {
    let path = model_path(dir);
    if !path.exists() {
        return None;
    }
    match Model::load(&path, geometry) {
        Ok(model) => {
            let generation = std::fs::read_to_string(generation_path(dir))
                .ok()
                .and_then(|t| t.trim().parse().ok())
                .unwrap_or(1);
            Some((model, generation))
        }
        Err(e) => {
            tracing::warn!("ignoring the persisted model: {e}");
            None
        }
    }
}
