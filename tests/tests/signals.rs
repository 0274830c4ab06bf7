//! Signals the service meets on a real machine, in every wait mode: systemd's SIGTERM followed at
//! once by SIGCONT, a debugger's or strace's SIGSTOP/SIGCONT, and SIGTERM while clients flood it.
//! Only a termination request stops the service, and a termination request always does.

use std::time::Duration;

use hexacomp_tests::{ServiceProcess, spawn_test_client, unique_instance};

const WAIT_MODES: [&str; 3] = ["spin", "sleep", "event"];

/// Rounds per wait mode of the TERM-then-CONT test. Before the fix, 1–4 of 8 stops were lost
/// with `--wait sleep`.
const TERM_CONT_ROUNDS: usize = 8;

/// A service of a new instance waiting as `wait`, with its state in a directory removed with
/// the returned guard.
fn start(test: &str, wait: &str) -> (ServiceProcess, tempfile::TempDir) {
    let state = tempfile::tempdir().unwrap();
    let dir = state.path().join("state");
    let args = ["--wait", wait, "--state-dir", dir.to_str().unwrap()];
    (ServiceProcess::start(&unique_instance(test), &args), state)
}

#[test]
fn sigterm_followed_at_once_by_sigcont_stops_the_service_in_every_wait_mode() {
    let mut stuck = Vec::new();
    for wait in WAIT_MODES {
        for round in 0..TERM_CONT_ROUNDS {
            let (mut service, _state) = start("termcont", wait);
            // systemd's `stop`: SIGTERM, then SIGCONT in case the process was stopped.
            match service.signal_and_wait(&[libc::SIGTERM, libc::SIGCONT], Duration::from_secs(10))
            {
                Some(status) => assert_eq!(
                    status.code(),
                    Some(0),
                    "--wait {wait}, round {round}: {status}\n{}",
                    service.log()
                ),
                None => stuck.push(format!("--wait {wait}, round {round}")),
            }
        }
    }
    assert!(
        stuck.is_empty(),
        "still running 10 s after SIGTERM+SIGCONT ({} of {}): {stuck:?}",
        stuck.len(),
        TERM_CONT_ROUNDS * WAIT_MODES.len()
    );
}

#[test]
fn sigstop_and_sigcont_do_not_stop_the_service_in_any_wait_mode() {
    for wait in WAIT_MODES {
        let (mut service, _state) = start("stopcont", wait);
        for _ in 0..5 {
            service.pause();
            service.resume();
        }
        // Still running and the serving thread still answering: a compensation round trip
        // after the last SIGCONT.
        let status = service
            .client()
            .and_then(|mut c| c.compensate_pose([0.0, 0.0, 280.0, 0.0, 0.0, 0.0]));
        assert!(
            service.is_running(),
            "--wait {wait}: the service exited after SIGSTOP/SIGCONT:\n{}",
            service.log()
        );
        assert!(
            status.is_ok(),
            "--wait {wait}: {status:?}\n{}",
            service.log()
        );
        assert!(
            !service.log().contains("stopped;"),
            "--wait {wait}: the service says it stopped:\n{}",
            service.log()
        );
        let (status, log) = service.stop_with(libc::SIGTERM);
        assert_eq!(status.code(), Some(0), "--wait {wait}: {status}\n{log}");
    }
}

#[test]
fn sigterm_during_a_flood_stops_the_service_in_every_wait_mode() {
    for wait in WAIT_MODES {
        let (mut service, _state) = start("termflood", wait);
        let flooders: Vec<_> = (0..2)
            .map(|_| spawn_test_client(&service.instance, &["flood", "--seconds", "30"]))
            .collect();
        // The flood is under way once the service has answered points.
        let deadline = std::time::Instant::now() + Duration::from_secs(30);
        while service
            .client()
            .and_then(|mut c| c.status())
            .map_or(0, |s| s.points)
            == 0
        {
            assert!(
                std::time::Instant::now() < deadline,
                "--wait {wait}: no points answered"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
        let status = service.signal_and_wait(&[libc::SIGTERM], Duration::from_secs(10));
        let log = service.log();
        for mut flooder in flooders {
            let _ = flooder.kill();
            let _ = flooder.wait();
        }
        let status = status.unwrap_or_else(|| {
            panic!("--wait {wait}: still running 10 s after SIGTERM during a flood:\n{log}")
        });
        assert_eq!(status.code(), Some(0), "--wait {wait}: {status}\n{log}");
        assert!(
            log.contains("stopped; iceoryx2 resources released"),
            "{log}"
        );
    }
}
