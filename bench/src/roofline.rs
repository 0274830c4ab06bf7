//! The arithmetic floor of the fused networks on this core: how many vector multiplies and adds
//! per nanosecond the core sustains, measured in the instruction set the fused model uses, and
//! the time a point's [`OPERATIONS_PER_BLOCK`] per block would take at that rate.

use std::hint::black_box;
use std::time::Instant;

use hexacomp_core::activation::LANES;
use hexacomp_core::fused::{FusedModel, OPERATIONS_PER_BLOCK};

/// Independent chains of multiply-then-add: enough to keep both arithmetic ports busy through
/// the operations' latency (4 cycles each on current x86 cores).
const CHAINS: usize = 8;
/// Rounds of the chains per measurement (about 0.1 s).
const ROUNDS: u64 = 20_000_000;

/// `ROUNDS` rounds of `a = a·m + c` on every lane of every chain: `2 · CHAINS` vector
/// operations per round.
#[inline(always)]
fn chains(rounds: u64, m: f64, c: f64) -> [[f64; LANES]; CHAINS] {
    let mut acc = [[1.0; LANES]; CHAINS];
    for _ in 0..rounds {
        for a in acc.iter_mut() {
            *a = std::array::from_fn(|l| a[l] * m + c);
        }
    }
    acc
}

/// [`chains`] in the target's baseline instruction set.
fn chains_baseline(rounds: u64, m: f64, c: f64) -> [[f64; LANES]; CHAINS] {
    chains(rounds, m, c)
}

/// [`chains`] compiled for AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn chains_avx2(rounds: u64, m: f64, c: f64) -> [[f64; LANES]; CHAINS] {
    chains(rounds, m, c)
}

/// Vector operations ([`LANES`] wide) per nanosecond this core sustains in the instruction set
/// `model` runs with: the best of three measurements.
pub fn peak_operations_per_ns(model: &FusedModel) -> f64 {
    let run = || {
        let (m, c) = (black_box(0.999_999_9), black_box(1e-9));
        let start = Instant::now();
        let result = match model.instruction_set() {
            #[cfg(target_arch = "x86_64")]
            // SAFETY: the model chose AVX2 only because the CPU reports it.
            "avx2" => unsafe { chains_avx2(ROUNDS, m, c) },
            _ => chains_baseline(ROUNDS, m, c),
        };
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
