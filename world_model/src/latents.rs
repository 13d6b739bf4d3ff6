//! Encoded frames of a dataset (autoencoder latents or pixels) and the training
//! windows cut from them.
//!
//! The world model works on normalised frames `(z - mean_c) / std_c` (per
//! channel), so that every objective (drifting, MSE, diffusion) sees unit-scale
//! data. Latents are encoded lazily, the first time a window needs them, and kept
//! (81k Push-T frames are 370 MB of f32 latents), so that training starts at once
//! and no frame is encoded twice. Pixels are not cached (the same frames would be
//! 9 GB of f32): they are normalised from the dataset's bytes on every read.
//!
//! A window starting at step t of an episode is: history o_{t-3..t}, targets
//! o_{t+1..t+4} and actions a_t..a_{t+3} (a_k is executed after observing o_k,
//! so a_{t+f} drives o_{t+f+1}). History steps before the episode's first frame
//! repeat that frame, exactly as a rollout starts from one observation repeated
//! four times; the targets always lie inside the episode. The window also names
//! the episode's first frame, the anchor a U-Net configured with one reads (a
//! rollout's first observation).

use burn::tensor::{Device, Tensor, TensorData};
use serde::{Deserialize, Serialize};

use crate::action::ActionScale;
use crate::codec::FrameCodec;
use crate::data::{EpisodeData, Split};

/// Per-channel normalisation of the encoded frames, stored with the world model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LatentStats {
    /// Channels C of an encoded frame (3 in pixel space).
    pub channels: usize,
    /// Side of an encoded frame (image / 8 for latents, the image for pixels).
    pub size: usize,
    /// Per-channel mean of the raw encoded frames.
    pub mean: Vec<f32>,
    /// Per-channel standard deviation of the raw encoded frames.
    pub std: Vec<f32>,
}

/// Lazily encoded, normalised latents (or normalised pixels) of every frame of a dataset.
pub struct Latents<'a> {
    data: &'a EpisodeData,
    stats: LatentStats,
    z: Vec<f32>,
    done: Vec<bool>,
    pixels: bool,
}

impl<'a> Latents<'a> {
    /// Statistics of the encoded frames, measured on up to `frames` evenly spaced
    /// training frames.
    pub fn measure_stats(
        data: &EpisodeData,
        codec: &FrameCodec,
        frames: usize,
        device: &Device,
    ) -> LatentStats {
        let train = data.frame_indices(Split::Train);
        let stride = (train.len() / frames.max(1)).max(1);
        let idx: Vec<usize> = train.iter().step_by(stride).take(frames).copied().collect();
        let (mut sum, mut sq, mut n) = (Vec::new(), Vec::new(), 0usize);
        let (mut channels, mut size) = (0, 0);
        for chunk in idx.chunks(64) {
            let z = codec.encode(data.frames_tensor(chunk, device)); // [b, C, s, s]
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

    /// An empty cache over `data` for frames encoded by `codec`.
    pub fn new(data: &'a EpisodeData, stats: LatentStats, codec: &FrameCodec) -> Self {
        let pixels = codec.is_pixels();
        let n = if pixels { 0 } else { data.len() };
        let per = stats.channels * stats.size * stats.size;
        Self { data, z: vec![0.0; n * per], done: vec![false; n], stats, pixels }
    }

    /// The normalisation in use.
    pub fn stats(&self) -> &LatentStats {
        &self.stats
    }

    /// Values per latent frame (C·s·s).
    fn per(&self) -> usize {
        self.stats.channels * self.stats.size * self.stats.size
    }

    /// Encodes the frames of `idx` that are not cached yet (pixels need nothing).
    pub fn ensure(&mut self, idx: &[usize], codec: &FrameCodec, device: &Device) {
        if self.pixels {
            return;
        }
        let mut missing: Vec<usize> = idx.iter().copied().filter(|&i| !self.done[i]).collect();
        missing.sort_unstable();
        missing.dedup();
        let (per, plane) = (self.per(), self.stats.size * self.stats.size);
        for chunk in missing.chunks(64) {
            let z = codec.encode(self.data.frames_tensor(chunk, device));
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
        let (c, s) = (self.stats.channels, self.stats.size);
        if self.pixels {
            let stat = |v: &[f32]| Tensor::<1>::from_floats(v, device).reshape([1, c, 1, 1]);
            let x = self.data.frames_tensor(idx, device); // [b F, 3, s, s] in [-1, 1]
            let x = (x - stat(&self.stats.mean)) / stat(&self.stats.std);
            return x.reshape([idx.len() / f, f, c, s, s]);
        }
        let per = self.per();
        let mut v = Vec::with_capacity(idx.len() * per);
        for &i in idx {
            debug_assert!(self.done[i], "frame {i} not encoded");
            v.extend_from_slice(&self.z[i * per..(i + 1) * per]);
        }
        Tensor::from_data(TensorData::new(v, [idx.len() / f, f, c, s, s]), device)
    }
}

/// One training/evaluation window: frame indices and normalised actions.
#[derive(Clone, Debug, PartialEq)]
pub struct Window {
    /// History frame indices o_{t-3..t} (clamped to the episode's first frame).
    pub history: Vec<usize>,
    /// Target frame indices o_{t+1..t+F}.
    pub targets: Vec<usize>,
    /// The episode's first frame index (the anchor).
    pub anchor: usize,
    /// Normalised actions a_t..a_{t+F-1}, `F x action_dim`.
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

/// The window of `history` + `future` frames at global step `t`, its actions
/// normalised with `scale` (whose size the caller checked against the data's).
pub fn window(data: &EpisodeData, t: usize, history: usize, future: usize, scale: &ActionScale) -> Window {
    let ep_start = data.episodes.iter().find(|r| r.contains(&t)).map_or(0, |r| r.start);
    let hist = (0..history).map(|k| (t + k + 1).saturating_sub(history).max(ep_start)).collect();
    let targets = (1..=future).map(|f| t + f).collect();
    let d = data.action_dim;
    let mut actions = Vec::with_capacity(future * d);
    for f in 0..future {
        scale.normalise_into(&data.actions[(t + f) * d..(t + f + 1) * d], &mut actions);
    }
    Window { history: hist, targets, anchor: ep_start, actions }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn toy() -> EpisodeData {
        // Two episodes of 6 and 3 frames of 1x1 pixels; actions a_k = (k, 511).
        EpisodeData {
            frames: vec![0; 9 * 3],
            actions: (0..9).flat_map(|k| [k as f32, 511.0]).collect(),
            action_dim: 2,
            size: 1,
            episodes: vec![0..6, 6..9],
            source: std::path::PathBuf::new(),
        }
    }

    #[test]
    fn windows_clamp_history_to_the_episode_start() {
        let d = toy();
        // Episode 0 (6 frames) with F = 4 has starts 0 and 1; episode 1 is too short.
        assert_eq!(window_starts(&d, Split::Train, 4), vec![0, 1]);
        let w = window(&d, 1, 4, 4, &ActionScale::pusht());
        assert_eq!(w.history, vec![0, 0, 0, 1]);
        assert_eq!(w.targets, vec![2, 3, 4, 5]);
        assert_eq!(w.anchor, 0);
        // a'_1 = 2·1/511 − 1, a'_y = 2·511/511 − 1 = 1.
        assert!((w.actions[0] - (2.0 / 511.0 - 1.0)).abs() < 1e-6);
        assert_eq!(w.actions[1], 1.0);
        // A window in the second episode repeats that episode's first frame.
        assert_eq!(window(&d, 7, 4, 1, &ActionScale::pusht()).history, vec![6, 6, 6, 7]);
        assert_eq!(window(&d, 7, 4, 1, &ActionScale::pusht()).anchor, 6);
    }

    #[test]
    fn pixel_frames_are_read_normalised_from_the_bytes() {
        // 2x2 frames: byte b maps to b/127.5 - 1, then (x - mean_c) / std_c.
        let d = EpisodeData {
            frames: (0..3 * 4 * 3).map(|i| (i * 20) as u8).collect(),
            actions: vec![0.0; 6],
            action_dim: 2,
            size: 2,
            episodes: std::iter::once(0..3).collect(),
            source: std::path::PathBuf::new(),
        };
        let stats =
            LatentStats { channels: 3, size: 2, mean: vec![0.0, 0.5, -0.5], std: vec![1.0, 2.0, 0.5] };
        let mut lat = Latents::new(&d, stats, &FrameCodec::pixels(2));
        let device = burn::tensor::Device::flex();
        lat.ensure(&[2, 1], &FrameCodec::pixels(2), &device);
        let v = lat.tensor(&[2, 1], 2, &device).into_data().try_to_vec::<f32>().unwrap();
        assert_eq!(v.len(), 2 * 3 * 4);
        // Frame 2, channel 1, pixel 0 is byte index 2·12 + 1 = 25 → 500 % 256 = 244:
        // (244/127.5 − 1 − 0.5) / 2 = 0.206863.
        assert!((v[4] - 0.206_863).abs() < 1e-5, "{}", v[4]);
        // Frame 1, channel 2, pixel 3 is byte 12 + 9 + 2 = 23 → 460 % 256 = 204:
        // (204/127.5 − 1 + 0.5) / 0.5 = 2.2.
        assert!((v[12 + 8 + 3] - 2.2).abs() < 1e-5, "{}", v[23]);
    }
}
