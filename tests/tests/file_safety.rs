//! A failing command never destroys a file: outputs are written whole or not at all, a folder of
//! results is replaced as a unit, and an output that is an input is refused before anything is
//! written. Real binaries, real files.

use std::collections::BTreeMap;
use std::os::unix::process::CommandExt;
use std::path::Path;
use std::process::{Command, Output};

use hexacomp_tests::{binary, expect_success, text};

/// Runs `name` with `args` in `dir`.
fn run_in(dir: &Path, name: &str, args: &[&str]) -> Output {
    Command::new(binary(name))
        .args(args)
        .current_dir(dir)
        .output()
        .unwrap_or_else(|e| panic!("running {name}: {e}"))
}

/// Runs `name` with `args` in `dir`, asserting success; its stderr.
fn ok(dir: &Path, name: &str, args: &[&str]) -> String {
    text(&expect_success(run_in(dir, name, args), args).stderr)
}

/// Every file of `dir` (not recursive) with its bytes.
fn contents(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| {
            let e = e.unwrap();
            (
                e.file_name().to_string_lossy().into_owned(),
                std::fs::read(e.path()).unwrap_or_default(),
            )
        })
        .collect()
}

#[test]
fn an_output_that_is_an_input_is_refused_and_the_input_kept() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(
        d,
        "hexacomp-trainer",
        &["plan", "--count", "30", "--out", "poses.csv"],
    );
    ok(
        d,
        "hexacomp-trainer",
        &["simulate", "--plan", "poses.csv", "--out", "m.csv"],
    );
    ok(
        d,
        "hexacomp-trainer",
        &["solve", "--measurements", "m.csv", "--out", "c.csv"],
    );
    ok(d, "hexacomp-trainer", &["geometry", "--out", "g.toml"]);
    std::os::unix::fs::symlink("m.csv", d.join("alias.csv")).unwrap();
    let cases: [(&str, &[&str]); 9] = [
        (
            "hexacomp-trainer",
            &["simulate", "--plan", "poses.csv", "--out", "poses.csv"],
        ),
        (
            "hexacomp-trainer",
            &["solve", "--measurements", "m.csv", "--out", "m.csv"],
        ),
        (
            "hexacomp-trainer",
            &["solve", "--measurements", "m.csv", "--out", "alias.csv"],
        ),
        (
            "hexacomp-trainer",
            &["identify", "--measurements", "m.csv", "--out", "./m.csv"],
        ),
        (
            "hexacomp-trainer",
            &["train", "--corrections", "c.csv", "--out", "c.csv"],
        ),
        (
            "hexacomp-trainer",
            &[
                "predict",
                "--model",
                "x.hxm",
                "--poses",
                "poses.csv",
                "--out",
                "poses.csv",
            ],
        ),
        (
            "hexacomp-trainer",
            &["--geometry", "g.toml", "plan", "--out", "g.toml"],
        ),
        (
            "hexacomp-trainer",
            &["--geometry", "g.toml", "geometry", "--out", "g.toml"],
        ),
        (
            "hexacomp-client",
            &[
                "--instance",
                "hexacomp-file-safety-none",
                "compensate",
                "--input",
                "poses.csv",
                "--output",
                "poses.csv",
            ],
        ),
    ];
    let before = contents(d);
    for (name, args) in cases {
        let output = run_in(d, name, args);
        let report = text(&output.stderr);
        assert!(!output.status.success(), "{args:?} succeeded");
        assert!(
            report.contains("is the same file as the input"),
            "{args:?}: {report}"
        );
        assert_eq!(contents(d), before, "{args:?} changed the folder");
    }
}

#[test]
fn a_write_that_runs_out_of_space_leaves_the_existing_file_and_names_it() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(
        d,
        "hexacomp-trainer",
        &["plan", "--count", "5", "--out", "poses.csv"],
    );
    let before = contents(d);
    // The new file would be about 200 kB; the process may write 16 kB (as on a full disk, the
    // write fails part-way).
    let mut command = Command::new(binary("hexacomp-trainer"));
    command
        .args(["plan", "--count", "2000", "--out", "poses.csv"])
        .current_dir(d);
    // SAFETY: between fork and exec the child calls only setrlimit and signal, both
    // async-signal-safe; no memory is allocated and no lock is taken.
    unsafe {
        command.pre_exec(|| {
            let limit = libc::rlimit {
                rlim_cur: 16 * 1024,
                rlim_max: 16 * 1024,
            };
            if libc::setrlimit(libc::RLIMIT_FSIZE, &limit) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            // Past the limit a write fails with EFBIG instead of killing the process.
            libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
            Ok(())
        });
    }
    let output = command.output().unwrap();
    let report = text(&output.stderr);
    assert!(!output.status.success(), "{report}");
    assert!(
        report.contains("poses.csv: cannot write: File too large")
            && report.contains("left as it was"),
        "{report}"
    );
    assert_eq!(contents(d), before, "the old file, and no temporary left");
}

#[test]
fn a_failing_calibrate_leaves_the_previous_folder_whole() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(
        d,
        "hexacomp-trainer",
        &[
            "calibrate",
            "--count",
            "40",
            "--validation",
            "5",
            "--out-dir",
            "cal",
        ],
    );
    let before = contents(&d.join("cal"));
    assert!(before.contains_key("model.hxm") && before.contains_key("corrections.csv"));
    // Measurements in inches: refused, after the measurements were copied into the new folder
    // and before any model.
    let measured = std::fs::read_to_string(d.join("cal/measurements.csv")).unwrap();
    let inches: Vec<String> = measured
        .lines()
        .enumerate()
        .map(|(i, line)| {
            if i == 0 {
                return line.to_string();
            }
            let mut cells: Vec<String> = line.split(',').map(str::to_string).collect();
            for cell in &mut cells[13..22] {
                *cell = (cell.parse::<f64>().unwrap() / 25.4).to_string();
            }
            cells.join(",")
        })
        .collect();
    std::fs::write(d.join("inches.csv"), inches.join("\n") + "\n").unwrap();
    let output = run_in(
        d,
        "hexacomp-trainer",
        &[
            "calibrate",
            "--measurements",
            "inches.csv",
            "--out-dir",
            "cal",
        ],
    );
    assert!(!output.status.success(), "{}", text(&output.stderr));
    assert_eq!(contents(&d.join("cal")), before);
    let mut names: Vec<String> = contents(d).into_keys().collect();
    names.sort();
    assert_eq!(names, ["cal", "inches.csv"], "no staging folder left");

    // A successful calibrate from the folder's own measurements replaces it as a unit, with the
    // measurements copied byte for byte.
    ok(
        d,
        "hexacomp-trainer",
        &[
            "calibrate",
            "--measurements",
            "cal/measurements.csv",
            "--out-dir",
            "cal",
        ],
    );
    let after = contents(&d.join("cal"));
    assert_eq!(after["measurements.csv"], before["measurements.csv"]);
    assert!(
        !after.contains_key("poses.csv"),
        "the old folder's files are gone"
    );

    // `.` and a file are not folders calibrate can replace: refused before any work.
    for target in [".", "inches.csv"] {
        let output = run_in(
            d,
            "hexacomp-trainer",
            &["calibrate", "--count", "40", "--out-dir", target],
        );
        let report = text(&output.stderr);
        assert!(!output.status.success(), "{target}: {report}");
        assert!(
            !report.contains("Selection of hidden nodes"),
            "{target}: trained first"
        );
    }

    // A folder holding files calibrate did not write is refused, not replaced.
    std::fs::write(d.join("cal/notes.txt"), b"mine").unwrap();
    let output = run_in(
        d,
        "hexacomp-trainer",
        &["calibrate", "--count", "40", "--out-dir", "cal"],
    );
    let report = text(&output.stderr);
    assert!(!output.status.success(), "{report}");
    assert!(report.contains("notes.txt"), "{report}");
    assert_eq!(std::fs::read(d.join("cal/notes.txt")).unwrap(), b"mine");
}

#[test]
fn an_output_to_dev_stdout_goes_down_the_pipe() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (_, model) = hexacomp_tests::save_smooth_model(d, 2);
    ok(
        d,
        "hexacomp-trainer",
        &["plan", "--count", "5", "--out", "poses.csv"],
    );
    let output = run_in(
        d,
        "hexacomp-trainer",
        &[
            "predict",
            "--model",
            model.to_str().unwrap(),
            "--poses",
            "poses.csv",
            "--out",
            "/dev/stdout",
        ],
    );
    assert!(output.status.success(), "{}", text(&output.stderr));
    let written = text(&output.stdout);
    assert!(written.starts_with("id,q1,q2,q3,q4,q5,q6,dq1"), "{written}");
    assert_eq!(written.lines().count(), 6);
}
