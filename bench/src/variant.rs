//! The ways a pose can be compensated, measured side by side: over iceoryx2 by the service
//! (`hexacomp`) or by the echo server (`echo`), over a Unix domain socket (`uds`), or by calling
//! the computation directly (`inprocess`).

use std::path::Path;

use hexacomp_client::wire::{PointRequest, RequestKind};
use hexacomp_client::{Client, ClientOptions, CompensatedPoint};
use hexacomp_core::Geometry;
use hexacomp_service::Generation;
use hexacomp_service::serving::compute_points;

use crate::uds::UdsClient;

/// One way of compensating poses.
pub trait Variant {
    /// Compensates `poses` (`[x, y, z, a, b, c]`, mm and degrees), one result per pose into
    /// `out`.
    fn compensate(
        &mut self,
        poses: &[[f64; 6]],
        out: &mut [CompensatedPoint],
    ) -> anyhow::Result<()>;
}

/// A variant reached through `hexacomp-client` over iceoryx2 (`hexacomp` or `echo`).
pub struct OverIceoryx {
    client: Client,
}

impl OverIceoryx {
    /// Connects to the service (or echo server) of `instance`.
    pub fn connect(instance: &str) -> anyhow::Result<Self> {
        Ok(Self {
            client: Client::connect(instance, &ClientOptions::default())?,
        })
    }
}

impl Variant for OverIceoryx {
    fn compensate(
        &mut self,
        poses: &[[f64; 6]],
        out: &mut [CompensatedPoint],
    ) -> anyhow::Result<()> {
        Ok(self
            .client
            .compensate_batch(RequestKind::Poses, poses, out)?)
    }
}

/// The `uds` baseline.
pub struct OverSocket(UdsClient);

impl OverSocket {
    /// Connects to the socket server at `path`.
    pub fn connect(path: &Path) -> anyhow::Result<Self> {
        Ok(Self(UdsClient::connect(path)?))
    }
}

impl Variant for OverSocket {
    fn compensate(
        &mut self,
        poses: &[[f64; 6]],
        out: &mut [CompensatedPoint],
    ) -> anyhow::Result<()> {
        self.0.compensate(poses, out)
    }
}

/// The `inprocess` baseline: the service's own computation (`compute_points`), called directly.
pub struct InProcess {
    geometry: Geometry,
    model: Option<Generation>,
}

impl InProcess {
    /// Compensates with `model` (generation 1) for `geometry`.
    pub fn new(geometry: Geometry, model: Option<hexacomp_core::model::Model>) -> Self {
        Self {
            geometry,
            model: model.map(|model| Generation::new(&model, 1)),
        }
    }
}

impl Variant for InProcess {
    fn compensate(
        &mut self,
        poses: &[[f64; 6]],
        out: &mut [CompensatedPoint],
    ) -> anyhow::Result<()> {
        let count = poses.len().min(out.len());
        compute_points(
            &self.geometry,
            self.model.as_ref(),
            RequestKind::Poses,
            count,
            |i| PointRequest { values: poses[i] },
            |i, point| out[i] = CompensatedPoint::from(&point),
        );
        Ok(())
    }
}
