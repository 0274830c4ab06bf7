//! Files and folders replaced whole or not at all, and still in place after a power loss.
//!
//! New content goes to a temporary beside the target (same directory, so same file system), which
//! is flushed to disk and renamed over the target; then the directory itself is flushed, because
//! the rename lives in the directory: without that, after a power loss the rename can be gone and
//! the old file back (as databases do it, e.g. SQLite's and PostgreSQL's `fsync` of the directory
//! after a rename). A temporary that is dropped before it is committed — an error, a panic — is
//! removed; one left by a kill is a hidden `.<name>.<random>.tmp` beside the target, never the
//! target itself.
//!
//! Temporaries are created exclusively under a fresh random name (`O_EXCL`), so two writers of the
//! same target never write into each other's temporary and a planted symbolic link is never
//! followed. They are created as an ordinary file or folder would be (`0666` and `0777` less the
//! umask), so the result is as readable as before.

use std::io::{BufWriter, Write};
use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};

use tempfile::{NamedTempFile, TempDir};

/// The directory that holds `path` (`.` for a bare file name).
fn parent_of(path: &Path) -> &Path {
    match path.parent() {
        Some(parent) if !parent.as_os_str().is_empty() => parent,
        _ => Path::new("."),
    }
}

/// The temporary's name prefix for `path`: `.<name>.`.
fn temporary_prefix(path: &Path) -> std::io::Result<String> {
    let name = path
        .file_name()
        .ok_or_else(|| std::io::Error::other("the path names no file"))?;
    Ok(format!(".{}.", name.to_string_lossy()))
}

/// A file being written: nothing appears at the target until [`NewFile::commit`], which replaces
/// the target whole and durably. Dropped uncommitted, the temporary is removed and the target is
/// untouched.
pub struct NewFile {
    target: PathBuf,
    file: BufWriter<NamedTempFile>,
}

impl NewFile {
    /// Starts writing the file at `path` (created or replaced on commit).
    pub fn create(path: &Path) -> std::io::Result<Self> {
        let file = tempfile::Builder::new()
            .prefix(&temporary_prefix(path)?)
            .suffix(".tmp")
            .permissions(std::fs::Permissions::from_mode(0o666))
            .tempfile_in(parent_of(path))?;
        Ok(Self {
            target: path.to_path_buf(),
            file: BufWriter::new(file),
        })
    }

    /// Flushes the content to disk, renames it over the target and flushes the directory.
    pub fn commit(self) -> std::io::Result<()> {
        let file = self.file.into_inner().map_err(|e| e.into_error())?;
        file.as_file().sync_all()?;
        file.persist(&self.target).map_err(|e| e.error)?;
        sync_directory_of(&self.target)
    }
}

impl Write for NewFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.file.write(buf)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.file.flush()
    }
}

/// Replaces the file at `path` with `bytes`: whole or not at all, durable once this returns.
pub fn replace_file(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let mut file = NewFile::create(path)?;
    file.write_all(bytes)?;
    file.commit()
}

/// A folder being filled: files are written into a temporary folder beside the target
/// ([`NewDirectory::path`]), and [`NewDirectory::commit`] puts it in the target's place in one
/// step (the old folder, if any, is exchanged atomically and then removed). Dropped uncommitted,
/// the temporary folder and everything in it are removed and the target is untouched.
pub struct NewDirectory {
    target: PathBuf,
    staging: TempDir,
}

impl NewDirectory {
    /// Starts filling the folder at `path` (created, or replaced as a whole, on commit). A
    /// symbolic link at `path` is resolved: the folder it points to is the one replaced.
    pub fn create(path: &Path) -> std::io::Result<Self> {
        let target = match std::fs::symlink_metadata(path) {
            Ok(meta) if meta.file_type().is_symlink() => std::fs::canonicalize(path)?,
            _ => path.to_path_buf(),
        };
        let staging = tempfile::Builder::new()
            .prefix(&temporary_prefix(&target)?)
            .suffix(".tmp")
            .permissions(std::fs::Permissions::from_mode(0o777))
            .tempdir_in(parent_of(&target))?;
        Ok(Self { target, staging })
    }

    /// The temporary folder to write the new files into.
    pub fn path(&self) -> &Path {
        self.staging.path()
    }

    /// Flushes the new folder and puts it in the target's place: an existing target is exchanged
    /// with it in one `renameat2(RENAME_EXCHANGE)` and then removed, so that at every moment the
    /// target is either the whole old folder or the whole new one.
    pub fn commit(self) -> std::io::Result<()> {
        std::fs::File::open(self.staging.path())?.sync_all()?;
        if std::fs::symlink_metadata(&self.target).is_ok() {
            rustix::fs::renameat_with(
                rustix::fs::CWD,
                self.staging.path(),
                rustix::fs::CWD,
                &self.target,
                rustix::fs::RenameFlags::EXCHANGE,
            )?;
            sync_directory_of(&self.target)?;
            // The staging path now holds the old folder: dropping it removes it.
            self.staging.close()
        } else {
            let staging = self.staging.keep();
            if let Err(e) = std::fs::rename(&staging, &self.target) {
                let _ = std::fs::remove_dir_all(&staging);
                return Err(e);
            }
            sync_directory_of(&self.target)
        }
    }
}

/// Flushes the directory that holds `path` (its entries: creations, renames) to disk.
pub fn sync_directory_of(path: &Path) -> std::io::Result<()> {
    std::fs::File::open(parent_of(path))?.sync_all()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(dir: &Path) -> Vec<String> {
        let mut names: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        names
    }

    #[test]
    fn a_file_is_replaced_whole_and_no_temporary_is_left() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("model.hxm");
        replace_file(&path, b"first").unwrap();
        replace_file(&path, b"second, longer").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"second, longer");
        assert_eq!(names(dir.path()), ["model.hxm"]);
    }

    #[test]
    fn a_new_file_and_folder_get_the_permissions_the_umask_gives() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("plain");
        std::fs::write(&path, b"x").unwrap();
        let plain = std::fs::metadata(&path).unwrap().permissions().mode() & 0o777;
        let replaced = dir.path().join("replaced");
        replace_file(&replaced, b"x").unwrap();
        let mode = std::fs::metadata(&replaced).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, plain);
        let folder = dir.path().join("folder");
        NewDirectory::create(&folder).unwrap().commit().unwrap();
        let plain_folder = dir.path().join("plain-folder");
        std::fs::create_dir(&plain_folder).unwrap();
        let mode_of = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode_of(&folder), mode_of(&plain_folder));
    }

    #[test]
    fn a_file_dropped_uncommitted_leaves_the_old_file_and_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.csv");
        replace_file(&path, b"old").unwrap();
        let mut file = NewFile::create(&path).unwrap();
        file.write_all(b"half a new fi").unwrap();
        drop(file);
        assert_eq!(std::fs::read(&path).unwrap(), b"old");
        assert_eq!(names(dir.path()), ["out.csv"]);
    }

    #[test]
    fn a_temporary_that_cannot_be_created_leaves_the_old_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("missing").join("generation");
        assert!(replace_file(&path, b"2").is_err());
        assert_eq!(names(dir.path()), Vec::<String>::new());
    }

    #[test]
    fn a_failed_rename_removes_the_temporary() {
        let dir = tempfile::tempdir().unwrap();
        // The target is a directory that is not empty: renaming a file over it fails.
        let path = dir.path().join("model.hxm");
        std::fs::create_dir(&path).unwrap();
        std::fs::write(path.join("inside"), b"x").unwrap();
        assert!(replace_file(&path, b"new").is_err());
        assert_eq!(names(dir.path()), ["model.hxm"]);
        assert!(path.join("inside").exists());
    }

    #[test]
    fn a_folder_is_replaced_as_a_unit() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("calibration");
        let first = NewDirectory::create(&target).unwrap();
        replace_file(&first.path().join("a.csv"), b"1").unwrap();
        replace_file(&first.path().join("old-only.csv"), b"1").unwrap();
        first.commit().unwrap();
        assert_eq!(names(&target), ["a.csv", "old-only.csv"]);

        let second = NewDirectory::create(&target).unwrap();
        replace_file(&second.path().join("a.csv"), b"2").unwrap();
        second.commit().unwrap();
        assert_eq!(names(&target), ["a.csv"]);
        assert_eq!(std::fs::read(target.join("a.csv")).unwrap(), b"2");
        assert_eq!(names(dir.path()), ["calibration"]);
    }

    #[test]
    fn a_folder_dropped_uncommitted_leaves_the_old_folder_whole() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("calibration");
        std::fs::create_dir(&target).unwrap();
        std::fs::write(target.join("model.hxm"), b"old").unwrap();
        let new = NewDirectory::create(&target).unwrap();
        replace_file(&new.path().join("model.hxm"), b"new").unwrap();
        drop(new);
        assert_eq!(std::fs::read(target.join("model.hxm")).unwrap(), b"old");
        assert_eq!(names(dir.path()), ["calibration"]);
    }

    #[test]
    fn a_folder_behind_a_link_is_replaced_and_the_link_kept() {
        let dir = tempfile::tempdir().unwrap();
        let real = dir.path().join("real");
        std::fs::create_dir(&real).unwrap();
        std::fs::write(real.join("x"), b"old").unwrap();
        let link = dir.path().join("link");
        std::os::unix::fs::symlink(&real, &link).unwrap();
        let new = NewDirectory::create(&link).unwrap();
        replace_file(&new.path().join("x"), b"new").unwrap();
        new.commit().unwrap();
        assert!(
            std::fs::symlink_metadata(&link)
                .unwrap()
                .file_type()
                .is_symlink()
        );
        assert_eq!(std::fs::read(real.join("x")).unwrap(), b"new");
    }

    #[test]
    fn a_planted_link_is_never_followed() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("model.hxm");
        let elsewhere = dir.path().join("elsewhere");
        std::fs::write(&elsewhere, b"not to be touched").unwrap();
        // Whatever name an attacker guesses, the temporary is created exclusively.
        for guess in [".model.hxm.tmp", ".model.hxm.000000.tmp"] {
            std::os::unix::fs::symlink(&elsewhere, dir.path().join(guess)).unwrap();
        }
        replace_file(&path, b"new").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"new");
        assert_eq!(std::fs::read(&elsewhere).unwrap(), b"not to be touched");
    }
}
