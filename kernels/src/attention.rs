//! Multi-head self-attention over each image's positions, the core of the CPU
//! U-Net's attention layers (`world_model::unet::cpu`): given the projected
//! queries, keys and values, the heads' outputs before the output projection.

use crate::elementwise::{exp, has_avx2_fma};

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
pub fn attend(qkv: &[f32], s: Heads) -> Vec<f32> {
    #[cfg(target_arch = "x86_64")]
    if has_avx2_fma() {
        // SAFETY: the CPU supports AVX2 and FMA (checked just above), the
        // requirement of calling a function compiled with those features.
        #[allow(unsafe_code)]
        return unsafe { attend_avx2(qkv, s) };
    }
    attend_impl(qkv, s)
}

/// [`attend`] compiled for AVX2 + FMA (its loops vectorise 8 wide).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn attend_avx2(qkv: &[f32], s: Heads) -> Vec<f32> {
    attend_impl(qkv, s)
}

/// Scores row by row (`q·k` accumulated over the head's channels), softmax, then the
/// values weighted through the transposed weights so every inner loop runs along
/// contiguous positions.
#[inline(always)]
fn attend_impl(qkv: &[f32], s: Heads) -> Vec<f32> {
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
        // The portable path gives the same bytes as the dispatched one.
        assert_eq!(attend_impl(&qkv, Heads { channels: 1, heads: 1, images: 1, positions: 2 }), o);
    }
}
