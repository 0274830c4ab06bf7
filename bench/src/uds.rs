//! The `uds` baseline: the same compensation served over a Unix domain socket with blocking
//! reads — what a user would otherwise build. One thread per connection; the server computes
//! with the service's own [`compute_points`], two points at a time as the service does.
//!
//! Frames, little-endian: a request is `count: u32, kind: u32` and `count` points of six `f64`;
//! the response is `count` points of `legs: 6 × f64, corrections: 6 × f64, generation: u64,
//! status: u8`, 3 bytes of padding and `uncertainty_mm: f32` (the [`PointResponse`] layout,
//! 112 bytes).

use std::io::{Read, Write};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::Path;
use std::time::Duration;

use anyhow::{Context, ensure};
use hexacomp_client::CompensatedPoint;
use hexacomp_client::wire::{MAX_BATCH, PointRequest, PointResponse, RequestKind};
use hexacomp_core::Geometry;
use hexacomp_service::Generation;
use hexacomp_service::serving::compute_points;
use hexacomp_service::termination::TerminationSignals;

const HEADER_BYTES: usize = 8;
const POINT_BYTES: usize = 48;
const RESPONSE_BYTES: usize = 112;

/// Serves compensation on a socket at `path` until SIGTERM or SIGINT, then removes the socket
/// file and returns.
pub fn serve(path: &Path, geometry: Geometry, model: Option<Generation>) -> anyhow::Result<()> {
    // Blocked before any thread starts: every thread inherits the mask, and the signal waits
    // for this thread.
    let termination = TerminationSignals::block()?;
    let _ = std::fs::remove_file(path);
    let listener =
        UnixListener::bind(path).with_context(|| format!("binding {}", path.display()))?;
    let shared = std::sync::Arc::new((geometry, model));
    let socket = path.to_path_buf();
    std::thread::spawn(move || {
        for stream in listener.incoming() {
            let stream = match stream {
                Ok(stream) => stream,
                Err(e) => {
                    eprintln!("error: accepting a connection: {e}");
                    let _ = std::fs::remove_file(&socket);
                    std::process::exit(1);
                }
            };
            let shared = shared.clone();
            std::thread::spawn(move || {
                let (geometry, model) = &*shared;
                // A client that hangs up ends its thread; nothing to report.
                let _ = serve_connection(stream, geometry, model.as_ref());
            });
        }
    });
    while termination.wait(Duration::from_secs(1)).is_none() {}
    let _ = std::fs::remove_file(path);
    Ok(())
}

fn serve_connection(
    mut stream: UnixStream,
    geometry: &Geometry,
    model: Option<&Generation>,
) -> std::io::Result<()> {
    let mut request = vec![0u8; MAX_BATCH * POINT_BYTES];
    let mut response = vec![0u8; MAX_BATCH * RESPONSE_BYTES];
    loop {
        let mut header = [0u8; HEADER_BYTES];
        stream.read_exact(&mut header)?;
        let count = u32::from_le_bytes(header[0..4].try_into().expect("4 bytes")) as usize;
        let kind = match u32::from_le_bytes(header[4..8].try_into().expect("4 bytes")) {
            1 => RequestKind::Joints,
            _ => RequestKind::Poses,
        };
        if count > MAX_BATCH {
            return Err(std::io::Error::other("batch too large"));
        }
        stream.read_exact(&mut request[..count * POINT_BYTES])?;
        compute_points(
            geometry,
            model,
            kind,
            count,
            |i| PointRequest {
                values: read_f64s::<6>(&request[i * POINT_BYTES..]),
            },
            |i, answer| write_response(&mut response[i * RESPONSE_BYTES..], &answer),
        );
        stream.write_all(&response[..count * RESPONSE_BYTES])?;
    }
}

fn read_f64s<const N: usize>(bytes: &[u8]) -> [f64; N] {
    std::array::from_fn(|i| f64::from_le_bytes(bytes[i * 8..i * 8 + 8].try_into().expect("8")))
}

fn write_response(out: &mut [u8], point: &PointResponse) {
    for (i, v) in point.legs.iter().chain(&point.corrections).enumerate() {
        out[i * 8..i * 8 + 8].copy_from_slice(&v.to_le_bytes());
    }
    out[96..104].copy_from_slice(&point.generation.to_le_bytes());
    out[104] = point.status;
    out[105..108].fill(0);
    out[108..112].copy_from_slice(&point.uncertainty_mm.to_le_bytes());
}

/// A client of the socket server.
#[derive(Debug)]
pub struct UdsClient {
    stream: UnixStream,
    request: Vec<u8>,
    response: Vec<u8>,
}

impl UdsClient {
    /// Connects to the server at `path`.
    pub fn connect(path: &Path) -> anyhow::Result<Self> {
        let stream = UnixStream::connect(path)
            .with_context(|| format!("connecting to {}", path.display()))?;
        Ok(Self {
            stream,
            request: vec![0u8; HEADER_BYTES + MAX_BATCH * POINT_BYTES],
            response: vec![0u8; MAX_BATCH * RESPONSE_BYTES],
        })
    }

    /// Compensates up to [`MAX_BATCH`] poses (mm, degrees), one result per pose into `out`.
    pub fn compensate(
        &mut self,
        poses: &[[f64; 6]],
        out: &mut [CompensatedPoint],
    ) -> anyhow::Result<()> {
        ensure!(
            poses.len() <= MAX_BATCH && poses.len() == out.len(),
            "one output per pose, at most {MAX_BATCH}"
        );
        let count = poses.len();
        self.request[0..4].copy_from_slice(&(count as u32).to_le_bytes());
        self.request[4..8].copy_from_slice(&(RequestKind::Poses as u32).to_le_bytes());
        for (i, pose) in poses.iter().enumerate() {
            let at = HEADER_BYTES + i * POINT_BYTES;
            for (j, v) in pose.iter().enumerate() {
                self.request[at + j * 8..at + j * 8 + 8].copy_from_slice(&v.to_le_bytes());
            }
        }
        self.stream
            .write_all(&self.request[..HEADER_BYTES + count * POINT_BYTES])?;
        self.stream
            .read_exact(&mut self.response[..count * RESPONSE_BYTES])?;
        for (i, slot) in out.iter_mut().enumerate() {
            let bytes = &self.response[i * RESPONSE_BYTES..];
            *slot = CompensatedPoint::from(&PointResponse {
                legs: read_f64s::<6>(bytes),
                corrections: read_f64s::<6>(&bytes[48..]),
                generation: u64::from_le_bytes(bytes[96..104].try_into().expect("8")),
                status: bytes[104],
                reserved: [0; 3],
                uncertainty_mm: f32::from_le_bytes(bytes[108..112].try_into().expect("4")),
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hexacomp_client::PointStatus;
    use hexacomp_core::Pose;
    use hexacomp_core::compensator::compensate_pose;

    #[test]
    fn socket_answers_equal_the_direct_computation() {
        let dir = tempfile::tempdir().unwrap();
        let socket = dir.path().join("bench.sock");
        let geometry = Geometry::prototype();
        {
            let (socket, geometry) = (socket.clone(), geometry.clone());
            std::thread::spawn(move || serve(&socket, geometry, None));
        }
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(5);
        let mut client = loop {
            match UdsClient::connect(&socket) {
                Ok(client) => break client,
                Err(_) if std::time::Instant::now() < deadline => {
                    std::thread::sleep(std::time::Duration::from_millis(5))
                }
                Err(e) => panic!("{e:#}"),
            }
        };
        let poses = [
            [0.0, 0.0, 280.0, 0.0, 0.0, 0.0],
            [12.5, -30.0, 300.0, 4.0, -3.0, 7.0],
            [0.0, 0.0, 900.0, 0.0, 0.0, 0.0],
        ];
        let mut out = [CompensatedPoint::empty(); 3];
        client.compensate(&poses, &mut out).unwrap();
        for (pose, got) in poses.iter().zip(&out) {
            let want = compensate_pose(
                &geometry,
                None::<&hexacomp_core::fused::FusedModel>,
                &Pose::from_mm_deg(*pose),
            );
            assert_eq!(got.legs, want.legs);
            assert_eq!(got.status as u8, want.status as u8);
        }
        assert_eq!(out[2].status, PointStatus::OutOfStroke);
    }
}
