//! The C library (`libhexacomp.a` and `.so`, `client-c/include/hexacomp.h`, `hexacomp.pc`) used by a C
//! program compiled here with the system's C compiler, against a running service: every point
//! it prints equals the compensator's answer bit for bit, its error paths give codes, and a call
//! to a stopped service gives the timeout code after the deadline `hexacomp_set_timeout` set.

use hexacomp_core::Geometry;
use hexacomp_core::compensator::{compensate_legs, compensate_pose};
use hexacomp_core::fused::FusedModel;
use hexacomp_core::pose::Pose;
use hexacomp_tests::c_program::{compile, run_against};
use hexacomp_tests::{ServiceProcess, save_smooth_model, test_uncertainty, unique_instance};

fn numbers(fields: &[&str]) -> [f64; 6] {
    std::array::from_fn(|k| fields[k].parse().unwrap())
}

#[test]
fn a_c_program_linked_statically_and_dynamically_gets_the_compensators_answers() {
    let dir = tempfile::tempdir().unwrap();
    let (mut model, path) = save_smooth_model(dir.path(), 51);
    // With an uncertainty, as `calibrate` writes a model.
    model.uncertainty = Some(test_uncertainty());
    model.save(&path).unwrap();
    let g = Geometry::prototype();
    for shared in [false, true] {
        let exe = compile("client_test.c", dir.path(), shared);
        // A service of its own per program: the status counters it prints are this run's.
        let instance = unique_instance("cabi");
        let service =
            ServiceProcess::with_model(&instance, &dir.path().join(format!("s{shared}")), &path);
        let stdout = run_against(&exe, &service);
        let mut checked = std::collections::BTreeMap::new();
        let mut with_uncertainty = 0;
        let mut deadlines = Vec::new();
        for line in stdout.lines() {
            let fields: Vec<&str> = line.split(' ').collect();
            match fields[0] {
                "S" => assert_eq!(fields[1], "1"),
                "P" | "J" | "B" | "K" | "A" => {
                    let input = numbers(&fields[2..8]);
                    let expected = if matches!(fields[0], "J" | "K") {
                        compensate_legs(&g, Some(&FusedModel::new(&model)), &input)
                    } else {
                        compensate_pose(
                            &g,
                            Some(&FusedModel::new(&model)),
                            &Pose::from_mm_deg(input),
                        )
                    };
                    assert_eq!(fields[8], (expected.status as u8).to_string(), "{line}");
                    assert_eq!(fields[9], "1", "{line}");
                    let legs = numbers(&fields[10..16]);
                    let corrections = numbers(&fields[16..22]);
                    // The uncertainty travels as an f32 (0: none); `%.9g` prints it exactly.
                    let sigma: f32 = fields[22].parse().unwrap();
                    assert_eq!(
                        sigma.to_bits(),
                        expected
                            .uncertainty_mm
                            .map_or(0.0f32, |s| s as f32)
                            .to_bits(),
                        "{line}"
                    );
                    with_uncertainty += usize::from(sigma > 0.0);
                    for k in 0..6 {
                        assert_eq!(legs[k].to_bits(), expected.legs[k].to_bits(), "{line}");
                        assert_eq!(
                            corrections[k].to_bits(),
                            expected.corrections[k].to_bits(),
                            "{line}"
                        );
                    }
                    *checked.entry(fields[0]).or_insert(0) += 1;
                }
                // Requests and points the service counted: 64 poses, 64 joints, three batches
                // (64 poses, 64 joints, 0 points).
                "R" => assert_eq!(fields[1..], ["131", "256"], "{line}"),
                "T" => deadlines.push((fields[1].to_string(), fields[2].to_string())),
                "OK" => {}
                other => panic!("unexpected line {other:?}"),
            }
        }
        let expected_counts = [("A", 1), ("B", 64), ("J", 64), ("K", 64), ("P", 64)];
        assert_eq!(checked, expected_counts.into_iter().collect());
        assert!(
            with_uncertainty > 200,
            "{with_uncertainty} of 257 points with an uncertainty"
        );
        let timeouts: Vec<&str> = deadlines.iter().map(|(d, _)| d.as_str()).collect();
        assert_eq!(timeouts, ["50000", "300000"], "{stdout}");
        // The short deadline was the one set, not the 10 s the program connected with.
        let waited: u64 = deadlines[0].1.parse().unwrap();
        assert!(waited < 5_000_000, "a 50 ms deadline waited {waited} µs");
        assert_eq!(stdout.lines().last(), Some("OK"));
    }
}
