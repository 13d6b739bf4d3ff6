//! Element-wise pieces of the CPU kernels: a vectorisable `exp`, lane-summed
//! statistics and the GroupNorm parameters, shared by the decoder, the U-Net and
//! the policy kernels.
//!
//! Why: libm's `expf` is a call per element, which keeps loops over SiLU, mish
//! and softmax scalar; a float sum in one accumulator cannot vectorise either.

/// `n` zeros, written now rather than left to the allocator. A large `vec![0.0; n]` is
/// `calloc`'d memory whose pages the kernel maps to its one shared zero page until they are
/// written; a buffer that is read before it is written (`out[i] += ...` into fresh zeros) then
/// faults twice per page, and the second fault copies the page and flushes it from the TLB of
/// every CPU that runs the process. With two threads in one process each flush interrupts
/// the other core: the full-size pixel U-Net ran no faster on two threads than on one
/// (BENCHMARKS.md, 2026-12-02, "two threads in one process"). Writing the zeros first maps
/// each page once, with nothing to flush.
///
/// A buffer of [`HUGE`] bytes or more is first marked for transparent huge pages (where Linux
/// offers them on request, `madvise` mode): the full-size pixel U-Net's activations are
/// 100 MB a layer at batch 8, freshly mapped by the allocator every time, and 2 MB pages fault
/// 512 times less often than 4 KB ones and take less of the TLB.
pub fn zeros(n: usize) -> Vec<f32> {
    let mut v: Vec<f32> = Vec::with_capacity(n);
    if n * 4 >= HUGE {
        advise_huge_pages(v.as_mut_ptr().cast(), n * 4);
    }
    // Keeps the allocation and the zeroing apart, so the compiler cannot fold them back
    // into one zeroed allocation.
    std::hint::black_box(v.as_mut_ptr());
    v.resize(n, 0.0);
    v
}

/// Buffers from this size (bytes) ask for huge pages ([`zeros`]).
pub const HUGE: usize = 4 << 20;

/// Asks Linux to back the whole 4 KB pages of `len` bytes at `ptr` with transparent huge pages
/// where 2 MB-aligned stretches of them allow; a hint, so a refusal changes nothing.
#[cfg(target_os = "linux")]
fn advise_huge_pages(ptr: *mut u8, len: usize) {
    const PAGE: usize = 4096;
    /// `MADV_HUGEPAGE` in Linux's `<asm-generic/mman-common.h>`.
    const MADV_HUGEPAGE: i32 = 14;
    // SAFETY: the C library's `madvise(2)`, declared with its C signature.
    #[allow(unsafe_code)]
    unsafe extern "C" {
        fn madvise(addr: *mut u8, len: usize, advice: i32) -> i32;
    }
    let start = (ptr as usize).next_multiple_of(PAGE);
    let end = (ptr as usize + len) / PAGE * PAGE;
    if end > start {
        // SAFETY: [start, end) lies inside the allocation `ptr..ptr + len` this process owns
        // (rounded inwards to whole pages); MADV_HUGEPAGE changes only how the kernel backs
        // those pages, never their contents or mapping, and its result is only a hint.
        #[allow(unsafe_code)]
        unsafe {
            madvise(start as *mut u8, end - start, MADV_HUGEPAGE)
        };
    }
}

/// Nothing to advise outside Linux.
#[cfg(not(target_os = "linux"))]
fn advise_huge_pages(_: *mut u8, _: usize) {}

/// The sum of `f(v)` over `xs`: runs of 512 values summed in 8 f32 lanes (which
/// vectorises), the runs' totals in f64.
#[inline(always)]
pub fn lane_sum(xs: &[f32], f: impl Fn(f32) -> f32) -> f64 {
    let mut total = 0.0f64;
    for run in xs.chunks(512) {
        let mut lanes = [0.0f32; 8];
        let mut it = run.chunks_exact(8);
        for c in &mut it {
            for (l, &v) in lanes.iter_mut().zip(c) {
                *l += f(v);
            }
        }
        total += lanes.iter().map(|&l| f64::from(l)).sum::<f64>();
        total += it.remainder().iter().map(|&v| f64::from(f(v))).sum::<f64>();
    }
    total
}

/// `e^x` for f32 without a library call, so loops over it vectorise (Cephes' `expf`:
/// x = n ln 2 + r with |r| <= ln 2 / 2, a degree-7 polynomial for e^r, 2^n from the
/// exponent bits). Within a few ulp of `f32::exp` on [-87, 88); clamped outside.
#[inline(always)]
pub fn exp(x: f32) -> f32 {
    const LOG2E: f32 = std::f32::consts::LOG2_E;
    // 1.5 · 2^23: adding it rounds to an integer, which then sits in the low mantissa bits.
    const MAGIC: f32 = 12_582_912.0;
    let x = x.clamp(-87.0, 88.0);
    let shifted = x * LOG2E + MAGIC;
    let n = shifted - MAGIC;
    let r = x - n * 0.693_359_4 - n * -2.121_944_4e-4;
    let z = r * r;
    let p = (((((1.987_569_2e-4 * r + 1.398_199_9e-3) * r + 8.333_452e-3) * r + 4.166_579_6e-2) * r
        + 1.666_666_5e-1)
        * r
        + 0.5)
        * z
        + r
        + 1.0;
    let bits = shifted.to_bits().wrapping_sub(MAGIC.to_bits()).wrapping_add(127) << 23;
    p * f32::from_bits(bits)
}

/// GroupNorm parameters.
#[derive(Clone, Debug)]
pub struct Norm {
    /// Groups.
    pub groups: usize,
    /// Per-channel scale γ.
    pub gamma: Vec<f32>,
    /// Per-channel shift β.
    pub beta: Vec<f32>,
    /// Added to the variance.
    pub eps: f64,
}

/// Mean and biased variance of all the values in `parts` (`count` of them), in two
/// passes — the sum, then the squared deviations from the mean — each part by
/// [`lane_sum`], the parts' totals in f64: GroupNorm's statistics.
#[inline(always)]
pub fn mean_var<'a, I: Iterator<Item = &'a [f32]>>(parts: impl Fn() -> I, count: f64) -> (f64, f64) {
    let mean = parts().map(|p| lane_sum(p, |v| v)).sum::<f64>() / count;
    let m = mean as f32;
    let var = parts().map(|p| lane_sum(p, |v| (v - m) * (v - m))).sum::<f64>() / count;
    (mean, var)
}

/// Whether this CPU has AVX2 and FMA, which every kernel compiled with
/// `#[target_feature(enable = "avx2,fma")]` needs before it may be called (std caches
/// the detection, so this is cheap on a hot path).
#[cfg(target_arch = "x86_64")]
pub fn has_avx2_fma() -> bool {
    std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
}

/// Never on other architectures (the AVX2 kernels are not compiled there).
#[cfg(not(target_arch = "x86_64"))]
pub fn has_avx2_fma() -> bool {
    false
}

/// Whether this CPU has AVX-512F, which every kernel compiled with
/// `#[target_feature(enable = "avx512f")]` needs before it may be called (cached by std).
#[cfg(target_arch = "x86_64")]
pub fn has_avx512f() -> bool {
    std::arch::is_x86_feature_detected!("avx512f")
}

/// Never on other architectures (the AVX-512 kernels are not compiled there).
#[cfg(not(target_arch = "x86_64"))]
pub fn has_avx512f() -> bool {
    false
}

/// `n` deterministic test values in [-1, 1), scrambled by `seed`.
#[cfg(test)]
pub(crate) fn test_values(n: usize, seed: u32) -> Vec<f32> {
    (0..n).map(|i| (((i as u32).wrapping_mul(2_654_435_761) ^ seed) % 1000) as f32 / 500.0 - 1.0).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exp_is_within_a_few_ulp_of_the_library() {
        let mut worst = 0.0f32;
        for i in -87_000..88_000 {
            let x = i as f32 / 1000.0 + 0.000_37;
            let (a, e) = (exp(x), x.exp());
            worst = worst.max(((a - e) / e).abs());
        }
        assert!(worst < 3e-7, "relative error {worst}");
        // Clamped, not overflowing: e^-100 -> e^-87 (tiny), e^100 -> e^88 (finite).
        assert!(exp(-100.0) < 2e-38 && exp(100.0).is_finite());
    }

    #[test]
    fn lane_sums_match_a_plain_sum() {
        // 1 + 2 + ... + 1000 = 500500 (runs of 512 and 488 values, the second with no
        // remainder past its 8-lane blocks): exact, every partial sum is an integer below
        // 2^24. The squares sum to 1000·1001·2001 / 6 = 333,833,500; partial sums of up to
        // ~1.1e8 in f32 round, to within 1e-6 relative.
        let xs: Vec<f32> = (1..=1000).map(|i| i as f32).collect();
        assert_eq!(lane_sum(&xs, |v| v), 500_500.0);
        assert!((lane_sum(&xs, |v| v * v) / 333_833_500.0 - 1.0).abs() < 1e-6);
        // 13 values: one 8-lane block and a remainder of 5, summed in f64.
        assert_eq!(lane_sum(&xs[..13], |v| v), 91.0);
        assert_eq!(lane_sum(&[], |v| v), 0.0);
    }
}
