//! The CSV formats: exact round trips and strict refusal naming file, line and column.

use glam::DVec3;
use hexacomp_core::observation::Observation;
use hexacomp_core::records::{JointCorrection, MeasuredConfiguration, NamedPose};
use hexacomp_formats::Error;
use hexacomp_formats::{
    read_corrections, read_measurements, read_poses, write_corrections, write_measurements,
    write_poses,
};

fn write(dir: &tempfile::TempDir, name: &str, text: &str) -> std::path::PathBuf {
    let path = dir.path().join(name);
    std::fs::write(&path, text).unwrap();
    path
}

fn format_error(result: Result<impl std::fmt::Debug, Error>) -> (u64, Option<String>, String) {
    match result {
        Err(Error::Format {
            line,
            column,
            message,
            ..
        }) => (line, column, message),
        other => panic!("expected a format error, got {other:?}"),
    }
}

const MEASUREMENT_HEADER: &str =
    "id,x,y,z,a,b,c,q1,q2,q3,q4,q5,q6,p1x,p1y,p1z,p2x,p2y,p2z,p3x,p3y,p3z";

#[test]
fn poses_round_trip_to_the_bit() {
    let dir = tempfile::tempdir().unwrap();
    let rows = vec![
        NamedPose {
            id: "1".into(),
            pose_mm_deg: [0.1, -2.0 / 3.0, 280.0, 1e-7, -3.3, 9.9],
        },
        NamedPose {
            id: "p-2".into(),
            pose_mm_deg: [1.0, 2.0, 3.0, 4.0, 5.0, 6.0],
        },
    ];
    let path = dir.path().join("poses.csv");
    write_poses(std::fs::File::create(&path).unwrap(), &rows).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.starts_with("id,x,y,z,a,b,c\n"), "{text}");
    assert_eq!(read_poses(&path).unwrap().into_items(), rows);
}

#[test]
fn measurements_and_corrections_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let m = vec![MeasuredConfiguration {
        id: "7".into(),
        pose_mm_deg: [1.5, 2.5, 290.0, 3.0, -4.0, 5.0],
        legs: [350.1, 351.2, 352.3, 353.4, 354.5, 355.6],
        observed: Observation::Targets(vec![
            Some(DVec3::new(1.0, 2.0, 3.0)),
            Some(DVec3::new(4.0, 5.0, 6.0)),
            Some(DVec3::new(7.0, 8.0, 9.0)),
        ]),
    }];
    let path = dir.path().join("m.csv");
    write_measurements(std::fs::File::create(&path).unwrap(), &m).unwrap();
    assert_eq!(
        std::fs::read_to_string(&path)
            .unwrap()
            .lines()
            .next()
            .unwrap(),
        MEASUREMENT_HEADER
    );
    assert_eq!(read_measurements(&path).unwrap().into_items(), m);

    let c = vec![JointCorrection {
        id: "7".into(),
        legs: [350.1, 351.2, 352.3, 353.4, 354.5, 355.6],
        corrections: [0.1, -0.2, 0.3, -0.4, 0.5, -0.6],
    }];
    let path = dir.path().join("c.csv");
    write_corrections(
        std::fs::File::create(&path).unwrap(),
        &c,
        &["cond_pt"],
        &[vec!["3.5".into()]],
    )
    .unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(
        text.starts_with("id,q1,q2,q3,q4,q5,q6,dq1,dq2,dq3,dq4,dq5,dq6,cond_pt\n"),
        "{text}"
    );
    assert_eq!(read_corrections(&path).unwrap().into_items(), c);
}

#[test]
fn comments_blank_columns_order_and_extra_columns_are_accepted() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(
        &dir,
        "p.csv",
        "# written by a laser tracker export\nc,b,a,z,y,x,id,operator\n# a comment row\n3,2,1,300,0,0,a1,kim\n",
    );
    let rows = read_poses(&path).unwrap();
    assert_eq!(rows[0].id, "a1");
    assert_eq!(rows[0].pose_mm_deg, [0.0, 0.0, 300.0, 1.0, 2.0, 3.0]);
    assert!((rows[0].pose().angles.z - 3f64.to_radians()).abs() < 1e-16);
}

#[test]
fn missing_column_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let header = MEASUREMENT_HEADER.replace(",q4", "");
    let path = write(&dir, "m.csv", &format!("{header}\n"));
    let (line, column, message) = format_error(read_measurements(&path));
    assert_eq!((line, column.as_deref()), (1, Some("q4")));
    assert_eq!(message, "required column is missing from the header");
}

#[test]
fn nan_is_refused_with_line_and_column() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(
        &dir,
        "p.csv",
        "id,x,y,z,a,b,c\n1,0,0,300,0,0,0\n# note\n2,0,NaN,300,0,0,0\n",
    );
    let err = read_poses(&path).unwrap_err();
    assert_eq!(
        err.to_string(),
        format!(
            "{}:4: column y: \"NaN\" is not a finite number",
            path.display()
        )
    );
}

#[test]
fn duplicate_ids_name_both_lines() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(
        &dir,
        "p.csv",
        "id,x,y,z,a,b,c\n1,0,0,300,0,0,0\n1,0,0,301,0,0,0\n",
    );
    let (line, column, message) = format_error(read_poses(&path));
    assert_eq!((line, column.as_deref()), (3, Some("id")));
    assert_eq!(
        message,
        "duplicate id \"1\" (first on line 2; numeric ids are compared by value)"
    );
}

#[test]
fn wrong_width_text_and_empty_files_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let short = write(&dir, "a.csv", "id,x,y,z,a,b,c\n1,0,0,300,0,0\n");
    assert_eq!(
        format_error(read_poses(&short)),
        (2, None, "row has 6 fields, the header has 7".into())
    );
    let text = write(&dir, "b.csv", "id,x,y,z,a,b,c\n1,0,zero,300,0,0,0\n");
    assert_eq!(
        format_error(read_poses(&text)),
        (2, Some("y".into()), "\"zero\" is not a number".into())
    );
    let empty = write(&dir, "c.csv", "");
    assert_eq!(
        format_error(read_poses(&empty)).2,
        "the file is empty: expected a header row"
    );
    let no_id = write(&dir, "d.csv", "id,x,y,z,a,b,c\n,0,0,300,0,0,0\n");
    assert_eq!(
        format_error(read_poses(&no_id)),
        (2, Some("id".into()), "empty id".into())
    );
    let missing = dir.path().join("missing.csv");
    assert!(
        read_poses(&missing)
            .unwrap_err()
            .to_string()
            .contains("missing.csv")
    );
}

#[test]
fn records_keep_the_line_the_editor_shows_past_comments_and_blank_lines() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(
        &dir,
        "poses.csv",
        "# planned on Monday\n\nid,x,y,z,a,b,c\n# first\np1,0,0,280,0,0,0\n# moved\np2,1,0,280,0,0,0\n",
    );
    let records = read_poses(&path).unwrap();
    let ids: Vec<&str> = records.iter().map(|r| r.id.as_str()).collect();
    assert_eq!(ids, ["p1", "p2"]);
    assert_eq!((records.line(0), records.line(1)), (5, 7));
    assert_eq!(records.file, path.display().to_string());
}

#[test]
fn a_blank_line_between_rows_is_refused_with_its_line() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(
        &dir,
        "p.csv",
        "id,x,y,z,a,b,c\n1,0,0,300,0,0,0\n\n# later\n2,0,0,301,0,0,0\n\n\n",
    );
    let (line, column, message) = format_error(read_poses(&path));
    assert_eq!((line, column), (3, None));
    assert!(message.starts_with("blank line between rows"), "{message}");
    // After the header too (the first row may be the one lost).
    let path = write(&dir, "r.csv", "id,x,y,z,a,b,c\n\n1,0,0,300,0,0,0\n");
    assert_eq!(format_error(read_poses(&path)).0, 2);
    // Blank lines before the header and after the last row are not between rows.
    let path = write(
        &dir,
        "q.csv",
        "\n# export\n\nid,x,y,z,a,b,c\n1,0,0,300,0,0,0\n2,0,0,301,0,0,0\n\n\n",
    );
    assert_eq!(read_poses(&path).unwrap().len(), 2);
}

#[test]
fn numeric_ids_that_are_the_same_number_are_duplicates() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(
        &dir,
        "p.csv",
        "id,x,y,z,a,b,c\n1,0,0,300,0,0,0\n01,0,0,301,0,0,0\n",
    );
    let (line, column, message) = format_error(read_poses(&path));
    assert_eq!((line, column.as_deref()), (3, Some("id")));
    assert_eq!(
        message,
        "duplicate id \"01\" (first on line 2; numeric ids are compared by value)"
    );
    // Other ids are compared as written.
    let path = write(
        &dir,
        "q.csv",
        "id,x,y,z,a,b,c\na1,0,0,300,0,0,0\na01,0,0,301,0,0,0\n0,0,0,302,0,0,0\n",
    );
    assert_eq!(read_poses(&path).unwrap().len(), 3);
}

#[test]
fn an_error_quotes_at_most_40_characters_of_a_field_and_no_line_0() {
    let dir = tempfile::tempdir().unwrap();
    let huge = "9".repeat(100_000) + "x";
    let path = write(
        &dir,
        "p.csv",
        &format!("id,x,y,z,a,b,c\n1,{huge},0,300,0,0,0\n"),
    );
    let message = read_poses(&path).unwrap_err().to_string();
    assert!(message.len() < 200, "{} bytes", message.len());
    assert!(
        message.ends_with(&format!(
            "\"{}\"… (100001 bytes) is not a number",
            "9".repeat(40)
        )),
        "{message}"
    );
    let empty = write(&dir, "c.csv", "");
    assert_eq!(
        read_poses(&empty).unwrap_err().to_string(),
        format!(
            "{}: the file is empty: expected a header row",
            empty.display()
        )
    );
}

#[test]
fn a_line_longer_than_a_mebibyte_is_refused_without_being_read_whole() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(&dir, "p.csv", &"x".repeat(200 << 20));
    let (line, column, message) = format_error(read_poses(&path));
    assert_eq!((line, column), (1, None));
    assert_eq!(
        message,
        "line longer than 1 MiB: not a CSV file of hexacomp"
    );
}

#[test]
fn a_file_streams_row_by_row_and_stops_at_its_first_bad_row() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(
        &dir,
        "p.csv",
        "id,x,y,z,a,b,c\n1,0,0,300,0,0,0\n# note\n2,0,0,301,0,0,0\n3,0,x,302,0,0,0\n4,0,0,303,0,0,0\n",
    );
    let mut rows = hexacomp_formats::stream_poses(&path).unwrap();
    let (line, first) = rows.next().unwrap().unwrap();
    assert_eq!((line, first.id.as_str()), (2, "1"));
    assert_eq!(rows.next().unwrap().unwrap().0, 4);
    let error = rows.next().unwrap().unwrap_err().to_string();
    assert!(
        error.ends_with("p.csv:5: column y: \"x\" is not a number"),
        "{error}"
    );
}

#[test]
fn a_byte_order_mark_is_dropped_and_quotes_crs_and_missing_columns_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(
        &dir,
        "bom.csv",
        "\u{feff}id,x,y,z,a,b,c\r\n1,0,0,300,0,0,0\r\n",
    );
    assert_eq!(read_poses(&path).unwrap()[0].pose_mm_deg[2], 300.0);
    let path = write(
        &dir,
        "quote.csv",
        "id,x,y,z,a,b,c,note\n1,0,0,300,0,0,0,\"two\n2,0,0,301,0,0,0,lines\"\n",
    );
    let (line, _, message) = format_error(read_poses(&path));
    assert_eq!(line, 2);
    assert!(message.starts_with("an unbalanced quote"), "{message}");
    let path = write(&dir, "cr.csv", "id,x,y,z,a,b,c\r1,0,0,300,0,0,0\r");
    let (line, _, message) = format_error(read_poses(&path));
    assert_eq!(line, 1);
    assert!(
        message.starts_with("a carriage return inside the line"),
        "{message}"
    );
    // A missing column is reported on the header's own line, past comments.
    let path = write(&dir, "m.csv", "# export\nid,x,y,z,a,b\n");
    assert_eq!(
        format_error(read_poses(&path)),
        (
            2,
            Some("c".into()),
            "required column is missing from the header".into()
        )
    );
}
