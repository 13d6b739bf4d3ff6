//! Multi-head self-attention over each image's positions, the core of the CPU
//! U-Net's attention layers (`world_model::unet::cpu`): given the projected
//! queries, keys and values, the heads' outputs before the output projection.
//!
//! Per image and head, the scores and the weighted values are two matrix products on the
//! `gemm` crate's kernels (`matrix::matmul_general`: AVX2 as built here; the AVX-512 kernel
//! reads row-major operands only), reading queries, keys and values in place through
//! strides; the softmax runs between them. At the imported U-Net's
//! 24² maps one head's scores are 576 × 576 floats (1.3 MB): the products block them for the
//! caches, which the loop version (`attend_loops`, kept as the reference the tests compare
//! against) did not (BENCHMARKS.md, 2026-12-02).

use crate::elementwise::{exp, has_avx2_fma, has_avx512f};
use crate::matrix::{Strided, ViewMut, matmul_general};

/// The shapes of one attention call.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Heads {
    /// Channels c (queries, keys and values have c each).
    pub channels: usize,
    /// Heads (dividing `channels`).
    pub heads: usize,
    /// Images (samples × frames).
    pub images: usize,
    /// Positions per image (h·w).
    pub positions: usize,
}

/// Attention per image and head: softmax(q·kᵀ/√d)·v with d = c / heads.
///
/// # Shapes
/// - `qkv`: `[3c, images·positions]` channel-major (queries, then keys, then values)
/// - returns `[c, images·positions]`
///
/// # Panics
/// If `qkv` is shorter than `3c · images · positions` (a caller's bug).
pub fn attend(qkv: &[f32], s: Heads) -> Vec<f32> {
    let (c, t) = (s.channels, s.positions);
    let cols = s.images * t;
    assert!(qkv.len() >= 3 * c * cols, "attention: qkv holds {} values, not 3·{c}·{cols}", qkv.len());
    let d = c / s.heads;
    let scale = 1.0 / (d as f32).sqrt();
    let mut o = crate::elementwise::zeros(c * cols);
    if t == 0 || d == 0 {
        return o;
    }
    // scores[t1, t2] = Σ_dd q[dd, t1] k[dd, t2]; then each row's softmax of scale · scores.
    let mut scores = crate::elementwise::zeros(t * t);
    for img in 0..s.images {
        for hd in 0..s.heads {
            let at = |part: usize| (part * c + hd * d) * cols + img * t;
            // qᵀ: [t, d] (rows step 1, columns step `cols`) times k: [d, t].
            matmul_general(
                t,
                d,
                t,
                Strided { data: &qkv[at(0)..], rs: 1, cs: cols },
                Strided { data: &qkv[at(1)..], rs: cols, cs: 1 },
                ViewMut { data: &mut scores, ld: t },
                false,
            );
            softmax_rows(&mut scores, t, scale);
            // out[dd, t1] = Σ_t2 v[dd, t2] p[t1, t2]: v [d, t] times pᵀ [t, t].
            let at_out = (hd * d) * cols + img * t;
            matmul_general(
                d,
                t,
                t,
                Strided { data: &qkv[at(2)..], rs: cols, cs: 1 },
                Strided { data: &scores, rs: 1, cs: t },
                ViewMut { data: &mut o[at_out..], ld: cols },
                false,
            );
        }
    }
    o
}

/// Each `t`-long row of `scores` replaced by softmax(scale · row) (scale > 0).
///
/// The same code compiled for AVX-512F, AVX2 + FMA or neither: the operations and their
/// order are the same (Rust contracts no multiply-add on its own), so the bytes are too.
fn softmax_rows(scores: &mut [f32], t: usize, scale: f32) {
    #[cfg(target_arch = "x86_64")]
    if has_avx512f() {
        // SAFETY: the CPU supports AVX-512F (checked just above), the requirement of
        // calling a function compiled with it.
        #[allow(unsafe_code)]
        return unsafe { softmax_rows_avx512(scores, t, scale) };
    }
    #[cfg(target_arch = "x86_64")]
    if has_avx2_fma() {
        // SAFETY: the CPU supports AVX2 and FMA (checked just above), the
        // requirement of calling a function compiled with those features.
        #[allow(unsafe_code)]
        return unsafe { softmax_rows_avx2(scores, t, scale) };
    }
    softmax_rows_impl(scores, t, scale)
}

/// [`softmax_rows`] compiled for AVX2 + FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn softmax_rows_avx2(scores: &mut [f32], t: usize, scale: f32) {
    softmax_rows_impl(scores, t, scale)
}

/// [`softmax_rows`] compiled for AVX-512F (its loops vectorise 16 wide).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
fn softmax_rows_avx512(scores: &mut [f32], t: usize, scale: f32) {
    softmax_rows_impl(scores, t, scale)
}

#[inline(always)]
fn softmax_rows_impl(scores: &mut [f32], t: usize, scale: f32) {
    for r in scores.chunks_mut(t) {
        // max(scale · x) = scale · max(x) for scale > 0.
        let max = r.iter().copied().fold(f32::NEG_INFINITY, f32::max);
        r.iter_mut().for_each(|v| *v = exp((*v - max) * scale));
        let sum: f32 = r.iter().sum();
        r.iter_mut().for_each(|v| *v /= sum);
    }
}

/// The loop version of [`attend`], the reference its tests compare against: scores
/// row by row (`q·k` accumulated over the head's channels), softmax, then the
/// values weighted through the transposed weights so every inner loop runs along
/// contiguous positions.
#[cfg(test)]
fn attend_loops(qkv: &[f32], s: Heads) -> Vec<f32> {
    let (c, t) = (s.channels, s.positions);
    let cols = s.images * t;
    let d = c / s.heads;
    let scale = 1.0 / (d as f32).sqrt();
    let mut o = vec![0.0; c * cols];
    let mut attn = vec![0.0f32; t * t];
    let mut attn_t = vec![0.0f32; t * t];
    for img in 0..s.images {
        for hd in 0..s.heads {
            let row = |part: usize, dd: usize| &qkv[(part * c + hd * d + dd) * cols + img * t..][..t];
            attn.fill(0.0);
            for dd in 0..d {
                let (q, k) = (row(0, dd), row(1, dd));
                for (t1, &qv) in q.iter().enumerate() {
                    let qv = qv * scale;
                    attn[t1 * t..][..t].iter_mut().zip(k).for_each(|(a, &kv)| *a += qv * kv);
                }
            }
            for r in attn.chunks_mut(t) {
                let max = r.iter().copied().fold(f32::NEG_INFINITY, f32::max);
                r.iter_mut().for_each(|v| *v = exp(*v - max));
                let sum: f32 = r.iter().sum();
                r.iter_mut().for_each(|v| *v /= sum);
            }
            // attn_t[t2][t1] = attn[t1][t2].
            for (t1, r) in attn.chunks(t).enumerate() {
                for (t2, &a) in r.iter().enumerate() {
                    attn_t[t2 * t + t1] = a;
                }
            }
            for dd in 0..d {
                let v = row(2, dd);
                let out = &mut o[(hd * d + dd) * cols + img * t..][..t];
                for (col, &vv) in attn_t.chunks(t).zip(v) {
                    out.iter_mut().zip(col).for_each(|(ov, &a)| *ov += a * vv);
                }
            }
        }
    }
    o
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_head_by_hand() {
        // c = 1, one head, one image of two positions: q = [1, 0], k = [0, ln 3], v = [2, 6].
        // Scores q·k/√1: position 0 sees [0, ln 3] → softmax [1/4, 3/4] → 0.5 + 4.5 = 5;
        // position 1 sees [0, 0] → [1/2, 1/2] → 4.
        let qkv = [1.0, 0.0, 0.0, 3f32.ln(), 2.0, 6.0];
        let o = attend(&qkv, Heads { channels: 1, heads: 1, images: 1, positions: 2 });
        assert!((o[0] - 5.0).abs() < 1e-5 && (o[1] - 4.0).abs() < 1e-5, "{o:?}");
        let o = attend_loops(&qkv, Heads { channels: 1, heads: 1, images: 1, positions: 2 });
        assert!((o[0] - 5.0).abs() < 1e-5 && (o[1] - 4.0).abs() < 1e-5, "{o:?}");
    }

    #[test]
    fn products_match_the_loops() {
        // Two heads of 3 channels, three images of 7 positions (odd sizes, so no kernel's
        // block fits exactly), and one head over 40 positions of one image.
        for s in [
            Heads { channels: 6, heads: 2, images: 3, positions: 7 },
            Heads { channels: 4, heads: 1, images: 1, positions: 40 },
        ] {
            let qkv = crate::elementwise::test_values(3 * s.channels * s.images * s.positions, 11);
            let (fast, slow) = (attend(&qkv, s), attend_loops(&qkv, s));
            let worst = fast.iter().zip(&slow).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
            assert!(worst < 1e-5, "{s:?}: differs by {worst}");
        }
    }

    #[test]
    fn every_softmax_build_gives_the_same_bytes() {
        // 3 rows of 37 scores: a row length no vector width divides.
        let scores = crate::elementwise::test_values(3 * 37, 5).iter().map(|v| v * 30.0).collect::<Vec<_>>();
        let mut plain = scores.clone();
        softmax_rows_impl(&mut plain, 37, 0.25);
        let mut dispatched = scores.clone();
        softmax_rows(&mut dispatched, 37, 0.25);
        assert_eq!(plain, dispatched);
        assert!(plain.chunks(37).all(|r| (r.iter().sum::<f32>() - 1.0).abs() < 1e-5));
    }

    #[test]
    fn a_short_qkv_is_refused() {
        let s = Heads { channels: 2, heads: 1, images: 1, positions: 3 };
        let r = std::panic::catch_unwind(|| attend(&[0.0; 17], s));
        assert!(r.is_err(), "3·2·3 = 18 values are needed");
    }
}
