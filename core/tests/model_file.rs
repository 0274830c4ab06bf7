//! The model file: exact round trip, and each kind of bad file refused with its own reason.

mod common;

use common::{model, uncertainty};
use hexacomp_core::Geometry;
use hexacomp_core::error::{Error, ModelFileProblem};
use hexacomp_core::model::{FORMAT_VERSION, Model, Networks};
use hexacomp_core::network::Network;

fn problem(bytes: &[u8]) -> ModelFileProblem {
    Model::from_bytes(bytes).unwrap_err()
}

#[test]
fn model_round_trips_through_a_file_exactly() {
    let g = Geometry::prototype();
    let m = model(&g);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.hxm");
    m.save(&path).unwrap();
    assert_eq!(Model::load(&path, &g).unwrap(), m);
    // No temporary file is left beside it.
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
}

#[test]
fn a_model_with_an_uncertainty_is_version_2_and_one_without_stays_version_1() {
    let g = Geometry::prototype();
    let plain = model(&g);
    let bytes = plain.to_bytes();
    // Builds that read only version 1 keep reading models without an uncertainty.
    assert_eq!(u16::from_le_bytes([bytes[8], bytes[9]]), 1);
    assert_eq!(Model::from_bytes(&bytes).unwrap().uncertainty, None);
    let with = Model {
        uncertainty: Some(uncertainty()),
        ..plain.clone()
    };
    let bytes = with.to_bytes();
    // Networks with an uncertainty stay version 2 (version 3 is the physical model's).
    assert_eq!(u16::from_le_bytes([bytes[8], bytes[9]]), 2);
    assert_eq!(FORMAT_VERSION, 3);
    let read = Model::from_bytes(&bytes).unwrap();
    assert_eq!(read, with);
    assert_eq!(read.format_version(), 2);
    // A version-2 file is the version-1 payload and the uncertainty after it.
    let old = plain.to_bytes();
    let old_payload = &old[14..old.len() - 8];
    assert_eq!(&bytes[14..14 + old_payload.len()], old_payload);
}

/// `bytes` with the format version `version` and the checksum recomputed.
fn with_version(bytes: &[u8], version: u16) -> Vec<u8> {
    let mut changed = bytes[..bytes.len() - 8].to_vec();
    changed[8..10].copy_from_slice(&version.to_le_bytes());
    let checksum = crc::Crc::<u64>::new(&crc::CRC_64_XZ).checksum(&changed);
    changed.extend_from_slice(&checksum.to_le_bytes());
    changed
}

#[test]
fn a_version_2_file_without_a_valid_uncertainty_is_refused() {
    let g = Geometry::prototype();
    // Announced as version 2, but the payload ends with the model.
    let missing = with_version(&model(&g).to_bytes(), 2);
    assert!(
        matches!(problem(&missing), ModelFileProblem::Corrupt(_)),
        "{:?}",
        problem(&missing)
    );
    // An uncertainty whose variance is negative.
    let mut bad = uncertainty();
    bad.constant_variance_mm2 = -1e-6;
    let negative = Model {
        uncertainty: Some(bad),
        ..model(&g)
    }
    .to_bytes();
    match problem(&negative) {
        ModelFileProblem::Corrupt(why) => assert!(why.contains("variance"), "{why}"),
        other => panic!("{other:?}"),
    }
    // Version 1 with an uncertainty after the model: bytes the version does not have.
    let extra = with_version(
        &Model {
            uncertainty: Some(uncertainty()),
            ..model(&g)
        }
        .to_bytes(),
        1,
    );
    assert!(
        matches!(problem(&extra), ModelFileProblem::Corrupt(_)),
        "{:?}",
        problem(&extra)
    );
}

#[test]
fn each_kind_of_bad_file_has_its_own_reason() {
    let g = Geometry::prototype();
    let bytes = model(&g).to_bytes();
    assert_eq!(
        problem(b"PK\x03\x04 a zip file"),
        ModelFileProblem::NotAModel
    );
    assert!(matches!(
        problem(&bytes[..bytes.len() - 3]),
        ModelFileProblem::Truncated { .. }
    ));
    assert!(matches!(
        problem(&bytes[..12]),
        ModelFileProblem::Truncated {
            actual: 12,
            expected: 14
        }
    ));
    let mut corrupted = bytes.clone();
    corrupted[40] ^= 0x01;
    assert_eq!(problem(&corrupted), ModelFileProblem::Checksum);
    let mut newer = bytes.clone();
    newer[8..10].copy_from_slice(&(FORMAT_VERSION + 1).to_le_bytes());
    assert_eq!(
        problem(&newer),
        ModelFileProblem::Version {
            found: FORMAT_VERSION + 1,
            supported: FORMAT_VERSION
        }
    );
    let mut longer = bytes.clone();
    longer.push(0);
    assert!(matches!(problem(&longer), ModelFileProblem::Corrupt(_)));
}

#[test]
fn a_model_for_another_geometry_is_refused_by_fingerprint() {
    let g = Geometry::prototype();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.hxm");
    model(&g).save(&path).unwrap();
    let mut other = g.clone();
    other.base_joints[0].x += 0.1;
    match Model::load(&path, &other) {
        Err(Error::ModelFile {
            problem: ModelFileProblem::Geometry { model, geometry },
            ..
        }) => {
            assert_eq!(model, g.fingerprint().to_string());
            assert_eq!(geometry, other.fingerprint().to_string());
        }
        other => panic!("expected a geometry mismatch, got {other:?}"),
    }
}

#[test]
fn non_finite_weights_and_inconsistent_shapes_are_refused() {
    assert!(Network::from_weights(3, 1, vec![f64::NAN; Network::weight_count(3, 1)]).is_err());
    assert!(Network::from_weights(3, 1, vec![0.0; 5]).is_err());
    assert!(Network::from_weights(0, 1, vec![0.0; 1]).is_err());
    let g = Geometry::prototype();
    let mut m = model(&g);
    m.correction_bounds[2] = [1.0, -1.0];
    assert!(m.validate().is_err());
    m = model(&g);
    m.networks = Networks::Decoupled(vec![]);
    assert!(m.validate().is_err());
}

#[test]
fn max_slope_bounds_every_finite_difference_and_is_exact_for_one_node_at_its_centre() {
    let g = Geometry::prototype();
    let m = model(&g);
    let bound = m.max_slope();
    let mut seen: f64 = 0.0;
    let h = 1e-3;
    for i in 0..2000 {
        let t = i as f64;
        let q: [f64; 6] = std::array::from_fn(|k| 355.0 + 70.0 * (t * 0.731 + k as f64).sin());
        let u: [f64; 6] = std::array::from_fn(|k| (t * 1.37 + 2.0 * k as f64).cos());
        let norm = u.iter().map(|x| x * x).sum::<f64>().sqrt();
        let q2: [f64; 6] = std::array::from_fn(|k| q[k] + h * u[k] / norm);
        let (a, b) = (m.raw_corrections(&q), m.raw_corrections(&q2));
        for k in 0..6 {
            seen = seen.max((a[k] - b[k]).abs() / h);
        }
    }
    assert!(
        seen > 0.0 && seen <= bound * (1.0 + 1e-9),
        "seen {seen} bound {bound}"
    );

    // One hidden node, input 0.5 on leg 1 only, output weight 2: at the normalisation's
    // mean tanh' = 1, so the slope there is exactly 2 · 0.5 / span.
    let w = vec![0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 2.0, 0.1];
    let single = Model {
        networks: Networks::Decoupled(
            (0..6)
                .map(|_| Network::from_weights(1, 1, w.clone()).unwrap())
                .collect(),
        ),
        ..model(&g)
    };
    let expected = 2.0 * 0.5 / 140.0;
    assert!((single.max_slope() - expected).abs() < 1e-15);
    let centre = [355.0; 6];
    let mut step = centre;
    step[0] += 1e-4;
    let fd = (single.raw_corrections(&step)[0] - single.raw_corrections(&centre)[0]) / 1e-4;
    assert!((fd - expected).abs() < 1e-9 * expected.max(1.0), "fd {fd}");
}

#[test]
fn a_file_cut_right_after_the_magic_or_the_header_is_truncated_not_foreign() {
    let g = Geometry::prototype();
    let bytes = model(&g).to_bytes();
    // Exactly the magic: a model file, cut before the end of its header.
    assert_eq!(
        problem(&bytes[..8]),
        ModelFileProblem::Truncated {
            actual: 8,
            expected: 14
        }
    );
    // One byte short of the magic: not a model at all.
    assert_eq!(problem(&bytes[..7]), ModelFileProblem::NotAModel);
    // Exactly the header: truncated, and the expected size counts payload and checksum.
    let payload = u32::from_le_bytes(bytes[10..14].try_into().unwrap()) as usize;
    assert_eq!(bytes.len(), 14 + payload + 8);
    assert_eq!(
        problem(&bytes[..14]),
        ModelFileProblem::Truncated {
            actual: 14,
            expected: bytes.len()
        }
    );
}
