//! Load, with real processes: sixteen NC-like clients beside a client that floods full batches
//! and one that never reads its responses; and a memory soak (20 s here, five minutes with
//! `HEXACOMP_SOAK_SECONDS=300 cargo test --release -p hexacomp-tests --test load -- --nocapture
//! soak`).

use std::time::{Duration, Instant};

use hexacomp_tests::{
    ServiceProcess, memory_kib, save_smooth_model, spawn_test_client, test_client_report,
    unique_instance,
};

/// The two tests here each load both cores; one at a time.
static HEAVY: std::sync::Mutex<()> = std::sync::Mutex::new(());

const WELL_BEHAVED: usize = 16;

#[test]
fn sixteen_clients_are_served_beside_a_flooder_and_a_client_that_never_reads() {
    let _heavy = HEAVY.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let (_, model) = save_smooth_model(dir.path(), 21);
    let instance = unique_instance("load16");
    let service = ServiceProcess::with_model(&instance, &dir.path().join("s"), &model);
    let seconds = "6";
    let good: Vec<_> = (0..WELL_BEHAVED)
        .map(|i| {
            let batch = if i % 4 == 0 { "16" } else { "1" };
            spawn_test_client(
                &instance,
                &[
                    "stream",
                    "--seconds",
                    seconds,
                    "--period-us",
                    "1000",
                    "--batch",
                    batch,
                ],
            )
        })
        .collect();
    let flood = spawn_test_client(&instance, &["flood", "--seconds", seconds]);
    let silent = spawn_test_client(&instance, &["no-collect", "--seconds", seconds]);
    let reports: Vec<_> = good.into_iter().map(test_client_report).collect();
    let flood = test_client_report(flood);
    let silent = test_client_report(silent);

    let mut worst_p99: f64 = 0.0;
    let mut worst_max: f64 = 0.0;
    for report in &reports {
        // Every request of every well-behaved client answered within its 500 ms deadline,
        // never refused, every point computed.
        assert_eq!(report["timeouts"], 0, "{report}");
        assert_eq!(report["overloaded"], 0, "{report}");
        assert_eq!(report["other_errors"], 0, "{report}");
        assert_eq!(report["bad_points"], 0, "{report}");
        assert!(report["requests"].as_u64().unwrap() >= 500, "{report}");
        worst_p99 = worst_p99.max(report["p99_us"].as_f64().unwrap());
        worst_max = worst_max.max(report["max_us"].as_f64().unwrap());
    }
    // The flooder got its share and was told "overloaded" for the rest.
    assert!(flood["served"].as_u64().unwrap() > 0, "{flood}");
    assert!(flood["overloaded"].as_u64().unwrap() > 0, "{flood}");
    assert_eq!(flood["other"], 0, "{flood}");
    // The silent client hit its in-flight limit and went on sending: nothing blocked.
    assert!(silent["limit_hits"].as_u64().unwrap() > 0, "{silent}");
    let status = service.client().unwrap().status().unwrap();
    assert!(status.overloaded > 0);
    assert_eq!(status.errors, 0);
    eprintln!(
        "{WELL_BEHAVED} clients at 1 kHz: worst p99 {worst_p99:.0} µs, worst max {worst_max:.0} µs; \
         flood served {} / overloaded {}; silent sent {} (limit hit {}); service: {} requests, \
         {} overloaded",
        flood["served"],
        flood["overloaded"],
        silent["sent"],
        silent["limit_hits"],
        status.requests,
        status.overloaded
    );
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
    let total = seconds.to_string();
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
            &[
                "stream",
                "--seconds",
                &total,
                "--batch",
                batch,
                "--period-us",
                period,
            ],
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
        deployer.deploy(&bytes[deploys % 2]).unwrap();
        deploys += 1;
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
