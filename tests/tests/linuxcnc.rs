//! hexacomp against the real LinuxCNC (Debian's linuxcnc-uspace, POSIX non-realtime): the
//! example configuration `integrations/linuxcnc/hexapod-sim` (LinuxCNC's hexapod sim with the
//! HAL component between motion and the drives), driven headless by `drive.py`.
//!
//! - inverse kinematics: poses commanded by MDI give the joint positions hexacomp's nominal
//!   inverse kinematics computes for the geometry converted from the configuration, and the
//!   component's `uncertainty` pin the service's uncertainty for those legs;
//! - a G-code program with the component in the loop: every servo period's motor command out of
//!   the component is the command into it plus the service's correction for that period's legs;
//! - the service killed mid-program: fault raised, correction held, machine stopped, program
//!   completed once the service is back;
//! - no service answering from the start: the servo thread runs on while the component's helper
//!   thread tries to connect, and the connection is picked up once the service is back;
//! - a restart into another model, a deploy, and `enable` 0 with the service killed: every
//!   servo period follows the component's law (each change of the correction ramped at
//!   `max-rate`), and compensation switched off is no fault.
//!
//! The five tests share LinuxCNC (one instance per machine) and run one at a time.

use std::collections::BTreeMap;
use std::sync::Mutex;
use std::time::Duration;

use hexacomp_core::compensator::{PointStatus, compensate_legs};
use hexacomp_core::fused::FusedModel;
use hexacomp_core::model::Model;
use hexacomp_core::sampling::{SamplerOptions, WorkspaceSampler};
use hexacomp_core::{Pose, inverse_kinematics};
use hexacomp_tests::linuxcnc::{
    Sample, SimConfig, SimService, linuxcnc_available, read_samples, realtime_kernel,
};
use hexacomp_tests::{binary, smooth_model_for};
use serde_json::json;

/// The ini with fast moves, for tests about positions rather than the machine's dynamics.
fn fast_moves(ini: String) -> String {
    ini.replace("MAX_LINEAR_VELOCITY = 10.0", "MAX_LINEAR_VELOCITY = 200.0")
        .replace(
            "MAX_LINEAR_ACCELERATION = 20.0",
            "MAX_LINEAR_ACCELERATION = 4000.0",
        )
        .replace("MAX_ANGULAR_VELOCITY = 6", "MAX_ANGULAR_VELOCITY = 2000")
        .replace("MAX_VELOCITY = 20.0", "MAX_VELOCITY = 400.0")
        .replace("MAX_ACCELERATION = 200.0", "MAX_ACCELERATION = 8000.0")
}

/// One LinuxCNC at a time.
static LINUXCNC: Mutex<()> = Mutex::new(());
const MM_PER_INCH: f64 = 25.4;
/// Longest run of one LinuxCNC session.
const SESSION: Duration = Duration::from_secs(400);

fn one_at_a_time() -> std::sync::MutexGuard<'static, ()> {
    LINUXCNC
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// The correction the service's `model` gives for `sample`'s legs (inch).
fn service_correction(sim: &SimConfig, model: &Model, sample: &Sample) -> [f64; 6] {
    let legs_mm = sample.legs.map(|q| q * MM_PER_INCH);
    let answer = compensate_legs(&sim.geometry, Some(&FusedModel::new(model)), &legs_mm);
    assert_eq!(answer.status, PointStatus::Ok, "legs {legs_mm:?} mm");
    answer.corrections.map(|c| c / MM_PER_INCH)
}

/// The 1-σ position uncertainty (inch) the service's model gives for `joints` (inch), as the
/// service sends it (an `f32` of mm).
fn service_uncertainty(sim: &SimConfig, joints: &[f64]) -> f64 {
    let legs_mm: [f64; 6] = std::array::from_fn(|j| joints[j] * MM_PER_INCH);
    let answer = compensate_legs(&sim.geometry, Some(&FusedModel::new(&sim.model)), &legs_mm);
    assert_eq!(answer.status, PointStatus::Ok, "legs {legs_mm:?} mm");
    let sigma_mm = answer.uncertainty_mm.expect("the model has an uncertainty") as f32;
    f64::from(sigma_mm) / MM_PER_INCH
}

/// Largest relative difference between the uncertainty pin and the service's: the legs the
/// component sent and those LinuxCNC reports agree to rounding, the `f32` on the wire to 6e-8.
const UNCERTAINTY_TOLERANCE: f64 = 1e-6;

/// The correction the component added in `sample` (inch).
fn applied_correction(sample: &Sample) -> [f64; 6] {
    std::array::from_fn(|j| sample.motor_out[j] - sample.motor_in[j])
}

/// A pose in machine units (inch, degrees), rounded to the 1e-6 the MDI text carries exactly.
fn in_machine_units(pose: &Pose) -> [f64; 6] {
    let pose = pose.to_mm_deg();
    std::array::from_fn(|k| {
        let value = if k < 3 {
            pose[k] / MM_PER_INCH
        } else {
            pose[k]
        };
        (value * 1e6).round() / 1e6
    })
}

/// A pose in machine units (inch, degrees) in hexacomp's (mm, degrees).
fn to_mm_deg(pose: &[f64; 6]) -> [f64; 6] {
    std::array::from_fn(|k| {
        if k < 3 {
            pose[k] * MM_PER_INCH
        } else {
            pose[k]
        }
    })
}

fn max_difference(a: [f64; 6], b: [f64; 6]) -> f64 {
    (0..6).map(|j| (a[j] - b[j]).abs()).fold(0.0, f64::max)
}

/// Samples after homing with the correction fully applied.
fn compensating(samples: &[Sample]) -> Vec<Sample> {
    samples
        .iter()
        .filter(|s| s.blend == 1.0 && s.legs.iter().all(|&q| q > 20.0))
        .copied()
        .collect()
}

/// Largest difference between a correction the component added and the one it should have, in:
/// the rounding of `motor_in + correction`, far below the corrections (1e-3 in).
const CORRECTION_TOLERANCE_IN: f64 = 1e-12;

/// The value of `key = value` or `setp key value` in the configuration file `name`.
fn setting(sim: &SimConfig, name: &str, key: &str) -> f64 {
    let text = std::fs::read_to_string(sim.path(name)).expect("a configuration file");
    text.lines()
        .find_map(|line| {
            let line = line.trim();
            let rest = line.strip_prefix(key)?;
            rest.trim_start_matches([' ', '=']).parse().ok()
        })
        .unwrap_or_else(|| panic!("{name} sets no {key}"))
}

/// The largest change of the applied correction per servo period the configuration allows, in:
/// the component's `max-rate` (mm/s) times the servo period.
fn ramp_step(sim: &SimConfig) -> f64 {
    let rate_mm_s = setting(sim, "hexacomp.hal", "setp hexacomp.0.max-rate");
    let period_s = setting(sim, "hexapod-hexacomp.ini", "SERVO_PERIOD") * 1e-9;
    rate_mm_s * period_s / MM_PER_INCH
}

/// What [`check_periods`] saw.
struct PeriodCheck {
    /// Periods faulted (no good answer in time).
    faults: usize,
    /// Periods in which compensation was not used (`enable` 0 or not homed).
    unused: usize,
    /// Periods in which the correction's change was limited to the ramp step.
    ramped: Vec<usize>,
    /// Ramps that began right after an answered period that needed none (a new model's answer,
    /// or a correction changing faster than the ramp along a path); the others began after a
    /// fault, when the legs had moved on under a held correction.
    ramps_after_an_answer: Vec<usize>,
    /// Largest change of the applied correction from one period to the next, in.
    largest_change: f64,
    /// Largest |added − the component's law| over the periods checked, in.
    worst: f64,
    /// Largest service correction, in.
    largest_correction: f64,
}

/// Replays the component's law over `periods` (consecutive servo periods) from the first
/// answered one on, and checks every period against it: while compensation is used (`blend`
/// rising or 1; `enable` and `homed` are not sampled, the blend's ramp tells) and not faulted,
/// the held correction is the service's for that period's legs from the model of the sampled
/// generation (`models`); otherwise it is the previous one (zero once unused with blend 0), and
/// an unused period is no fault.
/// The correction added is the previous period's moved towards blend × held by at most `step`.
/// Faulted periods before the first answered one (nothing to compare them with) are counted.
/// Unused periods are never faults, before it as after.
fn check_periods(
    sim: &SimConfig,
    models: &BTreeMap<u64, &Model>,
    periods: &[Sample],
    step: f64,
) -> PeriodCheck {
    let used =
        |i: usize| periods[i].blend == 1.0 || (i > 0 && periods[i].blend > periods[i - 1].blend);
    let first_answered = (0..periods.len())
        .find(|&i| used(i) && !periods[i].fault)
        .expect("no period was answered");
    let mut check = PeriodCheck {
        faults: periods[..first_answered].iter().filter(|s| s.fault).count(),
        unused: 0,
        ramped: Vec::new(),
        ramps_after_an_answer: Vec::new(),
        largest_change: 0.0,
        worst: 0.0,
        largest_correction: 0.0,
    };
    let model = |sample: &Sample| -> &Model {
        models
            .get(&sample.generation)
            .unwrap_or_else(|| panic!("no model of generation {}", sample.generation))
    };
    let mut held = service_correction(
        sim,
        model(&periods[first_answered]),
        &periods[first_answered],
    );
    let unused_fault = (1..=first_answered).find(|&i| !used(i) && periods[i].fault);
    assert_eq!(unused_fault, None, "a fault while not in use");
    for i in first_answered + 1..periods.len() {
        let (before, sample) = (&periods[i - 1], &periods[i]);
        if !used(i) {
            check.unused += 1;
            assert!(
                !sample.fault,
                "period {i}: a fault while not in use: {sample:?}"
            );
            if sample.blend == 0.0 {
                // Ramped out and not used: the component forgets what it held.
                held = [0.0; 6];
            }
        } else if sample.fault {
            check.faults += 1;
        } else {
            held = service_correction(sim, model(sample), sample);
            check.largest_correction = (held.iter())
                .map(|c| c.abs())
                .fold(check.largest_correction, f64::max);
        }
        let previous = applied_correction(before);
        let added = applied_correction(sample);
        let mut limited = false;
        let law: [f64; 6] = std::array::from_fn(|j| {
            let change = sample.blend * held[j] - previous[j];
            limited |= change.abs() > step + CORRECTION_TOLERANCE_IN;
            previous[j] + change.clamp(-step, step)
        });
        if limited {
            let ramp_began = check.ramped.last() != Some(&(i - 1));
            if ramp_began && !before.fault {
                check.ramps_after_an_answer.push(i);
            }
            check.ramped.push(i);
        }
        let difference = max_difference(added, law);
        check.worst = check.worst.max(difference);
        check.largest_change = check.largest_change.max(max_difference(added, previous));
        assert!(
            difference <= CORRECTION_TOLERANCE_IN,
            "period {i}, legs {:?}: added {added:?}, the law gives {law:?} (held {held:?}, \
             previous {previous:?})",
            sample.legs
        );
    }
    assert!(
        check.largest_change <= step + CORRECTION_TOLERANCE_IN,
        "a step of {} in, the ramp allows {step} in",
        check.largest_change
    );
    check
}

/// Periods in which the legs moved.
fn moving_periods(periods: &[Sample]) -> usize {
    periods
        .windows(2)
        .filter(|w| w[0].legs != w[1].legs)
        .count()
}

#[test]
fn linuxcnc_joints_equal_hexacomp_inverse_kinematics_for_mdi_poses() {
    if !linuxcnc_available("mdi_inverse_kinematics") {
        return;
    }
    let _guard = one_at_a_time();
    // Fast moves: this test is about kinematics, not the machine's dynamics.
    let sim = SimConfig::prepare("ik", fast_moves);
    let mut sampler =
        WorkspaceSampler::new(&sim.geometry, 8, SamplerOptions::default()).expect("sampler");
    // Machine units (inch, degrees), rounded to the 1e-6 the MDI text carries exactly.
    // Only poses inside the model's trained range: elsewhere the component faults and
    // feed-inhibit stops the machine, as it should.
    let trained = |pose: &[f64; 6]| {
        let legs = inverse_kinematics(&sim.geometry, &Pose::from_mm_deg(to_mm_deg(pose))).lengths;
        (0..6).all(|i| {
            (sim.model.training_range[i][0]..=sim.model.training_range[i][1]).contains(&legs[i])
        })
    };
    let poses: Vec<[f64; 6]> =
        std::iter::repeat_with(|| in_machine_units(&sampler.sample().expect("a workspace pose")))
            .filter(trained)
            .take(300)
            .collect();
    let _service = sim.start_service("service.log");
    let results = sim.start_linuxcnc(json!({ "mdi": poses })).finish(SESSION);

    let recorded = results["mdi"].as_array().expect("mdi results");
    assert_eq!(recorded.len(), poses.len());
    let mut worst = 0.0f64;
    let mut uncertainties = Vec::new();
    for (pose, record) in poses.iter().zip(recorded) {
        let joints: Vec<f64> = serde_json::from_value(record["joints"].clone()).expect("joints");
        let pin = record["uncertainty"].as_f64().expect("the uncertainty pin");
        let expected = service_uncertainty(&sim, &joints);
        assert!(
            (pin - expected).abs() <= UNCERTAINTY_TOLERANCE * expected,
            "pose {pose:?}: uncertainty pin {pin} in, the service's {expected} in"
        );
        uncertainties.push(pin);
        let nominal = inverse_kinematics(&sim.geometry, &Pose::from_mm_deg(to_mm_deg(pose)));
        for (leg, &joint) in joints.iter().enumerate() {
            let length = nominal.lengths[leg];
            let relative = (joint * MM_PER_INCH - length).abs() / length;
            worst = worst.max(relative);
            assert!(
                relative <= 1e-9,
                "pose {pose:?}: LinuxCNC leg {leg} {joint} in, hexacomp {} in ({relative:.2e})",
                length / MM_PER_INCH
            );
        }
    }
    assert!(
        results["errors"].as_array().is_some_and(|e| e.is_empty()),
        "{results}"
    );
    // The pin follows the legs: a pin stuck at one value (or at 0) would not tell where the
    // model extrapolates.
    let (least, most) = uncertainties
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(l, m), &u| (l.min(u), m.max(u)));
    assert!(
        least > 0.0 && most > 1.1 * least,
        "uncertainty pin from {least} to {most} in over {} poses",
        poses.len()
    );
    eprintln!(
        "{} MDI poses: largest |LinuxCNC − hexacomp| / leg length {worst:.2e}; uncertainty pin \
         {least:.2e} to {most:.2e} in, the service's for the legs",
        poses.len()
    );
}

/// Runs the demo program with the sampler recording; `during` runs once the program started.
fn run_demo(
    test: &str,
    during: impl FnOnce(&SimConfig, SimService),
) -> (SimConfig, serde_json::Value, Vec<Sample>) {
    let sim = SimConfig::prepare(test, SimConfig::add_sampler);
    let service = sim.start_service("service.log");
    let plan = json!({
        "program": sim.path("demo.ngc"),
        "started": sim.path("started"),
        "sampler": {"channel": 0, "cfg": hexacomp_tests::linuxcnc::SAMPLER_CFG,
                    "out": sim.path("samples.txt")},
    });
    let mut run = sim.start_linuxcnc(plan);
    let deadline = std::time::Instant::now() + Duration::from_secs(120);
    while !sim.path("started").exists() {
        assert!(
            std::time::Instant::now() < deadline,
            "the program did not start"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    during(&sim, service);
    let results = run.finish(SESSION);
    let samples = read_samples(&sim.path("samples.txt"));
    assert!(
        results["program"].is_object(),
        "the program did not end: {results}"
    );
    assert_eq!(results["sampler_overruns"], json!(0), "samples were lost");
    (sim, results, samples)
}

#[test]
fn a_program_runs_with_the_component_adding_the_services_corrections() {
    if !linuxcnc_available("program_in_the_loop") {
        return;
    }
    let _guard = one_at_a_time();
    let mut service = None;
    let (sim, results, samples) = run_demo("loop", |_, child| service = Some(child));
    let compensating = compensating(&samples);
    assert!(
        compensating.len() > 3000,
        "{} compensated periods",
        compensating.len()
    );
    let check = check_periods(
        &sim,
        &BTreeMap::from([(1, &sim.model)]),
        &compensating,
        ramp_step(&sim),
    );
    let PeriodCheck {
        faults,
        worst,
        largest_correction,
        ..
    } = check;
    // Along the path the corrections change far slower than the ramp: followed exactly, a
    // ramp only after a fault (the legs moved on under the held correction).
    assert_eq!(
        check.ramps_after_an_answer, [0usize; 0],
        "ramps along the path"
    );
    // No fault where LinuxCNC runs realtime. Without PREEMPT_RT its servo thread is an ordinary
    // thread sharing the cores, and a period misses its 900 µs wait as often as the machine is
    // busy (8.5 % of the periods with a load average of 6 on 2 cores, 58 % beside a release
    // build and the load tests' CPU burners): how often is then a matter of the machine, not of
    // the code, and only the handling of each fault (checked above: the correction is held)
    // decides; feed-inhibit makes the program take longer, not go wrong. What must have happened
    // is the comparison itself: thousands of periods, and at least a quarter of them, answered
    // and checked against the service's numbers.
    let realtime = realtime_kernel();
    let answered = compensating.len() - faults;
    eprintln!(
        "{faults} of {} periods faulted (realtime kernel: {realtime})",
        compensating.len()
    );
    if realtime {
        assert_eq!(faults, 0, "faulted periods on a realtime kernel");
    }
    assert!(
        answered >= 2000 && answered >= compensating.len() / 4,
        "only {answered} of {} periods were answered and compared",
        compensating.len()
    );
    let moved = moving_periods(&compensating);
    assert!(moved > 2000, "the legs moved in only {moved} periods");
    assert!(
        results["errors"].as_array().is_some_and(|e| e.is_empty()),
        "{results}"
    );
    let last = samples.last().expect("samples");
    eprintln!(
        "{} compensated periods ({moved} moving), largest correction {largest_correction:.6} in, \
         largest |applied − the component's law| {worst:.1e} in, {faults} periods faulted \
         (timeouts, correction held), {} in the whole run, homing included; {} periods ramped \
         (after faults), largest change in one period {:.2e} in (ramp step {:.2e} in); program \
         {:.1} s",
        compensating.len(),
        last.fault_count,
        check.ramped.len(),
        check.largest_change,
        ramp_step(&sim),
        results["program"]["seconds"].as_f64().unwrap_or_default()
    );
    drop(service);
}

#[test]
fn killing_the_service_mid_program_faults_holds_and_recovers() {
    if !linuxcnc_available("service_killed") {
        return;
    }
    let _guard = one_at_a_time();
    let mut restarted = None;
    let (sim, results, samples) = run_demo("kill", |sim, service| {
        std::thread::sleep(Duration::from_millis(1500));
        service.kill();
        std::thread::sleep(Duration::from_millis(2000));
        restarted = Some(sim.start_service("service-2.log"));
    });
    // The longest run of faulted periods after homing: the outage.
    let compensating = compensating(&samples);
    let mut longest = (0, 0);
    let mut start = None;
    for (i, sample) in compensating.iter().enumerate() {
        match (sample.fault, start) {
            (true, None) => start = Some(i),
            (false, Some(s)) => {
                if i - s > longest.1 - longest.0 {
                    longest = (s, i);
                }
                start = None;
            }
            _ => {}
        }
    }
    let (first, end) = longest;
    assert!(
        end - first >= 1500,
        "outage of {} periods (the service was down 2 s)",
        end - first
    );
    let before = compensating[first - 1];
    assert!(!before.fault);
    let held = applied_correction(&before);
    for sample in &compensating[first..end] {
        // The last good correction, held.
        assert!(
            max_difference(applied_correction(sample), held) <= CORRECTION_TOLERANCE_IN,
            "{sample:?}"
        );
    }
    // feed-inhibit stopped the machine: the legs stand still for the rest of the outage.
    let stopped = first + 500;
    for sample in &compensating[stopped..end] {
        assert_eq!(
            sample.legs, compensating[stopped].legs,
            "the machine moved while faulted"
        );
    }
    // Recovered: the service's corrections again, the program ran to its end.
    // The restarted service serves model.hxm again, as generation 2 (its --model).
    check_periods(
        &sim,
        &BTreeMap::from([(1, &sim.model), (2, &sim.model)]),
        &compensating[end - 1..],
        ramp_step(&sim),
    );
    let moved_after = moving_periods(&compensating[end..]);
    assert!(
        moved_after > 500,
        "the machine moved {moved_after} periods after recovery"
    );
    eprintln!(
        "outage {} periods: correction held, legs still from period {} of it on; {} periods moving \
         after recovery; program {:.1} s",
        end - first,
        stopped - first,
        moved_after,
        results["program"]["seconds"].as_f64().unwrap_or_default()
    );
    drop(restarted);
}

#[test]
fn a_restart_into_another_model_and_a_deploy_ramp_in_and_enable_0_is_no_fault() {
    if !linuxcnc_available("ramps") {
        return;
    }
    let _guard = one_at_a_time();
    let mut services = Vec::new();
    let mut models = Vec::new();
    let (sim, results, samples) = run_demo("ramps", |sim, first| {
        // Two more models for the same machine, different corrections (as a recalibration
        // gives), and the trainer to deploy one, where the LinuxCNC user can run them.
        for (seed, name) in [(41, "model-b.hxm"), (42, "model-c.hxm")] {
            let model = smooth_model_for(&sim.geometry, seed);
            model.save(&sim.path(name)).expect("saving a model");
            models.push(model);
        }
        std::fs::copy(binary("hexacomp-trainer"), sim.path("hexacomp-trainer")).unwrap();
        // Generation 1 serves; the service dies and comes back with model b (generation 2).
        std::thread::sleep(Duration::from_millis(1500));
        first.kill();
        std::thread::sleep(Duration::from_millis(1000));
        services.push(sim.start_service_with_model("service-2.log", "model-b.hxm"));
        // Model c deployed to the running service (generation 3).
        std::thread::sleep(Duration::from_millis(2000));
        let deploy = sim.run(
            sim.path("hexacomp-trainer"),
            &[
                "deploy",
                "--geometry",
                "geometry.toml",
                "--model",
                "model-c.hxm",
            ],
        );
        assert!(
            deploy.status.success()
                && String::from_utf8_lossy(&deploy.stdout).contains("generation 3"),
            "deploy: {}{}",
            String::from_utf8_lossy(&deploy.stdout),
            String::from_utf8_lossy(&deploy.stderr)
        );
        // Compensation switched off, then the service gone: not used is no fault, the machine
        // runs on with the correction ramping out.
        std::thread::sleep(Duration::from_millis(2000));
        let setp = sim.run("halcmd", &["setp", "hexacomp.0.enable", "0"]);
        assert!(setp.status.success(), "halcmd: {setp:?}");
        std::thread::sleep(Duration::from_millis(300));
        services.pop().expect("the second service").kill();
    });
    assert!(
        results["errors"].as_array().is_some_and(|e| e.is_empty()),
        "{results}"
    );
    let served = BTreeMap::from([(1, &sim.model), (2, &models[0]), (3, &models[1])]);
    let step = ramp_step(&sim);
    let homed = samples
        .iter()
        .position(|s| s.blend > 0.0)
        .expect("compensation was used");
    let check = check_periods(&sim, &served, &samples[homed..], step);
    // The scenario happened: each new model's corrections ramped in over several periods (the
    // models differ by far more than one step), and compensation was switched off while the
    // program ran.
    let began = |generation: u64| {
        homed
            + samples[homed..]
                .iter()
                .position(|s| s.generation == generation)
                .unwrap_or_else(|| panic!("generation {generation} never served"))
    };
    for generation in [2, 3] {
        let first = began(generation) - homed;
        assert!(
            check.ramped.contains(&first),
            "generation {generation}: its first answer (period {first}) was not ramped in"
        );
        let ramp = check
            .ramped
            .iter()
            .filter(|&&i| (first..first + 1000).contains(&i));
        assert!(
            ramp.count() >= 10,
            "generation {generation}: no ramp after its first answer (period {first})"
        );
    }
    assert!(check.unused >= 100, "enable 0 for {} periods", check.unused);
    let off = homed
        + samples[homed..]
            .iter()
            .position(|s| s.blend < 1.0 && s.generation == 3)
            .unwrap();
    let last = samples.last().unwrap();
    assert_eq!(
        last.fault_count, samples[off].fault_count,
        "faults counted while not in use"
    );
    assert!(
        moving_periods(&samples[off..]) > 500,
        "the machine did not run on with compensation off and no service"
    );
    eprintln!(
        "{} periods checked against the component's law: {} ramped (largest change {:.3e} in per \
         period, the ramp allows {step:.3e} in), {} faulted, {} not in use (no fault), largest \
         correction {:.6} in; program {:.1} s",
        samples.len() - homed,
        check.ramped.len(),
        check.largest_change,
        check.faults,
        check.unused,
        check.largest_correction,
        results["program"]["seconds"].as_f64().unwrap_or_default()
    );
}

#[test]
fn while_connecting_hangs_the_servo_thread_runs_on_and_picks_up_the_connection_later() {
    if !linuxcnc_available("connect") {
        return;
    }
    let _guard = one_at_a_time();
    let sim = SimConfig::prepare("connect", |ini| ini);
    // A connection attempt that hangs: a stopped service (SIGSTOP, as a debugger or a frozen
    // process leaves it) still has its endpoints, and connecting waits for a status answer that
    // does not come, as long as the connection's deadline. Done in the servo thread, with wait-us
    // as that deadline, a 60 s wait-us would stop the servo thread for a minute: impossible to
    // miss.
    let hal = sim.path("hexacomp.hal");
    let wiring = std::fs::read_to_string(&hal).unwrap();
    let line = wiring
        .lines()
        .find(|l| l.starts_with("setp hexacomp.0.wait-us "))
        .expect("the wait-us line")
        .to_string();
    std::fs::write(
        &hal,
        wiring.replace(&line, "setp hexacomp.0.wait-us 60000000"),
    )
    .unwrap();
    let service = sim.start_service("service.log");
    service.pause();
    let mut run = sim.start_linuxcnc(json!({
        "without_service": {"seconds": 5, "measured": sim.path("measured"),
                            "restarted": sim.path("restarted")},
    }));
    let deadline = std::time::Instant::now() + Duration::from_secs(180);
    while !sim.path("measured").exists() && !run.ended() {
        assert!(std::time::Instant::now() < deadline, "no measurement");
        std::thread::sleep(Duration::from_millis(20));
    }
    service.resume();
    std::fs::write(sim.path("restarted"), "").unwrap();
    let results = run.finish(SESSION);
    assert!(results["failure"].is_null(), "{results}");
    let report = &results["without_service"];
    // HEXACOMP_ERROR_TIMEOUT: the helper's attempts did hang on the stopped service (an absent
    // service, code 3, would fail at once and prove nothing).
    assert_eq!(report["last_error"], json!(4), "{results}");
    let seconds = report["seconds"].as_f64().unwrap();
    let faulted = report["faulted"].as_f64().unwrap();
    // A 1 ms servo thread that ran on faults in (nearly) every period; one stopped by a hanging
    // connection would fault in at most the first second's.
    assert!(
        faulted >= 0.5 * seconds * 1000.0,
        "the component faulted in {faulted} periods in {seconds:.1} s: the servo thread stalled"
    );
    eprintln!(
        "no service: {faulted} periods faulted in {seconds:.2} s (last error: timeout); \
         connected {:.2} s after the service was continued",
        report["connected_after"].as_f64().unwrap_or(f64::NAN)
    );
    drop(service);
}

/// A LinuxCNC session held up by drive.py until `done` exists: created when the session is
/// dropped (a failing test included), which then waits for LinuxCNC to shut down cleanly.
struct HeldSession {
    run: hexacomp_tests::linuxcnc::LinuxCncRun,
    done: std::path::PathBuf,
}

impl Drop for HeldSession {
    fn drop(&mut self) {
        let _ = std::fs::write(&self.done, "");
        let deadline = std::time::Instant::now() + Duration::from_secs(60);
        while !self.run.ended() && std::time::Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

/// Waits until `path` exists, or panics after `seconds` with LinuxCNC's logs.
fn wait_for_file(
    path: &std::path::Path,
    seconds: u64,
    linuxcnc: &mut hexacomp_tests::linuxcnc::LinuxCncRun,
) {
    let deadline = std::time::Instant::now() + Duration::from_secs(seconds);
    while !path.exists() {
        if linuxcnc.ended() || std::time::Instant::now() > deadline {
            let results = linuxcnc.finish(Duration::from_secs(5));
            panic!("{} never appeared: {results}", path.display());
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// The data rows of a CSV file (header and comments left out), whole lines only.
fn data_rows(path: &std::path::Path) -> usize {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let whole = text.rfind('\n').map_or("", |end| &text[..end]);
    whole
        .lines()
        .skip(1)
        .filter(|l| !l.starts_with('#'))
        .count()
}

#[test]
fn a_campaign_through_linuxcnc_killed_and_resumed_calibrates_and_verify_shows_ap_ten_times_better()
{
    if !linuxcnc_available("campaign") {
        return;
    }
    let _guard = one_at_a_time();
    let sim = SimConfig::prepare("campaign", fast_moves);
    // Compensation off while the machine is measured, as on a real machine.
    let hal = sim.path("hexacomp.hal");
    let wiring = std::fs::read_to_string(&hal).unwrap();
    std::fs::write(
        &hal,
        wiring.replace("setp hexacomp.0.enable 1", "setp hexacomp.0.enable 0"),
    )
    .unwrap();
    std::fs::copy(binary("hexacomp-trainer"), sim.path("hexacomp-trainer")).unwrap();
    let trainer = |args: &[&str]| {
        let output = sim.run(
            sim.path("hexacomp-trainer"),
            &[&["--geometry", "geometry.toml"][..], args].concat(),
        );
        (
            output.status.success(),
            format!(
                "{}{}",
                String::from_utf8_lossy(&output.stdout),
                String::from_utf8_lossy(&output.stderr)
            ),
        )
    };
    let ok = |args: &[&str]| {
        let (success, said) = trainer(args);
        assert!(success, "{args:?}: {said}");
        said
    };
    ok(&["plan", "--count", "80", "--out", "plan.csv"]);
    let campaign = [
        "campaign",
        "--plan",
        "plan.csv",
        "--out",
        "campaign.csv",
        "--machine",
        "linuxcnc",
        "--readings",
        "2",
    ];
    // LinuxCNC not running: a clear message, no record.
    let (success, said) = trainer(&campaign);
    assert!(
        !success && said.contains("LinuxCNC is not running"),
        "{said}"
    );
    assert!(!sim.path("campaign.csv").exists());

    let _service = sim.start_service("service.log");
    let mut session = HeldSession {
        run: sim.start_linuxcnc(json!({
            "unhomed": {"ready": sim.path("on"), "go": sim.path("home")},
            "hold": {"ready": sim.path("ready"), "done": sim.path("done")},
        })),
        done: sim.path("done"),
    };
    wait_for_file(&sim.path("on"), 120, &mut session.run);
    let (success, said) = trainer(&campaign);
    assert!(!success && said.contains("not homed"), "{said}");
    assert!(!sim.path("campaign.csv").exists());
    std::fs::write(sim.path("home"), "").unwrap();
    wait_for_file(&sim.path("ready"), 120, &mut session.run);

    // Killed once a few configurations are on disk, then run again to the end.
    let mut child = sim.spawn(
        sim.path("hexacomp-trainer"),
        &[&["--geometry", "geometry.toml"][..], &campaign].concat(),
        "killed-campaign.err",
    );
    let deadline = std::time::Instant::now() + Duration::from_secs(120);
    while data_rows(&sim.path("campaign.csv")) < 5 {
        assert!(std::time::Instant::now() < deadline, "no rows recorded");
        assert!(
            child.try_wait().unwrap().is_none(),
            "the campaign ended early: {}",
            std::fs::read_to_string(sim.path("killed-campaign.err")).unwrap_or_default()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    hexacomp_tests::signal_child(&child, libc::SIGKILL);
    child.wait().unwrap();
    let at_kill = data_rows(&sim.path("campaign.csv"));
    assert!((5..80).contains(&at_kill), "{at_kill} rows at the kill");
    let said = ok(&campaign);
    assert!(
        said.contains(&format!("{} of 80 configurations to measure", 80 - at_kill)),
        "{said}"
    );
    let rows = hexacomp_formats::read_measurements(&sim.path("campaign.csv")).unwrap();
    assert_eq!(rows.len(), 80, "every configuration once");

    ok(&[
        "calibrate",
        "--measurements",
        "campaign.csv",
        "--out-dir",
        "cal",
    ]);
    let cycles = ["--cycles", "5", "--readings", "1", "--machine", "linuxcnc"];
    ok(&[&["verify", "--out", "before.csv"][..], &cycles].concat());
    let deploy = ok(&["deploy", "--model", "cal/model.hxm"]);
    assert!(deploy.contains("generation 2"), "{deploy}");
    let setp = sim.run("halcmd", &["setp", "hexacomp.0.enable", "1"]);
    assert!(setp.status.success(), "halcmd: {setp:?}");
    let said = ok(&[
        &["verify", "--out", "after.csv", "--before", "before.json"][..],
        &cycles,
    ]
    .concat());
    std::fs::write(sim.path("done"), "").unwrap();
    let results = session.run.finish(SESSION);
    let report = |name: &str| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(sim.path(name)).unwrap()).unwrap()
    };
    let (before, after) = (report("before.json"), report("after.json"));
    let worst = |r: &serde_json::Value, key: &str| {
        r["poses"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| p[key].as_f64().unwrap())
            .fold(0.0, f64::max)
    };
    let (ap_before, ap_after) = (worst(&before, "ap_p_mm"), worst(&after, "ap_p_mm"));
    eprintln!("{said}");
    assert!(
        ap_before >= 10.0 * ap_after,
        "worst AP_P {ap_before} mm before, {ap_after} mm after"
    );
    assert!(
        worst(&after, "rp_l_mm") <= 1.3 * worst(&before, "rp_l_mm"),
        "RP_l {} after, {} before",
        worst(&after, "rp_l_mm"),
        worst(&before, "rp_l_mm")
    );
    assert!(
        results["errors"].as_array().is_some_and(|e| e.is_empty()),
        "{results}"
    );
}

/// The ini `text` with the joints' settings the export lists (`#   [JOINT_N] offset …: KEY = V,
/// …`) put in their sections.
fn with_moved_joints(text: &str, export: &str) -> String {
    let mut settings: BTreeMap<(String, String), String> = BTreeMap::new();
    for line in export.lines().filter(|l| l.starts_with("#   [JOINT_")) {
        let section = line[line.find('[').unwrap() + 1..line.find(']').unwrap()].to_string();
        let (_, list) = line.split_once(": ").unwrap();
        for item in list.split(", ") {
            let (key, value) = item.split_once(" = ").unwrap();
            settings.insert((section.clone(), key.to_string()), value.to_string());
        }
    }
    let mut section = String::new();
    text.lines()
        .map(|line| {
            let trimmed = line.trim();
            if let Some(name) = trimmed.strip_prefix('[').and_then(|l| l.strip_suffix(']')) {
                section = name.to_string();
            }
            match trimmed.split_once('=') {
                Some((key, _)) => settings
                    .get(&(section.clone(), key.trim().to_string()))
                    .map_or(line.to_string(), |v| format!("{} = {v}", key.trim())),
                None => line.to_string(),
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
        + "\n"
}

#[test]
fn an_exported_identified_geometry_gives_linuxcncs_inverse_and_forward_kinematics() {
    if !linuxcnc_available("export") {
        return;
    }
    let _guard = one_at_a_time();
    let sim = SimConfig::prepare("export", fast_moves);
    // An identified geometry: the configuration's joints moved by up to a millimetre, leg
    // offsets as identify finds them.
    let mut identified = sim.geometry.clone();
    for leg in 0..6 {
        let k = leg as f64;
        identified.base_joints[leg] += glam::DVec3::new(0.3 * k - 0.7, -0.2 + 0.11 * k, 0.05 * k);
        identified.platform_joints[leg] += glam::DVec3::new(-0.1 * k, 0.4 - 0.13 * k, 0.2);
    }
    identified.leg_offsets = [0.5, -0.25, 0.125, 0.0, 0.0625, -1.0];
    identified.save(&sim.path("identified.toml")).unwrap();
    std::fs::copy(binary("hexacomp-trainer"), sim.path("hexacomp-trainer")).unwrap();
    let export = sim.run(
        sim.path("hexacomp-trainer"),
        &[
            "--geometry",
            "identified.toml",
            "export",
            "--linuxcnc",
            "hexapod-hexacomp.ini",
            "--out",
            "identified.hal",
        ],
    );
    assert!(export.status.success(), "{export:?}");
    // Put it in as the export says: the HAL file's genhexkins lines, the joints' settings.
    let hal = std::fs::read_to_string(sim.path("identified.hal")).unwrap();
    std::fs::write(sim.path("kinematics.hal"), &hal).unwrap();
    let ini = std::fs::read_to_string(sim.path("hexapod-hexacomp.ini")).unwrap();
    // The joints' home offsets before: the encoder lengths at the home switches (inch).
    let home_offsets: Vec<f64> = ini
        .lines()
        .filter_map(|l| l.trim().strip_prefix("HOME_OFFSET"))
        .map(|v| v.trim_start_matches([' ', '=']).trim().parse().unwrap())
        .collect();
    assert_eq!(home_offsets.len(), 6);
    let moved = with_moved_joints(&ini, &hal);
    assert_ne!(moved, ini, "no joint settings moved");
    std::fs::write(sim.path("hexapod-hexacomp.ini"), moved).unwrap();
    // Compensation off: this test is about the kinematics.
    let wiring = std::fs::read_to_string(sim.path("hexacomp.hal")).unwrap();
    std::fs::write(
        sim.path("hexacomp.hal"),
        wiring.replace("setp hexacomp.0.enable 1", "setp hexacomp.0.enable 0"),
    )
    .unwrap();

    let mut sampler =
        WorkspaceSampler::new(&identified, 5, SamplerOptions::default()).expect("sampler");
    let poses: Vec<[f64; 6]> = (0..20)
        .map(|_| in_machine_units(&sampler.sample().expect("a workspace pose")))
        .collect();
    let results = sim.start_linuxcnc(json!({ "mdi": poses })).finish(SESSION);
    // Inverse: LinuxCNC's joints are the real leg lengths, hexacomp's commanded ones plus the
    // offsets; and the motors (their zero at the home switch, where the encoder read the home
    // offset of before) are commanded hexacomp's commanded lengths.
    let mut worst_inverse = 0.0f64;
    for record in results["mdi"].as_array().expect("mdi results") {
        let pose: [f64; 6] = serde_json::from_value(record["pose"].clone()).unwrap();
        let joints: [f64; 6] = serde_json::from_value(record["joints"].clone()).unwrap();
        let motors: [f64; 6] = serde_json::from_value(record["motors"].clone()).unwrap();
        let legs = inverse_kinematics(&identified, &Pose::from_mm_deg(to_mm_deg(&pose))).lengths;
        for leg in 0..6 {
            let encoder = (motors[leg] + home_offsets[leg]) * MM_PER_INCH;
            worst_inverse = worst_inverse.max((encoder - legs[leg]).abs());
            let difference =
                (joints[leg] * MM_PER_INCH - (legs[leg] + identified.leg_offsets[leg])).abs();
            worst_inverse = worst_inverse.max(difference);
        }
    }
    assert!(
        worst_inverse < 1e-6,
        "inverse kinematics differ by {worst_inverse} mm"
    );
    // Forward: the pose LinuxCNC's forward kinematics gave for the joints at home is the one
    // hexacomp's gives for the same legs.
    let joints: [f64; 6] = serde_json::from_value(results["homed_joints"].clone()).unwrap();
    let homed: [f64; 6] = serde_json::from_value(results["homed_position"].clone()).unwrap();
    let encoder: [f64; 6] =
        std::array::from_fn(|leg| joints[leg] * MM_PER_INCH - identified.leg_offsets[leg]);
    let forward = hexacomp_core::forward_kinematics(
        &identified,
        &encoder,
        &identified.home_pose(),
        &hexacomp_core::kinematics::ForwardOptions::default(),
    )
    .expect("forward kinematics")
    .to_mm_deg();
    let homed = to_mm_deg(&homed);
    let worst_forward = (0..6)
        .map(|k| (forward[k] - homed[k]).abs())
        .fold(0.0, f64::max);
    assert!(
        worst_forward < 1e-6,
        "forward kinematics: LinuxCNC {homed:?}, hexacomp {forward:?}"
    );
    eprintln!(
        "exported geometry: inverse kinematics agree to {worst_inverse:.1e} mm over {} poses, \
         forward to {worst_forward:.1e} (mm, degrees) at home",
        poses.len()
    );
}
