//! The control thread: status, telemetry and deploy endpoints. Models are validated and persisted here, then
//! handed to the serving thread; retired models come back here to be freed.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use crossbeam_channel::{Receiver, Sender, TrySendError};
use hexacomp_core::Geometry;
use hexacomp_protocol::endpoints::{self, Role};
use hexacomp_protocol::{DeployReply, PROTOCOL_VERSION, StatusReport, TelemetryReport, text_field};
use iceoryx2::prelude::*;

use crate::{Counters, Error, Generation, state, validate};

/// How long a deploy waits for the serving thread to take the accepted model in before it
/// answers anyway (saying so).
const TAKE_IN_PATIENCE: Duration = Duration::from_secs(1);

/// `first` and `second` joined with "; ", either may be empty.
fn join(first: String, second: &str) -> String {
    if first.is_empty() {
        second.to_string()
    } else {
        format!("{first}; {second}")
    }
}

/// How often the control thread polls its endpoints while idle. Every wake-up of this thread may
/// land on the serving thread's core and preempt it (about 35 µs on a virtual machine here, at
/// a 1 ms interval a visible p99.9 bump); status, telemetry and deploy answers wait up to this
/// long.
const IDLE_POLL: Duration = Duration::from_millis(10);

/// What the control thread needs.
pub struct ControlSetup {
    /// The instance name.
    pub instance: String,
    /// The geometry served.
    pub geometry: Geometry,
    /// Where accepted models persist.
    pub state_dir: PathBuf,
    /// Accepted models to the serving thread.
    pub outgoing: Sender<Box<Generation>>,
    /// Retired models from the serving thread.
    pub retired: Receiver<Box<Generation>>,
    /// Shared counters.
    pub counters: Arc<Counters>,
    /// Set to stop.
    pub stop: Arc<AtomicBool>,
    /// Provenance of the model serving at start.
    pub initial_summary: String,
    /// The last generation number given out before this start (the serving model's, or a
    /// higher one whose model was not served): the next deploy is numbered after it.
    pub last_numbered: u64,
    /// When the model serving at start was accepted (`None`: no model).
    pub model_since: Option<std::time::SystemTime>,
    /// How the serving thread waits (status report value).
    pub wait_mode: u32,
}

/// What the reports say about the model serving: its summary and when it was accepted.
#[derive(Debug, Default)]
struct ServingModel {
    summary: String,
    since: Option<std::time::SystemTime>,
}

/// A one-line summary of a model for the status report.
pub fn summarise(model: &hexacomp_core::model::Model) -> String {
    let p = &model.provenance;
    if model.is_physical() {
        let accuracy = if p.validation_rmse_mm.is_finite() {
            format!("{:.4} mm cross-validated", p.validation_rmse_mm)
        } else {
            "not cross-validated".to_string()
        };
        return format!(
            "physical model, {} configurations, {accuracy}; {}",
            p.configurations, p.source
        );
    }
    format!(
        "hidden {:?}, {} legs, {} configurations, validation RMSE {:.4} mm; {}",
        model.hidden_nodes(),
        model.input.name(),
        p.configurations,
        p.validation_rmse_mm,
        p.source
    )
}

/// A server of one of the control thread's endpoints: requests `Req` in, replies `Reply` out.
type ControlServer<Req, Reply> = iceoryx2::port::server::Server<ipc::Service, Req, (), Reply, ()>;

/// The control thread's node and its endpoints' servers. The fields are dropped in their
/// order: the servers, then their endpoints, then the node.
struct ControlPorts {
    telemetry: ControlServer<u64, TelemetryReport>,
    deploy: ControlServer<[u8], DeployReply>,
    status: ControlServer<u64, StatusReport>,
    /// The endpoints (status, deploy, telemetry), kept open while their servers serve.
    _endpoints: (
        endpoints::StatusEndpoint,
        endpoints::DeployEndpoint,
        endpoints::TelemetryEndpoint,
    ),
    node: Node<ipc::Service>,
}

impl ControlPorts {
    /// Creates the control thread's node and serves the status, deploy and telemetry endpoints
    /// of `instance`.
    fn open(instance: &str) -> Result<Self, Error> {
        let node = NodeBuilder::new()
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .create::<ipc::Service>()
            .map_err(|e| Error::Iceoryx(format!("creating the control thread's node: {e}")))?;
        let status_service = endpoints::status(&node, instance, Role::Serve)?;
        let deploy_service = endpoints::deploy(&node, instance, Role::Serve)?;
        let telemetry_service = endpoints::telemetry(&node, instance, Role::Serve)?;
        let status = status_service
            .server_builder()
            .create()
            .map_err(|e| Error::Iceoryx(format!("status server: {e:?}")))?;
        let deploy = deploy_service
            .server_builder()
            .create()
            .map_err(|e| Error::Iceoryx(format!("deploy server: {e:?}")))?;
        let telemetry = telemetry_service
            .server_builder()
            .create()
            .map_err(|e| Error::Iceoryx(format!("telemetry server: {e:?}")))?;
        Ok(Self {
            telemetry,
            deploy,
            status,
            _endpoints: (status_service, deploy_service, telemetry_service),
            node,
        })
    }
}

/// Creates the status, telemetry and deploy endpoints and serves them until stopped.
pub fn run(setup: ControlSetup, ready: Sender<Result<(), Error>>) {
    let ports = match ControlPorts::open(&setup.instance) {
        Ok(ports) => {
            let _ = ready.send(Ok(()));
            ports
        }
        Err(e) => {
            let _ = ready.send(Err(e));
            return;
        }
    };
    let start = Instant::now();
    let mut serving = ServingModel {
        summary: setup.initial_summary.clone(),
        since: setup.model_since,
    };
    // The last generation number given out. Only this thread numbers models, one deploy at a
    // time, so numbers are unique and increase in the order the models are handed over (the
    // serving thread's counter lags until it takes a model in).
    let mut numbered = setup.last_numbered;
    while !setup.stop.load(Ordering::Relaxed) {
        let mut busy = false;
        while let Ok(old) = setup.retired.try_recv() {
            drop(old);
        }
        if let Ok(Some(request)) = ports.status.receive() {
            busy = true;
            if let Err(e) = request.send_copy(status_report(&setup, &serving, start)) {
                tracing::warn!("answering a status request failed: {e:?}");
            }
        }
        if let Ok(Some(request)) = ports.telemetry.receive() {
            busy = true;
            if let Err(e) = request.send_copy(telemetry_report(&setup.counters, &serving)) {
                tracing::warn!("answering a telemetry request failed: {e:?}");
            }
        }
        if let Ok(Some(request)) = ports.deploy.receive() {
            busy = true;
            // A deployer killed before the answer leaves the old model serving: its dead node is
            // cleaned up, which disconnects its request, and the validated model is dropped.
            let deployer_alive = || {
                ports.node.try_cleanup_dead_nodes();
                request.is_connected()
            };
            let reply = handle_deploy(
                &setup,
                request.payload(),
                deployer_alive,
                &mut numbered,
                &mut serving,
            );
            if let Err(e) = request.send_copy(reply) {
                tracing::warn!("answering a deploy request failed: {e:?}");
            }
        }
        if !busy {
            std::thread::sleep(IDLE_POLL);
        }
    }
}

/// The status report: the counters, the geometry and the model serving, `start` the instant the
/// control thread started serving (the uptime counts from it).
fn status_report(setup: &ControlSetup, serving: &ServingModel, start: Instant) -> StatusReport {
    let c = &setup.counters;
    StatusReport {
        protocol: PROTOCOL_VERSION,
        wait_mode: setup.wait_mode,
        geometry_fingerprint: setup.geometry.fingerprint().0,
        generation: c.generation.load(Ordering::Relaxed),
        requests: c.requests.load(Ordering::Relaxed),
        points: c.points.load(Ordering::Relaxed),
        errors: c.errors.load(Ordering::Relaxed),
        overloaded: c.overloaded.load(Ordering::Relaxed),
        persist_failures: c.persist_failures.load(Ordering::Relaxed),
        uptime_ns: start.elapsed().as_nanos() as u64,
        geometry_name: text_field(&setup.geometry.name),
        model: text_field(&serving.summary),
    }
}

/// The telemetry report: the serving thread's answer times and the model's age.
fn telemetry_report(counters: &Counters, serving: &ServingModel) -> TelemetryReport {
    let times = &counters.answer_times;
    let since_epoch = |t: std::time::SystemTime| {
        t.duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
    };
    TelemetryReport {
        protocol: PROTOCOL_VERSION,
        reserved: 0,
        deadline_ns: u64::try_from(times.deadline().as_nanos()).unwrap_or(u64::MAX),
        deadline_misses: times.misses(),
        model_since_unix_ns: serving.since.map_or(0, since_epoch),
        latency_buckets: times.buckets(),
        latency_sum_ns: times.sum_ns(),
        spare: [0; 4],
    }
}

/// Validates a deployed model, hands it to the serving thread as generation `numbered + 1`,
/// persists it and answers once it serves; refuses it when it is invalid, when its deployer is
/// gone by the time it is validated (`deployer_alive`, asked once, just before committing) or
/// when the serving thread cannot take it (nothing is persisted then). `numbered` is the last
/// generation number given out.
fn handle_deploy(
    setup: &ControlSetup,
    bytes: &[u8],
    deployer_alive: impl FnOnce() -> bool,
    numbered: &mut u64,
    serving: &mut ServingModel,
) -> DeployReply {
    let latest = *numbered;
    let refuse = |why: String| {
        tracing::warn!("refused a deployed model: {why}");
        DeployReply {
            accepted: 0,
            reserved: [0; 7],
            generation: latest,
            message: text_field(&why),
        }
    };
    let model = match validate::validate(bytes, &setup.geometry) {
        Ok(model) => model,
        Err(why) => return refuse(why.to_string()),
    };
    if !deployer_alive() {
        return refuse("the deployer disconnected before the model was committed".into());
    }
    let number = match crate::daemon::next_generation(Some(latest).filter(|&n| n > 0)) {
        Ok(number) => number,
        Err(e) => return refuse(e.to_string()),
    };
    let line = summarise(&model);
    match setup
        .outgoing
        .try_send(Box::new(Generation::new(&model, number)))
    {
        Ok(()) => *numbered = number,
        Err(TrySendError::Full(_)) => {
            return refuse(format!(
                "the serving thread has not taken in generation {latest} yet: deploy again"
            ));
        }
        Err(TrySendError::Disconnected(_)) => {
            return refuse("the serving thread has stopped".into());
        }
    }
    let mut note = persist_accepted(setup, bytes, number);
    // The reply says the model serves: wait until the serving thread has taken it in (between
    // two requests; within its 10 ms tick when it sleeps in event mode).
    if !taken_in(&setup.counters, number) {
        note = join(
            note,
            "accepted, not serving yet: the serving thread has not taken it in",
        );
    }
    serving.summary = line;
    serving.since = Some(std::time::SystemTime::now());
    tracing::info!("accepted a model as generation {number}");
    DeployReply {
        accepted: 1,
        reserved: [0; 7],
        generation: number,
        message: text_field(&note),
    }
}

/// Persists the accepted model file `bytes` as generation `number`: an empty note, or, when
/// that fails (counted), what the deploy's reply says of it: what a restart would serve.
fn persist_accepted(setup: &ControlSetup, bytes: &[u8], number: u64) -> String {
    let Err(e) = state::persist(&setup.state_dir, bytes, number) else {
        return String::new();
    };
    tracing::error!("accepted generation {number} but could not persist it: {e}");
    setup
        .counters
        .persist_failures
        .fetch_add(1, Ordering::Relaxed);
    format!(
        "accepted but not persisted ({e}); a restart would serve {}",
        match state::persisted_generation(&setup.state_dir) {
            Ok(Some(persisted)) => format!("generation {persisted}"),
            Ok(None) => "no model".into(),
            Err(e) => format!("nothing: {e}"),
        }
    )
}

/// Waits up to [`TAKE_IN_PATIENCE`], polling every 100 µs, until the serving thread serves
/// generation `number` or a later one; whether it did (a warning is logged when not).
fn taken_in(counters: &Counters, number: u64) -> bool {
    let deadline = Instant::now() + TAKE_IN_PATIENCE;
    while counters.generation.load(Ordering::Relaxed) < number {
        if Instant::now() >= deadline {
            tracing::warn!("generation {number} was not taken in within {TAKE_IN_PATIENCE:?}");
            return false;
        }
        std::thread::sleep(Duration::from_micros(100));
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use hexacomp_core::model::{Model, NetworkInput, Networks, Provenance};
    use hexacomp_core::network::{Network, Normalisation};

    /// A valid model for the prototype: every leg corrected by `offset_mm`, everywhere.
    fn constant_model(offset_mm: f64) -> Model {
        let g = Geometry::prototype();
        let [min, max] = g.leg_range;
        let mut weights = vec![0.0; Network::weight_count(1, 1)];
        *weights.last_mut().unwrap() = offset_mm;
        let network = Network::from_weights(1, 1, weights).unwrap();
        Model {
            networks: Networks::Decoupled(vec![network; 6]),
            input: NetworkInput::Commanded,
            normalisation: Normalisation {
                mean: [(min + max) / 2.0; 6],
                span: [max - min; 6],
            },
            training_range: [g.leg_range; 6],
            correction_bounds: [[-0.5, 0.5]; 6],
            geometry: g.fingerprint(),
            provenance: Provenance::default(),
            uncertainty: None,
        }
    }

    /// A control setup whose serving side is `incoming`, with its state in `dir`.
    fn setup(
        dir: &std::path::Path,
        last_numbered: u64,
    ) -> (ControlSetup, Receiver<Box<Generation>>) {
        let (outgoing, incoming) = crossbeam_channel::bounded(1);
        let (_, retired) = crossbeam_channel::bounded(1);
        let setup = ControlSetup {
            instance: "unit".into(),
            geometry: Geometry::prototype(),
            state_dir: dir.to_path_buf(),
            outgoing,
            retired,
            counters: Arc::new(Counters::default()),
            stop: Arc::new(AtomicBool::new(false)),
            initial_summary: String::new(),
            last_numbered,
            model_since: None,
            wait_mode: 0,
        };
        (setup, incoming)
    }

    fn deploy(setup: &ControlSetup, offset_mm: f64, numbered: &mut u64) -> DeployReply {
        let bytes = constant_model(offset_mm).to_bytes();
        handle_deploy(
            setup,
            &bytes,
            || true,
            numbered,
            &mut ServingModel::default(),
        )
    }

    fn persisted_generation(dir: &std::path::Path) -> String {
        std::fs::read_to_string(dir.join("generation")).unwrap()
    }

    #[test]
    fn a_deploy_is_answered_only_once_the_serving_thread_has_taken_the_model_in() {
        let dir = tempfile::tempdir().unwrap();
        let (setup, incoming) = setup(dir.path(), 1);
        let counters = setup.counters.clone();
        // A serving thread that is slow to take the model in.
        let taker = std::thread::spawn(move || {
            let generation = incoming.recv().unwrap();
            std::thread::sleep(Duration::from_millis(50));
            counters
                .generation
                .store(generation.number, Ordering::Relaxed);
        });
        let mut numbered = 1;
        let reply = deploy(&setup, 0.1, &mut numbered);
        assert_eq!((reply.accepted, reply.generation), (1, 2));
        assert_eq!(setup.counters.generation.load(Ordering::Relaxed), 2);
        assert_eq!(text(&reply.message), "");
        taker.join().unwrap();
    }

    #[test]
    fn deploys_are_numbered_from_the_initial_generation_whatever_the_counter_says() {
        let dir = tempfile::tempdir().unwrap();
        // The serving thread's counter still 0 (it has not stored the initial generation yet).
        let (setup, incoming) = setup(dir.path(), 5);
        let counters = setup.counters.clone();
        let taker = std::thread::spawn(move || {
            for generation in incoming.iter() {
                counters
                    .generation
                    .store(generation.number, Ordering::Relaxed);
            }
        });
        let mut numbered = setup.last_numbered;
        let given: Vec<u64> = [0.1, 0.2, 0.3]
            .iter()
            .map(|offset| deploy(&setup, *offset, &mut numbered).generation)
            .collect();
        assert_eq!(given, [6, 7, 8]);
        assert_eq!(persisted_generation(dir.path()), "8");
        drop(setup);
        taker.join().unwrap();
    }

    #[test]
    fn an_accepted_deploy_dates_the_model_and_a_refused_one_does_not() {
        let dir = tempfile::tempdir().unwrap();
        let (setup, _incoming) = setup(dir.path(), 0);
        let mut serving = ServingModel::default();
        let mut numbered = 0;
        let refused = handle_deploy(&setup, b"no model", || true, &mut numbered, &mut serving);
        assert_eq!(refused.accepted, 0);
        assert_eq!(
            telemetry_report(&setup.counters, &serving).model_since_unix_ns,
            0
        );
        let before = std::time::SystemTime::now();
        let bytes = constant_model(0.1).to_bytes();
        let accepted = handle_deploy(&setup, &bytes, || true, &mut numbered, &mut serving);
        assert_eq!(accepted.accepted, 1);
        let since = telemetry_report(&setup.counters, &serving).model_since_unix_ns;
        let ns = |t: std::time::SystemTime| {
            t.duration_since(std::time::UNIX_EPOCH).unwrap().as_nanos() as u64
        };
        assert!(
            (ns(before)..=ns(std::time::SystemTime::now())).contains(&since),
            "{since}"
        );
    }

    #[test]
    fn with_no_serving_thread_taking_models_in_the_reply_says_so_and_the_next_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let (setup, _incoming) = setup(dir.path(), 1);
        let mut numbered = 1;
        let first = deploy(&setup, 0.1, &mut numbered);
        assert_eq!((first.accepted, first.generation), (1, 2));
        assert!(
            text(&first.message).contains("not serving yet"),
            "{}",
            text(&first.message)
        );
        let second = deploy(&setup, 0.2, &mut numbered);
        assert_eq!((second.accepted, second.generation), (0, 2));
        assert!(
            text(&second.message).contains("has not taken in generation 2 yet"),
            "{}",
            text(&second.message)
        );
        // The refused model was not persisted, and its number was not given out.
        assert_eq!(persisted_generation(dir.path()), "2");
        assert_eq!(numbered, 2);
    }

    #[test]
    fn a_model_for_a_stopped_serving_thread_is_refused_and_not_persisted() {
        let dir = tempfile::tempdir().unwrap();
        let (setup, incoming) = setup(dir.path(), 1);
        drop(incoming);
        let mut numbered = 1;
        let reply = deploy(&setup, 0.1, &mut numbered);
        assert_eq!((reply.accepted, reply.generation), (0, 1));
        assert!(text(&reply.message).contains("has stopped"));
        assert!(!dir.path().join("model.hxm").exists());
    }

    fn text(field: &[u8; hexacomp_protocol::TEXT_BYTES]) -> String {
        hexacomp_protocol::field_text(field)
    }
}
