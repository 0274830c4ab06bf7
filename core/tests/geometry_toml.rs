//! The geometry TOML: round trips and refusal of malformed files with errors that name the
//! problem.

use hexacomp_core::{Error, Geometry};

fn prototype_toml() -> String {
    Geometry::prototype().to_toml_string()
}

/// The prototype's TOML with the line starting with `key` replaced by `replacement`.
fn with_line(key: &str, replacement: &str) -> String {
    let text = prototype_toml();
    assert!(text.contains(key), "{key} not in\n{text}");
    text.lines()
        .map(|l| {
            if l.starts_with(key) {
                replacement.to_string()
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
}

fn invalid_message(text: &str) -> String {
    match Geometry::from_toml_str(text) {
        Err(Error::InvalidGeometry(m)) => m,
        other => panic!("expected InvalidGeometry, got {other:?}"),
    }
}

#[test]
fn toml_round_trip_through_a_file_keeps_every_number_and_the_fingerprint() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("prototype.toml");
    let g = Geometry::prototype();
    g.save(&path).unwrap();
    let back = Geometry::load(&path).unwrap();
    assert_eq!(back, g);
    assert_eq!(back.fingerprint(), g.fingerprint());
    // Saving the reloaded geometry gives byte-identical text.
    assert_eq!(back.to_toml_string(), g.to_toml_string());
}

const HAND_WRITTEN: &str = r#"
name = "hand"
base_joints = [[357.393, -95.763, 0], [357.393, 95.763, 0], [-95.763, 357.393, 0],
               [-261.630, 261.630, 0], [-261.630, -261.630, 0], [-95.763, -357.393, 0]]
platform_joints = [[176.777, -176.777, 0], [176.777, 176.777, 0], [64.705, 241.481, 0],
                   [-241.481, 64.705, 0], [-241.481, -64.705, 0], [64.705, -241.481, 0]]
leg_range = [280.0, 430.0]
home = [0, 0, 280, 0, 0, 0]
targets = [[0, 180, 25], [-155.885, -90, 25], [155.885, -90, 25]]
[workspace]
radius = 75.0
z_range = [230.0, 330.0]
tilt_max = 15.0
yaw_range = [-10.0, 10.0]
"#;

#[test]
fn a_hand_written_file_in_the_design_layout_loads() {
    let g = Geometry::from_toml_str(HAND_WRITTEN).unwrap();
    assert_eq!(g.name, "hand");
    assert_eq!(g.base_joints[2].y, 357.393);
    assert_eq!(g.workspace.tilt_max, 15.0);
    // Integers are accepted where floats are expected.
    assert_eq!(g.home, [0.0, 0.0, 280.0, 0.0, 0.0, 0.0]);
}

#[test]
fn an_architecturally_singular_platform_is_refused() {
    // Two similar hexagons with evenly spaced joints (every leg turned by the same 30°) form a
    // platform that is singular everywhere; it must not load.
    let text = r#"
name = "singular"
base_joints = [[370, 0, 0], [185, 320.429, 0], [-185, 320.429, 0],
               [-370, 0, 0], [-185, -320.429, 0], [185, -320.429, 0]]
platform_joints = [[216.506, 125, 0], [0, 250, 0], [-216.506, 125, 0],
                   [-216.506, -125, 0], [0, -250, 0], [216.506, -125, 0]]
leg_range = [280.0, 430.0]
home = [0, 0, 280, 0, 0, 0]
targets = [[0, 180, 25], [-155.9, -90, 25], [155.9, -90, 25]]
[workspace]
radius = 75.0
z_range = [230.0, 330.0]
tilt_max = 15.0
yaw_range = [-10.0, 10.0]
"#;
    let message = invalid_message(text);
    assert!(
        message.starts_with("the platform is singular at the home pose"),
        "{message}"
    );
}

#[test]
fn wrong_row_count_is_named() {
    let text = with_line(
        "base_joints",
        "base_joints = [[1.0, 2.0, 0.0], [3.0, 4.0, 0.0], [5.0, 6.0, 0.0], [7.0, 8.0, 0.0], [9.0, 1.0, 0.0]]",
    );
    assert_eq!(invalid_message(&text), "base_joints has 5 rows, expected 6");
}

#[test]
fn non_finite_number_is_named_with_its_position() {
    let text = with_line("home", "home = [0.0, 0.0, nan, 0.0, 0.0, 0.0]");
    assert_eq!(
        invalid_message(&text),
        "home[2] is NaN, expected a finite number"
    );
    let text = with_line(
        "targets",
        "targets = [[0.0, 180.0, 25.0], [-155.9, -90.0, inf], [155.9, -90.0, 25.0]]",
    );
    assert_eq!(
        invalid_message(&text),
        "targets[1][2] is inf, expected a finite number"
    );
}

#[test]
fn collinear_targets_are_refused() {
    let text = with_line(
        "targets",
        "targets = [[0.0, 0.0, 25.0], [100.0, 0.0, 25.0], [200.0, 0.0, 25.0]]",
    );
    let message = invalid_message(&text);
    assert!(message.starts_with("targets are collinear"), "{message}");
}

#[test]
fn home_outside_the_stroke_names_the_legs() {
    let text = with_line("home", "home = [0.0, 0.0, 150.0, 0.0, 0.0, 0.0]");
    let message = invalid_message(&text);
    assert!(message.starts_with("home pose"), "{message}");
    assert!(
        message.contains("outside the stroke [280, 430] mm"),
        "{message}"
    );
    assert!(
        message.contains("leg 1 = ") && message.contains("leg 6 = "),
        "{message}"
    );
}

#[test]
fn other_inconsistencies_are_refused() {
    let cases = [
        (
            "leg_range",
            "leg_range = [430.0, 280.0]",
            "leg_range [430, 280]",
        ),
        ("tilt_max", "tilt_max = 95.0", "workspace.tilt_max 95°"),
        (
            "radius",
            "radius = -1.0",
            "workspace.radius -1 mm is negative",
        ),
    ];
    for (key, line, expected) in cases {
        let message = invalid_message(&with_line(key, line));
        assert!(message.starts_with(expected), "{key}: {message}");
    }
}

#[test]
fn syntax_errors_and_unknown_keys_are_parse_errors() {
    for text in [
        "name = \"x\"\nbase_joints = [[",
        &format!(
            "{}\nlegs = 7\n",
            prototype_toml().replacen("name", "colour = 1\nname", 1)
        ),
    ] {
        assert!(matches!(
            Geometry::from_toml_str(text),
            Err(Error::GeometryParse(_))
        ));
    }
    let missing = with_line("leg_range", "");
    match Geometry::from_toml_str(&missing) {
        Err(Error::GeometryParse(m)) => assert!(m.contains("leg_range"), "{m}"),
        other => panic!("expected a parse error naming leg_range, got {other:?}"),
    }
}

#[test]
fn a_missing_file_names_the_path() {
    let err = Geometry::load(std::path::Path::new("/nonexistent/geometry.toml")).unwrap_err();
    assert!(
        err.to_string().contains("/nonexistent/geometry.toml"),
        "{err}"
    );
}

#[test]
fn leg_offsets_are_optional_round_trip_and_enter_the_fingerprint() {
    let prototype = Geometry::prototype();
    assert!(!prototype.to_toml_string().contains("leg_offsets"));
    let mut identified = prototype.clone();
    identified.leg_offsets = [0.1, -0.2, 0.0, 0.05, 0.3, -0.45];
    let text = identified.to_toml_string();
    assert!(
        text.contains("leg_offsets = [0.1, -0.2, 0.0, 0.05, 0.3, -0.45]"),
        "{text}"
    );
    let back = Geometry::from_toml_str(&text).unwrap();
    assert_eq!(back, identified);
    assert_ne!(back.fingerprint(), prototype.fingerprint());
    // Commanded lengths are the joint distances minus the offsets.
    let home = prototype.home_pose();
    let nominal = hexacomp_core::inverse_kinematics(&prototype, &home).lengths;
    let shifted = hexacomp_core::inverse_kinematics(&identified, &home).lengths;
    for i in 0..6 {
        assert!((nominal[i] - shifted[i] - identified.leg_offsets[i]).abs() < 1e-12);
    }
}

#[test]
fn any_number_of_targets_from_three_is_read_and_written_back() {
    let text = with_line(
        "targets",
        "targets = [[0.0, 180.0, 25.0], [-155.9, -90.0, 25.0], [155.9, -90.0, 25.0], [0.0, 0.0, 60.0], [10.0, 20.0, 30.0]]",
    );
    let geometry = Geometry::from_toml_str(&text).expect("five targets");
    assert_eq!(geometry.targets.len(), 5);
    assert_eq!(
        Geometry::from_toml_str(&geometry.to_toml_string()).unwrap(),
        geometry
    );
    let text = with_line(
        "targets",
        "targets = [[0.0, 180.0, 25.0], [-155.9, -90.0, 25.0]]",
    );
    assert_eq!(
        invalid_message(&text),
        "targets has 2 rows, at least 3 are needed"
    );
    // Four targets on one line are as collinear as three.
    let text = with_line(
        "targets",
        "targets = [[0.0, 0.0, 25.0], [100.0, 0.0, 25.0], [200.0, 0.0, 25.0], [-50.0, 0.0, 25.0]]",
    );
    assert!(invalid_message(&text).starts_with("targets are collinear"));
}

#[test]
fn fiducials_are_read_checked_and_left_out_of_the_fingerprint() {
    let prototype = Geometry::prototype();
    assert_eq!(prototype.fiducials.len(), 6);
    let mut bare = prototype.clone();
    bare.fiducials.clear();
    assert_eq!(bare.fingerprint(), prototype.fingerprint());
    let text = bare.to_toml_string();
    assert!(!text.contains("fiducials"), "{text}");
    assert_eq!(Geometry::from_toml_str(&text).unwrap(), bare);

    let with = |entries: &str| format!("{text}{entries}");
    let one = "\n[[fiducials]]\nname = \"nest A\"\nposition = [450.0, 0.0, 12.5]\n";
    let read = Geometry::from_toml_str(&with(one)).unwrap();
    assert_eq!(read.fiducials[0].name, "nest A");
    assert_eq!(
        read.fiducials[0].position,
        glam::DVec3::new(450.0, 0.0, 12.5)
    );
    let twice = format!("{one}{one}");
    let message = Geometry::from_toml_str(&with(&twice))
        .unwrap_err()
        .to_string();
    assert!(
        message.contains("fiducial \"nest A\" is named twice"),
        "{message}"
    );
    let nan = one.replace("12.5", "nan");
    let message = Geometry::from_toml_str(&with(&nan))
        .unwrap_err()
        .to_string();
    assert!(
        message.contains("fiducial \"nest A\" position[2] is NaN"),
        "{message}"
    );
    let unknown = one.replace("position", "place");
    assert!(Geometry::from_toml_str(&with(&unknown)).is_err());
}
