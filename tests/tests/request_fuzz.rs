//! Request handling fuzzed over the wire: a real service, and a raw iceoryx2 client that sends
//! what `hexacomp-client` never would: every bit pattern of a point (NaN, ±∞, subnormals, huge
//! values), any protocol version and kind, any count up to and beyond a request's limit. Each
//! request gets an answer within its deadline, with the outcome its header calls for, and each
//! point exactly what the compensator computes in this process. Longer runs:
//! `HEXACOMP_FUZZ_REQUESTS=100000 cargo test --release -p hexacomp-tests --test request_fuzz`.

use std::time::{Duration, Instant};

use hexacomp_client::wire::{
    MAX_BATCH, PROTOCOL_VERSION, PointRequest, RequestHeader, RequestKind, RequestOutcome,
};
use hexacomp_core::Geometry;
use hexacomp_core::compensator::{PointStatus, compensate_legs, compensate_pose};
use hexacomp_core::fused::FusedModel;
use hexacomp_core::pose::Pose;
use hexacomp_tests::{
    ServiceProcess, raw_client, save_smooth_model, spawn_test_client, test_client_report,
    unique_instance,
};

/// SplitMix64: a small deterministic generator, so that a failure replays from its seed.
struct Random(u64);

impl Random {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }

    /// A value a fuzzer would pick: any bit pattern, a special value, or a plausible one.
    fn value(&mut self, plausible: f64) -> f64 {
        const SPECIAL: [f64; 10] = [
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::MIN_POSITIVE / 4.0,
            -0.0,
            0.0,
            f64::MAX,
            f64::MIN,
            1e300,
            -1e-310,
        ];
        match self.below(4) {
            0 => f64::from_bits(self.next()),
            1 => SPECIAL[self.below(SPECIAL.len() as u64) as usize],
            _ => plausible + (self.below(2001) as f64 - 1000.0) / 100.0,
        }
    }
}

/// Requests per run: 3000, or `HEXACOMP_FUZZ_REQUESTS`.
fn requests() -> usize {
    std::env::var("HEXACOMP_FUZZ_REQUESTS")
        .ok()
        .and_then(|n| n.parse().ok())
        .unwrap_or(3000)
}

#[test]
fn any_request_gets_its_outcome_and_every_point_exactly_the_compensators_answer() {
    let dir = tempfile::tempdir().unwrap();
    let (model, path) = save_smooth_model(dir.path(), 11);
    let instance = unique_instance("fuzzwire");
    let service = ServiceProcess::with_model(&instance, &dir.path().join("s"), &path);
    let g = Geometry::prototype();
    let (_node, _factory, client) = raw_client(&instance, MAX_BATCH).unwrap();
    let mut random = Random(0x5eed_0001);
    let mut outcomes = [0usize; 3];
    let mut statuses = [0usize; 6];
    let requests = requests();
    for r in 0..requests {
        let protocol = match random.below(8) {
            0 => random.next() as u32,
            _ => PROTOCOL_VERSION,
        };
        let kind = match random.below(8) {
            0 => random.next() as u32,
            k => (k % 2) as u32,
        };
        let count = match random.below(16) {
            0 => 0,
            1 => MAX_BATCH,
            _ => 1 + random.below(40) as usize,
        };
        let points: Vec<[f64; 6]> = (0..count)
            .map(|_| {
                if kind == RequestKind::Joints as u32 {
                    std::array::from_fn(|_| random.value(355.0))
                } else {
                    let plausible = [0.0, 0.0, 280.0, 0.0, 0.0, 0.0];
                    std::array::from_fn(|i| random.value(plausible[i]))
                }
            })
            .collect();
        let mut request = client.loan_slice_uninit(count).unwrap();
        *request.user_header_mut() = RequestHeader { protocol, kind };
        let request = request.write_from_fn(|i| PointRequest { values: points[i] });
        let pending = request.send().unwrap();
        let deadline = Instant::now() + Duration::from_secs(2);
        let response = loop {
            if let Some(response) = pending.receive().unwrap() {
                break response;
            }
            assert!(Instant::now() < deadline, "request {r} got no answer");
            std::thread::yield_now();
        };
        let header = *response.user_header();
        assert_eq!(header.protocol, PROTOCOL_VERSION);
        let expected = if protocol != PROTOCOL_VERSION {
            RequestOutcome::ProtocolMismatch
        } else if kind > 1 {
            RequestOutcome::UnknownKind
        } else {
            RequestOutcome::Served
        };
        assert_eq!(header.outcome, expected as u32, "request {r}");
        outcomes[expected as usize] += 1;
        if expected != RequestOutcome::Served {
            assert!(response.payload().is_empty());
            continue;
        }
        assert_eq!(response.payload().len(), count);
        for (point, answer) in points.iter().zip(response.payload()) {
            let local = if kind == RequestKind::Joints as u32 {
                compensate_legs(&g, Some(&FusedModel::new(&model)), point)
            } else {
                compensate_pose(
                    &g,
                    Some(&FusedModel::new(&model)),
                    &Pose::from_mm_deg(*point),
                )
            };
            let status = PointStatus::from_u8(answer.status).expect("a known status");
            assert_eq!(status, local.status, "request {r} point {point:?}");
            statuses[status as usize] += 1;
            let same = |a: &[f64; 6], b: &[f64; 6]| {
                a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
            };
            assert!(same(&answer.legs, &local.legs), "request {r} {point:?}");
            assert!(same(&answer.corrections, &local.corrections));
            assert_eq!(answer.generation, 1);
            assert_eq!(answer.reserved, [0; 3]);
            assert_eq!(
                answer.uncertainty_mm.to_bits(),
                local.uncertainty_mm.map_or(0.0f32, |s| s as f32).to_bits()
            );
        }
    }
    // The fuzzer reached every outcome and the statuses a point can have with a model.
    assert!(outcomes.iter().all(|n| *n > 0), "outcomes {outcomes:?}");
    for status in [
        PointStatus::Ok,
        PointStatus::OutOfStroke,
        PointStatus::InvalidInput,
    ] {
        assert!(statuses[status as usize] > 0, "statuses {statuses:?}");
    }
    eprintln!("{requests} requests: outcomes {outcomes:?}, point statuses {statuses:?}");

    // A request beyond the limit (a client port made for bigger loans) gets its own outcome.
    let report = test_client_report(spawn_test_client(
        &instance,
        &["oversize", "--points", "4096"],
    ));
    assert_eq!(report["outcome"], RequestOutcome::BatchTooLarge as u32);
    assert_eq!(report["points"], 0);
    // The service still serves well-formed requests, and counted every refusal.
    let mut ok = service.client().unwrap();
    ok.compensate_pose([0.0, 0.0, 280.0, 0.0, 0.0, 0.0])
        .unwrap();
    let status = ok.status().unwrap();
    assert_eq!(
        status.errors as usize,
        outcomes[1] + outcomes[2] + 1,
        "refusals counted"
    );
}
