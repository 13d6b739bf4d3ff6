//! The roofline's reference points on this machine: one core's FP32 peak, measured as
//! independent FMA chains in AVX2 (8 lanes) and, where the CPU has it, AVX-512 (16 lanes),
//! and the throughput of the `gemm` crate (`kernels::matrix::matmul`), the AVX-512 kernel and
//! the same-bits kernels (`kernels::chain_gemm`), one thread, at the shapes the hot paths multiply. Criterion's throughput is in elements: here one element is one
//! FLOP (a multiply-add counts 2), so `thrpt` reads directly as GFLOP/s when it prints
//! `Gelem/s`. BENCHMARKS.md's roofline table divides each path's measured GFLOP/s by these.
//!
//! `cargo bench -p kernels --bench roofline` (add `--profile dev` to reuse the test build's
//! optimised kernels instead of a release build).

// criterion_group! generates undocumented functions.
#![allow(missing_docs)]

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use kernels::chain_gemm::{self, Kernel};
use kernels::matrix::{View, ViewMut};

/// FMA rounds per call: long enough that the call's overhead is noise.
const ROUNDS: usize = 100_000;

/// Independent accumulators: FMA latency (4 cycles) × 2 FMA ports needs at least 8.
const CHAINS: usize = 12;

#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
#[target_feature(enable = "avx2,fma")]
fn fma_chains_avx2(rounds: usize, a: f32, b: f32) -> f32 {
    use std::arch::x86_64::*;
    let (va, vb) = (_mm256_set1_ps(a), _mm256_set1_ps(b));
    let mut acc = [_mm256_set1_ps(1.0); CHAINS];
    for _ in 0..rounds {
        for x in acc.iter_mut() {
            *x = _mm256_fmadd_ps(*x, va, vb);
        }
    }
    let mut sum = [0.0f32; 8];
    let total = acc.iter().fold(_mm256_setzero_ps(), |s, x| _mm256_add_ps(s, *x));
    // SAFETY: `sum` holds 8 floats, the width of one __m256 store; unaligned stores are allowed.
    unsafe { _mm256_storeu_ps(sum.as_mut_ptr(), total) };
    sum.iter().sum()
}

#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
#[target_feature(enable = "avx512f")]
fn fma_chains_avx512(rounds: usize, a: f32, b: f32) -> f32 {
    use std::arch::x86_64::*;
    let (va, vb) = (_mm512_set1_ps(a), _mm512_set1_ps(b));
    let mut acc = [_mm512_set1_ps(1.0); CHAINS];
    for _ in 0..rounds {
        for x in acc.iter_mut() {
            *x = _mm512_fmadd_ps(*x, va, vb);
        }
    }
    acc.iter().map(|x| _mm512_reduce_add_ps(*x)).sum()
}

fn peak(c: &mut Criterion) {
    let mut g = c.benchmark_group("fma_peak");
    #[cfg(target_arch = "x86_64")]
    {
        if is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma") {
            g.throughput(Throughput::Elements((ROUNDS * CHAINS * 8 * 2) as u64));
            g.bench_function("avx2", |bch| {
                // SAFETY: the CPU has AVX2 and FMA (checked just above).
                #[allow(unsafe_code)]
                bch.iter(|| unsafe {
                    fma_chains_avx2(black_box(ROUNDS), black_box(0.999_999), black_box(1e-7))
                })
            });
        }
        if is_x86_feature_detected!("avx512f") {
            g.throughput(Throughput::Elements((ROUNDS * CHAINS * 16 * 2) as u64));
            g.bench_function("avx512", |bch| {
                // SAFETY: the CPU has AVX-512F (checked just above).
                #[allow(unsafe_code)]
                bch.iter(|| unsafe {
                    fma_chains_avx512(black_box(ROUNDS), black_box(0.999_999), black_box(1e-7))
                })
            });
        }
    }
    g.finish();
}

/// `(name, m, k, n)`: the products the hot paths run most.
const SHAPES: [(&str, usize, usize, usize); 7] = [
    // The imported 96-channel U-Net's Winograd products: 96 × 96 weights by 8 images' 4×4
    // tiles of a 48² map (one of 16 per convolution).
    ("unet96_winograd", 96, 96, 8 * 24 * 24),
    // The same network's im2col products (its strided and 1×1-adjacent convolutions).
    ("unet96_im2col", 96, 96 * 9, 8 * 12 * 12),
    // The shipped latent U-Net (64 channels at 6², 3×3 im2col, a batch of 50 chunks).
    ("latent_unet64", 64, 64 * 9, 50 * 4 * 36),
    // The imported GPC policy's 1-D U-Net at 1024 channels, kernel 5, 8 episodes × 16 steps.
    ("policy_unet1024", 1024, 1024 * 5, 8 * 16),
    // Its other levels at batch 8: 512 channels at 8 steps, 1024 at 4.
    ("policy_unet512_b8", 512, 512 * 5, 8 * 8),
    ("policy_unet1024_b8_deep", 1024, 1024 * 5, 8 * 4),
    // One episode's decision (batch 1): 256 channels at its 16 steps.
    ("policy_unet256_b1", 256, 256 * 5, 16),
];

fn products(c: &mut Criterion) {
    let mut g = c.benchmark_group("gemm");
    g.sample_size(20);
    for (name, m, k, n) in SHAPES {
        // Values in [-1, 1): any fill costs the same; these stay finite.
        let fill =
            |len: usize, s: usize| (0..len).map(|i| ((i * 7919 + s) % 2000) as f32 / 1000.0 - 1.0).collect();
        let (a, b): (Vec<f32>, Vec<f32>) = (fill(m * k, 1), fill(k * n, 2));
        let mut out = vec![0.0f32; m * n];
        g.throughput(Throughput::Elements((2 * m * k * n) as u64));
        g.bench_function(format!("{name}/gemm_crate"), |bch| {
            bch.iter(|| kernels::matrix::matmul(m, k, n, black_box(&a), black_box(&b), &mut out, false))
        });
        if kernels::avx512_gemm::avx512_enabled() {
            g.bench_function(format!("{name}/avx512"), |bch| {
                bch.iter(|| {
                    kernels::avx512_gemm::fast_matmul(m, k, n, black_box(&a), black_box(&b), &mut out, false)
                })
            });
        }
        // The same-bits-everywhere kernels (kernels::chain_gemm), each forced.
        for kernel in [Kernel::Avx2, Kernel::Avx512] {
            g.bench_function(format!("{name}/chain_{kernel:?}"), |bch| {
                bch.iter(|| {
                    let (av, bv) = (View { data: black_box(&a), ld: k }, View { data: black_box(&b), ld: n });
                    chain_gemm::matmul_on(kernel, (m, k, n), av, bv, ViewMut { data: &mut out, ld: n }, false)
                })
            });
        }
    }
    g.finish();
}

criterion_group!(benches, peak, products);
criterion_main!(benches);
