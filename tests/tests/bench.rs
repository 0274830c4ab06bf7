//! `hexacomp-bench` as a user runs it: the demo end to end, the four-variant comparison, the
//! batch sweep and hot swaps under load — each with the real service, echo and socket servers
//! as child processes. Latency figures are not asserted here (benchmarks check those); what is
//! asserted is that every report is produced, complete and consistent.

use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard, OnceLock};

use hexacomp_tests::{json_file, path_str, run, text};

/// One benchmark at a time: each starts a busy-polling server, and the machine has two cores.
fn exclusive() -> MutexGuard<'static, ()> {
    static LOCK: Mutex<()> = Mutex::new(());
    LOCK.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

fn bench(args: &[&str]) -> String {
    let output = run("hexacomp-bench", args);
    assert!(
        output.status.success(),
        "hexacomp-bench {args:?} failed:\n{}\n{}",
        text(&output.stdout),
        text(&output.stderr)
    );
    text(&output.stdout)
}

/// The demo, run once on short settings: its output folder (with the calibrated model) and
/// what it printed.
fn demo() -> &'static (tempfile::TempDir, String) {
    static DEMO: OnceLock<(tempfile::TempDir, String)> = OnceLock::new();
    DEMO.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let stdout = bench(&["demo", "--duration", "2", "--out-dir", path_str(dir.path())]);
        (dir, stdout)
    })
}

fn model() -> PathBuf {
    demo().0.path().join("model.hxm")
}

/// Runs `command` with the demo's model on 3000 points of a line, reports into `dir`: what it
/// printed and its JSON summary.
fn on_a_short_line(command: &str, dir: &Path) -> (String, serde_json::Value) {
    let summary = dir.join(format!("{command}.json"));
    let stdout = bench(&[
        command,
        "--model",
        path_str(&model()),
        "--points",
        "3000",
        "--shape",
        "line",
        "--json",
        path_str(&summary),
        "--out-dir",
        path_str(dir),
    ]);
    (stdout, json_file(&summary))
}

/// The curves of a chart that have at least two points: its coloured lines (the axes and the
/// mesh are black) with more than one point, left of the legend (x < 600).
fn drawn_curves(svg: &str) -> usize {
    svg.split("<polyline")
        .skip(1)
        .filter(|line| !line.contains("stroke=\"#000000\""))
        .filter(|line| {
            let points = &line[line.find("points=\"").unwrap() + 8..];
            let xs: Vec<f64> = points[..points.find('"').unwrap()]
                .split_whitespace()
                .map(|p| p.split(',').next().unwrap().parse().unwrap())
                .collect();
            xs.len() > 1 && xs.iter().all(|x| *x < 600.0)
        })
        .count()
}

/// Parses the first number after `label` in `text`.
fn number_after(text: &str, label: &str) -> f64 {
    let rest = &text[text
        .find(label)
        .unwrap_or_else(|| panic!("no {label:?} in\n{text}"))
        + label.len()..];
    rest.split_whitespace()
        .next()
        .and_then(|t| {
            t.trim_end_matches(|c: char| !c.is_ascii_digit())
                .parse()
                .ok()
        })
        .unwrap_or_else(|| panic!("no number after {label:?} in\n{text}"))
}

#[test]
fn demo_calibrates_hot_swaps_streams_and_compensates_the_path() {
    let _one = exclusive();
    let (dir, stdout) = demo();
    assert!(stdout.contains("generation 0"), "{stdout}");
    assert!(stdout.contains("accepted as generation 1"), "{stdout}");
    // The virtual machine's path error: compensation must shrink it by an order of magnitude.
    let before = number_after(stdout, "nominal (uncompensated)");
    let after = number_after(stdout, "\ncompensated");
    assert!(
        before > 0.3 && after < before / 10.0,
        "{before} → {after}\n{stdout}"
    );
    // The floor the same machine reaches with its exact legs: above zero (its repeatability),
    // below what the compensated run reaches, and the same in the summary.
    // The service's uncertainty against the errors reached along the path: the model the demo
    // calibrates carries one, and on its own virtual machine it holds (95.45 % if calibrated).
    let sigma = number_after(stdout, "the service's uncertainty: mean σ ");
    assert!(sigma > 0.004 && sigma < 0.02, "mean σ {sigma}\n{stdout}");
    let share = number_after(stdout, " mm; ");
    assert!(
        (85.0..=100.0).contains(&share),
        "{share} % within 2σ\n{stdout}"
    );
    assert!(
        stdout.contains(&format!(
            "the service's 1-σ uncertainty {sigma:.4} mm mean, {share:.1} % of the errors"
        )),
        "{stdout}"
    );
    let floor = number_after(stdout, "exact (the floor)");
    assert!(floor > 0.0 && floor < after, "{floor} {after}\n{stdout}");
    assert_eq!(
        number_after(stdout, "exact legs with the machine's repeatability: "),
        floor,
        "{stdout}"
    );
    for variant in ["hexacomp", "echo", "uds", "inprocess"] {
        assert!(
            stdout.contains(&format!("\n{variant} ")),
            "{variant}\n{stdout}"
        );
    }
    assert!(!stdout.contains("requests failed"), "{stdout}");
    assert!(
        !stdout.contains("points answered"),
        "every point ok\n{stdout}"
    );
    for file in [
        "demo-latency.hgrm",
        "demo-percentiles.svg",
        "demo-latency-along-path.svg",
        "demo-accuracy.svg",
        "model.hxm",
    ] {
        assert!(dir.path().join(file).exists(), "{file}");
    }
    // Every variant streamed the same path: in both latency charts, named in the legend and
    // drawn (a curve per variant; along the path, hexacomp's median too).
    // The accuracy chart: before, after, the floor, and twice the service's uncertainty.
    let accuracy = std::fs::read_to_string(dir.path().join("demo-accuracy.svg")).unwrap();
    assert!(
        accuracy.contains("2σ (the service&apos;s uncertainty)"),
        "no 2σ series in the legend"
    );
    assert_eq!(drawn_curves(&accuracy), 4);
    for (chart, curves) in [
        ("demo-percentiles.svg", 4),
        ("demo-latency-along-path.svg", 5),
    ] {
        let svg = std::fs::read_to_string(dir.path().join(chart)).unwrap();
        for variant in ["hexacomp", "echo", "uds", "inprocess"] {
            assert!(svg.contains(variant), "{variant} in {chart}");
        }
        assert_eq!(drawn_curves(&svg), curves, "{chart}");
    }
    // 2 s at 1 kHz: 2001 round trips in the histogram.
    let hgrm = std::fs::read_to_string(dir.path().join("demo-latency.hgrm")).unwrap();
    assert!(hgrm.contains("Total count    =         2001"), "{hgrm}");
}

#[test]
fn compare_reports_all_four_variants_in_the_json_summary() {
    let _one = exclusive();
    let dir = tempfile::tempdir().unwrap();
    let summary = dir.path().join("compare.json");
    let stdout = bench(&[
        "compare",
        "--model",
        path_str(&model()),
        "--points",
        "4000",
        "--rounds",
        "2",
        "--shape",
        "figure-eight",
        "--json",
        path_str(&summary),
        "--out-dir",
        path_str(dir.path()),
    ]);
    let json = json_file(&summary);
    let variants = json["variants"].as_object().unwrap();
    assert_eq!(variants.len(), 4, "{json}");
    for name in ["hexacomp", "echo", "uds", "inprocess"] {
        let v = &variants[name];
        assert_eq!(v["points"], 8000, "{name}: {v}");
        let keys = [
            "p50_ns", "p90_ns", "p99_ns", "p999_ns", "p9999_ns", "max_ns",
        ];
        let values: Vec<u64> = keys.iter().map(|k| v[k].as_u64().unwrap()).collect();
        assert!(values[0] > 0, "{name}: {v}");
        assert!(
            values.windows(2).all(|w| w[0] <= w[1]),
            "{name}: percentiles ordered: {v}"
        );
        assert!(v["deadline_misses"].is_u64());
        assert!(dir.path().join(format!("compare-{name}.hgrm")).exists());
    }
    assert!(stdout.contains("p50 hexacomp / echo"), "{stdout}");
    assert!(dir.path().join("compare-percentiles.svg").exists());
}

#[test]
fn batches_report_throughput_for_every_size_and_variant() {
    let _one = exclusive();
    let dir = tempfile::tempdir().unwrap();
    let (_, json) = on_a_short_line("batches", dir.path());
    let sizes: Vec<u64> = json["batch_sizes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap())
        .collect();
    assert_eq!(sizes, (0..=10).map(|k| 1u64 << k).collect::<Vec<_>>());
    for name in ["hexacomp", "echo", "uds", "inprocess"] {
        let rates = json["points_per_second"][name].as_array().unwrap();
        assert_eq!(rates.len(), 11, "{name}");
        assert!(
            rates.iter().all(|r| r.as_f64().unwrap() > 0.0),
            "{name}: {rates:?}"
        );
    }
    assert!(dir.path().join("batches.svg").exists());
}

#[test]
fn compute_compares_both_forms_of_the_model_beside_the_arithmetic_floor() {
    let dir = tempfile::tempdir().unwrap();
    // The command itself fails when the two forms disagree on a pose of the path.
    let (stdout, json) = on_a_short_line("compute", dir.path());
    let hidden = hexacomp_core::model::Model::load(&model(), &hexacomp_core::Geometry::prototype())
        .unwrap()
        .hidden_nodes();
    let hidden_json: Vec<usize> = json["hidden_nodes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap() as usize)
        .collect();
    assert_eq!(hidden_json, hidden);
    assert_eq!(
        json["fused_blocks"].as_u64().unwrap() as usize,
        hidden.iter().sum::<usize>().div_ceil(4)
    );
    assert!(json["points"].as_u64().unwrap() >= 3000);
    let difference = json["largest_difference_mm"].as_f64().unwrap();
    assert!((0.0..=1e-6).contains(&difference), "{difference}");
    for form in ["reference", "fused"] {
        let f = &json[form];
        assert!(f["single_p50_ns"].as_u64().unwrap() > 0, "{form}");
        assert!(f["networks_mean_ns"].as_f64().unwrap() > 0.0, "{form}");
        let rates = f["batch_points_per_second"].as_array().unwrap();
        assert_eq!(rates.len(), json["batch_sizes"].as_array().unwrap().len());
        assert!(
            rates.iter().all(|r| r.as_f64().unwrap() > 0.0),
            "{form}: {rates:?}"
        );
    }
    // The default model is the physical one: no networks, a floor of nothing.
    let floor = json["networks_floor_ns"].as_f64().unwrap();
    assert!(
        floor.is_finite() && (floor > 0.0) != hidden.is_empty(),
        "{floor}"
    );
    assert!(stdout.contains("arithmetic floor"), "{stdout}");
}

#[test]
fn hot_swaps_under_load_lose_nothing() {
    let _one = exclusive();
    let dir = tempfile::tempdir().unwrap();
    let summary = dir.path().join("swap.json");
    // The command itself fails when a request fails, a deploy is refused or the generations do
    // not advance once per deploy.
    let stdout = bench(&[
        "swap",
        "--model",
        path_str(&model()),
        "--duration",
        "3",
        "--interval",
        "0.5",
        "--json",
        path_str(&summary),
        "--out-dir",
        path_str(dir.path()),
    ]);
    assert!(
        stdout.contains("0 failed requests, 0 points not ok"),
        "{stdout}"
    );
    let accepted = number_after(&stdout, "requests, ");
    assert!(accepted >= 4.0, "{stdout}");
    let json = json_file(&summary);
    assert!(
        json["variants"]["during_swaps"]["points"].as_u64().unwrap() > 0,
        "{json}"
    );
    assert!(
        json["variants"]["steady"]["points"].as_u64().unwrap() > 0,
        "{json}"
    );
}

#[test]
fn paths_that_leave_the_workspace_are_refused_before_anything_starts() {
    let _one = exclusive();
    let dir = tempfile::tempdir().unwrap();
    let output = run(
        "hexacomp-bench",
        &[
            "path",
            "--model",
            path_str(&model()),
            "--shape",
            "circle",
            "--size",
            "200",
            "--duration",
            "1",
            "--out-dir",
            path_str(dir.path()),
        ],
    );
    assert!(!output.status.success());
    let stderr = text(&output.stderr);
    assert!(stderr.contains("does not fit the workspace"), "{stderr}");
    assert!(
        !dir.path().join("service.log").exists(),
        "no service was started"
    );
}
