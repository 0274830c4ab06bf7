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
///
/// A symbolic link at the target is followed: the file it points to is replaced, the link kept.
/// A target that exists and is not a regular file (`/dev/stdout`, `/dev/null`, a FIFO) is written
/// in place: a stream has no old content to keep, and replacing the device node would be wrong.
/// A replaced file keeps its permission bits; a new one gets `0666` less the umask.
pub struct NewFile {
    target: PathBuf,
    output: Output,
}

/// Where a [`NewFile`]'s bytes go.
enum Output {
    /// A temporary beside the regular file it replaces on commit.
    Replacing(BufWriter<NamedTempFile>),
    /// A stream written in place.
    Stream(BufWriter<std::fs::File>),
}

impl NewFile {
    /// Starts writing the file at `path` (created or replaced on commit).
    pub fn create(path: &Path) -> std::io::Result<Self> {
        if is_descriptor_path(path) {
            // `/dev/stdout` and the like name a descriptor the caller was given (a pipe, a
            // terminal, a file opened by the shell with `>>`): written in place, appending, so
            // that a log the shell opened for appending is not written over from its start.
            let stream = std::fs::OpenOptions::new().append(true).open(path)?;
            return Ok(Self::stream(path, stream));
        }
        let target = follow_links(path)?;
        let existing = std::fs::metadata(&target).ok();
        if let Some(meta) = existing.as_ref().filter(|m| !m.is_file()) {
            if meta.is_dir() {
                return Err(std::io::Error::other("is a folder, not a file"));
            }
            let stream = std::fs::OpenOptions::new().write(true).open(&target)?;
            return Ok(Self::stream(&target, stream));
        }
        let mode = match &existing {
            Some(meta) if meta.permissions().mode() & 0o222 == 0 => {
                return Err(std::io::Error::new(
                    std::io::ErrorKind::PermissionDenied,
                    "the file is read-only: it is not replaced",
                ));
            }
            Some(meta) => meta.permissions().mode() & 0o777,
            None => 0o666,
        };
        let file = tempfile::Builder::new()
            .prefix(&temporary_prefix(&target)?)
            .suffix(".tmp")
            .permissions(std::fs::Permissions::from_mode(mode))
            .tempfile_in(parent_of(&target))?;
        if existing.is_some() {
            // The umask applied at creation; a replaced file keeps exactly its old mode.
            file.as_file()
                .set_permissions(std::fs::Permissions::from_mode(mode))?;
        }
        Ok(Self {
            target,
            output: Output::Replacing(BufWriter::new(file)),
        })
    }

    fn stream(path: &Path, file: std::fs::File) -> Self {
        Self {
            target: path.to_path_buf(),
            output: Output::Stream(BufWriter::new(file)),
        }
    }

    /// Flushes the content to disk, renames it over the target and flushes the directory (for a
    /// stream: flushes it).
    pub fn commit(self) -> std::io::Result<()> {
        match self.output {
            Output::Stream(mut stream) => stream.flush(),
            Output::Replacing(file) => {
                let file = file.into_inner().map_err(|e| e.into_error())?;
                file.as_file().sync_all()?;
                file.persist(&self.target).map_err(|e| e.error)?;
                sync_directory_of(&self.target)
            }
        }
    }
}

impl Write for NewFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        match &mut self.output {
            Output::Replacing(file) => file.write(buf),
            Output::Stream(stream) => stream.write(buf),
        }
    }

    fn flush(&mut self) -> std::io::Result<()> {
        match &mut self.output {
            Output::Replacing(file) => file.flush(),
            Output::Stream(stream) => stream.flush(),
        }
    }
}

/// Whether `path` names a file descriptor of the process rather than a file: `/dev/stdout`,
/// `/dev/stderr`, `/dev/fd/N`, `/proc/self/fd/N`.
fn is_descriptor_path(path: &Path) -> bool {
    path == Path::new("/dev/stdout")
        || path == Path::new("/dev/stderr")
        || path.starts_with("/dev/fd")
        || path.starts_with("/proc/self/fd")
}

/// The file `path` finally names, following symbolic links one at a time (a dangling link names
/// the file it would point to, which is then created).
fn follow_links(path: &Path) -> std::io::Result<PathBuf> {
    let mut current = path.to_path_buf();
    for _ in 0..40 {
        match std::fs::symlink_metadata(&current) {
            Ok(meta) if meta.file_type().is_symlink() => {
                let next = std::fs::read_link(&current)?;
                current = if next.is_absolute() {
                    next
                } else {
                    parent_of(&current).join(next)
                };
            }
            _ => return Ok(current),
        }
    }
    Err(std::io::Error::other("too many levels of symbolic links"))
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
    /// symbolic link at `path` is followed as [`NewFile`] follows one: the folder it points to is
    /// the one replaced, the link kept.
    pub fn create(path: &Path) -> std::io::Result<Self> {
        let target = follow_links(path)?;
        if target.file_name().is_none() || target.ends_with(".") {
            return Err(std::io::Error::other(
                "names no folder of its own (such as `.` or `..`): give the folder by name",
            ));
        }
        if std::fs::metadata(&target).is_ok_and(|m| !m.is_dir()) {
            return Err(std::io::Error::other("exists and is not a folder"));
        }
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
    ///
    /// An error means the target was not replaced. Once it is, what follows cannot undo it: a
    /// failure to flush the directory or to remove the old folder is returned as `Ok(Some(_))`,
    /// a warning to pass on (the new folder is in place).
    pub fn commit(self) -> std::io::Result<Option<String>> {
        std::fs::File::open(self.staging.path())?.sync_all()?;
        let replaced = std::fs::symlink_metadata(&self.target).is_ok();
        if replaced {
            rustix::fs::renameat_with(
                rustix::fs::CWD,
                self.staging.path(),
                rustix::fs::CWD,
                &self.target,
                rustix::fs::RenameFlags::EXCHANGE,
            )?;
        } else {
            std::fs::rename(self.staging.path(), &self.target)?;
        }
        let mut warnings = Vec::new();
        if let Err(e) = sync_directory_of(&self.target) {
            warnings.push(format!(
                "the folder's parent could not be flushed to disk: {e}"
            ));
        }
        // After an exchange the staging path holds the old folder; after a rename it is gone.
        let old = self.staging.keep();
        if replaced && let Err(e) = std::fs::remove_dir_all(&old) {
            warnings.push(format!(
                "the previous folder, now at {}, could not be removed: {e}",
                old.display()
            ));
        }
        Ok((!warnings.is_empty()).then(|| warnings.join("; ")))
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
        assert_eq!(
            NewDirectory::create(&folder).unwrap().commit().unwrap(),
            None
        );
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
        assert_eq!(first.commit().unwrap(), None);
        assert_eq!(names(&target), ["a.csv", "old-only.csv"]);

        let second = NewDirectory::create(&target).unwrap();
        replace_file(&second.path().join("a.csv"), b"2").unwrap();
        assert_eq!(second.commit().unwrap(), None);
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
        assert_eq!(new.commit().unwrap(), None);
        assert!(
            std::fs::symlink_metadata(&link)
                .unwrap()
                .file_type()
                .is_symlink()
        );
        assert_eq!(std::fs::read(real.join("x")).unwrap(), b"new");
    }

    #[test]
    fn a_stream_is_written_in_place_and_a_link_to_a_file_is_followed() {
        let dir = tempfile::tempdir().unwrap();
        // /dev/null stays the device (it would become a plain file if renamed over).
        replace_file(Path::new("/dev/null"), b"into the void").unwrap();
        assert!(!std::fs::metadata("/dev/null").unwrap().is_file());
        let real = dir.path().join("v3.hxm");
        std::fs::write(&real, b"old").unwrap();
        std::fs::set_permissions(&real, std::fs::Permissions::from_mode(0o640)).unwrap();
        let link = dir.path().join("model.hxm");
        std::os::unix::fs::symlink("v3.hxm", &link).unwrap();
        replace_file(&link, b"new").unwrap();
        assert!(std::fs::symlink_metadata(&link).unwrap().is_symlink());
        assert_eq!(std::fs::read(&real).unwrap(), b"new");
        let mode = std::fs::metadata(&real).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o640, "a replaced file keeps its permissions");
    }

    #[test]
    fn a_dangling_link_creates_its_target_and_a_read_only_file_is_not_replaced() {
        let dir = tempfile::tempdir().unwrap();
        let link = dir.path().join("latest.csv");
        std::os::unix::fs::symlink("run42.csv", &link).unwrap();
        replace_file(&link, b"42").unwrap();
        assert_eq!(std::fs::read(dir.path().join("run42.csv")).unwrap(), b"42");
        assert!(std::fs::symlink_metadata(&link).unwrap().is_symlink());
        let locked = dir.path().join("locked.csv");
        std::fs::write(&locked, b"keep").unwrap();
        std::fs::set_permissions(&locked, std::fs::Permissions::from_mode(0o444)).unwrap();
        let error = replace_file(&locked, b"new").unwrap_err();
        assert_eq!(error.kind(), std::io::ErrorKind::PermissionDenied);
        assert_eq!(std::fs::read(&locked).unwrap(), b"keep");
    }

    #[test]
    fn a_folder_target_that_is_a_file_or_dot_is_refused_at_once() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("cal");
        std::fs::write(&file, b"x").unwrap();
        let message = |path: &Path| NewDirectory::create(path).err().unwrap().to_string();
        assert!(message(&file).contains("not a folder"));
        assert!(message(Path::new(".")).contains("give the folder by name"));
        assert!(message(&dir.path().join("sub/..")).contains("give the folder by name"));
        assert_eq!(std::fs::read(&file).unwrap(), b"x");
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
