//! What the state directory holds after the service's refusals, and what a start makes of a
//! state directory it did not write: a refused second service changes nothing, a start model is
//! numbered after the persisted generations, a generation file without a number or at the end of
//! the numbers is refused by name, and a shared directory is refused and left as it was.

use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use hexacomp_client::DeployOutcome;
use hexacomp_tests::{ServiceProcess, binary, path_str, save_smooth_model, unique_instance};

/// Starts the service and expects it to refuse to start: its output once it exited (within
/// 30 s; a service that serves instead is killed and the test fails).
fn refused_start(args: &[&str]) -> Output {
    let mut child = Command::new(binary("hexacomp-service"))
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(30);
    while child.try_wait().unwrap().is_none() {
        if Instant::now() > deadline {
            let _ = child.kill();
            let output = child.wait_with_output().unwrap();
            panic!(
                "the service started instead of refusing:\n{}",
                String::from_utf8_lossy(&output.stderr)
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let output = child.wait_with_output().unwrap();
    assert_eq!(
        output.status.code(),
        Some(1),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    output
}

fn deploy(service: &ServiceProcess, model: &Path) -> DeployOutcome {
    let bytes = std::fs::read(model).unwrap();
    service.client().unwrap().deploy(&bytes).unwrap()
}

/// A state directory in which a service served `model` as generation 1 and accepted it again
/// as generation 2, then stopped: (its temporary directory, the state directory, the instance,
/// the model file).
fn two_generations_persisted(test: &str) -> (tempfile::TempDir, PathBuf, String, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let state = dir.path().join("state");
    let instance = unique_instance(test);
    let (_, model) = save_smooth_model(dir.path(), 1);
    let service = ServiceProcess::with_model(&instance, &state, &model);
    assert!(matches!(
        deploy(&service, &model),
        DeployOutcome::Accepted { generation: 2, .. }
    ));
    service.stop_with(libc::SIGTERM);
    (dir, state, instance, model)
}

#[test]
fn a_refused_second_service_changes_nothing_in_the_state_directory() {
    let dir = tempfile::tempdir().unwrap();
    let state = dir.path().join("state");
    let instance = unique_instance("second");
    let (_, first) = save_smooth_model(dir.path(), 1);
    let other = dir.path().join("other.hxm");
    hexacomp_tests::smooth_model(2).save(&other).unwrap();
    let service = ServiceProcess::with_model(&instance, &state, &first);
    for _ in 0..2 {
        assert!(matches!(
            deploy(&service, &first),
            DeployOutcome::Accepted { .. }
        ));
    }
    let before = std::fs::read(state.join("model.hxm")).unwrap();
    let output = refused_start(&[
        "--instance",
        &instance,
        "--state-dir",
        path_str(&state),
        "--model",
        path_str(&other),
    ]);
    let message = String::from_utf8_lossy(&output.stderr);
    assert!(message.contains("already served"), "{message}");
    assert!(
        std::fs::read(state.join("model.hxm")).unwrap() == before,
        "the refused service replaced the persisted model"
    );
    assert_eq!(
        std::fs::read_to_string(state.join("generation")).unwrap(),
        "3"
    );
    // A restart serves what the first service persisted, under its number.
    let (status, _) = service.stop_with(libc::SIGTERM);
    assert!(status.success());
    let restarted = ServiceProcess::start(&instance, &["--state-dir", path_str(&state)]);
    assert_eq!(restarted.client().unwrap().status().unwrap().generation, 3);
}

#[test]
fn a_start_model_is_numbered_after_the_persisted_generations() {
    let (_dir, state, instance, model) = two_generations_persisted("startnumber");
    let service = ServiceProcess::with_model(&instance, &state, &model);
    assert_eq!(service.client().unwrap().status().unwrap().generation, 3);
    assert_eq!(
        std::fs::read_to_string(state.join("generation")).unwrap(),
        "3"
    );
}

#[test]
fn a_generation_file_without_a_number_is_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let state = dir.path().join("state");
    let instance = unique_instance("garbage");
    let (_, model) = save_smooth_model(dir.path(), 1);
    ServiceProcess::with_model(&instance, &state, &model).stop_with(libc::SIGTERM);
    // Written over what the link points to: the file the service reads.
    std::fs::write(state.join("generation"), "garbage").unwrap();
    let output = refused_start(&["--instance", &instance, "--state-dir", path_str(&state)]);
    let message = String::from_utf8_lossy(&output.stderr);
    assert!(
        message.contains(
            &state
                .join("current")
                .join("generation")
                .display()
                .to_string()
        ) && message.contains("not a generation number"),
        "{message}"
    );
}

#[test]
fn at_the_last_generation_number_a_deploy_is_refused_and_the_model_keeps_its_number() {
    let dir = tempfile::tempdir().unwrap();
    let state = dir.path().join("state");
    let instance = unique_instance("lastnumber");
    let (_, model) = save_smooth_model(dir.path(), 1);
    ServiceProcess::with_model(&instance, &state, &model).stop_with(libc::SIGTERM);
    std::fs::write(state.join("generation"), u64::MAX.to_string()).unwrap();
    let service = ServiceProcess::start(&instance, &["--state-dir", path_str(&state)]);
    match deploy(&service, &model) {
        DeployOutcome::Refused { reason, generation } => {
            assert!(reason.contains("exhausted"), "{reason}");
            assert_eq!(generation, u64::MAX);
        }
        accepted => panic!("expected a refusal, got {accepted:?}"),
    }
    assert_eq!(
        service.client().unwrap().status().unwrap().generation,
        u64::MAX
    );
    let answer = service
        .client()
        .unwrap()
        .compensate_pose([0.0, 0.0, 280.0, 0.0, 0.0, 0.0])
        .unwrap();
    assert_eq!(answer.generation, u64::MAX);
}

#[test]
fn a_shared_state_directory_is_refused_and_left_as_it_was() {
    let dir = tempfile::tempdir().unwrap();
    let shared = dir.path().join("shared");
    std::fs::create_dir(&shared).unwrap();
    std::fs::set_permissions(&shared, std::fs::Permissions::from_mode(0o1777)).unwrap();
    let output = refused_start(&[
        "--instance",
        &unique_instance("shared"),
        "--state-dir",
        path_str(&shared),
    ]);
    let message = String::from_utf8_lossy(&output.stderr);
    assert!(message.contains("writable by others"), "{message}");
    let mode = std::fs::metadata(&shared).unwrap().permissions().mode() & 0o7777;
    assert_eq!(mode, 0o1777, "the shared directory's mode was changed");
}

#[test]
fn after_an_ignored_persisted_model_deploys_are_numbered_after_its_number() {
    let (_dir, state, instance, model) = two_generations_persisted("ignorednumber");
    // Damaged (written through the link, into the current generation's file): ignored.
    std::fs::write(state.join("model.hxm"), b"not a model").unwrap();
    let service = ServiceProcess::start(&instance, &["--state-dir", path_str(&state)]);
    assert_eq!(service.client().unwrap().status().unwrap().generation, 0);
    assert!(
        service.log().contains("ignoring the persisted model"),
        "{}",
        service.log()
    );
    match deploy(&service, &model) {
        DeployOutcome::Accepted { generation, .. } => assert_eq!(generation, 3),
        refused => panic!("{refused:?}"),
    }
}
