//! The state directory: the last accepted model and its generation, persisted as one unit.
//!
//! Layout (docs/formats.md):
//! - `g-<N>/model.hxm` and `g-<N>/generation`: one persisted generation, written and flushed to
//!   disk before it becomes current;
//! - `current` → `g-<N>`: a symbolic link, replaced by one rename: the commit. Whatever fails or
//!   crashes, `current` names either the previous generation or the new one, each complete;
//! - `model.hxm` → `current/model.hxm` and `generation` → `current/generation`: fixed links, so
//!   that the paths of the first layout (two plain files) still read the current pair.
//!
//! A directory in the first layout (plain `model.hxm` and `generation`, no `current`) is read as
//! it is and converted by the next persist.

use std::io::ErrorKind;
use std::os::unix::fs::{DirBuilderExt, MetadataExt, PermissionsExt};
use std::path::{Path, PathBuf};

use hexacomp_core::Geometry;
use hexacomp_core::durable::{replace_file, sync_directory_of};
use hexacomp_core::model::Model;

use crate::Error;

const CURRENT: &str = "current";
const MODEL: &str = "model.hxm";
const GENERATION: &str = "generation";

/// The accepted model's file in a state directory (a link to the current generation's).
pub fn model_path(dir: &Path) -> PathBuf {
    dir.join(MODEL)
}

/// Where the persisted pair is read from: `current/` when it exists, else (the first layout)
/// the directory itself. The fixed links are for other tools; a crash while they are being
/// made (converting the first layout) must not make a restart read a mixed pair.
fn pair_dir(dir: &Path) -> Result<PathBuf, Error> {
    let current = dir.join(CURRENT);
    match std::fs::symlink_metadata(&current) {
        Ok(_) => Ok(current),
        Err(e) if e.kind() == ErrorKind::NotFound => Ok(dir.to_path_buf()),
        Err(cause) => Err(Error::StateFile {
            path: current,
            cause,
        }),
    }
}

/// Prepares the state directory: creates it with mode 0700 when it does not exist; an existing
/// one is used as it is, never changed, if it belongs to this user and no one else may write to
/// it. A shared directory (`/tmp`, `/var/lib`) is refused: the service needs one of its own.
pub fn prepare(dir: &Path) -> Result<(), Error> {
    let fail = |cause: std::io::Error| Error::StateDir {
        path: dir.to_path_buf(),
        cause,
    };
    match std::fs::symlink_metadata(dir) {
        Err(e) if e.kind() == ErrorKind::NotFound => {
            if let Some(parent) = dir.parent().filter(|p| !p.as_os_str().is_empty()) {
                std::fs::create_dir_all(parent).map_err(fail)?;
            }
            return std::fs::DirBuilder::new()
                .mode(0o700)
                .create(dir)
                .map_err(fail);
        }
        Err(e) => return Err(fail(e)),
        Ok(_) => {}
    }
    // Followed, as the service will follow it (a link to the real directory is fine).
    let metadata = std::fs::metadata(dir).map_err(fail)?;
    if !metadata.is_dir() {
        return Err(fail(std::io::Error::other("not a directory")));
    }
    // SAFETY: geteuid cannot fail and has no preconditions.
    let user = unsafe { libc::geteuid() };
    if metadata.uid() != user {
        return Err(fail(std::io::Error::other(format!(
            "owned by user {}, not by this service's user {user}: give the service a \
             directory of its own",
            metadata.uid()
        ))));
    }
    let mode = metadata.permissions().mode();
    if mode & 0o022 != 0 {
        return Err(fail(std::io::Error::other(format!(
            "writable by others (mode {:o}): a shared directory; give the service a \
             directory of its own",
            mode & 0o7777
        ))));
    }
    Ok(())
}

/// Persists an accepted model file (its bytes) and its generation as one unit: the new
/// generation's directory is written and flushed, then `current` is switched to it by one
/// rename and the state directory flushed. On success a restart serves this pair; on failure,
/// the pair persisted before (nothing of the new one is left behind).
pub fn persist(dir: &Path, model_file: &[u8], generation: u64) -> Result<(), Error> {
    let name = format!("g-{generation}");
    let target = dir.join(&name);
    let fail = |path: &Path, cause: std::io::Error| Error::Persist {
        path: path.to_path_buf(),
        cause,
    };
    if std::fs::read_link(dir.join(CURRENT)).is_ok_and(|current| current == Path::new(&name)) {
        return Err(fail(
            &target,
            std::io::Error::other("this generation is already the persisted one"),
        ));
    }
    // A directory of this number left by a crash before its commit: never current, so stale.
    let _ = std::fs::remove_dir_all(&target);
    let written = (|| {
        std::fs::DirBuilder::new().mode(0o700).create(&target)?;
        replace_file(&target.join(MODEL), model_file)?;
        replace_file(&target.join(GENERATION), generation.to_string().as_bytes())
    })();
    if let Err(cause) = written {
        let _ = std::fs::remove_dir_all(&target);
        return Err(fail(&target, cause));
    }
    let current = dir.join(CURRENT);
    if let Err(cause) = switch_link(&current, Path::new(&name)) {
        let _ = std::fs::remove_dir_all(&target);
        return Err(fail(&link_temporary(&current), cause));
    }
    // Committed: `current` names the new generation. From here on the generation directory
    // stays, whatever fails.
    if let Err(cause) = sync_directory_of(&current) {
        return Err(Error::Persist {
            path: dir.to_path_buf(),
            cause: std::io::Error::new(
                cause.kind(),
                format!(
                    "generation {generation} is current, but flushing the directory failed \
                     ({cause}): after a power loss the previous one may come back"
                ),
            ),
        });
    }
    // Committed. The fixed links and the removal of older generations are housekeeping: their
    // failure changes nothing a restart serves, so it is logged, not reported.
    for file in [MODEL, GENERATION] {
        let link = Path::new(CURRENT).join(file);
        let path = dir.join(file);
        if std::fs::read_link(&path).ok().as_deref() != Some(link.as_path())
            && let Err(e) = replace_link(&path, &link)
        {
            tracing::warn!("state directory: linking {}: {e}", path.display());
        }
    }
    remove_other_generations(dir, &name);
    Ok(())
}

/// Where a new link for `path` (a file of the state directory) is made before its rename:
/// `.<name>.link` beside it.
fn link_temporary(path: &Path) -> PathBuf {
    let name = path.file_name().unwrap_or_default().to_string_lossy();
    path.with_file_name(format!(".{name}.link"))
}

/// Replaces `path` by a symbolic link to `target`, made at [`link_temporary`] and renamed over
/// it (one rename: `path` is the old link or the new one, never missing).
fn switch_link(path: &Path, target: &Path) -> std::io::Result<()> {
    let temporary = link_temporary(path);
    let _ = std::fs::remove_file(&temporary);
    std::os::unix::fs::symlink(target, &temporary)?;
    std::fs::rename(&temporary, path).inspect_err(|_| {
        let _ = std::fs::remove_file(&temporary);
    })
}

/// [`switch_link`], then the directory flushed.
fn replace_link(path: &Path, target: &Path) -> std::io::Result<()> {
    switch_link(path, target)?;
    sync_directory_of(path)
}

/// Removes the generation directories other than `keep` (older ones, and any a crash left).
fn remove_other_generations(dir: &Path, keep: &str) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let name = entry.file_name();
        let name = name.to_string_lossy();
        let numbered = name
            .strip_prefix("g-")
            .is_some_and(|n| n.parse::<u64>().is_ok());
        if numbered
            && name != keep
            && let Err(e) = std::fs::remove_dir_all(entry.path())
        {
            tracing::warn!("state directory: removing {}: {e}", entry.path().display());
        }
    }
}

/// The persisted generation number: `Ok(None)` when nothing is persisted, an error naming the
/// file when it holds anything but a decimal number from 1 to 2⁶⁴ − 1.
pub fn persisted_generation(dir: &Path) -> Result<Option<u64>, Error> {
    let path = pair_dir(dir)?.join(GENERATION);
    let text = match std::fs::read_to_string(&path) {
        Err(e) if e.kind() == ErrorKind::NotFound => return Ok(None),
        Err(cause) => return Err(Error::StateFile { path, cause }),
        Ok(text) => text,
    };
    match text.trim().parse::<u64>() {
        Ok(number) if number > 0 => Ok(Some(number)),
        _ => Err(Error::StateFile {
            path,
            cause: std::io::Error::other(format!(
                "{:?} is not a generation number (a decimal number from 1 to {})",
                text.chars().take(40).collect::<String>(),
                u64::MAX
            )),
        }),
    }
}

/// The model file [`restore`] reads (the current generation's), whose modification time is
/// when it was persisted: its deploy, or the start that loaded it.
pub fn persisted_model_file(dir: &Path) -> Result<PathBuf, Error> {
    Ok(pair_dir(dir)?.join(MODEL))
}

/// The persisted model and generation, if any, for `geometry`. A model file for another
/// geometry or a damaged one is reported and ignored; a generation file that does not hold a
/// generation number, or a model without one, is an error naming the file.
pub fn restore(dir: &Path, geometry: &Geometry) -> Result<Option<(Model, u64)>, Error> {
    let pair = pair_dir(dir)?;
    let path = pair.join(MODEL);
    match std::fs::symlink_metadata(&path) {
        Err(e) if e.kind() == ErrorKind::NotFound && pair == dir => return Ok(None),
        Err(cause) => return Err(Error::StateFile { path, cause }),
        Ok(_) => {}
    }
    let generation = persisted_generation(dir)?.ok_or_else(|| Error::StateFile {
        path: pair.join(GENERATION),
        cause: std::io::Error::new(ErrorKind::NotFound, "missing beside the persisted model"),
    })?;
    match Model::load(&path, geometry) {
        Ok(model) => Ok(Some((model, generation))),
        Err(e) => {
            tracing::warn!("ignoring the persisted model: {e}");
            Ok(None)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What a restart reads: the model file's bytes and the generation.
    fn pair(dir: &Path) -> (Vec<u8>, Option<u64>) {
        let from = pair_dir(dir).unwrap();
        (
            std::fs::read(from.join(MODEL)).unwrap_or_default(),
            persisted_generation(dir).unwrap(),
        )
    }

    #[test]
    fn each_persist_replaces_the_pair_and_leaves_one_generation_directory() {
        let dir = tempfile::tempdir().unwrap();
        persist(dir.path(), b"model one", 1).unwrap();
        persist(dir.path(), b"model two", 2).unwrap();
        assert_eq!(pair(dir.path()), (b"model two".to_vec(), Some(2)));
        let mut names: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        names.sort();
        assert_eq!(names, ["current", "g-2", "generation", "model.hxm"]);
    }

    #[test]
    fn a_persist_that_fails_part_way_leaves_the_previous_pair() {
        let dir = tempfile::tempdir().unwrap();
        persist(dir.path(), b"model one", 1).unwrap();
        // The generation file's place is taken by a directory that is not empty: writing two
        // files one after the other (the first layout) replaced the model, then failed here.
        std::fs::remove_file(dir.path().join(GENERATION)).unwrap();
        std::fs::create_dir(dir.path().join(GENERATION)).unwrap();
        std::fs::write(dir.path().join(GENERATION).join("x"), b"x").unwrap();
        let result = persist(dir.path(), b"model two", 2);
        match result {
            Ok(()) => assert_eq!(pair(dir.path()), (b"model two".to_vec(), Some(2))),
            Err(_) => assert_eq!(pair(dir.path()), (b"model one".to_vec(), Some(1))),
        }
    }

    #[test]
    fn a_failed_commit_changes_nothing_and_leaves_no_new_directory() {
        let dir = tempfile::tempdir().unwrap();
        persist(dir.path(), b"model one", 1).unwrap();
        // The place of the new `current` link is taken by a directory that is not empty: the
        // switch fails after the new generation's directory was written.
        std::fs::create_dir(dir.path().join(".current.link")).unwrap();
        std::fs::write(dir.path().join(".current.link").join("x"), b"x").unwrap();
        assert!(persist(dir.path(), b"model two", 2).is_err());
        assert_eq!(pair(dir.path()), (b"model one".to_vec(), Some(1)));
        assert!(!dir.path().join("g-2").exists());
    }

    #[test]
    fn a_directory_in_the_first_layout_is_read_and_converted() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join(MODEL), b"old model").unwrap();
        std::fs::write(dir.path().join(GENERATION), b"7").unwrap();
        assert_eq!(pair(dir.path()), (b"old model".to_vec(), Some(7)));
        persist(dir.path(), b"new model", 8).unwrap();
        assert_eq!(pair(dir.path()), (b"new model".to_vec(), Some(8)));
        assert!(
            std::fs::symlink_metadata(dir.path().join(MODEL))
                .unwrap()
                .file_type()
                .is_symlink()
        );
    }

    #[test]
    fn a_generation_file_without_a_generation_number_is_an_error_naming_it() {
        let dir = tempfile::tempdir().unwrap();
        for text in ["garbage", "", "0", "-1", "18446744073709551616"] {
            std::fs::write(dir.path().join(GENERATION), text).unwrap();
            let error = persisted_generation(dir.path()).unwrap_err().to_string();
            assert!(error.contains("generation"), "{text:?}: {error}");
            assert!(error.contains(&dir.path().display().to_string()), "{error}");
        }
        std::fs::write(dir.path().join(GENERATION), u64::MAX.to_string()).unwrap();
        assert_eq!(persisted_generation(dir.path()).unwrap(), Some(u64::MAX));
    }

    #[test]
    fn a_shared_or_foreign_directory_is_refused_and_left_as_it_was() {
        let dir = tempfile::tempdir().unwrap();
        let shared = dir.path().join("shared");
        std::fs::create_dir(&shared).unwrap();
        std::fs::set_permissions(&shared, std::fs::Permissions::from_mode(0o1777)).unwrap();
        let error = prepare(&shared).unwrap_err().to_string();
        assert!(error.contains("writable by others"), "{error}");
        let mode = std::fs::metadata(&shared).unwrap().permissions().mode() & 0o7777;
        assert_eq!(mode, 0o1777);
        // A new one is created for the owner only; an existing private one is used as it is.
        let own = dir.path().join("a").join("state");
        prepare(&own).unwrap();
        assert_eq!(
            std::fs::metadata(&own).unwrap().permissions().mode() & 0o7777,
            0o700
        );
        std::fs::set_permissions(&own, std::fs::Permissions::from_mode(0o750)).unwrap();
        prepare(&own).unwrap();
        assert_eq!(
            std::fs::metadata(&own).unwrap().permissions().mode() & 0o7777,
            0o750
        );
    }
}
