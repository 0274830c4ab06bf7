//! Measurements files beyond three targets always seen: any number of targets, empty cells for a
//! target not seen, a 6-DoF probe's pose in either rotation convention; and their refusals.

use glam::DVec3;
use hexacomp_core::observation::Observation;
use hexacomp_core::pose::PoseConvention;
use hexacomp_core::records::MeasuredConfiguration;
use hexacomp_formats::{read_measurements, read_measurements_in, write_measurements_in};

const HEAD: &str = "id,x,y,z,a,b,c,q1,q2,q3,q4,q5,q6";
const COMMANDED: &str = "0,0,280,0,0,0,350,351,352,353,354,355";

/// Reads `text` as `m.csv`: the records, or the error text without the folder.
fn read(text: &str, convention: PoseConvention) -> Result<Vec<MeasuredConfiguration>, String> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.csv");
    std::fs::write(&path, text).unwrap();
    read_measurements_in(&path, convention)
        .map(|r| r.into_items())
        .map_err(|e| e.to_string().replace(&dir.path().display().to_string(), ""))
}

fn write_and_read(
    rows: &[MeasuredConfiguration],
    convention: PoseConvention,
) -> Vec<MeasuredConfiguration> {
    let mut bytes = Vec::new();
    write_measurements_in(&mut bytes, rows, convention).unwrap();
    read(std::str::from_utf8(&bytes).unwrap(), convention).unwrap()
}

fn row(id: &str, observed: Observation) -> MeasuredConfiguration {
    MeasuredConfiguration {
        id: id.into(),
        pose_mm_deg: [0.5, -1.0, 280.0, 1.0, 2.0, 3.0],
        legs: [350.0, 351.0, 352.0, 353.0, 354.0, 355.0],
        observed,
    }
}

#[test]
fn four_targets_with_one_not_seen_read_as_written() {
    let text = format!(
        "{HEAD},p1x,p1y,p1z,p2x,p2y,p2z,p3x,p3y,p3z,p4x,p4y,p4z\n\
         a,{COMMANDED},1,2,3,,,,7,8,9,10,11,12\n\
         b,{COMMANDED},1,2,3,4,5,6,7,8,9, , ,\n"
    );
    let rows = read(&text, PoseConvention::Linuxcnc).unwrap();
    let p = |x: f64| Some(DVec3::new(x, x + 1.0, x + 2.0));
    assert_eq!(
        rows[0].observed,
        Observation::Targets(vec![p(1.0), None, p(7.0), p(10.0)])
    );
    assert_eq!(
        rows[1].observed,
        Observation::Targets(vec![p(1.0), p(4.0), p(7.0), None])
    );
    assert_eq!(write_and_read(&rows, PoseConvention::Linuxcnc), rows);
}

#[test]
fn a_probe_pose_reads_and_writes_in_either_convention() {
    let rows = vec![
        row(
            "1",
            Observation::Pose([0.5, -1.0, 280.1, 1.0 / 3.0, -2.0, 7.5]),
        ),
        row("2", Observation::Pose([0.0, 0.0, 300.0, 10.0, 12.0, -30.0])),
    ];
    assert_eq!(write_and_read(&rows, PoseConvention::Linuxcnc), rows);
    // Through PI's U, V, W: the same rotation back, to rounding.
    let back = write_and_read(&rows, PoseConvention::PiUvw);
    for (a, b) in rows.iter().zip(&back) {
        let (Observation::Pose(a), Observation::Pose(b)) = (&a.observed, &b.observed) else {
            panic!("poses");
        };
        for k in 0..6 {
            assert!((a[k] - b[k]).abs() < 1e-10, "{a:?} vs {b:?}");
        }
    }
    // The file holds U, V, W: other numbers than a, b, c.
    let mut bytes = Vec::new();
    write_measurements_in(&mut bytes, &rows[1..], PoseConvention::PiUvw).unwrap();
    let text = String::from_utf8(bytes).unwrap();
    assert!(
        text.starts_with(&format!("{HEAD},mx,my,mz,ma,mb,mc\n")),
        "{text}"
    );
    assert!(!text.contains(",10,12,-30"), "{text}");
}

#[test]
fn bad_measured_columns_and_cells_are_refused_with_their_place() {
    let targets = "p1x,p1y,p1z,p2x,p2y,p2z,p3x,p3y,p3z";
    for (text, expected) in [
        (
            format!("{HEAD},{targets}\na,{COMMANDED},1,2,3,4,,6,7,8,9\n"),
            "m.csv:2: column p2y: empty, but target 2's other coordinates are given",
        ),
        (
            format!(
                "{HEAD},{targets},mx,my,mz,ma,mb,mc\na,{COMMANDED},1,2,3,4,5,6,7,8,9,1,2,3,4,5,6\n"
            ),
            "m.csv:1: column p1x: a measurements file holds target points or a measured pose",
        ),
        (
            format!("{HEAD},mx,my,mz,ma,mb\na,{COMMANDED},1,2,3,4,5\n"),
            "m.csv:1: column mc: required column is missing",
        ),
        (
            format!("{HEAD},mx,my,mz,ma,mb,mc\na,{COMMANDED},1,2,3,4,,6\n"),
            "m.csv:2: column mb: \"\" is not a number",
        ),
        (
            format!("{HEAD},mx,my,mz,ma,mb,mc\na,{COMMANDED},1,2,NaN,4,5,6\n"),
            "m.csv:2: column mz: \"NaN\" is not a finite number",
        ),
        (
            format!("{HEAD},p1x,p1y,p1z,p2x,p2y,p2z\na,{COMMANDED},1,2,3,4,5,6\n"),
            "m.csv:1: column p3x: required column is missing",
        ),
        (
            format!("{HEAD},{targets},p4x,p4y\na,{COMMANDED},1,2,3,4,5,6,7,8,9,1,2\n"),
            "m.csv:1: column p4z: required column is missing",
        ),
        (
            format!("{HEAD}\na,{COMMANDED}\n"),
            "m.csv:1: column p1x: required column is missing",
        ),
    ] {
        let message = read(&text, PoseConvention::Linuxcnc).expect_err(&text);
        assert!(message.contains(expected), "{expected}\n{message}");
    }
}

#[test]
fn rows_measured_two_ways_are_not_written_into_one_file() {
    let rows = vec![
        row("1", Observation::Pose([0.0; 6])),
        row("2", Observation::Targets(vec![Some(DVec3::ONE); 3])),
    ];
    let error = write_measurements_in(Vec::new(), &rows, PoseConvention::Linuxcnc).unwrap_err();
    assert!(
        error
            .to_string()
            .contains("configuration 2 measured otherwise"),
        "{error}"
    );
}

#[test]
fn the_default_reader_is_the_linuxcnc_convention() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.csv");
    std::fs::write(
        &path,
        format!("{HEAD},mx,my,mz,ma,mb,mc\na,{COMMANDED},1,2,3,4,5,6\n"),
    )
    .unwrap();
    assert_eq!(
        read_measurements(&path).unwrap()[0].observed,
        Observation::Pose([1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
    );
}

#[test]
fn a_row_with_nothing_measured_is_read_as_such_not_refused() {
    let targets = "p1x,p1y,p1z,p2x,p2y,p2z,p3x,p3y,p3z";
    let rows = read(
        &format!("{HEAD},{targets}\na,{COMMANDED},,,,,,,,,\n"),
        PoseConvention::Linuxcnc,
    )
    .unwrap();
    assert_eq!(rows[0].observed, Observation::Targets(vec![None; 3]));
    let text =
        format!("{HEAD},mx,my,mz,ma,mb,mc\na,{COMMANDED},,,,,,\nb,{COMMANDED},1,2,3,4,5,6\n");
    let rows = read(&text, PoseConvention::PiUvw).unwrap();
    assert_eq!(rows[0].observed, Observation::PoseMissed);
    assert_eq!(write_and_read(&rows, PoseConvention::Linuxcnc), rows);
}
