//! What the serving thread allocates per request and on a model switch: the real serving loop
//! runs in this process, and a counting allocator counts only on that thread, by size.
//!
//! hexacomp's own code (header check, compensation, model switch) allocates nothing. iceoryx2
//! 0.10 itself allocates two small objects per request on the server side: a 24-byte
//! `Arc<AtomicUsize>` in `Server::receive` (port/server.rs:751) and a 48-byte shared state in
//! `ActiveRequest::loan_slice_uninit` (port/details/chunk_mut_shared_state.rs:102), each freed
//! when the request or response is done. This test pins exactly that, so that an allocation of
//! ours, or a change in iceoryx2, shows up.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::Duration;

use hexacomp_client::RequestKind;
use hexacomp_client::{Client, ClientOptions, CompensatedPoint};
use hexacomp_core::Geometry;
use hexacomp_service::Counters;
use hexacomp_service::control::{ControlSetup, run as run_control};
use hexacomp_service::serving::{ServingSetup, WaitMode, serve};

mod common;
use common::generation;

thread_local! {
    static ON_SERVING_THREAD: Cell<bool> = const { Cell::new(false) };
}
/// Heap operations on the serving thread of the sizes iceoryx2 0.10 uses per request.
static IOX_OBJECTS: AtomicUsize = AtomicUsize::new(0);
/// Heap operations on the serving thread of any other size.
static OTHER: AtomicUsize = AtomicUsize::new(0);

fn count(layout: Layout) {
    if ON_SERVING_THREAD.with(Cell::get) {
        let counter = if matches!(layout.size(), 24 | 48) {
            &IOX_OBJECTS
        } else {
            &OTHER
        };
        counter.fetch_add(1, Ordering::SeqCst);
    }
}

struct Counting;

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count(layout);
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        count(layout);
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// One at a time: the counters are global (per process), each wait mode counted on its own.
static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

#[test]
fn spin_mode_allocates_only_iceoryx2s_two_objects_per_request_and_nothing_on_a_swap() {
    serving_thread_allocations(WaitMode::Spin);
}

#[test]
fn sleep_mode_allocates_only_iceoryx2s_two_objects_per_request_and_nothing_on_a_swap() {
    serving_thread_allocations(WaitMode::Sleep);
}

#[test]
fn event_mode_allocates_only_iceoryx2s_two_objects_per_request_and_nothing_on_a_swap() {
    serving_thread_allocations(WaitMode::Event);
}

/// Serves 5000 requests of a client in `wait` mode, with a model switch half-way, and counts
/// the serving thread's heap operations.
fn serving_thread_allocations(wait: WaitMode) {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let geometry = Geometry::prototype();
    let instance = format!("alloc-{}-{}", std::process::id(), wait.wire_value());
    let (to_serving, incoming) = crossbeam_channel::bounded(1);
    let (retired_tx, retired_rx) = crossbeam_channel::bounded(4);
    let (ready_tx, ready_rx) = crossbeam_channel::bounded(1);
    let stop = Arc::new(AtomicBool::new(false));
    let setup = ServingSetup {
        instance: instance.clone(),
        geometry: geometry.clone(),
        initial: Some(generation(&geometry, 1)),
        incoming,
        retired: retired_tx,
        counters: Arc::new(Counters::default()),
        stop: stop.clone(),
        wait,
        client_budget: Some(hexacomp_service::admission::DEFAULT_POINTS_PER_SECOND),
    };
    let serving = std::thread::spawn(move || {
        ON_SERVING_THREAD.with(|f| f.set(true));
        serve(setup, ready_tx);
    });
    assert_eq!(
        ready_rx.recv().unwrap().unwrap(),
        wait,
        "the wait mode in effect"
    );
    // The real control thread serves status and deploy (`Client::connect` asks the status for
    // the wait mode); it only reads the counters here.
    let (unused_tx, unused_rx) = crossbeam_channel::bounded(1);
    let (control_ready_tx, control_ready_rx) = crossbeam_channel::bounded(1);
    let state = tempfile::tempdir().unwrap();
    let control_setup = ControlSetup {
        instance: instance.clone(),
        geometry: geometry.clone(),
        state_dir: state.path().to_path_buf(),
        outgoing: unused_tx,
        retired: unused_rx,
        counters: Arc::new(Counters::default()),
        stop: stop.clone(),
        initial_summary: String::new(),
        last_numbered: 0,
        model_since: None,
        wait_mode: wait.wire_value(),
    };
    let control = std::thread::spawn(move || run_control(control_setup, control_ready_tx));
    control_ready_rx.recv().unwrap().unwrap();
    let mut client = Client::connect(
        &instance,
        &ClientOptions {
            timeout: Duration::from_secs(2),
        },
    )
    .unwrap();
    let points = [
        [0.0, 0.0, 280.0, 0.0, 0.0, 0.0],
        [20.0, -10.0, 300.0, 3.0, -4.0, 5.0],
    ];
    let mut out = [CompensatedPoint::empty(); 2];
    // Warm up: first requests may set up connections.
    for _ in 0..100 {
        client
            .compensate_batch(RequestKind::Poses, &points, &mut out)
            .unwrap();
    }
    let (iox_before, other_before) = (
        IOX_OBJECTS.load(Ordering::SeqCst),
        OTHER.load(Ordering::SeqCst),
    );
    let requests = 5000;
    for i in 0..requests {
        if i == 2500 {
            to_serving.send(generation(&geometry, 2)).unwrap();
        }
        client
            .compensate_batch(RequestKind::Poses, &points, &mut out)
            .unwrap();
    }
    let iox = IOX_OBJECTS.load(Ordering::SeqCst) - iox_before;
    let other = OTHER.load(Ordering::SeqCst) - other_before;
    assert_eq!(out[0].generation, 2, "the swap happened");
    assert_eq!(
        other, 0,
        "{wait:?}: {other} heap operations of hexacomp's own on the serving thread"
    );
    // Two objects allocated and freed per request, all inside iceoryx2.
    assert_eq!(
        iox,
        4 * requests,
        "{wait:?}: iceoryx2's per-request heap operations changed"
    );
    // The retired model came back to be freed here, not there.
    assert_eq!(retired_rx.try_recv().unwrap().number, 1);
    stop.store(true, Ordering::SeqCst);
    serving.join().unwrap();
    control.join().unwrap();
}
