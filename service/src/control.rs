//! The control thread: status and deploy endpoints. Models are validated and persisted here, then
//! handed to the serving thread; retired models come back here to be freed.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use crossbeam_channel::{Receiver, Sender};
use hexacomp_client::wire::{
    DeployReply, MAX_CLIENTS, MAX_NODES, PROTOCOL_VERSION, StatusReport, text_field,
};
use hexacomp_client::{Endpoint, iceoryx_name};
use hexacomp_core::Geometry;
use iceoryx2::prelude::*;

use crate::{Counters, Generation, state, validate};

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
/// a 1 ms interval a visible p99.9 bump); status and deploy answers wait up to this long.
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
    /// How the serving thread waits (status report value).
    pub wait_mode: u32,
}

/// A one-line summary of a model for the status report.
pub fn summarise(model: &hexacomp_core::model::Model) -> String {
    let p = &model.provenance;
    format!(
        "hidden {:?}, {} legs, {} configurations, validation RMSE {:.4} mm; {}",
        model.hidden_nodes(),
        model.input.name(),
        p.configurations,
        p.validation_rmse_mm,
        p.source
    )
}

/// Creates the status and deploy endpoints and serves them until stopped.
pub fn run(setup: ControlSetup, ready: Sender<Result<(), String>>) {
    let started = (|| -> Result<_, String> {
        let node = NodeBuilder::new()
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .create::<ipc::Service>()
            .map_err(|e| format!("creating the iceoryx2 node: {e}"))?;
        let name = |endpoint| iceoryx_name(&setup.instance, endpoint).map_err(|e| e.to_string());
        let status_service = node
            .service_builder(&name(Endpoint::Status)?)
            .request_response::<u64, StatusReport>()
            .max_clients(MAX_CLIENTS)
            .max_servers(1)
            .max_nodes(MAX_NODES)
            .open_or_create()
            .map_err(|e| format!("status endpoint: {e:?}"))?;
        let deploy_service = node
            .service_builder(&name(Endpoint::Deploy)?)
            .request_response::<[u8], DeployReply>()
            .max_clients(MAX_CLIENTS)
            .max_servers(1)
            .max_nodes(MAX_NODES)
            .open_or_create()
            .map_err(|e| format!("deploy endpoint: {e:?}"))?;
        let status = status_service
            .server_builder()
            .create()
            .map_err(|e| format!("status server: {e:?}"))?;
        let deploy = deploy_service
            .server_builder()
            .create()
            .map_err(|e| format!("deploy server: {e:?}"))?;
        Ok((node, status_service, deploy_service, status, deploy))
    })();
    let (node, _s, _d, status, deploy) = match started {
        Ok(parts) => {
            let _ = ready.send(Ok(()));
            parts
        }
        Err(e) => {
            let _ = ready.send(Err(e));
            return;
        }
    };
    let start = Instant::now();
    let mut summary = setup.initial_summary.clone();
    // The last generation number given out. Only this thread numbers models, one deploy at a
    // time, so numbers are unique and increase in the order the models are handed over (the
    // serving thread's counter lags until it takes a model in).
    let mut numbered = setup.counters.generation.load(Ordering::Relaxed);
    while !setup.stop.load(Ordering::Relaxed) {
        let mut busy = false;
        while let Ok(old) = setup.retired.try_recv() {
            drop(old);
        }
        if let Ok(Some(request)) = status.receive() {
            busy = true;
            let c = &setup.counters;
            let report = StatusReport {
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
                model: text_field(&summary),
            };
            if let Err(e) = request.send_copy(report) {
                tracing::warn!("answering a status request failed: {e:?}");
            }
        }
        if let Ok(Some(request)) = deploy.receive() {
            busy = true;
            // A deployer killed before the answer leaves the old model serving: its dead node is
            // cleaned up, which disconnects its request, and the validated model is dropped.
            let deployer_alive = || {
                node.try_cleanup_dead_nodes();
                request.is_connected()
            };
            let reply = handle_deploy(
                &setup,
                request.payload(),
                deployer_alive,
                &mut numbered,
                &mut summary,
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

/// Validates, persists and hands over a deployed model as generation `numbered + 1`, unless it is
/// refused or its deployer is gone by the time it is validated (`deployer_alive`, asked once,
/// just before committing). `numbered` is the last generation number given out.
fn handle_deploy(
    setup: &ControlSetup,
    bytes: &[u8],
    deployer_alive: impl FnOnce() -> bool,
    numbered: &mut u64,
    summary: &mut String,
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
        Err(why) => return refuse(why),
    };
    if !deployer_alive() {
        return refuse("the deployer disconnected before the model was committed".into());
    }
    let number = latest + 1;
    let mut note = String::new();
    if let Err(e) = state::persist(&setup.state_dir, &model, number) {
        tracing::error!("accepted generation {number} but could not persist it: {e}");
        setup
            .counters
            .persist_failures
            .fetch_add(1, Ordering::Relaxed);
        note = format!("accepted but not persisted: {e}");
    }
    let line = summarise(&model);
    let generation = Box::new(Generation { model, number });
    if setup.outgoing.send(generation).is_err() {
        return refuse("the serving thread has stopped".into());
    }
    *numbered = number;
    // The reply says the model serves: wait until the serving thread has taken it in (between
    // two requests; within its 10 ms tick when it sleeps in event mode).
    let deadline = Instant::now() + TAKE_IN_PATIENCE;
    while setup.counters.generation.load(Ordering::Relaxed) < number {
        if Instant::now() >= deadline {
            tracing::warn!("generation {number} was not taken in within {TAKE_IN_PATIENCE:?}");
            note = join(
                note,
                "accepted, not serving yet: the serving thread has not taken it in",
            );
            break;
        }
        std::thread::sleep(Duration::from_micros(100));
    }
    *summary = line;
    tracing::info!("accepted a model as generation {number}");
    DeployReply {
        accepted: 1,
        reserved: [0; 7],
        generation: number,
        message: text_field(&note),
    }
}
