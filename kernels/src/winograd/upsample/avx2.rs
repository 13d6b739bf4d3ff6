//! The AVX2 transforms of [`super`]: 8 tiles per vector, the stride-2 tile columns
//! of a bordered row split into even and odd lanes (the per-image Winograd kernel's
//! [`tile_columns`]), and the two column phases' outputs interleaved into runs of 32
//! pixels. Called only after
//! [`crate::elementwise::has_avx2_fma`] has confirmed AVX2 and FMA.

use std::arch::x86_64::{
    __m256, _mm256_add_ps, _mm256_castpd_ps, _mm256_castps_pd, _mm256_loadu_ps, _mm256_permute2f128_ps,
    _mm256_set1_ps, _mm256_setzero_ps, _mm256_storeu_ps, _mm256_sub_ps, _mm256_unpackhi_pd,
    _mm256_unpackhi_ps, _mm256_unpacklo_pd, _mm256_unpacklo_ps,
};

use super::super::avx2::{store_run, tile_columns};
use super::{LANES, Pass, Tiles, Upsample3x3};
use crate::padded::Padded;

/// [`super::transform_input`] for 8 tiles at a time: each of the 3 rows' 17 columns
/// split into the tiles' columns `d0, d1, d2` ([`tile_columns`]), `[d0 − d1, d1, d2 − d1]`
/// along x, the same along y, 9 runs of 8 tiles stored.
#[target_feature(enable = "avx2,fma")]
pub(super) fn transform_input_avx2(x: &Padded, t: &Tiles, ty: usize, v: &mut [f32], at: usize) {
    let mut buf = [0.0f32; 2 * LANES + 2];
    for ci in 0..x.channels() {
        for x0 in (0..t.tw).step_by(LANES) {
            let n = LANES.min(t.tw - x0);
            let mut along_x = |r: usize| {
                let src = &x.bordered_row(ci, 2 * ty + t.a + r)[2 * x0 + t.b..];
                let [d0, d1, d2, _] = tile_columns(src, &mut buf);
                [_mm256_sub_ps(d0, d1), d1, _mm256_sub_ps(d2, d1)]
            };
            let (t0, t1, t2) = (along_x(0), along_x(1), along_x(2));
            let base = ci * 9 * t.nk + at + x0;
            let mut store = |p: usize, val: __m256| store_run(&mut v[p * t.nk + base..], n, val);
            for j in 0..3 {
                store(j, _mm256_sub_ps(t0[j], t1[j]));
                store(3 + j, t1[j]);
                store(6 + j, _mm256_sub_ps(t2[j], t1[j]));
            }
        }
    }
}

/// [`super::transform_output`] for 8 tiles at a time: per column phase, 9 runs of
/// products to the 2x2 outputs (Aᵀ along y, then x, plus the bias); each output row's
/// four values per tile (phase b = 0 and 1 of columns 2dx) interleaved into 32 pixels.
#[target_feature(enable = "avx2,fma")]
#[allow(unsafe_code)]
pub(super) fn transform_output_avx2(k: &Upsample3x3, m: &[Vec<f32>; 2], p: &Pass, out: &mut [f32]) {
    let mut px = [0.0f32; 4 * LANES];
    for co in 0..k.cout {
        let bias = _mm256_set1_ps(k.bias[co]);
        for r in 0..p.rows {
            let ty = p.ty0 + r;
            for x0 in (0..p.tw).step_by(LANES) {
                let n = LANES.min(p.tw - x0);
                // y[b][dy][dx] for 8 tiles: Aᵀ along y (rows dy, dy + 1), then x, plus the bias.
                let mut y = [[[_mm256_setzero_ps(); 2]; 2]; 2];
                let base = co * 9 * p.nk + r * p.tw + x0;
                for (yb, mb) in y.iter_mut().zip(m) {
                    let src = &mb[base..];
                    assert!(src.len() >= 8 * p.nk + LANES);
                    // SAFETY: point i < 9, so the run of 8 ends within `src` (asserted above;
                    // products past a row's last tile belong to the next row or channel, or
                    // to the padding, and are never written out).
                    let mv: [__m256; 9] =
                        std::array::from_fn(|i| unsafe { _mm256_loadu_ps(src.as_ptr().add(i * p.nk)) });
                    for (dy, ybd) in yb.iter_mut().enumerate() {
                        let s: [__m256; 3] =
                            std::array::from_fn(|j| _mm256_add_ps(mv[dy * 3 + j], mv[dy * 3 + 3 + j]));
                        let s1b = _mm256_add_ps(s[1], bias);
                        *ybd = [_mm256_add_ps(s[0], s1b), _mm256_add_ps(s1b, s[2])];
                    }
                }
                for (dy, (y0, y1)) in y[0].iter().zip(&y[1]).enumerate() {
                    // Per tile: (dx 0, b 0), (dx 0, b 1), (dx 1, b 0), (dx 1, b 1).
                    let (e0, e1, o0, o1) = (y0[0], y1[0], y0[1], y1[1]);
                    let (lo_e, hi_e) = (_mm256_unpacklo_ps(e0, e1), _mm256_unpackhi_ps(e0, e1));
                    let (lo_o, hi_o) = (_mm256_unpacklo_ps(o0, o1), _mm256_unpackhi_ps(o0, o1));
                    let pd = _mm256_castps_pd;
                    // Tiles 0|4, 1|5, 2|6 and 3|7, four pixels each.
                    let t04 = _mm256_castpd_ps(_mm256_unpacklo_pd(pd(lo_e), pd(lo_o)));
                    let t15 = _mm256_castpd_ps(_mm256_unpackhi_pd(pd(lo_e), pd(lo_o)));
                    let t26 = _mm256_castpd_ps(_mm256_unpacklo_pd(pd(hi_e), pd(hi_o)));
                    let t37 = _mm256_castpd_ps(_mm256_unpackhi_pd(pd(hi_e), pd(hi_o)));
                    let runs = [
                        _mm256_permute2f128_ps::<0x20>(t04, t15),
                        _mm256_permute2f128_ps::<0x20>(t26, t37),
                        _mm256_permute2f128_ps::<0x31>(t04, t15),
                        _mm256_permute2f128_ps::<0x31>(t26, t37),
                    ];
                    let oy = 4 * ty + 2 * dy + p.a;
                    let at = (co * p.h2 + oy) * p.w2 + 4 * x0;
                    if n == LANES {
                        let dst = &mut out[at..at + 4 * LANES];
                        for (q, run) in runs.iter().enumerate() {
                            // SAFETY: `dst` holds 32 floats.
                            unsafe { _mm256_storeu_ps(dst.as_mut_ptr().add(q * LANES), *run) };
                        }
                    } else {
                        for (q, run) in runs.iter().enumerate() {
                            // SAFETY: `px` holds 32 floats.
                            unsafe { _mm256_storeu_ps(px.as_mut_ptr().add(q * LANES), *run) };
                        }
                        out[at..at + 4 * n].copy_from_slice(&px[..4 * n]);
                    }
                }
            }
        }
    }
}
