//! Episode data for world-model training, loaded from a replay-buffer dataset.
//!
//! Frames are kept in memory as bytes (81k Push-T frames are 2.2 GB) and turned
//! into `[-1, 1]` tensors batch by batch. Episodes are split deterministically:
//! every 10th episode (index % 10 == 9) is held out for evaluation and never
//! used in training.

use std::path::Path;

use burn::tensor::{Device, Tensor};
use harness::replay::ReplayReader;

use crate::error::WorldModelError;

/// Frames, actions and episode boundaries of a dataset.
#[derive(Clone)]
pub struct EpisodeData {
    /// `n x h x w x 3` bytes.
    pub frames: Vec<u8>,
    /// `n x action_dim` actions (Push-T: world units).
    pub actions: Vec<f32>,
    /// Entries per action.
    pub action_dim: usize,
    /// Image side.
    pub size: usize,
    /// Step ranges of each episode.
    pub episodes: Vec<std::ops::Range<usize>>,
    /// The dataset it was read from (named in errors about its contents).
    pub source: std::path::PathBuf,
}

/// Which episodes a step index set is drawn from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Split {
    /// Episodes with index % 10 != 9.
    Train,
    /// Episodes with index % 10 == 9.
    HeldOut,
}

impl Split {
    /// Whether episode `i` belongs to this split.
    pub fn contains(self, i: usize) -> bool {
        (i % 10 == 9) == (self == Split::HeldOut)
    }
}

impl EpisodeData {
    /// Loads a dataset, checking that its frames are `expected_size` square RGB.
    ///
    /// # Errors
    /// [`WorldModelError::Data`] naming the dataset for a missing/invalid layout or
    /// a wrong image size.
    pub fn load(path: &Path, expected_size: usize) -> Result<Self, WorldModelError> {
        let err = |m: String| WorldModelError::Data { path: path.to_path_buf(), message: m };
        let r = ReplayReader::open(path).map_err(|e| err(e.to_string()))?;
        let shape = r.img.shape();
        if shape[1] != expected_size || shape[2] != expected_size {
            return Err(err(format!(
                "images are {}x{}, the model expects {expected_size}x{expected_size}",
                shape[1], shape[2]
            )));
        }
        let frames = r.img.read_rows(0, r.steps()).map_err(|e| err(e.to_string()))?;
        let actions: Vec<f32> =
            r.action.read_f64().map_err(|e| err(e.to_string()))?.into_iter().map(|v| v as f32).collect();
        let episodes = (0..r.episodes()).map(|i| r.episode_range(i)).collect();
        Ok(Self {
            frames,
            actions,
            action_dim: r.action.row_len(),
            size: expected_size,
            episodes,
            source: path.to_path_buf(),
        })
    }

    /// Number of frames.
    pub fn len(&self) -> usize {
        self.frames.len() / (self.size * self.size * 3)
    }

    /// Whether there are no frames.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// All frame indices of a split.
    pub fn frame_indices(&self, split: Split) -> Vec<usize> {
        self.episodes
            .iter()
            .enumerate()
            .filter(|(i, _)| split.contains(*i))
            .flat_map(|(_, r)| r.clone())
            .collect()
    }

    /// Frame `i` (HWC bytes).
    pub fn frame(&self, i: usize) -> &[u8] {
        let n = self.size * self.size * 3;
        &self.frames[i * n..(i + 1) * n]
    }

    /// Frames `idx` as a `[b, 3, h, w]` tensor in [-1, 1].
    pub fn frames_tensor(&self, idx: &[usize], device: &Device) -> Tensor<4> {
        let frames: Vec<&[u8]> = idx.iter().map(|&i| self.frame(i)).collect();
        nn::frames::frames_to_tensor(&frames, self.size, device)
    }
}

pub use harness::image::psnr;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn split_holds_out_every_tenth_episode() {
        assert!(Split::HeldOut.contains(9) && Split::HeldOut.contains(19));
        assert!(Split::Train.contains(0) && !Split::Train.contains(9));
    }

    #[test]
    fn frames_round_trip_through_tensors() {
        let data = EpisodeData {
            frames: (0..2 * 4 * 4 * 3).map(|i| (i * 5 % 256) as u8).collect(),
            actions: vec![0.0; 4],
            action_dim: 2,
            size: 4,
            episodes: std::iter::once(0..2).collect(),
            source: std::path::PathBuf::new(),
        };
        let t = data.frames_tensor(&[1, 0], &Device::flex());
        let back = nn::frames::tensor_to_frames(t);
        assert_eq!(back[0], data.frames[48..96]);
        assert_eq!(back[1], data.frames[..48]);
    }
}
