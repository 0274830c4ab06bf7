//! The state directory: the last accepted model and its generation, written atomically so that a
//! crash mid-write never leaves a broken file.

use std::path::{Path, PathBuf};

use hexacomp_core::Geometry;
use hexacomp_core::durable::replace_file;
use hexacomp_core::model::Model;

/// The accepted model's file in a state directory.
pub fn model_path(dir: &Path) -> PathBuf {
    dir.join("model.hxm")
}

fn generation_path(dir: &Path) -> PathBuf {
    dir.join("generation")
}

/// Creates the state directory, readable and writable by its owner only.
pub fn prepare(dir: &Path) -> std::io::Result<()> {
    std::fs::create_dir_all(dir)?;
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(dir, std::fs::Permissions::from_mode(0o700))
}

/// Persists an accepted model file (its bytes) and its generation, each file replaced whole and
/// durably ([`hexacomp_core::durable::replace_file`]).
pub fn persist(dir: &Path, model_file: &[u8], generation: u64) -> Result<(), String> {
    let path = model_path(dir);
    replace_file(&path, model_file).map_err(|e| format!("writing {}: {e}", path.display()))?;
    let path = generation_path(dir);
    replace_file(&path, generation.to_string().as_bytes())
        .map_err(|e| format!("writing {}: {e}", path.display()))
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
