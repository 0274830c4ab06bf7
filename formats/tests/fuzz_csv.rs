//! Fuzzing the CSV readers: random bytes, and random edits of a valid file of each kind (so that
//! most cases get past the header and reach the row checks). No input may panic; every refusal
//! has a message. Deeper runs: `PROPTEST_CASES=20000 cargo test --release -p hexacomp-formats
//! --test fuzz_csv`.

#[path = "../../core/tests/common/edits.rs"]
mod edits;

use std::path::Path;

use edits::{apply, edit};
use hexacomp_formats::{
    read_corrections, read_fiducials, read_joints, read_measurements, read_poses, read_registration,
};
use proptest::prelude::*;

const POSES: &str = "id,x,y,z,a,b,c\np1,1.5,-2,280,0.5,-1,3\np2,0,0,300,0,0,0\n";
const JOINTS: &str = "id,q1,q2,q3,q4,q5,q6\nj1,350,351,352,353,354,355\n";
const CORRECTIONS: &str =
    "id,q1,q2,q3,q4,q5,q6,dq1,dq2,dq3,dq4,dq5,dq6\nc1,350,351,352,353,354,355,0.1,0,0,0,0,-0.2\n";
const MEASUREMENTS: &str = "id,x,y,z,a,b,c,q1,q2,q3,q4,q5,q6,p1x,p1y,p1z,p2x,p2y,p2z,p3x,p3y,p3z\n\
m1,0,0,280,0,0,0,350,351,352,353,354,355,1,2,3,4,5,6,7,8,9\n";
const FIDUCIALS: &str = "name,x,y,z,weight\nF1,450,0,0,1\nF2,0,450,0,0.5\nF3,-450,0,20,1\n";
const REGISTRATION: &str = "format = 1\ncreated = \"2026-11-24T00:14:14Z\"\nnominal = \"n.csv\"\n\
measured = \"m.csv\"\ninstrument_pose = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]\nlocked = []\n\
tolerance_mm = 0.05\nrms_mm = 0.01\nmax_mm = 0.02\n\
[[fiducials]]\nname = \"F1\"\nnominal = [1.0, 0.0, 0.0]\nmeasured = [1.0, 0.0, 0.0]\nweight = 1.0\nresidual = [0.0, 0.0, 0.0]\n\
[[fiducials]]\nname = \"F2\"\nnominal = [0.0, 1.0, 0.0]\nmeasured = [0.0, 1.0, 0.0]\nweight = 1.0\nresidual = [0.0, 0.0, 0.0]\n\
[[fiducials]]\nname = \"F3\"\nnominal = [0.0, 0.0, 1.0]\nmeasured = [0.0, 0.0, 1.0]\nweight = 1.0\nresidual = [0.0, 0.0, 0.0]\n";

fn assert_refusal_has_a_message<T>(result: Result<T, hexacomp_formats::Error>) {
    if let Err(e) = result {
        assert!(
            !e.to_string().trim().is_empty(),
            "a refusal without a message"
        );
    }
}

/// Reads `bytes` as every CSV kind.
fn read_as_every_csv(dir: &Path, bytes: &[u8]) {
    let path = dir.join("input.csv");
    std::fs::write(&path, bytes).unwrap();
    assert_refusal_has_a_message(read_poses(&path));
    assert_refusal_has_a_message(read_joints(&path));
    assert_refusal_has_a_message(read_corrections(&path));
    assert_refusal_has_a_message(read_measurements(&path));
    assert_refusal_has_a_message(read_fiducials(&path));
    assert_refusal_has_a_message(read_registration(&path));
}

proptest! {
    #[test]
    fn csv_readers_take_any_bytes(bytes in prop::collection::vec(any::<u8>(), 0..512)) {
        let dir = tempfile::tempdir().unwrap();
        read_as_every_csv(dir.path(), &bytes);
    }

    #[test]
    fn csv_readers_take_any_edit_of_a_valid_file(
        which in 0..6usize,
        edits in prop::collection::vec(edit(), 1..6),
    ) {
        let dir = tempfile::tempdir().unwrap();
        let valid = [POSES, JOINTS, CORRECTIONS, MEASUREMENTS, FIDUCIALS, REGISTRATION][which];
        read_as_every_csv(dir.path(), &apply(valid.as_bytes(), &edits));
    }
}

#[test]
fn the_valid_fiducials_and_registration_read() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("input");
    std::fs::write(&path, FIDUCIALS).unwrap();
    let fiducials = read_fiducials(&path).unwrap();
    assert_eq!(fiducials.len(), 3);
    assert_eq!(fiducials[1].weight, 0.5);
    std::fs::write(&path, REGISTRATION).unwrap();
    assert_eq!(read_registration(&path).unwrap().fiducials.len(), 3);
}
