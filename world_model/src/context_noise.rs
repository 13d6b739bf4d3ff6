//! Context-noise augmentation: training histories corrupted with Gaussian noise of
//! a random level, so that the U-Net learns to predict from imperfect histories.
//!
//! Not in the DriftWorld paper (off by default). In a closed-loop rollout the
//! history is the model's own earlier output; errors in it compound over the 75
//! chunks of a 300-step Push-T episode (filmstrips: the T erodes into a blob within
//! ~10 chunks while MuJoCo's stays put). Self-forcing (spec §7) trains on the
//! model's own errors but costs one extra pass per chunk; corrupting the true
//! history costs nothing and is the remedy GameNGen (Valevski et al. 2024) and
//! Diffusion Forcing use for the same drift. Each row (context × sample) draws its
//! own level σ ~ U[0, σ_max] in units of the normalised latents (std 1 per channel),
//! so clean and strongly corrupted histories both occur; the model is not told σ.

use burn::tensor::{Device, Distribution, Tensor};
use harness::seed::splitmix64;

/// Per-row noise levels σ_r = σ_max · u_r, u_r uniform in [0, 1) from `seed`.
pub fn levels(rows: usize, sigma_max: f32, seed: u64) -> Vec<f32> {
    let mut state = seed;
    (0..rows)
        .map(|_| {
            state = splitmix64(state);
            sigma_max * ((state >> 40) as f32 / (1u64 << 24) as f32)
        })
        .collect()
}

/// Adds σ_r · ε to every element of history row r (ε standard normal, drawn from
/// the device's generator); `sigma_max = 0` returns `hist` unchanged.
///
/// # Shapes
/// `hist`: `[r, C, K, s, s]` → the same
pub fn corrupt(hist: Tensor<5>, sigma_max: f32, seed: u64) -> Tensor<5> {
    if sigma_max <= 0.0 {
        return hist;
    }
    let device: Device = hist.device();
    let dims = hist.dims();
    let sigma = Tensor::<1>::from_floats(levels(dims[0], sigma_max, seed).as_slice(), &device)
        .reshape([dims[0], 1, 1, 1, 1]); // [r, 1, 1, 1, 1]
    let eps = Tensor::<5>::random(dims, Distribution::Normal(0.0, 1.0), &device);
    hist + eps * sigma
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn levels_lie_in_range_and_vary_by_row() {
        let l = levels(1000, 0.5, 7);
        assert!(l.iter().all(|&v| (0.0..0.5).contains(&v)));
        // Uniform on [0, 0.5): mean 0.25, and both halves of the range occur.
        let mean = l.iter().sum::<f32>() / 1000.0;
        assert!((mean - 0.25).abs() < 0.02, "{mean}");
        assert!(l.iter().any(|&v| v < 0.05) && l.iter().any(|&v| v > 0.45));
        assert_eq!(l, levels(1000, 0.5, 7), "a pure function of the seed");
        assert_ne!(l, levels(1000, 0.5, 8));
    }

    #[test]
    fn each_row_gets_noise_of_its_own_level() {
        let device = Device::flex();
        let (r, n) = (6, 4 * 4 * 12 * 12); // rows of C·K·s·s = 2304 elements
        let hist = Tensor::<5>::ones([r, 4, 4, 12, 12], &device);
        let out = corrupt(hist.clone(), 0.8, 3);
        let diff: Vec<f32> = (out - hist).into_data().try_into_vec::<f32>().unwrap();
        for (row, &sigma) in levels(r, 0.8, 3).iter().enumerate() {
            let d = &diff[row * n..(row + 1) * n];
            let std = (d.iter().map(|v| v * v).sum::<f32>() / n as f32).sqrt();
            // The sample std of 2304 normals scaled by σ is σ within a few percent
            // (standard error σ/√(2·2304) ≈ 0.015σ); allow 10% and 0.01 absolute.
            assert!((std - sigma).abs() < 0.1 * sigma + 0.01, "row {row}: std {std}, σ {sigma}");
        }
    }

    #[test]
    fn zero_level_is_the_identity() {
        let device = Device::flex();
        let hist = Tensor::<5>::random([2, 3, 4, 5, 5], Distribution::Default, &device);
        let out = corrupt(hist.clone(), 0.0, 1);
        let diff: f32 = (out - hist).abs().max().into_scalar();
        assert_eq!(diff, 0.0);
    }
}
