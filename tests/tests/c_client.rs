//! The C library (`libhexacomp.a` and `.so`, `client-c/include/hexacomp.h`, `hexacomp.pc`) used by a C
//! program compiled here with the system's C compiler, against a running service: every point
//! it prints equals the compensator's answer bit for bit, its error paths give codes, and a call
//! to a stopped service gives the timeout code after the deadline `hexacomp_set_timeout` set.

use std::path::{Path, PathBuf};
use std::process::Command;

use hexacomp_core::Geometry;
use hexacomp_core::compensator::{compensate_legs, compensate_pose};
use hexacomp_core::pose::Pose;
use hexacomp_tests::{ServiceProcess, library_dir, save_smooth_model, unique_instance};

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

/// Writes `hexacomp.pc` for this build (the library in the build directory, the header in
/// `client-c/include`) from `client-c/hexacomp.pc.in` into `dir`, as an install step would.
fn write_pkg_config(dir: &Path) {
    let template = std::fs::read_to_string(workspace().join("client-c/hexacomp.pc.in")).unwrap();
    let filled = template
        .replace("@LIBDIR@", &library_dir().display().to_string())
        .replace(
            "@INCLUDEDIR@",
            &workspace().join("client-c/include").display().to_string(),
        )
        .replace("@VERSION@", env!("CARGO_PKG_VERSION"));
    assert!(
        !filled.contains('@'),
        "a placeholder left unfilled:\n{filled}"
    );
    std::fs::write(dir.join("hexacomp.pc"), filled).unwrap();
}

/// The words `pkg-config` prints for `args` with the `hexacomp.pc` of `dir`; `None` where
/// pkg-config is not installed, unless `HEXACOMP_REQUIRE_PKG_CONFIG` is set (as in CI), which
/// turns its absence into a failure.
fn pkg_config(dir: &Path, args: &[&str]) -> Option<Vec<String>> {
    let output = match Command::new("pkg-config")
        .env("PKG_CONFIG_PATH", dir)
        .args(args)
        .arg("hexacomp")
        .output()
    {
        Ok(output) => output,
        Err(e) if std::env::var_os("HEXACOMP_REQUIRE_PKG_CONFIG").is_none() => {
            eprintln!(
                "pkg-config not found ({e}): hexacomp.pc is not checked, the template's Libs.private and fixed paths used"
            );
            return None;
        }
        Err(e) => panic!("running pkg-config (Debian: apt-get install pkg-config): {e}"),
    };
    assert!(
        output.status.success(),
        "pkg-config {args:?} hexacomp failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    Some(
        String::from_utf8(output.stdout)
            .unwrap()
            .split_whitespace()
            .map(str::to_string)
            .collect(),
    )
}

/// The template's `Libs.private` words, for a machine without pkg-config: the one list of what
/// the static library needs from the system.
fn libs_private() -> Vec<String> {
    let template = std::fs::read_to_string(workspace().join("client-c/hexacomp.pc.in")).unwrap();
    let line = template
        .lines()
        .find_map(|l| l.strip_prefix("Libs.private:"))
        .expect("hexacomp.pc.in has a Libs.private line");
    line.split_whitespace().map(str::to_string).collect()
}

/// Compiles `tests/c/client_test.c` against the static or the shared library, with the flags
/// `hexacomp.pc` gives.
fn compile(out: &Path, shared: bool) -> PathBuf {
    write_pkg_config(out);
    let exe = out.join(if shared {
        "client_test_shared"
    } else {
        "client_test_static"
    });
    let mut cc = Command::new(std::env::var("CC").unwrap_or_else(|_| "cc".into()));
    let include = format!("-I{}", workspace().join("client-c/include").display());
    cc.args(["-std=c11", "-Wall", "-Wextra", "-Werror", "-O2"])
        .args(pkg_config(out, &["--cflags"]).unwrap_or_else(|| vec![include]))
        .arg(workspace().join("tests/c/client_test.c"))
        .arg("-o")
        .arg(&exe);
    if shared {
        let libs = vec![
            format!("-L{}", library_dir().display()),
            "-lhexacomp".into(),
        ];
        cc.args(pkg_config(out, &["--libs"]).unwrap_or(libs));
        cc.arg(format!("-Wl,-rpath,{}", library_dir().display()));
    } else {
        // The archive itself, then what it needs from the system (`Libs.private`).
        cc.arg(library_dir().join("libhexacomp.a"));
        cc.args(
            pkg_config(out, &["--static", "--libs-only-l"])
                .unwrap_or_else(libs_private)
                .into_iter()
                .filter(|flag| flag != "-lhexacomp"),
        );
    }
    // The test program itself uses libm (sin, cos).
    cc.arg("-lm");
    let output = cc.output().expect("running the C compiler");
    assert!(
        output.status.success(),
        "compiling the C test program failed:\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    exe
}

fn numbers(fields: &[&str]) -> [f64; 6] {
    std::array::from_fn(|k| fields[k].parse().unwrap())
}

#[test]
fn a_c_program_linked_statically_and_dynamically_gets_the_compensators_answers() {
    let dir = tempfile::tempdir().unwrap();
    let (model, path) = save_smooth_model(dir.path(), 51);
    let g = Geometry::prototype();
    for shared in [false, true] {
        let exe = compile(dir.path(), shared);
        // A service of its own per program: the status counters it prints are this run's.
        let instance = unique_instance("cabi");
        let service =
            ServiceProcess::with_model(&instance, &dir.path().join(format!("s{shared}")), &path);
        let output = Command::new(&exe)
            .arg(&instance)
            .arg(service.pid().to_string())
            .output()
            .unwrap();
        let stdout = String::from_utf8_lossy(&output.stdout);
        assert!(
            output.status.success(),
            "{} failed:\n{}\n{stdout}",
            exe.display(),
            String::from_utf8_lossy(&output.stderr)
        );
        let mut checked = std::collections::BTreeMap::new();
        let mut deadlines = Vec::new();
        for line in stdout.lines() {
            let fields: Vec<&str> = line.split(' ').collect();
            match fields[0] {
                "S" => assert_eq!(fields[1], "1"),
                "P" | "J" | "B" | "K" | "A" => {
                    let input = numbers(&fields[2..8]);
                    let expected = if matches!(fields[0], "J" | "K") {
                        compensate_legs(&g, Some(&model), &input)
                    } else {
                        compensate_pose(&g, Some(&model), &Pose::from_mm_deg(input))
                    };
                    assert_eq!(fields[8], (expected.status as u8).to_string(), "{line}");
                    assert_eq!(fields[9], "1", "{line}");
                    let legs = numbers(&fields[10..16]);
                    let corrections = numbers(&fields[16..22]);
                    for k in 0..6 {
                        assert_eq!(legs[k].to_bits(), expected.legs[k].to_bits(), "{line}");
                        assert_eq!(
                            corrections[k].to_bits(),
                            expected.corrections[k].to_bits(),
                            "{line}"
                        );
                    }
                    *checked.entry(fields[0]).or_insert(0) += 1;
                }
                // Requests and points the service counted: 64 poses, 64 joints, three batches
                // (64 poses, 64 joints, 0 points).
                "R" => assert_eq!(fields[1..], ["131", "256"], "{line}"),
                "T" => deadlines.push((fields[1].to_string(), fields[2].to_string())),
                "OK" => {}
                other => panic!("unexpected line {other:?}"),
            }
        }
        let expected_counts = [("A", 1), ("B", 64), ("J", 64), ("K", 64), ("P", 64)];
        assert_eq!(checked, expected_counts.into_iter().collect());
        let timeouts: Vec<&str> = deadlines.iter().map(|(d, _)| d.as_str()).collect();
        assert_eq!(timeouts, ["50000", "300000"], "{stdout}");
        // The short deadline was the one set, not the 10 s the program connected with.
        let waited: u64 = deadlines[0].1.parse().unwrap();
        assert!(waited < 5_000_000, "a 50 ms deadline waited {waited} µs");
        assert_eq!(stdout.lines().last(), Some("OK"));
    }
}
