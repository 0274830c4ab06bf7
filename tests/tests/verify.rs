//! `hexacomp-trainer verify` as a user runs it on the virtual machine: the ISO 9283 pose test
//! before and after a calibration (AP at least 10× better, RP not worse), its figures recomputed
//! here from the raw attained poses by the standard's formulas, `check` against it, a registered tracker giving the
//! figures the base frame gives, and bad input refused with nothing written.

use std::collections::BTreeMap;
use std::path::Path;

use hexacomp_tests::{json_file, text, trainer_fails, trainer_in, trainer_ok_stdout};
use serde_json::Value;

/// The raw attained poses by pose name, in file order.
fn raw_poses(path: &Path) -> BTreeMap<String, Vec<[f64; 6]>> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("cycle,pose,x,y,z,a,b,c"));
    let mut poses: BTreeMap<String, Vec<[f64; 6]>> = BTreeMap::new();
    for line in lines {
        let cells: Vec<&str> = line.split(',').collect();
        assert_eq!(cells.len(), 8, "{line}");
        let values: [f64; 6] = std::array::from_fn(|k| cells[2 + k].parse().unwrap());
        poses.entry(cells[1].to_string()).or_default().push(values);
    }
    poses
}

fn number(value: &Value, key: &str) -> f64 {
    value[key]
        .as_f64()
        .unwrap_or_else(|| panic!("{key} in {value}"))
}

/// AP and RP of `attained` at `commanded` as ISO 9283 § 7.2 writes them (no angle near ±180°
/// here, so angles are averaged as they are): `[AP_P, AP_a, AP_b, AP_c, RP_l, RP_a, RP_b, RP_c]`.
fn iso_figures(commanded: &[f64], attained: &[[f64; 6]]) -> [f64; 8] {
    let n = attained.len() as f64;
    let mean: Vec<f64> = (0..6)
        .map(|k| attained.iter().map(|p| p[k]).sum::<f64>() / n)
        .collect();
    let ap_p = ((mean[0] - commanded[0]).powi(2)
        + (mean[1] - commanded[1]).powi(2)
        + (mean[2] - commanded[2]).powi(2))
    .sqrt();
    let l: Vec<f64> = attained
        .iter()
        .map(|p| {
            ((p[0] - mean[0]).powi(2) + (p[1] - mean[1]).powi(2) + (p[2] - mean[2]).powi(2)).sqrt()
        })
        .collect();
    let l_mean = l.iter().sum::<f64>() / n;
    let s = |values: &[f64], m: f64| {
        (values.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
    };
    let angle = |k: usize| -> Vec<f64> { attained.iter().map(|p| p[k]).collect() };
    [
        ap_p,
        mean[3] - commanded[3],
        mean[4] - commanded[4],
        mean[5] - commanded[5],
        l_mean + 3.0 * s(&l, l_mean),
        3.0 * s(&angle(3), mean[3]),
        3.0 * s(&angle(4), mean[4]),
        3.0 * s(&angle(5), mean[5]),
    ]
}

const KEYS: [&str; 8] = [
    "ap_p_mm", "ap_a_deg", "ap_b_deg", "ap_c_deg", "rp_l_mm", "rp_a_deg", "rp_b_deg", "rp_c_deg",
];

/// Checks every pose's figures in `json` against the standard's formulas applied to the raw CSV
/// (1e-9 mm and degrees), and the attained poses in the JSON against the CSV.
fn check_report_against_raw(json: &Value, raw: &BTreeMap<String, Vec<[f64; 6]>>) {
    let poses = json["poses"].as_array().unwrap();
    for pose in poses {
        let name = pose["name"].as_str().unwrap();
        let attained = &raw[name];
        let commanded: Vec<f64> = pose["commanded"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        let expected = iso_figures(&commanded, attained);
        for (key, want) in KEYS.iter().zip(expected) {
            // The CSV holds every number to the bit: only the order of the sums differs.
            let tolerance = 1e-9;
            let got = number(pose, key);
            assert!(
                (got - want).abs() <= tolerance,
                "{name} {key}: report {got}, from the raw poses {want}"
            );
        }
        assert_eq!(number(pose, "cycles") as usize, attained.len());
        let in_json: Vec<[f64; 6]> = serde_json::from_value(pose["attained"].clone()).unwrap();
        assert_eq!(&in_json, attained, "{name}: the JSON's attained poses");
    }
}

fn worst(json: &Value, key: &str) -> f64 {
    json["poses"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| number(p, key))
        .fold(0.0, f64::max)
}

#[test]
fn a_calibrated_model_improves_ap_tenfold_rp_holds_and_the_report_agrees_with_the_raw_poses() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    trainer_ok_stdout(d, &["calibrate", "--out-dir", "cal"]);
    trainer_ok_stdout(d, &["verify", "--out", "before.csv"]);
    let printed = trainer_ok_stdout(
        d,
        &[
            "verify",
            "--out",
            "after.csv",
            "--model",
            "cal/model.hxm",
            "--before",
            "before.json",
            "--air-temperature",
            "20.5",
            "--instrument-mpe",
            "15+6",
        ],
    );
    let (before, after) = (
        json_file(&d.join("before.json")),
        json_file(&d.join("after.json")),
    );
    let names: Vec<&str> = after["poses"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["name"].as_str().unwrap())
        .collect();
    assert_eq!(
        names,
        [
            "P1", "P5", "P4", "P3", "P2", "O1", "O2", "O3", "O4", "O5", "O6"
        ]
    );
    for (json, raw) in [(&before, "before.csv"), (&after, "after.csv")] {
        let raw = raw_poses(&d.join(raw));
        assert!(raw.values().all(|attained| attained.len() == 30));
        check_report_against_raw(json, &raw);
    }
    let (ap_before, ap_after) = (worst(&before, "ap_p_mm"), worst(&after, "ap_p_mm"));
    assert!(
        ap_before >= 10.0 * ap_after,
        "worst AP_P {ap_before} mm before, {ap_after} mm after"
    );
    for (b, a) in before["poses"]
        .as_array()
        .unwrap()
        .iter()
        .zip(after["poses"].as_array().unwrap())
    {
        assert!(
            number(a, "rp_l_mm") <= 1.3 * number(b, "rp_l_mm"),
            "{}: RP_l {a} after, {b} before",
            a["name"]
        );
    }
    assert_eq!(after["conditions"]["air_temperature_c"], 20.5);
    assert_eq!(
        after["conditions"]["instrument_mpe_um"],
        serde_json::json!([15.0, 6.0])
    );
    assert_eq!(after["conditions"]["model"], "cal/model.hxm");
    assert!(printed.contains("× better"), "{printed}");
    // The readable report: both runs' tables and a chart per pose and run.
    let html = std::fs::read_to_string(d.join("after.html")).unwrap();
    assert!(html.contains("<h2>Before</h2>") && html.contains("<h2>After</h2>"));
    assert_eq!(html.matches("<svg").count(), 2 * names.len());

    // The monthly check against what verify proved: the same machine and model keep the
    // promise; compensation lost, or a machine that changed (another draw of its errors, as after
    // a crash), do not.
    let said = trainer_ok_stdout(
        d,
        &[
            "check",
            "--promise",
            "after.json",
            "--model",
            "cal/model.hxm",
            "--out",
            "c.csv",
        ],
    );
    assert!(said.starts_with("still good: "), "{said}");
    assert_eq!(raw_poses(&d.join("c.csv")).len(), names.len());
    for other in [
        &["check", "--promise", "after.json"][..],
        &[
            "check",
            "--promise",
            "after.json",
            "--model",
            "cal/model.hxm",
            "--machine-seed",
            "5",
        ],
    ] {
        let output = trainer_in(d, other);
        assert!(!output.status.success(), "{other:?}");
        assert!(
            text(&output.stdout).starts_with("retrain: "),
            "{other:?}: {}",
            text(&output.stdout)
        );
    }
}

#[test]
fn a_tracker_away_from_the_base_needs_its_registration_and_then_gives_the_base_frames_figures() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let at = "2500,-1500,-800,0.3,-0.2,135";
    trainer_ok_stdout(d, &["plan", "--count", "3", "--out", "plan.csv"]);
    trainer_ok_stdout(
        d,
        &[
            "simulate",
            "--plan",
            "plan.csv",
            "--out",
            "tracker.csv",
            "--instrument-pose",
            at,
            "--fiducials-out",
            "measured.csv",
        ],
    );
    trainer_ok_stdout(
        d,
        &[
            "register",
            "--measured",
            "measured.csv",
            "--out",
            "registration.toml",
        ],
    );
    let short = ["--cycles", "5", "--no-orientation-poses"];
    let refused = trainer_fails(
        d,
        &[
            &["verify", "--out", "t.csv", "--instrument-pose", at][..],
            &short,
        ]
        .concat(),
    );
    assert!(refused.contains("give --registration"), "{refused}");
    assert!(!d.join("t.csv").exists() && !d.join("t.json").exists());
    trainer_ok_stdout(
        d,
        &[
            &[
                "verify",
                "--out",
                "tracker.csv",
                "--instrument-pose",
                at,
                "--registration",
                "registration.toml",
            ][..],
            &short,
        ]
        .concat(),
    );
    trainer_ok_stdout(d, &[&["verify", "--out", "base.csv"][..], &short].concat());
    // The same attained poses (the noise is keyed on the pose and cycle), seen through the
    // registration: they differ by its error only, micrometres, not the metres between frames.
    let (tracker, base) = (
        raw_poses(&d.join("tracker.csv")),
        raw_poses(&d.join("base.csv")),
    );
    assert_eq!(tracker.len(), 5);
    for (name, poses) in &base {
        for (t, b) in tracker[name].iter().zip(poses) {
            let distance =
                ((t[0] - b[0]).powi(2) + (t[1] - b[1]).powi(2) + (t[2] - b[2]).powi(2)).sqrt();
            assert!(
                distance < 0.05,
                "{name}: {t:?} through the tracker, {b:?} in the base"
            );
            assert!(distance > 0.0, "{name}: the registration was not applied");
        }
    }
}

#[test]
fn bad_input_is_refused_with_its_cause_and_nothing_written() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    trainer_ok_stdout(
        d,
        &[
            "verify",
            "--out",
            "five.csv",
            "--cycles",
            "3",
            "--no-orientation-poses",
        ],
    );
    let written = |stem: &str| {
        ["csv", "json", "html"]
            .iter()
            .any(|e| d.join(format!("{stem}.{e}")).exists())
    };
    // A previous run of other poses cannot be set beside this one.
    let error = trainer_fails(
        d,
        &[
            "verify",
            "--out",
            "all.csv",
            "--cycles",
            "3",
            "--before",
            "five.json",
        ],
    );
    assert!(
        error.contains("five.json") && error.contains("other poses"),
        "{error}"
    );
    assert!(!written("all"));
    // A file that is not a verify report.
    std::fs::write(d.join("not.json"), "{\"poses\": 3}").unwrap();
    let error = trainer_fails(
        d,
        &[
            "verify", "--out", "all.csv", "--cycles", "3", "--before", "not.json",
        ],
    );
    assert!(
        error.contains("not.json") && error.contains("not a report"),
        "{error}"
    );
    // The derived report would replace the run set beside it.
    let before = std::fs::read(d.join("five.json")).unwrap();
    let error = trainer_fails(
        d,
        &[
            "verify",
            "--out",
            "five.csv",
            "--cycles",
            "3",
            "--before",
            "five.json",
        ],
    );
    assert!(error.contains("five.json"), "{error}");
    assert_eq!(std::fs::read(d.join("five.json")).unwrap(), before);
    // Two outputs in one file, a temperature that is not one, one cycle.
    let error = trainer_fails(
        d,
        &[
            "verify", "--out", "x.csv", "--json", "x.csv", "--cycles", "3",
        ],
    );
    assert!(error.contains("two outputs"), "{error}");
    let error = trainer_fails(
        d,
        &[
            "verify",
            "--out",
            "x.csv",
            "--cycles",
            "3",
            "--air-temperature",
            "NaN",
        ],
    );
    assert!(error.contains("--air-temperature"), "{error}");
    let error = trainer_fails(d, &["verify", "--out", "x.csv", "--cycles", "1"]);
    assert!(error.contains("--cycles"), "{error}");
    assert!(!written("x"));
}
