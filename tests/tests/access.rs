//! Access: what a running service leaves on the machine is not writable by other users — its
//! state directory (owner only) and iceoryx2's shared memory and management files (owner only;
//! iceoryx2's one global id counter excepted). The permission model is in README.md.

use std::os::unix::fs::MetadataExt;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};

use hexacomp_client::DeployOutcome;
use hexacomp_tests::{ServiceProcess, save_smooth_model, unique_instance};

/// Files and directories under `dir` (recursively) owned by `uid`, with their modes. Symbolic
/// links are left out: their own mode is always 0777 and means nothing (what they point to is
/// listed where it is).
fn owned_entries(dir: &Path, uid: u32, keep: &dyn Fn(&Path) -> bool) -> Vec<(PathBuf, u32, bool)> {
    let mut found = Vec::new();
    let Ok(entries) = std::fs::read_dir(dir) else {
        return found;
    };
    for entry in entries.flatten() {
        let path = entry.path();
        // Entries of other tests' processes may vanish while we look.
        let Ok(meta) = std::fs::symlink_metadata(&path) else {
            continue;
        };
        if meta.uid() == uid && !meta.file_type().is_symlink() && keep(&path) {
            found.push((path.clone(), meta.mode() & 0o7777, meta.is_dir()));
        }
        if meta.is_dir() {
            found.extend(owned_entries(&path, uid, keep));
        }
    }
    found
}

#[test]
fn state_directory_and_shared_memory_are_not_writable_by_other_users() {
    let dir = tempfile::tempdir().unwrap();
    let state = dir.path().join("state");
    // The service creates its state directory for its owner only (one that others may write
    // to is refused: `persisted_state.rs`).
    let (_, model) = save_smooth_model(dir.path(), 41);
    let instance = unique_instance("access");
    let service = ServiceProcess::with_model(&instance, &state, &model);
    let mut client = service.client().unwrap();
    let outcome = client.deploy(&std::fs::read(&model).unwrap()).unwrap();
    assert!(
        matches!(outcome, DeployOutcome::Accepted { generation: 2, .. }),
        "{outcome:?}"
    );

    let state_mode = std::fs::metadata(&state).unwrap().mode() & 0o777;
    assert_eq!(state_mode, 0o700, "state directory mode {state_mode:o}");
    let uid = unsafe { libc::geteuid() };
    let persisted = owned_entries(&state, uid, &|_| true);
    assert!(
        persisted.len() >= 2,
        "model and generation files: {persisted:?}"
    );
    for (path, mode, _) in &persisted {
        assert_eq!(mode & 0o022, 0, "{} mode {mode:o}", path.display());
    }

    // iceoryx2's files while the service and a client run: shared memory in /dev/shm, node
    // and service records under /tmp/iceoryx2.
    let iceoryx = |p: &Path| {
        p.file_name()
            .and_then(|n| n.to_str())
            .is_some_and(|n| n.starts_with("iox2_") && !n.ends_with(".global_mgmt"))
    };
    let mut files = owned_entries(Path::new("/dev/shm"), uid, &iceoryx);
    files.extend(owned_entries(Path::new("/tmp/iceoryx2"), uid, &|_| true));
    let shared_memory = files
        .iter()
        .filter(|(p, _, _)| p.starts_with("/dev/shm"))
        .count();
    assert!(shared_memory >= 3, "the service's shared memory: {files:?}");
    for (path, mode, is_dir) in &files {
        if *is_dir {
            assert_eq!(mode & 0o022, 0, "{} mode {mode:o}", path.display());
        } else {
            assert_eq!(mode & 0o077, 0, "{} mode {mode:o}", path.display());
        }
    }
    eprintln!(
        "checked {} persisted files and {} iceoryx2 entries ({shared_memory} shared-memory \
         segments)",
        persisted.len(),
        files.len()
    );
}

#[test]
fn a_service_whose_iceoryx2_root_belongs_to_another_user_says_so() {
    // SAFETY: geteuid has no preconditions.
    if unsafe { libc::geteuid() } != 0 {
        eprintln!("skipped: needs root, to run the service as another user");
        return;
    }
    let user = hexacomp_tests::linuxcnc::LINUXCNC_USER;
    let (uid, gid) = hexacomp_tests::linuxcnc::user_ids(user);
    // A directory the other user can reach, holding the service and an iceoryx2 configuration
    // (read from the working directory) whose root belongs to root, 0750, as iceoryx2 leaves
    // it for the user that came first.
    let dir = tempfile::tempdir().unwrap();
    std::fs::set_permissions(
        dir.path(),
        std::os::unix::fs::PermissionsExt::from_mode(0o755),
    )
    .unwrap();
    let root = dir.path().join("iceoryx2");
    std::fs::create_dir(&root).unwrap();
    std::fs::set_permissions(&root, std::os::unix::fs::PermissionsExt::from_mode(0o750)).unwrap();
    let work = dir.path().join("work");
    std::fs::create_dir_all(work.join("config")).unwrap();
    std::fs::write(
        work.join("config/iceoryx2.toml"),
        format!("[global]\nroot-path = \"{}/\"\n", root.display()),
    )
    .unwrap();
    let service = work.join("hexacomp-service");
    std::fs::copy(hexacomp_tests::binary("hexacomp-service"), &service).unwrap();
    std::os::unix::fs::chown(&work, Some(uid), Some(gid)).unwrap();
    std::os::unix::fs::chown(&service, Some(uid), Some(gid)).unwrap();
    let output = std::process::Command::new(&service)
        .args([
            "--instance",
            &unique_instance("root"),
            "--state-dir",
            "state",
        ])
        .current_dir(&work)
        .env("HOME", &work)
        .uid(uid)
        .gid(gid)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains(&format!(
            "iceoryx2's root {}/ belongs to user 0 and this process runs as user {uid}",
            root.display()
        )),
        "{stderr}"
    );
}
