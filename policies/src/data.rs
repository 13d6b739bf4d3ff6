//! Demonstrations for policy training, read from a replay-buffer dataset.
//!
//! Only episodes of the chosen behaviour (the scripted expert by default, as
//! recorded in the dataset's attributes) are used, optionally only the first N.
//! A sample at step t of an episode is: frames and proprioception at t−1 and t
//! (repeating the first frame at the episode start) and the 16 actions from t−1
//! (repeating the first action before the start and the last one past the end), as
//! diffusion_policy's sequence sampler windows and pads them: the action window
//! starts with the oldest observation, so action index `obs − 1` is the current
//! step's — the first one the policy executes.

use std::path::{Path, PathBuf};

use harness::replay::ReplayReader;
use harness::task::Task;

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

/// Privileged per-step labels of what a frame shows, used only to pre-train the
/// frame encoder ([`crate::pretrain`]); never a policy input.
#[derive(Clone, Debug, PartialEq)]
pub enum FrameLabels {
    /// Push-T: the block's and the (randomised) goal's poses (x, y, θ); the agent's
    /// position is the proprioception. Pre-training maps them through the square
    /// world's symmetries.
    PushT {
        /// `n` block poses.
        block: Vec<[f32; 3]>,
        /// `n` goal poses (drawn in every frame).
        goal: Vec<[f32; 3]>,
    },
    /// The state columns a task names ([`Task::frame_labels`]), `names.len()` per
    /// step, step-major.
    Columns {
        /// The columns' names.
        names: Vec<String>,
        /// Their values.
        values: Vec<f32>,
    },
    /// None: the encoder cannot be pre-trained on this data.
    None,
}

/// Frames, proprioception and actions of the selected episodes.
pub struct Demos {
    /// `n x s x s x 3` bytes.
    pub frames: Vec<u8>,
    /// `n x proprio_dim`: what the policy read at each step ([`Task::recorded_proprio`]).
    pub proprio: Vec<f32>,
    /// Entries per proprioceptive vector.
    pub proprio_dim: usize,
    /// `n x action_dim` actions.
    pub actions: Vec<f32>,
    /// Entries per action.
    pub action_dim: usize,
    /// What the frames show, for encoder pre-training.
    pub labels: FrameLabels,
    /// Frame side.
    pub size: usize,
    /// Step ranges (into the arrays above) of each selected episode.
    pub episodes: Vec<std::ops::Range<usize>>,
}

impl Demos {
    /// Loads the episodes whose behaviour is `behaviour` (all if `None`), at most
    /// `limit`, of a dataset of `task`.
    ///
    /// # Errors
    /// [`DataError`] naming the dataset for unreadable arrays, another task's data, a
    /// wrong image size or action width, or no episodes.
    pub fn load(
        path: &Path,
        task: &dyn Task,
        behaviour: Option<&str>,
        limit: Option<usize>,
        size: usize,
    ) -> Result<Self, DataError> {
        let err = |m: String| DataError { path: path.to_path_buf(), message: m };
        let r = ReplayReader::open(path).map_err(|e| err(e.to_string()))?;
        let (action_dim, sdim) = check_layout(path, &r, task, size)?;
        let (poses, named) = (task.pose_labels(), task.frame_labels());
        let proprio_dim = task.observation_spec().proprio.len();
        let behaviours =
            harness::replay::origin::episodes_in(path, &r.attrs).map_err(|e| err(e.to_string()))?;
        let state = r.state.read_f64().map_err(|e| err(e.to_string()))?;
        let action = r.action.read_f64().map_err(|e| err(e.to_string()))?;
        let (mut block, mut goal, mut columns) = (Vec::new(), Vec::new(), Vec::new());
        let mut d = Demos {
            frames: Vec::new(),
            proprio: Vec::new(),
            proprio_dim,
            actions: Vec::new(),
            action_dim,
            labels: FrameLabels::None,
            size,
            episodes: Vec::new(),
        };
        for i in 0..r.episodes() {
            if limit.is_some_and(|l| d.episodes.len() >= l) {
                break;
            }
            if let Some(want) = behaviour {
                let got = behaviours.get(i).and_then(|e| e.behaviour.as_deref());
                if got != Some(want) {
                    continue;
                }
            }
            let rg = r.episode_range(i);
            let start = d.len();
            d.frames.extend(r.img.read_rows(rg.start, rg.end).map_err(|e| err(e.to_string()))?);
            let states: Vec<Vec<f64>> =
                rg.clone().map(|t| state[t * sdim..(t + 1) * sdim].to_vec()).collect();
            let acts: Vec<Vec<f32>> = rg
                .clone()
                .map(|t| action[t * action_dim..(t + 1) * action_dim].iter().map(|&v| v as f32).collect())
                .collect();
            let proprio = task.recorded_proprio(&states, &acts);
            if proprio.len() != acts.len() || proprio.iter().any(|p| p.len() != proprio_dim) {
                return Err(err(format!(
                    "episode {i}: the task's proprioception is not {proprio_dim} entries per step"
                )));
            }
            d.proprio.extend(proprio.into_iter().flatten());
            d.actions.extend(acts.into_iter().flatten());
            for row in &states {
                if let Some(p) = poses {
                    block.push(p.object.map(|c| row[c] as f32));
                    goal.push(p.goal.map(|c| row[c] as f32));
                } else {
                    columns.extend(named.iter().map(|(c, _)| row[*c] as f32));
                }
            }
            d.episodes.push(start..d.len());
        }
        if d.episodes.is_empty() {
            return Err(err(format!("no episodes with behaviour {behaviour:?}")));
        }
        d.labels = if poses.is_some() {
            FrameLabels::PushT { block, goal }
        } else if named.is_empty() {
            FrameLabels::None
        } else {
            FrameLabels::Columns { names: named.into_iter().map(|(_, n)| n).collect(), values: columns }
        };
        Ok(d)
    }

    /// The proprioception read at step `i`.
    pub fn proprio_at(&self, i: usize) -> &[f32] {
        &self.proprio[i * self.proprio_dim..(i + 1) * self.proprio_dim]
    }

    /// The action executed at step `i`.
    pub fn action_at(&self, i: usize) -> &[f32] {
        &self.actions[i * self.action_dim..(i + 1) * self.action_dim]
    }

    /// Min-max statistics of the proprioception and the actions.
    pub fn normalisation(&self) -> Normalisation {
        Normalisation {
            agent_pos: min_max(&self.proprio, self.proprio_dim),
            action: min_max(&self.actions, self.action_dim),
        }
    }

    /// Number of samples (one per step).
    pub fn len(&self) -> usize {
        self.proprio.len() / self.proprio_dim.max(1)
    }

    /// Whether there are no samples.
    pub fn is_empty(&self) -> bool {
        self.proprio.is_empty()
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

/// Per-entry minimum and maximum of `dim`-wide rows.
fn min_max(rows: &[f32], dim: usize) -> Range {
    let mut r = Range { min: vec![f32::INFINITY; dim], max: vec![f32::NEG_INFINITY; dim] };
    for row in rows.chunks(dim.max(1)) {
        for (d, x) in row.iter().enumerate() {
            r.min[d] = r.min[d].min(*x);
            r.max[d] = r.max[d].max(*x);
        }
    }
    r
}

/// Checks that the dataset at `path` (opened as `r`) is `task`'s, with `size`² frames, the
/// task's action width and the state columns its labels name; returns the action and state
/// widths.
///
/// # Errors
/// [`DataError`] naming the dataset and what does not fit.
fn check_layout(
    path: &Path,
    r: &ReplayReader,
    task: &dyn Task,
    size: usize,
) -> Result<(usize, usize), DataError> {
    let err = |m: String| DataError { path: path.to_path_buf(), message: m };
    let shape = r.img.shape();
    if shape[1] != size || shape[2] != size {
        return Err(err(format!("images are {}x{}, the policy takes {size}x{size}", shape[1], shape[2])));
    }
    let scenario = harness::replay::origin::scenario_in(path, &r.attrs).map_err(|e| err(e.to_string()))?;
    if scenario != task.name() {
        return Err(err(format!("a {scenario} dataset, not {}", task.name())));
    }
    let (action_dim, sdim) = (r.action.row_len(), r.state.row_len());
    if action_dim != task.action_spec().dim {
        return Err(err(format!(
            "data/action has {action_dim} columns, {} actions have {}",
            task.name(),
            task.action_spec().dim
        )));
    }
    let poses = task.pose_labels();
    if let Some(p) = poses.filter(|p| sdim < p.columns_needed()) {
        return Err(err(format!(
            "data/state has {sdim} columns; {}'s poses are columns {:?} (object) and {:?} (goal)",
            task.name(),
            p.object,
            p.goal
        )));
    }
    let named = task.frame_labels();
    if let Some((c, name)) = named.iter().find(|(c, _)| *c >= sdim) {
        return Err(err(format!("data/state has {sdim} columns, label {name} is column {c}")));
    }
    Ok((action_dim, sdim))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn samples_pad_at_both_ends() {
        let d = Demos {
            frames: vec![],
            proprio: vec![0.0; 10],
            proprio_dim: 2,
            actions: vec![0.0; 10],
            action_dim: 2,
            labels: FrameLabels::None,
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
