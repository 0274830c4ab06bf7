//! Summaries of pose errors in the layout of the paper's Table 2: max, mean and standard
//! deviation of the position-error norm `‖δ_A‖` (mm) and the orientation-error norm `‖ε‖` (deg).

use crate::pose::Pose;

/// Max, mean and sample standard deviation of a set of non-negative error norms.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ErrorStats {
    /// Largest value.
    pub max: f64,
    /// Arithmetic mean.
    pub mean: f64,
    /// Sample standard deviation (divisor `n − 1`; 0 for fewer than two values).
    pub std: f64,
    /// Number of values.
    pub count: usize,
}

impl ErrorStats {
    /// The statistics of `values`; all zero for an empty set.
    pub fn of(values: &[f64]) -> Self {
        let count = values.len();
        if count == 0 {
            return Self::default();
        }
        let mean = values.iter().sum::<f64>() / count as f64;
        let max = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let std = if count > 1 {
            let ss: f64 = values.iter().map(|v| (v - mean).powi(2)).sum();
            (ss / (count - 1) as f64).sqrt()
        } else {
            0.0
        };
        Self {
            max,
            mean,
            std,
            count,
        }
    }
}

/// The error of a reached pose against the commanded one, as the paper evaluates it (Sec. 4.2).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PoseErrorNorm {
    /// `‖δ_A‖`: distance between reached and commanded position of `A`, mm.
    pub position_mm: f64,
    /// `‖ε‖`: angle of the rotation from commanded to reached orientation, degrees.
    pub orientation_deg: f64,
}

impl PoseErrorNorm {
    /// The error of `reached` against `commanded`.
    pub fn between(commanded: &Pose, reached: &Pose) -> Self {
        let twist = commanded.twist_to(reached);
        Self {
            position_mm: twist.translation.length(),
            orientation_deg: twist.rotation.length().to_degrees(),
        }
    }
}

/// Table 2 statistics of a set of pose errors.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PoseErrorStats {
    /// Statistics of `‖δ_A‖`, mm.
    pub position_mm: ErrorStats,
    /// Statistics of `‖ε‖`, degrees.
    pub orientation_deg: ErrorStats,
}

impl PoseErrorStats {
    /// The statistics of `errors`.
    pub fn of(errors: &[PoseErrorNorm]) -> Self {
        let position: Vec<f64> = errors.iter().map(|e| e.position_mm).collect();
        let orientation: Vec<f64> = errors.iter().map(|e| e.orientation_deg).collect();
        Self {
            position_mm: ErrorStats::of(&position),
            orientation_deg: ErrorStats::of(&orientation),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    #[test]
    fn stats_of_known_values() {
        let s = ErrorStats::of(&[1.0, 2.0, 3.0, 4.0]);
        assert_eq!(s.max, 4.0);
        assert_eq!(s.mean, 2.5);
        assert!((s.std - (5.0f64 / 3.0).sqrt()).abs() < 1e-15);
        assert_eq!(s.count, 4);
        assert_eq!(ErrorStats::of(&[]), ErrorStats::default());
    }

    #[test]
    fn pose_error_norm_of_known_displacement() {
        let a = Pose::from_mm_deg([0.0, 0.0, 300.0, 0.0, 0.0, 0.0]);
        let b = Pose::new(
            DVec3::new(0.3, 0.4, 300.0),
            DVec3::new(0.0, 0.0, 0.1f64.to_radians()),
        );
        let e = PoseErrorNorm::between(&a, &b);
        assert!((e.position_mm - 0.5).abs() < 1e-12);
        assert!((e.orientation_deg - 0.1).abs() < 1e-12);
    }
}
