//! Motion weighting (spec §4, DriftWorld's latent family): latent tokens that
//! change between the last context frame and the target weigh more in the loss.
//!
//! Most of a Push-T frame is static background, so with one drift problem per
//! latent cell (`--field token`) an unweighted mean spends nearly all of the
//! gradient on cells that do not move, while the agent and the block — what a
//! world model is for — are a few cells. Per future frame, with δ the distance of
//! each token between the true target and the true last context frame:
//!
//! - q = quantile_{q_hi}(δ) over the frame's tokens; norm = clamp(δ / (q + 1e-6), 0, 1);
//! - gate = clamp(1 − median(δ) / (q + 1e-6), 0, 1), which switches the weighting off
//!   for frames that change everywhere alike (a camera move, not an object);
//! - n_τ = relu(norm − τ) / (1 − τ);
//! - weight = 1 + λ · tanh(α · n_τ) · gate, multiplying that token's loss.
//!
//! Quantiles interpolate linearly between order statistics (torch.quantile's
//! default), the median included.

use serde::{Deserialize, Serialize};

/// The weighting's parameters; the defaults are the paper's RT-1/Bridge values.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MotionWeighting {
    /// Largest extra weight λ (a moving token weighs up to 1 + λ).
    pub lambda: f32,
    /// Slope α of the tanh.
    pub alpha: f32,
    /// Quantile of δ that counts as full motion.
    pub q_hi: f32,
    /// Normalised motion below which a token gets no extra weight.
    pub tau: f32,
}

impl Default for MotionWeighting {
    fn default() -> Self {
        Self { lambda: 12.0, alpha: 2.5, q_hi: 0.98, tau: 0.35 }
    }
}

/// The `q`-quantile of `v` with linear interpolation (`v` is sorted in place).
fn quantile(v: &mut [f32], q: f32) -> f32 {
    v.sort_by(f32::total_cmp);
    let pos = q.clamp(0.0, 1.0) * (v.len() - 1) as f32;
    let (lo, hi) = (pos.floor() as usize, pos.ceil() as usize);
    v[lo] + (v[hi] - v[lo]) * (pos - lo as f32)
}

impl MotionWeighting {
    /// Token weights for `delta`, which holds consecutive frames of `tokens` values
    /// each; the result has the same layout.
    pub fn weights(&self, delta: &[f32], tokens: usize) -> Vec<f32> {
        let mut out = Vec::with_capacity(delta.len());
        for frame in delta.chunks(tokens.max(1)) {
            let mut sorted = frame.to_vec();
            let q = quantile(&mut sorted, self.q_hi);
            let median = quantile(&mut sorted, 0.5);
            let gate = (1.0 - median / (q + 1e-6)).clamp(0.0, 1.0);
            out.extend(frame.iter().map(|&d| {
                let norm = (d / (q + 1e-6)).clamp(0.0, 1.0);
                let n_tau = (norm - self.tau).max(0.0) / (1.0 - self.tau);
                1.0 + self.lambda * (self.alpha * n_tau).tanh() * gate
            }));
        }
        out
    }
}

/// δ per token: the Euclidean distance over `channels` between `a` and `b`, both
/// laid out as `[frames, channels, tokens]`; the result is `[frames, tokens]`.
pub fn token_distances(a: &[f32], b: &[f32], channels: usize, tokens: usize) -> Vec<f32> {
    let frames = a.len() / (channels * tokens).max(1);
    let mut out = vec![0.0f32; frames * tokens];
    for f in 0..frames {
        for c in 0..channels {
            let base = (f * channels + c) * tokens;
            for t in 0..tokens {
                let d = a[base + t] - b[base + t];
                out[f * tokens + t] += d * d;
            }
        }
    }
    out.iter_mut().for_each(|v| *v = v.sqrt());
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_interpolate_linearly() {
        // Sorted 1, 2, 3, 4: position 0.5·3 = 1.5 → 2.5; 0.98·3 = 2.94 → 3 + 0.94 = 3.94.
        assert_eq!(quantile(&mut [4.0, 1.0, 3.0, 2.0], 0.5), 2.5);
        assert!((quantile(&mut [4.0, 1.0, 3.0, 2.0], 0.98) - 3.94).abs() < 1e-6);
    }

    #[test]
    fn a_still_background_and_one_moving_token() {
        // 50 tokens, 49 still (δ = 0), one moving (δ = 2).
        let mut delta = vec![0.0f32; 50];
        delta[7] = 2.0;
        let w = MotionWeighting::default().weights(&delta, 50);
        // q_0.98: position 0.98·49 = 48.02 between sorted[48] = 0 and sorted[49] = 2 → 0.04.
        // median 0 → gate 1. The mover: norm = clamp(2 / 0.04) = 1, n_τ = 1,
        // weight = 1 + 12·tanh(2.5) = 1 + 12·0.986614 = 12.83937. The still ones: 1.
        assert!((w[7] - (1.0 + 12.0 * 2.5f32.tanh())).abs() < 1e-4, "{}", w[7]);
        assert!(w.iter().enumerate().all(|(i, &x)| i == 7 || x == 1.0));
    }

    #[test]
    fn uniform_change_is_gated_off() {
        // Every token moves alike: median = q, gate = 1 − q/(q + 1e-6) ≈ 0 → all weights ≈ 1.
        let w = MotionWeighting::default().weights(&[3.0; 20], 20);
        assert!(w.iter().all(|&x| (x - 1.0).abs() < 1e-4), "{w:?}");
    }

    #[test]
    fn frames_are_weighted_separately() {
        // Frame 0 still everywhere (q = 0: all weights 1); frame 1 has a mover.
        let mut delta = vec![0.0f32; 8];
        delta[4 + 2] = 1.0;
        let w = MotionWeighting::default().weights(&delta, 4);
        assert!(w[..4].iter().all(|&x| x == 1.0));
        assert!(w[6] > 10.0 && w[4] == 1.0, "{w:?}");
    }

    #[test]
    fn distances_are_per_token_over_channels() {
        // 1 frame, 2 channels, 2 tokens: token 0 differs by (3, 4) → 5; token 1 equal → 0.
        let a = [3.0, 0.0, 4.0, 1.0];
        let b = [0.0, 0.0, 0.0, 1.0];
        assert_eq!(token_distances(&a, &b, 2, 2), vec![5.0, 0.0]);
    }
}
