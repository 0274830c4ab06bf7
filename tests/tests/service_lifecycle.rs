//! The service's life outside serving: what it does with a persisted model it cannot use, a
//! `--model` that validation refuses, SIGTERM and SIGINT, its log (plain text in a file, at the
//! level `RUST_LOG` names), readiness and log priorities under systemd, and `--client-budget 0`.

use std::path::Path;

use std::time::{Duration, Instant};

use hexacomp_client::wire::{
    MAX_BATCH, MAX_REQUESTS_IN_FLIGHT, PROTOCOL_VERSION, PointRequest, RequestHeader, RequestKind,
    RequestOutcome,
};
use hexacomp_client::{Error, PointStatus};
use hexacomp_core::Geometry;
use hexacomp_tests::{
    ServiceProcess, binary, path_str, raw_client, save_smooth_model, smooth_model, unique_instance,
};

/// The prototype with its base 1 mm wider: another geometry fingerprint.
fn other_geometry() -> Geometry {
    let mut g = Geometry::prototype();
    g.name = "other".into();
    for joint in &mut g.base_joints {
        joint.x *= 1.001;
    }
    g
}

#[test]
fn a_damaged_or_foreign_persisted_model_is_ignored_with_a_warning_and_not_served() {
    let dir = tempfile::tempdir().unwrap();
    let instance = unique_instance("restore");
    let state = dir.path().join("state");
    let (_, model) = save_smooth_model(dir.path(), 3);
    // A first run persists the model as generation 1.
    let service = ServiceProcess::with_model(&instance, &state, &model);
    assert_eq!(service.client().unwrap().status().unwrap().generation, 1);
    service.kill();
    let persisted = state.join("model.hxm");
    let good = std::fs::read(&persisted).unwrap();

    let mut damaged = good.clone();
    damaged[60] ^= 0x01;
    let mut foreign = smooth_model(3);
    foreign.geometry = other_geometry().fingerprint();
    for (bytes, why) in [
        (damaged, "checksum mismatch"),
        (foreign.to_bytes(), "trained for geometry"),
    ] {
        std::fs::write(&persisted, &bytes).unwrap();
        let service = ServiceProcess::start(&instance, &["--state-dir", path_str(&state)]);
        let mut client = service.client().unwrap();
        assert_eq!(client.status().unwrap().generation, 0);
        let point = client
            .compensate_pose([0.0, 0.0, 280.0, 0.0, 0.0, 0.0])
            .unwrap();
        assert_eq!(point.status, PointStatus::NoModel);
        let log = service.log();
        assert!(
            log.contains("ignoring the persisted model") && log.contains(why),
            "{log}"
        );
        service.kill();
        // The file is left as it was, for the user to look at.
        assert_eq!(std::fs::read(&persisted).unwrap(), bytes);
    }
}

#[test]
fn a_model_that_validation_refuses_stops_the_start_with_the_reason() {
    let dir = tempfile::tempdir().unwrap();
    let state = dir.path().join("state");
    let mut foreign = smooth_model(4);
    foreign.geometry = other_geometry().fingerprint();
    let path = dir.path().join("foreign.hxm");
    foreign.save(&path).unwrap();
    let output = std::process::Command::new(binary("hexacomp-service"))
        .args(["--instance", &unique_instance("badmodel")])
        .args(["--state-dir", path_str(&state), "--model", path_str(&path)])
        .output()
        .unwrap();
    let message = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(1), "{message}");
    assert!(
        message.contains(&format!("{}: refused: ", path.display()))
            && message.contains("trained for geometry"),
        "{message}"
    );
    // Nothing was persisted for a later start to pick up.
    assert!(!state.join("model.hxm").exists());
}

#[test]
fn sigterm_and_sigint_stop_the_service_cleanly_and_the_instance_can_start_again() {
    let dir = tempfile::tempdir().unwrap();
    let instance = unique_instance("signal");
    let state = dir.path().join("state");
    let (_, model) = save_smooth_model(dir.path(), 5);
    let mut service = ServiceProcess::with_model(&instance, &state, &model);
    for signal in [libc::SIGTERM, libc::SIGINT] {
        let mut client = service.client().unwrap();
        client
            .compensate_pose([0.0, 0.0, 280.0, 0.0, 0.0, 0.0])
            .unwrap();
        let (status, log) = service.stop_with(signal);
        assert_eq!(status.code(), Some(0), "signal {signal}: {status}\n{log}");
        assert!(
            log.contains("stopped; iceoryx2 resources released"),
            "signal {signal}:\n{log}"
        );
        // Its standard error is a file, not a terminal: no colour codes in it.
        assert!(
            log.contains("INFO") && !log.contains('\u{1b}'),
            "signal {signal}: escape sequences in the log:\n{log:?}"
        );
        // The connected client times out; once it is gone, so are the endpoints: a new client
        // finds no service.
        client.set_timeout(Duration::from_millis(50));
        let stale = client.compensate_pose([0.0, 0.0, 280.0, 0.0, 0.0, 0.0]);
        assert!(matches!(stale, Err(Error::Timeout { .. })), "{stale:?}");
        drop(client);
        let absent = hexacomp_client::Client::connect(&instance, &Default::default());
        assert!(
            matches!(absent, Err(Error::ServiceAbsent { .. })),
            "{absent:?}"
        );
        // The instance starts again at once, with the persisted model.
        service = ServiceProcess::start(&instance, &["--state-dir", path_str(&state)]);
        assert_eq!(service.client().unwrap().status().unwrap().generation, 1);
    }
}

#[test]
fn rust_log_sets_the_level_and_a_value_that_names_none_is_said() {
    let dir = tempfile::tempdir().unwrap();
    let state = dir.path().join("state");
    let (_, model) = save_smooth_model(dir.path(), 5);
    let args = ["--state-dir", path_str(&state), "--model", path_str(&model)];
    // At warn, the start and the stop (info) are not logged.
    let instance = unique_instance("quiet");
    let service = ServiceProcess::start_with_env(&instance, &args, &[("RUST_LOG", "warn")]);
    let (status, log) = service.stop_with(libc::SIGTERM);
    assert_eq!(status.code(), Some(0), "{log}");
    assert!(!log.contains("INFO"), "{log}");
    // A value that is no single level: info, and said; an empty one: info.
    for (value, said) in [("hexacomp_service=debug", true), ("", false)] {
        let instance = unique_instance("loud");
        let service = ServiceProcess::start_with_env(&instance, &args, &[("RUST_LOG", value)]);
        let (status, log) = service.stop_with(libc::SIGTERM);
        assert_eq!(status.code(), Some(0), "{log}");
        assert!(log.contains("INFO"), "RUST_LOG={value:?}:\n{log}");
        assert_eq!(log.contains("is not a single level"), said, "{log}");
    }
}

/// Sends four full batches from each of two clients while the service is stopped, then lets it
/// answer them all at once, `rounds` times; counts the answers `overloaded`. Every request is
/// answered while the other client's requests wait, the case where a budget applies.
fn overloaded_while_others_wait(service: &ServiceProcess, rounds: usize) -> usize {
    let clients = [0, 1].map(|_| raw_client(&service.instance, MAX_BATCH).unwrap());
    let mut overloaded = 0;
    for _ in 0..rounds {
        service.pause();
        let pending: Vec<_> = clients
            .iter()
            .flat_map(|(_, _, client)| {
                (0..MAX_REQUESTS_IN_FLIGHT).map(|_| {
                    let mut request = client.loan_slice_uninit(MAX_BATCH).unwrap();
                    *request.user_header_mut() = RequestHeader {
                        protocol: PROTOCOL_VERSION,
                        kind: RequestKind::Poses as u32,
                    };
                    let request = request.write_from_fn(|_| PointRequest {
                        values: [0.0, 0.0, 280.0, 0.0, 0.0, 0.0],
                    });
                    request.send().unwrap()
                })
            })
            .collect();
        service.resume();
        for pending in pending {
            let deadline = Instant::now() + Duration::from_secs(10);
            let response = loop {
                if let Some(response) = pending.receive().unwrap() {
                    break response;
                }
                assert!(Instant::now() < deadline, "a request got no answer");
                std::thread::sleep(Duration::from_micros(100));
            };
            match response.user_header().outcome {
                o if o == RequestOutcome::Served as u32 => {
                    assert_eq!(response.payload().len(), MAX_BATCH)
                }
                o if o == RequestOutcome::Overloaded as u32 => overloaded += 1,
                o => panic!("outcome {o}"),
            }
        }
    }
    overloaded
}

#[test]
fn a_client_budget_of_0_never_answers_overloaded() {
    let dir = tempfile::tempdir().unwrap();
    // With a budget of 1 point per second the burst allowance (four full batches) is spent in
    // the first round: later requests are answered overloaded while the other client's wait.
    let limited = ServiceProcess::start(
        &unique_instance("budget1"),
        &[
            "--state-dir",
            path_str(&dir.path().join("a")),
            "--client-budget",
            "1",
        ],
    );
    let refused = overloaded_while_others_wait(&limited, 3);
    assert!(refused > 0, "budget 1: {refused} overloaded");
    let unlimited = ServiceProcess::start(
        &unique_instance("budget0"),
        &[
            "--state-dir",
            path_str(&dir.path().join("b")),
            "--client-budget",
            "0",
        ],
    );
    assert_eq!(overloaded_while_others_wait(&unlimited, 3), 0);
    let status = unlimited.client().unwrap().status().unwrap();
    assert_eq!(
        (status.points, status.overloaded),
        ((3 * 2 * MAX_REQUESTS_IN_FLIGHT * MAX_BATCH) as u64, 0)
    );
    eprintln!("budget 1: {refused} of 24 requests overloaded; budget 0: none");
}

#[test]
fn an_event_mode_service_without_its_wake_up_says_it_sleeps() {
    use hexacomp_client::wire::endpoints::{self, Role};
    use iceoryx2::prelude::*;
    let instance = unique_instance("nowake");
    // Another process's listener holds the wake endpoint's only listener slot: the service's
    // own listener cannot be created, and it serves by sleeping instead.
    let node = NodeBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .unwrap();
    let wake = endpoints::wake(&node, &instance, Role::Serve).unwrap();
    let _listener = wake.listener_builder().create().unwrap();
    let dir = tempfile::tempdir().unwrap();
    let state = dir.path().join("state");
    let service = ServiceProcess::start(
        &instance,
        &["--wait", "event", "--state-dir", path_str(&state)],
    );
    let mut client = service.client().unwrap();
    assert_eq!(
        client.status().unwrap().wait_mode,
        "sleep",
        "{}",
        service.log()
    );
    assert!(
        service.log().contains("serving with --wait sleep"),
        "{}",
        service.log()
    );
    // Clients are served (they do not wait for a wake-up that never comes).
    client
        .compensate_pose([0.0, 0.0, 280.0, 0.0, 0.0, 0.0])
        .unwrap();
}

/// Starts the service for `instance` as systemd would with `Type=notify`: `NOTIFY_SOCKET` names
/// `socket`, `JOURNAL_STREAM` is `journal_stream`; standard error goes to `log`; RUST_LOG=`level`.
fn start_as_under_systemd(
    instance: &str,
    state: &Path,
    socket: &Path,
    log: &Path,
    journal_stream: &str,
    level: &str,
) -> std::process::Child {
    std::process::Command::new(binary("hexacomp-service"))
        .args([
            "--instance",
            instance,
            "--state-dir",
            path_str(state),
            "--wait",
            "event",
        ])
        .env("NOTIFY_SOCKET", socket)
        .env("JOURNAL_STREAM", journal_stream)
        .env("RUST_LOG", level)
        .stdout(std::process::Stdio::null())
        .stderr(std::fs::File::create(log).unwrap())
        .spawn()
        .unwrap()
}

/// The next notification on `socket` (20 s at most).
fn next_notification(socket: &std::os::unix::net::UnixDatagram) -> String {
    let mut buffer = [0u8; 4096];
    let n = socket
        .recv(&mut buffer)
        .expect("a notification within 20 s");
    String::from_utf8_lossy(&buffer[..n]).into_owned()
}

#[test]
fn under_systemd_ready_is_notified_once_serving_and_log_lines_carry_the_journals_priorities() {
    use std::os::unix::fs::MetadataExt;
    let dir = tempfile::tempdir().unwrap();
    let socket_path = dir.path().join("notify.sock");
    let socket = std::os::unix::net::UnixDatagram::bind(&socket_path).unwrap();
    socket
        .set_read_timeout(Some(Duration::from_secs(20)))
        .unwrap();
    let log = dir.path().join("service.log");
    // The journal's stream is standard error itself, named by device and inode (the file
    // exists before the service opens it: `File::create` keeps its inode).
    std::fs::write(&log, "").unwrap();
    let metadata = std::fs::metadata(&log).unwrap();
    let stream = format!("{}:{}", metadata.dev(), metadata.ino());
    let instance = unique_instance("notify");
    // A level that names none: the warning about it is logged at warning priority.
    let mut child = start_as_under_systemd(
        &instance,
        &dir.path().join("state"),
        &socket_path,
        &log,
        &stream,
        "verbose",
    );
    let ready = next_notification(&socket);
    assert!(ready.lines().any(|l| l == "READY=1"), "{ready:?}");
    assert!(
        ready.contains(&format!("STATUS=serving instance {instance}")),
        "{ready:?}"
    );
    // Ready means serving: a client connects and is answered at once, without retrying.
    let options = hexacomp_client::ClientOptions {
        timeout: Duration::from_secs(2),
    };
    let status = hexacomp_client::status_of(&instance, &options);
    assert!(status.is_ok(), "READY=1 sent before serving: {status:?}");
    hexacomp_tests::signal_child(&child, libc::SIGTERM);
    let stopping = next_notification(&socket);
    assert!(stopping.lines().any(|l| l == "STOPPING=1"), "{stopping:?}");
    assert_eq!(child.wait().unwrap().code(), Some(0));
    let text = std::fs::read_to_string(&log).unwrap();
    assert!(
        !text.contains('\x1b'),
        "colour codes in the journal: {text}"
    );
    for line in text.lines() {
        assert!(
            ["<3>", "<4>", "<6>", "<7>"]
                .iter()
                .any(|p| line.starts_with(p)),
            "a line without its priority: {line:?}"
        );
    }
    assert!(
        text.lines()
            .any(|l| l.starts_with("<6>") && l.contains(&format!("serving instance {instance}"))),
        "{text}"
    );
    assert!(
        text.lines()
            .any(|l| l.starts_with("<4>") && l.contains("is not a single level")),
        "{text}"
    );

    // A JOURNAL_STREAM inherited by a service whose standard error goes elsewhere names
    // another file: plain lines, no priorities.
    let other = dir.path().join("other.log");
    let instance = unique_instance("notify2");
    let mut child = start_as_under_systemd(
        &instance,
        &dir.path().join("state2"),
        &socket_path,
        &other,
        &stream,
        "info",
    );
    next_notification(&socket);
    hexacomp_tests::signal_child(&child, libc::SIGTERM);
    next_notification(&socket);
    assert_eq!(child.wait().unwrap().code(), Some(0));
    let text = std::fs::read_to_string(&other).unwrap();
    assert!(text.contains("serving instance"), "{text}");
    assert!(
        !text.contains("<6>"),
        "priorities in a file that is not the journal: {text}"
    );
}
