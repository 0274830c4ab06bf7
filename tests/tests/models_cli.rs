//! `train → inspect → predict` and `calibrate` as a user runs them; bad model and corrections
//! files refused, each with its own reason.

use std::path::{Path, PathBuf};

use hexacomp_core::Geometry;
use hexacomp_core::compensator::{compensate_legs, compensate_pose};
use hexacomp_core::fused::FusedModel;
use hexacomp_core::model::Model;
use hexacomp_tests::{assert_says, expect_success, path_str, run, test_uncertainty, text};

fn trainer(args: &[&str]) -> std::process::Output {
    run("hexacomp-trainer", args)
}

/// Runs the trainer with `args`, asserting success; its stdout and stderr.
fn ok(args: &[&str]) -> String {
    let output = expect_success(trainer(args), args);
    text(&output.stdout) + &text(&output.stderr)
}

/// Plans, simulates and solves 40 configurations; returns the corrections file.
fn corrections(dir: &Path) -> PathBuf {
    let (poses, m, c) = (dir.join("poses.csv"), dir.join("m.csv"), dir.join("c.csv"));
    ok(&["plan", "--count", "40", "--out", path_str(&poses)]);
    ok(&[
        "simulate",
        "--plan",
        path_str(&poses),
        "--out",
        path_str(&m),
    ]);
    ok(&[
        "solve",
        "--measurements",
        path_str(&m),
        "--out",
        path_str(&c),
    ]);
    c
}

fn train_small(dir: &Path, arch: &str) -> PathBuf {
    let model = dir.join(format!("{arch}.hxm"));
    let c = corrections(dir);
    let out = ok(&[
        "train",
        "--corrections",
        path_str(&c),
        "--arch",
        arch,
        "--hidden-max",
        "4",
        "--restarts",
        "1",
        "--out",
        path_str(&model),
    ]);
    assert!(out.contains("Selection of hidden nodes"), "{out}");
    assert!(dir.join(format!("{arch}.selection.svg")).exists());
    model
}

#[test]
fn predict_returns_exactly_the_library_compensation() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let model_path = train_small(d, "decoupled");
    let inspected = ok(&["inspect", path_str(&model_path)]);
    assert!(
        inspected.contains("decoupled (six single-output networks)"),
        "{inspected}"
    );
    assert!(
        inspected.contains("matches geometry prototype"),
        "{inspected}"
    );
    assert!(
        inspected.contains("trained on     40 configurations"),
        "{inspected}"
    );

    // The model carries an uncertainty (as `calibrate` writes it): σ² = 2e-5 + 3e-5 · h mm²,
    // h the squared norm of the legs' features over 13.
    let mut with = Model::load(&model_path, &Geometry::prototype()).unwrap();
    with.uncertainty = Some(test_uncertainty());
    with.save(&model_path).unwrap();
    let inspected = ok(&["inspect", path_str(&model_path)]);
    assert!(inspected.contains("format version 2"), "{inspected}");
    assert!(
        inspected.contains("uncertainty    1-σ position"),
        "{inspected}"
    );

    let out = d.join("out.csv");
    ok(&[
        "predict",
        "--model",
        path_str(&model_path),
        "--poses",
        path_str(&d.join("poses.csv")),
        "--out",
        path_str(&out),
    ]);
    let g = Geometry::prototype();
    let model = Model::load(&model_path, &g).unwrap();
    let poses = hexacomp_formats::read_poses(&d.join("poses.csv")).unwrap();
    let written = std::fs::read_to_string(&out).unwrap();
    let mut lines = written.lines();
    assert_eq!(
        lines.next().unwrap(),
        "id,q1,q2,q3,q4,q5,q6,dq1,dq2,dq3,dq4,dq5,dq6,status,uncertainty_mm"
    );
    // One row per pose, no more, no less.
    assert_eq!(written.lines().count(), 1 + poses.len());
    assert!(!poses.is_empty());
    let mut joints = String::from("id,q1,q2,q3,q4,q5,q6\n");
    let mut with_sigma = 0;
    for (line, row) in lines.zip(&poses) {
        let expected = compensate_pose(&g, Some(&FusedModel::new(&model)), &row.pose());
        let cells: Vec<&str> = line.split(',').collect();
        assert_eq!(cells[0], row.id);
        for i in 0..6 {
            assert_eq!(cells[1 + i].parse::<f64>().unwrap(), expected.legs[i]);
            assert_eq!(
                cells[7 + i].parse::<f64>().unwrap(),
                expected.corrections[i]
            );
        }
        assert_eq!(cells[13], expected.status.name());
        match expected.uncertainty_mm {
            Some(sigma) => {
                assert!(sigma > 2e-5f64.sqrt(), "{sigma}");
                assert_eq!(cells[14].parse::<f64>().unwrap(), sigma);
                with_sigma += 1;
            }
            None => assert_eq!(cells[14], ""),
        }
        let nominal = hexacomp_core::inverse_kinematics(&g, &row.pose()).lengths;
        joints += &format!("{},{}\n", row.id, nominal.map(|q| q.to_string()).join(","));
    }
    assert!(with_sigma > 0, "no point was answered with an uncertainty");
    // --joints gives the same numbers from the nominal legs.
    std::fs::write(d.join("joints.csv"), joints).unwrap();
    let out2 = d.join("out2.csv");
    ok(&[
        "predict",
        "--model",
        path_str(&model_path),
        "--joints",
        path_str(&d.join("joints.csv")),
        "--out",
        path_str(&out2),
    ]);
    let legs = hexacomp_formats::read_joints(&d.join("joints.csv")).unwrap();
    let written = std::fs::read_to_string(&out2).unwrap();
    assert_eq!(written.lines().count(), 1 + legs.len());
    for (line, row) in written.lines().skip(1).zip(&legs) {
        let expected = compensate_legs(&g, Some(&FusedModel::new(&model)), &row.legs);
        let cells: Vec<&str> = line.split(',').collect();
        assert_eq!(cells[0], row.id);
        for i in 0..6 {
            assert_eq!(cells[1 + i].parse::<f64>().unwrap(), expected.legs[i]);
        }
        assert_eq!(
            cells[14].parse::<f64>().ok(),
            expected.uncertainty_mm,
            "{line}"
        );
    }
}

#[test]
fn bad_model_files_are_refused_each_with_its_reason() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let model_path = train_small(d, "coupled");
    let bytes = std::fs::read(&model_path).unwrap();
    let mut corrupted = bytes.clone();
    corrupted[30] ^= 0x40;
    let mut newer = bytes.clone();
    newer[8] = 9;
    let cases: [(&str, Vec<u8>, &str); 4] = [
        (
            "truncated.hxm",
            bytes[..bytes.len() / 2].to_vec(),
            "truncated",
        ),
        ("corrupted.hxm", corrupted, "checksum mismatch"),
        (
            "newer.hxm",
            newer,
            "format version 9, this build reads versions 1 to 3",
        ),
        ("text.hxm", b"id,q1\n".to_vec(), "not a hexacomp model file"),
    ];
    for (name, content, reason) in cases {
        let path = d.join(name);
        std::fs::write(&path, content).unwrap();
        for args in [
            vec![
                "predict",
                "--model",
                path_str(&path),
                "--poses",
                path_str(&d.join("poses.csv")),
                "--out",
                path_str(&d.join("o.csv")),
            ],
            vec!["inspect", path_str(&path)],
        ] {
            let output = trainer(&args);
            assert_eq!(output.status.code(), Some(1), "{name}");
            let message = text(&output.stderr);
            assert!(
                message.contains(name) && message.contains(reason),
                "{name}: {message}"
            );
        }
    }
    // Another geometry: the same file, refused by fingerprint.
    let mut other = Geometry::prototype();
    other.platform_joints[2].z += 0.5;
    let geometry = d.join("other.toml");
    other.save(&geometry).unwrap();
    let output = trainer(&[
        "predict",
        "--geometry",
        path_str(&geometry),
        "--model",
        path_str(&model_path),
        "--poses",
        path_str(&d.join("poses.csv")),
        "--out",
        path_str(&d.join("o.csv")),
    ]);
    assert_eq!(output.status.code(), Some(1));
    assert_says(&output.stderr, "trained for geometry");
}

#[test]
fn empty_and_one_row_corrections_files_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let header = "id,q1,q2,q3,q4,q5,q6,dq1,dq2,dq3,dq4,dq5,dq6\n";
    for (name, content, reason) in [
        ("empty.csv", String::new(), "the file is empty"),
        (
            "header.csv",
            header.to_string(),
            "training needs at least 6 configurations, got 0",
        ),
        (
            "one.csv",
            format!("{header}1,350,350,350,350,350,350,0.1,0.1,0.1,0.1,0.1,0.1\n"),
            "got 1",
        ),
    ] {
        let path = d.join(name);
        std::fs::write(&path, content).unwrap();
        let output = trainer(&[
            "train",
            "--corrections",
            path_str(&path),
            "--out",
            path_str(&d.join("m.hxm")),
        ]);
        assert_eq!(output.status.code(), Some(1), "{name}");
        assert!(
            text(&output.stderr).contains(reason),
            "{name}: {}",
            text(&output.stderr)
        );
        assert!(!d.join("m.hxm").exists());
    }
}

#[test]
fn calibrate_runs_the_whole_pipeline_and_summarises() {
    let dir = tempfile::tempdir().unwrap();
    let out_dir = dir.path().join("cal");
    let report = ok(&[
        "calibrate",
        "--arch",
        "physical,coupled,decoupled",
        "--count",
        "60",
        "--validation",
        "30",
        "--out-dir",
        path_str(&out_dir),
    ]);
    for file in [
        "poses.csv",
        "measurements.csv",
        "corrections.csv",
        "model.hxm",
        "model-coupled.hxm",
        "model-decoupled.hxm",
        "model-decoupled.selection.svg",
        "model-physical.hxm",
    ] {
        assert!(out_dir.join(file).exists(), "{file} missing");
    }
    // The candidates are compared on configurations they were not fitted on; on the virtual
    // machine, whose errors have the physical model's form, the physical model wins and is the
    // model file.
    for (name, says) in [
        ("coupled", "hidden nodes"),
        ("decoupled", "hidden nodes"),
        ("physical", "identified and cross-validated in"),
    ] {
        let line = report
            .lines()
            .find(|l| l.starts_with(&format!("  {name} ")) && l.contains("cross-validated"))
            .unwrap_or_else(|| panic!("no cross-validated {name} summary in\n{report}"));
        assert!(line.contains(says), "{line}");
    }
    assert!(
        report.contains("model.hxm = the physical model"),
        "{report}"
    );
    assert_eq!(
        std::fs::read(out_dir.join("model.hxm")).unwrap(),
        std::fs::read(out_dir.join("model-physical.hxm")).unwrap()
    );
    assert!(
        report.contains("Calibration summary (60 configurations, virtual platform)"),
        "{report}"
    );
    assert!(report.contains("time: "), "{report}");
    // The residuals split by shape name the virtual instrument's noise: 0.02 mm a reading, three
    // averaged, 11.5 µm per coordinate (60 configurations estimate it within about 5 %, 1 σ).
    let instrument: f64 = report
        .split("its residuals hold ")
        .nth(1)
        .and_then(|rest| rest.split(' ').next()?.parse().ok())
        .unwrap_or_else(|| panic!("no split of the residuals in\n{report}"));
    assert!((9.5..13.5).contains(&instrument), "{instrument} µm");
    // How every Levenberg–Marquardt run ended: (16 sizes + the final fit) × 3 restarts per network.
    for (architecture, runs) in [("coupled", 51), ("decoupled", 6 * 51)] {
        let line = report
            .lines()
            .find(|l| l.trim_start().starts_with(architecture) && l.contains("runs:"))
            .unwrap_or_else(|| panic!("no {architecture} summary in\n{report}"));
        let counts: Vec<usize> = line
            .split(|c: char| !c.is_ascii_digit())
            .filter(|w| !w.is_empty())
            .map(|w| w.parse().unwrap())
            .collect();
        // … trained in X.YZ s; N runs: a settled, b at the cap, c found no lower loss
        let [total, settled, cap, no_descent] = counts[counts.len() - 4..] else {
            unreachable!()
        };
        assert_eq!(total, runs, "{line}");
        assert_eq!(settled + cap + no_descent, total, "{line}");
    }
    // Both protocols on the fresh poses: reached mean, max, orientation; measured mean and
    // orientation. The instrument's noise makes the measured mean differ from the reached one.
    assert!(report.contains("measured mean ‖δ_A‖ (mm)"), "{report}");
    let row: Vec<f64> = report
        .lines()
        .find(|l| l.starts_with("robust decoupled"))
        .unwrap_or_else(|| panic!("no robust decoupled row in\n{report}"))
        ["robust decoupled".len()..]
        .split_whitespace()
        .take(5)
        .map(|w| w.parse().unwrap())
        .collect();
    assert_eq!(row.len(), 5, "{row:?}");
    assert!(row[0] > 0.0 && row[3] > 0.0 && row[0] != row[3], "{row:?}");
    // The physical model's row lies between the floor's and the decoupled networks'.
    let reached_mean = |label: &str| -> f64 {
        let line = report
            .lines()
            .find(|l| l.starts_with(label))
            .unwrap_or_else(|| panic!("no {label} row in\n{report}"));
        line[label.len()..]
            .split_whitespace()
            .next()
            .unwrap()
            .parse()
            .unwrap()
    };
    let physical = reached_mean("physical model ");
    let floor = reached_mean("floor (exact legs, with the machine's repeatability)");
    assert!(
        floor < physical && physical < row[0],
        "{floor} {physical} {row:?}"
    );
    // Every model file carries its uncertainty, and the check says how it held: the physical
    // model's row ends with its mean σ and the share within 2σ.
    for file in ["model.hxm", "model-coupled.hxm", "model-decoupled.hxm"] {
        let model = Model::load(&out_dir.join(file), &Geometry::prototype()).unwrap();
        let u = model
            .uncertainty
            .unwrap_or_else(|| panic!("{file} has no uncertainty"));
        assert!(u.leverage_variance_mm2 > 0.0, "{file}: {u:?}");
    }
    let line = report
        .lines()
        .find(|l| l.starts_with("physical model "))
        .unwrap();
    let cells: Vec<&str> = line.split_whitespace().collect();
    let share: f64 = cells[cells.len() - 2].parse().unwrap();
    assert_eq!(cells[cells.len() - 1], "%", "{line}");
    assert!((50.0..=100.0).contains(&share), "{line}");
    assert!(
        report.contains("its 1-σ position uncertainty: "),
        "{report}"
    );
    // The lead-screw resolution: each tried, the chosen one's error the model's.
    let resolution = report
        .lines()
        .find_map(|l| l.strip_prefix("physical model: lead-screw curves of "))
        .unwrap_or_else(|| panic!("{report}"));
    let chosen = resolution.split_whitespace().next().unwrap();
    let tried = resolution.split_once('(').unwrap().1;
    for basis in ["8: ", "12: ", "16: "] {
        assert!(tried.contains(basis), "{resolution}");
    }
    // The error of `what` among `tried` ("8: 0.0353 ± 0.0010 mm, 12: …").
    let error_of = |tried: &str, what: &str| -> String {
        tried
            .split(", ")
            .find_map(|s| s.strip_prefix(&format!("{what}: ")))
            .unwrap_or_else(|| panic!("no {what} in {tried}"))
            .split_whitespace()
            .next()
            .unwrap()
            .to_string()
    };
    // Then the smoothness prior at that resolution: each weight tried, none among them with the
    // resolution's own error, and the chosen weight's error the model's.
    let smoothing = report
        .lines()
        .find_map(|l| l.strip_prefix("physical model: the curves' smoothness prior of weight "))
        .unwrap_or_else(|| panic!("{report}"));
    let weight = smoothing.split(',').next().unwrap();
    assert!(
        smoothing.contains(&format!(
            "the lowest cross-validated at {chosen} coefficients"
        )),
        "{smoothing}"
    );
    let weights = smoothing.split_once('(').unwrap().1;
    assert_eq!(error_of(weights, "0"), error_of(tried, chosen), "{report}");
    for tried_weight in ["0.003", "0.01", "0.03"] {
        error_of(weights, tried_weight);
    }
    assert!(
        report.contains(&format!(
            "physical model: {} mm cross-validated",
            error_of(weights, weight)
        )),
        "{report}"
    );
    // A repeatability that is not a length is refused before anything runs.
    for bad in ["--repeatability-mm=-0.1", "--repeatability-mm=nan"] {
        let refused = trainer(&["calibrate", bad, "--out-dir", path_str(&out_dir)]);
        assert!(!refused.status.success());
        assert_says(&refused.stderr, "is not a repeatability in mm");
    }
}

/// By default `calibrate` fits the physical model alone and writes it as it is: a version-3
/// model file that `inspect` shows with its cross-validated accuracy, and whose corrections at a
/// pose are the model's own, the same from the pose as from its nominal legs.
#[test]
fn calibrate_by_default_writes_the_physical_model_itself() {
    let dir = tempfile::tempdir().unwrap();
    let out_dir = dir.path().join("cal");
    let report = ok(&[
        "calibrate",
        "--count",
        "60",
        "--validation",
        "10",
        "--out-dir",
        path_str(&out_dir),
    ]);
    assert!(!report.contains("Levenberg"), "networks trained:\n{report}");
    for file in ["model-coupled.hxm", "model-decoupled.hxm"] {
        assert!(!out_dir.join(file).exists(), "{file} written");
    }
    let geometry = Geometry::prototype();
    let model = Model::load(&out_dir.join("model.hxm"), &geometry).unwrap();
    assert!(model.is_physical());
    assert_eq!(model.format_version(), 3);
    assert!(model.uncertainty.is_some());
    let inspect = ok(&["inspect", path_str(&out_dir.join("model.hxm"))]);
    assert!(
        inspect.contains("mm cross-validated (Eq. 21, against the measurements)"),
        "{inspect}"
    );
    let pose = hexacomp_core::Pose::from_mm_deg([10.0, -5.0, 330.0, 1.0, -2.0, 3.0]);
    let from_pose = compensate_pose(&geometry, Some(&model), &pose);
    let q = hexacomp_core::inverse_kinematics(&geometry, &pose).lengths;
    let from_legs = compensate_legs(&geometry, Some(&model), &q);
    assert_eq!(from_pose.status, from_legs.status);
    for i in 0..6 {
        assert!(
            (from_pose.legs[i] - from_legs.legs[i]).abs() < 1e-9,
            "leg {i}: {from_pose:?} {from_legs:?}"
        );
        assert!(
            from_pose.corrections[i].abs() > 1e-3,
            "leg {i}: {from_pose:?}"
        );
    }
}

/// The peak resident memory (VmHWM, KiB) that `child` reached, polled until it exits, and its
/// exit status.
fn peak_memory_kib(mut child: std::process::Child) -> (std::process::ExitStatus, u64) {
    let mut peak = 0;
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            return (status, peak);
        }
        let status = std::fs::read_to_string(format!("/proc/{}/status", child.id()));
        let hwm = status.ok().and_then(|s| {
            s.lines()
                .find_map(|l| l.strip_prefix("VmHWM:"))
                .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
        });
        peak = peak.max(hwm.unwrap_or(0));
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
}

#[test]
fn predict_streams_a_large_file_in_far_less_memory_than_its_size() {
    use std::io::Write;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (_, model) = hexacomp_tests::save_smooth_model(d, 1);
    let poses = d.join("poses.csv");
    let mut file = std::io::BufWriter::new(std::fs::File::create(&poses).unwrap());
    writeln!(file, "id,x,y,z,a,b,c").unwrap();
    for i in 0..400_000u32 {
        let t = f64::from(i) * 1e-4;
        writeln!(
            file,
            "{i},{:.12},{:.12},{:.12},{:.12},{:.12},{:.12}",
            20.0 * t.sin(),
            20.0 * t.cos(),
            300.0 + 10.0 * (3.0 * t).sin(),
            2.0 * (5.0 * t).sin(),
            2.0 * (7.0 * t).cos(),
            3.0 * (2.0 * t).sin()
        )
        .unwrap();
    }
    drop(file);
    let size_kib = std::fs::metadata(&poses).unwrap().len() / 1024;
    let out = d.join("out.csv");
    let child = std::process::Command::new(hexacomp_tests::binary("hexacomp-trainer"))
        .args([
            "predict",
            "--model",
            path_str(&model),
            "--poses",
            path_str(&poses),
            "--out",
            path_str(&out),
        ])
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let (status, peak_kib) = peak_memory_kib(child);
    assert!(status.success());
    assert_eq!(
        std::fs::read_to_string(&out).unwrap().lines().count(),
        400_001
    );
    // Reading the whole file first took about 5 times its size; streaming, a fraction of it.
    assert!(
        peak_kib > 0 && peak_kib < size_kib,
        "peak {peak_kib} KiB for a {size_kib} KiB file"
    );
}
