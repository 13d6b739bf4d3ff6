//! The AVX2 + FMA kernels of [`super`]: the input and output transforms with
//! explicit shuffles (the stride-2 tile columns of a bordered row split into even
//! and odd lanes) and the register-tiled products. Called only after
//! [`crate::elementwise::has_avx2_fma`] has confirmed both features.

use std::arch::x86_64::{
    __m256, _mm256_add_ps, _mm256_castpd_ps, _mm256_castps_pd, _mm256_fmadd_ps, _mm256_loadu_ps,
    _mm256_permute2f128_ps, _mm256_permute4x64_pd, _mm256_set1_ps, _mm256_setzero_ps, _mm256_shuffle_ps,
    _mm256_storeu_ps, _mm256_sub_ps, _mm256_unpackhi_ps, _mm256_unpacklo_ps,
};

use super::{LANES, OUT, Pass, Scratch, VECS, Winograd3x3};
use crate::padded::Padded;

/// `[a0 a2 a4 a6 b0 b2 b4 b6]` and `[a1 a3 a5 a7 b1 b3 b5 b7]`.
#[inline]
#[target_feature(enable = "avx2,fma")]
fn split(a: __m256, b: __m256) -> (__m256, __m256) {
    let e = _mm256_shuffle_ps::<0x88>(a, b); // [a0 a2 b0 b2 | a4 a6 b4 b6]
    let o = _mm256_shuffle_ps::<0xDD>(a, b); // [a1 a3 b1 b3 | a5 a7 b5 b7]
    (
        _mm256_castpd_ps(_mm256_permute4x64_pd::<0xD8>(_mm256_castps_pd(e))),
        _mm256_castpd_ps(_mm256_permute4x64_pd::<0xD8>(_mm256_castps_pd(o))),
    )
}

/// The first four columns of 8 stride-2 tiles starting at `src[0]`: `[d0, d1, d2, d3]`,
/// lane `k` of `dq` being `src[2k + q]`. Fewer than 18 values left in `src` (the end of
/// a bordered row) are read through `buf`, zero-padded. Shared by this module's input
/// transform and [`super::upsample`]'s.
#[inline]
#[target_feature(enable = "avx2,fma")]
#[allow(unsafe_code)]
pub(super) fn tile_columns(src: &[f32], buf: &mut [f32; 2 * LANES + 2]) -> [__m256; 4] {
    let d: &[f32] = if src.len() >= buf.len() {
        &src[..buf.len()]
    } else {
        buf.fill(0.0);
        buf.iter_mut().zip(src).for_each(|(a, &b)| *a = b);
        buf
    };
    // SAFETY: `d` holds 18 floats, so loads at offsets 0, 8, 2 and 10 are in bounds.
    unsafe {
        let p = d.as_ptr();
        let (d0, d1) = split(_mm256_loadu_ps(p), _mm256_loadu_ps(p.add(8)));
        let (d2, d3) = split(_mm256_loadu_ps(p.add(2)), _mm256_loadu_ps(p.add(10)));
        [d0, d1, d2, d3]
    }
}

/// Stores the first `n` (at most 8) lanes of `val` at the start of `dst`: one vector
/// store for a whole run, through a bounce buffer for a row's last, partial one.
#[inline]
#[target_feature(enable = "avx2,fma")]
#[allow(unsafe_code)]
pub(super) fn store_run(dst: &mut [f32], n: usize, val: __m256) {
    if n == LANES {
        let d = &mut dst[..LANES];
        // SAFETY: `d` holds 8 floats.
        unsafe { _mm256_storeu_ps(d.as_mut_ptr(), val) };
    } else {
        let mut tail = [0.0f32; LANES];
        // SAFETY: `tail` holds 8 floats.
        unsafe { _mm256_storeu_ps(tail.as_mut_ptr(), val) };
        dst[..n].copy_from_slice(&tail[..n]);
    }
}

/// [`transform_input_impl`] with AVX2 intrinsics: the even and odd columns of each
/// row are split with two shuffles each ([`tile_columns`]), and all 16 transformed
/// runs of 8 tiles stay in registers until stored.
#[target_feature(enable = "avx2,fma")]
pub(super) fn transform_input_avx2(x: &Padded, ty: usize, s: &mut Scratch, at: usize) {
    let (tw, cin, nk) = (s.row_tiles, s.cin, s.tiles);
    let mut buf = [0.0f32; 2 * LANES + 2];
    for ci in 0..cin {
        for x0 in (0..tw).step_by(LANES) {
            let n = LANES.min(tw - x0);
            // Row r's transform along x: [d0 - d2, d1 + d2, d2 - d1, d1 - d3] for 8 tiles.
            let mut along_x = |r: usize| {
                let [d0, d1, d2, d3] = tile_columns(&x.bordered_row(ci, 2 * ty + r)[2 * x0..], &mut buf);
                [_mm256_sub_ps(d0, d2), _mm256_add_ps(d1, d2), _mm256_sub_ps(d2, d1), _mm256_sub_ps(d1, d3)]
            };
            let t0 = along_x(0);
            let t1 = along_x(1);
            let t2 = along_x(2);
            let t3 = along_x(3);
            let base = ci * 16 * nk + at + x0;
            let mut store = |p: usize, v: __m256| store_run(&mut s.v[p * nk + base..], n, v);
            // Along y: v[i * 4 + j] from column j of the four rows.
            for j in 0..4 {
                store(j, _mm256_sub_ps(t0[j], t2[j]));
                store(4 + j, _mm256_add_ps(t1[j], t2[j]));
                store(8 + j, _mm256_sub_ps(t2[j], t1[j]));
                store(12 + j, _mm256_sub_ps(t1[j], t3[j]));
            }
        }
    }
}

/// [`transform_output_impl`] with AVX2 intrinsics: 16 runs of 8 products loaded,
/// transformed in registers, interleaved into two rows of 16 pixels with unpack and
/// lane permutes.
#[target_feature(enable = "avx2,fma")]
#[allow(unsafe_code)]
pub(super) fn transform_output_avx2(
    k: &Winograd3x3,
    s: &Scratch,
    pass: &Pass,
    residual: Option<&[f32]>,
    out: &mut [f32],
) {
    let (tw, nk) = (s.row_tiles, s.tiles);
    let (h, w) = (pass.h, pass.w);
    let mut px = [0.0f32; 2 * LANES];
    for co in 0..k.cout {
        let b = _mm256_set1_ps(k.bias[co]);
        for r in 0..pass.rows {
            let (oy, k0) = (2 * (pass.ty0 + r), r * tw);
            for x0 in (0..tw).step_by(LANES) {
                let n = LANES.min(tw - x0);
                let base = co * 16 * nk + k0 + x0;
                let m = |p: usize| {
                    let src = &s.m[p * nk + base..][..LANES];
                    // SAFETY: `src` holds 8 floats (products past a row's last tile belong
                    // to the next row or channel, or to the padding; they are never written out).
                    unsafe { _mm256_loadu_ps(src.as_ptr()) }
                };
                // Along y (Aᵀ over i): s0 = m0 + m1 + m2, s1 = m1 - m2 - m3, per column j.
                let (mut s0, mut s1) = ([b; 4], [b; 4]);
                for j in 0..4 {
                    let (m0, m1, m2, m3) = (m(j), m(4 + j), m(8 + j), m(12 + j));
                    s0[j] = _mm256_add_ps(_mm256_add_ps(m0, m1), m2);
                    s1[j] = _mm256_sub_ps(_mm256_sub_ps(m1, m2), m3);
                }
                for (dy, sd) in [s0, s1].iter().enumerate() {
                    // Along x: even pixels (plus the bias once), odd pixels.
                    let e = _mm256_add_ps(_mm256_add_ps(_mm256_add_ps(sd[0], sd[1]), sd[2]), b);
                    let o = _mm256_add_ps(_mm256_sub_ps(_mm256_sub_ps(sd[1], sd[2]), sd[3]), b);
                    let (lo, hi) = (_mm256_unpacklo_ps(e, o), _mm256_unpackhi_ps(e, o));
                    let first = _mm256_permute2f128_ps::<0x20>(lo, hi);
                    let second = _mm256_permute2f128_ps::<0x31>(lo, hi);
                    let at = (co * h + oy + dy) * w + 2 * x0;
                    if n == LANES {
                        let dst = &mut out[at..at + 2 * LANES];
                        let (mut first, mut second) = (first, second);
                        if let Some(res) = residual {
                            let rs = &res[at..at + 2 * LANES];
                            // SAFETY: `rs` holds 16 floats.
                            unsafe {
                                first = _mm256_add_ps(first, _mm256_loadu_ps(rs.as_ptr()));
                                second = _mm256_add_ps(second, _mm256_loadu_ps(rs.as_ptr().add(8)));
                            }
                        }
                        // SAFETY: `dst` holds 16 floats.
                        unsafe {
                            _mm256_storeu_ps(dst.as_mut_ptr(), first);
                            _mm256_storeu_ps(dst.as_mut_ptr().add(8), second);
                        }
                    } else {
                        // SAFETY: `px` holds 16 floats.
                        unsafe {
                            _mm256_storeu_ps(px.as_mut_ptr(), first);
                            _mm256_storeu_ps(px.as_mut_ptr().add(8), second);
                        }
                        let dst = &mut out[at..at + 2 * n];
                        for (i, d) in dst.iter_mut().enumerate() {
                            *d = px[i] + residual.map_or(0.0, |r| r[at + i]);
                        }
                    }
                }
            }
        }
    }
}

/// The matrix products with AVX2 + FMA: a 4-channel x 24-tile block of sums in twelve
/// registers through the whole reduction (fewer tiles at the end of a pass). For each of
/// `points` positions `p`, `m[·, p, ·] = u[p]ᵀ v[·, p, ·]`: `u` `[points, blocks, cin, 4]`,
/// `v` `[cin, points, nk]`, `m` `[blocks · 4, points, nk]` (`nk` a whole number of vectors).
#[target_feature(enable = "avx2,fma")]
#[allow(unsafe_code)]
pub(super) fn products_avx2_fma(u: &[f32], cin: usize, points: usize, v: &[f32], m: &mut [f32], nk: usize) {
    let blocks = u.len() / (points * cin * OUT);
    let stride = points * nk;
    for p in 0..points {
        let v = &v[p * nk..];
        for b in 0..blocks {
            let wb = &u[(p * blocks + b) * cin * OUT..][..cin * OUT];
            let m = &mut m[(b * OUT * points + p) * nk..];
            let mut t = 0;
            while t < nk {
                match (nk - t) / LANES {
                    1 => block::<1>(wb, v, m, cin, stride, nk, t),
                    2 => block::<2>(wb, v, m, cin, stride, nk, t),
                    _ => block::<VECS>(wb, v, m, cin, stride, nk, t),
                }
                t += LANES * VECS.min((nk - t) / LANES);
            }
        }
    }
}

/// One register block: `N` vectors of tiles from tile `t`, 4 output channels; rows
/// (input channels of `v`, output channels of `m`) are `stride` floats apart.
#[target_feature(enable = "avx2,fma")]
#[allow(unsafe_code)]
fn block<const N: usize>(
    wb: &[f32],
    v: &[f32],
    m: &mut [f32],
    cin: usize,
    stride: usize,
    nk: usize,
    t: usize,
) {
    assert!(wb.len() >= cin * OUT && t + N * LANES <= nk);
    assert!(v.len() >= (cin - 1) * stride + nk && m.len() >= (OUT - 1) * stride + nk);
    let mut acc = [[_mm256_setzero_ps(); N]; OUT];
    for ci in 0..cin {
        // SAFETY: ci < cin and t + N·8 <= nk (asserted above), so every load is within `v`.
        let x: [_; N] =
            std::array::from_fn(|n| unsafe { _mm256_loadu_ps(v.as_ptr().add(ci * stride + t + n * LANES)) });
        let w = &wb[ci * OUT..ci * OUT + OUT];
        for (aj, &wj) in acc.iter_mut().zip(w) {
            let wv = _mm256_set1_ps(wj);
            for (a, &xn) in aj.iter_mut().zip(&x) {
                *a = _mm256_fmadd_ps(wv, xn, *a);
            }
        }
    }
    for (j, aj) in acc.iter().enumerate() {
        for (n, a) in aj.iter().enumerate() {
            // SAFETY: j < 4 and t + N·8 <= nk (asserted above), so the store is within `m`.
            unsafe { _mm256_storeu_ps(m.as_mut_ptr().add(j * stride + t + n * LANES), *a) };
        }
    }
}
