//! Running Push-T episodes with scripted behaviours, recording what datasets need.
//!
//! A [`Behaviour`] maps the privileged environment to an action; [`Noisy`] adds
//! Gaussian action noise and a control lag to any behaviour; [`run_episode`]
//! resets to a seed, steps until success or the step limit and returns per-step
//! rows (state before the action, the action, the coverage after it) plus,
//! optionally, the observation images.

use std::collections::VecDeque;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use super::decoy::Decoy;
use super::expert::Expert;
use super::explore::Explorer;
use super::geometry::Pose2;
use super::physics::PushTState;
use super::render::Rasterizer;
use super::{PushTEnv, Score};
use crate::error::ScenarioError;

/// Something that chooses Push-T actions from the privileged state.
pub trait Behaviour {
    /// The next action: the agent's absolute target position (world units).
    fn act(&mut self, env: &PushTEnv) -> [f64; 2];
}

impl Behaviour for Expert {
    fn act(&mut self, env: &PushTEnv) -> [f64; 2] {
        Expert::act(self, env)
    }
}

impl Behaviour for Decoy {
    fn act(&mut self, env: &PushTEnv) -> [f64; 2] {
        Decoy::act(self, env)
    }
}

impl Behaviour for Explorer {
    fn act(&mut self, env: &PushTEnv) -> [f64; 2] {
        Explorer::act(self, env)
    }
}

/// Wraps a behaviour with Gaussian action noise (σ in world units) and a lag of
/// `lag` control steps (the first `lag` actions hold the agent where it starts).
pub struct Noisy<B> {
    inner: B,
    noise: Option<Normal<f64>>,
    lag: usize,
    queue: VecDeque<[f64; 2]>,
    rng: ChaCha8Rng,
}

impl<B: Behaviour> Noisy<B> {
    /// Wraps `inner`; `seed` drives the noise only.
    pub fn new(inner: B, sigma: f64, lag: usize, seed: u64) -> Self {
        let noise = (sigma > 0.0).then(|| Normal::new(0.0, sigma).ok()).flatten();
        Self { inner, noise, lag, queue: VecDeque::new(), rng: ChaCha8Rng::seed_from_u64(seed) }
    }
}

impl<B: Behaviour> Behaviour for Noisy<B> {
    fn act(&mut self, env: &PushTEnv) -> [f64; 2] {
        let mut a = self.inner.act(env);
        if let Some(n) = &self.noise {
            a = [a[0] + n.sample(&mut self.rng), a[1] + n.sample(&mut self.rng)];
        }
        let size = env.config().world.size;
        let a = a.map(|v| v.clamp(0.0, size));
        if self.lag == 0 {
            return a;
        }
        if self.queue.is_empty() {
            let hold = env.state().agent;
            self.queue.extend(std::iter::repeat_n(hold, self.lag));
        }
        self.queue.push_back(a);
        self.queue.pop_front().unwrap_or(a)
    }
}

/// One recorded control step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepRow {
    /// Control step index (0-based).
    pub step: u32,
    /// Agent position before the action.
    pub agent: [f64; 2],
    /// Block pose before the action.
    pub block: Pose2,
    /// The action (absolute target).
    pub action: [f64; 2],
    /// Coverage after the action.
    pub coverage: f64,
}

/// A finished episode.
#[derive(Clone, Debug)]
pub struct Episode {
    /// Episode seed.
    pub seed: u64,
    /// Goal pose.
    pub goal: Pose2,
    /// One row per control step.
    pub rows: Vec<StepRow>,
    /// Observation images before each action (only when asked for), plus the final one.
    pub frames: Vec<Vec<u8>>,
    /// Max over steps of the reward clip(c / 0.95, 0, 1).
    pub score: f64,
    /// Whether coverage exceeded the success threshold.
    pub success: bool,
}

/// Something that turns a state into an RGB image.
pub trait FrameSource {
    /// Renders `state` with `goal`.
    ///
    /// # Errors
    /// [`ScenarioError::Render`] when the renderer fails.
    fn frame(&mut self, state: &PushTState, goal: &Pose2) -> Result<Vec<u8>, ScenarioError>;
}

impl FrameSource for Rasterizer {
    fn frame(&mut self, state: &PushTState, goal: &Pose2) -> Result<Vec<u8>, ScenarioError> {
        Ok(self.render(state, goal))
    }
}

/// What to record besides the per-step rows.
#[derive(Default)]
pub struct Record<'a> {
    /// Render the observation before every action (and after the last).
    pub frames: Option<&'a mut dyn FrameSource>,
}

/// Runs one episode from `seed` until success or `max_steps`.
///
/// # Errors
/// The environment's errors (a diverging simulation, a non-finite action), naming seed and step.
pub fn run_episode(
    env: &mut PushTEnv,
    behaviour: &mut dyn Behaviour,
    seed: u64,
    max_steps: u32,
    mut record: Record<'_>,
) -> Result<Episode, ScenarioError> {
    env.reset(seed)?;
    let goal = env.goal();
    let mut rows = Vec::with_capacity(max_steps as usize);
    let mut frames = Vec::new();
    let mut best = Score { coverage: 0.0, iou: 0.0, reward: 0.0, success: false };
    for step in 0..max_steps {
        let before = env.state();
        if let Some(r) = record.frames.as_mut() {
            frames.push(r.frame(&before, &goal)?);
        }
        let action = behaviour.act(env);
        let s = env.step(action)?;
        rows.push(StepRow { step, agent: before.agent, block: before.block, action, coverage: s.coverage });
        if s.reward > best.reward || s.success {
            best = s;
        }
        if s.success {
            break;
        }
    }
    if let Some(r) = record.frames.as_mut() {
        frames.push(r.frame(&env.state(), &goal)?);
    }
    Ok(Episode { seed, goal, rows, frames, score: best.reward, success: best.success })
}
