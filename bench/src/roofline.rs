//! The arithmetic floor of the fused networks on this core: how many vector multiplies and adds
//! per nanosecond the core sustains, measured in the instruction set the fused model uses, and
//! the time a point's [`OPERATIONS_PER_BLOCK`] per block would take at that rate.

use std::hint::black_box;
use std::time::Instant;

use hexacomp_core::activation::LANES;
use hexacomp_core::fused::{FusedModel, OPERATIONS_PER_BLOCK};

/// Independent chains of each kind, multiplies and adds apart: 2 × 6 chains of a 3–4 cycle
/// operation keep two multiply and two add pipes busy (12 of the 16 vector registers).
const CHAINS: usize = 6;
/// Rounds of the chains per measurement (about 0.1 s).
const ROUNDS: u64 = 20_000_000;

/// `ROUNDS` rounds of `a = a·m` and `b = b + c` on every lane of every chain: `2 · CHAINS`
/// vector operations per round.
#[inline(always)]
fn chains(rounds: u64, m: f64, c: f64) -> [[f64; LANES]; 2 * CHAINS] {
    let mut products = [[1.0; LANES]; CHAINS];
    let mut sums = [[1.0; LANES]; CHAINS];
    for _ in 0..rounds {
        for (p, s) in products.iter_mut().zip(sums.iter_mut()) {
            *p = p.map(|v| v * m);
            *s = s.map(|v| v + c);
        }
    }
    std::array::from_fn(|i| {
        if i < CHAINS {
            products[i]
        } else {
            sums[i - CHAINS]
        }
    })
}

/// [`chains`] in the target's baseline instruction set.
fn chains_baseline(rounds: u64, m: f64, c: f64) -> [[f64; LANES]; 2 * CHAINS] {
    chains(rounds, m, c)
}

/// [`chains`] compiled for AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn chains_avx2(rounds: u64, m: f64, c: f64) -> [[f64; LANES]; 2 * CHAINS] {
    chains(rounds, m, c)
}

/// Vector operations ([`LANES`] wide) per nanosecond this core sustains in the instruction set
/// `model` runs with: the best of three measurements.
pub fn peak_operations_per_ns(model: &FusedModel) -> f64 {
    #[cfg(target_arch = "x86_64")]
    let avx2 = model.instruction_set() == "avx2" && std::arch::is_x86_feature_detected!("avx2");
    let run = || {
        // m·v stays normal over the rounds (0.99999995^(2·10⁷) ≈ e⁻¹).
        let (m, c) = (black_box(0.999_999_95), black_box(1e-9));
        let start = Instant::now();
        #[cfg(target_arch = "x86_64")]
        let result = if avx2 {
            // SAFETY: AVX2 was detected on this CPU just above.
            unsafe { chains_avx2(ROUNDS, m, c) }
        } else {
            chains_baseline(ROUNDS, m, c)
        };
        #[cfg(not(target_arch = "x86_64"))]
        let result = chains_baseline(ROUNDS, m, c);
        black_box(result);
        (ROUNDS * 2 * CHAINS as u64) as f64 / start.elapsed().as_nanos() as f64
    };
    (0..3).map(|_| run()).fold(0.0, f64::max)
}

/// The time the fused networks of `model` need per point at `peak` vector operations per ns,
/// ns: `blocks · OPERATIONS_PER_BLOCK / peak`.
pub fn networks_floor_ns(model: &FusedModel, peak: f64) -> f64 {
    (model.blocks() * OPERATIONS_PER_BLOCK) as f64 / peak
}
