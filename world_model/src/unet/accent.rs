//! Action accentuation's guidance input (spec §3): the U-Net is told how strongly
//! its prediction should move away from "nothing moved".
//!
//! In training, each context draws a strength α (log-uniform on [1, 4], or exactly
//! 1 with probability 0.1) and the drifting loss gets the true current frame o_t
//! as one more negative with weight (α − 1)(N − 1) ([`crate::drift_step`]), which
//! makes the negatives' mixture (1/α)·q_θ + ((α − 1)/α)·δ(o_t) — classifier-free
//! guidance with "the scene did not change" as the unconditional sample. α reaches
//! the network as fixed random Fourier features `[cos 2παW, sin 2παW]` (W ~ N(0, 1),
//! 128 of them, not trained) through a two-layer MLP whose last layer starts at
//! zero, added to every frame's action embedding. At inference α is a setting
//! (the model config's `alpha`; the authors use 2.5–3).
//!
//! W is drawn from a fixed seed ([`FOURIER_SEED`]) rather than stored: it is the
//! same in every process, so checkpoints hold only the MLP.

use burn::module::Module;
use burn::nn::{Initializer, Linear, LinearConfig};
use burn::tensor::activation::silu;
use burn::tensor::{Device, Tensor};
use harness::rng::Rng;

/// Fourier frequencies of α.
pub const FOURIER_FEATURES: usize = 128;

/// Seed of the fixed frequencies W.
pub const FOURIER_SEED: u64 = 0xACCE_4700;

/// Training α's range: log-uniform on [1, ALPHA_MAX].
pub const ALPHA_MAX: f32 = 4.0;

/// Probability that a training context gets α = 1 (no accentuation).
pub const ALPHA_ONE_PROBABILITY: f32 = 0.1;

/// A training context's α from two uniform draws in [0, 1): `coin` picks α = 1 with
/// probability [`ALPHA_ONE_PROBABILITY`], otherwise α = 4^u.
pub fn training_alpha(coin: f32, u: f32) -> f32 {
    if coin < ALPHA_ONE_PROBABILITY { 1.0 } else { ALPHA_MAX.powf(u) }
}

/// The fixed frequencies W (`[1, FOURIER_FEATURES]`).
fn frequencies(device: &Device) -> Tensor<2> {
    let w = Rng::new(FOURIER_SEED).normals_f32(FOURIER_FEATURES);
    Tensor::<1>::from_floats(w.as_slice(), device).reshape([1, FOURIER_FEATURES])
}

/// The α MLP: Fourier features → Linear → SiLU → Linear (zero-initialised).
#[derive(Module, Debug)]
pub struct AlphaMlp {
    pub(super) l1: Linear,
    pub(super) l2: Linear,
}

impl AlphaMlp {
    /// An MLP to an `emb`-sized vector whose output is zero until trained.
    pub fn new(emb: usize, device: &Device) -> Self {
        Self {
            l1: LinearConfig::new(2 * FOURIER_FEATURES, emb).init(device),
            l2: LinearConfig::new(emb, emb).with_initializer(Initializer::Zeros).init(device),
        }
    }

    /// # Shapes
    /// `alpha` `[b]` → `[b, emb]`
    pub fn forward(&self, alpha: Tensor<1>) -> Tensor<2> {
        let [b] = alpha.dims();
        let device = alpha.device();
        let args = alpha.reshape([b, 1]) * frequencies(&device) * (2.0 * std::f64::consts::PI); // [b, 128]
        let phi = Tensor::cat(vec![args.clone().cos(), args.sin()], 1); // [b, 256]
        self.l2.forward(silu(self.l1.forward(phi)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn training_alphas_follow_the_spec() {
        // coin < 0.1 → 1; otherwise 4^u: u = 0 → 1, u = 0.5 → 2, u → 1 → 4.
        assert_eq!(training_alpha(0.05, 0.7), 1.0);
        assert_eq!(training_alpha(0.5, 0.0), 1.0);
        assert!((training_alpha(0.5, 0.5) - 2.0).abs() < 1e-6);
        assert!((training_alpha(0.99, 0.999_999) - 4.0).abs() < 1e-4);
    }

    #[test]
    fn starts_at_zero_and_separates_alphas_once_trained() {
        let device = Device::flex();
        let mlp = AlphaMlp::new(16, &device);
        let a = Tensor::<1>::from_floats([1.0f32, 2.5].as_slice(), &device);
        let zero: f32 = mlp.forward(a.clone()).abs().max().into_scalar();
        assert_eq!(zero, 0.0, "the zero-initialised last layer makes the MLP a no-op");
        // With a non-zero last layer, different α give different embeddings, and the
        // frequencies are the same in every call (fixed seed).
        let live = AlphaMlp { l2: LinearConfig::new(16, 16).init(&device), ..mlp };
        let y = live.forward(a.clone());
        let again = live.forward(a);
        let rows: Vec<f32> = y.clone().into_data().try_to_vec().unwrap_or_default();
        assert!(rows[..16].iter().zip(&rows[16..]).any(|(p, q)| (p - q).abs() > 1e-4));
        let same: f32 = (y - again).abs().max().into_scalar();
        assert_eq!(same, 0.0);
    }
}
