//! What the C library allocates per call, on the calling thread (an NC's servo thread): a C
//! program linked with `libhexacomp.a` counts every heap operation of its own thread during
//! the calls (`tests/c/allocations_test.c` replaces malloc and its relatives), against a real
//! service in each wait mode, for calls answered and calls that time out.
//!
//! hexacomp's own code allocates nothing per call, answered or failed: the error detail is
//! written into a fixed per-thread buffer. iceoryx2 0.10 itself allocates one 48-byte object
//! per request on the client side (the shared state of the loaned request:
//! request_mut_uninit.rs:270, port/details/chunk_mut_shared_state.rs:102), freed when the
//! request is done. This test pins
//! exactly that, so that an allocation of ours, or a change in iceoryx2, shows up.

use std::collections::BTreeMap;

use hexacomp_tests::c_program::{compile, run_against};
use hexacomp_tests::{ServiceProcess, save_smooth_model, unique_instance};

/// One line of the program's output: calls made, heap allocations and frees, allocations by
/// size.
#[derive(Debug)]
struct Tally {
    calls: u64,
    allocations: u64,
    frees: u64,
    by_size: BTreeMap<u64, u64>,
}

fn tallies(stdout: &str) -> BTreeMap<String, Tally> {
    stdout
        .lines()
        .filter(|line| *line != "OK")
        .map(|line| {
            let fields: Vec<&str> = line.split(' ').collect();
            let number = |s: &str| s.parse::<u64>().unwrap_or_else(|_| panic!("{line}"));
            let by_size = fields[4..]
                .iter()
                .map(|pair| {
                    let (size, count) = pair.split_once('x').unwrap_or_else(|| panic!("{line}"));
                    (number(size), number(count))
                })
                .collect();
            let tally = Tally {
                calls: number(fields[1]),
                allocations: number(fields[2]),
                frees: number(fields[3]),
                by_size,
            };
            (fields[0].to_string(), tally)
        })
        .collect()
}

#[test]
fn c_calls_allocate_only_iceoryx2s_request_object_answered_or_timed_out_in_every_wait_mode() {
    let dir = tempfile::tempdir().unwrap();
    let (_, model) = save_smooth_model(dir.path(), 23);
    let exe = compile("allocations_test.c", dir.path(), false);
    for wait in ["spin", "sleep", "event"] {
        let instance = unique_instance(&format!("calloc-{wait}"));
        let state = dir.path().join(format!("state-{wait}"));
        let service = ServiceProcess::start(
            &instance,
            &[
                "--state-dir",
                state.to_str().unwrap(),
                "--model",
                model.to_str().unwrap(),
                "--wait",
                wait,
            ],
        );
        let stdout = run_against(&exe, &service);
        assert_eq!(stdout.lines().last(), Some("OK"), "{wait}");
        let tallies = tallies(&stdout);
        for kind in [
            "ANSWERED_JOINTS",
            "ANSWERED_POSES",
            "FIRST_TIMED_OUT_JOINTS",
            "TIMED_OUT_JOINTS",
        ] {
            let tally = &tallies[kind];
            assert!(tally.calls > 0, "{wait} {kind}: no calls made");
            assert_eq!(
                tally.by_size,
                BTreeMap::from([(48, tally.calls)]),
                "{wait} {kind}: heap allocations by size over {} calls",
                tally.calls
            );
            assert_eq!(
                (tally.allocations, tally.frees),
                (tally.calls, tally.calls),
                "{wait} {kind}: one allocation and one free per call"
            );
        }
    }
}
