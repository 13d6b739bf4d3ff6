//! Demonstrations for policy training, read from a replay-buffer dataset.
//!
//! Only episodes of the chosen behaviour (the scripted expert by default, as
//! recorded in the dataset's attributes) are used, optionally only the first N.
//! A sample at step t of an episode is: frames and agent positions at t−1 and t
//! (repeating the first frame at the episode start) and the 16 actions from t−1
//! (repeating the first action before the start and the last one past the end), as
//! diffusion_policy's sequence sampler windows and pads them: the action window
//! starts with the oldest observation, so action index `obs − 1` is the current
//! step's — the first one the policy executes.

use std::path::{Path, PathBuf};

use harness::replay::ReplayReader;

use crate::diffusion::{Normalisation, Range};

/// Why demonstrations could not be loaded.
#[derive(Debug, thiserror::Error)]
#[error("dataset {path}: {message}")]
pub struct DataError {
    /// The dataset.
    pub path: PathBuf,
    /// What is wrong.
    pub message: String,
}

/// Frames, agent positions and actions of the selected episodes.
pub struct Demos {
    /// `n x s x s x 3` bytes.
    pub frames: Vec<u8>,
    /// `n` agent positions.
    pub agent_pos: Vec<[f32; 2]>,
    /// `n` block poses (x, y, θ), privileged: used only to pre-train the encoder.
    pub block: Vec<[f32; 3]>,
    /// `n` goal poses (x, y, θ; drawn in every frame), used only to pre-train the encoder.
    pub goal: Vec<[f32; 3]>,
    /// `n` actions.
    pub actions: Vec<[f32; 2]>,
    /// Frame side.
    pub size: usize,
    /// Step ranges (into the arrays above) of each selected episode.
    pub episodes: Vec<std::ops::Range<usize>>,
}

impl Demos {
    /// Loads the episodes whose behaviour is `behaviour` (all if `None`), at most `limit`.
    ///
    /// # Errors
    /// [`DataError`] naming the dataset for unreadable arrays, a wrong image size or no episodes.
    pub fn load(
        path: &Path,
        behaviour: Option<&str>,
        limit: Option<usize>,
        size: usize,
    ) -> Result<Self, DataError> {
        let err = |m: String| DataError { path: path.to_path_buf(), message: m };
        let r = ReplayReader::open(path).map_err(|e| err(e.to_string()))?;
        let shape = &r.img.meta.shape;
        if shape[1] != size || shape[2] != size {
            return Err(err(format!("images are {}x{}, the policy takes {size}x{size}", shape[1], shape[2])));
        }
        if let Some(other) = r.attrs["evalharness"]["scenario"].as_str().filter(|s| *s != "pusht") {
            return Err(err(format!(
                "a {other} dataset: the policy trainer reads Push-T's agent, block and goal columns, \
                 and does not train {other} policies yet"
            )));
        }
        let behaviours = r.attrs["evalharness"]["episodes"].as_array().cloned().unwrap_or_default();
        let state = r.state.read_f64().map_err(|e| err(e.to_string()))?;
        let sdim = r.state.row_len();
        if sdim < 8 {
            return Err(err(format!(
                "data/state has {sdim} columns, expected agent x, y, block x, y, θ, goal x, y, θ"
            )));
        }
        let action = r.action.read_f64().map_err(|e| err(e.to_string()))?;
        let mut d = Demos {
            frames: Vec::new(),
            agent_pos: Vec::new(),
            block: Vec::new(),
            goal: Vec::new(),
            actions: Vec::new(),
            size,
            episodes: Vec::new(),
        };
        for i in 0..r.episodes() {
            if limit.is_some_and(|l| d.episodes.len() >= l) {
                break;
            }
            if let Some(want) = behaviour {
                let got = behaviours.get(i).and_then(|e| e["behaviour"].as_str());
                if got != Some(want) {
                    continue;
                }
            }
            let rg = r.episode_range(i);
            let start = d.agent_pos.len();
            d.frames.extend(r.img.read_rows(rg.start, rg.end).map_err(|e| err(e.to_string()))?);
            for t in rg.clone() {
                let row = &state[t * sdim..(t + 1) * sdim];
                d.agent_pos.push([row[0] as f32, row[1] as f32]);
                d.block.push([row[2] as f32, row[3] as f32, row[4] as f32]);
                d.goal.push([row[5] as f32, row[6] as f32, row[7] as f32]);
                d.actions.push([action[t * 2] as f32, action[t * 2 + 1] as f32]);
            }
            d.episodes.push(start..d.agent_pos.len());
        }
        if d.episodes.is_empty() {
            return Err(err(format!("no episodes with behaviour {behaviour:?}")));
        }
        Ok(d)
    }

    /// Min-max statistics of agent positions and actions.
    pub fn normalisation(&self) -> Normalisation {
        let range = |v: &[[f32; 2]]| {
            let mut r = Range { min: vec![f32::INFINITY; 2], max: vec![f32::NEG_INFINITY; 2] };
            for p in v {
                for (d, x) in p.iter().enumerate() {
                    r.min[d] = r.min[d].min(*x);
                    r.max[d] = r.max[d].max(*x);
                }
            }
            r
        };
        Normalisation { agent_pos: range(&self.agent_pos), action: range(&self.actions) }
    }

    /// Number of samples (one per step).
    pub fn len(&self) -> usize {
        self.agent_pos.len()
    }

    /// Whether there are no samples.
    pub fn is_empty(&self) -> bool {
        self.agent_pos.is_empty()
    }

    /// Observation step indices (`obs` of them, oldest first) and action indices
    /// (`horizon`) of the sample at global step `t`.
    pub fn sample_indices(&self, t: usize, obs: usize, horizon: usize) -> (Vec<usize>, Vec<usize>) {
        let ep = self.episodes.iter().find(|r| r.contains(&t)).cloned().unwrap_or(t..t + 1);
        let o = (0..obs).map(|k| (t + k + 1).saturating_sub(obs).max(ep.start)).collect();
        let a = (0..horizon).map(|k| (t + k + 1).saturating_sub(obs).max(ep.start).min(ep.end - 1)).collect();
        (o, a)
    }

    /// Frame `i` (HWC bytes).
    pub fn frame(&self, i: usize) -> &[u8] {
        let n = self.size * self.size * 3;
        &self.frames[i * n..(i + 1) * n]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn samples_pad_at_both_ends() {
        let d = Demos {
            frames: vec![],
            agent_pos: vec![[0.0; 2]; 5],
            block: vec![[0.0; 3]; 5],
            goal: vec![[0.0; 3]; 5],
            actions: vec![[0.0; 2]; 5],
            size: 1,
            episodes: vec![0..3, 3..5],
        };
        // First step of episode 1: the observation repeats step 3; the action window starts
        // one step before t (clamped to 3) and runs past the end (4).
        assert_eq!(d.sample_indices(3, 2, 4), (vec![3, 3], vec![3, 3, 4, 4]));
        // Step 2 of episode 0: observations 1, 2; actions 1, 2 (index obs − 1 = 1 is step 2).
        assert_eq!(d.sample_indices(2, 2, 2), (vec![1, 2], vec![1, 2]));
    }
}
