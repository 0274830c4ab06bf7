//! The covariance of an identification's residuals, and its two variances told apart by their
//! shape.
//!
//! At each configuration `c` the residuals of its targets (`n_c` coordinates, mm) hold the
//! instrument's noise, independent on every coordinate (variance `σ²`), and whatever moved the
//! platform as a whole there: the machine's repeatability, and what the model's form misses at
//! that configuration's legs. Both move the legs, which move the targets by `K_c·δ` (`K_c` how
//! the targets move per mm of each leg, `n_c × 6`, of rank 6 with three targets or more). The
//! instrument's noise fills all `n_c` directions of a configuration, the platform's only the six
//! `K_c` spans: two sums of squares of the residuals, the whole and its part in those spans,
//! tell the two variances apart (`split_by_shape`). The machine's repeatability and the
//! form's misfit have the same shape and are not told apart.

use nalgebra::{DMatrix, DVector};

/// The covariance `Ω = σ² I + v Σ_c K_c K_cᵀ` of an identification's residuals, mm².
#[derive(Debug, Clone)]
pub(crate) struct ResidualNoise {
    /// `σ²`, the variance per coordinate of the instrument's noise (and of what the model's
    /// form misses where the residuals' shape does not tell it apart), mm².
    pub(crate) instrument_variance_mm2: f64,
    /// `v`, the variance of each leg's length at every move that moved the platform and the
    /// parameters with it: the repeatability, or what the residuals' shape shows beyond an
    /// assumed one (`uncertainty::Propagation::of`), mm².
    pub(crate) repeatability_variance_mm2: f64,
    /// `K`: how each residual moves per mm of each leg (residuals × legs), configuration after
    /// configuration.
    pub(crate) moves: DMatrix<f64>,
    /// Each configuration's first residual and number of residuals.
    pub(crate) blocks: Vec<(usize, usize)>,
}

impl ResidualNoise {
    /// `A Ω Aᵀ` for a linear map `A` of the residuals (any rows × the residuals).
    pub(crate) fn sandwich(&self, a: &DMatrix<f64>) -> DMatrix<f64> {
        let mut result = a * a.transpose() * self.instrument_variance_mm2;
        for &(start, height) in &self.blocks {
            let moved = a.columns(start, height) * self.moves.rows(start, height);
            result += &moved * moved.transpose() * self.repeatability_variance_mm2;
        }
        result
    }
}

/// The residuals' variance told apart by shape, mm²: the instrument's per coordinate, the
/// platform's per leg and configuration (see the module's documentation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShapeSplit {
    /// Per coordinate, independent: the instrument's noise.
    pub instrument_variance_mm2: f64,
    /// Per leg and configuration, moving all its targets together: the repeatability and what
    /// the model's form misses.
    pub platform_variance_mm2: f64,
    /// The standard error of `platform_variance_mm2`, by the delete-one-configuration
    /// jackknife (0.91–0.95× the scatter over draws in this module's test: a little short);
    /// infinite where a configuration left out leaves the two inseparable.
    pub platform_error_mm2: f64,
}

/// Singular values of a configuration's `K_c` below this share of its largest are directions
/// its legs do not move the targets in.
const MOVE_RANK_TOLERANCE: f64 = 1e-9;

/// What the hat matrix `H = U Uᵀ` of an identification (`U` the residuals' rows of its kept
/// left singular vectors: a projection without a smoothness prior, not with one) does to the
/// expected squares of its residuals `r = (I − H) e`, `e` of covariance
/// `σ² I + w Σ_c K_c K_cᵀ`: each configuration's share, per unit of `σ²` and of `w`.
struct HatMoments {
    /// `Uᵀ U` (the identity without a prior).
    gram: DMatrix<f64>,
    /// `S = Σ_c M_c M_cᵀ`, `M_c = U_cᵀ K_c`.
    spread: DMatrix<f64>,
}

impl HatMoments {
    /// The moments of `kept` (`U`) with `moves` (`K`) in `blocks`.
    fn of(kept: &DMatrix<f64>, moves: &DMatrix<f64>, blocks: &[(usize, usize)]) -> Self {
        let directions = kept.ncols();
        let mut spread = DMatrix::<f64>::zeros(directions, directions);
        for &(start, height) in blocks {
            let kept_moves = kept.rows(start, height).transpose() * moves.rows(start, height);
            spread += &kept_moves * kept_moves.transpose();
        }
        Self {
            gram: kept.transpose() * kept,
            spread,
        }
    }

    /// The coefficients of `σ²` and `w` in the expected squares of a configuration's residuals
    /// `Qᵀ E_cᵀ r` (`Q` orthonormal columns, `dimensions` of them: the identity, or a basis of
    /// the `K_c`'s span), `kept_here` its `Qᵀ U_c`, and `own = ‖K_c‖² − 2‖M_c‖²` (with
    /// `Q Qᵀ K_c = K_c`). The platform's moves of every configuration reach these residuals
    /// through `I − H`, as `Σ_c' ‖Qᵀ E_cᵀ (I − H) E_c' K_c'‖² = own + tr(Qᵀ U_c S U_cᵀ Q)`; the
    /// instrument's noise as `‖Qᵀ E_cᵀ (I − H)‖² = dimensions − 2‖Qᵀ U_c‖² + tr(Qᵀ U_c Uᵀ U
    /// U_cᵀ Q)` (`dimensions − ‖Qᵀ U_c‖²` where `H` is a projection).
    fn expected(&self, kept_here: &DMatrix<f64>, dimensions: usize, own: f64) -> [f64; 2] {
        [
            dimensions as f64 - 2.0 * kept_here.norm_squared()
                + (kept_here * &self.gram * kept_here.transpose()).trace(),
            own + (kept_here * &self.spread * kept_here.transpose()).trace(),
        ]
    }
}

/// `‖K_c‖² − 2‖U_cᵀ K_c‖²` of a configuration's `kept_here` (`U_c`) and `leg_moves` (`K_c`).
fn own_moves(kept_here: &DMatrix<f64>, leg_moves: &DMatrix<f64>) -> f64 {
    leg_moves.norm_squared() - 2.0 * (kept_here.transpose() * leg_moves).norm_squared()
}

/// The coefficients of `σ²` and `w` in `E‖r‖²` for residuals `r = (I − H) e`, `e` of covariance
/// `σ² I + w Σ_c K_c K_cᵀ` (`H = U Uᵀ`, `kept` the residuals' rows of the identification's kept
/// left singular vectors, `K` = `moves` in `blocks`, as in [`split_by_shape`]):
/// `tr((I − H)²)` and `Σ_c ‖(I − H) E_c K_c‖²` (`m − r` and `‖K‖² − Σ_c ‖U_cᵀ K_c‖²` without a
/// smoothness prior).
pub(crate) fn expected_squares(
    kept: &DMatrix<f64>,
    moves: &DMatrix<f64>,
    blocks: &[(usize, usize)],
) -> [f64; 2] {
    let hat = HatMoments::of(kept, moves, blocks);
    blocks.iter().fold([0.0; 2], |sum, &(start, height)| {
        let kept_here = kept.rows(start, height).into_owned();
        let own = own_moves(&kept_here, &moves.rows(start, height).into_owned());
        let [instrument, platform] = hat.expected(&kept_here, height, own);
        [sum[0] + instrument, sum[1] + platform]
    })
}

/// `σ²` and `w` of residuals `r = (I − H) e`, `e` of covariance `σ² I + w Σ_c K_c K_cᵀ`, by the
/// method of moments: `H = U Uᵀ` the identification's hat matrix (`kept`, the residuals' rows
/// of its kept left singular vectors, residuals × directions: a projection without a
/// smoothness prior, not with one), `K` = `moves` (residuals × legs) in `blocks` (each
/// configuration's first residual and number of residuals). With `P` the projection onto the
/// `K_c`'s spans, `E rᵀ A r = tr((I − H) A (I − H) Ω)` for `A = I` and `A = P` are two linear
/// equations in `σ²` and `w`. Either may come out negative where the residuals' own scatter
/// takes it there. `None` where no configuration has a coordinate its legs cannot move (fewer
/// than three targets everywhere): the two cannot be told apart. The residuals are taken as
/// the targets' coordinates, each with the instrument's noise: not those of targets placed
/// by a measured pose, whose noise the pose's six directions hold. `kept` and `moves` have a
/// row per residual, and the blocks tile the residuals in order.
pub(crate) fn split_by_shape(
    residual: &DVector<f64>,
    kept: &DMatrix<f64>,
    moves: &DMatrix<f64>,
    blocks: &[(usize, usize)],
) -> Option<ShapeSplit> {
    debug_assert!(kept.nrows() == residual.len() && moves.nrows() == residual.len());
    debug_assert_eq!(
        blocks
            .iter()
            .try_fold(0, |at, &(start, height)| (start == at)
                .then_some(at + height)),
        Some(residual.len()),
        "the blocks tile the residuals"
    );
    // Each configuration's residuals' expectations, whole and in the spans ([`HatMoments`]):
    // summed, they are the expectations of the whole residuals.
    let hat = HatMoments::of(kept, moves, blocks);
    let mut terms: Vec<Moments> = Vec::with_capacity(blocks.len());
    // A configuration without a target seen adds nothing.
    for &(start, height) in blocks.iter().filter(|(_, height)| *height > 0) {
        let leg_moves = moves.rows(start, height).into_owned();
        let svd = leg_moves.clone().svd(true, false);
        let largest = svd.singular_values.max();
        let spanned: Vec<usize> = (0..svd.singular_values.len())
            .filter(|&i| svd.singular_values[i] > MOVE_RANK_TOLERANCE * largest)
            .collect();
        let basis = svd.u.expect("U was asked for").select_columns(&spanned);
        let kept_here = kept.rows(start, height).into_owned();
        let kept_in_span = basis.transpose() * &kept_here;
        let here = residual.rows(start, height);
        let own = own_moves(&kept_here, &leg_moves);
        let [whole_instrument, whole_platform] = hat.expected(&kept_here, height, own);
        let [span_instrument, span_platform] = hat.expected(&kept_in_span, spanned.len(), own);
        terms.push(Moments {
            sums: [
                here.norm_squared(),
                (basis.transpose() * here).norm_squared(),
            ],
            instrument: [whole_instrument, span_instrument],
            platform: [whole_platform, span_platform],
        });
    }
    let total = terms
        .iter()
        .fold(Moments::default(), |sum, term| sum.plus(term, 1.0));
    let (instrument, platform) = total.solved()?;
    // The delete-one-configuration jackknife of w; none where leaving one out leaves the two
    // variances inseparable (that configuration alone told them apart).
    let left_out: Option<Vec<f64>> = terms
        .iter()
        .map(|term| Some(total.plus(term, -1.0).solved()?.1))
        .collect();
    let platform_error_mm2 = left_out.map_or(f64::INFINITY, |left_out| {
        let count = left_out.len() as f64;
        let mean = left_out.iter().sum::<f64>() / count;
        let scatter: f64 = left_out.iter().map(|w| (w - mean).powi(2)).sum();
        ((count - 1.0) / count * scatter).sqrt()
    });
    Some(ShapeSplit {
        instrument_variance_mm2: instrument,
        platform_variance_mm2: platform,
        platform_error_mm2,
    })
}

/// The two sums of squares of [`split_by_shape`] (`A = I`, `A = P`) and the coefficients of
/// `σ²` and `w` in their expectations, summed over configurations.
#[derive(Debug, Clone, Copy, Default)]
struct Moments {
    sums: [f64; 2],
    instrument: [f64; 2],
    platform: [f64; 2],
}

impl Moments {
    /// These moments plus `scale` times `other`'s.
    fn plus(self, other: &Moments, scale: f64) -> Moments {
        let add = |a: [f64; 2], b: [f64; 2]| [a[0] + scale * b[0], a[1] + scale * b[1]];
        Moments {
            sums: add(self.sums, other.sums),
            instrument: add(self.instrument, other.instrument),
            platform: add(self.platform, other.platform),
        }
    }

    /// `(σ², w)` solving the two equations; `None` where they are dependent (to rounding), as
    /// where no coordinate lies outside the spans.
    fn solved(&self) -> Option<(f64, f64)> {
        let [all, in_spans] = self.sums;
        let determinant =
            self.instrument[0] * self.platform[1] - self.instrument[1] * self.platform[0];
        // A NaN determinant fails the comparison as a dependent pair does.
        let independent = determinant.abs() > 1e-9 * (self.instrument[0] * self.platform[1]).abs();
        if !independent {
            return None;
        }
        Some((
            (all * self.platform[1] - in_spans * self.platform[0]) / determinant,
            (self.instrument[0] * in_spans - self.instrument[1] * all) / determinant,
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, StandardNormal};

    /// Configurations of this many residuals (three targets).
    const HEIGHT: usize = 9;

    /// Fifty configurations' `K` (random moves, mm per mm), their blocks, and the kept
    /// directions of an identification whose columns hold the legs' offsets (`K` itself, as
    /// the identification's do) and a hundred more: the physical model's size (108 columns).
    /// With a `prior` weight above 0 the hundred are held back as a smoothness prior holds the
    /// curves' (rows `√prior` on each, stacked below): the kept directions are the residuals'
    /// rows of the stacked system's, and the hat matrix no projection.
    fn identification(
        rng: &mut ChaCha8Rng,
        prior: f64,
    ) -> (DMatrix<f64>, Vec<(usize, usize)>, DMatrix<f64>) {
        let configurations = 50;
        let rows = configurations * HEIGHT;
        let moves = DMatrix::<f64>::from_fn(rows, 6, |_, _| StandardNormal.sample(&mut *rng));
        let blocks = (0..configurations).map(|c| (c * HEIGHT, HEIGHT)).collect();
        let mut columns = DMatrix::<f64>::from_fn(rows + 100, 106, |r, c| match r.cmp(&rows) {
            std::cmp::Ordering::Less => StandardNormal.sample(&mut *rng),
            _ if c == r - rows + 6 => prior.sqrt(),
            _ => 0.0,
        });
        columns.view_mut((0, 0), (rows, 6)).copy_from(&moves);
        let kept = columns
            .svd(true, false)
            .u
            .unwrap()
            .rows(0, rows)
            .into_owned();
        (moves, blocks, kept)
    }

    /// Residuals `(I − H) e` of the identification `(K, blocks, U)`, `e` drawn with `instrument`
    /// variance per coordinate and `platform` per leg and configuration (mm²).
    fn residual_draw(
        rng: &mut ChaCha8Rng,
        (moves, blocks, kept): (&DMatrix<f64>, &[(usize, usize)], &DMatrix<f64>),
        instrument: f64,
        platform: f64,
    ) -> DVector<f64> {
        let mut noise =
            DVector::<f64>::from_fn(moves.nrows(), |_, _| StandardNormal.sample(&mut *rng))
                * instrument.sqrt();
        for &(start, height) in blocks {
            let legs = DVector::<f64>::from_fn(6, |_, _| StandardNormal.sample(&mut *rng));
            let moved = moves.rows(start, height) * legs * platform.sqrt();
            let mut here = noise.rows_mut(start, height);
            here += moved;
        }
        &noise - kept * (kept.transpose() * &noise)
    }

    #[test]
    fn the_expected_squares_are_what_the_residuals_hold_on_average() {
        for prior in [0.0, 225.0] {
            let mut rng = ChaCha8Rng::seed_from_u64(13);
            let (moves, blocks, kept) = identification(&mut rng, prior);
            let [freedom, share] = expected_squares(&kept, &moves, &blocks);
            if prior == 0.0 {
                // A projection: m − r, and ‖K‖² less what the kept directions take.
                assert!((freedom - (450.0 - 106.0)).abs() < 1e-9, "{freedom}");
                let taken: f64 = blocks
                    .iter()
                    .map(|&(start, height)| {
                        (kept.rows(start, height).transpose() * moves.rows(start, height))
                            .norm_squared()
                    })
                    .sum();
                assert!((share - (moves.norm_squared() - taken)).abs() < 1e-9 * share);
            }
            // Each variance alone, 400 draws: the mean sum of squares within four of its
            // standard errors (0.4 % of it for the instrument's) of the expectation.
            for (instrument, platform) in [(1.0, 0.0), (0.0, 1.0)] {
                let squares: Vec<f64> = (0..400)
                    .map(|_| {
                        residual_draw(&mut rng, (&moves, &blocks, &kept), instrument, platform)
                            .norm_squared()
                    })
                    .collect();
                let n = squares.len() as f64;
                let mean = squares.iter().sum::<f64>() / n;
                let error =
                    (squares.iter().map(|s| (s - mean).powi(2)).sum::<f64>() / (n - 1.0) / n)
                        .sqrt();
                let expected = instrument * freedom + platform * share;
                assert!(
                    (mean - expected).abs() < 4.0 * error,
                    "prior {prior}, instrument {instrument}, platform {platform}: {mean} ± \
                     {error} against {expected}"
                );
            }
        }
    }

    /// The mean split over `draws` residuals of `instrument` and `platform` variances (mm²),
    /// its standard errors, and the root mean square of the jackknife's standard error of
    /// the platform's variance.
    fn mean_split(
        instrument: f64,
        platform: f64,
        prior: f64,
        draws: usize,
    ) -> ([f64; 2], [f64; 2], f64) {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let (moves, blocks, kept) = identification(&mut rng, prior);
        let mut sums = [[0.0; 2]; 2];
        let mut jackknifed = 0.0;
        for _ in 0..draws {
            let residual = residual_draw(&mut rng, (&moves, &blocks, &kept), instrument, platform);
            let split = split_by_shape(&residual, &kept, &moves, &blocks).unwrap();
            jackknifed += split.platform_error_mm2.powi(2);
            for (k, value) in [split.instrument_variance_mm2, split.platform_variance_mm2]
                .into_iter()
                .enumerate()
            {
                sums[k][0] += value;
                sums[k][1] += value * value;
            }
        }
        let n = draws as f64;
        let mean = sums.map(|[s, _]| s / n);
        let error = [0, 1].map(|k| ((sums[k][1] / n - mean[k].powi(2)) / n).sqrt());
        (mean, error, (jackknifed / n).sqrt())
    }

    #[test]
    fn the_split_recovers_the_instruments_and_the_platforms_variance() {
        // The virtual platform's instrument (0.02 mm a reading, three averaged) beside a
        // platform variance of twice its repeatability's, and beside none; without a prior, and
        // with one holding the hundred columns back to about half of what the data sees
        // (singular values about √450 ≈ 21, the prior's 15).
        for (instrument, platform, prior) in [
            (1.33e-4, 3.2e-5, 0.0),
            (1.33e-4, 0.0, 0.0),
            (0.0, 1.6e-5, 0.0),
            (1.33e-4, 3.2e-5, 225.0),
            (0.0, 1.6e-5, 225.0),
        ] {
            let (mean, error, jackknifed) = mean_split(instrument, platform, prior, 400);
            for (what, truth, k) in [("instrument", instrument, 0), ("platform", platform, 1)] {
                assert!(
                    (mean[k] - truth).abs() < 4.0 * error[k] + 1e-12,
                    "{what}: {} ± {} against {truth} mm² (instrument {instrument}, platform \
                     {platform}, prior {prior})",
                    mean[k],
                    error[k]
                );
            }
            // The check can tell: the standard error is well below what is estimated.
            assert!(error[0] < 0.02 * instrument.max(1e-4), "{error:?}");
            assert!(error[1] < 0.1 * platform.max(1e-5), "{error:?}");
            // The jackknife's standard error is the scatter of w over the draws (400 draws
            // estimate that scatter within 3.5 %, 1 σ).
            let scattered = error[1] * 400f64.sqrt();
            assert!(
                (0.85..1.15).contains(&(jackknifed / scattered)),
                "the jackknife gives {jackknifed} where w scatters by {scattered} mm²"
            );
        }
    }

    #[test]
    fn residuals_the_legs_can_make_everywhere_are_not_split() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let (moves, _, kept) = identification(&mut rng, 0.0);
        let residual = DVector::<f64>::from_fn(moves.nrows(), |_, _| 1e-3);
        // Blocks of six residuals: each K_c spans them all.
        let blocks: Vec<(usize, usize)> = (0..moves.nrows() / 6).map(|c| (c * 6, 6)).collect();
        assert_eq!(split_by_shape(&residual, &kept, &moves, &blocks), None);
    }
}
