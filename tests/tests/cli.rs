//! The binaries as a user runs them: real processes, real files.

use hexacomp_core::Geometry;
use hexacomp_tests::run;

fn stdout(output: &std::process::Output) -> String {
    String::from_utf8(output.stdout.clone()).expect("UTF-8 output")
}

fn stderr(output: &std::process::Output) -> String {
    String::from_utf8(output.stderr.clone()).expect("UTF-8 output")
}

#[test]
fn trainer_geometry_prints_the_prototype_so_that_it_loads_back() {
    let output = run("hexacomp-trainer", &["geometry"]);
    assert!(output.status.success(), "{}", stderr(&output));
    let text = stdout(&output);
    let prototype = Geometry::prototype();
    assert!(text.starts_with(&format!(
        "# hexacomp geometry; fingerprint {}",
        prototype.fingerprint()
    )));
    assert_eq!(Geometry::from_toml_str(&text).unwrap(), prototype);
}

#[test]
fn trainer_uses_a_geometry_file_and_writes_one() {
    let dir = tempfile::tempdir().unwrap();
    let mut geometry = Geometry::prototype();
    geometry.name = "test-machine".into();
    geometry.workspace.tilt_max = 10.0;
    let input = dir.path().join("machine.toml");
    geometry.save(&input).unwrap();
    let copy = dir.path().join("copy.toml");
    let output = run(
        "hexacomp-trainer",
        &[
            "geometry",
            "--geometry",
            input.to_str().unwrap(),
            "--out",
            copy.to_str().unwrap(),
        ],
    );
    assert!(output.status.success(), "{}", stderr(&output));
    assert_eq!(Geometry::load(&copy).unwrap(), geometry);
}

#[test]
fn trainer_survey_reports_the_uncompensated_errors_of_the_default_machine() {
    let output = run("hexacomp-trainer", &["survey", "--poses", "300"]);
    assert!(output.status.success(), "{}", stderr(&output));
    let text = stdout(&output);
    assert!(
        text.contains("machine seed 18, 300 workspace poses"),
        "{text}"
    );
    // The mean rows: our value, then the paper's.
    let means: Vec<(f64, f64)> = text
        .lines()
        .filter(|l| l.contains(" mean "))
        .map(|l| {
            let numbers: Vec<f64> = l
                .split_whitespace()
                .filter_map(|w| w.parse().ok())
                .collect();
            (numbers[0], numbers[1])
        })
        .collect();
    assert_eq!(means.len(), 2, "{text}");
    assert_eq!(means[0].1, 0.642);
    assert_eq!(means[1].1, 0.184);
    assert!((means[0].0 / 0.642 - 1.0).abs() < 0.25, "{text}");
    assert!((means[1].0 / 0.184 - 1.0).abs() < 0.25, "{text}");
}

#[test]
fn a_malformed_geometry_file_is_refused_with_its_path_and_problem() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.toml");
    let text = Geometry::prototype()
        .to_toml_string()
        .replace("leg_range = [280.0, 430.0]", "leg_range = [280.0, nan]");
    std::fs::write(&path, text).unwrap();
    let output = run(
        "hexacomp-trainer",
        &["survey", "--geometry", path.to_str().unwrap()],
    );
    assert_eq!(output.status.code(), Some(1));
    let message = stderr(&output);
    assert!(message.contains(path.to_str().unwrap()), "{message}");
    assert!(message.contains("leg_range[1] is NaN"), "{message}");
}

#[test]
fn service_refuses_an_instance_name_that_is_not_a_service_name() {
    let output = run("hexacomp-service", &["--instance", "a/b"]);
    assert_eq!(output.status.code(), Some(1));
    assert!(
        stderr(&output).contains("invalid instance name \"a/b\""),
        "{}",
        stderr(&output)
    );
}

#[test]
fn a_client_timeout_of_0_ms_is_refused_before_connecting() {
    let output = run(
        "hexacomp-client",
        &[
            "--instance",
            "no-such-instance",
            "--timeout-ms",
            "0",
            "status",
        ],
    );
    assert_eq!(output.status.code(), Some(2), "{}", stderr(&output));
    assert!(
        stderr(&output).contains("--timeout-ms"),
        "{}",
        stderr(&output)
    );
}

#[test]
fn an_option_without_effect_is_an_error_and_a_negative_range_parses() {
    // Without --from-linuxcnc (and --workspace-radius) these options would be ignored.
    for args in [
        &["geometry", "--tilt-max=5"][..],
        &["geometry", "--leg-range", "280,430"],
        &[
            "geometry",
            "--from-linuxcnc",
            "x.ini",
            "--z-range",
            "250,320",
        ],
    ] {
        let output = run("hexacomp-trainer", args);
        assert_eq!(
            output.status.code(),
            Some(2),
            "{args:?}: {}",
            stderr(&output)
        );
        assert!(
            stderr(&output).contains("required arguments were not provided"),
            "{args:?}: {}",
            stderr(&output)
        );
    }
    // `--yaw-range -10,10` is a range, not an option: it gets as far as reading the ini.
    let output = run(
        "hexacomp-trainer",
        &[
            "geometry",
            "--from-linuxcnc",
            "missing.ini",
            "--workspace-radius",
            "30",
            "--z-range",
            "250,320",
            "--tilt-max",
            "5",
            "--yaw-range",
            "-10,10",
        ],
    );
    assert!(
        stderr(&output).contains("missing.ini"),
        "{}",
        stderr(&output)
    );
    // predict names both of its possible inputs.
    let output = run(
        "hexacomp-trainer",
        &["predict", "--model", "m.hxm", "--out", "o.csv"],
    );
    assert!(
        stderr(&output).contains("--poses <FILE>|--joints <FILE>"),
        "{}",
        stderr(&output)
    );
}

#[test]
fn simulate_names_the_file_line_and_configuration_it_cannot_measure() {
    let dir = tempfile::tempdir().unwrap();
    let plan = dir.path().join("far.csv");
    std::fs::write(&plan, "id,x,y,z,a,b,c\n1,0,0,300,0,0,0\n2,0,0,520,0,0,0\n").unwrap();
    let out = dir.path().join("m.csv");
    let output = run(
        "hexacomp-trainer",
        &[
            "simulate",
            "--plan",
            plan.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ],
    );
    let message = stderr(&output);
    assert!(!output.status.success(), "{message}");
    // The geometry's own stroke, not the virtual machine's.
    assert!(
        message.contains(&format!(
            "{}:3: configuration 2: the pose needs leg 1 at",
            plan.display()
        )) && message.contains("outside the geometry's stroke [280, 430] mm"),
        "{message}"
    );
    assert!(!out.exists());
}

#[test]
fn client_compensate_summarises_the_statuses_it_wrote() {
    let dir = tempfile::tempdir().unwrap();
    let (_, model) = hexacomp_tests::save_smooth_model(dir.path(), 3);
    let instance = hexacomp_tests::unique_instance("compensate-summary");
    let _service =
        hexacomp_tests::ServiceProcess::with_model(&instance, &dir.path().join("state"), &model);
    let poses = dir.path().join("poses.csv");
    // Two poses in the workspace, one far above it (out of stroke).
    std::fs::write(
        &poses,
        "id,x,y,z,a,b,c\n1,0,0,300,0,0,0\n2,5,0,310,0,0,0\n3,0,0,520,0,0,0\n",
    )
    .unwrap();
    let out = dir.path().join("out.csv");
    let output = run(
        "hexacomp-client",
        &[
            "--instance",
            &instance,
            "compensate",
            "--input",
            poses.to_str().unwrap(),
            "--output",
            out.to_str().unwrap(),
        ],
    );
    assert!(output.status.success(), "{}", stderr(&output));
    assert!(
        stderr(&output).contains("compensated 3 points → ")
            && stderr(&output).contains("(1 out_of_stroke; model generations"),
        "{}",
        stderr(&output)
    );
}

#[test]
fn client_status_json_and_metrics_give_the_services_counters() {
    let dir = tempfile::tempdir().unwrap();
    let (_, model) = hexacomp_tests::save_smooth_model(dir.path(), 4);
    let instance = hexacomp_tests::unique_instance("metrics");
    let state = dir.path().join("state");
    // A deadline of 0: every answer misses it.
    let service = hexacomp_tests::ServiceProcess::start(
        &instance,
        &[
            "--state-dir",
            state.to_str().unwrap(),
            "--model",
            model.to_str().unwrap(),
            "--deadline-us",
            "0",
        ],
    );
    let poses = dir.path().join("poses.csv");
    std::fs::write(&poses, "id,x,y,z,a,b,c\n1,0,0,300,0,0,0\n2,5,0,310,0,0,0\n").unwrap();
    let out = dir.path().join("out.csv");
    let client = |args: &[&str]| {
        let mut all = vec!["--instance", &instance];
        all.extend_from_slice(args);
        run("hexacomp-client", &all)
    };
    let compensate = |input: &std::path::Path, output: &std::path::Path| {
        let compensated = client(&[
            "compensate",
            "--input",
            input.to_str().unwrap(),
            "--output",
            output.to_str().unwrap(),
        ]);
        assert!(compensated.status.success(), "{}", stderr(&compensated));
    };
    compensate(&poses, &out);

    // One request of two points served: the JSON says so, with every field.
    let status = client(&["status", "--json"]);
    assert!(status.status.success(), "{}", stderr(&status));
    let json: serde_json::Value = serde_json::from_slice(&status.stdout).unwrap();
    assert_eq!(json["instance"], instance.as_str());
    assert_eq!(json["generation"], 1);
    assert_eq!(
        (json["requests"].as_u64(), json["points"].as_u64()),
        (Some(1), Some(2))
    );
    assert_eq!(json["errors"], 0);
    assert!(json["uptime_s"].as_f64().unwrap() > 0.0, "{json}");

    // The same counters as metrics, into a file a collector reads.
    let file = dir.path().join("hexacomp.prom");
    let metrics = client(&["metrics", "--output", file.to_str().unwrap()]);
    assert!(metrics.status.success(), "{}", stderr(&metrics));
    let text = std::fs::read_to_string(&file).unwrap();
    let sample = |name: &str| -> f64 {
        let line = text
            .lines()
            .find(|l| l.starts_with(&format!("{name}{{hexacomp_instance=\"{instance}\"")))
            .unwrap_or_else(|| panic!("no {name} in\n{text}"));
        line.rsplit(' ').next().unwrap().parse().unwrap()
    };
    assert_eq!(sample("hexacomp_up"), 1.0);
    assert_eq!(sample("hexacomp_model_generation"), 1.0);
    // The status request above is not a compensation request: still one, of two points.
    assert_eq!(sample("hexacomp_requests_total"), 1.0);
    assert_eq!(sample("hexacomp_points_total"), 2.0);
    assert_eq!(sample("hexacomp_request_errors_total"), 0.0);
    // The serving thread's answer times: the one request, in the histogram; it missed the
    // deadline of 0; the model, loaded at the start, is as old as the service at most.
    assert_eq!(sample("hexacomp_answer_duration_seconds_count"), 1.0);
    let all = text
        .lines()
        .find(|l| l.contains("_bucket{") && l.contains("le=\"+Inf\""))
        .unwrap_or_else(|| panic!("no +Inf bucket in\n{text}"));
    assert!(all.ends_with(" 1"), "{all}");
    assert!(sample("hexacomp_answer_duration_seconds_sum") > 0.0);
    assert_eq!(sample("hexacomp_deadline_seconds"), 0.0);
    assert_eq!(sample("hexacomp_deadline_misses_total"), 1.0);
    let age = sample("hexacomp_model_age_seconds");
    assert!(
        (0.0..=sample("hexacomp_uptime_seconds") + 1.0).contains(&age),
        "{text}"
    );

    // The status as text says what the JSON said.
    let text_status = client(&["status"]);
    let text_status = String::from_utf8_lossy(&text_status.stdout).to_string();
    assert!(
        text_status.contains("requests      1 (2 points), 0 errors"),
        "{text_status}"
    );

    // A batch of 100 points is served and counted, but not timed: its time is its points'.
    let batch = dir.path().join("batch.csv");
    let rows: String = (1..=100).map(|i| format!("{i},0,0,300,0,0,0\n")).collect();
    std::fs::write(&batch, format!("id,x,y,z,a,b,c\n{rows}")).unwrap();
    compensate(&batch, &dir.path().join("batch-out.csv"));
    let metrics = client(&["metrics"]);
    let text = String::from_utf8_lossy(&metrics.stdout).to_string();
    assert!(
        text.contains(&format!(
            "hexacomp_requests_total{{hexacomp_instance=\"{instance}\"}} 2\n"
        )) && text.contains(&format!(
            "hexacomp_answer_duration_seconds_count{{hexacomp_instance=\"{instance}\"}} 1\n"
        )),
        "{text}"
    );

    // Gone: the collector's file is replaced by `hexacomp_up 0` alone, the reason on standard
    // error, and still exit status 0.
    drop(service);
    let down = client(&[
        "--timeout-ms",
        "200",
        "metrics",
        "--output",
        file.to_str().unwrap(),
    ]);
    assert!(down.status.success(), "{}", stderr(&down));
    let text = std::fs::read_to_string(&file).unwrap();
    assert!(
        text.contains(&format!(
            "hexacomp_up{{hexacomp_instance=\"{instance}\"}} 0"
        )),
        "{text}"
    );
    assert!(!text.contains("hexacomp_requests_total"), "{text}");
    assert!(
        stderr(&down).contains("hexacomp_up 0: instance"),
        "{}",
        stderr(&down)
    );
    // A name that cannot be an instance is the timer's mistake, not a service that is down.
    let wrong = run("hexacomp-client", &["--instance", "a/b", "metrics"]);
    assert_eq!(wrong.status.code(), Some(1), "{}", stderr(&wrong));
    assert!(
        stderr(&wrong).contains("invalid instance name"),
        "{}",
        stderr(&wrong)
    );

    // JSON status of a service that is gone is an error, not an empty object.
    assert!(
        !client(&["--timeout-ms", "200", "status", "--json"])
            .status
            .success()
    );

    // Restarted without --model, the persisted model's age counts from its deploy: the
    // persisted file's time (set here to a known one).
    let deployed = std::time::UNIX_EPOCH + std::time::Duration::from_secs(1_000_000_000);
    std::fs::File::options()
        .write(true)
        .open(state.join("model.hxm"))
        .unwrap()
        .set_modified(deployed)
        .unwrap();
    let _restarted =
        hexacomp_tests::ServiceProcess::start(&instance, &["--state-dir", state.to_str().unwrap()]);
    let metrics = client(&["metrics"]);
    let text = String::from_utf8_lossy(&metrics.stdout).to_string();
    assert!(
        text.contains(&format!(
            "hexacomp_model_accepted_timestamp_seconds{{hexacomp_instance=\"{instance}\"}} \
             1000000000.000\n"
        )),
        "{text}"
    );
}

#[test]
fn every_command_writes_its_manual_pages_and_completions_and_needs_a_subcommand_otherwise() {
    for (name, other) in [
        ("hexacomp-service", "--cpu=1"),
        ("hexacomp-trainer", "plan"),
        ("hexacomp-client", "status"),
        ("hexacomp-bench", "demo"),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path().to_str().unwrap();
        for option in ["--generate-man", "--generate-completions"] {
            let output = run(name, &[option, d]);
            assert!(
                output.status.success(),
                "{name} {option}: {}",
                String::from_utf8_lossy(&output.stderr)
            );
        }
        let page = std::fs::read_to_string(dir.path().join(format!("{name}.1"))).unwrap();
        assert!(page.contains(&format!(".TH {name} 1")), "{page}");
        for script in [name.to_string(), format!("_{name}"), format!("{name}.fish")] {
            let text = std::fs::read_to_string(dir.path().join(&script)).unwrap();
            assert!(text.contains(name), "{script}: {text}");
        }
        // Alone or not at all: with a subcommand or another option, clap refuses.
        let mixed = run(name, &["--generate-man", d, other]);
        assert_eq!(
            mixed.status.code(),
            Some(2),
            "{name} --generate-man {other}"
        );
    }
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path().to_str().unwrap();
    assert!(
        run("hexacomp-trainer", &["--generate-man", d])
            .status
            .success()
    );
    let calibrate =
        std::fs::read_to_string(dir.path().join("hexacomp-trainer-calibrate.1")).unwrap();
    assert!(calibrate.contains("out\\-dir"), "{calibrate}");
    assert!(
        run("hexacomp-bench", &["--generate-man", d])
            .status
            .success()
    );
    assert!(dir.path().join("hexacomp-bench-demo.1").exists());
    assert!(
        !dir.path().join("hexacomp-bench-serve-echo.1").exists(),
        "a page for a hidden command"
    );
    // Without a subcommand (the subcommand is optional only for the options above): clap's
    // usage error and status 2, as before.
    for name in ["hexacomp-trainer", "hexacomp-client", "hexacomp-bench"] {
        let output = run(name, &[]);
        assert_eq!(output.status.code(), Some(2), "{name}");
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(stderr.contains("a subcommand is required"), "{stderr}");
    }
}
