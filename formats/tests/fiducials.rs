//! The fiducials reader (`name,x,y,z[,weight]`) and the registration TOML: bad input is an error
//! naming the file, line and column; a written registration reads back to the same numbers.

use glam::DVec3;
use hexacomp_core::records::NamedPoint;
use hexacomp_formats::{
    RegisteredFiducial, RegistrationFile, read_fiducials, read_registration, write_fiducials,
};

/// Reads `text` as a fiducials file named `f.csv`: the error text, or the points.
fn fiducials(text: &str) -> Result<Vec<NamedPoint>, String> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("f.csv");
    std::fs::write(&path, text).unwrap();
    read_fiducials(&path)
        .map(|r| r.into_items())
        .map_err(|e| e.to_string().replace(&dir.path().display().to_string(), ""))
}

#[test]
fn fiducials_read_by_name_with_an_optional_weight() {
    let points = fiducials("z,name,y,x\n0.5,F1,2,1\n# comment\n3,F2,-1,7e2\n").unwrap();
    assert_eq!(points[0].position, DVec3::new(1.0, 2.0, 0.5));
    assert_eq!(points[1].position, DVec3::new(700.0, -1.0, 3.0));
    assert_eq!(points[1].weight, 1.0);
    let weighted = fiducials("name,x,y,z,weight\nF1,1,2,3,0\n").unwrap();
    assert_eq!(weighted[0].weight, 0.0);
}

#[test]
fn bad_fiducials_are_refused_with_file_line_and_column() {
    for (text, expected) in [
        (
            "name,x,y,z\nF1,1,NaN,3\n",
            "/f.csv:2: column y: \"NaN\" is not a finite number",
        ),
        (
            "name,x,y\nF1,1,2\n",
            "/f.csv:1: column z: required column is missing from the header",
        ),
        (
            "id,x,y,z\nF1,1,2,3\n",
            "/f.csv:1: column name: required column is missing",
        ),
        (
            "name,x,y,z\nF1,1,2,3\nF1,4,5,6\n",
            "/f.csv:3: column name: duplicate name \"F1\" (first on line 2)",
        ),
        (
            "name,x,y,z\nF1,1,two,3\n",
            "/f.csv:2: column y: \"two\" is not a number",
        ),
        ("name,x,y,z\n,1,2,3\n", "/f.csv:2: column name: empty name"),
        (
            "name,x,y,z,weight\nF1,1,2,3,-1\n",
            "/f.csv:2: column weight: weight -1 is negative",
        ),
        (
            "name,x,y,z\nF1,1,2\n",
            "/f.csv:2: row has 3 fields, the header has 4",
        ),
    ] {
        let message = fiducials(text).expect_err(text);
        assert!(message.contains(expected), "{text:?}: {message}");
    }
}

#[test]
fn written_fiducials_read_back_to_the_same_bits() {
    let points: Vec<NamedPoint> = (0..4)
        .map(|k| NamedPoint {
            name: format!("F{k}"),
            position: DVec3::new(0.1 * k as f64, -1.0 / 3.0, 1e-7 + k as f64 * 1234.5678),
            weight: 1.0,
        })
        .collect();
    let mut text = Vec::new();
    write_fiducials(&mut text, &points).unwrap();
    assert_eq!(
        fiducials(std::str::from_utf8(&text).unwrap()).unwrap(),
        points
    );
}

/// A registration whose residuals are those its pose gives.
fn registration() -> RegistrationFile {
    let mut file = RegistrationFile {
        format: 1,
        created: "2026-11-24T00:00:00Z".into(),
        nominal: "nominal.csv".into(),
        measured: "tracker.csv".into(),
        instrument_pose: [2500.0095, -1.0 / 3.0, -800.1, 0.1 / 3.0, -0.02, 135.000545],
        locked: vec!["a".into(), "b".into()],
        tolerance_mm: 0.05,
        rms_mm: 0.0134,
        max_mm: 0.0202,
        instrument_mpe_um: Some([15.0, 6.0]),
        supported_mm: Some(0.0345),
        fiducials: (0..3)
            .map(|k| RegisteredFiducial {
                name: format!("F{k}"),
                nominal: [k as f64, 1.0, 2.0],
                measured: [0.1, k as f64 / 7.0, -3.0],
                weight: 1.0,
                residual: [0.0; 3],
            })
            .collect(),
    };
    let pose = file.instrument_pose();
    for f in &mut file.fiducials {
        f.residual = (pose.transform_point(DVec3::from_array(f.measured))
            - DVec3::from_array(f.nominal))
        .to_array();
    }
    file
}

/// Writes `text` as `r.toml` and reads it: the error text, or the registration.
fn read_text(text: &str) -> Result<RegistrationFile, String> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("r.toml");
    std::fs::write(&path, text).unwrap();
    read_registration(&path).map_err(|e| e.to_string())
}

#[test]
fn a_registration_reads_back_exactly() {
    let file = registration();
    assert_eq!(read_text(&file.to_toml_string()).unwrap(), file);
}

#[test]
fn bad_registrations_are_refused_with_their_cause() {
    let good = registration().to_toml_string();
    for (text, expected) in [
        (
            good.replace("format = 1", "format = 2"),
            "format version 2, this build reads version 1",
        ),
        (
            good.replace("locked = [\"a\", \"b\"]", "locked = [\"q\"]"),
            "locked names \"q\"",
        ),
        (
            good.replace("tolerance_mm = 0.05", "tolerance_mm = nan"),
            "not finite",
        ),
        (
            good.replace("2500.0095", "\"x\""),
            "r.toml: not a registration file",
        ),
        (good.replace("rms_mm", "rms"), "unknown field `rms`"),
        (
            good.replace("[[fiducials]]\nname = \"F2\"", "[[other]]\nname = \"F2\""),
            "unknown field `other`",
        ),
        ("format = 1\n".to_string(), "missing field"),
    ] {
        let message = read_text(&text).expect_err(&text);
        assert!(message.contains(expected), "{expected}: {message}");
    }
    let mut two = registration();
    two.fiducials.truncate(2);
    let message = read_text(&two.to_toml_string()).expect_err("two fiducials");
    assert!(
        message.contains("2 fiducials: a registration has at least three"),
        "{message}"
    );
    let mut unused = registration();
    unused.fiducials[0].weight = 0.0;
    let message = read_text(&unused.to_toml_string()).expect_err("two used");
    assert!(
        message.contains("2 fiducials of positive weight"),
        "{message}"
    );
    let mut twice = registration();
    twice.fiducials[1].name = "F0".into();
    let message = read_text(&twice.to_toml_string()).expect_err("twice");
    assert!(
        message.contains("fiducial \"F0\" appears twice"),
        "{message}"
    );
    let mut negative = registration();
    negative.fiducials[2].weight = -1.0;
    let message = read_text(&negative.to_toml_string()).expect_err("negative");
    assert!(message.contains("negative weight -1"), "{message}");
    let mut edited = registration();
    edited.instrument_pose[0] += 0.01;
    let message = read_text(&edited.to_toml_string()).expect_err("edited");
    assert!(
        message.contains("instrument_pose does not give fiducial \"F0\"'s residual"),
        "{message}"
    );
}
