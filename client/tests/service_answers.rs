//! How `Client` reports what a service answers, against a stand-in service built here on real
//! iceoryx2 ports that answers each compensation request as a test tells it to: overloaded,
//! refused for an unknown reason, another protocol version, the wrong number of points. And a
//! model file too large to deploy, refused before anything is sent (one of the largest size
//! allowed is sent whole).

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

use hexacomp_client::wire::endpoints::{self, Role};
use hexacomp_client::wire::{
    DeployReply, MAX_BATCH, MAX_MODEL_BYTES, PROTOCOL_VERSION, PointResponse, RequestKind,
    RequestOutcome, ResponseHeader, StatusReport, WAIT_SPIN, text_field,
};
use hexacomp_client::{Client, ClientOptions, Error, PointStatus};
use iceoryx2::prelude::*;

/// How the stand-in answers the next compensation requests.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
enum Answer {
    /// Served, one point per point asked, each with status `ok` and generation 7.
    Served,
    /// Served, but one point more than asked.
    OnePointTooMany,
    /// The outcome `Overloaded`.
    Overloaded,
    /// An outcome no client knows (a newer service).
    UnknownOutcome,
    /// A response header of protocol version 99.
    OtherProtocol,
}

/// A stand-in for `hexacomp-service` on its three endpoints, answering from a thread.
struct StandIn {
    instance: String,
    answer: Arc<AtomicU32>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl StandIn {
    fn start(test: &str) -> Self {
        let instance = format!("answers-{}-{test}", std::process::id());
        let answer = Arc::new(AtomicU32::new(Answer::Served as u32));
        let stop = Arc::new(AtomicBool::new(false));
        let (ready_tx, ready_rx) = std::sync::mpsc::channel();
        let thread = {
            let (instance, answer, stop) = (instance.clone(), answer.clone(), stop.clone());
            std::thread::spawn(move || serve(&instance, &answer, &stop, ready_tx))
        };
        ready_rx
            .recv_timeout(Duration::from_secs(30))
            .expect("the stand-in service started");
        Self {
            instance,
            answer,
            stop,
            thread: Some(thread),
        }
    }

    fn answer(&self, answer: Answer) {
        self.answer.store(answer as u32, Ordering::Relaxed);
    }

    fn client(&self) -> Client {
        let options = ClientOptions {
            timeout: Duration::from_secs(10),
        };
        Client::connect(&self.instance, &options).expect("connecting to the stand-in")
    }
}

impl Drop for StandIn {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

fn serve(
    instance: &str,
    answer: &AtomicU32,
    stop: &AtomicBool,
    ready: std::sync::mpsc::Sender<()>,
) {
    let node = NodeBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .unwrap();
    let compensate = endpoints::compensate(&node, instance, Role::Serve).unwrap();
    let status = endpoints::status(&node, instance, Role::Serve).unwrap();
    let deploy = endpoints::deploy(&node, instance, Role::Serve).unwrap();
    let compensate = compensate
        .server_builder()
        .initial_max_slice_len(MAX_BATCH + 1)
        .create()
        .unwrap();
    let status = status.server_builder().create().unwrap();
    let deploy = deploy.server_builder().create().unwrap();
    ready.send(()).unwrap();
    while !stop.load(Ordering::Relaxed) {
        if let Some(request) = status.receive().unwrap() {
            request
                .send_copy(StatusReport {
                    protocol: PROTOCOL_VERSION,
                    wait_mode: WAIT_SPIN,
                    geometry_fingerprint: 0,
                    generation: 7,
                    requests: 0,
                    points: 0,
                    errors: 0,
                    overloaded: 0,
                    persist_failures: 0,
                    uptime_ns: 0,
                    geometry_name: text_field("stand-in"),
                    model: text_field(""),
                })
                .unwrap();
        }
        // Every deploy is accepted as generation 8 and the size of the model file received is
        // reported in the message.
        if let Some(request) = deploy.receive().unwrap() {
            let received = request.payload().len();
            request
                .send_copy(DeployReply {
                    accepted: 1,
                    reserved: [0; 7],
                    generation: 8,
                    message: text_field(&received.to_string()),
                })
                .unwrap();
        }
        if let Some(request) = compensate.receive().unwrap() {
            let asked = request.payload().len();
            let (protocol, outcome, points) = match answer.load(Ordering::Relaxed) {
                a if a == Answer::Served as u32 => {
                    (PROTOCOL_VERSION, RequestOutcome::Served as u32, asked)
                }
                a if a == Answer::OnePointTooMany as u32 => {
                    (PROTOCOL_VERSION, RequestOutcome::Served as u32, asked + 1)
                }
                a if a == Answer::Overloaded as u32 => {
                    (PROTOCOL_VERSION, RequestOutcome::Overloaded as u32, 0)
                }
                a if a == Answer::UnknownOutcome as u32 => (PROTOCOL_VERSION, 77, 0),
                _ => (99, RequestOutcome::ProtocolMismatch as u32, 0),
            };
            let mut response = request
                .loan_slice_uninit(points)
                .unwrap()
                .write_from_fn(|i| PointResponse {
                    legs: [300.0 + i as f64; 6],
                    corrections: [0.001; 6],
                    generation: 7,
                    status: PointStatus::Ok as u8,
                    reserved: [0; 3],
                    uncertainty_mm: 0.004,
                });
            *response.user_header_mut() = ResponseHeader {
                protocol,
                outcome,
                generation: 7,
            };
            response.send().unwrap();
        }
        std::thread::sleep(Duration::from_micros(50));
    }
}

const POSE: [f64; 6] = [0.0, 0.0, 280.0, 0.0, 0.0, 0.0];

#[test]
fn each_answer_of_the_service_is_reported_as_its_own_error() {
    let service = StandIn::start("errors");
    let mut client = service.client();
    // The stand-in's served answer comes through as it was sent.
    let point = client.compensate_pose(POSE).unwrap();
    assert_eq!(
        (point.legs, point.status, point.generation),
        ([300.0; 6], PointStatus::Ok, 7)
    );
    assert_eq!(point.uncertainty_mm, Some(f64::from(0.004f32)));
    service.answer(Answer::Overloaded);
    assert_eq!(client.compensate_pose(POSE), Err(Error::Overloaded));
    service.answer(Answer::UnknownOutcome);
    assert_eq!(
        client.compensate_joints([350.0; 6]),
        Err(Error::Refused { outcome: 77 })
    );
    service.answer(Answer::OtherProtocol);
    assert_eq!(
        client.compensate_pose(POSE),
        Err(Error::ProtocolMismatch { service: 99 })
    );
    service.answer(Answer::OnePointTooMany);
    let mut out = [hexacomp_client::CompensatedPoint::empty(); 3];
    let error = client
        .compensate_batch(RequestKind::Poses, &[POSE; 3], &mut out)
        .unwrap_err();
    assert_eq!(
        error,
        Error::Transport("the service answered 4 points for 3".into())
    );
    // Nothing of the wrong-length answer was handed out.
    assert!(
        out.iter()
            .all(|p| *p == hexacomp_client::CompensatedPoint::empty())
    );
    // And the client is still usable afterwards.
    service.answer(Answer::Served);
    assert_eq!(client.compensate_pose(POSE).unwrap().generation, 7);
}

#[test]
fn a_model_file_beyond_the_deploy_limit_is_refused_before_sending() {
    let service = StandIn::start("toolarge");
    let mut client = service.client();
    let file = vec![0u8; MAX_MODEL_BYTES + 1];
    assert_eq!(
        client.deploy(&file),
        Err(Error::ModelTooLarge {
            bytes: MAX_MODEL_BYTES + 1
        })
    );
    // A file of the largest size allowed is sent whole.
    assert_eq!(
        client.deploy(&file[..MAX_MODEL_BYTES]),
        Ok(hexacomp_client::DeployOutcome::Accepted {
            generation: 8,
            warning: MAX_MODEL_BYTES.to_string()
        })
    );
}
