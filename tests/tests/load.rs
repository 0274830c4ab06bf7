//! Load, with real processes: sixteen NC-like clients beside two processes that only burn CPU,
//! then beside a client that floods full batches and one that never reads its responses; and a
//! memory soak (20 s here, five minutes with
//! `HEXACOMP_SOAK_SECONDS=300 cargo test --release -p hexacomp-tests --test load -- --nocapture
//! soak`).

use std::time::{Duration, Instant};

use hexacomp_client::DeployOutcome;
use hexacomp_tests::{
    ServiceProcess, memory_kib, save_smooth_model, spawn_test_client, test_client_report,
    unique_instance,
};

/// The two tests here each load both cores; one at a time.
static HEAVY: std::sync::Mutex<()> = std::sync::Mutex::new(());

const WELL_BEHAVED: usize = 16;

/// How long each phase streams, seconds.
const PHASE_SECONDS: &str = "2";

/// Rounds of the two phases. Other load on the machine can stall every process of a round for
/// 100 ms at a time (a CPU quota's period), which no control phase cancels out; a fairness defect
/// shows in every round. So the best round decides.
const ROUNDS: usize = 3;

/// Points per second each client may ask for in this test: far below what one serving thread
/// computes on any machine (about 2 M points/s here), so the flooder exceeds it everywhere.
const CLIENT_BUDGET: &str = "300000";

/// The share of their throughput the well-behaved clients may lose to the flooder and the
/// client that never reads, beyond the CPU those take. Measured on a 2-core machine, 22 runs:
/// 1–16 % lost on the whole and the worst client up to 20 % when idle or beside a release build,
/// 25 % (worst client 31 %) in one run with a package install beside it; the serving loop
/// without the fair queue lost 55–69 % (worst client 72–86 %).
const MAX_THROUGHPUT_LOSS: f64 = 0.4;

/// Starts the sixteen 1 kHz clients (every fourth sends batches of 16) and the misbehaving
/// clients `others` (test-client argument lists) at once; returns their reports.
fn run_phase(
    instance: &str,
    others: &[&[&str]],
) -> (Vec<serde_json::Value>, Vec<serde_json::Value>) {
    let good: Vec<_> = (0..WELL_BEHAVED)
        .map(|i| {
            let batch = if i % 4 == 0 { "16" } else { "1" };
            spawn_test_client(
                instance,
                &[
                    "stream",
                    "--seconds",
                    PHASE_SECONDS,
                    "--period-us",
                    "1000",
                    "--batch",
                    batch,
                ],
            )
        })
        .collect();
    let others: Vec<_> = others
        .iter()
        .map(|args| spawn_test_client(instance, args))
        .collect();
    (
        good.into_iter().map(test_client_report).collect(),
        others.into_iter().map(test_client_report).collect(),
    )
}

/// Every request of every well-behaved client answered within its 500 ms deadline, never
/// refused, every point computed.
fn assert_all_served(phase: &str, reports: &[serde_json::Value]) {
    for report in reports {
        assert_eq!(report["timeouts"], 0, "{phase}: {report}");
        assert_eq!(report["overloaded"], 0, "{phase}: {report}");
        assert_eq!(report["other_errors"], 0, "{phase}: {report}");
        assert_eq!(report["bad_points"], 0, "{phase}: {report}");
        assert!(
            report["requests"].as_u64().unwrap() > 0,
            "{phase}: {report}"
        );
    }
}

#[test]
fn sixteen_clients_keep_their_throughput_beside_a_flooder_and_a_client_that_never_reads() {
    let _heavy = HEAVY.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let (_, model) = save_smooth_model(dir.path(), 21);
    let instance = unique_instance("load16");
    let (state, model) = (dir.path().join("s"), model.to_str().unwrap().to_string());
    let service = ServiceProcess::start(
        &instance,
        &[
            "--state-dir",
            state.to_str().unwrap(),
            "--model",
            &model,
            "--client-budget",
            CLIENT_BUDGET,
        ],
    );
    // What the sixteen achieve on this machine beside two processes that take a core as the
    // misbehaving clients do but leave the service alone, then beside the misbehaving clients:
    // the difference is what the service's handling of them costs, not the CPU they burn. The
    // two phases alternate, twice, so that other load on the machine weighs on both alike.
    let burn_args: &[&str] = &["burn", "--seconds", PHASE_SECONDS];
    let flood_args: &[&str] = &["flood", "--seconds", PHASE_SECONDS];
    let silent_args: &[&str] = &["no-collect", "--seconds", PHASE_SECONDS];
    let (mut control, mut beside, mut misbehaving) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..ROUNDS {
        control.extend(run_phase(&instance, &[burn_args, burn_args]).0);
        let (good, others) = run_phase(&instance, &[flood_args, silent_args]);
        beside.extend(good);
        misbehaving.push(others);
    }
    assert_all_served("beside two CPU burners", &control);
    assert_all_served("beside a flooder", &beside);
    // The scenario happened, every round: the flooder was served and told "overloaded" beyond
    // its budget, the silent client hit its in-flight limit and went on sending.
    for others in &misbehaving {
        let (flood, silent) = (&others[0], &others[1]);
        assert!(flood["served"].as_u64().unwrap() > 0, "{flood}");
        assert!(flood["overloaded"].as_u64().unwrap() > 0, "{flood}");
        assert_eq!(flood["other"], 0, "{flood}");
        assert!(silent["limit_hits"].as_u64().unwrap() > 0, "{silent}");
    }
    let (flood, silent) = (&misbehaving[0][0], &misbehaving[0][1]);
    // Each client keeps its throughput, compared with itself beside the burners in the same
    // round; a round's figure is its worst client's.
    let requests = |r: &serde_json::Value| r["requests"].as_u64().unwrap() as f64;
    let worst_per_round: Vec<f64> = control
        .chunks(WELL_BEHAVED)
        .zip(beside.chunks(WELL_BEHAVED))
        .map(|(alone, with)| {
            alone
                .iter()
                .zip(with)
                .map(|(a, b)| requests(b) / requests(a))
                .fold(f64::INFINITY, f64::min)
        })
        .collect();
    let worst = worst_per_round.iter().cloned().fold(0.0, f64::max);
    let total =
        beside.iter().map(requests).sum::<f64>() / control.iter().map(requests).sum::<f64>();
    let status = service.client().unwrap().status().unwrap();
    let p50 = |reports: &[serde_json::Value]| {
        let mut p: Vec<f64> = reports
            .iter()
            .map(|r| r["p50_us"].as_f64().unwrap())
            .collect();
        p.sort_by(f64::total_cmp);
        p[p.len() / 2]
    };
    eprintln!(
        "{WELL_BEHAVED} clients at 1 kHz beside a flooder and a silent client kept {:.1} % of \
         their requests (worst client in the best round {:.1} %, in each round {:?}); median p50 {:.0} µs beside two CPU burners, {:.0} µs beside the misbehaving clients; \
         first round: flood served {} / overloaded {}, silent sent {} (limit hit {}); service: {} requests, \
         {} overloaded",
        100.0 * total,
        100.0 * worst,
        worst_per_round
            .iter()
            .map(|w| format!("{:.1} %", 100.0 * w))
            .collect::<Vec<_>>(),
        p50(&control),
        p50(&beside),
        flood["served"],
        flood["overloaded"],
        silent["sent"],
        silent["limit_hits"],
        status.requests,
        status.overloaded
    );
    assert!(
        worst >= 1.0 - MAX_THROUGHPUT_LOSS,
        "in the best round a well-behaved client kept only {:.1} % of its requests (allowed loss \
         {:.0} %): \
         beside the burners {control:?}, beside the misbehaving clients {beside:?}",
        100.0 * worst,
        100.0 * MAX_THROUGHPUT_LOSS
    );
    assert!(status.overloaded > 0);
    assert_eq!(status.errors, 0);
}

#[test]
fn soak_memory_stays_flat_through_streams_batches_swaps_and_client_churn() {
    let _heavy = HEAVY.lock().unwrap_or_else(|e| e.into_inner());
    let seconds: u64 = std::env::var("HEXACOMP_SOAK_SECONDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(20);
    let dir = tempfile::tempdir().unwrap();
    let models: Vec<_> = (0..2)
        .map(|seed| save_smooth_model(dir.path(), 30 + seed).1)
        .collect();
    let instance = unique_instance("soak");
    let service = ServiceProcess::with_model(&instance, &dir.path().join("s"), &models[0]);
    let streams: Vec<_> = [
        ("1", "1000"),
        ("64", "2000"),
        ("1024", "20000"),
        ("1", "200"),
    ]
    .iter()
    .map(|(batch, period)| {
        spawn_test_client(
            &instance,
            &["stream", "--batch", batch, "--period-us", period],
        )
    })
    .collect();
    let mut deployer = service.client().unwrap();
    let bytes: Vec<_> = models.iter().map(|m| std::fs::read(m).unwrap()).collect();
    let start = Instant::now();
    let mut samples: Vec<(f64, u64, u64)> = Vec::new();
    let mut deploys = 0usize;
    let mut churned = 0usize;
    while start.elapsed() < Duration::from_secs(seconds) {
        // Every second: a hot swap, a short-lived client that connects and leaves, a sample.
        let outcome = deployer.deploy(&bytes[deploys % 2]).unwrap();
        deploys += 1;
        assert!(
            matches!(outcome, DeployOutcome::Accepted { generation, .. }
                if generation == 1 + deploys as u64),
            "hot swap {deploys}: {outcome:?}"
        );
        let mut passing = service.client().unwrap();
        passing
            .compensate_pose([0.0, 0.0, 280.0, 0.0, 0.0, 0.0])
            .unwrap();
        drop(passing);
        churned += 1;
        let pid = service.pid();
        samples.push((
            start.elapsed().as_secs_f64(),
            memory_kib(pid, "VmRSS"),
            memory_kib(pid, "RssAnon"),
        ));
        std::thread::sleep(Duration::from_millis(1000));
    }
    for stream in streams {
        let report = test_client_report(stream);
        assert_eq!(report["timeouts"], 0, "{report}");
        assert_eq!(report["other_errors"], 0, "{report}");
    }
    // After a warm-up (first quarter), heap memory does not grow: compare the second quarter
    // with the last.
    let quarter = samples.len() / 4;
    let mean = |s: &[(f64, u64, u64)], f: fn(&(f64, u64, u64)) -> u64| {
        s.iter().map(f).sum::<u64>() as f64 / s.len() as f64
    };
    let early = &samples[quarter..2 * quarter];
    let late = &samples[samples.len() - quarter..];
    let anon_growth = mean(late, |s| s.2) - mean(early, |s| s.2);
    let rss_growth = mean(late, |s| s.1) - mean(early, |s| s.1);
    eprintln!(
        "soak {seconds} s: {deploys} hot swaps, {churned} short-lived clients; RSS {} → {} KiB \
         (growth {rss_growth:+.0} KiB after warm-up), heap {} → {} KiB (growth {anon_growth:+.0} KiB)",
        samples[0].1,
        samples.last().unwrap().1,
        samples[0].2,
        samples.last().unwrap().2
    );
    assert!(
        anon_growth < 512.0,
        "heap grew {anon_growth:.0} KiB: {samples:?}"
    );
    assert!(
        rss_growth < 2048.0,
        "RSS grew {rss_growth:.0} KiB: {samples:?}"
    );
}
