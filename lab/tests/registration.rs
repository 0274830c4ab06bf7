//! Registration: a campaign measured in a tracker's own frame, located from six fiducials read
//! with 10 µm noise, calibrates blind within 10 % of the same campaign given in the base frame;
//! the refusals name their cause.

mod common;

use glam::DVec3;
use hexacomp_core::Geometry;
use hexacomp_core::Pose;
use hexacomp_core::records::NamedPoint;
use hexacomp_core::rigid_fit::Locked;
use hexacomp_measuring::registration::{
    InstrumentMpe, RegistrationOptions, accuracy_from_residuals, into_base_frame, register,
    supported_accuracy,
};
use hexacomp_virtual::{ErrorModel, ErrorVariant, VirtualPlatform, measure_fiducials};
use rand::SeedableRng;
use rand_distr::Distribution;

/// Six fiducials on the prototype's base plate and floor (base frame, mm).
fn nominal_fiducials() -> Vec<NamedPoint> {
    [
        (450.0, 0.0, 0.0),
        (225.0, 389.7, 0.0),
        (-225.0, 389.7, 20.0),
        (-450.0, 0.0, 0.0),
        (-225.0, -389.7, 40.0),
        (225.0, -389.7, 0.0),
    ]
    .iter()
    .enumerate()
    .map(|(k, &(x, y, z))| NamedPoint {
        name: format!("F{}", k + 1),
        position: DVec3::new(x, y, z),
        weight: 1.0,
    })
    .collect()
}

/// The noise of a fiducial reading: 10 µm RMS of the point in 3D (5.8 µm per coordinate).
const FIDUCIAL_SIGMA_MM: f64 = 0.010 / 1.732_050_807_568_877_2;

#[test]
fn an_instrument_frame_campaign_calibrates_within_ten_percent_of_the_base_frame_one() {
    let g = Geometry::prototype();
    let tracker = Pose::from_mm_deg([2500.0, -1500.0, -800.0, 0.3, -0.2, 135.0]);
    // The default machine, and two robots the networks were never tuned on.
    for (machine_seed, variant) in [
        (18, ErrorVariant::Paper),
        (7, ErrorVariant::Paper),
        (3, ErrorVariant::StrongPitch),
    ] {
        let model = ErrorModel::variant(variant);
        let platform = VirtualPlatform::new(&g, &model, machine_seed, 1).unwrap();
        // The plan without the legs' extremes: with them, the paper's decoupled networks lose
        // more through a registration on the strong-pitch robot (× 1.22 on average over the
        // four draws, 1.07–1.43; docs/accuracy.md), a sensitivity of those networks, not of
        // the registration this test is about.
        let mut campaign = common::campaign_of_150();
        campaign.plan.leg_extremes = false;
        let (_, base_frame) =
            hexacomp_lab::measure_virtual(&campaign.plan, &mut platform.clone()).unwrap();
        let base = common::blind_decoupled(&g, &platform, &base_frame).0;
        // The same campaign as the tracker reports it, registered from four draws of the
        // fiducials' noise: the registration's error is a different systematic offset each time.
        let mut ratios = Vec::new();
        for draw in 1..=4 {
            let mut registered = base_frame.clone();
            for row in &mut registered {
                row.observed = row.observed.in_frame(&tracker.inverse());
            }
            let nominal = nominal_fiducials();
            let measured = measure_fiducials(&nominal, &tracker, FIDUCIAL_SIGMA_MM, draw).unwrap();
            let registration = register(&nominal, &measured, &RegistrationOptions::default())
                .expect("registration");
            into_base_frame(&mut registered, &registration.instrument);
            let via_tracker = common::blind_decoupled(&g, &platform, &registered).0;
            ratios.push(via_tracker.position_mm.mean / base.position_mm.mean);
        }
        eprintln!(
            "machine {machine_seed} {variant}: mean {:.4} mm from the base frame; through four \
             registrations × {:.3?}",
            base.position_mm.mean, ratios
        );
        let mean_ratio = ratios.iter().sum::<f64>() / ratios.len() as f64;
        assert!(mean_ratio <= 1.10, "machine {machine_seed}: {ratios:?}");
    }
}

/// The registration of `measured` onto the nominal fiducials with `options`: its error text.
fn refusal(measured: &[NamedPoint], options: &RegistrationOptions) -> String {
    register(&nominal_fiducials(), measured, options)
        .expect_err("refused")
        .to_string()
}

fn tracker_readings() -> Vec<NamedPoint> {
    let tracker = Pose::from_mm_deg([1200.0, 800.0, -700.0, 0.0, 0.0, -60.0]);
    measure_fiducials(&nominal_fiducials(), &tracker, 0.005, 1).unwrap()
}

#[test]
fn two_swapped_names_are_refused_and_named() {
    let mut measured = tracker_readings();
    let (f2, f5) = (measured[1].position, measured[4].position);
    measured[1].position = f5;
    measured[4].position = f2;
    let message = refusal(&measured, &RegistrationOptions::default());
    assert!(
        message.contains("The names F2 and F5 look swapped"),
        "{message}"
    );
}

#[test]
fn inches_are_refused_and_named() {
    let mut measured = tracker_readings();
    for point in &mut measured {
        point.position /= 25.4;
    }
    let message = refusal(&measured, &RegistrationOptions::default());
    assert!(
        message.contains("the measured coordinates look like inches"),
        "{message}"
    );
}

#[test]
fn a_knocked_fiducial_is_named() {
    let mut measured = tracker_readings();
    measured[2].position += DVec3::new(0.0, 0.4, -0.1);
    let message = refusal(&measured, &RegistrationOptions::default());
    assert!(message.contains("fiducial F3 is"), "{message}");
    assert!(message.contains("Without F3 the others fit"), "{message}");
}

#[test]
fn collinear_fiducials_are_refused() {
    let nominal: Vec<NamedPoint> = (0..4)
        .map(|k| NamedPoint {
            name: format!("L{k}"),
            position: DVec3::new(200.0 * k as f64, 100.0 * k as f64, 0.5 * (k % 2) as f64),
            weight: 1.0,
        })
        .collect();
    let tracker = Pose::from_mm_deg([1000.0, 0.0, 0.0, 0.0, 0.0, 20.0]);
    let measured = measure_fiducials(&nominal, &tracker, 0.0, 1).unwrap();
    let message = register(&nominal, &measured, &RegistrationOptions::default())
        .expect_err("collinear")
        .to_string();
    assert!(message.contains("nearly collinear"), "{message}");
}

#[test]
fn unknown_names_and_too_few_common_ones_are_refused_with_the_names() {
    let mut measured = tracker_readings();
    measured[5].name = "G6".into();
    let message = refusal(&measured, &RegistrationOptions::default());
    assert!(
        message.contains("names only in the nominal file: F6")
            && message.contains("names only in the measured file: G6"),
        "{message}"
    );
    let message = refusal(&measured[..2], &RegistrationOptions::default());
    assert!(
        message.contains("2 fiducial names are common to both files"),
        "{message}"
    );
}

#[test]
fn a_tracker_off_level_is_refused_when_its_vertical_is_locked() {
    let tracker = Pose::from_mm_deg([1200.0, 800.0, -700.0, 0.05, 0.0, -60.0]);
    let measured = measure_fiducials(&nominal_fiducials(), &tracker, 0.005, 1).unwrap();
    let options = RegistrationOptions {
        locked: Locked::from_names(["a", "b"]).unwrap(),
        ..Default::default()
    };
    let message = refusal(&measured, &options);
    assert!(
        message.contains("does not meet the locked parameters (a, b)"),
        "{message}"
    );
    // Levelled, the same lock registers it.
    let level = Pose::from_mm_deg([1200.0, 800.0, -700.0, 0.0, 0.0, -60.0]);
    let measured = measure_fiducials(&nominal_fiducials(), &level, 0.005, 1).unwrap();
    let registration = register(&nominal_fiducials(), &measured, &options).expect("level");
    assert_eq!(registration.instrument.angles.x, 0.0);
    assert!((registration.instrument.angles.z.to_degrees() + 60.0).abs() < 1e-3);
}

/// The registration's stated error at the platform is what repeated registrations with the
/// instrument's noise scatter by: 400 registrations with each fiducial read with σ from its
/// distance (MPE 15 µm + 6 µm/m taken as 2σ), their error at the platform's targets against the
/// propagated figure, and their residuals against the expected ones.
#[test]
fn the_supported_accuracy_is_what_repeated_registrations_scatter_by() {
    let g = Geometry::prototype();
    let tracker = Pose::from_mm_deg([2500.0, -1500.0, -800.0, 0.3, -0.2, 135.0]);
    let mpe: InstrumentMpe = "15+6".parse().unwrap();
    let platform = hexacomp_core::kinematics::target_points(&g, &g.home_pose());
    let nominal = nominal_fiducials();
    let into_tracker = tracker.inverse();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let normal = rand_distr::Normal::new(0.0, 1.0).unwrap();
    let (mut worst_square, mut residual_square) = (vec![0.0; platform.len()], 0.0);
    let trials = 400;
    let mut stated = None;
    for _ in 0..trials {
        let measured: Vec<NamedPoint> = nominal
            .iter()
            .map(|f| {
                let sigma = mpe.sigma_mm((f.position - tracker.position).length());
                let noise = DVec3::new(
                    normal.sample(&mut rng),
                    normal.sample(&mut rng),
                    normal.sample(&mut rng),
                ) * sigma;
                NamedPoint {
                    position: into_tracker.transform_point(f.position + noise),
                    ..f.clone()
                }
            })
            .collect();
        let options = RegistrationOptions {
            tolerance_mm: 1.0,
            ..Default::default()
        };
        let registration = register(&nominal, &measured, &options).expect("registration");
        let support = supported_accuracy(&registration, &mpe, &platform);
        stated.get_or_insert(support);
        for (square, p) in worst_square.iter_mut().zip(&platform) {
            let seen = into_tracker.transform_point(*p);
            *square += (registration.instrument.transform_point(seen) - *p).length_squared();
        }
        residual_square += registration.rms_mm.powi(2);
    }
    let stated = stated.unwrap();
    let scattered = worst_square
        .iter()
        .map(|s| (s / trials as f64).sqrt())
        .fold(0.0, f64::max);
    let residual = (residual_square / trials as f64).sqrt();
    eprintln!(
        "registration error at the platform: stated {:.5} mm, scattered {scattered:.5} mm; \
         residual RMS expected {:.5} mm, found {residual:.5} mm",
        stated.registration_mm, stated.expected_rms_mm
    );
    assert!((scattered / stated.registration_mm - 1.0).abs() < 0.1);
    assert!((residual / stated.expected_rms_mm - 1.0).abs() < 0.1);
    // A reading at the platform: √3 × half the MPE at that distance.
    let distance = stated.platform_distance_mm / 1000.0;
    assert!((stated.point_mm - 3f64.sqrt() * 0.5 * (15.0 + 6.0 * distance) / 1000.0).abs() < 1e-12);
}

#[test]
fn a_knock_the_layout_cannot_place_lists_the_candidates() {
    // Four fiducials on the floor, one pushed down 0.4 mm: any three of four coplanar points fit,
    // so no single one may be blamed.
    let nominal: Vec<NamedPoint> = [(400.0, 0.0), (0.0, 400.0), (-400.0, 0.0), (0.0, -400.0)]
        .iter()
        .enumerate()
        .map(|(k, &(x, y))| NamedPoint {
            name: format!("N{}", k + 1),
            position: DVec3::new(x, y, 0.0),
            weight: 1.0,
        })
        .collect();
    let tracker = Pose::from_mm_deg([1500.0, 200.0, -600.0, 0.0, 0.0, 30.0]);
    let mut measured = measure_fiducials(&nominal, &tracker, 0.0, 1).unwrap();
    measured[1].position = tracker
        .inverse()
        .transform_point(nominal[1].position - DVec3::new(0.0, 0.0, 0.4));
    let message = register(&nominal, &measured, &RegistrationOptions::default())
        .expect_err("knocked")
        .to_string();
    assert!(
        message.contains("Without any one of N1, N2, N3, N4 the others fit"),
        "{message}"
    );
}

#[test]
fn a_weak_layout_shows_in_the_registrations_error_at_the_platform() {
    // Six fiducials along a 2 m rail, 20 mm apart across it: they fit within 0.01 mm, but the
    // rotation about the rail is poorly fixed and moves a target 1 m away.
    let nominal: Vec<NamedPoint> = (0..6)
        .map(|k| NamedPoint {
            name: format!("R{k}"),
            position: DVec3::new(
                -1000.0 + 400.0 * k as f64,
                10.0 * (k % 2) as f64 * 2.0 - 10.0,
                0.0,
            ),
            weight: 1.0,
        })
        .collect();
    let tracker = Pose::from_mm_deg([0.0, -2000.0, 500.0, 0.0, 0.0, 90.0]);
    let measured = measure_fiducials(&nominal, &tracker, 0.005, 3).unwrap();
    let registration =
        register(&nominal, &measured, &RegistrationOptions::default()).expect("registration");
    assert!(registration.max_mm < 0.02, "{}", registration.max_mm);
    let shown = accuracy_from_residuals(&registration);
    let platform = [DVec3::new(0.0, 1000.0, 300.0)];
    let support = supported_accuracy(&registration, &shown, &platform);
    eprintln!(
        "rail: residual RMS {:.4} mm, the registration's error 1 m away {:.4} mm",
        registration.rms_mm, support.registration_mm
    );
    assert!(support.registration_mm > 0.05, "{support:?}");
}
