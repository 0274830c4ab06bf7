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
