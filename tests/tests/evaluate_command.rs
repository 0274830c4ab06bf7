//! The `evaluate` command against the evaluation library it prints.

use std::process::Command;

use hexacomp_calibration::pitch_resolution::PITCH_RESOLUTIONS;
use hexacomp_calibration::train::TrainOptions;
use hexacomp_core::Geometry;
use hexacomp_core::stats::PoseErrorStats;
use hexacomp_lab::evaluate::{EvaluationOptions, Method, Protocol, evaluate};
use hexacomp_virtual::{DEFAULT_MACHINE_SEED, ErrorModel};

fn row<'t>(text: &'t str, head: &[&str]) -> Vec<&'t str> {
    text.lines()
        .map(|l| l.split_whitespace().collect::<Vec<_>>())
        .find(|words| words.starts_with(head))
        .unwrap_or_else(|| panic!("no row {head:?} in\n{text}"))[head.len()..]
        .to_vec()
}

/// The lines of `text` from the first one that starts with `heading` to the next blank line.
fn section<'t>(text: &'t str, heading: &str) -> &'t str {
    let start = text
        .find(&format!("\n{heading}"))
        .unwrap_or_else(|| panic!("no section {heading:?} in\n{text}"));
    let rest = &text[start + 1..];
    &rest[..rest.find("\n\n").unwrap_or(rest.len())]
}

fn four(values: &[f64]) -> Vec<String> {
    values.iter().map(|v| format!("{v:.4}")).collect()
}

#[test]
fn the_evaluate_command_prints_the_tables_of_the_largest_size_and_writes_the_figures() {
    let g = Geometry::prototype();
    let dir = tempfile::tempdir().unwrap();
    let out_dir = dir.path().join("figures");
    // Sizes out of order: the tables are of the largest, whatever its place in the list.
    let output = Command::new(hexacomp_tests::binary("hexacomp-trainer"))
        .args([
            "evaluate",
            "--sizes",
            "24,20",
            "--validation",
            "3",
            "--seed",
            "2",
        ])
        .args(["--validation-seed", "5", "--out-dir"])
        .arg(&out_dir)
        .output()
        .unwrap();
    let stdout = String::from_utf8(output.stdout).unwrap();
    assert!(
        output.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&output.stderr)
    );
    // What the command documents it runs: plan and noise from --seed, the default machine and
    // error variant, default training with equivalent input.
    let o = EvaluationOptions {
        training_sizes: vec![24, 20],
        validation_count: 3,
        plan_seed: 2,
        leg_extremes: true,
        validation_seed: 5,
        error_model: ErrorModel::default(),
        machine_seed: DEFAULT_MACHINE_SEED,
        noise_seed: 2,
        instrument_seed: 3,
        train: TrainOptions::default(),
    };
    let evaluation = evaluate(&g, &o, &|_| {}).unwrap();
    let largest = &evaluation.sizes[0];
    assert_eq!(largest.configurations, 24);

    // The lead-screw resolution: chosen at 24 configurations, eight at 20 (too few to hold two
    // out of each of five folds besides the twelve legs' extremes the plan starts with).
    let chosen = largest.resolution.as_ref().unwrap();
    assert_eq!(chosen.scores.len(), PITCH_RESOLUTIONS.len());
    assert!(evaluation.sizes[1].resolution.is_none());
    let resolution = section(&stdout, "The physical model's lead-screw resolution");
    let resolution_row = |n: &str| {
        resolution
            .lines()
            .find(|l| l.split_whitespace().next() == Some(n))
            .unwrap_or_else(|| panic!("{resolution}"))
            .to_string()
    };
    let cells: Vec<String> = resolution_row("24")
        .split_whitespace()
        .map(String::from)
        .collect();
    let mut expected = vec!["24".to_string(), chosen.options.pitch_basis.to_string()];
    for s in &chosen.scores {
        expected.extend([
            format!("{:.4}", s.cross_validated_rmse_mm),
            "±".into(),
            format!("{:.4}", s.standard_error_mm),
        ]);
    }
    assert_eq!(cells, expected, "{resolution}");
    assert!(
        resolution_row("20").contains("8 (too few to cross-validate)"),
        "{resolution}"
    );

    // Table 2.
    assert!(
        stdout.contains(
            "Table 2: pose errors at 3 fresh validation poses, 24 training configurations"
        ),
        "{stdout}"
    );
    // Table 2 twice: measured (the paper's protocol) first, then reached; then the paper's own.
    for (protocol, heading) in [
        (Protocol::Measured, "measured, the paper's protocol"),
        (
            Protocol::Reached,
            "reached: the pose the virtual machine really reached",
        ),
    ] {
        let table = section(&stdout, heading);
        let stats: Vec<PoseErrorStats> = Method::ALL
            .iter()
            .map(|m| largest.stats(*m, protocol))
            .collect();
        for (head, pick) in [
            (
                ["‖δ_A‖", "(mm)", "max"],
                (|s: &PoseErrorStats| s.position_mm.max) as fn(&PoseErrorStats) -> f64,
            ),
            (["‖δ_A‖", "(mm)", "mean"], |s| s.position_mm.mean),
            (["‖δ_A‖", "(mm)", "std"], |s| s.position_mm.std),
            (["‖ε‖", "(deg)", "max"], |s| s.orientation_deg.max),
            (["‖ε‖", "(deg)", "mean"], |s| s.orientation_deg.mean),
            (["‖ε‖", "(deg)", "std"], |s| s.orientation_deg.std),
        ] {
            let values: Vec<f64> = stats.iter().map(pick).collect();
            assert_eq!(row(table, &head), four(&values), "{protocol:?} {head:?}");
        }
    }
    // The paper's figures are printed with the measured table only.
    let paper = "The paper's Table 2, in its protocol on its prototype: mean ‖δ_A‖ 0.642 mm";
    assert!(
        section(&stdout, "measured, the paper's protocol").contains(paper),
        "{stdout}"
    );
    assert_eq!(stdout.matches(paper).count(), 1);
    // Fig. 13's numbers, one row per size in the order given.
    for size in &evaluation.sizes {
        let head = size.configurations.to_string();
        let expected: Vec<String> = Method::ALL
            .iter()
            .flat_map(|m| {
                let s = size.stats(*m, Protocol::Reached);
                [
                    format!("{:.4}", s.position_mm.mean),
                    "/".to_string(),
                    format!("{:.4}", s.orientation_deg.mean),
                ]
            })
            .collect();
        assert_eq!(row(&stdout, &[&head]), expected);
    }
    // Against the floor: each method's mean and max over the floor's, per size.
    let against = section(&stdout, "Against the floor");
    for size in &evaluation.sizes {
        let floor = size.stats(Method::Floor, Protocol::Reached).position_mm;
        let expected: Vec<String> = Method::ALL
            .iter()
            .filter(|m| **m != Method::Floor)
            .flat_map(|m| {
                let s = size.stats(*m, Protocol::Reached).position_mm;
                [
                    format!("{:.2}", s.mean / floor.mean),
                    "/".to_string(),
                    format!("{:.2}", s.max / floor.max),
                ]
            })
            .collect();
        assert_eq!(row(against, &[&size.configurations.to_string()]), expected);
    }
    // Table 1.
    assert!(stdout.contains("Table 1: robust networks at 24 configurations"));
    for (name, trained) in [
        ("coupled", &largest.coupled),
        ("decoupled", &largest.decoupled),
    ] {
        let words = row(&stdout, &[name]).join(" ");
        let nodes = format!("{:?}", trained.model.hidden_nodes());
        assert!(words.starts_with(&nodes), "{words}");
        assert!(
            words.ends_with(&format!("{:.4}", trained.validation_rmse_mm)),
            "{words}"
        );
    }
    assert!(stdout.contains(&format!(
        "{} of the training configurations had cond(PT) above c = 1e3",
        evaluation.above_threshold
    )));
    // The input comparison, labelled with the size it was made at.
    assert!(
        stdout.contains("Network input, robust decoupled at 24 configurations, reached:"),
        "{stdout}"
    );
    for (input, s) in &evaluation.inputs {
        let head = [input.name(), "legs"];
        let values = [
            s.position_mm.mean,
            s.position_mm.max,
            s.orientation_deg.mean,
        ];
        assert_eq!(row(&stdout, &head), four(&values), "{head:?}");
    }
    for file in [
        "fig12_position.svg",
        "fig12_orientation.svg",
        "fig13_position.svg",
        "fig13_orientation.svg",
    ] {
        let svg = std::fs::read_to_string(out_dir.join(file)).unwrap();
        assert!(
            svg.contains("<svg") && svg.contains("robust decoupled"),
            "{file}"
        );
    }
}
