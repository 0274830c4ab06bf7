//! The answering order with real iceoryx2 ports, driven step by step in this process: requests
//! are queued first, then [`Answerer::answer_next`] is called and what each client got is read.
//! No timing is involved: every request waits before the first answer.

use hexacomp_core::Geometry;
use hexacomp_core::compensator::compensate_pose;
use hexacomp_core::pose::Pose;
use hexacomp_protocol::{
    PROTOCOL_VERSION, PointRequest, PointResponse, RequestHeader, RequestKind, RequestOutcome,
    ResponseHeader,
};
use hexacomp_service::Counters;
use hexacomp_service::answering::Answerer;
use hexacomp_service::serving::{ServingLoop, compensation_endpoint};

mod common;
use common::generation;
use iceoryx2::prelude::*;

type ClientPort = iceoryx2::port::client::Client<
    ipc::Service,
    [PointRequest],
    RequestHeader,
    [PointResponse],
    ResponseHeader,
>;
type Pending = iceoryx2::pending_response::PendingResponse<
    ipc::Service,
    [PointRequest],
    RequestHeader,
    [PointResponse],
    ResponseHeader,
>;

/// Sends `points` copies of the home pose; the request waits for its answer.
fn send(client: &ClientPort, points: usize) -> Pending {
    let mut request = client.loan_slice_uninit(points).expect("loan");
    *request.user_header_mut() = RequestHeader {
        protocol: PROTOCOL_VERSION,
        kind: RequestKind::Poses as u32,
    };
    let request = request.write_from_fn(|_| PointRequest {
        values: [0.0, 0.0, 280.0, 0.0, 0.0, 0.0],
    });
    request.send().expect("send")
}

/// How many points the answer to `pending` carries, if it has come (served requests only).
fn answered_points(pending: &Pending) -> Option<usize> {
    let response = pending.receive().expect("receive")?;
    assert_eq!(
        response.user_header().outcome,
        RequestOutcome::Served as u32
    );
    Some(response.payload().len())
}

/// A node, the compensation endpoint of a fresh instance and `clients` client ports on it, in
/// the order created (iceoryx2 scans its clients in that order).
fn endpoint_with_clients(
    test: &str,
    clients: usize,
) -> (
    Node<ipc::Service>,
    hexacomp_service::serving::CompensationEndpoint,
    Vec<ClientPort>,
) {
    let node = NodeBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .expect("node");
    let instance = format!("answering-{test}-{}", std::process::id());
    let endpoint = compensation_endpoint(&node, &instance).expect("endpoint");
    let ports = (0..clients)
        .map(|_| {
            endpoint
                .0
                .client_builder()
                .initial_max_slice_len(hexacomp_protocol::MAX_BATCH)
                .create()
                .expect("client port")
        })
        .collect();
    (node, endpoint, ports)
}

#[test]
fn a_client_behind_a_backlog_is_answered_second_not_fifth() {
    let (_node, (_service, server), ports) = endpoint_with_clients("backlog", 2);
    let (flooder, paced) = (&ports[0], &ports[1]);
    let backlog: Vec<_> = (0..4).map(|_| send(flooder, 8)).collect();
    let single = send(paced, 1);
    let geometry = Geometry::prototype();
    let counters = Counters::default();
    let mut answerer = Answerer::new(&server, &geometry, &counters, None);
    assert!(answerer.answer_next(None));
    assert!(answerer.answer_next(None));
    // Two answers: one for each client, whichever iceoryx2 found first.
    assert_eq!(answered_points(&single), Some(1));
    let flooder_answered = backlog.iter().filter_map(answered_points).count();
    assert_eq!(flooder_answered, 1);
    // The rest of the backlog follows.
    for _ in 0..3 {
        assert!(answerer.answer_next(None));
    }
    assert!(!answerer.answer_next(None));
    assert_eq!(
        counters.requests.load(std::sync::atomic::Ordering::Relaxed),
        5
    );
}

#[test]
fn a_large_batch_steps_aside_for_a_single_point_that_waits() {
    let (_node, (_service, server), ports) = endpoint_with_clients("step", 2);
    let (batch, single) = (send(&ports[0], 1024), send(&ports[1], 1));
    let geometry = Geometry::prototype();
    let counters = Counters::default();
    let mut answerer = Answerer::new(&server, &geometry, &counters, None);
    // One step of the serving loop answers the batch, and the single point during it.
    assert!(answerer.answer_next(None));
    assert_eq!(answered_points(&batch), Some(1024));
    assert_eq!(answered_points(&single), Some(1));
    assert!(!answerer.answer_next(None));
}

#[test]
fn the_serving_loop_switches_models_between_two_requests_and_hands_the_old_one_back() {
    use std::sync::atomic::Ordering::Relaxed;
    let (_node, (_service, server), ports) = endpoint_with_clients("switch", 1);
    let geometry = Geometry::prototype();
    let counters = Counters::default();
    let (to_serving, incoming) = crossbeam_channel::bounded(1);
    let (retired_tx, retired) = crossbeam_channel::bounded(4);
    let answerer = Answerer::new(&server, &geometry, &counters, None);
    let mut serving = ServingLoop::new(
        answerer,
        Some(generation(&geometry, 1)),
        incoming,
        retired_tx,
        &counters,
    );
    assert_eq!(
        counters.generation.load(Relaxed),
        1,
        "published before serving"
    );
    assert!(!serving.poll_once(), "no request waits yet");
    // What the answer to `send`'s pose must be with the model of `number`.
    let home = Pose::from_mm_deg([0.0, 0.0, 280.0, 0.0, 0.0, 0.0]);
    let expected =
        |number| compensate_pose(&geometry, Some(&generation(&geometry, number).model), &home).legs;
    let answer = |pending: &Pending| {
        let response = pending.receive().expect("receive").expect("answered");
        let point = response.payload()[0];
        (
            response.user_header().generation,
            point.generation,
            point.legs,
        )
    };
    let first = send(&ports[0], 1);
    assert!(serving.poll_once());
    assert_eq!(answer(&first), (1, 1, expected(1)));
    to_serving.send(generation(&geometry, 2)).unwrap();
    let second = send(&ports[0], 1);
    assert!(serving.poll_once());
    assert_eq!(answer(&second), (2, 2, expected(2)));
    assert_ne!(expected(1), expected(2), "the two models must differ");
    assert_eq!(counters.generation.load(Relaxed), 2);
    assert_eq!(retired.try_recv().map(|g| g.number), Ok(1));
    drop(serving);
    assert_eq!(
        retired.try_recv().map(|g| g.number),
        Ok(2),
        "the last one on drop"
    );
}
