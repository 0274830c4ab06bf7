//! Files replaced whole or not at all, and still in place after a power loss.
//!
//! The new content goes to a temporary file beside the target, which is flushed to disk and
//! renamed over the target; then the directory itself is flushed, because the rename lives in the
//! directory: without that, after a power loss the rename can be gone and the old file back (as
//! databases do it, e.g. SQLite's and PostgreSQL's `fsync` of the directory after a rename).

use std::io::Write;
use std::path::Path;

/// Replaces the file at `path` with `bytes`: whole or not at all, durable once this returns.
/// The temporary file is `.<name>.tmp` in the same directory, created anew (one left by a crash
/// is removed first; a symbolic link planted there is removed, never followed) and removed again
/// if writing or renaming fails.
pub fn replace_file(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let name = path
        .file_name()
        .ok_or_else(|| std::io::Error::other("the path names no file"))?;
    let temporary = path.with_file_name(format!(".{}.tmp", name.to_string_lossy()));
    if std::fs::symlink_metadata(&temporary).is_ok_and(|m| !m.is_dir()) {
        std::fs::remove_file(&temporary)?;
    }
    let written = (|| {
        let mut file = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&temporary)?;
        file.write_all(bytes)?;
        file.sync_all()?;
        std::fs::rename(&temporary, path)
    })();
    if written.is_err() {
        let _ = std::fs::remove_file(&temporary);
    }
    written?;
    sync_directory_of(path)
}

/// Flushes the directory that holds `path` (its entries: creations, renames) to disk.
pub fn sync_directory_of(path: &Path) -> std::io::Result<()> {
    let directory = match path.parent() {
        Some(parent) if !parent.as_os_str().is_empty() => parent,
        _ => Path::new("."),
    };
    std::fs::File::open(directory)?.sync_all()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_file_is_replaced_whole_and_no_temporary_is_left() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("model.hxm");
        replace_file(&path, b"first").unwrap();
        replace_file(&path, b"second, longer").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"second, longer");
        let names: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, ["model.hxm"]);
    }

    #[test]
    fn a_temporary_that_cannot_be_created_leaves_the_old_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("generation");
        replace_file(&path, b"1").unwrap();
        // The temporary's place is taken by a directory: creating it fails.
        std::fs::create_dir(dir.path().join(".generation.tmp")).unwrap();
        assert!(replace_file(&path, b"2").is_err());
        assert_eq!(std::fs::read(&path).unwrap(), b"1");
    }

    #[test]
    fn a_failed_rename_removes_the_temporary() {
        let dir = tempfile::tempdir().unwrap();
        // The target is a directory that is not empty: renaming a file over it fails.
        let path = dir.path().join("model.hxm");
        std::fs::create_dir(&path).unwrap();
        std::fs::write(path.join("inside"), b"x").unwrap();
        assert!(replace_file(&path, b"new").is_err());
        assert!(!dir.path().join(".model.hxm.tmp").exists());
        assert!(path.join("inside").exists());
    }

    #[test]
    fn a_leftover_temporary_or_planted_link_is_replaced_not_followed() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("model.hxm");
        let elsewhere = dir.path().join("elsewhere");
        std::fs::write(&elsewhere, b"not to be touched").unwrap();
        std::os::unix::fs::symlink(&elsewhere, dir.path().join(".model.hxm.tmp")).unwrap();
        replace_file(&path, b"new").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"new");
        assert_eq!(std::fs::read(&elsewhere).unwrap(), b"not to be touched");
    }
}
