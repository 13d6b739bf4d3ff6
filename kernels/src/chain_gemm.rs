//! A single-precision matrix product whose floats are the same on every CPU: each element of
//! `c` is one chain of FMAs in depth order (`acc = a·b + acc`, from `c` or zero), whether it
//! runs on AVX-512 registers ([`crate::avx512_gemm`]), AVX2 ones (here), or a scalar
//! `f32::mul_add` loop (here, for CPUs with neither).
//!
//! Why: a policy's actions feed back into its MuJoCo episode, so a product that rounds
//! differently on another machine gives that machine other rows. The `gemm` crate's kernels
//! split the depth into blocks summed apart, and which kernel it runs depends on the CPU; the
//! project's AVX-512 kernel alone is fast but exists only where the CPU has AVX-512. Since
//! every kernel here is the same chain, the dispatch may pick whichever is fastest for a shape
//! (16-lane tiles for wide products, 8-lane ones for narrow) without changing a bit.
//!
//! Layout: `c[m, n] (+)= a[m, k] · b[k, n]`, row-major with row strides. The AVX2 micro-tile is
//! 6 rows × 16 columns of `c` in 12 registers; each step of the depth loop broadcasts 6 values
//! of `a`, loads 16 of `b` and issues 12 FMAs. Columns are walked in blocks of `NC` (256) and
//! depth in passes of `KC` (256); each pass copies its block of `b` into contiguous panels of
//! 16 columns (256 KB, in L2), then every 6-row block of `a` (6 KB, in L1) meets every panel,
//! so `a` (the policies' weights, megabytes) is read once per pass, not once per panel. The
//! last panel and row block are masked.

#![cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]

#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::*;

use crate::elementwise::{has_avx2_fma, has_avx512f};
use crate::matrix::{View, ViewMut};

/// Rows of `c` per AVX2 micro-tile.
const MR: usize = 6;
/// Columns of `c` per AVX2 micro-tile: two 8-lane registers.
const NR: usize = 16;
/// Depth per pass: a `KC` × 16 panel of `b` is 16 KB.
const KC: usize = 256;
/// Columns per block: the block's panels (`KC` × `NC`, 256 KB) stay in L2 while every row
/// block of `a` passes over them.
const NC: usize = 256;
/// Products at least this wide run on the AVX-512 kernel where the CPU has it (its tiles are
/// 32 columns wide; narrower ones would leave its registers half empty).
const WIDE: usize = 32;

/// Which kernel runs a product: any of them gives the same bits.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kernel {
    /// [`crate::avx512_gemm`]'s 8 × 32 tiles.
    Avx512,
    /// This module's 6 × 16 tiles.
    Avx2,
    /// A scalar `f32::mul_add` loop.
    Scalar,
}

/// The kernel [`matmul_strided`] runs for a product `n` columns wide on this CPU.
pub fn kernel_for(n: usize) -> Kernel {
    if n >= WIDE && has_avx512f() {
        Kernel::Avx512
    } else if has_avx2_fma() {
        Kernel::Avx2
    } else {
        Kernel::Scalar
    }
}

/// `c (+)= a · b` for contiguous row-major `a: [m, k]`, `b: [k, n]`, `c: [m, n]`, the same
/// bits on every CPU (this module).
pub fn matmul(m: usize, k: usize, n: usize, a: &[f32], b: &[f32], c: &mut [f32], accumulate: bool) {
    let (a, b, c) = (View { data: a, ld: k }, View { data: b, ld: n }, ViewMut { data: c, ld: n });
    matmul_strided(m, k, n, a, b, c, accumulate);
}

/// `c (+)= a · b` with row strides, on the fastest of this module's kernels for the shape.
///
/// # Panics
/// If a slice is too short for its shape and stride (a bug in the caller).
pub fn matmul_strided(m: usize, k: usize, n: usize, a: View, b: View, c: ViewMut, accumulate: bool) {
    matmul_on(kernel_for(n), (m, k, n), a, b, c, accumulate);
}

/// [`matmul_strided`] on a chosen kernel (the tests compare them); a kernel this CPU lacks
/// falls back to the scalar loop.
///
/// # Panics
/// If a slice is too short for its shape and stride (a bug in the caller).
pub fn matmul_on(
    kernel: Kernel,
    (m, k, n): (usize, usize, usize),
    a: View,
    b: View,
    c: ViewMut,
    accumulate: bool,
) {
    if m == 0 || n == 0 {
        return;
    }
    let need = |rows: usize, cols: usize, ld: usize| if cols == 0 { 0 } else { (rows - 1) * ld + cols };
    assert!(
        a.ld >= k
            && b.ld >= n
            && c.ld >= n
            && a.data.len() >= need(m, k, a.ld)
            && (k == 0 || b.data.len() >= need(k, n, b.ld))
            && c.data.len() >= need(m, n, c.ld),
        "matmul shapes"
    );
    if k == 0 {
        if !accumulate {
            c.data.chunks_mut(c.ld).take(m).for_each(|row| row[..n].fill(0.0));
        }
        return;
    }
    match kernel {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: the CPU has AVX-512F (checked here); m, k, n > 0 and every slice holds the
        // elements its shape and stride address (asserted above).
        #[allow(unsafe_code)]
        Kernel::Avx512 if has_avx512f() => unsafe {
            crate::avx512_gemm::matmul((m, k, n), a.data, a.ld, b.data, b.ld, c.data, c.ld, accumulate);
        },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as above, with AVX2 and FMA.
        #[allow(unsafe_code)]
        Kernel::Avx2 | Kernel::Avx512 if has_avx2_fma() => unsafe {
            avx2((m, k, n), a.data, a.ld, b.data, b.ld, c.data, c.ld, accumulate);
        },
        _ => scalar((m, k, n), a, b, c, accumulate),
    }
}

/// The chain itself, row by row: for each row of `c`, depth in order, every column.
fn scalar((m, k, n): (usize, usize, usize), a: View, b: View, c: ViewMut, accumulate: bool) {
    for i in 0..m {
        let row = &mut c.data[i * c.ld..i * c.ld + n];
        if !accumulate {
            row.fill(0.0);
        }
        for p in 0..k {
            let x = a.data[i * a.ld + p];
            let bp = &b.data[p * b.ld..p * b.ld + n];
            row.iter_mut().zip(bp).for_each(|(s, &y)| *s = x.mul_add(y, *s));
        }
    }
}

/// The AVX2 kernel: `c (+)= a · b` for `a: [m, k]` (row stride `lda`), `b: [k, n]` (`ldb`),
/// `c: [m, n]` (`ldc`).
///
/// # Safety
/// The CPU has AVX2 and FMA ([`has_avx2_fma`]); `m, k, n > 0`; `a` holds `(m − 1)·lda + k`
/// elements, `b` `(k − 1)·ldb + n` and `c` `(m − 1)·ldc + n`; `lda ≥ k`, `ldb ≥ n`, `ldc ≥ n`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[allow(clippy::too_many_arguments, unsafe_code)]
unsafe fn avx2(
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
    let mut panels = vec![0.0f32; KC * NC];
    for jc in (0..n).step_by(NC) {
        let nc = NC.min(n - jc);
        for k0 in (0..k).step_by(KC) {
            let kc = KC.min(k - k0);
            // Every panel of this column block, each kc × 16 contiguous (zeros past column n).
            for (q, panel) in panels.chunks_exact_mut(KC * NR).take(nc.div_ceil(NR)).enumerate() {
                let masks = panel_masks(nc - q * NR);
                let mut src = b.wrapping_add(k0 * ldb + jc + q * NR);
                for dst in panel.chunks_exact_mut(NR).take(kc) {
                    // SAFETY: row k0 + p < k of b, its unmasked columns < n (contract); `dst`
                    // holds NR = 16 floats. Masked lanes are not read (and stored as zeros).
                    unsafe {
                        _mm256_storeu_ps(dst.as_mut_ptr(), _mm256_maskload_ps(src, masks[0]));
                        _mm256_storeu_ps(
                            dst.as_mut_ptr().add(8),
                            _mm256_maskload_ps(src.wrapping_add(8), masks[1]),
                        );
                    }
                    src = src.wrapping_add(ldb);
                }
            }
            let from_c = accumulate || k0 > 0;
            let mut i0 = 0;
            while i0 < m {
                let rows = MR.min(m - i0);
                // A row block of a (rows × kc, in L1) meets every panel in turn: a is read once
                // per pass, whatever n.
                for (q, panel) in panels.chunks_exact(KC * NR).take(nc.div_ceil(NR)).enumerate() {
                    let t = Tile {
                        a: a.wrapping_add(i0 * lda + k0),
                        lda,
                        b: panel.as_ptr(),
                        c: c.wrapping_add(i0 * ldc + jc + q * NR),
                        ldc,
                        kc,
                        masks: panel_masks(nc - q * NR),
                        from_c,
                    };
                    // SAFETY: rows i0..i0 + rows < m, depth k0..k0 + kc ≤ k and the panel's
                    // unmasked columns < n are inside the slices by the caller's contract;
                    // masked lanes of c are neither read nor written.
                    unsafe {
                        match rows {
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

/// The lanes of a panel's two registers that hold columns (`cols` left in the row): all bits
/// set in a lane that is loaded and stored.
#[cfg(target_arch = "x86_64")]
fn panel_masks(cols: usize) -> [__m256i; 2] {
    let lane = |i: usize| if i < cols { -1i32 } else { 0 };
    // SAFETY: `_mm256_setr_epi32` needs only AVX, which every caller of the AVX2 kernel has;
    // building a register from integers touches no memory.
    #[allow(unsafe_code)]
    let reg = |o: usize| unsafe {
        _mm256_setr_epi32(
            lane(o),
            lane(o + 1),
            lane(o + 2),
            lane(o + 3),
            lane(o + 4),
            lane(o + 5),
            lane(o + 6),
            lane(o + 7),
        )
    };
    [reg(0), reg(8)]
}

/// One micro-tile's pointers: its first element of `a`, the panel of `b` and `c`.
#[cfg(target_arch = "x86_64")]
struct Tile {
    a: *const f32,
    lda: usize,
    b: *const f32,
    c: *mut f32,
    ldc: usize,
    kc: usize,
    masks: [__m256i; 2],
    /// The sums start from `c` (accumulating, or a later depth pass), else from zero.
    from_c: bool,
}

#[cfg(target_arch = "x86_64")]
impl Tile {
    /// `R` rows of the tile over its `kc` steps of depth.
    ///
    /// # Safety
    /// AVX2 and FMA; `R` rows of `a` hold `kc` readable elements each, the panel `kc` rows of
    /// 16, and `R` rows of `c` the masks' lanes.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    #[allow(unsafe_code)]
    unsafe fn run<const R: usize>(&self) {
        let [m0, m1] = self.masks;
        // Row pointers, stepped by pointer additions (no overflow checks in the debug build's
        // depth loop).
        let rows_a: [*const f32; R] = std::array::from_fn(|r| self.a.wrapping_add(r * self.lda));
        let rows_c: [*mut f32; R] = std::array::from_fn(|r| self.c.wrapping_add(r * self.ldc));
        let mut acc = [[_mm256_setzero_ps(); 2]; R];
        if self.from_c {
            for (row, &p) in acc.iter_mut().zip(&rows_c) {
                // SAFETY: row r of c and its unmasked lanes are inside `c` (contract).
                *row = unsafe { [_mm256_maskload_ps(p, m0), _mm256_maskload_ps(p.add(8), m1)] };
            }
        }
        let mut q = self.b;
        for p in 0..self.kc {
            // SAFETY: row p < kc of the panel (16 floats each).
            let (b0, b1) = unsafe { (_mm256_loadu_ps(q), _mm256_loadu_ps(q.add(8))) };
            for (row, &ra) in acc.iter_mut().zip(&rows_a) {
                // SAFETY: element (r, p) of the tile's rows of a (contract).
                let x = _mm256_set1_ps(unsafe { *ra.add(p) });
                row[0] = _mm256_fmadd_ps(x, b0, row[0]);
                row[1] = _mm256_fmadd_ps(x, b1, row[1]);
            }
            q = q.wrapping_add(NR);
        }
        for (row, &p) in acc.iter().zip(&rows_c) {
            // SAFETY: as for the loads of c.
            unsafe {
                _mm256_maskstore_ps(p, m0, row[0]);
                _mm256_maskstore_ps(p.add(8), m1, row[1]);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::elementwise::test_values;

    #[test]
    fn every_kernel_gives_the_scalar_chains_bits() {
        // Shapes around every edge of both tile sizes: rows short of a tile (1, 5, 7), a tile and
        // a bit (9, 13, 17), columns short of an 8-lane register (5), of a 16-wide panel (12), of
        // a 32-wide one (20), a panel and a bit (33, 70), depth across a pass (KC + 3), and the
        // policy U-Net's shapes at batch 1 and 8 (16 and 128 columns, depth 3·256).
        let shapes = [
            (1, 1, 1),
            (7, 3, 5),
            (5, 4, 12),
            (9, 4, 20),
            (13, 300, 33),
            (17, 259, 70),
            (256, 768, 16),
            (64, 768, 128),
        ];
        let kernels = [Kernel::Avx512, Kernel::Avx2, Kernel::Scalar];
        for (i, &(m, k, n)) in shapes.iter().enumerate() {
            let (a, b) = (test_values(m * k, i as u32), test_values(k * n, 100 + i as u32));
            // c with a wider row stride than n, and values past each row that must survive.
            let ldc = n + 3;
            for acc in [false, true] {
                let start = test_values(m * ldc, 200 + i as u32);
                let mut want = start.clone();
                for row in 0..m {
                    for j in 0..n {
                        let mut s = if acc { want[row * ldc + j] } else { 0.0 };
                        for p in 0..k {
                            s = a[row * k + p].mul_add(b[p * n + j], s);
                        }
                        want[row * ldc + j] = s;
                    }
                }
                for kernel in kernels {
                    let mut got = start.clone();
                    let (av, bv) = (View { data: &a, ld: k }, View { data: &b, ld: n });
                    matmul_on(kernel, (m, k, n), av, bv, ViewMut { data: &mut got, ld: ldc }, acc);
                    assert!(
                        want.iter().zip(&got).all(|(x, y)| x.to_bits() == y.to_bits()),
                        "{kernel:?} on {m}×{k}×{n}, accumulate {acc}: differs from the scalar chain"
                    );
                }
            }
        }
    }

    #[test]
    fn an_empty_depth_zeroes_or_keeps_c() {
        let mut c = vec![1.5f32; 6];
        matmul(2, 0, 3, &[], &[], &mut c, true);
        assert_eq!(c, vec![1.5; 6]);
        matmul(2, 0, 3, &[], &[], &mut c, false);
        assert_eq!(c, vec![0.0; 6]);
    }

    #[test]
    fn wide_products_take_the_widest_kernel_the_cpu_has() {
        let narrow = if has_avx2_fma() { Kernel::Avx2 } else { Kernel::Scalar };
        assert_eq!(kernel_for(16), narrow);
        assert_eq!(kernel_for(WIDE), if has_avx512f() { Kernel::Avx512 } else { narrow });
    }
}
