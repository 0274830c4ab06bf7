//! `hexacomp-trainer plan → simulate → solve → identify` as a user runs it, its corrections
//! checked against the virtual machine they were measured on, and its answers to bad
//! measurement files.

use hexacomp_core::Geometry;
use hexacomp_core::stats::PoseErrorNorm;
use hexacomp_formats::{read_corrections, read_measurements, read_poses};
use hexacomp_tests::{assert_says, run, text, trainer_in, trainer_ok};
use hexacomp_virtual::{DEFAULT_MACHINE_SEED, ErrorModel, ErrorVariant, VirtualPlatform};

#[test]
fn plan_simulate_solve_identify_produce_the_design_formats() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    trainer_ok(
        d,
        &["plan", "--count", "60", "--seed", "3", "--out", "poses.csv"],
    );
    trainer_ok(
        d,
        &[
            "simulate",
            "--plan",
            "poses.csv",
            "--seed",
            "2",
            "--out",
            "m.csv",
        ],
    );
    let solved = trainer_ok(d, &["solve", "--measurements", "m.csv", "--out", "c.csv"]);
    assert!(
        solved.contains("60 of 60 configurations kept, 0 excluded")
            && solved.contains("robust compensator: 60 configurations"),
        "{solved}"
    );
    let ordinary = trainer_ok(
        d,
        &[
            "solve",
            "--ordinary",
            "--measurements",
            "m.csv",
            "--out",
            "o.csv",
        ],
    );
    assert!(ordinary.contains("ordinary compensator"), "{ordinary}");
    let identified = trainer_ok(
        d,
        &["identify", "--measurements", "m.csv", "--out", "id.toml"],
    );
    assert!(
        identified.contains("identified 42/42 parameter directions"),
        "{identified}"
    );

    let poses = read_poses(&d.join("poses.csv")).unwrap();
    let measurements = read_measurements(&d.join("m.csv")).unwrap();
    let corrections = read_corrections(&d.join("c.csv")).unwrap();
    assert_eq!(
        (poses.len(), measurements.len(), corrections.len()),
        (60, 60, 60)
    );
    // The corrections against the truth: the virtual machine that was measured (its noise from
    // another seed), commanded with the corrected legs, reaches the planned poses far closer
    // than with the nominal ones.
    let mut machine = VirtualPlatform::new(
        &Geometry::prototype(),
        &ErrorModel::variant(ErrorVariant::Paper),
        DEFAULT_MACHINE_SEED,
        99,
    )
    .unwrap();
    let (mut before, mut after) = (Vec::new(), Vec::new());
    for ((p, m), c) in poses.iter().zip(&measurements).zip(&corrections) {
        assert_eq!((&p.id, &p.pose_mm_deg), (&m.id, &m.pose_mm_deg));
        assert_eq!((&m.id, m.legs), (&c.id, c.legs));
        let target = p.pose();
        let nominal = machine.move_legs(&c.legs, &target).unwrap();
        before.push(PoseErrorNorm::between(&target, &nominal).position_mm);
        let corrected: [f64; 6] = std::array::from_fn(|i| c.legs[i] + c.corrections[i]);
        let reached = machine.move_legs(&corrected, &target).unwrap();
        after.push(PoseErrorNorm::between(&target, &reached).position_mm);
    }
    let worst = |e: &[f64]| e.iter().copied().fold(0.0, f64::max);
    let mean = |e: &[f64]| e.iter().sum::<f64>() / e.len() as f64;
    eprintln!(
        "position error at the 60 configurations: nominal mean {:.4} mm (worst {:.4}), \
         corrected mean {:.4} mm (worst {:.4})",
        mean(&before),
        worst(&before),
        mean(&after),
        worst(&after)
    );
    assert!(mean(&after) < mean(&before) / 10.0);
    assert!(
        worst(&after) < 0.05,
        "worst corrected error {} mm",
        worst(&after)
    );
    let header = std::fs::read_to_string(d.join("c.csv")).unwrap();
    assert!(header.starts_with(
        "id,q1,q2,q3,q4,q5,q6,dq1,dq2,dq3,dq4,dq5,dq6,cond_pt,iterations,converged,residual_mm\n"
    ));
    // With the same seeds the robust and ordinary solves coincide inside the workspace.
    assert_eq!(header, std::fs::read_to_string(d.join("o.csv")).unwrap());
    // The identified geometry loads on its own and carries leg offsets.
    let g = Geometry::load(&d.join("id.toml")).unwrap();
    assert!(
        g.leg_offsets.iter().any(|o| o.abs() > 0.01),
        "{:?}",
        g.leg_offsets
    );
}

#[test]
fn bad_measurement_files_are_refused_with_file_line_and_column() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    trainer_ok(d, &["plan", "--count", "5", "--out", "poses.csv"]);
    trainer_ok(d, &["simulate", "--plan", "poses.csv", "--out", "m.csv"]);
    let good = std::fs::read_to_string(d.join("m.csv")).unwrap();
    let lines: Vec<&str> = good.lines().collect();
    let cases = [
        (
            "missing.csv",
            good.replacen(",q3,", ",q3x,", 1),
            "m.csv:1: column q3: required column is missing from the header",
        ),
        (
            "dup.csv",
            format!("{}\n{}\n{}\n", lines[0], lines[1], lines[1]),
            "dup.csv:3: column id: duplicate id \"1\" (first on line 2; numeric ids are compared by value)",
        ),
    ];
    for (name, content, expected) in cases {
        let path = d.join(name);
        std::fs::write(&path, &content).unwrap();
        let output = run(
            "hexacomp-trainer",
            &[
                "solve",
                "--measurements",
                path.to_str().unwrap(),
                "--out",
                d.join("c.csv").to_str().unwrap(),
            ],
        );
        let message = text(&output.stderr);
        assert_eq!(output.status.code(), Some(1), "{name}: {message}");
        assert!(message.starts_with("error: "), "{name}: {message}");
        let expected = expected.replace("m.csv", name);
        assert!(message.contains(&expected), "{name}: {message}");
    }
    // A NaN in a named place: line 3 is the second data row; x is its second column.
    let mut rows: Vec<String> = lines.iter().map(|l| l.to_string()).collect();
    let mut cells: Vec<&str> = rows[2].split(',').collect();
    cells[1] = "NaN";
    rows[2] = cells.join(",");
    let path = d.join("nan.csv");
    std::fs::write(&path, rows.join("\n")).unwrap();
    let output = run(
        "hexacomp-trainer",
        &[
            "solve",
            "--measurements",
            path.to_str().unwrap(),
            "--out",
            d.join("c.csv").to_str().unwrap(),
        ],
    );
    assert_says(
        &output.stderr,
        "nan.csv:3: column x: \"NaN\" is not a finite number",
    );
}

#[test]
fn gross_errors_are_excluded_by_line_and_a_file_of_them_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    trainer_ok(d, &["plan", "--count", "20", "--out", "poses.csv"]);
    trainer_ok(d, &["simulate", "--plan", "poses.csv", "--out", "m.csv"]);
    let good = std::fs::read_to_string(d.join("m.csv")).unwrap();
    let lines: Vec<String> = good.lines().map(str::to_string).collect();
    // `change(lines, row, column, f)`: row `row` (1-based id = line − 1), cell `column`.
    let change = |lines: &mut Vec<String>, row: usize, column: usize, f: &dyn Fn(f64) -> f64| {
        let mut cells: Vec<String> = lines[row].split(',').map(str::to_string).collect();
        cells[column] = f(cells[column].parse().unwrap()).to_string();
        lines[row] = cells.join(",");
    };
    // Row id 2: a commanded leg beyond the stroke. Row id 4: a target 40 mm away.
    let mut bad = lines.clone();
    change(&mut bad, 2, 7, &|_| 445.0);
    change(&mut bad, 4, 16, &|x| x + 40.0);
    std::fs::write(d.join("bad.csv"), bad.join("\n") + "\n").unwrap();
    let report = trainer_ok(d, &["solve", "--measurements", "bad.csv", "--out", "c.csv"]);
    let bad_csv = d.join("bad.csv").display().to_string();
    assert!(
        report.contains(&format!(
            "excluded: configuration 2 ({bad_csv}:3): cannot be solved: leg 1 length 445"
        )),
        "{report}"
    );
    assert!(
        report.contains(&format!(
            "excluded: configuration 4 ({bad_csv}:5): fit residual"
        )),
        "{report}"
    );
    assert!(
        report.contains("18 of 20 configurations kept, 2 excluded"),
        "{report}"
    );
    // 18 rows are too few to identify 42 parameters from: the user is told the check is off.
    assert!(
        report.contains("note: the consistency check (against the identified geometry) was left out: 18 configurations, it needs 20"),
        "{report}"
    );
    let written = read_corrections(&d.join("c.csv")).unwrap();
    let ids: Vec<&str> = written.iter().map(|c| c.id.as_str()).collect();
    let expected: Vec<String> = (1..=20)
        .filter(|id| *id != 2 && *id != 4)
        .map(|id| id.to_string())
        .collect();
    assert_eq!(ids, expected);

    // Inches: every row is a gross error; the file is refused and c.csv is left as it was.
    let before = std::fs::read(d.join("c.csv")).unwrap();
    let mut inches = lines.clone();
    for row in 1..inches.len() {
        for column in 13..22 {
            change(&mut inches, row, column, &|x| x / 25.4);
        }
    }
    std::fs::write(d.join("inches.csv"), inches.join("\n") + "\n").unwrap();
    let output = trainer_in(
        d,
        &["solve", "--measurements", "inches.csv", "--out", "c.csv"],
    );
    let report = text(&output.stderr);
    assert!(!output.status.success(), "{report}");
    // The refusal names the file, and every row is listed with its line before it.
    let inches_csv = d.join("inches.csv").display().to_string();
    assert!(
        report.contains(&format!(
            "error: {inches_csv}: refused: 20 of 20 configurations would be excluded"
        )),
        "{report}"
    );
    for id in 1..=20 {
        assert!(
            report.contains(&format!(
                "excluded: configuration {id} ({inches_csv}:{}): ",
                id + 1
            )),
            "{report}"
        );
    }
    assert_eq!(std::fs::read(d.join("c.csv")).unwrap(), before);
}

/// Nominal fiducials on the prototype's base (base frame, mm).
const NOMINAL_FIDUCIALS: &str = "name,x,y,z\nF1,450,0,0\nF2,225,389.7,0\nF3,-225,389.7,20\n\
F4,-450,0,0\nF5,-225,-389.7,40\nF6,225,-389.7,0\n";

#[test]
fn a_tracker_campaign_is_registered_and_solved_in_the_base_frame() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    trainer_ok(d, &["plan", "--count", "30", "--out", "plan.csv"]);
    trainer_ok(d, &["simulate", "--plan", "plan.csv", "--out", "base.csv"]);
    trainer_ok(
        d,
        &[
            "simulate",
            "--plan",
            "plan.csv",
            "--out",
            "tracker.csv",
            "--instrument-pose",
            "2500,-1500,-800,0.3,-0.2,135",
            "--fiducials-out",
            "measured.csv",
        ],
    );
    // The nominal fiducials: the six of the built-in geometry.
    let output = trainer_in(
        d,
        &[
            "register",
            "--measured",
            "measured.csv",
            "--out",
            "registration.toml",
            "--instrument-mpe",
            "15+6",
        ],
    );
    assert!(output.status.success(), "{}", text(&output.stderr));
    let printed = text(&output.stdout);
    assert!(
        printed.contains("position   x 2500.0") && printed.contains("c 135.0"),
        "{printed}"
    );
    assert!(
        printed.contains("a measured target is known to"),
        "{printed}"
    );
    let inspected = text(&trainer_in(d, &["inspect", "registration.toml"]).stdout);
    assert!(
        inspected.contains("6 fiducials used: RMS")
            && inspected.contains("fiducials of geometry prototype")
            && inspected.contains("with an instrument of MPE 15 µm + 6 µm/m"),
        "{inspected}"
    );

    // Solved through the registration, the corrections are those of the base-frame campaign
    // up to the registration's error (the same noise draws: only the frame differs).
    trainer_ok(
        d,
        &[
            "solve",
            "--measurements",
            "base.csv",
            "--out",
            "base-dq.csv",
        ],
    );
    let said = trainer_ok(
        d,
        &[
            "solve",
            "--measurements",
            "tracker.csv",
            "--registration",
            "registration.toml",
            "--out",
            "tracker-dq.csv",
        ],
    );
    assert!(said.contains("brought into the base frame"), "{said}");
    let base = read_corrections(&d.join("base-dq.csv")).unwrap();
    let tracker = read_corrections(&d.join("tracker-dq.csv")).unwrap();
    assert_eq!(base.len(), 30);
    let largest = base
        .iter()
        .zip(tracker.iter())
        .flat_map(|(b, t)| (0..6).map(move |i| (b.corrections[i] - t.corrections[i]).abs()))
        .fold(0.0, f64::max);
    assert!(largest < 0.03, "corrections differ by {largest} mm");
    assert!(largest > 0.0, "the registration changed nothing");

    // Without the registration the same file is refused as a whole.
    let output = trainer_in(
        d,
        &["solve", "--measurements", "tracker.csv", "--out", "x.csv"],
    );
    assert!(!output.status.success());
    assert_says(&output.stderr, "give --registration");
}

#[test]
fn a_refused_registration_writes_nothing_and_leaves_the_old_one() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("nominal.csv"), NOMINAL_FIDUCIALS).unwrap();
    // F2 and F5 swapped by the operator.
    std::fs::write(
        d.join("measured.csv"),
        NOMINAL_FIDUCIALS
            .replace("F2,", "X,")
            .replace("F5,", "F2,")
            .replace("X,", "F5,"),
    )
    .unwrap();
    std::fs::write(d.join("registration.toml"), "the previous registration").unwrap();
    let output = trainer_in(
        d,
        &[
            "register",
            "--nominal",
            "nominal.csv",
            "--measured",
            "measured.csv",
            "--out",
            "registration.toml",
        ],
    );
    assert!(!output.status.success());
    let message = text(&output.stderr);
    assert!(
        message.contains("The names F2 and F5 look swapped")
            && message.contains("no registration written"),
        "{message}"
    );
    assert_eq!(
        std::fs::read_to_string(d.join("registration.toml")).unwrap(),
        "the previous registration"
    );
    let names: Vec<_> = std::fs::read_dir(d)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    assert_eq!(names.len(), 3, "{names:?}");
}

#[test]
fn gaps_and_a_probe_in_pi_angles_are_solved_and_reported() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    trainer_ok(d, &["plan", "--count", "30", "--out", "plan.csv"]);
    trainer_ok(d, &["simulate", "--plan", "plan.csv", "--out", "base.csv"]);
    trainer_ok(
        d,
        &[
            "simulate",
            "--plan",
            "plan.csv",
            "--out",
            "gaps.csv",
            "--drop-rate",
            "0.3",
        ],
    );
    let gaps = std::fs::read_to_string(d.join("gaps.csv")).unwrap();
    let gappy_rows = gaps.lines().filter(|l| l.contains(",,,")).count();
    assert!(gappy_rows > 3, "{gaps}");
    let said = trainer_ok(
        d,
        &[
            "solve",
            "--measurements",
            "gaps.csv",
            "--out",
            "gaps-dq.csv",
        ],
    );
    assert_eq!(
        said.matches("cannot be used: 2 of 3 targets seen").count(),
        gappy_rows,
        "{said}"
    );
    assert!(
        said.contains(&format!(
            "{gappy_rows} whose targets seen do not fix the pose"
        )),
        "{said}"
    );
    assert_eq!(
        read_corrections(&d.join("gaps-dq.csv")).unwrap().len(),
        30 - gappy_rows
    );
    // Read for a geometry with four targets, the file is refused at its first row.
    let prototype = Geometry::prototype().to_toml_string();
    std::fs::write(
        d.join("four.toml"),
        prototype.replace("targets = [", "targets = [[0.0, 0.0, 60.0], "),
    )
    .unwrap();
    let output = trainer_in(
        d,
        &[
            "--geometry",
            "four.toml",
            "solve",
            "--measurements",
            "gaps.csv",
            "--out",
            "x.csv",
        ],
    );
    assert!(!output.status.success());
    assert!(
        text(&output.stderr).contains(
            "gaps.csv:2: configuration 1: 3 measured targets, but geometry prototype names 4"
        ),
        "{}",
        text(&output.stderr)
    );

    // A 6-DoF probe writing PI's U, V, W: read in that convention, the corrections are those of
    // the targets it was fitted to (to the fit's noise); read as LinuxCNC angles, they are not.
    trainer_ok(
        d,
        &[
            "simulate",
            "--plan",
            "plan.csv",
            "--out",
            "probe.csv",
            "--probe",
            "--pose-convention",
            "pi-uvw",
        ],
    );
    assert!(
        std::fs::read_to_string(d.join("probe.csv"))
            .unwrap()
            .contains(",mx,my,mz,ma,mb,mc\n")
    );
    trainer_ok(
        d,
        &[
            "solve",
            "--measurements",
            "base.csv",
            "--out",
            "base-dq.csv",
        ],
    );
    trainer_ok(
        d,
        &[
            "solve",
            "--measurements",
            "probe.csv",
            "--pose-convention",
            "pi-uvw",
            "--out",
            "probe-dq.csv",
        ],
    );
    let largest_difference = |other: &str| {
        let base = read_corrections(&d.join("base-dq.csv")).unwrap();
        let other = read_corrections(&d.join(other)).unwrap();
        base.iter()
            .zip(other.iter())
            .flat_map(|(b, o)| (0..6).map(move |i| (b.corrections[i] - o.corrections[i]).abs()))
            .fold(0.0, f64::max)
    };
    assert!(largest_difference("probe-dq.csv") < 1e-6);
    let output = trainer_in(
        d,
        &[
            "solve",
            "--measurements",
            "probe.csv",
            "--out",
            "wrong-dq.csv",
        ],
    );
    assert!(
        !output.status.success() || largest_difference("wrong-dq.csv") > 0.01,
        "read in the wrong convention, the probe's poses gave the same corrections"
    );
}
