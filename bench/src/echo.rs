//! The `echo` baseline: an iceoryx2 server with the service's endpoints, payload types and
//! busy-polling loop that answers every compensation request without computing anything (the
//! legs it returns are the request's values). What it costs is the transport floor under
//! hexacomp's round trip.

use anyhow::Context;
use hexacomp_client::wire::endpoints::{self, Role};
use hexacomp_client::wire::{
    DeployReply, PROTOCOL_VERSION, PointResponse, RequestOutcome, ResponseHeader, StatusReport,
    WAIT_SPIN, text_field,
};
use hexacomp_service::serving::compensation_endpoint;
use iceoryx2::prelude::*;
use iceoryx2_bb_posix::signal::SignalHandler;

/// Serves `instance` until SIGINT/SIGTERM, answering compensation requests with their own
/// values, status queries with a report naming the echo server, and deploys with a refusal.
pub fn serve(instance: &str) -> anyhow::Result<()> {
    set_log_level_from_env_or(LogLevel::Error);
    let node = NodeBuilder::new()
        .create::<ipc::Service>()
        .context("creating the iceoryx2 node")?;
    // The service's own endpoint: same sizes, same server settings.
    let (_compensate_service, compensate) =
        compensation_endpoint(&node, instance).map_err(anyhow::Error::msg)?;
    let status_service = endpoints::status(&node, instance, Role::Serve)?;
    let status = status_service
        .server_builder()
        .create()
        .map_err(|e| anyhow::anyhow!("echo status port: {e:?}"))?;
    let deploy_service = endpoints::deploy(&node, instance, Role::Serve)?;
    let deploy = deploy_service
        .server_builder()
        .create()
        .map_err(|e| anyhow::anyhow!("echo deploy port: {e:?}"))?;

    let mut idle_polls = 0u32;
    loop {
        match compensate.receive() {
            Ok(Some(active)) => {
                let count = active.payload().len();
                let loan = active
                    .loan_slice_uninit(count)
                    .map_err(|e| anyhow::anyhow!("loaning a response: {e:?}"))?;
                let mut response = loan.write_from_fn(|i| PointResponse {
                    legs: active.payload()[i].values,
                    ..PointResponse::default()
                });
                *response.user_header_mut() = ResponseHeader {
                    protocol: PROTOCOL_VERSION,
                    outcome: RequestOutcome::Served as u32,
                    generation: 0,
                };
                response
                    .send()
                    .map_err(|e| anyhow::anyhow!("sending a response: {e:?}"))?;
            }
            Ok(None) => {
                std::hint::spin_loop();
                idle_polls += 1;
                // Termination signals (iceoryx2's handler: the echo server is the bench's own
                // child, stopped by the bench), and the other endpoints
                // every few thousand idle polls.
                if SignalHandler::termination_requested() {
                    return Ok(());
                }
                if idle_polls >= 4096 {
                    idle_polls = 0;
                    answer_control(&status, &deploy)?;
                }
            }
            Err(e) => anyhow::bail!("receiving a request: {e:?}"),
        }
    }
}

type StatusServer = iceoryx2::port::server::Server<ipc::Service, u64, (), StatusReport, ()>;
type DeployServer = iceoryx2::port::server::Server<ipc::Service, [u8], (), DeployReply, ()>;

fn answer_control(status: &StatusServer, deploy: &DeployServer) -> anyhow::Result<()> {
    if let Ok(Some(request)) = status.receive() {
        request
            .send_copy(StatusReport {
                protocol: PROTOCOL_VERSION,
                wait_mode: WAIT_SPIN,
                geometry_fingerprint: 0,
                generation: 0,
                requests: 0,
                points: 0,
                errors: 0,
                overloaded: 0,
                persist_failures: 0,
                uptime_ns: 0,
                geometry_name: text_field("echo (hexacomp-bench transport floor)"),
                model: text_field(""),
            })
            .map_err(|e| anyhow::anyhow!("answering status: {e:?}"))?;
    }
    if let Ok(Some(request)) = deploy.receive() {
        request
            .send_copy(DeployReply {
                accepted: 0,
                reserved: [0; 7],
                generation: 0,
                message: text_field("the echo server takes no models"),
            })
            .map_err(|e| anyhow::anyhow!("answering deploy: {e:?}"))?;
    }
    Ok(())
}
