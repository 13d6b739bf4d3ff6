//! What a batch of paired episodes starts from and what a branch returns: the
//! environments reset to the episode seeds, their goals and frame scorers, the
//! first frames, the per-episode policy noise streams; the timing split; and a
//! branch's rows, filmstrip frames and (for `collect --policy`) whole
//! trajectories; and each episode's running score and when it ends. The branches
//! themselves are in [`super::paired`].

use std::collections::VecDeque;
use std::sync::Arc;

use anyhow::Result;
use harness::rng::Rng;
use harness::seed::{derive, fnv1a};
use mujoco_rs::prelude::MjModel;
use scenarios::pusht::frame_score::{FrameScorer, SceneCheck};
use scenarios::pusht::render::Rasterizer;
use scenarios::pusht::rollout::Episode;
use scenarios::pusht::{PushTConfig, PushTEnv};

use super::results::EpisodeRow;

/// A frame and the agent position seen with it.
pub(crate) type Seen = (Vec<u8>, [f32; 2]);

/// Wall-clock split of a batch.
#[derive(Clone, Copy, Debug, Default)]
pub struct Timing {
    /// MuJoCo stepping and rendering.
    pub sim_s: f64,
    /// World-model prediction and decoding.
    pub world_model_s: f64,
    /// Policy inference (both branches).
    pub policy_s: f64,
    /// Frames the world model generated.
    pub frames: u64,
}

impl Timing {
    /// Adds another split.
    pub fn add(&mut self, o: &Timing) {
        self.sim_s += o.sim_s;
        self.world_model_s += o.world_model_s;
        self.policy_s += o.policy_s;
        self.frames += o.frames;
    }
}

/// What a rollout needs besides the policy.
pub struct Setup<'a> {
    /// Scenario.
    pub cfg: &'a PushTConfig,
    /// Compiled MuJoCo model.
    pub model: &'a Arc<MjModel>,
    /// Master seed of the policy noise.
    pub master_seed: u64,
    /// Control steps per episode.
    pub max_steps: usize,
}

/// What both branches start from: environments reset to the seeds, their goals,
/// frame scorers, the first rendered frames and the policy noise streams.
pub struct Start {
    pub(super) envs: Vec<PushTEnv>,
    pub(super) goals: Vec<[f64; 3]>,
    pub(super) scorers: Vec<FrameScorer>,
    pub(super) first: Vec<Vec<u8>>,
    pub(super) start_pos: Vec<[f32; 2]>,
    pub(super) policy_rngs: Vec<Rng>,
    pub(super) seeds: Vec<u64>,
    /// Keep the last frame of every action chunk (for filmstrips and GIFs).
    pub record: bool,
    /// MuJoCo branch only: keep every step's observation, state, action and coverage
    /// (`collect --policy`).
    pub trajectories: bool,
}

/// A branch's rows and, when recording, each episode's frames at the end of every
/// action chunk (the first frame first).
pub struct BranchOut {
    /// One row per episode.
    pub rows: Vec<EpisodeRow>,
    /// Recorded frames per episode (empty unless recording).
    pub frames: Vec<Vec<Vec<u8>>>,
    /// Whole episodes in the dataset layout of `collect` (empty unless
    /// [`Start::trajectories`]; the MuJoCo branch only).
    pub episodes: Vec<Episode>,
}

impl Start {
    /// Resets one environment per seed.
    ///
    /// # Errors
    /// A diverging first physics step, naming the seed.
    pub fn new(policy: &str, seeds: &[u64], s: &Setup) -> Result<Self> {
        let raster = Rasterizer::new(s.cfg);
        let mut envs = Vec::with_capacity(seeds.len());
        for &seed in seeds {
            let mut env = PushTEnv::new(s.model.clone(), s.cfg);
            env.reset(seed)?;
            envs.push(env);
        }
        let scorers = envs.iter().map(|e| FrameScorer::new(s.cfg, &e.goal(), raster.size())).collect();
        Ok(Self {
            goals: envs.iter().map(|e| e.goal().to_array()).collect(),
            scorers,
            first: envs.iter().map(|e| raster.render(&e.state(), &e.goal())).collect(),
            start_pos: envs.iter().map(|e| e.state().agent.map(|v| v as f32)).collect(),
            policy_rngs: seeds
                .iter()
                .map(|&sd| Rng::new(derive(s.master_seed, &[fnv1a(policy), sd])))
                .collect(),
            seeds: seeds.to_vec(),
            record: false,
            trajectories: false,
            envs,
        })
    }

    pub(super) fn recording(&self) -> Vec<Vec<Vec<u8>>> {
        if self.record { self.first.iter().map(|f| vec![f.clone()]).collect() } else { Vec::new() }
    }

    pub(super) fn histories(&self, o: usize) -> Vec<VecDeque<Seen>> {
        (0..self.envs.len())
            .map(|i| (0..o).map(|_| (self.first[i].clone(), self.start_pos[i])).collect())
            .collect()
    }
}

/// Per-episode running score.
#[derive(Clone, Debug, Default)]
pub(super) struct Track {
    pub(super) best_reward: f64,
    pub(super) max_cov: f64,
    pub(super) last_cov: f64,
    /// Control steps executed (until success or the step limit).
    pub(super) steps: usize,
    /// Score so far at the end of each action chunk (repeated after the episode ended,
    /// so every trace of a batch has the same length).
    pub(super) trace: Vec<f64>,
    /// Scene checks of the last frame the policy saw.
    pub(super) scene: Option<SceneCheck>,
}

impl Track {
    pub(super) fn add(&mut self, cov: f64, success_cov: f64) {
        self.best_reward = self.best_reward.max((cov / success_cov).clamp(0.0, 1.0));
        self.max_cov = self.max_cov.max(cov);
        self.last_cov = cov;
    }

    pub(super) fn end_chunk(&mut self) {
        self.trace.push((self.best_reward * 1e6).round() / 1e6);
    }
}

/// Episodes still running: gym-pusht ends an episode at success, and so does each
/// branch here, at the end of the action chunk that reached it (its score, the best
/// reward so far, cannot change after that).
pub(super) fn still_active(active: &[usize], track: &[Track]) -> Vec<usize> {
    active.iter().copied().filter(|&i| track[i].best_reward < 1.0).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn succeeded_episodes_leave_the_batch_and_keep_their_trace() {
        let mut track = vec![Track::default(); 3];
        // Success coverage 0.95: coverage 0.95 gives reward 1 (ends), 0.5 gives 0.526.
        track[0].add(0.5, 0.95);
        track[1].add(0.95, 0.95);
        track[2].add(0.2, 0.95);
        assert_eq!(still_active(&[0, 1, 2], &track), vec![0, 2]);
        // A finished episode is not revived, and its trace keeps the batch's length.
        assert_eq!(still_active(&[0, 2], &track), vec![0, 2]);
        track.iter_mut().for_each(Track::end_chunk);
        track.iter_mut().for_each(Track::end_chunk);
        assert_eq!(track[1].trace, vec![1.0, 1.0]);
        assert_eq!(track[0].trace, vec![0.526316, 0.526316]);
    }
}
