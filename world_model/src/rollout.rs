//! Autoregressive generation in latent space, one chunk at a time: the loop that
//! `wm eval`'s videos, `rank`'s world-model branch and `plan`'s imagination drive.
//!
//! Each [`Rollout::step`] predicts the next F ≤ `future` frames of every row from
//! its last K (spec §8: the history is real at first, then generated), refuses
//! non-finite output, and slides the history window by F. The check is here, in
//! the one place every driver goes through, because a diverged model must never
//! turn into silently black frames and plausible-looking numbers.

use burn::tensor::{Tensor, TensorData};
use harness::rng::Rng;

use crate::model::WorldModel;

/// Latents that are NaN or infinite, by the generated frames they were found in
/// (counted from the rollout's start; callers add which episode or policy).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("the world model produced non-finite latents in generated frames {first}..{end}")]
pub struct NonFiniteLatents {
    /// First frame of the chunk.
    pub first: usize,
    /// One past its last frame.
    pub end: usize,
}

/// Why a rollout step failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RolloutError {
    /// The model diverged.
    #[error(transparent)]
    NonFinite(#[from] NonFiniteLatents),
    /// Actions of a size the model does not read.
    #[error(transparent)]
    Actions(#[from] crate::error::SettingError),
}

/// A batch of autoregressive rollouts: each row's last K normalised latents and
/// its anchor (the episode's first frame, read only by anchored models).
pub struct Rollout {
    history: Tensor<5>,
    anchor: Tensor<4>,
    generated: usize,
}

impl Rollout {
    /// Rollouts that continue from `history`.
    ///
    /// # Shapes
    /// - `history`: `[b, K, C, s, s]`
    /// - `anchor`: `[b, C, s, s]`
    pub fn new(history: Tensor<5>, anchor: Tensor<4>) -> Self {
        Self { history, anchor, generated: 0 }
    }

    /// Frames generated per row so far.
    pub fn generated(&self) -> usize {
        self.generated
    }

    /// Predicts each row's next `f` frames (`f` ≤ the model's `future`) and appends
    /// them to its history. `action(row, j)` is the task's action (Push-T: world
    /// units, 0..511) that drives the row's j-th frame of the chunk, normalised here
    /// with the model's [`ActionScale`](crate::action::ActionScale); `rngs` holds one
    /// generator stream per row.
    ///
    /// # Shapes
    /// - returns `[b, f, C, s, s]`
    ///
    /// # Errors
    /// Any NaN or infinite latent in the chunk (the history is then left unchanged),
    /// or an action whose size is not the model's.
    pub fn step<'a>(
        &mut self,
        wm: &WorldModel,
        f: usize,
        action: impl Fn(usize, usize) -> &'a [f32],
        rngs: &mut [Rng],
    ) -> Result<Tensor<5>, RolloutError> {
        let [b, k, _, _, _] = self.history.dims();
        let scale = wm.cfg.action_scale();
        let d = scale.dim();
        let mut acts: Vec<f32> = Vec::with_capacity(b * f * d);
        for r in 0..b {
            for j in 0..f {
                let a = action(r, j);
                scale.check(a.len())?;
                scale.normalise_into(a, &mut acts);
            }
        }
        let act = Tensor::<3>::from_data(TensorData::new(acts, [b, f, d]), wm.device()); // [b, f, d]
        let pred = wm.predict(self.history.clone(), self.anchor.clone(), act, rngs); // [b, f, C, s, s]
        let check: f32 = pred.clone().abs().sum().into_scalar();
        if !check.is_finite() {
            return Err(NonFiniteLatents { first: self.generated, end: self.generated + f }.into());
        }
        self.history = Tensor::cat(vec![self.history.clone(), pred.clone()], 1).narrow(1, f, k);
        self.generated += f;
        Ok(pred)
    }

    /// Keeps only `rows` (indices into the current batch, in the order given): for
    /// episodes that end while others go on.
    pub fn keep(&mut self, rows: &[usize]) {
        let pick5 = |t: &Tensor<5>| Tensor::cat(rows.iter().map(|&p| t.clone().narrow(0, p, 1)).collect(), 0);
        let pick4 = |t: &Tensor<4>| Tensor::cat(rows.iter().map(|&p| t.clone().narrow(0, p, 1)).collect(), 0);
        if !rows.is_empty() {
            self.history = pick5(&self.history);
            self.anchor = pick4(&self.anchor);
        }
    }
}

#[cfg(test)]
mod tests {
    use burn::tensor::{Device, Distribution};

    use super::*;
    use crate::codec::FrameCodec;
    use crate::model::WorldModelConfig;
    use crate::unet::UNetConfig;

    /// A small untrained pixel-space one-pass model: frames of 3 × 8 × 8, K = 4, F = 4.
    fn model() -> WorldModel {
        let device = Device::flex();
        let unet_cfg = UNetConfig { model_channels: 32, ..UNetConfig::pusht_latent(3) };
        let cfg = WorldModelConfig::pixels(unet_cfg.clone(), 8);
        WorldModel::from_parts(cfg, FrameCodec::pixels(8), unet_cfg.init(&device), &device)
    }

    fn rngs() -> Vec<Rng> {
        (0..2).map(Rng::new).collect()
    }

    #[test]
    fn a_step_is_one_prediction_and_slides_the_history() {
        let wm = model();
        let device = wm.device().clone();
        let hist = Tensor::<5>::random([2, 4, 3, 8, 8], Distribution::Default, &device); // [b, K, C, s, s]
        let anchor = hist.clone().narrow(1, 0, 1).reshape([2, 3, 8, 8]);
        // Row r's j-th action is (100 r + 10 j, 50): normalised 2a/511 − 1.
        let table: Vec<Vec<[f32; 2]>> =
            (0..2).map(|r| (0..3).map(|j| [(100 * r + 10 * j) as f32, 50.0]).collect()).collect();
        let raw = |r: usize, j: usize| table[r][j].as_slice();
        let acts: Vec<f32> = table.iter().flatten().flat_map(|a| a.map(|v| 2.0 * v / 511.0 - 1.0)).collect();
        let direct = wm.predict(
            hist.clone(),
            anchor.clone(),
            Tensor::<3>::from_data(TensorData::new(acts, [2, 3, 2]), &device),
            &mut rngs(),
        );
        let mut roll = Rollout::new(hist.clone(), anchor);
        let pred = roll.step(&wm, 3, raw, &mut rngs()).unwrap(); // [2, 3, C, s, s]
        assert_eq!(pred.dims(), [2, 3, 3, 8, 8]);
        let diff: f32 = (pred.clone() - direct).abs().max().into_scalar();
        assert_eq!(diff, 0.0);
        assert_eq!(roll.generated(), 3);
        // History after 3 new frames: the old frame 3, then the 3 predictions.
        let want = Tensor::cat(vec![hist.narrow(1, 3, 1), pred], 1);
        let diff: f32 = (roll.history.clone() - want).abs().max().into_scalar();
        assert_eq!(diff, 0.0);
        // Keeping row 1 alone keeps its history.
        let row1 = roll.history.clone().narrow(0, 1, 1);
        roll.keep(&[1]);
        assert_eq!(roll.history.dims()[0], 1);
        assert_eq!((roll.history.clone() - row1).abs().max().into_scalar::<f32>(), 0.0);
    }

    #[test]
    fn non_finite_latents_are_an_error_naming_the_frames() {
        let wm = model();
        let device = wm.device().clone();
        let hist = Tensor::<5>::random([2, 4, 3, 8, 8], Distribution::Default, &device);
        let anchor = hist.clone().narrow(1, 0, 1).reshape([2, 3, 8, 8]);
        let mut roll = Rollout::new(hist.clone(), anchor);
        roll.step(&wm, 4, |_, _| &[256.0, 256.0], &mut rngs()).unwrap();
        // A NaN in row 0's history spreads through the convolutions into its prediction.
        let nan = Tensor::<5>::full([1, 1, 3, 8, 8], f32::NAN, &device);
        roll.history = Tensor::cat(vec![nan, roll.history.clone().narrow(0, 1, 1).narrow(1, 0, 1)], 0)
            .expand([2, 4, 3, 8, 8]);
        let before = roll.history.clone();
        let err = roll.step(&wm, 2, |_, _| &[256.0, 256.0], &mut rngs()).unwrap_err();
        assert_eq!(err, RolloutError::NonFinite(NonFiniteLatents { first: 4, end: 6 }));
        assert_eq!(err.to_string(), "the world model produced non-finite latents in generated frames 4..6");
        assert_eq!(roll.generated(), 4, "a failed step generates nothing");
        // A failed step keeps the history: row 1 as it was, row 0 still all NaN.
        let row = |t: &Tensor<5>, r: usize| t.clone().narrow(0, r, 1);
        assert!(row(&roll.history, 1).equal(row(&before, 1)).all().into_scalar::<bool>());
        assert!(row(&roll.history, 0).is_nan().all().into_scalar::<bool>());
    }

    #[test]
    fn actions_of_another_size_are_an_error() {
        let wm = model();
        let device = wm.device().clone();
        let hist = Tensor::<5>::random([1, 4, 3, 8, 8], Distribution::Default, &device);
        let anchor = hist.clone().narrow(1, 0, 1).reshape([1, 3, 8, 8]);
        let mut roll = Rollout::new(hist, anchor);
        let err = roll.step(&wm, 1, |_, _| &[0.0; 7], &mut rngs()).unwrap_err();
        assert_eq!(err.to_string(), "actions have 7 entries, the world model reads 2");
        assert_eq!(roll.generated(), 0);
    }
}
