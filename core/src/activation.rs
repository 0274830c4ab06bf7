//! The hidden layer's activation (Eq. 11, `tanh`) on [`LANES`] values at once, written with the
//! four basic operations and bit manipulation only, so that the compiler turns it into SIMD
//! instructions (the C library's `tanh` is one call per value and cannot be vectorised).
//!
//! Error bound: within [`TANH_MAX_ERROR`] (absolute) of `tanh`, checked against the C
//! library's `tanh` (itself within one ulp) on a grid of 5 million points over [−25, 25], at
//! tiny values and at the ends (the largest difference seen is 3.3e-16, in a random sample). What it does to a
//! correction is part of `FusedModel::error_bound_mm`. `±∞` gives `±1` and NaN stays NaN, as
//! with `f64::tanh`.
//!
//! Each lane is computed by the same sequence of IEEE 754 operations whatever the instruction
//! set (no fused multiply-add is written, and Rust never contracts `a * b + c` into one), so the
//! result is the same bits on a machine with or without AVX2.

/// Values evaluated together: four `f64`, one 256-bit AVX register.
pub const LANES: usize = 4;

/// The largest absolute difference from the exact `tanh` (see the module documentation).
pub const TANH_MAX_ERROR: f64 = 1e-15;

/// Beyond this, `tanh` is 1 to the last bit (`1 − tanh 20 ≈ 8.5e-18`, below half an ulp of 1).
const SATURATION: f64 = 20.0;
/// `log₂ e`.
const LOG2_E: f64 = std::f64::consts::LOG2_E;
/// `ln 2` split Cody–Waite style (fdlibm's split): the high part has 32 significant bits, so
/// `n · LN2_HIGH` is exact for any `|n| < 2²⁰` (here `|n| ≤ 58`); the low part is the rest.
const LN2_HIGH: f64 = f64::from_bits(0x3fe6_2e42_fee0_0000);
const LN2_LOW: f64 = f64::from_bits(0x3dea_39ef_3579_3c76);
/// `1.5 · 2⁵²`: adding it rounds to an integer and leaves that integer in the low mantissa bits.
const ROUNDING_SHIFTER: f64 = 6_755_399_441_055_744.0;
/// `1/k!` for k = 0..=12: the Taylor polynomial of `e^r`, whose remainder on `|r| ≤ ln2/2` is
/// below `0.347¹³/13! ≈ 1.7e-16` relative.
const EXP_TAYLOR: [f64; 13] = [
    1.0,
    1.0,
    1.0 / 2.0,
    1.0 / 6.0,
    1.0 / 24.0,
    1.0 / 120.0,
    1.0 / 720.0,
    1.0 / 5_040.0,
    1.0 / 40_320.0,
    1.0 / 362_880.0,
    1.0 / 3_628_800.0,
    1.0 / 39_916_800.0,
    1.0 / 479_001_600.0,
];

/// `tanh` of each lane: `sign(z) · (1 − e)/(1 + e)` with `e = exp(−2|z|)`, `|z|` capped at 20.
#[inline(always)]
pub fn tanh_lanes(z: [f64; LANES]) -> [f64; LANES] {
    let magnitude = z.map(|v| {
        let a = v.abs();
        // A comparison with NaN is false: NaN passes through.
        if a > SATURATION { SATURATION } else { a }
    });
    let e = exp_lanes(magnitude.map(|a| -2.0 * a));
    std::array::from_fn(|l| ((1.0 - e[l]) / (1.0 + e[l])).copysign(z[l]))
}

/// `exp` of each lane for `u ∈ [−40, 0]` (what [`tanh_lanes`] needs): `u = n·ln2 + r`,
/// `e^u = 2ⁿ · e^r` with `e^r` from its Taylor polynomial (Estrin's scheme) and `2ⁿ` built in
/// the exponent bits.
#[inline(always)]
fn exp_lanes(u: [f64; LANES]) -> [f64; LANES] {
    let shifted = u.map(|u| u * LOG2_E + ROUNDING_SHIFTER);
    let n = shifted.map(|s| s - ROUNDING_SHIFTER);
    let r: [f64; LANES] = std::array::from_fn(|l| (u[l] - n[l] * LN2_HIGH) - n[l] * LN2_LOW);
    let p = taylor_estrin(r);
    // The low 12 bits of `shifted`'s bits are n mod 4096; adding the exponent bias and shifting
    // them into the exponent field gives 2ⁿ for −1022 ≤ n ≤ 1023 (here −58 ≤ n ≤ 0).
    let scale = shifted.map(|s| f64::from_bits(s.to_bits().wrapping_add(1023) << 52));
    std::array::from_fn(|l| p[l] * scale[l])
}

/// The Taylor polynomial `Σ rᵏ/k!`, k = 0..=12, of each lane by Estrin's scheme: pairs of
/// coefficients combined with `r`, pairs of those with `r²`, then `r⁴` and `r⁸` — seven
/// dependent operations where Horner's rule has twenty-four, so that the blocks of a model
/// overlap in the pipeline. Lane by lane, as the compiler vectorises it.
#[inline(always)]
fn taylor_estrin(r: [f64; LANES]) -> [f64; LANES] {
    let c = &EXP_TAYLOR;
    let times =
        |a: [f64; LANES], b: [f64; LANES]| -> [f64; LANES] { std::array::from_fn(|l| a[l] * b[l]) };
    // a + b·x, lane by lane.
    let plus_times = |a: [f64; LANES], b: [f64; LANES], x: [f64; LANES]| -> [f64; LANES] {
        std::array::from_fn(|l| a[l] + b[l] * x[l])
    };
    let pair = |k: usize| -> [f64; LANES] { std::array::from_fn(|l| c[k] + c[k + 1] * r[l]) };
    let r2 = times(r, r);
    let r4 = times(r2, r2);
    let r8 = times(r4, r4);
    let low = plus_times(pair(0), pair(2), r2);
    let middle = plus_times(pair(4), pair(6), r2);
    let high = plus_times(pair(8), pair(10), r2);
    let top = plus_times(high, [c[12]; LANES], r4);
    plus_times(plus_times(low, middle, r4), top, r8)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The largest absolute error against `f64::tanh` over `values`, and where.
    fn worst(values: impl Iterator<Item = f64>) -> (f64, f64) {
        let values: Vec<f64> = values.collect();
        let mut worst = (0.0, 0.0);
        for chunk in values.chunks(LANES) {
            let mut z = [0.0; LANES];
            z[..chunk.len()].copy_from_slice(chunk);
            let got = tanh_lanes(z);
            for (v, g) in chunk.iter().zip(got) {
                let error = (g - v.tanh()).abs();
                if error > worst.0 {
                    worst = (error, *v);
                }
            }
        }
        worst
    }

    #[test]
    fn tanh_lanes_is_within_its_bound_everywhere() {
        // A dense grid over the range where tanh is not yet 1, its ends, and tiny values.
        let grid = (-2_500_000..=2_500_000).map(|i| i as f64 * 1e-5);
        let tiny = (0..300).flat_map(|k| {
            let v = 10f64.powi(-k);
            [v, -v]
        });
        let ends = [19.0, 19.5, 20.0, 20.5, 25.0, 700.0, 1e300, f64::MAX];
        let ends = ends.into_iter().flat_map(|v| [v, -v]);
        let (error, at) = worst(grid.chain(tiny).chain(ends));
        assert!(error <= TANH_MAX_ERROR, "error {error:e} at {at}");
    }

    #[test]
    fn tanh_lanes_is_odd_and_keeps_infinities_nan_and_zeros() {
        let got = tanh_lanes([f64::INFINITY, f64::NEG_INFINITY, f64::NAN, -0.0]);
        assert_eq!(got[0], 1.0);
        assert_eq!(got[1], -1.0);
        assert!(got[2].is_nan());
        assert_eq!(got[3].to_bits(), (-0.0f64).to_bits());
        for v in [1e-8, 0.3, 1.7, 6.0, 18.9] {
            let [a, b, ..] = tanh_lanes([v, -v, 0.0, 0.0]);
            assert_eq!(a, -b, "{v}");
        }
    }
}
