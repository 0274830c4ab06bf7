//! Faults, with real processes: the service SIGKILLed mid-stream and restarted, again and again,
//! without any cleanup by hand; clients SIGKILLed mid-request; a deployer SIGKILLed mid-deploy;
//! a state directory that cannot be written.

use std::collections::HashSet;
use std::time::{Duration, Instant};

use hexacomp_client::DeployOutcome;
use hexacomp_core::Geometry;
use hexacomp_core::compensator::compensate_pose;
use hexacomp_core::fused::FusedModel;
use hexacomp_core::pose::Pose;
use hexacomp_tests::{
    ServiceProcess, path_str, save_smooth_model, spawn_test_client, test_client_report,
    unique_instance, wait_until_connected,
};
use iceoryx2::node::NodeView;
use iceoryx2::prelude::*;

/// iceoryx2 nodes (alive or dead, not yet cleaned up) created by any of `pids`.
fn nodes_of(pids: &HashSet<i32>) -> usize {
    let mut count = 0;
    Node::<ipc::Service>::list(Config::global_config(), |state| {
        let id = match &state {
            NodeState::Alive(view) => Some(*view.id()),
            NodeState::Dead(view) => Some(*view.id()),
            NodeState::Inaccessible(id) | NodeState::Undefined(id) => Some(*id),
        };
        if let Some(pid) = id.and_then(|id| id.pid::<ipc::Service>().ok())
            && pids.contains(&pid.value())
        {
            count += 1;
        }
        CallbackProgression::Continue
    })
    .unwrap();
    count
}

/// Polls `condition` for up to `within`.
fn eventually(within: Duration, mut condition: impl FnMut() -> bool) -> bool {
    let deadline = Instant::now() + within;
    while Instant::now() < deadline {
        if condition() {
            return true;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    condition()
}

const KILLS: usize = 5;

/// How long a test waits for an event before it fails: far longer than any event takes on a
/// loaded machine, so that only a missing event fails it.
const PATIENCE: Duration = Duration::from_secs(60);

#[test]
fn the_service_sigkilled_mid_stream_five_times_restarts_without_cleanup_and_clients_recover() {
    let dir = tempfile::tempdir().unwrap();
    let state = dir.path().join("state");
    let (model, path) = save_smooth_model(dir.path(), 1);
    let instance = unique_instance("killloop");
    let mut service = ServiceProcess::with_model(&instance, &state, &path);
    // Three NC-like clients stream through every kill (1 kHz, 200 ms deadline), until the
    // scenario is over.
    let mut streams: Vec<_> = (0..3)
        .map(|_| {
            spawn_test_client(
                &instance,
                &["stream", "--period-us", "1000", "--timeout-ms", "200"],
            )
        })
        .collect();
    streams.iter_mut().for_each(wait_until_connected);
    let mut killed = HashSet::new();
    for _ in 0..KILLS {
        // Each kill comes while the clients stream: the service has just answered 100 requests.
        let mut status = service.client().unwrap();
        let before = status.status().unwrap().requests;
        assert!(
            eventually(PATIENCE, || status
                .status()
                .is_ok_and(|s| s.requests >= before + 100)),
            "the streaming clients did not reach the service"
        );
        killed.insert(service.pid() as i32);
        service.kill();
        // Restart at once: no --model (the persisted one serves), no cleanup by hand.
        service = ServiceProcess::start(&instance, &["--state-dir", path_str(&state)]);
    }
    let mut status = service.client().unwrap();
    assert_eq!(status.status().unwrap().generation, 1);
    let before = status.status().unwrap().requests;
    assert!(
        eventually(PATIENCE, || status
            .status()
            .is_ok_and(|s| s.requests >= before + 300)),
        "the clients did not come back after the last restart"
    );
    for stream in streams {
        let report = test_client_report(stream);
        // While the service was down, requests timed out; nothing else went wrong, and every
        // client was served again after its last timeout.
        assert_eq!(report["other_errors"], 0, "{report}");
        assert_eq!(report["bad_points"], 0, "{report}");
        assert!(report["timeouts"].as_u64().unwrap() >= 1, "{report}");
        assert!(
            report["served_since_timeout"].as_u64().unwrap() >= 1,
            "{report}"
        );
    }
    // Every killed service's iceoryx2 nodes were reclaimed by the processes that came after.
    assert_eq!(
        nodes_of(&killed),
        0,
        "stale nodes of killed services remain"
    );
    // And the last service computes what the persisted model computes.
    let pose = [4.0, -6.0, 285.0, 1.0, -2.0, 3.0];
    let point = status.compensate_pose(pose).unwrap();
    let expected = compensate_pose(
        &Geometry::prototype(),
        Some(&FusedModel::new(&model)),
        &Pose::from_mm_deg(pose),
    );
    assert_eq!(point.legs, expected.legs);
}

#[test]
fn clients_sigkilled_mid_request_do_not_disturb_the_others_and_their_slots_are_reclaimed() {
    let dir = tempfile::tempdir().unwrap();
    let (_, path) = save_smooth_model(dir.path(), 2);
    let instance = unique_instance("killclients");
    let service = ServiceProcess::with_model(&instance, &dir.path().join("s"), &path);
    // Two clients stream from before the first victim starts until after the last is killed.
    let mut survivors: Vec<_> = (0..2)
        .map(|_| spawn_test_client(&instance, &["stream", "--period-us", "200"]))
        .collect();
    survivors.iter_mut().for_each(wait_until_connected);
    // More victims than the service admits clients at once (32): only works if the slots of
    // killed clients are reclaimed.
    let mut victims = Vec::new();
    for round in 0..6 {
        let mut batch: Vec<_> = (0..8)
            .map(|i| {
                let batch = if (round + i) % 2 == 0 { "1" } else { "1024" };
                spawn_test_client(&instance, &["stream", "--seconds", "30", "--batch", batch])
            })
            .collect();
        // Killed once connected (their node created and set up), mid-stream.
        batch.iter_mut().for_each(wait_until_connected);
        for mut victim in batch {
            victim.kill().unwrap();
            victim.wait().unwrap();
            victims.push(victim.id() as i32);
        }
    }
    for survivor in survivors {
        let report = test_client_report(survivor);
        assert_eq!(report["timeouts"], 0, "{report}");
        assert_eq!(report["other_errors"], 0, "{report}");
        assert_eq!(report["overloaded"], 0, "{report}");
        assert!(report["requests"].as_u64().unwrap() >= 100, "{report}");
    }
    // A new client still connects and is served after 48 killed ones.
    let mut client = service.client().unwrap();
    client
        .compensate_pose([0.0, 0.0, 280.0, 0.0, 0.0, 0.0])
        .unwrap();
    // iceoryx2 removes dead nodes when a node is created; one attempt fails while another
    // process or thread is cleaning up (the other tests here start and kill services and
    // clients meanwhile), so each look creates a node, as every client and service start does.
    let victims: HashSet<i32> = victims.into_iter().collect();
    assert!(
        eventually(Duration::from_secs(5), || {
            drop(NodeBuilder::new().create::<ipc::Service>());
            nodes_of(&victims) == 0
        }),
        "stale nodes of killed clients remain"
    );
}

#[test]
fn a_deployer_killed_mid_deploy_leaves_the_old_model_serving() {
    let dir = tempfile::tempdir().unwrap();
    let (old, old_path) = save_smooth_model(dir.path(), 3);
    let (_, new_path) = save_smooth_model(dir.path(), 4);
    let state = dir.path().join("state");
    let instance = unique_instance("deploydie");
    let service = ServiceProcess::with_model(&instance, &state, &old_path);
    // A deployer's request may be dropped with its dead client before the service takes it, or
    // taken, validated and refused: deployers die until the service has refused at least one
    // (five at least, a hundred at most).
    let refusals = || {
        service
            .log()
            .matches("refused a deployed model: the deployer disconnected")
            .count()
    };
    let deadline = Instant::now() + PATIENCE;
    let mut deployers = 0;
    while deployers < 5 || refusals() == 0 {
        assert!(
            deployers < 100 && Instant::now() < deadline,
            "no dead deployer's model reached the service in {deployers} tries"
        );
        let child = spawn_test_client(
            &instance,
            &["deploy-and-die", "--model", path_str(&new_path)],
        );
        let output = child.wait_with_output().unwrap();
        use std::os::unix::process::ExitStatusExt;
        assert_eq!(output.status.signal(), Some(libc::SIGKILL));
        deployers += 1;
        if deployers >= 5 {
            // The refusal of the last one may still be on its way: look again for a while.
            eventually(Duration::from_millis(500), || refusals() > 0);
        }
    }
    eprintln!(
        "{} of {deployers} dead deployers' models refused",
        refusals()
    );
    let mut client = service.client().unwrap();
    let status = client.status().unwrap();
    assert_eq!(status.generation, 1);
    assert!(status.model.contains("smooth_model(3)"), "{}", status.model);
    let pose = [1.0, 2.0, 300.0, 0.5, 0.5, 0.5];
    let point = client.compensate_pose(pose).unwrap();
    let expected = compensate_pose(
        &Geometry::prototype(),
        Some(&FusedModel::new(&old)),
        &Pose::from_mm_deg(pose),
    );
    assert_eq!(point.legs, expected.legs);
    // The persisted model is still the old one: a restart serves it.
    drop(client);
    service.kill();
    let service = ServiceProcess::start(&instance, &["--state-dir", path_str(&state)]);
    let mut client = service.client().unwrap();
    assert!(client.status().unwrap().model.contains("smooth_model(3)"));
    // A deployer that stays for the answer is accepted as usual.
    let bytes = std::fs::read(&new_path).unwrap();
    assert!(matches!(
        client.deploy(&bytes).unwrap(),
        DeployOutcome::Accepted { generation: 2, .. }
    ));
}

#[test]
fn a_state_directory_that_cannot_be_written_is_reported_and_serving_goes_on() {
    let dir = tempfile::tempdir().unwrap();
    let (_, first) = save_smooth_model(dir.path(), 5);
    let (second_model, second) = save_smooth_model(dir.path(), 6);
    let state = dir.path().join("state");
    let instance = unique_instance("unwritable");
    let service = ServiceProcess::with_model(&instance, &state, &first);
    // The place of the link that commits a persist (`.current.link`, renamed over `current`)
    // is taken by a directory that is not empty: persisting fails whoever we are (root ignores
    // permission bits, not this).
    std::fs::create_dir(state.join(".current.link")).unwrap();
    std::fs::write(state.join(".current.link").join("x"), b"x").unwrap();
    let mut client = service.client().unwrap();
    match client.deploy(&std::fs::read(&second).unwrap()).unwrap() {
        DeployOutcome::Accepted {
            generation,
            warning,
        } => {
            assert_eq!(generation, 2);
            assert!(warning.contains("not persisted"), "{warning}");
            assert!(
                warning.contains("a restart would serve generation 1"),
                "{warning}"
            );
        }
        refused => panic!("{refused:?}"),
    }
    let status = client.status().unwrap();
    assert_eq!(status.persist_failures, 1);
    assert_eq!(status.generation, 2);
    let pose = [0.0, 5.0, 290.0, 0.0, 1.0, 0.0];
    let point = client.compensate_pose(pose).unwrap();
    let expected = compensate_pose(
        &Geometry::prototype(),
        Some(&FusedModel::new(&second_model)),
        &Pose::from_mm_deg(pose),
    );
    assert_eq!((point.legs, point.generation), (expected.legs, 2));
    // The status line says it too.
    let output = hexacomp_tests::run("hexacomp-client", &["--instance", &instance, "status"]);
    let text = String::from_utf8_lossy(&output.stdout);
    assert!(text.contains("NOT persisted"), "{text}");
    // As the warning said, a restart serves generation 1, whole.
    drop(client);
    service.kill();
    let service = ServiceProcess::start(&instance, &["--state-dir", path_str(&state)]);
    let status = service.client().unwrap().status().unwrap();
    assert_eq!(status.generation, 1);
    assert!(status.model.contains("smooth_model(5)"), "{}", status.model);
}

#[test]
fn a_client_connected_to_a_spinning_service_wakes_the_event_mode_service_that_replaced_it() {
    let dir = tempfile::tempdir().unwrap();
    let state = dir.path().join("state");
    let (_, path) = save_smooth_model(dir.path(), 1);
    let instance = unique_instance("waitswitch");
    let args = |wait: &'static str| ["--state-dir", path_str(&state), "--wait", wait];
    let service = ServiceProcess::start(
        &instance,
        &[
            "--state-dir",
            path_str(&state),
            "--model",
            path_str(&path),
            "--wait",
            "spin",
        ],
    );
    // An NC-like client: 1 kHz, 8 ms deadline. An event-mode service that is not notified
    // answers on its 10 ms tick only: most of its requests would time out.
    let mut stream = spawn_test_client(
        &instance,
        &["stream", "--period-us", "1000", "--timeout-ms", "8"],
    );
    wait_until_connected(&mut stream);
    service.kill();
    let service = ServiceProcess::start(&instance, &args("event"));
    let mut status = service.client().unwrap();
    assert_eq!(status.status().unwrap().wait_mode, "event");
    // The stream is served by the new service: 3000 requests (about 3 s at 1 kHz).
    assert!(
        eventually(PATIENCE, || status
            .status()
            .is_ok_and(|s| s.requests >= 3000)),
        "the stream did not reach the restarted service"
    );
    let report = test_client_report(stream);
    assert_eq!(report["other_errors"], 0, "{report}");
    // Served without a timeout for its last 200 requests or more: woken by each request. Not
    // woken, one request in five or more waits past 8 ms for the tick (0.8²⁰⁰ ≈ 4·10⁻²⁰).
    assert!(
        report["served_since_timeout"].as_u64().unwrap() >= 200,
        "{report}"
    );
    eprintln!("across a restart from spin into event mode: {report}");
}
