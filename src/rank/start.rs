//! What a batch of paired episodes starts from and what a branch returns: the
//! environments reset to the episode seeds, their goals and frame scorers, the
//! first frames, the per-episode policy noise streams; the timing split; and a
//! branch's rows, filmstrip frames and (for `collect --policy`) whole
//! trajectories. The branches themselves are in [`super::paired`].

use std::collections::VecDeque;
use std::sync::Arc;

use anyhow::Result;
use harness::rng::Rng;
use harness::seed::{derive, fnv1a};
use mujoco_rs::prelude::MjModel;
use scenarios::pusht::frame_score::FrameScorer;
use scenarios::pusht::render::Rasterizer;
use scenarios::pusht::rollout::Episode;
use scenarios::pusht::{PushTConfig, PushTEnv};

use super::results::EpisodeRow;

/// A frame and the agent position seen with it.
pub(super) type Seen = (Vec<u8>, [f32; 2]);

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
    /// The first frames without the goal (what a goal-free world model reads).
    pub(super) first_without_goal: Vec<Vec<u8>>,
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
            first_without_goal: envs.iter().map(|e| raster.render_without_goal(&e.state())).collect(),
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
