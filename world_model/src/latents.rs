//! Autoencoder latents of a dataset and the training windows cut from them.
//!
//! The world model works on normalised latents `(z - mean_c) / std_c` (per latent
//! channel), so that every objective (drifting, MSE, diffusion) sees unit-scale
//! data. Frames are encoded lazily, the first time a window needs them, and kept
//! (81k Push-T frames are 370 MB of f32 latents), so that training starts at once
//! and no frame is encoded twice.
//!
//! A window starting at step t of an episode is: history o_{t-3..t}, targets
//! o_{t+1..t+4} and actions a_t..a_{t+3} (a_k is executed after observing o_k,
//! so a_{t+f} drives o_{t+f+1}). History steps before the episode's first frame
//! repeat that frame, exactly as a rollout starts from one observation repeated
//! four times; the targets always lie inside the episode.

use burn::tensor::{Device, Tensor, TensorData};
use serde::{Deserialize, Serialize};

use crate::autoencoder::Autoencoder;
use crate::data::{EpisodeData, Split};

/// Per-channel latent normalisation, stored with the world model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LatentStats {
    /// Latent channels C.
    pub channels: usize,
    /// Latent side (image / 8).
    pub size: usize,
    /// Per-channel mean of the raw latents.
    pub mean: Vec<f32>,
    /// Per-channel standard deviation of the raw latents.
    pub std: Vec<f32>,
}

/// Normalises world-unit actions: a' = 2a/511 − 1 (spec §1, world-model stats 0..511).
pub fn normalise_action(a: f32) -> f32 {
    2.0 * a / 511.0 - 1.0
}

/// Lazily encoded, normalised latents of every frame of a dataset.
pub struct Latents<'a> {
    data: &'a EpisodeData,
    stats: LatentStats,
    z: Vec<f32>,
    done: Vec<bool>,
}

impl<'a> Latents<'a> {
    /// Latent statistics measured on up to `frames` evenly spaced training frames.
    pub fn measure_stats(
        data: &EpisodeData,
        ae: &Autoencoder,
        frames: usize,
        device: &Device,
    ) -> LatentStats {
        let train = data.frame_indices(Split::Train);
        let stride = (train.len() / frames.max(1)).max(1);
        let idx: Vec<usize> = train.iter().step_by(stride).take(frames).copied().collect();
        let (mut sum, mut sq, mut n) = (Vec::new(), Vec::new(), 0usize);
        let (mut channels, mut size) = (0, 0);
        for chunk in idx.chunks(64) {
            let z = ae.encode(data.frames_tensor(chunk, device)); // [b, C, s, s]
            let [b, c, s, _] = z.dims();
            (channels, size) = (c, s);
            sum.resize(c, 0f64);
            sq.resize(c, 0f64);
            let v = z.into_data().convert::<f32>().try_into_vec::<f32>().unwrap_or_default();
            for (i, x) in v.iter().enumerate() {
                let ch = (i / (s * s)) % c;
                sum[ch] += f64::from(*x);
                sq[ch] += f64::from(*x) * f64::from(*x);
            }
            n += b * s * s;
        }
        let n = n.max(1) as f64;
        let mean: Vec<f32> = sum.iter().map(|s| (s / n) as f32).collect();
        let std =
            sq.iter().zip(&sum).map(|(q, s)| ((q / n - (s / n).powi(2)).max(1e-8)).sqrt() as f32).collect();
        LatentStats { channels, size, mean, std }
    }

    /// An empty cache over `data`.
    pub fn new(data: &'a EpisodeData, stats: LatentStats) -> Self {
        let per = stats.channels * stats.size * stats.size;
        Self { data, z: vec![0.0; data.len() * per], done: vec![false; data.len()], stats }
    }

    /// The normalisation in use.
    pub fn stats(&self) -> &LatentStats {
        &self.stats
    }

    /// Values per latent frame (C·s·s).
    fn per(&self) -> usize {
        self.stats.channels * self.stats.size * self.stats.size
    }

    /// Encodes the frames of `idx` that are not cached yet.
    pub fn ensure(&mut self, idx: &[usize], ae: &Autoencoder, device: &Device) {
        let mut missing: Vec<usize> = idx.iter().copied().filter(|&i| !self.done[i]).collect();
        missing.sort_unstable();
        missing.dedup();
        let (per, plane) = (self.per(), self.stats.size * self.stats.size);
        for chunk in missing.chunks(64) {
            let z = ae.encode(self.data.frames_tensor(chunk, device));
            let v = z.into_data().convert::<f32>().try_into_vec::<f32>().unwrap_or_default();
            for (k, &i) in chunk.iter().enumerate() {
                let dst = &mut self.z[i * per..(i + 1) * per];
                for (j, d) in dst.iter_mut().enumerate() {
                    let c = j / plane;
                    *d = (v[k * per + j] - self.stats.mean[c]) / self.stats.std[c];
                }
                self.done[i] = true;
            }
        }
    }

    /// Normalised latents of `idx` (already encoded) as a `[b, F, C, s, s]` tensor,
    /// where `idx` holds `b·F` frame indices, frame-major within each row.
    pub fn tensor(&self, idx: &[usize], f: usize, device: &Device) -> Tensor<5> {
        let per = self.per();
        let mut v = Vec::with_capacity(idx.len() * per);
        for &i in idx {
            debug_assert!(self.done[i], "frame {i} not encoded");
            v.extend_from_slice(&self.z[i * per..(i + 1) * per]);
        }
        let s = self.stats.size;
        Tensor::from_data(TensorData::new(v, [idx.len() / f, f, self.stats.channels, s, s]), device)
    }
}

/// One training/evaluation window: frame indices and normalised actions.
#[derive(Clone, Debug, PartialEq)]
pub struct Window {
    /// History frame indices o_{t-3..t} (clamped to the episode's first frame).
    pub history: Vec<usize>,
    /// Target frame indices o_{t+1..t+F}.
    pub targets: Vec<usize>,
    /// Normalised actions a_t..a_{t+F-1}, `F x 2`.
    pub actions: Vec<f32>,
}

/// Every valid window start (global step index t) of a split: t + F must lie in the episode.
pub fn window_starts(data: &EpisodeData, split: Split, future: usize) -> Vec<usize> {
    data.episodes
        .iter()
        .enumerate()
        .filter(|(i, r)| split.contains(*i) && r.len() > future)
        .flat_map(|(_, r)| r.start..r.end - future)
        .collect()
}

/// The window of `history` + `future` frames at global step `t`.
pub fn window(data: &EpisodeData, t: usize, history: usize, future: usize) -> Window {
    let ep_start = data.episodes.iter().find(|r| r.contains(&t)).map_or(0, |r| r.start);
    let hist = (0..history).map(|k| (t + k + 1).saturating_sub(history).max(ep_start)).collect();
    let targets = (1..=future).map(|f| t + f).collect();
    let actions =
        (0..future).flat_map(|f| [0, 1].map(|d| normalise_action(data.actions[(t + f) * 2 + d]))).collect();
    Window { history: hist, targets, actions }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn toy() -> EpisodeData {
        // Two episodes of 6 and 3 frames of 1x1 pixels; actions a_k = (k, 511).
        EpisodeData {
            frames: vec![0; 9 * 3],
            actions: (0..9).flat_map(|k| [k as f32, 511.0]).collect(),
            size: 1,
            episodes: vec![0..6, 6..9],
        }
    }

    #[test]
    fn windows_clamp_history_to_the_episode_start() {
        let d = toy();
        // Episode 0 (6 frames) with F = 4 has starts 0 and 1; episode 1 is too short.
        assert_eq!(window_starts(&d, Split::Train, 4), vec![0, 1]);
        let w = window(&d, 1, 4, 4);
        assert_eq!(w.history, vec![0, 0, 0, 1]);
        assert_eq!(w.targets, vec![2, 3, 4, 5]);
        // a'_1 = 2·1/511 − 1, a'_y = 2·511/511 − 1 = 1.
        assert!((w.actions[0] - (2.0 / 511.0 - 1.0)).abs() < 1e-6);
        assert_eq!(w.actions[1], 1.0);
        // A window in the second episode repeats that episode's first frame.
        assert_eq!(window(&d, 7, 4, 1).history, vec![6, 6, 6, 7]);
    }
}
