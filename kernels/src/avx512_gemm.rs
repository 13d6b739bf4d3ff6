//! A single-precision matrix product for CPUs with AVX-512F: the world model's products
//! (its U-Net's Winograd, im2col, 1×1, temporal and attention projections) on 16-lane
//! registers, where the `gemm` crate as built here stops at AVX2.
//!
//! Why not the `gemm` crate's own AVX-512 kernels (its `x86-v4` feature): Cargo unifies
//! features, so they would run the policies' products too, and the policies' floats, hence
//! the MuJoCo branch's rows, would then differ between AVX2 and AVX-512 machines. This kernel
//! is called only where the world model multiplies ([`fast_matmul`], re-exported by `matrix`).
//!
//! Layout: `c[m, n] (+)= a[m, k] · b[k, n]`, row-major with row strides. A micro-tile is 8
//! rows × 32 columns of `c` held in 16 registers; each step of the depth loop broadcasts 8
//! values of `a`, loads 32 of `b` and issues 16 FMAs. Columns are walked in blocks of `NC`
//! (256) and depth in passes of `KC` (256); each pass copies its block of `b` into contiguous
//! panels of 32 columns (256 KB, in L2; read in place, rows a multiple of 4 KB apart fall into
//! a few of L1's sets and evict each other), then every 8-row block of `a` (8 KB, in L1, its
//! rows read in place as 8 streams) meets every panel, so a large `a` is read once per pass,
//! not once per panel. The last panel and the last row block are masked.
//!
//! Each element of `c` is one chain of FMAs in depth order (`acc = a·b + acc`, starting from
//! `c` or zero): exactly what a scalar `f32::mul_add` loop gives, whatever the blocking, the
//! thread count or the machine, which the tests check bit for bit.

#![cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]

#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::*;

use crate::elementwise::has_avx512f;
use crate::matrix::{View, ViewMut};

/// Rows of `c` per micro-tile.
const MR: usize = 8;
/// Columns of `c` per micro-tile: two 16-lane registers.
const NR: usize = 32;
/// Depth per pass: a `KC` × 32 panel of `b` is 32 KB.
const KC: usize = 256;
/// Columns per block: a pass's panels (`KC` × `NC`, 256 KB) stay in L2 while every row block
/// of `a` passes over them.
const NC: usize = 256;

/// `c (+)= a · b` like [`matmul_strided`](crate::matrix::matmul_strided), on this crate's AVX-512 kernel
/// (this module) where the CPU has AVX-512F, else on the `gemm` crate's (AVX2).
/// `EVALHARNESS_GEMM=crate` keeps the `gemm` crate's everywhere.
///
/// The two kernels sum in different orders, so their floats differ in the last bits: the
/// world model's products (whose branch is reproducible per machine) use this one; the
/// policies keep [`matmul`](crate::matrix::matmul), so the MuJoCo branch's rows are the same bytes on every x86-64
/// CPU with FMA.
///
/// # Panics
/// If a slice is too short for its shape and stride (a bug in the caller).
pub fn fast_matmul_strided(m: usize, k: usize, n: usize, a: View, b: View, c: ViewMut, accumulate: bool) {
    if m == 0 || n == 0 || k == 0 || !avx512_enabled() {
        return crate::matrix::matmul_strided(m, k, n, a, b, c, accumulate);
    }
    let need = |rows: usize, cols: usize, ld: usize| (rows - 1) * ld + cols;
    assert!(
        a.ld >= k
            && b.ld >= n
            && c.ld >= n
            && a.data.len() >= need(m, k, a.ld)
            && b.data.len() >= need(k, n, b.ld)
            && c.data.len() >= need(m, n, c.ld),
        "matmul shapes"
    );
    #[cfg(target_arch = "x86_64")]
    // SAFETY: the CPU has AVX-512F (`avx512_enabled`); the shapes are non-empty and each
    // slice holds every element its shape and row stride address (checked above).
    #[allow(unsafe_code)]
    unsafe {
        matmul((m, k, n), a.data, a.ld, b.data, b.ld, c.data, c.ld, accumulate)
    };
}

/// [`fast_matmul_strided`] for contiguous row-major `a: [m, k]`, `b: [k, n]`, `c: [m, n]`.
pub fn fast_matmul(m: usize, k: usize, n: usize, a: &[f32], b: &[f32], c: &mut [f32], accumulate: bool) {
    fast_matmul_strided(
        m,
        k,
        n,
        View { data: a, ld: k },
        View { data: b, ld: n },
        ViewMut { data: c, ld: n },
        accumulate,
    );
}

/// Whether [`fast_matmul_strided`] runs the AVX-512 kernel: the CPU has it and
/// `EVALHARNESS_GEMM` is not `crate` (read once).
pub fn avx512_enabled() -> bool {
    static ON: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *ON.get_or_init(|| has_avx512f() && std::env::var("EVALHARNESS_GEMM").map_or(true, |v| v != "crate"))
}

/// `c (+)= a · b` for `a: [m, k]` (row stride `lda`), `b: [k, n]` (`ldb`), `c: [m, n]`
/// (`ldc`); `accumulate` adds to `c` instead of overwriting it.
///
/// # Safety
/// The CPU has AVX-512F ([`has_avx512f`]); `m, k, n > 0`; `a` holds `(m − 1)·lda + k`
/// elements, `b` `(k − 1)·ldb + n` and `c` `(m − 1)·ldc + n` (every element the shapes and
/// strides address); `lda ≥ k`, `ldb ≥ n`, `ldc ≥ n`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
#[allow(clippy::too_many_arguments, unsafe_code)]
pub unsafe fn matmul(
    (m, k, n): (usize, usize, usize),
    a: &[f32],
    lda: usize,
    b: &[f32],
    ldb: usize,
    c: &mut [f32],
    ldc: usize,
    accumulate: bool,
) {
    let (a, b, c) = (a.as_ptr(), b.as_ptr(), c.as_mut_ptr());
    // The panels of b, copied contiguous: b's rows are often a multiple of 4 KB apart, and
    // read in place they fall into a few of L1's sets and evict each other.
    let mut panels = vec![0.0f32; KC * NC];
    for jc in (0..n).step_by(NC) {
        let nc = NC.min(n - jc);
        let count = nc.div_ceil(NR);
        for k0 in (0..k).step_by(KC) {
            let kc = KC.min(k - k0);
            for (q, panel) in panels.chunks_exact_mut(KC * NR).take(count).enumerate() {
                let [m0, m1] = panel_masks(nc - q * NR);
                let mut src = b.wrapping_add(k0 * ldb + jc + q * NR);
                for dst in panel.chunks_exact_mut(NR).take(kc) {
                    // SAFETY: row k0 + p < k of b, its unmasked columns < n (contract);
                    // `dst` holds NR = 32 floats. Masked lanes are not read.
                    unsafe {
                        _mm512_storeu_ps(dst.as_mut_ptr(), _mm512_maskz_loadu_ps(m0, src));
                        _mm512_storeu_ps(
                            dst.as_mut_ptr().add(16),
                            _mm512_maskz_loadu_ps(m1, src.wrapping_add(16)),
                        );
                    }
                    src = src.wrapping_add(ldb);
                }
            }
            let start = if accumulate || k0 > 0 { Start::FromC } else { Start::Zero };
            let mut i0 = 0;
            while i0 < m {
                let rows = MR.min(m - i0);
                // A row block of a (in L1) meets every panel of the block in turn, so a is
                // read once per pass, however many columns.
                for (q, panel) in panels.chunks_exact(KC * NR).take(count).enumerate() {
                    // SAFETY: rows i0..i0 + rows < m, depth k0..k0 + kc ≤ k and the panel's
                    // unmasked columns < n are inside the slices by the caller's contract;
                    // masked lanes are neither read nor written.
                    let t = unsafe {
                        Tile {
                            a: a.add(i0 * lda + k0),
                            lda,
                            b: panel.as_ptr(),
                            ldb: NR,
                            c: c.add(i0 * ldc + jc + q * NR),
                            ldc,
                            kc,
                            masks: panel_masks(nc - q * NR),
                            start,
                        }
                    };
                    // SAFETY: as above; the tile's rows are `rows`, its columns the masks'.
                    unsafe {
                        match rows {
                            8 => t.run::<8>(),
                            7 => t.run::<7>(),
                            6 => t.run::<6>(),
                            5 => t.run::<5>(),
                            4 => t.run::<4>(),
                            3 => t.run::<3>(),
                            2 => t.run::<2>(),
                            _ => t.run::<1>(),
                        }
                    }
                }
                i0 += rows;
            }
        }
    }
}

/// The lanes of a panel's two registers that hold columns (`cols` left in the row).
fn panel_masks(cols: usize) -> [u16; 2] {
    let lanes = |n: usize| if n >= 16 { u16::MAX } else { (1u16 << n) - 1 };
    [lanes(cols.min(NR)), lanes(cols.min(NR).saturating_sub(16))]
}

/// Where a pass's sums start.
#[derive(Clone, Copy)]
enum Start {
    /// From zero (the first pass of an overwriting product).
    Zero,
    /// From `c` (accumulating, or a later depth pass).
    FromC,
}

/// One micro-tile's pointers: its first element of `a`, `b` and `c`, their row strides.
struct Tile {
    a: *const f32,
    lda: usize,
    b: *const f32,
    ldb: usize,
    c: *mut f32,
    ldc: usize,
    kc: usize,
    masks: [u16; 2],
    start: Start,
}

#[cfg(target_arch = "x86_64")]
impl Tile {
    /// `R` rows of the tile over its `kc` steps of depth.
    ///
    /// # Safety
    /// AVX-512F; `R` rows of `a` hold `kc` readable elements each, `kc` rows of `b` and `R`
    /// rows of `c` hold the masks' lanes.
    #[target_feature(enable = "avx512f")]
    #[inline]
    #[allow(unsafe_code)]
    unsafe fn run<const R: usize>(&self) {
        let [m0, m1] = self.masks;
        // Row pointers, stepped by pointer additions: index arithmetic in the depth loop
        // would carry the debug build's overflow checks (the tests' and CI's build).
        // SAFETY: rows r < R of a and c start inside their slices (contract).
        let rows_a: [*const f32; R] = std::array::from_fn(|r| unsafe { self.a.add(r * self.lda) });
        let rows_c: [*mut f32; R] = std::array::from_fn(|r| unsafe { self.c.add(r * self.ldc) });
        let mut acc = [[_mm512_setzero_ps(); 2]; R];
        if let Start::FromC = self.start {
            for (row, &p) in acc.iter_mut().zip(&rows_c) {
                // SAFETY: row r of c and its unmasked lanes are inside `c` (contract).
                *row = unsafe { [_mm512_maskz_loadu_ps(m0, p), _mm512_maskz_loadu_ps(m1, p.add(16))] };
            }
        }
        let mut q = self.b;
        for p in 0..self.kc {
            // SAFETY: row p < kc of the panel of b, its unmasked lanes (contract).
            let (b0, b1) = unsafe { (_mm512_maskz_loadu_ps(m0, q), _mm512_maskz_loadu_ps(m1, q.add(16))) };
            for (row, &ra) in acc.iter_mut().zip(&rows_a) {
                // SAFETY: element (r, p) of the tile's rows of a (contract).
                let x = _mm512_set1_ps(unsafe { *ra.add(p) });
                row[0] = _mm512_fmadd_ps(x, b0, row[0]);
                row[1] = _mm512_fmadd_ps(x, b1, row[1]);
            }
            // SAFETY: one row of b further; past the panel's last row it is never read.
            q = q.wrapping_add(self.ldb);
        }
        for (row, &p) in acc.iter().zip(&rows_c) {
            // SAFETY: as for the loads of c.
            unsafe {
                _mm512_mask_storeu_ps(p, m0, row[0]);
                _mm512_mask_storeu_ps(p.add(16), m1, row[1]);
            }
        }
    }
}

#[cfg(all(test, target_arch = "x86_64"))]
mod tests {
    use super::*;
    use crate::elementwise::test_values;

    /// The scalar chain the kernel promises: per element, FMAs in depth order.
    fn reference(
        (m, k, n): (usize, usize, usize),
        a: &[f32],
        b: &[f32],
        c: &mut [f32],
        ldc: usize,
        acc: bool,
    ) {
        for i in 0..m {
            for j in 0..n {
                let mut s = if acc { c[i * ldc + j] } else { 0.0 };
                for p in 0..k {
                    s = a[i * k + p].mul_add(b[p * n + j], s);
                }
                c[i * ldc + j] = s;
            }
        }
    }

    #[test]
    fn equals_the_scalar_fma_chain_bit_for_bit() {
        if !has_avx512f() {
            eprintln!("no AVX-512F on this CPU: the kernel is never called here");
            return;
        }
        // Shapes around every edge: rows short of a tile (1, 7), a tile and a bit (9, 17),
        // columns short of a register (5), of a panel (20), a panel and a bit (33, 70),
        // depth across a pass boundary (KC + 3), and the U-Net's 96 × 96 Winograd product.
        let shapes = [(1, 1, 1), (7, 3, 5), (9, 4, 20), (17, 300, 33), (8, 259, 70), (96, 96, 64)];
        for (i, &(m, k, n)) in shapes.iter().enumerate() {
            let (a, b) = (test_values(m * k, i as u32), test_values(k * n, 100 + i as u32));
            // c with a wider row stride than n, and values past each row that must survive.
            let ldc = n + 3;
            for acc in [false, true] {
                let mut want = test_values(m * ldc, 200 + i as u32);
                let mut got = want.clone();
                reference((m, k, n), &a, &b, &mut want, ldc, acc);
                // SAFETY: checked has_avx512f() above; the slices hold the shapes exactly.
                #[allow(unsafe_code)]
                unsafe {
                    matmul((m, k, n), &a, k, &b, n, &mut got, ldc, acc)
                };
                assert!(
                    want.iter().zip(&got).all(|(x, y)| x.to_bits() == y.to_bits()),
                    "{m}×{k}×{n}, accumulate {acc}: differs from the scalar chain"
                );
            }
        }
    }

    #[test]
    fn masks_cover_exactly_the_columns_left() {
        assert_eq!(panel_masks(1), [1, 0]);
        assert_eq!(panel_masks(16), [u16::MAX, 0]);
        assert_eq!(panel_masks(20), [u16::MAX, 0b1111]);
        assert_eq!(panel_masks(32), [u16::MAX, u16::MAX]);
        assert_eq!(panel_masks(100), [u16::MAX, u16::MAX]);
    }
}
