//! Push-T's scripted behaviours by name, and many episodes of them run in parallel,
//! deterministically (`collect`, `simulate`; Lift's and Can's are `robosuite::runs`).
//!
//! Episodes are processed in batches; inside a batch rayon runs them on
//! `--jobs` threads, each with its own MuJoCo data on the shared model, and the
//! results come back in seed order. Every random stream of an episode derives
//! from its seed alone, so any `--jobs` gives byte-identical outputs.

use std::sync::Arc;

use harness::seed::{derive, fnv1a};
use mujoco_rs::prelude::MjModel;
use rayon::prelude::*;

use super::decoy::Decoy;
use super::expert::Expert;
use super::explore::Explorer;
use super::mj_render::{MujocoRenderer, SideBySide};
use super::render::Rasterizer;
use super::rollout::{Behaviour, Episode, FrameSource, Noisy, Record, run_episode};
use super::{PushTConfig, PushTEnv};
use crate::error::ScenarioError;

/// The scripted behaviours.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BehaviourKind {
    /// The sampling-planner expert.
    Expert,
    /// Smooth random targets.
    Explore,
    /// The expert pushing the block to seeded random poses instead of the goal.
    Decoy,
}

impl BehaviourKind {
    /// Parses a behaviour name.
    ///
    /// # Errors
    /// [`ScenarioError::UnknownBehaviour`] listing the behaviours (or a checkpoint folder,
    /// which the commands that take a name also take).
    pub fn parse(name: &str) -> Result<Self, ScenarioError> {
        match name {
            "expert" => Ok(Self::Expert),
            "explore" => Ok(Self::Explore),
            "decoy" => Ok(Self::Decoy),
            other => Err(ScenarioError::UnknownBehaviour {
                what: "policy".into(),
                name: other.into(),
                listed: " behaviours: expert, explore, decoy; or a checkpoint folder".into(),
            }),
        }
    }

    /// Its name.
    pub fn name(self) -> &'static str {
        match self {
            Self::Expert => "expert",
            Self::Explore => "explore",
            Self::Decoy => "decoy",
        }
    }
}

/// Noise and lag applied to the expert's actions.
#[derive(Clone, Copy, Debug)]
pub struct Perturbation {
    /// Gaussian std (world units).
    pub noise: f64,
    /// Control-step lag.
    pub lag: usize,
}

/// How a dataset names an episode's behaviour: a perturbed expert is not an expert
/// demonstration (`expert+noise80+lag2`), so consumers that want clean demonstrations
/// (the policy trainer's `--behaviour expert`) can tell them apart.
pub fn behaviour_label(kind: BehaviourKind, p: Perturbation) -> String {
    let mut label = kind.name().to_string();
    if kind == BehaviourKind::Expert {
        if p.noise > 0.0 {
            label.push_str(&format!("+noise{}", p.noise));
        }
        if p.lag > 0 {
            label.push_str(&format!("+lag{}", p.lag));
        }
    }
    label
}

/// Builds the behaviour of one episode; its randomness derives from the seed only.
fn behaviour(kind: BehaviourKind, env: &PushTEnv, seed: u64, p: Perturbation) -> Box<dyn Behaviour> {
    match kind {
        BehaviourKind::Expert => {
            let expert = Expert::new(env.model(), env.config());
            if p.noise > 0.0 || p.lag > 0 {
                Box::new(Noisy::new(expert, p.noise, p.lag, derive(seed, &[fnv1a("expert/noise")])))
            } else {
                Box::new(expert)
            }
        }
        BehaviourKind::Explore => Box::new(Explorer::new(derive(seed, &[fnv1a("explore")]))),
        BehaviourKind::Decoy => {
            Box::new(Decoy::new(Expert::new(env.model(), env.config()), derive(seed, &[fnv1a("decoy")])))
        }
    }
}

/// Frames to record for one episode.
#[derive(Clone, Copy, Debug)]
pub struct FrameSpec {
    /// Side in pixels.
    pub size: usize,
    /// Also MuJoCo's OpenGL rendering, beside the rasteriser's (frames twice as wide).
    pub beside_mujoco: bool,
}

fn frame_source(
    model: &Arc<MjModel>,
    cfg: &PushTConfig,
    spec: FrameSpec,
) -> Result<Box<dyn FrameSource>, ScenarioError> {
    let raster = Rasterizer::with_size(cfg, spec.size);
    Ok(if spec.beside_mujoco {
        let mujoco = MujocoRenderer::new(model.clone(), spec.size)?;
        Box::new(SideBySide { mujoco, raster })
    } else {
        Box::new(raster)
    })
}

/// What each episode needs.
pub struct Runner {
    /// Scenario parameters.
    pub cfg: PushTConfig,
    model: Arc<MjModel>,
    pool: rayon::ThreadPool,
    /// Step limit.
    pub max_steps: u32,
    /// Expert perturbation.
    pub perturbation: Perturbation,
}

impl Runner {
    /// Builds a pool of `jobs` threads for episodes on `model` (compiled from `cfg`); episodes
    /// end at `max_steps` (the task's limit if `None`). The caller checks the settings (a
    /// finite noise of at least 0, a positive step limit) and names the flags that set them.
    ///
    /// # Errors
    /// Threads that cannot be started.
    pub fn on_model(
        cfg: PushTConfig,
        model: Arc<MjModel>,
        jobs: usize,
        max_steps: Option<u32>,
        perturbation: Perturbation,
    ) -> Result<Self, ScenarioError> {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(jobs.max(1))
            .build()
            .map_err(ScenarioError::Threads)?;
        let max_steps = max_steps.unwrap_or(cfg.task.max_steps);
        Ok(Self { cfg, model, pool, max_steps, perturbation })
    }

    /// Runs one episode per `(seed, behaviour)` in `work`, calling `done` with each
    /// result in input order. `frames(i)` says whether to render episode i's
    /// observations, and at what size.
    ///
    /// # Errors
    /// The first episode that fails ([`ScenarioError::Episode`], naming its seed and
    /// behaviour), or what `done` returns.
    pub fn run<E: From<ScenarioError>>(
        &self,
        work: &[(u64, BehaviourKind)],
        frames: impl Fn(usize) -> Option<FrameSpec> + Sync,
        mut done: impl FnMut(usize, Episode) -> Result<(), E>,
    ) -> Result<(), E> {
        let batch = self.pool.current_num_threads() * 4;
        for (b, chunk) in work.chunks(batch).enumerate() {
            let results: Vec<Result<Episode, ScenarioError>> = self.pool.install(|| {
                chunk
                    .par_iter()
                    .enumerate()
                    .map_init(
                        || PushTEnv::new(self.model.clone(), &self.cfg),
                        |env, (k, &(seed, kind))| {
                            let index = b * batch + k;
                            let mut source = frames(index)
                                .map(|spec| frame_source(&self.model, &self.cfg, spec))
                                .transpose()?;
                            let mut beh = behaviour(kind, env, seed, self.perturbation);
                            // Shorten the trait object's lifetime (no coercion happens inside an Option).
                            let frames = source.as_deref_mut().map(|s| s as &mut dyn FrameSource);
                            let record = Record { frames };
                            run_episode(env, beh.as_mut(), seed, self.max_steps, record).map_err(|e| {
                                ScenarioError::Episode {
                                    scenario: String::new(),
                                    seed,
                                    behaviour: kind.name().into(),
                                    source: Box::new(e),
                                }
                            })
                        },
                    )
                    .collect()
            });
            for (k, r) in results.into_iter().enumerate() {
                done(b * batch + k, r?)?;
            }
        }
        Ok(())
    }
}
