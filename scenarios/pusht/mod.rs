//! Push-T in MuJoCo: push a T-shaped block onto a goal pose with a disk agent.
//!
//! [`PushTEnv`] is one episode: a seeded reset (a pure function of the seed, see
//! [`initial_state`]), 10 Hz control of the agent's target position, exact
//! coverage scoring and a 96x96 RGB observation from [`render::Rasterizer`].
//! The geometry, physics constants and reset distribution follow the GPC /
//! DriftWorld variant (randomised goal); `reset.fixed_goal` gives the standard one.

pub mod colors;
pub mod config;
pub mod datasets;
pub mod decoy;
pub mod expert;
pub mod explore;
pub mod frame_score;
pub mod geometry;
pub mod goal_free;
pub mod gpc_render;
#[cfg(feature = "mujoco-render")]
pub mod mj_render;
pub mod numpy_rng;
pub mod path;
pub mod perceive;
pub mod physics;
pub mod plan_cost;
pub mod pygame_raster;
pub mod render;
pub mod rollout;
pub mod runs;
pub mod scripted;
pub mod task;

use std::sync::Arc;

use mujoco_rs::prelude::MjModel;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

pub use config::PushTConfig;
pub use geometry::{Pose2, TShape};
pub use physics::{PushTPhysics, PushTState};
pub use task::PushTTask;

/// Push-T for the task table (`crate::load_task`): the shipped scene, or a scenario file's.
pub(crate) fn registered(
    file: Option<&std::path::Path>,
) -> Result<Box<dyn harness::task::Task>, crate::ScenarioError> {
    let cfg = file.map_or_else(|| Ok(PushTConfig::default()), PushTConfig::from_file)?;
    Ok(Box::new(PushTTask::new(cfg)?))
}

/// The GPC-faithful Push-T for the task table: the shipped `pusht_gpc.toml`, or a file's.
pub(crate) fn registered_gpc(
    file: Option<&std::path::Path>,
) -> Result<Box<dyn harness::task::Task>, crate::ScenarioError> {
    let cfg = file.map_or_else(PushTConfig::gpc, PushTConfig::from_file)?;
    Ok(Box::new(PushTTask::new(cfg)?))
}

use crate::error::ScenarioError;
use geometry::wrap_angle;

/// The score of one state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Score {
    /// area(block ∩ goal) / area(goal), exact.
    pub coverage: f64,
    /// IoU = c / (2 - c) (both Ts have the same area).
    pub iou: f64,
    /// clip(c / success_coverage, 0, 1).
    pub reward: f64,
    /// c > success_coverage.
    pub success: bool,
}

/// Scores a block pose against a goal pose.
pub fn score(cfg: &PushTConfig, block: &Pose2, goal: &Pose2) -> Score {
    let c = geometry::coverage(&cfg.shape(), block, goal);
    let thr = cfg.task.success_coverage;
    Score {
        coverage: c,
        iou: geometry::iou_from_coverage(c),
        reward: (c / thr).clamp(0.0, 1.0),
        success: c > thr,
    }
}

/// The initial state and goal of episode `seed`: a pure function of (config, seed).
///
/// Draw order as GPC's reset: agent x, y; block x, y; block θ = N(0,1)·2π − π;
/// goal x, y; goal θ; then the agent is redrawn while it is closer than
/// `min_agent_block_distance` to the block's centre or its disk touches the T.
/// With `reset.rng = "gpc-numpy"` the draws are GPC's own ([`numpy_rng::gpc_initial_state`]).
///
/// # Errors
/// [`ScenarioError::ImpossibleReset`] when [`MAX_RESET_DRAWS`] draws of the agent
/// never satisfy those conditions (a scenario whose `reset` fields admit no state).
pub fn initial_state(cfg: &PushTConfig, seed: u64) -> Result<(PushTState, Pose2), ScenarioError> {
    if cfg.reset.rng == config::ResetRng::GpcNumpy {
        return numpy_rng::gpc_initial_state(cfg, seed);
    }
    let stream = harness::seed::derive(seed, &[harness::seed::fnv1a("pusht/reset")]);
    let mut rng = ChaCha8Rng::seed_from_u64(stream);
    let r = &cfg.reset;
    let uni = |rng: &mut ChaCha8Rng, range: [f64; 2]| rng.random_range(range[0]..range[1]);
    let angle = |rng: &mut ChaCha8Rng| {
        let n: f64 = rng.sample(StandardNormal);
        wrap_angle(n * std::f64::consts::TAU - std::f64::consts::PI)
    };
    let mut agent = [uni(&mut rng, r.agent_range), uni(&mut rng, r.agent_range)];
    let block_xy = [uni(&mut rng, r.block_range), uni(&mut rng, r.block_range)];
    let block = Pose2::new(block_xy[0], block_xy[1], angle(&mut rng));
    let goal_xy = [uni(&mut rng, r.goal_range), uni(&mut rng, r.goal_range)];
    let mut goal = Pose2::new(goal_xy[0], goal_xy[1], angle(&mut rng));
    if r.fixed_goal {
        goal = cfg.fixed_goal();
    }
    let shape = cfg.shape();
    let clear = |a: [f64; 2]| {
        let d = (a[0] - block.x).hypot(a[1] - block.y);
        d >= r.min_agent_block_distance && shape.distance(block.inverse_apply(a)) > cfg.agent.radius + 1.0
    };
    let mut draws = 1;
    while !clear(agent) {
        if draws == MAX_RESET_DRAWS {
            return Err(ScenarioError::ImpossibleReset {
                seed,
                draws,
                field: "reset.min_agent_block_distance".into(),
            });
        }
        agent = [uni(&mut rng, r.agent_range), uni(&mut rng, r.agent_range)];
        draws += 1;
    }
    Ok((PushTState { agent, agent_vel: [0.0; 2], block }, goal))
}

/// Draws of the agent's position [`initial_state`] makes before it gives up. A
/// feasible scenario needs a handful (the shipped one: under 2 on average); a
/// million makes a wrongly refused seed practically impossible while bounding the
/// time an impossible `reset` section takes to ~0.1 s.
pub const MAX_RESET_DRAWS: u32 = 1_000_000;

/// One Push-T episode in MuJoCo.
pub struct PushTEnv {
    model: Arc<MjModel>,
    cfg: PushTConfig,
    physics: PushTPhysics,
    goal: Pose2,
    seed: u64,
    step: u32,
}

impl PushTEnv {
    /// An environment on a compiled model (see [`PushTPhysics::compile`]); call
    /// [`PushTEnv::reset`] before stepping.
    pub fn new(model: Arc<MjModel>, cfg: &PushTConfig) -> Self {
        // A placeholder until `reset` (a validated config always resets seed 0).
        let (state, goal) = initial_state(cfg, 0).unwrap_or_else(|_| {
            let c = cfg.world.size / 2.0;
            (
                PushTState { agent: [c, c], agent_vel: [0.0; 2], block: Pose2::new(c, c, 0.0) },
                Pose2::new(c, c, 0.0),
            )
        });
        let mut physics = PushTPhysics::new(model.clone(), cfg);
        physics.set_state(&state);
        Self { model, cfg: cfg.clone(), physics, goal, seed: 0, step: 0 }
    }

    /// Resets to episode `seed`: sets the initial state and runs one physics step.
    ///
    /// # Errors
    /// [`ScenarioError::NonFinite`] if that first step diverges.
    pub fn reset(&mut self, seed: u64) -> Result<(), ScenarioError> {
        let (state, goal) = initial_state(&self.cfg, seed)?;
        self.physics.set_state(&state);
        self.physics.physics_step(state.agent);
        self.goal = goal;
        self.seed = seed;
        self.step = 0;
        self.check()
    }

    /// Applies one action (the agent's absolute target position) for one control step.
    ///
    /// # Errors
    /// [`ScenarioError::BadAction`] for a non-finite action and
    /// [`ScenarioError::NonFinite`] when the simulation diverges; both name seed and step.
    pub fn step(&mut self, action: [f64; 2]) -> Result<Score, ScenarioError> {
        if !action.iter().all(|v| v.is_finite()) {
            return Err(ScenarioError::BadAction {
                seed: self.seed,
                step: self.step,
                action: action.to_vec(),
            });
        }
        self.physics.control_step(action);
        self.step += 1;
        self.check()?;
        Ok(self.score())
    }

    fn check(&self) -> Result<(), ScenarioError> {
        match self.physics.divergence() {
            None => Ok(()),
            Some(detail) => Err(ScenarioError::NonFinite {
                scenario: "pusht".into(),
                seed: self.seed,
                step: self.step,
                detail,
            }),
        }
    }

    /// The score of the current state.
    pub fn score(&self) -> Score {
        score(&self.cfg, &self.physics.state().block, &self.goal)
    }

    /// The current simulator state.
    pub fn state(&self) -> PushTState {
        self.physics.state()
    }

    /// Overwrites the simulator state (for planners that imagine with the simulator).
    pub fn set_state(&mut self, state: &PushTState) {
        self.physics.set_state(state);
    }

    /// A copy at the current state, goal, seed and step, on a simulation of its own
    /// (for planners that imagine with the simulator). Velocities of the block are
    /// not carried over: it is damped to quasi-static motion (see [`physics`](self::physics)).
    pub fn fork(&self) -> Self {
        let mut copy = Self::new(self.model.clone(), &self.cfg);
        copy.set_state(&self.state());
        copy.set_goal(self.goal);
        copy.seed = self.seed;
        copy.step = self.step;
        copy
    }

    /// Overwrites the goal (for planners that act on an estimated scene).
    pub fn set_goal(&mut self, goal: Pose2) {
        self.goal = goal;
    }

    /// The goal pose of this episode.
    pub fn goal(&self) -> Pose2 {
        self.goal
    }

    /// The episode seed.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// Control steps taken since the reset.
    pub fn steps(&self) -> u32 {
        self.step
    }

    /// The compiled MuJoCo model (shared; planners build their own data on it).
    pub fn model(&self) -> Arc<MjModel> {
        self.model.clone()
    }

    /// The parameters.
    pub fn config(&self) -> &PushTConfig {
        &self.cfg
    }
}

#[cfg(test)]
mod tests;
