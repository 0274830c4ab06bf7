//! The service as a library, in this test's own process: started from options, answering a real
//! iceoryx2 client, stopped, joined, and stopped by `Drop` when not joined.

use std::time::Duration;

use hexacomp_client::{Client, ClientOptions, Error};
use hexacomp_core::Geometry;
use hexacomp_service::{Service, ServiceOptions};

fn instance(test: &str) -> String {
    format!("inproc-{test}-{}", std::process::id())
}

fn connect(instance: &str) -> Result<Client, Error> {
    Client::connect(
        instance,
        &ClientOptions {
            timeout: Duration::from_secs(5),
        },
    )
}

#[test]
fn a_service_started_in_process_answers_and_joins_after_stop() {
    let state = tempfile::tempdir().unwrap();
    let name = instance("join");
    let service = Service::start(ServiceOptions::new(
        &name,
        Geometry::prototype(),
        state.path().join("state"),
    ))
    .unwrap();
    let mut client = connect(&name).unwrap();
    let status = client.status().unwrap();
    assert_eq!(status.generation, 0, "no model yet: {status:?}");
    let answer = client
        .compensate_pose([0.0, 0.0, 280.0, 0.0, 0.0, 0.0])
        .unwrap();
    assert_eq!(answer.status.name(), "no_model");
    assert!(!service.is_finished());
    service.stop();
    service.join().unwrap();
    drop(client);
    assert!(matches!(connect(&name), Err(Error::ServiceAbsent { .. })));
}

#[test]
fn dropping_a_service_stops_it_and_frees_the_instance() {
    let state = tempfile::tempdir().unwrap();
    let name = instance("drop");
    let options = ServiceOptions::new(&name, Geometry::prototype(), state.path().join("state"));
    let service = Service::start(options.clone()).unwrap();
    connect(&name).unwrap().status().unwrap();
    drop(service);
    // The instance is free: a second service starts on it and answers.
    let again = Service::start(options).unwrap();
    connect(&name).unwrap().status().unwrap();
    again.stop();
    again.join().unwrap();
}
