//! The service and its clients as separate processes: results equal `predict`, hot swap in a
//! stream, refused deploys, SIGKILL and restart, invalid points.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use hexacomp_calibration::pipeline::Pipeline;
use hexacomp_calibration::plan::PlanOptions;
use hexacomp_calibration::train::{Architecture, TrainOptions};
use hexacomp_client::wire::RequestKind;
use hexacomp_client::{CompensatedPoint, DeployOutcome, PointStatus};
use hexacomp_core::compensator::{compensate_legs, compensate_pose};
use hexacomp_core::fused::FusedModel;
use hexacomp_core::model::Model;
use hexacomp_core::sampling::{SamplerOptions, WorkspaceSampler};
use hexacomp_core::stats::PoseErrorNorm;
use hexacomp_core::{Geometry, Pose, inverse_kinematics};
use hexacomp_tests::{ServiceProcess, path_str, test_uncertainty, unique_instance};
use hexacomp_virtual::{DEFAULT_MACHINE_SEED, ErrorModel, VirtualPlatform};

/// A small decoupled model of the default virtual machine, trained with `seed`, saved in `dir`.
fn small_model(dir: &Path, seed: u64) -> (Model, PathBuf) {
    let g = Geometry::prototype();
    let pipeline = Pipeline {
        plan: PlanOptions {
            count: 40,
            seed,
            ..Default::default()
        },
        train: TrainOptions {
            hidden_sizes: vec![1, 2, 3],
            restarts: 1,
            seed,
            ..Default::default()
        },
        ..Default::default()
    };
    let mut platform =
        VirtualPlatform::new(&g, &ErrorModel::default(), DEFAULT_MACHINE_SEED, seed).unwrap();
    let (_, measurements) = hexacomp_lab::measure_virtual(&pipeline.plan, &mut platform).unwrap();
    let calibration = pipeline
        .calibrate(&g, &measurements, &[Architecture::Decoupled], &|_, _| {})
        .unwrap();
    let model = calibration.models[0].1.model.clone();
    let path = dir.join(format!("model-{seed}.hxm"));
    model.save(&path).unwrap();
    (model, path)
}

fn poses(count: usize, seed: u64) -> Vec<Pose> {
    WorkspaceSampler::new(&Geometry::prototype(), seed, SamplerOptions::default())
        .unwrap()
        .samples(count)
        .unwrap()
}

fn assert_same(got: &CompensatedPoint, expected: &hexacomp_core::compensator::Compensated) {
    assert_eq!(got.legs, expected.legs);
    assert_eq!(got.corrections, expected.corrections);
    assert_eq!(got.status as u8, expected.status as u8);
    // The uncertainty travels as an f32.
    assert_eq!(
        got.uncertainty_mm,
        expected.uncertainty_mm.map(|sigma| f64::from(sigma as f32))
    );
}

#[test]
fn client_results_equal_predict_for_10000_poses_single_and_batched() {
    let dir = tempfile::tempdir().unwrap();
    let (mut model, path) = small_model(dir.path(), 1);
    // With an uncertainty, as `calibrate` writes a model.
    model.uncertainty = Some(test_uncertainty());
    model.save(&path).unwrap();
    let g = Geometry::prototype();
    let service =
        ServiceProcess::with_model(&unique_instance("equal"), &dir.path().join("state"), &path);
    let mut client = service.client().unwrap();
    let poses = poses(10_000, 3);
    let mut with_uncertainty = 0;
    for pose in &poses {
        let got = client.compensate_pose(pose.to_mm_deg()).unwrap();
        with_uncertainty += usize::from(got.uncertainty_mm.is_some());
        assert_same(
            &got,
            &compensate_pose(
                &g,
                Some(&FusedModel::new(&model)),
                &Pose::from_mm_deg(pose.to_mm_deg()),
            ),
        );
        assert_eq!(got.generation, 1);
    }
    assert!(
        with_uncertainty > 9_000,
        "{with_uncertainty} of 10000 answered with an uncertainty"
    );
    let points: Vec<[f64; 6]> = poses.iter().map(|p| p.to_mm_deg()).collect();
    let mut out = vec![CompensatedPoint::empty(); 1024];
    for chunk in points.chunks(1024) {
        let out = &mut out[..chunk.len()];
        client
            .compensate_batch(RequestKind::Poses, chunk, out)
            .unwrap();
        for (got, pose) in out.iter().zip(chunk) {
            assert_same(
                got,
                &compensate_pose(
                    &g,
                    Some(&FusedModel::new(&model)),
                    &Pose::from_mm_deg(*pose),
                ),
            );
        }
    }
    // Joints: the same numbers from the nominal legs.
    let legs: Vec<[f64; 6]> = poses
        .iter()
        .take(1024)
        .map(|p| inverse_kinematics(&g, &Pose::from_mm_deg(p.to_mm_deg())).lengths)
        .collect();
    let out = &mut out[..legs.len()];
    client
        .compensate_batch(RequestKind::Joints, &legs, out)
        .unwrap();
    for (got, q) in out.iter().zip(&legs) {
        assert_same(got, &compensate_legs(&g, Some(&FusedModel::new(&model)), q));
    }
    let status = client.status().unwrap();
    assert_eq!(status.requests, 10_000 + 10 + 1);
    assert_eq!(status.errors, 0);
}

#[test]
fn hot_swap_in_a_stream_of_requests_loses_nothing_and_never_mixes_a_batch() {
    let dir = tempfile::tempdir().unwrap();
    let (_, first) = small_model(dir.path(), 1);
    let (_, second) = small_model(dir.path(), 2);
    let service =
        ServiceProcess::with_model(&unique_instance("swap"), &dir.path().join("state"), &first);
    let mut client = service.client().unwrap();
    let points: Vec<[f64; 6]> = poses(8, 5).iter().map(|p| p.to_mm_deg()).collect();
    let mut out = [CompensatedPoint::empty(); 8];
    let mut generations = Vec::new();
    let mut stream = |generations: &mut Vec<u64>| {
        client
            .compensate_batch(RequestKind::Poses, &points, &mut out)
            .unwrap();
        let g = out[0].generation;
        assert!(
            out.iter().all(|p| p.generation == g),
            "a batch mixed generations"
        );
        assert!(out.iter().all(|p| p.status == PointStatus::Ok));
        generations.push(g);
    };
    // The stream runs before, during and after the deploy, however fast the machine: the deploy
    // starts once 1000 requests were answered, and the stream goes on for 1000 requests after the
    // deploy command has finished.
    const AROUND: usize = 1000;
    for _ in 0..AROUND {
        stream(&mut generations);
    }
    let instance = service.instance.clone();
    let deployer = std::thread::spawn(move || {
        let output = hexacomp_tests::run(
            "hexacomp-trainer",
            &[
                "deploy",
                "--instance",
                &instance,
                "--model",
                path_str(&second),
            ],
        );
        String::from_utf8_lossy(&output.stdout).into_owned()
            + &String::from_utf8_lossy(&output.stderr)
    });
    let deadline = Instant::now() + Duration::from_secs(120);
    while !deployer.is_finished() {
        assert!(Instant::now() < deadline, "the deploy did not finish");
        stream(&mut generations);
    }
    let during = generations.len() - AROUND;
    for _ in 0..AROUND {
        stream(&mut generations);
    }
    let said = deployer.join().unwrap();
    assert!(said.contains("accepted as generation 2"), "{said}");
    // Generation 1 then generation 2, switched once, never back; the switch came after the
    // deploy started and at the latest with the first request after it was reported done (the
    // reply comes once the model serves).
    let switch = generations
        .iter()
        .position(|g| *g == 2)
        .expect("the new model must have served");
    assert!(
        (AROUND..=AROUND + during).contains(&switch),
        "switched at request {switch}, the deploy ran during requests {AROUND}..{}",
        AROUND + during
    );
    assert!(generations[..switch].iter().all(|g| *g == 1));
    assert!(generations[switch..].iter().all(|g| *g == 2));
    eprintln!(
        "{} requests of 8 points, {during} during the deploy, switched at request {switch}",
        generations.len()
    );
}

#[test]
fn refused_deploys_leave_the_old_model_serving_and_say_why() {
    let dir = tempfile::tempdir().unwrap();
    let (_, first) = small_model(dir.path(), 1);
    let service = ServiceProcess::with_model(
        &unique_instance("refuse"),
        &dir.path().join("state"),
        &first,
    );
    let mut client = service.client().unwrap();
    let bytes = std::fs::read(&first).unwrap();
    let mut corrupt = bytes.clone();
    corrupt[40] ^= 0xff;
    let mut other_geometry = Model::from_bytes(&bytes).unwrap();
    other_geometry.geometry = hexacomp_core::Fingerprint(42);
    for (file, reason) in [
        (corrupt, "checksum mismatch"),
        (
            other_geometry.to_bytes(),
            "trained for geometry 000000000000002a",
        ),
        (b"not a model".to_vec(), "not a hexacomp model file"),
    ] {
        match client.deploy(&file).unwrap() {
            DeployOutcome::Refused {
                reason: said,
                generation,
            } => {
                assert!(said.contains(reason), "{said}");
                assert_eq!(generation, 1);
            }
            other => panic!("expected a refusal, got {other:?}"),
        }
        let point = client
            .compensate_pose([0.0, 0.0, 280.0, 0.0, 0.0, 0.0])
            .unwrap();
        assert_eq!((point.generation, point.status), (1, PointStatus::Ok));
    }
    assert_eq!(client.status().unwrap().generation, 1);
}

#[test]
fn after_sigkill_a_restarted_service_serves_the_last_accepted_model() {
    let dir = tempfile::tempdir().unwrap();
    let state = dir.path().join("state");
    let (_, first) = small_model(dir.path(), 1);
    let (second_model, second) = small_model(dir.path(), 2);
    let instance = unique_instance("kill");
    let service = ServiceProcess::start(
        &instance,
        &["--state-dir", path_str(&state), "--model", path_str(&first)],
    );
    let mut client = service.client().unwrap();
    let bytes = std::fs::read(&second).unwrap();
    assert!(matches!(
        client.deploy(&bytes).unwrap(),
        DeployOutcome::Accepted { generation: 2, .. }
    ));
    service.kill();
    // The connected client gets a clear error, not a hang.
    let error = client
        .compensate_pose([0.0, 0.0, 280.0, 0.0, 0.0, 0.0])
        .unwrap_err();
    assert!(
        matches!(error, hexacomp_client::Error::Timeout { .. }),
        "{error:?}"
    );
    // Restart without --model and without any cleanup: the persisted generation 2 serves.
    let service = ServiceProcess::start(&instance, &["--state-dir", path_str(&state)]);
    assert_eq!(service.client().unwrap().status().unwrap().generation, 2);
    // The old client works again once the service is back (a retry within its deadline).
    let g = Geometry::prototype();
    let pose = [5.0, -3.0, 290.0, 1.0, 2.0, -3.0];
    let deadline = Instant::now() + Duration::from_secs(10);
    let point = loop {
        match client.compensate_pose(pose) {
            Ok(point) => break point,
            Err(e) => assert!(Instant::now() < deadline, "the client did not recover: {e}"),
        }
    };
    assert_eq!(point.generation, 2);
    assert_same(
        &point,
        &compensate_pose(
            &g,
            Some(&FusedModel::new(&second_model)),
            &Pose::from_mm_deg(pose),
        ),
    );
}

#[test]
fn invalid_points_get_their_status_and_the_service_keeps_serving() {
    let dir = tempfile::tempdir().unwrap();
    let (model, path) = small_model(dir.path(), 1);
    let service = ServiceProcess::with_model(
        &unique_instance("invalid"),
        &dir.path().join("state"),
        &path,
    );
    let mut client = service.client().unwrap();
    let nan = client
        .compensate_pose([f64::NAN, 0.0, 280.0, 0.0, 0.0, 0.0])
        .unwrap();
    assert_eq!(nan.status, PointStatus::InvalidInput);
    let inf = client
        .compensate_joints([f64::INFINITY, 350.0, 350.0, 350.0, 350.0, 350.0])
        .unwrap();
    assert_eq!(inf.status, PointStatus::InvalidInput);
    let low = client
        .compensate_pose([0.0, 0.0, 100.0, 0.0, 0.0, 0.0])
        .unwrap();
    assert_eq!(low.status, PointStatus::OutOfStroke);
    let below_trained = model.training_range[0][0] - 1.0;
    let untrained = client
        .compensate_joints([below_trained.max(281.0), 350.0, 350.0, 350.0, 350.0, 350.0])
        .unwrap();
    assert_eq!(untrained.status, PointStatus::OutsideTrainedRange);
    let fine = client
        .compensate_pose([0.0, 0.0, 280.0, 0.0, 0.0, 0.0])
        .unwrap();
    assert_eq!(fine.status, PointStatus::Ok);
    assert!(fine.corrections.iter().any(|c| *c != 0.0));
}

#[test]
fn without_a_model_the_service_answers_nominal_inverse_kinematics() {
    let dir = tempfile::tempdir().unwrap();
    let service = ServiceProcess::start(
        &unique_instance("nomodel"),
        &["--state-dir", path_str(&dir.path().join("state"))],
    );
    let mut client = service.client().unwrap();
    let pose = [10.0, 20.0, 300.0, 3.0, -2.0, 5.0];
    let point = client.compensate_pose(pose).unwrap();
    assert_eq!((point.status, point.generation), (PointStatus::NoModel, 0));
    assert_eq!(
        point.legs,
        inverse_kinematics(&Geometry::prototype(), &Pose::from_mm_deg(pose)).lengths
    );
}

#[test]
fn a_second_service_for_the_same_instance_is_refused_and_the_absent_one_is_reported() {
    let dir = tempfile::tempdir().unwrap();
    let instance = unique_instance("twice");
    let absent = hexacomp_client::Client::connect(&instance, &Default::default()).unwrap_err();
    assert!(
        matches!(absent, hexacomp_client::Error::ServiceAbsent { .. }),
        "{absent:?}"
    );
    let service =
        ServiceProcess::start(&instance, &["--state-dir", path_str(&dir.path().join("a"))]);
    let mut first = service.client().unwrap();
    let output = std::process::Command::new(hexacomp_tests::binary("hexacomp-service"))
        .args([
            "--instance",
            &instance,
            "--state-dir",
            path_str(&dir.path().join("b")),
        ])
        .output()
        .unwrap();
    assert_eq!(output.status.code(), Some(1));
    let message = String::from_utf8_lossy(&output.stderr);
    assert!(
        message.contains("is already served by another hexacomp-service"),
        "{message}"
    );
    // The first service was not disturbed: its client is served as before.
    let point = first
        .compensate_pose([0.0, 0.0, 280.0, 0.0, 0.0, 0.0])
        .unwrap();
    assert_eq!(point.status, PointStatus::NoModel);
    assert_eq!(first.status().unwrap().errors, 0);
}

/// CPU time (user + system) a process has used, from /proc, in seconds.
fn cpu_seconds(pid: u32) -> f64 {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap();
    let fields: Vec<&str> = stat
        .rsplit(')')
        .next()
        .unwrap()
        .split_whitespace()
        .collect();
    let ticks: f64 = fields[11].parse::<f64>().unwrap() + fields[12].parse::<f64>().unwrap();
    // SAFETY: sysconf has no preconditions.
    ticks / unsafe { libc::sysconf(libc::_SC_CLK_TCK) } as f64
}

#[test]
fn event_mode_serves_the_same_numbers_swaps_and_leaves_the_core_free_when_idle() {
    let dir = tempfile::tempdir().unwrap();
    let (first_model, first) = small_model(dir.path(), 1);
    let (_, second) = small_model(dir.path(), 2);
    let service = ServiceProcess::start(
        &unique_instance("event"),
        &[
            "--state-dir",
            path_str(&dir.path().join("state")),
            "--model",
            path_str(&first),
            "--wait",
            "event",
        ],
    );
    let mut client = service.client().unwrap();
    assert_eq!(client.status().unwrap().wait_mode, "event");
    let g = Geometry::prototype();
    for pose in poses(2000, 9) {
        let values = pose.to_mm_deg();
        let got = client.compensate_pose(values).unwrap();
        assert_same(
            &got,
            &compensate_pose(
                &g,
                Some(&FusedModel::new(&first_model)),
                &Pose::from_mm_deg(values),
            ),
        );
    }
    let bytes = std::fs::read(&second).unwrap();
    assert!(matches!(
        client.deploy(&bytes).unwrap(),
        DeployOutcome::Accepted { generation: 2, .. }
    ));
    let point = client
        .compensate_pose([0.0, 0.0, 280.0, 0.0, 0.0, 0.0])
        .unwrap();
    assert_eq!(point.generation, 2);
    // Idle for a second: a spinning thread would use a whole core; the event-mode thread sleeps.
    let before = cpu_seconds(service.pid());
    std::thread::sleep(Duration::from_secs(1));
    let used = cpu_seconds(service.pid()) - before;
    assert!(
        used < 0.2,
        "an idle event-mode service used {used:.2} s of CPU in 1 s"
    );
}

/// A model whose answers are known by hand: for each leg `k` one tanh node on that leg's own
/// normalised length, `Δq_k = b2_k + w2_k · tanh(b1 + (q_k − mean) / span)` (Eq. 10, Eq. 11).
struct HandModel {
    model: Model,
    mean: f64,
    span: f64,
    b1: f64,
    w2: [f64; 6],
    b2: [f64; 6],
}

impl HandModel {
    fn new() -> Self {
        use hexacomp_core::model::{NetworkInput, Networks, Provenance};
        use hexacomp_core::network::{Network, Normalisation};
        let g = Geometry::prototype();
        let [min, max] = g.leg_range;
        let (mean, span, b1) = ((min + max) / 2.0, (max - min) / 2.0, 0.1);
        let w2: [f64; 6] = std::array::from_fn(|k| 0.2 + 0.05 * k as f64);
        let b2: [f64; 6] = std::array::from_fn(|k| 0.01 * (k as f64 - 2.5));
        // Weight order: input weights (6 per hidden node), hidden biases, output weights,
        // output biases.
        let network = |k: usize| {
            let mut weights = vec![0.0; Network::weight_count(1, 1)];
            weights[k] = 1.0;
            weights[6] = b1;
            weights[7] = w2[k];
            weights[8] = b2[k];
            Network::from_weights(1, 1, weights).unwrap()
        };
        let model = Model {
            networks: Networks::Decoupled((0..6).map(network).collect()),
            input: NetworkInput::Commanded,
            normalisation: Normalisation {
                mean: [mean; 6],
                span: [span; 6],
            },
            training_range: [g.leg_range; 6],
            correction_bounds: [[-1.0, 1.0]; 6],
            geometry: g.fingerprint(),
            provenance: Provenance {
                source: "hand-made known-answer model".into(),
                ..Provenance::default()
            },
            uncertainty: None,
        };
        Self {
            model,
            mean,
            span,
            b1,
            w2,
            b2,
        }
    }

    /// The correction of leg `k` at nominal length `q` (mm), by the formula.
    fn correction(&self, k: usize, q: f64) -> f64 {
        self.b2[k] + self.w2[k] * (self.b1 + (q - self.mean) / self.span).tanh()
    }
}

#[test]
fn served_corrections_equal_a_network_computed_by_hand() {
    let dir = tempfile::tempdir().unwrap();
    let hand = HandModel::new();
    let path = dir.path().join("hand.hxm");
    hand.model.save(&path).unwrap();
    let service =
        ServiceProcess::with_model(&unique_instance("hand"), &dir.path().join("state"), &path);
    let mut client = service.client().unwrap();
    let g = Geometry::prototype();
    let [min, max] = g.leg_range;
    let mut checked = 0;
    for i in 0..50 {
        let t = i as f64 / 49.0;
        // Leg lengths across the stroke (kept 2 mm inside it, so that the corrected legs stay in
        // it), each leg at another place.
        let legs: [f64; 6] =
            std::array::from_fn(|k| min + 2.0 + (max - min - 4.0) * ((t + k as f64 / 6.0) % 1.0));
        let point = client.compensate_joints(legs).unwrap();
        assert_eq!((point.status, point.generation), (PointStatus::Ok, 1));
        for (k, q) in legs.iter().enumerate() {
            let expected = hand.correction(k, *q);
            assert!(
                (point.corrections[k] - expected).abs() < 1e-12,
                "leg {k} at {q} mm: served {} mm, by hand {expected} mm",
                point.corrections[k]
            );
            assert!((point.legs[k] - (q + expected)).abs() < 1e-12);
        }
        checked += 1;
    }
    assert_eq!(checked, 50);
}

#[test]
fn served_corrections_bring_the_virtual_machine_closer_to_the_commanded_poses() {
    let dir = tempfile::tempdir().unwrap();
    let (_, path) = small_model(dir.path(), 1);
    let service =
        ServiceProcess::with_model(&unique_instance("truth"), &dir.path().join("state"), &path);
    let mut client = service.client().unwrap();
    let g = Geometry::prototype();
    // The machine the model was trained on (its repeatability noise from another seed).
    let mut machine =
        VirtualPlatform::new(&g, &ErrorModel::default(), DEFAULT_MACHINE_SEED, 77).unwrap();
    let targets = poses(100, 11);
    let (mut before, mut after) = (0.0, 0.0);
    for pose in &targets {
        let uncompensated = machine.move_to_pose(pose).unwrap();
        before += PoseErrorNorm::between(pose, &uncompensated).position_mm;
        let point = client.compensate_pose(pose.to_mm_deg()).unwrap();
        assert_ne!(point.status, PointStatus::OutOfStroke, "{pose:?}");
        let compensated = machine.move_legs(&point.legs, pose).unwrap();
        after += PoseErrorNorm::between(pose, &compensated).position_mm;
    }
    let (before, after) = (before / 100.0, after / 100.0);
    eprintln!("mean position error: {before:.4} mm uncompensated, {after:.4} mm compensated");
    assert!(
        after < before / 5.0,
        "compensation left {after:.4} mm of {before:.4} mm"
    );
}

#[test]
fn concurrent_deploys_get_unique_generations_in_the_order_they_take_effect() {
    let dir = tempfile::tempdir().unwrap();
    let state = dir.path().join("state");
    let (_, first) = hexacomp_tests::save_smooth_model(dir.path(), 60);
    let service = ServiceProcess::with_model(&unique_instance("deploys"), &state, &first);
    const DEPLOYERS: usize = 3;
    const ROUNDS: usize = 3;
    let files: Vec<Vec<u8>> = (0..DEPLOYERS)
        .map(|k| hexacomp_tests::smooth_model(61 + k as u64).to_bytes())
        .collect();
    let mut given = Vec::new();
    for _ in 0..ROUNDS {
        // Three deployers, released together, each with its own connection.
        let start = std::sync::Barrier::new(DEPLOYERS);
        let replies: Vec<u64> = std::thread::scope(|scope| {
            let threads: Vec<_> = files
                .iter()
                .map(|file| {
                    let (service, start) = (&service, &start);
                    scope.spawn(move || {
                        let mut client = service.client().unwrap();
                        start.wait();
                        match client.deploy(file).unwrap() {
                            DeployOutcome::Accepted { generation, .. } => generation,
                            refused => panic!("{refused:?}"),
                        }
                    })
                })
                .collect();
            threads.into_iter().map(|t| t.join().unwrap()).collect()
        });
        given.extend(replies);
    }
    given.sort_unstable();
    let expected: Vec<u64> = (2..2 + (DEPLOYERS * ROUNDS) as u64).collect();
    assert_eq!(given, expected, "each deploy names its own generation");
    // The last one given out is the one that serves, and the one persisted.
    let last = *expected.last().unwrap();
    let mut client = service.client().unwrap();
    let deadline = Instant::now() + Duration::from_secs(60);
    while client.status().unwrap().generation != last {
        assert!(Instant::now() < deadline, "generation {last} never served");
        std::thread::sleep(Duration::from_millis(5));
    }
    let persisted = std::fs::read_to_string(state.join("generation")).unwrap();
    assert_eq!(persisted.trim(), last.to_string());
}
