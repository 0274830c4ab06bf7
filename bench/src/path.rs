//! Interpolated tool paths inside the task workspace, as an NC interpolator produces them: a
//! shape traversed at a feed rate with a trapezoidal velocity profile (constant acceleration up
//! to the feed, cruise, constant deceleration to rest), sampled once per interpolation period.
//!
//! Poses are `[x, y, z, a, b, c]` in mm and degrees (LinuxCNC's convention), in the base frame,
//! centred on the middle of the geometry's task workspace.

use anyhow::{Context, bail, ensure};
use hexacomp_core::sampling::tilt;
use hexacomp_core::{Geometry, Pose, inverse_kinematics};

/// The shape a path traces.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Shape {
    /// Straight moves back and forth along the xy diagonal, each from rest to rest, as many
    /// whole moves as the duration holds (then a dwell); constant orientation.
    Line,
    /// Circles in the horizontal plane through the workspace centre; constant orientation.
    Circle,
    /// Four turns up and four down (±`height`), the tool tilted by `tilt` towards the centre all
    /// the way round.
    Helix,
    /// A figure-eight (lemniscate of Gerono) in the horizontal plane while the platform rolls
    /// by ±`tilt` and yaws by ±`yaw`.
    FigureEight,
}

impl Shape {
    /// The name used on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Shape::Line => "line",
            Shape::Circle => "circle",
            Shape::Helix => "helix",
            Shape::FigureEight => "figure-eight",
        }
    }
}

/// What to interpolate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathSpec {
    /// The shape.
    pub shape: Shape,
    /// Radius of circle, helix and figure-eight, half-length of the line, mm.
    pub size_mm: f64,
    /// Helix: half of its height, mm.
    pub height_mm: f64,
    /// Helix and figure-eight: tilt of the tool, degrees.
    pub tilt_deg: f64,
    /// Figure-eight: yaw amplitude, degrees.
    pub yaw_deg: f64,
    /// Feed rate along the path, mm/s.
    pub feed_mm_s: f64,
    /// Acceleration and deceleration of the feed, mm/s².
    pub accel_mm_s2: f64,
    /// Time from start to standstill, s.
    pub duration_s: f64,
    /// Interpolation rate, points per second.
    pub rate_hz: f64,
}

impl Default for PathSpec {
    fn default() -> Self {
        Self {
            shape: Shape::Helix,
            size_mm: 40.0,
            height_mm: 20.0,
            tilt_deg: 8.0,
            yaw_deg: 8.0,
            feed_mm_s: 25.0,
            accel_mm_s2: 250.0,
            duration_s: 60.0,
            rate_hz: 1000.0,
        }
    }
}

/// An interpolated path.
#[derive(Debug, Clone, PartialEq)]
pub struct Path {
    /// Poses `[x, y, z, a, b, c]`, mm and degrees, one per interpolation period.
    pub poses: Vec<[f64; 6]>,
    /// Interpolation period, s.
    pub period_s: f64,
}

/// A trapezoidal feed profile over a distance: distance travelled as a function of time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Trapezoid {
    length: f64,
    peak: f64,
    accel: f64,
}

impl Trapezoid {
    /// The profile moving `length` mm from rest to rest with at most `feed` mm/s and `accel`
    /// mm/s²; triangular when the length is too short to reach the feed.
    pub fn new(length: f64, feed: f64, accel: f64) -> Self {
        let peak = feed.min((length * accel).sqrt());
        Self {
            length,
            peak,
            accel,
        }
    }

    /// Time from start to standstill, s.
    pub fn duration(&self) -> f64 {
        if self.length <= 0.0 {
            return 0.0;
        }
        self.length / self.peak + self.peak / self.accel
    }

    /// Distance travelled after `t` seconds, mm (clamped to `[0, length]`).
    pub fn distance_at(&self, t: f64) -> f64 {
        let ramp = self.peak / self.accel;
        let total = self.duration();
        let s = if t <= 0.0 {
            0.0
        } else if t < ramp {
            0.5 * self.accel * t * t
        } else if t < total - ramp {
            0.5 * self.peak * ramp + self.peak * (t - ramp)
        } else if t < total {
            let left = total - t;
            self.length - 0.5 * self.accel * left * left
        } else {
            self.length
        };
        s.clamp(0.0, self.length)
    }
}

impl PathSpec {
    fn validate(&self) -> anyhow::Result<()> {
        let positive = [
            ("size", self.size_mm),
            ("feed", self.feed_mm_s),
            ("acceleration", self.accel_mm_s2),
            ("duration", self.duration_s),
            ("rate", self.rate_hz),
        ];
        for (name, value) in positive {
            ensure!(
                value.is_finite() && value > 0.0,
                "the path's {name} must be a positive number, not {value}"
            );
        }
        for (name, value) in [
            ("height", self.height_mm),
            ("tilt", self.tilt_deg),
            ("yaw", self.yaw_deg),
        ] {
            ensure!(
                value.is_finite() && value >= 0.0,
                "the path's {name} must be ≥ 0, not {value}"
            );
        }
        ensure!(
            self.duration_s * self.rate_hz <= 1e8,
            "{} s at {} Hz is more than 10⁸ points",
            self.duration_s,
            self.rate_hz
        );
        Ok(())
    }

    /// The pose at phase `u` of one lap (`u` in `[0, 1]`), relative to the workspace centre:
    /// `[x, y, z, a, b, c]`, mm and degrees.
    fn lap_pose(&self, u: f64) -> [f64; 6] {
        use std::f64::consts::TAU;
        let r = self.size_mm;
        match self.shape {
            Shape::Line => {
                let s = r * (2.0 * u - 1.0) / std::f64::consts::SQRT_2;
                [s, s, 0.0, 0.0, 0.0, 0.0]
            }
            Shape::Circle => {
                let phi = TAU * u;
                [r * phi.cos(), r * phi.sin(), 0.0, 0.0, 0.0, 0.0]
            }
            Shape::Helix => {
                let phi = TAU * 4.0 * (2.0 * u);
                let up = 1.0 - (2.0 * u - 1.0).abs();
                [
                    r * phi.cos(),
                    r * phi.sin(),
                    self.height_mm * (2.0 * up - 1.0),
                    // Tilted towards the centre: rotation about the tangent.
                    -self.tilt_deg * phi.sin(),
                    self.tilt_deg * phi.cos(),
                    0.0,
                ]
            }
            Shape::FigureEight => {
                let phi = TAU * u;
                [
                    r * phi.sin(),
                    r * phi.sin() * phi.cos(),
                    0.0,
                    self.tilt_deg * (2.0 * phi).sin(),
                    0.0,
                    self.yaw_deg * phi.sin(),
                ]
            }
        }
    }

    /// Cumulative position arc length over one lap at `SAMPLES + 1` equally spaced phases, mm.
    fn lap_arc_lengths(&self) -> Vec<f64> {
        const SAMPLES: usize = 8192;
        let mut lengths = Vec::with_capacity(SAMPLES + 1);
        let mut total = 0.0;
        let mut previous = self.lap_pose(0.0);
        lengths.push(0.0);
        for k in 1..=SAMPLES {
            let pose = self.lap_pose(k as f64 / SAMPLES as f64);
            total += ((pose[0] - previous[0]).powi(2)
                + (pose[1] - previous[1]).powi(2)
                + (pose[2] - previous[2]).powi(2))
            .sqrt();
            lengths.push(total);
            previous = pose;
        }
        lengths
    }
}

/// The lap phase at which the arc length reaches `s` (linear between the tabulated phases).
fn phase_at(arc: &[f64], s: f64) -> f64 {
    let samples = arc.len() - 1;
    let k = arc.partition_point(|&v| v < s).clamp(1, samples);
    let (a, b) = (arc[k - 1], arc[k]);
    let within = if b > a { (s - a) / (b - a) } else { 0.0 };
    ((k - 1) as f64 + within.clamp(0.0, 1.0)) / samples as f64
}

/// Interpolates `spec` around the centre of `geometry`'s task workspace and checks that every
/// pose is reachable (all legs within their stroke) and within the workspace's tilt.
pub fn interpolate(geometry: &Geometry, spec: &PathSpec) -> anyhow::Result<Path> {
    spec.validate()?;
    let workspace = &geometry.workspace;
    let centre = [
        0.0,
        0.0,
        0.5 * (workspace.z_range[0] + workspace.z_range[1]),
        0.0,
        0.0,
        0.5 * (workspace.yaw_range[0] + workspace.yaw_range[1]),
    ];
    let period = 1.0 / spec.rate_hz;
    let count = (spec.duration_s * spec.rate_hz).round() as usize + 1;
    let arc = spec.lap_arc_lengths();
    let lap_length = *arc.last().expect("tabulated");
    let mut poses = Vec::with_capacity(count);
    match spec.shape {
        // Rest-to-rest moves from one end of the line to the other, as many as fit.
        Shape::Line => {
            let stroke = Trapezoid::new(lap_length, spec.feed_mm_s, spec.accel_mm_s2);
            let move_time = stroke.duration();
            // Whole moves only; the rest of the duration dwells at the end of the last one.
            let moves = (spec.duration_s / move_time).floor().max(1.0);
            for k in 0..count {
                let t = k as f64 * period;
                let index = (t / move_time).floor().min(moves - 1.0);
                let s = stroke.distance_at(t - index * move_time);
                let forward = (index as u64).is_multiple_of(2);
                let u = phase_at(&arc, s);
                poses.push(spec.lap_pose(if forward { u } else { 1.0 - u }));
            }
        }
        // Closed curves: one profile over the whole duration, lap after lap.
        _ => {
            let feed = spec.feed_mm_s;
            ensure!(
                spec.duration_s > feed / spec.accel_mm_s2,
                "{} s is too short to accelerate to {feed} mm/s and stop again",
                spec.duration_s
            );
            let length = feed * (spec.duration_s - feed / spec.accel_mm_s2);
            let profile = Trapezoid::new(length, feed, spec.accel_mm_s2);
            for k in 0..count {
                let s = profile.distance_at(k as f64 * period);
                let u = phase_at(&arc, s % lap_length);
                poses.push(spec.lap_pose(u));
            }
        }
    }
    for pose in &mut poses {
        for (value, offset) in pose.iter_mut().zip(centre) {
            *value += offset;
        }
    }
    check_reachable(geometry, &poses).with_context(|| {
        format!(
            "the {} path (size {} mm) does not fit the workspace of {}",
            spec.shape.name(),
            spec.size_mm,
            geometry.name
        )
    })?;
    Ok(Path {
        poses,
        period_s: period,
    })
}

fn check_reachable(geometry: &Geometry, poses: &[[f64; 6]]) -> anyhow::Result<()> {
    let workspace = &geometry.workspace;
    for (index, values) in poses.iter().enumerate() {
        let pose = Pose::from_mm_deg(*values);
        if !inverse_kinematics(geometry, &pose).all_in_stroke() {
            bail!("point {index} {values:.3?} puts a leg outside its stroke");
        }
        let tilt_deg = tilt(&pose).to_degrees();
        if tilt_deg > workspace.tilt_max + 1e-9 {
            bail!(
                "point {index} tilts {tilt_deg:.2}° (the workspace allows {}°)",
                workspace.tilt_max
            );
        }
        let radius = values[0].hypot(values[1]);
        if radius > workspace.radius + 1e-9 {
            bail!(
                "point {index} is {radius:.2} mm off the axis (the workspace radius is {} mm)",
                workspace.radius
            );
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn speeds(path: &Path) -> Vec<f64> {
        path.poses
            .windows(2)
            .map(|w| {
                ((w[1][0] - w[0][0]).powi(2)
                    + (w[1][1] - w[0][1]).powi(2)
                    + (w[1][2] - w[0][2]).powi(2))
                .sqrt()
                    / path.period_s
            })
            .collect()
    }

    #[test]
    fn trapezoid_reaches_the_feed_and_stops_at_the_length() {
        let profile = Trapezoid::new(100.0, 20.0, 200.0);
        // 0.1 s ramps, 100 mm at 20 mm/s = 5 s, plus one ramp time.
        assert!((profile.duration() - 5.1).abs() < 1e-12);
        assert_eq!(profile.distance_at(0.0), 0.0);
        assert!((profile.distance_at(0.1) - 1.0).abs() < 1e-12);
        assert!((profile.distance_at(2.6) - 51.0).abs() < 1e-12);
        assert_eq!(profile.distance_at(5.1), 100.0);
        assert_eq!(profile.distance_at(9.0), 100.0);
        // Finite differences: the speed never exceeds the feed.
        let dt = 1e-4;
        let max_speed = (0..51_000)
            .map(|k| {
                (profile.distance_at((k + 1) as f64 * dt) - profile.distance_at(k as f64 * dt)) / dt
            })
            .fold(0.0, f64::max);
        assert!(max_speed <= 20.0 + 1e-9, "{max_speed}");
    }

    #[test]
    fn short_moves_are_triangular() {
        let profile = Trapezoid::new(1.0, 20.0, 200.0);
        // Peak speed sqrt(1 · 200) ≈ 14.1 mm/s < 20, reached at half the length.
        let peak_time = (1.0f64 / 200.0).sqrt();
        assert!((profile.duration() - 2.0 * peak_time).abs() < 1e-12);
        assert!((profile.distance_at(peak_time) - 0.5).abs() < 1e-12);
    }

    #[test]
    fn every_shape_follows_the_feed_profile_inside_the_workspace() {
        let geometry = Geometry::prototype();
        for shape in [Shape::Line, Shape::Circle, Shape::Helix, Shape::FigureEight] {
            let spec = PathSpec {
                shape,
                duration_s: 12.0,
                ..PathSpec::default()
            };
            let path = interpolate(&geometry, &spec).unwrap();
            assert_eq!(path.poses.len(), 12_001);
            let v = speeds(&path);
            let peak = v.iter().cloned().fold(0.0, f64::max);
            // Arc-length tabulation and the chord of one period: within 0.5 % of the feed.
            assert!(
                peak <= spec.feed_mm_s * 1.005 && peak >= spec.feed_mm_s * 0.99,
                "{}: peak speed {peak}",
                shape.name()
            );
            assert!(
                v[0] < 0.2 && *v.last().unwrap() < 0.2,
                "{}: starts and ends at rest",
                shape.name()
            );
            // Acceleration by finite differences stays within the limit (+ chord error).
            let accel = v
                .windows(2)
                .map(|w| (w[1] - w[0]).abs() / path.period_s)
                .fold(0.0, f64::max);
            assert!(
                accel <= spec.accel_mm_s2 * 1.05,
                "{}: {accel} mm/s²",
                shape.name()
            );
        }
    }

    #[test]
    fn helix_and_figure_eight_change_orientation() {
        let geometry = Geometry::prototype();
        for (shape, angle_index) in [(Shape::Helix, 4), (Shape::FigureEight, 5)] {
            let spec = PathSpec {
                shape,
                duration_s: 30.0,
                ..PathSpec::default()
            };
            let path = interpolate(&geometry, &spec).unwrap();
            let range = path
                .poses
                .iter()
                .map(|p| p[angle_index])
                .fold((f64::MAX, f64::MIN), |(lo, hi), v| (lo.min(v), hi.max(v)));
            assert!(range.1 - range.0 > 10.0, "{}: {range:?}", shape.name());
        }
    }

    #[test]
    fn paths_outside_the_workspace_are_refused_with_the_point() {
        let geometry = Geometry::prototype();
        let spec = PathSpec {
            shape: Shape::Circle,
            size_mm: 120.0,
            duration_s: 5.0,
            ..PathSpec::default()
        };
        let message = format!("{:#}", interpolate(&geometry, &spec).unwrap_err());
        assert!(
            message.contains("does not fit") && message.contains("point"),
            "{message}"
        );
        let bad = PathSpec {
            feed_mm_s: f64::NAN,
            ..PathSpec::default()
        };
        assert!(interpolate(&geometry, &bad).is_err());
    }
}
