//! `hexacomp-trainer campaign` as a user runs it: killed with SIGKILL mid-campaign and run again,
//! it records what an uninterrupted campaign does, no row twice; a row cut short is measured
//! again; a user's instrument program that hangs or answers nonsense leaves a recorded gap; bad
//! plans and another plan's record are refused with their place.

use std::io::Write;
use std::os::unix::fs::PermissionsExt;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use hexacomp_formats::read_measurements;
use hexacomp_tests::{assert_says, binary, signal_child, text, trainer_in, trainer_ok};

/// The data lines of a file (header and comment lines left out), whole lines only.
fn data_lines(path: &Path) -> Vec<String> {
    let bytes = std::fs::read(path).unwrap_or_default();
    let whole = bytes
        .iter()
        .rposition(|b| *b == b'\n')
        .map_or(0, |last| last + 1);
    text(&bytes[..whole])
        .lines()
        .skip(1)
        .filter(|line| !line.starts_with('#'))
        .map(str::to_string)
        .collect()
}

/// A row without its last cell (the time it was measured), keyed by id.
fn rows_without_time(path: &Path) -> Vec<String> {
    let mut rows: Vec<String> = data_lines(path)
        .iter()
        .map(|line| line.rsplit_once(',').expect("cells").0.to_string())
        .collect();
    rows.sort();
    rows
}

/// Starts the campaign of `plan.csv` in `dir` into `out`, slowed by `dwell` seconds between
/// readings, and returns it once `rows` configurations are on disk (waiting for the rows, not a
/// duration; it must not end before, and must record within a minute).
fn campaign_recording(dir: &Path, out: &str, dwell: &str, rows: usize) -> std::process::Child {
    let mut child = Command::new(binary("hexacomp-trainer"))
        .args(["campaign", "--plan"])
        .arg(dir.join("plan.csv"))
        .arg("--out")
        .arg(dir.join(out))
        .args(["--dwell", dwell])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let start = Instant::now();
    while data_lines(&dir.join(out)).len() < rows {
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "no rows recorded"
        );
        assert!(
            child.try_wait().unwrap().is_none(),
            "the campaign ended early"
        );
        std::thread::sleep(Duration::from_millis(2));
    }
    child
}

#[test]
fn a_campaign_killed_and_run_again_records_what_an_uninterrupted_one_does() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    trainer_ok(d, &["plan", "--count", "20", "--out", "plan.csv"]);
    trainer_ok(d, &["campaign", "--plan", "plan.csv", "--out", "whole.csv"]);

    // The same campaign, slowed down by a dwell between readings, killed once three
    // configurations are on disk.
    let mut child = campaign_recording(d, "killed.csv", "0.2", 3);
    signal_child(&child, libc::SIGKILL);
    child.wait().unwrap();
    let at_kill = data_lines(&d.join("killed.csv")).len();
    assert!((3..20).contains(&at_kill), "{at_kill} rows at the kill");

    let said = trainer_ok(
        d,
        &["campaign", "--plan", "plan.csv", "--out", "killed.csv"],
    );
    assert!(
        said.contains(&format!("{} of 20 configurations to measure", 20 - at_kill)),
        "{said}"
    );
    assert_eq!(
        rows_without_time(&d.join("killed.csv")),
        rows_without_time(&d.join("whole.csv"))
    );
    // Read as a measurements file: 20 configurations, none twice (the reader refuses duplicates).
    assert_eq!(read_measurements(&d.join("killed.csv")).unwrap().len(), 20);

    // Finished: run again, it says so and changes nothing.
    let before = std::fs::read(d.join("killed.csv")).unwrap();
    let said = trainer_ok(
        d,
        &["campaign", "--plan", "plan.csv", "--out", "killed.csv"],
    );
    assert!(said.contains("the campaign is finished"), "{said}");
    assert_eq!(std::fs::read(d.join("killed.csv")).unwrap(), before);
}

#[test]
fn a_row_cut_short_by_a_kill_is_measured_again() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    trainer_ok(d, &["plan", "--count", "6", "--out", "plan.csv"]);
    trainer_ok(d, &["campaign", "--plan", "plan.csv", "--out", "cut.csv"]);
    std::fs::copy(d.join("cut.csv"), d.join("whole.csv")).unwrap();
    // The record as a kill during the last append leaves it: the last line cut short.
    let whole = std::fs::read_to_string(d.join("whole.csv")).unwrap();
    let cut = whole.trim_end().rfind('\n').unwrap() + 1 + 17;
    std::fs::write(d.join("cut.csv"), &whole[..cut]).unwrap();
    let said = trainer_ok(d, &["campaign", "--plan", "plan.csv", "--out", "cut.csv"]);
    assert!(said.contains("1 of 6 configurations to measure"), "{said}");
    assert_eq!(
        rows_without_time(&d.join("cut.csv")),
        rows_without_time(&d.join("whole.csv"))
    );
}

/// Writes an executable shell script `name` in `dir`.
fn script(dir: &Path, name: &str, body: &str) {
    let path = dir.join(name);
    let mut file = std::fs::File::create(&path).unwrap();
    writeln!(file, "#!/bin/sh\n{body}").unwrap();
    drop(file);
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755)).unwrap();
}

#[test]
fn a_users_instrument_program_is_read_and_its_failures_are_recorded_gaps() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    trainer_ok(d, &["plan", "--count", "3", "--out", "plan.csv"]);
    // The example program of integrations/instrument replays a tracker's export; target 2 is
    // not seen. Every reading of the three configurations is in the export.
    let ids: Vec<String> = data_lines(&d.join("plan.csv"))
        .iter()
        .map(|line| line.split(',').next().unwrap().to_string())
        .collect();
    let mut export = String::from("id,reading,p1x,p1y,p1z,p2x,p2y,p2z,p3x,p3y,p3z\n");
    for id in &ids {
        for reading in 1..=3 {
            export += &format!("{id},{reading},1.5,2,3,,,,7,8,9.25\n");
        }
    }
    std::fs::write(d.join("export.csv"), export).unwrap();
    let program = format!(
        "{} {}",
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../integrations/instrument/replay-export.sh")
            .display(),
        d.join("export.csv").display()
    );
    trainer_ok(
        d,
        &[
            "campaign",
            "--plan",
            "plan.csv",
            "--out",
            "good.csv",
            "--instrument",
            "command",
            "--no-reference",
            "--instrument-command",
            &program,
        ],
    );
    let rows = read_measurements(&d.join("good.csv")).unwrap();
    assert_eq!(rows.len(), 3);
    assert_eq!(
        rows[0].observed,
        hexacomp_core::observation::Observation::Targets(vec![
            Some(glam::DVec3::new(1.5, 2.0, 3.0)),
            None,
            Some(glam::DVec3::new(7.0, 8.0, 9.25)),
        ])
    );

    // A program that hangs is killed after the timeout, with what it started; one that answers
    // a line of the wrong width is retried; both leave gaps, named as they happen, and after
    // three gaps in a row the campaign stops with an error (what it recorded stays).
    script(d, "hang.sh", "sleep 30 &\nsleep 30");
    let hang = d.join("hang.sh").display().to_string();
    let start = Instant::now();
    let output = trainer_in(
        d,
        &[
            "campaign",
            "--plan",
            "plan.csv",
            "--out",
            "hang.csv",
            "--instrument",
            "command",
            "--no-reference",
            "--instrument-command",
            &hang,
            "--command-timeout",
            "0.2",
            "--readings",
            "1",
            "--retries",
            "1",
        ],
    );
    let said = text(&output.stderr);
    assert!(!output.status.success(), "{said}");
    assert!(start.elapsed() < Duration::from_secs(20));
    assert_eq!(said.matches("gap: configuration").count(), 3, "{said}");
    assert!(
        said.contains("did not answer within 200ms (killed with what it started)"),
        "{said}"
    );
    assert!(
        said.contains("3 configurations in a row gave no reading"),
        "{said}"
    );
    assert_eq!(data_lines(&d.join("hang.csv")).len(), 3);
    script(d, "narrow.sh", "echo 1,2,3,4");
    let narrow = d.join("narrow.sh").display().to_string();
    let said = text(
        &trainer_in(
            d,
            &[
                "campaign",
                "--plan",
                "plan.csv",
                "--out",
                "narrow.csv",
                "--instrument",
                "command",
                "--no-reference",
                "--instrument-command",
                &narrow,
                "--readings",
                "1",
            ],
        )
        .stderr,
    );
    assert!(
        said.contains("has 4 cells, expected 9 (3 targets × x,y,z)"),
        "{said}"
    );
    // solve lists the gaps as configurations with nothing seen.
    let output = trainer_in(
        d,
        &["solve", "--measurements", "narrow.csv", "--out", "dq.csv"],
    );
    assert!(
        text(&output.stderr).matches("0 of 3 targets seen").count() == 3,
        "{}",
        text(&output.stderr)
    );
}

#[test]
fn a_plan_outside_the_stroke_and_another_plans_record_are_refused_with_their_place() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(
        d.join("plan.csv"),
        "id,x,y,z,a,b,c\n1,0,0,280,0,0,0\n2,0,0,900,0,0,0\n",
    )
    .unwrap();
    let output = trainer_in(d, &["campaign", "--plan", "plan.csv", "--out", "m.csv"]);
    assert!(!output.status.success());
    assert_says(
        &output.stderr,
        "plan.csv:3: configuration 2: the pose needs leg 1",
    );
    assert!(!d.join("m.csv").exists(), "a record was started");

    trainer_ok(
        d,
        &["plan", "--count", "4", "--seed", "1", "--out", "one.csv"],
    );
    trainer_ok(
        d,
        &["plan", "--count", "4", "--seed", "2", "--out", "two.csv"],
    );
    trainer_ok(d, &["campaign", "--plan", "one.csv", "--out", "m.csv"]);
    let before = std::fs::read(d.join("m.csv")).unwrap();
    let output = trainer_in(d, &["campaign", "--plan", "two.csv", "--out", "m.csv"]);
    assert!(!output.status.success());
    assert!(
        text(&output.stderr).contains("m.csv:3: configuration")
            && text(&output.stderr).contains("was not recorded from this plan"),
        "{}",
        text(&output.stderr)
    );
    assert_eq!(std::fs::read(d.join("m.csv")).unwrap(), before);
}

#[test]
fn a_program_that_cannot_start_stops_the_campaign_before_anything_is_recorded() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    trainer_ok(d, &["plan", "--count", "5", "--out", "plan.csv"]);
    let missing = d.join("no such tracker.sh").display().to_string();
    let output = trainer_in(
        d,
        &[
            "campaign",
            "--plan",
            "plan.csv",
            "--out",
            "m.csv",
            "--instrument",
            "command",
            "--no-reference",
            "--instrument-command",
            &format!("'{missing}' --fast"),
        ],
    );
    assert!(!output.status.success());
    let said = text(&output.stderr);
    assert!(said.contains(&format!("cannot run {missing}")), "{said}");
    let record = std::fs::read_to_string(d.join("m.csv")).unwrap();
    assert!(data_lines(&d.join("m.csv")).is_empty(), "{record}");
}

#[test]
fn two_campaigns_on_one_file_other_settings_and_foreign_files_are_refused_and_left_as_they_are() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    trainer_ok(d, &["plan", "--count", "8", "--out", "plan.csv"]);
    // A second campaign while the first records.
    let mut first = campaign_recording(d, "m.csv", "0.3", 1);
    let output = trainer_in(d, &["campaign", "--plan", "plan.csv", "--out", "m.csv"]);
    assert!(!output.status.success());
    assert_says(
        &output.stderr,
        "another campaign is recording into this file",
    );
    signal_child(&first, libc::SIGKILL);
    first.wait().unwrap();

    // The same record with another seed: refused at its settings line, unchanged.
    let before = std::fs::read(d.join("m.csv")).unwrap();
    let output = trainer_in(
        d,
        &[
            "campaign", "--plan", "plan.csv", "--out", "m.csv", "--seed", "2",
        ],
    );
    assert!(!output.status.success());
    assert_says(
        &output.stderr,
        "m.csv:2: this file was not recorded by this campaign",
    );
    assert_eq!(std::fs::read(d.join("m.csv")).unwrap(), before);

    // A file of another kind, its last line without a line end: refused, not cut.
    let foreign = "id,x,y,z\n1,2,3,4";
    std::fs::write(d.join("other.csv"), foreign).unwrap();
    let output = trainer_in(d, &["campaign", "--plan", "plan.csv", "--out", "other.csv"]);
    assert!(!output.status.success());
    assert_says(
        &output.stderr,
        "other.csv:1: this file was not recorded by this campaign",
    );
    assert_eq!(
        std::fs::read_to_string(d.join("other.csv")).unwrap(),
        foreign
    );
}

/// The reference configuration's rows of a drift log: `(event, decision, note)`.
fn drift_events(path: &Path) -> Vec<(String, String, String)> {
    let text = std::fs::read_to_string(path).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    let column = |name: &str| header.iter().position(|c| *c == name).unwrap();
    let (event, decision, note) = (column("event"), column("decision"), column("note"));
    let mut reader = csv::ReaderBuilder::new()
        .comment(Some(b'#'))
        .from_reader(text.as_bytes());
    reader
        .records()
        .map(|r| {
            let r = r.unwrap();
            (
                r[event].to_string(),
                r[decision].to_string(),
                r[note].to_string(),
            )
        })
        .collect()
}

/// The target points of each row of a record, by id.
fn targets_by_id(path: &Path) -> std::collections::BTreeMap<String, Vec<glam::DVec3>> {
    read_measurements(path)
        .unwrap()
        .iter()
        .map(|row| {
            let points = row
                .observed
                .points(&hexacomp_core::Geometry::prototype())
                .into_iter()
                .map(|(_, p)| p)
                .collect();
            (row.id.clone(), points)
        })
        .collect()
}

/// The arguments of a campaign recording `plan` into `out`, the virtual tracker standing at `at`.
fn campaign<'a>(plan: &'a str, out: &'a str, at: &'a str, more: &[&'a str]) -> Vec<&'a str> {
    [
        &[
            "campaign",
            "--plan",
            plan,
            "--out",
            out,
            "--instrument-pose",
            at,
        ][..],
        more,
    ]
    .concat()
}

/// Registers the virtual tracker standing at `at` as `out` (its fiducials read by `simulate`).
fn register_tracker(d: &Path, at: &str, out: &str) {
    let fiducials = format!("{out}.fiducials.csv");
    trainer_ok(
        d,
        &[
            "simulate",
            "--plan",
            "first.csv",
            "--out",
            "unused.csv",
            "--instrument-pose",
            at,
            "--fiducials-out",
            &fiducials,
        ],
    );
    trainer_ok(d, &["register", "--measured", &fiducials, "--out", out]);
}

#[test]
fn a_tracker_moved_between_runs_stops_the_campaign_and_registered_again_it_goes_on_in_the_first_frame()
 {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (at_a, at_b) = (
        "2500,-1500,-800,0.3,-0.2,135",
        "2300,-1800,-780,0.1,0.2,150",
    );
    trainer_ok(d, &["plan", "--count", "24", "--out", "plan.csv"]);
    let plan = std::fs::read_to_string(d.join("plan.csv")).unwrap();
    let first: Vec<&str> = plan.lines().take(13).collect();
    std::fs::write(d.join("first.csv"), first.join("\n") + "\n").unwrap();
    register_tracker(d, at_a, "a.toml");
    register_tracker(d, at_b, "b.toml");
    let under_a = ["--registration", "a.toml"];
    trainer_ok(d, &campaign("plan.csv", "whole.csv", at_a, &under_a));
    // The first twelve configurations with the tracker at A.
    trainer_ok(d, &campaign("first.csv", "c.csv", at_a, &under_a));
    assert_eq!(data_lines(&d.join("c.csv")).len(), 12);
    // The tracker moved to B; the campaign still believes it at A: the reference moved metres.
    let output = trainer_in(d, &campaign("plan.csv", "c.csv", at_b, &under_a));
    let error = text(&output.stderr);
    assert!(!output.status.success());
    assert!(
        error.contains("the targets moved together") && error.contains("register it again"),
        "{error}"
    );
    assert_eq!(
        data_lines(&d.join("c.csv")).len(),
        12,
        "a row recorded after the drift"
    );
    let events = drift_events(&d.join("c.drift.csv"));
    assert_eq!(events.last().unwrap().1, "stopped", "{events:?}");
    // A run without a registration cannot continue a campaign begun with one.
    let error = text(&trainer_in(d, &campaign("plan.csv", "c.csv", at_b, &[])).stderr);
    assert!(error.contains("began with a registration"), "{error}");
    // Registered again at B: it goes on, its readings brought into A's frame.
    trainer_ok(
        d,
        &campaign("plan.csv", "c.csv", at_b, &["--registration", "b.toml"]),
    );
    let events = drift_events(&d.join("c.drift.csv"));
    let start = events
        .iter()
        .rev()
        .find(|(event, _, _)| event == "start")
        .unwrap();
    assert_eq!(start.1, "ok", "{events:?}");
    assert!(start.2.starts_with("re-registered"), "{events:?}");
    let (resumed, whole) = (
        targets_by_id(&d.join("c.csv")),
        targets_by_id(&d.join("whole.csv")),
    );
    assert_eq!(resumed.len(), 24);
    let firsts: Vec<&str> = first[1..]
        .iter()
        .map(|line| line.split(',').next().unwrap())
        .collect();
    for (id, points) in &resumed {
        let largest = points
            .iter()
            .zip(&whole[id])
            .map(|(p, q)| p.distance(*q))
            .fold(0.0, f64::max);
        if firsts.contains(&id.as_str()) {
            assert_eq!(largest, 0.0, "configuration {id} measured at A");
        } else {
            // Measured from B: the same attained pose, through two registrations.
            assert!(
                largest > 0.0 && largest < 0.05,
                "configuration {id}: {largest} mm"
            );
        }
    }
    // The fiducials measured at the end (at B) against A's registration: the record's frame
    // changed during the campaign, so a registration made from them is not the record's.
    let output = trainer_in(d, &campaign("plan.csv", "c.csv", at_b, &under_a));
    let error = text(&output.stderr);
    assert!(
        !output.status.success() && error.contains("frame changed during the campaign"),
        "{error}"
    );
}

#[test]
fn accepted_drift_is_logged_and_a_warm_up_that_does_not_settle_records_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    trainer_ok(d, &["plan", "--count", "6", "--out", "plan.csv"]);
    // A reference that never agrees with itself to 0.1 µm: the gate gives up after three.
    let error = text(
        &trainer_in(
            d,
            &[
                "campaign",
                "--plan",
                "plan.csv",
                "--out",
                "w.csv",
                "--warm-up-limit",
                "0.0001",
                "--warm-up-interval",
                "0",
                "--warm-up-max",
                "3",
            ],
        )
        .stderr,
    );
    assert!(
        error.contains("did not settle in 3 measurements"),
        "{error}"
    );
    assert!(data_lines(&d.join("w.csv")).is_empty());
    let events = drift_events(&d.join("w.drift.csv"));
    assert_eq!(events.len(), 3);
    assert!(
        events
            .iter()
            .all(|(e, decision, _)| e == "warm-up" && decision == "warming")
    );

    // A limit below the machine's repeatability: the first periodic reference stops the
    // campaign, naming the configurations measured since the last good one; accepted, it goes on.
    let tight = [
        "campaign",
        "--plan",
        "plan.csv",
        "--out",
        "t.csv",
        "--drift-limit",
        "0.001",
        "--reference-every",
        "2",
    ];
    let error = text(&trainer_in(d, &tight).stderr);
    assert!(error.contains("may hold the drift"), "{error}");
    let recorded = data_lines(&d.join("t.csv")).len();
    assert_eq!(recorded, 2, "{error}");
    let ids: Vec<String> = data_lines(&d.join("t.csv"))
        .iter()
        .map(|l| l.split(',').next().unwrap().to_string())
        .collect();
    assert!(error.contains(&ids.join(", ")), "{error}");
    // Run again as it is: refused before anything moves, the suspect rows named.
    let error = text(&trainer_in(d, &tight).stderr);
    assert!(
        error.contains("stopped on drift") && error.contains(&ids.join(", ")),
        "{error}"
    );
    assert_eq!(data_lines(&d.join("t.csv")).len(), 2);
    // Kept with --accept-drift: the start's reference, beyond the limit, becomes the baseline and
    // the kept rows are logged; the tight limit stops the campaign again at its next reference.
    let output = trainer_in(d, &[&tight[..], &["--accept-drift"]].concat());
    assert!(!output.status.success());
    let events = drift_events(&d.join("t.drift.csv"));
    let accepted = events
        .iter()
        .find(|(e, decision, _)| e == "start" && decision == "accepted")
        .unwrap_or_else(|| panic!("{events:?}"));
    assert!(
        accepted.2.contains(&format!("kept {}", ids.join(", "))),
        "{events:?}"
    );
    assert_eq!(data_lines(&d.join("t.csv")).len(), 4);
    // With a limit above the machine's repeatability it ends.
    let output = trainer_in(
        d,
        &[&tight[..5], &["--accept-drift", "--reference-every", "2"]].concat(),
    );
    assert!(output.status.success(), "{}", text(&output.stderr));
    assert_eq!(data_lines(&d.join("t.csv")).len(), 6);
    let events = drift_events(&d.join("t.drift.csv"));
    assert_eq!(events.last().unwrap().0, "end", "{events:?}");

    // Stopped at the end reference, nothing left to measure: --accept-drift still decides and
    // logs it (the start reference measured), it is not "nothing to do".
    let end_only = [
        "campaign",
        "--plan",
        "plan.csv",
        "--out",
        "e.csv",
        "--drift-limit",
        "0.001",
        "--reference-every",
        "0",
    ];
    let output = trainer_in(d, &end_only);
    assert!(!output.status.success());
    assert_eq!(
        drift_events(&d.join("e.drift.csv")).last().unwrap().1,
        "stopped"
    );
    let said = text(&trainer_in(d, &[&end_only[..], &["--accept-drift"]].concat()).stderr);
    assert!(!said.contains("nothing to do"), "{said}");
    let last = drift_events(&d.join("e.drift.csv")).pop().unwrap();
    assert!(
        last.0 == "start" && last.1 == "accepted" && last.2.starts_with("kept "),
        "{last:?}: {said}"
    );
    let said = trainer_ok(d, &end_only);
    assert!(said.contains("nothing to do"), "{said}");
}

#[test]
fn a_drift_log_lost_edited_or_shared_is_refused_and_a_missing_end_reference_is_taken() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    trainer_ok(d, &["plan", "--count", "6", "--out", "plan.csv"]);
    let first: Vec<String> = std::fs::read_to_string(d.join("plan.csv"))
        .unwrap()
        .lines()
        .take(4)
        .map(str::to_string)
        .collect();
    std::fs::write(d.join("first.csv"), first.join("\n") + "\n").unwrap();
    trainer_ok(d, &["campaign", "--plan", "first.csv", "--out", "a.csv"]);
    let log = std::fs::read_to_string(d.join("a.drift.csv")).unwrap();
    // Lost: the record's rows would lose the frame and baseline they were measured under.
    std::fs::rename(d.join("a.drift.csv"), d.join("kept.csv")).unwrap();
    let error = text(&trainer_in(d, &["campaign", "--plan", "plan.csv", "--out", "a.csv"]).stderr);
    assert!(
        error.contains("holds 3 configurations but its drift log"),
        "{error}"
    );
    assert_eq!(data_lines(&d.join("a.csv")).len(), 3);
    assert!(
        !d.join("a.drift.csv").exists(),
        "the refused run left the empty log it created"
    );
    // Edited: a decision it does not know, named with its line.
    std::fs::write(
        d.join("a.drift.csv"),
        log.replace(",baseline,", ",basline,"),
    )
    .unwrap();
    let error = text(&trainer_in(d, &["campaign", "--plan", "plan.csv", "--out", "a.csv"]).stderr);
    assert!(
        error.contains("a.drift.csv:3") && error.contains("\"basline\" is not one of"),
        "{error}"
    );
    // Shared: another record's log is refused.
    std::fs::write(d.join("a.drift.csv"), &log).unwrap();
    let output = trainer_in(
        d,
        &[
            "campaign",
            "--plan",
            "first.csv",
            "--out",
            "b.csv",
            "--drift-log",
            "a.drift.csv",
        ],
    );
    assert_says(&output.stderr, "not recorded by this campaign");
    assert_eq!(std::fs::read_to_string(d.join("a.drift.csv")).unwrap(), log);
    assert!(
        !d.join("b.csv").exists() && !d.join("b.readings.csv").exists(),
        "the refused run left the record and readings log it created"
    );
    // Killed after the last row, before the end reference: run again, it takes it.
    let cut: Vec<&str> = log.lines().collect();
    assert!(cut.last().unwrap().starts_with("R") && cut.last().unwrap().contains(",end,"));
    std::fs::write(
        d.join("a.drift.csv"),
        cut[..cut.len() - 1].join("\n") + "\n",
    )
    .unwrap();
    let said = trainer_ok(d, &["campaign", "--plan", "first.csv", "--out", "a.csv"]);
    assert!(!said.contains("nothing to do"), "{said}");
    let events = drift_events(&d.join("a.drift.csv"));
    assert_eq!(events.last().unwrap().0, "end", "{events:?}");
    let said = trainer_ok(d, &["campaign", "--plan", "first.csv", "--out", "a.csv"]);
    assert!(said.contains("nothing to do"), "{said}");
    // A plan id that names a reference measurement.
    std::fs::write(d.join("r.csv"), "id,x,y,z,a,b,c\nR1,0,0,280,0,0,0\n").unwrap();
    let error = text(&trainer_in(d, &["campaign", "--plan", "r.csv", "--out", "r-out.csv"]).stderr);
    assert!(error.contains("r.csv:2: configuration R1"), "{error}");
}

/// Runs the trainer in `dir` with `input` on its standard input; its output.
fn trainer_typing(dir: &Path, args: &[&str], input: &str) -> std::process::Output {
    let mut child = Command::new(binary("hexacomp-trainer"))
        .args(args)
        .current_dir(dir)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    child
        .stdin
        .take()
        .unwrap()
        .write_all(input.as_bytes())
        .unwrap();
    child.wait_with_output().unwrap()
}

#[test]
fn an_operator_confirms_the_moves_and_types_the_readings_and_the_end_of_input_stops_the_campaign() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(
        d.join("plan.csv"),
        "id,x,y,z,a,b,c\nA,0,0,280,0,0,0\nB,10,0,290,1,0,0\n",
    )
    .unwrap();
    let args = [
        "campaign",
        "--plan",
        "plan.csv",
        "--out",
        "m.csv",
        "--machine",
        "manual",
        "--instrument",
        "manual",
        "--readings",
        "2",
        "--no-reference",
        "--retries",
        "0",
    ];
    // A: confirmed; a typing mistake asked again at no cost (no retries left), then two readings
    // (P2 not seen in both). B: a line that is no confirmation asked again, confirmed, then
    // "stop" at the reading: the campaign ends, A stays recorded, B is no gap.
    let output = trainer_typing(
        d,
        &args,
        "\n1,2,3\n1,2,3,,,,7,8,9\n1,2,3.5,,,,7,8,9.5\n4,5,6\n\nstop\n",
    );
    let said = text(&output.stderr);
    assert!(!output.status.success(), "{said}");
    assert!(
        said.contains("move to configuration A: x y z a b c = 0.0000"),
        "{said}"
    );
    assert!(said.contains("has 3 cells, expected 9"), "{said}");
    assert!(said.contains("\"4,5,6\" is no confirmation"), "{said}");
    assert!(said.contains("stopped by the operator"), "{said}");
    assert_eq!(data_lines(&d.join("m.csv")).len(), 1, "{said}");
    let rows = read_measurements(&d.join("m.csv")).unwrap();
    assert_eq!(rows.len(), 1);
    assert_eq!(
        rows[0].observed,
        hexacomp_core::observation::Observation::Targets(vec![
            Some(glam::DVec3::new(1.0, 2.0, 3.25)),
            None,
            Some(glam::DVec3::new(7.0, 8.0, 9.25)),
        ])
    );
    // Run again: only B is asked for; "stop" at the move ends the campaign without a row.
    let output = trainer_typing(d, &args, "stop\n");
    assert_says(&output.stderr, "stopped by the operator");
    assert_eq!(data_lines(&d.join("m.csv")).len(), 1);
    let output = trainer_typing(d, &args, "\n4,5,6,7,8,9,10,11,12\n4,5,6,7,8,9,10,11,12\n");
    assert!(output.status.success(), "{}", text(&output.stderr));
    assert_eq!(read_measurements(&d.join("m.csv")).unwrap().len(), 2);
}

#[test]
fn the_readings_log_holds_every_attempt_its_outcome_and_the_temperatures_and_gives_the_record() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(
        d.join("plan.csv"),
        "id,x,y,z,a,b,c\nA,0,0,280,0,0,0\nB,10,0,290,1,0,0\n",
    )
    .unwrap();
    // Reading 2's first attempt fails; reading 3 was knocked (p1x 0.5 mm off); the others
    // scatter by a micrometre per reading.
    script(
        d,
        "tracker.sh",
        "if [ \"$8\" = 2 ] && [ ! -e \"$1.failed\" ]; then touch \"$1.failed\"; exit 1; fi\n\
         x=$(echo \"$8\" | awk '{ print ($1 == 3) ? 1.5 : 1 + $1 / 1000 }')\n\
         echo \"$x,2,3,4,5,6,7,8,9\"",
    );
    script(d, "temperatures.sh", "echo 20.5,");
    let tracker = d.join("tracker.sh").display().to_string();
    let temperatures = d.join("temperatures.sh").display().to_string();
    trainer_ok(
        d,
        &[
            "campaign",
            "--plan",
            "plan.csv",
            "--out",
            "m.csv",
            "--instrument",
            "command",
            "--instrument-command",
            &tracker,
            "--readings",
            "5",
            "--temperatures-command",
            &temperatures,
        ],
    );
    let log = std::fs::read_to_string(d.join("m.readings.csv")).unwrap();
    let header: Vec<&str> = log.lines().next().unwrap().split(',').collect();
    let column = |name: &str| header.iter().position(|c| *c == name).unwrap();
    let mut reader = csv::ReaderBuilder::new()
        .comment(Some(b'#'))
        .from_reader(log.as_bytes());
    let rows: Vec<csv::StringRecord> = reader.records().map(|r| r.unwrap()).collect();
    let of_a: Vec<&csv::StringRecord> = rows
        .iter()
        .filter(|r| &r[column("configuration")] == "A")
        .collect();
    // Five readings, one of them tried twice: six attempts.
    let attempts: Vec<(String, String, String)> = of_a
        .iter()
        .map(|r| {
            (
                r[column("id")].to_string(),
                r[column("kept")].to_string(),
                r[column("failure")].to_string(),
            )
        })
        .collect();
    let ids: Vec<&str> = attempts.iter().map(|(id, _, _)| id.as_str()).collect();
    assert_eq!(ids, ["A/1.1", "A/2.1", "A/2.2", "A/3.1", "A/4.1", "A/5.1"]);
    assert!(
        attempts[1].1.is_empty() && attempts[1].2.contains("exited with"),
        "{attempts:?}"
    );
    assert_eq!(
        attempts[3].1, "0",
        "the knocked reading is an outlier: {attempts:?}"
    );
    assert!(attempts.iter().filter(|(_, kept, _)| kept == "1").count() == 4);
    assert!(
        of_a.iter()
            .all(|r| &r[column("air_c")] == "20.5" && r[column("machine_c")].is_empty())
    );
    // The record's p1x is the mean of the kept readings in the log.
    let kept_mean = of_a
        .iter()
        .filter(|r| &r[column("kept")] == "1")
        .map(|r| r[column("p1x")].parse::<f64>().unwrap())
        .sum::<f64>()
        / 4.0;
    let record = read_measurements(&d.join("m.csv")).unwrap();
    let a = record.iter().find(|r| r.id == "A").unwrap();
    let hexacomp_core::observation::Observation::Targets(points) = &a.observed else {
        panic!("targets")
    };
    assert!(
        (points[0].unwrap().x - kept_mean).abs() < 1e-12,
        "{points:?} vs {kept_mean}"
    );

    // A temperature program that fails: said, the cells left empty, the campaign goes on.
    script(d, "broken.sh", "exit 3");
    let output = trainer_in(
        d,
        &[
            "campaign",
            "--plan",
            "plan.csv",
            "--out",
            "n.csv",
            "--temperatures-command",
            &d.join("broken.sh").display().to_string(),
        ],
    );
    assert!(output.status.success(), "{}", text(&output.stderr));
    assert_says(&output.stderr, "temperatures not read");
}

#[test]
fn a_resumed_campaign_estimates_the_time_left_from_the_configurations_recorded() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    trainer_ok(d, &["plan", "--count", "6", "--out", "plan.csv"]);
    let plan = std::fs::read_to_string(d.join("plan.csv")).unwrap();
    let first: Vec<&str> = plan.lines().take(4).collect();
    std::fs::write(d.join("first.csv"), first.join("\n") + "\n").unwrap();
    trainer_ok(d, &["campaign", "--plan", "first.csv", "--out", "m.csv"]);
    // The three rows as a slow machine records them: 40 s apart, then a pause of two hours
    // (another day's run) that does not count.
    let record = std::fs::read_to_string(d.join("m.csv")).unwrap();
    let times = [
        "2026-01-01T08:00:00Z",
        "2026-01-01T08:00:40Z",
        "2026-01-01T10:00:00Z",
    ];
    let mut rows = 0;
    let edited: Vec<String> = record
        .lines()
        .map(|line| {
            if line.starts_with('#') || line.starts_with("id,") {
                return line.to_string();
            }
            rows += 1;
            let (cells, _) = line.rsplit_once(',').unwrap();
            format!("{cells},{}", times[rows - 1])
        })
        .collect();
    std::fs::write(d.join("m.csv"), edited.join("\n") + "\n").unwrap();
    let said = trainer_ok(d, &["campaign", "--plan", "plan.csv", "--out", "m.csv"]);
    // Three configurations and two measurements of the reference (start, end), 40 s each.
    assert!(
        said.contains("3 of 6 configurations to measure, about 3m 20s ")
            && said.contains(
                "(40s per configuration, the median of 1 recorded in a row, and as much per \
                 measurement of the reference: 2)"
            ),
        "{said}"
    );
    // A new campaign: what its settling and dwelling take at least, references included (six
    // configurations, the reference at the start, after the third and at the end).
    let mut child = Command::new(binary("hexacomp-trainer"))
        .current_dir(d)
        .args(["campaign", "--plan", "plan.csv", "--out", "new.csv"])
        .args(["--settle", "100", "--dwell", "10", "--readings", "2"])
        .args(["--reference-every", "3"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut first = String::new();
    std::io::BufRead::read_line(
        &mut std::io::BufReader::new(child.stderr.take().unwrap()),
        &mut first,
    )
    .unwrap();
    child.kill().unwrap();
    child.wait().unwrap();
    assert!(
        first.contains(
            "6 of 6 configurations to measure, at least 16m 30s of settling and dwelling for \
             them and 3 measurements of the reference"
        ),
        "{first}"
    );
}

/// The movements (`moved_mm`) of a fiducials file a campaign wrote.
fn fiducial_movements(path: &Path) -> Vec<f64> {
    let mut reader = csv::Reader::from_path(path).unwrap();
    let column = reader
        .headers()
        .unwrap()
        .iter()
        .position(|c| c == "moved_mm")
        .unwrap();
    reader
        .records()
        .map(|r| r.unwrap()[column].parse().unwrap())
        .collect()
}

#[test]
fn the_fiducials_measured_at_the_end_refuse_a_registration_the_tracker_no_longer_stands_at() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let at = "2500,-1500,-800,0.3,-0.2,135";
    // Registered there, then bumped 0.2 mm along the base's x before the campaign began: the
    // references agree with each other all campaign long, only the fiducials can tell.
    let bumped = "2500.2,-1500,-800,0.3,-0.2,135";
    trainer_ok(d, &["plan", "--count", "6", "--out", "plan.csv"]);
    std::fs::copy(d.join("plan.csv"), d.join("first.csv")).unwrap();
    register_tracker(d, at, "a.toml");
    let under_a = ["--registration", "a.toml"];

    let stderr = trainer_ok(d, &campaign("plan.csv", "good.csv", at, &under_a));
    assert!(stderr.contains("the registration holds"), "{stderr}");
    let moved = fiducial_movements(&d.join("good.fiducials.csv"));
    assert!(
        moved.len() >= 3 && moved.iter().all(|m| *m < 0.04),
        "{moved:?}"
    );
    let again = trainer_ok(d, &campaign("plan.csv", "good.csv", at, &under_a));
    assert!(
        again.contains("nothing to do") && again.contains("the registration holds"),
        "{again}"
    );

    // A user's own file where the campaign writes its fiducials: refused before anything.
    let foreign = "name,x,y,z\nF1,1,2,3\n";
    std::fs::write(d.join("x.fiducials.csv"), foreign).unwrap();
    let error = text(&trainer_in(d, &campaign("plan.csv", "x.csv", at, &under_a)).stderr);
    assert!(error.contains("a campaign did not write"), "{error}");
    assert!(!d.join("x.csv").exists());
    assert_eq!(
        std::fs::read_to_string(d.join("x.fiducials.csv")).unwrap(),
        foreign
    );

    // A row measured again after the fiducials: they no longer check the campaign's end, and a
    // run killed before its end measures them again.
    let record = std::fs::read_to_string(d.join("good.csv")).unwrap();
    let mut lines: Vec<&str> = record.lines().collect();
    lines.pop();
    std::fs::write(d.join("good.csv"), lines.join("\n") + "\n").unwrap();
    let mut child = Command::new(binary("hexacomp-trainer"))
        .current_dir(d)
        .args(campaign("plan.csv", "good.csv", at, &under_a))
        .args(["--dwell", "1", "--readings", "3"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // The row is on disk; the end reference then takes two seconds of dwelling.
    while data_lines(&d.join("good.csv")).len() < 6 {
        assert!(
            child.try_wait().unwrap().is_none(),
            "the campaign ended early"
        );
        std::thread::sleep(Duration::from_millis(2));
    }
    signal_child(&child, libc::SIGKILL);
    child.wait().unwrap();
    assert!(
        !d.join("good.fiducials.csv").exists(),
        "the fiducials measured before the row were kept"
    );
    let stderr = trainer_ok(d, &campaign("plan.csv", "good.csv", at, &under_a));
    assert!(
        stderr.contains("reference R") && stderr.contains("the registration holds"),
        "{stderr}"
    );

    let output = trainer_in(d, &campaign("plan.csv", "c.csv", bumped, &under_a));
    let error = text(&output.stderr);
    assert!(!output.status.success(), "{error}");
    assert!(
        error.contains("moved together")
            && error.contains("register --measured")
            && error.contains("give that registration to solve"),
        "{error}"
    );
    assert_eq!(data_lines(&d.join("c.csv")).len(), 6, "every row is kept");
    let moved = fiducial_movements(&d.join("c.fiducials.csv"));
    assert!(
        moved.iter().all(|m| (m - 0.2).abs() < 0.04),
        "each fiducial moved the bump: {moved:?}"
    );
    // Run again, the decision stands, unless the check is declined in so many words.
    let output = trainer_in(d, &campaign("plan.csv", "c.csv", bumped, &under_a));
    assert!(!output.status.success());
    assert!(text(&output.stderr).contains("moved together"));
    let declined = trainer_ok(
        d,
        &campaign(
            "plan.csv",
            "c.csv",
            bumped,
            &[&under_a[..], &["--skip-fiducials"]].concat(),
        ),
    );
    assert!(
        declined.contains("the registration is unchecked"),
        "{declined}"
    );
    // Registered from the fiducials measured at the end, it stands where the bump put it.
    trainer_ok(
        d,
        &[
            "register",
            "--measured",
            "c.fiducials.csv",
            "--out",
            "c.toml",
        ],
    );
    // At the platform (300 mm above the base's origin) the new registration places a point the
    // tracker reads where it is, within what the fiducials' noise allows; the old one 0.2 mm off.
    let platform_point = glam::DVec3::new(0.0, 0.0, 300.0);
    let stands = hexacomp_core::Pose::from_mm_deg([2500.2, -1500.0, -800.0, 0.3, -0.2, 135.0]);
    let seen = stands.inverse().transform_point(platform_point);
    let placed_by = |file: &str| {
        let r = hexacomp_formats::read_registration(&d.join(file)).unwrap();
        r.instrument_pose()
            .transform_point(seen)
            .distance(platform_point)
    };
    assert!(placed_by("c.toml") < 0.03, "{}", placed_by("c.toml"));
    assert!(
        (placed_by("a.toml") - 0.2).abs() < 0.03,
        "{}",
        placed_by("a.toml")
    );
    // The finished campaign decides against the registration given now, not the first one.
    let holds = trainer_ok(
        d,
        &campaign("plan.csv", "c.csv", bumped, &["--registration", "c.toml"]),
    );
    assert!(holds.contains("the registration holds"), "{holds}");
}

/// The raw lines of a readings log by configuration and reading (`A/2.1` → ("A", 2)): the
/// targets as the instrument reported them.
fn raw_readings(path: &Path) -> std::collections::HashMap<(String, usize), String> {
    let mut reader = csv::ReaderBuilder::new()
        .comment(Some(b'#'))
        .from_path(path)
        .unwrap();
    let header = reader.headers().unwrap().clone();
    let targets: Vec<usize> = header
        .iter()
        .enumerate()
        .filter(|(_, c)| c.starts_with('p') && c.len() == 3)
        .map(|(k, _)| k)
        .collect();
    reader
        .records()
        .map(|r| {
            let r = r.unwrap();
            let (configuration, number) = r[0].split_once('/').unwrap();
            let reading: usize = number.split_once('.').unwrap().0.parse().unwrap();
            let line: Vec<&str> = targets.iter().map(|k| &r[*k]).collect();
            ((configuration.to_string(), reading), line.join(","))
        })
        .collect()
}

#[test]
fn a_campaign_reads_the_lines_a_trackers_software_appends_and_skips_those_from_before_the_move() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    trainer_ok(d, &["plan", "--count", "4", "--out", "plan.csv"]);
    let common = ["--no-reference", "--readings", "3"];
    trainer_ok(
        d,
        &[
            &["campaign", "--plan", "plan.csv", "--out", "v.csv"][..],
            &common,
        ]
        .concat(),
    );
    let raw = raw_readings(&d.join("v.readings.csv"));
    assert_eq!(raw.len(), 12);
    // The tracker's software: a line from an earlier session already in its file.
    let export = d.join("export.txt");
    std::fs::write(&export, "9,9,9,9,9,9,9,9,9\n").unwrap();
    let mut child = Command::new(binary("hexacomp-trainer"))
        .current_dir(d)
        .args(["campaign", "--plan", "plan.csv", "--out", "f.csv"])
        .args(["--instrument", "file", "--instrument-file", "export.txt"])
        .args(["--command-timeout", "60"])
        .args(common)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let stderr = std::io::BufReader::new(child.stderr.take().unwrap());
    let mut asked = std::collections::HashMap::<(String, usize), usize>::new();
    let (mut configurations_done, mut partial) = (0, false);
    let mut shown = Vec::new();
    for line in std::io::BufRead::lines(stderr) {
        let line = line.unwrap();
        shown.push(line.clone());
        let Some(rest) = line.strip_prefix("configuration ") else {
            continue;
        };
        let Some((id, rest)) = rest.split_once(", reading ") else {
            continue;
        };
        let Some((number, _)) = rest.split_once(": measure") else {
            continue;
        };
        let key = (id.to_string(), number.parse::<usize>().unwrap());
        let times = asked.entry(key.clone()).or_default();
        *times += 1;
        let mut append = String::new();
        if std::mem::take(&mut partial) {
            append.push_str(",9,9,9,9,9,9\n");
        }
        // The first configuration's second reading: first a line that is no reading.
        if key.1 == 2 && *times == 1 && asked.len() == 2 {
            append.push_str("target not found\n");
        } else {
            append.push_str(&raw[&key]);
            append.push('\n');
            // After a configuration's last reading the software measures once more, before
            // the machine moved on: that line belongs to no reading. After the second
            // configuration it is still writing that line when the next one begins.
            if key.1 == 3 && configurations_done == 1 {
                append.push_str("9,9,9");
                partial = true;
            } else if key.1 == 3 {
                append.push_str(&raw[&key]);
                append.push('\n');
            }
            if key.1 == 3 {
                configurations_done += 1;
            }
        }
        std::fs::OpenOptions::new()
            .append(true)
            .open(&export)
            .unwrap()
            .write_all(append.as_bytes())
            .unwrap();
    }
    let status = child.wait().unwrap();
    let shown = shown.join("\n");
    assert!(status.success(), "{shown}");
    let log = std::fs::read_to_string(d.join("f.readings.csv")).unwrap();
    assert!(
        log.contains("export.txt:3: the line \"\"target not found\"\" has 1 cells"),
        "the line that is no reading is a failed attempt, named by its place: {log}"
    );
    assert_eq!(
        shown
            .matches("skipped 1 line appended before configuration")
            .count(),
        2,
        "{shown}"
    );
    assert_eq!(
        shown
            .matches("skipped, being written before the readings began")
            .count(),
        1,
        "{shown}"
    );
    assert_eq!(
        rows_without_time(&d.join("f.csv")),
        rows_without_time(&d.join("v.csv")),
        "the followed readings give the virtual instrument's record"
    );
}
